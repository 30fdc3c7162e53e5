"""`clutch-sim synth`: generate a synthetic test campaign (the virtual test car).

    clutch-sim synth --out DIR [--seed S] [--runs N] [--duration S]
        [--mechanism ID [--magnitude X] | --extra-effect NAME [--magnitude X]]
        [--friction-spread F] [--torque-noise NM] [--pack-temperature]
        [--storage mcap|sqlite3] [--compression none|lz4] [--params BASE.yaml]

Writes DIR/bench.csv, DIR/bags/run_00 ... (one rosbag2 bag per run), DIR/truth.yaml (the
true model, for tests; diagnose never reads it) and DIR/campaign.json (schedule and truth
metadata). Magnitudes: see clutch_model.virtual_car.campaign (module docstring).
"""
from __future__ import annotations

EXTRA_EFFECTS = ("torque_ripple", "pressure_temperature_cross")


def mechanism_ids() -> tuple:
    """The catalog's ids (the mechanism objects are the one source)."""
    from clutch_model.plant.mechanisms import CATALOG

    return tuple(CATALOG)


def magnitude_parameters() -> str:
    from clutch_model.plant.mechanisms import CATALOG

    return ", ".join(f"{cls.magnitude_parameter()} ({mid})" for mid, cls in CATALOG.items())


def add_parser(subparsers) -> None:
    from clutch_sim.cli import add_params_option

    p = subparsers.add_parser(
        "synth", help="generate a synthetic car-test campaign (bags, bench CSV, truth)",
        description="Virtual test car: simulate a seeded eLSD test campaign from a perturbed "
                    "reference clutch (optionally with a hidden mechanism or an effect outside "
                    "the catalog) and write noisy car-test bags, the SAE#2 bench table and the "
                    "truth.")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--seed", type=int, default=0, help="random seed; same seed, same files (default 0)")
    p.add_argument("--runs", type=int, default=12, metavar="N", help="number of test runs = bags (default 12)")
    p.add_argument("--duration", type=float, default=9.0, metavar="S", help="duration of a run, s (default 9)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--mechanism", choices=mechanism_ids(), default=None,
                   help="hidden catalog mechanism in the true car")
    g.add_argument("--extra-effect", dest="extra_effect", choices=EXTRA_EFFECTS, default=None,
                   help="hidden effect outside the catalog (a diagnosis should say 'unexplained')")
    p.add_argument("--magnitude", type=float, default=None, metavar="X",
                   help=f"the mechanism's parameter ({magnitude_parameters()}) or the extra "
                        "effect's amplitude; default: a typical visible value")
    p.add_argument("--friction-spread", dest="friction_spread", type=float, default=0.05,
                   metavar="F", help="relative spread of the true friction coefficients around "
                                     "the base model's, uniform +-F (default 0.05)")
    p.add_argument("--torque-noise", dest="torque_noise", type=float, default=8.0, metavar="NM",
                   help="torque sensor white-noise sigma, N*m (default 8)")
    p.add_argument("--pack-temperature", dest="pack_temperature", action="store_true",
                   help="also log /clutch/pack_temperature (10 Hz)")
    p.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap", help="bag storage (default mcap)")
    p.add_argument("--compression", choices=("none", "lz4"), default="none",
                   help="MCAP chunk compression (default none)")
    add_params_option(p)
    from clutch_sim.commands._car_logs import add_car_logs_options
    add_car_logs_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    import sys

    from clutch_model.errors import ParamsError
    from clutch_model.plant.params import load_model
    from clutch_model.virtual_car.campaign import (CampaignSpec, check_output_dir, run_names,
                                    synthesize_campaign, write_campaign)

    if getattr(args, "conditions", "lab") == "car-logs":
        from clutch_sim.commands._car_logs import run_car_logs
        return run_car_logs(args)
    if args.magnitude is not None and not (args.mechanism or args.extra_effect):
        raise ParamsError("--magnitude needs --mechanism or --extra-effect")
    if args.compression != "none" and args.storage != "mcap":
        raise ParamsError("--compression lz4 needs --storage mcap")
    base = load_model(args.params)
    spec = CampaignSpec(seed=args.seed, n_runs=args.runs, run_duration_s=args.duration,
                        mechanism=args.mechanism, extra_effect=args.extra_effect,
                        magnitude=args.magnitude, friction_spread=args.friction_spread,
                        torque_noise_nm=args.torque_noise,
                        include_pack_temperature=args.pack_temperature)
    spec.validate()
    check_output_dir(args.out, run_names(spec.n_runs))

    def note(msg):
        print(f"synth: {msg}", file=sys.stderr)

    note(f"simulating {spec.n_runs} runs (seed {spec.seed})")
    result = synthesize_campaign(spec, base_model=base)
    try:
        from tqdm import tqdm
        bar = tqdm(total=len(result.runs), desc="writing bags", unit="bag", file=sys.stderr,
                   leave=False, disable=None)
    except ImportError:  # pragma: no cover
        bar = None

    def progress(_name):
        if bar is not None:
            bar.update(1)

    try:
        paths = write_campaign(result, args.out, storage=args.storage,
                               compression=args.compression, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    meta = result.metadata
    hidden = (f"mechanism {meta['mechanism']}" if meta["mechanism"]
              else f"extra effect {meta['extra_effect']['name']} "
                   f"(magnitude {meta['extra_effect']['magnitude']:g})" if meta["extra_effect"]
              else "no hidden mechanism")
    print(f"wrote {len(paths['bags'])} bags to {paths['bags'][0].parent}")
    print(f"bench table: {paths['bench']} ({len(result.bench)} rows)")
    print(f"truth: {paths['truth']} ({hidden}; expected diagnosis: {result.expected_cause})")
    print(f"campaign metadata: {paths['metadata']}")
    return 0
