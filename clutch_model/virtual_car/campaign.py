"""The virtual test car: synthetic eLSD test campaigns with a known truth.

``synthesize_campaign(spec)`` drives a "true" clutch (the base model — RC-1 unless given —
with its friction coefficients perturbed, plus an optional hidden mechanism or an effect
outside the catalog) through a realistic car-test schedule and returns what the loggers
would have recorded: noisy car-test channels per run (written as bags by
``write_campaign``), the SAE#2 bench table of the same friction material, and the truth.

Test schedule (thesis §5.1, "validation dataset")
  * ``n_runs`` runs of ``run_duration_s`` (~9 s), in log-time order, ``gap_s`` (+ up to
    ``gap_jitter_s``) apart. Each run holds a sump temperature and a slip level; sump levels
    (``sump_range_c``, 30-90 °C) and slip levels (``slip_range_rad_s``, 1-15 rad/s,
    log-spaced) are stratified over the campaign so the runs cover both ranges. A fraction
    of the runs (``slip_ramp_fraction``) ramp the slip by ±20-40 % over the run; every slip
    trace carries a slow ±2 % fluctuation, the sump a slow warm-up of < 1 °C per run.
  * Force: ``n_requests`` (4) torque requests per run, held ~1.5-2 s, in random order (steps
    up and down), reached through a 40-80 ms actuator ramp; between two requests (sometimes
    two pairs) and at the end the actuator releases to a low force (150-500 N) for 0.5 s,
    so hysteresis, preload and offsets show; the direct request-to-request steps include
    both a step up and a step down. Request forces are stratified over
    [1 kN, F_hi] with F_hi = min(12 kN, power_limit_w / (0.2 · N_f · r_m · |slip|)), which
    keeps the slip power of a run below ~8 kW and the pack below ~200 °C.
  * Sampling: applied force, slip speed and measured torque at ``rate_hz`` (200 Hz) on one
    time grid from the run's start; sump (and optionally pack) temperature at
    ``temperature_rate_hz`` (10 Hz) from the same start.

Plant: ``clutch_model.plant.simulate`` over the whole campaign from the TRUE inputs at the force
rate (runs concatenated, ``run_start`` at each run's first row, so friction_degradation's
energy carries across runs in time order). Sensor torque =
``predict_measured_torque(true model, ...)`` (torque_offset, transport_delay), then the
extra effect (if any), then noise.

Sensor noise (white, Gaussian, seeded): force ``force_noise_n`` (20 N), slip
``slip_noise_rad_s`` (0.05 rad/s), temperatures ``temperature_noise_c`` (0.3 °C, also the
variance in the Temperature messages), torque σ = hypot(``torque_noise_nm`` (8 N·m),
``torque_noise_rel`` · run peak torque) plus an optional slow drift (Ornstein-Uhlenbeck,
std ``torque_drift_nm``, time constant ``torque_drift_tau_s``).

True friction: RC-1's (or the base model's) a0..a19 each multiplied by (1 + U(−s, s)),
s = ``friction_spread`` (the thesis' Monte Carlo interval convention), redrawn (seeded) until
μ_f ≥ 0.01 (certified, clutch_model.plant.friction) over P ∈ [0, 6] MPa, θ ∈ [0, 230] °C, ω ∈ [0, 30] rad/s. The exponent i
is not perturbed.

Bench (SAE#2 μPVT, thesis §5.1 "verification dataset"): for each sump temperature
(30, 75, 120 °C), each slip speed (0.008, 0.04, 0.5, 4, 15 rad/s — the lowest for the μ_S
fit) and each pressure (0.1-6 MPa, 9 steps, dense over the car's 0.1-1.5 MPa), one point:
plate temperature = sump + 1 °C + 0.15 °C/(MPa·rad/s) · P·ω (+ 0.2 °C noise), μ = the TRUE
friction polynomials at (ω, P, plate temperature) + N(0, 0.003). The bench is a fresh plate
pack on bench oil: no car mechanism (nor friction_degradation, nor an extra effect) applies.

Hidden mechanisms (``mechanism`` = catalog id, ``magnitude`` = its single parameter) and
magnitudes that give a visible but realistic effect against the default noise (torque
σ = 8 N·m). Default campaign (12 runs, seeds 1-3): torque 0-1700 N·m (holds 150-1600 N·m),
pack 30-145 °C, dissipated energy E_c ≈ 0.26-0.29 MJ. "RMS" = RMS change of the noise-free
sensor torque against the no-mechanism twin at the default magnitude (seeds 1-3):

| id | parameter | visible range | default | RMS | what shows |
|---|---|---|---|---|---|
| actuator_lag | tau_s [s] | 0.05-0.3 | 0.15 | 130-160 N·m | slower torque rise/fall at every step |
| actuator_hysteresis | ratio [-] | 0.05-0.2 | 0.12 | 87-93 N·m | torque low after steps up, high after steps down / releases |
| spring_preload | preload_n [N] | 300-1500 | 800 | 102-107 N·m | torque lost at every force, relatively most at low force |
| friction_degradation | energy_scale_j [J] | E_c/0.25-E_c/0.05 (≈ 1-5 MJ) | μ ≈ −11.5 % at the end (≈ 2.1 MJ) | 48-54 N·m | torque falls run by run |
| torque_offset | offset_nm [N·m] | 10-50 | 25 | 25 N·m | constant shift, plain during releases |
| transport_delay | delay_s [s] | 0.02-0.2 | 0.08 | 110-135 N·m | torque edges late vs force edges |
| drag_torque | coeff_nm_per_rad_s | 2-10 | 6 | 25-32 N·m | + coeff·ω·ν(θ)/ν(60 °C) always; plainest at release force, cold |
| torque_sensor_lag | tau_s [s] | 0.02-0.2 | 0.06 | 76-87 N·m (seeds 1-2) | torque edges rounded (first-order) vs force edges |

The visible ranges and defaults live on the mechanism objects (``Mechanism.virtual_car``);
the table restates them with the effect they have.

(A physically typical open-pack drag is < 1 N·m/(rad/s), which would hide in the 8 N·m
noise — the range above is what a diagnosis can be expected to see.)

``friction_degradation`` without a magnitude: the energy scale is set to E_c/−ln(0.88), E_c
the campaign's energy without degradation (a pre-pass), so μ_f has dropped by ≈ 11.5 % at
the end (a little less than 12 %: the degraded clutch dissipates less). Its energy is E = ∫|ω·T| dt.

Extra effects (``extra_effect``; outside the catalog, so a diagnosis must answer
``unexplained``), both car-only:

| name | effect | visible range | default |
|---|---|---|---|
| torque_ripple | sensor torque × (1 + A·sin(k·φ(t) + φ0)), φ = ∫ω dt per run (slip angle), k = ``ripple_order`` (1: once per relative revolution, a runout / plate-parallelism ripple), φ0 random per run | A = 0.03-0.15 | 0.06 (RMS 32-33 N·m) |
| pressure_temperature_cross | μ_f × (1 + c·P·(θ_pack − 60 °C)), P in MPa (car ATF additive interaction the bench oil lacks; a P·θ cross term the polynomials cannot represent); applied inside the plant, so it heats the pack too | c = 1e-3-4e-3 1/(MPa·°C) | 2e-3 (RMS 42-46 N·m) |

Every random draw comes from ``seed`` (separate streams for friction, schedule, noise and
bench), so the same spec gives the same arrays.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from numba import njit

from clutch_model.plant import kernels as K
from clutch_model.plant import params as P
from clutch_model.plant.friction import friction_grid, friction_positive
from clutch_model.formats.bag_writer import DEFAULT_START_TIME_NS, RunSignals, TopicSeries
from clutch_model.formats.bench_csv import BenchData
from clutch_model.formats.results import jsonable, write_json
from clutch_model.errors import DataError, ParamsError
from clutch_model.plant.mechanisms import CATALOG, make_mechanism
from clutch_model.plant.params import ClutchModel, load_model

# what the car draws for each catalog mechanism comes from the mechanism objects
MECHANISM_PARAMETER = {mid: cls.magnitude_parameter() for mid, cls in CATALOG.items()}
DEFAULT_MAGNITUDE = {mid: cls.virtual_car.default for mid, cls in CATALOG.items()}
VISIBLE_RANGE = {**{mid: cls.virtual_car.visible for mid, cls in CATALOG.items()},
                 "torque_ripple": (0.03, 0.15),
                 "pressure_temperature_cross": (1e-3, 4e-3)}
EXTRA_EFFECTS = {
    "torque_ripple": "sensor torque x (1 + A sin(k phi + phi0)), phi = slip angle (int w dt) "
                     "per run: once-per-revolution runout / plate-parallelism ripple",
    "pressure_temperature_cross": "mu_f x (1 + c P (theta_pack - 60 C)), P in MPa: a "
                                  "pressure-temperature cross term of the car's ATF/lining "
                                  "the polynomials cannot represent",
}
DEFAULT_EXTRA_MAGNITUDE = {"torque_ripple": 0.06, "pressure_temperature_cross": 2e-3}
DEGRADATION_DEFAULT_DROP = 0.12
MU_POSITIVE_MIN = 0.01
FRICTION_CHECK_BOX = {"pressure_mpa": (0.0, 6.0), "theta_c": (0.0, 230.0), "slip_rad_s": (0.0, 30.0)}


@dataclass
class CampaignSpec:
    """Everything that defines a synthetic campaign (see the module docstring)."""

    seed: int = 0
    n_runs: int = 12
    run_duration_s: float = 9.0
    rate_hz: float = 200.0
    temperature_rate_hz: float = 10.0
    gap_s: float = 120.0
    gap_jitter_s: float = 30.0
    start_time_ns: int = DEFAULT_START_TIME_NS
    # schedule
    sump_range_c: tuple = (30.0, 90.0)
    slip_range_rad_s: tuple = (1.0, 15.0)
    slip_ramp_fraction: float = 0.3
    negative_slip_fraction: float = 0.0
    n_requests: int = 4
    force_range_n: tuple = (1000.0, 12000.0)
    release_force_range_n: tuple = (150.0, 500.0)
    actuator_ramp_s: tuple = (0.04, 0.08)
    power_limit_w: float = 8000.0
    # truth
    friction_spread: float = 0.05
    mechanism: str | None = None
    magnitude: float | None = None
    extra_effect: str | None = None
    ripple_order: float = 1.0
    # sensors
    include_pack_temperature: bool = False
    force_noise_n: float = 20.0
    slip_noise_rad_s: float = 0.05
    temperature_noise_c: float = 0.3
    torque_noise_nm: float = 8.0
    torque_noise_rel: float = 0.0
    torque_drift_nm: float = 0.0
    torque_drift_tau_s: float = 5.0
    # bench
    bench_slip_speeds_rad_s: tuple = (0.008, 0.04, 0.5, 4.0, 15.0)
    bench_pressures_mpa: tuple = (0.1, 0.25, 0.5, 0.75, 1.0, 1.5, 2.5, 4.0, 6.0)
    bench_sump_temperatures_c: tuple = (30.0, 75.0, 120.0)
    bench_noise: float = 0.003
    bench_plate_noise_c: float = 0.2

    def validate(self) -> None:
        def need(cond, msg):
            if not cond:
                raise ParamsError(f"campaign spec: {msg}")
        need(self.n_runs >= 1, "need at least one run")
        need(self.n_requests >= 1, "need at least one torque request per run")
        need(self.rate_hz > 0 and self.temperature_rate_hz > 0, "sample rates must be > 0")
        need(self.run_duration_s >= 1.0 + 0.6 * self.n_requests,
             f"run duration must be >= {1.0 + 0.6 * self.n_requests:g} s for "
             f"{self.n_requests} requests")
        need(self.gap_s >= 0 and self.gap_jitter_s >= 0, "gaps must be >= 0")
        need(0 < self.sump_range_c[0] <= self.sump_range_c[1], "sump range must be positive, ascending")
        need(0 < self.slip_range_rad_s[0] <= self.slip_range_rad_s[1], "slip range must be positive, ascending")
        need(0 <= self.force_range_n[0] < self.force_range_n[1], "force range must be ascending, >= 0")
        need(0 <= self.friction_spread < 1, "friction spread must be in [0, 1)")
        for name in ("force_noise_n", "slip_noise_rad_s", "temperature_noise_c", "torque_noise_nm",
                     "torque_noise_rel", "torque_drift_nm", "bench_noise", "bench_plate_noise_c"):
            need(getattr(self, name) >= 0, f"{name} must be >= 0")
        need(self.torque_drift_tau_s > 0, "torque_drift_tau_s must be > 0")
        need(not (self.mechanism and self.extra_effect),
             "choose a hidden mechanism or an extra effect, not both")
        if self.mechanism is not None and self.mechanism not in CATALOG:
            raise ParamsError(f"unknown mechanism '{self.mechanism}' "
                              f"(known: {', '.join(CATALOG)})")
        if self.extra_effect is not None and self.extra_effect not in EXTRA_EFFECTS:
            raise ParamsError(f"unknown extra effect '{self.extra_effect}' "
                              f"(known: {', '.join(EXTRA_EFFECTS)})")
        if self.magnitude is not None:
            need(math.isfinite(self.magnitude), "magnitude must be finite")
            need(self.mechanism or self.extra_effect, "magnitude given without a mechanism or extra effect")
            if self.mechanism:
                make_mechanism(self.mechanism, **{MECHANISM_PARAMETER[self.mechanism]: self.magnitude})

    @property
    def expected_cause(self) -> str:
        """What a correct diagnosis names: the mechanism id, 'unexplained' or 'none'."""
        if self.mechanism:
            return self.mechanism
        if self.extra_effect:
            return "unexplained"
        return "none"


@dataclass(frozen=True)
class SynthRun:
    """One synthetic run: truth on the plant grid plus the measured channels."""

    name: str
    start_time_ns: int
    t_s: np.ndarray                  # plant grid = force/slip/torque stamps, s from run start
    applied_force_n: np.ndarray      # true actuator force
    slip_speed_rad_s: np.ndarray     # true slip
    sump_temperature_c: np.ndarray   # true sump on the plant grid
    plant_torque_nm: np.ndarray      # transmitted torque
    sensor_torque_nm: np.ndarray     # noise-free sensor reading (measurement mechanisms, extra effect)
    pack_temperature_c: np.ndarray
    friction_coefficient: np.ndarray
    signals: RunSignals              # the noisy channels written to the bag
    schedule: dict = field(default_factory=dict)

    @property
    def measured_torque_nm(self) -> np.ndarray:
        return self.signals.measured_torque.values


@dataclass(frozen=True)
class CampaignResult:
    spec: CampaignSpec
    runs: list
    bench: BenchData
    true_model: ClutchModel
    metadata: dict

    @property
    def expected_cause(self) -> str:
        return self.spec.expected_cause

    def run_names(self) -> list:
        return [r.name for r in self.runs]


# ----------------------------------------------------------------------------- truth
def friction_is_positive(model: ClutchModel, minimum: float = MU_POSITIVE_MIN) -> bool:
    """μ_f >= minimum over FRICTION_CHECK_BOX (the one friction positivity check)."""
    return friction_positive(model.friction_coefficients, model.friction_exponent,
                             FRICTION_CHECK_BOX["pressure_mpa"], FRICTION_CHECK_BOX["theta_c"],
                             FRICTION_CHECK_BOX["slip_rad_s"], minimum=minimum)


def perturb_friction(model: ClutchModel, spread: float, rng, max_tries: int = 1000):
    """(model with a0..a19 x (1 + U(-spread, spread)), relative factors). Redraws until μ_f
    stays positive over the check box."""
    a0 = model.friction_coefficients
    if spread == 0:
        return model.copy(), np.ones_like(a0)
    for _ in range(max_tries):
        factors = 1.0 + rng.uniform(-spread, spread, a0.size)
        cand = model.with_friction(a=a0 * factors)
        if friction_is_positive(cand):
            return cand, factors
    raise ParamsError(f"no friction perturbation with spread {spread} keeps mu_f > "
                      f"{MU_POSITIVE_MIN} over P in [0, 6] MPa, theta in [0, 230] C, "
                      f"w in [0, 30] rad/s after {max_tries} draws")


# -------------------------------------------------------------------------- schedule
def _stratified(rng, n, lo, hi, log=False):
    u = (rng.permutation(n) + rng.uniform(0.1, 0.9, n)) / n
    if log:
        return float(lo) * (float(hi) / float(lo)) ** u
    return lo + (hi - lo) * u


def _torque_per_newton(model: ClutchModel, mu: float = 0.2) -> float:
    g = model.data["geometry"]
    ro, ri = float(g["r_outer"]), float(g["r_inner"])
    r_m = 2.0 / 3.0 * (ro ** 3 - ri ** 3) / (ro ** 2 - ri ** 2)
    return mu * float(g["friction_surfaces"]) * r_m


def _force_profile(rng, spec: CampaignSpec, t, f_hi):
    n = spec.n_requests
    f_lo = spec.force_range_n[0]
    levels = np.round(_stratified(rng, n, f_lo, f_hi), 1)
    # one (sometimes two) release(s) between requests; the direct steps go up and down
    releases = np.zeros(max(n - 1, 0), dtype=bool)
    if n > 1:
        n_rel = 1 + int(n - 1 >= 3 and rng.random() < 0.3)
        releases[rng.choice(n - 1, n_rel, replace=False)] = True
    for _ in range(100):
        steps = np.diff(levels)[~releases]
        if steps.size < 2 or (np.any(steps > 0) and np.any(steps < 0)):
            break
        levels = levels[rng.permutation(n)]
    f_rel = round(float(rng.uniform(*spec.release_force_range_n)), 1)
    idle0, idle_end, rel_dur = float(rng.uniform(0.4, 0.6)), 0.5, 0.5
    avail = spec.run_duration_s - idle0 - idle_end - rel_dur * releases.sum()
    w = rng.uniform(0.85, 1.15, n)
    holds = avail * w / w.sum()
    ramps = rng.uniform(*spec.actuator_ramp_s, 2 * n + 1)
    ri = iter(ramps)
    tt, ff = [0.0, idle0], [f_rel, f_rel]
    tc = idle0
    for j in range(n):
        tt.append(tc + next(ri)); ff.append(levels[j])
        tc += holds[j]
        tt.append(tc); ff.append(levels[j])
        if j < n - 1 and releases[j]:
            tt.append(tc + next(ri)); ff.append(f_rel)
            tc += rel_dur
            tt.append(tc); ff.append(f_rel)
    tt.append(tc + next(ri)); ff.append(f_rel)
    tt.append(max(spec.run_duration_s, tc + 0.1)); ff.append(f_rel)
    tt = [round(float(x), 4) for x in tt]
    ff = [round(float(x), 1) for x in ff]
    force = np.interp(t, tt, ff)
    sched = {"requests_n": [round(float(x), 1) for x in levels],
             "release_after_request": [bool(x) for x in releases],
             "release_force_n": round(f_rel, 1),
             "breakpoints_s": tt, "breakpoints_n": ff}
    return force, sched


def _slip_profile(rng, spec: CampaignSpec, t, w0):
    dur = spec.run_duration_s
    sign = -1.0 if rng.random() < spec.negative_slip_fraction else 1.0
    if rng.random() < spec.slip_ramp_fraction:
        r = float(rng.uniform(0.2, 0.4)) * (1 if rng.random() < 0.5 else -1)
        base = w0 * (1.0 - r + 2.0 * r * t / dur)
        kind = "ramp"
    else:
        r = 0.0
        base = np.full(t.size, w0)
        kind = "constant"
    f = float(rng.uniform(0.2, 0.6))
    ph = float(rng.uniform(0, 2 * np.pi))
    slip = sign * base * (1.0 + 0.02 * np.sin(2 * np.pi * f * t + ph))
    return slip, {"slip_level_rad_s": round(sign * w0, 4), "slip_profile": kind,
                  "slip_ramp_rel": round(r, 4)}


# ---------------------------------------------------------------------------- plant
@njit(cache=True)
def _trajectory_pt_cross(p, t, force, slip, sump, run_start, coeff):
    """kernels.run_trajectory with μ_f x (1 + coeff·P·(θ_pack − 60)), applied through the
    degradation factor slot (p[ENERGY_SCALE_J] = 1, energy state = −ln factor). Columns of
    the record as kernels.O_*; O_ENERGY is not meaningful here."""
    n = t.size
    d = K.derived_constants(p)
    out = np.zeros((n, K.N_OUT))
    state = np.zeros(K.N_STATE)
    scratch = np.zeros(K.N_OUT)
    for k in range(n):
        if k == 0 or run_start[k]:
            K.init_state(state, force[k], sump[k], p)
        else:
            K.advance(state, slip[k - 1], sump[k - 1], t[k] - t[k - 1], p, d, scratch)
        K.pack_force_target(state, force[k], p)
        fp = state[K.S_FPACK]
        if fp > d[K.D_FMAX]:
            fp = d[K.D_FMAX]
        pr = fp / d[K.D_AN] * 1e-6
        fac = 1.0 + coeff * pr * (state[K.S_THETA] - 60.0)
        if fac < 0.05:
            fac = 0.05
        state[K.S_ENERGY] = -math.log(fac)
        K.outputs(state, slip[k], sump[k], p, d, out[k])
    return out


def _simulate_truth(model: ClutchModel, t, force, slip, sump, run_start, spec: CampaignSpec,
                    extra_magnitude):
    from clutch_model.plant.simulate import simulate

    if spec.extra_effect == "pressure_temperature_cross":
        if model.mechanism("friction_degradation") is not None:
            raise ParamsError("pressure_temperature_cross cannot be combined with "
                              "friction_degradation in the base model")
        p = model.vector()
        p[P.ENERGY_SCALE_J] = 1.0
        rs = np.ascontiguousarray(run_start, dtype=np.bool_)
        out = _trajectory_pt_cross(p, t, force, slip, sump, rs, float(extra_magnitude))
        return {"torque": out[:, K.O_TORQUE], "pack": out[:, K.O_THETA],
                "power": out[:, K.O_POWER], "mu": out[:, K.O_MU]}
    res = simulate(model, t, force, slip, sump, run_start=run_start)
    return {"torque": res.torque_nm, "pack": res.pack_temperature_c, "power": res.power_w,
            "mu": res.friction_coefficient}


# ------------------------------------------------------------------------------ bench
def synthesize_bench(true_model: ClutchModel, spec: CampaignSpec, rng) -> BenchData:
    """SAE#2 μPVT table of the true friction material (module docstring)."""
    rows = []
    for sump in spec.bench_sump_temperatures_c:
        for w in spec.bench_slip_speeds_rad_s:
            for pr in spec.bench_pressures_mpa:
                rows.append((w, pr, sump))
    arr = np.asarray(rows, dtype=float)
    w, pr, sump = arr[:, 0], arr[:, 1], arr[:, 2]
    plate = sump + 1.0 + 0.15 * pr * np.abs(w) + rng.normal(0.0, spec.bench_plate_noise_c, w.size)
    mu = friction_grid(true_model.friction_coefficients, true_model.friction_exponent, np.abs(w), pr, plate)
    mu = mu + rng.normal(0.0, spec.bench_noise, w.size)
    # logged resolution of the bench: 1e-4 rad/s, 1 kPa, 0.01 C, 1e-4
    return BenchData(slip_speed_rad_s=np.round(w, 4), pressure_mpa=np.round(pr, 3),
                     plate_temperature_c=np.round(plate, 2), sump_temperature_c=np.round(sump, 2),
                     friction_coefficient=np.round(mu, 4), source="synth")


