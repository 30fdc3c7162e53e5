"""Driveline mode of the clutch_sim node (parameter ``slip_source: driveline``): what the node
needs besides its open-loop path, kept in one module so that node.py only dispatches on the mode.

In driveline mode slip is an output. The node integrates two rotating sides coupled by the
clutch (clutch_model.DrivelinePlant, the same compiled equations as the offline
clutch_model.simulate_driveline), driven by the external torques of the topics ``torque_a`` and
``torque_b`` (std_msgs/Float64, N m, signed; input QoS; held; 0 until they first arrive and
while stale after input_timeout_s). The plant starts once ``applied_force`` and
``sump_temperature`` have arrived (slip_speed is not subscribed); the initial speeds apply then
and after ~/reset. It publishes ``slip_speed`` (= w_a - w_b, exactly 0 while locked),
``speed_a`` and ``speed_b`` (std_msgs/Float64, rad/s, output QoS) besides the usual outputs;
``clutch_torque`` is the transmitted torque and ``clutch_state.locked`` the stick phase.

Pieces:
- ``PARAMETERS``: ``slip_source`` and ``driveline.*`` as (name, default, kind, range,
  description, runtime) rows, the layout of clutch_sim_ros.params' parameter table;
  ``driveline_params(values)`` turns the ``driveline.*`` values into clutch_model's
  DrivelineParams.
- ``TorqueInputs``: the two held torque channels (validity, freshness, stale -> 0).
- ``DrivelineSource``: ROS-free: plant + torque inputs, with the calls of the node's tick
  (``ready``, ``reset``, ``sample``, ``advance``, ``state`` for the sim-time redo snapshot).
- ``DrivelineTopics``: the rclpy subscriptions and publishers of driveline mode.
"""
from __future__ import annotations

import math
from typing import Mapping, Optional

import numpy as np

from clutch_model import DrivelineParams, DrivelinePlant
from clutch_model.plant import driveline as DL
from clutch_model.plant.inputs import InputChannel

SLIP_SOURCES = ("topic", "driveline")
TORQUE_MAX_NM = 1.0e6          # |torque| above it is rejected, like a force above 1 MN
TORQUE_TOPICS = ("torque_a", "torque_b")
OUTPUT_TOPICS = ("slip_speed", "speed_a", "speed_b")

_D = DrivelineParams()
# name, default, kind, range (inclusive), description, what a change at runtime does
PARAMETERS: tuple = (
    ("slip_source", "topic", str, None,
     'where the slip comes from: "topic" (input slip_speed, open loop) or "driveline" (two '
     "inertias coupled by the clutch, driven by torque_a/torque_b; slip_speed is published)",
     "switches the mode; the plant restarts"),
    ("driveline.inertia_a_kgm2", _D.inertia_a_kgm2, float, (1e-6, 1e6),
     "driveline mode: inertia of side a (differential case / input), kg m^2",
     "applies from the next tick (speeds kept)"),
    ("driveline.inertia_b_kgm2", _D.inertia_b_kgm2, float, (1e-6, 1e6),
     "driveline mode: inertia of side b (clutched axle), kg m^2",
     "applies from the next tick (speeds kept)"),
    ("driveline.damping_a_nms", _D.damping_a_nms, float, (0.0, 1e6),
     "driveline mode: viscous loss of side a, N m s/rad", "applies from the next tick"),
    ("driveline.damping_b_nms", _D.damping_b_nms, float, (0.0, 1e6),
     "driveline mode: viscous loss of side b, N m s/rad", "applies from the next tick"),
    ("driveline.initial_speed_a_rad_s", _D.initial_speed_a_rad_s, float, (-1e5, 1e5),
     "driveline mode: speed of side a at start and after ~/reset, rad/s",
     "applies at the next start or ~/reset"),
    ("driveline.initial_speed_b_rad_s", _D.initial_speed_b_rad_s, float, (-1e5, 1e5),
     "driveline mode: speed of side b at start and after ~/reset, rad/s",
     "applies at the next start or ~/reset"),
)
PARAMETER_NAMES = tuple(row[0] for row in PARAMETERS)
DEFAULTS = {row[0]: row[1] for row in PARAMETERS}


def check_value(name: str, value) -> Optional[str]:
    """None when ``value`` is acceptable for ``name`` (one of PARAMETERS), else the reason."""
    row = next((r for r in PARAMETERS if r[0] == name), None)
    if row is None:
        return None
    if name == "slip_source":
        return None if value in SLIP_SOURCES else \
            f"slip_source must be one of {', '.join(SLIP_SOURCES)}, got {value!r}"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return f"{name} must be a number, got {value!r}"
    lo, hi = row[3]
    if not (lo <= value <= hi):
        return f"{name} must be in [{lo:g}, {hi:g}], got {value!r}"
    return None


def driveline_params(values: Mapping[str, object]) -> DrivelineParams:
    """DrivelineParams from ``driveline.*`` parameter values (missing ones: defaults).
    Raises ValueError with a one-line reason for a bad value."""
    out = {}
    for name in PARAMETER_NAMES[1:]:
        value = values.get(name, DEFAULTS[name])
        reason = check_value(name, value)
        if reason:
            raise ValueError(f"parameter {reason}")
        out[name.split(".", 1)[1]] = float(value)
    return DrivelineParams(**out)


