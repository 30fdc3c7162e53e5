"""The one least-squares objective on measured torque (car-data calibration and diagnosis).

    r(x) = (predicted(x) - measured)[mask] / scale   ++   ridge * (x[ridge_index] - ridge_center)
                                                    ++   prior @ (x[ridge_index] - ridge_center)

``predict(xs)`` maps parameter vectors to predicted *measured* torque on the whole campaign
(one row per x, through ``clutch_model.prediction.predict_campaign``), so the Jacobian is a
forward difference computed as ONE batch over the perturbed parameter sets. For
``scipy.optimize.least_squares(obj.residuals, x0, jac=obj.jacobian, ...)``.
"""
from __future__ import annotations

import math

import numpy as np

NONFINITE_RESIDUAL = 1e3   # residual (in units of the noise scale) of a non-finite prediction


class TorqueLeastSquares:
    def __init__(self, predict, measured, mask, scale: float = 1.0, ridge: float = 0.0,
                 ridge_index=slice(None), ridge_center=0.0, steps=None, prior=None):
        self._predict = predict
        self.measured = np.asarray(measured, float)
        self.mask = np.asarray(mask, bool)
        self.scale = float(scale)
        self.ridge = float(ridge)
        self.ridge_index = ridge_index
        self.ridge_center = ridge_center
        # further linear pseudo-observations of the ridged parameters (rows x their count)
        self.prior = None if prior is None or np.size(prior) == 0 else np.atleast_2d(np.asarray(prior, float))
        self._steps = steps or (lambda x: np.full(x.size, 1e-4))
        self.evaluations = 0           # parameter sets simulated
        self.jacobians = 0
        self._cache_x = None
        self._cache_r = None

    @property
    def n_data(self) -> int:
        return int(self.mask.sum())

    def predict(self, xs) -> np.ndarray:
        """Predicted measured torque on the whole campaign, one row per x."""
        pred = self._predict(xs)
        self.evaluations += len(pred)
        return pred

    def data_residuals(self, preds) -> np.ndarray:
        """(predicted - measured)[mask] / scale of prediction rows (n_sets, n)."""
        r = (preds[:, self.mask] - self.measured[self.mask][None, :]) / self.scale
        # a parameter set whose simulation runs away (e.g. a friction term feeding its own
        # heat) predicts non-finite torque: a large finite misfit lets the solver step back
        return np.where(np.isfinite(r), r, NONFINITE_RESIDUAL)

    def residuals(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if self._cache_x is not None and np.array_equal(x, self._cache_x):
            return self._cache_r
        r = self.data_residuals(self.predict([x]))[0]
        if self.ridge:
            r = np.concatenate([r, self.ridge * (x[self.ridge_index] - self.ridge_center)])
        if self.prior is not None:
            r = np.concatenate([r, self.prior @ (x[self.ridge_index] - self.ridge_center)])
        self._cache_x, self._cache_r = x.copy(), r
        return r

    def data_rmse(self, x) -> float:
        """RMSE of predicted - measured torque over the mask at x."""
        r = self.residuals(x)[:self.n_data] * self.scale
        return float(math.sqrt(np.mean(r * r))) if r.size else math.nan

    def jacobian(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        r0 = self.residuals(x)
        steps = np.asarray(self._steps(x), float)
        xs = np.repeat(x[None, :], x.size, axis=0) + np.diag(steps)
        rs = self.data_residuals(self.predict(xs))
        n = rs.shape[1]
        jac = np.zeros((r0.size, x.size))
        jac[:n] = ((rs - r0[None, :n]) / steps[:, None]).T
        cols = np.arange(x.size)[self.ridge_index]
        if self.ridge:
            jac[n:n + cols.size, cols] = self.ridge * np.eye(cols.size)
        if self.prior is not None:
            jac[r0.size - self.prior.shape[0]:, cols] = self.prior
        self.jacobians += 1
        return jac
