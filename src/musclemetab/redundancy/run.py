"""The pipeline from files to results: the one way the command line, the study and Python
users solve.

* :func:`solve_files` / :func:`solve_sides`: one trial with an effort workflow (model, IK, ID or
  ground forces; window or gait cycle), a :class:`~.solution.Solution`;
* :func:`solve_emg_ten`: EMG-TEN, or an effort workflow's EMG-informed solve, over one or more
  trials, a :class:`~.result.Result`;
* :func:`estimate_files`: muscle-tendon parameters from fiber lengths and/or EMG over trials,
  written to a folder, a :class:`~.result.Result`;
* :func:`write_solution_folder`: a solution and the inverse dynamics computed for it;
* :func:`emg_mappings_of_legs`: the EMG mapping of each leg of an EMG problem of both legs.

Each reads and checks its files before OpenSim is asked anything, gets the geometry from
:func:`musclemetab.geometry.compute_geometry` (OpenSim in its own worker process) and solves
with the array-level functions of :mod:`.solve` and :mod:`.emg_pipeline`.
"""

from __future__ import annotations

import dataclasses
import os
import time as _time
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import OptionError
from ..events import WALKING_CYCLE_DURATION_S
from ..messages import name_list
from ..processes import BackgroundCall
from ._docs import fill_doc
from .emg_inputs import (
    check_emg_range,
    check_emg_window,
    mapped_emg_table,
    one_model,
    path_list,
    resolve_emg_mapping,
    trial_labels,
)
from .emg_pipeline import solve_emg_ten_arrays
from .emg_ten import EmgTenSettings
from .result import EMG_TEN, ESTIMATE_FORMAT, Result
from .inputs import (
    MESH_FREQUENCY_HZ,
    GeometryArrays,
    check_id_coordinates,
    check_moments_per_body_mass,
    check_time_ranges,
    read_inverse_dynamics,
    read_kinematics,
)
from .ipopt import SolverOptions
from .solution import Solution
from .solve import solve_trial
from .workflows import PassiveParameters, check_workflow_options, read_passive_parameters, read_tendon_stiffness_json

__all__ = ["solve_files", "solve_sides", "solve_emg_ten", "emg_mappings_of_legs", "estimate_files",
           "write_solution_folder", "WEIGHT_NAMES", "EMG_SCALE_BOUNDS"]

WEIGHT_NAMES = {"activation": "w_activation", "reserve": "w_reserve", "velocity": "w_velocity",
                "fiber_length": "w_fiber_length", "emg": "w_emg"}
#: default bounds of the EMG scale factors (those of EMG-TEN)
EMG_SCALE_BOUNDS = (0.05, 2.5)



