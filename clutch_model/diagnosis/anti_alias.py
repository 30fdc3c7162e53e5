"""The torque sensor's own filter: structure left after a named measurement lag that a
second-order low-pass on the reading removes.

A torque sensor's amplifier or logger low-passes the reading before it is sampled (an
anti-alias filter, commonly a second-order Butterworth a little below the logging's Nyquist
frequency), beside whatever lag the catalog's ``torque_sensor_lag`` or ``transport_delay``
names. The one time constant fitted to both takes the filter's group delay as well (on an outside
generator's 22.4 ms sensor lag behind a 60.7 Hz Butterworth, logged at 317 Hz: 25.8 ms, the
filter's group delay being 3.7 ms), and what it leaves around the torque's fast edges is the
filter's shape: the flexible residual model predicts it from the inputs (held-out t = 5.1, 1.7 %
of the innovation variance), and the answer was `unexplained`. The same lag without the filter
is named (22.2 ms [17.2, 27.1]).

So when structure remains after causes that include a lag or a delay on the measurement,
the named model's reading goes through one more second-order low-pass (natural frequency and
damping fitted with the friction correction, from a tenth to a third of the torque's logging
rate at damping 0.7; a named torque-sensor lag refitted with them, the reading first through
the lag, then the filter); where the structure test then finds nothing left, the structure was the
sensor's filter, not a cause: the named causes stand, and the extended model keeps them
without the filter (it is the sensor's, and the replay's torque is the clutch's).
"""
from __future__ import annotations

import math

import numpy as np

from clutch_model.diagnosis.force_dynamics import (ReadingObjective, _fit_from_best_start, second_order_force,
                                                   taken_out)
from clutch_model.diagnosis.lag_rivals import LAG_BOUNDS_S, asymmetric_lagged_torque
from clutch_model.plant.mechanisms import ParamSpec

ANTI_ALIAS_F_N_BOUNDS_HZ = (5.0, 2000.0)
ANTI_ALIAS_DAMPING_BOUNDS = (0.3, 3.0)
START_RATE_SHARES = (0.1, 0.2, 0.33)     # the filter's start, as a share of the torque's logging rate
MEASUREMENT_TIMED = ("torque_sensor_lag", "transport_delay")


class AntiAliasObjective(ReadingObjective):
    """The reading through x'' = w^2 (T - x) - 2 zeta w x': x = [log f_n, log damping] then the
    friction correction. With ``lag_s``, the named torque-sensor lag is refitted with it, the
    reading T first through that lag: x = [log tau, log f_n, log damping] then the correction
    (the lag alone took the filter's group delay as well)."""

    def __init__(self, base, campaign, fit_mask, f_n_hz: float, noise_sigma_nm: float = 1.0,
                 ridge_factor: float = 1.0, lag_s: float | None = None):
        specs = [ParamSpec("f_n_hz", True, *ANTI_ALIAS_F_N_BOUNDS_HZ, np.array([f_n_hz])),
                 ParamSpec("damping", True, *ANTI_ALIAS_DAMPING_BOUNDS, np.array([0.7]))]
        self.with_lag = lag_s is not None
        if self.with_lag:
            specs = [ParamSpec("tau_s", True, *LAG_BOUNDS_S, np.array([lag_s]))] + specs
        super().__init__(base, campaign, fit_mask, specs, noise_sigma_nm=noise_sigma_nm, ridge_factor=ridge_factor)

    def reading(self, plant, values) -> np.ndarray:
        pi = self._plant_inputs
        plant = np.ascontiguousarray(plant, float)
        if self.with_lag:
            plant = asymmetric_lagged_torque(pi.t, plant, pi.run_start, float(values[0]), float(values[0]))
            values = values[1:]
        f_n = float(values[0])
        step = min(5e-4, 0.2 / (2.0 * math.pi * f_n))        # RK4 well inside its accuracy
        return second_order_force(pi.t, plant, pi.run_start, f_n, float(values[1]), step)


def fit_anti_alias(base, campaign, fit_mask, rate_hz: float, noise_sigma_nm: float = 1.0, ridge_factor: float = 1.0,
                   lag_s: float | None = None):
    """The second-order low-pass on ``base``'s reading (after a torque-sensor lag refitted from
    ``lag_s`` when given), with the friction correction, on the training rows ``fit_mask``,
    from the best of START_RATE_SHARES x ``rate_hz`` at damping 0.7."""
    lo, hi = ANTI_ALIAS_F_N_BOUNDS_HZ
    starts = [float(np.clip(s * rate_hz, lo, hi)) for s in START_RATE_SHARES]
    obj = AntiAliasObjective(base, campaign, fit_mask, starts[0], noise_sigma_nm, ridge_factor, lag_s)
    head = [math.log(lag_s)] if lag_s is not None else []
    return _fit_from_best_start(obj, [head + [math.log(f), math.log(0.7)] for f in starts], 40, "anti_alias_filter")


def remainder_in_the_sensor(data, campaign, sigma_nm: float, remainder_test, say=lambda msg: None):
    """A check for ``selection.select_causes(remainder_in_the_sensor=...)``: called with the
    named model, the named ids and the structure found after them, it returns why that
    structure is the torque sensor's filter ('' when it is not, or the named causes hold no
    lag or delay on the measurement). ``remainder_test(resid, fitted)`` is the selection's own
    test of what remains."""
    from clutch_model.diagnosis.selection import residual, row_interval_s

    def check(current, named_ids, struct) -> str:
        if not any(i in MEASUREMENT_TIMED for i in named_ids):
            return ""
        interval = row_interval_s(data.t, data.run_start)
        if not interval > 0:
            return ""
        lag, base, ridge = taken_out(current, ["torque_sensor_lag"])
        lag_s = float(lag[0].values["tau_s"]) if lag else None
        say(f"structure left after {', '.join(named_ids)}: checking the torque sensor's own filter (a second-order "
            f"low-pass on the reading" + (", the sensor lag refitted with it)" if lag else ")"))
        fit = fit_anti_alias(base, campaign, np.asarray(data.train_mask, bool), 1.0 / interval, sigma_nm, ridge,
                             lag_s=float(np.clip(lag_s, *LAG_BOUNDS_S)) if lag else None)
        f_n, zeta = float(fit.parameters["f_n_hz"]), float(fit.parameters["damping"])
        left = remainder_test(residual(data, fit), fit)
        figure = f"held-out t = {left.comparison.t_stat:.1f}" if left is not None else "no test"
        if left is None or left.structured:
            say(f"a second-order low-pass of {f_n:.3g} Hz, damping {zeta:.2g}, on the reading leaves structure "
                f"({figure}): not the sensor's filter")
            return ""
        say(f"a second-order low-pass of {f_n:.3g} Hz, damping {zeta:.2g}, on the reading leaves none ({figure}): "
            f"the torque sensor's own filter")
        return (f"the structure left is the torque sensor's own filter: a second-order low-pass of {f_n:.3g} Hz, "
                f"damping {zeta:.2g}, on the named reading leaves none ({figure}); not a cause")
    return check
