"""The car-log virtual test car: every condition is really in the written bags, the truth
sidecar is consistent with the project's plant, same seed -> same files."""
import glob
import json
from pathlib import Path

import numpy as np
import pytest
from scipy import signal as sps

from clutch_model.plant.params import load_model
from clutch_model.plant.simulate import simulate
from clutch_model.virtual_car.car_logs import load_truth_sidecar
from clutch_model.virtual_car.signals import TopicClock
from tests.virtual_car.conftest import make_campaign


def sidecar(paths, name):
    return load_truth_sidecar(Path(paths["truth"]).parent / "truth" / f"{name}.npz")


def test_topics_on_their_own_clocks(short_campaign):
    result, paths, runs = short_campaign
    clocks = result.spec.clocks
    truth = json.loads(Path(paths["truth"]).read_text())
    for run, meta in zip(runs, truth["runs"]):
        for ch, (t, _v) in run.samples.items():
            clock = clocks[ch]
            dt = np.diff(t)
            assert np.median(dt) == pytest.approx(1.0 / clock.rate_hz, rel=0.02), ch
            # jitter: stamps against the nominal grid (phase fitted) are uniform +-jitter
            k = np.round((t - t[0]) * clock.rate_hz)
            dev = (t - t[0]) - k / clock.rate_hz
            dev -= np.mean(dev)
            bound = clock.jitter_s * 2 + clock.quantum_s
            assert np.max(np.abs(dev)) <= bound + 1e-9, ch
            if t.size > 200 and clock.jitter_s > 0:
                assert np.std(dev) == pytest.approx(np.sqrt(clock.jitter_s ** 2 / 3 + clock.quantum_s ** 2 / 12),
                                                    rel=0.15), ch
        # the topics are not aligned: force, slip and torque stamps mostly differ
        tf, ts, tq = run.samples["applied_force"][0], run.samples["slip_speed"][0], run.samples["measured_torque"][0]
        assert np.mean(np.isin(np.round(tq, 6), np.round(tf, 6))) < 0.2
        assert np.mean(np.isin(np.round(ts, 6), np.round(tf, 6))) < 0.2
        # quantised stamps: log times are whole multiples of the quantum from the run start
        side = sidecar(paths, run.name)
        rel = side["torque_log_time_ns"] - meta["start_time_ns"]
        assert np.all(rel % int(round(clocks["measured_torque"].quantum_s * 1e9)) == 0)
        np.testing.assert_allclose(run.torque_measured_t, side["torque_t_s"], atol=1e-9)


def test_truth_sidecar_consistent(short_campaign):
    result, paths, runs = short_campaign
    model = load_model(paths["truth_model"])
    for run in runs:
        side = sidecar(paths, run.name)
        # measured = noise-free reading + noise, at the same stamps
        np.testing.assert_allclose(run.torque_measured_raw_nm, side["torque_true_nm"] + side["torque_noise_nm"],
                                   atol=1e-9)
        # the fine grid is the project's plant: re-simulate the true inputs independently
        sim = simulate(model, side["fine_t_s"], side["fine_applied_force_n"], side["fine_slip_speed_rad_s"],
                       side["fine_sump_temperature_c"])
        slipping = ~side["fine_plant_locked"]
        np.testing.assert_allclose(sim.torque_nm[slipping], side["fine_torque_nm"][slipping], rtol=1e-9, atol=1e-9)
        np.testing.assert_array_equal(sim.locked, side["fine_plant_locked"])


def test_lock_phases_driveline_torque_and_slip_noise(short_campaign):
    result, paths, runs = short_campaign
    sigma = result.spec.noise["slip_speed"].sigma
    n_locked = 0
    for run in runs:
        side = sidecar(paths, run.name)
        lk = side["fine_locked"]
        assert lk.any(), "every 10 s run has a lock phase"
        cap = side["fine_static_capacity_nm"][lk]
        tq = side["fine_torque_nm"][lk]
        ratio = tq / cap
        # the driveline sets the torque: below the static capacity, not equal to it
        assert np.all(ratio >= 0.2 - 1e-9) and np.all(ratio <= 0.8 + 1e-9)
        assert np.std(ratio) > 0.01
        # the measured slip while locked is sensor noise around 0
        w = run.slip_raw_rad_s[side["slip_locked"]]
        n_locked += w.size
        assert abs(np.mean(w)) < 4 * sigma / np.sqrt(w.size)
        assert np.std(w) == pytest.approx(sigma, rel=0.2)
        assert np.mean(np.abs(w) > 1e-3) > 0.9   # the model's tolerance sees it as slipping
    assert n_locked > 200


NOISE_CASES = {
    "ar1": "ar1", "lowpass": "lowpass", "held": "held", "median": "median", "drift": "drift", "white": "white",
}


