"""Shared pytest setup (numba's cache directory is chosen by clutch_model._numba_cache)."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
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


@pytest.fixture(scope="session")
def cluster(tmp_path_factory):
    """(scheduler address, client) of a `dask scheduler` + 2 single-thread `dask worker`s started
    as separate processes (shared by the Monte Carlo and diagnose cluster tests)."""
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


