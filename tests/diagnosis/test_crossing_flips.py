"""The measured torque's flip times a slip zero crossing: a slip reading that logs the crossing
late (a wheel encoder counting over a window) gets the crossing's window widened back to the
flip; a torque that flips late (a sensor lag) leaves the window as the slip made it."""
import numpy as np

from clutch_model.diagnosis.lockup import campaign_lockup, with_torque_flips, without_locked_torque
from clutch_model.formats.bag_reader import Campaign, Run

TRUE_CROSSINGS = np.arange(2.0, 20.0, 2.0)        # 5 sin(2 pi 0.25 t): a crossing every 2 s


def windowed(t_fine, y_fine, window_s):
    """What an encoder counting over the last ``window_s`` reads: the mean over that window."""
    c = np.concatenate([[0.0], np.cumsum(y_fine)])
    k = int(round(window_s / (t_fine[1] - t_fine[0])))
    i = np.arange(y_fine.size)
    return (c[i + 1] - c[np.maximum(i + 1 - k, 0)]) / np.minimum(i + 1, k)


def lagged(t_fine, y_fine, tau_s):
    """A first-order sensor lag, exact for a piecewise-constant input."""
    a = np.exp(-(t_fine[1] - t_fine[0]) / tau_s)
    out = np.empty_like(y_fine)
    acc = y_fine[0]
    for j, v in enumerate(y_fine):
        acc = a * acc + (1 - a) * v
        out[j] = acc
    return out


def run_of(seed, slip_window_s=0.0, torque_lag_s=0.0):
    """One 20 s run: slip 5 sin(2 pi 0.25 t) logged at 200 Hz (jittered), the clutch torque
    600 sign(slip) N*m (+ 0.05 slip) logged at 500 Hz with 2 N*m of noise, force at 250 Hz."""
    rng = np.random.default_rng(seed)
    tf = np.arange(0.0, 20.0, 1e-4)                         # the truth, at 10 kHz
    slip = 5 * np.sin(2 * np.pi * 0.25 * tf)
    torque = 600.0 * np.sign(slip) + 0.05 * slip
    slip_read = windowed(tf, slip, slip_window_s) if slip_window_s else slip
    torque_read = lagged(tf, torque, torque_lag_s) if torque_lag_s else torque
    ts = np.sort(np.arange(0.0, 20.0, 0.005) + rng.uniform(0, 0.001, 4000))
    tt = np.sort(np.arange(0.0, 20.0, 0.002) + rng.uniform(0, 0.0005, 10000))
    ws = np.interp(ts, tf, slip_read) + rng.normal(0, 0.02, ts.size)
    yt = np.interp(tt, tf, torque_read) + rng.normal(0, 2.0, tt.size)
    t = np.arange(0.0, 20.0, 0.004)
    samples = {"applied_force": (t, np.full(t.size, 4000.0)), "slip_speed": (ts, ws),
               "sump_temperature": (t, np.full(t.size, 60.0)), "measured_torque": (tt, yt)}
    grid = lambda tt_, v: v[np.clip(np.searchsorted(tt_, t, side="right") - 1, 0, None)]
    return Run(name=f"r{seed}", t=t, applied_force_n=np.full(t.size, 4000.0), slip_speed_rad_s=grid(ts, ws),
               sump_temperature_c=np.full(t.size, 60.0), torque_measured_nm=grid(tt, yt), samples=samples)


def test_a_slip_logged_late_is_measured_at_the_flips_and_its_crossings_widened_back():
    window = 0.08                                             # the slip reads 40 ms late
    campaign = Campaign([run_of(1, slip_window_s=window), run_of(2, slip_window_s=window)])
    plain = campaign_lockup(campaign)
    results = campaign_lockup(campaign)
    lead = with_torque_flips(results, campaign)
    assert abs(lead - window / 2) < 0.006
    measured = [x for r in results for x in r.crossing_leads_s if x is not None]
    assert len(measured) >= 2 * TRUE_CROSSINGS.size - 2
    for before, after in zip(plain, results):
        assert len(after.crossings) == len(before.crossings)
        for (a0, b0), (a1, b1) in zip(before.crossings, after.crossings):
            assert b1 == b0 and a0 - a1 >= lead - 1e-12
        # every true crossing, the instant the torque flips, now lies in a window
        for tc in TRUE_CROSSINGS:
            assert any(a + 0.003 <= tc <= b for a, b in after.crossings), tc
            assert not any(a <= tc <= b for a, b in before.crossings), tc
    # independently of the windows: every row still compared has the logged slip's sign where
    # the measured torque is well away from zero, so a model given that slip flips with it
    unlocked, _ = without_locked_torque(campaign)
    for run in unlocked.runs:
        y = run.torque_measured_nm
        kept = np.isfinite(y) & (np.abs(y) > 50) & (run.t > 0.1)    # the run starts at a crossing
        assert kept.sum() > 0.9 * np.isfinite(y).sum() - 50
        assert np.all(np.sign(run.slip_speed_rad_s[kept]) == np.sign(y[kept]))
    # and without the flips the same rows are not: the late slip has the wrong sign on rows at every crossing
    for run, res in zip(campaign.runs, plain):
        y = run.torque_measured_nm
        kept = ~res.excluded_at(run.t, 0.1) & (np.abs(y) > 50) & (run.t > 0.1)
        assert np.sum(np.sign(run.slip_speed_rad_s[kept]) != np.sign(y[kept])) > 2 * TRUE_CROSSINGS.size


def test_a_torque_that_flips_late_leaves_the_crossings_as_the_slip_made_them():
    campaign = Campaign([run_of(3, torque_lag_s=0.02), run_of(4, torque_lag_s=0.02)])
    plain = campaign_lockup(campaign)
    results = campaign_lockup(campaign)
    assert with_torque_flips(results, campaign) == 0.0
    measured = [x for r in results for x in r.crossing_leads_s if x is not None]
    assert len(measured) >= 2 * TRUE_CROSSINGS.size - 2
    assert np.median(measured) < -0.01                        # ln 2 x 20 ms after the slip
    assert [r.crossings for r in results] == [r.crossings for r in plain]


def test_no_flip_under_load_measures_nothing():
    """A torque within a few noise sds of zero across the crossings (the clutch open: 6 N*m of
    drag against 2 N*m of noise) times none of them."""
    campaign = Campaign([run_of(5, slip_window_s=0.08)])
    run = campaign.runs[0]
    tt, yt = run.samples["measured_torque"]
    run.samples["measured_torque"] = (tt, yt * 0.01 + np.random.default_rng(6).normal(0, 2.0, tt.size))
    results = campaign_lockup(campaign)
    assert with_torque_flips(results, campaign) == 0.0
    assert all(x is None for x in results[0].crossing_leads_s)
