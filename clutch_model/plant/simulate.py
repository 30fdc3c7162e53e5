"""Simulators over the compiled plant equations, in the manner of scipy's solve_ivp:
plain arrays in, a result object out.

- ``simulate``: one trajectory over sampled inputs (replay timing of docs/bags.md).
- ``simulate_batch``: many parameter sets on the same inputs (Monte Carlo), in parallel.
- ``Plant``: the real-time step simulator the ROS node drives (state in, inputs held over
  dt, state out).
- ``ChunkedSimulation``: ``simulate`` one chunk of rows at a time, resuming from the state at
  the chunk boundary (memory bounded by a chunk; the same numbers as one call, bit for bit).
All of them run the same kernel functions (clutch_model.plant.kernels).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clutch_model.plant import kernels as K
from clutch_model.plant.mechanisms import apply_measurement
from clutch_model.plant.params import ClutchModel


@dataclass
class SimResult:
    """One simulated trajectory; every array has the length of ``t``."""

    t: np.ndarray
    torque_nm: np.ndarray
    asperity_torque_nm: np.ndarray
    hydrodynamic_torque_nm: np.ndarray
    drag_torque_nm: np.ndarray
    friction_coefficient: np.ndarray
    film_thickness_m: np.ndarray
    pack_temperature_c: np.ndarray
    viscosity_pa_s: np.ndarray
    power_w: np.ndarray
    energy_j: np.ndarray
    locked: np.ndarray
    pack_force_n: np.ndarray
    force_clamped: np.ndarray
    pressure_mpa: np.ndarray
    out_of_range: np.ndarray
    asperity_pressure_pa: np.ndarray


@dataclass
class BatchResult:
    torque_nm: np.ndarray            # (n_sets, n)
    pack_temperature_c: np.ndarray   # (n_sets, n)


def _as_inputs(t, applied_force_n, slip_speed_rad_s, sump_temperature_c, run_start):
    t = np.ascontiguousarray(t, dtype=float)
    n = t.size
    f = np.ascontiguousarray(np.broadcast_to(np.asarray(applied_force_n, float), (n,)))
    w = np.ascontiguousarray(np.broadcast_to(np.asarray(slip_speed_rad_s, float), (n,)))
    s = np.ascontiguousarray(np.broadcast_to(np.asarray(sump_temperature_c, float), (n,)))
    if run_start is None:
        rs = np.zeros(n, dtype=np.bool_)
    else:
        rs = np.ascontiguousarray(run_start, dtype=np.bool_)
    if n:
        rs[0] = True
    for name, arr in (("time", t), ("applied force", f), ("slip speed", w), ("sump temperature", s)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} has non-finite samples")
    return t, f, w, s, rs


def _sim_result(t, out) -> SimResult:
    return SimResult(
        t=t, torque_nm=out[:, K.O_TORQUE], asperity_torque_nm=out[:, K.O_TA],
        hydrodynamic_torque_nm=out[:, K.O_TH], drag_torque_nm=out[:, K.O_DRAG],
        friction_coefficient=out[:, K.O_MU], film_thickness_m=out[:, K.O_H],
        pack_temperature_c=out[:, K.O_THETA], viscosity_pa_s=out[:, K.O_VISC],
        power_w=out[:, K.O_POWER], energy_j=out[:, K.O_ENERGY], locked=out[:, K.O_LOCKED] > 0.5,
        pack_force_n=out[:, K.O_FPACK], force_clamped=out[:, K.O_CLAMPED] > 0.5,
        pressure_mpa=out[:, K.O_PRESSURE_MPA], out_of_range=out[:, K.O_RANGE] > 0.5,
        asperity_pressure_pa=out[:, K.O_PA])


def _start_states(start_index, start_states, n):
    """Checked (start_index int64 (n,), start_states float64 (m, N_STATE)) or None."""
    if start_states is None:
        return None
    si = np.ascontiguousarray(start_index, dtype=np.int64)
    ss = np.ascontiguousarray(np.atleast_2d(start_states), dtype=float)
    if si.shape != (n,) or ss.shape[1] != K.N_STATE or (si.size and si.max() >= ss.shape[0]):
        raise ValueError("start_index must give, for each row, -1 or a row of start_states (m, N_STATE)")
    return si, ss


def simulate(model: ClutchModel, t, applied_force_n, slip_speed_rad_s, sump_temperature_c,
             run_start=None, energy0_j: float = 0.0, start_index=None, start_states=None) -> SimResult:
    """Simulate the plant over sampled inputs (zero-order hold between samples).

    ``run_start`` marks rows where a new test run (bag) starts: the plant restarts there
    (film at initial.film_thickness, pack at the sump temperature) while the dissipated
    energy carries on (friction_degradation). ``start_states`` (m, N_STATE) with
    ``start_index`` (one per row, -1 = none): a run_start row k with start_index[k] = j starts
    from the plant state start_states[j] instead (the state a simulation had after that row,
    ``ChunkedSimulation.state``; diagnosis.sample). Returns the plant signals at every sample.
    """
    t, f, w, s, rs = _as_inputs(t, applied_force_n, slip_speed_rad_s, sump_temperature_c, run_start)
    given = _start_states(start_index, start_states, t.size)
    if given is None:
        out = K.run_trajectory(model.vector(), t, f, w, s, rs, float(energy0_j))
    else:
        out = K.run_trajectory_from(model.vector(), t, f, w, s, rs, float(energy0_j), *given)
    return _sim_result(t, out)


class ChunkedSimulation:
    """``simulate`` over consecutive chunks of rows: each ``run`` continues from the plant
    state after the previous chunk's last row (film, pack temperature, actuator lag and
    hysteresis, energy, slip sign and angle, discovered-term filters, and that row's inputs,
    which are held over the step into the next chunk). Splitting the rows anywhere — mid
    engagement included — gives the numbers of one ``simulate`` call bit for bit (the kernel
    runs the same row code in the same order). The kernel releases the GIL.

    >>> sim = ChunkedSimulation(model, energy0_j=0.0)
    >>> for t, f, w, s in chunks:          # the first chunk starts a run
    ...     res = sim.run(t, f, w, s)      # SimResult of these rows
    """

    def __init__(self, model: ClutchModel, energy0_j: float = 0.0):
        self.model = model
        self._p = model.vector()
        self._d = None                        # on the first run (in the thread that simulates)
        self.state = np.zeros(K.N_STATE)
        self.state[K.S_ENERGY] = float(energy0_j)
        self.carry = np.zeros(K.N_CARRY)      # the last row simulated (time, slip, sump)
        self._buf = np.zeros((0, K.N_OUT))

    @property
    def energy_j(self) -> float:
        return float(self.state[K.S_ENERGY])

    def branch(self) -> "ChunkedSimulation":
        """An independent simulation that goes on from this one's state (for trying two
        continuations of the same rows)."""
        twin = ChunkedSimulation(self.model)
        twin._p, twin._d = self._p, self._d
        twin.state, twin.carry = self.state.copy(), self.carry.copy()
        return twin

    def run(self, t, applied_force_n, slip_speed_rad_s, sump_temperature_c, run_start=None,
            copy: bool = True) -> SimResult:
        """Simulate the next rows; ``run_start`` marks rows that restart the plant (the very
        first row always does). ``copy=False``: the result's arrays are views of a buffer the
        next call overwrites."""
        t = np.ascontiguousarray(t, dtype=float)
        n = t.size
        f = np.ascontiguousarray(np.broadcast_to(np.asarray(applied_force_n, float), (n,)))
        w = np.ascontiguousarray(np.broadcast_to(np.asarray(slip_speed_rad_s, float), (n,)))
        s = np.ascontiguousarray(np.broadcast_to(np.asarray(sump_temperature_c, float), (n,)))
        rs = np.zeros(n, dtype=np.bool_) if run_start is None else np.array(run_start, dtype=np.bool_)
        if n and self.carry[K.C_HAS_PREV] == 0.0:
            rs[0] = True
        for name, arr in (("time", t), ("applied force", f), ("slip speed", w), ("sump temperature", s)):
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{name} has non-finite samples")
        if copy:
            out = np.zeros((n, K.N_OUT))
        else:
            if self._buf.shape[0] < n:
                self._buf = np.zeros((n, K.N_OUT))
            out = self._buf[:n]
        if self._d is None:
            self._d = K.derived_constants(self._p)
        K.run_chunk(self._p, self._d, t, f, w, s, rs, self.state, self.carry, out)
        return _sim_result(t, out)


def predict_measured_torque(model: ClutchModel, t, torque_nm, run_start=None) -> np.ndarray:
    """What the torque sensor reads: the model's measurement mechanisms applied."""
    t = np.asarray(t, dtype=float)
    rs = np.zeros(t.size, bool) if run_start is None else np.asarray(run_start, bool)
    return apply_measurement(model.mechanisms, t, np.asarray(torque_nm, float), rs)


