"""Inertia corrections of IPOPT on the EFFORT-GEN problem: how many factorisations, and which options save them.

IPOPT factorises the KKT matrix once per iteration when its inertia is right (as many negative
eigenvalues as constraints). When it is not, the Hessian block is perturbed (``H + delta_w I``)
and the matrix factorised again, ``delta_w`` growing until the inertia is right. Each such
repeat costs a full MUMPS factorisation, the largest part of a solve (``docs/solver.md``,
"Inertia corrections").

For each trial and each option set this script solves EFFORT-GEN with IPOPT writing its
detailed log (``file_print_level 6``) to a temporary file and counts in it the successful
factorisations and the ones refused for wrong inertia ("Factorization failed with retval = 2"),
the iterations that needed a perturbation (the ``lg(rg)`` column), the largest excess of
negative eigenvalues MUMPS reported, and the objective's change against the default options.
Counts are the same on any machine load; times are not (the load average is printed).

Trials: the example subject's slow, normal and fast trials (right leg, ID file) and, with
``--gait2392``, the right leg of OpenSim's gait2392 subject over its first gait cycle.

    python benchmarks/inertia.py [--trials slow normal fast] [--gait2392] [--options default ...] [--variant V]
    python benchmarks/inertia.py --quick

``--quick``: the window 0.6-0.8 s of the normal trial (geometry from the package's cache) with the
default options and a larger first perturbation (a check that the script runs; its counts say
nothing of the full trials').
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
# one BLAS thread (MUMPS runs with one in the solver; the dense factorisations of --attribute
# only spin with more on a shared machine)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

#: IPOPT option sets tried on top of the package's (IPOPT's documentation names each option;
#: IPOPT's defaults in brackets)
OPTION_SETS = {
    "default": {},
    # the first trial perturbation [1e-4] and its growth on the first correction [100] / later [8]
    "first_pert_1e-2": {"first_hessian_perturbation": 1e-2},
    "inc_fact_first_1e3": {"perturb_inc_fact_first": 1e3},
    # keep more of the previous iteration's perturbation [decrease factor 1/3]
    "dec_fact_0.9": {"perturb_dec_fact": 0.9},
    # accept a wrong inertia when the step is a direction of positive curvature (Chiang and Zavala 2016) [0]
    "neg_curv_1e-12": {"neg_curv_test_tol": 1e-12},
    "neg_curv_1e-12_noreg": {"neg_curv_test_tol": 1e-12, "neg_curv_test_reg": "no"},
    # MUMPS' pivot tolerance: IPOPT's default 1e-6 (the package uses 1e-4, MUMPS_OPTIONS)
    "mumps_pivtol_1e-6": {"mumps_pivtol": 1e-6},
}

#: equivalent forms of a constraint (same feasible set, so the same optimum; another Hessian):
#: the experiment that tells whether a constraint's curvature causes the inertia corrections
VARIANTS = ("as-built", "pennation-sqrt")


def use_variant(variant: str):
    """Switch the interval constraints to ``variant`` (one of :data:`VARIANTS`) for the NLPs built
    from now on in this process. ``pennation-sqrt``: the pennation identity
    ``(l~M lMo)^2 - w^2 - lp^2 = 0``, whose Hessian ``diag(2 lMo^2, -2)`` in ``(l~M, lp)`` is
    indefinite whatever its multiplier, written as ``l~M lMo - sqrt(lp^2 + w^2) = 0`` (the same
    fibers: ``l~M > 0``), whose Hessian is zero in ``l~M``. Only the interval rows are switched
    (the last node keeps its row)."""
    from musclemetab.redundancy import transcription

    original = getattr(transcription, "_as_built_node_expressions", transcription._node_expressions)
    transcription._as_built_node_expressions = original
    if variant == "as-built":
        transcription._node_expressions = original
        return

    def node_expressions(sym, M, D, h, P, optimal_reserve_Nm, ca, backward=False):
        syms, g, _ = original(sym, M, D, h, P, optimal_reserve_Nm, ca, backward)
        penn = syms["lm"] * P["lmo"] - ca.sqrt(syms["lp"] ** 2 + P["w2"])
        return syms, ca.vertcat(g[: 2 * M], penn, g[3 * M:]), penn

    transcription._node_expressions = node_expressions


def solve_counted(solve, options: dict) -> dict:
    """Run ``solve(ipopt_options)`` with IPOPT's detailed log in a temporary file; counts and results."""
    from kkt import count_factorisations

    from musclemetab.redundancy.ipopt import SolverOptions

    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "ipopt.log"
        ipopt = {"output_file": str(log), "file_print_level": 6, **options}
        t0, c0 = time.perf_counter(), time.process_time()
        sol = solve(SolverOptions(ipopt=ipopt))
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        counts = count_factorisations(log.read_text())
    s = sol.record
    return {**counts, "iterations": s.iterations, "status": s.status, "objective": s.objective,
            "solve_s": s.solve_time_s, "wall_s": wall, "cpu_s": cpu}


