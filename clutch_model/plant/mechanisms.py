"""Candidate model extensions (CONTRACT.md, "Diagnosis: mechanism catalog").

Each mechanism is one small object, in the manner of PySINDy's candidate terms: an id,
its physical parameters with bounds, and how it changes the plant (written into the kernel
parameter vector, so the step simulator, the batch simulator and the node all apply it) or
the measurement (applied to a predicted torque trace by ``replay``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from clutch_model.plant import params as P
from clutch_model.errors import ParamsError


@dataclass
class Mechanism:
    """Base class. ``values`` maps parameter name -> value."""

    values: dict = field(default_factory=dict)

    id = "base"
    kind = "plant"  # "plant" or "measurement"
    parameters = ()
    bounds = {}
    physics = ""

    state_keys = ()  # non-fitted entries carried in the model file (campaign state)

    def __post_init__(self):
        unknown = set(self.values) - set(self.parameters) - set(self.state_keys)
        if unknown:
            raise ParamsError(f"mechanism {self.id}: unknown entry '{sorted(unknown)[0]}' "
                              f"(parameters: {', '.join(self.parameters)})")
        for name in self.parameters:
            if name not in self.values:
                raise ParamsError(f"mechanism {self.id}: missing parameter '{name}'")
            v = float(self.values[name])
            if not np.isfinite(v):
                raise ParamsError(f"mechanism {self.id}: '{name}' must be finite")
            lo, hi = self.bounds[name]
            if not (lo <= v <= hi):
                raise ParamsError(f"mechanism {self.id}: '{name}'={v} outside [{lo}, {hi}]")
            self.values[name] = v

    def copy(self):
        return type(self)({k: (list(v) if isinstance(v, list) else v) for k, v in self.values.items()})

    def to_dict(self) -> dict:
        return {"id": self.id, **{k: float(v) if k in self.parameters else v for k, v in self.values.items()}}

    @property
    def parameter_values(self) -> dict:
        return {k: self.values[k] for k in self.parameters}

    def apply_to_vector(self, p: np.ndarray) -> None:
        """Plant mechanisms write their parameters into the kernel vector."""

    def apply_to_measurement(self, t: np.ndarray, torque: np.ndarray, run_start: np.ndarray) -> np.ndarray:
        """Measurement mechanisms map plant torque to what the sensor reads."""
        return torque


class ActuatorLag(Mechanism):
    id = "actuator_lag"
    parameters = ("tau_s",)
    bounds = {"tau_s": (0.0, 2.0)}
    physics = "pack force follows the measured force through a first-order lag"

    def apply_to_vector(self, p):
        p[P.LAG_TAU_S] = self.values["tau_s"]


class ActuatorHysteresis(Mechanism):
    id = "actuator_hysteresis"
    parameters = ("ratio",)
    bounds = {"ratio": (0.0, 0.9)}
    physics = "ball-ramp friction: pack force moves only when the band F(1±ratio) pushes it"

    def apply_to_vector(self, p):
        p[P.HYST_RATIO] = self.values["ratio"]


class SpringPreload(Mechanism):
    id = "spring_preload"
    parameters = ("preload_n",)
    bounds = {"preload_n": (0.0, 50000.0)}
    physics = "return springs: pack force = max(F - preload, 0)"

    def apply_to_vector(self, p):
        p[P.PRELOAD_N] = self.values["preload_n"]


class FrictionDegradation(Mechanism):
    """``energy_history`` (optional state, written by ``diagnose``): [[log_time_ns, E_j], ...],
    the campaign's dissipated energy at known times (its runs' starts and ends). A replay whose
    first bag starts at or after a recorded time starts from that energy, so later runs replayed
    on their own continue the campaign instead of starting from a fresh lining."""

    id = "friction_degradation"
    parameters = ("energy_scale_j",)
    state_keys = ("energy_history",)
    bounds = {"energy_scale_j": (1.0, 1e15)}
    physics = "lining glazing / ATF ageing: mu_f scaled by exp(-E/energy_scale)"

    def __post_init__(self):
        super().__post_init__()
        hist = self.values.get("energy_history")
        if hist is not None:
            try:
                rows = [[int(t), float(e)] for t, e in hist]
            except (TypeError, ValueError):
                raise ParamsError("mechanism friction_degradation: energy_history must be "
                                  "[[log_time_ns, energy_j], ...]") from None
            if any(not np.isfinite(e) or e < 0 for _, e in rows):
                raise ParamsError("mechanism friction_degradation: energy_history energies must be >= 0")
            self.values["energy_history"] = sorted(rows)

    def apply_to_vector(self, p):
        p[P.ENERGY_SCALE_J] = self.values["energy_scale_j"]

    def energy_at(self, time_ns: int) -> float:
        """Campaign energy known at or before ``time_ns`` (0 before the campaign)."""
        energy = 0.0
        for t, e in self.values.get("energy_history") or []:
            if t <= time_ns:
                energy = e
        return energy


class DragTorque(Mechanism):
    id = "drag_torque"
    parameters = ("coeff_nm_per_rad_s",)
    bounds = {"coeff_nm_per_rad_s": (-1e4, 1e4)}
    physics = "open-clutch viscous drag: + coeff * w * mu(theta)/mu(60 C)"

    def apply_to_vector(self, p):
        p[P.DRAG_COEFF] = self.values["coeff_nm_per_rad_s"]


class TorqueOffset(Mechanism):
    id = "torque_offset"
    kind = "measurement"
    parameters = ("offset_nm",)
    bounds = {"offset_nm": (-1e5, 1e5)}
    physics = "torque sensor bias: measured = true + offset"

    def apply_to_measurement(self, t, torque, run_start):
        return torque + self.values["offset_nm"]


class TransportDelay(Mechanism):
    id = "transport_delay"
    kind = "measurement"
    parameters = ("delay_s",)
    bounds = {"delay_s": (0.0, 10.0)}
    physics = "measured torque lags the plant by a pure delay"

    def apply_to_measurement(self, t, torque, run_start):
        return delay_signal(t, torque, run_start, self.values["delay_s"])


def delay_signal(t, y, run_start, delay_s):
    """y(t - delay) per run, linearly interpolated, the run's first value before its start.

    Works on a 1-D trace or on (n_sets, n) traces sharing the time grid ``t``.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    out = np.empty_like(y)
    starts = np.flatnonzero(run_start)
    if starts.size == 0 or starts[0] != 0:
        starts = np.concatenate([[0], starts])
    ends = np.append(starts[1:], t.size)
    for a, b in zip(starts, ends):
        tt = t[a:b]
        q = tt - delay_s
        if y.ndim == 1:
            out[a:b] = np.interp(q, tt, y[a:b])
        else:
            # vectorised linear interpolation for many traces on one grid
            idx = np.clip(np.searchsorted(tt, q, side="right") - 1, 0, tt.size - 1)
            nxt = np.minimum(idx + 1, tt.size - 1)
            span = tt[nxt] - tt[idx]
            w = np.where(span > 0, (q - tt[idx]) / np.where(span > 0, span, 1.0), 0.0)
            w = np.clip(w, 0.0, 1.0)
            seg = y[:, a:b]
            out[:, a:b] = seg[:, idx] * (1 - w) + seg[:, nxt] * w
    return out


