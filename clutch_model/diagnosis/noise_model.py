"""A noise model for a residual series: autoregressive, fitted by Burg's method.

The residual of a good model (measured - predicted torque) is sensor noise, and car sensors
rarely give white noise: a first-order sensor filter makes it AR(1)-like (phi up to 0.95 at
fast logging), an anti-alias filter band-limits it, a slow sensor logged on a fast grid holds
each value, a median filter smooths it, and offsets drift slowly. One AR(p) model, its order
chosen by BIC, describes all of these well enough to predict the next sample from the past
ones; what it cannot predict (its innovations) is what any claimed structure must beat.

Samples are taken in their own order (the measured torque's own time stamps, regular or not):
the model is a sequence model, not a continuous-time one. A series is split into segments at
run starts and at missing values (NaN), each segment starting without history; Burg's lattice
pools the forward and backward errors of all segments, so short runs and long drives are
fitted alike, and the order-m predictors of the recursion give exact one-step predictions
for the first samples of a segment (the m-th sample is predicted from the m before it).

Burg rather than Yule-Walker: the Yule-Walker equations on a windowed autocorrelation bias
near-unit-root processes (phi = 0.95, held values, drifts) toward white noise; Burg's
estimates stay stable and close to least squares (statsmodels is not a dependency of the
project, and the recursion is a few lines of numpy).
"""
from __future__ import annotations

import math
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

DEFAULT_MAX_ORDER = 48
FLOOR_EXTRA_ORDER = 8     # a white floor turns AR(p) into ARMA(p, p): approximated by a longer AR


def segments_of(values: np.ndarray, run_start: np.ndarray | None = None, mask: np.ndarray | None = None) -> list:
    """(start, stop) index pairs of the maximal stretches of finite values (within ``mask``)
    that do not cross a run start."""
    x = np.asarray(values, float)
    ok = np.isfinite(x)
    if mask is not None:
        ok &= np.asarray(mask, bool)
    brk = np.zeros(x.size, bool)
    if run_start is not None:
        brk |= np.asarray(run_start, bool)
    okp = np.r_[False, ok]
    starts = np.flatnonzero(ok & (~okp[:-1] | brk))
    # a stretch ends before the next start or the next non-ok row
    stops = np.flatnonzero(np.r_[ok[1:] & ~brk[1:], False] == False)  # noqa: E712 (last row of a stretch)
    stops = stops[ok[stops]] + 1
    return list(zip(starts.tolist(), stops.tolist()))


