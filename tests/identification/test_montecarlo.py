import numpy as np
import pytest

from clutch_model.identification.halving import interval_halving
from clutch_model.identification.montecarlo import chunk_indices, draw_samples, run_montecarlo
from clutch_model.plant.params import load_model

from .conftest import NOISE_NM, grid_friction_min, measured_rmse, noise_free_rmse


def test_draw_samples_reproducible_and_bounded(rc1):
    a = rc1.friction_coefficients
    A = draw_samples(a, 500, 0.05, seed=7)
    assert np.array_equal(A, draw_samples(a, 500, 0.05, seed=7))
    lo, hi = np.minimum(0.95 * a, 1.05 * a), np.maximum(0.95 * a, 1.05 * a)
    assert np.all((A >= lo) & (A <= hi))
    B = draw_samples(a, 500, 0.05, seed=7, varied=[0, 3])
    assert np.array_equal(B[:, [0, 3]], A[:, [0, 3]]) and np.all(B[:, 1] == a[1])


@pytest.mark.parametrize("x_min", [0.37, 0.02, 0.999])
def test_interval_halving_finds_minimum(x_min):
    calls = []

    def f(xs):
        xs = np.asarray(xs, float)
        calls.extend(xs.tolist())
        return np.abs(xs - x_min) ** 1.5          # unimodal, not symmetric about the midpoint
    h = interval_halving(f, 1.0, 0.0, rel_tol=1e-4)  # bounds in either order
    assert h.start_interval == (0.0, 1.0)
    assert h.x == pytest.approx(x_min, abs=2e-4)
    assert h.f == pytest.approx(abs(h.x - x_min) ** 1.5, abs=1e-15)
    assert h.interval[0] <= x_min <= h.interval[1] and h.interval[1] - h.interval[0] <= 1e-4
    assert h.evaluations == len(calls)                # the count it reports is the work it did
    assert all(0.0 <= x <= 1.0 for x in calls)
    assert len(calls) < 40                            # halving: ~2 evaluations per halving of 1e4


@pytest.fixture(scope="module")
def mc_serial(rc1, car_runs):
    return run_montecarlo(rc1, car_runs[0], n_samples=400, spread=0.05, seed=5, chunk_size=64, progress=False)


def test_montecarlo_improves_held_out_rmse(rc1, truth, car_runs, mc_serial):
    res = mc_serial
    assert res.accepted.sum() > 200
    # accepted exactly when the friction law stays positive on the box, judged on an independent grid
    grid_min = np.array([grid_friction_min(a, rc1.friction_exponent) for a in res.samples])
    assert np.array_equal(res.accepted, grid_min >= 0.0)
    assert np.all(np.isnan(res.rmse[~res.accepted])) and np.all(np.isfinite(res.rmse[res.accepted]))
    assert res.better.sum() > 0 and res.rmse_refined < res.rmse_nominal
    nominal = measured_rmse(rc1, car_runs[1])
    refined = measured_rmse(rc1.with_friction(a=res.refined_a), car_runs[1])
    assert refined < 0.5 * nominal
    assert refined < 3 * NOISE_NM
    # closer to the truth's plant torque on the held-out inputs (noise-free) than RC-1 is
    held = car_runs[1]
    assert noise_free_rmse(rc1.with_friction(a=res.refined_a), truth, held) < 0.35 * noise_free_rmse(rc1, truth, held)
    assert grid_friction_min(res.refined_a, rc1.friction_exponent) >= 0.0


def test_montecarlo_save(tmp_path, mc_serial):
    files = mc_serial.save(tmp_path, plot_coefficients=[0, 3])
    names = {p.name for p in files}
    assert {"samples.npz", "refined_model.yaml", "summary.json", "scatter.png"} <= names
    assert [p.name for p in tmp_path.glob("*.png")] == ["scatter.png"]      # one figure, not one per coefficient
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


def test_montecarlo_scatter_one_figure_a_panel_per_coefficient(tmp_path, mc_serial):
    import matplotlib.image as mpimg

    from clutch_model.identification.plots import montecarlo_scatter

    two = mpimg.imread(montecarlo_scatter(mc_serial, tmp_path / "two", coefficients=[0, 3])[0]
                       if (tmp_path / "two").mkdir() is None else None)
    (tmp_path / "all").mkdir()
    files = montecarlo_scatter(mc_serial, tmp_path / "all")
    assert [p.name for p in files] == ["scatter.png"] and len(mc_serial.varied) == 20
    every = mpimg.imread(files[0])
    # 20 panels: 5 columns x 4 rows; 2 panels: 2 columns x 1 row
    assert every.shape[0] > 2.5 * two.shape[0] and every.shape[1] > 2 * two.shape[1]
