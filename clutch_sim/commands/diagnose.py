"""clutch-sim diagnose: fit, calibrate, find what the simulation gets wrong, name the cause,
extend the model and measure the gain on held-out runs."""
from __future__ import annotations

import json
import sys
from pathlib import Path

from clutch_sim.cli import add_params_option
from clutch_sim.commands._common import add_topic_options, load_runs


def add_parser(sub):
    p = sub.add_parser("diagnose", help="the whole loop: bench fit, car calibration, cause, extension, gain",
                       description="Fit friction on the bench, calibrate on the car runs (holding runs out), "
                                   "show what the baseline gets wrong, name the cause among the mechanism "
                                   "catalog (or none / unexplained), extend the model and measure the gain "
                                   "on the held-out runs. Writes DIR/report.json, DIR/report.html (+ PNG), "
                                   "DIR/calibrated_model.yaml and DIR/extended_model.yaml.")
    p.add_argument("--bench", required=True, metavar="BENCH.csv", help="SAE#2 bench friction table")
    p.add_argument("--bags", "--bag", dest="bags", nargs="+", required=True, metavar="BAG")
    p.add_argument("--out", required=True, metavar="DIR")
    add_params_option(p)
    p.add_argument("--held-out", nargs="+", metavar="RUN", default=None,
                   help="bags to hold out, whole ('BAG') or a time span in s from the bag's first message "
                        "('BAG[t0:t1]') (default: every third run from the second, of 3 runs the one between the "
                        "others in sump temperature, or time spans of few long runs)")
    p.add_argument("--candidates", nargs="+", metavar="ID", default=None,
                   help="mechanism ids to consider (default: the whole catalog)")
    p.add_argument("--mc-samples", type=int, default=200,
                   help="Monte Carlo samples of the car calibration (0 = regression only; default 200)")
    p.add_argument("--seed", type=int, default=0, help="Monte Carlo seed")
    p.add_argument("--diagnosis-rate", default="auto", metavar="HZ|auto|native",
                   help="row rate the diagnosis works at: 'auto' (default) decimates fast logs (anti-aliased) to "
                        "the rate the diagnosis needs (about 200 Hz; campaigns below twice that are left as they "
                        "are), a number in Hz asks for that rate, 'native' keeps every row (docs/diagnosis.md)")
    p.add_argument("--sample-budget-s", default="auto", metavar="S|auto|all",
                   help="campaigns longer than this many seconds (after decimation) are calibrated and "
                        "diagnosed on windows of 10 s spread over the whole log, each started from the plant "
                        "state of a simulation of the whole campaign (docs/diagnosis_scale.md); 'auto' (default) "
                        "= 180 s, about 3 minutes of diagnosis for an hour of 1 kHz data on 2 cores; "
                        "'all' or 0 = always the whole campaign")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS|local",
                   help="run the candidate fits on a Dask cluster: a scheduler address (tcp://host:8786) or "
                        "'local' (a 2-worker LocalCluster on this machine); default: in this process. "
                        "The results equal the serial run's")
    p.add_argument("--no-progress", action="store_true", help="no progress bars on stderr (stage lines stay)")
    p.add_argument("--no-plots", action="store_true",
                   help="write report.html without the PNG figures (faster when diagnosing many campaigns)")
    add_topic_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from clutch_model.formats.bench_csv import read_bench
    from clutch_model.diagnosis.calibration import car_calibration
    from clutch_model.diagnosis.continued_bags import join_continued_bags
    from clutch_model.diagnosis.engine import diagnose_campaign
    from clutch_model.diagnosis.parallel import FitExecutor
    from clutch_model.diagnosis.report import ProgressiveReport
    from clutch_model.diagnosis.split import choose_split
    from clutch_model.errors import ParamsError
    from clutch_model.identification.friction_fit import fit_friction
    from clutch_model.plant.mechanisms import CATALOG
    from clutch_model.plant.params import load_model

    if args.candidates:
        bad = [c for c in args.candidates if c not in CATALOG]
        if bad:
            raise ParamsError(f"unknown mechanism id '{bad[0]}' (known: {', '.join(CATALOG)})")
    if args.mc_samples < 0:
        raise ParamsError("--mc-samples must be >= 0")
    rate = _diagnosis_rate(args.diagnosis_rate)
    budget = _sample_budget(args.sample_budget_s)
    nominal = load_model(args.params)
    bench = read_bench(args.bench)
    runs = load_runs(args, args.bags)
    names = [r.name for r in runs]
    split = choose_split(runs, args.held_out)   # checks the split before the slow work
    missing = sorted({h.run for h in split.held_out} - set(names))
    if missing:
        raise ParamsError(f"held-out run not in the campaign: {missing[0]}")

    def say(msg):
        print(f"diagnose: {msg}", file=sys.stderr, flush=True)

    say(f"fitting friction on {args.bench}")
    # jointly refined: a bench whose lowest slip is not on the static plateau biases the two-stage
    # fit's mu_S toward mu_C, i runs to its bound and the model puts a step below the bench's slips
    # (docs/diagnosis_statistics.md, "The bench fit")
    bench_fit = fit_friction(bench, nominal, joint=True)
    bench_model = bench_fit.model.with_mechanisms([m for m in nominal.mechanisms])
    # a recorder rolling over to a new bag mid-drive: such bags are diagnosed as one drive
    runs, joins = join_continued_bags(bench_model, runs, say)
    held_out = [joins.drive_label(h) for h in args.held_out] if args.held_out else None

    def calibrate(model, fit_campaign):
        return car_calibration(model, fit_campaign, mc_samples=args.mc_samples, seed=args.seed, progress=say)

    writer = ProgressiveReport(args.out, plots=not args.no_plots, joins=joins)      # each output written as soon as it is known
    with FitExecutor(args.scheduler, progress=not args.no_progress, say=say) as executor:
        held = [runs]
        del runs                  # the engine's reference only: the native rows are freed once decimated
        diagnose_campaign(nominal, bench_model, held.pop(), held_out=held_out, candidates=args.candidates,
                          calibrate=calibrate, progress=say, checkpoint=writer, diagnosis_rate_hz=rate,
                          fit_executor=executor, sample_budget_s=budget,
                          bench_info={"rmse": bench_fit.rmse, "rows": bench_fit.n_rows,
                                      "active_constraints": [c.name for c in bench_fit.active_constraints]})
    rep = json.loads((Path(args.out) / "report.json").read_text())
    for c in rep["causes"] or [rep["cause"]]:
        print(f"cause: {c['id']}" + (f" {c['parameters']}" if c.get("parameters") else "")
              + (f" 95 % {c['parameters_ci95']}" if c.get("parameters_ci95") else ""))
    r = rep["rmse_nm"]
    print(f"held-out RMSE [N*m]: nominal {r['nominal']:.2f}, calibrated {r['calibrated']:.2f}, "
          f"extended {r['extended']:.2f} (gain {rep['gain_pct']:.1f} %) on {', '.join(rep['held_out_runs'])}")
    print(f"report: {args.out}/report.html")
    return 0


