"""Offline replay of car-test runs through a model (`clutch-sim replay`; grid and timing: docs/bags.md).

The runs are predicted as one campaign by ``clutch_model.prediction.predict_campaign``: the
plant restarts at each run (film at initial.film_thickness, pack at the first sump sample,
actuator states neutral) while the dissipated energy carries from one run to the next.
``torque_sim`` predicts the *measured* torque: the model's measurement mechanisms are applied.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clutch_model.formats.bag_reader import Campaign
from clutch_model.plant.params import ClutchModel
from clutch_model.plant.simulate import SimResult
from clutch_model.prediction import predict_campaign
from clutch_model.formats.table_csv import write_table_csv


@dataclass(frozen=True)
class ReplayResult:
    campaign: Campaign
    sim: SimResult               # plant signals on the concatenated grid
    torque_sim: np.ndarray       # predicted measured torque (measurement mechanisms applied)

    def rmse_torque(self, names=None) -> float:
        return self._rmse(names, lambda r, sl: (self.torque_sim[sl], self.campaign.torque_measured[sl]))

    def rmse_pack_temperature(self, names=None) -> float:
        return self._rmse(names, lambda r, sl: (self.sim.pack_temperature_c[sl], r.pack_temperature_measured_c))

    def _rmse(self, names, pair) -> float:
        """RMSE over the runs named (all by default), summed run by run in run order."""
        keep = None if names is None else set(names)
        sq, n = 0.0, 0
        for r, sl in self.campaign.slices():
            if keep is None or r.name in keep:
                pred, meas = pair(r, sl)
                if meas is not None:
                    s, m = sum_squares(pred, meas)
                    sq += s
                    n += m
        return math.sqrt(sq / n) if n else math.nan

    def per_run(self):
        """[(name, torque RMSE, pack temperature RMSE or nan, rows)] in run order."""
        rows = []
        for r, sl in self.campaign.slices():
            meas_t = r.pack_temperature_measured_c
            rows.append((r.name, _rmse(self.torque_sim[sl], self.campaign.torque_measured[sl]),
                         _rmse(self.sim.pack_temperature_c[sl], meas_t) if meas_t is not None else math.nan,
                         len(r)))
        return rows


SUM_BLOCK_ROWS = 1 << 16


class SquareSums:
    """Sum of squared differences (and their count) over the rows where prediction and
    measurement are both finite, fed the consecutive rows of one run in pieces of any size:
    summed per window of SUM_BLOCK_ROWS rows of the run (numpy's pairwise sum inside a window),
    the windows added in order. A run fed whole or in blocks gives the same float, so the
    block-wise replay (``replay_stream``) prints the RMSEs of the whole one."""

    def __init__(self):
        self.sq = 0.0
        self.n = 0
        self._held = []
        self._rows = 0

    def add(self, pred, meas) -> "SquareSums":
        pred = np.asarray(pred, float)
        meas = np.asarray(meas, float)
        a = 0
        while a < pred.size:
            take = min(pred.size - a, SUM_BLOCK_ROWS - self._rows)
            p, m = pred[a:a + take], meas[a:a + take]
            ok = np.isfinite(m) & np.isfinite(p)
            self._held.append(p - m if ok.all() else p[ok] - m[ok])
            self._rows += take
            a += take
            if self._rows == SUM_BLOCK_ROWS:
                self._flush()
        return self

    def _flush(self) -> None:
        d = self._held[0] if len(self._held) == 1 else np.concatenate(self._held)
        if d.size:
            self.sq += float(np.sum(d ** 2))
            self.n += int(d.size)
        self._held, self._rows = [], 0

    def total(self) -> tuple[float, int]:
        """(sum of squares, count) of everything added (the window so far included)."""
        if self._rows:
            self._flush()
        return self.sq, self.n


def sum_squares(pred, meas) -> tuple[float, int]:
    """(sum of squared differences, count) over one run's rows where both are finite
    (``SquareSums``)."""
    return SquareSums().add(pred, meas).total()


def _rmse(pred, meas) -> float:
    sq, n = sum_squares(pred, meas)
    return math.sqrt(sq / n) if n else math.nan


def replay_runs(model: ClutchModel, runs, energy0_j: float | None = None) -> ReplayResult:
    """Simulate runs (a Campaign or a list of Run) through ``model``. The dissipated energy
    starts at ``energy0_j``, by default what the model's campaign history knows at the first
    run's start (0 for a fresh model)."""
    campaign = runs if isinstance(runs, Campaign) else Campaign(list(runs))
    pred = predict_campaign(model, campaign, energy0_j=energy0_j)
    return ReplayResult(campaign=campaign, sim=pred.sim, torque_sim=pred.torque_nm)


def replay_csv_header(has_torque: bool, has_pack: bool) -> list:
    header = ["bag", "t", "torque_sim", "pack_temperature_sim", "locked"]
    if has_torque:
        header.append("torque_measured")
    if has_pack:
        header.append("pack_temperature_measured")
    return header


def replay_csv_blocks(result: ReplayResult, has_torque: bool, has_pack: bool):
    """(bag name, columns of replay_csv_header) per run of ``result``."""
    for r, sl in result.campaign.slices():
        cols = [r.t, result.torque_sim[sl], result.sim.pack_temperature_c[sl],
                result.sim.locked[sl].astype(np.int64)]
        if has_torque:
            cols.append(r.torque_measured_nm if r.torque_measured_nm is not None else np.full(len(r), np.nan))
        if has_pack:
            cols.append(r.pack_temperature_measured_c if r.pack_temperature_measured_c is not None
                        else np.full(len(r), np.nan))
        yield r.name, cols


def write_replay_csv(result: ReplayResult, path) -> Path:
    """OUT.csv: bag,t,torque_sim,pack_temperature_sim,locked[,torque_measured][,pack_temperature_measured].

    ``locked`` is 1 where the model reports the static capacity (|slip| < lock_slip_rad_s)."""
    runs = result.campaign.runs
    has_torque = any(r.torque_measured_nm is not None for r in runs)
    has_pack = any(r.pack_temperature_measured_c is not None for r in runs)
    return write_table_csv(path, replay_csv_header(has_torque, has_pack),
                           replay_csv_blocks(result, has_torque, has_pack))
