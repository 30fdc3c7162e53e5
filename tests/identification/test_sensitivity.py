import numpy as np
import pytest

from clutch_model.identification import sensitivity as se
from clutch_model.plant.friction import friction_grid


def test_scale_friction_scales_mu_exactly(rc1):
    a = rc1.friction_coefficients
    w, p, t = np.array([0.0, 0.01, 0.05, 1.0, 20.0]), np.full(5, 2.0), np.full(5, 80.0)
    mu = friction_grid(rc1.friction_coefficients, rc1.friction_exponent, w, p, t)
    for f in (0.99, 1.01):
        mu_s = friction_grid(se.scale_friction(a, f), rc1.friction_exponent, w, p, t)
        assert np.allclose(mu_s, f * mu, rtol=1e-12)


def test_thesis_friction_sensitivity(rc1):
    fs = se.friction_sensitivity(rc1)
    assert fs.scenario.slip_rad_s == pytest.approx(2 * np.pi) and fs.scenario.pressure_mpa == 0.5
    s_abs, s_norm = fs.steady_mean()
    assert 0.8 < s_norm < 1.05            # asperity torque ~ mu_f: torque is ~proportional to mu_f
    assert s_abs > 0 and 0.1 < fs.steady_from_s < 2.0
    assert np.all(fs.torque_plus[fs.steady] > fs.torque_nominal[fs.steady])


def test_parameter_sensitivities_two_steps_agree(rc1):
    rows, t_ss, t_mean = se.parameter_sensitivities(rc1)
    names = [r.name for r in rows]
    assert len(names) == len(set(names)) >= 40
    assert all(r.agree for r in rows), [r.name for r in rows if not r.agree]
    top = {r.name: r.s for r in rows[:6]}
    assert top["friction.a0"] == pytest.approx(rows[0].s) and top["geometry.friction_surfaces"] > 0.9
    by = {r.name: r.s for r in rows}
    assert by["friction.a5"] == 0.0                # static friction plays no part while slipping


def test_identifiability_screen_on_slipping_car_runs(rc1, car_runs):
    scr = se.identifiability_screen(rc1, car_runs[0])
    sel = set(scr.selected)
    assert 0 in sel and 3 in sel
    assert not sel & set(range(5, 15))             # mu_S, omega_S invisible without lock-up
    assert scr.collinearity <= 15.0
    assert se.identifiable_coefficients(rc1, car_runs[0]) == scr.selected
