"""The second-order force path, the rival beyond the catalog of a named time mechanism
(clutch_model/diagnosis/force_dynamics.py)."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from clutch_model.diagnosis.force_dynamics import group_delay_s, second_order_force, time_mechanism_ids
from clutch_model.plant.mechanisms import make_mechanism


def _reference(t, force, f_n, zeta):
    """solve_ivp (tight tolerance) on the force linear between rows, from rest at the first."""
    w = 2 * np.pi * f_n

    def rhs(tt, z):
        return [z[1], w * w * (np.interp(tt, t, force) - z[0]) - 2 * zeta * w * z[1]]
    sol = solve_ivp(rhs, (t[0], t[-1]), [force[0], 0.0], t_eval=t, rtol=1e-10, atol=1e-8, method="DOP853",
                    max_step=float(np.min(np.diff(t))))
    return sol.y[0]


@pytest.mark.parametrize("f_n,zeta", [(2.4, 0.6), (1.0, 2.5), (8.0, 0.3)])
def test_second_order_force_matches_solve_ivp_on_jittered_rows(f_n, zeta):
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.004, 0.016, 700))          # rows on a jittered ~100 Hz clock
    force = 2000 + 1500 * np.sin(2 * np.pi * 0.7 * t) + 800 * (np.sin(2 * np.pi * 0.23 * t) > 0)
    run_start = np.zeros(t.size, bool)
    run_start[0] = True
    got = second_order_force(t, force, run_start, f_n, zeta)
    np.testing.assert_allclose(got, _reference(t, force, f_n, zeta), rtol=0, atol=1e-5 * np.ptp(force))


def test_second_order_force_restarts_each_run_and_keeps_a_held_force():
    t = np.r_[np.arange(0, 5, 0.005), np.arange(0, 5, 0.005)]
    force = np.r_[np.full(1000, 3000.0), np.full(1000, 500.0)]
    force[200:1000] = 6000.0                                 # a step in the first run
    run_start = np.zeros(t.size, bool)
    run_start[[0, 1000]] = True
    got = second_order_force(t, force, run_start, 2.0, 0.7)
    assert got[0] == 3000.0 and got[199] == 3000.0           # at rest at the request
    np.testing.assert_allclose(got[1000:], 500.0)            # the second run starts from its own force
    assert got[999] == pytest.approx(6000.0, rel=1e-6)       # unit gain once settled
    peak = got[200:1000].max()                               # damping 0.7: 4.6 % overshoot of the step
    assert (peak - 6000.0) / 3000.0 == pytest.approx(np.exp(-np.pi * 0.7 / np.sqrt(1 - 0.49)), rel=0.02)


def test_time_mechanisms_and_their_group_delay():
    assert time_mechanism_ids(["drag_torque", "transport_delay", "actuator_lag", "torque_offset"]) == \
        ["transport_delay", "actuator_lag"]
    assert time_mechanism_ids(["torque_sensor_lag"]) == ["torque_sensor_lag"]
    mechs = [make_mechanism("transport_delay", delay_s=0.03), make_mechanism("actuator_lag", tau_s=0.05),
             make_mechanism("drag_torque", coeff_nm_per_rad_s=2.0)]
    assert group_delay_s(mechs) == pytest.approx(0.08)
