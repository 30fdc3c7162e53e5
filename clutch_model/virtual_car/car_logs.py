"""The virtual test car, shaped like real car logs (docs/virtual_car.md).

``synthesize_car_logs(spec)`` drives a true clutch (the base model with perturbed friction,
catalog mechanisms via ``ClutchModel.with_mechanisms``, and optional effects outside the
catalog) through a controller-like drive on a fine internal grid (``fine_rate_hz``, 1 kHz),
then samples every topic on its own clock (``signals.TopicClock``: rate, phase, jitter,
stamp quantisation) and adds each sensor's noise (``signals.Noise``: white, AR(1),
band-limited, held, median-filtered, drifting), the value then logged in the channel's steps
(``resolution``, e.g. a slip in 0.01 rad/s: a locked clutch's slip reads mostly exact zeros)
and pinned at its sensor's range (``sensor_range``: a share of the campaign's peak, e.g. a
torque sensor saturating at 0.8 of the peak torque reads +-that beyond it).
``write_car_logs`` writes one rosbag2 bag per
run, the bench table, ``truth.yaml`` (the true model in the parameter-file schema),
``truth.json`` (mechanisms, effects, clocks, noise, schedule) and one sidecar
``truth/<run>.npz`` per run with the noise-free torque at the measured torque's own stamps.

Drive (per run, segments back to back until the run's end; ``schedule``):
  hold     force ramps (50-300 ms) to a level and holds 0.5-3 s
  ramp     force ramps linearly to a new level over 0.5-2 s
  sweep    force = mean + amplitude·sin(chirp 0.2 → 4 Hz) for 2-4 s (a controller's dither)
  release  force drops (50-200 ms) to 150-500 N and stays 0.3-1 s
  lock     force rises to a high level; the slip falls to exactly 0 over 0.2-0.5 s, stays 0
           for 0.8-2.5 s (the clutch is locked), then rises again; while locked the transmitted
           torque is set by the driveline: ``load_fraction`` (0.2-0.8, slowly varying) × the
           clutch's static capacity (the plant's locked output), so it is below the capacity
           and not equal to it.
  Slip moves smoothly between segment levels (1-15 rad/s, log-uniform) with a ±2 % wobble
  (``slip_sign_changes``: a segment flips the sign with probability 0.25, crossing 0 in
  ~0.1 s while slipping; a lock keeps the sign of the slip before it in the torque);
  request forces are capped by ``power_limit_w`` / (0.2·N_f·r_m·|slip|).
Schedules: ``short-runs`` (10 runs × 10 s), ``few-long`` (3 runs × 60 s), ``long-drive``
(one bag of 240 s); ``n_runs`` / ``run_duration_s`` override.
``logger_pause_runs``: the first N runs each lose every topic for U(``logger_pause_s``) while
the clutch runs on (a recorder's stall).

Effects outside the catalog (``effects``: [{"name": ..., parameter: value}]):
  torque_sensor_lowpass  tau_s       measured = first-order low-pass of the transmitted torque
                                     (post-processing, a measurement effect); mimics
                                     actuator_lag (it *is* the catalog's torque_sensor_lag when
                                     the catalog knows that id)
  torque_sensor_thermal_offset  slope_nm_per_c  measured + slope·(θ_sump − 60 °C): a sensor zero
                                     that moves with the oil's temperature; mimics torque_offset,
                                     its constant part (a measurement effect)
  torque_ripple          amplitude   transmitted torque × (1 + A·sin(order·φ + φ0)), φ = ∫ω dt
                         (order 1)   per run: once-per-revolution runout
  slip_power_fade        k_per_kw    μ_f / (1 + k·P̄/1 kW), P̄ = slip power through a first-order
                         (tau_s 1.0) filter: reversible fade, mimics friction_degradation
  slip_acceleration_friction gain_s2_per_rad  μ_f × (1 + c·a), a = d|ω|/dt through a first-order
                         (tau_s 0.03) low-pass: frictional memory, the friction rises while the slip
                                     speeds up; mimics actuator_lag (an engagement's slip falls
                                     as its torque rises)
  pressure_temperature_cross coeff   μ_f × (1 + c·P·(θ_pack − 60 °C)), P in MPa
  run_friction_level     spread      μ_f × (1 + U(−s, s)) drawn per run
  actuator_rate_limit    rate_n_per_s  the pack force follows the measured force at a slew rate
                                     of at most R (a motor's speed limit): mimics actuator_lag
                                     on fast edges, nothing on slow ones (a force-path effect:
                                     the plant is driven by the limited force, the force sensor
                                     reads the request)
  actuator_second_order  f_n_hz      the pack force follows the measured force through a
                         (damping 0.7) second-order response (natural frequency f_n, damping
                                     ratio): a hydraulic / motor-and-gear actuator with inertia;
                                     mimics transport_delay and actuator_lag (group delay
                                     2·damping/(2π·f_n)); a force-path effect like the rate limit
  actuator_backlash      half_width_n  the pack force follows the measured force through a play
                                     of constant half-width w: it moves only when the request
                                     leaves [x − w, x + w] (gear or linkage backlash); mimics
                                     actuator_hysteresis, whose band F(1 ± ratio) grows with the
                                     force (a force-path effect)
  torque_judder          amplitude   transmitted torque × (1 + A·exp(−|ω|/s)·sin(2π f t + φ0)) while
                         (frequency_hz 10, slipping, φ0 random per run: a judder (stick-slip exciting a
                          slip_scale_rad_s 8) driveline mode), strongest at low slip; no catalog mechanism
                                     is an oscillation
  force_sensor_hysteresis  half_width_n  the force sensor reads the pack force through a play of
                                     constant half-width w (a sensor with mechanical
                                     hysteresis): the logged force trails the true one by w on
                                     every move, so the pack force leads the log; mimics
                                     actuator_hysteresis, whose band can only trail (a
                                     force-path effect: the plant sees the profile, the log
                                     the played profile)
  force_sensor_lag       tau_s       the force sensor reads the pack force through a first-order
                                     lag (a slow load cell or its filter): the log trails the
                                     pack force, so the pack force leads the log; the mirror of
                                     actuator_lag, which can only trail (a force-path effect)
  torque_sensor_gain     gain        measured = gain × the reading (the sensor's scale off by a few
                                     per cent): not a discrepancy of the clutch, the car
                                     calibration takes it into the friction level (expected
                                     diagnosis `none`)
  force_sensor_offset    offset_n    the force sensor reads the force offset_n low: the pack
                                     gets the logged force + offset_n (a zero or calibration
                                     error); read high it would be the catalog's spring_preload,
                                     read low it is no catalog mechanism (a force-path effect)
  actuator_asymmetric_lag  tau_release_s  the pack force follows the measured force through
                         (tau_apply_s  a first-order lag of time constant tau_apply_s while the
                          0.04)        force rises and tau_release_s while it falls (a hydraulic
                                     actuator filled by a pump, drained through an orifice);
                                     mimics actuator_lag, which has one time constant (a
                                     force-path effect)
  actuator_force_dependent_lag  tau_high_s  the pack force follows the measured force through a
                         (tau_low_s    first-order lag whose time constant grows from tau_low_s
                          0.02, force_ref_n 6000)  at zero pack force to tau_high_s at force_ref_n
                                     (linear, constant beyond): a valve or motor slowing with the
                                     load; mimics actuator_lag (a force-path effect)
  actuator_oil_temperature_lag  tau_40_s  the pack force follows the measured force through a
                         (coeff_per_c  first-order lag whose time constant follows the sump
                          0.03)        temperature, tau_40_s * exp(-coeff_per_c (sump - 40 C)):
                                     cold oil, slow valve; mimics actuator_lag (a force-path
                                     effect)
  actuator_force_delay   delay_s     the pack force is the measured force delay_s late (linear
                                     between fine rows, the run's first force before it: a
                                     command or pressure signal on a slow bus); the slip and
                                     the reading stay on time, so it mimics transport_delay,
                                     which reads the whole torque late (a force-path effect)
  actuator_force_ceiling  share_of_peak  the pack force stops at share_of_peak times the
                                     campaign's largest requested force while the log passes it
                                     (a motor current or supply pressure limit); no catalog
                                     mechanism (a force-path effect)
  torque_sensor_resonance  f_n_hz    measured = the torque reading through a second-order
                         (damping 0.3) low-pass of natural frequency f_n_hz and damping (a load
                                     cell or shaft with little damping, or a second-order
                                     anti-alias filter): it overshoots the torque's edges and
                                     rings; mimics torque_sensor_lag (a measurement effect)
  torque_sensor_asymmetric_lag  tau_fall_s  measured = the transmitted torque through a first-order
                         (tau_rise_s   lag of tau_rise_s while the reading moves away from zero
                          0.015)       and tau_fall_s while it moves toward zero (a sensor filter
                                     or bus averaging that differs by direction); mimics
                                     torque_sensor_lag (a measurement effect)
Friction effects (slip_power_fade, slip_acceleration_friction, pressure_temperature_cross, run_friction_level) run in ``_trajectory_friction_factor``, the kernels' own step
functions with the friction factor written through the degradation slot each row (so the
factor heats the pack like any friction); measurement effects post-process the fine grid.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
from numba import njit
from scipy import signal as sps

from clutch_model.errors import DataError, ParamsError
from clutch_model.formats.bag_writer import DEFAULT_START_TIME_NS, RunSignals, TopicSeries
from clutch_model.plant import kernels as K
from clutch_model.plant import params as P
from clutch_model.plant.mechanisms import CATALOG, delay_signal, make_mechanism
from clutch_model.plant.mechanisms.base import run_bounds
from clutch_model.plant.params import ClutchModel, load_model
from clutch_model.virtual_car.signals import (Noise, TopicClock, WhiteNoise, make_noise,
                                              sample_signal)

SCHEDULES = {"short-runs": (10, 10.0), "few-long": (3, 60.0), "long-drive": (1, 240.0)}
CHANNELS = ("applied_force", "slip_speed", "sump_temperature", "measured_torque", "pack_temperature")

EFFECTS = {
    "torque_sensor_lowpass": {"kind": "measurement", "parameters": {"tau_s": 0.05},
                              "mimics": "actuator_lag", "catalog_equivalent": "torque_sensor_lag",
                              "physics": "torque sensor / bus averaging band-limits the reading: "
                                         "first-order low-pass of the transmitted torque"},
    "torque_sensor_thermal_offset": {"kind": "measurement", "parameters": {"slope_nm_per_c": 0.4},
                                     "mimics": "torque_offset", "catalog_equivalent": None,
                                     "physics": "measured = reading + slope_nm_per_c x (sump - 60 C): the "
                                                "sensor's zero moves with the oil's temperature"},
    "torque_ripple": {"kind": "plant-torque", "parameters": {"amplitude": 0.06, "order": 1.0},
                      "mimics": None, "catalog_equivalent": None,
                      "physics": "once-per-revolution runout: torque x (1 + A sin(order phi + phi0)), "
                                 "phi = slip angle"},
    "slip_power_fade": {"kind": "friction", "parameters": {"k_per_kw": 0.03, "tau_s": 1.0},
                        "mimics": "friction_degradation", "catalog_equivalent": None,
                        "physics": "reversible fade: mu_f / (1 + k P_slip/1 kW), P_slip low-passed"},
    "slip_acceleration_friction": {"kind": "friction", "parameters": {"gain_s2_per_rad": 0.006, "tau_s": 0.03},
                                   "mimics": "actuator_lag", "catalog_equivalent": None,
                                   "physics": "frictional memory: mu_f x (1 + c a), a = d/dt of |slip| through a "
                                              "first-order low-pass of tau_s (the film and lining lag a change of "
                                              "slip): the friction rises while the slip speeds up"},
    "pressure_temperature_cross": {"kind": "friction", "parameters": {"coeff": 2e-3},
                                   "mimics": None, "catalog_equivalent": None,
                                   "physics": "mu_f x (1 + c P (theta_pack - 60 C)), P in MPa"},
    "run_friction_level": {"kind": "friction", "parameters": {"spread": 0.08},
                           "mimics": None, "catalog_equivalent": None,
                           "physics": "mu_f x (1 + U(-s, s)) per run (lining / oil state of the day)"},
    "actuator_rate_limit": {"kind": "force-path", "parameters": {"rate_n_per_s": 40000.0},
                            "mimics": "actuator_lag", "catalog_equivalent": None,
                            "physics": "the actuator's motor slews the pack force at most "
                                       "rate_n_per_s toward the measured force (slew-rate limit)"},
    "actuator_second_order": {"kind": "force-path", "parameters": {"f_n_hz": 2.5, "damping": 0.7},
                              "mimics": "transport_delay", "catalog_equivalent": None,
                              "physics": "the pack force follows the measured force through a "
                                         "second-order response (natural frequency f_n_hz, damping "
                                         "ratio): an actuator with inertia"},
    "actuator_backlash": {"kind": "force-path", "parameters": {"half_width_n": 300.0},
                          "mimics": "actuator_hysteresis", "catalog_equivalent": None,
                          "physics": "the pack force follows the measured force through a play of "
                                     "constant half-width half_width_n (gear or linkage backlash)"},
    "torque_judder": {"kind": "plant-torque", "parameters": {"amplitude": 0.06, "frequency_hz": 10.0,
                                                             "slip_scale_rad_s": 8.0},
                      "mimics": None, "catalog_equivalent": None,
                      "physics": "judder: torque x (1 + A exp(-|slip|/slip_scale) sin(2 pi f t + phi0)) while "
                                 "slipping (stick-slip exciting a driveline mode), strongest at low slip"},
    "force_sensor_hysteresis": {"kind": "force-path", "parameters": {"half_width_n": 300.0},
                                "mimics": "actuator_hysteresis", "catalog_equivalent": None,
                                "physics": "the force sensor reads the pack force through a play of constant "
                                           "half-width half_width_n (sensor hysteresis): the log trails the "
                                           "pack force on every move"},
    "force_sensor_lag": {"kind": "force-path", "parameters": {"tau_s": 0.08},
                         "mimics": "actuator_lag", "catalog_equivalent": None,
                         "physics": "the force sensor reads the pack force through a first-order lag of "
                                    "tau_s: the log trails the pack force"},
    "torque_sensor_gain": {"kind": "measurement", "parameters": {"gain": 0.95},
                           "mimics": None, "catalog_equivalent": None, "calibration": True,
                           "physics": "measured = gain x the reading: the sensor's scale off by a few per cent, "
                                      "which the car calibration takes into the friction level"},
    "force_sensor_offset": {"kind": "force-path", "parameters": {"offset_n": 500.0},
                            "mimics": "spring_preload", "catalog_equivalent": None,
                            "physics": "the force sensor reads offset_n low: the pack gets the "
                                       "logged force + offset_n"},
    "actuator_asymmetric_lag": {"kind": "force-path", "parameters": {"tau_release_s": 0.2, "tau_apply_s": 0.04},
                                "mimics": "actuator_lag", "catalog_equivalent": None,
                                "physics": "the pack force follows the measured force through a "
                                           "first-order lag of time constant tau_apply_s while it "
                                           "rises and tau_release_s while it falls (pump-filled, "
                                           "orifice-drained actuator)"},
    "actuator_force_dependent_lag": {"kind": "force-path",
                                     "parameters": {"tau_high_s": 0.2, "tau_low_s": 0.02, "force_ref_n": 6000.0},
                                     "mimics": "actuator_lag", "catalog_equivalent": None,
                                     "physics": "the pack force follows the measured force through a "
                                                "first-order lag whose time constant grows linearly from "
                                                "tau_low_s at zero pack force to tau_high_s at force_ref_n "
                                                "(a valve or motor slowing with the load)"},
    "actuator_oil_temperature_lag": {"kind": "force-path", "parameters": {"tau_40_s": 0.08, "coeff_per_c": 0.03},
                                     "mimics": "actuator_lag", "catalog_equivalent": None,
                                     "physics": "the pack force follows the measured force through a "
                                                "first-order lag of time constant tau_40_s x exp(-coeff_per_c "
                                                "x (sump - 40 C)): an actuator slower in cold oil"},
    "actuator_force_ceiling": {"kind": "force-path", "parameters": {"share_of_peak": 0.7},
                               "mimics": None, "catalog_equivalent": None,
                               "physics": "the pack force is min(F, share_of_peak x the campaign's largest "
                                          "requested force): a force-limited actuator"},
    "actuator_force_delay": {"kind": "force-path", "parameters": {"delay_s": 0.02},
                             "mimics": "transport_delay", "catalog_equivalent": None,
                             "physics": "the pack force is the measured force delay_s late (a pure delay on the "
                                        "force path): the slip and the torque reading stay on time"},
    "torque_sensor_resonance": {"kind": "measurement", "parameters": {"f_n_hz": 6.0, "damping": 0.3},
                                "mimics": "torque_sensor_lag", "catalog_equivalent": None,
                                "physics": "measured = the torque reading through a second-order low-pass "
                                           "of natural frequency f_n_hz and damping (a resonant load cell "
                                           "or shaft, or a second-order anti-alias filter)"},
    "torque_sensor_asymmetric_lag": {"kind": "measurement", "parameters": {"tau_fall_s": 0.15, "tau_rise_s": 0.015},
                                     "mimics": "torque_sensor_lag", "catalog_equivalent": None,
                                     "physics": "measured = the transmitted torque through a first-order lag "
                                                "of tau_rise_s while the reading moves away from zero and "
                                                "tau_fall_s while it moves toward zero"},
}

DEFAULT_CLOCKS = {
    "applied_force": TopicClock(200.0, jitter_s=1e-3, quantum_s=1e-4),
    "slip_speed": TopicClock(100.0, jitter_s=0.5e-3, quantum_s=1e-4),
    "sump_temperature": TopicClock(10.0, jitter_s=2e-3, quantum_s=1e-3),
    "measured_torque": TopicClock(50.0, jitter_s=1e-3, quantum_s=1e-4),
    "pack_temperature": TopicClock(10.0, jitter_s=2e-3, quantum_s=1e-3),
}
DEFAULT_NOISE = {
    "applied_force": WhiteNoise(20.0),
    "slip_speed": WhiteNoise(0.05),
    "sump_temperature": WhiteNoise(0.3),
    "measured_torque": WhiteNoise(8.0),
    "pack_temperature": WhiteNoise(0.5),
}


@dataclass
class CarLogSpec:
    """Everything that defines a car-log campaign (module docstring)."""

    seed: int = 0
    schedule: str = "short-runs"
    n_runs: int | None = None
    run_duration_s: float | None = None
    fine_rate_hz: float = 1000.0
    gap_s: float = 60.0
    # the first this many runs are one drive cut into consecutive bags (a recorder rolling over):
    # no pause between them, the plant (pack temperature, film, mechanism states) and the sump
    # carry across their boundaries; later runs follow after pauses as usual (0: none)
    continuous_runs: int = 0
    # the first this many runs each have one logger pause: every topic silent for
    # U(logger_pause_s) from U(0.3, 0.6) of the run while the clutch runs on (0: none)
    logger_pause_runs: int = 0
    logger_pause_s: tuple = (1.0, 3.0)
    start_time_ns: int = DEFAULT_START_TIME_NS
    clocks: dict = field(default_factory=dict)      # channel -> TopicClock (defaults above)
    noise: dict = field(default_factory=dict)       # channel -> Noise (defaults above)
    resolution: dict = field(default_factory=dict)  # channel -> the step its value is logged in (0: none)
    sensor_range: dict = field(default_factory=dict)  # channel -> its sensor's range as a share of the
    #                                                   campaign's peak |clean value|: the logged value pinned there
    random_phase: bool = True                       # each topic's first sample at U(0, period)
    lockup: bool = True
    slip_sign_changes: bool = False                 # segments may change the slip's sign
    lock_dwell_s: tuple = (0.8, 2.5)
    load_fraction: tuple = (0.2, 0.8)
    mechanisms: list = field(default_factory=list)  # [{"id": ..., <parameter>: value}]
    effects: list = field(default_factory=list)     # [{"name": ..., <parameter>: value}]
    friction_spread: float = 0.05
    include_pack_temperature: bool = False
    sump_range_c: tuple = (30.0, 80.0)
    slip_range_rad_s: tuple = (1.0, 15.0)
    force_range_n: tuple = (1000.0, 12000.0)
    release_force_range_n: tuple = (150.0, 500.0)
    power_limit_w: float | None = None              # default 5 kW (runs <= 20 s), else 2.5 kW

    def __post_init__(self):
        self.clocks = {**DEFAULT_CLOCKS, **self.clocks}
        self.noise = {**DEFAULT_NOISE, **self.noise}
        if self.schedule not in SCHEDULES:
            raise ParamsError(f"unknown schedule '{self.schedule}' (known: {', '.join(SCHEDULES)})")
        n, dur = SCHEDULES[self.schedule]
        self.n_runs = int(self.n_runs if self.n_runs is not None else n)
        self.run_duration_s = float(self.run_duration_s if self.run_duration_s is not None else dur)
        if self.power_limit_w is None:
            self.power_limit_w = 5000.0 if self.run_duration_s <= 20.0 else 2500.0

    def validate(self) -> None:
        def need(cond, msg):
            if not cond:
                raise ParamsError(f"car-log spec: {msg}")
        need(self.n_runs >= 1, "need at least one run")
        need(self.run_duration_s >= 4.0, "runs must last at least 4 s")
        need(self.fine_rate_hz >= 500.0, "the fine grid must be at least 500 Hz")
        need(1.0 / self.fine_rate_hz <= K.MAX_STEP_S, "the fine grid step must not exceed the kernel step")
        for ch, clock in self.clocks.items():
            need(ch in CHANNELS, f"unknown channel '{ch}'")
            need(isinstance(clock, TopicClock), f"{ch}: clock must be a TopicClock")
            need(clock.rate_hz <= self.fine_rate_hz, f"{ch}: rate above the fine grid's")
        for ch, noise in self.noise.items():
            need(ch in CHANNELS and isinstance(noise, Noise), f"{ch}: bad noise entry")
        ids = [m.get("id") for m in self.mechanisms]
        need(len(set(ids)) == len(ids), "a mechanism is listed twice")
        for m in self.mechanisms:
            _mechanism(m)
        for e in self.effects:
            name = e.get("name")
            if name not in EFFECTS:
                raise ParamsError(f"unknown effect '{name}' (known: {', '.join(EFFECTS)})")
            extra = set(e) - {"name"} - set(EFFECTS[name]["parameters"])
            need(not extra, f"effect {name}: unknown parameter '{sorted(extra)[0] if extra else ''}'")
        need(0 < self.load_fraction[0] <= self.load_fraction[1] < 1, "load fraction must be in (0, 1)")
        for ch, share in self.sensor_range.items():
            need(ch in CHANNELS and 0 < float(share), f"{ch}: bad sensor range")

    def effect_values(self, name: str):
        for e in self.effects:
            if e["name"] == name:
                vals = dict(EFFECTS[name]["parameters"])
                vals.update({k: float(v) for k, v in e.items() if k != "name"})
                return vals
        return None

    @property
    def expected_causes(self) -> list:
        """Catalog ids a correct diagnosis names (effects with a catalog twin count as it)."""
        out = [m["id"] for m in self.mechanisms]
        for e in self.effects:
            eq = EFFECTS[e["name"]]["catalog_equivalent"]
            if eq and eq in CATALOG:
                out.append(eq)
        return out

    @property
    def expected_cause(self) -> str:
        if any(not (EFFECTS[e["name"]]["catalog_equivalent"] in CATALOG or EFFECTS[e["name"]].get("calibration"))
               for e in self.effects):
            return "unexplained"
        causes = self.expected_causes
        return causes[0] if causes else "none"


def _mechanism(raw: dict):
    if "id" not in raw:
        raise ParamsError("car-log spec: each mechanism needs an 'id'")
    return make_mechanism(str(raw["id"]), **{k: v for k, v in raw.items() if k != "id"})


@dataclass
class CarLogRun:
    """One run: the fine-grid truth, the per-topic samples (noisy) and the truth there."""

    name: str
    start_time_ns: int
    fine: dict          # t_s, applied_force_n, slip_speed_rad_s, sump_temperature_c, torque_nm,
                        # sensor_torque_nm, pack_temperature_c, locked
    signals: RunSignals
    sample_truth: dict  # channel -> {"t_true_s", "t_stamp_s", "clean", "noise"}
    schedule: list

    @property
    def first_stamp_s(self) -> float:
        return min(float(s["t_stamp_s"][0]) for s in self.sample_truth.values() if s["t_stamp_s"].size)


@dataclass
class CarLogResult:
    spec: CarLogSpec
    runs: list
    bench: object
    true_model: ClutchModel
    truth: dict


# ---------------------------------------------------------------------------- profile
def _smooth_step(u):
    u = np.clip(u, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * u)


def _drive_profile(rng, spec: CarLogSpec, t: np.ndarray, k_t: float):
    """True force, slip and driveline load fraction (nan while slipping) on the fine grid."""
    n = t.size
    dur = float(t[-1] + (t[1] - t[0]))
    force = np.empty(n)
    slip = np.empty(n)
    load = np.full(n, np.nan)
    wlo, whi = spec.slip_range_rad_s
    flo, fhi_max = spec.force_range_n

    sign = [1.0]

    def slip_level():
        level = float(wlo * (whi / wlo) ** rng.uniform())
        if spec.slip_sign_changes and rng.random() < 0.25:
            sign[0] = -sign[0]          # the other wheel faster: slip crosses 0 while slipping
        return sign[0] * level

    def f_cap(w):
        return max(min(fhi_max, spec.power_limit_w / (k_t * max(w, 1e-3))), flo + 500.0)

    f_rel = float(rng.uniform(*spec.release_force_range_n))
    f_cur, w_cur = f_rel, slip_level()
    kinds = ["hold", "ramp", "sweep", "release"] + (["lock"] if spec.lockup else [])
    weights = np.array([0.3, 0.2, 0.15, 0.2] + ([0.1] if spec.lockup else []))
    weights /= weights.sum()
    segments = []
    # a lock phase in every run that has room for one
    forced_lock_at = float(rng.uniform(0.25, 0.6)) * dur if (spec.lockup and dur >= 6.0) else None
    i0 = 0
    tc = 0.0
    first = True
    while i0 < n:
        if first:
            kind, seg_d = "release", float(rng.uniform(0.3, 0.6))
            first = False
        elif forced_lock_at is not None and tc >= forced_lock_at:
            kind, forced_lock_at = "lock", None
        else:
            kind = str(rng.choice(kinds, p=weights))
            if kind == "lock":
                forced_lock_at = None
        if kind == "hold":
            seg_d = float(rng.uniform(0.5, 3.0))
        elif kind == "ramp":
            seg_d = float(rng.uniform(0.5, 2.0))
        elif kind == "sweep":
            seg_d = float(rng.uniform(2.0, 4.0))
        elif kind == "release" and tc > 0:
            seg_d = float(rng.uniform(0.3, 1.0))
        elif kind == "lock":
            t_in, dwell, t_out = (float(rng.uniform(0.2, 0.5)), float(rng.uniform(*spec.lock_dwell_s)),
                                  float(rng.uniform(0.3, 0.6)))
            seg_d = t_in + dwell + t_out
        i1 = min(n, i0 + max(1, int(round(seg_d * spec.fine_rate_hz))))
        tt = t[i0:i1] - t[i0]
        w_new = slip_level()
        info = {"kind": kind, "t0_s": round(float(t[i0]), 4), "t1_s": round(float(t[i1 - 1]), 4)}
        if kind == "lock":
            f_lock = float(rng.uniform(0.5, 1.0)) * fhi_max
            rise = np.minimum(tt / 0.2, 1.0)
            force[i0:i1] = f_cur + (f_lock - f_cur) * rise
            sl = np.where(tt < t_in, w_cur * (1.0 - _smooth_step(tt / t_in)), 0.0)
            out_t = tt - (t_in + dwell)
            sl = np.where(out_t > 0, w_new * _smooth_step(out_t / t_out), sl)
            slip[i0:i1] = sl
            in_lock = (tt >= t_in) & (out_t <= 0)
            c0 = float(rng.uniform(*spec.load_fraction))
            amp = min(c0 - spec.load_fraction[0], spec.load_fraction[1] - c0, 0.15)
            fr = float(rng.uniform(0.2, 1.0))
            load[i0:i1][in_lock] = c0 + amp * np.sin(2 * np.pi * fr * tt[in_lock])
            f_cur, w_cur = f_lock, w_new
            info.update({"force_n": round(f_lock, 1), "lock_from_s": round(float(t[i0]) + t_in, 4),
                         "lock_to_s": round(float(t[i0]) + t_in + dwell, 4),
                         "load_fraction_mean": round(c0, 3)})
        else:
            blend = _smooth_step(tt / 0.3)
            base_w = w_cur + (w_new - w_cur) * blend
            wob = 1.0 + 0.02 * np.sin(2 * np.pi * rng.uniform(0.2, 0.6) * tt + rng.uniform(0, 2 * np.pi))
            slip[i0:i1] = base_w * wob
            cap = f_cap(max(abs(w_cur), abs(w_new)) * 1.02)
            if kind == "hold":
                lvl = float(rng.uniform(flo, cap))
                r = float(rng.uniform(0.05, 0.3))
                force[i0:i1] = f_cur + (lvl - f_cur) * np.minimum(tt / r, 1.0)
                info["force_n"] = round(lvl, 1)
            elif kind == "ramp":
                lvl = float(rng.uniform(flo, cap))
                force[i0:i1] = f_cur + (lvl - f_cur) * np.minimum(tt / max(seg_d, 1e-3), 1.0)
                info["force_n"] = round(lvl, 1)
            elif kind == "sweep":
                mean = float(rng.uniform(flo + 0.3 * (cap - flo), flo + 0.7 * (cap - flo)))
                amp = float(rng.uniform(0.2, 0.45)) * min(mean - flo * 0.5, cap - mean)
                f0, f1 = 0.2, 4.0
                ph = 2 * np.pi * (f0 * tt + (f1 - f0) * tt ** 2 / (2 * max(seg_d, 1e-3)))
                into = np.minimum(tt / 0.2, 1.0)
                force[i0:i1] = (f_cur + (mean - f_cur) * into) + amp * np.sin(ph) * into
                lvl = float(force[i1 - 1])
                info.update({"force_mean_n": round(mean, 1), "amplitude_n": round(amp, 1)})
            else:  # release
                lvl = f_rel
                r = float(rng.uniform(0.05, 0.2))
                force[i0:i1] = f_cur + (lvl - f_cur) * np.minimum(tt / r, 1.0)
                info["force_n"] = round(lvl, 1)
            f_cur = float(force[i1 - 1])
            w_cur = w_new
        segments.append(info)
        tc = float(t[i1 - 1])
        i0 = i1
    return np.maximum(force, 0.0), slip, load, segments


def _torque_per_newton(model: ClutchModel, mu: float = 0.2) -> float:
    g = model.data["geometry"]
    ro, ri = float(g["r_outer"]), float(g["r_inner"])
    r_m = 2.0 / 3.0 * (ro ** 3 - ri ** 3) / (ro ** 2 - ri ** 2)
    return mu * float(g["friction_surfaces"]) * r_m


# ------------------------------------------------------------------------------ plant
@njit(cache=True)
def _trajectory_friction_factor(p, t, force, slip, sump, run_start, run_level, pt_coeff, fade_k_per_w,
                                fade_tau, degr_scale, energy0, accel_gain=0.0, accel_tau=0.03):
    """kernels.run_trajectory with μ_f × factor, factor = run_level[run]·(1 + pt_coeff·P·(θ−60))
    / (1 + fade_k·P̄) · exp(−E/degr_scale) · (1 + clip(accel_gain·a, ±0.5)), a = d/dt of |slip|
    through a low-pass of accel_tau, written through the degradation slot (p's energy
    scale must be 1: the energy state holds −ln factor). E, P̄ and a are tracked here; the
    record's O_ENERGY column holds E. Needs steps ≤ kernels.MAX_STEP_S (one sub-step)."""
    n = t.size
    d = K.derived_constants(p)
    out = np.zeros((n, K.N_OUT))
    state = np.zeros(K.N_STATE)
    scratch = np.zeros(K.N_OUT)
    energy = energy0
    pbar = 0.0
    prev_power = 0.0
    slip_lp = 0.0
    accel = 0.0
    run = -1
    for k in range(n):
        if k == 0 or run_start[k]:
            K.init_state(state, force[k], sump[k], p)
            run += 1
            pbar = 0.0
            prev_power = 0.0
            slip_lp = abs(slip[k])
            accel = 0.0
        else:
            dt = t[k] - t[k - 1]
            K.advance(state, slip[k - 1], sump[k - 1], dt, p, d, scratch)
            energy += 0.5 * (prev_power + scratch[K.O_POWER]) * dt
            a = math.exp(-dt / fade_tau)
            pbar = a * pbar + (1.0 - a) * prev_power
            if accel_gain != 0.0:
                # |slip| linear over the step through the low-pass, exactly; a = (|w| - y) / tau
                u0, u1 = abs(slip[k - 1]), abs(slip[k])
                rate = (u1 - u0) / dt
                slip_lp = u1 - rate * accel_tau + (slip_lp - u0 + rate * accel_tau) * math.exp(-dt / accel_tau)
                accel = (u1 - slip_lp) / accel_tau
        K.pack_force_target(state, force[k], p)
        fp = state[K.S_FPACK]
        if fp > d[K.D_FMAX]:
            fp = d[K.D_FMAX]
        pr = fp / d[K.D_AN] * 1e-6
        fac = run_level[run] * (1.0 + pt_coeff * pr * (state[K.S_THETA] - 60.0)) / (1.0 + fade_k_per_w * pbar)
        if degr_scale > 0.0:
            fac *= math.exp(-energy / degr_scale)
        if accel_gain != 0.0:
            fac *= 1.0 + min(max(accel_gain * accel, -0.5), 0.5)
        if fac < 0.05:
            fac = 0.05
        state[K.S_ENERGY] = -math.log(fac)
        K.outputs(state, slip[k], sump[k], p, d, out[k])
        prev_power = out[k, K.O_POWER]
        out[k, K.O_ENERGY] = energy
    return out


