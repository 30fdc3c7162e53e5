"""No behaviour change: `clutch-sim replay` of the shipped sample bags through the reference
clutch reproduces the output recorded before the house refactor (friction law, mechanisms and
prediction path moved into their own modules) to 1e-9 N*m and 1e-9 C.

The reference (tests/model/data/replay_sample_bags.csv.gz: bag, t, torque_sim,
pack_temperature_sim) was written by `clutch-sim replay --bag bags/run_00 bags/run_01
bags/run_02` at the commit before the refactor; if the sample bags are ever regenerated, so
must it be (from a commit whose physics is trusted)."""
import csv
import gzip
from pathlib import Path

import numpy as np

from clutch_sim.cli import main as cli

ROOT = Path(__file__).resolve().parents[2]
REFERENCE = Path(__file__).with_name("data") / "replay_sample_bags.csv.gz"


def _columns(rows):
    return ([r["bag"] for r in rows], np.array([float(r["t"]) for r in rows]),
            np.array([float(r["torque_sim"]) for r in rows]),
            np.array([float(r["pack_temperature_sim"]) for r in rows]))


def test_replay_of_sample_bags_matches_the_pre_refactor_reference(tmp_path):
    out = tmp_path / "replay.csv"
    bags = [str(ROOT / "bags" / f"run_0{k}") for k in range(3)]
    assert cli(["replay", "--bag", *bags, "--out", str(out)]) == 0
    with open(out) as fh:
        names, t, torque, pack = _columns(list(csv.DictReader(fh)))
    with gzip.open(REFERENCE, "rt") as fh:
        ref_names, ref_t, ref_torque, ref_pack = _columns(list(csv.DictReader(fh)))
    assert names == ref_names
    assert np.array_equal(t, ref_t)
    assert np.max(np.abs(torque - ref_torque)) < 1e-9
    assert np.max(np.abs(pack - ref_pack)) < 1e-9
