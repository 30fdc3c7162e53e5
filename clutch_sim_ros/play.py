"""Live replay of car-test bags into the clutch_sim node (like ``ros2 bag play``).

Real time (default): every input message of the bags (/clutch/applied_force,
/clutch/slip_speed, /clutch/sump_temperature) is published unchanged at its recorded
timing, scaled by ``rate``; the node runs on its own wall-clock timer.

Lock-step (``clock=True``): deterministic, as fast as the node answers. The node must run
with use_sim_time:=true (it then steps once per /clock message). For every row of the
offline replay grid (clutch_model.formats.bag_reader.read_bag: one row per valid applied_force message at or
after the first valid sample of every input; inputs = latest valid samples at or before
the row) the player

1. publishes the row's inputs (applied force, slip speed, sump temperature),
2. publishes /clock = the row's log time t_k,
3. waits for the node's clutch_state stamped t_k and checks that it echoes the inputs sent.
   The node takes every input that arrived before a /clock message before it steps, so the
   state at t_k is integrated from t_{k-1} with row k-1's inputs and sampled with row k's --
   offline replay's timing. If the answer is missing (lost message) or echoes other inputs
   (a message overtaken in transit), the inputs and the same /clock time are sent again: the
   node recomputes a repeated time from the state before it, so a retry is exact.
4. after a retry, waits until every /clock sent for t_k has been answered (or a deadline:
   one was lost) before the next row's inputs go out: a /clock that was only late would
   otherwise recompute t_k with row k+1's inputs and the plant would hold those over the
   next step.

So the live outputs equal offline replay of the same bags to numerical precision (the node
publishes the plant torque; offline ``torque_sim`` adds the model's measurement mechanisms,
none in the reference clutch). Before each bag the player calls the node's ``~/reset``
(plant restarts like at a new run of offline replay; the dissipated energy restarts at 0,
while offline replay carries it across bags -- only friction_degradation reads it). The
handshake needs publish_every = 1.

Topics: the bags' ``/clutch/...`` inputs are published under ``namespace`` (default
``/clutch``: unchanged); /clock is global, so lock-step must be the only /clock source of the
ROS domain (live_replay uses a private domain). In real time the node's own rules apply:
e.g. a gap longer than input_timeout_s in a bag's force makes the force stale (0 N).
"""
from __future__ import annotations

import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from clutch_model.errors import ClutchSimError, DataError

from clutch_model.formats.bag_messages import bag_start_ns, normalize_namespace, read_messages, read_run, row_times_ns

NODE_NAME = "clutch_sim"


class PlayError(ClutchSimError):
    """The node did not answer (not running, wrong namespace, not in sim time, ...)."""


@dataclass
class BagResult:
    name: str
    rows: int = 0
    t_ns: Optional[np.ndarray] = None
    torque_nm: Optional[np.ndarray] = None
    pack_temperature_c: Optional[np.ndarray] = None
    torque_measured_nm: Optional[np.ndarray] = None
    run: object = None


@dataclass
class PlayResult:
    bags: list = field(default_factory=list)
    retries: int = 0
    messages: int = 0
    wall_s: float = 0.0


