"""Car-test bags for live play (rosbags only, no ROS).

- ``read_messages``: every input message of a bag in log-time order, unchanged (real-time
  play republishes them as recorded, invalid ones included: the node rejects those).
- ``read_run``: the bag on the replay grid (docs/bags.md), via ``clutch_model.formats.bag_reader.read_bag``
  (the grid offline replay uses, invalid samples dropped): lock-step play publishes exactly
  these rows, so the live outputs equal offline replay.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clutch_model.errors import DataError

INPUTS = ("applied_force", "slip_speed", "sump_temperature")


def normalize_namespace(ns: str) -> str:
    """'/clutch', 'clutch/', '/' -> '/clutch', '/clutch', '' (topic = ns + '/name')."""
    ns = (ns or "").strip().strip("/")
    return "/" + ns if ns else ""


@dataclass
class InputMessage:
    t_ns: int                 # log time
    topic: str                # one of INPUTS
    value: float
    stamp_ns: int = 0         # Temperature header stamp
    frame_id: str = ""
    variance: float = 0.0


@dataclass
class BagMessages:
    name: str
    path: Path
    start_ns: int             # log time of the bag's first message (any topic)
    messages: list            # InputMessage, log-time order (stable)


def bag_name(path) -> str:
    from clutch_model.formats.bag_reader import bag_name as _name

    return _name(Path(path))


def bag_start_ns(path) -> int:
    """Log time of a bag's first message (for ordering bags), without decoding messages."""
    from rosbags.highlevel import AnyReader

    path = Path(path)
    if not path.exists():
        raise DataError(f"bag not found: {path}")
    try:
        with AnyReader([path]) as reader:
            return int(reader.start_time)
    except Exception as exc:
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise DataError(f"bag {bag_name(path)}: unreadable ({text})") from None


def default_topics():
    from clutch_model.formats.bag_reader import TopicNames

    return TopicNames()


def read_messages(path, topics=None) -> BagMessages:
    """The input messages of one bag (rosbag2 MCAP/sqlite3 directory or bare .mcap);
    ``topics``: clutch_model.formats.bag_reader.TopicNames (default /clutch/...)."""
    from rosbags.highlevel import AnyReader

    from clutch_model.formats.typestore import typestore

    path = Path(path)
    if not path.exists():
        raise DataError(f"bag not found: {path}")
    topics = topics or default_topics()
    wanted = {getattr(topics, n): n for n in INPUTS}
    out: list[InputMessage] = []
    try:
        with AnyReader([path], default_typestore=typestore()) as reader:
            start_ns = int(reader.start_time)
            conns = [c for c in reader.connections if c.topic in wanted]
            for conn, t, data in reader.messages(connections=conns):
                msg = reader.deserialize(data, conn.msgtype)
                topic = wanted[conn.topic]
                if topic == "sump_temperature":
                    out.append(InputMessage(int(t), topic, float(msg.temperature),
                                            msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
                                            msg.header.frame_id, float(msg.variance)))
                else:
                    out.append(InputMessage(int(t), topic, float(msg.data)))
    except Exception as exc:  # rosbags raises a variety of types on broken bags
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise DataError(f"bag {bag_name(path)}: unreadable ({text})") from None
    present = {m.topic for m in out}
    missing = [getattr(topics, n) for n in INPUTS if n not in present]
    if missing:
        raise DataError(f"bag {bag_name(path)}: no messages on {', '.join(missing)}")
    out.sort(key=lambda m: m.t_ns)
    return BagMessages(name=bag_name(path), path=path, start_ns=start_ns, messages=out)


def read_run(path, topics=None):
    """The bag on the offline replay grid (clutch_model.formats.bag_reader.Run)."""
    from clutch_model.formats.bag_reader import read_bag

    return read_bag(Path(path), topics or default_topics())


def row_times_ns(run) -> np.ndarray:
    """Log times (ns) of a Run's rows (Run.t is in s from the bag's first message)."""
    return run.start_time_ns + np.round(np.asarray(run.t) * 1e9).astype(np.int64)
