"""EMG-TEN and EMG-informed solves from arrays (:func:`musclemetab.redundancy.emg_run.solve_emg_ten`
reads the files): trials prepared (mesh
inputs, EMG at the nodes, initial guess), the problem of :mod:`.emg_ten` solved, the result
assembled (:mod:`.result`), with the standard errors and correlations of the estimated factors
(:func:`record_identifiability`)."""

from __future__ import annotations

import time as _time
from dataclasses import replace
from typing import Sequence

import numpy as np

from ..errors import DataMismatchError, OptionError, UnknownMuscleError
from ..messages import name_list
from .emg_inputs import emg_at_nodes, mapping_for_muscles, resolve_emg_mapping, trial_labels
from .emg_ten import EmgTenSettings, EmgTenTrial, settings_for_muscles, solve_emg_ten_ocp
from .result import EMG_TEN, Result, assemble_result
from .inputs import check_moment_magnitudes, restrict_geometry, trial_inputs
from .parameters import MuscleTendonParameters
from .ipopt import SolverOptions
from .static_opt import initial_guess, static_optimisation

__all__ = ["solve_emg_ten_arrays", "prepare_emg_ten_trials", "emg_ten_options", "record_identifiability"]


def solve_emg_ten_arrays(
    geometries: Sequence,
    model_parameters,
    id_data: Sequence[tuple[np.ndarray, np.ndarray]],
    emg_tables: Sequence,
    *,
    labels: Sequence[str] | None = None,
    ik_times: Sequence[np.ndarray] | None = None,
    passive=None,
    emg_mapping="default",
    settings: EmgTenSettings | None = None,
    options: SolverOptions | None = None,
    sources: Sequence[dict] | None = None,
    check_units: bool = True,
    workflow: str = EMG_TEN,
    tendon_stiffness=None,
    before_solve=None,
    parameters: tuple[MuscleTendonParameters, dict] | None = None,
) -> Result:
    """EMG-TEN from arrays: per trial a geometry-like object, ``(ID time, ID moments)`` with
    columns in the order of ``geometry.dofs``, and an EMG table (time-indexed ``DataFrame``,
    channels as columns, or already mapped to muscles by ``musclemetab.emg.map_channels``).
    ``before_solve``: see :func:`.emg_run.solve_emg_ten` (called for the trials whose ``sources``
    name their model and IK files). ``parameters``: the workflow's muscle parameters and their
    record when they are known (:class:`.problem.Problem`; ``model_parameters`` is then not used)."""
    t_start = _time.perf_counter()
    settings = settings_for_muscles(settings, restrict_geometry(list(geometries)[0]).muscles) if geometries \
        else (settings or EmgTenSettings())
    options = emg_ten_options(options, settings)
    trials, params, wf_record = prepare_emg_ten_trials(
        geometries, model_parameters, id_data, emg_tables, labels=labels, ik_times=ik_times, passive=passive,
        emg_mapping=emg_mapping, settings=settings, options=options, sources=sources, check_units=check_units,
        workflow="effort-cal" if workflow == EMG_TEN else workflow, tendon_stiffness=tendon_stiffness,
        parameters=parameters)
    t_prep = _time.perf_counter() - t_start
    if before_solve is not None and workflow != EMG_TEN:  # the solutions' muscle parameters are known
        for trial in trials:
            if trial.sources.get("model") and trial.sources.get("ik"):
                before_solve(model_path=trial.sources["model"], ik_path=trial.sources["ik"],
                             parameters=params.subset(trial.inputs.muscles), time_s=trial.inputs.mesh_time_s,
                             dofs=tuple(trial.inputs.dofs))
    ocp = solve_emg_ten_ocp(trials, params, settings, options)
    name = EMG_TEN if workflow == EMG_TEN else f"{workflow} emg-{settings.emg_mode}"
    result = assemble_result(trials, params, wf_record, ocp, settings, options, t_prep, t_start, name=name)
    if ocp.success and name == EMG_TEN and settings.goals.w_emg > 0:  # the estimate's doubts
        record_identifiability(result, trials, params, settings, options, ocp)
    return result


def record_identifiability(result: Result, trials, params, settings: EmgTenSettings, options: SolverOptions,
                           ocp) -> dict:
    """The standard errors and correlations of the estimated factors (tendon stiffness, EMG
    scales) at the optimum ``ocp`` of the EMG-TEN problem of ``trials``
    (:func:`.identifiability.identifiability`, as for ``estimate``: the inverse of the reduced
    Hessian on the factors, scaled by the EMG tracking residual); warned (a pair with
    ``|r| > 0.9``, a near-singular reduced Hessian) and recorded in ``result.record.doubts
    ["identifiability"]`` (``parameters.json``, ``solve.doubts``). The time it took is recorded
    as ``identifiability_time_s``. Needs a tracking cost (``goals.w_emg > 0``): its residual
    gives the scale of the standard errors."""
    from .emg_ten import emg_ten_problem
    from .identifiability import identifiability, warn_identifiability

    t0 = _time.perf_counter()
    blocks, goals, specs = emg_ten_problem(trials, params, settings)
    report = identifiability(blocks, params, goals, specs, ocp, optimal_reserve_Nm=options.optimal_reserve_Nm,
                             coupling=settings.coupling)
    warn_identifiability(report, remedy="couple them (EmgTenSettings tendon_groups / emg_groups) or take one as "
                         "known (a tendon group left out of the estimation)")
    report["identifiability_time_s"] = _time.perf_counter() - t0
    result.record = result.record.with_(doubts={**(result.record.doubts or {}), "identifiability": report})
    return report


