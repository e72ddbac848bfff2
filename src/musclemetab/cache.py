"""On-disk cache of what OpenSim computes: muscle geometry, model parameters and the model work
of a solution's OpenSim files (:mod:`musclemetab.redundancy.export`, ``docs/opensim_files.md``).

Entries are ``.npz`` files named by a content key: the SHA-256 of a JSON description of
the request that includes the SHA-256 of every input file (never file names or times),
so an entry is found again whatever the files are called and is never reused after a
file changes. Integrity rules, the same for every kind of entry:

* an entry is written atomically (a reader sees a complete file or none) with a SHA-256
  checksum of its arrays; one that cannot be written is skipped with a :class:`CacheWarning`;
* an entry that cannot be read, fails its checksum or does not fit the request is deleted
  with a :class:`CacheWarning` and computed again;
* a cache folder that cannot be used, or an entry that is a folder or a link, is left alone:
  the result is computed without the cache (with a :class:`CacheWarning`).

Entries a caller receives as a file (inverse dynamics, a ``.sto``) carry their checksum in a
sidecar ``<name>.sha256`` and follow the same rules.

The folder is ``$MUSCLEMETAB_CACHE/geometry`` (default ``~/.cache/musclemetab/geometry``),
or the folder a caller names (``--cache-dir``). The same entries, under the same rules, keep
the solver's differentiated functions in ``$MUSCLEMETAB_CACHE/functions``
(:mod:`musclemetab.redundancy.function_cache`), and the other folders of :data:`CACHE_FOLDERS`
what their modules compute. :func:`cache_usage` counts the entries of each folder and
:func:`clear_cache` deletes them (``musclemetab cache``), touching no other file.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import CacheWarning, OutputError
from .io.atomic import atomic_path

__all__ = ["CACHE_FOLDERS", "cache_root", "cache_folder", "default_cache_dir", "content_key", "entry_path",
           "read_entry", "discard_entry", "write_entry", "read_file_entry", "discard_file_entry", "seal_file_entry",
           "cached_texts", "CacheUsage", "cache_usage", "clear_cache"]

CHECKSUM = "checksum"

#: The folders of the package cache (under :func:`cache_root`) and what each keeps.
CACHE_FOLDERS = {
    "geometry": "muscle-tendon lengths and moment arms, model parameters, the OpenSim files' model work (OpenSim)",
    "functions": "the solver's differentiated functions, per problem structure and package version (CasADi)",
    "inverse_dynamics": "inverse dynamics computed from ground forces (OpenSim)",
    "scale": "scaled models (OpenSim's scale tool)",
    "ik": "inverse kinematics from markers (OpenSim)",
    "figures": "figures that depend only on the package",
}

#: The name of a cache entry: an optional prefix, a content key (:func:`content_key`), a suffix,
#: and ``.sha256`` for the checksum of a file entry. Nothing else in a cache folder is the package's
#: to delete (a temporary file is an entry being written).
_ENTRY_NAME = re.compile(r"(?:[A-Za-z0-9_]+-)?[0-9a-f]{32}\.[A-Za-z0-9]+(?:\.sha256)?")


def cache_root() -> Path:
    """``$MUSCLEMETAB_CACHE``, else ``$XDG_CACHE_HOME/musclemetab`` (default ``~/.cache/musclemetab``)."""
    root = os.environ.get("MUSCLEMETAB_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "musclemetab"
    )
    return Path(root)


def cache_folder(name: str) -> Path:
    """The folder ``name`` of :data:`CACHE_FOLDERS` under :func:`cache_root` (not created)."""
    if name not in CACHE_FOLDERS:
        raise ValueError(f"no cache folder {name!r}; one of {', '.join(CACHE_FOLDERS)}")
    return cache_root() / name


def default_cache_dir() -> Path:
    """The geometry's cache folder: ``$MUSCLEMETAB_CACHE/geometry`` (:func:`cache_folder`)."""
    return cache_folder("geometry")


def content_key(spec: dict) -> str:
    """A 32-hex-digit key of a JSON-serialisable request description."""
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:32]


def _usable_folder(folder: Path, what: str) -> Path | None:
    """``folder`` if it is (or can be made) a writable folder; ``None`` with a warning otherwise."""
    try:
        if folder.exists() and not folder.is_dir():
            raise NotADirectoryError(f"{folder} is a file")
        folder.mkdir(parents=True, exist_ok=True)
        if not os.access(folder, os.W_OK | os.X_OK):
            raise PermissionError("not writable")
    except OSError as exc:
        warnings.warn(f"{what} cache folder {folder} cannot be used ({exc.strerror or exc}); computing without "
                      "the cache (set MUSCLEMETAB_CACHE to a writable folder)", CacheWarning, stacklevel=4)
        return None
    return folder


