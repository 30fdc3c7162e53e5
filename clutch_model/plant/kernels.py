"""The plant equations (thesis eq. 3.1-3.18, 4.9-4.14, the details pinned in docs/model.md),
compiled with numba. One set of equations serves the step simulator (node), the
single-trajectory simulator (replay) and the batch simulator (Monte Carlo).

State vector (float64[N_STATE]):
  0 film_thickness h [m]        1 pack_temperature [C]
  2 hysteresis output [N]       3 pack force [N]
  4 energy E = int |w T| dt [J] 5 sign of the last slip above the lock tolerance
  6 heat power |w T| at the last output [W]
  7 actuator force (lag state) [N]  8 measured-force target of the lag [N]
  9 slip angle int w dt since the run start, wrapped to [-pi, pi) [rad]
  10 pack force before the last advance [N]   11 length of the last advance [s]
  12 heat power |w T| of the output before the last advance (the previous row's) [W]
  13.. low-pass states of the discovered terms (one per term slot)
  then memo slots (``_memo_*``): the viscosity, asperity pressure and hydrodynamic flow
  factor last computed, with every input they depend on as their key. A row evaluates them at
  the same film thickness and pack temperature several times (film step, end-of-step power,
  the row's outputs); a value is reused only when its keys are equal, so it is the value the
  call would return, bit for bit, whatever state or parameters come next.
  last: the slip input held over the last advance [rad/s] (S_WPREV)

Force chain (the pack_force path, mechanisms in catalog order): measured force (negative -> 0)
-> actuator_lag (first order) -> actuator_hysteresis (play operator) -> spring_preload
(minus the preload, >= 0) = pack force. Inside a step the lagged force moves monotonically,
so the play operator is exact along it.

Film integration: exponential (Rosenbrock-)Euler steps on h with the analytic Jacobian,
sub-stepped so that h changes by at most MAX_REL_DH per sub-step. It is exact for the
linearised film equation, so the stiffness near contact (|J| up to ~1e3 1/s) costs nothing
at steady state, and the relative-change limit keeps h > 0 by construction.
Thermal: exact exponential solution of eq. 3.18 over the step with the heat input held
at the trapezoid of the start and end powers.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from clutch_model.plant import friction
from clutch_model.plant import layout as P
from clutch_model.plant.friction import P_MAX_MPA, THETA_MAX_C

S_H, S_THETA, S_FHYST, S_FPACK, S_ENERGY, S_SIGN, S_POWER, S_FLAG, S_FTARGET = range(9)
S_ANGLE, S_FPREV, S_DT, S_PPREV, S_TERM0 = 9, 10, 11, 12, 13
S_MEMO0 = S_TERM0 + P.MAX_DISCOVERED_TERMS
# memo slots: a flag (1 = filled), the keys, the value
(M_VISC_OK, M_VISC_THETA, M_VISC_A0, M_VISC_A1, M_VISC,
 M_PA_OK, M_PA_H, M_PA_SIGMA, M_PA_KP, M_PA,
 M_HY_OK, M_HY_HH, M_HY) = range(S_MEMO0, S_MEMO0 + 13)
# the slip input held over the last advance (the slip rate of discovered terms), after the memo
S_WPREV = S_MEMO0 + 13
N_STATE = S_MEMO0 + 14

# signals the discovered terms are built from (defined in layout, numba-free)
from clutch_model.plant.layout import (SIG_NONE, SIG_PRESSURE, SIG_PACK_TEMP, SIG_SLIP_ABS,  # noqa: E402
                                       SIG_SLIP_POWER, SIG_ENERGY, SIG_FORCE_RATE, SIG_SIN_ANGLE,
                                       SIG_COS_ANGLE, SIG_SLIP, SIG_SLIP_SIGN, SIG_SLIP_RATE, TERM_FRICTION,
                                       TERM_TORQUE)
THETA_REF_C = 60.0
DISC_FACTOR_MIN = 0.05

# output record
N_OUT = 16
(O_TORQUE, O_TA, O_TH, O_MU, O_H, O_THETA, O_VISC, O_POWER, O_ENERGY, O_LOCKED,
 O_FPACK, O_CLAMPED, O_PRESSURE_MPA, O_RANGE, O_DRAG, O_PA) = range(16)

# derived constants
N_DER = 12
(D_AN, D_Q, D_KP, D_FMAX, D_TA_GEOM, D_TH_GEOM, D_FILM_DEN, D_KD12, D_SQRTK, D_MU60,
 D_FE0, D_HMAX) = range(12)

MAX_REL_DH = 0.1
MAX_STEP_S = 0.0051       # longer steps are split (inputs held): 200 Hz rows are one step
MAX_SUBSTEPS = 400
INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
SQRT2 = math.sqrt(2.0)
SLIP_LIMIT = 1.0e4        # |slip| clamp inside the model (the node rejects > 1000)
SUMP_MIN, SUMP_MAX = -100.0, 500.0
H_MAX = 1.0e-2            # film cap [m]: far beyond any open-clutch gap


@njit(cache=True, inline='always')
def greenwood_williamson_fe(x):
    """F_e(x) = 1/sqrt(2 pi) * int_x^inf (s - x) exp(-s^2/2) ds (eq. 3.7), closed form."""
    v = math.exp(-0.5 * x * x) * INV_SQRT_2PI - x * 0.5 * math.erfc(x / SQRT2)
    return v if v > 0.0 else 0.0


@njit(cache=True)
def derived_constants(p):
    d = np.empty(N_DER)
    ro, ri = p[P.R_OUTER], p[P.R_INNER]
    an = math.pi * (ro * ro - ri * ri)
    d[D_AN] = an
    q = ro * ro + ri * ri + (ro * ro - ri * ri) / math.log(ri / ro)
    d[D_Q] = q
    kp = p[P.YOUNGS] * math.pi * p[P.ASP_DENSITY] * p[P.ASP_RADIUS] * p[P.SIGMA]
    d[D_KP] = kp
    d[D_FE0] = INV_SQRT_2PI
    d[D_FMAX] = 0.9 * an * kp * INV_SQRT_2PI
    d[D_TA_GEOM] = p[P.N_FRICTION] * (ro ** 3 - ri ** 3) / 3.0 * 2.0 * math.pi
    d[D_TH_GEOM] = p[P.N_FRICTION] * (ro ** 4 - ri ** 4) / 2.0 * math.pi * p[P.A_RED]
    d[D_FILM_DEN] = 6.0 * an * q * p[P.A_RED]
    d[D_KD12] = 12.0 * p[P.K_PERM] * p[P.LINING_D]
    d[D_SQRTK] = math.sqrt(p[P.K_PERM])
    d[D_MU60] = p[P.ALPHA0] * 60.0 ** (-p[P.ALPHA1])
    d[D_HMAX] = max(H_MAX, 10.0 * p[P.H0])
    return d


@njit(cache=True, inline='always')
def viscosity(theta, p):
    """ATF dynamic viscosity [Pa s], eq. 3.17, theta clamped to [1, 1e6] C (the upper bound
    is far outside any clutch; it only keeps a runaway parameter set's viscosity above 0, so
    the film equation never divides by zero)."""
    th = theta if theta > 1.0 else 1.0
    if th > 1e6:
        th = 1e6
    return p[P.ALPHA0] * th ** (-p[P.ALPHA1])


@njit(cache=True, inline='always')
def hydrodynamic_flow_factor(hh):
    """phi_f + phi_fs of the hydrodynamic torque (eq. 3.10-3.11) at h / sigma."""
    phi_f = 1.0 + 0.5 * math.exp(-0.8 * hh)
    phi_fs = 11.1 * hh ** 2.31 * math.exp(-2.38 * hh + 0.11 * hh * hh) if hh <= 5.0 else 0.0
    return phi_f + phi_fs


@njit(cache=True, inline='always')
def _memo_viscosity(state, theta, p):
    """viscosity(theta, p), reused from the state's memo when theta and alpha_0/1 are equal."""
    if (state[M_VISC_OK] == 1.0 and state[M_VISC_THETA] == theta and state[M_VISC_A0] == p[P.ALPHA0]
            and state[M_VISC_A1] == p[P.ALPHA1]):
        return state[M_VISC]
    v = viscosity(theta, p)
    state[M_VISC_OK] = 1.0
    state[M_VISC_THETA] = theta
    state[M_VISC_A0] = p[P.ALPHA0]
    state[M_VISC_A1] = p[P.ALPHA1]
    state[M_VISC] = v
    return v


