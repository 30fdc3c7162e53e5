import json

import numpy as np
import pytest

from clutch_model.formats.bench_csv import write_bench
from clutch_model.virtual_car import identification_data as td
from clutch_model.plant.params import load_model
from clutch_sim.cli import main


@pytest.fixture(scope="module")
def files(tmp_path_factory, rc1, truth, bench_rc1):
    d = tmp_path_factory.mktemp("ident_cli")
    write_bench(d / "bench.csv", bench_rc1)
    runs = td.synthetic_runs(truth, n_runs=3, duration_s=6.0, noise_nm=15.0, pack_noise_c=0.3, seed=21)
    bags = [str(p) for p in td.write_runs_as_bags(runs, d / "bags")]
    th, mu = td.synthetic_viscosity(rc1)
    np.savetxt(d / "visc.csv", np.c_[th, mu], delimiter=",", header="pack_temperature_c,viscosity_pa_s",
               comments="")
    return d, bags


def _one_line_error(capsys, rc):
    err = capsys.readouterr().err.strip().splitlines()
    assert rc != 0 and len(err) == 1 and "error" in err[0] and "Traceback" not in err[0]
    return err[0]


def test_fit_friction_cli(files, capsys):
    d, _ = files
    rc = main(["fit-friction", "--bench", str(d / "bench.csv"), "--out", str(d / "fit.yaml"), "--starts", "1"])
    assert rc == 0
    assert "RMSE" in capsys.readouterr().out
    assert load_model(d / "fit.yaml").friction_coefficients.shape == (20,)
    assert "active_constraints" in json.loads((d / "fit.fit.json").read_text())


def test_fit_friction_bad_csv(files, capsys, tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("slip_speed_rad_s,pressure_mpa\n1,2\n")
    msg = _one_line_error(capsys, main(["fit-friction", "--bench", str(bad), "--out", str(tmp_path / "m.yaml")]))
    assert "fit-friction" in msg
    assert not (tmp_path / "m.yaml").exists()


def test_fit_thermal_cli(files, capsys):
    d, bags = files
    rc = main(["fit-thermal", "--bags", *bags, "--viscosity", str(d / "visc.csv"), "--out", str(d / "th.yaml")])
    assert rc == 0
    out = capsys.readouterr().out
    assert "alpha0" in out and "b1" in out
    m = load_model(d / "th.yaml")
    assert m.data["viscosity"]["alpha1"] == pytest.approx(1.89, rel=0.02)
    capsys.readouterr()
    _one_line_error(capsys, main(["fit-thermal", "--out", str(d / "x.yaml")]))


def test_calibrate_cli(files, capsys):
    d, bags = files
    rc = main(["calibrate", "--bags", *bags[:2], "--out", str(d / "cal.yaml"), "--coefficients", "a0,a3"])
    assert rc == 0
    side = json.loads((d / "cal.fit.json").read_text())
    assert side["coefficients_moved"] == [0, 3] and side["rmse_after"] < side["rmse_before"]
    capsys.readouterr()
    _one_line_error(capsys, main(["calibrate", "--bags", str(d / "nope"), "--out", str(d / "c.yaml")]))


def test_montecarlo_cli(files, capsys):
    d, bags = files
    out = d / "mc"
    rc = main(["montecarlo", "--bags", *bags[:2], "--samples", "64", "--spread", "0.05", "--seed", "1",
               "--out", str(out), "--chunk-size", "32", "--halving", "a3"])
    assert rc == 0
    for name in ("samples.npz", "refined_model.yaml", "summary.json", "scatter.png"):
        assert (out / name).exists(), name
    capsys.readouterr()
    _one_line_error(capsys, main(["montecarlo", "--bags", *bags[:1], "--samples", "4", "--spread", "2",
                                  "--seed", "1", "--out", str(d / "mc2")]))


def test_sensitivity_cli(files, capsys, tmp_path):
    d, bags = files
    rc = main(["sensitivity", "--out", str(tmp_path), "--duration", "1.5", "--bags", *bags[:1]])
    assert rc == 0
    for name in ("torque_response.csv", "torque_response.png", "finite_difference.png",
                 "parameter_sensitivity.csv", "identifiability.csv"):
        assert (tmp_path / name).exists(), name
    assert "friction.a0" in (tmp_path / "parameter_sensitivity.csv").read_text()


def test_console_entry_bad_bench_one_line(tmp_path):
    import os
    import subprocess
    import sys
    from pathlib import Path

    bad = tmp_path / "bad.csv"
    bad.write_bytes(b"\x00\x01garbage")
    exe = Path(sys.executable).with_name("clutch-sim")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "clutch_sim.cli"]
    p = subprocess.run(cmd + ["fit-friction", "--bench", str(bad), "--out", str(tmp_path / "m.yaml")],
                       capture_output=True, text=True, timeout=120, env=dict(os.environ))
    assert p.returncode != 0
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("clutch-sim fit-friction: error:"), p.stderr
