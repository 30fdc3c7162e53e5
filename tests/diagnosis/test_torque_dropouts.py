"""A dropout of the torque topic (a gap of its stamps) in a log whose topics run on their own
clocks: the plant must still follow what the force and the slip did inside the gap. The model is
compared at the torque's own stamps, and the rows the plant steps over are those stamps; across
a 400 ms gap that held the force of the gap's first row (a lock's 8 kN) through a release."""
from __future__ import annotations

import numpy as np

from clutch_model.diagnosis.measured_time import GAP_PERIODS, measured_time_campaign
from clutch_model.formats.bag_reader import Campaign, Run
from clutch_model.plant.params import load_model
from clutch_model.prediction import predict_campaign


def _run(torque_t):
    tf = np.arange(0.0, 3.0, 0.005)                                     # force at 200 Hz
    force = np.interp(tf, [0.0, 1.0, 1.1, 3.0], [8000.0, 8000.0, 300.0, 300.0])
    ts = np.arange(0.0013, 3.0, 0.01)                                   # slip at 100 Hz, its own clock
    slip = np.interp(ts, [0.0, 1.0, 1.3, 3.0], [0.5, 0.5, 6.0, 6.0])
    tsump = np.arange(0.0, 3.0, 0.1)
    sump = np.full(tsump.size, 60.0)
    torque = np.zeros(torque_t.size)                                    # values do not matter here
    samples = {"applied_force": (tf, force), "slip_speed": (ts, slip), "sump_temperature": (tsump, sump),
               "measured_torque": (torque_t, torque)}
    return Run(name="r", t=tf, applied_force_n=force, slip_speed_rad_s=np.interp(tf, ts, slip),
               sump_temperature_c=np.full(tf.size, 60.0), torque_measured_nm=np.interp(tf, torque_t, torque),
               samples=samples)


def test_a_torque_dropout_leaves_the_plant_following_the_inputs():
    stamps = np.arange(0.0027, 3.0, 0.004)                              # torque at 250 Hz
    gap = (stamps > 0.95) & (stamps < 1.35)
    full = measured_time_campaign(Campaign([_run(stamps)]), rate_hz=1.0)
    dropped = measured_time_campaign(Campaign([_run(stamps[~gap])]), rate_hz=1.0)
    # rows inside the gap, at the torque's period, with no torque on them
    g = dropped.t
    inside = (g > 0.95) & (g < 1.35)
    assert inside.sum() >= 0.4 / 0.004 - 3
    assert np.max(np.diff(g)) <= GAP_PERIODS * 0.004
    assert not np.isfinite(dropped.torque_measured[inside]).any()
    # the model's torque at the stamps after the gap is what it is without the dropout
    model = load_model(None)
    p_full = predict_campaign(model, full).torque_nm
    p_drop = predict_campaign(model, dropped).torque_nm
    after = stamps[~gap][stamps[~gap] > 1.35]
    a = p_full[np.searchsorted(full.t, after)]
    b = p_drop[np.searchsorted(dropped.t, after)]
    np.testing.assert_allclose(b, a, rtol=0.02, atol=2.0)
    # and the torque moved a lot across the gap (the release is in it)
    assert a[0] < 0.5 * p_full[np.searchsorted(full.t, stamps[gap][0])]


def test_no_gap_no_extra_rows():
    stamps = np.arange(0.0027, 3.0, 0.004)
    jittered = stamps + np.random.default_rng(0).uniform(-0.001, 0.001, stamps.size)
    camp = measured_time_campaign(Campaign([_run(np.sort(jittered))]), rate_hz=1.0)
    assert np.isfinite(camp.torque_measured).sum() == stamps.size
    assert camp.t.size <= stamps.size + 4                             # the 1 Hz fill only


def test_a_torque_on_the_force_clock_is_aligned_only_when_it_has_every_stamp():
    """On one clock the replay grid compares each force row with the torque sample at it; a
    slower torque on that clock, or a dropout, would leave rows holding a stale sample."""
    from clutch_model.diagnosis.measured_time import topics_unaligned
    tf = np.arange(0.0, 3.0, 0.005)

    def with_torque(tq):
        return [_run_on_force_clock(tf, tq)]
    assert not topics_unaligned(with_torque(tf))
    assert not topics_unaligned(with_torque(tf[10:-10]))          # starts late, ends early: no row held
    assert topics_unaligned(with_torque(tf[::5]))                 # 40 Hz on the 200 Hz clock
    dropout = (tf > 1.0) & (tf < 1.2)
    assert topics_unaligned(with_torque(tf[~dropout]))
    assert topics_unaligned(with_torque(tf + 0.0007))              # its own clock


def _run_on_force_clock(tf, tq):
    zeros = np.zeros(tf.size)
    samples = {"applied_force": (tf, zeros + 5000.0), "slip_speed": (tf, zeros + 3.0),
               "sump_temperature": (tf, zeros + 60.0), "measured_torque": (tq, np.zeros(tq.size))}
    return Run(name="r", t=tf, applied_force_n=zeros + 5000.0, slip_speed_rad_s=zeros + 3.0,
               sump_temperature_c=zeros + 60.0, torque_measured_nm=zeros, samples=samples)
