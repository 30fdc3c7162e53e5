"""Topics a gateway forwarded in bursts (clutch_model/diagnosis/receive_bursts.py). Independent
truth: the instants the samples were taken, and a plant simulated on a 0.1 ms grid read there."""
import numpy as np

from clutch_model.diagnosis.input_hold import with_midpoint_force
from clutch_model.diagnosis.measured_time import measured_time_campaign
from clutch_model.diagnosis.receive_bursts import find_receive_bursts, retimed, topic_bursts
from clutch_model.formats.bag_reader import Campaign, read_bag
from clutch_model.formats.bag_writer import write_run_bag

from .chirp_run import chirp_truth, force_n, rms_off, slip_rad_s

PERIOD_S = 1.0 / 200.0


def _bursts(rng, duration_s, lo=0.010, hi=0.020):
    """A gateway's flush instants, 10-20 ms apart."""
    return np.cumsum(rng.uniform(lo, hi, int(duration_s / lo) + 2))


def _received(taken, flushes, spacing_s=0.0):
    """Log times of samples ``taken`` forwarded at the first flush after them (+0.4 ms on the
    way), the frames of one flush ``spacing_s`` apart."""
    j = np.searchsorted(flushes, taken + 0.4e-3)
    logged = flushes[j]
    first = np.r_[True, logged[1:] != logged[:-1]]
    pos = np.arange(logged.size) - np.maximum.accumulate(np.where(first, np.arange(logged.size), 0))
    return logged + pos * spacing_s


def test_burst_received_samples_get_their_period_and_instants_back():
    rng = np.random.default_rng(1)
    taken = np.arange(0.0, 44.0, PERIOD_S) + rng.uniform(-0.2e-3, 0.2e-3, 8800)
    for spacing in (0.0, 3e-6):                  # one log time per burst, or frames microseconds apart
        logged = _received(taken, _bursts(rng, 45.0), spacing)
        found = topic_bursts(logged)
        assert found is not None and found.share_in_bursts > 0.5, found
        assert abs(found.period_s - PERIOD_S) < 0.01 * PERIOD_S, found
        assert 0.013 < found.burst_interval_s < 0.017, found
        late = logged - taken                        # as logged: 8 ms late on average, up to 20 ms
        off = retimed(logged, found.period_s) - taken
        assert np.mean(late) > 6e-3 and np.max(late) > 15e-3
        # the grid's phase found: late by the 0.4 ms on the way, and within a fraction of a period
        assert abs(np.mean(off)) < 1e-3 and np.std(off) < 0.8e-3, (off.mean(), off.std())
        assert np.all(np.diff(retimed(logged, found.period_s)) > 0)


def test_clocks_event_logging_and_duplicates_are_not_bursts():
    rng = np.random.default_rng(2)
    jittered = np.sort(np.arange(0.0, 20.0, 1e-3) + rng.uniform(-0.5e-3, 0.5e-3, 20000))   # 1 kHz, +-0.5 ms
    # logged on change: every 5 ms sample during ramps, a 0.5 s heartbeat during holds
    ramps = np.concatenate([np.arange(a, a + 0.4, PERIOD_S) for a in np.arange(0.0, 60.0, 2.0)])
    holds = np.concatenate([np.arange(a + 0.5, a + 2.0, 0.5) for a in np.arange(0.0, 60.0, 2.0)])
    event = np.sort(np.r_[ramps, holds])
    clock = np.arange(0.0, 30.0, PERIOD_S)
    dup = np.sort(np.r_[clock, clock[rng.random(clock.size) < 0.05]])                      # 5 % sent twice
    for t in (jittered, event, dup):
        found = topic_bursts(t)
        assert found is not None and found.share_in_bursts < 0.1 and not np.isfinite(found.period_s), found
    assert topic_bursts(np.zeros(10)) is None                                             # too few to tell


def _bag(tmp_path, seed=3):
    """A 6 s run: force and torque sampled at 200 Hz on their own clocks (a force chirp, 2 N*m
    of torque noise), both forwarded in bursts every 10-20 ms; slip at 1 kHz, sump at 10 Hz."""
    model, fine, truth = chirp_truth()
    rng = np.random.default_rng(seed)
    flushes = _bursts(rng, 6.5)
    tf = 0.0013 + PERIOD_S * np.arange(int(5.9 / PERIOD_S))
    tq = 0.0037 + PERIOD_S * np.arange(int(5.9 / PERIOD_S))
    torque = np.interp(tq, fine, truth) + rng.normal(0.0, 2.0, tq.size)
    tl, ts = np.arange(0.0, 6.0, 0.001), np.arange(0.0, 6.0, 0.1)
    write_run_bag(tmp_path / "b", {"applied_force": (_received(tf, flushes), force_n(tf)),
                                   "slip_speed": (tl, slip_rad_s(tl)), "sump_temperature": (ts, np.full(ts.size, 60.0)),
                                   "measured_torque": (_received(tq, flushes), torque)})
    return model, read_bag(tmp_path / "b")


def test_a_bag_received_in_bursts_is_compared_at_the_instants_sampled(tmp_path):
    model, run = _bag(tmp_path)
    # the bag keeps the bursts: several frames share one log time
    assert np.mean(np.diff(run.samples["measured_torque"][0]) == 0) > 0.4
    found = find_receive_bursts(Campaign([run]))
    assert set(found.topics) == {run.name}
    assert set(found.topics[run.name]) == {"applied_force", "measured_torque"}, found.topics
    for b in found.topics[run.name].values():
        assert abs(b.period_s - PERIOD_S) < 0.03 * PERIOD_S, b
    assert "received in bursts" in found.describe()
    retimed_camp = found.apply(Campaign([run]))
    r = retimed_camp.runs[0]
    assert np.all(np.diff(r.samples["applied_force"][0]) > 0) and np.all(np.diff(r.t) > 0)
    assert r.t.size == run.t.size and np.all(r.samples["slip_speed"][0] == run.samples["slip_speed"][0])
    # the true model meets the torque to about its noise (2 N*m; 3.1 measured, the rest the 0.4 ms
    # on the way) at the instants re-timed; as logged, the force staircase and the late torque put
    # it off by the torque's rate times the wait (52 N*m)
    at_instants = rms_off(model, with_midpoint_force(measured_time_campaign(retimed_camp, rate_hz=1000.0)))
    as_logged = rms_off(model, with_midpoint_force(measured_time_campaign(Campaign([run]), rate_hz=1000.0)))
    assert at_instants < 4.0 and as_logged > 5.0 * at_instants, (at_instants, as_logged)
