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
    """Wait until the node reports (its /diagnostics inputs status) these held inputs: the event
    that the next /clock step uses them."""
    want = {"applied_force.value": force, "sump_temperature.value": SUMP_C,
            "torque_a.value": tau_a, "torque_b.value": tau_b}

    def arrived(_, values):
        return all(k in values and float(values[k]) == v for k, v in want.items())

    st = rig.io.wait_status("inputs", fqn, arrived, timeout=60.0)
    assert st is not None and arrived(st, {kv.key: kv.value for kv in st.values}), \
        f"inputs {want} not reported by the node"


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


def test_rig_over_dds_in_lockstep_equals_offline(client, driveline_node):
    rig = Rig(client)
    fqn = f"{NS}/clutch_sim"
    ready = lambda: (all(p.get_subscription_count() > 0 for p in (rig.io.pf, rig.io.ps, rig.pa, rig.pb,  # noqa: E731
                                                                  rig.io.pclock))
                     and client.node.count_publishers(f"{NS}/speed_b") > 0)
    assert client.spin_until(ready, 60.0), driveline_node.log()

    force, tau_a, tau_b, stamps, states, torques = [], [], [], [], [], []
    k = 0
    for seconds, f, a, b in PHASES:
        rig.send(f, a, b)
        _wait_inputs_arrived(rig, fqn, f, a, b)
        for _ in range(int(round(seconds * 1e9 / DT_NS))):
            t = T0 + k * DT_NS
            rig.io.clock(t)

            def answered():
                return (any(stamp_ns(m.header.stamp) == t for m in rig.io.states)
                        and all(len(v) >= k + 1 for v in rig.out.values()) and len(rig.io.torques) >= k + 1)

            assert client.spin_until(answered, 30.0), f"no outputs for step {k}\n" + driveline_node.log()
            (st,) = [m for m in rig.io.states if stamp_ns(m.header.stamp) == t]
            rig.io.states.clear()
            states.append(st)
            force.append(f), tau_a.append(a), tau_b.append(b), stamps.append(t)
            k += 1
    n = k
    assert all(len(v) == n for v in rig.out.values()) and len(rig.io.torques) == n
    slip = np.array(rig.out["slip_speed"])
    wa, wb = np.array(rig.out["speed_a"]), np.array(rig.out["speed_b"])
    torque = np.array([m.data for m in rig.io.torques])
    locked = np.array([st.locked for st in states])
    force, tau_a, tau_b = np.array(force), np.array(tau_a), np.array(tau_b)
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
