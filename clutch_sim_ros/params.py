"""The ROS parameters of the clutch_sim node, declared in one place.

``SPEC`` lists every parameter (name, default, type, range, what it does, how a runtime change
applies) without importing ROS, so ``clutch-sim-node --help`` can print it. ``declare(node)``
declares them all with descriptors (ranges as FloatingPointRange / IntegerRange) and returns the
values as a ``NodeParams``; ``check_change(name, value)`` is the node's on-set validation.

Every parameter applies at runtime (``ros2 param set`` / the SetParameters service) or the
change is refused with a reason. Floats accept integers (a YAML ``rate_hz: 1000`` is stored as
1000.0 and range-checked like a float). ``use_sim_time`` is rclpy's own parameter: the node
switches between its wall-clock timer and /clock stepping when it changes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Optional

from clutch_sim_ros import driveline_io as DIO


@dataclass(frozen=True)
class Spec:
    name: str
    default: object
    kind: type                      # float | int | str | bool
    range: Optional[tuple] = None   # (lo, hi), inclusive
    description: str = ""
    runtime: str = ""               # what a change at runtime does


SPEC: tuple[Spec, ...] = (
    Spec("rate_hz", 1000.0, float, (1.0, 10000.0),
         "model step and publish tick in wall-clock mode, Hz",
         "timer period changes at once"),
    Spec("publish_every", 1, int, (1, 100000),
         "publish the outputs every N-th tick (the model steps every tick)",
         "applies from the next tick"),
    Spec("clutch_params_file", "", str, None,
         'clutch parameter YAML (schema of config/reference_clutch.yaml); "" = the shipped '
         "reference clutch RC-1",
         "file is loaded and checked first (refused with the loader's reason); the plant then "
         "restarts with the new model"),
    Spec("input_timeout_s", 0.1, float, (1e-4, 3600.0),
         "an input without a valid message for this long is stale (diagnostics WARN, ERROR after "
         "10x); a stale applied force counts as 0 N, s",
         "applies from the next tick"),
    Spec("lock_slip_rad_s", 0.001, float, (0.0, 1000.0),
         "|slip| below this = locked clutch (static torque capacity), rad/s",
         "applies from the next tick (plant state kept)"),
    Spec("frame_id", "clutch", str, None,
         "header.frame_id of the stamped outputs (pack_temperature, clutch_state)",
         "applies from the next published sample"),
    Spec("use_sim_time", False, bool, None,
         "step once per /clock message (lock-step, plant time = /clock time) instead of the "
         "wall-clock timer",
         "switches the stepping (timer <-> /clock); the plant state is kept"),
) + tuple(Spec(*row) for row in DIO.PARAMETERS)   # slip_source, driveline.* (driveline mode)
SPEC_BY_NAME = {s.name: s for s in SPEC}
DECLARED = tuple(s.name for s in SPEC if s.name != "use_sim_time")   # use_sim_time: rclpy's


@dataclass(frozen=True)
class NodeParams:
    rate_hz: float = 1000.0
    publish_every: int = 1
    clutch_params_file: str = ""
    input_timeout_s: float = 0.1
    lock_slip_rad_s: float = 0.001
    frame_id: str = "clutch"
    use_sim_time: bool = False
    slip_source: str = "topic"
    driveline_inertia_a_kgm2: float = DIO.DEFAULTS["driveline.inertia_a_kgm2"]
    driveline_inertia_b_kgm2: float = DIO.DEFAULTS["driveline.inertia_b_kgm2"]
    driveline_damping_a_nms: float = DIO.DEFAULTS["driveline.damping_a_nms"]
    driveline_damping_b_nms: float = DIO.DEFAULTS["driveline.damping_b_nms"]
    driveline_initial_speed_a_rad_s: float = DIO.DEFAULTS["driveline.initial_speed_a_rad_s"]
    driveline_initial_speed_b_rad_s: float = DIO.DEFAULTS["driveline.initial_speed_b_rad_s"]

    @property
    def period_s(self) -> float:
        return 1.0 / self.rate_hz

    def value(self, name: str):
        """The value of parameter ``name`` (ROS name, e.g. driveline.inertia_a_kgm2)."""
        return getattr(self, field_name(name))

    def driveline(self):
        """clutch_model.DrivelineParams of the driveline.* parameters."""
        return DIO.driveline_params({n: self.value(n) for n in DIO.PARAMETER_NAMES[1:]})

    def with_value(self, name: str, value) -> "NodeParams":
        return replace(self, **{field_name(name): SPEC_BY_NAME[name].kind(value)})


def field_name(name: str) -> str:
    """NodeParams field of a parameter: the ROS name with '.' as '_'."""
    return name.replace(".", "_")


assert [f.name for f in fields(NodeParams)] == [field_name(s.name) for s in SPEC]


def check_change(name: str, value) -> Optional[str]:
    """None when ``value`` is acceptable for parameter ``name``, else the reason (one line)."""
    spec = SPEC_BY_NAME.get(name)
    if spec is None:
        return None
    if spec.kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"{name} must be a number, got {value!r}"
    elif spec.kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            return f"{name} must be an integer, got {value!r}"
    elif not isinstance(value, spec.kind):
        return f"{name} must be a {spec.kind.__name__}, got {value!r}"
    if spec.range is not None:
        lo, hi = spec.range
        if not (isinstance(value, (int, float)) and math.isfinite(value) and lo <= value <= hi):
            return f"{name} must be in [{lo:g}, {hi:g}], got {value!r}"
    return DIO.check_value(name, value)     # slip_source: one of its choices


def check(params: NodeParams) -> None:
    """Raise ValueError for an invalid value."""
    for spec in SPEC:
        reason = check_change(spec.name, params.value(spec.name))
        if reason:
            raise ValueError(f"parameter {reason}")


def descriptor(spec: Spec):
    """The rcl_interfaces ParameterDescriptor of one parameter."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType

    text = f"{spec.description}. At runtime: {spec.runtime}"
    if spec.kind is float:
        # dynamic typing so that an integer (YAML `1000`) is accepted; declare() and the node's
        # pre-set callback turn it into a double, which rclpy then checks against the range
        return ParameterDescriptor(
            description=text, dynamic_typing=True,
            additional_constraints=f"number in [{spec.range[0]:g}, {spec.range[1]:g}]; integers accepted",
            floating_point_range=[FloatingPointRange(from_value=float(spec.range[0]),
                                                     to_value=float(spec.range[1]), step=0.0)])
    if spec.kind is int:
        return ParameterDescriptor(description=text, type=ParameterType.PARAMETER_INTEGER,
                                   integer_range=[IntegerRange(from_value=spec.range[0],
                                                               to_value=spec.range[1], step=1)])
    if spec.name == "slip_source":
        return ParameterDescriptor(description=text, type=ParameterType.PARAMETER_STRING,
                                   additional_constraints="one of: " + ", ".join(DIO.SLIP_SOURCES))
    return ParameterDescriptor(description=text, type=ParameterType.PARAMETER_STRING)


