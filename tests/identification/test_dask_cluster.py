"""Monte Carlo on a real Dask cluster: a `dask scheduler` and two `dask worker` processes started
here as separate processes (not an in-process LocalCluster; the ``cluster`` fixture of
tests/conftest.py), reached by address; the result
equals the serial run bit for bit, through the library and through `clutch-sim montecarlo
--scheduler ADDRESS`."""
import json
import os

import numpy as np

from clutch_model.identification.montecarlo import chunk_indices, run_montecarlo
from clutch_model.virtual_car import identification_data as td
from clutch_sim.cli import main


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
