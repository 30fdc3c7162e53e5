"""Compare where the measurement is: a model evaluated at the measured torque's own stamps.

Two ways, both keeping the replay CSV of the contract as it is:

``simulate_at_measured_times`` (use this for calibration and diagnosis residuals) simulates
each run on a fine grid (``rate_hz``, 1 kHz by default) joined with the torque stamps, every
input linearly interpolated between its own samples (first-order hold), so the model's output
sits exactly at each torque sample's log time. A zero-order hold of the inputs (the replay
grid) lags the true inputs by half a sample period on average: force at 200 Hz held makes
the model ~2.5 ms late (on the car-log virtual car: best-aligned lag −2.5 to −4 ms with the
hold, −0.5 to 0 ms with the linear one), which a diagnosis would read as a transport delay.

``at_measured_times`` evaluates a per-row signal of the replay grid at the torque stamps:

The replay grid has one row per applied-force message and holds the latest
torque sample at each row; a torque logged at 50 Hz against a 200 Hz force grid is then up to
20 ms stale, which looks like a transport delay. Here the model's per-row signal (the plant
torque, or the predicted measurement) is evaluated at each torque sample's own log time by
linear interpolation between the two grid rows around it. Between rows the plant evolves
with the inputs held, so linear interpolation is exact up to the curvature over one row
interval (5 ms at 200 Hz) and smooths a step at an input sample over one interval — fine
where the force grid is dense relative to the torque rate, as on car logs (100-1000 Hz force,
10-200 Hz torque). Torque samples before a run's first grid row or after its last get NaN
(``valid`` False): the model has no state there.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def interpolate_on_grid(t_grid, y_grid, t_query) -> np.ndarray:
    """Linear interpolation of a per-row signal at query times; NaN outside the grid."""
    t_grid = np.asarray(t_grid, float)
    y_grid = np.asarray(y_grid, float)
    t_query = np.asarray(t_query, float)
    out = np.interp(t_query, t_grid, y_grid)
    out[(t_query < t_grid[0]) | (t_query > t_grid[-1])] = np.nan
    return out


@dataclass
class MeasuredComparison:
    """Model and measurement at the measured torque's stamps, runs concatenated."""

    names: list               # run names, in campaign order
    run_index: np.ndarray     # run of each sample
    t: np.ndarray             # stamp, s from the run's bag start
    model: np.ndarray         # the model signal evaluated there (NaN where invalid)
    measured: np.ndarray
    valid: np.ndarray         # inside the run's grid and finite

    @property
    def residual(self) -> np.ndarray:
        return self.measured - self.model

    def rmse(self, mask=None) -> float:
        ok = self.valid if mask is None else (self.valid & mask)
        return float(np.sqrt(np.mean(self.residual[ok] ** 2))) if ok.any() else float("nan")

    def run_slice(self, j: int) -> slice:
        idx = np.flatnonzero(self.run_index == j)
        return slice(int(idx[0]), int(idx[-1]) + 1) if idx.size else slice(0, 0)


def at_measured_times(campaign, y_grid) -> MeasuredComparison:
    """Evaluate a per-row signal of a bag_reader.Campaign (e.g. ReplayResult.torque_sim)
    at every run's measured-torque stamps (``Run.torque_measured_t``). Runs without a
    measured torque contribute nothing."""
    y_grid = np.asarray(y_grid, float)
    parts = {"i": [], "t": [], "m": [], "y": []}
    for j, (run, sl) in enumerate(campaign.slices()):
        tq = run.torque_measured_t
        if tq is None or tq.size == 0:
            continue
        parts["i"].append(np.full(tq.size, j))
        parts["t"].append(tq)
        parts["m"].append(interpolate_on_grid(run.t, y_grid[sl], tq))
        parts["y"].append(run.torque_measured_raw_nm)
    if not parts["t"]:
        z = np.zeros(0)
        return MeasuredComparison(campaign.names, z.astype(int), z, z, z, z.astype(bool))
    cat = np.concatenate
    model, meas = cat(parts["m"]), cat(parts["y"])
    return MeasuredComparison(campaign.names, cat(parts["i"]), cat(parts["t"]), model, meas,
                              np.isfinite(model) & np.isfinite(meas))


