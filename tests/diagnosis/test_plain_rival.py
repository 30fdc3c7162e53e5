"""A named cause against a candidate, not named, that predicts the held-out rows far better in
plain squares (plain_rival.py): the answer turns ``unexplained`` with both as the closest; a
rival that does about as well, or worse, leaves the named answer alone. The selection is stood
in for by fixed predictions; the block test and the verdict are the module's own."""
from __future__ import annotations

import numpy as np

from clutch_model.diagnosis.plain_rival import RIVAL_CUT, named_or_plain_rival
from clutch_model.diagnosis.selection import Cause, CandidateScore, Selection, SelectionData, SelectionStep
from .synthetic_residuals import Fixed, run_grid

RATE_HZ, RUN_S, N_RUNS = 200.0, 12.0, 4


def _data(seed=0):
    t, run, run_start = run_grid(RATE_HZ, RUN_S, N_RUNS)
    structure = 6.0 * np.sin(2 * np.pi * 0.3 * t + run) + 3.0 * np.sign(np.sin(2 * np.pi * 0.7 * t))
    y = structure + np.random.default_rng(seed).normal(0.0, 1.0, t.size)
    test = (t % 3.0) >= 2.0                      # a third of every run, in spans
    return SelectionData(y=y, t=t, run_start=run_start, train_mask=~test, test_mask=test), structure


def _selection(named: Fixed, rivals: dict) -> Selection:
    scores = [CandidateScore("actuator_hysteresis", named, None)]
    scores += [CandidateScore(cid, fit, None) for cid, fit in rivals.items()]
    step = SelectionStep(scores, "actuator_hysteresis", [])
    cause = Cause("actuator_hysteresis", named, {"ratio": 0.05}, {"ratio": [0.02, 0.09]}, None)
    return Selection("named", [cause], [step], named, None, None, [], {}, "named in order", None)


def test_a_rival_that_cuts_the_named_plain_error_by_far_takes_the_name_away():
    data, structure = _data()
    named = Fixed(0.2 * structure)                       # a sliver of it
    sel, found = named_or_plain_rival(data, _selection(named, {"torque_sensor_lag": Fixed(0.9 * structure),
                                                                "drag_torque": Fixed(np.zeros_like(structure))}))
    assert sel.verdict == "unexplained" and sel.causes == []
    assert sel.closest == ["actuator_hysteresis", "torque_sensor_lag"]
    assert found["took_the_name"] and found["rival"] == "torque_sensor_lag"
    # the cut: 1 - (1 + 0.01 S) / (1 + 0.64 S), S the structure's mean square over the noise's (~27)
    s2 = np.mean(structure[data.test_mask] ** 2)
    expected = 1.0 - (1.0 + 0.01 * s2) / (1.0 + 0.64 * s2)
    assert abs(found["rivals"]["torque_sensor_lag"]["cut_frac"] - expected) < 0.03
    assert found["rivals"]["drag_torque"]["cut_frac"] < 0
    assert sel.closest_leaves["held_out_rmse"] > 1.0


def test_a_rival_about_as_good_or_worse_leaves_the_named_cause():
    data, structure = _data(seed=1)
    named = Fixed(0.6 * structure)
    # 0.6 -> 0.65 of the structure: the rival cuts about a fifth, under RIVAL_CUT
    rivals = {"torque_sensor_lag": Fixed(0.65 * structure), "spring_preload": Fixed(0.1 * structure)}
    sel, found = named_or_plain_rival(data, _selection(named, rivals))
    assert sel.verdict == "named" and [c.id for c in sel.causes] == ["actuator_hysteresis"]
    assert not found["took_the_name"]
    assert 0 < found["rivals"]["torque_sensor_lag"]["cut_frac"] < RIVAL_CUT
    assert found["rivals"]["spring_preload"]["cut_frac"] < 0


def test_nothing_is_checked_where_nothing_is_named():
    data, structure = _data()
    sel = _selection(Fixed(np.zeros_like(structure)), {"torque_sensor_lag": Fixed(structure)})
    none = Selection("none", [], sel.steps, sel.final, None, None, [], {}, "nothing", None)
    out, found = named_or_plain_rival(data, none)
    assert out is none and found is None
