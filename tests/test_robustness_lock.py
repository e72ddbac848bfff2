"""The study lock after a crash: many runs starting at once on the folder, exactly one holds it.

Before the takeover was made atomic, two runs starting together after a crash both held the
lock in about a quarter of the tries (78 of 300 pairs); ``benchmarks/lock_takeover.py`` runs
the full measurement."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from musclemetab.errors import OptionError
from musclemetab.study.runner import LOCK_FILE, study_lock

_BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "lock_takeover.py"


_ROUNDS = """
import json, sys
from pathlib import Path
sys.path.insert(0, {bench!r})
import lock_takeover
print(json.dumps([lock_takeover.holders_after_crash(Path({folder!r}) / f"round{{r}}", {starts}) for r in range({rounds})]))
"""


# 300 simultaneous starts: python benchmarks/lock_takeover.py --starts 300 --rounds 3 (about 30 s a round)
@pytest.mark.parametrize("starts, rounds", [(2, 30), (24, 1)])
def test_stale_lock_taken_over_by_exactly_one_of_many_simultaneous_starts(tmp_path, starts, rounds):
    """The rounds of ``benchmarks/lock_takeover.py`` in a small process of their own, whose
    contenders are forked from it (a fork of the test process, which holds every module the
    tests imported, takes several times longer); the number of holders of each round."""
    code = _ROUNDS.format(bench=str(_BENCH.parent), folder=str(tmp_path), starts=starts, rounds=rounds)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    held = json.loads(r.stdout)
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
