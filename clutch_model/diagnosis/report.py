"""report.json, report.html and the evidence plots of a diagnosis."""
from __future__ import annotations

import html
import json
import math
from pathlib import Path

import numpy as np

from clutch_model.formats.results import jsonable
from clutch_model.plant.params import save_model
from clutch_model.diagnosis import features as F
from clutch_model.diagnosis.engine import Diagnosis
from clutch_model.diagnosis.structure_test import EncompassingTest


def _co_fitted(fitted) -> dict:
    """{"co_fitted": {mech_id: {parameter: value}}} of the causes already in the model that a
    candidate's fit moved with its own parameters (fitting.co_fitted_ids), or {}."""
    co = getattr(getattr(fitted, "fit", None), "co_parameters", None)
    return {"co_fitted": dict(co)} if co else {}


def _plain_squares(test) -> dict:
    """A plain-squares block test (structure_test.PlainCrossFit) as report.json shows it."""
    return {"t": test.t_stat, "p": test.p_value, "blocks": test.n_blocks, "mean_square_cut": test.cut_frac}


def _encompassing(test) -> dict:
    """An encompassing test (structure_test.EncompassingTest) as report.json shows it."""
    return {"t": test.t_stat, "p": test.p_value, "blocks": test.n_blocks, "weight": test.weight,
            "noise_order": test.noise_order}


def report_dict(d: Diagnosis) -> dict:
    cand = []
    for sc in d.scores:
        f, c = sc.fitted.fit, sc.comparison
        cand.append({"id": sc.id, "held_out_rmse_nm": f.held_out_rmse_nm, "fit_rmse_nm": f.fit_rmse_nm,
                     "parameters": f.parameters, "refit_with_friction": f.joint,
                     "friction_correction": [float(v) for v in f.friction_correction],
                     "held_out_t": c.t_stat, "held_out_p": c.p_value, "held_out_delta_loglik": c.delta_ll,
                     "innovation_variance_cut": c.gain_frac, "significant": sc.significant})
    cand.sort(key=lambda c: c["held_out_rmse_nm"] if c["held_out_rmse_nm"] is not None else math.inf)
    sel = d.selection
    steps = []
    for k, st in enumerate(sel.steps if sel else []):
        steps.append({"step": k + 1, "chosen": st.chosen, "look_ahead": st.look_ahead, "replaced_by": st.replaced_by,
                      "lookalikes": st.lookalikes,
                      "parted_in_plain_squares": {rival: _plain_squares(test) for rival, test in st.parted.items()
                                                  if not isinstance(test, EncompassingTest)},
                      "parted_by_encompassing": {rival: _encompassing(test) for rival, test in st.parted.items()
                                                 if isinstance(test, EncompassingTest)},
                      "scores": [{"id": sc.id, "held_out_t": sc.comparison.t_stat,
                                  "held_out_p": sc.comparison.p_value,
                                  "innovation_variance_cut": sc.comparison.gain_frac,
                                  "parameters": sc.fitted.parameters,
                                  **_co_fitted(sc.fitted),
                                  **({"against_twin": {"held_out_t": sc.own.t_stat,
                                                       "plain_gain_frac": sc.own.plain_gain_frac,
                                                       "held_out_pieces_rmse_nm": sc.own_pieces}}
                                     if sc.own not in (None, False) else {})} for sc in st.scores]})

    def structure(st):
        if st is None:
            return None
        out = {"structured": st.structured, "held_out_t": st.comparison.t_stat, "held_out_p": st.p_value,
               "innovation_variance_cut": st.gain_frac, "follows": st.top_features(3)}
        if st.plain is not None:
            out["cross_fit_plain"] = _plain_squares(st.plain)
        return out

    cause = {"id": d.cause_id, "evidence": d.evidence, "parameters": d.cause_parameters,
             "parameters_ci95": d.cause_ci95}
    return jsonable({
        "status": "complete",
        "cause": cause,
        "causes": d.causes,
        "rmse_nm": {"nominal": d.rmse["nominal"], "calibrated": d.rmse["calibrated"],
                    "extended": d.rmse["extended"], "bench_fit": d.rmse["bench"]},
        "gain_pct": d.gain_pct,
        "held_out_runs": d.held_out,
        "fit_runs": d.fit_runs,
        "split": d.split.how if d.split else "",
        "locked_rows": d.locked_rows,
        "noise_model": d.noise,
        "noise_sigma_nm": d.sigma_nm,
        "candidates": cand,
        "selection": {"verdict": sel.verdict if sel else None, "reason": sel.reason if sel else "",
                      "steps": steps,
                      "baseline_structure": structure(sel.baseline_structure) if sel else None,
                      "remainder_structure": structure(sel.remainder_structure) if sel else None,
                      "closest": sel.closest if sel else [], "closest_leaves": sel.closest_leaves if sel else {},
                      "run_level": sel.run_level.as_dict() if sel and sel.run_level is not None else None,
                      "force_path_check": d.force_path_check,
                      "lag_rival_checks": d.lag_rival_checks,
                      "force_band_check": d.force_band_check,
                      "force_offset_check": d.force_offset_check,
                      "force_ceiling_check": d.force_ceiling_check,
                      "sump_offset_check": d.sump_offset_check,
                      "wear_preload_check": d.wear_preload_check,
                      "plain_rival_check": d.plain_rival_check,
                      "torque_line_check": d.torque_line_check,
                      "bench_anchor": d.bench_anchor,
                      "ridged_selection": d.ridged_selection,
                      "discovery": ({"accepted": d.discovery.accepted, "reason": d.discovery.selection.reason,
                                     "tried": d.discovery.tried()} if d.discovery is not None else None)},
        "residual_features_r2": d.features_r2,
        "bench_fit": d.bench_info,
        "calibration": d.calibration_info,
        "timings_s": d.timings,
        "diagnosis_rate": d.diagnosis_rate,
        "diagnosis_sample": d.diagnosis_sample,
        "inputs": d.inputs,
    })


