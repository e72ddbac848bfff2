"""Process pools of the package: the study runner's units and the legs of ``solve --side both``.

Workers are started with ``spawn`` (OpenSim and CasADi cannot share a process; each worker
starts its own OpenSim worker process when it needs one), ignore Ctrl-C while idle, and their
BLAS/OpenMP thread pools are sized so that the workers together use the machine's cores.
"""

from __future__ import annotations

import os
import signal
from concurrent.futures import ProcessPoolExecutor

__all__ = ["THREAD_VARIABLES", "pin_threads", "ignore_sigint", "spawn_pool"]

#: environment variables that size the thread pools of BLAS/LAPACK and OpenMP libraries
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


def pin_threads(threads: int):
    """Set the thread variables the caller has not set to ``threads`` (for the worker
    processes, which read them when their libraries load); returns a function that
    restores the environment."""
    added = [v for v in THREAD_VARIABLES if v not in os.environ]
    for v in added:
        os.environ[v] = str(threads)

    def restore():
        for v in added:
            os.environ.pop(v, None)

    return restore


def ignore_sigint() -> None:
    """Pool worker start-up: Ctrl-C is handled by the work running in it, not by the idle worker."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def spawn_pool(workers: int):
    """``(pool, restore)``: a spawn-started pool of ``workers`` processes with pinned thread
    pools, and the function that restores this process's environment after ``pool.shutdown``."""
    import multiprocessing

    restore = pin_threads(max(1, (os.cpu_count() or 1) // workers))
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=ignore_sigint)
    return pool, restore