@pytest.fixture(scope="module")
def noise_campaigns(tmp_path_factory):
    from clutch_model.virtual_car.signals import make_noise
    specs = {"white": make_noise("white", 8.0), "ar1": make_noise("ar1", 8.0, phi=0.95),
             "lowpass": make_noise("lowpass", 8.0, cutoff_hz=10.0), "held": make_noise("held", 8.0, update_hz=10.0),
             "median": make_noise("median", 8.0, window=5), "drift": make_noise("drift", 4.0, drift=10.0, tau_s=5.0)}
    out = {}
    for kind, noise in specs.items():
        out[kind] = make_campaign(tmp_path_factory, f"noise_{kind}", seed=21, schedule="long-drive",
                                  run_duration_s=60.0, noise={"measured_torque": noise},
                                  clocks={"measured_torque": TopicClock(200.0, jitter_s=0.5e-3, quantum_s=1e-4)})
    return out


def _noise(campaign):
    result, paths, runs = campaign
    side = sidecar(paths, runs[0].name)
    return runs[0].torque_measured_raw_nm - side["torque_true_nm"]


def _lag1(x):
    x = x - x.mean()
    return float(np.dot(x[1:], x[:-1]) / np.dot(x, x))


def test_noise_classes_are_in_the_bags(noise_campaigns):
    white = _noise(noise_campaigns["white"])
    assert np.std(white) == pytest.approx(8.0, rel=0.05)
    assert abs(_lag1(white)) < 0.03
    ar1 = _noise(noise_campaigns["ar1"])
    assert _lag1(ar1) == pytest.approx(0.95, abs=0.015)       # phi recovered from the noise series
    assert np.std(ar1) == pytest.approx(8.0, rel=0.2)

    def band_ratio(x, fs=200.0):
        f, pxx = sps.welch(x, fs=fs, nperseg=1024)
        return float(np.mean(pxx[f > 40]) / np.mean(pxx[(f > 0.5) & (f < 5)]))
    assert band_ratio(white) == pytest.approx(1.0, abs=0.35)
    low = _noise(noise_campaigns["lowpass"])
    assert band_ratio(low) < 0.02                              # 10 Hz sensor filter
    assert np.std(low) == pytest.approx(8.0, rel=0.2)
    held = _noise(noise_campaigns["held"])
    assert np.mean(np.abs(np.diff(held)) < 1e-9) == pytest.approx(1 - 10.0 / 200.0, abs=0.01)   # 10 Hz held at 200 Hz
    med = _noise(noise_campaigns["median"])
    assert np.std(med) == pytest.approx(8.0, rel=0.1)
    assert 0.3 < _lag1(med) < 0.9
    drift = _noise(noise_campaigns["drift"])
    slow = np.convolve(drift, np.ones(200) / 200, mode="valid")   # 1 s means: white averages away
    assert np.std(slow) > 5.0 and np.std(drift - np.interp(np.arange(drift.size), np.arange(slow.size) + 100, slow)) \
        == pytest.approx(4.0, rel=0.25)


def test_same_seed_same_files(tmp_path_factory):
    a = make_campaign(tmp_path_factory, "det_a", seed=5, n_runs=2, mechanisms=[{"id": "actuator_lag", "tau_s": 0.1}])
    b = make_campaign(tmp_path_factory, "det_b", seed=5, n_runs=2, mechanisms=[{"id": "actuator_lag", "tau_s": 0.1}])
    c = make_campaign(tmp_path_factory, "det_c", seed=6, n_runs=2, mechanisms=[{"id": "actuator_lag", "tau_s": 0.1}])
    for pa, pb in zip(a[1]["bags"], b[1]["bags"]):
        fa = sorted(Path(pa).glob("*.mcap"))[0].read_bytes()
        fb = sorted(Path(pb).glob("*.mcap"))[0].read_bytes()
        assert fa == fb
    assert Path(a[1]["truth"]).read_text() == Path(b[1]["truth"]).read_text()
    assert not np.array_equal(a[2][0].torque_measured_raw_nm[:100], c[2][0].torque_measured_raw_nm[:100])


