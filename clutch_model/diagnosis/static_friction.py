"""The static friction from the slip's approach to each lock phase.

The Stribeck law's static part (mu_S, and omega_S, the slip speed over which the friction falls
from mu_S to mu_C) sets the torque at slip speeds below ~0.1 rad/s: the clutch's capacity as it
locks. A bench that never slips that slowly leaves both unidentified (a bench down to
0.049 rad/s, omega_S of 0.03 rad/s: the static part is 2 % of the torque on its slowest row), and
the car calibration does not see them either: the diagnosis leaves the rows next to each lock
phase out of every residual (``engine.LOCK_PAD_S``: the lock's edges, the sign of a slip that is
sensor noise). On car logs those rows are where the written models are worst: on an outside
generator's drag campaign with lock-up the calibrated model read mu_S 0.18 against a true 0.23,
and its replay of unseen drives was 130-270 N*m off the true torque on the ~1 % of rows with
slip below 0.05 rad/s, 3.6 N*m on the rest.

So, once the diagnosis is done, each written model (calibrated and extended, each with its own
mechanisms) gets the constant terms of mu_S and omega_S (a5, a10) fitted on the rows just before
each lock phase (``lock_entry_rows``): within ``ENTRY_WINDOW_S`` of the phase's start, the
measured slip clearly above its sensor noise and the lock detection's exit threshold, away from
the slip's zero crossings. Only before a phase: after one, a measurement delay or a torque
sensor's lag still shows the driveline's torque (``engine.lock_tail_needed_s``), which no
friction law follows. The fit (``identification.calibrate_friction`` on those rows, the plant
simulated through the whole runs) is kept only when it cuts the RMSE on them by
``MIN_RMSE_CUT``. Nothing the diagnosis decided depends on it: those rows are in none of its
residuals, so its verdict, held-out RMSEs and gain are the same.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from clutch_model.errors import ClutchSimError
from clutch_model.formats.bag_reader import Campaign
from clutch_model.identification.calibrate import calibrate_friction
from clutch_model.plant.friction import monomials
from clutch_model.plant.params import ClutchModel
from clutch_model.prediction import predict_campaign

ENTRY_WINDOW_S = 0.2        # rows before a lock phase's start (the diagnosis' lock pad)
NOISE_SDS = 4.0             # the measured |slip| above this many slip-sensor noise sds ...
COEFFICIENTS = (5, 10)      # mu_S and omega_S, constant terms
# mu_S's slopes in pressure (a6) and pack temperature (a8) join where the rows before the lock
# phases spread over this much of each (10th to 90th percentile) and at least MIN_ENTRIES_SLOPES
# phases: the ninth generator's none campaign with lock-up had mu_S falling from 0.183 at 50 C
# to 0.145 at 80 C (mu_C 0.174 there); a5 alone put mu_S at 0.152 and left 62 N*m on the rows
PRESSURE_SPREAD_MPA = 0.5
TEMPERATURE_SPREAD_C = 10.0
MIN_ENTRIES_SLOPES = 6
MIN_ROWS = 20
EDGE_PERIODS = 2.0          # rows stop this many slip sample periods before the last slipping sample
MIN_ENTRIES = 2
MIN_RMSE_CUT = 0.10         # kept when the RMSE on the entry rows falls by at least this fraction
MAX_ITERATIONS = 15


@dataclass
class StaticFrictionFit:
    """What the fit did to one model (report.json ``calibration.static_friction``)."""

    kept: bool
    rows: int
    entries: int
    rmse_before_nm: float = float("nan")
    rmse_after_nm: float = float("nan")
    mu_s_before: float = float("nan")      # at the entry rows' median pressure and temperature
    mu_s_after: float = float("nan")
    omega_s_before_rad_s: float = float("nan")
    omega_s_after_rad_s: float = float("nan")
    note: str = ""
    coefficients: list = None               # the friction coefficients fitted (a5, a10, ...)
    held_out_before_nm: float = float("nan")  # fitted on every other phase: RMSE on the others
    held_out_after_nm: float = float("nan")

    def to_json(self) -> dict:
        out = {"kept": self.kept, "rows": self.rows, "lock_entries": self.entries, "note": self.note,
               "coefficients": [f"a{k}" for k in (self.coefficients or [])]}
        for k in ("rmse_before_nm", "rmse_after_nm", "held_out_before_nm", "held_out_after_nm",
                  "mu_s_before", "mu_s_after",
                  "omega_s_before_rad_s", "omega_s_after_rad_s"):
            v = getattr(self, k)
            out[k] = float(v) if np.isfinite(v) else None
        return out

    def describe(self, which: str) -> str:
        if not np.isfinite(self.rmse_before_nm):
            return f"static friction ({which}): {self.note}"
        return (f"static friction ({which}), {self.rows} rows before {self.entries} lock phases: "
                f"RMSE {self.rmse_before_nm:.1f} -> {self.rmse_after_nm:.1f} N*m, mu_S {self.mu_s_before:.3f} -> "
                f"{self.mu_s_after:.3f}, omega_S {self.omega_s_before_rad_s:.3f} -> {self.omega_s_after_rad_s:.3f} rad/s "
                f"({', '.join(f'a{k}' for k in (self.coefficients or []))})"
                + ("" if self.kept else f" ({self.note})"))


def lock_entry_rows(campaign: Campaign, lock_results, window_s: float = ENTRY_WINDOW_S) -> tuple:
    """-> (row mask over the campaign, number of lock phases with rows): rows within
    ``window_s`` before each lock phase whose |slip| stands above NOISE_SDS slip-noise sds and
    the detection's exit threshold, outside every zero crossing's window, and at or before the
    last slip sample above that floor (the detection smooths the slip, so its phases start a
    little after the clutch has locked: on an outside generator's campaign 12-17 ms, where the
    measured torque is already the driveline's). Call it while the runs still carry their
    slip samples (``run.samples``); without them the grid's slip stands in."""
    masks, entries = [], 0
    for run, res in zip(campaign.runs, lock_results):
        t = np.asarray(run.t, float)
        m = np.zeros(t.size, bool)
        floor = max(NOISE_SDS * res.noise_sigma_rad_s, res.threshold_exit_rad_s)
        w = np.asarray(run.slip_speed_rad_s, float)
        slipping = np.abs(w) > floor
        if "slip_speed" in getattr(run, "samples", {}):
            ts, ws = np.asarray(run.slip_raw_t, float), np.abs(np.asarray(run.slip_raw_rad_s, float))
        else:
            ts, ws = t, np.abs(w)
        above = ts[ws > floor]
        # the clutch may lock anywhere between the last slipping sample and the next, and a
        # slipping sample that close is as likely the sensor's noise about a locked clutch: the
        # rows stop EDGE_PERIODS slip periods before it (on the ninth generator's none campaign,
        # 100 Hz slip, the measured torque fell from 1312 to 283 N*m within 2 ms after a
        # sample still reading 0.0062 rad/s; the true model was 1100 N*m off there)
        margin = EDGE_PERIODS * float(np.median(np.diff(ts))) if ts.size > 1 else 0.0
        for a, _b in res.segments:
            k = np.searchsorted(above, a) - 1
            if k < 0:
                continue
            edge = above[k]               # the last slip sample above the floor before the phase
            near = (t > a - window_s) & (t <= edge - margin) & slipping
            if near.any():
                # the slip's sign as it approaches the lock: a row of the other sign is the slip
                # sensor's noise (slipping at 0.003 rad/s, its noise 0.003 rad/s), and the model's
                # torque flips with it (a 1200 N*m phase read -1226 against 1486 N*m measured)
                near &= np.sign(w) == np.sign(np.median(w[near]))
            if near.any():
                entries += 1
                m |= near
        masks.append(m & ~res.excluded_at(t, 0.0))
    return (np.concatenate(masks) if masks else np.zeros(0, bool)), entries


def _static_at(model: ClutchModel, pressure_mpa: float, theta_c: float) -> tuple:
    a = model.friction_coefficients
    M = monomials(pressure_mpa, theta_c)        # P and theta clamped to the box, as the kernel does
    return float(M @ a[5:10]), float(M @ a[10:15])


def fit_static_friction(model: ClutchModel, campaign: Campaign, rows: np.ndarray, entries: int) -> tuple:
    """-> (model, StaticFrictionFit): a5 and a10 of ``model`` fitted on ``rows`` of ``campaign``
    (whose measured torque is kept there), the other coefficients and the mechanisms as they
    are; the model unchanged unless a fit on every other lock phase's rows cuts the RMSE on the
    others' by MIN_RMSE_CUT, and the fit on all of them cuts theirs as much."""
    n = int(np.count_nonzero(rows & np.isfinite(campaign.torque_measured)))
    if n < MIN_ROWS or entries < MIN_ENTRIES:
        return model, StaticFrictionFit(False, n, entries, note=f"{n} rows before {entries} lock phases: too few")
    # mu_S and omega_S reported at the entry rows' median pressure and pack temperature
    try:
        pred = predict_campaign(model, campaign)
    except (ClutchSimError, ValueError, FloatingPointError) as e:
        return model, StaticFrictionFit(False, n, entries, note=f"simulation failed: {e}")
    pressure = np.asarray(pred.sim.pressure_mpa, float)[rows]
    pack = np.asarray(pred.pack_temperature_c, float)[rows]
    pressure_mpa, theta_c = float(np.median(pressure)), float(np.median(pack))
    mu0, ws0 = _static_at(model, pressure_mpa, theta_c)
    coefficients = list(COEFFICIENTS)
    if entries >= MIN_ENTRIES_SLOPES:
        p10, p90 = np.percentile(pressure, [10, 90])
        t10, t90 = np.percentile(pack, [10, 90])
        coefficients += [6] if p90 - p10 >= PRESSURE_SPREAD_MPA else []
        coefficients += [8] if t90 - t10 >= TEMPERATURE_SPREAD_C else []
    # held out first: fitted on every other lock phase's rows, the fit must cut the RMSE on the
    # others' by MIN_RMSE_CUT (a tenth generator's none campaign, rows already at 5.6 N*m with
    # 3.2 N*m of noise: fitted on all of them the cut was 10.7 %, and the unseen drives' replay
    # went from 4.8 to 12.9 N*m)
    a_rows, b_rows = _alternate_phases(rows)
    try:
        half = calibrate_friction(model, campaign, coefficients=sorted(coefficients), rows=a_rows,
                                  max_iterations=MAX_ITERATIONS)
        held_before = _rmse_on(pred.torque_nm, campaign, b_rows)
        held_after = _rmse_on(predict_campaign(half.model, campaign).torque_nm, campaign, b_rows)
        # the whole campaign is simulated (the dissipated energy carries from run to run)
        cal = calibrate_friction(model, campaign, coefficients=sorted(coefficients), rows=rows,
                                 max_iterations=MAX_ITERATIONS)
    except (ClutchSimError, ValueError, FloatingPointError) as e:
        return model, StaticFrictionFit(False, n, entries, note=f"fit failed: {e}")
    mu1, ws1 = _static_at(cal.model, pressure_mpa, theta_c)
    fit = StaticFrictionFit(False, n, entries, cal.rmse_before, cal.rmse_after, mu0, mu1, ws0, ws1,
                            coefficients=sorted(coefficients))
    if not cal.positive:
        fit.note = "kept as it was: the fitted friction is not positive over the car's range"
        return model, fit
    fit.held_out_before_nm, fit.held_out_after_nm = held_before, held_after
    if not (np.isfinite(held_after) and held_after <= (1.0 - MIN_RMSE_CUT) * held_before):
        fit.note = (f"kept as it was: fitted on every other lock phase, it cut the RMSE on the others by "
                    f"less than {100 * MIN_RMSE_CUT:.0f} % ({held_before:.1f} -> {held_after:.1f} N*m)")
        return model, fit
    if not (np.isfinite(cal.rmse_after) and cal.rmse_after <= (1.0 - MIN_RMSE_CUT) * cal.rmse_before):
        fit.note = f"kept as it was: the fit cut the RMSE by less than {100 * MIN_RMSE_CUT:.0f} %"
        return model, fit
    fit.kept = True
    return cal.model, fit          # calibrate_friction keeps the model's mechanisms


def _alternate_phases(rows: np.ndarray) -> tuple:
    """(rows of the 1st, 3rd, ... lock phase, rows of the 2nd, 4th, ...): a phase's rows are
    one contiguous stretch of ``rows``."""
    idx = np.flatnonzero(rows)
    phase = np.concatenate([[0], np.cumsum(np.diff(idx) > 1)])
    a, b = np.zeros(rows.size, bool), np.zeros(rows.size, bool)
    a[idx[phase % 2 == 0]] = True
    b[idx[phase % 2 == 1]] = True
    return a, b


def _rmse_on(predicted_nm: np.ndarray, campaign: Campaign, rows: np.ndarray) -> float:
    m = rows & np.isfinite(campaign.torque_measured)
    return float(np.sqrt(np.mean((predicted_nm[m] - campaign.torque_measured[m]) ** 2))) if m.any() else float("nan")


def with_entry_torque(campaign: Campaign, torque_by_run: list, rows: np.ndarray) -> Campaign:
    """The campaign with each run's measured torque ``torque_by_run`` (before the lock phases
    were left out) on ``rows`` and NaN elsewhere."""
    runs = []
    for (run, sl), tq in zip(campaign.slices(), torque_by_run):
        runs.append(replace(run, torque_measured_nm=np.where(rows[sl], tq, np.nan)))
    return Campaign(runs)
