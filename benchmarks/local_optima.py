"""Which optimum does a solve reach? gait2392's legs solved from several starts.

    python benchmarks/local_optima.py [--units effort-cal/l effort-ten/l effort-ten/r]
    python benchmarks/local_optima.py --quick

The muscle redundancy problem is not convex (compliant tendons, fiber dynamics): IPOPT ends at
a local optimum, and which one can depend on where it starts and on the barrier's path, not only
on how far it converges. On OpenSim's gait2392 subject (both legs over their gait cycles, inverse
dynamics from the ground forces; EFFORT-CAL with the passive calibration of
``benchmarks/study.py``'s validation study, EFFORT-TEN with its triceps-surae tendons at kT = 20)
each unit is solved

* cold, with the package's default stop (static optimisation start, IPOPT's adaptive barrier to
  tolerance 1e-8): the reference;
* cold to tolerance 1e-10 (the same optimum, converged further);
* cold with IPOPT's monotone barrier from ``mu_init`` 0.01 to tolerance 1e-10 (another path);
* warm from the leg's EFFORT-GEN solution (``warm_start=``, as a study with ``--warm-start``).

Printed per unit and start: the objective's relative difference to the reference, IPOPT's
iterations and CPU time, and the largest relative differences of the six study models'
whole-body rates (basal heat included) and of the rate of each muscle above 1 % of its leg's
(the cycle averages of ``per_muscle.csv``). docs/study.md, "Warm-started chains", reports the
result: several optima, whose single-muscle rates differ by up to about 10 %.

``--quick``: the right leg's EFFORT-TEN alone on the window 1.0-1.4 s (a check that the script
runs; a window that short says nothing of the cycle's optima).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
UNITS = ("effort-cal/l", "effort-ten/l", "effort-ten/r")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", nargs="+", default=list(UNITS), metavar="WORKFLOW/SIDE",
                    help=f"units of gait2392 to solve (default {' '.join(UNITS)})")
    ap.add_argument("--quick", action="store_true", help="effort-ten/r on 1.0-1.4 s only")
    args = ap.parse_args(argv)
    span = {"window": (1.0, 1.4)} if args.quick else {"cycle": "auto"}
    warnings.simplefilter("ignore")  # gait2392's diagnoses and flags, the same for every start
    sys.path.insert(0, str(HERE))
    from study import _gait2392_passive

    from musclemetab.datasets import gait2392_subject01
    from musclemetab.events import GaitCycle
    from musclemetab.metabolics.solution import metabolics_from_solution
    from musclemetab.metabolics.per_muscle import per_muscle_table
    from musclemetab.redundancy.problem import TrialFiles, load_problem, solve

    g = gait2392_subject01()
    tmp = Path(tempfile.mkdtemp(prefix="local_optima-"))
    passive = _gait2392_passive(g.model, tmp / "gait2392_passive.csv")

    def problem(workflow, side):
        kw = {} if workflow == "effort-gen" else {"passive": passive}
        if workflow == "effort-ten":
            kw["tendon_stiffness"] = {f"{m}_{side}": 20.0 for m in ("soleus", "med_gas", "lat_gas")}
        return load_problem(g.model, [TrialFiles(ik=g.ik)], workflow=workflow, side=side,
                            external_loads=g.external_loads, **span, **kw)

    def rates(solution):
        m = metabolics_from_solution(solution, g.body_mass_kg, g.height_m or 1.8)
        c = solution.record.gait_cycle
        table = per_muscle_table(m, GaitCycle(c["start_s"], c["toe_off_s"], c["end_s"]) if c else None)
        whole = {k: m.whole_body[k].mean_W_per_kg for k in m.models}
        return whole, table.set_index(["model", "muscle"])

    def worst(new, ref):
        (wb, per), (wb0, per0) = new, ref
        d_wb = {k: abs(wb[k] / wb0[k] - 1) for k in wb0}
        big = per0["share_of_leg_pct"] > 1.0
        d = (per["muscle_W"][big] / per0["muscle_W"][big] - 1).abs()
        k = max(d_wb, key=d_wb.get)
        return f"{100 * d_wb[k]:6.3f} % ({k})", f"{100 * d.max():6.2f} % ({'/'.join(d.idxmax())})"

    print("start                                   objective   iter  CPU s   whole body          muscles")
    for unit in ["effort-ten/r"] if args.quick else args.units:
        workflow, side = unit.split("/")
        p = problem(workflow, side)
        gen = next(iter(solve(problem("effort-gen", side)).solutions.values()))
        default = p.options
        starts = {
            "cold (the reference)": (default, None),
            "cold, tol 1e-10": (default.with_(tol=1e-10), None),
            "cold, monotone from mu_init 0.01, tol 1e-10": (default.with_(tol=1e-10, ipopt={
                **default.ipopt, "mu_strategy": "monotone", "mu_init": 0.01}), None),
            "warm from EFFORT-GEN": (default, gen),
        }
        print(f"\n{unit}")
        ref = f0 = None
        for name, (options, warm) in starts.items():
            c0 = time.process_time()
            s = next(iter(solve(p, options, warm_start=warm).solutions.values()))
            cpu = time.process_time() - c0
            r = rates(s)
            if ref is None:
                ref, f0 = r, s.record.objective
            wb, mus = worst(r, ref)
            print(f"  {name:<42} {(s.record.objective - f0) / f0:+9.1e} {s.record.iterations:5d} {cpu:6.1f}   "
                  f"{wb:<18}  {mus}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
