"""Where diagnose's candidate fits run: in this process, or on a Dask cluster, ahead of time.

The forward selection (selection.select_causes) asks the candidates one after the other for
their fit on the same training set, then for a costlier refit of the best few. A
``FitExecutor`` with a cluster answers the first such request of a step by submitting the fit
of *every* candidate still in the running (the same training set, the same inputs) and the
following requests from the finished jobs; when the fits of a step are known it submits the
refits of the ``refine_top`` best on the training rows the same way. Every job is the
candidate's own plain function of its inputs (candidates.fit_job / refine_job), so the
results equal the serial run's; a request the prefetch did not foresee (a jackknife refit on
fewer rows, another ranking) simply runs as its own job. Serially, the executor runs each
request when asked and only counts it for the progress bar.

Progress: one tqdm bar per selection step on stderr (fits done, elapsed, estimated time left).
The cluster: clutch_model.identification.cluster (the one Monte Carlo uses): "local" (a
2-worker LocalCluster) or a scheduler address.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from clutch_model.diagnosis.candidates import fit_job, model_digest, refine_job, rows_digest

REFINE_TOP = 3          # select_causes' default refine_top: the refits worth submitting ahead


def _digest(mask) -> str:
    return rows_digest(mask).hex()


def _train_mse(fitted, train) -> float:
    """selection's ranking of first fits (mean squared training residual)."""
    y = np.asarray(train.data.y, float)
    r = y - np.asarray(fitted.predict(train.data), float)
    ok = np.asarray(train.data.train_mask, bool) & np.isfinite(r)
    return float(np.mean(r[ok] ** 2)) if ok.any() else math.inf


def slim_context(ctx):
    """The candidate context without the raw topic samples (what a worker needs to fit)."""
    from clutch_model.formats.bag_reader import Campaign

    camp = ctx.campaign
    runs = [replace(r, samples={}) for r in camp.runs]
    return replace(ctx, campaign=Campaign(runs))


