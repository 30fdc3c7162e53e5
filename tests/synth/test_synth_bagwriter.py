"""Car-test bag writer: rosbag2 MCAP/sqlite3 directories and bare .mcap files, read back
with rosbags and decoded with mcap + mcap_ros2 (no ROS)."""
from pathlib import Path

import numpy as np
import pytest

from clutch_model.formats.bag_writer import DEFAULT_TOPICS, RunSignals, TopicSeries, write_run_bag
from clutch_model.errors import DataError

START = 1_700_000_000_123_000_000


def _signals(seed=0, pack=True):
    rng = np.random.default_rng(seed)
    t = np.arange(400) / 200.0
    tt = np.arange(20) / 10.0 + 0.0004          # own time stamps, not aligned with the 200 Hz grid
    tq = np.arange(380) / 190.0 + 0.0013
    return RunSignals(
        applied_force=TopicSeries(t, rng.normal(5000, 2000, t.size)),
        slip_speed=TopicSeries(t, rng.normal(5, 1, t.size)),
        sump_temperature=TopicSeries(tt, rng.normal(60, 0.3, tt.size), variance=0.09),
        measured_torque=TopicSeries(tq, rng.normal(500, 100, tq.size)),
        pack_temperature=TopicSeries(tt, rng.normal(80, 0.3, tt.size), variance=0.09) if pack else None)


def _expected(sig):
    out = {}
    for key, ser in sig.channels().items():
        ns = START + np.round(ser.t_s * 1e9).astype(np.int64)
        out[DEFAULT_TOPICS[key]] = (ns, ser.values, ser.variance)
    return out


def _read_anyreader(path):
    from rosbags.highlevel import AnyReader

    got = {}
    with AnyReader([Path(path)]) as reader:
        for conn, ts, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.msgtype == "sensor_msgs/msg/Temperature":
                stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                assert stamp == ts
                val, var = msg.temperature, msg.variance
            else:
                assert conn.msgtype == "std_msgs/msg/Float64"
                val, var = msg.data, 0.0
            got.setdefault(conn.topic, ([], [], set()))
            got[conn.topic][0].append(ts)
            got[conn.topic][1].append(val)
            got[conn.topic][2].add(var)
    return got


def _assert_equal(got, expected):
    assert set(got) == set(expected)
    for topic, (ns, vals, var) in expected.items():
        np.testing.assert_array_equal(np.asarray(got[topic][0]), ns)
        np.testing.assert_array_equal(np.asarray(got[topic][1]), vals)
        assert got[topic][2] == {var}


@pytest.mark.parametrize("storage, compression", [("mcap", "none"), ("mcap", "lz4"), ("sqlite3", "none")])
def test_bag_dir_round_trip(tmp_path, storage, compression):
    sig = _signals()
    path = write_run_bag(tmp_path / "run_a", sig, storage=storage, start_time_ns=START,
                         compression=compression)
    assert (path / "metadata.yaml").is_file()
    _assert_equal(_read_anyreader(path), _expected(sig))


def test_optional_topics_and_dict_input(tmp_path):
    sig = _signals(pack=False)
    raw = {"applied_force": (sig.applied_force.t_s, sig.applied_force.values),
           "slip_speed": sig.slip_speed, "sump_temperature": sig.sump_temperature,
           "measured_torque": sig.measured_torque}
    path = write_run_bag(tmp_path / "b", raw, start_time_ns=START)
    got = _read_anyreader(path)
    assert "/clutch/pack_temperature" not in got
    _assert_equal(got, _expected(sig))


@pytest.mark.parametrize("compression", ["none", "lz4"])
def test_bare_mcap(tmp_path, compression):
    sig = _signals(3)
    path = write_run_bag(tmp_path / "sub" / "run_b.mcap", sig, start_time_ns=START,
                         compression=compression)
    assert path.is_file()
    assert sorted(p.name for p in path.parent.iterdir()) == ["run_b.mcap"]  # no temp left over
    _assert_equal(_read_anyreader(path), _expected(sig))   # AnyReader opens bare .mcap files


def _decode_without_ros(mcap_file):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    got = {}
    with open(mcap_file, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            assert schema.encoding == "ros2msg"
            assert channel.message_encoding == "cdr"
            val = decoded.temperature if schema.name == "sensor_msgs/msg/Temperature" else decoded.data
            got.setdefault(channel.topic, ([], [], set()))
            got[channel.topic][0].append(message.log_time)
            got[channel.topic][1].append(val)
            got[channel.topic][2].add(getattr(decoded, "variance", 0.0))
    return got


@pytest.mark.parametrize("compression", ["none", "lz4"])
def test_mcap_decodes_without_ros(tmp_path, compression):
    sig = _signals(4)
    d = write_run_bag(tmp_path / "run_c", sig, start_time_ns=START, compression=compression)
    f = write_run_bag(tmp_path / "run_d.mcap", sig, start_time_ns=START, compression=compression)
    for mcap_file in (d / "run_c.mcap", f):
        _assert_equal(_decode_without_ros(mcap_file), _expected(sig))


@pytest.mark.parametrize("compression", ["none", "lz4"])
def test_deterministic_bytes(tmp_path, compression):
    sig = _signals(5)
    a = write_run_bag(tmp_path / "x" / "run", sig, start_time_ns=START, compression=compression)
    b = write_run_bag(tmp_path / "y" / "run", sig, start_time_ns=START, compression=compression)
    for name in ("run.mcap", "metadata.yaml"):
        assert (a / name).read_bytes() == (b / name).read_bytes()


def test_refuses_overwrite_and_bad_options(tmp_path):
    sig = _signals()
    write_run_bag(tmp_path / "r", sig)
    with pytest.raises(DataError, match="exists already"):
        write_run_bag(tmp_path / "r", sig)
    with pytest.raises(DataError):
        write_run_bag(tmp_path / "s", sig, storage="rosbag1")
    with pytest.raises(DataError):
        write_run_bag(tmp_path / "t.mcap", sig, storage="sqlite3")
    with pytest.raises(DataError):
        write_run_bag(tmp_path / "u", {"applied_force": ([0.0], [1.0])})
    with pytest.raises(DataError):
        TopicSeries([0.0, 1.0], [1.0])
