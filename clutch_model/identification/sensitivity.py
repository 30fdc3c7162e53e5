"""Sensitivity analysis — thesis §3.3 (eq. 3.19-3.20) and beyond.

* ``friction_sensitivity``: the thesis experiment. Constant inputs w = 60 rpm (2 pi rad/s),
  theta_sump = 60 C, P = 500 kPa (force = P A_N); mu_f perturbed by +-1 % by scaling the mu_C
  and mu_S polynomials (a0..a9) and k_V (a15..a19) by (1 +- 0.01), which scales
  mu_f = mu_C + (mu_S - mu_C) e + k_V w exactly by (1 +- 0.01) (omega_S untouched);
  S(t) = (T(mu_f + d) - T(mu_f - d)) / (2 d), d = 0.01 mu_f(t) (figures 3.6-3.7).
* ``parameter_sensitivities``: every physical parameter of the model (geometry, surface,
  viscosity, thermal, friction, initial film): normalised sensitivity (dT/dp) p/T
  time-averaged over the steady state (film settled), by central differences at two relative
  steps that are checked against each other. One batch-simulator call.
* ``identifiability_screen`` / ``identifiable_coefficients``: which friction coefficients the
  car data can identify at all. A global Morris screen (SALib trajectories, +-spread around
  the model; elementary effects taken on the whole torque trace, so mu* is the RMS torque
  change in N*m per full-range move) keeps the coefficients with an effect above a threshold;
  then a local collinearity filter (Brun et al. 2001: collinearity index of the normalised
  sensitivity columns <= gamma_max; greedy, constant terms first, then linear, then quadratic,
  each group by decreasing sensitivity) drops the ones whose effect the already selected
  coefficients reproduce.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from clutch_model.plant import params as P
from clutch_model.plant.params import ClutchModel
from clutch_model.plant.simulate import simulate, simulate_batch
from clutch_model.identification import box
from clutch_model.identification.evaluate import CampaignInputs, as_campaign, param_rows, predict

_DEGREE = (0, 1, 2, 1, 2)   # of the monomials 1, P, P^2, theta, theta^2

# friction coefficients that scale mu_f exactly (mu_C, mu_S, k_V); omega_S not
MU_SCALING_COEFFS = list(range(0, 10)) + list(range(15, 20))

PARAMETER_NAMES = {
    P.R_OUTER: "geometry.r_outer", P.R_INNER: "geometry.r_inner", P.N_FRICTION: "geometry.friction_surfaces",
    P.N_SEPARATOR: "geometry.separator_plates", P.A_RED: "geometry.non_grooved_fraction",
    P.SIGMA: "surface.rms_roughness", P.YOUNGS: "surface.youngs_modulus",
    P.ASP_DENSITY: "surface.asperity_density", P.ASP_RADIUS: "surface.asperity_tip_radius",
    P.K_PERM: "surface.permeability", P.LINING_D: "surface.lining_thickness",
    P.BJ_CHI: "surface.beavers_joseph_chi", P.ALPHA0: "viscosity.alpha0", P.ALPHA1: "viscosity.alpha1",
    P.PLATE_HEAT_CAPACITY: "thermal.plate_heat_capacity", P.B1: "thermal.b1", P.B2: "thermal.b2",
    P.B3: "thermal.b3", P.B4: "thermal.b4", P.HTF_MIN: "thermal.htf_min", P.FRICTION_I: "friction.i",
    **{P.FRICTION_A + k: f"friction.a{k}" for k in range(20)}, P.H0: "initial.film_thickness",
}


def scale_friction(a, factor):
    """Coefficients with mu_f scaled exactly by ``factor`` (a0..a9, a15..a19 scaled)."""
    a = np.array(a, dtype=float)
    a[MU_SCALING_COEFFS] *= factor
    return a


# --- the thesis experiment (eq. 3.19-3.20) ---------------------------------------------------------
@dataclass
class ThesisScenario:
    slip_rad_s: float = 2.0 * math.pi     # 60 rpm
    sump_c: float = 60.0
    pressure_mpa: float = 0.5             # 500 kPa
    duration_s: float = 3.0
    rate_hz: float = 1000.0

    def inputs(self, model: ClutchModel):
        t = np.arange(0.0, self.duration_s + 0.5 / self.rate_hz, 1.0 / self.rate_hz)
        force = np.full(t.size, self.pressure_mpa * 1e6 * model.nominal_area_m2)
        return t, force, np.full(t.size, self.slip_rad_s), np.full(t.size, self.sump_c)


@dataclass
class FrictionSensitivity:
    t: np.ndarray
    torque_nominal: np.ndarray
    torque_plus: np.ndarray
    torque_minus: np.ndarray
    mu_f: np.ndarray
    sensitivity: np.ndarray          # dT/dmu_f, N*m per unit mu_f (eq. 3.20)
    normalized: np.ndarray           # dT/dmu_f * mu_f / T
    rel_step: float
    steady_from_s: float
    scenario: ThesisScenario

    @property
    def steady(self) -> np.ndarray:
        return self.t >= self.steady_from_s

    def steady_mean(self) -> tuple:
        s = self.steady
        return float(np.mean(self.sensitivity[s])), float(np.mean(self.normalized[s]))


def _steady_start(t, film):
    """First time the film stays within 1 % of its final value."""
    far = np.abs(film - film[-1]) > 0.01 * abs(film[-1])
    idx = np.flatnonzero(far)
    k = int(idx[-1] + 1) if idx.size else 0
    return float(t[min(k, t.size - 1)])


def friction_sensitivity(model: ClutchModel, scenario: ThesisScenario | None = None,
                         rel_step: float = 0.01) -> FrictionSensitivity:
    sc = scenario or ThesisScenario()
    t, f, w, s = sc.inputs(model)
    nom = simulate(model, t, f, w, s)
    a = model.friction_coefficients
    rows = [model.with_friction(a=scale_friction(a, 1 + rel_step)).vector(),
            model.with_friction(a=scale_friction(a, 1 - rel_step)).vector()]
    b = simulate_batch(np.array(rows), t, f, w, s).torque_nm
    mu = nom.friction_coefficient
    with np.errstate(divide="ignore", invalid="ignore"):
        sens = np.where(mu > 0, (b[0] - b[1]) / (2.0 * rel_step * mu), 0.0)
        norm = np.where(np.abs(nom.torque_nm) > 1e-9, sens * mu / nom.torque_nm, 0.0)
    return FrictionSensitivity(t=t, torque_nominal=nom.torque_nm, torque_plus=b[0], torque_minus=b[1], mu_f=mu,
                               sensitivity=sens, normalized=norm, rel_step=rel_step,
                               steady_from_s=_steady_start(t, nom.film_thickness_m), scenario=sc)


# --- every parameter ----------------------------------------------------------------------------------
@dataclass
class ParameterSensitivity:
    name: str
    index: int
    value: float
    s_coarse: float          # normalised sensitivity, step steps[0]
    s_fine: float            # step steps[1]
    agree: bool

    @property
    def s(self) -> float:
        return self.s_fine


def parameter_sensitivities(model: ClutchModel, scenario: ThesisScenario | None = None,
                            steps=(1e-2, 1e-3), rel_tol: float = 0.05, abs_tol: float = 1e-6):
    """Normalised steady-state sensitivities of the clutch torque to every parameter, ranked by
    magnitude. Returns (list[ParameterSensitivity], steady_from_s, mean nominal torque)."""
    sc = scenario or ThesisScenario()
    t, f, w, s = sc.inputs(model)
    nom = simulate(model, t, f, w, s)
    steady = t >= _steady_start(t, nom.film_thickness_m)
    base = model.vector()
    idx = [k for k in PARAMETER_NAMES if base[k] != 0.0]
    rows = []
    for k in idx:
        for h in steps:
            for sign in (1.0, -1.0):
                p = base.copy()
                p[k] *= 1.0 + sign * h
                rows.append(p)
    T = simulate_batch(np.array(rows), t, f, w, s).torque_nm
    t0 = nom.torque_nm[steady]
    out = []
    j = 0
    for k in idx:
        vals = []
        for h in steps:
            d = (T[j, steady] - T[j + 1, steady]) / (2.0 * h)
            with np.errstate(divide="ignore", invalid="ignore"):
                vals.append(float(np.mean(np.where(np.abs(t0) > 1e-9, d / t0, 0.0))))
            j += 2
        agree = abs(vals[0] - vals[1]) <= rel_tol * max(abs(vals[0]), abs(vals[1])) + abs_tol
        out.append(ParameterSensitivity(PARAMETER_NAMES[k], int(k), float(base[k]), vals[0], vals[1], bool(agree)))
    out.sort(key=lambda r: -abs(r.s))
    return out, float(t[steady][0]), float(np.mean(t0))


# --- identifiability on car data ------------------------------------------------------------------------
@dataclass
class ScreenResult:
    selected: list                    # coefficient indices the data can identify
    effect_nm: np.ndarray             # (20,) Morris mu*: RMS torque change per full +-spread move
    effect_sigma_nm: np.ndarray       # (20,) spread of the elementary effects
    morris_rmse_mu_star: np.ndarray   # (20,) SALib mu* of the RMSE (scalar output)
    local_msqr: np.ndarray            # (20,) RMS of dT/da_k * a_k (N*m per 100 %)
    collinearity: float               # index of the selected set
    steps: list = field(default_factory=list)   # [(k, gamma after adding, accepted)]
    threshold_nm: float = 0.0
    candidates: list = field(default_factory=list)
    n_simulations: int = 0

    def table(self) -> list:
        rows = []
        for k in range(20):
            rows.append({"coefficient": f"a{k}", "block": box.BLOCK_OF[k], "monomial": box.MONOMIAL[k % 5],
                         "morris_effect_nm": float(self.effect_nm[k]), "morris_sigma_nm": float(self.effect_sigma_nm[k]),
                         "morris_rmse_mu_star_nm": float(self.morris_rmse_mu_star[k]),
                         "local_rms_nm_per_100pct": float(self.local_msqr[k]),
                         "candidate": k in self.candidates, "identifiable": k in self.selected})
        return rows


def collinearity_index(S: np.ndarray) -> float:
    """Brun's collinearity index of sensitivity columns S (n, k): 1/sqrt(min eig of the
    normalised S'S); 1 = orthogonal, large = one column is nearly a combination of others."""
    if S.shape[1] == 0:
        return 1.0
    nrm = np.linalg.norm(S, axis=0)
    nrm[nrm == 0] = 1.0
    Sn = S / nrm
    ev = np.linalg.eigvalsh(Sn.T @ Sn)
    return float(1.0 / math.sqrt(max(ev[0], 1e-300)))


