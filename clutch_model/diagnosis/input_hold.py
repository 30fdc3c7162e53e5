"""The inputs the diagnosis gives the plant and the noise they carry into it: the slip
smoothed where the torque sensor is quieter than that noise, the noise models floored at it,
the force at each step's midpoint.

The model's own noise (``decide_input_noise``, ``InputNoise``). The model is driven by the
measured slip and force, sensor noise included, and that noise reaches the predicted torque
through the friction curve's slope and the viscous terms (0.05 rad/s of white slip noise:
~0.2 N*m near Nyquist on the virtual car) where the measured torque, made from the true
inputs, has none of it. Against a white or AR(1) torque noise that is immaterial. Against a
torque sensor that is quiet at high frequencies (a 10 Hz band limit) the noise model's
innovation variance is a fraction of a percent of the noise variance, the whitened one-step
errors weigh exactly the frequencies where the model carries that noise, and a candidate that
smooths the model's output gains there whatever it means: on actuator_lag@lowpass#1 (a 70 ms
actuator lag) the torque-sensor lag won at held-out t = 693 against 37 and was named. Two
measures, both from figures of the data:

- every noise model of the diagnosis gets a white floor (``noise_model.white_floor``) of
  NOISE_FLOOR_FACTOR times the model torque's own typical noise near Nyquist (the nominal
  model on the first run's first 20 s, at the measured torque's stamps): no comparison may
  weigh a frequency by more than the model's own noise allows (0.48 N*m on the virtual car;
  against 8 N*m of white torque noise it changes nothing);
- when the measured torque's noise power near Nyquist (``high_frequency_noise``: trimmed mean
  square of 4th differences) is below SMOOTHING_NOISE_RATIO times the slip noise's part of
  the model torque (the slip sensor's noise times the model's rms slope dT/d(slip),
  ``model_input_noise``), the plant is driven by the slip smoothed with a 5 ms Gaussian (-3 dB
  at 25 Hz, zero phase: no delay added), unless the smoothing would take out of the slip more
  than its noise (``typical_smoothing_removal``: a driveline oscillation on the slip is the
  slip's own motion, not noise).

With both, actuator_lag@lowpass#1 names the actuator lag (t = 53 against 45 for the sensor
lag, head to head won); with the floor alone the sensor lag still won head to head, with the
smoothing alone a campaign with nothing hidden under the same noise named a hysteresis. A
10 Hz band-limited torque noise is smoothed (0.17 N*m near Nyquist against 2 x 0.22); white,
AR(1), drift, median-filtered and held noise are not (a torque reading held at 10 Hz has the
power of its jumps there, 0.62 N*m; smoothed, its true torque-sensor lags read as lookalikes of
an actuator lag). The force is not smoothed: its noise moves the torque less near Nyquist and
its edges carry the lag family's evidence. The slip as logged stays in the run's samples
(``slip_speed_logged``) for the lock-up detection, which estimates the slip sensor's noise
from it. Replay is not changed; report.json's ``inputs`` gives the figures and the decision.

The force at each step's midpoint (``with_midpoint_force``).

The plant integrates from row k to row k+1 with row k's inputs held (replay timing). Held at
its value at t_k, a force that varies continuously between its samples reaches the film on
average half a row interval late: 2.5 ms on a 200 Hz grid, 10 ms on 50 Hz torque stamps. The
diagnosis reads such a misfit as a transport delay or as structure the inputs predict, on data
with no effect at all. Given the force at the step's midpoint (t_k + t_{k+1}) / 2, linearly
interpolated between its own logged samples, the held value is the midpoint rule's: the film
sees the force of its step, second-order accurate and without lag.

Only the force: the film's squeeze dynamics integrate it. The slip and sump temperature enter
the torque at the row's own time (Stribeck and hydrodynamic terms) and the slow pack heat
balance over the step, where half a row interval is immaterial. Replay (the contract's row
timing) is not changed: this is how the diagnosis feeds the plant the logged force.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np


def force_at_step_midpoints(t: np.ndarray, sample_t: np.ndarray, sample_force: np.ndarray) -> np.ndarray:
    """Force for rows at ``t``: linear interpolation of the logged samples at the midpoint
    of each row's step to the next row; the last row (no next step) at its own time."""
    t = np.asarray(t, float)
    if t.size == 0:
        return np.zeros(0)
    mid = np.empty_like(t)
    mid[:-1] = 0.5 * (t[:-1] + t[1:])
    mid[-1] = t[-1]
    return np.interp(mid, np.asarray(sample_t, float), np.asarray(sample_force, float))


