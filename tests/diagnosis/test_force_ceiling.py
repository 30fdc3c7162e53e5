"""A ceiling on the pack force (force_ceiling.py): the path, its fit on noise-free torque, and
the rule that a ceiling binding on a few rows never takes the name."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from clutch_model.diagnosis.force_ceiling import MIN_CEILING_BINDING, ceiling_force, fit_force_ceiling


def test_ceiling_force_is_the_force_below_it_and_the_ceiling_above():
    f = np.array([0.0, 500.0, 2000.0, 8000.0, 12000.0])
    assert np.array_equal(ceiling_force(f, 8000.0), [0.0, 500.0, 2000.0, 8000.0, 8000.0])
    assert np.array_equal(ceiling_force(f, 1e9), f)


def test_a_ceiling_is_recovered_where_the_log_passes_it():
    """The pack force stops at 70 % of the campaign's largest force while the log passes it:
    ForceCeilingObjective fitted on the noise-free torque (the plant driven by the capped force)
    gives the ceiling back within 3 % and cuts the error of the log taken as the pack force by
    more than 90 %."""
    from clutch_model.formats.bag_reader import Campaign
    from clutch_model.replay import replay_runs
    from .noise_free_campaigns import reference_campaign, with_measured_torque

    model, logged_inputs = reference_campaign(5, 4, 6.0)
    top = float(np.nanmax(logged_inputs.force))
    ceiling = 0.7 * top
    capped = Campaign([replace(r, applied_force_n=ceiling_force(r.applied_force_n, ceiling))
                       for r, _ in logged_inputs.slices()])
    torque = replay_runs(model, capped).torque_sim
    logged = with_measured_torque(logged_inputs, torque)
    every = np.ones(logged.t.size, bool)

    def rmse(pred):
        return float(np.sqrt(np.mean((np.asarray(pred) - torque) ** 2)))
    as_logged = rmse(replay_runs(model, logged).torque_sim)
    fit = fit_force_ceiling(model, logged, every)
    assert fit.parameters["ceiling_n"] == pytest.approx(ceiling, rel=0.03)
    assert rmse(fit.predicted) < 0.1 * as_logged
    # binding: the capped rows are far more than the rule's share
    assert np.mean(logged.force > ceiling + 50.0) > 5 * MIN_CEILING_BINDING


def test_a_ceiling_at_the_largest_forces_only_is_refused(monkeypatch):
    """A ceiling that holds the force off the measured one on under MIN_CEILING_BINDING of the
    fitted rows never takes the name: the selection stays as it was, flagged rarely_binding."""
    from types import SimpleNamespace

    import clutch_model.diagnosis.force_ceiling as fc
    import clutch_model.diagnosis.force_dynamics as fd

    t = np.linspace(0.0, 10.0, 2001)
    force = 5000.0 + 4000.0 * np.sin(2 * np.pi * 0.3 * t)
    camp = SimpleNamespace(t=t, force=force)
    monkeypatch.setattr(fd.PlantInputs, "of", staticmethod(lambda c: SimpleNamespace(
        force=c.force, at_rows=lambda x: np.asarray(x))))
    monkeypatch.setattr(fd, "_force_noise_n", lambda *s: 10.0)
    before, taken = SimpleNamespace(verdict="named"), SimpleNamespace(verdict="unexplained")
    every = np.ones(t.size, bool)
    sel, found = fc._unless_rarely_binding(taken, before, {"took_the_name": True}, camp, every, 8999.0, print)
    assert sel is before and found["rarely_binding"] and not found["took_the_name"]
    sel, found = fc._unless_rarely_binding(taken, before, {"took_the_name": True}, camp, every, 7000.0, print)
    assert sel is taken and found["took_the_name"] and found["binding_row_fraction"] > 0.2
