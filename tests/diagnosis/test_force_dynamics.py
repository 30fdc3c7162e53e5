"""The force paths beyond the catalog (clutch_model/diagnosis/force_dynamics.py): the
second-order force path and the asymmetric lag, the rivals of a named time mechanism, the
play of constant width, the rival of a named hysteresis band, and the force offset."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from clutch_model.diagnosis.force_dynamics import (group_delay_s, offset_force, play_starts_n, played_force,
                                                   second_order_force, time_mechanism_ids)
from clutch_model.diagnosis.lag_rivals import (asymmetric_lagged_force, asymmetric_lagged_torque,
                                               force_dependent_lagged_force)
from clutch_model.plant.mechanisms import make_mechanism
from clutch_model.virtual_car.signals import AR1Noise


def _reference(t, force, f_n, zeta):
    """solve_ivp (tight tolerance) on the force linear between rows, from rest at the first."""
    w = 2 * np.pi * f_n

    def rhs(tt, z):
        return [z[1], w * w * (np.interp(tt, t, force) - z[0]) - 2 * zeta * w * z[1]]
    sol = solve_ivp(rhs, (t[0], t[-1]), [force[0], 0.0], t_eval=t, rtol=1e-10, atol=1e-8, method="DOP853",
                    max_step=float(np.min(np.diff(t))))
    return sol.y[0]


@pytest.mark.parametrize("f_n,zeta", [(2.4, 0.6), (1.0, 2.5), (8.0, 0.3)])
def test_second_order_force_matches_solve_ivp_on_jittered_rows(f_n, zeta):
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.004, 0.016, 700))          # rows on a jittered ~100 Hz clock
    force = 2000 + 1500 * np.sin(2 * np.pi * 0.7 * t) + 800 * (np.sin(2 * np.pi * 0.23 * t) > 0)
    run_start = np.zeros(t.size, bool)
    run_start[0] = True
    got = second_order_force(t, force, run_start, f_n, zeta)
    np.testing.assert_allclose(got, _reference(t, force, f_n, zeta), rtol=0, atol=1e-5 * np.ptp(force))


def test_second_order_force_restarts_each_run_and_keeps_a_held_force():
    t = np.r_[np.arange(0, 5, 0.005), np.arange(0, 5, 0.005)]
    force = np.r_[np.full(1000, 3000.0), np.full(1000, 500.0)]
    force[200:1000] = 6000.0                                 # a step in the first run
    run_start = np.zeros(t.size, bool)
    run_start[[0, 1000]] = True
    got = second_order_force(t, force, run_start, 2.0, 0.7)
    assert got[0] == 3000.0 and got[199] == 3000.0           # at rest at the request
    np.testing.assert_allclose(got[1000:], 500.0)            # the second run starts from its own force
    assert got[999] == pytest.approx(6000.0, rel=1e-6)       # unit gain once settled
    peak = got[200:1000].max()                               # damping 0.7: 4.6 % overshoot of the step
    assert (peak - 6000.0) / 3000.0 == pytest.approx(np.exp(-np.pi * 0.7 / np.sqrt(1 - 0.49)), rel=0.02)


@pytest.mark.parametrize("tau_apply,tau_release", [(0.04, 0.25), (0.2, 0.02), (0.06, 0.06)])
def test_asymmetric_lag_matches_solve_ivp_on_jittered_rows(tau_apply, tau_release):
    """x' = (F - x) / tau, tau = tau_apply while F > x, tau_release while F < x, F linear
    between rows: solve_ivp (tight tolerance, steps no longer than the rows' and the events of
    F crossing x resolved by the small step) against the kernel's exact substeps."""
    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.004, 0.016, 600))
    force = 2000 + 1500 * np.sin(2 * np.pi * 0.7 * t) + 800 * (np.sin(2 * np.pi * 0.23 * t) > 0)
    run_start = np.zeros(t.size, bool)
    run_start[0] = True

    def rhs(tt, x):
        d = np.interp(tt, t, force) - x[0]
        return [d / (tau_apply if d > 0 else tau_release)]
    ref = solve_ivp(rhs, (t[0], t[-1]), [force[0]], t_eval=t, rtol=1e-10, atol=1e-6, method="LSODA",
                    max_step=2e-4).y[0]
    got = asymmetric_lagged_force(t, force, run_start, tau_apply, tau_release)
    # each 0.5 ms substep exact for the linear input; only the switch of tau inside one is not
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-4 * np.ptp(force))
    if tau_apply == tau_release:       # one time constant: the symmetric lag
        sym = asymmetric_lagged_force(t, force, run_start, 0.06, 0.06)
        np.testing.assert_array_equal(got, sym)


@pytest.mark.parametrize("tau_low,tau_high", [(0.01, 0.25), (0.2, 0.03)])
def test_force_dependent_lag_matches_solve_ivp_on_jittered_rows(tau_low, tau_high):
    """x' = (F - x) / tau(x), tau linear in x between f_low and f_high and constant beyond, F
    linear between rows: solve_ivp (tight tolerance) against the kernel's substeps (the
    constant held over each 0.5 ms substep at its middle's x)."""
    rng = np.random.default_rng(9)
    t = np.cumsum(rng.uniform(0.004, 0.016, 600))
    force = 2500 + 2000 * np.sin(2 * np.pi * 0.7 * t) + 800 * (np.sin(2 * np.pi * 0.23 * t) > 0)
    run_start = np.zeros(t.size, bool)
    run_start[0] = True
    f_low, f_high = 1000.0, 4500.0

    def tau(x):
        return tau_low + (tau_high - tau_low) * min(max((x - f_low) / (f_high - f_low), 0.0), 1.0)

    ref = solve_ivp(lambda tt, x: [(np.interp(tt, t, force) - x[0]) / tau(x[0])], (t[0], t[-1]), [force[0]],
                    t_eval=t, rtol=1e-10, atol=1e-6, method="LSODA", max_step=2e-4).y[0]
    got = force_dependent_lagged_force(t, force, run_start, tau_low, tau_high, f_low, f_high)
    np.testing.assert_allclose(got, ref, rtol=0, atol=3e-4 * np.ptp(force))
    # equal constants: the catalog's one lag, whatever the force
    one = force_dependent_lagged_force(t, force, run_start, 0.08, 0.08, f_low, f_high)
    np.testing.assert_allclose(one, asymmetric_lagged_force(t, force, run_start, 0.08, 0.08), rtol=0, atol=1e-9)


