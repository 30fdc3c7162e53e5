"""A 6 s run under a force chirp whose samples a test times as it likes (shared by the torque
clock and the receive-burst tests): the reference plant simulated on a 0.1 ms grid."""
from __future__ import annotations

import numpy as np

from clutch_model.plant.params import load_model
from clutch_model.plant.simulate import simulate
from clutch_model.prediction import predict_campaign

DURATION_S = 6.0


def force_n(t):
    return 7000.0 + 4000.0 * np.sin(2 * np.pi * (0.5 + 0.6 * t) * t)


def slip_rad_s(t):
    return 6.0 + 2.0 * np.sin(2 * np.pi * 0.7 * t)


def chirp_truth():
    """(the reference model, the fine grid, the plant torque on it)."""
    model = load_model(None)
    fine = np.arange(0.0, DURATION_S, 1e-4)
    return model, fine, simulate(model, fine, force_n(fine), slip_rad_s(fine), 60.0).torque_nm


def rms_off(model, camp) -> float:
    """RMS of the measured torque less the model's prediction after the first 0.3 s."""
    p = predict_campaign(model, camp).torque_nm
    y = camp.torque_measured
    ok = np.isfinite(y) & (camp.t > 0.3)
    return float(np.sqrt(np.mean((p - y)[ok] ** 2)))
