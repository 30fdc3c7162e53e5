"""The clutch in the driveline against independent expectations: closed-form solutions of two
inertias coupled by a constant-capacity clutch (lock time, common acceleration, transmitted
torque, breaking loose, with and without viscous losses), momentum balance, a slipping phase
of the full plant against solve_ivp(Radau, rtol=1e-9) on the independent transcription of the
thesis, and the step simulator against the trajectory simulator."""
import math

import numpy as np
import pytest
import yaml
from hypothesis import given, settings, strategies as st
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from clutch_model import ClutchModel, DrivelineParams, DrivelinePlant, load_model, simulate_driveline
from clutch_model.plant import driveline as DL
from clutch_model.plant import kernels as K
from clutch_model.plant.params import REFERENCE_CLUTCH

from .reference_plant import ReferencePlant

RAW = yaml.safe_load(REFERENCE_CLUTCH.read_text())
MODEL = load_model()
MU = 0.12


def coulomb_clutch(force_n: float):
    """RC-1 made a Coulomb clutch: mu_f = MU at every slip, pressure and temperature (mu_C =
    mu_S, k_V = 0), a vanishing oil viscosity (no hydrodynamic torque) and the film started at
    its asperity equilibrium for ``force_n`` (A_N P_a(h*) = F, from an independent root solve).
    Its static and sliding torque are then both MU * F * TA_GEOM / A_N."""
    raw = yaml.safe_load(REFERENCE_CLUTCH.read_text())
    a = [0.0] * 20
    a[0] = a[5] = MU
    a[10] = 1.0
    raw["friction"]["a"] = a
    raw["viscosity"]["alpha0"] = 1e-12
    ref = ReferencePlant(raw)
    h_star = brentq(lambda h: ref.AN * ref.pa(h) - force_n, 1e-12, 30 * ref.sigma, xtol=1e-20, rtol=1e-15)
    raw["initial"]["film_thickness"] = h_star
    model = ClutchModel.from_dict(raw)
    geom = ref.nf * (ref.ro ** 3 - ref.ri ** 3) / 3 * 2 * math.pi
    return model, MU * force_n * geom / ref.AN


FORCE = 5000.0
COULOMB, CAPACITY = coulomb_clutch(FORCE)   # capacity ~ 393 N m


def test_coulomb_clutch_has_constant_capacity():
    t = np.arange(0, 0.5, 0.001)
    r = simulate_driveline(COULOMB, t, FORCE, 300.0, -100.0, 60.0,
                           DrivelineParams(0.5, 1.2, 0.0, 0.0, 40.0, 10.0))
    np.testing.assert_allclose(r.static_capacity_nm, CAPACITY, rtol=1e-9)
    slipping = ~r.locked
    np.testing.assert_allclose(r.clutch_torque_nm[slipping], CAPACITY, rtol=1e-9)


