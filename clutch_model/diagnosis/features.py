"""What the residual follows: the evidence behind a diagnosis.

Residual r = measured - predicted torque of the calibrated baseline. Each feature is a
signal on the campaign grid; we report how much of the residual's variance a small
regression on it explains (R^2, on the held-out runs, with coefficients fitted on the fit runs),
plus the classic views: lag cross-correlation, hysteresis loops, drift over the campaign.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from clutch_model.formats.bag_reader import Campaign

DIRECTION_BAND_FRAC = 0.03    # force_direction's play: this fraction of the force's 95th percentile...
DIRECTION_BAND_NOISE = 5.0    # ...or this many force-noise sigmas, the larger


@njit(cache=True)
def played_force(force, run_start, half_width_n):
    """The force through a play of constant half-width ``half_width_n``: it moves only when the
    input leaves [x - w, x + w]; each run starts at its first force (centred in the play)."""
    out = np.empty(force.size)
    x = 0.0
    for k in range(force.size):
        if k == 0 or run_start[k]:
            x = force[k]
        else:
            x = min(max(x, force[k] - half_width_n), force[k] + half_width_n)
        out[k] = x
    return out


def last_move_direction(force, run_start, band_n: float) -> np.ndarray:
    """The direction of the force's last move, in [-1, 1]: (F - play(F, b)) / b, a play of
    half-width ``band_n`` (b) restarted at each run's start. +1 while the force rises and after
    a rise, -1 while it falls and after a fall, in between over a reversal of less than 2 b."""
    f = np.ascontiguousarray(np.asarray(force, float))
    return (f - played_force(f, np.asarray(run_start, bool), float(band_n))) / float(band_n)


def force_direction(force: np.ndarray, run_start: np.ndarray) -> np.ndarray:
    """The direction of the force's last move (last_move_direction), with the play's half-width
    b DIRECTION_BAND_FRAC of the force's 95th percentile or DIRECTION_BAND_NOISE force-noise
    sigmas (first differences), the larger, so the sensor's noise does not flip it. The memory
    a hysteresis of either sign carries: a band the pack force trails (the catalog's) or one it
    leads (a force sensor that trails the pack force)."""
    f = np.nan_to_num(np.asarray(force, float))
    rs = np.asarray(run_start, bool)
    sigma = noise_sigma(f, rs)
    band = max(DIRECTION_BAND_FRAC * float(np.percentile(np.abs(f), 95)),
               DIRECTION_BAND_NOISE * (sigma if np.isfinite(sigma) else 0.0), 1e-9)
    return last_move_direction(f, rs, band)


def _finite_rows(residual, run_start):
    """The residual's finite rows in order, with the run starts carried over: differences are
    taken between consecutive *measured* rows (on a measured-time grid the rows between torque
    samples are NaN; lock-up rows are NaN too)."""
    r = np.asarray(residual, float)
    run_start = np.asarray(run_start, bool)
    ok = np.isfinite(r)
    if ok.all():
        return r, run_start
    run_id = np.cumsum(run_start)
    rid = run_id[ok]
    rs = np.ones(rid.size, bool)
    rs[1:] = rid[1:] != rid[:-1]
    return r[ok], rs


def noise_sigma(residual: np.ndarray, run_start: np.ndarray) -> float:
    """Sensor-noise level from the data: robust (MAD) scale of the first differences of the
    residual, / sqrt(2). Slow structure (calibration error, drift, offsets) cancels in the
    differences; isolated steps are outliers the median ignores."""
    r, run_start = _finite_rows(residual, run_start)
    d = np.diff(r)
    ok = np.isfinite(d) & ~run_start[1:]
    d = d[ok]
    if d.size < 10:
        return math.nan
    mad = np.median(np.abs(d - np.median(d)))
    return float(1.4826 * mad / math.sqrt(2.0))


def noise_ar1(residual: np.ndarray, run_start: np.ndarray) -> float:
    """Lag-one correlation phi of the noise, if it is AR(1)-like (a band-limited sensor), from
    the lag-one autocorrelation rho of the residual's first differences: rho = -(1 - phi)/2
    (-1/2 for white noise). Differences are clipped at 4 robust sigmas so model-error steps do
    not count. Clipped to [0, 0.9]."""
    r, run_start = _finite_rows(residual, run_start)
    d = np.diff(r)
    ok = np.isfinite(d) & ~run_start[1:]
    pair = ok[1:] & ok[:-1]
    if pair.sum() < 50:
        return 0.0
    scale = 1.4826 * np.median(np.abs(d[ok] - np.median(d[ok]))) or 1.0
    dc = np.clip(np.where(ok, d, 0.0), -4 * scale, 4 * scale)
    rho = float(np.sum(dc[1:] * dc[:-1] * pair) / np.sum(dc[ok] ** 2))
    return float(min(max(1.0 + 2.0 * rho, 0.0), 0.9))


def noise_profile(residual: np.ndarray, t: np.ndarray, run_start: np.ndarray, block_s: float = 1.0):
    """Per-row noise level: the MAD estimate of noise_sigma() over consecutive block_s windows
    of each run, so noise that differs from run to run (or grows with the torque level) is
    not mistaken for structure, corrected for AR(1)-correlated noise (differences of such noise
    have variance 2 sigma^2 (1 - phi), not 2 sigma^2). Falls back to the campaign-wide estimate
    for short blocks."""
    r = np.asarray(residual, float)
    out = np.full(r.size, noise_sigma(r, run_start))
    starts = np.flatnonzero(run_start)
    ends = np.append(starts[1:], r.size)
    for a, b in zip(starts, ends):
        block = np.floor((t[a:b] - t[a]) / block_s).astype(np.int64)
        for k in np.unique(block):
            rows = a + np.flatnonzero(block == k)
            d = np.diff(r[rows][np.isfinite(r[rows])])   # consecutive measured rows
            d = d[np.isfinite(d)]
            if d.size >= 20:
                out[rows] = _robust_rms(d) / math.sqrt(2.0)
    return out / math.sqrt(1.0 - noise_ar1(r, run_start))


def _robust_rms(d: np.ndarray) -> float:
    """RMS of d after dropping outliers beyond 5 MAD-sigmas (model-error steps): nearly the
    efficiency of the plain RMS for Gaussian noise (MAD alone has 37 %, which made the noise
    floor of three held-out runs uncertain by +-5 %)."""
    s0 = 1.4826 * np.median(np.abs(d - np.median(d)))
    if s0 <= 0:
        return float(np.sqrt(np.mean(d ** 2)))
    kept = d[np.abs(d - np.median(d)) <= 5.0 * s0]
    return float(np.sqrt(np.mean((kept - np.mean(kept)) ** 2)))


NEAR_STAMP_FRAC = 0.05   # samples closer than this share of the median interval nearly coincide


def time_derivative(y, t) -> np.ndarray:
    """dy/dt at each sample of one stretch: np.gradient's (second order on uneven samples),
    except beside two stamps that nearly coincide (closer than NEAR_STAMP_FRAC of the median
    interval), where it is the difference across the sample's two neighbours (0 where they
    share a stamp). A torque topic may stamp a sample twice, 2 ns apart, and np.gradient then
    takes the rate from the 2 ns side: on an outside generator's drive (230 such pairs in a
    151 s bag at 930 Hz) a rounding difference of the prediction there read as a rate of some
    1e5 N*m/s, the sub-row timing allowance (selection.sub_row_timing) turned it into a 23 N*m
    spike on two rows, and a 0.7 % force hysteresis without that spike took the name on it
    (89 % of its held-out log-likelihood gain)."""
    y = np.asarray(y, float)
    t = np.asarray(t, float)
    h = np.diff(t)
    pos = h[h > 0]
    if not pos.size:
        return np.zeros(y.size)
    near = h < NEAR_STAMP_FRAC * float(np.median(pos))
    if not near.any():
        return np.gradient(y, t)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.gradient(y, t)
    beside = np.zeros(y.size, bool)
    beside[:-1] |= near
    beside[1:] |= near
    lo = np.maximum(np.arange(y.size) - 1, 0)
    hi = np.minimum(np.arange(y.size) + 1, y.size - 1)
    span = t[hi] - t[lo]
    wide = np.where(span > 0, (y[hi] - y[lo]) / np.where(span > 0, span, 1.0), 0.0)
    out[beside] = wide[beside]
    out[~np.isfinite(out)] = 0.0
    return out


def _per_run_gradient(y, t, run_start):
    out = np.zeros_like(y)
    starts = np.flatnonzero(run_start)
    ends = np.append(starts[1:], y.size)
    for a, b in zip(starts, ends):
        if b - a > 2:
            out[a:b] = time_derivative(y[a:b], t[a:b])
    return out


def _smooth(y, run_start, width):
    """Centered moving average per run."""
    out = np.empty_like(y)
    starts = np.flatnonzero(run_start)
    ends = np.append(starts[1:], y.size)
    k = np.ones(width) / width
    for a, b in zip(starts, ends):
        seg = y[a:b]
        if seg.size >= width:
            pad = np.pad(seg, (width // 2, width - 1 - width // 2), mode="edge")
            out[a:b] = np.convolve(pad, k, mode="valid")
        else:
            out[a:b] = seg.mean()
    return out


@dataclass
class FeatureSet:
    names: list
    columns: dict           # name -> (n, k) design block


def feature_signals(campaign: Campaign, sim) -> dict:
    """Signals a residual may follow, each as a design block (columns)."""
    c = campaign
    t, f, w = c.t, np.maximum(c.force, 0.0), c.slip
    theta = sim.pack_temperature_c
    torque = sim.torque_nm
    dfdt = _per_run_gradient(_smooth(f, c.run_start, 5), t, c.run_start)
    # direction of the last force change (hysteresis memory): +1 after a rise, -1 after a fall
    direction = np.zeros_like(f)
    for a, b in _segments(c.run_start):
        last = 0.0
        for k in range(a, b):
            if dfdt[k] > 2e3:
                last = 1.0
            elif dfdt[k] < -2e3:
                last = -1.0
            direction[k] = last
    angle = np.zeros_like(w)
    turning = np.zeros(w.size, bool)   # runs where the slip angle covers >= 3 revolutions
    for a, b in _segments(c.run_start):
        dt = np.diff(t[a:b], prepend=t[a])
        angle[a:b] = np.cumsum(w[a:b] * dt)
        turning[a:b] = np.ptp(angle[a:b]) >= 6 * np.pi
    p_mpa = sim.pressure_mpa
    scale_t = max(np.nanstd(torque), 1e-9)
    return {
        "constant offset": np.ones((t.size, 1)),
        "torque level": torque[:, None] / scale_t,
        "force": f[:, None] / max(f.max(), 1.0),
        "force rate dF/dt": dfdt[:, None] / max(np.abs(dfdt).max(), 1.0),
        "force direction (hysteresis)": (direction * f)[:, None] / max(f.max(), 1.0),
        "slip speed": w[:, None] / max(np.abs(w).max(), 1e-9),
        "pack temperature": (theta - 60.0)[:, None] / 100.0,
        "dissipated energy (campaign)": (sim.energy_j / max(sim.energy_j.max(), 1.0) * torque)[:, None] / scale_t,
        "pressure x temperature": (p_mpa * (theta - 60.0) / 100.0 * torque)[:, None] / scale_t,
        "slip angle (once per rev)": (np.column_stack([np.sin(angle), np.cos(angle)])
                                      * (torque * turning)[:, None] / scale_t),
        "time in run": _time_in_run(t, c.run_start)[:, None],
    }


def _segments(run_start):
    starts = np.flatnonzero(run_start)
    ends = np.append(starts[1:], run_start.size)
    return list(zip(starts, ends))


def _time_in_run(t, run_start):
    out = np.empty_like(t)
    for a, b in _segments(run_start):
        out[a:b] = (t[a:b] - t[a]) / max(t[b - 1] - t[a], 1e-9)
    return out


PER_RUN_FEATURES = ("slip angle (once per rev)",)


def _slow_per_run_basis(time_in_run):
    return np.column_stack([np.ones_like(time_in_run), time_in_run, time_in_run ** 2])


def explained_variance(residual, features: dict, run_index) -> dict:
    """Share of the residual's variance (about zero) that a least-squares fit on each feature
    block explains, over the whole campaign (evidence, not a test). Phase-like features (slip
    angle) are fitted per run, since their phase is arbitrary from run to run, and are credited
    only with what they add to a slow per-run trend (1, t, t^2): at low slip one revolution
    spans a whole run and would otherwise pass for any slow drift."""
    out = {}
    ok = np.isfinite(residual)
    r = residual[ok]
    denom = float(np.dot(r, r))
    if denom <= 0:
        return {name: 0.0 for name in features}
    runs = run_index[ok]
    slow = _slow_per_run_basis(features["time in run"][ok, 0]) if "time in run" in features else None

    def per_run_sse(A):
        sse = 0.0
        for g in np.unique(runs):
            sel = runs == g
            coef, *_ = np.linalg.lstsq(A[sel], r[sel], rcond=None)
            sse += float(np.sum((r[sel] - A[sel] @ coef) ** 2))
        return sse

    for name, X in features.items():
        A = X[ok]
        if name in PER_RUN_FEATURES and slow is not None:
            out[name] = max(0.0, (per_run_sse(slow) - per_run_sse(np.column_stack([slow, A]))) / denom)
            continue
        if name != "constant offset":
            A = np.column_stack([A, np.ones(A.shape[0])])
        coef, *_ = np.linalg.lstsq(A, r, rcond=None)
        out[name] = max(0.0, 1.0 - float(np.sum((r - A @ coef) ** 2)) / denom)
    return out


def lag_cross_correlation(measured, predicted, run_start, dt, max_lag_s=0.5):
    """Lag (s) maximising the correlation of the measured torque's derivative with the
    predicted one's (positive: the measurement lags the model)."""
    lags = np.arange(-int(max_lag_s / dt), int(max_lag_s / dt) + 1)
    m = np.nan_to_num(np.diff(measured))
    p = np.nan_to_num(np.diff(predicted))
    keep = ~run_start[1:]
    m = np.where(keep, m, 0.0)
    p = np.where(keep, p, 0.0)
    corr = np.array([np.dot(m[max(0, L):m.size + min(0, L)], p[max(0, -L):p.size - max(0, L)]) for L in lags])
    norm = np.sqrt(np.dot(m, m) * np.dot(p, p)) or 1.0
    corr = corr / norm
    return lags * dt, corr


def drift_per_run(campaign: Campaign, residual, predicted):
    """Per run: mean residual relative to the mean predicted torque (a drift indicator)."""
    rows = []
    for r, sl in campaign.slices():
        res = residual[sl]
        ok = np.isfinite(res)
        pred = predicted[sl][ok]
        rows.append((r.name, float(np.mean(res[ok])) if ok.any() else math.nan,
                     float(np.mean(res[ok]) / max(np.mean(np.abs(pred)), 1e-9)) if ok.any() else math.nan))
    return rows
