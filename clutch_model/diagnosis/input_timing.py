"""How the logged inputs are read between their samples: as the samples of a continuous signal
(linear between them), or held until the next one, as replay reads them.

Where the topics are not aligned the diagnosis compares model and measurement at the
measured torque's own stamps (measured_time.py), and it must say what the force and the slip
were between their samples. Two readings, and data of either kind:

- *linear* (``measured_time_campaign`` + ``input_hold.with_midpoint_force``): the samples of a
  continuous force and slip, each row's force the mean of the linear interpolant over the
  row's step. A sensor sampling a force that moves continuously; the project's virtual car.
- *held* (``with_held_inputs``): each sample holds until the next one, each row's force the
  mean of that staircase over the step, the slip the latest sample at or before the row. The
  contract's replay (one row per force message, inputs held), and a plant driven by a
  controller's commanded force, which moves in steps.

The two differ by half a force sample period in when the force reaches the film: 2.5 ms at
200 Hz. Read the wrong way, the data carry that much apparent delay. A campaign made as replay
reads it (the plant driven by the force held between its 200 Hz samples, the torque logged at
1 kHz, nothing hidden: an independent generator's `none`), read linearly, named a 2.5 ms
transport delay (held-out t = 16.9, RMSE 6.49 -> 5.24 N*m), and the extended model made the
unseen bag worse under replay (13.2 -> 14.1 N*m against the true torque): the delay made up
for the reading, not for anything in the clutch.

So the data choose (``choose_input_timing``). The bench-fitted model is simulated both ways
on the campaign's slipping rows (|slip| > MIN_SLIP_RAD_S, up to MAX_ROWS rows from each run's
start) and the measured torque regressed on the difference of the two predictions, d = held -
linear, beside the linear prediction and a constant (the bench friction's misfit, which moves
with the torque's level, not its rate):

    measured - linear = beta * d + gamma * linear + c + noise

beta = 0 says linear, 1 says held; the held reading is taken when BETA_HELD < beta <=
BETA_HELD_MAX. Since stop 61 the regression also holds the shape of an actuator hysteresis
(the model with a 3 % band, less the linear prediction, ``HYSTERESIS_PROBE_RATIO``) when the
data give it a band of 1 % or more (``HYSTERESIS_MIN_BAND``): the torque a hysteresis moves
follows the sign of the force's rate, as the half-period lag of the held reading does, and took
the weight. Where there is no hysteresis its shape stays out: under a force that never rests
(a sweep) the two columns are nearly collinear, and on clean logs of either kind the column
moved beta by +0.36 with a band of -0.1 to -0.2 %. On an outside generator's hysteresis (a 5.7 % band,
chirps, a log held as replay reads it) beta was 4.56 without it, so the linear reading was kept,
a transport delay took up the half period and the rest stayed structure (`unexplained`); with
it beta is 0.96, the hysteresis is named alone and the held-out RMSE goes 23.5 -> 3.1 N*m. On
the 45 campaigns of three generators it moved no other decision across 0.5 or 4 except an
eighth-generator hysteresis (23.6 -> 2.2, held; it had been named under the linear reading
too). Measured: on the virtual car's `none` campaigns under every unaligned condition
(unaligned, quantised, sign_changes, car; seeds 1-5) beta was -0.33 to 0.18; on the two
independent generators' `none` campaigns, made as replay reads the inputs, 0.89 to 1.82.

A delay or a lag in the data makes the measurement later than both readings, and the held
reading is the linear one half a force period later: the two are confounded, and beta far
above 1 (7.5 to 96 with a catalog delay or lag on the virtual car and the two generators)
says a time mechanism is there, not how the inputs were read. The linear reading is then kept
(the diagnosis as it was before the choice): where the log held its inputs, the fitted delay or
time constant comes out half a force period long, 2.5 ms at 200 Hz. Taking the held reading
there instead cost a pair on the virtual car (a 113 ms delay with a 2.5 N*m/(rad/s) drag,
car#3, beta 30: the drag's held-out t after the delay fell from 6.3 to 1.9, and it was lost).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

BETA_HELD = 0.5          # the held reading is taken above this weight on it ...
BETA_HELD_MAX = 4.0      # ... and up to this one: far later than both readings, a delay or a lag
                         # is in the data and the weight says nothing of the reading
MIN_SLIP_RAD_S = 0.3     # rows compared: slipping (a lock phase's torque is the driveline's)
MAX_ROWS = 200_000       # rows simulated per reading, shared by the runs from their starts
# two readings of one log (the inputs', the sump's, the torque's stamps; the plant on its grid or
# its rows) are told apart only where their predictions differ by this much at least ...
READING_MIN_DIFFERENCE_NM = 0.1
READING_NOISE_FRAC = 0.3  # ... and by this share of the measured torque's noise near Nyquist
HYSTERESIS_PROBE_RATIO = 0.03   # the band of the hysteresis whose shape joins the regression ...
HYSTERESIS_MIN_BAND = 0.01      # ... and the band it must find in the data to keep its place there


def held_at(sample_t: np.ndarray, sample_v: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The latest sample at or before each time (the first sample before it)."""
    i = np.searchsorted(np.asarray(sample_t, float), np.asarray(t, float), side="right") - 1
    return np.asarray(sample_v, float)[np.clip(i, 0, len(sample_v) - 1)]