@pytest.mark.parametrize("tau_rise,tau_fall", [(0.015, 0.15), (0.12, 0.02)])
def test_asymmetric_sensor_lag_matches_solve_ivp_through_a_sign_change(tau_rise, tau_fall):
    """y' = (T - y) / tau, tau = tau_rise while (T - y) T > 0 (the reading moves away from zero
    toward the torque), tau_fall otherwise, on a torque that changes sign (slip reversals):
    solve_ivp against the kernel; a NaN row (a locked one) is held through."""
    rng = np.random.default_rng(11)
    t = np.cumsum(rng.uniform(0.004, 0.016, 600))
    torque = 250 * np.sin(2 * np.pi * 0.4 * t) + 120 * (np.sin(2 * np.pi * 1.3 * t) > 0)
    run_start = np.zeros(t.size, bool)
    run_start[0] = True

    def rhs(tt, y):
        u = np.interp(tt, t, torque)
        return [(u - y[0]) / (tau_rise if (u - y[0]) * u > 0 else tau_fall)]
    ref = solve_ivp(rhs, (t[0], t[-1]), [torque[0]], t_eval=t, rtol=1e-10, atol=1e-6, method="LSODA",
                    max_step=2e-4).y[0]
    got = asymmetric_lagged_torque(t, torque, run_start, tau_rise, tau_fall)
    np.testing.assert_allclose(got, ref, rtol=0, atol=2e-4 * np.ptp(torque))
    with_gap = torque.copy()
    with_gap[300] = np.nan
    held = asymmetric_lagged_torque(t, with_gap, run_start, tau_rise, tau_fall)
    assert np.isfinite(held).all() and held[300] == held[299]


def test_asymmetric_lag_restarts_each_run_and_settles_at_the_force():
    t = np.r_[np.arange(0, 3, 0.005), np.arange(0, 3, 0.005)]
    force = np.r_[np.full(600, 4000.0), np.full(600, 800.0)]
    force[100:300] = 1000.0                                  # a release, then a re-apply
    run_start = np.zeros(t.size, bool)
    run_start[[0, 600]] = True
    got = asymmetric_lagged_force(t, force, run_start, 0.02, 0.3)
    np.testing.assert_allclose(got[600:], 800.0)             # the second run starts from its own force
    # 0.2 s into the release (tau 0.3 s): 1000 + 3000 exp(-0.2 / 0.3), the input a ramp over one row
    assert got[140] == pytest.approx(1000 + 3000 * np.exp(-(t[140] - t[100]) / 0.3), rel=0.01)
    # re-applied (tau 20 ms): settled at the force within 0.2 s
    assert got[340] == pytest.approx(4000.0, abs=5.0)


def test_time_mechanisms_and_their_group_delay():
    assert time_mechanism_ids(["drag_torque", "transport_delay", "actuator_lag", "torque_offset"]) == \
        ["transport_delay", "actuator_lag"]
    assert time_mechanism_ids(["torque_sensor_lag"]) == ["torque_sensor_lag"]
    mechs = [make_mechanism("transport_delay", delay_s=0.03), make_mechanism("actuator_lag", tau_s=0.05),
             make_mechanism("drag_torque", coeff_nm_per_rad_s=2.0)]
    assert group_delay_s(mechs) == pytest.approx(0.08)


@pytest.mark.parametrize("w", [50.0, 400.0])
def test_played_force_is_the_play_operator_on_a_sine(w):
    """Through a play of half-width w, a sine of amplitude A > w (from its centre) comes out
    with peaks A - w, never further than w from the input, flat for the time the input takes
    to fall 2 w after each peak, and then following it exactly (offset by w)."""
    t = np.arange(0.0, 10.0, 0.001)
    amp, level = 1500.0, 3000.0
    force = level + amp * np.sin(2 * np.pi * 0.5 * t)
    run_start = np.zeros(t.size, bool)
    run_start[0] = True
    got = played_force(force, run_start, w)
    assert np.max(np.abs(got - force)) <= w + 1e-9
    late = t > 2.0                                            # after the first reversal
    assert got[late].max() == pytest.approx(level + amp - w, abs=1e-6)
    assert got[late].min() == pytest.approx(level - amp + w, abs=1e-6)
    # after the peak at t = 2.5 s the output holds until the input has fallen 2 w
    t_release = 2.5 + np.arccos(1 - 2 * w / amp) / (2 * np.pi * 0.5)
    hold = (t > 2.5 + 0.01) & (t < t_release - 0.01)
    np.testing.assert_allclose(got[hold], level + amp - w, atol=1e-9)
    follow = (t > t_release + 0.01) & (t < 3.5 - 0.01)
    np.testing.assert_allclose(got[follow], force[follow] + w, atol=1e-9)


def test_played_force_restarts_each_run_and_a_zero_play_is_the_force():
    rng = np.random.default_rng(4)
    force = 2000 + rng.normal(0, 300, 600)
    run_start = np.zeros(600, bool)
    run_start[[0, 250]] = True
    np.testing.assert_array_equal(played_force(force, run_start, 0.0), force)
    got = played_force(force, run_start, 200.0)
    assert got[0] == force[0] and got[250] == force[250]     # each run centred on its first force
    ref = np.empty_like(force)                               # the play row by row
    for k in range(600):
        ref[k] = force[k] if run_start[k] else min(max(ref[k - 1], force[k] - 200.0), force[k] + 200.0)
    np.testing.assert_array_equal(got, ref)


def test_last_move_direction_follows_the_moves_and_not_a_small_reversal():
    """+1 once the force has risen 2 b, -1 once it has fallen 2 b, held through a reversal
    smaller than 2 b (a sensor's noise), 0 at each run's first row."""
    from clutch_model.diagnosis.force_dynamics import last_move_direction

    force = np.r_[np.linspace(1000, 3000, 201), np.linspace(3000, 2980, 21), np.linspace(2980, 1000, 199),
                  np.linspace(1000, 1500, 51)]
    run_start = np.zeros(force.size, bool)
    run_start[[0, 421]] = True
    d = last_move_direction(force, run_start, 50.0)
    assert d[0] == 0.0 and d[421] == 0.0
    np.testing.assert_allclose(d[20:201], 1.0)               # risen 100 N = 2 b by row 10
    np.testing.assert_allclose(d[201:222], 1.0 - np.arange(21) / 50.0)   # a 20 N dip: still rising
    np.testing.assert_allclose(d[240:421], -1.0)
    np.testing.assert_allclose(d[440:], 1.0)                 # the second run's own rise