def _plots(d: Diagnosis, out: Path) -> list:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = d.campaign
    files = []
    held = d.eval_mask if d.eval_mask is not None else np.isin(c.run_index, [c.names.index(n) for n in d.held_out])
    cal_pred = d.calibrated_fit.predicted
    ext_pred = d.extended_fit.predicted if d.extended_fit else cal_pred
    resid = d.calibrated_fit.residual

    # 1. held-out runs: measured vs models
    held_runs = d.held_out_runs
    runs = [r for r in c.runs if r.name in held_runs]
    fig, axes = plt.subplots(len(runs), 1, figsize=(10, 2.6 * len(runs)), squeeze=False)
    for ax, (r, sl) in zip(axes[:, 0], [(r, sl) for r, sl in c.slices() if r.name in held_runs]):
        ax.plot(r.t, c.torque_measured[sl], ".", ms=1.5, color="0.5", label="measured")
        ax.plot(r.t, d.nominal_pred[sl], lw=1, color="tab:orange", label="nominal RC-1")
        ax.plot(r.t, cal_pred[sl], lw=1, color="tab:blue", label="calibrated")
        if d.extended_fit:
            ax.plot(r.t, ext_pred[sl], lw=1, color="tab:green", label=f"extended ({d.cause_id})")
        ax.set_title(f"held-out run {r.name}", fontsize=9)
        ax.set_ylabel("torque [N·m]")
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(out / "torque_held_out.png", dpi=90)
    plt.close(fig)
    files.append(("torque_held_out.png", "Held-out runs: measured torque and the models"))

    # 2. residual against the candidate features
    sim = d.calibrated_sim
    fr = F.feature_signals(c, sim)
    dfdt = fr["force rate dF/dt"][:, 0]
    theta = sim.pack_temperature_c
    energy = sim.energy_j
    panels = [("t (campaign order) [s]", _campaign_time(c)), ("applied force [N]", c.force),
              ("force rate (normalised)", dfdt), ("slip speed [rad/s]", c.slip),
              ("pack temperature [°C]", theta), ("dissipated energy [J]", energy)]
    fig, axes = plt.subplots(2, 3, figsize=(12, 6))
    for ax, (label, x) in zip(axes.ravel(), panels):
        ax.plot(x[~held], resid[~held], ".", ms=1, alpha=0.3, color="tab:blue", label="fit runs")
        ax.plot(x[held], resid[held], ".", ms=1, alpha=0.3, color="tab:red", label="held-out")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_xlabel(label, fontsize=8)
        ax.set_ylabel("residual [N·m]", fontsize=8)
    axes[0, 0].legend(fontsize=7, markerscale=8)
    fig.suptitle("Calibrated baseline: residual (measured − simulated) against what it might follow", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "residuals.png", dpi=90)
    plt.close(fig)
    files.append(("residuals.png", "Residual of the calibrated baseline against time, force, force rate, slip, temperature and energy"))

    # 3. lag cross-correlation and 4. hysteresis loops and 5. drift
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    dt = float(np.median(np.diff(c.t[~c.run_start]))) if c.t.size > 2 else 0.005
    lags, corr = F.lag_cross_correlation(c.torque_measured, cal_pred, c.run_start, dt)
    axes[0].plot(lags * 1e3, corr)
    k = int(np.argmax(corr))
    axes[0].axvline(lags[k] * 1e3, color="r", lw=0.8)
    axes[0].set_title(f"lag cross-correlation: peak at {lags[k] * 1e3:.0f} ms", fontsize=9)
    axes[0].set_xlabel("lag of measured vs simulated [ms]")
    r0, sl0 = next((r, sl) for r, sl in c.slices() if r.name == held_runs[0])
    axes[1].plot(c.force[sl0], c.torque_measured[sl0], ".", ms=1.5, color="0.5", label="measured")
    axes[1].plot(c.force[sl0], cal_pred[sl0], lw=0.8, color="tab:blue", label="calibrated")
    axes[1].set_title(f"torque vs force, run {r0.name} (hysteresis loop)", fontsize=9)
    axes[1].set_xlabel("applied force [N]")
    axes[1].set_ylabel("torque [N·m]")
    axes[1].legend(fontsize=7)
    drift = F.drift_per_run(c, resid, cal_pred)
    e_end = [float(energy[sl][-1]) for _, sl in c.slices()]
    colors = ["tab:red" if name in held_runs else "tab:blue" for name, *_ in drift]
    axes[2].scatter(e_end, [100 * x[2] for x in drift], c=colors)
    axes[2].axhline(0, color="k", lw=0.5)
    axes[2].set_title("drift over the campaign (red: held-out)", fontsize=9)
    axes[2].set_xlabel("dissipated energy at run end [J]")
    axes[2].set_ylabel("mean residual / mean torque [%]")
    fig.tight_layout()
    fig.savefig(out / "lag_hysteresis_drift.png", dpi=90)
    plt.close(fig)
    files.append(("lag_hysteresis_drift.png", "Lag cross-correlation, torque-vs-force loop, drift per run"))

    # 6. candidates
    fig, ax = plt.subplots(figsize=(8, 3.2))
    ids = [f.id for f in d.candidates]
    vals = [f.held_out_rmse_nm for f in d.candidates]
    ax.barh(ids, vals, color=["tab:green" if i == d.cause_id else "0.6" for i in ids])
    ax.axvline(d.rmse["calibrated"], color="tab:blue", lw=1, label="calibrated baseline")
    ax.axvline(d.sigma_nm, color="k", ls="--", lw=1, label="noise level")
    ax.set_xlabel("held-out RMSE [N·m]")
    ax.invert_yaxis()
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "candidates.png", dpi=90)
    plt.close(fig)
    files.append(("candidates.png", "Held-out RMSE of every refitted candidate"))
    return files


