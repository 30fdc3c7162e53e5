"""Lock-up phases found from the data, robust to a noisy slip signal.

While the clutch is locked the measured slip is sensor noise around 0 (its std is unknown
and the noise may be coloured), and the transmitted torque is set by the driveline, so
locked samples must be kept out of calibration and diagnosis residuals.

Method (``detect_lockup``):
1. smooth the signed slip with a centred moving average over ``smooth_s``;
2. estimate the slip sensor's noise from the data: start from the white-noise estimate of
   first differences (1.4826·MAD(Δslip)/√2), then iterate: candidate lock segments are those
   where the smoothed |slip| stays below ``k_enter``·σ for at least ``min_dwell_s``, and σ
   becomes the robust std (1.4826·MAD) of the *raw* slip inside them — so coloured noise
   (AR(1) φ → 1, where differences see only a fraction of the std) still gets its full std
   after a few rounds. σ is capped so the thresholds stay below ``max_threshold_rad_s``;
3. hysteresis: a lock phase is a connected span with smoothed |slip| < ``k_exit``·σ that
   contains a sample below ``k_enter``·σ, trimmed at both ends to its first and last sample
   below ``k_enter``·σ (the exit threshold bridges noise excursions inside a lock; the edges
   sit at the enter threshold), lasting at least ``min_dwell_s`` (so brief zero crossings of
   a slipping clutch are not locks). Thresholds never go below the model's
   lock tolerance ``lock_slip_rad_s``.

Zero crossings of a slipping clutch (``crossings``): where the smoothed signed slip changes
sign outside a lock phase. The friction torque flips from +T to -T there within a few
milliseconds, and the sampled slip places that instant only to within a slip sample (and its
noise): a model given the measured slip puts the flip a few ms early or late and is off by
2T on the torque samples in between (measured on short runs with sign changes, slip at
124 Hz, the torque at 220 Hz: the true model itself was 1000-2000 N*m off on one or two rows
per crossing, RMS 35-62 N*m over such runs against 12.8 N*m of noise, hiding an 8 %
hysteresis). So the slip samples that bracket a crossing (one more on each side), widened by
the crossing's timing uncertainty (3 noise sds over the slip's slope there), span rows the
clutch model is not compared on (``excluded_at``). Only those: with 0.2 s on each side, as a
lock is padded, the sensor's smear of the flip was lost as evidence and a 32 ms torque-sensor
lag on the virtual car's sign_changes condition was named actuator_lag.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import uniform_filter1d

MAD_TO_SIGMA = 1.4826


@dataclass
class LockupResult:
    mask: np.ndarray          # locked at each input sample
    segments: list            # [(t_start_s, t_end_s), ...] of the lock phases
    noise_sigma_rad_s: float  # the slip sensor noise std estimated from the data
    threshold_enter_rad_s: float
    threshold_exit_rad_s: float
    crossings: list = field(default_factory=list)   # [(t_before_s, t_after_s)] of each zero crossing
    crossing_leads_s: list = field(default_factory=list)   # per crossing with a measured torque flip: how much
    # earlier the torque flipped than the logged slip crossed (s; negative: later); see with_torque_flips
    slip_reading_lead_s: float = 0.0   # the campaign's: how late the logged slip crosses zero (with_torque_flips)

    def at(self, t_query, pad_s: float = 0.0) -> np.ndarray:
        """Boolean mask at other times (grid rows, torque stamps): inside a lock phase,
        widened by ``pad_s`` on both sides."""
        return _inside(t_query, self.segments, pad_s)

    def excluded_at(self, t_query, pad_s: float = 0.0) -> np.ndarray:
        """The rows the clutch model is not compared on: ``at`` (the lock phases, widened by
        ``pad_s``) and the slip's zero crossings (their own windows, not widened by ``pad_s``:
        away from the flip's uncertain instant a model with the right measurement dynamics
        follows the flipped torque, and the sensor's smear of it is evidence for them)."""
        return self.at(t_query, pad_s) | _inside(t_query, self.crossings)

    @property
    def locked_time_s(self) -> float:
        return float(sum(b - a for a, b in self.segments))


