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

from .conftest import REPO, Io, NodeProcess, StderrLines, stamp_ns, subprocess_env, write_test_bag

pytestmark = pytest.mark.ros

FQN = "/rig1/clutch_sim"
RTOL_WALL = 1e-4   # wall-clock mode vs the offline simulator at the node's stamps (see the force step test)


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


def _feed_until(io: Io, cond, force, slip=10.0, sump=60.0, timeout: float = 30.0, what: str = "condition"):
    """Publish the inputs every 10 ms until ``cond()``; the deadline is generous (an event
    wait, not a timing assertion)."""
    assert io.client.spin_until(cond, timeout, step=lambda: io.send(force, slip, sump)), f"timed out waiting for {what}"


def test_shipped_config_namespace_and_parameters(io1):
    params = _get_params(io1, FQN, ["rate_hz", "publish_every", "clutch_params_file", "input_timeout_s",
                                    "lock_slip_rad_s", "frame_id", "use_sim_time"])
    assert params == {"rate_hz": 1000.0, "publish_every": 1, "clutch_params_file": "", "input_timeout_s": 0.1,
                      "lock_slip_rad_s": 0.001, "frame_id": "clutch", "use_sim_time": False}
    assert isinstance(params["rate_hz"], float)          # the YAML integer 1000 is a double
    _feed_until(io1, lambda: len(io1.states) > 10, 1000.0, what="outputs")
    st = io1.wait_status("timing", FQN, lambda s, v: int(v["ticks"]) > 0)
    # diagnostic_aggregator naming: "<node name>: <status>", no leading '/'; hardware_id = fqn
    assert st is not None and st.name == "clutch_sim: timing" and st.hardware_id == FQN
    assert io1.states[-1].header.frame_id == "clutch" and io1.temps[-1].header.frame_id == "clutch"


def test_force_step_matches_offline_simulator(io1):
    """A force step: the plant the node stepped equals the offline step simulator on the
    inputs the node used (echoed in clutch_state) at the node's stamps -- in wall-clock mode
    the plant advances by the time elapsed since the previous tick and stamps are plant time,
    so this holds to numerical precision however late the ticks were."""
    from clutch_model import load_model, simulate

    _feed(io1, 0.1, 800.0)
    io1.states.clear()
    assert _reset(io1).success
    _feed_until(io1, lambda: sum(m.energy == 0.0 for m in io1.states) > 0 and len(io1.states) > 300, 800.0,
                what="restart and 300 ticks at 800 N")
    t_step = time.time_ns()
    _feed_until(io1, lambda: sum(m.applied_force == 4000.0 for m in io1.states) > 400, 4000.0,
                what="400 ticks at 4000 N")
    io1.client.spin_for(0.05)
    states = io1.states[:]
    start = max(k for k, m in enumerate(states) if m.energy == 0.0)   # the restart tick
    states = states[start:]
    f = np.array([m.applied_force for m in states])
    w = np.array([m.slip_speed for m in states])
    s = np.array([m.sump_temperature for m in states])
    assert {800.0, 4000.0} <= set(f) <= {0.0, 800.0, 4000.0}     # 0: force stale in a long stall
    stamps = np.array([stamp_ns(m.header.stamp) for m in states])
    assert np.all(np.diff(stamps) > 0)
    off = simulate(load_model(None), (stamps - stamps[0]) * 1e-9, f, w, s)
    # RTOL: equal to numerical precision, except that a tick this client did not see merges
    # two plant steps into one (sub-step split: ~1e-5); a plant step off by one 1 ms tick
    # would show as ~1e-2
    np.testing.assert_allclose([m.clutch_torque for m in states], off.torque_nm, rtol=RTOL_WALL, atol=1e-9)
    np.testing.assert_allclose([m.pack_temperature for m in states], off.pack_temperature_c, rtol=RTOL_WALL)
    np.testing.assert_allclose([m.energy for m in states], off.energy_j, rtol=RTOL_WALL, atol=1e-9)
    k_used = int(np.argmax(f == 4000.0))
    assert stamps[k_used] >= t_step - 1_000_000          # causal: not used before it was sent
    assert max(m.clutch_torque for m in states[k_used:]) > 3 * states[k_used - 1].clutch_torque > 0


