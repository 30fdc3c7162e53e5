"""`clutch-sim diagnose` on car-log data: a matrix of hidden causes × data conditions × seeds.

Cases: nothing (`none`), every catalog mechanism, pairs of causes, and effects outside the
catalog (lookalikes such as a torque-sensor low-pass, which *is* the catalog's
torque_sensor_lag, a reversible slip-power fade that mimics friction_degradation, a per-run
friction level, ripple, a pressure×temperature term: a right diagnosis says `unexplained`,
never a catalog name). Conditions: clean lab-like, unaligned topics with jitter and a 50 Hz
torque, AR(1) φ 0.95, band-limited / held / median-filtered / drifting torque noise, lock-up
phases, one long drive in one bag, few long runs, everything at once
(clutch_model/virtual_car/hidden_campaigns.py, docs/diagnosis_matrix.md).

Each cell: the car-log virtual test car writes the bags, with later bags from the same true
clutch that `clutch-sim diagnose` (run as a subprocess, whatever report.json it writes:
`causes` when present, else `cause`) never sees; `clutch-sim replay` of calibrated_model.yaml
and extended_model.yaml over every bag, scored on the unseen ones against the noise-free
true torque (lock phases out) -> the held-out gain. Magnitudes come from --magnitude-seed,
which diagnose never sees.

Prints one line per cell as it finishes, then the confusion matrix (expected vs named), the
pass / held-out gain per cell (case × condition) and wall / CPU times; --out DIR writes
matrix.json and matrix.md.

    python bench/bench_diagnose_matrix.py --quick                 # a few minutes
    python bench/bench_diagnose_matrix.py --seeds 2 --jobs 2 --out /tmp/matrix
    python bench/bench_diagnose_matrix.py --cells 'none@*' '*@ar1' --seeds 3
"""
from __future__ import annotations

import argparse
import fnmatch
import json
import math
import os
import sys
import tempfile
import time
from collections import Counter, defaultdict
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from clutch_model.virtual_car.hidden_campaigns import CASES, CONDITIONS, run_cell

# --quick: one cell per risk, small campaigns
QUICK_CELLS = ["none@ar1", "spring_preload+torque_offset@lab", "torque_sensor_lowpass@unaligned",
               "actuator_lag@long_drive"]


def select_cells(patterns, quick: bool) -> list:
    every = [f"{c}@{k}" for k in CONDITIONS for c in CASES]
    if patterns:
        cells = [c for c in every if any(fnmatch.fnmatchcase(c, p) for p in patterns)]
    elif quick:
        cells = list(QUICK_CELLS)
    else:
        cells = every
    return [tuple(c.split("@")) for c in cells]


def _cell_job(case, condition, seed, work, kw):
    t0 = time.perf_counter()
    try:
        res = run_cell(case, condition, seed, work, **kw).to_dict()
    except Exception as exc:  # noqa: BLE001 - a broken cell is a figure, not the end of the bench
        res = {"cell": f"{case}@{condition}#{seed}", "case": case, "condition": condition, "seed": seed,
               "expected": "?", "named_label": "error", "judgement": "refused", "passed": False,
               "error": f"{type(exc).__name__}: {exc}", "wall_s": {}, "cpu_s": {},
               "held_out_gain_pct": float("nan")}
    res["wall_s"]["cell"] = time.perf_counter() - t0
    return res


def _f(x, fmt="{:.1f}"):
    return "—" if x is None or (isinstance(x, float) and not math.isfinite(x)) else fmt.format(x)


def cell_line(r: dict) -> str:
    rp = r.get("replay_rmse_nm", {})
    mags = ", ".join(f"{k} {v:.3g}" for k, v in (r.get("magnitudes") or {}).items())
    verdict = "PASS" if r.get("passed") else "FAIL"
    s = (f"{r['cell']:48s} {verdict} {r['judgement']:11s} expected {r['expected']:30s} named "
         f"{r['named_label']:30s}")
    if rp:
        s += (f" unseen vs true torque: cal {_f(rp.get('calibrated'))} ext {_f(rp.get('extended'))} N*m"
              f" (gain {_f(r.get('held_out_gain_pct'), '{:+.0f}')} %, diagnose {_f(r.get('diagnose_gain_pct'), '{:+.0f}')} %)")
    w = r.get("wall_s", {})
    s += f" [{mags}] wall {_f(w.get('cell'), '{:.0f}')} s (diagnose {_f(w.get('diagnose'), '{:.0f}')} s, cpu {_f(r.get('cpu_s', {}).get('diagnose'), '{:.0f}')} s)"
    if r.get("error"):
        s += f"  ! {r['error']}"
    return s


def confusion(results) -> tuple:
    exp_labels = sorted({r["expected"] for r in results})
    named_labels = sorted({r["named_label"] for r in results})
    counts = Counter((r["expected"], r["named_label"]) for r in results)
    return exp_labels, named_labels, counts