def test_schedules_mechanisms_and_effects(tmp_path_factory):
    res, paths, runs = make_campaign(tmp_path_factory, "long", seed=8, schedule="long-drive",
                                     mechanisms=[{"id": "actuator_lag", "tau_s": 0.08},
                                                 {"id": "torque_offset", "offset_nm": 20.0}],
                                     effects=[{"name": "torque_sensor_lowpass", "tau_s": 0.05}])
    assert len(runs) == 1 and runs[0].duration_s > 235.0
    kinds = {s["kind"] for s in res.truth["runs"][0]["segments"]}
    assert kinds == {"hold", "ramp", "sweep", "release", "lock"}
    model = load_model(paths["truth_model"])
    assert sorted(m.id for m in model.mechanisms) == ["actuator_lag", "torque_offset"]
    truth = json.loads(Path(paths["truth"]).read_text())
    assert truth["effects"][0]["name"] == "torque_sensor_lowpass" and truth["effects"][0]["mimics"] == "actuator_lag"
    side = sidecar(paths, runs[0].name)
    # the sensor reading is the low-pass of (transmitted + offset): check one step response
    fine_t, sens, trans = side["fine_t_s"], side["fine_sensor_torque_nm"], side["fine_torque_nm"]
    a = np.exp(-(fine_t[1] - fine_t[0]) / 0.05)
    y = np.empty_like(trans)
    y[0] = trans[0] + 20.0
    for k in range(1, y.size):
        y[k] = a * y[k - 1] + (1 - a) * (trans[k] + 20.0)
    np.testing.assert_allclose(sens, y, atol=1e-6)
    few, _, runs3 = make_campaign(tmp_path_factory, "few", seed=9, schedule="few-long", run_duration_s=20.0,
                                  effects=[{"name": "slip_power_fade"}, {"name": "run_friction_level"}])
    assert len(runs3) == 3 and few.truth["expected_cause"] == "unexplained"
    assert len(few.truth["effect_draws"]["run_friction_levels"]) == 3


def test_friction_effect_changes_torque_not_when_off(tmp_path_factory):
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs
    base = synthesize_car_logs(CarLogSpec(seed=3, n_runs=1))
    zero = synthesize_car_logs(CarLogSpec(seed=3, n_runs=1, effects=[{"name": "pressure_temperature_cross",
                                                                      "coeff": 0.0}]))
    on = synthesize_car_logs(CarLogSpec(seed=3, n_runs=1, effects=[{"name": "slip_power_fade", "k_per_kw": 0.05}]))
    slip = ~base.runs[0].fine["locked"]
    # the custom kernel loop with a neutral factor is the plant itself
    np.testing.assert_allclose(zero.runs[0].fine["torque_nm"][slip], base.runs[0].fine["torque_nm"][slip], rtol=1e-6)
    d = on.runs[0].fine["torque_nm"][slip] - base.runs[0].fine["torque_nm"][slip]
    assert np.sqrt(np.mean(d ** 2)) > 10.0


def test_slip_acceleration_friction_scales_the_torque_by_the_filtered_slip_acceleration():
    """slip_acceleration_friction: the torque is the plant's times 1 + c a, a = d|w|/dt through
    a first-order low-pass of tau (the reference: scipy.signal.lsim of s / (tau s + 1) on |w|,
    linear between fine rows), where the clutch slips; the heat the factor adds moves the torque
    by far less than the factor does."""
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs
    c, tau = 0.008, 0.03
    base = synthesize_car_logs(CarLogSpec(seed=4, n_runs=1))
    on = synthesize_car_logs(CarLogSpec(seed=4, n_runs=1, effects=[{"name": "slip_acceleration_friction",
                                                                     "gain_s2_per_rad": c, "tau_s": tau}]))
    fine_on, fine = on.runs[0].fine, base.runs[0].fine
    t = fine["t_s"] - fine["t_s"][0]
    w = np.abs(fine["slip_speed_rad_s"])
    _, a, _ = sps.lsim(([1.0, 0.0], [tau, 1.0]), w, t, X0=None, interp=True)
    factor = 1.0 + np.clip(c * a, -0.5, 0.5)
    rows = ~fine["locked"] & ~fine_on["locked"] & (np.abs(fine["torque_nm"]) > 50.0) & (t > 20 * tau)
    assert rows.sum() > 500
    ratio = fine_on["torque_nm"][rows] / fine["torque_nm"][rows]
    np.testing.assert_allclose(ratio, factor[rows], rtol=0, atol=0.01)
    assert np.std(factor[rows]) > 0.02                     # the effect is there to be seen
    assert on.spec.expected_cause == "unexplained"


def test_actuator_rate_limit_drives_the_plant_with_the_slew_limited_force():
    """actuator_rate_limit: the plant sees the request slewed at most R per second, the force
    sensor reads the request. Checked against the plant driven with a slew-limited force
    computed here; a limit no edge reaches changes nothing."""
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs
    rate = 30000.0
    base = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1))
    on = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1, effects=[{"name": "actuator_rate_limit", "rate_n_per_s": rate}]))
    loose = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1, effects=[{"name": "actuator_rate_limit",
                                                                       "rate_n_per_s": 1e9}]))
    fb, fo = base.runs[0].fine, on.runs[0].fine
    np.testing.assert_array_equal(fo["applied_force_n"], fb["applied_force_n"])
    np.testing.assert_array_equal(loose.runs[0].fine["torque_nm"], fb["torque_nm"])
    t, request = fb["t_s"], fb["applied_force_n"]
    step = rate * float(np.median(np.diff(t)))
    assert np.max(np.abs(np.diff(request))) > 3 * step          # the drive has edges the limit bites
    pack = np.empty_like(request)
    pack[0] = request[0]
    for k in range(1, request.size):
        pack[k] = pack[k - 1] + np.clip(request[k] - pack[k - 1], -step, step)
    _assert_plant_driven_by(pack, on, base, rtol=1e-9, atol=1e-6, min_change_rms_nm=5.0)