def entry_path(spec: dict, cache_dir: str | os.PathLike | None, what: str, prefix: str = "",
               suffix: str = ".npz") -> Path | None:
    """Where the entry of ``spec`` lives, or ``None`` when the cache cannot be used (warned)."""
    folder = _usable_folder(Path(cache_dir) if cache_dir else default_cache_dir(), what)
    if folder is None:
        return None
    path = folder / f"{prefix}{content_key(spec)}{suffix}"
    if path.is_dir() or path.is_symlink() or _sidecar(path).is_dir():
        warnings.warn(f"{what} cache entry {path} is a folder or a link, not a file; computing without the "
                      "cache (remove it)", CacheWarning, stacklevel=3)
        return None
    return path


def existing_entry(spec: dict, cache_dir: str | os.PathLike | None, prefix: str = "") -> bool:
    """Whether an entry for ``spec`` exists (no folder is created, nothing is read)."""
    folder = Path(cache_dir) if cache_dir else default_cache_dir()
    return (folder / f"{prefix}{content_key(spec)}.npz").is_file()


def _checksum(arrays: dict) -> str:
    """SHA-256 of the arrays of an entry (names, shapes, types and values)."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        if name == CHECKSUM:
            continue
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def read_entry(path: Path) -> tuple[dict | None, str]:
    """The arrays of an intact entry, or ``(None, reason)`` (``(None, "")`` when there is none)."""
    if not path.is_file():
        return None, ""
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        stored = str(arrays[CHECKSUM])
    except Exception as exc:  # truncated, not an npz, no checksum
        return None, f"cannot be read ({type(exc).__name__})"
    if _checksum(arrays) != stored:
        return None, "does not match its checksum (it was modified or damaged)"
    logging.getLogger(__name__).debug("cache entry used: %s", path)
    return arrays, ""


def discard_entry(path: Path, problem: str, what: str) -> None:
    """Delete an entry that cannot be used, with a warning saying why."""
    warnings.warn(f"{what} cache entry {path} {problem}; deleted, computing it again", CacheWarning, stacklevel=3)
    path.unlink(missing_ok=True)


def write_entry(path: Path, what: str, *, compress: bool = False, **arrays) -> None:
    """Write an entry atomically with its checksum (``compress``: deflated, for arrays that shrink
    several times, such as text); a failure to write is a warning."""
    arrays[CHECKSUM] = np.array(_checksum(arrays))
    try:
        with atomic_path(path, suffix=".npz") as tmp:
            (np.savez_compressed if compress else np.savez)(tmp, **arrays)
        logging.getLogger(__name__).debug("cache entry written: %s", path)
    except OSError as exc:
        warnings.warn(f"could not write the {what} cache entry {path} ({exc.strerror or exc}); "
                      "continuing without caching it", CacheWarning, stacklevel=3)


def _sidecar(path: Path) -> Path:
    return path.with_name(path.name + ".sha256")


def read_file_entry(path: Path) -> str:
    """Check a file entry (a file the cache hands out by path, e.g. an inverse-dynamics ``.sto``)
    against its SHA-256 sidecar ``<name>.sha256``: ``""`` when intact, else why not
    (``"missing"`` when there is no entry)."""
    from .io.atomic import file_sha256

    if not path.is_file():
        return "missing"
    try:
        stored = _sidecar(path).read_text(encoding="ascii").strip()
        actual = file_sha256(path)
    except (OSError, UnicodeDecodeError) as exc:
        return f"has no readable checksum ({type(exc).__name__})"
    if stored != actual:
        return "does not match its checksum (it was modified or damaged)"
    return ""


def discard_file_entry(path: Path, problem: str, what: str) -> None:
    """Delete a file entry and its checksum, with a warning saying why."""
    warnings.warn(f"{what} cache entry {path} {problem}; deleted, computing it again", CacheWarning, stacklevel=3)
    path.unlink(missing_ok=True)
    _sidecar(path).unlink(missing_ok=True)


def seal_file_entry(path: Path, what: str) -> None:
    """Write the SHA-256 sidecar of a complete file entry (atomically); a failure is a warning."""
    from .io.atomic import file_sha256

    try:
        with atomic_path(_sidecar(path), suffix=".sha256") as tmp:
            Path(tmp).write_text(file_sha256(path) + "\n", encoding="ascii")
    except OSError as exc:
        warnings.warn(f"could not write the checksum of the {what} cache entry {path} ({exc.strerror or exc}); "
                      "it will be computed again next time", CacheWarning, stacklevel=3)


def cached_texts(spec: dict, cache_dir: str | os.PathLike, what: str, prefix: str, compute, keys,
                 use_cache: bool = True) -> dict[str, str]:
    """Named texts (a file's text, a JSON record ...) that ``compute()`` returns as a dict, cached
    together as one entry under the key of ``spec``; an entry lacking one of ``keys`` is deleted with
    a :class:`CacheWarning` and computed again, like any entry that fails its checksum."""
    entry = entry_path(spec, cache_dir, what, prefix=prefix) if use_cache else None
    if entry is not None:
        arrays, problem = read_entry(entry)
        if arrays is not None:
            if set(keys) <= set(arrays):
                return {k: str(arrays[k]) for k in keys}
            problem = f"does not hold a {what} result"
        if problem:
            discard_entry(entry, problem, what)
    texts = compute()
    if entry is not None:
        write_entry(entry, what, **{k: np.array(texts[k]) for k in keys})
    return texts


#: bump when a cached model result changes meaning
MODEL_CACHE_FORMAT = 2  # 2: the layout's coordinates carry their default value


def _model_spec(path: Path, target: str) -> dict:
    from .io.atomic import file_sha256

    return {"fmt": MODEL_CACHE_FORMAT, "model": file_sha256(path), "call": target}


def model_call_is_cached(model_path: str | os.PathLike, target: str, cache_dir=None) -> bool:
    """Whether :func:`cached_model_call` would answer from the cache (nothing is created)."""
    try:
        return existing_entry(_model_spec(Path(model_path), target), cache_dir, prefix="model-")
    except OSError:
        return False


def cached_model_call(model_path: str | os.PathLike, target: str, cache_dir=None, use_cache: bool = True, *,
                      compute) -> dict:
    """The result of the OpenSim worker function ``target`` (``"module:function"``) applied to
    the model file alone, ``compute(target, path)`` (the OpenSim bridge's ``call``, given by
    the caller: the cache sits below the bridge), cached by the file's content. The result must
    be JSON data; it is returned in its JSON form (tuples become lists) whether computed now or
    read back."""
    path = Path(model_path)
    entry = entry_path(_model_spec(path, target), cache_dir, "model", prefix="model-") if use_cache else None
    if entry is not None:
        arrays, problem = read_entry(entry)
        if arrays is not None:
            try:
                return json.loads(str(arrays["result"]))
            except (KeyError, ValueError):
                problem = "does not hold a model result"
        if problem:
            discard_entry(entry, problem, "model")
    text = json.dumps(compute(target, str(path)))
    if entry is not None:
        write_entry(entry, "model", result=np.array(text))
    return json.loads(text)


@dataclass(frozen=True)
class CacheUsage:
    """The entries of one folder of the package cache: ``folder`` (its path), ``entries`` (files,
    a file entry's checksum counted with it) and ``size_bytes``."""

    name: str
    folder: Path
    entries: int
    size_bytes: int


def _entries(folder: Path) -> list[Path]:
    """The package's entries in ``folder`` (regular files named as entries; links and other files left out)."""
    if not folder.is_dir() or folder.is_symlink():
        return []
    try:
        return sorted(p for p in folder.iterdir()
                      if _ENTRY_NAME.fullmatch(p.name) and p.is_file() and not p.is_symlink())
    except OSError as exc:
        raise OutputError(f"the cache folder {folder} cannot be read ({exc.strerror or exc}); check its "
                          "permissions") from None


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except FileNotFoundError:  # deleted meanwhile by another process
        return 0


def _usage(name: str, files: list[Path]) -> CacheUsage:
    return CacheUsage(name, cache_folder(name), sum(not p.name.endswith(".sha256") for p in files),
                      sum(_size(p) for p in files))


def cache_usage(names=None) -> list[CacheUsage]:
    """The entries of the cache folders ``names`` (default all of :data:`CACHE_FOLDERS`); nothing is created."""
    return [_usage(n, _entries(cache_folder(n))) for n in (names or CACHE_FOLDERS)]


def clear_cache(names=None) -> list[CacheUsage]:
    """Delete the entries of the cache folders ``names`` (default all); returns what was deleted.

    Only files named as the package names its entries are deleted: a file of another name in a cache
    folder (e.g. when ``$MUSCLEMETAB_CACHE`` names a folder of the user's), links, the folders
    themselves and the temporary files of entries being written stay. A process using an entry
    meanwhile computes it again."""
    removed, kept = [], []
    for n in names or CACHE_FOLDERS:
        gone, sizes = [], {}
        for p in _entries(cache_folder(n)):
            sizes[p] = _size(p)
            try:
                p.unlink(missing_ok=True)
                gone.append(p)
            except OSError as exc:  # the others are deleted all the same: entries stand alone
                kept.append((p, exc))
        usage = CacheUsage(n, cache_folder(n), sum(not p.name.endswith(".sha256") for p in gone),
                           sum(sizes[p] for p in gone))
        logging.getLogger(__name__).debug("cache cleared: %d entries in %s", usage.entries, usage.folder)
        removed.append(usage)
    if kept:
        path, exc = kept[0]
        raise OutputError(f"could not delete {len(kept)} cache file(s), e.g. {path} ({exc.strerror or exc}); the "
                          "other entries are deleted: check the folder's permissions and run it again")
    return removed
