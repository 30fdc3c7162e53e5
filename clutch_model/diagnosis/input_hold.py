"""The inputs the diagnosis gives the plant: smoothed without phase, the force at each step's
midpoint.

Smoothed inputs (``with_smoothed_inputs``). The model is driven by the measured force and
slip, sensor noise included, and that noise reaches the predicted torque: a white slip noise
of 0.05 rad/s moves it at every sample through the Stribeck and viscous terms. Where the
torque sensor's own noise is band-limited (a 10 Hz filter, a held or median-filtered reading),
the whitened one-step errors weigh exactly the high frequencies where the model carries that
input noise, and a candidate that smooths the model's output gains there, whatever it means:
on actuator_lag@lowpass#1 (a 70 ms actuator lag) the torque-sensor lag won at held-out
t = 693 against 37 and was named. The diagnosis is about the plant, so it works on the
cleaner inputs, as it does with the sump temperature: force and slip smoothed by a Gaussian
kernel of 5 ms standard deviation (-3 dB at 25 Hz, zero phase: no delay added), after which
the actuator lag wins (t = 53 against 43) and is named. The slip as logged stays in the run's
samples (``slip_speed_logged``) for the lock-up detection, which estimates the slip sensor's
noise from it. Replay is not changed.

The force at each step's midpoint (``with_midpoint_force``).

The plant integrates from row k to row k+1 with row k's inputs held (replay timing). Held at
its value at t_k, a force that varies continuously between its samples reaches the film on
average half a row interval late: 2.5 ms on a 200 Hz grid, 10 ms on 50 Hz torque stamps. The
diagnosis reads such a misfit as a transport delay or as structure the inputs predict, on data
with no effect at all. Given the force at the step's midpoint (t_k + t_{k+1}) / 2, linearly
interpolated between its own logged samples, the held value is the midpoint rule's: the film
sees the force of its step, second-order accurate and without lag.

Only the force: the film's squeeze dynamics integrate it. The slip and sump temperature enter
the torque at the row's own time (Stribeck and hydrodynamic terms) and the slow pack heat
balance over the step, where half a row interval is immaterial. Replay (the contract's row
timing) is not changed: this is how the diagnosis feeds the plant the logged force.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np


def force_at_step_midpoints(t: np.ndarray, sample_t: np.ndarray, sample_force: np.ndarray) -> np.ndarray:
    """Force for rows at ``t``: linear interpolation of the logged samples at the midpoint
    of each row's step to the next row; the last row (no next step) at its own time."""
    t = np.asarray(t, float)
    if t.size == 0:
        return np.zeros(0)
    mid = np.empty_like(t)
    mid[:-1] = 0.5 * (t[:-1] + t[1:])
    mid[-1] = t[-1]
    return np.interp(mid, np.asarray(sample_t, float), np.asarray(sample_force, float))


def with_midpoint_force(campaign):
    """The campaign (bag_reader.Campaign) with every run's applied force taken at its steps'
    midpoints from the run's own force samples (runs without them are kept as they are)."""
    from clutch_model.formats.bag_reader import Campaign

    runs = []
    for run in campaign.runs:
        samples = run.samples.get("applied_force")
        if samples is None or samples[0].size < 2 or run.t.size < 2:
            runs.append(run)
            continue
        runs.append(replace(run, applied_force_n=force_at_step_midpoints(run.t, *samples)))
    return Campaign(runs)


INPUT_SMOOTHING_S = 0.005   # Gaussian kernel's standard deviation: -3 dB at 25 Hz


def gaussian_smooth(t: np.ndarray, y: np.ndarray, sigma_s: float) -> np.ndarray:
    """Zero-phase Gaussian smoothing of samples ``y`` at times ``t`` (standard deviation
    ``sigma_s``): resampled on their median interval, filtered, read back at ``t``. Samples
    further apart than about three kernel widths are returned as they are."""
    from scipy.ndimage import gaussian_filter1d

    t = np.asarray(t, float)
    y = np.asarray(y, float)
    if t.size < 3 or not sigma_s > 0:
        return y
    dt = float(np.median(np.diff(t)))
    if not dt > 0 or sigma_s < 0.3 * dt:
        return y
    grid = t[0] + dt * np.arange(int(np.floor((t[-1] - t[0]) / dt)) + 2)
    smooth = gaussian_filter1d(np.interp(grid, t, y), sigma_s / dt, mode="nearest")
    return np.interp(t, grid, smooth)


def with_smoothed_inputs(campaign, sigma_s: float = INPUT_SMOOTHING_S):
    """The campaign (bag_reader.Campaign) with every run's applied force and slip smoothed
    (gaussian_smooth), both their logged samples and the grid rows; the slip as logged is
    kept as ``samples["slip_speed_logged"]`` (module docstring)."""
    from clutch_model.formats.bag_reader import Campaign

    runs = []
    for run in campaign.runs:
        samples = dict(run.samples)
        if "applied_force" in samples:
            st, sv = samples["applied_force"]
            samples["applied_force"] = (st, gaussian_smooth(st, sv, sigma_s))
        if "slip_speed" in samples:
            samples.setdefault("slip_speed_logged", samples["slip_speed"])
            st, sv = samples["slip_speed_logged"]
            samples["slip_speed"] = (st, gaussian_smooth(st, sv, sigma_s))
        runs.append(replace(run, applied_force_n=gaussian_smooth(run.t, run.applied_force_n, sigma_s),
                            slip_speed_rad_s=gaussian_smooth(run.t, run.slip_speed_rad_s, sigma_s),
                            samples=samples))
    return Campaign(runs)
