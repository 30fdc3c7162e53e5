"""`make run`: the main job on the shipped defaults.

1. replays the sample car-test bags in bags/ through the reference clutch (offline, as
   `clutch-sim replay` does) and prints the validation figures;
2. starts the ROS 2 node, plays the same bags into it in sim-time lock-step, records its
   outputs to out/live.mcap and prints the live torque's RMSE against the measured torque
   and its agreement with the offline replay.
"""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    from clutch_model.errors import ClutchSimError

    try:
        return _main()
    except ClutchSimError as exc:
        print(f"make run: error: {exc}", file=sys.stderr)
        return 1


def _main() -> int:
    from clutch_model.plant.params import load_model
    from clutch_model.replay import replay_runs, write_replay_csv
    from clutch_model.formats.bag_reader import read_bags

    bags = sorted(p for p in (ROOT / "bags").iterdir() if p.is_dir() and (p / "metadata.yaml").exists())
    if not bags:
        print("make run: no sample bags in bags/ (python -m clutch_model.virtual_car.sample_bags writes them)", file=sys.stderr)
        return 1
    out = ROOT / "out"
    out.mkdir(exist_ok=True)
    model = load_model()
    runs = read_bags(bags)
    result = replay_runs(model, runs)
    write_replay_csv(result, out / "replay.csv")
    print(f"== offline replay of {len(runs)} sample bags through RC-1 -> out/replay.csv")
    for name, rmse_t, rmse_th, n in result.per_run():
        th = f", pack temperature RMSE {rmse_th:6.2f} C" if rmse_th == rmse_th else ""
        print(f"  {name}: {n} rows, torque RMSE {rmse_t:7.2f} N*m{th}")
    print(f"  all bags: torque RMSE {result.rmse_torque():.2f} N*m")

    print("\n== live: clutch-sim-node driven by the bags in sim-time lock-step -> out/live.mcap")
    try:
        from clutch_sim_ros.live import live_replay
    except ImportError as exc:
        print(f"  (live replay unavailable: {exc})")
        return 0
    figures = live_replay(bags, namespace="/clutch", out_mcap=out / "live.mcap")
    offline = {name: rmse for name, rmse, _, _ in result.per_run()}
    for run in figures["runs"]:
        print(f"  {run['bag']}: {run['rows']} rows, live torque RMSE {run['rmse_nm']:7.2f} N*m "
              f"(offline {offline.get(run['bag'], float('nan')):.2f})")
    print(f"  all bags: live torque RMSE {figures['rmse_nm']:.2f} N*m, {figures['rows']} lock-step ticks in "
          f"{figures['wall_s']:.1f} s, {figures['retries']} retries, node exit code {figures['node_exit_code']}")
    print("\nnext: clutch-sim diagnose --bench bags/bench.csv --bags bags/run_* --out out/diag  (see README)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
