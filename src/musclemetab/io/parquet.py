"""Parquet copies of the package's tables, written when the optional ``parquet`` extra is installed.

Every table the package writes is a CSV file (or an OpenSim storage file); a Parquet copy beside
it is a convenience for pandas/Arrow users and needs ``pyarrow``
(``pip install "musclemetab[parquet]"``). Without it the copies are simply not written.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

__all__ = ["parquet_available", "write_parquet"]


def parquet_available() -> bool:
    """Whether pandas can write Parquet here (``pyarrow`` installed)."""
    return importlib.util.find_spec("pyarrow") is not None


def write_parquet(frame, path: str | os.PathLike) -> Path | None:
    """Write ``frame`` to ``path`` as Parquet (no index); ``None`` (and nothing written) without ``pyarrow``."""
    if not parquet_available():
        return None
    frame.to_parquet(path, index=False)
    return Path(path)
