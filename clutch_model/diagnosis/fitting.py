"""Joint fits of a candidate mechanism and a small friction correction on car runs.

Every candidate (and the baseline, with no mechanism) is refitted the same way so that
their held-out errors compare like with like: the mechanism's physical parameters plus an
additive friction correction within the thesis' polynomial structure,

    mu_C, mu_S += c0 + c1 p + c2 p^2 + c3 q + c4 q^2         (mu_S - mu_C unchanged)
    k_V        += (k0 + k1 p + k2 p^2 + k3 q + k4 q^2) / 10
    p = P - 1 MPa,  q = (theta - 80 C) / 50 C,

i.e. the 10 coefficients of mu_C and k_V that car runs (slip >> omega_S) can identify, moved
in a well-conditioned basis; the correction is exact in a0..a19. A weak ridge keeps it small
where the runs do not constrain it. The objective is the one torque least-squares objective
(``identification.objective``): predicted *measured* torque (``prediction.predict_campaign``)
minus measured, on the fit runs only; the whole campaign is always simulated (in time order,
energy from 0 at its start) so that state that carries between runs (dissipated energy) sees
every run's inputs. Each mechanism brings its own search space (``Mechanism.search_space``).
Jacobians are forward differences computed as one parallel batch of perturbed parameter sets.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from clutch_model.formats.bag_reader import Campaign
from clutch_model.identification.objective import TorqueLeastSquares
from clutch_model.plant.mechanisms import CATALOG, DIAGNOSIS_CANDIDATES, CampaignScale, ParamSpec, make_mechanism
from clutch_model.plant.params import ClutchModel
from clutch_model.prediction import PlantInputs, predict_campaign

N_CORR = 10
P_CENTER_MPA = 1.0
THETA_CENTER_C, THETA_SCALE_C = 80.0, 50.0
K_V_SCALE = 0.1
RIDGE_SCALE = 0.05     # a correction of 0.05 in mu costs about one noise-level SSE


P_SCALE_MPA = 1.0


def friction_correction_basis(pressure_mpa, pack_temperature_c) -> np.ndarray:
    """[1, p, p^2, q, q^2] at a point, or one such row per point of arrays (p = (P -
    P_CENTER_MPA) / P_SCALE_MPA, q = (theta - THETA_CENTER_C) / THETA_SCALE_C): the change of
    mu_C and mu_S there is this . delta[:5], of k_V this . delta[5:] * K_V_SCALE
    (apply_friction_correction)."""
    p = (np.asarray(pressure_mpa, float) - P_CENTER_MPA) / P_SCALE_MPA
    q = (np.asarray(pack_temperature_c, float) - THETA_CENTER_C) / THETA_SCALE_C
    return np.stack([np.ones_like(p), p, p * p, q, q * q], axis=-1)


def _quadratic_in_poly(block: np.ndarray, c, pc, ps, tc, ts):
    """Add c0 + c1 p + c2 p^2 + c3 q + c4 q^2 (p=(P-pc)/ps, q=(theta-tc)/ts) to a polynomial
    block [1, P, P^2, theta, theta^2] exactly."""
    c0, c1, c2, c3, c4 = c
    block[0] += c0 - c1 * pc / ps + c2 * pc * pc / ps ** 2 - c3 * tc / ts + c4 * tc * tc / ts ** 2
    block[1] += c1 / ps - 2 * c2 * pc / ps ** 2
    block[2] += c2 / ps ** 2
    block[3] += c3 / ts - 2 * c4 * tc / ts ** 2
    block[4] += c4 / ts ** 2


def apply_friction_correction(a: np.ndarray, delta) -> np.ndarray:
    """Coefficients a0..a19 with the additive friction correction folded in."""
    delta = np.asarray(delta, dtype=float)
    a = np.array(a, dtype=float)
    for base in (0, 5):          # mu_C and mu_S move together
        _quadratic_in_poly(a[base:base + 5], delta[:5], P_CENTER_MPA, P_SCALE_MPA, THETA_CENTER_C, THETA_SCALE_C)
    _quadratic_in_poly(a[15:20], delta[5:10] * K_V_SCALE, P_CENTER_MPA, P_SCALE_MPA, THETA_CENTER_C, THETA_SCALE_C)
    return a


def search_space(mech_id: str, campaign: Campaign, energy_total_j: float, torque_scale: float):
    """The mechanism's own search space on this campaign (start grids span what a car shows)."""
    return CATALOG[mech_id].search_space(CampaignScale.of(campaign, energy_total_j, torque_scale))


