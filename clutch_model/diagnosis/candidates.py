"""Catalog mechanisms as candidates of the forward selection (selection.Candidate).

A candidate is fitted on top of the model so far (the calibrated baseline, or the baseline
with the causes already named): ``fit`` moves the mechanism's own parameters with the friction
as it is (cheap: one parameter), ``refine`` refits them jointly with the baseline's friction
correction (fitting.fit_candidate), from the model so far and, at the first step, also from
the bench-fitted friction (a car calibration may have absorbed part of the mechanism).
Intervals: the Jacobian of the prediction at the fit (``sensitivity``), one batch of
perturbed simulations, for selection's cluster-robust sandwich.
"""
from __future__ import annotations

import hashlib
import math
import pickle
from collections import OrderedDict
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from clutch_model.diagnosis.fitting import (CampaignObjective, CandidateFit, fit_candidate, search_space,
                                            time_parameter_names)
from clutch_model.plant.mechanisms import CATALOG
from clutch_model.diagnosis.input_hold import _samples, high_frequency_noise
from clutch_model.diagnosis.selection import ParameterSensitivity, SelectionData, TrainingSet, row_interval_s

FORCE_BAND_NOISE_FACTOR = 2.0   # a band on the force must be this many times the force noise wide
MIN_FRICTION_DROP = 0.02        # a friction degradation must take this share of the friction over the campaign
LEVEL_WANDER_FACTOR = 3.0       # a constant torque must be this many times the residual's slow wander
LEVEL_BLOCK_S = 5.0             # the blocks whose mean levels measure that wander (s)


@dataclass
class CampaignContext:
    """What every mechanism fit on one campaign shares."""

    campaign: object               # formats.bag_reader.Campaign (locked rows: NaN torque)
    energy_total_j: float
    torque_scale: float
    sigma_nm: float
    bench_model: object = None     # ClutchModel: a second start at the first step
    slip_smoothing_s: float = 0.0  # sd of the Gaussian the slip driving the plant is smoothed with (input_hold)
    friction_ridge_factor: float = 1.0   # the friction correction's ridge (friction_ridge.py; inf: none)
    force_sample_period_s: float = 0.0   # the applied force's median sample interval as logged (0: the rows')
    logged_force_noise_n: float = float("nan")   # the force's noise from its samples as logged (NaN: the rows')

    def __post_init__(self):
        self._friction_only: dict = {}
        self._fits = FitMemo()                      # fit_alone's results by value (fit_memo_key)

    def at_friction_ridge(self, factor: float) -> "CampaignContext":
        """This context with every friction correction at ridge ``factor``; it shares the fits
        made alone (their friction is held, no ridge applies)."""
        ctx = replace(self, friction_ridge_factor=float(factor))
        ctx._fits = self._fits
        return ctx

    def friction_only(self, base_model, mask: np.ndarray) -> np.ndarray:
        """The prediction of ``base_model`` with its friction correction refitted alone on the
        training rows ``mask`` (no mechanism): the twin of a candidate refitted jointly with the
        friction from that base. Cached per base (by value) and mask."""
        mask = np.asarray(mask, bool)
        key = (model_digest(base_model), rows_digest(mask))
        hit = self._friction_only.get(key)
        if hit is None:
            fit = fit_candidate(base_model, self.campaign, mask, None, self.energy_total_j, self.torque_scale,
                                fit_friction=True, noise_sigma_nm=self.sigma_nm,
                                ridge_factor=self.friction_ridge_factor)
            hit = np.asarray(fit.predicted, float)
            self._friction_only[key] = hit
        return hit

    @cached_property
    def row_interval_s(self) -> float:
        """Median interval between the comparison rows (s)."""
        return row_interval_s(self.campaign.t, self.campaign.run_start)

    @cached_property
    def timing_interval_s(self) -> float:
        """The interval the model is timed to: the comparison rows' or, when the torque is
        compared on rows faster than the force is sampled, the force samples' (the plant holds
        each force sample until the next; its timing is known to half that interval).

        Measured on an outside generator's campaign with the force at 50 Hz and the torque at
        500 Hz (rows decimated to 250 Hz), a 17.1 ms transport delay: the delay was named at
        13.5 ms and a 4.8 ms actuator lag beside it (the torque sensor reads the plant between
        the force samples, a ramp where the held force steps); the lag is not named now."""
        force_s = float(self.force_sample_period_s)
        return max(self.row_interval_s, force_s) if math.isfinite(force_s) else self.row_interval_s

    @cached_property
    def force_noise_n(self) -> float:
        """The applied force's sensor noise near its Nyquist frequency (white-equivalent sd, N),
        from the force's samples as logged (``logged_force_noise_n``, taken before the rows were
        regridded) or else each run's own force samples (input_hold.high_frequency_noise); NaN
        for rows without runs' force samples. The rows' force, interpolated onto the measured
        torque's stamps, has lost its noise between the samples: on an outside generator's
        campaign (a 100 Hz force, AR(1) 0.93 noise of sd 49 N, the torque at 200 Hz) the rows
        gave 1.74 N where the samples as logged give 10.2 N, and a backlash of 11 N half-width,
        fitted to that noise, was taken for a play beyond the catalog."""
        if math.isfinite(self.logged_force_noise_n):
            return float(self.logged_force_noise_n)
        runs = getattr(self.campaign, "runs", None)
        if not runs:
            return float("nan")
        return high_frequency_noise([_samples(run, "applied_force", run.applied_force_n)[1] for run in runs])

    @cached_property
    def typical_force_n(self) -> float:
        """Median applied force on the rows the torque is compared on (N)."""
        camp = self.campaign
        rows = np.isfinite(np.asarray(camp.torque_measured, float)) & (np.asarray(camp.force, float) > 0)
        return float(np.median(np.asarray(camp.force, float)[rows])) if rows.any() else float("nan")


