"""The node in wall-clock mode, as a subprocess, against a test client in this process:
step response vs the offline simulator, parameters and remapping from YAML, start-up hold,
bad and stale inputs on /diagnostics, ~/reset, a fuzzed stream and a flood, real-time play
and record, clean shutdown."""
from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from .conftest import REPO, CpuMeter, Io, NodeProcess, stamp_ns, subprocess_env, write_test_bag

pytestmark = pytest.mark.ros

FQN = "/rig1/clutch_sim"


@pytest.fixture(scope="module")
def rig1(domain_id, tmp_path_factory):
    """The shipped config, in namespace /rig1 (exactly the documented command line)."""
    node = NodeProcess(domain_id, ["-r", "__ns:=/rig1", "--params-file", str(REPO / "config" / "clutch_sim.yaml")],
                       tmp_path_factory.mktemp("rig1"))
    yield node
    assert node.stop(signal.SIGINT) == 0, node.log()


@pytest.fixture(scope="module")
def io1(client, rig1):
    io = Io(client, "/rig1")
    io.wait_matched()
    return io


def _feed(io: Io, seconds: float, force, slip=10.0, sump=60.0, period=0.005):
    """Publish the inputs every ``period`` for ``seconds`` while spinning."""
    end = time.monotonic() + seconds
    nxt = 0.0
    while time.monotonic() < end:
        if time.monotonic() >= nxt:
            io.send(force, slip, sump)
            nxt = time.monotonic() + period
        io.client.executor.spin_once(timeout_sec=0.001)


def _reset(io: Io, fqn: str = FQN):
    from std_srvs.srv import Trigger

    cli = io.client.node.create_client(Trigger, f"{fqn}/reset")
    assert cli.wait_for_service(timeout_sec=5.0)
    fut = cli.call_async(Trigger.Request())
    assert io.client.spin_until(fut.done, 5.0)
    io.client.node.destroy_client(cli)
    return fut.result()


def _get_params(io: Io, fqn: str, names):
    from rcl_interfaces.srv import GetParameters
    from rclpy.parameter import parameter_value_to_python

    cli = io.client.node.create_client(GetParameters, f"{fqn}/get_parameters")
    assert cli.wait_for_service(timeout_sec=5.0)
    fut = cli.call_async(GetParameters.Request(names=list(names)))
    assert io.client.spin_until(fut.done, 5.0)
    io.client.node.destroy_client(cli)
    return {n: parameter_value_to_python(v) for n, v in zip(names, fut.result().values)}


def test_shipped_config_namespace_and_parameters(io1):
    params = _get_params(io1, FQN, ["rate_hz", "publish_every", "clutch_params_file", "input_timeout_s",
                                    "lock_slip_rad_s", "use_sim_time"])
    assert params == {"rate_hz": 1000, "publish_every": 1, "clutch_params_file": "", "input_timeout_s": 0.1,
                      "lock_slip_rad_s": 0.001, "use_sim_time": False}
    _feed(io1, 0.6, 1000.0)
    st = io1.wait_status("timing", FQN, lambda s, v: int(v["ticks"]) > 0)
    assert st is not None and st.hardware_id == FQN


