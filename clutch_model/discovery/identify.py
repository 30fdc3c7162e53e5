"""Discover the missing term: sparse identification on the residual of the calibrated model,
then a joint refit of the selected terms with the friction inside the simulation, accepted
only when it holds on held-out data.

    result = discover(campaign, calibrated_model, split)
    result.accepted, result.terms, result.coefficients, result.parameters_ci95, result.model

1. The calibrated model is simulated over the whole campaign (time order, state carried);
   r = measured − predicted measured torque, at the measurement's own rows, locked rows out.
2. Each library term gives a regressor (terms.Term.regressor: g × asperity torque for a μ_f
   multiplier, g for an additive torque). The friction correction the calibration itself may
   still move (the 10 directions of diagnosis.fitting's correction, linearised) is projected
   out of the residual and of every regressor first (Frisch-Waugh-Lovell): a term is credited
   only with what a friction refit could not do.
3. Sparse selection with scikit-learn's orthogonal matching pursuit, its sparsity chosen by
   cross-validation grouped by run (or by time span for few long runs: grouped folds keep
   coloured noise and per-run levels from passing for structure) with the one-standard-error
   rule, and 0 terms allowed.
4. The selected terms become the plant mechanism ``discovered`` (applied inside the compiled
   kernel, so a term that changes the state -- pack temperature through the heat it
   dissipates, a low-pass -- is simulated) and are refitted jointly with the friction
   correction by scipy's least_squares on the fit rows.
5. The held-out test (heldout.block_gain_test unless another is given) decides; 95 % intervals
   come from a block sandwich covariance of the refit (robust to coloured noise).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.optimize import least_squares
from sklearn.linear_model import orthogonal_mp
from sklearn.model_selection import GroupKFold

from clutch_model.diagnosis.fitting import (K_V_SCALE, N_CORR, RIDGE_SCALE, apply_friction_correction,
                                            friction_correction_basis)
from clutch_model.discovery.heldout import HeldOutVerdict, block_gain_test
from clutch_model.discovery.terms import Term, TermSignals, default_library, describe, partner
from clutch_model.errors import DataError
from clutch_model.identification.objective import TorqueLeastSquares
from clutch_model.plant import kernels as K
from clutch_model.plant import layout as P
from clutch_model.plant.mechanisms.discovered import Discovered
from clutch_model.plant.params import ClutchModel
from clutch_model.prediction import PlantInputs, predict_campaign
from clutch_model.replay import replay_runs

MAX_TERMS = 4            # sparsity ceiling of the search (the plant holds up to 6)
CV_FOLDS = 5
MIN_GROUPS = 3
SPAN_GROUPS = 6          # a campaign of fewer runs is cut into this many time spans
REFIT_NFEV = 30
TAU_RANGE_S = (0.05, 100.0)  # a low-passed term's fitted time constant stays in this range
PRIOR_MU = 0.003             # unseen_range_prior: the friction change that costs one noise-level SSE
PRIOR_THETA_C = np.arange(20.0, 150.0, 10.0)   # its grid of pack temperatures
PRIOR_MARGIN_C = 5.0         # a grid temperature this far outside the fit rows' range is unseen
CI_BLOCK_S = 2.0
CI_MIN_RUN_CLUSTERS = 5  # with this many fit runs the intervals are cluster-robust over runs
RUN_CORRECTION_MAX = 0.3
MATERIAL_FRAC = 0.2      # a term's effect must reach 20 % of the RMS of what remains (4 % of its variance)


@dataclass
class Tried:
    """One extension that was tried, for the report."""
    terms: list
    coefficients: list
    held_out_rmse_nm: float
    verdict: HeldOutVerdict

    def to_dict(self) -> dict:
        return {"id": "discovered", "terms": list(self.terms),
                "parameters": dict(zip(self.terms, [float(c) for c in self.coefficients])),
                "held_out_rmse_nm": float(self.held_out_rmse_nm),
                "gain_pct": float(self.verdict.gain_pct), "accepted": bool(self.verdict.accepted),
                "reason": self.verdict.reason}


@dataclass
class DiscoveryResult:
    accepted: bool
    terms: list                           # Term objects (selected; refitted)
    coefficients: np.ndarray
    parameters_ci95: dict                 # term id -> [lo, hi]
    readings: list                        # plain words, one per term (ripple pair as one)
    evidence: str
    rmse_nm: dict                         # held-out: calibrated, extended
    gain_pct: float
    model: ClutchModel | None             # the extended model (None when nothing accepted)
    verdict: HeldOutVerdict | None
    tried: list = field(default_factory=list)       # Tried
    cv_mse: list = field(default_factory=list)      # grouped-CV MSE for 0..MAX_TERMS terms
    residual: np.ndarray | None = field(default=None, repr=False)   # extended, whole campaign
    base_residual: np.ndarray | None = field(default=None, repr=False)

    @property
    def parameters(self) -> dict:
        return {t.id: float(c) for t, c in zip(self.terms, self.coefficients)}

    def to_cause(self) -> dict:
        """The report.json cause entry (contract: id, evidence, parameters, parameters_ci95)."""
        return {"id": "discovered", "evidence": self.evidence, "parameters": self.parameters,
                "parameters_ci95": {k: [float(v[0]), float(v[1])] for k, v in self.parameters_ci95.items()}}

    def candidates(self) -> list:
        """report.json ``candidates`` entries of everything tried."""
        return [t.to_dict() for t in self.tried]


# ------------------------------------------------------------------------------ helpers
def _eval_mask(split, campaign) -> np.ndarray:
    """A held-out row mask from: a boolean row mask, an object with ``eval_mask``, an object
    with ``held_out`` names, or a list of held-out run names."""
    n = campaign.t.size
    if hasattr(split, "eval_mask"):
        return np.asarray(split.eval_mask, bool)
    if isinstance(split, np.ndarray) and split.dtype == bool:
        if split.size != n:
            raise DataError("held-out mask does not match the campaign")
        return split
    names = list(getattr(split, "held_out", split))
    unknown = set(names) - set(campaign.names)
    if unknown:
        raise DataError(f"held-out run not in the campaign: {sorted(unknown)[0]}")
    idx = [campaign.names.index(x) for x in names]
    return np.isin(campaign.run_index, idx)


def _noise_sigma(noise_model, residual, run_start) -> float:
    if noise_model is not None:
        s = getattr(noise_model, "sigma_nm", None)
        if s is not None and np.isfinite(s) and s > 0:
            return float(s)
    d = np.diff(residual)
    d = d[np.isfinite(d) & ~run_start[1:]]
    if d.size < 10:
        return 1.0
    s = 1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0)
    return float(s) if s > 0 else 1.0


def friction_directions(sig: TermSignals) -> np.ndarray:
    """d(torque)/d(friction correction) linearised: the 10 directions of
    diagnosis.fitting.apply_friction_correction (μ_C and μ_S together, and k_V)."""
    mu = sig.friction_coefficient
    dt_dmu = np.where(mu > 1e-9, sig.asperity_torque_nm / np.where(mu > 1e-9, mu, 1.0), 0.0)
    basis = friction_correction_basis(sig.values["pressure"], sig.values["pack_temperature"] + K.THETA_REF_C)
    w = np.where(sig.locked, 0.0, sig.values["slip_abs"])
    return np.column_stack([basis * dt_dmu[:, None], basis * (dt_dmu * w * K_V_SCALE)[:, None]])


def _groups(campaign, rows) -> np.ndarray:
    """CV groups on the fit rows: runs, or time spans when there are too few runs."""
    run = np.asarray(campaign.run_index)[rows]
    if np.unique(run).size >= MIN_GROUPS:
        return run
    t = np.asarray(campaign.t)[rows]
    # time from the first fit row, per run, concatenated into one axis
    order = np.arange(t.size)
    span = np.floor(order / max(1, math.ceil(t.size / SPAN_GROUPS))).astype(np.int64)
    return span


def select_terms(y, X, groups, max_terms=MAX_TERMS):
    """Grouped-CV orthogonal matching pursuit. Returns (support indices in order of entry,
    cv MSE for 0..max_terms terms). Sparsity: the fewest terms whose CV MSE is within one
    standard error of the best (0 allowed)."""
    m = X.shape[1]
    kmax = int(min(max_terms, m))
    ng = np.unique(groups).size
    folds = GroupKFold(n_splits=int(min(CV_FOLDS, ng)))
    mse = []
    for tr, te in folds.split(X, y, groups):
        row = [float(np.mean(y[te] ** 2))]
        path = orthogonal_mp(X[tr], y[tr], n_nonzero_coefs=kmax, return_path=True)
        path = path.reshape(m, -1)
        for k in range(kmax):
            coef = path[:, min(k, path.shape[1] - 1)]
            row.append(float(np.mean((y[te] - X[te] @ coef) ** 2)))
        mse.append(row)
    mse = np.asarray(mse)                 # folds x (kmax + 1)
    mean = mse.mean(axis=0)
    # SE of the difference to the best, per fold (paired): the fold-to-fold spread of levels
    # is shared and cancels
    best = int(np.argmin(mean))
    diff = mse - mse[:, [best]]
    se = diff.std(axis=0, ddof=1) / math.sqrt(mse.shape[0]) if mse.shape[0] > 1 else np.zeros(kmax + 1)
    k_star = next(k for k in range(kmax + 1) if mean[k] <= mean[best] + se[k])
    if k_star == 0:
        return [], mean.tolist()
    coef = orthogonal_mp(X, y, n_nonzero_coefs=k_star)
    support = [int(j) for j in np.flatnonzero(coef)]
    # order by entry: re-run the path
    path = orthogonal_mp(X, y, n_nonzero_coefs=k_star, return_path=True).reshape(m, -1)
    order = []
    for k in range(path.shape[1]):
        for j in np.flatnonzero(path[:, k]):
            if j not in order:
                order.append(int(j))
    return [j for j in order if j in support], mean.tolist()


# --------------------------------------------------------------------------- joint refit
class _Refit(TorqueLeastSquares):
    """The project's torque least-squares objective over x = the term coefficients (scaled),
    then the log time constant of each low-passed term (a dynamic's time scale is fitted, not
    taken from the library's grid), then the friction correction (ridge-held at the anchor's
    friction), every x simulated over the whole campaign through the one prediction path."""

    def __init__(self, base: ClutchModel, campaign, rows, terms, scales, sigma_nm, unseen_prior=None):
        self.base = base
        self.terms = list(terms)
        self.scales = np.asarray(scales, float)
        self.k = len(terms)
        self.lagged = [i for i, t in enumerate(self.terms) if t.tau_s > 0]
        self.m = len(self.lagged)
        self.a0 = base.friction_coefficients
        self.others = [m for m in base.mechanisms if m.id != "discovered"]
        self._inputs = PlantInputs.of(campaign)
        ridge = math.sqrt(max(int(rows.sum()), 1)) * sigma_nm / RIDGE_SCALE
        super().__init__(self._predict_xs, campaign.torque_measured, rows, ridge=ridge,
                         ridge_index=slice(self.k + self.m, None), prior=unseen_prior)

    def start(self, coefficients) -> np.ndarray:
        """x of the given term coefficients at the terms' own time constants, no friction change."""
        log_tau = [math.log(self.terms[i].tau_s) for i in self.lagged]
        return np.concatenate([np.asarray(coefficients, float) * self.scales, log_tau, np.zeros(N_CORR)])

    def bounds(self):
        lo = np.concatenate([np.full(self.k, -np.inf), np.full(self.m, math.log(TAU_RANGE_S[0])),
                             np.full(N_CORR, -0.3)])
        hi = np.concatenate([np.full(self.k, np.inf), np.full(self.m, math.log(TAU_RANGE_S[1])),
                             np.full(N_CORR, 0.3)])
        return lo, hi

    def coefficients(self, x):
        return np.asarray(x[:self.k], float) / self.scales

    def terms_at(self, x) -> list:
        """The terms with the time constants of x."""
        out = list(self.terms)
        for j, i in enumerate(self.lagged):
            t = out[i]
            out[i] = Term(t.kind, t.a, t.b, float(math.exp(x[self.k + j])))
        return out

    def model_at(self, x) -> ClutchModel:
        mech = Discovered({"terms": [t.id for t in self.terms_at(x)],
                           "coefficients": [float(c) for c in self.coefficients(x)]})
        a = apply_friction_correction(self.a0, x[self.k + self.m:])
        return self.base.with_friction(a=a).with_mechanisms(self.others + [mech])

    def _predict_xs(self, xs) -> np.ndarray:
        return predict_campaign([self.model_at(x) for x in xs], self._inputs).torque_nm


