"""The baseline plant against independent expectations: closed forms vs quadrature, the
asperity equilibrium vs a root solve, the simulators vs solve_ivp(Radau, rtol=1e-8) on an
independent transcription of the thesis, the thermal energy balance, and the pins of
docs/model.md (force clamp, lock-up, friction box)."""
import math

import numpy as np
import pytest
import yaml
from hypothesis import given, settings, strategies as st
from scipy.optimize import brentq

from clutch_model import Plant, load_model, simulate, simulate_batch
from clutch_model.plant import kernels as K
from clutch_model.plant.params import REFERENCE_CLUTCH

from .reference_plant import ReferencePlant

MODEL = load_model()
RAW = yaml.safe_load(REFERENCE_CLUTCH.read_text())
REF = ReferencePlant(RAW)


def step_profile(rate, sump, slip, duration=6.0):
    t = np.arange(0, duration, 1 / rate)
    F = np.full_like(t, 300.0)
    F[(t >= 0.5) & (t < 2.5)] = 6000.0
    F[(t >= 3.0) & (t < 4.5)] = 12000.0
    F[t >= 4.5] = 2000.0
    return t, F, np.full_like(t, slip), np.full_like(t, float(sump))


@pytest.mark.parametrize("x", [0.0, 0.1, 0.5, 1.0, 2.0, 3.5, 5.0])
def test_fe_closed_form_matches_quadrature(x):
    assert K.greenwood_williamson_fe(x) == pytest.approx(REF.fe_quad(x), rel=1e-9, abs=1e-15)


def test_reference_constants_of_contract():
    # P_a(0) = 5.96 MPa and the force limit 0.9 * A_N * P_a(0) = 43.8 kN (docs/model.md)
    d = K.derived_constants(MODEL.vector())
    assert d[K.D_KP] * K.greenwood_williamson_fe(0.0) == pytest.approx(5.96e6, rel=2e-3)
    assert MODEL.max_pack_force_n == pytest.approx(43.8e3, rel=2e-3)
    # Q with ln(r_i/r_o) (the thesis' ln(r_i/r_i) is a typo)
    ro, ri = 0.075, 0.055
    assert d[K.D_Q] == pytest.approx(ro ** 2 + ri ** 2 + (ro ** 2 - ri ** 2) / math.log(ri / ro))


@pytest.mark.parametrize("force", [500.0, 4000.0, 15000.0, 40000.0])
def test_film_settles_at_asperity_equilibrium(force):
    """At rest the film carries nothing: F_app = A_N * P_a(h*). h* from a root solve."""
    sigma = RAW["surface"]["rms_roughness"]
    h_star = brentq(lambda h: REF.AN * REF.pa(h) - force, 1e-12, 30 * sigma, xtol=1e-18, rtol=1e-14)
    t = np.arange(0, 30.0, 0.01)
    r = simulate(MODEL, t, force, 0.0, 60.0)
    assert r.film_thickness_m[-1] == pytest.approx(h_star, rel=1e-4)
    assert REF.AN * r.asperity_pressure_pa[-1] == pytest.approx(force, rel=1e-4)


@pytest.mark.parametrize("rate", [200, 1000])
@pytest.mark.parametrize("sump,slip", [(20, 2.0), (60, 8.0), (100, -15.0), (40, 0.5), (80, 25.0)])
def test_simulators_match_radau(rate, sump, slip):
    t, F, w, s = step_profile(rate, sump, slip)
    torque_ref, theta_ref = REF.simulate(t, F, w, s, rtol=1e-8)
    rms_ref = np.sqrt(np.mean(torque_ref ** 2))
    single = simulate(MODEL, t, F, w, s)
    batch = simulate_batch([MODEL, MODEL], t, F, w, s)
    for torque in (single.torque_nm, batch.torque_nm[0], batch.torque_nm[1]):
        assert np.sqrt(np.mean((torque - torque_ref) ** 2)) <= 0.005 * rms_ref
    rise = np.max(np.abs(theta_ref - sump))
    assert np.max(np.abs(single.pack_temperature_c - theta_ref)) < 0.01 + 1e-3 * rise
    # the step simulator (node) runs the same equations sample by sample
    plant = Plant(MODEL)
    plant.reset(F[0], s[0])
    stepped = np.empty(t.size)
    for k in range(t.size):
        if k:
            plant.advance(t[k] - t[k - 1])
        stepped[k] = plant.sample(F[k], w[k], s[k])[K.O_TORQUE]
    np.testing.assert_allclose(stepped, single.torque_nm, rtol=1e-12, atol=1e-9)


