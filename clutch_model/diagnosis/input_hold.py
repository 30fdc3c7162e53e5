"""The applied force a step-holding plant should be given: its value at each step's midpoint.

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