class FitExecutor:
    """Runs candidate fits (module doc). ``scheduler``: None (this process), "local" or a Dask
    scheduler address; use as a context manager (the cluster connection is closed on exit)."""

    def __init__(self, scheduler: str | None = None, progress: bool = False, say=None, refine_top: int = REFINE_TOP):
        self.scheduler = scheduler
        self.progress = progress
        self.say = say or (lambda msg: None)
        self.refine_top = refine_top
        self.conn = None
        self.label = "serial"
        self._group = []
        self._ctx_future = {}
        self._pending = {}          # key -> future or (result,)
        self._bar = None
        self._bar_key = None
        self.jobs = 0

    # -- lifetime -----------------------------------------------------------------------
    def __enter__(self):
        if self.scheduler:
            from clutch_model.identification.cluster import connect
            from clutch_model.identification.montecarlo import _worker_warmup

            self.say(f"connecting to the Dask cluster ({self.scheduler})")
            self.conn = connect(self.scheduler, warmup=_worker_warmup)
            self.label = self.conn.label
            n = len(self.conn.client.scheduler_info().get("workers", {}))
            self.say(f"candidate fits on {self.label} ({n} workers, ready in {self.conn.startup_s:.1f} s)")
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def close(self):
        self._close_bar()
        if self.conn is not None:
            for fut in self._pending.values():
                if not isinstance(fut, tuple):
                    fut.cancel()
            self._pending.clear()
            self.conn.close()
            self.conn = None

    def register(self, candidates) -> list:
        """Attach the candidates of one selection (they share a context) -> the candidates."""
        self._group = list(candidates)
        for c in self._group:
            c.executor = self
        return self._group

    # -- progress -----------------------------------------------------------------------
    def _close_bar(self):
        if self._bar is not None:
            self._bar.close()
        self._bar, self._bar_key = None, None

    def _tick(self, phase, total: int, desc: str):
        if not self.progress:
            return
        if self._bar_key != phase:
            self._close_bar()
            from tqdm import tqdm

            self._bar = tqdm(total=max(total, 1), desc=desc, unit="fit", dynamic_ncols=True, leave=True,
                             mininterval=0.5, smoothing=0.0)
            self._bar_key = phase
        self._bar.update(1)
        if self._bar.n >= self._bar.total:
            self._close_bar()

    # -- jobs ---------------------------------------------------------------------------
    def _ctx(self, ctx):
        key = id(ctx)
        if key not in self._ctx_future:
            self._ctx_future[key] = (ctx, self.conn.client.scatter(slim_context(ctx), broadcast=True))
        return self._ctx_future[key][1]

    def _submit(self, key, fn, *args):
        if key in self._pending:
            return
        ctx_f = self._ctx(args[0])
        self._pending[key] = self.conn.client.submit(fn, ctx_f, *args[1:], pure=False)
        self.jobs += 1

    def _result(self, key, fn, *args):
        if self.conn is None:
            self.jobs += 1
            return fn(*args)
        self._submit(key, fn, *args)
        fut = self._pending.pop(key)
        return fut.result()

    @staticmethod
    def _phase(train):
        """What identifies a selection step's requests: the model so far (by identity and by
        value, so a reused id() never matches an old entry), the named causes, the rows."""
        model = getattr(train.base, "model", None)
        try:
            value = model_digest(model).hex()
        except Exception:             # not a ClutchModel: identity only
            value = ""
        return (id(train.base), value, tuple(train.selected), _digest(train.mask))

    def _remaining(self, train):
        return [c for c in self._group if c.id not in train.selected]

    def fit(self, cand, train, bases):
        phase = self._phase(train)
        key = ("fit", cand.id) + phase
        main = train.train_mask is None          # a selection step (not a jackknife refit)
        if self.conn is not None and main and any(c is cand for c in self._group):
            for c in self._remaining(train):     # every fit of this step, ahead
                self._submit(("fit", c.id) + phase, fit_job, c.context, c.id, c.fit_bases(train), train.mask)
        res = self._result(key, fit_job, cand.context, cand.id, bases, train.mask)
        on_top = f" on top of {', '.join(train.selected)}" if train.selected else ""
        if main:
            self._tick(("fit",) + phase, len(self._remaining(train)), f"candidate fits{on_top}")
        else:
            self._tick(("jackknife",) + phase[:2], 10, f"interval refits of {cand.id}")
        return res

    def _maybe_prefetch_refines(self, train, phase):
        """When every first fit of the step is known, submit the refits of the best few on the
        training rows (the ranking selection will make)."""
        if self.conn is None or self.refine_top <= 0:
            return
        rem = self._remaining(train)
        done = getattr(self, "_fits_done", {})
        self._fits_done = done
        fits = done.setdefault(phase, {})
        missing = [c for c in rem if c.id not in fits]
        if missing:
            return
        ranked = sorted(rem, key=lambda c: _train_mse(fits[c.id], train))
        for c in ranked[: self.refine_top]:
            self._submit(("refine", c.id) + phase, refine_job, c.context, c.id, c.refine_bases(train),
                         fits[c.id].parameters, train.mask, fits[c.id].fit.co_parameters)

    def note_fit(self, cand, train, fitted):
        """The ModelFit a candidate returned for a selection step (for the refit prefetch)."""
        if self.conn is None or train.train_mask is not None:
            return
        phase = self._phase(train)
        done = getattr(self, "_fits_done", {})
        self._fits_done = done
        done.setdefault(phase, {})[cand.id] = fitted
        self._maybe_prefetch_refines(train, phase)

    def refine(self, cand, fitted, train, bases):
        phase = self._phase(train)
        key = ("refine", cand.id) + phase
        if key in self._pending and self._pending_start_ok(fitted, train, phase, cand):
            res = self._result(key, refine_job, cand.context, cand.id, bases, fitted.parameters, train.mask,
                               fitted.fit.co_parameters)
        else:
            self._pending.pop(key, None)
            res = self._result(("refine-now", cand.id) + phase, refine_job, cand.context, cand.id, bases,
                               fitted.parameters, train.mask, fitted.fit.co_parameters)
        on_top = f" on top of {', '.join(train.selected)}" if train.selected else ""
        self._tick(("refine",) + phase, min(self.refine_top, len(self._remaining(train))), f"refits{on_top}")
        return res

    def _pending_start_ok(self, fitted, train, phase, cand) -> bool:
        """The prefetched refit started from the same first fit selection passes now."""
        fits = getattr(self, "_fits_done", {}).get(phase, {})
        f = fits.get(cand.id)
        return (f is not None and f.parameters == fitted.parameters
                and f.fit.co_parameters == fitted.fit.co_parameters)
