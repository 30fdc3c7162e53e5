"""A torque oscillation whose power follows the inputs (clutch_model/diagnosis/torque_line.py),
on residuals of known make-up: a judder strongest at low slip is found and its frequency
recovered; coloured noise has no line; an interference line whose power does not follow the
clutch is no judder."""
import numpy as np
import pytest

from clutch_model.diagnosis.torque_line import LINE_RATIO, line_check

RATE_HZ = 200.0


def _drive(seed, n_runs=4, duration_s=10.0):
    """Runs of a slip that sweeps between 0.5 and 30 rad/s and a torque of 300-900 N*m."""
    rng = np.random.default_rng(seed)
    t_runs, slips, torques = [], [], []
    for k in range(n_runs):
        t = np.arange(0.0, duration_s, 1.0 / RATE_HZ)
        slip = 15.0 + 14.5 * np.sin(2 * np.pi * t / rng.uniform(3.0, 6.0) + rng.uniform(0, 6))
        torque = 600.0 + 300.0 * np.sin(2 * np.pi * t / rng.uniform(2.0, 4.0) + rng.uniform(0, 6))
        t_runs.append(t + 100.0 * k)
        slips.append(slip)
        torques.append(torque)
    t = np.concatenate(t_runs)
    run_start = np.zeros(t.size, bool)
    run_start[np.cumsum([0] + [x.size for x in t_runs[:-1]])] = True
    run = np.cumsum(run_start) - 1
    test = run == 1
    return rng, t, run_start, run, ~test, test, np.concatenate(slips), np.concatenate(torques)


def _ar1(rng, n, phi, sd):
    e = rng.normal(0.0, sd * np.sqrt(1 - phi ** 2), n)
    out = np.empty(n)
    acc = 0.0
    for k in range(n):
        acc = phi * acc + e[k]
        out[k] = acc
    return out


def _judder(rng, t, run, slip, torque, f_hz=9.8, amp_frac=0.06, slip_scale=8.0):
    phase = rng.uniform(0, 2 * np.pi, run.max() + 1)[run]
    return torque * amp_frac * np.exp(-np.abs(slip) / slip_scale) * np.sin(2 * np.pi * f_hz * t + phase)


def _checked(resid, t, run_start, train, test, slip, torque):
    return line_check(resid, t, run_start, train, test, torque, slip, alpha=1e-3)


@pytest.mark.parametrize("phi", [0.0, 0.93])
def test_a_judder_strongest_at_low_slip_is_a_line_whose_power_the_inputs_predict(phi):
    rng, t, run_start, run, train, test, slip, torque = _drive(3)
    resid = _ar1(rng, t.size, phi, 8.0) + _judder(rng, t, run, slip, torque)
    got = _checked(resid, t, run_start, train, test, slip, torque)
    assert got["frequency_hz"] == pytest.approx(9.8, abs=0.5), got
    assert got["line_ratio"] >= LINE_RATIO
    assert got["envelope_mean_square_cut"] > 0.5 and got["envelope_p"] < 0.05, got
    assert got["took_the_name"], got


@pytest.mark.parametrize("kind", ["white", "ar1", "band10hz"])
def test_coloured_noise_has_no_line(kind):
    from scipy.signal import butter, lfilter

    rng, t, run_start, run, train, test, slip, torque = _drive(4)
    if kind == "white":
        resid = rng.normal(0.0, 8.0, t.size)
    elif kind == "ar1":
        resid = _ar1(rng, t.size, 0.95, 8.0)
    else:
        b, a = butter(2, 10.0 / (RATE_HZ / 2))
        resid = lfilter(b, a, rng.normal(0.0, 20.0, t.size))
    got = _checked(resid, t, run_start, train, test, slip, torque)
    assert got["line_ratio"] < LINE_RATIO / 2, (kind, got)
    assert "envelope_t" not in got and not got["took_the_name"], got


def test_an_interference_line_that_does_not_follow_the_clutch_is_no_judder():
    rng, t, run_start, run, train, test, slip, torque = _drive(5)
    # a constant 12 Hz pick-up of 6 N*m on the torque sensor, its phase per run
    phase = rng.uniform(0, 2 * np.pi, run.max() + 1)[run]
    resid = _ar1(rng, t.size, 0.9, 8.0) + 6.0 * np.sin(2 * np.pi * 12.0 * t + phase)
    got = _checked(resid, t, run_start, train, test, slip, torque)
    assert got["frequency_hz"] == pytest.approx(12.0, abs=0.5) and got["line_ratio"] >= LINE_RATIO, got
    assert "envelope_t" in got
    cut, p = got["envelope_mean_square_cut"], got["envelope_p"]
    assert not (cut > 0.5 and p < 0.05), got
    assert not (cut > 0.2 and p < 1e-3), got
    assert not got["took_the_name"], got
