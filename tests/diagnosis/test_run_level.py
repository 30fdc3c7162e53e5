"""A friction level that differs from run to run: found by the analysis of variance of the
level over runs under every noise class, never on pure noise, and reported by the selection as
``unexplained`` where it would otherwise say ``none``."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from clutch_model.diagnosis.run_level import MIN_LEVEL_SD, run_level_test, run_level_tests
from clutch_model.diagnosis.selection import SelectionData, select_causes

from .synthetic_residuals import NOISE_CLASSES, make_inputs, make_noise, split_every_third

SIGMA_NM = 8.0
LEVELS = np.array([0.0, 0.06, -0.05, 0.03, -0.02, 0.07])     # relative friction level per run


def _campaign(seed, noise, levels=None):
    d = make_inputs(seed, n_runs=6, duration_s=8.0)
    run_id = np.cumsum(d["run_start"]) - 1
    torque = 40.0 * d["torque"]           # hundreds of N·m, like the clutch
    level = np.zeros(torque.size) if levels is None else np.asarray(levels)[run_id]
    measured = torque * (1.0 + level) + make_noise(noise, d["run_start"], SIGMA_NM, 900 + seed)
    return d, torque, measured, run_id


@pytest.mark.parametrize("noise", NOISE_CLASSES)
def test_level_per_run_found_and_estimated(noise):
    d, torque, measured, run_id = _campaign(1, noise, LEVELS)
    rows = np.ones(torque.size, bool)
    res = run_level_test(measured - torque, torque, rows, d["run_start"], d["t"])
    assert res.found, res.as_dict()
    # the levels relative to their mean, within 1 % each; the spread near the truth's
    est = np.asarray(res.levels)
    assert np.max(np.abs((est - est.mean()) - (LEVELS - LEVELS.mean()))) < 0.01, res.levels
    assert 0.5 * LEVELS.std() < res.between_sd < 1.5 * LEVELS.std(ddof=1)


@pytest.mark.parametrize("noise", NOISE_CLASSES)
def test_no_level_on_pure_noise(noise):
    for seed in (2, 3, 4):
        d, torque, measured, run_id = _campaign(seed, noise)
        rows = np.ones(torque.size, bool)
        res = run_level_test(measured - torque, torque, rows, d["run_start"], d["t"])
        assert not res.found, res.as_dict()
        assert res.between_sd < MIN_LEVEL_SD
        # unweighted pieces, and the pair the selection runs (each at half the level)
        plain = run_level_test(measured - torque, torque, rows, d["run_start"], d["t"], whiten=False)
        assert not plain.found and plain.p_value > 0.01, plain.as_dict()
        both = run_level_tests(measured - torque, torque, rows, d["run_start"], d["t"])
        assert not both.found and both.other is not None and not both.other.found


@pytest.mark.parametrize("noise", NOISE_CLASSES)
def test_level_per_run_found_by_the_pair_of_weightings(noise):
    """The selection's pair of tests finds the levels under every noise class, and the one it
    reports estimates them within 1.5 % each."""
    d, torque, measured, run_id = _campaign(1, noise, LEVELS)
    res = run_level_tests(measured - torque, torque, np.ones(torque.size, bool), d["run_start"], d["t"])
    assert res.found and res.alpha == pytest.approx(0.0005), res.as_dict()
    est = np.asarray(res.levels)
    assert np.max(np.abs((est - est.mean()) - (LEVELS - LEVELS.mean()))) < 0.015, (res.weighting, res.levels)


def test_one_run_has_nothing_to_compare():
    d, torque, measured, run_id = _campaign(5, "white", LEVELS)
    one = run_id == 0
    start = d["run_start"][one]
    res = run_level_test((measured - torque)[one], torque[one], np.ones(one.sum(), bool), start, d["t"][one])
    assert not res.found and len(res.levels) == 1


@dataclass
class _Torque:
    """The baseline: predicts the clutch torque itself (the model the levels scale)."""
    torque: np.ndarray
    id: str = "baseline"
    parameters: dict = None

    def predict(self, data):
        return self.torque


def _selection(levels):
    d, torque, measured, run_id = _campaign(6, "ar1_095", levels)
    train, test = split_every_third(d["run_start"])
    feats = np.column_stack([d["force"], np.abs(d["slip"])])
    data = SelectionData(y=measured, t=d["t"], run_start=d["run_start"], train_mask=train, test_mask=test,
                         features=feats, feature_names=["force", "slip"], groups=run_id)
    return select_causes(data, _Torque(torque), [], intervals=False)


def test_selection_says_unexplained_for_a_level_per_run_and_none_without():
    sel = _selection(LEVELS)
    assert sel.verdict == "unexplained", sel.reason
    assert "friction level differs from run to run" in sel.reason
    assert sel.run_level is not None and sel.run_level.found
    sel = _selection(None)
    assert sel.verdict == "none", sel.reason
    assert sel.run_level is not None and not sel.run_level.found


def _clock_campaign(seed, noise, truth):
    """Four runs whose friction rises over the campaign: with the energy dissipated so far
    (``truth="energy"``, also within each run) or by a level per run in run order
    (``truth="levels"``, constant within a run). Returns (measured, baseline residual,
    residual of "μ_f rises with the energy", rows, run_start, t): both models fitted by least
    squares over the whole campaign, as the calibration and the discovery fit them."""
    d = make_inputs(seed, n_runs=4, duration_s=10.0)
    run_id = np.cumsum(d["run_start"]) - 1
    torque = 40.0 * d["torque"]
    energy = d["energy"] / d["energy"][-1]                 # 0 -> 1 over the campaign
    # +1 % over the campaign (the residual's RMS about 3 noise sds), or the same rise in steps
    if truth == "energy":
        factor = 1.0 + 0.01 * energy
    else:
        factor = 1.0 + 0.01 * (run_id + 0.5) / 4.0
    measured = torque * factor + make_noise(noise, d["run_start"], SIGMA_NM, 700 + seed)
    r = measured - torque
    level = np.linalg.lstsq(torque[:, None], r, rcond=None)[0]
    both = np.linalg.lstsq(np.column_stack([torque, torque * energy]), r, rcond=None)[0]
    base = r - level[0] * torque
    extension = r - both[0] * torque - both[1] * torque * energy
    return measured, base, extension, np.ones(r.size, bool), d["run_start"], d["t"]


@pytest.mark.parametrize("noise", NOISE_CLASSES)
def test_energy_term_holds_within_runs_only_when_the_friction_follows_the_energy(noise):
    """A term in the energy dissipated so far fits levels that rise with the run order as well
    as a friction that rises with the energy; only the latter changes within a run. The
    within-run forecast (each run's level fitted on its first half, the second half predicted)
    holds for it under every noise class and not for the levels."""
    from clutch_model.diagnosis.run_level import within_run_forecast

    for seed in (1, 2):
        measured, base, ext, rows, run_start, t = _clock_campaign(seed, noise, "energy")
        w = within_run_forecast(measured, base, ext, rows, run_start, t)
        assert w.runs == 4 and w.holds(1e-3, 0.005), (seed, w.comparison)
        measured, base, ext, rows, run_start, t = _clock_campaign(seed, noise, "levels")
        # the campaign-wide fit sees the rise: the energy term cuts the residual over the runs
        assert np.mean(ext ** 2) < 0.5 * np.mean(base ** 2)
        w = within_run_forecast(measured, base, ext, rows, run_start, t)
        assert not w.holds(1e-3, 0.005), (seed, w.comparison)
        assert w.comparison.rmse_alt > w.comparison.rmse_null


def test_a_degradation_named_alone_must_not_be_contradicted_within_the_runs():
    """Three runs whose friction levels fall with the run order (+8 %, -4 %, -9 %) and are
    constant within each run: an energy degradation fitted to them predicts a decline within
    each run that is not there, and its second-half forecasts are worse in plain squares than
    a level of the run, so it is not named (`unexplained`, the degradation the closest); on a
    true degradation (the same decline, within the runs too) the name stands. Independent
    truth: the measured torque is built from the levels or from the degradation itself."""
    from dataclasses import dataclass as _dc
    from types import SimpleNamespace

    from clutch_model.diagnosis.engine import degradation_within_runs
    from clutch_model.diagnosis.selection import Selection

    @_dc
    class Fixed:
        prediction: np.ndarray

        def predict(self, data):
            return self.prediction

    d = make_inputs(3, n_runs=3, duration_s=12.0, rate_hz=200.0)
    torque, energy, run_start = d["torque"], d["energy"], d["run_start"]
    run = np.cumsum(run_start) - 1
    scale = energy[-1] / np.log(1.0 / 0.83)                   # 17 % over the campaign
    decline = np.exp(-energy / scale)
    level = np.array([1.08, 0.96, 0.91])[run]
    noise = make_noise("white", run_start, SIGMA_NM, 7)
    train, test = run != 1, run == 1
    for truth, named_stays in ((torque * level, False), (torque * decline, True)):
        y = truth + noise
        # the degradation as fitted: the decline scaled to the data's mean level
        fitted = torque * decline * (np.sum(y * torque * decline) / np.sum((torque * decline) ** 2))
        data = SelectionData(y=y, t=d["t"], run_start=run_start, train_mask=train, test_mask=test)
        sel = Selection("named", [SimpleNamespace(id="friction_degradation")], [], Fixed(fitted), None, None, [],
                        {}, "named")
        out = degradation_within_runs(data, sel, Fixed(torque), lambda msg: None)
        if named_stays:
            assert out is sel
        else:
            assert out.verdict == "unexplained" and out.closest == ["friction_degradation"], out.reason
            assert out.causes == [] and "worse than a level of the run" in out.reason
