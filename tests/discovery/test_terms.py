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
