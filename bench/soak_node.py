"""Soak and fuzz of the clutch_sim node: a long run at 1 kHz on a hypothesis-generated input stream.

    .venv/bin/python bench/soak_node.py [--duration 30] [--rate 1000] [--seed 0] [--json OUT.json]
    .venv/bin/python bench/soak_node.py --duration 3600          # the hour-long soak

The node runs as a subprocess in sim time (use_sim_time:=true, input_timeout_s 0.05) in a
private ROS domain; this process publishes its inputs and /clock at --rate in real time
(one /clock tick per period, paced by the wall clock). The stream is a sequence of segments
drawn by hypothesis strategies:

- ``steady``: valid inputs (force 0..50 kN -- beyond the pack-force clamp --, slip +-1000 rad/s,
  sump -40..200 C) on a random walk;
- ``nonfinite``: NaN / +inf / -inf bursts on one or more inputs;
- ``out_of_range``: force > 1e6 N, |slip| > 1000 rad/s, sump outside [-40, 200] C;
- ``flood``: 5..40 messages per input and tick, valid and invalid mixed;
- ``gap``: some inputs silent for 60..400 ticks (stale after 50: force counts as 0 N);
- ``clock_back``: the sim clock jumps back by 1 ms .. 10 s (the node restarts the plant).

Reports (and writes with --json): ticks sent and the achieved rate, node memory (RSS) at the
start and end and its growth, the on-time share (clutch_state for a /clock tick received before
the next tick was sent), the answered share, rejected input counts, clock jumps back, non-finite
outputs received (must be 0), the node's callback errors and non-finite resets, and whether
the node is still alive. Exit status 0 when the node survived with zero non-finite outputs and
zero callback errors.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import random
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
os.environ.setdefault("NUMBA_CACHE_DIR", str(REPO / ".numba_cache"))
sys.path.insert(0, str(REPO))

INPUTS = ("applied_force", "slip_speed", "sump_temperature")
INPUT_TIMEOUT_S = 0.05
FIELDS = ("applied_force", "pack_force", "slip_speed", "sump_temperature", "clutch_torque", "asperity_torque",
          "hydrodynamic_torque", "friction_coefficient", "film_thickness", "pack_temperature", "viscosity",
          "power", "energy")


# ---- the input stream (hypothesis strategies) ------------------------------------------
def stream_strategy():
    from hypothesis import strategies as st

    which = st.sets(st.sampled_from(INPUTS), min_size=1, max_size=3).map(sorted)
    ticks = st.integers(20, 600)
    steady = st.fixed_dictionaries({
        "kind": st.just("steady"), "ticks": ticks,
        "force": st.floats(0.0, 50_000.0), "slip": st.floats(-1000.0, 1000.0), "sump": st.floats(-40.0, 200.0),
        "walk": st.floats(0.0, 0.05)})
    nonfinite = st.fixed_dictionaries({
        "kind": st.just("nonfinite"), "ticks": st.integers(1, 200), "inputs": which,
        "value": st.sampled_from([math.nan, math.inf, -math.inf])})
    out_of_range = st.fixed_dictionaries({
        "kind": st.just("out_of_range"), "ticks": st.integers(1, 200), "inputs": which,
        "scale": st.floats(1.000001, 1e300)})
    flood = st.fixed_dictionaries({
        "kind": st.just("flood"), "ticks": st.integers(10, 300), "per_tick": st.integers(5, 40),
        "bad_share": st.floats(0.0, 1.0)})
    gap = st.fixed_dictionaries({
        "kind": st.just("gap"), "ticks": st.integers(60, 400), "inputs": which})
    clock_back = st.fixed_dictionaries({
        "kind": st.just("clock_back"), "ticks": st.just(0), "jump_s": st.floats(0.001, 10.0)})
    segment = st.one_of(steady, steady, nonfinite, out_of_range, flood, gap, clock_back)
    return st.lists(segment, min_size=3, max_size=12)


def _bad_value(name: str, scale: float, rng: random.Random) -> float:
    if name == "applied_force":
        return 1e6 * scale
    if name == "slip_speed":
        return rng.choice((1.0, -1.0)) * 1000.0 * scale
    return rng.choice((200.0 * scale, -40.0 * scale - 1e-3))


# ---- the driver -------------------------------------------------------------------------
@dataclass
class Stats:
    ticks: int = 0
    messages: int = 0
    answered: int = 0
    on_time: int = 0
    nonfinite_outputs: int = 0
    outputs: int = 0
    segments: dict = field(default_factory=dict)
    clock_backs_sent: int = 0


class Driver:
    def __init__(self, rate_hz: float, deadline: float, node_pid: int):
        import rclpy
        from clutch_msgs.msg import ClutchState
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import Temperature
        from std_msgs.msg import Float64

        from clutch_sim_ros.diagnostics import values_of

        self.period = 1.0 / rate_hz
        self.deadline = deadline
        self.node_pid = node_pid
        self.stats = Stats()
        self.values_of = values_of
        rclpy.init()
        self.node = Node("clutch_sim_soak")
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        rel = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        n = self.node
        self.Float64, self.Temperature, self.Clock = Float64, Temperature, Clock
        self.pub = {"applied_force": n.create_publisher(Float64, "applied_force", qos_profile_sensor_data),
                    "slip_speed": n.create_publisher(Float64, "slip_speed", qos_profile_sensor_data),
                    "sump_temperature": n.create_publisher(Temperature, "sump_temperature", qos_profile_sensor_data)}
        self.pub_clock = n.create_publisher(Clock, "/clock", rel)
        self.sent_at: dict[int, float] = {}
        self.diag: dict[str, dict] = {}
        n.create_subscription(ClutchState, "clutch_state", self._on_state, rel)
        n.create_subscription(Float64, "clutch_torque", self._on_float, rel)
        n.create_subscription(Temperature, "pack_temperature", self._on_temp, rel)
        n.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, 10)
        self.t_sim_ns = 1_000_000_000_000
        self.period_ns = int(round(self.period * 1e9))
        self.current = {"applied_force": 2000.0, "slip_speed": 10.0, "sump_temperature": 60.0}
        self.rng = random.Random(0)
        self._next_wall = time.monotonic()
        self._clock_msg = Clock()

    # ---- outputs
    def _check(self, values) -> None:
        self.stats.outputs += 1
        if not all(math.isfinite(v) for v in values):
            self.stats.nonfinite_outputs += 1

    def _on_state(self, msg) -> None:
        self._check([getattr(msg, f) for f in FIELDS])
        t = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        if self.sent_at.pop(t, None) is not None:
            self.stats.answered += 1
            if t == self._last_clock_t:     # answered before the next tick was sent
                self.stats.on_time += 1

    def _on_float(self, msg) -> None:
        self._check([msg.data])

    def _on_temp(self, msg) -> None:
        self._check([msg.temperature])

    def _on_diag(self, msg) -> None:
        for st in msg.status:
            if st.hardware_id.endswith("/clutch_sim"):
                self.diag[st.name.split(": ")[-1]] = self.values_of(st)

    # ---- inputs
    def _send(self, name: str, value: float) -> None:
        if name == "sump_temperature":
            self.pub[name].publish(self.Temperature(temperature=float(value)))
        else:
            self.pub[name].publish(self.Float64(data=float(value)))
        self.stats.messages += 1

    _last_clock_t = None

    def _tick(self, silent=(), overrides=None, extra=None) -> None:
        """One period: inputs, /clock, then spin until the next period is due."""
        for name in INPUTS:
            if name in silent:
                continue
            for value in (extra or {}).get(name, ()):
                self._send(name, value)
            self._send(name, (overrides or {}).get(name, self.current[name]))
        self.t_sim_ns += self.period_ns
        t = self.t_sim_ns
        self._clock_msg.clock.sec, self._clock_msg.clock.nanosec = divmod(t, 1_000_000_000)
        self.sent_at[t] = time.monotonic()
        self._last_clock_t = t
        self.pub_clock.publish(self._clock_msg)
        self.stats.ticks += 1
        self._next_wall += self.period
        if self._next_wall < time.monotonic() - 0.05:      # far behind: do not try to catch up
            self._next_wall = time.monotonic()
        while True:
            left = self._next_wall - time.monotonic()
            if left <= 0:
                break
            self.executor.spin_once(timeout_sec=min(left, 0.002))
        if len(self.sent_at) > 5000:                          # unanswered ticks (node restarting)
            for key in sorted(self.sent_at)[:-1000]:
                self.sent_at.pop(key, None)

    def play(self, segments) -> None:
        rng = self.rng
        for seg in segments:
            if time.monotonic() >= self.deadline:
                return
            kind = seg["kind"]
            self.stats.segments[kind] = self.stats.segments.get(kind, 0) + 1
            if kind == "clock_back":
                self.t_sim_ns = max(self.period_ns, self.t_sim_ns - int(seg["jump_s"] * 1e9))
                self.sent_at.clear()
                self.stats.clock_backs_sent += 1
                self._tick()
                continue
            if kind == "steady":
                self.current = {"applied_force": seg["force"], "slip_speed": seg["slip"],
                                "sump_temperature": seg["sump"]}
            for _ in range(seg["ticks"]):
                if time.monotonic() >= self.deadline:
                    return
                if kind == "steady":
                    w = seg["walk"]
                    c = self.current
                    c["applied_force"] = min(50_000.0, max(0.0, c["applied_force"] * (1 + rng.uniform(-w, w))))
                    c["slip_speed"] = min(1000.0, max(-1000.0, c["slip_speed"] + rng.uniform(-w, w) * 50))
                    c["sump_temperature"] = min(200.0, max(-40.0, c["sump_temperature"] + rng.uniform(-w, w)))
                    self._tick()
                elif kind == "nonfinite":
                    self._tick(overrides={n: seg["value"] for n in seg["inputs"]})
                elif kind == "out_of_range":
                    self._tick(overrides={n: _bad_value(n, seg["scale"], rng) for n in seg["inputs"]})
                elif kind == "flood":
                    extra = {}
                    for n in INPUTS:
                        values = []
                        for _ in range(seg["per_tick"]):
                            if rng.random() < seg["bad_share"]:
                                values.append(rng.choice((math.nan, math.inf, -math.inf, _bad_value(n, 2.0, rng))))
                            else:
                                values.append(self.current[n] * rng.uniform(0.9, 1.1))
                        extra[n] = values
                    self._tick(extra=extra)
                elif kind == "gap":
                    self._tick(silent=set(seg["inputs"]))

    def drain(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown()


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def soak(duration_s: float, rate_hz: float = 1000.0, seed: int = 0, progress: bool = True) -> dict:
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import seed as hyp_seed

    domain = os.environ.get("ROS_DOMAIN_ID") or str(random.Random(seed ^ os.getpid()).randint(1, 200))
    os.environ["ROS_DOMAIN_ID"] = domain
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH", "")) if p))
    proc = subprocess.Popen([sys.executable, "-m", "clutch_sim_ros.node", "--ros-args", "-p", "use_sim_time:=true",
                             "-p", f"input_timeout_s:={INPUT_TIMEOUT_S}"], env=env, cwd=str(REPO),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    driver = None
    result: dict = {"duration_s": duration_s, "rate_hz": rate_hz, "seed": seed}
    try:
        start = time.monotonic()
        driver = Driver(rate_hz, start + duration_s + 3600.0, proc.pid)
        # discovery, then a warm-up second of valid inputs (numba, allocations) before the window
        while (any(p.get_subscription_count() == 0 for p in driver.pub.values())
               or driver.pub_clock.get_subscription_count() == 0):
            if proc.poll() is not None or time.monotonic() - start > 60:
                raise RuntimeError(f"node did not come up: {proc.stderr.read()[-500:]}")
            driver.executor.spin_once(timeout_sec=0.05)
        driver.drain(0.5)
        driver.deadline = time.monotonic() + 1.0
        driver.play([{"kind": "steady", "ticks": int(rate_hz), "force": 3000.0, "slip": 20.0, "sump": 60.0,
                      "walk": 0.0}])
        driver.stats = Stats()
        rss0 = _rss_mb(proc.pid)
        t0 = time.monotonic()
        rss_t = [(t0, rss0)]
        driver.deadline = t0 + duration_s
        rounds = 0
        last_print = t0
        while time.monotonic() < driver.deadline and proc.poll() is None:
            rounds += 1

            @hyp_seed(seed * 100_003 + rounds)
            @settings(max_examples=50, database=None, deadline=None, phases=[Phase.generate],
                      suppress_health_check=list(HealthCheck))
            @given(stream_strategy())
            def drive(segments):
                driver.play(segments)

            drive()
            if time.monotonic() - rss_t[-1][0] >= 10.0 and proc.poll() is None:
                rss_t.append((time.monotonic(), _rss_mb(proc.pid)))
            if progress and time.monotonic() - last_print > 10:
                last_print = time.monotonic()
                print(f"soak: {last_print - t0:.0f}/{duration_s:g} s, {driver.stats.ticks} ticks, "
                      f"{driver.stats.nonfinite_outputs} non-finite outputs", file=sys.stderr, flush=True)
        wall = time.monotonic() - t0
        driver.drain(1.5)          # answers in flight and a diagnostics report covering the end
        alive = proc.poll() is None
        rss1 = _rss_mb(proc.pid) if alive else float("nan")
        s = driver.stats
        inputs, timing = driver.diag.get("inputs", {}), driver.diag.get("timing", {})
        result.update({
            "wall_s": wall, "ticks": s.ticks, "achieved_hz": s.ticks / wall if wall else 0.0,
            "input_messages": s.messages, "segments": s.segments, "clock_backs_sent": s.clock_backs_sent,
            "answered_pct": 100.0 * s.answered / max(1, s.ticks),
            "on_time_pct": 100.0 * s.on_time / max(1, s.ticks),
            "outputs_received": s.outputs, "nonfinite_outputs": s.nonfinite_outputs,
            "rss_start_mb": rss0, "rss_end_mb": rss1, "rss_growth_mb": rss1 - rss0,
            "rss_samples_mb": [round(r, 2) for _, r in rss_t],
            "rss_growth_second_half_mb": (rss_t[-1][1] - rss_t[len(rss_t) // 2][1]) if len(rss_t) > 2 else float("nan"),
            "rejected": {n: int(inputs.get(f"{n}.rejected", -1)) for n in INPUTS},
            "received": {n: int(inputs.get(f"{n}.received", -1)) for n in INPUTS},
            "clock_jumps_back": int(timing.get("clock_jumps_back", -1)),
            "callback_errors": int(timing.get("callback_errors", -1)),
            "nonfinite_resets": int(timing.get("nonfinite_resets", -1)),
            "node_alive": alive,
        })
    finally:
        if driver is not None:
            driver.close()
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        result["node_exit_code"] = proc.returncode
    return result


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=30.0, metavar="S", help="soak length, s (default 30)")
    ap.add_argument("--rate", type=float, default=1000.0, metavar="HZ", help="/clock ticks per wall second")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None, metavar="OUT.json")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args()
    res = soak(args.duration, args.rate, args.seed, progress=not args.quiet)
    print(f"clutch_sim soak: {res['wall_s']:.0f} s at {args.rate:g} Hz sim-time ticks (seed {args.seed})")
    print(f"  ticks sent             {res['ticks']} ({res['achieved_hz']:.0f} Hz achieved), "
          f"{res['input_messages']} input messages")
    print(f"  segments               {res['segments']}")
    print(f"  answered / on time     {res['answered_pct']:.2f} % / {res['on_time_pct']:.2f} % of ticks")
    print(f"  node memory (RSS)      {res['rss_start_mb']:.1f} -> {res['rss_end_mb']:.1f} MB "
          f"(growth {res['rss_growth_mb']:+.1f} MB; second half {res['rss_growth_second_half_mb']:+.1f} MB; "
          f"every 10 s: {res['rss_samples_mb']})")
    print(f"  rejected inputs        {res['rejected']} of {res['received']} received")
    print(f"  clock jumps back       {res['clock_jumps_back']} seen by the node ({res['clock_backs_sent']} sent)")
    print(f"  non-finite outputs     {res['nonfinite_outputs']} of {res['outputs_received']} received")
    print(f"  callback errors        {res['callback_errors']}, non-finite resets {res['nonfinite_resets']}")
    print(f"  node alive             {res['node_alive']} (exit code after SIGINT {res['node_exit_code']})")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2))
    ok = res["node_alive"] and res["nonfinite_outputs"] == 0 and res["callback_errors"] == 0
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
