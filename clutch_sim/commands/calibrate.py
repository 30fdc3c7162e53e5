"""clutch-sim calibrate: refine the friction coefficients on car-test bags (least squares)."""
from __future__ import annotations

from clutch_sim.cli import add_params_option
from clutch_sim.commands._common import add_topic_options, load_runs


def add_parser(sub):
    p = sub.add_parser("calibrate", help="refine the friction coefficients against measured car torque",
                       description="Gradient-based calibration (scipy least_squares on the batch simulator) of the "
                                   "friction coefficients the bags can identify (identifiability screen), with a "
                                   "ridge toward the starting model (the bench fit) and the friction positivity "
                                   "check of §5.3. Writes MODEL.yaml and MODEL.fit.json (RMSE, moved coefficients, "
                                   "standard errors).")
    p.add_argument("--bags", "--bag", dest="bags", nargs="+", required=True, metavar="BAG")
    add_params_option(p)
    p.add_argument("--out", required=True, metavar="MODEL.yaml")
    p.add_argument("--coefficients", default="auto", metavar="LIST",
                   help="'auto' (identifiability screen, default) or a list such as a0,a3,a15")
    p.add_argument("--regularization", type=float, default=0.05, metavar="X",
                   help="ridge weight toward the starting coefficients (default 0.05; 0 = none)")
    p.add_argument("--max-iterations", type=int, default=40, metavar="N")
    p.add_argument("--hold-out", nargs="+", default=None, metavar="RUN",
                   help="run (bag) names left out of the fit; their RMSE is reported")
    add_topic_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    import sys

    import numpy as np

    from clutch_model.errors import ParamsError
    from clutch_model.identification import parse_coefficients
    from clutch_model.identification.calibrate import calibrate_friction
    from clutch_model.identification.evaluate import CampaignInputs, rmse_of
    from clutch_model.formats.results import write_json
    from clutch_model.identification.friction_fit import sidecar_path
    from clutch_model.plant.params import load_model, save_model
    from clutch_model.formats.bag_reader import Campaign

    if args.regularization < 0 or args.max_iterations < 1:
        raise ParamsError("--regularization must be >= 0 and --max-iterations >= 1")
    coeffs = "auto" if args.coefficients.strip().lower() == "auto" else parse_coefficients(args.coefficients)
    model = load_model(args.params)
    runs = load_runs(args, args.bags)
    camp = Campaign(runs)
    rows = None
    held = []
    if args.hold_out:
        unknown = sorted(set(args.hold_out) - set(camp.names))
        if unknown:
            raise ParamsError(f"--hold-out: no run named {unknown[0]!r}")
        held = [j for j, r in enumerate(camp.runs) if r.name in set(args.hold_out)]
        rows = ~np.isin(camp.run_index, held)
        if not rows.any():
            raise ParamsError("--hold-out leaves no run to fit on")

    def say(msg):
        print(f"calibrate: {msg}", file=sys.stderr, flush=True)

    res = calibrate_friction(model, camp, coefficients=coeffs, regularization=args.regularization,
                             max_iterations=args.max_iterations, rows=rows, progress=say)
    lines = res.summary_lines()
    report = res.to_json()
    if held:
        hmask = np.isin(camp.run_index, held)
        inp = CampaignInputs.from_campaign(camp, model, rows=hmask)
        before = float(rmse_of(model.vector(), res.a_before[None, :], inp)[0])
        after = float(rmse_of(res.model.vector(), res.a_after[None, :], inp)[0])
        lines.append(f"held-out runs {', '.join(args.hold_out)}: RMSE {before:.3f} -> {after:.3f} N*m")
        report["held_out"] = {"runs": list(args.hold_out), "rmse_before": before, "rmse_after": after}
    save_model(res.model, args.out, header="\n".join(lines))
    sc = sidecar_path(args.out)
    write_json(sc, report)
    print("\n".join(lines))
    print(f"wrote {args.out} and {sc}")
    return 0
