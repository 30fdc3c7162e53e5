"""Lock-up found from noisy slip data; the model compared where the measurement is."""
import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from clutch_model.diagnosis.lockup import detect_lockup, detect_lockup_run
from clutch_model.diagnosis.measured_time import (at_measured_times, choose_plant_grid, interpolate_on_grid,
                                                  replay_at_measured_times, simulate_at_measured_times)
from clutch_model.formats.bag_reader import Campaign
from clutch_model.plant import kernels as K
from clutch_model.plant.params import load_model
from clutch_model.plant.simulate import simulate
from clutch_model.virtual_car.car_logs import load_truth_sidecar
from clutch_model.virtual_car.signals import make_noise
from tests.virtual_car.conftest import make_campaign


def sidecar(paths, name):
    return load_truth_sidecar(Path(paths["truth"]).parent / "truth" / f"{name}.npz")


def precision_recall(paths, runs, **options):
    tp = fp = fn = 0
    for run in runs:
        side = sidecar(paths, run.name)
        det = detect_lockup_run(run, **options).at(side["slip_t_s"])
        true = side["slip_locked"]
        tp += int(np.sum(det & true)); fp += int(np.sum(det & ~true)); fn += int(np.sum(~det & true))
    return tp / max(tp + fp, 1), tp / max(tp + fn, 1), tp + fn


def test_kernel_lock_reports_static_capacity_with_last_sign(tmp_path):
    """Lock-up (docs/model.md): |slip| < lock tolerance -> static capacity (asperity torque with
    mu_f at w = 0, no hydrodynamic part), sign of the last slip above the tolerance."""
    model = load_model(None)
    t = np.arange(0, 2.0, 0.005)
    slip = np.where(t < 1.0, -3.0, 0.0)
    force = np.full(t.size, 5000.0)
    sim = simulate(model, t, force, slip, 60.0)
    locked = t >= 1.0
    np.testing.assert_array_equal(sim.locked, locked)
    p = model.vector()
    mu0 = np.array([K.friction_coefficient(0.0, pr, th, p) for pr, th in
                    zip(sim.pressure_mpa[locked], sim.pack_temperature_c[locked])])
    np.testing.assert_allclose(sim.friction_coefficient[locked], mu0, rtol=1e-12)
    assert np.all(sim.hydrodynamic_torque_nm[locked] == 0)
    assert np.all(sim.torque_nm[locked] < 0)                     # sign of the last slip (-3)
    np.testing.assert_allclose(sim.torque_nm[locked], sim.asperity_torque_nm[locked])
    # and replay writes the contract's locked column
    from clutch_model.formats.bag_writer import write_run_bag
    from clutch_sim.cli import main
    write_run_bag(tmp_path / "b", {"applied_force": (t, force), "slip_speed": (t, slip),
                                   "sump_temperature": (t, np.full(t.size, 60.0))})
    assert main(["replay", "--bag", str(tmp_path / "b"), "--out", str(tmp_path / "o.csv")]) == 0
    rows = list(csv.DictReader((tmp_path / "o.csv").open()))
    np.testing.assert_array_equal([int(r["locked"]) for r in rows], locked.astype(int))


def test_lock_detection_on_car_logs(short_campaign):
    _, paths, runs = short_campaign
    prec, rec, n = precision_recall(paths, runs)
    assert n > 300
    assert prec >= 0.85 and rec >= 0.95, (prec, rec)
    # the noise estimate is the slip sensor's (0.05 rad/s white)
    sig = [detect_lockup_run(r).noise_sigma_rad_s for r in runs]
    assert np.allclose(sig, 0.05, rtol=0.25)


def test_lock_detection_coloured_slip_noise_long_runs(tmp_path_factory):
    _, paths, runs = make_campaign(tmp_path_factory, "lock_ar1", seed=31, schedule="few-long",
                                   run_duration_s=40.0,
                                   noise={"slip_speed": make_noise("ar1", 0.08, phi=0.9)})
    prec, rec, n = precision_recall(paths, runs)
    assert n > 300
    assert prec >= 0.85 and rec >= 0.95, (prec, rec)
    sig = [detect_lockup_run(r).noise_sigma_rad_s for r in runs]
    assert np.allclose(sig, 0.08, rtol=0.3)     # full std, though differences see ~0.45 of it


