"""Each muscle redundancy problem of the test run solved once, whatever process asks.

The tests, the command line they call, the studies they run (in the test process, in a
process pool or on a Dask cluster) and the parallel test workers (pytest-xdist) solve the same
example problems many times. :func:`install` wraps :func:`musclemetab.redundancy.run.solve_files`
and :func:`musclemetab.redundancy.emg_run.solve_emg_ten` (the pipeline that the command line, the
studies and Python users call) so that a call is solved once per test run:
its result (and the warnings it gave) is pickled into a folder shared by every process of
the run, under a key made of the input files' content (SHA-256) and every other argument by
value, like the package's own caches. A second call with the same key gets the stored result
and its warnings again; a call that is being solved by another process waits for it (one
lock file per key). A warm start (a :class:`~musclemetab.redundancy.solution.Solution`) counts by
the content of its pickle, as does any other in-memory argument. Calls with arguments that do not
pickle, and calls that raise, solve as
usual and are not stored. Beside each pickle a ``.json`` file says what the key
stands for.
"""

from __future__ import annotations

import contextlib
import dataclasses
import fcntl
import functools
import hashlib
import inspect
import json
import os
import pickle
import warnings
from pathlib import Path

#: environment variable naming the memo folder, for processes the test run starts
MEMO_ENV = "MUSCLEMETAB_TEST_SOLVE_MEMO"

_PLAIN = (str, int, float, bool, type(None))


def solve_key(func, args, kwargs) -> tuple[str, dict] | None:
    """``(key, content)`` of a solve call: input files by SHA-256, every other argument by value.

    ``cache_dir`` (where the geometry is cached) does not change the result and is left out, nor
    does ``exclude_missing_ok`` when no muscle is excluded, nor ``before_solve`` (work started
    beside the solve; a stored result does not call it).
    ``options=None``, ``settings=None`` and ``grf_threshold_N=None`` count as the defaults they
    stand for. A warm-start solution and any other in-memory object (a sample's parameter
    transform, a bound method of its draw) count by the content of their pickle. ``None`` when an
    argument does not pickle (a lambda, a local function): such calls always solve.
    """
    from musclemetab.io.atomic import file_sha256
    from musclemetab.redundancy.emg_ten import EmgTenSettings
    from musclemetab.redundancy.goals import Goals
    from musclemetab.redundancy.ipopt import SolverOptions
    from musclemetab.redundancy.solution import Solution

    from musclemetab.emg import RawEmgPath, processing_record

    def plain(value):
        if isinstance(value, RawEmgPath) and value.is_file():  # raw EMG: its processing is part of the key
            return {"sha256": file_sha256(value), "emg_processing": processing_record(value)}
        if isinstance(value, (str, os.PathLike)) and Path(value).is_file():
            return {"sha256": file_sha256(value)}
        if isinstance(value, os.PathLike):
            return os.fspath(value)
        if isinstance(value, _PLAIN):
            return value
        if isinstance(value, (list, tuple)):
            return [plain(v) for v in value]
        if isinstance(value, dict) and all(isinstance(k, str) for k in value):
            return {k: plain(v) for k, v in value.items()}
        if isinstance(value, (SolverOptions, EmgTenSettings, Goals)):
            return {type(value).__name__: plain(dataclasses.asdict(value))}
        if isinstance(value, Solution):  # a warm start: by the content of its pickle
            return {"Solution": hashlib.sha256(pickle.dumps(value)).hexdigest()}
        try:  # another in-memory object (a sample's parameter transform, its start): by its pickle
            return {type(value).__name__: hashlib.sha256(pickle.dumps(value)).hexdigest()}
        except Exception as exc:  # not picklable (a lambda, a local function): the call solves
            raise TypeError(type(value).__name__) from exc

    bound = inspect.signature(func).bind(*args, **kwargs)
    bound.apply_defaults()
    content = {"function": f"{func.__module__}.{func.__qualname__}"}
    for name, value in bound.arguments.items():
        if name in ("cache_dir", "before_solve") or (name == "exclude_missing_ok"
                                                      and not bound.arguments.get("exclude_muscles")):
            continue  # none changes the result (exclude_missing_ok only says how to treat exclude_muscles)
        if name == "options" and value is None:
            value = SolverOptions()
        if name == "settings" and value is None:
            value = EmgTenSettings()
        if name == "grf_threshold_N" and value is None:  # the command line's "not given": the default
            from musclemetab.events import DEFAULT_GRF_THRESHOLD_N

            value = DEFAULT_GRF_THRESHOLD_N
        try:
            content[name] = plain(value)
        except TypeError:
            return None
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest(), content


