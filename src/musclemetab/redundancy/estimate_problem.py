"""The problem of a parameter estimation (:func:`.problem.load_problem` with ``estimate``,
:func:`.estimate_run.estimate_files`): its options checked (:func:`check_estimate_options`),
its trials read with their measured fiber lengths and EMG (:func:`read_estimate_trials`), and
its solve with the records of ``parameters.json`` and each trial's ``summary.json``
(:func:`solve_estimate`)."""

from __future__ import annotations

import dataclasses
import os
from typing import NamedTuple

from ..errors import OptionError
from ..messages import name_list
from .trial_files import TrialArrays

__all__ = ["EstimateOptions", "check_estimate_options", "read_estimate_trials", "solve_estimate", "WEIGHT_NAMES",
           "EMG_SCALE_BOUNDS"]

WEIGHT_NAMES = {"activation": "w_activation", "reserve": "w_reserve", "velocity": "w_velocity",
                "fiber_length": "w_fiber_length", "emg": "w_emg"}
#: default bounds of the EMG scale factors (those of EMG-TEN)
EMG_SCALE_BOUNDS = (0.05, 2.5)


class EstimateOptions(NamedTuple):
    """The checked options of an estimation: the factors' specs (without the EMG scales, added
    once the tracked muscles are known), goals, EMG mode, EMG couplings and bounds."""

    specs: list
    goals: object
    mode: str | None
    couple: list
    bounds: dict


def check_estimate_options(workflow, n: int, n_id: int, ultrasound, emg, estimate, couple, bounds, weights,
                           emg_mode, emg_tolerance, exclude_muscles) -> EstimateOptions:
    """The cheap checks of :func:`.estimate_run.estimate_files`' options, before any file is read."""
    from .estimate import FIELDS, _coupling, parameter_specs
    from .emg_ten import emg_bound
    from .goals import Goals
    from .workflows import get_workflow

    if not (ultrasound or emg):
        raise OptionError("estimate needs measurements: give --ultrasound (fiber lengths) or --emg files, or both")
    counts = [("--ultrasound", len(ultrasound)), ("--emg", len(emg))]
    if n_id != n or any(k not in (0, n) for _, k in counts):
        given = ", ".join(f"{k} {o}" for o, k in counts if k)
        raise OptionError(f"{n} --ik, {n_id} --id and {given} files; give one of each per trial, in the "
                          "same order")
    estimate = {k: list(v) for k, v in estimate.items()}
    bounds = {k: (float(lo), float(hi)) for k, (lo, hi) in (bounds or {}).items()}
    bad = [k for k in bounds if k not in (*FIELDS, "emg_scale")]
    if bad:
        raise OptionError(f"--bounds: unknown kind '{bad[0]}'; use {', '.join((*FIELDS, 'emg_scale'))}")
    couple = list(couple)
    coupled = {m for g in couple for m in _coupling(g)[1]}
    clash = [m for m in exclude_muscles if any(m in v for v in estimate.values()) or m in coupled]
    if clash:
        raise OptionError(f"--exclude-muscles {name_list(clash, sep=' ')} and --estimate/--couple name the same muscle"
                          f"{'s' if len(clash) > 1 else ''}: a muscle left out of the problem has no parameter to "
                          "estimate; drop it from one of them")
    specs = parameter_specs(estimate, couple, bounds)
    given = {**get_workflow(workflow).goals.effort_weights(), "w_fiber_length": 100.0, "w_emg": 10.0 if emg else 0.0}
    for k, v in (weights or {}).items():
        if k not in WEIGHT_NAMES:
            raise OptionError(f"--weights: unknown weight '{k}'; use {', '.join(WEIGHT_NAMES)}")
        given[WEIGHT_NAMES[k]] = float(v)
    mode = emg_mode or "constrained"
    if emg:
        if not (emg_tolerance >= 0):
            raise OptionError(f"--emg-tolerance must be a non-negative number, not {emg_tolerance}")
        if mode == "tracking" and not given["w_emg"] > 0:
            raise OptionError("--emg-mode tracking needs a positive EMG weight (--emg-weight)")
    goals = Goals(**given, emg_tolerance=emg_bound(mode, emg_tolerance) if emg else None).resolved(
        mode if emg else None)
    return EstimateOptions(specs, goals, mode if emg else None, couple, bounds)