@dataclass
class ModelFit:
    """A fitted model (baseline or with mechanisms): selection.Fitted."""

    id: str
    fit: CandidateFit
    base_model: object             # the model the fit started from (its friction is what x corrects)
    context: CampaignContext
    mask: np.ndarray               # training rows it was fitted on

    @property
    def parameters(self) -> dict:
        return dict(self.fit.parameters)

    @property
    def model(self):
        return self.fit.model

    def without_mechanism(self) -> np.ndarray | None:
        """The prediction of this fit's twin without the mechanism: the same fit with the
        mechanism left out. A candidate refitted jointly with the friction correction, or
        from the bench friction, may gain on held-out rows through the refit alone; selection
        names it only when its mechanism beats this twin.

        A joint fit's twin is refitted: the friction correction alone, from the same base on
        the same training rows (the nested model). Taking the mechanism out of the joint fit
        and keeping its friction, as before, left a twin tuned to work with the mechanism:
        on actuator_lag+friction_degradation@ar1#1 the degradation's friction, right on the
        early held-out run where little energy had been dissipated yet, made that twin as good
        as the degradation there (12.07 vs 11.75 N*m, t = 2.3) while it was 26-29 N*m on the
        later training runs. A fit with the friction as it was keeps the mechanism-removed
        twin (its base).

        A cause refitted with the others in the model (selection's backfitting) starts from a
        base that holds its own mechanism as first fitted; the twin leaves that out too, or it
        would keep the mechanism at its earlier size and measure only the change of it."""
        if self.id == "baseline":
            return None
        if self.fit.joint:
            base = self.base_model
            if any(m.id == self.id for m in base.mechanisms):
                base = base.with_mechanisms([m for m in base.mechanisms if m.id != self.id])
            return self.context.friction_only(base, self.mask)
        from clutch_model.prediction import predict_campaign

        # with co-fitted mechanisms moved, the twin is the model they were moved from
        model = self.base_model if self.fit.co_parameters else self.fit.model
        twin = model.with_mechanisms([m for m in model.mechanisms if m.id != self.id])
        return np.asarray(predict_campaign([twin], self.context.campaign, energy0_j=0.0).torque_nm)[0]

    @property
    def dynamic(self) -> bool:
        """Its mechanism acts in time (a parameter in seconds: a lag, a delay), not as a torque
        map; the baseline is neither (selection.head_to_head)."""
        return any(True for _ in self._time_parameters())

    def _time_parameters(self):
        """(mechanism id, parameter name, fitted value) of each parameter in seconds of this
        fit's mechanism and of those co-fitted with it."""
        if self.id == "baseline":
            return
        for mech_id, values in [(self.id, self.fit.parameters), *self.fit.co_parameters.items()]:
            for name in time_parameter_names(mech_id):
                yield mech_id, name, values.get(name)

    @property
    def time_parameter_names(self) -> tuple:
        """Names of this fit's own parameters in seconds (selection widens their intervals by
        the rows' timing resolution)."""
        return tuple(name for mech_id, name, _ in self._time_parameters() if mech_id == self.id)

    @property
    def below_resolution(self) -> str | None:
        """Why this fit cannot name its mechanism, or None. A time parameter (unit s: a lag, a
        delay) shorter than half the comparison rows' interval is below the data's time
        resolution: the plant holds each row's inputs over its step, so a simulation on those
        rows is only timed to half a row interval (the midpoint force leaves a residual timing
        error of ~1 ms at 200 Hz: a "lag" of 0.5-1.3 ms was fitted on campaigns with nothing
        hidden), and topics stamped on their own clocks jitter by as much.

        When the slip driving the plant is smoothed (input_hold: the model's own noise near
        Nyquist exceeds the torque sensor's), the model is defined only at the smoothing's
        time scale, and a lag or delay shorter than the Gaussian's sd filters the model's own
        input noise: on an outside campaign with nothing hidden (torque noise band-limited at
        17 Hz, 2.45 ms rows) a 2 ms torque-sensor lag predicted the held-out data at t = 105
        (innovation variance -57 %, plain mean square -4 %)."""
        return (self._below_time_resolution() or self._below_force_resolution()
                or self._below_friction_resolution() or self._below_level_wander())

    @property
    def below_resolution_alone(self) -> str | None:
        """Why this fit cannot name its mechanism when that is only for what it leaves: a
        friction decline too small, or a constant within the residual's slow wander, measure the
        fit against its own residual, and a second cause fitted with it takes part of that
        residual. None when the fit is resolved, or when the data themselves cannot resolve it
        (a time or a force parameter below the rows' resolution)."""
        if self._below_time_resolution() or self._below_force_resolution():
            return None
        return self._below_friction_resolution() or self._below_level_wander()

    def _below_time_resolution(self) -> str | None:
        ctx = self.context
        half_row_s = 0.5 * ctx.timing_interval_s
        smooth_s = ctx.slip_smoothing_s
        whose = "row" if ctx.timing_interval_s <= ctx.row_interval_s else "applied force's sample"
        for mech_id, name, v in self._time_parameters():
            if isinstance(v, (int, float)) and v < half_row_s:
                return (f"{mech_id} {name} = {1e3 * v:.2g} ms is below the time resolution of the "
                        f"data (half the {1e3 * ctx.timing_interval_s:.3g} ms {whose} interval)")
            if isinstance(v, (int, float)) and v < smooth_s:
                return (f"{mech_id} {name} = {1e3 * v:.2g} ms is below the time resolution of the "
                        f"model's inputs (the slip is smoothed with a {1e3 * smooth_s:.3g} ms Gaussian)")
        return None

    def _marked_parameters(self, mark: str):
        """(mechanism id, parameter name, fitted value) of each of this fit's mechanisms whose
        class names that parameter under ``mark`` (``force_band``, ``torque_level``)."""
        if self.id == "baseline":
            return
        for mech_id in self.id.split("+"):
            name = getattr(CATALOG.get(mech_id), mark, None)
            v = self.fit.parameters.get(name) if name else None
            if isinstance(v, (int, float)):
                yield mech_id, name, v

    def _below_level_wander(self) -> str | None:
        """A constant torque (a sensor bias) smaller than LEVEL_WANDER_FACTOR times the slow
        wander of what remains is not told from that wander: the RMS of the mean residual over
        LEVEL_BLOCK_S blocks of the training rows (with the constant in the fit). A sensor
        offset drifting over tens of seconds has a mean over one campaign that is a single
        draw, and no noise model of a fraction of a second's memory forecasts it: on an
        outside campaign with a 26 ms delay and no offset (one 62 s drive, drift 4.6 N*m with
        a 35 s time constant) a 6.5 N*m offset was named beside the delay at held-out t = 3.8
        (innovation variance -1.4 %); its 2 s means wander by 2.6 N*m. Under white noise of a
        few N*m the block means wander by a fraction of a N*m, under AR(1) 0.95 noise by up to
        3 N*m, and the offsets of the catalog's range (10-50 N*m) stand out.

        The blocks are 5 s (2 s until stop 46): a drift an offset can be taken for is slow, and
        shorter blocks also count fast level scatter that the constant's own estimate averages
        out. On spring_preload+torque_offset@car#8 (``--quick``, magnitude seed 20261129: a
        14.2 N*m offset beside a 416 N preload under AR(1) 0.9 noise and the car's friction
        wandering by 5 % from one drive segment to the next) the offset refitted with the
        preload came out at 14.7-16.1 N*m; the 2 s means wandered by 5.9 N*m, the 5 s means by
        2.1-2.6, and the offset was refused beside the preload (``unexplained``). Offsets fitted
        to a slow drift alone (60 s drive, OU 35 s; tests/diagnosis/test_selection.py) stand
        0.7-2.1 times above the 5 s wander, as at 2 s (0.7-1.8)."""
        if self.fit.residual is None:
            return None
        for mech_id, name, v in self._marked_parameters("torque_level"):
            wander = self.level_wander_nm
            if np.isfinite(wander) and abs(v) < LEVEL_WANDER_FACTOR * wander:
                return (f"{mech_id} {name} = {v:.3g} N*m is within the slow wander of the residual (its "
                        f"{LEVEL_BLOCK_S:g} s means wander by {wander:.3g} N*m RMS; a constant must stand "
                        f"{LEVEL_WANDER_FACTOR:g} times above it)")
        return None

    @cached_property
    def level_wander_nm(self) -> float:
        """RMS of the residual's mean over LEVEL_BLOCK_S blocks of each run's training rows
        (blocks with fewer than 10 such rows left out); NaN without such blocks. Whatever moves
        the level counts: a drift, and the block-to-block scatter of coloured noise (AR(1) 0.95
        noise of 7 N*m at 200 Hz: 1.9-2.8 N*m in 2 s blocks), so a constant is named only when it
        stands out of both."""
        camp = self.context.campaign
        r = np.where(self.mask, np.asarray(self.fit.residual, float), np.nan)
        t = np.asarray(camp.t, float)
        starts = np.flatnonzero(np.asarray(camp.run_start, bool))
        means = []
        for a, b in zip(starts, np.r_[starts[1:], t.size]):
            ok = np.isfinite(r[a:b])
            if not ok.any():
                continue
            blk = np.floor((t[a:b][ok] - t[a]) / LEVEL_BLOCK_S).astype(np.int64)
            sums, counts = np.bincount(blk, weights=r[a:b][ok]), np.bincount(blk)
            full = counts >= 10
            means.extend((sums[full] / counts[full]).tolist())
        return float(np.sqrt(np.mean(np.square(means)))) if means else float("nan")

    def _below_force_resolution(self) -> str | None:
        """A band on the force (an actuator hysteresis' half-width ratio x F) narrower than
        FORCE_BAND_NOISE_FACTOR times the force sensor's noise is below the force's resolution:
        within such a band the play operator stops the pack force from following the noise's
        reversals, a filter on the model's own input noise rather than an actuator's play.
        Measured on the car conditions (AR(1) 0.9 torque and slip noise, 20 N force noise):
        hysteresis ratios of 0.001-0.006 (bands of 3-17 N at the typical force of ~3000 N)
        were fitted where no hysteresis was hidden, at held-out t of 4.1-6.3, and named (a third
        cause on transport_delay+drag_torque@car#1, a first on pressure_temperature_cross@car#1)
        with the plain held-out mean square down only 1.7-2.4 %; the virtual car's hysteresis
        is 0.05-0.2 (bands of 150-600 N).

        A constant on the force (a spring preload) within the same bound acts where the measured
        force is its noise about zero (released, the model's torque from the noise's positive
        half is clipped away): a filter on the model's input noise too. Measured on
        actuator_lag+transport_delay@lockup#1 (``--quick``, magnitude seed 20261202, 20 N force
        noise): a 5.6 N preload was named third beside the pair (held-out t = 4.5, innovation
        variance -2.4 %); the virtual car's preloads are 300-1500 N."""
        for mech_id, band, v in self._marked_parameters("force_band"):
            noise, force = self.context.force_noise_n, self.context.typical_force_n
            if np.isfinite(noise) and np.isfinite(force) and v * force < FORCE_BAND_NOISE_FACTOR * noise:
                return (f"{mech_id} {band} = {v:.2g} is below the force's resolution (a band of "
                        f"{v * force:.3g} N at the typical {force:.4g} N, within {FORCE_BAND_NOISE_FACTOR:g} "
                        f"times the force noise of {noise:.3g} N)")
        for mech_id, name, v in self._marked_parameters("force_level"):
            noise = self.context.force_noise_n
            if np.isfinite(noise) and abs(v) < FORCE_BAND_NOISE_FACTOR * noise:
                return (f"{mech_id} {name} = {v:.3g} N is below the force's resolution (within "
                        f"{FORCE_BAND_NOISE_FACTOR:g} times the force noise of {noise:.3g} N)")
        return None

    def _below_friction_resolution(self) -> str | None:
        """A friction degradation that takes less than MIN_FRICTION_DROP of the friction over
        the whole campaign (1 - exp(-E / energy_scale), E the energy the campaign dissipated)
        is below what the car resolves of the friction's level: the car calibration's own
        friction misfits (its level and temperature slope against the day's lining and oil)
        are that large, and a decline that small over one drive reads as a temperature slope.
        Measured on actuator_lag+transport_delay@long_drive#1 (``--quick``, magnitude seed
        20261202, one 40 s drive, no degradation hidden): a degradation taking 0.6 % of the
        friction was named third beside the pair (held-out t = 4.4, innovation variance -1.0 %);
        the virtual car's degradations take 6-20 %."""
        energy = float(self.context.energy_total_j)
        for mech_id, name, v in self._marked_parameters("friction_decay"):
            if np.isfinite(energy) and energy > 0 and v > 0:
                drop = -math.expm1(-energy / v)
                if drop < MIN_FRICTION_DROP:
                    return (f"{mech_id} {name} = {v:.3g} J takes {100 * drop:.2g} % of the friction over the "
                            f"campaign ({energy:.3g} J dissipated): below the friction level's resolution "
                            f"({100 * MIN_FRICTION_DROP:g} %)")
        return None

    def predict(self, data: SelectionData = None) -> np.ndarray:
        return self.fit.predicted

    def _objective_at_fit(self):
        """(CampaignObjective, x at the fit, mechanism search spaces) of this fit, on its training
        rows: x = the mechanism's parameters in their search transform, then the co-fitted
        mechanisms' (fitting.co_fitted_ids, as fitted), then the friction correction if it was
        refitted."""
        ctx = self.context
        mech_id = None if self.id == "baseline" else self.id
        specs = search_space(mech_id, ctx.campaign, ctx.energy_total_j, ctx.torque_scale) if mech_id else []
        co = self.fit.co_parameters
        co_specs = [(cid, search_space(cid, ctx.campaign, ctx.energy_total_j, ctx.torque_scale)) for cid in co]
        base = self.base_model.with_mechanisms(self.fit.model.mechanisms) if co else self.base_model
        obj = CampaignObjective(base, ctx.campaign, self.mask, mech_id, specs, fit_friction=self.fit.joint,
                                noise_sigma_nm=ctx.sigma_nm, co_specs=co_specs,
                                ridge_factor=ctx.friction_ridge_factor)
        x = np.array([s.to_x(self.fit.parameters[s.name]) for s in specs]
                     + [s.to_x(co[cid][s.name]) for cid, cs in co_specs for s in cs]
                     + (list(self.fit.friction_correction) if obj.fit_friction else []), float)
        return obj, x, specs

    def _jacobian(self, obj: CampaignObjective, x: np.ndarray) -> np.ndarray:
        """d(prediction)/dx at x over every row of the campaign: forward differences, one batch."""
        steps = np.where(np.arange(x.size) < obj.n_mech, 1e-3 * np.maximum(np.abs(x), 1.0), 1e-4)
        lo, hi = obj.bounds()
        steps = np.where(x + steps > hi, -steps, steps)
        preds = obj.predict(np.vstack([x, x[None, :] + np.diag(steps)]))
        return ((preds[1:] - preds[0][None, :]) / steps[:, None]).T

    def sensitivity(self):
        """d(prediction)/dx at the fit, x = the mechanism's parameters in their search transform
        (then the co-fitted mechanisms' and the friction correction, if it was refitted, as
        nuisance columns): ``flexibility`` of a fitted mechanism."""
        return None if self.id == "baseline" else self.flexibility()

    def flexibility(self):
        """What this fit could absorb of the rows it was fitted on: its Jacobian over every
        parameter fitted there (the baseline's too: its friction correction) and the ridge's
        penalty per column (structure_test.cross_fitted_residual); None when nothing was fitted."""
        obj, x, specs = self._objective_at_fit()
        if x.size == 0:
            return None
        penalty = np.where(np.arange(x.size) >= obj.n_mech, obj.ridge ** 2, 0.0)
        return ParameterSensitivity([s.name for s in specs], x, self._jacobian(obj, x), [s.from_x for s in specs],
                                    estimator="ols", penalty=penalty)


