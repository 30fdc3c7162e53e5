"""Interval halving (thesis §6.2.2, table 6.4; the algorithm of the thesis' ref. [25]).

For a unimodal f on [a, b]: with x_m the midpoint and L = b - a, evaluate x1 = a + L/4 and
x2 = b - L/4; if f(x1) < f(x_m) keep [a, x_m] (new midpoint x1), elif f(x2) < f(x_m) keep
[x_m, b] (new midpoint x2), else keep [x1, x2]. Each iteration halves the interval with two
evaluations, which are done together (one batch-simulator call).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class HalvingResult:
    x: float
    f: float
    interval: tuple
    start_interval: tuple
    iterations: int
    evaluations: int
    history: list = field(default_factory=list)   # (a, b, x_m, f_m)


def interval_halving(f_many, a: float, b: float, rel_tol: float = 1e-3, max_iter: int = 40) -> HalvingResult:
    """Minimise a unimodal function on [a, b]. ``f_many(xs) -> array`` evaluates several points
    at once. Stops when the interval is below rel_tol of its starting length."""
    a, b = float(min(a, b)), float(max(a, b))
    start = (a, b)
    xm = 0.5 * (a + b)
    fm = float(np.asarray(f_many(np.array([xm])))[0])
    n_eval = 1
    hist = [(a, b, xm, fm)]
    L0 = b - a
    it = 0
    while (b - a) > rel_tol * L0 and it < max_iter:
        L = b - a
        x1, x2 = a + 0.25 * L, b - 0.25 * L
        f1, f2 = (float(v) for v in np.asarray(f_many(np.array([x1, x2]))))
        n_eval += 2
        if f1 < fm:
            b, xm, fm = xm, x1, f1
        elif f2 < fm:
            a, xm, fm = xm, x2, f2
        else:
            a, b = x1, x2
        it += 1
        hist.append((a, b, xm, fm))
    return HalvingResult(x=xm, f=fm, interval=(a, b), start_interval=start, iterations=it, evaluations=n_eval,
                         history=hist)