@njit(cache=True, inline='always')
def _memo_asperity_pressure(state, h, p, d):
    """asperity_pressure(h, p, d), reused when h, sigma and k_P are equal."""
    if (state[M_PA_OK] == 1.0 and state[M_PA_H] == h and state[M_PA_SIGMA] == p[P.SIGMA]
            and state[M_PA_KP] == d[D_KP]):
        return state[M_PA]
    v = asperity_pressure(h, p, d)
    state[M_PA_OK] = 1.0
    state[M_PA_H] = h
    state[M_PA_SIGMA] = p[P.SIGMA]
    state[M_PA_KP] = d[D_KP]
    state[M_PA] = v
    return v


@njit(cache=True, inline='always')
def _memo_flow_factor(state, hh):
    """hydrodynamic_flow_factor(hh), reused when h / sigma is equal."""
    if state[M_HY_OK] == 1.0 and state[M_HY_HH] == hh:
        return state[M_HY]
    v = hydrodynamic_flow_factor(hh)
    state[M_HY_OK] = 1.0
    state[M_HY_HH] = hh
    state[M_HY] = v
    return v


@njit(cache=True, inline='always')
def friction_coefficient(w_abs, pressure_mpa, theta, p):
    """Stribeck mu_f(w, P, theta) of the parameter vector (clutch_model.plant.friction)."""
    return friction.mu_at(p, P.FRICTION_A, p[P.FRICTION_I],
                       w_abs, pressure_mpa, theta)


