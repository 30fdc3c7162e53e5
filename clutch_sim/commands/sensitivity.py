"""clutch-sim sensitivity: torque sensitivity to mu_f (thesis §3.3) and to every parameter."""
from __future__ import annotations

from clutch_sim.cli import add_params_option
from clutch_sim.commands._common import add_topic_options, load_runs


def add_parser(sub):
    p = sub.add_parser("sensitivity", help="sensitivity of the clutch torque to mu_f and every parameter",
                       description="Thesis eq. 3.19-3.20 at w = 60 rpm, sump 60 C, P = 500 kPa with mu_f +-1 %% "
                                   "(torque_response.*, finite_difference.*), normalised steady-state "
                                   "sensitivities of every parameter by central differences at two step sizes "
                                   "(parameter_sensitivity.*), and with --bags the Morris/collinearity screen of "
                                   "which friction coefficients those bags can identify (identifiability.*).")
    p.add_argument("--out", required=True, metavar="DIR")
    add_params_option(p)
    p.add_argument("--bags", "--bag", dest="bags", nargs="+", default=None, metavar="BAG",
                   help="car-test bags for the identifiability screen")
    p.add_argument("--duration", type=float, default=3.0, metavar="S", help="simulated time (default 3 s)")
    p.add_argument("--rate", type=float, default=1000.0, metavar="HZ", help="sample rate (default 1000 Hz)")
    p.add_argument("--seed", type=int, default=0, help="seed of the Morris trajectories")
    add_topic_options(p)
    p.set_defaults(func=run)


def _write_csv(path, header, rows):
    import csv

    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)


def run(args) -> int:
    from pathlib import Path

    from clutch_model.errors import ParamsError
    from clutch_model.identification import plots
    from clutch_model.identification.sensitivity import (ThesisScenario, friction_sensitivity,
                                                         identifiability_screen, parameter_sensitivities)
    from clutch_model.plant.params import load_model

    if args.duration <= 0 or args.rate <= 0:
        raise ParamsError("--duration and --rate must be > 0")
    model = load_model(args.params)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sc = ThesisScenario(duration_s=args.duration, rate_hz=args.rate)
    fs = friction_sensitivity(model, sc)
    _write_csv(out / "torque_response.csv", ["t", "torque_nominal", "torque_mu_plus", "torque_mu_minus", "mu_f"],
               ((f"{a:.6g}", repr(float(b)), repr(float(c)), repr(float(d)), repr(float(e))) for a, b, c, d, e in
                zip(fs.t, fs.torque_nominal, fs.torque_plus, fs.torque_minus, fs.mu_f)))
    _write_csv(out / "finite_difference.csv", ["t", "dT_dmu_f", "normalized"],
               ((f"{a:.6g}", repr(float(b)), repr(float(c))) for a, b, c in zip(fs.t, fs.sensitivity, fs.normalized)))
    plots.sensitivity_figures(fs, out)
    s_abs, s_norm = fs.steady_mean()
    print(f"mu_f sensitivity (eq. 3.20) at steady state (t >= {fs.steady_from_s:.2f} s): dT/dmu_f = "
          f"{s_abs:.1f} N*m, normalised {s_norm:.3f}")
    rows, t_ss, t_mean = parameter_sensitivities(model, sc)
    _write_csv(out / "parameter_sensitivity.csv",
               ["rank", "parameter", "value", "normalized_step_1e-2", "normalized_step_1e-3", "steps_agree"],
               ((j + 1, r.name, repr(r.value), f"{r.s_coarse:.6g}", f"{r.s_fine:.6g}", r.agree)
                for j, r in enumerate(rows)))
    plots.parameter_ranking_figure(rows, out)
    print(f"normalised steady-state sensitivities (dT/dp)(p/T), mean torque {t_mean:.1f} N*m, top 10:")
    for r in rows[:10]:
        print(f"  {r.name:32s} {r.s: .4f}{'' if r.agree else '  (step sizes disagree)'}")
    bad = [r.name for r in rows if not r.agree]
    if bad:
        print(f"step sizes disagree for: {', '.join(bad)}")
    if args.bags:
        runs = load_runs(args, args.bags)
        scr = identifiability_screen(model, runs, seed=args.seed)
        tab = scr.table()
        _write_csv(out / "identifiability.csv", list(tab[0].keys()), (list(r.values()) for r in tab))
        plots.identifiability_figure(scr, out)
        print(f"identifiable from the bags: {', '.join(f'a{k}' for k in scr.selected) or 'none'} "
              f"(collinearity index {scr.collinearity:.1f}; threshold {scr.threshold_nm:.3g} N*m)")
    print(f"wrote {out}/torque_response.(csv|png), finite_difference.(csv|png), parameter_sensitivity.(csv|png)"
          + (", identifiability.(csv|png)" if args.bags else ""))
    return 0
