"""Results as JSON: the one cleaner every JSON file of the project goes through (report.json,
the fit sidecars, the Monte Carlo summary, the virtual car's metadata).

``jsonable`` turns numpy arrays and scalars into plain lists and numbers, tuples into lists,
paths into strings and dict keys into strings, and writes non-finite floats as ``null`` (so the
files parse with any strict JSON reader; ``json.dumps(..., allow_nan=False)`` then holds).
"""
from __future__ import annotations

import json
import math
from pathlib import Path, PurePath

import numpy as np


def finite_or_none(x):
    """float(x), or None when x is NaN or infinite."""
    x = float(x)
    return x if math.isfinite(x) else None


def jsonable(obj):
    """Plain JSON types, non-finite floats as None (recursively)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [jsonable(v) for v in obj.tolist()]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return finite_or_none(obj)
    if isinstance(obj, PurePath):
        return str(obj)
    return obj


def write_json(path, obj, indent: int = 2) -> Path:
    """Write ``jsonable(obj)`` as strict JSON (no NaN/Infinity) and return the path."""
    path = Path(path)
    path.write_text(json.dumps(jsonable(obj), indent=indent, allow_nan=False) + "\n")
    return path