def test_batch_runs_distinct_parameter_sets():
    t, F, w, s = step_profile(200, 60, 5.0, duration=3.0)
    a = MODEL.friction_coefficients
    models = [MODEL.with_friction(a * f) for f in (0.9, 1.0, 1.1)]
    batch = simulate_batch(models, t, F, w, s)
    for j, m in enumerate(models):
        np.testing.assert_allclose(batch.torque_nm[j], simulate(m, t, F, w, s).torque_nm, rtol=1e-12)
    assert batch.torque_nm[0].mean() < batch.torque_nm[1].mean() < batch.torque_nm[2].mean()


def test_thermal_energy_balance_adiabatic():
    """No heat transfer: every joule dissipated ends in the separator plates."""
    raw = yaml.safe_load(REFERENCE_CLUTCH.read_text())
    raw["thermal"]["b"] = [0.0, 0.0, 0.0, 0.0]
    raw["thermal"]["htf_min"] = 1e-9
    from clutch_model import ClutchModel
    m = ClutchModel.from_dict(raw)
    t, F, w, s = step_profile(500, 40, 3.0, duration=4.0)
    r = simulate(m, t, F, w, s)
    stored = (r.pack_temperature_c[-1] - 40.0) * raw["thermal"]["plate_heat_capacity"] * raw["geometry"]["separator_plates"]
    assert stored == pytest.approx(r.energy_j[-1], rel=1e-6)
    # and E is the integral of the power (trapezoid on the output grid agrees closely)
    e_trap = np.trapezoid(r.power_w, t)
    assert r.energy_j[-1] == pytest.approx(e_trap, rel=2e-3)


def test_thermal_steady_state():
    """Constant heat input: the pack settles at theta_sump + q / (H_tf * A_N)."""
    t = np.arange(0, 1500.0, 0.1)
    r = simulate(MODEL, t, 3000.0, 2.0, 50.0)
    q = r.power_w[-1] / RAW["geometry"]["separator_plates"]
    b = RAW["thermal"]["b"]
    htf = b[0] + b[1] * 2.0 + b[2] * 3.0 + b[3] * 2.0 * 3.0
    assert r.pack_temperature_c[-1] == pytest.approx(50.0 + q / (htf * REF.AN), abs=0.02)


def test_force_clamp_and_positive_film():
    t = np.arange(0, 5.0, 0.001)
    r = simulate(MODEL, t, 1e6, 5.0, 60.0)
    assert r.force_clamped.all()
    assert np.all(r.pack_force_n <= MODEL.max_pack_force_n + 1e-9)
    assert np.all(r.film_thickness_m > 0)
    assert np.all(np.isfinite(r.torque_nm))


def test_negative_force_counts_as_zero():
    t = np.arange(0, 2.0, 0.005)
    a = simulate(MODEL, t, -5000.0, 5.0, 60.0)
    b = simulate(MODEL, t, 0.0, 5.0, 60.0)
    np.testing.assert_array_equal(a.torque_nm, b.torque_nm)


def test_lockup_reports_static_capacity_with_last_sign():
    t = np.arange(0, 4.0, 0.005)
    w = np.where(t < 2.0, -3.0, 0.0)
    r = simulate(MODEL, t, 5000.0, w, 60.0)
    locked = t >= 2.0
    assert r.locked[locked].all() and not r.locked[~locked].any()
    assert np.all(r.torque_nm[locked] < 0)  # sign of the last slip above the tolerance
    np.testing.assert_allclose(r.hydrodynamic_torque_nm[locked], 0.0)
    k = np.flatnonzero(locked)[-1]
    mu_s = K.friction_coefficient(0.0, r.pressure_mpa[k], r.pack_temperature_c[k], MODEL.vector())
    d = K.derived_constants(MODEL.vector())
    assert r.torque_nm[k] == pytest.approx(-mu_s * r.asperity_pressure_pa[k] * d[K.D_TA_GEOM], rel=1e-12)


