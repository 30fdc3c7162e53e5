"""A fit the selection asks for again is the fit it got the first time (candidates.fit_alone,
FitMemo).

The memo keys a fit by value (mechanism, base model, rows, joint or alone, starts, the ridge of a
joint fit). The expectation is independent of it: ``fitting.fit_candidate`` called directly on
the same inputs. Repeats are counted by the fits actually made.
"""
from __future__ import annotations

import numpy as np
import pytest

import clutch_model.diagnosis.candidates as candidates
from clutch_model.diagnosis.candidates import CampaignContext, FitMemo, fit_alone, model_digest
from clutch_model.diagnosis.fitting import fit_candidate
from clutch_model.plant.mechanisms import make_mechanism
from clutch_model.prediction import predict_campaign

from .noise_free_campaigns import reference_campaign, with_measured_torque


@pytest.fixture(scope="module")
def offset_campaign():
    model, campaign = reference_campaign(seed=5, n_runs=2, run_duration_s=4.0)
    truth = model.with_mechanisms([make_mechanism("torque_offset", offset_nm=12.0)])
    torque = predict_campaign(truth, campaign, energy0_j=0.0).torque_nm
    rng = np.random.default_rng(3)
    campaign = with_measured_torque(campaign, torque + rng.normal(0.0, 1.0, torque.size))
    return model, campaign


def _context(campaign):
    scale = float(np.nanpercentile(np.abs(campaign.torque_measured), 95))
    return CampaignContext(campaign, energy_total_j=1e6, torque_scale=scale, sigma_nm=1.0)


def _counting(monkeypatch):
    made = []
    real = candidates.fit_candidate

    def counted(*args, **kwargs):
        made.append(args[3])
        return real(*args, **kwargs)

    monkeypatch.setattr(candidates, "fit_candidate", counted)
    return made


def test_a_repeated_fit_is_the_fit_made_once(offset_campaign, monkeypatch):
    model, campaign = offset_campaign
    ctx = _context(campaign)
    made = _counting(monkeypatch)
    mask = np.arange(campaign.t.size) % 3 != 0
    direct = fit_candidate(model, campaign, mask, "torque_offset", ctx.energy_total_j, ctx.torque_scale,
                           fit_friction=True, noise_sigma_nm=ctx.sigma_nm)
    first = fit_alone(ctx, "torque_offset", model, mask, joint=True)
    # an equal model built anew (another object), the same rows as another array
    again = fit_alone(ctx, "torque_offset", model.copy(), mask.copy(), joint=True)
    assert made == ["torque_offset"]
    for fit in (first, again):
        assert fit.parameters["offset_nm"] == pytest.approx(direct.parameters["offset_nm"], rel=1e-12)
        np.testing.assert_array_equal(fit.residual, direct.residual)
        np.testing.assert_array_equal(fit.friction_correction, direct.friction_correction)
    assert first.parameters["offset_nm"] == pytest.approx(12.0, abs=0.5)
    # what a caller does to its copy does not reach the memo
    again.parameters["offset_nm"] = -1.0
    assert fit_alone(ctx, "torque_offset", model, mask, joint=True).parameters["offset_nm"] == first.parameters["offset_nm"]
    assert len(made) == 1


def test_fits_that_differ_in_any_input_are_made_apart(offset_campaign, monkeypatch):
    model, campaign = offset_campaign
    ctx = _context(campaign)
    made = _counting(monkeypatch)
    mask = np.ones(campaign.t.size, bool)
    fit_alone(ctx, "torque_offset", model, mask)
    fit_alone(ctx, "torque_offset", model, mask, joint=True)                       # joint
    fit_alone(ctx, "torque_offset", model, mask, start={"offset_nm": 5.0})           # another start
    other_rows = mask.copy()
    other_rows[: other_rows.size // 2] = False
    fit_alone(ctx, "torque_offset", model, other_rows)                              # other rows
    moved = model.with_friction(a=model.friction_coefficients * 1.01)
    assert model_digest(moved) != model_digest(model)
    fit_alone(ctx, "torque_offset", moved, mask)                                     # another base
    fit_alone(ctx, "drag_torque", model, mask)                                       # another mechanism
    assert len(made) == 6
    # at another ridge: a joint fit is made again, a fit alone (friction held) is shared
    ridged = ctx.at_friction_ridge(16.0)
    fit_alone(ridged, "torque_offset", model, mask)
    assert len(made) == 6
    at_ridge = fit_alone(ridged, "torque_offset", model, mask, joint=True)
    assert len(made) == 7
    direct = fit_candidate(model, campaign, mask, "torque_offset", ctx.energy_total_j, ctx.torque_scale,
                           fit_friction=True, noise_sigma_nm=ctx.sigma_nm, ridge_factor=16.0)
    np.testing.assert_array_equal(at_ridge.friction_correction, direct.friction_correction)


def test_the_memo_forgets_the_least_recently_used_beyond_its_bytes():
    class Fit:
        def __init__(self, n):
            self.residual, self.predicted = np.zeros(n), np.zeros(n)

    memo = FitMemo(max_bytes=3 * 2 * 8 * 100)          # three fits of 100 rows
    for k in "abc":
        memo.put(k, Fit(100))
    assert memo.get("a") is not None                   # "a" used: "b" is now the oldest
    memo.put("d", Fit(100))
    assert memo.get("b") is None
    assert all(memo.get(k) is not None for k in "acd")
    memo.put("e", Fit(1000))                           # larger than the budget alone: kept, the rest go
    assert memo.get("e") is not None and all(memo.get(k) is None for k in "acd")
