"""clutch-sim driveline: run a closed-loop scenario offline (slip controller + clutch in the driveline)."""
from __future__ import annotations

from clutch_sim.cli import add_params_option


def add_parser(sub):
    p = sub.add_parser("driveline", help="closed loop offline: PI slip controller on the clutch in a driveline",
                       description="Simulate a torque-split scenario with the clutch inside the two-inertia "
                                   "driveline and a PI slip controller commanding the force; write the "
                                   "trajectory (CSV) and a plot of slip, force and clutch torque (PNG).")
    p.add_argument("--scenario", default="split-mu", help="scenario name (default: %(default)s; known: split-mu)")
    add_params_option(p)
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--rate", type=float, default=1000.0, metavar="HZ",
                   help="controller and sample rate, Hz (default: %(default)s)")
    p.set_defaults(func=run)


def run(args) -> int:
    from pathlib import Path

    from clutch_model.closed_loop.plots import plot_scenario
    from clutch_model.closed_loop.scenarios import get_scenario, run_scenario, summary, write_scenario_csv
    from clutch_model.errors import ParamsError
    from clutch_model.plant.params import load_model

    if not (1.0 <= args.rate <= 100000.0):
        raise ParamsError(f"--rate must be in [1, 100000] Hz, got {args.rate:g}")
    model = load_model(args.params)
    scenario = get_scenario(args.scenario, rate_hz=args.rate)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    result = run_scenario(model, scenario)
    csv_path = out / f"{scenario.name}.csv"
    write_scenario_csv(result, csv_path)
    png = plot_scenario(result, out / f"{scenario.name}.png")
    s = summary(result)
    print(f"{scenario.name}: {scenario.description}")
    print(f"  slip tracking (settled, target > 0): RMS error {s['slip_rms_error_rad_s']:.3f} rad/s")
    print(f"  wheel on ice: top speed {s['max_speed_b_controlled_rad_s']:.0f} rad/s controlled, "
          f"{s['max_speed_b_open_rad_s']:.0f} rad/s with the clutch open")
    print(f"  clutch torque carried to the gripping side: {s['mean_clutch_torque_nm']:.0f} N*m mean; "
          f"locked {100 * s['locked_fraction']:.0f} % of the time; pack up to {s['peak_pack_temperature_c']:.1f} C")
    print(f"wrote {csv_path} and {png}")
    return 0
