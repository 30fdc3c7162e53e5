"""ClutchSimNode in this process, with faults injected: a non-finite plant output is never
published (the plant restarts, the event is counted), an exception in the tick is counted and
the node keeps ticking; start-up errors exit with code 1 and a one-line reason."""
from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from .conftest import REPO, Client, Io, subprocess_env

pytestmark = pytest.mark.ros


@pytest.fixture()
def node_and_io(domain_id):
    from rclpy.parameter import Parameter

    from clutch_sim_ros.node import ClutchSimNode

    client = Client(domain_id)
    node = ClutchSimNode(context=client.context, namespace="/inproc",
                         parameter_overrides=[Parameter("rate_hz", Parameter.Type.DOUBLE, 200.0)])
    client.executor.add_node(node)
    io = Io(client, "/inproc")
    io.wait_matched()
    yield node, io
    client.executor.remove_node(node)
    node.destroy_node()
    client.close()


def _run_until(io: Io, cond, what: str, timeout: float = 60.0):
    """Feed the inputs every 10 ms until ``cond()`` (an event wait with a generous deadline)."""
    assert io.client.spin_until(cond, timeout, step=lambda: io.send(3000.0, 12.0, 70.0)), f"timed out: {what}"


def test_nonfinite_output_is_never_published(node_and_io):
    node, io = node_and_io
    _run_until(io, lambda: len(io.states) > 10, "outputs")
    assert node.counters.nonfinite_resets == 0
    real_sample = node._plant.sample
    node._plant.sample = lambda *args: np.full(16, math.nan)
    _run_until(io, lambda: node.counters.nonfinite_resets > 10, "non-finite samples")
    io.client.spin_for(0.05)                   # samples already in flight arrive
    io.states.clear()
    io.torques.clear()
    published = node.counters.published
    resets = node.counters.nonfinite_resets
    _run_until(io, lambda: node.counters.nonfinite_resets > resets + 20, "more non-finite samples")
    assert node.counters.published == published, "a non-finite sample was published"
    assert all(math.isfinite(m.clutch_torque) for m in io.states) and all(math.isfinite(m.data) for m in io.torques)
    node._plant.sample = real_sample
    io.states.clear()
    _run_until(io, lambda: len(io.states) > 5, "outputs after the fault")
    assert all(math.isfinite(m.clutch_torque) for m in io.states)
    assert io.states[0].energy == 0.0          # the plant restarted after the fault


def test_exception_in_tick_is_counted_and_node_keeps_running(node_and_io):
    node, io = node_and_io
    _run_until(io, lambda: len(io.states) > 10, "outputs")
    ticks0 = node.counters.ticks

    def boom(dt):
        raise RuntimeError("injected")

    real_advance = node._plant.advance
    node._plant.advance = boom
    _run_until(io, lambda: node.counters.callback_errors > 10 and node.counters.ticks - ticks0 > 30, "errors counted")
    node._plant.advance = real_advance
    from clutch_sim_ros.diagnostics import values_of

    diag = node.diagnostics()
    timing = next(s for s in diag.status if s.name.endswith(": timing"))
    assert int(values_of(timing)["callback_errors"]) > 10 and timing.name == "clutch_sim: timing"
    assert timing.hardware_id == "/inproc/clutch_sim"


def test_startup_errors_exit_1_with_one_line(domain_id, tmp_path):
    env = subprocess_env(domain_id)
    for args, text in ((["-p", f"clutch_params_file:={tmp_path / 'missing.yaml'}"], "parameter file not found"),
                       (["-p", "rate_hz:=-5.0"], "rate_hz")):
        res = subprocess.run([sys.executable, "-m", "clutch_sim_ros.node", "--ros-args", *args], env=env,
                             cwd=str(REPO), capture_output=True, text=True, timeout=60)
        assert res.returncode == 1
        assert text in res.stderr and "Traceback" not in res.stderr
