"""Scaling curve of `clutch-sim replay` on long 1 kHz car-test campaigns (issue 13).

For each campaign length (default 1, 10 and 60 minutes) this writes a synthetic campaign —
runs of at most 10 minutes, MCAP rosbag2 directories: force, slip and measured torque at
1 kHz (each topic on its own time stamps), sump and pack temperature at 10 Hz, realistic
engagement profiles, the measured torque = RC-1's torque + noise — then runs
`clutch-sim replay` on it as a separate process and prints its wall time, peak memory
(getrusage of that child: ru_maxrss) and cost per simulated second, plus the multiple of real
time, in wall time and in CPU time (user + system, which a loaded machine inflates far less).
Process start-up (imports, numba cache load) is included, as a user sees it. The in-process
split — CPU seconds of each pipeline stage (decode + grid, simulate, CSV), each on its own
thread — is printed for the shortest campaign (``--split``: for every campaign).

Usage: python bench/bench_scaling.py [--minutes 1 10 60] [--run-minutes 10] [--workdir DIR] [--keep]
       [--split] [--diagnose] [--hidden ID:NAME=VALUE] [--seed N]
`--diagnose` also times `clutch-sim diagnose` the same way (hook: the diagnosis' own scaling
work decides its options; see DIAGNOSE_ARGS). Figures are upper bounds on a shared machine:
the load average is printed with them.
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("NUMBA_CACHE_DIR", str(ROOT / ".numba_cache"))
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

RATE_HZ = 1000.0
SLOW_HZ = 10.0
RUN_MAX_S = 600.0
# extra `clutch-sim diagnose` options: the diagnosis decimates 1 kHz logs to its own rate by
# default (--diagnosis-rate auto) and diagnoses campaigns longer than 180 s on a sample of
# windows (--sample-budget-s auto; add "--sample-budget-s", "all" to time the whole campaign);
# progress bars are for terminals, not for this table
DIAGNOSE_ARGS: list = ["--no-progress"]


def load_avg() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "n/a"


def clutch_sim_exe() -> list:
    exe = Path(sys.executable).with_name("clutch-sim")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "clutch_sim.cli"]


def run_inputs(duration_s: float, seed: int):
    """1 kHz engagement profile: force plateaus with ramps, slip swinging 0.5..8 rad/s with
    lock-ups, slowly warming sump."""
    rng = np.random.default_rng(seed)
    n = int(round(duration_s * RATE_HZ))
    t = np.arange(n) / RATE_HZ
    seg = 2.0                                                   # s per force level
    levels = rng.uniform(0.0, 20000.0, int(duration_s / seg) + 2)
    k = (t / seg).astype(np.int64)
    frac = np.clip((t / seg - k) / 0.25, 0.0, 1.0)             # 0.5 s ramp between levels
    force = levels[k] + (levels[k + 1] - levels[k]) * frac + rng.normal(0, 30, n)
    slip = 4.0 + 3.5 * np.sin(2 * np.pi * t / 23.0) + 0.8 * np.sin(2 * np.pi * t / 3.1)
    slip = np.where(np.abs(slip) < 0.3, 0.0, slip) + rng.normal(0, 0.02, n)
    sump = 50.0 + 30.0 * (1 - np.exp(-t / 900.0))
    return t, force, slip, sump


def hidden_model(spec: str | None):
    """RC-1, or RC-1 with one hidden mechanism: ``ID:NAME=VALUE[,NAME=VALUE]``, e.g.
    ``actuator_lag:tau_s=0.03``."""
    from clutch_model.plant.mechanisms import make_mechanism
    from clutch_model.plant.params import load_model

    model = load_model(None)
    if not spec:
        return model
    mech_id, _, values = spec.partition(":")
    kw = {k: float(v) for k, v in (item.split("=", 1) for item in values.split(",") if item)}
    return model.with_mechanisms([make_mechanism(mech_id, **kw)])


def write_campaign(out: Path, minutes: float, seed: int = 0, run_max_s: float = RUN_MAX_S,
                   hidden: str | None = None) -> tuple[list, float]:
    """Write the campaign's bags (runs of at most ``run_max_s``; the true clutch RC-1, or RC-1
    with the ``hidden`` mechanism); returns (bag paths, seconds spent writing)."""
    from clutch_model.formats.bag_writer import RunSignals, TopicSeries, write_run_bag
    from clutch_model.plant.simulate import simulate

    model = hidden_model(hidden)
    total_s = minutes * 60.0
    n_runs = max(1, int(np.ceil(total_s / run_max_s - 1e-9)))
    run_s = total_s / n_runs
    out.mkdir(parents=True, exist_ok=True)
    bags, t_write = [], 0.0
    start_ns = 1_748_851_200_000_000_000
    for j in range(n_runs):
        rng = np.random.default_rng(seed * 1000 + j)
        t, force, slip, sump = run_inputs(run_s, seed * 1000 + j)
        sim = simulate(model, t, force, slip, sump)
        slow = np.arange(0.0, run_s, 1.0 / SLOW_HZ) + 0.0003
        idx = np.minimum((slow * RATE_HZ).astype(np.int64), t.size - 1)
        sig = RunSignals(
            applied_force=TopicSeries(t, force),
            slip_speed=TopicSeries(t + 0.00011, slip),          # own time stamps
            sump_temperature=TopicSeries(slow, sump[idx] + rng.normal(0, 0.3, slow.size), variance=0.09),
            measured_torque=TopicSeries(t + 0.00023, sim.torque_nm + rng.normal(0, 5.0, t.size)),
            pack_temperature=TopicSeries(slow, sim.pack_temperature_c[idx] + rng.normal(0, 0.3, slow.size),
                                         variance=0.09))
        t0 = time.perf_counter()
        bags.append(write_run_bag(out / f"run_{j:02d}", sig, start_time_ns=start_ns))
        t_write += time.perf_counter() - t0
        start_ns += int((run_s + 60.0) * 1e9)
    return bags, t_write


GNU_TIME = Path("/usr/bin/time")


def timed_process(cmd: list, env: dict) -> tuple[float, float, float, int, str]:
    """(wall s, CPU s (user + system), peak RSS MB, exit code, last output line) of one child
    process. CPU time is the figure to read on a loaded machine (wall time waits for the other
    jobs' turns). Peak memory and CPU time from
    /usr/bin/time (the child's own maximum RSS); without it from wait4's ru_maxrss, which can
    also count the pages a forked child shared with this (large) process before its exec."""
    stats = None
    if GNU_TIME.exists():
        fd, stats = tempfile.mkstemp(suffix=".time")
        os.close(fd)
        cmd = [str(GNU_TIME), "-f", "%M %U %S", "-o", stats] + cmd
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    rss_mb = usage.ru_maxrss / 1024.0
    cpu = usage.ru_utime + usage.ru_stime
    if stats is not None:
        try:
            rss_kb, user, system = Path(stats).read_text().split()[-3:]
            rss_mb, cpu = int(rss_kb) / 1024.0, float(user) + float(system)
        finally:
            os.unlink(stats)
    lines = [ln for ln in out.strip().splitlines() if ln.strip()]
    return wall, cpu, rss_mb, proc.returncode, (lines[-1] if lines else "")


def diagnose_stages(out: Path) -> str:
    """The diagnosis' rate and stage times from its report.json."""
    import json

    try:
        rep = json.loads((out / "report.json").read_text())
    except (OSError, ValueError):
        return "(no report.json)"
    rate = rep.get("diagnosis_rate") or {}
    stages = ", ".join(f"{k} {v:.1f}" for k, v in (rep.get("timings_s") or {}).items())
    return (f"diagnosed at {rate.get('rate_hz', float('nan')):.0f} Hz (factor {rate.get('factor', 1)}), "
            f"cause {rep.get('cause', {}).get('id')}; stages [s]: {stages}")


def breakdown(bags, out_csv: Path) -> dict:
    """In-process split of a replay (`replay_bags`, the command's pipeline) in CPU s per stage:
    decode + grid, simulate (+ measured-torque prediction, RMSE sums), CSV (format + write);
    plus the wall and CPU time of the whole (without process start-up)."""
    from clutch_model.plant.params import load_model
    from clutch_model.replay_stream import replay_bags

    model = load_model(None)
    replay_bags(model, [ROOT / "bags" / "run_00"], out_csv)       # kernels loaded
    w0, c0 = time.perf_counter(), time.process_time()
    res = replay_bags(model, bags, out_csv)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    return {"decode_s": res.cpu_s["decode"], "simulate_s": res.cpu_s["simulate"], "csv_s": res.cpu_s["csv"],
            "wall_s": wall, "cpu_s": cpu, "rows": res.rows}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, nargs="+", default=[1.0, 10.0, 60.0])
    ap.add_argument("--workdir", default=None, help="where to write the campaigns (default: a temp dir)")
    ap.add_argument("--run-minutes", type=float, default=RUN_MAX_S / 60.0,
                    help="longest bag of a campaign (default %(default)g min; 60 = one bag per hour)")
    ap.add_argument("--keep", action="store_true", help="keep the campaigns and outputs")
    ap.add_argument("--split", action="store_true", help="in-process stage split for every campaign")
    ap.add_argument("--diagnose", action="store_true", help="also time `clutch-sim diagnose` on each campaign")
    ap.add_argument("--hidden", default=None, metavar="ID:NAME=VALUE",
                    help="a mechanism hidden in the true clutch, e.g. actuator_lag:tau_s=0.03 (default: none)")
    ap.add_argument("--seed", type=int, default=0, help="campaign seed (default %(default)s)")
    args = ap.parse_args(argv)

    work = Path(args.workdir) if args.workdir else Path(tempfile.mkdtemp(prefix="bench_scaling-"))
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    exe = clutch_sim_exe()
    # warm the numba cache so the first row does not pay a compile
    subprocess.run(exe + ["replay", "--bag", str(ROOT / "bags" / "run_00"), "--out", str(work / "warm.csv")],
                   env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
    rows = []
    print(f"clutch-sim replay scaling, 1 kHz campaigns (load avg {load_avg()}, {os.cpu_count()} cores)")
    print(f"{'minutes':>8} {'runs':>5} {'rows':>10} {'write s':>8} {'wall s':>7} {'cpu s':>6} {'x real':>7} "
          f"{'x real cpu':>10} {'ms/sim s':>9} {'peak MB':>8}")
    try:
        for minutes in args.minutes:
            camp = work / f"campaign_{minutes:g}min"
            if camp.exists():
                shutil.rmtree(camp)
            bags, t_write = write_campaign(camp, minutes, seed=args.seed, run_max_s=60.0 * args.run_minutes,
                                           hidden=args.hidden)
            sim_s = minutes * 60.0
            cmd = exe + ["replay", "--bag", *map(str, bags), "--out", str(camp / "replay.csv")]
            wall, cpu, rss, rc, last = timed_process(cmd, env)
            if rc != 0:
                print(f"replay failed on {minutes:g} min: {last}")
                return 1
            n_rows = sum(1 for _ in open(camp / "replay.csv")) - 1
            row = {"minutes": minutes, "runs": len(bags), "rows": n_rows, "write_s": t_write, "replay_s": wall,
                   "replay_cpu_s": cpu, "x_real_time": sim_s / wall, "ms_per_sim_s": 1e3 * wall / sim_s,
                   "peak_mb": rss}
            print(f"{minutes:8g} {len(bags):5d} {n_rows:10d} {t_write:8.1f} {wall:7.2f} {cpu:6.2f} "
                  f"{sim_s / wall:7.0f} {sim_s / cpu:10.0f} {1e3 * wall / sim_s:9.2f} {rss:8.0f}  (load {load_avg()})",
                  flush=True)
            if args.diagnose:
                dcmd = exe + ["diagnose", "--bench", str(ROOT / "bags" / "bench.csv"), "--bags", *map(str, bags),
                              "--out", str(camp / "diagnose")] + DIAGNOSE_ARGS
                dwall, dcpu, drss, drc, dlast = timed_process(dcmd, env)
                row.update({"diagnose_s": dwall, "diagnose_cpu_s": dcpu, "diagnose_peak_mb": drss, "diagnose_rc": drc})
                print(f"{'':8} diagnose: {dwall:.1f} s (cpu {dcpu:.1f} s), {1e3 * dwall / sim_s:.1f} ms per simulated s, "
                      f"peak {drss:.0f} MB" + ("" if drc == 0 else f" (failed: {dlast})") + f"  (load {load_avg()})",
                      flush=True)
                print(f"{'':8} {diagnose_stages(camp / 'diagnose')}", flush=True)
            rows.append(row)
            if args.split or minutes == min(args.minutes):
                b = breakdown(bags, camp / "replay_inproc.csv")
                print(f"{'':8} in-process (no start-up): wall {b['wall_s']:.2f} s, CPU {b['cpu_s']:.2f} s "
                      f"({sim_s / b['wall_s']:.0f}x / {sim_s / b['cpu_s']:.0f}x real time); CPU per stage: "
                      f"decode {b['decode_s']:.2f} s, simulate {b['simulate_s']:.2f} s, CSV {b['csv_s']:.2f} s",
                      flush=True)
            if not args.keep:
                shutil.rmtree(camp, ignore_errors=True)
    finally:
        if not args.keep and not args.workdir:
            shutil.rmtree(work, ignore_errors=True)
    print(f"(load avg after: {load_avg()})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
