"""The candidate-term library: objects with ids the plant understands, units, plain words, and
feature functions that reproduce what the compiled plant evaluates."""
import numpy as np
import pytest

from clutch_model.discovery.terms import Term, TermSignals, default_library, describe
from clutch_model.formats.bag_reader import Campaign, Run
from clutch_model.plant.friction import friction_grid
from clutch_model.plant.mechanisms import make_mechanism
from clutch_model.plant.params import load_model
from clutch_model.plant.simulate import simulate


def test_library_terms_are_distinct_parseable_and_outside_the_polynomials():
    lib = default_library()
    ids = [t.id for t in lib]
    assert len(ids) == len(set(ids))
    assert all(Term.from_id(i) == t for i, t in zip(ids, lib))
    # what the friction polynomials already represent is not a candidate
    for redundant in ("mu:pressure", "mu:pack_temperature", "mu:slip_abs", "mu:pressure*slip_abs",
                      "mu:pack_temperature*slip_abs", "mu:pressure*pressure"):
        assert redundant not in ids
    for wanted in ("mu:slip_power", "mu:pressure*pack_temperature", "mu:sin_slip_angle", "mu:cos_slip_angle",
                   "mu:energy", "mu:force_rate", "mu:slip_power@3s", "torque:slip_sign"):
        assert wanted in ids
    assert {t.kind for t in lib} == {"mu", "torque"}


def test_units_and_readings():
    t = Term.from_id("mu:slip_power")
    assert t.units == "1/(kW)"
    assert t.reading(-0.04) == "μ_f falls 4 % per kW of slip power"
    pxt = Term.from_id("mu:pressure*pack_temperature")
    assert pxt.units == "1/(MPa·°C)"
    assert "rises 0.2 % per MPa·°C of contact pressure × pack temperature above 60 °C" in pxt.reading(2e-3)
    assert Term.from_id("torque:slip_sign").units == "N·m"
    lines = describe([Term.from_id("mu:sin_slip_angle"), Term.from_id("mu:cos_slip_angle")], [0.03, 0.04])
    assert lines == ["μ_f ripples ±5 % once per revolution of slip (phase 53° from each run's start)"]


def test_features_reproduce_the_plant():
    """For every unfiltered multiplier, the plant's mu_f / mu_f(no term) - 1 is c x the term's
    feature computed from the simulated signals (TermSignals)."""
    t = np.arange(0.0, 3.0, 0.005)
    force = np.interp(t, [0, 0.5, 0.55, 1.5, 1.6, 3.0], [300, 300, 8000, 8000, 4000, 4000])
    slip = 3.0 + 0.5 * np.sin(t)
    sump = np.full(t.size, 50.0)
    run = Run("r", t, force, slip, sump, torque_measured_nm=np.zeros(t.size))
    camp = Campaign([run])
    rc1 = load_model()
    c = 1e-3
    for term in default_library():
        if term.kind != "mu" or term.tau_s > 0:
            continue
        model = rc1.with_mechanisms([make_mechanism("discovered", terms=[term.id], coefficients=[c])])
        sim = simulate(model, t, force, slip, sump)
        base = friction_grid(rc1.friction_coefficients, rc1.friction_exponent, np.abs(slip), sim.pressure_mpa, sim.pack_temperature_c)
        g = term.feature(TermSignals.from_simulation(camp, sim))
        np.testing.assert_allclose(sim.friction_coefficient / base - 1.0, c * g, rtol=1e-9, atol=1e-12,
                                   err_msg=term.id)


def test_low_passed_feature_matches_the_plant_filter():
    t = np.arange(0.0, 3.0, 0.005)
    force = np.where(t > 0.5, 7000.0, 300.0)
    slip, sump = np.full(t.size, 4.0), np.full(t.size, 50.0)
    camp = Campaign([Run("r", t, force, slip, sump, torque_measured_nm=np.zeros(t.size))])
    term = Term.from_id("mu:slip_power@0.3s")
    c = 1e-3
    model = load_model().with_mechanisms([make_mechanism("discovered", terms=[term.id], coefficients=[c])])
    sim = simulate(model, t, force, slip, sump)
    base = friction_grid(load_model().friction_coefficients, load_model().friction_exponent, np.abs(slip), sim.pressure_mpa, sim.pack_temperature_c)
    g = term.feature(TermSignals.from_simulation(camp, sim))
    np.testing.assert_allclose(sim.friction_coefficient / base - 1.0, c * g, rtol=1e-9, atol=1e-12)
    assert g[-1] == pytest.approx(sim.power_w[-2] * 1e-3, rel=0.02)   # settled: follows the power


