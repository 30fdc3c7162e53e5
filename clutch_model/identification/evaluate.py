"""Batch evaluation of friction-coefficient sets on a car-test campaign: parameter rows ->
predicted *measured* torque (through ``clutch_model.prediction.predict_campaign``) -> RMSE.
Everything here is a pure function of its arguments (Dask chunks call ``chunk_rmse``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clutch_model.errors import DataError
from clutch_model.formats.bag_reader import Campaign
from clutch_model.plant import layout as P
from clutch_model.plant.params import ClutchModel
from clutch_model.prediction import PlantInputs, predict_campaign

A_SLICE = slice(P.FRICTION_A, P.FRICTION_A + P.N_FRICTION_COEFFS)


def as_campaign(runs_or_campaign) -> Campaign:
    if isinstance(runs_or_campaign, Campaign):
        return runs_or_campaign
    runs = list(runs_or_campaign)
    if not runs:
        raise DataError("no runs")
    return Campaign(runs)


@dataclass(frozen=True, kw_only=True)
class CampaignInputs(PlantInputs):
    """The simulator inputs of a campaign plus what RMSE needs (picklable, no model)."""

    torque_measured: np.ndarray
    mask: np.ndarray                 # rows with a finite measured torque that count
    measurement: list = None         # measurement mechanisms (torque_offset, transport_delay, ...)
    names: list = None

    @classmethod
    def from_campaign(cls, campaign, model: ClutchModel | None = None, rows=None) -> "CampaignInputs":
        campaign = as_campaign(campaign)
        meas = np.asarray(campaign.torque_measured, float)
        mask = np.isfinite(meas)
        if rows is not None:
            mask &= np.asarray(rows, bool)
        if not mask.any():
            raise DataError("no measured torque in the runs (/clutch/measured_torque)")
        mech = [m.copy() for m in (model.mechanisms if model is not None else []) if m.path == "measurement"]
        plant = PlantInputs.of(campaign)
        return cls(**plant.__dict__, torque_measured=meas, mask=mask, measurement=mech,
                   names=list(campaign.names))

    @property
    def simulated_seconds(self) -> float:
        """Total simulated time of one parameter set over the campaign."""
        starts = np.flatnonzero(self.run_start)
        ends = np.append(starts[1:], self.t.size) - 1
        return float(np.sum(self.t[ends] - self.t[starts]))


def predict(pmat, inputs: CampaignInputs) -> np.ndarray:
    """Predicted measured torque (S, N) for parameter rows ``pmat`` (S, 48); the campaign's
    energy starts at 0."""
    return predict_campaign(np.atleast_2d(pmat), inputs, energy0_j=0.0, measurement=inputs.measurement).torque_nm


def rmse_rows(pred: np.ndarray, inputs: CampaignInputs) -> np.ndarray:
    d = pred[:, inputs.mask] - inputs.torque_measured[inputs.mask][None, :]
    return np.sqrt(np.mean(d * d, axis=1))


def param_rows(base_vector, A) -> np.ndarray:
    """Kernel parameter rows: the base vector with friction coefficients a0..a19 from A."""
    A = np.atleast_2d(np.asarray(A, float))
    pm = np.repeat(np.asarray(base_vector, float)[None, :], A.shape[0], axis=0)
    pm[:, A_SLICE] = A
    return np.ascontiguousarray(pm)


def rmse_of(base_vector, A, inputs: CampaignInputs) -> np.ndarray:
    return rmse_rows(predict(param_rows(base_vector, A), inputs), inputs)


def chunk_rmse(base_vector, A_chunk, inputs: CampaignInputs, numba_threads: int | None = None) -> np.ndarray:
    """RMSE of each coefficient row of one chunk (pure: same arguments, same floats — the batch
    kernel computes each row independently, whatever the thread count)."""
    if numba_threads:
        import numba

        numba.set_num_threads(max(1, min(int(numba_threads), numba.config.NUMBA_NUM_THREADS)))
    if len(A_chunk) == 0:
        return np.empty(0)
    return rmse_of(base_vector, A_chunk, inputs)
