import json

import numpy as np
import pytest

from clutch_model.errors import FitError
from clutch_model.identification import box, friction_fit as ff
from clutch_model.virtual_car import identification_data as td
from clutch_model.plant.friction import friction_grid
from clutch_model.plant.params import load_model


def _grid_extrema(a):
    P, T = np.meshgrid(np.linspace(0, 20, 201), np.linspace(0, 230, 231), indexing="ij")
    out = {}
    for name, k in (("mu_C", 0), ("mu_S", 5), ("omega_S", 10), ("k_V", 15)):
        v = a[k] + a[k + 1] * P + a[k + 2] * P ** 2 + a[k + 3] * T + a[k + 4] * T ** 2
        out[name] = (v.min(), v.max())
    return out


def test_stribeck_matches_kernel_and_jacobian(rc1, bench_rc1):
    a, i = rc1.friction_coefficients, rc1.friction_exponent
    b = bench_rc1
    mu, J = ff.stribeck(a, i, b.slip_speed_rad_s, b.pressure_mpa, b.plate_temperature_c, jac=True)
    assert np.allclose(mu, friction_grid(a, i, b.slip_speed_rad_s, b.pressure_mpa, b.plate_temperature_c),
                       atol=1e-14)
    for k in (0, 3, 7, 11, 13, 16, 20):
        h = 1e-7 * (abs(a[k]) if k < 20 else i)
        ap, ip = (a.copy(), i)
        if k < 20:
            ap[k] += h
        else:
            ip += h
        fd = (ff.stribeck(ap, ip, b.slip_speed_rad_s, b.pressure_mpa, b.plate_temperature_c) - mu) / h
        assert np.allclose(fd, J[:, k], rtol=1e-3, atol=1e-6 * np.abs(J[:, k]).max())


def test_recovers_truth_from_noisy_bench(rc1, bench_rc1):
    base = td.perturbed_friction(rc1, {k: 0.3 * (-1) ** k for k in range(20)}).with_friction(i=2.0)
    fit = ff.fit_friction(bench_rc1, base_model=base)
    a_true = rc1.friction_coefficients
    assert fit.rmse < 1.2 * 0.002                          # at the noise floor
    z = (fit.a - a_true) / fit.stderr[:20]
    assert np.all(np.isfinite(fit.stderr))
    assert np.max(np.abs(z)) < 4.0, z                      # within the stated uncertainty
    assert abs(fit.i - rc1.friction_exponent) < 4 * fit.stderr[20]
    # the friction itself where the bench data lives
    b = bench_rc1
    mu_fit = ff.stribeck(fit.a, fit.i, b.slip_speed_rad_s, b.pressure_mpa, b.plate_temperature_c)
    mu_true = ff.stribeck(a_true, rc1.friction_exponent, b.slip_speed_rad_s, b.pressure_mpa, b.plate_temperature_c)
    assert np.sqrt(np.mean((mu_fit - mu_true) ** 2)) < 0.0015


def test_constraints_hold_on_dense_grid_and_active_ones_reported(rc1, bench_rc1):
    fit = ff.fit_friction(bench_rc1, base_model=rc1, mu_offset=0.22, n_random_starts=1)
    g = _grid_extrema(fit.a)
    assert g["mu_S"][0] > 0
    assert 0 < g["mu_C"][0] and g["mu_C"][1] < 0.22 + 1e-9
    assert 0.001 - 1e-9 < g["omega_S"][0] and g["omega_S"][1] < 0.05 + 1e-9
    assert -0.01 - 1e-9 < g["k_V"][0] and g["k_V"][1] < 0.01 + 1e-9
    assert fit.i > 0
    names = [c.name for c in fit.active_constraints]
    assert "mu_C < 0.22" in names                         # the truth's mu_C reaches 0.24
    assert all(c.satisfied for c in fit.constraints)


def test_joint_refinement_not_worse(rc1, bench_rc1):
    two = ff.fit_friction(bench_rc1, base_model=rc1, n_random_starts=0)
    joint = ff.fit_friction(bench_rc1, base_model=rc1, n_random_starts=0, joint=True)
    assert joint.rmse <= two.rmse + 1e-12
    assert box.constraints_satisfied(joint.a, joint.i, joint.mu_offset, tol=1e-7)


