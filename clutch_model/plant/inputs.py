"""Input validity (docs/interfaces.md, "Input validity") and the held-input channels of the node.

Pure Python, no rclpy. The limits are clutch_model.formats.bag_reader' (offline replay drops the samples
the node rejects), so the node and offline replay see the same inputs.
"""
from __future__ import annotations

import math
from typing import Callable, Optional

from clutch_model.formats.bag_reader import FORCE_MAX_N, SLIP_MAX_RAD_S, SUMP_RANGE_C

# FORCE_MAX_N: applied force above it is rejected (a negative force is valid: counts as 0)
# SLIP_MAX_RAD_S: |slip| above it is rejected
SUMP_MIN_C, SUMP_MAX_C = SUMP_RANGE_C


def valid_force(value: float) -> bool:
    return math.isfinite(value) and value <= FORCE_MAX_N


def valid_slip(value: float) -> bool:
    return math.isfinite(value) and abs(value) <= SLIP_MAX_RAD_S


def valid_sump(value: float) -> bool:
    return math.isfinite(value) and SUMP_MIN_C <= value <= SUMP_MAX_C


VALIDATORS: dict[str, Callable[[float], bool]] = {
    "applied_force": valid_force,
    "slip_speed": valid_slip,
    "sump_temperature": valid_sump,
}
INPUT_TOPICS = tuple(VALIDATORS)


class InputChannel:
    """One input topic: the last good value (held), counters and freshness.

    ``offer(value)`` applies one message; ``on_tick(t)`` stamps a value that arrived since the
    last tick with the tick time ``t`` (the node's time base: steady clock in wall-clock mode,
    sim time in sim-time mode), so freshness has the resolution of one tick. Freshness is
    measured from the last *valid* message: a sensor that only sends NaN goes stale.
    """

    __slots__ = ("name", "_valid", "value", "received", "rejected", "last_good_ns", "_pending",
                 "rx_ns", "unused")

    def __init__(self, name: str, validator: Optional[Callable[[float], bool]] = None):
        self.name = name
        self._valid = validator or VALIDATORS[name]
        self.value: Optional[float] = None      # last good value (held)
        self.received = 0                       # messages seen, good or bad
        self.rejected = 0                       # messages rejected as invalid
        self.last_good_ns: Optional[int] = None  # tick time of the last good value
        self._pending = False
        self.rx_ns = 0                          # middleware receive time of the last good value (system ns)
        self.unused = False                     # last good value not yet published

    def offer(self, value: float, rx_ns: int = 0) -> bool:
        """Apply one message; returns False (and counts) when it is rejected."""
        self.received += 1
        try:
            value = float(value)
        except (TypeError, ValueError):
            self.rejected += 1
            return False
        if not self._valid(value):
            self.rejected += 1
            return False
        self.value = value
        self.rx_ns = rx_ns
        self.unused = True
        self._pending = True
        return True

    def on_tick(self, t_ns: int) -> None:
        if self._pending:
            self.last_good_ns = t_ns
            self._pending = False

    def rebase(self, t_ns: int) -> None:
        """The time base changed (wall clock <-> sim time): a held value counts as received
        at ``t_ns`` of the new base (its age restarts instead of comparing two clocks)."""
        if self.last_good_ns is not None:
            self.last_good_ns = t_ns

    def age_s(self, now_ns: int) -> Optional[float]:
        """Seconds since the last good value, None before the first one."""
        if self.last_good_ns is None:
            return None
        return max(0.0, (now_ns - self.last_good_ns) * 1e-9)

    def is_stale(self, now_ns: int, timeout_s: float) -> bool:
        age = self.age_s(now_ns)
        return age is None or age > timeout_s