def _negative_eigenvalues(d) -> int:
    """Negative eigenvalues of the block-diagonal factor ``D`` of an LDL^T factorisation (1x1 and
    2x2 blocks; by Sylvester's law of inertia, those of the factorised matrix)."""
    import numpy as np

    n, i, count = d.shape[0], 0, 0
    while i < n:
        if i + 1 < n and d[i + 1, i] != 0.0:
            count += int(np.sum(np.linalg.eigvalsh(d[i:i + 2, i:i + 2]) < 0))
            i += 2
        else:
            count += int(d[i, i] < 0)
            i += 1
    return count


def attribute(trial: str, start_frame: int, frames: int, iterations) -> list[dict]:
    """Which constraints' curvature gives the KKT matrix its surplus negative eigenvalues.

    On a short window of the trial (``frames`` IK frames from ``start_frame``, unfiltered, so that
    the KKT matrix can be factorised densely with its inertia, ``scipy.linalg.ldl``), IPOPT is stopped
    after each of ``iterations``; the matrix IPOPT factorises at that iterate is assembled
    (``benchmarks/kkt.py``: Hessian of the Lagrangian plus the barrier term, the constraint
    Jacobian) and its negative eigenvalues counted beyond the number of constraints (the
    surplus IPOPT removes by perturbing the Hessian block). The count is repeated with the
    Lagrange multipliers of one family of rows set to zero, which removes that family's
    curvature from the Hessian and nothing else: the family whose removal removes the surplus
    is its source. Rows per interval: activation dynamics, fiber kinematics, pennation
    identity, Hill equilibrium (``M`` each), moment equilibrium (``D``); the last node's
    pennation rows.
    """
    import dataclasses

    import numpy as np
    import scipy.linalg as sla

    sys.path.insert(0, str(HERE))
    import kkt

    from musclemetab.geometry import compute_geometry
    from musclemetab.model import read_muscle_parameters
    from musclemetab.redundancy.inputs import DEFAULT_DOFS, read_inverse_dynamics, restrict_geometry, trial_inputs
    from musclemetab.redundancy.ipopt import SolverOptions, build_nlp
    from musclemetab.redundancy.static_opt import initial_guess, static_optimisation
    from musclemetab.redundancy.workflows import workflow_parameters

    ex = kkt._example()
    geom = restrict_geometry(compute_geometry(ex.model, ex.ik[trial], dofs=list(DEFAULT_DOFS)))
    cut = slice(start_frame, start_frame + frames)
    geom = dataclasses.replace(geom, time=geom.time[cut], lmt_m=geom.lmt_m[cut], moment_arms_m=geom.moment_arms_m[cut])
    id_time, id_mom = read_inverse_dynamics(ex.id[trial], geom.dofs)
    params, _ = workflow_parameters("effort-gen", read_muscle_parameters(ex.model), geom.muscles)
    params = params.subset(geom.muscles)
    inputs = trial_inputs(geom, id_time, id_mom, filter_inputs=False)  # too few frames for the filter's padding
    options = SolverOptions()
    nlp = build_nlp(inputs, params, initial_guess(inputs, params, static_optimisation(inputs, params)), options)
    M, D = len(inputs.muscles), len(inputs.dofs)
    m = np.asarray(nlp["lbg"]).size
    per_interval = 4 * M + D
    intervals = (m - M) // per_interval  # the last node's M pennation rows close the list
    row = np.arange(intervals * per_interval).reshape(intervals, per_interval)
    families = {"activation dynamics": row[:, :M], "fiber kinematics": row[:, M:2 * M],
                "pennation identity": np.concatenate([row[:, 2 * M:3 * M].ravel(), np.arange(m - M, m)]),
                "Hill equilibrium": row[:, 3 * M:4 * M], "moment equilibrium": row[:, 4 * M:]}
    out = []
    for k in iterations:
        x, lam_g, lam_x, mu, it = kkt.iterate(nlp, options, k)
        counts = {}
        for name, rows in [("all rows", None), *families.items()]:
            lam = lam_g.copy()
            if rows is not None:
                lam[np.ravel(rows)] = 0.0
            K, _, n, m = kkt.kkt_matrix(nlp, x, lam, lam_x, mu)
            _, d, _ = sla.ldl(K.toarray(), check_finite=False)
            counts[name] = _negative_eigenvalues(d) - m
        out.append({"iteration": it, "mu": mu, "rows": K.shape[0], **counts})
    return out


