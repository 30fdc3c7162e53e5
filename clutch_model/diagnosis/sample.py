"""The diagnosis sample: windows of a long campaign, each started from the plant state the
model has there, so that the costly stages simulate a bounded number of rows.

`diagnose` runs thousands of simulations of the campaign it diagnoses (calibration, candidate
fits, refits, intervals, discovery); the plant integrates every 5.1 ms of simulated time, so
an hour of data costs tens of CPU-minutes however it is decimated. When the (decimated)
campaign lasts longer than ``budget_s``, those stages work on a sample instead:

* **windows** of ``window_s`` (10 s) inside the runs, one per equal stratum of the campaign's
  time (so the sample spans the whole log: the dissipated energy, the sump and pack
  temperature trends), each placed within its stratum where it adds the most of the
  campaign's operating range not yet covered (bins of applied force x |slip|, pack
  temperature and slip power, from one simulation of the whole campaign) and has measured
  torque outside lock-up;
* each window is a run of the sampled campaign that **starts from the plant state** a
  simulation of the whole campaign has at its first row (``ChunkedSimulation.state``: film
  thickness, pack temperature, dissipated energy, actuator and hysteresis states; the plant
  kernel's ``run_*_from``), so `friction_degradation` sees the campaign's energy and the pack
  its temperature. With the model whose state it is, the window reproduces the whole
  simulation bit for bit; another parameter set (a candidate) starts from that state, i.e.
  from the best estimate of the real plant's state, and is compared over the window;
* the first ``warmup_s`` (1 s) of each window is not scored (measured torque NaN): the
  measurement mechanisms (transport delay, sensor lag) restart at each window, and a
  candidate's fast states (film, actuator lag) settle to its own dynamics;
* the windows are the runs the split sees: whole windows are held out (the split's rule for
  campaigns of 3 runs or more), so held-out data stays whole time spans never fitted.

The states come from the bench-fitted model for the car calibration, then from the
calibrated model for the friction correction, the candidate fits and the verdict.
Campaigns shorter than the budget are diagnosed as before, row for row.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from clutch_model.formats.bag_reader import Campaign, Run

DEFAULT_BUDGET_S = 180.0    # simulated seconds of data (warm-ups included) the costly stages see
WINDOW_S = 10.0
WARMUP_S = 1.0
MIN_SCORED_FRAC = 0.3       # a window is placed where at least this share of rows is scored
COVER_BINS = 8


@dataclass
class WindowRun(Run):
    """A window of a run (t: s from the source bag's first message) that starts from a given
    plant state (``prediction.PlantInputs``)."""

    plant_state0: np.ndarray | None = None
    source: str = ""
    warmup_s: float = 0.0


@dataclass
class SamplePlan:
    """Which windows the diagnosis works on (report.json ``diagnosis_sample``)."""

    budget_s: float
    total_s: float
    window_s: float = WINDOW_S
    warmup_s: float = WARMUP_S
    windows: list = field(default_factory=list)      # (run name, t0, t1), campaign order
    rows_full: int = 0
    rows_sample: int = 0

    @property
    def sampled_s(self) -> float:
        return float(sum(t1 - t0 for _, t0, t1 in self.windows))

    def to_json(self) -> dict:
        return {"sampled": True, "budget_s": self.budget_s, "campaign_s": self.total_s,
                "sampled_s": self.sampled_s, "window_s": self.window_s, "warmup_s": self.warmup_s,
                "windows": [window_label(n, t0, t1) for n, t0, t1 in self.windows],
                "rows": {"campaign": self.rows_full, "sample": self.rows_sample},
                "start_states": "the plant state of a simulation of the whole campaign at each window's first row "
                                "(bench-fitted model for the car calibration, then the calibrated model)"}

    def describe(self) -> str:
        return (f"diagnosis sample: {len(self.windows)} windows of {self.window_s:g} s ({self.sampled_s:.0f} s of "
                f"{self.total_s:.0f} s, {self.rows_sample} of {self.rows_full} rows), each from the plant state of "
                f"the whole campaign's simulation, first {self.warmup_s:g} s not scored")


def not_sampled(budget_s, total_s) -> dict:
    return {"sampled": False, "budget_s": budget_s, "campaign_s": total_s}


def _fmt(x: float) -> str:
    return f"{round(float(x), 3):g}"


def window_label(run: str, t0: float, t1: float) -> str:
    """The split's label of a time span: "<bag>[t0:t1]" (s from the bag's first message)."""
    return f"{run}[{_fmt(t0)}:{_fmt(t1)}]"


def campaign_seconds(campaign: Campaign) -> float:
    return float(sum(r.duration_s for r in campaign.runs))


@dataclass
class _Slot:
    """A possible window: rows [k0, k1) of the campaign, inside run j."""

    run: int
    k0: int
    k1: int
    mid_s: float          # campaign time (runs end to end) of its middle
    scored: float         # share of rows with measured torque outside lock-up
    cells: frozenset      # operating-range bins it covers


def _slot_starts(r: Run, window_s: float) -> np.ndarray:
    """Window starts (s) tried in a run: window_s / 2 apart; a run no longer than a window is
    one window."""
    if r.duration_s <= window_s:
        return np.array([float(r.t[0])])
    return np.arange(float(r.t[0]), float(r.t[-1]) - window_s + 1e-9, window_s / 2.0)


def start_rows(campaign: Campaign, window_s: float = WINDOW_S) -> np.ndarray:
    """Every row a window may start at (``choose_windows``), sorted."""
    return np.concatenate([sl.start + np.searchsorted(r.t, _slot_starts(r, window_s))
                           for r, sl in campaign.slices()]).astype(np.int64)


def _candidate_slots(campaign: Campaign, window_s: float, warmup_s: float, labels: dict) -> list:
    slots, offset = [], 0.0
    scored = np.isfinite(campaign.torque_measured)
    for j, (r, sl) in enumerate(campaign.slices()):
        t = r.t
        dur = r.duration_s
        for a in _slot_starts(r, window_s):
            k0 = sl.start + int(np.searchsorted(t, a))
            k1 = sl.start + int(np.searchsorted(t, a + window_s)) if dur > window_s else sl.stop
            if k1 - k0 < 4:
                continue
            kw = sl.start + int(np.searchsorted(t, t[k0 - sl.start] + warmup_s))
            sc = float(np.mean(scored[kw:k1])) if k1 > kw else 0.0
            cells = frozenset((name, int(b)) for name, lab in labels.items() for b in np.unique(lab[kw:k1]))
            mid = offset + 0.5 * (float(t[k0 - sl.start]) + float(t[k1 - 1 - sl.start])) - float(t[0])
            slots.append(_Slot(j, k0, k1, mid, sc, cells))
        offset += dur
    return slots


def _bin_labels(campaign: Campaign, pack_temperature_c: np.ndarray, slip_power_w: np.ndarray) -> dict:
    """Operating-range bins of every row (quantile bins over the scored rows)."""
    ok = np.isfinite(campaign.torque_measured)
    if not ok.any():
        ok = np.ones(campaign.t.size, bool)

    def bins(x):
        edges = np.unique(np.quantile(x[ok], np.linspace(0, 1, COVER_BINS + 1)[1:-1]))
        return np.searchsorted(edges, x)

    force, slip = bins(campaign.force), bins(np.abs(campaign.slip))
    return {"force x slip": force * (COVER_BINS + 1) + slip, "pack temperature": bins(pack_temperature_c),
            "slip power": bins(np.abs(slip_power_w))}


def choose_windows(campaign: Campaign, budget_s: float, pack_temperature_c, slip_power_w,
                   window_s: float = WINDOW_S, warmup_s: float = WARMUP_S) -> list:
    """-> [(run index, k0, k1)] (rows [k0, k1)) in campaign order: one window per stratum
    (module doc)."""
    n = max(3, int(budget_s // window_s))
    slots = _candidate_slots(campaign, window_s, warmup_s,
                             _bin_labels(campaign, np.asarray(pack_temperature_c), np.asarray(slip_power_w)))
    total = campaign_seconds(campaign)
    strata = [[] for _ in range(n)]
    for s in slots:
        strata[min(n - 1, int(s.mid_s / total * n))].append(s)
    covered, chosen = set(), []
    for group in strata:
        # windows never share rows (a held-out window must hold nothing a fitted one has)
        group = [s for s in group if all(s.k1 <= c.k0 or s.k0 >= c.k1 for c in chosen)]
        group = [s for s in group if s.scored >= MIN_SCORED_FRAC] or group
        if not group:
            continue
        best = max(group, key=lambda s: (len(s.cells - covered), s.scored, -s.k0))
        covered |= best.cells
        chosen.append(best)
    return [(s.run, s.k0, s.k1) for s in sorted(chosen, key=lambda s: s.k0)]


@dataclass
class FullPass:
    """One simulation of the whole campaign: the states at the given rows and what the
    sample and the report need of its rows."""

    states: np.ndarray            # (len(rows), N_STATE)
    torque_nm: np.ndarray         # plant torque, every row
    pack_temperature_c: np.ndarray
    power_w: np.ndarray
    energy_end_j: float


def full_pass(model, campaign: Campaign, rows, energy0_j: float = 0.0) -> FullPass:
    """Simulate ``model`` over the whole campaign (energy from ``energy0_j``) in chunks ending
    at each of ``rows`` (sorted), keeping the plant state after each of those rows
    (``ChunkedSimulation``: the numbers of one ``simulate`` call)."""
    from clutch_model.plant.simulate import ChunkedSimulation

    n = campaign.t.size
    sim = ChunkedSimulation(model, energy0_j)
    torque, theta, power = np.empty(n), np.empty(n), np.empty(n)
    states = []
    keep = rows_set(rows)
    bounds = sorted({k + 1 for k in keep} | {n})
    a = 0
    for b in bounds:
        if b > a:
            res = sim.run(campaign.t[a:b], campaign.force[a:b], campaign.slip[a:b], campaign.sump[a:b],
                          run_start=campaign.run_start[a:b], copy=False)
            torque[a:b], theta[a:b], power[a:b] = res.torque_nm, res.pack_temperature_c, res.power_w
        if b - 1 in keep:
            states.append(sim.state.copy())
        a = b
    from clutch_model.plant.kernels import N_STATE

    return FullPass(np.array(states, float).reshape(len(states), N_STATE), torque, theta, power, sim.energy_j)


def rows_set(rows) -> set:
    return {int(k) for k in rows}


def sample_campaign(campaign: Campaign, windows: list, states: np.ndarray, warmup_s: float = WARMUP_S):
    """The sampled campaign (one WindowRun per window, started from ``states[i]``, measured
    torque NaN during the warm-up) and its rows in the whole campaign."""
    runs, rows = [], []
    for i, (j, k0, k1) in enumerate(windows):
        r = campaign.runs[j]
        off = _run_offset(campaign, j)
        a, b = k0 - off, k1 - off
        t = r.t[a:b]
        tq = None
        if r.torque_measured_nm is not None:
            tq = np.array(r.torque_measured_nm[a:b], float)
            tq[t < t[0] + warmup_s] = np.nan
        pk = r.pack_temperature_measured_c
        runs.append(WindowRun(
            name=window_label(r.name, t[0], t[-1]), t=t, applied_force_n=r.applied_force_n[a:b],
            slip_speed_rad_s=r.slip_speed_rad_s[a:b], sump_temperature_c=r.sump_temperature_c[a:b],
            torque_measured_nm=tq, pack_temperature_measured_c=None if pk is None else pk[a:b],
            start_time_ns=int(r.start_time_ns) + int(round(float(t[0]) * 1e9)), samples={},
            plant_grid=None if r.plant_grid is None else r.plant_grid.window(a, b),
            plant_state0=np.array(states[i], float), source=r.name, warmup_s=warmup_s))
        rows.append(np.arange(k0, k1))
    return Campaign(runs), np.concatenate(rows)


def _run_offset(campaign: Campaign, j: int) -> int:
    return int(sum(len(r) for r in campaign.runs[:j]))


def with_states(sample: Campaign, states: np.ndarray) -> Campaign:
    """The sampled campaign with its windows started from other states (same order)."""
    return Campaign([replace(r, plant_state0=np.array(s, float)) for r, s in zip(sample.runs, states)])


def source_index(sample: Campaign, names: list) -> np.ndarray:
    """Per sample row: the index in ``names`` of the bag its window comes from."""
    return np.concatenate([np.full(len(r), names.index(r.source), np.int64) for r in sample.runs])


def plan_for(budget_s, campaign: Campaign) -> bool:
    """Whether a campaign is sampled under ``budget_s`` (None / 0 / inf: never)."""
    return budget_s is not None and 0 < budget_s < math.inf and campaign_seconds(campaign) > budget_s