def step_mean_of_held(sample_t: np.ndarray, sample_v: np.ndarray, t: np.ndarray) -> np.ndarray:
    """For rows at ``t``: the mean over each row's step [t_k, t_k+1] of the samples held
    until the next one (exact integral of the staircase); the last row, the held value."""
    ts = np.asarray(sample_t, float)
    vs = np.asarray(sample_v, float)
    t = np.asarray(t, float)
    out = held_at(ts, vs, t)
    if t.size < 2 or ts.size == 0:
        return out
    area = np.concatenate([[0.0], np.cumsum(vs[:-1] * np.diff(ts))])   # integral up to each sample

    def integral(x):
        i = np.clip(np.searchsorted(ts, x, side="right") - 1, 0, ts.size - 1)
        return area[i] + vs[i] * (x - ts[i])            # before the first sample: its value held back

    dt = np.diff(t)
    ok = dt > 0
    mean = (integral(t[1:]) - integral(t[:-1]))
    out[:-1][ok] = mean[ok] / dt[ok]
    return out


def with_held_inputs(campaign):
    """The measured-time campaign (``measured_time_campaign``, with or without the midpoint
    force: the force and slip are read again from each run's own samples) read as replay
    reads its inputs: each row's force the mean over its step of the force
    samples held until the next one, the slip the latest sample at or before the row (the
    sump temperature, slow, as it is); a plant grid (``run_plant_grid``) read held as well.
    Runs without their own samples are kept."""
    from clutch_model.formats.bag_reader import Campaign

    from clutch_model.diagnosis.measured_time import run_plant_grid

    runs = []
    for run in campaign.runs:
        held = _held_run_inputs(run, np.asarray(run.t, float))
        if held is not None:
            run = replace(run, applied_force_n=held[0], slip_speed_rad_s=held[1])
            if run.plant_grid is not None:
                run = replace(run, plant_grid=run_plant_grid(run, held=True))
        runs.append(run)
    return Campaign(runs)


@dataclass
class InputTiming:
    """The reading chosen, and the figures it was chosen on."""

    held: bool
    beta: float            # weight on the held reading (0 linear, 1 held)
    rows: int              # rows compared
    difference_rms_nm: float   # rms of held - linear prediction on them
    hysteresis_band: float = 0.0   # the band a hysteresis in the data took (0: none, beta without it)

    def describe(self) -> str:
        what = "held between samples (as replay)" if self.held else "linear between samples"
        band = (f"; a hysteresis band of {100 * self.hysteresis_band:.1f} % held apart"
                if self.hysteresis_band else "")
        return (f"inputs read {what}: the measured torque sides with the held reading by weight "
                f"{self.beta:.2f} over {self.rows} slipping rows (the readings differ by "
                f"{self.difference_rms_nm:.2f} N*m rms{band})")

    def to_dict(self) -> dict:
        return {"inputs_between_samples": "held" if self.held else "linear", "held_weight": self.beta,
                "rows": self.rows, "difference_rms_nm": self.difference_rms_nm,
                "hysteresis_band_held_apart": self.hysteresis_band}


def _held_run_inputs(run, t: np.ndarray) -> tuple:
    """(force, slip) of a run read held at rows ``t`` (with_held_inputs' reading), or None
    when the run has not its own samples."""
    force = run.samples.get("applied_force")
    slip = run.samples.get("slip_speed")
    if force is None or slip is None or t.size < 2:
        return None
    return step_mean_of_held(*force, t), held_at(*slip, t)


@dataclass
class ReadingComparison:
    """Two readings of one campaign's head simulated by one model, on its slipping rows."""

    p_first: np.ndarray      # the first reading's prediction (every row)
    y: np.ndarray            # the measured torque (every row)
    ok: np.ndarray           # slipping rows with every value finite
    d: np.ndarray            # second - first prediction on those rows
    n: int
    rms: float               # rms of d


def force_sample_period_s(campaign) -> float:
    """The applied force's median sample interval (its own samples; the rows' when a run has
    none), s."""
    from clutch_model.diagnosis.measured_time import median_interval_s

    dts = [median_interval_s(run.samples.get("applied_force", (run.t,))[0]) for run in campaign.runs]
    dts = [d for d in dts if np.isfinite(d)]
    return float(np.median(dts)) if dts else float("nan")


def reading_unsettled(inputs: dict) -> bool:
    """Whether the inputs' reading between samples is left open by the data: read linearly
    with a weight on the held reading above BETA_HELD_MAX (a delay or lag in the data, which the
    held reading's half period of the force mimics)."""
    beta = inputs.get("held_weight")
    return (inputs.get("inputs_between_samples") == "linear" and beta is not None
            and np.isfinite(beta) and beta > BETA_HELD_MAX)


