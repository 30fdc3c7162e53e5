"""Bulk MCAP decoding (clutch_model.formats.mcap_bulk) against rosbags' general per-message
decoder: the same series and the same replay grid, bit for bit, on the shipped sample bags and
on bags written here (several chunks, ties, lz4, bare files, variable frame_id lengths); the
general decoder for everything else (sqlite3, other message types, corrupt chunks)."""
from pathlib import Path

import numpy as np
import pytest

from clutch_model.errors import DataError
from clutch_model.formats.bag_reader import TopicNames, _read_topics, read_bag
from clutch_model.formats.bag_writer import RunSignals, TopicSeries, write_run_bag
from clutch_model.formats.mcap_bulk import read_scalar_topics

SAMPLES = Path(__file__).resolve().parents[2] / "bags"
T = TopicNames()
WANTED = [T.applied_force, T.slip_speed, T.sump_temperature, T.measured_torque, T.pack_temperature]
START = 1_700_000_000_000_000_000


def _same_series(a, b):
    assert a[1] == b[1]
    assert a[0].keys() == b[0].keys()
    for topic in b[0]:
        np.testing.assert_array_equal(a[0][topic][0], b[0][topic][0])
        # bit for bit (NaN payloads and signed zeros included)
        np.testing.assert_array_equal(a[0][topic][1].view(np.int64), b[0][topic][1].view(np.int64))


def _same_run(a, b):
    for attr in ("t", "applied_force_n", "slip_speed_rad_s", "sump_temperature_c", "torque_measured_nm",
                 "pack_temperature_measured_c"):
        x, y = getattr(a, attr), getattr(b, attr)
        assert (x is None) == (y is None), attr
        if x is not None:
            np.testing.assert_array_equal(x.view(np.int64), y.view(np.int64), err_msg=attr)
    assert (a.name, a.start_time_ns, a.rejected_samples) == (b.name, b.start_time_ns, b.rejected_samples)


def _long_signals(seconds=40.0, seed=3):
    """1 kHz force/slip/torque with ties and a bad value, 10 Hz temperatures, unaligned stamps."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * 1000)) / 1000.0
    t_slip = t.copy()
    t_slip[100:110] = t_slip[100]                 # equal log times on one topic: order matters
    force = rng.normal(5000, 2000, t.size)
    force[500] = np.nan                            # rejected by the reader, same on both paths
    tt = np.arange(int(seconds * 10)) / 10.0 + 0.00037
    return RunSignals(
        applied_force=TopicSeries(t, force),
        slip_speed=TopicSeries(t_slip, rng.normal(5, 1, t.size)),
        sump_temperature=TopicSeries(tt, rng.normal(60, 0.3, tt.size), variance=0.09),
        measured_torque=TopicSeries(t + 0.0002, rng.normal(500, 100, t.size)),
        pack_temperature=TopicSeries(tt, rng.normal(80, 0.3, tt.size), variance=0.09))


def _chunk_count(mcap_path):
    from mcap.reader import make_reader

    with open(mcap_path, "rb") as fh:
        return len(make_reader(fh).get_summary().chunk_indexes)


@pytest.mark.parametrize("name", ["run_00", "run_01", "run_02"])
def test_sample_bags_bulk_equals_general(name):
    path = SAMPLES / name
    bulk = read_scalar_topics(path, WANTED)
    assert bulk is not None                        # the sample bags take the bulk path
    _same_series(bulk, _read_topics(path, WANTED, bulk=False))
    _same_run(read_bag(path), read_bag(path, bulk=False))


@pytest.fixture(scope="module")
def long_bags(tmp_path_factory):
    d = tmp_path_factory.mktemp("bulk")
    sig = _long_signals()
    return {"mcap": write_run_bag(d / "mcap", sig, start_time_ns=START),
            "lz4": write_run_bag(d / "lz4", sig, start_time_ns=START, compression="lz4"),
            "bare": write_run_bag(d / "bare.mcap", sig, start_time_ns=START),
            "sqlite3": write_run_bag(d / "sqlite3", sig, storage="sqlite3", start_time_ns=START)}


@pytest.mark.parametrize("kind", ["mcap", "lz4", "bare"])
def test_long_mcap_bulk_equals_general(long_bags, kind):
    path = long_bags[kind]
    mcap_file = path if kind == "bare" else path / f"{path.name}.mcap"
    assert _chunk_count(mcap_file) > 1             # several chunks: merged and ordered across them
    bulk = read_scalar_topics(path, WANTED)
    assert bulk is not None
    general = _read_topics(path, WANTED, bulk=False)
    _same_series(bulk, general)
    assert bulk[0][T.applied_force][0].size == 40_000
    run = read_bag(path)
    _same_run(run, read_bag(path, bulk=False))
    assert run.rejected_samples == 1


def test_sqlite3_takes_general_path_with_same_numbers(long_bags):
    assert read_scalar_topics(long_bags["sqlite3"], WANTED) is None
    a, b = read_bag(long_bags["sqlite3"]), read_bag(long_bags["mcap"])
    b.name = a.name
    _same_run(a, b)


def _write_raw(path, messages, msgtype_of):
    """A bag of hand-made messages [(topic, t_ns, msg object)] with rosbags' serializer."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {tp: w.add_connection(tp, mt, typestore=ts) for tp, mt in msgtype_of.items()}
        for topic, t_ns, msg in messages:
            w.write(conns[topic], t_ns, ts.serialize_cdr(msg, msgtype_of[topic]))
    return path, ts