# --------------------------------------------------------------------------- campaign
@dataclass(frozen=True)
class Truth:
    """Stage 1: the true clutch (perturbed friction) and its relative friction factors."""
    model: ClutchModel
    friction_factors: np.ndarray


@dataclass(frozen=True)
class Schedule:
    """Stage 2: the test schedule, on each run's grid and concatenated in log-time order."""
    t_run: np.ndarray                # plant grid of a run, s from its start
    t_temp: np.ndarray               # temperature grid of a run
    start_ns: tuple                  # log time of each run's start
    force: tuple                     # true actuator force per run
    slip: tuple                      # true slip per run
    sump: tuple                      # true sump per run (plant grid)
    runs: tuple                      # schedule facts per run (dicts, not mutated)
    t_abs: np.ndarray                # concatenated grid, s from the campaign start
    run_start: np.ndarray

    @property
    def n_runs(self) -> int:
        return len(self.start_ns)

    @property
    def n_rows(self) -> int:
        return int(self.t_run.size)


@dataclass(frozen=True)
class HiddenMechanism:
    """Stage 3: the true model with its hidden catalog mechanism (if any) and its value."""
    model: ClutchModel
    value: float | None


@dataclass(frozen=True)
class PlantTruth:
    """Stage 4: the true plant on the whole campaign and what the noise-free sensor reads."""
    torque: np.ndarray
    pack: np.ndarray
    power: np.ndarray
    mu: np.ndarray
    sensor: np.ndarray
    extra_magnitude: float | None