@njit(cache=True)
def term_signal(code, state, w, pressure_mpa, theta):
    """Value of one discovered-term signal (SIG_*) at the current state and inputs:
    contact pressure [MPa], pack temperature above 60 C [C], |slip| [rad/s], slip power of
    the previous row's output [kW], dissipated energy [MJ], pack-force rate over the last step [kN/s],
    sin/cos of the slip angle, signed slip [rad/s], sign of slip, slip rate over the last step
    [rad/s^2]."""
    if code == SIG_PRESSURE:
        return pressure_mpa
    if code == SIG_PACK_TEMP:
        return theta - THETA_REF_C
    if code == SIG_SLIP_ABS:
        return abs(w)
    if code == SIG_SLIP_POWER:
        return state[S_PPREV] * 1e-3
    if code == SIG_ENERGY:
        return state[S_ENERGY] * 1e-6
    if code == SIG_FORCE_RATE:
        dt = state[S_DT]
        return (state[S_FPACK] - state[S_FPREV]) / dt * 1e-3 if dt > 0.0 else 0.0
    if code == SIG_SIN_ANGLE:
        return math.sin(state[S_ANGLE])
    if code == SIG_COS_ANGLE:
        return math.cos(state[S_ANGLE])
    if code == SIG_SLIP:
        return w
    if code == SIG_SLIP_SIGN:
        return 1.0 if w > 0.0 else (-1.0 if w < 0.0 else 0.0)
    if code == SIG_SLIP_RATE:
        dt = state[S_DT]
        return (w - state[S_WPREV]) / dt if dt > 0.0 else 0.0
    return 1.0


@njit(cache=True)
def term_raw(p, j, state, w, pressure_mpa, theta):
    """Product of the two signals of discovered-term slot j (before its low-pass)."""
    base = P.DISC_SLOTS + P.DISC_SLOT * j
    g = term_signal(int(p[base + 1]), state, w, pressure_mpa, theta)
    b = int(p[base + 2])
    if b != SIG_NONE:
        g *= term_signal(b, state, w, pressure_mpa, theta)
    return g