def replay_at_measured_times(model, runs, energy0_j=None):
    """replay_runs(model, runs) evaluated at the measured torque's stamps:
    (ReplayResult, MeasuredComparison of the predicted measured torque)."""
    from clutch_model.replay import replay_runs

    result = replay_runs(model, runs, energy0_j=energy0_j)
    return result, at_measured_times(result.campaign, result.torque_sim)


def plant_inputs_start_s(run) -> float:
    """When a run's plant can start: its first instant with both a force and a slip sample.

    The replay grid starts once every input topic has started, the sump temperature
    included, and a sump logged at 1-4 Hz starts up to a second after the others. The plant
    started from its rest state there (an open film) has missed that much squeeze under the
    force already applied, and at low force the film remembers it for a second or more:
    on an outside campaign (sump at 3.7 Hz, first row 0.23 s after the force and slip began)
    the true model was 23 N*m off over the run's first second, and a candidate that mimicked
    the missed squeeze won a lookalike head to head there. The sump temperature moves the
    torque through the oil and pack temperatures, slowly: its first sample is held back to
    the plant's start."""
    starts = [float(run.samples[ch][0][0]) for ch in ("applied_force", "slip_speed")
              if ch in run.samples and len(run.samples[ch][0])]
    return max(starts) if len(starts) == 2 else float(run.t[0])


def _run_grid(run, rate_hz, from_inputs: bool = False):
    tq = run.torque_measured_t
    t0 = min(plant_inputs_start_s(run), float(run.t[0])) if from_inputs else float(run.t[0])
    t_end = float(run.t[-1])
    if tq is not None and tq.size:
        t_end = max(t_end, float(tq[-1]))
    fine = t0 + np.arange(int(np.floor((t_end - t0) * rate_hz)) + 1) / rate_hz
    stamps = tq[(tq >= t0) & (tq <= t_end)] if tq is not None else np.zeros(0)
    if stamps.size:
        # fine points within 0.2 periods of a stamp are dropped (no near-duplicate rows)
        pos = np.clip(np.searchsorted(stamps, fine), 1, stamps.size - 1) if stamps.size > 1 else np.zeros(fine.size, int)
        near = np.minimum(np.abs(fine - stamps[pos]), np.abs(fine - stamps[np.maximum(pos - 1, 0)]))
        fine = fine[near > 0.2 / rate_hz]
    return _gaps_filled(np.union1d(fine, stamps), stamps)


GAP_PERIODS = 3.0    # a gap of the torque stamps longer than this many of their median periods


def _gaps_filled(grid, stamps):
    """The grid with rows at the torque's median period inside every gap of its stamps longer
    than GAP_PERIODS periods (a dropout of the torque topic): without them the plant crossed
    the gap in one step with the inputs of its first row, and what the force and the slip did
    in it was lost (an outside generator's 50-500 ms torque dropouts fell on the release after
    a lock phase: the model, still held at the lock's 14 kN, read 87 N*m where the clutch gave
    385, 300 N*m off for 0.2 s after each such gap). The rows carry no torque."""
    if stamps.size < 3:
        return grid
    period = float(np.median(np.diff(stamps)))
    if not period > 0.0:
        return grid
    gap = np.diff(grid)
    wide = np.flatnonzero(gap > GAP_PERIODS * period)
    if not wide.size:
        return grid
    fill = [np.arange(grid[k] + period, grid[k + 1] - 0.5 * period, period) for k in wide]
    return np.union1d(grid, np.concatenate(fill))


