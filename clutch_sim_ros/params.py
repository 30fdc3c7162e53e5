"""The ROS parameters of the clutch_sim node, declared in one place.

``PARAMETERS`` holds every parameter with its default and descriptor; ``declare(node)``
declares them all and returns the values as a typed ``NodeParams``. ``use_sim_time`` is
rclpy's built-in parameter (declared by rclpy itself) and is only read here.
"""
from __future__ import annotations

from dataclasses import dataclass

from rcl_interfaces.msg import IntegerRange, ParameterDescriptor, ParameterType
from rclpy.node import Node


@dataclass(frozen=True)
class NodeParams:
    rate_hz: float = 1000.0
    publish_every: int = 1
    clutch_params_file: str = ""
    input_timeout_s: float = 0.1
    lock_slip_rad_s: float = 0.001
    use_sim_time: bool = False

    @property
    def period_s(self) -> float:
        return 1.0 / self.rate_hz


_RANGES = {"rate_hz": (1.0, 10000.0), "input_timeout_s": (1e-4, 3600.0), "lock_slip_rad_s": (0.0, 1000.0)}


def _float(desc: str) -> ParameterDescriptor:
    # dynamic typing: a YAML `rate_hz: 1000` (integer) is accepted and converted to float;
    # the range is checked in check() (rclpy skips floating_point_range for integers)
    return ParameterDescriptor(description=desc, read_only=True, dynamic_typing=True)


# name -> (default, descriptor). Read-only: the node reads them once at start-up.
PARAMETERS: dict[str, tuple[object, ParameterDescriptor]] = {
    "rate_hz": (NodeParams.rate_hz, _float(
        "model step and publish tick in wall-clock mode, Hz (dt = 1/rate_hz)")),
    "publish_every": (NodeParams.publish_every, ParameterDescriptor(
        type=ParameterType.PARAMETER_INTEGER, read_only=True,
        description="publish the outputs every N-th tick (the model steps every tick)",
        integer_range=[IntegerRange(from_value=1, to_value=100000, step=1)])),
    "clutch_params_file": (NodeParams.clutch_params_file, ParameterDescriptor(
        type=ParameterType.PARAMETER_STRING, read_only=True,
        description='clutch parameter YAML (schema of config/reference_clutch.yaml); "" = the '
                    "shipped reference clutch RC-1")),
    "input_timeout_s": (NodeParams.input_timeout_s, _float(
        "an input without a message for this long is stale (diagnostics WARN, ERROR after 10x); "
        "a stale applied force counts as 0 N, s")),
    "lock_slip_rad_s": (NodeParams.lock_slip_rad_s, _float(
        "|slip| below this = locked clutch (static torque capacity), rad/s")),
}


def declare(node: Node) -> NodeParams:
    """Declare every parameter of PARAMETERS on ``node`` and return their values."""
    for name, (default, descriptor) in PARAMETERS.items():
        node.declare_parameter(name, default, descriptor)
    values = {name: node.get_parameter(name).value for name in PARAMETERS}
    for name in _RANGES:
        if isinstance(values[name], bool) or not isinstance(values[name], (int, float)):
            raise ValueError(f"parameter {name} must be a number, got {values[name]!r}")
    use_sim_time = bool(node.get_parameter("use_sim_time").value)
    params = NodeParams(
        rate_hz=float(values["rate_hz"]), publish_every=int(values["publish_every"]),
        clutch_params_file=str(values["clutch_params_file"] or ""),
        input_timeout_s=float(values["input_timeout_s"]),
        lock_slip_rad_s=float(values["lock_slip_rad_s"]), use_sim_time=use_sim_time)
    check(params)
    return params


def check(params: NodeParams) -> None:
    """Raise ValueError for out-of-range values."""
    for name, (lo, hi) in _RANGES.items():
        value = getattr(params, name)
        if not (lo <= value <= hi):
            raise ValueError(f"parameter {name} must be in [{lo:g}, {hi:g}], got {value}")
    if params.publish_every < 1:
        raise ValueError(f"parameter publish_every must be >= 1, got {params.publish_every}")