@njit(cache=True)
def discovered_terms(p, state, w, pressure_mpa, theta):
    """(friction multiplier 1 + sum c g, additive torque sum c g) of the discovered terms."""
    n = int(p[P.DISC_N])
    fac = 1.0
    add = 0.0
    for j in range(n):
        base = P.DISC_SLOTS + P.DISC_SLOT * j
        g = state[S_TERM0 + j] if p[base + 3] > 0.0 else term_raw(p, j, state, w, pressure_mpa, theta)
        if int(p[base]) == TERM_FRICTION:
            fac += p[base + 4] * g
        else:
            add += p[base + 4] * g
    if fac < DISC_FACTOR_MIN:
        fac = DISC_FACTOR_MIN
    return fac, add


@njit(cache=True, inline='always')
def asperity_pressure(h, p, d):
    """Mean asperity pressure P_a(h) = E * pi * N * beta * sigma * F_e(h/sigma) (eq. 3.5-3.6)."""
    return d[D_KP] * greenwood_williamson_fe(h / p[P.SIGMA])


@njit(cache=True, inline='always')
def film_rate(h, f_pack, mu, p, d):
    """dh/dt of eq. 3.2 and its derivative d(dh/dt)/dh.

    dh/dt = phi * xi * delta / (g * A_red) * gamma * h^3, gamma = -1/(6 mu A_N Q); the h^3
    cancels the one in delta's denominator, so the rate is finite at h -> 0.
    """
    sigma = p[P.SIGMA]
    hh = h / sigma
    # each transcendental once (the values are those of the separate calls, bit for bit)
    e056 = math.exp(-0.56 * hh)
    gauss = math.exp(-0.5 * hh * hh) * INV_SQRT_2PI          # standard normal density at hh
    upper_tail = 0.5 * math.erfc(hh / SQRT2)                   # Q(hh) = P(s > hh)
    phi = 1.0 - 0.9 * e056
    eta = 1.0 / (1.0 + p[P.BJ_CHI] * h / d[D_SQRTK])
    h3 = h * h * h
    num = h3 * (1.0 + 3.0 * eta) + d[D_KD12]
    g = 0.5 * (1.0 + math.erf(hh / SQRT2))
    c = phi * num / (mu * d[D_FILM_DEN] * g)
    fe = gauss - hh * upper_tail                               # greenwood_williamson_fe(hh)
    if not (fe > 0.0):
        fe = 0.0
    f_asp = d[D_AN] * d[D_KP] * fe
    xi = f_pack - f_asp
    rate = -c * xi
    # Jacobian: d rate/dh = -c' xi + c dF_a/dh ; dF_a/dh = -A_N kP Q(H)/sigma
    dfa_dh = -d[D_AN] * d[D_KP] * upper_tail / sigma
    dphi = 0.9 * 0.56 / sigma * e056
    deta = -eta * eta * p[P.BJ_CHI] / d[D_SQRTK]
    dnum = 3.0 * h * h * (1.0 + 3.0 * eta) + h3 * 3.0 * deta
    dg = gauss / sigma
    dc = c * (dphi / phi + dnum / num - dg / g)
    jac = -dc * xi + c * dfa_dh
    return rate, jac


@njit(cache=True, inline='always')
def force_chain(f_actuator, f_hyst_prev, p):
    """Hysteresis then preload on the actuator force: (hysteresis output, pack force)."""
    r = p[P.HYST_RATIO]
    fh = f_actuator
    if r > 0.0:
        lo, hi = f_actuator * (1.0 - r), f_actuator * (1.0 + r)
        fh = f_hyst_prev
        if fh < lo:
            fh = lo
        elif fh > hi:
            fh = hi
    pre = p[P.PRELOAD_N]
    f = fh
    if pre > 0.0:
        f = fh - pre if fh > pre else 0.0
    return fh, f


