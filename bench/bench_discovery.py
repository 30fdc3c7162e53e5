"""Discovery beyond the catalog: discovery rate and false-discovery rate over seeds.

Each case is a campaign of the virtual test car (9 runs of 7 s at 200 Hz, coloured torque
noise: white 6 N·m + Ornstein-Uhlenbeck 5 N·m with τ 0.3 s) whose true clutch carries an
effect outside the catalog with a magnitude drawn from the seed, or none:

  none          no effect
  run_level     each run's torque level scaled by 1 + N(0, s), s drawn in 2-5 % (structure that
                nothing in the inputs predicts)
  slip_power    μ_f × (1 + c·P_slip[kW]), c in −(1-4) %/kW
  p_x_theta     μ_f × (1 + c·P[MPa]·(θ_pack − 60 °C)), c in 1e-3-4e-3
  ripple        μ_f × (1 + A·sin(φ + φ0)), φ the slip angle, A in 3-12 %, φ0 random
  vc_p_x_theta  the virtual car's own pressure_temperature_cross (an independent implementation
                of the P·θ term), c in 1e-3-4e-3
  random_ripple the virtual car's torque_ripple, A in 3-15 %: once per revolution but its phase
                redrawn every run, so nothing predicts it on an unseen run (a null case)

The calibrated model is made as the diagnosis makes it (bench fit + friction correction on
the fit runs); ``discover`` gets the campaign, that model and the held-out runs.
Printed per case: accepted, terms found, coefficient vs truth, held-out gain, and the gap to
the true model closed on the held-out runs (RMSE against the noise-free torque, calibrated vs
extended). Discovery rate = effect cases accepted with exactly the true term(s);
false-discovery rate = none/run_level cases with any term accepted.

    python bench/bench_discovery.py [--seeds N] [--first-seed S]
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_CACHE_DIR", str(Path(__file__).resolve().parents[1] / ".numba_cache"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

CASES = ["none", "run_level", "random_ripple", "slip_power", "p_x_theta", "vc_p_x_theta", "ripple"]
NULL_CASES = ("none", "run_level", "random_ripple")


def truth_for(case: str, seed: int):
    """(true terms, run-level spread) of a case, magnitudes from the seed."""
    rng = np.random.default_rng([seed, CASES.index(case), 99])
    lu = lambda lo, hi: float(np.exp(rng.uniform(np.log(lo), np.log(hi))))  # noqa: E731
    if case == "none":
        return {}, 0.0
    if case == "run_level":
        return {}, lu(0.02, 0.05)
    if case == "slip_power":
        return {"mu:slip_power": -lu(0.01, 0.04)}, 0.0
    if case == "p_x_theta":
        return {"mu:pressure*pack_temperature": lu(1e-3, 4e-3)}, 0.0
    if case == "vc_p_x_theta":
        return {"mu:pressure*pack_temperature": lu(1e-3, 4e-3)}, 0.0
    if case == "random_ripple":
        return {}, lu(0.03, 0.15)
    if case == "ripple":
        a, ph = lu(0.03, 0.12), float(rng.uniform(0, 2 * np.pi))
        return {"mu:sin_slip_angle": a * math.cos(ph), "mu:cos_slip_angle": a * math.sin(ph)}, 0.0
    raise KeyError(case)


def run_case(case: str, seed: int) -> dict:
    from clutch_model.discovery import discover
    from clutch_model.discovery.synthetic import make_case

    terms, mag = truth_for(case, seed)
    if case == "vc_p_x_theta":
        tc = make_case(seed, extra_effect="pressure_temperature_cross", extra_magnitude=terms[next(iter(terms))])
    elif case == "random_ripple":
        tc = make_case(seed, extra_effect="torque_ripple", extra_magnitude=mag)
    else:
        tc = make_case(seed, terms, run_level_spread=mag)
    t0 = time.perf_counter()
    res = discover(tc.campaign, tc.calibrated_model, tc.held_out, friction_anchor=tc.bench_model)
    elapsed = time.perf_counter() - t0
    eval_mask = np.isin(tc.campaign.run_index, [tc.campaign.names.index(n) for n in tc.held_out])
    meas = tc.campaign.torque_measured
    ok = eval_mask & np.isfinite(res.base_residual)
    pred_cal = meas - res.base_residual
    pred_ext = meas - (res.residual if res.accepted else res.base_residual)
    ok &= np.isfinite(pred_ext)
    gap_cal = float(np.sqrt(np.mean((pred_cal[ok] - tc.noise_free_torque[ok]) ** 2)))
    gap_ext = float(np.sqrt(np.mean((pred_ext[ok] - tc.noise_free_torque[ok]) ** 2)))
    found = res.parameters if res.accepted else {}
    right = res.accepted and set(found) == set(terms)
    if terms and right:
        truth = np.array([terms[k] for k in sorted(terms)])
        est = np.array([found[k] for k in sorted(terms)])
        rel_err = float(np.linalg.norm(est - truth) / np.linalg.norm(truth))
    else:
        rel_err = math.nan
    return {"case": case, "seed": seed, "truth": terms, "magnitude": mag, "accepted": res.accepted,
            "found": found, "right": right, "rel_err": rel_err, "gain_pct": res.gain_pct,
            "gap_cal": gap_cal, "gap_ext": gap_ext, "seconds": elapsed,
            "reason": res.tried[-1].verdict.reason if res.tried else "no term selected"}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--cases", nargs="*", default=CASES, choices=CASES)
    args = ap.parse_args(argv)
    rows = []
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        for case in args.cases:
            r = run_case(case, seed)
            rows.append(r)
            fmt = ", ".join(f"{k} {v:.3g}" for k, v in r["found"].items()) or "-"
            print(f"seed {seed:3d} {case:10s} accepted={str(r['accepted']):5s} right={str(r['right']):5s} "
                  f"found [{fmt}] rel.err {r['rel_err']:.3f} gain {r['gain_pct']:5.1f} % "
                  f"gap to truth {r['gap_cal']:.2f} -> {r['gap_ext']:.2f} N·m ({r['seconds']:.1f} s) "
                  f"| {r['reason']}", flush=True)
    effects = [r for r in rows if r["case"] not in NULL_CASES]
    nulls = [r for r in rows if r["case"] in NULL_CASES]
    print()
    print("| case | campaigns | accepted | right term(s) | median coef. error | median held-out gain | "
          "gap to truth closed (median) |")
    print("|---|---|---|---|---|---|---|")
    for case in args.cases:
        rr = [r for r in rows if r["case"] == case]
        errs = [r["rel_err"] for r in rr if np.isfinite(r["rel_err"])]
        gains = [r["gain_pct"] for r in rr if r["accepted"]]
        closed = [100 * (1 - r["gap_ext"] / r["gap_cal"]) for r in rr if r["gap_cal"] > 0]
        print(f"| {case} | {len(rr)} | {sum(r['accepted'] for r in rr)} | {sum(r['right'] for r in rr)} | "
              f"{np.median(errs) * 100 if errs else math.nan:.1f} % | "
              f"{np.median(gains) if gains else math.nan:.1f} % | {np.median(closed):.0f} % |")
    if effects:
        print(f"\ndiscovery rate: {sum(r['right'] for r in effects)}/{len(effects)} effect campaigns "
              f"({100 * sum(r['right'] for r in effects) / len(effects):.0f} %)")
    if nulls:
        print(f"false-discovery rate: {sum(r['accepted'] for r in nulls)}/{len(nulls)} campaigns without a "
              f"predictable effect ({100 * sum(r['accepted'] for r in nulls) / len(nulls):.0f} %)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
