"""Benchmark: redrawing the report of a study folder, and a demo run with nothing changed.

    python benchmarks/report.py DIR [--repeats 3] [--baseline-src SRC]
    python benchmarks/report.py --quick

``DIR`` is a finished study folder (e.g. made by ``musclemetab demo --out DIR``). Each
measurement runs a new process, as a user does:

1. ``musclemetab report DIR --force`` (every figure drawn, the page written) with the default
   worker processes (the usable cores), with ``--workers 2`` and with ``--workers 1``; with
   ``--baseline-src SRC`` also the same command (default workers and ``--workers 1``) with
   another source tree of the package first on ``PYTHONPATH`` (e.g. a checkout of an earlier
   version: ``git worktree add /tmp/base main`` then ``--baseline-src /tmp/base/src``).
   Target: under 3 s on an idle 2-core machine.
2. ``musclemetab report DIR`` with nothing changed (the page is up to date: the cost of
   checking the content key).
3. When ``DIR`` was made by ``musclemetab demo``: ``musclemetab demo --out DIR`` again, nothing
   changed (every unit up to date, the report cached). Target: under 2 s.

Printed: the median and the best wall time (s) and the median processor time of the process and its
workers (user + system, s), and the ratios of the baseline's wall and processor times to this
version's, with the same workers option, measured in the same run. The
measurements alternate between the configurations so that a change in the machine's load
affects them alike.

``--quick``: ``DIR`` is made first, a study of one unit (EFFORT-GEN of the normal trial cut to
0.6-0.8 s, ``benchmarks/_quick.py``; the package's cache), and 1. (default workers alone) and 2.
are measured once: a check that the script runs (the test suite runs it so).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path


def _run(args, env) -> tuple[float, float]:
    """Wall time and processor time (user + system of the child processes) of one command."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "musclemetab", *args], env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        sys.exit(f"musclemetab {' '.join(args)} failed:\n{proc.stdout}\n{proc.stderr}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _env(src: str | None) -> dict:
    env = dict(os.environ)
    if src:
        env["PYTHONPATH"] = os.pathsep.join([str(Path(src).resolve()), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def _quick_study() -> str:
    """``--quick``: a finished one-unit study (run in this process), its output folder."""
    import tempfile
    import warnings

    from _quick import tiny_study
    from solver import _example

    from musclemetab.study import load_study
    from musclemetab.study.runner import run_study

    path = tiny_study(_example(), Path(tempfile.mkdtemp(prefix="mm-report-")))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = run_study(load_study(path), workers=1, progress=False)
    if run.failed:
        sys.exit(f"the quick study failed: {run.failed}")
    return str(path.parent / "out")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study_dir", metavar="DIR", nargs="?",
                    help="a finished study folder (e.g. from musclemetab demo --out DIR); required but with --quick")
    ap.add_argument("--repeats", type=int, default=3, help="repeats of each measurement (median and best reported)")
    ap.add_argument("--baseline-src", metavar="SRC", help="source tree of the package to compare with")
    ap.add_argument("--quick", action="store_true", help="a one-unit study made first; default workers, once")
    args = ap.parse_args(argv)
    if args.quick:
        args.study_dir, args.repeats, args.baseline_src = _quick_study(), 1, None
    elif args.study_dir is None:
        ap.error("DIR is required (or --quick)")
    folder = str(Path(args.study_dir).resolve())
    if not (Path(folder) / "results.csv").is_file():
        sys.exit(f"{folder}: not a finished study folder (no results.csv)")
    here = str(Path(__file__).resolve().parents[1] / "src")
    configs = {"this version, default workers": (_env(here), ["report", folder, "--force"]),
               "this version, --workers 2": (_env(here), ["report", folder, "--force", "--workers", "2"]),
               "this version, --workers 1": (_env(here), ["report", folder, "--force", "--workers", "1"])}
    if args.quick:
        configs = {k: v for k, v in configs.items() if k == "this version, default workers"}
    if args.baseline_src:
        configs["baseline, default workers"] = (_env(args.baseline_src), ["report", folder, "--force"])
        configs["baseline, --workers 1"] = (_env(args.baseline_src), ["report", folder, "--force", "--workers", "1"])
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}; study folder {folder}")
    times = {k: [] for k in configs}
    for _ in range(args.repeats):
        for name, (env, cmd) in configs.items():
            times[name].append(_run(cmd, env))
    if not args.quick:  # the last run of the quick one is this version's
        _run(["report", folder], configs["this version, default workers"][0])  # leave the page of this version
    times["report, nothing changed"] = [_run(["report", folder], _env(here)) for _ in range(args.repeats)]
    if (Path(folder) / "study.toml").is_file() and Path(folder).joinpath("study.json").is_file():
        times["demo again, nothing changed"] = [
            _run(["demo", "--out", folder, "--no-progress"], _env(here)) for _ in range(args.repeats)]
    ref = {k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v))
           for k, v in times.items() if k.startswith("baseline")}
    print(f"{'measurement':36s} {'wall (s)':>9s} {'best':>6s} {'cpu (s)':>8s}"
          + (f" {'baseline/this: wall':>20s} {'cpu':>6s}" if ref else ""))
    for name, values in times.items():
        wall = statistics.median(w for w, _ in values)
        cpu = statistics.median(c for _, c in values)
        line = f"{name:36s} {wall:9.2f} {min(w for w, _ in values):6.2f} {cpu:8.2f}"
        # against the baseline with the same workers option (default workers for --workers 2)
        base = ref.get("baseline, --workers 1" if name.endswith("--workers 1") else "baseline, default workers")
        if base and name.startswith("this version"):
            line += f" {base[0] / wall:19.2f}x {base[1] / cpu:5.2f}x"
        print(line)
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
