"""Effort- vs energy-minimising solutions of the example subject's normal trial.

    python docs/scripts/energy_objective.py [--workflow effort-cal] [--goals effort,UM10:1:0,UM10:0.01:1]
                                            [--warm-start] [--out DIR]
    python docs/scripts/energy_objective.py --smoothing-table

Each goal is ``effort`` (the workflow's effort goal alone) or ``MODEL:W:W_EFFORT[:S[:FORM]]`` (the
energy goal of the smooth ``MODEL`` with weight ``W`` beside the effort goal with weight
``W_EFFORT``; smoothing ``S``, default (or empty) the goal's; ``FORM`` ``objective`` (default) or
``model``). Every solve starts from the static-optimisation guess; with ``--warm-start`` each energy
goal starts from the solution of ``effort`` (give it first).
Prints, per solution: IPOPT's outcome, the moment residual, the reserves, the goal's value
(the smooth model's leg mean in W/kg), smooth and exact UM10's leg mean over the same nodes
(W/kg of body mass, no basal: the yardstick for every solution), the whole-body rate of every exact model (W/kg, both
legs, 1.2 W/kg basal heat of body mass, the metabolics stage's trimming), the peak
activations of the main muscles, and their peak activations at the nodes where their fibers
lengthen; with ``--out`` the tables are also written as CSV there, and each solution folder
(``OUT/<goal with : as _>``).
The numbers of ``docs/energy_objective.md`` were made with the defaults.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

MAIN_MUSCLES = ("soleus_r", "gasmed_r", "gaslat_r", "tibant_r", "vaslat_r", "vasmed_r", "vasint_r", "recfem_r",
                "bflh_r", "semimem_r", "glmax2_r", "glmed1_r", "iliacus_r", "psoas_r")


def _goal(text, subject):
    from musclemetab.redundancy.energy import EnergyGoal

    if text == "effort":
        return None
    model, weight, effort, *rest = text.split(":")
    smoothing, form = (rest + ["", ""])[:2]
    return EnergyGoal(model, float(weight), subject.body_mass_kg, subject.height_m, effort_weight=float(effort),
                      **({"smoothing": float(smoothing)} if smoothing else {}), **({"form": form} if form else {}))


def exact_leg_mean_W_per_kg(model, sol, subject, n, form="model"):
    """The exact ``model``'s leg mean (W/kg of body mass, no basal) over nodes ``0 ... n-1``,
    muscle masses and slow-twitch fractions as the goal takes them; ``form="objective"``: the
    energy goal's form, ``H_AM + max(W + H_SL, 0)`` of the model without its non-negativity rule
    (UM03, BH04, HO06, UC16; the other models are their own objective form)."""
    from musclemetab.metabolics.registry import ALL_MODELS
    from musclemetab.redundancy.energy import CLAMPED_MODELS
    from musclemetab.metabolics.solution import states_of_solution
    from musclemetab.properties import metabolic_properties

    st = states_of_solution(sol)
    p = sol.parameters.subset(sol.muscles)
    mass, fst = metabolic_properties(list(sol.muscles), subject.body_mass_kg, subject.height_m,
                                     p.max_isometric_force_N, p.optimal_fiber_length_m)
    states = {k: v[:, :n] for k, v in st.states.items()}
    steady = {}  # as the smooth models take them: steady-state stimulation time, dF_CE/dt = 0
    if model == "BH04":  # BH04's heat off below the threshold e = 0.1
        steady["stimulation_time_s"] = np.where(states["excitation"] > 0.1, np.inf, 0.0)
    if model == "LW05":
        steady["stimulation_time_s"] = np.full_like(states["excitation"], np.inf)
        steady["fiber_force_rate_N_per_s"] = np.zeros_like(states["excitation"])
    unclamped = form == "objective" and model in CLAMPED_MODELS
    rates = ALL_MODELS[model](**states, max_isometric_force_N=p.max_isometric_force_N,
                              optimal_fiber_length_m=p.optimal_fiber_length_m,
                              max_contraction_velocity=p.max_contraction_velocity, muscle_mass_kg=mass,
                              slow_twitch_fraction=fst, basal=False, **(steady or {"time_s": st.time_s[:n]}),
                              **({"non_negative": False} if unclamped else {}))
    total = rates.total
    if unclamped:
        total = rates.activation_maintenance + np.maximum(rates.work + rates.shortening_lengthening, 0.0)
    return float(np.mean(total.sum(axis=0))) / subject.body_mass_kg


def smoothing_table(subject, workflow) -> int:
    import pandas as pd

    import warnings

    from musclemetab.metabolics.smooth import SMOOTH_MODELS
    from musclemetab.redundancy import solve_files
    from musclemetab.redundancy.energy import CLAMPED_MODELS, EnergyGoal
    from musclemetab.redundancy.objective import leg_rate_W_per_kg

    sol = solve_files(subject.model, subject.ik["normal"], subject.id["normal"], workflow)
    n = sol.summary["n_intervals"]
    rows = []
    for form in ("objective", "model"):
        for model in SMOOTH_MODELS:
            if form == "model" and model not in CLAMPED_MODELS:
                continue  # the same as its objective form
            exact = exact_leg_mean_W_per_kg(model, sol, subject, n, form)
            row = {"form": form, "model": model, "exact": exact}
            for s in (1e-2, 1e-3, 1e-4):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # the model form's warning
                    goal = EnergyGoal(model, 1.0, subject.body_mass_kg, subject.height_m, smoothing=s, form=form)
                v = float(np.mean(leg_rate_W_per_kg(goal, sol.parameters, sol.muscles, sol.excitation[:n],
                                                    sol.activation[:n], sol.lm_norm[:n],
                                                    sol.fiber_velocity_lmo_per_s[:n])))
                row[f"s={s:g}"] = v
                row[f"bias % s={s:g}"] = 100.0 * (v / exact - 1.0)
            rows.append(row)
    print(pd.DataFrame(rows).to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    return 0


def main(argv=None) -> int:
    import pandas as pd

    from musclemetab.datasets import example_subject
    from musclemetab.metabolics.solution import metabolics_from_solution
    from musclemetab.redundancy import Goals, get_workflow, solve_files
    from musclemetab.redundancy.energy import EnergyGoal
    from musclemetab.redundancy.objective import leg_rate_W_per_kg

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--workflow", default="effort-cal")
    ap.add_argument("--goals", default="effort,UM10:1:0,UM10:0.01:1")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--warm-start", action="store_true",
                    help="start each energy goal from the solution of the goal 'effort' (listed first) instead of "
                    "the static-optimisation guess")
    ap.add_argument("--smoothing-table", action="store_true",
                    help="instead: every smooth model at s = 1e-2, 1e-3, 1e-4 against its exact model on the "
                    "effort solution's nodes (leg mean, W/kg of body mass, no basal), in the goal's objective "
                    "form and, for UM03, BH04, HO06 and UC16, in the model form")
    args = ap.parse_args(argv)
    ex = example_subject()
    if args.smoothing_table:
        return smoothing_table(ex, args.workflow)
    rows, wb_rows, act_rows, len_rows = [], [], [], []
    effort = None
    for text in args.goals.split(","):
        goal = _goal(text, ex)
        t0 = time.perf_counter()
        sol = solve_files(ex.model, ex.ik["normal"], ex.id["normal"], args.workflow,
                          goals=Goals(**get_workflow(args.workflow).goals.effort_weights(), energy=goal)
                          if goal else None,
                          **({"warm_start": effort} if args.warm_start and goal and effort is not None else {}))
        if goal is None:
            effort = sol
        wall = time.perf_counter() - t0
        if args.out:  # the solution folder, for a closer look (musclemetab metabolics, plausibility)
            sol.write(args.out / text.replace(":", "_"))
        s = sol.summary
        N = s["n_intervals"]
        um10 = EnergyGoal("UM10", 1.0, ex.body_mass_kg, ex.height_m)  # the same yardstick for every solution
        rows.append({
            "goal": text, "status": s["status"], "iterations": s["iterations"], "wall_s": round(wall, 1),
            "max_moment_residual_Nm": s["max_moment_residual_Nm"],
            "max_reserve_rms_Nm": max(s["reserve_rms_Nm"].values()),
            "objective": s["objective"], **{f"term_{k}": v for k, v in s["objective_terms"].items()},
            "goal_leg_mean_W_per_kg": (s.get("energy_goal") or {}).get("leg_mean_W_per_kg", np.nan),
            "smooth_UM10_leg_mean_W_per_kg": float(np.mean(leg_rate_W_per_kg(
                um10, sol.parameters, sol.muscles, sol.excitation[:N], sol.activation[:N], sol.lm_norm[:N],
                sol.fiber_velocity_lmo_per_s[:N]))),
        })
        if sol.success:
            rows[-1]["exact_UM10_leg_mean_W_per_kg"] = exact_leg_mean_W_per_kg("UM10", sol, ex, N)
            if goal is not None:  # the goal's own model, exact, in both forms
                for form in ("objective", "model"):
                    rows[-1][f"exact_goal_{form}_leg_mean_W_per_kg"] = exact_leg_mean_W_per_kg(goal.model, sol, ex,
                                                                                                N, form)
        if not sol.success:
            print(f"{text}: {s['status']} (not evaluated further)")
            continue
        met = metabolics_from_solution(sol, ex.body_mass_kg, ex.height_m, models="all,LW05,MA68")
        wb_rows.append({"goal": text, **{m: met.whole_body[m].mean_W_per_kg for m in met.models}})
        act_rows.append({"goal": text, **{m: float(np.max(sol.activation[:, sol.muscle_index(m)]))
                                          for m in MAIN_MUSCLES if m in sol.muscles}})
        lengthening = sol.fiber_velocity_lmo_per_s > 0
        len_rows.append({"goal": text, **{m: float(np.max(sol.activation[:, i], initial=0.0,
                                                            where=lengthening[:, i]))
                                          for m in MAIN_MUSCLES if m in sol.muscles
                                          for i in [sol.muscle_index(m)]}})
        print(f"{text}: {s['status']} in {s['iterations']} iterations, {wall:.1f} s", flush=True)
    tables = {"solves": pd.DataFrame(rows), "whole_body_W_per_kg": pd.DataFrame(wb_rows),
              "peak_activation": pd.DataFrame(act_rows),
              "peak_activation_lengthening": pd.DataFrame(len_rows)}
    for name, df in tables.items():
        print(f"\n{name}\n{df.to_string(index=False, float_format=lambda v: f'{v:.4g}')}")
        if args.out:
            args.out.mkdir(parents=True, exist_ok=True)
            df.to_csv(args.out / f"{name}.csv", index=False, float_format="%.6g")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
