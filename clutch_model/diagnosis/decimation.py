"""Anti-aliased decimation of a campaign to the diagnosis rate (long, fast car logs).

A 1 kHz car log carries five times more rows than the diagnosis can use: the plant integrates
in steps of at most ``kernels.MAX_STEP_S`` (5.1 ms, ~196 Hz) whatever the row rate, the
fastest time constant any catalog mechanism is searched from is 3 ms (transport_delay and
torque_sensor_lag grids; actuator_lag from 5 ms), and a car's force and slip signals are far
slower than that. Every row above the diagnosis rate costs one more output evaluation in each
of the thousands of simulations a diagnosis runs, and one more row in every held-out test,
while adding only measurement noise, which the anti-aliasing filter averages away.

The diagnosis rate (``choose_diagnosis_rate``) is the lowest rate that keeps

* the plant's own step: rate >= 1 / MAX_STEP_S (the plant still simulates at its own steps;
  rows no sparser than its step keep the replay timing of docs/bags.md: inputs held per step);
* the fastest mechanism's corner: a first-order lag of the fastest searched time constant
  (tau_min = 3 ms, corner 1 / (2 pi tau_min) = 53 Hz) inside the filter's flat passband with a
  margin: PASSBAND x rate / 2 >= CORNER_MARGIN x corner;
* the data's own bandwidth: the frequency below which SIGNAL_POWER of the power of the
  (detrended) applied force and slip speed lies, inside the passband — when no model is given;
  diagnose gives one and checks instead what this rule guards against, on the data: the plant
  (the nominal model) simulated on the decimated rows must stay within ERROR_FRAC of the
  decimated torque noise's sd of its native simulation filtered the same way
  (``decimation_error``, first SAMPLE_S of data); q is lowered until it does. Step-like force
  requests, whose spectrum never ends, are so decimated as far as the plant's response allows.

The native rate is divided by the largest integer q with native / q >= that rate; q < 2 (every
campaign at 200-390 Hz, e.g. the virtual test cars) means no decimation at all, so campaigns
at the rate the diagnosis was designed for are diagnosed exactly as before. Decimation
(``decimate_campaign``) filters each run's force, slip, sump and measured torque with
scipy.signal.resample_poly (a zero-phase Kaiser-window FIR, line-padded at the ends) and keeps
every q-th stamp, so no delay is introduced (the force is taken half a decimated step later,
less half a native one: the plant holds each row's force until the next row, and this keeps
the hold's mean delay what it was at the native rate, ``_held_force``); the measured torque's noise becomes band-limited
at the new Nyquist, which the noise model the held-out tests fit to the data
(noise_model.fit_noise_model) sees as it is. Each topic's raw samples (``Run.samples``) are
kept, so lock-up is still detected on the raw slip and mapped to the decimated rows (its
0.1 s pad is wider than the filter's half-length).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from clutch_model.plant import kernels as K

PASSBAND = 0.8                # resample_poly's Kaiser FIR is flat to ~0.8 of the new Nyquist
CORNER_MARGIN = 1.5           # the fastest lag's corner sits this far inside the passband
SIGNAL_POWER = 0.999          # power fraction of force and slip that must stay in the passband
MIN_DECIMATION = 2            # below this factor the campaign is left as it is
ERROR_FRAC = 0.1              # the decimated plant within 0.1 noise sd of the native one (1 % of the variance)
SAMPLE_S = 300.0              # data the error check simulates (the first part of each run)


@dataclass(frozen=True)
class DecimationPlan:
    native_rate_hz: float
    factor: int                    # q: keep every q-th (filtered) row; 1 = no decimation
    min_rate_hz: float             # the lowest rate the rules above allow
    reasons: dict                  # rule -> rate it asks for (Hz)
    checked: dict = None           # factor -> (decimation error RMS, noise sd at that rate), N*m

    @property
    def rate_hz(self) -> float:
        return self.native_rate_hz / self.factor

    def describe(self) -> str:
        if self.factor < 2:
            return (f"rows at {self.native_rate_hz:.0f} Hz diagnosed as they are (the diagnosis needs "
                    f">= {self.min_rate_hz:.0f} Hz)")
        why = ", ".join(f"{k} {v:.0f} Hz" + (" (left to the plant check)" if self.checked and k == "input bandwidth"
                                             else "") for k, v in self.reasons.items())
        chk = ""
        if self.checked and self.factor in self.checked:
            e, sd = self.checked[self.factor]
            chk = f"; the plant on the decimated rows is within {e:.2f} N*m RMS of the native one, noise sd {sd:.2f} N*m"
        return (f"rows at {self.native_rate_hz:.0f} Hz decimated by {self.factor} to {self.rate_hz:.0f} Hz "
                f"(anti-aliased; the diagnosis needs >= {self.min_rate_hz:.0f} Hz: {why}{chk})")

    def to_json(self) -> dict:
        out = {"native_rate_hz": self.native_rate_hz, "factor": self.factor, "rate_hz": self.rate_hz,
               "min_rate_hz": self.min_rate_hz, "rules_hz": dict(self.reasons)}
        if self.checked:
            out["error_check_nm"] = {str(q): {"decimation_error_rms": e, "noise_sd": s}
                                     for q, (e, s) in sorted(self.checked.items())}
        return out


def fastest_time_constant_s() -> float:
    """The shortest time constant (s) any catalog mechanism's start grid reaches (parameters
    in seconds: lags and delays)."""
    from clutch_model.plant.mechanisms import CATALOG, CampaignScale

    scale = CampaignScale(max_force_n=2e4, max_slip_rad_s=10.0, energy_total_j=1e6, torque_scale_nm=100.0)
    fastest = math.inf
    for cls in CATALOG.values():
        try:
            specs = cls.search_space(scale)
        except Exception:           # a mechanism whose space needs more of the campaign
            continue
        for s in specs:
            # a duration in s (tau_s, delay_s), not a rate per rad/s
            if s.name.endswith("_s") and "_per_" not in s.name and len(s.grid) and np.min(s.grid) > 0:
                fastest = min(fastest, float(np.min(s.grid)))
    return fastest if math.isfinite(fastest) else 0.003


def _rows(run, measured_time: bool) -> np.ndarray:
    """Rows of the run that carry data: with measured_time, the torque stamps (the fill grid
    rows between them carry no measurement)."""
    if measured_time and run.torque_measured_nm is not None:
        keep = np.isfinite(run.torque_measured_nm)
        if keep.sum() >= 2:
            return np.flatnonzero(keep)
    return np.arange(len(run))


def native_rate_hz(campaign, measured_time: bool = False) -> float:
    """Median row rate of the campaign (rows that carry data)."""
    dts = []
    for run in campaign.runs:
        rows = _rows(run, measured_time)
        if rows.size > 2:
            dts.append(np.diff(run.t[rows]))
    if not dts:
        return math.nan
    dt = float(np.median(np.concatenate(dts)))
    return 1.0 / dt if dt > 0 else math.nan


def signal_bandwidth_hz(campaign, rate_hz: float, power: float = SIGNAL_POWER, max_rows: int = 1 << 20) -> float:
    """Frequency below which ``power`` of the (linearly detrended) applied force's and slip
    speed's power lies (Welch spectra per run, the larger of the two)."""
    from scipy.signal import welch

    out = 0.0
    sizes = [len(r) for r in campaign.runs if len(r) >= 64]
    if not sizes:
        return out
    nperseg = min(4096, min(sizes))                 # one frequency grid for every run
    for name in ("applied_force_n", "slip_speed_rad_s"):
        f_acc, p_acc = None, None
        used = 0
        for run in campaign.runs:
            x = np.asarray(getattr(run, name), float)
            if x.size < nperseg or used >= max_rows:
                continue
            x = x[: max(max_rows - used, nperseg)]
            used += x.size
            f, p = welch(x, fs=rate_hz, nperseg=nperseg, detrend="linear")
            p_acc = p if p_acc is None else p_acc + p
            f_acc = f
        if p_acc is None or not np.isfinite(p_acc).all() or p_acc.sum() <= 0:
            continue
        c = np.cumsum(p_acc) / p_acc.sum()
        out = max(out, float(f_acc[min(int(np.searchsorted(c, power)), f_acc.size - 1)]))
    return out


