"""Viscosity (eq. 3.17) and heat-transfer (eq. 5.11-5.14) identification — thesis §5.2.2.

Viscosity: mu = alpha0 * theta^-alpha1 is linear in log space (log mu = log alpha0 -
alpha1 log theta); that LS solution starts a nonlinear LS refinement on the viscosity itself
(scipy least_squares), whose Jacobian gives the standard errors.

Heat transfer: from runs with a measured pack temperature, eq. 5.11 turns every sample into
an H_tf value,
    H_tf = C / (A_N (theta_pack - theta_sump)) * (|w T| / (N_sp C) - d theta_pack / dt),
with C = rho V c_p (``thermal.plate_heat_capacity``), T the measured torque and d theta/dt
from the Savitzky-Golay-smoothed pack temperature on a uniform time grid (every term of
the balance gets the same smoothing, so the filter does not bias it). Samples with |theta_pack -
theta_sump| below a threshold (H_tf is a ratio with that difference in the denominator) and
the filter's edge windows are dropped. b1..b4 of H_tf = b1 + b2 |w| + b3 F + b4 |w| F
(F in kN, as in the kernel) then follow by linear LS (eq. 5.13-5.14). Default
``weighting="power"`` weights each sample by (A_N dtheta)^2, i.e. fits the heat balance in
watts instead of the ratio: eq. 5.11's H_tf has the temperature difference in its denominator,
so its noise grows as 1/dtheta and the unweighted LS (``weighting="thesis"``) is dominated by
the samples that carry the least information. Standard errors: Newey-West (the smoothed
samples are correlated over one filter window; plain s^2 (X'X)^-1 would be several times too
small).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from clutch_model.errors import DataError, FitError
from clutch_model.formats.results import finite_or_none
from clutch_model.plant.params import ClutchModel

B_NAMES = ("b1", "b2", "b3", "b4")
B_UNITS = ("W/m^2/K", "W/m^2/K per rad/s", "W/m^2/K per kN", "W/m^2/K per rad/s/kN")


# --- viscosity -----------------------------------------------------------------------------------
@dataclass
class ViscosityFit:
    alpha0: float
    alpha1: float
    stderr: tuple           # (alpha0, alpha1)
    rmse: float             # Pa s
    rmse_log: float
    n: int

    def summary_lines(self) -> list:
        return [f"viscosity (eq. 3.17): alpha0 = {self.alpha0:.5g} +- {self.stderr[0]:.2g}, "
                f"alpha1 = {self.alpha1:.5g} +- {self.stderr[1]:.2g}; RMSE {self.rmse:.3g} Pa s "
                f"({self.n} samples)"]

    def to_json(self) -> dict:
        return {"alpha0": self.alpha0, "alpha1": self.alpha1, "stderr": {"alpha0": self.stderr[0],
                "alpha1": self.stderr[1]}, "rmse_pa_s": self.rmse, "rmse_log": self.rmse_log, "n": self.n}


def read_viscosity_csv(path):
    """CSV with header ``pack_temperature_c,viscosity_pa_s`` -> (theta, mu)."""
    import csv

    try:
        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
    except UnicodeDecodeError:
        raise DataError(f"{path}: not a text CSV file") from None
    if not rows:
        raise DataError(f"{path}: empty file")
    header = [h.strip() for h in rows[0]]
    need = ("pack_temperature_c", "viscosity_pa_s")
    if any(h not in header for h in need):
        raise DataError(f"{path}: header must contain {','.join(need)} (got {','.join(header)})")
    jt, jm = header.index(need[0]), header.index(need[1])
    th, mu = [], []
    for ln, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        try:
            th.append(float(row[jt]))
            mu.append(float(row[jm]))
        except (ValueError, IndexError):
            raise DataError(f"{path}: line {ln}: not two numbers") from None
    return np.asarray(th), np.asarray(mu)


def fit_viscosity(theta_c, viscosity_pa_s) -> ViscosityFit:
    from scipy.optimize import least_squares

    th = np.asarray(theta_c, float)
    mu = np.asarray(viscosity_pa_s, float)
    ok = np.isfinite(th) & np.isfinite(mu)
    th, mu = th[ok], mu[ok]
    if th.size < 3:
        raise FitError(f"viscosity: {th.size} usable samples; need at least 3")
    if np.any(th < 1.0) or np.any(mu <= 0):
        raise FitError("viscosity: eq. 3.17 needs pack temperatures >= 1 C and positive viscosities")
    if np.ptp(np.log(th)) < 1e-6:
        raise FitError("viscosity: all samples at one temperature; alpha1 cannot be identified")
    X = np.stack([np.ones_like(th), -np.log(th)], axis=1)
    (la0, a1), *_ = np.linalg.lstsq(X, np.log(mu), rcond=None)
    x0 = np.array([la0, a1])

    def resid(x):
        return np.exp(x[0]) * th ** (-x[1]) - mu

    def jac(x):
        m = np.exp(x[0]) * th ** (-x[1])
        return np.stack([m, -m * np.log(th)], axis=1)

    res = least_squares(resid, x0, jac=jac, method="lm", xtol=1e-14, ftol=1e-14)
    x = res.x
    r = resid(x)
    dof = max(th.size - 2, 1)
    s2 = float(r @ r) / dof
    J = jac(x)
    try:
        cov = s2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        cov = np.full((2, 2), np.inf)
    a0 = float(np.exp(x[0]))
    se = (float(a0 * math.sqrt(max(cov[0, 0], 0))), float(math.sqrt(max(cov[1, 1], 0))))
    rl = np.log(a0 * th ** (-x[1])) - np.log(mu)
    return ViscosityFit(alpha0=a0, alpha1=float(x[1]), stderr=se, rmse=float(np.sqrt(np.mean(r ** 2))),
                        rmse_log=float(np.sqrt(np.mean(rl ** 2))), n=int(th.size))


# --- heat transfer -----------------------------------------------------------------------------------
@dataclass
class HeatTransferFit:
    b: np.ndarray                 # (4,)
    stderr: np.ndarray            # (4,)
    t_stat: np.ndarray            # |b| / se
    correlation: np.ndarray       # (4, 4)
    rmse_htf: float               # of the H_tf regression, W/m^2/K
    n_used: int
    n_total: int
    weighting: str
    min_delta_c: float
    notes: list = field(default_factory=list)
    rmse_pack_before: float = math.nan   # simulated vs measured pack temperature, C
    rmse_pack_after: float = math.nan

    @property
    def identifiable(self) -> np.ndarray:
        return self.t_stat >= 2.0

    def summary_lines(self) -> list:
        lines = [f"heat transfer (eq. 5.11-5.14, {self.weighting} weighting): {self.n_used} of {self.n_total} "
                 f"samples used (|theta_pack - theta_sump| >= {self.min_delta_c:g} C), "
                 f"H_tf RMSE {self.rmse_htf:.4g} W/m^2/K"]
        for k in range(4):
            flag = "" if self.identifiable[k] else "  <- barely identifiable (|b|/se < 2)"
            lines.append(f"  {B_NAMES[k]} = {self.b[k]: .5g} +- {self.stderr[k]:.2g} {B_UNITS[k]} "
                         f"(|b|/se {self.t_stat[k]:.3g}){flag}")
        if np.isfinite(self.rmse_pack_after):
            lines.append(f"pack temperature RMSE (simulated vs measured): {self.rmse_pack_before:.3f} C with "
                         f"the base model -> {self.rmse_pack_after:.3f} C with the fit")
        lines += [f"note: {n}" for n in self.notes]
        return lines

    def to_json(self) -> dict:
        return {"b": [float(x) for x in self.b], "stderr": [float(x) for x in self.stderr],
                "t_stat": [float(x) for x in self.t_stat], "identifiable": [bool(x) for x in self.identifiable],
                "correlation": np.round(self.correlation, 4).tolist(), "rmse_htf": self.rmse_htf,
                "n_used": self.n_used, "n_total": self.n_total, "weighting": self.weighting,
                "min_delta_c": self.min_delta_c, "rmse_pack_before_c": _num(self.rmse_pack_before),
                "rmse_pack_after_c": _num(self.rmse_pack_after), "notes": self.notes}


_num = finite_or_none


def _uniform(t, *ys):
    """Resample onto a uniform grid at the median step (zero-order hold for the inputs is
    close enough at car-test rates; linear interpolation here)."""
    dt = float(np.median(np.diff(t)))
    if dt <= 0:
        raise DataError("run time stamps are not increasing")
    if np.allclose(np.diff(t), dt, rtol=1e-3, atol=1e-9):
        return t, dt, ys
    tu = np.arange(t[0], t[-1] + 0.5 * dt, dt)
    return tu, dt, tuple(np.interp(tu, t, y) for y in ys)


def heat_transfer_samples(runs, model: ClutchModel, window_s: float = 1.0, polyorder: int = 2,
                          min_delta_c: float = 3.0):
    """Eq. 5.11 on consistently filtered signals, per sample, from runs with measured torque
    and pack temperature.

    The heat balance C dtheta/dt = q - A_N dtheta_ps H_tf (q = |w T| / N_sp) is linear in
    b, so one linear filter S (Savitzky-Golay, ``window_s``) applied to every term keeps it
    exact: S(q) - C d/dt S(theta) = A_N S(dtheta_ps X) b with X = (1, |w|, F_kN, |w| F_kN)
    (S = Savitzky-Golay smoothing, d/dt = central differences of the smoothed signal).
    Filtering only the derivative (and not q) would bias H_tf badly at every torque step,
    since the heating term is 10-100x the cooling term while the clutch slips.
    Returns dict of arrays: y [W] (left side), z [W/(W/m^2/K)] (regressors A_N S(dtheta X)),
    d = S(dtheta_ps) [C], htf = y / (A_N d) (eq. 5.11), used mask, x (raw regressors)."""
    from scipy.signal import savgol_filter

    C = float(model.data["thermal"]["plate_heat_capacity"])
    n_sp = float(model.data["geometry"]["separator_plates"])
    an = model.nominal_area_m2
    fmax = model.max_pack_force_n
    pre = model.mechanism("spring_preload")
    preload = pre.values["preload_n"] if pre is not None else 0.0
    cols = {k: [] for k in ("y", "z", "d", "x", "edge")}
    window = 1
    usable = 0
    for r in runs:
        if r.pack_temperature_measured_c is None or r.torque_measured_nm is None:
            continue
        usable += 1
        if len(r) < 5:
            continue
        t, dt, (f, w, sump, tq, pack) = _uniform(np.asarray(r.t, float), r.applied_force_n, r.slip_speed_rad_s,
                                                r.sump_temperature_c, r.torque_measured_nm,
                                                r.pack_temperature_measured_c)
        win = max(int(round(window_s / dt)) | 1, (polyorder + 2) | 1)
        if win > t.size:
            continue
        window = max(window, win)
        sg = lambda v, deriv=0: savgol_filter(v, win, polyorder, deriv=deriv, delta=dt, mode="interp")  # noqa: E731
        fkn = np.clip(np.clip(f, 0.0, None) - preload, 0.0, fmax) * 1e-3
        wa = np.abs(w)
        q = np.abs(w * tq) / n_sp
        delta = pack - sump
        X = np.stack([np.ones_like(t), wa, fkn, wa * fkn], axis=1)
        # d/dt S(theta) by central differences: every operator here is linear and shift-
        # invariant (away from the dropped edges), so it commutes with the heat balance.
        # (S-G's own derivative kernel is not the derivative of its smoothing kernel.)
        y = sg(q) - C * np.gradient(sg(pack), dt)
        z = an * np.stack([sg(delta * X[:, k]) for k in range(4)], axis=1)
        edge = np.zeros(t.size, bool)
        edge[:win // 2 + 1] = True
        edge[-(win // 2 + 1):] = True
        for k, v in (("y", y), ("z", z), ("d", sg(delta)), ("x", X), ("edge", edge)):
            cols[k].append(v)
    if usable == 0:
        raise FitError("no run has both /clutch/pack_temperature and /clutch/measured_torque; the heat "
                       "transfer fit needs them")
    if not cols["y"]:
        raise FitError("the runs with a pack temperature are too short for the derivative filter")
    out = {k: np.concatenate(v) for k, v in cols.items()}
    out["window"] = window
    with np.errstate(divide="ignore", invalid="ignore"):
        out["htf"] = out["y"] / (an * out["d"])
    out["used"] = (~out["edge"]) & np.isfinite(out["htf"]) & (np.abs(out["d"]) >= min_delta_c)
    return out


def fit_heat_transfer(runs, model: ClutchModel, min_delta_c: float = 3.0, window_s: float = 1.0,
                      polyorder: int = 2, weighting: str = "power", evaluate: bool = True) -> HeatTransferFit:
    """b1..b4 by linear LS on eq. 5.11's H_tf (see module doc and heat_transfer_samples)."""
    if weighting not in ("thesis", "power"):
        raise ValueError("weighting is 'thesis' or 'power'")
    s = heat_transfer_samples(runs, model, window_s, polyorder, min_delta_c)
    u = s["used"]
    n = int(u.sum())
    if n < 8:
        raise FitError(f"heat transfer: only {n} samples with |theta_pack - theta_sump| >= {min_delta_c:g} C; "
                       "need at least 8 (lower --min-delta)")
    an = model.nominal_area_m2
    if weighting == "thesis":      # H_tf samples (eq. 5.11) on the effective regressors
        X = s["z"][u] / (an * s["d"][u])[:, None]
        y = s["htf"][u]
    else:                          # the heat balance in watts
        X = s["z"][u]
        y = s["y"][u]
    b, _, rank, _ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ b
    XtX = X.T @ X
    notes = []
    try:
        bread = np.linalg.inv(XtX)
    except np.linalg.LinAlgError:
        bread = np.linalg.pinv(XtX)
        notes.append("the regressors are collinear (X'X singular); standard errors from the pseudo-inverse")
    # smoothed samples are correlated over a filter window: Newey-West (HAC) covariance
    lag = int(s["window"])
    cov = bread @ _newey_west(X * r[:, None], lag, n_params=4) @ bread
    if rank < 4:
        notes.append(f"the data span only {rank} of the 4 regressor directions (1, |w|, F, |w|F)")
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    d = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    corr = cov / np.outer(d, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        tstat = np.where(se > 0, np.abs(b) / se, np.inf)
    weak = [B_NAMES[k] for k in range(4) if tstat[k] < 2.0]
    f = s["x"][u][:, 2]
    if weak:
        notes.append(f"{', '.join(weak)} barely identifiable (|b|/se < 2): with F in kN the force terms are "
                     f"small against b1 over the data's force range ({f.min():.3g}..{f.max():.3g} kN), and "
                     "their columns are strongly correlated with the others (see correlation)")
    htf_hat = s["x"][u] @ b
    fit = HeatTransferFit(b=b, stderr=se, t_stat=tstat, correlation=corr,
                          rmse_htf=float(np.sqrt(np.mean((htf_hat - s["htf"][u]) ** 2))), n_used=n,
                          n_total=int(u.size), weighting=weighting, min_delta_c=float(min_delta_c), notes=notes)
    if evaluate:
        fit.rmse_pack_before = pack_temperature_rmse(model, runs)
        fit.rmse_pack_after = pack_temperature_rmse(with_thermal(model, b=b), runs)
    return fit


def _newey_west(g, lag, n_params):
    """Newey-West long-run covariance of the score rows g (n, k), Bartlett weights."""
    n = g.shape[0]
    S = g.T @ g
    for ell in range(1, min(lag, n - 1) + 1):
        w = 1.0 - ell / (lag + 1.0)
        G = g[ell:].T @ g[:-ell]
        S += w * (G + G.T)
    return S * n / max(n - n_params, 1)


def with_thermal(model: ClutchModel, b=None, alpha0=None, alpha1=None) -> ClutchModel:
    new = model.copy()
    if b is not None:
        new.data["thermal"]["b"] = [float(x) for x in b]
    if alpha0 is not None:
        new.data["viscosity"]["alpha0"] = float(alpha0)
    if alpha1 is not None:
        new.data["viscosity"]["alpha1"] = float(alpha1)
    return new


def pack_temperature_rmse(model: ClutchModel, runs) -> float:
    """Replay the runs and compare the simulated pack temperature with the measured one."""
    from clutch_model.replay import replay_runs

    runs = [r for r in runs if r.pack_temperature_measured_c is not None]
    if not runs:
        return math.nan
    return replay_runs(model, runs).rmse_pack_temperature()
