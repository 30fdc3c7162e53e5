"""Sensor clocks and sensor noise of the car-log virtual test car (see docs/virtual_car.md).

Each topic has a ``TopicClock`` (its own rate, phase, jitter and time-stamp quantisation) and
each sensor a ``Noise`` object (white, AR(1), band-limited, held, median-filtered, drifting),
in the manner of PySINDy's candidate terms: one small object per class, ``sample(rng, t_s)``
returns the additive noise at the topic's sample times.

Timing model: a sample is taken at an irregular instant ``t_true`` (nominal k/rate plus the
topic's phase plus jitter); its log time is ``t_true`` rounded to the stamp quantum. The
value is the physical signal at ``t_true`` plus the sensor noise. So jitter is real
irregular sampling (no mean delay), and quantisation is a stamp error of at most half a
quantum. A topic stamped on arrival (``arrival_jitter_s``) has its log times scattered around
``t_true`` on top: a gateway stamping the frames as they come, the values still the signal at
the instants they were sampled.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal as sps

from clutch_model.errors import ParamsError


# ----------------------------------------------------------------------------- clocks
@dataclass
class TopicClock:
    """When a topic's samples are taken and how they are stamped.

    rate_hz: nominal rate (10-1000 Hz). phase_s: offset of the first nominal sample from the
    run start (negative: starts before; samples before 0 are dropped). jitter_s: half-width
    of the uniform sampling jitter (±jitter_s around the nominal instant; clipped to keep
    the order). quantum_s: log-time resolution (stamps rounded to it; 0 = ns).
    arrival_jitter_s: half-width of the uniform scatter of the stamps around the sampling
    instants (a gateway stamping the frames as they arrive, the value still the signal at the
    instant it was sampled; 0 = stamped when sampled). burst_s: a gateway forwards the frames
    in bursts, flushing every ``burst_s`` on average (2/3 to 4/3 of it, uniform): each frame
    is stamped at the first flush after it was sampled, the frames of one flush 1 µs apart
    (0 = no bursts).
    """

    rate_hz: float
    phase_s: float = 0.0
    jitter_s: float = 0.0
    quantum_s: float = 0.0
    arrival_jitter_s: float = 0.0
    burst_s: float = 0.0

    def __post_init__(self):
        if not (0 < self.rate_hz <= 10000):
            raise ParamsError(f"topic clock: rate {self.rate_hz} Hz out of (0, 10000]")
        if self.jitter_s < 0 or self.quantum_s < 0 or self.arrival_jitter_s < 0 or self.burst_s < 0:
            raise ParamsError("topic clock: jitter and quantum must be >= 0")
        if self.jitter_s + self.arrival_jitter_s >= 0.5 / self.rate_hz:
            raise ParamsError(f"topic clock: jitter ±{self.jitter_s + self.arrival_jitter_s} s must be below half "
                              f"the sample period {0.5 / self.rate_hz} s")

    def sample_times(self, rng, duration_s: float):
        """(t_true, t_stamp) in s from the run start, strictly increasing stamps in [0, duration)."""
        period = 1.0 / self.rate_hz
        k0 = math.ceil((0.0 - self.phase_s) / period - 1e-9)
        n = int(math.floor((duration_s - self.phase_s) / period - 1e-9)) - k0 + 1
        nominal = self.phase_s + (k0 + np.arange(max(n, 0))) * period
        jit = rng.uniform(-self.jitter_s, self.jitter_s, nominal.size) if self.jitter_s > 0 else 0.0
        t_true = np.clip(nominal + jit, 0.0, duration_s - 1e-9)
        arrival = (rng.uniform(-self.arrival_jitter_s, self.arrival_jitter_s, t_true.size)
                   if self.arrival_jitter_s > 0 else 0.0)
        q = self.quantum_s if self.quantum_s > 0 else 1e-9
        t_stamp = np.round(np.clip(t_true + arrival, 0.0, duration_s - 1e-9) / q) * q
        if self.burst_s > 0 and t_stamp.size:
            t_stamp = self._forwarded_in_bursts(rng, t_stamp, duration_s, q)
        keep = np.concatenate([[True], np.diff(t_stamp) > 0.5e-9]) if t_stamp.size else np.zeros(0, bool)
        return t_true[keep], t_stamp[keep]

    def _forwarded_in_bursts(self, rng, t_stamp, duration_s: float, q: float) -> np.ndarray:
        """Stamps at the gateway's flushes (``burst_s``): the first flush at or after each
        sample, its frames 1 µs apart; frames after the last flush go with the run's end."""
        n = int(np.ceil(duration_s / (self.burst_s * 2.0 / 3.0))) + 1
        flushes = np.round(np.cumsum(rng.uniform(2.0 / 3.0, 4.0 / 3.0, n) * self.burst_s) / q) * q
        j = np.searchsorted(flushes, t_stamp)
        at = np.where(j < flushes.size, flushes[np.minimum(j, flushes.size - 1)], t_stamp[-1])
        first = np.r_[True, at[1:] != at[:-1]]
        idx = np.arange(at.size)
        pos = idx - np.maximum.accumulate(np.where(first, idx, 0))
        return np.minimum(at + pos * 1e-6, duration_s - 1e-9)

    def to_dict(self) -> dict:
        out = {"rate_hz": self.rate_hz, "phase_s": self.phase_s, "jitter_s": self.jitter_s,
               "quantum_s": self.quantum_s}
        if self.arrival_jitter_s > 0:
            out["arrival_jitter_s"] = self.arrival_jitter_s
        if self.burst_s > 0:
            out["burst_s"] = self.burst_s
        return out


