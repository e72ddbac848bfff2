"""How cheap can a warm-started EFFORT-TEN solve be? Starting points and barrier settings compared.

    python benchmarks/warm_start.py [--trial normal]
    python benchmarks/warm_start.py --across-trials [--trial normal]

    python benchmarks/warm_start.py --trial slow --workflow effort-cal [--repeats 2]
    python benchmarks/warm_start.py --trial normal --workflow effort-gen --samples 1 2

On one trial of the example subject (EFFORT-GEN solved first, cold), EFFORT-TEN (or
``--workflow effort-cal``) is solved, with the package's default stop (the optimum):

* cold (static optimisation, IPOPT's ``mu_init`` 0.1: the study's procedure);
* warm from the EFFORT-GEN solution with ``mu_init`` 1e-6 (``solve_files(warm_start=...)``, the
  package's warm start from a solution read from files), and from the solution in memory, whose
  optimum and multipliers the package hands to IPOPT's warm start (``Solution.multipliers``);
* the same with IPOPT's ``warm_start_init_point`` and EFFORT-GEN's multipliers (``lam_x``, ``lam_g``:
  the problems have the same variables and constraints), with IPOPT's default and with small
  warm-start bound pushes (``warm_start_bound_push``, ``warm_start_mult_bound_push`` and
  ``warm_start_slack_bound_push`` 1e-9 to 1e-2), with the fractions (``warm_start_bound_frac``,
  ``warm_start_slack_bound_frac``) as small and ``mu_init`` at 1e-4 or EFFORT-GEN's last barrier
  parameter, with the bound multipliers alone, and from a monotone barrier at ``mu_init`` 1e-9 and 1e-4;
* warm from EFFORT-GEN's solution adapted to EFFORT-TEN's parameters (the same tendon forces,
  fiber states that give them: :func:`musclemetab.uncertainty.adapted_start`);
* warm from EFFORT-TEN's own cold optimum (the floor of any warm start that follows the barrier
  path from 1e-6);
* warm from EFFORT-GEN with ``mu_init`` 1e-7, 1e-8 and 1e-9 (no barrier path from 1e-6).

``--samples K ...``: instead, uncertainty samples of the trial's ``--workflow`` (EFFORT-GEN too),
from the cold, adapted and multiplier starts (:func:`samples`; docs/solver.md, "Uncertainty
samples start from the nominal's multipliers").

``--across-trials``: instead, EFFORT-GEN of the other two trials started from this trial's
EFFORT-GEN solution (resampled over the window's normalised time) at ``mu_init`` 1e-6 to 0.1,
against their cold solves.

Printed per variant: IPOPT's iterations, its CPU time (``solve_cpu_time_s``), the objective's
relative difference to the cold solve's, and the largest relative differences to the cold
solve's rates: the whole-body rates of the six study models and the rate of every muscle above
1 % of its leg's. The CPU times are comparable within one run only; ``--repeats N`` solves the
cold problem and each variant N times, alternately, and prints the CPU range (docs/solver.md,
"Warm starts at the optimum").

``--quick``: the package's warm start and the one from the second workflow's own optimum alone,
on the window 0.6-0.8 s of the trial (geometry from the package's cache; a check that the script
runs, its times say nothing of a whole trial's).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trial", default="normal", choices=("slow", "normal", "fast"))
    ap.add_argument("--workflow", default="effort-ten", choices=("effort-ten", "effort-cal", "effort-gen"),
                    help="the second solve of the chain (default effort-ten)")
    ap.add_argument("--repeats", type=int, default=1, help="solves of the cold problem and of each variant, alternately")
    ap.add_argument("--quick", action="store_true",
                    help="the package's warm start and the one from the workflow's own optimum, on 0.6-0.8 s")
    ap.add_argument("--samples", type=int, nargs="+", metavar="K",
                    help="instead: uncertainty samples K (package priors, seed 1) of --workflow (effort-gen too)")
    ap.add_argument("--across-trials", action="store_true",
                    help="instead: EFFORT-GEN of the other trials started from this trial's EFFORT-GEN")
    args = ap.parse_args(argv)
    if args.across_trials:
        return across_trials(args.trial)
    sys.path.insert(0, str(HERE))
    from solver import _example

    import musclemetab.redundancy.ipopt as ipopt_module
    from musclemetab.redundancy import SolverOptions, solve_files
    from musclemetab.uncertainty import adapted_start

    ex = _example()
    window = (0.6, 0.8) if args.quick else None
    kkt: dict = {}
    start_multipliers: dict = {}
    run_ipopt = ipopt_module.run_ipopt

    def recording_run_ipopt(solver, options, x0, lbx, ubx, lbg, ubg, multipliers=None, p=None, start=None):
        """IPOPT as the package runs it (from ``start``, a solution's optimum and multipliers, when
        the package gives one), keeping the optimum's multipliers, or started from
        ``start_multipliers`` with the variant's own IPOPT options."""
        if not start_multipliers:
            out = run_ipopt(solver, options, x0, lbx, ubx, lbg, ubg, kkt, p=p, start=start)
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

    def solve(workflow, warm=None, ipopt=None, multipliers=None, keep_multipliers=False, transform=None):
        start_multipliers.clear()
        start_multipliers.update(multipliers or {})
        if warm is not None and not keep_multipliers:  # a start from the states alone, as from a solution folder
            warm = replace(warm, multipliers=None)
        return solve_files(ex.model, ex.ik[args.trial], ex.id[args.trial], workflow, window=window,
                           passive=None if workflow == "effort-gen" else ex.passive_moments_mat,
                           tendon_stiffness="example" if workflow == "effort-ten" else None,
                           warm_start=warm, options=SolverOptions(ipopt=dict(ipopt or {})),
                           **({} if transform is None else {"parameter_transform": transform}))

    def pushes(v):
        return {"warm_start_init_point": "yes", "warm_start_bound_push": v, "warm_start_mult_bound_push": v,
                "warm_start_slack_bound_push": v}

    if args.samples:
        return samples(args, ex, solve, kkt, pushes)
    if args.workflow == "effort-gen":
        ap.error("--workflow effort-gen needs --samples")

    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}; trial {args.trial}, "
          f"EFFORT-GEN -> {args.workflow.upper()}" + (f", window {window[0]:g}-{window[1]:g} s" if window else ""))
    wf = args.workflow
    gen = solve("effort-gen")
    gen_point = dict(kkt)
    cold = solve(wf)
    cold_rates = _rates(cold, ex)

    mu_gen = gen.record.convergence.get("final_barrier_parameter") or 1e-11

    def fractions(v, mu, **more):
        return {**pushes(v), "warm_start_bound_frac": v, "warm_start_slack_bound_frac": v, "mu_init": mu, **more}

    variants = [("cold (static optimisation)", {}),
                ("warm from GEN, mu_init 1e-6 (the package's)", dict(warm=gen)),
                ("warm from GEN in memory (optimum and multipliers)", dict(warm=gen, keep_multipliers=True)),
                (f"warm from GEN adapted to {wf.upper()}'s parameters", dict(warm=adapted_start(gen, cold.parameters)))]
    for v in (1e-9, 1e-6, 1e-4, 1e-3, 1e-2):
        variants.append((f"  + GEN's multipliers, pushes {v:g}",
                         dict(warm=gen, multipliers=gen_point, ipopt=pushes(v))))
    variants += [
        ("  + multipliers, pushes and fractions 1e-4, mu_init 1e-4",
         dict(warm=gen, multipliers=gen_point, ipopt=fractions(1e-4, 1e-4))),
        ("  + multipliers, pushes and fractions 1e-6, mu_init GEN's last",
         dict(warm=gen, multipliers=gen_point, ipopt=fractions(1e-6, mu_gen))),
        ("  + multipliers, pushes and fractions 1e-9, mu_init GEN's last",
         dict(warm=gen, multipliers=gen_point, ipopt=fractions(1e-9, mu_gen))),
        ("  + multipliers, pushes 1e-4, monotone from 1e-4",
         dict(warm=gen, multipliers=gen_point, ipopt=fractions(1e-4, 1e-4, mu_strategy="monotone"))),
        ("  + bound multipliers only (lam_g 0), pushes 1e-4",
         dict(warm=gen, multipliers={**gen_point, "lam_g": 0 * gen_point["lam_g"]}, ipopt=pushes(1e-4))),
        ("  + multipliers, pushes 1e-9, monotone from 1e-9",
         dict(warm=gen, multipliers=gen_point, ipopt={**pushes(1e-9), "mu_strategy": "monotone", "mu_init": 1e-9})),
        (f"warm from {wf.upper()}'s own cold optimum", dict(warm=cold)),
        ("warm from GEN, mu_init 1e-9", dict(warm=gen, ipopt={"mu_init": 1e-9})),
    ]
    if args.quick:  # the package's warm start and the floor of any warm start (the cold solve above: the reference)
        variants = [v for v in variants if v[0] in ("warm from GEN, mu_init 1e-6 (the package's)",
                                                    f"warm from {wf.upper()}'s own cold optimum")]
    rows = {label: [] for label, _ in variants}
    for _ in range(args.repeats):
        for label, kw in variants:
            rows[label].append(solve(wf, **kw))
    f_cold = cold.record.objective
    print(f"\n{wf.upper() + ' start':<52} {'iterations':>10} {'IPOPT CPU s':>12} {'objective':>14} {'vs cold':>9} "
          f"{'whole body':>10} {'muscles':>9}")
    for label, sols in rows.items():
        r = sols[0].record
        cpu = sorted(s.record.solve_cpu_time_s for s in sols)
        cpu_text = f"{cpu[0]:.2f}" if len(cpu) == 1 else f"{cpu[0]:.2f}-{cpu[-1]:.2f}"
        if sols[0].success:
            body, muscles = _rate_difference(_rates(sols[0], ex), cold_rates)
            rates = f"{100 * body:>9.4f}% {100 * muscles:>8.4f}%"
        else:
            rates = f"{r.status}"
        print(f"{label:<52} {r.iterations:>10d} {cpu_text:>12} {r.objective:>14.8g} "
              f"{(r.objective - f_cold) / f_cold:>+9.1e} {rates}")
    return 0


