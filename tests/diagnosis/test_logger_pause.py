"""A logger pause (every input silent at once inside a bag): found from the raw stamps, and the
rows after it kept out of the residuals while the pack temperature may be off."""
import math

import numpy as np
import pytest

from clutch_model.diagnosis.logger_pause import (PACK_TOLERANCE_K, input_pauses, pauses_of_run,
                                                 without_rows_after_pauses)
from clutch_model.formats.bag_reader import Campaign, Run
from clutch_model.plant import layout as L
from clutch_model.plant.params import load_model

REFERENCE = load_model()       # the shipped reference clutch


def _run(duration_s=30.0, silent=((10.0, 11.5),), force_silent=(), slip_rad_s=5.0, force_n=3000.0,
         torque_nm=400.0, name="r"):
    """A run at constant slip, force and torque; force 200 Hz, slip 100 Hz, torque 200 Hz;
    ``silent``: spans where every topic is silent; ``force_silent``: spans of the force alone."""
    def stamps(rate, extra=()):
        t = np.arange(0.0, duration_s, 1.0 / rate)
        for a, b in tuple(silent) + tuple(extra):
            t = t[(t < a) | (t > b)]
        return t
    tf, ts, tq = stamps(200.0, force_silent), stamps(100.0), stamps(200.0)
    rows = tf
    return Run(name, rows, np.full(rows.size, force_n), np.full(rows.size, slip_rad_s), np.full(rows.size, 60.0),
               torque_measured_nm=np.full(rows.size, torque_nm),
               samples={"applied_force": (tf, np.full(tf.size, force_n)),
                        "slip_speed": (ts, np.full(ts.size, slip_rad_s)),
                        "measured_torque": (tq, np.full(tq.size, torque_nm))})


def test_a_pause_of_every_input_is_found_and_one_topic_alone_is_not():
    (t0, t1), = input_pauses(_run())
    assert t0 == pytest.approx(10.0, abs=0.006) and t1 == pytest.approx(11.5, abs=0.006)
    # the force silent alone (logged on change): the slip still says what the clutch did
    assert input_pauses(_run(silent=(), force_silent=((10.0, 12.0),))) == []
    # a silence shorter than PAUSE_MIN_S is the topics' own jitter
    assert input_pauses(_run(silent=((10.0, 10.1),))) == []


def test_the_rows_left_out_end_where_the_pack_bound_has_decayed_to_the_tolerance():
    """Constant slip and force: the bound decays at one rate, A_N*H_tf/C, and the rows are
    left out to t1 + ln(bound0 / tolerance) / rate (an analytic expectation from the plant's
    heat law, thesis eq. 3.18)."""
    slip, force, torque = 5.0, 3000.0, 400.0
    run = _run(duration_s=400.0, slip_rad_s=slip, force_n=force, torque_nm=torque)
    pause, = pauses_of_run(run, REFERENCE)
    p = REFERENCE.vector()
    c, n_sp, area = p[L.PLATE_HEAT_CAPACITY], p[L.N_SEPARATOR], REFERENCE.nominal_area_m2
    bound0 = slip * torque * (pause.t1_s - pause.t0_s) / (n_sp * c)
    assert pause.pack_bound_k == pytest.approx(bound0, rel=1e-9)
    h = max(p[L.B1] + p[L.B2] * slip + p[L.B3] * force / 1e3 + p[L.B4] * slip * force / 1e3, p[L.HTF_MIN])
    rate = area * h / c
    expected_end = pause.t1_s + math.log(bound0 / PACK_TOLERANCE_K) / rate
    assert 30.0 < expected_end - pause.t1_s < 300.0          # the pack's slow memory: tens of seconds
    assert pause.left_out_to_s == pytest.approx(expected_end, abs=0.01)


def test_rows_after_a_pause_lose_their_torque_and_the_rest_keep_it():
    quiet = _run(name="quiet", silent=())
    paused = _run(name="paused")
    campaign, mask, pauses = without_rows_after_pauses(Campaign([quiet, paused]), REFERENCE)
    assert [p.run for p in pauses] == ["paused"]
    q, r = campaign.runs
    assert np.isfinite(q.torque_measured_nm).all()
    after = (r.t > pauses[0].t0_s) & (r.t <= pauses[0].left_out_to_s)
    assert after.any() and np.isnan(r.torque_measured_nm[after]).all()
    assert np.isfinite(r.torque_measured_nm[~after]).all()
    assert mask.sum() == pauses[0].rows_left_out == after.sum()


def test_a_pause_while_the_clutch_is_open_leaves_nothing_out():
    """No slip power near the pause: the pack cannot have taken heat the model missed."""
    pause, = pauses_of_run(_run(slip_rad_s=0.0), REFERENCE)
    assert pause.pack_bound_k == 0.0 and pause.left_out_to_s == pause.t1_s
