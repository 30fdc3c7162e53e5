"""Hidden-campaign checks of the diagnosis on car-log data (docs/diagnosis_matrix.md).

A *cell* is a case (what the true clutch hides: nothing, a catalog mechanism, two at once,
or an effect outside the catalog) under a data condition (clean lab-like, unaligned topics,
coloured / band-limited / held / median-filtered noise, lock-up phases, one long bag, few
long runs, everything at once) and a seed. ``make_hidden_campaign`` writes it with the
car-log virtual test car (``car_logs.py``): the bags ``clutch-sim diagnose`` gets, *later*
bags from the same true clutch that it never sees, and the truth sidecars. ``check_campaign``
then does what an outside check does: ``clutch-sim diagnose`` on the seen bags (a
subprocess, as a user runs it), ``clutch-sim replay`` of calibrated_model.yaml and
extended_model.yaml on every bag (so state such as the dissipated energy is carried through),
the replayed torque on the unseen bags scored against the noise-free true torque, plus
``score_against_truth`` (the model simulated at the measured torque's own stamps).

Magnitudes are drawn from a seed the diagnosis never sees (``magnitude_seed``), log-uniform
over each cause's visible range. The campaign seed fixes the drive, so every case of a
condition and seed shares one drive (a twin comparison).

Used by bench/bench_diagnose_matrix.py (the matrix) and
tests/diagnosis/test_car_log_conditions.py (one small campaign per condition class).
"""
from __future__ import annotations

import csv
import json
import math
import os
import resource
import shutil
import subprocess
import sys
import time
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clutch_model.plant.mechanisms import CATALOG
from clutch_model.virtual_car.car_logs import (DEFAULT_CLOCKS, EFFECTS, CarLogSpec, load_truth_sidecar,
                                               measurement_tail_s, near_true_lock,
                                               score_against_truth, synthesize_car_logs,
                                               true_sensor_torque_at, write_car_logs)
from clutch_model.virtual_car.signals import TopicClock, make_noise

VERDICTS_WITHOUT_CAUSE = ("none", "unexplained", "discovered")

# ------------------------------------------------------------------------ conditions
LAB_CLOCKS = {ch: TopicClock(200.0) for ch in ("applied_force", "slip_speed", "sump_temperature",
                                               "measured_torque", "pack_temperature")}
# a torque sensor sampling at 125 Hz on its own clock, its frames stamped as they arrive (up to
# 2.8 ms, 35 % of the period, either side of the instant the value was taken)
GATEWAY_TORQUE_CLOCK = TopicClock(125.0, arrival_jitter_s=2.8e-3, quantum_s=1e-4)
# force and torque sampled at 200 Hz, their frames forwarded by a gateway in bursts every 10-20 ms
BURST_CLOCKS = {"applied_force": TopicClock(200.0, jitter_s=0.2e-3, quantum_s=1e-4, burst_s=0.015),
                "measured_torque": TopicClock(200.0, jitter_s=0.2e-3, quantum_s=1e-4, burst_s=0.015)}


