"""A ceiling on the pack force: the rival beyond the catalog of named causes, and of `none`.

An actuator whose motor current, valve or supply pressure is limited cannot push the pack
beyond some force F_max, whatever the controller asks for: the pack force is min(F, F_max).
No catalog mechanism is that. Above the ceiling the torque stops following the measured force:
its level (the calibration's friction terms and a preload or an offset fit part of it) and its
fast moves, so a dither on the force (a controller's 60-120 Hz square or sine) vanishes from
the torque there, which a torque-sensor or actuator lag imitates by filtering it.

So where causes are named, the ceiling (one parameter, with the friction correction refitted)
takes the place of every named mechanism and meets the named model head to head on the
held-out rows, as the other rivals beyond the catalog do (``force_dynamics._rival_in_place``);
where nothing is named it meets the calibrated model (``force_dynamics._none_against``). A
ceiling that holds the force off the measured one on under ``MIN_CEILING_BINDING`` of the
fitted rows (by more than the force noise band) clips a few peaks, not an actuator's limit,
and never takes the name.

Measured on an outside generator's campaign (a ceiling at 73 % of the peak force, a 108 Hz
square dither of 5.5 % logged at 1 kHz, torque noise 2.5 N*m): a 5.8 ms torque_sensor_lag was
named at held-out t = 83.7 (RMSE 24.3 -> 14.3 N*m), a wrong name.
"""
from __future__ import annotations

import math

import numpy as np

from clutch_model.diagnosis.force_dynamics import (ForcePathObjective, _fit_from_best_start, _none_against,
                                                   _rival_in_place, in_place_of_named,
                                                   unless_rarely_binding)
from clutch_model.plant.mechanisms import ParamSpec

CEILING_START_QUANTILES = (0.5, 0.7, 0.85, 0.95)   # starts: the training rows' force at these quantiles
CEILING_LOW_QUANTILE = 0.2                        # the ceiling's lower bound: the force at this quantile
MIN_CEILING_BINDING = 0.01   # a ceiling must hold the force off the measured one on this share of the fitted rows


def ceiling_force(force, ceiling_n: float) -> np.ndarray:
    """The pack force under a ceiling: min(F, ceiling)."""
    return np.minimum(np.asarray(force, float), float(ceiling_n))


class ForceCeilingObjective(ForcePathObjective):
    """The ceiling on the force path: x = [log ceiling in kN] then the friction correction."""

    def __init__(self, base, campaign, fit_mask, bounds_kn, start_kn: float, noise_sigma_nm: float = 1.0,
                 ridge_factor: float = 1.0):
        specs = [ParamSpec("ceiling_kn", True, bounds_kn[0], bounds_kn[1], np.array([start_kn]))]
        super().__init__(base, campaign, fit_mask, specs, noise_sigma_nm=noise_sigma_nm, ridge_factor=ridge_factor)

    def path_force(self, values) -> np.ndarray:
        return ceiling_force(self._plant_inputs.force, 1e3 * values[0])


def _training_force(campaign, fit_mask) -> np.ndarray:
    f = np.asarray(campaign.force, float)[np.asarray(fit_mask, bool)]
    return f[np.isfinite(f) & (f > 0.0)]


def fit_force_ceiling(base, campaign, fit_mask, noise_sigma_nm: float = 1.0, max_nfev: int = 40,
                      ridge_factor: float = 1.0):
    """The force ceiling on ``base``, jointly with the friction correction, on the training
    rows ``fit_mask``; started from the best of the training force's quantiles
    CEILING_START_QUANTILES, bounded between its CEILING_LOW_QUANTILE quantile and its
    largest value. None when the training rows carry no positive force."""
    f = _training_force(campaign, fit_mask)
    if f.size < 10:
        return None
    top = float(f.max())
    low = min(float(np.quantile(f, CEILING_LOW_QUANTILE)), 0.5 * top)
    bounds_kn = (max(1e-3 * low, 1e-3), 1e-3 * top)
    starts = sorted({float(np.clip(1e-3 * np.quantile(f, q), *bounds_kn)) for q in CEILING_START_QUANTILES})
    obj = ForceCeilingObjective(base, campaign, fit_mask, bounds_kn, starts[0], noise_sigma_nm, ridge_factor)
    fit = _fit_from_best_start(obj, [[math.log(v)] for v in starts], max_nfev, "force_ceiling")
    fit.parameters = {"ceiling_n": 1e3 * float(fit.parameters["ceiling_kn"])}
    return fit


def _unless_rarely_binding(sel, before, found: dict, campaign, train, ceiling_n: float, say):
    """A ceiling the force passes (by more than the force noise band) on under
    MIN_CEILING_BINDING of the fitted rows never takes the name."""
    return unless_rarely_binding(sel, before, found, campaign, train, lambda pi: ceiling_force(pi.force, ceiling_n),
                                 MIN_CEILING_BINDING, "the ceiling", say)


def named_or_force_ceiling(data, sel, campaign, sigma_nm: float, alpha: float, min_gain_frac: float,
                           say=lambda msg: None):
    """Named causes checked against a ceiling on the pack force in their place -> (selection,
    what the check found: a dict for the report, or None when there was nothing to check).
    Taking the name (``_rival_in_place``), the answer reads ``unexplained``."""
    footing = in_place_of_named(sel)
    if footing is None:
        return sel, None
    stand_in, base, ridge = footing
    say(f"{', '.join(sel.cause_ids)} named: checking a ceiling on the pack force beyond the catalog in their place")
    train = np.asarray(data.train_mask, bool)
    fit = fit_force_ceiling(base, campaign, train, noise_sigma_nm=sigma_nm, ridge_factor=ridge)
    if fit is None:
        return sel, None
    c = float(fit.parameters["ceiling_n"])
    before = sel
    sel, found = _rival_in_place(data, sel, base, stand_in, fit, f"ceiling of {c:.5g} N on the pack force",
                                 "force_ceiling", alpha, min_gain_frac, say,
                                 "the pack force stops at a ceiling the measured force passes (a force-limited "
                                 "actuator)")
    return _unless_rarely_binding(sel, before, found, campaign, train, c, say)


def none_or_force_ceiling(data, sel, campaign, sigma_nm: float, alpha: float, min_gain_frac: float,
                          say=lambda msg: None):
    """A selection that named nothing, checked against a ceiling on the pack force (fitted on the
    calibrated model with the friction correction, judged as the rate limit is:
    ``_none_against``) -> (selection, what the check found, or None when there was nothing to
    check)."""
    if sel.verdict != "none":
        return sel, None
    say("nothing named: checking a ceiling on the pack force beyond the catalog")
    train = np.asarray(data.train_mask, bool)
    fit = fit_force_ceiling(sel.final.fit.model, campaign, train, noise_sigma_nm=sigma_nm)
    if fit is None:
        return sel, None
    c = float(fit.parameters["ceiling_n"])
    before = sel
    sel, found = _none_against(data, sel, fit, "force ceiling", f"ceiling of {c:.5g} N on the pack force",
                               f"the pack force stops at {c:.5g} N while the measured force passes it (a "
                               f"force-limited actuator)", "force_ceiling", alpha, min_gain_frac, say)
    return _unless_rarely_binding(sel, before, found, campaign, train, c, say)
