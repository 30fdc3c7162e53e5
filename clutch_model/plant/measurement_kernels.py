"""Compiled loops of the measurement mechanisms (torque_sensor_lag's low-pass, whole or chunked by
``measurement_stream``); imported only when a model has them."""
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


@njit(cache=True, nogil=True)
def lowpass_held(u, dt, a, y0, y):
    """y[0] = y0; then the zero-order-hold recurrence y[k+1] = u[k] + a[k] (y[k] - u[k])."""
    y[0] = y0
    for k in range(u.size - 1):
        if dt[k] <= 0.0:
            y[k + 1] = y[k]
        else:
            y[k + 1] = u[k] + a[k] * (y[k] - u[k])