@dataclass(frozen=True)
class Condition:
    """How the data look. ``clocks``: "lab" (every topic at 200 Hz on one grid, no jitter),
    "car" (the car-log defaults: force 200 Hz ±1 ms, slip 100 Hz, torque 50 Hz ±1 ms, sump
    10 Hz, topics unaligned), "gateway" (the car's, the torque at 125 Hz stamped on arrival,
    ``GATEWAY_TORQUE_CLOCK``) or "bursts" (the car's, force and torque forwarded in bursts,
    ``BURST_CLOCKS``). ``torque_noise``: (kind, options) of the torque sensor's noise,
    σ = ``torque_noise_sigma`` (8 N·m). ``size`` / ``quick_size``: (runs diagnose sees, later runs it never sees,
    run duration s)."""

    name: str
    description: str
    klass: str
    clocks: str = "lab"
    torque_noise: tuple = ("white", {})
    torque_noise_sigma: float = 8.0
    slip_noise: tuple | None = None
    slip_noise_sigma: float = 0.05
    resolution: dict | None = None      # channel -> the step its value is logged in
    sensor_range: dict | None = None    # channel -> its sensor's range, a share of the campaign's peak
    lockup: bool = False
    slip_sign_changes: bool = False
    schedule: str = "short-runs"
    size: tuple = (6, 2, 8.0)
    quick_size: tuple = (4, 2, 8.0)
    continuous_drive: bool = False      # the runs diagnose sees are one drive cut into consecutive bags
    #                                     (car_logs.CarLogSpec.continuous_runs); the unseen runs follow after pauses
    logger_pause: bool = False          # each run diagnose sees has a logger pause (car_logs.CarLogSpec.logger_pause_runs)

    def spec_kwargs(self, quick: bool = False) -> dict:
        seen, unseen, dur = self.quick_size if quick else self.size
        kind, opts = self.torque_noise
        noise = {"measured_torque": make_noise(kind, self.torque_noise_sigma, **opts)}
        if self.slip_noise is not None:
            noise["slip_speed"] = make_noise(self.slip_noise[0], self.slip_noise_sigma, **self.slip_noise[1])
        kw = {"schedule": self.schedule, "n_runs": seen + unseen, "run_duration_s": dur,
              "noise": noise, "lockup": self.lockup, "slip_sign_changes": self.slip_sign_changes,
              "resolution": dict(self.resolution or {}), "sensor_range": dict(self.sensor_range or {}),
              "continuous_runs": seen if self.continuous_drive else 0,
              "logger_pause_runs": seen if self.logger_pause else 0}
        if self.clocks == "lab":
            kw.update(clocks=dict(LAB_CLOCKS), random_phase=False)
        elif self.clocks == "gateway":
            kw.update(clocks=dict(DEFAULT_CLOCKS, measured_torque=GATEWAY_TORQUE_CLOCK))
        elif self.clocks == "bursts":
            kw.update(clocks=dict(DEFAULT_CLOCKS, **BURST_CLOCKS))
        return kw

    def seen_runs(self, quick: bool = False) -> int:
        return (self.quick_size if quick else self.size)[0]


