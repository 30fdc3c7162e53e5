"""Lock-up found from noisy slip data; the model compared where the measurement is."""
import csv
from pathlib import Path

import numpy as np
import pytest

from clutch_model.diagnosis.lockup import detect_lockup, detect_lockup_run
from clutch_model.diagnosis.measured_time import (at_measured_times, interpolate_on_grid,
                                                  replay_at_measured_times, simulate_at_measured_times)
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
