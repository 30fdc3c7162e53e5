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

ENTRY_WINDOW_S = 0.2        # rows before a lock phase's start (the diagnosis' lock pad)
NOISE_SDS = 4.0             # the measured |slip| above this many slip-sensor noise sds ...
COEFFICIENTS = (5, 10)      # mu_S and omega_S, constant terms
MIN_ROWS = 20
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

    def to_json(self) -> dict:
        out = {"kept": self.kept, "rows": self.rows, "lock_entries": self.entries, "note": self.note}
        for k in ("rmse_before_nm", "rmse_after_nm", "mu_s_before", "mu_s_after",
                  "omega_s_before_rad_s", "omega_s_after_rad_s"):
            v = getattr(self, k)
            out[k] = float(v) if np.isfinite(v) else None
        return out

    def describe(self, which: str) -> str:
        if not np.isfinite(self.rmse_before_nm):
            return f"static friction ({which}): {self.note}"
        return (f"static friction ({which}), {self.rows} rows before {self.entries} lock phases: "
                f"RMSE {self.rmse_before_nm:.1f} -> {self.rmse_after_nm:.1f} N*m, mu_S {self.mu_s_before:.3f} -> "
                f"{self.mu_s_after:.3f}, omega_S {self.omega_s_before_rad_s:.3f} -> {self.omega_s_after_rad_s:.3f} rad/s"
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
        slipping = np.abs(np.asarray(run.slip_speed_rad_s, float)) > floor
        if "slip_speed" in getattr(run, "samples", {}):
            ts, ws = np.asarray(run.slip_raw_t, float), np.abs(np.asarray(run.slip_raw_rad_s, float))
        else:
            ts, ws = t, np.abs(np.asarray(run.slip_speed_rad_s, float))
        above = ts[ws > floor]
        for a, _b in res.segments:
            k = np.searchsorted(above, a) - 1
            if k < 0:
                continue
            edge = above[k]               # the last slip sample above the floor before the phase
            near = (t > a - window_s) & (t <= edge) & slipping
            if near.any():
                # the slip's sign as it approaches the lock: a row of the other sign is the slip
                # sensor's noise (slipping at 0.003 rad/s, its noise 0.003 rad/s), and the model's
                # torque flips with it (a 1200 N*m phase read -1226 against 1486 N*m measured)
                sign = np.sign(np.median(np.asarray(run.slip_speed_rad_s, float)[near]))
                near &= np.sign(np.asarray(run.slip_speed_rad_s, float)) == sign
            if near.any():
                entries += 1
                m |= near
        masks.append(m & ~res.excluded_at(t, 0.0))
    return (np.concatenate(masks) if masks else np.zeros(0, bool)), entries


def _static_at(model: ClutchModel, pressure_mpa: float, theta_c: float) -> tuple:
    a = model.friction_coefficients
    M = monomials(pressure_mpa, theta_c)
    return float(M @ a[5:10]), float(M @ a[10:15])


def fit_static_friction(model: ClutchModel, campaign: Campaign, rows: np.ndarray, entries: int) -> tuple:
    """-> (model, StaticFrictionFit): a5 and a10 of ``model`` fitted on ``rows`` of ``campaign``
    (whose measured torque is kept there), the other coefficients and the mechanisms as they
    are; the model unchanged unless the fit cuts the RMSE on the rows by MIN_RMSE_CUT."""
    n = int(np.count_nonzero(rows & np.isfinite(campaign.torque_measured)))
    if n < MIN_ROWS or entries < MIN_ENTRIES:
        return model, StaticFrictionFit(False, n, entries, note=f"{n} rows before {entries} lock phases: too few")
    # mu_S and omega_S reported at the entry rows' median pressure and sump temperature
    pressure_mpa = float(np.median(campaign.force[rows])) / model.nominal_area_m2 / 1e6
    theta_c = float(np.median(campaign.sump[rows]))
    mu0, ws0 = _static_at(model, pressure_mpa, theta_c)
    # the whole campaign is simulated (the dissipated energy carries from run to run)
    try:
        cal = calibrate_friction(model, campaign, coefficients=list(COEFFICIENTS), rows=rows,
                                 max_iterations=MAX_ITERATIONS)
    except (ClutchSimError, ValueError, FloatingPointError) as e:
        return model, StaticFrictionFit(False, n, entries, note=f"fit failed: {e}")
    mu1, ws1 = _static_at(cal.model, pressure_mpa, theta_c)
    fit = StaticFrictionFit(False, n, entries, cal.rmse_before, cal.rmse_after, mu0, mu1, ws0, ws1)
    if not (np.isfinite(cal.rmse_after) and cal.rmse_after <= (1.0 - MIN_RMSE_CUT) * cal.rmse_before
            and cal.positive):
        fit.note = f"kept as it was: the fit cut the RMSE by less than {100 * MIN_RMSE_CUT:.0f} %"
        return model, fit
    fit.kept = True
    return cal.model.with_mechanisms(model.mechanisms), fit


def with_entry_torque(campaign: Campaign, torque_by_run: list, rows: np.ndarray) -> Campaign:
    """The campaign with each run's measured torque ``torque_by_run`` (before the lock phases
    were left out) on ``rows`` and NaN elsewhere."""
    runs = []
    for (run, sl), tq in zip(campaign.slices(), torque_by_run):
        runs.append(replace(run, torque_measured_nm=np.where(rows[sl], tq, np.nan)))
    return Campaign(runs)