def test_a_sensor_play_is_recovered_where_the_mirror_play_is_not():
    """The force sensor reads the pack force through a play of 300 N (the log trails the pack
    force): SensorPlayObjective's path, the log plus w in its last move's direction, fitted on
    noise-free torque gives the play back and cuts the error of the log taken as the pack force
    by more than 90 %; the constant play (the pack force trailing the log) fits its 1 N lower
    bound and leaves most of it."""
    from dataclasses import replace

    from clutch_model.diagnosis.force_dynamics import fit_play, fit_sensor_play
    from clutch_model.formats.bag_reader import Campaign
    from clutch_model.replay import replay_runs
    from .noise_free_campaigns import reference_campaign, with_measured_torque

    model, pack = reference_campaign(3, 4, 6.0)
    torque = replay_runs(model, pack).torque_sim
    logged = with_measured_torque(Campaign([replace(r, applied_force_n=played_force(
        np.asarray(r.applied_force_n, float), np.arange(len(r.applied_force_n)) == 0, 300.0))
        for r, _ in pack.slices()]), torque)
    every = np.ones(pack.t.size, bool)

    def rmse(pred):
        return float(np.sqrt(np.mean((np.asarray(pred) - torque) ** 2)))
    as_logged = rmse(replay_runs(model, logged).torque_sim)
    fit = fit_sensor_play(model, logged, every, [30.0, 150.0, 1000.0], band_n=20.0)
    assert fit.parameters["half_width_n"] == pytest.approx(300.0, rel=0.2)
    assert rmse(fit.predicted) < 0.1 * as_logged
    mirror = fit_play(model, logged, every, [30.0, 150.0, 1000.0])
    assert mirror.parameters["half_width_n"] < 10.0 and rmse(mirror.predicted) > 0.6 * as_logged


def test_play_starts_are_the_named_band_at_the_training_forces():
    force = np.r_[np.full(100, 1000.0), np.full(100, 3000.0), np.full(100, 9000.0)]
    fit = np.ones(300, bool)
    fit[200:] = False                                        # the 9 kN rows are held out
    starts = play_starts_n(0.1, force, fit)
    assert starts == [pytest.approx(100.0), pytest.approx(200.0), pytest.approx(300.0)]


def test_a_force_read_high_is_the_catalog_preload_and_read_low_is_not():
    """offset_force(F, -p) is the pack force of the catalog's spring_preload p run through the
    plant (the same torque), and a sensor reading low gives more force everywhere."""
    from clutch_model.plant.params import load_model
    from clutch_model.plant.simulate import simulate

    t = np.arange(0.0, 4.0, 0.005)
    force = 1500 + 1200 * np.sin(2 * np.pi * 0.6 * t)
    slip, sump = np.full(t.size, 20.0), np.full(t.size, 60.0)
    model = load_model(None)
    preloaded = simulate(model.with_mechanisms([make_mechanism("spring_preload", preload_n=400.0)]),
                         t, force, slip, sump).torque_nm
    read_high = simulate(model, t, offset_force(force, -400.0), slip, sump).torque_nm
    np.testing.assert_allclose(read_high, preloaded, rtol=1e-9, atol=1e-9)
    assert np.all(offset_force(force, 400.0) == force + 400.0)
    assert offset_force(np.array([100.0]), -400.0)[0] == 0.0


# --- the rival's plain error: larger by chance or larger ------------------------------------------

def _ar1(rng, n, phi=0.9, sd=8.0):
    """AR(1) noise of stationary std ``sd``: the virtual car's own noise class."""
    return AR1Noise(sd, phi).sample(rng, np.zeros(n))


def _rows(duration_s=40.0, rate_hz=100.0):
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    run_start = np.zeros(t.size, bool)
    run_start[0] = True
    return t, run_start


def test_plain_worse_test_holds_its_level_under_coloured_noise_and_sees_a_level():
    from clutch_model.diagnosis.structure_test import plain_worse_test

    t, run_start = _rows()
    rows = np.ones(t.size, bool)
    rejected = 0
    for seed in range(200):
        rng = np.random.default_rng(seed)
        # two models equally good: their residuals share the noise and differ by equal misfits
        noise = _ar1(rng, t.size)
        a, b = _ar1(rng, t.size, 0.95, 2.0), _ar1(rng, t.size, 0.95, 2.0)
        rejected += plain_worse_test(noise + a, noise + b, rows, run_start, t).p_value < 0.1
    assert 0.04 <= rejected / 200 <= 0.18                  # a one-sided test at 10 %
    rng = np.random.default_rng(1)
    noise = _ar1(rng, t.size)
    # a level of 5 N*m under AR(1) 0.9 noise of 8 N*m: its square beside the noise's block means
    worse = plain_worse_test(noise, noise + 5.0, rows, run_start, t)
    assert worse.p_value < 1e-3 and worse.t_stat > 0
    assert plain_worse_test(noise + 5.0, noise, rows, run_start, t).t_stat < 0
    assert plain_worse_test(noise, noise + 5.0, rows & (t < 2.0), run_start, t).p_value == 1.0   # < 3 blocks


def test_a_force_path_rival_takes_the_name_when_its_larger_plain_error_is_chance():
    from clutch_model.diagnosis.force_dynamics import PLAIN_WORSE_ALPHA, rival_takes_the_name
    from clutch_model.diagnosis.selection import SelectionData, _compare
    from clutch_model.diagnosis.structure_test import DEFAULT_MAX_ORDER

    t, run_start = _rows(60.0)
    rng = np.random.default_rng(5)
    noise = _ar1(rng, t.size)
    train = (t % 6.0) < 4.0                                  # 2 s of every 6 held out
    data = SelectionData(y=noise, t=t, run_start=run_start, train_mask=train, test_mask=~train)
    # the named model misses a short response at every force edge (what whitening sees) ...
    edges = 6.0 * np.exp(-((t % 0.5) / 0.02))
    r_named = noise + edges
    # ... the rival has it, with a level of its own per 3 s that averages out (what plain squares see)
    wander = np.repeat(rng.choice([-1.0, 1.0], int(np.ceil(t.size / 300))), 300)[:t.size] * 2.5
    r_rival = noise + wander
    head = _compare(data, r_named, r_rival, DEFAULT_MAX_ORDER)
    assert head.t_stat > 4 and head.rmse_alt > head.rmse_null     # innovations for it, plain RMSE against
    takes, worse, plain = rival_takes_the_name(data, head, r_named, r_rival, 1e-3, 0.005)
    assert takes and worse.p_value >= PLAIN_WORSE_ALPHA and plain is None
    # a level that is the rival's own misfit, not chance: refused
    r_rival_level = noise + 2.5
    head = _compare(data, r_named, r_rival_level, DEFAULT_MAX_ORDER)
    takes, worse, _ = rival_takes_the_name(data, head, r_named, r_rival_level, 1e-3, 0.005)
    assert not takes and worse.p_value < PLAIN_WORSE_ALPHA
    # the innovations not won: the plain-squares test instead, which the wandering level fails
    takes, worse, plain = rival_takes_the_name(data, _compare(data, r_rival, r_named, DEFAULT_MAX_ORDER), r_rival,
                                               r_named, 1e-3, 0.005)
    assert not takes and worse is None and plain.cut_frac < 0.2