CONDITIONS = {c.name: c for c in (
    Condition("lab", "clean, lab-like: every topic at 200 Hz on one grid, white noise, no lock-up",
              "lab"),
    Condition("unaligned", "topics on their own clocks: force 200 Hz ±1 ms, slip 100 Hz ±0.5 ms, "
                           "torque 50 Hz ±1 ms, sump 10 Hz, random phases", "unaligned", clocks="car"),
    Condition("gateway", "topics on their own clocks, the torque sampled at 125 Hz on its sensor's clock and "
                         "stamped as its frames arrive (±2.8 ms around the instant sampled)", "unaligned",
              clocks="gateway"),
    Condition("bursts", "topics on their own clocks, force and torque sampled at 200 Hz and forwarded by a "
                        "gateway in bursts every 10-20 ms (the frames of a burst 1 µs apart)", "unaligned",
              clocks="bursts"),
    Condition("ar1", "coloured torque noise AR(1) φ 0.95, σ 8 N·m", "coloured-noise",
              torque_noise=("ar1", {"phi": 0.95})),
    Condition("lowpass", "band-limited torque noise (2nd-order 10 Hz)", "filtered-noise",
              torque_noise=("lowpass", {"cutoff_hz": 10.0})),
    Condition("held", "torque noise drawn at 10 Hz and held on the 200 Hz topic", "filtered-noise",
              torque_noise=("held", {"update_hz": 10.0})),
    Condition("median", "median-filtered torque noise (window 5)", "filtered-noise",
              torque_noise=("median", {"window": 5})),
    Condition("drift", "white torque noise plus a slow drift (OU, 4 N·m, 10 s)", "coloured-noise",
              torque_noise=("drift", {"drift": 4.0, "tau_s": 10.0})),
    Condition("slow_drift", "white torque noise plus a slow drift (OU, 5 N·m, 36 s; a sensor warming up) "
                            "over few long runs, time spans held out", "coloured-noise",
              torque_noise=("drift", {"drift": 5.0, "tau_s": 36.0}), schedule="few-long",
              size=(3, 1, 40.0), quick_size=(2, 1, 30.0)),
    Condition("lockup", "lock-up phases: slip exactly 0, the driveline sets the torque", "lockup",
              lockup=True),
    Condition("quantised", "lock-up phases, every value logged in steps: slip 0.01 rad/s (its noise "
                           "0.004 rad/s, below one step), torque 0.5 N·m, force 10 N; topics on their own clocks",
              "lockup", clocks="car", lockup=True,
              slip_noise=("white", {}), slip_noise_sigma=0.004,
              resolution={"slip_speed": 0.01, "measured_torque": 0.5, "applied_force": 10.0}),
    Condition("clipped", "lock-up phases, topics on their own clocks, the torque sensor saturating at 0.8 of "
                         "the campaign's peak torque (its reading pinned there beyond it)", "sensor-range",
              clocks="car", lockup=True, sensor_range={"measured_torque": 0.8}),
    Condition("sign_changes", "the slip changes sign while slipping (crossing 0 in ~0.1 s), topics on "
                              "their own clocks", "slip-sign", clocks="car", slip_sign_changes=True),
    Condition("long_drive", "one long drive in one bag (a later bag held out)", "one-bag",
              schedule="long-drive", size=(1, 1, 120.0), quick_size=(1, 1, 40.0)),
    Condition("few_long", "few long runs", "few-long", schedule="few-long",
              size=(3, 1, 40.0), quick_size=(2, 1, 20.0)),
    Condition("rollover", "one drive cut into consecutive bags by a recorder rolling over (no pause: the pack "
                          "temperature and every state carry across; the unseen bags after a pause), topics on "
                          "their own clocks, lock-up",
              "rollover", clocks="car", lockup=True, schedule="few-long", size=(4, 1, 30.0),
              quick_size=(3, 1, 20.0), continuous_drive=True),
    Condition("pause", "a logger pause of 1-3 s in every bag diagnose sees (every topic silent while the clutch "
                       "runs on; the unseen bags without one), topics on their own clocks, lock-up, a quiet torque sensor "
                       "(white, 1.5 N·m)", "pause",
              clocks="car", lockup=True, torque_noise_sigma=1.5, size=(4, 2, 20.0), quick_size=(3, 2, 15.0), logger_pause=True),
    Condition("car", "everything at once: unaligned topics, AR(1) φ 0.9 torque and slip noise, "
                     "lock-up, few long runs", "car", clocks="car",
              torque_noise=("ar1", {"phi": 0.9}), slip_noise=("ar1", {"phi": 0.9}), lockup=True,
              schedule="few-long", size=(3, 1, 30.0), quick_size=(2, 1, 20.0)),
)}

