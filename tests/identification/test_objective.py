"""The one torque least-squares objective: its ridge and linear prior rows (pseudo-observations
of the ridged parameters) and their Jacobian, checked against a linear model whose exact least
squares solution is known."""
import numpy as np
from scipy.optimize import least_squares

from clutch_model.identification.objective import TorqueLeastSquares


def _linear_problem(seed=3):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(200, 4))
    x_true = np.array([1.0, -2.0, 0.5, 0.3])
    y = a @ x_true + 0.01 * rng.normal(size=200)
    return a, y


def test_prior_rows_and_jacobian_solve_the_augmented_least_squares():
    a, y = _linear_problem()
    ridge, prior = 2.0, np.array([[0.0, 0.0, 3.0, 1.0], [0.0, 0.0, 0.0, 5.0]])[:, 2:]   # on x[2:]
    obj = TorqueLeastSquares(lambda xs: np.array([a @ x for x in xs]), y, np.ones(200, bool),
                             ridge=ridge, ridge_index=slice(2, None), prior=prior)
    x = np.array([0.9, -1.8, 0.4, 0.2])
    r = obj.residuals(x)
    assert r.size == 200 + 2 + 2
    np.testing.assert_allclose(r[202:], prior @ x[2:])
    jac = obj.jacobian(x)
    np.testing.assert_allclose(jac[:200], a, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(jac[200:202, 2:], ridge * np.eye(2))
    np.testing.assert_allclose(jac[202:, 2:], prior)
    assert not jac[200:, :2].any()
    # the solution is the augmented normal equations' (independent of the objective's code)
    big = np.vstack([a, np.hstack([np.zeros((2, 2)), ridge * np.eye(2)]), np.hstack([np.zeros((2, 2)), prior])])
    x_ref = np.linalg.lstsq(big, np.concatenate([y, np.zeros(4)]), rcond=None)[0]
    sol = least_squares(obj.residuals, np.zeros(4), jac=obj.jacobian, xtol=1e-12, ftol=1e-12)
    np.testing.assert_allclose(sol.x, x_ref, rtol=1e-6, atol=1e-8)


def test_no_prior_is_the_plain_ridge():
    a, y = _linear_problem()
    plain = TorqueLeastSquares(lambda xs: np.array([a @ x for x in xs]), y, np.ones(200, bool), ridge=1.0)
    empty = TorqueLeastSquares(lambda xs: np.array([a @ x for x in xs]), y, np.ones(200, bool), ridge=1.0,
                               prior=np.zeros((0, 4)))
    x = np.array([0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(plain.residuals(x), empty.residuals(x))
    np.testing.assert_array_equal(plain.jacobian(x), empty.jacobian(x))
