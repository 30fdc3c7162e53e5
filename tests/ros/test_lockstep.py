"""Sim-time lock-step: the node driven by /clock gives the offline simulator's numbers
(clutch_model.plant.simulate / clutch_model.replay.replay_runs) to numerical precision; and
``clutch-sim play --clock --record`` + ``live_replay`` reproduce offline replay of bags."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from .conftest import Io, NodeProcess, StderrLines, stamp_ns, subprocess_env, write_test_bag, REPO

pytestmark = pytest.mark.ros

RTOL, ATOL = 1e-9, 1e-9
T0 = 1_700_000_000_000_000_000


def _lockstep(io: Io, t_ns, force, slip, sump, timeout=60.0, retry_s=1.0):
    """Drive the node one /clock tick at a time; returns the clutch_state of every tick.

    Inputs and /clock are separate topics (the node's /clock subscription is best effort), so
    a tick can reach the node before that tick's inputs, or be lost. A tick counts only when
    the node's state for it echoes the inputs sent; otherwise the inputs and the same clock
    time are sent again after ``retry_s`` -- the node recomputes a repeated time from the
    state before it (idempotent), so a retry gives the numbers of a first delivery."""
    out = []
    for k, t in enumerate(t_ns):
        want = (float(force[k]), float(slip[k]), float(sump[k]))
        got, sent, answers = [], [0], [0]

        def answered():
            while io.states:
                m = io.states.pop(0)
                if stamp_ns(m.header.stamp) == int(t):
                    answers[0] += 1
                    if (m.applied_force, m.slip_speed, m.sump_temperature) == want:
                        got.append(m)
            return bool(got)

        def tick():
            io.send(*want)
            io.clock(int(t))
            sent[0] += 1

        assert io.client.spin_until(answered, timeout, step=tick, step_period=retry_s), \
            f"no clutch_state for tick {k} with its inputs {want}"
        # a retried tick: every /clock sent for it answered before the next tick's inputs go
        # out (a late one would recompute this tick with them); a lost one ends the wait
        io.client.spin_until(lambda: answered() and answers[0] >= sent[0], 10.0)
        out.append(got[-1])
    return out


@pytest.fixture(scope="module")
def sim_node(domain_id, tmp_path_factory):
    node = NodeProcess(domain_id, ["-r", "__ns:=/ls", "-p", "use_sim_time:=true"],
                       tmp_path_factory.mktemp("ls"))
    yield node
    assert node.stop() == 0, node.log()


def test_force_step_lockstep_equals_offline_simulator(client, sim_node):
    from clutch_model import load_model, simulate

    io = Io(client, "/ls")
    io.wait_matched(clock=True)
    n = 300
    t_ns = T0 + np.arange(n, dtype=np.int64) * 2_000_000          # 500 Hz sim clock
    force = np.where(np.arange(n) < 60, 500.0, 4000.0)
    force[220:] = 1200.0                                           # step up, then down
    slip = np.where(np.arange(n) < 180, 8.0, -3.0)                 # sign change
    sump = np.full(n, 60.0)
    states = _lockstep(io, t_ns, force, slip, sump)
    torque = np.array([m.clutch_torque for m in states])
    pack = np.array([m.pack_temperature for m in states])
    assert np.array_equal([m.applied_force for m in states], force)   # inputs echoed exactly

    off = simulate(load_model(None), (t_ns - t_ns[0]) * 1e-9, force, slip, sump)
    np.testing.assert_allclose(torque, off.torque_nm, rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(pack, off.pack_temperature_c, rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose([m.film_thickness for m in states], off.film_thickness_m, rtol=RTOL, atol=1e-15)
    np.testing.assert_allclose([m.energy for m in states], off.energy_j, rtol=RTOL, atol=ATOL)
    assert torque[100] > 5 * torque[30] > 0 and torque[-1] < 0       # the step shows, sign follows slip
    # clutch_torque and pack_temperature topics carry the same samples: published in step
    # with clutch_state, one of each per computed tick (a retried tick is computed again, with
    # the same numbers once its inputs are in: the last sample per stamp is the tick's)
    assert client.spin_until(lambda: len(io.temps) >= n and len(io.torques) == len(io.temps), 30.0)
    last = {stamp_ns(tp.header.stamp): (tq.data, tp.temperature) for tq, tp in zip(io.torques, io.temps)}
    assert sorted(last) == list(t_ns)
    assert np.array_equal([last[t][0] for t in t_ns], torque)
    assert np.array_equal([last[t][1] for t in t_ns], pack)

    # a repeated /clock time recomputes that step from the state before it with the new inputs
    force2 = force.copy()
    force2[-1] = 9000.0
    (redo,) = _lockstep(io, t_ns[-1:], force2[-1:], slip[-1:], sump[-1:])
    off2 = simulate(load_model(None), (t_ns - t_ns[0]) * 1e-9, force2, slip, sump)
    assert redo.clutch_torque == pytest.approx(off2.torque_nm[-1], rel=RTOL)
    assert redo.clutch_torque != pytest.approx(torque[-1], rel=1e-3)

    # a clock that goes backwards restarts the plant (initial film, pack at the sump, energy 0)
    (restart,) = _lockstep(io, [T0 - 1_000_000_000], [2000.0], [4.0], [45.0])
    off3 = simulate(load_model(None), [0.0], [2000.0], [4.0], [45.0])
    assert restart.energy == 0.0 and restart.pack_temperature == 45.0
    assert restart.clutch_torque == pytest.approx(off3.torque_nm[0], rel=RTOL)


def _read_recording(path):
    from rosbags.highlevel import AnyReader

    out = {}
    with AnyReader([path]) as reader:
        for conn, t, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t, reader.deserialize(raw, conn.msgtype)))
    return out


def test_play_clock_and_record_equal_offline_replay(domain_id, tmp_path):
    """clutch-sim play --clock --record (a separate process) against a sim-time node: the
    recorded outputs equal offline replay of the same bags (MCAP dir, sqlite3 dir, bare .mcap,
    one with invalid samples), bag after bag."""
    from clutch_model import load_model
    from clutch_model.replay import replay_runs
    from clutch_model.formats.bag_reader import read_bags

    bags = [write_test_bag(tmp_path / "run_01", 1.5, seed=0, start_ns=T0, bad_samples=True),
            write_test_bag(tmp_path / "run_02", 1.0, seed=1, start_ns=T0 + 60_000_000_000, storage="sqlite3"),
            write_test_bag(tmp_path / "run_03.mcap", 1.0, seed=2, start_ns=T0 + 120_000_000_000)]
    node = NodeProcess(domain_id, ["-r", "__ns:=/rigA", "-p", "use_sim_time:=true"], tmp_path)
    out = tmp_path / "live.mcap"
    try:
        cmd = [sys.executable, "-m", "clutch_sim.cli", "play", "--bag", *map(str, reversed(bags)), "--clock",
               "--namespace", "/rigA", "--record", str(out)]
        res = subprocess.run(cmd, env=subprocess_env(domain_id), cwd=str(REPO), capture_output=True,
                             text=True, timeout=120)
        assert res.returncode == 0, res.stderr + node.log()
        assert "played 3 bag(s)" in res.stdout
    finally:
        assert node.stop() == 0, node.log()

    off = replay_runs(load_model(None), read_bags(bags))
    rec = _read_recording(out)
    states = rec["/rigA/clutch_state"]
    assert len(states) == off.sim.torque_nm.size
    t_log = np.array([t for t, _ in states])
    assert np.array_equal(t_log, [stamp_ns(m.header.stamp) for _, m in states])       # logged at sim time
    rows = np.concatenate([r.start_time_ns + np.round(r.t * 1e9).astype(np.int64) for r in off.campaign.runs])
    assert np.array_equal(t_log, rows)
    np.testing.assert_allclose([m.clutch_torque for _, m in states], off.sim.torque_nm, rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose([m.pack_temperature for _, m in states], off.sim.pack_temperature_c,
                               rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose([m.data for _, m in rec["/rigA/clutch_torque"]], off.sim.torque_nm,
                               rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose([m.temperature for _, m in rec["/rigA/pack_temperature"]],
                               off.sim.pack_temperature_c, rtol=RTOL, atol=ATOL)
    np.testing.assert_array_equal([m.applied_force for _, m in states], off.campaign.force)
    assert "/diagnostics" in rec
    # nothing logged before the data starts (no 1970 log times), nothing after it ends
    all_log = [t for msgs in rec.values() for t, _ in msgs]
    assert min(all_log) >= rows[0] and max(all_log) <= rows[-1]


def test_play_clock_retried_steps_stay_exact(domain_id, tmp_path):
    """A player that gives up waiting after 1 ms sends most steps again while their first
    /clock is still on its way: the late /clock must not recompute a step with the next
    step's inputs (the outputs still equal offline replay, every step)."""
    from clutch_model import load_model
    from clutch_model.replay import replay_runs
    from clutch_model.formats.bag_reader import read_bags
    from clutch_sim_ros.play import play

    bag = write_test_bag(tmp_path / "run_x", 1.0, seed=5, start_ns=T0)
    node = NodeProcess(domain_id, ["-r", "__ns:=/rigX", "-p", "use_sim_time:=true"], tmp_path)
    try:
        res = play([bag], "/rigX", clock=True, progress=False, domain_id=domain_id, ack_timeout_s=0.001,
                   max_attempts=1000)
    finally:
        assert node.stop() == 0, node.log()
    off = replay_runs(load_model(None), read_bags([bag]))
    assert res.retries > 0
    np.testing.assert_allclose(res.bags[0].torque_nm, off.sim.torque_nm, rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(res.bags[0].pack_temperature_c, off.sim.pack_temperature_c, rtol=RTOL, atol=ATOL)


def test_live_replay_returns_offline_rmse(domain_id, tmp_path):
    from clutch_model import load_model
    from clutch_model.replay import replay_runs
    from clutch_model.formats.bag_reader import read_bags
    from clutch_sim_ros.live import live_replay

    bags = [write_test_bag(tmp_path / "run_a", 1.0, seed=3, start_ns=T0),
            write_test_bag(tmp_path / "run_b", 1.0, seed=4, start_ns=T0 + 30_000_000_000)]
    summary = live_replay(bags, "/live", tmp_path / "out" / "live.mcap", domain_id=domain_id, progress=False)
    off = replay_runs(load_model(None), read_bags(bags))
    assert summary["node_exit_code"] == 0
    assert summary["rows"] == off.sim.torque_nm.size
    assert summary["rmse_nm"] == pytest.approx(off.rmse_torque(), rel=1e-9)
    for run, (name, rmse, _, n) in zip(summary["runs"], off.per_run()):
        assert (run["bag"], run["rows"]) == (name, n) and run["rmse_nm"] == pytest.approx(rmse, rel=1e-9)
    rec = _read_recording(tmp_path / "out" / "live.mcap")
    assert len(rec["/live/clutch_state"]) == summary["rows"]


def test_record_process_records_play_clock_losslessly(client, domain_id, tmp_path):
    """`clutch-sim record --use-sim-time` in its own process while `clutch-sim play --clock`
    drives a sim-time node: every step's clutch_state is in the bag (none lost), nothing is
    logged before the data starts (no 1970 log times), and Ctrl-C leaves a complete bag."""
    import signal

    from rosbags.highlevel import AnyReader

    from clutch_sim_ros.record import READY_LINE

    from clutch_model.formats.bag_messages import read_run, row_times_ns

    bag = write_test_bag(tmp_path / "run_r", 2.0, seed=6, start_ns=T0)
    rows = row_times_ns(read_run(bag))
    node = NodeProcess(domain_id, ["-r", "__ns:=/rigR", "-p", "use_sim_time:=true"], tmp_path)
    out = tmp_path / "rec.mcap"
    env = subprocess_env(domain_id)
    rec = subprocess.Popen([sys.executable, "-m", "clutch_sim.cli", "record", "--out", str(out), "--namespace", "/rigR",
                            "--use-sim-time"], env=env, cwd=str(REPO), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True)
    err = StderrLines(rec)    # the recorder's stderr, read as it comes (its ready line is the event)
    data_topics = [f"/rigR/{name}" for name in ("clutch_torque", "pack_temperature", "clutch_state")]

    def recorder_ready():
        # the recorder's own subscriptions matched the node's publishers (its ready line), and
        # the recorder's subscriptions on every output are in the graph (what the node's
        # publishers discover, too)
        return (err.has(READY_LINE)
                and all(client.node.count_subscribers(t) >= 1 and client.node.count_publishers(t) >= 1
                        for t in data_topics))

    try:
        assert client.spin_until(recorder_ready, 120.0), err.text() + node.log()
        play = subprocess.run([sys.executable, "-m", "clutch_sim.cli", "play", "--bag", str(bag), "--clock",
                               "--namespace", "/rigR"], env=env, cwd=str(REPO), capture_output=True, text=True,
                              timeout=300)
        assert play.returncode == 0, play.stderr + node.log()
        client.spin_for(1.0)
        rec.send_signal(signal.SIGINT)
        rec.wait(timeout=60)
        rec_err = err.text(join_timeout_s=10)
    finally:
        if rec.poll() is None:
            rec.kill()
        assert node.stop() == 0, node.log()
    assert rec.returncode == 0 and "Traceback" not in rec_err, rec_err
    with AnyReader([out]) as reader:
        msgs = [(c.topic, t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages()]
    stamps = [stamp_ns(m.header.stamp) for topic, _, m in msgs if topic == "/rigR/clutch_state"]
    assert set(stamps) == set(int(t) for t in rows)                  # every step recorded
    assert sum(1 for topic, _, _ in msgs if topic == "/rigR/clutch_torque") >= len(rows)
    assert min(t for _, t, _ in msgs) >= rows[0]                     # nothing before the data
