"""How the diagnosis reads the logged sump temperature: smoothed, or as logged (each sample
held until the next one, the run's first sample its initial pack temperature, as replay reads
it). The data choose.

The sump temperature moves over minutes, but it sets the initial pack temperature, and through
it the viscosity during a run's first engagement: at cold, slow films a few tenths of a degree
move an engagement transient by tens of N*m. Two kinds of logs:

- a sump sensor with noise on a sump that drifts smoothly, and a clutch that heats against
  the true sump: one noisy first sample shifts the first engagement (0.5 C of noise moves a
  cold transient by ~15 N*m on the virtual car). The reading smoothed over SMOOTH_WINDOW_S
  (a local linear Savitzky-Golay fit) is nearer the temperature the clutch saw;
- a plant driven by the sump temperature as logged (quantised to 1 C, held between 2 Hz
  samples), the contract's replay reading. Smoothed, that reading is warmer or colder than
  what the plant saw by up to half a quantum: on an outside generator's cold start (pack 14 C,
  sump quantised to 1 C at 2 Hz) the true model on the smoothed sump was 23 N*m off a film
  squeezing out over 1.5 s, its RMSE on the campaign's slipping rows 13.4 N*m against 6.3 as
  logged. The calibration took that misfit into the friction, and a 52 ms actuator lag
  (effect 25 N*m RMS) read ``none``; on the sump as logged it was named at 47 ms
  [37, 58], held-out RMSE 20.8 -> 6.0 N*m. Without the rate term the lag took part of the
  weight there (0.47, the smoothed reading kept); with it the weight is 1.10 and the rate's
  coefficient -0.052 s, the lag itself.

So ``choose_sump_reading`` simulates the bench-fitted model both ways on the runs' slipping
rows (|slip| > MIN_SLIP_RAD_S, up to MAX_ROWS rows from the runs' starts, where the initial
temperature acts) and regresses the measured torque on the difference of the two predictions,
d = logged - smoothed, beside the smoothed prediction and a constant (the bench friction's
misfit, which moves with the torque's level) and the smoothed prediction's rate (a lag or a
delay in the data, torque ~ p - tau dp/dt, moves engagement transients as a colder film does):

    measured - smoothed = beta * d + gamma * smoothed + c + kappa * d(smoothed)/dt + noise

beta = 0 says smoothed, 1 says as logged; the logged reading is taken when BETA_LOGGED < beta
<= BETA_LOGGED_MAX. Where the two readings hardly differ (d below
``input_timing.difference_bar_nm``: 0.1 N*m rms, or 0.3 of the torque's noise near Nyquist) the
weight says nothing and the smoothed reading is kept, as it was before the choice: over 45 outside campaigns the weight was
0.67-1.17 wherever d reached 0.3 of that noise, and anywhere from -22 to 222 below it; on the
virtual car (the clutch against the true sump) a friction that follows the slip's acceleration
took it to 3.0 at d = 0.85 N*m under 8 N*m of noise, and the logged reading lost that effect.
A warm clutch is not such a case: half a degree moves the friction level by ~0.25 % (1-2 N*m at
600 N*m), and the weight is read as at cold. Replay is not changed; report.json's ``inputs``
gives the figures and the decision (``sump_reading``, ``sump_logged_weight``,
``sump_difference_rms_nm``).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from clutch_model.diagnosis.features import time_derivative
from clutch_model.diagnosis.input_timing import READING_MIN_DIFFERENCE_NM

SMOOTH_WINDOW_S = 2.0
BETA_LOGGED = 0.5          # the logged reading is taken above this weight on it ...
BETA_LOGGED_MAX = 4.0      # ... and up to this one (far beyond, something else moves the torque)
MIN_SLIP_RAD_S = 0.3       # rows compared: slipping (a lock phase's torque is the driveline's)
MAX_ROWS = 200_000         # rows simulated per reading, shared by the runs from their starts


def smooth_sump(campaign, window_s: float = SMOOTH_WINDOW_S):
    """The campaign with each run's sump temperature smoothed (local linear Savitzky-Golay fit
    over ``window_s``)."""
    from scipy.signal import savgol_filter

    from clutch_model.formats.bag_reader import Campaign

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


def logged_sump(campaign):
    """The campaign with each run's sump temperature read as replay reads it: the latest
    logged sample at or before each row, the first sample before it. Runs without their own
    samples keep their rows' sump."""
    from clutch_model.diagnosis.input_timing import held_at
    from clutch_model.formats.bag_reader import Campaign

    runs = []
    for r in campaign.runs:
        s = r.samples.get("sump_temperature")
        if s is None or len(s[0]) == 0:
            runs.append(r)
            continue
        runs.append(replace(r, sump_temperature_c=held_at(s[0], s[1], np.asarray(r.t, float))))
    return Campaign(runs)