def samples(args, ex, solve, kkt, pushes) -> int:
    """Uncertainty samples ``args.samples`` of ``args.workflow`` on ``args.trial`` (the package's
    priors, seed 1): cold, from the nominal solution adapted to the sample (``adapted_start``,
    ``mu_init`` 1e-6), from the nominal optimum and multipliers with pushes 1e-4 and with IPOPT's
    default pushes 1e-3 (``sample_start``, what a study's sample does); iterations, IPOPT CPU s,
    CPU over cold, objective and rates against cold."""
    from musclemetab.uncertainty import DEFAULT_SEED, adapted_start, draw, read_priors, sample_start

    wf = args.workflow
    nominal = solve(wf)
    point = dict(kkt)
    print(f"nominal {wf.upper()}: {nominal.record.iterations} iterations, {nominal.record.solve_cpu_time_s:.2f} CPU s")
    for k in args.samples:
        t = draw(read_priors(None), nominal.muscles, k, DEFAULT_SEED).parameters
        variants = {"cold": dict(transform=t),
                    "adapted nominal, mu_init 1e-6": dict(warm=adapted_start(nominal, t(nominal.parameters)), transform=t),
                    "nominal optimum and multipliers, pushes 1e-4": dict(warm=nominal, multipliers=point,
                                                                         ipopt=pushes(1e-4), transform=t),
                    "the same, pushes 1e-3 (the package's)": dict(warm=sample_start(nominal, t(nominal.parameters)),
                                                                  keep_multipliers=True, transform=t)}
        rows = {label: [solve(wf, **kw) for _ in range(args.repeats)] for label, kw in variants.items()}
        cold = rows["cold"]
        cold_rates, cpu_cold = _rates(cold[0], ex), np.median([s.record.solve_cpu_time_s for s in cold])
        print(f"\nsample {k}, load average {os.getloadavg()[0]:.1f}")
        print(f"{'start':<48} {'iterations':>10} {'IPOPT CPU s':>12} {'x cold':>6} {'objective':>9} {'whole body':>10} "
              f"{'muscles':>9}")
        for label, sols in rows.items():
            r, cpu = sols[0].record, sorted(s.record.solve_cpu_time_s for s in sols)
            body, muscles = _rate_difference(_rates(sols[0], ex), cold_rates)
            print(f"{label:<48} {r.iterations:>10d} {cpu[0]:>5.2f}-{cpu[-1]:<6.2f} {np.median(cpu) / cpu_cold:>6.2f} "
                  f"{(r.objective - cold[0].objective) / cold[0].objective:>+9.1e} {100 * body:>9.4f}% {100 * muscles:>8.4f}%")
    return 0


#: the study's six metabolic models
MODELS = ("UM03", "BH04", "HO06", "LW07", "UM10", "UC16")


def _rates(solution, subject):
    """``(whole-body rate per model, mean rate per muscle per model)`` with ``subject``'s mass and height."""
    from musclemetab.metabolics.solution import metabolics_from_solution

    result = metabolics_from_solution(solution, subject.body_mass_kg, subject.height_m, models=list(MODELS))
    return ({m: result.whole_body[m].mean_W_per_kg for m in MODELS},
            {m: result.rates[m].total.mean(axis=1) for m in MODELS})


def _rate_difference(rates, reference) -> tuple[float, float]:
    """Largest relative differences: whole-body rates, and muscles above 1 % of the leg's rate."""
    body = max(abs(rates[0][m] / reference[0][m] - 1) for m in MODELS)
    muscles = 0.0
    for m in MODELS:
        ref = reference[1][m]
        big = ref > 0.01 * ref.sum()
        muscles = max(muscles, float(np.max(np.abs(rates[1][m][big] / ref[big] - 1))))
    return body, muscles


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
