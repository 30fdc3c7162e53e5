"""The sump temperature as the diagnosis reads it: smoothed where the clutch heated against a
smooth sump that its sensor logged with noise, as logged (held, as replay reads it) where the
plant was driven by the logged, quantised readings. Cold engagements, where the film squeezes
out over a second and a few tenths of a degree move the transient, decide it."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.signal import lfilter

from clutch_model.diagnosis.sump_reading import choose_sump_reading, logged_sump, smooth_sump
from clutch_model.formats.bag_reader import Campaign, Run
from clutch_model.plant.params import load_model
from clutch_model.prediction import predict_campaign

RATE_HZ = 200.0


def _runs(sump_true, sump_logged_t, sump_logged):
    """Four cold runs of 4 s: an engagement to 9 kN at slow slip, a release, a second one."""
    t = np.arange(0.0, 4.0, 1.0 / RATE_HZ)
    force = np.interp(t, [0.0, 0.3, 0.5, 2.0, 2.2, 2.6, 2.8, 4.0], [200, 200, 9000, 9000, 300, 300, 7000, 7000])
    slip = np.interp(t, [0.0, 0.5, 1.0, 4.0], [3.0, 0.4, 0.2, 0.5])
    runs = []
    for k in range(4):
        true = sump_true[k](t)
        samples = {"applied_force": (t, force), "slip_speed": (t, slip),
                   "sump_temperature": (sump_logged_t[k], sump_logged[k]),
                   "measured_torque": (t, np.zeros(t.size))}
        runs.append(Run(name=f"r{k}", t=t.copy(), start_time_ns=k * 10_000_000_000, applied_force_n=force.copy(), slip_speed_rad_s=slip.copy(),
                        sump_temperature_c=true, torque_measured_nm=np.zeros(t.size), samples=samples))
    return Campaign(runs)


def _with_torque(campaign, torque):
    return Campaign([replace(r, torque_measured_nm=np.asarray(torque)[sl].copy()) for r, sl in campaign.slices()])


def _lagged(torque, campaign, tau_s):
    """A first-order lag of the torque within each run (a lag in the data)."""
    a = np.exp(-1.0 / (RATE_HZ * tau_s))
    out = np.empty_like(torque)
    for _, sl in campaign.slices():
        out[sl] = lfilter([1 - a], [1, -a], torque[sl], zi=[a * torque[sl][0]])[0]
    return out


def _quantised_campaign():
    """A sump warming 13.6 -> 14.9 C over the four runs, logged at 2 Hz in 1 C steps."""
    rng = np.random.default_rng(3)
    true = [(lambda t, k=k: 13.6 + 0.35 * k + 0.02 * t) for k in range(4)]
    ts = [np.arange(0.05, 4.0, 0.5) for _ in range(4)]
    logged = [np.round(true[k](ts[k]) + rng.normal(0, 0.05, ts[k].size)) for k in range(4)]
    return _runs(true, ts, logged)


def test_logged_reading_is_what_replay_reads():
    camp = _quantised_campaign()
    read = logged_sump(camp)
    for run, (ts, vs) in zip(read.runs, (r.samples["sump_temperature"] for r in camp.runs)):
        i = np.clip(np.searchsorted(ts, run.t, side="right") - 1, 0, ts.size - 1)
        np.testing.assert_array_equal(run.sump_temperature_c, vs[i])
        assert run.sump_temperature_c[0] == vs[0]          # the first sample before it


def test_a_plant_driven_by_the_logged_sump_is_read_as_logged_even_with_a_lag():
    model = load_model(None)
    camp = _quantised_campaign()
    rng = np.random.default_rng(0)
    truth = predict_campaign(model, logged_sump(camp), energy0_j=0.0).torque_nm
    smooth = predict_campaign(model, smooth_sump(camp), energy0_j=0.0).torque_nm
    assert np.sqrt(np.mean((truth - smooth) ** 2)) > 1.0          # the readings differ at cold
    measured = _lagged(truth, camp, 0.05) + rng.normal(0, 2.0, truth.size)
    reading = choose_sump_reading(_with_torque(camp, measured), model)
    assert reading.logged, reading.describe()
    assert 0.6 < reading.beta < 1.6


def test_a_plant_on_a_smooth_sump_logged_with_noise_is_read_smoothed():
    model = load_model(None)
    rng = np.random.default_rng(1)
    true = [(lambda t, k=k: 13.8 + 0.3 * k + 0.02 * t) for k in range(4)]
    ts = [np.arange(0.0, 4.0, 0.1) for _ in range(4)]
    logged = [true[k](ts[k]) + rng.normal(0, 0.4, ts[k].size) for k in range(4)]
    camp = _runs(true, ts, logged)
    truth = predict_campaign(model, camp, energy0_j=0.0).torque_nm       # the true sump drives it
    measured = truth + rng.normal(0, 2.0, truth.size)
    reading = choose_sump_reading(_with_torque(camp, measured), model)
    assert reading.difference_rms_nm > 1.0, reading.describe()
    assert not reading.logged, reading.describe()
    assert reading.beta < 0.5


def test_readings_that_agree_keep_the_smoothed_one():
    """A sump logged as it is (steady, no noise, no steps): the two readings predict the same
    torque and the weight would say nothing."""
    model = load_model(None)
    true = [(lambda t, k=k: 80.0 + 5.0 * k + 0.0 * t) for k in range(4)]
    ts = [np.arange(0.05, 4.0, 0.5) for _ in range(4)]
    camp = _runs(true, ts, [true[k](ts[k]) for k in range(4)])
    measured = predict_campaign(model, logged_sump(camp), energy0_j=0.0).torque_nm
    reading = choose_sump_reading(_with_torque(camp, measured), model)
    assert not reading.logged
    assert reading.difference_rms_nm < 0.1 and np.isnan(reading.beta)


def test_a_difference_small_against_the_noise_is_not_weighed():
    """Readings that differ by far less than the torque's noise near Nyquist: the weight would
    follow whatever else the torque carries, and the smoothed reading is kept."""
    model = load_model(None)
    camp = _quantised_campaign()
    truth = predict_campaign(model, logged_sump(camp), energy0_j=0.0).torque_nm
    smooth = predict_campaign(model, smooth_sump(camp), energy0_j=0.0).torque_nm
    diff = float(np.sqrt(np.mean((truth - smooth) ** 2)))
    measured = truth + np.random.default_rng(2).normal(0, 2.0, truth.size)
    reading = choose_sump_reading(_with_torque(camp, measured), model, noise_nm=10.0 * diff)
    assert not reading.logged and np.isnan(reading.beta), reading.describe()
    assert reading.least_nm == pytest.approx(3.0 * diff)