def draw_truth(spec: CampaignSpec, base: ClutchModel, rng) -> Truth:
    model, factors = perturb_friction(base, spec.friction_spread, rng)
    return Truth(model, factors)


def plan_schedule(spec: CampaignSpec, base: ClutchModel, rng) -> Schedule:
    """Runs of stratified sump and slip levels, torque requests and releases (module doc)."""
    n = spec.n_runs
    n_rows = int(round(spec.run_duration_s * spec.rate_hz))
    t_run = np.arange(n_rows) / spec.rate_hz
    n_temp = int(round(spec.run_duration_s * spec.temperature_rate_hz))
    t_temp = np.arange(n_temp) / spec.temperature_rate_hz
    sumps = _stratified(rng, n, *spec.sump_range_c)
    slips = _stratified(rng, n, *spec.slip_range_rad_s, log=True)
    k_t = _torque_per_newton(base)
    offsets_s, sched, F, W, S = [], [], [], [], []
    t_cur = 0.0
    for i in range(n):
        offsets_s.append(t_cur)
        w_run, s_run = float(slips[i]), float(sumps[i])
        slip, s_info = _slip_profile(rng, spec, t_run, w_run)
        w_peak = float(np.max(np.abs(slip)))
        f_hi = min(spec.force_range_n[1], spec.power_limit_w / (k_t * w_peak))
        f_hi = max(f_hi, min(spec.force_range_n[1], spec.force_range_n[0] + 2000.0))
        force, f_info = _force_profile(rng, spec, t_run, f_hi)
        warm = float(rng.uniform(0.0, 0.08))
        sump = s_run + warm * t_run
        sched.append({"sump_level_c": round(s_run, 3), "sump_warmup_c_per_s": round(warm, 4),
                      **s_info, **f_info})
        F.append(force); W.append(slip); S.append(sump)
        t_cur += spec.run_duration_s + spec.gap_s + float(rng.uniform(0, spec.gap_jitter_s))
    # log times in whole ms from the campaign start
    start_ns = [int(spec.start_time_ns) + int(round(o * 1e3)) * 1_000_000 for o in offsets_s]
    t_abs = np.concatenate([(sn - spec.start_time_ns) * 1e-9 + t_run for sn in start_ns])
    run_start = np.zeros(t_abs.size, dtype=bool)
    run_start[np.arange(n) * n_rows] = True
    return Schedule(t_run=t_run, t_temp=t_temp, start_ns=tuple(start_ns), force=tuple(F), slip=tuple(W),
                    sump=tuple(S), runs=tuple(sched), t_abs=t_abs, run_start=run_start)