def choose_diagnosis_rate(campaign, measured_time: bool = False, rate_hz: float | None = None,
                          model=None) -> DecimationPlan:
    """The decimation plan of a campaign (module doc). ``rate_hz``: a requested diagnosis rate
    instead of the rules (the factor is still an integer: native / q >= rate_hz). ``model``
    (with the rules only): the factor is lowered until the plant on the decimated rows stays
    within ERROR_FRAC of the noise of the native one (``decimation_error``)."""
    native = native_rate_hz(campaign, measured_time)
    if not math.isfinite(native) or native <= 0:
        return DecimationPlan(native, 1, math.nan, {})
    tau = fastest_time_constant_s()
    corner = 1.0 / (2.0 * math.pi * tau)
    reasons = {"plant step": 1.0 / K.MAX_STEP_S,
               "fastest mechanism": 2.0 * CORNER_MARGIN * corner / PASSBAND}
    if rate_hz is None and native < MIN_DECIMATION * max(reasons.values()):
        # too slow to decimate at all: the campaign is diagnosed as it is, nothing computed
        return DecimationPlan(float(native), 1, float(max(reasons.values())), reasons)
    reasons["input bandwidth"] = 2.0 * signal_bandwidth_hz(campaign, native) / PASSBAND
    need = max(reasons.values()) if rate_hz is None else float(rate_hz)
    if model is not None and rate_hz is None:
        # the error check below measures what the bandwidth rule guards against (the plant's
        # response to the filtered inputs), on the data itself: step-like force requests, whose
        # spectrum never ends, are then decimated as far as the plant's response allows
        need = max(v for k, v in reasons.items() if k != "input bandwidth")
    q = max(1, int(math.floor(native / need * (1 + 1e-9))))
    checked = {}
    if model is not None and rate_hz is None:
        while q >= MIN_DECIMATION:
            err, sd = decimation_error(model, campaign, q, measured_time)
            checked[q] = (err, sd)
            if not (err > ERROR_FRAC * sd):           # NaN (nothing to check): accepted
                break
            q -= 1
    if q < MIN_DECIMATION:
        q = 1
    return DecimationPlan(float(native), q, float(need), reasons, checked or None)


