"""The one prediction path: campaign + model -> predicted *measured* torque.

The runs of a campaign are simulated as one trajectory in log-time order: the plant restarts
at each run (film, pack temperature, actuator states) while the dissipated energy carries from
run to run (friction_degradation); the model's measurement mechanisms (torque_offset,
transport_delay, torque_sensor_lag, in catalog order) then map the plant torque to what the
sensor reads. Replay, calibration, Monte Carlo, sensitivity and diagnosis all predict through
``predict_campaign``.

What it predicts for:
  * a ``ClutchModel``: one trajectory with every plant signal (``Prediction.sim``);
  * a list of ``ClutchModel``: one batch (parallel over the models), each with its own
    measurement mechanisms;
  * a parameter matrix (rows of ``ClutchModel.vector()``): one batch, with the measurement
    mechanisms given in ``measurement`` (shared by all rows).
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from clutch_model.plant.mechanisms import apply_measurement
from clutch_model.plant.params import ClutchModel
from clutch_model.plant.simulate import SimResult, simulate, simulate_batch


@dataclass(frozen=True)
class PlantGrid:
    """A run's plant inputs on a grid finer than its rows: the plant is simulated on ``t`` and
    read at ``rows`` (the index in ``t`` of each of the run's rows; the grid may start before
    the first row, with the inputs: the plant restarts at ``t[0]``). The
    diagnosis compares where a sparse torque was measured (diagnosis.measured_time): its rows
    sit at the torque's stamps, 10-20 ms apart at 50-100 Hz, and a force stepping within such
    a step reaches the plant only through its own samples. The sump temperature, slow, is read
    from the run's rows (linearly between them)."""

    t: np.ndarray
    force: np.ndarray
    slip: np.ndarray
    rows: np.ndarray

    def window(self, a: int, b: int) -> "PlantGrid":
        """The grid of the run's rows a..b-1 (a window of the run; from the run's start with
        its first row)."""
        lo, hi = (0 if a == 0 else int(self.rows[a])), int(self.rows[b - 1]) + 1
        return PlantGrid(self.t[lo:hi], self.force[lo:hi], self.slip[lo:hi], self.rows[a:b] - lo)


def _grid_of(run):
    """(t, force, slip, sump, rows) of a run on its plant grid, or None (the rows themselves)."""
    g = getattr(run, "plant_grid", None)
    if g is None:
        return None
    sump = np.interp(g.t, np.asarray(run.t, float), np.asarray(run.sump_temperature_c, float))
    return g.t, g.force, g.slip, sump, g.rows


def _start_states(runs, sizes) -> tuple:
    """(start_index, start_states) of runs concatenated in blocks of ``sizes`` rows: the runs
    with a ``plant_state0`` (diagnosis.sample.WindowRun) start from it; (None, None) when none
    does."""
    if not any(getattr(r, "plant_state0", None) is not None for r in runs):
        return None, None
    index = np.full(int(sum(sizes)), -1, dtype=np.int64)
    states, k = [], 0
    for r, n in zip(runs, sizes):
        if getattr(r, "plant_state0", None) is not None:
            index[k] = len(states)
            states.append(np.asarray(r.plant_state0, float))
        k += n
    return index, np.ascontiguousarray(np.stack(states))


@dataclass(frozen=True)
class PlantInputs:
    """The simulator inputs of a campaign on its concatenated grid."""

    t: np.ndarray
    force: np.ndarray
    slip: np.ndarray
    sump: np.ndarray
    run_start: np.ndarray
    first_start_time_ns: int | None = None   # log time of the first run (campaign energy history)
    # runs that start from a given plant state (diagnosis.sample: windows of a long campaign):
    # start_index[k] = j >= 0 on such a run's first row, start_states[j] its state; else None
    start_index: np.ndarray | None = None
    start_states: np.ndarray | None = None
    # runs on a plant grid finer than their rows (PlantGrid): the index in the grid of each of
    # the campaign's rows, where predictions are read; None: the grid is the rows
    pick: np.ndarray | None = None

    @classmethod
    def of(cls, campaign) -> "PlantInputs":
        """From a Campaign (or anything carrying t, force, slip, sump, run_start). Runs with a
        ``plant_state0`` (diagnosis.sample.WindowRun) start from that plant state."""
        if isinstance(campaign, PlantInputs):
            return campaign
        runs = getattr(campaign, "runs", None)
        if runs and any(getattr(r, "plant_grid", None) is not None for r in runs):
            return cls._on_plant_grids(runs)
        start = int(runs[0].start_time_ns) if runs else None
        index, states = _start_states(runs or [], [len(r) for r in runs or []])
        return cls(t=np.ascontiguousarray(campaign.t, float), force=np.ascontiguousarray(campaign.force, float),
                   slip=np.ascontiguousarray(campaign.slip, float), sump=np.ascontiguousarray(campaign.sump, float),
                   run_start=np.ascontiguousarray(campaign.run_start, bool), first_start_time_ns=start,
                   start_index=index, start_states=states)

    @classmethod
    def _on_plant_grids(cls, runs) -> "PlantInputs":
        """Runs concatenated on their plant grids (a run without one on its rows), ``pick``
        the campaign's rows in them."""
        parts, picks = [], []
        off = 0
        for r in runs:
            part = _grid_of(r)
            if part is None:
                part = (r.t, r.applied_force_n, r.slip_speed_rad_s, r.sump_temperature_c, np.arange(len(r)))
            part = tuple(np.asarray(x, float) for x in part[:4]) + (np.asarray(part[4], np.int64),)
            parts.append(part)
            picks.append(part[4] + off)
            off += part[0].size
        sizes = [p[0].size for p in parts]
        run_start = np.zeros(off, bool)
        run_start[np.cumsum([0] + sizes[:-1])] = True
        start_index, start_states = _start_states(runs, sizes)
        cat = (lambda k: np.ascontiguousarray(np.concatenate([p[k] for p in parts])))
        return cls(t=cat(0), force=cat(1), slip=cat(2), sump=cat(3), run_start=run_start,
                   first_start_time_ns=int(runs[0].start_time_ns), start_index=start_index,
                   start_states=start_states, pick=np.concatenate(picks))

    def at_rows(self, values):
        """A signal on the simulation grid (1-D, or (n_sets, n)) read at the campaign's rows."""
        return values if self.pick is None else np.asarray(values)[..., self.pick]

    @property
    def start(self) -> dict:
        """The given start states as keyword arguments of simulate / simulate_batch."""
        if self.start_states is None:
            return {}
        return {"start_index": self.start_index, "start_states": self.start_states}

    @property
    def n_rows(self) -> int:
        """Rows of the campaign (what predictions give; the simulation grid may be finer)."""
        return int(self.t.size if self.pick is None else self.pick.size)