def hide_mechanism(spec: CampaignSpec, model: ClutchModel, schedule: Schedule) -> HiddenMechanism:
    """Add the spec's catalog mechanism at its magnitude (default: the mechanism's own
    virtual-car default; friction_degradation: a fixed drop of mu over the campaign)."""
    if not spec.mechanism:
        return HiddenMechanism(model, None)
    value = spec.magnitude if spec.magnitude is not None else DEFAULT_MAGNITUDE[spec.mechanism]
    if spec.mechanism == "friction_degradation" and value is None:
        pre = _simulate_truth(model, *_plant_inputs(schedule), spec, None)
        e_tot = float(np.sum(_per_run_energy(schedule.t_abs, pre["power"], schedule.run_start)))
        value = e_tot / -math.log(1.0 - DEGRADATION_DEFAULT_DROP)
    return HiddenMechanism(_with_mechanism(model, spec.mechanism, value), float(value))


def simulate_plant(spec: CampaignSpec, model: ClutchModel, schedule: Schedule) -> PlantTruth:
    """The true plant over the whole campaign (energy carried across runs) and the noise-free
    sensor (the model's measurement mechanisms)."""
    from clutch_model.plant.simulate import predict_measured_torque

    extra = None
    if spec.extra_effect:
        extra = spec.magnitude if spec.magnitude is not None else DEFAULT_EXTRA_MAGNITUDE[spec.extra_effect]
    sim = _simulate_truth(model, *_plant_inputs(schedule), spec, extra)
    sensor = np.asarray(predict_measured_torque(model, schedule.t_abs, sim["torque"], schedule.run_start), float)
    return PlantTruth(torque=sim["torque"], pack=sim["pack"], power=sim["power"], mu=sim["mu"], sensor=sensor,
                      extra_magnitude=extra)


