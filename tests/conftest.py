"""Shared fixtures: the example subject and the reference documents.

The example data are located through ``MUSCLEMETAB_DATA`` (set by CI to the shared data
folder); without it, a folder ``shared/data/example_subject`` beside the repository is
used; otherwise the files are downloaded (pooch). The tests need the real data: they
fail, not skip, when it cannot be had.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("MUSCLEMETAB_SHARED", REPO.parent / "shared"))

if not os.environ.get("MUSCLEMETAB_DATA") and (SHARED / "data" / "example_subject").is_dir():
    os.environ["MUSCLEMETAB_DATA"] = str(SHARED / "data" / "example_subject")


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
def reference_dir() -> Path:
    """The method's reference tables (published values used as test oracles)."""
    path = SHARED / "reference"
    assert path.is_dir(), f"reference folder {path} not found; set MUSCLEMETAB_SHARED"
    return path


@pytest.fixture(scope="session")
def reference_table(reference_dir):
    import pandas as pd

    return pd.read_csv(reference_dir / "muscle_properties.csv", comment="#").set_index("name")


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
