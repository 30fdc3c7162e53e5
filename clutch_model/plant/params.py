"""Clutch parameter files (the schema of config/reference_clutch.yaml) and the flat
parameter vector the compiled kernels read.

A model file is the reference-clutch schema plus an optional ``mechanisms:`` list.
``ClutchModel`` keeps the YAML structure (so a fitted model is written back in the same
schema) and knows how to pack itself into ``vector()`` for the simulators.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
import yaml

from clutch_model.errors import ParamsError
from clutch_model.plant.layout import *  # noqa: F401,F403  (kernel vector layout)
from clutch_model.plant.mechanisms import mechanism_from_dict, ordered

# the reference clutch RC-1, shipped as package data (config/reference_clutch.yaml links to it)
REFERENCE_CLUTCH = Path(str(resources.files("clutch_model") / "data" / "reference_clutch.yaml"))

_REQUIRED = {
    "geometry": ["r_outer", "r_inner", "friction_surfaces", "separator_plates", "non_grooved_fraction"],
    "surface": ["rms_roughness", "youngs_modulus", "asperity_density", "asperity_tip_radius",
                "permeability", "lining_thickness", "beavers_joseph_chi"],
    "viscosity": ["alpha0", "alpha1"],
    "thermal": ["plate_heat_capacity", "b", "htf_min"],
    "friction": ["i", "a"],
    "initial": ["film_thickness"],
}


def _copy_tree(node):
    """A copy of the parameter tree: its dicts and lists copied, its leaves (numbers, strings)
    shared, anything else deep-copied. A fit copies the model hundreds of times, and
    ``copy.deepcopy`` of the tree was 4 % of a diagnosis."""
    if isinstance(node, dict):
        return {k: _copy_tree(v) for k, v in node.items()}
    if isinstance(node, list):
        return [_copy_tree(v) for v in node]
    if node is None or isinstance(node, (bool, int, float, str)):
        return node
    return copy.deepcopy(node)


@dataclass
class ClutchModel:
    """A clutch: the nested parameter dict of the YAML schema plus its mechanisms."""

    data: dict
    mechanisms: list = field(default_factory=list)
    source: str = "<memory>"

    # -- construction ------------------------------------------------------------------
    @classmethod
    def from_dict(cls, raw: dict, source: str = "<memory>") -> "ClutchModel":
        if not isinstance(raw, dict):
            raise ParamsError(f"{source}: not a mapping of parameter sections")
        data = copy.deepcopy({k: v for k, v in raw.items() if k != "mechanisms"})
        for section, keys in _REQUIRED.items():
            if not isinstance(data.get(section), dict):
                raise ParamsError(f"{source}: missing section '{section}'")
            for key in keys:
                if key not in data[section]:
                    raise ParamsError(f"{source}: missing '{section}.{key}'")
        mechs = [mechanism_from_dict(m, source) for m in (raw.get("mechanisms") or [])]
        model = cls(data=data, mechanisms=mechs, source=source)
        model._validate()
        return model

    def _validate(self) -> None:
        try:
            vec = self._vector_unchecked()
        except (TypeError, ValueError) as exc:
            raise ParamsError(f"{self.source}: non-numeric parameter ({exc})") from None
        if not np.all(np.isfinite(vec)):
            raise ParamsError(f"{self.source}: non-finite parameter value")
        g = self.data["geometry"]
        if not (0 < float(g["r_inner"]) < float(g["r_outer"])):
            raise ParamsError(f"{self.source}: need 0 < geometry.r_inner < geometry.r_outer")
        positive = [("geometry", "friction_surfaces"), ("geometry", "separator_plates"),
                    ("geometry", "non_grooved_fraction"), ("surface", "rms_roughness"),
                    ("surface", "youngs_modulus"), ("surface", "asperity_density"),
                    ("surface", "asperity_tip_radius"), ("surface", "permeability"),
                    ("surface", "lining_thickness"), ("viscosity", "alpha0"),
                    ("thermal", "plate_heat_capacity"), ("thermal", "htf_min"),
                    ("initial", "film_thickness")]
        for sec, key in positive:
            if not float(self.data[sec][key]) > 0:
                raise ParamsError(f"{self.source}: {sec}.{key} must be > 0")
        if len(self.data["thermal"]["b"]) != 4:
            raise ParamsError(f"{self.source}: thermal.b needs 4 values b1..b4")
        if len(self.data["friction"]["a"]) != N_FRICTION_COEFFS:
            raise ParamsError(f"{self.source}: friction.a needs 20 values a0..a19")

    # -- access --------------------------------------------------------------------------
    @property
    def friction_coefficients(self) -> np.ndarray:
        return np.asarray(self.data["friction"]["a"], dtype=float)

    @property
    def friction_exponent(self) -> float:
        return float(self.data["friction"]["i"])

    @property
    def lock_slip_rad_s(self) -> float:
        return float(self.data.get("lock_slip_rad_s", DEFAULT_LOCK_SLIP_RAD_S))

    def mechanism(self, mech_id: str):
        for m in self.mechanisms:
            if m.id == mech_id:
                return m
        return None

    def initial_energy_j(self, start_time_ns: int) -> float:
        """Dissipated campaign energy when a replay starts at ``start_time_ns``."""
        for mech_id in ("friction_degradation", "discovered"):
            m = self.mechanism(mech_id)
            if m is not None and m.values.get("energy_history") is not None:
                return m.energy_at(start_time_ns)
        return 0.0

    def copy(self) -> "ClutchModel":
        return ClutchModel(_copy_tree(self.data), [m.copy() for m in self.mechanisms], self.source)

    def with_friction(self, a=None, i=None) -> "ClutchModel":
        new = self.copy()
        if a is not None:
            new.data["friction"]["a"] = [float(x) for x in np.asarray(a, dtype=float)]
        if i is not None:
            new.data["friction"]["i"] = float(i)
        return new

    def with_mechanisms(self, mechanisms) -> "ClutchModel":
        new = self.copy()
        new.mechanisms = [m.copy() for m in mechanisms]
        return new

    def with_lock_slip(self, lock_slip_rad_s: float) -> "ClutchModel":
        new = self.copy()
        new.data["lock_slip_rad_s"] = float(lock_slip_rad_s)
        return new

    # -- kernel vector ---------------------------------------------------------------------
    def _vector_unchecked(self) -> np.ndarray:
        d = self.data
        g, s, v, th, fr = d["geometry"], d["surface"], d["viscosity"], d["thermal"], d["friction"]
        p = np.zeros(N_PARAMS)
        p[R_OUTER], p[R_INNER] = g["r_outer"], g["r_inner"]
        p[N_FRICTION], p[N_SEPARATOR] = g["friction_surfaces"], g["separator_plates"]
        p[A_RED] = g["non_grooved_fraction"]
        p[SIGMA], p[YOUNGS] = s["rms_roughness"], s["youngs_modulus"]
        p[ASP_DENSITY], p[ASP_RADIUS] = s["asperity_density"], s["asperity_tip_radius"]
        p[K_PERM], p[LINING_D], p[BJ_CHI] = s["permeability"], s["lining_thickness"], s["beavers_joseph_chi"]
        p[ALPHA0], p[ALPHA1] = v["alpha0"], v["alpha1"]
        p[PLATE_HEAT_CAPACITY] = th["plate_heat_capacity"]
        p[B1:B4 + 1] = np.asarray(th["b"], dtype=float)
        p[HTF_MIN] = th["htf_min"]
        p[FRICTION_I] = fr["i"]
        p[FRICTION_A:FRICTION_A + N_FRICTION_COEFFS] = np.asarray(fr["a"], dtype=float)
        p[H0] = d["initial"]["film_thickness"]
        p[LOCK_SLIP] = d.get("lock_slip_rad_s", DEFAULT_LOCK_SLIP_RAD_S)
        for m in ordered(self.mechanisms):
            m.apply_to_vector(p)
        return p

    def vector(self) -> np.ndarray:
        """The flat float64 parameter vector of the kernels (layout: constants above)."""
        return self._vector_unchecked()

    # -- derived quantities ------------------------------------------------------------------
    @property
    def nominal_area_m2(self) -> float:
        g = self.data["geometry"]
        return math.pi * (float(g["r_outer"]) ** 2 - float(g["r_inner"]) ** 2)

    @property
    def max_pack_force_n(self) -> float:
        """0.9 * A_N * P_a(0): above it the film has no equilibrium (docs/model.md)."""
        s = self.data["surface"]
        pa0 = (float(s["youngs_modulus"]) * math.pi * float(s["asperity_density"])
               * float(s["asperity_tip_radius"]) * float(s["rms_roughness"]) / math.sqrt(2 * math.pi))
        return 0.9 * self.nominal_area_m2 * pa0

    # -- files -------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        out = copy.deepcopy(self.data)
        if self.mechanisms:
            out["mechanisms"] = [m.to_dict() for m in self.mechanisms]
        return out


def load_model(path=None) -> ClutchModel:
    """Read a clutch parameter file (reference schema + optional mechanisms)."""
    path = Path(path) if path else REFERENCE_CLUTCH
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ParamsError(f"parameter file not found: {path}") from None
    except OSError as exc:
        raise ParamsError(f"cannot read parameter file {path}: {exc.strerror}") from None
    try:
        raw = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        line = getattr(getattr(exc, "problem_mark", None), "line", None)
        where = f" (line {line + 1})" if line is not None else ""
        raise ParamsError(f"{path}: not valid YAML{where}") from None
    return ClutchModel.from_dict(raw, source=str(path))


def _plain(obj):
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (np.floating,)):
        return float(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    return obj


def save_model(model: ClutchModel, path, header: str | None = None) -> Path:
    """Write a model in the reference schema (plus ``mechanisms:``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = yaml.safe_dump(_plain(model.to_dict()), sort_keys=False, default_flow_style=None)
    if header:
        text = "".join(f"# {line}\n" for line in header.splitlines()) + text
    path.write_text(text)
    return path
