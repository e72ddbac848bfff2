"""Benchmark of the muscle redundancy solver on the example subject.

For every trial (slow, normal, fast) and workflow (effort-gen, effort-cal, effort-ten):
IPOPT wall time and iterations, objective, time from files to solution with the geometry
cached (``solve_files`` in a warm process), and the split of the solve into NLP function
evaluations and IPOPT's own work (mostly the MUMPS factorisation). Cold command-line runs
(``musclemetab solve`` in a new process, geometry and model parameters cached) are also
timed (median of ``--cold-repeat``).

With ``--baseline moco`` OpenSim's MocoInverse solves the same trials on the same mesh
(100 intervals per second, compliant tendons; set-up of ``docs/solver.md``) in a
separate process (``benchmarks/_moco_baseline.py``; opensim and casadi cannot share a
process), and the ratios of solve times (wall and CPU, with the load average) are printed. Timings on shared machines vary by
10-40 % from run to run: compare ratios measured in the same run.

Usage::

    python benchmarks/solver.py [--trials slow normal fast] [--workflows effort-gen ...]
        [--baseline moco [--moco-trials normal ...] [--moco-tendons compliant|rigid]]
        [--repeat 1] [--json results.json]
    python benchmarks/solver.py --quick

``--quick``: EFFORT-GEN of the window 0.6-0.8 s of the normal trial, one solve and one cold
command-line run of it, the geometry from the package's cache (``$MUSCLEMETAB_CACHE``), no
baseline: a check that the script runs (the test suite runs it so); its times say nothing of a
whole trial's.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
TRIALS = ("slow", "normal", "fast")
WORKFLOWS = ("effort-gen", "effort-cal", "effort-ten")
REFERENCE_OBJECTIVE = {"slow": 1.4137e-2, "normal": 2.3170e-2, "fast": 3.2867e-2}


def _example():
    from musclemetab.datasets import example_subject

    shared = HERE.parent.parent / "shared" / "data" / "example_subject"
    if not os.environ.get("MUSCLEMETAB_DATA") and shared.is_dir():
        os.environ["MUSCLEMETAB_DATA"] = str(shared)
    return example_subject()


def run_solver(ex, trials, workflows, cache_dir, repeat, options=None, window=None):
    from musclemetab.geometry import compute_geometry
    from musclemetab.model import read_muscle_parameters
    from musclemetab.redundancy import solve_files

    t0 = time.perf_counter()
    for t in trials:  # warm the geometry cache and the OpenSim worker (not timed below)
        compute_geometry(ex.model, ex.ik[t], cache_dir=cache_dir)
    read_muscle_parameters(ex.model, cache_dir=cache_dir)
    import casadi  # noqa: F401  (process start-up costs are measured by the cold run)

    warm = time.perf_counter() - t0
    rows = []
    for trial in trials:
        for wf in workflows:
            runs = []
            for _ in range(repeat):
                t0 = time.perf_counter()
                sol = solve_files(ex.model, ex.ik[trial], ex.id[trial], wf, cache_dir=cache_dir, options=options,
                                  window=window)
                runs.append((time.perf_counter() - t0, sol))
            wall, sol = min(runs, key=lambda r: r[0])
            s = sol.summary
            fun = sum(s.get("function_evaluation_time_s", {}).values())
            rows.append(dict(
                trial=trial, workflow=wf, status=s["status"], iterations=s["iterations"], N=s["n_intervals"],
                objective=s["objective"], solve_s=s["solve_time_s"], solve_cpu_s=s.get("solve_cpu_time_s"),
                functions_s=fun, ipopt_internal_s=s["solve_time_s"] - fun, build_s=s["build_time_s"],
                files_to_solution_s=wall, max_moment_residual_Nm=s["max_moment_residual_Nm"],
                ms_per_iteration=1e3 * s["solve_time_s"] / max(s["iterations"], 1),
                all_solve_s=[r[1].summary["solve_time_s"] for r in runs], window=window,
            ))
            print(_fmt_row(rows[-1]), flush=True)
    return rows, warm


def _fmt_row(r):
    ref = REFERENCE_OBJECTIVE.get(r["trial"]) if r["workflow"] == "effort-gen" and not r["window"] else None
    # the study's logged objectives are those of its stop (--stop authors); the default stop's optimum lies 2-6 % below
    rel = f" ({100 * (r['objective'] / ref - 1):+.3f} % vs study's stop)" if ref else ""
    return (f"{r['trial']:>6} {r['workflow']:<10} N={r['N']:>3} {r['status']:<16} it={r['iterations']:>3} "
            f"J={r['objective']:.6e}{rel:<24} solve {r['solve_s']:5.2f} s "
            f"(functions {r['functions_s']:.2f}, IPOPT+MUMPS {r['ipopt_internal_s']:.2f}; "
            f"{r['ms_per_iteration']:.0f} ms/it) build {r['build_s']:.2f} s files->solution {r['files_to_solution_s']:5.2f} s")


def cold_cli(ex, trial, cache_dir, linear_solver="mumps", window=None):
    """One ``musclemetab solve`` in a new process: wall time, the solve time it reports, and
    the time outside the solve (imports, files, problem set-up, writing). ``cache_dir`` None:
    the package's cache."""
    out = tempfile.mkdtemp(prefix="mm-bench-")
    cmd = [sys.executable, "-m", "musclemetab", "solve", "--model", str(ex.model), "--ik", str(ex.ik[trial]),
           "--id", str(ex.id[trial]), "--workflow", "effort-gen", "--linear-solver", linear_solver, "--out", out,
           *(["--cache-dir", str(cache_dir)] if cache_dir else []),
           *(["--window", f"{window[0]:g}:{window[1]:g}"] if window else [])]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        print(proc.stderr, file=sys.stderr)
        return {"wall_s": wall}
    s = json.loads((Path(out) / "summary.json").read_text())
    return {"wall_s": wall, "solve_s": s["solve_time_s"], "overhead_s": wall - s["solve_time_s"],
            "total_in_process_s": s["total_time_s"]}


