"""Lock phases under a measurement delay or sensor lag: the measured torque shows each lock
phase's driveline torque for a delay (or a few sensor time constants) after it ends, where no
clutch model can follow. The diagnosis leaves that tail out once it names such a cause and
diagnoses again; the truth scoring of the hidden campaigns leaves out the true tail."""
from __future__ import annotations

import os

import numpy as np
import pytest

from clutch_model.diagnosis.engine import LOCK_PAD_S, lock_tail_needed_s, with_lock_tail
from clutch_model.diagnosis.lockup import LockupResult
from clutch_model.formats.bag_reader import Campaign, Run
from clutch_model.virtual_car.car_logs import CarLogSpec, measurement_tail_s, near_true_lock
from clutch_model.virtual_car.hidden_campaigns import check_campaign, make_hidden_campaign

HIDDEN_SEED = int(os.environ.get("CLUTCH_HIDDEN_SEED", "20261123"))


def test_tail_follows_the_named_delay_and_sensor_lag():
    delay = {"id": "transport_delay", "parameters": {"delay_s": 0.15}, "parameters_ci95": {"delay_s": [0.14, 0.16]}}
    lag = {"id": "torque_sensor_lag", "parameters": {"tau_s": 0.05}, "parameters_ci95": {"tau_s": [0.04, 0.06]}}
    drag = {"id": "drag_torque", "parameters": {"coeff_nm_per_rad_s": 3.0}}
    assert lock_tail_needed_s([]) == 0.0
    assert lock_tail_needed_s([drag]) == 0.0
    assert lock_tail_needed_s([delay, drag]) == pytest.approx(0.16)          # the upper bound
    assert lock_tail_needed_s([lag]) == pytest.approx(3 * 0.06)
    assert lock_tail_needed_s([delay, lag]) == pytest.approx(0.16 + 0.18)
    # no interval: the estimate itself
    assert lock_tail_needed_s([{"id": "transport_delay", "parameters": {"delay_s": 0.12}}]) == pytest.approx(0.12)


def _run(name, t, torque):
    n = t.size
    return Run(name=name, t=t, applied_force_n=np.full(n, 5000.0), slip_speed_rad_s=np.full(n, 5.0),
               sump_temperature_c=np.full(n, 60.0), torque_measured_nm=torque)


def test_with_lock_tail_leaves_out_only_the_rows_after_each_phase():
    t = np.arange(0.005, 4.0, 0.01)            # no row on a boundary
    torque = np.where((t >= 1.0 - LOCK_PAD_S) & (t <= 1.5 + LOCK_PAD_S), np.nan, 100.0)   # already masked
    camp = Campaign([_run("a", t, torque.copy()), _run("b", t, np.full(t.size, 100.0))])
    locks = [LockupResult(np.zeros(t.size, bool), [(1.0, 1.5)], 0.01, 0.03, 0.045),
             LockupResult(np.zeros(t.size, bool), [], 0.01, 0.03, 0.045)]
    wider, more = with_lock_tail(camp, locks, 0.2)
    a = wider.runs[0].torque_measured_nm
    newly = (t > 1.5 + LOCK_PAD_S) & (t <= 1.5 + LOCK_PAD_S + 0.2)
    assert np.all(np.isnan(a[newly]))
    assert np.array_equal(np.isnan(a), np.isnan(torque) | newly)            # nothing before, nothing else
    assert np.array_equal(more[: t.size], newly)
    assert not more[t.size:].any()
    assert np.array_equal(wider.runs[1].torque_measured_nm, camp.runs[1].torque_measured_nm)


def test_with_lock_tail_also_follows_each_zero_crossing_of_the_slip():
    """A delayed or low-passed reading flips after the slip: the tail is left out past each zero
    crossing's window too (the window itself was left out before), and nowhere else."""
    t = np.arange(0.005, 4.0, 0.01)
    window = (2.0, 2.06)
    torque = np.where((t >= window[0]) & (t <= window[1]), np.nan, 100.0)
    camp = Campaign([_run("a", t, torque.copy())])
    locks = [LockupResult(np.zeros(t.size, bool), [], 0.01, 0.03, 0.045, crossings=[window])]
    wider, more = with_lock_tail(camp, locks, 0.1)
    newly = (t > window[1]) & (t <= window[1] + 0.1)
    assert newly.sum() == 10
    assert np.array_equal(np.isnan(wider.runs[0].torque_measured_nm), np.isnan(torque) | newly)
    assert np.array_equal(more, newly)
    # the crossing's own tail when given (a delay's part only): none leaves the crossing's rows
    _, none_more = with_lock_tail(camp, locks, 0.1, crossing_tail_s=0.0)
    assert not none_more.any()
    _, short = with_lock_tail(camp, locks, 0.1, crossing_tail_s=0.03)
    assert np.array_equal(short, (t > window[1]) & (t <= window[1] + 0.03))


