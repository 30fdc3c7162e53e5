"""The static friction (mu_S, omega_S) of the written models, fitted on the rows before each lock
phase: recovered on data with a known truth, left alone when it is already right, and never fed
a locked row (where the driveline sets the torque) or a row whose slip sign is sensor noise."""
from __future__ import annotations

import numpy as np
import pytest

from clutch_model.diagnosis.lockup import campaign_lockup
from clutch_model.diagnosis.static_friction import (fit_static_friction, lock_entry_rows, with_entry_torque,
                                                    _static_at)
from clutch_model.formats.bag_reader import Campaign, Run
from clutch_model.plant.params import load_model
from clutch_model.plant.simulate import simulate
from clutch_model.prediction import predict_campaign

RATE_HZ = 500.0


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _true_slip(t, sign):
    """Slipping at 3 rad/s, a 0.4 s approach to a 1 s lock phase, a release, three times."""
    lock = np.zeros_like(t)
    for start in (1.0, 3.2, 5.4):
        lock = np.maximum(lock, _smoothstep((t - start) / 0.4) - _smoothstep((t - start - 1.4) / 0.4))
    slip = sign * 3.0 * (1.0 - lock)
    slip[lock > 0.9999] = 0.0
    return slip


def _campaign(truth, seed: int):
    rng = np.random.default_rng(seed)
    runs = []
    for k, sign in enumerate((1.0, -1.0)):
        t = np.arange(0.0, 7.5, 1.0 / RATE_HZ)
        slip = _true_slip(t, sign)
        force = 4000.0 + 3000.0 * _smoothstep(t / 2.0) + 1000.0 * np.sin(0.7 * t)
        sim = simulate(truth, t, force, slip, 60.0)
        locked = np.abs(slip) == 0.0
        torque = sim.torque_nm.copy()
        torque[locked] *= 0.6                                 # the driveline's torque, below capacity
        torque += rng.normal(0.0, 2.0, t.size)
        slip_measured = slip + np.where(locked, rng.normal(0.0, 2e-4, t.size),
                                        rng.normal(0.0, 3e-3, t.size))
        runs.append(Run(name=f"run{k}", t=t, applied_force_n=force, slip_speed_rad_s=slip_measured,
                        sump_temperature_c=np.full(t.size, 60.0), torque_measured_nm=torque,
                        start_time_ns=int(k * 100e9)))
    return Campaign(runs), [np.abs(_true_slip(r.t, 1.0)) == 0.0 for r in runs]


def _with_static(model, d_mu_s, omega_s):
    a = model.friction_coefficients.copy()
    a[5] += d_mu_s
    a[10] = omega_s
    return model.with_friction(a=a)


@pytest.fixture(scope="module")
def reference():
    return load_model(None)


def test_entry_rows_slip_before_each_lock_phase_and_never_inside_one(reference):
    truth = _with_static(reference, 0.04, 0.03)
    camp, true_locked = _campaign(truth, seed=1)
    rows, entries = lock_entry_rows(camp, campaign_lockup(camp))
    assert entries == 6                                     # three phases in each of two runs
    locked = np.concatenate(true_locked)
    assert rows.sum() > 100
    assert not np.any(rows & locked)                       # no row the driveline sets
    # every row carries the sign of its run's approach (a flipped sign is the sensor's noise)
    for (run, sl), sign in zip(camp.slices(), (1.0, -1.0)):
        assert np.all(np.sign(run.slip_speed_rad_s[rows[sl]]) == sign)
    # and every row is within the window before a phase: the true slip below its 3 rad/s
    assert np.all(np.abs(camp.slip[rows]) < 3.0)


def test_static_friction_recovered_from_the_lock_entries(reference):
    truth = _with_static(reference, 0.04, 0.03)
    camp, _ = _campaign(truth, seed=2)
    rows, entries = lock_entry_rows(camp, campaign_lockup(camp))
    torque = [r.torque_measured_nm for r in camp.runs]
    start = _with_static(reference, -0.01, 0.05)          # the bench never slipped that slowly
    fitted, fit = fit_static_friction(start, with_entry_torque(camp, torque, rows), rows, entries)
    assert fit.kept
    # compared where the rows are: their median contact pressure and pack temperature
    sim = predict_campaign(truth, camp).sim
    p_mpa, theta_c = float(np.median(sim.pressure_mpa[rows])), float(np.median(sim.pack_temperature_c[rows]))
    mu_true, ws_true = _static_at(truth, p_mpa, theta_c)
    mu_fit, ws_fit = _static_at(fitted, p_mpa, theta_c)
    assert mu_fit == pytest.approx(mu_true, rel=0.03)
    assert fit.mu_s_after == pytest.approx(mu_true, rel=0.03)
    assert ws_fit == pytest.approx(ws_true, rel=0.35)
    assert fit.rmse_after_nm < 0.25 * fit.rmse_before_nm
    # only the static terms moved (mu_S's constant and, the rows spreading over 0.5 MPa, its
    # slope in pressure; omega_S's constant), the mechanisms kept
    moved = np.flatnonzero(fitted.friction_coefficients != start.friction_coefficients)
    assert set(moved) <= set(fit.coefficients) <= {5, 6, 8, 10}
    assert {5, 10} <= set(fit.coefficients)
    assert fitted.mechanisms == start.mechanisms


def test_static_friction_left_alone_when_already_right(reference):
    truth = _with_static(reference, 0.04, 0.03)
    camp, _ = _campaign(truth, seed=3)
    rows, entries = lock_entry_rows(camp, campaign_lockup(camp))
    torque = [r.torque_measured_nm for r in camp.runs]
    fitted, fit = fit_static_friction(truth, with_entry_torque(camp, torque, rows), rows, entries)
    assert not fit.kept
    assert fitted is truth
    assert fit.to_json()["kept"] is False


def test_too_few_lock_entries_change_nothing(reference):
    truth = _with_static(reference, 0.04, 0.03)
    camp, _ = _campaign(truth, seed=4)
    rows, entries = lock_entry_rows(camp, campaign_lockup(camp))
    one = rows & (camp.run_index == 0) & (camp.t < 2.0)
    fitted, fit = fit_static_friction(reference, camp, one, 1)
    assert fitted is reference and not fit.kept and "too few" in fit.note