@fill_doc
def solve_files(
    model_path: str | os.PathLike,
    ik_path: str | os.PathLike,
    id_path: str | os.PathLike | None,
    workflow: str = "effort-gen",
    *,
    dofs: Sequence[str] | None = None,
    side: str = "r",
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
    goals=None,
    cache_dir: str | os.PathLike | None = None,
    check_units: bool = True,
    warm_start: Solution | None = None,
    exclude_muscles: Sequence[str] = (),
    exclude_missing_ok: bool = False,
    diagnose_only: bool = False,
    parameter_transform=None,
    before_solve=None,
) -> Solution:
    """Solve from files: model ``.osim``, IK ``.mot`` and ID ``.sto`` (or ground forces).

    ``side`` (``"r"``/``"l"``) chooses the leg; ``dofs`` default to the DOFs discovered from
    the model for that side (:func:`musclemetab.layout.discover_dofs`). The window is the IK
    file, ``window=(T0, T1)`` or ``cycle="auto"|N`` (:mod:`.window`; the foot's force from
    ``external_loads`` or from ``grf``, column ``grf_column``, contact above ``grf_threshold_N``,
    default 20 N, a cycle lasting ``cycle_duration_s``, 0.8-2.0 s by default). With ``id_path=None``
    and ``external_loads`` (an OpenSim ExternalLoads file), the inverse dynamics is computed
    by OpenSim over the window (:func:`musclemetab.external_loads.compute_inverse_dynamics`);
    its path is ``solution.record.inputs["id"]``. The mesh has ``mesh_frequency_hz``
    intervals per second (the study's 100 by default). ``exclude_muscles`` leaves muscles out of
    the problem (e.g. one whose fiber cannot reach force equilibrium within the bounds).
    The trial is diagnosed before the solve (:mod:`.diagnosis`: blocking findings raise
    :class:`~.diagnosis.InfeasibleInputError`, the others warn; ``summary.json``'s
    ``diagnosis``); with ``diagnose_only`` the :class:`~.diagnosis.Diagnosis` is returned,
    unchecked, instead of a solution, and nothing is solved. ``parameter_transform``: see
    :func:`.solve.solve_trial`. ``before_solve``: a function called, once the problem is known and
    before IPOPT starts, with the keywords ``model_path``, ``ik_path``, ``time_s`` (the mesh),
    ``parameters`` (the muscles' :class:`~.parameters.MuscleTendonParameters`) and ``dofs`` of the
    solution to come, e.g. :func:`.export.prepare_opensim_files` (``musclemetab solve``); not
    called with ``parameter_transform``.

    The inputs are checked (columns, units, time ranges) before the geometry is computed.

    Parameters
    ----------
    %(model)s
    ik_path, id_path
        The IK ``.mot`` and ID ``.sto`` files (``id_path=None``: from ``external_loads``).
    workflow
        ``effort-gen``, ``effort-cal`` or ``effort-ten`` (:mod:`.workflows`).
    %(side_dofs)s
    %(passive)s
    tendon_stiffness, tendon_stiffness_file
        EFFORT-TEN's tendon stiffness (:func:`.workflows.workflow_parameters`).
    %(options)s
    goals
        The effort weights (:class:`.transcription.Goals`; default: the workflow's).
    %(cache_dir)s
    %(check_units)s
    """
    from ..layout import check_dofs_in_model, check_side, discover_dofs, read_layout
    from .window import frames_in_window, resolve_window

    check_side(side)
    if not (mesh_frequency_hz > 0 and np.isfinite(mesh_frequency_hz)):
        raise OptionError(f"--mesh-frequency must be a positive number of intervals per second, not {mesh_frequency_hz!r}")
    # Cheap checks of the options and parameter files first.
    wf = check_workflow_options(workflow, passive, tendon_stiffness, tendon_stiffness_file)
    if passive is not None and not isinstance(passive, PassiveParameters):
        passive = read_passive_parameters(passive)
    if tendon_stiffness_file is not None:
        read_tendon_stiffness_json(tendon_stiffness_file)
    if id_path is None and external_loads is None:
        raise OptionError("give the inverse dynamics (--id ID.sto) or the ground forces to compute it "
                          "(--external-loads GRF.xml)")
    # Model parameters and geometry come from the on-disk cache when it holds them: no
    # OpenSim work at all then. Otherwise the OpenSim worker is started as soon as it is
    # known to be needed, so that its start-up overlaps with reading the files and the
    # imports of pandas and CasADi; the model parameters are asked for in a
    # background thread.
    from ..geometry import compute_geometry, geometry_is_cached
    from ..model import model_is_cached
    from ..opensim_bridge import start_in_background

    model_cached = model_is_cached(model_path, cache_dir)
    if not model_cached:
        start_in_background()
    params_request = None if model_cached else BackgroundCall(_read_model_parameters, model_path, cache_dir)
    layout = read_layout(model_path, cache_dir=cache_dir)
    loads = None
    if external_loads is not None:
        from ..external_loads import read_external_loads

        loads = read_external_loads(external_loads)
        loads.check_bodies(layout)
    from ..io import read_table

    # Each input file is read once; the tables go on to the window, the checks and the geometry.
    id_table = id_columns = None
    if id_path is not None:
        id_table = read_table(id_path)
        id_columns = list(id_table.columns)
        check_id_coordinates(id_path, id_columns, layout)
    if dofs:
        dofs = tuple(dofs)
        check_dofs_in_model(layout, dofs)
    else:
        dofs = tuple(discover_dofs(layout, side, id_columns))
    if model_cached and (id_path is None or not geometry_is_cached(model_path, ik_path, list(dofs),
                                                                   cache_dir=cache_dir)):
        start_in_background()
    ik_table = read_table(ik_path)
    trial_window = resolve_window(ik_table, side=side, window=window, cycle=cycle, id_path=id_table,
                                  external_loads=loads, grf_path=grf, layout=layout, grf_column=grf_column,
                                  grf_threshold_N=grf_threshold_N, cycle_duration_s=cycle_duration_s)
    id_record = None
    if id_path is None:
        from ..external_loads import ID_COORDINATE_FILTER_HZ, compute_inverse_dynamics

        id_path = compute_inverse_dynamics(model_path, ik_path, loads, trial_window.start_s, trial_window.end_s,
                                           cache_dir=cache_dir)
        id_table = read_table(id_path)
        id_record = {"computed_by": "OpenSim InverseDynamicsTool (muscles excluded)",
                     "coordinate_lowpass_hz": ID_COORDINATE_FILTER_HZ, "external_loads": str(loads.path),
                     "ground_force_data": str(loads.datafile)}
    ik_time, _ = read_kinematics(ik_table, dofs, check_units=check_units)
    id_time, id_moments = read_inverse_dynamics(id_table, dofs)
    keep = frames_in_window(ik_time, trial_window)
    ik_time = ik_time[keep]
    check_time_ranges(ik_time, id_time, ik_path, id_path)

    t0 = _time.perf_counter()
    geometry = compute_geometry(model_path, ik_table, dofs=list(dofs), side=side, cache_dir=cache_dir)
    if keep.size != len(geometry.time):
        geometry = GeometryArrays(np.asarray(geometry.time)[keep], geometry.muscles, geometry.dofs,
                             np.asarray(geometry.lmt_m)[keep], np.asarray(geometry.moment_arms_m)[keep])
    geometry, exclude_muscles = exclude_from_geometry(geometry, exclude_muscles, exclude_missing_ok)
    t_geometry = _time.perf_counter() - t0
    import casadi  # noqa: F401  (imported while the worker answers)

    model_parameters = (params_request.result() if params_request is not None
                        else _read_model_parameters(model_path, cache_dir))
    if check_units:
        from ..model import read_model

        check_moments_per_body_mass(id_moments, dofs, read_model(model_path, cache_dir=cache_dir).body_mass_kg, id_path, model_path)
    sources = {"model": Path(model_path), "ik": Path(ik_path), "id": Path(id_path)}
    if loads is not None:
        sources["external_loads"] = loads.path
    diagnosis, params = _diagnose_files(geometry, model_parameters, id_time, id_moments, wf, ik_time, passive,
                                        tendon_stiffness, tendon_stiffness_file, options, mesh_frequency_hz,
                                        Path(ik_path).stem, sources, check=not diagnose_only)
    if diagnose_only:
        return diagnosis
    if before_solve is not None and parameter_transform is None:
        from .inputs import mesh_for_window, restrict_geometry

        solved = restrict_geometry(geometry)
        before_solve(model_path=model_path, ik_path=ik_path, parameters=params.subset(solved.muscles),
                     time_s=mesh_for_window(float(ik_time[0]), float(ik_time[-1]), mesh_frequency_hz),
                     dofs=tuple(solved.dofs))
    solution = solve_trial(
        geometry, model_parameters, id_time, id_moments, wf,
        ik_time_s=ik_time, passive=passive, tendon_stiffness=tendon_stiffness,
        tendon_stiffness_file=tendon_stiffness_file, options=options, goals=goals, sources=sources,
        check_units=check_units, warm_start=warm_start, mesh_frequency_hz=mesh_frequency_hz,
        parameter_transform=parameter_transform,
    )
    trial = {"geometry_time_s": t_geometry, "side": side,
             "diagnosis": _diagnosis_record(diagnosis, solution, geometry, id_time, id_moments, ik_time,
                                            mesh_frequency_hz)}
    if exclude_muscles:
        trial["excluded_muscles"] = list(exclude_muscles)
    if trial_window.source != "inverse-kinematics file":
        trial["window"] = trial_window.record()
    if id_record is not None:
        trial["inverse_dynamics"] = id_record
    return dataclasses.replace(solution, record=solution.record.with_(**trial))


