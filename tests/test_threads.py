"""The BLAS libraries under numpy and scipy run one thread under clutch-sim (clutch_model/threads.py).

Checked in a fresh interpreter without the thread-count variables `make test` sets, so the
libraries start with their own default (one thread per core)."""
from __future__ import annotations

import json
import os
import subprocess
import sys

PROBE = r"""
import json
from threadpoolctl import threadpool_info
import numpy, scipy.linalg
def blas():
    return sorted(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")
before = blas()
from clutch_model.threads import limit_blas_threads
limiter = limit_blas_threads()
during = blas()
limiter.restore_original_limits()
print(json.dumps({"before": before, "during": during, "after": blas()}))
"""


def test_blas_runs_one_thread_and_the_limit_can_be_undone():
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["before"], "numpy/scipy loaded no BLAS library threadpoolctl knows"
    assert got["during"] == [1] * len(got["before"])
    assert got["after"] == got["before"]
