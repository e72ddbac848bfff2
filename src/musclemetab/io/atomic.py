"""Atomic file output: write to a temporary file beside the target, then rename.

A reader (or a resumed study) therefore never sees a half-written file: either the old
file, or the complete new one.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["file_sha256", "atomic_write_text", "atomic_write_bytes", "atomic_path", "atomic_directory",
           "check_output_folder", "check_inside"]


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a file's content, as a hexadecimal string."""
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(
        prefix=f".{path.name}.", suffix=suffix if suffix is not None else ".tmp", dir=path.parent
    )
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        if tmp_path.exists():
            os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp makes 0600; give a normal file's mode
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary directory; on success, its files are moved into ``path``.

    Use it when one step writes several files that belong together: if the step fails
    none of them appears in ``path``. Files already in ``path`` and not rewritten stay.
    """
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".partial-", dir=path))
    try:
        yield tmp
        for item in sorted(tmp.iterdir()):
            target = path / item.name
            if target.is_dir() and not item.is_dir():
                shutil.rmtree(target)
            os.replace(item, target)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def check_output_folder(path: str | os.PathLike, option: str = "--out") -> Path:
    """Check, before any work, that ``path`` is or can become a writable folder.

    Raises :class:`~musclemetab.errors.OptionError` naming ``option`` when ``path`` is an
    existing file, lies below a file, or cannot be created or written to. The check
    creates nothing that stays: folders it had to create to try are removed again.
    """
    from ..errors import OptionError

    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OptionError(f"{option} {path} is an existing file, not a folder; give the path of a folder")
    created = []
    try:
        missing = []
        p = path.absolute()
        while not p.exists():
            missing.append(p)
            p = p.parent
        if not p.is_dir():
            raise OptionError(f"{option} {path} cannot be created: {p} is a file; give a folder path")
        for d in reversed(missing):
            d.mkdir()
            created.append(d)
        probe = Path(tempfile.mkdtemp(prefix=".musclemetab-probe-", dir=path))
        probe.rmdir()
    except OSError as exc:
        raise OptionError(f"{option} {path} is not a writable folder ({exc.strerror or exc}); "
                          "choose a folder you can write to") from None
    finally:
        for d in reversed(created):
            try:
                d.rmdir()
            except OSError:  # pragma: no cover - something was written into it meanwhile
                pass
    return path


def check_inside(root: str | os.PathLike, path: str | os.PathLike, what: str = "output") -> Path:
    """``path`` resolved; :class:`~musclemetab.errors.OptionError` unless it lies inside ``root``."""
    from ..errors import OptionError

    root_r = Path(root).resolve()
    p = Path(path)
    p = (p if p.is_absolute() else root_r / p).resolve()
    if not p.is_relative_to(root_r):
        raise OptionError(f"{what} {p} would be written outside the output folder {root_r}; "
                          "use plain names without '..' or '/'")
    return p