def exclude_from_geometry(geometry, exclude_muscles: Sequence[str] = (), missing_ok: bool = False):
    """``(geometry without the muscles of exclude_muscles, the excluded muscles it had)``;
    :class:`~musclemetab.errors.UnknownMuscleError` for a name the geometry lacks (unless
    ``missing_ok``: a muscle of the other leg)."""
    if not exclude_muscles:
        return geometry, []
    from ..errors import UnknownMuscleError

    unknown = [m for m in exclude_muscles if m not in geometry.muscles]
    excluded = [m for m in exclude_muscles if m in geometry.muscles]
    if unknown and not missing_ok:
        raise UnknownMuscleError(
            f"--exclude-muscles: {', '.join(unknown)} {'is' if len(unknown) == 1 else 'are'} not among the "
            f"muscles of the problem ({', '.join(geometry.muscles[:8])}, ...); check the names and the side"
        )
    kept = [i for i, m in enumerate(geometry.muscles) if m not in set(excluded)]
    kept_geometry = GeometryArrays(np.asarray(geometry.time), [geometry.muscles[i] for i in kept], geometry.dofs,
                                   np.asarray(geometry.lmt_m)[:, kept], np.asarray(geometry.moment_arms_m)[:, :, kept])
    return kept_geometry, excluded


