"""`clutch-sim synth --conditions car-logs`: the car-log virtual test car (options and run).

Kept apart from synth.py so the lab campaign's options stay as they are; synth.py only adds
``--conditions`` and hands car-logs runs to ``run_car_logs``.
"""
from __future__ import annotations

# the virtual car's effects (car_logs.EFFECTS, whose module the help must not import: numerics)
EFFECT_NAMES = ("torque_sensor_lowpass", "torque_sensor_thermal_offset", "torque_ripple", "slip_power_fade",
                "slip_acceleration_friction", "pressure_temperature_cross", "run_friction_level",
                "actuator_rate_limit", "actuator_second_order", "actuator_backlash", "torque_judder",
                "force_sensor_hysteresis", "force_sensor_lag", "torque_sensor_gain", "force_sensor_offset",
                "actuator_asymmetric_lag", "actuator_force_dependent_lag", "torque_sensor_asymmetric_lag",
                "torque_sensor_resonance", "actuator_force_delay", "actuator_force_ceiling",
                "actuator_oil_temperature_lag")

CHANNEL_KEYS = {"force": "applied_force", "slip": "slip_speed", "sump": "sump_temperature",
                "torque": "measured_torque", "pack": "pack_temperature"}


def add_car_logs_options(p) -> None:
    g = p.add_argument_group("car-log conditions (with --conditions car-logs)")
    g.add_argument("--conditions", choices=("lab", "car-logs"), default="lab",
                   help="lab: the 200 Hz single-grid campaign (default); car-logs: topics on their "
                        "own clocks, noise classes, controller drive, lock-up (docs/virtual_car.md)")
    g.add_argument("--schedule", choices=("short-runs", "few-long", "long-drive"), default="short-runs",
                   help="10 runs x 10 s, 3 x 60 s, or one 240 s bag (default short-runs)")
    g.add_argument("--car-runs", type=int, default=None, metavar="N", help="override the schedule's run count")
    g.add_argument("--car-duration", type=float, default=None, metavar="S", help="override the schedule's run duration")
    g.add_argument("--car-mechanism", action="append", default=[], metavar="ID[=X]",
                   help="catalog mechanism in the true car (repeat for two at once), e.g. actuator_lag=0.1")
    g.add_argument("--effect", action="append", default=[], metavar="NAME[=X|:k=v,...]",
                   help="effect outside the catalog (or a sensor's gain): " + ", ".join(EFFECT_NAMES))
    g.add_argument("--torque-noise-model", default=None, metavar="SPEC",
                   help="torque sensor noise class, e.g. ar1:sigma=8,phi=0.95 | lowpass:sigma=8,cutoff_hz=10 | "
                        "held:sigma=8,update_hz=10 | median:sigma=8,window=5 | drift:sigma=8,drift=10,tau_s=20 "
                        "(default white with --torque-noise)")
    g.add_argument("--slip-noise-model", default=None, metavar="SPEC", help="slip sensor noise class (default white:sigma=0.05)")
    g.add_argument("--rate", action="append", default=[], metavar="TOPIC=HZ",
                   help="topic rate (force, slip, sump, torque, pack), e.g. torque=50 (defaults 200/100/10/50/10)")
    g.add_argument("--jitter", action="append", default=[], metavar="TOPIC=S",
                   help="uniform sampling jitter half-width, e.g. force=0.001")
    g.add_argument("--no-lockup", dest="lockup", action="store_false", help="no lock-up phases")
    g.add_argument("--slip-sign-changes", action="store_true",
                   help="the slip changes sign between segments (crosses 0 while slipping)")


def _pairs(items, what):
    from clutch_model.errors import ParamsError

    out = {}
    for item in items:
        key, _, val = item.partition("=")
        if key not in CHANNEL_KEYS:
            raise ParamsError(f"--{what} {item}: topic must be one of {', '.join(CHANNEL_KEYS)}")
        try:
            out[CHANNEL_KEYS[key]] = float(val)
        except ValueError:
            raise ParamsError(f"--{what} {item}: '{val}' is not a number") from None
    return out


def run_car_logs(args) -> int:
    import sys

    from clutch_model.plant.params import load_model
    from clutch_model.virtual_car.car_logs import (DEFAULT_CLOCKS, CarLogSpec, parse_item, parse_noise,
                                                   synthesize_car_logs, write_car_logs)
    from clutch_model.virtual_car.signals import TopicClock, WhiteNoise

    mechs = [parse_item(m, "mechanism") for m in args.car_mechanism]
    if args.mechanism:
        mechs.append(parse_item(args.mechanism + (f"={args.magnitude}" if args.magnitude is not None else ""),
                                "mechanism"))
    effects = [parse_item(e, "effect") for e in args.effect]
    rates, jitters = _pairs(args.rate, "rate"), _pairs(args.jitter, "jitter")
    clocks = {}
    for ch, c in DEFAULT_CLOCKS.items():
        if ch in rates or ch in jitters:
            rate = rates.get(ch, c.rate_hz)
            jit = jitters.get(ch, min(c.jitter_s, 0.25 / rate))
            clocks[ch] = TopicClock(rate, c.phase_s, jit, c.quantum_s)
    noise = {"measured_torque": parse_noise(args.torque_noise_model) if args.torque_noise_model
             else WhiteNoise(args.torque_noise)}
    if args.slip_noise_model:
        noise["slip_speed"] = parse_noise(args.slip_noise_model)
    spec = CarLogSpec(seed=args.seed, schedule=args.schedule, n_runs=args.car_runs,
                      run_duration_s=args.car_duration, clocks=clocks, noise=noise,
                      lockup=args.lockup, slip_sign_changes=args.slip_sign_changes, mechanisms=mechs, effects=effects,
                      friction_spread=args.friction_spread,
                      include_pack_temperature=args.pack_temperature)
    spec.validate()
    print(f"synth: car-logs, {spec.n_runs} run(s) x {spec.run_duration_s:g} s (seed {spec.seed})", file=sys.stderr)
    result = synthesize_car_logs(spec, base_model=load_model(args.params))
    try:
        from tqdm import tqdm
        bar = tqdm(total=len(result.runs), desc="writing bags", unit="bag", file=sys.stderr, leave=False, disable=None)
    except ImportError:  # pragma: no cover
        bar = None
    try:
        paths = write_car_logs(result, args.out, storage=args.storage, compression=args.compression,
                               progress=(lambda _n: bar.update(1)) if bar is not None else None)
    finally:
        if bar is not None:
            bar.close()
    print(f"wrote {len(paths['bags'])} bags to {paths['bags'][0].parent}")
    print(f"bench table: {paths['bench']}")
    print(f"truth: {paths['truth']} and {paths['truth_model']} (expected diagnosis: "
          f"{result.truth['expected_cause']}); noise-free torque per run in {paths['sidecars'][0].parent}")
    return 0
