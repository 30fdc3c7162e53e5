"""A return-spring preload growing with the lining's wear (wear_preload.py): the energy share it
grows with, its fit on noise-free torque, and the rule that a named preload is what it checks."""
from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from clutch_model.diagnosis.wear_preload import energy_share, fit_wear_preload, named_or_wearing_preload
from clutch_model.prediction import PlantInputs


def test_the_energy_share_rises_from_0_to_1_over_the_campaign():
    from .noise_free_campaigns import reference_campaign

    model, campaign = reference_campaign(5, 3, 4.0)
    share = energy_share(model, PlantInputs.of(campaign))
    assert share.shape == campaign.t.shape
    assert share[0] == 0.0 and share[-1] == pytest.approx(1.0)
    assert np.all(np.diff(share) >= -1e-12)          # dissipated energy never falls, across bags too


def test_a_preload_growing_with_the_energy_is_recovered():
    """The pack force max(F - (p0 + g E / E_campaign), 0), p0 = 200 N, g = 600 N, on the
    reference plant: WearPreloadObjective fitted on the noise-free torque from the named
    constant preload (the mean, 500 N) gives p0 and g back within 10 % of g and cuts the
    error of the best constant preload by more than 90 %."""
    from clutch_model.formats.bag_reader import Campaign
    from clutch_model.plant.mechanisms import make_mechanism
    from clutch_model.replay import replay_runs
    from .noise_free_campaigns import reference_campaign, with_measured_torque

    model, logged_inputs = reference_campaign(5, 4, 6.0)
    share = energy_share(model, PlantInputs.of(logged_inputs))
    p0, g = 200.0, 600.0
    pack = np.maximum(logged_inputs.force - (p0 + g * share), 0.0)
    worn = Campaign([replace(r, applied_force_n=pack[sl].copy()) for r, sl in logged_inputs.slices()])
    torque = replay_runs(model, worn).torque_sim
    logged = with_measured_torque(logged_inputs, torque)
    every = np.ones(logged.t.size, bool)

    def rmse(pred):
        return float(np.sqrt(np.mean((np.asarray(pred) - torque) ** 2)))
    constant = min(rmse(replay_runs(model.with_mechanisms([make_mechanism("spring_preload", preload_n=p)]),
                                    logged).torque_sim) for p in (300.0, 400.0, 500.0, 600.0, 700.0))
    fit = fit_wear_preload(model, logged, every, preload_n=500.0)
    assert fit.parameters["start_preload_n"] == pytest.approx(p0, abs=0.1 * g)
    assert fit.parameters["growth_n"] == pytest.approx(g, abs=0.1 * g)
    assert rmse(fit.predicted) < 0.1 * constant


def test_only_a_named_preload_is_checked():
    sel = SimpleNamespace(verdict="named", cause_ids=["friction_degradation"])
    assert named_or_wearing_preload(None, sel, None, 1.0, 1e-3, 0.01) == (sel, None)
    sel = SimpleNamespace(verdict="none", cause_ids=[])
    assert named_or_wearing_preload(None, sel, None, 1.0, 1e-3, 0.01) == (sel, None)