@pytest.mark.parametrize("ca,cb", [(0.0, 0.0), (2.0, 0.8)])
def test_lock_time_common_acceleration_and_transmitted_torque(ca, cb):
    """Slip decays at constant clutch torque C, locks at the analytic instant, then both sides
    run at one speed with (J_a+J_b) dw/dt = tau_a + tau_b - (c_a+c_b) w and the clutch carries
    T_lock = (J_b (tau_a - c_a w) - J_a (tau_b - c_b w)) / (J_a + J_b)."""
    ja, jb, tau_a, tau_b, wa0, wb0 = 0.5, 1.2, 300.0, -100.0, 40.0, 10.0
    t = np.arange(0, 0.4, 0.001)
    r = simulate_driveline(COULOMB, t, FORCE, tau_a, tau_b, 60.0, DrivelineParams(ja, jb, ca, cb, wa0, wb0))

    def side(w0, j, c, tau, tt):     # J dw/dt = tau - c w, exact
        if c == 0.0:
            return w0 + tau / j * tt
        return tau / c + (w0 - tau / c) * np.exp(-c * tt / j)

    wa_slip = lambda tt: side(wa0, ja, ca, tau_a - CAPACITY, tt)  # noqa: E731
    wb_slip = lambda tt: side(wb0, jb, cb, tau_b + CAPACITY, tt)  # noqa: E731
    t_lock = brentq(lambda tt: wa_slip(tt) - wb_slip(tt), 0.0, 0.4, xtol=1e-15)
    w_lock = float(wa_slip(t_lock))
    before, after = t < t_lock, t > t_lock
    assert not r.locked[before].any() and r.locked[after].all()
    # exact for constant torques; with losses the 2nd-order speed steps (1 ms) are within 1e-6
    rtol = 1e-9 if ca == cb == 0.0 else 1e-6
    np.testing.assert_allclose(r.speed_a_rad_s[before], wa_slip(t[before]), rtol=rtol, atol=1e-9)
    np.testing.assert_allclose(r.speed_b_rad_s[before], wb_slip(t[before]), rtol=rtol, atol=1e-9)
    w_common = side(w_lock, ja + jb, ca + cb, tau_a + tau_b, t[after] - t_lock)
    np.testing.assert_allclose(r.speed_a_rad_s[after], w_common, rtol=rtol)
    np.testing.assert_array_equal(r.speed_a_rad_s[after], r.speed_b_rad_s[after])
    assert np.all(r.slip_speed_rad_s[after] == 0.0)
    t_lock_expected = (jb * (tau_a - ca * w_common) - ja * (tau_b - cb * w_common)) / (ja + jb)
    np.testing.assert_allclose(r.clutch_torque_nm[after], t_lock_expected, rtol=rtol)
    if ca == cb == 0.0:   # the closed forms of the issue
        assert t_lock == pytest.approx((wa0 - wb0) / ((CAPACITY - tau_a) / ja + (CAPACITY + tau_b) / jb))
        np.testing.assert_allclose(np.diff(r.speed_a_rad_s[after]) / 0.001, (tau_a + tau_b) / (ja + jb), rtol=1e-9)
        np.testing.assert_allclose(r.clutch_torque_nm[after], (jb * tau_a - ja * tau_b) / (ja + jb), rtol=1e-12)
    if ca == cb == 0.0:   # heat: the slip falls linearly, so E = C * s0 * t_lock / 2 at lock-up
        assert r.energy_j[after][0] == pytest.approx(CAPACITY * (wa0 - wb0) * t_lock / 2, rel=1e-9)
    # no heat while locked
    np.testing.assert_array_equal(r.power_w[after], 0.0)
    assert np.all(np.diff(r.energy_j[after]) == 0.0)


