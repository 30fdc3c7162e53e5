"""Calibration of the friction coefficients on car-test runs (measured torque) — regression
counterpart of the thesis' Monte Carlo refinement (§5.3), beyond the thesis.

scipy.optimize.least_squares (trust-region reflective, bounded) on the one torque objective
(``objective.TorqueLeastSquares``): residuals are (predicted measured torque - measured
torque) / sqrt(n), plus a ridge toward a prior (the bench fit) in relative units; the Jacobian
is a forward difference computed as ONE batch-simulator call over the k perturbed parameter
sets. Only the coefficients the data can
identify move (``sensitivity.identifiability_screen`` unless given). The result must keep
mu_f >= 0 over P in [0, 6] MPa, theta in [0, 230] C, w in [0, 30] rad/s (§5.3 check,
``box.friction_positive``); if the optimum violates it, the step from the start is shortened
(bisection) until it holds.

Uncertainty: cov = s^2 (J'J)^-1 at the optimum (J of the data residuals w.r.t. the moved
coefficients, s^2 = SSR/(n - k)). It assumes white residuals; car-test residuals are
correlated in time (model error), so read it as a lower bound.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from clutch_model.errors import FitError
from clutch_model.plant.params import ClutchModel
from clutch_model.identification import box
from clutch_model.identification.evaluate import CampaignInputs, as_campaign, param_rows, predict, rmse_of
from clutch_model.identification.objective import TorqueLeastSquares


@dataclass(frozen=True)
class CalibrationResult:
    model: ClutchModel
    rmse_before: float
    rmse_after: float
    coefficients_moved: list
    a_before: np.ndarray
    a_after: np.ndarray
    stderr: np.ndarray                 # (20,), nan for coefficients that did not move
    covariance: np.ndarray             # (k, k) over coefficients_moved, coefficient units
    residual_std: float
    n_evaluations: int                 # parameter sets simulated (incl. the screen's)
    n_iterations: int
    positive: bool
    backtracked: float                 # fraction of the step kept (1 = full optimum)
    elapsed_s: float
    message: str = ""
    screen: object = None
    notes: list = field(default_factory=list)

    @property
    def correlation(self) -> np.ndarray:
        d = np.sqrt(np.clip(np.diag(self.covariance), 1e-300, None))
        return self.covariance / np.outer(d, d)

    def summary_lines(self) -> list:
        lines = [f"calibrate: torque RMSE {self.rmse_before:.3f} -> {self.rmse_after:.3f} N*m "
                 f"({self.n_evaluations} model evaluations, {self.n_iterations} iterations, {self.elapsed_s:.1f} s)",
                 "moved: " + (", ".join(f"a{k}" for k in self.coefficients_moved) or "none")]
        for k in self.coefficients_moved:
            rel = abs(self.stderr[k] / self.a_after[k]) if self.a_after[k] else math.inf
            lines.append(f"  a{k:<2d} {self.a_before[k]: .5e} -> {self.a_after[k]: .5e} +- {self.stderr[k]:.2e} "
                         f"(rel {rel:.1%}; {box.BLOCK_OF[k]}: {box.MONOMIAL[k % 5]})")
        lines.append(f"friction positive over P [0,6] MPa x theta [0,230] C x w [0,30] rad/s: {self.positive}"
                     + (f" (step shortened to {self.backtracked:.3f} of the optimum)" if self.backtracked < 1 else ""))
        lines += [f"note: {n}" for n in self.notes]
        return lines

    def to_json(self) -> dict:
        return {"rmse_before": self.rmse_before, "rmse_after": self.rmse_after,
                "coefficients_moved": [int(k) for k in self.coefficients_moved],
                "a_before": [float(x) for x in self.a_before], "a_after": [float(x) for x in self.a_after],
                "stderr": {f"a{k}": float(self.stderr[k]) for k in self.coefficients_moved},
                "correlation": np.round(self.correlation, 4).tolist() if self.coefficients_moved else [],
                "residual_std": self.residual_std, "n_evaluations": self.n_evaluations,
                "n_iterations": self.n_iterations, "positive": self.positive, "backtracked": self.backtracked,
                "elapsed_s": self.elapsed_s, "message": self.message, "notes": self.notes,
                "screen_selected": list(self.screen.selected) if self.screen is not None else None}


def coefficient_scale(a) -> np.ndarray:
    """Relative scale of each coefficient (|a_k|, floored where a_k ~ 0 by the value that moves
    its term by 1e-3 in mu over the car box)."""
    a = np.asarray(a, float)
    basis_max = np.tile([1.0, 6.0, 36.0, 230.0, 230.0 ** 2], 4)
    return np.maximum(np.abs(a), 1e-3 / basis_max)


def _positive_fraction(a_start, a_end, i, steps=30):
    """Largest t in [0, 1] (bisection) with a_start + t (a_end - a_start) friction-positive."""
    if box.friction_positive(a_end, i):
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        if box.friction_positive(a_start + mid * (a_end - a_start), i):
            lo = mid
        else:
            hi = mid
    return lo


# --- stages ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CoefficientChoice:
    """Stage 1: which coefficients move (identifiability screen or given)."""
    moved: tuple
    screen: object = None
    n_evaluations: int = 0


@dataclass(frozen=True)
class Coordinates:
    """The optimiser's coordinates: x_j = (a_k - a_start_k) / scale_k over the moved k."""
    a_start: np.ndarray
    idx: np.ndarray
    scale: np.ndarray

    def coeffs(self, x) -> np.ndarray:
        a = self.a_start.copy()
        a[self.idx] = self.a_start[self.idx] + self.scale * x
        return a

    def x_of(self, a) -> np.ndarray:
        return (np.asarray(a, float)[self.idx] - self.a_start[self.idx]) / self.scale


