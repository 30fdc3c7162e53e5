"""The node in driveline mode (``slip_source: driveline``) as its own process, driven over DDS by
an independent rig client in sim-time lock-step (the test publishes /clock and waits for each
step's outputs; no wall-clock assertion): open clutch keeps the speeds apart; a force locks the
sides and they stay locked; a torque while locked accelerates both sides together with the
clutch carrying (J_b*tau_a - J_a*tau_b)/(J_a + J_b); less force lets them break loose; momentum
balances; the node publishes slip_speed and does not subscribe to it; the run equals offline
simulate_driveline."""
from __future__ import annotations

import numpy as np
import pytest

from clutch_model import DrivelineParams, load_model, simulate_driveline

from .conftest import Io, NodeProcess, stamp_ns

pytestmark = pytest.mark.ros

NS = "/dlrig"
T0 = 1_700_000_000_000_000_000
DT_NS = 2_000_000
JA, JB = 0.5, 1.2
SUMP_C = 60.0
# (seconds, applied force N, torque_a N m, torque_b N m): open, press (locks), torque while
# locked, less force (breaks loose)
PHASES = ((0.3, 0.0, 0.0, 0.0), (1.0, 6000.0, 0.0, 0.0), (0.5, 6000.0, 300.0, -50.0),
          (0.6, 300.0, 300.0, -50.0))


class Rig:
    """The rig client: publishers of force, sump, torques and /clock; collectors of the node's
    outputs (clutch_state, clutch_torque via Io; slip_speed, speed_a, speed_b here)."""

    def __init__(self, client):
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from std_msgs.msg import Float64

        rel = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.io = Io(client, NS)
        self.Float64 = Float64
        self.pa = client.node.create_publisher(Float64, f"{NS}/torque_a", rel)
        self.pb = client.node.create_publisher(Float64, f"{NS}/torque_b", rel)
        self.out = {name: [] for name in ("slip_speed", "speed_a", "speed_b")}
        for name, store in self.out.items():
            client.node.create_subscription(Float64, f"{NS}/{name}", lambda m, s=store: s.append(m.data), rel)

    def send(self, force, tau_a, tau_b) -> None:
        self.io.send(force=force, sump=SUMP_C)
        self.pa.publish(self.Float64(data=float(tau_a)))
        self.pb.publish(self.Float64(data=float(tau_b)))


def _wait_inputs_arrived(rig: Rig, fqn: str, force, tau_a, tau_b) -> None:
    """Send the held inputs (again every 0.1 s: the node's inputs are best effort) until the node
    reports them on /diagnostics (inputs status): the event that the next /clock step uses them."""
    from clutch_sim_ros.diagnostics import values_of

    want = {"applied_force.value": force, "sump_temperature.value": SUMP_C,
            "torque_a.value": tau_a, "torque_b.value": tau_b}

    def arrived():
        st = rig.io.node_status("inputs", fqn)
        values = values_of(st) if st is not None else {}
        return all(k in values and float(values[k]) == v for k, v in want.items())

    rig.io.diags.clear()
    assert rig.io.client.spin_until(arrived, 60.0, step=lambda: rig.send(force, tau_a, tau_b), step_period=0.1), \
        f"inputs {want} not reported by the node"