def as_double(parameters: list) -> list:
    """Pre-set callback: integers given for float parameters become doubles (so the
    descriptor's FloatingPointRange applies and the stored type is double)."""
    from rclpy.parameter import Parameter

    out = []
    for p in parameters:
        spec = SPEC_BY_NAME.get(p.name)
        if (spec is not None and spec.kind is float and p.type_ == Parameter.Type.INTEGER):
            p = Parameter(p.name, Parameter.Type.DOUBLE, float(p.value))
        out.append(p)
    return out


def declare(node) -> NodeParams:
    """Declare every parameter of SPEC on ``node`` (integers for floats become doubles) and
    return their values. Raises ValueError with a one-line reason for a bad value."""
    from rclpy.parameter import Parameter

    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException

    for name in DECLARED:
        spec = SPEC_BY_NAME[name]
        try:
            node.declare_parameter(name, spec.default, descriptor(spec))
        except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
            text = " ".join(str(exc).split())
            reason = text.split("Reason: ", 1)[-1].rsplit(":", 1)[0] if "Reason: " in text else text
            raise ValueError(f"parameter {name} refused: {reason}") from None
    converted = as_double([node.get_parameter(n) for n in DECLARED])
    changed = [p for p in converted if p.type_ == Parameter.Type.DOUBLE
               and node.get_parameter(p.name).type_ != Parameter.Type.DOUBLE]
    for p in converted:
        reason = check_change(p.name, p.value)
        if reason:
            raise ValueError(f"parameter {reason}")
    if changed:
        result = node.set_parameters_atomically(changed)
        if not result.successful:
            raise ValueError(f"parameters: {result.reason}")
    values = {n: node.get_parameter(n).value for n in DECLARED}
    values["use_sim_time"] = bool(node.get_parameter("use_sim_time").value)
    params = NodeParams(**{field_name(n): SPEC_BY_NAME[n].kind(v) for n, v in values.items()})
    check(params)
    return params


def help_text() -> str:
    """The parameter section of ``clutch-sim-node --help``."""
    lines = []
    for s in SPEC:
        rng = f" in [{s.range[0]:g}, {s.range[1]:g}]" if s.range else ""
        lines.append(f"  {s.name} ({s.kind.__name__}{rng}, default {s.default!r})")
        lines.append(f"      {s.description}; at runtime: {s.runtime}")
    return "\n".join(lines)