def _diagnose_files(geometry, model_parameters, id_time, id_moments, wf, ik_time, passive, tendon_stiffness,
                    tendon_stiffness_file, options, mesh_frequency_hz, label, sources, check=True):
    """The diagnosis of one trial before its solve (:mod:`.diagnosis`): an
    :class:`~.diagnosis.InfeasibleInputError` for blocking findings, a warning for the others;
    ``(diagnosis, the workflow's parameters of the problem's muscles)``."""
    from .diagnosis import diagnose_geometry
    from .inputs import restrict_geometry
    from .workflows import workflow_parameters

    params, _ = workflow_parameters(wf, model_parameters, restrict_geometry(geometry).muscles, passive=passive,
                                    tendon_stiffness=tendon_stiffness, tendon_stiffness_file=tendon_stiffness_file)
    diagnosis = diagnose_geometry(
        geometry, params, id_time, id_moments, ik_time_s=ik_time, mesh_frequency_hz=mesh_frequency_hz,
        optimal_reserve_Nm=(options or SolverOptions()).optimal_reserve_Nm, trial=label,
        sources={k: str(v) for k, v in sources.items()})
    return (diagnosis.check(f"trial {label}") if check else diagnosis), params


def _diagnosis_record(diagnosis, solution, geometry, id_time, id_moments, ik_time,
                      mesh_frequency_hz=MESH_FREQUENCY_HZ) -> dict:
    """``summary.json``'s ``diagnosis``: the findings before the solve and, when the solve did
    not converge, the constraints its last iterate left violated (``last_iterate``)."""
    record = diagnosis.to_dict()
    if not solution.success:
        from .diagnosis import last_iterate_violations
        from .inputs import restrict_geometry, trial_inputs

        g = restrict_geometry(geometry)
        moments = np.asarray(id_moments, dtype=float).reshape(len(id_time), -1)
        moments = moments[:, [list(geometry.dofs).index(d) for d in g.dofs]]
        inputs = trial_inputs(g, id_time, moments, ik_time_s=ik_time, mesh_frequency_hz=mesh_frequency_hz)
        record["last_iterate"] = [f.to_dict() for f in last_iterate_violations(solution, inputs)]
    return record


def _solve_files_recording_warnings(args, kwargs, progress_s=None):
    """:func:`solve_files` in a pool worker: the solution and the warnings it raised; with
    ``progress_s`` the progress lines every ``progress_s`` seconds on this process's standard
    error (the caller's), labelled with the leg (:class:`~.ipopt.solve_progress`)."""
    import contextlib
    import warnings

    from .ipopt import solve_progress

    progress = contextlib.nullcontext() if progress_s is None else \
        solve_progress(progress_s, label=f" side {kwargs.get('side')}")
    with warnings.catch_warnings(record=True) as caught, progress:
        warnings.simplefilter("always")
        solution = solve_files(*args, **kwargs)
    return solution, [(w.category, str(w.message)) for w in caught]


