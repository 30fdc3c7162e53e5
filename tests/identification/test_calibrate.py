import numpy as np
import pytest

from clutch_model.errors import FitError
from clutch_model.identification import box
from clutch_model.identification.calibrate import calibrate_friction
from clutch_model.identification.evaluate import CampaignInputs, rmse_of

from clutch_model import simulate
from clutch_model.plant.friction import stribeck

from .conftest import NOISE_NM


def held_out_rmse(model, runs):
    inp = CampaignInputs.from_campaign(runs, model)
    return float(rmse_of(model.vector(), model.friction_coefficients[None, :], inp)[0])


def test_calibration_reaches_noise_floor_on_held_out_runs(rc1, truth, car_runs):
    fit_runs, held = car_runs
    res = calibrate_friction(rc1, fit_runs)
    before, after = held_out_rmse(rc1, held), held_out_rmse(res.model, held)
    assert before > 5 * NOISE_NM
    assert after < 1.1 * NOISE_NM, (before, after)
    assert res.rmse_after < res.rmse_before and res.rmse_after < 1.1 * NOISE_NM
    assert 0 in res.coefficients_moved and not set(range(5, 15)) & set(res.coefficients_moved)
    assert res.positive and box.friction_positive(res.a_after, rc1.friction_exponent)
    unmoved = [k for k in range(20) if k not in res.coefficients_moved]
    assert np.array_equal(res.a_after[unmoved], rc1.friction_coefficients[unmoved])
    assert np.all(np.isfinite(res.stderr[res.coefficients_moved]))
    assert res.n_evaluations > 0
    # the friction it finds is the truth's where the car runs slip (not merely a torque fit)
    inp = CampaignInputs.from_campaign(held, truth)
    s = simulate(truth, inp.t, inp.force, inp.slip, inp.sump, run_start=inp.run_start)
    slide = ~s.locked & (s.pressure_mpa > 0.05)
    pts = (np.abs(inp.slip[slide]), s.pressure_mpa[slide], s.pack_temperature_c[slide])
    i = truth.friction_exponent
    mu_true = stribeck(truth.friction_coefficients, i, *pts)
    err_before = np.sqrt(np.mean((stribeck(rc1.friction_coefficients, i, *pts) - mu_true) ** 2))
    err_after = np.sqrt(np.mean((stribeck(res.a_after, i, *pts) - mu_true) ** 2))
    assert err_after < 0.3 * err_before, (err_before, err_after)


def test_explicit_coefficients_and_rows(rc1, car_runs):
    fit_runs, _ = car_runs
    from clutch_model.formats.bag_reader import Campaign

    camp = Campaign(list(fit_runs))
    rows = camp.run_index < 3
    res = calibrate_friction(rc1, camp, coefficients=[0, 3], rows=rows)
    assert res.coefficients_moved == [0, 3]
    assert res.rmse_after < 0.5 * res.rmse_before
    with pytest.raises(FitError):
        calibrate_friction(rc1, camp, coefficients=[25])