@njit(cache=True, inline='always')
def film_step(h, f_start, f_target, tau, dt, mu, p, d, f_hyst):
    """Advance the film over dt. Actuator force: f_target if tau <= 0, else the first-order
    lag from f_start towards f_target (exact), sampled at each sub-step's midpoint and passed
    through the force chain (hysteresis from ``f_hyst``, preload)."""
    remaining = dt
    elapsed = 0.0
    n = 0
    hmax = d[D_HMAX]
    while remaining > 1e-15 and n < MAX_SUBSTEPS:
        s = remaining
        for _ in range(8):
            if tau > 0.0:
                fa = f_target + (f_start - f_target) * math.exp(-(elapsed + 0.5 * s) / tau)
            else:
                fa = f_target
            fm = force_chain(fa, f_hyst, p)[1]
            if fm > d[D_FMAX]:
                fm = d[D_FMAX]
            rate, jac = film_rate(h, fm, mu, p, d)
            z = jac * s
            if abs(z) < 1e-8:
                phi1 = 1.0 + 0.5 * z
            elif z > 50.0:
                phi1 = math.exp(50.0) / z
            else:
                phi1 = math.expm1(z) / z
            dh = phi1 * s * rate
            lim = MAX_REL_DH * h
            if abs(dh) <= lim or n == MAX_SUBSTEPS - 1:
                break
            s = s * max(0.1, 0.9 * lim / abs(dh))
        if dh < -0.5 * h:  # only reachable at the sub-step cap
            dh = -0.5 * h
        h = h + dh
        if h > hmax:
            h = hmax
        remaining -= s
        elapsed += s
        n += 1
    return h


@njit(cache=True, inline='always')
def _clamped_force(applied_force):
    f = applied_force if applied_force > 0.0 else 0.0
    if not (f < 1e12):
        f = 1e12
    return f


@njit(cache=True, inline='always')
def pack_force_target(state, applied_force, p):
    """Take one measured-force sample: it becomes the lag's target; without a lag the
    actuator force, hysteresis and pack force follow at once. Returns the pack force."""
    f = _clamped_force(applied_force)
    state[S_FTARGET] = f
    if p[P.LAG_TAU_S] <= 0.0:
        state[S_FLAG] = f
        fh, fp = force_chain(f, state[S_FHYST], p)
        state[S_FHYST] = fh
        state[S_FPACK] = fp
    return state[S_FPACK]


@njit(cache=True)
def init_state(state, applied_force, sump_temperature, p):
    state[S_H] = p[P.H0]
    state[S_THETA] = min(max(sump_temperature, SUMP_MIN), SUMP_MAX)
    state[S_ENERGY] = state[S_ENERGY]  # energy is carried (campaign), not reset here
    state[S_SIGN] = 1.0
    state[S_POWER] = 0.0
    # actuator at rest at the first sample, hysteresis centred on it
    f = _clamped_force(applied_force)
    state[S_FLAG] = f
    state[S_FTARGET] = f
    fh, fp = force_chain(f, f, p)
    state[S_FHYST] = fh
    state[S_FPACK] = fp
    state[S_ANGLE] = 0.0
    state[S_FPREV] = fp
    state[S_DT] = 0.0
    state[S_PPREV] = 0.0
    state[S_WPREV] = 0.0
    for j in range(P.MAX_DISCOVERED_TERMS):
        state[S_TERM0 + j] = 0.0
    state[M_VISC_OK] = 0.0
    state[M_PA_OK] = 0.0
    state[M_HY_OK] = 0.0