CATALOG = {cls.id: cls for cls in (ActuatorLag, ActuatorHysteresis, SpringPreload,
                                   FrictionDegradation, TorqueOffset, TransportDelay, DragTorque)}


def make_mechanism(mech_id: str, **values) -> Mechanism:
    if mech_id == "discovered":   # beyond the catalog: terms found from the data
        from clutch_model.plant.discovered import Discovered
        return Discovered(dict(values))
    if mech_id not in CATALOG:
        raise ParamsError(f"unknown mechanism id '{mech_id}' (known: {', '.join(CATALOG)})")
    return CATALOG[mech_id](dict(values))


def mechanism_from_dict(raw, source="<memory>") -> Mechanism:
    if not isinstance(raw, dict) or "id" not in raw:
        raise ParamsError(f"{source}: each mechanisms entry needs an 'id'")
    values = {k: v for k, v in raw.items() if k != "id"}
    try:
        return make_mechanism(str(raw["id"]), **values)
    except (TypeError, ValueError) as exc:
        raise ParamsError(f"{source}: mechanism {raw['id']}: {exc}") from None


def apply_measurement(mechanisms, t, torque, run_start):
    """Apply every measurement mechanism of a model to a plant-torque trace."""
    out = torque
    for m in mechanisms:
        if m.kind == "measurement":
            out = m.apply_to_measurement(t, out, run_start)
    return out