def _sample(campaign, measured_time: bool, sample_s: float):
    """The first ``sample_s`` of data of each run (state exact: each run restarts the plant),
    fill rows dropped, as a campaign."""
    from clutch_model.formats.bag_reader import Campaign

    per_run = sample_s / max(len(campaign.runs), 1)
    runs = []
    for r in campaign.runs:
        rows = _rows(r, measured_time)
        t = r.t[rows]
        rows = rows[t <= t[0] + max(per_run, 10.0)]
        pick = lambda a: None if a is None else np.asarray(a)[rows]      # noqa: E731
        runs.append(replace(r, t=r.t[rows], plant_grid=None, applied_force_n=pick(r.applied_force_n),
                            slip_speed_rad_s=pick(r.slip_speed_rad_s), sump_temperature_c=pick(r.sump_temperature_c),
                            torque_measured_nm=pick(r.torque_measured_nm),
                            pack_temperature_measured_c=pick(r.pack_temperature_measured_c)))
    return Campaign(runs)


def decimation_error(model, campaign, q: int, measured_time: bool = False, sample_s: float = SAMPLE_S) -> tuple:
    """(RMS difference between ``model``'s torque simulated on the q-decimated rows and its
    native simulation filtered the same way, sd of the measured torque's noise at the
    decimated rate), N*m, on the first ``sample_s`` of the campaign's data outside lock-up.
    The noise sd: robust first differences (features.noise_sigma) of the decimated measured
    torque minus the decimated native simulation."""
    from clutch_model.diagnosis.features import noise_sigma
    from clutch_model.diagnosis.lockup import without_locked_torque
    from clutch_model.prediction import predict_campaign

    sample = _sample(campaign, measured_time, sample_s)
    vec = model.vector()[None, :]
    native = predict_campaign(vec, sample, measurement=list(model.mechanisms)).torque_nm[0]
    dec = decimate_campaign(sample, DecimationPlan(0.0, q, 0.0, {}), False)
    dec_unlocked, _ = without_locked_torque(dec)
    pred = predict_campaign(vec, dec, measurement=list(model.mechanisms)).torque_nm[0]
    ref = np.concatenate([_filtered(native[sl], q) for _, sl in sample.slices()])
    ok = np.isfinite(dec_unlocked.torque_measured)
    if ok.sum() < 20:
        return math.nan, math.nan
    err = float(np.sqrt(np.mean((pred - ref)[ok] ** 2)))
    sd = noise_sigma(np.where(ok, dec.torque_measured - ref, np.nan), dec.run_start)
    return err, sd