@njit(cache=True)
def outputs(state, slip, sump_temperature, p, d, out):
    """Torque and the full record at the current state with the current inputs.
    Call pack_force_target() with the sample's force first. Updates sign and power."""
    w = slip
    if not (w < SLIP_LIMIT):
        w = SLIP_LIMIT
    if not (w > -SLIP_LIMIT):
        w = -SLIP_LIMIT
    w_abs = abs(w)
    h = state[S_H]
    theta = state[S_THETA]
    f_pack = state[S_FPACK]
    clamped = 0.0
    if f_pack > d[D_FMAX]:
        f_pack = d[D_FMAX]
        clamped = 1.0
    pressure_mpa = f_pack / d[D_AN] * 1e-6
    mu = _memo_viscosity(state, theta, p)
    pa = _memo_asperity_pressure(state, h, p, d)
    locked = w_abs < p[P.LOCK_SLIP]
    if not locked:
        state[S_SIGN] = 1.0 if w > 0.0 else -1.0
    sign = state[S_SIGN]
    degr = 1.0
    if p[P.ENERGY_SCALE_J] > 0.0:
        degr = math.exp(-state[S_ENERGY] / p[P.ENERGY_SCALE_J])
    extra = 0.0
    if p[P.DISC_N] > 0.0:
        fac, extra = discovered_terms(p, state, w, pressure_mpa, theta)
        degr *= fac
    if locked:
        mu_f = friction_coefficient(0.0, pressure_mpa, theta, p) * degr
        t_a = sign * mu_f * pa * d[D_TA_GEOM]
        t_h = 0.0
        drag = 0.0
    else:
        mu_f = friction_coefficient(w_abs, pressure_mpa, theta, p) * degr
        t_a = sign * mu_f * pa * d[D_TA_GEOM]
        hh = h / p[P.SIGMA]
        t_h = w * _memo_flow_factor(state, hh) / h * mu * d[D_TH_GEOM]
        drag = p[P.DRAG_COEFF] * w * mu / d[D_MU60] if p[P.DRAG_COEFF] != 0.0 else 0.0
        drag += extra
    torque = t_a + t_h + drag
    power = abs(w * torque)
    state[S_POWER] = power
    out[O_TORQUE] = torque
    out[O_TA] = t_a
    out[O_TH] = t_h
    out[O_MU] = mu_f
    out[O_H] = h
    out[O_THETA] = theta
    out[O_VISC] = mu
    out[O_POWER] = power
    out[O_ENERGY] = state[S_ENERGY]
    out[O_LOCKED] = 1.0 if locked else 0.0
    out[O_FPACK] = f_pack
    out[O_CLAMPED] = clamped
    out[O_PRESSURE_MPA] = pressure_mpa
    out[O_RANGE] = 1.0 if (pressure_mpa > P_MAX_MPA or theta < 0.0 or theta > THETA_MAX_C) else 0.0
    out[O_DRAG] = drag
    out[O_PA] = pa
    return torque


@njit(cache=True, inline='always')
def advance(state, slip, sump_temperature, dt, p, d, scratch):
    """Integrate the state over dt with the current inputs held (the pack-force target is
    the one set by the last pack_force_target() call). Steps longer than MAX_STEP_S are
    split, so slow input rates (10 Hz) keep the accuracy of fast ones."""
    if not (dt > 0.0):
        return
    if p[P.DISC_N] > 0.0:
        _advance_term_filters(state, slip, dt, p, d)   # driven by the last sample's signals
    state[S_FPREV] = state[S_FPACK]
    state[S_DT] = dt
    state[S_PPREV] = state[S_POWER]
    state[S_WPREV] = min(max(slip, -SLIP_LIMIT), SLIP_LIMIT)
    n = int(math.ceil(dt / MAX_STEP_S))
    if n < 1:
        n = 1
    h = dt / n
    for _ in range(n):
        _advance_once(state, slip, sump_temperature, h, p, d, scratch)


@njit(cache=True, inline='always')
def _advance_once(state, slip, sump_temperature, dt, p, d, scratch):
    theta0 = state[S_THETA]
    mu = _memo_viscosity(state, theta0, p)
    tau = p[P.LAG_TAU_S]
    f_start = state[S_FLAG]
    f_target = state[S_FTARGET]
    state[S_H] = film_step(state[S_H], f_start, f_target, tau, dt, mu, p, d, state[S_FHYST])
    if tau > 0.0:
        fa = f_target + (f_start - f_target) * math.exp(-dt / tau)
        state[S_FLAG] = fa
        fh, fp = force_chain(fa, state[S_FHYST], p)
        state[S_FHYST] = fh
        state[S_FPACK] = fp
    p_start = state[S_POWER]
    outputs(state, slip, sump_temperature, p, d, scratch)  # end-of-step power, inputs held
    p_end = scratch[O_POWER]
    heat = 0.5 * (p_start + p_end)
    sump = min(max(sump_temperature, SUMP_MIN), SUMP_MAX)
    # thermal, eq. 3.18, exact for held heat input
    w_abs = min(abs(slip), SLIP_LIMIT)
    f_kn = min(state[S_FPACK], d[D_FMAX]) * 1e-3
    htf = p[P.B1] + p[P.B2] * w_abs + p[P.B3] * f_kn + p[P.B4] * w_abs * f_kn
    if htf < p[P.HTF_MIN]:
        htf = p[P.HTF_MIN]
    k = htf * d[D_AN]
    q = heat / p[P.N_SEPARATOR]
    # theta -> theta_eq = sump + q/k with rate k/C; written with expm1 so that k -> 0
    # degrades gracefully to the adiabatic q*dt/C
    frac = -math.expm1(-k * dt / p[P.PLATE_HEAT_CAPACITY])
    state[S_THETA] = theta0 + (q / k - (theta0 - sump)) * frac
    state[S_ENERGY] += heat * dt
    state[S_POWER] = p_end  # heat power at the end of the step (inputs held)
    a = state[S_ANGLE] + min(max(slip, -SLIP_LIMIT), SLIP_LIMIT) * dt
    state[S_ANGLE] = a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))


