"""The fast CSV writer of replay (orjson blocks) against the csv module with Python's repr:
the same rows, labels and numbers bit for bit; the fallback writes the very same bytes."""
import csv

import numpy as np
import pytest

from clutch_model.formats import table_csv
from clutch_model.formats.table_csv import write_table_csv


def _reference(path, header, blocks):
    """What replay wrote before: csv.writer, repr(float), non-finite -> empty."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for label, cols in blocks:
            for k in range(len(cols[0])):
                w.writerow([label] + ["" if not np.isfinite(c[k]) else repr(float(c[k])) if c.dtype.kind == "f"
                                      else str(int(c[k])) for c in cols])


def _blocks():
    rng = np.random.default_rng(4)
    n = table_csv.BLOCK_ROWS + 1234                          # more than one block
    wild = rng.normal(size=n) * 10.0 ** rng.integers(-300, 300, n)
    wild[:6] = [5e-324, 1.7976931348623157e308, -0.0, 1e-5, 1e16, np.inf]
    meas = rng.normal(500, 100, n)
    meas[::7] = np.nan
    return [("run_00", [np.arange(n) / 1000.0, wild, meas]),
            ("odd, \"name\"", [np.arange(10) / 3.0, np.full(10, np.nan), np.linspace(-1, 1, 10)])]


def _parse(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def _same_numbers(a, b):
    assert len(a) == len(b)
    for ra, rb in zip(a, b):
        assert ra[0] == rb[0] and len(ra) == len(rb)
        for x, y in zip(ra[1:], rb[1:]):
            assert (x == "") == (y == "")
            if x:
                assert np.float64(x).view(np.int64) == np.float64(y).view(np.int64)


def test_fast_csv_same_numbers_as_repr(tmp_path):
    pytest.importorskip("orjson")
    header = ["bag", "t", "x", "y"]
    write_table_csv(tmp_path / "fast.csv", header, _blocks())
    _reference(tmp_path / "ref.csv", header, _blocks())
    hf, rf = _parse(tmp_path / "fast.csv")
    hr, rr = _parse(tmp_path / "ref.csv")
    assert hf == hr
    _same_numbers(rf, rr)


def test_integer_columns(tmp_path):
    header = ["bag", "t", "locked"]
    blocks = [("b", [np.arange(5) * 0.5, np.array([0, 1, 1, 0, 1], dtype=np.int8)])]
    write_table_csv(tmp_path / "i.csv", header, blocks)
    _, rows = _parse(tmp_path / "i.csv")
    assert rows == [["b", "0.0", "0"], ["b", "0.5", "1"], ["b", "1.0", "1"], ["b", "1.5", "0"], ["b", "2.0", "1"]]


def test_fallback_without_orjson_writes_the_old_bytes(tmp_path, monkeypatch):
    monkeypatch.setattr(table_csv, "_orjson", lambda: None)
    header = ["bag", "t", "x", "y"]
    write_table_csv(tmp_path / "slow.csv", header, _blocks())
    _reference(tmp_path / "ref.csv", header, _blocks())
    assert (tmp_path / "slow.csv").read_bytes() == (tmp_path / "ref.csv").read_bytes()