def _assert_plant_driven_by(pack_force, on, base, rtol, atol, min_change_rms_nm):
    """The effect's one-run campaign ``on`` is the plant driven by ``pack_force`` (the request of
    the effect-free ``base`` through the effect) while slipping, and differs from ``base`` by
    more than ``min_change_rms_nm`` RMS there."""
    fb, fo = base.runs[0].fine, on.runs[0].fine
    run_start = np.zeros(fb["t_s"].size, bool)
    run_start[0] = True
    ref = simulate(on.true_model, fb["t_s"], pack_force, fb["slip_speed_rad_s"], fb["sump_temperature_c"],
                   run_start=run_start)
    slipping = ~(fo["locked"] | fb["locked"])
    np.testing.assert_allclose(fo["torque_nm"][slipping], ref.torque_nm[slipping], rtol=rtol, atol=atol)
    d = fo["torque_nm"][slipping] - fb["torque_nm"][slipping]
    assert np.sqrt(np.mean(d ** 2)) > min_change_rms_nm


def test_actuator_second_order_drives_the_plant_with_the_filtered_force():
    """actuator_second_order: the plant sees the request through x'' = w^2 (F - x) - 2 zeta w x'
    (at rest at the request at the run's start), the force sensor reads the request. The
    reference pack force comes from solve_ivp (tight tolerance) on the request held over each
    fine step; the plant driven with it must give the generated torque."""
    from scipy.integrate import solve_ivp
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs
    f_n, zeta = 2.4, 0.6
    base = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1))
    on = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1, effects=[{"name": "actuator_second_order",
                                                                    "f_n_hz": f_n, "damping": zeta}]))
    fb, fo = base.runs[0].fine, on.runs[0].fine
    np.testing.assert_array_equal(fo["applied_force_n"], fb["applied_force_n"])
    t, request = fb["t_s"], fb["applied_force_n"]
    dt, w = float(t[1] - t[0]), 2 * np.pi * f_n

    def rhs(tt, z):
        k = min(int(np.floor(tt / dt + 1e-9)), request.size - 1)
        return [z[1], w * w * (request[k] - z[0]) - 2 * zeta * w * z[1]]
    ref_pack = np.empty_like(request)
    z = np.array([request[0], 0.0])
    ref_pack[0] = z[0]
    for k in range(1, request.size):   # one solve per held step: the input is smooth inside it
        z = solve_ivp(rhs, (t[k - 1], t[k]), z, rtol=1e-10, atol=1e-8, method="DOP853", first_step=dt / 4).y[:, -1]
        ref_pack[k] = z[0]
    # the force path is visibly slower
    _assert_plant_driven_by(ref_pack, on, base, rtol=1e-6, atol=1e-3, min_change_rms_nm=10.0)
    truth = on.truth["effects"][0]
    assert truth["name"] == "actuator_second_order" and truth["parameters"] == {"f_n_hz": f_n, "damping": zeta}
    assert on.spec.expected_cause == "unexplained"


def test_actuator_backlash_drives_the_plant_through_a_play_of_constant_width():
    """actuator_backlash: the plant sees the request through a play of constant half-width w
    (the pack force moves only when the request leaves [x - w, x + w]), the force sensor reads
    the request. The reference play is computed here row by row; the played force never
    strays more than w from the request, and reaches it again after every reversal larger
    than 2 w. Unlike the catalog's hysteresis band F(1 +- ratio), the play's width does not
    grow with the force."""
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs
    w = 250.0
    base = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1))
    on = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1, effects=[{"name": "actuator_backlash", "half_width_n": w}]))
    fb, fo = base.runs[0].fine, on.runs[0].fine
    np.testing.assert_array_equal(fo["applied_force_n"], fb["applied_force_n"])
    request = fb["applied_force_n"]
    pack = np.empty_like(request)
    pack[0] = request[0]
    for k in range(1, request.size):
        pack[k] = min(max(pack[k - 1], request[k] - w), request[k] + w)
    assert np.max(np.abs(pack - request)) <= w + 1e-9
    assert np.mean(np.abs(pack - request) > 0.5 * w) > 0.1     # the play is engaged much of the drive
    _assert_plant_driven_by(pack, on, base, rtol=1e-9, atol=1e-6, min_change_rms_nm=5.0)
    truth = on.truth["effects"][0]
    assert truth["name"] == "actuator_backlash" and truth["parameters"] == {"half_width_n": w}
    assert truth["mimics"] == "actuator_hysteresis" and on.spec.expected_cause == "unexplained"