def _simulate_plant(model: ClutchModel, spec: CarLogSpec, t, force, slip, sump, run_start, rng):
    """Plant signals on the fine grid: torque, pack temperature, locked, power, mu."""
    from clutch_model.plant.simulate import simulate

    pt = spec.effect_values("pressure_temperature_cross")
    fade = spec.effect_values("slip_power_fade")
    lvl = spec.effect_values("run_friction_level")
    acc = spec.effect_values("slip_acceleration_friction")
    info = {}
    if pt is None and fade is None and lvl is None and acc is None:
        res = simulate(model, t, force, slip, sump, run_start=run_start)
        return {"torque": res.torque_nm, "pack": res.pack_temperature_c, "locked": res.locked,
                "power": res.power_w, "mu": res.friction_coefficient}, info
    n_runs = int(np.count_nonzero(run_start)) or 1
    levels = np.ones(n_runs)
    if lvl is not None:
        levels = 1.0 + rng.uniform(-lvl["spread"], lvl["spread"], n_runs)
        info["run_friction_levels"] = [float(x) for x in levels]
    degr = model.mechanism("friction_degradation")
    p = model.vector()
    p[P.ENERGY_SCALE_J] = 1.0
    out = _trajectory_friction_factor(
        p, np.ascontiguousarray(t), np.ascontiguousarray(force), np.ascontiguousarray(slip),
        np.ascontiguousarray(sump), np.ascontiguousarray(run_start, dtype=np.bool_), levels,
        float(pt["coeff"]) if pt else 0.0, float(fade["k_per_kw"]) * 1e-3 if fade else 0.0,
        float(fade["tau_s"]) if fade else 1.0,
        float(degr.values["energy_scale_j"]) if degr is not None else 0.0, 0.0,
        float(acc["gain_s2_per_rad"]) if acc else 0.0, float(acc["tau_s"]) if acc else 0.03)
    return {"torque": out[:, K.O_TORQUE], "pack": out[:, K.O_THETA], "locked": out[:, K.O_LOCKED] > 0.5,
            "power": out[:, K.O_POWER], "mu": out[:, K.O_MU]}, info


