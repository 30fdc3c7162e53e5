"""A candidate's own parameter is recovered from a start at zero (diagnosis.fitting).

The measured torque is the model's own prediction with the mechanism added, noise-free, so the
least-squares optimum is the true value exactly. The starts are the ones the diagnosis meets:
a torque offset smaller than its grid's spacing starts at the grid's centre (~0 N*m), a drag
coefficient below its first non-zero grid point starts at its bound 0 -- both starts trf used
to leave unmoved (its first trust radius is |x0|).
"""
from __future__ import annotations


import numpy as np
import pytest

from clutch_model.diagnosis.fitting import co_fitted_ids, fit_candidate, search_space, start_shift
from clutch_model.plant.mechanisms import make_mechanism
from clutch_model.prediction import predict_campaign

from .noise_free_campaigns import reference_campaign, with_measured_torque


@pytest.fixture(scope="module")
def inputs():
    return reference_campaign(seed=5, n_runs=3, run_duration_s=4.0)


@pytest.mark.parametrize("mech_id, name, true_value", [("torque_offset", "offset_nm", 15.3),
                                                        ("torque_offset", "offset_nm", -7.0),
                                                        ("drag_torque", "coeff_nm_per_rad_s", 0.6)])
def test_a_parameter_starting_at_zero_reaches_the_truth(inputs, mech_id, name, true_value):
    model, campaign = inputs
    truth = model.with_mechanisms([make_mechanism(mech_id, **{name: true_value})])
    campaign = with_measured_torque(campaign, predict_campaign(truth, campaign, energy0_j=0.0).torque_nm)
    scale = float(np.nanpercentile(np.abs(campaign.torque_measured), 95))
    spec = search_space(mech_id, campaign, 1e6, scale)[0]
    grid = np.array(spec.grid)
    # the start the grid gives is ~0, well away from the truth
    assert abs(grid[np.argmin(np.abs(grid - true_value))]) < 1e-9
    mask = np.ones(campaign.t.size, bool)
    # from the grid, and from a start as a fit that did not move leaves it (the offset's grid
    # centre is linspace's 2.8e-14 N*m on some campaigns, not 0)
    for joint, start in ((False, None), (True, None), (False, {name: 2.8e-14}), (True, {name: 2.8e-14})):
        fit = fit_candidate(model, campaign, mask, mech_id, 1e6, scale, fit_friction=joint, noise_sigma_nm=1.0,
                            start=start)
        assert fit.parameters[name] == pytest.approx(true_value, rel=0.02), (joint, start)
        assert fit.fit_rmse_nm < 0.05 * abs(true_value)


def test_start_shift_moves_only_starts_at_zero():
    from clutch_model.plant.mechanisms import ParamSpec
    specs = [ParamSpec("offset_nm", False, -100.0, 100.0, np.linspace(-20.0, 20.0, 11)),
             ParamSpec("tau_s", True, 1e-4, 2.0, np.geomspace(0.005, 1.0, 10))]
    x0 = np.array([1e-14, np.log(0.05), 0.0])
    shift = start_shift(x0, specs)
    assert shift[0] == pytest.approx(4.0)
    assert shift[1] == 0.0 and shift[2] == 0.0
    assert not start_shift(np.array([3.0, np.log(0.05)]), specs).any()


def test_a_time_mechanism_on_top_of_another_moves_it_back():
    """A lag fitted alone on a lag + delay takes up their sum; a delay fitted on top of it
    moves the lag back with it (fitting.co_fitted_ids) and both reach the truth. Fitted on top
    of the lag as it was, the delay alone only adds delay."""
    model, campaign = _inputs_fine()
    truth = model.with_mechanisms([make_mechanism("actuator_lag", tau_s=0.08),
                                   make_mechanism("transport_delay", delay_s=0.04)])
    campaign = with_measured_torque(campaign, predict_campaign(truth, campaign, energy0_j=0.0).torque_nm)
    scale = float(np.nanpercentile(np.abs(campaign.torque_measured), 95))
    mask = np.ones(campaign.t.size, bool)
    lag_alone = fit_candidate(model, campaign, mask, "actuator_lag", 1e6, scale, fit_friction=False)
    assert lag_alone.parameters["tau_s"] > 0.1            # the sum taken up (the test's premise)
    on_top = lag_alone.model
    assert co_fitted_ids("transport_delay", on_top) == ("actuator_lag",)
    assert co_fitted_ids("drag_torque", on_top) == ()     # a torque map moves nothing with it
    fit = fit_candidate(on_top, campaign, mask, "transport_delay", 1e6, scale, fit_friction=False)
    assert fit.parameters["delay_s"] == pytest.approx(0.04, rel=0.05)
    assert fit.co_parameters["actuator_lag"]["tau_s"] == pytest.approx(0.08, rel=0.05)
    by_id = {m.id: m.values for m in fit.model.mechanisms}
    assert by_id["actuator_lag"]["tau_s"] == pytest.approx(0.08, rel=0.05)
    assert fit.fit_rmse_nm < 0.1 * lag_alone.fit_rmse_nm
    # and the refit with the friction correction, started from there, stays there
    joint = fit_candidate(on_top, campaign, mask, "transport_delay", 1e6, scale, fit_friction=True,
                          noise_sigma_nm=1.0, start=fit.parameters, co_start=fit.co_parameters)
    assert joint.parameters["delay_s"] == pytest.approx(0.04, rel=0.05)
    assert joint.co_parameters["actuator_lag"]["tau_s"] == pytest.approx(0.08, rel=0.05)


def _inputs_fine():
    """Step force profiles at 200 Hz (a lag and a delay of tens of ms told apart)."""
    return reference_campaign(seed=7, n_runs=3, run_duration_s=4.0, rate_hz=200.0)
