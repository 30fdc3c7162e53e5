"""Readings pinned at the torque sensor's range are found from the readings and left out; a
continuous or quantised reading, and a message logged twice, have no rail."""
from __future__ import annotations

import numpy as np

from clutch_model.diagnosis.torque_range import RAIL_MIN_SAMPLES, find_torque_rails, without_torque_at_rails
from clutch_model.formats.bag_reader import Campaign, Run


def _run(name, torque_t, torque, t0=0.0):
    tf = np.arange(t0, torque_t[-1], 0.005)                             # force rows at 200 Hz
    force = np.full(tf.size, 3000.0)
    samples = {"applied_force": (tf, force), "slip_speed": (tf, np.ones(tf.size)),
               "sump_temperature": (tf, np.full(tf.size, 60.0)), "measured_torque": (torque_t, torque)}
    held = torque[np.maximum(np.searchsorted(torque_t, tf, side="right") - 1, 0)]
    return Run(name=name, t=tf, applied_force_n=force, slip_speed_rad_s=np.ones(tf.size),
               sump_temperature_c=np.full(tf.size, 60.0), torque_measured_nm=held, samples=samples)


def _reading(seed, duration_s=20.0, rate_hz=1000.0):
    """A moving torque (N*m) with coloured noise at its own stamps."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0013, duration_s, 1.0 / rate_hz)
    e = rng.normal(0.0, 2.0, t.size)
    noise = np.empty(t.size)
    noise[0] = e[0]
    for k in range(1, t.size):
        noise[k] = 0.9 * noise[k - 1] + e[k]
    return t, 1000.0 * np.sin(2 * np.pi * 0.3 * t) + 150.0 * np.sin(2 * np.pi * 2.1 * t) + noise


def test_a_clipped_reading_has_its_rails_found_and_left_out():
    runs, clipped = [], 0
    for k in range(3):
        t, y = _reading(k)
        y = np.clip(y, -900.0, 850.0)                 # an asymmetric range
        clipped += int(np.sum((y == -900.0) | (y == 850.0)))
        runs.append(_run(f"r{k}", t, y))
    camp = Campaign(runs)
    rails = find_torque_rails(camp)
    assert rails.rails_nm == (-900.0, 850.0)
    assert rails.at_rails == clipped and rails.readings == sum(r.samples["measured_torque"][0].size for r in runs)
    out = without_torque_at_rails(camp, rails)
    for before, after in zip(camp.runs, out.runs):
        t_b, v_b = before.samples["measured_torque"]
        t_a, v_a = after.samples["measured_torque"]
        assert np.all(v_a > -900.0) and np.all(v_a < 850.0)
        assert t_a.size == t_b.size - np.sum((v_b == -900.0) | (v_b == 850.0))
        # a row is left without torque exactly where the reading it holds is on a rail
        held = v_b[np.searchsorted(t_b, before.t, side="right") - 1]
        on_rail = (held == -900.0) | (held == 850.0)
        assert on_rail.any()
        np.testing.assert_array_equal(~np.isfinite(after.torque_measured_nm), on_rail)
        np.testing.assert_array_equal(after.torque_measured_nm[~on_rail], before.torque_measured_nm[~on_rail])


def test_continuous_quantised_and_doubled_readings_have_no_rail():
    t, y = _reading(7)
    assert not find_torque_rails(Campaign([_run("c", t, y)])).found
    q = np.round(y / 0.5) * 0.5                      # quantised: most values shared, the extremes are not
    assert not find_torque_rails(Campaign([_run("q", t, q)])).found
    t2, y2 = np.repeat(t, 2), np.repeat(y, 2)        # every message logged twice
    assert not find_torque_rails(Campaign([_run("d", t2, y2)])).found


def test_a_short_flat_top_is_not_a_rail():
    t, y = _reading(3)
    top = float(y.max())
    k = int(np.argmax(y))
    y[k:k + RAIL_MIN_SAMPLES - 2] = top               # a few equal readings at the peak
    rails = find_torque_rails(Campaign([_run("s", t, y)]))
    assert not rails.found
    y[k:k + RAIL_MIN_SAMPLES + 40] = top             # held at the extreme: a rail
    assert find_torque_rails(Campaign([_run("s", t, y)])).rails_nm == (top,)
