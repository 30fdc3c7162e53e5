"""The whole loop of `clutch-sim diagnose`.

1. fit the friction model on the bench (thesis §5.2.1);
2. calibrate on the car runs it fits on (regression + Monte Carlo, thesis §5.3), holding runs
   out: every third run from the second (interleaved in time, so drift, temperatures and
   slip levels are on both sides), moved off the campaign's extreme slip/temperature runs so
   validation stays inside the fit runs' envelope; the held-out runs' inputs still drive the
   campaign's carried state, their torque is never fitted;
3. show what the baseline gets wrong (residual features, lag, loops, drift);
4. name the cause: fit every catalog mechanism (jointly with the same friction correction the
   baseline got) and compare on the held-out runs against the noise level (verdict.py);
5. extend the model with the winner, and measure the gain on the held-out runs.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from clutch_model.errors import DataError
from clutch_model.plant.params import ClutchModel
from clutch_model.replay import replay_runs
from clutch_model.formats.bag_reader import Campaign
from clutch_model.diagnosis.lockup import without_locked_torque
from clutch_model.diagnosis.measured_time import measured_time_campaign, topics_unaligned
from clutch_model.plant.simulate import SimResult
from clutch_model.diagnosis import features as F
from clutch_model.diagnosis.fitting import CANDIDATE_IDS, CandidateFit, fit_candidate
from clutch_model.diagnosis.verdict import blocks, decide, score_candidates

JOINT_REFITS = 3


def smooth_sump(campaign: Campaign, window_s: float = 2.0) -> Campaign:
    """The campaign with each run's sump temperature smoothed (local linear Savitzky-Golay fit
    over window_s). The sump changes over minutes, but its sensor noise enters the model
    through the initial pack temperature, i.e. the viscosity during the first engagement; at
    cold, slow films 0.5 C of noise in one sample moves an engagement transient by ~15 N*m.
    Diagnosis is about the plant, so it works on the cleaner input (replay keeps the contract's
    raw first sample)."""
    from dataclasses import replace

    from scipy.signal import savgol_filter

    runs = []
    for r in campaign.runs:
        dt = float(np.median(np.diff(r.t))) if len(r) > 2 else 1.0
        win = int(min(len(r), max(5, round(window_s / dt)))) // 2 * 2 + 1
        if win > len(r):
            win -= 2
        sump = r.sump_temperature_c
        if win >= 5:
            sump = savgol_filter(sump, win, 1, mode="interp")
        runs.append(replace(r, sump_temperature_c=np.asarray(sump, float)))
    return Campaign(runs)


def choose_held_out(names: list, runs=None) -> list:
    """Every third run from the second (time order); one run when there are two or three.

    With the runs given, a chosen run that holds an extreme of the campaign (highest or lowest
    mean |slip| or sump temperature) is swapped for its next (else previous) neighbour in time
    that holds none: the held-out runs then test the model inside the fit runs' operating
    envelope instead of an extrapolation of the calibration (a k_V*w friction term fitted at
    slips up to 8 rad/s can pass for drag torque there, and not at 14 rad/s)."""
    n = len(names)
    if n < 2:
        raise DataError("diagnose needs at least 2 car-test runs (one is held out for validation)")
    if n <= 3:
        picks = [n // 2] if n == 3 else [n - 1]
    else:
        picks = list(range(1, n, 3))
    if runs is not None and n >= 4:
        slip = np.array([float(np.mean(np.abs(r.slip_speed_rad_s))) for r in runs])
        sump = np.array([float(np.mean(r.sump_temperature_c)) for r in runs])
        extreme = {int(np.argmax(slip)), int(np.argmin(slip)), int(np.argmax(sump)), int(np.argmin(sump))}
        chosen = set()
        for k in picks:
            if k in extreme:
                for j in (k + 1, k - 1, k + 2, k - 2):
                    if 0 <= j < n and j not in extreme and j not in chosen and j not in picks:
                        k = j
                        break
            chosen.add(k)
        picks = sorted(chosen)
    return [names[k] for k in picks]


@dataclass
class Diagnosis:
    cause_id: str
    reason: str
    evidence: str
    cause_parameters: dict
    sigma_nm: float
    rmse: dict                       # nominal, bench, calibrated, extended (held-out)
    held_out: list
    fit_runs: list
    candidates: list                 # CandidateFit, sorted by held-out RMSE
    scores: list
    features_r2: dict
    nominal_model: ClutchModel
    bench_model: ClutchModel
    calibrated_model: ClutchModel
    extended_model: ClutchModel
    campaign: Campaign
    calibrated_fit: CandidateFit
    calibrated_sim: SimResult        # plant signals of the calibrated model on the campaign
    extended_fit: CandidateFit | None
    nominal_pred: np.ndarray
    noise_phi: float = 0.0
    bench_info: dict = field(default_factory=dict)
    calibration_info: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)

    @property
    def gain_pct(self) -> float:
        c, e = self.rmse["calibrated"], self.rmse["extended"]
        return 100.0 * (c - e) / c if c > 0 else 0.0


def _rmse(resid, mask):
    ok = mask & np.isfinite(resid)
    return float(np.sqrt(np.mean(resid[ok] ** 2))) if ok.any() else math.nan


def diagnose_campaign(nominal: ClutchModel, bench_model: ClutchModel, runs, held_out=None,
                      candidates=None, calibrate=None, progress=None, bench_info=None,
                      measured_time=None) -> Diagnosis:
    """Diagnose a campaign given the bench-fitted model. ``measured_time`` (default: when the
    torque and force topics are not aligned) compares model and measurement at the measured
    torque's own stamps (``measured_time_campaign``) instead of the replay grid.
    ``calibrate(model, fit_campaign)`` may
    add a car-data calibration (regression + Monte Carlo) before the shared friction
    correction; it returns (model, info)."""
    tick = time.perf_counter()
    timings = {}
    campaign = runs if isinstance(runs, Campaign) else Campaign(list(runs))
    if measured_time is None:
        measured_time = topics_unaligned(campaign.runs)
    if measured_time:
        # compare where the measurement is: rows at the torque's own stamps, inputs
        # interpolated between their samples (diagnosis.measured_time)
        campaign = measured_time_campaign(campaign)
    campaign = smooth_sump(campaign)
    # lock-up phases (found from the slip data): the driveline sets the torque there
    campaign, _lockups = without_locked_torque(campaign)
    names = campaign.names
    if not np.isfinite(campaign.torque_measured).any():
        raise DataError("the bags have no /clutch/measured_torque: nothing to diagnose against")
    held_out = list(held_out) if held_out else choose_held_out(names, campaign.runs)
    unknown = set(held_out) - set(names)
    if unknown:
        raise DataError(f"held-out run not in the campaign: {sorted(unknown)[0]}")
    fit_runs = [n for n in names if n not in held_out]
    if not fit_runs:
        raise DataError("every run is held out: nothing left to fit on")
    held_idx = [names.index(n) for n in held_out]
    eval_mask = np.isin(campaign.run_index, held_idx)
    fit_mask = ~eval_mask
    say = progress or (lambda msg: None)

    # nominal and bench models on the campaign
    nominal_rep = replay_runs(nominal, campaign)
    nominal_resid = campaign.torque_measured - nominal_rep.torque_sim
    bench_rep = replay_runs(bench_model, campaign)
    energy_total = float(bench_rep.sim.energy_j[-1])
    torque_scale = float(np.nanpercentile(np.abs(campaign.torque_measured), 95))
    sigma_guess = F.noise_sigma(campaign.torque_measured - bench_rep.torque_sim, campaign.run_start)
    if not np.isfinite(sigma_guess) or sigma_guess <= 0:
        sigma_guess = max(1e-3 * torque_scale, 1e-6)
    timings["simulate nominal"] = time.perf_counter() - tick

    # calibration on the fit runs: optional regression + Monte Carlo, then the shared correction
    calibration_info = {}
    cal_base = bench_model
    t0 = time.perf_counter()
    if calibrate is not None:
        say("calibrating friction on the fit runs (regression + Monte Carlo)")
        cal_base, calibration_info = calibrate(bench_model, campaign.subset(fit_runs))
    timings["car calibration"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    say("fitting the baseline friction correction")
    calibrated = fit_candidate(cal_base, campaign, fit_mask, None, energy_total, torque_scale,
                               noise_sigma_nm=sigma_guess)
    timings["friction correction"] = time.perf_counter() - t0

    resid0 = calibrated.residual

    # candidates: every mechanism alone (one parameter, cheap) on both the car-calibrated and
    # the bench-fitted friction -- a car calibration may have absorbed part of the mechanism --
    # then the JOINT_REFITS best on the fit runs refitted jointly with the friction correction,
    # from the friction they did best on
    fits, tried = {}, {}
    ids = list(candidates) if candidates else CANDIDATE_IDS
    t0 = time.perf_counter()
    starts = [(calibrated.model, cal_base)]
    if cal_base is not bench_model:
        starts.append((bench_model, bench_model))
    for cid in ids:
        say(f"fitting candidate {cid}")
        tried[cid] = []
        for start_model, joint_base in starts:
            fit = fit_candidate(start_model, campaign, fit_mask, cid, energy_total, torque_scale,
                                fit_friction=False, noise_sigma_nm=sigma_guess)
            tried[cid].append((fit, joint_base))
        fits[cid] = min((f for f, _ in tried[cid]), key=lambda f: f.fit_rmse_nm)
    # joint refits from every start: a car calibration that absorbed a drift can trap the
    # joint fit in it, the bench friction does not
    for cid in sorted(fits, key=lambda k: fits[k].fit_rmse_nm)[:JOINT_REFITS]:
        say(f"refitting {cid} jointly with the friction correction")
        for single, joint_base in tried[cid]:
            joint = fit_candidate(joint_base, campaign, fit_mask, cid, energy_total, torque_scale,
                                  noise_sigma_nm=sigma_guess, start=single.parameters)
            if joint.fit_rmse_nm <= fits[cid].fit_rmse_nm:
                fits[cid] = joint
    fits = list(fits.values())
    for fit in fits:
        fit.held_out_rmse_nm = _rmse(fit.residual, eval_mask)
    timings["candidates"] = time.perf_counter() - t0
    calibrated.held_out_rmse_nm = _rmse(resid0, eval_mask)

    labels = blocks(campaign.t, eval_mask, campaign.run_index)
    # the noise level, from the residual of the model that fits the fit runs best (the least
    # structure left in it: step transients of an unmodelled lag would otherwise pass for noise)
    ref = min([calibrated] + fits, key=lambda f: f.fit_rmse_nm)
    sigma_rows = F.noise_profile(ref.residual, campaign.t, campaign.run_start)
    sigma_rows = np.where(np.isfinite(sigma_rows) & (sigma_rows > 0), sigma_rows,
                          max(float(np.nanstd(resid0)) * 1e-3, 1e-9))
    noise_phi = F.noise_ar1(ref.residual, campaign.run_start)
    mse0, excess, noise_ms, scores = score_candidates(resid0, {f.id: f.residual for f in fits}, sigma_rows, labels,
                                                      noise_phi)
    sigma = math.sqrt(noise_ms)
    held_meas = campaign.torque_measured[eval_mask]
    torque_ms = float(np.nanmean(held_meas ** 2)) if np.isfinite(held_meas).any() else 0.0
    cause, best, reason = decide(mse0, excess, noise_ms, scores, torque_ms)
    fits.sort(key=lambda f: f.held_out_rmse_nm)

    # features of the calibrated residual (evidence)
    sim_cal = replay_runs(calibrated.model, campaign).sim
    feats = F.feature_signals(campaign, sim_cal)
    r2 = F.explained_variance(resid0, feats, campaign.run_index)

    extended_fit = None
    extended_model = calibrated.model
    cause_params = {}
    if best is not None:
        extended_fit = next(f for f in fits if f.id == cause)
        extended_model = extended_fit.model
        cause_params = dict(extended_fit.parameters)
        if cause == "friction_degradation":
            _record_energy_history(extended_model, campaign)
    rmse = {
        "nominal": _rmse(nominal_resid, eval_mask),
        "bench": _rmse(campaign.torque_measured - bench_rep.torque_sim, eval_mask),
        "calibrated": calibrated.held_out_rmse_nm,
        "extended": extended_fit.held_out_rmse_nm if extended_fit else calibrated.held_out_rmse_nm,
    }
    if cause == "unexplained":
        top = sorted(r2.items(), key=lambda kv: -kv[1])[:3]
        cause_params = {"residual_follows": {k: round(v, 3) for k, v in top}}
    evidence = _evidence(cause, reason, sigma, rmse, scores, r2, cause_params)
    timings["total"] = time.perf_counter() - tick
    return Diagnosis(cause_id=cause, reason=reason, evidence=evidence, cause_parameters=cause_params,
                     sigma_nm=sigma, rmse=rmse, held_out=held_out, fit_runs=fit_runs, candidates=fits,
                     scores=scores, features_r2=r2, nominal_model=nominal, bench_model=bench_model,
                     calibrated_model=calibrated.model, extended_model=extended_model, campaign=campaign,
                     calibrated_fit=calibrated, calibrated_sim=sim_cal, extended_fit=extended_fit,
                     nominal_pred=nominal_rep.torque_sim,
                     bench_info=bench_info or {}, calibration_info=calibration_info, timings=timings,
                     noise_phi=noise_phi)


def _record_energy_history(model: ClutchModel, campaign: Campaign) -> None:
    """Store the campaign's dissipated energy at each run's start and end in the model, so a
    later replay of runs after this campaign continues from it (mechanisms.FrictionDegradation)."""
    energy = replay_runs(model, campaign, energy0_j=0.0).sim.energy_j
    history = []
    for r, sl in campaign.slices():
        e = energy[sl]
        history.append([int(r.start_time_ns), float(e[0])])
        history.append([int(r.start_time_ns + round(float(r.t[-1]) * 1e9)), float(e[-1])])
    model.mechanism("friction_degradation").values["energy_history"] = history


def _evidence(cause, reason, sigma, rmse, scores, r2, params) -> str:
    top = [(k, v) for k, v in sorted(r2.items(), key=lambda kv: -kv[1])[:3] if v >= 0.05]
    follows = (", ".join(f"{k} (R² {v:.2f})" for k, v in top) if top
               else "none of the candidate features (each explains < 5 % of it)")
    ranked = "; ".join(f"{s.id} {s.rmse:.1f} N·m (z={s.z_stat:.1f}, explains {100 * s.explained:.0f} %)"
                       for s in scores[:3])
    base = (f"On the held-out runs the calibrated baseline has RMSE {rmse['calibrated']:.2f} N·m against a "
            f"sensor-noise level of {sigma:.2f} N·m estimated from the data (nominal RC-1: "
            f"{rmse['nominal']:.2f} N·m). Its residual follows {follows}. Best refitted candidates: {ranked}.")
    if cause == "none":
        return base + f" Verdict none: {reason}; no structural discrepancy beyond noise and calibration."
    if cause == "unexplained":
        return base + f" Verdict unexplained: {reason}."
    pstr = ", ".join(f"{k} = {v:.4g}" for k, v in params.items())
    return (base + f" Verdict {cause} ({pstr}): {reason}; the extended model's held-out RMSE is "
            f"{rmse['extended']:.2f} N·m.")
