"""Benchmark: the demo end to end, and study throughput with 1 and 2 worker processes.

    python benchmarks/study.py [--repeats 1] [--study STUDY.toml | --two-subjects]

1. ``musclemetab demo`` in a new process, with an empty geometry cache and an empty output
   folder: the wall time a new user waits (OpenSim worker start-up, geometry, six solves,
   metabolics, analysis, figures and the report). Target: under 60 s on 2 cores.
2. The demo's study (3 trials x 2 workflows = 6 units) run again with ``--force`` (warm
   geometry cache) with 1 worker process and with 2: units per minute and the speed-up of
   2 workers over 1 measured in the same run.
3. A resumed run (nothing to do): the cost of checking that every unit is up to date.

With ``--study STUDY.toml`` only 2 and 3 are measured, on that study (after one run that fills
the geometry and inverse-dynamics caches). ``--two-subjects`` writes and measures a study of two
subjects with different models and legs: the example subject's normal trial (Rajagopal model,
right leg, ID file) and OpenSim's gait2392 subject (its own model, ``side = "both"``: each leg
over its own gait cycle, inverse dynamics from the ground forces, the legs added), EFFORT-GEN
with every study model: three units (the example's right leg, gait2392's right and left legs)
scheduled together.
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
    proc = subprocess.run([sys.executable, "-m", "musclemetab", *args], env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"musclemetab {' '.join(args)} failed:\n{proc.stdout}\n{proc.stderr}")
    return dt


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=1, help="repeats of each measurement (median reported)")
    ap.add_argument("--study", metavar="STUDY.toml", help="measure this study's throughput instead of the demo's")
    ap.add_argument("--two-subjects", action="store_true",
                    help="measure a two-subject study (example subject and gait2392, different models and legs)")
    args = ap.parse_args(argv)
    import statistics

    tmp = Path(tempfile.mkdtemp(prefix="musclemetab-bench-study-"))
    env = dict(os.environ)
    print(f"machine: {os.cpu_count()} CPUs; output under {tmp}")

    if args.two_subjects:
        args.study = _two_subject_study(tmp / "two-subjects.toml")
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


def _two_subject_study(path: Path) -> Path:
    """Write the two-subject study file (data from :mod:`musclemetab.datasets`)."""
    import json

    from musclemetab.datasets import example_subject, gait2392_subject01

    ex, g = example_subject(), gait2392_subject01()
    subjects = [
        ({"name": "example", "model": ex.model, "body_mass_kg": ex.body_mass_kg, "height_m": ex.height_m},
         {"name": "normal", "ik": ex.ik["normal"], "id": ex.id["normal"]}),
        # the data set gives no height (used for the speed normalisation only): 1.8 m
        ({"name": "gait2392", "model": g.model, "body_mass_kg": g.body_mass_kg, "height_m": g.height_m or 1.8,
          "side": "both"},
         {"name": "walk1", "ik": g.ik, "external_loads": g.external_loads, "cycle": "auto"}),
    ]

    def table(values: dict) -> list[str]:  # TOML values: JSON strings and numbers are valid TOML
        return [f"{k} = {json.dumps(v if isinstance(v, (int, float)) else str(v))}" for k, v in values.items()]

    lines = table({"name": "two subjects", "output": "out"}) + ['workflows = ["effort-gen"]']
    for subject, trial in subjects:
        lines += ["", "[[subjects]]", *table(subject), "", "[[subjects.trials]]", *table(trial)]
    path.write_text("\n".join(lines) + "\n")
    return path


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
