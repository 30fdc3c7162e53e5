"""Does `clutch-sim record` keep up with the node at 1 kHz while the cores are busy?

    .venv/bin/python bench/bench_record.py [--seconds 10] [--load N] [--rate 1000]

Starts the node (wall clock, --rate), N busy-loop processes (default one per core) and
`clutch-sim record` as a separate process; this process feeds the inputs and keeps its own
reliable subscription to clutch_state. After --seconds the recorder gets SIGINT. Prints the
messages recorded per second, the recorder's exit code, and how many of the clutch_state
messages this process received inside the recording's span are missing from the bag (target 0).
"""
from __future__ import annotations

import argparse
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
os.environ.setdefault("NUMBA_CACHE_DIR", str(REPO / ".numba_cache"))
sys.path.insert(0, str(REPO))

BUSY_SRC = "import time, sys\nend = time.monotonic() + float(sys.argv[1])\nwhile time.monotonic() < end:\n    pass\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--load", type=int, default=os.cpu_count() or 2)
    args = ap.parse_args()

    import rclpy
    from clutch_msgs.msg import ClutchState
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosbags.highlevel import AnyReader
    from sensor_msgs.msg import Temperature
    from std_msgs.msg import Float64

    domain = str(random.randint(1, 200))
    os.environ["ROS_DOMAIN_ID"] = domain
    env = dict(os.environ, PYTHONPATH=str(REPO))
    out = Path(tempfile.mkdtemp(prefix="bench_record_")) / "rec.mcap"
    node = subprocess.Popen([sys.executable, "-m", "clutch_sim_ros.node", "--ros-args", "-p", f"rate_hz:={args.rate}",
                             "-p", "input_timeout_s:=2.0"], env=env, cwd=str(REPO), stderr=subprocess.DEVNULL)
    rclpy.init()
    client = Node("bench_record")
    rel = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    pubs = (client.create_publisher(Float64, "applied_force", rel), client.create_publisher(Float64, "slip_speed", rel),
            client.create_publisher(Temperature, "sump_temperature", rel))
    seen = []
    client.create_subscription(ClutchState, "clutch_state",
                               lambda m: seen.append(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec), rel)
    ex = SingleThreadedExecutor()
    ex.add_node(client)
    busy, rec = [], None

    def send():
        pubs[0].publish(Float64(data=3000.0))
        pubs[1].publish(Float64(data=12.0))
        pubs[2].publish(Temperature(temperature=60.0))

    def spin(seconds, feed=True):
        end, nxt = time.monotonic() + seconds, 0.0
        while time.monotonic() < end:
            if feed and time.monotonic() >= nxt:
                send()
                nxt = time.monotonic() + 0.01
            ex.spin_once(timeout_sec=0.002)

    try:
        while not seen:
            send()
            ex.spin_once(timeout_sec=0.05)
        rec = subprocess.Popen([sys.executable, "-m", "clutch_sim.cli", "record", "--out", str(out), "--namespace", "/"],
                               env=env, cwd=str(REPO), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        n0 = client.count_subscribers("clutch_state")
        while client.count_subscribers("clutch_state") <= n0:
            spin(0.1)
        busy = [subprocess.Popen([sys.executable, "-c", BUSY_SRC, str(args.seconds + 5)]) for _ in range(args.load)]
        spin(args.seconds)
        rec.send_signal(signal.SIGINT)
        while rec.poll() is None:
            spin(0.1)
        _, err = rec.communicate()
    finally:
        for p in busy:
            p.terminate()
        if rec is not None and rec.poll() is None:
            rec.kill()
        node.send_signal(signal.SIGINT)
        node.wait(timeout=20)
        client.destroy_node()
        rclpy.try_shutdown()
    with AnyReader([out]) as reader:
        conns = [c for c in reader.connections if c.topic == "/clutch_state"]
        stamps = []
        for c, t, raw in reader.messages(conns):
            m = reader.deserialize(raw, c.msgtype)
            stamps.append(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)
        total = sum(c.msgcount for c in reader.connections)
        log_times = [t for _, t, _ in reader.messages()]
    recorded = set(stamps)
    lo, hi = min(recorded), max(recorded)
    inside = {t for t in seen if lo <= t <= hi}
    missing = len(inside - recorded)
    span = (max(log_times) - min(log_times)) * 1e-9
    print(f"clutch-sim record under load ({args.load} busy processes, node at {args.rate:g} Hz, {args.seconds:g} s)")
    print(f"  recorder exit code        {rec.returncode}" + (f" ({err.strip().splitlines()[-1]})" if err.strip() else ""))
    print(f"  messages recorded         {total} over {span:.1f} s ({total / span:.0f}/s, all topics)")
    print(f"  clutch_state recorded     {len(recorded)} ({len(recorded) / span:.0f}/s)")
    print(f"  missing from the bag      {missing} of {len(inside)} received by this client in the span (target 0)")
    return 0 if missing == 0 and rec.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
