"""Monte Carlo refinement of the friction coefficients on car-test runs — thesis §5.3, §6.2.2.

1. Samples: a = lb + (ub - lb) U, [lb, ub] = a_nom -+ spread a_nom (eq. 5.15-5.17), all drawn
   up front from numpy's default_rng(seed) as one (N, 20) matrix (coefficients not varied keep
   their nominal value; the draw is the same, so --screen changes nothing else); i fixed.
2. Rejected if mu_f < 0 anywhere in P in [0, 6] MPa, theta in [0, 230] C, w in [0, 30] rad/s
   (``box.friction_positive_many``: exact interval branch-and-bound).
3. Every accepted sample simulated on the runs with the batch simulator, in fixed chunks of
   ``chunk_size`` accepted samples (a chunk is a pure function: ``evaluate.chunk_rmse``);
   serially or on a Dask distributed cluster — same chunks, same floats.
4. The mean of the samples that beat the nominal RMSE (§6.2.2) replaces the varied
   coefficients if it improves the RMSE; then interval halving (table 6.4) on chosen
   coefficients, one after the other, over [a, a + width |a|] in the direction of the trend
   (the mean of the better samples), width 0.4 as in the thesis.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clutch_model.errors import FitError
from clutch_model.formats.results import finite_or_none, write_json
from clutch_model.plant.params import ClutchModel, save_model
from clutch_model.identification import box
from clutch_model.identification.evaluate import CampaignInputs, as_campaign, chunk_rmse, rmse_of
from clutch_model.identification.halving import interval_halving


def draw_samples(a_nominal, n: int, spread: float, seed: int, varied=None) -> np.ndarray:
    """(n, 20) uniform samples around a_nominal (eq. 5.15-5.17)."""
    a = np.asarray(a_nominal, float)
    rng = np.random.default_rng(seed)
    U = rng.random((int(n), a.size))
    lb, ub = a - spread * a, a + spread * a
    A = lb + (ub - lb) * U
    if varied is not None:
        fixed = np.setdiff1d(np.arange(a.size), np.asarray(list(varied), int))
        A[:, fixed] = a[fixed]
    return A


def chunk_indices(accepted: np.ndarray, chunk_size: int) -> list:
    idx = np.flatnonzero(accepted)
    return [idx[k:k + chunk_size] for k in range(0, idx.size, chunk_size)]


@dataclass(frozen=True)
class MonteCarloResult:
    samples: np.ndarray
    rmse: np.ndarray                # nan where rejected
    accepted: np.ndarray
    seed: int
    spread: float
    nominal_a: np.ndarray
    exponent_i: float
    rmse_nominal: float
    varied: list
    mean_better: np.ndarray
    rmse_mean: float
    refined_a: np.ndarray
    rmse_refined: float
    halving: list = field(default_factory=list)
    chunk_size: int = 256
    scheduler: str = "serial"
    elapsed_s: float = 0.0          # simulation phase (incl. Dask cluster start-up)
    startup_s: float = 0.0          # Dask cluster start-up part of elapsed_s
    simulated_seconds_per_sample: float = 0.0
    notes: list = field(default_factory=list)
    refined_model: ClutchModel | None = None

    @property
    def better(self) -> np.ndarray:
        return self.accepted & (np.nan_to_num(self.rmse, nan=np.inf) < self.rmse_nominal)

    @property
    def n_evaluated(self) -> int:
        return int(self.accepted.sum())

    @property
    def samples_per_s(self) -> float:
        return self.n_evaluated / self.elapsed_s if self.elapsed_s > 0 else math.nan

    @property
    def samples_per_s_after_startup(self) -> float:
        dt = self.elapsed_s - self.startup_s
        return self.n_evaluated / dt if dt > 0 else math.nan

    @property
    def best_rmse(self) -> float:
        return float(np.nanmin(self.rmse)) if self.n_evaluated else math.nan

    def summary_lines(self) -> list:
        nb = int(self.better.sum())
        lines = [f"montecarlo: {self.samples.shape[0]} samples (spread +-{self.spread:g}, seed {self.seed}), "
                 f"{self.n_evaluated} accepted (friction >= 0 on the car box), {nb} beat the nominal RMSE "
                 f"{self.rmse_nominal:.3f} N*m; best sample {self.best_rmse:.3f}",
                 f"simulation: {self.elapsed_s:.1f} s on {self.scheduler} ({self.samples_per_s:.1f} samples/s, "
                 f"{self.samples_per_s * self.simulated_seconds_per_sample:.0f} simulated s per s"
                 + (f"; {self.samples_per_s_after_startup:.1f} samples/s after the {self.startup_s:.1f} s "
                    "cluster start-up" if self.startup_s else "") + ")",
                 f"mean of the better samples: RMSE {self.rmse_mean:.3f} N*m"]
        for h in self.halving:
            lines.append(f"interval halving a{h['coefficient']}: [{h['start_interval'][0]:.4e}, "
                         f"{h['start_interval'][1]:.4e}] -> {h['value']:.4e} (RMSE {h['rmse']:.3f}, "
                         f"{'kept' if h['kept'] else 'not kept'})")
        lines.append(f"refined model: RMSE {self.rmse_refined:.3f} N*m (nominal {self.rmse_nominal:.3f})")
        for k in self.varied:
            if self.refined_a[k] != self.nominal_a[k]:
                lines.append(f"  a{k:<2d} {self.nominal_a[k]: .5e} -> {self.refined_a[k]: .5e}")
        lines += [f"note: {n}" for n in self.notes]
        return lines

    def to_json(self) -> dict:
        num = finite_or_none
        return {"n_samples": int(self.samples.shape[0]), "n_accepted": self.n_evaluated,
                "n_better": int(self.better.sum()), "seed": self.seed, "spread": self.spread,
                "varied": [int(k) for k in self.varied], "rmse_nominal": self.rmse_nominal,
                "best_sample_rmse": num(self.best_rmse), "rmse_mean_of_better": num(self.rmse_mean),
                "rmse_refined": self.rmse_refined, "nominal_a": [float(x) for x in self.nominal_a],
                "mean_better_a": [float(x) for x in self.mean_better],
                "refined_a": [float(x) for x in self.refined_a], "i": self.exponent_i,
                "halving": self.halving, "chunk_size": self.chunk_size, "scheduler": self.scheduler,
                "elapsed_s": self.elapsed_s, "startup_s": self.startup_s, "samples_per_s": num(self.samples_per_s),
                "simulated_seconds_per_sample": self.simulated_seconds_per_sample, "notes": self.notes}

    def save(self, outdir, plots: bool = True, plot_coefficients=None) -> list:
        """DIR/samples.npz, DIR/refined_model.yaml, DIR/summary.json and the scatter plots."""
        out = Path(outdir)
        out.mkdir(parents=True, exist_ok=True)
        written = []
        np.savez_compressed(out / "samples.npz", samples=self.samples, rmse=self.rmse, accepted=self.accepted,
                            seed=self.seed, spread=self.spread, nominal=self.nominal_a,
                            rmse_nominal=self.rmse_nominal, varied=np.asarray(self.varied, int),
                            mean_better=self.mean_better, refined=self.refined_a, i=self.exponent_i)
        written.append(out / "samples.npz")
        if self.refined_model is not None:
            save_model(self.refined_model, out / "refined_model.yaml", header="\n".join(self.summary_lines()))
            written.append(out / "refined_model.yaml")
        write_json(out / "summary.json", self.to_json())
        written.append(out / "summary.json")
        if plots:
            from clutch_model.identification.plots import montecarlo_scatter

            written += montecarlo_scatter(self, out, coefficients=plot_coefficients)
        return written


def _worker_warmup(threads=None):
    """Load the compiled batch kernel in a Dask worker (numba cache) before the timed work, and
    limit its BLAS threads as the command line does (clutch_model.threads)."""
    import numba

    from clutch_model.plant.simulate import simulate_batch
    from clutch_model.threads import limit_blas_threads

    limit_blas_threads()
    if threads:
        numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    from clutch_model.plant.params import load_model

    p = load_model(None).vector()
    t = np.arange(4) * 0.005
    simulate_batch(np.stack([p, p]), t, np.full(4, 1000.0), np.ones(4), np.full(4, 60.0))
    return True


def _progress_bar(progress, n_total):
    if not progress:
        return None
    from tqdm import tqdm

    return tqdm(total=n_total, unit="sample", desc="monte carlo", dynamic_ncols=True, smoothing=0.1)


def _run_chunks(base, A, chunks, inputs, scheduler, progress, n_total):
    """RMSE of the accepted samples, chunk by chunk: serially or on Dask. Returns (rmse,
    scheduler label, cluster start-up seconds)."""
    rmse = np.full(A.shape[0], np.nan)
    if scheduler is None:
        bar = _progress_bar(progress, n_total)
        try:
            for ch in chunks:
                rmse[ch] = chunk_rmse(base, A[ch], inputs)
                if bar is not None:
                    bar.update(len(ch))
        finally:
            if bar is not None:
                bar.close()
        return rmse, "serial", 0.0
    from dask.distributed import as_completed

    from clutch_model.identification.cluster import connect

    conn = connect(scheduler, warmup=_worker_warmup)
    client, threads, label, startup = conn.client, conn.threads, conn.label, conn.startup_s
    bar = None
    try:
        bar = _progress_bar(progress, n_total)
        inputs_f = client.scatter(inputs, broadcast=True)
        futs = {client.submit(chunk_rmse, base, A[ch], inputs_f, threads, pure=False): j
                for j, ch in enumerate(chunks)}
        for fut in as_completed(futs):
            j = futs[fut]
            rmse[chunks[j]] = fut.result()
            if bar is not None:
                bar.update(len(chunks[j]))
    finally:
        if bar is not None:
            bar.close()
        conn.close()
    return rmse, label, startup


def run_montecarlo(model: ClutchModel, runs_or_campaign, n_samples: int, spread: float, seed: int = 0,
                   chunk_size: int = 256, scheduler: str | None = None, varied=None, halving=(3, 4),
                   halving_width: float = 0.4, halving_tol: float = 1e-2, progress: bool = True,
                   rows=None, inputs: CampaignInputs | None = None) -> MonteCarloResult:
    """The Monte Carlo refit (module doc). ``scheduler``: None (serial), "local" (a 2-worker
    LocalCluster) or a Dask scheduler address."""
    if n_samples < 1:
        raise FitError("--samples must be >= 1")
    if not (0 < spread < 1):
        raise FitError("--spread must be in (0, 1) (a fraction of each coefficient, e.g. 0.05)")
    if chunk_size < 1:
        raise FitError("chunk size must be >= 1")
    inputs = inputs or CampaignInputs.from_campaign(as_campaign(runs_or_campaign), model, rows=rows)
    base = model.vector()
    a_nom = model.friction_coefficients
    i_exp = model.friction_exponent
    varied = list(range(20)) if varied is None else sorted({int(k) for k in varied})
    halving = [int(k) for k in (halving or [])]
    notes = []
    A = draw_samples(a_nom, n_samples, spread, seed, varied)
    accepted = box.friction_positive_many(A, i_exp)
    rmse_nom = float(rmse_of(base, a_nom[None, :], inputs)[0])
    chunks = chunk_indices(accepted, chunk_size)
    t0 = time.perf_counter()
    rmse, label, startup = _run_chunks(base, A, chunks, inputs, scheduler, progress, int(accepted.sum()))
    elapsed = time.perf_counter() - t0
    better = accepted & (np.nan_to_num(rmse, nan=np.inf) < rmse_nom)
    mean_better = A[better].mean(axis=0) if better.any() else a_nom.copy()
    if not better.any():
        notes.append("no sample beat the nominal RMSE; the mean step is skipped")
    # the mean of the better samples, if it helps
    cand = a_nom.copy()
    cand[varied] = mean_better[varied]
    rmse_mean = float(rmse_of(base, cand[None, :], inputs)[0]) if better.any() else rmse_nom
    if better.any() and rmse_mean < rmse_nom and box.friction_positive(cand, i_exp):
        refined, rmse_ref = cand, rmse_mean
    else:
        refined, rmse_ref = a_nom.copy(), rmse_nom
        if better.any():
            notes.append("the mean of the better samples did not improve the RMSE (or made friction negative); "
                         "kept the nominal coefficients before halving")
    # interval halving, one coefficient after the other (thesis: a3, then a4)
    hres = []
    for k in halving:
        if not 0 <= k < 20:
            raise FitError(f"halving coefficient a{k} is not one of a0..a19")
        ref = refined.copy()
        trend = mean_better[k] - a_nom[k]
        direction = 1.0 if trend == 0 else math.copysign(1.0, trend)
        lo, hi = sorted((a_nom[k], a_nom[k] + direction * halving_width * abs(a_nom[k])))

        def f_many(xs, k=k, ref=ref):
            rows = np.repeat(ref[None, :], len(xs), axis=0)
            rows[:, k] = xs
            vals = rmse_of(base, rows, inputs)
            ok = box.friction_positive_many(rows, i_exp)
            return np.where(ok, vals, np.inf)

        h = interval_halving(f_many, lo, hi, rel_tol=halving_tol)
        kept = bool(np.isfinite(h.f) and h.f < rmse_ref)
        if kept:
            refined = ref.copy()
            refined[k] = h.x
            rmse_ref = h.f
        hres.append({"coefficient": k, "start_interval": [float(lo), float(hi)], "value": float(h.x),
                     "rmse": float(h.f), "iterations": h.iterations, "evaluations": h.evaluations, "kept": kept})
    res = MonteCarloResult(samples=A, rmse=rmse, accepted=accepted, seed=int(seed), spread=float(spread),
                           nominal_a=a_nom.copy(), exponent_i=i_exp, rmse_nominal=rmse_nom, varied=varied,
                           mean_better=mean_better, rmse_mean=rmse_mean, refined_a=refined,
                           rmse_refined=float(rmse_ref), halving=hres, chunk_size=int(chunk_size), scheduler=label,
                           elapsed_s=elapsed, startup_s=startup,
                           simulated_seconds_per_sample=inputs.simulated_seconds, notes=notes,
                           refined_model=model.with_friction(a=refined))
    return res
