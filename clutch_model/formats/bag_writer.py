"""Write car-test bags (docs/bags.md) from arrays, without ROS.

One run = one rosbag2 bag (version 9) written with ``rosbags``:

| topic | type | unit |
|---|---|---|
| /clutch/applied_force | std_msgs/msg/Float64 | N |
| /clutch/slip_speed | std_msgs/msg/Float64 | rad/s |
| /clutch/sump_temperature | sensor_msgs/msg/Temperature | °C |
| /clutch/measured_torque | std_msgs/msg/Float64 | N·m |
| /clutch/pack_temperature (optional) | sensor_msgs/msg/Temperature | °C |

Every topic has its own time stamps; the log time of a message is ``start_time_ns`` plus its
time in seconds (rounded to the ns). A Temperature message's ``header.stamp`` is its log time
and its ``variance`` the channel's noise variance (0 = unknown).

Storage: an MCAP rosbag2 directory (``storage="mcap"``, default), a sqlite3 one
(``"sqlite3"``), or a bare ``.mcap`` file (path ending in ``.mcap``; the bag is written to a
temporary directory beside it and its .mcap moved out). MCAP files carry ``ros2msg`` schemas,
so Foxglove, PlotJuggler and ``mcap_ros2`` decode them without a ROS installation.

``compression="lz4"`` re-chunks the MCAP file with LZ4 chunk compression (the ``mcap``
writer; all indexes kept, the rosbag2 metadata record copied) — about 40 % smaller for noisy
signals. LZ4, not zstd: rosbags, the ``mcap`` Python reader (which needs the absent
``zstandard`` package for zstd), Foxglove, PlotJuggler and rosbag2_storage_mcap all read LZ4.

Output is deterministic: the same arrays give byte-identical files (no wall-clock time is
written; rosbags and mcap embed only their library name and version).
"""
from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clutch_model.errors import DataError

DEFAULT_TOPICS = {
    "applied_force": "/clutch/applied_force",
    "slip_speed": "/clutch/slip_speed",
    "sump_temperature": "/clutch/sump_temperature",
    "measured_torque": "/clutch/measured_torque",
    "pack_temperature": "/clutch/pack_temperature",
}
FLOAT64 = "std_msgs/msg/Float64"
TEMPERATURE = "sensor_msgs/msg/Temperature"
MSGTYPES = {"applied_force": FLOAT64, "slip_speed": FLOAT64, "sump_temperature": TEMPERATURE,
            "measured_torque": FLOAT64, "pack_temperature": TEMPERATURE}
FRAME_IDS = {"sump_temperature": "axle_sump", "pack_temperature": "clutch_pack"}
CHANNEL_ORDER = ("applied_force", "slip_speed", "sump_temperature", "measured_torque",
                 "pack_temperature")
REQUIRED = ("applied_force", "slip_speed", "sump_temperature")

# 2025-06-02T08:00:00Z: default log time of a bag's first message
DEFAULT_START_TIME_NS = 1_748_851_200_000_000_000


@dataclass
class TopicSeries:
    """One topic: sample times in s (from the bag's start) and values (SI).
    ``variance`` goes into Temperature messages (the sensor noise variance; 0 = unknown)."""

    t_s: np.ndarray
    values: np.ndarray
    variance: float = 0.0

    def __post_init__(self):
        self.t_s = np.asarray(self.t_s, dtype=float).ravel()
        self.values = np.asarray(self.values, dtype=float).ravel()
        if self.t_s.size != self.values.size:
            raise DataError(f"topic series: {self.t_s.size} times but {self.values.size} values")


@dataclass
class RunSignals:
    """The measured channels of one car-test run, each with its own time stamps."""

    applied_force: TopicSeries
    slip_speed: TopicSeries
    sump_temperature: TopicSeries
    measured_torque: TopicSeries | None = None
    pack_temperature: TopicSeries | None = None

    def channels(self) -> dict:
        return {k: getattr(self, k) for k in CHANNEL_ORDER if getattr(self, k) is not None}