def _filtered(x: np.ndarray, q: int) -> np.ndarray:
    from scipy.signal import resample_poly

    if x.size < 2:
        return x.copy()
    y = resample_poly(x, 1, q, padtype="line")
    return y[: (x.size + q - 1) // q]


def _held_force(x: np.ndarray, q: int) -> np.ndarray:
    """The anti-aliased force for rows q native samples apart, taken (q - 1) / 2 native
    samples after each row: the plant holds a row's force over the step to the next row
    (replay timing), a mean delay of half a step; the shift gives the decimated rows the same
    mean delay as the native ones (half a native step). On the 1 kHz bench profile it cuts the
    decimated plant's torque error from 2.4 to 0.6 N*m RMS (q = 5)."""
    n_out = (x.size + q - 1) // q
    h = (q - 1) / 2.0
    lo, frac = int(math.floor(h)), h - math.floor(h)

    def shifted(k):
        y = np.concatenate([x[k:], np.full(k, x[-1])]) if k else x
        return _filtered(y, q)[:n_out]

    out = shifted(lo)
    if frac > 0:
        out = (1.0 - frac) * out + frac * shifted(lo + 1)
    return out


def decimate_run(run, q: int, measured_time: bool = False):
    """One run at every q-th data row, its inputs and measured torque low-passed first
    (anti-aliased, zero phase). Missing torque samples are bridged for the filter and the
    decimated rows whose filter window reaches one are NaN."""
    if q < 2:
        return run
    rows = _rows(run, measured_time)
    t = run.t[rows]
    keep = slice(0, None, q)
    out = {}
    for name in ("slip_speed_rad_s", "sump_temperature_c"):
        out[name] = _filtered(np.asarray(getattr(run, name), float)[rows], q)
    out["applied_force_n"] = _held_force(np.asarray(run.applied_force_n, float)[rows], q)
    tq = run.torque_measured_nm
    if tq is not None:
        tq = np.asarray(tq, float)[rows]
        ok = np.isfinite(tq)
        if ok.any():
            filled = np.interp(t, t[ok], tq[ok]) if not ok.all() else tq
            tq_dec = _filtered(filled, q)
            if not ok.all():
                half = 10 * q                                  # resample_poly's half-length (window 10 q)
                bad = np.convolve((~ok).astype(float), np.ones(2 * half + 1), mode="same") > 0
                tq_dec = np.where(bad[keep], np.nan, tq_dec)
        else:
            tq_dec = tq[keep].copy()
        out["torque_measured_nm"] = tq_dec
    if run.pack_temperature_measured_c is not None:
        out["pack_temperature_measured_c"] = np.asarray(run.pack_temperature_measured_c, float)[rows][keep]
    return replace(run, t=t[keep].copy(), plant_grid=None, **out)


def decimate_campaign(campaign, plan: DecimationPlan, measured_time: bool = False):
    """The campaign at the plan's rate (unchanged when its factor is 1)."""
    from clutch_model.formats.bag_reader import Campaign

    if plan.factor < 2:
        return campaign
    return Campaign([decimate_run(r, plan.factor, measured_time) for r in campaign.runs])
