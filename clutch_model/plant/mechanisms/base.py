"""What a mechanism is: one object that describes itself (in the manner of PySINDy's
candidate terms).

A mechanism class carries
  * ``id`` and a one-line ``physics`` description,
  * ``path``: what it acts on, one of PATHS (the force reaching the pack, the friction, the
    transmitted torque, the measurement),
  * ``parameters``: its physical parameters (name, unit, physical bounds checked on load),
  * ``search_space(scale)``: how a fit searches them on a campaign (log or linear, bounds,
    start grid),
  * ``virtual_car``: the range in which the virtual test car draws it and its default,
  * its hook: a plant mechanism writes ``kernel_slot`` of the kernel parameter vector
    (``apply_to_vector``), a measurement mechanism maps plant torque to what the sensor
    reads (``apply_to_measurement``).
An instance holds the parameter values (``values``) of one model.

Mechanisms compose: each acts on its own path, and mechanisms on one path apply in catalog
order (``CATALOG``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from clutch_model.errors import ParamsError

PATHS = ("pack_force", "friction", "transmitted_torque", "measurement")


@dataclass(frozen=True)
class Parameter:
    """A physical parameter of a mechanism."""
    name: str
    unit: str
    bounds: tuple                  # (lo, hi) physically admissible, checked when a model loads
    description: str = ""


_LOG_MAX = math.log(np.finfo(float).max)


@dataclass(frozen=True)
class ParamSpec:
    """How a fit searches one parameter: transform, bounds and a start grid."""
    name: str
    log: bool
    lo: float
    hi: float
    grid: np.ndarray

    def to_x(self, v):
        return math.log(v) if self.log else float(v)

    def from_x(self, x):
        """The parameter's value at ``x`` (a log-searched value beyond float range: inf, e.g.
        the end of a wide interval)."""
        if not self.log:
            return float(x)
        return math.exp(x) if x < _LOG_MAX else math.inf


@dataclass(frozen=True)
class CampaignScale:
    """What a search space may depend on: the campaign's scales."""
    max_force_n: float
    max_slip_rad_s: float
    energy_total_j: float
    torque_scale_nm: float

    @classmethod
    def of(cls, campaign, energy_total_j: float, torque_scale_nm: float) -> "CampaignScale":
        force = np.asarray(campaign.force, float)
        slip = np.asarray(campaign.slip, float)
        return cls(max_force_n=float(np.nanmax(force)) if force.size else 1e4,
                   max_slip_rad_s=float(np.nanmax(np.abs(slip))) if slip.size else 0.0,
                   energy_total_j=float(energy_total_j), torque_scale_nm=float(torque_scale_nm))


@dataclass(frozen=True)
class VirtualCarRange:
    """How the virtual test car hides the mechanism: magnitudes in ``visible`` (lo, hi) show
    against the default sensor noise; ``default`` is used when none is given (None: the car
    derives one from the campaign, see clutch_model.virtual_car.campaign)."""
    visible: tuple | None
    default: float | None


@dataclass
class Mechanism:
    """Base class. ``values`` maps parameter name -> value."""

    values: dict = field(default_factory=dict)

    id = "base"
    path = "pack_force"
    parameters = ()                # Parameter objects
    physics = ""
    virtual_car = VirtualCarRange(None, None)
    kernel_slot = None             # index in the kernel parameter vector (plant mechanisms)
    diagnosis_candidate = True     # fitted as a candidate by `clutch-sim diagnose`
    state_keys = ()                # non-fitted entries carried in the model file (campaign state)
    force_band = None              # parameter that is a band on the force as a share of it (a play
                                   # operator's half-width): resolved only when wider than the force noise
    force_level = None             # parameter that is a constant on the force (N, a preload): resolved
                                   # only when larger than the force noise
    friction_decay = None          # parameter that is the energy per e-fold of the friction (J): resolved
                                   # only when the friction it takes over the campaign is a few per cent
    torque_level = None            # parameter that is a constant torque on the measurement (a sensor
                                   # bias): resolved only when it stands out of the residual's slow wander

    # -- description --------------------------------------------------------------------
    @property
    def kind(self) -> str:
        """"measurement" or "plant" (everything that changes what the plant transmits)."""
        return "measurement" if self.path == "measurement" else "plant"

    @classmethod
    def parameter_names(cls) -> tuple:
        return tuple(p.name for p in cls.parameters)

    @classmethod
    def time_parameter_names(cls) -> tuple:
        """Its parameters in seconds (a delay, a lag): a mechanism that acts in time."""
        return tuple(p.name for p in cls.parameters if p.unit == "s")

    @classmethod
    def magnitude_parameter(cls) -> str:
        """The parameter a single magnitude sets (the virtual car, the CLI's --magnitude)."""
        return cls.parameters[0].name

    @classmethod
    def search_space(cls, scale: CampaignScale) -> list:
        """[ParamSpec] for fitting on a campaign of this ``scale``."""
        raise NotImplementedError

    # -- values ---------------------------------------------------------------------------
    def __post_init__(self):
        names = self.parameter_names()
        unknown = set(self.values) - set(names) - set(self.state_keys)
        if unknown:
            raise ParamsError(f"mechanism {self.id}: unknown entry '{sorted(unknown)[0]}' "
                              f"(parameters: {', '.join(names)})")
        for par in self.parameters:
            if par.name not in self.values:
                raise ParamsError(f"mechanism {self.id}: missing parameter '{par.name}'")
            v = float(self.values[par.name])
            if not np.isfinite(v):
                raise ParamsError(f"mechanism {self.id}: '{par.name}' must be finite")
            lo, hi = par.bounds
            if not (lo <= v <= hi):
                raise ParamsError(f"mechanism {self.id}: '{par.name}'={v} outside [{lo}, {hi}]")
            self.values[par.name] = v

    def copy(self):
        return type(self)({k: (list(v) if isinstance(v, list) else v) for k, v in self.values.items()})

    def to_dict(self) -> dict:
        names = self.parameter_names()
        return {"id": self.id, **{k: float(v) if k in names else v for k, v in self.values.items()}}

    @property
    def parameter_values(self) -> dict:
        return {k: self.values[k] for k in self.parameter_names()}

    # -- hooks ----------------------------------------------------------------------------
    def apply_to_vector(self, p: np.ndarray) -> None:
        """Plant mechanisms write their parameter into their kernel slot."""
        if self.kernel_slot is not None:
            p[self.kernel_slot] = self.values[self.magnitude_parameter()]

    def apply_to_measurement(self, t: np.ndarray, torque: np.ndarray, run_start: np.ndarray) -> np.ndarray:
        """Measurement mechanisms map plant torque to what the sensor reads."""
        return torque


def run_bounds(run_start, n: int):
    """[(first row, end row)] of each run of a concatenated campaign grid."""
    starts = np.flatnonzero(run_start)
    if starts.size == 0 or starts[0] != 0:
        starts = np.concatenate([[0], starts])
    ends = np.append(starts[1:], n)
    return list(zip(starts.tolist(), ends.tolist()))
