"""A small PI slip controller: from the slip error to the clutch force, as an eLSD controller
would command it (the same object runs offline inside simulate_driveline and in the ROS example
controller process)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Optional, Union


@dataclass
class PISlipController:
    """force = clip(kp * e + ki * integral(e), force_min_n, force_max_n), e = |slip| - target.

    The lower limit is a kiss-point preload (as eLSD controllers keep the pack filled): from an
    open 100 um gap the film needs ~1 s at 1 kN (>2 s at 400 N) to squeeze before the clutch carries torque. Too much
    slip asks for more force; a locked clutch (slip 0) gives e = -target, so the force
    falls until the clutch slips at the target again. The integral stops while the output is
    saturated in the direction of the error (anti-windup by conditional integration). Call
    ``update(t, slip)`` once per sample; the integral advances by the time since the last call.
    """

    target_slip_rad_s: Union[float, Callable[[float], float]] = 3.0
    kp_n_per_rad_s: float = 600.0
    ki_n_per_rad: float = 3000.0
    force_min_n: float = 1000.0     # kiss-point preload: keeps the film squeezed, no fill delay
    force_max_n: float = 20000.0
    integral: float = 0.0
    _t_prev: Optional[float] = field(default=None, repr=False)
    _force: float = field(default=0.0, repr=False)

    def target(self, t: float) -> float:
        tgt = self.target_slip_rad_s
        return float(tgt(t)) if callable(tgt) else float(tgt)

    def update(self, t: float, slip_rad_s: float) -> float:
        """The force command for the slip measured at time t."""
        if not math.isfinite(slip_rad_s):
            return self._force                      # hold the last command on a bad sample
        error = abs(slip_rad_s) - self.target(t)
        if self._t_prev is not None and t > self._t_prev:
            dt = t - self._t_prev
            saturated_high = self._force >= self.force_max_n and error > 0
            saturated_low = self._force <= self.force_min_n and error < 0
            if not (saturated_high or saturated_low):
                self.integral += error * dt
        self._t_prev = t
        force = self.kp_n_per_rad_s * error + self.ki_n_per_rad * self.integral
        self._force = min(max(force, self.force_min_n), self.force_max_n)
        return self._force

    def __call__(self, t: float, speed_a_rad_s: float, speed_b_rad_s: float) -> float:
        """simulate_driveline's controller signature: force(t, speed_a, speed_b)."""
        return self.update(t, speed_a_rad_s - speed_b_rad_s)

    def reset(self) -> None:
        self.integral, self._t_prev, self._force = 0.0, None, 0.0
