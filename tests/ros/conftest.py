"""Helpers of the ROS integration tests: a private ROS domain per test module, the node as a
subprocess (``python -m clutch_sim_ros.node --ros-args ...``), and an rclpy test client in
this process."""
from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def _need_ros():
    pytest.importorskip("rclpy")
    try:
        import clutch_msgs.msg  # noqa: F401
    except ImportError:
        pytest.skip("clutch_msgs is not built (make venv)")


def _worker_domains() -> list[int]:
    """The ROS domains (1..200) this pytest-xdist worker may use (all of them without xdist)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")          # "gw0", "gw1", ...
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
    index = int(worker[2:]) if worker.startswith("gw") and worker[2:].isdigit() else 0
    return [d for d in range(1, 201) if d % count == index % count]


@pytest.fixture(scope="module")
def domain_id():
    """A random ROS_DOMAIN_ID (1..200) for this module: subprocesses and the client use it.

    Under pytest-xdist each worker draws from its own residue class modulo the number of
    workers, so modules running at the same time on different workers never share a domain."""
    _need_ros()
    old = {k: os.environ.get(k) for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")}
    domain = random.choice(_worker_domains())
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    # discovery on this host only (also for the subprocesses, which inherit the environment)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    yield domain
    for key, value in old.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


def subprocess_env(domain: int) -> dict:
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH", "")) if p)
    env.setdefault("NUMBA_CACHE_DIR", str(REPO / ".numba_cache"))
    return env


class NodeProcess:
    """clutch_sim node in a subprocess; ``stop()`` sends SIGINT (or SIGTERM) and returns the
    exit code."""

    def __init__(self, domain: int, ros_args: list, tmp_path: Path, extra_args: tuple = ()):
        self.log_path = tmp_path / f"node_{random.randint(0, 1 << 30)}.log"
        self._log = open(self.log_path, "w")
        self.cmd = [sys.executable, "-m", "clutch_sim_ros.node", *extra_args, "--ros-args", *ros_args]
        self.proc = subprocess.Popen(self.cmd, env=subprocess_env(domain), cwd=str(REPO),
                                     stdout=self._log, stderr=subprocess.STDOUT)

    def alive(self) -> bool:
        return self.proc.poll() is None

    def log(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return f"exit code {self.proc.returncode}; log:\n" + self.log_path.read_text()

    def stop(self, sig=signal.SIGINT, timeout: float = 10.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
                self._log.close()
                raise AssertionError(f"node did not stop on {sig!r} within {timeout} s")
        self._log.close()
        return self.proc.returncode


class StderrLines:
    """A subprocess' stderr read line by line as it comes, on a daemon thread (a line such as
    ``record``'s ready line is the event a test waits for)."""

    def __init__(self, proc: subprocess.Popen):
        self.lines: list = []
        self._thread = threading.Thread(target=self._read, args=(proc,), daemon=True)
        self._thread.start()

    def _read(self, proc):
        for line in iter(proc.stderr.readline, ""):
            self.lines.append(line)

    def has(self, text: str) -> bool:
        return any(text in line for line in self.lines)

    def text(self, join_timeout_s: float | None = None) -> str:
        """What was read; with ``join_timeout_s``, first wait that long for the end of the stream."""
        if join_timeout_s is not None:
            self._thread.join(timeout=join_timeout_s)
        return "".join(self.lines)


class Client:
    """An rclpy node + executor in a private context, with small waiting helpers."""

    def __init__(self, domain: int):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node

        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = Node(f"test_client_{random.randint(0, 1 << 30)}", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.01, max(0.0, end - time.monotonic())))

    def spin_until(self, cond, timeout: float, step=None, step_period: float = 0.01) -> bool:
        """Spin until ``cond()`` (True) or ``timeout`` s (False: a generous deadline, never a
        timing assertion); ``step()`` is called every ``step_period`` s meanwhile."""
        end = time.monotonic() + timeout
        next_step = 0.0
        while not cond():
            now = time.monotonic()
            if now > end:
                return False
            if step is not None and now >= next_step:
                step()
                next_step = now + step_period
            self.executor.spin_once(timeout_sec=0.005)
        return True

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


