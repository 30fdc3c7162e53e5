"""`clutch-sim replay` on bags written here and read back: the contract's row grid, sampling and
output timing, several bags in log-time order, storages, measurement mechanisms, bad input."""
import csv
import subprocess
import sys

import numpy as np
import pytest

from clutch_model import load_model, make_mechanism, simulate
from clutch_model.formats.bag_writer import write_run_bag
from clutch_model.formats.bag_reader import read_bag
from clutch_sim.cli import main as cli

MODEL = load_model()


def signals(seed=0, duration=3.0, offset=0.0):
    """Unaligned topics: force at 200 Hz, slip at 100 Hz starting late, sump at 10 Hz."""
    rng = np.random.default_rng(seed)
    tf = np.arange(0, duration, 0.005) + offset
    force = np.where((tf > 0.5) & (tf < 2.0), 6000.0, 400.0) + rng.normal(0, 20, tf.size)
    ts = np.arange(0.0123, duration, 0.01) + offset
    slip = 4.0 + rng.normal(0, 0.05, ts.size)
    tt = np.arange(0.0537, duration, 0.1) + offset  # no sample coincides with a force row
    sump = 55.0 + rng.normal(0, 0.3, tt.size)
    tq = tf + 0.001
    torque = 0.1 * force + rng.normal(0, 5, tf.size)
    return {"applied_force": (tf, force), "slip_speed": (ts, slip), "sump_temperature": (tt, sump),
            "measured_torque": (tq, torque)}


def read_csv(path):
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    return rows


def expected(sig, t_first_msg, model=MODEL, energy0=0.0):
    """Independent re-statement of the contract's grid and sampling."""
    tf, f = sig["applied_force"]
    start = max(sig["applied_force"][0][0], sig["slip_speed"][0][0], sig["sump_temperature"][0][0])
    rows = tf[tf >= start]

    def latest(name):
        t, v = sig[name]
        return np.array([v[np.flatnonzero(t <= x)[-1]] for x in rows])

    f_rows, w_rows, s_rows = latest("applied_force"), latest("slip_speed"), latest("sump_temperature")
    sim = simulate(model, rows - t_first_msg, f_rows, w_rows, s_rows, energy0_j=energy0)
    return rows - t_first_msg, sim


@pytest.mark.parametrize("storage", ["mcap", "sqlite3", "bare"])
def test_replay_grid_and_values(tmp_path, storage):
    sig = signals()
    bag = tmp_path / ("run_a.mcap" if storage == "bare" else "run_a")
    write_run_bag(bag, sig, storage="mcap" if storage == "bare" else storage)
    out = tmp_path / "out.csv"
    assert cli(["replay", "--bag", str(bag), "--out", str(out)]) == 0
    rows = read_csv(out)
    assert list(rows[0].keys()) == ["bag", "t", "torque_sim", "pack_temperature_sim", "locked",
                                    "torque_measured"]
    assert {r["bag"] for r in rows} == {"run_a"}
    t_exp, sim = expected(sig, t_first_msg=0.0)
    np.testing.assert_array_equal([int(r["locked"]) for r in rows], sim.locked.astype(int))
    t = np.array([float(r["t"]) for r in rows])
    np.testing.assert_allclose(t, t_exp, atol=1e-9)
    np.testing.assert_allclose([float(r["torque_sim"]) for r in rows], sim.torque_nm, rtol=1e-5, atol=1e-6)  # log times are ns-rounded
    np.testing.assert_allclose([float(r["pack_temperature_sim"]) for r in rows], sim.pack_temperature_c, rtol=1e-7)
    # measured torque: the latest sample at or before the row (stamped 1 ms after the force)
    tq, torque = sig["measured_torque"]
    first = rows[0]
    meas0 = first["torque_measured"]
    assert meas0 == "" if not (tq <= t_exp[0]).any() else float(meas0) == pytest.approx(torque[tq <= t_exp[0]][-1])


def test_several_bags_in_log_time_order_carry_energy(tmp_path):
    model = MODEL.with_mechanisms([make_mechanism("friction_degradation", energy_scale_j=2e5)])
    params = tmp_path / "m.yaml"
    from clutch_model import save_model
    save_model(model, params)
    a, b = signals(1), signals(2)
    write_run_bag(tmp_path / "early", a, start_time_ns=1_000_000_000_000)
    write_run_bag(tmp_path / "late", b, start_time_ns=1_100_000_000_000)
    out = tmp_path / "out.csv"
    # given in the wrong order on the command line
    assert cli(["replay", "--bag", str(tmp_path / "late"), str(tmp_path / "early"), "--params", str(params),
                "--out", str(out)]) == 0
    rows = read_csv(out)
    assert rows[0]["bag"] == "early" and rows[-1]["bag"] == "late"
    _, sim_a = expected(a, 0.0, model)
    _, sim_b = expected(b, 0.0, model, energy0=sim_a.energy_j[-1] + sim_a.power_w[-1] * 0.005)
    late = np.array([float(r["torque_sim"]) for r in rows if r["bag"] == "late"])
    # the second bag continues from the first's dissipated energy (within one step's heat)
    np.testing.assert_allclose(late, sim_b.torque_nm, rtol=2e-3)
    _, fresh = expected(b, 0.0, model)
    assert np.mean(np.abs(late)) < np.mean(np.abs(fresh.torque_nm))


