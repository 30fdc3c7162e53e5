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

from dataclasses import dataclass

import numpy as np

from clutch_model.plant.mechanisms import apply_measurement
from clutch_model.plant.params import ClutchModel
from clutch_model.plant.simulate import SimResult, simulate, simulate_batch


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

    @classmethod
    def of(cls, campaign) -> "PlantInputs":
        """From a Campaign (or anything carrying t, force, slip, sump, run_start). Runs with a
        ``plant_state0`` (diagnosis.sample.WindowRun) start from that plant state."""
        if isinstance(campaign, PlantInputs):
            return campaign
        runs = getattr(campaign, "runs", None)
        start = int(runs[0].start_time_ns) if runs else None
        index, states = None, None
        if runs and any(getattr(r, "plant_state0", None) is not None for r in runs):
            index = np.full(len(campaign.t), -1, dtype=np.int64)
            states, k = [], 0
            for r in runs:
                if getattr(r, "plant_state0", None) is not None:
                    index[k] = len(states)
                    states.append(np.asarray(r.plant_state0, float))
                k += len(r)
            states = np.ascontiguousarray(np.stack(states))
        return cls(t=np.ascontiguousarray(campaign.t, float), force=np.ascontiguousarray(campaign.force, float),
                   slip=np.ascontiguousarray(campaign.slip, float), sump=np.ascontiguousarray(campaign.sump, float),
                   run_start=np.ascontiguousarray(campaign.run_start, bool), first_start_time_ns=start,
                   start_index=index, start_states=states)

    @property
    def start(self) -> dict:
        """The given start states as keyword arguments of simulate / simulate_batch."""
        if self.start_states is None:
            return {}
        return {"start_index": self.start_index, "start_states": self.start_states}

    @property
    def n_rows(self) -> int:
        return int(self.t.size)


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


def predict_campaign(model_or_rows, campaign, energy0_j: float | None = None, measurement=None) -> Prediction:
    """Predicted measured torque of a model (or models, or parameter rows) on a campaign.

    ``energy0_j``: dissipated energy at the first row; default: what a single model's campaign
    history knows at the first run's start, 0 for batches. ``measurement``: measurement
    mechanisms for parameter rows (models carry their own)."""
    inputs = PlantInputs.of(campaign)
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