def confusion_text(results) -> str:
    exp_labels, named_labels, counts = confusion(results)
    hdr = "expected \\ named"
    w0 = max(len(hdr), *(len(e) for e in exp_labels))
    ws = [max(3, len(n)) for n in named_labels]
    lines = [f"{hdr:{w0}s} | " + " | ".join(f"{n:>{w}s}" for n, w in zip(named_labels, ws))]
    for e in exp_labels:
        lines.append(f"{e:{w0}s} | " + " | ".join(f"{(counts[e, n] or ''):>{w}}" for n, w in zip(named_labels, ws)))
    return "\n".join(lines)


def grid(results) -> tuple:
    """case × condition -> 'passes/n, median held-out gain'."""
    by = defaultdict(list)
    for r in results:
        by[r["case"], r["condition"]].append(r)
    cases = [c for c in CASES if any(k[0] == c for k in by)]
    conds = [k for k in CONDITIONS if any(x[1] == k for x in by)]
    cell = {}
    for key, rs in by.items():
        ok = sum(bool(r.get("passed")) for r in rs)
        gains = sorted(r["held_out_gain_pct"] for r in rs if isinstance(r.get("held_out_gain_pct"), float)
                       and math.isfinite(r["held_out_gain_pct"]) and r.get("named"))
        g = f" {gains[len(gains) // 2]:+.0f}%" if gains else ""
        names = "/".join(sorted({r["named_label"] for r in rs}))
        cell[key] = f"{ok}/{len(rs)}{g} {names}"
    return cases, conds, cell


def grid_text(results, sep=" | ") -> str:
    cases, conds, cell = grid(results)
    w0 = max(len("case"), *(len(c) for c in cases))
    ws = {k: max(len(k), *(len(cell.get((c, k), "")) for c in cases)) for k in conds}
    lines = [f"{'case':{w0}s}{sep}" + sep.join(f"{k:{ws[k]}s}" for k in conds)]
    for c in cases:
        lines.append(f"{c:{w0}s}{sep}" + sep.join(f"{cell.get((c, k), ''):{ws[k]}s}" for k in conds))
    return "\n".join(lines)


def summary(results) -> dict:
    n = len(results)
    judg = Counter(r["judgement"] for r in results)
    named = [r for r in results if r.get("named")]
    held = [r for r in named if r.get("gain_holds")]
    by_class = defaultdict(lambda: [0, 0])
    for r in results:
        by_class[r.get("condition_class", r["condition"])][0] += bool(r.get("passed"))
        by_class[r.get("condition_class", r["condition"])][1] += 1
    walls = [r["wall_s"].get("cell", float("nan")) for r in results]
    return {"cells": n, "passed": sum(bool(r.get("passed")) for r in results), "judgements": dict(judg),
            "named_with_gain_holding": f"{len(held)}/{len(named)}",
            "pass_by_condition_class": {k: f"{a}/{b}" for k, (a, b) in by_class.items()},
            "wall_s_total_cells": sum(w for w in walls if math.isfinite(w)),
            "diagnose_wall_s_median": _median([r["wall_s"].get("diagnose", float("nan")) for r in results])}


def _median(xs):
    xs = sorted(x for x in xs if isinstance(x, float) and math.isfinite(x))
    return xs[len(xs) // 2] if xs else None


def _json_safe(x):
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_safe(v) for v in x]
    return x


