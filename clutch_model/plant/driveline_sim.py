"""The clutch inside a driveline, offline and stepped (front ends over clutch_model.plant.driveline,
in the manner of simulate.py):

- ``simulate_driveline(model, t, force, torque_a, torque_b, sump, driveline)`` -> ``DrivelineResult``:
  one trajectory on sampled inputs (replay timing). The force may be a controller instead of
  samples: a callable ``force(t, speed_a, speed_b) -> N`` called at every row with the speeds
  of that instant (closed loop offline).
- ``DrivelinePlant``: the real-time step simulator the ROS node drives in driveline mode
  (``reset``, ``sample(inputs) -> record``, ``advance(dt)``, as ``Plant``).
Both run the same compiled equations.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Callable, Union

import numpy as np

from clutch_model.errors import ParamsError
from clutch_model.plant import driveline as DL
from clutch_model.plant import kernels as K
from clutch_model.plant.params import ClutchModel


@dataclass(frozen=True)
class DrivelineParams:
    """Two rotating sides (a: differential case / input, b: clutched axle) with viscous losses.
    Field names are those of the node parameters ``driveline.*``."""

    inertia_a_kgm2: float = 0.5
    inertia_b_kgm2: float = 1.2
    damping_a_nms: float = 0.05
    damping_b_nms: float = 0.05
    initial_speed_a_rad_s: float = 0.0
    initial_speed_b_rad_s: float = 0.0

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ParamsError(f"driveline.{f.name} must be a finite number, got {value!r}")
        for name in ("inertia_a_kgm2", "inertia_b_kgm2"):
            if not getattr(self, name) > 0.0:
                raise ParamsError(f"driveline.{name} must be > 0, got {getattr(self, name)}")
        for name in ("damping_a_nms", "damping_b_nms"):
            if getattr(self, name) < 0.0:
                raise ParamsError(f"driveline.{name} must be >= 0, got {getattr(self, name)}")
        for name in ("initial_speed_a_rad_s", "initial_speed_b_rad_s"):
            if abs(getattr(self, name)) > 1e5:
                raise ParamsError(f"driveline.{name} must be within +-1e5 rad/s")

    @classmethod
    def from_mapping(cls, values: dict) -> "DrivelineParams":
        unknown = set(values) - {f.name for f in fields(cls)}
        if unknown:
            raise ParamsError(f"unknown driveline parameter '{sorted(unknown)[0]}'")
        try:
            return cls(**{k: float(v) for k, v in values.items()})
        except (TypeError, ValueError) as exc:
            raise ParamsError(f"driveline parameters: {exc}") from None

    def vector(self) -> np.ndarray:
        q = np.empty(DL.N_DL_PARAMS)
        q[DL.Q_JA], q[DL.Q_JB] = self.inertia_a_kgm2, self.inertia_b_kgm2
        q[DL.Q_CA], q[DL.Q_CB] = self.damping_a_nms, self.damping_b_nms
        q[DL.Q_WA0], q[DL.Q_WB0] = self.initial_speed_a_rad_s, self.initial_speed_b_rad_s
        return q


@dataclass
class DrivelineResult:
    """One closed-loop trajectory; every array has the length of ``t``."""

    t: np.ndarray
    applied_force_n: np.ndarray
    torque_a_nm: np.ndarray
    torque_b_nm: np.ndarray
    speed_a_rad_s: np.ndarray
    speed_b_rad_s: np.ndarray
    slip_speed_rad_s: np.ndarray           # w_a - w_b, exactly 0 while locked
    clutch_torque_nm: np.ndarray           # transmitted (acts -T on a, +T on b)
    static_capacity_nm: np.ndarray
    lock_torque_nm: np.ndarray             # torque needed to keep the sides together
    locked: np.ndarray
    asperity_torque_nm: np.ndarray
    hydrodynamic_torque_nm: np.ndarray
    friction_coefficient: np.ndarray
    film_thickness_m: np.ndarray
    pack_temperature_c: np.ndarray
    pack_force_n: np.ndarray
    power_w: np.ndarray
    energy_j: np.ndarray
    driveline: DrivelineParams

    @property
    def angular_momentum_nms(self) -> np.ndarray:
        """J_a w_a + J_b w_b: the clutch torque cancels in it."""
        d = self.driveline
        return d.inertia_a_kgm2 * self.speed_a_rad_s + d.inertia_b_kgm2 * self.speed_b_rad_s


def _result(t, force, tau_a, tau_b, out, driveline) -> DrivelineResult:
    return DrivelineResult(
        t=t, applied_force_n=force, torque_a_nm=tau_a, torque_b_nm=tau_b,
        speed_a_rad_s=out[:, DL.R_WA], speed_b_rad_s=out[:, DL.R_WB], slip_speed_rad_s=out[:, DL.R_SLIP],
        clutch_torque_nm=out[:, K.O_TORQUE], static_capacity_nm=out[:, DL.R_CAPACITY],
        lock_torque_nm=out[:, DL.R_LOCK_TORQUE], locked=out[:, K.O_LOCKED] > 0.5,
        asperity_torque_nm=out[:, K.O_TA], hydrodynamic_torque_nm=out[:, K.O_TH] + out[:, K.O_DRAG],
        friction_coefficient=out[:, K.O_MU], film_thickness_m=out[:, K.O_H],
        pack_temperature_c=out[:, K.O_THETA], pack_force_n=out[:, K.O_FPACK], power_w=out[:, K.O_POWER],
        energy_j=out[:, K.O_ENERGY], driveline=driveline)


def _column(name, value, n):
    arr = np.ascontiguousarray(np.broadcast_to(np.asarray(value, dtype=float), (n,)))
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} has non-finite samples")
    return arr


ForceInput = Union[float, np.ndarray, Callable[[float, float, float], float]]


def simulate_driveline(model: ClutchModel, t, applied_force_n: ForceInput, torque_a_nm, torque_b_nm,
                       sump_temperature_c, driveline: DrivelineParams | None = None,
                       energy0_j: float = 0.0) -> DrivelineResult:
    """Simulate the clutch inside the driveline over sampled inputs (zero-order hold).

    Row k's record comes from the state at t_k (integrated from t_{k-1} with row k-1's inputs
    held) and row k's inputs. ``applied_force_n`` is samples (array or scalar) or a controller
    ``force(t_k, speed_a_k, speed_b_k) -> N`` called once per row with the speeds at t_k.
    """
    driveline = driveline or DrivelineParams()
    t = np.ascontiguousarray(t, dtype=float)
    n = t.size
    if n == 0:
        raise ValueError("empty time grid")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
        raise ValueError("time must be finite and non-decreasing")
    tau_a = _column("torque_a", torque_a_nm, n)
    tau_b = _column("torque_b", torque_b_nm, n)
    sump = _column("sump temperature", sump_temperature_c, n)
    p = DL.driveline_vector_lock_slip(model.vector())
    q = driveline.vector()
    if not callable(applied_force_n):
        force = _column("applied force", applied_force_n, n)
        out = DL.run_driveline(p, q, t, force, tau_a, tau_b, sump, float(energy0_j))
        return _result(t, force, tau_a, tau_b, out, driveline)
    plant = DrivelinePlant(model, driveline)
    controller = applied_force_n
    force = np.empty(n)
    out = np.empty((n, DL.N_DL_OUT))
    for k in range(n):
        if k:
            plant.advance(t[k] - t[k - 1])
        f = float(controller(float(t[k]), plant.speed_a_rad_s, plant.speed_b_rad_s))
        if not math.isfinite(f):
            raise ValueError(f"controller returned a non-finite force at t = {t[k]:g} s")
        if k == 0:
            plant.reset(f, sump[0], keep_energy_j=float(energy0_j))
        force[k] = f
        out[k] = plant.sample(f, tau_a[k], tau_b[k], sump[k])
    return _result(t, force, tau_a, tau_b, out, driveline)


class DrivelinePlant:
    """Real-time step simulator of the clutch in the driveline (the node's driveline mode).

    >>> plant = DrivelinePlant(model, DrivelineParams(...)); plant.reset(force, sump)
    >>> rec = plant.sample(force, torque_a, torque_b, sump)   # record at the current state
    >>> plant.advance(dt)                                      # last sample's inputs held over dt
    >>> rec = plant.step(dt, force, torque_a, torque_b, sump)  # the two in one (advance, then sample)

    ``rec`` is the kernels' record (``K.O_*``; O_TORQUE is the transmitted torque, O_LOCKED the
    stick phase) followed by ``driveline.R_WA, R_WB, R_SLIP, R_CAPACITY, R_LOCK_TORQUE``.
    ``state`` is one flat array (plant state + speeds + stick flag): copy it to snapshot and
    write it back to restore (sim-time redo of a step).
    """

    def __init__(self, model: ClutchModel, driveline: DrivelineParams | None = None):
        self.model = model
        self.driveline = driveline or DrivelineParams()
        self._p = DL.driveline_vector_lock_slip(model.vector())
        self._d = K.derived_constants(self._p)
        self._q = self.driveline.vector()
        self.state = np.zeros(DL.N_DL_STATE)
        self.record = np.zeros(DL.N_DL_OUT)
        self._scratch = np.zeros(K.N_OUT)
        self._tau_a = self._tau_b = 0.0
        self._sump = 20.0
        self.max_pack_force_n = float(self._d[K.D_FMAX])
        # compile (or load from numba's cache) every kernel now, at start-up, not on the first tick
        self.reset(0.0, 20.0)
        self.sample(0.0, 1.0, 0.0, 20.0)
        self.advance(1e-3)
        self.reset(0.0, 20.0)

    def reset(self, applied_force_n: float, sump_temperature_c: float, keep_energy_j: float = 0.0) -> None:
        """Initial film, pack at the sump temperature, the initial speeds of the driveline."""
        self.state[:] = 0.0
        self.state[K.S_ENERGY] = keep_energy_j
        DL.init_state(self.state, float(applied_force_n), float(sump_temperature_c), self._p, self._q)
        self._sump = float(sump_temperature_c)

    def sample(self, applied_force_n: float, torque_a_nm: float, torque_b_nm: float,
               sump_temperature_c: float) -> np.ndarray:
        """Apply a new input sample and return the record (see class doc)."""
        self._tau_a, self._tau_b = float(torque_a_nm), float(torque_b_nm)
        self._sump = float(sump_temperature_c)
        DL.sample(self.state, float(applied_force_n), self._tau_a, self._tau_b, self._sump,
                  self._p, self._d, self._q, self.record)
        return self.record

    def step(self, dt: float, applied_force_n: float, torque_a_nm: float, torque_b_nm: float,
             sump_temperature_c: float) -> np.ndarray:
        """advance(dt) with the previous sample's inputs held, then sample the new inputs (the
        node's sim-time order: the record at t + dt from the state there and the inputs at t + dt)."""
        self.advance(dt)
        return self.sample(applied_force_n, torque_a_nm, torque_b_nm, sump_temperature_c)

    def advance(self, dt: float) -> None:
        DL.advance(self.state, self._tau_a, self._tau_b, self._sump, float(dt), self._p, self._d,
                   self._q, self._scratch)

    @property
    def speed_a_rad_s(self) -> float:
        return float(self.state[DL.X_WA])

    @property
    def speed_b_rad_s(self) -> float:
        return float(self.state[DL.X_WB])

    @property
    def slip_speed_rad_s(self) -> float:
        """w_a - w_b (exactly 0 while locked)."""
        return 0.0 if self.locked else float(self.state[DL.X_WA] - self.state[DL.X_WB])

    @property
    def locked(self) -> bool:
        return bool(self.state[DL.X_LOCKED] > 0.5)

    @property
    def energy_j(self) -> float:
        return float(self.state[K.S_ENERGY])
