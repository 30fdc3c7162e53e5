"""Small noise-free campaigns from the virtual test car whose measured torque a test sets
(shared by the candidate-fit and friction-ridge tests)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from clutch_model.diagnosis.sump_reading import smooth_sump
from clutch_model.discovery.synthetic import _campaign_from
from clutch_model.formats.bag_reader import Campaign
from clutch_model.plant.params import load_model
from clutch_model.virtual_car.campaign import CampaignSpec, synthesize_campaign


def reference_campaign(seed: int, n_runs: int, run_duration_s: float, rate_hz: float = 100.0):
    """(the reference model, a campaign of its inputs with the sump temperature smoothed as
    diagnose smooths it), the friction exactly the model's."""
    spec = CampaignSpec(seed=seed, n_runs=n_runs, run_duration_s=run_duration_s, rate_hz=rate_hz,
                        friction_spread=0.0)
    model = load_model(None)
    result = synthesize_campaign(spec, base_model=model)
    campaign, _ = _campaign_from(result, 0.0, np.random.default_rng(0))
    return model, smooth_sump(campaign)


def with_measured_torque(campaign, torque):
    """The campaign with ``torque`` (whole-campaign rows) as its measured torque."""
    return Campaign([replace(r, torque_measured_nm=np.asarray(torque)[sl].copy()) for r, sl in campaign.slices()])