def test_measurement_mechanisms_apply_to_replay(tmp_path):
    sig = signals(3)
    write_run_bag(tmp_path / "r", sig)
    out0, out1 = tmp_path / "o0.csv", tmp_path / "o1.csv"
    model = MODEL.with_mechanisms([make_mechanism("torque_offset", offset_nm=30.0),
                                   make_mechanism("transport_delay", delay_s=0.1)])
    from clutch_model import save_model
    save_model(model, tmp_path / "m.yaml")
    assert cli(["replay", "--bag", str(tmp_path / "r"), "--out", str(out0)]) == 0
    assert cli(["replay", "--bag", str(tmp_path / "r"), "--out", str(out1), "--model", str(tmp_path / "m.yaml")]) == 0
    r0, r1 = read_csv(out0), read_csv(out1)
    t = np.array([float(r["t"]) for r in r0])
    y0 = np.array([float(r["torque_sim"]) for r in r0])
    y1 = np.array([float(r["torque_sim"]) for r in r1])
    shifted = np.interp(t - 0.1, t, y0)  # first value before the start
    np.testing.assert_allclose(y1, shifted + 30.0, rtol=1e-9, atol=1e-6)


def _cli_subprocess(*args):
    return subprocess.run([sys.executable, "-m", "clutch_sim.cli", *args], capture_output=True, text=True, timeout=120)


def test_bad_bags_fail_with_one_line(tmp_path):
    sig = signals()
    good = tmp_path / "good"
    write_run_bag(good, sig)
    no_slip = {k: v for k, v in sig.items() if k != "slip_speed"}
    # a bag without slip topic: write it with the slip channel renamed away
    write_run_bag(tmp_path / "noslip", {**no_slip, "slip_speed": sig["slip_speed"]}, topics={"slip_speed": "/other/slip"})
    trunc = tmp_path / "trunc.mcap"
    write_run_bag(trunc, sig)
    data = trunc.read_bytes()
    trunc.write_bytes(data[: len(data) // 2])
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    cases = [tmp_path / "missing", tmp_path / "noslip", trunc, empty]
    for bag in cases:
        out = tmp_path / "o.csv"
        res = _cli_subprocess("replay", "--bag", str(good), str(bag), "--out", str(out))
        assert res.returncode != 0, bag
        assert "Traceback" not in res.stderr
        lines = [ln for ln in res.stderr.splitlines() if ln.strip() and not ln.startswith("reading bags")]
        assert len(lines) == 1 and "error" in lines[0], res.stderr


def test_read_bag_drops_samples_the_node_would_reject(tmp_path):
    sig = signals()
    tf, f = sig["applied_force"]
    f = f.copy()
    f[100] = np.nan
    f[101] = 2e6
    sig["applied_force"] = (tf, f)
    write_run_bag(tmp_path / "r", sig)
    run = read_bag(tmp_path / "r")
    assert run.rejected_samples == 2
    assert np.all(np.isfinite(run.applied_force_n)) and run.applied_force_n.max() < 1e6


def test_streamed_replay_equals_whole_campaign(tmp_path):
    """`clutch-sim replay` goes bag by bag (memory bounded by a bag): the same OUT.csv bytes as
    the whole campaign simulated at once, with plant and measurement mechanisms and the energy
    carried across bags; bags given out of log-time order."""
    from pathlib import Path

    from clutch_model.formats.bag_reader import read_bags
    from clutch_model.plant.mechanisms import mechanism_from_dict
    from clutch_model.plant.params import load_model
    from clutch_model.replay import replay_runs, write_replay_csv
    from clutch_model.replay_stream import replay_bags

    bags = [Path(__file__).resolve().parents[2] / "bags" / n for n in ("run_02", "run_00", "run_01")]
    mechs = [{"id": "friction_degradation", "energy_scale_j": 2e5}, {"id": "transport_delay", "delay_s": 0.012},
             {"id": "actuator_lag", "tau_s": 0.04}]
    for k, model in enumerate([load_model(None),
                               load_model(None).with_mechanisms([mechanism_from_dict(m) for m in mechs])]):
        whole = replay_runs(model, read_bags(bags))
        write_replay_csv(whole, tmp_path / f"whole{k}.csv")
        streamed = replay_bags(model, bags, tmp_path / f"stream{k}.csv")
        assert (tmp_path / f"stream{k}.csv").read_bytes() == (tmp_path / f"whole{k}.csv").read_bytes()
        assert [r[0] for r in streamed.per_run] == ["run_00", "run_01", "run_02"]
        assert streamed.rows == len(whole.torque_sim)
        assert np.isclose(streamed.rmse_torque(), whole.rmse_torque(), rtol=1e-12)
        assert np.isclose(streamed.rmse_pack_temperature(), whole.rmse_pack_temperature(), rtol=1e-12)
        assert [r[1] for r in streamed.per_run] == [r[1] for r in whole.per_run()]
