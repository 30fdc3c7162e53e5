"""A torque reading offset that follows the sump temperature (sump_offset.py): recovered on
noise-free torque, and not fitted where the sump does not move."""
from __future__ import annotations

import numpy as np
import pytest

from clutch_model.diagnosis.sump_offset import MIN_SUMP_SPAN_C, SUMP_REFERENCE_C, fit_sump_offset


def test_a_sump_following_offset_is_recovered():
    """measured = plant + 4 N*m + 0.5 N*m per degree of sump above 60 C: SumpOffsetObjective,
    fitted with the friction correction on the noise-free torque, gives both back and leaves
    under a tenth of the error of the plant read as it is."""
    from clutch_model.replay import replay_runs
    from .noise_free_campaigns import reference_campaign, with_measured_torque

    model, camp = reference_campaign(6, 4, 6.0)
    assert np.ptp(camp.sump) > MIN_SUMP_SPAN_C
    plant = replay_runs(model, camp).torque_sim
    measured = plant + 4.0 + 0.5 * (np.asarray(camp.sump) - SUMP_REFERENCE_C)
    logged = with_measured_torque(camp, measured)
    every = np.ones(camp.t.size, bool)
    fit = fit_sump_offset(model, logged, every)
    assert fit.parameters["slope_nm_per_c"] == pytest.approx(0.5, abs=0.05)
    assert fit.parameters["offset_nm"] == pytest.approx(4.0, abs=1.0)

    def rmse(pred):
        return float(np.sqrt(np.mean((np.asarray(pred) - measured) ** 2)))
    assert rmse(fit.predicted) < 0.1 * rmse(plant)


def test_no_slope_is_fitted_where_the_sump_does_not_move():
    from dataclasses import replace

    from clutch_model.formats.bag_reader import Campaign
    from .noise_free_campaigns import reference_campaign

    model, camp = reference_campaign(6, 2, 4.0)
    flat = Campaign([replace(r, sump_temperature_c=np.full(len(r.t), 55.0)) for r, _ in camp.slices()])
    assert fit_sump_offset(model, flat, np.ones(flat.t.size, bool)) is None