@dataclass(frozen=True)
class Prediction:
    """Predicted measured torque (``torque_nm``, (n,) or (n_sets, n)) and the plant behind it."""

    torque_nm: np.ndarray              # what the sensor reads (measurement mechanisms applied)
    plant_torque_nm: np.ndarray        # transmitted torque
    pack_temperature_c: np.ndarray
    energy0_j: float
    sim: SimResult | None = None       # every plant signal (single model only)


def initial_energy(model: ClutchModel, inputs: PlantInputs) -> float:
    """Campaign energy the model knows at the first run's start (0 for a fresh model)."""
    if inputs.first_start_time_ns is None:
        return 0.0
    return model.initial_energy_j(inputs.first_start_time_ns)


def _sim_at(sim: SimResult, pick) -> SimResult:
    return replace(sim, **{f.name: getattr(sim, f.name)[pick] for f in fields(sim)})


def predict_campaign(model_or_rows, campaign, energy0_j: float | None = None, measurement=None,
                     on_grid: bool = False) -> Prediction:
    """Predicted measured torque of a model (or models, or parameter rows) on a campaign.

    ``energy0_j``: dissipated energy at the first row; default: what a single model's campaign
    history knows at the first run's start, 0 for batches. ``measurement``: measurement
    mechanisms for parameter rows (models carry their own). Runs on a plant grid finer than
    their rows (PlantGrid) are simulated on it, the measurement mechanisms applied there, and
    every signal read at the rows (``on_grid``: left on the grid, ``PlantInputs.at_rows``)."""
    inputs = PlantInputs.of(campaign)
    pred = _predict_on_grid(model_or_rows, inputs, energy0_j, measurement)
    if inputs.pick is None or on_grid:
        return pred
    pick = inputs.pick
    return Prediction(torque_nm=pred.torque_nm[..., pick], plant_torque_nm=pred.plant_torque_nm[..., pick],
                      pack_temperature_c=pred.pack_temperature_c[..., pick], energy0_j=pred.energy0_j,
                      sim=None if pred.sim is None else _sim_at(pred.sim, pick))


def _predict_on_grid(model_or_rows, inputs: PlantInputs, energy0_j, measurement) -> Prediction:
    args = (inputs.t, inputs.force, inputs.slip, inputs.sump)
    if isinstance(model_or_rows, ClutchModel):
        model = model_or_rows
        e0 = initial_energy(model, inputs) if energy0_j is None else float(energy0_j)
        sim = simulate(model, *args, run_start=inputs.run_start, energy0_j=e0, **inputs.start)
        torque = apply_measurement(model.mechanisms, inputs.t, sim.torque_nm, inputs.run_start)
        return Prediction(torque_nm=torque, plant_torque_nm=sim.torque_nm,
                          pack_temperature_c=sim.pack_temperature_c, energy0_j=e0, sim=sim)
    e0 = 0.0 if energy0_j is None else float(energy0_j)
    if isinstance(model_or_rows, np.ndarray):
        res = simulate_batch(np.atleast_2d(model_or_rows), *args, run_start=inputs.run_start, energy0_j=e0,
                             **inputs.start)
        torque = res.torque_nm
        if measurement:
            torque = apply_measurement(measurement, inputs.t, torque, inputs.run_start)
        return Prediction(torque_nm=torque, plant_torque_nm=res.torque_nm,
                          pack_temperature_c=res.pack_temperature_c, energy0_j=e0)
    models = list(model_or_rows)
    res = simulate_batch(models, *args, run_start=inputs.run_start, energy0_j=e0, **inputs.start)
    torque = np.empty_like(res.torque_nm)
    for j, m in enumerate(models):
        torque[j] = apply_measurement(m.mechanisms, inputs.t, res.torque_nm[j], inputs.run_start)
    return Prediction(torque_nm=torque, plant_torque_nm=res.torque_nm,
                      pack_temperature_c=res.pack_temperature_c, energy0_j=e0)