def read_estimate_trials(model, files, labels, *, workflow, side, dofs, passive, options, cache_dir, exclude_muscles,
                         emg_mapping, specs):
    """The trials of an estimation from files (IK, ID, ultrasound and/or EMG, :class:`~.problem.TrialFiles`):
    ``(trials, parameters of the workflow, their record, DOFs, EMG mapping)``."""
    from ..geometry import compute_geometry
    from ..io import read_table
    from .diagnosis import diagnose_geometry
    from .emg_inputs import mapped_emg_table, mapping_for_muscles, resolve_emg_mapping
    from .estimate import read_fiber_lengths
    from .inputs import check_time_ranges, read_inverse_dynamics, read_kinematics, restrict_geometry
    from ..io import source_path
    from .trial_files import exclude_from_geometry, fiber_lengths_without, mapping_without, read_model_parameters, \
        trial_dofs
    from .workflows import get_workflow, workflow_parameters

    with_emg = any(f.emg is not None for f in files)
    measured = [read_fiber_lengths(f.ultrasound) if f.ultrasound is not None else {} for f in files]
    mapping = resolve_emg_mapping(emg_mapping or "default") if with_emg else {}
    if exclude_muscles:
        mapping = mapping_without(mapping, exclude_muscles)
        measured = [fiber_lengths_without(us, exclude_muscles) for us in measured]
    wf = get_workflow(workflow)
    model_parameters = read_model_parameters(model)
    trials, params, wf_record = [], None, None
    for f, lab, us in zip(files, labels, measured):
        ik, idp = str(f.ik), str(f.id)
        id_table = read_table(idp)
        # the first trial's DOFs (or the given ones) for every trial, each ID file checked as solve_files does
        dofs = list(trial_dofs(model, [id_table], dofs, side, cache_dir))
        t_ik, _ = read_kinematics(ik, dofs)
        t_id, mom = read_inverse_dynamics(id_table, dofs)
        check_time_ranges(t_ik, t_id, ik, idp)
        g = compute_geometry(model, ik, dofs=list(dofs), side=side, cache_dir=cache_dir)
        g, _ = exclude_from_geometry(g, exclude_muscles)
        nominal, record = workflow_parameters(wf, model_parameters, g.muscles, passive=passive)
        diagnosis = diagnose_geometry(g, nominal, t_id, mom, ik_time_s=t_ik, specs=specs, trial=lab,
                                      optimal_reserve_Nm=options.optimal_reserve_Nm).check(f"trial {lab}")
        muscles = restrict_geometry(g).muscles
        if params is None:
            params, wf_record = nominal.subset(muscles), record
        table = None
        if with_emg:
            mapping = mapping_for_muscles(emg_mapping or "default", mapping, muscles)
            table = mapped_emg_table(f.emg, mapping, str(f.emg))
        emg_source = source_path(f.emg) if isinstance(f.emg, (str, os.PathLike)) else f"EMG table of trial {lab}"
        sources = {"model": source_path(model), "ik": source_path(ik), "id": source_path(idp),
                   **({"emg": emg_source} if with_emg else {})}
        trials.append(TrialArrays(lab, g, t_id, mom, t_ik, table, sources, {}, diagnosis, us))
    return trials, params, wf_record, tuple(dofs), mapping


def solve_estimate(problem):
    """Solve the estimation ``problem`` (:func:`.estimate.estimate_parameters`): the
    :class:`~.result.Result` with each trial's solution (the estimates applied) and the content of
    ``parameters.json`` (``document``; the personalised model and the validation are added when
    written, :func:`.estimate_run.estimate_files`)."""
    from .emg_inputs import emg_at_nodes
    from .estimate import estimate_parameters, fiber_length_trial
    from .record import ProblemRecord, RunRecord
    from .records_build import trial_solution
    from .result import ESTIMATE_FORMAT, Result
    from .solve import prepare_trial
    from .static_opt import initial_guess

    options, goals, specs = problem.options, problem.goals, list(problem.specs)
    emg_muscles = next((s.muscles for s in specs if s.kind == "emg_scale"), ())
    trials = []
    for t in problem.trials:
        inputs, p, so = prepare_trial(t.geometry, problem.parameters, t.id_time_s, t.id_moments_Nm,
                                      ik_time_s=t.ik_time_s, options=options,
                                      sources={k: v for k, v in t.sources.items() if k != "emg"})
        emg = {}
        if t.emg is not None:
            emg = dict(emg_muscles=emg_muscles, emg_nodes=emg_at_nodes(t.emg, dict(problem.emg_mapping), inputs,
                                                                       emg_muscles, str(t.sources["emg"]),
                                                                       str(t.sources["ik"])))
        trials.append(fiber_length_trial(t.label, inputs, initial_guess(inputs, p, so), dict(t.fiber_lengths), **emg))
    res, est = estimate_parameters(trials, problem.parameters, specs, goals, options=options)
    run = RunRecord.from_result(res, {"model": problem.trials[0].sources["model"]})
    estimated = est.parameters()
    emg_record = {}
    if emg_muscles:
        bounds = next(s.bounds for s in specs if s.kind == "emg_scale")
        emg_record = {"emg": {"mode": problem.emg_mode, "tolerance": goals.emg_tolerance, "weight": goals.w_emg,
                              "mapping": dict(problem.emg_mapping), "scale": dict(res.factors.get("emg_scale", {})),
                              "bounds": list(bounds),
                              "max_deviation": {t.label: float(abs(d).max()) if d.size else 0.0
                                                for t, d in zip(trials, res.emg_deviation)}}}
    solutions = {}
    for t, o, trial in zip(trials, res.trials, problem.trials):
        diag = trial.diagnosis
        solutions[t.label] = trial_solution(
            "estimate", run, t.inputs, problem.parameters, options, goals, o, solved=estimated,
            fiber_dynamics=goals.fiber_dynamics, specs=specs, **emg_record,
            workflow={"name": f"{problem.workflow} estimate", "estimate": est.to_dict()["factors"]},
            diagnosis=diag.to_dict(),
            **({"excluded_muscles": list(problem.excluded_muscles)} if problem.excluded_muscles else {}))
        if not run.success:
            from .diagnosis import last_iterate_violations

            s = solutions[t.label]
            violated = [f.to_dict() for f in last_iterate_violations(s, t.inputs)]
            solutions[t.label] = dataclasses.replace(
                s, record=s.record.with_(diagnosis={**diag.to_dict(), "last_iterate": violated}))
    doc = {"format": ESTIMATE_FORMAT, "format_version": 1, **est.to_dict(), **emg_record, "solve": run.to_dict(),
           "trials": list(problem.labels)}
    factors = {k: dict(v) for k, v in est.factors.items()}
    if emg_muscles:
        factors["emg_scale"] = dict(res.factors.get("emg_scale", {}))
    return Result(solutions=solutions, parameters=estimated, factors=factors,
                  record=ProblemRecord.from_dict(run.to_dict()),
                  emg_channels={m: list(c) for m, c in problem.emg_mapping.items()}, document=doc, trials=tuple(trials))
