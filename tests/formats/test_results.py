"""The project's one JSON cleaner: numpy values become plain JSON, non-finite floats null."""
import json
import math
from pathlib import Path

import numpy as np

from clutch_model.formats.results import jsonable, write_json


def test_jsonable_plain_types_and_nonfinite_as_null():
    obj = {"a": np.float64(1.5), 3: np.int32(7), "arr": np.array([[1.0, np.nan], [np.inf, -2.0]]),
           "flag": np.bool_(True), "t": (np.float32(0.25), None, "x"), "p": Path("/tmp/r.json"),
           "nested": [{"v": float("-inf")}]}
    out = jsonable(obj)
    assert out == {"a": 1.5, "3": 7, "arr": [[1.0, None], [None, -2.0]], "flag": True,
                   "t": [0.25, None, "x"], "p": "/tmp/r.json", "nested": [{"v": None}]}
    assert type(out["3"]) is int and type(out["flag"]) is bool and type(out["a"]) is float


def test_write_json_is_strict_json(tmp_path):
    path = write_json(tmp_path / "r.json", {"rmse": np.float64(np.nan), "ci": np.array([1.0, 2.0])})

    def no_constants(name):
        raise AssertionError(f"non-standard JSON constant {name}")

    back = json.loads(path.read_text(), parse_constant=no_constants)
    assert back == {"rmse": None, "ci": [1.0, 2.0]}
    assert not math.isnan(back["ci"][0])