# ------------------------------------------------------------------------------ cases
# visible ranges on the car-log virtual test car (log-uniform draws)
MECHANISM_RANGES = {mid: cls.virtual_car.visible for mid, cls in CATALOG.items()}
DEGRADATION_DROP = (0.06, 0.2)     # friction_degradation: friction lost over the seen runs
EFFECT_RANGES = {"torque_sensor_lowpass": ("tau_s", (0.02, 0.15)),
                 "slip_power_fade": ("k_per_kw", (0.03, 0.08)),
                 "run_friction_level": ("spread", (0.06, 0.12)),
                 "torque_ripple": ("amplitude", (0.05, 0.15)),
                 "pressure_temperature_cross": ("coeff", (1.5e-3, 4e-3)),
                 "actuator_rate_limit": ("rate_n_per_s", (2.0e4, 6.0e4)),
                 "actuator_second_order": ("f_n_hz", (1.5, 4.0)),
                 "actuator_backlash": ("half_width_n", (150.0, 500.0)),
                 "force_sensor_offset": ("offset_n", (300.0, 800.0)),
                 "force_sensor_hysteresis": ("half_width_n", (150.0, 500.0)),
                 "torque_judder": ("amplitude", (0.04, 0.10)),
                 "actuator_asymmetric_lag": ("tau_release_s", (0.12, 0.3)),
                 "actuator_force_dependent_lag": ("tau_high_s", (0.12, 0.3)),
                 "actuator_oil_temperature_lag": ("tau_40_s", (0.05, 0.12)),
                 "torque_sensor_asymmetric_lag": ("tau_fall_s", (0.08, 0.25)),
                 "torque_sensor_resonance": ("f_n_hz", (4.0, 9.0)),
                 "force_sensor_lag": ("tau_s", (0.04, 0.12)),
                 "actuator_force_delay": ("delay_s", (0.015, 0.05)),
                 "actuator_force_ceiling": ("share_of_peak", (0.6, 0.8)),
                 "torque_sensor_thermal_offset": ("slope_nm_per_c", (0.3, 0.8)),
                 "torque_sensor_gain": ("gain", (0.93, 0.97)),
                 "slip_acceleration_friction": ("gain_s2_per_rad", (0.004, 0.012))}


@dataclass(frozen=True)
class Case:
    """What the true clutch hides: catalog ``mechanisms`` and ``effects`` outside the catalog."""

    name: str
    kind: str                   # none | mechanism | pair | lookalike | outside
    mechanisms: tuple = ()
    effects: tuple = ()


def _cases() -> dict:
    out = [Case("none", "none")]
    out += [Case(m, "mechanism", mechanisms=(m,)) for m in CATALOG]
    out += [Case(f"{a}+{b}", "pair", mechanisms=(a, b)) for a, b in
            (("spring_preload", "torque_offset"), ("actuator_lag", "friction_degradation"),
             ("transport_delay", "drag_torque"), ("actuator_lag", "transport_delay"),
             ("torque_offset", "friction_degradation"))]
    out += [Case(e, "lookalike" if EFFECTS[e]["mimics"] else "outside", effects=(e,))
            for e in ("torque_sensor_lowpass", "slip_power_fade", "run_friction_level",
                      "torque_ripple", "pressure_temperature_cross", "actuator_rate_limit",
                      "actuator_second_order", "actuator_backlash", "force_sensor_offset",
                      "actuator_asymmetric_lag", "actuator_force_dependent_lag",
                      "torque_sensor_asymmetric_lag", "slip_acceleration_friction",
                      "force_sensor_hysteresis", "torque_judder", "torque_sensor_resonance",
                      "force_sensor_lag", "actuator_force_delay", "actuator_force_ceiling",
                      "torque_sensor_thermal_offset", "actuator_oil_temperature_lag")]
    # the torque sensor's scale a few per cent off: the calibration's, nothing to name
    out += [Case("torque_sensor_gain", "none", effects=("torque_sensor_gain",))]
    return {c.name: c for c in out}


CASES = _cases()


def _stable(*parts) -> int:
    return zlib.crc32("/".join(map(str, parts)).encode())


def draw_magnitudes(case: Case, seed: int, magnitude_seed: int) -> dict:
    """{cause: value}, log-uniform over its visible range, from ``magnitude_seed`` (never given
    to the diagnosis) and the cell. friction_degradation: the friction drop over the seen runs."""
    rng = np.random.default_rng([int(magnitude_seed), _stable(case.name), int(seed)])

    def logu(lo, hi):
        return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))

    out = {}
    for m in case.mechanisms:
        rr = DEGRADATION_DROP if m == "friction_degradation" else MECHANISM_RANGES[m]
        out[m] = logu(*rr)
    for e in case.effects:
        out[e] = logu(*EFFECT_RANGES[e][1])
    return out


