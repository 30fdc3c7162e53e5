"""Torque-split scenarios for the clutch in the driveline.

``split-mu``: one wheel on ice. Side b is the wheel on ice (tyre + half-shaft inertia), side a
the differential case with the wheel that grips, carrying the car's inertia reflected to it.
The engine torque reaches both sides through the differential; the ice gives side b almost no
road torque, so with the clutch open the ice wheel flares. The slip controller presses the
clutch so that it carries torque from the spinning wheel to the gripping side, holding the slip
at its target (3 rad/s, then 1.5 rad/s), and lets the clutch lock when the target is 0. The
pack is pre-filled (the controller's kiss-point preload) for 1 s before the driver pulls away.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from clutch_model.closed_loop.controller import PISlipController
from clutch_model.errors import ParamsError
from clutch_model.plant.driveline_sim import DrivelineParams, DrivelineResult, simulate_driveline


@dataclass
class Scenario:
    name: str
    description: str
    t: np.ndarray
    torque_a_nm: np.ndarray
    torque_b_nm: np.ndarray
    sump_temperature_c: float
    driveline: DrivelineParams
    target_slip: Callable[[float], float]


def split_mu(rate_hz: float = 1000.0, duration_s: float = 7.0) -> Scenario:
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    drive = np.interp(t, [0.0, 1.0, 1.7, 5.5, 6.0], [0.0, 0.0, 500.0, 500.0, 150.0])  # per side, N m
    ice_road = 0.08 * 4000.0 * 0.32                      # mu_ice * wheel load * radius, ~100 N m
    torque_b = drive - np.minimum(drive, ice_road)       # the ice carries at most ice_road
    torque_a = drive                                     # grip: road torque moves the car (J_a)
    driveline = DrivelineParams(inertia_a_kgm2=40.0, inertia_b_kgm2=1.2, damping_a_nms=0.5,
                                damping_b_nms=0.2, initial_speed_a_rad_s=10.0, initial_speed_b_rad_s=10.0)

    def target(tk: float) -> float:
        return 3.0 if tk < 3.5 else (1.5 if tk < 5.0 else 0.0)

    return Scenario("split-mu", "one wheel on ice: PI slip control transfers torque to the gripping side",
                    t, torque_a, torque_b, 60.0, driveline, target)


SCENARIOS: dict[str, Callable[..., Scenario]] = {"split-mu": split_mu}


def get_scenario(name: str, **kwargs) -> Scenario:
    if name not in SCENARIOS:
        raise ParamsError(f"unknown scenario '{name}' (known: {', '.join(SCENARIOS)})")
    return SCENARIOS[name](**kwargs)


@dataclass
class ScenarioRun:
    scenario: Scenario
    controlled: DrivelineResult
    open_clutch: DrivelineResult
    controller: PISlipController


def run_scenario(model, scenario: Scenario, controller: PISlipController | None = None) -> ScenarioRun:
    """The scenario with the slip controller in the loop, and with the clutch left open."""
    controller = controller or PISlipController(target_slip_rad_s=scenario.target_slip)
    sc = scenario
    controlled = simulate_driveline(model, sc.t, controller, sc.torque_a_nm, sc.torque_b_nm,
                                    sc.sump_temperature_c, sc.driveline)
    open_clutch = simulate_driveline(model, sc.t, 0.0, sc.torque_a_nm, sc.torque_b_nm,
                                     sc.sump_temperature_c, sc.driveline)
    return ScenarioRun(sc, controlled, open_clutch, controller)


CSV_COLUMNS = ("t", "applied_force_n", "torque_a_nm", "torque_b_nm", "speed_a_rad_s", "speed_b_rad_s",
               "slip_speed_rad_s", "target_slip_rad_s", "clutch_torque_nm", "static_capacity_nm", "locked",
               "pack_temperature_c", "open_clutch_speed_b_rad_s")


def write_scenario_csv(run: ScenarioRun, path) -> None:
    r, sc = run.controlled, run.scenario
    target = np.array([sc.target_slip(tk) for tk in sc.t])
    cols = [r.t, r.applied_force_n, r.torque_a_nm, r.torque_b_nm, r.speed_a_rad_s, r.speed_b_rad_s,
            r.slip_speed_rad_s, target, r.clutch_torque_nm, r.static_capacity_nm, r.locked.astype(float),
            r.pack_temperature_c, run.open_clutch.speed_b_rad_s]
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(CSV_COLUMNS), comments="", fmt="%.9g")


def summary(run: ScenarioRun) -> dict:
    """Figures of a run: slip tracking where the target is held (from 0.5 s after each change and
    1 s after the drive starts),
    the ice wheel's top speed with and without control, torque moved to the gripping side."""
    r, sc = run.controlled, run.scenario
    target = np.array([sc.target_slip(tk) for tk in sc.t])
    changes = sc.t[np.flatnonzero(np.diff(target)) + 1]
    settled = np.ones(sc.t.size, bool)
    for tc in np.concatenate([[sc.t[0]], changes]):
        settled &= ~((sc.t >= tc) & (sc.t < tc + 0.5))
    driven = np.abs(sc.torque_b_nm) > 1.0
    if driven.any():                      # the pull-away transient: the first second of drive
        t_drive = sc.t[np.flatnonzero(driven)[0]]
        settled &= ~((sc.t >= t_drive) & (sc.t < t_drive + 1.0))
    active = settled & (target > 0) & driven
    err = np.abs(r.slip_speed_rad_s) - target
    return {
        "slip_rms_error_rad_s": float(np.sqrt(np.mean(err[active] ** 2))) if active.any() else float("nan"),
        "max_speed_b_open_rad_s": float(run.open_clutch.speed_b_rad_s.max()),
        "max_speed_b_controlled_rad_s": float(r.speed_b_rad_s.max()),
        "mean_clutch_torque_nm": float(np.mean(np.abs(r.clutch_torque_nm[active]))) if active.any() else 0.0,
        "locked_fraction": float(np.mean(r.locked)),
        "peak_pack_temperature_c": float(r.pack_temperature_c.max()),
    }
