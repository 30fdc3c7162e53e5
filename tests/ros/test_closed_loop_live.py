"""The example slip controller in its own process closes the loop over DDS: a driveline host
(clutch_sim_ros.driveline_io, stepped in lock-step, one controller answer per tick) on the
split-mu torques; the run equals the same loop computed in-process, and the controller holds
the slip near its target."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from clutch_model import DrivelinePlant, load_model
from clutch_model.closed_loop import PISlipController
from clutch_model.closed_loop.scenarios import split_mu
from clutch_sim_ros import driveline_io as DIO

from .conftest import REPO, Client, subprocess_env

pytestmark = pytest.mark.ros


def _in_process(model, sc, n, f0):
    plant = DrivelinePlant(model, sc.driveline)
    pi = PISlipController(target_slip_rad_s=3.0, kp_n_per_rad_s=600.0, ki_n_per_rad=3000.0,
                          force_min_n=1000.0, force_max_n=20000.0)
    force, slip = np.empty(n), np.empty(n)
    f = f0
    for k in range(n):
        if k == 0:
            plant.reset(f, sc.sump_temperature_c)
        else:
            plant.advance(sc.t[k] - sc.t[k - 1])
        rec = plant.sample(f, sc.torque_a_nm[k], sc.torque_b_nm[k], sc.sump_temperature_c)
        force[k], slip[k] = f, DIO.DrivelineSource.outputs(rec)[0]
        f = pi.update(k * 0.002, slip[k])
    return force, slip


def test_controller_process_closes_the_loop(domain_id, tmp_path):
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64

    model = load_model()
    sc = split_mu(rate_hz=500.0, duration_s=3.0)
    n, f0 = sc.t.size, 1000.0
    log = open(tmp_path / "controller.log", "w")
    # -X faulthandler: a controller that does not exit after SIGINT is sent SIGABRT below and
    # its threads' Python stacks land in its log (the failure message shows them)
    proc = subprocess.Popen([sys.executable, "-X", "faulthandler", str(REPO / "examples/closed_loop/slip_controller_node.py"),
                             "--ros-args", "-r", "__ns:=/cl", "-p", "sample_time_s:=0.002"],
                            env=subprocess_env(domain_id), cwd=str(REPO), stdout=log, stderr=subprocess.STDOUT)
    host = Client(domain_id)
    try:
        rel = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        from rclpy.node import Node
        node = Node("driveline_host", namespace="/cl", context=host.context)
        host.executor.add_node(node)
        src = DIO.DrivelineSource(model, sc.driveline)
        topics = DIO.DrivelineTopics(node, src, rel, rel)
        answers = []       # the controller's answers to real ticks (probe answers are 0.0, see below)
        probe_answers = []

        def on_answer(m):
            (answers if m.data != 0.0 else probe_answers).append(m.data)

        sub = node.create_subscription(Float64, "applied_force", on_answer, rel)
        # the loop starts once a probe has gone there and back: a NaN slip, which the controller
        # answers with its initial command 0.0 and leaves its state untouched (the node's sample
        # counter moves, but the integral only starts at the first finite sample). Matched as seen
        # from the host is not enough: with volatile durability a sample written before the
        # controller's reader matched the host's writer is never delivered (CI: no answer at tick
        # 0, 1 run in about 60). Probes and ticks share one reliable writer, so every probe the
        # controller takes is answered before tick 0's answer; real answers are >= force_min_n.
        probe = Float64()
        probe.data = float("nan")
        ok = host.spin_until(lambda: len(probe_answers) > 0, 60.0,
                             step=lambda: topics.publishers[0].publish(probe), step_period=0.2)
        assert ok, "controller not discovered; log:\n" + (tmp_path / "controller.log").read_text()
        force, slip = np.empty(n), np.empty(n)
        f = f0
        for k in range(n):
            src.torques.torque_a.offer(sc.torque_a_nm[k])      # the rig's torques (held inputs)
            src.torques.torque_b.offer(sc.torque_b_nm[k])
            if k == 0:
                src.reset(f, sc.sump_temperature_c)
            else:
                src.advance(sc.t[k] - sc.t[k - 1])
            rec = src.sample(f, sc.sump_temperature_c, int(sc.t[k] * 1e9), 1.0)
            force[k], slip[k] = f, DIO.DrivelineSource.outputs(rec)[0]
            topics.publish(rec)
            assert host.spin_until(lambda: len(answers) == k + 1, 30.0), f"no controller answer at tick {k}"
            f = answers[k]
        ref_force, ref_slip = _in_process(model, sc, n, f0)
        # equal up to rounding: the probes move the controller's clock by whole samples, so its
        # time steps are (k + p) * dt - (k + p - 1) * dt, not bit for bit dt (1e-13 relative)
        np.testing.assert_allclose(force, ref_force, rtol=1e-9, atol=0.0)
        np.testing.assert_allclose(slip, ref_slip, rtol=0.0, atol=1e-9)
        settled = (sc.t > 2.2) & (sc.t < 3.0)
        assert np.max(np.abs(np.abs(slip[settled]) - 3.0)) < 1.0
        assert force.max() > 2000.0
    finally:
        host.close()
        proc.send_signal(subprocess.signal.SIGINT)
        try:
            try:
                rc = proc.wait(timeout=60)     # generous: a loaded machine shuts rclpy down slowly
            except subprocess.TimeoutExpired:
                proc.send_signal(subprocess.signal.SIGABRT)
                proc.wait(timeout=30)
                log.flush()
                stacks = (tmp_path / "controller.log").read_text()[-6000:]
                pytest.fail(f"the controller did not exit within 60 s of SIGINT; its stacks:\n{stacks}")
            assert rc == 0
        finally:
            if proc.poll() is None:
                proc.kill()
            log.close()
