import numpy as np
import pytest

from clutch_model.errors import FitError
from clutch_model.identification.calibrate import calibrate_friction

from .conftest import NOISE_NM, TRUTH_REL, grid_friction_min, measured_rmse, noise_free_rmse


def test_calibration_recovers_the_true_clutch(rc1, truth, car_runs):
    fit_runs, held = car_runs
    res = calibrate_friction(rc1, fit_runs)
    before, after = measured_rmse(rc1, held), measured_rmse(res.model, held)
    assert before > 5 * NOISE_NM
    assert after < 1.1 * NOISE_NM, (before, after)
    assert res.rmse_after < res.rmse_before and res.rmse_after < 1.1 * NOISE_NM
    # the screen picks exactly the coefficients the truth perturbed (a0, a1, a3, a15) ...
    assert sorted(res.coefficients_moved) == sorted(TRUTH_REL)
    # ... and the calibrated plant reproduces the true plant's torque on runs it never saw, far
    # below the sensor noise (RC-1 is off by ~120 N*m there)
    assert noise_free_rmse(rc1, truth, held) > 50.0
    assert noise_free_rmse(res.model, truth, held) < 0.2 * NOISE_NM
    assert res.positive and grid_friction_min(res.a_after, rc1.friction_exponent) >= 0.0
    unmoved = [k for k in range(20) if k not in res.coefficients_moved]
    assert np.array_equal(res.a_after[unmoved], rc1.friction_coefficients[unmoved])
    assert np.all(np.isfinite(res.stderr[res.coefficients_moved]))
    assert res.n_evaluations > 0


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