def _lockstep(client, rig: Rig, node, fqn: str, phases, k0: int) -> dict:
    """Drive the node through ``phases`` one /clock step (DT_NS) at a time from step ``k0``:
    the inputs of a phase are sent and seen arrived (held), then each step's outputs awaited."""
    for v in rig.out.values():
        v.clear()
    rig.io.torques.clear()
    rig.io.states.clear()
    force, tau_a, tau_b, stamps, states = [], [], [], [], []
    k = 0
    for seconds, f, a, b in phases:
        _wait_inputs_arrived(rig, fqn, f, a, b)
        for _ in range(int(round(seconds * 1e9 / DT_NS))):
            t = T0 + (k0 + k) * DT_NS
            rig.io.clock(t)

            def answered():
                return (any(stamp_ns(m.header.stamp) == t for m in rig.io.states)
                        and all(len(v) >= k + 1 for v in rig.out.values()) and len(rig.io.torques) >= k + 1)

            assert client.spin_until(answered, 30.0), f"no outputs for step {k0 + k}\n" + node.log()
            (st,) = [m for m in rig.io.states if stamp_ns(m.header.stamp) == t]
            rig.io.states.clear()
            states.append(st)
            force.append(f), tau_a.append(a), tau_b.append(b), stamps.append(t)
            k += 1
    return {"force": np.array(force), "tau_a": np.array(tau_a), "tau_b": np.array(tau_b), "stamps": stamps,
            "states": states}


@pytest.fixture(scope="module")
def driveline_node(client, domain_id, tmp_path_factory):
    node = NodeProcess(domain_id, ["-r", f"__ns:={NS}", "-p", "use_sim_time:=true", "-p", "slip_source:=driveline",
                                   "-p", f"driveline.inertia_a_kgm2:={JA}", "-p", f"driveline.inertia_b_kgm2:={JB}",
                                   "-p", "driveline.damping_a_nms:=0.0", "-p", "driveline.damping_b_nms:=0.0",
                                   "-p", "driveline.initial_speed_a_rad_s:=30.0",
                                   "-p", "driveline.initial_speed_b_rad_s:=10.0",
                                   "-p", "input_timeout_s:=3600.0"], tmp_path_factory.mktemp("dl"))
    yield node
    assert node.stop() == 0, node.log()


def test_node_publishes_slip_speed_and_does_not_subscribe_to_it(client, driveline_node):
    node = client.node
    subs_of_node, pubs_of_node = set(), set()

    def discovered():   # the node's endpoints, inputs and outputs, are in the graph by node name
        try:
            subs_of_node.update(t for t, _ in node.get_subscriber_names_and_types_by_node("clutch_sim", NS))
            pubs_of_node.update(t for t, _ in node.get_publisher_names_and_types_by_node("clutch_sim", NS))
        except Exception:   # the node itself not discovered yet
            return False
        return ({f"{NS}/{t}" for t in ("applied_force", "sump_temperature", "torque_a", "torque_b")} <= subs_of_node
                and {f"{NS}/{t}" for t in ("clutch_state", "slip_speed", "speed_a", "speed_b")} <= pubs_of_node)

    assert client.spin_until(discovered, 60.0), driveline_node.log()
    assert f"{NS}/slip_speed" not in subs_of_node
    assert node.count_subscribers(f"{NS}/slip_speed") == 0      # nobody subscribes, the node neither
    assert node.count_publishers(f"{NS}/slip_speed") == 1


@pytest.fixture(scope="module")
def rig(client, driveline_node):
    r = Rig(client)
    ready = lambda: (all(p.get_subscription_count() > 0 for p in (r.io.pf, r.io.ps, r.pa, r.pb,  # noqa: E731
                                                                  r.io.pclock))
                     and client.node.count_publishers(f"{NS}/speed_b") > 0)
    assert client.spin_until(ready, 60.0), driveline_node.log()
    return r