def test_save_writes_model_header_and_sidecar(tmp_path, rc1, bench_rc1):
    fit = ff.fit_friction(bench_rc1, base_model=rc1, n_random_starts=0)
    y, j = fit.save(tmp_path / "m.yaml")
    text = y.read_text()
    assert text.startswith("# fit-friction:") and "active constraints:" in text
    m = load_model(y)
    assert np.allclose(m.friction_coefficients, fit.a) and m.friction_exponent == pytest.approx(fit.i)
    assert m.data["geometry"] == rc1.data["geometry"]
    side = json.loads(j.read_text())
    assert side["rmse"] == pytest.approx(fit.rmse) and "active_constraints" in side and "a4" in side["stderr"]


def test_too_little_data_is_a_fit_error(bench_rc1):
    with pytest.raises(FitError):
        ff.fit_friction(bench_rc1.subset(np.arange(5)))


# a rig whose slowest slip step (0.03 rad/s) is not on the static plateau of RC-1 (omega_S ~0.03)
SLIPS_FROM_003 = (0.03, 0.06, 0.13, 0.28, 0.6, 1.25, 2.65, 5.6, 11.9, 25.0)
RIG_PRESSURES, RIG_SUMPS = (0.3, 0.8, 1.5, 2.5, 3.5, 4.5), (25.0, 55.0, 85.0, 115.0)


def _below_bench_error(fit, truth, w=0.003):
    """RMS relative friction error at a slip below the bench's slowest, over the car's P and theta."""
    P, T = np.meshgrid([0.5, 1.5, 3.0], [40.0, 70.0, 100.0], indexing="ij")
    W = np.full(P.size, w)
    mt = friction_grid(truth.friction_coefficients, truth.friction_exponent, W, P.ravel(), T.ravel())
    mf = friction_grid(fit.a, fit.i, W, P.ravel(), T.ravel())
    return float(np.sqrt(np.mean((mf / mt - 1.0) ** 2)))


@pytest.mark.parametrize("seed", [1, 2])
def test_joint_refinement_recovers_the_friction_below_the_slowest_bench_slip(rc1, seed):
    """Step 1 takes mu_S from the 0.03 rad/s rows, where the friction is already on its way to
    mu_C: the two-stage fit is 7-8 % off at 0.003 rad/s (its free i runs away to make up for the
    biased mu_S); refined jointly with i at its constant it is within 3 %."""
    bench = td.synthetic_bench(rc1, slips=SLIPS_FROM_003, pressures=RIG_PRESSURES, sumps=RIG_SUMPS,
                               noise=0.002, seed=seed)
    two = ff.fit_friction(bench, base_model=rc1)
    joint = ff.fit_friction(bench, base_model=rc1, joint=True)
    assert _below_bench_error(two, rc1) > 0.05
    assert _below_bench_error(joint, rc1) < 0.03
    assert joint.i == rc1.friction_exponent
    assert joint.rmse <= two.rmse + 1e-12


def test_joint_refinement_frees_i_where_the_bench_resolves_it(rc1):
    """A clutch whose Stribeck exponent is 1.5, on a bench down to 0.0005 rad/s: i at the base
    model's 3.11 fits it significantly worse, so the refinement frees it and finds 1.5."""
    truth = rc1.with_friction(i=1.5)
    joint = ff.fit_friction(td.synthetic_bench(truth, noise=0.002, seed=1), base_model=rc1, joint=True)
    assert joint.i == pytest.approx(1.5, abs=0.1)
    assert any("i free" in w and "significantly better" in w for w in joint.warnings)


def test_joint_refinement_keeps_mu_s_where_no_bench_row_sees_it(rc1):
    """A bench from 0.1 rad/s never sees mu_S (omega_S ~0.03 rad/s): mu_S keeps step 1's value
    rather than wandering unconstrained below the bench's slips."""
    bench = td.synthetic_bench(rc1, slips=SLIPS_FROM_003[2:], pressures=RIG_PRESSURES, sumps=RIG_SUMPS,
                               noise=0.002, seed=1)
    two = ff.fit_friction(bench, base_model=rc1, fit_i=False)
    joint = ff.fit_friction(bench, base_model=rc1, joint=True)
    assert any("no bench row sees mu_S" in w for w in joint.warnings)
    np.testing.assert_array_equal(joint.a[5:10], two.a[5:10])
