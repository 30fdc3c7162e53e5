"""clutch-sim fit-friction: constrained friction fit on SAE#2 bench data (thesis §5.2.1)."""
from __future__ import annotations

from clutch_sim.cli import add_params_option


def add_parser(sub):
    p = sub.add_parser("fit-friction", help="fit the friction polynomials to bench data (SAE#2)",
                       description="Fit mu_S to the lowest-slip rows (eq. 5.3), then mu_C, omega_S, k_V and the "
                                   "exponent i by constrained nonlinear least squares (eq. 5.2) with the chapter-4 "
                                   "inequalities enforced over P in [0, 20] MPa x theta in [0, 230] C. Writes "
                                   "MODEL.yaml (the base model with the fitted coefficients; the fit summary in its "
                                   "header) and MODEL.fit.json (RMSE, standard errors, active constraints).")
    p.add_argument("--bench", required=True, metavar="BENCH.csv", help="bench CSV (docs/bags.md, Bench data)")
    p.add_argument("--out", required=True, metavar="MODEL.yaml")
    add_params_option(p)
    p.add_argument("--mu-offset", type=float, default=None, metavar="X",
                   help="upper bound of mu_C (eq. 4.5; default: the largest mu in the bench data)")
    p.add_argument("--joint", action="store_true",
                   help="after the two-stage fit, refine all 20 coefficients together, i at the base model's constant "
                        "unless freeing it is significantly better (beyond the thesis; diagnose always does)")
    p.add_argument("--low-slip-max", type=float, default=None, metavar="RAD_S",
                   help="rows with |slip| <= this feed the mu_S fit (default: the lowest slip level)")
    p.add_argument("--starts", type=int, default=3, metavar="N", help="random starts besides RC-1 and flat ones")
    p.add_argument("--seed", type=int, default=0, help="seed of the random starts")
    p.add_argument("--plot", metavar="PNG", default=None, help="also plot the fitted friction over the bench points")
    p.set_defaults(func=run)


def run(args) -> int:
    from clutch_model.formats.bench_csv import read_bench
    from clutch_model.errors import ParamsError
    from clutch_model.identification.friction_fit import fit_friction
    from clutch_model.plant.params import load_model

    if args.starts < 0:
        raise ParamsError("--starts must be >= 0")
    base = load_model(args.params)
    bench = read_bench(args.bench)
    fit = fit_friction(bench, base, mu_offset=args.mu_offset, low_slip_max=args.low_slip_max, joint=args.joint,
                       n_random_starts=args.starts, seed=args.seed)
    yaml_path, json_path = fit.save(args.out)
    print("\n".join(fit.summary_lines()))
    print(f"wrote {yaml_path} and {json_path}")
    if args.plot:
        from clutch_model.identification.plots import friction_fit_figure

        friction_fit_figure(fit, bench, args.plot)
        print(f"wrote {args.plot}")
    return 0