def test_rig_over_dds_in_lockstep_equals_offline(client, driveline_node, rig):
    fqn = f"{NS}/clutch_sim"

    run = _lockstep(client, rig, driveline_node, fqn, PHASES, 0)
    force, tau_a, tau_b, stamps, states = run["force"], run["tau_a"], run["tau_b"], run["stamps"], run["states"]
    k = len(stamps)
    n = k
    assert all(len(v) == n for v in rig.out.values()) and len(rig.io.torques) == n
    slip = np.array(rig.out["slip_speed"])
    wa, wb = np.array(rig.out["speed_a"]), np.array(rig.out["speed_b"])
    torque = np.array([m.data for m in rig.io.torques])
    locked = np.array([st.locked for st in states])
    # clutch_state carries the inputs the plant used and the plant's slip
    np.testing.assert_array_equal([st.applied_force for st in states], force)
    np.testing.assert_array_equal([st.slip_speed for st in states], slip)
    np.testing.assert_array_equal([st.clutch_torque for st in states], torque)
    np.testing.assert_array_equal(slip, wa - wb)
    dt = DT_NS * 1e-9
    bounds = np.cumsum([0] + [int(round(p[0] * 1e9 / DT_NS)) for p in PHASES])
    open_, press, drive, release = (slice(bounds[i], bounds[i + 1]) for i in range(4))

    # open clutch: the speeds stay apart (drag only), not locked
    assert np.all(slip[open_] > 19.0) and not locked[open_].any()
    # force: the sides lock and stay locked, slip exactly 0
    lock_at = bounds[1] + int(np.argmax(locked[press]))
    assert locked[lock_at] and lock_at < bounds[2] - 50
    assert locked[lock_at:bounds[3]].all() and np.all(slip[lock_at:bounds[3]] == 0.0)
    # torque while locked: both accelerate at (tau_a + tau_b)/(J_a + J_b); the clutch carries
    # the inertia-weighted share (no losses)
    d = slice(bounds[2] + 1, bounds[3])
    np.testing.assert_allclose(np.diff(wa[d]) / dt, (300.0 - 50.0) / (JA + JB), rtol=1e-9)
    np.testing.assert_allclose(np.diff(wb[d]) / dt, (300.0 - 50.0) / (JA + JB), rtol=1e-9)
    np.testing.assert_allclose(torque[d], (JB * 300.0 - JA * -50.0) / (JA + JB), rtol=1e-12)
    # less force: they break loose (side a driven ahead) and stay apart
    assert not locked[release][-1] and slip[release][-1] > 1.0
    loose_at = bounds[3] + int(np.argmin(locked[release]))
    assert not locked[loose_at:].any()
    # momentum balance: J_a w_a + J_b w_b changes by the torques' impulse (held inputs)
    impulse = np.concatenate([[0.0], np.cumsum((tau_a + tau_b)[:-1] * dt)])
    momentum = JA * wa + JB * wb - impulse
    np.testing.assert_allclose(momentum, momentum[0], rtol=1e-12, atol=1e-9)
    # live equals offline on the same inputs and the same steps
    t = (np.array(stamps) - T0) * 1e-9
    off = simulate_driveline(load_model(), t, force, tau_a, tau_b, SUMP_C,
                             DrivelineParams(JA, JB, 0.0, 0.0, 30.0, 10.0))
    np.testing.assert_array_equal(locked, off.locked)
    for live, ref in ((slip, off.slip_speed_rad_s), (wa, off.speed_a_rad_s), (wb, off.speed_b_rad_s),
                      (torque, off.clutch_torque_nm),
                      (np.array([st.pack_temperature for st in states]), off.pack_temperature_c)):
        np.testing.assert_allclose(live, ref, rtol=1e-9, atol=1e-9)
    # and the graph: still no subscription of the node's to slip_speed (only this rig's)
    node_subs = [t for t, _ in client.node.get_subscriber_names_and_types_by_node("clutch_sim", NS)]
    assert f"{NS}/torque_a" in node_subs and f"{NS}/slip_speed" not in node_subs
    assert client.node.count_subscribers(f"{NS}/slip_speed") == 1       # the rig's own


def _set(client, name: str, value):
    """Set one parameter of the node over its parameter service -> SetParametersResult."""
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    pc = AsyncParameterClient(client.node, f"{NS}/clutch_sim")
    assert client.spin_until(lambda: pc.services_are_ready(), 30.0)
    future = pc.set_parameters([Parameter(name, value=value)])
    assert client.spin_until(future.done, 30.0)
    (result,) = future.result().results
    return result