def _as_signals(run_signals) -> RunSignals:
    if isinstance(run_signals, RunSignals):
        return run_signals
    if not isinstance(run_signals, dict):
        raise DataError("run_signals must be a RunSignals or a dict of channel -> (t_s, values)")
    unknown = set(run_signals) - set(CHANNEL_ORDER)
    if unknown:
        raise DataError(f"unknown channel(s) {', '.join(sorted(unknown))} "
                        f"(known: {', '.join(CHANNEL_ORDER)})")
    kw = {}
    for key, val in run_signals.items():
        if val is None or isinstance(val, TopicSeries):
            kw[key] = val
        else:
            kw[key] = TopicSeries(*val)
    missing = [k for k in REQUIRED if kw.get(k) is None]
    if missing:
        raise DataError(f"run_signals lacks channel(s) {', '.join(missing)}")
    return RunSignals(**kw)


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def write_run_bag(path, run_signals, storage: str = "mcap",
                  start_time_ns: int = DEFAULT_START_TIME_NS, compression: str = "none",
                  topics: dict | None = None) -> Path:
    """Write one car-test run as a rosbag2 bag (see the module docstring).

    path: bag directory to create (must not exist), or a bare ``*.mcap`` file.
    run_signals: ``RunSignals`` or ``{channel: TopicSeries | (t_s, values)}`` with channels
      applied_force, slip_speed, sump_temperature (required), measured_torque,
      pack_temperature (optional).
    storage: "mcap" or "sqlite3". compression: "none" or "lz4" (MCAP chunk compression).
    topics: override topic names ({channel: topic}).
    Returns the path written.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.errors import WriterError

    path = Path(path)
    signals = _as_signals(run_signals)
    if storage not in ("mcap", "sqlite3"):
        raise DataError(f"unknown bag storage '{storage}' (use mcap or sqlite3)")
    if compression not in ("none", "lz4"):
        raise DataError(f"unknown bag compression '{compression}' (use none or lz4)")
    bare = path.suffix == ".mcap"
    if bare and storage != "mcap":
        raise DataError(f"{path}: a bare .mcap file needs storage mcap")
    if compression != "none" and storage != "mcap":
        raise DataError("compression lz4 applies to MCAP storage only")
    if path.exists():
        raise DataError(f"{path} exists already, not overwriting")
    start_time_ns = int(start_time_ns)
    names = dict(DEFAULT_TOPICS)
    names.update(topics or {})

    ts = _typestore()
    chans = signals.channels()
    stamps, order_chan, order_idx = [], [], []
    for ci, (key, ser) in enumerate(chans.items()):
        if not np.all(np.isfinite(ser.t_s)):
            raise DataError(f"{key}: non-finite time stamps")
        ns = start_time_ns + np.round(ser.t_s * 1e9).astype(np.int64)
        if ns.size and ns.min() < 0:
            raise DataError(f"{key}: time stamps before 1970")
        stamps.append(ns)
        order_chan.append(np.full(ns.size, ci))
        order_idx.append(np.arange(ns.size))
    all_ns = np.concatenate(stamps)
    all_c = np.concatenate(order_chan)
    all_i = np.concatenate(order_idx)
    order = np.lexsort((all_i, all_c, all_ns))   # time order; ties: channel order, sample order

    if bare:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp_root = Path(tempfile.mkdtemp(prefix=".bagwriter-", dir=path.parent))
        bag_dir = tmp_root / path.stem
    else:
        path.parent.mkdir(parents=True, exist_ok=True)
        bag_dir = path
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    try:
        try:
            writer = Writer(bag_dir, version=9, storage_plugin=plugin)
        except WriterError as exc:
            raise DataError(f"cannot write bag {path}: {exc}") from None
        with writer:
            conns, payloads = [], []
            for ci, key in enumerate(chans):
                conns.append(writer.add_connection(names[key], MSGTYPES[key], typestore=ts))
                payloads.append(_payloads(key, chans[key], stamps[ci]))
            write = writer.write
            for c, i, ns in zip(all_c[order].tolist(), all_i[order].tolist(), all_ns[order].tolist()):
                write(conns[c], ns, payloads[c][i])
        if storage == "mcap" and compression == "lz4":
            _rechunk_lz4(bag_dir / f"{bag_dir.name}.mcap")
        if bare:
            os.replace(bag_dir / f"{bag_dir.name}.mcap", path)
    except BaseException:
        if not bare and bag_dir.exists():
            shutil.rmtree(bag_dir, ignore_errors=True)
        raise
    finally:
        if bare:
            shutil.rmtree(tmp_root, ignore_errors=True)
    return path


def _message_maker(ts, key, series: TopicSeries):
    """Per-message CDR serializer with rosbags (the reference ``_payloads`` is checked against)."""
    msgtype = MSGTYPES[key]
    values = series.values
    if msgtype == FLOAT64:
        Float64 = ts.types[FLOAT64]

        def make(i, _ns):
            return ts.serialize_cdr(Float64(data=float(values[i])), FLOAT64)
        return make
    Temperature = ts.types[TEMPERATURE]
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    frame = FRAME_IDS.get(key, "")
    var = float(series.variance)

    def make_t(i, ns):
        hdr = Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id=frame)
        return ts.serialize_cdr(Temperature(header=hdr, temperature=float(values[i]), variance=var),
                                TEMPERATURE)
    return make_t


def _payloads(key, series: TopicSeries, stamps_ns: np.ndarray) -> list:
    """The CDR bytes of every message of a channel, built in bulk with numpy (the same bytes as
    rosbags' serializer, ``_message_maker``; an hour at 1 kHz in seconds, not minutes).
    Float64: encapsulation header 00 01 00 00 + float64. Temperature: header + int32 sec +
    uint32 nanosec + uint32 len(frame_id)+1 + frame_id + NUL, zero padding to 8 (payload
    offsets), float64 temperature, float64 variance."""
    values = np.asarray(series.values, dtype="<f8")
    n = values.size
    if MSGTYPES[key] == FLOAT64:
        rec = np.zeros(n, dtype=[("encap", "V4"), ("data", "<f8")])
        rec["encap"] = np.void(b"\x00\x01\x00\x00")
        rec["data"] = values
    else:
        frame = FRAME_IDS.get(key, "").encode() + b"\x00"
        pad = (-(12 + len(frame))) % 8
        stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
        rec = np.zeros(n, dtype=[("encap", "V4"), ("sec", "<i4"), ("nanosec", "<u4"), ("len", "<u4"),
                                 ("frame", f"V{len(frame) + pad}"), ("temperature", "<f8"), ("variance", "<f8")])
        rec["encap"] = np.void(b"\x00\x01\x00\x00")
        rec["sec"] = stamps_ns // 1_000_000_000
        rec["nanosec"] = stamps_ns % 1_000_000_000
        rec["len"] = len(frame)
        rec["frame"] = np.void(frame + b"\x00" * pad)
        rec["temperature"] = values
        rec["variance"] = float(series.variance)
    size = rec.dtype.itemsize
    buf = rec.tobytes()
    return [buf[k:k + size] for k in range(0, n * size, size)]


def _rechunk_lz4(mcap_path: Path) -> None:
    """Rewrite an MCAP file with LZ4-compressed chunks (same schemas, channels, messages,
    metadata records; all indexes)."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, IndexType, Writer as McapWriter

    tmp = mcap_path.with_name(mcap_path.name + ".lz4tmp")
    with mcap_path.open("rb") as src, tmp.open("wb") as dst:
        reader = make_reader(src)
        header = reader.get_header()
        writer = McapWriter(dst, compression=CompressionType.LZ4, index_types=IndexType.ALL)
        writer.start(profile=header.profile, library=header.library)
        summary = reader.get_summary()
        schema_ids, channel_ids = {}, {}
        for sid in sorted(summary.schemas):
            s = summary.schemas[sid]
            schema_ids[sid] = writer.register_schema(s.name, s.encoding, s.data)
        for cid in sorted(summary.channels):
            ch = summary.channels[cid]
            channel_ids[cid] = writer.register_channel(ch.topic, ch.message_encoding,
                                                       schema_ids[ch.schema_id], dict(ch.metadata))
        for _schema, channel, msg in reader.iter_messages(log_time_order=False):
            writer.add_message(channel_ids[channel.id], msg.log_time, msg.data,
                               msg.publish_time, msg.sequence)
        for meta in reader.iter_metadata():
            writer.add_metadata(meta.name, dict(meta.metadata))
        writer.finish()
    os.replace(tmp, mcap_path)
