"""Replay in blocks of rows (memory bounded by a block): the plant resumes from the state saved at
each block boundary, the measurement mechanisms carry their state, the grid is built chunk by
chunk as the MCAP samples become final — and every number equals the whole-run replay's, bit
for bit, whatever the block size (blocks that split an engagement mid-way included)."""
from pathlib import Path

import numpy as np
import pytest

from clutch_model import load_model, make_mechanism, simulate
from clutch_model.formats.bag_reader import read_bag, read_bags
from clutch_model.formats.bag_stream import BagBlocks
from clutch_model.formats.bag_writer import RunSignals, TopicSeries, write_run_bag
from clutch_model.plant.mechanisms import apply_measurement
from clutch_model.plant.measurement_stream import MeasurementStream
from clutch_model.plant.simulate import ChunkedSimulation
from clutch_model.replay import replay_runs, write_replay_csv
from clutch_model.replay_stream import replay_bags

SAMPLES = Path(__file__).resolve().parents[2] / "bags"
SIM_FIELDS = ("torque_nm", "asperity_torque_nm", "hydrodynamic_torque_nm", "drag_torque_nm",
              "friction_coefficient", "film_thickness_m", "pack_temperature_c", "viscosity_pa_s",
              "power_w", "energy_j", "locked", "pack_force_n", "force_clamped", "pressure_mpa",
              "out_of_range", "asperity_pressure_pa")


def plant_mechanisms():
    """Every plant mechanism, each with state or a kernel slot: lag, hysteresis, preload,
    wear, drag, and discovered terms with low-pass states and the slip angle."""
    return [make_mechanism("actuator_lag", tau_s=0.04), make_mechanism("actuator_hysteresis", ratio=0.05),
            make_mechanism("spring_preload", preload_n=300.0),
            make_mechanism("friction_degradation", energy_scale_j=2e5),
            make_mechanism("drag_torque", coeff_nm_per_rad_s=0.5),
            make_mechanism("discovered", terms=["mu:slip_power@0.3s", "torque:sin_slip_angle",
                                                "mu:force_rate", "torque:energy*slip_sign@0.05s"],
                           coefficients=[-0.02, 3.0, 0.001, 0.5])]


def measurement_mechanisms():
    return [make_mechanism("torque_offset", offset_nm=12.5), make_mechanism("transport_delay", delay_s=0.0137),
            make_mechanism("torque_sensor_lag", tau_s=0.021)]


