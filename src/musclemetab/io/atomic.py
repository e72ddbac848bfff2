"""Atomic file output: write to a temporary file beside the target, then rename.

A reader (or a resumed study) therefore never sees a half-written file: either the old
file, or the complete new one.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from ..errors import OptionError, OutputError

#: The lock file of a folder a run works on (a study's output folder, ``solve --out``)
LOCK_FILE = ".musclemetab.lock"
#: The list of the output files the package wrote into a folder, one ``SHA-256  name`` line
#: each (the format of ``sha256sum``, so ``sha256sum -c .musclemetab-files`` checks them)
FILES_MANIFEST = ".musclemetab-files"

__all__ = ["file_sha256", "source_path", "atomic_write_text", "atomic_write_bytes", "atomic_path", "atomic_directory",
           "check_output_folder", "check_inside", "check_replaceable", "written_files", "is_written",
           "FolderLock", "LOCK_FILE", "FILES_MANIFEST"]


def source_path(path: str | os.PathLike) -> Path:
    """An input file as a record keeps it: absolute (the folder the command ran in put in front of
    a relative name), so that a later command run from another folder finds it; links are kept as
    named."""
    return Path(os.path.abspath(path))


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
def atomic_path(path: str | os.PathLike, suffix: str | None = None, *, mark: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` if the block succeeds.

    With ``mark`` (an output file of the package) the file is listed in the folder's
    :data:`FILES_MANIFEST`, and a file already at ``path`` is replaced only when that list
    holds it unchanged (:func:`check_replaceable`)."""
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
        if mark:
            _replace_marked(path.parent, {path.name: tmp_path})
        else:
            os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def atomic_write_bytes(path: str | os.PathLike, data: bytes, *, mark: bool = False) -> Path:
    with atomic_path(path, mark=mark) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def atomic_write_text(path: str | os.PathLike, text: str, *, mark: bool = False) -> Path:
    with atomic_path(path, mark=mark) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike, *, mark: bool = False) -> Iterator[Path]:
    """Yield a temporary directory; on success, its files are moved into ``path``.

    An :class:`OSError` while writing (permission, disk full, file-size limit) is raised as
    :class:`~musclemetab.errors.OutputError` naming ``path``; the temporary directory is removed.

    Use it when one step writes several files that belong together: if the step fails
    none of them appears in ``path``. Files already in ``path`` and not rewritten stay.
    A file is never moved onto a folder; with ``mark`` (output files of the package) the
    files are listed in the folder's :data:`FILES_MANIFEST` and none replaces a file that the
    list does not hold unchanged (:func:`check_replaceable`, checked for all before any moves).
    """
    path = Path(path)
    tmp = None
    try:
        path.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=".partial-", dir=path))
        yield tmp
        items = sorted(tmp.iterdir())
        if mark:
            _replace_marked(path, {item.name: item for item in items if not item.is_dir()})
            items = [item for item in items if item.is_dir()]
        else:
            check_replaceable(path, [item.name for item in items if not item.is_dir()], files=False)
        for item in items:
            os.replace(item, path / item.name)
    except OSError as exc:
        raise output_error(exc, path) from None
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


def written_files(folder: str | os.PathLike) -> dict[str, set[str]]:
    """The files the package listed in ``folder``'s :data:`FILES_MANIFEST`: name -> the SHA-256
    values it was written with (two while a replacement was under way); ``{}`` without a list.
    Lines that are not ``<64 hex digits>  <name>`` are ignored."""
    try:
        text = (Path(folder) / FILES_MANIFEST).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return {}
    listed: dict[str, set[str]] = {}
    for line in text.splitlines():
        digest, sep, name = line.partition("  ")
        if sep and len(digest) == 64 and all(c in "0123456789abcdef" for c in digest) and name:
            listed.setdefault(name, set()).add(digest)
    return listed


def is_written(folder: str | os.PathLike, name: str) -> bool:
    """Whether ``folder/name`` is a file the package wrote and nobody changed since (listed in the
    folder's :data:`FILES_MANIFEST` with its present SHA-256)."""
    path = Path(folder) / name
    if path.is_symlink() or not path.is_file():
        return False
    return file_sha256(path) in written_files(folder).get(name, ())


@contextlib.contextmanager
def _folder_flock(folder: Path):
    """An exclusive ``flock`` of ``folder`` (one process at a time updates its list of files)."""
    import fcntl

    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the flock