@dataclass
class NoiseModel:
    """AR(p) noise: x_t = -sum_{k=1..p} a_k x_{t-k} + e_t, var(e_t) = innovation_variance.

    ``lattice[m]`` holds the order-m prediction-error filter [1, a_1..a_m] and
    ``order_variance[m]`` its error variance (m = 0: the variance of the series itself)."""

    a: np.ndarray                   # [1, a_1, ..., a_p]
    innovation_variance: float
    lattice: list
    order_variance: np.ndarray
    n_samples: int
    bic: float

    @property
    def order(self) -> int:
        return self.a.size - 1

    @property
    def variance(self) -> float:
        """Stationary variance of the fitted process (order-0 error variance)."""
        return float(self.order_variance[0])

    @property
    def innovation_sigma(self) -> float:
        return math.sqrt(self.innovation_variance)

    def innovations(self, x: np.ndarray, run_start: np.ndarray | None = None):
        """One-step prediction errors e and their model variances v, per row (NaN where x is
        NaN). A segment's k-th sample (k < p) is predicted by the order-k predictor."""
        x = np.asarray(x, float)
        e = np.full(x.size, np.nan)
        v = np.full(x.size, np.nan)
        p = self.order
        for a, b in segments_of(x, run_start):
            seg = x[a:b]
            e[a:b] = lfilter(self.a, [1.0], seg)
            m = min(p, b - a)
            for k in range(m):
                ak = self.lattice[k]
                e[a + k] = float(np.dot(ak, seg[k::-1][:ak.size]))
            v[a:b] = self.innovation_variance
            v[a:a + m] = self.order_variance[:m]
        return e, v

    def predict_one_step(self, x: np.ndarray, run_start: np.ndarray | None = None) -> np.ndarray:
        """x_hat_t = E[x_t | x_{t-1}, ...] (from the segment's own past)."""
        e, _ = self.innovations(x, run_start)
        return np.asarray(x, float) - e

    def forecast(self, history: np.ndarray, steps: int) -> np.ndarray:
        """Multi-step prediction: the next ``steps`` values after ``history`` (oldest first)."""
        h = list(np.asarray(history, float)[-self.order:]) if self.order else []
        coef = -self.a[1:]
        out = np.empty(steps)
        for j in range(steps):
            past = h[::-1][:self.order]
            val = float(np.dot(coef[:len(past)], past)) if past else 0.0
            out[j] = val
            h.append(val)
        return out

    def autocovariance(self, lags: int) -> np.ndarray:
        """Autocovariance of the fitted process at lags 0..lags."""
        return _autocovariance(self.lattice, self.order_variance, lags)

    def forecast_variance(self, steps: int) -> np.ndarray:
        """Variance of the h-step prediction error, h = 1..steps (psi-weights of the AR)."""
        psi = lfilter([1.0], self.a, np.r_[1.0, np.zeros(steps - 1)])
        return self.innovation_variance * np.cumsum(psi ** 2)

    def log_likelihood(self, x: np.ndarray, run_start: np.ndarray | None = None, mask=None) -> np.ndarray:
        """Per-row Gaussian log-likelihood of the one-step predictions (NaN outside mask)."""
        e, v = self.innovations(x, run_start)
        ll = -0.5 * (np.log(2 * np.pi * v) + e * e / v)
        if mask is not None:
            ll = np.where(mask, ll, np.nan)
        return ll


def _stable_reflection(k: float) -> float:
    """A reflection coefficient kept inside the unit interval (a stable filter)."""
    return min(max(k, -0.999999), 0.999999)


def _step_up(a: np.ndarray, e: float, k: float) -> tuple:
    """One order up of a prediction-error filter and its error variance with reflection
    coefficient k (shared by Burg's and Levinson-Durbin's recursions)."""
    ext = np.r_[a, 0.0]
    return ext + k * ext[::-1], e * (1.0 - k * k)


def _burg(segments: list, max_order: int):
    """Multi-segment Burg recursion -> (filters per order, error variance per order)."""
    f = [s.astype(float).copy() for s in segments]
    b = [s.astype(float).copy() for s in segments]
    n = sum(s.size for s in segments)
    e0 = sum(float(np.dot(s, s)) for s in segments) / max(n, 1)
    a = np.array([1.0])
    filters, var = [a], [e0]
    e = e0
    for m in range(1, max_order + 1):
        num = den = 0.0
        for fi, bi in zip(f, b):
            if fi.size <= m:
                continue
            ff, bb = fi[m:], bi[m - 1:-1]
            num += float(np.dot(ff, bb))
            den += float(np.dot(ff, ff) + np.dot(bb, bb))
        if den <= 0.0:
            break
        k = _stable_reflection(-2.0 * num / den)
        for fi, bi in zip(f, b):
            if fi.size <= m:
                continue
            ff = fi[m:].copy()
            bb = bi[m - 1:-1].copy()
            fi[m:] = ff + k * bb
            bi[m:] = bb + k * ff
        a, e = _step_up(a, e, k)
        filters.append(a)
        var.append(e)
    return filters, np.array(var)


