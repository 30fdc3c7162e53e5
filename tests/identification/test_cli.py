import csv
import json

import numpy as np
import pytest

from clutch_model import simulate
from clutch_model.formats.bag_reader import read_bags
from clutch_model.formats.bench_csv import read_bench, write_bench
from clutch_model.virtual_car import identification_data as td
from clutch_model.plant.params import load_model
from clutch_sim.cli import main

from .conftest import measured_rmse, stribeck_mu


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


def test_fit_friction_cli(files, capsys, rc1):
    d, _ = files
    rc = main(["fit-friction", "--bench", str(d / "bench.csv"), "--out", str(d / "fit.yaml"), "--starts", "1"])
    assert rc == 0
    assert "RMSE" in capsys.readouterr().out
    fitted = load_model(d / "fit.yaml")
    side = json.loads((d / "fit.fit.json").read_text())
    assert "active_constraints" in side
    # the fitted friction law reproduces the bench table it was fitted to (noise 0.002) and the
    # true law the table was drawn from, evaluated independently at the bench points
    b = read_bench(d / "bench.csv")
    args = (b.pressure_mpa, b.plate_temperature_c, b.slip_speed_rad_s)
    mu_fit = stribeck_mu(fitted.friction_coefficients, fitted.friction_exponent, *args)
    mu_true = stribeck_mu(rc1.friction_coefficients, rc1.friction_exponent, *args)
    assert np.sqrt(np.mean((mu_fit - b.friction_coefficient) ** 2)) < 0.0025
    assert side["rmse"] == pytest.approx(np.sqrt(np.mean((mu_fit - b.friction_coefficient) ** 2)), rel=1e-6)
    assert np.sqrt(np.mean((mu_fit - mu_true) ** 2)) < 0.001


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


def test_montecarlo_cli(files, capsys, rc1):
    d, bags = files
    out = d / "mc"
    rc = main(["montecarlo", "--bags", *bags[:2], "--samples", "64", "--spread", "0.05", "--seed", "1",
               "--out", str(out), "--chunk-size", "32", "--halving", "a3"])
    assert rc == 0
    for name in ("scatter.png",):
        assert (out / name).stat().st_size > 1000, name
    summary = json.loads((out / "summary.json").read_text())
    refined = load_model(out / "refined_model.yaml")
    z = np.load(out / "samples.npz")
    a0 = rc1.friction_coefficients
    # the samples are the requested +-5 % cloud around RC-1, 64 of them, seeded
    assert z["samples"].shape == (64, 20) and int(z["seed"]) == 1
    assert np.all(np.abs(z["samples"] - a0) <= 0.05 * np.abs(a0) + 1e-15)
    np.testing.assert_array_equal(refined.friction_coefficients, summary["refined_a"])
    # the RMSEs it reports are the ones an independent replay of the bags gives
    assert summary["rmse_nominal"] == pytest.approx(measured_rmse(rc1, read_bags(bags[:2])), rel=1e-6)
    assert summary["rmse_refined"] == pytest.approx(measured_rmse(refined, read_bags(bags[:2])), rel=1e-6)
    assert summary["rmse_refined"] < 0.5 * summary["rmse_nominal"]
    capsys.readouterr()
    _one_line_error(capsys, main(["montecarlo", "--bags", *bags[:1], "--samples", "4", "--spread", "2",
                                  "--seed", "1", "--out", str(d / "mc2")]))


def _csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_sensitivity_cli(files, capsys, tmp_path, rc1):
    d, bags = files
    rc = main(["sensitivity", "--out", str(tmp_path), "--duration", "1.5", "--bags", *bags[:1]])
    assert rc == 0
    for name in ("torque_response.png", "finite_difference.png", "identifiability.csv"):
        assert (tmp_path / name).stat().st_size > 100, name
    # the thesis scenario (500 kPa, 60 rpm, 60 C sump) simulated independently
    tr = _csv(tmp_path / "torque_response.csv")
    t = np.array([float(r["t"]) for r in tr])
    assert t[0] == 0.0 and t[-1] == pytest.approx(1.5) and np.allclose(np.diff(t), 1e-3)
    force = 0.5e6 * rc1.nominal_area_m2
    nominal = simulate(rc1, t, force, 2.0 * np.pi, 60.0).torque_nm
    np.testing.assert_allclose([float(r["torque_nominal"]) for r in tr], nominal, rtol=1e-9, atol=1e-9)
    end = tr[-1]
    assert float(end["torque_mu_plus"]) > float(end["torque_nominal"]) > float(end["torque_mu_minus"]) > 0
    # parameter sensitivities: a0's is a finite difference we can redo through the public API ...
    ps = {r["parameter"]: r for r in _csv(tmp_path / "parameter_sensitivity.csv")}
    h, a = 1e-3, rc1.friction_coefficients

    def torque_end(a0_factor):
        aa = a.copy()
        aa[0] *= a0_factor
        return simulate(rc1.with_friction(a=aa), t, force, 2.0 * np.pi, 60.0).torque_nm[-1]

    s_a0 = (torque_end(1 + h) - torque_end(1 - h)) / (2 * h) / nominal[-1]
    assert float(ps["friction.a0"]["normalized_step_1e-3"]) == pytest.approx(s_a0, rel=0.02)
    # ... and scaling every coefficient that multiplies mu_f is scaling mu_f: their normalised
    # sensitivities add up to the mu_f sensitivity of the finite-difference experiment
    mu_scaling = [f"friction.a{k}" for k in (*range(10), *range(15, 20))]
    total = sum(float(ps[n]["normalized_step_1e-3"]) for n in mu_scaling if n in ps)
    fd = _csv(tmp_path / "finite_difference.csv")
    assert total == pytest.approx(float(fd[-1]["normalized"]), rel=0.03)
    ranks = [abs(float(r["normalized_step_1e-3"])) for r in _csv(tmp_path / "parameter_sensitivity.csv")]
    assert ranks == sorted(ranks, reverse=True)


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
