"""Bags that continue one drive: a recorder that rolls over to a new bag every minute or so
writes one drive as consecutive bags, the next bag's first message a few ms after the last
one's. Each bag restarts the plant (film open, pack at the sump temperature: the replay
contract), so a pack at 150 °C at the roll-over reads as a friction level that jumps from bag
to bag: structure that no mechanism explains (measured on a continuous drive cut into 60-90 s
bags, nothing hidden: the friction level differed between bags by -28 % to +32 %, F = 36.9,
and the answer was `unexplained`).

The diagnosis joins such bags into one drive, the plant state carried across the roll-over,
when the data says so. The bags are simulated in time order with the bench-fitted model, each
from the state the path chosen so far left; at every bag that starts within
``CONTINUATION_GAP_S`` of the previous bag's last message it is simulated both ways (restarted,
continued), and the bags are joined when the continued simulation fits the bag's slipping rows
better by ``JOIN_RATIO`` in mean square. Both are scaled by the least-squares torque scale that
fits the previous bag, so a friction level the bench got wrong does not decide (a scale of
each hypothesis' own takes the level the two pack temperatures give the bag, and kept a 20 s
bag of a drive apart); they are compared where the force has been steady (``steady_force``: a
95 ms actuator lag the bench model lacks put both simulations 54-70 N*m off on every slipping
row and kept a drive apart; on its steady rows, restarted 69 and 66 N*m, continued 9.5 and
8.5). Checked pair by pair, each from a restarted previous bag, a drive of six bags came out
as three of two. Bags written back to
back by a recorder that restarts the plant with each bag (the replay contract) stay apart:
their restarted simulation fits better.

Report labels stay in the bags' own terms: a joined drive is named ``first..last`` inside
the diagnosis, and ``bag_labels`` maps its spans back to "bag" / "bag[t0:t1]" (s from that
bag's first message)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from clutch_model.formats.bag_reader import Run, latest_sample, replay_grid

CONTINUATION_GAP_S = 0.5     # a bag starting this soon after the previous one's last message may continue it
JOIN_RATIO = 0.9             # continued fits the next bag's slipping rows below this fraction of restarted (MS)
DECISION_WINDOW_S = 60.0     # rows of the next bag compared: its first this many seconds
SLIPPING_RAD_S = 0.5
STEADY_S, STEADY_BAND_N, STEADY_BAND_FRAC = 0.5, 200.0, 0.03   # the rows compared: force steady (steady_force)
MIN_ROWS = 50
INPUTS = ("applied_force", "slip_speed", "sump_temperature")


@dataclass(frozen=True)
class Part:
    """A bag inside a joined drive: its offset (s of its first message after the drive's) and
    the end of its last sample (s from its own first message)."""

    name: str
    offset_s: float
    end_s: float


@dataclass
class Drive:
    name: str
    parts: list
    gaps_s: list

    def as_dict(self) -> dict:
        return {"drive": self.name, "bags": [p.name for p in self.parts],
                "offsets_s": [round(p.offset_s, 6) for p in self.parts], "gaps_s": [round(g, 6) for g in self.gaps_s]}


@dataclass
class Joins:
    """What the diagnosis joined, and every roll-over it weighed."""

    drives: list = field(default_factory=list)        # Drive
    checks: list = field(default_factory=list)        # dict per candidate roll-over

    def as_dict(self) -> dict:
        return {"gap_s": CONTINUATION_GAP_S, "join_ratio": JOIN_RATIO,
                "drives": [d.as_dict() for d in self.drives], "checks": self.checks}

    def bag_labels(self, label: str) -> list:
        """A diagnosis label ("run" or "run[t0:t1]", s from the run's first message) in the
        bags' own terms (a drive's span may cover several bags)."""
        from clutch_model.diagnosis.split import HeldOut, parse_held_out

        h = parse_held_out(label)
        drive = next((d for d in self.drives if d.name == h.run), None)
        if drive is None:
            return [label]
        if h.whole_run:
            return [p.name for p in drive.parts]
        out = []
        for p in drive.parts:
            a, b = max(h.t0, p.offset_s), min(h.t1, p.offset_s + p.end_s)
            if b > a:
                whole = a <= p.offset_s and b >= p.offset_s + p.end_s
                out.append(p.name if whole else HeldOut(p.name, a - p.offset_s, b - p.offset_s).label)
        return out

    def relabel(self, labels) -> list:
        return [x for lab in labels for x in self.bag_labels(lab)]

    def drive_label(self, label: str) -> str:
        """A bag label given by the user ("bag" or "bag[t0:t1]") as a label of the run the
        diagnosis works on."""
        from clutch_model.diagnosis.split import HeldOut, parse_held_out

        h = parse_held_out(label)
        for d in self.drives:
            for p in d.parts:
                if p.name == h.run:
                    if h.whole_run:
                        return HeldOut(d.name, p.offset_s, p.offset_s + p.end_s + 1e-3).label
                    return HeldOut(d.name, p.offset_s + h.t0, p.offset_s + h.t1).label
        return label


def bag_end_s(run: Run) -> float:
    """The bag's last valid sample on any clutch topic, s from its first message."""
    ends = [float(t[-1]) for t, _ in run.samples.values() if len(t)]
    return max(ends) if ends else float(run.t[-1])


def gap_s(prev: Run, nxt: Run) -> float:
    return (int(nxt.start_time_ns) - int(prev.start_time_ns)) * 1e-9 - bag_end_s(prev)


def may_continue(prev: Run, nxt: Run, max_gap_s: float = CONTINUATION_GAP_S) -> bool:
    """Whether ``nxt`` starts soon enough after ``prev``'s last message to continue it, with
    the same topics."""
    g = gap_s(prev, nxt)
    return 0.0 <= g <= max_gap_s and set(prev.samples) == set(nxt.samples) and all(c in prev.samples for c in INPUTS)


def join_runs(runs: list, name: str | None = None) -> Run:
    """Consecutive bags as one run on the replay grid: every topic's samples in one time base
    (s from the first bag's first message), rows at every force sample once every input has
    started, each input the latest sample at or before the row."""
    first = runs[0]
    t0 = int(first.start_time_ns)
    chans: dict = {}
    for r in runs:
        off = (int(r.start_time_ns) - t0) * 1e-9
        for ch, (t, v) in r.samples.items():
            chans.setdefault(ch, []).append((np.asarray(t, float) + off, np.asarray(v, float)))
    samples = {ch: (np.concatenate([a for a, _ in parts]), np.concatenate([b for _, b in parts]))
               for ch, parts in chans.items()}
    rows, force, slip, sump = replay_grid(*(samples[c] for c in INPUTS))
    run = Run(name=name or f"{first.name}..{runs[-1].name}", t=rows, applied_force_n=force,
              slip_speed_rad_s=slip, sump_temperature_c=sump, start_time_ns=t0, rejected_samples=int(sum(r.rejected_samples for r in runs)), samples=samples)
    if "measured_torque" in samples:
        run.torque_measured_nm = latest_sample(*samples["measured_torque"], rows)
    if "pack_temperature" in samples:
        run.pack_temperature_measured_c = latest_sample(*samples["pack_temperature"], rows)
    return run


def steady_force(t, force, half_window_s: float = STEADY_S) -> np.ndarray:
    """Rows whose force stayed within max(STEADY_BAND_N, STEADY_BAND_FRAC of it) over the
    ``half_window_s`` before them: there a force path's dynamics the bench model lacks (a lag,
    a hysteresis) have settled, and what tells a carried plant state from a restarted one, the
    pack temperature, is left."""
    from scipy.ndimage import maximum_filter1d, minimum_filter1d

    t, force = np.asarray(t, float), np.asarray(force, float)
    if t.size < 3:
        return np.zeros(t.size, bool)
    dt = float(np.median(np.diff(t)))
    w = int(max(1, round(half_window_s / dt))) if dt > 0 else 1
    n = w + 1                                   # the row and the half_window_s before it
    spread = (maximum_filter1d(force, n, mode="nearest", origin=(n - 1) // 2)
              - minimum_filter1d(force, n, mode="nearest", origin=(n - 1) // 2))
    return (spread < np.maximum(STEADY_BAND_N, STEADY_BAND_FRAC * np.abs(force))) & (t > t[0] + half_window_s)


def _compared_rows(run: Run, pred: np.ndarray, window_s: float | None = None) -> np.ndarray:
    """The rows two simulations are compared on: slipping, measured, predicted, the force steady
    (``steady_force``) where enough rows are; within the run's first ``window_s``."""
    meas = np.asarray(run.torque_measured_nm, float)
    t = np.asarray(run.t, float)
    use = np.isfinite(meas) & np.isfinite(pred) & (np.abs(run.slip_speed_rad_s) > SLIPPING_RAD_S)
    if window_s is not None:
        use &= t < t[0] + window_s
    steady = use & steady_force(t, run.applied_force_n)
    return steady if np.count_nonzero(steady) >= MIN_ROWS else use


def _run_on(sim, run: Run, t_offset_s: float, restart: bool) -> np.ndarray:
    """The plant torque of ``run``'s rows, simulated on from ``sim`` (restarted, or continued
    with its times ``t_offset_s`` after the drive's start)."""
    t = np.asarray(run.t, float) + t_offset_s
    rs = np.zeros(t.size, bool)
    rs[0] = restart
    return np.array(sim.run(t, run.applied_force_n, run.slip_speed_rad_s, run.sump_temperature_c,
                            run_start=rs).torque_nm)


def continuation_check(prev: Run, prev_pred: np.ndarray, nxt: Run, restarted: np.ndarray,
                       continued: np.ndarray) -> dict:
    """Compare the two simulations of ``nxt`` (restarted, continued from ``prev``) on its
    slipping rows (its first DECISION_WINDOW_S, the force steady), both scaled by the torque
    scale that fits ``prev``'s simulation to its measured torque (the same in both: a friction
    level the bench model got wrong is taken out, the level the two pack temperatures give
    ``nxt`` is not)."""
    out = {"bag": nxt.name, "after": prev.name, "gap_s": round(gap_s(prev, nxt), 6), "joined": False}
    if prev.torque_measured_nm is None or nxt.torque_measured_nm is None:
        out["why"] = "no measured torque"
        return out
    ref = _compared_rows(prev, prev_pred)
    use = _compared_rows(nxt, restarted + continued, DECISION_WINDOW_S)
    if np.count_nonzero(use) < MIN_ROWS or np.count_nonzero(ref) < MIN_ROWS:
        out["why"] = "too few slipping rows to tell"
        return out
    p = prev_pred[ref]
    k = float(np.asarray(prev.torque_measured_nm, float)[ref] @ p) / float(p @ p) if np.any(p) else 1.0
    meas = np.asarray(nxt.torque_measured_nm, float)[use]
    ms_apart = float(np.mean((meas - k * restarted[use]) ** 2))
    ms_together = float(np.mean((meas - k * continued[use]) ** 2))
    out.update(torque_scale=k, rmse_restarted_nm=float(np.sqrt(ms_apart)),
               rmse_continued_nm=float(np.sqrt(ms_together)), rows=int(np.count_nonzero(use)),
               joined=bool(ms_together < JOIN_RATIO * ms_apart))
    return out


def join_continued_bags(model, runs: list, say=None) -> tuple:
    """-> (runs, Joins): the campaign's bags with every roll-over the data confirms joined
    into one drive. The bags are simulated in time order with ``model``, each from the state
    the path chosen so far left (``continuation_check`` at every candidate roll-over)."""
    from clutch_model.plant.simulate import ChunkedSimulation

    runs = sorted(runs, key=lambda r: r.start_time_ns)
    joins = Joins()
    if not any(may_continue(prev, nxt) for prev, nxt in zip(runs, runs[1:])):
        return runs, joins          # no bag starts right after another: nothing to simulate
    groups, gaps = [[runs[0]]], [[]]
    sim = ChunkedSimulation(model)
    drive_start_ns = int(runs[0].start_time_ns)
    pred = _run_on(sim, runs[0], 0.0, restart=True)
    for prev, nxt in zip(runs, runs[1:]):
        if may_continue(prev, nxt):
            restart_sim, continue_sim = sim.branch(), sim.branch()
            restarted = _run_on(restart_sim, nxt, 0.0, restart=True)
            continued = _run_on(continue_sim, nxt, (int(nxt.start_time_ns) - drive_start_ns) * 1e-9, restart=False)
            chk = continuation_check(prev, pred, nxt, restarted, continued)
            joins.checks.append(chk)
            if chk["joined"]:
                groups[-1].append(nxt)
                gaps[-1].append(chk["gap_s"])
                sim, pred = continue_sim, continued
                continue
            sim, pred = restart_sim, restarted
        else:
            pred = _run_on(sim, nxt, 0.0, restart=True)
        drive_start_ns = int(nxt.start_time_ns)
        groups.append([nxt])
        gaps.append([])
    out = []
    for grp, gp in zip(groups, gaps):
        if len(grp) == 1:
            out.append(grp[0])
            continue
        drive = join_runs(grp)
        t0 = int(grp[0].start_time_ns)
        joins.drives.append(Drive(drive.name, [Part(r.name, (int(r.start_time_ns) - t0) * 1e-9, bag_end_s(r))
                                               for r in grp], gp))
        out.append(drive)
    if say is not None:
        for d in joins.drives:
            say(f"bags {', '.join(p.name for p in d.parts)} are one drive (each starts "
                f"{max(d.gaps_s) * 1e3:.0f} ms or less after the previous one's last message, and the plant "
                f"continued across fits its torque better than restarted): diagnosed as {d.name}, the plant "
                f"state carried, times in s from {d.parts[0].name}'s first message")
        kept = [c for c in joins.checks if not c["joined"]]
        if kept:
            say(f"{len(kept)} bag(s) start right after the previous one but fit better restarted: kept apart")
    return out, joins