@dataclass
class MeasuredTimeGrid:
    """A campaign's simulation grid for comparing where the measurement is: per run a
    ``rate_hz`` grid from the run's first replay row joined with its torque stamps, inputs
    linearly interpolated between their own samples (held after the last one); runs
    concatenated in log-time order. Feed ``t, force, slip, sump, run_start`` to
    ``simulate`` / ``simulate_batch``; ``torque_rows`` picks the rows of the torque samples."""

    names: list
    t: np.ndarray
    force: np.ndarray
    slip: np.ndarray
    sump: np.ndarray
    run_start: np.ndarray
    run_index: np.ndarray        # run of each grid row
    torque_run: np.ndarray       # run of each torque sample
    torque_t: np.ndarray         # stamp of each torque sample, s from its bag start
    torque_measured: np.ndarray  # the measured torque samples
    torque_rows: np.ndarray      # grid row of each torque sample (-1: before the run's first row)
    start_time_ns: int = 0       # the first run's start (for the model's energy history)

    def at_torque_stamps(self, values) -> np.ndarray:
        """A per-grid-row signal (1-D, or (n_sets, n_rows)) at the torque samples; NaN (or
        False for booleans) where a torque sample has no row."""
        values = np.asarray(values)
        ok = self.torque_rows >= 0
        rows = np.maximum(self.torque_rows, 0)
        picked = values[..., rows]
        if values.dtype == bool:
            return picked & ok
        return np.where(ok, picked, np.nan)

    def comparison(self, y_grid) -> MeasuredComparison:
        model = self.at_torque_stamps(np.asarray(y_grid, float))
        return MeasuredComparison(self.names, self.torque_run, self.torque_t, model, self.torque_measured,
                                  np.isfinite(model) & np.isfinite(self.torque_measured))


def measured_time_grid(runs, rate_hz: float = 1000.0) -> MeasuredTimeGrid:
    """Build the measured-time grid of runs (a Campaign or a list of Run as read by
    bag_reader, which keep every topic's own samples)."""
    from clutch_model.formats.bag_reader import Campaign

    campaign = runs if isinstance(runs, Campaign) else Campaign(list(runs))
    grids, inputs = [], {"applied_force": [], "slip_speed": [], "sump_temperature": []}
    tr, tt, tm, rows = [], [], [], []
    off = 0
    for j, run in enumerate(campaign.runs):
        g = _run_grid(run, rate_hz)
        grids.append(g)
        for ch in inputs:
            ts, vs = run.samples[ch]
            inputs[ch].append(np.interp(g, ts, vs))
        tq = run.torque_measured_t
        if tq is not None and tq.size:
            pos = np.minimum(np.searchsorted(g, tq), g.size - 1)
            hit = np.abs(g[pos] - tq) < 1e-12
            tr.append(np.full(tq.size, j)); tt.append(tq); tm.append(run.torque_measured_raw_nm)
            rows.append(np.where(hit, off + pos, -1))
        off += g.size
    sizes = [g.size for g in grids]
    run_start = np.zeros(off, bool)
    run_start[np.cumsum([0] + sizes[:-1])] = True
    cat = (lambda xs, dt=float: np.concatenate(xs) if xs else np.zeros(0, dt))
    return MeasuredTimeGrid(
        names=campaign.names, t=np.concatenate(grids), force=np.concatenate(inputs["applied_force"]),
        slip=np.concatenate(inputs["slip_speed"]), sump=np.concatenate(inputs["sump_temperature"]),
        run_start=run_start, run_index=np.repeat(np.arange(len(grids)), sizes),
        torque_run=cat(tr, int), torque_t=cat(tt), torque_measured=cat(tm), torque_rows=cat(rows, int),
        start_time_ns=int(campaign.runs[0].start_time_ns))


@dataclass
class MeasuredTimeSimulation:
    """A model simulated on a MeasuredTimeGrid."""

    grid: MeasuredTimeGrid
    sim: object               # plant.simulate.SimResult on grid.t
    torque_pred: np.ndarray   # predicted measured torque (measurement mechanisms applied)
    comparison: MeasuredComparison   # at the torque stamps (exact grid rows)

    @property
    def t(self):
        return self.grid.t

    @property
    def run_index(self):
        return self.grid.run_index


