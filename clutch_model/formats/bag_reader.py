"""Car-test runs: reading rosbag2 bags (MCAP or sqlite3 directories, bare .mcap files) with
rosbags, and putting their samples on the replay grid (docs/bags.md).

Grid: one row per `applied_force` message at or after the first sample of every input topic;
each input is the latest sample at or before the row's time. Samples the ROS node would
reject (non-finite, |slip| > 1000 rad/s, force > 1e6 N, sump outside [-40, 200] C) are
dropped here too, so offline replay and the live node see the same inputs.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from clutch_model.errors import DataError
from clutch_model.formats.topics import TopicNames

FORCE_MAX_N = 1e6
SLIP_MAX_RAD_S = 1000.0
SUMP_RANGE_C = (-40.0, 200.0)


@dataclass
class Run:
    """One test run on the replay grid (arrays of equal length, t in s from the bag start)."""

    name: str
    t: np.ndarray
    applied_force_n: np.ndarray
    slip_speed_rad_s: np.ndarray
    sump_temperature_c: np.ndarray
    torque_measured_nm: np.ndarray | None = None
    pack_temperature_measured_c: np.ndarray | None = None
    start_time_ns: int = 0
    rejected_samples: int = 0
    # every topic's own samples as logged (times in s from the bag's first message, valid
    # samples only, log-time order): {channel: (t_s, values)}, channel one of applied_force,
    # slip_speed, sump_temperature, measured_torque, pack_temperature. The grid above holds
    # the latest sample at each force row; diagnosis compares where the measurement is.
    samples: dict = field(default_factory=dict)
    # a grid finer than the rows that the plant is simulated on and read at the rows
    # (prediction.PlantGrid: the diagnosis' rows at a sparse torque's stamps, the force's own
    # samples between them); None: the plant steps from row to row
    plant_grid: object = None

    @property
    def torque_measured_t(self) -> np.ndarray | None:
        """Log times (s from the bag's first message) of the measured-torque samples."""
        s = self.samples.get("measured_torque")
        return None if s is None else s[0]

    @property
    def torque_measured_raw_nm(self) -> np.ndarray | None:
        """The measured-torque samples at their own times ``torque_measured_t``."""
        s = self.samples.get("measured_torque")
        return None if s is None else s[1]

    @property
    def slip_raw_t(self) -> np.ndarray:
        """Log times of the slip samples as logged (``slip_speed_logged`` when the diagnosis has
        put smoothed ones under ``slip_speed``)."""
        return self.samples.get("slip_speed_logged", self.samples["slip_speed"])[0]

    @property
    def slip_raw_rad_s(self) -> np.ndarray:
        return self.samples.get("slip_speed_logged", self.samples["slip_speed"])[1]

    @property
    def duration_s(self) -> float:
        return float(self.t[-1] - self.t[0]) if self.t.size else 0.0

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass
class Campaign:
    """Runs in log-time order, concatenated for the simulators (plant restarts at run_start)."""

    runs: list
    t: np.ndarray = field(init=False)
    force: np.ndarray = field(init=False)
    slip: np.ndarray = field(init=False)
    sump: np.ndarray = field(init=False)
    torque_measured: np.ndarray = field(init=False)
    run_start: np.ndarray = field(init=False)
    run_index: np.ndarray = field(init=False)

    def __post_init__(self):
        if not self.runs:
            raise DataError("no runs")
        self.runs = sorted(self.runs, key=lambda r: r.start_time_ns)
        cat = np.concatenate
        self.t = cat([r.t for r in self.runs])
        self.force = cat([r.applied_force_n for r in self.runs])
        self.slip = cat([r.slip_speed_rad_s for r in self.runs])
        self.sump = cat([r.sump_temperature_c for r in self.runs])
        self.torque_measured = cat([r.torque_measured_nm if r.torque_measured_nm is not None
                                    else np.full(len(r), np.nan) for r in self.runs])
        self.run_start = np.zeros(self.t.size, dtype=bool)
        self.run_index = np.zeros(self.t.size, dtype=np.int64)
        k = 0
        for j, r in enumerate(self.runs):
            self.run_start[k] = True
            self.run_index[k:k + len(r)] = j
            k += len(r)

    def slices(self):
        k = 0
        for r in self.runs:
            yield r, slice(k, k + len(r))
            k += len(r)

    @property
    def names(self):
        return [r.name for r in self.runs]

    def subset(self, names) -> "Campaign":
        keep = set(names)
        return Campaign([r for r in self.runs if r.name in keep])


def bag_name(path: Path) -> str:
    path = Path(path)
    return path.stem if path.is_file() and path.suffix == ".mcap" else path.name


def _scalar(msg) -> float:
    if hasattr(msg, "temperature"):
        return float(msg.temperature)
    return float(msg.data)


def _read_topics(path: Path, wanted: list, bulk: bool = True) -> tuple[dict, int]:
    """{topic: (log_times_ns int64, values float64)} for the wanted topics present, and the
    bag's first log time. MCAP bags of Float64/Temperature topics are decoded in bulk
    (``mcap_bulk``, the same numbers); anything else, or ``bulk=False``, one message at a time
    with rosbags."""
    if not path.exists():
        raise DataError(f"bag not found: {path}")
    if bulk:
        from clutch_model.formats.mcap_bulk import read_scalar_topics

        got = read_scalar_topics(path, wanted)
        if got is not None:
            return got
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import ReaderError
    try:
        with AnyReader([path]) as reader:
            conns = [c for c in reader.connections if c.topic in wanted]
            series = {}
            raw = {}
            for conn, t_ns, data in reader.messages(connections=conns):
                raw.setdefault(conn.topic, []).append((t_ns, data, conn.msgtype))
            first = None
            for conn, t_ns, _ in reader.messages():
                first = t_ns
                break
            if first is None:
                raise DataError(f"bag {bag_name(path)}: no messages")
            for topic, items in raw.items():
                times = np.fromiter((it[0] for it in items), dtype=np.int64, count=len(items))
                values = np.empty(len(items))
                for j, (_, data, typ) in enumerate(items):
                    values[j] = _scalar(reader.deserialize(data, typ))
                order = np.argsort(times, kind="stable")
                series[topic] = (times[order], values[order])
            return series, int(first)
    except DataError:
        raise
    except (ReaderError, KeyError, ValueError, IndexError, AssertionError, EOFError, OSError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise DataError(f"bag {bag_name(path)}: unreadable ({msg})") from None
    except Exception as exc:  # rosbags raises a variety of types on truncated files
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise DataError(f"bag {bag_name(path)}: unreadable ({type(exc).__name__}: {msg})") from None


def _valid(topic_kind: str, values: np.ndarray) -> np.ndarray:
    ok = np.isfinite(values)
    if topic_kind == "force":
        ok &= values <= FORCE_MAX_N
    elif topic_kind == "slip":
        ok &= np.abs(values) <= SLIP_MAX_RAD_S
    elif topic_kind == "sump":
        ok &= (values >= SUMP_RANGE_C[0]) & (values <= SUMP_RANGE_C[1])
    return ok


_CHANNEL = {"force": "applied_force", "slip": "slip_speed", "sump": "sump_temperature"}


def latest_sample(times: np.ndarray, values: np.ndarray, at: np.ndarray) -> np.ndarray:
    idx = np.searchsorted(times, at, side="right") - 1
    if not idx.size or idx.min() >= 0:           # the usual case: every row has a sample before it
        return values.take(idx)
    out = np.full(at.size, np.nan)
    ok = idx >= 0
    out[ok] = values[idx[ok]]
    return out


def replay_grid(force, slip, sump) -> tuple:
    """The replay grid of the three inputs' samples ((times, values) each, times in any one
    unit, sorted): a row at every force sample at or after the first sample of every input,
    each input the latest sample at or before the row. -> (rows, force, slip, sump)."""
    start = max(force[0][0], slip[0][0], sump[0][0])
    rows = force[0][force[0] >= start]
    return rows, latest_sample(*force, rows), latest_sample(*slip, rows), latest_sample(*sump, rows)


def run_with_samples(run: Run, samples: dict) -> Run:
    """``run`` with its samples (``Run.samples``, times in s) replaced and its replay-grid rows
    rebuilt from them (``replay_grid``; the measured torque and pack temperature the latest
    sample at or before each row): a diagnosis that re-times a topic (e.g. one received in
    bursts) puts the run back on the grid ``read_bag`` builds."""
    rows, force, slip, sump = replay_grid(samples["applied_force"], samples["slip_speed"],
                                          samples["sump_temperature"])
    extra = {attr: latest_sample(*samples[chan], rows) for attr, chan in _MEASURED if chan in samples}
    return replace(run, t=rows, applied_force_n=force, slip_speed_rad_s=slip, sump_temperature_c=sump,
                   samples=samples, **extra)


# the measured channels put on the replay grid beside the inputs: (Run attribute, channel)
_MEASURED = (("torque_measured_nm", "measured_torque"), ("pack_temperature_measured_c", "pack_temperature"))


def read_bag(path, topics: TopicNames = TopicNames(), bulk: bool = True) -> Run:
    """Read one car-test bag and put it on the replay grid. ``bulk=False`` forces rosbags'
    general per-message decoder (the bulk MCAP path gives the same numbers, faster)."""
    path = Path(path)
    wanted = [topics.applied_force, topics.slip_speed, topics.sump_temperature,
              topics.measured_torque, topics.pack_temperature]
    series, first_ns = _read_topics(path, wanted, bulk=bulk)
    name = bag_name(path)
    rejected = 0
    inputs = {}
    samples = {}
    for kind, topic in (("force", topics.applied_force), ("slip", topics.slip_speed),
                        ("sump", topics.sump_temperature)):
        if topic not in series:
            raise DataError(f"bag {name}: missing topic {topic}")
        times, values = series[topic]
        ok = _valid(kind, values)
        n_ok = int(np.count_nonzero(ok))
        rejected += ok.size - n_ok
        if not n_ok:
            raise DataError(f"bag {name}: topic {topic} has no valid samples")
        inputs[kind] = (times, values) if n_ok == ok.size else (times[ok], values[ok])
        samples[_CHANNEL[kind]] = ((inputs[kind][0] - first_ns) * 1e-9, inputs[kind][1])
    rows, force, slip, sump = replay_grid(inputs["force"], inputs["slip"], inputs["sump"])
    if rows.size < 2:
        raise DataError(f"bag {name}: fewer than 2 applied_force samples after every input has started")
    run = Run(
        name=name,
        t=(rows - first_ns) * 1e-9,
        applied_force_n=force,
        slip_speed_rad_s=slip,
        sump_temperature_c=sump,
        start_time_ns=first_ns,
        rejected_samples=rejected,
        samples=samples,
    )
    for attr, chan in _MEASURED:
        topic = getattr(topics, chan)
        if topic in series:
            times, values = series[topic]
            setattr(run, attr, latest_sample(times, values, rows))
            ok = np.isfinite(values)
            samples[chan] = ((times[ok] - first_ns) * 1e-9, values[ok])
    return run


def read_bags(paths, topics: TopicNames = TopicNames(), progress: bool = False) -> list:
    """Read several bags; returned in log-time order. Duplicate names are an error."""
    paths = [Path(p) for p in paths]
    if not paths:
        raise DataError("no bags given")
    it = paths
    if progress and len(paths) > 1:
        from tqdm import tqdm
        it = tqdm(paths, desc="reading bags", unit="bag", leave=False, disable=None)  # no bar off a TTY
    runs = [read_bag(p, topics) for p in it]
    names = [r.name for r in runs]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise DataError(f"several bags are named {sorted(dup)[0]!r}")
    return sorted(runs, key=lambda r: r.start_time_ns)
