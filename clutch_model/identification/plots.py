"""Figures of the identification tools (matplotlib, Agg backend, PNG)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from clutch_model.identification import box


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def montecarlo_scatter(result, outdir, coefficients=None) -> list:
    """Figures 6.11-6.16 as ONE figure, ``DIR/scatter.png``: a panel per varied coefficient
    (value vs RMSE of the samples that beat the nominal, their mean in red, the nominal dashed,
    the nominal RMSE dotted). One figure and one savefig: drawing ~21 separate figures used to
    cost more than the Monte Carlo simulation itself."""
    plt = _plt()
    out = Path(outdir)
    better = result.better
    ks = list(result.varied if coefficients is None else coefficients)
    if not ks:
        return []
    pct = f"{result.spread * 100:g}%"
    A, r = result.samples, result.rmse
    ncol = min(5, len(ks))
    nrow = int(np.ceil(len(ks) / ncol))
    # fixed margins and few ticks: tight_layout and tick layout of 20 axes cost more than the drawing
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.0 * ncol + 0.6, 2.4 * nrow + 0.6), squeeze=False,
                             sharey=True)
    for ax, k in zip(axes.ravel(), ks):
        ax.locator_params(axis="x", nbins=3)
        ax.locator_params(axis="y", nbins=4)
        if better.any():
            ax.scatter(A[better, k], r[better], s=3, alpha=0.5, color="tab:blue", rasterized=True,
                       linewidths=0)
            ax.axvline(result.mean_better[k], color="tab:red", lw=1.2)
        ax.axvline(result.nominal_a[k], color="k", lw=0.9, ls="--")
        ax.axhline(result.rmse_nominal, color="0.5", lw=0.8, ls=":")
        ax.set_title(f"a{k} ({box.BLOCK_OF[k]}: {box.MONOMIAL[k % 5]})", fontsize=7)
        ax.tick_params(labelsize=6)
        ax.xaxis.get_offset_text().set_fontsize(6)
    for ax in axes[:, 0]:
        ax.set_ylabel("torque RMSE [N m]", fontsize=7)
    for ax in axes.ravel()[len(ks):]:
        ax.axis("off")
    fig.suptitle(f"Monte Carlo (+-{pct}): {int(better.sum())} of {result.n_evaluated} samples beat the "
                 f"nominal RMSE {result.rmse_nominal:.2f} N m (dotted); red = their mean, dashed = nominal",
                 fontsize=9)
    fig.subplots_adjust(left=0.06, right=0.99, bottom=0.05, top=1 - 0.75 / fig.get_figheight(),
                        wspace=0.25, hspace=0.45)
    p = out / "scatter.png"
    fig.savefig(p, dpi=90)
    plt.close(fig)
    return [p]


def sensitivity_figures(fs, outdir) -> list:
    """Figures 3.6 (torque response, nominal and +-1 % mu_f) and 3.7 (finite difference)."""
    plt = _plt()
    out = Path(outdir)
    sc = fs.scenario
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.plot(fs.t, fs.torque_nominal, label="nominal")
    ax.plot(fs.t, fs.torque_plus, lw=0.8, label=f"mu_f +{fs.rel_step:.0%}")
    ax.plot(fs.t, fs.torque_minus, lw=0.8, label=f"mu_f -{fs.rel_step:.0%}")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("clutch torque [N m]")
    ax.set_title(f"Clutch torque response (w = {sc.slip_rad_s:.3g} rad/s, sump {sc.sump_c:g} C, "
                 f"P = {sc.pressure_mpa * 1000:g} kPa)", fontsize=9)
    ax.legend()
    fig.tight_layout()
    p1 = out / "torque_response.png"
    fig.savefig(p1, dpi=110)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.plot(fs.t, fs.sensitivity)
    ax.axvline(fs.steady_from_s, color="0.5", ls=":", label=f"steady state from {fs.steady_from_s:.2f} s")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("dT_clu / dmu_f [N m]")
    ax.set_title("Finite difference sensitivity (eq. 3.20)", fontsize=9)
    ax.legend()
    fig.tight_layout()
    p2 = out / "finite_difference.png"
    fig.savefig(p2, dpi=110)
    plt.close(fig)
    return [p1, p2]


def parameter_ranking_figure(rows, outdir, top: int = 25) -> Path:
    plt = _plt()
    rows = [r for r in rows if abs(r.s) > 0][:top]
    fig, ax = plt.subplots(figsize=(7.0, 0.28 * max(len(rows), 4) + 1.2))
    y = np.arange(len(rows))[::-1]
    ax.barh(y, [r.s for r in rows], color=["tab:blue" if r.agree else "tab:orange" for r in rows])
    ax.set_yticks(y)
    ax.set_yticklabels([r.name for r in rows], fontsize=7)
    ax.axvline(0, color="k", lw=0.6)
    ax.set_xlabel("normalised sensitivity (dT/dp) p/T at steady state")
    ax.set_title("Torque sensitivity to every parameter (orange: step sizes disagree)", fontsize=9)
    fig.tight_layout()
    p = Path(outdir) / "parameter_sensitivity.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    return p


def identifiability_figure(screen, outdir) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8.0, 3.8))
    x = np.arange(20)
    col = ["tab:green" if k in screen.selected else ("tab:orange" if k in screen.candidates else "0.6")
           for k in x]
    floor = max(screen.threshold_nm, 1e-9) * 1e-3
    ax.bar(x, np.maximum(screen.effect_nm, floor), color=col)
    ax.set_yscale("log")
    ax.set_ylim(floor, max(float(screen.effect_nm.max()), screen.threshold_nm) * 3)
    for k in x:
        if screen.effect_nm[k] <= 0:
            ax.text(k, floor * 1.5, "0", ha="center", va="bottom", fontsize=7, color="0.3")
    ax.axhline(screen.threshold_nm, color="k", ls=":", lw=0.8, label=f"threshold {screen.threshold_nm:.3g} N m")
    ax.set_xticks(x)
    ax.set_xticklabels([f"a{k}" for k in x], fontsize=7)
    ax.set_ylabel("Morris mu* [N m RMS]")
    ax.set_title("Which friction coefficients the car data identifies (green: selected, orange: collinear "
                 "with the selected, 0: no effect at all)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    p = Path(outdir) / "identifiability.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    return p


def friction_fit_figure(fit, bench, path) -> Path:
    """Figures 6.7-6.9 style: fitted mu_f vs slip at a few pressures for the bench's sump
    temperatures, with the bench points."""
    from clutch_model.plant.friction import stribeck

    plt = _plt()
    th_levels = np.unique(np.round(np.asarray(bench.plate_temperature_c) / 40.0) * 40.0)[:4]
    fig, axes = plt.subplots(1, len(th_levels), figsize=(4.0 * len(th_levels), 3.6), squeeze=False)
    w = np.geomspace(max(np.min(np.abs(bench.slip_speed_rad_s)), 1e-4), np.max(np.abs(bench.slip_speed_rad_s)), 200)
    for ax, th in zip(axes[0], th_levels):
        near = np.abs(bench.plate_temperature_c - th) < 20
        for pr in (1.0, 5.0, 10.0, 20.0):
            ax.plot(w, stribeck(fit.a, fit.i, w, np.full_like(w, pr), np.full_like(w, th)), label=f"{pr:g} MPa")
        ax.scatter(np.abs(bench.slip_speed_rad_s[near]), bench.friction_coefficient[near], s=4, color="k", alpha=0.4)
        ax.set_xscale("log")
        ax.set_xlabel("slip speed [rad/s]")
        ax.set_title(f"theta ~ {th:g} C", fontsize=9)
    axes[0][0].set_ylabel("friction coefficient")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)