def test_bad_inputs_rejected_held_and_reported(io1):
    from diagnostic_msgs.msg import DiagnosticStatus

    from clutch_sim_ros.diagnostics import values_of

    io1.diags.clear()
    _feed_until(io1, lambda: (io1.node_status("inputs", FQN) is not None
                              and io1.node_status("inputs", FQN).level == DiagnosticStatus.OK), 1500.0, 10.0, 60.0,
                what="all inputs fresh")
    before = io1.node_status("inputs", FQN)
    rej0 = {k: int(values_of(before)[f"{k}.rejected"]) for k in ("applied_force", "slip_speed", "sump_temperature")}
    bad = [(math.nan, None, None), (2e6, None, None), (math.inf, None, None), (None, math.nan, None),
           (None, 1500.0, None), (None, -math.inf, None), (None, None, 250.0), (None, None, -41.0),
           (None, None, math.nan)]
    turn = [0]

    def bad_or_negative_force():   # alternately: invalid values on every input / a negative force
        turn[0] += 1                # (valid: counts as 0 N); slip and sump stay held (stale)
        if turn[0] % 2:
            for f, w, s in bad:
                io1.send(f, w, s)
        else:
            io1.send(-100.0, None, None)

    def rejected_enough():
        st = io1.node_status("inputs", FQN)
        if st is None:
            return False
        v = values_of(st)
        return all(int(v[f"{k}.rejected"]) - rej0[k] >= 3 for k in rej0)

    io1.diags.clear()
    assert io1.client.spin_until(rejected_enough, 60.0, step=bad_or_negative_force, step_period=0.02)
    io1.states.clear()
    assert io1.client.spin_until(lambda: len(io1.states) > 5 and io1.states[-1].applied_force == -100.0, 60.0,
                                 step=bad_or_negative_force, step_period=0.02)
    last = io1.states[-1]

    # a report names the rejections made since the one before it: wait for one that does (an
    # event, not a moment: on a loaded machine the latest report may fall in a window where the
    # sender stalled, and then it names only the held inputs' age)
    def reported_rejected():
        st = io1.node_status("inputs", FQN)
        return st is not None and st.level >= DiagnosticStatus.WARN and "rejected" in st.message

    io1.diags.clear()
    assert io1.client.spin_until(reported_rejected, 60.0, step=bad_or_negative_force, step_period=0.02)
    assert (last.applied_force, last.slip_speed, last.sump_temperature) == (-100.0, 10.0, 60.0)
    assert last.pack_force == 0.0
    for m in io1.states:
        assert m.slip_speed == 10.0 and m.sump_temperature == 60.0       # last good values held
        assert all(math.isfinite(getattr(m, k)) for k in ("clutch_torque", "pack_temperature", "film_thickness",
                                                             "power", "energy", "viscosity"))


def test_stale_force_opens_clutch_and_diagnostics_escalate(io1):
    from diagnostic_msgs.msg import DiagnosticStatus

    from clutch_sim_ros.diagnostics import values_of

    io1.states.clear()
    _feed_until(io1, lambda: io1.states and io1.states[-1].applied_force == 3000.0
                and io1.states[-1].clutch_torque > 100.0, 3000.0, 10.0, 60.0, what="engaged clutch")
    engaged = io1.states[-1].clutch_torque
    # keep slip and sump fresh, stop the force: once it is stale it counts as 0 N and the clutch
    # opens (safe state); plant time keeps wall time, so this happens however busy the machine is
    _feed_until(io1, lambda: (io1.states[-1].applied_force == 0.0 and io1.states[-1].pack_force == 0.0
                              and io1.states[-1].clutch_torque < 0.3 * engaged), None, 10.0, 60.0,
                what="the clutch to open")
    assert 0.0 < io1.states[-1].clutch_torque                       # the viscous part is left
    io1.diags.clear()
    stale = []
    _feed_until(io1, lambda: (io1.node_status("inputs", FQN) is not None
                              and values_of(io1.node_status("inputs", FQN))["applied_force.state"] == "stale"
                              and not stale.append(io1.node_status("inputs", FQN))), None, 10.0, 60.0,
                what="applied_force stale on /diagnostics")
    assert stale[0].level >= DiagnosticStatus.WARN and "applied_force stale" in stale[0].message
    assert "counts as 0 N" in stale[0].message
    _feed_until(io1, lambda: (io1.node_status("inputs", FQN) is not None
                              and io1.node_status("inputs", FQN).level == DiagnosticStatus.ERROR), None, 10.0, 60.0,
                what="ERROR after 10 x input_timeout_s")
    io1.diags.clear()
    _feed_until(io1, lambda: (io1.node_status("inputs", FQN) is not None
                              and io1.node_status("inputs", FQN).level == DiagnosticStatus.OK
                              and io1.states[-1].applied_force == 2000.0), 2000.0, 10.0, 60.0,
                what="OK again with a fresh force")