def test_a_rival_the_innovations_are_blind_to_takes_the_name_by_a_material_plain_cut():
    """A long noise model forecasts a slow misfit from its own past (an AR(48) did on an
    asymmetric torque-sensor lag: innovations at t = 2.5 with the plain mean square cut by half).
    With the innovations short of it, the rival takes the name when it cuts the named model's
    plain held-out mean square materially at the test level over blocks, and not when what it
    changes is noise or a small part of the misfit."""
    from dataclasses import replace

    from clutch_model.diagnosis.force_dynamics import rival_takes_the_name
    from clutch_model.diagnosis.selection import SelectionData, _compare
    from clutch_model.diagnosis.structure_test import DEFAULT_MAX_ORDER, MIN_PLAIN_CUT

    t, run_start = _rows(60.0)
    rng = np.random.default_rng(11)
    noise = _ar1(rng, t.size, phi=0.95)
    train = (t % 6.0) < 4.0
    data = SelectionData(y=noise, t=t, run_start=run_start, train_mask=train, test_mask=~train)
    slow = 10.0 * np.sin(2 * np.pi * 0.4 * t + 1.0)           # what the named model leaves
    cases = {"removes most of it": (noise + slow, noise + 0.2 * slow, True),
             "a noise of its own": (noise, noise + 1.5 * _ar1(rng, t.size, phi=0.95, sd=1.0), False),
             "a tenth of it": (noise + slow, noise + 0.95 * slow, False)}
    for what, (r_named, r_rival, expected) in cases.items():
        head = _compare(data, r_named, r_rival, DEFAULT_MAX_ORDER)
        short = replace(head, t_stat=2.0, p_value=0.03)       # the innovations short of it
        takes, worse, plain = rival_takes_the_name(data, short, r_named, r_rival, 1e-3, 0.005)
        assert worse is None and plain is not None, what
        assert takes is expected, (what, plain)
        assert (plain.cut_frac > MIN_PLAIN_CUT) is expected, (what, plain)
        # expected cut in plain squares: 1 - E r_rival^2 / E r_named^2 on the held-out rows
        rows = ~train
        cut = 1.0 - np.sum(r_rival[rows] ** 2) / np.sum(r_named[rows] ** 2)
        assert plain.cut_frac == pytest.approx(cut, abs=0.02), what


def test_a_rate_limit_binding_on_a_few_rows_is_below_resolution():
    """A slew-rate limit that holds the force off the measured one on a few rows (the steps of
    a force sampled slower than the rows) is not an actuator's slew and never takes the name;
    one that binds on every large edge keeps what its test found."""
    from types import SimpleNamespace

    from clutch_model.diagnosis.force_dynamics import MIN_RATE_LIMIT_BINDING, _unless_rarely_binding

    t, run_start = _rows(40.0, 200.0)
    rng = np.random.default_rng(3)
    # controller-like edges: 4 kN applied and released over 50 ms every 2 s, force noise 5 N
    phase = t % 2.0
    force = 4000.0 * np.clip(np.minimum(phase - 0.5, 1.55 - phase) / 0.05, 0.0, 1.0) + rng.normal(0.0, 5.0, t.size)
    force[np.isin(np.arange(t.size), [1000, 3000, 5000, 7000])] += 1500.0   # a few isolated one-row jumps
    n = t.size
    campaign = SimpleNamespace(t=t, force=force, slip=np.full(n, 10.0), sump=np.full(n, 60.0),
                               run_start=run_start, runs=None)
    before = SimpleNamespace(final=SimpleNamespace(context=SimpleNamespace(force_noise_n=5.0)))
    named = SimpleNamespace(final=before.final, verdict="unexplained")
    train = (t % 6.0) < 4.0
    # 8e4 N/s on 4 kN / 50 ms edges (8e4 N/s): binding on no edge, only the isolated jumps
    sel, found = _unless_rarely_binding(named, before, {"took_the_name": True}, campaign, train, 1.0e5, print)
    assert sel is before and not found["took_the_name"] and found["rarely_binding"]
    assert 0 < found["binding_row_fraction"] < MIN_RATE_LIMIT_BINDING
    # 20 kN/s: every edge takes 0.2 s instead of 50 ms, a tenth of the rows held off
    sel, found = _unless_rarely_binding(named, before, {"took_the_name": True}, campaign, train, 2.0e4, print)
    assert sel is named and found["took_the_name"]
    assert found["binding_row_fraction"] > 10 * MIN_RATE_LIMIT_BINDING


def test_slip_acceleration_matches_a_tight_ode_reference():
    """d/dt of |slip| through a low-pass: (|w| - y) / tau with tau y' = |w| - y, against solve_ivp
    on a slip that crosses zero (|w| has a kink there) and is linear between uneven rows."""
    from clutch_model.diagnosis.slip_acceleration import slip_acceleration

    rng = np.random.default_rng(2)
    t = np.cumsum(rng.uniform(0.003, 0.007, 800))
    t -= t[0]
    slip = 40.0 * np.sin(2 * np.pi * 0.7 * t) + 5.0 * np.sin(2 * np.pi * 3.1 * t)
    run_start = np.zeros(t.size, bool)
    run_start[0] = True
    tau = 0.03
    u = lambda s: abs(np.interp(s, t, slip))      # the input linear between rows, as the kernel takes it
    ref = solve_ivp(lambda s, y: [(u(s) - y[0]) / tau], (t[0], t[-1]), [abs(slip[0])], t_eval=t,
                    rtol=1e-10, atol=1e-10, max_step=5e-4)
    expected = (np.abs(slip) - ref.y[0]) / tau
    got = slip_acceleration(t, slip, run_start, tau)
    scale = np.max(np.abs(expected))
    # |w| is linear between rows except across a zero crossing, where the kernel takes the chord
    crossing = np.zeros(t.size, bool)
    crossing[1:] = np.sign(slip[1:]) != np.sign(slip[:-1])
    settled = ~crossing & (t > 5 * tau)
    assert np.max(np.abs(got - expected)[settled]) < 0.02 * scale
    # a slip speeding up at a constant rate a settles at a after a few tau
    ramp = slip_acceleration(t, 2.0 + 50.0 * t, run_start, tau)
    assert ramp[t > 20 * tau] == pytest.approx(50.0, rel=1e-6)