def unseen_range_prior(sim, slip, fit_rows, sigma_nm) -> np.ndarray:
    """Rows that hold the friction correction near 0 where the fit rows never were.

    The correction is quadratic in pressure and temperature (diagnosis.fitting), and the car
    rows cover a part of the range the bench table measured. Left free, its squares extrapolate:
    measured on slip_power_fade@held#1, a later run 13 °C colder than any fit row came out at
    43.8 N*m against the true torque with the refitted correction, 7.5 N*m with the bench
    friction and the same term. So at points of the friction's domain (a grid of pack
    temperature PRIOR_THETA_C, pressure 0 to 1.5x the highest seen) outside the fit rows'
    box, the correction's change of mu_C and mu_S, and of k_V times the fit rows' RMS slip,
    are pseudo-observations of 0, weighted so that a change of PRIOR_MU in both at every point
    costs one noise-level sum of squares (as the ridge does for the coefficients). Inside the
    box the data decide as before. On that cell (with the fitted time constant): unseen-bag
    gain -81 % without the prior, +20 % with it (PRIOR_MU 0.01: -53 %)."""
    p = np.asarray(sim.pressure_mpa, float)[fit_rows]
    th = np.asarray(sim.pack_temperature_c, float)[fit_rows]
    w = np.abs(np.asarray(slip, float))[fit_rows]
    if p.size == 0:
        return np.zeros((0, N_CORR))
    p_lo, p_hi, th_lo, th_hi = float(p.min()), float(p.max()), float(th.min()), float(th.max())
    w_ref = float(np.sqrt(np.mean(w ** 2)))
    pts = [(pp, tt) for pp in np.linspace(0.0, 1.5 * p_hi, 7) for tt in PRIOR_THETA_C
           if tt < th_lo - PRIOR_MARGIN_C or tt > th_hi + PRIOR_MARGIN_C or pp > 1.05 * p_hi or pp < 0.95 * p_lo]
    if not pts:
        return np.zeros((0, N_CORR))
    weight = math.sqrt(fit_rows.sum() / (2 * len(pts))) * sigma_nm / PRIOR_MU
    rows = np.zeros((2 * len(pts), N_CORR))
    for j, (pp, tt) in enumerate(pts):
        basis = friction_correction_basis(pp, tt)
        rows[2 * j, :5] = basis                          # mu_C and mu_S
        rows[2 * j + 1, 5:] = basis * K_V_SCALE * w_ref  # k_V w (apart: the two may cancel at one slip only)
    return weight * rows