@njit(cache=True)
def _slew_limited(force, run_start, step_n):
    """The force each fine row reaches when it may move at most ``step_n`` per row toward the
    request (restarted at the request at each run's start)."""
    out = np.empty_like(force)
    for k in range(force.size):
        if k == 0 or run_start[k]:
            out[k] = force[k]
        else:
            d = force[k] - out[k - 1]
            out[k] = out[k - 1] + min(max(d, -step_n), step_n)
    return out


@njit(cache=True)
def _played(force, run_start, half_width_n):
    """The force each fine row reaches through a play of constant half-width: it moves only
    when the request leaves [x - w, x + w] (restarted at the request at each run's start)."""
    out = np.empty_like(force)
    for k in range(force.size):
        if k == 0 or run_start[k]:
            out[k] = force[k]
        else:
            out[k] = min(max(out[k - 1], force[k] - half_width_n), force[k] + half_width_n)
    return out


@njit(cache=True)
def _asymmetric_lagged(force, run_start, tau_apply_steps, tau_release_steps):
    """The force each fine row reaches through a first-order lag of ``tau_apply_steps`` fine
    rows while it rises toward the request and ``tau_release_steps`` while it falls (exact for
    a request held over each row; restarted at the request at each run's start)."""
    out = np.empty_like(force)
    a_up, a_down = 1.0 - math.exp(-1.0 / tau_apply_steps), 1.0 - math.exp(-1.0 / tau_release_steps)
    for k in range(force.size):
        if k == 0 or run_start[k]:
            out[k] = force[k]
        else:
            d = force[k] - out[k - 1]
            out[k] = out[k - 1] + (a_up if d > 0.0 else a_down) * d
    return out


