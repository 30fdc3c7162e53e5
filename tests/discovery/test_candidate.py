"""Discovery as a candidate of the diagnosis' forward selection: fitted on the training rows
only (held-out torque never read), on top of the model so far, predicting every row."""
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from clutch_model.discovery.candidate import DiscoveryCandidate
from clutch_model.discovery.synthetic import make_case
from clutch_model.formats.bag_reader import Campaign


def test_fit_uses_training_rows_only_and_finds_the_term():
    truth = {"mu:pressure*pack_temperature": 2.5e-3}
    tc = make_case(41, truth)
    camp = tc.campaign
    held = np.isin(camp.run_index, [camp.names.index(n) for n in tc.held_out])
    train = SimpleNamespace(mask=~held, base=SimpleNamespace(model=tc.calibrated_model), selected=())
    fitted = DiscoveryCandidate(camp, bench_model=tc.bench_model).fit(train)
    assert set(fitted.parameters) == set(truth)
    assert fitted.parameters["mu:pressure*pack_temperature"] == pytest.approx(2.5e-3, rel=0.15)
    lo, hi = fitted.parameters_ci95["mu:pressure*pack_temperature"]
    assert lo < fitted.parameters["mu:pressure*pack_temperature"] < hi
    pred = fitted.predict(None)
    assert pred.shape == camp.torque_measured.shape and np.isfinite(pred).all()
    assert fitted.model.mechanism("discovered") is not None
    # the held-out torque is never read: scrambling it changes nothing
    runs = [replace(r, torque_measured_nm=r.torque_measured_nm + 500.0 * np.sin(np.arange(len(r))))
            if r.name in tc.held_out else r for r in camp.runs]
    again = DiscoveryCandidate(Campaign(runs), bench_model=tc.bench_model).fit(train)
    assert again.parameters == fitted.parameters
    np.testing.assert_allclose(again.predict(None), pred)


def test_nothing_to_find_returns_the_model_so_far():
    tc = make_case(42, {})
    camp = tc.campaign
    held = np.isin(camp.run_index, [camp.names.index(n) for n in tc.held_out])
    train = SimpleNamespace(mask=~held, base=SimpleNamespace(model=tc.calibrated_model), selected=())
    fitted = DiscoveryCandidate(camp, bench_model=tc.bench_model).fit(train)
    assert fitted.parameters == {} and fitted.model is tc.calibrated_model
    from clutch_model.replay import replay_runs
    np.testing.assert_allclose(fitted.predict(None), replay_runs(tc.calibrated_model, camp).torque_sim, atol=1e-9)


def test_a_refit_that_fails_numerically_names_nothing_and_says_why(monkeypatch):
    """A joint refit that breaks down (scipy: "array must not contain infs or NaNs", seen when a
    term makes the simulation run away) ends the search with no term and a reason; it must not
    escape as an exception (diagnose would show a traceback)."""
    import clutch_model.discovery.identify as identify

    def broken(*args, **kwargs):
        raise ValueError("array must not contain infs or NaNs")

    monkeypatch.setattr(identify, "least_squares", broken)
    tc = make_case(41, {"mu:pressure*pack_temperature": 2.5e-3})
    camp = tc.campaign
    held = np.isin(camp.run_index, [camp.names.index(n) for n in tc.held_out])
    train = SimpleNamespace(mask=~held, base=SimpleNamespace(model=tc.calibrated_model), selected=())
    fitted = DiscoveryCandidate(camp, bench_model=tc.bench_model).fit(train)
    assert fitted.parameters == {} and fitted.model is tc.calibrated_model
    assert any("joint refit failed (array must not contain infs or NaNs)" in d[2] for d in fitted.dropped)
    assert np.isfinite(fitted.predict(None)).all()
