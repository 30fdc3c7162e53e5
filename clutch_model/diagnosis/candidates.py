"""Catalog mechanisms as candidates of the forward selection (selection.Candidate).

A candidate is fitted on top of the model so far (the calibrated baseline, or the baseline
with the causes already named): ``fit`` moves the mechanism's own parameters with the friction
as it is (cheap: one parameter), ``refine`` refits them jointly with the baseline's friction
correction (fitting.fit_candidate), from the model so far and, at the first step, also from
the bench-fitted friction (a car calibration may have absorbed part of the mechanism).
Intervals: the Jacobian of the prediction at the fit (``sensitivity``), one batch of
perturbed simulations, for selection's cluster-robust sandwich.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clutch_model.diagnosis.fitting import CampaignObjective, CandidateFit, fit_candidate, search_space
from clutch_model.diagnosis.selection import ParameterSensitivity, SelectionData, TrainingSet


@dataclass
class CampaignContext:
    """What every mechanism fit on one campaign shares."""

    campaign: object               # formats.bag_reader.Campaign (locked rows: NaN torque)
    energy_total_j: float
    torque_scale: float
    sigma_nm: float
    bench_model: object = None     # ClutchModel: a second start at the first step


@dataclass
class ModelFit:
    """A fitted model (baseline or with mechanisms): selection.Fitted."""

    id: str
    fit: CandidateFit
    base_model: object             # the model the fit started from (its friction is what x corrects)
    context: CampaignContext
    mask: np.ndarray               # training rows it was fitted on

    @property
    def parameters(self) -> dict:
        return dict(self.fit.parameters)

    @property
    def model(self):
        return self.fit.model

    def predict(self, data: SelectionData = None) -> np.ndarray:
        return self.fit.predicted

    def sensitivity(self):
        """d(prediction)/dx at the fit, x = the mechanism's parameters in their search transform
        (then the friction correction, if it was refitted): forward differences, one batch."""
        if self.id == "baseline":
            return None
        ctx = self.context
        specs = search_space(self.id, ctx.campaign, ctx.energy_total_j, ctx.torque_scale)
        obj = CampaignObjective(self.base_model, ctx.campaign, self.mask, self.id, specs,
                                fit_friction=self.fit.joint, noise_sigma_nm=ctx.sigma_nm)
        x = np.array([s.to_x(self.fit.parameters[s.name]) for s in specs]
                     + (list(self.fit.friction_correction) if self.fit.joint else []), float)
        steps = np.where(np.arange(x.size) < len(specs), 1e-3 * np.maximum(np.abs(x), 1.0), 1e-4)
        lo, hi = obj.bounds()
        steps = np.where(x + steps > hi, -steps, steps)
        xs = np.vstack([x, x[None, :] + np.diag(steps)])
        preds = obj.predict(xs)
        jac = ((preds[1:] - preds[0][None, :]) / steps[:, None]).T
        return ParameterSensitivity([s.name for s in specs], x, jac, [s.from_x for s in specs], estimator="ols")


def baseline_fit(calibrated: CandidateFit, base_model, context: CampaignContext, mask) -> ModelFit:
    return ModelFit("baseline", calibrated, base_model, context, mask)


@dataclass
class MechanismCandidate:
    """One catalog mechanism as a candidate (selection.Candidate)."""

    id: str
    context: CampaignContext

    def _fit(self, base_model, train: TrainingSet, joint: bool, start=None) -> ModelFit:
        ctx = self.context
        fit = fit_candidate(base_model, ctx.campaign, train.mask, self.id, ctx.energy_total_j, ctx.torque_scale,
                            fit_friction=joint, noise_sigma_nm=ctx.sigma_nm, start=start)
        return ModelFit(self.id, fit, base_model, ctx, np.asarray(train.mask, bool).copy())

    def fit(self, train: TrainingSet) -> ModelFit:
        """The mechanism alone on the model so far; at the first step also on the bench
        friction (a car calibration may have absorbed part of the mechanism: a preload reads
        as less friction), the better on the training rows kept."""
        best = self._fit(train.base.model, train, joint=False)
        ctx = self.context
        if not train.selected and ctx.bench_model is not None:
            alt = self._fit(ctx.bench_model.with_mechanisms(list(train.base.model.mechanisms)), train, joint=False)
            if alt.fit.fit_rmse_nm < best.fit.fit_rmse_nm:
                best = alt
        return best

    def refine(self, fitted: ModelFit, train: TrainingSet) -> ModelFit:
        ctx = self.context
        # the baseline's friction before its correction (refitted jointly), else the model so far
        bases = [train.base.base_model if train.base.id == "baseline" else train.base.model]
        if not train.selected and ctx.bench_model is not None:
            bases.append(ctx.bench_model.with_mechanisms(list(train.base.model.mechanisms)))
        best = None
        for base in bases:
            start = fitted.parameters
            if base is not bases[0]:          # the bench friction: the mechanism alone first
                start = self._fit(base, train, joint=False).parameters
            cand = self._fit(base, train, joint=True, start=start)
            if best is None or cand.fit.fit_rmse_nm < best.fit.fit_rmse_nm:
                best = cand
        return best