def test_a_crossing_asks_for_the_delay_alone():
    """After a lock phase a delay and three sensor time constants; after a zero crossing the
    delay alone (a sensor lag's smear of the flip is its evidence, not a jump to leave out)."""
    from clutch_model.diagnosis.engine import lock_tail_needed_s

    causes = [{"id": "transport_delay", "parameters": {"delay_s": 0.02}, "parameters_ci95": {"delay_s": [0.018, 0.022]}},
              {"id": "torque_sensor_lag", "parameters": {"tau_s": 0.04}, "parameters_ci95": {"tau_s": [0.035, 0.05]}}]
    assert lock_tail_needed_s(causes) == pytest.approx(0.022 + 3 * 0.05)
    assert lock_tail_needed_s(causes, delay_only=True) == pytest.approx(0.022)
    assert lock_tail_needed_s(causes[1:], delay_only=True) == 0.0


def test_truth_scoring_leaves_out_the_sensor_tail():
    ft = np.arange(0.0, 3.0, 0.001)
    side = {"fine_t_s": ft, "fine_locked": ((ft >= 1.0) & (ft <= 1.5)).astype(np.int8)}
    t = np.array([0.85, 0.95, 1.2, 1.55, 1.65, 1.75, 1.85, 2.0])
    assert near_true_lock(side, t, 0.1).tolist() == [False, True, True, True, False, False, False, False]
    assert near_true_lock(side, t, 0.1, tail_s=0.2).tolist() == [False, True, True, True, True, True, False, False]
    spec = CarLogSpec(mechanisms=[{"id": "transport_delay", "delay_s": 0.12}],
                      effects=[{"name": "torque_sensor_lowpass", "tau_s": 0.03}])
    assert measurement_tail_s(spec) == pytest.approx(0.12 + 0.09)
    assert measurement_tail_s(CarLogSpec()) == 0.0


# acceptance-style (111 s on the 2-core machine, the slowest test of `make test`): the lock tail
# itself is checked by the tests above; `-m slow` runs it
@pytest.mark.slow
def test_a_delay_longer_than_the_lock_pad_is_named_at_its_size(tmp_path):
    """A 0.3 s transport delay (a slow bus) with lock-up phases: the measured torque shows each
    lock phase's driveline torque for 0.3 s after it, longer than the lock pad (0.2 s). The
    diagnosis leaves that tail out once the delay is in sight and diagnoses again: the delay is
    named at its size and its gain holds on runs diagnose never saw."""
    camp = make_hidden_campaign("transport_delay", "lockup", 47, tmp_path / "campaign",
                                magnitude_seed=HIDDEN_SEED, magnitudes={"transport_delay": 0.3}, quick=True)
    res = check_campaign(camp, tmp_path, mc_samples=40, stamps=False)
    what = f"diagnose said {res.named_label}: {(res.report or {}).get('cause', {}).get('evidence', res.error)}"
    assert res.judgement == "ok", what
    (cause,) = res.report["causes"]
    assert cause["parameters"]["delay_s"] == pytest.approx(0.3, rel=0.05), what
    lo, hi = cause["parameters_ci95"]["delay_s"]
    assert lo < 0.3 < hi and hi - lo < 0.03, what      # timing resolution included (half a row)
    # the gain holds on the runs diagnose never saw, against the true torque (tail left out)
    assert res.replay_rmse_nm["extended"] < 0.5 * res.replay_rmse_nm["calibrated"], res.replay_rmse_nm


def test_time_parameters_carry_the_grid_timing_resolution():
    from clutch_model.diagnosis.engine import with_timing_resolution

    causes = [{"id": "transport_delay", "parameters": {"delay_s": 0.2978}, "parameters_ci95": {"delay_s": [0.2977, 0.298]}},
              {"id": "drag_torque", "parameters": {"coeff_nm_per_rad_s": 2.0},
               "parameters_ci95": {"coeff_nm_per_rad_s": [1.9, 2.1]}},
              {"id": "drag_torque", "parameters": {"coeff_nm_per_rad_s": 2.0},
               "parameters_ci95": {"coeff_nm_per_rad_s": [2.1, 2.3]}}]
    with_timing_resolution(causes, 0.0025)
    assert causes[0]["parameters_ci95"]["delay_s"] == pytest.approx([0.2952, 0.3005])
    assert causes[1]["parameters_ci95"]["coeff_nm_per_rad_s"] == pytest.approx([1.9, 2.1])   # not a time
    assert causes[2]["parameters_ci95"]["coeff_nm_per_rad_s"] == pytest.approx([2.0, 2.3])   # holds the value


