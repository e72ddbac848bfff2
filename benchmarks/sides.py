"""Benchmark: ``solve --side both`` on the gait2392 subject with 1 and 2 worker processes.

    python benchmarks/sides.py [--repeats 1]
    python benchmarks/sides.py --quick

EFFORT-GEN of each leg's first gait cycle (found from the ground forces, inverse dynamics
computed by OpenSim), both legs, run as a new process with ``--workers 1`` (one leg after the
other) and ``--workers 2`` (the legs at once), after one run that fills the geometry,
layout and inverse-dynamics caches. Prints the wall times, their ratio measured in the same
run, and checks that both runs wrote the same solutions.

``--quick``: the example subject's normal trial over the window 0.6-0.8 s instead (both legs, its
ID file), the package's cache (``$MUSCLEMETAB_CACHE``) and no run to fill it: a check that the
script runs (the test suite runs it so); its times say nothing of gait2392's.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

from study import _musclemetab  # the timed command-line run of benchmarks/study.py


def _solve(data: Path, out: Path, workers: int, env) -> float:
    args = ["solve", "--model", str(data / "subject01_simbody.osim"), "--ik", str(data / "subject01_walk1_ik.mot"),
            "--external-loads", str(data / "subject01_walk1_grf.xml"), "--cycle", "auto", "--side", "both",
            "--workers", str(workers), "--out", str(out)]
    return _musclemetab(*args, env=env)


def _solve_quick(_, out: Path, workers: int, env) -> float:
    """``--quick``: the example subject's normal trial over the quick window, both legs."""
    from _quick import window_arg
    from solver import _example

    ex = _example()
    return _musclemetab("solve", "--model", str(ex.model), "--ik", str(ex.ik["normal"]), "--id", str(ex.id["normal"]),
                        "--window", window_arg(), "--side", "both", "--workers", str(workers), "--out", str(out), env=env)


def main(argv=None) -> int:
    import statistics

    import numpy as np

    from musclemetab.datasets import gait2392_subject01
    from musclemetab.redundancy import Solution

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=1, help="repeats of each measurement (median reported)")
    ap.add_argument("--quick", action="store_true", help="the example's normal trial over 0.6-0.8 s, both legs, "
                    "the package's cache")
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="musclemetab-bench-sides-"))
    print(f"machine: {os.cpu_count()} CPUs; output under {tmp}")
    if args.quick:
        solve, data, env, args.repeats = _solve_quick, None, dict(os.environ), 1
    else:
        solve, data, env = _solve, gait2392_subject01().model.parent, dict(os.environ, MUSCLEMETAB_CACHE=str(tmp / "cache"))
        solve(data, tmp / "warm", 2, env)  # fill the caches
    times = {w: statistics.median(solve(data, tmp / f"w{w}_{i}", w, env) for i in range(args.repeats))
             for w in (1, 2)}
    print(f"{'workers':>8} {'wall s':>8}")
    for w, s in times.items():
        print(f"{w:>8} {s:>8.1f}")
    print(f"speed-up of 2 workers over 1: {times[1] / times[2]:.2f}x")
    same = all(np.array_equal(getattr(Solution.load(tmp / "w1_0" / side), k), getattr(Solution.load(tmp / "w2_0" / side), k))
               for side in "rl" for k in ("activation", "lm_norm", "reserve_Nm"))
    print(f"solutions of 1 and 2 workers identical: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
