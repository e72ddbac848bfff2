"""Shared fixtures: the example data sets, the stored reference values, a loopback mirror.

The example data are located by :mod:`musclemetab.datasets` alone: ``MUSCLEMETAB_DATA`` when
set (a folder holding one data set's files, or one sub-folder per data set), otherwise the
files are downloaded with pooch on first use. The tests need the real data: they fail, not
skip, when it cannot be had. Every value a test compares against lives in this repository
(``tests/data/``, sources named in its README) or comes from those data sets.
"""

from __future__ import annotations

import contextlib
import functools
import http.server
import os
import shutil
import threading
from pathlib import Path

import pytest

TEST_DATA = Path(__file__).resolve().parent / "data"


@pytest.fixture(scope="session")
def example():
    from musclemetab.datasets import example_subject

    return example_subject()


@pytest.fixture(scope="session")
def gait2392():
    """OpenSim's gait2392 walking example (second subject: other model family, both legs, 60 Hz)."""
    from musclemetab.datasets import gait2392_subject01

    return gait2392_subject01()


@pytest.fixture(scope="session")
def reference_table():
    """Published per-muscle values of the example subject (``tests/data/muscle_properties_reference.csv``)."""
    import pandas as pd

    return pd.read_csv(TEST_DATA / "muscle_properties_reference.csv").set_index("name")


@pytest.fixture(scope="session")
def demo(tmp_path_factory):
    """``musclemetab demo`` run once per test session: ``(output folder, results table)``."""
    import pandas as pd

    from musclemetab.cli import main

    out = tmp_path_factory.mktemp("demo")
    code = main(["demo", "--out", str(out), "--workers", "2", "--no-progress"])
    assert code == 0
    return out, pd.read_csv(out / "results.csv")


@pytest.fixture(scope="session")
def geometry_cache(_isolated_cache) -> Path:
    """The test session's geometry cache (``$MUSCLEMETAB_CACHE/geometry``), shared by every
    test that computes the example subject's geometry: each trial goes through OpenSim once."""
    from musclemetab.geometry import default_cache_dir

    return default_cache_dir()


_PLAIN = (str, int, float, bool, type(None))


def _solve_key(func, args, kwargs) -> str | None:
    """Content key of a solve call: input files by SHA-256, every other argument by value.

    ``cache_dir`` (where the geometry is cached) does not change the result and is left out.
    ``options=None`` and ``settings=None`` count as the defaults they stand for. ``None`` when
    an argument is neither a file, a plain value, a list/tuple/dict of those nor a settings
    dataclass (an in-memory object such as a warm start): such calls always solve.
    """
    import dataclasses
    import hashlib
    import inspect
    import json

    from musclemetab.io.atomic import file_sha256
    from musclemetab.redundancy.emg_ten import EmgTenSettings
    from musclemetab.redundancy.problem import SolverOptions

    def plain(value):
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
        if isinstance(value, (SolverOptions, EmgTenSettings)):
            return {type(value).__name__: plain(dataclasses.asdict(value))}
        raise TypeError(type(value).__name__)

    bound = inspect.signature(func).bind(*args, **kwargs)
    bound.apply_defaults()
    content = {"function": f"{func.__module__}.{func.__qualname__}"}
    for name, value in bound.arguments.items():
        if name == "cache_dir":
            continue
        if name == "options" and value is None:
            value = SolverOptions()
        if name == "settings" and value is None:
            value = EmgTenSettings()
        try:
            content[name] = plain(value)
        except TypeError:
            return None
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()


def _solved_once(solve):
    """``solve`` with its results kept for the test session (see ``_each_problem_solved_once``)."""
    import copy
    import warnings

    results: dict = {}

    @functools.wraps(solve)
    def solve_once(*args, **kwargs):
        key = _solve_key(solve, args, kwargs)
        if key is None:
            return solve(*args, **kwargs)
        if key not in results:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                result = solve(*args, **kwargs)
            results[key] = (result, caught)
        result, caught = results[key]
        for w in caught:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        return copy.deepcopy(result)

    return solve_once


@pytest.fixture(autouse=True, scope="session")
def _each_problem_solved_once():
    """Each muscle redundancy problem is solved once per test session (in this process).

    The command line, the studies run in this process and the tests calling the package
    solve the same example problems many times. :func:`solve_files` and
    :func:`solve_emg_ten` keep their results here, keyed by the input files' content and
    every setting (like the package's own caches); a repeated call gets a copy of the first
    call's result and its warnings again. Calls with other inputs or settings, and calls that
    raise, solve as usual. Worker processes of a study (``--workers 2``, Dask) solve for
    themselves.
    """
    import musclemetab.redundancy as redundancy
    import musclemetab.redundancy.emg_ten as emg_ten
    import musclemetab.redundancy.solve as solve

    solve_files = _solved_once(solve.solve_files)
    solve_emg_ten = _solved_once(emg_ten.solve_emg_ten)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(solve, "solve_files", solve_files)
        mp.setattr(redundancy, "solve_files", solve_files)
        mp.setattr(emg_ten, "solve_emg_ten", solve_emg_ten)
        mp.setattr(redundancy, "solve_emg_ten", solve_emg_ten)
        yield


@contextlib.contextmanager
def loopback_mirror(files: dict, root: Path):
    """Serve ``{path under the server root: local file}`` over HTTP on 127.0.0.1.

    Yields ``(root, base_url)``; the files are copied under ``root`` so a test may alter them.
    """
    for rel, source in files.items():
        target = root / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(source, target)
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(root))
    handler.log_message = lambda *a, **k: None
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield root, f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=5)


@pytest.fixture()
def dataset_mirror(tmp_path):
    """``mirror(dataset, local_folder, commit)``: a loopback server laid out like the source
    repository at ``commit`` (files at ``<commit>/<path in the repository>``); returns
    ``(server root, base URL of the commit)``."""
    import musclemetab.datasets as ds

    with contextlib.ExitStack() as stack:
        def mirror(dataset: str, folder: Path, commit: str):
            files = {f"{commit}/{path}": Path(folder) / name for name, (_, path) in ds.manifest(dataset).items()}
            root, url = stack.enter_context(loopback_mirror(files, tmp_path / "www" / dataset))
            return root, f"{url}{commit}/"

        yield mirror


@pytest.fixture(autouse=True, scope="session")
def _isolated_cache(tmp_path_factory):
    """Keep the geometry cache of a test run out of the user's cache."""
    old = os.environ.get("MUSCLEMETAB_CACHE")
    os.environ["MUSCLEMETAB_CACHE"] = str(tmp_path_factory.mktemp("cache"))
    yield
    if old is None:
        os.environ.pop("MUSCLEMETAB_CACHE", None)
    else:
        os.environ["MUSCLEMETAB_CACHE"] = old