def _mechanism_entry(mid: str, value: float) -> dict:
    return {"id": mid, CATALOG[mid].magnitude_parameter(): float(value)}


def seen_energy_j(spec: CarLogSpec, n_seen: int) -> float:
    """Energy dissipated over the first ``n_seen`` runs by the campaign's twin without any
    mechanism or effect (same seed, same drive)."""
    twin = CarLogSpec(**{**_spec_fields(spec), "mechanisms": [], "effects": []})
    res = synthesize_car_logs(twin)
    e = 0.0
    for run in res.runs[:n_seen]:
        f = run.fine
        e += float(np.sum(np.abs(f["torque_nm"] * f["slip_speed_rad_s"]))) / spec.fine_rate_hz
    return e


def _spec_fields(spec: CarLogSpec) -> dict:
    from dataclasses import fields
    return {f.name: getattr(spec, f.name) for f in fields(spec)}


def build_spec(case: Case, condition: Condition, seed: int, magnitudes: dict, quick: bool = False) -> CarLogSpec:
    kw = condition.spec_kwargs(quick)
    spec = CarLogSpec(seed=int(seed), **kw)
    mechs = []
    for m in case.mechanisms:
        if m == "friction_degradation":
            e = seen_energy_j(spec, condition.seen_runs(quick))
            mechs.append(_mechanism_entry(m, e / -math.log(1.0 - magnitudes[m])))
        else:
            mechs.append(_mechanism_entry(m, magnitudes[m]))
    effects = [{"name": e, EFFECT_RANGES[e][0]: magnitudes[e]} for e in case.effects]
    return CarLogSpec(seed=int(seed), mechanisms=mechs, effects=effects, **kw)


# ------------------------------------------------------------------ campaign on disk
@dataclass
class HiddenCampaign:
    case: Case
    condition: Condition
    seed: int
    magnitudes: dict
    spec: CarLogSpec
    root: Path
    seen_bags: list
    unseen_bags: list
    expected_causes: list          # catalog ids a right diagnosis names (set)
    expected_verdict: str          # none | unexplained | the first expected cause
    synth_s: float = 0.0

    @property
    def expected_label(self) -> str:
        if self.expected_verdict in ("none", "unexplained"):
            return self.expected_verdict
        return "+".join(sorted(self.expected_causes))

    @property
    def truth_dir(self) -> Path:
        return self.root / "truth"

    @property
    def bench_csv(self) -> Path:
        return self.root / "bench.csv"


def make_hidden_campaign(case, condition, seed: int, out_dir, magnitude_seed: int = 20261123,
                         quick: bool = False, magnitudes: dict | None = None) -> HiddenCampaign:
    """Write the cell's campaign to ``out_dir`` (bags/, bench.csv, truth.json, truth/)."""
    case = CASES[case] if isinstance(case, str) else case
    condition = CONDITIONS[condition] if isinstance(condition, str) else condition
    t0 = time.perf_counter()
    mags = dict(magnitudes) if magnitudes is not None else draw_magnitudes(case, seed, magnitude_seed)
    spec = build_spec(case, condition, seed, mags, quick)
    res = synthesize_car_logs(spec)
    out_dir = Path(out_dir)
    paths = write_car_logs(res, out_dir)
    bags = [str(p) for p in paths["bags"]]
    n_seen = condition.seen_runs(quick)
    unexplained = res.truth["expected_cause"] == "unexplained"
    return HiddenCampaign(case=case, condition=condition, seed=int(seed), magnitudes=mags, spec=spec,
                          root=out_dir, seen_bags=bags[:n_seen], unseen_bags=bags[n_seen:],
                          expected_causes=[] if unexplained else list(res.truth["expected_causes"]),
                          expected_verdict=res.truth["expected_cause"],
                          synth_s=time.perf_counter() - t0)


