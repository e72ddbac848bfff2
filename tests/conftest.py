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