def _reset(client) -> None:
    from std_srvs.srv import Trigger

    cli = client.node.create_client(Trigger, f"{NS}/clutch_sim/reset")
    assert client.spin_until(cli.service_is_ready, 30.0)
    future = cli.call_async(Trigger.Request())
    assert client.spin_until(future.done, 30.0) and future.result().success
    client.node.destroy_client(cli)


def test_runtime_driveline_and_slip_source_changes(client, driveline_node, rig):
    """Bad values are refused with a reason; new inertias and initial speeds apply (from ~/reset:
    the run then equals offline with the new driveline); slip_source topic restarts the plant
    with slip_speed subscribed, driveline again unsubscribes it."""
    fqn = f"{NS}/clutch_sim"
    bad = _set(client, "driveline.inertia_a_kgm2", 0.0)
    assert not bad.successful and "inertia_a_kgm2" in bad.reason and "range" in bad.reason   # descriptor range
    bad = _set(client, "slip_source", "wheel")
    assert not bad.successful and "one of topic, driveline" in bad.reason
    for name, value in (("driveline.inertia_a_kgm2", 1.0), ("driveline.initial_speed_a_rad_s", 20.0),
                        ("driveline.initial_speed_b_rad_s", 5.0)):
        assert _set(client, name, value).successful
    _reset(client)
    k0 = 10_000                                   # /clock keeps going forward
    phases = ((0.6, 6000.0, 0.0, 0.0), (0.2, 6000.0, 300.0, -50.0))
    run = _lockstep(client, rig, driveline_node, fqn, phases, k0)
    wa, wb = np.array(rig.out["speed_a"]), np.array(rig.out["speed_b"])
    assert (wa[0], wb[0]) == (20.0, 5.0)          # the new initial speeds at the restart
    t = (np.array(run["stamps"]) - run["stamps"][0]) * 1e-9
    off = simulate_driveline(load_model(), t, run["force"], run["tau_a"], run["tau_b"], SUMP_C,
                             DrivelineParams(1.0, JB, 0.0, 0.0, 20.0, 5.0))
    np.testing.assert_allclose(wa, off.speed_a_rad_s, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(wb, off.speed_b_rad_s, rtol=1e-9, atol=1e-9)
    assert off.locked[-1] and run["states"][-1].locked
    assert run["states"][-1].clutch_torque == pytest.approx((JB * 300.0 + 1.0 * 50.0) / (1.0 + JB), rel=1e-12)

    def node_subscribes_slip(want: bool):
        def check():
            try:
                topics = {t for t, _ in client.node.get_subscriber_names_and_types_by_node("clutch_sim", NS)}
            except Exception:
                return False
            return (f"{NS}/slip_speed" in topics) == want and (f"{NS}/torque_a" in topics) != want
        return check

    assert _set(client, "slip_source", "topic").successful
    k1 = k0 + len(t) + 10

    def tick(k):
        def step():   # the switch happens at a tick; a repeated /clock time is an idempotent redo
            rig.io.send(force=2000.0, slip=7.5, sump=SUMP_C)
            rig.io.clock(T0 + k * DT_NS)
        return step

    assert client.spin_until(node_subscribes_slip(True), 60.0, step=tick(k1), step_period=0.2), driveline_node.log()
    t_j = T0 + (k1 + 1) * DT_NS
    rig.io.states.clear()
    got = []

    def answered():   # open loop again: clutch_state carries the slip_speed input
        got.extend(m for m in rig.io.states if stamp_ns(m.header.stamp) == t_j and m.slip_speed == 7.5)
        rig.io.states.clear()
        return bool(got)

    assert client.spin_until(answered, 60.0, step=tick(k1 + 1), step_period=0.2), driveline_node.log()
    assert got[-1].applied_force == 2000.0 and not got[-1].locked
    assert _set(client, "slip_source", "driveline").successful
    assert client.spin_until(node_subscribes_slip(False), 60.0, step=tick(k1 + 2), step_period=0.2), \
        driveline_node.log()