@dataclass
class CandidateFit:
    id: str                      # mechanism id, or "baseline"
    model: ClutchModel
    parameters: dict
    friction_correction: np.ndarray
    fit_rmse_nm: float
    held_out_rmse_nm: float = math.nan
    joint: bool = False          # refitted jointly with the friction correction
    residual: np.ndarray = field(default=None, repr=False)   # measured - predicted, whole campaign
    predicted: np.ndarray = field(default=None, repr=False)
    evaluations: int = 0
    co_parameters: dict = field(default_factory=dict)   # {mech_id: {parameter: value}} of the mechanisms
                                                        # of the base refitted with it (co_fitted_ids)


def time_parameter_names(mech_id: str) -> tuple:
    """The catalog mechanism's parameters in seconds (a delay, a lag); () for an id outside the
    catalog."""
    return CATALOG[mech_id].time_parameter_names() if mech_id in CATALOG else ()


def time_mechanism_ids(ids) -> list:
    """The ids among ``ids`` whose catalog mechanism acts in time (a parameter in seconds)."""
    return [i for i in ids if time_parameter_names(i)]


def co_fitted_ids(mech_id: str | None, base: ClutchModel) -> tuple:
    """The mechanisms of ``base`` whose parameters move with ``mech_id``'s when it is fitted on
    top of them: a mechanism that acts in time (a delay, a lag) is fitted together with the
    time mechanisms already in the model. Two of them in series add their group delays, so
    the first one named has taken up the sum and the second, fitted alone on top of it, only
    adds delay: on a true 80 ms actuator lag + 40 ms transport delay (three 30 s runs, AR(1)
    0.9 torque noise) the lag was fitted at 119 ms and a delay on top of it at 8 ms, worse
    on the held-out rows (t = -1.5), and the pair was never named."""
    if mech_id is None or not time_mechanism_ids([mech_id]):
        return ()
    return tuple(i for i in time_mechanism_ids([m.id for m in base.mechanisms]) if i != mech_id)


CO_START_SCALES = (1.0, 0.67, 0.33)    # a co-fitted time parameter starts at these shares of its value


