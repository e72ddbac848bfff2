"""Muscle-tendon parameters estimated from fiber lengths and/or EMG over trials, from files to a
folder (:func:`estimate_files`, the pipeline of ``musclemetab estimate`` and of a study's
``[subjects.estimate]``), a :class:`~.result.Result`."""

from __future__ import annotations

from .._docs import fill_doc
from .ipopt import SolverOptions
from .result import Result
from .run import check_solution_folders

__all__ = ["estimate_files", "write_estimate"]


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
    from .emg_inputs import trial_labels
    from .problem import TrialFiles, load_problem, solve

    check_output_folder(out)
    given = [list(x or ()) for x in (ik, id, emg, ultrasound)]
    _check_estimate_outputs(out, model, trial_labels(given[0], labels), validate)
    ik, id, emg, ultrasound = ([*x, *[None] * (max(map(len, given)) - len(x))] for x in given)  # counts checked later
    files = [TrialFiles(*trial, label=None, ultrasound=us) for *trial, us in zip(ik, id, emg, ultrasound)]
    problem = load_problem(model, files, workflow=workflow, labels=labels, side=side, dofs=dofs, passive=passive,
                           options=options if options is not None else SolverOptions(max_iter=max_iter),
                           cache_dir=cache_dir, exclude_muscles=exclude_muscles, emg_mapping=emg_mapping,
                           estimate=estimate, couple=couple, bounds=bounds, weights=weights, emg_mode=emg_mode,
                           emg_tolerance=emg_tolerance)
    return write_estimate(solve(problem), out, validate=validate)


def write_estimate(result: Result, out, validate: bool = False) -> Result:
    """Write an estimation's ``result`` (:func:`.problem.solve` of an estimation problem) to
    ``out``: with ``validate`` the validation re-solves first (each trial with the estimates and
    the effort goals only, their fit to the measurements), then the personalised model, the
    trials' folders, ``parameters.json`` and the validation's folders; raises the solve's
    :class:`~musclemetab.errors.SolverError` (after writing) when it did not converge."""
    from ..processes import sigint_deferred
    from .estimate import FIELDS, write_personalised_model
    from .solve import solve_with_parameters

    problem, doc = result.problem, result.document
    run, estimated, factors = result.run_record, result.parameters, result.factors
    validation, fits, failed = {}, {}, None  # the validation re-solves, before anything is written
    if validate and run.success:
        from .identifiability import tracking_fit

        for t, trial in zip(result.trials, problem.trials):
            lab = t.label
            sol = validation[lab] = solve_with_parameters(
                trial.geometry, estimated, trial.id_time_s, trial.id_moments_Nm, ik_time_s=trial.ik_time_s,
                options=problem.options, goals=problem.goals.effort(),
                workflow_record={"name": f"{problem.workflow} validation"})
            if not sol.success:
                failed = sol.run_record.failure(f"the validation re-solve of {lab}")
                break
            scale = factors.get("emg_scale", {})
            fits[lab] = tracking_fit(
                sol, {m: t.fiber_length_nodes_m[:, j] for j, m in enumerate(t.fiber_muscles)},
                {m: scale[m] * t.emg_nodes[:, j] for j, m in enumerate(t.emg_muscles)})
    with sigint_deferred():  # Ctrl-C leaves the previous output or all the new one
        if run.success:
            estimate = {s.kind: list(s.muscles) for s in problem.specs if s.kind in FIELDS}
            path, report = write_personalised_model(problem.trials[0].sources["model"], estimated, estimate, out)
            doc["personalised_model"] = {"path": path.name, "muscles": report}
        if validate and run.success and failed is None:
            from .identifiability import warn_validation

            doc["validation"] = fits
            doc["validation_warnings"] = warn_validation(fits)
        result.write(out)
        for lab, sol in validation.items():
            sol.write(f"{out}/validation/{lab}")
    if not run.success:
        from .diagnosis import trials_violation_text
        from .emg_ten import emg_failure

        err = emg_failure(run, problem.emg_mode, f"the estimation (written to {out})")
        raise type(err)(err.message + trials_violation_text(result.solutions))
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