def simulate_at_measured_times(model, runs, rate_hz: float = 1000.0, energy0_j=None,
                               grid: MeasuredTimeGrid | None = None) -> MeasuredTimeSimulation:
    """Simulate runs on their measured-time grid (``measured_time_grid``; pass ``grid`` to
    reuse one): runs in log-time order, the plant restarting at each run and the dissipated
    energy carried (as replay), measurement mechanisms applied; the comparison with the
    measured torque sits at the torque's own stamps."""
    from clutch_model.plant.simulate import predict_measured_torque, simulate

    g = grid if grid is not None else measured_time_grid(runs, rate_hz)
    if energy0_j is None:
        energy0_j = model.initial_energy_j(g.start_time_ns)
    sim = simulate(model, g.t, g.force, g.slip, g.sump, run_start=g.run_start, energy0_j=energy0_j)
    pred = np.asarray(predict_measured_torque(model, g.t, sim.torque_nm, g.run_start), float)
    return MeasuredTimeSimulation(grid=g, sim=sim, torque_pred=pred, comparison=g.comparison(pred))


PLANT_GRID_DENSER = 1.5    # the force's samples at least this many times denser than the rows ...
PLANT_GRID_FORCE_CONTENT = 2.0   # ... doing between the rows this many times its noise (force_between_rows)


def median_interval_s(t) -> float:
    """The median interval of sample times ``t``, s (NaN under three samples)."""
    t = np.asarray(t, float)
    return float(np.median(np.diff(t))) if t.size > 2 else float("nan")


def plant_grid_needed(runs) -> bool:
    """Whether the rows at the measured torque's stamps are too sparse for the plant: further
    apart than the plant's own step (``kernels.MAX_STEP_S``, 5.1 ms: torque logged under ~196
    Hz) while the force was logged PLANT_GRID_DENSER times denser. The plant holds a row's force
    over its step; a force stepping within a 10 ms torque interval (a controller's request at 1
    kHz) then reaches it late or not at all. Measured on an outside generator's campaign
    (torque at 100 Hz, force at 1 kHz with 3-8 ms steps, an 8.3 ms transport delay): the true
    model simulated on the torque's rows was 10-13 N*m off its own replay at the torque stamps
    (noise 1.3 N*m); on the force's own samples 1.4."""
    from clutch_model.plant import kernels as K

    row, force, content = [], [], []
    for run in runs:
        tq = run.torque_measured_t
        samples = run.samples.get("applied_force")
        if tq is None or samples is None or tq.size < 3 or samples[0].size < 3:
            continue
        row.append(median_interval_s(tq))
        force.append(median_interval_s(samples[0]))
        content.append(force_between_rows(tq, *samples))
    if not row:
        return False
    row_s, force_s = float(np.median(row)), float(np.median(force))
    return bool(row_s > K.MAX_STEP_S and force_s * PLANT_GRID_DENSER < row_s
                and np.nanmax(content) > PLANT_GRID_FORCE_CONTENT)


def force_between_rows(rows_t, sample_t, sample_force) -> float:
    """How much the force does between rows at ``rows_t`` that a line through the rows misses:
    the rms of its samples less the line through its values at the rows, in units of its own
    noise (robust, from first differences: a step is one outlier among them, the noise is in
    all). About 1-1.5 for a smooth force with white sensor noise; steps between the rows take
    it far above. NaN when the force has too few samples to tell (features.noise_sigma)."""
    from clutch_model.diagnosis.features import noise_sigma

    ts, vs = np.asarray(sample_t, float), np.asarray(sample_force, float)
    inside = (ts >= rows_t[0]) & (ts <= rows_t[-1])
    noise = noise_sigma(vs, np.zeros(vs.size, bool))
    if inside.sum() < 3 or not np.isfinite(noise):
        return float("nan")
    line = np.interp(ts[inside], rows_t, np.interp(rows_t, ts, vs))
    miss = float(np.sqrt(np.mean((vs[inside] - line) ** 2)))
    return miss / max(noise, 1e-9 * max(float(np.max(np.abs(vs))), 1.0))


