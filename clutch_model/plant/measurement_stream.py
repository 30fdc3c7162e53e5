"""The measurement mechanisms (``mechanisms.apply_measurement``) one chunk of rows at a time,
with each mechanism's state carried across chunk boundaries: the numbers of the whole trace,
bit for bit.

- torque_offset: no state (the same addition).
- transport_delay: the rows of the current run that a later row's ``t - delay`` can still fall
  on (from the last row at or before ``t_last - delay``, or the run's first row): np.interp
  of a row only reads the two samples around ``t - delay`` (or the run's first value before
  its start), so interpolating on that tail plus the chunk gives the whole run's value.
- torque_sensor_lag: the recurrence's last (t, u, y); its coefficients are computed with the
  same numpy expressions from the same time steps (element by element), the recurrence in the
  same floating-point operations.

A measurement mechanism without a chunked form (none today) makes ``chunkable`` false: the
caller then applies ``apply_measurement`` to whole runs.
"""
from __future__ import annotations

import numpy as np

from clutch_model.plant.mechanisms import ordered
from clutch_model.plant.mechanisms.torque_sensor_lag import lowpass_coefficients


class _Offset:
    def __init__(self, m):
        self.offset = m.values["offset_nm"]

    def run(self, t, y, starts_run):
        return y + self.offset


class _Delay:
    def __init__(self, m):
        self.delay = m.values["delay_s"]
        self.t = self.y = None

    def run(self, t, y, starts_run):
        if starts_run or self.t is None:
            tt, yy = t, y
        else:
            tt, yy = np.concatenate([self.t, t]), np.concatenate([self.y, y])
        out = np.interp(t - self.delay, tt, yy)
        keep = max(int(np.searchsorted(tt, tt[-1] - self.delay, side="right")) - 1, 0)
        self.t, self.y = tt[keep:].copy(), yy[keep:].copy()
        return out


class _SensorLag:
    def __init__(self, m):
        self.tau = m.values["tau_s"]
        self.last = None                    # (t, u, y) of the run's previous row

    def run(self, t, u, starts_run):
        if self.tau <= 0.0:
            return u.copy()
        if starts_run or self.last is None:
            tt, uu, y0 = t, u, u[0]
        else:
            tt, uu, y0 = np.concatenate([[self.last[0]], t]), np.concatenate([[self.last[1]], u]), self.last[2]
        dt = np.diff(tt)
        a, c = lowpass_coefficients(dt, self.tau)
        y = np.empty_like(uu)
        _lowpass_linear(uu, dt, a, c, y0, y)
        self.last = (float(tt[-1]), float(uu[-1]), float(y[-1]))
        return y if tt.size == t.size else y[1:]


def _lowpass_linear(u, dt, a, c, y0, y):
    from clutch_model.plant.measurement_kernels import lowpass_linear

    lowpass_linear(u, dt, a, c, y0, y)


_CHUNKED = {"torque_offset": _Offset, "transport_delay": _Delay, "torque_sensor_lag": _SensorLag}


class MeasurementStream:
    """``apply_measurement(mechanisms, t, torque, run_start)`` chunk by chunk: ``run(t,
    torque, starts_run)`` maps the plant torque of the next rows of one run (``starts_run``:
    these rows start a new run) to what the sensor reads."""

    def __init__(self, mechanisms):
        ms = [m for m in ordered(mechanisms) if m.path == "measurement"]
        self.chunkable = all(m.id in _CHUNKED for m in ms)
        self._stages = [_CHUNKED[m.id](m) for m in ms] if self.chunkable else []

    def run(self, t, torque, starts_run: bool) -> np.ndarray:
        if not self.chunkable:
            raise ValueError("a measurement mechanism has no chunked form: apply it to whole runs")
        out = torque
        for stage in self._stages:
            out = stage.run(t, out, starts_run)
        return out