def solve_sides(model_path, ik_path, id_path, workflow: str = "effort-gen", *, sides=("r", "l"), workers: int = 1,
                **kwargs) -> dict:
    """:func:`solve_files` for each leg of ``sides``: ``{side: Solution}`` in the order of ``sides``.

    The legs are independent problems. With ``workers`` > 1 they are solved in a pool of
    ``min(workers, len(sides))`` processes (:func:`musclemetab.processes.spawn_pool`), each
    with its own OpenSim worker; the warnings of a leg are raised again here, in the order of
    ``sides``, and its errors as if it had been solved in this process; while progress lines are
    on here (:class:`~.ipopt.solve_progress`) each leg writes its own, labelled with the leg. The solutions are the
    same either way (``tests/test_gait2392.py``; time: ``benchmarks/sides.py``). A ``before_solve``
    function (:func:`solve_files`) is called for legs solved in this process only.
    """
    import warnings

    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise OptionError(f"--workers must be a whole number of at least 1, not {workers!r}")
    sides = tuple(sides)
    if workers == 1 or len(sides) == 1:
        return {side: solve_files(model_path, ik_path, id_path, workflow, side=side, **kwargs) for side in sides}
    kwargs.pop("before_solve", None)  # it would run in the leg's process, not in this one
    from ..processes import spawn_pool, stop_pool

    from .ipopt import progress_interval

    pool, restore = spawn_pool(min(workers, len(sides)))
    try:
        futures = {side: pool.submit(_solve_files_recording_warnings, (model_path, ik_path, id_path, workflow),
                                     {**kwargs, "side": side}, progress_interval()) for side in sides}
        results = {side: fut.result() for side, fut in futures.items()}
    except KeyboardInterrupt:  # the legs' processes ignore Ctrl-C: stopped, not waited for
        stop_pool(pool)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        restore()
    for _, caught in results.values():
        for category, message in caught:
            warnings.warn(message, category, stacklevel=2)
    return {side: solution for side, (solution, _) in results.items()}


def _read_model_parameters(model_path, cache_dir=None):
    from ..model import read_muscle_parameters

    return read_muscle_parameters(model_path, cache_dir=cache_dir)


