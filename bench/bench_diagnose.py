"""`clutch-sim diagnose` speed and hit rate.

Speed (issue 5 target: <= 60 s with a warm JIT cache): one campaign of 9 runs of ~9 s at
200 Hz plus the 135-row bench table, through the real CLI (bag decoding included), timed
per stage.
Hit rate: campaigns from the virtual test car with every catalog mechanism, none, and both
effects outside the catalog, magnitudes drawn log-uniformly over each effect's visible range,
over --seeds seeds (default 2; each campaign takes ~15-30 s on this 2-core machine).
Gain on unseen runs: each campaign has 3 more runs after the 9 diagnosed ones; `clutch-sim
replay` of calibrated_model.yaml and extended_model.yaml on those 3 bags alone (as an outside
check would do) gives the gain that holds on runs diagnose never saw.

    python bench/bench_diagnose.py [--seeds N] [--first-seed S] [--speed-only] [--speed]

--speed: issue 9's long-work target instead (<= 60 s): 10 runs x 10 s at 500 Hz with an
actuator lag, through the real CLI, wall and CPU time, per-stage times, the diagnosis rate
chosen and the load average (the machine is shared: CPU time is the figure to read).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path


import numpy as np  # noqa: E402

def _cases():
    from clutch_model.plant.mechanisms import DIAGNOSIS_CANDIDATES
    from clutch_model.virtual_car.campaign import EXTRA_EFFECTS

    return ["none", *DIAGNOSIS_CANDIDATES, *EXTRA_EFFECTS]


CASES = _cases()


def campaign(tmp: Path, seed: int, case: str, n_runs=9, duration=9.0, extra_runs=0, rate_hz=200.0):
    from clutch_model.virtual_car.campaign import EXTRA_EFFECTS, VISIBLE_RANGE, CampaignSpec, synthesize_campaign, write_campaign

    rng = np.random.default_rng([seed, CASES.index(case)])
    kw, mag = {}, None
    if case != "none":
        rr = VISIBLE_RANGE[case]
        if rr is not None:
            mag = float(np.exp(rng.uniform(np.log(rr[0]), np.log(rr[1]))))
        key = "extra_effect" if case in EXTRA_EFFECTS else "mechanism"
        kw = {key: case, "magnitude": mag}
    spec = CampaignSpec(seed=seed, n_runs=n_runs + extra_runs, run_duration_s=duration, rate_hz=rate_hz, **kw)
    write_campaign(synthesize_campaign(spec), tmp)
    return spec, mag


def diagnose(tmp: Path, n_runs=None):
    from clutch_sim.cli import main as cli

    bags = sorted(str(p) for p in (tmp / "bags").iterdir())[:n_runs]
    t0 = time.perf_counter()
    rc = cli(["diagnose", "--bench", str(tmp / "bench.csv"), "--bags", *bags, "--out", str(tmp / "diag")])
    wall = time.perf_counter() - t0
    assert rc == 0
    return json.loads((tmp / "diag" / "report.json").read_text()), wall


def unseen_gain(tmp: Path, n_runs: int):
    """(calibrated, extended) torque RMSE of `clutch-sim replay` on the runs after the first n_runs."""
    import contextlib
    import csv
    import io

    from clutch_sim.cli import main as cli

    bags = sorted(str(p) for p in (tmp / "bags").iterdir())[n_runs:]
    out = []
    for name in ("calibrated_model.yaml", "extended_model.yaml"):
        csv_path = tmp / f"unseen_{name}.csv"
        with contextlib.redirect_stdout(io.StringIO()):
            assert cli(["replay", "--bag", *bags, "--params", str(tmp / "diag" / name), "--out", str(csv_path)]) == 0
        rows = list(csv.DictReader(csv_path.open()))
        err = np.array([float(r["torque_sim"]) - float(r["torque_measured"]) for r in rows if r["torque_measured"]])
        out.append(float(np.sqrt(np.mean(err ** 2))))
    return out


def load_avg() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "n/a"


def speed_500hz(seed: int, rate_hz: float = 500.0) -> int:
    """issue 9 item 7: `clutch-sim diagnose` on 10 runs x 10 s at 500 Hz, <= 60 s."""
    import os

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        campaign(tmp / "warm", 1, "none", n_runs=3, duration=4.0)
        diagnose(tmp / "warm")   # JIT cache warm-up
        campaign(tmp / "speed", seed, "actuator_lag", n_runs=10, duration=10.0, rate_hz=rate_hz)
        load0 = load_avg()
        c0 = os.times()
        rep, wall = diagnose(tmp / "speed")
        c1 = os.times()
        cpu = (c1.user - c0.user) + (c1.system - c0.system)
    rate = rep.get("diagnosis_rate", {})
    print(f"speed: 10 runs x 10 s at {rate_hz:g} Hz + bench rows: {wall:.1f} s wall, {cpu:.1f} s CPU "
          f"(target <= 60 s); diagnosed at {rate.get('rate_hz', rate_hz):.0f} Hz (factor {rate.get('factor', 1)}); "
          f"cause {rep['cause']['id']}; load avg {load0} -> {load_avg()} on {os.cpu_count()} cores")
    print("  stages [s]: " + ", ".join(f"{k} {v:.1f}" for k, v in rep["timings_s"].items()))
    return 0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--first-seed", type=int, default=101)
    ap.add_argument("--speed-only", action="store_true")
    ap.add_argument("--speed", action="store_true", help="10 runs x 10 s at 500 Hz (issue 9 item 7) only")
    ap.add_argument("--rate-hz", type=float, default=500.0, help="--speed: the campaign's rate (default 500 Hz)")
    args = ap.parse_args()
    if args.speed:
        return speed_500hz(args.first_seed, args.rate_hz)

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        campaign(tmp / "warm", 1, "none", n_runs=3, duration=4.0)
        diagnose(tmp / "warm")   # JIT cache warm-up
        campaign(tmp / "speed", args.first_seed, "actuator_lag")
        rep, wall = diagnose(tmp / "speed")
        print(f"speed: 9 runs x 9 s at 200 Hz + 135 bench rows: {wall:.1f} s wall (target <= 60 s)")
        print("  stages [s]: " + ", ".join(f"{k} {v:.1f}" for k, v in rep["timings_s"].items()))
    if args.speed_only:
        return 0
    hits, total = 0, 0
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        for case in CASES:
            with tempfile.TemporaryDirectory() as tmp:
                spec, mag = campaign(Path(tmp), seed, case, extra_runs=3)
                rep, wall = diagnose(Path(tmp), n_runs=9)
                unseen = unseen_gain(Path(tmp), 9)
            ok = rep["cause"]["id"] == spec.expected_cause
            hits += ok
            total += 1
            r = rep["rmse_nm"]
            mag_s = f"{mag:.4g}" if mag is not None else "default"
            print(f"seed {seed} {case:27s} magnitude {mag_s:<10s} -> "
                  f"{rep['cause']['id']:22s} {'ok ' if ok else 'MISS'} held-out RMSE cal {r['calibrated']:.1f} "
                  f"ext {r['extended']:.1f} N*m, noise {rep['noise_sigma_nm']:.1f}; unseen runs: cal "
                  f"{unseen[0]:.1f} ext {unseen[1]:.1f} N*m; {wall:.0f} s", flush=True)
    print(f"hit rate: {hits}/{total}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