def test_reset_service_restarts_plant(io1):
    from clutch_model import load_model

    _feed_until(io1, lambda: io1.states and io1.states[-1].sump_temperature == 55.0 and io1.states[-1].energy > 1000.0
                and io1.states[-1].pack_temperature > 56.0, 5000.0, 30.0, 55.0, what="a hot clutch")
    hot = io1.states[-1]
    io1.states.clear()
    res = _reset(io1)
    assert res.success and "restarts" in res.message
    _feed_until(io1, lambda: any(m.energy < hot.energy for m in io1.states), 5000.0, 30.0, 55.0, what="the restart")
    first = next(m for m in io1.states if m.energy < hot.energy)
    assert first.energy == 0.0 and first.pack_temperature == 55.0
    assert first.film_thickness == pytest.approx(load_model(None).data["initial"]["film_thickness"], rel=1e-12)


def test_stall_is_made_up_and_flagged(io1, rig1):
    """The node process stopped for 0.4 s (SIGSTOP/SIGCONT, a stall as under heavy load): the
    next tick advances the plant by the whole gap (plant time keeps wall time) -- the node's
    outputs equal the offline simulator at the node's stamps, gap included -- and /diagnostics
    flags the stall."""
    from clutch_model import load_model, simulate

    from clutch_sim_ros.diagnostics import values_of

    _feed_until(io1, lambda: io1.states and io1.states[-1].applied_force == 2500.0, 2500.0, 20.0, 60.0,
                what="steady inputs")
    io1.states.clear()
    assert _reset(io1).success
    _feed_until(io1, lambda: sum(m.energy == 0.0 for m in io1.states) > 0 and len(io1.states) > 100,
                2500.0, 20.0, 60.0, what="the restart")
    k_reset = max(k for k, m in enumerate(io1.states) if m.energy == 0.0)   # the restart, before the stop
    last_before_ns = stamp_ns(io1.states[-1].header.stamp)
    rig1.proc.send_signal(signal.SIGSTOP)
    try:
        time.sleep(0.4)
    finally:
        rig1.proc.send_signal(signal.SIGCONT)
    # outputs stamped after the stop (samples already in flight when it began may still arrive)
    _feed_until(io1, lambda: sum(stamp_ns(m.header.stamp) > last_before_ns for m in io1.states) > 200,
                2500.0, 20.0, 60.0, what="outputs after the stall")
    states = io1.states[k_reset:]
    assert not any(m.energy == 0.0 for m in states if stamp_ns(m.header.stamp) > last_before_ns)  # no restart
    stamps = np.array([stamp_ns(m.header.stamp) for m in states])
    gaps = np.diff(stamps) * 1e-9
    assert gaps.max() >= 0.35, (gaps.max(), len(states))   # one tick made up the whole stop
    off = simulate(load_model(None), (stamps - stamps[0]) * 1e-9, [m.applied_force for m in states],
                   [m.slip_speed for m in states], [m.sump_temperature for m in states])
    np.testing.assert_allclose([m.energy for m in states], off.energy_j, rtol=RTOL_WALL, atol=1e-9)
    np.testing.assert_allclose([m.clutch_torque for m in states], off.torque_nm, rtol=RTOL_WALL, atol=1e-9)
    st = io1.wait_status("timing", FQN, lambda s, v: int(v["stalls"]) >= 1)
    vals = values_of(st)
    assert int(vals["stalls"]) >= 1 and float(vals["longest_gap_ms"]) >= 350.0


