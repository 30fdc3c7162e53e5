"""A constant torque in the clutch torque's direction (signed_torque.py), the bench-anchor
check's rival beyond the catalog of a preload: recovered as a dead band and as a fixed drag on
noise-free torque, and told from a spring preload, whose torque moves with the friction."""
from __future__ import annotations

import numpy as np
import pytest

from clutch_model.diagnosis.signed_torque import fit_signed_torque, signed_constant_torque


def test_signed_constant_torque_is_a_dead_band_or_a_fixed_drag():
    t = np.array([-30.0, -3.0, 0.0, 2.0, 30.0])
    assert signed_constant_torque(t, -4.0).tolist() == [-26.0, 0.0, 0.0, 0.0, 26.0]
    assert signed_constant_torque(t, 4.0).tolist() == [-34.0, -7.0, 0.0, 6.0, 34.0]


def rmse(a, b):
    ok = np.isfinite(a) & np.isfinite(b)
    return float(np.sqrt(np.mean((np.asarray(a)[ok] - np.asarray(b)[ok]) ** 2)))


@pytest.mark.parametrize("d_nm", [-4.65, 6.0])
def test_a_signed_constant_torque_is_recovered(d_nm):
    from clutch_model.replay import replay_runs
    from .noise_free_campaigns import reference_campaign, with_measured_torque

    model, camp = reference_campaign(6, 4, 6.0)
    plant = np.asarray(replay_runs(model, camp).torque_sim, float)
    measured = signed_constant_torque(plant, d_nm)
    fit = fit_signed_torque(model, with_measured_torque(camp, measured), np.ones(camp.t.size, bool))
    assert fit.parameters["torque_nm"] == pytest.approx(d_nm, abs=0.1)
    assert rmse(fit.predicted, measured) < 0.05 * rmse(plant, measured)


def test_a_spring_preload_is_not_a_constant_torque():
    """A 400 N preload takes mu x 400 N off the pack: its torque moves with the friction
    coefficient, so the best constant torque leaves a good part of it, where the preload, fitted
    as the catalog fits it, leaves nothing."""
    from clutch_model.diagnosis.fitting import fit_candidate
    from clutch_model.plant.mechanisms import make_mechanism
    from clutch_model.replay import replay_runs
    from .noise_free_campaigns import reference_campaign, with_measured_torque

    model, camp = reference_campaign(6, 4, 6.0)
    truth = model.with_mechanisms([make_mechanism("spring_preload", preload_n=400.0)])
    measured = np.asarray(replay_runs(truth, camp).torque_sim, float)
    plant = np.asarray(replay_runs(model, camp).torque_sim, float)
    logged = with_measured_torque(camp, measured)
    every = np.ones(camp.t.size, bool)
    signed = fit_signed_torque(model, logged, every)
    assert signed.parameters["torque_nm"] < 0.0
    preload = fit_candidate(model, logged, every, "spring_preload", 1.0, 1.0, fit_friction=False)
    assert preload.parameters["preload_n"] == pytest.approx(400.0, rel=0.05)
    left_signed, effect = rmse(signed.predicted, measured), rmse(plant, measured)
    assert left_signed < 0.6 * effect                           # it takes much of it (25 of 58 N*m) ...
    assert left_signed > 0.2 * effect                           # ... not all
    assert rmse(preload.predicted, measured) < 0.01 * effect
