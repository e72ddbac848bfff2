"""Solve one trial with one workflow: inputs -> static optimisation -> OCP -> :class:`Solution`.

:func:`solve_trial` works on arrays (a geometry-like object, model parameters, the ID
moments); :func:`musclemetab.redundancy.run.solve_files` reads the files and calls it.
"""

from __future__ import annotations

import os
import time as _time
from dataclasses import replace
from typing import Mapping

import numpy as np

from .inputs import (
    MESH_FREQUENCY_HZ,
    check_moment_magnitudes,
    trial_inputs,
    restrict_geometry,
)
from .parameters import MuscleTendonParameters
from .ipopt import SolverOptions, single_trial_goals, solve_ocp
from .transcription import Goals
from .record import RunRecord
from .records_build import input_preparation, trial_solution
from .solution import Solution
from .static_opt import guess_from_solution, initial_guess, static_optimisation
from .workflows import (
    PassiveParameters,
    get_workflow,
    workflow_parameters,
)

__all__ = ["solve_trial", "solve_with_parameters", "prepare_trial", "workflow_goals", "muscles_at_fiber_length_bound", "WARM_START_MU_INIT"]

#: Barrier parameter at the start of a warm-started solve (the default start uses IPOPT's 0.1).
WARM_START_MU_INIT = 1e-6


def prepare_trial(geometry, params: MuscleTendonParameters, id_time_s, id_moments_Nm, *, ik_time_s=None,
                  options: SolverOptions | None = None, sources: dict | None = None, check_units: bool = True,
                  filter_inputs: bool = True, mesh_frequency_hz: float = MESH_FREQUENCY_HZ):
    """Mesh inputs of one trial (muscles and DOFs the problem keeps), its parameters and the
    static optimisation of its initial guess: ``(inputs, params, static optimisation)``."""
    options = options or SolverOptions()
    all_dofs = tuple(geometry.dofs)
    geometry = restrict_geometry(geometry)
    if tuple(geometry.dofs) != all_dofs:
        keep = [all_dofs.index(d) for d in geometry.dofs]
        id_moments_Nm = np.asarray(id_moments_Nm, dtype=float).reshape(len(id_time_s), -1)[:, keep]
    params = params.subset(geometry.muscles)
    inputs = trial_inputs(geometry, id_time_s, id_moments_Nm, ik_time_s=ik_time_s,
                            filter_inputs=filter_inputs, mesh_frequency_hz=mesh_frequency_hz,
                            sources=dict(sources or {}))
    if check_units:
        check_moment_magnitudes(inputs.moments_frames_Nm, inputs.dofs, inputs.moment_arms_frames_m,
                                params.max_isometric_force_N, (sources or {}).get("id", "inverse dynamics"),
                                options.optimal_reserve_Nm)
    return inputs, params, static_optimisation(inputs, params)


def solve_with_parameters(
    geometry,
    params: MuscleTendonParameters,
    id_time_s: np.ndarray,
    id_moments_Nm: np.ndarray,
    *,
    ik_time_s: np.ndarray | None = None,
    options: SolverOptions | None = None,
    goals: Goals | None = None,
    workflow_record: dict | None = None,
    sources: dict | None = None,
    check_units: bool = True,
    filter_inputs: bool = True,
    warm_start: Solution | None = None,
    mesh_frequency_hz: float = MESH_FREQUENCY_HZ,
) -> Solution:
    """Solve the muscle redundancy problem with explicit muscle parameters, ``goals`` (default
    ``Goals()``: the effort weights ``[wAct, wTres, wVm] = [1, 1000, 0.01]``; also the energy goal
    and the fiber dynamics) and the numerical settings ``options``.

    ``id_moments_Nm`` columns follow ``geometry.dofs``. Returns a :class:`Solution` whose
    ``summary['status']``/``success`` report IPOPT's outcome (a failed solve is returned, not
    raised, so that it can be inspected; :meth:`Solution.load` refuses it by default).

    ``warm_start``: a previous solution of the same trial (same mesh and muscles, e.g. another
    workflow) used as initial guess, with IPOPT's barrier parameter starting at 1e-6. This is
    an option for speed, not the study's procedure: the problem has several local optima and a
    warm-started solve may end in another one (``summary['initial_guess']`` records it).
    """
    t_start = _time.perf_counter()
    goals, options = single_trial_goals(goals), options or SolverOptions()
    inputs, params, so = prepare_trial(geometry, params, id_time_s, id_moments_Nm, ik_time_s=ik_time_s,
                                       options=options, sources=sources, check_units=check_units,
                                       filter_inputs=filter_inputs, mesh_frequency_hz=mesh_frequency_hz)
    if warm_start is None:
        guess = initial_guess(inputs, params, so)
    else:
        guess = guess_from_solution(warm_start, inputs, params, options.optimal_reserve_Nm)
        if guess.start is None:  # from its optimum and multipliers: IPOPT's warm start (ipopt.py)
            options = options.with_(ipopt={"mu_init": WARM_START_MU_INIT, **options.ipopt})
    t_prep = _time.perf_counter() - t_start
    ocp = solve_ocp(inputs, params, guess, options, goals)
    energy = {}
    if goals.energy is not None:
        from .objective import leg_rate_W_per_kg

        N = inputs.n_intervals
        rate = leg_rate_W_per_kg(goals.energy, params, inputs.muscles, ocp.excitation, ocp.activation[:N],
                                 ocp.lm_norm[:N], ocp.fiber_velocity_lmo_per_s)
        energy = {"energy_goal": {**goals.energy.record(), "w_activation": goals.w_activation,
                                  "leg_mean_W_per_kg": float(np.mean(rate))},
                  "energy_form": goals.energy.form_record()}
    solution = trial_solution(
        "effort", RunRecord.from_result(ocp, sources), inputs, params, options, goals, ocp,
        fiber_dynamics=goals.fiber_dynamics, sources=sources, preparation_time_s=t_prep,
        problem_size={"variables": ocp.n_variables, "equality_constraints": ocp.n_constraints},
        static_optimisation_objective=so.objective,
        initial_guess="static optimisation (rigid tendons)" if warm_start is None else
        f"warm start from {warm_start.record.workflow_name or 'a previous solution'} "
        + ("(its optimum and multipliers)" if ocp.started_from_optimum else
           f"(mu_init {WARM_START_MU_INIT:g})" if guess.start is None else "(its states)"),
        workflow=dict(workflow_record or {"name": "custom"}),
        input_preparation=input_preparation(filter_inputs, mesh_frequency_hz), **energy)
    return replace(solution, record=solution.record.with_(total_time_s=_time.perf_counter() - t_start))


