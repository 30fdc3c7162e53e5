"""transport_delay: the measured torque lags the plant by a pure delay."""
import numpy as np

from clutch_model.plant.mechanisms.base import Mechanism, Parameter, ParamSpec, VirtualCarRange, run_bounds


class TransportDelay(Mechanism):
    id = "transport_delay"
    path = "measurement"
    parameters = (Parameter("delay_s", "s", (0.0, 10.0), "sensor / bus latency"),)
    physics = "measured torque lags the plant by a pure delay"
    virtual_car = VirtualCarRange(visible=(0.02, 0.2), default=0.08)

    @classmethod
    def search_space(cls, scale):
        return [ParamSpec("delay_s", True, 1e-4, 2.0, np.geomspace(0.003, 0.8, 12))]

    def apply_to_measurement(self, t, torque, run_start):
        return delay_signal(t, torque, run_start, self.values["delay_s"])


def delay_signal(t, y, run_start, delay_s):
    """y(t - delay) per run, linearly interpolated, the run's first value before its start.

    Works on a 1-D trace or on (n_sets, n) traces sharing the time grid ``t``.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    out = np.empty_like(y)
    for a, b in run_bounds(run_start, t.size):
        tt = t[a:b]
        q = tt - delay_s
        if y.ndim == 1:
            out[a:b] = np.interp(q, tt, y[a:b])
        else:
            # vectorised linear interpolation for many traces on one grid
            idx = np.clip(np.searchsorted(tt, q, side="right") - 1, 0, tt.size - 1)
            nxt = np.minimum(idx + 1, tt.size - 1)
            span = tt[nxt] - tt[idx]
            w = np.where(span > 0, (q - tt[idx]) / np.where(span > 0, span, 1.0), 0.0)
            w = np.clip(w, 0.0, 1.0)
            seg = y[:, a:b]
            out[:, a:b] = seg[:, idx] * (1 - w) + seg[:, nxt] * w
    return out