def record_runs(spec: CampaignSpec, schedule: Schedule, plant: PlantTruth, rng) -> list:
    """Per run: the extra effect on the sensor (if any), noise, the logged channels."""
    runs = []
    var_t = spec.temperature_noise_c ** 2
    n_rows, t_run, t_temp = schedule.n_rows, schedule.t_run, schedule.t_temp
    n_temp = t_temp.size
    e_runs = _per_run_energy(schedule.t_abs, plant.power, schedule.run_start)
    names = run_names(schedule.n_runs)
    for i in range(schedule.n_runs):
        info = dict(schedule.runs[i])
        sl = slice(i * n_rows, (i + 1) * n_rows)
        slip_i = schedule.slip[i]
        sens = plant.sensor[sl].copy()
        if spec.extra_effect == "torque_ripple":
            phi = np.concatenate([[0.0], np.cumsum(0.5 * (slip_i[1:] + slip_i[:-1]) * np.diff(t_run))])
            phi0 = float(rng.uniform(0, 2 * np.pi))
            sens = sens * (1.0 + plant.extra_magnitude * np.sin(spec.ripple_order * phi + phi0))
            info["ripple_phase_rad"] = round(phi0, 4)
        peak = float(np.max(np.abs(plant.torque[sl])))
        sigma = math.hypot(spec.torque_noise_nm, spec.torque_noise_rel * peak)
        torque_meas = sens + rng.normal(0.0, 1.0, n_rows) * sigma
        if spec.torque_drift_nm > 0:
            torque_meas = torque_meas + _ou(rng, n_rows, 1.0 / spec.rate_hz,
                                            spec.torque_drift_tau_s, spec.torque_drift_nm)
        force_meas = schedule.force[i] + rng.normal(0.0, spec.force_noise_n, n_rows)
        slip_meas = slip_i + rng.normal(0.0, spec.slip_noise_rad_s, n_rows)
        sump_meas = np.interp(t_temp, t_run, schedule.sump[i]) + rng.normal(0.0, spec.temperature_noise_c, n_temp)
        pack_series = None
        if spec.include_pack_temperature:
            pack_meas = (np.interp(t_temp, t_run, plant.pack[sl])
                         + rng.normal(0.0, spec.temperature_noise_c, n_temp))
            pack_series = TopicSeries(t_temp, pack_meas, var_t)
        signals = RunSignals(applied_force=TopicSeries(t_run, force_meas),
                             slip_speed=TopicSeries(t_run, slip_meas),
                             sump_temperature=TopicSeries(t_temp, sump_meas, var_t),
                             measured_torque=TopicSeries(t_run, torque_meas),
                             pack_temperature=pack_series)
        info.update({"torque_noise_sigma_nm": round(sigma, 4),
                     "peak_torque_nm": round(peak, 2),
                     "peak_pack_temperature_c": round(float(np.max(plant.pack[sl])), 2),
                     "energy_j": round(float(e_runs[i]), 1)})
        runs.append(SynthRun(name=names[i], start_time_ns=schedule.start_ns[i], t_s=t_run.copy(),
                             applied_force_n=schedule.force[i], slip_speed_rad_s=slip_i,
                             sump_temperature_c=schedule.sump[i],
                             plant_torque_nm=plant.torque[sl].copy(), sensor_torque_nm=sens,
                             pack_temperature_c=plant.pack[sl].copy(),
                             friction_coefficient=plant.mu[sl].copy(), signals=signals, schedule=info))
    return runs