def with_midpoint_force(campaign):
    """The campaign (bag_reader.Campaign) with every run's applied force taken at its steps'
    midpoints from the run's own force samples (runs without them are kept as they are)."""
    from clutch_model.formats.bag_reader import Campaign

    runs = []
    for run in campaign.runs:
        samples = run.samples.get("applied_force")
        if samples is None or samples[0].size < 2 or run.t.size < 2:
            runs.append(run)
            continue
        runs.append(replace(run, applied_force_n=force_at_step_midpoints(run.t, *samples)))
    return Campaign(runs)


SLIP_SMOOTHING_S = 0.005      # Gaussian kernel's standard deviation: -3 dB at 25 Hz
SMOOTHING_NOISE_RATIO = 2.0   # smooth when the torque's high-frequency noise is below this many
                              # times the slip noise's part of the predicted torque
SMOOTHING_SIGNAL_RATIO = 1.5  # ... and the smoothing takes out of the slip at most this many times
                              # its noise (typical_smoothing_removal): more is the slip's own motion
SENSITIVITY_WINDOW_S = 20.0   # rows of the first run the torque's slip sensitivity is taken on
SLIP_STEP_RAD_S = 0.1
NOISE_FLOOR_FACTOR = 2.5      # noise models floored at this many times the model's own noise
HF_TRIM = 0.05                # share of the largest differences left out of the mean square
HF_DIFFERENCE_ORDER = 4       # 4th differences: the top of the band (gain 16 sin^4(w/2))


def high_frequency_noise(y_runs, order: int = HF_DIFFERENCE_ORDER, typical: bool = False) -> float:
    """White-equivalent standard deviation of a signal's noise near its sampling rate's Nyquist
    frequency, from its ``order``-th differences pooled over runs, scaled so white noise of sd s
    gives s. Its power (default): their mean square with the top HF_TRIM left out (a transient
    of the signal is not noise); on 200 Hz samples an AR(1) 0.95 noise of sd 8 gives 1.36, a
    10 Hz band-limited one 0.18, one drawn at 10 Hz and held 0.64 (its jumps). ``typical``:
    1.4826 MAD instead, the typical difference's (the held noise: 0), robust to a signal with
    many transients (a model's engagements)."""
    from math import comb

    from scipy.stats import norm

    d = [np.diff(np.asarray(y, float)[np.isfinite(y)], order) for y in y_runs]
    d = np.concatenate([x for x in d if x.size]) if any(x.size for x in d) else np.zeros(0)
    if d.size < 10:
        return float("nan")
    d = d - np.median(d)
    if typical:
        return float(1.4826 * np.median(np.abs(d)) / np.sqrt(comb(2 * order, order)))
    kept = np.sort(d * d)[:max(1, int(round((1.0 - HF_TRIM) * d.size)))]
    # a standard normal's mean square below its (1 - HF_TRIM) quantile of |x|
    q = norm.ppf(1.0 - HF_TRIM / 2.0)
    normal_kept = 1.0 - 2.0 * q * norm.pdf(q) / (1.0 - HF_TRIM)
    return float(np.sqrt(np.mean(kept) / normal_kept / comb(2 * order, order)))


@dataclass
class InputNoise:
    """What the measured inputs' noise does to the model's prediction, and what the diagnosis
    does about it: the slip smoothed or not, the noise models' white floor (module docstring)."""

    torque_noise_hf_nm: float          # the measured torque's noise near Nyquist
    slip_noise_hf_rad_s: float         # the slip sensor's
    torque_per_slip_nm_s: float        # rms dT/d(slip) of the model on slipping rows
    model_noise_hf_nm: float           # the model torque's own noise near Nyquist (inputs as logged)
    smoothed: bool
    sigma_s: float = SLIP_SMOOTHING_S
    smoothing_removes_rad_s: float = float("nan")   # the typical slip the smoothing would take out

    @property
    def slip_noise_in_torque_nm(self) -> float:
        return self.slip_noise_hf_rad_s * self.torque_per_slip_nm_s

    @property
    def noise_floor_nm(self) -> float:
        """White floor of every noise model of the diagnosis (noise_model.white_floor)."""
        v = NOISE_FLOOR_FACTOR * self.model_noise_hf_nm
        return float(v) if np.isfinite(v) else 0.0

    def describe(self) -> str:
        what = (f"slip smoothed without phase ({1e3 * self.sigma_s:.0f} ms Gaussian)" if self.smoothed
                else "inputs as logged")
        return (f"inputs: {what}; noise floor {self.noise_floor_nm:.2f} N*m (the torque's noise near "
                f"Nyquist {self.torque_noise_hf_nm:.2f} N*m, the model's {self.model_noise_hf_nm:.2f} N*m, "
                f"of which the slip noise {self.slip_noise_in_torque_nm:.2f} N*m)")

    def to_dict(self) -> dict:
        return {"slip_smoothed": self.smoothed, "sigma_s": self.sigma_s if self.smoothed else 0.0,
                "noise_floor_nm": self.noise_floor_nm, "torque_noise_hf_nm": self.torque_noise_hf_nm,
                "model_noise_hf_nm": self.model_noise_hf_nm,
                "slip_noise_in_torque_nm": self.slip_noise_in_torque_nm,
                "slip_smoothing_removes_rad_s": self.smoothing_removes_rad_s}


