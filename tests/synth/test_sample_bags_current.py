"""The sample data shipped in bags/ is what its generator writes today: regenerate into a
temporary directory and compare the decoded messages (topic, log time, header stamp, values) of
every bag and the bench table row by row. A change to the virtual car, the bag writer or the
plant that would silently make bags/ stale fails here."""
import csv
import math

import numpy as np
import pytest

from clutch_model.virtual_car.sample_bags import SAMPLE_DIR, write_sample_data

RUNS = ("run_00", "run_01", "run_02")


def _numbers(msg, prefix=""):
    """All numeric fields of a deserialized message, flattened by dotted name."""
    out = {}
    for name in getattr(msg, "__dataclass_fields__", {}):
        if name == "__msgtype__":
            continue
        v = getattr(msg, name)
        if isinstance(v, bool):
            out[prefix + name] = float(v)
        elif isinstance(v, (int, float)):
            out[prefix + name] = float(v)
        elif hasattr(v, "__dataclass_fields__"):
            out.update(_numbers(v, prefix + name + "."))
    return out


def decoded(bag):
    from rosbags.highlevel import AnyReader

    from clutch_model.formats.typestore import typestore

    rows = []
    with AnyReader([bag], default_typestore=typestore()) as reader:
        types = sorted((c.topic, c.msgtype) for c in reader.connections)
        for conn, t, raw in reader.messages():
            rows.append((conn.topic, int(t), _numbers(reader.deserialize(raw, conn.msgtype))))
    rows.sort(key=lambda r: (r[0], r[1]))
    return types, rows


@pytest.fixture(scope="module")
def fresh(tmp_path_factory):
    out = tmp_path_factory.mktemp("sample_fresh")
    write_sample_data(out)
    return out


@pytest.mark.parametrize("run", RUNS)
def test_shipped_bag_equals_regenerated(fresh, run):
    shipped_types, shipped = decoded(SAMPLE_DIR / run)
    new_types, new = decoded(fresh / run)
    assert shipped_types == new_types
    assert len(shipped) == len(new) > 1000
    assert [(r[0], r[1]) for r in shipped] == [(r[0], r[1]) for r in new]   # topics and log times exact
    for (topic, t, a), (_, _, b) in zip(shipped, new):
        assert a.keys() == b.keys(), topic
        for k in a:
            assert math.isclose(a[k], b[k], rel_tol=1e-9, abs_tol=1e-9), (topic, t, k, a[k], b[k])


def test_shipped_bench_table_equals_regenerated(fresh):
    def rows(path):
        with open(path, newline="") as fh:
            r = list(csv.reader(fh))
        return r[0], np.array(r[1:], float)

    h_old, old = rows(SAMPLE_DIR / "bench.csv")
    h_new, new = rows(fresh / "bench.csv")
    assert h_old == h_new and old.shape == new.shape == (135, len(h_old))
    np.testing.assert_allclose(old, new, rtol=1e-9, atol=1e-12)


def test_shipped_readme_equals_regenerated(fresh):
    assert (SAMPLE_DIR / "README.md").read_text() == (fresh / "README.md").read_text()
