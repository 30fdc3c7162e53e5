"""Monte Carlo on a real Dask cluster: a `dask scheduler` and two `dask worker` processes started
here as separate processes (not an in-process LocalCluster), reached by address; the result
equals the serial run bit for bit, through the library and through `clutch-sim montecarlo
--scheduler ADDRESS`."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from clutch_model.identification.montecarlo import chunk_indices, run_montecarlo
from clutch_model.virtual_car import identification_data as td
from clutch_sim.cli import main

ROOT = Path(__file__).resolve().parents[2]
DASK = Path(sys.executable).with_name("dask")


def _start(cmd, env, log):
    # own process group: teardown signals the group (the worker's nanny and its worker process)
    return subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)


def _stop(proc):
    if proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=20)
    except (ProcessLookupError, subprocess.TimeoutExpired):
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait(timeout=10)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """(scheduler address, client) of a scheduler + 2 single-thread workers in separate processes."""
    if not DASK.exists():
        pytest.skip(f"no dask executable beside {sys.executable}")
    from dask.distributed import Client

    d = tmp_path_factory.mktemp("dask")
    sfile = d / "scheduler.json"
    env = dict(os.environ)
    # the workers import clutch_model from this checkout; one numba thread each (1 core per worker)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    env.update(NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1")
    procs, logs = [], []
    client = None
    try:
        logs.append(open(d / "scheduler.log", "w"))
        procs.append(_start([str(DASK), "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                             "--scheduler-file", str(sfile)], env, logs[-1]))
        deadline = time.monotonic() + 120
        while not sfile.exists() or not sfile.read_text().strip():
            if procs[0].poll() is not None or time.monotonic() > deadline:
                pytest.fail("dask scheduler did not start: " + (d / "scheduler.log").read_text()[-2000:])
            time.sleep(0.2)
        time.sleep(0.2)                                   # the file is written in one go; be safe
        address = json.loads(sfile.read_text())["address"]
        for k in range(2):
            logs.append(open(d / f"worker{k}.log", "w"))
            procs.append(_start([str(DASK), "worker", "--scheduler-file", str(sfile), "--nthreads", "1",
                                 "--nworkers", "1", "--no-dashboard", "--name", f"w{k}",
                                 "--local-directory", str(d / f"w{k}")], env, logs[-1]))
        client = Client(address, timeout="60s")
        client.wait_for_workers(2, timeout=180)
        yield address, client
    finally:
        if client is not None:
            client.close()
        for p in reversed(procs):
            _stop(p)
        for f in logs:
            f.close()


def test_workers_are_separate_processes(cluster):
    _, client = cluster
    pids = client.run(os.getpid)
    assert len(pids) == 2 and len(set(pids.values())) == 2 and os.getpid() not in pids.values()
    import clutch_model

    where = client.run(lambda: __import__("clutch_model").__file__)
    assert set(where.values()) == {clutch_model.__file__}     # this checkout's code on the workers


def test_montecarlo_on_cluster_equals_serial(cluster, rc1, car_runs):
    address, client = cluster
    runs = car_runs[0][:2]
    kw = dict(n_samples=160, spread=0.2, seed=13, chunk_size=24, progress=False, halving=(3,))
    serial = run_montecarlo(rc1, runs, **kw)
    before = sum(len(v) for v in client.run(lambda dask_worker: list(dask_worker.state.log)).values())
    remote = run_montecarlo(rc1, runs, scheduler=address, **kw)
    assert len(chunk_indices(serial.accepted, 24)) >= 4            # enough chunks for both workers
    assert (~serial.accepted).any()
    assert np.array_equal(serial.samples, remote.samples)
    assert np.array_equal(serial.accepted, remote.accepted)
    assert np.array_equal(serial.rmse, remote.rmse, equal_nan=True)
    assert np.array_equal(serial.refined_a, remote.refined_a)
    assert remote.scheduler == f"dask {address}"
    after = {w: len(v) for w, v in client.run(lambda dask_worker: list(dask_worker.state.log)).items()}
    assert sum(after.values()) > before and all(n > 0 for n in after.values())   # both workers worked


def test_montecarlo_cli_scheduler_address(cluster, rc1, truth, tmp_path, capsys):
    address, _ = cluster
    runs = td.synthetic_runs(truth, n_runs=2, duration_s=4.0, noise_nm=15.0, seed=23)
    bags = [str(p) for p in td.write_runs_as_bags(runs, tmp_path / "bags")]
    args = ["montecarlo", "--bags", *bags, "--samples", "96", "--spread", "0.05", "--seed", "3",
            "--chunk-size", "16", "--halving", "a3", "--no-plots"]
    assert main(args + ["--out", str(tmp_path / "serial")]) == 0
    assert main(args + ["--out", str(tmp_path / "dask"), "--scheduler", address]) == 0
    capsys.readouterr()
    s, d = np.load(tmp_path / "serial" / "samples.npz"), np.load(tmp_path / "dask" / "samples.npz")
    for key in ("samples", "rmse", "accepted", "refined"):
        assert np.array_equal(s[key], d[key], equal_nan=key == "rmse"), key
    from clutch_model.plant.params import load_model

    assert np.array_equal(load_model(tmp_path / "serial" / "refined_model.yaml").friction_coefficients,
                          load_model(tmp_path / "dask" / "refined_model.yaml").friction_coefficients)
    assert json.loads((tmp_path / "dask" / "summary.json").read_text())["scheduler"] == f"dask {address}"