def test_no_lock_where_there_is_none(tmp_path_factory):
    _, paths, runs = make_campaign(tmp_path_factory, "nolock", seed=32, n_runs=3, lockup=False)
    for run in runs:
        assert detect_lockup_run(run).mask.mean() < 0.005
    # a slipping clutch crossing zero quickly is not locked
    rng = np.random.default_rng(0)
    t = np.arange(0, 20, 0.01)
    w = 5 * np.sin(2 * np.pi * 0.5 * t) + rng.normal(0, 0.05, t.size)
    assert not detect_lockup(t, w).mask.any()


def test_lock_detection_on_a_slip_logged_in_coarse_steps():
    """A slip logged in 0.01 rad/s steps whose noise while locked (0.004 rad/s) is below one
    step reads a locked clutch as exact zeros with a stray +-0.01: the noise estimate must not
    collapse to nothing (every stray step would then break the lock). The lock phases are found
    as on a continuous slip; slipping stays slipping."""
    from clutch_model.diagnosis.lockup import slip_quantum

    rng = np.random.default_rng(7)
    t = np.arange(0, 20, 0.01)                                    # slip at 100 Hz
    locked = ((t > 5) & (t < 8)) | ((t > 12) & (t < 15.5))
    slipping = 6 + 3 * np.sin(2 * np.pi * 0.3 * t) + rng.normal(0, 0.1, t.size)
    w = np.round(np.where(locked, rng.normal(0, 0.004, t.size), slipping) / 0.01) * 0.01
    assert abs(slip_quantum(w) - 0.01) < 1e-9
    assert slip_quantum(np.where(locked, rng.normal(0, 0.004, t.size), slipping)) == 0.0   # continuous
    det = detect_lockup(t, w)
    found = det.at(t)
    assert found[locked].mean() > 0.95
    assert not found[~locked & (np.abs(t - 8) > 0.1) & (np.abs(t - 12) > 0.1)
                     & (np.abs(t - 5) > 0.1) & (np.abs(t - 15.5) > 0.1)].any()
    assert len(det.segments) == 2
    # and a continuous slip with the same noise gives the same phases
    cont = detect_lockup(t, np.where(locked, rng.normal(0, 0.004, t.size), slipping))
    assert len(cont.segments) == 2


def test_zero_crossings_of_a_slipping_clutch_are_found_and_left_out():
    """A slip crossing zero while slipping is no lock, but the samples around each crossing are
    rows the model is not compared on (the torque flips sign there within ms; the sampled slip
    times the flip only to a sample and to its noise over its slope): each true crossing lies
    in one found span, a few slip samples wide; none is found where the slip keeps its sign or
    inside a lock phase."""
    rng = np.random.default_rng(3)
    t = np.arange(0, 20, 0.008)                                   # slip at 125 Hz
    true = 5 * np.sin(2 * np.pi * 0.25 * t)                        # crossings every 2 s
    w = true + rng.normal(0, 0.06, t.size)
    det = detect_lockup(t, w)
    assert not det.mask.any()
    t_cross = np.arange(2.0, 20.0, 2.0)
    assert len(det.crossings) >= t_cross.size
    for tc in t_cross:
        near = [c for c in det.crossings if c[0] - 0.03 <= tc <= c[1] + 0.03]
        assert near, tc
    assert all(any(abs(0.5 * (a + b) - tc) < 0.05 for tc in t_cross) for a, b in det.crossings)
    # only the samples around the flip, whatever the lock pad: the bracketing slip samples, one
    # more on each side, and 3 noise sds over the slope (here 3 x 0.06 / 7.9 = 23 ms)
    excluded = det.excluded_at(t, pad_s=0.2)
    assert excluded[np.abs(t - 4.0) < 0.02].all()
    assert not excluded[(np.abs(t - 4.0) > 0.06) & (np.abs(t - 4.0) < 0.9)].any()
    # a crossing twice as slow is timed half as well: its window is wider
    slow = detect_lockup(t, 0.5 * true + rng.normal(0, 0.06, t.size))
    width = lambda c: np.median([b - a for a, b in c])
    assert width(slow.crossings) > 1.5 * width(det.crossings)
    # one sign throughout, or noise around 0 inside a lock: no crossing outside the locks
    assert detect_lockup(t, 3 + np.abs(true) + rng.normal(0, 0.06, t.size)).crossings == []
    locked = np.where((t > 8) & (t < 11), 0.0, 3 + np.abs(true)) + rng.normal(0, 0.06, t.size)
    det = detect_lockup(t, locked)
    assert det.segments and det.crossings == []
    assert det.excluded_at(t).sum() == det.at(t).sum()


