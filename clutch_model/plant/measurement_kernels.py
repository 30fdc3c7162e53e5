"""Compiled loops of the chunked measurement mechanisms (``measurement_stream``); imported only
when a model has them."""
from numba import njit


@njit(cache=True, nogil=True)
def lowpass_linear(u, dt, a, c, y0, y):
    """y[0] = y0; then torque_sensor_lag's recurrence (u linear between samples) with the same
    operations in the same order: y[k+1] = u[k+1] + a[k] (y[k] - u[k]) - c[k] (u[k+1] - u[k])."""
    y[0] = y0
    for k in range(u.size - 1):
        if dt[k] <= 0.0:
            y[k + 1] = y[k]
        else:
            y[k + 1] = u[k + 1] + a[k] * (y[k] - u[k]) - c[k] * (u[k + 1] - u[k])
