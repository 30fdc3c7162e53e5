"""clutch_model: the wet-clutch plant (pure Python + numba, never rclpy).

The names below are loaded on first use, so importing a light submodule (the error types,
the bag topic names) does not compile or load the numba kernels.
"""
from __future__ import annotations

import importlib

from clutch_model import _numba_cache  # noqa: F401  (before anything imports numba)
from clutch_model.errors import ClutchSimError, DataError, FitError, ParamsError

_LAZY = {
    "ClutchModel": "clutch_model.plant.params", "load_model": "clutch_model.plant.params",
    "save_model": "clutch_model.plant.params", "REFERENCE_CLUTCH": "clutch_model.plant.params",
    "CATALOG": "clutch_model.plant.mechanisms", "make_mechanism": "clutch_model.plant.mechanisms",
    "Plant": "clutch_model.plant.simulate", "SimResult": "clutch_model.plant.simulate",
    "BatchResult": "clutch_model.plant.simulate", "simulate": "clutch_model.plant.simulate",
    "simulate_batch": "clutch_model.plant.simulate",
    "predict_measured_torque": "clutch_model.plant.simulate",
    "DrivelineParams": "clutch_model.plant.driveline_sim", "DrivelinePlant": "clutch_model.plant.driveline_sim",
    "DrivelineResult": "clutch_model.plant.driveline_sim", "simulate_driveline": "clutch_model.plant.driveline_sim",
}

__all__ = ["ClutchSimError", "DataError", "FitError", "ParamsError", *_LAZY]


def __getattr__(name):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'clutch_model' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
