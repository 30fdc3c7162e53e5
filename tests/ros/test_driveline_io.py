"""Driveline mode's ROS pieces (clutch_sim_ros.driveline_io) before they are wired into the
node: parameters, held/stale torques, and a host node with DrivelineTopics stepped in sim-time
lock-step, driven over DDS by a rig client, equal to the offline simulate_driveline."""
from __future__ import annotations

import numpy as np
import pytest

from clutch_model import DrivelineParams, load_model, simulate_driveline
from clutch_model.plant import kernels as K
from clutch_sim_ros import driveline_io as DIO

from .conftest import Client


def test_parameters_map_to_driveline_params_and_reject_bad_values():
    d = DIO.driveline_params({"driveline.inertia_a_kgm2": 2, "driveline.initial_speed_b_rad_s": -3.5})
    assert d == DrivelineParams(inertia_a_kgm2=2.0, initial_speed_b_rad_s=-3.5)
    assert DIO.driveline_params({}) == DrivelineParams()
    with pytest.raises(ValueError, match="inertia_b_kgm2 must be in"):
        DIO.driveline_params({"driveline.inertia_b_kgm2": 0.0})
    with pytest.raises(ValueError, match="damping_a_nms must be a number"):
        DIO.driveline_params({"driveline.damping_a_nms": "x"})
    assert DIO.check_value("slip_source", "driveline") is None
    assert "one of topic, driveline" in DIO.check_value("slip_source", "wheel")
    assert set(DIO.PARAMETER_NAMES) == {"slip_source"} | {f"driveline.{k}" for k in DrivelineParams.__dataclass_fields__}


def test_torques_are_zero_until_they_arrive_held_then_zero_when_stale():
    src = DIO.TorqueInputs()
    ms = 1_000_000
    assert src.held(0, 0.1) == (0.0, 0.0)
    src.torque_a.offer(120.0)
    assert src.held(1 * ms, 0.1) == (120.0, 0.0)
    assert not src.torque_b.offer(float("nan")) and not src.torque_b.offer(2e6)
    assert src.torque_b.rejected == 2
    src.torque_b.offer(-40.0)
    assert src.held(50 * ms, 0.1) == (120.0, -40.0)        # a held, b new
    assert src.held(102 * ms, 0.1) == (0.0, -40.0)         # a stale after 0.1 s
    src.torque_a.offer(80.0)
    assert src.held(103 * ms, 0.1) == (80.0, -40.0)


def test_source_waits_for_force_and_sump_only():
    assert DIO.DrivelineSource.ready(0.0, 60.0)
    assert not DIO.DrivelineSource.ready(None, 60.0) and not DIO.DrivelineSource.ready(100.0, None)


