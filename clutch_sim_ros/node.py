"""The clutch_sim node: the wet-clutch plant (clutch_model.Plant) stepped in real time or in
lock-step with /clock.

    clutch-sim-node --ros-args -r __ns:=/clutch --params-file config/clutch_sim.yaml
    python -m clutch_sim_ros.node --ros-args -p use_sim_time:=true

Topics (relative names, so a namespace or remap places them; see docs/node.md):
  in   applied_force (std_msgs/Float64, N), slip_speed (std_msgs/Float64, rad/s),
       sump_temperature (sensor_msgs/Temperature, C)
  out  clutch_torque (std_msgs/Float64, N m), pack_temperature (sensor_msgs/Temperature, C),
       clutch_state (clutch_msgs/ClutchState, stamped, SI), /diagnostics (2 Hz)
  srv  ~/reset (std_srvs/Trigger)
  sim time only: /clock (rosgraph_msgs/Clock) drives the steps.
  slip_source driveline (closed loop, clutch_sim_ros.driveline_io): slip_speed is not
       subscribed; in torque_a, torque_b (std_msgs/Float64, N m); out slip_speed, speed_a,
       speed_b (std_msgs/Float64, rad/s); clutch_torque = transmitted torque (the lock torque
       while locked). The plant starts once applied_force and sump_temperature have arrived.

QoS.
- Inputs: sensor-data QoS, latest value only (best effort, keep last 1, volatile). They are
  sampled signals the node holds until the next sample, so only the newest value matters: a
  lost sample is superseded by the next one; best effort never makes the sender block or
  retransmit; a flooding publisher cannot build a backlog (a newer sample overwrites the older
  one in the middleware); and a best-effort subscription matches both best-effort and reliable
  publishers. Each input has an ordinary subscription whose callback only validates the value
  and stores it (latest-value store, clutch_model.plant.inputs.InputChannel); the tick reads
  the store. The callbacks share the step's mutually exclusive callback group, so a tick never
  sees a half-applied input.
- Outputs: reliable, keep last 1000 (1 s at 1 kHz), volatile. A recorder or controller that
  asks for reliable gets every sample even when it lags by up to a second; best-effort
  subscribers still match.
- /clock: best effort (keep last 10), so it matches every clock source (rosbag2 and simulators
  publish /clock best effort).

Executor: rclpy's SingleThreadedExecutor (``--executor multi`` for a MultiThreadedExecutor;
measured slower under the GIL, bench/bench_node.py).

Timing. Wall-clock mode (use_sim_time false): a steady-clock timer at rate_hz. Each tick first
advances the plant by the time elapsed since the previous tick (steady clock; 1/rate_hz when on
time, more when the tick is late or ticks were missed -- the kernels sub-step long steps) with
the previous inputs held, then samples it with the latest inputs and publishes. So plant time
keeps wall time whatever the load; lateness, missed ticks and stalls (a gap > 0.1 s, WARN) are
reported on /diagnostics. Stamps are plant time: the system clock at the plant's start plus the
steady time since (re-anchored when the system clock drifts > 1 ms), so stamp differences are
exactly the plant's steps. Sim-time mode (use_sim_time true): one step per /clock message;
when the clock advances from t_prev to t the plant is advanced by t - t_prev with the previous
inputs held, then sampled with the latest inputs and published stamped t, so the outputs at
t_k come from the state at t_k and the inputs at t_k, exactly as offline replay. Inputs that
arrived before a /clock message are applied before its step (their callbacks come first in the
executor's order). A repeated /clock time recomputes that step from the state before it with
the latest inputs (idempotent; used by `clutch-sim play --clock` to retry); a clock that goes
backwards restarts the plant. Changing use_sim_time at runtime switches between the two (the
plant state is kept; the first tick in the new time base samples without advancing).

Start-up and inputs. Until the first valid sample of every input has arrived the plant is held
at its initial state and nothing is published. The first tick with all inputs starts the plant
(film at initial.film_thickness, pack at the sump temperature, pack force = applied force,
energy 0). Invalid input messages (input validity rules of clutch_model.plant.inputs) are
rejected, counted on /diagnostics and the last good value is held; a negative force is valid
(the model counts it as 0). An input without a valid message for input_timeout_s is stale
(diagnostics WARN, ERROR after 10 x): a stale applied force is treated as 0 N, which opens the
clutch -- the safe state of a limited-slip differential -- while the stale slip speed and sump
temperature are held. In sim-time mode freshness is measured in sim time.

Outputs. clutch_state carries the inputs the plant used (applied_force is 0 while the force is
stale), the plant record of clutch_model.plant.kernels (hydrodynamic_torque includes the drag
torque of the drag_torque mechanism, so asperity + hydrodynamic = clutch_torque); stamped
outputs carry header.frame_id = the frame_id parameter.

Parameters (clutch_sim_ros.params): each applies at runtime or the change is refused with a
reason; floats accept integers; ranges are in the descriptors.

Robustness. Every published float is checked; a non-finite output is not published, the plant
restarts at the next tick and the event is counted. Exceptions in a callback are counted and
logged (throttled), never raised into the executor.
"""
from __future__ import annotations

