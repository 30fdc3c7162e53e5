"""Bags that continue one drive (a recorder rolling over mid-drive) are joined, the plant state
carried; bags written back to back whose plant restarted with each bag (the replay contract)
stay apart. Real bags written and read back; the decision uses a model whose friction level
is 10 % off the truth's, as the bench model may be."""
from __future__ import annotations

import numpy as np
import pytest

from clutch_model import REFERENCE_CLUTCH, load_model
from clutch_model.diagnosis.continued_bags import join_continued_bags, may_continue
from clutch_model.diagnosis.report import in_bag_terms
from clutch_model.formats.bag_reader import read_bags
from clutch_model.formats.bag_writer import RunSignals, TopicSeries, write_run_bag
from clutch_model.plant.simulate import simulate

START_NS = 1_700_000_000_000_000_000
CUT_S = (0.0, 40.0, 80.0, 120.0)        # three bags of 40 s
FORCE_HZ, SLIP_HZ, TORQUE_HZ = 200.0, 100.0, 250.0


def _drive(rng):
    """A hard drive on a 1 kHz grid: engagements at 8-20 rad/s that heat the pack."""
    t = np.arange(0.0, CUT_S[-1], 1e-3)
    phase = (t % 6.0) / 6.0
    force = np.where(phase < 0.7, 6000.0 + 3000.0 * np.sin(2 * np.pi * t / 17.0), 300.0)
    slip = 14.0 + 6.0 * np.sin(2 * np.pi * t / 23.0)
    sump = np.full(t.size, 60.0)
    return t, force, slip, sump


def _bags(tmp_path, continuous: bool, seed=3):
    rng = np.random.default_rng(seed)
    model = load_model(REFERENCE_CLUTCH)
    t, force, slip, sump = _drive(rng)
    starts = np.zeros(t.size, bool)
    starts[0] = True
    if not continuous:                      # the contract's runs: the plant restarts with each bag
        for c in CUT_S[1:-1]:
            starts[np.searchsorted(t, c)] = True
    torque = simulate(model, t, force, slip, sump, run_start=starts).torque_nm
    paths = []
    for j, (a, b) in enumerate(zip(CUT_S, CUT_S[1:])):
        first = a + 0.004 * j                # each bag's first message a few ms after the last one's

        def series(hz, values, noise):
            ts = np.arange(first, b - 1e-3, 1.0 / hz)
            ts = ts + rng.uniform(0, 0.2 / hz, ts.size)
            v = np.interp(ts, t, values) + noise * rng.standard_normal(ts.size)
            return TopicSeries(ts - first, v)

        sig = RunSignals(applied_force=series(FORCE_HZ, force, 10.0), slip_speed=series(SLIP_HZ, slip, 0.02),
                         sump_temperature=series(10.0, sump, 0.05), measured_torque=series(TORQUE_HZ, torque, 1.0))
        paths.append(write_run_bag(tmp_path / f"run_{j:03d}", sig, start_time_ns=START_NS + int(round(first * 1e9))))
    return read_bags(paths)


def _decision_model():
    m = load_model(REFERENCE_CLUTCH)
    a = m.friction_coefficients.copy()
    a[:10] *= 0.9                           # mu_C and mu_S 10 % low: the bench's friction level off
    return m.with_friction(a=a)


def test_a_drive_cut_into_bags_is_joined_and_reported_in_bag_terms(tmp_path):
    runs = _bags(tmp_path, continuous=True)
    assert all(may_continue(p, n) for p, n in zip(runs, runs[1:]))
    said = []
    joined, joins = join_continued_bags(_decision_model(), runs, said.append)
    assert len(joined) == 1 and [p.name for p in joins.drives[0].parts] == ["run_000", "run_001", "run_002"]
    for c in joins.checks:
        assert c["joined"] and c["rmse_continued_nm"] < 0.5 * c["rmse_restarted_nm"], c
    drive = joined[0]
    # one time base: every input sample of the three bags, rows increasing across the roll-overs
    assert np.all(np.diff(drive.t) > 0)
    assert drive.t[-1] > 119.0 and drive.start_time_ns == runs[0].start_time_ns
    assert sum(len(r.samples["measured_torque"][0]) for r in runs) == len(drive.samples["measured_torque"][0])
    assert np.isfinite(drive.torque_measured_nm).all()
    assert any("one drive" in s for s in said)
    # labels: a span of the drive in the bags' own terms, and back
    off1 = joins.drives[0].parts[1].offset_s        # run_001's first message in the drive's time
    assert abs(off1 - 40.004) < 2e-3
    f = lambda x: f"{round(x, 3):g}"
    assert joins.bag_labels(f"{drive.name}[50:60]") == [f"run_001[{f(50 - off1)}:{f(60 - off1)}]"]
    end0 = joins.drives[0].parts[0].end_s
    assert joins.bag_labels(f"{drive.name}[35:45]") == [f"run_000[35:{f(end0)}]", f"run_001[0:{f(45 - off1)}]"]
    assert joins.bag_labels(drive.name) == ["run_000", "run_001", "run_002"]
    assert joins.drive_label("run_001[10:20]") == f"{drive.name}[{f(off1 + 10)}:{f(off1 + 20)}]"
    rep = in_bag_terms({"held_out_runs": [f"{drive.name}[50:60]"], "fit_runs": [drive.name]}, joins)
    assert rep["held_out_runs"] == [f"run_001[{f(50 - off1)}:{f(60 - off1)}]"]
    assert rep["fit_runs"] == ["run_000", "run_001", "run_002"]
    assert rep["continued_bags"]["drives"][0]["bags"] == ["run_000", "run_001", "run_002"]


def test_bags_whose_plant_restarted_stay_apart(tmp_path):
    runs = _bags(tmp_path, continuous=False)
    assert all(may_continue(p, n) for p, n in zip(runs, runs[1:]))     # back to back in time
    joined, joins = join_continued_bags(_decision_model(), runs)
    assert [r.name for r in joined] == ["run_000", "run_001", "run_002"] and not joins.drives
    for c in joins.checks:
        assert not c["joined"] and c["rmse_restarted_nm"] < c["rmse_continued_nm"], c
    # nothing joined: the report is unchanged but says what it weighed
    rep = in_bag_terms({"held_out_runs": ["run_001"]}, joins)
    assert rep["held_out_runs"] == ["run_001"] and len(rep["continued_bags"]["checks"]) == 2


@pytest.mark.parametrize("gap_s", [2.0, -0.5])
def test_bags_apart_in_time_are_not_candidates(tmp_path, gap_s):
    runs = _bags(tmp_path, continuous=True)
    from dataclasses import replace

    moved = replace(runs[1], start_time_ns=runs[1].start_time_ns + int(gap_s * 1e9))
    assert not may_continue(runs[0], moved)
    # a campaign with no bag right after another is returned as it is, nothing simulated
    # (no model needed) and nothing weighed
    apart, joins = join_continued_bags(None, [moved, runs[0]])
    assert [r.name for r in apart] == sorted(r.name for r in (moved, runs[0])) and not joins.checks
