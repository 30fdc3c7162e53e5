"""A discovered extension that follows the slip angle (a once-per-revolution ripple) is accepted
only when a whole run is held out: the angle restarts with each bag, so time spans held out of
the fitted runs cannot show that the ripple's phase carries to another bag."""
from __future__ import annotations

import numpy as np

from clutch_model.diagnosis.engine import held_out_whole_runs, phase_unchecked
from clutch_model.diagnosis.selection import SelectionData

RIPPLE = {"mu:sin_slip_angle": 0.04, "mu:cos_slip_angle": -0.02}


def _data(test_rows):
    """Three runs of 100 rows; ``test_rows`` held out, the rest trained on."""
    n = 300
    run_start = np.zeros(n, bool)
    run_start[[0, 100, 200]] = True
    test = np.zeros(n, bool)
    test[test_rows] = True
    return SelectionData(y=np.zeros(n), t=np.tile(np.arange(100) * 0.005, 3), run_start=run_start,
                         train_mask=~test, test_mask=test, features=np.zeros((n, 1)), feature_names=["x"],
                         groups=np.cumsum(run_start) - 1)


def test_spans_of_fitted_runs_cannot_check_the_ripple_phase():
    spans = _data(np.r_[30:50, 130:150, 230:250])
    assert not held_out_whole_runs(spans)
    why = phase_unchecked(spans, RIPPLE)
    assert "slip angle" in why and "mu:sin_slip_angle" in why
    # terms that do not follow the angle are checked by the spans like any other
    assert phase_unchecked(spans, {"mu:pressure*pack_temperature": 2e-3}) == ""


def test_a_run_held_out_whole_checks_it():
    whole = _data(np.r_[100:200])
    assert held_out_whole_runs(whole)
    assert phase_unchecked(whole, RIPPLE) == ""
    # a whole run and spans of the others: the whole run checks the phase
    mixed = _data(np.r_[100:200, 230:250])
    assert phase_unchecked(mixed, RIPPLE) == ""
