"""clutch-sim record: record the clutch_sim node's outputs to an MCAP rosbag2."""
from __future__ import annotations

import math
import sys

from clutch_sim.cli import add_params_option


def add_parser(sub):
    p = sub.add_parser(
        "record", help="record the node's outputs (torque, pack temperature, state, diagnostics) to MCAP",
        description="Record NS/clutch_torque, NS/pack_temperature, NS/clutch_state and /diagnostics "
                    "to an MCAP rosbag2 with message schemas, until --duration elapses or Ctrl-C (which ends "
                    "the recording normally: what was delivered is written, the bag is closed, exit 0). "
                    "Messages are queued to a writer thread (reliable QoS, 1000 deep), so recording keeps up "
                    "with the node at 1 kHz.")
    p.add_argument("--out", required=True, metavar="OUT.mcap",
                   help="OUT.mcap = bare MCAP file; any other name = rosbag2 directory (must not exist)")
    add_params_option(p)  # accepted for uniformity (not used)
    p.add_argument("--namespace", default="/clutch", metavar="NS", help="the node's namespace (default /clutch)")
    p.add_argument("--duration", type=float, default=None, metavar="S", help="stop after S seconds (wall clock)")
    p.add_argument("--use-sim-time", action="store_true", help="log time = /clock time instead of wall time")
    p.set_defaults(func=run)


def run(args) -> int:
    from clutch_model.errors import DataError

    if args.params:
        print("clutch-sim record: note: --params is not used", file=sys.stderr)
    if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        raise DataError(f"--duration must be a positive number, got {args.duration}")
    try:
        from clutch_sim_ros.record import record
    except ImportError as exc:
        raise DataError(f"ROS 2 (rclpy, clutch_msgs) is not available: {exc}") from None
    result = record(args.out, args.namespace, args.duration, use_sim_time=args.use_sim_time)
    total = sum(result["counts"].values())
    how = " (stopped by Ctrl-C; the bag is complete)" if result.get("interrupted") else ""
    print(f"recorded {total} messages -> {result['out']}{how}")
    if result.get("skipped"):
        print(f"  {result['skipped']} messages before the first /clock not recorded")
    for topic, n in result["counts"].items():
        print(f"  {topic}: {n}")
    return 0