def _campaign_time(c):
    out = np.empty_like(c.t)
    offset = 0.0
    for r, sl in c.slices():
        out[sl] = r.t - r.t[0] + offset
        offset = out[sl][-1] + 1.0
    return out


def _write_text(path: Path, text: str) -> None:
    """Write through a temporary file and rename, so an interrupted run never leaves half a file."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)


def _save_model(model, path: Path, header: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    save_model(model, tmp, header=header)
    tmp.replace(path)


class ProgressiveReport:
    """Writes each output of a diagnosis as soon as it is known (engine checkpoint): the split
    and the calibrated model first (calibrated_model.yaml, extended_model.yaml = the
    calibrated model until a cause is named, a report.json with ``status``), then the whole
    report. Ctrl-C keeps what was written."""

    def __init__(self, out_dir, plots: bool = True, joins=None):
        self.out = Path(out_dir)
        self.plots = plots
        self.joins = joins          # continued_bags.Joins: bags diagnosed as one drive, or None
        self.out.mkdir(parents=True, exist_ok=True)
        self.partial = {"status": "started"}

    def _partial(self, status: str, **fields):
        self.partial.update(fields)
        self.partial["status"] = status
        rep = in_bag_terms(jsonable(self.partial), self.joins)
        _write_text(self.out / "report.json", json.dumps(rep, indent=2, allow_nan=False))

    def __call__(self, stage: str, **kw):
        if stage == "split":
            self._partial("split done; calibrating", held_out_runs=kw["split"].labels, split=kw["split"].how,
                          locked_rows=kw.get("locked_rows", 0), diagnosis_rate=kw.get("diagnosis_rate"),
                          diagnosis_sample=kw.get("diagnosis_sample"), inputs=kw.get("inputs"))
        elif stage == "calibrated":
            header = "clutch-sim diagnose: calibrated baseline (bench fit + car calibration)"
            _save_model(kw["model"], self.out / "calibrated_model.yaml", header)
            _save_model(kw["model"], self.out / "extended_model.yaml",
                        "clutch-sim diagnose: extended model (= the calibrated model until a cause is named)")
            self._partial("calibrated; naming causes", rmse_nm=dict(kw["rmse"]), calibration=kw.get("info", {}))
        elif stage == "selected":
            write_report(kw["diagnosis"], self.out, plots=self.plots, joins=self.joins)


def in_bag_terms(rep: dict, joins) -> dict:
    """The report with the labels of bags the diagnosis joined into one drive
    (continued_bags) given in the bags' own terms, and what was joined."""
    if joins is None or not joins.checks:
        return rep
    rep = dict(rep)
    for key in ("held_out_runs", "fit_runs"):
        if isinstance(rep.get(key), list):
            rep[key] = joins.relabel(rep[key])
    sample = rep.get("diagnosis_sample")
    if isinstance(sample, dict) and isinstance(sample.get("windows"), list):
        rep["diagnosis_sample"] = {**sample, "windows": joins.relabel(sample["windows"])}
    rep["continued_bags"] = joins.as_dict()
    return rep