@fill_doc
def solve_emg_ten(
    model_path,
    ik_paths: Sequence[str | os.PathLike],
    id_paths: Sequence[str | os.PathLike],
    emg_paths: Sequence[str | os.PathLike],
    *,
    emg_mapping="default",
    labels: Sequence[str] | None = None,
    passive=None,
    dofs: Sequence[str] | None = None,
    side: str = "r",
    settings: EmgTenSettings | None = None,
    options: SolverOptions | None = None,
    cache_dir: str | os.PathLike | None = None,
    check_units: bool = True,
    workflow: str = EMG_TEN,
    tendon_stiffness=None,
    exclude_muscles: Sequence[str] = (),
    exclude_missing_ok: bool = False,
    diagnose_only: bool = False,
    before_solve=None,
) -> Result:
    """EMG-TEN from files: one model, and per trial an IK ``.mot``, an ID ``.sto`` and an EMG file.

    Parameters
    ----------
    model_path
        The ``.osim`` model (a list with one path per trial is accepted; they must be the
        same model).
    ik_paths, id_paths, emg_paths
        One file of each per trial, in the same order. EMG files hold processed, normalised
        envelopes (``musclemetab.emg.read_processed_emg``).
    %(emg_mapping)s
    %(labels)s
    %(passive)s
    %(side_dofs)s
    settings
        :class:`~.emg_ten.EmgTenSettings`: weights, bounds, couplings, EMG mode (default the study's).
    %(options)s
    %(cache_dir)s
    %(check_units)s
    exclude_muscles
        Muscles left out of the problem (as :func:`solve_files`). Their EMG channels are not
        used and their tendon stiffness is not estimated (each with a warning naming them).

    Each trial is diagnosed before the problem is built (:mod:`.diagnosis`): blocking
    findings raise :class:`~.diagnosis.InfeasibleInputError` naming muscles and times; with
    ``diagnose_only`` the list of the trials' :class:`~.diagnosis.Diagnosis` is returned,
    unchecked, and nothing is solved. ``before_solve``: called for each trial as by
    :func:`solve_files`, once the problem is known and before IPOPT starts, when the solve
    estimates no muscle parameter (an EMG-informed solve of an effort workflow; not EMG-TEN,
    whose tendon stiffness is known only after the solve).
    Input errors (package exceptions naming the file, channel or muscle) are raised before
    OpenSim is started: unequal numbers of IK/ID/EMG files, different models, EMG channels
    missing for the mapping, EMG not covering a trial's IK window, EMG outside ``[0, 1]`` in
    the window, besides the IK/ID checks of the single-trial solver (columns, units, time
    ranges). Muscles of a custom mapping that the model lacks are reported after the geometry.
    """
    from ..io import read_table
    from ..model import read_muscle_parameters
    from ..processes import BackgroundCall
    from .workflows import read_passive_parameters

    ik_paths = path_list(ik_paths, "ik_paths")
    id_paths = path_list(id_paths, "id_paths")
    emg_paths = path_list(emg_paths, "emg_paths")
    if not ik_paths:
        raise OptionError("EMG-TEN needs at least one trial (IK, ID and EMG file)")
    if not (len(ik_paths) == len(id_paths) == len(emg_paths)):
        raise OptionError(
            f"{len(ik_paths)} IK, {len(id_paths)} ID and {len(emg_paths)} EMG files; give one of each per trial, "
            "in the same order"
        )
    model = one_model(model_path, len(ik_paths))
    labels = trial_labels(ik_paths, labels)
    mapping = resolve_emg_mapping(emg_mapping)
    settings = settings or EmgTenSettings()
    if passive is not None and not hasattr(passive, "for_muscles"):
        passive = read_passive_parameters(passive)
    # each file is read once; every file is checked before OpenSim is asked anything
    id_tables = [read_table(p) for p in id_paths]
    dofs = _trial_dofs(model, id_tables, dofs, side, cache_dir)
    id_data, emg_tables, ik_times, ik_tables = [], [], [], []
    for ik, idp, id_table, emg, lab in zip(ik_paths, id_paths, id_tables, emg_paths, labels):
        ik_tables.append(read_table(ik))
        ik_time, _ = read_kinematics(ik_tables[-1], dofs, check_units=check_units)
        id_time, id_moments = read_inverse_dynamics(id_table, dofs)
        check_time_ranges(ik_time, id_time, ik, idp)
        table = mapped_emg_table(emg, mapping, f"EMG of trial {lab}")
        what = str(table.attrs.get("path", f"EMG of trial {lab}"))
        check_emg_window(table, ik_time, what, str(ik))
        check_emg_range(table, float(ik_time[0]), float(ik_time[-1]), settings.emg_range_tolerance, what)
        id_data.append((id_time, id_moments))
        emg_tables.append(table)
        ik_times.append(ik_time)
    params_request = BackgroundCall(read_muscle_parameters, model)
    from ..geometry import compute_geometry

    t0 = _time.perf_counter()
    geometries = [compute_geometry(model, ik, dofs=list(dofs), side=side, cache_dir=cache_dir) for ik in ik_tables]
    t_geometry = _time.perf_counter() - t0
    model_parameters = params_request.result()
    excluded = []
    if exclude_muscles:
        from .emg_ten import settings_without
        from .inputs import restrict_geometry

        settings = settings_without(settings, restrict_geometry(geometries[0]).muscles, exclude_muscles)
        pairs = [exclude_from_geometry(g, exclude_muscles, exclude_missing_ok) for g in geometries]
        geometries, excluded = [g for g, _ in pairs], pairs[0][1]
        mapping = _mapping_without(mapping, excluded)
        emg_tables = [_columns_without(t, excluded) for t in emg_tables]
    diagnoses = _diagnose_emg_trials(geometries, model_parameters, id_data, ik_times, labels, passive, settings,
                                     options, workflow, tendon_stiffness, check=not diagnose_only)
    if diagnose_only:
        return diagnoses
    if check_units:
        from ..model import read_model
        from .inputs import check_moments_per_body_mass

        mass = read_model(model).body_mass_kg
        for (_, moments), idp in zip(id_data, id_paths):
            check_moments_per_body_mass(moments, dofs, mass, idp, model)
    sources = [{"model": Path(model), "ik": Path(ik), "id": Path(idp),
                "emg": Path(emg) if isinstance(emg, (str, os.PathLike)) else f"EMG table of trial {lab}"}
               for ik, idp, emg, lab in zip(ik_paths, id_paths, emg_paths, labels)]
    result = solve_emg_ten_arrays(
        geometries, model_parameters, id_data, emg_tables, labels=labels, ik_times=ik_times, passive=passive,
        emg_mapping=mapping, settings=settings, options=options, sources=sources, check_units=check_units,
        workflow=workflow, tendon_stiffness=tendon_stiffness, before_solve=before_solve,
    )
    # the leg, in each trial's record as the single-trial solve's record holds it
    trial_entries = {label: {"side": side, "diagnosis": _diagnosis_record(diagnosis, solution, g, t, m, ik),
                             **({"excluded_muscles": list(excluded)} if excluded else {})}
                     for (label, solution), diagnosis, g, (t, m), ik in zip(result.solutions.items(), diagnoses,
                                                                          geometries, id_data, ik_times)}
    solutions = {label: dataclasses.replace(solution, record=solution.record.with_(**trial_entries[label]))
                 for label, solution in result.solutions.items()}
    return dataclasses.replace(result, solutions=solutions,
                               record=result.record.with_(geometry_time_s=t_geometry, side=side))


