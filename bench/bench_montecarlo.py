"""Benchmark of the Monte Carlo refit and comparison with gradient-based calibration.

1. Throughput: Monte Carlo samples per second on 2 minutes of 200 Hz car data (8 runs x 15 s),
   serial (numba prange over the chunk's samples) and on a Dask LocalCluster (2 workers x 1
   thread), the two results checked equal; extrapolated time of the thesis campaign
   (300,000 samples x 20 s simulated each; target <= 20 min on 2 cores, i.e. >= 5,000 simulated
   seconds per wall second).
2. calibrate_friction wall time on 6 runs x 9 s x 200 Hz (the diagnosis engine's budget: < 10 s).
3. Gradient (least_squares) vs Monte Carlo on the same data and the same budget of model
   evaluations: held-out RMSE, coefficient errors against the known truth, and the parameter
   uncertainty each implies (LS: covariance s^2 (J'J)^-1; MC: spread of the better samples).

Usage: python bench/bench_montecarlo.py [--samples 2048] [--no-dask] [--json OUT.json]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

THESIS_SAMPLES, THESIS_SECONDS = 300_000, 20.0
TRUTH_REL = {0: -0.05, 1: 0.10, 3: 0.12, 15: 0.25}


def load_avg() -> str:
    try:
        return Path("/proc/loadavg").read_text().split()[0]
    except OSError:
        return "n/a"


def throughput(model, truth, n_samples, use_dask):
    from clutch_model.virtual_car import identification_data as td
    from clutch_model.identification.montecarlo import run_montecarlo

    runs = td.synthetic_runs(truth, n_runs=8, duration_s=15.0, rate_hz=200.0, noise_nm=15.0, seed=101)
    kw = dict(n_samples=n_samples, spread=0.05, seed=1, chunk_size=256, progress=False, halving=())
    run_montecarlo(model, runs[:1], n_samples=8, spread=0.05, seed=0, progress=False, halving=())  # warm numba
    out = {}
    serial = run_montecarlo(model, runs, **kw)
    sim_s = serial.simulated_seconds_per_sample
    out["data"] = {"runs": len(runs), "simulated_s_per_sample": sim_s, "rate_hz": 200.0}
    out["serial"] = {"accepted": serial.n_evaluated, "elapsed_s": serial.elapsed_s,
                     "samples_per_s": serial.samples_per_s, "sim_s_per_s": serial.samples_per_s * sim_s}
    print(f"[1] Monte Carlo throughput on {sim_s:.0f} s of 200 Hz car data ({len(runs)} runs), "
          f"{serial.n_evaluated} accepted samples of {n_samples}, chunks of 256 (load avg {load_avg()})")
    print(f"    serial (numba prange):        {serial.samples_per_s:7.1f} samples/s  "
          f"{serial.samples_per_s * sim_s:8.0f} simulated s / s   ({serial.elapsed_s:.1f} s)")
    best = serial.samples_per_s * sim_s
    if use_dask:
        d = run_montecarlo(model, runs, scheduler="local", **kw)
        steady = d.n_evaluated / max(d.elapsed_s - d.startup_s, 1e-9)
        equal = bool(np.array_equal(serial.rmse, d.rmse, equal_nan=True))
        out["dask_local"] = {"elapsed_s": d.elapsed_s, "startup_s": d.startup_s, "samples_per_s": d.samples_per_s,
                             "samples_per_s_after_startup": steady, "sim_s_per_s": d.samples_per_s * sim_s,
                             "sim_s_per_s_after_startup": steady * sim_s, "equal_to_serial": equal}
        print(f"    Dask LocalCluster 2x1:        {d.samples_per_s:7.1f} samples/s  "
              f"{d.samples_per_s * sim_s:8.0f} simulated s / s   ({d.elapsed_s:.1f} s incl. "
              f"{d.startup_s:.1f} s cluster start-up; {steady * sim_s:.0f} sim s/s after it)")
        print(f"    Dask result equals serial:    {equal}")
        best = max(best, steady * sim_s)
    total = THESIS_SAMPLES * THESIS_SECONDS
    t_serial = total / (serial.samples_per_s * sim_s)
    out["thesis_campaign"] = {"samples": THESIS_SAMPLES, "seconds_each": THESIS_SECONDS,
                              "serial_min": t_serial / 60, "best_min": total / best / 60,
                              "target_min": 20.0, "target_sim_s_per_s": 5000.0}
    print(f"    thesis campaign ({THESIS_SAMPLES:,} samples x {THESIS_SECONDS:g} s): serial {t_serial / 60:.1f} min, "
          f"best {total / best / 60:.1f} min (target <= 20 min = >= 5,000 sim s/s; thesis: ~2 weeks on 16 cores)")
    return out


def calibrate_timing(model, truth):
    from clutch_model.virtual_car import identification_data as td
    from clutch_model.identification.calibrate import calibrate_friction

    runs = td.synthetic_runs(truth, n_runs=6, duration_s=9.0, rate_hz=200.0, noise_nm=15.0, seed=7)
    calibrate_friction(model, runs[:1], coefficients=[0], max_iterations=2)  # warm
    t0 = time.perf_counter()
    res = calibrate_friction(model, runs)
    dt = time.perf_counter() - t0
    print(f"[2] calibrate_friction on 6 runs x 9 s x 200 Hz: {dt:.2f} s (target < 10 s), "
          f"{res.n_evaluations} model evaluations, RMSE {res.rmse_before:.1f} -> {res.rmse_after:.2f} N*m")
    return {"elapsed_s": dt, "n_evaluations": res.n_evaluations, "rmse_before": res.rmse_before,
            "rmse_after": res.rmse_after}


def compare(model, truth):
    from clutch_model.virtual_car import identification_data as td
    from clutch_model.identification.calibrate import calibrate_friction
    from clutch_model.identification.evaluate import CampaignInputs, rmse_of
    from clutch_model.identification.montecarlo import run_montecarlo

    runs = td.synthetic_runs(truth, n_runs=8, duration_s=9.0, rate_hz=200.0, noise_nm=15.0, seed=11)
    fit, held = runs[:6], runs[6:]
    hin = CampaignInputs.from_campaign(held, model)
    a_true = truth.friction_coefficients

    def held_rmse(a):
        return float(rmse_of(model.vector(), np.asarray(a)[None, :], hin)[0])

    noise = held_rmse(a_true)
    t0 = time.perf_counter()
    ls = calibrate_friction(model, fit)
    t_ls = time.perf_counter() - t0
    budget = ls.n_evaluations
    rows = [{"method": "nominal (bench fit)", "evaluations": 0, "wall_s": 0.0,
             "held_out_rmse": held_rmse(model.friction_coefficients), "a": model.friction_coefficients}]
    rows.append({"method": "least_squares (screened)", "evaluations": budget, "wall_s": t_ls,
                 "held_out_rmse": held_rmse(ls.a_after), "a": ls.a_after})
    mcs = {}
    for spread in (0.05, 0.2):
        for mult in (1, 10):
            n = budget * mult
            t0 = time.perf_counter()
            mc = run_montecarlo(model, fit, n_samples=n, spread=spread, seed=3, progress=False)
            wall = time.perf_counter() - t0
            ev = mc.n_evaluated + sum(h["evaluations"] for h in mc.halving) + 2
            key = f"monte carlo +-{spread:g} x{mult}"
            mcs[key] = mc
            rows.append({"method": key, "evaluations": ev, "wall_s": wall, "held_out_rmse": held_rmse(mc.refined_a),
                         "a": mc.refined_a})
    print(f"[3] gradient vs Monte Carlo, fit on 6 runs x 9 s, held out 2 runs; truth = RC-1 with "
          f"{', '.join(f'a{k} {v:+.0%}' for k, v in TRUTH_REL.items())}; noise floor (truth) {noise:.2f} N*m")
    print(f"    {'method':28s} {'evals':>6s} {'wall s':>7s} {'held-out RMSE':>14s}   "
          + "  ".join(f"err a{k:<2d}" for k in TRUTH_REL))
    for r in rows:
        errs = "  ".join(f"{(r['a'][k] - a_true[k]) / abs(a_true[k]):+7.1%}" for k in TRUTH_REL)
        print(f"    {r['method']:28s} {r['evaluations']:6d} {r['wall_s']:7.2f} {r['held_out_rmse']:14.2f}   {errs}")
    print("    uncertainty implied (1 sigma, relative):")
    for k in ls.coefficients_moved:
        mc = mcs["monte carlo +-0.2 x10"]
        b = mc.better
        sd = float(np.std(mc.samples[b, k])) if b.any() else float("nan")
        print(f"      a{k:<2d} least_squares s^2(J'J)^-1: {ls.stderr[k] / abs(ls.a_after[k]):6.2%}   actual error "
              f"{(ls.a_after[k] - a_true[k]) / abs(a_true[k]):+7.2%}   | MC +-20% x10 spread of the better samples "
              f"{sd / abs(a_true[k]):6.2%}")
    return {"noise_floor_rmse": noise, "budget": budget,
            "rows": [{k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in r.items()} for r in rows],
            "ls_stderr_rel": {f"a{k}": float(ls.stderr[k] / abs(ls.a_after[k])) for k in ls.coefficients_moved}}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=2048, help="Monte Carlo samples of the throughput run")
    ap.add_argument("--no-dask", action="store_true")
    ap.add_argument("--json", default=None, metavar="PATH")
    args = ap.parse_args()
    from clutch_model import load_model
    from clutch_model.virtual_car import identification_data as td

    model = load_model()
    truth = td.perturbed_friction(model, TRUTH_REL)
    res = {"cpu_count": os.cpu_count(), "load_avg_start": load_avg()}
    res["throughput"] = throughput(model, truth, args.samples, not args.no_dask)
    res["calibrate"] = calibrate_timing(model, truth)
    res["comparison"] = compare(model, truth)
    res["load_avg_end"] = load_avg()
    print(f"(load average at start {res['load_avg_start']}, at end {res['load_avg_end']}; {os.cpu_count()} CPUs)")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