class CampaignObjective(TorqueLeastSquares):
    """The torque least-squares objective of one candidate: x = the mechanism's parameters
    (in their search transform), then those of the mechanisms of ``base`` co-fitted with it
    (``co_specs``: [(mech_id, [ParamSpec])]), then the friction correction."""

    def __init__(self, base: ClutchModel, campaign: Campaign, fit_mask: np.ndarray, mech_id: str | None,
                 specs, fit_friction: bool = True, noise_sigma_nm: float = 1.0, co_specs=(),
                 ridge_factor: float = 1.0):
        self.base = base
        self.campaign = campaign
        self.mech_id = mech_id
        self.own_specs = list(specs or [])
        self.co_specs = [(cid, list(cs)) for cid, cs in co_specs]
        self.specs = self.own_specs + [s for _, cs in self.co_specs for s in cs]
        # ridge_factor multiplies the friction correction's ridge (friction_ridge.choose_ridge_factor
        # for the written models); infinite: no correction is fitted
        self.fit_friction = bool(fit_friction) and math.isfinite(ridge_factor)
        self.a0 = base.friction_coefficients
        self.n_mech = len(self.specs)
        mask = fit_mask & np.isfinite(campaign.torque_measured)
        n_fit = int(mask.sum())
        ridge = (ridge_factor * math.sqrt(max(n_fit, 1)) * noise_sigma_nm / RIDGE_SCALE
                 if self.fit_friction else 0.0)
        self._plant_inputs = PlantInputs.of(campaign)
        super().__init__(self._predict_xs, campaign.torque_measured, mask, ridge=ridge,
                         ridge_index=slice(self.n_mech, None), steps=self._fd_steps)

    def values_at(self, x) -> dict:
        """{mech_id: {parameter: value}} of the candidate and the co-fitted mechanisms at x."""
        x = np.asarray(x, dtype=float)
        out, j = {}, 0
        for mid, specs in ([(self.mech_id, self.own_specs)] if self.mech_id is not None else []) + self.co_specs:
            out[mid] = {s.name: s.from_x(x[j + k]) for k, s in enumerate(specs)}
            j += len(specs)
        return out

    def model_at(self, x) -> ClutchModel:
        x = np.asarray(x, dtype=float)
        values = self.values_at(x)
        co = {cid: make_mechanism(cid, **{**next(m.values for m in self.base.mechanisms if m.id == cid),
                                         **values[cid]}) for cid, _ in self.co_specs}
        mechs = [co.get(m.id, m) for m in self.base.mechanisms if m.id != self.mech_id]
        if self.mech_id is not None:
            mechs.append(make_mechanism(self.mech_id, **values[self.mech_id]))
        delta = x[self.n_mech:] if self.fit_friction else np.zeros(N_CORR)
        return self.base.with_friction(a=apply_friction_correction(self.a0, delta)).with_mechanisms(mechs)

    def _predict_xs(self, xs) -> np.ndarray:
        """Predicted measured torque on the whole campaign (energy from 0 at its start)."""
        return predict_campaign([self.model_at(x) for x in xs], self._plant_inputs, energy0_j=0.0).torque_nm

    def _fd_steps(self, x) -> np.ndarray:
        steps = np.where(np.arange(x.size) < self.n_mech, 1e-3 * np.maximum(np.abs(x), 1.0), 1e-4)
        for j, s in enumerate(self.specs):
            hi = math.log(s.hi) if s.log else s.hi
            if x[j] + steps[j] > hi:
                steps[j] = -steps[j]
        return steps

    def bounds(self):
        lo = [math.log(s.lo) if s.log else s.lo for s in self.specs]
        hi = [math.log(s.hi) if s.log else s.hi for s in self.specs]
        if self.fit_friction:
            lo += [-0.3] * N_CORR
            hi += [0.3] * N_CORR
        return np.array(lo), np.array(hi)


def _rmse(r):
    return float(np.sqrt(np.mean(r ** 2))) if r.size else math.nan


def start_shift(x0: np.ndarray, specs) -> np.ndarray:
    """Per coordinate of x, what to add so that no mechanism parameter starts at ~0.

    scipy's trf takes its first trust-region radius as the norm of x0 in Jacobian-scaled units
    (1 only when x0 is exactly 0), and stops on ``ftol`` when the first steps gain nothing.
    A torque offset whose grid's best point is its centre (2.8e-14 N*m) or a drag coefficient
    clipped to 1e-12 above its bound therefore never moved: on a campaign with a 15.3 N*m offset
    the offset fitted on the bench friction stayed at 6e-14 N*m (from a start at exactly 0 the
    same solver reaches 15.4 N*m). Such a coordinate is shifted by its grid's spacing, which the
    radius then starts from; other coordinates are left alone, so fits that did move are
    unchanged."""
    shift = np.zeros_like(x0)
    for j, s in enumerate(specs):
        xs = np.array([s.to_x(v) for v in s.grid], dtype=float)
        step = float(np.min(np.abs(np.diff(xs)))) if xs.size > 1 else 1.0
        step = step if step > 0 and math.isfinite(step) else 1.0
        if abs(x0[j]) < 1e-6 * step:
            shift[j] = step
    return shift


