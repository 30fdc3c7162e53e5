"""Constraint checking of the friction polynomials over a (P, theta) box, and of the
friction coefficient itself over a (P, theta, w) box.

The Stribeck coefficients mu_C, mu_S, omega_S, k_V are separable quadratics
q(P, theta) = c0 + c1 P + c2 P^2 + c3 theta + c4 theta^2 (thesis eq. 4.10-4.14). Their
minimum and maximum over a box is the constant plus the 1-D extrema of the P part and of
the theta part, and each 1-D extremum sits at an end of its interval or at the vertex
-c1/(2 c2) when that is inside. That is the thesis' check at corners, interior extrema and
edge extrema (eq. 5.4-5.9), evaluated exactly: every one of the thesis' candidate points is
one of the 3 x 3 products of {lo, hi, vertex} in P and theta.

For the optimiser the same idea gives a continuous constraint function: the 9 points
(P_k, theta_l) with P_k in {lo, hi, clip(vertex)} (likewise theta) all lie in the box, so
demanding lo <= q <= hi at those points is neither stronger nor weaker than demanding it
on the whole box. Their gradients with respect to the coefficients are the monomials at
the points (the vertex moves with the coefficients, but q is stationary there).

The friction coefficient mu_f = mu_C + (mu_S - mu_C) exp(-(w/omega_S)^i) + k_V w is not a
polynomial; ``friction_positive`` certifies mu_f >= 0 over a (P, theta, w) box by interval
branch-and-bound (numba) after a quick vectorised pre-check, with a dense grid as the
fallback answer if the branch-and-bound runs out of budget (it practically never does).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from clutch_model.plant.kernels import P_MAX_MPA, THETA_MAX_C

# the box the polynomials are constrained on (thesis §5.2.1, docs/model.md)
P_BOX = (0.0, P_MAX_MPA)
THETA_BOX = (0.0, THETA_MAX_C)
# the box of the positivity check of §5.3 (car operating range)
CAR_P_BOX = (0.0, 6.0)
CAR_THETA_BOX = (0.0, 230.0)
CAR_W_BOX = (0.0, 30.0)

# blocks of the coefficient vector a0..a19 (thesis table 6.3 order, docs/model.md)
BLOCKS = {"mu_C": slice(0, 5), "mu_S": slice(5, 10), "omega_S": slice(10, 15), "k_V": slice(15, 20)}
BLOCK_OF = ["mu_C"] * 5 + ["mu_S"] * 5 + ["omega_S"] * 5 + ["k_V"] * 5
MONOMIAL = ["1", "P", "P^2", "theta", "theta^2"]
COEFF_NAMES = [f"a{k}" for k in range(20)]

# chapter 4 inequalities (strict ones get a tiny margin in the fitter)
OMEGA_S_RANGE = (0.001, 0.05)
K_V_RANGE = (-0.01, 0.01)


def coefficient_label(k: int) -> str:
    return f"a{k} ({BLOCK_OF[k]}: {MONOMIAL[k % 5]})"


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


# --- chapter 4 constraints over the P, theta box ----------------------------------------------
@dataclass
class ConstraintReport:
    """One inequality of chapter 4 checked over the box."""

    name: str            # e.g. "omega_S <= 0.05"
    block: str           # mu_C | mu_S | omega_S | k_V | i
    bound: float
    side: str            # "lower" | "upper"
    extreme: float       # min (lower) or max (upper) of the block over the box
    at_pressure_mpa: float
    at_theta_c: float
    margin: float        # extreme - bound (lower) or bound - extreme (upper); >= 0 satisfied
    satisfied: bool
    active: bool

    def describe(self) -> str:
        where = ("" if self.block == "i" else
                 f" at P={self.at_pressure_mpa:.3g} MPa, theta={self.at_theta_c:.4g} C")
        state = "ACTIVE" if self.active else ("ok" if self.satisfied else "VIOLATED")
        return f"{self.name}: extreme {self.extreme:.6g}{where} (margin {self.margin:.3g}, {state})"

    def to_dict(self) -> dict:
        return {k: (float(v) if isinstance(v, (float, np.floating)) else v)
                for k, v in self.__dict__.items()}


def constraint_bounds(mu_offset: float):
    """[(block, lower, upper)] of chapter 4 (eq. 4.2, 4.5, 4.6, 4.8); None = unbounded."""
    return [("mu_S", 0.0, None), ("mu_C", 0.0, float(mu_offset)),
            ("omega_S", OMEGA_S_RANGE[0], OMEGA_S_RANGE[1]), ("k_V", K_V_RANGE[0], K_V_RANGE[1])]


def check_constraints(a, i, mu_offset, p_range=P_BOX, theta_range=THETA_BOX,
                      active_tol: float = 1e-6, active_abs: float = 3e-6) -> list:
    """Every inequality of chapter 4 over the box, evaluated exactly (see module doc).
    A constraint is *active* when its margin is below ``active_tol`` (relative to the bound's
    scale) or ``active_abs`` (the fitter keeps strict inequalities 1e-6 inside)."""
    a = np.asarray(a, float)
    out = []
    for block, lo, hi in constraint_bounds(mu_offset):
        c = a[BLOCKS[block]]
        vmin, vmax, (pmin, tmin), (pmax, tmax) = poly_range(c, p_range, theta_range)
        scale = max(abs(lo or 0.0), abs(hi or 0.0), 1e-3)
        tol = max(active_tol * scale, active_abs)
        if lo is not None:
            m = float(vmin - lo)
            out.append(ConstraintReport(f"{block} > {lo:g}", block, lo, "lower", float(vmin), float(pmin),
                                        float(tmin), m, m >= -active_tol * scale, abs(m) <= tol))
        if hi is not None:
            m = float(hi - vmax)
            out.append(ConstraintReport(f"{block} < {hi:g}", block, hi, "upper", float(vmax), float(pmax),
                                        float(tmax), m, m >= -active_tol * scale, abs(m) <= tol))
    m = float(i)
    out.append(ConstraintReport("i > 0", "i", 0.0, "lower", float(i), math.nan, math.nan, m, m > 0, m <= active_tol))
    return out


def constraints_satisfied(a, i, mu_offset, p_range=P_BOX, theta_range=THETA_BOX, tol=1e-9) -> bool:
    return all(r.margin >= -tol for r in check_constraints(a, i, mu_offset, p_range, theta_range))


def grid_extrema(a, p_range=P_BOX, theta_range=THETA_BOX, n_p=201, n_theta=231):
    """{block: (min, max)} on a dense grid (independent check of the exact ranges)."""
    a = np.asarray(a, float)
    pg, tg = np.meshgrid(np.linspace(*p_range, n_p), np.linspace(*theta_range, n_theta), indexing="ij")
    return {b: (float(eval_poly(a[s], pg, tg).min()), float(eval_poly(a[s], pg, tg).max()))
            for b, s in BLOCKS.items()}


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
def _mu_raw(a, i, w, pr, th):
    """mu_f before the kernel's floor at 0 (omega_S floored at 1e-6 as in the kernel)."""
    pr2, th2 = pr * pr, th * th
    mu_c = a[0] + a[1] * pr + a[2] * pr2 + a[3] * th + a[4] * th2
    mu_s = a[5] + a[6] * pr + a[7] * pr2 + a[8] * th + a[9] * th2
    w_s = a[10] + a[11] * pr + a[12] * pr2 + a[13] * th + a[14] * th2
    k_v = a[15] + a[16] * pr + a[17] * pr2 + a[18] * th + a[19] * th2
    if w_s < 1e-6:
        w_s = 1e-6
    r = w / w_s
    e = math.exp(-(r ** i)) if r < 1e6 else 0.0
    return mu_c + (mu_s - mu_c) * e + k_v * w


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
def friction_min_bb(a, i, plo, phi, tlo, thi, wlo, whi, max_boxes):
    """Branch-and-bound on min mu_f over the box. Returns (status, best point value, lower
    bound): status +1 certified mu_f >= 0 everywhere, -1 found mu_f < 0, 0 undecided."""
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
        v = _mu_raw(a, i, 0.5 * (b4 + b5), 0.5 * (b0 + b1), 0.5 * (b2 + b3))
        v0 = _mu_raw(a, i, b4, 0.5 * (b0 + b1), 0.5 * (b2 + b3))
        v = min(v, v0)
        if v < best:
            best = v
        if v < 0.0:
            return -1, best, min(glb, v)
        lb, espan = _lower_bound(a, i, b0, b1, b2, b3, b4, b5)
        if lb >= 0.0:
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
    mu_c = eval_poly(a[0:5], P, T)
    mu_s = eval_poly(a[5:10], P, T)
    w_s = np.maximum(eval_poly(a[10:15], P, T), 1e-6)
    k_v = eval_poly(a[15:20], P, T)
    r = W / w_s
    with np.errstate(over="ignore"):
        e = np.where(r < 1e6, np.exp(-np.power(r, float(i))), 0.0)
    return float((mu_c + (mu_s - mu_c) * e + k_v * W).min())