@njit(cache=True)
def _force_dependent_lagged(force, run_start, tau_low_steps, tau_high_steps, force_ref_n):
    """The force each fine row reaches through a first-order lag whose time constant (in fine
    rows) is linear in the pack force, ``tau_low_steps`` at 0 to ``tau_high_steps`` at
    ``force_ref_n`` and constant beyond (taken at the previous row's pack force)."""
    out = np.empty_like(force)
    for k in range(force.size):
        if k == 0 or run_start[k]:
            out[k] = force[k]
        else:
            share = min(max(out[k - 1] / force_ref_n, 0.0), 1.0)
            tau = tau_low_steps + (tau_high_steps - tau_low_steps) * share
            out[k] = out[k - 1] + (1.0 - math.exp(-1.0 / tau)) * (force[k] - out[k - 1])
    return out


@njit(cache=True)
def _oil_temperature_lagged(force, sump_c, run_start, tau_40_steps, coeff_per_c):
    """The force each fine row reaches through a first-order lag whose time constant (in fine
    rows) is ``tau_40_steps`` x exp(-coeff_per_c (sump - 40 C)), at the row's sump temperature
    (exact for a request held over each row)."""
    out = np.empty_like(force)
    for k in range(force.size):
        if k == 0 or run_start[k]:
            out[k] = force[k]
        else:
            tau = tau_40_steps * math.exp(-coeff_per_c * (sump_c[k] - 40.0))
            out[k] = out[k - 1] + (1.0 - math.exp(-1.0 / tau)) * (force[k] - out[k - 1])
    return out