def emg_ten_options(options: SolverOptions | None, settings: EmgTenSettings) -> SolverOptions:
    """``options`` (default ``SolverOptions()``) of an EMG-TEN or EMG-informed solve: numerics
    only; its goals are ``settings.goals`` (which refuse the energy goal, :class:`.emg_ten.EmgTenSettings`)."""
    return options or SolverOptions()


def prepare_emg_ten_trials(
    geometries: Sequence,
    model_parameters,
    id_data: Sequence[tuple[np.ndarray, np.ndarray]],
    emg_tables: Sequence,
    *,
    labels: Sequence[str] | None = None,
    ik_times: Sequence[np.ndarray] | None = None,
    passive=None,
    emg_mapping="default",
    settings: EmgTenSettings | None = None,
    options: SolverOptions | None = None,
    sources: Sequence[dict] | None = None,
    check_units: bool = True,
    workflow: str = "effort-cal",
    tendon_stiffness=None,
    parameters: tuple[MuscleTendonParameters, dict] | None = None,
) -> tuple[list[EmgTenTrial], MuscleTendonParameters, dict]:
    """The trials of an EMG-TEN problem (mesh inputs, EMG at the nodes, initial guess), the
    muscle parameters (calibrated passive muscle, nominal ``kT``) and their record; the
    arguments are those of :func:`solve_emg_ten_arrays`. Nothing is solved."""
    from .workflows import workflow_parameters

    settings = settings or EmgTenSettings()
    options = emg_ten_options(options, settings)
    geometries, id_data, emg_tables = list(geometries), list(id_data), list(emg_tables)
    n = len(geometries)
    if not (n == len(id_data) == len(emg_tables)) or n == 0:
        raise OptionError(f"{n} geometries, {len(id_data)} ID and {len(emg_tables)} EMG tables; give one of each "
                          "per trial (at least one trial)")
    labels = [f"trial_{i + 1}" for i in range(n)] if labels is None else trial_labels(list(range(n)), labels)
    sources = [dict(s) for s in (sources or [{} for _ in range(n)])]
    mapping = resolve_emg_mapping(emg_mapping)
    ik_times = list(ik_times) if ik_times is not None else [None] * n

    # same model (hence the same muscles and DOFs) for all trials
    all_dofs = [tuple(g.dofs) for g in geometries]
    restricted = [restrict_geometry(g) for g in geometries]
    ref = restricted[0]
    for lab, g in zip(labels[1:], restricted[1:]):
        if tuple(g.muscles) != tuple(ref.muscles) or tuple(g.dofs) != tuple(ref.dofs):
            only_a = sorted(set(ref.muscles) - set(g.muscles))
            only_b = sorted(set(g.muscles) - set(ref.muscles))
            raise DataMismatchError(
                f"trial {lab} has other muscles or DOFs than trial {labels[0]} (only in {labels[0]}: "
                f"{', '.join(only_a) or '-'}; only in {lab}: {', '.join(only_b) or '-'}; DOFs {list(g.dofs)} vs "
                f"{list(ref.dofs)}); are the trials from different models? All trials of one EMG-TEN problem "
                "need the same model"
            )
    muscles = tuple(ref.muscles)
    settings = settings_for_muscles(settings, muscles)
    mapping = mapping_for_muscles(emg_mapping, mapping, muscles)
    missing_kt = [m for m in settings.tendon_muscles if m not in muscles]
    if missing_kt:
        raise UnknownMuscleError(
            f"the tendon stiffness of {name_list(missing_kt)} is to be estimated but the problem has no such muscle "
            f"({', '.join(muscles[:6])} ...); change EmgTenSettings.tendon_groups"
        )
    params, wf_record = parameters if parameters is not None else \
        workflow_parameters(workflow, model_parameters, muscles, passive=passive, tendon_stiffness=tendon_stiffness)
    emg_muscles = tuple(sorted(mapping))

    trials = []
    for i, (g, (id_time, id_moments), emg, lab) in enumerate(zip(restricted, id_data, emg_tables, labels)):
        id_moments = np.asarray(id_moments, dtype=float).reshape(len(id_time), -1)
        if tuple(g.dofs) != all_dofs[i]:
            keep = [all_dofs[i].index(d) for d in g.dofs]
            id_moments = id_moments[:, keep]
        src = sources[i]
        inputs = trial_inputs(g, id_time, id_moments, ik_time_s=ik_times[i], sources=src)
        if check_units:
            check_moment_magnitudes(inputs.moments_frames_Nm, inputs.dofs, inputs.moment_arms_frames_m,
                                    params.max_isometric_force_N, src.get("id", f"inverse dynamics of {lab}"),
                                    options.optimal_reserve_Nm)
        emg_nodes = emg_at_nodes(emg, mapping, inputs, emg_muscles, str(src.get("emg", f"EMG of trial {lab}")),
                                 str(src.get("ik", f"trial {lab}")), settings.emg_range_tolerance)
        so = static_optimisation(inputs, params)
        guess = initial_guess(inputs, params, so)
        guess = replace(guess, reserve=guess.reserve / options.optimal_reserve_Nm)
        trials.append(EmgTenTrial(label=lab, inputs=inputs, emg_muscles=emg_muscles, emg_nodes=emg_nodes,
                                  emg_channels={m: list(mapping[m]) for m in emg_muscles}, guess=guess,
                                  sources=src, static_optimisation_objective=so.objective))
    return trials, params, wf_record