@pytest.mark.parametrize("tau,ratio", [(0.09, 5.0), (0.03, 4.0)])
def test_led_force_undoes_a_first_order_sensor_lag(tau, ratio):
    """A force sensor lagging the pack force by tau: led_force applied to its log is
    (1 + tau s) / (1 + tau s / ratio) of it, so log and lead together are the pack force
    through a lag of tau / ratio -- each computed by solve_ivp (tight tolerance) on rows of a
    jittered clock, the pack force linear between rows."""
    from clutch_model.diagnosis.force_dynamics import led_force

    rng = np.random.default_rng(11)
    t = np.cumsum(rng.uniform(0.002, 0.006, 2500))          # a ~250 Hz jittered clock
    pack = 2000 + 1500 * np.sin(2 * np.pi * 0.9 * t) + 2500 * (np.sin(2 * np.pi * 0.31 * t) > 0)
    pack = np.convolve(pack, np.ones(25) / 25, mode="same")   # edges some 0.1 s wide
    pack[:13], pack[-13:] = pack[13], pack[-14]

    def lag(x, tc):
        def rhs(tt, z):
            return [(np.interp(tt, t, x) - z[0]) / tc]
        return solve_ivp(rhs, (t[0], t[-1]), [x[0]], t_eval=t, rtol=1e-10, atol=1e-8, method="DOP853",
                         max_step=float(np.min(np.diff(t)))).y[0]
    log = lag(pack, tau)
    run_start = np.zeros(t.size, bool)
    run_start[0] = True
    got = led_force(t, log, run_start, tau, ratio)
    want = lag(pack, tau / ratio)
    assert np.max(np.abs(got - want)) < 5e-3 * np.ptp(pack)
    # the log itself is far off the pack force; the lead brings it close
    assert np.sqrt(np.mean((got - pack) ** 2)) < 0.5 * np.sqrt(np.mean((log - pack) ** 2))


def test_a_force_sensor_lag_is_recovered_where_the_actuator_lag_cannot_go():
    """The force sensor reads the pack force through an 80 ms lag (the pack force leads the
    log): ForceSensorLagObjective fitted on noise-free torque gives the lag back and cuts the
    error of the log taken as the pack force by more than 65 % (the lead is rolled off at five
    times the sensor's corner, so on the steps of these drives some error stays, and the fit
    asks a somewhat longer lag: +30 % here)."""
    from dataclasses import replace

    from clutch_model.diagnosis.force_dynamics import fit_force_sensor_lag
    from clutch_model.formats.bag_reader import Campaign
    from clutch_model.replay import replay_runs
    from .noise_free_campaigns import reference_campaign, with_measured_torque

    model, pack = reference_campaign(4, 4, 6.0)
    torque = replay_runs(model, pack).torque_sim
    runs = []
    for r, _ in pack.slices():
        f = np.asarray(r.applied_force_n, float)
        tt = np.asarray(r.t, float)
        a = np.exp(-np.diff(tt, prepend=tt[0]) / 0.08)
        log = np.empty_like(f)
        log[0] = f[0]
        for k in range(1, f.size):                  # the pack force held between rows, lagged exactly
            log[k] = a[k] * log[k - 1] + (1 - a[k]) * f[k - 1]
        runs.append(replace(r, applied_force_n=log))
    logged = with_measured_torque(Campaign(runs), torque)
    every = np.ones(pack.t.size, bool)

    def rmse(pred):
        return float(np.sqrt(np.mean((np.asarray(pred) - torque) ** 2)))
    as_logged = rmse(replay_runs(model, logged).torque_sim)
    fit = fit_force_sensor_lag(model, logged, every)
    assert 0.07 < fit.parameters["tau_s"] < 0.12
    assert rmse(fit.predicted) < 0.35 * as_logged


def test_a_resonant_torque_sensor_is_recovered_by_the_second_order_reading():
    """The torque read through a second-order sensor at 6 Hz, damping 0.3:
    SecondOrderReadingObjective fitted on the noise-free reading gives the frequency and the
    damping back, and its prediction is within a few per cent of the reading where the plant's
    torque taken as the reading is far off."""
    from clutch_model.diagnosis.force_dynamics import fit_second_order_reading
    from clutch_model.replay import replay_runs
    from .noise_free_campaigns import reference_campaign, with_measured_torque

    model, camp = reference_campaign(5, 4, 6.0)
    plant = np.asarray(replay_runs(model, camp).torque_sim, float)
    t = np.asarray(camp.t, float)
    run_start = np.zeros(t.size, bool)
    for _, sl in camp.slices():
        run_start[sl.start] = True
    reading = second_order_force(t, plant, run_start, 6.0, 0.3)
    measured = with_measured_torque(camp, reading)
    every = np.ones(t.size, bool)

    def rmse(pred):
        return float(np.sqrt(np.mean((np.asarray(pred) - reading) ** 2)))
    fit = fit_second_order_reading(model, measured, every, delay_s=0.02)
    assert fit.parameters["f_n_hz"] == pytest.approx(6.0, rel=0.1)
    assert fit.parameters["damping"] == pytest.approx(0.3, rel=0.2)
    assert rmse(fit.predicted) < 0.1 * rmse(plant)


@pytest.mark.parametrize("f_n,zeta", [(36.7, 1.85), (3.0, 1.2)])
def test_an_overdamped_force_path_is_two_first_order_lags(f_n, zeta):
    """overdamped_poles_s: the second-order path equals two first-order lags in series with the
    time constants it returns (solve_ivp on the lags)."""
    from clutch_model.diagnosis.force_dynamics import overdamped_poles_s

    slow, fast = overdamped_poles_s(f_n, zeta)
    assert slow > fast > 0
    t = np.arange(0.0, 1.5, 0.0005)
    force = 2000 + 1500 * np.sin(2 * np.pi * 1.7 * t) + 800 * (np.sin(2 * np.pi * 0.9 * t) > 0)
    run_start = np.zeros(t.size, bool)
    run_start[0] = True

    def rhs(tt, z):
        return [(np.interp(tt, t, force) - z[0]) / slow, (z[0] - z[1]) / fast]
    ref = solve_ivp(rhs, (t[0], t[-1]), [force[0], force[0]], t_eval=t, rtol=1e-10, atol=1e-8, method="DOP853",
                    max_step=0.0005).y[1]
    np.testing.assert_allclose(second_order_force(t, force, run_start, f_n, zeta), ref, rtol=0, atol=2e-4 * np.ptp(force))
    assert overdamped_poles_s(f_n, 0.7) is None                 # it rings: no first-order pair