def _quick_reject(A, i, p_range, theta_range, w_range):
    """Vectorised: True where mu_f < 0 at one of a few candidate points (w = lo, w = hi at
    the extremal points of mu_S and mu_C + k_V w_hi)."""
    A = np.atleast_2d(np.asarray(A, float))
    bad = np.zeros(A.shape[0], bool)
    # mu_f(w_lo) with w_lo = 0 is mu_S: its exact box minimum
    if w_range[0] == 0.0:
        smin = poly_range(A[:, 5:10], p_range, theta_range)[0]
        bad |= smin < 0.0
    whi = w_range[1]
    comb = A[:, 0:5] + whi * A[:, 15:20]   # mu_C + k_V w_hi (e ~ 0 at large w)
    pp, tt = poly_candidates(comb, p_range, theta_range)
    for j in range(pp.shape[1]):
        for k in range(A.shape[0]):
            if not bad[k] and _mu_raw(A[k], float(i), whi, pp[k, j], tt[k, j]) < 0.0:
                bad[k] = True
    return bad


def friction_positive_many(A, i, p_range=CAR_P_BOX, theta_range=CAR_THETA_BOX, w_range=CAR_W_BOX,
                           max_boxes: int = 200_000) -> np.ndarray:
    """mu_f >= 0 over the (P, theta, w) box for each coefficient row of A (S, 20)."""
    A = np.ascontiguousarray(np.atleast_2d(np.asarray(A, float)))
    ok = ~_quick_reject(A, i, p_range, theta_range, w_range)
    for k in np.flatnonzero(ok):
        status, _, _ = friction_min_bb(A[k], float(i), float(p_range[0]), float(p_range[1]),
                                       float(theta_range[0]), float(theta_range[1]),
                                       float(w_range[0]), float(w_range[1]), int(max_boxes))
        if status == 0:  # undecided within budget: the dense grid decides
            ok[k] = friction_min_grid(A[k], i, p_range, theta_range, w_range) >= 0.0
        else:
            ok[k] = status > 0
    return ok


def friction_positive(a, i, p_range=CAR_P_BOX, theta_range=CAR_THETA_BOX, w_range=CAR_W_BOX,
                      check_grid: bool = True, max_boxes: int = 200_000) -> bool:
    """The friction positivity check of §5.3: mu_f(w, P, theta) >= 0 everywhere in
    P in [0, 6] MPa, theta in [0, 230] C, w in [0, 30] rad/s (by default).

    Exact box bounds (interval branch-and-bound, certified) and, with ``check_grid``, a dense
    grid as a second opinion: both must agree that the friction stays non-negative."""
    a = np.asarray(a, float)
    if not friction_positive_many(a[None, :], i, p_range, theta_range, w_range, max_boxes)[0]:
        return False
    if check_grid:
        return friction_min_grid(a, i, p_range, theta_range, w_range) >= 0.0
    return True
