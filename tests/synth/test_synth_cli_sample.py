"""`clutch-sim synth` and the shipped sample data (python -m clutch_model.virtual_car.sample_bags)."""
import filecmp
import json

import numpy as np
import pytest

from clutch_model.plant.mechanisms import CATALOG
from clutch_model.plant.params import load_model
from clutch_model.virtual_car.sample_bags import SAMPLE_DIR, write_sample_data
from clutch_model.virtual_car.campaign import EXTRA_EFFECTS
from clutch_sim.cli import main
from clutch_sim.commands import synth as synth_cmd


def test_cli_choices_match_catalog():
    assert set(synth_cmd.mechanism_ids()) == set(CATALOG)
    assert set(synth_cmd.EXTRA_EFFECTS) == set(EXTRA_EFFECTS)


def test_cli_synth_writes_campaign(tmp_path, capsys):
    out = tmp_path / "camp"
    rc = main(["synth", "--out", str(out), "--runs", "2", "--duration", "4", "--seed", "5",
               "--mechanism", "spring_preload", "--magnitude", "600", "--storage", "sqlite3"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert str(out / "truth.yaml") in printed
    assert sorted(p.name for p in (out / "bags").iterdir()) == ["run_00", "run_01"]
    assert list((out / "bags" / "run_00").glob("*.db3"))
    assert load_model(out / "truth.yaml").mechanism("spring_preload").values["preload_n"] == 600.0
    assert json.loads((out / "campaign.json").read_text())["expected_cause"] == "spring_preload"
    # never overwrites bags; one-line error, exit 1
    rc = main(["synth", "--out", str(out), "--runs", "2"])
    assert rc == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "already holds" in err[0]


@pytest.mark.parametrize("argv, needle", [
    (["--magnitude", "3"], "--magnitude needs"),
    (["--mechanism", "actuator_lag", "--magnitude", "-1"], "outside"),
    (["--runs", "0"], "at least one run"),
    (["--friction-spread", "1.5"], "spread"),
    (["--params", "/no/such/model.yaml"], "not found"),
])
def test_cli_synth_user_errors(tmp_path, capsys, argv, needle):
    rc = main(["synth", "--out", str(tmp_path / "o")] + argv)
    assert rc == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err


def test_cli_extra_effect(tmp_path, capsys):
    rc = main(["synth", "--out", str(tmp_path), "--runs", "1", "--duration", "4",
               "--extra-effect", "torque_ripple", "--compression", "lz4", "--pack-temperature"])
    assert rc == 0
    meta = json.loads((tmp_path / "campaign.json").read_text())
    assert meta["expected_cause"] == "unexplained"
    assert meta["extra_effect"]["name"] == "torque_ripple"
    assert load_model(tmp_path / "truth.yaml").mechanisms == []


def test_sample_data_deterministic(tmp_path):
    a = write_sample_data(tmp_path / "a")
    write_sample_data(tmp_path / "b")
    for p in a:
        rel = p.relative_to(tmp_path / "a")
        files = [p] if p.is_file() else sorted(x for x in p.rglob("*") if x.is_file())
        for f in files:
            other = tmp_path / "b" / f.relative_to(tmp_path / "a")
            assert filecmp.cmp(f, other, shallow=False), rel
    total = sum(f.stat().st_size for f in (tmp_path / "a").rglob("*") if f.is_file())
    assert total < 700 * 1024


@pytest.mark.skipif(not (SAMPLE_DIR / "run_00").is_dir(), reason="sample bags not generated")
def test_shipped_sample_bags_readable():
    from rosbags.highlevel import AnyReader

    from clutch_model.formats.bench_csv import read_bench

    assert len(read_bench(SAMPLE_DIR / "bench.csv")) == 135
    starts = []
    for name in ("run_00", "run_01", "run_02"):
        with AnyReader([SAMPLE_DIR / name]) as reader:
            counts = {c.topic: c.msgcount for c in reader.connections}
            starts.append(reader.start_time)
            assert counts["/clutch/applied_force"] == 1800
            assert counts["/clutch/measured_torque"] == 1800
            assert counts["/clutch/sump_temperature"] == 90
            assert 8.9e9 < reader.duration < 9.1e9
    assert np.all(np.diff(starts) > 120e9)
