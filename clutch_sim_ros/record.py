"""Record the node's outputs to an MCAP rosbag2 (rosbags Writer, no rosbag2_py).

The subscriptions are raw (``raw=True``): the serialized CDR bytes are written as received,
with the message definitions of ``bag_types.typestore()`` as ``ros2msg`` schemas, so rosbags,
the ``mcap`` readers and Foxglove decode the file without ROS.

Output: a path ending in ``.mcap`` is written as a bare MCAP file (the rosbag2 directory is
written beside it and its .mcap moved out on close); any other path becomes a rosbag2
directory (metadata.yaml + .mcap). Log time: a ``log_time()`` callable (default: the
recorder node's ROS clock at reception -- sim time when use_sim_time is set); nothing is
logged before the data starts (no 1970 log times). The subscriptions only queue the bytes; a
writer thread writes them, so recording keeps up at 1 kHz.
"""
from __future__ import annotations

import queue
import shutil
import struct
import signal
import sys
import tempfile
import threading
from functools import partial
from pathlib import Path
from typing import Callable, Optional

from clutch_model.errors import DataError

from clutch_model.formats.bag_messages import normalize_namespace

RECORD_QOS_DEPTH = 1000
READY_LINE = "record: ready"   # printed (stderr) once every output of the node is matched
EARLY_LIMIT = 100_000     # messages held until the first valid log time (sim time: the first /clock)


