"""`clutch-sim replay` block by block: memory bounded by a block of rows, not the log.

``replay_runs`` simulates a campaign as one array; for hours of 1 kHz logs that holds every
row of every bag at once. Here the bags are put in log-time order from their headers (no
decoding), then each is read chunk by chunk (``formats.bag_stream``: bulk MCAP decoding, the
replay grid built as the samples become final) in blocks of ``BLOCK_ROWS`` rows (~65 s at
1 kHz). Each block is simulated from the plant state the previous block left
(``plant.simulate.ChunkedSimulation``), its measurement mechanisms applied with their state
carried (``plant.measurement_stream``), formatted and appended to OUT.csv, and dropped. The
dissipated energy carries from bag to bag. The numbers are those of the whole-campaign replay,
bit for bit (``write_replay_csv(replay_runs(...))`` writes the same bytes, and the RMSEs are
summed block by block in both).

The three stages overlap in a pipeline on three threads: decoding and gridding block k+1
(main thread), simulating block k (the compiled kernel releases the GIL) and formatting block
k-1 (orjson per column, rows assembled by a compiled loop that releases the GIL); at most a few
blocks are in flight.

A bag that is not a single-file MCAP (sqlite3, compressed files) is read whole by the general
decoder and then simulated in blocks (memory bounded by that bag). A corrupt MCAP chunk met
mid-bag stops the bulk stream: the bag's rows are taken back from OUT.csv and the bag is read
again by the general decoder, which reads it or reports it.
"""
from __future__ import annotations

import math
import os
import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clutch_model.errors import DataError
from clutch_model.formats.bag_reader import TopicNames, bag_name
from clutch_model.formats.bag_stream import BLOCK_ROWS, BagBlocks
from clutch_model.plant.params import ClutchModel
from clutch_model.replay import SquareSums, replay_csv_header

IN_FLIGHT = 3            # blocks between decoding and writing


@dataclass
class _Sums:
    sq: float = 0.0
    n: int = 0

    def add(self, sq: float, n: int) -> None:
        self.sq += sq
        self.n += n

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
    # CPU seconds per stage (each stage's own thread): decode + grid, simulate (+ measurement
    # mechanisms and RMSE sums), format + write
    cpu_s: dict = field(default_factory=lambda: {"decode": 0.0, "simulate": 0.0, "csv": 0.0})

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


class _CsvOut:
    """OUT.csv, opened at the first row (a replay whose first bag fails writes nothing)."""

    def __init__(self, path: Path, header: list):
        self.path = path
        self.header = (",".join(header) + "\r\n").encode()
        self.fh = None
        self.size = 0
        self.rows = 0

    def write(self, data, rows: int) -> None:
        if self.fh is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.fh = self.path.open("wb")
            self.fh.write(self.header)
            self.size = len(self.header)
        self.fh.write(data)
        self.size += len(data)
        self.rows += rows

    def truncate(self, size: int, rows: int) -> None:
        if self.fh is not None:
            self.fh.flush()
            self.fh.truncate(max(size, len(self.header)))
            self.fh.seek(0, os.SEEK_END)
            self.size, self.rows = max(size, len(self.header)), rows

    def close(self, failed: bool) -> None:
        if self.fh is not None:
            self.fh.close()
            if failed and self.rows == 0:
                self.path.unlink(missing_ok=True)


class _Inline:
    """A one-thread executor's interface, run in the caller's thread (``threads=False``)."""

    def submit(self, fn, *args):
        fut = Future()
        try:
            fut.set_result(fn(*args))
        except BaseException as exc:  # noqa: BLE001 - handed to whoever asks for the result
            fut.set_exception(exc)
        return fut

    def shutdown(self, wait=True, cancel_futures=False):
        pass


class _BagReplay:
    """One bag through the plant and into OUT.csv, block by block (``simulate`` runs in the
    simulation stage, ``write`` in the CSV stage)."""

    def __init__(self, model: ClutchModel, name: str, energy0_j: float, has_torque: bool, has_pack: bool,
                 cpu_s: dict):
        from clutch_model.plant.measurement_stream import MeasurementStream
        from clutch_model.plant.simulate import ChunkedSimulation

        self.model = model
        self.prefix = _label_prefix(name)
        self.sim = ChunkedSimulation(model, energy0_j)
        self.measurement = MeasurementStream(model.mechanisms)
        self.has_torque, self.has_pack = has_torque, has_pack
        self.torque = SquareSums()
        self.pack = SquareSums()
        self.any_pack = False
        self.rows = 0
        self.cpu_s = cpu_s

    def simulate(self, block) -> tuple:
        """Simulation stage: (block, predicted measured torque, pack temperature, locked)."""
        c0 = time.thread_time()
        res = self.sim.run(block.t, block.force, block.slip, block.sump, copy=False)
        plant = np.array(res.torque_nm)
        if self.measurement.chunkable:
            torque = self.measurement.run(block.t, plant, block.first)
        else:                                        # the whole bag is one block
            from clutch_model.plant.mechanisms import apply_measurement

            rs = np.zeros(len(block), bool)
            rs[0] = True
            torque = apply_measurement(self.model.mechanisms, block.t, plant, rs)
        out = (block, torque, np.array(res.pack_temperature_c), res.locked)
        self.cpu_s["simulate"] += time.thread_time() - c0
        return out

    def write(self, csv_out: "_CsvOut", sim_future: Future) -> None:
        """CSV stage (blocks in order): the RMSE sums, then the block's OUT.csv rows."""
        from clutch_model.formats.table_csv import write_block

        block, torque, pack, locked = sim_future.result()
        c0 = time.thread_time()
        n = len(block)
        if block.torque_measured is not None:
            self.torque.add(torque, block.torque_measured)
        if block.pack_measured is not None:
            self.any_pack = True
            self.pack.add(pack, block.pack_measured)
        cols = [block.t, torque, pack, locked]
        if self.has_torque:
            cols.append(block.torque_measured if block.torque_measured is not None else np.full(n, np.nan))
        if self.has_pack:
            cols.append(block.pack_measured if block.pack_measured is not None else np.full(n, np.nan))
        write_block(csv_out.write, self.prefix, cols)
        self.rows += n
        self.cpu_s["csv"] += time.thread_time() - c0