# ------------------------------------------------------------------ reading a report
def named_causes(report: dict) -> tuple:
    """(verdict, [named catalog ids]) from report.json: ``causes`` when the report has it,
    else ``cause`` (one cause, the report format before several causes)."""
    cause = report.get("cause") or {}
    verdict = str(cause.get("id", "error"))
    if "causes" in report and report["causes"] is not None:
        ids = [str(c.get("id")) for c in report["causes"] if str(c.get("id")) not in VERDICTS_WITHOUT_CAUSE]
    else:
        ids = [] if verdict in VERDICTS_WITHOUT_CAUSE else [verdict]
    return verdict, ids


def named_label(verdict: str, ids: list) -> str:
    return "+".join(sorted(ids)) if ids else verdict


def judge(expected_verdict: str, expected_causes: list, verdict: str, ids: list) -> str:
    """ok | wrong (a catalog name that is not there, or a cause where there is none) |
    partial (some of the causes, nothing wrong) | missed (none / unexplained where a cause
    is) | false-alarm (unexplained where there is nothing) | refused (diagnose failed)."""
    if verdict in ("refused", "error", "timeout"):
        return "refused"
    named, want = set(ids), set(expected_causes)
    if named - want:
        return "wrong"
    if want:
        if named == want:
            return "ok"
        return "partial" if named else "missed"
    if expected_verdict == "none":
        return "ok" if verdict == "none" else "false-alarm"
    # effect outside the catalog: unexplained (or a validated discovered extension)
    return "ok" if verdict in ("unexplained", "discovered") else "missed"


# ------------------------------------------------------------------------ the CLI
def clutch_sim_command() -> list:
    """How a user starts clutch-sim from this interpreter's environment."""
    exe = Path(sys.executable).with_name("clutch-sim")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "clutch_sim.cli"]


def run_clutch_sim(args: list, timeout_s: float | None = None) -> tuple:
    """Run ``clutch-sim ARGS`` as a subprocess. Returns (returncode, stderr tail, wall s,
    cpu s of the child). returncode None on timeout."""
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    try:
        p = subprocess.run(clutch_sim_command() + [str(a) for a in args], capture_output=True,
                           text=True, timeout=timeout_s, env=os.environ.copy())
        rc, err = p.returncode, (p.stderr or "").strip()
    except subprocess.TimeoutExpired as exc:
        rc, err = None, f"timed out after {timeout_s} s: {(exc.stderr or b'')[-300:]!r}"
    wall = time.perf_counter() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    return rc, err[-600:], wall, cpu


def score_replay_csv(csv_path, truth_dir, bags: set, lock_pad_s: float = 0.1, tail_s: float = 0.0) -> dict:
    """RMSE of a replay CSV's ``torque_sim`` against the noise-free true torque
    (``true_sensor_torque_at``) on the rows of ``bags``, rows within ``lock_pad_s`` of a true
    lock phase, or ``tail_s`` after it, left out (the driveline sets the sensor's reading there:
    ``car_logs.near_true_lock``, ``car_logs.measurement_tail_s``)."""
    rows = {}
    with open(csv_path, newline="") as fh:
        for r in csv.DictReader(fh):
            if r["bag"] in bags:
                rows.setdefault(r["bag"], []).append((float(r["t"]), float(r["torque_sim"])))
    sq, n, per = 0.0, 0, {}
    for bag, vals in rows.items():
        t, sim = np.array(vals).T
        side = load_truth_sidecar(Path(truth_dir) / f"{bag}.npz")
        truth = true_sensor_torque_at(side, t)
        near = near_true_lock(side, t, lock_pad_s, tail_s)
        ok = np.isfinite(truth) & np.isfinite(sim) & ~near
        err = sim[ok] - truth[ok]
        per[bag] = float(np.sqrt(np.mean(err ** 2))) if err.size else float("nan")
        sq += float(np.sum(err ** 2))
        n += int(err.size)
    return {"rmse_nm": float(np.sqrt(sq / n)) if n else float("nan"), "runs": per, "samples": n}


