"""Ctrl-C on the CLI: one line, exit code 130, no traceback, what was written is kept --
montecarlo (numba kernels; an interrupt inside a compiled call surfaces as a SystemError) and
play --clock --record (the bag is complete and readable)."""
from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time

import pytest

from .conftest import REPO, NodeProcess, subprocess_env, write_test_bag

pytestmark = pytest.mark.ros


class _Cli:
    """A clutch-sim process (SIGINT at default, as in a terminal) with its stderr collected."""

    def __init__(self, args, env):
        self.proc = subprocess.Popen([sys.executable, "-m", "clutch_sim.cli", *args], env=env, cwd=str(REPO),
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                     preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        self.err = []
        self._reader = threading.Thread(target=lambda: self.err.extend(iter(lambda: self.proc.stderr.read(1), "")),
                                        daemon=True)
        self._reader.start()

    def wait_for(self, text: str, timeout: float = 120.0) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end and self.proc.poll() is None:
            if text in "".join(self.err):
                return True
            time.sleep(0.05)
        return False

    def interrupt(self, timeout: float = 120.0) -> str:
        self.proc.send_signal(signal.SIGINT)
        self.proc.wait(timeout=timeout)
        self._reader.join(timeout=10)
        return "".join(self.err)


def _lines(text: str) -> list[str]:
    return [ln for ln in text.replace("\r", "\n").splitlines() if ln.strip() and "%|" not in ln]


@pytest.mark.parametrize("delay_s", [0.0, 1.0])
def test_montecarlo_interrupted(delay_s, domain_id, tmp_path):
    cli = _Cli(["montecarlo", "--bags", str(REPO / "bags" / "run_00"), "--samples", "50000", "--spread", "0.05",
                "--seed", "1", "--out", str(tmp_path / "mc"), "--no-plots"], subprocess_env(domain_id))
    assert cli.wait_for("monte carlo"), "".join(cli.err)[-2000:]     # inside the sampling loop
    time.sleep(delay_s)
    err = cli.interrupt()
    assert cli.proc.returncode == 130, err[-2000:]
    assert "Traceback" not in err and "SystemError" not in err
    assert _lines(err)[-1].startswith("clutch-sim montecarlo: interrupted"), err[-2000:]


def test_play_record_interrupted_keeps_a_complete_bag(client, domain_id, tmp_path):
    from clutch_msgs.msg import ClutchState
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosbags.highlevel import AnyReader

    t0 = 1_700_000_000_000_000_000
    bag = write_test_bag(tmp_path / "run_long", seconds=200.0, seed=1, start_ns=t0)
    node = NodeProcess(domain_id, ["-r", "__ns:=/intr", "-p", "use_sim_time:=true"], tmp_path)
    out = tmp_path / "partial.mcap"
    try:
        cli = _Cli(["play", "--bag", str(bag), "--clock", "--namespace", "/intr", "--record", str(out)],
                   subprocess_env(domain_id))
        states = []
        client.node.create_subscription(ClutchState, "/intr/clutch_state", states.append,
                                        QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
        assert client.spin_until(lambda: len(states) > 200 or cli.proc.poll() is not None, 120.0)  # rows playing
        assert cli.proc.poll() is None, "".join(cli.err)[-2000:]
        err = cli.interrupt()
    finally:
        assert node.stop() == 0, node.log()
    assert cli.proc.returncode == 130, err[-2000:]
    assert "Traceback" not in err
    assert _lines(err)[-1].startswith("clutch-sim play: interrupted"), err[-2000:]
    with AnyReader([out]) as reader:
        msgs = [(c.topic, t) for c, t, _ in reader.messages()]
    recorded = [t for topic, t in msgs if topic == "/intr/clutch_state"]
    assert recorded and min(t for _, t in msgs) >= t0