@dataclass(frozen=True)
class RegressionFit:
    """Stage 2: the bounded least-squares optimum."""
    a_opt: np.ndarray
    n_evaluations: int
    n_iterations: int
    message: str


@dataclass(frozen=True)
class PositiveStep:
    """Stage 3: the step kept so that friction stays positive over the car box."""
    a_after: np.ndarray
    fraction: float
    positive: bool
    notes: tuple = ()


@dataclass(frozen=True)
class Uncertainty:
    """Stage 4: RMSE and covariance at the result."""
    rmse_after: float
    covariance: np.ndarray
    stderr: np.ndarray
    residual_std: float
    n_evaluations: int
    notes: tuple = ()


def choose_coefficients(model: ClutchModel, campaign, inputs: CampaignInputs, coefficients="auto",
                        screen_kw: dict | None = None, say=lambda msg: None) -> CoefficientChoice:
    if isinstance(coefficients, str) and coefficients == "auto":
        from clutch_model.identification.sensitivity import identifiability_screen

        say("identifiability screen")
        screen = identifiability_screen(model, campaign, inputs=inputs, **(screen_kw or {}))
        return CoefficientChoice(tuple(screen.selected), screen, screen.n_simulations)
    moved = sorted({int(k) for k in coefficients})
    if any(k < 0 or k > 19 for k in moved):
        raise FitError("coefficient indices must be within 0..19")
    return CoefficientChoice(tuple(moved))


def fit_regression(coords: Coordinates, base_vector, inputs: CampaignInputs, rmse0: float, a_prior,
                   regularization: float, max_rel_change: float, fd_step: float, max_iterations: int,
                   say=lambda msg: None) -> RegressionFit:
    """Bounded least squares on the one torque objective, ridge toward ``a_prior``."""
    from scipy.optimize import least_squares

    n = int(inputs.mask.sum())

    def predict_rows(xs):
        return predict(param_rows(base_vector, np.array([coords.coeffs(x) for x in xs])), inputs)

    obj = TorqueLeastSquares(predict_rows, inputs.torque_measured, inputs.mask, scale=math.sqrt(n),
                             ridge=float(regularization) * rmse0, ridge_center=coords.x_of(a_prior),
                             steps=lambda x: np.full(x.size, fd_step))

    def jac(x):
        J = obj.jacobian(x)
        say(f"iteration {obj.jacobians}: RMSE {obj.data_rmse(x):.3f}")
        return J

    k = coords.idx.size
    res = least_squares(obj.residuals, np.zeros(k), jac=jac, bounds=(np.full(k, -max_rel_change),
                                                                      np.full(k, max_rel_change)),
                        method="trf", x_scale=1.0, max_nfev=max_iterations, xtol=1e-10, ftol=1e-10, gtol=1e-10)
    return RegressionFit(a_opt=coords.coeffs(res.x), n_evaluations=obj.evaluations, n_iterations=obj.jacobians,
                         message=str(res.message))


def keep_friction_positive(a_start, a_opt, i_exp: float) -> PositiveStep:
    """The largest part of the step a_start -> a_opt that keeps mu_f >= 0 over the car box."""
    if not box.friction_positive(a_start, i_exp):
        a_after = a_start + 1.0 * (a_opt - a_start)
        return PositiveStep(a_after, 1.0, bool(box.friction_positive(a_after, i_exp)),
                            ("the starting model's friction is already negative somewhere in the car box",))
    frac = _positive_fraction(a_start, a_opt, i_exp)
    notes = () if frac >= 1.0 else ("the unconstrained optimum makes mu_f negative somewhere in the car box; "
                                    f"kept {frac:.3f} of the step",)
    a_after = a_start + frac * (a_opt - a_start)
    return PositiveStep(a_after, frac, bool(box.friction_positive(a_after, i_exp)), notes)


