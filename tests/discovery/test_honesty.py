"""Honesty tests of the discovery beyond the catalog, on campaigns of the virtual test car with
coloured torque noise (white + Ornstein-Uhlenbeck) and a calibrated model made as the
diagnosis makes it (bench fit + friction correction on the fit runs):

* no effect -> no term; per-run random friction levels (nothing in the inputs predicts them)
  -> no term; a once-per-revolution ripple whose phase is random per run (unpredictable on
  unseen runs) -> no term;
* friction falling with slip power, a pressure x temperature term (also as the virtual car's own
  independent implementation), a once-per-revolution ripple -> found, exactly that term, with
  its coefficient close to the truth inside a 95 % interval of sensible width, a held-out gain,
  and most of the gap to the true model closed on the held-out runs.

CLUTCH_HIDDEN_SEED=<int> draws other campaigns (default fixed, so CI is reproducible);
bench/bench_discovery.py runs the same cases over many seeds.
"""
import math
import os

import numpy as np
import pytest

from clutch_model.discovery import discover
from clutch_model.discovery.synthetic import make_case

SEED = int(os.environ.get("CLUTCH_HIDDEN_SEED", "20261123")) % 100000


def _run(case_seed, terms=None, **kw):
    tc = make_case(SEED + case_seed, terms or {}, **kw)
    res = discover(tc.campaign, tc.calibrated_model, tc.held_out, friction_anchor=tc.bench_model)
    return tc, res


def _gap_closed(tc, res):
    """Share of the calibrated model's held-out RMSE against the noise-free torque that the
    extension removes."""
    eval_mask = np.isin(tc.campaign.run_index, [tc.campaign.names.index(n) for n in tc.held_out])
    ok = eval_mask & np.isfinite(res.residual) & np.isfinite(res.base_residual)
    meas = tc.campaign.torque_measured
    gap_cal = np.sqrt(np.mean((meas - res.base_residual - tc.noise_free_torque)[ok] ** 2))
    gap_ext = np.sqrt(np.mean((meas - res.residual - tc.noise_free_torque)[ok] ** 2))
    return 1.0 - gap_ext / gap_cal


def _assert_no_term(res):
    assert not res.accepted, res.evidence
    assert res.model is None and res.terms == [] and res.gain_pct == 0.0
    assert res.rmse_nm["extended"] == res.rmse_nm["calibrated"]


def test_no_effect_no_term():
    _, res = _run(1)
    _assert_no_term(res)


def test_per_run_random_friction_levels_no_term():
    _, res = _run(2, run_level_spread=0.04)
    _assert_no_term(res)


def test_ripple_with_a_random_phase_per_run_is_not_claimed():
    # the virtual car's torque_ripple: once per revolution, but its phase is redrawn every
    # run, so nothing predicts it on a run the search never saw
    _, res = _run(3, extra_effect="torque_ripple", extra_magnitude=0.06)
    _assert_no_term(res)


def _assert_found(tc, res, truth: dict, rel_tol: float):
    assert res.accepted, res.evidence
    assert set(res.parameters) == set(truth), res.parameters
    for tid, value in truth.items():
        assert res.parameters[tid] == pytest.approx(value, rel=rel_tol, abs=rel_tol * max(abs(v) for v in truth.values()))
        lo, hi = res.parameters_ci95[tid]
        assert lo < res.parameters[tid] < hi
        assert hi - lo < 0.5 * max(abs(v) for v in truth.values())
    assert res.gain_pct > 5.0
    assert res.rmse_nm["extended"] < res.rmse_nm["calibrated"]
    assert _gap_closed(tc, res) > 0.5
    # stated and usable: the extended model carries the mechanism, the evidence reads it
    mech = res.model.mechanism("discovered")
    assert mech.parameter_values == pytest.approx(res.parameters)
    cause = res.to_cause()
    assert cause["id"] == "discovered" and set(cause["parameters_ci95"]) == set(truth)
    assert "held-out" in cause["evidence"]


def test_friction_falling_with_slip_power_is_found():
    truth = {"mu:slip_power": -0.025}
    tc, res = _run(4, truth)
    _assert_found(tc, res, truth, rel_tol=0.15)
    assert "μ_f falls" in res.evidence and "per kW of slip power" in res.evidence


def test_pressure_temperature_term_is_found():
    truth = {"mu:pressure*pack_temperature": 2.5e-3}
    tc, res = _run(5, truth)
    _assert_found(tc, res, truth, rel_tol=0.15)


def test_virtual_cars_own_pressure_temperature_cross_is_found():
    # independent implementation of the effect (virtual_car.campaign), not the discovered mechanism
    tc, res = _run(6, extra_effect="pressure_temperature_cross", extra_magnitude=2.5e-3)
    _assert_found(tc, res, {"mu:pressure*pack_temperature": 2.5e-3}, rel_tol=0.15)


def test_once_per_revolution_ripple_is_found():
    amp, phase = 0.06, 1.0
    truth = {"mu:sin_slip_angle": amp * math.cos(phase), "mu:cos_slip_angle": amp * math.sin(phase)}
    tc, res = _run(7, truth)
    _assert_found(tc, res, truth, rel_tol=0.15)
    assert math.hypot(*res.coefficients) == pytest.approx(amp, rel=0.1)
    assert "once per revolution" in res.evidence


def test_a_fade_with_its_own_time_constant_is_found_and_the_time_constant_fitted():
    # friction falling with the slip power seen through a 1.2 s lag, a time constant the
    # library does not hold (it offers 0.3 s and 3 s as starts): the refit fits it
    truth_tau_s, truth_c = 1.2, -0.03
    tc, res = _run(11, {f"mu:slip_power@{truth_tau_s:g}s": truth_c})
    assert res.accepted, res.evidence
    [term] = res.terms
    assert (term.kind, term.a, term.b) == ("mu", "slip_power", None)
    assert term.tau_s == pytest.approx(truth_tau_s, rel=0.15)
    assert res.coefficients[0] == pytest.approx(truth_c, rel=0.15)
    lo, hi = res.parameters_ci95[term.id]
    assert lo < truth_c < hi
    tau_reading = res.readings[0].split("τ 95 % interval ")[1]
    tau_lo, tau_hi = (float(v) for v in tau_reading.removesuffix(" s").split(" to "))
    assert tau_lo < truth_tau_s < tau_hi and tau_hi / tau_lo < 1.5
    assert _gap_closed(tc, res) > 0.7
    # the extended model carries the fitted time constant
    assert res.model.mechanism("discovered").values["terms"] == [term.id]
