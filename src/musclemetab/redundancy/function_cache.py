"""A group's symbolic functions, kept between processes in the package cache.

:func:`.transcription.group_functions` differentiates a group's constraints and objective once
per structure: the constraints' Jacobian and the Hessian of the Lagrangian, with common
subexpressions eliminated. On the example's 40 muscles that takes about 0.2 s, the largest part
of what a new process spends on the problem before IPOPT starts. The functions depend on nothing
but the group's structure, the CasADi version and the package's code, so a new process reads
them back, serialised by CasADi, from an entry of the package cache (:mod:`musclemetab.cache`)
keyed by those three: the structure as its ``repr``, the code as the package's version and the
SHA-256 of every module of the package (any change of the package makes new entries; the older
ones stay until ``musclemetab cache --clear``, :func:`musclemetab.cache.clear_cache`). Reading
an entry takes about a fifth of the build and gives the same functions (the same operations in
the same order). The text is stored deflated (0.33 MB for the example's 40 muscles, against
3.0 MB as it is).

The entries live in ``$MUSCLEMETAB_CACHE/functions`` (default ``~/.cache/musclemetab/functions``),
beside the geometry, scaling and IK caches, and follow their rules: written atomically with a
checksum, an entry that cannot be read is deleted with a
:class:`~musclemetab.errors.CacheWarning` and the functions are built again, an unusable folder
means building without the cache. ``docs/solver.md`` ("Start-up of a command").
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path
from typing import Callable

import numpy as np

from ..cache import CHECKSUM, cache_folder, discard_entry, entry_path, read_entry, write_entry

__all__ = ["cached_functions", "code_digest", "functions_cache_dir"]

_WHAT = "symbolic functions"


def functions_cache_dir() -> Path:
    """``$MUSCLEMETAB_CACHE/functions`` (default ``~/.cache/musclemetab/functions``)."""
    return cache_folder("functions")


@functools.lru_cache(maxsize=1)
def code_digest() -> str:
    """SHA-256 of every module of the package (their paths and bytes), once per process."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()


def cached_functions(kind: str, structure, build: Callable[[], dict]) -> dict:
    """The CasADi functions ``build()`` returns (``{name: Function}``) for ``structure``, read from
    the cache when an entry of this ``kind``, ``structure``, CasADi version and package code is
    there, else built and written to it."""
    import casadi as ca

    from .. import __version__

    spec = {"kind": kind, "structure": repr(structure), "casadi": ca.__version__, "musclemetab": __version__,
            "code": code_digest()}
    path = entry_path(spec, functions_cache_dir(), _WHAT, prefix="functions-")
    if path is None:  # the folder cannot be used (warned)
        return build()
    arrays, problem = read_entry(path)
    if arrays is not None:
        try:
            return {name: ca.Function.deserialize(text.tobytes().decode("ascii"))
                    for name, text in arrays.items() if name != CHECKSUM}
        except (RuntimeError, UnicodeDecodeError) as exc:
            problem = f"cannot be read by CasADi ({type(exc).__name__})"
    if problem:
        discard_entry(path, problem, _WHAT)
    functions = build()
    write_entry(path, _WHAT, compress=True, **{name: np.frombuffer(f.serialize().encode("ascii"), dtype=np.uint8)
                                               for name, f in functions.items()})
    return functions