def test_breaks_loose_when_the_needed_torque_exceeds_the_capacity_and_relocks():
    """Locked at rest; tau_b = -k t makes T_lock = J_a k t / (J_a + J_b) grow: locked until it
    reaches C at t* = C (J_a + J_b) / (J_a k), then slipping at torque C. When tau_b returns to
    0 the slip decays and the sides lock again, at the analytic instant."""
    ja, jb, k = 0.5, 1.2, 2000.0
    dt = 0.0005
    t = np.arange(0, 1.2, dt)
    t_star = CAPACITY * (ja + jb) / (ja * k)     # ~0.67 s
    t_off = 0.8
    tau_b = np.where(t < t_off, -k * t, 0.0)
    r = simulate_driveline(COULOMB, t, FORCE, 0.0, tau_b, 60.0, DrivelineParams(ja, jb, 0.0, 0.0, 5.0, 5.0))
    held = t < t_star - dt
    assert r.locked[held].all()
    np.testing.assert_allclose(r.clutch_torque_nm[held], ja * k * t[held] / (ja + jb), rtol=1e-9)
    # common speed while locked: w = 5 - k t^2 / (2 (J_a + J_b)) (row k-1's torque held over the row)
    rows = np.flatnonzero(held)[1:]
    expected = 5.0 - np.array([np.sum(k * t[:m] * dt) for m in rows]) / (ja + jb)
    np.testing.assert_allclose(r.speed_a_rad_s[rows], expected, rtol=1e-9)
    slipping = (t > t_star + dt) & (t < t_off)
    assert not r.locked[slipping].any()
    assert np.all(r.slip_speed_rad_s[slipping] > 0)
    np.testing.assert_allclose(r.clutch_torque_nm[slipping], CAPACITY, rtol=1e-9)
    # side a decelerates at C / J_a while slipping
    np.testing.assert_allclose(np.diff(r.speed_a_rad_s[slipping]) / dt, -CAPACITY / ja, rtol=1e-7)
    # after t_off: ds/dt = -C (1/J_a + 1/J_b) until the slip is gone
    k_off = np.flatnonzero(t >= t_off)[0]
    s_off = r.slip_speed_rad_s[k_off]
    t_relock = t[k_off] + s_off / (CAPACITY * (1 / ja + 1 / jb))
    assert not r.locked[(t > t_off) & (t < t_relock)].any()
    assert r.locked[t > t_relock].all()
    # exactly two lock transitions: no chatter
    assert np.count_nonzero(np.diff(r.locked.astype(int))) == 2


def test_less_force_lets_the_sides_break_loose():
    """Constant torques need T_lock = 300 N m; the force falls from 5 kN to 2 kN: the sides stay
    locked down to F* = 300 N m / (MU * TA_GEOM / A_N) and slip from there on, at the capacity."""
    ja, jb, dt = 0.5, 1.2, 0.001
    tau_a = 300.0 * (ja + jb) / jb
    t = np.arange(0, 1.0, dt)
    force = np.interp(t, [0.0, 0.2, 0.8, 1.0], [FORCE, FORCE, 2000.0, 2000.0])
    r = simulate_driveline(COULOMB, t, force, tau_a, 0.0, 60.0, DrivelineParams(ja, jb, 0.0, 0.0, 3.0, 3.0))
    # the capacity follows the asperity load of the film, which settles within a row at this
    # vanishing viscosity: at row k it carries the force held over the previous row
    carried = np.concatenate([[force[0]], force[:-1]])
    np.testing.assert_allclose(r.static_capacity_nm, CAPACITY / FORCE * carried, rtol=1e-6)
    f_star = 300.0 / (CAPACITY / FORCE)
    assert r.locked[carried > f_star * 1.001].all()
    loose = carried < f_star * 0.999
    assert not r.locked[loose].any()
    np.testing.assert_allclose(r.clutch_torque_nm[r.locked], 300.0, rtol=1e-12)
    np.testing.assert_allclose(r.clutch_torque_nm[loose], CAPACITY / FORCE * carried[loose], rtol=1e-6)
    assert np.all(r.slip_speed_rad_s[loose] > 0) and np.all(np.diff(r.slip_speed_rad_s[loose]) > 0)
    assert np.count_nonzero(np.diff(r.locked.astype(int))) == 1


def test_stays_locked_just_below_capacity_without_chatter():
    ja, jb = 0.5, 1.2
    tau_a = 0.999 * CAPACITY * (ja + jb) / jb       # T_lock = 0.999 C
    t = np.arange(0, 2.0, 0.001)
    r = simulate_driveline(COULOMB, t, FORCE, tau_a, 0.0, 60.0, DrivelineParams(ja, jb, 0.0, 0.0, 0.0, 0.0))
    assert r.locked.all()
    assert np.all(r.slip_speed_rad_s == 0.0)
    np.testing.assert_allclose(r.clutch_torque_nm, 0.999 * CAPACITY, rtol=1e-9)
    r2 = simulate_driveline(COULOMB, t, FORCE, 1.001 * tau_a / 0.999, 0.0, 60.0,
                            DrivelineParams(ja, jb, 0.0, 0.0, 0.0, 0.0))
    assert not r2.locked[1:].any()
    assert np.all(np.diff(r2.slip_speed_rad_s) > 0)


