"""Pieces of clutch_sim_ros without a running graph: input validity, parameters, diagnostics,
the rosbags typestore and the MCAP output."""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.ros


def test_input_validity_rules():
    from clutch_model.plant.inputs import valid_force, valid_slip, valid_sump

    assert valid_force(0.0) and valid_force(-500.0) and valid_force(1e6)
    assert not any(valid_force(x) for x in (math.nan, math.inf, -math.inf, 1e6 + 1))
    assert valid_slip(-1000.0) and valid_slip(1000.0) and valid_slip(0.0)
    assert not any(valid_slip(x) for x in (math.nan, 1000.001, -1000.001, math.inf))
    assert valid_sump(-40.0) and valid_sump(200.0)
    assert not any(valid_sump(x) for x in (-40.01, 200.01, math.nan))


def test_input_channel_holds_last_good_value_and_goes_stale():
    from clutch_model.plant.inputs import InputChannel

    ch = InputChannel("applied_force")
    assert ch.value is None and ch.is_stale(0, 0.1)
    assert ch.offer(100.0)
    ch.on_tick(1_000_000_000)
    assert not ch.offer(math.nan) and not ch.offer(2e6)
    ch.on_tick(1_050_000_000)          # rejected messages do not refresh
    assert ch.value == 100.0 and (ch.received, ch.rejected) == (3, 2)
    assert ch.age_s(1_050_000_000) == pytest.approx(0.05)
    assert not ch.is_stale(1_050_000_000, 0.1) and ch.is_stale(1_200_000_000, 0.1)
    assert ch.offer(-50.0)             # negative force is valid
    ch.on_tick(1_300_000_000)
    assert ch.value == -50.0 and not ch.is_stale(1_300_000_000, 0.1)


def test_parameter_defaults_and_ranges():
    from clutch_sim_ros.params import SPEC, NodeParams, check, check_change, descriptor

    assert {s.name: s.default for s in SPEC} == {
        "rate_hz": 1000.0, "publish_every": 1, "clutch_params_file": "", "input_timeout_s": 0.1,
        "lock_slip_rad_s": 0.001, "frame_id": "clutch", "use_sim_time": False, "slip_source": "topic",
        "driveline.inertia_a_kgm2": 0.5, "driveline.inertia_b_kgm2": 1.2, "driveline.damping_a_nms": 0.05,
        "driveline.damping_b_nms": 0.05, "driveline.initial_speed_a_rad_s": 0.0,
        "driveline.initial_speed_b_rad_s": 0.0}
    assert "one of topic, driveline" in check_change("slip_source", "wheel")
    assert "[1e-06, 1e+06]" in check_change("driveline.inertia_b_kgm2", 0.0)
    assert NodeParams().with_value("driveline.inertia_a_kgm2", 2).driveline().inertia_a_kgm2 == 2.0
    check(NodeParams())
    for bad in (dict(rate_hz=0.0), dict(rate_hz=math.nan), dict(publish_every=0),
                dict(input_timeout_s=-1.0), dict(lock_slip_rad_s=-0.1)):
        with pytest.raises(ValueError):
            check(NodeParams(**bad))
    assert check_change("rate_hz", 500) is None                  # integers accepted for floats
    assert "number" in check_change("rate_hz", "fast") and "[1, 10000]" in check_change("rate_hz", 2e4)
    assert "integer" in check_change("publish_every", 2.5)
    # every numeric parameter carries its range in the descriptor
    for s in SPEC:
        if s.kind is float:
            (r,) = descriptor(s).floating_point_range
            assert (r.from_value, r.to_value) == s.range and descriptor(s).dynamic_typing
        elif s.kind is int:
            (r,) = descriptor(s).integer_range
            assert (r.from_value, r.to_value) == s.range