def campaign_head(campaign, max_rows: int = MAX_ROWS, keep=None):
    """The first ``max_rows`` rows of the campaign, shared by its runs from their starts (runs
    with a measured torque, and ``keep(run)`` when given), or None when no run is left."""
    from clutch_model.diagnosis.input_hold import run_rows
    from clutch_model.formats.bag_reader import Campaign

    per_run = max(max_rows // max(len(campaign.runs), 1), 2)
    runs = [run_rows(r, slice(0, per_run)) for r in campaign.runs if r.torque_measured_nm is not None]
    runs = [r for r in runs if keep is None or keep(r)]
    return Campaign(runs) if runs else None


def difference_bar_nm(noise_nm: float) -> float:
    """How far two readings' predictions must differ (rms, N*m) for the data to choose between
    them: READING_MIN_DIFFERENCE_NM, and READING_NOISE_FRAC of ``noise_nm`` (the measured
    torque's noise near Nyquist; NaN counts as 0)."""
    return max(READING_MIN_DIFFERENCE_NM, READING_NOISE_FRAC * (noise_nm if np.isfinite(noise_nm) else 0.0))


def compare_readings(model, first, second, min_slip_rad_s: float = MIN_SLIP_RAD_S) -> ReadingComparison:
    """``model`` simulated on two readings of the same rows (campaigns ``first`` and
    ``second``), compared on the rows where the clutch slips (|slip| > ``min_slip_rad_s``:
    a lock phase's torque is the driveline's) and every value is finite."""
    from clutch_model.prediction import predict_campaign

    p_first, p_second = (np.asarray(predict_campaign(model, c, energy0_j=0.0).torque_nm, float)
                         for c in (first, second))
    y = np.asarray(first.torque_measured, float)
    ok = (np.isfinite(y) & np.isfinite(p_first) & np.isfinite(p_second)
          & (np.abs(np.asarray(first.slip, float)) > min_slip_rad_s))
    d = (p_second - p_first)[ok]
    n = int(ok.sum())
    return ReadingComparison(p_first, y, ok, d, n, float(np.sqrt(np.mean(d * d))) if n else 0.0)


def choose_input_timing(linear, model, max_rows: int = MAX_ROWS) -> InputTiming:
    """Which reading of the inputs the measured torque sides with (module docstring): the
    model simulated on the linear campaign (``with_midpoint_force`` of the measured-time
    campaign, its runs' own samples kept) and on the same rows read held, up to ``max_rows``
    rows from the runs' starts; the torque regressed on the difference of the two
    predictions. Only the chosen campaign is ever built whole (``with_held_inputs``)."""
    from clutch_model.plant.mechanisms import make_mechanism
    from clutch_model.prediction import predict_campaign

    head = campaign_head(linear, max_rows, keep=lambda r: _held_run_inputs(r, r.t) is not None)
    if head is None:
        return InputTiming(held=False, beta=float("nan"), rows=0, difference_rms_nm=0.0)
    cmp = compare_readings(model, head, with_held_inputs(head))
    p_lin, y, ok, d, n, rms = cmp.p_first, cmp.y, cmp.ok, cmp.d, cmp.n, cmp.rms
    if n < 10 or not rms > 0:
        return InputTiming(held=False, beta=float("nan"), rows=n, difference_rms_nm=rms)
    # the shape of an actuator hysteresis (the same model with a band of HYSTERESIS_PROBE_RATIO,
    # less the linear prediction): the torque it moves follows the sign of the force's rate,
    # as the held reading's half-period lag does, and without it takes the weight
    probe = [m for m in model.mechanisms if m.id != "actuator_hysteresis"] + [
        make_mechanism("actuator_hysteresis", ratio=HYSTERESIS_PROBE_RATIO)]
    p_hyst = np.asarray(predict_campaign(model.with_mechanisms(probe), head, energy0_j=0.0).torque_nm, float)
    band = np.nan_to_num((p_hyst - p_lin)[ok])
    X = np.column_stack([d, p_lin[ok], np.ones(n)])
    beta = float(np.linalg.lstsq(X, (y - p_lin)[ok], rcond=None)[0][0])
    coef = np.linalg.lstsq(np.column_stack([X, band]), (y - p_lin)[ok], rcond=None)[0]
    band_ratio = float(coef[3]) * HYSTERESIS_PROBE_RATIO
    if band_ratio >= HYSTERESIS_MIN_BAND:       # a hysteresis is there: its shape takes its part
        beta = float(coef[0])
    else:
        band_ratio = 0.0
    return InputTiming(held=bool(BETA_HELD < beta <= BETA_HELD_MAX), beta=beta, rows=n, difference_rms_nm=rms,
                       hysteresis_band=band_ratio)
