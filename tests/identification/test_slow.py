"""Heavier identification checks (pytest -m slow)."""
import numpy as np
import pytest

from clutch_model.identification.calibrate import calibrate_friction
from clutch_model.identification.evaluate import CampaignInputs, rmse_of
from clutch_model.identification.montecarlo import run_montecarlo

from .conftest import NOISE_NM

pytestmark = pytest.mark.slow


def test_dask_scheduler_address_equals_serial(rc1, car_runs):
    from dask.distributed import LocalCluster

    kw = dict(n_samples=300, spread=0.05, seed=4, chunk_size=64, progress=False)
    serial = run_montecarlo(rc1, car_runs[0], **kw)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cl:
        remote = run_montecarlo(rc1, car_runs[0], scheduler=cl.scheduler_address, **kw)
    assert np.array_equal(serial.rmse, remote.rmse, equal_nan=True)
    assert np.array_equal(serial.refined_a, remote.refined_a)


def test_gradient_beats_monte_carlo_at_equal_budget(rc1, truth, car_runs):
    fit, held = car_runs
    hin = CampaignInputs.from_campaign(held, rc1)
    ls = calibrate_friction(rc1, fit)
    mc = run_montecarlo(rc1, fit, n_samples=ls.n_evaluations, spread=0.2, seed=2, progress=False)
    r_ls = rmse_of(rc1.vector(), ls.a_after[None], hin)[0]
    r_mc = rmse_of(rc1.vector(), mc.refined_a[None], hin)[0]
    r_nom = rmse_of(rc1.vector(), rc1.friction_coefficients[None], hin)[0]
    assert r_ls < 1.1 * NOISE_NM and r_mc < 0.5 * r_nom
    assert r_ls <= r_mc
    # the LS standard errors cover the truth for the moved coefficients (within 4 sigma)
    k = ls.coefficients_moved
    z = (ls.a_after[k] - truth.friction_coefficients[k]) / ls.stderr[k]
    assert np.all(np.abs(z) < 4.0), z