@njit(cache=True)
def _asymmetric_sensor(torque, run_start, tau_rise_steps, tau_fall_steps):
    """The reading each fine row gives through a first-order lag of ``tau_rise_steps`` fine
    rows while it moves away from zero toward the torque ((T - y) T > 0) and
    ``tau_fall_steps`` while it moves toward zero."""
    out = np.empty_like(torque)
    a_rise, a_fall = 1.0 - math.exp(-1.0 / tau_rise_steps), 1.0 - math.exp(-1.0 / tau_fall_steps)
    for k in range(torque.size):
        if k == 0 or run_start[k]:
            out[k] = torque[k]
        else:
            d = torque[k] - out[k - 1]
            out[k] = out[k - 1] + (a_rise if d * torque[k] > 0.0 else a_fall) * d
    return out


def _second_order_per_run(force, run_start, f_n_hz, damping, dt_s):
    """The force each fine row reaches through a unit-gain second-order response (natural
    frequency ``f_n_hz``, damping ratio ``damping``; exact zero-order-hold discretisation),
    restarted at rest at the request at each run's start."""
    w = 2.0 * math.pi * f_n_hz
    b, a, _ = sps.cont2discrete(([w * w], [1.0, 2.0 * damping * w, w * w]), dt_s, method="zoh")
    b = np.ravel(b)
    zi = sps.lfilter_zi(b, a)
    out = np.empty_like(force)
    for s0, s1 in run_bounds(run_start, force.size):
        out[s0:s1], _ = sps.lfilter(b, a, force[s0:s1], zi=zi * force[s0])
    return out


def _lowpass_per_run(t, y, run_start, tau_s):
    out = np.empty_like(y)
    starts = list(np.flatnonzero(run_start)) + [y.size]
    for a, b in zip(starts[:-1], starts[1:]):
        dt = float(np.median(np.diff(t[a:b]))) if b - a > 1 else 1.0
        al = math.exp(-dt / tau_s)
        out[a:b], _ = sps.lfilter([1 - al], [1.0, -al], y[a:b], zi=[al * y[a]])
    return out