def campaign_metadata(spec: CampaignSpec, base: ClutchModel, truth: Truth, hidden: HiddenMechanism,
                      plant: PlantTruth, runs: list, schedule: Schedule) -> dict:
    e_total = float(np.sum(_per_run_energy(schedule.t_abs, plant.power, schedule.run_start)))
    extra = plant.extra_magnitude
    meta = {
        "generator": "clutch_model.virtual_car.campaign",
        "expected_cause": spec.expected_cause,
        "seed": int(spec.seed),
        "base_model": str(base.source),
        "friction_spread": spec.friction_spread,
        "friction_factors": [float(x) for x in truth.friction_factors],
        "true_friction_a": [float(x) for x in hidden.model.friction_coefficients],
        "mechanism": ({"id": spec.mechanism, MECHANISM_PARAMETER[spec.mechanism]: float(hidden.value)}
                      if spec.mechanism else None),
        "extra_effect": ({"name": spec.extra_effect, "magnitude": float(extra),
                          "description": EXTRA_EFFECTS[spec.extra_effect],
                          **({"order": spec.ripple_order} if spec.extra_effect == "torque_ripple" else {})}
                         if spec.extra_effect else None),
        "campaign_energy_j": e_total,
        "runs": [{"name": r.name, "start_time_ns": r.start_time_ns, **r.schedule} for r in runs],
        "spec": jsonable(asdict(spec)),
    }
    if spec.mechanism == "friction_degradation":
        meta["friction_factor_at_end"] = math.exp(-e_total / float(hidden.value))
    return meta