def test_diagnostics_levels():
    from diagnostic_msgs.msg import DiagnosticStatus as S

    from clutch_sim_ros import diagnostics as D
    from clutch_model.plant.inputs import InputChannel

    chans = [InputChannel(n) for n in ("applied_force", "slip_speed", "sump_temperature")]
    st = D.inputs_status("/n", "/n", chans, 0, 0.1, {})
    assert st.level == S.ERROR and "no applied_force yet" in st.message
    for ch, v in zip(chans, (1000.0, 5.0, 60.0)):
        ch.offer(v)
        ch.on_tick(0)
    st = D.inputs_status("/n", "/n", chans, 50_000_000, 0.1, {})
    assert st.level == S.OK
    st = D.inputs_status("/n", "/n", chans, 500_000_000, 0.1, {})
    assert st.level == S.WARN and "counts as 0 N" in st.message
    st = D.inputs_status("/n", "/n", chans, 1_500_000_000, 0.1, {})
    assert st.level == S.ERROR
    chans[1].offer(math.nan)
    chans[1].on_tick(1_500_000_000)
    for ch in chans:
        ch.on_tick(1_500_000_000)
    st = D.inputs_status("/n", "/n", chans, 1_500_000_000, 0.1, {"slip_speed": 0})
    vals = D.values_of(st)
    assert vals["slip_speed.rejected"] == "1" and vals["slip_speed.rejected_recent"] == "1"


def test_typestore_hash_matches_compiled_interface():
    from clutch_model.formats.typestore import CLUTCH_STATE, typestore

    ts = typestore()
    share = Path(sys.prefix) / "share" / "clutch_msgs" / "msg" / "ClutchState.json"
    if not share.is_file():
        pytest.skip("clutch_msgs not installed in this prefix")
    compiled = json.loads(share.read_text())["type_hashes"][0]["hash_string"]
    assert ts.hash_rihs01(CLUTCH_STATE) == compiled
    names = [f[0] for f in ts.fielddefs[CLUTCH_STATE][1]]
    assert names == ["header", "applied_force", "pack_force", "slip_speed", "sump_temperature",
                     "clutch_torque", "asperity_torque", "hydrodynamic_torque", "friction_coefficient",
                     "film_thickness", "pack_temperature", "viscosity", "power", "energy", "locked"]


def test_rclpy_cdr_decodes_with_typestore_and_mcap_roundtrip(tmp_path):
    """A ClutchState serialized by rclpy is written raw to a bare .mcap and read back by
    rosbags (AnyReader) and by mcap_ros2 without ROS."""
    from clutch_msgs.msg import ClutchState
    from rclpy.serialization import serialize_message

    from clutch_model.errors import DataError
    from clutch_model.formats.typestore import typestore
    from clutch_sim_ros.record import McapOut

    msg = ClutchState(applied_force=1234.5, pack_force=1200.0, slip_speed=-3.25, sump_temperature=61.0,
                      clutch_torque=-456.75, energy=12.5, locked=True)
    msg.header.stamp.sec, msg.header.stamp.nanosec = 17, 250
    data = serialize_message(msg)
    decoded = typestore().deserialize_cdr(data, "clutch_msgs/msg/ClutchState")
    assert (decoded.applied_force, decoded.clutch_torque, decoded.locked) == (1234.5, -456.75, True)

    out = tmp_path / "rec.mcap"
    bag = McapOut(out)
    conn = bag.writer.add_connection("/clutch/clutch_state", "clutch_msgs/msg/ClutchState", typestore=typestore())
    bag.writer.write(conn, 17_000_000_250, data)
    assert bag.close() == out and out.is_file() and not any(p.name.startswith(".rec") for p in tmp_path.iterdir())

    from rosbags.highlevel import AnyReader

    with AnyReader([out]) as reader:
        (c, t, raw), = list(reader.messages())
        m = reader.deserialize(raw, c.msgtype)
    assert t == 17_000_000_250 and m.slip_speed == -3.25 and m.header.stamp.nanosec == 250

    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(out, "rb") as fh:
        (schema, channel, message, ros_msg), = list(make_reader(fh, decoder_factories=[DecoderFactory()])
                                                    .iter_decoded_messages())
    assert schema.name == "clutch_msgs/msg/ClutchState" and ros_msg.energy == 12.5
    assert ros_msg.clutch_torque == -456.75 and ros_msg.locked is True and ros_msg.header.stamp.sec == 17

    # never overwritten unless asked: a clear DataError, the recording untouched, no temp left
    before = out.read_bytes()
    with pytest.raises(DataError, match="exists already"):
        McapOut(out)
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.mcap"]
    # asked: replaced by the new recording, which reads back with its own message only
    bag = McapOut(out, overwrite=True)
    conn = bag.writer.add_connection("/clutch/clutch_state", "clutch_msgs/msg/ClutchState", typestore=typestore())
    bag.writer.write(conn, 99_000_000_000, data)
    bag.close()
    with AnyReader([out]) as reader:
        assert [t for _, t, _ in reader.messages()] == [99_000_000_000]