def _inside(t_query, spans, pad_s: float = 0.0) -> np.ndarray:
    """Boolean mask of ``t_query`` inside any (a, b) of ``spans``, each widened by ``pad_s``."""
    t_query = np.asarray(t_query, float)
    out = np.zeros(t_query.size, bool)
    for a, b in spans:
        out |= (t_query >= a - pad_s) & (t_query <= b + pad_s)
    return out


def _spans(mask):
    """(start, end_exclusive) index pairs of the True runs of a boolean array."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def _hysteresis(t, a, t_in, t_out, min_dwell_s):
    mask = np.zeros(a.size, bool)
    segs = []
    for i0, i1 in _spans(a < t_out):
        core = np.flatnonzero(a[i0:i1] < t_in)
        if core.size == 0:
            continue
        i0, i1 = i0 + int(core[0]), i0 + int(core[-1]) + 1   # edges at the enter threshold
        if t[i1 - 1] - t[i0] < min_dwell_s:
            continue
        mask[i0:i1] = True
        segs.append((float(t[i0]), float(t[i1 - 1])))
    return mask, segs


def detect_lockup(t_s, slip_rad_s, smooth_s: float = 0.05, min_dwell_s: float = 0.25,
                  k_enter: float = 3.0, k_exit: float = 4.5, lock_slip_rad_s: float = 1e-3,
                  max_threshold_rad_s: float = 0.5, max_rounds: int = 12) -> LockupResult:
    """Lock phases of one run from its slip samples (own times, s). See the module docstring."""
    t = np.asarray(t_s, float)
    w = np.asarray(slip_rad_s, float)
    ok = np.isfinite(t) & np.isfinite(w)
    t, w = t[ok], w[ok]
    if t.size < 3:
        return LockupResult(np.zeros(t.size, bool), [], float("nan"), lock_slip_rad_s, lock_slip_rad_s)
    rate = (t.size - 1) / max(t[-1] - t[0], 1e-9)
    m = max(1, int(round(smooth_s * rate)))
    a = np.abs(uniform_filter1d(w, m, mode="nearest"))
    sigma = MAD_TO_SIGMA * float(np.median(np.abs(np.diff(w) - np.median(np.diff(w))))) / np.sqrt(2.0)
    sigma_cap = max_threshold_rad_s / k_exit
    # a slip logged in steps of q reads a locked clutch as mostly exact zeros: the MAD sees no
    # noise at all, and the thresholds would fall to the lock tolerance, below one step
    # (slip_resolution: the quantum, or the median change of a reading whose changes recur)
    floor = min(max(slip_resolution(w) / np.sqrt(12.0), 1e-12), sigma_cap)
    sigma = min(max(sigma, floor), sigma_cap)
    for _ in range(max_rounds):
        t_in = max(k_enter * sigma, lock_slip_rad_s)
        t_out = max(k_exit * sigma, t_in)
        mask, _ = _hysteresis(t, a, t_in, t_out, min_dwell_s)
        if mask.sum() < 10:
            break
        x = w[mask]
        new = min(MAD_TO_SIGMA * float(np.median(np.abs(x - np.median(x)))), sigma_cap)
        if abs(new - sigma) <= 0.02 * sigma:
            sigma = max(new, sigma, floor)
            break
        sigma = max(new, floor)
    t_in = max(k_enter * sigma, lock_slip_rad_s)
    t_out = max(k_exit * sigma, t_in)
    mask, segs = _hysteresis(t, a, t_in, t_out, min_dwell_s)
    full = np.zeros(ok.size, bool)
    full[np.flatnonzero(ok)] = mask
    return LockupResult(full, segs, float(sigma), float(t_in), float(t_out),
                        crossings=_zero_crossings(t, uniform_filter1d(w, m, mode="nearest"), mask, sigma, m, raw=w))


def slip_quantum(w, on_grid_frac: float = 0.95) -> float:
    """The step a slip signal is logged in (rad/s), or 0 when it is not quantised: the smallest
    nonzero change between successive samples that recurs (three times or more; a continuous
    signal repeats none), kept when at least ``on_grid_frac`` of the changes are its multiples.
    Measured on an outside generator's campaign (slip logged in 0.01 rad/s steps, noise sd
    0.004 rad/s while locked): the locked slip read 0 on all but a few samples, the
    first-difference MAD was 0, the lock thresholds fell to the 0.001 rad/s tolerance, a single
    0.01 reading broke every lock phase and none of the 22 % locked time was found."""
    w = np.asarray(w, float)
    w = w[np.isfinite(w)]
    d = np.abs(np.diff(w))
    d = d[d > 0]
    if d.size < 10:
        return 0.0
    vals, counts = np.unique(np.round(d, 12), return_counts=True)
    repeated = vals[counts >= 3]
    if repeated.size == 0:
        return 0.0
    q = float(repeated[0])
    r = d / q
    return q if float(np.mean(np.abs(r - np.round(r)) < 0.05)) >= on_grid_frac else 0.0


def slip_resolution(w, recurring_frac: float = 0.5, recurring_steps: int = 4) -> float:
    """The smallest change the slip reading resolves (rad/s): its quantum (``slip_quantum``)
    when it is logged on one grid; else, for a reading whose changes are few recurring steps
    (the ``recurring_steps`` commonest hold at least ``recurring_frac`` of them), the median of
    its changes; else 0 (a continuous reading, whose changes do not recur, even when each value
    is held over several samples). The second is the difference of two quantised readings:
    slip from two wheel encoders, each counting its tone wheel's edges over a window on its own
    grid (0.217 and 0.233 rad/s on an outside generator's campaign), changes by either quantum,
    their difference or their sum, so no one grid holds 95 % of its changes (the two quanta
    held 92 %). There the first-difference MAD was 0 (74 % of the successive samples unchanged),
    the noise estimate fell to nothing, none of the 2-5 % locked time was found and the locked
    dither made 150-180 zero crossings per bag."""
    q = slip_quantum(w)
    if q > 0.0:
        return q
    w = np.asarray(w, float)
    d = np.abs(np.diff(w[np.isfinite(w)]))
    d = d[d > 0.0]
    if d.size < 10:
        return 0.0
    _, counts = np.unique(np.round(d, 9), return_counts=True)
    if np.sort(counts)[::-1][:recurring_steps].sum() < recurring_frac * d.size:
        return 0.0
    return float(np.median(d))


MAX_CROSSING_S = 0.25     # a crossing's window on each side at most (a slower one dwells: a lock)


def _zero_crossings(t, smoothed, locked, sigma: float, half: int, raw=None) -> list:
    """[(t0, t1)] around each sign change of the smoothed signed slip between samples i and
    i+1 outside a lock phase: the two bracketing samples, widened on each side by one sample
    and by the crossing's timing uncertainty, 3 noise sds over the slip's slope there (a slow
    crossing is timed less well than a fast one; the slope from the smoothed slip ``half``
    samples on either side). The bracket also takes in the sign changes of the ``raw`` slip
    within ``half`` samples: where the slip curves through zero its moving average crosses a
    sample or two away from the samples themselves, and a plant driven by the logged slip flips
    its torque at the first sample of the new sign (an outside generator's one-bag `none`,
    slip decelerating through zero at 250 Hz: the window ended at that sample, the torque
    sample 0.4 ms after it read the flip half done, 957 N*m off the model, and that one row was
    90 % of the held-out sum of squares: `unexplained`)."""
    flip = np.flatnonzero((np.sign(smoothed[:-1]) * np.sign(smoothed[1:]) < 0) & ~locked[:-1] & ~locked[1:])
    raw_flip = (np.flatnonzero(np.sign(raw[:-1]) * np.sign(raw[1:]) < 0) if raw is not None
                else np.zeros(0, int))
    n = t.size
    out = []
    for i in flip:
        a, b = max(i - half, 0), min(i + 1 + half, n - 1)
        slope = abs(smoothed[b] - smoothed[a]) / max(t[b] - t[a], 1e-9)
        widen = min(3.0 * sigma / slope, MAX_CROSSING_S) if slope > 0 else MAX_CROSSING_S
        near = raw_flip[(raw_flip >= i - half) & (raw_flip <= i + half)]
        first, last = (min(i, int(near.min())), max(i, int(near.max()))) if near.size else (i, i)
        out.append((float(t[max(first - 1, 0)] - widen), float(t[min(last + 2, n - 1)] + widen)))
    return out


def detect_lockup_run(run, **options) -> LockupResult:
    """``detect_lockup`` on a bag_reader.Run's own slip samples (``run.slip_raw_t``);
    use ``.at(run.t)`` for its grid rows and ``.at(run.torque_measured_t)`` for the torque
    samples."""
    return detect_lockup(run.slip_raw_t, run.slip_raw_rad_s, **options)


def slip_samples(run) -> tuple:
    """(t, slip) the lock-up detection reads for a bag_reader.Run: its own slip samples as
    logged when it has them, else its grid slip."""
    if "slip_speed" in getattr(run, "samples", {}):
        return run.slip_raw_t, run.slip_raw_rad_s
    return run.t, run.slip_speed_rad_s


def campaign_lockup(campaign, **options) -> list:
    """``LockupResult`` per run of a bag_reader.Campaign (campaign order), from each run's
    ``slip_samples``."""
    return [detect_lockup(*slip_samples(run), **options) for run in campaign.runs]


FLIP_SEARCH_S = 0.3          # the measured torque's flip is looked for within this of a slip crossing
FLIP_LEVEL_S = (0.15, 0.35)  # where the torque's levels before and after the flip are read (s from the crossing)
FLIP_LEVEL_NOISE_SDS = 10.0  # both levels this many torque noise sds from zero: the flip is under load
MIN_FLIPS = 3                # measured flips for a campaign's lead


def torque_flip_lead(crossing, t_slip, slip, t_torque, torque, torque_noise_nm: float):
    """(lead, flip): how much earlier (s) the measured torque flipped sign than the logged slip
    crossed zero the same way, at one crossing window (t0, t1) of ``LockupResult.crossings``,
    and the flip's instant; None where the torque does not flip once under load there. The
    torque's instant is its one sign change within ``FLIP_SEARCH_S`` of the window's centre,
    the slip's the nearest of its sign changes in the same direction (a slip dithering about
    zero after the flip crosses many times), each interpolated between its two samples."""
    c = 0.5 * (crossing[0] + crossing[1])
    lo, hi = FLIP_LEVEL_S
    before = torque[(t_torque > c - hi) & (t_torque < c - lo)]
    after = torque[(t_torque > c + lo) & (t_torque < c + hi)]
    if before.size < 3 or after.size < 3:
        return None
    level_before, level_after = float(np.median(before)), float(np.median(after))
    if (np.sign(level_before) * np.sign(level_after) >= 0
            or min(abs(level_before), abs(level_after)) < FLIP_LEVEL_NOISE_SDS * torque_noise_nm):
        return None
    to = np.sign(level_after)

    def sign_changes(t, y):
        m = (t > c - FLIP_SEARCH_S) & (t < c + FLIP_SEARCH_S)
        t, y = t[m], y[m]
        k = np.flatnonzero((np.sign(y[:-1]) == -to) & (np.sign(y[1:]) == to))
        return t[k] - y[k] * (t[k + 1] - t[k]) / (y[k + 1] - y[k])

    flips, slips = sign_changes(t_torque, torque), sign_changes(t_slip, slip)
    if flips.size != 1 or slips.size == 0:
        return None
    return float(slips[np.argmin(np.abs(slips - flips[0]))] - flips[0]), float(flips[0])


def with_torque_flips(results: list, campaign) -> float:
    """Widen each zero crossing's window back to the measured torque's flip where the logged
    slip crosses *after* the torque flipped (returns the campaign's lead, s; 0 when the slip is
    not late). At a crossing under load the friction torque flips within milliseconds of the
    true slip's zero, so the measured flip times the crossing; a slip reading that averages a
    wheel encoder's counts over a window logs the crossing half a window late, and no clutch
    mechanism makes the torque flip before the slip that drives it. The model given that slip
    keeps the old sign meanwhile and is off by twice the torque: on an outside generator's
    `none` (slip from two encoders, windows 67-97 ms) the torque led the logged slip by 4-40 ms
    (median 33.5) at each of 11 crossings, and 67 held-out rows off by 20-1600 N*m held 99.6 %
    of its held-out sum of squares (`unexplained`, t = 6558). A torque flipping *after* the
    slip is left to the diagnosis: a sensor lag and a transport delay do that, and the smear is
    their evidence. The campaign's lead (the median over crossings with a measured flip, from
    3 of them, when positive) widens the crossings where no flip is measured; a crossing's own
    measured lead widens it when larger."""
    measured = []
    for run, res in zip(campaign.runs, results):
        res.crossing_leads_s = []
        tt, yt = run.torque_measured_t, run.torque_measured_raw_nm
        if not res.crossings or tt is None or tt.size < 3:
            continue
        sigma_t = MAD_TO_SIGMA * float(np.median(np.abs(np.diff(yt)))) / np.sqrt(2.0)
        ts, ws = slip_samples(run)
        seen = set()
        for cr in res.crossings:
            found = torque_flip_lead(cr, ts, ws, tt, yt, sigma_t)
            lead = None
            if found is not None and found[1] not in seen:      # one flip times one crossing
                lead = found[0]
                seen.add(found[1])
                measured.append(lead)
            res.crossing_leads_s.append(lead)
    campaign_lead = float(np.median(measured)) if len(measured) >= MIN_FLIPS else 0.0
    campaign_lead = min(max(campaign_lead, 0.0), MAX_CROSSING_S)
    for res in results:
        leads = res.crossing_leads_s or [None] * len(res.crossings)
        res.crossings = [(a - min(max(campaign_lead, lead or 0.0), MAX_CROSSING_S), b)
                         for (a, b), lead in zip(res.crossings, leads)]
        res.slip_reading_lead_s = campaign_lead
    return campaign_lead


def without_locked_torque(campaign, pad_s: float = 0.1, model_lock_slip_rad_s: float = 0.0, **options):
    """(campaign with the measured torque set to NaN on grid rows inside a lock phase or a zero
    crossing of the slip (widened by ``pad_s``), [LockupResult per run]). While locked the
    driveline sets the torque, and across a zero crossing the sampled slip does not time the
    torque's flip, so those rows say nothing about the clutch model; NaN keeps them out of
    every residual.

    ``model_lock_slip_rad_s``: rows whose slip (as the plant reads it) is inside the model's
    own lock band are left out too. The model locks there and gives its static capacity, which
    the driveline's torque never is; a stick shorter than ``min_dwell_s`` is no lock phase (a
    slipping clutch crossing zero stays that long below the thresholds under a noisy slip), and
    on an outside generator's slip-controlled drive (PI on the slip, sticks of 0.1-0.2 s, slip
    logged within 2e-4 rad/s of 0 while stuck) such rows, scored, were 411 N*m off the true
    model on one run and took the calibration's held-out RMSE from 7 to 12.6 N*m."""
    from dataclasses import replace

    from clutch_model.formats.bag_reader import Campaign

    results = campaign_lockup(campaign, **options)
    with_torque_flips(results, campaign)
    runs = []
    for run, res in zip(campaign.runs, results):
        if run.torque_measured_nm is not None:
            out = res.excluded_at(run.t, pad_s) if (res.segments or res.crossings) else np.zeros(run.t.size, bool)
            if model_lock_slip_rad_s > 0.0:
                out |= np.abs(np.asarray(run.slip_speed_rad_s, float)) < model_lock_slip_rad_s
            if out.any():
                run = replace(run, torque_measured_nm=np.where(out, np.nan, run.torque_measured_nm))
        runs.append(run)
    return Campaign(runs), results