def run_plant_grid(run, held: bool = False):
    """The run's plant grid (prediction.PlantGrid): its rows joined with its force samples
    between them, the force and slip read from their own samples there (``held``: the latest
    sample at or before, as replay holds them; else linearly between samples), or None when
    the run has not its own samples. The grid starts with the first instant with a force and a
    slip sample (``plant_inputs_start_s``), before the first row when the torque began later.
    Force stamps within 0.05 ms of a row are left out (no near-empty steps)."""
    from clutch_model.diagnosis.input_timing import held_at
    from clutch_model.prediction import PlantGrid

    force, slip = run.samples.get("applied_force"), run.samples.get("slip_speed")
    rows_t = np.asarray(run.t, float)
    if force is None or slip is None or rows_t.size < 2:
        return None
    tf = np.asarray(force[0], float)
    start = min(plant_inputs_start_s(run), float(rows_t[0]))
    inside = tf[(tf >= start) & (tf < rows_t[-1])]
    if inside.size:
        pos = np.clip(np.searchsorted(rows_t, inside), 1, rows_t.size - 1)
        near = np.minimum(np.abs(inside - rows_t[pos]), np.abs(inside - rows_t[pos - 1]))
        inside = inside[near > 5e-5]
    t = np.union1d(rows_t, inside)

    def read(samples):
        return held_at(*samples, t) if held else np.interp(t, *samples)

    return PlantGrid(t=t, force=read(force), slip=read(slip), rows=np.searchsorted(t, rows_t))




@dataclass
class PlantGridChoice:
    """Whether the diagnosis simulates on the plant grids (``choose_plant_grid``)."""

    used: bool
    difference_rms_nm: float = 0.0   # rms of grid - rows prediction on the slipping rows compared
    least_nm: float = 0.0
    rows: int = 0

    def describe(self) -> str:
        if not self.rows:
            return "plant grid: the rows are dense enough for the plant"
        what = "simulated on the force's own samples" if self.used else "simulated on the rows alone"
        return (f"plant grid: the rows at the torque's stamps are sparse; {what} (the two differ by "
                f"{self.difference_rms_nm:.3g} N*m rms over {self.rows} slipping rows, against a bar of "
                f"{self.least_nm:.3g})")

    def to_dict(self) -> dict:
        return {"plant_grid": self.used, "plant_grid_difference_rms_nm": self.difference_rms_nm}


def choose_plant_grid(campaign, model, noise_nm: float = 0.0) -> PlantGridChoice:
    """Keep the runs' plant grids (``run_plant_grid``) where they matter: ``model`` simulated on
    the campaign's head with them and on the rows alone (both started with the inputs, before
    the first torque sample: only what the force did between the rows is weighed), kept when
    the two predictions differ on the slipping rows by ``input_timing.difference_bar_nm`` of
    ``noise_nm`` (the measured torque's noise near Nyquist) at least.
    A force that moves smoothly between the torque's samples reaches the plant as well through
    the step's midpoint (input_hold), and the grid then costs simulation time (four to ten
    times the rows) and changes nothing."""
    from clutch_model.diagnosis.input_timing import campaign_head, compare_readings, difference_bar_nm

    if not any(r.plant_grid is not None for r in campaign.runs):
        return PlantGridChoice(used=False)
    head = campaign_head(campaign)
    if head is None:
        return PlantGridChoice(used=False)
    cmp = compare_readings(model, without_plant_grid(head, keep_start=True), head)
    least = difference_bar_nm(noise_nm)
    return PlantGridChoice(used=bool(cmp.n >= 10 and cmp.rms >= least), difference_rms_nm=cmp.rms,
                           least_nm=least, rows=cmp.n)