@contextlib.contextmanager
def locked(path: Path):
    """Hold an exclusive lock on the file ``path`` (created if missing) across processes."""
    with open(path, "a+") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _memoised(solve, folder: Path):
    """``solve`` with its results kept in ``folder`` for every process of the test run."""
    import copy

    in_process: dict = {}

    @functools.wraps(solve)
    def solve_once(*args, **kwargs):
        keyed = solve_key(solve, args, kwargs)
        if keyed is None:
            return solve(*args, **kwargs)
        key, content = keyed
        if key not in in_process:
            stored = folder / f"{key}.pkl"
            with locked(folder / f"{key}.lock"):
                if stored.is_file():
                    in_process[key] = pickle.loads(stored.read_bytes())
                else:
                    with warnings.catch_warnings(record=True) as caught:
                        warnings.simplefilter("always")
                        result = solve(*args, **kwargs)
                    said = [(str(w.message), w.category, w.filename, w.lineno) for w in caught]
                    in_process[key] = (result, said)
                    tmp = stored.with_suffix(f".tmp{os.getpid()}")
                    tmp.write_bytes(pickle.dumps(in_process[key]))
                    tmp.replace(stored)
                    stored.with_suffix(".json").write_text(json.dumps(content, indent=1, default=str))
        result, said = in_process[key]
        for message, category, filename, lineno in said:
            warnings.warn_explicit(message, category, filename, lineno)
        return copy.deepcopy(result)

    return solve_once


def install(folder: str | os.PathLike) -> callable:
    """Wrap the package's solve functions with the memo in ``folder``; returns the undo."""
    import musclemetab.redundancy as redundancy
    import musclemetab.redundancy.emg_run as emg_run
    import musclemetab.redundancy.run as run

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    os.environ[MEMO_ENV] = str(folder)
    originals = [(run, "solve_files", run.solve_files), (emg_run, "solve_emg_ten", emg_run.solve_emg_ten)]
    for module, name, func in originals:
        wrapped = _memoised(func, folder)
        setattr(module, name, wrapped)
        setattr(redundancy, name, wrapped)

    def undo():
        for module, name, func in originals:
            setattr(module, name, func)
            setattr(redundancy, name, func)

    return undo


@contextlib.contextmanager
def solved_again():
    """Within the block, this process solves every call itself (the memo's stored results are
    neither used nor added to): for a test whose claim is that a solve repeated in another process
    gives the same numbers."""
    import musclemetab.redundancy as redundancy
    import musclemetab.redundancy.emg_run as emg_run
    import musclemetab.redundancy.run as run

    wrapped = [(module, name, getattr(module, name)) for module in (run, emg_run, redundancy)
               for name in ("solve_files", "solve_emg_ten") if hasattr(module, name)]
    for module, name, func in wrapped:
        setattr(module, name, getattr(func, "__wrapped__", func))
    try:
        yield
    finally:
        for module, name, func in wrapped:
            setattr(module, name, func)


def install_in_worker() -> None:
    """In a process the test run started (a study's pool worker, a Dask worker): use the
    run's memo, when the run named one."""
    folder = os.environ.get(MEMO_ENV)
    if folder:
        install(folder)


def start_pool_worker() -> None:
    """Initialiser of the package's pool workers (a study's units, the legs of ``solve --side
    both``) in the tests: the package's own initialiser, then the run's memo."""
    from musclemetab import processes

    processes.ignore_sigint()
    install_in_worker()
