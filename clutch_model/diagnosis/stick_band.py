"""Rows where the slip sensor does not resolve the friction's Stribeck transition.

Near stick the friction falls from its static to its Coulomb level over a slip of a few
omega_S (0.03-0.05 rad/s on the reference clutch, with exponent i ~ 3 the fall is steep). A
clutch held there by a slip controller slips at a few hundredths of a rad/s, and a slip
sensor that logs in steps of 0.028 rad/s, or with noise of that size, reads 0.028 and 0.056
in turn where the true slip is 0.04: the model, given the slip as logged, jumps between its
static and its Coulomb torque from one row to the next, tens of N*m, while the measured
torque, made by the true slip, stays within its own noise. Those rows say nothing about the
clutch model: what they hold is the slip reading's error through the friction's slope.

They also decide the diagnosis. The held-out test whitens the residual with an AR noise
model whose innovations are the size of the torque sensor's noise (about 1 N*m), so a jump
of 35 N*m on one row weighs like 1000 rows of noise, and a candidate that smooths the
model's output -- a torque-sensor lag -- gains there whatever it means. Measured on an
outside generator's closed-loop drive (one 571 s bag, slip targets down to 0.5 rad/s, slip
logged in 0.028 rad/s steps, a hidden 63 ms actuator lag with friction degradation): 5 % of
the rows, all with the logged slip below 0.06 rad/s, held 100 % of the log-likelihood
difference between the two lags. The sensor lag beat the actuator lag head to head at
t = 28.7 and took the first step; without those rows the actuator lag beat it at t = 26.5.

The rule (``stick_band_rows``): on each slipping row, the slip reading's uncertainty s (the
slip sensor's noise sd as the lock-up detection estimates it, at least a quantum / sqrt 12)
moves the friction coefficient from mu(|w| - s) to mu(|w| + s); with the measured torque
as the torque's scale that is a torque uncertainty of |T| |mu(|w|+s) - mu(|w|-s)| / (2 mu(|w|)).
A row is kept out of the residuals where it exceeds STICK_BAND_NOISE_FACTOR times the torque
sensor's noise near Nyquist. The friction is the given model's (the diagnosis gives its bench
fit) at the row's pressure (force / A_N) and sump temperature, its Stribeck transition alone:
the band ends sharply a few omega_S above zero. The viscous slope k_V is left out: it carries
the slip noise into the torque at every slip, smoothly, and where that noise matters against
a quiet torque sensor the slip is smoothed instead (input_hold). With it, a campaign whose
torque sensor is quiet near Nyquist (0.12 N*m) and one of whose slip sensors is noisy
(0.06 rad/s) lost 5 % of its rows, up to 6.5 rad/s of slip. The static friction fit
(static_friction.py) still reads these rows: it is fitted on the torque before any row is left
out.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from clutch_model.plant.friction import stribeck

STICK_BAND_NOISE_FACTOR = 3.0   # the slip reading's torque uncertainty, in torque-noise sds, that leaves a row out


@dataclass
class StickBand:
    """What ``without_stick_band`` left out: rows, and the figures the rule used."""

    rows: int
    slip_resolution_rad_s: list      # s per run
    torque_noise_nm: float
    max_slip_rad_s: float            # the largest |slip| among the rows left out (0: none)

    def describe(self) -> str:
        s = ", ".join(f"{x:.3f}" for x in self.slip_resolution_rad_s[:4])
        return (f"stick band: {self.rows} slipping rows below {self.max_slip_rad_s:.3f} rad/s kept out of the "
                f"residuals: the slip reading (uncertainty {s} rad/s) moves the model's friction there by more than "
                f"{STICK_BAND_NOISE_FACTOR:g} x the torque's noise ({self.torque_noise_nm:.2f} N*m)")

    def to_dict(self) -> dict:
        return {"stick_band_rows": self.rows, "stick_band_slip_resolution_rad_s": self.slip_resolution_rad_s,
                "stick_band_max_slip_rad_s": self.max_slip_rad_s}


def stick_band_rows(slip_rad_s, force_n, sump_temperature_c, torque_nm, model, slip_resolution_rad_s: float,
                    torque_noise_nm: float, factor: float = STICK_BAND_NOISE_FACTOR) -> np.ndarray:
    """Rows (bool) whose torque uncertainty from the slip reading exceeds ``factor`` times
    ``torque_noise_nm`` (module docstring); False where any input is missing."""
    w = np.abs(np.asarray(slip_rad_s, float))
    tq = np.abs(np.asarray(torque_nm, float))
    s = float(slip_resolution_rad_s)
    out = np.zeros(w.size, bool)
    if not (s > 0 and np.isfinite(s) and torque_noise_nm > 0 and np.isfinite(torque_noise_nm)):
        return out
    ok = np.isfinite(w) & np.isfinite(tq) & np.isfinite(force_n) & np.isfinite(sump_temperature_c)
    if not ok.any():
        return out
    p = np.asarray(force_n, float)[ok] / model.nominal_area_m2 / 1e6
    th = np.asarray(sump_temperature_c, float)[ok]
    a, i = np.array(model.friction_coefficients, float), model.friction_exponent
    a[15:20] = 0.0       # the Stribeck transition alone: the k_V slope is smooth (docstring)
    mu = stribeck(a, i, w[ok], p, th)
    hi = stribeck(a, i, w[ok] + s, p, th)
    lo = stribeck(a, i, np.maximum(w[ok] - s, 0.0), p, th)
    with np.errstate(divide="ignore", invalid="ignore"):
        swing = tq[ok] * np.abs(hi - lo) / (2.0 * mu)
    out[ok] = np.isfinite(swing) & (mu > 0) & (swing > factor * torque_noise_nm)
    return out


def without_stick_band(campaign, model, lock_results: list, torque_noise_nm: float):
    """(campaign with the measured torque NaN on its stick-band rows, StickBand). Per run, the
    slip resolution is the lock-up detection's slip noise sd (``LockupResult``); rows already
    without a torque (locked) are left as they are."""
    from clutch_model.formats.bag_reader import Campaign

    runs, total, res_s, top = [], 0, [], 0.0
    for run, lock in zip(campaign.runs, lock_results):
        s = float(getattr(lock, "noise_sigma_rad_s", float("nan")))
        res_s.append(round(s, 5) if np.isfinite(s) else float("nan"))
        y = run.torque_measured_nm
        if y is None or not np.isfinite(s):
            runs.append(run)
            continue
        band = stick_band_rows(run.slip_speed_rad_s, run.applied_force_n, run.sump_temperature_c, y, model, s,
                               torque_noise_nm) & np.isfinite(y)
        if band.any():
            total += int(band.sum())
            top = max(top, float(np.max(np.abs(run.slip_speed_rad_s[band]))))
            run = replace(run, torque_measured_nm=np.where(band, np.nan, y))
        runs.append(run)
    return Campaign(runs), StickBand(total, res_s, float(torque_noise_nm), top)