# ---------------------------------------------------------------------------- campaign
def synthesize_car_logs(spec: CarLogSpec | None = None, base_model: ClutchModel | None = None,
                        progress=None) -> CarLogResult:
    """Generate a car-log campaign (module docstring). Same spec, same arrays."""
    from clutch_model.plant.simulate import predict_measured_torque
    from clutch_model.virtual_car.campaign import CampaignSpec, perturb_friction, synthesize_bench

    spec = spec or CarLogSpec()
    spec.validate()
    base = base_model if base_model is not None else load_model(None)
    ss = np.random.SeedSequence(int(spec.seed))
    rng_fric, rng_sched, rng_clock, rng_noise, rng_bench, rng_eff = (np.random.default_rng(s)
                                                                     for s in ss.spawn(6))
    true_model, factors = perturb_friction(base, spec.friction_spread, rng_fric)
    mechs = [_mechanism(m) for m in spec.mechanisms]
    true_model = true_model.with_mechanisms([m for m in true_model.mechanisms
                                             if m.id not in {x.id for x in mechs}] + mechs)

    n_runs, dur = spec.n_runs, spec.run_duration_s
    n_fine = int(round(dur * spec.fine_rate_hz))
    t_run = np.arange(n_fine) / spec.fine_rate_hz
    k_t = _torque_per_newton(base)
    sumps = spec.sump_range_c[0] + (spec.sump_range_c[1] - spec.sump_range_c[0]) * (
        (rng_sched.permutation(n_runs) + rng_sched.uniform(0.1, 0.9, n_runs)) / n_runs)
    F, W, L, S, schedules, start_ns = [], [], [], [], [], []
    t_cur = 0.0
    def continues(i):                                            # run i continues run i - 1
        return 0 < i < spec.continuous_runs

    for i in range(n_runs):
        force, slip, load, segs = _drive_profile(rng_sched, spec, t_run, k_t)
        warm = float(rng_sched.uniform(0.0, min(0.08, 20.0 / dur)))
        if continues(i):
            sumps[i] = S[-1][-1] + warm / spec.fine_rate_hz       # the sump goes on from where it was
        S.append(sumps[i] + warm * t_run)
        F.append(force); W.append(slip); L.append(load)
        schedules.append({"sump_level_c": round(float(sumps[i]), 3), "sump_warmup_c_per_s": round(warm, 4),
                          "segments": segs})
        start_ns.append(int(spec.start_time_ns) + int(round(t_cur * 1e3)) * 1_000_000)
        t_cur += dur if continues(i + 1) else dur + spec.gap_s + float(rng_sched.uniform(0, 0.25 * spec.gap_s))
    t_abs = np.concatenate([(sn - spec.start_time_ns) * 1e-9 + t_run for sn in start_ns])
    run_start = np.zeros(t_abs.size, dtype=bool)
    run_start[[i * n_fine for i in range(n_runs) if not continues(i)]] = True
    force_all, slip_all, sump_all, load_all = (np.concatenate(x) for x in (F, W, S, L))

    if progress:
        progress("simulating the true plant on the fine grid")
    force_pack = force_all
    rate = spec.effect_values("actuator_rate_limit")
    if rate is not None:
        force_pack = _slew_limited(force_all, run_start, float(rate["rate_n_per_s"]) / spec.fine_rate_hz)
    second = spec.effect_values("actuator_second_order")
    if second is not None:
        force_pack = _second_order_per_run(force_pack, run_start, float(second["f_n_hz"]),
                                           float(second["damping"]), 1.0 / spec.fine_rate_hz)
    backlash = spec.effect_values("actuator_backlash")
    if backlash is not None:
        force_pack = _played(force_pack, run_start, float(backlash["half_width_n"]))
    asym = spec.effect_values("actuator_asymmetric_lag")
    if asym is not None:
        force_pack = _asymmetric_lagged(force_pack, run_start, float(asym["tau_apply_s"]) * spec.fine_rate_hz,
                                        float(asym["tau_release_s"]) * spec.fine_rate_hz)
    by_force = spec.effect_values("actuator_force_dependent_lag")
    if by_force is not None:
        force_pack = _force_dependent_lagged(force_pack, run_start, float(by_force["tau_low_s"]) * spec.fine_rate_hz,
                                             float(by_force["tau_high_s"]) * spec.fine_rate_hz,
                                             float(by_force["force_ref_n"]))
    oil = spec.effect_values("actuator_oil_temperature_lag")
    if oil is not None:
        force_pack = _oil_temperature_lagged(force_pack, np.ascontiguousarray(sump_all, float), run_start,
                                             float(oil["tau_40_s"]) * spec.fine_rate_hz, float(oil["coeff_per_c"]))
    late = spec.effect_values("actuator_force_delay")
    if late is not None:
        force_pack = delay_signal(t_abs, force_pack, run_start, float(late["delay_s"]))
    capped = spec.effect_values("actuator_force_ceiling")
    if capped is not None:
        force_pack = np.minimum(force_pack, float(capped["share_of_peak"]) * float(np.max(force_all)))
    # what the force sensor logs: the request, or the pack force through the sensor's play
    force_logged = force_all
    sensor_play = spec.effect_values("force_sensor_hysteresis")
    if sensor_play is not None:
        force_logged = _played(force_pack, run_start, float(sensor_play["half_width_n"]))
    slow_sensor = spec.effect_values("force_sensor_lag")
    if slow_sensor is not None:
        force_logged = _lowpass_per_run(t_abs, np.asarray(force_pack, float), run_start, float(slow_sensor["tau_s"]))
    reads_low = spec.effect_values("force_sensor_offset")
    if reads_low is not None:
        force_pack = force_pack + float(reads_low["offset_n"])
    plant, eff_info = _simulate_plant(true_model, spec, t_abs, force_pack, slip_all, sump_all, run_start, rng_eff)
    # the driveline sets the transmitted torque while locked (below the static capacity)
    locked = plant["locked"] & np.isfinite(load_all)
    transmitted = np.where(locked, np.nan_to_num(load_all) * plant["torque"], plant["torque"])
    ripple = spec.effect_values("torque_ripple")
    phases = []
    if ripple is not None:
        for i in range(n_runs):
            sl = slice(i * n_fine, (i + 1) * n_fine)
            phi = np.concatenate([[0.0], np.cumsum(0.5 * (slip_all[sl][1:] + slip_all[sl][:-1]) / spec.fine_rate_hz)])
            ph0 = float(rng_eff.uniform(0, 2 * np.pi))
            phases.append(ph0)
            transmitted[sl] = transmitted[sl] * (1.0 + ripple["amplitude"] * np.sin(ripple["order"] * phi + ph0))
        eff_info["ripple_phases_rad"] = phases
    judder = spec.effect_values("torque_judder")
    if judder is not None:
        phases = []
        for i in range(n_runs):
            sl = slice(i * n_fine, (i + 1) * n_fine)
            ph0 = float(rng_eff.uniform(0, 2 * np.pi))
            phases.append(ph0)
            tt = t_abs[sl] - t_abs[sl][0]
            osc = judder["amplitude"] * np.exp(-np.abs(slip_all[sl]) / judder["slip_scale_rad_s"]) \
                * np.sin(2 * np.pi * judder["frequency_hz"] * tt + ph0)
            transmitted[sl] = np.where(locked[sl], transmitted[sl], transmitted[sl] * (1.0 + osc))
        eff_info["judder_phases_rad"] = phases
    sensor = np.asarray(predict_measured_torque(true_model, t_abs, transmitted, run_start), float)
    gain = spec.effect_values("torque_sensor_gain")
    if gain is not None:
        sensor = float(gain["gain"]) * sensor
    lp = spec.effect_values("torque_sensor_lowpass")
    if lp is not None:
        sensor = _lowpass_per_run(t_abs, sensor, run_start, lp["tau_s"])
    resonance = spec.effect_values("torque_sensor_resonance")
    if resonance is not None:
        sensor = _second_order_per_run(np.asarray(sensor, float), run_start, float(resonance["f_n_hz"]),
                                       float(resonance["damping"]), 1.0 / spec.fine_rate_hz)
    thermal = spec.effect_values("torque_sensor_thermal_offset")
    if thermal is not None:
        sensor = sensor + float(thermal["slope_nm_per_c"]) * (np.asarray(sump_all, float) - 60.0)
    asym_sensor = spec.effect_values("torque_sensor_asymmetric_lag")
    if asym_sensor is not None:
        sensor = _asymmetric_sensor(np.ascontiguousarray(sensor, float), run_start,
                                    float(asym_sensor["tau_rise_s"]) * spec.fine_rate_hz,
                                    float(asym_sensor["tau_fall_s"]) * spec.fine_rate_hz)

    runs = []
    names = [f"drive_{i:02d}" for i in range(n_runs)] if spec.schedule == "long-drive" else \
        [f"run_{i:02d}" for i in range(n_runs)]
    # each channel's noise-free value over the whole campaign, and a sensor's range
    # (``sensor_range``): its reading pinned at +-share x the campaign's peak of it
    whole = {"applied_force": force_logged, "slip_speed": slip_all, "sump_temperature": sump_all,
             "measured_torque": sensor, "pack_temperature": plant["pack"]}
    rails = {ch: float(share) * float(np.max(np.abs(whole[ch]))) for ch, share in spec.sensor_range.items()}
    for i in range(n_runs):
        sl = slice(i * n_fine, (i + 1) * n_fine)
        fine = {"t_s": t_run.copy(), "applied_force_n": force_logged[sl], "slip_speed_rad_s": slip_all[sl],
                "sump_temperature_c": sump_all[sl], "torque_nm": transmitted[sl],
                "sensor_torque_nm": sensor[sl], "pack_temperature_c": plant["pack"][sl],
                "locked": locked[sl], "plant_locked": plant["locked"][sl],
                "static_capacity_nm": np.where(plant["locked"][sl], plant["torque"][sl], np.nan)}
        clean_fine = {ch: values[sl] for ch, values in whole.items()}
        chans = [c for c in CHANNELS if c != "pack_temperature" or spec.include_pack_temperature]
        series, truth = {}, {}
        pause = None
        if i < spec.logger_pause_runs:       # its own generator: every other draw stays as it was
            rng_pause = np.random.default_rng([int(spec.seed), 7310, i])
            p0 = float(rng_pause.uniform(0.3, 0.6)) * dur
            pause = (p0, p0 + float(rng_pause.uniform(*spec.logger_pause_s)))
            schedules[i] = {**schedules[i], "logger_pause_s": [round(pause[0], 4), round(pause[1], 4)]}
        for ch in chans:
            clock = spec.clocks[ch]
            if spec.random_phase:
                clock = replace(clock, phase_s=float(rng_clock.uniform(0, 1.0 / clock.rate_hz)))
            t_true, t_stamp = clock.sample_times(rng_clock, dur)
            clean = sample_signal(t_run, clean_fine[ch], t_true)
            noise = spec.noise[ch].sample(rng_noise, t_true)
            var = float(spec.noise[ch].sigma ** 2) if ch in ("sump_temperature", "pack_temperature") else 0.0
            step = float(spec.resolution.get(ch, 0.0) or 0.0)
            logged = clean + noise if step <= 0 else np.round((clean + noise) / step) * step
            if ch in rails:
                logged = np.clip(logged, -rails[ch], rails[ch])
            if pause is not None:                # the logger silent, the clutch running on
                kept = (t_stamp < pause[0]) | (t_stamp > pause[1])
                t_true, t_stamp, clean, noise, logged = (a[kept] for a in (t_true, t_stamp, clean, noise, logged))
            series[ch] = TopicSeries(t_stamp, logged, var)
            truth[ch] = {"t_true_s": t_true, "t_stamp_s": t_stamp, "clean": clean, "noise": noise,
                         "phase_s": clock.phase_s}
        runs.append(CarLogRun(name=names[i], start_time_ns=start_ns[i], fine=fine,
                              signals=RunSignals(**series), sample_truth=truth, schedule=schedules[i]))

    bench = synthesize_bench(true_model, CampaignSpec(), rng_bench)
    truth_meta = {
        "generator": "clutch_model.virtual_car.car_logs",
        "seed": int(spec.seed),
        "expected_cause": spec.expected_cause,
        "expected_causes": spec.expected_causes,
        "mechanisms": [m.to_dict() for m in true_model.mechanisms],
        "effects": [{"name": e["name"], "parameters": spec.effect_values(e["name"]),
                     **{k: v for k, v in EFFECTS[e["name"]].items() if k != "parameters"}}
                    for e in spec.effects],
        "effect_draws": eff_info,
        "friction_spread": spec.friction_spread,
        "friction_factors": [float(x) for x in factors],
        "true_friction_a": [float(x) for x in true_model.friction_coefficients],
        "lock_slip_rad_s": true_model.lock_slip_rad_s,
        "clocks": {ch: c.to_dict() for ch, c in spec.clocks.items()},
        "noise": {ch: n.to_dict() for ch, n in spec.noise.items()},
        "resolution": {ch: float(q) for ch, q in spec.resolution.items()},
        "sensor_range": {ch: {"share_of_peak": float(spec.sensor_range[ch]), "rail": rails[ch]} for ch in rails},
        "fine_rate_hz": spec.fine_rate_hz,
        "runs": [{"name": r.name, "start_time_ns": r.start_time_ns, "duration_s": dur,
                  "first_stamp_s": r.first_stamp_s,
                  "locked_fraction": float(np.mean(r.fine["locked"])),
                  "peak_torque_nm": float(np.max(np.abs(r.fine["torque_nm"]))),
                  "peak_pack_temperature_c": float(np.max(r.fine["pack_temperature_c"])),
                  "samples": {ch: int(s["t_stamp_s"].size) for ch, s in r.sample_truth.items()},
                  "topic_phase_s": {ch: float(s["phase_s"]) for ch, s in r.sample_truth.items()},
                  **r.schedule} for r in runs],
        "spec": _jsonable({k: v for k, v in asdict(spec).items() if k not in ("clocks", "noise")}),
    }
    return CarLogResult(spec=spec, runs=runs, bench=bench, true_model=true_model, truth=truth_meta)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    return obj


