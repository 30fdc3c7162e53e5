import numpy as np
import pytest

from clutch_model.identification import box
from clutch_model.identification.evaluate import CampaignInputs, rmse_of
from clutch_model.identification.halving import interval_halving
from clutch_model.identification.montecarlo import chunk_indices, draw_samples, run_montecarlo
from clutch_model.plant.params import load_model

from .conftest import NOISE_NM, grid_friction_min


def test_draw_samples_reproducible_and_bounded(rc1):
    a = rc1.friction_coefficients
    A = draw_samples(a, 500, 0.05, seed=7)
    assert np.array_equal(A, draw_samples(a, 500, 0.05, seed=7))
    lo, hi = np.minimum(0.95 * a, 1.05 * a), np.maximum(0.95 * a, 1.05 * a)
    assert np.all((A >= lo) & (A <= hi))
    B = draw_samples(a, 500, 0.05, seed=7, varied=[0, 3])
    assert np.array_equal(B[:, [0, 3]], A[:, [0, 3]]) and np.all(B[:, 1] == a[1])


def test_interval_halving_finds_minimum():
    seen = []

    def f(xs):
        seen.extend(np.atleast_1d(xs).tolist())
        return (np.asarray(xs) - 0.37) ** 2

    h = interval_halving(f, 0.0, 1.0, rel_tol=1e-4)
    assert h.x == pytest.approx(0.37, abs=1e-3)
    assert h.evaluations == len(seen)                # the count it reports is what it evaluated


@pytest.fixture(scope="module")
def mc_serial(rc1, car_runs):
    return run_montecarlo(rc1, car_runs[0], n_samples=400, spread=0.05, seed=5, chunk_size=64, progress=False)


def test_montecarlo_improves_held_out_rmse(rc1, car_runs, mc_serial):
    res = mc_serial
    assert res.accepted.sum() > 200
    # accepted samples keep friction >= 0 on an independent dense grid of the car box
    for a in res.samples[res.accepted][:25]:
        assert grid_friction_min(a, rc1.friction_exponent) >= 0.0
    assert np.all(np.isnan(res.rmse[~res.accepted])) and np.all(np.isfinite(res.rmse[res.accepted]))
    assert res.better.sum() > 0 and res.rmse_refined < res.rmse_nominal
    inp = CampaignInputs.from_campaign(car_runs[1], rc1)
    nominal = rmse_of(rc1.vector(), rc1.friction_coefficients[None], inp)[0]
    refined = rmse_of(rc1.vector(), res.refined_a[None], inp)[0]
    assert refined < 0.5 * nominal
    assert refined < 3 * NOISE_NM
    assert box.friction_positive(res.refined_a, rc1.friction_exponent)


def test_montecarlo_save(tmp_path, mc_serial):
    files = mc_serial.save(tmp_path, plot_coefficients=[0, 3])
    names = {p.name for p in files}
    assert {"samples.npz", "refined_model.yaml", "summary.json", "scatter_a0.png", "scatter_a3.png"} <= names
    z = np.load(tmp_path / "samples.npz")
    assert {"samples", "rmse", "accepted", "seed", "spread"} <= set(z.files)
    assert int(z["seed"]) == 5 and float(z["spread"]) == 0.05
    assert np.allclose(load_model(tmp_path / "refined_model.yaml").friction_coefficients, mc_serial.refined_a)


def test_dask_local_cluster_equals_serial(rc1, car_runs):
    runs = car_runs[0][:2]
    kw = dict(n_samples=120, spread=0.2, seed=9, chunk_size=32, progress=False, halving=(3,))
    serial = run_montecarlo(rc1, runs, **kw)
    dask = run_montecarlo(rc1, runs, scheduler="local", **kw)
    assert (~serial.accepted).any()                  # some samples rejected at +-20 %
    assert len(chunk_indices(serial.accepted, 32)) > 2
    assert np.array_equal(serial.samples, dask.samples)
    assert np.array_equal(serial.accepted, dask.accepted)
    assert np.array_equal(serial.rmse, dask.rmse, equal_nan=True)
    assert np.array_equal(serial.refined_a, dask.refined_a)
    assert "LocalCluster" in dask.scheduler
