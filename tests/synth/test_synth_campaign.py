"""The virtual test car: determinism, noise levels, truth, and the direction of each hidden
mechanism's effect against its no-mechanism twin (same seed = same schedule and noise)."""
import json

import numpy as np
import pytest

from clutch_model.plant import kernels as K
from clutch_model.plant.friction import friction_grid
from clutch_model.plant.params import load_model
from clutch_model.virtual_car.campaign import (CATALOG, DEFAULT_MAGNITUDE, MECHANISM_PARAMETER, CampaignSpec,
                                _trajectory_pt_cross, friction_is_positive, synthesize_campaign,
                                write_campaign)
from clutch_model.errors import DataError, ParamsError

SEED = 7
N_RUNS = 4


def _spec(**kw):
    return CampaignSpec(seed=SEED, n_runs=N_RUNS, **kw)


@pytest.fixture(scope="module")
def twin():
    return synthesize_campaign(_spec())


def _cat(result, attr):
    return np.concatenate([getattr(r, attr) for r in result.runs])


def _meas(result):
    return np.concatenate([r.measured_torque_nm for r in result.runs])


def test_deterministic(twin):
    again = synthesize_campaign(_spec())
    for a, b in zip(twin.runs, again.runs):
        assert a.start_time_ns == b.start_time_ns
        for key, ser in a.signals.channels().items():
            other = b.signals.channels()[key]
            np.testing.assert_array_equal(ser.t_s, other.t_s)
            np.testing.assert_array_equal(ser.values, other.values)
    np.testing.assert_array_equal(twin.bench.friction_coefficient, again.bench.friction_coefficient)
    np.testing.assert_array_equal(twin.true_model.friction_coefficients,
                                  again.true_model.friction_coefficients)
    other = synthesize_campaign(CampaignSpec(seed=SEED + 1, n_runs=N_RUNS))
    assert not np.array_equal(_meas(twin), _meas(other))


def test_schedule_shape(twin):
    spec = twin.spec
    assert [r.name for r in twin.runs] == [f"run_{i:02d}" for i in range(N_RUNS)]
    starts = np.array([r.start_time_ns for r in twin.runs])
    gaps = np.diff(starts) * 1e-9 - spec.run_duration_s
    assert np.all(gaps >= spec.gap_s) and np.all(gaps <= spec.gap_s + spec.gap_jitter_s)
    for r in twin.runs:
        assert r.signals.applied_force.t_s.size == 1800
        assert r.signals.sump_temperature.t_s.size == 90
        assert r.signals.pack_temperature is None
        assert len(r.schedule["requests_n"]) == 4
        assert any(r.schedule["release_after_request"])
        f = r.applied_force_n
        assert f.max() <= 12000 + 1e-9 and f.min() >= 150 - 1e-9
        # ends released, so hysteresis/offset show at low force
        assert f[-1] <= 500
        assert 30 <= r.sump_temperature_c.min() and r.sump_temperature_c.max() <= 91
        assert 1 * 0.55 <= np.abs(r.slip_speed_rad_s).min() and np.abs(r.slip_speed_rad_s).max() <= 15 * 1.45
        assert r.pack_temperature_c.max() < 200
    assert twin.expected_cause == "none"


def test_noise_levels(twin):
    spec = twin.spec
    res_t = _meas(twin) - _cat(twin, "sensor_torque_nm")
    assert abs(res_t.std() / spec.torque_noise_nm - 1) < 0.05
    assert abs(res_t.mean()) < 0.5
    res_f = np.concatenate([r.signals.applied_force.values - r.applied_force_n for r in twin.runs])
    assert abs(res_f.std() / spec.force_noise_n - 1) < 0.05
    res_w = np.concatenate([r.signals.slip_speed.values - r.slip_speed_rad_s for r in twin.runs])
    assert abs(res_w.std() / spec.slip_noise_rad_s - 1) < 0.05
    res_s = np.concatenate([r.signals.sump_temperature.values
                            - np.interp(r.signals.sump_temperature.t_s, r.t_s, r.sump_temperature_c)
                            for r in twin.runs])
    assert abs(res_s.std() / spec.temperature_noise_c - 1) < 0.2
    assert twin.runs[0].signals.sump_temperature.variance == pytest.approx(spec.temperature_noise_c ** 2)


