"""How many threads the linear algebra under numpy and scipy may use: one.

Every dense problem here is small (noise-model regressions of a few dozen columns, the QR
and SVD of a least-squares step with 1 to 13 parameters), and OpenBLAS' threads, started for
each such call, spin while they wait for the next one. Measured on a 2-core machine,
``clutch-sim diagnose`` of one quick campaign (actuator_second_order@lab#2, 4 runs):

    BLAS threads  numba threads   CPU s   wall s
    2 (default)   2 (default)     133     70
    1             2                95     52
    1             1                71     72

The spinning threads took the second core from the plant kernel's parallel batches, so one
BLAS thread is faster as well as cheaper. The numba kernel keeps its threads (a batch of
parameter sets is real parallel work). The command line applies the limit to every command,
and a Dask worker to its jobs (``identification.montecarlo._worker_warmup``), so a fit made
on a cluster equals the serial one to the last bit (BLAS sums in another order with another
thread count).
"""
from __future__ import annotations

BLAS_THREADS = 1


def limit_blas_threads(threads: int = BLAS_THREADS):
    """Limit the BLAS libraries loaded by numpy and scipy to ``threads`` threads, for the
    rest of the process -> the threadpoolctl limiter (``restore_original_limits()`` undoes it)."""
    import numpy  # noqa: F401  (load the BLAS library the limit applies to)
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=int(threads), user_api="blas")
