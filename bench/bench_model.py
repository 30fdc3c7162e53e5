"""Plant speed, measured in one run (ratios are what count: this machine is noisy).

Prints: numba cold start (compile or cache load); single-trajectory simulation speed as a
multiple of real time at 200 Hz and 1 kHz input rates, and as a ratio to scipy solve_ivp
(Radau, rtol 1e-6, same jitted equations, restarted at every input sample as the zero-order
hold requires) on the same trajectory; a whole `replay` (bag decoding + simulation + CSV) as
a multiple of real time; batch throughput in simulated seconds per wall second for 1, 100 and
10,000 parameter sets. Targets (issue 2): simulation >= 1,000x real time and >= 300x solve_ivp;
replay >= 100x; batch >= 5,000 simulated s per wall s.
"""
from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path


import numpy as np  # noqa: E402


def car_inputs(duration_s, rate_hz, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(0, duration_s, 1 / rate_hz)
    steps = np.repeat(rng.uniform(500, 10000, int(duration_s / 2) + 1), 2 * rate_hz)[: t.size]
    force = steps + rng.normal(0, 20, t.size)
    slip = 5 + 3 * np.sin(2 * np.pi * t / 17) + rng.normal(0, 0.05, t.size)
    sump = 60 + 0.1 * t / duration_s + rng.normal(0, 0.3, t.size)
    return t, force, slip, sump


def timeit(fn, repeat=3):
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> int:
    t0 = time.perf_counter()
    from clutch_model.plant import kernels as K
    from clutch_model import load_model, simulate, simulate_batch
    import_s = time.perf_counter() - t0
    model = load_model()
    p = model.vector()
    t, f, w, s = car_inputs(1.0, 200)
    t0 = time.perf_counter()
    simulate(model, t, f, w, s)
    simulate_batch([model], t, f, w, s)
    cold = time.perf_counter() - t0
    print(f"numba: import {import_s:.2f} s, first calls (cache load or compile) {cold:.2f} s")

    print("\n== single trajectory (2 min of car data)")
    for rate in (200, 1000):
        t, f, w, s = car_inputs(120.0, rate)
        wall = timeit(lambda: simulate(model, t, f, w, s))
        print(f"  {rate:5d} Hz: {wall * 1e3:7.1f} ms -> {120.0 / wall:8.0f}x real time, "
              f"{wall / t.size * 1e9:6.0f} ns per step")

    # solve_ivp on the same jitted equations (10 s at 200 Hz; both timed on it)
    from scipy.integrate import solve_ivp
    d = K.derived_constants(p)
    t, f, w, s = car_inputs(10.0, 200)
    state = np.zeros(K.N_STATE)
    rec = np.zeros(K.N_OUT)

    def rhs(_t, y, fk, wk, sk):
        state[K.S_H], state[K.S_THETA], state[K.S_FPACK], state[K.S_ENERGY] = y[0], y[1], fk, 0.0
        torque = K.outputs(state, wk, sk, p, d, rec)
        dh, _ = K.film_rate(y[0], min(fk, d[K.D_FMAX]), K.viscosity(y[1], p), p, d)
        fkn = min(fk, d[K.D_FMAX]) * 1e-3
        htf = max(p[K.P.B1] + p[K.P.B2] * abs(wk) + p[K.P.B3] * fkn + p[K.P.B4] * abs(wk) * fkn, p[K.P.HTF_MIN])
        q = abs(wk * torque)
        return [dh, (q / p[K.P.N_SEPARATOR] - htf * d[K.D_AN] * (y[1] - sk)) / p[K.P.PLATE_HEAT_CAPACITY], q]

    def run_ivp():
        y = np.array([p[K.P.H0], s[0], 0.0])
        for k in range(t.size - 1):
            sol = solve_ivp(rhs, (t[k], t[k + 1]), y, method="Radau", rtol=1e-6, atol=[1e-13, 1e-6, 1e-3],
                            args=(max(f[k], 0.0), w[k], s[k]))
            y = sol.y[:, -1]
        return y

    ivp = timeit(run_ivp, repeat=1)
    ours = timeit(lambda: simulate(model, t, f, w, s))
    print(f"  solve_ivp(Radau) on 10 s at 200 Hz: {ivp:.2f} s; clutch_model: {ours * 1e3:.2f} ms "
          f"-> {ivp / ours:,.0f}x faster than solve_ivp")

    print("\n== whole replay (bag decoding + simulation + CSV), 2 min at 200 Hz")
    from clutch_model.formats.bag_writer import write_run_bag
    from clutch_model.replay import replay_runs, write_replay_csv
    from clutch_model.formats.bag_reader import read_bags
    t, f, w, s = car_inputs(120.0, 200)
    torque = simulate(model, t, f, w, s).torque_nm
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "bench_run"
        write_run_bag(bag, {"applied_force": (t, f), "slip_speed": (t, w),
                            "sump_temperature": (t[::20], s[::20]), "measured_torque": (t, torque)})

        def replay():
            runs = read_bags([bag])
            write_replay_csv(replay_runs(model, runs), Path(tmp) / "out.csv")

        wall = timeit(replay, repeat=2)
        t_read = timeit(lambda: read_bags([bag]), repeat=2)
    print(f"  replay {wall:.2f} s -> {120.0 / wall:.0f}x real time (bag decoding {t_read:.2f} s of it)")

    print("\n== batch (10 s of 200 Hz car data per parameter set)")
    t, f, w, s = car_inputs(10.0, 200)
    rng = np.random.default_rng(1)
    for n_sets in (1, 100, 10_000):
        a = model.friction_coefficients * (1 + 0.05 * rng.uniform(-1, 1, (n_sets, 20)))
        pm = np.repeat(p[None, :], n_sets, axis=0)
        pm[:, K.P.FRICTION_A:K.P.FRICTION_A + 20] = a
        simulate_batch(pm[:2], t, f, w, s)
        wall = timeit(lambda: simulate_batch(pm, t, f, w, s), repeat=1 if n_sets > 1000 else 3)
        print(f"  {n_sets:6d} sets: {wall:7.3f} s -> {n_sets * 10.0 / wall:10,.0f} simulated s per wall s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