def _ci95(refit: _Refit, x, campaign) -> tuple:
    """Half-widths of 95 % intervals of the term coefficients and of the log time constants
    of the low-passed terms: sandwich covariance with the scores summed per run
    (CI_MIN_RUN_CLUSTERS or more fit runs: an effect that is not the same from run to run,
    e.g. a slow ripple whose phase changes, is not taken for a precise one) or
    else over CI_BLOCK_S blocks of each run (coloured noise within a block), scaled by
    G/(G-1) for G clusters."""
    jac = refit.jacobian(x)
    r = refit.residuals(x)
    n = refit.n_data
    a = jac.T @ jac
    t = np.asarray(campaign.t)[refit.mask]
    run = np.asarray(campaign.run_index)[refit.mask]
    if np.unique(run).size >= CI_MIN_RUN_CLUSTERS:
        blk = run          # clusters = runs: a term's effect may differ from run to run
    else:
        blk = run * 1_000_000 + np.floor((t - t.min()) / CI_BLOCK_S).astype(np.int64)
    _, lab = np.unique(blk, return_inverse=True)
    scores = jac[:n] * r[:n, None]
    s = np.zeros((lab.max() + 1, x.size))
    np.add.at(s, lab, scores)
    g = s.shape[0]
    b = s.T @ s * (g / (g - 1.0) if g > 1 else 1.0)
    try:
        ainv = np.linalg.inv(a)
    except np.linalg.LinAlgError:
        ainv = np.linalg.pinv(a)
    cov = ainv @ b @ ainv
    half = 1.959964 * np.sqrt(np.maximum(np.diag(cov)[:refit.k + refit.m], 0.0))
    return half[:refit.k] / refit.scales, half[refit.k:]