@dataclass
class SumpReading:
    """The reading chosen, and the figures it was chosen on."""

    logged: bool
    beta: float                 # weight on the logged reading (0 smoothed, 1 as logged)
    rows: int                   # rows compared
    difference_rms_nm: float    # rms of logged - smoothed prediction on them
    least_nm: float = READING_MIN_DIFFERENCE_NM   # the difference below which the choice is not made

    def describe(self) -> str:
        what = "as logged (held, as replay)" if self.logged else "smoothed"
        if not self.difference_rms_nm >= self.least_nm:
            return (f"sump temperature read {what}: the two readings differ by "
                    f"{self.difference_rms_nm:.2f} N*m rms over {self.rows} slipping rows, below "
                    f"{self.least_nm:.2f} N*m")
        return (f"sump temperature read {what}: the measured torque sides with the logged reading by "
                f"weight {self.beta:.2f} over {self.rows} slipping rows (the readings differ by "
                f"{self.difference_rms_nm:.2f} N*m rms)")

    def to_dict(self) -> dict:
        return {"sump_reading": "logged" if self.logged else "smoothed", "sump_logged_weight": self.beta,
                "sump_difference_rms_nm": self.difference_rms_nm}

    def apply(self, campaign):
        """The campaign with the sump read this way."""
        return logged_sump(campaign) if self.logged else smooth_sump(campaign)


def choose_sump_reading(campaign, model, noise_nm: float = 0.0, max_rows: int = MAX_ROWS) -> SumpReading:
    """Which reading of the sump temperature the measured torque sides with (module
    docstring): ``model`` simulated on both readings of the first ``max_rows`` rows (shared
    by the runs from their starts), the torque regressed on the difference when the two differ
    by ``input_timing.difference_bar_nm`` of ``noise_nm`` (the measured torque's noise near
    Nyquist) at least."""
    from clutch_model.diagnosis.input_timing import campaign_head, compare_readings, difference_bar_nm

    head = campaign_head(campaign, max_rows)
    if head is None:
        return SumpReading(logged=False, beta=float("nan"), rows=0, difference_rms_nm=0.0)
    cmp = compare_readings(model, smooth_sump(head), logged_sump(head), MIN_SLIP_RAD_S)
    p_smooth, y, ok, d, n, rms = cmp.p_first, cmp.y, cmp.ok, cmp.d, cmp.n, cmp.rms
    least = difference_bar_nm(noise_nm)
    if n < 10 or not rms >= least:
        return SumpReading(logged=False, beta=float("nan"), rows=n, difference_rms_nm=rms, least_nm=least)
    # the smoothed prediction's rate: a lag or delay in the data (torque ~ p - tau dp/dt) moves
    # engagement transients as a colder film does, and without it takes the weight
    rate = np.concatenate([time_derivative(p_smooth[sl], head.t[sl]) if sl.stop - sl.start > 1
                           else np.zeros(sl.stop - sl.start) for _, sl in head.slices()])
    ok_rate = np.isfinite(rate[ok])
    X = np.column_stack([d, p_smooth[ok], np.ones(n), np.where(ok_rate, rate[ok], 0.0)])
    beta = float(np.linalg.lstsq(X, (y - p_smooth)[ok], rcond=None)[0][0])
    return SumpReading(logged=bool(BETA_LOGGED < beta <= BETA_LOGGED_MAX), beta=beta, rows=n,
                       difference_rms_nm=rms, least_nm=least)


__all__ = ["SumpReading", "choose_sump_reading", "logged_sump", "smooth_sump"]