import gc
import math
import signal
import sys
import time
from typing import Optional

if __name__ == "__main__":  # run as a program: a signal during the imports below exits cleanly too
    signal.signal(signal.SIGINT, lambda *_: sys.exit(0))
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))

import numpy as np
import rclpy
from builtin_interfaces.msg import Time as TimeMsg
from clutch_msgs.msg import ClutchState
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import Temperature
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from clutch_model import Plant, load_model
from clutch_model.plant import kernels as K
from clutch_model.plant.inputs import INPUT_TOPICS, InputChannel

from clutch_sim_ros import diagnostics as D
from clutch_sim_ros import driveline_io as DIO
from clutch_sim_ros import params as P


EXAMPLE = ("clutch-sim-node --ros-args -r __ns:=/clutch --params-file config/clutch_sim.yaml "
           "-p rate_hz:=500 -p frame_id:=clutch_rear")
TOPICS_HELP = """topics (relative: a namespace or remap places them):
  in   applied_force     std_msgs/msg/Float64          actuator force on the pack, N
  in   slip_speed        std_msgs/msg/Float64          slip speed, rad/s
  in   sump_temperature  sensor_msgs/msg/Temperature   sump oil temperature, C
  out  clutch_torque     std_msgs/msg/Float64          transmitted torque, N m
  out  pack_temperature  sensor_msgs/msg/Temperature   clutch pack temperature, C
  out  clutch_state      clutch_msgs/msg/ClutchState   stamped full state (SI)
  out  /diagnostics      diagnostic_msgs/msg/DiagnosticArray  (2 Hz: inputs, timing, plant)
  srv  ~/reset           std_srvs/srv/Trigger          restart the plant state
  in   /clock            rosgraph_msgs/msg/Clock       (use_sim_time:=true) one step per message
with slip_source:=driveline (closed loop: slip_speed is an output, not subscribed):
  in   torque_a, torque_b        std_msgs/msg/Float64  external torques on sides a, b, N m
  out  slip_speed, speed_a, speed_b  std_msgs/msg/Float64  w_a - w_b, w_a, w_b, rad/s
QoS: inputs best effort keep-last 1; outputs reliable keep-last 1000; /clock best effort."""

NODE_NAME = "clutch_sim"
DIAGNOSTICS_PERIOD_S = 0.5
STAMP_DRIFT_NS = 1_000_000      # re-anchor wall-mode stamps when the system clock drifts more
INPUT_QOS = QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST,
                       depth=1, durability=DurabilityPolicy.VOLATILE)
OUTPUT_QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                        depth=1000, durability=DurabilityPolicy.VOLATILE)
CLOCK_QOS = QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST,
                       depth=10, durability=DurabilityPolicy.VOLATILE)