def test_force_sensor_hysteresis_logs_the_pack_force_through_a_play_the_plant_never_sees():
    """force_sensor_hysteresis: the plant sees the request unchanged (its torque is the
    effect-free car's), the force sensor logs it through a play of constant half-width w
    computed here row by row: the log trails the pack force by up to w on every move, the
    reverse of the catalog's band, which makes the pack force trail the log."""
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs
    w = 300.0
    base = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1))
    on = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1, effects=[{"name": "force_sensor_hysteresis", "half_width_n": w}]))
    fb, fo = base.runs[0].fine, on.runs[0].fine
    np.testing.assert_allclose(fo["torque_nm"], fb["torque_nm"], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(fo["pack_temperature_c"], fb["pack_temperature_c"], rtol=1e-12, atol=1e-9)
    request = fb["applied_force_n"]
    logged = np.empty_like(request)
    logged[0] = request[0]
    for k in range(1, request.size):
        logged[k] = min(max(logged[k - 1], request[k] - w), request[k] + w)
    np.testing.assert_allclose(fo["applied_force_n"], logged, rtol=0, atol=1e-9)
    assert np.max(np.abs(logged - request)) <= w + 1e-9
    assert np.mean(np.abs(logged - request) > 0.5 * w) > 0.1     # the play is engaged much of the drive
    truth = on.truth["effects"][0]
    assert truth["name"] == "force_sensor_hysteresis" and truth["parameters"] == {"half_width_n": w}
    assert truth["mimics"] == "actuator_hysteresis" and on.spec.expected_cause == "unexplained"


def test_torque_judder_is_an_oscillation_strongest_at_low_slip_while_slipping():
    """torque_judder: the transmitted torque of the effect-free car times 1 + A exp(-|w|/s)
    sin(2 pi f t + phi0) on the slipping rows (a unit sinusoid at f once divided by the
    envelope, fitted here), untouched while locked; the plant's heat is the effect-free car's."""
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs
    amp, f_hz, scale = 0.06, 10.0, 8.0
    base = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1))
    on = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1, effects=[{"name": "torque_judder", "amplitude": amp}]))
    fb, fo = base.runs[0].fine, on.runs[0].fine
    locked = fb["locked"].astype(bool)
    assert locked.any() and (~locked).mean() > 0.5
    np.testing.assert_array_equal(fo["torque_nm"][locked], fb["torque_nm"][locked])
    np.testing.assert_allclose(fo["pack_temperature_c"], fb["pack_temperature_c"], rtol=1e-12, atol=1e-9)
    ok = ~locked & (np.abs(fb["torque_nm"]) > 10.0)
    q = fo["torque_nm"][ok] / fb["torque_nm"][ok] - 1.0
    env = amp * np.exp(-np.abs(fb["slip_speed_rad_s"][ok]) / scale)
    tt = (fb["t_s"] - fb["t_s"][0])[ok]
    x = np.column_stack([env * np.sin(2 * np.pi * f_hz * tt), env * np.cos(2 * np.pi * f_hz * tt)])
    beta, *_ = np.linalg.lstsq(x, q, rcond=None)
    assert np.hypot(*beta) == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(x @ beta, q, rtol=0, atol=1e-9)
    truth = on.truth["effects"][0]
    assert truth["name"] == "torque_judder" and truth["parameters"]["frequency_hz"] == f_hz
    assert truth["mimics"] is None and on.spec.expected_cause == "unexplained"


def test_force_sensor_offset_drives_the_plant_with_more_force_than_logged():
    """force_sensor_offset: the force sensor reads the request, the pack gets it plus the
    offset (the plant driven with request + c gives the generated torque)."""
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs
    c = 450.0
    base = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1))
    on = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1, effects=[{"name": "force_sensor_offset", "offset_n": c}]))
    np.testing.assert_array_equal(on.runs[0].fine["applied_force_n"], base.runs[0].fine["applied_force_n"])
    _assert_plant_driven_by(base.runs[0].fine["applied_force_n"] + c, on, base, rtol=1e-9, atol=1e-6,
                            min_change_rms_nm=10.0)
    assert on.spec.expected_cause == "unexplained"