def test_temperature_frame_ids_of_any_length(tmp_path):
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    Temp, Header, Time, F64 = (ts.types[n] for n in ("sensor_msgs/msg/Temperature", "std_msgs/msg/Header",
                                                      "builtin_interfaces/msg/Time", "std_msgs/msg/Float64"))
    rng = np.random.default_rng(0)
    msgs = []
    for k in range(300):
        t = START + k * 1_000_000
        frame = "x" * (k % 13)                     # every padding case, and the empty string
        msgs.append((T.sump_temperature, t, Temp(header=Header(stamp=Time(sec=k, nanosec=7), frame_id=frame),
                                                 temperature=float(rng.normal(60, 5)), variance=float(k))))
        msgs.append((T.applied_force, t, F64(data=float(rng.normal(1000, 10)))))
        msgs.append((T.slip_speed, t, F64(data=float(rng.normal(3, 1)))))
    path, _ = _write_raw(tmp_path / "frames", msgs, {T.sump_temperature: "sensor_msgs/msg/Temperature",
                                                     T.applied_force: "std_msgs/msg/Float64",
                                                     T.slip_speed: "std_msgs/msg/Float64"})
    bulk = read_scalar_topics(path, WANTED)
    assert bulk is not None
    _same_series(bulk, _read_topics(path, WANTED, bulk=False))
    expected = [m[2].temperature for m in msgs if m[0] == T.sump_temperature]
    np.testing.assert_array_equal(bulk[0][T.sump_temperature][1], expected)


def test_other_message_types_fall_back(tmp_path):
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    F32, F64 = ts.types["std_msgs/msg/Float32"], ts.types["std_msgs/msg/Float64"]
    Temp, Header, Time = (ts.types[n] for n in ("sensor_msgs/msg/Temperature", "std_msgs/msg/Header",
                                                "builtin_interfaces/msg/Time"))
    msgs = []
    for k in range(50):
        t = START + k * 5_000_000
        msgs += [(T.applied_force, t, F32(data=1000.0 + k)), (T.slip_speed, t, F64(data=2.0)),
                 (T.sump_temperature, t, Temp(header=Header(stamp=Time(sec=0, nanosec=0), frame_id="s"),
                                              temperature=60.0, variance=0.0))]
    path, _ = _write_raw(tmp_path / "f32", msgs, {T.applied_force: "std_msgs/msg/Float32",
                                                  T.slip_speed: "std_msgs/msg/Float64",
                                                  T.sump_temperature: "sensor_msgs/msg/Temperature"})
    assert read_scalar_topics(path, WANTED) is None
    run = read_bag(path)                           # general decoder: Float32 has .data too
    np.testing.assert_array_equal(run.applied_force_n, 1000.0 + np.arange(50))


def test_truncated_bag_is_an_error_not_numbers(long_bags, tmp_path):
    import shutil

    src = long_bags["bare"]
    dst = tmp_path / "truncated.mcap"
    shutil.copy(src, dst)
    data = dst.read_bytes()
    dst.write_bytes(data[: len(data) // 2])        # a recording cut short: no summary, half a chunk
    assert read_scalar_topics(dst, WANTED) is None
    with pytest.raises(DataError, match="unreadable"):
        read_bag(dst)


def test_messages_out_of_log_time_order(tmp_path):
    """Logged out of order (ties included), over several chunks: both paths order them alike."""
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    F64 = ts.types["std_msgs/msg/Float64"]
    Temp, Header, Time = (ts.types[n] for n in ("sensor_msgs/msg/Temperature", "std_msgs/msg/Header",
                                                "builtin_interfaces/msg/Time"))
    rng = np.random.default_rng(5)
    n = 30_000
    t_force = START + rng.integers(0, 2_000, n) * 1_000_000          # many equal log times
    msgs = [(T.applied_force, int(t), F64(data=float(k))) for k, t in enumerate(t_force)]
    msgs += [(T.slip_speed, START + int(t), F64(data=float(-k))) for k, t in enumerate(rng.permutation(n) * 10_000)]
    msgs += [(T.sump_temperature, START + k * 50_000_000,
              Temp(header=Header(stamp=Time(sec=0, nanosec=0), frame_id="sump"), temperature=60.0 + k, variance=0.0))
             for k in range(40)]
    order = rng.permutation(len(msgs))
    path, _ = _write_raw(tmp_path / "shuffled", [msgs[k] for k in order],
                         {T.applied_force: "std_msgs/msg/Float64", T.slip_speed: "std_msgs/msg/Float64",
                          T.sump_temperature: "sensor_msgs/msg/Temperature"})
    assert _chunk_count(path / "shuffled.mcap") > 1
    bulk = read_scalar_topics(path, WANTED)
    assert bulk is not None
    _same_series(bulk, _read_topics(path, WANTED, bulk=False))
    assert np.all(np.diff(bulk[0][T.applied_force][0]) >= 0)
    _same_run(read_bag(path), read_bag(path, bulk=False))


def test_mcap_header_equals_rosbags(long_bags):
    from rosbags.highlevel import AnyReader

    from clutch_model.formats.mcap_bulk import mcap_header

    for kind in ("mcap", "lz4", "bare"):
        with AnyReader([long_bags[kind]]) as reader:
            expected = int(reader.start_time), {c.topic for c in reader.connections if c.msgcount > 0}
        assert mcap_header(long_bags[kind]) == expected
    assert mcap_header(long_bags["sqlite3"]) is None
    for name in ("run_00", "run_02"):                     # run_02 logs no pack temperature
        with AnyReader([SAMPLES / name]) as reader:
            expected = int(reader.start_time), {c.topic for c in reader.connections if c.msgcount > 0}
        assert mcap_header(SAMPLES / name) == expected