def _rmse(r, mask):
    ok = mask & np.isfinite(r)
    return float(np.sqrt(np.mean(r[ok] ** 2))) if ok.any() else math.nan


# ----------------------------------------------------------------------------- discover
@dataclass
class Search:
    """What the search on the training rows found (no held-out data used): the selected terms
    refitted jointly with the friction inside the simulation (``fit``: coefficients, ci, model,
    predicted measured torque on every row), and what it needs to refit subsets (``refit``)."""

    library: list
    chosen: list                      # Term objects (after dropping those whose interval covers 0)
    fit: dict | None                  # None: nothing selected
    cv_mse: list
    dropped: list                     # [(term ids, coefficients, reason)]
    residual: np.ndarray              # measured - predicted of the starting model, every row
    valid: np.ndarray                 # rows scored at all (finite, not locked, valid_mask)
    refit: Callable = field(repr=False, default=None)   # refit(terms) -> fit dict


def search(campaign, model: ClutchModel, fit_mask, noise_model=None, *, library=None, valid_mask=None,
           max_terms: int = MAX_TERMS, friction_anchor: ClutchModel | None = None, progress=None) -> Search:
    """Steps 1-4 of the module docstring on the training rows ``fit_mask`` only: the sparse
    search on what ``model`` leaves, the joint refit inside the simulation, and the dropping of
    terms whose 95 % interval covers 0. See ``discover`` for the arguments."""
    say = progress or (lambda msg: None)
    library = list(library) if library is not None else default_library()
    say("discovery: simulating the model so far")
    rep = replay_runs(model, campaign)
    sim = rep.sim
    resid = np.asarray(campaign.torque_measured, float) - rep.torque_sim
    valid = np.isfinite(resid) & ~np.asarray(sim.locked, bool)
    if valid_mask is not None:
        valid &= np.asarray(valid_mask, bool)
    fit_rows = valid & np.asarray(fit_mask, bool)
    if fit_rows.sum() < 50:
        raise DataError("discovery needs slipping rows with a measured torque on the fit data")
    sigma = _noise_sigma(noise_model, np.where(fit_rows, resid, np.nan), np.asarray(campaign.run_start, bool))

    # ---- regressors on the fit rows, friction directions projected out
    sig = TermSignals.from_simulation(campaign, sim)
    cols = np.column_stack([t.regressor(sig) for t in library])[fit_rows]
    z = friction_directions(sig)[fit_rows]
    y = resid[fit_rows]
    zq, _ = np.linalg.qr(z)
    x_perp = cols - zq @ (zq.T @ cols)
    y_perp = y - zq @ (zq.T @ y)
    norms = np.sqrt(np.mean(x_perp ** 2, axis=0))
    usable = norms > 1e-9 * max(float(np.sqrt(np.mean(y ** 2))), 1e-12)
    xs = np.where(usable[None, :], x_perp / np.where(usable, norms, 1.0)[None, :], 0.0)
    groups = _groups(campaign, fit_rows)

    say("discovery: sparse search (orthogonal matching pursuit, grouped cross-validation)")
    support, cv_mse = select_terms(y_perp, xs[:, usable], groups, max_terms)
    idx_usable = np.flatnonzero(usable)
    chosen = [library[int(idx_usable[j])] for j in support]
    for t in list(chosen):   # a once-per-revolution term comes with its quadrature partner
        p = partner(t)
        if p is not None and p.id not in {c.id for c in chosen}:
            chosen.append(p)
    chosen = _one_time_constant_each(chosen)[:P.MAX_DISCOVERED_TERMS]

    lib_ids = [t.id for t in library]
    anchor = model if friction_anchor is None else friction_anchor.with_mechanisms(model.mechanisms)

    def column(term):
        """A term's projected regressor on the fit rows (None: the projected residual)."""
        if term is None:
            return y_perp
        if term.id in lib_ids:
            return x_perp[:, lib_ids.index(term.id)]
        c = term.regressor(sig)[fit_rows]
        return c - zq @ (zq.T @ c)

    def refit(terms):
        return _refit_terms(terms, column, sig, sim, fit_rows, anchor, campaign, sigma, say)

    out = Search(library=library, chosen=chosen, fit=None, cv_mse=cv_mse, dropped=[], residual=resid,
                 valid=valid, refit=refit)
    # linear start, joint refit inside the simulation; terms whose 95 % interval covers 0 are
    # dropped and the rest refitted (a ripple pair stays while either half holds)
    while chosen:
        try:
            fit = refit(chosen)
        except (ValueError, np.linalg.LinAlgError) as exc:
            # a numerical failure of the joint refit (e.g. a term that makes the simulation run
            # away at every step the solver tries) means these terms cannot be fitted: none is
            # named, and the report says why
            text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            out.dropped.append(([t.id for t in chosen], [], f"dropped: the joint refit failed ({text})"))
            say(f"discovery: the joint refit of {', '.join(t.id for t in chosen)} failed ({text})")
            chosen = []
            break
        chosen = fit["terms"]
        keep = _significant(chosen, fit["ci"])
        why = "95 % interval covers 0"
        if len(keep) == len(chosen):
            keep = _material(chosen, fit, sig, campaign, fit_rows)
            why = f"its effect is below {100 * MATERIAL_FRAC:.0f} % of what remains (immaterial)"
        if len(keep) == len(chosen):
            out.chosen, out.fit = chosen, fit
            break
        out.dropped.append(([t.id for t in chosen], list(fit["coefficients"]),
                            "dropped: " + ", ".join(t.id for t in chosen if t not in keep) + f" ({why})"))
        chosen = keep
    if not chosen:
        out.chosen = []
    return out


