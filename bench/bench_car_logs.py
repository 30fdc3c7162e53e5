"""How visible each hidden cause is on the car-log virtual test car (docs/virtual_car.md).

For every catalog mechanism and effect outside the catalog at its default magnitude, prints
the RMS change of the noise-free sensor torque at the measured torque's stamps against the
no-mechanism twin (same seed, same drive), off lock-up, per schedule and seed; and the
generation time. Usage: python bench/bench_car_logs.py [--seeds 1 2] [--schedules short-runs long-drive]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from clutch_model.virtual_car.car_logs import EFFECTS, CarLogSpec, synthesize_car_logs, truth_sidecar_arrays
from clutch_model.virtual_car.campaign import DEFAULT_MAGNITUDE, MECHANISM_PARAMETER

CASES = ([("mechanism", m, {"id": m, MECHANISM_PARAMETER[m]: v}) for m, v in DEFAULT_MAGNITUDE.items() if v is not None]
         + [("mechanism", "friction_degradation", {"id": "friction_degradation", "energy_scale_j": 2.0e6})]
         + [("effect", e, {"name": e}) for e in EFFECTS])


def sensor_at_stamps(result):
    out = []
    for run in result.runs:
        side = truth_sidecar_arrays(run)
        out.append((side["torque_true_nm"], side["torque_locked"]))
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--schedules", nargs="+", default=["short-runs", "long-drive"])
    a = ap.parse_args()
    print(f"{'case':32s} " + " ".join(f"{s + '/' + str(k):>16s}" for s in a.schedules for k in a.seeds))
    base = {}
    for s in a.schedules:
        for k in a.seeds:
            t0 = time.perf_counter()
            base[s, k] = sensor_at_stamps(synthesize_car_logs(CarLogSpec(seed=k, schedule=s)))
            print(f"  (no-mechanism twin {s} seed {k}: {time.perf_counter() - t0:.1f} s)")
    for kind, name, entry in CASES:
        cells = []
        for s in a.schedules:
            for k in a.seeds:
                spec = CarLogSpec(seed=k, schedule=s, **({"mechanisms": [entry]} if kind == "mechanism" else {"effects": [entry]}))
                got = sensor_at_stamps(synthesize_car_logs(spec))
                d = np.concatenate([(g[0] - b[0])[~(g[1] | b[1])] for g, b in zip(got, base[s, k])])
                cells.append(f"{np.sqrt(np.mean(d ** 2)):13.1f} Nm")
        print(f"{kind[:4]} {name:27s} " + " ".join(cells))


if __name__ == "__main__":
    main()
