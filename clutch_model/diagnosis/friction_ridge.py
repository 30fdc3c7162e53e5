"""The friction correction of the models diagnose writes, held to what the data support: its
ridge chosen by cross-validation over the fitted stretches.

Every fit of the selection (the baseline and each candidate) refits a 10-term friction
correction (``fitting``) with a ridge that charges a change of 0.05 in mu one noise-level sum
of squares; those fits keep it. Where the car calibration already matches the friction, that
correction only follows the noise,
and under coloured noise (AR(1) 0.9 torque and slip noise, three 30 s runs) it follows it a long
way: on such a campaign with the bench friction true to the car, the calibrated model was
10.2 N*m off on later runs against 2.1 N*m without the correction (the true torque at the
torque stamps), while it cut the fitted rows' RMSE by only 0.3 N*m.

The correction is nearly linear in the torque (mu scales the clutch torque wherever the clutch
slips), so its cross-validation is one batch of simulations: the prediction's Jacobian J in
the correction at zero, then for each ridge factor in FACTORS and each fold (a contiguous
stretch of fitted rows within a run; the held-out stretches between them cut a long drive),
the ridged linear fit on the other folds predicting the fold. The factor with the least
cross-validated mean square is kept, the stronger ridge on a near tie (RELATIVE_TIE); an
infinite one means the written model carries no correction. With fewer than two folds the ridge
stays as it is. ``held_to_the_data`` applies it to a fit about to be written (the calibrated
model, the final named one), its mechanisms as fitted.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from clutch_model.diagnosis.fitting import N_CORR, CampaignObjective, apply_friction_correction, fit_candidate

FACTORS = (1.0, 10.0, 100.0, math.inf)   # multiples of the correction's ridge (fitting.RIDGE_SCALE)
RELATIVE_TIE = 1e-3                      # cross-validated mean squares this close: the stronger ridge
STEP = 1e-4                              # the Jacobian's step in the correction (mu)


def ridge_label(factor: float) -> str:
    """A ridge factor as report.json and the progress lines give it ("inf": no correction)."""
    return "inf" if math.isinf(factor) else f"{factor:g}"


@dataclass
class RidgeChoice:
    """The chosen factor and what decided it."""

    factor: float
    folds: int
    cv_rmse_nm: dict = field(default_factory=dict)     # {factor: cross-validated RMSE}

    def to_json(self) -> dict:
        return {"ridge_factor": ridge_label(self.factor), "folds": self.folds,
                "cv_rmse_nm": {ridge_label(f): v for f, v in self.cv_rmse_nm.items()},
                "fitted": math.isfinite(self.factor)}


def fold_index(run_index, rows) -> np.ndarray:
    """Per row, the number of its contiguous stretch of ``rows`` within one run (-1 off them)."""
    rows = np.asarray(rows, bool)
    run = np.asarray(run_index)
    start = rows & ~np.concatenate([[False], rows[:-1] & (run[1:] == run[:-1])])
    folds = np.cumsum(start) - 1
    return np.where(rows, folds, -1)


def cross_validated_rmse(jac: np.ndarray, resid0: np.ndarray, folds: np.ndarray, ridge: float,
                         factors=FACTORS) -> dict:
    """{factor: RMSE of the folds predicted by the ridged linear fit on the others}. ``jac``:
    rows x N_CORR, ``resid0``: measured - predicted at no correction, ``ridge``: the weight at
    factor 1 for all rows (scaled with the square root of the rows a fit uses)."""
    n = resid0.size
    out = {}
    for f in factors:
        sse = 0.0
        for k in range(int(folds.max()) + 1):
            test = folds == k
            train = ~test
            if math.isinf(f):
                delta = np.zeros(jac.shape[1])
            else:
                lam2 = (f * ridge) ** 2 * train.sum() / n
                a = jac[train].T @ jac[train] + lam2 * np.eye(jac.shape[1])
                delta = np.linalg.solve(a, jac[train].T @ resid0[train])
            sse += float(np.sum((resid0[test] - jac[test] @ delta) ** 2))
        out[f] = math.sqrt(sse / n)
    return out


def choose_ridge_factor(base, campaign, fit_mask, noise_sigma_nm: float) -> RidgeChoice:
    """The friction correction's ridge factor (module doc) for the model ``base`` (without a
    correction) on the fitted rows ``fit_mask``."""
    obj = CampaignObjective(base, campaign, fit_mask, None, [], True, noise_sigma_nm)
    rows = obj.mask
    folds = fold_index(campaign.run_index, rows)
    n_folds = int(folds.max()) + 1
    if n_folds < 2:
        return RidgeChoice(1.0, n_folds)
    xs = np.vstack([np.zeros(N_CORR), STEP * np.eye(N_CORR)])
    preds = obj.predict(xs)
    jac = ((preds[1:] - preds[0][None, :]) / STEP).T[rows]
    resid0 = np.asarray(campaign.torque_measured, float)[rows] - preds[0][rows]
    ok = np.isfinite(resid0) & np.all(np.isfinite(jac), axis=1)
    cv = cross_validated_rmse(jac[ok], resid0[ok], folds[rows][ok], obj.ridge)
    best = min(cv.values())
    factor = max(f for f, v in cv.items() if v * v <= best * best * (1 + RELATIVE_TIE))
    return RidgeChoice(factor, n_folds, cv)


def without_correction(fit):
    """The model of a fit (fitting.CandidateFit) with its friction correction taken out (the
    correction is additive in a0..a19), or None when it has none."""
    if not getattr(fit, "joint", False) or getattr(fit, "friction_correction", None) is None:
        return None
    delta = np.asarray(fit.friction_correction, float)
    a = np.asarray(fit.model.friction_coefficients, float)
    return fit.model.with_friction(a=a - apply_friction_correction(np.zeros_like(a), delta))


def held_to_the_data(fit, campaign, fit_mask, energy_total_j: float, torque_scale: float,
                     noise_sigma_nm: float):
    """A fit to be written (the calibrated model, the extended one) with its friction correction
    refitted at the ridge the data support (choose_ridge_factor on the fit's model without the
    correction; its mechanisms as fitted) -> (fit, RidgeChoice or None when it has no
    correction). At factor 1 the fit is returned as it is."""
    base = without_correction(fit)
    if base is None:
        return fit, None
    choice = choose_ridge_factor(base, campaign, fit_mask, noise_sigma_nm)
    if choice.factor == 1.0:
        return fit, choice
    refit = fit_candidate(base, campaign, fit_mask, None, energy_total_j, torque_scale,
                          noise_sigma_nm=noise_sigma_nm, ridge_factor=choice.factor)
    refit.id, refit.parameters, refit.co_parameters = fit.id, dict(fit.parameters), dict(fit.co_parameters)
    return refit, choice