def bitwise_equal(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape and a.dtype == b.dtype
    if a.dtype.kind == "f":
        return np.array_equal(a.view(np.int64), b.view(np.int64))
    return np.array_equal(a, b)


def split_points(n, sizes):
    """Chunk bounds: the given sizes in turn, then the rest."""
    bounds, k, j = [0], 0, 0
    while k < n:
        k = min(n, k + sizes[j % len(sizes)])
        bounds.append(k)
        j += 1
    return list(zip(bounds[:-1], bounds[1:]))


@pytest.mark.parametrize("sizes", [[1], [37, 1000, 2], [1700]])
def test_chunked_plant_equals_whole_run_with_every_plant_mechanism(sizes):
    run = read_bag(SAMPLES / "run_00")
    model = load_model().with_mechanisms(plant_mechanisms())
    args = (run.t, run.applied_force_n, run.slip_speed_rad_s, run.sump_temperature_c)
    whole = simulate(model, *args, energy0_j=1.5e5)
    # chunk boundaries also mid-engagement: the pack force ramping while the clutch slips
    engaging = np.flatnonzero((np.abs(np.diff(whole.pack_force_n)) > 1.0) & ~whole.locked[1:]) + 1
    assert engaging.size > 10
    cuts = {b for _, b in split_points(len(run), sizes)} | set(engaging[:: max(engaging.size // 7, 1)].tolist())
    cuts = sorted(cuts | {0, len(run)})
    chunks = list(zip(cuts[:-1], cuts[1:]))
    sim = ChunkedSimulation(model, energy0_j=1.5e5)
    parts = [sim.run(*(x[a:b] for x in args)) for a, b in chunks]
    for name in SIM_FIELDS:
        got = np.concatenate([getattr(p, name) for p in parts])
        assert bitwise_equal(got, getattr(whole, name)), name
    assert sim.energy_j == whole.energy_j[-1]


def test_chunked_plant_restarts_at_run_starts_and_reuses_its_buffer():
    a, b = read_bag(SAMPLES / "run_00"), read_bag(SAMPLES / "run_01")
    model = load_model().with_mechanisms(plant_mechanisms())
    cat = [np.concatenate([x, y]) for x, y in zip((a.t, a.applied_force_n, a.slip_speed_rad_s, a.sump_temperature_c),
                                                  (b.t, b.applied_force_n, b.slip_speed_rad_s, b.sump_temperature_c))]
    rs = np.zeros(cat[0].size, bool)
    rs[len(a)] = True
    whole = simulate(model, *cat, run_start=rs)
    sim = ChunkedSimulation(model)
    got = []
    for lo, hi in split_points(rs.size, [999]):     # one chunk holds the second run's start
        res = sim.run(*(x[lo:hi] for x in cat), run_start=rs[lo:hi], copy=False)
        got.append(res.torque_nm.copy())            # views of a buffer the next chunk overwrites
    assert bitwise_equal(np.concatenate(got), whole.torque_nm)


def test_a_branch_goes_on_from_the_same_state_and_leaves_its_origin_alone():
    """Two branches of one chunked simulation, each run on the same rest of the rows, give the
    whole run's numbers bit for bit; running a branch does not move the simulation it came from."""
    run = read_bag(SAMPLES / "run_00")
    model = load_model().with_mechanisms(plant_mechanisms())
    args = (run.t, run.applied_force_n, run.slip_speed_rad_s, run.sump_temperature_c)
    whole = simulate(model, *args, energy0_j=1.5e5)
    half = len(run) // 2
    sim = ChunkedSimulation(model, energy0_j=1.5e5)
    sim.run(*(x[:half] for x in args))
    state = sim.state.copy()
    first, second = sim.branch(), sim.branch()
    for twin in (first, second):
        rest = twin.run(*(x[half:] for x in args))
        assert bitwise_equal(rest.torque_nm, whole.torque_nm[half:])
    assert bitwise_equal(sim.state, state)
    assert bitwise_equal(sim.run(*(x[half:] for x in args)).torque_nm, whole.torque_nm[half:])


@pytest.mark.parametrize("sizes", [[1], [5, 333], [2000]])
def test_chunked_measurement_equals_whole_trace(sizes):
    rng = np.random.default_rng(7)
    n = 2500
    t = np.cumsum(rng.uniform(0.0005, 0.0015, n))
    t[1200:1203] = t[1199]                       # repeated stamps (dt = 0) in the sensor lag
    torque = np.cumsum(rng.normal(0, 3.0, n))
    rs = np.zeros(n, bool)
    rs[0] = rs[1700] = True                      # two runs
    mechs = measurement_mechanisms()
    whole = apply_measurement(mechs, t, torque, rs)
    got = []
    for lo, hi in ((0, 1700), (1700, n)):
        stream = MeasurementStream(mechs)
        assert stream.chunkable
        for a, b in split_points(hi - lo, sizes):
            got.append(stream.run(t[lo + a:lo + b], torque[lo + a:lo + b], starts_run=a == 0))
    assert bitwise_equal(np.concatenate(got), whole)


def test_every_measurement_mechanism_alone_chunked():
    rng = np.random.default_rng(8)
    t = np.arange(3000) * 1e-3
    torque = np.cumsum(rng.normal(0, 3.0, t.size))
    rs = np.zeros(t.size, bool)
    rs[0] = True
    for m in measurement_mechanisms() + [make_mechanism("transport_delay", delay_s=0.0),
                                         make_mechanism("transport_delay", delay_s=5.0),
                                         make_mechanism("torque_sensor_lag", tau_s=0.0)]:
        stream = MeasurementStream([m])
        got = np.concatenate([stream.run(t[a:b], torque[a:b], a == 0) for a, b in split_points(t.size, [700, 3])])
        assert bitwise_equal(got, apply_measurement([m], t, torque, rs)), m.to_dict()


def long_signals(seconds=45.0, seed=3):
    """1 kHz topics on their own stamps (ties, a rejected sample, slip starting late), 10 Hz
    temperatures: several MCAP chunks."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * 1000)) / 1000.0
    t_slip = t[37:] + 0.00011
    t_slip[100:110] = t_slip[100]
    force = np.abs(rng.normal(5000, 2000, t.size))
    force[500] = np.nan
    t_force = t.copy()
    t_force[20000:20003] = t[20000]               # repeated force stamps: the row takes the last one
    tt = np.arange(int(seconds * 10)) / 10.0 + 0.00037
    return RunSignals(
        applied_force=TopicSeries(t_force, force),
        slip_speed=TopicSeries(t_slip, rng.normal(5, 1, t_slip.size)),
        sump_temperature=TopicSeries(tt, rng.normal(60, 0.3, tt.size), variance=0.09),
        measured_torque=TopicSeries(t + 0.0002, rng.normal(500, 100, t.size)),
        pack_temperature=TopicSeries(tt, rng.normal(80, 0.3, tt.size), variance=0.09))


@pytest.fixture(scope="module")
def long_bags(tmp_path_factory):
    d = tmp_path_factory.mktemp("chunked")
    sig = long_signals()
    return [write_run_bag(d / "long_a", sig, start_time_ns=1_700_000_000_000_000_000),
            write_run_bag(d / "long_b.mcap", long_signals(seed=4), start_time_ns=1_700_000_100_000_000_000,
                          compression="lz4")]


@pytest.mark.parametrize("block_rows", [2, 4096, 30011, 1 << 16])
def test_streamed_grid_equals_read_bag(long_bags, block_rows):
    from mcap.reader import make_reader

    for path in long_bags:
        f = path if path.is_file() else next(path.glob("*.mcap"))
        with open(f, "rb") as fh:
            assert len(make_reader(fh).get_summary().chunk_indexes) > 3     # grid rows cross chunks
        bag = BagBlocks(path, block_rows=block_rows)
        assert bag.bulk
        blocks = list(bag.blocks())
        assert all(len(b) == block_rows for b in blocks[:-1]) and 0 < len(blocks[-1]) <= block_rows
        assert [b.first for b in blocks] == [True] + [False] * (len(blocks) - 1)
        run = read_bag(path)
        assert bag.start_time_ns == run.start_time_ns
        for attr, field in (("t", "t"), ("applied_force_n", "force"), ("slip_speed_rad_s", "slip"),
                            ("sump_temperature_c", "sump"), ("torque_measured_nm", "torque_measured"),
                            ("pack_temperature_measured_c", "pack_measured")):
            got = np.concatenate([getattr(b, field) for b in blocks])
            assert bitwise_equal(got, getattr(run, attr)), attr


@pytest.mark.parametrize("threads", [True, False])
def test_replay_in_blocks_equals_whole_replay_with_every_mechanism(tmp_path, long_bags, threads):
    """OUT.csv bytes and RMSEs of the block-wise replay (blocks far smaller than a bag, bags out
    of order, sample bags and 1 kHz bags, energy carried) equal the whole campaign's."""
    bags = [SAMPLES / "run_01", long_bags[1], SAMPLES / "run_00", long_bags[0]]
    model = load_model().with_mechanisms(plant_mechanisms() + measurement_mechanisms())
    whole = replay_runs(model, read_bags(bags))
    write_replay_csv(whole, tmp_path / "whole.csv")
    streamed = replay_bags(model, bags, tmp_path / "blocks.csv", block_rows=1111, threads=threads)
    assert (tmp_path / "blocks.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()
    assert streamed.per_run == [r for r in whole.per_run()]
    assert streamed.rmse_torque() == whole.rmse_torque()
    assert streamed.rmse_pack_temperature() == whole.rmse_pack_temperature()


def test_corrupt_chunk_mid_bag_gives_the_general_decoders_answer(tmp_path, long_bags):
    """A chunk that fails the bulk path's checks after rows were written: the bag's rows are
    taken back and the bag goes to the general decoder — the same result as the whole-bag
    reader (which also falls back), rows or error."""
    from mcap.reader import make_reader

    from clutch_model.errors import DataError
    from clutch_model.formats.mcap_bulk import NotBulk, ScalarStream
    from clutch_model.formats.topics import TopicNames

    tp = TopicNames()
    WANTED = [tp.applied_force, tp.slip_speed, tp.sump_temperature, tp.measured_torque, tp.pack_temperature]

    src = next(long_bags[0].glob("*.mcap"))
    bad = tmp_path / "bad.mcap"
    data = bytearray(src.read_bytes())
    with open(src, "rb") as fh:
        chunks = sorted(make_reader(fh).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    ci = chunks[len(chunks) // 2]
    assert ci.compression == ""
    records = ci.chunk_start_offset + 1 + 8 + 8 + 8 + 8 + 4 + 4 + 8          # chunk record header, no compression
    assert data[records] == 0x05                                            # the chunk's first message record
    data[records] = 0x06                                                    # its opcode no longer a message's
    bad.write_bytes(bytes(data))
    batches = ScalarStream(bad, set(WANTED)).batches()
    assert next(batches)                                                    # the stream starts fine ...
    with pytest.raises(NotBulk):                                            # ... and stops at that chunk
        list(batches)
    model = load_model()
    bags = [SAMPLES / "run_00", bad]
    try:
        whole = replay_runs(model, read_bags(bags))
    except DataError as exc:
        with pytest.raises(DataError, match=str(exc)[:20]):
            replay_bags(model, bags, tmp_path / "o.csv", block_rows=500)
        rows = (tmp_path / "o.csv").read_text().splitlines()
        assert len(rows) == 1 + len(read_bag(SAMPLES / "run_00"))      # the good bag only
        return
    write_replay_csv(whole, tmp_path / "whole.csv")
    replay_bags(model, bags, tmp_path / "o.csv", block_rows=500)
    assert (tmp_path / "o.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()


def test_csv_blocks_are_orjsons_fields_row_by_row():
    """The compiled row assembly writes, field for field, what orjson writes for each column
    (the format before it: each column dumped, split on commas, rows joined), held columns
    (formatted once per run of equal values) and non-finite values (empty fields) included."""
    orjson = pytest.importorskip("orjson")
    from clutch_model.formats.table_csv import format_block

    def reference(prefix, cols):
        fields = [orjson.dumps(c if c.dtype.kind == "f" else c.astype(np.int64),
                               option=orjson.OPT_SERIALIZE_NUMPY)[1:-1].replace(b"null", b"").split(b",")
                  for c in cols]
        return b"".join(prefix + b",".join(row) + b"\r\n" for row in zip(*fields))

    rng = np.random.default_rng(5)
    for n in (1, 2, 64, 65, 1000, 70000):
        wild = rng.normal(size=n) * 10.0 ** rng.integers(-300, 300, n)
        wild[:6] = [5e-324, 1.7976931348623157e308, -0.0, 1e-5, 1e16, np.inf][:min(6, n)] + list(wild[min(6, n):6])
        held = np.repeat(50 + rng.random(n // 100 + 1), 100)[:n]
        held[5:300] = np.nan
        cols = [np.arange(n) * 1e-3 + 0.00023, wild, rng.random(n) < 0.2, held, np.full(n, np.nan),
                rng.integers(-5, 5, n).astype(np.int8)]
        prefix = b'"run, 0",'
        assert bytes(format_block(orjson, prefix, cols)) == reference(prefix, cols), n
