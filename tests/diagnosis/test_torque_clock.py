"""The torque's sample instants: its logged stamps, or its sensor's regular clock
(clutch_model/diagnosis/torque_clock.py). Independent truth: the ticks the stamps were made from,
and a plant simulated on a 0.1 ms grid read at the instants the values were taken."""
import numpy as np

from clutch_model.diagnosis.input_hold import with_midpoint_force
from clutch_model.diagnosis.measured_time import measured_time_campaign
from clutch_model.diagnosis.torque_clock import (choose_torque_stamps, clock_ticks, regular_clock,
                                                 with_torque_stamps)
from clutch_model.formats.bag_reader import read_bag
from clutch_model.formats.bag_writer import write_run_bag

from .chirp_run import chirp_truth, force_n, rms_off, slip_rad_s

PERIOD_S = 1.0 / 125.0


def _ticks(n, rng, drop_frac=0.02):
    """A 125 Hz clock running 20 ppm fast with a slow 1 ms wander against the log's, 2 % of its
    frames and one 1.6 s stretch lost."""
    k = np.arange(n)
    ticks = 3.3e-3 + PERIOD_S * (1 + 20e-6) * k + 1e-3 * np.sin(2 * np.pi * k * PERIOD_S / 900.0)
    keep = rng.random(n) > drop_frac
    keep[5000:5200] = False
    return ticks[keep]


def test_the_clock_is_found_under_stamps_scattered_by_a_third_of_its_period():
    rng = np.random.default_rng(1)
    ticks = _ticks(200_000, rng)                      # 27 min at 125 Hz
    stamps = ticks + rng.uniform(-0.35, 0.35, ticks.size) * PERIOD_S
    found = regular_clock(stamps)
    assert found is not None
    stamp_err = np.sqrt(np.mean((stamps - ticks) ** 2))
    tick_err = np.sqrt(np.mean((found - ticks) ** 2))
    assert stamp_err > 1.5e-3 and tick_err < 0.05e-3, (stamp_err, tick_err)


def test_no_clock_behind_stamps_that_keep_no_phase():
    rng = np.random.default_rng(2)
    assert regular_clock(np.cumsum(rng.exponential(PERIOD_S, 5000))) is None      # Poisson arrivals
    assert regular_clock(np.arange(20) * PERIOD_S + 0.001 * rng.random(20)) is None  # too few to tell
    # stamps exactly on a clock: found, and equal to the stamps
    stamps = 0.004 + PERIOD_S * np.arange(3000)
    np.testing.assert_allclose(regular_clock(stamps), stamps, rtol=0, atol=1e-9)


def _bag(tmp_path, on_arrival: bool, seed=3):
    """A 6 s run: force and slip at 1 kHz (a force chirp), the torque at 125 Hz with 2 N*m of
    noise, its stamps scattered +-2.8 ms. ``on_arrival``: the values taken at the clock's ticks
    (a gateway stamping frames as they arrive); else at the stamps (irregular sampling)."""
    model, fine, truth = chirp_truth()
    rng = np.random.default_rng(seed)
    ticks = 0.0031 + PERIOD_S * np.arange(int(5.9 / PERIOD_S))
    stamps = ticks + rng.uniform(-0.35, 0.35, ticks.size) * PERIOD_S
    taken = ticks if on_arrival else stamps
    values = np.interp(taken, fine, truth) + rng.normal(0.0, 2.0, ticks.size)
    tf, ts = np.arange(0.0, 6.0, 0.001), np.arange(0.0, 6.0, 0.1)
    write_run_bag(tmp_path / "b", {"applied_force": (tf, force_n(tf)), "slip_speed": (tf, slip_rad_s(tf)),
                                   "sump_temperature": (ts, np.full(ts.size, 60.0)),
                                   "measured_torque": (stamps, values)})
    return model, read_bag(tmp_path / "b"), ticks, fine, truth


def test_values_taken_on_the_clock_are_compared_at_its_ticks(tmp_path):
    model, run, ticks, fine, truth = _bag(tmp_path, on_arrival=True)
    found = clock_ticks(_campaign([run]))
    assert set(found) == {run.name}
    np.testing.assert_allclose(found[run.name], ticks, rtol=0, atol=0.4e-3)   # 0.1 ms rms
    camp = with_midpoint_force(measured_time_campaign([run], rate_hz=1.0))
    choice = choose_torque_stamps(camp, model, found, noise_nm=2.0)
    assert choice.on_clock and 0.8 < choice.beta < 1.2, choice
    assert 1.4e-3 < choice.jitter_rms_s < 1.9e-3, choice
    # compared at the ticks, the model meets the values to about their noise (2 N*m; the rest is
    # the plant stepping from row to row at 125 Hz); at the stamps it is off by the torque's rate
    # times the scatter (14.6 N*m)
    at_ticks = with_midpoint_force(measured_time_campaign(with_torque_stamps(_campaign([run]), found), rate_hz=1.0))
    assert rms_off(model, at_ticks) < 4.0 and rms_off(model, camp) > 10.0


def test_values_taken_at_their_stamps_stay_there(tmp_path):
    model, run, _, _, _ = _bag(tmp_path, on_arrival=False)
    found = clock_ticks(_campaign([run]))
    assert set(found) == {run.name}                    # the stamps keep a clock all the same
    camp = with_midpoint_force(measured_time_campaign([run], rate_hz=1.0))
    choice = choose_torque_stamps(camp, model, found, noise_nm=2.0)
    assert not choice.on_clock and abs(choice.beta) < 0.2, choice
    assert rms_off(model, camp) < 4.0


def _campaign(runs):
    from clutch_model.formats.bag_reader import Campaign
    return Campaign(list(runs))