def test_force_step_matches_offline_simulator(io1):
    """A force step: the plant the node stepped equals the offline step simulator on the
    inputs the node used (echoed in clutch_state), dt = 1/rate_hz; and the settled torque
    equals the offline simulator on the inputs as the client sent them."""
    from clutch_model import load_model, simulate

    _feed(io1, 0.1, 800.0)
    io1.states.clear()
    assert _reset(io1).success
    t_send0 = time.time_ns()
    _feed(io1, 0.4, 800.0)
    t_step = time.time_ns()
    _feed(io1, 0.5, 4000.0)
    io1.client.spin_for(0.05)
    states = io1.states[:]
    start = next(k for k, m in enumerate(states) if m.energy == 0.0)   # the restart tick
    states = states[start:]
    f = np.array([m.applied_force for m in states])
    w = np.array([m.slip_speed for m in states])
    s = np.array([m.sump_temperature for m in states])
    assert set(f) == {800.0, 4000.0} and len(states) > 700
    off = simulate(load_model(None), np.arange(len(states)) * 1e-3, f, w, s)
    np.testing.assert_allclose([m.clutch_torque for m in states], off.torque_nm, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose([m.pack_temperature for m in states], off.pack_temperature_c, rtol=1e-9, atol=1e-9)

    # against the client's own schedule: the step placed at the first tick stamped after it
    # was sent (tolerance: the transport latency shifts the step by a tick or two)
    stamps = np.array([stamp_ns(m.header.stamp) for m in states])
    k_sent = int(np.argmax(stamps >= t_step))
    sent_force = np.where(np.arange(len(states)) >= k_sent, 4000.0, 800.0)
    off_c = simulate(load_model(None), np.arange(len(states)) * 1e-3, sent_force, 10.0, 60.0)
    torque = np.array([m.clutch_torque for m in states])
    after = np.arange(len(states)) > k_sent + 50
    np.testing.assert_allclose(torque[after], off_c.torque_nm[after], rtol=0.05)
    assert abs(states[-1].pack_temperature - off_c.pack_temperature_c[-1]) < 0.2
    k_used = int(np.argmax(f == 4000.0))
    assert 0 <= k_used - k_sent <= 20                      # the new force reached the plant within 20 ticks
    assert (stamps[k_used] - t_step) * 1e-9 < 0.05
    assert stamps[0] >= t_send0 - 200_000_000


def test_bad_inputs_rejected_held_and_reported(io1):
    from diagnostic_msgs.msg import DiagnosticStatus

    _feed(io1, 0.2, 1500.0, 10.0, 60.0)
    before = io1.wait_status("inputs", FQN, lambda s, v: v["applied_force.state"] == "fresh")
    from clutch_sim_ros.diagnostics import values_of

    rej0 = {k: int(values_of(before)[f"{k}.rejected"]) for k in ("applied_force", "slip_speed", "sump_temperature")}
    bad = [(math.nan, None, None), (2e6, None, None), (math.inf, None, None), (None, math.nan, None),
           (None, 1500.0, None), (None, -math.inf, None), (None, None, 250.0), (None, None, -41.0),
           (None, None, math.nan)]
    for f, w, s in bad:
        io1.send(f, w, s)
        io1.client.spin_for(0.01)
    io1.states.clear()
    io1.diags.clear()

    def send_negative_force():   # valid: counts as 0 N; slip and sump stay held (stale)
        io1.send(-100.0, None, None)

    io1.client.spin_until(lambda: (io1.node_status("inputs", FQN) is not None and int(values_of(
        io1.node_status("inputs", FQN))["sump_temperature.rejected"]) >= rej0["sump_temperature"] + 3), 5.0,
        step=send_negative_force)
    st = io1.node_status("inputs", FQN)
    vals = values_of(st)
    assert int(vals["applied_force.rejected"]) - rej0["applied_force"] == 3
    assert int(vals["slip_speed.rejected"]) - rej0["slip_speed"] == 3
    assert int(vals["sump_temperature.rejected"]) - rej0["sump_temperature"] == 3
    assert st.level >= DiagnosticStatus.WARN and "rejected" in st.message
    last = io1.states[-1]
    assert (last.applied_force, last.slip_speed, last.sump_temperature) == (-100.0, 10.0, 60.0)
    assert last.pack_force == 0.0
    for m in io1.states:
        assert all(math.isfinite(getattr(m, k)) for k in ("clutch_torque", "pack_temperature", "film_thickness",
                                                             "power", "energy", "viscosity"))


def test_stale_force_opens_clutch_and_diagnostics_escalate(io1):
    from diagnostic_msgs.msg import DiagnosticStatus

    _feed(io1, 0.3, 3000.0, 10.0, 60.0)
    engaged = io1.states[-1].clutch_torque
    assert io1.states[-1].applied_force == 3000.0 and engaged > 100.0
    # keep slip and sump fresh, stop the force
    end = time.monotonic() + 0.4
    while time.monotonic() < end:
        io1.send(None, 10.0, 60.0)
        io1.client.spin_for(0.01)
    last = io1.states[-1]
    assert last.applied_force == 0.0 and last.pack_force == 0.0          # safe state: open clutch
    assert 0.0 < last.clutch_torque < 0.3 * engaged                    # only the viscous part left
    warn = io1.wait_status("inputs", FQN, lambda s, v: v["applied_force.state"] == "stale")
    assert warn.level == DiagnosticStatus.WARN and "applied_force stale" in warn.message

    def keep_slip():
        io1.send(None, 10.0, 60.0)

    err = []
    io1.client.spin_until(lambda: (io1.node_status("inputs", FQN) is not None
                                   and io1.node_status("inputs", FQN).level == DiagnosticStatus.ERROR
                                   and not err.append(1)), 3.0, step=keep_slip)
    assert err, "no ERROR after 10 x input_timeout_s"
    _feed(io1, 0.2, 2000.0)
    io1.diags.clear()
    assert io1.client.spin_until(lambda: (io1.node_status("inputs", FQN) is not None
                                          and io1.node_status("inputs", FQN).level == DiagnosticStatus.OK), 3.0,
                                 step=lambda: io1.send(2000.0, 10.0, 60.0))
    assert io1.states[-1].applied_force == 2000.0


def test_reset_service_restarts_plant(io1):
    from clutch_model import load_model

    _feed(io1, 0.5, 5000.0, 30.0, 55.0)
    hot = io1.states[-1]
    assert hot.energy > 1000.0 and hot.pack_temperature > 56.0
    io1.states.clear()
    res = _reset(io1)
    assert res.success and "restarts" in res.message
    _feed(io1, 0.05, 5000.0, 30.0, 55.0)
    first = next(m for m in io1.states if m.energy < hot.energy)
    assert first.energy == 0.0 and first.pack_temperature == 55.0
    assert first.film_thickness == pytest.approx(load_model(None).data["initial"]["film_thickness"], rel=1e-12)


FUZZ_FLOOD = textwrap.dedent(r"""
    import math, random, sys, time, rclpy
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from std_msgs.msg import Float64
    from sensor_msgs.msg import Temperature
    ns, fuzz_s, flood_s, hz = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4])
    rclpy.init()
    n = Node("fuzz_flood")
    pf = n.create_publisher(Float64, ns + "/applied_force", qos_profile_sensor_data)
    pw = n.create_publisher(Float64, ns + "/slip_speed", qos_profile_sensor_data)
    ps = n.create_publisher(Temperature, ns + "/sump_temperature", qos_profile_sensor_data)
    while pf.get_subscription_count() == 0:
        time.sleep(0.01)
    rng = random.Random(7)
    special = [math.nan, math.inf, -math.inf, 0.0, -0.0, 1e308, -1e308, 5e-324, 1e6, 1e6 + 1,
               -1e6, 1000.0, -1000.0, 1000.0001, -40.0, 200.0, 200.0001, 43782.0, 1e5]
    def val():
        r = rng.random()
        return rng.choice(special) if r < 0.4 else rng.uniform(-2e6, 2e6) if r < 0.7 else rng.uniform(-300, 300)
    end = time.monotonic() + fuzz_s
    k = 0
    while time.monotonic() < end:
        pf.publish(Float64(data=val())); pw.publish(Float64(data=val())); ps.publish(Temperature(temperature=val()))
        k += 1
        if k % 20 == 0:
            time.sleep(0.001)
    f, w, s = Float64(data=3000.0), Float64(data=20.0), Temperature(temperature=70.0)
    period = 1.0 / hz
    t = time.monotonic(); end = t + flood_s; m = 0
    while t < end:
        pf.publish(f); pw.publish(w); ps.publish(s); m += 1
        nxt = t + period
        while True:
            t = time.monotonic()
            if t >= nxt:
                break
            if nxt - t > 0.0006:
                time.sleep(nxt - t - 0.0004)
    print(k, m / flood_s, flush=True)
""")


def test_fuzzed_stream_and_flood(io1, rig1, domain_id):
    """Random values (NaN, inf, huge, negative, boundaries) on every input, then a flood at
    10x the step rate on every input: the node keeps running at >= 95 % of rate_hz, never
    publishes a non-finite value and never raises."""
    from clutch_sim_ros.diagnostics import values_of

    _feed(io1, 0.1, 1000.0)
    io1.states.clear()
    io1.diags.clear()
    proc = subprocess.Popen([sys.executable, "-c", FUZZ_FLOOD, "/rig1", "1.5", "3.0", "10000"],
                            env=subprocess_env(domain_id), stdout=subprocess.PIPE, text=True)
    meter = CpuMeter([os.getpid(), rig1.proc.pid, proc.pid])
    try:
        end = time.monotonic() + 30.0
        while proc.poll() is None and time.monotonic() < end:
            io1.client.executor.spin_once(timeout_sec=0.01)
        out = proc.communicate(timeout=10)[0].split()
        others = meter.others_cores()
    finally:
        if proc.poll() is None:
            proc.kill()
    fuzz_msgs, flood_hz = int(out[0]), float(out[1])
    io1.client.spin_for(0.6)
    assert fuzz_msgs > 1000 and 3 * flood_hz >= 10 * 1000    # >= 10 input messages per step
    assert io1.states, "no output during fuzz/flood"
    for m in io1.states:
        assert all(math.isfinite(getattr(m, k)) for k in ("applied_force", "slip_speed", "sump_temperature",
                                                             "clutch_torque", "pack_temperature", "power"))
    timing = [values_of(st) for arr in io1.diags for st in arr.status if st.name == f"{FQN}: timing"]
    assert timing and int(timing[-1]["callback_errors"]) == 0 and int(timing[-1]["nonfinite_resets"]) == 0
    flood = [float(v["achieved_hz"]) for v in timing[-7:-2]]          # windows inside the flood
    print("achieved Hz during the flood:", flood, "flood Hz per topic:", flood_hz, "others' CPU:", others)
    if np.median(flood) < 950.0 and others > 0.5:
        pytest.skip(f"step rate under flood not judged: other processes used {others:.1f} cores "
                    f"(achieved {np.median(flood):.0f} Hz)")
    assert np.median(flood) >= 950.0, flood
    inputs = [values_of(st) for arr in io1.diags for st in arr.status if st.name == f"{FQN}: inputs"]
    assert int(inputs[-1]["applied_force.rejected"]) > 0
    # still answers promptly
    io1.states.clear()
    _feed(io1, 0.05, 2222.0)
    assert io1.states and io1.states[-1].applied_force == 2222.0


def test_realtime_play_and_record(io1, domain_id, tmp_path):
    """clutch-sim record + clutch-sim play (real time, --rate 2) as processes: the recording
    holds the node's outputs driven by the bag's inputs."""
    from rosbags.highlevel import AnyReader

    bag = write_test_bag(tmp_path / "run_rt", seconds=2.0, seed=5)
    out = tmp_path / "rec_dir"
    env = subprocess_env(domain_id)
    rec = subprocess.Popen([sys.executable, "-m", "clutch_sim.cli", "record", "--out", str(out), "--namespace",
                            "/rig1"], env=env, cwd=str(REPO), stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    try:
        n0 = io1.client.node.count_subscribers("/rig1/clutch_state")
        assert io1.client.spin_until(lambda: io1.client.node.count_subscribers("/rig1/clutch_state") > n0, 20.0)
        play = subprocess.run([sys.executable, "-m", "clutch_sim.cli", "play", "--bag", str(bag), "--namespace",
                               "/rig1", "--rate", "2"], env=env, cwd=str(REPO), capture_output=True, text=True,
                              timeout=60)
        assert play.returncode == 0, play.stderr
        time.sleep(1.0)
        rec.send_signal(signal.SIGINT)            # Ctrl-C ends a recording cleanly (exit 0, file kept)
        rec_out, rec_err = rec.communicate(timeout=30)
    finally:
        if rec.poll() is None:
            rec.kill()
    assert rec.returncode == 0, rec_err
    assert (out / "metadata.yaml").is_file()
    with AnyReader([out]) as reader:
        topics = {c.topic: c.msgcount for c in reader.connections}
        forces = [reader.deserialize(raw, c.msgtype).applied_force
                  for c, _, raw in reader.messages([c for c in reader.connections if c.topic == "/rig1/clutch_state"])]
    assert topics["/rig1/clutch_state"] > 500 and topics["/rig1/clutch_torque"] > 500
    assert topics["/diagnostics"] >= 1
    from clutch_model.formats.bag_messages import read_messages

    bag_forces = {m.value for m in read_messages(bag).messages if m.topic == "applied_force"}
    played = set(forces) & bag_forces
    assert len(played) > 50


def test_yaml_parameters_remap_and_startup_hold(client, domain_id, tmp_path):
    """Parameters from a YAML file (node key beats /**), a topic remap, the start-up hold and a
    SIGTERM shutdown with exit code 0."""
    from clutch_model import load_model, simulate
    from diagnostic_msgs.msg import DiagnosticStatus
    from std_msgs.msg import Float64

    from clutch_sim_ros.diagnostics import values_of

    yaml_file = tmp_path / "params.yaml"
    yaml_file.write_text(textwrap.dedent("""
        /**:
          ros__parameters:
            rate_hz: 100
            publish_every: 1
            input_timeout_s: 0.3
        /rig2/clutch_sim:
          ros__parameters:
            rate_hz: 200
            publish_every: 4
    """))
    node = NodeProcess(domain_id, ["-r", "__ns:=/rig2", "--params-file", str(yaml_file),
                                   "-r", "clutch_torque:=torque_nm"], tmp_path)
    try:
        io = Io(client, "/rig2")
        torques = []
        client.node.create_subscription(Float64, "/rig2/torque_nm", torques.append, 100)
        io.wait_matched()
        # start-up hold: no sump temperature yet -> nothing published, diagnostics ERROR
        end = time.monotonic() + 0.6
        while time.monotonic() < end:
            io.send(2000.0, 5.0, None)
            client.spin_for(0.01)
        assert not io.states and not torques
        st = io.node_status("inputs", "/rig2/clutch_sim")
        assert st is not None and st.level == DiagnosticStatus.ERROR and "no sump_temperature yet" in st.message
        # all inputs -> the plant starts; outputs every 4th tick of 200 Hz
        t0 = time.monotonic()
        end = t0 + 1.5
        while time.monotonic() < end:
            io.send(2000.0, 5.0, 40.0)
            client.spin_for(0.01)
        client.spin_for(0.1)
        wall = time.monotonic() - t0
        assert 0.6 * 50 * wall < len(io.states) < 1.3 * 50 * wall
        assert len(torques) >= len(io.states) - 2
        states = io.states
        n = 4 * (len(states) - 1) + 1
        off = simulate(load_model(None), np.arange(n) / 200.0, 2000.0, 5.0, 40.0)
        np.testing.assert_allclose([m.clutch_torque for m in states], off.torque_nm[::4], rtol=1e-9)
        np.testing.assert_allclose([m.pack_temperature for m in states], off.pack_temperature_c[::4], rtol=1e-9)
        timing = io.wait_status("timing", "/rig2/clutch_sim", lambda s, v: True)
        vals = values_of(timing)
        assert float(vals["rate_hz"]) == 200.0 and abs(float(vals["achieved_hz"]) - 200.0) < 20.0
        assert float(values_of(io.node_status("inputs", "/rig2/clutch_sim"))["input_timeout_s"]) == 0.3
    finally:
        assert node.stop(signal.SIGTERM) == 0, node.log()