def test_bag_reading_for_play(tmp_path):
    from clutch_model.formats.bag_messages import read_messages, read_run, row_times_ns

    from .conftest import write_test_bag

    bag = write_test_bag(tmp_path / "run_x", seconds=1.0, bad_samples=True)
    msgs = read_messages(bag)
    assert [m.t_ns for m in msgs.messages] == sorted(m.t_ns for m in msgs.messages)
    assert sum(1 for m in msgs.messages if m.topic == "applied_force") == 100
    assert any(math.isnan(m.value) for m in msgs.messages)        # real-time play sends them as is
    run = read_run(bag)
    t = row_times_ns(run)
    assert np.all(np.diff(t) > 0) and np.all(np.isfinite(run.applied_force_n))
    assert t[0] >= max(next(m.t_ns for m in msgs.messages if m.topic == n)
                       for n in ("applied_force", "slip_speed", "sump_temperature"))


def test_lockstep_recording_keeps_the_last_answer_per_sim_time():
    """A retried lock-step tick is answered twice at the same sim time (first with stale
    inputs or late); the recording keeps the later answer, each topic's messages in order,
    and releases a message only once its topic moves to a later time (or at the end)."""
    from clutch_sim_ros.record import LatestPerLogTime

    held = LatestPerLogTime()
    written = []

    def put(topic, item, t):
        released = held.put(topic, item, t)
        if released is not None:
            written.append(released)

    put("state", "s10-stale", 10)
    put("torque", "q10-stale", 10)
    put("state", "s10", 10)            # the retry's answer supersedes
    put("torque", "q10", 10)
    assert written == [] and held.superseded == 2
    put("state", "s20", 20)            # a later time releases the last answer of the earlier one
    assert written == ["s10"]
    put("torque", "q20", 20)
    assert written == ["s10", "q10"]
    assert held.is_new("state", 30) and not held.is_new("state", 20)
    written.extend(held.drain())
    assert written == ["s10", "q10", "s20", "q20"] and held.drain() == []


def test_a_reset_whose_response_is_lost_is_sent_again():
    """``Player.reset_node``: a ~/reset response lost on the way (sent before the server matched
    the client's response reader) is asked for again; one that never comes is a clear
    PlayError after the deadline, and a refused reset says why."""
    from clutch_sim_ros.play import Player, PlayError

    class Future:
        def __init__(self, answer):
            self.answer = answer

        def done(self):
            return self.answer is not None

        def result(self):
            return self.answer

    class Response:
        def __init__(self, success, message=""):
            self.success, self.message = success, message

    class Client:
        def __init__(self, answers):
            self.answers, self.calls, self.removed = list(answers), 0, 0

        def wait_for_service(self, timeout_sec):
            return True

        def call_async(self, request):
            self.calls += 1
            return Future(self.answers.pop(0) if self.answers else None)

        def remove_pending_request(self, future):
            self.removed += 1

    class Trigger:
        Request = object

    def player(answers):
        p = object.__new__(Player)
        p._reset_client, p._Trigger, p.ns, p.clock_mode = Client(answers), Trigger, "/rig", True
        p._spin_until = lambda done, timeout_s: done()
        return p

    p = player([None, None, Response(True)])                  # two responses lost, the third comes
    assert p.reset_node(timeout_s=5.0, attempt_s=0.0) is True
    assert p._reset_client.calls == 3 and p._reset_client.removed == 2
    with pytest.raises(PlayError, match="did not answer within 0.01 s"):
        player([]).reset_node(timeout_s=0.01, attempt_s=0.0)
    with pytest.raises(PlayError, match="reset failed: busy"):
        player([Response(False, "busy")]).reset_node()
