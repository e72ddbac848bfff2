"""One muscle redundancy problem, built once from files and solved once: :class:`Problem`,
:func:`load_problem` and :func:`solve` (``docs/problem.md``, "In Python").

``problem = load_problem(model, trials, workflow=..., side=...)`` reads and checks every input
(options, parameter files, columns, units, time ranges, EMG coverage) before any OpenSim work
(:mod:`.trial_files`), then gets the geometry and the model's muscle parameters, works out the
workflow's parameters and goals, and diagnoses each trial. ``result = solve(problem)`` solves it
(the single-trial effort solve of :mod:`.solve`, or the EMG problem of :mod:`.emg_pipeline`) and
returns a :class:`~.result.Result` that keeps the problem (``result.problem``), so that the
stages after the solve (sensitivities, samples of the parameters, re-solves) start from it
instead of reading the files again: ``problem.with_parameters(p)`` is the same problem with other
muscle parameters.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Mapping, Sequence

import numpy as np

from ..errors import OptionError
from ..events import WALKING_CYCLE_DURATION_S
from .diagnosis import Diagnosis
from .emg_ten import EmgTenSettings
from .goals import Goals, ParameterSpec
from .inputs import MESH_FREQUENCY_HZ, GeometryArrays
from .ipopt import SolverOptions
from .parameters import MuscleTendonParameters
from .result import EMG_TEN, Result
from .solve import solve_with_parameters

if TYPE_CHECKING:
    import pandas as pd

    from .solution import Solution

__all__ = ["Problem", "ProblemTrial", "TrialFiles", "load_problem", "solve", "read_problem", "load_result"]


@dataclass(frozen=True)
class TrialFiles:
    """The files of one trial: IK ``.mot``, ID ``.sto`` (``None``: computed from the ground
    forces of an effort solve), EMG (EMG problems, estimation), its label (default the IK file's
    stem) and measured fiber lengths (``ultrasound``, estimation)."""

    ik: str | os.PathLike
    id: str | os.PathLike | None = None
    emg: str | os.PathLike | None = None
    label: str | None = None
    ultrasound: str | os.PathLike | None = None


@dataclass(frozen=True)
class ProblemTrial:
    """One trial of a :class:`Problem`, ready for the mesh: the geometry (cropped to the window,
    the muscles left out removed), the ID time and moments (columns in ``geometry.dofs``, any
    assistance device's torque taken off), the IK frame times, the EMG table mapped to muscles
    (EMG problems), the source files, the entries of its record known before the solve (window,
    computed inverse dynamics, assistance), its diagnosis and its measured fiber lengths
    (``{muscle: (time s, length m)}``, estimation)."""

    label: str
    geometry: GeometryArrays
    id_time_s: np.ndarray
    id_moments_Nm: np.ndarray
    ik_time_s: np.ndarray
    emg: "pd.DataFrame | None"
    sources: Mapping[str, Path | str]
    record: Mapping[str, object]
    diagnosis: Diagnosis
    fiber_lengths: Mapping[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)


@dataclass(frozen=True)
class Problem:
    """What a solve needs (:func:`load_problem`, :func:`solve`).

    ``kind``: ``"effort"`` (one trial of an effort workflow), ``"emg"`` (EMG-TEN or an
    EMG-informed solve over trials) or ``"estimate"`` (muscle-tendon parameters from measured
    fiber lengths and/or EMG, :func:`.estimate_run.estimate_files`).

    ``trials`` (:class:`ProblemTrial`), the muscle-tendon ``parameters`` the workflow gives (for
    the muscles the problem keeps; ``workflow_record`` says where they came from), ``goals``,
    ``specs`` (the estimated factors, empty for an effort solve), the solver ``options`` it is
    solved with (the stop included), the ``workflow`` name, the ``side``, ``dofs``, mesh frequency
    and the muscles left out. An EMG problem has ``emg`` (its :class:`~.emg_ten.EmgTenSettings`)
    and ``emg_mapping`` (muscle -> channels), and ``emg_mode`` (an EMG problem or an estimation
    with EMG). ``model`` is the model file; ``inputs`` the
    keywords it was loaded with (:func:`load_problem`), from which :mod:`.problem_file` rebuilds
    it."""

    kind: str
    workflow: str
    side: str
    dofs: tuple[str, ...]
    trials: tuple[ProblemTrial, ...]
    parameters: MuscleTendonParameters
    goals: Goals
    specs: tuple[ParameterSpec, ...]
    options: SolverOptions
    model: Path
    mesh_frequency_hz: float = MESH_FREQUENCY_HZ
    excluded_muscles: tuple[str, ...] = ()
    emg: EmgTenSettings | None = None
    emg_mode: str | None = None
    emg_mapping: Mapping[str, Sequence[str]] = field(default_factory=dict)
    workflow_record: Mapping[str, object] = field(default_factory=dict)
    check_units: bool = True
    geometry_time_s: float = 0.0
    inputs: Mapping[str, object] = field(default_factory=dict, repr=False)

    @property
    def labels(self) -> tuple[str, ...]:
        return tuple(t.label for t in self.trials)

    @property
    def diagnoses(self) -> list[Diagnosis]:
        return [t.diagnosis for t in self.trials]

    def with_parameters(self, parameters: MuscleTendonParameters) -> "Problem":
        """The same problem with other muscle parameters (e.g. a sample of
        :mod:`musclemetab.uncertainty`), for the same muscles."""
        if tuple(parameters.names) != tuple(self.parameters.names):
            raise OptionError("the parameters must name the problem's muscles in its order "
                              f"({', '.join(self.parameters.names[:4])}, ...)")
        return dataclasses.replace(self, parameters=parameters)

    def write(self, out_dir: str | os.PathLike) -> Path:
        """Write ``out_dir/problem.json`` (:mod:`.problem_file`; :func:`read_problem` reads it)."""
        from .problem_file import write_problem

        return write_problem(self, out_dir)

    def with_options(self, options: SolverOptions) -> "Problem":
        """The same problem solved with other solver ``options``."""
        if self.kind == "estimate":
            return dataclasses.replace(self, options=options)
        if self.kind == "effort":
            from .solve import workflow_goals

            goals, options = workflow_goals(self.workflow, self.goals, options)
            return dataclasses.replace(self, goals=goals, options=options)
        from .emg_pipeline import emg_ten_options

        return dataclasses.replace(self, options=emg_ten_options(options, self.emg))


def _trial_files(trials) -> list[TrialFiles]:
    if isinstance(trials, (TrialFiles, str, os.PathLike)):
        trials = [trials]
    out = []
    for t in trials:
        if isinstance(t, TrialFiles):
            out.append(t)
        elif isinstance(t, Mapping):
            out.append(TrialFiles(**t))
        elif isinstance(t, (str, os.PathLike)):
            out.append(TrialFiles(t))
        else:
            out.append(TrialFiles(*t))
    return out


def load_problem(
    model: str | os.PathLike,
    trials,
    *,
    workflow: str = "effort-gen",
    labels: Sequence[str] | None = None,
    side: str = "r",
    dofs: Sequence[str] | None = None,
    emg: EmgTenSettings | None = None,
    emg_mapping="default",
    window: tuple[float, float] | None = None,
    cycle: str | int | None = None,
    external_loads: str | os.PathLike | None = None,
    grf: str | os.PathLike | None = None,
    grf_column: str | None = None,
    grf_threshold_N: float | None = None,
    cycle_duration_s: tuple[float, float] | None = WALKING_CYCLE_DURATION_S,
    mesh_frequency_hz: float = MESH_FREQUENCY_HZ,
    passive=None,
    tendon_stiffness: Mapping[str, float] | None = None,
    tendon_stiffness_file=None,
    options: SolverOptions | None = None,
    goals: Goals | None = None,
    cache_dir: str | os.PathLike | None = None,
    check_units: bool = True,
    exclude_muscles: Sequence[str] = (),
    exclude_missing_ok: bool = False,
    diagnose_only: bool = False,
    assistance: str | os.PathLike | None = None,
    assistance_gain: float = 1.0,
    assistance_cycle_s: tuple[float, float] | None = None,
    assistance_both_legs: bool = False,
    estimate: Mapping[str, Sequence[str]] | None = None,
    couple: Sequence = (),
    bounds: Mapping[str, tuple[float, float]] | None = None,
    weights: Mapping[str, float] | None = None,
    emg_mode: str | None = None,
    emg_tolerance: float = 0.01,
) -> Problem:
    """Read, check and prepare a problem (:class:`Problem`) from files.

    ``trials``: :class:`TrialFiles` (or ``(ik, id[, emg])`` tuples, or dicts of the same keys),
    one per trial. An effort workflow (``effort-gen``, ``-cal``, ``-ten``) without ``emg`` settings
    solves one trial (its window: ``window``, ``cycle`` and the ground-force keywords, as
    :func:`.run.solve_files`); ``workflow="emg-ten"`` or ``emg`` (:class:`~.emg_ten.EmgTenSettings`,
    e.g. :func:`~.emg_ten.informed_settings`) makes an EMG problem over all trials, each with
    its EMG file (``emg_mapping`` as :func:`.emg_run.solve_emg_ten`). The other keywords are those
    of :func:`.run.solve_files` and :func:`.emg_run.solve_emg_ten`. With ``diagnose_only`` the
    trials' :class:`~.diagnosis.Diagnosis` (unchecked) is returned instead: one for an effort
    problem, a list for an EMG problem. ``estimate`` (``{kind: [muscle, ...]}``) makes a
    parameter estimation over the trials with their ``ultrasound`` and/or ``emg`` files
    (``couple``, ``bounds``, ``weights``, ``emg_mode``, ``emg_tolerance`` as
    :func:`.estimate_run.estimate_files`)."""
    from ..layout import check_side

    files = _trial_files(trials)
    check_side(side)
    inputs = {"model": model, "labels": None if labels is None else list(labels),
              "trials": [dataclasses.asdict(t) for t in files],
              "workflow": workflow, "side": side, "dofs": None if not dofs else list(dofs),
              "window": window, "cycle": cycle, "external_loads": external_loads, "grf": grf, "grf_column": grf_column,
              "grf_threshold_N": grf_threshold_N, "cycle_duration_s": cycle_duration_s,
              "mesh_frequency_hz": mesh_frequency_hz, "passive": passive, "tendon_stiffness": tendon_stiffness,
              "tendon_stiffness_file": tendon_stiffness_file, "emg_mapping": emg_mapping,
              "check_units": check_units, "exclude_muscles": list(exclude_muscles),
              "exclude_missing_ok": exclude_missing_ok, "assistance": assistance, "assistance_gain": assistance_gain,
              "assistance_cycle_s": assistance_cycle_s, "assistance_both_legs": assistance_both_legs,
              "options": options, "goals": goals, "emg": emg,
              "estimate": estimate, "couple": list(couple), "bounds": bounds, "weights": weights, "emg_mode": emg_mode,
              "emg_tolerance": emg_tolerance}
    if estimate is not None:
        return _load_estimate(model, files, labels, workflow, side, dofs, estimate, couple, bounds, weights, emg_mode,
                              emg_tolerance, emg_mapping, passive, options, cache_dir, exclude_muscles, inputs)
    if workflow == EMG_TEN or emg is not None:
        return _load_emg(model, files, labels, workflow, side, dofs, emg, emg_mapping, passive, tendon_stiffness,
                         options, cache_dir, check_units, exclude_muscles, exclude_missing_ok, diagnose_only, inputs)
    if len(files) != 1:
        raise OptionError(f"an effort workflow without EMG solves one trial, not {len(files)}; solve each trial on its "
                          "own, or give EMG settings for one problem over them")
    from .trial_files import read_effort_trial
    from .workflows import (PassiveParameters, check_workflow_options, read_passive_parameters,
                            read_tendon_stiffness_json)

    if not (mesh_frequency_hz > 0 and np.isfinite(mesh_frequency_hz)):
        raise OptionError("--mesh-frequency must be a positive number of intervals per second, not "
                          f"{mesh_frequency_hz!r}")
    # cheap checks of the options and parameter files first
    wf = check_workflow_options(workflow, passive, tendon_stiffness, tendon_stiffness_file)
    if passive is not None and not isinstance(passive, PassiveParameters):
        passive = read_passive_parameters(passive)
    if tendon_stiffness_file is not None:
        read_tendon_stiffness_json(tendon_stiffness_file)
    from .solve import workflow_goals

    goals, options = workflow_goals(wf, goals, options)
    trial = files[0]
    read = read_effort_trial(
        model, trial.ik, trial.id, wf, dofs=dofs, side=side, window=window, cycle=cycle, external_loads=external_loads,
        grf=grf, grf_column=grf_column, grf_threshold_N=grf_threshold_N, cycle_duration_s=cycle_duration_s,
        mesh_frequency_hz=mesh_frequency_hz, passive=passive, tendon_stiffness=tendon_stiffness,
        tendon_stiffness_file=tendon_stiffness_file, options=options, cache_dir=cache_dir, check_units=check_units,
        exclude_muscles=exclude_muscles, exclude_missing_ok=exclude_missing_ok, diagnose_only=diagnose_only,
        assistance=assistance, assistance_gain=assistance_gain, assistance_cycle_s=assistance_cycle_s,
        assistance_both_legs=assistance_both_legs)
    if diagnose_only:
        return read
    arrays, params, wf_record, dofs, excluded, t_geometry = read
    arrays = arrays._replace(label=trial.label or (labels or [arrays.label])[0])
    return Problem(kind="effort", workflow=wf.name, side=side, dofs=tuple(dofs), trials=(ProblemTrial(*arrays),),
                   parameters=params, goals=goals, specs=(), options=options, model=Path(model),
                   mesh_frequency_hz=float(mesh_frequency_hz),
                   excluded_muscles=tuple(excluded), workflow_record=wf_record, check_units=check_units,
                   geometry_time_s=t_geometry, inputs=inputs)


def _load_emg(model, files, labels, workflow, side, dofs, settings, emg_mapping, passive, tendon_stiffness, options,
              cache_dir, check_units, exclude_muscles, exclude_missing_ok, diagnose_only, inputs):
    """:func:`load_problem` of an EMG problem (EMG-TEN, an EMG-informed solve)."""
    from .emg_inputs import mapping_for_muscles, one_model, path_list, resolve_emg_mapping, trial_labels
    from .emg_pipeline import emg_ten_options
    from .emg_ten import emg_ten_specs, settings_for_muscles
    from .inputs import restrict_geometry
    from .trial_files import read_emg_trials
    from .workflows import read_passive_parameters

    ik_paths = path_list([f.ik for f in files], "ik_paths")
    id_paths = path_list([f.id for f in files if f.id is not None], "id_paths")
    emg_paths = path_list([f.emg for f in files if f.emg is not None], "emg_paths")
    if not ik_paths:
        raise OptionError("EMG-TEN needs at least one trial (IK, ID and EMG file)")
    if not (len(ik_paths) == len(id_paths) == len(emg_paths)):
        raise OptionError(
            f"{len(ik_paths)} IK, {len(id_paths)} ID and {len(emg_paths)} EMG files; give one of each per trial, "
            "in the same order"
        )
    model = one_model(model, len(ik_paths))
    given = [f.label for f in files]
    labels = trial_labels(ik_paths, labels if labels is not None or all(g is None for g in given) else given)
    mapping = resolve_emg_mapping(emg_mapping)
    settings = settings or EmgTenSettings()
    if passive is not None and not hasattr(passive, "for_muscles"):
        passive = read_passive_parameters(passive)
    read = read_emg_trials(model, ik_paths, id_paths, emg_paths, labels, mapping=mapping, settings=settings,
                           workflow=workflow, passive=passive, dofs=dofs, side=side, options=options,
                           cache_dir=cache_dir, check_units=check_units, tendon_stiffness=tendon_stiffness,
                           exclude_muscles=exclude_muscles, exclude_missing_ok=exclude_missing_ok,
                           diagnose_only=diagnose_only)
    if diagnose_only:
        return read
    trials, params, wf_record, settings, mapping, dofs, excluded, t_geometry = read
    muscles = restrict_geometry(trials[0].geometry).muscles
    full = settings_for_muscles(settings, muscles)
    emg_muscles = sorted(mapping_for_muscles(mapping, mapping, muscles))
    specs = emg_ten_specs(full, muscles, emg_muscles)
    goals = full.problem_goals
    return Problem(kind="emg", workflow=workflow, side=side, dofs=tuple(dofs),
                   trials=tuple(ProblemTrial(*t) for t in trials), emg_mode=settings.emg_mode,
                   parameters=params, goals=goals, specs=tuple(specs), options=emg_ten_options(options, settings),
                   model=Path(model), excluded_muscles=tuple(excluded), emg=settings,
                   emg_mapping={m: list(c) for m, c in mapping.items()}, workflow_record=wf_record,
                   check_units=check_units, geometry_time_s=t_geometry, inputs=inputs)


def _load_estimate(model, files, labels, workflow, side, dofs, estimate, couple, bounds, weights, emg_mode,
                   emg_tolerance, emg_mapping, passive, options, cache_dir, exclude_muscles, inputs):
    """:func:`load_problem` of a parameter estimation."""
    from .emg_inputs import trial_labels
    from .emg_ten import settings_for_muscles
    from .estimate import emg_couplings
    from .estimate_problem import EMG_SCALE_BOUNDS, check_estimate_options, read_estimate_trials
    from .goals import coupling_pairs

    exclude_muscles = list(exclude_muscles or ())
    checked = check_estimate_options(workflow, sum(f.ik is not None for f in files),
                                     sum(f.id is not None for f in files),
                                     [f.ultrasound for f in files if f.ultrasound is not None],
                                     [f.emg for f in files if f.emg is not None], estimate, couple, bounds, weights,
                                     emg_mode, emg_tolerance, exclude_muscles)
    given = [f.label for f in files]
    labels = trial_labels([f.ik for f in files], labels if labels is not None or all(g is None for g in given)
                          else given)
    options = options if options is not None else SolverOptions()
    trials, params, wf_record, dofs, mapping = read_estimate_trials(
        model, files, labels, workflow=workflow, side=side, dofs=dofs, passive=passive, options=options,
        cache_dir=cache_dir, exclude_muscles=exclude_muscles, emg_mapping=emg_mapping, specs=checked.specs)
    specs = list(checked.specs)
    if checked.mode is not None:
        emg_muscles = tuple(sorted(mapping))
        groups = emg_couplings(checked.couple) or settings_for_muscles(EmgTenSettings(), params.names).emg_groups
        specs.append(ParameterSpec("emg_scale", emg_muscles, checked.bounds.get("emg_scale", EMG_SCALE_BOUNDS),
                                   coupling_pairs(groups, emg_muscles, consecutive=False)))
    return Problem(kind="estimate", workflow=workflow, side=side, dofs=tuple(dofs),
                   trials=tuple(ProblemTrial(*t) for t in trials), parameters=params, goals=checked.goals,
                   specs=tuple(specs), options=options, model=Path(model), excluded_muscles=tuple(exclude_muscles),
                   emg_mode=checked.mode, emg_mapping={m: list(c) for m, c in mapping.items()},
                   workflow_record=wf_record, inputs=inputs)


def solve(problem: Problem, options: SolverOptions | None = None, *, warm_start: "Solution | None" = None,
          before_solve: Callable[..., object] | None = None) -> Result:
    """Solve ``problem`` (with ``options`` instead of its own, when given): a
    :class:`~.result.Result` whose ``problem`` is the problem solved.

    ``warm_start`` (an effort problem): a previous solution of the same trial as initial guess
    (:func:`.solve.solve_with_parameters`). ``before_solve``: called once the problem is known and
    before IPOPT starts, for each trial, with the keywords ``model_path``, ``ik_path``, ``time_s``
    (the mesh), ``parameters`` (the muscles' :class:`~.parameters.MuscleTendonParameters`) and
    ``dofs`` of the solution to come (not for EMG-TEN, whose parameters are known only after the
    solve)."""
    if options is not None:
        problem = problem.with_options(options)
    if problem.kind == "estimate":
        from .estimate_problem import solve_estimate

        result = solve_estimate(problem)
    else:
        result = _solve_emg(problem, before_solve) if problem.kind == "emg" else \
            _solve_effort(problem, warm_start, before_solve)
    solutions = {label: dataclasses.replace(sol, problem=problem) for label, sol in result.solutions.items()}
    return dataclasses.replace(result, solutions=solutions, problem=problem)


def _trial_entries(problem: Problem, trial: ProblemTrial, solution) -> dict:
    """The entries of a trial's record that the problem adds to its solution's."""
    from .trial_files import diagnosis_record

    return {"side": problem.side,
            "diagnosis": diagnosis_record(trial.diagnosis, solution, trial.geometry, trial.id_time_s,
                                          trial.id_moments_Nm, trial.ik_time_s, problem.mesh_frequency_hz),
            **({"excluded_muscles": list(problem.excluded_muscles)} if problem.excluded_muscles else {}),
            **dict(trial.record)}


def _solve_effort(problem: Problem, warm_start, before_solve) -> Result:
    """One trial of an effort workflow (:func:`.solve.solve_with_parameters`)."""
    from .inputs import mesh_for_window, restrict_geometry
    from .record import ProblemRecord

    trial = problem.trials[0]
    if before_solve is not None:
        solved = restrict_geometry(trial.geometry)
        before_solve(model_path=trial.sources["model"], ik_path=trial.sources["ik"],
                     parameters=problem.parameters.subset(solved.muscles), dofs=tuple(solved.dofs),
                     time_s=mesh_for_window(float(trial.ik_time_s[0]), float(trial.ik_time_s[-1]),
                                            problem.mesh_frequency_hz))
    solution = solve_with_parameters(
        trial.geometry, problem.parameters, trial.id_time_s, trial.id_moments_Nm, ik_time_s=trial.ik_time_s,
        options=problem.options, goals=problem.goals, workflow_record=dict(problem.workflow_record),
        sources=dict(trial.sources), check_units=problem.check_units, warm_start=warm_start,
        mesh_frequency_hz=problem.mesh_frequency_hz)
    solution = dataclasses.replace(solution, record=solution.record.with_(
        geometry_time_s=problem.geometry_time_s, **_trial_entries(problem, trial, solution)))
    record = ProblemRecord.from_dict({"workflow": problem.workflow, **solution.run_record.to_dict(),
                                      "total_time_s": solution.record.total_time_s,
                                      "geometry_time_s": problem.geometry_time_s, "side": problem.side})
    return Result(solutions={trial.label: solution}, parameters=solution.parameters, factors={}, record=record)


def _solve_emg(problem: Problem, before_solve) -> Result:
    """The EMG problem over all trials (:func:`.emg_pipeline.solve_emg_ten_arrays`)."""
    from .emg_pipeline import solve_emg_ten_arrays

    trials = problem.trials
    result = solve_emg_ten_arrays(
        [t.geometry for t in trials], None, [(t.id_time_s, t.id_moments_Nm) for t in trials], [t.emg for t in trials],
        labels=list(problem.labels), ik_times=[t.ik_time_s for t in trials],
        emg_mapping={m: list(c) for m, c in problem.emg_mapping.items()},
        settings=problem.emg, options=problem.options, sources=[dict(t.sources) for t in trials],
        check_units=problem.check_units, workflow=problem.workflow, before_solve=before_solve,
        parameters=(problem.parameters, dict(problem.workflow_record)))
    solutions = {t.label: dataclasses.replace(sol, record=sol.record.with_(**_trial_entries(problem, t, sol)))
                 for t, sol in zip(trials, result.solutions.values())}
    return dataclasses.replace(result, solutions=solutions,
                               record=result.record.with_(geometry_time_s=problem.geometry_time_s, side=problem.side))


def read_problem(out_dir: str | os.PathLike, cache_dir: str | os.PathLike | None = None) -> Problem | None:
    """The problem of a result folder, rebuilt from its ``problem.json`` (:mod:`.problem_file`):
    :func:`load_problem` again with the recorded files (checked by their hashes) and keywords, the
    geometry from the cache in ``cache_dir``, then the recorded muscle parameters and solver
    options; ``None``, with a warning saying why, when the folder has no ``problem.json`` (written
    before results kept their problem) or an input file is gone or changed."""
    from .problem_file import problem_keywords

    kept = problem_keywords(out_dir)
    if kept is None:
        return None
    kw = dict(kept["keywords"])
    trials = [TrialFiles(**t) for t in kw.pop("trials")]
    problem = load_problem(kw.pop("model"), trials, **kw, options=kept["options"], goals=kept["goals"],
                           emg=kept["emg"], cache_dir=cache_dir)
    parameters = dataclasses.replace(kept["parameters"], sources=dict(problem.parameters.sources))
    return problem.with_parameters(parameters).with_options(kept["solved_options"])


def load_result(out_dir: str | os.PathLike, *, require_success: bool = True,
                cache_dir: str | os.PathLike | None = None) -> Result:
    """:meth:`.result.Result.load` of ``out_dir`` with its problem (:func:`read_problem`) in
    ``result.problem`` (``None`` when it cannot be rebuilt, with a warning saying why)."""
    result = Result.load(out_dir, require_success=require_success)
    return dataclasses.replace(result, problem=read_problem(out_dir, cache_dir=cache_dir))
