"""clutch-sim montecarlo: Monte Carlo refit of the friction coefficients (thesis §5.3, §6.2.2)."""
from __future__ import annotations

from clutch_sim.cli import add_params_option
from clutch_sim.commands._common import add_topic_options, load_runs


def add_parser(sub):
    p = sub.add_parser("montecarlo", help="Monte Carlo refit of the 20 friction coefficients on car bags",
                       description="Uniform samples of a0..a19 within +-spread of the model's values (i fixed), "
                                   "rejected where friction goes negative on P [0,6] MPa x theta [0,230] C x "
                                   "w [0,30] rad/s, simulated on the bags; the mean of the samples beating the "
                                   "nominal RMSE, then interval halving. Writes DIR/samples.npz, "
                                   "DIR/refined_model.yaml, DIR/summary.json and scatter plots. Same seed, same "
                                   "result, serial or on Dask.")
    p.add_argument("--bags", "--bag", dest="bags", nargs="+", required=True, metavar="BAG")
    add_params_option(p)
    p.add_argument("--samples", type=int, required=True, metavar="N")
    p.add_argument("--spread", type=float, required=True, metavar="F", help="e.g. 0.05 for +-5 %%")
    p.add_argument("--seed", type=int, required=True, metavar="S")
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS|local",
                   help="run the chunks on Dask: 'local' = LocalCluster(2 workers x 1 thread), or a scheduler "
                        "address (tcp://host:8786)")
    p.add_argument("--chunk-size", type=int, default=256, metavar="N", help="samples per batch (default 256)")
    p.add_argument("--halving", default="a3,a4", metavar="LIST",
                   help="coefficients refined by interval halving, in order (default a3,a4; 'none' to skip)")
    p.add_argument("--halving-width", type=float, default=0.4, metavar="F",
                   help="halving interval [a, a + F|a|] toward the trend (default 0.4, as in the thesis)")
    p.add_argument("--screen", action="store_true",
                   help="vary only the coefficients the bags can identify (identifiability screen)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG scatter plots")
    add_topic_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    import sys

    from clutch_model.errors import ParamsError
    from clutch_model.identification import parse_coefficients
    from clutch_model.identification.evaluate import CampaignInputs
    from clutch_model.identification.montecarlo import run_montecarlo
    from clutch_model.plant.params import load_model
    from clutch_model.formats.bag_reader import Campaign

    if args.samples < 1:
        raise ParamsError("--samples must be >= 1")
    if not 0 < args.spread < 1:
        raise ParamsError("--spread must be in (0, 1), e.g. 0.05")
    if args.chunk_size < 1:
        raise ParamsError("--chunk-size must be >= 1")
    halving = parse_coefficients(args.halving, keep_order=True)
    model = load_model(args.params)
    camp = Campaign(load_runs(args, args.bags))
    inputs = CampaignInputs.from_campaign(camp, model)
    varied = None
    if args.screen:
        from clutch_model.identification.sensitivity import identifiability_screen

        scr = identifiability_screen(model, camp, inputs=inputs, seed=args.seed)
        varied = scr.selected
        print(f"montecarlo: screen keeps {', '.join(f'a{k}' for k in varied) or 'nothing'}", file=sys.stderr)
        if not varied:
            raise ParamsError("the identifiability screen found no coefficient these bags can identify")
    res = run_montecarlo(model, camp, args.samples, args.spread, seed=args.seed, chunk_size=args.chunk_size,
                         scheduler=args.scheduler, varied=varied, halving=halving,
                         halving_width=args.halving_width, progress=True, inputs=inputs)
    written = res.save(args.out, plots=not args.no_plots)
    print("\n".join(res.summary_lines()))
    print(f"wrote {len(written)} files to {args.out} (samples.npz, refined_model.yaml, summary.json"
          f"{', scatter.png' if not args.no_plots else ''})")
    return 0