def _autocovariance(filters: list, var: np.ndarray, lags: int) -> np.ndarray:
    """Autocovariance (lags 0..lags) of the AR model given by a Levinson/Burg recursion's
    prediction-error filters and error variances (step-up relations, then the AR recursion)."""
    p = len(filters) - 1
    g = np.zeros(lags + 1)
    g[0] = var[0]
    for m in range(1, min(p, lags) + 1):
        prev = filters[m - 1]
        k = filters[m][m]
        g[m] = -k * var[m - 1] - float(np.dot(prev[1:m], g[m - 1:0:-1]))
    a = filters[p]
    for m in range(p + 1, lags + 1):
        g[m] = -float(np.dot(a[1:], g[m - p:m][::-1]))
    return g


def _levinson(g: np.ndarray, order: int):
    """Levinson-Durbin on an autocovariance -> (filters per order, error variance per order)."""
    a = np.array([1.0])
    e = float(g[0])
    filters, var = [a], [e]
    for m in range(1, order + 1):
        delta = float(np.dot(a, g[m:0:-1]))
        a, e = _step_up(a, e, _stable_reflection(-delta / e if e > 0 else 0.0))
        filters.append(a)
        var.append(e)
    return filters, np.array(var)


_FLOOR_VARIANCE: ContextVar = ContextVar("noise_floor_variance", default=0.0)


@contextmanager
def white_floor(variance: float):
    """Within the block, every fitted noise model is floored with white noise of ``variance``
    (``with_white_floor``): the diagnosis's floor for the noise its model carries from its
    measured inputs (diagnosis.input_hold)."""
    token = _FLOOR_VARIANCE.set(max(float(variance), 0.0) if np.isfinite(variance) else 0.0)
    try:
        yield
    finally:
        _FLOOR_VARIANCE.reset(token)


def with_white_floor(nm: "NoiseModel", floor_variance: float) -> "NoiseModel":
    """The AR approximation of the noise model's spectrum plus white noise of
    ``floor_variance`` (AR(p) plus white noise is ARMA(p, p): approximated by AR(max(2p,
    p + FLOOR_EXTRA_ORDER)), at most DEFAULT_MAX_ORDER): its one-step predictions can never be
    better than that floor."""
    if not floor_variance > 0:
        return nm
    p = min(max(2 * nm.order, nm.order + FLOOR_EXTRA_ORDER), DEFAULT_MAX_ORDER)
    g = _autocovariance(nm.lattice, nm.order_variance, p)
    g[0] += floor_variance
    filters, var = _levinson(g, p)
    return NoiseModel(a=filters[p], innovation_variance=float(var[p]), lattice=filters, order_variance=var,
                      n_samples=nm.n_samples, bic=nm.bic)


def fit_noise_model(x: np.ndarray, run_start: np.ndarray | None = None, mask: np.ndarray | None = None,
                    max_order: int = DEFAULT_MAX_ORDER, criterion: str = "bic") -> NoiseModel:
    """Fit AR(p), p <= max_order by BIC (or AIC), to the finite rows of x inside mask, segments
    split at run starts. The series is taken as zero-mean noise: a mean is not removed (an
    offset is structure, for the candidates to explain)."""
    x = np.asarray(x, float)
    segs = [x[a:b] for a, b in segments_of(x, run_start, mask)]
    segs = [s for s in segs if s.size >= 2]
    n = sum(s.size for s in segs)
    if n < 10:
        raise ValueError("too few samples to fit a noise model")
    max_order = int(max(0, min(max_order, n // 10, max(s.size for s in segs) - 1)))
    filters, var = _burg(segs, max_order)
    var = np.maximum(var, 1e-300)
    # effective sample count of order m: the rows predicted with a full order-m history
    orders = np.arange(var.size)
    n_eff = np.array([sum(max(s.size - m, 0) for s in segs) for m in orders], float)
    pen = np.log(n_eff) if criterion == "bic" else 2.0
    ic = n_eff * np.log(var) + orders * pen
    p = int(np.argmin(ic))
    nm = NoiseModel(a=filters[p], innovation_variance=float(var[p]), lattice=filters[:p + 1],
                    order_variance=var[:p + 1], n_samples=n, bic=float(ic[p]))
    return with_white_floor(nm, _FLOOR_VARIANCE.get())
