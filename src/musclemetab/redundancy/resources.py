"""What a problem costs the machine: its size and memory (refused before building beyond
:data:`MAX_PROBLEM_MEMORY_MB`), and the process settings of a solve (glibc's allocator
threshold, OpenBLAS' threads)."""

from __future__ import annotations

import ctypes
import ctypes.util

from ..errors import OptionError

__all__ = ["problem_size", "problem_memory_mb", "check_problem_memory", "MAX_PROBLEM_MEMORY_MB", "tune_malloc",
           "set_blas_threads"]


def problem_size(n_muscles: int, n_dofs: int, n_intervals: int) -> tuple[int, int]:
    """Number of variables and equality constraints (``205 N + 120`` and ``165 N + 40`` for 40/5)."""
    M, D, N = n_muscles, n_dofs, n_intervals
    return (5 * M + D) * N + 3 * M, (4 * M + D) * N + M


#: Memory of a problem, measured on the example trial (40 muscles, 5 DOFs): 73 MB, plus 0.47 MB
#: per mesh interval (the peak resident memory of ``musclemetab solve`` was 202 MB with N = 118
#: and 312 MB with N = 354), scaled by the variables per interval for other sizes.
PROBLEM_BASE_MB = 73.0
PROBLEM_MB_PER_INTERVAL = 0.47
#: Largest problem built (estimated memory, MB): beyond it the mesh is refused before building
#: (e.g. a 30 s trial at 1000 intervals per second would need about 14 GB)
MAX_PROBLEM_MEMORY_MB = 8000.0


def problem_memory_mb(sizes) -> float:
    """Estimated memory (MB) of a problem over trials of ``sizes`` = ``[(muscles, DOFs, intervals), ...]``."""
    per_interval = sum(n * (5 * m + d) / 205.0 for m, d, n in sizes)
    return PROBLEM_BASE_MB + PROBLEM_MB_PER_INTERVAL * per_interval


def check_problem_memory(sizes) -> None:
    """Raise :class:`OptionError` when the problem of ``sizes`` (see :func:`problem_memory_mb`)
    would need more than :data:`MAX_PROBLEM_MEMORY_MB`, naming the estimate and the remedy."""
    mb = problem_memory_mb(sizes)
    if mb > MAX_PROBLEM_MEMORY_MB:
        n = sum(s[2] for s in sizes)
        raise OptionError(f"the problem would have {n} mesh intervals and need about {mb:.0f} MB of memory, more "
                          f"than the limit of {MAX_PROBLEM_MEMORY_MB:.0f} MB; solve a shorter window (--window, "
                          "--cycle) or a coarser mesh (--mesh-frequency, the study's is 100 per second)")


_MALLOC_TUNED = False


def tune_malloc(threshold_bytes: int = 512 * 1024 * 1024) -> bool:
    """Raise glibc's mmap/trim thresholds so freed work arrays are reused, not unmapped.

    Equivalent to ``MALLOC_MMAP_THRESHOLD_``/``MALLOC_TRIM_THRESHOLD_``/``MALLOC_TOP_PAD_``
    in the environment, set at run time with ``mallopt``. Returns ``False`` (and does
    nothing) where glibc is not available.
    """
    global _MALLOC_TUNED
    if _MALLOC_TUNED:
        return True
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD = -1, -2, -3
    ok = bool(mallopt(M_MMAP_THRESHOLD, min(threshold_bytes, 2**31 - 1)))
    ok &= bool(mallopt(M_TRIM_THRESHOLD, min(2 * threshold_bytes, 2**31 - 1)))
    ok &= bool(mallopt(M_TOP_PAD, 64 * 1024 * 1024))
    _MALLOC_TUNED = ok
    return ok


def set_blas_threads(n: int) -> bool:
    """Set the thread count of CasADi's bundled OpenBLAS (used by MUMPS).

    Acts on the library instance already loaded by the IPOPT plugin (found by its soname);
    returns ``False`` when it is not loaded or has no such function.
    """
    import os

    try:
        lib = ctypes.CDLL("libcasadi-tp-openblas.so.0", mode=getattr(os, "RTLD_NOLOAD", 4) | os.RTLD_LOCAL)
        lib.openblas_set_num_threads(int(n))
    except (OSError, AttributeError):
        return False
    return True
