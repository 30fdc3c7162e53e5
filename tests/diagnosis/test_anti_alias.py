"""The torque sensor's own filter (anti_alias.py): a second-order low-pass on the reading,
recovered on noise-free torque, against scipy's own Butterworth filter of the same plant torque."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from clutch_model.diagnosis.anti_alias import fit_anti_alias


@pytest.mark.parametrize("lag_s", [None, 0.02])
def test_a_butterworth_on_the_reading_is_recovered(lag_s):
    """The plant torque through a 60 Hz second-order Butterworth (scipy.signal.lsim of its
    analogue transfer function, on a 2 kHz grid), behind a 20 ms first-order sensor lag or
    alone: the fit (the lag refitted from 27 ms, the lag plus the filter's group delay) gives
    back the lag (and, alone, f_n and damping 1/sqrt 2), and its reading is within 1 % of the
    sensor's effect, where the plant read as it is leaves all of it."""
    from clutch_model.replay import replay_runs
    from .noise_free_campaigns import reference_campaign, with_measured_torque

    model, camp = reference_campaign(6, 4, 6.0)
    plant = np.asarray(replay_runs(model, camp).torque_sim, float)
    b, a = signal.butter(2, 2 * np.pi * 60.0, analog=True)
    if lag_s:
        a = np.polymul(a, [lag_s, 1.0])
    t = np.asarray(camp.t, float)
    measured = np.empty_like(plant)
    starts = np.flatnonzero(np.asarray(camp.run_start, bool))
    for i0, i1 in zip(starts, np.append(starts[1:], t.size)):
        tf = np.arange(t[i0], t[i1 - 1], 5e-4)
        _, y, _ = signal.lsim((b, a), np.interp(tf, t[i0:i1], plant[i0:i1]), tf - tf[0])
        y = y + plant[i0] * (1 - signal.step((b, a), T=tf - tf[0])[1])     # at rest at the first torque
        measured[i0:i1] = np.interp(t[i0:i1], tf, y)
    effect = np.sqrt(np.mean((measured - plant) ** 2))
    assert effect > 1.0
    rate = 1.0 / np.median(np.diff(t))
    fit = fit_anti_alias(model, with_measured_torque(camp, measured), np.ones(t.size, bool), rate,
                         lag_s=0.027 if lag_s else None)
    if lag_s:
        # behind a lag ten times slower the filter's own shape is weakly seen (f_n 38 Hz, damping
        # 0.44 read the same to 0.1 %), but the lag is the named one and the reading is the sensor's
        assert fit.parameters["tau_s"] == pytest.approx(lag_s, rel=0.05)
        assert fit.parameters["f_n_hz"] > 20.0
    else:
        assert fit.parameters["f_n_hz"] == pytest.approx(60.0, rel=0.1)
        assert fit.parameters["damping"] == pytest.approx(1 / np.sqrt(2), rel=0.15)
    assert np.sqrt(np.mean((fit.predicted - measured) ** 2)) < 0.01 * effect