def test_relative_torque_noise_and_drift():
    r = synthesize_campaign(_spec(torque_noise_nm=0.0, torque_noise_rel=0.01))
    for run in r.runs:
        peak = np.abs(run.plant_torque_nm).max()
        res = run.measured_torque_nm - run.sensor_torque_nm
        assert abs(res.std() / (0.01 * peak) - 1) < 0.1
    d = synthesize_campaign(_spec(torque_noise_nm=0.0, torque_drift_nm=5.0, torque_drift_tau_s=2.0))
    res = d.runs[0].measured_torque_nm - d.runs[0].sensor_torque_nm
    assert 1.0 < res.std() < 15.0
    assert np.abs(np.diff(res)).max() < 2.0        # slow, not white


def test_true_friction_perturbation(twin):
    nominal = load_model().friction_coefficients
    true = twin.true_model.friction_coefficients
    rel = true / nominal - 1
    assert np.all(np.abs(rel) <= 0.05 + 1e-12) and np.any(np.abs(rel) > 0.01)
    assert friction_is_positive(twin.true_model)
    assert twin.true_model.friction_exponent == load_model().friction_exponent
    assert twin.true_model.mechanisms == []


def test_bench_table(twin):
    b = twin.bench
    assert len(b) == 135
    assert b.slip_speed_rad_s.min() <= 0.01
    assert set(np.round(b.sump_temperature_c, 6)) == {30.0, 75.0, 120.0}
    assert np.all(b.plate_temperature_c > b.sump_temperature_c)
    tm = twin.true_model
    mu_true = friction_grid(tm.friction_coefficients, tm.friction_exponent, b.slip_speed_rad_s,
                            b.pressure_mpa, b.plate_temperature_c)
    res = b.friction_coefficient - mu_true
    assert 0.002 < res.std() < 0.0045 and abs(res.mean()) < 0.001


def test_no_mechanism_on_bench():
    a = synthesize_campaign(_spec(mechanism="friction_degradation", magnitude=1e5))
    b = synthesize_campaign(_spec())
    np.testing.assert_array_equal(a.bench.friction_coefficient, b.bench.friction_coefficient)


# ------------------------------------------------------------- hidden mechanisms vs twin
def _mech(mid, mag=None, **kw):
    return synthesize_campaign(_spec(mechanism=mid, magnitude=mag, **kw))


def test_torque_offset_shifts_mean_residual(twin):
    m = _mech("torque_offset", 25.0)
    assert m.true_model.mechanism("torque_offset").values["offset_nm"] == 25.0
    # the same noise draws: the residual vs the twin's measurement is the offset
    d = _meas(m) - _meas(twin)
    assert d.mean() == pytest.approx(25.0, abs=1e-6)
    np.testing.assert_array_equal(_cat(m, "plant_torque_nm"), _cat(twin, "plant_torque_nm"))
    assert m.expected_cause == "torque_offset"


def _best_lag(x, y, max_lag):
    scores = [np.corrcoef(x[: x.size - k], y[k:])[0, 1] for k in range(max_lag)]
    return int(np.argmax(scores))


def test_transport_delay_shifts_cross_correlation(twin):
    m = _mech("transport_delay", 0.08)
    lags = [_best_lag(a.sensor_torque_nm, b.measured_torque_nm, 60) for a, b in zip(twin.runs, m.runs)]
    assert all(abs(lag - 16) <= 1 for lag in lags), lags
    # and against the force: the torque peak lag grows by the delay
    base = [_best_lag(np.diff(r.signals.applied_force.values), np.diff(r.measured_torque_nm), 80)
            for r in twin.runs]
    late = [_best_lag(np.diff(r.signals.applied_force.values), np.diff(r.measured_torque_nm), 80)
            for r in m.runs]
    assert np.median(np.subtract(late, base)) == pytest.approx(16, abs=3)


def _hold_mask(run, lo, hi, settle_s=0.6):
    """Samples in force holds with the true force in [lo, hi], settle_s after the step."""
    f = run.applied_force_n
    steady = np.ones(f.size, bool)
    moving = np.flatnonzero(np.abs(np.diff(f)) > 1e-6)
    n_settle = int(settle_s * 200)
    for k in moving:
        steady[k: k + n_settle] = False
    return steady & (f >= lo) & (f <= hi)