def engagement_profile(dt=0.001, duration=3.0):
    """RC-1, warm: engage on a slipping driveline, hold, release the force slowly (breaks loose),
    engage again."""
    t = np.arange(0, duration, dt)
    force = np.interp(t, [0, 0.2, 0.3, 1.2, 2.0, 2.3, 3.0], [0, 0, 6000, 6000, 200, 5000, 5000])
    tau_a = 150.0 + 40.0 * np.sin(2 * np.pi * t / 0.7)
    tau_b = -60.0 * np.ones_like(t)
    return t, force, tau_a, tau_b


def test_momentum_balance_through_lock_and_break_loose():
    t, force, tau_a, tau_b = engagement_profile()
    # no losses: J_a w_a + J_b w_b changes by the external impulse exactly (row k-1's torques held)
    r = simulate_driveline(MODEL, t, force, tau_a, tau_b, 60.0, DrivelineParams(0.5, 1.2, 0.0, 0.0, 60.0, 20.0))
    assert r.locked.any() and (~r.locked).any()
    assert np.count_nonzero(np.diff(r.locked.astype(int))) >= 3
    impulse = np.concatenate([[0.0], np.cumsum((tau_a + tau_b)[:-1] * np.diff(t))])
    np.testing.assert_allclose(r.angular_momentum_nms - r.angular_momentum_nms[0], impulse,
                               rtol=1e-11, atol=1e-9 * np.abs(r.angular_momentum_nms).max())
    # with viscous losses: against the loss integral of an independent fine quadrature
    dl = DrivelineParams(0.5, 1.2, 0.4, 0.3, 60.0, 20.0)
    fine = 10
    tf = np.linspace(0, t[-1], (t.size - 1) * fine + 1)
    hold = lambda y: np.repeat(y[:-1], fine)  # noqa: E731 (row values held over the row)
    rf = simulate_driveline(MODEL, tf, np.append(hold(force), force[-1]), np.append(hold(tau_a), tau_a[-1]),
                            np.append(hold(tau_b), tau_b[-1]), 60.0, dl)
    loss = dl.damping_a_nms * rf.speed_a_rad_s + dl.damping_b_nms * rf.speed_b_rad_s
    external = np.append(hold(tau_a + tau_b), 0.0)
    integral = np.sum(external[:-1] * np.diff(tf)) - np.trapezoid(loss, tf)
    change = rf.angular_momentum_nms[-1] - rf.angular_momentum_nms[0]
    assert change == pytest.approx(integral, rel=1e-6)