def _gain(cal: float, ext: float) -> float:
    return 100.0 * (cal - ext) / cal if cal and math.isfinite(cal) and math.isfinite(ext) else float("nan")


@dataclass
class CheckResult:
    """What ``check_campaign`` found (``to_dict`` for JSON)."""

    cell: str
    case: str
    condition: str
    condition_class: str
    seed: int
    magnitudes: dict
    expected: str
    expected_causes: list
    hidden: dict = field(default_factory=dict)             # the true mechanisms / effects
    verdict: str = "error"
    named: list = field(default_factory=list)
    judgement: str = "refused"
    report: dict | None = None
    error: str = ""
    diagnose_gain_pct: float = float("nan")
    replay_rmse_nm: dict = field(default_factory=dict)      # calibrated / extended, unseen bags
    stamps_rmse_nm: dict = field(default_factory=dict)      # score_against_truth, unseen bags
    held_out_gain_pct: float = float("nan")                 # replay-based, vs the true torque
    stamps_gain_pct: float = float("nan")
    wall_s: dict = field(default_factory=dict)
    cpu_s: dict = field(default_factory=dict)

    @property
    def named_label(self) -> str:
        return named_label(self.verdict, self.named)

    @property
    def gain_holds(self) -> bool | None:
        """Where a cause is named, or an extension beyond the catalog is claimed (`discovered`),
        the extended model beats the calibrated one on unseen runs against the true torque;
        None when nothing is named."""
        if not self.named and self.verdict != "discovered":
            return None
        return bool(self.held_out_gain_pct > 0.0)

    @property
    def passed(self) -> bool:
        return self.judgement == "ok" and self.gain_holds is not False

    def to_dict(self) -> dict:
        d = {k: v for k, v in self.__dict__.items() if k != "report"}
        d.update(named_label=self.named_label, gain_holds=self.gain_holds, passed=self.passed)
        if self.report:
            d["report"] = {k: self.report.get(k) for k in ("cause", "causes", "rmse_nm", "gain_pct",
                                                           "held_out_runs", "noise_sigma_nm")}
        return d


def unseen_stamps_rmse_nm(camp: HiddenCampaign, model_path, runs=None) -> float:
    """RMSE (N*m) of the model at ``model_path`` against the true torque of ``camp``'s unseen
    bags, at the torque stamps (car_logs.score_against_truth; lock phases and the measurement
    tail left out), pooled over those bags' samples. ``runs``: read_bags of the seen and unseen
    bags, when already read."""
    from clutch_model.formats.bag_reader import read_bags
    from clutch_model.plant.params import load_model

    if runs is None:
        runs = read_bags(camp.seen_bags + camp.unseen_bags)
    sc = score_against_truth(load_model(model_path), runs, camp.truth_dir, tail_s=measurement_tail_s(camp.spec))
    n = sc["run_samples"]
    use = [r for r in (Path(b).name for b in camp.unseen_bags) if n.get(r, 0) > 0]
    sq = sum(sc["runs"][r] ** 2 * n[r] for r in use)
    return math.sqrt(sq / sum(n[r] for r in use)) if use else float("nan")