def test_actuator_asymmetric_lag_applies_and_releases_at_their_own_time_constants():
    """actuator_asymmetric_lag: the plant sees the request through x' = (F - x) / tau, tau the
    apply constant while x rises toward F and the release constant while it falls (the
    request held over each fine step). The reference is solve_ivp (tight tolerance) step by
    step, each step's tau chosen by the sign of F - x at its start (x never crosses a held F)."""
    from scipy.integrate import solve_ivp
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs
    ta, tr = 0.03, 0.21
    base = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1))
    on = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1, effects=[{"name": "actuator_asymmetric_lag",
                                                                    "tau_release_s": tr, "tau_apply_s": ta}]))
    fb, fo = base.runs[0].fine, on.runs[0].fine
    np.testing.assert_array_equal(fo["applied_force_n"], fb["applied_force_n"])
    t, request = fb["t_s"], fb["applied_force_n"]
    pack = np.empty_like(request)
    pack[0] = request[0]
    for k in range(1, request.size):
        tau = ta if request[k] > pack[k - 1] else tr
        pack[k] = solve_ivp(lambda _t, x: (request[k] - x) / tau, (t[k - 1], t[k]), [pack[k - 1]],
                            rtol=1e-11, atol=1e-9).y[0, -1]
    rising, falling = np.diff(request) > 1.0, np.diff(request) < -1.0
    assert rising.any() and falling.any()
    # slow release: the pack force trails a falling request far more than a rising one
    lag = request - pack
    assert np.mean(-lag[1:][falling]) > 3 * np.mean(lag[1:][rising])
    _assert_plant_driven_by(pack, on, base, rtol=1e-6, atol=1e-3, min_change_rms_nm=5.0)
    truth = on.truth["effects"][0]
    assert truth["name"] == "actuator_asymmetric_lag"
    assert truth["parameters"] == {"tau_release_s": tr, "tau_apply_s": ta}
    assert truth["mimics"] == "actuator_lag" and on.spec.expected_cause == "unexplained"


def test_actuator_force_delay_drives_the_plant_with_the_force_read_late():
    """actuator_force_delay: the plant sees the request delay_s late (linear between fine rows,
    the first request before the run's start, independent of the generator's own helper: a
    loop over the rows), the force sensor logs the request on time."""
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs
    delay = 0.0237
    base = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1))
    on = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1, effects=[{"name": "actuator_force_delay",
                                                                    "delay_s": delay}]))
    fb, fo = base.runs[0].fine, on.runs[0].fine
    np.testing.assert_array_equal(fo["applied_force_n"], fb["applied_force_n"])
    t, request = fb["t_s"], fb["applied_force_n"]
    pack = np.empty_like(request)
    for k in range(t.size):
        tq = t[k] - delay
        j = int(np.searchsorted(t, tq, side="right")) - 1
        pack[k] = request[0] if j < 0 else (request[j] if j == t.size - 1 else
                                            request[j] + (tq - t[j]) / (t[j + 1] - t[j]) * (request[j + 1] - request[j]))
    _assert_plant_driven_by(pack, on, base, rtol=1e-6, atol=1e-3, min_change_rms_nm=5.0)
    truth = on.truth["effects"][0]
    assert truth["name"] == "actuator_force_delay" and truth["parameters"] == {"delay_s": delay}
    assert truth["mimics"] == "transport_delay" and on.spec.expected_cause == "unexplained"


def test_actuator_force_dependent_lag_slows_with_the_pack_force():
    """actuator_force_dependent_lag: the plant sees the request through x' = (F - x) / tau(x),
    tau linear from tau_low at 0 N to tau_high at force_ref_n, constant beyond (the request held
    over each fine step; solve_ivp step by step with tau at the step's start, as the car takes
    it)."""
    from scipy.integrate import solve_ivp
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs
    lo, hi, ref_n = 0.02, 0.25, 6000.0
    base = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1))
    on = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1, effects=[{"name": "actuator_force_dependent_lag",
                                                                    "tau_high_s": hi}]))
    t, request = base.runs[0].fine["t_s"], base.runs[0].fine["applied_force_n"]
    pack = np.empty_like(request)
    pack[0] = request[0]
    for k in range(1, request.size):
        tau = lo + (hi - lo) * min(max(pack[k - 1] / ref_n, 0.0), 1.0)
        pack[k] = solve_ivp(lambda _t, x: (request[k] - x) / tau, (t[k - 1], t[k]), [pack[k - 1]],
                            rtol=1e-11, atol=1e-9).y[0, -1]
    _assert_plant_driven_by(pack, on, base, rtol=1e-6, atol=1e-3, min_change_rms_nm=5.0)
    truth = on.truth["effects"][0]
    assert truth["parameters"] == {"tau_high_s": hi, "tau_low_s": lo, "force_ref_n": ref_n}
    assert truth["mimics"] == "actuator_lag" and on.spec.expected_cause == "unexplained"