def estimate_uncertainty(coords: Coordinates, base_vector, inputs: CampaignInputs, a_after,
                         fd_step: float) -> Uncertainty:
    """RMSE and cov = s^2 (J'J)^-1 at ``a_after`` (one batch: the result + k perturbations)."""
    idx, scale = coords.idx, coords.scale
    x_after = coords.x_of(a_after)
    A = [np.asarray(a_after, float)]
    for j in range(idx.size):
        xp = x_after.copy()
        xp[j] += fd_step
        A.append(coords.coeffs(xp))
    pred = predict(param_rows(base_vector, np.array(A)), inputs)
    meas = inputs.torque_measured[inputs.mask]
    r = pred[0][inputs.mask] - meas
    Ja = ((pred[1:, inputs.mask] - pred[0][inputs.mask][None, :]) / (fd_step * scale[:, None])).T   # dT/da
    s2 = float(r @ r) / max(meas.size - idx.size, 1)
    JtJ = Ja.T @ Ja
    notes = ()
    try:
        cov = s2 * np.linalg.inv(JtJ)
    except np.linalg.LinAlgError:
        cov = s2 * np.linalg.pinv(JtJ)
        notes = ("J'J singular at the optimum: covariance from the pseudo-inverse",)
    stderr = np.full(20, np.nan)
    stderr[idx] = np.sqrt(np.clip(np.diag(cov), 0, None))
    return Uncertainty(rmse_after=float(np.sqrt(np.mean(r ** 2))), covariance=cov, stderr=stderr,
                       residual_std=math.sqrt(s2), n_evaluations=len(A), notes=notes)


# --- the orchestrator ---------------------------------------------------------------------------------
def calibrate_friction(model: ClutchModel, runs_or_campaign, coefficients="auto", prior: ClutchModel | None = None,
                       regularization: float = 0.05, max_rel_change: float = 1.0, fd_step: float = 1e-4,
                       max_iterations: int = 40, rows=None, screen_kw: dict | None = None,
                       progress=None) -> CalibrationResult:
    """Refine the friction coefficients against the measured torque (see module doc), in
    stages: choose coefficients -> regression -> keep friction positive -> uncertainty.

    coefficients: "auto" (identifiability screen), or indices 0..19.
    prior: model whose coefficients the ridge pulls toward (default: ``model``, i.e. the bench fit).
    regularization: ridge weight; a relative change x of a coefficient costs
        (regularization * rmse_before * x)^2 in mean-square torque.
    rows: optional boolean mask over the campaign rows to fit on (e.g. hold runs out).
    """
    t0 = time.perf_counter()
    say = progress or (lambda msg: None)
    campaign = as_campaign(runs_or_campaign)
    inputs = CampaignInputs.from_campaign(campaign, model, rows=rows)
    base = model.vector()
    i_exp = model.friction_exponent
    a_start = model.friction_coefficients.copy()
    a_prior = (prior.friction_coefficients if prior is not None else a_start).copy()

    choice = choose_coefficients(model, campaign, inputs, coefficients, screen_kw, say)
    rmse0 = float(rmse_of(base, a_start[None, :], inputs)[0])
    if not choice.moved:
        return CalibrationResult(model=model.copy(), rmse_before=rmse0, rmse_after=rmse0, coefficients_moved=[],
                                 a_before=a_start, a_after=a_start.copy(), stderr=np.full(20, np.nan),
                                 covariance=np.zeros((0, 0)), residual_std=rmse0,
                                 n_evaluations=choice.n_evaluations + 1, n_iterations=0,
                                 positive=box.friction_positive(a_start, i_exp), backtracked=1.0,
                                 elapsed_s=time.perf_counter() - t0, screen=choice.screen,
                                 notes=["no coefficient is identifiable from these runs; model unchanged"])
    idx = np.array(choice.moved)
    coords = Coordinates(a_start=a_start, idx=idx, scale=coefficient_scale(a_start)[idx])
    fit = fit_regression(coords, base, inputs, rmse0, a_prior, regularization, max_rel_change, fd_step,
                         max_iterations, say)
    step = keep_friction_positive(a_start, fit.a_opt, i_exp)
    unc = estimate_uncertainty(coords, base, inputs, step.a_after, fd_step)
    return CalibrationResult(model=model.with_friction(a=step.a_after), rmse_before=rmse0,
                             rmse_after=unc.rmse_after, coefficients_moved=[int(k) for k in idx],
                             a_before=a_start, a_after=step.a_after, stderr=unc.stderr, covariance=unc.covariance,
                             residual_std=unc.residual_std,
                             n_evaluations=choice.n_evaluations + 1 + fit.n_evaluations + unc.n_evaluations,
                             n_iterations=fit.n_iterations, positive=step.positive, backtracked=step.fraction,
                             elapsed_s=time.perf_counter() - t0, message=fit.message, screen=choice.screen,
                             notes=[*step.notes, *unc.notes])