def logged_force_noise_n(campaign) -> float:
    """The applied force's noise near its Nyquist frequency (high_frequency_noise, N) from its
    samples as logged, pooled over the runs; NaN when no run carries them."""
    runs = [r for r in getattr(campaign, "runs", []) if "applied_force" in (getattr(r, "samples", None) or {})]
    if not runs:
        return float("nan")
    return high_frequency_noise([r.samples["applied_force"][1] for r in runs])


def _samples(run, channel, grid_values):
    s = run.samples.get(channel)
    return (s[0], s[1]) if s is not None else (run.t, grid_values)


GRID_FIELDS = ("t", "applied_force_n", "slip_speed_rad_s", "sump_temperature_c", "torque_measured_nm",
               "pack_temperature_measured_c")


def run_rows(run, keep):
    """The run (bag_reader.Run) on the grid rows ``keep`` (a mask or a slice) of every per-row
    field; its own samples kept, its plant grid (prediction.PlantGrid) cut to a slice's rows
    (dropped for a mask)."""
    grid = getattr(run, "plant_grid", None)
    if grid is not None:
        rows = np.arange(len(run))[keep]
        contiguous = isinstance(keep, slice) and (keep.step in (None, 1)) and rows.size > 0
        grid = grid.window(int(rows[0]), int(rows[-1]) + 1) if contiguous else None
    return replace(run, plant_grid=grid, **{f: (getattr(run, f)[keep] if getattr(run, f) is not None else None)
                                            for f in GRID_FIELDS})


def model_input_noise(campaign, model, window_s: float = SENSITIVITY_WINDOW_S) -> tuple:
    """(rms of d(predicted torque)/d(slip) in N*m per rad/s on slipping rows, the predicted
    torque's noise near Nyquist at the measured torque's stamps in N*m) of ``model`` on the
    first ``window_s`` of the campaign's first run (two simulations, the second with the slip
    moved by SLIP_STEP_RAD_S)."""
    from clutch_model.formats.bag_reader import Campaign
    from clutch_model.prediction import predict_campaign

    run = campaign.runs[0]
    keep = run.t <= run.t[0] + window_s
    if keep.sum() < 10:
        return float("nan"), float("nan")
    base = replace(run_rows(run, keep), samples={})
    step = np.sign(base.slip_speed_rad_s) * SLIP_STEP_RAD_S
    moved = replace(base, slip_speed_rad_s=base.slip_speed_rad_s + np.where(step == 0, SLIP_STEP_RAD_S, step))
    pred = predict_campaign(model, Campaign([base]), energy0_j=0.0).torque_nm
    pred2 = predict_campaign(model, Campaign([moved]), energy0_j=0.0).torque_nm
    slipping = np.abs(base.slip_speed_rad_s) > 1.0
    dt = np.abs(pred2 - pred)[slipping]
    dt = dt[np.isfinite(dt)]
    slope = float(np.sqrt(np.mean(dt ** 2)) / SLIP_STEP_RAD_S) if dt.size else float("nan")
    tq_t = run.samples["measured_torque"][0] if "measured_torque" in run.samples else run.t
    tq_t = tq_t[(tq_t >= base.t[0]) & (tq_t <= base.t[-1])]
    ok = np.isfinite(pred)
    at = np.interp(tq_t, base.t[ok], pred[ok]) if ok.sum() > 1 else np.zeros(0)
    return slope, high_frequency_noise([at], typical=True)


