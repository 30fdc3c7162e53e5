"""diagnose on campaigns of other shapes: one long run (held-out time spans, labelled
"<bag>[t0:t1]"), slowly drifting sensor noise (stays `none`), and an interrupted run (the
calibrated model and the split are already on disk)."""
import json
import re

import numpy as np
import pytest

from clutch_model.diagnosis.engine import diagnose_campaign
from clutch_model.diagnosis.report import ProgressiveReport
from clutch_model.formats.bag_reader import read_bags
from clutch_model.formats.bench_csv import read_bench
from clutch_model.identification.friction_fit import fit_friction
from clutch_model.plant.params import load_model
from clutch_model.virtual_car.campaign import CampaignSpec, synthesize_campaign, write_campaign
from clutch_sim.cli import main as cli


def _campaign(tmp_path, **kw):
    spec = CampaignSpec(**kw)
    write_campaign(synthesize_campaign(spec), tmp_path / "campaign")
    return sorted(str(p) for p in (tmp_path / "campaign" / "bags").iterdir())


def _diagnose(tmp_path, bags):
    out = tmp_path / "diag"
    rc = cli(["diagnose", "--bench", str(tmp_path / "campaign" / "bench.csv"), "--bags", *bags,
              "--out", str(out), "--mc-samples", "20"])
    assert rc == 0
    return json.loads((out / "report.json").read_text())


def test_one_long_run_is_diagnosed_on_held_out_spans(tmp_path):
    bags = _campaign(tmp_path, seed=811, n_runs=1, run_duration_s=40.0, n_requests=16,
                     mechanism="actuator_lag", magnitude=0.12)
    assert len(bags) == 1
    rep = _diagnose(tmp_path, bags)
    assert rep["status"] == "complete"
    assert rep["cause"]["id"] == "actuator_lag", rep["cause"]["evidence"]
    assert [c["id"] for c in rep["causes"]] == ["actuator_lag"]
    name = rep["fit_runs"][0]
    spans = rep["held_out_runs"]
    assert len(spans) >= 2
    for label in spans:
        m = re.fullmatch(re.escape(name) + r"\[([0-9.]+):([0-9.]+)\]", label)
        assert m and float(m[1]) < float(m[2]) <= 40.0 + 1e-3
    lo, hi = rep["cause"]["parameters_ci95"]["tau_s"]
    assert lo <= rep["cause"]["parameters"]["tau_s"] <= hi
    assert rep["cause"]["parameters"]["tau_s"] == pytest.approx(0.12, rel=0.25)
    assert rep["gain_pct"] > 10.0


def test_drifting_sensor_noise_is_none(tmp_path):
    """White noise plus an Ornstein-Uhlenbeck drift as large as the noise (tau 5 s)."""
    bags = _campaign(tmp_path, seed=812, n_runs=8, run_duration_s=7.0, torque_drift_nm=8.0,
                     torque_drift_tau_s=5.0)
    rep = _diagnose(tmp_path, bags)
    assert rep["cause"]["id"] == "none", rep["cause"]["evidence"]
    assert rep["causes"] == [] and rep["gain_pct"] == 0.0


def test_interrupted_diagnosis_keeps_the_calibrated_model(tmp_path):
    bags = _campaign(tmp_path, seed=813, n_runs=4, run_duration_s=5.0)
    nominal = load_model(None)
    bench_model = fit_friction(read_bench(tmp_path / "campaign" / "bench.csv"), nominal).model
    out = tmp_path / "diag"
    writer = ProgressiveReport(out)

    def checkpoint(stage, **kw):
        writer(stage, **kw)
        if stage == "calibrated":
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        diagnose_campaign(nominal, bench_model, read_bags(bags), checkpoint=checkpoint)
    rep = json.loads((out / "report.json").read_text())
    assert rep["status"].startswith("calibrated")
    assert rep["held_out_runs"] and np.isfinite(rep["rmse_nm"]["calibrated"])
    cal = load_model(out / "calibrated_model.yaml")
    assert load_model(out / "extended_model.yaml").friction_coefficients.tolist() == \
        cal.friction_coefficients.tolist()
    assert not (out / "report.html").exists()
