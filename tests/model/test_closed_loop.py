"""The closed-loop pieces: the PI slip controller (independent expectations of its law and
anti-windup), the split-mu scenario under control against the open clutch, and the
`clutch-sim driveline` command (files written, one-line errors)."""
import subprocess
import sys

import numpy as np
import pytest

from clutch_model import load_model
from clutch_model.closed_loop import PISlipController
from clutch_model.closed_loop.scenarios import get_scenario, run_scenario, summary, CSV_COLUMNS


def test_pi_law_and_conditional_integration():
    c = PISlipController(target_slip_rad_s=2.0, kp_n_per_rad_s=100.0, ki_n_per_rad=1000.0,
                         force_min_n=0.0, force_max_n=5000.0)
    assert c.update(0.0, -5.0) == pytest.approx(300.0)          # e = |slip| - target = 3, no integral yet
    assert c.update(0.1, -5.0) == pytest.approx(300.0 + 1000.0 * 0.3)
    assert c.update(0.2, 1.0) == pytest.approx(-100.0 + 1000.0 * (0.3 - 0.1))
    # saturated high: the integral stops growing while the error pushes further up
    for k in range(3, 200):
        c.update(k * 0.1, 50.0)
    assert c._force == 5000.0
    frozen = c.integral
    c.update(20.0, 50.0)
    assert c.integral == frozen
    # and comes off the limit as soon as the slip is below target
    assert c.update(20.1, 0.0) < 5000.0
    assert c.update(20.2, float("nan")) == c._force                # a bad sample holds the command


@pytest.fixture(scope="module")
def split_mu_run():
    return run_scenario(load_model(), get_scenario("split-mu", rate_hz=500.0))


def test_split_mu_controller_holds_the_slip_and_saves_the_ice_wheel(split_mu_run):
    run = split_mu_run
    r, sc = run.controlled, run.scenario
    s = summary(run)
    assert s["slip_rms_error_rad_s"] < 0.3
    assert s["max_speed_b_controlled_rad_s"] < 0.2 * s["max_speed_b_open_rad_s"]
    # where the target is 0 the clutch ends locked and carries torque to the gripping side
    assert r.locked[-1] and r.slip_speed_rad_s[-1] == 0.0
    # slipping with b faster than a: the clutch torque is negative (brakes b, drives a)
    slipping = (~r.locked) & (np.abs(r.slip_speed_rad_s) > 0.5)
    assert np.all(np.sign(r.clutch_torque_nm[slipping]) == np.sign(r.slip_speed_rad_s[slipping]))
    assert np.all(r.applied_force_n >= 1000.0) and np.all(r.applied_force_n <= 20000.0)
    # the open clutch lets the ice wheel flare
    assert run.open_clutch.speed_b_rad_s.max() > 5 * run.open_clutch.speed_a_rad_s.max()


def test_cli_driveline_writes_plot_and_csv(tmp_path):
    out = tmp_path / "cl"
    proc = subprocess.run([sys.executable, "-m", "clutch_sim.cli", "driveline", "--scenario", "split-mu",
                           "--rate", "500", "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "RMS error" in proc.stdout
    png = out / "split-mu.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20000
    data = np.genfromtxt(out / "split-mu.csv", delimiter=",", names=True)
    assert tuple(data.dtype.names) == CSV_COLUMNS
    assert data.size == 3500 and np.all(np.isfinite(data["slip_speed_rad_s"]))
    bad = subprocess.run([sys.executable, "-m", "clutch_sim.cli", "driveline", "--scenario", "dry-road",
                          "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 1
    assert bad.stderr.strip() == "clutch-sim driveline: error: unknown scenario 'dry-road' (known: split-mu)"