def decide_input_noise(campaign, model, ratio: float = SMOOTHING_NOISE_RATIO) -> InputNoise:
    """Smooth the slip when the measured torque is quieter near Nyquist than the slip noise the
    model carries into its prediction; floor the noise models at the model's own noise
    (module docstring)."""
    tq = [_samples(r, "measured_torque", r.torque_measured_nm) for r in campaign.runs
          if r.torque_measured_nm is not None or "measured_torque" in r.samples]
    sl = [_samples(r, "slip_speed_logged" if "slip_speed_logged" in r.samples else "slip_speed",
                   r.slip_speed_rad_s) for r in campaign.runs]
    h_torque = high_frequency_noise([y for _, y in tq])
    h_slip = high_frequency_noise([y for _, y in sl])
    slope, h_model = model_input_noise(campaign, model)
    removes = typical_smoothing_removal([(t, y) for t, y in sl if y is not None])
    smooth = bool(np.isfinite(slope) and np.isfinite(h_torque) and np.isfinite(h_slip)
                  and h_torque < ratio * h_slip * slope
                  and removes <= SMOOTHING_SIGNAL_RATIO * h_slip)
    return InputNoise(h_torque, h_slip, slope, h_model, smooth, smoothing_removes_rad_s=removes)


def typical_smoothing_removal(slip_runs, sigma_s: float = SLIP_SMOOTHING_S) -> float:
    """The typical size (1.4826 MAD) of what the Gaussian smoothing takes out of the slip as
    logged, pooled over runs (rad/s). From white noise of sd s near Nyquist it takes about 0.7 s
    (the virtual car's 0.05 rad/s slip noise at 200 Hz: 0.035); where it takes more than
    SMOOTHING_SIGNAL_RATIO times the noise it takes the slip's own fast motion, and the
    smoothed slip is the wrong input: on an outside generator's campaigns with an 8-12 Hz
    driveline oscillation of 1-3 rad/s on the slip (its sensor noise 0.015 rad/s near
    Nyquist) the smoothing took 0.15 rad/s out of it, 13 % of the oscillation, and a friction
    following the slip's acceleration (the smoothing's own error) was taken for structure
    beyond the catalog where nothing was hidden."""
    parts = []
    for t, y in slip_runs:
        t, y = np.asarray(t, float), np.asarray(y, float)
        ok = np.isfinite(t) & np.isfinite(y)
        if ok.sum() >= 3:
            parts.append(y[ok] - gaussian_smooth(t[ok], y[ok], sigma_s))
    if not parts:
        return float("nan")
    d = np.concatenate(parts)
    return float(1.4826 * np.median(np.abs(d - np.median(d))))


def with_smoothed_slip(campaign, sigma_s: float = SLIP_SMOOTHING_S):
    """The campaign (bag_reader.Campaign) with every run's slip smoothed (gaussian_smooth),
    both its logged samples and the grid rows; the slip as logged is kept as
    ``samples["slip_speed_logged"]`` for the lock-up detection (module docstring)."""
    from clutch_model.formats.bag_reader import Campaign

    runs = []
    for run in campaign.runs:
        samples = dict(run.samples)
        if "slip_speed" in samples:
            samples.setdefault("slip_speed_logged", samples["slip_speed"])
            st, sv = samples["slip_speed_logged"]
            samples["slip_speed"] = (st, gaussian_smooth(st, sv, sigma_s))
        runs.append(replace(run, slip_speed_rad_s=gaussian_smooth(run.t, run.slip_speed_rad_s, sigma_s),
                            samples=samples))
    return Campaign(runs)


def gaussian_smooth(t: np.ndarray, y: np.ndarray, sigma_s: float) -> np.ndarray:
    """Zero-phase Gaussian smoothing of samples ``y`` at times ``t`` (standard deviation
    ``sigma_s``): resampled on their median interval, filtered, read back at ``t``. Samples
    further apart than about three kernel widths are returned as they are."""
    from scipy.ndimage import gaussian_filter1d

    t = np.asarray(t, float)
    y = np.asarray(y, float)
    if t.size < 3 or not sigma_s > 0:
        return y
    dt = float(np.median(np.diff(t)))
    if not dt > 0 or sigma_s < 0.3 * dt:
        return y
    grid = t[0] + dt * np.arange(int(np.floor((t[-1] - t[0]) / dt)) + 2)
    smooth = gaussian_filter1d(np.interp(grid, t, y), sigma_s / dt, mode="nearest")
    return np.interp(t, grid, smooth)
