"""Process pools of the package (the study runner's units and the legs of ``solve --side both``)
and a call in a background thread (:class:`BackgroundCall`).

Workers are started with ``spawn`` (OpenSim and CasADi cannot share a process; each worker
starts its own OpenSim worker process when it needs one), ignore Ctrl-C while idle, and their
BLAS/OpenMP thread pools are sized so that the workers together use the machine's cores.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from concurrent.futures import ProcessPoolExecutor

__all__ = ["THREAD_VARIABLES", "pin_threads", "ignore_sigint", "spawn_pool", "stop_pool", "call_recording_warnings",
           "warn_again", "sigint_deferred", "sigint_noted", "interrupt_noted", "sigterm_as_sigint", "terminated",
           "BackgroundCall"]

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
    """Pool worker start-up: Ctrl-C is handled by the work running in it, not by the idle worker;
    warnings are printed as one line each (:func:`musclemetab.messages.install`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from .messages import install

    install()


class _Pool(ProcessPoolExecutor):
    """A process pool whose workers start with Ctrl-C ignored: a worker is started (by
    ``submit``) while this process ignores SIGINT, a setting the new process inherits, so that a
    Ctrl-C during a worker's start-up (before its initialiser runs) prints no traceback from it."""

    def submit(self, *args, **kwargs):
        if threading.current_thread() is not threading.main_thread():
            return super().submit(*args, **kwargs)
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            return super().submit(*args, **kwargs)
        finally:
            signal.signal(signal.SIGINT, previous)


def spawn_pool(workers: int):
    """``(pool, restore)``: a spawn-started pool of ``workers`` processes with pinned thread
    pools, and the function that restores this process's environment after ``pool.shutdown``."""
    import multiprocessing

    restore = pin_threads(max(1, (os.cpu_count() or 1) // workers))
    pool = _Pool(max_workers=workers, mp_context=multiprocessing.get_context("spawn"), initializer=ignore_sigint)
    return pool, restore


def stop_pool(pool) -> None:
    """Stop a pool at once (after Ctrl-C in this process): its queued work is cancelled and its
    worker processes, which ignore Ctrl-C, are terminated rather than waited for."""
    for proc in list((getattr(pool, "_processes", None) or {}).values()):  # CPython's map of the workers
        if proc.is_alive():
            proc.terminate()
    pool.shutdown(wait=True, cancel_futures=True)


def call_recording_warnings(fn, *args, **kwargs) -> tuple[object, list[tuple[type, str]]]:
    """``(fn(*args, **kwargs), [(category, message), ...])``: in a pool worker (or on a Dask
    worker), the result and every warning the call raised, instead of printing them there, for
    the process that waits for the result to raise again (:func:`warn_again`). There, where the
    user looks (a terminal, a notebook), each is said once per run, however many workers met it,
    and under that process's warning filters."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = fn(*args, **kwargs)
    return result, [(w.category, str(w.message)) for w in caught]


def warn_again(caught, stacklevel: int = 1) -> None:
    """Raise the warnings :func:`call_recording_warnings` recorded in another process, in order,
    as if raised ``stacklevel`` frames up from the caller (1: the caller's line)."""
    import warnings

    for category, message in caught:
        warnings.warn(message, category, stacklevel=stacklevel + 1)


#: Set when a :func:`sigint_noted` block saw Ctrl-C that was not raised yet (an interrupt that
#: Python code or a library swallowed, e.g. one that ran through an import guarded by
#: ``except ImportError``); cleared when it is raised.
_NOTED = threading.Event()


def interrupt_noted() -> bool:
    """Whether a :func:`sigint_noted` block has seen Ctrl-C that is still to be raised (the block
    raises it when the native code returns): a callback of that code may stop it quietly."""
    return _NOTED.is_set()


def _raise_noted() -> None:
    """Raise :class:`KeyboardInterrupt` for a Ctrl-C noted earlier and not raised (swallowed)."""
    if _NOTED.is_set():
        _NOTED.clear()
        raise KeyboardInterrupt


@contextlib.contextmanager
def sigint_deferred():
    """Hold Ctrl-C (SIGINT) back while the block runs (e.g. the files of several output folders
    moved into place) and raise :class:`KeyboardInterrupt` after it, so that an interrupt leaves
    either the previous outputs or all the new ones. A Ctrl-C noted by an enclosing
    :func:`sigint_noted` block and swallowed on its way is raised before the block (nothing is
    written). Outside the main thread it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _raise_noted()
    caught = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught and previous is not signal.SIG_IGN:
        raise KeyboardInterrupt


class _InterruptLinesDropped:
    """Standard error while :func:`sigint_noted` runs native code: the line CasADi writes for
    the interrupt it caught in a callback (``CasADi - <time> WARNING("KeyboardInterruptException")
    [...]``) is dropped, so that Ctrl-C ends a command with its own one line
    (``musclemetab: interrupted``); every other line passes."""

    def __init__(self, stream):
        self._stream, self._line = stream, ""

    def write(self, text):  # CasADi writes its line in pieces: each line is held until it is whole
        self._line += text
        *lines, self._line = self._line.split("\n")
        for line in lines:
            if "KeyboardInterruptException" not in line:
                self._stream.write(line + "\n")
        return len(text)

    def flush(self):
        if self._line and not self._line.startswith("CasADi"):  # a partial line of another writer
            self._stream.write(self._line)
            self._line = ""
        self._stream.flush()

    def close_block(self):
        """What is held when the block ends, written unless it is the interrupt's line."""
        line, self._line = self._line, ""
        if line and "KeyboardInterruptException" not in line:
            try:
                self._stream.write(line)
            except (OSError, ValueError):  # a closed or full stream loses the line (messages.write_quietly)
                pass

    def __getattr__(self, name):
        return getattr(self._stream, name)


@contextlib.contextmanager
def sigint_noted():
    """Run native code that stops itself on Ctrl-C (IPOPT through CasADi, which then returns a
    failure status instead of raising) and raise :class:`KeyboardInterrupt` after it when
    Ctrl-C came, so that the interrupt is not taken for a failed solve. The handler in place
    (Python's default, or a study unit's) is still called when the signal comes. A Ctrl-C
    noted by an enclosing block and swallowed on its way is raised on entry. Outside the
    main thread, or with Ctrl-C ignored (an idle pool worker), it does nothing."""
    previous = signal.getsignal(signal.SIGINT) if threading.current_thread() is threading.main_thread() else None
    if not callable(previous):
        yield
        return
    _raise_noted()
    caught = []

    def note(signum, frame):
        caught.append(signum)
        _NOTED.set()
        previous(signum, frame)

    signal.signal(signal.SIGINT, note)
    import sys

    stderr = sys.stderr
    filtered = sys.stderr = _InterruptLinesDropped(stderr) if stderr is not None else None
    try:
        yield
    finally:
        sys.stderr = stderr
        if filtered is not None:
            filtered.close_block()
        signal.signal(signal.SIGINT, previous)
        if caught:
            _NOTED.clear()  # raised below, or already on its way out of the block
    if caught:
        raise KeyboardInterrupt


#: Set when SIGTERM came while a :func:`sigterm_as_sigint` block ran.
_TERMINATED = threading.Event()


def terminated() -> bool:
    """Whether the interrupt being handled came from SIGTERM (a batch scheduler stopping the
    job, ``kill PID``) rather than Ctrl-C."""
    return _TERMINATED.is_set()


@contextlib.contextmanager
def sigterm_as_sigint():
    """While the block runs, SIGTERM is handled as Ctrl-C: the SIGINT handler in place is called
    (a study unit's, :func:`sigint_noted`'s, Python's default raising
    :class:`KeyboardInterrupt`), so that the work stops the way Ctrl-C stops it: the pool's
    workers interrupted and ended, the running units marked interrupted, nothing half-written.
    :func:`terminated` then says the stop came from SIGTERM (the command line's status is 143,
    128 + SIGTERM, instead of 130). With SIGINT ignored (a process started in the background
    of a shell script inherits that), SIGTERM raises :class:`KeyboardInterrupt` all the same.
    Outside the main thread it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def on_sigterm(signum, frame):
        _TERMINATED.set()
        handler = signal.getsignal(signal.SIGINT)
        if callable(handler):
            handler(signal.SIGINT, frame)
        else:
            raise KeyboardInterrupt

    _TERMINATED.clear()
    previous = signal.signal(signal.SIGTERM, on_sigterm)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


class BackgroundCall:
    """Run ``func(*args)`` in a daemon thread of this process (e.g. a request to the OpenSim
    worker while the caller reads its files); :meth:`result` waits for it and re-raises its
    error in the caller's thread."""

    def __init__(self, func, *args):
        self._value = self._error = None
        self._thread = threading.Thread(target=self._run, args=(func, args), daemon=True)
        self._thread.start()

    def _run(self, func, args):
        try:
            self._value = func(*args)
        except BaseException as exc:  # re-raised in the caller's thread
            self._error = exc

    def result(self):
        """The value of ``func(*args)``, once it has returned (its exception, if it raised)."""
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._value