def markdown(results, meta) -> str:
    s = summary(results)
    md = ["# Diagnosis matrix (bench/bench_diagnose_matrix.py)", "",
          f"{meta['command']}  ", f"{meta['date']}, load average {meta['loadavg']}, {meta['cpus']} CPUs; "
          f"{s['passed']}/{s['cells']} cells pass; named causes whose gain holds on unseen bags: "
          f"{s['named_with_gain_holding']}", "",
          "## Confusion (expected vs named)", "", "```", confusion_text(results), "```", "",
          "## Per cell: passes/seeds, median held-out gain (unseen bags, vs the true torque), names", "",
          "```", grid_text(results), "```", "", "## Cells", "",
          "| cell | verdict | expected | named | cal / ext RMSE N·m | gain % | diagnose gain % | wall s (diagnose) | note |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        rp = r.get("replay_rmse_nm", {})
        md.append(f"| {r['cell']} | {'pass' if r.get('passed') else 'FAIL'} {r['judgement']} | {r['expected']} | "
                  f"{r['named_label']} | {_f(rp.get('calibrated'))} / {_f(rp.get('extended'))} | "
                  f"{_f(r.get('held_out_gain_pct'), '{:+.0f}')} | {_f(r.get('diagnose_gain_pct'), '{:+.0f}')} | "
                  f"{_f(r['wall_s'].get('cell'), '{:.0f}')} ({_f(r['wall_s'].get('diagnose'), '{:.0f}')}) | "
                  f"{(r.get('error') or '').replace('|', '/')[:120]} |")
    return "\n".join(md) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help=f"small campaigns, cells {' '.join(QUICK_CELLS)}")
    ap.add_argument("--seeds", type=int, default=1, help="seeds per cell (default 1)")
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--magnitude-seed", type=int, default=20261123,
                    help="seed of the hidden magnitudes (never given to diagnose)")
    ap.add_argument("--cells", nargs="+", metavar="CASE@CONDITION",
                    help="glob patterns, e.g. 'none@*' '*@ar1' 'actuator_lag+*@lab'")
    ap.add_argument("--jobs", type=int, default=1, help="cells run in parallel (process pool)")
    ap.add_argument("--mc-samples", type=int, default=None, help="diagnose --mc-samples (default: diagnose's own)")
    ap.add_argument("--timeout", type=float, default=1800.0, help="per diagnose / replay call, s")
    ap.add_argument("--out", type=Path, default=None, help="write matrix.json and matrix.md here")
    ap.add_argument("--keep", action="store_true", help="keep each cell's campaign and outputs (--work)")
    ap.add_argument("--work", type=Path, default=None, help="work directory (default: a temporary one)")
    ap.add_argument("--list", action="store_true", help="list the cases and conditions and exit")
    args = ap.parse_args(argv)

    if args.list:
        for c in CASES.values():
            print(f"case      {c.name:32s} {c.kind}")
        for k in CONDITIONS.values():
            print(f"condition {k.name:12s} [{k.klass}] {k.description}")
        return 0
    cells = select_cells(args.cells, args.quick)
    if not cells:
        print("no cell matches --cells", file=sys.stderr)
        return 2
    jobs = [(case, cond, seed) for seed in range(args.first_seed, args.first_seed + args.seeds) for case, cond in cells]
    meta = {"command": "python bench/bench_diagnose_matrix.py " + " ".join(sys.argv[1:] if argv is None else argv),
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "loadavg": " ".join(f"{x:.1f}" for x in os.getloadavg()), "cpus": os.cpu_count(),
            "quick": args.quick, "magnitude_seed": args.magnitude_seed}
    print(f"{len(jobs)} cells ({len(cells)} case@condition x {args.seeds} seed(s)), jobs {args.jobs}, "
          f"load average {meta['loadavg']}", flush=True)
    kw = {"magnitude_seed": args.magnitude_seed, "quick": args.quick, "mc_samples": args.mc_samples,
          "timeout_s": args.timeout, "keep": args.keep}
    t0 = time.perf_counter()
    results = []
    with tempfile.TemporaryDirectory(prefix="diag_matrix_") as tmp:
        root = args.work or Path(tmp)
        work = [root / f"{case}@{cond}#{seed}".replace("+", "_") for case, cond, seed in jobs]
        if args.jobs <= 1:
            for (case, cond, seed), w in zip(jobs, work):
                results.append(_cell_job(case, cond, seed, w, kw))
                print(cell_line(results[-1]), flush=True)
        else:
            with ProcessPoolExecutor(max_workers=args.jobs) as pool:
                futs = [pool.submit(_cell_job, case, cond, seed, w, kw) for (case, cond, seed), w in zip(jobs, work)]
                for fut in as_completed(futs):
                    results.append(fut.result())
                    print(cell_line(results[-1]), flush=True)
    order = {j: i for i, j in enumerate(f"{c}@{k}#{s}" for c, k, s in jobs)}
    results.sort(key=lambda r: order.get(r["cell"], 0))
    wall = time.perf_counter() - t0
    s = summary(results)
    print("\nconfusion (rows expected, columns named):")
    print(confusion_text(results))
    print("\nper cell (case x condition): passes/seeds, median held-out gain on unseen bags vs the true torque, names:")
    print(grid_text(results))
    print(f"\n{s['passed']}/{s['cells']} cells pass ({', '.join(f'{k} {v}' for k, v in s['judgements'].items())}); "
          f"named causes whose gain holds on unseen bags: {s['named_with_gain_holding']}")
    print("pass by condition class: " + ", ".join(f"{k} {v}" for k, v in s["pass_by_condition_class"].items()))
    print(f"wall {wall:.0f} s for the matrix; diagnose median {_f(s['diagnose_wall_s_median'], '{:.0f}')} s per cell; "
          f"load average now {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        meta["wall_s"] = wall
        (args.out / "matrix.json").write_text(json.dumps(_json_safe({"meta": meta, "summary": s, "cells": results}),
                                                         indent=1, default=str) + "\n")
        (args.out / "matrix.md").write_text(markdown(results, meta))
        print(f"wrote {args.out / 'matrix.json'} and {args.out / 'matrix.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
