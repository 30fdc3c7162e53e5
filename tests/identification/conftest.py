"""Shared synthetic data with known truth for the identification tests."""
import numpy as np
import pytest

from clutch_model import load_model, predict_measured_torque, simulate
from clutch_model.formats.bag_reader import Campaign
from clutch_model.virtual_car import identification_data as td

NOISE_NM = 15.0
# friction perturbation of the "true" car clutch against RC-1 (the bench fit)
TRUTH_REL = {0: -0.05, 1: 0.10, 3: 0.12, 15: 0.25}


@pytest.fixture(scope="session")
def rc1():
    return load_model()


@pytest.fixture(scope="session")
def truth(rc1):
    return td.perturbed_friction(rc1, TRUTH_REL)


@pytest.fixture(scope="session")
def car_runs(truth):
    """8 runs x 9 s x 200 Hz from the perturbed truth + 15 N*m noise: 6 to fit, 2 held out."""
    runs = td.synthetic_runs(truth, n_runs=8, duration_s=9.0, rate_hz=200.0, noise_nm=NOISE_NM, seed=11)
    return runs[:6], runs[6:]


@pytest.fixture(scope="session")
def bench_rc1(rc1):
    return td.synthetic_bench(rc1, noise=0.002, seed=3)


def stribeck_mu(a, i, P, T, W, pinned=True):
    """The Stribeck friction law written out independently of the package:
    mu = g0 + (g1 - g0) exp(-(|w| / ws)^i) + g3 |w|, each g a quadratic in P (MPa) and T (C).
    ``pinned``: as the plant evaluates it (docs/model.md): P clamped to [0, 20] MPa, T to
    [0, 230] C, mu floored at 0; without it, the raw law (for positivity checks)."""
    a = np.asarray(a, float)
    P, T, W = (np.asarray(x, float) for x in (P, T, W))
    if pinned:
        P, T = np.clip(P, 0.0, 20.0), np.clip(T, 0.0, 230.0)

    def poly(k):
        return a[k] + a[k + 1] * P + a[k + 2] * P ** 2 + a[k + 3] * T + a[k + 4] * T ** 2

    ws = np.maximum(poly(10), 1e-6)
    mu = poly(0) + (poly(5) - poly(0)) * np.exp(-(np.abs(W) / ws) ** i) + poly(15) * np.abs(W)
    return np.maximum(mu, 0.0) if pinned else mu


def grid_friction_min(a, i, p=(0, 6), th=(0, 230), w=(0, 30)):
    """Independent dense-grid evaluation of the raw Stribeck law (no code shared with box)."""
    P, T, W = np.meshgrid(np.linspace(*p, 31), np.linspace(*th, 47),
                          np.concatenate([np.linspace(*w, 61), np.geomspace(1e-4, w[1], 60)]), indexing="ij")
    return float(stribeck_mu(a, i, P, T, W, pinned=False).min())


def noise_free_rmse(model, truth, runs):
    """RMSE between the model's and the truth's plant torque on the runs' inputs (no noise)."""
    camp = Campaign(list(runs))

    def torque(m):
        return simulate(m, camp.t, camp.force, camp.slip, camp.sump, run_start=camp.run_start).torque_nm

    return float(np.sqrt(np.mean((torque(model) - torque(truth)) ** 2)))


def measured_rmse(model, runs):
    """RMSE of the model's predicted sensor torque against the runs' measured torque, computed
    from the public simulator (not the identification code path)."""
    camp = Campaign(list(runs))
    sim = simulate(model, camp.t, camp.force, camp.slip, camp.sump, run_start=camp.run_start)
    pred = predict_measured_torque(model, camp.t, sim.torque_nm, camp.run_start)
    return float(np.sqrt(np.mean((pred - camp.torque_measured) ** 2)))