def parameter_matrix(models) -> np.ndarray:
    return np.ascontiguousarray(np.stack([m.vector() for m in models]))


def simulate_batch(param_matrix, t, applied_force_n, slip_speed_rad_s, sump_temperature_c,
                   run_start=None, energy0_j: float = 0.0, start_index=None, start_states=None) -> BatchResult:
    """Run many parameter sets (rows of ``param_matrix``, see ``ClutchModel.vector``, or a
    list of ClutchModel) over the same inputs, in parallel over the sets. ``start_index`` /
    ``start_states``: runs started from given plant states, as in ``simulate``."""
    if not isinstance(param_matrix, np.ndarray):
        param_matrix = parameter_matrix(param_matrix)
    pm = np.ascontiguousarray(np.atleast_2d(param_matrix), dtype=float)
    t, f, w, s, rs = _as_inputs(t, applied_force_n, slip_speed_rad_s, sump_temperature_c, run_start)
    given = _start_states(start_index, start_states, t.size)
    if given is None:
        torque, theta = K.run_batch(pm, t, f, w, s, rs, float(energy0_j))
    else:
        torque, theta = K.run_batch_from(pm, t, f, w, s, rs, float(energy0_j), *given)
    return BatchResult(torque_nm=torque, pack_temperature_c=theta)


