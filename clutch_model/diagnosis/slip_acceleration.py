"""A friction that follows the slip's acceleration: the rival beyond the catalog of a named
time mechanism.

A wet clutch's friction coefficient is not a function of the slip speed alone: the oil film and
the lining's pores take time to follow a change of slip (frictional memory), so the friction
rises for a while when the slip speeds up and falls when it slows down,

    T_measured = T (1 + c a),     a = d/dt of |slip| through a first-order low-pass of tau,

(``a`` in rad/s^2, ``c`` in s^2/rad, signed). Where the slip changes with the force (an
engagement: the torque rises, the slip falls), the factor moves the torque in time as a delay
or a lag does, and the catalog names one of those: an outside generator's friction term
c = 0.006 s^2/rad was named actuator_lag (7.8 ms) at held-out t = 14.9. So when a time
mechanism is named, this rival takes the named time mechanisms' place (the friction correction
refitted with it from the named fit's footing, the other named causes kept) and meets the named
model head to head on the held-out rows as every rival does
(``force_dynamics._rival_in_place``); taking the name turns the answer ``unexplained``. It
cannot move the torque that follows the force at constant slip, which every catalog time
mechanism does, so on a true delay or lag it loses.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from clutch_model.diagnosis.fitting import time_mechanism_ids
from clutch_model.diagnosis.force_dynamics import (ReadingObjective, _fit_from_best_start, _none_against,
                                                   _refused, _rival_in_place, taken_out)
from clutch_model.diagnosis.force_dynamics import _lag_step
from clutch_model.plant.mechanisms import ParamSpec
from clutch_model.plant.params import ClutchModel

GAIN_BOUNDS_S2_PER_RAD = (-0.05, 0.05)
TAU_BOUNDS_S = (2e-3, 0.5)
START_TAUS_S = (0.01, 0.03, 0.1)
START_GAINS_S2_PER_RAD = (-0.005, 0.005)
MAX_FACTOR = 0.5          # the factor's excursion is held within 1 +- this
# where nothing is named, the friction must cut the calibrated model's plain held-out mean square
# by this much: on a `none` campaign of the CI (test_says_none_without_mechanism) c = -0.00085
# s^2/rad through 90 ms cut it by 2 % (8.35 -> 8.26 N*m) at t = 5.9; the virtual car's effect
# cut it by 86 % (30.5 -> 11.4 N*m) on lab#1
MIN_NONE_PLAIN_CUT = 0.05


@njit(cache=True)
def slip_acceleration(t, slip, run_start, tau_s):
    """d/dt of |slip| through a first-order low-pass of ``tau_s`` on the rows ``t`` (s):
    (|slip| - y) / tau with y the low-passed |slip|, each run from rest at its first |slip|;
    exact for |slip| linear between rows (NaN rows held through)."""
    n = slip.size
    out = np.zeros(n)
    y = 0.0
    for k in range(n):
        u1 = abs(slip[k])
        if k == 0 or run_start[k] or not math.isfinite(y):
            y = u1
            continue
        u0 = abs(slip[k - 1])
        dt = t[k] - t[k - 1]
        if not (dt > 0.0 and math.isfinite(u0) and math.isfinite(u1)):
            continue
        y = _lag_step(y, u0, (u1 - u0) / dt, dt, tau_s)
        out[k] = (u1 - y) / tau_s
    return out


class SlipAccelerationObjective(ReadingObjective):
    """x = [c (s^2/rad), log tau] then the friction correction; the plant is the base model's,
    its torque times 1 + c a (``slip_acceleration``)."""

    def __init__(self, base: ClutchModel, campaign, fit_mask, noise_sigma_nm: float = 1.0, ridge_factor: float = 1.0):
        specs = [ParamSpec("gain_s2_per_rad", False, GAIN_BOUNDS_S2_PER_RAD[0], GAIN_BOUNDS_S2_PER_RAD[1],
                           np.array([0.0])),
                 ParamSpec("tau_s", True, TAU_BOUNDS_S[0], TAU_BOUNDS_S[1], np.array([START_TAUS_S[1]]))]
        super().__init__(base, campaign, fit_mask, specs, noise_sigma_nm=noise_sigma_nm, ridge_factor=ridge_factor)
        self._accel: dict = {}

    def acceleration(self, tau_s: float) -> np.ndarray:
        key = float(tau_s)
        if key not in self._accel:
            pi = self._plant_inputs
            self._accel = {key: slip_acceleration(pi.t, pi.slip, pi.run_start, key)}   # the latest only
        return self._accel[key]

    def reading(self, plant, values) -> np.ndarray:
        gain, tau = values
        return plant * (1.0 + np.clip(gain * self.acceleration(tau), -MAX_FACTOR, MAX_FACTOR))


def fit_slip_acceleration(base: ClutchModel, campaign, fit_mask, noise_sigma_nm: float = 1.0,
                          max_nfev: int = 40, ridge_factor: float = 1.0):
    """The slip-acceleration friction on ``base`` (its time mechanisms taken out), jointly with
    the friction correction, on the training rows; started from the best of START_GAINS x
    START_TAUS."""
    obj = SlipAccelerationObjective(base, campaign, fit_mask, noise_sigma_nm, ridge_factor)
    starts = [[g, math.log(tau)] for g in START_GAINS_S2_PER_RAD for tau in START_TAUS_S]
    return _fit_from_best_start(obj, starts, max_nfev, "slip_acceleration_friction")


def named_or_slip_acceleration(data, sel, campaign, sigma_nm: float, alpha: float, min_gain_frac: float,
                               say=lambda msg: None):
    """A selection that named a time mechanism, checked against a friction that follows the
    slip's acceleration in its place (module docstring) -> (selection, what the check found: a
    dict for the report, or None when there was nothing to check)."""
    timed = time_mechanism_ids(sel.cause_ids) if sel.verdict == "named" else []
    if not timed:
        return sel, None
    stand_in, base, ridge = taken_out(sel.final, timed)
    say(f"{', '.join(timed)} named: checking a friction that follows the slip's acceleration beyond the catalog "
        f"in its place")
    fit = fit_slip_acceleration(base, campaign, np.asarray(data.train_mask, bool), noise_sigma_nm=sigma_nm,
                                ridge_factor=ridge)
    c, tau = float(fit.parameters["gain_s2_per_rad"]), float(fit.parameters["tau_s"])
    return _rival_in_place(data, sel, base, stand_in, fit,
                           f"friction following the slip's acceleration ({c:+.3g} s^2/rad, low-pass {1e3 * tau:.3g} ms)",
                           "slip_acceleration_friction", alpha, min_gain_frac, say,
                           "the friction follows the slip's acceleration, not a delayed force or reading")


def none_or_slip_acceleration(data, sel, campaign, sigma_nm: float, alpha: float, min_gain_frac: float,
                              say=lambda msg: None):
    """A selection that named nothing, checked against a friction that follows the slip's
    acceleration on the calibrated model -> (selection, what the check found, or None when
    there was nothing to check). Where the slip's acceleration does not follow the force edges
    no time mechanism mimics it, and what it leaves is a smooth misfit the noise model
    forecasts from its past; judged as the rate limit is (``force_dynamics._none_against``:
    significantly better than the calibrated model and than its twin, the friction correction
    refitted alone). Measured on slip_acceleration_friction@lab#1 (c = 0.011 s^2/rad): the
    calibrated model was 35.7 N*m off the true torque on the unseen runs and the answer read
    `none`."""
    if sel.verdict != "none":
        return sel, None
    say("nothing named: checking a friction that follows the slip's acceleration beyond the catalog")
    fit = fit_slip_acceleration(sel.final.fit.model, campaign, np.asarray(data.train_mask, bool),
                                noise_sigma_nm=sigma_nm)
    c, tau = float(fit.parameters["gain_s2_per_rad"]), float(fit.parameters["tau_s"])
    before = sel
    sel, found = _none_against(data, sel, fit, "slip-acceleration friction",
                               f"friction following the slip's acceleration ({c:+.3g} s^2/rad, low-pass "
                               f"{1e3 * tau:.3g} ms)",
                               f"the friction follows the slip's acceleration ({c:+.3g} s^2/rad through a "
                               f"{1e3 * tau:.3g} ms low-pass: frictional memory)", "slip_acceleration_friction",
                               alpha, min_gain_frac, say)
    cut = found["plain_mean_square_cut"]
    if cut >= MIN_NONE_PLAIN_CUT:
        return sel, found
    return _refused(before, found, "immaterial", f"the slip-acceleration friction cuts the plain held-out mean "
                    f"square by {100 * cut:.1f} % (under {100 * MIN_NONE_PLAIN_CUT:g} %)", say)
