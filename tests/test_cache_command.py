"""``musclemetab cache``: the package cache's folders, their entries and sizes, and clearing them.

The cache is a temporary folder (``MUSCLEMETAB_CACHE``) holding entries written by the package's
own writers (:func:`musclemetab.cache.write_entry`, a file entry sealed with its checksum, a
functions entry of :func:`~musclemetab.redundancy.function_cache.cached_functions`) beside files
that are not the package's: the counts and sizes are checked against the files on disk, and
clearing must delete exactly the entries.
"""

from __future__ import annotations

import numpy as np
import pytest

from musclemetab.cache import cache_folder, entry_path, seal_file_entry, write_entry
from musclemetab.commands import main


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A package cache with entries in three folders and files of the user's among them."""
    import casadi as ca

    from musclemetab.redundancy.function_cache import cached_functions

    root = tmp_path / "cache"
    monkeypatch.setenv("MUSCLEMETAB_CACHE", str(root))
    entries = {}
    for i in range(3):  # geometry entries, as compute_geometry writes them
        path = entry_path({"request": i}, None, "geometry")
        write_entry(path, "geometry", lengths=np.arange(100.0 * (i + 1)))
        entries.setdefault("geometry", []).append(path)
    x = ca.SX.sym("x")
    cached_functions("test", "one structure", lambda: {"f": ca.Function("f", [x], [x ** 2])})
    entries["functions"] = sorted(cache_folder("functions").iterdir())
    sto = entry_path({"trial": 1}, cache_folder("inverse_dynamics"), "inverse dynamics", prefix="id-", suffix=".sto")
    sto.write_text("inverse dynamics\nendheader\n")
    seal_file_entry(sto, "inverse dynamics")
    entries["inverse_dynamics"] = [sto, sto.with_name(sto.name + ".sha256")]
    theirs = [cache_folder("geometry") / "notes.txt", cache_folder("geometry") / ".entry.npz.abc123.npz",
              cache_folder("functions") / "functions-not-a-key.npz", root / "README"]
    for p in theirs:
        p.write_text("not the package's\n")
    return root, entries, theirs


def test_the_cache_listed(cache, capsys):
    root, entries, _ = cache
    assert main(["cache"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"cache: {root}"
    rows = {line.split()[0]: line.split() for line in lines[2:]}
    for name, files in entries.items():
        count = sum(not p.name.endswith(".sha256") for p in files)  # a file entry counts with its checksum
        size = sum(p.stat().st_size for p in files)
        assert (int(rows[name][1]), rows[name][2]) == (count, f"{size / 1e6:.1f}")
    assert len(entries["functions"]) == 1 and int(rows["total"][1]) == 3 + 1 + 1
    assert int(rows["scale"][1]) == 0 and int(rows["ik"][1]) == 0 and not cache_folder("ik").exists()


def test_clearing_deletes_the_entries_and_nothing_else(cache, capsys):
    root, entries, theirs = cache
    size = {name: sum(p.stat().st_size for p in files) for name, files in entries.items()}
    assert main(["cache", "--clear", "--folders", "functions"]) == 0
    assert capsys.readouterr().out.strip() == (f"cache: deleted 1 entries ({size['functions'] / 1e6:.1f} MB) from "
                                               f"{root} (functions 1)")
    assert not any(p.exists() for p in entries["functions"])
    assert all(p.exists() for p in entries["geometry"] + entries["inverse_dynamics"])
    assert main(["cache", "--clear"]) == 0
    rest = (size["geometry"] + size["inverse_dynamics"]) / 1e6
    assert capsys.readouterr().out.strip() == (
        f"cache: deleted 4 entries ({rest:.1f} MB) from {root} "
        "(geometry 3, functions 0, inverse_dynamics 1, scale 0, ik 0, figures 0)")
    assert not any(p.exists() for files in entries.values() for p in files)
    assert all(p.read_text() == "not the package's\n" for p in theirs)  # the user's files stay
    assert cache_folder("geometry").is_dir()


def test_bad_input(cache, tmp_path, monkeypatch, capsys):
    with pytest.raises(SystemExit) as exc:  # a usage error: one line, status 1
        main(["cache", "--folders", "geometry", "models"])
    assert exc.value.code == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("musclemetab: error: argument --folders: invalid choice: 'models'") and "\n" not in err
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    monkeypatch.setenv("MUSCLEMETAB_CACHE", str(a_file))
    assert main(["cache", "--clear"]) == 1
    assert capsys.readouterr().err.strip() == (f"musclemetab: error: the package cache {a_file} is a file, not a "
                                               "folder: set MUSCLEMETAB_CACHE to a folder")
    assert a_file.read_text() == "x"


def test_an_entry_that_cannot_be_deleted(cache, monkeypatch, capsys):
    """An entry the file system refuses to delete (a folder without write permission) is named in one
    line, exit status 1; the entries of the other folders are deleted all the same."""
    from pathlib import Path

    root, entries, _ = cache
    unlink = Path.unlink

    def refuse_geometry(self, missing_ok=False):
        if self.parent.name == "geometry":
            raise PermissionError(13, "Permission denied")
        return unlink(self, missing_ok=missing_ok)

    monkeypatch.setattr(Path, "unlink", refuse_geometry)
    assert main(["cache", "--clear"]) == 1
    err = capsys.readouterr().err.strip()
    first = sorted(entries["geometry"])[0]  # deleted in the order of their names
    assert err == (f"musclemetab: error: could not delete 3 cache file(s), e.g. {first} (Permission denied); the "
                   "other entries are deleted: check the folder's permissions and run it again")
    assert all(p.exists() for p in entries["geometry"])
    assert not any(p.exists() for p in entries["functions"] + entries["inverse_dynamics"])
