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


def _truth_run(pause_slip_rad_s, duration_s=120.0, pause=(30.0, 33.0), slip_rad_s=5.0, force_n=3000.0,
               noise_nm=1.0, seed=0):
    """A run whose clutch (the reference model) slipped at ``pause_slip_rad_s`` through a pause
    of every topic, at ``slip_rad_s`` elsewhere: rows on a 200 Hz grid through the pause (as the
    diagnosis' measured-time grid fills it), the logged inputs held at what they were before and
    after it, the measured torque the truth's plus white noise, NaN inside the pause."""
    from clutch_model.prediction import predict_campaign

    t = np.arange(0.0, duration_s, 0.005)
    inside = (t > pause[0]) & (t < pause[1])
    force = np.full(t.size, force_n)
    true_slip = np.where(inside, pause_slip_rad_s, slip_rad_s)
    # a controller's force steps, so the torque level is seen at more than one operating point
    force = np.where((t % 20.0) < 10.0, force_n, 0.7 * force_n)
    force[inside] = force_n
    truth = Run("truth", t, force, true_slip, np.full(t.size, 40.0))
    torque = np.asarray(predict_campaign(REFERENCE, Campaign([truth])).torque_nm, float)
    measured = torque + np.random.default_rng(seed).normal(0.0, noise_nm, t.size)
    measured[inside] = np.nan
    logged = ~inside
    samples = {"applied_force": (t[logged], force[logged]),
               "slip_speed": (t[logged], np.full(int(logged.sum()), slip_rad_s)),
               "measured_torque": (t[logged], measured[logged])}
    run = Run("r", t, np.where(inside, force_n, force), np.full(t.size, slip_rad_s), np.full(t.size, 40.0),
              torque_measured_nm=measured, samples=samples)
    return run, torque


@pytest.mark.parametrize("pause_slip", [0.0, 2.5, 5.0])
def test_the_pause_heat_is_recovered_from_the_rows_after_it_and_they_are_kept(pause_slip):
    """Known truth: the clutch slipped at 0, 2.5 or 5 rad/s (heat scale 0, 0.5, 1 of the edges'
    5 rad/s) through a 3 s pause at 3 kN. The worst case leaves tens of seconds out; the
    estimate recovers the scale with a narrow interval around the truth, the rows left out are
    the film's settling (the force of the pause's last instants unknown), and the run driven
    through the pause at the estimate predicts the rows after it as the truth does."""
    from clutch_model.prediction import predict_campaign

    run, torque_true = _truth_run(pause_slip)
    worst, = pauses_of_run(run, REFERENCE)
    assert worst.left_out_to_s - worst.t1_s > 10.0
    campaign, mask, (pause,) = without_rows_after_pauses(Campaign([run]), REFERENCE)
    lo, hi = pause.heat.heat_scale_ci95
    assert pause.heat.heat_scale == pytest.approx(pause_slip / 5.0, abs=0.02)
    width = hi - lo                     # a 95 % interval: the truth within it, give or take its width
    assert width < 0.05 and lo - width <= pause_slip / 5.0 <= hi + width
    assert pause.left_out_to_s - pause.t1_s < 0.25 * (worst.left_out_to_s - worst.t1_s)
    assert mask.sum() == pause.rows_left_out < worst.rows_left_out
    after = (run.t > pause.t1_s) & (run.t < pause.t1_s + 20.0)
    pred = np.asarray(predict_campaign(REFERENCE, campaign).torque_nm, float)
    assert np.sqrt(np.mean((pred[after] - torque_true[after]) ** 2)) < 0.5
    # without the estimate (inputs interpolated through the pause: the edges' slip) the rows
    # after a pause at standstill are off by the pack's extra heat
    if pause_slip == 0.0:
        held = np.asarray(predict_campaign(REFERENCE, Campaign([run])).torque_nm, float)
        assert np.sqrt(np.mean((held[after] - torque_true[after]) ** 2)) > 2.0


def test_without_the_estimate_the_worst_case_decides():
    run, _ = _truth_run(2.5)
    worst, = pauses_of_run(run, REFERENCE)
    _, mask, (pause,) = without_rows_after_pauses(Campaign([run]), REFERENCE, fit_heat=False)
    assert pause.heat is None and pause.left_out_to_s == worst.left_out_to_s
    assert mask.sum() == worst.rows_left_out


@pytest.mark.parametrize("level", [0.96, 1.04])
def test_a_friction_level_the_model_gets_wrong_is_not_taken_for_heat(level):
    """The clutch 4 % stronger or weaker than the model, AR(1) sensor noise (phi 0.9): the
    level is fitted on the rows away from the pause, and the heat scale's interval still holds
    the truth's 0.5."""
    from dataclasses import replace

    run, torque_true = _truth_run(2.5)
    rng = np.random.default_rng(1)
    noise = np.zeros(run.t.size)
    for k in range(1, noise.size):
        noise[k] = 0.9 * noise[k - 1] + rng.normal(0.0, 1.5)
    measured = np.where(np.isnan(run.torque_measured_nm), np.nan, level * torque_true + noise)
    _, _, (pause,) = without_rows_after_pauses(Campaign([replace(run, torque_measured_nm=measured)]), REFERENCE)
    lo, hi = pause.heat.heat_scale_ci95
    assert pause.heat.level == pytest.approx(level, abs=0.002)
    assert lo <= 0.5 <= hi and hi - lo < 0.3
