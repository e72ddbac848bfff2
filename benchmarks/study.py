"""Benchmark: the demo end to end, and study throughput with 1 and 2 worker processes.

    python benchmarks/study.py [--repeats 1]

1. ``musclemetab demo`` in a new process, with an empty geometry cache and an empty output
   folder: the wall time a new user waits (OpenSim worker start-up, geometry, six solves,
   metabolics, analysis, figures and the report). Target: under 60 s on 2 cores.
2. The demo's study (3 trials x 2 workflows = 6 units) run again with ``--force`` (warm
   geometry cache) with 1 worker process and with 2: units per minute and the speed-up of
   2 workers over 1 measured in the same run.
3. A resumed run (nothing to do): the cost of checking that every unit is up to date.

``--study FILE`` measures 2. (and 3.) on another study file instead of the demo's (e.g. a
study with several subjects and both legs; its output goes to a temporary folder) and
``--skip-demo`` skips 1. The worker processes run with their BLAS/OpenMP thread pools sized
to their share of the cores (``musclemetab.study.runner``). Timings on a shared machine vary
with its load: the load average is printed, and the 1- and 2-worker runs alternate when
``--repeats`` is above 1.
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
    ap.add_argument("--study", type=Path, help="study file for the throughput runs (default: the demo's)")
    ap.add_argument("--skip-demo", action="store_true", help="skip the end-to-end demo run")
    args = ap.parse_args(argv)
    import statistics

    tmp = Path(tempfile.mkdtemp(prefix="musclemetab-bench-study-"))
    env = dict(os.environ)
    print(f"machine: {os.cpu_count()} CPUs; output under {tmp}; load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")

    demo_times = []
    for i in range(0 if args.skip_demo and args.study else args.repeats):
        env["MUSCLEMETAB_CACHE"] = str(tmp / f"cache{i}")  # cold geometry cache
        demo_times.append(_musclemetab("demo", "--out", str(tmp / f"demo{i}"), "--no-progress", env=env))
    if demo_times:
        demo_s = statistics.median(demo_times)
        print(f"\n1. demo end to end (cold cache, new process): {demo_s:.1f} s "
              f"(target < 60 s; {'met' if demo_s < 60 else 'NOT met'})")

    env["MUSCLEMETAB_CACHE"] = str(tmp / "cache0")
    if args.study:
        from musclemetab.study import load_study
        from musclemetab.study.runner import unit_batches

        study = args.study.resolve()
        n_units = sum(len(b) for b in unit_batches(load_study(study)))
        out = ["--out", str(tmp / "study-out")]
        _musclemetab("run", str(study), *out, "--no-progress", env=env)  # geometry cache filled, not timed
        what = f"{study.name}, {n_units} units"
    else:
        study = tmp / "demo0" / "study.toml"
        n_units, out = 6, []
        what = "6 units: 3 trials x EFFORT-GEN/EFFORT-TEN, 6 models"
    times = {1: [], 2: []}
    for _ in range(args.repeats):
        for workers in (1, 2):
            times[workers].append(_musclemetab("run", str(study), *out, "--force", "--no-progress", "--workers",
                                               str(workers), env=env))
    rates = {w: statistics.median(t) for w, t in times.items()}
    print(f"\n2. study throughput ({what}; warm geometry cache; load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())})")
    print(f"{'workers':>8} {'wall s':>8} {'units/min':>10} {'s/unit':>8}")
    for w, s in rates.items():
        print(f"{w:>8} {s:>8.1f} {60 * n_units / s:>10.1f} {s / n_units:>8.2f}")
    print(f"speed-up of 2 workers over 1 (same run): {rates[1] / rates[2]:.2f}x")

    resumed = statistics.median(
        [_musclemetab("run", str(study), *out, "--no-progress", env=env) for _ in range(max(1, args.repeats))]
    )
    print(f"\n3. resumed run, every unit up to date: {resumed:.2f} s "
          f"({rates[1] / resumed:.0f}x faster than recomputing with 1 worker)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