def run_moco(ex, trial, mesh_interval, tendons):
    cmd = [sys.executable, str(HERE / "_moco_baseline.py"), "--model", str(ex.model), "--ik", str(ex.ik[trial]),
           "--id", str(ex.id[trial]), "--mesh-interval", str(mesh_interval), "--tendons", tendons,
           "--workdir", tempfile.mkdtemp(prefix="mm-moco-")]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"MocoInverse baseline failed:\n{proc.stderr[-3000:]}")
    out = json.loads(lines[-1])
    out["process_wall_s"] = wall
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description="Benchmark of the muscle redundancy solver.")
    p.add_argument("--trials", nargs="+", default=list(TRIALS), choices=TRIALS)
    p.add_argument("--workflows", nargs="+", default=list(WORKFLOWS), choices=WORKFLOWS)
    p.add_argument("--repeat", type=int, default=1, help="solves per (trial, workflow); the fastest is kept")
    p.add_argument("--baseline", choices=("moco",), help="also run OpenSim MocoInverse on the same trials")
    p.add_argument("--moco-trials", nargs="+", choices=TRIALS, default=["normal"],
                   help="trials for the baseline (default: normal; each takes minutes)")
    p.add_argument("--moco-tendons", choices=("compliant", "rigid"), default="compliant")
    p.add_argument("--mesh-interval", type=float, default=0.01, help="baseline mesh interval (default 0.01 s, as the solver)")
    p.add_argument("--cache-dir", help="geometry cache (default: a temporary folder)")
    p.add_argument("--no-cold", action="store_true", help="skip the cold command-line run")
    p.add_argument("--cold-repeat", type=int, default=3, help="cold command-line runs (median reported)")
    p.add_argument("--linear-solver", default="mumps", help="IPOPT's linear solver (default mumps)")
    p.add_argument("--json", help="write all figures to this file")
    p.add_argument("--quick", action="store_true",
                   help="EFFORT-GEN of the normal trial's window 0.6-0.8 s alone, one solve and one cold run, the "
                   "package's geometry cache, no baseline (the test suite runs it so)")
    args = p.parse_args(argv)
    window = None
    if args.quick:
        from _quick import WINDOW

        args.trials, args.workflows, args.repeat, args.cold_repeat, args.baseline = ["normal"], ["effort-gen"], 1, 1, None
        window = WINDOW

    ex = _example()
    # the quick run: the package's cache (the geometry other runs computed)
    cache_dir = Path(args.cache_dir) if args.cache_dir else None if args.quick else Path(tempfile.mkdtemp(
        prefix="mm-geometry-"))
    print(f"musclemetab solver benchmark: {os.cpu_count()} cores, load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    from musclemetab.redundancy.ipopt import SolverOptions

    options = SolverOptions(linear_solver=args.linear_solver)
    print(f"linear solver: {args.linear_solver}")
    rows, warm = run_solver(ex, args.trials, args.workflows, cache_dir, args.repeat, options, window)
    result = {"solver": rows, "geometry_and_worker_warmup_s": warm}
    solve = [r["solve_s"] for r in rows]
    f2s = [r["files_to_solution_s"] for r in rows]
    print(f"\nsolve time: median {statistics.median(solve):.2f} s, max {max(solve):.2f} s (target <= 3 s); "
          f"files->solution (geometry cached, warm process): median {statistics.median(f2s):.2f} s, "
          f"max {max(f2s):.2f} s (target <= 4 s; warm process: imports done, OpenSim worker running)")
    fun = sum(r["functions_s"] for r in rows)
    tot = sum(solve)
    print(f"time split: NLP function evaluations {100 * fun / tot:.0f} %, IPOPT internals (MUMPS factorisation "
          f"and solves, step computation) {100 * (tot - fun) / tot:.0f} %")
    if not args.no_cold:
        trial = "normal" if "normal" in args.trials else args.trials[0]
        colds = [cold_cli(ex, trial, cache_dir, args.linear_solver, window) for _ in range(max(1, args.cold_repeat))]
        ok = [c for c in colds if "overhead_s" in c]
        result["cold_cli"] = {trial: colds}
        if ok:
            med = {k: statistics.median(c[k] for c in ok) for k in ("wall_s", "solve_s", "overhead_s")}
            warm_row = [r for r in rows if r["trial"] == trial and r["workflow"] == "effort-gen"]
            warm_txt = (f"; warm process files->solution {warm_row[0]['files_to_solution_s']:.2f} s "
                        f"(solve {warm_row[0]['solve_s']:.2f} s)") if warm_row else ""
            print(f"cold 'musclemetab solve' ({trial}, effort-gen, new process, geometry and model parameters "
                  f"cached; OpenSim started only by a run whose OpenSim files' model work is not yet in the "
                  f"package's cache, $MUSCLEMETAB_CACHE), median of {len(ok)}: {med['wall_s']:.2f} s, of which "
                  f"the solve "
                  f"{med['solve_s']:.2f} s and everything else (imports, files, set-up, writing) "
                  f"{med['overhead_s']:.2f} s{warm_txt}")

    if args.baseline == "moco":
        result["moco"] = {}
        for trial in args.moco_trials:
            m = run_moco(ex, trial, args.mesh_interval, args.moco_tendons)
            result["moco"][trial] = m
            ours = [r for r in rows if r["trial"] == trial and r["workflow"] == "effort-gen"] or \
                [r for r in rows if r["trial"] == trial]
            if not ours:
                print(f"  (no musclemetab solve of the {trial} trial in this run to compare with)")
                continue
            ours = ours[0]
            print(f"MocoInverse {trial} ({args.moco_tendons} tendons, mesh {args.mesh_interval} s): {m['status']}, "
                  f"{m['iterations']} iterations, solve {m['solve_s']:.1f} s, set-up {m['setup_s']:.1f} s, "
                  f"max |reserve| {m.get('max_reserve_control', float('nan')):.2f} N m")
            print(f"  ratio MocoInverse solve / musclemetab solve ({ours['workflow']}): "
                  f"{m['solve_s'] / ours['solve_s']:.1f}x; set-up+solve vs files->solution: "
                  f"{(m['solve_s'] + m['setup_s']) / ours['files_to_solution_s']:.1f}x")
            if m.get("solve_cpu_s") and ours.get("solve_cpu_s"):
                print(f"  CPU-time ratio MocoInverse solve / musclemetab solve: "
                      f"{m['solve_cpu_s'] / ours['solve_cpu_s']:.1f}x ({m['solve_cpu_s']:.1f} / "
                      f"{ours['solve_cpu_s']:.2f} CPU s; load average now "
                      f"{' '.join(f'{x:.2f}' for x in os.getloadavg())})")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
