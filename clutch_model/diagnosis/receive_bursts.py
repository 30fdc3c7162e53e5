"""Topics received in bursts: samples a gateway forwarded together, re-timed at their period.

A CAN or Ethernet gateway that forwards a sensor's frames in bursts (every 10-20 ms, say) gives
each frame of a burst the burst's log time, or log times microseconds apart: a force sampled
at 200 Hz arrives as two to four messages at once, then nothing until the next burst. Read as
logged, every frame of a burst but the last is stamped up to a burst period after it was
taken, and held between bursts the force is a staircase that lags the pack force by half a
burst period on average: a lag that no clutch has. On an outside generator's campaign with
nothing hidden (force and torque at 200 Hz forwarded in bursts every 10-20 ms, 6 bags of
44 s) the diagnosis saw 67 distinct torque instants per second, the residual followed the
force rate, and the answer read `unexplained` with actuator_lag closest; the true model
itself replays those bags 13.8 N*m off the noise-free torque against 1.9 N*m of noise.

A topic was received in bursts (``topic_bursts``) when at least ``BURSTY_SHARE`` of its
messages follow the one before by less than ``BURST_GAP_S`` and a tenth of its mean interval
(a jittered sensor clock almost never does: at 1 kHz with +-0.5 ms of jitter, 0.5 % of
intervals fall under 0.1 ms; a log with duplicated messages has a few per cent). Its sample
period is the time between bursts per message (bursts after a gap of more than
``BURST_GAP_OUTLIER`` typical burst intervals, a dropout, left out). Each burst's messages are
then spread back from its log time at that period, in their logged order, the last half a
period before the burst (the expected time of the latest sample a burst can hold, the sensor's
phase being unknown), and never before the burst before it.

Only the diagnosis re-times (``apply``): ``replay`` keeps the contract's rows, one per force
message at its log time, so an extended model is replayed on the inputs as logged.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from clutch_model.formats.bag_reader import Campaign, run_with_samples

BURST_GAP_S = 0.5e-3         # a message within this (and a tenth of the mean interval) of the one before is in its burst
BURSTY_SHARE = 0.3           # ... for at least this share of a topic's messages: received in bursts
BURST_GAP_OUTLIER = 5.0      # a burst this many typical burst intervals after the one before follows a dropout
MIN_MESSAGES = 50
PHASE_WINDOW = 64            # bursts over which the sensor grid's phase is found
PHASE_STEPS = 48             # phases tried per sample period
PHASE_MATCH = 0.8            # share of a window's bursts the phase must account for
PERIOD_REFINE = 0.004        # the period searched within this share of the bursts' mean
PERIOD_REFINE_BURSTS = 2000
CHANNELS = ("applied_force", "slip_speed", "sump_temperature", "measured_torque", "pack_temperature")


@dataclass
class TopicBursts:
    """How one topic of one run was received."""

    share_in_bursts: float         # messages within a burst gap of the one before
    burst_interval_s: float = float("nan")   # typical time between bursts
    period_s: float = float("nan")           # the sample period behind them


def _bursts(t: np.ndarray) -> tuple:
    """(first message, one past the last) of each burst of the log times ``t``: messages
    within BURST_GAP_S and a tenth of the mean interval of the one before join its burst."""
    mean_gap = (t[-1] - t[0]) / (t.size - 1)
    inside = np.diff(t) < min(BURST_GAP_S, 0.1 * mean_gap)
    starts = np.r_[0, np.flatnonzero(~inside) + 1]
    return starts, np.r_[starts[1:], t.size]


def topic_bursts(t) -> TopicBursts | None:
    """How a topic's log times (s, non-decreasing) came: None when too few to tell; a
    TopicBursts with its sample period when received in bursts (module doc)."""
    t = np.asarray(t, float)
    if t.size < MIN_MESSAGES or not t[-1] > t[0]:
        return None
    starts, ends = _bursts(t)
    share = 1.0 - (starts.size - 1) / (t.size - 1)
    if share < BURSTY_SHARE:
        return TopicBursts(share)
    counts = ends - starts
    w = t[ends - 1]                                          # each burst's log time
    between = np.diff(w)
    if between.size < 2:
        return TopicBursts(share)
    typical = float(np.median(between))
    normal = between <= BURST_GAP_OUTLIER * typical
    period = float(np.sum(between[normal]) / np.sum(counts[1:][normal]))
    return TopicBursts(share, typical, refined_period(w, counts, period))


def _phases(period_s: float) -> np.ndarray:
    """The grid phases tried over one sample period."""
    return (np.arange(PHASE_STEPS) + 0.5) / PHASE_STEPS * period_s


def _windows(n: int):
    """Each window of PHASE_WINDOW bursts (from the second: a burst is counted from the one before)."""
    for a in range(1, n, PHASE_WINDOW):
        yield np.arange(a, min(a + PHASE_WINDOW, n))


def _grid_counts(w: np.ndarray, counts: np.ndarray, idx: np.ndarray, thetas: np.ndarray, period_s: float):
    """For grids of phases ``thetas`` (rows) and the bursts ``idx`` (columns): whether the burst
    holds as many grid instants since the burst before it as it holds messages, and the number
    of its last grid instant -> (meets, now)."""
    now = np.floor((w[idx][None, :] - thetas[:, None]) / period_s)
    before = np.floor((w[idx - 1][None, :] - thetas[:, None]) / period_s)
    return (now - before) == counts[idx][None, :], now


def _grid_phase_last(w: np.ndarray, counts: np.ndarray, period_s: float) -> np.ndarray:
    """Each burst's last sample instant on the sensor's sample grid (theta + n * period), or NaN.

    The grid's phase theta is found over PHASE_WINDOW bursts at a time: the phase for which the
    most bursts hold as many grid instants since the burst before them as they hold messages
    (the centre of the phases that do best). A burst whose count it meets gets the grid instant
    at or before its log time; the others (a lost frame, a phase no window agrees on) NaN."""
    last = np.full(w.size, np.nan)
    thetas = _phases(period_s)
    for idx in _windows(w.size):
        share = _grid_counts(w, counts, idx, thetas, period_s)[0].mean(axis=1)
        if share.max() < PHASE_MATCH:
            continue
        best = share >= share.max() - 1e-12
        theta = float(np.angle(np.mean(np.exp(2j * np.pi * thetas[best] / period_s)))) / (2 * np.pi) * period_s
        theta %= period_s
        meets, now = _grid_counts(w, counts, idx, np.array([theta]), period_s)
        ok = meets[0]
        last[idx[ok]] = theta + now[0][ok] * period_s
    return last


def _phase_share(w: np.ndarray, counts: np.ndarray, period_s: float) -> float:
    """The mean over windows of the largest share of bursts a grid phase accounts for."""
    thetas = _phases(period_s)
    shares = [float(np.max(np.mean(_grid_counts(w, counts, idx, thetas, period_s)[0], axis=1)))
              for idx in _windows(w.size)]
    return float(np.mean(shares)) if shares else 0.0


def refined_period(w: np.ndarray, counts: np.ndarray, period_s: float) -> float:
    """The sample period that lets a grid account for the most bursts (``_phase_share``) within
    PERIOD_REFINE of ``period_s``, on the first PERIOD_REFINE_BURSTS bursts (their log times
    ``w`` and message ``counts``): the period from the bursts' span is off by up to two periods
    over the span (0.2 % on a 6 s bag), which moves the grid by a third of a period over a
    window of bursts."""
    w, counts = w[:PERIOD_REFINE_BURSTS], counts[:PERIOD_REFINE_BURSTS]
    periods = period_s * (1.0 + np.linspace(-PERIOD_REFINE, PERIOD_REFINE, 41))
    share = np.array([_phase_share(w, counts, p) for p in periods])
    best = share >= share.max() - 1e-12
    return float(np.mean(periods[best])) if share.max() >= PHASE_MATCH else period_s


def retimed(t, period_s: float) -> np.ndarray:
    """A burst-received topic's log times spread back from each burst's log time at the sample
    period (module doc): from the burst's last instant on the sensor's grid where its phase is
    found (``_grid_phase_last``), else from half a period before the burst."""
    t = np.asarray(t, float)
    starts, ends = _bursts(t)
    counts = ends - starts
    w = t[ends - 1]                                          # each burst's log time
    # the burst's samples were taken after the burst before it: squeezed in where the period
    # would reach back beyond it
    step = np.minimum(period_s, np.r_[np.inf, np.diff(w)] / (counts - 0.5))
    last = w - 0.5 * step
    on_grid = _grid_phase_last(w, counts, period_s)
    found = np.isfinite(on_grid)
    last[found], step[found] = on_grid[found], period_s
    burst = np.repeat(np.arange(starts.size), counts)
    from_last = (ends - 1)[burst] - np.arange(t.size)
    return last[burst] - step[burst] * from_last


@dataclass
class ReceiveBursts:
    """The topics found received in bursts, per run, and their sample periods."""

    topics: dict = field(default_factory=dict)      # run name -> {channel: TopicBursts}

    @property
    def found(self) -> bool:
        return bool(self.topics)

    def describe(self) -> str:
        chans = sorted({c for per in self.topics.values() for c in per})
        parts = []
        for c in chans:
            tb = [per[c] for per in self.topics.values() if c in per]
            parts.append(f"{c.replace('_', ' ')} ({100 * np.mean([b.share_in_bursts for b in tb]):.0f} % of messages "
                         f"within {1e3 * BURST_GAP_S:g} ms of the one before, a burst every "
                         f"{1e3 * np.median([b.burst_interval_s for b in tb]):.3g} ms, "
                         f"{1e3 * np.median([b.period_s for b in tb]):.3g} ms per sample)")
        return (f"inputs: received in bursts in {len(self.topics)} run(s): {'; '.join(parts)}; each burst's samples "
                f"re-timed back from its log time at their period (replay keeps the log times)")

    def to_dict(self) -> dict:
        return {"received_in_bursts": {name: {c: {"share_in_bursts": b.share_in_bursts,
                                                   "burst_interval_s": b.burst_interval_s,
                                                   "period_s": b.period_s} for c, b in per.items()}
                                       for name, per in self.topics.items()}}

    def apply(self, campaign):
        """The campaign with every burst-received topic re-timed (``retimed``) and each run put on
        the replay grid of its re-timed samples (``bag_reader.run_with_samples``)."""
        return Campaign([self._run(r) for r in campaign.runs])

    def _run(self, run):
        per = self.topics.get(run.name)
        if not per:
            return run
        samples = dict(run.samples)
        for chan, b in per.items():
            t, v = samples[chan]
            samples[chan] = (retimed(t, b.period_s), v)
        return run_with_samples(run, samples)


def find_receive_bursts(campaign) -> ReceiveBursts:
    """The topics of each run received in bursts (``topic_bursts``)."""
    out = {}
    for r in campaign.runs:
        per = {}
        for chan in CHANNELS:
            if chan not in r.samples:
                continue
            b = topic_bursts(r.samples[chan][0])
            if b is not None and np.isfinite(b.period_s) and b.period_s > 0:
                per[chan] = b
        if per:
            out[r.name] = per
    return ReceiveBursts(out)