def discover(campaign, calibrated_model: ClutchModel, split, noise_model=None, *, library=None,
             held_out_test=None, valid_mask=None, max_terms: int = MAX_TERMS,
             friction_anchor: ClutchModel | None = None, progress=None) -> DiscoveryResult:
    """Search ``library`` (terms.default_library()) for terms that explain what the calibrated
    model leaves on the fit runs, refit them inside the simulation, and accept them only if
    ``held_out_test`` (heldout.block_gain_test) says they hold on the held-out rows.

    campaign: clutch_model.formats.bag_reader.Campaign (measured torque on its grid);
    split: held-out run names, a boolean held-out row mask, or an object with ``eval_mask``
    (or ``held_out`` names); noise_model: optional object with ``sigma_nm`` (the noise level,
    used to weigh the friction correction's ridge); valid_mask: optional rows to use at all
    (e.g. rows where the measurement has its own sample); locked rows are always left out.
    friction_anchor: the model whose friction the refit's correction starts from and is held
    near (the bench-fitted model the calibration started from; default: the calibrated model).
    A calibration on car data absorbs whatever part of a missing term its friction polynomials
    can mimic (friction falling with slip power looks much like k_V rising less with pressure);
    anchored on the bench friction, the joint refit gives that part back to the term.
    """
    library = list(library) if library is not None else default_library()
    test = held_out_test or block_gain_test
    eval_mask = _eval_mask(split, campaign)
    found = search(campaign, calibrated_model, ~eval_mask, noise_model, library=library, valid_mask=valid_mask,
                   max_terms=max_terms, friction_anchor=friction_anchor, progress=progress)
    resid, valid, cv_mse = found.residual, found.valid, found.cv_mse
    eval_rows = valid & eval_mask
    if eval_rows.sum() < 10:
        raise DataError("discovery needs slipping rows with a measured torque on the held-out data")
    base_rmse = _rmse(resid, eval_rows)
    tried = [Tried(ids, coefs, math.nan, HeldOutVerdict(False, 0.0, base_rmse, math.nan, 0.0, "-", reason))
             for ids, coefs, reason in found.dropped]
    empty = DiscoveryResult(accepted=False, terms=[], coefficients=np.zeros(0), parameters_ci95={},
                            readings=[], evidence="", rmse_nm={"calibrated": base_rmse, "extended": base_rmse},
                            gain_pct=0.0, model=None, verdict=None, tried=tried, cv_mse=cv_mse,
                            base_residual=resid)
    if found.fit is None:
        empty.evidence = ("Discovery: the sparse search over "
                          f"{len(library)} candidate terms found none that predicts the calibrated model's "
                          "residual across fit runs better than nothing (grouped cross-validation, "
                          "one-standard-error rule, 95 % intervals excluding 0).")
        return empty
    chosen, fit, keep = found.chosen, found.fit, found.chosen
    base_eval = np.where(valid, resid, np.nan)
    resid_ext = np.where(valid, np.asarray(campaign.torque_measured, float) - fit["predicted"], np.nan)
    verdict = test(campaign, eval_rows, base_eval, resid_ext)
    # each term (a ripple pair as one) must earn its place on the held-out data too: the
    # extension refitted without it must lose to the extension with it, else it goes
    while verdict.accepted and keep and len(_term_groups(chosen)) > 1:
        weakest = None
        for group in _term_groups(chosen):
            rest = [t for t in chosen if t not in group]
            fit_r = found.refit(rest)
            resid_r = np.where(valid, np.asarray(campaign.torque_measured, float) - fit_r["predicted"], np.nan)
            v = test(campaign, eval_rows, resid_r, resid_ext)
            if not v.accepted and (weakest is None or v.z_stat < weakest[1].z_stat):
                weakest = (group, v, rest, fit_r, resid_r)
        if weakest is None:
            break
        group, v, rest, fit_r, resid_r = weakest
        tried.append(Tried([t.id for t in chosen], list(fit["coefficients"]), _rmse(resid_ext, eval_rows),
                           HeldOutVerdict(False, v.gain_pct, v.rmse_base_nm, v.rmse_candidate_nm, v.z_stat,
                                          v.runs_improved,
                                          f"dropped {', '.join(t.id for t in group)}: it adds nothing that "
                                          f"holds on the held-out data ({v.reason})")))
        chosen, fit, resid_ext = fit_r["terms"], fit_r, resid_r
        verdict = test(campaign, eval_rows, base_eval, resid_ext)
    coefs, ci, model = fit["coefficients"], fit["ci"], fit["model"]
    if verdict.accepted and keep:
        verdict = _holds_run_by_run(verdict, chosen, coefs, model, campaign, resid_ext, eval_rows)
    if verdict.accepted and not keep:
        verdict = HeldOutVerdict(False, verdict.gain_pct, verdict.rmse_base_nm, verdict.rmse_candidate_nm,
                                 verdict.z_stat, verdict.runs_improved,
                                 "no term's 95 % interval excludes 0 on the fit runs")
    ext_rmse = _rmse(resid_ext, eval_rows)
    tried.append(Tried([t.id for t in chosen], list(coefs), ext_rmse, verdict))
    readings = describe(chosen, coefs, ci, fit.get("tau_ci95_s"))

    if not verdict.accepted:
        empty.tried = tried
        empty.evidence = (f"Discovery tried {'; '.join(readings)}: refitted jointly with the friction inside "
                          f"the simulation it does not hold ({verdict.reason}); "
                          "the structure stays unexplained.")
        return empty
    if any(t.a == "energy" or t.b == "energy" for t in chosen):
        _record_energy_history(model, campaign)
    evidence = (f"Beyond the catalog, a sparse search over {len(library)} physical candidate terms "
                f"(orthogonal matching pursuit, cross-validated across fit runs) on the calibrated model's "
                f"residual, refitted jointly with the friction inside the simulation, finds: "
                + "; ".join(readings) + f". On the held-out data: {verdict.reason}.")
    return DiscoveryResult(accepted=True, terms=chosen, coefficients=coefs, parameters_ci95=ci,
                           readings=readings, evidence=evidence,
                           rmse_nm={"calibrated": base_rmse, "extended": ext_rmse},
                           gain_pct=verdict.gain_pct, model=model, verdict=verdict, tried=tried,
                           cv_mse=cv_mse, residual=resid_ext, base_residual=resid)