def _write_manifest(folder: Path, listed: dict[str, set[str]]) -> None:
    lines = [f"{digest}  {name}\n" for name in sorted(listed) for digest in sorted(listed[name])]
    fd, tmp = tempfile.mkstemp(prefix=f"{FILES_MANIFEST}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.writelines(lines)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, folder / FILES_MANIFEST)
    finally:
        Path(tmp).unlink(missing_ok=True)


def _replace_marked(folder: Path, new: dict[str, Path]) -> None:
    """Move the files ``new`` (name -> the complete file) into ``folder`` as output files of
    the package: refused as a whole (:func:`check_replaceable`) when one would replace a file
    the package did not write; listed in :data:`FILES_MANIFEST` with their SHA-256 first (the
    old value kept until the move is done, so that a run killed in between leaves a folder
    whose files are all still known)."""
    folder = Path(folder)
    digests = {name: file_sha256(src) for name, src in new.items()}
    with _folder_flock(folder):
        check_replaceable(folder, list(new))
        listed = written_files(folder)
        listed = {n: d for n, d in listed.items() if (folder / n).is_file()}  # files removed since: dropped
        for name, digest in digests.items():
            listed[name] = listed.get(name, set()) | {digest}
        _write_manifest(folder, listed)
        for name, src in new.items():
            os.replace(src, folder / name)
        for name, digest in digests.items():
            listed[name] = {digest}
        _write_manifest(folder, listed)


def output_error(exc: OSError, path: str | os.PathLike) -> OutputError:
    """The :class:`~musclemetab.errors.OutputError` of a failed write into ``path``: one line
    naming the folder, the reason (no permission, disk full, file-size limit) and the remedy."""
    import errno

    reason = {errno.ENOSPC: "the disk is full", errno.EDQUOT: "the disk quota is exhausted",
              errno.EFBIG: "a file would exceed the file-size limit (ulimit -f)",
              errno.EACCES: "permission denied", errno.EPERM: "permission denied",
              errno.EROFS: "the file system is read-only"}.get(exc.errno, exc.strerror or str(exc))
    return OutputError(f"cannot write the output folder {path} ({reason}); the files of this step were not written "
                       "(the folder keeps what it held): free space or choose a folder you can write to, and run again")


def check_replaceable(folder: str | os.PathLike, names, *, files: bool = True,
                      elsewhere: str = "choose another output folder (--out)") -> None:
    """Raise :class:`~musclemetab.errors.OptionError` naming the path when one of the files
    ``names`` that the package is about to write into ``folder`` exists there as a folder
    (or a link to one): the package replaces its own files, never deletes a folder it did not
    write. With ``files``, also when one exists as a file (or a link) that ``folder``'s
    :data:`FILES_MANIFEST` does not list with its present SHA-256: a file of the user, or one
    changed since the package wrote it, is never replaced (a folder written before the
    package kept the list has none: its files are not taken for the package's). Checked for
    every name before any file is moved, so nothing is half written. ``elsewhere``: the message's
    other remedy (the option that names another place)."""
    from ..errors import OptionError

    folder = Path(folder)
    taken = [folder / n for n in names if (folder / n).is_dir()]
    if taken:
        raise OptionError(f"{taken[0]} is a folder, where musclemetab writes its file {taken[0].name}; it is not "
                          "removed: move it away or choose another output folder")
    if not files:
        return
    present = [n for n in names if (folder / n).exists() or (folder / n).is_symlink()]
    if not present:
        return
    listed = written_files(folder)
    for name in present:
        path = folder / name
        if path.is_symlink() or name not in listed:
            why = (f"not listed in {folder / FILES_MANIFEST}" if listed or (folder / FILES_MANIFEST).exists() else
                   f"{folder} has no {FILES_MANIFEST}, the list of the files musclemetab wrote there")
            raise OptionError(f"{path} was not written by musclemetab ({why}); it is not replaced: move the file "
                              f"away, or {elsewhere}")
        if file_sha256(path) not in listed[name]:
            raise OptionError(f"{path} was changed since musclemetab wrote it (its SHA-256 is not the one in "
                              f"{folder / FILES_MANIFEST}); it is not replaced: move the file away, or {elsewhere}")


def check_output_folder(path: str | os.PathLike, option: str = "--out") -> Path:
    """Check, before any work, that ``path`` is or can become a writable folder.

    Raises :class:`~musclemetab.errors.OptionError` naming ``option`` when ``path`` is an
    existing file, lies below a file, or cannot be created or written to. The check
    creates nothing that stays: folders it had to create to try are removed again.
    """
    from ..errors import OptionError, OutputError

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
    from ..errors import OptionError, OutputError

    root_r = Path(root).resolve()
    p = Path(path)
    p = (p if p.is_absolute() else root_r / p).resolve()
    if not p.is_relative_to(root_r):
        raise OptionError(f"{what} {p} would be written outside the output folder {root_r}; "
                          "use plain names without '..' or '/'")
    return p


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def _boot_id() -> str:
    """This boot of the machine (Linux), so that a lock written before a restart is known stale."""
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text(encoding="ascii").strip()
    except OSError:
        return ""


class FolderLock:
    """Hold ``DIR/.musclemetab.lock`` while a run works on the folder ``DIR`` (a study's output
    folder, or the ``--out`` of ``solve``); ``what`` names the folder in the messages.

    Raises :class:`OptionError` naming the lock file when another live process holds it.
    The lock file is created complete (written aside, then linked into place, which fails if
    it exists). A lock whose process no longer runs (same host: the process id is gone, or the
    machine restarted since, by its boot id) is stale and taken over: the check and the
    replacement happen under an exclusive ``flock`` of the study folder, so of many runs
    starting at once after a crash exactly one takes the lock.
    """

    def __init__(self, folder: Path, what: str = "study folder"):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_FILE
        self.what = what
        self.owned = False
        self.created: list[Path] = []

    def __enter__(self):
        self.created = []  # the folders made for the run, innermost first
        p = self.folder.absolute()
        while not p.exists():
            self.created.append(p)
            p = p.parent
        self.folder.mkdir(parents=True, exist_ok=True)
        info = {"pid": os.getpid(), "host": socket.gethostname(), "boot_id": _boot_id(),
                "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        import tempfile

        fd, tmp = tempfile.mkstemp(prefix=f"{self.path.name}.", suffix=".tmp", dir=self.folder)
        try:
            os.fchmod(fd, 0o644)
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                json.dump(info, f)
            holder = self._take(tmp, info)
        finally:
            Path(tmp).unlink(missing_ok=True)
        if self.owned:
            return self
        who = (f"process {holder.get('pid')} on {holder.get('host')}, since {holder.get('started')}"
               if holder else "a process that did not record itself")
        raise OptionError(
            f"the {self.what} {self.folder} is in use by another musclemetab run ({who}; lock file "
            f"{self.path}); wait for that run to finish, or delete the lock file if no run uses the folder"
        )

    def _take(self, tmp: str, info: dict) -> dict | None:
        """Put the complete lock ``tmp`` in place, or take over a stale one; the holder otherwise."""
        import fcntl

        try:
            os.link(tmp, self.path)  # atomic: fails when a lock exists
            self.owned = True
            return info
        except FileExistsError:
            pass
        fd = os.open(self.folder, os.O_RDONLY)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)  # one takeover at a time; released on close
            holder = self._holder()
            if holder is None and not self.path.exists():  # released meanwhile
                os.link(tmp, self.path)
                self.owned = True
            elif self._stale(holder, info):
                os.replace(tmp, self.path)  # the stale lock replaced in one step
                self.owned = True
            return holder
        finally:
            os.close(fd)

    @staticmethod
    def _stale(holder: dict | None, me: dict) -> bool:
        if holder is None or holder.get("host") != me["host"] or not isinstance(holder.get("pid"), int):
            return False
        if holder.get("boot_id") and me["boot_id"] and holder["boot_id"] != me["boot_id"]:
            return True  # written before the machine restarted
        return not _process_alive(holder["pid"])

    def _holder(self) -> dict | None:
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        return data if isinstance(data, dict) else None

    def __exit__(self, *exc):
        if self.owned:
            holder = self._holder()
            if holder is None or holder.get("pid") == os.getpid():
                self.path.unlink(missing_ok=True)
            self.owned = False
        for d in self.created:  # folders made for the run and left empty (it stopped before writing)
            try:
                d.rmdir()
            except OSError:
                break
        return False