def valid_torque(value: float) -> bool:
    return math.isfinite(value) and abs(value) <= TORQUE_MAX_NM


class TorqueInputs:
    """The external torques: held, 0 before the first valid message and while stale."""

    def __init__(self):
        self.torque_a = InputChannel("torque_a", valid_torque)
        self.torque_b = InputChannel("torque_b", valid_torque)

    @property
    def channels(self) -> tuple[InputChannel, InputChannel]:
        return self.torque_a, self.torque_b

    def held(self, now_ns: int, timeout_s: float) -> tuple[float, float]:
        """Stamp this tick's arrivals and return (tau_a, tau_b) for it."""
        out = []
        for ch in self.channels:
            ch.on_tick(now_ns)
            out.append(0.0 if ch.value is None or ch.is_stale(now_ns, timeout_s) else ch.value)
        return out[0], out[1]


class DrivelineSource:
    """Driveline mode without ROS: the plant and its torque inputs, called by the node's tick.

    Tick (wall clock or /clock), with force and sump the node's held inputs:
        if not src.ready(force_value, sump_value): wait        # slip_speed is not needed
        first tick / after ~/reset:  src.reset(force, sump)
        else:                        src.advance(dt)            # previous inputs held
        record = src.sample(force, sump, now_ns, input_timeout_s)
        publish record (src.state_inputs(...) gives the inputs for clutch_state)
    ``state`` is the flat plant state to snapshot/restore for a repeated /clock time.
    """

    def __init__(self, model, driveline: DrivelineParams | None = None):
        self.torques = TorqueInputs()
        self.driveline = driveline or DrivelineParams()
        self.plant = DrivelinePlant(model, self.driveline)
        self.last_torques = (0.0, 0.0)

    @staticmethod
    def ready(force_value: Optional[float], sump_value: Optional[float]) -> bool:
        return force_value is not None and sump_value is not None

    @property
    def state(self) -> np.ndarray:
        return self.plant.state

    def reset(self, applied_force_n: float, sump_temperature_c: float) -> None:
        self.plant.reset(applied_force_n, sump_temperature_c)

    def advance(self, dt: float) -> None:
        self.plant.advance(dt)

    def sample(self, applied_force_n: float, sump_temperature_c: float, now_ns: int,
               input_timeout_s: float) -> np.ndarray:
        self.last_torques = self.torques.held(now_ns, input_timeout_s)
        return self.plant.sample(applied_force_n, *self.last_torques, sump_temperature_c)

    def set_model(self, model) -> None:
        """A new clutch model (parameter change), the state kept."""
        state = self.plant.state.copy()
        self.plant = DrivelinePlant(model, self.driveline)
        self.plant.state[:] = state

    def set_driveline(self, driveline: DrivelineParams) -> None:
        """New inertias/losses from the next step, the state kept (initial speeds: next reset)."""
        state = self.plant.state.copy()
        self.driveline = driveline
        self.plant = DrivelinePlant(self.plant.model, driveline)
        self.plant.state[:] = state

    @staticmethod
    def state_inputs(applied_force_n: float, sump_temperature_c: float, record) -> tuple[float, float, float]:
        """(applied_force, slip_speed, sump_temperature) for clutch_state: the slip is the plant's."""
        return applied_force_n, float(record[DL.R_SLIP]), sump_temperature_c

    @staticmethod
    def outputs(record) -> tuple[float, float, float]:
        """(slip_speed, speed_a, speed_b) of a record."""
        return float(record[DL.R_SLIP]), float(record[DL.R_WA]), float(record[DL.R_WB])


class DrivelineTopics:
    """The rclpy side of driveline mode on ``node``: subscriptions torque_a/torque_b (into
    ``source.torques``) and publishers slip_speed, speed_a, speed_b."""

    def __init__(self, node, source: DrivelineSource, input_qos, output_qos, callback_group=None):
        from std_msgs.msg import Float64

        self._msgs = [Float64(), Float64(), Float64()]
        a, b = source.torques.channels
        self.subscriptions = [
            node.create_subscription(Float64, "torque_a", self._offer(a), input_qos, callback_group=callback_group),
            node.create_subscription(Float64, "torque_b", self._offer(b), input_qos, callback_group=callback_group),
        ]
        self.publishers = [node.create_publisher(Float64, name, output_qos) for name in OUTPUT_TOPICS]

    @staticmethod
    def _offer(channel: InputChannel):
        def callback(msg, info):   # two arguments: rclpy passes the message info
            channel.offer(msg.data, info.get("received_timestamp", 0))
        return callback

    def publish(self, record) -> None:
        for pub, msg, value in zip(self.publishers, self._msgs, DrivelineSource.outputs(record)):
            msg.data = value
            pub.publish(msg)

    def destroy(self, node) -> None:
        for sub in self.subscriptions:
            node.destroy_subscription(sub)
        for pub in self.publishers:
            node.destroy_publisher(pub)
