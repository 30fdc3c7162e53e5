"""The force a step-holding plant is given on sparse rows: the step's midpoint value.

Reference: the plant simulated on a 1 kHz grid (the force held over 1 ms steps, close to the
continuous force); on 50 Hz rows the force held from each row is 10 ms late on average, the
midpoint force is not. The torque at the rows is compared with the 1 kHz reference there."""
import numpy as np

from clutch_model.diagnosis.input_hold import force_at_step_midpoints
from clutch_model.plant.params import load_model
from clutch_model.plant.simulate import simulate


def test_midpoints_of_a_ramp_are_exact():
    t = np.array([0.0, 0.02, 0.05, 0.06])
    ts = np.linspace(0.0, 0.1, 11)
    f = force_at_step_midpoints(t, ts, 100.0 + 2000.0 * ts)
    assert np.allclose(f, 100.0 + 2000.0 * np.array([0.01, 0.035, 0.055, 0.06]), rtol=0, atol=1e-9)


def test_midpoint_force_removes_the_half_step_lag():
    model = load_model(None)
    fine = np.arange(0, 3.0, 1e-3)
    force = 3000.0 + 2500.0 * np.sin(2 * np.pi * 1.5 * fine)           # controller-like sweep
    slip = np.full(fine.size, 15.0)
    sump = np.full(fine.size, 60.0)
    ref = simulate(model, fine, force, slip, sump).torque_nm
    rows = np.arange(0, fine.size, 20)                                  # 50 Hz rows
    t = fine[rows]
    held = simulate(model, t, force[rows], slip[rows], sump[rows]).torque_nm
    mid = simulate(model, t, force_at_step_midpoints(t, fine, force), slip[rows], sump[rows]).torque_nm
    late = slice(10, None)                                              # after the first engagement
    err_held = np.sqrt(np.mean((held - ref[rows])[late] ** 2))
    err_mid = np.sqrt(np.mean((mid - ref[rows])[late] ** 2))
    assert err_held > 1.0                                               # the hold is visibly late
    assert err_mid < 0.2 * err_held, (err_held, err_mid)
