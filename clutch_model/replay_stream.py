"""`clutch-sim replay` bag by bag: memory bounded by the largest bag, not the campaign.

``replay_runs`` simulates a campaign as one array; for hours of 1 kHz logs that holds every
row of every bag at once (≈ 250 MB per 10 minutes). Here the bags are put in log-time order
from their headers (no decoding), then each is read (bulk MCAP decoding), simulated with the
dissipated energy carried from the previous bag — which is all that carries from bag to bag,
so the numbers are those of the whole-campaign replay, bit for bit — written to OUT.csv and
dropped. The RMSEs are accumulated as sums of squares.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clutch_model.errors import DataError
from clutch_model.formats.bag_reader import TopicNames, bag_name, read_bag
from clutch_model.formats.table_csv import write_table_csv
from clutch_model.plant.params import ClutchModel
from clutch_model.replay import replay_csv_blocks, replay_csv_header, replay_runs


@dataclass
class _Sums:
    sq: float = 0.0
    n: int = 0

    def add(self, pred, meas) -> float:
        ok = np.isfinite(meas) & np.isfinite(pred)
        sq = float(np.sum((np.asarray(pred)[ok] - np.asarray(meas)[ok]) ** 2))
        self.sq += sq
        self.n += int(ok.sum())
        return math.sqrt(sq / ok.sum()) if ok.any() else math.nan

    @property
    def rmse(self) -> float:
        return math.sqrt(self.sq / self.n) if self.n else math.nan


@dataclass
class StreamedReplay:
    """What ``replay_bags`` printed-worthy: per bag (name, torque RMSE, pack temperature RMSE
    or nan, rows), and the campaign RMSEs."""

    per_run: list = field(default_factory=list)
    torque: _Sums = field(default_factory=_Sums)
    pack: _Sums = field(default_factory=_Sums)

    def rmse_torque(self) -> float:
        return self.torque.rmse

    def rmse_pack_temperature(self) -> float:
        return self.pack.rmse

    @property
    def rows(self) -> int:
        return sum(r[3] for r in self.per_run)


def bag_header(path) -> tuple[int, set]:
    """(log time of the bag's first message, topics with messages) from the bag's index."""
    from clutch_model.formats.mcap_bulk import mcap_header

    path = Path(path)
    if not path.exists():
        raise DataError(f"bag not found: {path}")
    got = mcap_header(path)
    if got is not None:
        return got
    from rosbags.highlevel import AnyReader

    try:
        with AnyReader([path]) as reader:
            return int(reader.start_time), {c.topic for c in reader.connections if c.msgcount > 0}
    except Exception as exc:  # rosbags raises a variety of types on broken bags
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise DataError(f"bag {bag_name(path)}: unreadable ({text})") from None


def replay_bags(model: ClutchModel, paths, out_csv, topics: TopicNames = TopicNames(),
                progress: bool = False) -> StreamedReplay:
    """Replay bags one at a time into OUT.csv (module doc); the same file as
    ``write_replay_csv(replay_runs(model, read_bags(paths)))``."""
    paths = [Path(p) for p in paths]
    if not paths:
        raise DataError("no bags given")
    names = [bag_name(p) for p in paths]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise DataError(f"several bags are named {sorted(dup)[0]!r}")
    headers = [bag_header(p) for p in paths]
    order = sorted(range(len(paths)), key=lambda k: headers[k][0])
    has_torque = any(topics.measured_torque in h[1] for h in headers)
    has_pack = any(topics.pack_temperature in h[1] for h in headers)
    out = StreamedReplay()
    bar = None
    if progress and len(paths) > 1:
        from tqdm import tqdm
        bar = tqdm(total=len(paths), desc="replay", unit="bag", leave=False, disable=None)

    def blocks():
        energy_j = None
        for k in order:
            run = read_bag(paths[k], topics)
            res = replay_runs(model, [run], energy0_j=energy_j)
            energy_j = float(res.sim.energy_j[-1])
            rt = out.torque.add(res.torque_sim, res.campaign.torque_measured)
            rp = math.nan
            if run.pack_temperature_measured_c is not None:
                rp = out.pack.add(res.sim.pack_temperature_c, run.pack_temperature_measured_c)
            out.per_run.append((run.name, rt, rp, len(run)))
            yield from replay_csv_blocks(res, has_torque, has_pack)
            del run, res                     # before the next bag is read: one bag in memory at a time
            if bar is not None:
                bar.update(1)

    try:
        it = blocks()
        # the first bag is read before OUT.csv is opened (a bad first bag writes nothing; a bad
        # later one keeps what was written)
        first = [b for b in [next(it, None)] if b is not None]

        def chained():
            while first:
                yield first.pop()            # not kept referenced once written
            yield from it

        write_table_csv(out_csv, replay_csv_header(has_torque, has_pack), chained())
    finally:
        if bar is not None:
            bar.close()
    return out
