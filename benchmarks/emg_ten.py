"""Benchmark of EMG-TEN on the example subject: slow, normal and fast trials in one NLP.

Prints the wall time from files to result (geometry cached, OpenSim worker warm), the IPOPT
solve time and iterations, the size of the three-trial problem, the time per iteration, the
split of the solve into NLP function evaluations and IPOPT's own work (the linear solves
with MUMPS), the estimates against ``docs/solver.md``, and the ratio to the
study's MATLAB run (141-206 s, 77 250 variables, 135-235 iterations).

``--count-factorizations`` re-runs the solve with IPOPT's print level 7 captured to a file and
counts the KKT factorisations (each iteration factorises once, plus once per inertia
correction); the printing itself costs a little time, so this run is not the timed one.

Usage::

    python benchmarks/emg_ten.py [--mapping authors|default] [--coupling constraints|shared]
        [--repeat 1] [--count-factorizations] [--json results.json] [--quick]

``--quick``: two of the trials (normal and fast: one NLP of several trials, built and solved as
that of three), each cut to 0.2 s of its motion (IK, ID and EMG files written cropped to a
temporary folder, always with the same content: ``benchmarks/_quick.py``), their geometry from
the package's cache (``$MUSCLEMETAB_CACHE``), so that the whole path runs in seconds (the test
suite runs it so); its times say nothing of the full problem's.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
TRIALS = ("slow", "normal", "fast")
#: the trials of ``--quick``
QUICK_TRIALS = ("normal", "fast")
# docs/solver.md-§6.8 and the study's IPOPT log of the combined problem
STUDY = {"wall_s": (141.0, 206.0), "variables": 77250, "equalities": 62002, "inequalities": 3375,
         "iterations": (135, 235)}
STUDY_KT_SCALE = {"soleus_r": 0.303371, "vaslat_r": 0.134165}
STUDY_EMG_SCALE = {"bflh_r": 0.46443, "gaslat_r": 0.51219, "gasmed_r": 0.51219, "semiten_r": 0.41215,
                   "soleus_r": 2.32622, "tibant_r": 1.84726, "vasint_r": 0.39787, "vaslat_r": 0.39787,
                   "vasmed_r": 0.39787}


def _example():
    from musclemetab.datasets import example_subject

    shared = HERE.parent.parent / "shared" / "data" / "example_subject"
    if not os.environ.get("MUSCLEMETAB_DATA") and shared.is_dir():
        os.environ["MUSCLEMETAB_DATA"] = str(shared)
    return example_subject()


def _cropped(ex, folder: Path):
    """``{kind: {trial: path}}`` of the IK, ID and EMG files of the trials of ``--quick`` cut short
    (``--quick``: :func:`_quick.cropped_trial`), written into ``folder``."""
    from _quick import cropped_trial

    out = {"ik": {}, "id": {}, "emg": {}}
    for t in QUICK_TRIALS:
        files = cropped_trial(ex, t, folder / t, kinds=("ik", "id", "emg"))
        for kind in out:
            out[kind][t] = files[kind]
    return out


def _solve(ex, args, cache_dir, options=None):
    from musclemetab.redundancy.emg_ten import EmgTenSettings
    from musclemetab.redundancy.emg_run import solve_emg_ten

    files, trials = args.files, args.trials
    return solve_emg_ten(
        ex.model, [files["ik"][t] for t in trials], [files["id"][t] for t in trials], [files["emg"][t] for t in trials],
        emg_mapping=args.mapping, labels=trials, settings=EmgTenSettings(coupling=args.coupling),
        options=options, cache_dir=cache_dir,
    )


def count_factorizations(ex, args, cache_dir) -> dict:
    """Solve once with IPOPT's print level 7 sent to a file; count the factorisations."""
    from musclemetab.redundancy import SolverOptions

    with tempfile.TemporaryFile(mode="w+b") as log:
        sys.stdout.flush()
        saved = os.dup(1)
        os.dup2(log.fileno(), 1)
        try:
            result = _solve(ex, args, cache_dir, SolverOptions(print_level=7))
        finally:
            sys.stdout.flush()
            os.dup2(saved, 1)
            os.close(saved)
        log.seek(0)
        text = log.read().decode(errors="replace")
    per_iter = [int(x) for x in re.findall(r"Number of trial factorizations performed: (\d+)", text)]
    return {"factorizations": sum(per_iter), "iterations": result.iterations,
            "per_iteration_histogram": {k: per_iter.count(k) for k in sorted(set(per_iter))},
            "solve_time_s_print_level_7": result.record.solve_time_s}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--mapping", default="authors", help="EMG mapping: authors (default, as §6.8) or default")
    p.add_argument("--coupling", default="shared", choices=("shared", "constraints"),
                   help="couplings of the scale factors: one variable per group (default) or equality "
                   "constraints (the study's NLP)")
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--count-factorizations", action="store_true")
    p.add_argument("--json", metavar="FILE")
    p.add_argument("--quick", action="store_true", help="the normal and fast trials, each cut to 0.2 s (seconds in all)")
    args = p.parse_args(argv)

    args.trials = QUICK_TRIALS if args.quick else TRIALS
    ex = _example()
    cache_dir = None if args.quick else Path(tempfile.mkdtemp(prefix="emg_ten_bench_"))  # quick: the package's
    args.files = (_cropped(ex, Path(tempfile.mkdtemp(prefix="emg_ten_quick_"))) if args.quick else
                  {"ik": dict(ex.ik), "id": dict(ex.id), "emg": dict(ex.emg)})
    from musclemetab.geometry import compute_geometry
    from musclemetab.model import read_muscle_parameters

    for t in args.trials:  # geometry cache and OpenSim worker warm (not timed)
        compute_geometry(ex.model, args.files["ik"][t], cache_dir=cache_dir)
    read_muscle_parameters(ex.model, cache_dir=cache_dir)
    import casadi  # noqa: F401

    runs = []
    for _ in range(args.repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        result = _solve(ex, args, cache_dir)
        runs.append((time.perf_counter() - t0, time.process_time() - c0, result))
    wall, cpu, result = min(runs, key=lambda r: r[0])
    r = result.record.to_dict()  # the problem's record (ProblemRecord), as parameters.json holds it
    fun = sum(r["function_evaluation_time_s"].values())
    size = r["problem_size"]
    row = {
        "mapping": args.mapping, "coupling": args.coupling, "status": r["status"], "iterations": r["iterations"],
        "objective": r["objective"], "files_to_result_s": wall, "process_cpu_s": cpu,
        "solve_s": r["solve_time_s"], "solve_cpu_s": r["solve_cpu_time_s"], "build_s": r["build_time_s"],
        "preparation_s": r["preparation_time_s"], "functions_s": fun, "ipopt_internal_s": r["solve_time_s"] - fun,
        "ms_per_iteration": r["ms_per_iteration"], "variables": size["variables"],
        "equalities": size["equality_constraints"], "inequalities": size["inequality_constraints"],
        "function_evaluation_time_s": r["function_evaluation_time_s"],
        "tendon_scale": result.tendon_scale, "emg_scale": result.emg_scale,
        "achilles_N_per_mm": result.achilles_stiffness_N_per_mm(), "all_walls_s": [x[0] for x in runs],
    }
    if args.count_factorizations:
        row.update(count_factorizations(ex, args, cache_dir))
    from dataclasses import replace

    from musclemetab.redundancy.emg_ten import build_emg_ten_nlp

    other = "constraints" if args.coupling == "shared" else "shared"
    nlp = build_emg_ten_nlp(result.trials, result.parameters.replace(
        tendon_stiffness={m: 35.0 for m in result.tendon_stiffness}), replace(result.settings, coupling=other))
    row["other_form"] = {"coupling": other, "variables": nlp["n_variables"],
                         "equalities": nlp["n_equality_constraints"], "inequalities": nlp["n_inequality_constraints"]}

    sizes = " + ".join(str(t["n_intervals"]) for t in r.get("trials") or [] if "n_intervals" in t) or "?"
    print(f"EMG-TEN, example subject, trials {', '.join(args.trials)} (N = {sizes}), mapping {args.mapping}, "
          f"couplings as {args.coupling}{' (--quick: 0.2 s of each)' if args.quick else ''}")
    print(f"  status {r['status']}, {r['iterations']} iterations, objective {r['objective']:.6e}")
    print(f"  problem: {size['variables']} variables, {size['equality_constraints']} equality and "
          f"{size['inequality_constraints']} inequality constraints (study: {STUDY['variables']}, "
          f"{STUDY['equalities']}, {STUDY['inequalities']}); with the couplings as {other}: "
          f"{row['other_form']['variables']}, {row['other_form']['equalities']}, {row['other_form']['inequalities']}")
    print(f"  files -> result {wall:.1f} s (process CPU {cpu:.1f} s); IPOPT {r['solve_time_s']:.1f} s "
          f"(CPU {r['solve_cpu_time_s']:.1f} s), {r['ms_per_iteration']:.0f} ms per iteration; build "
          f"{r['build_time_s']:.2f} s; inputs + static optimisation {r['preparation_time_s']:.2f} s")
    print(f"  IPOPT time: NLP functions {fun:.1f} s ({100 * fun / r['solve_time_s']:.0f} %: "
          + ", ".join(f"{k} {v:.2f}" for k, v in r["function_evaluation_time_s"].items())
          + f"), IPOPT's own work (MUMPS factorisations and solves) {r['solve_time_s'] - fun:.1f} s "
          f"({100 * (r['solve_time_s'] - fun) / r['solve_time_s']:.0f} %)")
    if args.count_factorizations:
        print(f"  KKT factorisations: {row['factorizations']} in {row['iterations']} iterations "
              f"(per iteration: {row['per_iteration_histogram']}); about "
              f"{1e3 * (r['solve_time_s'] - fun) / max(row['factorizations'], 1):.0f} ms of IPOPT's own time each")
    lo, hi = STUDY["wall_s"]
    print(f"  study's MATLAB run: {lo:.0f}-{hi:.0f} s, {STUDY['iterations'][0]}-{STUDY['iterations'][1]} "
          f"iterations -> this run takes {r['solve_time_s'] / hi:.2f}-{r['solve_time_s'] / lo:.2f} of its time "
          f"({lo / r['solve_time_s']:.1f}-{hi / r['solve_time_s']:.1f}x faster; IPOPT time)")
    ts = result.tendon_scale
    print(f"  kT factors: triceps surae {ts['soleus_r']:.6f} (study {STUDY_KT_SCALE['soleus_r']}), vasti "
          f"{ts['vaslat_r']:.6f} (study {STUDY_KT_SCALE['vaslat_r']})")
    print("  EMG scale factors: " + ", ".join(f"{m} {v:.5f} (study {STUDY_EMG_SCALE.get(m, float('nan'))})"
                                              for m, v in result.emg_scale.items()))
    ach = result.achilles_stiffness_N_per_mm()
    if ach:
        print(f"  Achilles tendon stiffness: {ach['at_max_isometric_force']:.0f} N/mm at F0; at the peak walking "
              "force " + ", ".join(f"{t} {k:.0f}" for t, k in ach["at_peak_walking_force"].items())
              + " N/mm (in vivo 141-170 N/mm)")
    if args.json:
        Path(args.json).write_text(json.dumps(row, indent=2, default=float) + "\n")
    return 0 if result.success else 1


if __name__ == "__main__":
    sys.exit(main())
