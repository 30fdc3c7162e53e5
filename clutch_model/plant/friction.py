"""The friction law: Stribeck's mu_f(w, P, theta) with separable quadratic coefficients
(thesis eq. 4.9-4.14, constant exponent i), written once.

    mu_f = mu_C + (mu_S - mu_C) exp(-(w / omega_S)^i) + k_V w
    q(P, theta) = c0 + c1 P + c2 P^2 + c3 theta + c4 theta^2   for q in mu_C, mu_S, omega_S, k_V

Coefficients a0..a19 in table order: a0-a4 mu_C, a5-a9 mu_S, a10-a14 omega_S, a15-a19 k_V.
P [MPa] is clamped to [0, 20], theta [C] to [0, 230], omega_S floored at 1e-6 rad/s and
mu_f floored at 0 (the raw value, before the floor, is what positivity checks look at).

- ``mu_raw`` / ``mu``: numba scalars for the kernels and the branch-and-bound box check;
- ``friction_grid``: the scalar law over arrays (numba loop; the virtual car's bench table);
- ``stribeck``: the vectorised law (numpy) with its Jacobian w.r.t. (a0..a19, i) for the fits.

- ``friction_positive`` / ``friction_positive_many``: THE positivity check, mu_f >= minimum
  over a (P, theta, w) box (default the car's: P in [0, 6] MPa, theta in [0, 230] C, w in
  [0, 30] rad/s). The coefficient blocks are separable quadratics, so their exact range over
  a box is the constant plus the 1-D extrema of the P and theta parts (``poly_range``: ends
  or vertex); mu_f itself is not a polynomial, so it is certified by interval
  branch-and-bound on ``mu_raw`` (numba) after a quick vectorised pre-check, with a dense
  grid as the fallback answer if the branch-and-bound runs out of budget (it practically
  never does).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

P_MAX_MPA, THETA_MAX_C = 20.0, 230.0
P_BOX = (0.0, P_MAX_MPA)
THETA_BOX = (0.0, THETA_MAX_C)
OMEGA_S_FLOOR = 1e-6
EXP_ZERO_ARG = 746.0     # exp(-x) rounds to 0.0 for x >= 745.14 (half the least subnormal)
N_COEFFS = 20

# blocks of the coefficient vector a0..a19 (table order)
BLOCKS = {"mu_C": slice(0, 5), "mu_S": slice(5, 10), "omega_S": slice(10, 15), "k_V": slice(15, 20)}
BLOCK_OF = ["mu_C"] * 5 + ["mu_S"] * 5 + ["omega_S"] * 5 + ["k_V"] * 5
MONOMIAL = ["1", "P", "P^2", "theta", "theta^2"]
# the box of the positivity check (thesis §5.3: the car's operating range)
CAR_P_BOX = (0.0, 6.0)
CAR_THETA_BOX = (0.0, 230.0)
CAR_W_BOX = (0.0, 30.0)


@njit(cache=True)
def mu_raw(a, i, w_abs, pressure_mpa, theta):
    """mu_f before the floor at 0 (P and theta clamped, omega_S floored)."""
    return mu_raw_at(a, 0, i, w_abs, pressure_mpa, theta)


@njit(cache=True, inline='always')
def mu_raw_at(v, base, i, w_abs, pressure_mpa, theta):
    """``mu_raw`` of the coefficients v[base:base + 20] (read in place: the kernels pass the
    whole parameter vector, and a slice per call would cost a reference count per row)."""
    pr = min(max(pressure_mpa, 0.0), P_MAX_MPA)
    th = min(max(theta, 0.0), THETA_MAX_C)
    pr2, th2 = pr * pr, th * th
    b = base
    mu_c = v[b] + v[b + 1] * pr + v[b + 2] * pr2 + v[b + 3] * th + v[b + 4] * th2
    mu_s = v[b + 5] + v[b + 6] * pr + v[b + 7] * pr2 + v[b + 8] * th + v[b + 9] * th2
    w_s = v[b + 10] + v[b + 11] * pr + v[b + 12] * pr2 + v[b + 13] * th + v[b + 14] * th2
    k_v = v[b + 15] + v[b + 16] * pr + v[b + 17] * pr2 + v[b + 18] * th + v[b + 19] * th2
    if w_s < OMEGA_S_FLOOR:
        w_s = OMEGA_S_FLOOR
    r = w_abs / w_s
    e = 0.0
    if r < 1e6:
        x = r ** i
        if not (x >= EXP_ZERO_ARG):     # exp(-x) is exactly 0 beyond it: skip libm's underflow path
            e = math.exp(-x)
    return mu_c + (mu_s - mu_c) * e + k_v * w_abs


@njit(cache=True)
def mu(a, i, w_abs, pressure_mpa, theta):
    """mu_f(w, P, theta) >= 0 (the kernels' friction coefficient)."""
    return mu_at(a, 0, i, w_abs, pressure_mpa, theta)


@njit(cache=True, inline='always')
def mu_at(v, base, i, w_abs, pressure_mpa, theta):
    """``mu`` of the coefficients v[base:base + 20], read in place."""
    m = mu_raw_at(v, base, i, w_abs, pressure_mpa, theta)
    return m if m > 0.0 else 0.0


@njit(cache=True)
def friction_grid(a, i, w_abs, pressure_mpa, theta):
    """mu_f (floored) on arrays of the same shape, by the kernels' scalar law."""
    out = np.empty(w_abs.size)
    for k in range(w_abs.size):
        out[k] = mu(a, i, w_abs[k], pressure_mpa[k], theta[k])
    return out


def monomials(pressure_mpa, theta_c):
    """[1, P, P^2, theta, theta^2] with P and theta clamped to the box like the kernel."""
    pr = np.clip(np.asarray(pressure_mpa, float), *P_BOX)
    th = np.clip(np.asarray(theta_c, float), *THETA_BOX)
    return np.stack([np.ones_like(pr), pr, pr * pr, th, th * th], axis=-1)


def stribeck(a, i, w_abs, pressure_mpa, theta_c, jac: bool = False, floor: bool = True):
    """Vectorised mu_f (floored at 0 like the kernel unless ``floor=False``) and optionally its
    Jacobian with respect to (a0..a19, i): (mu, J (m, 21)). Inputs broadcast to 1-D rows."""
    a = np.asarray(a, float)
    w = np.abs(np.asarray(w_abs, float))
    M = monomials(pressure_mpa, theta_c)
    mu_c, mu_s, w_s_raw, k_v = (M @ a[0:5], M @ a[5:10], M @ a[10:15], M @ a[15:20])
    floored = w_s_raw < OMEGA_S_FLOOR
    w_s = np.where(floored, OMEGA_S_FLOOR, w_s_raw)
    r = w / w_s
    big = r >= 1e6
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        ri = np.where(big, np.inf, np.power(np.where(big, 1.0, r), i))
        e = np.where(big, 0.0, np.exp(-ri))
    m = mu_c + (mu_s - mu_c) * e + k_v * w
    neg = m < 0.0
    if floor:
        m = np.where(neg, 0.0, m)
    if not jac:
        return m
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        d_ws = np.where(floored | big, 0.0, (mu_s - mu_c) * e * i * ri / w_s)
        lnr = np.where(r > 0, np.log(np.where(r > 0, r, 1.0)), 0.0)
        d_i = np.where(big, 0.0, -(mu_s - mu_c) * e * ri * lnr)
    d_ws = np.nan_to_num(d_ws)
    d_i = np.nan_to_num(d_i)
    J = np.concatenate([M * (1.0 - e)[..., None], M * e[..., None], M * d_ws[..., None],
                        M * w[..., None], d_i[..., None]], axis=-1)
    if floor:
        J[neg] = 0.0
    return m, J


# --- separable quadratics ------------------------------------------------------------------
def eval_poly(c, pressure, theta):
    """c0 + c1 P + c2 P^2 + c3 theta + c4 theta^2 (c: (..., 5), broadcast)."""
    c = np.asarray(c, float)
    pressure = np.asarray(pressure, float)
    theta = np.asarray(theta, float)
    return (c[..., 0] + c[..., 1] * pressure + c[..., 2] * pressure ** 2
            + c[..., 3] * theta + c[..., 4] * theta ** 2)


def _quad_1d_candidates(b, c, lo, hi):
    """Candidate points {lo, hi, clip(vertex)} of b x + c x^2 on [lo, hi] (arrays (..., 3))."""
    b = np.asarray(b, float)
    c = np.asarray(c, float)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        v = np.where(c != 0.0, -b / (2.0 * c), lo)
    v = np.clip(np.nan_to_num(v, nan=lo, posinf=hi, neginf=lo), lo, hi)
    return np.stack([np.full_like(v, lo), np.full_like(v, hi), v], axis=-1)


def poly_candidates(c, p_range=P_BOX, theta_range=THETA_BOX):
    """The 9 points (P, theta) of the box that hold the min and the max of the separable
    quadratic(s) c (..., 5). Returns (P (..., 9), theta (..., 9))."""
    c = np.asarray(c, float)
    pc = _quad_1d_candidates(c[..., 1], c[..., 2], *p_range)
    tc = _quad_1d_candidates(c[..., 3], c[..., 4], *theta_range)
    pp, tt = np.broadcast_arrays(pc[..., :, None], tc[..., None, :])
    shape = pp.shape[:-2] + (9,)
    return pp.reshape(shape), tt.reshape(shape)


def poly_range(c, p_range=P_BOX, theta_range=THETA_BOX):
    """Exact (min, max) of the separable quadratic(s) c (..., 5) over the box, and where:
    returns (min, max, (P_min, theta_min), (P_max, theta_max))."""
    c = np.asarray(c, float)
    pp, tt = poly_candidates(c, p_range, theta_range)
    vals = eval_poly(c[..., None, :], pp, tt)
    jmin = np.argmin(vals, axis=-1)
    jmax = np.argmax(vals, axis=-1)
    take = lambda arr, j: np.take_along_axis(arr, j[..., None], axis=-1)[..., 0]  # noqa: E731
    return (take(vals, jmin), take(vals, jmax), (take(pp, jmin), take(tt, jmin)),
            (take(pp, jmax), take(tt, jmax)))


# --- friction positivity over (P, theta, w) ----------------------------------------------------
@njit(cache=True)
def _range1(c1, c2, lo, hi):
    fa = c1 * lo + c2 * lo * lo
    fb = c1 * hi + c2 * hi * hi
    mn = min(fa, fb)
    mx = max(fa, fb)
    if c2 != 0.0:
        v = -c1 / (2.0 * c2)
        if lo < v < hi:
            fv = c1 * v + c2 * v * v
            mn = min(mn, fv)
            mx = max(mx, fv)
    return mn, mx


@njit(cache=True)
def _prange(a, k, plo, phi, tlo, thi):
    p1, p2 = _range1(a[k + 1], a[k + 2], plo, phi)
    t1, t2 = _range1(a[k + 3], a[k + 4], tlo, thi)
    return a[k] + p1 + t1, a[k] + p2 + t2


@njit(cache=True)
def _lower_bound(a, i, plo, phi, tlo, thi, wlo, whi):
    cl, ch = _prange(a, 0, plo, phi, tlo, thi)
    sl, sh = _prange(a, 5, plo, phi, tlo, thi)
    wsl, wsh = _prange(a, 10, plo, phi, tlo, thi)
    kl, kh = _prange(a, 15, plo, phi, tlo, thi)
    if wsl < 1e-6:
        wsl = 1e-6
    if wsh < 1e-6:
        wsh = 1e-6
    rl = wlo / wsh
    rh = whi / wsl
    e_hi = math.exp(-(rl ** i)) if rl < 1e6 else 0.0
    e_lo = math.exp(-(rh ** i)) if rh < 1e6 else 0.0
    s1 = cl * (1.0 - e_lo) + sl * e_lo
    s2 = cl * (1.0 - e_hi) + sl * e_hi
    lb = min(s1, s2)
    kv = min(min(kl * wlo, kl * whi), min(kh * wlo, kh * whi))
    return lb + kv, e_hi - e_lo


@njit(cache=True)
def friction_min_bb(a, i, plo, phi, tlo, thi, wlo, whi, max_boxes, minimum=0.0):
    """Branch-and-bound on min mu_f over the box. Returns (status, best point value, lower
    bound): status +1 certified mu_f >= minimum everywhere, -1 found mu_f < minimum, 0 undecided."""
    stack = np.empty((max_boxes + 64, 6))
    stack[0, 0], stack[0, 1], stack[0, 2] = plo, phi, tlo
    stack[0, 3], stack[0, 4], stack[0, 5] = thi, wlo, whi
    n = 1
    best = 1e300
    glb = 1e300
    sp, st = max(phi - plo, 1e-12), max(thi - tlo, 1e-12)
    sw = max(whi - wlo, 1e-12)
    it = 0
    while n > 0:
        n -= 1
        b0, b1, b2, b3, b4, b5 = stack[n, 0], stack[n, 1], stack[n, 2], stack[n, 3], stack[n, 4], stack[n, 5]
        v = mu_raw(a, i, 0.5 * (b4 + b5), 0.5 * (b0 + b1), 0.5 * (b2 + b3))
        v0 = mu_raw(a, i, b4, 0.5 * (b0 + b1), 0.5 * (b2 + b3))
        v = min(v, v0)
        if v < best:
            best = v
        if v < minimum:
            return -1, best, min(glb, v)
        lb, espan = _lower_bound(a, i, b0, b1, b2, b3, b4, b5)
        if lb >= minimum:
            if lb < glb:
                glb = lb
            continue
        it += 1
        if it > max_boxes or n + 2 >= stack.shape[0]:
            return 0, best, lb
        # split the dimension that loosens the bound most
        wp, wt = (b1 - b0) / sp, (b3 - b2) / st
        ww = max(espan, (b5 - b4) / sw)
        if ww >= wp and ww >= wt:
            lo = b4 if b4 > 1e-9 else 1e-9
            if b5 / lo > 4.0:
                m = math.sqrt(lo * b5)
            else:
                m = 0.5 * (b4 + b5)
            stack[n, 0], stack[n, 1], stack[n, 2], stack[n, 3], stack[n, 4], stack[n, 5] = b0, b1, b2, b3, b4, m
            stack[n + 1, 0], stack[n + 1, 1], stack[n + 1, 2], stack[n + 1, 3] = b0, b1, b2, b3
            stack[n + 1, 4], stack[n + 1, 5] = m, b5
        elif wp >= wt:
            m = 0.5 * (b0 + b1)
            stack[n, 0], stack[n, 1], stack[n, 2], stack[n, 3], stack[n, 4], stack[n, 5] = b0, m, b2, b3, b4, b5
            stack[n + 1, 0], stack[n + 1, 1], stack[n + 1, 2], stack[n + 1, 3] = m, b1, b2, b3
            stack[n + 1, 4], stack[n + 1, 5] = b4, b5
        else:
            m = 0.5 * (b2 + b3)
            stack[n, 0], stack[n, 1], stack[n, 2], stack[n, 3], stack[n, 4], stack[n, 5] = b0, b1, b2, m, b4, b5
            stack[n + 1, 0], stack[n + 1, 1], stack[n + 1, 2], stack[n + 1, 3] = b0, b1, m, b3
            stack[n + 1, 4], stack[n + 1, 5] = b4, b5
        n += 2
    return 1, best, glb


def _w_grid(w_range, n=64):
    lo, hi = w_range
    g = np.unique(np.concatenate([np.linspace(lo, hi, n), lo + np.geomspace(1e-5, max(hi - lo, 1e-4), n)]))
    return g[(g >= lo) & (g <= hi)]


def friction_min_grid(a, i, p_range=CAR_P_BOX, theta_range=CAR_THETA_BOX, w_range=CAR_W_BOX,
                      n_p=25, n_theta=47, n_w=64) -> float:
    """Minimum of mu_f (before the floor at 0) on a dense (P, theta, w) grid, with w dense
    near 0 (log-spaced) where the Stribeck drop happens."""
    a = np.asarray(a, float)
    pg = np.linspace(*p_range, n_p)
    tg = np.linspace(*theta_range, n_theta)
    wg = _w_grid(w_range, n_w)
    P, T, W = np.meshgrid(pg, tg, wg, indexing="ij")
    return float(stribeck(a, float(i), W.ravel(), P.ravel(), T.ravel(), floor=False).min())


def _quick_reject(A, i, p_range, theta_range, w_range, minimum=0.0):
    """Vectorised: True where mu_f < minimum at one of a few candidate points (w = lo, w = hi at
    the extremal points of mu_S and mu_C + k_V w_hi)."""
    A = np.atleast_2d(np.asarray(A, float))
    bad = np.zeros(A.shape[0], bool)
    # mu_f(w_lo) with w_lo = 0 is mu_S: its exact box minimum
    if w_range[0] == 0.0:
        smin = poly_range(A[:, 5:10], p_range, theta_range)[0]
        bad |= smin < minimum
    whi = w_range[1]
    comb = A[:, 0:5] + whi * A[:, 15:20]   # mu_C + k_V w_hi (e ~ 0 at large w)
    pp, tt = poly_candidates(comb, p_range, theta_range)
    for j in range(pp.shape[1]):
        for k in range(A.shape[0]):
            if not bad[k] and mu_raw(A[k], float(i), whi, pp[k, j], tt[k, j]) < minimum:
                bad[k] = True
    return bad


def friction_positive_many(A, i, p_range=CAR_P_BOX, theta_range=CAR_THETA_BOX, w_range=CAR_W_BOX,
                           max_boxes: int = 200_000, minimum: float = 0.0) -> np.ndarray:
    """mu_f >= minimum over the (P, theta, w) box for each coefficient row of A (S, 20)."""
    A = np.ascontiguousarray(np.atleast_2d(np.asarray(A, float)))
    ok = ~_quick_reject(A, i, p_range, theta_range, w_range, minimum)
    for k in np.flatnonzero(ok):
        status, _, _ = friction_min_bb(A[k], float(i), float(p_range[0]), float(p_range[1]),
                                       float(theta_range[0]), float(theta_range[1]),
                                       float(w_range[0]), float(w_range[1]), int(max_boxes), float(minimum))
        if status == 0:  # undecided within budget: the dense grid decides
            ok[k] = friction_min_grid(A[k], i, p_range, theta_range, w_range) >= minimum
        else:
            ok[k] = status > 0
    return ok


def friction_positive(a, i, p_range=CAR_P_BOX, theta_range=CAR_THETA_BOX, w_range=CAR_W_BOX,
                      check_grid: bool = True, max_boxes: int = 200_000, minimum: float = 0.0) -> bool:
    """The friction positivity check (§5.3), the one used everywhere: mu_f(w, P, theta) >=
    ``minimum`` (default 0) everywhere in P in [0, 6] MPa, theta in [0, 230] C, w in [0, 30]
    rad/s (by default).

    Exact box bounds (interval branch-and-bound, certified) and, with ``check_grid``, a dense
    grid as a second opinion: both must agree that the friction stays non-negative."""
    a = np.asarray(a, float)
    if not friction_positive_many(a[None, :], i, p_range, theta_range, w_range, max_boxes, minimum)[0]:
        return False
    if check_grid:
        return friction_min_grid(a, i, p_range, theta_range, w_range) >= minimum
    return True
