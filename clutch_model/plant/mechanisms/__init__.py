"""Candidate model extensions: the mechanism catalog.

Each mechanism is one object in its own module (see ``base.Mechanism``): id, parameters with
units and physical bounds, search space for fitting, the virtual car's range, the path it acts
on and its hook into the kernels. ``CATALOG`` lists them in the contract's table order, which
is also the order in which mechanisms on one path compose. Adding a mechanism = one module
here (plus a kernel slot and kernel code if it changes the plant).
"""
from __future__ import annotations

from clutch_model.errors import ParamsError
from clutch_model.plant.mechanisms.actuator_hysteresis import ActuatorHysteresis
from clutch_model.plant.mechanisms.actuator_lag import ActuatorLag
from clutch_model.plant.mechanisms.base import (PATHS, CampaignScale, Mechanism, Parameter, ParamSpec,
                                                VirtualCarRange)
from clutch_model.plant.mechanisms.discovered import Discovered
from clutch_model.plant.mechanisms.drag_torque import DragTorque
from clutch_model.plant.mechanisms.friction_degradation import FrictionDegradation
from clutch_model.plant.mechanisms.spring_preload import SpringPreload
from clutch_model.plant.mechanisms.torque_offset import TorqueOffset
from clutch_model.plant.mechanisms.torque_sensor_lag import TorqueSensorLag, lowpass_signal
from clutch_model.plant.mechanisms.transport_delay import TransportDelay, delay_signal

# the catalog, in table order (= composition order on a shared path)
CATALOG = {cls.id: cls for cls in (ActuatorLag, ActuatorHysteresis, SpringPreload, FrictionDegradation,
                                   TorqueOffset, TransportDelay, DragTorque, TorqueSensorLag)}
CATALOG_ORDER = {mid: k for k, mid in enumerate(CATALOG)}
# beyond the catalog: extensions a model file may carry (found from data), applied after it
EXTENSIONS = {Discovered.id: Discovered}
DIAGNOSIS_CANDIDATES = [mid for mid, cls in CATALOG.items() if cls.diagnosis_candidate]

__all__ = ["CATALOG", "CATALOG_ORDER", "DIAGNOSIS_CANDIDATES", "EXTENSIONS", "Discovered", "PATHS", "CampaignScale", "Mechanism",
           "Parameter", "ParamSpec", "VirtualCarRange", "apply_measurement", "delay_signal",
           "lowpass_signal", "make_mechanism", "mechanism_from_dict", "ordered"]


def make_mechanism(mech_id: str, **values) -> Mechanism:
    cls = CATALOG.get(mech_id) or EXTENSIONS.get(mech_id)
    if cls is None:
        raise ParamsError(f"unknown mechanism id '{mech_id}' (known: {', '.join([*CATALOG, *EXTENSIONS])})")
    return cls(dict(values))


def mechanism_from_dict(raw, source="<memory>") -> Mechanism:
    if not isinstance(raw, dict) or "id" not in raw:
        raise ParamsError(f"{source}: each mechanisms entry needs an 'id'")
    values = {k: v for k, v in raw.items() if k != "id"}
    try:
        return make_mechanism(str(raw["id"]), **values)
    except (TypeError, ValueError) as exc:
        raise ParamsError(f"{source}: mechanism {raw['id']}: {exc}") from None


def ordered(mechanisms) -> list:
    """Mechanisms in catalog order (the order in which same-path mechanisms compose)."""
    return sorted(mechanisms, key=lambda m: CATALOG_ORDER.get(m.id, len(CATALOG_ORDER)))


def apply_measurement(mechanisms, t, torque, run_start):
    """What the torque sensor reads: every measurement mechanism, in catalog order
    (torque_offset, transport_delay, torque_sensor_lag), applied to a plant-torque trace
    (1-D, or (n_sets, n) on one grid)."""
    out = torque
    for m in ordered(mechanisms):
        if m.path == "measurement":
            out = m.apply_to_measurement(t, out, run_start)
    return out
