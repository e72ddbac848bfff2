"""Many runs starting at once on a study folder whose lock a crashed run left behind.

Each round: a lock file naming a process that has ended (same host and boot) is put in a
fresh folder; N processes wait at a barrier, then all enter ``study_lock`` at once and stay
alive until every one has answered. The number of processes that hold the lock must be 1.

    python benchmarks/lock_takeover.py --starts 2 --rounds 300     # pairs, as a user would
    python benchmarks/lock_takeover.py --starts 300 --rounds 3     # a crowd
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import socket
import tempfile
import time
from pathlib import Path


def _contender(folder, barrier, answers, done):
    from musclemetab.errors import OptionError
    from musclemetab.study.runner import study_lock

    barrier.wait()
    lock = study_lock(Path(folder))
    try:
        lock.__enter__()
        answers.put(1)
        done.wait()  # hold the lock until every contender has answered
    except OptionError:
        answers.put(0)


def dead_pid() -> int:
    """The process id of a process that has ended."""
    p = mp.get_context("fork").Process(target=int)
    p.start()
    p.join()
    return p.pid


def crashed_lock(folder: Path) -> None:
    """The lock file a run killed while it held the folder leaves behind."""
    from musclemetab.study.runner import LOCK_FILE, _boot_id

    folder.mkdir(parents=True, exist_ok=True)
    (folder / LOCK_FILE).write_text(json.dumps({"pid": dead_pid(), "host": socket.gethostname(),
                                                "boot_id": _boot_id(), "started": "2026-01-01T00:00:00Z"}))


def holders_after_crash(folder: Path, starts: int) -> int:
    """How many of ``starts`` simultaneous runs hold the lock a crashed run left in ``folder``."""
    crashed_lock(folder)
    ctx = mp.get_context("fork")
    barrier, answers, done = ctx.Barrier(starts), ctx.Queue(), ctx.Event()
    procs = [ctx.Process(target=_contender, args=(str(folder), barrier, answers, done)) for _ in range(starts)]
    for p in procs:
        p.start()
    held = sum(answers.get(timeout=120) for _ in procs)
    done.set()
    for p in procs:
        p.join()
    return held


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=int, default=2, help="processes starting at once in each round")
    ap.add_argument("--rounds", type=int, default=300)
    ap.add_argument("--quick", action="store_true", help="3 rounds of 2 starts (seconds; the test suite runs it so)")
    args = ap.parse_args()
    if args.quick:
        args.starts, args.rounds = 2, 3
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        held = [holders_after_crash(Path(tmp) / f"round{r}", args.starts) for r in range(args.rounds)]
    counts = ", ".join(f"{held.count(k)} round(s) with {k} holder(s)" for k in sorted(set(held)))
    print(f"{args.rounds} rounds of {args.starts} simultaneous starts after a crash: {counts} "
          f"({time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
