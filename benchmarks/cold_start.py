"""Cold start of ``musclemetab solve``: a new process against the same solve in a warm one.

Runs ``musclemetab solve`` (example subject, one trial, EFFORT-GEN) in new processes with
the geometry, the model parameters and the solver's differentiated functions cached (an untimed
command per tree fills the caches first), alternating between this source tree and, with
``--baseline-src``, another one (e.g. an older version), so that both see the same machine
load. Reports per tree the median wall time, the solve time IPOPT reports and the rest
(interpreter start, imports, reading files, OpenSim if it is started, set-up, writing), and
the process CPU time.

"Warm" is the same solve repeated in one long-lived process: ``solve_files`` with the same
arguments, called once untimed (imports done, caches hot, the solution's OpenSim files written
once so that their model work is in the cache), then ``--repeat`` times timed; a warm solve
writes no files. A cold command with every cache entry there starts no OpenSim: it writes the
OpenSim files from the cached model work (``docs/opensim_files.md``).
The last table gives cold minus warm per tree: the wall times, and the "rest" (wall minus
IPOPT's solve time, which removes the run-to-run swing of the solve itself), in wall and
CPU seconds. That difference is what a cold command costs over a warm one.

Those imports are also timed once after each round of cold commands, and the last lines split
each tree's cold rest into them and the package's own share.

``--dependencies`` measures instead what no change of the package can remove from a cold
solve: in ``--repeat`` new interpreters (of this Python, so of its installed SciPy), the
import of NumPy, of CasADi with its IPOPT plugin loaded (a one-variable ``nlpsol``), and of
``scipy.signal`` and ``scipy.interpolate`` (the inputs' filter and splines, needed before IPOPT
starts), each timed, with their sum as a share of the 1.5 s a cold command may add to a solve.
Run it with the Pythons of two environments to compare SciPy versions.

    python benchmarks/cold_start.py [--trial normal] [--repeat 3] [--baseline-src OTHER/src]
    python benchmarks/cold_start.py --dependencies [--repeat 5]
    python benchmarks/cold_start.py --quick

``--quick``: the window 0.6-0.8 s of the normal trial (``--window``), one cold and one warm solve of
this tree, the package's cache (``$MUSCLEMETAB_CACHE``); the warm process runs first, its untimed
solve (and its OpenSim files) filling the caches. A check that the script runs; its times say
nothing of a whole trial's.
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


def _env(src: Path, cache: Path | None) -> dict:
    """The environment of a process of the tree ``src`` with the cache ``cache`` (None: the package's)."""
    return dict(os.environ, PYTHONPATH=str(src), **({"MUSCLEMETAB_CACHE": str(cache)} if cache else {}))


def cold_run(src: Path, ex, trial: str, cache: Path | None, window=None) -> dict:
    out = Path(tempfile.mkdtemp(prefix="mm-cold-")) / "out"
    env = _env(src, cache)
    # the command line's entry: `python -m musclemetab` (older trees: the module musclemetab.cli)
    entry = "musclemetab" if (src / "musclemetab" / "__main__.py").is_file() else "musclemetab.cli"
    cmd = [sys.executable, "-m", entry, "solve", "--model", str(ex.model), "--ik", str(ex.ik[trial]),
           "--id", str(ex.id[trial]), "--workflow", "effort-gen", "--out", str(out),
           *(["--window", f"{window[0]:g}:{window[1]:g}"] if window else [])]
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
window = tuple(json.loads(sys.argv[5])) if len(sys.argv) > 5 else None
first = solve_files(model, ik, idf, "effort-gen", window=window)  # imports, in-memory caches, the first solve: untimed
try:  # the OpenSim files of that solve, untimed: the cold command finds their model work in the cache
    from musclemetab.redundancy.export import write_solution_opensim_files
except ImportError:  # a tree without them
    write_solution_opensim_files = None
if write_solution_opensim_files is not None:
    import tempfile
    write_solution_opensim_files(first, tempfile.mkdtemp(prefix="mm-warm-files-"))
runs = []
for _ in range(repeat):
    w0, c0 = time.perf_counter(), time.process_time()
    sol = solve_files(model, ik, idf, "effort-gen", window=window)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    s = sol.summary
    runs.append({"wall_s": wall, "solve_s": s["solve_time_s"], "rest_s": wall - s["solve_time_s"], "cpu_s": cpu,
                 "solve_cpu_s": s.get("solve_cpu_time_s", float("nan")),
                 "rest_cpu_s": cpu - s.get("solve_cpu_time_s", float("nan"))})
print(json.dumps(runs))
"""


def run_in_tree(code: str, src: Path, ex, trial: str, cache: Path | None, repeat: int, what: str, window=None):
    """Run ``code`` in a new process with the package of ``src``, given the trial's model, IK
    and ID files, ``repeat`` and ``window`` (JSON); its last line of output, read as JSON."""
    proc = subprocess.run([sys.executable, "-c", code, str(ex.model), str(ex.ik[trial]), str(ex.id[trial]),
                           str(repeat), *([json.dumps(list(window))] if window else [])], capture_output=True,
                          text=True, env=_env(src, cache))
    if proc.returncode != 0:
        sys.exit(f"{what} failed with {src}:\n{proc.stderr}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def warm_runs(src: Path, ex, trial: str, cache: Path | None, repeat: int, window=None) -> list[dict]:
    """The same solve repeated in one process (see the module docstring)."""
    return run_in_tree(_WARM, src, ex, trial, cache, repeat, "the warm solve", window)


#: what a cold command may spend beyond the solve itself (seconds)
COLD_BUDGET_S = 1.5

_DEPENDENCIES = """
import json, time
t0 = time.perf_counter()
import numpy
t1 = time.perf_counter()
import casadi
x = casadi.SX.sym("x")
casadi.nlpsol("s", "ipopt", {"x": x, "f": x * x}, {"ipopt": {"print_level": 0}, "print_time": False})
t2 = time.perf_counter()
import scipy.interpolate, scipy.signal
t3 = time.perf_counter()
import scipy
print(json.dumps({"scipy": scipy.__version__, "numpy_s": t1 - t0, "casadi_ipopt_s": t2 - t1, "scipy_s": t3 - t2}))
"""


def dependency_run() -> dict:
    """The imports a cold solve cannot avoid, timed in one new interpreter (seconds, and SciPy's version)."""
    proc = subprocess.run([sys.executable, "-c", _DEPENDENCIES], capture_output=True, text=True)
    if proc.returncode != 0:
        sys.exit(f"the imports failed:\n{proc.stderr}")
    run = json.loads(proc.stdout.strip().splitlines()[-1])
    run["total_s"] = run["numpy_s"] + run["casadi_ipopt_s"] + run["scipy_s"]
    return run


def dependency_floor(repeat: int) -> int:
    """The imports a cold solve cannot avoid, in ``repeat`` new interpreters (``--dependencies``)."""
    runs = [dependency_run() for _ in range(repeat)]
    version = runs[0]["scipy"]
    for r in runs:
        r.pop("scipy")
    med = _median(runs)
    print(f"imports a cold solve needs: {os.cpu_count()} cores, load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}; SciPy {version}, Python {sys.version.split()[0]}")
    print(f"{'numpy s':>8} {'casadi+ipopt s':>15} {'scipy.signal+interpolate s':>27} {'total s':>8} {'total / budget':>15}")
    print(f"{med['numpy_s']:>8.2f} {med['casadi_ipopt_s']:>15.2f} {med['scipy_s']:>27.2f} {med['total_s']:>8.2f} "
          f"{med['total_s'] / COLD_BUDGET_S:>15.2f}")
    print(f"(medians of {repeat}; totals {min(r['total_s'] for r in runs):.2f}-{max(r['total_s'] for r in runs):.2f} s; "
          f"budget {COLD_BUDGET_S:g} s)")
    return 0


def _median(rs: list[dict]) -> dict:
    return {k: statistics.median(r[k] for r in rs) for k in rs[0]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trial", default="normal", choices=("slow", "normal", "fast"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--baseline-src", type=Path, help="another source tree (its src folder) to compare with")
    ap.add_argument("--dependencies", action="store_true",
                    help="time only the imports of NumPy, CasADi (with IPOPT) and SciPy that a cold solve needs")
    ap.add_argument("--quick", action="store_true",
                    help="the normal trial's window 0.6-0.8 s, one cold and one warm solve, the package's cache")
    args = ap.parse_args(argv)
    if args.dependencies:
        return dependency_floor(args.repeat)
    window = None
    if args.quick:
        from _quick import WINDOW

        args.trial, args.repeat, args.baseline_src, window = "normal", 1, None, WINDOW
    ex = _example()
    trees = {"this tree": HERE.parent / "src"}
    if args.baseline_src:
        trees["baseline"] = args.baseline_src.resolve()
    cache = None if args.quick else Path(tempfile.mkdtemp(prefix="mm-cold-cache-"))
    print(f"cold start: {os.cpu_count()} cores, load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if args.quick:  # the warm process's untimed solve fills the caches
        warm = {name: warm_runs(src, ex, args.trial, cache, args.repeat, window) for name, src in trees.items()}
    else:
        for src in trees.values():  # fill each tree's caches (not timed)
            cold_run(src, ex, args.trial, cache)
    runs = {name: [] for name in trees}
    floor = []  # the dependencies' imports, timed between the commands (the same machine state)
    for _ in range(args.repeat):
        for name, src in trees.items():
            runs[name].append(cold_run(src, ex, args.trial, cache, window))
        if not args.quick:
            floor.append(dependency_run()["total_s"])
    if not args.quick:
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
    if floor:  # what the package adds beyond the imports no change of it can remove
        dep = statistics.median(floor)
        print(f"\nimports of NumPy, CasADi with IPOPT, scipy.signal and scipy.interpolate in new interpreters: "
              f"{dep:.2f} s (median of {len(floor)}, {min(floor):.2f}-{max(floor):.2f} s)")
        for name in trees:
            rest = _median(runs[name])["rest_s"]
            print(f"{name:<10} cold rest {rest:.2f} s = those imports {dep:.2f} s + the package's own "
                  f"{rest - dep:.2f} s (budget for the rest {COLD_BUDGET_S:g} s)")
    print(f"(medians of {args.repeat}; load average at the end {' '.join(f'{x:.2f}' for x in os.getloadavg())})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