def _plant_inputs(schedule: Schedule):
    return (schedule.t_abs, np.concatenate(schedule.force), np.concatenate(schedule.slip),
            np.concatenate(schedule.sump), schedule.run_start)


def _with_mechanism(model: ClutchModel, mech_id: str, value: float) -> ClutchModel:
    mech = make_mechanism(mech_id, **{MECHANISM_PARAMETER[mech_id]: float(value)})
    others = [m for m in model.mechanisms if m.id != mech_id]
    return model.with_mechanisms(others + [mech])


def synthesize_campaign(spec: CampaignSpec | None = None, base_model: ClutchModel | None = None,
                        progress=None) -> CampaignResult:
    """Generate a campaign (see the module docstring), in stages: truth -> schedule -> hidden
    mechanism -> plant -> recorded runs -> bench -> metadata. ``progress``: optional
    callable(str). Every stage draws from its own seeded stream."""
    spec = spec or CampaignSpec()
    spec.validate()
    base = base_model if base_model is not None else load_model(None)
    ss = np.random.SeedSequence(int(spec.seed))
    rng_fric, rng_sched, rng_noise, rng_bench = (np.random.default_rng(s) for s in ss.spawn(4))

    truth = draw_truth(spec, base, rng_fric)
    schedule = plan_schedule(spec, base, rng_sched)
    hidden = hide_mechanism(spec, truth.model, schedule)
    if progress:
        progress("simulating the true plant")
    plant = simulate_plant(spec, hidden.model, schedule)
    runs = record_runs(spec, schedule, plant, rng_noise)
    if progress:
        progress("bench table")
    bench = synthesize_bench(hidden.model, spec, rng_bench)
    meta = campaign_metadata(spec, base, truth, hidden, plant, runs, schedule)
    return CampaignResult(spec=spec, runs=runs, bench=bench, true_model=hidden.model, metadata=meta)