def baseline_fit(calibrated: CandidateFit, base_model, context: CampaignContext, mask) -> ModelFit:
    return ModelFit("baseline", calibrated, base_model, context, mask)


FIT_MEMO_BYTES = 256 * 2 ** 20   # the arrays fit_alone keeps of the fits it made, per context


def model_digest(model) -> bytes:
    """A model by value: every parameter, every mechanism with its values (equal models, equal
    digests; a digest says nothing of the object's identity)."""
    return hashlib.sha1(pickle.dumps(model.to_dict(), protocol=4)).digest()


def rows_digest(mask) -> bytes:
    """A set of rows (a boolean mask) by value."""
    m = np.ascontiguousarray(np.asarray(mask, bool))
    return hashlib.sha1(np.packbits(m).tobytes() + str(m.size).encode()).digest()


class FitMemo:
    """Fits kept by value (``fit_memo_key``), at most FIT_MEMO_BYTES of their residual and
    prediction arrays, the least recently used forgotten first."""

    def __init__(self, max_bytes: int = None):
        self.max_bytes = FIT_MEMO_BYTES if max_bytes is None else int(max_bytes)
        self._fits: OrderedDict = OrderedDict()
        self._bytes = 0

    def get(self, key):
        hit = self._fits.get(key)
        if hit is None:
            return None
        self._fits.move_to_end(key)
        return hit[0]

    def put(self, key, fit) -> None:
        size = sum(np.asarray(a).nbytes for a in (fit.residual, fit.predicted) if a is not None)
        self._fits[key] = (fit, size)
        self._bytes += size
        while self._bytes > self.max_bytes and len(self._fits) > 1:
            self._bytes -= self._fits.popitem(last=False)[1][1]