def test_runtime_parameters_apply_or_are_refused(io1, tmp_path):
    """Each parameter applies at runtime or is refused with a reason; integers are accepted
    for floats; use_sim_time really switches the stepping to /clock and back."""
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    def set_params(**values):
        cli = io1.client.node.create_client(SetParameters, f"{FQN}/set_parameters")
        assert cli.wait_for_service(timeout_sec=10.0)
        req = SetParameters.Request(parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()])
        fut = cli.call_async(req)
        assert io1.client.spin_until(fut.done, 30.0)
        io1.client.node.destroy_client(cli)
        return fut.result().results

    (r,) = set_params(rate_hz=500)                           # integer for a float
    assert r.successful
    assert _get_params(io1, FQN, ["rate_hz"]) == {"rate_hz": 500.0}
    st = io1.wait_status("timing", FQN, lambda s, v: float(v["rate_hz"]) == 500.0)
    assert st is not None
    for bad, text in ((dict(rate_hz=0.0), "out of range"), (dict(rate_hz="fast"), "number"),
                      (dict(publish_every=0), "out of range"), (dict(input_timeout_s=-1.0), "out of range"),
                      (dict(clutch_params_file=str(tmp_path / "missing.yaml")), "clutch_params_file refused"),
                      (dict(use_sim_time=3), "BOOL")):
        (r,) = set_params(**bad)
        assert not r.successful and text in r.reason, (bad, r.reason)
    assert _get_params(io1, FQN, ["rate_hz", "publish_every"]) == {"rate_hz": 500.0, "publish_every": 1}

    (r,) = set_params(frame_id="rear_clutch")
    assert r.successful
    _feed_until(io1, lambda: io1.states and io1.states[-1].header.frame_id == "rear_clutch", 1000.0,
                what="the new frame_id")
    # use_sim_time: now one step per /clock, stamped with it
    (r,) = set_params(use_sim_time=True)
    assert r.successful
    t_sim = 1_234_000_000_000
    io1.states.clear()

    def clock_step():
        io1.send(1000.0, 10.0, 60.0)
        io1.clock(t_sim)

    assert io1.client.spin_until(lambda: any(stamp_ns(m.header.stamp) == t_sim for m in io1.states), 30.0,
                                 step=clock_step)
    io1.client.spin_for(0.6)                                   # no new /clock: no step at another time
    first = next(k for k, m in enumerate(io1.states) if stamp_ns(m.header.stamp) == t_sim)
    assert all(stamp_ns(m.header.stamp) == t_sim for m in io1.states[first:])   # steps only on /clock
    st = io1.wait_status("timing", FQN, lambda s, v: v["mode"] == "sim_time")
    assert st is not None
    assert all(r.successful for r in set_params(use_sim_time=False, rate_hz=1000, frame_id="clutch"))
    io1.states.clear()
    _feed_until(io1, lambda: len(io1.states) > 20 and abs(stamp_ns(io1.states[-1].header.stamp) - time.time_ns()) < 60e9,
                1000.0, what="wall-clock stepping again")


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
    """Random values (NaN, inf, huge, negative, boundaries) on every input, then a flood of
    10000 messages/s per input: the node keeps running, never publishes a non-finite value,
    never raises, counts the rejected inputs and still answers. (The step rate under a flood is
    measured by bench/bench_node.py --flood, not asserted here.)"""
    from clutch_sim_ros.diagnostics import values_of

    _feed(io1, 0.1, 1000.0)
    io1.states.clear()
    io1.diags.clear()
    proc = subprocess.Popen([sys.executable, "-c", FUZZ_FLOOD, "/rig1", "1.5", "3.0", "10000"],
                            env=subprocess_env(domain_id), stdout=subprocess.PIPE, text=True)
    try:
        assert io1.client.spin_until(lambda: proc.poll() is not None, 120.0), "fuzz/flood publisher hung"
        out = proc.communicate(timeout=30)[0].split()
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0 and int(out[0]) > 0
    assert rig1.alive(), rig1.log()
    io1.client.spin_for(0.6)
    assert io1.states, "no output during fuzz/flood"
    for m in io1.states:
        assert all(math.isfinite(getattr(m, k)) for k in ("applied_force", "slip_speed", "sump_temperature",
                                                             "clutch_torque", "pack_temperature", "power"))
    st = io1.wait_status("timing", FQN, lambda s, v: True)
    timing = values_of(st)
    assert int(timing["callback_errors"]) == 0 and int(timing["nonfinite_resets"]) == 0
    inputs = values_of(io1.wait_status("inputs", FQN, lambda s, v: True))
    assert int(inputs["applied_force.rejected"]) > 0 and int(inputs["sump_temperature.rejected"]) > 0
    # still answers
    io1.states.clear()
    _feed_until(io1, lambda: io1.states and io1.states[-1].applied_force == 2222.0, 2222.0, what="an answer")


