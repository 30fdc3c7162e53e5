"""When the measured torque was sampled: at its logged stamps, or on its sensor's regular clock.

A torque sensor on a CAN bus samples on its own regular clock; the gateway that puts its frames
into ROS stamps them when they arrive, after the bus and the scheduler have added a varying
wait. The values then belong to the sensor's instants and the stamps scatter around them: with
the torque at 125 Hz and stamps up to 2.8 ms off (an outside generator's log, the values sampled
every 8 ms, the stamps jittered by up to 35 % of that), the diagnosis compared each value with
the model a jitter away from where it was taken, an error of the torque's rate times the jitter
(6.4 N*m rms). A time mechanism cannot take that up, but anything that smooths the model's torque
can: a second-order force path beside a 10.4 ms torque-sensor lag predicted the held-out rows
better (t = 14.2), and the lag was not named.

The sensor's clock is found from the stamps (``regular_clock``): the period whose phase the
stamps keep (the coherence of exp(2 pi i t / T) over candidate periods near the median interval),
each stamp given the tick nearest to it, and the ticks' times fitted to the stamps by least
squares, block by block along a long log (the fit of the blocks before numbers the next one,
and each block's ticks come from a line fitted around it: a sensor's clock drifts against the
log's). No clock is found where the stamps do not keep a phase (coherence under
``MIN_COHERENCE``), or where two stamps take the same tick.

Stamps can also scatter because the sensor sampled when they say (the project's virtual car
samples each topic at its jittered stamps). So the data choose (``choose_torque_stamps``), as
they choose how the inputs are read between samples (input_timing): the bench-fitted model's
torque at the stamps, p(s), and at the clock's ticks, p(r) (linear between the stamps' rows),
and the measured torque regressed on their difference beside p(s) and a constant:

    measured - p(s) = beta * (p(r) - p(s)) + gamma * p(s) + c + noise

The jitter is independent of whatever else the model gets wrong, so beta reads 1 when the values
belong to the ticks and 0 when they belong to the stamps. The ticks are taken when beta exceeds
``BETA_CLOCK`` by two standard errors and the two readings differ by a share of the torque's
noise (``input_timing.difference_bar_nm``); the torque is then compared at its ticks. On the virtual car's
`gateway` condition (a smooth torque at 125 Hz stamped on arrival) the readings differ by
1.2 N*m against 8 N*m of noise: the weight is 1.09 with nothing hidden and -0.98 under a 112 ms
sensor lag, 72 N*m off the bench model, and the stamps are kept either way.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

MIN_STAMPS = 50
PERIOD_SEARCH_FRAC = 0.02      # candidate periods within this share of the median interval
PERIOD_STEPS = 801
HEAD_STAMPS = 4000             # the period is found on a run's first stamps, then fitted along it
MIN_COHERENCE = 0.25           # |mean exp(2 pi i t / T)| of the stamps on the clock's period
BETA_CLOCK = 0.5
MAX_ROWS = 20000


def _coherence(span: np.ndarray, period: float) -> complex:
    return complex(np.mean(np.exp(2j * np.pi * span / period)))


def regular_clock(stamps) -> np.ndarray | None:
    """The ticks of the regular clock the ``stamps`` (s, increasing) keep, one per stamp, or None
    when they keep none (module doc)."""
    s = np.asarray(stamps, float)
    if s.size < MIN_STAMPS or not np.all(np.diff(s) > 0):
        return None
    period0 = float(np.median(np.diff(s)))
    head = s[:HEAD_STAMPS] - s[0]
    periods = period0 * (1.0 + np.linspace(-PERIOD_SEARCH_FRAC, PERIOD_SEARCH_FRAC, PERIOD_STEPS))
    # the coherence peak is ~period / span wide: a first pass on a coarse grid, then a fine one
    coh = np.array([abs(_coherence(head, p)) for p in periods])
    k = int(np.argmax(coh))
    fine = np.linspace(periods[max(k - 1, 0)], periods[min(k + 1, periods.size - 1)], 41)
    coh_fine = np.array([abs(_coherence(head, p)) for p in fine])
    period = float(fine[int(np.argmax(coh_fine))])
    if coh_fine.max() < MIN_COHERENCE:
        return None
    phase = float(np.angle(_coherence(head, period)))
    a, b = s[0] + period * phase / (2 * np.pi), period
    # number the ticks block by block, the clock refitted on the last two blocks numbered (a
    # sensor's clock may drift against the log's by a few parts per million along a long drive)
    w = HEAD_STAMPS
    ticks = np.empty(s.size)
    for start in range(0, s.size, w):
        end = min(start + w, s.size)
        ticks[start:end] = np.rint((s[start:end] - a) / b)
        lo = max(0, end - 2 * w)
        b, a = np.polyfit(ticks[lo:end], s[lo:end], 1)
    if np.any(np.diff(ticks) <= 0):
        return None
    out = np.empty(s.size)
    for start in range(0, s.size, w):
        end = min(start + w, s.size)
        lo, hi = max(0, start - w // 2), min(s.size, end + w // 2)
        b, a = np.polyfit(ticks[lo:hi], s[lo:hi], 1)
        out[start:end] = a + b * ticks[start:end]
    return out


def with_torque_stamps(campaign, stamps_by_run: dict):
    """The campaign with the measured torque's samples moved to ``stamps_by_run[name]`` (runs
    not in it as they are)."""
    from clutch_model.formats.bag_reader import Campaign

    out = []
    for r in campaign.runs:
        new = stamps_by_run.get(r.name)
        if new is None or "measured_torque" not in r.samples:
            out.append(r)
            continue
        samples = dict(r.samples)
        samples["measured_torque"] = (np.asarray(new, float), r.samples["measured_torque"][1])
        out.append(replace(r, samples=samples))
    return Campaign(out)


@dataclass
class TorqueStamps:
    """The torque's sample instants chosen, and the figures they were chosen on."""

    on_clock: bool
    ticks: dict                   # run name -> the clock's ticks (runs whose stamps keep a clock)
    beta: float = float("nan")    # weight on the ticks (0 the stamps, 1 the ticks)
    rows: int = 0
    jitter_rms_s: float = 0.0     # rms of stamp - tick over the runs with a clock
    difference_rms_nm: float = 0.0   # rms of p(ticks) - p(stamps) on the rows compared
    least_nm: float = 0.0
    beta_se: float = float("inf")    # the weight's standard error

    def describe(self) -> str:
        if not self.ticks:
            return "torque stamps: no regular clock behind them; compared at the stamps"
        where = "at the clock's ticks" if self.on_clock else "at the stamps"
        return (f"torque stamps: {len(self.ticks)} run(s) keep a regular clock (stamps {1e3 * self.jitter_rms_s:.2f} ms "
                f"rms off its ticks); the measured torque sides with the ticks by weight {self.beta:.2f} "
                f"(standard error {self.beta_se:.2f}) over "
                f"{self.rows} slipping rows (the readings differ by {self.difference_rms_nm:.3g} N*m rms, bar "
                f"{self.least_nm:.3g}): compared {where}")

    def to_dict(self) -> dict:
        return {"torque_on_sensor_clock": self.on_clock, "torque_clock_weight": self.beta,
                "torque_clock_weight_se": self.beta_se,
                "torque_stamp_jitter_rms_s": self.jitter_rms_s,
                "torque_clock_difference_rms_nm": self.difference_rms_nm}


