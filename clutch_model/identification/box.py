"""Constraint checking of the friction polynomials over a (P, theta) box (chapter 4).

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

The exact 1-D/2-D range machinery and the positivity check of mu_f itself over a
(P, theta, w) box live with the friction law (``clutch_model.plant.friction``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clutch_model.plant.friction import (BLOCK_OF, BLOCKS, CAR_P_BOX, CAR_THETA_BOX, CAR_W_BOX,  # noqa: F401
                                         MONOMIAL, P_BOX, THETA_BOX, eval_poly, friction_min_bb,
                                         friction_min_grid, friction_positive, friction_positive_many,
                                         poly_candidates, poly_range)

# the polynomials are constrained on P_BOX x THETA_BOX (thesis §5.2.1, docs/model.md)
COEFF_NAMES = [f"a{k}" for k in range(20)]

# chapter 4 inequalities (strict ones get a tiny margin in the fitter)
OMEGA_S_RANGE = (0.001, 0.05)
K_V_RANGE = (-0.01, 0.01)


def coefficient_label(k: int) -> str:
    return f"a{k} ({BLOCK_OF[k]}: {MONOMIAL[k % 5]})"


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
