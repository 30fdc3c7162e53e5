"""Compare where the measurement is: a model evaluated at the measured torque's own stamps.

The replay grid (CONTRACT.md) has one row per applied-force message and holds the latest
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
