"""Ctrl-C on the CLI: one line, exit code 130, no traceback, what was written is kept --
montecarlo (numba kernels; an interrupt inside a compiled call surfaces as a SystemError) and
play --clock --record (the bag is complete and readable)."""
from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from .conftest import REPO, NodeProcess, subprocess_env, write_test_bag

pytestmark = pytest.mark.ros


def _start(cmd, env):
    return subprocess.Popen(cmd, env=env, cwd=str(REPO), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _lines(text: str) -> list[str]:
    return [ln for ln in text.replace("\r", "\n").splitlines() if ln.strip() and "%|" not in ln]


@pytest.mark.parametrize("delay_s", [1.0, 2.5])
def test_montecarlo_interrupted(delay_s, domain_id, tmp_path):
    out = tmp_path / "mc"
    proc = _start([sys.executable, "-m", "clutch_sim.cli", "montecarlo", "--bags", str(REPO / "bags" / "run_00"),
                   "--samples", "20000", "--spread", "0.05", "--seed", "1", "--out", str(out), "--no-plots"],
                  subprocess_env(domain_id))
    time.sleep(delay_s)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err[-2000:]
    assert "Traceback" not in err and "SystemError" not in err
    last = _lines(err)[-1]                    # (a Ctrl-C still during start-up: "clutch-sim: interrupted")
    assert last.startswith("clutch-sim montecarlo: interrupted") or last == "clutch-sim: interrupted", last


def test_play_record_interrupted_keeps_a_complete_bag(domain_id, tmp_path):
    from rosbags.highlevel import AnyReader

    bag = write_test_bag(tmp_path / "run_long", seconds=30.0, seed=1, start_ns=1_700_000_000_000_000_000)
    node = NodeProcess(domain_id, ["-r", "__ns:=/intr", "-p", "use_sim_time:=true"], tmp_path)
    out = tmp_path / "partial.mcap"
    try:
        proc = _start([sys.executable, "-m", "clutch_sim.cli", "play", "--bag", str(bag), "--clock", "--namespace",
                       "/intr", "--record", str(out)], subprocess_env(domain_id))
        deadline = time.monotonic() + 120
        while not any(p.name.startswith(".partial") for p in tmp_path.iterdir()) and time.monotonic() < deadline:
            time.sleep(0.1)          # the recording has started
        time.sleep(3.0)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        assert node.stop() == 0, node.log()
    assert proc.returncode == 130, err[-2000:]
    assert "Traceback" not in err
    assert _lines(err)[-1].startswith("clutch-sim play: interrupted"), err[-2000:]
    with AnyReader([out]) as reader:
        msgs = [(c.topic, t) for c, t, _ in reader.messages()]
    states = [t for topic, t in msgs if topic == "/intr/clutch_state"]
    assert states and min(t for _, t in msgs) >= 1_700_000_000_000_000_000