def write_report(d: Diagnosis, out_dir, plots: bool = True, joins=None) -> dict:
    """report.json, both models and report.html, with the figures unless ``plots`` is False
    (drawing them is about a fifth of a short diagnosis); ``joins``: bags diagnosed as one
    drive (continued_bags.Joins), reported in the bags' own terms."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rep = in_bag_terms(report_dict(d), joins)
    _save_model(d.calibrated_model, out / "calibrated_model.yaml",
                "clutch-sim diagnose: calibrated baseline (bench fit + car calibration)")
    _save_model(d.extended_model, out / "extended_model.yaml",
                f"clutch-sim diagnose: extended model, cause = {d.cause_id}"
                + (f" ({', '.join(c['id'] for c in d.causes)})" if len(d.causes) > 1 else ""))
    _write_text(out / "report.json", json.dumps(jsonable(rep), indent=2, allow_nan=False) + "\n")
    files = _plots(d, out) if plots else []
    _write_text(out / "report.html", _html(d, rep, files))
    return rep


def _html(d: Diagnosis, rep: dict, files) -> str:
    e = html.escape
    verdict = {"none": "No structural discrepancy beyond noise and calibration",
               "unexplained": "Structure that no known mechanism explains"}.get(
        d.cause_id, "Cause" + ("s: " if len(d.causes) > 1 else ": ") + ", ".join(c["id"] for c in d.causes))

    def interval(c, k, v):
        lo, hi = c.get("parameters_ci95", {}).get(k, (None, None))
        ci = f" (95 %: {lo:.4g} – {hi:.4g})" if lo is not None and hi is not None else ""
        return f"{k} = {v:.4g}{ci}"

    if d.causes:
        params = "; ".join(e(", ".join(interval(c, k, v) for k, v in c["parameters"].items())) for c in d.causes)
    elif d.cause_id == "unexplained" and d.selection is not None and d.selection.closest:
        left = d.selection.closest_leaves
        params = e(f"closest: {', '.join(d.selection.closest)}, which leaves a held-out RMSE of "
                   f"{left.get('held_out_rmse', float('nan')):.2f} N·m"
                   + (f" with structure the inputs predict ({left['structure_found_by']})"
                      if "structure_found_by" in left else ""))
    else:
        params = ""
    rows = []
    for c in rep["candidates"]:
        cut = c.get("innovation_variance_cut")
        expl = "" if cut is None else f"{100 * cut:.1f} %"
        z = "" if c.get("held_out_t") is None else f"{c['held_out_t']:.1f}"
        pars = ", ".join(f"{k}={v:.4g}" for k, v in c["parameters"].items())
        cls = " class=win" if c["id"] == d.cause_id else ""
        star = " *" if c["refit_with_friction"] else ""
        rows.append(f"<tr{cls}><td>{e(c['id'])}{star}</td><td>{c['held_out_rmse_nm']:.2f}</td>"
                    f"<td>{c['fit_rmse_nm']:.2f}</td><td>{expl}</td><td>{z}</td><td>{e(pars)}</td></tr>")
    rows = "".join(rows)
    r = rep["rmse_nm"]
    imgs = "".join(f"<figure><img src='{e(f)}' alt='{e(cap)}'><figcaption>{e(cap)}</figcaption></figure>"
                   for f, cap in files) or "<p>(figures not drawn: diagnose --no-plots)</p>"
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>clutch-sim diagnosis</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:1em auto;color:#222}}
.verdict{{font-size:1.5em;padding:.5em;background:#eef5ee;border-left:6px solid #2a2}}
table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}}
td:first-child{{text-align:left}}tr.win{{background:#dfd}}img{{max-width:100%}}</style></head><body>
<div class="verdict">{e(verdict)}{(' — ' + params) if params else ''}</div>
<p><b>Gain on held-out runs:</b> RMSE {r['calibrated']:.2f} → {r['extended']:.2f} N·m
({rep['gain_pct']:.1f} %); nominal RC-1 {r['nominal']:.2f} N·m; noise level {d.sigma_nm:.2f} N·m (estimated from the data).</p>
<p>{e(d.evidence)}</p>
<p><b>Held-out runs:</b> {e(', '.join(d.held_out))} — {e(rep['split'])}.</p>
<h3>Candidates (each mechanism fitted on the fit runs; * = refitted jointly with the baseline's friction correction)</h3>
<table><tr><th>id</th><th>held-out RMSE [N·m]</th><th>fit RMSE</th><th>cuts the held-out innovation variance by</th><th>held-out t</th><th>parameters</th></tr>
{rows}</table>
<h3>Evidence</h3>{imgs}
<p style="color:#777">Files: report.json, calibrated_model.yaml, extended_model.yaml.</p>
</body></html>"""