@pytest.mark.ros
def test_lockstep_over_dds_equals_offline(domain_id):
    """A rig client publishes torque_a/torque_b; the host node (DrivelineTopics + DrivelineSource,
    stepped like the node in sim time) publishes slip_speed/speed_a/speed_b; the received samples
    equal simulate_driveline on the same inputs exactly."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64

    rel = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    model = load_model()
    dl = DrivelineParams(0.5, 1.2, 0.05, 0.05, 40.0, 10.0)
    host, rig = Client(domain_id), Client(domain_id)
    try:
        src = DIO.DrivelineSource(model, dl)
        topics = DIO.DrivelineTopics(host.node, src, rel, rel)
        pa = rig.node.create_publisher(Float64, "torque_a", rel)
        pb = rig.node.create_publisher(Float64, "torque_b", rel)
        got = {name: [] for name in DIO.OUTPUT_TOPICS}
        for name in DIO.OUTPUT_TOPICS:
            rig.node.create_subscription(Float64, name, lambda m, n=name: got[n].append(m.data), rel)

        def matched():
            host.executor.spin_once(timeout_sec=0.0)
            return (pa.get_subscription_count() and pb.get_subscription_count()
                    and all(p.get_subscription_count() for p in topics.publishers))

        assert rig.spin_until(matched, 20.0), "host and rig did not discover each other"
        n, dt = 400, 0.002
        t = np.arange(n) * dt
        force = np.where(t < 0.1, 0.0, 5000.0)
        force[t > 0.5] = 300.0
        tau_a = 200.0 + 50 * np.sin(2 * np.pi * t / 0.3)
        tau_b = np.full(n, -80.0)
        for k in range(n):
            pa.publish(Float64(data=float(tau_a[k])))
            pb.publish(Float64(data=float(tau_b[k])))
            arrived = lambda: (src.torques.torque_a.value == tau_a[k]  # noqa: E731
                               and src.torques.torque_b.value == tau_b[k])
            assert host.spin_until(arrived, 5.0), f"torques of tick {k} not received"
            now_ns = int(round(t[k] * 1e9))
            if k == 0:
                src.reset(force[0], 60.0)
            else:
                src.advance(t[k] - t[k - 1])   # the offline grid's steps
            topics.publish(src.sample(force[k], 60.0, now_ns, 1.0))
        assert rig.spin_until(lambda: all(len(v) == n for v in got.values()), 10.0)
        off = simulate_driveline(model, t, force, tau_a, tau_b, 60.0, dl)
        assert np.array_equal(got["slip_speed"], off.slip_speed_rad_s)
        assert np.array_equal(got["speed_a"], off.speed_a_rad_s)
        assert np.array_equal(got["speed_b"], off.speed_b_rad_s)
        assert off.locked.any() and (~off.locked).any()      # both phases went over the wire
        L = off.angular_momentum_nms
        assert L[-1] != L[0]
    finally:
        rig.close()
        host.close()


def test_rig_sequence_through_the_node_path():
    """The rig checks of the issue on DrivelineSource, stepped as the node steps (1 kHz, held
    inputs): open clutch keeps the speeds apart; force locks the sides and they stay locked; a
    torque while locked accelerates both together with the clutch carrying the inertia-weighted
    share; less force lets them break loose; momentum balances throughout (no losses)."""
    ja, jb = 0.5, 1.2
    src = DIO.DrivelineSource(load_model(), DrivelineParams(ja, jb, 0.0, 0.0, 30.0, 10.0))
    dt, ms = 0.001, 1_000_000
    log = []
    impulse = 0.0
    tau_prev = 0.0

    def run(seconds, force, tau_a):
        nonlocal impulse, tau_prev
        for _ in range(int(round(seconds / dt))):
            k = len(log)
            if k == 0:
                src.reset(force, 60.0)
            else:
                src.advance(dt)
                impulse += tau_prev * dt
            if tau_a is not None:
                src.torques.torque_a.offer(tau_a)
            rec = src.sample(force, 60.0, k * ms, 10.0)
            tau_prev = src.last_torques[0] + src.last_torques[1]
            slip, wa, wb = DIO.DrivelineSource.outputs(rec)
            log.append((slip, wa, wb, rec[K.O_TORQUE], bool(rec[K.O_LOCKED]), ja * wa + jb * wb - impulse))

    run(0.5, 0.0, None)                                   # open clutch, no torques
    open_phase = np.array(log)
    assert np.all(open_phase[:, 0] > 19.0) and not open_phase[:, 4].any()
    run(1.5, 6000.0, None)                                # press: locks and stays locked
    locked_from = next(i for i, row in enumerate(log) if row[4])
    assert all(row[4] and row[0] == 0.0 for row in log[locked_from:])
    n0 = len(log)
    run(0.5, 6000.0, 300.0)                               # torque on side a while locked
    phase = np.array(log[n0 + 1:])
    assert phase[:, 4].all()
    np.testing.assert_allclose(np.diff(phase[:, 1]) / dt, 300.0 / (ja + jb), rtol=1e-9)
    np.testing.assert_allclose(phase[:, 3], jb * 300.0 / (ja + jb), rtol=1e-12)
    n1 = len(log)
    run(1.0, 300.0, 300.0)                                # less force: breaks loose
    assert not log[-1][4] and log[-1][0] > 0.0
    assert any(row[4] for row in log[n1:n1 + 5]) and not all(row[4] for row in log[n1:])
    momentum = np.array([row[5] for row in log])
    np.testing.assert_allclose(momentum, momentum[0], rtol=1e-12)


def test_parameter_changes_keep_the_state():
    model = load_model()
    src = DIO.DrivelineSource(model, DrivelineParams(0.5, 1.2, 0.0, 0.0, 30.0, 10.0))
    src.reset(0.0, 60.0)
    src.torques.torque_a.offer(100.0)
    src.sample(0.0, 60.0, 0, 1.0)
    src.advance(0.01)
    before = src.state.copy()
    src.set_driveline(DrivelineParams(2.0, 1.2, 0.0, 0.0, 0.0, 0.0))
    np.testing.assert_array_equal(src.state, before)            # speeds kept, initial speeds unused
    drag = src.sample(0.0, 60.0, 10_000_000, 1.0)[K.O_TORQUE]        # open clutch: viscous drag only
    src.advance(0.01)
    # side a now accelerates at (100 N m - drag) / 2 kg m^2
    accel = (src.plant.speed_a_rad_s - before[src.plant.state.size - 3]) / 0.01
    assert 0.0 < drag < 5.0 and accel == pytest.approx((100.0 - drag) / 2.0, rel=1e-3)
    src.set_model(model.with_lock_slip(0.01))
    assert src.plant.speed_a_rad_s == src.state[src.state.size - 3]
    src.reset(0.0, 60.0)
    assert src.plant.speed_a_rad_s == 0.0 and src.plant.locked          # new initial speeds at reset