def output_topics(namespace: str) -> list[tuple[str, str]]:
    """(topic, rosbags msgtype) of the node's outputs under ``namespace``."""
    ns = normalize_namespace(namespace)
    return [(f"{ns}/clutch_torque", "std_msgs/msg/Float64"),
            (f"{ns}/pack_temperature", "sensor_msgs/msg/Temperature"),
            (f"{ns}/clutch_state", "clutch_msgs/msg/ClutchState"),
            ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")]


STAMPED = {"sensor_msgs/msg/Temperature", "clutch_msgs/msg/ClutchState"}   # node outputs with a header


def header_stamp_ns(data: bytes) -> int:
    """header.stamp of a serialized message whose first field is a std_msgs/Header (CDR:
    4-byte encapsulation, then int32 sec, uint32 nanosec); 0 when unreadable."""
    if len(data) < 12:
        return 0
    endian = "<" if data[1] & 1 else ">"
    sec, nsec = struct.unpack_from(endian + "iI", data, 4)
    return sec * 1_000_000_000 + nsec if sec > 0 else 0


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


class LatestPerLogTime:
    """Lock-step recording: per topic, the newest message of each log time. A lock-step tick
    that is retried (its answer was late, or its inputs reached the node after its /clock) is
    answered again at the same sim time; the later answer is the one that counts, so a
    message is held until its topic brings a later log time (or ``drain()``), and one at the
    same log time replaces it. ``put`` returns the message it releases, or None."""

    def __init__(self):
        self._held: dict = {}
        self.superseded = 0

    def put(self, topic: str, item: tuple, log_time: int):
        prev = self._held.get(topic)
        self._held[topic] = (log_time, item)
        if prev is None:
            return None
        if prev[0] == log_time:
            self.superseded += 1
            return None
        return prev[1]

    def is_new(self, topic: str, log_time: int) -> bool:
        prev = self._held.get(topic)
        return prev is None or prev[0] != log_time

    def drain(self) -> list:
        items = [item for _, item in self._held.values()]
        self._held = {}
        return items


class Recorder:
    """Raw subscriptions on ``node`` to the node's outputs, written to ``out`` by a writer
    thread (the executor thread only queues the bytes, so a slow disk or the MCAP encoder
    never delays the subscriptions).

    QoS: reliable, keep last RECORD_QOS_DEPTH, so no message is lost while the recorder is
    busy (the node keeps 1000 per output for lagging readers). Nothing is written before the
    data starts: while ``gated`` (until ``open_gate()``) messages are counted in ``skipped``;
    while ``log_time()`` is not a valid time (None or <= 0: the ROS clock in sim time before the
    first /clock) they are skipped too, or with ``hold_early`` held and logged at the first valid
    time (the node's outputs for the first /clock can arrive before that /clock does). ``counts`` = messages queued for writing per topic.
    """

    def __init__(self, node, out, namespace: str = "/clutch", *, log_time: Optional[Callable[[], int]] = None,
                 overwrite: bool = False, topics: Optional[list] = None, gated: bool = False,
                 hold_early: bool = False, header_time: bool = False, lockstep: bool = False):
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        from clutch_model.formats.typestore import typestore

        qos = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                         depth=RECORD_QOS_DEPTH, durability=DurabilityPolicy.VOLATILE)
        self._node = node
        self._log_time = log_time or (lambda: node.get_clock().now().nanoseconds)
        self.bag = McapOut(out, overwrite=overwrite)
        self.counts: dict[str, int] = {}
        self.skipped = 0
        self.hold_early = hold_early
        self._early: list = []
        # header_time (sim time): the node's stamped outputs are logged at their header stamp
        # (the /clock time of their step) and clutch_torque at the stamp of the next stamped
        # output (published right after it in the same step)
        self.header_time = header_time
        self._unstamped_wait: list = []
        self.last_stamp: dict[str, int] = {}
        self._gate_open = not gated
        # lock-step (log time = the /clock time of the step): a retried step's answer supersedes
        # the earlier one at the same log time (LatestPerLogTime)
        self._latest = LatestPerLogTime() if lockstep else None
        self._subs = []
        self._data_subs = []      # the node's own outputs (not /diagnostics): must be matched
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._error: Optional[BaseException] = None
        store = typestore()
        for topic, msgtype in (topics or output_topics(namespace)):
            conn = self.bag.writer.add_connection(topic, msgtype, typestore=store)
            self.counts[topic] = 0
            kind = "stamped" if msgtype in STAMPED else ("diag" if topic == "/diagnostics" else "plain")
            sub = node.create_subscription(_python_type(msgtype), topic, partial(self._on_message, conn, topic, kind),
                                           qos, raw=True)
            self._subs.append(sub)
            if topic != "/diagnostics":
                self._data_subs.append(sub)
        self._thread = threading.Thread(target=self._write_loop, name="mcap-writer", daemon=True)
        self._thread.start()

    def open_gate(self) -> None:
        """From now on messages are written (the data starts)."""
        self._gate_open = True

    def matched(self) -> bool:
        """Every output topic of the node has a publisher matched to this recorder."""
        return all(sub.get_publisher_count() > 0 for sub in self._data_subs)

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def _on_message(self, conn, topic: str, kind: str, data: bytes) -> None:
        if self.bag.closed:
            return
        if kind == "stamped":
            self.last_stamp[topic] = header_stamp_ns(data)
        if self.header_time and self._gate_open and kind != "diag":
            if kind == "plain":
                self._unstamped_wait.append((conn, topic, data))
                return
            t = self.last_stamp[topic]
            if t > 0:
                for c, tp, d in self._unstamped_wait:
                    self._queue.put((c, t, d))
                    self.counts[tp] += 1
                self._unstamped_wait = []
                self._queue.put((conn, t, data))
                self.counts[topic] += 1
                return
        t = self._log_time() if self._gate_open else None
        if t is None or t <= 0:
            if self._gate_open and self.hold_early and len(self._early) < EARLY_LIMIT:
                self._early.append((conn, topic, data))   # logged at the first valid time
            else:
                self.skipped += 1
            return
        if self._early:
            for c, tp, d in self._early:
                self._queue.put((c, int(t), d))
                self.counts[tp] += 1
            self._early = []
        if self._latest is not None and kind != "diag":
            if self._latest.is_new(topic, int(t)):
                self.counts[topic] += 1
            released = self._latest.put(topic, (conn, int(t), data), int(t))
            if released is not None:
                self._queue.put(released)
            return
        self._queue.put((conn, int(t), data))
        self.counts[topic] += 1

    def _write_loop(self) -> None:
        write = self.bag.writer.write
        while True:
            item = self._queue.get()
            if item is None:
                return
            if self._error is None:
                try:
                    write(*item)
                except BaseException as exc:   # reported by close()
                    self._error = exc

    def close(self) -> Path:
        """Stop receiving, write everything queued, close the bag (idempotent). Messages
        still held for want of a valid log time are not written (counted in ``skipped``)."""
        self.skipped += len(self._early) + len(self._unstamped_wait)
        self._early, self._unstamped_wait = [], []
        for sub in self._subs:
            try:
                self._node.destroy_subscription(sub)
            except Exception:   # context already shut down
                pass
        self._subs, self._data_subs = [], []
        if self._latest is not None:
            for item in self._latest.drain():
                self._queue.put(item)
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        path = self.bag.close()
        if self._error is not None:
            error, self._error = self._error, None
            raise DataError(f"writing {self.bag.out} failed: {error}")
        return path


