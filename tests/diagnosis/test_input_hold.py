"""The force a step-holding plant is given on sparse rows: the step's midpoint value.

Reference: the plant simulated on a 1 kHz grid (the force held over 1 ms steps, close to the
continuous force); on 50 Hz rows the force held from each row is 10 ms late on average, the
midpoint force is not. The torque at the rows is compared with the 1 kHz reference there."""
import numpy as np
import pytest

from clutch_model.diagnosis.input_hold import force_at_step_midpoints
from clutch_model.plant.params import load_model
from clutch_model.plant.simulate import simulate


def test_midpoints_of_a_ramp_are_exact():
    t = np.array([0.0, 0.02, 0.05, 0.06])
    ts = np.linspace(0.0, 0.1, 11)
    f = force_at_step_midpoints(t, ts, 100.0 + 2000.0 * ts)
    assert np.allclose(f, 100.0 + 2000.0 * np.array([0.01, 0.035, 0.055, 0.06]), rtol=0, atol=1e-9)


def test_midpoint_force_removes_the_half_step_lag():
    model = load_model(None)
    fine = np.arange(0, 3.0, 1e-3)
    force = 3000.0 + 2500.0 * np.sin(2 * np.pi * 1.5 * fine)           # controller-like sweep
    slip = np.full(fine.size, 15.0)
    sump = np.full(fine.size, 60.0)
    ref = simulate(model, fine, force, slip, sump).torque_nm
    rows = np.arange(0, fine.size, 20)                                  # 50 Hz rows
    t = fine[rows]
    held = simulate(model, t, force[rows], slip[rows], sump[rows]).torque_nm
    mid = simulate(model, t, force_at_step_midpoints(t, fine, force), slip[rows], sump[rows]).torque_nm
    late = slice(10, None)                                              # after the first engagement
    err_held = np.sqrt(np.mean((held - ref[rows])[late] ** 2))
    err_mid = np.sqrt(np.mean((mid - ref[rows])[late] ** 2))
    assert err_held > 1.0                                               # the hold is visibly late
    assert err_mid < 0.2 * err_held, (err_held, err_mid)


# --- the slip smoothed without phase where the torque sensor is quiet (input_hold) -----------

def _jittered_times(rng, rate_hz, duration_s, jitter_s):
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    return np.sort(t + rng.uniform(-jitter_s, jitter_s, t.size))


def test_smoothing_adds_no_delay_and_has_the_gaussian_gain():
    """A 3 Hz sine on jittered 200 Hz stamps comes out in phase, scaled by the Gaussian
    kernel's gain exp(-2 pi^2 sigma^2 f^2) (0.996); a 60 Hz one, also in phase, at most to
    that gain (0.17; the linear resampling on and off the uniform grid takes a little more)."""
    from clutch_model.diagnosis.input_hold import SLIP_SMOOTHING_S, gaussian_smooth

    rng = np.random.default_rng(3)
    t = _jittered_times(rng, 200.0, 6.0, 1e-3)
    inner = (t > 0.5) & (t < 5.5)
    for f_hz in (3.0, 60.0):
        gain = np.exp(-2 * np.pi ** 2 * SLIP_SMOOTHING_S ** 2 * f_hz ** 2)
        y = gaussian_smooth(t, np.sin(2 * np.pi * f_hz * t), SLIP_SMOOTHING_S)
        # least squares on sin and cos: the cos part is the phase
        basis = np.column_stack([np.sin(2 * np.pi * f_hz * t), np.cos(2 * np.pi * f_hz * t)])[inner]
        (a, b), *_ = np.linalg.lstsq(basis, y[inner], rcond=None)
        if f_hz < 10:
            assert a == pytest.approx(gain, rel=0.01), (f_hz, a, gain)
        else:
            assert 0.05 < a < 1.05 * gain, (f_hz, a, gain)
        assert abs(np.arctan2(b, a)) < 0.02, (f_hz, b)      # 0.02 rad at 60 Hz: 53 us