@njit(cache=True)
def _advance_term_filters(state, slip, dt, p, d):
    """First-order low-pass (exact for the signal held over dt) of every discovered term
    that has a time constant, driven by its signal at the last sample (held over the step)."""
    w = min(max(slip, -SLIP_LIMIT), SLIP_LIMIT)
    pressure_mpa = min(state[S_FPACK], d[D_FMAX]) / d[D_AN] * 1e-6
    for j in range(int(p[P.DISC_N])):
        tau = p[P.DISC_SLOTS + P.DISC_SLOT * j + 3]
        if tau > 0.0:
            g = term_raw(p, j, state, w, pressure_mpa, state[S_THETA])
            x = state[S_TERM0 + j]
            state[S_TERM0 + j] = x + (g - x) * -math.expm1(-dt / tau)


@njit(cache=True)
def _row(k, state, p, d, t, force, slip, sump, run_start, scratch, out):
    """Row k of the replay grid: restart or advance from row k-1, take row k's force sample,
    write the record of row k into ``out`` and return its torque."""
    if k == 0 or run_start[k]:
        init_state(state, force[k], sump[k], p)
    else:
        advance(state, slip[k - 1], sump[k - 1], t[k] - t[k - 1], p, d, scratch)
    pack_force_target(state, force[k], p)
    return outputs(state, slip[k], sump[k], p, d, out)


@njit(cache=True)
def run_trajectory(p, t, force, slip, sump, run_start, energy0):
    """Replay timing (docs/bags.md): row k's outputs come from the state at t_k (integrated
    from t_{k-1} with row k-1's inputs held) and row k's inputs. A run_start row restarts
    the plant (film, pack temperature, actuator states); energy carries over."""
    n = t.size
    d = derived_constants(p)
    out = np.empty((n, N_OUT))          # every element is written (_store)
    state = np.zeros(N_STATE)
    scratch = np.zeros(N_OUT)
    rec = np.zeros(N_OUT)
    state[S_ENERGY] = energy0
    for k in range(n):
        _row(k, state, p, d, t, force, slip, sump, run_start, scratch, rec)
        _store(out, k, rec)
    return out


@njit(cache=True, nogil=True, inline='always')
def _store(out, k, rec):
    """out[k, :] = rec, element by element (a row view per row would cost an atomic
    reference count each)."""
    for j in range(N_OUT):
        out[k, j] = rec[j]


@njit(cache=True, parallel=True)
def run_batch(pmat, t, force, slip, sump, run_start, energy0):
    """Torque and pack temperature for many parameter sets (rows of pmat) on one input set."""
    m = pmat.shape[0]
    n = t.size
    torque = np.empty((m, n))
    theta = np.empty((m, n))
    for j in prange(m):
        p = pmat[j]
        d = derived_constants(p)
        state = np.zeros(N_STATE)
        scratch = np.zeros(N_OUT)
        out = np.zeros(N_OUT)
        state[S_ENERGY] = energy0
        for k in range(n):
            torque[j, k] = _row(k, state, p, d, t, force, slip, sump, run_start, scratch, out)
            theta[j, k] = out[O_THETA]
    return torque, theta