class Io:
    """Publishers of the node's inputs and collectors of its outputs under a namespace."""

    def __init__(self, client: Client, ns: str, reliable_inputs: bool = True):
        from clutch_msgs.msg import ClutchState
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import Temperature
        from std_msgs.msg import Float64

        self.client, self.ns = client, ns.rstrip("/")
        node = client.node
        rel = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        qin = rel if reliable_inputs else qos_profile_sensor_data
        self.Float64, self.Temperature, self.Clock = Float64, Temperature, Clock
        self.pf = node.create_publisher(Float64, f"{self.ns}/applied_force", qin)
        self.pw = node.create_publisher(Float64, f"{self.ns}/slip_speed", qin)
        self.ps = node.create_publisher(Temperature, f"{self.ns}/sump_temperature", qin)
        self.pclock = node.create_publisher(Clock, "/clock", rel)
        self.states, self.torques, self.temps, self.diags = [], [], [], []
        node.create_subscription(ClutchState, f"{self.ns}/clutch_state", self.states.append, rel)
        node.create_subscription(Float64, f"{self.ns}/clutch_torque", self.torques.append, rel)
        node.create_subscription(Temperature, f"{self.ns}/pack_temperature", self.temps.append, rel)
        node.create_subscription(DiagnosticArray, "/diagnostics", self.diags.append, rel)

    def send(self, force=None, slip=None, sump=None) -> None:
        if force is not None:
            self.pf.publish(self.Float64(data=float(force)))
        if slip is not None:
            self.pw.publish(self.Float64(data=float(slip)))
        if sump is not None:
            self.ps.publish(self.Temperature(temperature=float(sump)))

    def clock(self, t_ns: int) -> None:
        msg = self.Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(int(t_ns), 1_000_000_000)
        self.pclock.publish(msg)

    def wait_matched(self, timeout: float = 20.0, clock: bool = False) -> None:
        node = self.client.node

        def ready():
            pubs = [self.pf, self.pw, self.ps] + ([self.pclock] if clock else [])
            return (all(p.get_subscription_count() > 0 for p in pubs)
                    and node.count_publishers(f"{self.ns}/clutch_state") > 0)

        assert self.client.spin_until(ready, timeout), f"node in {self.ns or '/'} not discovered"
        self.client.spin_for(0.3)

    def node_status(self, kind: str, fqn: str):
        """The latest DiagnosticStatus '<node name>: <kind>' of the node ``fqn`` (its
        hardware_id) received, or None."""
        name = fqn.rsplit("/", 1)[-1]
        for arr in reversed(self.diags):
            for st in arr.status:
                if st.name == f"{name}: {kind}" and st.hardware_id == fqn:
                    return st
        return None

    def wait_status(self, kind: str, fqn: str, pred, timeout: float = 30.0):
        from clutch_sim_ros.diagnostics import values_of

        found = []

        def check():
            st = self.node_status(kind, fqn)
            if st is not None and pred(st, values_of(st)):
                found.append(st)
                return True
            return False

        self.diags.clear()
        ok = self.client.spin_until(check, timeout)
        return found[0] if ok else self.node_status(kind, fqn)


@pytest.fixture(scope="module")
def client(domain_id):
    c = Client(domain_id)
    yield c
    c.close()


class CpuMeter:
    """CPU used by processes other than ``pids`` over a window (cores, from /proc): timing
    assertions are only meaningful when the machine is not busy with other work."""

    def __init__(self, pids):
        self.pids = list(pids)
        self._t0, self._total0, self._ours0 = time.monotonic(), self._total(), self._ours()

    @staticmethod
    def _total() -> float:
        fields = Path("/proc/stat").read_text().splitlines()[0].split()[1:]
        user, nice, system, idle, iowait, irq, softirq, steal = (int(x) for x in fields[:8])
        return (user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK")

    def _ours(self) -> float:
        total = 0.0
        for pid in self.pids:
            try:
                f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
                total += (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")
            except (OSError, IndexError):
                pass
        return total

    def others_cores(self) -> float:
        wall = max(time.monotonic() - self._t0, 1e-3)
        return max(0.0, ((self._total() - self._total0) - (self._ours() - self._ours0)) / wall)


def stamp_ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def write_test_bag(path: Path, seconds: float = 2.0, seed: int = 0, start_ns=None, storage: str = "mcap",
                   bad_samples: bool = False) -> Path:
    """A small car-test bag: force steps at 100 Hz, slip at 50 Hz, sump at 10 Hz, measured
    torque at 100 Hz, on unaligned time grids."""
    import numpy as np

    from clutch_model.formats.bag_writer import write_run_bag

    rng = np.random.default_rng(seed)
    tf = np.arange(0.0, seconds, 0.01)
    force = np.where((tf % 1.0) < 0.5, 3500.0 + 500 * seed, 700.0) + rng.normal(0, 20, tf.size)
    tw = np.arange(0.003, seconds, 0.02)
    slip = 6.0 + 2.0 * np.sin(2 * tw) + rng.normal(0, 0.05, tw.size)
    ts = np.arange(0.001, seconds, 0.1)
    sump = 50.0 + 5 * seed + 0.3 * ts
    if bad_samples:  # the node would reject these; offline replay drops them too
        force[17] = np.nan
        slip[5] = 5000.0
        sump[3] = 900.0
    tm = np.arange(0.0, seconds, 0.01)
    meas = 400.0 + rng.normal(0, 10, tm.size)
    kw = {"start_time_ns": start_ns} if start_ns is not None else {}
    return write_run_bag(path, {"applied_force": (tf, force), "slip_speed": (tw, slip),
                                "sump_temperature": (ts, sump), "measured_torque": (tm, meas)},
                         storage=storage, **kw)