def clock_ticks(campaign) -> dict:
    """run name -> the regular clock's ticks of its torque stamps, for the runs that keep one
    and whose stamps are not on it already."""
    out = {}
    for r in campaign.runs:
        s = r.torque_measured_t
        if s is None:
            continue
        ticks = regular_clock(s)
        if ticks is not None and np.any(np.abs(ticks - s) > 1e-9):
            out[r.name] = ticks
    return out


def choose_torque_stamps(campaign, model, ticks: dict, noise_nm: float = 0.0,
                         max_rows: int = MAX_ROWS) -> TorqueStamps:
    """Whether the measured torque belongs to its clock's ``ticks`` (``clock_ticks``) or to its
    stamps (module doc): ``model`` simulated on the head of ``campaign`` (the measured-time
    campaign at the stamps) and read at both."""
    from clutch_model.diagnosis.input_timing import MIN_SLIP_RAD_S, campaign_head, difference_bar_nm
    from clutch_model.prediction import predict_campaign

    if not ticks:
        return TorqueStamps(False, {})
    jitter = np.concatenate([ticks[r.name] - r.torque_measured_t for r in campaign.runs if r.name in ticks])
    jitter_rms = float(np.sqrt(np.mean(jitter ** 2)))
    head = campaign_head(campaign, max_rows, keep=lambda r: r.name in ticks)
    if head is None:
        return TorqueStamps(False, ticks, jitter_rms_s=jitter_rms)
    p = np.asarray(predict_campaign(model, head, energy0_j=0.0).torque_nm, float)
    cols = {"y": [], "ps": [], "pr": [], "slip": []}
    at = 0
    for r in head.runs:
        n = len(r)
        y = np.asarray(r.torque_measured_nm, float)
        rows = np.flatnonzero(np.isfinite(y))
        s_all, r_all = r.torque_measured_t, ticks[r.name]
        j = np.searchsorted(s_all, r.t[rows])
        j = np.minimum(j, s_all.size - 1)
        hit = np.abs(s_all[j] - r.t[rows]) < 1e-9
        rows, j = rows[hit], j[hit]
        if rows.size < 3:
            at += n
            continue
        ps = p[at:at + n][rows]
        cols["y"].append(y[rows])
        cols["ps"].append(ps)
        cols["pr"].append(np.interp(r_all[j], r.t[rows], ps))
        cols["slip"].append(np.asarray(r.slip_speed_rad_s, float)[rows])
        at += n
    if not cols["y"]:
        return TorqueStamps(False, ticks, jitter_rms_s=jitter_rms)
    y, ps, pr, slip = (np.concatenate(cols[k]) for k in ("y", "ps", "pr", "slip"))
    ok = np.isfinite(y) & np.isfinite(ps) & np.isfinite(pr) & (np.abs(slip) > MIN_SLIP_RAD_S)
    d = (pr - ps)[ok]
    rms = float(np.sqrt(np.mean(d * d))) if d.size else 0.0
    least = difference_bar_nm(noise_nm)
    beta, se = float("nan"), float("inf")
    if d.size >= 10 and rms > 0:
        a = np.column_stack([d, ps[ok], np.ones(d.size)])
        coef, *_ = np.linalg.lstsq(a, (y - ps)[ok], rcond=None)
        beta = float(coef[0])
        resid = (y - ps)[ok] - a @ coef
        cov = np.linalg.pinv(a.T @ a) * float(resid @ resid) / max(d.size - 3, 1)
        se = float(np.sqrt(max(cov[0, 0], 0.0)))
    # the weight must stand clear of the bar: a model far off the data (the bench friction, a
    # hidden mechanism) scatters it by its error over the readings' difference
    used = bool(np.isfinite(beta) and beta - 2.0 * se > BETA_CLOCK and rms >= least)
    return TorqueStamps(used, ticks, beta, int(d.size), jitter_rms, rms, least, se)
