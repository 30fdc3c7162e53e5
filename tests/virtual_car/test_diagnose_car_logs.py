"""`clutch-sim diagnose` on car-log campaigns (topics on their own clocks, lock-up phases):
lock rows stay out, the model is compared where the measurement is. Slow (about 1.5 min
each): run with -m slow."""
import glob
import json

import pytest

from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs, write_car_logs
from clutch_sim.cli import main as cli

pytestmark = pytest.mark.slow


def diagnose(tmp_path, **spec):
    write_car_logs(synthesize_car_logs(CarLogSpec(n_runs=4, **spec)), tmp_path / "c")
    bags = sorted(glob.glob(str(tmp_path / "c" / "bags" / "*")))
    assert cli(["diagnose", "--bench", str(tmp_path / "c" / "bench.csv"), "--bags", *bags,
                "--out", str(tmp_path / "d")]) == 0
    return json.loads((tmp_path / "d" / "report.json").read_text())


def test_car_logs_without_mechanism_is_none(tmp_path):
    report = diagnose(tmp_path, seed=11)
    assert report["cause"]["id"] == "none"
    assert report["rmse_nm"]["calibrated"] < 10.0      # torque noise 8 N*m: lock rows are out


def test_car_logs_actuator_lag_named(tmp_path):
    report = diagnose(tmp_path, seed=12, mechanisms=[{"id": "actuator_lag", "tau_s": 0.1}])
    assert report["cause"]["id"] == "actuator_lag"
    assert report["cause"]["parameters"]["tau_s"] == pytest.approx(0.1, rel=0.15)
    assert report["gain_pct"] > 50