def record(out, namespace: str = "/clutch", duration_s: Optional[float] = None, *,
           use_sim_time: bool = False, overwrite: bool = False, progress: bool = True) -> dict:
    """Record the node's outputs until ``duration_s`` elapsed (wall clock) or SIGINT/SIGTERM.

    Log time: the system clock at reception, or with ``use_sim_time`` the sim time: the node's
    stamped outputs at their header stamp (the /clock time of their step), clutch_torque with
    the stamped output of its step, /diagnostics at the /clock time (held until the first
    /clock arrives; never logged at 0). On SIGINT/SIGTERM the
    messages already delivered are still taken and written (up to 2 s), then the bag is
    closed: it is complete. Once a publisher of every output of the node is matched, the line
    ``record: ready: <topics> matched`` goes to stderr (a script starting the data after it loses
    nothing). Returns {"out", "counts": {topic: messages}, "skipped",
    "interrupted"}."""
    import time

    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.signals import SignalHandlerOptions

    stop = []

    def on_signal(signum, frame):
        stop.append(signum)

    old = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = Node("clutch_sim_record", context=context, parameter_overrides=[
        Parameter("use_sim_time", Parameter.Type.BOOL, bool(use_sim_time))])
    log_time = None if use_sim_time else time.time_ns
    recorder = None
    executor = SingleThreadedExecutor(context=context)
    try:
        recorder = Recorder(node, out, namespace, overwrite=overwrite, log_time=log_time, hold_early=use_sim_time,
                            header_time=use_sim_time)
        executor.add_node(node)
        start = time.monotonic()
        last_print = start
        announced = False
        try:
            while context.ok() and not stop:
                now = time.monotonic()
                if duration_s is not None and now - start >= duration_s:
                    break
                executor.spin_once(timeout_sec=0.1)
                if not announced and recorder.matched():   # the event a driver can wait for
                    announced = True
                    print(f"{READY_LINE}: {', '.join(t for t, _ in output_topics(namespace)[:-1])} matched",
                          file=sys.stderr, flush=True)
                if progress and now - last_print >= 2.0:
                    last_print = now
                    print(f"\rrecording {out}: {recorder.total} messages, {now - start:.0f} s", end="",
                          file=sys.stderr, flush=True)
            # drain: what the middleware already delivered is written too
            idle_since, end = time.monotonic(), time.monotonic() + 2.0
            while context.ok() and time.monotonic() < end and time.monotonic() - idle_since < 0.2:
                before = recorder.total + recorder.skipped
                executor.spin_once(timeout_sec=0.02)
                if recorder.total + recorder.skipped != before:
                    idle_since = time.monotonic()
        except ExternalShutdownException:
            pass
        if progress:
            print(file=sys.stderr)
        path = recorder.close()
        return {"out": str(path), "counts": dict(recorder.counts), "skipped": recorder.skipped,
                "interrupted": bool(stop)}
    finally:
        if recorder is not None:
            recorder.close()
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
        for sig, handler in old.items():
            signal.signal(sig, handler)
