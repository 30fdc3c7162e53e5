"""Driveline speed against the open-loop plant, measured in one run (ratios are what count).

Prints simulated seconds per wall second for 2 min of car-like inputs at 200 Hz and 1 kHz:
- open loop: clutch_model.simulate (slip an input);
- driveline: clutch_model.simulate_driveline (slip from the two inertias; the same force and
  sump, torques chosen so that the clutch slips, locks and breaks loose);
- driveline stepped: DrivelinePlant.sample + advance(1 ms) from Python, as the node calls it
  (per-tick cost in us, next to Plant's);
- closed loop offline: simulate_driveline with the PI slip controller called every row.
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_CACHE_DIR", str(Path(__file__).resolve().parents[1] / ".numba_cache"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402


def inputs(duration_s, rate_hz, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(0, duration_s, 1 / rate_hz)
    force = np.repeat(rng.uniform(500, 10000, int(duration_s / 2) + 1), int(2 * rate_hz))[: t.size]
    slip = 5 + 3 * np.sin(2 * np.pi * t / 17)
    sump = np.full(t.size, 60.0)
    tau_a = 600 * np.sin(2 * np.pi * t / 5.0) + 200
    tau_b = -100 + 0 * t
    return t, force, slip, sump, tau_a, tau_b


def best(fn, repeat=3):
    out = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out = min(out, time.perf_counter() - t0)
    return out


def main() -> int:
    from clutch_model import DrivelineParams, DrivelinePlant, Plant, load_model, simulate, simulate_driveline
    from clutch_model.closed_loop import PISlipController

    model = load_model()
    dl = DrivelineParams(0.5, 1.2, 0.05, 0.05, 30.0, 10.0)
    t0 = time.perf_counter()
    t, f, w, s, ta, tb = inputs(1.0, 200)
    simulate(model, t, f, w, s)
    simulate_driveline(model, t, f, ta, tb, s, dl)
    print(f"numba first calls (cache load or compile): {time.perf_counter() - t0:.2f} s")

    duration = 120.0
    for rate in (200, 1000):
        t, f, w, s, ta, tb = inputs(duration, rate)
        r = simulate_driveline(model, t, f, ta, tb, s, dl)
        transitions = int(np.count_nonzero(np.diff(r.locked.astype(int))))
        open_wall = best(lambda: simulate(model, t, f, w, s))
        dl_wall = best(lambda: simulate_driveline(model, t, f, ta, tb, s, dl))
        print(f"\n== 2 min at {rate} Hz ({100 * r.locked.mean():.0f} % locked, {transitions} lock/unlock transitions)")
        print(f"  open loop  simulate           : {duration / open_wall:9,.0f} simulated s per wall s")
        print(f"  driveline  simulate_driveline : {duration / dl_wall:9,.0f} simulated s per wall s "
              f"({dl_wall / open_wall:.2f}x the open-loop cost)")

    print("\n== node-style stepping from Python, 1 kHz (sample + advance(1 ms) per tick)")
    n = 20000
    t, f, w, s, ta, tb = inputs(n / 1000.0, 1000)
    plant = Plant(model)
    plant.reset(f[0], 60.0)

    def step_plant():
        for k in range(n):
            plant.sample(f[k], w[k], 60.0)
            plant.advance(0.001)

    dplant = DrivelinePlant(model, dl)
    dplant.reset(f[0], 60.0)

    def step_driveline():
        for k in range(n):
            dplant.sample(f[k], ta[k], tb[k], 60.0)
            dplant.advance(0.001)

    tp = best(step_plant, 2) / n * 1e6
    td = best(step_driveline, 2) / n * 1e6
    print(f"  Plant          : {tp:6.1f} us per tick")
    print(f"  DrivelinePlant : {td:6.1f} us per tick ({td / tp:.2f}x; a 1 kHz tick has 1000 us)")

    print("\n== closed loop offline (PI controller called from Python every row), 2 min at 1 kHz")
    t, f, w, s, ta, tb = inputs(duration, 1000)
    wall = best(lambda: simulate_driveline(model, t, PISlipController(3.0), ta, tb, s, dl), 1)
    print(f"  simulate_driveline + controller: {duration / wall:,.0f} simulated s per wall s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