def test_spring_preload_hurts_low_force_most(twin):
    m = _mech("spring_preload", 800.0)
    lo, hi = [], []
    for a, b in zip(twin.runs, m.runs):
        for lst, (f0, f1) in ((lo, (1000, 3500)), (hi, (7000, 12000))):
            k = _hold_mask(a, f0, f1)
            if k.any():
                lst.append(np.mean(b.plant_torque_nm[k]) / np.mean(a.plant_torque_nm[k]))
    assert lo and hi
    assert np.mean(lo) < np.mean(hi) < 1.0
    assert np.mean(_meas(m) - _meas(twin)) < -20


def test_actuator_lag_slows_steps(twin):
    m = _mech("actuator_lag", 0.15)
    a, b = twin.runs[0], m.runs[0]
    f = a.applied_force_n
    up = np.flatnonzero((np.diff(f) > 0) & (np.diff(np.r_[0.0, np.diff(f)]) > 0)) + 1
    # 50 ms after a step-up begins the lagged torque is lower
    k = np.array([i + 10 for i in up if i + 10 < f.size])
    assert np.mean(b.plant_torque_nm[k] - a.plant_torque_nm[k]) < -20
    # settled holds agree within a few %
    s = _hold_mask(a, 1000, 12000, settle_s=1.2)
    assert np.median(np.abs(b.plant_torque_nm[s] / a.plant_torque_nm[s] - 1)) < 0.03


def test_actuator_hysteresis_direction(twin):
    m = _mech("actuator_hysteresis", 0.12)
    after_up, after_down = [], []
    for a, b in zip(twin.runs, m.runs):
        bp = a.schedule["breakpoints_s"]
        levels = a.schedule["breakpoints_n"]
        for j in range(1, len(bp) - 1):
            if abs(levels[j] - levels[j + 1]) < 1e-6 and bp[j + 1] - bp[j] > 0.8:   # a hold
                prev = levels[j - 1]
                k = (a.t_s > bp[j] + 0.6) & (a.t_s < bp[j + 1])
                diff = np.mean(b.plant_torque_nm[k] - a.plant_torque_nm[k])
                (after_up if levels[j] > prev + 1 else after_down if levels[j] < prev - 1 else []).append(diff)
    assert after_up and after_down
    assert np.mean(after_up) < -10 and np.mean(after_down) > 5


def test_friction_degradation_grows_over_campaign(twin):
    m = synthesize_campaign(CampaignSpec(seed=SEED, n_runs=N_RUNS, mechanism="friction_degradation"))
    assert m.metadata["friction_factor_at_end"] == pytest.approx(0.88, abs=0.01)
    ratios = [np.mean(b.plant_torque_nm[_hold_mask(a, 1000, 12000)])
              / np.mean(a.plant_torque_nm[_hold_mask(a, 1000, 12000)]) for a, b in zip(twin.runs, m.runs)]
    assert ratios[0] > ratios[-1]
    assert ratios[-1] < 0.95


def test_drag_torque_adds_with_slip(twin):
    m = _mech("drag_torque", 6.0)
    d = _cat(m, "plant_torque_nm") - _cat(twin, "plant_torque_nm")
    assert np.mean(d) > 10


@pytest.mark.parametrize("mid", sorted(MECHANISM_PARAMETER))
def test_every_mechanism_has_a_default_and_changes_torque(twin, mid):
    assert set(MECHANISM_PARAMETER) == set(CATALOG)
    m = synthesize_campaign(_spec(mechanism=mid))
    mech = m.true_model.mechanism(mid)
    assert mech is not None
    if DEFAULT_MAGNITUDE[mid] is not None:
        assert mech.values[MECHANISM_PARAMETER[mid]] == DEFAULT_MAGNITUDE[mid]
    rms = np.sqrt(np.mean((_cat(m, "sensor_torque_nm") - _cat(twin, "sensor_torque_nm")) ** 2))
    assert rms > 1.5 * m.spec.torque_noise_nm, (mid, rms)