def test_a_crossing_window_covers_the_samples_that_cross():
    """A slip that creeps at 0.1 rad/s and then drops through zero fast (a corner): its moving
    average crosses zero samples before the samples themselves do. The window still takes in
    the last sample of the old sign and one sample past the first of the new one, where a plant
    on the logged slip has just flipped its torque (before: the window ended at the first
    sample of the new sign, or one sample before it at 100 rad/s/s)."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 2.0, 0.008)                                   # slip at 125 Hz
    for creep, drop in ((0.1, 40.0), (0.12, 80.0), (0.15, 60.0), (0.1, 100.0)):
        w = np.maximum(np.where(t < 1.0, creep, creep - drop * (t - 1.0)), -3.0) + rng.normal(0, 0.01, t.size)
        det = detect_lockup(t, w)
        assert not det.mask.any()
        raw = np.flatnonzero(np.sign(w[:-1]) * np.sign(w[1:]) < 0)
        assert raw.size == 1
        k = int(raw[0])
        assert det.excluded_at(t)[k:k + 3].all(), (creep, drop)      # old sign, new sign, one after
        assert not det.excluded_at(t)[np.abs(t - t[k]) > 0.1].any()  # and no more than around it


def test_interpolate_on_grid():
    tg = np.array([0.0, 0.1, 0.25, 0.3])
    y = 3 * tg + 1
    q = np.array([-0.01, 0.0, 0.05, 0.2, 0.3, 0.31])
    out = interpolate_on_grid(tg, y, q)
    assert np.isnan(out[0]) and np.isnan(out[-1])
    np.testing.assert_allclose(out[1:-1], 3 * q[1:-1] + 1)


def sse_by_lag(t_meas, meas, t_grid, model_grid, keep, lags_ms):
    """Sum of squared residuals of meas(t) against model(t - lag), over common samples."""
    shifted = [interpolate_on_grid(t_grid, model_grid, t_meas - lag * 1e-3) for lag in lags_ms]
    ok = keep & np.all(np.isfinite(shifted), axis=0)
    return np.array([np.sum((meas[ok] - m[ok]) ** 2) for m in shifted])


def test_measured_time_removes_the_apparent_delay(short_campaign):
    """No mechanism; torque at 50 Hz, force at 200 Hz jittered +-1 ms, slip at 100 Hz. Simulated
    where the measurement is (linear input hold, output at the torque's own stamps) the
    residual is best aligned at lag 0; the replay grid's held inputs make the model ~2.5 ms
    late; the measured torque held on the force grid (the replay CSV's column) looks ~10 ms
    late."""
    result, paths, runs = short_campaign
    assert result.spec.clocks["measured_torque"].rate_hz == 50 and not result.spec.mechanisms
    model = load_model(paths["truth_model"])
    mts = simulate_at_measured_times(model, runs)
    res, cmp_grid = replay_at_measured_times(model, runs)
    lags = np.arange(-20, 20.5, 0.5)
    sse_meas = sse_zoh = sse_held = 0.0
    for j, (run, sl) in enumerate(res.campaign.slices()):
        lock = detect_lockup_run(run)
        cmp = mts.comparison
        ms = cmp.run_slice(j)
        keep = ~lock.at(cmp.t[ms], pad_s=0.1)
        rows = mts.run_index == j
        sse_meas = sse_meas + sse_by_lag(cmp.t[ms], cmp.measured[ms], mts.t[rows], mts.torque_pred[rows], keep, lags)
        sse_zoh = sse_zoh + sse_by_lag(cmp.t[ms], cmp.measured[ms], run.t, res.torque_sim[sl], keep, lags)
        keep_g = ~lock.at(run.t, pad_s=0.1) & np.isfinite(run.torque_measured_nm)
        sse_held = sse_held + sse_by_lag(run.t, run.torque_measured_nm, run.t, res.torque_sim[sl], keep_g, lags)
        # against the noise-free truth at the same stamps, off lock: the true model is close
        side = sidecar(paths, run.name)
        ok = cmp.valid[ms] & keep
        err = cmp.model[ms][ok] - side["torque_true_nm"][ok]
        assert np.sqrt(np.mean(err ** 2)) < 8.0
        assert ok.mean() > 0.5
    best_meas, best_zoh, best_held = (float(lags[np.argmin(x)]) for x in (sse_meas, sse_zoh, sse_held))
    print("best lags (ms): measured-time", best_meas, "replay grid", best_zoh, "held", best_held)
    assert abs(best_meas) <= 0.5
    assert best_held >= 5.0
    assert best_zoh <= -1.5      # the replay grid's input hold (half a period), seen as a delay


def test_at_measured_times_matches_replay_rows_when_aligned(short_campaign):
    """Queried exactly at grid rows, the evaluation returns the rows' values."""
    result, paths, runs = short_campaign
    res, _ = replay_at_measured_times(load_model(paths["truth_model"]), runs)
    run, sl = next(res.campaign.slices())
    vals = interpolate_on_grid(run.t, res.torque_sim[sl], run.t)
    np.testing.assert_allclose(vals, res.torque_sim[sl])
    cmp = at_measured_times(res.campaign, res.torque_sim)
    assert cmp.t.size == sum(r.torque_measured_t.size for r in res.campaign.runs)


def test_measured_time_grid_rows_and_batch(short_campaign):
    from clutch_model.diagnosis.measured_time import measured_time_grid
    from clutch_model.plant.simulate import simulate_batch
    result, paths, runs = short_campaign
    g = measured_time_grid(runs, rate_hz=500.0)
    ok = g.torque_rows >= 0
    assert ok.mean() > 0.97                       # only samples before a run's first row miss
    np.testing.assert_array_equal(g.t[g.torque_rows[ok]], g.torque_t[ok])
    assert np.all(g.run_index[g.torque_rows[ok]] == g.torque_run[ok])
    # inputs: between the two samples around each row, at the linear weight of its time
    run0 = runs[0]
    tf, vf = run0.samples["applied_force"]
    rows0 = g.run_index == 0
    tg, fg = g.t[rows0], g.force[rows0]
    k = np.searchsorted(tf, tg, side="right") - 1
    inside = (k >= 0) & (k < tf.size - 1)
    k = k[inside]
    w = (tg[inside] - tf[k]) / (tf[k + 1] - tf[k])
    assert np.all((w >= 0) & (w <= 1))
    np.testing.assert_allclose(fg[inside], (1 - w) * vf[k] + w * vf[k + 1], rtol=1e-9, atol=1e-9)
    model = load_model(paths["truth_model"])
    one = simulate_at_measured_times(model, runs, grid=g)
    batch = simulate_batch([model, model], g.t, g.force, g.slip, g.sump, run_start=g.run_start)
    np.testing.assert_allclose(batch.torque_nm[1], one.sim.torque_nm, rtol=1e-9, atol=1e-9)
    picked = g.at_torque_stamps(batch.torque_nm)
    assert picked.shape == (2, g.torque_t.size)
    np.testing.assert_allclose(picked[0][ok], one.comparison.model[ok])


def test_without_locked_torque(short_campaign):
    from clutch_model.diagnosis.lockup import without_locked_torque
    from clutch_model.formats.bag_reader import Campaign
    result, paths, runs = short_campaign
    camp, locks = without_locked_torque(Campaign(runs), pad_s=0.1)
    for run, new, lk in zip(Campaign(runs).runs, camp.runs, locks):
        side = sidecar(paths, run.name)
        gone = ~np.isfinite(new.torque_measured_nm) & np.isfinite(run.torque_measured_nm)
        np.testing.assert_array_equal(gone, lk.at(run.t, 0.1) & np.isfinite(run.torque_measured_nm))
        kept = np.isfinite(new.torque_measured_nm)
        np.testing.assert_array_equal(new.torque_measured_nm[kept], run.torque_measured_nm[kept])
        # every truly locked row is out (the grid's torque is the latest sample: pad covers it)
        fine_locked = np.interp(run.t, side["fine_t_s"], side["fine_locked"].astype(float)) > 0
        assert not np.any(kept & fine_locked)


def test_a_stick_shorter_than_a_lock_phase_is_left_out():
    """A slip-controlled clutch sticks for 0.15 s between two slip directions (the slip logged
    within 2e-4 rad/s of 0, the torque the driveline's): shorter than a lock phase's dwell, so
    no lock phase is found and the zero crossing's window covers only its start, but
    the model locks there and gives its static capacity. Those rows are left out by the model's
    own lock band; the slipping rows around them are kept."""
    from clutch_model.diagnosis.lockup import without_locked_torque
    from clutch_model.formats.bag_reader import Run
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 3.0, 0.0025)
    stick = (t >= 1.5) & (t < 1.65)
    slip = np.where(t < 1.5, -2.0 * (1.5 - t), np.where(stick, 0.0, 3.0 * (t - 1.65)))
    slip = slip + np.where(stick, rng.uniform(0.0, 2e-4, t.size), rng.normal(0, 1e-3, t.size))
    torque = np.where(stick, 120.0, np.sign(slip) * 300.0)
    run = Run(name="r", t=t, applied_force_n=np.full(t.size, 3000.0), slip_speed_rad_s=slip,
              sump_temperature_c=np.full(t.size, 60.0), torque_measured_nm=torque,
              samples={"slip_speed": (t, slip)})
    plain, res = without_locked_torque(Campaign([run]), pad_s=0.1)
    assert not res[0].segments                                     # too short for a lock phase
    assert np.isfinite(plain.runs[0].torque_measured_nm[stick]).mean() > 0.3
    model = load_model(None)
    camp, _ = without_locked_torque(Campaign([run]), pad_s=0.1, model_lock_slip_rad_s=model.lock_slip_rad_s)
    kept = np.isfinite(camp.runs[0].torque_measured_nm)
    assert not np.any(kept & stick)
    away = np.abs(slip) > 0.05
    assert np.all(kept[away] == np.isfinite(plain.runs[0].torque_measured_nm)[away])


def test_measured_time_campaign(short_campaign):
    from clutch_model.diagnosis.measured_time import measured_time_campaign
    from clutch_model.replay import replay_runs
    result, paths, runs = short_campaign
    camp = measured_time_campaign(runs)
    model = load_model(paths["truth_model"])
    rep = replay_runs(model, camp)
    mts = simulate_at_measured_times(model, runs, rate_hz=1000.0)
    replay_rows = np.zeros(camp.t.size, bool)
    for run, (new, sl) in zip(runs, camp.slices()):
        ok = np.isfinite(new.torque_measured_nm)
        # measured samples sit at their own stamps, nothing else is measured; the grid starts
        # at the first force and slip sample, the replay grid's first row or before it
        assert new.t[0] <= run.t[0]
        np.testing.assert_array_equal(new.t[ok], run.torque_measured_t[run.torque_measured_t >= new.t[0]])
        replay_rows[sl] = new.t >= run.t[0]
    # the grid-based replay on it agrees with the 1 kHz measured-time simulation at the stamps
    # (which starts at the replay grid's first row; the film's start differs over a few rows)
    ok = np.isfinite(camp.torque_measured) & replay_rows
    a = rep.torque_sim[ok]
    b = mts.comparison.model[mts.comparison.valid]
    lock = np.concatenate([detect_lockup_run(r).at(r.torque_measured_t[r.torque_measured_t >= r.t[0]], 0.1)
                           for r in runs])
    assert a.size == b.size
    assert np.sqrt(np.mean((a - b)[~lock] ** 2)) < 3.0


def test_lock_detection_with_slip_sign_changes(tmp_path_factory):
    """Slip crossing 0 while slipping is not a lock; locked torque keeps the last slip's sign."""
    res, paths, runs = make_campaign(tmp_path_factory, "signs", seed=33, schedule="few-long",
                                     run_duration_s=40.0, slip_sign_changes=True)
    crossings = 0
    for run in runs:
        side = sidecar(paths, run.name)
        w = side["fine_slip_speed_rad_s"]
        crossings += int(np.sum((w[1:] * w[:-1] < 0)))
        lk = side["fine_locked"]
        # while locked the driveline torque has the sign of the slip before the lock
        starts = np.flatnonzero(np.diff(lk.astype(int)) == 1) + 1
        for s0 in starts:
            before = w[:s0][np.abs(w[:s0]) > 1e-3][-1]
            assert np.sign(side["fine_torque_nm"][s0]) == np.sign(before)
    assert crossings >= 2
    prec, rec, n = precision_recall(paths, runs)
    assert prec >= 0.85 and rec >= 0.95, (prec, rec)


def test_plant_starts_where_force_and_slip_start(tmp_path):
    """A sump temperature logged at 2 Hz starts 0.45 s after the force and slip: the replay grid
    starts there, with the film at rest although 400 N have squeezed it since the start. The
    diagnosis's grid starts at the first instant with a force and a slip sample (the sump's first
    sample held back), so the model follows the true torque from there; independent truth: the
    plant simulated from the log's start on a fine grid with the noise-free inputs."""
    from clutch_model.diagnosis.measured_time import measured_time_campaign, plant_inputs_start_s
    from clutch_model.formats.bag_reader import read_bag
    from clutch_model.formats.bag_writer import write_run_bag
    from clutch_model.replay import replay_runs
    model = load_model(None)
    fine = np.arange(0.0, 2.5, 1e-4)
    force = lambda t: np.where(t < 1.2, 400.0, 400.0 + 3000.0 * np.minimum((t - 1.2) / 0.3, 1.0))
    slip = lambda t: 8.0 + 2.0 * np.sin(2 * np.pi * 0.5 * t)
    truth = simulate(model, fine, force(fine), slip(fine), 60.0).torque_nm
    tf, tw = np.arange(0.002, 2.45, 0.002), np.arange(0.004, 2.45, 0.005)
    tq, ts = np.arange(0.0035, 2.45, 0.005), np.arange(0.45, 2.45, 0.5)
    write_run_bag(tmp_path / "b", {"applied_force": (tf, force(tf)), "slip_speed": (tw, slip(tw)),
                                   "sump_temperature": (ts, np.full(ts.size, 60.0)),
                                   "measured_torque": (tq, np.interp(tq, fine, truth))})
    run = read_bag(tmp_path / "b")
    t_bag = run.samples["applied_force"][0][0] - 0.002           # the bag's time base
    assert run.t[0] - t_bag >= 0.45 - 1e-9                       # the replay grid waits for the sump
    camp = measured_time_campaign([run])
    assert abs(camp.t[0] - plant_inputs_start_s(run)) < 1e-12
    assert abs(camp.t[0] - t_bag - 0.004) < 1e-6                 # the first slip sample
    resid = camp.torque_measured - replay_runs(model, camp).torque_sim
    ok = np.isfinite(resid)
    assert np.count_nonzero(ok & (camp.t < run.t[0])) >= 85       # the torque before the sump is compared
    late = replay_runs(model, [run])                              # from the replay grid's first row
    tt = run.torque_measured_t
    at = (tt >= run.t[0]) & (tt < run.t[0] + 0.75)
    err_late = np.interp(tt[at], run.t, late.torque_sim) - run.torque_measured_raw_nm[at]
    early = ok & (camp.t >= run.t[0]) & (camp.t < run.t[0] + 0.75)
    rms_late, rms_early = np.sqrt(np.mean(err_late ** 2)), np.sqrt(np.mean(resid[early] ** 2))
    scale = np.sqrt(np.mean(truth[(fine > 0.45) & (fine < 1.2)] ** 2))
    assert rms_late > 0.05 * scale, (rms_late, scale)            # the missed squeeze shows
    assert rms_early < 0.2 * rms_late, (rms_early, rms_late)


def test_a_sparse_torque_is_compared_on_the_force_own_samples(tmp_path):
    """Torque logged at 100 Hz, the force requested at 1 kHz in 3-8 ms steps: rows at the
    torque's stamps hold one force over each 10 ms step, and the plant misses what the force
    did inside it. The rows get a plant grid on the force's own samples (prediction.PlantGrid),
    read held as logged. Independent truth: the plant simulated on a 0.1 ms grid with the held
    force, read at the torque stamps."""
    from clutch_model.diagnosis.input_timing import with_held_inputs
    from clutch_model.diagnosis.measured_time import force_between_rows, measured_time_campaign, plant_grid_needed
    from clutch_model.formats.bag_reader import read_bag
    from clutch_model.formats.bag_writer import write_run_bag
    from clutch_model.prediction import predict_campaign
    model = load_model(None)
    rng = np.random.default_rng(7)
    edges = np.cumsum(rng.uniform(0.003, 0.008, 800))
    levels = 4000.0 + 9000.0 * rng.random(edges.size)
    tf = np.arange(0.0, 3.0, 0.001)
    force_f = lambda t: levels[np.clip(np.searchsorted(edges, t, side="right"), 0, levels.size - 1)]
    fine = np.arange(0.0, 3.0, 1e-4)
    held = force_f(tf)[np.clip(np.searchsorted(tf, fine, side="right") - 1, 0, tf.size - 1)]
    slip = lambda t: 6.0 + 2.0 * np.sin(2 * np.pi * 0.7 * t)
    truth = simulate(model, fine, held, slip(fine), 60.0).torque_nm
    tw, tq = np.arange(0.0, 3.0, 0.001), np.arange(0.0104, 2.99, 0.01)
    ts = np.arange(0.0, 3.0, 0.1)
    write_run_bag(tmp_path / "b", {"applied_force": (tf, force_f(tf)), "slip_speed": (tw, slip(tw)),
                                   "sump_temperature": (ts, np.full(ts.size, 60.0)),
                                   "measured_torque": (tq, np.interp(tq, fine, truth))})
    run = read_bag(tmp_path / "b")
    assert force_between_rows(run.torque_measured_t, *run.samples["applied_force"]) > 10.0
    assert plant_grid_needed([run])
    camp = with_held_inputs(measured_time_campaign([run], rate_hz=1.0))
    assert camp.runs[0].plant_grid is not None
    ok = np.isfinite(camp.torque_measured) & (camp.t > 0.2)
    on_grid = predict_campaign(model, camp).torque_nm
    rows_only = predict_campaign(model, Campaign([replace(r, plant_grid=None) for r in camp.runs])).torque_nm
    # and on the rows of a window of the run (diagnosis.sample) the grid is cut with them
    from clutch_model.diagnosis.input_hold import run_rows
    head = run_rows(camp.runs[0], slice(0, 100))
    np.testing.assert_allclose(predict_campaign(model, Campaign([head])).torque_nm, on_grid[:100], rtol=0, atol=1e-9)
    err = lambda p: float(np.sqrt(np.mean((p - camp.torque_measured)[ok] ** 2)))   # noqa: E731
    assert on_grid.shape == camp.t.shape
    assert err(on_grid) < 0.3, err(on_grid)
    assert err(rows_only) > 10 * err(on_grid), (err(rows_only), err(on_grid))
    # the diagnosis keeps the grid where it moves the prediction by 0.3 of the torque's noise
    choice = choose_plant_grid(camp, model, noise_nm=2.0)
    assert choice.used and choice.difference_rms_nm > 5.0, choice


def test_the_plant_grid_is_dropped_where_the_force_moves_smoothly(tmp_path):
    """The same sparse torque under a force that moves smoothly between its samples: the rows'
    midpoint force reaches the plant as well as a grid would, and none is made."""
    from clutch_model.diagnosis.input_hold import with_midpoint_force
    from clutch_model.diagnosis.measured_time import (force_between_rows, measured_time_campaign,
                                                      plant_grid_needed, run_plant_grid)
    from clutch_model.formats.bag_reader import read_bag
    from clutch_model.formats.bag_writer import write_run_bag
    model = load_model(None)
    force = lambda t: 7000.0 + 3000.0 * np.sin(2 * np.pi * 0.8 * t)      # noqa: E731
    slip = lambda t: 6.0 + 2.0 * np.sin(2 * np.pi * 0.7 * t)             # noqa: E731
    tf, tq, ts = np.arange(0.0, 3.0, 0.001), np.arange(0.0104, 2.99, 0.01), np.arange(0.0, 3.0, 0.1)
    fine = np.arange(0.0, 3.0, 1e-4)
    truth = simulate(model, fine, force(fine), slip(fine), 60.0).torque_nm
    write_run_bag(tmp_path / "b", {"applied_force": (tf, force(tf)), "slip_speed": (tf, slip(tf)),
                                   "sump_temperature": (ts, np.full(ts.size, 60.0)),
                                   "measured_torque": (tq, np.interp(tq, fine, truth))})
    run = read_bag(tmp_path / "b")
    # a line through the rows misses nothing of this force: no grid is made
    assert force_between_rows(run.torque_measured_t, *run.samples["applied_force"]) < 1.0
    assert not plant_grid_needed([run])
    camp = with_midpoint_force(measured_time_campaign([run], rate_hz=1.0))
    assert camp.runs[0].plant_grid is None
    # and given one, it would be dropped: the two predictions differ by 0.56 N*m on torques of ~1 kN*m
    camp = Campaign([replace(r, plant_grid=run_plant_grid(r)) for r in camp.runs])
    choice = choose_plant_grid(camp, model, noise_nm=4.0)
    assert not choice.used and choice.rows > 200 and choice.difference_rms_nm < 1.0, choice


def test_lock_detection_on_a_slip_from_two_counting_encoders():
    """Slip as the difference of two wheel encoders, each counting over a window and read out
    faster than its count changes, each on its own grid (0.217 and 0.233 rad/s): most successive
    samples repeat, the changes are either quantum, their difference or their sum (no one grid),
    and the first-difference MAD is 0. The noise estimate keeps at least the reading's typical
    change / sqrt 12; the lock phases are found and the locked dither makes no zero crossings."""
    from clutch_model.diagnosis.lockup import slip_quantum, slip_resolution

    rng = np.random.default_rng(11)
    t = np.arange(0, 30, 0.006)                                   # slip messages at ~167 Hz
    locked = ((t > 6) & (t < 9)) | ((t > 17) & (t < 21))
    true_slip = np.where(locked, 0.0, 4 + 2 * np.sin(2 * np.pi * 0.2 * t))
    base = 80 + 30 * np.sin(2 * np.pi * 0.03 * t)                 # the axle side
    qa, qb = 0.233, 0.217

    def encoder(speed, q, period_s):
        ticks = np.arange(0, 30, period_s) + rng.uniform(0, period_s, 1)
        read = q * np.floor(np.interp(ticks, t, speed) / q + rng.uniform(0, 1, ticks.size))
        return read[np.clip(np.searchsorted(ticks, t, side="right") - 1, 0, None)]

    w = encoder(base + true_slip, qa, 0.012) - encoder(base, qb, 0.013)
    assert slip_quantum(w) == 0.0                                 # not on one grid
    assert qb * 0.9 < slip_resolution(w) < qa * 1.1
    assert slip_resolution(true_slip + rng.normal(0, 0.05, t.size)) == 0.0     # continuous
    held = np.repeat(true_slip[::10] + rng.normal(0, 0.05, t.size // 10), 10)    # ... held 10 samples
    assert slip_resolution(held) == 0.0
    det = detect_lockup(t, w)
    assert det.noise_sigma_rad_s > 0.05
    found = det.at(t)
    assert found[locked].mean() > 0.9
    assert not found[~locked & (np.abs(t - 6) > 0.3) & (np.abs(t - 9) > 0.3)
                     & (np.abs(t - 17) > 0.3) & (np.abs(t - 21) > 0.3)].any()
    assert len(det.segments) == 2 and det.crossings == []