def fit_memo_key(ctx, mech_id, base_model, mask, joint, start, co_start) -> tuple:
    """What a fit of ``fit_alone`` is a function of, besides its context's campaign: the
    mechanism, the base model by value, the training rows, joint (at the context's ridge) or
    alone, the starts."""
    ridge = float(ctx.friction_ridge_factor) if joint else None
    return (mech_id, bool(joint), ridge, model_digest(base_model), rows_digest(mask),
            pickle.dumps((start, co_start), protocol=4))


def fit_alone(ctx: CampaignContext, mech_id: str, base_model, mask, joint: bool = False,
              start=None, co_start=None) -> CandidateFit:
    """One fit of the mechanism on ``base_model`` (module doc; a time mechanism moves the time
    mechanisms of the model with it, fitting.co_fitted_ids).

    The fit is a plain function of its inputs, and the selection asks for the same one many
    times: a chain of causes refitted for backward elimination or a swap check starts with the
    fits the forward steps made, a refit from the bench friction starts from the fit alone
    there, the selection at the data's ridge fits alone on the bench friction as the first did.
    Each fit is therefore kept on the context (``FitMemo``) and a repeated request gets a copy
    of it: on actuator_second_order@lab#2 70 of 309 fits were repeats, 18 % of the CPU."""
    key = fit_memo_key(ctx, mech_id, base_model, mask, joint, start, co_start)
    hit = ctx._fits.get(key)
    if hit is None:
        hit = fit_candidate(base_model, ctx.campaign, mask, mech_id, ctx.energy_total_j, ctx.torque_scale,
                            fit_friction=joint, noise_sigma_nm=ctx.sigma_nm, start=start, co_start=co_start,
                            ridge_factor=ctx.friction_ridge_factor)
        ctx._fits.put(key, hit)
    return replace(hit, parameters=dict(hit.parameters),
                   co_parameters={k: dict(v) for k, v in hit.co_parameters.items()})


