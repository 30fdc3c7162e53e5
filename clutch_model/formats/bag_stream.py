"""A car-test bag on the replay grid in blocks of rows, read chunk by chunk (memory bounded by a
block, not the bag): the rows ``bag_reader.read_bag`` builds, bit for bit, in the same order.

MCAP bags take ``mcap_bulk.ScalarStream``: its batches hold the samples whose log time is
final, so the grid rows (force samples at or after the first valid sample of every input) up to
the batch's end can be built from the batch and the last sample before it of every topic (the
grid is "latest sample at or before the row", docs/bags.md). Anything else — or a bulk stream
that stops on a corrupt chunk (``NotBulk``; the caller starts the bag over) — is read whole by
``read_bag`` and cut into blocks.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clutch_model.errors import DataError
from clutch_model.formats.bag_reader import _valid, bag_name, read_bag
from clutch_model.formats.topics import TopicNames

BLOCK_ROWS = 1 << 16          # ~65 s of 1 kHz rows


@dataclass
class GridBlock:
    """Consecutive rows of one bag's replay grid (``first``: the block starts the bag)."""

    t: np.ndarray
    force: np.ndarray
    slip: np.ndarray
    sump: np.ndarray
    torque_measured: np.ndarray | None
    pack_measured: np.ndarray | None
    first: bool

    def __len__(self) -> int:
        return int(self.t.size)


class BagBlocks:
    """One bag's grid rows in blocks of ``block_rows`` (the last one shorter): ``name``,
    ``start_time_ns``, ``blocks()``. ``bulk``: whether the bag is streamed (MCAP) or read whole."""

    def __init__(self, path, topics: TopicNames = TopicNames(), block_rows: int = BLOCK_ROWS,
                 bulk: bool = True):
        from clutch_model.formats.mcap_bulk import scalar_stream

        self.path = Path(path)
        self.name = bag_name(self.path)
        self.topics = topics
        self.block_rows = max(int(block_rows), 2)
        self._wanted = [topics.applied_force, topics.slip_speed, topics.sump_temperature,
                        topics.measured_torque, topics.pack_temperature]
        self._stream = scalar_stream(self.path, self._wanted) if bulk else None
        if self._stream is not None and not {topics.applied_force, topics.slip_speed,
                                             topics.sump_temperature} <= self._stream.topics:
            self._stream = None               # read_bag words the error
        self.bulk = self._stream is not None
        self._run = None
        if self._stream is None:
            self._run = read_bag(self.path, topics, bulk=bulk)
            self.start_time_ns = int(self._run.start_time_ns)
        else:
            self.start_time_ns = int(self._stream.first_ns)

    def blocks(self):
        rows = self._rows_whole() if self._stream is None else self._rows_streamed()
        return _fixed_blocks(rows, self.block_rows)

    # -- whole bag (general decoder) ---------------------------------------------------------
    def _rows_whole(self):
        r = self._run
        self._run = None                       # the blocks own the arrays from here on
        yield (r.t, r.applied_force_n, r.slip_speed_rad_s, r.sump_temperature_c,
               r.torque_measured_nm, r.pack_temperature_measured_c)

    # -- streamed (MCAP bulk) ----------------------------------------------------------------
    def _rows_streamed(self):
        tp = self.topics
        inputs = (("force", tp.applied_force), ("slip", tp.slip_speed), ("sump", tp.sump_temperature))
        measured = [topic for topic in (tp.measured_torque, tp.pack_temperature) if topic in self._stream.topics]
        first_ns = self._stream.first_ns
        tail = {}                 # topic -> (time, value) of its last sample so far (inputs: valid ones)
        first_valid = {}          # input kind -> log time of its first valid sample
        t0 = None
        n_rows = 0
        empty = (np.zeros(0, np.int64), np.zeros(0))
        for batch in self._stream.batches():
            valid = {}
            for kind, topic in inputs:
                times, values = batch.get(topic, empty)
                ok = _valid(kind, values)
                if not ok.all():
                    times, values = times[ok], values[ok]
                valid[kind] = (times, values)
                if kind not in first_valid and times.size:
                    first_valid[kind] = int(times[0])
            if t0 is None and len(first_valid) == 3:
                t0 = max(first_valid.values())
            if t0 is not None:
                ft = valid["force"][0]
                rows = ft if (not ft.size or ft[0] >= t0) else ft[ft >= t0]
                if rows.size:
                    fv = valid["force"][1]
                    if np.all(ft[1:] > ft[:-1]):           # no repeated stamps: row k's force is its own sample
                        force = fv[ft.size - rows.size:]
                    else:
                        force = _latest_from(tail.get(tp.applied_force), ft, fv, rows)
                    cols = [force] + [_latest_from(tail.get(topic), *valid[kind], rows) for kind, topic in inputs[1:]]
                    meas = {topic: _latest_from(tail.get(topic), *batch.get(topic, empty), rows) for topic in measured}
                    n_rows += rows.size
                    yield ((rows - first_ns) * 1e-9, *cols, meas.get(tp.measured_torque),
                           meas.get(tp.pack_temperature))
            for kind, topic in inputs:
                times, values = valid[kind]
                if times.size:
                    tail[topic] = (times[-1], values[-1])
            for topic in measured:
                times, values = batch.get(topic, empty)
                if times.size:
                    tail[topic] = (times[-1], values[-1])
        for kind, topic in inputs:
            if kind not in first_valid:
                raise DataError(f"bag {self.name}: topic {topic} has no valid samples")
        if n_rows < 2:
            raise DataError(f"bag {self.name}: fewer than 2 applied_force samples after every input has started")


def _latest_from(tail, times: np.ndarray, values: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The latest sample at or before each of ``at`` among ``tail`` (the last sample before this
    batch, or None) and the batch's samples; NaN where there is none (``bag_reader.latest_sample``)."""
    idx = np.searchsorted(times, at, side="right") - 1
    if not idx.size or idx.min() >= 0:
        return values.take(idx)
    out = values.take(np.maximum(idx, 0)) if values.size else np.empty(at.size)
    out[idx < 0] = tail[1] if tail is not None else np.nan
    return out


def _fixed_blocks(row_batches, block_rows: int):
    """Re-cut batches of rows (tuples of equal-length arrays, None for an absent column) into
    GridBlocks of exactly ``block_rows`` rows, the last one shorter and handed out only once the
    bag is complete: a bag that fails its end checks (no valid samples, fewer than 2 rows) has
    yielded no block."""
    held = []
    n_held = 0
    first = True
    for batch in row_batches:
        held.append(batch)
        n_held += batch[0].size
        while n_held >= block_rows:
            block, held, n_held = _take(held, n_held, block_rows)
            yield GridBlock(*block, first=first)
            first = False
    if n_held:
        block, held, n_held = _take(held, n_held, n_held)
        yield GridBlock(*block, first=first)


def _take(held: list, n_held: int, n: int):
    """(the first n rows of the held batches, the rest, rows left)."""
    out, rest, got = [], [], 0
    for j, batch in enumerate(held):
        size = batch[0].size
        if got + size <= n:
            out.append(batch)
            got += size
            if got == n:
                rest = held[j + 1:]
                break
        else:
            k = n - got
            out.append(tuple(None if c is None else c[:k] for c in batch))
            rest = [tuple(None if c is None else c[k:] for c in batch)] + held[j + 1:]
            got = n
            break
    ncols = len(out[0])
    if len(out) == 1:
        cols = out[0]
    else:
        cols = tuple(None if out[0][c] is None else np.concatenate([b[c] for b in out]) for c in range(ncols))
    return cols, rest, n_held - n