def _per_run_energy(t, power, run_start):
    starts = list(np.flatnonzero(run_start)) + [t.size]
    out = []
    for a, b in zip(starts[:-1], starts[1:]):
        tt, pp = t[a:b], power[a:b]
        out.append(float(np.sum(0.5 * (pp[1:] + pp[:-1]) * np.diff(tt))))
    return np.asarray(out)


def _ou(rng, n, dt, tau, sigma):
    a = math.exp(-dt / tau)
    b = sigma * math.sqrt(1.0 - a * a)
    e = rng.normal(0.0, 1.0, n)
    x = np.empty(n)
    x[0] = sigma * e[0]
    for k in range(1, n):
        x[k] = a * x[k - 1] + b * e[k]
    return x



# ------------------------------------------------------------------------------ files
def run_names(n_runs: int) -> list:
    return [f"run_{i:02d}" for i in range(n_runs)]


def check_output_dir(out_dir, names) -> None:
    """DataError if out_dir/bags already holds a bag of these names (bags are never
    overwritten)."""
    bag_root = Path(out_dir) / "bags"
    if Path(out_dir).exists() and not Path(out_dir).is_dir():
        raise DataError(f"output {out_dir} is not a directory")
    clash = [n for n in names if (bag_root / n).exists()]
    if clash:
        more = f" (+{len(clash) - 3} more)" if len(clash) > 3 else ""
        raise DataError(f"{bag_root} already holds bag(s) {', '.join(clash[:3])}{more}; "
                        f"choose an empty output directory")


def write_campaign(result: CampaignResult, out_dir, storage: str = "mcap", compression: str = "none",
                   progress=None) -> dict:
    """Write ``out_dir/bench.csv``, ``out_dir/bags/<run>/`` (one rosbag2 bag per run),
    ``out_dir/truth.yaml`` (the true model in the parameter-file schema, mechanisms included)
    and ``out_dir/campaign.json`` (the schedule, noise and truth metadata, incl.
    ``expected_cause`` and any extra effect). Returns the paths."""
    from clutch_model.formats.bag_writer import write_run_bag
    from clutch_model.formats.bench_csv import write_bench
    from clutch_model.plant.params import save_model

    out_dir = Path(out_dir)
    bag_root = out_dir / "bags"
    check_output_dir(out_dir, [r.name for r in result.runs])
    bag_root.mkdir(parents=True, exist_ok=True)
    paths = {"bench": out_dir / "bench.csv", "truth": out_dir / "truth.yaml",
             "metadata": out_dir / "campaign.json", "bags": []}
    write_bench(paths["bench"], result.bench)
    spec = result.spec
    hdr = (f"TRUE clutch of a synthetic campaign (clutch_model.virtual_car.campaign, seed {spec.seed}).\n"
           f"expected diagnosis: {spec.expected_cause}"
           + (f" ({result.metadata['extra_effect']['name']}: not representable in this file)"
              if spec.extra_effect else "")
           + "\nGround truth for tests: diagnose must never read this file.")
    save_model(result.true_model, paths["truth"], header=hdr)
    for run in result.runs:
        if progress:
            progress(run.name)
        paths["bags"].append(write_run_bag(bag_root / run.name, run.signals, storage=storage,
                                           start_time_ns=run.start_time_ns, compression=compression))
    write_json(paths["metadata"], result.metadata, indent=1)
    return paths
