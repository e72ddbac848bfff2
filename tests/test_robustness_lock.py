"""The study lock after a crash: many runs starting at once on the folder, exactly one holds it.

Before the takeover was made atomic, two runs starting together after a crash both held the
lock in about a quarter of the tries (78 of 300 pairs); ``benchmarks/lock_takeover.py`` runs
the full measurement."""

from __future__ import annotations

import importlib.util
import json
import os
import socket
from pathlib import Path

import pytest

from musclemetab.errors import OptionError
from musclemetab.study.runner import LOCK_FILE, study_lock

_BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "lock_takeover.py"


def _bench():
    spec = importlib.util.spec_from_file_location("lock_takeover", _BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# 300 simultaneous starts: python benchmarks/lock_takeover.py --starts 300 --rounds 3 (about 30 s a round)
@pytest.mark.parametrize("starts, rounds", [(2, 30), (24, 1)])
def test_stale_lock_taken_over_by_exactly_one_of_many_simultaneous_starts(tmp_path, starts, rounds):
    bench = _bench()
    held = [bench.holders_after_crash(tmp_path / f"round{r}", starts) for r in range(rounds)]
    assert held == [1] * rounds


def test_lock_of_a_live_process_is_refused_and_left_in_place(tmp_path):
    folder = tmp_path / "study"
    folder.mkdir()
    mine = {"pid": os.getppid(), "host": socket.gethostname(), "started": "2026-01-01T00:00:00Z"}
    (folder / LOCK_FILE).write_text(json.dumps(mine))
    with pytest.raises(OptionError, match=f"in use by another musclemetab run .*process {os.getppid()}"):
        study_lock(folder).__enter__()
    assert json.loads((folder / LOCK_FILE).read_text()) == mine
    assert sorted(p.name for p in folder.iterdir()) == [LOCK_FILE]  # no temporary file left


def test_lock_written_before_a_restart_is_stale(tmp_path):
    folder = tmp_path / "study"
    folder.mkdir()
    # a live process id, but another boot of the machine: the run that wrote it is gone
    (folder / LOCK_FILE).write_text(json.dumps({"pid": os.getppid(), "host": socket.gethostname(),
                                                "boot_id": "another-boot", "started": "2026-01-01T00:00:00Z"}))
    with study_lock(folder) as lock:
        assert json.loads(lock.path.read_text())["pid"] == os.getpid()
    assert list(folder.iterdir()) == []