def test_tail_covers_every_candidate_that_predicts_the_held_out_data():
    """Candidates are compared on the same rows: a torque-sensor lag that predicts the held-out
    data better than the noise model asks for its tail even when another cause is named (a
    0.1 s sensor lag lost to actuator_lag while the rows its tail spoils were compared), and a
    candidate that does not predict it asks for nothing."""
    from types import SimpleNamespace as NS

    from clutch_model.diagnosis.engine import _lock_tail_of

    def score(cid, significant, **params):
        return NS(id=cid, significant=significant, fitted=NS(parameters=params))

    scores = [score("actuator_lag", True, tau_s=0.1), score("torque_sensor_lag", True, tau_s=0.09),
              score("transport_delay", False, delay_s=0.5)]
    named = NS(causes=[{"id": "actuator_lag", "parameters": {"tau_s": 0.1}}], cause_id="actuator_lag",
               scores=scores, selection=NS(closest=[]))
    assert _lock_tail_of(named) == pytest.approx(3 * 0.09)
    # a named delay asks for more than the runner-up's lag: the longest wins
    delay = {"id": "transport_delay", "parameters": {"delay_s": 0.3}, "parameters_ci95": {"delay_s": [0.29, 0.31]}}
    assert _lock_tail_of(NS(causes=[delay], cause_id="transport_delay", scores=scores,
                            selection=NS(closest=[]))) == pytest.approx(0.31)
    # nothing significant, nothing named: no tail
    quiet = [score("torque_sensor_lag", False, tau_s=0.2), score("transport_delay", False, delay_s=0.3)]
    assert _lock_tail_of(NS(causes=[], cause_id="none", scores=quiet, selection=NS(closest=[]))) == 0.0
    # unexplained between lookalikes: the closest candidates' tails, significant or not
    assert _lock_tail_of(NS(causes=[], cause_id="unexplained", scores=quiet,
                            selection=NS(closest=["transport_delay"]))) == pytest.approx(0.3)
    assert _lock_tail_of(NS(causes=[], cause_id="none", scores=quiet, selection=None)) == 0.0


def test_the_first_step_asks_for_its_tail_before_the_selection_goes_on():
    """The first selection step (every catalog mechanism fitted alone) already holds the
    candidates whose tail ``_lock_tail_of`` would count after a whole diagnosis: the screen stops
    the diagnosis there with the longest tail a significant candidate asks for, and lets it go
    on when none asks for more than the slack."""
    from types import SimpleNamespace as NS

    from clutch_model.diagnosis.engine import (LOCK_TAIL_SCREEN_MARGIN, LOCK_TAIL_SLACK_S, WiderLockTail, _lock_tail_of,
                                               _lock_tail_screen)

    def score(cid, significant, **params):
        return NS(id=cid, significant=significant, fitted=NS(parameters=params))

    step = NS(scores=[score("actuator_lag", True, tau_s=0.1), score("torque_sensor_lag", True, tau_s=0.04),
                      score("transport_delay", True, delay_s=0.09), score("drag_torque", True, coeff_nm_per_rad_s=3.0)])
    with pytest.raises(WiderLockTail) as raised:
        _lock_tail_screen(0.0)(step)
    assert raised.value.tail_s == pytest.approx(LOCK_TAIL_SCREEN_MARGIN * 3 * 0.04)
    assert raised.value.which == "torque_sensor_lag"
    # the tail the whole diagnosis would have asked for with nothing named, with the margin that
    # stands for the named causes' upper bounds
    whole = NS(causes=[], cause_id="none", scores=step.scores, selection=NS(closest=[]))
    assert raised.value.tail_s == pytest.approx(LOCK_TAIL_SCREEN_MARGIN * _lock_tail_of(whole))
    assert LOCK_TAIL_SCREEN_MARGIN >= 1.0
    # on rows with that tail left out the same step asks for nothing more: the diagnosis goes on
    _lock_tail_screen(3 * 0.04 + LOCK_TAIL_SLACK_S)(step)
    _lock_tail_screen(3 * 0.04 - 0.5 * LOCK_TAIL_SLACK_S)(step)      # within the slack
    with pytest.raises(WiderLockTail):
        _lock_tail_screen(3 * 0.04 - 2.0 * LOCK_TAIL_SLACK_S)(step)
    # not significant, or within the slack: the diagnosis goes on
    _lock_tail_screen(0.0)(NS(scores=[score("transport_delay", False, delay_s=0.3),
                                      score("transport_delay", True, delay_s=0.5 * LOCK_TAIL_SLACK_S)]))
    _lock_tail_screen(0.0)(NS(scores=[]))