def fit_job(ctx: CampaignContext, mech_id: str, bases: list, mask) -> tuple:
    """``MechanismCandidate.fit`` as a plain function of its inputs (a job a Dask worker can
    run): the mechanism alone on each base model in turn, the better on the training rows kept
    (the first wins ties) -> (CandidateFit, index of its base)."""
    best, k_best = None, 0
    for k, base in enumerate(bases):
        fit = fit_alone(ctx, mech_id, base, mask)
        if best is None or fit.fit_rmse_nm < best.fit_rmse_nm:
            best, k_best = fit, k
    return best, k_best


def refine_job(ctx: CampaignContext, mech_id: str, bases: list, start: dict, mask, co_start=None) -> tuple:
    """``MechanismCandidate.refine`` as a plain function: jointly with the friction correction
    from each base (the first from ``start`` and ``co_start``, the others from the mechanism
    fitted alone on them), the best on the training rows -> (CandidateFit, index of its base)."""
    best, k_best = None, 0
    for k, base in enumerate(bases):
        if k == 0:
            st, co = start, co_start
        else:
            alone = fit_alone(ctx, mech_id, base, mask)
            st, co = alone.parameters, alone.co_parameters
        cand = fit_alone(ctx, mech_id, base, mask, joint=True, start=st, co_start=co)
        if best is None or cand.fit_rmse_nm < best.fit_rmse_nm:
            best, k_best = cand, k
    return best, k_best