def test_actuator_oil_temperature_lag_is_slower_in_cold_oil():
    """actuator_oil_temperature_lag: the plant sees the request through x' = (F - x) / tau,
    tau = tau_40 exp(-c (sump - 40 C)) at the fine row's sump temperature (the request held over
    each fine step; solve_ivp step by step), in a cold run and in a hot one; the cold run's
    torque moves more (its lag is four times the hot run's)."""
    from scipy.integrate import solve_ivp
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs
    tau_40, coeff = 0.1, 0.03
    change = []
    for sumps in ((30.0, 32.0), (75.0, 78.0)):
        base = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1, sump_range_c=sumps))
        on = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1, sump_range_c=sumps,
                                            effects=[{"name": "actuator_oil_temperature_lag", "tau_40_s": tau_40}]))
        t, request = base.runs[0].fine["t_s"], base.runs[0].fine["applied_force_n"]
        sump = base.runs[0].fine["sump_temperature_c"]
        pack = np.empty_like(request)
        pack[0] = request[0]
        for k in range(1, request.size):
            tau = tau_40 * np.exp(-coeff * (sump[k] - 40.0))
            pack[k] = solve_ivp(lambda _t, x: (request[k] - x) / tau, (t[k - 1], t[k]), [pack[k - 1]],
                                rtol=1e-11, atol=1e-9).y[0, -1]
        _assert_plant_driven_by(pack, on, base, rtol=1e-6, atol=1e-3, min_change_rms_nm=1.0)
        slipping = ~(on.runs[0].fine["locked"] | base.runs[0].fine["locked"])
        d = on.runs[0].fine["torque_nm"][slipping] - base.runs[0].fine["torque_nm"][slipping]
        change.append(float(np.sqrt(np.mean(d ** 2))))
    assert change[0] > 1.5 * change[1], change
    truth = on.truth["effects"][0]
    assert truth["parameters"] == {"tau_40_s": tau_40, "coeff_per_c": coeff}
    assert truth["mimics"] == "actuator_lag" and on.spec.expected_cause == "unexplained"


def test_torque_sensor_asymmetric_lag_reads_rises_fast_and_falls_slowly():
    """torque_sensor_asymmetric_lag: the plant is untouched, the reading is the noise-free
    measurement of the effect-free car through y' = (T - y) / tau, tau_rise while (T - y) T > 0,
    tau_fall otherwise (T held over each fine step; solved exactly step by step here)."""
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs
    rise, fall = 0.015, 0.18
    base = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1))
    on = synthesize_car_logs(CarLogSpec(seed=2, n_runs=1, effects=[{"name": "torque_sensor_asymmetric_lag",
                                                                    "tau_fall_s": fall}]))
    fb, fo = base.runs[0].fine, on.runs[0].fine
    np.testing.assert_array_equal(fo["torque_nm"], fb["torque_nm"])          # the plant is the same
    t, u = fb["t_s"], fb["sensor_torque_nm"]
    y = np.empty_like(u)
    y[0] = u[0]
    for k in range(1, u.size):
        tau = rise if (u[k] - y[k - 1]) * u[k] > 0 else fall
        y[k] = u[k] + (y[k - 1] - u[k]) * np.exp(-(t[k] - t[k - 1]) / tau)
    np.testing.assert_allclose(fo["sensor_torque_nm"], y, rtol=1e-9, atol=1e-6)
    assert np.sqrt(np.mean((y - u) ** 2)) > 5.0
    truth = on.truth["effects"][0]
    assert truth["mimics"] == "torque_sensor_lag" and on.spec.expected_cause == "unexplained"


def test_cli_car_logs(tmp_path):
    from clutch_sim.cli import main
    out = tmp_path / "c"
    assert main(["synth", "--conditions", "car-logs", "--out", str(out), "--car-runs", "2", "--car-duration", "6",
                 "--car-mechanism", "spring_preload=500", "--effect", "torque_ripple=0.05",
                 "--torque-noise-model", "ar1:sigma=6,phi=0.9", "--rate", "torque=100"]) == 0
    assert len(glob.glob(str(out / "bags" / "*"))) == 2
    truth = json.loads((out / "truth.json").read_text())
    assert truth["noise"]["measured_torque"]["kind"] == "ar1" and truth["clocks"]["measured_torque"]["rate_hz"] == 100
    assert main(["synth", "--conditions", "car-logs", "--out", str(tmp_path / "d"), "--effect", "nope"]) == 1


def test_score_against_truth(short_campaign):
    """The true model scores close to 0 against the true torque (input noise only); a model
    with a wrong mechanism scores far worse."""
    from clutch_model.plant.mechanisms import make_mechanism
    from clutch_model.virtual_car.car_logs import score_against_truth, true_sensor_torque_at
    result, paths, runs = short_campaign
    truth_dir = Path(paths["truth"]).parent / "truth"
    model = load_model(paths["truth_model"])
    good = score_against_truth(model, runs, truth_dir)
    bad = score_against_truth(model.with_mechanisms([make_mechanism("torque_offset", offset_nm=20.0)]), runs, truth_dir)
    assert good["rmse_nm"] < 6.0 and good["samples"] > 1000
    assert bad["rmse_nm"] == pytest.approx(np.hypot(20.0, good["rmse_nm"]), rel=0.1)
    side = sidecar(paths, runs[0].name)
    np.testing.assert_allclose(true_sensor_torque_at(side, side["fine_t_s"][5:9]), side["fine_sensor_torque_nm"][5:9])


