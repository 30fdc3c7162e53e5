"""Closed loop offline in one command: a PI slip controller on the clutch inside the driveline,
one wheel on ice (split-mu). Writes the trajectory (CSV) and the plot (PNG).

    python examples/closed_loop/run_offline.py [--out out/closed_loop] [--params MODEL.yaml]

The same as `clutch-sim driveline --scenario split-mu --out DIR`; this script shows the library
calls a controls engineer would change (controller gains, target, scenario torques).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))   # run from a checkout

from clutch_model import load_model  # noqa: E402
from clutch_model.closed_loop import PISlipController  # noqa: E402
from clutch_model.closed_loop.plots import plot_scenario  # noqa: E402
from clutch_model.closed_loop.scenarios import run_scenario, split_mu, summary, write_scenario_csv  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/closed_loop")
    ap.add_argument("--params", default=None, help="clutch parameter file (default RC-1)")
    ap.add_argument("--kp", type=float, default=600.0, help="proportional gain, N per rad/s")
    ap.add_argument("--ki", type=float, default=3000.0, help="integral gain, N per rad")
    args = ap.parse_args()

    model = load_model(args.params)
    scenario = split_mu(rate_hz=1000.0)
    controller = PISlipController(target_slip_rad_s=scenario.target_slip, kp_n_per_rad_s=args.kp,
                                  ki_n_per_rad=args.ki, force_min_n=1000.0, force_max_n=20000.0)
    run = run_scenario(model, scenario, controller)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_scenario_csv(run, out / "split-mu.csv")
    png = plot_scenario(run, out / "split-mu.png")
    for key, value in summary(run).items():
        print(f"{key}: {value:.3f}")
    print(f"wrote {out / 'split-mu.csv'} and {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
