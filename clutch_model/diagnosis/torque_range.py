"""The torque sensor's range: readings pinned at a rail carry no torque.

A torque sensor (or its amplifier, or the bus signal's scaling) saturates: beyond its range it
reports its limit. The reading then says only that the torque is at least that, and a model
compared there is charged for a misfit that is the sensor's: on an outside generator's
campaign with nothing hidden (the torque clipped at +-1268 N*m, 78 % of its peak, on 1.3 % of
the messages; all topics at 1 kHz) the flexible residual model predicted the held-out residual
at t = 24.5 and the answer read ``unexplained``.

A rail shows in the readings themselves: the campaign's extreme value repeats exactly, sample
after sample, where a continuous reading (noise on a moving torque) reaches its extreme once.
Over 101 campaigns of seven outside generators without a rail, quantised torque readings among
them (0.5 and 1 N*m steps, up to 99.9 % of their readings sharing a value with another), each
extreme was read at most 4 times (3 in a row, on quantised readings); the clipped campaign read
its upper rail 1344 times, 447 in a row.

``find_torque_rails`` looks at each extreme of the measured torque over the whole campaign
(duplicate messages, the same stamp and value, counted once): it is a rail when at least
RAIL_MIN_SAMPLES readings (and RAIL_MIN_SHARE of them) sit exactly on it, RAIL_MIN_RUN of them
in a row somewhere. ``without_torque_at_rails`` takes those readings out as if they had not
been received (a torque message lost), and the rows that would hold one of them get no
measured torque (NaN: kept out of calibration and residuals, as lock-up rows are). Replay is
not changed; report.json's ``inputs`` gives the rails found (``torque_rails_nm``,
``torque_samples_at_rails``).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

RAIL_MIN_SAMPLES = 10     # readings exactly at an extreme for it to be a rail ...
RAIL_MIN_SHARE = 1e-3     # ... and this share of all readings
RAIL_MIN_RUN = 3          # ... and this many in a row somewhere
RAIL_TOL = 1e-9           # "exactly": relative to the rail's size


@dataclass
class TorqueRails:
    """The rails of the measured torque found in a campaign (none: an empty tuple)."""

    rails_nm: tuple           # the rail values, lower first
    at_rails: int             # readings on a rail (duplicates counted once)
    readings: int             # readings in all (duplicates counted once)

    @property
    def found(self) -> bool:
        return bool(self.rails_nm)

    def on_rail(self, values: np.ndarray) -> np.ndarray:
        """Which of ``values`` sit on a rail."""
        values = np.asarray(values, float)
        hit = np.zeros(values.shape, bool)
        for rail in self.rails_nm:
            hit |= _at(values, rail)
        return hit

    def describe(self) -> str:
        if not self.found:
            return "torque range: no rail in the readings"
        rails = " and ".join(f"{r:+.1f}" for r in self.rails_nm)
        return (f"torque range: the readings sit on a rail at {rails} N*m ({self.at_rails} of {self.readings}, "
                f"{100.0 * self.at_rails / max(self.readings, 1):.2f} %): the sensor's range; those readings are "
                f"left out")

    def to_dict(self) -> dict:
        return {"torque_rails_nm": [float(r) for r in self.rails_nm], "torque_samples_at_rails": int(self.at_rails)}


def _at(values: np.ndarray, level: float) -> np.ndarray:
    """Which of ``values`` sit exactly (RAIL_TOL) on ``level``."""
    return np.abs(np.asarray(values, float) - level) <= RAIL_TOL * max(abs(level), 1.0)


def _readings(run) -> tuple:
    """(times, values) of a run's torque messages, a message repeated with the same stamp and
    value counted once."""
    s = run.samples.get("measured_torque")
    if s is None:
        return np.zeros(0), np.zeros(0)
    t, v = np.asarray(s[0], float), np.asarray(s[1], float)
    keep = np.ones(t.size, bool)
    keep[1:] = ~((t[1:] == t[:-1]) & (v[1:] == v[:-1]))
    return t[keep], v[keep]


def _longest_run(flags: np.ndarray) -> int:
    """The longest stretch of consecutive True in ``flags``."""
    if not flags.any():
        return 0
    edges = np.diff(np.concatenate([[0], flags.astype(np.int8), [0]]))
    return int(np.max(np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)))


def find_torque_rails(campaign) -> TorqueRails:
    """The rails of the campaign's measured torque (module docstring)."""
    values = [_readings(run)[1] for run in campaign.runs]
    values = [v[np.isfinite(v)] for v in values]
    n = int(sum(v.size for v in values))
    if n == 0:
        return TorqueRails((), 0, 0)
    pooled = np.concatenate(values)
    rails, at = [], 0
    for extreme in (float(pooled.min()), float(pooled.max())):
        on = [_at(v, extreme) for v in values]
        count = int(sum(o.sum() for o in on))
        if (count >= max(RAIL_MIN_SAMPLES, RAIL_MIN_SHARE * n)
                and max(_longest_run(o) for o in on) >= RAIL_MIN_RUN and extreme not in rails):
            rails.append(extreme)
            at += count
    return TorqueRails(tuple(rails), at, n)


def without_torque_at_rails(campaign, rails: TorqueRails):
    """The campaign with the readings on a rail taken out of each run's torque messages, and
    no measured torque (NaN) on the rows that would hold one of them."""
    from clutch_model.formats.bag_reader import Campaign

    if not rails.found:
        return campaign
    out = []
    for run in campaign.runs:
        s = run.samples.get("measured_torque")
        if s is None:
            out.append(run)
            continue
        t, v = np.asarray(s[0], float), np.asarray(s[1], float)
        bad = rails.on_rail(v)
        if not bad.any():
            out.append(run)
            continue
        torque = run.torque_measured_nm
        if torque is not None:
            # each row holds the latest reading at or before it (the replay grid)
            latest = np.searchsorted(t, np.asarray(run.t, float), side="right") - 1
            held_bad = np.zeros(latest.size, bool)
            ok = latest >= 0
            held_bad[ok] = bad[latest[ok]]
            torque = np.where(held_bad, np.nan, np.asarray(torque, float))
        samples = {**run.samples, "measured_torque": (t[~bad], v[~bad])}
        out.append(replace(run, samples=samples, torque_measured_nm=torque))
    return Campaign(out)