# ------------------------------------------------------------------------------ files
def write_car_logs(result: CarLogResult, out_dir, storage: str = "mcap", compression: str = "none",
                   progress=None) -> dict:
    """Write ``bench.csv``, ``bags/<run>/``, ``truth.yaml``, ``truth.json`` and
    ``truth/<run>.npz`` (see ``truth_sidecar_arrays``). Returns the paths."""
    from clutch_model.formats.bag_writer import write_run_bag
    from clutch_model.formats.bench_csv import write_bench
    from clutch_model.plant.params import save_model

    out_dir = Path(out_dir)
    bag_root = out_dir / "bags"
    clash = [r.name for r in result.runs if (bag_root / r.name).exists()]
    if clash:
        raise DataError(f"{bag_root} already holds bag(s) {', '.join(clash[:3])}; choose an empty output directory")
    (out_dir / "truth").mkdir(parents=True, exist_ok=True)
    bag_root.mkdir(parents=True, exist_ok=True)
    paths = {"bench": out_dir / "bench.csv", "truth_model": out_dir / "truth.yaml",
             "truth": out_dir / "truth.json", "bags": [], "sidecars": []}
    write_bench(paths["bench"], result.bench)
    hdr = (f"TRUE clutch of a car-log campaign (clutch_model.virtual_car.car_logs, seed {result.spec.seed}).\n"
           f"expected diagnosis: {result.truth['expected_cause']}"
           + (" (effects outside the catalog are not representable in this file)" if result.spec.effects else "")
           + "\nGround truth for tests: diagnose must never read this file.")
    save_model(result.true_model, paths["truth_model"], header=hdr)
    for run in result.runs:
        if progress:
            progress(run.name)
        paths["bags"].append(write_run_bag(bag_root / run.name, run.signals, storage=storage,
                                           start_time_ns=run.start_time_ns, compression=compression))
        side = out_dir / "truth" / f"{run.name}.npz"
        np.savez_compressed(side, **truth_sidecar_arrays(run))
        paths["sidecars"].append(side)
    paths["truth"].write_text(json.dumps(result.truth, indent=1) + "\n")
    return paths


def truth_sidecar_arrays(run: CarLogRun) -> dict:
    """The arrays of ``truth/<run>.npz``. Times ``*_t_s`` are s from the bag's first message
    (the reader's time base); ``*_log_time_ns`` the absolute log times as written.

    torque_t_s, torque_log_time_ns   the measured torque's stamps
    torque_true_nm      noise-free sensor reading there (measurement mechanisms and effects
                        included): score a model's predicted measurement against this
    torque_transmitted_nm  transmitted torque at the sample instants (before measurement
                        mechanisms)
    torque_noise_nm     measured - torque_true_nm (the sensor noise series)
    torque_locked       the clutch is locked at the sample instant
    slip_t_s, slip_true_rad_s, slip_noise_rad_s, slip_locked   the same for the slip topic
    force_t_s, force_true_n      the applied-force topic's stamps and noise-free values
    fine_t_s, fine_applied_force_n, fine_slip_speed_rad_s, fine_sump_temperature_c,
    fine_torque_nm, fine_sensor_torque_nm, fine_pack_temperature_c, fine_locked,
    fine_plant_locked, fine_static_capacity_nm (NaN while slipping)
                        the fine simulation grid (s from the bag's first message); fine_torque_nm
                        is the transmitted torque (the driveline's while locked)
    """
    t0 = run.first_stamp_s
    fine = run.fine
    tq = run.sample_truth["measured_torque"]
    sl = run.sample_truth["slip_speed"]
    fo = run.sample_truth["applied_force"]

    def locked_at(t_true):
        idx = np.clip(np.round(t_true * (fine["t_s"].size / (fine["t_s"][-1] + fine["t_s"][1]))).astype(int),
                      0, fine["t_s"].size - 1)
        return fine["locked"][idx]

    out = {
        "torque_t_s": tq["t_stamp_s"] - t0,
        "torque_log_time_ns": run.start_time_ns + np.round(tq["t_stamp_s"] * 1e9).astype(np.int64),
        "torque_true_nm": tq["clean"],
        "torque_transmitted_nm": np.interp(tq["t_true_s"], fine["t_s"], fine["torque_nm"]),
        "torque_noise_nm": tq["noise"],
        "torque_locked": locked_at(tq["t_true_s"]),
        "slip_t_s": sl["t_stamp_s"] - t0,
        "slip_true_rad_s": sl["clean"],
        "slip_noise_rad_s": sl["noise"],
        "slip_locked": locked_at(sl["t_true_s"]),
        "force_t_s": fo["t_stamp_s"] - t0,
        "force_true_n": fo["clean"],
        "bag_first_log_time_ns": np.int64(run.start_time_ns + int(round(t0 * 1e9))),
    }
    for k, v in fine.items():
        out[f"fine_{k}" if k != "t_s" else "fine_t_s"] = v - t0 if k == "t_s" else v
    return out