def _holds_run_by_run(verdict, terms, coefs, model, campaign, resid_ext, eval_rows) -> HeldOutVerdict:
    """What remains must not still follow the terms: on each held-out run, the coefficients
    that would fit that run best (least squares of the extended residual on the terms'
    regressors) must be a small correction of the fitted ones. The RMS of that per-run
    correction relative to the RMS of the terms' whole effect on the run must stay below
    RUN_CORRECTION_MAX in the median held-out run. An effect whose form holds but whose size or
    phase differs from run to run (a ripple with a random phase per run) fails here even when a
    lucky phase gives a held-out gain."""
    sim = replay_runs(model, campaign).sim
    sig = TermSignals.from_simulation(campaign, sim)
    xr = np.column_stack([t.regressor(sig) for t in terms])
    effect = xr @ np.asarray(coefs, float)
    ratios = []
    for j in np.unique(np.asarray(campaign.run_index)[eval_rows]):
        rows = eval_rows & (np.asarray(campaign.run_index) == j) & np.isfinite(resid_ext)
        if rows.sum() < 20:
            continue
        e_rms = float(np.sqrt(np.mean(effect[rows] ** 2)))
        if e_rms <= 0:
            continue
        delta = np.linalg.lstsq(xr[rows], resid_ext[rows], rcond=None)[0]
        ratios.append(float(np.sqrt(np.mean((xr[rows] @ delta) ** 2))) / e_rms)
    if not ratios:
        return verdict
    med = float(np.median(ratios))
    if med <= RUN_CORRECTION_MAX:
        return verdict
    return HeldOutVerdict(False, verdict.gain_pct, verdict.rmse_base_nm, verdict.rmse_candidate_nm, verdict.z_stat,
                          verdict.runs_improved,
                          f"what remains on the held-out runs still follows the terms: each run would want "
                          f"them changed by {100 * med:.0f} % of their effect (median; at most "
                          f"{100 * RUN_CORRECTION_MAX:.0f} % for an effect that holds from run to run)")