def test_unseen_range_prior_holds_the_friction_correction_only_outside_the_fit_rows():
    from types import SimpleNamespace

    from clutch_model.diagnosis.fitting import (P_CENTER_MPA, THETA_CENTER_C, THETA_SCALE_C,
                                                apply_friction_correction)
    from clutch_model.discovery.identify import N_CORR, PRIOR_MARGIN_C, PRIOR_MU, unseen_range_prior

    n, sigma = 4000, 8.0
    rng = np.random.default_rng(0)
    sim = SimpleNamespace(pressure_mpa=rng.uniform(0.2, 1.0, n), pack_temperature_c=rng.uniform(60.0, 90.0, n))
    slip = rng.uniform(-8.0, 8.0, n)
    rows = unseen_range_prior(sim, slip, np.ones(n, bool), sigma_nm=sigma)
    assert rows.shape[1] == N_CORR and rows.shape[0] > 0 and rows.shape[0] % 2 == 0
    weight = rows[0, 0]                   # each mu row's constant basis is 1 x weight
    # a shift of PRIOR_MU in mu_C/mu_S and in k_V w at every held point costs one noise-level SSE
    shift = np.zeros(N_CORR)
    shift[0] = PRIOR_MU
    assert float(np.sum((rows @ shift) ** 2)) == pytest.approx(0.5 * n * sigma ** 2, rel=1e-9)
    # every row is the correction's own change at a point outside the fit rows' box
    delta = np.random.default_rng(1).normal(size=N_CORR) * 1e-3
    a = apply_friction_correction(np.zeros(20), delta)
    w_ref = float(np.sqrt(np.mean(slip ** 2)))
    for mu_row, kv_row in zip(rows[0::2] / weight, rows[1::2] / weight):
        p = mu_row[1] + P_CENTER_MPA
        theta = mu_row[3] * THETA_SCALE_C + THETA_CENTER_C
        assert (theta < 60.0 - PRIOR_MARGIN_C or theta > 90.0 + PRIOR_MARGIN_C or p > 1.05 or p < 0.19)
        basis = np.array([1.0, p, p * p, theta, theta * theta])
        assert mu_row @ delta == pytest.approx(a[0:5] @ basis, abs=1e-12)        # mu_C's change
        assert kv_row @ delta == pytest.approx(a[15:20] @ basis * w_ref, abs=1e-12)   # k_V w's change
    # fit rows over the whole temperature grid: only pressures above the seen ones are held
    wide = SimpleNamespace(pressure_mpa=np.linspace(0.0, 1.0, n), pack_temperature_c=np.linspace(10.0, 160.0, n))
    held = unseen_range_prior(wide, slip, np.ones(n, bool), sigma_nm=sigma)
    assert np.all(held[0::2, 1] / held[0, 0] + P_CENTER_MPA > 1.05)


def test_an_unresolved_time_constant_has_the_interval_zero_to_infinity():
    """A low-passed term's time constant whose log half-width exceeds exp's range (1e3 ended a
    diagnosis with OverflowError) gets [0, inf]; a resolved one tau e^-h .. tau e^h."""
    import math

    from clutch_model.discovery.identify import tau_interval_s
    assert tau_interval_s(0.08, 1e3) == [0.0, math.inf]
    lo, hi = tau_interval_s(0.08, 0.5)
    assert lo == pytest.approx(0.08 * math.exp(-0.5)) and hi == pytest.approx(0.08 * math.exp(0.5))


def test_slip_rate_torque_term_reads_an_inertia_as_the_plant_applies_it():
    """torque:slip_rate (an inertia J between the clutch and the torque sensor reads J dw/dt):
    the plant adds c x the slip's change over the last step, the feature reproduces it, and on
    a sine of the slip it is the derivative to the step's first order."""
    t = np.arange(0.0, 2.0, 0.002)
    slip = 4.0 + 2.0 * np.sin(2 * np.pi * 1.5 * t)
    force = np.full(t.size, 6000.0)
    sump = np.full(t.size, 50.0)
    camp = Campaign([Run("r", t, force, slip, sump, torque_measured_nm=np.zeros(t.size))])
    rc1 = load_model()
    term = Term.from_id("torque:slip_rate")
    assert term in default_library()
    assert term.units == "N·m/(rad/s²)"
    c = 0.25
    sim0 = simulate(rc1, t, force, slip, sump)
    sim = simulate(rc1.with_mechanisms([make_mechanism("discovered", terms=[term.id], coefficients=[c])]),
                   t, force, slip, sump)
    g = term.feature(TermSignals.from_simulation(camp, sim))
    # the added torque also heats the pack a little (the friction moves by ~1 % of the term)
    np.testing.assert_allclose(sim.torque_nm - sim0.torque_nm, c * g, atol=0.02 * np.max(np.abs(c * g)))
    assert g[0] == 0.0
    exact = 2.0 * 2 * np.pi * 1.5 * np.cos(2 * np.pi * 1.5 * (t[1:] - 0.001))   # the step's midpoint
    np.testing.assert_allclose(g[1:], exact, rtol=1e-3, atol=1e-3)
