"""Benchmark: the demo end to end, and study throughput with 1 and 2 worker processes.

    python benchmarks/study.py [--repeats 1] [--study STUDY.toml]

1. ``musclemetab demo`` in a new process, with an empty geometry cache and an empty output
   folder: the wall time a new user waits (OpenSim worker start-up, geometry, six solves,
   metabolics, analysis, figures and the report). Target: under 60 s on 2 cores.
2. The demo's study (3 trials x 2 workflows = 6 units) run again with ``--force`` (warm
   geometry cache) with 1 worker process and with 2: units per minute and the speed-up of
   2 workers over 1 measured in the same run.
3. A resumed run (nothing to do): the cost of checking that every unit is up to date.

With ``--study STUDY.toml`` only 2 and 3 are measured, on that study (after one run that fills
the geometry and inverse-dynamics caches).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _musclemetab(*args, env) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "musclemetab.cli", *args], env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"musclemetab {' '.join(args)} failed:\n{proc.stdout}\n{proc.stderr}")
    return dt


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=1, help="repeats of each measurement (median reported)")
    ap.add_argument("--study", metavar="STUDY.toml", help="measure this study's throughput instead of the demo's")
    args = ap.parse_args(argv)
    import statistics

    tmp = Path(tempfile.mkdtemp(prefix="musclemetab-bench-study-"))
    env = dict(os.environ)
    print(f"machine: {os.cpu_count()} CPUs; output under {tmp}")

    if args.study:
        from musclemetab.study import load_study
        from musclemetab.study.units import plan_units

        env["MUSCLEMETAB_CACHE"] = str(tmp / "cache0")
        study = Path(args.study).resolve()
        n_units = sum(len(stage) for stage in plan_units(load_study(study)))
        _musclemetab("run", str(study), "--no-progress", "--workers", "2", env=env)  # fill the caches
        return _throughput(study, n_units, env, args.repeats)
    demo_times = []
    for i in range(args.repeats):
        env["MUSCLEMETAB_CACHE"] = str(tmp / f"cache{i}")  # cold geometry cache
        demo_times.append(_musclemetab("demo", "--out", str(tmp / f"demo{i}"), "--no-progress", env=env))
    demo_s = statistics.median(demo_times)
    print(f"\n1. demo end to end (cold cache, new process): {demo_s:.1f} s "
          f"(target < 60 s; {'met' if demo_s < 60 else 'NOT met'})")

    env["MUSCLEMETAB_CACHE"] = str(tmp / "cache0")
    return _throughput(tmp / "demo0" / "study.toml", 6, env, args.repeats)


def _throughput(study, n_units, env, repeats) -> int:
    import statistics

    rates = {}
    for workers in (1, 2):
        times = [_musclemetab("run", str(study), "--force", "--no-progress", "--workers", str(workers), env=env)
                 for _ in range(repeats)]
        rates[workers] = statistics.median(times)
    print(f"\n2. study throughput ({n_units} units of {study}; warm geometry cache)")
    print(f"{'workers':>8} {'wall s':>8} {'units/min':>10} {'s/unit':>8}")
    for w, s in rates.items():
        print(f"{w:>8} {s:>8.1f} {60 * n_units / s:>10.1f} {s / n_units:>8.2f}")
    print(f"speed-up of 2 workers over 1 (same run): {rates[1] / rates[2]:.2f}x")

    resumed = statistics.median(
        [_musclemetab("run", str(study), "--no-progress", env=env) for _ in range(max(1, repeats))]
    )
    print(f"\n3. resumed run, every unit up to date: {resumed:.2f} s "
          f"({rates[1] / resumed:.0f}x faster than recomputing with 1 worker)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