def identifiability_screen(model: ClutchModel, campaign, spread: float = 0.1, trajectories: int = 8,
                           seed: int = 0, rel_threshold: float = 0.02, abs_threshold_nm: float = 0.5,
                           gamma_max: float = 15.0, candidates=None, local_step: float = 1e-3,
                           inputs: CampaignInputs | None = None) -> ScreenResult:
    """Which friction coefficients can the campaign's measured torque identify? (module doc)"""
    from SALib.analyze import morris as morris_analyze
    from SALib.sample import morris as morris_sample

    inputs = inputs or CampaignInputs.from_campaign(as_campaign(campaign), model)
    a0 = model.friction_coefficients
    cand = list(range(20)) if candidates is None else sorted(int(k) for k in candidates)
    lo = np.minimum(a0 * (1 - spread), a0 * (1 + spread))
    hi = np.maximum(a0 * (1 - spread), a0 * (1 + spread))
    same = hi <= lo
    hi[same] = lo[same] + 1e-12
    problem = {"num_vars": len(cand), "names": [f"a{k}" for k in cand],
               "bounds": [[float(lo[k]), float(hi[k])] for k in cand]}
    X = morris_sample.sample(problem, trajectories, num_levels=4, seed=seed)
    A_m = np.repeat(a0[None, :], X.shape[0], axis=0)
    A_m[:, cand] = X
    # local central differences for the collinearity filter
    A_l = []
    for k in range(20):
        for sgn in (1.0, -1.0):
            a = a0.copy()
            a[k] *= 1.0 + sgn * local_step
            A_l.append(a)
    base = model.vector()
    m = inputs.mask
    y = inputs.torque_measured[m]
    # Morris elementary effects on the whole trace, one trajectory (D + 1 parameter sets) at a
    # time: memory bounded by a trajectory, not the screen (an hour of car data: ~3 GB at once);
    # the batch kernel computes each set independently, so the numbers are the same
    D = len(cand)
    ee = [[] for _ in range(D)]
    rmse = np.empty(X.shape[0])
    for tr in range(trajectories):
        r0 = tr * (D + 1)
        Tm = predict(param_rows(base, A_m[r0:r0 + D + 1]), inputs)[:, m]
        rmse[r0:r0 + D + 1] = np.sqrt(np.mean((Tm - y[None, :]) ** 2, axis=1))
        for j in range(D):
            dx = X[r0 + j + 1] - X[r0 + j]
            v = int(np.argmax(np.abs(dx)))
            width = problem["bounds"][v][1] - problem["bounds"][v][0]
            step = dx[v] / width
            if step == 0:
                continue
            ee[v].append(np.sqrt(np.mean((Tm[j + 1] - Tm[j]) ** 2)) / abs(step))
        del Tm
    effect = np.zeros(20)
    sig = np.zeros(20)
    for j, k in enumerate(cand):
        if ee[j]:
            effect[k] = float(np.mean(ee[j]))
            sig[k] = float(np.std(ee[j]))
    mu_star = np.zeros(20)
    try:
        Si = morris_analyze.analyze(problem, X, rmse, num_levels=4, print_to_console=False, seed=seed)
        mu_star[cand] = np.asarray(Si["mu_star"], float)
    except Exception:  # SALib analysis is a secondary report only
        pass
    S = np.empty((int(np.count_nonzero(m)), 20))                                 # dT/da * a
    for k in range(20):
        Tl = predict(param_rows(base, np.array(A_l[2 * k:2 * k + 2])), inputs)[:, m]
        S[:, k] = (Tl[0] - Tl[1]) / (2 * local_step)
    msqr = np.sqrt(np.mean(S ** 2, axis=0))
    thr = max(abs_threshold_nm, rel_threshold * float(effect.max()))
    strong = [k for k in cand if effect[k] >= thr]
    # hierarchical order (response-surface convention): constant terms before linear before
    # quadratic ones, then by sensitivity; a higher-order term enters only if not collinear
    strong.sort(key=lambda k: (_DEGREE[k % 5], -msqr[k]))
    selected, steps = [], []
    for k in strong:
        g = collinearity_index(S[:, selected + [k]])
        ok = g <= gamma_max
        steps.append((int(k), float(g), bool(ok)))
        if ok:
            selected.append(k)
    return ScreenResult(selected=sorted(int(k) for k in selected), effect_nm=effect, effect_sigma_nm=sig,
                        morris_rmse_mu_star=mu_star, local_msqr=msqr,
                        collinearity=collinearity_index(S[:, selected]) if selected else 1.0, steps=steps,
                        threshold_nm=thr, candidates=[int(k) for k in strong],
                        n_simulations=int(X.shape[0] + 40))


def identifiable_coefficients(model: ClutchModel, campaign, **kw) -> list:
    """Indices (0..19) of the friction coefficients the campaign can identify (see
    ``identifiability_screen`` for the options)."""
    return identifiability_screen(model, campaign, **kw).selected