def load_truth_sidecar(path) -> dict:
    """Read ``truth/<run>.npz`` back as a dict of arrays."""
    with np.load(Path(path)) as z:
        return {k: z[k] for k in z.files}


def parse_item(text: str, kind: str) -> dict:
    """'actuator_lag=0.1' or 'slip_power_fade:k_per_kw=0.05,tau_s=2' -> a spec entry.
    ``kind`` "mechanism" ({"id": ...}) or "effect" ({"name": ...}). A bare value after '='
    sets the single (first) parameter."""
    from clutch_model.virtual_car.campaign import DEFAULT_MAGNITUDE, MECHANISM_PARAMETER

    key = "id" if kind == "mechanism" else "name"
    if ":" in text:
        name, rest = text.split(":", 1)
        entry = {key: name}
        for part in filter(None, rest.split(",")):
            k, _, v = part.partition("=")
            try:
                entry[k.strip()] = float(v)
            except ValueError:
                raise ParamsError(f"{kind} {name}: '{part}' is not name=number") from None
        return entry
    name, _, val = text.partition("=")
    entry = {key: name}
    if kind == "mechanism":
        if name not in MECHANISM_PARAMETER:
            raise ParamsError(f"unknown mechanism '{name}' (known: {', '.join(MECHANISM_PARAMETER)})")
        default = DEFAULT_MAGNITUDE.get(name)
        if default is None and name == "friction_degradation":
            default = 2.0e6   # ~ -10 % friction over a default short-runs campaign
        if not val and default is None:
            raise ParamsError(f"mechanism {name} needs a value ({name}=X)")
        entry[MECHANISM_PARAMETER[name]] = float(val) if val else float(default)
    else:
        if name not in EFFECTS:
            raise ParamsError(f"unknown effect '{name}' (known: {', '.join(EFFECTS)})")
        if val:
            try:
                entry[next(iter(EFFECTS[name]["parameters"]))] = float(val)
            except ValueError:
                raise ParamsError(f"effect {name}: '{val}' is not a number") from None
    return entry


def parse_noise(text: str) -> Noise:
    """'ar1:sigma=8,phi=0.95', 'lowpass:sigma=8,cutoff_hz=10', 'white:sigma=8'."""
    kind, _, rest = text.partition(":")
    opts = {}
    for part in filter(None, rest.split(",")):
        k, _, v = part.partition("=")
        try:
            opts[k.strip()] = float(v)
        except ValueError:
            raise ParamsError(f"noise {kind}: '{part}' is not name=number") from None
    sigma = opts.pop("sigma", 8.0)
    if "window" in opts:
        opts["window"] = int(opts["window"])
    return make_noise(kind, sigma, **opts)


def true_sensor_torque_at(sidecar: dict, t_s) -> np.ndarray:
    """The noise-free sensor reading at any times (s from the bag's first message, e.g. the
    replay CSV's ``t``), linearly interpolated on the fine grid; NaN outside it."""
    t_s = np.asarray(t_s, float)
    ft = sidecar["fine_t_s"]
    out = np.interp(t_s, ft, sidecar["fine_sensor_torque_nm"])
    out[(t_s < ft[0]) | (t_s > ft[-1])] = np.nan
    return out


def measurement_tail_s(spec: "CarLogSpec") -> float:
    """How long the sensor keeps showing a lock phase's driveline torque after it ends under the
    spec's true measurement mechanisms and effects: the transport delay plus three torque-sensor
    time constants (catalog torque_sensor_lag, the torque_sensor_lowpass effect; a resonant
    sensor's ringing envelope)."""
    tail = 0.0
    for m in spec.mechanisms:
        if m["id"] == "transport_delay":
            tail += float(m.get("delay_s", 0.0))
        elif m["id"] == "torque_sensor_lag":
            tail += 3.0 * float(m.get("tau_s", 0.0))
    lowpass = spec.effect_values("torque_sensor_lowpass")
    if lowpass is not None:
        tail += 3.0 * float(lowpass["tau_s"])
    resonance = spec.effect_values("torque_sensor_resonance")
    if resonance is not None:       # the ringing's envelope decays with 1 / (zeta w)
        tail += 3.0 / (float(resonance["damping"]) * 2.0 * math.pi * float(resonance["f_n_hz"]))
    return tail


def near_true_lock(sidecar: dict, t_s, lock_pad_s: float = 0.1, tail_s: float = 0.0) -> np.ndarray:
    """Times (s from the bag's first message) where the noise-free sensor reading is set by the
    driveline, not the clutch, or not timed by the sampled inputs: inside a true lock phase
    widened by ``lock_pad_s`` on both sides and by ``tail_s`` more after it
    (``measurement_tail_s``: the sensor shows the lock's torque that much later); and around
    each zero crossing of the true slip (the friction torque flips sign there, and a replay
    that holds the latest slip sample times the flip only to a slip sample)."""
    t_s = np.asarray(t_s, float)
    ft, fl = sidecar["fine_t_s"], sidecar["fine_locked"].astype(float)
    slip = sidecar.get("fine_slip_speed_rad_s")
    if slip is not None and slip.size > 1:
        flip = np.sign(slip[:-1]) * np.sign(slip[1:]) < 0
        fl = fl.copy()
        fl[:-1][flip] = 1.0
        fl[1:][flip] = 1.0
    near = np.interp(t_s, ft, fl) > 0
    if not fl.any():
        return near
    step = 0.005
    for d in np.arange(-lock_pad_s, lock_pad_s + tail_s + step / 2, step):
        near |= np.interp(t_s - d, ft, fl) > 0
    return near


def score_against_truth(model: ClutchModel, runs, truth_dir, rate_hz: float = 1000.0,
                        lock_pad_s: float = 0.1, tail_s: float = 0.0) -> dict:
    """Held-out scoring against the true torque: ``model`` simulated where the measurement is
    (diagnosis.measured_time.simulate_at_measured_times) on ``runs`` (read_bags output), its
    predicted measurement compared with ``torque_true_nm`` of ``truth_dir/<run>.npz`` at the
    torque stamps, samples within ``lock_pad_s`` of a true lock phase, or ``tail_s`` after it,
    left out (the driveline sets the torque there; ``near_true_lock``). Returns {"rmse_nm": overall, "runs": {name: rmse}, "samples": n}."""
    from clutch_model.diagnosis.measured_time import simulate_at_measured_times

    mts = simulate_at_measured_times(model, runs, rate_hz=rate_hz)
    cmp = mts.comparison
    sq, n, per, per_n = 0.0, 0, {}, {}
    for j, name in enumerate(cmp.names):
        side = load_truth_sidecar(Path(truth_dir) / f"{name}.npz")
        sl = cmp.run_slice(j)
        if sl.stop == sl.start:
            continue
        truth = side["torque_true_nm"]
        if truth.size != sl.stop - sl.start:
            raise DataError(f"truth sidecar of {name} does not match its bag ({truth.size} torque samples "
                            f"vs {sl.stop - sl.start})")
        near_lock = near_true_lock(side, cmp.t[sl], lock_pad_s, tail_s)
        ok = cmp.valid[sl] & ~near_lock
        err = cmp.model[sl][ok] - truth[ok]
        per[name] = float(np.sqrt(np.mean(err ** 2))) if err.size else float("nan")
        per_n[name] = int(err.size)
        sq += float(np.sum(err ** 2)); n += int(err.size)
    return {"rmse_nm": float(np.sqrt(sq / n)) if n else float("nan"), "runs": per, "samples": n,
            "run_samples": per_n}
