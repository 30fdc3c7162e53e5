"""Bench CSV (SAE#2) read/write: round trip and one-line errors naming file and line."""
import numpy as np
import pytest

from clutch_model.formats.bench_csv import BENCH_COLUMNS, BenchData, read_bench, write_bench
from clutch_model.errors import DataError

HEADER = ",".join(BENCH_COLUMNS)


def _table(n=7, seed=0):
    rng = np.random.default_rng(seed)
    return BenchData(slip_speed_rad_s=rng.uniform(0.005, 15, n), pressure_mpa=rng.uniform(0.1, 6, n),
                     plate_temperature_c=rng.uniform(30, 130, n), sump_temperature_c=rng.uniform(30, 120, n),
                     friction_coefficient=rng.uniform(0.1, 0.3, n))


def test_round_trip_exact(tmp_path):
    data = _table()
    path = write_bench(tmp_path / "b.csv", data)
    assert path.read_text().splitlines()[0] == HEADER
    back = read_bench(path)
    assert len(back) == 7
    for c in BENCH_COLUMNS:
        np.testing.assert_array_equal(getattr(back, c), getattr(data, c))


def test_columns_any_order_extra_ignored_blank_lines_crlf(tmp_path):
    p = tmp_path / "b.csv"
    p.write_bytes(b"\xef\xbb\xbf" + (
        "friction_coefficient, note ,pressure_mpa,sump_temperature_c,plate_temperature_c,slip_speed_rad_s\r\n"
        "0.21,first,1.5,60,62.5,0.01\r\n\r\n"
        " 0.19 ,x,3,60,64,5\r\n").encode())
    b = read_bench(p)
    np.testing.assert_array_equal(b.friction_coefficient, [0.21, 0.19])
    np.testing.assert_array_equal(b.slip_speed_rad_s, [0.01, 5.0])
    np.testing.assert_array_equal(b.plate_temperature_c, [62.5, 64.0])


@pytest.mark.parametrize("text, needle", [
    ("", "empty file"),
    (HEADER + "\n", "no data rows"),
    ("slip_speed_rad_s,pressure_mpa,plate_temperature_c,friction_coefficient\n1,2,3,4\n",
     ":1: header lacks column(s) sump_temperature_c"),
    (HEADER + "\n1,2,3,4,0.2\n1,2,3,4\n", ":3: expected 5 fields, got 4"),
    (HEADER + "\n1,2,3,4,0.2\n1,2,abc,4,0.2\n", ":3: column plate_temperature_c: 'abc' is not a number"),
    (HEADER + "\n1,2,3,4,nan\n", ":2: column friction_coefficient: non-finite"),
    (HEADER + "\n1,inf,3,4,0.2\n", ":2: column pressure_mpa: non-finite"),
    (HEADER + ",pressure_mpa\n1,2,3,4,0.2,5\n", "duplicate column(s) pressure_mpa"),
])
def test_bad_csv_one_line_errors(tmp_path, text, needle):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(DataError) as exc:
        read_bench(p)
    msg = str(exc.value)
    assert needle in msg
    assert str(p) in msg
    assert "\n" not in msg


def test_missing_and_binary_files(tmp_path):
    with pytest.raises(DataError, match="not found"):
        read_bench(tmp_path / "nope.csv")
    p = tmp_path / "bin.csv"
    p.write_bytes(b"\xff\xfe\x00\x01\x80\x81")
    with pytest.raises(DataError):
        read_bench(p)
    with pytest.raises(DataError):
        read_bench(tmp_path)


def test_length_mismatch_rejected():
    with pytest.raises(DataError, match="differ in length"):
        BenchData(slip_speed_rad_s=[1, 2], pressure_mpa=[1], plate_temperature_c=[1, 2],
                  sump_temperature_c=[1, 2], friction_coefficient=[1, 2])
