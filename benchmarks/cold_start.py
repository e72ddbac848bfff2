"""Cold start of ``musclemetab solve``: a new process against the same solve in a warm one.

Runs ``musclemetab solve`` (example subject, one trial, EFFORT-GEN) in new processes with
the geometry and model parameters cached, alternating between this source tree and, with
``--baseline-src``, another one (e.g. an older version), so that both see the same machine
load. Reports per tree the median wall time, the solve time IPOPT reports and the rest
(interpreter start, imports, reading files, OpenSim if it is started, set-up, writing), and
the process CPU time.

"Warm" is the same solve repeated in one long-lived process: ``solve_files`` with the same
arguments, called once untimed (imports done, caches hot), then ``--repeat`` times timed.
The last table gives cold minus warm per tree: the wall times, and the "rest" (wall minus
IPOPT's solve time, which removes the run-to-run swing of the solve itself), in wall and
CPU seconds. That difference is what a cold command costs over a warm one.

    python benchmarks/cold_start.py [--trial normal] [--repeat 3] [--baseline-src OTHER/src]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _example():
    sys.path.insert(0, str(HERE))
    from solver import _example as example  # the benchmarks' one way to locate the example data

    return example()


def cold_run(src: Path, ex, trial: str, cache: Path) -> dict:
    out = Path(tempfile.mkdtemp(prefix="mm-cold-")) / "out"
    env = dict(os.environ, PYTHONPATH=str(src), MUSCLEMETAB_CACHE=str(cache))
    # the command line's entry: `python -m musclemetab` (older trees: the module musclemetab.cli)
    entry = "musclemetab" if (src / "musclemetab" / "__main__.py").is_file() else "musclemetab.cli"
    cmd = [sys.executable, "-m", entry, "solve", "--model", str(ex.model), "--ik", str(ex.ik[trial]),
           "--id", str(ex.id[trial]), "--workflow", "effort-gen", "--out", str(out)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        sys.exit(f"musclemetab solve failed with {src}:\n{proc.stderr}")
    s = json.loads((out / "summary.json").read_text())
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "solve_s": s["solve_time_s"], "rest_s": wall - s["solve_time_s"],
            "cpu_s": cpu, "solve_cpu_s": s.get("solve_cpu_time_s", float("nan")),
            "rest_cpu_s": cpu - s.get("solve_cpu_time_s", float("nan"))}


_WARM = """
import json, sys, time
from musclemetab.redundancy import solve_files
model, ik, idf, repeat = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
solve_files(model, ik, idf, "effort-gen")  # imports, in-memory caches, the first solve: untimed
runs = []
for _ in range(repeat):
    w0, c0 = time.perf_counter(), time.process_time()
    sol = solve_files(model, ik, idf, "effort-gen")
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    s = sol.summary
    runs.append({"wall_s": wall, "solve_s": s["solve_time_s"], "rest_s": wall - s["solve_time_s"], "cpu_s": cpu,
                 "solve_cpu_s": s.get("solve_cpu_time_s", float("nan")),
                 "rest_cpu_s": cpu - s.get("solve_cpu_time_s", float("nan"))})
print(json.dumps(runs))
"""


def run_in_tree(code: str, src: Path, ex, trial: str, cache: Path, repeat: int, what: str):
    """Run ``code`` in a new process with the package of ``src``, given the trial's model, IK
    and ID files and ``repeat``; its last line of output, read as JSON."""
    env = dict(os.environ, PYTHONPATH=str(src), MUSCLEMETAB_CACHE=str(cache))
    proc = subprocess.run([sys.executable, "-c", code, str(ex.model), str(ex.ik[trial]), str(ex.id[trial]),
                           str(repeat)], capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        sys.exit(f"{what} failed with {src}:\n{proc.stderr}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def warm_runs(src: Path, ex, trial: str, cache: Path, repeat: int) -> list[dict]:
    """The same solve repeated in one process (see the module docstring)."""
    return run_in_tree(_WARM, src, ex, trial, cache, repeat, "the warm solve")


def _median(rs: list[dict]) -> dict:
    return {k: statistics.median(r[k] for r in rs) for k in rs[0]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trial", default="normal", choices=("slow", "normal", "fast"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--baseline-src", type=Path, help="another source tree (its src folder) to compare with")
    args = ap.parse_args(argv)
    ex = _example()
    trees = {"this tree": HERE.parent / "src"}
    if args.baseline_src:
        trees["baseline"] = args.baseline_src.resolve()
    cache = Path(tempfile.mkdtemp(prefix="mm-cold-cache-"))
    print(f"cold start: {os.cpu_count()} cores, load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for src in trees.values():  # fill each tree's caches (not timed)
        cold_run(src, ex, args.trial, cache)
    runs = {name: [] for name in trees}
    for _ in range(args.repeat):
        for name, src in trees.items():
            runs[name].append(cold_run(src, ex, args.trial, cache))
    warm = {name: warm_runs(src, ex, args.trial, cache, args.repeat) for name, src in trees.items()}
    head = f"{'wall s':>7} {'solve s':>8} {'rest s':>7} {'CPU s':>6} {'solve CPU s':>12} {'rest CPU s':>11}"
    print(f"{'tree':<10} {'run':<5} {head}")
    for name in trees:
        for kind, rs in (("cold", runs[name]), ("warm", warm[name])):
            med = _median(rs)
            print(f"{name:<10} {kind:<5} {med['wall_s']:>7.2f} {med['solve_s']:>8.2f} {med['rest_s']:>7.2f} "
                  f"{med['cpu_s']:>6.2f} {med['solve_cpu_s']:>12.2f} {med['rest_cpu_s']:>11.2f}")
    print(f"\n{'tree':<10} {'cold - warm: wall s':>20} {'rest s':>7} {'rest CPU s':>11}")
    for name in trees:
        c, w = _median(runs[name]), _median(warm[name])
        print(f"{name:<10} {c['wall_s'] - w['wall_s']:>20.2f} {c['rest_s'] - w['rest_s']:>7.2f} "
              f"{c['rest_cpu_s'] - w['rest_cpu_s']:>11.2f}")
    print(f"(medians of {args.repeat}; load average at the end {' '.join(f'{x:.2f}' for x in os.getloadavg())})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