def test_high_frequency_noise_of_the_noise_classes():
    """White-equivalent noise near Nyquist: white noise of sd 8 reads 8; a first-order
    low-pass of sd 8 (tau 50 ms at 200 Hz) its Nyquist level, 1.8; a value held over 20
    samples has power there (its jumps) but its typical difference is 0; a smooth signal added
    changes none of them much."""
    from scipy.signal import lfilter

    from clutch_model.diagnosis.input_hold import high_frequency_noise

    rng = np.random.default_rng(11)
    t = np.arange(0.0, 30.0, 0.005)
    smooth = 300.0 * np.sin(2 * np.pi * 0.7 * t) + 100.0 * np.sin(2 * np.pi * 2.1 * t)
    white = rng.normal(0.0, 8.0, t.size)
    a = np.exp(-0.005 / 0.05)
    low = lfilter([1 - a], [1, -a], white) * np.sqrt((1 + a) / (1 - a))     # sd 8 again
    held = np.repeat(rng.normal(0.0, 8.0, t.size // 20 + 1), 20)[:t.size]
    assert high_frequency_noise([white]) == pytest.approx(8.0, rel=0.05)
    assert high_frequency_noise([smooth + white]) == pytest.approx(8.0, rel=0.05)
    assert np.std(low) == pytest.approx(8.0, rel=0.15)
    # at Nyquist the first-order filter passes (1 - a) / (1 + a) of the white input's sd
    assert high_frequency_noise([smooth + low]) == pytest.approx(8.0 * np.sqrt((1 - a) / (1 + a)), rel=0.1)
    assert high_frequency_noise([smooth + held], typical=True) < 0.1
    assert high_frequency_noise([smooth + held]) > 0.3
    assert high_frequency_noise([smooth + white], typical=True) == pytest.approx(8.0, rel=0.05)


def _campaign(torque_noise, seed=5, slip_noise=0.05, torsion=0.0):
    from clutch_model.formats.bag_reader import Campaign, Run

    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 20.0, 0.005)
    slip = np.where((t > 8) & (t < 11), 0.0, 5.0 + 3.0 * np.sin(2 * np.pi * 0.2 * t)
                    + torsion * np.sin(2 * np.pi * 11.0 * t)) + rng.normal(0.0, slip_noise, t.size)
    force = 4000.0 + 2000.0 * np.sin(2 * np.pi * 0.3 * t)
    torque = 0.05 * force + torque_noise(rng, t.size)
    run = Run("r", t, force, slip, np.full(t.size, 60.0), torque_measured_nm=torque,
              samples={"applied_force": (t, force), "slip_speed": (t, slip), "measured_torque": (t, torque)})
    return Campaign([run]), slip


def test_slip_smoothed_only_under_a_quiet_torque_sensor_and_logged_slip_kept_for_lockup():
    """White torque noise: inputs as logged. Torque noise band-limited to 5 Hz (quiet near
    Nyquist): the slip is smoothed, its white noise variance cut to 1 / (2 sqrt(pi) sigma/dt);
    the slip as logged stays under slip_speed_logged, and the lock-up detection, which
    estimates the slip sensor's noise from it, reads the same noise and phases as on the raw
    samples."""
    from scipy.signal import butter, sosfilt

    from clutch_model.diagnosis.input_hold import decide_input_noise, with_smoothed_slip
    from clutch_model.diagnosis.lockup import detect_lockup, detect_lockup_run
    from clutch_model.plant.params import load_model

    model = load_model(None)
    white, _ = _campaign(lambda rng, n: rng.normal(0.0, 8.0, n))
    decision = decide_input_noise(white, model)
    assert not decision.smoothed
    assert decision.torque_noise_hf_nm == pytest.approx(8.0, rel=0.1)
    assert decision.slip_noise_in_torque_nm > 0.0
    band = butter(4, 5.0, fs=200.0, output="sos")
    quiet, slip = _campaign(lambda rng, n: 8.0 * sosfilt(band, rng.normal(0.0, 3.0, n)))
    decision = decide_input_noise(quiet, model)
    assert decision.smoothed, decision.describe()

    (out,) = with_smoothed_slip(quiet, decision.sigma_s).runs
    t = out.t
    noise = slip - np.where((t > 8) & (t < 11), 0.0, 5.0 + 3.0 * np.sin(2 * np.pi * 0.2 * t))
    smoothed_noise = out.slip_speed_rad_s - (slip - noise)
    expected = 1.0 / (2.0 * np.sqrt(np.pi) * decision.sigma_s / 0.005)
    inner = (t > 1) & (t < 19) & (np.abs(t - 8) > 0.1) & (np.abs(t - 11) > 0.1)
    assert np.var(smoothed_noise[inner]) / np.var(noise[inner]) == pytest.approx(expected, rel=0.15)
    assert np.array_equal(out.samples["slip_speed"][1], out.slip_speed_rad_s)
    assert np.array_equal(out.samples["slip_speed_logged"][1], slip)
    assert np.array_equal(out.applied_force_n, quiet.runs[0].applied_force_n)
    raw, seen = detect_lockup(t, slip), detect_lockup_run(out)
    assert seen.noise_sigma_rad_s == raw.noise_sigma_rad_s
    assert np.array_equal(seen.at(t), raw.at(t))
    assert raw.at(t)[(t > 8.5) & (t < 10.5)].all()


def test_the_slip_is_not_smoothed_where_the_smoothing_would_take_its_own_motion():
    """The quiet torque sensor of the test above, the slip carrying an 11 Hz driveline
    oscillation of 2 rad/s over a sensor noise of 0.015 rad/s: the 5 ms Gaussian would take
    12 % of the oscillation (its gain exp(-2 pi^2 sigma^2 f^2) = 0.94 at 11 Hz; about 0.1 rad/s
    typical), several times the noise, so the slip stays as logged. On the white slip noise of
    0.05 rad/s alone it takes 0.70 of the noise (x - g * x for white x: variance
    1 - 2 g_0 + sum g^2, with the kernel's centre weight g_0 = dt / (sigma sqrt(2 pi)) = 0.40
    and sum g^2 = 1 / (2 sqrt(pi) sigma / dt) = 0.28: 0.48, sd 0.70), and the slip is smoothed."""
    from scipy.signal import butter, sosfilt

    from clutch_model.diagnosis.input_hold import SMOOTHING_SIGNAL_RATIO, decide_input_noise
    from clutch_model.plant.params import load_model

    model = load_model(None)
    band = butter(4, 5.0, fs=200.0, output="sos")
    quiet = lambda rng, n: 8.0 * sosfilt(band, rng.normal(0.0, 3.0, n))   # noqa: E731
    plain, _ = _campaign(quiet)
    decision = decide_input_noise(plain, model)
    assert decision.smoothed
    assert decision.smoothing_removes_rad_s == pytest.approx(0.70 * 0.05, rel=0.1)
    oscillating, _ = _campaign(quiet, slip_noise=0.015, torsion=2.0)
    decision = decide_input_noise(oscillating, model)
    assert decision.smoothing_removes_rad_s > 3 * SMOOTHING_SIGNAL_RATIO * decision.slip_noise_hf_rad_s
    assert not decision.smoothed, decision.to_dict()
    assert decision.to_dict()["slip_smoothing_removes_rad_s"] == decision.smoothing_removes_rad_s


def test_the_force_noise_is_read_from_its_samples_as_logged():
    """A 100 Hz force with AR(1) 0.93 noise of sd 49 N (near Nyquist, white-equivalent: sd
    sqrt((1 - phi) / (1 + phi)) = 9.4 N), interpolated onto 200 Hz torque stamps: the rows keep a
    fraction of its noise near their own Nyquist frequency, the samples as logged all of it. The
    candidates' force resolution takes the logged figure (CampaignContext.logged_force_noise_n)."""
    from clutch_model.diagnosis.candidates import CampaignContext
    from clutch_model.diagnosis.input_hold import high_frequency_noise, logged_force_noise_n
    from clutch_model.formats.bag_reader import Campaign, Run

    rng = np.random.default_rng(11)
    tf = np.arange(0.0, 60.0, 0.01)
    noise = np.zeros(tf.size)
    e = rng.normal(0.0, 49.0 * np.sqrt(1 - 0.93 ** 2), tf.size)
    for k in range(1, tf.size):
        noise[k] = 0.93 * noise[k - 1] + e[k]
    force = 2000.0 + 1500.0 * np.sin(2 * np.pi * 0.2 * tf) + noise
    rows = np.arange(0.0, 59.99, 0.005)
    on_rows = np.interp(rows, tf, force)
    logged = Campaign([Run("r", rows, on_rows, np.full(rows.size, 5.0), np.full(rows.size, 60.0),
                           samples={"applied_force": (tf, force)})])
    expected = 49.0 * np.sqrt(0.07 / 1.93)
    assert logged_force_noise_n(logged) == pytest.approx(expected, rel=0.15)
    assert high_frequency_noise([on_rows]) < 0.5 * expected          # the rows lost it
    regridded = Campaign([Run("r", rows, on_rows, np.full(rows.size, 5.0), np.full(rows.size, 60.0))])
    ctx = CampaignContext(regridded, 1.0, 1.0, 1.0, logged_force_noise_n=logged_force_noise_n(logged))
    assert ctx.force_noise_n == pytest.approx(logged_force_noise_n(logged))
    assert CampaignContext(regridded, 1.0, 1.0, 1.0).force_noise_n < 0.5 * expected