class Plant:
    """Real-time step simulator: ``sample`` the latest inputs, read the record, ``advance``.

    >>> plant = Plant(model); plant.reset(force, sump)
    >>> rec = plant.sample(force, slip, sump)     # outputs at the current state
    >>> plant.advance(dt)                         # inputs of the last sample held over dt
    """

    def __init__(self, model: ClutchModel):
        self.model = model
        self._p = model.vector()
        self._d = K.derived_constants(self._p)
        self.state = np.zeros(K.N_STATE)
        self.record = np.zeros(K.N_OUT)
        self._scratch = np.zeros(K.N_OUT)
        self._slip = 0.0
        self._sump = 20.0
        self.max_pack_force_n = float(self._d[K.D_FMAX])

    def reset(self, applied_force_n: float, sump_temperature_c: float) -> None:
        self.state[:] = 0.0
        K.init_state(self.state, float(applied_force_n), float(sump_temperature_c), self._p)
        self._sump = float(sump_temperature_c)

    def sample(self, applied_force_n: float, slip_speed_rad_s: float, sump_temperature_c: float) -> np.ndarray:
        """Apply a new input sample and return the output record (see kernels.O_*)."""
        self._slip, self._sump = float(slip_speed_rad_s), float(sump_temperature_c)
        K.pack_force_target(self.state, float(applied_force_n), self._p)
        K.outputs(self.state, self._slip, self._sump, self._p, self._d, self.record)
        return self.record

    def advance(self, dt: float) -> None:
        K.advance(self.state, self._slip, self._sump, float(dt), self._p, self._d, self._scratch)

    @property
    def energy_j(self) -> float:
        return float(self.state[K.S_ENERGY])