def _diagnosis_rate(text: str):
    """--diagnosis-rate -> None (auto), 0 (native rows) or a rate in Hz."""
    from clutch_model.errors import ParamsError

    t = str(text).strip().lower()
    if t == "auto":
        return None
    if t == "native":
        return 0.0
    try:
        v = float(t)
    except ValueError:
        raise ParamsError(f"--diagnosis-rate must be 'auto', 'native' or a rate in Hz, not '{text}'") from None
    if not v > 0 or v != v or v == float("inf"):
        raise ParamsError(f"--diagnosis-rate must be a positive rate in Hz, not '{text}'")
    return v


def _sample_budget(text: str):
    """--sample-budget-s -> seconds (0 = never sample)."""
    from clutch_model.diagnosis.sample import DEFAULT_BUDGET_S
    from clutch_model.errors import ParamsError

    t = str(text).strip().lower()
    if t == "auto":
        return DEFAULT_BUDGET_S
    if t in ("all", "off", "none"):
        return 0.0
    try:
        v = float(t)
    except ValueError:
        raise ParamsError(f"--sample-budget-s must be 'auto', 'all' or seconds, not '{text}'") from None
    if not (v >= 0) or v == float("inf"):
        raise ParamsError(f"--sample-budget-s must be >= 0 seconds (0 = the whole campaign), not '{text}'")
    return v