def _named_lag(monkeypatch, row_s: float, tau_s: float):
    """(data on 20 s of rows ``row_s`` apart, a selection that named actuator_lag at ``tau_s``),
    force_dynamics.taken_out stubbed to take that lag out of an opaque model."""
    from types import SimpleNamespace

    from clutch_model.diagnosis import force_dynamics as FD

    t = np.arange(0.0, 20.0, row_s)
    run_start = np.zeros(t.size, bool)
    run_start[0] = True
    data = SimpleNamespace(t=t, run_start=run_start, train_mask=np.ones(t.size, bool))
    sel = SimpleNamespace(verdict="named", cause_ids=["actuator_lag"], final=object())
    lag = SimpleNamespace(id="actuator_lag", values={"tau_s": tau_s})
    monkeypatch.setattr(FD, "taken_out", lambda final, ids: ([lag], object(), 1.0))
    return data, sel


def test_a_force_path_whose_fast_pole_is_below_the_row_resolution_does_not_take_the_name(monkeypatch):
    """A named actuator lag met by an overdamped rival whose second pole (1.3 ms) is shorter than
    half the 8 ms rows: the rival is the lag itself with a sub-row timing term, and the named lag
    stands without a head-to-head (which it lost at t = 15.4 on an outside generator's campaign)."""
    from types import SimpleNamespace

    from clutch_model.diagnosis import force_dynamics as FD

    data, sel = _named_lag(monkeypatch, 0.008, 0.015)

    def fitted(f_n, zeta):
        return lambda *a, **k: SimpleNamespace(parameters={"f_n_hz": f_n, "damping": zeta})

    def head_to_head(*a, **k):
        return "compared", {"took_the_name": True}
    monkeypatch.setattr(FD, "_rival_in_place", head_to_head)
    monkeypatch.setattr(FD, "_second_pole_on_the_sensor", lambda *a, **k: {"path_told_apart": True})

    monkeypatch.setattr(FD, "fit_second_order", fitted(36.7, 1.85))
    kept, found = FD.named_or_force_dynamics(data, sel, None, 1.0, 1e-3, 0.005)
    assert kept is sel and found["fast_pole_below_resolution"] and not found["took_the_name"]
    assert found["pole_time_constants_s"][1] == pytest.approx(1.27e-3, rel=0.01)
    # a pole the rows resolve (8 Hz at 1.5: 52 and 7.6 ms) or a ringing path meets the named lag
    for f_n, zeta in ((8.0, 1.5), (5.0, 0.6)):
        monkeypatch.setattr(FD, "fit_second_order", fitted(f_n, zeta))
        assert FD.named_or_force_dynamics(data, sel, None, 1.0, 1e-3, 0.005)[0] == "compared"


def test_an_overdamped_path_not_told_from_a_sensor_pole_beside_the_lag_does_not_take_the_name(monkeypatch):
    """A named actuator lag beaten by an overdamped force path whose fast pole the rows resolve
    (10.5 Hz at 2.31: 66 and 3.5 ms): the path takes the name only when it is told from the lag
    with one more pole on the torque reading; a ringing path never meets that check."""
    from types import SimpleNamespace

    from clutch_model.diagnosis import force_dynamics as FD

    data, sel = _named_lag(monkeypatch, 0.002, 0.07)
    monkeypatch.setattr(FD, "_rival_in_place", lambda *a, **k: ("unexplained", {"took_the_name": True}))
    asked = []

    def sensor(told):
        def check(data, base, campaign, fit, poles, *a):
            asked.append(poles)
            return {"path_told_apart": told}
        return check

    for f_n, zeta, told, taken in ((10.5, 2.31, False, False), (10.5, 2.31, True, True), (5.0, 0.6, False, True)):
        monkeypatch.setattr(FD, "fit_second_order",
                            lambda *a, f_n=f_n, zeta=zeta, **k: SimpleNamespace(parameters={"f_n_hz": f_n,
                                                                                           "damping": zeta}))
        monkeypatch.setattr(FD, "_second_pole_on_the_sensor", sensor(told))
        out, found = FD.named_or_force_dynamics(data, sel, None, 1.0, 1e-3, 0.005)
        assert found["took_the_name"] is taken and (out == "unexplained") is taken, (f_n, zeta, told)
    assert len(asked) == 2
    assert asked[0][0] == pytest.approx(0.066, rel=0.02) and asked[0][1] == pytest.approx(3.5e-3, rel=0.05)


def _plant_torque(model, camp, force_delay_s=0.0):
    """The model's torque on the campaign, its force ``force_delay_s`` late."""
    from dataclasses import replace

    from clutch_model.formats.bag_reader import Campaign
    from clutch_model.plant.mechanisms import delay_signal
    from clutch_model.replay import replay_runs

    if force_delay_s:
        runs = []
        for r, _ in camp.slices():
            t = np.asarray(r.t, float)
            start = np.zeros(t.size, bool)
            start[0] = True
            runs.append(replace(r, applied_force_n=delay_signal(t, r.applied_force_n, start, force_delay_s)))
        camp = Campaign(runs)
    return np.asarray(replay_runs(model, camp).torque_sim, float)


def _read_late(camp, torque, delay_s):
    """The contract's transport delay: the torque at t - delay, linear, its first value before."""
    out = np.empty_like(torque)
    for _, sl in camp.slices():
        t = np.asarray(camp.t, float)[sl]
        out[sl] = np.interp(t - delay_s, t, torque[sl])
    return out


def test_a_force_delay_and_a_transport_delay_are_told_apart():
    """A pure delay on the force (the slip and the reading on time) and the catalog's transport
    delay (the whole torque read late) are not the same mechanism: on noise-free torque made
    by either, the force-delay rival (ForceDelayObjective, friction correction refitted) gives
    a 25 ms force delay back exactly, where the best transport delay on a 1 ms grid leaves
    1.1 N*m (of a 44 N*m effect: these runs always slip, where the two differ least); on a
    25 ms transport delay, which the catalog reproduces exactly, the rival leaves 1.0 N*m."""
    from clutch_model.diagnosis.lag_rivals import RIVALS
    from .noise_free_campaigns import reference_campaign, with_measured_torque

    model, camp = reference_campaign(6, 4, 6.0)
    every = np.ones(camp.t.size, bool)
    rival = next(r for r in RIVALS if r.key == "force_delay")

    def rmse(pred, want):
        return float(np.sqrt(np.mean((np.asarray(pred) - want) ** 2)))
    plant = _plant_torque(model, camp)
    # a true force delay
    forced = _plant_torque(model, camp, 0.025)
    fit = rival.fit(model, with_measured_torque(camp, forced), every, 0.02, 1.0)
    assert fit.parameters["delay_s"] == pytest.approx(0.025, rel=0.05)
    best_transport = min(rmse(_read_late(camp, plant, d), forced) for d in np.arange(0.0, 0.06, 1e-3))
    assert rmse(fit.predicted, forced) < 0.2 * best_transport
    # a true transport delay
    late = _read_late(camp, plant, 0.025)
    fit = rival.fit(model, with_measured_torque(camp, late), every, 0.025, 1.0)
    run_start = np.zeros(camp.t.size, bool)
    for _, sl in camp.slices():
        run_start[sl.start] = True
    catalog = make_mechanism("transport_delay", delay_s=0.025).apply_to_measurement(camp.t, plant, run_start)
    assert rmse(catalog, late) < 1e-9
    assert rmse(fit.predicted, late) > 0.5