# ------------------------------------------------------------------------------ noise
@dataclass
class Noise:
    """Base: zero noise. ``sigma`` is the stationary standard deviation of the noise."""

    sigma: float = 0.0
    kind = "none"

    def sample(self, rng, t_s: np.ndarray) -> np.ndarray:
        return np.zeros(np.asarray(t_s).size)

    def to_dict(self) -> dict:
        d = {"kind": self.kind}
        d.update({k: float(v) for k, v in self.__dict__.items()})
        return d


@dataclass
class WhiteNoise(Noise):
    kind = "white"

    def sample(self, rng, t_s):
        return rng.normal(0.0, self.sigma, np.asarray(t_s).size)


@dataclass
class AR1Noise(Noise):
    """Coloured noise: x_k = φ x_{k-1} + e_k per sample (stationary std ``sigma``)."""

    phi: float = 0.9
    kind = "ar1"

    def __post_init__(self):
        if not (-1 < self.phi < 1):
            raise ParamsError("AR(1) noise: phi must be in (-1, 1)")

    def sample(self, rng, t_s):
        n = np.asarray(t_s).size
        e = rng.normal(0.0, self.sigma * math.sqrt(1 - self.phi ** 2), n)
        if n == 0:
            return e
        x0 = rng.normal(0.0, self.sigma)
        x, _ = sps.lfilter([1.0], [1.0, -self.phi], e, zi=[self.phi * x0])
        return x


@dataclass
class LowpassNoise(Noise):
    """Band-limited noise: white noise through the sensor's 2nd-order Butterworth low-pass
    (cut-off ``cutoff_hz`` at the topic's mean rate), scaled to std ``sigma``."""

    cutoff_hz: float = 10.0
    kind = "lowpass"

    def sample(self, rng, t_s):
        t_s = np.asarray(t_s, float)
        n = t_s.size
        if n < 3:
            return rng.normal(0.0, self.sigma, n)
        fs = (n - 1) / (t_s[-1] - t_s[0])
        wn = min(self.cutoff_hz / (0.5 * fs), 0.99)
        b, a = sps.butter(2, wn)
        burn = int(5 * fs / self.cutoff_hz) + 10
        e = rng.normal(0.0, 1.0, n + burn)
        y = sps.lfilter(b, a, e)[burn:]
        # stationary std of the filter output for unit white input (impulse response energy)
        imp = sps.lfilter(b, a, np.r_[1.0, np.zeros(max(20 * burn, 2000))])
        return y * self.sigma / math.sqrt(float(np.sum(imp ** 2)))


@dataclass
class HeldNoise(Noise):
    """A slow sensor re-sent at the topic's rate: the noise is drawn at ``update_hz`` and
    held until the next update (sample-and-hold), e.g. 10 Hz held on a 200 Hz topic."""

    update_hz: float = 10.0
    kind = "held"

    def sample(self, rng, t_s):
        t_s = np.asarray(t_s, float)
        if t_s.size == 0:
            return np.zeros(0)
        slot = np.floor((t_s - t_s[0]) * self.update_hz + 1e-9).astype(np.int64)
        draws = rng.normal(0.0, self.sigma, int(slot[-1]) + 1)
        return draws[slot]


@dataclass
class MedianNoise(Noise):
    """Median-filtered noise (a logger's spike filter): white noise through a running median
    of ``window`` samples, scaled to std ``sigma``."""

    window: int = 5
    kind = "median"

    def sample(self, rng, t_s):
        n = np.asarray(t_s).size
        w = int(self.window) | 1
        e = rng.normal(0.0, 1.0, n + w)
        y = sps.medfilt(e, w)[w // 2: w // 2 + n]
        # std of the median of w unit normals (large-sample ~ sqrt(pi/(2w)), exact by table)
        return y * self.sigma / _median_std(w)


@dataclass
class DriftNoise(Noise):
    """White noise (std ``sigma``) plus a slow Ornstein-Uhlenbeck drift (std ``drift``,
    time constant ``tau_s``), e.g. a strain-gauge bridge warming up."""

    drift: float = 0.0
    tau_s: float = 20.0
    kind = "drift"

    def sample(self, rng, t_s):
        t_s = np.asarray(t_s, float)
        n = t_s.size
        white = rng.normal(0.0, self.sigma, n)
        if n == 0 or self.drift <= 0:
            return white
        dt = np.diff(t_s, prepend=t_s[0])
        a = np.exp(-dt / self.tau_s)
        e = rng.normal(0.0, 1.0, n) * self.drift * np.sqrt(1 - a * a)
        x = np.empty(n)
        x[0] = rng.normal(0.0, self.drift)
        for k in range(1, n):
            x[k] = a[k] * x[k - 1] + e[k]
        return white + x


def _median_std(w: int) -> float:
    g = np.random.default_rng(12345)
    return float(np.std(np.median(g.normal(size=(40000, w)), axis=1)))


NOISE_CLASSES = {c.kind: c for c in (WhiteNoise, AR1Noise, LowpassNoise, HeldNoise, MedianNoise,
                                     DriftNoise)}


def make_noise(kind: str, sigma: float, **options) -> Noise:
    """A noise object by class name (white, ar1, lowpass, held, median, drift)."""
    if kind not in NOISE_CLASSES:
        raise ParamsError(f"unknown noise class '{kind}' (known: {', '.join(NOISE_CLASSES)})")
    try:
        return NOISE_CLASSES[kind](float(sigma), **options)
    except TypeError as exc:
        raise ParamsError(f"noise {kind}: {exc}") from None


# --------------------------------------------------------------------- sampling helper
def sample_signal(t_fine: np.ndarray, y_fine: np.ndarray, t_true: np.ndarray) -> np.ndarray:
    """The fine-grid signal at the sample instants (linear interpolation)."""
    return np.interp(t_true, t_fine, y_fine)