@njit(cache=True, inline='always')
def _row_from(k, state, p, d, t, force, slip, sump, run_start, start_index, start_states, scratch, out):
    """``_row``, except that a run_start row with ``start_index[k] >= 0`` takes the plant state
    ``start_states[start_index[k]]`` (the state another simulation had after that same row:
    film, pack temperature, energy, actuator and term states) instead of the initial state.
    Taking the row's force sample and writing its outputs again leaves such a state as it was,
    so a run started from the state a whole simulation had at its row k continues exactly as
    that simulation does."""
    if run_start[k] and start_index[k] >= 0:
        i = start_index[k]
        for j in range(N_STATE):          # element-wise: no slice (reference count) per row
            state[j] = start_states[i, j]
        pack_force_target(state, force[k], p)
        return outputs(state, slip[k], sump[k], p, d, out)
    return _row(k, state, p, d, t, force, slip, sump, run_start, scratch, out)


@njit(cache=True)
def run_trajectory_from(p, t, force, slip, sump, run_start, energy0, start_index, start_states):
    """``run_trajectory`` whose runs may start from given plant states (``_row_from``)."""
    n = t.size
    d = derived_constants(p)
    out = np.empty((n, N_OUT))          # every element is written (_store)
    state = np.zeros(N_STATE)
    scratch = np.zeros(N_OUT)
    rec = np.zeros(N_OUT)
    state[S_ENERGY] = energy0
    for k in range(n):
        _row_from(k, state, p, d, t, force, slip, sump, run_start, start_index, start_states, scratch, rec)
        _store(out, k, rec)
    return out


@njit(cache=True, parallel=True)
def run_batch_from(pmat, t, force, slip, sump, run_start, energy0, start_index, start_states):
    """``run_batch`` whose runs may start from given plant states (``_row_from``; every
    parameter set starts from the same states)."""
    m = pmat.shape[0]
    n = t.size
    torque = np.empty((m, n))
    theta = np.empty((m, n))
    for j in prange(m):
        p = pmat[j]
        d = derived_constants(p)
        state = np.zeros(N_STATE)
        scratch = np.zeros(N_OUT)
        out = np.zeros(N_OUT)
        state[S_ENERGY] = energy0
        for k in range(n):
            torque[j, k] = _row_from(k, state, p, d, t, force, slip, sump, run_start, start_index, start_states,
                                     scratch, out)
            theta[j, k] = out[O_THETA]
    return torque, theta


# carry of a trajectory between chunks (``run_chunk``): the row before the chunk's first row
C_T, C_SLIP, C_SUMP, C_HAS_PREV = 0, 1, 2, 3
N_CARRY = 4


@njit(cache=True, nogil=True)
def run_chunk(p, d, t, force, slip, sump, run_start, state, carry, out):
    """``run_trajectory`` one chunk at a time: rows of ``t``.. continue from ``state`` (the
    plant state after the previous chunk's last row) and ``carry`` (that row's time, slip and
    sump: row 0 is advanced from it unless it starts a run). The same row code in the same
    order as run_trajectory, so chunked runs equal the whole run bit for bit. Writes
    out[:n] (n = t.size), updates state and carry. Releases the GIL."""
    n = t.size
    scratch = np.zeros(N_OUT)
    rec = np.zeros(N_OUT)
    for k in range(n):
        if k == 0 and carry[C_HAS_PREV] > 0.0 and not run_start[0]:
            advance(state, carry[C_SLIP], carry[C_SUMP], t[0] - carry[C_T], p, d, scratch)
            pack_force_target(state, force[0], p)
            outputs(state, slip[0], sump[0], p, d, rec)
        else:
            _row(k, state, p, d, t, force, slip, sump, run_start, scratch, rec)
        _store(out, k, rec)
    if n:
        carry[C_T] = t[n - 1]
        carry[C_SLIP] = slip[n - 1]
        carry[C_SUMP] = sump[n - 1]
        carry[C_HAS_PREV] = 1.0