# ------------------------------------------------------------------------ extra effects
def test_pt_cross_kernel_matches_baseline_at_zero(twin):
    t = np.arange(900) / 200.0
    f = np.where(t > 1, 6000.0, 300.0)
    rs = np.zeros(t.size, bool)
    rs[0] = True
    p = twin.true_model.vector()
    ref = K.run_trajectory(p, t, f, np.full(t.size, 5.0), np.full(t.size, 60.0), rs, 0.0)
    p2 = p.copy()
    p2[K.P.ENERGY_SCALE_J] = 1.0
    out = _trajectory_pt_cross(p2, t, f, np.full(t.size, 5.0), np.full(t.size, 60.0), rs, 0.0)
    np.testing.assert_allclose(out[:, K.O_TORQUE], ref[:, K.O_TORQUE], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(out[:, K.O_THETA], ref[:, K.O_THETA], rtol=1e-12)


def test_pressure_temperature_cross(twin):
    m = synthesize_campaign(_spec(extra_effect="pressure_temperature_cross", magnitude=2e-3))
    assert m.expected_cause == "unexplained" and m.true_model.mechanisms == []
    a, b = _cat(twin, "plant_torque_nm"), _cat(m, "plant_torque_nm")
    hot = (_cat(twin, "pack_temperature_c") > 90) & (_cat(twin, "applied_force_n") > 4000)
    cold = (_cat(twin, "pack_temperature_c") < 50) & (_cat(twin, "applied_force_n") > 4000)
    assert hot.any() and cold.any()
    assert np.mean(b[hot] / a[hot]) > 1.02
    assert np.mean(b[cold] / a[cold]) < 1.0


def test_torque_ripple(twin):
    m = synthesize_campaign(_spec(extra_effect="torque_ripple", magnitude=0.1))
    np.testing.assert_array_equal(_cat(m, "plant_torque_nm"), _cat(twin, "plant_torque_nm"))
    ratio = _cat(m, "sensor_torque_nm") / _cat(twin, "sensor_torque_nm")
    ok = np.abs(_cat(twin, "sensor_torque_nm")) > 50
    assert ratio[ok].max() == pytest.approx(1.1, abs=0.005)
    assert ratio[ok].min() == pytest.approx(0.9, abs=0.005)
    assert m.metadata["extra_effect"]["name"] == "torque_ripple"


def test_spec_errors():
    with pytest.raises(ParamsError):
        synthesize_campaign(CampaignSpec(mechanism="torque_offset", extra_effect="torque_ripple"))
    with pytest.raises(ParamsError):
        synthesize_campaign(CampaignSpec(mechanism="no_such"))
    with pytest.raises(ParamsError):
        synthesize_campaign(CampaignSpec(mechanism="actuator_lag", magnitude=-1))
    with pytest.raises(ParamsError):
        synthesize_campaign(CampaignSpec(n_runs=0))


def test_write_campaign(tmp_path):
    from rosbags.highlevel import AnyReader

    r = synthesize_campaign(CampaignSpec(seed=3, n_runs=2, run_duration_s=4.0,
                                         mechanism="torque_offset", magnitude=30.0,
                                         include_pack_temperature=True))
    paths = write_campaign(r, tmp_path)
    assert [p.name for p in paths["bags"]] == ["run_00", "run_01"]
    truth = load_model(paths["truth"])
    assert truth.mechanism("torque_offset").values["offset_nm"] == 30.0
    np.testing.assert_array_equal(truth.friction_coefficients, r.true_model.friction_coefficients)
    meta = json.loads(paths["metadata"].read_text())
    assert meta["expected_cause"] == "torque_offset"
    assert meta["runs"][1]["start_time_ns"] == r.runs[1].start_time_ns
    with AnyReader([paths["bags"][1]]) as reader:
        topics = {c.topic for c in reader.connections}
        assert "/clutch/pack_temperature" in topics
        first = min(ts for _, ts, _ in reader.messages())
        assert first == r.runs[1].start_time_ns
    with pytest.raises(DataError, match="already holds"):
        write_campaign(r, tmp_path)


def test_replay_of_truth_reaches_noise_floor(tmp_path):
    """Written bags + the lead's bag reader and replay: the true model (with its mechanism)
    explains the measured torque down to the sensor noise; the twin without it does not."""
    from clutch_model.replay import replay_runs
    from clutch_model.formats.bag_reader import read_bags

    r = synthesize_campaign(CampaignSpec(seed=11, n_runs=3, mechanism="transport_delay", magnitude=0.05))
    paths = write_campaign(r, tmp_path)
    runs = read_bags(reversed(paths["bags"]))
    assert [x.name for x in runs] == ["run_00", "run_01", "run_02"]
    rmse_true = replay_runs(r.true_model, runs).rmse_torque()
    rmse_twin = replay_runs(r.true_model.with_mechanisms([]), runs).rmse_torque()
    assert rmse_true == pytest.approx(r.spec.torque_noise_nm, rel=0.08)
    assert rmse_twin > 3 * rmse_true
