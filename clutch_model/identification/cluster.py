"""The Dask client that `montecarlo` and `diagnose` share: a 2-worker LocalCluster on this
machine ("local") or an existing cluster reached by its scheduler's address."""
from __future__ import annotations

import time
from dataclasses import dataclass


@dataclass
class DaskConnection:
    client: object                 # dask.distributed.Client
    cluster: object | None         # the LocalCluster started here (None: an existing cluster)
    label: str                     # "dask LocalCluster (2 workers x 1 thread)" or "dask <address>"
    threads: int | None            # numba threads per task (1 on the LocalCluster; None: the worker's own)
    startup_s: float = 0.0

    def close(self) -> None:
        try:
            self.client.close()
        finally:
            if self.cluster is not None:
                self.cluster.close()


def connect(scheduler: str, warmup=None, min_workers: int | None = None) -> DaskConnection:
    """A client of ``scheduler`` ("local" or an address), its workers waited for (2 on a
    LocalCluster, ``min_workers`` or 1 otherwise) and ``warmup(threads)`` run on each (e.g. to
    load the compiled kernels before the timed work)."""
    from dask.distributed import Client, LocalCluster

    t0 = time.perf_counter()
    cluster = None
    if scheduler == "local":
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                               env={"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})
        client = Client(cluster)
        threads, label = 1, "dask LocalCluster (2 workers x 1 thread)"
    else:
        client = Client(scheduler, timeout="20s")
        threads, label = None, f"dask {scheduler}"
    conn = DaskConnection(client, cluster, label, threads)
    try:
        client.wait_for_workers(2 if cluster is not None else (min_workers or 1), timeout=60)
        if warmup is not None:
            client.run(warmup, threads)
    except BaseException:
        conn.close()
        raise
    conn.startup_s = time.perf_counter() - t0
    return conn