def check_campaign(camp: HiddenCampaign, work_dir=None, mc_samples: int | None = None,
                   timeout_s: float | None = None, stamps: bool = True, plots: bool = False) -> CheckResult:
    """``clutch-sim diagnose`` on the seen bags, then both models replayed on every bag and
    scored on the unseen ones against the true torque (see the module docstring). ``plots``:
    let diagnose draw its figures (``--no-plots`` otherwise: they are not scored)."""
    work = Path(work_dir) if work_dir is not None else camp.root
    res = CheckResult(cell=f"{camp.case.name}@{camp.condition.name}#{camp.seed}", case=camp.case.name,
                      condition=camp.condition.name, condition_class=camp.condition.klass, seed=camp.seed,
                      magnitudes=camp.magnitudes, expected=camp.expected_label,
                      expected_causes=list(camp.expected_causes),
                      hidden={"mechanisms": camp.spec.mechanisms, "effects": camp.spec.effects})
    res.wall_s["synth"] = camp.synth_s
    diag = work / "diag"
    args = ["diagnose", "--bench", camp.bench_csv, "--bags", *camp.seen_bags, "--out", diag]
    if not plots:
        args.append("--no-plots")
    if mc_samples is not None:
        args += ["--mc-samples", int(mc_samples)]
    rc, err, wall, cpu = run_clutch_sim(args, timeout_s)
    res.wall_s["diagnose"], res.cpu_s["diagnose"] = wall, cpu
    if rc != 0:
        res.verdict = "timeout" if rc is None else "refused"
        res.error = err.splitlines()[-1] if err else f"exit {rc}"
        return res
    try:
        report = json.loads((diag / "report.json").read_text())
    except (OSError, ValueError) as exc:
        res.verdict, res.error = "error", f"report.json: {exc}"
        return res
    res.report = report
    res.verdict, res.named = named_causes(report)
    res.judgement = judge(camp.expected_verdict, camp.expected_causes, res.verdict, res.named)
    res.diagnose_gain_pct = float(report.get("gain_pct", float("nan")))
    unseen = {Path(b).name for b in camp.unseen_bags}
    t0 = time.perf_counter()
    cpu = 0.0
    for label, name in (("calibrated", "calibrated_model.yaml"), ("extended", "extended_model.yaml")):
        out_csv = work / f"replay_{label}.csv"
        rc, err, _, c = run_clutch_sim(["replay", "--bag", *camp.seen_bags, *camp.unseen_bags,
                                        "--params", diag / name, "--out", out_csv], timeout_s)
        cpu += c
        if rc != 0:
            res.error = f"replay {name}: {err.splitlines()[-1] if err else rc}"
            continue
        res.replay_rmse_nm[label] = score_replay_csv(out_csv, camp.truth_dir, unseen,
                                                     tail_s=measurement_tail_s(camp.spec))["rmse_nm"]
    res.wall_s["replay"], res.cpu_s["replay"] = time.perf_counter() - t0, cpu
    if len(res.replay_rmse_nm) == 2:
        res.held_out_gain_pct = _gain(res.replay_rmse_nm["calibrated"], res.replay_rmse_nm["extended"])
    if stamps:
        from clutch_model.formats.bag_reader import read_bags

        t0, c0 = time.perf_counter(), time.process_time()
        runs = read_bags(camp.seen_bags + camp.unseen_bags)
        for label, name in (("calibrated", "calibrated_model.yaml"), ("extended", "extended_model.yaml")):
            res.stamps_rmse_nm[label] = unseen_stamps_rmse_nm(camp, diag / name, runs)
        res.stamps_gain_pct = _gain(res.stamps_rmse_nm["calibrated"], res.stamps_rmse_nm["extended"])
        res.wall_s["stamps"], res.cpu_s["stamps"] = time.perf_counter() - t0, time.process_time() - c0
    return res


def run_cell(case: str, condition: str, seed: int, work_dir, magnitude_seed: int = 20261123,
             quick: bool = False, mc_samples: int | None = None, timeout_s: float | None = None,
             keep: bool = False, stamps: bool = True) -> CheckResult:
    """Make the cell's campaign under ``work_dir``, check it, tidy up (unless ``keep``)."""
    work = Path(work_dir)
    c0 = time.process_time()
    camp = make_hidden_campaign(case, condition, seed, work / "campaign", magnitude_seed, quick)
    synth_cpu = time.process_time() - c0
    try:
        res = check_campaign(camp, work, mc_samples=mc_samples, timeout_s=timeout_s, stamps=stamps)
    finally:
        if not keep:
            shutil.rmtree(work, ignore_errors=True)
    res.cpu_s["synth"] = synth_cpu
    return res