@dataclass
class MechanismCandidate:
    """One catalog mechanism as a candidate (selection.Candidate). ``executor``
    (diagnosis.parallel.FitExecutor) runs the fits, possibly ahead and elsewhere (the results
    are the same)."""

    id: str
    context: CampaignContext
    executor: object = None

    def fit_bases(self, train: TrainingSet) -> list:
        """The mechanism alone on the model so far; at the first step also on the bench
        friction (a car calibration may have absorbed part of the mechanism: a preload reads
        as less friction)."""
        bases = [train.base.model]
        ctx = self.context
        if not train.selected and ctx.bench_model is not None:
            bases.append(ctx.bench_model.with_mechanisms(list(train.base.model.mechanisms)))
        return bases

    def refine_bases(self, train: TrainingSet) -> list:
        """The baseline's friction before its correction (refitted jointly), else the model so
        far; at the first step also the bench friction."""
        bases = [train.base.base_model if train.base.id == "baseline" else train.base.model]
        ctx = self.context
        if not train.selected and ctx.bench_model is not None:
            bases.append(ctx.bench_model.with_mechanisms(list(train.base.model.mechanisms)))
        return bases

    def _model_fit(self, result, bases, train) -> ModelFit:
        fit, k = result
        return ModelFit(self.id, fit, bases[k], self.context, np.asarray(train.mask, bool).copy())

    def fit(self, train: TrainingSet) -> ModelFit:
        """The better of the mechanism fitted alone on each of ``fit_bases`` (training rows)."""
        bases = self.fit_bases(train)
        if self.executor is not None:
            fitted = self._model_fit(self.executor.fit(self, train, bases), bases, train)
            self.executor.note_fit(self, train, fitted)
            return fitted
        return self._model_fit(fit_job(self.context, self.id, bases, train.mask), bases, train)

    def refine(self, fitted: ModelFit, train: TrainingSet) -> ModelFit:
        bases = self.refine_bases(train)
        if self.executor is not None:
            return self._model_fit(self.executor.refine(self, fitted, train, bases), bases, train)
        return self._model_fit(refine_job(self.context, self.id, bases, fitted.parameters, train.mask,
                                          fitted.fit.co_parameters), bases, train)