def _stamp_ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class Player:
    """Publishes bag inputs into a node graph. ``node`` is an rclpy Node owned by the caller
    (spun by ``executor`` inside the player's waits)."""

    def __init__(self, node, executor, namespace: str = "/clutch", *, clock: bool = False, rate: float = 1.0,
                 reset: bool = True, ack_timeout_s: float = 1.0, max_attempts: int = 20,
                 drain_timeout_s: float = 10.0, discovery_timeout_s: float = 20.0, recorder=None, progress: bool = True,
                 node_alive=None, stop_requested=None):
        from clutch_msgs.msg import ClutchState
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import Temperature
        from std_msgs.msg import Float64
        from std_srvs.srv import Trigger

        if not (rate > 0.0):
            raise DataError(f"--rate must be > 0, got {rate}")
        self.node, self.executor = node, executor
        self.ns = normalize_namespace(namespace)
        self.clock_mode, self.rate, self.reset_each_bag = clock, float(rate), reset
        self.ack_timeout_s, self.max_attempts = ack_timeout_s, max_attempts
        self.drain_timeout_s = drain_timeout_s
        self.discovery_timeout_s = discovery_timeout_s
        self.recorder, self.progress = recorder, progress
        self.node_alive = node_alive or (lambda: True)   # live_replay: its node subprocess runs
        self.stop_requested = stop_requested or (lambda: False)   # play(): a SIGINT noted
        qos = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                         depth=100, durability=DurabilityPolicy.VOLATILE)
        self._Float64, self._Temperature, self._Clock = Float64, Temperature, Clock
        self.pubs = {
            "applied_force": node.create_publisher(Float64, f"{self.ns}/applied_force", qos),
            "slip_speed": node.create_publisher(Float64, f"{self.ns}/slip_speed", qos),
            "sump_temperature": node.create_publisher(Temperature, f"{self.ns}/sump_temperature", qos),
        }
        self.clock_pub = node.create_publisher(Clock, "/clock", qos) if clock else None
        self._reset_client = node.create_client(Trigger, f"{self.ns}/{NODE_NAME}/reset")
        self._Trigger = Trigger
        self._awaiting: Optional[int] = None
        self._answer = None
        self._answers = 0         # clutch_state messages stamped with the awaited time
        if clock:
            node.create_subscription(ClutchState, f"{self.ns}/clutch_state", self._on_state, qos)
        self._sim_now_ns = 0
        self._retries = 0
        self._step_count = 0

    # ---- helpers -----------------------------------------------------------------------
    @property
    def sim_now_ns(self) -> int:
        """The last /clock time published (log time of recorded outputs in lock-step)."""
        return self._sim_now_ns

    def _on_state(self, msg) -> None:
        if self._awaiting is not None and _stamp_ns(msg.header.stamp) == self._awaiting:
            self._answer = msg
            self._answers += 1

    def _spin_until(self, done, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not done():
            left = deadline - time.monotonic()
            if left <= 0.0:
                return False
            self.spin_once(min(left, 0.05))
        return True

    def spin_once(self, timeout_sec: float) -> None:
        """One executor spin, then a noted stop request raised as KeyboardInterrupt here, at a
        point where it cannot be lost (a KeyboardInterrupt raised by the signal handler itself
        can land in a finalizer run during the spin -- rclpy's Future.__del__ -- where Python
        prints it and drops it: the play went on to the bag's end and exited 0)."""
        self.executor.spin_once(timeout_sec=timeout_sec)
        if self.stop_requested():
            raise KeyboardInterrupt

    def wait_for_node(self) -> None:
        """Wait until the node's subscriptions (and in lock-step its clutch_state and /clock
        subscription) are matched."""
        def ready():
            if not self.node_alive():
                raise PlayError("the clutch_sim node exited")
            if any(p.get_subscription_count() == 0 for p in self.pubs.values()):
                return False
            if self.recorder is not None and not self.recorder.matched():
                return False
            if self.clock_mode:
                if self.clock_pub.get_subscription_count() == 0:
                    return False
                if self.node.count_publishers(f"{self.ns}/clutch_state") == 0:
                    return False
            return True

        if not self._spin_until(ready, self.discovery_timeout_s):
            what = "its inputs" if not self.clock_mode else "its inputs, /clock and clutch_state"
            if self.recorder is not None:
                what += " and its outputs for recording"
            raise PlayError(f"no clutch_sim node found in namespace {self.ns or '/'} ({what} not "
                            f"matched within {self.discovery_timeout_s:g} s)"
                            + ("; lock-step needs the node with use_sim_time:=true" if self.clock_mode else ""))
        self._spin_until(lambda: False, 0.3)  # let the other side match our endpoints too

    def reset_node(self, timeout_s: float = 30.0, attempt_s: float = 2.0) -> bool:
        """Reset the node's plant (its ~/reset service) before a bag. A reset is idempotent, so
        a request whose response has not come within ``attempt_s`` is sent again until
        ``timeout_s``: ``wait_for_service`` matches the request's endpoints only, and a response
        sent before the server has matched this client's response reader is lost (a lock-step
        test on a loaded machine waited 5 s for one and failed)."""
        if not self._reset_client.wait_for_service(timeout_sec=min(timeout_s, 2.0)):
            if self.clock_mode:
                raise PlayError(f"service {self.ns}/{NODE_NAME}/reset not available")
            self.node.get_logger().warning("no ~/reset service: the node is not reset before the bag")
            return False
        deadline = time.monotonic() + timeout_s
        while True:
            future = self._reset_client.call_async(self._Trigger.Request())
            left = deadline - time.monotonic()
            if self._spin_until(future.done, max(min(attempt_s, left), 0.0)):
                if not future.result().success:
                    raise PlayError(f"{self.ns}/{NODE_NAME}/reset failed: {future.result().message}")
                return True
            self._reset_client.remove_pending_request(future)
            if time.monotonic() >= deadline:
                raise PlayError(f"{self.ns}/{NODE_NAME}/reset did not answer within {timeout_s:g} s")

    def _temperature(self, value: float, stamp_ns: int, frame_id: str = "", variance: float = 0.0):
        msg = self._Temperature()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
        msg.header.frame_id = frame_id
        msg.temperature = float(value)
        msg.variance = float(variance)
        return msg

    # ---- lock-step ---------------------------------------------------------------------
    def play_lockstep(self, path, topics=None, bar=None) -> BagResult:
        run = read_run(path, topics)
        t_ns = row_times_ns(run)
        n = len(run)
        torque, pack = np.full(n, np.nan), np.full(n, np.nan)
        result = BagResult(name=run.name, rows=n, t_ns=t_ns, torque_nm=torque, pack_temperature_c=pack,
                           torque_measured_nm=run.torque_measured_nm, run=run)
        if self.reset_each_bag:
            self.reset_node()
        F, Clock = self._Float64, self._Clock
        pf, pw, ps = (self.pubs[k] for k in ("applied_force", "slip_speed", "sump_temperature"))
        force_msg, slip_msg, clock_msg = F(), F(), Clock()
        for k in range(n):
            f = float(run.applied_force_n[k])
            w = float(run.slip_speed_rad_s[k])
            s = float(run.sump_temperature_c[k])
            t = int(t_ns[k])
            force_msg.data, slip_msg.data = f, w
            sump_msg = self._temperature(s, t)
            clock_msg.clock.sec, clock_msg.clock.nanosec = divmod(t, 1_000_000_000)
            torque_before = self.recorder.counts[f"{self.ns}/clutch_torque"] if self.recorder is not None else 0
            self._awaiting, self._answers = t, 0
            for attempt in range(self.max_attempts):
                self._answer = None
                pf.publish(force_msg)
                pw.publish(slip_msg)
                ps.publish(sump_msg)
                self._sim_now_ns = t
                if self.recorder is not None:
                    self.recorder.open_gate()     # the data starts at the first /clock
                self.clock_pub.publish(clock_msg)
                timeout = self.ack_timeout_s * (1 if attempt < 3 else 3)
                ok = self._spin_until(lambda: self._answer is not None, timeout)
                a = self._answer
                if ok and a.applied_force == f and a.slip_speed == w and a.sump_temperature == s:
                    break
                self._retries += 1
            else:
                raise PlayError(
                    f"bag {run.name}: no matching clutch_state from {self.ns}/{NODE_NAME} for clock "
                    f"{t * 1e-9:.6f} s after {self.max_attempts} attempts (is the node running with "
                    "use_sim_time:=true and publish_every:=1 in this namespace?)")
            if attempt > 0:
                self._drain(attempt + 1)
            torque[k] = a.clutch_torque
            pack[k] = a.pack_temperature
            self._awaiting = None
            if self.recorder is not None:  # the other outputs of this step, before the next clock
                self._flush_recorder(t, torque_before)
            if bar is not None:
                bar.update(1)
        return result

    def _drain(self, sent: int) -> None:
        """After a retried step: wait until every /clock sent for it has been answered (or
        ``drain_timeout_s``: a /clock message lost on the way). A /clock that was only late,
        not lost, would otherwise reach the node after the next step's inputs and recompute
        this step with them -- the plant would then advance with the wrong held inputs. /clock
        messages of one publisher arrive in order and the node answers each one it takes, so
        once ``sent`` answers are in, none of this step's clocks is still on its way."""
        self._spin_until(lambda: self._answers >= sent, self.drain_timeout_s)

    def _flush_recorder(self, t_ns: int, torque_before: int, timeout_s: float = 30.0) -> None:
        """Wait until the recorder has taken this step's outputs (clutch_state and
        pack_temperature stamped t_ns, one more clutch_torque), so they are logged at this
        step's time before the next /clock. They are reliable and already answered for by
        clutch_state, so the wait ends at once unless the machine is very busy."""
        rec = self.recorder
        state, temp, torque = (f"{self.ns}/{n}" for n in ("clutch_state", "pack_temperature", "clutch_torque"))
        self._spin_until(lambda: (rec.last_stamp.get(state) == t_ns and rec.last_stamp.get(temp) == t_ns
                                  and rec.counts[torque] > torque_before), timeout_s)

    # ---- real time ---------------------------------------------------------------------
    def play_realtime(self, path, topics=None, bar=None) -> BagResult:
        bag = read_messages(path, topics)
        if self.reset_each_bag:
            self.reset_node()
        F = self._Float64
        msgs = bag.messages
        t0_bag = msgs[0].t_ns
        t0_wall = time.monotonic()
        for m in msgs:
            due = t0_wall + (m.t_ns - t0_bag) * 1e-9 / self.rate
            while True:
                left = due - time.monotonic()
                if left <= 0.0:
                    break
                if left > 0.002:
                    self.spin_once(left - 0.001)
                elif left > 0.0004:
                    time.sleep(left - 0.0003)
            if self.recorder is not None:
                self.recorder.open_gate()         # the data starts with the first input sent
            if m.topic == "sump_temperature":
                self.pubs["sump_temperature"].publish(self._temperature(m.value, m.stamp_ns, m.frame_id, m.variance))
            else:
                self.pubs[m.topic].publish(F(data=m.value))
            if bar is not None:
                bar.update(1)
        return BagResult(name=bag.name, rows=len(msgs))

    # ---- both --------------------------------------------------------------------------
    def play(self, paths, topics=None) -> PlayResult:
        """Play the bags in log-time order (``topics``: clutch_model.formats.bag_reader.TopicNames of the
        bags' input topics, default /clutch/...)."""
        from tqdm import tqdm

        self._retries = 0
        self._step_count = 0
        paths = [Path(p) for p in paths]
        if not paths:
            raise DataError("no bags given")
        ordered = sorted(((bag_start_ns(p), p) for p in paths), key=lambda x: x[0])
        self.wait_for_node()
        out = PlayResult()
        start = time.monotonic()
        with tqdm(desc="play" + (" --clock" if self.clock_mode else ""), unit="row" if self.clock_mode else "msg",
                  disable=None if self.progress else True, leave=False) as bar:
            for _, path in ordered:
                res = self.play_lockstep(path, topics, bar) if self.clock_mode else self.play_realtime(path, topics, bar)
                out.bags.append(res)
                out.messages += res.rows
        out.retries = self._retries
        out.wall_s = time.monotonic() - start
        return out


def play(paths, namespace: str = "/clutch", *, clock: bool = False, rate: float = 1.0, record_out=None,
         reset: bool = True, topics=None, overwrite: bool = False, progress: bool = True,
         context=None, domain_id: Optional[int] = None, ack_timeout_s: float = 1.0,
         max_attempts: int = 20) -> PlayResult:
    """Play bags into a running node (own rclpy context); optionally record its outputs.
    Lock-step: a step is sent again when the node's answer takes longer than ``ack_timeout_s``
    (three times that from the fourth attempt), at most ``max_attempts`` times."""
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.node import Node

    own = context is None
    stop, noting = [], own and threading.current_thread() is threading.main_thread()
    if noting:
        # SIGINT only noted, and raised where the player spins (Player.spin_once), as record does
        old_handler = signal.signal(signal.SIGINT, lambda signum, frame: stop.append(signum))
    if own:
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain_id)   # an own context: rclpy installs no handler
    node = Node("clutch_sim_play", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    recorder = None
    try:
        player = Player(node, executor, namespace, clock=clock, rate=rate, reset=reset, progress=progress,
                        ack_timeout_s=ack_timeout_s, max_attempts=max_attempts, stop_requested=lambda: bool(stop))
        if record_out is not None:
            from clutch_sim_ros.record import Recorder

            log_time = (lambda: player.sim_now_ns) if clock else (lambda: time.time_ns())
            recorder = Recorder(node, record_out, namespace, log_time=log_time, overwrite=overwrite, gated=True,
                                lockstep=bool(clock))
            player.recorder = recorder
        try:
            result = player.play(paths, topics)
        except (KeyboardInterrupt, ExternalShutdownException):
            raise KeyboardInterrupt from None
        if recorder is not None and not clock:  # the tail: outputs still in flight
            end = time.monotonic() + 0.6
            while time.monotonic() < end:
                player.spin_once(0.05)
        return result
    finally:
        if recorder is not None:
            recorder.close()
        executor.shutdown()
        node.destroy_node()
        if own:
            context.try_shutdown()
        if noting:   # None: a handler not set from Python, which cannot be put back
            signal.signal(signal.SIGINT, signal.SIG_DFL if old_handler is None else old_handler)