def test_slipping_phase_matches_radau():
    """A slipping phase of the full RC-1 plant (film squeeze, Stribeck friction, hydrodynamic
    torque, pack heating) against solve_ivp(Radau, rtol=1e-9) on the independent transcription
    of the thesis with the two speed equations added."""
    ref = ReferencePlant(RAW)
    ja, jb, ca, cb = 2.0, 3.0, 0.3, 0.2
    tau_a, tau_b = 400.0, -100.0
    t = np.arange(0, 0.6, 0.001)
    force = np.where(t < 0.05, 0.0, 4000.0)

    def rhs(_t, y, f):
        h, theta, _e, wa, wb = y
        s = wa - wb
        T = ref.torque(h, theta, f, s)
        fkn = f * 1e-3
        b = ref.b
        htf = max(b[0] + b[1] * abs(s) + b[2] * fkn + b[3] * abs(s) * fkn, ref.htf_min)
        power = abs(s * T)
        dtheta = (power / ref.nsp - htf * ref.AN * (theta - 60.0)) / ref.cp
        return [ref.dhdt(h, f, theta), dtheta, power, (tau_a - ca * wa - T) / ja, (tau_b - cb * wb + T) / jb]

    y0 = [ref.h0, 60.0, 0.0, 90.0, 10.0]
    k_step = np.flatnonzero(force > 0)[0]
    states = [solve_ivp(rhs, (t[0], t[k_step]), y0, method="Radau", rtol=1e-9,
                        atol=[1e-15, 1e-9, 1e-6, 1e-9, 1e-9], t_eval=t[:k_step + 1], args=(0.0,))]
    states.append(solve_ivp(rhs, (t[k_step], t[-1]), states[0].y[:, -1], method="Radau", rtol=1e-9,
                            atol=[1e-15, 1e-9, 1e-6, 1e-9, 1e-9], t_eval=t[k_step:], args=(4000.0,)))
    assert all(s.success for s in states)
    y = np.concatenate([states[0].y[:, :-1], states[1].y], axis=1)
    slip_ref = y[3] - y[4]
    assert slip_ref.min() > 5.0   # the window is a slipping phase (film squeezed, slip up to ~118 and down to ~20 rad/s)
    assert slip_ref[0] - slip_ref[-1] > 50.0
    r = simulate_driveline(MODEL, t, force, tau_a, tau_b, 60.0, DrivelineParams(ja, jb, ca, cb, 90.0, 10.0))
    assert not r.locked.any()
    scale = np.abs(slip_ref).max()
    assert np.max(np.abs(r.slip_speed_rad_s - slip_ref)) < 2e-3 * scale
    assert np.max(np.abs(r.speed_a_rad_s - y[3])) < 2e-3 * scale
    np.testing.assert_allclose(r.pack_temperature_c, y[1], atol=0.02 + 2e-3 * (y[1].max() - 60.0))
    np.testing.assert_allclose(r.film_thickness_m, y[0], rtol=5e-3)


def test_step_simulator_equals_trajectory_simulator():
    t, force, tau_a, tau_b = engagement_profile(dt=0.002, duration=2.5)
    dl = DrivelineParams(0.5, 1.2, 0.1, 0.1, 60.0, 20.0)
    r = simulate_driveline(MODEL, t, force, tau_a, tau_b, 60.0, dl)
    plant = DrivelinePlant(MODEL, dl)
    plant.reset(force[0], 60.0)
    recs = np.empty((t.size, DL.N_DL_OUT))
    for k in range(t.size):
        if k:
            plant.advance(t[k] - t[k - 1])
        recs[k] = plant.sample(force[k], tau_a[k], tau_b[k], 60.0)
        assert plant.locked == r.locked[k]
    np.testing.assert_array_equal(recs[:, K.O_TORQUE], r.clutch_torque_nm)
    np.testing.assert_array_equal(recs[:, DL.R_SLIP], r.slip_speed_rad_s)
    stepper = DrivelinePlant(MODEL, dl)
    stepper.reset(force[0], 60.0)
    first = stepper.sample(force[0], tau_a[0], tau_b[0], 60.0)[K.O_TORQUE]
    stepped = [first] + [stepper.step(t[k] - t[k - 1], force[k], tau_a[k], tau_b[k], 60.0)[K.O_TORQUE]
                         for k in range(1, t.size)]
    np.testing.assert_array_equal(stepped, r.clutch_torque_nm)
    # a controller that returns the same samples gives the same trajectory
    rc = simulate_driveline(MODEL, t, lambda tk, wa, wb: float(np.interp(tk, t, force)), tau_a, tau_b, 60.0, dl)
    np.testing.assert_array_equal(rc.speed_b_rad_s, r.speed_b_rad_s)