def _mapping_without(mapping: dict, excluded: Sequence[str]) -> dict:
    """The EMG mapping without the excluded muscles (a warning names those that had EMG)."""
    import warnings

    from ..errors import MusclemetabWarning

    dropped = [m for m in mapping if m in set(excluded)]
    if dropped:
        warnings.warn(f"--exclude-muscles {' '.join(dropped)}: the EMG of {', '.join(dropped)} "
                      f"({', '.join(c for m in dropped for c in mapping[m])}) is not used (the muscle is out of the "
                      "problem)", MusclemetabWarning, stacklevel=3)
    return {m: c for m, c in mapping.items() if m not in set(excluded)}


def _columns_without(table, excluded):
    """An EMG table mapped to muscles without the excluded muscles' columns (its attributes kept)."""
    out = table.drop(columns=[c for c in excluded if c in table.columns])
    out.attrs.update(table.attrs)
    return out


def _fiber_lengths_without(measured: dict, excluded) -> dict:
    """Measured fiber lengths without the excluded muscles (a warning names those dropped)."""
    import warnings

    from ..errors import MusclemetabWarning

    dropped = [m for m in measured if m in set(excluded)]
    if dropped:
        warnings.warn(f"--exclude-muscles {' '.join(dropped)}: the measured fiber lengths of {', '.join(dropped)} "
                      "are not used (the muscle is out of the problem)", MusclemetabWarning, stacklevel=3)
    return {m: v for m, v in measured.items() if m not in set(excluded)}


def _diagnose_emg_trials(geometries, model_parameters, id_data, ik_times, labels, passive, settings, options,
                         workflow, tendon_stiffness, check=True) -> list:
    """The diagnosis of each trial of an EMG problem before it is built (the estimated tendon
    stiffness within its bounds)."""
    from .diagnosis import diagnose_geometry
    from .emg_ten import settings_for_muscles
    from .inputs import restrict_geometry
    from .transcription import ParameterSpec
    from .workflows import workflow_parameters

    muscles = restrict_geometry(geometries[0]).muscles
    settings = settings_for_muscles(settings or EmgTenSettings(), muscles)
    params, _ = workflow_parameters("effort-cal" if workflow == EMG_TEN else workflow, model_parameters, muscles,
                                    passive=passive, tendon_stiffness=tendon_stiffness)
    kt = [m for m in settings.tendon_muscles if m in muscles]
    specs = [ParameterSpec("tendon_stiffness", tuple(kt), settings.tendon_scale_bounds)] if kt else []
    reserve = (options or SolverOptions()).optimal_reserve_Nm
    out = [diagnose_geometry(g, params, t, m, ik_time_s=ik, specs=specs, optimal_reserve_Nm=reserve, trial=lab)
           for g, (t, m), ik, lab in zip(geometries, id_data, ik_times, labels)]
    return [d.check(f"trial {d.trial}") for d in out] if check else out


