"""clutch-sim play: publish car-test bags' inputs into a running clutch_sim node (live replay)."""
from __future__ import annotations

import math
import sys

from clutch_sim.cli import add_params_option
from clutch_sim.commands._common import add_topic_options, topics_from_args


def add_parser(sub):
    p = sub.add_parser(
        "play", help="publish bags' input topics into a running clutch_sim node (like ros2 bag play)",
        description="Publish the bags' /clutch/applied_force, /clutch/slip_speed and "
                    "/clutch/sump_temperature to a running clutch-sim-node, at their recorded timing "
                    "(scaled by --rate), or with --clock in lock-step with a node started with "
                    "use_sim_time:=true (deterministic: equal to offline replay). Before each bag the "
                    "node's ~/reset service is called (the plant restarts as at a new run).")
    p.add_argument("--bag", "--bags", dest="bags", nargs="+", required=True, metavar="BAG",
                   help="rosbag2 directories (MCAP or sqlite3) or bare .mcap files, played in log-time order")
    add_params_option(p)  # accepted for uniformity: the model is the node's clutch_params_file
    p.add_argument("--rate", type=float, default=1.0, help="playback speed factor in real time (default 1)")
    p.add_argument("--clock", action="store_true",
                   help="lock-step: publish /clock per replay row and wait for the node's answer")
    p.add_argument("--namespace", default="/clutch", metavar="NS",
                   help="publish the inputs as NS/applied_force etc. (default /clutch); the node's namespace")
    p.add_argument("--record", default=None, metavar="OUT.mcap",
                   help="also record the node's outputs (clutch_torque, pack_temperature, clutch_state, "
                        "/diagnostics); OUT.mcap = bare MCAP file, other names = rosbag2 directory")
    p.add_argument("--no-reset", dest="reset", action="store_false", help="do not call ~/reset before each bag")
    add_topic_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from clutch_model.errors import DataError

    if args.params:
        print("clutch-sim play: note: --params is not used; the node's clutch_params_file sets the model",
              file=sys.stderr)
    if not (args.rate > 0 and math.isfinite(args.rate)):
        raise DataError(f"--rate must be a positive number, got {args.rate}")
    try:
        from clutch_sim_ros.play import play
    except ImportError as exc:
        raise DataError(f"ROS 2 (rclpy, clutch_msgs) is not available: {exc}") from None
    result = play(args.bags, args.namespace, clock=args.clock, rate=args.rate, record_out=args.record,
                  reset=args.reset, topics=topics_from_args(args))
    unit = "rows" if args.clock else "messages"
    print(f"played {len(result.bags)} bag(s), {result.messages} {unit} in {result.wall_s:.1f} s"
          + (f" ({result.retries} lock-step retries)" if args.clock else ""))
    if args.clock:
        for bag in result.bags:
            print(f"  {bag.name}: {bag.rows} rows")
    if args.record:
        print(f"recorded -> {args.record}")
    return 0
