"""Rows where the slip reading does not resolve the friction's Stribeck transition."""
from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from clutch_model.diagnosis.stick_band import stick_band_rows, without_stick_band
from clutch_model.formats.bag_reader import Campaign, Run
from clutch_model.plant.friction import stribeck
from clutch_model.plant.params import load_model

MODEL = load_model()
N = 2000
FORCE_N = 3000.0
SUMP_C = 60.0
TORQUE_NM = 300.0
TORQUE_NOISE_NM = 0.5


def _logged(true_slip, quantum, noise_sd, seed=0):
    rng = np.random.default_rng(seed)
    x = true_slip + rng.normal(0.0, noise_sd, N)
    return np.round(x / quantum) * quantum


def _friction(slip):
    """The reference clutch's friction coefficient at ``slip`` (the full law, k_V included), at
    the tests' force and sump temperature."""
    p = np.full(np.size(slip), FORCE_N / MODEL.nominal_area_m2 / 1e6)
    th = np.full(np.size(slip), SUMP_C)
    mu = stribeck(MODEL.friction_coefficients, MODEL.friction_exponent, np.abs(slip), p, th)
    return mu


def _flags(logged, resolution):
    return stick_band_rows(logged, np.full(N, FORCE_N), np.full(N, SUMP_C), np.full(N, TORQUE_NM), MODEL,
                           resolution, TORQUE_NOISE_NM)


def test_quantised_slip_near_stick_is_left_out_and_the_model_jumps_there():
    quantum, noise = 0.028, 0.008
    resolution = np.hypot(noise, quantum / np.sqrt(12.0))
    logged = _logged(0.04, quantum, noise)
    flagged = _flags(logged, resolution)
    assert flagged.mean() > 0.5
    # independent: the model given the logged slip moves by far more than the torque's noise
    # from row to row (relative to its value at the true slip, times the torque)
    mu_true = _friction(np.array([0.04]))[0]
    torque = TORQUE_NM * _friction(logged) / mu_true
    assert np.std(np.diff(torque)) / np.sqrt(2.0) > 5 * TORQUE_NOISE_NM


def test_the_same_sensor_well_above_the_transition_leaves_nothing_out():
    quantum, noise = 0.028, 0.008
    resolution = np.hypot(noise, quantum / np.sqrt(12.0))
    logged = _logged(2.0, quantum, noise)
    assert not _flags(logged, resolution).any()
    mu_true = _friction(np.array([2.0]))[0]
    torque = TORQUE_NM * _friction(logged) / mu_true
    assert np.std(np.diff(torque)) / np.sqrt(2.0) < TORQUE_NOISE_NM


def test_the_viscous_slope_alone_leaves_nothing_out():
    # a noisy slip at 6 rad/s moves the model through k_V by more than 3 torque noise sds, but
    # the band is the Stribeck transition's (module docstring)
    noise = 0.06
    logged = _logged(6.0, 1e-6, noise)
    mu_true = _friction(np.array([6.0]))[0]
    torque = 2000.0 * _friction(logged) / mu_true
    quiet = 0.05
    assert np.std(torque) > 3 * quiet
    flagged = stick_band_rows(logged, np.full(N, FORCE_N), np.full(N, SUMP_C), np.full(N, 2000.0), MODEL,
                              noise, quiet)
    assert not flagged.any()


def test_without_stick_band_blanks_the_rows_and_keeps_locked_ones_blank():
    t = np.arange(N) * 0.005
    slip = np.where(t < 5.0, 2.0, 0.04)
    torque = np.full(N, TORQUE_NM)
    torque[:100] = np.nan                      # locked rows, already blank
    run = Run(name="r", t=t, applied_force_n=np.full(N, FORCE_N), slip_speed_rad_s=slip,
              sump_temperature_c=np.full(N, SUMP_C), torque_measured_nm=torque)
    lock = SimpleNamespace(noise_sigma_rad_s=0.01)
    out, band = without_stick_band(Campaign([run]), MODEL, [lock], TORQUE_NOISE_NM)
    y = out.runs[0].torque_measured_nm
    assert np.isnan(y[:100]).all()
    assert np.isfinite(y[100:1000]).all()            # slipping at 2 rad/s: kept
    assert np.isnan(y[1000:]).all()                   # at 0.04 rad/s: left out
    assert band.rows == N - 1000
    assert 0.039 < band.max_slip_rad_s < 0.041
    # a run whose slip noise is unknown is left as it is
    out2, band2 = without_stick_band(Campaign([replace(run)]), MODEL, [SimpleNamespace(noise_sigma_rad_s=np.nan)],
                                     TORQUE_NOISE_NM)
    assert band2.rows == 0 and np.array_equal(np.isnan(out2.runs[0].torque_measured_nm), np.isnan(torque))