def test_realtime_play_and_record(io1, domain_id, tmp_path):
    """clutch-sim record + clutch-sim play (real time, --rate 2) as processes against the 1 kHz
    node: the recording holds the node's outputs driven by the bag's inputs, loses no message
    (every clutch_state this test's own reliable subscription got while the recorder ran is in
    it), logs nothing before the recording started, and is complete after Ctrl-C."""
    from rosbags.highlevel import AnyReader

    bag = write_test_bag(tmp_path / "run_rt", seconds=2.0, seed=5)
    out = tmp_path / "rec_dir"
    env = subprocess_env(domain_id)
    t_launch = time.time_ns()
    rec = subprocess.Popen([sys.executable, "-m", "clutch_sim.cli", "record", "--out", str(out), "--namespace",
                            "/rig1"], env=env, cwd=str(REPO), stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    play = None
    from clutch_sim_ros.record import READY_LINE

    err = StderrLines(rec)    # the recorder's stderr, read as it comes (its ready line is the event)
    try:
        # the recorder's own subscriptions matched the node's publishers (its ready line: under
        # load, the graph can show the recorder long before the node's writers have matched it,
        # and 1 s of data played before that is lost to it) and its subscription is in the graph
        n0 = io1.client.node.count_subscribers("/rig1/clutch_state")
        assert io1.client.spin_until(lambda: err.has(READY_LINE)
                                     and io1.client.node.count_subscribers("/rig1/clutch_state") > n0, 120.0), \
            err.text()
        io1.client.spin_for(0.5)
        io1.states.clear()
        play = subprocess.Popen([sys.executable, "-m", "clutch_sim.cli", "play", "--bag", str(bag), "--namespace",
                                 "/rig1", "--rate", "2"], env=env, cwd=str(REPO), stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        assert io1.client.spin_until(lambda: play.poll() is not None, 120.0), "play did not finish"
        assert play.returncode == 0, play.stderr.read()
        io1.client.spin_for(0.5)
        rec.send_signal(signal.SIGINT)            # Ctrl-C ends a recording cleanly (exit 0, file kept)
        assert io1.client.spin_until(lambda: rec.poll() is not None, 60.0), "record did not stop"
        rec_out = rec.stdout.read()
        rec_err = err.text(join_timeout_s=30)
    finally:
        for proc in (rec, play):
            if proc is not None and proc.poll() is None:
                proc.kill()
    assert rec.returncode == 0, rec_err
    assert "Traceback" not in rec_err and "recorded" in rec_out
    assert (out / "metadata.yaml").is_file()
    with AnyReader([out]) as reader:
        topics = {c.topic: c.msgcount for c in reader.connections}
        rec_states = [(t, reader.deserialize(raw, c.msgtype)) for c, t, raw in
                      reader.messages([c for c in reader.connections if c.topic == "/rig1/clutch_state"])]
        log_times = [t for _, t, _ in reader.messages()]
    assert min(log_times) >= t_launch                     # nothing stamped before the recording
    assert topics["/rig1/clutch_state"] > 100 and topics["/rig1/clutch_torque"] > 100
    assert topics["/diagnostics"] >= 1
    recorded = {stamp_ns(m.header.stamp) for _, m in rec_states}
    lo, hi = min(recorded), max(recorded)
    seen = {stamp_ns(m.header.stamp) for m in io1.states}
    inside = {t for t in seen if lo <= t <= hi}
    assert len(inside) > 100
    assert inside <= recorded, f"{len(inside - recorded)} of {len(inside)} messages missing from the recording"
    from clutch_model.formats.bag_messages import read_messages

    bag_forces = {m.value for m in read_messages(bag).messages if m.topic == "applied_force"}
    played = {m.applied_force for _, m in rec_states} & bag_forces
    assert len(played) > 20


def test_yaml_parameters_remap_and_startup_hold(client, domain_id, tmp_path):
    """Parameters from a YAML file (node key beats /**, integers for floats), a topic remap,
    the start-up hold, publish_every and a SIGTERM shutdown with exit code 0."""
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
            input_timeout_s: 5
        /rig2/clutch_sim:
          ros__parameters:
            rate_hz: 200
            publish_every: 4
    """))
    node = NodeProcess(domain_id, ["-r", "__ns:=/rig2", "--params-file", str(yaml_file),
                                   "-r", "clutch_torque:=torque_nm"], tmp_path)
    fqn = "/rig2/clutch_sim"
    try:
        io = Io(client, "/rig2")
        torques = []
        client.node.create_subscription(Float64, "/rig2/torque_nm", torques.append, 100)
        io.wait_matched(timeout=60.0)
        params = _get_params(io, fqn, ["rate_hz", "publish_every", "input_timeout_s"])
        assert params == {"rate_hz": 200.0, "publish_every": 4, "input_timeout_s": 5.0}
        assert all(isinstance(params[k], float) for k in ("rate_hz", "input_timeout_s"))
        # start-up hold: no sump temperature yet -> nothing published, diagnostics ERROR
        io.diags.clear()
        _feed_until(io, lambda: (io.node_status("inputs", fqn) is not None
                                 and "no sump_temperature yet" in io.node_status("inputs", fqn).message
                                 and values_of(io.node_status("inputs", fqn))["applied_force.state"] == "fresh"),
                    2000.0, 5.0, None, what="start-up hold diagnostics")
        assert io.node_status("inputs", fqn).level == DiagnosticStatus.ERROR
        assert not io.states and not torques
        # all inputs -> the plant starts; outputs every 4th tick
        _feed_until(io, lambda: len(io.states) >= 40, 2000.0, 5.0, 40.0, what="40 outputs")
        assert client.spin_until(lambda: len(torques) >= 40, 30.0)        # the remapped topic carries them too
        states = io.states[:40]
        stamps = np.array([stamp_ns(m.header.stamp) for m in states])
        # the plant advanced by the elapsed time between ticks (4 ticks between published samples):
        # the offline simulator at the published stamps agrees to the integration error
        off = simulate(load_model(None), (stamps - stamps[0]) * 1e-9, 2000.0, 5.0, 40.0)
        np.testing.assert_allclose([m.clutch_torque for m in states], off.torque_nm, rtol=1e-2)
        np.testing.assert_allclose([m.pack_temperature for m in states], off.pack_temperature_c, atol=0.05)
        assert states[0].energy == 0.0 and states[-1].energy > 0.0
        # publish_every 4: published = ticks / 4 over a window (from the node's own counters)
        first = io.wait_status("timing", fqn, lambda s, v: int(v["published"]) > 0)
        second = io.wait_status("timing", fqn, lambda s, v: int(v["ticks"]) >= int(values_of(first)["ticks"]) + 40,
                                timeout=60.0)
        v1, v2 = values_of(first), values_of(second)
        d_ticks = int(v2["ticks"]) - int(v1["ticks"])
        d_pub = int(v2["published"]) - int(v1["published"])
        assert abs(4 * d_pub - d_ticks) <= 4, (d_pub, d_ticks)
        assert float(v2["rate_hz"]) == 200.0
        assert float(values_of(io.node_status("inputs", fqn))["input_timeout_s"]) == 5.0
    finally:
        assert node.stop(signal.SIGTERM) == 0, node.log()


def test_help_and_startup_errors_are_one_line(domain_id):
    env = subprocess_env(domain_id)
    res = subprocess.run([sys.executable, "-m", "clutch_sim_ros.node", "--help"], env=env, cwd=str(REPO),
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0
    for text in ("applied_force", "clutch_state", "/diagnostics", "~/reset", "rate_hz", "frame_id",
                 "use_sim_time", "[1, 10000]", "--ros-args", "--params-file"):
        assert text in res.stdout, text
    for args in (["--ros-args", "--params-file"], ["--ros-args", "--params-file", "/nonexistent/x.yaml"],
                 ["--ros-args", "-p", "publish_every:=0"], ["--bogus"]):
        res = subprocess.run([sys.executable, "-m", "clutch_sim_ros.node", *args], env=env, cwd=str(REPO),
                             capture_output=True, text=True, timeout=60)
        assert res.returncode != 0 and "Traceback" not in res.stderr, args
        assert len(res.stderr.strip().splitlines()) == 1, (args, res.stderr)
