"""Default topic names of a car-test bag (docs/bags.md). No heavy imports: the CLI builds its
``--topic-*`` options from here without loading numpy or numba."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TopicNames:
    applied_force: str = "/clutch/applied_force"
    slip_speed: str = "/clutch/slip_speed"
    sump_temperature: str = "/clutch/sump_temperature"
    measured_torque: str = "/clutch/measured_torque"
    pack_temperature: str = "/clutch/pack_temperature"