def solve_from(obj: CampaignObjective, x0: np.ndarray, max_nfev: int) -> np.ndarray:
    """The least-squares solution of ``obj`` from ``x0`` (trf within its bounds; x0 clipped just
    inside them)."""
    lo, hi = obj.bounds()
    x0 = np.clip(x0, lo + 1e-12, hi - 1e-12)
    # solved in u = x + shift: trf's first trust radius is |x0| in Jacobian-scaled units, so
    # a start at ~0 (an offset's grid centre, a drag coefficient at its bound) would never move
    shift = start_shift(x0, obj.specs)
    sol = least_squares(lambda u: obj.residuals(u - shift), x0 + shift, jac=lambda u: obj.jacobian(u - shift),
                        bounds=(lo + shift, hi + shift), method="trf", x_scale="jac", max_nfev=max_nfev,
                        xtol=1e-8, ftol=1e-8)
    return np.clip(sol.x - shift, lo, hi)     # the shift's rounding kept off the bounds' wrong side


def fit_candidate(base: ClutchModel, campaign: Campaign, fit_mask: np.ndarray, mech_id: str | None,
                  energy_total_j: float, torque_scale: float, fit_friction: bool = True,
                  max_nfev: int = 40, noise_sigma_nm: float = 1.0, start: dict | None = None,
                  co_start: dict | None = None, ridge_factor: float = 1.0) -> CandidateFit:
    """Fit one candidate (mech_id=None: the baseline with the friction correction only); the
    mechanisms of ``base`` that ``co_fitted_ids`` names move with it (``co_start``: {mech_id:
    {parameter: value}} to start them from, else their values in ``base``). ``ridge_factor``
    multiplies the friction correction's ridge (infinite: no correction is fitted)."""
    specs = search_space(mech_id, campaign, energy_total_j, torque_scale) if mech_id else []
    co_ids = co_fitted_ids(mech_id, base)
    co_specs = [(cid, search_space(cid, campaign, energy_total_j, torque_scale)) for cid in co_ids]
    obj = CampaignObjective(base, campaign, fit_mask, mech_id, specs, fit_friction, noise_sigma_nm, co_specs,
                            ridge_factor)
    fit_friction = obj.fit_friction
    n_corr = N_CORR if fit_friction else 0
    # the co-fitted parameters start at co_start, else at their values in base
    values0 = {**{m.id: m.values for m in base.mechanisms}, **(co_start or {})}
    co_flat = [(s, float(values0[cid][s.name])) for cid, cs in co_specs for s in cs]
    co_x = np.array([s.to_x(v) for s, v in co_flat])
    # start: the best point of the mechanism's grid (friction correction at 0), one batch; the
    # co-fitted parameters there at CO_START_SCALES shares of their start
    if specs and start:
        x0 = np.concatenate([[s.to_x(start[s.name]) for s in specs], co_x, np.zeros(n_corr)])
    elif specs:
        grid = np.array([[s.to_x(v) for v in s.grid] for s in specs]).T  # 1-parameter mechanisms
        co_rows = ([np.array([s.to_x(min(max(v * f, s.lo), s.hi)) for s, v in co_flat]) for f in CO_START_SCALES]
                   if co_flat else [co_x])
        xs = np.array([np.concatenate([g, c, np.zeros(n_corr)]) for c in co_rows for g in grid])
        preds = obj.predict(xs)
        sse = np.nansum(obj.data_residuals(preds) ** 2, axis=1)
        x0 = xs[int(np.argmin(sse))]
    else:
        x0 = np.zeros(n_corr)
    x = solve_from(obj, x0, max_nfev) if x0.size else x0
    model = obj.model_at(x)
    pred = obj.predict([x])[0]
    resid = campaign.torque_measured - pred
    values = obj.values_at(x)
    params = values.pop(mech_id, {})
    return CandidateFit(id=mech_id or "baseline", model=model, parameters=params, joint=fit_friction,
                        friction_correction=x[obj.n_mech:] if fit_friction else np.zeros(N_CORR),
                        fit_rmse_nm=_rmse(resid[obj.mask]), residual=resid, predicted=pred,
                        evaluations=obj.evaluations, co_parameters=values)


CANDIDATE_IDS = list(DIAGNOSIS_CANDIDATES)
__all__ = ["CANDIDATE_IDS", "CampaignObjective", "CandidateFit", "ParamSpec", "apply_friction_correction",
           "fit_candidate", "search_space"]
