"""torque_sensor_lag: the torque sensor (or its filter / bus averaging) is band-limited."""
import numpy as np

from clutch_model.plant.mechanisms.base import Mechanism, Parameter, ParamSpec, VirtualCarRange, run_bounds


class TorqueSensorLag(Mechanism):
    id = "torque_sensor_lag"
    path = "measurement"
    parameters = (Parameter("tau_s", "s", (0.0, 10.0), "time constant of the sensor's low-pass"),)
    physics = ("measured = first-order low-pass of the plant torque (time constant tau_s), "
               "started at each bag's first plant torque")
    virtual_car = VirtualCarRange(visible=(0.02, 0.2), default=0.06)
    diagnosis_candidate = True

    @classmethod
    def search_space(cls, scale):
        return [ParamSpec("tau_s", True, 1e-4, 2.0, np.geomspace(0.003, 0.8, 12))]

    def apply_to_measurement(self, t, torque, run_start):
        return lowpass_signal(t, torque, run_start, self.values["tau_s"])


def lowpass_coefficients(dt: np.ndarray, tau_s: float) -> tuple:
    """(a, c) of the first-order low-pass's exact steps dt (``lowpass_signal``): a = exp(-dt/tau),
    c = (1 - a) tau/dt (1 where dt <= 0)."""
    x = np.where(dt > 0, dt / tau_s, 0.0)
    return np.exp(-x), np.where(x > 0, -np.expm1(-x) / np.where(x > 0, x, 1.0), 1.0)


def lowpass_signal(t, u, run_start, tau_s, hold: bool = False):
    """First-order low-pass tau y' = u - y of each run, y = u at the run's first row.

    Exact discretisation on an irregular grid: ``u`` linear between samples (default) or
    held (``hold=True``, zero-order hold), with a = exp(-dt/tau), c = (1 - a) tau/dt:
        linear: y[k+1] = u[k+1] + a (y[k] - u[k]) - c (u[k+1] - u[k])
        held:   y[k+1] = u[k]   + a (y[k] - u[k])
    Works on a 1-D trace or on (n_sets, n) traces sharing ``t``."""
    t = np.asarray(t, dtype=float)
    u = np.asarray(u, dtype=float)
    if tau_s <= 0.0:
        return u.copy()
    dt = np.diff(t)
    a, c = lowpass_coefficients(dt, tau_s)
    from clutch_model.plant.measurement_kernels import lowpass_held, lowpass_linear

    traces = np.ascontiguousarray(u.reshape(-1, t.size))     # one trace per row
    y = np.empty_like(traces)
    for lo, hi in run_bounds(run_start, t.size):
        for u_run, y_run in zip(traces[:, lo:hi], y[:, lo:hi]):
            if hold:
                lowpass_held(u_run, dt[lo:hi - 1], a[lo:hi - 1], u_run[0], y_run)
            else:
                lowpass_linear(u_run, dt[lo:hi - 1], a[lo:hi - 1], c[lo:hi - 1], u_run[0], y_run)
    return y.reshape(u.shape)