def _material(terms, fit, sig, campaign, fit_rows) -> list:
    """Term groups whose effect on the fit rows (RMS of coefficient x regressor) is at least
    MATERIAL_FRAC of the RMS of what the extension leaves there."""
    left = (np.asarray(campaign.torque_measured, float) - fit["predicted"])[fit_rows]
    left_rms = float(np.sqrt(np.nanmean(left ** 2)))
    coef = dict(zip([t.id for t in terms], fit["coefficients"]))
    keep = []
    for group in _term_groups(terms):
        effect = sum(coef[t.id] * t.regressor(sig) for t in group)[fit_rows]
        if float(np.sqrt(np.mean(effect ** 2))) >= MATERIAL_FRAC * left_rms:
            keep += group
    return keep


def _one_time_constant_each(terms) -> list:
    """One low-passed term per signal: the library offers a slip-power low-pass at two time
    constants, and the refit fits the time constant, so a second one of the same signal would
    converge onto the first (both then carry half the effect, and neither interval excludes 0).
    The one the search chose first stays, its time constant a start."""
    out, seen = [], set()
    for t in terms:
        key = (t.kind, t.a, t.b)
        if t.tau_s > 0 and key in seen:
            continue
        if t.tau_s > 0:
            seen.add(key)
        out.append(t)
    return out


