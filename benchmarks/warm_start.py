"""How cheap can a warm-started EFFORT-TEN solve be? Starting points and barrier settings compared.

    python benchmarks/warm_start.py [--trial normal]
    python benchmarks/warm_start.py --across-trials [--trial normal]
    python benchmarks/warm_start.py --quick

On one trial of the example subject (EFFORT-GEN solved first, cold), EFFORT-TEN is solved:

* cold (static optimisation, IPOPT's ``mu_init`` 0.1: the study's procedure);
* warm from the EFFORT-GEN solution with ``mu_init`` 1e-6 (``solve_files(warm_start=...)``, the
  package's warm start);
* the same with IPOPT's ``warm_start_init_point`` and EFFORT-GEN's multipliers (``lam_x``, ``lam_g``:
  the problems have the same variables and constraints), with IPOPT's default and with small
  warm-start bound pushes;
* warm from EFFORT-GEN's solution adapted to EFFORT-TEN's parameters (the same tendon forces,
  fiber states that give them: :func:`musclemetab.uncertainty.adapted_start`);
* warm from EFFORT-TEN's own cold optimum (the floor of any warm start that follows the barrier
  path from 1e-6);
* warm from EFFORT-GEN with ``mu_init`` 1e-7, 1e-8 and 1e-9 (no barrier path from 1e-6).

``--across-trials``: instead, EFFORT-GEN of the other two trials started from this trial's
EFFORT-GEN solution (resampled over the window's normalised time) at ``mu_init`` 1e-6 to 0.1,
against their cold solves.

Printed per variant: IPOPT's iterations, its CPU time (``solve_cpu_time_s``) and the objective's
relative difference to the cold solve's. The CPU times are comparable within one run only.

``--quick``: the package's warm start and the one from EFFORT-TEN's own optimum alone, on the
window 0.6-0.8 s of the normal trial (geometry from the package's
cache; a check that the script runs, its times say nothing of a whole trial's).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trial", default="normal", choices=("slow", "normal", "fast"))
    ap.add_argument("--across-trials", action="store_true",
                    help="instead: EFFORT-GEN of the other trials started from this trial's EFFORT-GEN")
    ap.add_argument("--quick", action="store_true", help="two warm starts on the normal trial's window 0.6-0.8 s (seconds)")
    args = ap.parse_args(argv)
    window = None
    if args.quick:
        from _quick import WINDOW

        args.trial, args.across_trials, window = "normal", False, WINDOW
    if args.across_trials:
        return across_trials(args.trial)
    sys.path.insert(0, str(HERE))
    from solver import _example

    import musclemetab.redundancy.ipopt as ipopt_module
    from musclemetab.redundancy import SolverOptions, solve_files
    from musclemetab.uncertainty import adapted_start

    ex = _example()
    kkt: dict = {}
    start_multipliers: dict = {}
    run_ipopt = ipopt_module.run_ipopt

    def recording_run_ipopt(solver, options, x0, lbx, ubx, lbg, ubg, multipliers=None, p=None):
        """IPOPT as the package runs it, keeping the optimum's multipliers, or started from
        ``start_multipliers`` (a measurement only: the package has no such option)."""
        if not start_multipliers:
            out = run_ipopt(solver, options, x0, lbx, ubx, lbg, ubg, kkt, p=p)
            kkt["x"] = out[0]
            if multipliers is not None:
                multipliers.update(lam_g=kkt["lam_g"], lam_x=kkt["lam_x"])
            return out
        t0, c0 = time.perf_counter(), time.process_time()
        sol = solver(x0=start_multipliers["x"], p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg,
                     lam_x0=start_multipliers["lam_x"], lam_g0=start_multipliers["lam_g"])
        if multipliers is not None:
            multipliers.update(lam_g=np.asarray(sol["lam_g"]).ravel(), lam_x=np.asarray(sol["lam_x"]).ravel())
        return (np.asarray(sol["x"]).ravel(), np.asarray(sol["g"]).ravel(), float(sol["f"]), solver.stats(),
                time.perf_counter() - t0, time.process_time() - c0)

    ipopt_module.run_ipopt = recording_run_ipopt

    def solve(workflow, warm=None, ipopt=None, multipliers=None):
        start_multipliers.clear()
        start_multipliers.update(multipliers or {})
        return solve_files(ex.model, ex.ik[args.trial], ex.id[args.trial], workflow,
                           passive=None if workflow == "effort-gen" else ex.passive_moments_mat,
                           tendon_stiffness="example" if workflow == "effort-ten" else None,
                           warm_start=warm, options=SolverOptions(ipopt=dict(ipopt or {})), window=window)

    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}; trial {args.trial}"
          + (f", window {window[0]:g}-{window[1]:g} s" if window else ""))
    gen = solve("effort-gen")
    gen_point = dict(kkt)
    cold = solve("effort-ten")
    rows = [("EFFORT-GEN, cold", gen), ("EFFORT-TEN, cold (the study's)", cold)]
    push = {"warm_start_bound_push": 1e-9, "warm_start_mult_bound_push": 1e-9}
    variants = [
        ("warm from GEN, mu_init 1e-6 (the package's)", dict(warm=gen)),
        ("  + GEN's multipliers (warm_start_init_point)", dict(warm=gen, multipliers=gen_point,
                                                           ipopt={"mu_init": 1e-6, "warm_start_init_point": "yes"})),
        ("  + multipliers, bound pushes 1e-9", dict(warm=gen, multipliers=gen_point,
                                                 ipopt={"mu_init": 1e-6, "warm_start_init_point": "yes", **push})),
        ("warm from GEN adapted to TEN's parameters", dict(warm=adapted_start(gen, cold.parameters))),
        ("warm from TEN's own cold optimum", dict(warm=cold)),
        ("warm from GEN, mu_init 1e-7", dict(warm=gen, ipopt={"mu_init": 1e-7})),
        ("warm from GEN, mu_init 1e-8", dict(warm=gen, ipopt={"mu_init": 1e-8})),
        ("warm from GEN, mu_init 1e-9", dict(warm=gen, ipopt={"mu_init": 1e-9})),
    ]
    if args.quick:  # the package's warm start and the floor of any warm start
        variants = [variants[0], variants[4]]
    for label, kw in variants:
        rows.append((label, solve("effort-ten", **kw)))
    f_cold = cold.record.objective
    print(f"\n{'EFFORT-TEN start':<48} {'iterations':>10} {'IPOPT CPU s':>12} {'objective':>14} {'vs cold':>10}")
    for label, sol in rows:
        r = sol.record
        diff = "" if sol is gen else f"{(r.objective - f_cold) / f_cold:+.1e}"
        print(f"{label:<48} {r.iterations:>10d} {r.solve_cpu_time_s:>12.2f} {r.objective:>14.8g} {diff:>10}")
    cpu_gen, cpu_cold = gen.record.solve_cpu_time_s, cold.record.solve_cpu_time_s
    by_label = dict(rows)
    floor = by_label["warm from TEN's own cold optimum"].record.solve_cpu_time_s
    package = by_label["warm from GEN, mu_init 1e-6 (the package's)"].record.solve_cpu_time_s
    print(f"\nchain GEN -> TEN: cold {cpu_gen + cpu_cold:.2f} CPU s; with the package's warm start "
          f"{(cpu_gen + package) / (cpu_gen + cpu_cold):.2f}x; with a warm start as cheap "
          f"as one from TEN's own optimum {(cpu_gen + floor) / (cpu_gen + cpu_cold):.2f}x")
    return 0


def across_trials(source: str) -> int:
    """EFFORT-GEN of each other trial started from ``source``'s EFFORT-GEN solution, resampled over
    the window's normalised time (the trials are one gait cycle each), at several ``mu_init``,
    against its cold solve: iterations, IPOPT CPU s, objective difference."""
    sys.path.insert(0, str(HERE))
    from solver import _example

    from musclemetab.redundancy import SolverOptions, solve_files
    from musclemetab.redundancy.ipopt import solve_ocp
    from musclemetab.redundancy.sensitivity import problem_of_solution
    from musclemetab.redundancy.static_opt import InitialGuess

    ex = _example()
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}; EFFORT-GEN started from {source}'s")
    ref = solve_files(ex.model, ex.ik[source], ex.id[source], "effort-gen")
    s_ref = (ref.time_s - ref.time_s[0]) / (ref.time_s[-1] - ref.time_s[0])
    print(f"{'trial, start':<34} {'iterations':>10} {'IPOPT CPU s':>12} {'vs cold':>10}")
    for trial in ("slow", "normal", "fast"):
        if trial == source:
            continue
        cold = solve_files(ex.model, ex.ik[trial], ex.id[trial], "effort-gen")
        prob = problem_of_solution(cold)
        inputs, params = prob.inputs, prob.params.subset(prob.inputs.muscles)
        N, s = inputs.n_intervals, (inputs.mesh_time_s - inputs.mesh_time_s[0]) / (inputs.mesh_time_s[-1] -
                                                                                    inputs.mesh_time_s[0])

        def resampled(a):
            return np.column_stack([np.interp(s, s_ref[:a.shape[0]] if a.shape[0] == s_ref.size else
                                              s_ref[:-1], a[:, j]) for j in range(a.shape[1])])

        lm = resampled(ref.lm_norm)
        guess = InitialGuess(activation=resampled(ref.activation), lm_norm=lm,
                             lm_projected_m=np.sqrt(np.maximum((lm * params.optimal_fiber_length_m) ** 2
                                                               - params.width_m ** 2, 0.0)),
                             excitation=resampled(ref.excitation)[:N], reserve=resampled(ref.reserve_Nm)[:N] / 150.0,
                             fiber_velocity_lmo_per_s=resampled(ref.fiber_velocity_lmo_per_s)[:N])
        r = cold.record
        print(f"{trial + ', cold (the study)':<34} {r.iterations:>10d} {r.solve_cpu_time_s:>12.2f} {'':>10}")
        for mu in (1e-6, 1e-4, 1e-3, 1e-2, 1e-1):
            o = solve_ocp(inputs, params, guess, SolverOptions(ipopt={"mu_init": mu}), prob.goals)
            label = f"{trial}, from {source}, mu_init {mu:g}"
            print(f"{label:<34} {o.iterations:>10d} {o.solve_cpu_s:>12.2f} "
                  f"{(o.objective - cold.objective) / cold.objective:>+10.1e}{'' if o.success else ' ' + o.status}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
