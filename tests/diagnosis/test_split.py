"""Held-out data for any campaign shape: whole runs when there are enough, time spans of long
runs otherwise; the labels round-trip through report.json's notation."""
from dataclasses import dataclass

import numpy as np
import pytest

from clutch_model.diagnosis.split import HeldOut, choose_split, parse_held_out
from clutch_model.errors import DataError


@dataclass
class R:
    name: str
    t: np.ndarray
    slip_speed_rad_s: np.ndarray
    sump_temperature_c: np.ndarray

    @property
    def duration_s(self):
        return float(self.t[-1] - self.t[0])

    def __len__(self):
        return self.t.size


def _runs(n, duration_s, rate_hz=100.0):
    out = []
    for j in range(n):
        t = np.arange(int(duration_s * rate_hz)) / rate_hz
        out.append(R(f"run_{j:02d}", t, np.full(t.size, 5.0 + (j % 3)), np.full(t.size, 60.0 + (j % 4))))
    return out


def _concat(runs):
    return (np.concatenate([r.t for r in runs]),
            np.concatenate([np.full(len(r), j) for j, r in enumerate(runs)]))


def test_many_runs_hold_out_whole_runs():
    runs = _runs(9, 5.0)
    split = choose_split(runs)
    assert all(h.whole_run for h in split.held_out) and len(split.held_out) == 3
    t, idx = _concat(runs)
    fit, ev = split.masks([r.name for r in runs], idx, t)
    assert not (fit & ev).any()
    held_idx = {[r.name for r in runs].index(h.run) for h in split.held_out}
    assert set(np.unique(idx[ev])) == held_idx
    assert set(split.fit_runs([r.name for r in runs])).isdisjoint(split.labels)


def test_one_long_run_holds_out_spans_with_guards():
    runs = _runs(1, 120.0)
    split = choose_split(runs)
    assert len(split.held_out) >= 3 and not any(h.whole_run for h in split.held_out)
    t, idx = _concat(runs)
    fit, ev = split.masks(["run_00"], idx, t)
    # about a third held out, the rest fitted, guards in neither
    assert 0.25 < ev.mean() < 0.4 and 0.55 < fit.mean() < 0.75
    assert not (fit & ev).any() and (~fit & ~ev).sum() > 0
    # spans are inside the run and labelled "<bag>[t0:t1]"
    for h in split.held_out:
        assert h.label.startswith("run_00[") and 0 <= h.t0 < h.t1 <= 120.0 + 1e-3
        assert parse_held_out(h.label) == h
    # every held-out row is inside a labelled span
    inside = np.zeros(t.size, bool)
    for h in split.held_out:
        inside |= (t >= h.t0) & (t < h.t1)
    assert inside[ev].all()


def test_two_runs_use_spans_and_a_whole_bag_label_parses():
    runs = _runs(2, 30.0)
    split = choose_split(runs)
    assert {h.run for h in split.held_out} == {"run_00", "run_01"}
    assert parse_held_out("run_00") == HeldOut("run_00")
    assert parse_held_out("a[b][1.5:3]") == HeldOut("a[b]", 1.5, 3.0)


def test_given_labels_and_bad_input():
    runs = _runs(1, 20.0)
    t, idx = _concat(runs)
    split = choose_split(runs, held_out=["run_00[5:10]"])
    fit, ev = split.masks(["run_00"], idx, t)
    assert ev.sum() == pytest.approx(500 - split.guard_s * 100, abs=2)
    with pytest.raises(DataError):
        choose_split(runs, held_out=["nope"]).masks(["run_00"], idx, t)
    with pytest.raises(DataError):
        parse_held_out("run_00[10:5]")
    with pytest.raises(DataError):
        choose_split(runs, held_out=["run_00"]).masks(["run_00"], idx, t)


def test_three_runs_hold_out_the_one_between_the_others_in_temperature():
    """Of three runs, the held-out one lies inside the fit runs' sump temperature range (the
    friction correction, quadratic in temperature, is not scored off the range it was fitted
    on), whatever its place in log time."""
    runs = _runs(3, 10.0)
    for sumps, expected in (((78.0, 36.0, 59.0), "run_02"), ((40.0, 50.0, 60.0), "run_01"),
                            ((55.0, 90.0, 30.0), "run_00")):
        for r, th in zip(runs, sumps):
            r.sump_temperature_c = np.full(r.t.size, th)
        split = choose_split(runs)
        assert split.labels == [expected]
        assert split.fit_runs([r.name for r in runs]) == [r.name for r in runs if r.name != expected]


def test_many_runs_hold_out_a_run_inside_the_fit_runs_pack_temperature_range():
    """With four runs or more the held-out run is moved off the hottest and coldest run by the
    predicted pack temperature (the friction law's temperature) before any slip or sump
    extreme: a held-out run hotter than every fit run would score the calibration's
    extrapolation, not the model."""
    runs = _runs(4, 10.0)
    # slip and sump: run_00 and run_03 hold every extreme, run_01 and run_02 none
    for r, (slip, sump) in zip(runs, ((2.0, 30.0), (5.0, 50.0), (5.0, 50.0), (9.0, 70.0))):
        r.slip_speed_rad_s = np.full(r.t.size, slip)
        r.sump_temperature_c = np.full(r.t.size, sump)
    assert choose_split(runs).labels == ["run_01"]                   # no pack temperature: as before
    hot = [np.full(r.t.size, th) for r, th in zip(runs, (50.0, 95.0, 70.0, 60.0))]
    assert choose_split(runs, pack_temperature_c=hot).labels == ["run_02"]   # run_01 is the hottest
    # a run peaking highest counts as the hot end too, whatever its mean
    peak = [np.linspace(th - d, th + d, r.t.size) for r, th, d in zip(runs, (60.0, 62.0, 64.0, 66.0),
                                                                          (5.0, 40.0, 5.0, 5.0))]
    assert choose_split(runs, pack_temperature_c=peak).labels == ["run_02"]
    # run_00, run_01, run_02 each an end of the pack temperature: run_03 (a slip and sump
    # extreme) is held out, a pack-temperature extreme weighing more
    three = [np.linspace(th - d, th + d, r.t.size) for r, th, d in zip(runs, (40.0, 95.0, 60.0, 70.0),
                                                                           (5.0, 5.0, 60.0, 5.0))]
    assert choose_split(runs, pack_temperature_c=three).labels == ["run_03"]
    # the split says what it weighed: the pack temperature only when it was usable
    assert "pack temperature" in choose_split(runs, pack_temperature_c=hot).how
    assert "pack temperature" not in choose_split(runs).how
    unusable = [np.full(r.t.size, np.nan) for r in runs]
    split = choose_split(runs, pack_temperature_c=unusable)
    assert split.labels == ["run_01"] and "pack temperature" not in split.how
    # a long log's windows are named as what they are, the picks unchanged
    windows = choose_split(runs, pack_temperature_c=hot, runs_are="windows")
    assert windows.labels == ["run_02"]
    assert windows.how.startswith("whole windows: ") and "moved off the windows with" in windows.how
    assert choose_split(runs[:3], runs_are="windows").how.startswith("whole windows: the window whose")
