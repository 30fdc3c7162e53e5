"""clutch-sim diagnose: fit, calibrate, find what the simulation gets wrong, name the cause,
extend the model and measure the gain on held-out runs."""
from __future__ import annotations

import sys

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
                   help="run names to hold out (default: every third run from the second)")
    p.add_argument("--candidates", nargs="+", metavar="ID", default=None,
                   help="mechanism ids to consider (default: the whole catalog)")
    p.add_argument("--mc-samples", type=int, default=200,
                   help="Monte Carlo samples of the car calibration (0 = regression only; default 200)")
    p.add_argument("--seed", type=int, default=0, help="Monte Carlo seed")
    add_topic_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from clutch_model.formats.bench_csv import read_bench
    from clutch_model.diagnosis.calibration import car_calibration
    from clutch_model.diagnosis.engine import choose_held_out, diagnose_campaign
    from clutch_model.diagnosis.report import write_report
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
    nominal = load_model(args.params)
    bench = read_bench(args.bench)
    runs = load_runs(args, args.bags)
    names = [r.name for r in runs]
    missing = sorted(set(args.held_out or []) - set(names))
    if missing:
        raise ParamsError(f"held-out run not in the campaign: {missing[0]}")
    choose_held_out(names)  # checks there is something to hold out, before the slow work

    def say(msg):
        print(f"diagnose: {msg}", file=sys.stderr, flush=True)

    say(f"fitting friction on {args.bench}")
    bench_fit = fit_friction(bench, nominal)
    bench_model = bench_fit.model.with_mechanisms([m for m in nominal.mechanisms])

    def calibrate(model, fit_campaign):
        return car_calibration(model, fit_campaign, mc_samples=args.mc_samples, seed=args.seed, progress=say)

    d = diagnose_campaign(nominal, bench_model, runs, held_out=args.held_out, candidates=args.candidates,
                          calibrate=calibrate, progress=say,
                          bench_info={"rmse": bench_fit.rmse, "rows": bench_fit.n_rows,
                                      "active_constraints": [c.name for c in bench_fit.active_constraints]})
    rep = write_report(d, args.out)
    print(f"cause: {rep['cause']['id']}"
          + (f" {rep['cause']['parameters']}" if rep["cause"]["parameters"] else ""))
    r = rep["rmse_nm"]
    print(f"held-out RMSE [N*m]: nominal {r['nominal']:.2f}, calibrated {r['calibrated']:.2f}, "
          f"extended {r['extended']:.2f} (gain {rep['gain_pct']:.1f} %) on {', '.join(rep['held_out_runs'])}")
    print(f"report: {args.out}/report.html")
    return 0