def _force_through(camp, lag):
    """The campaign with each run's force passed through ``lag(t, force, sump, run_start)``."""
    from dataclasses import replace

    from clutch_model.formats.bag_reader import Campaign

    runs = []
    for r, _ in camp.slices():
        t = np.asarray(r.t, float)
        start = np.zeros(t.size, bool)
        start[0] = True
        runs.append(replace(r, applied_force_n=lag(t, np.asarray(r.applied_force_n, float),
                                                   np.asarray(r.sump_temperature_c, float), start)))
    return Campaign(runs)


def test_oil_temperature_lag_matches_solve_ivp_as_the_oil_warms():
    """x' = (F - x) / tau(theta(t)), log tau linear in the sump temperature between theta_cold
    and theta_hot and constant beyond, the oil warming from 0 to 90 C through the run: solve_ivp
    (tight tolerance, theta and F linear between rows) against the kernel, which holds each
    row interval's constant at its middle temperature."""
    from clutch_model.diagnosis.lag_rivals import oil_temperature_lagged_force

    rng = np.random.default_rng(4)
    t = np.cumsum(rng.uniform(0.004, 0.012, 900))
    force = 2500 + 2000 * np.sin(2 * np.pi * 0.9 * t) + 900 * (np.sin(2 * np.pi * 0.31 * t) > 0)
    sump = np.linspace(0.0, 90.0, t.size)
    run_start = np.zeros(t.size, bool)
    run_start[0] = True
    cold, hot, th_cold, th_hot = 0.15, 0.02, 15.0, 75.0

    def tau(tt):
        share = min(max((np.interp(tt, t, sump) - th_cold) / (th_hot - th_cold), 0.0), 1.0)
        return cold * (hot / cold) ** share

    ref = solve_ivp(lambda tt, x: [(np.interp(tt, t, force) - x[0]) / tau(tt)], (t[0], t[-1]), [force[0]],
                    t_eval=t, rtol=1e-10, atol=1e-6, method="LSODA", max_step=2e-4).y[0]
    got = oil_temperature_lagged_force(t, force, sump, run_start, cold, hot, th_cold, th_hot)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-3 * np.ptp(force))
    # equal constants: the catalog's one lag, whatever the temperature
    one = oil_temperature_lagged_force(t, force, sump, run_start, 0.07, 0.07, th_cold, th_hot)
    np.testing.assert_allclose(one, asymmetric_lagged_force(t, force, run_start, 0.07, 0.07), rtol=0, atol=1e-9)


def test_an_oil_temperature_lag_is_recovered_and_one_lag_is_its_special_case():
    """The oil-temperature rival (OilTemperatureLagObjective, friction correction refitted) on
    noise-free torque of runs at sump temperatures from 30 to 90 C: a lag of 120 ms in the
    coldest oil and 25 ms in the hottest comes back within 5 %; on one catalog lag of 50 ms
    its two constants come back within the 1.5x that is the catalog's one lag. A campaign at
    one sump temperature is not checked: nothing tells the two constants apart."""
    from clutch_model.diagnosis.lag_rivals import (MIN_SUMP_SPAN_K, RIVALS, oil_temperature_lagged_force,
                                                   training_sump_span_c)
    from .noise_free_campaigns import reference_campaign, with_measured_torque

    model, camp = reference_campaign(7, 6, 4.0)
    every = np.ones(camp.t.size, bool)
    lo, hi = training_sump_span_c(camp, every)
    assert hi - lo > 2 * MIN_SUMP_SPAN_K
    rival = next(r for r in RIVALS if r.key == "oil_temperature_lag")
    assert rival.not_told(camp, every) is None
    truth = _plant_torque(model, _force_through(
        camp, lambda t, f, th, s: oil_temperature_lagged_force(t, f, th, s, 0.12, 0.025, lo, hi)))
    fit = rival.fit(model, with_measured_torque(camp, truth), every, 0.05, 1.0)
    assert fit.parameters["tau_cold_s"] == pytest.approx(0.12, rel=0.05)
    assert fit.parameters["tau_hot_s"] == pytest.approx(0.025, rel=0.05)
    assert fit.parameters["sump_cold_c"] == lo and fit.parameters["sump_hot_c"] == hi
    one = _plant_torque(model, _force_through(camp, lambda t, f, th, s: asymmetric_lagged_force(t, f, s, 0.05, 0.05)))
    fit = rival.fit(model, with_measured_torque(camp, one), every, 0.05, 1.0)
    assert rival.asymmetry_ratio(fit) < 1.5
    assert fit.parameters["tau_cold_s"] == pytest.approx(0.05, rel=0.1)
    # one sump temperature: the rival is not fitted
    from dataclasses import replace

    from clutch_model.formats.bag_reader import Campaign
    flat = Campaign([replace(r, sump_temperature_c=np.full(len(r), 60.0)) for r, _ in camp.slices()])
    assert "not told from one lag" in rival.not_told(flat, every)


class _Fitted:
    """A fitted model standing in for candidates.ModelFit: its prediction on every row, its
    parameters, and the Jacobian of the prediction in one parameter (for the interval)."""

    def __init__(self, predicted, parameters, slope=None):
        self.predicted, self.parameters, self._slope = np.asarray(predicted, float), dict(parameters), slope

    def predict(self, data):
        return self.predicted

    def sensitivity(self):
        from clutch_model.diagnosis.selection import ParameterSensitivity
        if self._slope is None:
            return None
        name, value = next(iter(self.parameters.items()))
        return ParameterSensitivity([name], np.array([value]), np.asarray(self._slope, float)[:, None],
                                    [lambda x: x])


