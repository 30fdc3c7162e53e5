"""A friction level that differs from run to run (lining or oil state of the day).

No input predicts such a level from one run to the next, so neither a candidate nor the
flexible residual model sees it on held-out runs; yet it is not noise: within a run, one
stretch's level predicts the others'. The test is a one-way analysis of variance of the level
over runs, with pieces of each run as the replicates:

- each run's scored rows are cut into ``PIECES_PER_RUN`` pieces of at least ``MIN_PIECE_S``;
- on each piece the residual is regressed on an offset, a slope in time and the model's own
  torque (generalised least squares, whitened with a noise model fitted to the residual); the
  torque coefficient is the piece's relative level (residual = level × torque: a friction
  scale), with its standard error. The piece's own offset and slope take slow sensor drift,
  which a mostly positive torque would otherwise pass for a level;
- each run's level is the inverse-variance weighted mean of its pieces; F = the between-run
  weighted mean square / the within-run one (the pieces' scatter about their run's mean, which
  rescales standard errors that a noise model got wrong by a factor), on (R - 1, pieces - R)
  degrees of freedom; the level's between-run standard deviation is the DerSimonian-Laird
  random-effects estimate with the rescaled errors.

The selection runs it twice (``run_level_tests``): with the pieces' regression whitened and
unweighted, each at ``ALPHA`` / 2 (whitening under band-limited noise weighs the frequencies
where a level has little of its signal).

A level is reported when F is significant at ``ALPHA`` and the between-run standard deviation
exceeds ``MIN_LEVEL_SD`` (materiality: a friction level is a few per cent; slow drift and
timing misfits leave far less on a torque of hundreds of N·m).

``selection.select_causes`` runs it on the baseline's residual over every scored row (training
and held-out) and uses it only where the verdict would otherwise be ``none``: a level found
turns it into ``unexplained`` with the levels in the reason (report.json
``selection.run_level`` always carries the figures). The calibration takes the training runs'
mean level, so what is left is their spread about it and the held-out runs' offsets.

Measured on the matrix campaigns (`--quick`, four seen runs, one held out): at campaign seed 2
the run_friction_level cells (spread 9.8 %; true seen-run levels 0.98, 1.06, 0.92, 0.99) give
F = 45 (lab), 27 (unaligned), 48 (drift) and 20 (median) on 3 and 12 dof, between-run sd
4.4-5.6 %: found; lock-up (p = 0.0015), AR(1) φ 0.95 noise (p = 0.004) and held noise
(p = 0.09): not found; one long drive has one level: nothing to compare. At
seed 1 the true seen-run levels differ by sd 2 % and the test finds none. On the campaigns
without an effect (eleven conditions at seed 2, ten at seed 1) the smallest p is 0.025 and
the largest between-run sd 0.7 %.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from clutch_model.diagnosis.noise_model import NoiseModel, fit_noise_model
from clutch_model.diagnosis.structure_test import PredictiveComparison, _whiten_columns, compare_residuals


ALPHA = 1e-3
MIN_LEVEL_SD = 0.02      # between-run standard deviation of the relative friction level
PIECES_PER_RUN = 4
MIN_PIECE_S = 1.5
MIN_PIECE_ROWS = 50
NUISANCE = 2             # per piece: offset and slope in time


@dataclass
class RunLevelResult:
    """Levels per run (relative: 0.05 = 5 % more torque than the model), the F test and the
    between-run standard deviation."""

    alpha: float = ALPHA                           # level of this test (halved when both weightings run)
    weighting: str = "whitened"                    # the pieces' regression: "whitened" (GLS) or "plain" (OLS)
    other: "RunLevelResult | None" = None          # the other weighting's result (run_level_tests)
    levels: list = field(default_factory=list)     # per run with pieces: mean relative level
    pieces: list = field(default_factory=list)     # per run: each piece's level
    f_stat: float = math.nan
    dof: tuple = (0, 0)
    p_value: float = 1.0
    between_sd: float = 0.0
    within_sd: float = math.nan                    # sd of one piece's level about its run's mean

    @property
    def found(self) -> bool:
        return bool(self.p_value < self.alpha and self.between_sd > MIN_LEVEL_SD)

    def as_dict(self) -> dict:
        out = {"levels": [round(v, 5) for v in self.levels], "f": self.f_stat, "dof": list(self.dof),
               "p": self.p_value, "alpha": self.alpha, "weighting": self.weighting,
               "between_run_sd": self.between_sd, "within_run_piece_sd": self.within_sd, "found": self.found}
        if self.other is not None:
            out["other_weighting"] = self.other.as_dict()
        return out


def _piece_level(r: np.ndarray, torque: np.ndarray, t: np.ndarray, noise: NoiseModel | None) -> tuple:
    """(level, its standard error) on one piece: GLS of the residual on offset, slope, torque."""
    tt = (t - t.mean()) / max(float(np.ptp(t)), 1e-9)
    cols = [np.ones_like(tt), tt][:NUISANCE]
    A = np.column_stack(cols + [torque, r])
    if noise is not None:
        A = _whiten_columns(noise, A, [(0, A.shape[0])])
    X, y = A[:, :-1], A[:, -1]
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    e = y - X @ beta
    s2 = float(e @ e) / max(y.size - X.shape[1], 1)
    try:
        cov = s2 * np.linalg.inv(X.T @ X)
    except np.linalg.LinAlgError:
        return float(beta[-1]), math.inf
    return float(beta[-1]), math.sqrt(max(float(cov[-1, -1]), 0.0))


def run_level_test(residual: np.ndarray, torque: np.ndarray, rows: np.ndarray, run_start: np.ndarray,
                   t: np.ndarray, pieces_per_run: int = PIECES_PER_RUN, whiten: bool = True) -> RunLevelResult:
    """Does the friction level differ from run to run? ``residual`` = measured − model torque,
    ``torque`` the model's torque on the same rows, ``rows`` the scored rows (no lock-up)."""
    r = np.asarray(residual, float)
    T = np.asarray(torque, float)
    t = np.asarray(t, float)
    ok = np.asarray(rows, bool) & np.isfinite(r) & np.isfinite(T)
    run_id = np.cumsum(np.asarray(run_start, bool)) - 1
    noise = fit_noise_model(r, run_start, ok) if whiten else None
    per_run = []
    for j in np.unique(run_id[ok]):
        idx = np.flatnonzero(ok & (run_id == j))
        if idx.size < pieces_per_run * MIN_PIECE_ROWS:
            continue
        span = float(t[idx[-1]] - t[idx[0]])
        k = min(pieces_per_run, int(span // MIN_PIECE_S))
        if k < 2:
            continue
        edges = np.linspace(t[idx[0]], t[idx[-1]], k + 1)
        lv = []
        for a, b in zip(edges[:-1], edges[1:]):
            sel = idx[(t[idx] >= a) & (t[idx] <= b)]
            if sel.size < MIN_PIECE_ROWS or np.ptp(T[sel]) <= 0:
                continue
            level, se = _piece_level(r[sel], T[sel], t[sel], noise)
            if math.isfinite(se) and se > 0:
                lv.append((level, se))
        if len(lv) >= 2:
            per_run.append(np.asarray(lv))          # rows: (level, standard error)
    # inverse-variance weights; the within-run scatter of the pieces about their run's mean
    # rescales the standard errors (a noise model that is off by a factor is off for both sides)
    w = [1.0 / v[:, 1] ** 2 for v in per_run]
    means = np.array([float(np.sum(wi * v[:, 0]) / np.sum(wi)) for wi, v in zip(w, per_run)])
    out = RunLevelResult(levels=[float(m) for m in means], pieces=[[float(x) for x in v[:, 0]] for v in per_run],
                         weighting="whitened" if whiten else "plain")
    R = len(per_run)
    if R < 2:
        return out
    W = np.array([float(np.sum(wi)) for wi in w])
    grand = float(np.sum(W * means) / W.sum())
    q_between = float(np.sum(W * (means - grand) ** 2))
    q_within = float(sum(np.sum(wi * (v[:, 0] - m) ** 2) for wi, v, m in zip(w, per_run, means)))
    df_b, df_w = R - 1, int(sum(v.shape[0] for v in per_run) - R)
    overdispersion = q_within / max(df_w, 1)
    out.f_stat = (q_between / df_b) / overdispersion if overdispersion > 0 else math.inf
    out.dof = (df_b, df_w)
    out.p_value = float(stats.f.sf(out.f_stat, df_b, df_w)) if math.isfinite(out.f_stat) else 0.0
    # between-run variance of the level (DerSimonian-Laird, standard errors rescaled)
    tau2 = (q_between - df_b * overdispersion) / max(W.sum() - float(np.sum(W ** 2)) / W.sum(), 1e-300)
    out.between_sd = math.sqrt(max(tau2, 0.0))
    out.within_sd = math.sqrt(overdispersion)    # piece scatter in units of its standard error
    return out


def run_level_tests(residual: np.ndarray, torque: np.ndarray, rows: np.ndarray, run_start: np.ndarray,
                    t: np.ndarray) -> RunLevelResult:
    """The level test with both weightings of the pieces' regression, each at ALPHA / 2: the
    found one (the smaller p when both or neither are), carrying the other in ``other``.

    Whitening is the efficient weighting when the noise model describes what the regression
    leaves; under band-limited sensor noise it weighs the frequencies above the band, where a
    friction level has little of its signal and the model's small timing misfits dominate.
    Measured on run_friction_level@lowpass#3 (true seen-run levels 1.056, 1.073, 0.927, 1.010):
    whitened piece levels scatter within a run by 5 standard errors (one piece at −0.77) and
    F = 3.2 (p = 0.06); unweighted, the levels relative to the first are +0.2, −10.2, −0.8 %
    (truth +1.6, −12.3, −4.4 %), F = 29.6 on 3 and 12 dof (p = 8e-6). The F test scales each
    weighting's standard errors by the pieces' own within-run scatter, so either is valid under
    coloured noise."""
    half = ALPHA / 2.0
    a = run_level_test(residual, torque, rows, run_start, t, whiten=True)
    b = run_level_test(residual, torque, rows, run_start, t, whiten=False)
    a.alpha = b.alpha = half
    first, second = (a, b) if (a.found, -a.p_value) >= (b.found, -b.p_value) else (b, a)
    first.other = second
    return first


@dataclass
class WithinRunForecast:
    """Each run's level fitted on its first half, used to predict its second half, without and
    with an extension's own change over the run (``within_run_forecast``)."""

    comparison: PredictiveComparison     # null: the level alone; alternative: with the extension
    runs: int
    residual_null: np.ndarray | None = None   # the second halves' errors, level alone (NaN elsewhere)
    residual_alt: np.ndarray | None = None    # ... with the extension's change
    rows: np.ndarray | None = None            # the second halves' rows

    def holds(self, alpha: float, min_gain_frac: float) -> bool:
        return self.runs > 0 and self.comparison.significant(alpha, min_gain_frac, plain_gain=True)


def within_run_forecast(measured: np.ndarray, residual_base: np.ndarray, residual_extension: np.ndarray,
                        rows: np.ndarray, run_start: np.ndarray, t: np.ndarray) -> WithinRunForecast:
    """Does an extension predict how the torque changes *within* a run, beyond a level of the run?

    A term in a quantity that grows over the campaign like a clock (the energy dissipated so
    far) fits any friction level that happens to rise or fall with the run order, and a whole
    run held out checks only that order: three seen runs have monotone levels one time in
    three. Within a run, such a term predicts a change that a level of the day does not. So on
    each run's scored rows, the first half (in time) fits the run's level and offset
    (measured − model ≈ a·torque + b, least squares) for the baseline's residual and for the
    extension's, and the second half is predicted: the extension's change over the run is
    kept, the level is not. The two forecasts are compared on the second halves as held-out
    rows (``structure_test.compare_residuals``: one AR noise model, block-robust t).

    Measured on run_friction_level@car#7 at full size (seen-run levels 1.017, 1.033, 1.047;
    "μ_f rises 30.6 % per MJ" fitted the held-out last seen run at t = 11.8 and made the unseen
    bag 56 % worse): within the runs t = 2.5, p = 0.008, second-half RMSE 7.26 → 7.33 N·m. The
    catalog's friction_degradation on its own case (friction_degradation@car#7): t = 13.8,
    second-half RMSE 9.69 → 7.13 N·m."""
    r0 = np.asarray(residual_base, float)
    r1 = np.asarray(residual_extension, float)
    T = np.asarray(measured, float) - r0
    t = np.asarray(t, float)
    ok = np.asarray(rows, bool) & np.isfinite(r0) & np.isfinite(r1) & np.isfinite(T)
    run_id = np.cumsum(np.asarray(run_start, bool)) - 1
    level0 = np.full_like(r0, np.nan)
    level1 = np.full_like(r0, np.nan)
    first = np.zeros(r0.size, bool)
    second = np.zeros(r0.size, bool)
    X = np.column_stack([T, np.ones_like(T)])
    runs = 0
    for j in np.unique(run_id[ok]):
        idx = np.flatnonzero(ok & (run_id == j))
        if idx.size < 2 * MIN_PIECE_ROWS:
            continue
        early = t[idx] < 0.5 * (t[idx[0]] + t[idx[-1]])
        a, b = idx[early], idx[~early]
        if a.size < MIN_PIECE_ROWS or b.size < MIN_PIECE_ROWS or np.ptp(T[a]) <= 0:
            continue
        for r, out in ((r0, level0), (r1, level1)):
            beta = np.linalg.lstsq(X[a], r[a], rcond=None)[0]
            out[idx] = r[idx] - X[idx] @ beta
        first[a] = True
        second[b] = True
        runs += 1
    return WithinRunForecast(compare_residuals(level0, level1, first, second, run_start, t), runs,
                             level0, level1, second)
