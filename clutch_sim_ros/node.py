"""The clutch_sim node: the wet-clutch plant (clutch_model.Plant) stepped in real time or in
lock-step with /clock.

    clutch-sim-node --ros-args -r __ns:=/clutch --params-file config/clutch_sim.yaml
    python -m clutch_sim_ros.node --ros-args -p use_sim_time:=true

Topics (relative names, so a namespace or remap places them; docs/interfaces.md):
  in   applied_force (std_msgs/Float64, N), slip_speed (std_msgs/Float64, rad/s),
       sump_temperature (sensor_msgs/Temperature, C)
  out  clutch_torque (std_msgs/Float64, N m), pack_temperature (sensor_msgs/Temperature, C),
       clutch_state (clutch_msgs/ClutchState, stamped, SI), /diagnostics (2 Hz, wall clock)
  srv  ~/reset (std_srvs/Trigger)
  sim time only: /clock (rosgraph_msgs/Clock) drives the steps.

QoS.
- Inputs: sensor-data QoS, latest value only (best effort, keep last 1, volatile). They are
  sampled signals the node holds until the next sample, so only the newest value matters: a
  lost sample is superseded by the next one; best effort never makes the sender block or
  retransmit; a flooding publisher cannot build a backlog (a newer sample overwrites the
  older one in the middleware); and a best-effort subscription matches both best-effort and
  reliable publishers. The node polls the inputs once per tick instead of waking the executor
  per message, so an input flood costs at most one take per input and tick (the latency stays
  within one period). Consequence: a message overwritten by a newer one before the next tick
  is never seen, so /diagnostics' received/rejected counts are of the messages the node took.
- Outputs: reliable (keep last 100, volatile). A recorder or controller that asks for
  reliable gets every sample (the history absorbs 100 ms of reader lag at 1 kHz);
  best-effort subscribers still match.
- /clock: best effort (keep last 10), so it matches every clock source (rosbag2 and
  simulators publish /clock best effort).

Executor: rclpy's SingleThreadedExecutor. A MultiThreadedExecutor (step timer in its own
callback group) was measured slower under the GIL (bench/bench_node.py --executor multi).

Timing. Wall-clock mode (use_sim_time false): a steady-clock timer at rate_hz; each tick
samples the plant with the latest inputs held, publishes (every publish_every-th tick) and
then advances the plant by exactly 1/rate_hz. Late ticks are counted, not made up (the
plant then runs slightly behind wall time). Sim-time mode (use_sim_time true): one step per
/clock message; when the clock advances from t_prev to t the plant is advanced by t - t_prev
with the previous inputs held, then sampled with the latest inputs and published stamped t,
so the outputs at t_k come from the state at t_k and the inputs at t_k, exactly as offline
replay. The inputs that arrived before a /clock message are taken (drained) before the step.
A repeated /clock time recomputes that step from the state before it with the latest inputs
(idempotent; used by `clutch-sim play --clock` to retry); a clock that goes backwards
restarts the plant.

Start-up and inputs. Until the first valid sample of every input has arrived the plant is
held at its initial state and nothing is published. The first tick with all inputs starts the
plant (film at initial.film_thickness, pack at the sump temperature, pack force = applied
force, energy 0). Invalid input messages (docs/interfaces.md, "Input validity") are rejected, counted on
/diagnostics and the last good value is held; a negative force is valid (the model counts it
as 0). An input without a valid message for input_timeout_s is stale (diagnostics WARN, ERROR
after 10 x): a stale applied force is treated as 0 N, which opens the clutch -- the safe state
of a limited-slip differential (open differential) -- while the stale slip speed and sump
temperature are held. In sim-time mode freshness is measured in sim time.

Outputs. clutch_state carries the inputs the plant used (applied_force is 0 while the force is
stale), the plant record of clutch_model.plant.kernels (hydrodynamic_torque includes the drag
torque of the drag_torque mechanism, so asperity + hydrodynamic = clutch_torque) and is
stamped with the tick time (wall clock, or the /clock time in sim time).

Robustness. Every published float is checked; a non-finite output is not published, the
plant restarts at the next tick and the event is counted. Exceptions in a callback are
counted and logged (throttled), never raised into the executor.
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
from rclpy.callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup
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

from clutch_sim_ros import diagnostics as D
from clutch_sim_ros import params as P
from clutch_model.plant.inputs import INPUT_TOPICS, InputChannel

NODE_NAME = "clutch_sim"
DIAGNOSTICS_PERIOD_S = 0.5
INPUT_QOS = QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST,
                       depth=1, durability=DurabilityPolicy.VOLATILE)
OUTPUT_QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                        depth=100, durability=DurabilityPolicy.VOLATILE)
CLOCK_QOS = QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST,
                       depth=10, durability=DurabilityPolicy.VOLATILE)
_TAKE_LIMIT = 8     # messages taken per input topic and tick (the history holds 1)


class PolledCallbackGroup(CallbackGroup):
    """Entities the executor neither waits on nor runs: the node takes their messages itself
    (rclpy's executors leave out of the wait set every entity whose group cannot execute)."""

    def can_execute(self, entity) -> bool:
        return False

    def beginning_execution(self, entity) -> bool:
        return False

    def ending_execution(self, entity) -> None:
        pass


def _time_msg(ns: int) -> TimeMsg:
    return TimeMsg(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _data(msg) -> float:
    return msg.data


def _temperature(msg) -> float:
    return msg.temperature


def _unused_callback(msg) -> None:  # polled subscriptions: the executor never calls it
    pass


class ClutchSimNode(Node):
    """Virtual wet clutch: input topics -> clutch_model.Plant -> output topics."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self.params = P.declare(self)
        model = load_model(self.params.clutch_params_file or None).with_lock_slip(
            self.params.lock_slip_rad_s)
        self.model = model
        self.max_pack_force_n = float(model.max_pack_force_n)
        self._plant = Plant(model)
        self._dt_s = self.params.period_s
        self._sim = self.params.use_sim_time

        self.inputs = {name: InputChannel(name) for name in INPUT_TOPICS}
        self._force, self._slip, self._sump = (self.inputs[n] for n in INPUT_TOPICS)
        self._running = False          # plant started (all inputs seen since start/reset)
        self._ever_started = False
        self._last_record: Optional[np.ndarray] = None
        self._tick_index = 0           # ticks since the plant (re)started
        # sim-time step bookkeeping
        self._t_prev_ns: Optional[int] = None
        self._last_step_reset = True
        self._snapshot = np.zeros_like(self._plant.state)
        self._now_tick_ns: Optional[int] = None    # time base of input freshness

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

        polled = PolledCallbackGroup()
        self._input_subs = [
            (self.create_subscription(Float64, "applied_force", _unused_callback, INPUT_QOS,
                                      callback_group=polled), self._force, _data),
            (self.create_subscription(Float64, "slip_speed", _unused_callback, INPUT_QOS,
                                      callback_group=polled), self._slip, _data),
            (self.create_subscription(Temperature, "sump_temperature", _unused_callback, INPUT_QOS,
                                      callback_group=polled), self._sump, _temperature),
        ]
        self._pub_torque = self.create_publisher(Float64, "clutch_torque", OUTPUT_QOS)
        self._pub_temp = self.create_publisher(Temperature, "pack_temperature", OUTPUT_QOS)
        self._pub_state = self.create_publisher(ClutchState, "clutch_state", OUTPUT_QOS)
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", OUTPUT_QOS)
        self.create_service(Trigger, "~/reset", self._on_reset)

        # the step has its own callback group: with a MultiThreadedExecutor it never waits for
        # the diagnostics or a service call (with the SingleThreadedExecutor groups change nothing)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        step_group = MutuallyExclusiveCallbackGroup()
        if self._sim:
            self.create_subscription(ClockMsg, "/clock", self._on_clock, CLOCK_QOS,
                                     callback_group=step_group)
            self._step_timer = None
        else:
            self._step_timer = self.create_timer(self._dt_s, self._on_timer, clock=steady,
                                                 callback_group=step_group)
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._on_diagnostics, clock=steady)
        self.get_logger().info(
            f"clutch model {model.source}; {'sim time: one step per /clock' if self._sim else f'{self.params.rate_hz:g} Hz'}, "
            f"publish every {self.params.publish_every}, input timeout {self.params.input_timeout_s:g} s; "
            f"waiting for {', '.join(self.inputs)}")

    # ---- inputs ------------------------------------------------------------------------
    def _poll_inputs(self) -> None:
        """Take every input message that arrived since the last tick, oldest first (the last
        good one wins). Inputs are polled by the tick instead of waking the executor per
        message: a flooding publisher costs the executor nothing, the inputs a tick uses are
        exactly those that arrived before it (in sim time: before its /clock message), and the
        latency is bounded by one period either way."""
        for sub, channel, value_of in self._input_subs:
            for _ in range(_TAKE_LIMIT):
                with sub.handle:
                    taken = sub.handle.take_message(sub.msg_type, sub.raw)
                if taken is None:
                    break
                channel.offer(value_of(taken[0]), taken[1].get("received_timestamp", 0))

    # ---- stepping ----------------------------------------------------------------------
    def _held_inputs(self, now_ns: int) -> Optional[tuple[float, float, float]]:
        """The inputs for this tick (None until every input has arrived); stale force -> 0."""
        self._poll_inputs()
        f, w, s = self._force, self._slip, self._sump
        f.on_tick(now_ns)
        w.on_tick(now_ns)
        s.on_tick(now_ns)
        self._now_tick_ns = now_ns
        if f.value is None or w.value is None or s.value is None:
            return None
        force = 0.0 if f.is_stale(now_ns, self.params.input_timeout_s) else f.value
        return force, w.value, s.value

    def _on_timer(self) -> None:
        """Wall-clock tick: sample -> publish -> advance(1/rate_hz)."""
        t0 = time.monotonic_ns()
        try:
            self._timer_bookkeeping(t0)
            inputs = self._held_inputs(t0)
            if inputs is None:
                return
            if not self._running:
                self._start(inputs)
            s0 = time.perf_counter_ns()
            record = self._plant.sample(*inputs)
            s1 = time.perf_counter_ns()
            if self._publish(record, inputs, time.time_ns()):
                s2 = time.perf_counter_ns()
                self._plant.advance(self._dt_s)
                self.timing.step_ms.add(((s1 - s0) + (time.perf_counter_ns() - s2)) * 1e-6)
        except Exception as exc:  # never raise into the executor
            self._callback_error(exc)
        finally:
            dur = time.monotonic_ns() - t0
            self.timing.tick_ms.add(dur * 1e-6)
            if dur > self._dt_s * 1e9:
                self.counters.overruns += 1

    def _timer_bookkeeping(self, t0: int) -> None:
        c = self.counters
        c.ticks += 1
        period_ns = self._dt_s * 1e9
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
            self.timing.period_ms.add((t0 - self._prev_tick_start_ns) * 1e-6)
        self._prev_next_call_ns = next_call
        self._prev_tick_start_ns = t0

    def _on_clock(self, msg: ClockMsg) -> None:
        """Sim-time step: advance by the clock increment, then sample and publish at t."""
        t0 = time.monotonic_ns()
        try:
            t_ns = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
            inputs = self._held_inputs(t_ns)
            if inputs is None:
                return
            self.counters.ticks += 1
            plant = self._plant
            s0 = time.perf_counter_ns()
            if not self._running or self._t_prev_ns is None:
                self._start(inputs)
            elif t_ns > self._t_prev_ns:
                plant.advance((t_ns - self._t_prev_ns) * 1e-9)
                self._last_step_reset = False
                self._snapshot[:] = plant.state
            elif t_ns == self._t_prev_ns:        # repeated time: recompute this step
                self.counters.redone_steps += 1
                self._tick_index -= 1
                if self._last_step_reset:
                    self._start(inputs)
                else:
                    plant.state[:] = self._snapshot
            else:                                # clock went backwards: restart
                self.counters.clock_jumps_back += 1
                self._start(inputs)
            self._t_prev_ns = t_ns
            record = plant.sample(*inputs)
            self.timing.step_ms.add((time.perf_counter_ns() - s0) * 1e-6)
            self._publish(record, inputs, t_ns)
        except Exception as exc:
            self._callback_error(exc)
        finally:
            self.timing.tick_ms.add((time.monotonic_ns() - t0) * 1e-6)

    def _start(self, inputs: tuple[float, float, float]) -> None:
        """(Re)start the plant from the current inputs: initial film, pack at the sump, energy 0."""
        self._plant.reset(inputs[0], inputs[2])
        self._snapshot[:] = self._plant.state
        self._last_step_reset = True
        self._tick_index = 0
        if not self._running:
            self._running = True
            self.get_logger().info("plant started" if self._ever_started else "all inputs received: plant started")
            self._ever_started = True

    def _publish(self, record: np.ndarray, inputs: tuple[float, float, float], stamp_ns: int) -> bool:
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
        torque_msg, temp_msg, st = self._torque_msg, self._temp_msg, self._state_msg
        torque_msg.data = values[K.O_TORQUE]
        temp_msg.header.stamp = stamp
        temp_msg.temperature = values[K.O_THETA]
        st.header.stamp = stamp
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
        c.published += 1
        if not self._sim:   # receive (middleware) -> published, system clock
            done = time.time_ns()
            for ch in (self._force, self._slip, self._sump):
                if ch.unused:
                    ch.unused = False
                    if ch.rx_ns:
                        self.timing.latency_ms.add((done - ch.rx_ns) * 1e-6)
        return True

    # ---- service -----------------------------------------------------------------------
    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        try:
            self.counters.resets += 1
            if self._force.value is None or self._slip.value is None or self._sump.value is None:
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

    # ---- diagnostics -------------------------------------------------------------------
    def _on_diagnostics(self) -> None:
        try:
            self._pub_diag.publish(self.diagnostics())
        except Exception as exc:
            self._callback_error(exc)

    def diagnostics(self) -> DiagnosticArray:
        mono, cpu, ticks = time.monotonic_ns(), time.process_time(), self.counters.ticks
        m0, c0, t0 = self._diag_last
        wall = max((mono - m0) * 1e-9, 1e-9)
        achieved = (ticks - t0) / wall
        cpu_pct = 100.0 * (cpu - c0) / wall
        self._diag_last = (mono, cpu, ticks)
        name = self.get_fully_qualified_name()
        now_ns = mono if not self._sim else self._now_tick_ns
        statuses = [
            D.inputs_status(name, name, self.inputs.values(), now_ns, self.params.input_timeout_s,
                            self._rejected_reported),
            D.timing_status(name, name, self.counters, self.timing, sim_time=self._sim,
                            rate_hz=self.params.rate_hz, achieved_hz=achieved, cpu_pct=cpu_pct),
            D.plant_status(name, name, self.counters, self._last_record if self._running else None,
                           running=self._running, max_pack_force_n=self.max_pack_force_n),
        ]
        self._rejected_reported = {ch.name: ch.rejected for ch in self.inputs.values()}
        self.counters.mark_reported()
        return D.array(self.get_clock().now().to_msg(), statuses)

    # ---- errors ------------------------------------------------------------------------
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


def main(args=None) -> int:
    """Console entry ``clutch-sim-node``: spin the node until SIGINT/SIGTERM, exit 0.

    ``args``: like sys.argv (program name first). Besides ``--ros-args ...`` it takes
    ``--executor single|multi`` (default single). Exit code 1 with a one-line reason for
    start-up errors (bad parameter file or value).
    """
    import argparse

    from rclpy.utilities import remove_ros_args

    argv = sys.argv if args is None else list(args)
    parser = argparse.ArgumentParser(prog="clutch-sim-node", description="virtual wet clutch node")
    parser.add_argument("--executor", choices=("single", "multi"), default="single")
    opts = parser.parse_args(remove_ros_args(argv)[1:])
    # SIGTERM like SIGINT: rclpy's handlers (installed by init) shut the context down and
    # chain to these, so a signal during start-up also ends in a clean exit
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    node = None
    code = 0
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
        if rclpy.ok():  # a real start-up error; otherwise a signal shut rclpy down mid-call
            sys.stderr.write(f"clutch-sim-node: error: {exc}\n")
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
