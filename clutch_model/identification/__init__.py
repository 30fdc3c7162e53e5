"""Identification of the clutch model (thesis chapter 5 and beyond).

- ``friction_fit``  fit_friction(bench, base_model, mu_offset) -> FrictionFitResult  (§5.2.1)
- ``thermal_fit``   fit_viscosity(theta, mu), fit_heat_transfer(runs, model)       (§5.2.2)
- ``calibrate``     calibrate_friction(model, runs_or_campaign, ...) -> CalibrationResult
- ``montecarlo``    run_montecarlo(model, runs, n_samples, spread, seed, scheduler=...)  (§5.3, §6.2.2)
- ``halving``       interval_halving(f_many, a, b)                                   (table 6.4)
- ``sensitivity``   friction_sensitivity, parameter_sensitivities (§3.3), identifiable_coefficients
- ``box``           constraint checks over the (P, theta) box, friction_positive(a, i)
- ``evaluate``      batch RMSE of coefficient sets on a campaign (pure chunk function)
- ``plots``         figures; synthetic data with known truth is in ``clutch_model.virtual_car``

Submodules are imported on first use (``from clutch_model.identification import fit_friction``
works) so the CLI stays quick to start.
"""
from __future__ import annotations

import importlib
import re

_EXPORTS = {
    "fit_friction": "friction_fit", "FrictionFitResult": "friction_fit",
    "fit_viscosity": "thermal_fit", "fit_heat_transfer": "thermal_fit",
    "calibrate_friction": "calibrate", "CalibrationResult": "calibrate",
    "run_montecarlo": "montecarlo", "MonteCarloResult": "montecarlo", "draw_samples": "montecarlo",
    "interval_halving": "halving",
    "friction_sensitivity": "sensitivity", "parameter_sensitivities": "sensitivity",
    "identifiability_screen": "sensitivity", "identifiable_coefficients": "sensitivity",
    "friction_positive": "box", "friction_positive_many": "box", "check_constraints": "box",
}

__all__ = sorted(_EXPORTS) + ["parse_coefficients"]


def __getattr__(name):
    if name in _EXPORTS:
        mod = importlib.import_module(f".{_EXPORTS[name]}", __name__)
        return getattr(mod, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def parse_coefficients(text: str, keep_order: bool = False) -> list:
    """'a3,a4' / '3 4' / 'a0-a4' -> [3, 4] / [3, 4] / [0, 1, 2, 3, 4]; '' or 'none' -> [].
    Sorted and unique unless ``keep_order`` (then in the given order, first occurrence)."""
    from clutch_model.errors import ParamsError

    text = (text or "").strip().lower()
    if text in ("", "none"):
        return []
    out = []
    for part in re.split(r"[,\s]+", text):
        if not part:
            continue
        m = re.fullmatch(r"a?(\d+)(?:-a?(\d+))?", part)
        if not m:
            raise ParamsError(f"bad coefficient '{part}' (use a0..a19, e.g. a3,a4 or a0-a4)")
        lo = int(m.group(1))
        hi = int(m.group(2)) if m.group(2) else lo
        if not (0 <= lo <= hi <= 19):
            raise ParamsError(f"coefficient range '{part}' is outside a0..a19")
        out.extend(range(lo, hi + 1))
    if keep_order:
        return list(dict.fromkeys(out))
    return sorted(set(out))


# the project-wide JSON cleaner (kept importable from here for older callers)
from clutch_model.formats.results import jsonable  # noqa: E402,F401
