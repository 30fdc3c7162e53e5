"""Synthetic data with known truth for parameter-recovery tests and benchmarks: SAE#2-style
bench rows from known friction coefficients, car-test runs simulated with a known model,
viscosity samples. (The full virtual test car with faults is clutch_model.virtual_car.campaign.)
"""
from __future__ import annotations

import numpy as np

from clutch_model.plant.friction import friction_grid
from clutch_model.plant.params import ClutchModel
from clutch_model.formats.bag_reader import Campaign, Run
from clutch_model.plant.simulate import predict_measured_torque, simulate
from clutch_model.formats.bench_csv import BenchData

BENCH_SLIPS = (0.0005, 0.002, 0.005, 0.01, 0.02, 0.035, 0.06, 0.1, 0.2, 0.4, 0.8, 1.5, 3.0, 6.0, 12.0, 25.0)
BENCH_PRESSURES = (0.5, 1.0, 2.0, 3.5, 5.0, 7.5, 10.0, 13.0, 16.5, 20.0)
BENCH_SUMPS = (20.0, 50.0, 80.0, 110.0, 140.0)


def synthetic_bench(model: ClutchModel, *, slips=BENCH_SLIPS, pressures=BENCH_PRESSURES, sumps=BENCH_SUMPS,
                    noise: float = 0.002, seed: int = 0) -> BenchData:
    """Bench rows (slip level x sump x pressure step), the plate hotter than the sump with the
    dissipated power, mu from the model's friction polynomials plus Gaussian noise."""
    rng = np.random.default_rng(seed)
    W, S, Pm = np.meshgrid(np.asarray(slips, float), np.asarray(sumps, float), np.asarray(pressures, float),
                           indexing="ij")
    W, S, Pm = W.ravel(), S.ravel(), Pm.ravel()
    plate = np.clip(S + 4.0 * Pm * np.sqrt(W) + rng.normal(0, 1.0, W.size), 0.0, 230.0)
    mu = friction_grid(model.friction_coefficients, model.friction_exponent, W, Pm, plate) + rng.normal(0.0, noise, W.size)
    return BenchData(slip_speed_rad_s=W, pressure_mpa=Pm, plate_temperature_c=plate,
                     sump_temperature_c=S, friction_coefficient=mu, source="synthetic")


def run_inputs(rng, duration_s=9.0, rate_hz=200.0, force_range=(2000.0, 25000.0), slip_range=(0.5, 5.0),
               sump_range=(40.0, 90.0), n_steps=4):
    """One car-test run's inputs: constant-ish slip and sump, n_steps torque requests (force
    steps through a 40 ms actuator lag) separated by open-clutch gaps."""
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    seg = duration_s / n_steps
    levels = rng.uniform(*force_range, n_steps)
    target = np.zeros_like(t)
    for k, lvl in enumerate(levels):
        on = (t >= k * seg + 0.15 * seg) & (t < (k + 1) * seg - 0.1 * seg)
        target[on] = lvl
    force = np.empty_like(t)
    f = 0.0
    alpha = 1.0 - np.exp(-1.0 / (rate_hz * 0.04))
    for k in range(t.size):
        f += alpha * (target[k] - f)
        force[k] = f
    w0 = rng.uniform(*slip_range)
    slip = w0 * (1.0 + 0.2 * np.sin(2 * np.pi * t / rng.uniform(2.0, 5.0) + rng.uniform(0, 6.28)))
    sump = np.full_like(t, rng.uniform(*sump_range)) + 0.05 * t
    return t, force, slip, sump


def synthetic_runs(model: ClutchModel, n_runs: int = 6, duration_s: float = 9.0, rate_hz: float = 200.0,
                   noise_nm: float = 15.0, pack_noise_c: float | None = None, seed: int = 0,
                   name_prefix: str = "run", **input_kw) -> list:
    """Car-test runs simulated with ``model`` (the truth) plus sensor noise. With
    ``pack_noise_c`` the runs also carry a measured pack temperature."""
    rng = np.random.default_rng(seed)
    runs = []
    for j in range(n_runs):
        t, force, slip, sump = run_inputs(rng, duration_s, rate_hz, **input_kw)
        runs.append(Run(name=f"{name_prefix}{j:02d}", t=t, applied_force_n=force, slip_speed_rad_s=slip,
                        sump_temperature_c=sump, start_time_ns=(j + 1) * 10 ** 12))
    camp = Campaign(runs)
    sim = simulate(model, camp.t, camp.force, camp.slip, camp.sump, run_start=camp.run_start)
    torque = predict_measured_torque(model, camp.t, sim.torque_nm, camp.run_start)
    torque = torque + rng.normal(0.0, noise_nm, torque.size)
    pack = None
    if pack_noise_c is not None:
        pack = sim.pack_temperature_c + rng.normal(0.0, pack_noise_c, torque.size)
    for r, sl in camp.slices():
        r.torque_measured_nm = torque[sl].copy()
        if pack is not None:
            r.pack_temperature_measured_c = pack[sl].copy()
    return camp.runs


def synthetic_viscosity(model: ClutchModel, noise_rel: float = 0.01, seed: int = 0, n: int = 40):
    """(pack_temperature_c, viscosity_pa_s) samples of eq. 3.17 with relative noise."""
    rng = np.random.default_rng(seed)
    th = np.linspace(20.0, 150.0, n)
    a0, a1 = float(model.data["viscosity"]["alpha0"]), float(model.data["viscosity"]["alpha1"])
    mu = a0 * th ** (-a1) * (1.0 + rng.normal(0.0, noise_rel, n))
    return th, mu


def perturbed_friction(model: ClutchModel, rel: dict) -> ClutchModel:
    """The model with friction coefficients a_k scaled by (1 + rel[k])."""
    a = model.friction_coefficients.copy()
    for k, v in rel.items():
        a[int(k)] *= 1.0 + float(v)
    return model.with_friction(a=a)


def write_runs_as_bags(runs, outdir, storage: str = "mcap") -> list:
    """Write runs as rosbag2 bags (one per run, every channel sampled on the run's grid), in
    log-time order; returns the bag paths."""
    from pathlib import Path

    from clutch_model.formats.bag_writer import DEFAULT_START_TIME_NS, write_run_bag

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for j, r in enumerate(runs):
        sig = {"applied_force": (r.t, r.applied_force_n), "slip_speed": (r.t, r.slip_speed_rad_s),
               "sump_temperature": (r.t, r.sump_temperature_c)}
        if r.torque_measured_nm is not None:
            sig["measured_torque"] = (r.t, r.torque_measured_nm)
        if r.pack_temperature_measured_c is not None:
            sig["pack_temperature"] = (r.t, r.pack_temperature_measured_c)
        paths.append(write_run_bag(out / r.name, sig, storage=storage,
                                   start_time_ns=DEFAULT_START_TIME_NS + j * 3_600 * 10 ** 9))
    return paths
