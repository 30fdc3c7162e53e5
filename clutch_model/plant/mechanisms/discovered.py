"""discovered: terms beyond the catalog found from the data (clutch_model.discovery), applied
inside the compiled plant, so replay, the batch simulator and the node all apply them. Not a
catalog entry (``mechanisms.EXTENSIONS``): it has no single magnitude and is not a diagnosis
candidate; it composes after the catalog's mechanisms.

A model file writes it as

    mechanisms:
    - id: discovered
      terms: ["mu:slip_power", "mu:pressure*pack_temperature"]
      coefficients: [-0.04, 0.002]

Term ids read ``<kind>:<signal>[*<signal>][@<tau>s]``:

* kind ``mu``: a multiplier on the friction coefficient, μ_f · (1 + Σ c·g) (floored at 0.05);
  kind ``torque``: an additive torque Σ c·g [N·m] while the clutch slips (it heats the pack
  like the rest of the transmitted torque);
* signals (kernels.SIG_*): ``pressure`` [MPa], ``pack_temperature`` (θ_pack − 60 °C) [°C],
  ``slip_abs`` |ω| [rad/s], ``slip`` ω [rad/s], ``slip_sign`` sign(ω), ``slip_power`` |ω·T|
  of the previous sample's output [kW], ``energy`` dissipated since the campaign start [MJ],
  ``force_rate`` pack-force rate over the last step [kN/s], ``sin_slip_angle`` /
  ``cos_slip_angle`` of the slip angle ∫ω dt since the run start (once per revolution),
  ``slip_rate`` the slip's change over the last step [rad/s²] (0 on a run's first row; an
  inertia between the clutch and the torque sensor reads J·dω/dt);
* ``@<tau>s``: the product passes a first-order low-pass with time constant tau (a dynamic
  on the friction or torque path, e.g. a surface temperature that follows the slip power),
  its state 0 at each run start.
"""
from __future__ import annotations

import re

import numpy as np

from clutch_model.errors import ParamsError
from clutch_model.plant import layout as P
from clutch_model.plant import layout as K   # the signal and term codes the kernels read
from clutch_model.plant.mechanisms.base import Mechanism
from clutch_model.plant.mechanisms.friction_degradation import FrictionDegradation

SIGNALS = {
    "pressure": K.SIG_PRESSURE,
    "pack_temperature": K.SIG_PACK_TEMP,
    "slip_abs": K.SIG_SLIP_ABS,
    "slip_power": K.SIG_SLIP_POWER,
    "energy": K.SIG_ENERGY,
    "force_rate": K.SIG_FORCE_RATE,
    "sin_slip_angle": K.SIG_SIN_ANGLE,
    "cos_slip_angle": K.SIG_COS_ANGLE,
    "slip": K.SIG_SLIP,
    "slip_sign": K.SIG_SLIP_SIGN,
    "slip_rate": K.SIG_SLIP_RATE,
}
KINDS = {"mu": K.TERM_FRICTION, "torque": K.TERM_TORQUE}
_TERM_RE = re.compile(r"^(mu|torque):([a-z_]+)(?:\*([a-z_]+))?(?:@([0-9.eE+-]+)s)?$")


def parse_term(term_id: str):
    """'mu:pressure*pack_temperature@0.5s' -> (kind, signal a, signal b or None, tau_s)."""
    m = _TERM_RE.match(str(term_id).strip())
    if not m:
        raise ParamsError(f"mechanism discovered: bad term '{term_id}' "
                          f"(expected <mu|torque>:<signal>[*<signal>][@<tau>s])")
    kind, a, b, tau = m.groups()
    for sig in (a, b):
        if sig is not None and sig not in SIGNALS:
            raise ParamsError(f"mechanism discovered: unknown signal '{sig}' in term '{term_id}' "
                              f"(known: {', '.join(SIGNALS)})")
    tau_s = float(tau) if tau else 0.0
    if not (np.isfinite(tau_s) and 0.0 <= tau_s <= 1e4):
        raise ParamsError(f"mechanism discovered: time constant of '{term_id}' must be in [0, 1e4] s")
    return kind, a, b, tau_s


def term_id(kind: str, a: str, b: str | None = None, tau_s: float = 0.0) -> str:
    out = f"{kind}:{a}" + (f"*{b}" if b else "")
    return out + (f"@{tau_s:g}s" if tau_s > 0 else "")


class Discovered(Mechanism):
    """Terms found from the data (see the module docstring). ``energy_history`` is the same
    optional campaign state as friction_degradation's (energy terms carry the campaign)."""

    id = "discovered"
    path = "friction"              # and an additive part of the transmitted torque
    parameters = ()
    state_keys = ("terms", "coefficients", "energy_history")
    physics = "terms beyond the catalog found from the data: mu_f (1 + sum c g) and torque + sum c g"
    diagnosis_candidate = False    # found by clutch_model.discovery, not fitted as a catalog candidate

    def __post_init__(self):
        super().__post_init__()
        terms = self.values.get("terms")
        coefs = self.values.get("coefficients")
        if not isinstance(terms, (list, tuple)) or not isinstance(coefs, (list, tuple)):
            raise ParamsError("mechanism discovered: needs lists 'terms' and 'coefficients'")
        if len(terms) != len(coefs):
            raise ParamsError("mechanism discovered: 'terms' and 'coefficients' differ in length")
        if len(terms) > P.MAX_DISCOVERED_TERMS:
            raise ParamsError(f"mechanism discovered: at most {P.MAX_DISCOVERED_TERMS} terms")
        try:
            coefs = [float(c) for c in coefs]
        except (TypeError, ValueError):
            raise ParamsError("mechanism discovered: coefficients must be numbers") from None
        if not all(np.isfinite(coefs)):
            raise ParamsError("mechanism discovered: coefficients must be finite")
        self._parsed = [parse_term(t) for t in terms]
        self.values["terms"] = [str(t) for t in terms]
        self.values["coefficients"] = coefs
        hist = self.values.get("energy_history")
        if hist is not None:
            try:
                self.values["energy_history"] = sorted([int(t), float(e)] for t, e in hist)
            except (TypeError, ValueError):
                raise ParamsError("mechanism discovered: energy_history must be "
                                  "[[log_time_ns, energy_j], ...]") from None

    def copy(self):
        return Discovered({k: (list(v) if isinstance(v, list) else v) for k, v in self.values.items()})

    def to_dict(self) -> dict:
        out = {"id": self.id, "terms": list(self.values["terms"]),
               "coefficients": [float(c) for c in self.values["coefficients"]]}
        if self.values.get("energy_history") is not None:
            out["energy_history"] = self.values["energy_history"]
        return out

    @property
    def parameter_values(self) -> dict:
        return dict(zip(self.values["terms"], self.values["coefficients"]))

    def apply_to_vector(self, p):
        p[P.DISC_N] = len(self._parsed)
        for j, ((kind, a, b, tau), c) in enumerate(zip(self._parsed, self.values["coefficients"])):
            base = P.DISC_SLOTS + P.DISC_SLOT * j
            p[base] = KINDS[kind]
            p[base + 1] = SIGNALS[a]
            p[base + 2] = SIGNALS[b] if b else K.SIG_NONE
            p[base + 3] = tau
            p[base + 4] = c

    # campaign energy known at or before time_ns, read from energy_history as friction_degradation does
    energy_at = FrictionDegradation.energy_at
