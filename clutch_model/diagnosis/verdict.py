"""The decision: which cause, if any, the held-out evidence supports.

Inputs are held-out residuals (measured - predicted) of the calibrated baseline and of each
refitted candidate, and the noise level sigma estimated from the data. Rules:

1. structure: the baseline's held-out mean-square error must exceed the noise floor by more
   than STRUCTURE_MIN (relative) for `unexplained`, and by NAMED_MIN for a named cause; below
   that the verdict is `none`;
2. a candidate wins if its held-out gain is significant against the noise and it removes at
   least EXPLAIN_MIN of the excess mean-square error above the noise floor. Significance: the
   candidate's correction c = (its prediction - the baseline's) was fitted on other runs, so
   under "the baseline residual r is noise" the matched-filter statistic
   z = sum(r c) / (sigma sqrt(sum c^2)) is standard normal; we ask z > Z_MIN, and, as a guard
   against noise that is not white, also a positive one-sided t statistic on per-block
   (BLOCK_S seconds) mean gains (t > T_MIN);
   among winners the lowest held-out RMSE is named;
3. structure without a winner is `unexplained` -- if it is also material: its RMS must exceed
   MATERIAL of the held-out torque's RMS (a 0.2 % friction misfit is not a discovery, even when
   the sensor is so quiet that it stands far above the noise).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

STRUCTURE_MIN = 0.12   # unexplained: baseline MSE must exceed the noise floor by 12 %
NAMED_MIN = 0.03       # a named cause: by 3 % (and the cause must explain half of it)
MATERIAL = 0.003       # unexplained structure must exceed 0.3 % of the torque (RMS)
EXPLAIN_MIN = 0.5      # a cause must remove half of the excess MSE
Z_MIN = 5.0            # matched-filter z of the held-out gain
T_MIN = 1.0            # block t statistic of the held-out gain (guard)
BLOCK_S = 1.0


@dataclass
class CandidateScore:
    id: str
    rmse: float
    gain_ms: float          # baseline MSE - candidate MSE (held-out)
    explained: float        # gain_ms / excess MSE of the baseline
    t_stat: float
    z_stat: float
    significant: bool


def blocks(t, eval_mask, run_index, block_s=BLOCK_S):
    """Block labels (-1 outside the held-out rows): consecutive block_s windows per run."""
    lab = np.full(t.size, -1, dtype=np.int64)
    nxt = 0
    for j in np.unique(run_index[eval_mask]):
        rows = np.flatnonzero(eval_mask & (run_index == j))
        if rows.size == 0:
            continue
        tb = np.floor((t[rows] - t[rows[0]]) / block_s).astype(np.int64)
        lab[rows] = nxt + tb
        nxt += int(tb.max()) + 1
    return lab


def block_t(d, labels):
    ok = labels >= 0
    if not ok.any():
        return 0.0
    lab = labels[ok]
    vals = d[ok]
    sums = np.bincount(lab, weights=vals)
    counts = np.bincount(lab)
    means = sums[counts > 0] / counts[counts > 0]
    if means.size < 3:
        return 0.0
    sd = means.std(ddof=1)
    if sd == 0:
        return math.inf if means.mean() > 0 else 0.0
    return float(means.mean() / (sd / math.sqrt(means.size)))


def score_candidates(base_resid, cand_resids: dict, sigma_rows, labels, noise_phi: float = 0.0):
    """sigma_rows: the noise level per row (features.noise_profile); noise_phi: its AR(1)
    correlation (features.noise_ar1), which inflates the variance of sum(r c) for slowly
    varying corrections c by (1 + phi)/(1 - phi)."""
    inflation = math.sqrt((1.0 + noise_phi) / (1.0 - noise_phi))
    ok = labels >= 0
    ok &= np.isfinite(base_resid)
    mse0 = float(np.mean(base_resid[ok] ** 2))
    noise_ms = float(np.mean(sigma_rows[ok] ** 2))
    excess = mse0 - noise_ms
    scores = []
    for cid, r in cand_resids.items():
        okc = ok & np.isfinite(r)
        mse = float(np.mean(r[okc] ** 2))
        d = np.where(okc, base_resid ** 2 - np.nan_to_num(r) ** 2, 0.0)
        t = block_t(d, np.where(okc, labels, -1))
        c = np.where(okc, base_resid - np.nan_to_num(r), 0.0)   # candidate's correction
        cc = float(np.dot(c, c))
        cs = float(np.dot(c * c, np.where(okc, sigma_rows, 0.0) ** 2))
        z = float(np.dot(np.where(okc, base_resid, 0.0), c) / (inflation * math.sqrt(cs))) if cs > 0 else 0.0
        gain = mse0 - mse
        explained = gain / excess if excess > 0 else 0.0
        scores.append(CandidateScore(cid, math.sqrt(mse), gain, explained, t, z,
                                     significant=bool(z > Z_MIN and t > T_MIN and gain > 0)))
    return mse0, excess, noise_ms, sorted(scores, key=lambda s: s.rmse)


def decide(mse0, excess, noise_ms, scores, torque_ms=0.0):
    """-> (cause id, winning score or None, reason). torque_ms: mean square of the held-out
    measured torque (materiality of unexplained structure)."""
    rel = excess / noise_ms if noise_ms > 0 else math.inf
    winners = [s for s in scores if s.significant and s.explained >= EXPLAIN_MIN]
    if winners and rel >= NAMED_MIN:
        best = winners[0]
        return best.id, best, (f"{best.id} removes {100 * best.explained:.0f} % of the excess error "
                               f"(z = {best.z_stat:.1f}, block t = {best.t_stat:.1f})")
    if rel < STRUCTURE_MIN:
        return "none", None, (f"held-out mean-square error is only {100 * rel:.1f} % above the noise floor "
                              f"(threshold {100 * STRUCTURE_MIN:.0f} %) and no candidate removes most of it")
    if excess < MATERIAL ** 2 * torque_ms:
        return "none", None, (f"the structure above the noise floor has an RMS of {math.sqrt(max(excess, 0.0)):.2f} N*m, "
                              f"below {100 * MATERIAL:.1f} % of the torque's RMS ({math.sqrt(torque_ms):.0f} N*m): "
                              f"calibration-level misfit, and no candidate removes most of it")
    return "unexplained", None, (f"held-out mean-square error is {100 * rel:.0f} % above the noise floor and no "
                                 f"candidate removes {100 * EXPLAIN_MIN:.0f} % of it significantly")