def solve_trial(
    geometry,
    model_parameters,
    id_time_s: np.ndarray,
    id_moments_Nm: np.ndarray,
    workflow: str = "effort-gen",
    *,
    ik_time_s: np.ndarray | None = None,
    passive: str | os.PathLike | PassiveParameters | None = None,
    tendon_stiffness: Mapping[str, float] | None = None,
    tendon_stiffness_file: str | os.PathLike | None = None,
    options: SolverOptions | None = None,
    goals: Goals | None = None,
    sources: dict | None = None,
    check_units: bool = True,
    warm_start: Solution | None = None,
    mesh_frequency_hz: float = MESH_FREQUENCY_HZ,
    parameter_transform=None,
) -> Solution:
    """Solve one trial with a named workflow (``effort-gen``, ``effort-cal``, ``effort-ten``).

    See :func:`musclemetab.redundancy.workflows.workflow_parameters` for ``passive`` and the
    tendon-stiffness arguments. The effort weights are those of ``goals``, by default the
    workflow's (``Workflow.goals``); the effort weight of ``goals.energy``, when it has one,
    overrides ``w_activation``. ``parameter_transform`` (a function of the workflow's
    :class:`MuscleTendonParameters`) gives the parameters solved with instead (e.g. a sample of
    :mod:`musclemetab.uncertainty`).
    """
    wf = get_workflow(workflow)
    params, record = workflow_parameters(
        wf, model_parameters, restrict_geometry(geometry).muscles, passive=passive,
        tendon_stiffness=tendon_stiffness, tendon_stiffness_file=tendon_stiffness_file,
    )
    if parameter_transform is not None:
        params = parameter_transform(params)
    goals, options = workflow_goals(wf, goals, options)
    return solve_with_parameters(
        geometry, params, id_time_s, id_moments_Nm, ik_time_s=ik_time_s, options=options, goals=goals,
        workflow_record=record, sources=sources, check_units=check_units, warm_start=warm_start,
        mesh_frequency_hz=mesh_frequency_hz,
    )


def workflow_goals(workflow, goals: Goals | None, options: SolverOptions | None) -> tuple[Goals, SolverOptions]:
    """``(goals, options)`` of a single-trial solve of ``workflow``: ``goals`` (default the
    workflow's, checked by :func:`.ipopt.single_trial_goals`) and ``options``; the effort weight of
    the energy goal, when it has one, overrides ``w_activation``."""
    goals, options = single_trial_goals(goals or get_workflow(workflow).goals), options or SolverOptions()
    effort = goals.energy.effort_weight if goals.energy is not None else None
    if effort is not None:
        goals = replace(goals, w_activation=effort)
    return goals, options


def muscles_at_fiber_length_bound(solution: Solution, tolerance: float = 1e-3) -> list[str]:
    """Muscles whose normalised fiber length reaches the problem's upper bound somewhere
    (1.7, or the widened bound recorded in ``summary['fiber_length_bounds']``)."""
    from .bounds import FIBER_LENGTH_BOUNDS

    widened = (solution.record.fiber_length_bounds or {}).get("widened_upper", {})
    top = np.max(np.asarray(solution.lm_norm, dtype=float), axis=0)
    return [m for m, v in zip(solution.muscles, top) if v >= widened.get(m, FIBER_LENGTH_BOUNDS[1]) - tolerance]