def _term_groups(terms) -> list:
    """Terms as the units that enter or leave together (a sin/cos ripple pair is one)."""
    groups, seen = [], set()
    for t in terms:
        if t.id in seen:
            continue
        p = partner(t)
        g = [t] + ([q for q in terms if p is not None and q.id == p.id])
        seen |= {q.id for q in g}
        groups.append(g)
    return groups


def _significant(terms, ci) -> list:
    """Terms whose 95 % interval excludes 0; both halves of a ripple pair if either does."""
    sig_ids = {t.id for t in terms if not (ci[t.id][0] <= 0.0 <= ci[t.id][1])}
    keep = []
    for t in terms:
        p = partner(t)
        if t.id in sig_ids or (p is not None and p.id in sig_ids):
            keep.append(t)
    return keep


def _refit_terms(chosen, column, sig, sim, fit_rows, anchor, campaign, sigma, say) -> dict:
    """Linear start from the projected regression (``column(term)``: a term's regressor on the
    fit rows with the friction directions projected out), then least_squares inside the
    simulation over the coefficients, the low-passed terms' time constants and the friction
    correction. The fit's ``terms`` carry the fitted time constants."""
    a_lin = np.linalg.lstsq(np.column_stack([column(t) for t in chosen]), column(None), rcond=None)[0]
    # scales: a coefficient of 1e-2 in scaled units moves the torque by ~1 % of its RMS
    torque_rms = max(float(np.sqrt(np.mean(sim.asperity_torque_nm[fit_rows] ** 2))), 1e-9)
    scales = []
    for t in chosen:
        g_rms = max(float(np.sqrt(np.mean(t.feature(sig)[fit_rows] ** 2))), 1e-12)
        scales.append(g_rms if t.kind == "mu" else g_rms / torque_rms)
    say(f"discovery: refitting {', '.join(t.id for t in chosen)} jointly with the friction (simulated)")
    refit = _Refit(anchor, campaign, fit_rows, chosen, scales, sigma,
                   unseen_prior=unseen_range_prior(sim, campaign.slip, fit_rows, sigma))
    lo, hi = refit.bounds()
    x0 = np.clip(refit.start(a_lin), lo, hi)
    # a trial step may drive the simulation out of range: its residuals overflow to inf and the
    # trust region rejects the step; a direction the rows do not resolve gets an infinite
    # interval (no name). Neither is worth a RuntimeWarning on the user's console.
    with np.errstate(over="ignore", invalid="ignore"):
        sol = least_squares(refit.residuals, x0, jac=refit.jacobian, bounds=(lo, hi), method="trf",
                            x_scale="jac", max_nfev=REFIT_NFEV, xtol=1e-8, ftol=1e-8)
        x = sol.x
        coefs = refit.coefficients(x)
        terms = refit.terms_at(x)
        half, half_log_tau = _ci95(refit, x, campaign)
    tau_ci = {terms[i].id: tau_interval_s(terms[i].tau_s, h) for i, h in zip(refit.lagged, half_log_tau)}
    return {"terms": terms, "coefficients": coefs, "model": refit.model_at(x), "predicted": refit.predict([x])[0],
            "ci": {t.id: [float(c - h), float(c + h)] for t, c, h in zip(terms, coefs, half)},
            "tau_ci95_s": tau_ci}


def tau_interval_s(tau_s: float, half_log_tau: float) -> list:
    """[tau e^-h, tau e^h]: the 95 % interval of a time constant whose log has half-width h. A
    time constant the rows do not resolve has an interval of [0, inf]: its half-width in log
    may exceed exp's range (h = 1e3 raised OverflowError and ended a diagnosis: a second-order
    actuator on the car, seed 3 of the matrix)."""
    with np.errstate(over="ignore"):
        return [float(tau_s * np.exp(-half_log_tau)), float(tau_s * np.exp(half_log_tau))]


def _record_energy_history(model: ClutchModel, campaign) -> None:
    """As the diagnosis does for friction_degradation: the campaign energy at each run's start
    and end, so a later replay of runs after this campaign continues from it."""
    energy = replay_runs(model, campaign, energy0_j=0.0).sim.energy_j
    hist = []
    for r, sl in campaign.slices():
        e = energy[sl]
        hist.append([int(r.start_time_ns), float(e[0])])
        hist.append([int(r.start_time_ns + round(float(r.t[-1]) * 1e9)), float(e[-1])])
    model.mechanism("discovered").values["energy_history"] = hist
