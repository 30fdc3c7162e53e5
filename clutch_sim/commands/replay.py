"""clutch-sim replay: simulate car-test bags offline and compare with the measured torque."""
from __future__ import annotations

import math
import sys

from clutch_sim.cli import add_params_option
from clutch_sim.commands._common import add_topic_options


def add_parser(sub):
    p = sub.add_parser("replay", help="simulate bags' inputs offline, write OUT.csv, print RMSE",
                       description="Simulate the bags' inputs offline (in log-time order, dissipated "
                                   "energy carried from bag to bag) and write the predicted torque "
                                   "and pack temperature next to the measured ones.")
    p.add_argument("--bag", "--bags", dest="bags", nargs="+", required=True, metavar="BAG",
                   help="rosbag2 directories (MCAP or sqlite3) or bare .mcap files")
    add_params_option(p)
    p.add_argument("--out", required=True, metavar="OUT.csv")
    add_topic_options(p)
    p.set_defaults(func=run)


def _keep_freed_memory() -> None:
    """glibc malloc: serve the per-block arrays (up to 32 MB) from the heap and keep freed
    pages for the next block, instead of an mmap/munmap and fresh page faults per array (half
    the page faults, a third of the system time of a replay). Elsewhere: nothing."""
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, 1 << 25)          # M_MMAP_THRESHOLD (its maximum on 64-bit)
        libc.mallopt(-1, 1 << 28)          # M_TRIM_THRESHOLD
    except (OSError, AttributeError):
        pass


def run(args) -> int:
    from clutch_model.plant.params import load_model
    from clutch_model.replay_stream import replay_bags

    from clutch_sim.commands._common import topics_from_args

    _keep_freed_memory()
    model = load_model(args.params)
    # bag by bag (memory bounded by the largest bag), the same numbers as the whole campaign at once
    result = replay_bags(model, args.bags, args.out, topics_from_args(args), progress=True)
    print(f"replayed {len(result.per_run)} bag(s), {result.rows} rows -> {args.out}")
    for name, rmse_t, rmse_th, n in result.per_run:
        extra = f", pack temperature RMSE {rmse_th:.2f} C" if not math.isnan(rmse_th) else ""
        print(f"  {name}: {n} rows, torque RMSE {rmse_t:.2f} N*m{extra}")
    rmse = result.rmse_torque()
    if math.isnan(rmse):
        print("torque RMSE: n/a (no /clutch/measured_torque in the bags)")
    else:
        print(f"torque RMSE: {rmse:.3f} N*m")
    rmse_th = result.rmse_pack_temperature()
    if not math.isnan(rmse_th):
        print(f"pack temperature RMSE: {rmse_th:.3f} C")
    sys.stdout.flush()
    return 0