def without_plant_grid(campaign, keep_start: bool = False):
    """The campaign simulated on its rows alone (every run's plant grid dropped; ``keep_start``:
    the grid cut to the rows and its first point, so the plant still starts with the inputs,
    before the first torque sample); the campaign itself when no run has a grid."""
    from dataclasses import replace

    from clutch_model.formats.bag_reader import Campaign
    from clutch_model.prediction import PlantGrid

    if not any(r.plant_grid is not None for r in campaign.runs):
        return campaign

    def cut(r):
        g = r.plant_grid
        if g is None or not keep_start or g.rows[0] == 0:
            return None
        # the rows as the plant reads them without a grid (their own force and slip), after
        # the grid's first point
        return PlantGrid(np.r_[g.t[0], r.t], np.r_[g.force[0], r.applied_force_n],
                         np.r_[g.slip[0], r.slip_speed_rad_s], np.arange(1, len(r) + 1))

    return Campaign([replace(r, plant_grid=cut(r)) for r in campaign.runs])


def measured_time_campaign(runs, rate_hz: float | None = None):
    """The campaign re-gridded for comparing where the measurement is, in the replay-grid
    form every grid-based tool takes (bag_reader.Campaign): per run a grid at ``rate_hz``
    (default: the run's mean applied-force rate) from the run's first instant with a force and
    a slip sample (``plant_inputs_start_s``; the replay grid waits for every input, the sump
    temperature included) joined with its torque stamps, inputs
    linearly interpolated between their own samples, ``torque_measured_nm`` the measured
    sample at its own stamp and NaN on every other row (so residuals exist only where the
    measurement is), pack temperature linearly interpolated. Names, start times and the raw
    samples are kept. Rows too sparse for the plant (``plant_grid_needed``) get a plant grid
    on the force's own samples (``run_plant_grid``, read linearly)."""
    from dataclasses import replace

    from clutch_model.formats.bag_reader import Campaign

    campaign = runs if isinstance(runs, Campaign) else Campaign(list(runs))
    fine = plant_grid_needed(campaign.runs)
    out = []
    for run in campaign.runs:
        tf = run.samples["applied_force"][0]
        rate = rate_hz or ((tf.size - 1) / max(float(tf[-1] - tf[0]), 1e-9) if tf.size > 1 else 200.0)
        g = _run_grid(run, rate, from_inputs=True)
        vals = {ch: np.interp(g, *run.samples[ch]) for ch in ("applied_force", "slip_speed", "sump_temperature")}
        torque = None
        tq = run.torque_measured_t
        if tq is not None and tq.size:
            torque = np.full(g.size, np.nan)
            pos = np.minimum(np.searchsorted(g, tq), g.size - 1)
            hit = np.abs(g[pos] - tq) < 1e-12
            torque[pos[hit]] = run.torque_measured_raw_nm[hit]
        pack = None
        if "pack_temperature" in run.samples:
            tp, vp = run.samples["pack_temperature"]
            pack = np.interp(g, tp, vp, left=np.nan, right=np.nan)
        row = replace(run, t=g, applied_force_n=vals["applied_force"], slip_speed_rad_s=vals["slip_speed"],
                      sump_temperature_c=vals["sump_temperature"], torque_measured_nm=torque,
                      pack_temperature_measured_c=pack, plant_grid=None)
        out.append(replace(row, plant_grid=run_plant_grid(row)) if fine else row)
    return Campaign(out)


def topics_unaligned(runs) -> bool:
    """True when some run's measured-torque stamps are not all force stamps, or leave force
    stamps between them without a torque sample (a slower torque on the force's clock, or a
    dropout of the torque topic): the replay grid would then hold each torque sample to later
    force rows, a stale reading that looks like a delay."""
    for run in runs:
        tq = run.torque_measured_t
        if tq is None or not tq.size or "applied_force" not in run.samples:
            continue
        tf = run.samples["applied_force"][0]
        pos = np.minimum(np.searchsorted(tf, tq), tf.size - 1)
        if np.any(np.abs(tf[pos] - tq) > 1e-9):
            return True
        within = np.count_nonzero((tf >= tq[0] - 1e-9) & (tf <= tq[-1] + 1e-9))
        if within > np.unique(pos).size:
            return True
    return False
