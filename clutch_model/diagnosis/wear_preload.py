"""A return-spring preload that grows as the lining wears: the rival beyond the catalog of a named preload.

As the friction lining wears, the piston travels further before the plates touch, and the
return springs push back harder at the kiss point: the force lost to them grows with the
energy the clutch has dissipated. The catalog's ``spring_preload`` is a constant; a preload
that grows over the campaign is fitted by the catalog as a constant preload at its mean and a
friction decline beside it (``friction_degradation``: the torque falls as the energy grows,
most where the force is small). Measured on an outside generator's campaign (the preload
growing 0 -> 497 N over seven 40 s bags, noise 2.2 N*m): `spring_preload` 125 N [76, 206] and
`friction_degradation` 7.5 MJ were named, 9.53 N*m held out, the unseen bags 19.9 N*m off the
noise-free torque (the calibrated model 32.3) -- catalog names for an effect outside it.

So where a preload is named, the preload growing linearly with the dissipated energy,
max(F - (p0 + g E / E_campaign), 0) (two parameters, with the friction correction refitted;
E the campaign's energy as the named model dissipates it, the bags in time order), takes the
place of every named mechanism and meets the named model head to head on the held-out rows as
the other rivals do (``force_dynamics._rival_in_place``). On a constant preload it can only tie;
beside a friction decline it cannot fit the decline where the force is large. Taking the name,
the answer is ``unexplained``; a growth under twice the force noise never takes it.
"""
from __future__ import annotations

import numpy as np

from clutch_model.diagnosis.force_dynamics import (ForcePathObjective, _fit_from_best_start, _rival_in_place,
                                                   _unless_below_force_resolution, in_place_of_named)
from clutch_model.plant.mechanisms import ParamSpec
from clutch_model.prediction import predict_campaign

START_BOUNDS_KN = (0.0, 10.0)      # the preload at the campaign's start
GROWTH_BOUNDS_KN = (-10.0, 10.0)   # its change over the campaign's dissipated energy


def energy_share(model, plant_inputs) -> np.ndarray:
    """The share of the campaign's dissipated energy reached at each plant row (0 at the first
    row, 1 at the last), as ``model`` dissipates it on ``plant_inputs``."""
    pred = predict_campaign(model, plant_inputs, energy0_j=0.0, on_grid=True)
    e = np.asarray(pred.sim.energy_j, float)
    e = np.nan_to_num(e - e[0]) if e.size else e
    top = float(np.max(e)) if e.size else 0.0
    return e / top if top > 0 else np.zeros_like(e)


class WearPreloadObjective(ForcePathObjective):
    """Pack force max(F - 1e3 (start + growth x energy share), 0): x = [start_kn, growth_kn] then
    the friction correction."""

    def __init__(self, base, campaign, fit_mask, noise_sigma_nm: float = 1.0, ridge_factor: float = 1.0):
        specs = [ParamSpec("start_kn", False, *START_BOUNDS_KN, np.array([0.0])),
                 ParamSpec("growth_kn", False, *GROWTH_BOUNDS_KN, np.array([0.0]))]
        super().__init__(base, campaign, fit_mask, specs, noise_sigma_nm=noise_sigma_nm, ridge_factor=ridge_factor)
        self.share = energy_share(base, self._plant_inputs)

    def path_force(self, values) -> np.ndarray:
        preload_n = 1e3 * (values[0] + values[1] * self.share)
        return np.maximum(np.asarray(self._plant_inputs.force, float) - preload_n, 0.0)


def fit_wear_preload(base, campaign, fit_mask, preload_n: float, noise_sigma_nm: float = 1.0,
                     max_nfev: int = 40, ridge_factor: float = 1.0):
    """The growing preload on ``base``, jointly with the friction correction, on the training
    rows ``fit_mask``; started from the named constant ``preload_n`` (no growth), from none
    growing to twice it, and from half of it growing by as much."""
    p = max(float(preload_n) * 1e-3, 0.01)
    obj = WearPreloadObjective(base, campaign, fit_mask, noise_sigma_nm, ridge_factor)
    fit = _fit_from_best_start(obj, [[p, 0.0], [0.0, 2.0 * p], [0.5 * p, p]], max_nfev, "wear_preload")
    fit.parameters = {"start_preload_n": 1e3 * float(fit.parameters["start_kn"]),
                      "growth_n": 1e3 * float(fit.parameters["growth_kn"])}
    return fit


def named_or_wearing_preload(data, sel, campaign, sigma_nm: float, alpha: float, min_gain_frac: float,
                             say=lambda msg: None):
    """Named causes that include a spring preload, checked against a preload growing with the
    dissipated energy in their place (module doc) -> (selection, what the check found, or None
    when there was nothing to check)."""
    if "spring_preload" not in sel.cause_ids:
        return sel, None
    footing = in_place_of_named(sel)
    if footing is None:
        return sel, None
    stand_in, base, ridge = footing
    named = sel.final.model.mechanism("spring_preload")
    named_preload = float(named.values["preload_n"]) if named is not None else 0.0
    say(f"{', '.join(sel.cause_ids)} named: checking a preload growing with the lining's wear beyond the catalog "
        f"in their place")
    fit = fit_wear_preload(base, campaign, np.asarray(data.train_mask, bool), named_preload, noise_sigma_nm=sigma_nm,
                           ridge_factor=ridge)
    p0, g = float(fit.parameters["start_preload_n"]), float(fit.parameters["growth_n"])
    out, found = _rival_in_place(data, sel, base, stand_in, fit,
                                 f"preload growing {p0:.4g} -> {p0 + g:.4g} N with the dissipated energy",
                                 "wear_preload", alpha, min_gain_frac, say,
                                 "the return springs' preload grows as the lining wears")
    return _unless_below_force_resolution(out, sel, found, abs(g), say)
