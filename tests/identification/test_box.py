import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clutch_model.identification import box

from .conftest import grid_friction_min

coef = st.floats(-1.0, 1.0, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(st.lists(coef, min_size=5, max_size=5))
def test_poly_range_is_exact(c):
    c = np.array(c) * np.array([1, 1 / 20, 1 / 400, 1 / 230, 1 / 230 ** 2])
    lo, hi, (pl, tl), (ph, th) = box.poly_range(c)
    pg, tg = np.meshgrid(np.linspace(0, 20, 401), np.linspace(0, 230, 461), indexing="ij")
    vals = box.eval_poly(c, pg, tg)
    assert lo <= vals.min() + 1e-12 and hi >= vals.max() - 1e-12     # never misses the extremes
    assert vals.min() - lo < 1e-3 * (abs(vals).max() + 1e-9)         # and is attained (grid is fine)
    assert 0 <= pl <= 20 and 0 <= tl <= 230
    assert abs(box.eval_poly(c, pl, tl) - lo) < 1e-12 and abs(box.eval_poly(c, ph, th) - hi) < 1e-12


def test_rc1_satisfies_chapter4_constraints_over_box(rc1):
    reps = box.check_constraints(rc1.friction_coefficients, rc1.friction_exponent, mu_offset=0.3)
    assert all(r.satisfied for r in reps), [r.describe() for r in reps if not r.satisfied]
    g = box.grid_extrema(rc1.friction_coefficients)
    assert g["omega_S"][1] < 0.05 and g["omega_S"][0] > 0.001 and g["mu_S"][0] > 0


def test_rc1_friction_positive_on_car_box(rc1):
    a, i = rc1.friction_coefficients, rc1.friction_exponent
    assert box.friction_positive(a, i)
    assert grid_friction_min(a, i) > 0


def test_friction_positive_rejects_negative_static_friction(rc1):
    a = rc1.friction_coefficients.copy()
    a[8] *= 1.3            # mu_S at 230 C goes below zero
    assert grid_friction_min(a, rc1.friction_exponent) < 0
    assert not box.friction_positive(a, rc1.friction_exponent)


def test_friction_positive_many_agrees_with_independent_grid(rc1):
    rng = np.random.default_rng(0)
    a0, i = rc1.friction_coefficients, rc1.friction_exponent
    A = a0 * (1 + 0.25 * (2 * rng.random((150, 20)) - 1))
    ok = box.friction_positive_many(A, i)
    grid = np.array([grid_friction_min(a, i) for a in A])
    assert 0.1 < ok.mean() < 0.95
    assert not np.any(ok & (grid < 0))          # sound: never accepts a grid-negative sample
    assert np.all(ok[grid > 1e-3])              # and accepts the clearly positive ones


@pytest.mark.parametrize("status_case", ["positive", "negative"])
def test_branch_and_bound_status(rc1, status_case):
    a = rc1.friction_coefficients.copy()
    if status_case == "negative":
        a[15] = -0.02      # k_V * w drives mu_f negative at high slip
    st_, best, lb = box.friction_min_bb(a, rc1.friction_exponent, 0.0, 6.0, 0.0, 230.0, 0.0, 30.0, 100000)
    assert st_ == (1 if status_case == "positive" else -1)
