"""Does a discovered extension hold on data the search never saw?

The interface is one callable, ``test(campaign, eval_mask, base_residual, candidate_residual)``
-> ``HeldOutVerdict``; ``discover`` takes any such test (the diagnosis' structure test plugs in
here). ``block_gain_test`` is the minimal one used when none is given:

* the candidate must lower the held-out mean-square error by at least GAIN_MIN_PCT of the
  baseline RMSE;
* significance that holds for coloured noise: a matched-filter statistic of the candidate's
  correction c = r0 − r1 (fitted on other data) against the baseline residual r0,
  z = Σ r0·c / sqrt(Σ_b (Σ_{i∈b} r1_i·c_i)²), its variance from the candidate's own residual
  summed over BLOCK_S spans of the held-out data (longer than the noise's correlation, so
  coloured noise is accounted for; r1, not r0, so the structure a good candidate explains does
  not inflate it). Under "r0 is noise" z is about standard normal; it must exceed Z_MIN;
* consistency across held-out runs (or spans): with three or more, the gain must be positive in
  at least RUN_SHARE_MIN of them, so structure that differs from run to run and that nothing in
  the inputs predicts (one run's friction level) cannot pass on one lucky run.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

GAIN_MIN_PCT = 2.0
Z_MIN = 5.0
RUN_SHARE_MIN = 2.0 / 3.0
BLOCK_S = 2.0


@dataclass
class HeldOutVerdict:
    accepted: bool
    gain_pct: float          # 100 (1 - rmse_candidate / rmse_base), held-out
    rmse_base_nm: float
    rmse_candidate_nm: float
    z_stat: float
    runs_improved: str       # "k/n"
    reason: str


def _blocks(t, rows, run_index, block_s):
    lab = np.full(t.size, -1, dtype=np.int64)
    nxt = 0
    for j in np.unique(run_index[rows]):
        sel = np.flatnonzero(rows & (run_index == j))
        tb = np.floor((t[sel] - t[sel[0]]) / block_s).astype(np.int64)
        lab[sel] = nxt + tb
        nxt += int(tb.max()) + 1
    return lab


def block_gain_test(campaign, eval_mask, base_residual, candidate_residual,
                    block_s: float = BLOCK_S) -> HeldOutVerdict:
    r0 = np.asarray(base_residual, float)
    r1 = np.asarray(candidate_residual, float)
    rows = np.asarray(eval_mask, bool) & np.isfinite(r0) & np.isfinite(r1)
    if rows.sum() < 10:
        return HeldOutVerdict(False, 0.0, math.nan, math.nan, 0.0, "0/0", "no held-out data")
    ms0, ms1 = float(np.mean(r0[rows] ** 2)), float(np.mean(r1[rows] ** 2))
    gain_pct = 100.0 * (1.0 - math.sqrt(ms1 / ms0)) if ms0 > 0 else 0.0
    run_index = np.asarray(campaign.run_index)
    lab = _blocks(np.asarray(campaign.t, float), rows, run_index, block_s)
    d = r0 ** 2 - r1 ** 2
    ok = lab >= 0
    c = np.where(ok, r0 - r1, 0.0)
    num = float(np.sum(np.where(ok, r0, 0.0) * c))
    block_sums = np.bincount(lab[ok], weights=(r1 * c)[ok])
    den = math.sqrt(float(np.sum(block_sums ** 2)))
    z_stat = num / den if den > 0 else (math.inf if num > 0 else 0.0)
    runs = np.unique(run_index[rows])
    improved = sum(float(np.mean(d[rows & (run_index == j)])) > 0 for j in runs)
    share_ok = runs.size < 3 or improved >= RUN_SHARE_MIN * runs.size
    accepted = bool(gain_pct >= GAIN_MIN_PCT and z_stat > Z_MIN and share_ok)
    if accepted:
        reason = (f"held-out RMSE {math.sqrt(ms0):.2f} -> {math.sqrt(ms1):.2f} N·m ({gain_pct:.1f} % lower), "
                  f"z = {z_stat:.1f}, better on {improved}/{runs.size} held-out runs")
    else:
        fails = []
        if gain_pct < GAIN_MIN_PCT:
            fails.append(f"held-out gain {gain_pct:.1f} % < {GAIN_MIN_PCT:g} %")
        if not z_stat > Z_MIN:
            fails.append(f"z = {z_stat:.1f} <= {Z_MIN:g}")
        if not share_ok:
            fails.append(f"better on only {improved}/{runs.size} held-out runs")
        reason = "; ".join(fails)
    return HeldOutVerdict(accepted, gain_pct, math.sqrt(ms0), math.sqrt(ms1), z_stat,
                          f"{improved}/{runs.size}", reason)
