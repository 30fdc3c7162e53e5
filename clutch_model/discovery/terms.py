"""Candidate terms with physical meaning, each one object (in the manner of PySINDy's
feature library, and of the catalog's mechanisms): an id the plant understands
(clutch_model.plant.mechanisms.discovered), the units of its coefficient, a plain-words reading, its
feature function of the plant's own signals, and its kind:

* ``mu``: a multiplier on the friction coefficient, μ_f · (1 + c·g);
* ``torque``: an additive torque c·g while the clutch slips;
* either, with ``tau_s`` > 0: g passes a first-order low-pass first (a dynamic on the friction
  or torque path, e.g. a lining surface temperature that follows the slip power).

The library leaves out what the calibrated friction polynomials already represent (μ_f in P,
P², θ, θ², and k_V·ω with k_V linear in P and θ): a multiplier in P, θ or ω alone, or P·ω,
θ·ω, would only re-fit the friction; P·θ is not in the polynomials and is a candidate.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from clutch_model.plant import kernels as K
from clutch_model.plant.mechanisms.discovered import parse_term, term_id

# signal name -> (units, words)
SIGNAL_INFO = {
    "pressure": ("MPa", "contact pressure"),
    "pack_temperature": ("°C", "pack temperature above 60 °C"),
    "slip_abs": ("rad/s", "slip speed"),
    "slip": ("rad/s", "signed slip speed"),
    "slip_sign": ("", "slip direction"),
    "slip_power": ("kW", "slip power"),
    "energy": ("MJ", "energy dissipated since the campaign start"),
    "force_rate": ("kN/s", "pack-force rate"),
    "sin_slip_angle": ("", "sine of the slip angle"),
    "cos_slip_angle": ("", "cosine of the slip angle"),
    "slip_rate": ("rad/s²", "slip acceleration"),
}
RIPPLE_PAIR = ("sin_slip_angle", "cos_slip_angle")


@dataclass
class TermSignals:
    """The plant signals terms are built from, on the campaign grid (kernels.term_signal's
    definitions, evaluated on a simulated trajectory), plus what the regressors need."""

    t: np.ndarray
    run_start: np.ndarray
    values: dict                    # signal name -> array
    asperity_torque_nm: np.ndarray  # what a mu multiplier scales
    friction_coefficient: np.ndarray
    locked: np.ndarray

    @classmethod
    def from_simulation(cls, campaign, sim) -> "TermSignals":
        t, rs = np.asarray(campaign.t, float), np.asarray(campaign.run_start, bool)
        w = np.clip(np.asarray(campaign.slip, float), -K.SLIP_LIMIT, K.SLIP_LIMIT)
        dt = np.diff(t, prepend=t[:1])
        dt[rs] = 0.0
        power_prev = np.concatenate([[0.0], sim.power_w[:-1]])
        power_prev[rs] = 0.0

        def per_step(x):
            """x's change over the last step / its length (0 on each run's first row)."""
            dx = np.diff(x, prepend=x[:1])
            dx[rs] = 0.0
            return np.where(dt > 0, dx / np.where(dt > 0, dt, 1.0), 0.0)

        rate = per_step(np.asarray(sim.pack_force_n, float)) * 1e-3
        # slip rate over the last step (kernel: the slip held over the last advance)
        slip_rate = per_step(w)
        # slip angle: left Riemann sum of the held slip, restarted at each run (kernel order)
        incr = np.concatenate([[0.0], w[:-1] * np.diff(t)])
        incr[rs] = 0.0
        angle = np.empty_like(incr)
        starts = np.flatnonzero(rs)
        for a, b in zip(starts, np.append(starts[1:], t.size)):
            angle[a:b] = np.cumsum(incr[a:b])
        values = {
            "pressure": np.asarray(sim.pressure_mpa, float),
            "pack_temperature": np.asarray(sim.pack_temperature_c, float) - K.THETA_REF_C,
            "slip_abs": np.abs(w),
            "slip": w,
            "slip_sign": np.sign(w),
            "slip_power": power_prev * 1e-3,
            "energy": np.asarray(sim.energy_j, float) * 1e-6,
            "force_rate": rate,
            "sin_slip_angle": np.sin(angle),
            "cos_slip_angle": np.cos(angle),
            "slip_rate": slip_rate,
        }
        return cls(t=t, run_start=rs, values=values,
                   asperity_torque_nm=np.asarray(sim.asperity_torque_nm, float),
                   friction_coefficient=np.asarray(sim.friction_coefficient, float),
                   locked=np.asarray(sim.locked, bool))


def low_pass(g: np.ndarray, t: np.ndarray, run_start: np.ndarray, tau_s: float) -> np.ndarray:
    """First-order low-pass per run, state 0 at the run start, driven by the previous row's
    value over each step (the kernel's order)."""
    out = np.zeros_like(g)
    starts = np.flatnonzero(run_start)
    for a, b in zip(starts, np.append(starts[1:], g.size)):
        x = 0.0
        for k in range(a + 1, b):
            x += (g[k - 1] - x) * -math.expm1(-(t[k] - t[k - 1]) / tau_s)
            out[k] = x
    return out


@dataclass(frozen=True)
class Term:
    """One candidate term: ``kind`` 'mu' or 'torque', signals ``a`` (× ``b``), low-pass
    ``tau_s`` (0: none)."""

    kind: str
    a: str
    b: str | None = None
    tau_s: float = 0.0

    @classmethod
    def from_id(cls, tid: str) -> "Term":
        kind, a, b, tau = parse_term(tid)
        return cls(kind, a, b, tau)

    @property
    def id(self) -> str:
        return term_id(self.kind, self.a, self.b, self.tau_s)

    @property
    def signal_units(self) -> str:
        units = [SIGNAL_INFO[s][0] for s in (self.a, self.b) if s and SIGNAL_INFO[s][0]]
        return "·".join(units)

    @property
    def units(self) -> str:
        """Units of the coefficient."""
        su = self.signal_units
        if self.kind == "mu":
            return f"1/({su})" if su else "1"
        return f"N·m/({su})" if su else "N·m"

    @property
    def words(self) -> str:
        w = SIGNAL_INFO[self.a][1]
        if self.b:
            w += " × " + SIGNAL_INFO[self.b][1]
        if self.tau_s > 0:
            w += f" (low-passed, τ = {self.tau_s:.3g} s)"
        return w

    @property
    def template(self) -> str:
        """Plain-words reading; format with pct (100·c) or c."""
        per = f" per {self.signal_units}" if self.signal_units else ""
        if self.kind == "mu":
            return "μ_f {direction} {pct_abs:.3g} %" + per + " of " + self.words
        return "the torque gains {c:.3g} N·m" + per + " of " + self.words

    def reading(self, c: float) -> str:
        return self.template.format(direction="rises" if c >= 0 else "falls", pct_abs=abs(100.0 * c),
                                    pct=100.0 * c, c=c)

    def feature(self, sig: TermSignals) -> np.ndarray:
        """g(t): the product of the term's signals (low-passed if tau_s > 0)."""
        g = sig.values[self.a].copy()
        if self.b:
            g = g * sig.values[self.b]
        if self.tau_s > 0:
            g = low_pass(g, sig.t, sig.run_start, self.tau_s)
        return g

    def regressor(self, sig: TermSignals) -> np.ndarray:
        """d(torque)/dc at c = 0: g × asperity torque for a mu multiplier, g for a torque term
        (0 where the clutch is locked: a torque term acts while it slips)."""
        g = self.feature(sig)
        if self.kind == "mu":
            return g * sig.asperity_torque_nm
        return np.where(sig.locked, 0.0, g)


# products of pairs the polynomials do not represent (P*w and theta*w are k_V terms,
# squares of P and theta are in every polynomial)
_PRODUCT_SIGNALS = ("pressure", "pack_temperature", "slip_abs", "slip_power", "energy")
_IN_POLYNOMIALS = {("pressure", "slip_abs"), ("pack_temperature", "slip_abs"),
                   ("pressure", "pressure"), ("pack_temperature", "pack_temperature")}


def default_library() -> list:
    """The candidate terms ``discover`` searches (see the module docstring)."""
    terms = [Term("mu", "slip_power"), Term("mu", "energy"), Term("mu", "force_rate"),
             Term("mu", "sin_slip_angle"), Term("mu", "cos_slip_angle"),
             Term("mu", "slip_power", tau_s=0.3), Term("mu", "slip_power", tau_s=3.0)]
    for a, b in itertools.combinations_with_replacement(_PRODUCT_SIGNALS, 2):
        if (a, b) in _IN_POLYNOMIALS or a == b and a != "slip_abs":
            continue
        terms.append(Term("mu", a, b))
    terms += [Term("torque", "slip_sign"), Term("torque", "slip"), Term("torque", "slip", "slip_abs"),
              Term("torque", "slip_rate")]
    return terms


def partner(term: Term) -> Term | None:
    """The other half of a once-per-revolution pair (its phase is arbitrary)."""
    if term.a in RIPPLE_PAIR and term.b is None:
        other = RIPPLE_PAIR[1 - RIPPLE_PAIR.index(term.a)]
        return Term(term.kind, other, None, term.tau_s)
    return None


def describe(terms, coefficients, intervals=None, tau_intervals=None) -> list:
    """Plain-words readings of fitted terms (with the 95 % intervals of their coefficients and
    fitted time constants when given); a sin/cos ripple pair is read as one amplitude."""
    coefs = dict(zip([t.id for t in terms], coefficients))
    lines, done = [], set()
    for t, c in zip(terms, coefficients):
        if t.id in done:
            continue
        p = partner(t)
        if p is not None and p.id in coefs:
            cs = coefs[Term(t.kind, "sin_slip_angle", None, t.tau_s).id]
            cc = coefs[Term(t.kind, "cos_slip_angle", None, t.tau_s).id]
            amp = math.hypot(cs, cc)
            phase = math.degrees(math.atan2(cc, cs))
            lines.append(f"μ_f ripples ±{100 * amp:.3g} % once per revolution of slip "
                         f"(phase {phase:.0f}° from each run's start)")
            done |= {t.id, p.id}
            continue
        text = t.reading(c)
        if intervals is not None and t.id in intervals:
            lo, hi = intervals[t.id]
            if t.kind == "mu":
                text += f" (95 % interval {100 * lo:.3g} to {100 * hi:.3g} %)"
            else:
                text += f" (95 % interval {lo:.3g} to {hi:.3g})"
        if tau_intervals is not None and t.id in tau_intervals:
            lo, hi = tau_intervals[t.id]
            text += f"; τ 95 % interval {lo:.3g} to {hi:.3g} s"
        lines.append(text)
        done.add(t.id)
    return lines
