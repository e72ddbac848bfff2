"""On-disk cache of what OpenSim computes: muscle geometry and model parameters.

Entries are ``.npz`` files named by a content key: the SHA-256 of a JSON description of
the request that includes the SHA-256 of every input file (never file names or times),
so an entry is found again whatever the files are called and is never reused after a
file changes. Entries are written atomically (a reader sees a complete file or none);
an entry that cannot be read is deleted and recomputed.

The folder is ``$MUSCLEMETAB_CACHE/geometry`` (default ``~/.cache/musclemetab/geometry``),
or the folder a caller names (``--cache-dir``).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from .io.atomic import atomic_path

__all__ = ["default_cache_dir", "content_key", "cache_file", "load_entry", "save_entry"]


def default_cache_dir() -> Path:
    """``$MUSCLEMETAB_CACHE`` or ``~/.cache/musclemetab``, plus ``/geometry``."""
    root = os.environ.get("MUSCLEMETAB_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "musclemetab"
    )
    return Path(root) / "geometry"


def content_key(spec: dict) -> str:
    """A 32-hex-digit key of a JSON-serialisable request description."""
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:32]


def cache_file(spec: dict, cache_dir: str | os.PathLike | None = None, prefix: str = "") -> Path:
    """Path of the entry for ``spec`` in ``cache_dir`` (default :func:`default_cache_dir`)."""
    folder = Path(cache_dir) if cache_dir else default_cache_dir()
    return folder / f"{prefix}{content_key(spec)}.npz"


def load_entry(path: Path, required: tuple[str, ...] = ()) -> dict[str, np.ndarray] | None:
    """The arrays of a cache entry, or ``None`` when there is none.

    An entry that cannot be read or lacks one of the ``required`` arrays is deleted.
    """
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            entry = {k: z[k] for k in z.files}
        if all(k in entry for k in required):
            return entry
    except Exception:
        pass
    path.unlink(missing_ok=True)  # unreadable entry: the caller recomputes it
    return None


def save_entry(path: Path, **arrays) -> None:
    """Write a cache entry atomically (no pickled objects: arrays and strings only)."""
    with atomic_path(path, suffix=".npz") as tmp:
        np.savez(tmp, **arrays)
