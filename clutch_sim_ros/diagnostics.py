"""/diagnostics of the clutch_sim node: counters the node updates every tick, and the
``diagnostic_msgs/DiagnosticArray`` built from them (2 Hz).

Three statuses, named ``<node name>: inputs | timing | plant`` (diagnostic_updater's
convention, no leading '/', so diagnostic_aggregator can path them); ``hardware_id`` is the
node's fully qualified name (tells namespaced rigs apart):

- inputs: per topic ``<topic>.state`` (fresh | stale | never), ``.age_s``, ``.value`` (held),
  ``.received``, ``.rejected`` (totals of the messages the node took; the input history keeps
  only the newest sample per tick) and ``.rejected_recent`` (since the last report).
  OK when all are fresh; WARN when one is stale (age > input_timeout_s; a stale applied force
  counts as 0 N) or inputs were rejected since the last report; ERROR when one is older than
  10 x input_timeout_s or has never arrived (the plant is then held at its initial state and
  nothing is published).
- timing: ticks, achieved rate, late ticks (started >= 1 period after schedule), missed ticks
  (periods the timer skipped; the plant still advances by the elapsed time, so plant time keeps
  wall time), stalls (a gap > STALL_S between ticks, made up in one sub-stepped advance),
  the longest gap, plant_time_s / wall_time_s since the plant started, on_time_pct, overruns
  (tick > 1 period), callback errors,
  non-finite resets, and p50/p99/max over the last 10000 ticks of the timer period, the
  lateness, the model step, the whole tick and the input latency (middleware receive time ->
  publish of the first sample computed with that input), process CPU % (all threads). WARN when
  the achieved rate is < 95 % of rate_hz (wall-clock mode) or an error/reset happened since
  the last report or a stall happened since the last report.
- plant: running/waiting, locked, pack force and whether it is clamped at
  model.max_pack_force_n, pressure and pack temperature and whether they leave the friction
  polynomials' box (P in [0, 20] MPa, theta in [0, 230] C). WARN while clamped or out of range
  (or when it happened since the last report).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Optional

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from clutch_model.plant.inputs import InputChannel

OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR
P_BOX_MPA = (0.0, 20.0)
THETA_BOX_C = (0.0, 230.0)
STALL_S = 0.1          # a gap between ticks longer than this is a stall (WARN)


class Ring:
    """Fixed-size ring buffer of floats (the last ``size`` samples) for percentiles."""

    __slots__ = ("_buf", "_i", "_n")

    def __init__(self, size: int = 10000):
        self._buf = np.zeros(size)
        self._i = 0
        self._n = 0

    def add(self, value: float) -> None:
        self._buf[self._i] = value
        self._i += 1
        if self._i == self._buf.size:
            self._i = 0
        if self._n < self._buf.size:
            self._n += 1

    def __len__(self) -> int:
        return self._n

    def values(self) -> np.ndarray:
        return self._buf[:self._n] if self._n < self._buf.size else self._buf.copy()

    def percentiles(self, qs=(50.0, 99.0)) -> list[float]:
        if not self._n:
            return [float("nan")] * (len(qs) + 1)
        v = self.values()
        return [float(x) for x in np.percentile(v, qs)] + [float(v.max())]



@dataclass
class Counters:
    """Totals since start; ``*_reported`` remember the value at the last report."""

    ticks: int = 0
    published: int = 0
    late_ticks: int = 0          # started >= 1 period after their scheduled time
    missed_ticks: int = 0        # periods the timer skipped (the plant advances by the elapsed time)
    stalls: int = 0              # gaps > STALL_S between ticks
    overruns: int = 0            # tick callback longer than one period
    callback_errors: int = 0
    nonfinite_resets: int = 0
    clock_jumps_back: int = 0    # sim time: /clock went backwards -> plant restarted
    redone_steps: int = 0        # sim time: repeated /clock time -> step recomputed
    resets: int = 0              # ~/reset calls
    clamped_ticks: int = 0
    out_of_range_ticks: int = 0
    reported: dict = field(default_factory=dict)

    def recent(self, name: str) -> int:
        return getattr(self, name) - self.reported.get(name, 0)

    def mark_reported(self) -> None:
        self.reported = {k: v for k, v in vars(self).items() if isinstance(v, int)}


@dataclass
class Timing:
    """Per-tick timing samples (ms) over the last ~10 s at 1 kHz."""

    period_ms: Ring = field(default_factory=Ring)      # between consecutive tick starts
    lateness_ms: Ring = field(default_factory=Ring)    # tick start - scheduled time
    step_ms: Ring = field(default_factory=Ring)        # model sample + advance
    tick_ms: Ring = field(default_factory=Ring)        # whole tick callback
    latency_ms: Ring = field(default_factory=Ring)     # input received (middleware) -> published with it
    longest_gap_ms: float = 0.0                        # longest time between two ticks
    plant_time_s: float = 0.0                          # plant time advanced since the plant started
    wall_time_s: float = 0.0                           # time base elapsed since the plant started


def _kv(key: str, value) -> KeyValue:
    if isinstance(value, float):
        text = f"{value:.6g}"
    elif isinstance(value, bool):
        text = "true" if value else "false"
    else:
        text = str(value)
    return KeyValue(key=key, value=text)


def _status(name: str, hw: str, level: int, message: str, values: Iterable[tuple]) -> DiagnosticStatus:
    return DiagnosticStatus(level=level, name=name, hardware_id=hw, message=message,
                            values=[_kv(k, v) for k, v in values])


def inputs_status(name: str, hw: str, channels: Iterable[InputChannel], now_ns: Optional[int],
                  timeout_s: float, rejected_before: dict) -> DiagnosticStatus:
    level, problems, values = OK, [], []
    for ch in channels:
        age = ch.age_s(now_ns) if now_ns is not None else None
        if ch.value is None or age is None:
            state, lvl = "never", ERROR
            problems.append(f"no {ch.name} yet")
        elif age > 10.0 * timeout_s:
            state, lvl = "stale", ERROR
            problems.append(f"{ch.name} stale {age:.3g} s")
        elif age > timeout_s:
            state, lvl = "stale", WARN
            problems.append(f"{ch.name} stale {age:.3g} s")
        else:
            state, lvl = "fresh", OK
        recent = ch.rejected - rejected_before.get(ch.name, 0)
        if recent > 0:
            lvl = max(lvl, WARN)
            problems.append(f"{recent} {ch.name} rejected")
        level = max(level, lvl)
        values += [(f"{ch.name}.state", state), (f"{ch.name}.age_s", age if age is not None else -1.0),
                   (f"{ch.name}.value", ch.value if ch.value is not None else float("nan")),
                   (f"{ch.name}.received", ch.received), (f"{ch.name}.rejected", ch.rejected),
                   (f"{ch.name}.rejected_recent", recent)]
    values.append(("input_timeout_s", timeout_s))
    message = "all inputs fresh" if not problems else "; ".join(problems)
    if any(ch.name == "applied_force" and ch.value is not None and now_ns is not None
           and ch.is_stale(now_ns, timeout_s) for ch in channels):
        message += " (stale applied force counts as 0 N)"
    return _status(f"{name}: inputs", hw, level, message, values)


def timing_status(name: str, hw: str, c: Counters, t: Timing, *, sim_time: bool, rate_hz: float,
                  achieved_hz: float, cpu_pct: float) -> DiagnosticStatus:
    ticks_due = c.ticks + c.missed_ticks
    on_time_pct = 100.0 * (c.ticks - c.late_ticks) / ticks_due if ticks_due else 100.0
    level, problems = OK, []
    if not sim_time and c.ticks > 0 and achieved_hz < 0.95 * rate_hz:
        level = WARN
        problems.append(f"achieved {achieved_hz:.1f} Hz of {rate_hz:g}")
    if c.recent("stalls"):
        level = WARN
        problems.append(f"{c.recent('stalls')} stall(s) > {STALL_S:g} s made up (longest gap "
                        f"{t.longest_gap_ms:.0f} ms)")
    for key in ("callback_errors", "nonfinite_resets", "clock_jumps_back"):
        if c.recent(key):
            level = WARN
            problems.append(f"{c.recent(key)} {key.replace('_', ' ')}")
    per = t.period_ms.percentiles()
    late = t.lateness_ms.percentiles()
    step = t.step_ms.percentiles()
    tick = t.tick_ms.percentiles()
    lat = t.latency_ms.percentiles()
    values = [("mode", "sim_time" if sim_time else "wall_clock"), ("rate_hz", rate_hz),
              ("achieved_hz", achieved_hz), ("ticks", c.ticks), ("published", c.published),
              ("late_ticks", c.late_ticks), ("missed_ticks", c.missed_ticks), ("stalls", c.stalls),
              ("longest_gap_ms", t.longest_gap_ms), ("plant_time_s", t.plant_time_s),
              ("wall_time_s", t.wall_time_s),
              ("on_time_pct", on_time_pct), ("overruns", c.overruns),
              ("callback_errors", c.callback_errors), ("nonfinite_resets", c.nonfinite_resets),
              ("clock_jumps_back", c.clock_jumps_back), ("redone_steps", c.redone_steps),
              ("resets", c.resets), ("cpu_pct", cpu_pct),
              ("period_ms.p50", per[0]), ("period_ms.p99", per[1]), ("period_ms.max", per[2]),
              ("lateness_ms.p50", late[0]), ("lateness_ms.p99", late[1]), ("lateness_ms.max", late[2]),
              ("step_ms.p50", step[0]), ("step_ms.p99", step[1]), ("step_ms.max", step[2]),
              ("tick_ms.p50", tick[0]), ("tick_ms.p99", tick[1]), ("tick_ms.max", tick[2]),
              ("latency_ms.p50", lat[0]), ("latency_ms.p99", lat[1]), ("latency_ms.max", lat[2]),
              ("latency_samples", len(t.latency_ms))]
    message = "ok" if not problems else "; ".join(problems)
    return _status(f"{name}: timing", hw, level, message, values)


def plant_status(name: str, hw: str, c: Counters, record: Optional[np.ndarray], *, running: bool,
                 max_pack_force_n: float) -> DiagnosticStatus:
    from clutch_model.plant import kernels as K

    if not running or record is None:
        return _status(f"{name}: plant", hw, OK, "waiting for the first sample of every input",
                       [("running", False), ("max_pack_force_n", max_pack_force_n)])
    clamped = bool(record[K.O_CLAMPED] > 0.5)
    p_mpa = float(record[K.O_PRESSURE_MPA])
    theta = float(record[K.O_THETA])
    p_out = not (P_BOX_MPA[0] <= p_mpa <= P_BOX_MPA[1])
    t_out = not (THETA_BOX_C[0] <= theta <= THETA_BOX_C[1])
    level, problems = OK, []
    if clamped or c.recent("clamped_ticks"):
        level = WARN
        problems.append(f"pack force clamped at {max_pack_force_n:.0f} N "
                        f"({c.recent('clamped_ticks')} ticks since last report)")
    if p_out or t_out or c.recent("out_of_range_ticks"):
        level = WARN
        problems.append("outside the friction polynomials' box P in [0, 20] MPa, theta in [0, 230] C "
                        f"({c.recent('out_of_range_ticks')} ticks since last report)")
    values = [("running", True), ("locked", bool(record[K.O_LOCKED] > 0.5)),
              ("clutch_torque_nm", float(record[K.O_TORQUE])),
              ("pack_force_n", float(record[K.O_FPACK])), ("force_clamped", clamped),
              ("max_pack_force_n", max_pack_force_n), ("clamped_ticks", c.clamped_ticks),
              ("pressure_mpa", p_mpa), ("pressure_out_of_box", p_out),
              ("pack_temperature_c", theta), ("temperature_out_of_box", t_out),
              ("out_of_range_ticks", c.out_of_range_ticks),
              ("film_thickness_m", float(record[K.O_H])), ("energy_j", float(record[K.O_ENERGY]))]
    message = "ok" if not problems else "; ".join(problems)
    return _status(f"{name}: plant", hw, level, message, values)


def array(stamp, statuses: list[DiagnosticStatus]) -> DiagnosticArray:
    msg = DiagnosticArray()
    msg.header.stamp = stamp
    msg.status = statuses
    return msg


def values_of(status: DiagnosticStatus) -> dict[str, str]:
    """The key/values of one status as a dict (for clients and tests)."""
    return {kv.key: kv.value for kv in status.values}
