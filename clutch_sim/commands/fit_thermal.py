"""clutch-sim fit-thermal: viscosity (eq. 3.17) and heat-transfer (eq. 5.11-5.14) fits."""
from __future__ import annotations

from clutch_sim.cli import add_params_option
from clutch_sim.commands._common import add_topic_options, load_runs


def add_parser(sub):
    p = sub.add_parser("fit-thermal", help="fit viscosity alpha0, alpha1 and heat transfer b1..b4",
                       description="Fit the viscosity law mu = alpha0 theta^-alpha1 (eq. 3.17) to samples "
                                   "(CSV pack_temperature_c,viscosity_pa_s) and the heat-transfer coefficient "
                                   "H_tf = b1 + b2|w| + b3 F + b4|w|F (F in kN, eq. 5.11-5.14) to the pack "
                                   "temperature measured in bags (/clutch/pack_temperature). Writes MODEL.yaml "
                                   "(the base model with the fitted values) and MODEL.fit.json.")
    p.add_argument("--bags", "--bag", dest="bags", nargs="+", default=None, metavar="BAG",
                   help="bags with /clutch/pack_temperature and /clutch/measured_torque")
    p.add_argument("--viscosity", metavar="CSV", default=None, help="viscosity samples")
    p.add_argument("--out", required=True, metavar="MODEL.yaml")
    add_params_option(p)
    p.add_argument("--min-delta", type=float, default=3.0, metavar="C",
                   help="drop samples with |theta_pack - theta_sump| below this (default 3 C)")
    p.add_argument("--window", type=float, default=1.0, metavar="S",
                   help="Savitzky-Golay smoothing window for the heat balance (default 1 s)")
    p.add_argument("--weighting", choices=("power", "thesis"), default="power",
                   help="'thesis': unweighted LS on eq. 5.11's H_tf; 'power' (default): the same equation "
                        "weighted by (A_N dtheta)^2, i.e. the heat balance in watts")
    add_topic_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from clutch_model.errors import ParamsError
    from clutch_model.formats.results import write_json
    from clutch_model.identification.friction_fit import sidecar_path
    from clutch_model.identification.thermal_fit import (fit_heat_transfer, fit_viscosity, read_viscosity_csv,
                                                         with_thermal)
    from clutch_model.plant.params import load_model, save_model

    if not args.bags and not args.viscosity:
        raise ParamsError("give --bags (heat transfer) and/or --viscosity CSV")
    if args.window <= 0 or args.min_delta < 0:
        raise ParamsError("--window must be > 0 and --min-delta >= 0")
    base = load_model(args.params)
    model = base
    lines, report = [], {}
    if args.viscosity:
        th, mu = read_viscosity_csv(args.viscosity)
        v = fit_viscosity(th, mu)
        model = with_thermal(model, alpha0=v.alpha0, alpha1=v.alpha1)
        lines += v.summary_lines()
        report["viscosity"] = v.to_json()
    if args.bags:
        runs = load_runs(args, args.bags)
        h = fit_heat_transfer(runs, model, min_delta_c=args.min_delta, window_s=args.window,
                              weighting=args.weighting)
        model = with_thermal(model, b=h.b)
        lines += h.summary_lines()
        report["heat_transfer"] = h.to_json()
    save_model(model, args.out, header="fit-thermal\n" + "\n".join(lines))
    sc = sidecar_path(args.out)
    write_json(sc, report)
    print("\n".join(lines))
    print(f"wrote {args.out} and {sc}")
    return 0
