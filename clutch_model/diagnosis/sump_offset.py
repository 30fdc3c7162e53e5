"""A torque reading offset that follows the sump temperature: the rival beyond the catalog of `none`.

A strain-gauge torque sensor's zero moves with its temperature, and on a differential the
sensor sits in the oil: measured = plant + a + k (theta_sump - 60 C). The catalog's
``torque_offset`` is the constant part. Over a campaign whose sump warms by tens of degrees
the reading drifts as slowly as the sump moves, and the structure test, which must not take a
slow drift of the noise for structure, leaves it to the noise model (a drift is forecast from
its own past); no catalog candidate explains the slope. So where nothing is named, the offset
with its slope (two parameters, with the friction correction refitted) meets the calibrated
model as the force paths beyond the catalog do (``force_dynamics._none_against``): taking the
name, the answer is ``unexplained``.

A slow drift of the sensor's noise rises with a warming sump within a run as well, so the
offset takes the name only when it also halves the calibrated model's plain held-out mean
square (MIN_PLAIN_CUT): on the virtual car's none@slow_drift#1 (an OU drift of 5 N*m over
36 s, two 30 s runs) a slope of 0.42 N*m per degree cut it by 10 % at held-out t = 7.4.

Measured on an outside generator's campaign (0.59 N*m per degree, the sump 46-77 C over six
bags, torque noise 1.3 N*m): `none` before, with the calibrated residual at 6.6 N*m held out;
the offset fits 0.587 N*m per degree at 1.45 N*m held out (t = 223): `unexplained`.
"""
from __future__ import annotations

import numpy as np

from clutch_model.diagnosis.force_dynamics import (ReadingObjective, _fit_from_best_start, _none_against, _refused,
                                                   _rival_in_place, in_place_of_named)
from clutch_model.plant.mechanisms import ParamSpec

SUMP_REFERENCE_C = 60.0
OFFSET_BOUNDS_NM = (-500.0, 500.0)
SLOPE_BOUNDS_NM_PER_C = (-20.0, 20.0)
STARTS = ((0.0, 0.0), (5.0, 0.3), (-5.0, -0.3))
MIN_SUMP_SPAN_C = 5.0      # a slope is only fitted where the training rows' sump spans this much
MIN_PLAIN_CUT = 0.5        # ... and takes the name from `none` only when it halves the calibrated
#                            model's plain held-out mean square


class SumpOffsetObjective(ReadingObjective):
    """measured = plant + offset + slope (sump - SUMP_REFERENCE_C): x = [offset, slope] then the
    friction correction."""

    def __init__(self, base, campaign, fit_mask, noise_sigma_nm: float = 1.0, ridge_factor: float = 1.0):
        specs = [ParamSpec("offset_nm", False, *OFFSET_BOUNDS_NM, np.array([0.0])),
                 ParamSpec("slope_nm_per_c", False, *SLOPE_BOUNDS_NM_PER_C, np.array([0.0]))]
        super().__init__(base, campaign, fit_mask, specs, noise_sigma_nm=noise_sigma_nm, ridge_factor=ridge_factor)

    def reading(self, plant, values) -> np.ndarray:
        return plant + values[0] + values[1] * (self._plant_inputs.sump - SUMP_REFERENCE_C)


def fit_sump_offset(base, campaign, fit_mask, noise_sigma_nm: float = 1.0, max_nfev: int = 40,
                    ridge_factor: float = 1.0):
    """The sump-following offset on ``base``, jointly with the friction correction, on the
    training rows ``fit_mask``. None when their sump spans less than MIN_SUMP_SPAN_C."""
    sump = np.asarray(campaign.sump, float)[np.asarray(fit_mask, bool)]
    sump = sump[np.isfinite(sump)]
    if sump.size < 10 or np.ptp(sump) < MIN_SUMP_SPAN_C:
        return None
    obj = SumpOffsetObjective(base, campaign, fit_mask, noise_sigma_nm, ridge_factor)
    return _fit_from_best_start(obj, [list(s) for s in STARTS], max_nfev, "sump_offset")


def none_or_sump_offset(data, sel, campaign, sigma_nm: float, alpha: float, min_gain_frac: float,
                        say=lambda msg: None):
    """A selection that named nothing, checked against a torque offset following the sump
    temperature (``_none_against``) -> (selection, what the check found, or None when there was
    nothing to check)."""
    if sel.verdict != "none":
        return sel, None
    train = np.asarray(data.train_mask, bool)
    fit = fit_sump_offset(sel.final.fit.model, campaign, train, noise_sigma_nm=sigma_nm)
    if fit is None:
        return sel, None
    say("nothing named: checked a torque offset following the sump temperature beyond the catalog")
    a, k = float(fit.parameters["offset_nm"]), float(fit.parameters["slope_nm_per_c"])
    before = sel
    sel, found = _none_against(data, sel, fit, "sump-following torque offset",
                               f"torque offset {a:+.3g} N*m {k:+.3g} N*m per degree of sump above "
                               f"{SUMP_REFERENCE_C:g} C",
                               f"the torque reading is off by {k:+.3g} N*m per degree of sump temperature (a "
                               f"sensor zero that moves with its temperature)", "sump_offset", alpha, min_gain_frac,
                               say)
    cut = float(found.get("plain_mean_square_cut", 0.0))
    if not found.get("took_the_name") or cut >= MIN_PLAIN_CUT:
        return sel, found
    return _refused(before, found, "below_half_the_error",
                    f"the sump-following offset cuts the plain held-out mean square by {100 * cut:.0f} % (under "
                    f"{100 * MIN_PLAIN_CUT:g} %: a slow drift of the noise rises with the sump as well)", say)


def named_or_sump_offset(data, sel, campaign, sigma_nm: float, alpha: float, min_gain_frac: float,
                         say=lambda msg: None):
    """Named causes checked against the sump-following torque offset in their place (``_rival_in_place``)
    -> (selection, what the check found, or None when there was nothing to check). A sump
    that warms with the energy dissipated makes the offset a lookalike of a friction decline,
    a drag or a constant offset; taking the name, the answer is ``unexplained``. On the virtual
    car's torque_sensor_thermal_offset@few_long#3 (``--quick``, 0.436 N*m per degree)
    friction_degradation had been named (a wrong name, the unseen runs 20 % worse)."""
    footing = in_place_of_named(sel)
    if footing is None:
        return sel, None
    stand_in, base, ridge = footing
    train = np.asarray(data.train_mask, bool)
    fit = fit_sump_offset(base, campaign, train, noise_sigma_nm=sigma_nm, ridge_factor=ridge)
    if fit is None:
        return sel, None
    say(f"{', '.join(sel.cause_ids)} named: checked a torque offset following the sump temperature in their place")
    k = float(fit.parameters["slope_nm_per_c"])
    return _rival_in_place(data, sel, base, stand_in, fit, f"torque offset of {k:+.3g} N*m per degree of sump",
                           "sump_offset", alpha, min_gain_frac, say,
                           "the torque reading's zero moves with the sump temperature")