def test_friction_clamps_box_and_floors():
    p = MODEL.vector()
    # outside the box the polynomials are evaluated at the box edge
    assert K.friction_coefficient(5.0, 35.0, 60.0, p) == K.friction_coefficient(5.0, 20.0, 60.0, p)
    assert K.friction_coefficient(5.0, 3.0, 400.0, p) == K.friction_coefficient(5.0, 3.0, 230.0, p)
    assert K.friction_coefficient(5.0, -1.0, -20.0, p) == K.friction_coefficient(5.0, 0.0, 0.0, p)
    # mu_f floored at 0
    q = MODEL.with_friction(a=-np.abs(MODEL.friction_coefficients)).vector()
    assert K.friction_coefficient(5.0, 3.0, 60.0, q) == 0.0
    # Stribeck limits: w = 0 -> mu_S; w >> w_S -> mu_C + k_V w
    a = MODEL.friction_coefficients
    P, th = 3.0, 60.0
    mu_c = a[0] + a[1] * P + a[2] * P * P + a[3] * th + a[4] * th * th
    mu_s = a[5] + a[6] * P + a[7] * P * P + a[8] * th + a[9] * th * th
    k_v = a[15] + a[16] * P + a[17] * P * P + a[18] * th + a[19] * th * th
    assert K.friction_coefficient(0.0, P, th, p) == pytest.approx(mu_s)
    assert K.friction_coefficient(10.0, P, th, p) == pytest.approx(mu_c + k_v * 10.0)


@settings(max_examples=60, deadline=None)
@given(
    force=st.lists(st.floats(-1e9, 1e9, allow_nan=False), min_size=2, max_size=30),
    slip=st.floats(-1e6, 1e6, allow_nan=False),
    sump=st.floats(-300, 1000, allow_nan=False),
    dt=st.floats(1e-6, 2.0),
)
def test_fuzzed_inputs_never_nan(force, slip, sump, dt):
    n = len(force)
    t = np.arange(n) * dt
    r = simulate(MODEL, t, np.array(force), slip, sump)
    for arr in (r.torque_nm, r.pack_temperature_c, r.film_thickness_m, r.energy_j):
        assert np.all(np.isfinite(arr))
    assert np.all(r.film_thickness_m > 0)


def test_kernel_memo_reuses_values_only_for_equal_inputs():
    """The kernel keeps viscosity, asperity pressure and hydrodynamic flow factor in memo slots
    of the state, keyed on every input they depend on. A state carried to another parameter
    set, or with its film or temperature changed, must give exactly the outputs of the same
    state without memo; and the memo must really be used within a trajectory."""
    from clutch_model.plant import layout as P

    p1 = MODEL.vector()
    variants = []                              # one input of a memo changed at a time
    for index, factor in ((P.ALPHA0, 1.3), (P.ALPHA1, 0.9), (P.SIGMA, 1.2), (P.YOUNGS, 0.8)):
        p2 = p1.copy()
        p2[index] *= factor
        variants.append(p2)
    state = np.zeros(K.N_STATE)
    scratch = np.zeros(K.N_OUT)
    d1 = K.derived_constants(p1)
    K.init_state(state, 5000.0, 60.0, p1)
    for _ in range(50):                        # engage: film thins, pack warms, memos fill
        K.advance(state, 3.0, 60.0, 1e-3, p1, d1, scratch)
        K.pack_force_target(state, 5000.0, p1)
        K.outputs(state, 3.0, 60.0, p1, d1, scratch)
    # the memos hold the values at this state's film and temperature
    assert state[K.M_VISC_THETA] == state[K.S_THETA] and state[K.M_PA_H] == state[K.S_H]
    assert state[K.M_VISC_OK] == state[K.M_PA_OK] == state[K.M_HY_OK] == 1.0

    def both(edit, p):
        d = K.derived_constants(p)
        with_memo, without = state.copy(), state.copy()
        edit(with_memo)
        edit(without)
        without[[K.M_VISC_OK, K.M_PA_OK, K.M_HY_OK]] = 0.0
        outs = []
        for s in (with_memo, without):
            out = np.zeros(K.N_OUT)
            K.pack_force_target(s, 5000.0, p)
            K.outputs(s, 3.0, 60.0, p, d, out)
            outs.append(out)
        return outs

    def thinner(s):
        s[K.S_H] *= 0.97

    def warmer(s):
        s[K.S_THETA] += 0.5

    for edit in (lambda s: None, thinner, warmer):
        for p in [p1] + variants:
            a, b = both(edit, p)
            assert np.array_equal(a, b)
    a1, _ = both(lambda s: None, p1)
    for p2 in variants:                        # each variant's own values, not p1's
        a2, _ = both(lambda s: None, p2)
        assert a1[K.O_VISC] != a2[K.O_VISC] or a1[K.O_PA] != a2[K.O_PA]
