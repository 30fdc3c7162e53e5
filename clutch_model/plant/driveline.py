"""The clutch inside a driveline, compiled with numba: two rotating sides coupled by the clutch
of clutch_model.plant.kernels (same film, thermal and torque equations, same parameter vector).

Side a (the differential case / input) and side b (the clutched axle), each with an inertia J
and a viscous loss c, driven by external torques tau_a, tau_b. The clutch torque T (signed)
acts -T on side a and +T on side b:

    J_a dw_a/dt = tau_a - c_a w_a - T          J_b dw_b/dt = tau_b - c_b w_b + T

Slipping (s = w_a - w_b != 0): T is the plant torque at slip s (asperity + hydrodynamic + drag,
sign of s) with the current film and pack temperature.

Stick phase (Karnopp). With the sides together at the common speed w, the torque that keeps
them together follows from both equations with dw_a/dt = dw_b/dt:

    T_lock = (J_b (tau_a - c_a w) - J_a (tau_b - c_b w)) / (J_a + J_b)

The sides stay locked (slip exactly 0, one common speed integrated exactly: (J_a + J_b) dw/dt =
tau_a + tau_b - (c_a + c_b) w) while |T_lock| <= the static capacity (asperity torque with
mu_f at w = 0, the kernel's lock-up torque) and the clutch transmits exactly T_lock. Beyond the
capacity they break loose in the direction of T_lock. Slipping sides lock when the slip enters
the band |s| < lock_slip_rad_s (or crosses zero: the crossing instant is located) and T_lock is
within the capacity; locking merges the speeds at the common speed of equal momentum.

Numerics. The slip equation is stiff near lock-up (dT/ds reaches ~1e4 N m s/rad at the
Stribeck knee against J ~ 1 kg m^2), so the speeds take L-stable linearly implicit steps (ROS2,
Verwer et al. 1999, two stages, W = I - gamma h J with dT/ds >= 0 by a finite difference):
no overshoot, no chatter at the lock boundary. Both sides see the same T, so the clutch
cancels exactly in the momentum J_a w_a + J_b w_b. The film and pack temperature advance with
kernels.advance between the two ROS2 stages (stage 1 sees the state at the sub-step's start,
stage 2 the state at its end; the heat input is the trapezoid of the start power and the power
at the predicted end slip). Sub-steps are <= MAX_STEP_S; a zero crossing of the slip inside a
sub-step is located (regula falsi on the sub-step length) and the stick test made there.

State vector (float64[N_DL_STATE]): the plant state of kernels (0..6), then w_a, w_b, locked.
Record (float64[N_DL_OUT]): the plant record of kernels (O_TORQUE = the transmitted torque), then
w_a, w_b, slip, static capacity, T_lock (torque needed to keep the sides together).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from clutch_model.plant import kernels as K

P = K.P     # the kernel parameter-vector layout, as the kernels import it

# driveline parameter vector
N_DL_PARAMS = 6
Q_JA, Q_JB, Q_CA, Q_CB, Q_WA0, Q_WB0 = range(6)

# state: plant state, then the speeds and the stick flag
X_WA, X_WB, X_LOCKED = K.N_STATE, K.N_STATE + 1, K.N_STATE + 2
N_DL_STATE = K.N_STATE + 3

# record: plant record, then
R_WA, R_WB, R_SLIP, R_CAPACITY, R_LOCK_TORQUE = range(K.N_OUT, K.N_OUT + 5)
N_DL_OUT = K.N_OUT + 5

MAX_STEP_S = 0.001          # speed sub-step; 1 kHz node ticks are one sub-step
MIN_LOCK_SLIP = 1e-9        # lock band floor (lock_slip_rad_s = 0 still locks at a located zero)
GAMMA = 1.0 - 1.0 / math.sqrt(2.0)
MAX_CROSSING_ITER = 40
MAX_EVENTS = 64             # zero crossings handled per sub-step


def driveline_vector_lock_slip(p: np.ndarray) -> np.ndarray:
    """The kernel parameter vector with the lock band floored at MIN_LOCK_SLIP (driveline use)."""
    p = np.array(p, dtype=float)
    p[P.LOCK_SLIP] = max(p[P.LOCK_SLIP], MIN_LOCK_SLIP)
    return p


@njit(cache=True)
def plant_torque(x, slip, sump, p, d, rec):
    """Plant torque at ``slip`` with the current film and pack temperature, leaving the state
    unchanged (kernels.outputs updates the slip sign and the power; both are restored)."""
    sign = x[K.S_SIGN]
    power = x[K.S_POWER]
    torque = K.outputs(x[:K.N_STATE], slip, sump, p, d, rec)
    x[K.S_SIGN] = sign
    x[K.S_POWER] = power
    return torque


@njit(cache=True)
def static_capacity(x, sump, p, d, rec):
    """Static torque capacity [N m]: the kernel's lock-up torque (asperity torque with mu_f at
    w = 0, no hydrodynamic part), magnitude."""
    return abs(plant_torque(x, 0.0, sump, p, d, rec))


@njit(cache=True)
def lock_torque(q, w, tau_a, tau_b):
    """Torque the clutch must carry to keep both sides at the common speed w."""
    ja, jb = q[Q_JA], q[Q_JB]
    return (jb * (tau_a - q[Q_CA] * w) - ja * (tau_b - q[Q_CB] * w)) / (ja + jb)


@njit(cache=True)
def common_speed(x, q):
    """Speed of both sides at equal angular momentum."""
    ja, jb = q[Q_JA], q[Q_JB]
    return (ja * x[X_WA] + jb * x[X_WB]) / (ja + jb)


@njit(cache=True)
def _locked_speed(q, w0, tau, h):
    """Exact common speed after h: (J_a + J_b) dw/dt = tau - (c_a + c_b) w."""
    j = q[Q_JA] + q[Q_JB]
    c = q[Q_CA] + q[Q_CB]
    z = -c * h / j
    phi1 = 1.0 + 0.5 * z if abs(z) < 1e-8 else math.expm1(z) / z
    return w0 + (tau - c * w0) / j * h * phi1


@njit(cache=True)
def _slope(x, s, t0, sump, p, d, rec):
    """dT/ds >= 0 at slip s by a one-sided difference away from zero (0 inside the lock band,
    where the torque is the capacity)."""
    if abs(s) < p[P.LOCK_SLIP]:
        return 0.0
    delta = 1e-7 * (abs(s) + 1e-3)
    s2 = s + delta if s > 0.0 else s - delta
    k = (plant_torque(x, s2, sump, p, d, rec) - t0) / (s2 - s)
    return k if k > 0.0 else 0.0


@njit(cache=True)
def _slip_step(x, h, tau_a, tau_b, sump, p, d, q, rec, scratch):
    """One coupled sub-step of length h while slipping, committed to x: ROS2 on the speeds,
    the film and pack temperature advanced in between (stage 1 sees the state at the start,
    stage 2 the state at the end, so the film's squeeze enters to second order; the heat input
    is the trapezoid of the start power and the power at the predicted end slip)."""
    ja, jb, ca, cb = q[Q_JA], q[Q_JB], q[Q_CA], q[Q_CB]
    wa, wb = x[X_WA], x[X_WB]
    s = wa - wb
    t0 = plant_torque(x, s, sump, p, d, rec)
    k = _slope(x, s, t0, sump, p, d, rec)
    gh = GAMMA * h
    m11 = 1.0 + gh * (ca + k) / ja
    m12 = -gh * k / ja
    m21 = -gh * k / jb
    m22 = 1.0 + gh * (cb + k) / jb
    det = m11 * m22 - m12 * m21
    fa = (tau_a - ca * wa - t0) / ja
    fb = (tau_b - cb * wb + t0) / jb
    k1a = (m22 * fa - m12 * fb) / det
    k1b = (m11 * fb - m21 * fa) / det
    wa2 = wa + h * k1a
    wb2 = wb + h * k1b
    s2 = wa2 - wb2
    if s2 * x[K.S_SIGN] < 0.0:
        # the stage point lies beyond zero slip: the torque is continued from this side (its
        # value at zero, the capacity with the current sign), so the step is a continuous
        # function of h and a crossing is located, not jumped over
        s2 = 0.0
    K.advance(x[:K.N_STATE], s2, sump, h, p, d, scratch)
    t2 = plant_torque(x, s2, sump, p, d, rec)
    fa = (tau_a - ca * wa2 - t2) / ja - 2.0 * k1a
    fb = (tau_b - cb * wb2 + t2) / jb - 2.0 * k1b
    k2a = (m22 * fa - m12 * fb) / det
    k2b = (m11 * fb - m21 * fa) / det
    x[X_WA] = wa + h * (1.5 * k1a + 0.5 * k2a)
    x[X_WB] = wb + h * (1.5 * k1b + 0.5 * k2b)
    s1 = x[X_WA] - x[X_WB]
    if s1 * x[K.S_SIGN] >= 0.0:
        K.outputs(x[:K.N_STATE], s1, sump, p, d, rec)   # power at the end: next step's start


@njit(cache=True)
def try_stick(x, tau_a, tau_b, sump, p, d, q, rec):
    """Karnopp: inside the lock band, lock (merge the speeds at equal momentum) when the torque
    needed to keep the sides together is within the static capacity. Returns the lock flag."""
    if x[X_LOCKED] > 0.5:
        return True
    if abs(x[X_WA] - x[X_WB]) >= p[P.LOCK_SLIP]:
        return False
    w = common_speed(x, q)
    if abs(lock_torque(q, w, tau_a, tau_b)) <= static_capacity(x, sump, p, d, rec):
        x[X_WA] = w
        x[X_WB] = w
        x[X_LOCKED] = 1.0
        x[K.S_POWER] = 0.0
        return True
    return False


@njit(cache=True)
def _break_loose(x, t_lock):
    """Slip starts in the direction the torques drive it; inside the band the clutch carries
    the capacity with that sign."""
    x[X_LOCKED] = 0.0
    x[K.S_SIGN] = 1.0 if t_lock >= 0.0 else -1.0


@njit(cache=True)
def _locate_zero(x, x0, h, s0, s1, tau_a, tau_b, sump, p, d, q, rec, scratch):
    """Step from x0 to where the slip reaches zero (Illinois regula falsi on the step length);
    x holds the state there. Returns the step length."""
    tol = 1e-3 * p[P.LOCK_SLIP]
    a, fa = 0.0, s0
    b, fb = h, s1
    side = 0
    hh = h
    for _ in range(MAX_CROSSING_ITER):
        hh = (a * fb - b * fa) / (fb - fa)
        if not (hh > a and hh < b):
            hh = 0.5 * (a + b)
        x[:] = x0
        _slip_step(x, hh, tau_a, tau_b, sump, p, d, q, rec, scratch)
        s = x[X_WA] - x[X_WB]
        if abs(s) <= tol:
            break
        if s * fa > 0.0:
            a, fa = hh, s
            if side == -1:
                fb *= 0.5
            side = -1
        else:
            b, fb = hh, s
            if side == 1:
                fa *= 0.5
            side = 1
    return hh


@njit(cache=True)
def _substep(x, x0, h, tau_a, tau_b, sump, p, d, q, rec, scratch):
    band = p[P.LOCK_SLIP]
    remaining = h
    events = 0
    while remaining > 0.0:
        if x[X_LOCKED] > 0.5:
            w = x[X_WA]
            t_lock = lock_torque(q, w, tau_a, tau_b)
            if abs(t_lock) <= static_capacity(x, sump, p, d, rec):
                w1 = _locked_speed(q, w, tau_a + tau_b, remaining)
                x[X_WA] = w1
                x[X_WB] = w1
                K.advance(x[:K.N_STATE], 0.0, sump, remaining, p, d, scratch)
                return
            _break_loose(x, t_lock)
        s0 = x[X_WA] - x[X_WB]
        x0[:] = x
        _slip_step(x, remaining, tau_a, tau_b, sump, p, d, q, rec, scratch)
        s1 = x[X_WA] - x[X_WB]
        if s0 * s1 < 0.0 and abs(s0) >= band and events < MAX_EVENTS:
            # the slip crosses zero inside the step: go to the crossing, then stick or slip on
            events += 1
            hh = _locate_zero(x, x0, remaining, s0, s1, tau_a, tau_b, sump, p, d, q, rec, scratch)
            remaining -= hh
            if abs(x[X_WA] - x[X_WB]) < band and not try_stick(x, tau_a, tau_b, sump, p, d, q, rec):
                _break_loose(x, lock_torque(q, common_speed(x, q), tau_a, tau_b))
            continue
        try_stick(x, tau_a, tau_b, sump, p, d, q, rec)
        return


@njit(cache=True)
def advance(x, tau_a, tau_b, sump, dt, p, d, q, scratch):
    """Integrate speeds, film and pack temperature over dt with the inputs held (the pack-force
    target is the one of the last sample). ``p`` with the lock band floored (see
    driveline_vector_lock_slip)."""
    if not (dt > 0.0):
        return
    n = int(math.ceil(dt / MAX_STEP_S - 1e-9))
    if n < 1:
        n = 1
    h = dt / n
    rec = np.empty(K.N_OUT)
    x0 = np.empty(N_DL_STATE)
    for _ in range(n):
        _substep(x, x0, h, tau_a, tau_b, sump, p, d, q, rec, scratch)


@njit(cache=True)
def init_state(x, applied_force, sump, p, q):
    """Start: plant initial state (kernels.init_state; energy carried), initial speeds; sides
    closer than the lock band start locked at their common speed."""
    K.init_state(x[:K.N_STATE], applied_force, sump, p)
    x[X_WA] = q[Q_WA0]
    x[X_WB] = q[Q_WB0]
    x[X_LOCKED] = 0.0
    if abs(q[Q_WA0] - q[Q_WB0]) < p[P.LOCK_SLIP]:
        w = common_speed(x, q)
        x[X_WA] = w
        x[X_WB] = w
        x[X_LOCKED] = 1.0


@njit(cache=True)
def sample(x, applied_force, tau_a, tau_b, sump, p, d, q, out):
    """Apply one input sample and write the record at the current state (see module doc).
    Sticks inside the band when it can, breaks loose when the new inputs need more than the
    capacity. Returns the transmitted torque."""
    ps = x[:K.N_STATE]
    K.pack_force_target(ps, applied_force, p)
    try_stick(x, tau_a, tau_b, sump, p, d, q, out)
    capacity = static_capacity(x, sump, p, d, out)
    t_lock = lock_torque(q, common_speed(x, q), tau_a, tau_b)
    if x[X_LOCKED] > 0.5 and abs(t_lock) > capacity:
        _break_loose(x, t_lock)
    if x[X_LOCKED] > 0.5:
        K.outputs(ps, 0.0, sump, p, d, out)   # record at zero slip: power 0
        out[K.O_TORQUE] = t_lock
        out[K.O_TA] = t_lock
        out[K.O_TH] = 0.0
        out[K.O_DRAG] = 0.0
        out[K.O_POWER] = 0.0
        out[K.O_LOCKED] = 1.0
        slip = 0.0
    else:
        slip = x[X_WA] - x[X_WB]
        K.outputs(ps, slip, sump, p, d, out)
        out[K.O_LOCKED] = 0.0
    out[R_WA] = x[X_WA]
    out[R_WB] = x[X_WB]
    out[R_SLIP] = slip
    out[R_CAPACITY] = capacity
    out[R_LOCK_TORQUE] = t_lock
    return out[K.O_TORQUE]


@njit(cache=True)
def run_driveline(p, q, t, force, tau_a, tau_b, sump, energy0):
    """Replay timing: row k's record from the state at t_k (integrated from t_{k-1} with row
    k-1's inputs held) and row k's inputs."""
    n = t.size
    d = K.derived_constants(p)
    out = np.zeros((n, N_DL_OUT))
    x = np.zeros(N_DL_STATE)
    scratch = np.zeros(K.N_OUT)
    x[K.S_ENERGY] = energy0
    for k in range(n):
        if k == 0:
            init_state(x, force[0], sump[0], p, q)
        else:
            advance(x, tau_a[k - 1], tau_b[k - 1], sump[k - 1], t[k] - t[k - 1], p, d, q, scratch)
        sample(x, force[k], tau_a[k], tau_b[k], sump[k], p, d, q, out[k])
    return out


def _drop_stale_cache() -> None:
    """numba invalidates a cached function only when its own source file changes; these kernels
    compile the functions of kernels.py (and what it imports from clutch_model.plant) into
    themselves, so their cache entries older than any other module of clutch_model.plant are
    removed here and recompiled on first use."""
    import os
    from pathlib import Path

    try:
        cache_dir = sample._cache._cache_path
        here = Path(__file__).resolve()
        newest_dependency = max(f.stat().st_mtime for f in here.parent.rglob("*.py")
                                if not f.name.startswith("driveline"))
        for name in os.listdir(cache_dir):
            if name.startswith("driveline.") and name.endswith((".nbi", ".nbc")):
                path = os.path.join(cache_dir, name)
                if os.stat(path).st_mtime < newest_dependency:
                    os.remove(path)
    except (AttributeError, OSError, ValueError):
        pass   # no cache configured, or another process got there first


_drop_stale_cache()
