"""Muscle-tendon parameters estimated from fiber lengths and/or EMG over trials, from files to a
folder (:func:`estimate_files`, the pipeline of ``musclemetab estimate`` and of a study's
``[subjects.estimate]``), a :class:`~.result.Result`."""

from __future__ import annotations

import dataclasses
import os

from ..errors import OptionError
from ..messages import name_list
from .._docs import fill_doc
from .result import ESTIMATE_FORMAT, Result
from .inputs import check_time_ranges
from .ipopt import SolverOptions
from .run import (
    EMG_SCALE_BOUNDS, WEIGHT_NAMES, _fiber_lengths_without, _mapping_without, _trial_dofs, check_solution_folders,
    exclude_from_geometry,
)

__all__ = ["estimate_files"]


@fill_doc
def estimate_files(
    model, ik, id, out, *, estimate, ultrasound=(), emg=(), labels=None, couple=(), bounds=None, weights=None,
    workflow: str = "effort-cal", side: str = "r", dofs=None, emg_mode: str | None = None,
    emg_mapping: str | None = None, emg_tolerance: float = 0.01, passive=None, max_iter: int = 10000,
    validate: bool = False, cache_dir=None, exclude_muscles=(), options: SolverOptions | None = None,
) -> Result:
    """Estimate muscle-tendon parameters over trials from files, and write them to ``out``.

    ``ik``, ``id`` and ``ultrasound`` / ``emg`` hold one file per trial, in the same order (at
    least one kind of measurement). ``estimate`` maps a kind (``tendon_stiffness``,
    ``optimal_fiber_length``, ``tendon_slack_length``) to its muscles; ``couple`` lists
    muscles sharing one factor; ``bounds`` maps a kind (or ``emg_scale``) to ``(low, high)``;
    ``weights`` maps ``activation``, ``reserve``, ``velocity``, ``fiber_length`` and ``emg`` to
    their weights (defaults: the workflow's, 100 and 10). The other options are those of
    ``musclemetab estimate`` (``docs/problem.md``). Writes ``out/<trial>/``,
    ``out/parameters.json``, ``out/<model>_personalised.osim`` and with ``validate``
    ``out/validation/<trial>/``; raises :class:`~musclemetab.errors.SolverError` (after
    writing) when the solve did not converge. A group of ``couple`` may name one kind
    (``{"kind": KIND, "muscles": [...]}`` or ``"KIND:M1,M2"``; kind ``emg_scale`` replaces the
    EMG-TEN groups of the EMG scale factors). The doubts of the estimate (factors on bounds,
    identifiability, widened fiber-length bounds) are warned and recorded in ``parameters.json``
    (``doubts``); the validation re-solve's fit to the measurements (RMS, Pearson r per measured
    muscle) under ``validation``. ``exclude_muscles`` leaves muscles out of every trial (as
    :func:`solve_files`); one named in ``estimate`` or ``couple`` is an
    :class:`~musclemetab.errors.OptionError`, its EMG and measured fiber lengths are not used
    (a warning names them). Each trial is diagnosed before the problem is built
    (:mod:`.diagnosis`, the estimated factors within their bounds).

    Parameters
    ----------
    %(model)s
    %(labels)s
    %(passive)s
    %(side_dofs)s
    emg_mapping
        As for :func:`solve_emg_ten` (default ``"default"``).
    %(cache_dir)s
    """
    from ..io import check_output_folder
    from .bounds import fiber_length_bounds_record
    from .transcription import Goals, ParameterSpec, coupling_pairs
    from .emg_inputs import emg_at_nodes, mapping_for_muscles, resolve_emg_mapping, trial_labels
    from .emg_ten import emg_bound, fiber_scheme
    from .estimate import (
        FIELDS,
        _coupling,
        emg_couplings,
        estimate_parameters,
        fiber_length_trial,
        parameter_specs,
        read_fiber_lengths,
        write_personalised_model,
    )
    from .ipopt import SolverOptions, solver_record
    from .record import ProblemRecord, RunRecord
    from .solution import build_solution
    from .solve import prepare_trial, solve_with_parameters
    from .static_opt import initial_guess
    from .workflows import get_workflow, workflow_parameters

    weights_given = weights
    check_output_folder(out)
    ik, id_files = [str(p) for p in ik], [str(p) for p in id]
    n = len(ik)
    us_files = [str(p) for p in ultrasound or ()]
    emg_files = [p if isinstance(p, os.PathLike) else str(p) for p in emg or ()]  # a RawEmgPath stays one
    if not (us_files or emg_files):
        raise OptionError("estimate needs measurements: give --ultrasound (fiber lengths) or --emg files, or both")
    counts = [("--ultrasound", len(us_files)), ("--emg", len(emg_files))]
    if len(id_files) != n or any(k not in (0, n) for _, k in counts):
        given = ", ".join(f"{k} {o}" for o, k in counts if k)
        raise OptionError(f"{n} --ik, {len(id_files)} --id and {given} files; give one of each per trial, in the "
                          "same order")
    estimate = {k: list(v) for k, v in estimate.items()}
    bounds = {k: (float(lo), float(hi)) for k, (lo, hi) in (bounds or {}).items()}
    bad = [k for k in bounds if k not in (*FIELDS, "emg_scale")]
    if bad:
        raise OptionError(f"--bounds: unknown kind '{bad[0]}'; use {', '.join((*FIELDS, 'emg_scale'))}")
    couple = list(couple)
    exclude_muscles = list(exclude_muscles or ())
    coupled = {m for g in couple for m in _coupling(g)[1]}
    clash = [m for m in exclude_muscles if any(m in v for v in estimate.values()) or m in coupled]
    if clash:
        raise OptionError(f"--exclude-muscles {name_list(clash, sep=' ')} and --estimate/--couple name the same muscle"
                          f"{'s' if len(clash) > 1 else ''}: a muscle left out of the problem has no parameter to "
                          "estimate; drop it from one of them")
    specs = parameter_specs(estimate, couple, bounds)
    wf = get_workflow(workflow)
    weights = {**wf.goals.effort_weights(), "w_fiber_length": 100.0, "w_emg": 10.0 if emg_files else 0.0}
    for k, v in (weights_given or {}).items():
        if k not in WEIGHT_NAMES:
            raise OptionError(f"--weights: unknown weight '{k}'; use {', '.join(WEIGHT_NAMES)}")
        weights[WEIGHT_NAMES[k]] = float(v)
    mode = emg_mode or "constrained"
    if emg_files:
        if not (emg_tolerance >= 0):
            raise OptionError(f"--emg-tolerance must be a non-negative number, not {emg_tolerance}")
        if mode == "tracking" and not weights["w_emg"] > 0:
            raise OptionError("--emg-mode tracking needs a positive EMG weight (--emg-weight)")
    tolerance = emg_bound(mode, emg_tolerance) if emg_files else None
    fiber_dynamics = fiber_scheme(mode if emg_files else None)
    goals = Goals(**weights, emg_tolerance=tolerance, fiber_dynamics=fiber_dynamics)
    labels = trial_labels(ik, labels)
    _check_estimate_outputs(out, model, labels, validate)
    measured = [read_fiber_lengths(p) for p in us_files] or [{} for _ in range(n)]
    mapping = resolve_emg_mapping(emg_mapping or "default") if emg_files else {}
    if exclude_muscles:
        mapping = _mapping_without(mapping, exclude_muscles)
        measured = [_fiber_lengths_without(us, exclude_muscles) for us in measured]
    emg_muscles = ()
    options = options if options is not None else SolverOptions(max_iter=max_iter)

    from ..geometry import compute_geometry
    from ..io import read_table
    from ..model import read_muscle_parameters
    from .inputs import read_inverse_dynamics, read_kinematics

    model_parameters = read_muscle_parameters(model)
    trials, prepared, params, diagnoses = [], [], None, []
    for i, (ik, idp, lab, us) in enumerate(zip(ik, id_files, labels, measured)):
        id_table = read_table(idp)
        # the first trial's DOFs (or the given ones) for every trial, each ID file checked as solve_files does
        dofs = list(_trial_dofs(model, [id_table], dofs, side, cache_dir))
        t_ik, _ = read_kinematics(ik, dofs)
        t_id, mom = read_inverse_dynamics(id_table, dofs)
        check_time_ranges(t_ik, t_id, ik, idp)
        g = compute_geometry(model, ik, dofs=list(dofs), side=side, cache_dir=cache_dir)
        g, _ = exclude_from_geometry(g, exclude_muscles)
        nominal, wf_record = workflow_parameters(wf, model_parameters, g.muscles, passive=passive)
        from .diagnosis import diagnose_geometry

        diagnoses.append(diagnose_geometry(g, nominal, t_id, mom, ik_time_s=t_ik, specs=specs, trial=lab,
                                           optimal_reserve_Nm=options.optimal_reserve_Nm).check(f"trial {lab}"))
        inputs, p, so = prepare_trial(g, nominal, t_id, mom, ik_time_s=t_ik, options=options,
                                      sources={"model": model, "ik": ik, "id": idp})
        params = p if params is None else params
        emg = {}
        if emg_files:
            mapping = mapping_for_muscles(emg_mapping or "default", mapping, inputs.muscles)
            emg_muscles = tuple(sorted(mapping))
            emg = dict(emg_muscles=emg_muscles,
                       emg_nodes=emg_at_nodes(emg_files[i], mapping, inputs, emg_muscles, str(emg_files[i]), str(ik)))
        trials.append(fiber_length_trial(lab, inputs, initial_guess(inputs, p, so), us, **emg))
        prepared.append((g, nominal, t_id, mom, t_ik))
    if emg_files:
        from .emg_ten import EmgTenSettings, settings_for_muscles

        groups = emg_couplings(couple) or settings_for_muscles(EmgTenSettings(), params.names).emg_groups
        specs.append(ParameterSpec("emg_scale", emg_muscles, bounds.get("emg_scale", EMG_SCALE_BOUNDS),
                                   coupling_pairs(groups, emg_muscles, consecutive=False)))
    res, est = estimate_parameters(trials, params, specs, goals, options=options)
    run = RunRecord.from_result(res, {"model": model})
    estimated = est.parameters()
    emg_record = {}
    if emg_files:
        emg_record = {"emg": {"mode": mode, "tolerance": tolerance, "weight": goals.w_emg, "mapping": mapping,
                              "scale": dict(res.factors.get("emg_scale", {})),
                              "bounds": list(bounds.get("emg_scale", EMG_SCALE_BOUNDS)),
                              "max_deviation": {t.label: float(abs(d).max()) if d.size else 0.0
                                                for t, d in zip(trials, res.emg_deviation)}}}
    solutions = {}
    for t, o, diag in zip(trials, res.trials, diagnoses):
        summary = {**run.to_dict(), **emg_record, "objective_trial": o.objective, "objective_terms": o.objective_terms,
                   "time_window_s": list(t.inputs.window_s), "n_intervals": t.inputs.n_intervals,
                   "mesh_step_s": t.inputs.step_s, "optimal_reserve_Nm": options.optimal_reserve_Nm,
                   "fiber_dynamics": fiber_dynamics,
                   "fiber_length_bounds": fiber_length_bounds_record(t.inputs, params, specs),
                   "workflow": {"name": f"{workflow} estimate", "estimate": est.to_dict()["factors"]},
                   "solver_options": solver_record(options, goals), "diagnosis": diag.to_dict(),
                   **({"excluded_muscles": list(exclude_muscles)} if exclude_muscles else {})}
        solutions[t.label] = build_solution(t.inputs, estimated.subset(t.inputs.muscles), o, summary)
        if not run.success:
            from .diagnosis import last_iterate_violations

            s = solutions[t.label]
            violated = [f.to_dict() for f in last_iterate_violations(s, t.inputs)]
            solutions[t.label] = dataclasses.replace(
                s, record=s.record.with_(diagnosis={**diag.to_dict(), "last_iterate": violated}))
    doc = {"format": ESTIMATE_FORMAT, "format_version": 1, **est.to_dict(), **emg_record, "solve": run.to_dict(),
           "trials": labels}
    factors = {k: dict(v) for k, v in est.factors.items()}
    if emg_files:
        factors["emg_scale"] = dict(res.factors.get("emg_scale", {}))
    validation, fits, failed = {}, {}, None  # the validation re-solves, before anything is written
    if validate and run.success:
        from .identifiability import tracking_fit

        for t, (g, _, t_id, mom, t_ik) in zip(trials, prepared):
            lab = t.label
            sol = validation[lab] = solve_with_parameters(g, estimated, t_id, mom, ik_time_s=t_ik, options=options,
                                                          goals=goals.effort(),
                                                          workflow_record={"name": f"{workflow} validation"})
            if not sol.success:
                failed = sol.run_record.failure(f"the validation re-solve of {lab}")
                break
            scale = factors.get("emg_scale", {})
            fits[lab] = tracking_fit(
                sol, {m: t.fiber_length_nodes_m[:, j] for j, m in enumerate(t.fiber_muscles)},
                {m: scale[m] * t.emg_nodes[:, j] for j, m in enumerate(t.emg_muscles)})
    from ..processes import sigint_deferred

    with sigint_deferred():  # Ctrl-C leaves the previous output or all the new one
        if run.success:
            path, report = write_personalised_model(model, estimated, estimate, out)
            doc["personalised_model"] = {"path": path.name, "muscles": report}
        if validate and run.success and failed is None:
            from .identifiability import warn_validation

            doc["validation"] = fits
            doc["validation_warnings"] = warn_validation(fits)
        result = Result(solutions=solutions, parameters=estimated, factors=factors,
                        record=ProblemRecord.from_dict(run.to_dict()),
                        emg_channels={m: list(c) for m, c in mapping.items()}, document=doc)
        result.write(out)
        for lab, sol in validation.items():
            sol.write(f"{out}/validation/{lab}")
    if not run.success:
        from .diagnosis import trials_violation_text
        from .emg_ten import emg_failure

        err = emg_failure(run, mode if emg_files else None, f"the estimation (written to {out})")
        raise type(err)(err.message + trials_violation_text(solutions))
    if failed is not None:
        raise failed
    return result


def _check_estimate_outputs(out, model, labels, validate: bool) -> None:
    """Refuse, before any work, an ``out`` where a file of the estimate (``parameters.json``, the
    personalised model, the trials' and with ``validate`` the validation's solution folders) would
    replace a folder, or a file the package did not write (:class:`OptionError` naming it)."""
    from pathlib import Path

    from ..io.atomic import check_replaceable
    from .result import PARAMETERS_FILE

    out = Path(out)
    check_replaceable(out, [PARAMETERS_FILE, f"{Path(model).stem}_personalised.osim"])
    check_solution_folders([out / lab for lab in labels] + ([out / "validation" / lab for lab in labels]
                                                           if validate else []))