def _trials(names, gait2392: bool, window=None):
    from musclemetab.datasets import example_subject, gait2392_subject01
    from musclemetab.redundancy import solve_files

    ex = example_subject()
    for name in names:
        yield name, lambda opts, n=name: solve_files(ex.model, ex.ik[n], ex.id[n], "effort-gen", options=opts,
                                                     window=window)
    if gait2392:
        g = gait2392_subject01()
        yield "gait2392 r", lambda opts: solve_files(g.model, g.ik, None, "effort-gen", external_loads=g.external_loads,
                                                     side="r", cycle="auto", options=opts)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", nargs="*", default=["slow", "normal", "fast"])
    parser.add_argument("--gait2392", action="store_true", help="also gait2392's right leg")
    parser.add_argument("--options", nargs="*", default=list(OPTION_SETS), choices=list(OPTION_SETS))
    parser.add_argument("--variant", default="as-built", choices=VARIANTS,
                        help="an equivalent form of a constraint (see use_variant)")
    parser.add_argument("--attribute", nargs="+", type=int, metavar="N",
                        help="START FRAMES ITERATION [ITERATION ...]: the surplus negative eigenvalues by constraint "
                             "family on FRAMES frames of the first trial from frame START, after each ITERATION "
                             "count of IPOPT iterations (see attribute)")
    parser.add_argument("--quick", action="store_true",
                        help="the normal trial's window 0.6-0.8 s, default options and first_pert_1e-2 (seconds)")
    args = parser.parse_args(argv)
    window = None
    if args.quick:
        from _quick import WINDOW

        args.trials, args.gait2392, args.options, args.attribute = ["normal"], False, ["default", "first_pert_1e-2"], None
        window = WINDOW
    use_variant(args.variant)
    if args.attribute:
        start, frames, *at = args.attribute
        print(f"surplus negative eigenvalues of the KKT matrix ({args.trials[0]} trial, frames {start}-{start + frames - 1};"
              f" the column of a family: its multipliers set to zero)")
        for r in attribute(args.trials[0], start, frames, at):
            print("  ".join(f"{key} {value:.1e}" if key == "mu" else f"{key} {value}" for key, value in r.items()), flush=True)
        return 0
    shared = HERE.parent.parent / "shared" / "data"
    if not os.environ.get("MUSCLEMETAB_DATA") and shared.is_dir():  # else the package downloads the data
        os.environ["MUSCLEMETAB_DATA"] = str(shared)
    print(f"inertia corrections ({args.variant} constraints): {os.cpu_count()} cores, load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"{'trial':<11} {'options':<22} {'status':<16} {'it':>4} {'fact':>5} {'wrong':>5} {'pert.it':>7} "
          f"{'fact/it':>7} {'excess':>6} {'solve s':>8} {'objective':>15} {'rel. change':>11}")
    for trial, solve in _trials(args.trials, args.gait2392, window):
        reference = None
        for name in args.options:
            r = solve_counted(solve, OPTION_SETS[name])
            if name == "default":
                reference = r["objective"]
            change = f"{r['objective'] / reference - 1:+.1e}" if reference else "n/a"
            print(f"{trial:<11} {name:<22} {r['status']:<16} {r['iterations']:>4} {r['factorisations']:>5} "
                  f"{r['wrong_inertia']:>5} {r['perturbed_iterations']:>7} "
                  f"{r['factorisations'] / max(r['iterations'], 1):>7.2f} {r['max_excess_negative']:>6} "
                  f"{r['solve_s']:>8.2f} {r['objective']:>15.9e} {change:>11}", flush=True)
    print(f"load average at the end {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