def test_a_force_read_high_that_takes_the_name_is_the_catalog_preload():
    """Where nothing is named, a signed force offset that takes the name reading the force high
    is the catalog's spring_preload: the selection's own preload candidate is named when it
    matches the offset and beats the calibrated model as the offset did (in the innovations, or
    by halving the plain held-out mean square over blocks), with an interval from its
    sensitivity; a preload candidate that does not match the offset, or that leaves the whole
    misfit, is not named and the verdict stays the offset's."""
    from clutch_model.diagnosis.force_dynamics import _read_high_is_the_preload
    from clutch_model.diagnosis.selection import CandidateScore, Selection, SelectionData, SelectionStep

    t, run_start = _rows(60.0)
    rng = np.random.default_rng(3)
    noise = _ar1(rng, t.size, phi=0.95, sd=1.0)
    misfit = 8.0 * np.sin(2 * np.pi * 0.3 * t) + 4.0        # what the calibration leaves of a preload
    truth = 100.0 + 20.0 * np.sin(2 * np.pi * 0.7 * t)
    y = truth + misfit + noise
    train = (t % 6.0) < 4.0
    data = SelectionData(y=y, t=t, run_start=run_start, train_mask=train, test_mask=~train)
    calibrated = _Fitted(truth, {})

    def selection(preload_n, leaves):
        fitted = _Fitted(truth + (1.0 - leaves) * misfit, {"preload_n": preload_n}, slope=misfit / preload_n)
        score = CandidateScore.__new__(CandidateScore)
        score.id, score.fitted = "spring_preload", fitted
        step = SelectionStep(scores=[score], chosen=None, lookalikes=[])
        return Selection("none", [], [step], calibrated, None, None, [], {}, "nothing predicts it")

    found = {"took_the_name": True}
    named = _read_high_is_the_preload(data, selection(380.0, 0.0), found, 370.0, 1e-3, 0.005, lambda m: None)
    assert named is not None and named.verdict == "named" and named.cause_ids == ["spring_preload"]
    assert named.causes[0].parameters == {"preload_n": 380.0}
    lo, hi = named.causes[0].parameters_ci95["preload_n"]
    assert lo < 380.0 < hi
    assert found["catalog_preload"]["named"] and found["catalog_equivalent"] == "spring_preload"
    assert not found["took_the_name"]            # the offset did not take it: the catalog's preload did
    # a candidate far from the offset, or one that leaves the whole misfit: the offset's verdict stands
    for preload_n, leaves in ((120.0, 0.0), (380.0, 1.0)):
        found = {"took_the_name": True}
        assert _read_high_is_the_preload(data, selection(preload_n, leaves), found, 370.0, 1e-3, 0.005,
                                         lambda m: None) is None
        assert found["took_the_name"] and not found["catalog_preload"]["named"]


def test_one_more_sensor_pole_is_recovered_on_top_of_a_named_sensor_lag():
    """SensorPoleObjective (friction correction refitted): on noise-free torque read through the
    catalog's 34 ms torque_sensor_lag and one more 5 ms pole, the model with the sensor lag gets
    the 5 ms pole back within 10 %, and the pole's torque is the truth's."""
    from clutch_model.diagnosis.lag_rivals import SensorPoleObjective, _fit_from_best_start
    from clutch_model.plant.mechanisms import make_mechanism
    from .noise_free_campaigns import reference_campaign, with_measured_torque

    model, camp = reference_campaign(5, 4, 5.0, rate_hz=400.0)
    run_start = np.zeros(camp.t.size, bool)
    for _, sl in camp.slices():
        run_start[sl.start] = True
    sensor = make_mechanism("torque_sensor_lag", tau_s=0.034)
    lagged = sensor.apply_to_measurement(camp.t, _plant_torque(model, camp), run_start)
    truth = asymmetric_lagged_torque(np.asarray(camp.t, float), lagged, run_start, 0.005, 0.005)
    base = model.with_mechanisms([sensor])
    obj = SensorPoleObjective(base, with_measured_torque(camp, truth), np.ones(camp.t.size, bool), 0.01)
    fit = _fit_from_best_start(obj, [[np.log(0.01 * r)] for r in (0.5, 1.0, 2.0)], 40, "sensor_pole")
    assert fit.parameters["tau_s"] == pytest.approx(0.005, rel=0.1)
    assert np.sqrt(np.mean((fit.predicted - truth) ** 2)) < 0.05 * np.std(truth - lagged) + 1e-6


def test_an_actuator_lag_and_a_sensor_pole_are_recovered_together():
    """LagAndSensorPoleObjective (friction correction refitted): on noise-free torque from the
    plant with the catalog's 60 ms actuator_lag, read through one more 3 ms pole (scipy.signal's
    first-order system, each run from rest at its first value), both time constants come back
    within 10 % from the path's rough split, and the torque is the truth's."""
    from scipy import signal

    from clutch_model.diagnosis.lag_rivals import fit_lag_and_sensor_pole
    from clutch_model.plant.mechanisms import make_mechanism
    from .noise_free_campaigns import reference_campaign, with_measured_torque

    model, camp = reference_campaign(5, 4, 5.0, rate_hz=400.0)
    t = np.asarray(camp.t, float)
    plant = _plant_torque(model.with_mechanisms([make_mechanism("actuator_lag", tau_s=0.06)]), camp)
    pole = signal.lti([1.0], [0.003, 1.0])
    truth = np.empty_like(plant)
    for _, sl in camp.slices():
        u = plant[sl]
        truth[sl] = u[0] + signal.lsim(pole, u - u[0], t[sl] - t[sl][0])[1]
    fit = fit_lag_and_sensor_pole(model, with_measured_torque(camp, truth), np.ones(t.size, bool), 0.055, 0.006)
    assert fit.parameters["tau_s"] == pytest.approx(0.06, rel=0.1)
    assert fit.parameters["sensor_tau_s"] == pytest.approx(0.003, rel=0.1)
    assert np.sqrt(np.mean((fit.predicted - truth) ** 2)) < 0.05 * np.std(truth - plant) + 1e-6


def test_a_pair_is_told_from_a_sensor_pole_only_when_it_predicts_better():
    """The named pair (actuator_lag beside a measurement lag) against one more sensor pole in
    the actuator lag's place: a pair that removes a misfit the pole leaves is told apart; a pair
    no better than the pole (the same residual and its own noise) is not."""
    from clutch_model.diagnosis.selection import SelectionData, predicts_better

    t, run_start = _rows(60.0)
    rng = np.random.default_rng(8)
    noise = _ar1(rng, t.size, phi=0.9, sd=1.0)
    train = (t % 6.0) < 4.0
    data = SelectionData(y=noise, t=t, run_start=run_start, train_mask=train, test_mask=~train)
    edges = 3.0 * np.exp(-((t % 0.5) / 0.03))                  # force edges the pole cannot follow
    told, head, _ = predicts_better(data, noise, noise + edges, 1e-3, 0.005)
    assert told and head.rmse_alt < head.rmse_null
    told, _, plain = predicts_better(data, noise + 0.1 * _ar1(rng, t.size, phi=0.9, sd=1.0), noise, 1e-3, 0.005)
    assert not told and plain.cut_frac < 0.005
