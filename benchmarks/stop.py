"""Where the solver stops: the default (``--stop optimum``) against the study's settings (``--stop authors``).

    python benchmarks/stop.py [--repeat 3] [--reference] [--quick]

On the example subject's normal trial (EFFORT-GEN, and EFFORT-TEN with the subject's tendon
stiffness) and slow trial (EFFORT-TEN), each unit is solved with both stops, alternating, in
this one process (``solve_files``, geometry cached, the NLP built before timing). Printed per
unit and stop: IPOPT's iterations and CPU time (``solve_cpu_time_s``; the median of
``--repeat`` solves), the objective and the whole-body rates of UM10 and BH04 (W/kg, basal heat
included, the subject's 72.6 kg and 1.743 m), then the ratio of the CPU times, optimum /
authors. With ``--reference`` each unit is also solved at IPOPT tolerance 1e-10 (monotone
barrier), and every stop's rates of the six study models are printed as their difference from
those. ``--quick``: the window 0.6-0.8 s of the normal trial (``benchmarks/_quick.py``; its geometry
from the package's cache, ``$MUSCLEMETAB_CACHE``), EFFORT-GEN, one repeat (a check that the script
runs; the test suite runs it so).

CPU times on a shared machine vary by 10-40 % between runs: compare the ratios of one run.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
UNITS = (("normal", "effort-gen"), ("normal", "effort-ten"), ("slow", "effort-ten"))


def _example():
    from musclemetab.datasets import example_subject

    shared = HERE.parent.parent / "shared" / "data" / "example_subject"
    if not os.environ.get("MUSCLEMETAB_DATA") and shared.is_dir():
        os.environ["MUSCLEMETAB_DATA"] = str(shared)
    return example_subject()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--reference", action="store_true", help="also solve at tolerance 1e-10 (monotone)")
    ap.add_argument("--quick", action="store_true", help="the normal trial's window 0.6-0.8 s, EFFORT-GEN, one repeat")
    args = ap.parse_args(argv)

    from musclemetab.metabolics.solution import metabolics_from_solution
    from musclemetab.redundancy import SolverOptions, solve_files

    ex = _example()
    # the quick run: the package's cache (the geometry other runs computed), the quick window
    cache = None if args.quick else tempfile.mkdtemp(prefix="musclemetab-stop-")
    units = UNITS[:1] if args.quick else UNITS
    repeat = 1 if args.quick else max(1, args.repeat)
    if args.quick:
        from _quick import WINDOW
    stops = {"authors": SolverOptions(stop="authors"), "optimum": SolverOptions(stop="optimum")}
    if args.reference:
        stops["tol 1e-10"] = SolverOptions(stop="authors", tol=1e-10)
    ratios = []
    for trial, workflow in units:
        kw = dict(passive=ex.passive_moments_mat, tendon_stiffness="example") if workflow == "effort-ten" else {}
        if args.quick:
            kw["window"] = WINDOW

        def solve(options):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return solve_files(ex.model, ex.ik[trial], ex.id[trial], workflow, options=options, cache_dir=cache, **kw)

        solve(stops["authors"])  # geometry, model and the NLP built before timing
        cpu = {name: [] for name in stops}
        last = {}
        for _ in range(repeat):
            for name, options in stops.items():
                sol = solve(options)
                cpu[name].append(sol.record.solve_cpu_time_s)
                last[name] = sol
        rates = {}
        for name, sol in last.items():
            met = metabolics_from_solution(sol, ex.body_mass_kg, ex.height_m, models="all", require_success=False)
            rates[name] = {m: met.whole_body[m].mean_W_per_kg for m in met.models}
        print(f"{trial} {workflow}:")
        for name, sol in last.items():
            conv = sol.record.convergence or {}
            line = (f"  {name:9s} {sol.record.iterations:4d} iterations, IPOPT CPU {statistics.median(cpu[name]):6.2f} s, "
                    f"objective {sol.record.objective:.7f}, UM10 {rates[name]['UM10']:.3f}, BH04 {rates[name]['BH04']:.3f} "
                    f"W/kg, final mu {conv.get('final_barrier_parameter')}, rate residue "
                    f"{100 * conv.get('max_rate_residue', float('nan')):.2f} %")
            if "tol 1e-10" in rates and name != "tol 1e-10":
                ref = rates["tol 1e-10"]
                worst = max(abs(rates[name][m] / ref[m] - 1) for m in ref)
                line += f"; largest rate difference to tol 1e-10 {100 * worst:.2f} %"
            print(line)
        ratio = statistics.median(cpu["optimum"]) / statistics.median(cpu["authors"])
        ratios.append(ratio)
        print(f"  IPOPT CPU optimum / authors: {ratio:.2f}x")
    print(f"IPOPT CPU optimum / authors over the units: {', '.join(f'{r:.2f}x' for r in ratios)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