def test_snapshot_restore_repeats_a_step():
    plant = DrivelinePlant(MODEL, DrivelineParams(initial_speed_a_rad_s=30.0))
    plant.reset(4000.0, 60.0)
    plant.sample(4000.0, 100.0, 0.0, 60.0)
    for _ in range(50):
        plant.advance(0.001)
        plant.sample(4000.0, 100.0, 0.0, 60.0)
    snap = plant.state.copy()
    plant.advance(0.001)
    first = plant.sample(4000.0, 100.0, 0.0, 60.0).copy()
    plant.state[:] = snap
    plant.advance(0.001)
    np.testing.assert_array_equal(plant.sample(4000.0, 100.0, 0.0, 60.0), first)


def test_bad_driveline_parameters():
    from clutch_model import ParamsError

    with pytest.raises(ParamsError, match="inertia_a_kgm2"):
        DrivelineParams(inertia_a_kgm2=0.0)
    with pytest.raises(ParamsError, match="damping_b_nms"):
        DrivelineParams(damping_b_nms=-1.0)
    with pytest.raises(ParamsError, match="unknown"):
        DrivelineParams.from_mapping({"inertia_c_kgm2": 1.0})
    with pytest.raises(ParamsError, match="finite"):
        DrivelineParams(initial_speed_a_rad_s=float("nan"))


@settings(max_examples=40, deadline=None)
@given(
    force=st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=2, max_size=20),
    tau_a=st.floats(-5e4, 5e4, allow_nan=False),
    tau_b=st.floats(-5e4, 5e4, allow_nan=False),
    speeds=st.tuples(st.floats(-500, 500), st.floats(-500, 500)),
    lock_slip=st.sampled_from([0.0, 1e-3, 0.5]),
    dt=st.floats(1e-6, 0.3),
)
def test_fuzzed_inputs_never_nan(force, tau_a, tau_b, speeds, lock_slip, dt):
    t = np.arange(len(force)) * dt
    model = MODEL.with_lock_slip(lock_slip)
    r = simulate_driveline(model, t, np.array(force), tau_a, tau_b, 60.0,
                           DrivelineParams(0.3, 1.0, 0.1, 0.1, *speeds))
    for arr in (r.clutch_torque_nm, r.speed_a_rad_s, r.speed_b_rad_s, r.slip_speed_rad_s, r.pack_temperature_c):
        assert np.all(np.isfinite(arr))
    assert np.all(r.slip_speed_rad_s[r.locked] == 0.0)
    assert np.all(np.abs(r.clutch_torque_nm[r.locked]) <= r.static_capacity_nm[r.locked] * (1 + 1e-12))


@pytest.mark.parametrize("factor", [0.999, 1.002])
def test_full_plant_at_the_capacity_boundary_does_not_chatter(factor):
    """RC-1 (Stribeck friction rising with slip): a torque needing 0.999 x the static capacity
    stays locked; 1.002 x breaks loose once and settles at the small slip where the sliding
    torque equals the needed torque, without returning to lock."""
    ja, jb = 0.5, 1.2
    t = np.arange(0, 4.0, 0.001)
    settle = simulate_driveline(MODEL, t[t < 2.0], 3000.0, 0.0, 0.0, 60.0, DrivelineParams(ja, jb, 0.0, 0.0, 10, 10))
    capacity = settle.static_capacity_nm[-1]
    tau_a = np.where(t < 2.0, 0.0, factor * capacity * (ja + jb) / jb)
    r = simulate_driveline(MODEL, t, 3000.0, tau_a, 0.0, 60.0, DrivelineParams(ja, jb, 0.0, 0.0, 10, 10))
    late = t >= 2.0
    if factor < 1:
        assert r.locked.all()
    else:
        assert r.locked[~late].all() and not r.locked[late].any()
        assert np.count_nonzero(np.diff(r.locked.astype(int))) == 1
        needed = factor * capacity
        assert r.clutch_torque_nm[-1] == pytest.approx(needed, rel=1e-4)
        assert 0 < r.slip_speed_rad_s[-1] < 0.05
        assert np.all(np.abs(np.diff(r.slip_speed_rad_s[t > 3.0])) < 1e-4)   # steady, no oscillation
