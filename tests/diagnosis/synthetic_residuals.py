"""Synthetic car-like inputs and sensor-noise classes for the statistical diagnosis tests.

Not the plant: cheap, seeded signals with the shapes a car campaign has (force ramps, holds,
sweeps and releases; slip levels that change; a pack temperature that follows the slip power;
dissipated energy; slip angle), and the noise classes a car's torque sensor shows."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.signal import butter, lfilter, medfilt

NOISE_CLASSES = ("white", "ar1_095", "bandlimited_10hz", "held_10hz", "median", "white_drift")


def make_inputs(seed: int, n_runs: int = 10, duration_s: float = 10.0, rate_hz: float = 200.0,
                jitter: bool = False):
    """Concatenated runs -> dict of arrays (t, run_start, force, slip, torque, power, energy,
    pack_temperature, angle). Torque = mu(slip) * force * 0.025 m (signed by slip)."""
    rng = np.random.default_rng(seed)
    out = {k: [] for k in ("t", "run_start", "force", "slip", "torque", "power", "energy",
                           "pack_temperature", "angle", "sump")}
    energy = 0.0
    for _ in range(n_runs):
        n = int(duration_s * rate_hz)
        dt = np.full(n, 1.0 / rate_hz)
        if jitter:
            dt *= rng.uniform(0.6, 1.4, n)
        t = np.concatenate([[0.0], np.cumsum(dt[:-1])])
        # force: a controller-like profile of ramps, holds, sweeps and releases
        force = np.zeros(n)
        k = 0
        while k < n:
            seg = int(rng.uniform(0.5, 2.0) * rate_hz)
            kind = rng.integers(4)
            lvl = rng.uniform(2e3, 2e4)
            x = np.linspace(0, 1, max(seg, 2))[:min(seg, n - k)]
            if kind == 0:
                f = lvl * x                                  # ramp
            elif kind == 1:
                f = np.full(x.size, lvl)                     # hold
            elif kind == 2:
                f = lvl * (0.6 + 0.4 * np.sin(2 * np.pi * (1 + 3 * x) * x))   # sweep
            else:
                f = lvl * (1 - x)                            # release
            force[k:k + f.size] = f
            k += f.size
        slip_lvl = rng.uniform(2.0, 15.0)
        slip = slip_lvl * (1 + 0.3 * np.sin(2 * np.pi * t / rng.uniform(3, 8) + rng.uniform(0, 6))) \
            * rng.choice([-1.0, 1.0])
        mu = 0.11 + 0.03 * np.exp(-np.abs(slip) / 5.0)
        torque = mu * force * 0.025 / 0.12 * np.sign(slip)
        power = np.abs(torque * slip)
        e = energy + np.cumsum(power * dt)
        energy = e[-1]
        sump = rng.uniform(40.0, 90.0)
        a = 1 - np.exp(-dt / 2.0)
        pack = lfilter([1.0], [1.0, -(1 - a[0])], a[0] * power / 200.0) + sump
        out["t"].append(t)
        rs = np.zeros(n, bool)
        rs[0] = True
        out["run_start"].append(rs)
        out["force"].append(force)
        out["slip"].append(slip)
        out["torque"].append(torque)
        out["power"].append(power)
        out["energy"].append(e)
        out["pack_temperature"].append(pack)
        out["angle"].append(np.cumsum(slip * dt))
        out["sump"].append(np.full(n, sump))
    return {k: np.concatenate(v) for k, v in out.items()}


def make_noise(kind: str, run_start: np.ndarray, sigma: float, seed: int, rate_hz: float = 200.0) -> np.ndarray:
    """One noise class per run (independent between runs), scaled to standard deviation sigma."""
    rng = np.random.default_rng(seed)
    starts = np.flatnonzero(run_start)
    ends = np.append(starts[1:], run_start.size)
    out = np.empty(run_start.size)
    for a, b in zip(starts, ends):
        n = b - a
        w = rng.normal(size=n + 4000)
        if kind == "white":
            x = w
        elif kind == "ar1_095":
            x = lfilter([1.0], [1.0, -0.95], w)
        elif kind == "bandlimited_10hz":
            bb, aa = butter(2, 10.0 / (rate_hz / 2))
            x = lfilter(bb, aa, w)
        elif kind == "held_10hz":
            hold = max(int(round(rate_hz / 10.0)), 1)
            x = np.repeat(w[::hold], hold)[:w.size]
        elif kind == "median":
            x = medfilt(w, 9)
        elif kind == "white_drift":
            drift = lfilter([1.0], [1.0, -(1 - 1.0 / (20 * rate_hz))], rng.normal(size=n + 4000))
            x = w / np.std(w) + 0.7 * drift / np.std(drift[4000:])
        else:
            raise KeyError(kind)
        x = x[4000:]
        out[a:b] = sigma * x / np.std(x)
    return out


def ou_drift_noise(run_start: np.ndarray, sigma: float, seed: int, rate_hz: float = 200.0,
                   tau_s: float = 36.0, drift_share: float = 0.6) -> np.ndarray:
    """White noise plus a slow Ornstein-Uhlenbeck drift (time constant tau_s, independent
    between runs; drift_share of the standard deviation sigma), each run started in the
    drift's stationary distribution."""
    rng = np.random.default_rng(seed)
    phi = np.exp(-1.0 / (tau_s * rate_hz))
    starts = np.flatnonzero(run_start)
    ends = np.append(starts[1:], run_start.size)
    out = np.empty(run_start.size)
    for a, b in zip(starts, ends):
        drift = lfilter([np.sqrt(1 - phi * phi)], [1.0, -phi], rng.normal(size=b - a),
                        zi=[phi * rng.normal()])[0]
        out[a:b] = sigma * (np.sqrt(1 - drift_share ** 2) * rng.normal(size=b - a) + drift_share * drift)
    return out


def split_spans(t: np.ndarray, run_start: np.ndarray, span_s: float = 7.0):
    """Time spans held out: every third span of span_s seconds of each run, from the second
    -> (train_mask, test_mask)."""
    run = np.cumsum(run_start) - 1
    test = np.zeros(t.size, bool)
    for r in np.unique(run):
        sel = run == r
        test[sel] = (np.floor(t[sel] / span_s).astype(int) % 3) == 1
    return ~test, test


def feature_signals(d: dict) -> dict:
    """The inputs a flexible residual model may use."""
    return {"force": d["force"], "slip": np.abs(d["slip"]), "pack_temperature": d["pack_temperature"],
            "power": d["power"], "energy": d["energy"], "sin_angle": np.sin(d["angle"]),
            "cos_angle": np.cos(d["angle"])}


def split_every_third(run_start: np.ndarray):
    """Whole runs held out: every third from the second -> (train_mask, test_mask)."""
    run = np.cumsum(run_start) - 1
    test = (run % 3) == 1
    return ~test, test


@dataclass
class Fixed:
    """A fitted model (selection.Fitted) that predicts a fixed series: a stand-in for a
    candidate fit in tests of the verdict's rules."""
    prediction: np.ndarray
    parameters: dict = field(default_factory=dict)
    parameters_ci95: dict = field(default_factory=dict)
    readings: list = field(default_factory=list)
    model: object = None

    def predict(self, data):
        return self.prediction


def run_grid(rate_hz: float, run_s: float, n_runs: int):
    """Runs of ``run_s`` at ``rate_hz`` end to end -> (t from each run's start, run index,
    run_start)."""
    n = int(rate_hz * run_s)
    t = np.tile(np.arange(n) / rate_hz, n_runs)
    run = np.repeat(np.arange(n_runs), n)
    return t, run, np.r_[True, run[1:] != run[:-1]]
