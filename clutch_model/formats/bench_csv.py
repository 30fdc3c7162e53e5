"""Bench data of the SAE#2 friction test (thesis §5.1, "verification dataset").

The SAE#2 (SAE J2490 μPVT) bench holds slip speed and sump temperature constant, steps the
apply pressure, and logs plate temperature and the friction coefficient; then it moves to the
next slip speed, and the whole sweep is repeated at other sump temperatures.

File format (docs/bags.md, "Bench data"): a CSV file whose header holds the five columns

    slip_speed_rad_s,pressure_mpa,plate_temperature_c,sump_temperature_c,friction_coefficient

in any order (extra columns are ignored), one row per bench point, every value a finite number.
``read_bench`` rejects anything else with a one-line ``DataError`` naming the file and line.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clutch_model.errors import DataError

BENCH_COLUMNS = ("slip_speed_rad_s", "pressure_mpa", "plate_temperature_c",
                 "sump_temperature_c", "friction_coefficient")


@dataclass
class BenchData:
    """One bench table; the five arrays have one entry per bench point (SI units, P in MPa)."""

    slip_speed_rad_s: np.ndarray
    pressure_mpa: np.ndarray
    plate_temperature_c: np.ndarray
    sump_temperature_c: np.ndarray
    friction_coefficient: np.ndarray
    source: str = "<memory>"

    def __post_init__(self):
        arrays = [np.asarray(getattr(self, c), dtype=float).ravel() for c in BENCH_COLUMNS]
        n = arrays[0].size
        if any(a.size != n for a in arrays):
            raise DataError(f"{self.source}: bench columns differ in length "
                            f"({', '.join(str(a.size) for a in arrays)})")
        for name, a in zip(BENCH_COLUMNS, arrays):
            setattr(self, name, a)

    def __len__(self) -> int:
        return int(self.slip_speed_rad_s.size)

    def columns(self) -> dict:
        """{column name: array} in contract order."""
        return {c: getattr(self, c) for c in BENCH_COLUMNS}

    def subset(self, mask) -> "BenchData":
        """The rows selected by a boolean mask or index array."""
        return BenchData(**{c: getattr(self, c)[mask] for c in BENCH_COLUMNS}, source=self.source)


def _parse_float(text: str):
    try:
        return float(text)
    except ValueError:
        return None


def read_bench(path) -> BenchData:
    """Read and validate a bench CSV (see the module docstring). Raises DataError."""
    path = Path(path)
    try:
        fh = path.open("r", newline="", encoding="utf-8-sig")
    except FileNotFoundError:
        raise DataError(f"bench file not found: {path}") from None
    except IsADirectoryError:
        raise DataError(f"bench file is a directory: {path}") from None
    except OSError as exc:
        raise DataError(f"cannot read bench file {path}: {exc.strerror}") from None
    with fh:
        try:
            rows = list(_numbered_rows(fh))
        except UnicodeDecodeError:
            raise DataError(f"{path}: not a text (UTF-8) CSV file") from None
        except csv.Error as exc:
            raise DataError(f"{path}: malformed CSV ({exc})") from None
    if not rows:
        raise DataError(f"{path}: empty file (expected header {','.join(BENCH_COLUMNS)})")
    header_line, header = rows[0]
    names = [h.strip() for h in header]
    missing = [c for c in BENCH_COLUMNS if c not in names]
    if missing:
        raise DataError(f"{path}:{header_line}: header lacks column(s) {', '.join(missing)} "
                        f"(expected {','.join(BENCH_COLUMNS)})")
    dup = sorted({c for c in BENCH_COLUMNS if names.count(c) > 1})
    if dup:
        raise DataError(f"{path}:{header_line}: duplicate column(s) {', '.join(dup)}")
    index = {c: names.index(c) for c in BENCH_COLUMNS}
    data = {c: [] for c in BENCH_COLUMNS}
    for line, fields in rows[1:]:
        if len(fields) != len(names):
            raise DataError(f"{path}:{line}: expected {len(names)} fields, got {len(fields)}")
        for c, j in index.items():
            text = fields[j].strip()
            value = _parse_float(text)
            if value is None:
                shown = text if len(text) <= 20 else text[:17] + "..."
                raise DataError(f"{path}:{line}: column {c}: '{shown}' is not a number")
            if not math.isfinite(value):
                raise DataError(f"{path}:{line}: column {c}: non-finite value '{text}'")
            data[c].append(value)
    if not data[BENCH_COLUMNS[0]]:
        raise DataError(f"{path}: no data rows after the header")
    return BenchData(**{c: np.asarray(v, dtype=float) for c, v in data.items()}, source=str(path))


def _numbered_rows(fh):
    """(line number, fields) of the non-blank CSV records."""
    reader = csv.reader(fh)
    for fields in reader:
        if not fields or all(not f.strip() for f in fields):
            continue
        yield reader.line_num, fields


def write_bench(path, data: BenchData) -> Path:
    """Write a bench table with the contract header; floats round-trip exactly (repr)."""
    path = Path(path)
    if not isinstance(data, BenchData):
        data = BenchData(**{c: data[c] for c in BENCH_COLUMNS})
    path.parent.mkdir(parents=True, exist_ok=True)
    cols = [getattr(data, c) for c in BENCH_COLUMNS]
    lines = [",".join(BENCH_COLUMNS)]
    for k in range(len(data)):
        lines.append(",".join(repr(float(col[k])) for col in cols))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