def _label_prefix(name: str) -> bytes:
    from clutch_model.formats.table_csv import _label_prefix as prefix

    return prefix(name).encode()


def replay_bags(model: ClutchModel, paths, out_csv, topics: TopicNames = TopicNames(),
                progress: bool = False, block_rows: int = BLOCK_ROWS, threads: bool = True) -> StreamedReplay:
    """Replay bags block by block into OUT.csv (module doc); the same file as
    ``write_replay_csv(replay_runs(model, read_bags(paths)))``. ``block_rows``: rows per block
    (the memory bound); ``threads=False`` runs the stages one after the other."""
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
    csv_out = _CsvOut(Path(out_csv), replay_csv_header(has_torque, has_pack))
    bar = None
    if progress and len(paths) > 1:
        from tqdm import tqdm
        bar = tqdm(total=len(paths), desc="replay", unit="bag", leave=False, disable=None)
    if threads:
        sim_stage = ThreadPoolExecutor(1, thread_name_prefix="replay-sim")
        out_stage = ThreadPoolExecutor(1, thread_name_prefix="replay-csv")
        # load the compiled kernels in their stages' threads while the first bag is opened
        sim_stage.submit(_warm_simulation, model)
        out_stage.submit(_warm_csv)
    else:
        sim_stage = out_stage = _Inline()
    failed = True
    try:
        energy_j = None
        for k in order:
            c0 = time.thread_time()
            bag = _open_bag(paths[k], topics, block_rows, model)
            out.cpu_s["decode"] += time.thread_time() - c0
            if energy_j is None:       # what the model's campaign history knows at the first bag
                energy_j = model.initial_energy_j(bag.start_time_ns)
            start = (csv_out.size, csv_out.rows)
            try:
                run = _replay_bag(bag, model, energy_j, has_torque, has_pack, csv_out, sim_stage, out_stage,
                                  out.cpu_s)
            except _BulkStopped:
                csv_out.truncate(*start)     # take the bag's rows back; the general decoder reads it
                bag = BagBlocks(paths[k], topics, _block_rows_for(model, block_rows), bulk=False)
                run = _replay_bag(bag, model, energy_j, has_torque, has_pack, csv_out, sim_stage, out_stage,
                                  out.cpu_s)
            energy_j = run.sim.energy_j
            torque, pack = _Sums(*run.torque.total()), _Sums(*run.pack.total())
            out.torque.add(torque.sq, torque.n)
            if run.any_pack:
                out.pack.add(pack.sq, pack.n)
            out.per_run.append((bag.name, torque.rmse, pack.rmse if run.any_pack else math.nan, run.rows))
            if bar is not None:
                bar.update(1)
        failed = False
    finally:
        sim_stage.shutdown(wait=True, cancel_futures=True)
        out_stage.shutdown(wait=True, cancel_futures=True)
        csv_out.close(failed)
        if bar is not None:
            bar.close()
    return out


def _warm_simulation(model: ClutchModel) -> None:
    from clutch_model.plant.simulate import ChunkedSimulation

    ChunkedSimulation(model).run([0.0, 1e-3], 0.0, 0.0, 50.0)


def _warm_csv() -> None:
    from clutch_model.formats.table_csv import write_block

    write_block(lambda data, rows: None, b"x,", [np.zeros(2), np.zeros(2, np.int64)])


class _BulkStopped(Exception):
    pass


def _block_rows_for(model: ClutchModel, block_rows: int) -> int:
    from clutch_model.plant.measurement_stream import MeasurementStream

    # a measurement mechanism without a chunked form sees whole bags
    return block_rows if MeasurementStream(model.mechanisms).chunkable else 1 << 62


def _open_bag(path: Path, topics: TopicNames, block_rows: int, model: ClutchModel) -> BagBlocks:
    return BagBlocks(path, topics, _block_rows_for(model, block_rows))


def _replay_bag(bag: BagBlocks, model, energy_j, has_torque, has_pack, csv_out, sim_stage, out_stage,
                cpu_s: dict) -> _BagReplay:
    """All blocks of one bag through the stages; raises _BulkStopped when the bulk stream stops."""
    from clutch_model.formats.mcap_bulk import NotBulk

    run = _BagReplay(model, bag.name, energy_j, has_torque, has_pack, cpu_s)
    in_flight = deque()
    blocks = bag.blocks()
    try:
        while True:
            c0 = time.thread_time()
            try:
                block = next(blocks, None)
            except (NotBulk, IndexError):
                if not bag.bulk:
                    raise
                raise _BulkStopped from None
            finally:
                cpu_s["decode"] += time.thread_time() - c0
            if block is None:
                break
            sim = sim_stage.submit(run.simulate, block)
            in_flight.append(out_stage.submit(run.write, csv_out, sim))
            del block, sim
            while len(in_flight) > IN_FLIGHT:
                in_flight.popleft().result()
    finally:
        errors = []
        while in_flight:                        # every submitted block finishes before the next step
            try:
                in_flight.popleft().result()
            except BaseException as exc:  # noqa: BLE001
                errors.append(exc)
        if errors:
            raise errors[0]
    return run