def _clock_offset_ns(with_error: bool = False):
    """System clock minus steady clock, read back to back (the best of three reads); with
    ``with_error`` also the read's uncertainty in ns (a preempted read is uncertain)."""
    best = None
    for _ in range(3):
        m0 = time.monotonic_ns()
        wall = time.time_ns()
        m1 = time.monotonic_ns()
        if best is None or m1 - m0 < best[0]:
            best = (m1 - m0, wall - (m0 + m1) // 2)
    return (best[1], best[0]) if with_error else best[1]


def _time_msg(ns: int) -> TimeMsg:
    return TimeMsg(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _load(path: str, lock_slip: float):
    return load_model(path or None).with_lock_slip(lock_slip)


class ClutchSimNode(Node):
    """Virtual wet clutch: input topics -> clutch_model.Plant -> output topics."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self.params = P.declare(self)
        model = _load(self.params.clutch_params_file, self.params.lock_slip_rad_s)
        self.model = model
        self.max_pack_force_n = float(model.max_pack_force_n)
        self._plant = Plant(model)
        self._pending_model = None       # (model, restart) swapped in by the next tick
        self._loaded_file_model = None   # validated by the on-set callback

        self.inputs = {name: InputChannel(name) for name in INPUT_TOPICS}
        self._force, self._slip, self._sump = (self.inputs[n] for n in INPUT_TOPICS)
        self._running = False          # plant started (all inputs seen since start/reset)
        self._ever_started = False
        self._last_record: Optional[np.ndarray] = None
        self._tick_index = 0           # ticks since the plant (re)started
        self._t_prev_ns: Optional[int] = None   # time of the previous step (steady or sim)
        self._t_start_ns: Optional[int] = None
        self._rebase = False           # time base changed: restamp the held inputs
        self._last_step_reset = True
        self._snapshot = np.zeros_like(self._plant.state)
        self._now_tick_ns: Optional[int] = None    # time base of input freshness
        self._stamp_offset_ns = _clock_offset_ns()

        self.counters = D.Counters()
        self.timing = D.Timing()
        self._prev_next_call_ns: Optional[int] = None
        self._prev_tick_start_ns: Optional[int] = None
        self._diag_last = (time.monotonic_ns(), time.process_time(), 0)
        self._rejected_reported: dict = {}
        self._last_error_log = 0.0

        # messages are allocated once and refilled each tick
        self._torque_msg = Float64()
        self._temp_msg = Temperature()
        self._state_msg = ClutchState()

        # inputs and the step share one mutually exclusive group: with a MultiThreadedExecutor
        # a tick never runs while an input is half applied, and diagnostics/services never
        # wait for a step (with the SingleThreadedExecutor groups change nothing)
        self._step_group = MutuallyExclusiveCallbackGroup()
        self.create_subscription(Float64, "applied_force", self._on_force, INPUT_QOS,
                                 callback_group=self._step_group)
        self._slip_sub = None          # slip_source topic: the slip_speed input
        self._dl: Optional[DIO.DrivelineSource] = None      # slip_source driveline: plant + torques
        self._dl_topics: Optional[DIO.DrivelineTopics] = None
        self._pending_source: Optional[str] = None          # slip_source change, applied by a tick
        self._pending_driveline = False                     # driveline.* change, applied by a tick
        self._set_slip_source(self.params.slip_source)
        self.create_subscription(Temperature, "sump_temperature", self._on_sump, INPUT_QOS,
                                 callback_group=self._step_group)
        self._pub_torque = self.create_publisher(Float64, "clutch_torque", OUTPUT_QOS)
        self._pub_temp = self.create_publisher(Temperature, "pack_temperature", OUTPUT_QOS)
        self._pub_state = self.create_publisher(ClutchState, "clutch_state", OUTPUT_QOS)
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", OUTPUT_QOS)
        self.create_service(Trigger, "~/reset", self._on_reset)

        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._step_timer = None
        self._clock_sub = None
        self._sim = None
        self._set_mode(self.params.use_sim_time)
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._on_diagnostics, clock=self._steady)
        self.add_pre_set_parameters_callback(P.as_double)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._on_parameters_set)
        self.get_logger().info(
            f"clutch model {model.source}; {self._mode_text()}, "
            f"publish every {self.params.publish_every}, input timeout {self.params.input_timeout_s:g} s; "
            f"waiting for {', '.join(ch.name for ch in self._required_inputs())}")

    def _mode_text(self) -> str:
        return "sim time: one step per /clock" if self._sim else f"{self.params.rate_hz:g} Hz"

    # ---- slip source (topic: open loop; driveline: closed loop) ---------------------
    def _set_slip_source(self, source: str) -> None:
        """Create the slip_speed input (topic) or the driveline plant, its torque inputs and
        slip/speed outputs (driveline); the plant restarts at the next tick."""
        if source == "driveline":
            if self._slip_sub is not None:
                self.destroy_subscription(self._slip_sub)
                self._slip_sub = None
            if self._dl is None:
                self._dl = DIO.DrivelineSource(self.model, self.params.driveline())
                self._dl_topics = DIO.DrivelineTopics(self, self._dl, INPUT_QOS, OUTPUT_QOS,
                                                      callback_group=self._step_group)
            self.inputs = {ch.name: ch for ch in (self._force, self._sump, *self._dl.torques.channels)}
        else:
            if self._dl_topics is not None:
                self._dl_topics.destroy(self)
            self._dl = self._dl_topics = None
            if self._slip_sub is None:
                self._slip_sub = self.create_subscription(Float64, "slip_speed", self._on_slip, INPUT_QOS,
                                                          callback_group=self._step_group)
            self.inputs = {ch.name: ch for ch in (self._force, self._slip, self._sump)}
        self._snapshot = np.zeros_like(self._plant_state())
        self._running = False
        self._rejected_reported = {}

    def _required_inputs(self) -> tuple:
        """The inputs that must have arrived before the plant starts."""
        if self._dl is not None:
            return self._force, self._sump
        return self._force, self._slip, self._sump

    def _plant_state(self) -> np.ndarray:
        return self._dl.state if self._dl is not None else self._plant.state

    def _sample(self, inputs, now_ns: int):
        """Sample the plant with this tick's inputs -> (record, inputs for clutch_state)."""
        if self._dl is None:
            return self._plant.sample(*inputs), inputs
        record = self._dl.sample(inputs[0], inputs[2], now_ns, self.params.input_timeout_s)
        return record, self._dl.state_inputs(inputs[0], inputs[2], record)

    def _apply_pending_source(self) -> None:
        source, self._pending_source = self._pending_source, None
        if source != ("driveline" if self._dl is not None else "topic"):
            self._set_slip_source(source)
            self.get_logger().info(f"slip_source changed: now {source}; plant restarts")

    # ---- stepping mode -------------------------------------------------------------
    def _set_mode(self, sim: bool) -> None:
        """Step on /clock (sim) or on the steady wall-clock timer; keeps the plant state."""
        if sim == self._sim:
            return
        if sim:
            if self._step_timer is not None:
                self.destroy_timer(self._step_timer)
                self._step_timer = None
            self._clock_sub = self.create_subscription(ClockMsg, "/clock", self._on_clock, CLOCK_QOS,
                                                       callback_group=self._step_group)
        else:
            if self._clock_sub is not None:
                self.destroy_subscription(self._clock_sub)
                self._clock_sub = None
            self._step_timer = self.create_timer(self.params.period_s, self._on_timer, clock=self._steady,
                                                 callback_group=self._step_group)
        changed = self._sim is not None
        self._sim = sim
        self._t_prev_ns = None            # the next tick continues without advancing
        self._prev_next_call_ns = self._prev_tick_start_ns = None
        self._rebase = changed
        if changed:
            self.get_logger().info(f"use_sim_time changed: now {self._mode_text()}")

    # ---- parameters ----------------------------------------------------------------
    def _on_set_parameters(self, parameters) -> SetParametersResult:
        for p in parameters:
            reason = P.check_change(p.name, p.value)
            if reason is None and p.name == "clutch_params_file":
                try:
                    self._loaded_file_model = load_model(p.value or None)
                except Exception as exc:  # a bad file is refused, the running model stays
                    reason = f"clutch_params_file refused: {exc}"
            if reason is not None:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _on_parameters_set(self, parameters) -> None:
        try:
            for p in parameters:
                if p.name not in P.SPEC_BY_NAME:
                    continue
                self.params = self.params.with_value(p.name, p.value)
                if p.name == "rate_hz" and self._step_timer is not None:
                    self._step_timer.timer_period_ns = int(round(1e9 / self.params.rate_hz))
                    self._prev_next_call_ns = None
                elif p.name == "clutch_params_file" and self._loaded_file_model is not None:
                    base = self._loaded_file_model
                    self._pending_model = (base.with_lock_slip(self.params.lock_slip_rad_s), True)
                    self._loaded_file_model = None
                elif p.name == "lock_slip_rad_s":
                    base, restart = self._pending_model or (self.model, False)
                    self._pending_model = (base.with_lock_slip(self.params.lock_slip_rad_s), restart)
                elif p.name == "use_sim_time":
                    self._set_mode(bool(p.value))
                elif p.name == "slip_source":
                    self._pending_source = p.value        # the next tick switches (step group)
                elif p.name.startswith("driveline."):
                    self._pending_driveline = True
                self.get_logger().info(f"parameter {p.name} = {p.value!r} applied")
        except Exception as exc:
            self._callback_error(exc)

    def _swap_model(self, inputs) -> None:
        """Apply a model change between ticks (after the advance with the old model)."""
        model, restart = self._pending_model
        self._pending_model = None
        state = self._plant.state.copy()
        self._plant = Plant(model)
        self.model = model
        self.max_pack_force_n = float(model.max_pack_force_n)
        if self._dl is not None:
            self._dl.set_model(model)            # state kept (restarted below if asked)
        if restart:
            self._start(inputs)
        else:
            self._plant.state[:] = state
        self.get_logger().info(f"clutch model {model.source}, lock slip {model.lock_slip_rad_s:g} rad/s"
                               + (": plant restarted" if restart else ""))

    # ---- inputs --------------------------------------------------------------------
    def _on_force(self, msg, info) -> None:
        self._force.offer(msg.data, info.get("received_timestamp", 0))

    def _on_slip(self, msg, info) -> None:
        self._slip.offer(msg.data, info.get("received_timestamp", 0))

    def _on_sump(self, msg, info) -> None:
        self._sump.offer(msg.temperature, info.get("received_timestamp", 0))

    # ---- stepping ------------------------------------------------------------------
    def _held_inputs(self, now_ns: int) -> Optional[tuple[float, float, float]]:
        """The inputs for this tick (None until every input has arrived); stale force -> 0."""
        if self._pending_source is not None:
            self._apply_pending_source()
        f, w, s = self._force, self._slip, self._sump
        if self._dl is not None:
            return self._held_driveline_inputs(now_ns)
        if self._rebase:
            for ch in (f, w, s):
                ch.rebase(now_ns)
            self._rebase = False
        f.on_tick(now_ns)
        w.on_tick(now_ns)
        s.on_tick(now_ns)
        self._now_tick_ns = now_ns
        if f.value is None or w.value is None or s.value is None:
            return None
        force = 0.0 if f.is_stale(now_ns, self.params.input_timeout_s) else f.value
        return force, w.value, s.value

    def _held_driveline_inputs(self, now_ns: int) -> Optional[tuple[float, float, float]]:
        """Driveline mode: force and sump (slip is the plant's; the torques are taken by the
        sample); (force, 0.0, sump) once both have arrived."""
        f, s = self._force, self._sump
        if self._rebase:
            for ch in self.inputs.values():
                ch.rebase(now_ns)
            self._rebase = False
        f.on_tick(now_ns)
        s.on_tick(now_ns)
        self._now_tick_ns = now_ns
        if not self._dl.ready(f.value, s.value):
            return None
        force = 0.0 if f.is_stale(now_ns, self.params.input_timeout_s) else f.value
        return force, 0.0, s.value

    def _step_to(self, t_ns: int, inputs) -> None:
        """Bring the plant to time t_ns (the tick's time base) with the previous inputs held."""
        plant = self._dl if self._dl is not None else self._plant
        if not self._running:
            self._start(inputs)
            self._t_start_ns = t_ns
        elif self._t_prev_ns is None:                 # first tick in a new time base
            self._snapshot[:] = plant.state
            self._t_start_ns = t_ns - int(self.timing.plant_time_s * 1e9)
        elif t_ns > self._t_prev_ns:
            dt = (t_ns - self._t_prev_ns) * 1e-9
            self._t_prev_ns = t_ns                    # an error below never repeats a long step
            plant.advance(dt)
            self.timing.plant_time_s += dt
            self._last_step_reset = False
            self._snapshot[:] = plant.state
        elif t_ns == self._t_prev_ns:                 # repeated time: recompute this step
            self.counters.redone_steps += 1
            self._tick_index -= 1
            if self._last_step_reset:
                self._start(inputs)
            else:
                plant.state[:] = self._snapshot
        else:                                         # clock went backwards: restart
            self.counters.clock_jumps_back += 1
            self._start(inputs)
            self._t_start_ns = t_ns
        self._t_prev_ns = t_ns
        if self._t_start_ns is not None:
            self.timing.wall_time_s = (t_ns - self._t_start_ns) * 1e-9
        if self._pending_model is not None:
            self._swap_model(inputs)
        if self._pending_driveline:
            self._pending_driveline = False
            if self._dl is not None:   # new inertias/losses from this step, speeds kept
                self._dl.set_driveline(self.params.driveline())

    def _on_timer(self) -> None:
        """Wall-clock tick: advance by the elapsed time -> sample -> publish."""
        t0 = time.monotonic_ns()
        try:
            self._timer_bookkeeping(t0)
            inputs = self._held_inputs(t0)
            if inputs is None:
                return
            s0 = time.perf_counter_ns()
            started = not self._running
            self._step_to(t0, inputs)
            if started or self._t_start_ns == t0:
                self._stamp_offset_ns = _clock_offset_ns()
            record, used = self._sample(inputs, t0)
            self.timing.step_ms.add((time.perf_counter_ns() - s0) * 1e-6)
            self._publish(record, used, self._stamp_offset_ns + t0)
        except Exception as exc:  # never raise into the executor
            self._callback_error(exc)
        finally:
            dur = time.monotonic_ns() - t0
            self.timing.tick_ms.add(dur * 1e-6)
            if self._step_timer is not None and dur > self._step_timer.timer_period_ns:
                self.counters.overruns += 1

    def _timer_bookkeeping(self, t0: int) -> None:
        c = self.counters
        c.ticks += 1
        period_ns = self._step_timer.timer_period_ns
        next_call = t0 + self._step_timer.time_until_next_call()
        if self._prev_next_call_ns is not None:
            scheduled = self._prev_next_call_ns
            lateness = t0 - scheduled
            self.timing.lateness_ms.add(lateness * 1e-6)
            if lateness >= period_ns:
                c.late_ticks += 1
            missed = int(round((next_call - scheduled) / period_ns)) - 1
            if missed > 0:
                c.missed_ticks += missed
        if self._prev_tick_start_ns is not None:
            gap_ms = (t0 - self._prev_tick_start_ns) * 1e-6
            self.timing.period_ms.add(gap_ms)
            if gap_ms > D.STALL_S * 1e3:
                c.stalls += 1
                self._throttled_error(f"stall: {gap_ms:.0f} ms between ticks (plant advanced by it)")
            if gap_ms > self.timing.longest_gap_ms:
                self.timing.longest_gap_ms = gap_ms
        self._prev_next_call_ns = next_call
        self._prev_tick_start_ns = t0

    def _on_clock(self, msg) -> None:
        """Sim-time step: advance by the clock increment, then sample and publish at t."""
        t0 = time.monotonic_ns()
        try:
            t_ns = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
            inputs = self._held_inputs(t_ns)
            if inputs is None:
                return
            self.counters.ticks += 1
            s0 = time.perf_counter_ns()
            self._step_to(t_ns, inputs)
            record, used = self._sample(inputs, t_ns)
            self.timing.step_ms.add((time.perf_counter_ns() - s0) * 1e-6)
            self._publish(record, used, t_ns)
        except Exception as exc:
            self._callback_error(exc)
        finally:
            self.timing.tick_ms.add((time.monotonic_ns() - t0) * 1e-6)

    def _start(self, inputs: tuple[float, float, float]) -> None:
        """(Re)start the plant from the current inputs: initial film, pack at the sump, energy 0."""
        if self._dl is not None:
            if self._pending_driveline:   # new initial speeds count at this start
                self._pending_driveline = False
                self._dl.set_driveline(self.params.driveline())
            self._dl.reset(inputs[0], inputs[2])
        else:
            self._plant.reset(inputs[0], inputs[2])
        self._snapshot[:] = self._plant_state()
        self._last_step_reset = True
        self._tick_index = 0
        self.timing.plant_time_s = 0.0
        self.timing.wall_time_s = 0.0
        if not self._running:
            self._running = True
            self.get_logger().info("plant started" if self._ever_started else "all inputs received: plant started")
            self._ever_started = True

    def _publish(self, record, inputs: tuple[float, float, float], stamp_ns: int) -> bool:
        """Check and publish one sample; False (plant restarted, nothing published) when the
        record is not finite."""
        values = record.tolist()
        if not all(map(math.isfinite, values)):
            self.counters.nonfinite_resets += 1
            self._running = False      # restart from the latest inputs at the next tick
            self._throttled_error("non-finite plant output: sample dropped, plant restarts")
            return False
        c = self.counters
        self._last_record = record
        if values[K.O_CLAMPED] > 0.5:
            c.clamped_ticks += 1
        if values[K.O_RANGE] > 0.5:
            c.out_of_range_ticks += 1
        index = self._tick_index
        self._tick_index += 1
        if index % self.params.publish_every:
            return True
        stamp = _time_msg(stamp_ns)
        frame = self.params.frame_id
        torque_msg, temp_msg, st = self._torque_msg, self._temp_msg, self._state_msg
        torque_msg.data = values[K.O_TORQUE]
        temp_msg.header.stamp = stamp
        temp_msg.header.frame_id = frame
        temp_msg.temperature = values[K.O_THETA]
        st.header.stamp = stamp
        st.header.frame_id = frame
        st.applied_force, st.slip_speed, st.sump_temperature = inputs
        st.pack_force = values[K.O_FPACK]
        st.clutch_torque = values[K.O_TORQUE]
        st.asperity_torque = values[K.O_TA]
        st.hydrodynamic_torque = values[K.O_TH] + values[K.O_DRAG]
        st.friction_coefficient = values[K.O_MU]
        st.film_thickness = values[K.O_H]
        st.pack_temperature = values[K.O_THETA]
        st.viscosity = values[K.O_VISC]
        st.power = values[K.O_POWER]
        st.energy = values[K.O_ENERGY]
        st.locked = values[K.O_LOCKED] > 0.5
        self._pub_torque.publish(torque_msg)
        self._pub_temp.publish(temp_msg)
        self._pub_state.publish(st)
        if self._dl_topics is not None:
            self._dl_topics.publish(record)
        c.published += 1
        if not self._sim:   # receive (middleware) -> published, system clock
            done = time.time_ns()
            for ch in self.inputs.values():
                if ch.unused:
                    ch.unused = False
                    if ch.rx_ns:
                        self.timing.latency_ms.add((done - ch.rx_ns) * 1e-6)
        return True

    # ---- service -------------------------------------------------------------------
    def _on_reset(self, request, response):
        try:
            self.counters.resets += 1
            if any(ch.value is None for ch in self._required_inputs()):
                response.success = True
                response.message = "plant not started yet (waiting for inputs); nothing to reset"
                return response
            self._running = False   # the next tick restarts it from the latest inputs
            self._t_prev_ns = None
            response.success = True
            response.message = ("plant state restarts at the next tick: film at its initial value, "
                                f"pack at the sump temperature ({self._sump.value:.2f} C), energy 0")
        except Exception as exc:
            self._callback_error(exc)
            response.success = False
            response.message = f"reset failed: {exc}"
        return response

    # ---- diagnostics ---------------------------------------------------------------
    def _on_diagnostics(self) -> None:
        try:
            if not self._sim:   # keep wall-mode stamps on the system clock
                offset, error = _clock_offset_ns(with_error=True)
                drift = offset - self._stamp_offset_ns
                if error < 100_000 and abs(drift) > STAMP_DRIFT_NS:
                    self._stamp_offset_ns += drift
            self._pub_diag.publish(self.diagnostics())
        except Exception as exc:
            self._callback_error(exc)

    def diagnostics(self):
        mono, cpu, ticks = time.monotonic_ns(), time.process_time(), self.counters.ticks
        m0, c0, t0 = self._diag_last
        wall = max((mono - m0) * 1e-9, 1e-9)
        achieved = (ticks - t0) / wall
        cpu_pct = 100.0 * (cpu - c0) / wall
        self._diag_last = (mono, cpu, ticks)
        name, hw = self.get_name(), self.get_fully_qualified_name()
        now_ns = mono if not self._sim else self._now_tick_ns
        statuses = [
            D.inputs_status(name, hw, self.inputs.values(), now_ns, self.params.input_timeout_s,
                            self._rejected_reported),
            D.timing_status(name, hw, self.counters, self.timing, sim_time=self._sim,
                            rate_hz=self.params.rate_hz, achieved_hz=achieved, cpu_pct=cpu_pct),
            D.plant_status(name, hw, self.counters, self._last_record if self._running else None,
                           running=self._running, max_pack_force_n=self.max_pack_force_n),
        ]
        self._rejected_reported = {ch.name: ch.rejected for ch in self.inputs.values()}
        self.counters.mark_reported()
        stamp_ns = self.get_clock().now().nanoseconds
        if stamp_ns <= 0:       # sim time before the first /clock: never stamp 1970
            stamp_ns = time.time_ns()
        return D.array(_time_msg(stamp_ns), statuses)

    # ---- errors --------------------------------------------------------------------
    def _callback_error(self, exc: BaseException) -> None:
        self.counters.callback_errors += 1
        self._throttled_error(f"callback error ({self.counters.callback_errors} so far): "
                              f"{type(exc).__name__}: {exc}")

    def _throttled_error(self, text: str) -> None:
        now = time.monotonic()
        if now - self._last_error_log >= 1.0:
            self._last_error_log = now
            self.get_logger().error(text)



def _make_executor(kind: str):
    if kind == "multi":
        return MultiThreadedExecutor(num_threads=2)
    return SingleThreadedExecutor()


def _one_line(exc: BaseException) -> str:
    """rcl errors span lines and end in ', at ./src/...c:123'; keep the reason."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    for marker in (", at ./src", ", at /"):
        cut = text.find(marker)
        if cut > 0:
            text = text[:cut]
    return text


def _check_ros_args(ros_args: list) -> Optional[str]:
    """Reasons rcl would fail on (and log about on extra lines) checked first: a
    --params-file without a readable file."""
    import os

    for k, arg in enumerate(ros_args):
        if arg == "--params-file":
            path = ros_args[k + 1] if k + 1 < len(ros_args) else None
            if path is None or path.startswith("-"):
                return "--params-file needs a file: --ros-args --params-file FILE.yaml"
            if not os.path.isfile(path):
                return f"parameter file not found: {path}"
    return None


class _ArgParser:
    """argparse with one-line errors (exit 2) and a help listing topics and parameters."""

    @staticmethod
    def build():
        import argparse

        class Parser(argparse.ArgumentParser):
            def error(self, message):
                self.exit(2, f"clutch-sim-node: error: {message}\n")

        parser = Parser(
            prog="clutch-sim-node", formatter_class=argparse.RawDescriptionHelpFormatter,
            usage="clutch-sim-node [--executor single|multi] [--ros-args ...]",
            description="Virtual wet clutch on ROS 2 (node name clutch_sim): steps the clutch model at "
                        "rate_hz in wall-clock time (late ticks made up: plant time keeps wall time), or once "
                        "per /clock message with use_sim_time:=true.",
            epilog=f"{TOPICS_HELP}\n\nparameters (--ros-args -p NAME:=VALUE or --params-file FILE; "
                   f"all settable at runtime):\n{P.help_text()}\n\nexample:\n  {EXAMPLE}\n"
                   "  clutch-sim play --bag BAG --clock --record out.mcap   # lock-step, with "
                   "-p use_sim_time:=true")
        parser.add_argument("--executor", choices=("single", "multi"), default="single",
                            help="rclpy executor (default single)")
        return parser


def main(args=None) -> int:
    """Console entry ``clutch-sim-node``: spin the node until SIGINT/SIGTERM, exit 0.

    ``args``: like sys.argv (program name first). Besides ``--ros-args ...`` it takes
    ``--executor single|multi`` (default single). Exit code 1 with a one-line reason for
    start-up errors (bad arguments, parameter file or value).
    """
    argv = sys.argv if args is None else list(args)
    ros_at = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    opts = _ArgParser.build().parse_args(argv[1:ros_at])   # --help / --executor; exits on errors
    reason = _check_ros_args(argv[ros_at:])
    if reason:
        sys.stderr.write(f"clutch-sim-node: error: {reason}\n")
        return 1
    interrupted = []

    def on_signal(signum, frame):  # SIGINT/SIGTERM: rclpy's handlers chain to this one
        interrupted.append(signum)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    node = None
    code = 0
    try:
        try:
            rclpy.init(args=argv)
            node = ClutchSimNode()
            gc.freeze()   # start-up objects leave the collector's generations: shorter GC pauses
            executor = _make_executor(opts.executor)
            executor.add_node(node)
            executor.spin()
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        except Exception as exc:
            if not interrupted:   # a real start-up error (not a signal mid-call)
                sys.stderr.write(f"clutch-sim-node: error: {_one_line(exc)}\n")
                code = 1
        finally:
            try:
                if node is not None:
                    node.destroy_node()
                rclpy.try_shutdown()
            except Exception:  # e.g. rcl_shutdown already called by rclpy's signal handler thread
                pass
    except KeyboardInterrupt:
        pass
    return code


if __name__ == "__main__":
    sys.exit(main())