def emg_mappings_of_legs(model, ik_path, emg_mapping, side: str, dofs=None, cache_dir=None) -> dict:
    """``{side: EMG mapping}`` of the legs to solve (``side`` ``"r"``, ``"l"`` or ``"both"``).
    With both legs the mapping must be a ``{muscle: [channels]}`` JSON file naming the muscles of
    both legs (the named mappings are one leg's electrodes); each leg takes the entries of its
    muscles (those spanning its DOFs, as its problem selects them, from the geometry of
    ``ik_path``)."""
    from ..errors import UnknownMuscleError
    from ..geometry import compute_geometry

    named = emg_mapping is None or str(emg_mapping).strip().lower() in ("default", "authors")
    if side != "both":
        return {side: emg_mapping or "default"}
    if named:
        raise OptionError("--side both with EMG needs --emg-mapping MAP.json: a JSON object naming each leg's "
                          "muscles and their EMG channels, e.g. {\"soleus_r\": [\"SOL_R\"], \"soleus_l\": "
                          "[\"SOL_L\"]} (the named mappings are one leg's electrodes)")
    if dofs:
        raise OptionError("--dofs names one leg's DOFs; with --side both leave it out (each leg's DOFs are discovered)")
    mapping = resolve_emg_mapping(emg_mapping)
    legs, placed = {}, set()
    for leg in ("r", "l"):
        muscles = set(compute_geometry(model, ik_path, side=leg, cache_dir=cache_dir).muscles)
        legs[leg] = {m: c for m, c in mapping.items() if m in muscles}
        placed |= set(legs[leg])
        if not legs[leg]:
            raise UnknownMuscleError(f"--emg-mapping {emg_mapping} names no muscle of the "
                                     f"{'right' if leg == 'r' else 'left'} leg; map its muscles to their channels")
    unplaced = sorted(set(mapping) - placed)
    if unplaced:
        raise UnknownMuscleError(f"--emg-mapping {emg_mapping}: {name_list(unplaced)} in neither leg's "
                                 "muscles; check the names")
    return legs


def _trial_dofs(model, id_files, dofs, side: str, cache_dir) -> tuple[str, ...]:
    """``dofs`` checked against the model, or the side's DOFs that every ID file (or its table,
    already read) holds."""
    from ..io import as_table, table_path
    from ..layout import check_dofs_in_model, check_side, discover_dofs, read_layout

    check_side(side)
    layout = read_layout(model, cache_dir=cache_dir)
    common = None
    for source in id_files:
        columns = list(as_table(source).columns)
        check_id_coordinates(table_path(source), columns, layout)
        common = [c for c in columns if common is None or c in common]
    if dofs:
        dofs = tuple(dofs)
        check_dofs_in_model(layout, dofs)
        return dofs
    return tuple(discover_dofs(layout, side, common))


#: The files a solution folder may hold (:func:`write_solution_folder`): each replaced only when
#: the package wrote it (:func:`musclemetab.io.atomic.check_replaceable`)
SOLUTION_FOLDER_FILES = ("solution.sto", "summary.json", "inverse_dynamics.sto", "model.osim", "states.sto",
                         "controls.sto", "forces.sto")


def check_solution_folders(folders) -> None:
    """Check, before anything is written, that none of the files of a solution folder
    (:data:`SOLUTION_FOLDER_FILES`) in any of ``folders`` would replace a file the package did not
    write, nor a folder (:class:`~musclemetab.errors.OptionError` naming the first)."""
    from ..io.atomic import check_replaceable

    for folder in folders:
        check_replaceable(folder, SOLUTION_FOLDER_FILES)


def write_solution_folder(solution, out, opensim_files: bool = True) -> None:
    """Write a solution; inverse dynamics computed by OpenSim goes beside it as ``inverse_dynamics.sto``,
    and with ``opensim_files`` the OpenSim model, states, controls and forces that reproduce it
    (:func:`.export.write_solution_opensim_files`)."""
    from pathlib import Path

    from ..io import atomic_write_bytes

    solution.write(out)
    if "inverse_dynamics" in solution.record:
        src = Path(solution.record.inputs["id"])
        atomic_write_bytes(Path(out) / "inverse_dynamics.sto", src.read_bytes(), mark=True)
    if opensim_files:
        from .export import write_solution_opensim_files

        write_solution_opensim_files(solution, out)



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
        raise OptionError(f"--exclude-muscles {' '.join(clash)} and --estimate/--couple name the same muscle"
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
