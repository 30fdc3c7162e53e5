"""Record the node's outputs to an MCAP rosbag2 (rosbags Writer, no rosbag2_py).

The subscriptions are raw (``raw=True``): the serialized CDR bytes are written as received,
with the message definitions of ``bag_types.typestore()`` as ``ros2msg`` schemas, so rosbags,
the ``mcap`` readers and Foxglove decode the file without ROS.

Output: a path ending in ``.mcap`` is written as a bare MCAP file (the rosbag2 directory is
written beside it and its .mcap moved out on close); any other path becomes a rosbag2
directory (metadata.yaml + .mcap). Log time: a ``log_time()`` callable (default: the
recorder node's ROS clock at reception -- sim time when use_sim_time is set).
"""
from __future__ import annotations

import shutil
import tempfile
from functools import partial
from pathlib import Path
from typing import Callable, Optional

from clutch_model.errors import DataError

from clutch_model.formats.bag_messages import normalize_namespace

RECORD_QOS_DEPTH = 1000


def output_topics(namespace: str) -> list[tuple[str, str]]:
    """(topic, rosbags msgtype) of the node's outputs under ``namespace``."""
    ns = normalize_namespace(namespace)
    return [(f"{ns}/clutch_torque", "std_msgs/msg/Float64"),
            (f"{ns}/pack_temperature", "sensor_msgs/msg/Temperature"),
            (f"{ns}/clutch_state", "clutch_msgs/msg/ClutchState"),
            ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")]


def _python_type(msgtype: str):
    from clutch_msgs.msg import ClutchState
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import Temperature
    from std_msgs.msg import Float64

    return {"std_msgs/msg/Float64": Float64, "sensor_msgs/msg/Temperature": Temperature,
            "clutch_msgs/msg/ClutchState": ClutchState,
            "diagnostic_msgs/msg/DiagnosticArray": DiagnosticArray}[msgtype]


class McapOut:
    """An MCAP rosbag2 being written: a directory, or a bare .mcap file moved out on close."""

    def __init__(self, out, overwrite: bool = False):
        from rosbags.rosbag2 import StoragePlugin, Writer

        self.out = Path(out)
        if self.out.exists():
            if not overwrite:
                raise DataError(f"{self.out} exists already; remove it or choose another --out")
            if self.out.is_dir():
                shutil.rmtree(self.out)
            else:
                self.out.unlink()
        self.out.parent.mkdir(parents=True, exist_ok=True)
        self.bare = self.out.suffix == ".mcap"
        if self.bare:
            self._tmp = Path(tempfile.mkdtemp(prefix=f".{self.out.stem}.", dir=self.out.parent))
            bag_dir = self._tmp / self.out.stem          # holds <stem>.mcap = out.name
        else:
            self._tmp = None
            bag_dir = self.out
        self.writer = Writer(bag_dir, version=9, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self._bag_dir = bag_dir
        self.closed = False

    def close(self) -> Path:
        if self.closed:
            return self.out
        self.closed = True
        self.writer.close()
        if self.bare:
            shutil.move(str(self._bag_dir / self.out.name), str(self.out))
            shutil.rmtree(self._tmp, ignore_errors=True)
        return self.out


class Recorder:
    """Raw subscriptions on ``node`` to the node's outputs, written to ``out``."""

    def __init__(self, node, out, namespace: str = "/clutch", *, log_time: Optional[Callable[[], int]] = None,
                 overwrite: bool = False, topics: Optional[list] = None):
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        from clutch_model.formats.typestore import typestore

        qos = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                         depth=RECORD_QOS_DEPTH, durability=DurabilityPolicy.VOLATILE)
        self._node = node
        self._log_time = log_time or (lambda: node.get_clock().now().nanoseconds)
        self.bag = McapOut(out, overwrite=overwrite)
        self.counts: dict[str, int] = {}
        self.last: dict[str, bytes] = {}
        self._subs = []
        store = typestore()
        for topic, msgtype in (topics or output_topics(namespace)):
            conn = self.bag.writer.add_connection(topic, msgtype, typestore=store)
            self.counts[topic] = 0
            self._subs.append(node.create_subscription(
                _python_type(msgtype), topic, partial(self._write, conn, topic), qos, raw=True))

    def _write(self, conn, topic: str, data: bytes) -> None:
        if self.bag.closed:
            return
        self.bag.writer.write(conn, int(self._log_time()), data)
        self.counts[topic] += 1

    def close(self) -> Path:
        for sub in self._subs:
            self._node.destroy_subscription(sub)
        self._subs = []
        return self.bag.close()


def record(out, namespace: str = "/clutch", duration_s: Optional[float] = None, *,
           use_sim_time: bool = False, overwrite: bool = False, progress: bool = True) -> dict:
    """Record the node's outputs until ``duration_s`` elapsed (wall clock) or SIGINT/SIGTERM.
    Returns {topic: messages written} and the output path."""
    import time

    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    rclpy.init()
    node = Node("clutch_sim_record", parameter_overrides=[
        Parameter("use_sim_time", Parameter.Type.BOOL, bool(use_sim_time))])
    recorder = None
    try:
        recorder = Recorder(node, out, namespace, overwrite=overwrite)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        start = time.monotonic()
        last_print = start
        try:
            while rclpy.ok():
                now = time.monotonic()
                if duration_s is not None and now - start >= duration_s:
                    break
                executor.spin_once(timeout_sec=0.1)
                if progress and now - last_print >= 2.0:
                    last_print = now
                    total = sum(recorder.counts.values())
                    print(f"\rrecording {out}: {total} messages, {now - start:.0f} s", end="",
                          file=_stderr(), flush=True)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        if progress:
            print(file=_stderr())
        path = recorder.close()
        return {"out": str(path), "counts": dict(recorder.counts)}
    finally:
        if recorder is not None:
            recorder.close()
        node.destroy_node()
        rclpy.try_shutdown()


def _stderr():
    import sys

    return sys.stderr
