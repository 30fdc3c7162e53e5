"""A logger pause: every input topic silent at once inside a bag, while the clutch ran on.

A recorder that stalls (a disk write, a gateway reset) loses the force and the slip together
for a second or more; the clutch did not stop. The plant is carried across the pause with the
last inputs held (as ``replay`` reads a bag), so whatever heat the pack really took in during
the pause is a guess, and the pack temperature after it is off by up to the pause's heat over
the plates' heat capacity. That error decays only with the pack's thermal time constant
(C / (H_tf·A_N), 40-80 s on the reference clutch), and each kelvin moves the friction by
0.2-0.4 % there: measured on an outside generator's campaign with nothing hidden (pauses of
1.1-2.4 s in four of six bags, torque noise 1 N·m), the calibrated model was 3-8 N·m off for
the rest of a bag after its pause against 1.5-3 N·m before it, the calibration bent to those
rows, its held-out RMSE rose above the uncalibrated model's, and a spring preload was named
on a campaign that had none.

Those rows say nothing about the clutch: they are kept out of every residual, like locked
rows (``without_rows_after_pauses``), from the pause to where the bound on the pack
temperature's error has decayed below ``PACK_TOLERANCE_K``:

    bound(t) = P_near · pause / (N_sp · C) · exp(−∫ A_N · H_tf(|ω|, F) / C dt),

P_near the largest slip power |ω·T| measured within ``POWER_WINDOW_S`` of the pause (the
power the clutch may have kept up through it), H_tf the plant's own heat-transfer law at each
row's slip and force. The plant still runs over those rows: the state is carried on.

A pause is a span in which neither the force nor the slip has a sample for longer than
``PAUSE_MIN_S`` and ``PAUSE_PERIODS`` of the topic's own median interval (a force logged on
change, or a slow slip topic, has long silences of its own; both together, beyond both
bounds, are the logger's).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from clutch_model.plant import layout as L

PAUSE_MIN_S = 0.25          # a pause of the inputs: both silent at least this long ...
PAUSE_PERIODS = 20.0        # ... and this many of each topic's median sample interval
PACK_TOLERANCE_K = 1.0      # rows left out while the pack temperature may be off by more than this
POWER_WINDOW_S = 1.0        # the slip power near a pause: its largest within this of either edge
INPUT_TOPICS = ("applied_force", "slip_speed")


@dataclass
class LoggerPause:
    """One pause of a run's inputs: [t0_s, t1_s] the last sample before and the first after
    (s from the bag's first message); rows up to ``left_out_to_s`` are kept out of residuals;
    ``pack_bound_k`` the bound on the pack temperature's error just after it."""
    run: str
    t0_s: float
    t1_s: float
    pack_bound_k: float
    left_out_to_s: float
    rows_left_out: int = 0

    def as_dict(self) -> dict:
        return {"bag": self.run, "t0_s": round(self.t0_s, 4), "t1_s": round(self.t1_s, 4),
                "pack_bound_k": round(self.pack_bound_k, 2), "left_out_to_s": round(self.left_out_to_s, 3),
                "rows_left_out": int(self.rows_left_out)}


def _silences(t: np.ndarray) -> np.ndarray:
    """(k, 2) spans between consecutive samples longer than the topic's pause bound."""
    t = np.sort(np.asarray(t, float))
    if t.size < 3:
        return np.empty((0, 2))
    d = np.diff(t)
    med = float(np.median(d[d > 0])) if np.any(d > 0) else 0.0
    long = d > max(PAUSE_MIN_S, PAUSE_PERIODS * med)
    return np.column_stack([t[:-1][long], t[1:][long]])


def input_pauses(run) -> list:
    """[(t0_s, t1_s)] spans in which every input topic of ``run`` is silent (its raw samples,
    ``Run.samples``), each at least ``PAUSE_MIN_S`` long."""
    spans = None
    for topic in INPUT_TOPICS:
        s = run.samples.get(topic + "_logged", run.samples.get(topic))
        if s is None:
            return []
        gaps = _silences(s[0])
        if spans is None:
            spans = [tuple(g) for g in gaps]
            continue
        both = []
        for a0, a1 in spans:
            for b0, b1 in gaps:
                lo, hi = max(a0, b0), min(a1, b1)
                if hi - lo >= PAUSE_MIN_S:
                    both.append((lo, hi))
        spans = both
    return spans or []


def _heat_transfer(p: np.ndarray, w_abs: np.ndarray, force_n: np.ndarray) -> np.ndarray:
    """The plant's H_tf (W/m²/K) at each row, floored as the plant floors it."""
    f_kn = np.maximum(np.asarray(force_n, float), 0.0) / 1000.0
    h = p[L.B1] + p[L.B2] * w_abs + p[L.B3] * f_kn + p[L.B4] * w_abs * f_kn
    return np.maximum(h, p[L.HTF_MIN])


def _near_power_w(run, t0: float, t1: float) -> float:
    """The largest slip power measured within POWER_WINDOW_S of the pause's edges."""
    s = run.samples.get("measured_torque")
    if s is not None:
        tt, torque = np.asarray(s[0], float), np.asarray(s[1], float)
    else:
        tt, torque = run.t, run.torque_measured_nm
    if torque is None:
        return 0.0
    near = (((tt >= t0 - POWER_WINDOW_S) & (tt <= t0)) | ((tt >= t1) & (tt <= t1 + POWER_WINDOW_S)))
    near &= np.isfinite(torque)
    if not near.any():
        return 0.0
    slip = np.interp(tt[near], run.t, np.asarray(run.slip_speed_rad_s, float))
    return float(np.max(np.abs(slip * torque[near])))


def pauses_of_run(run, model) -> list:
    """The run's logger pauses, each with the rows its pack temperature bound leaves out."""
    spans = input_pauses(run)
    if not spans:
        return []
    p = model.vector()
    area, capacity, plates = model.nominal_area_m2, p[L.PLATE_HEAT_CAPACITY], max(p[L.N_SEPARATOR], 1.0)
    t = np.asarray(run.t, float)
    w_abs = np.abs(np.asarray(run.slip_speed_rad_s, float))
    rate = area * _heat_transfer(p, w_abs, run.applied_force_n) / capacity      # 1/s
    had = np.isfinite(run.torque_measured_nm) if run.torque_measured_nm is not None else np.zeros(t.size, bool)
    out = []
    for t0, t1 in spans:
        bound0 = _near_power_w(run, t0, t1) * (t1 - t0) / (plates * capacity)
        k = np.flatnonzero(t >= t1)
        end = t1
        if k.size and bound0 > PACK_TOLERANCE_K:
            decay = np.exp(-np.cumsum(rate[k] * np.diff(t[k], prepend=t1)))
            over = np.flatnonzero(bound0 * decay > PACK_TOLERANCE_K)
            end = float(t[k[over[-1]]]) if over.size else t1
        rows = int(np.sum((t > t0) & (t <= end) & had))
        out.append(LoggerPause(run.name, float(t0), float(t1), float(bound0), end, rows))
    return out


def without_rows_after_pauses(campaign, model) -> tuple:
    """(campaign with the measured torque NaN from each logger pause to ``left_out_to_s``,
    mask of the rows left out that had a torque, [LoggerPause])."""
    from clutch_model.formats.bag_reader import Campaign

    runs, masks, pauses = [], [], []
    for run in campaign.runs:
        found = pauses_of_run(run, model) if run.torque_measured_nm is not None else []
        out = np.zeros(run.t.size, bool)
        for pause in found:
            out |= (run.t > pause.t0_s) & (run.t <= pause.left_out_to_s)
        if out.any():
            out &= np.isfinite(run.torque_measured_nm)
            run = replace(run, torque_measured_nm=np.where(out, np.nan, run.torque_measured_nm))
        runs.append(run)
        masks.append(out)
        pauses.extend(found)
    mask = np.concatenate(masks) if masks else np.zeros(0, bool)
    return Campaign(runs), mask, pauses