def test_synth_help_names_every_effect(capsys):
    """`clutch-sim synth --help` lists every effect the virtual car knows (the list is written
    out in the parser, which must not import the car)."""
    from clutch_model.virtual_car.car_logs import EFFECTS
    from clutch_sim.cli import main
    with pytest.raises(SystemExit):
        main(["synth", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for name in EFFECTS:
        assert name in text, name


def test_a_sensor_range_pins_the_logged_reading_at_a_share_of_the_campaign_peak():
    """sensor_range: the logged torque is the unclipped one wherever it lies within +-share x the
    campaign's peak noise-free torque, and exactly that limit beyond it; the truth keeps it unclipped."""
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs
    base = synthesize_car_logs(CarLogSpec(seed=5, n_runs=2))
    on = synthesize_car_logs(CarLogSpec(seed=5, n_runs=2, sensor_range={"measured_torque": 0.7}))
    rail = 0.7 * max(float(np.max(np.abs(r.fine["sensor_torque_nm"]))) for r in base.runs)
    assert on.truth["sensor_range"]["measured_torque"]["rail"] == pytest.approx(rail, rel=1e-12)
    pinned = 0
    for b, o in zip(base.runs, on.runs):
        raw, got = b.signals.measured_torque.values, o.signals.measured_torque.values
        inside = np.abs(raw) <= rail
        np.testing.assert_array_equal(got[inside], raw[inside])
        np.testing.assert_array_equal(got[~inside], np.sign(raw[~inside]) * rail)
        pinned += int((~inside).sum())
        np.testing.assert_array_equal(o.fine["sensor_torque_nm"], b.fine["sensor_torque_nm"])
        np.testing.assert_array_equal(o.signals.applied_force.values, b.signals.applied_force.values)
    assert pinned > 20


def test_a_drive_cut_into_bags_carries_the_plant_across_the_roll_overs():
    """continuous_runs: the first runs are one drive cut into consecutive bags. Each starts
    where the last ended (no pause), the pack temperature and the sump go on across the
    roll-over, and the plant equals one simulation of the whole drive; the run after them
    follows a pause and restarts with the pack at its sump."""
    from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs

    res = synthesize_car_logs(CarLogSpec(seed=4, n_runs=4, run_duration_s=10.0, continuous_runs=3))
    runs = res.runs
    for a, b in zip(runs[:2], runs[1:3]):
        end_a = a.start_time_ns * 1e-9 + a.fine["t_s"][-1]
        assert 0.0 < b.start_time_ns * 1e-9 - end_a < 2e-3          # the next fine step
        assert abs(b.fine["pack_temperature_c"][0] - a.fine["pack_temperature_c"][-1]) < 0.5
        assert abs(b.fine["sump_temperature_c"][0] - a.fine["sump_temperature_c"][-1]) < 0.01
    assert runs[1].fine["pack_temperature_c"][0] > runs[1].fine["sump_temperature_c"][0] + 5.0   # hot at the roll-over
    assert runs[3].start_time_ns * 1e-9 - (runs[2].start_time_ns * 1e-9 + 10.0) >= res.spec.gap_s
    assert runs[3].fine["pack_temperature_c"][0] == pytest.approx(runs[3].fine["sump_temperature_c"][0], abs=1e-6)
    # the drive's plant is one simulation: restarting the second bag would change it
    drive = {k: np.concatenate([r.fine[k] for r in runs[:3]]) for k in ("t_s", "applied_force_n",
                                                                      "slip_speed_rad_s", "sump_temperature_c")}
    t = np.concatenate([(r.start_time_ns - runs[0].start_time_ns) * 1e-9 + r.fine["t_s"] for r in runs[:3]])
    one = np.zeros(t.size, bool)
    one[0] = True
    locked = np.concatenate([r.fine["locked"] for r in runs[:3]])
    ref = simulate(res.true_model, t, drive["applied_force_n"], drive["slip_speed_rad_s"],
                   drive["sump_temperature_c"], run_start=one)
    got = np.concatenate([r.fine["torque_nm"] for r in runs[:3]])
    np.testing.assert_allclose(got[~locked], ref.torque_nm[~locked], rtol=1e-9, atol=1e-6)


def test_the_synth_help_lists_every_effect_of_the_virtual_car():
    """`synth --effect` names the effects from a list kept beside its options (the help must not
    import the numerics): it is the virtual car's table, no more, no less."""
    from clutch_model.virtual_car.car_logs import EFFECTS
    from clutch_sim.commands._car_logs import EFFECT_NAMES

    assert sorted(EFFECT_NAMES) == sorted(EFFECTS)
