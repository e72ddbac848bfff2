"""The pipeline from files to results: the one way the command line, the study and Python
users solve.

* :func:`solve_files` / :func:`solve_sides`: one trial with an effort workflow (model, IK, ID or
  ground forces; window or gait cycle), a :class:`~.solution.Solution`;
* :func:`.emg_run.solve_emg_ten`: EMG-TEN, or an effort workflow's EMG-informed solve, over one
  or more trials, a :class:`~.result.Result` (and :func:`.emg_run.emg_mappings_of_legs`);
* :func:`.estimate_run.estimate_files`: muscle-tendon parameters from fiber lengths and/or EMG
  over trials, written to a folder, a :class:`~.result.Result`;
* :func:`write_solution_folder`: a solution and the inverse dynamics computed for it; the helpers
  the three share (muscles left out, the trial's DOFs, the diagnosis record).

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
from .._docs import fill_doc
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

__all__ = ["solve_files", "solve_sides", "write_solution_folder", "check_solution_folders", "exclude_from_geometry",
           "WEIGHT_NAMES", "EMG_SCALE_BOUNDS"]

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
    assistance: str | os.PathLike | None = None,
    assistance_gain: float = 1.0,
    assistance_cycle_s: tuple[float, float] | None = None,
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
    called with ``parameter_transform``. ``assistance``: a device torque profile
    (:mod:`musclemetab.redundancy.assistance`, ``docs/assistance.md``) times ``assistance_gain`` taken off the
    ID moments before the solve; a profile over the gait cycle is mapped onto the cycle of
    ``cycle`` when the window comes from one, else onto ``assistance_cycle_s`` (start, end in s),
    else onto the window; ``summary.json``'s ``assistance`` records it with the device's work.

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
        The effort weights (:class:`.goals.Goals`; default: the workflow's).
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
    ik_time, ik_angles = read_kinematics(ik_table, dofs, check_units=check_units)
    id_time, id_moments = read_inverse_dynamics(id_table, dofs)
    keep = frames_in_window(ik_time, trial_window)
    ik_time, ik_angles = ik_time[keep], ik_angles[keep]
    check_time_ranges(ik_time, id_time, ik_path, id_path)
    device, file_moments = None, id_moments
    if assistance is not None:  # the muscles supply what the device does not (musclemetab.redundancy.assistance)
        id_moments, device = _assisted_moments(assistance, assistance_gain, assistance_cycle_s, trial_window, layout,
                                               model_path, cache_dir, side, dofs, id_time, id_moments,
                                               check_units)

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

        check_moments_per_body_mass(file_moments, dofs, read_model(model_path, cache_dir=cache_dir).body_mass_kg, id_path, model_path)
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
    if device is not None:
        from .assistance import assistance_record

        profile, cycle_s, cycle_source = device
        trial["assistance"] = assistance_record(profile, assistance_gain, dofs, ik_time, ik_angles, solution.time_s,
                                                cycle_s, cycle_source)
    return dataclasses.replace(solution, record=solution.record.with_(**trial))


def _assisted_moments(path, gain, cycle_s, trial_window, layout, model_path, cache_dir, side, dofs, id_time,
                      id_moments, check_units):
    """``(moments less the device torque, (profile, gait cycle, its source))`` of :func:`solve_files`."""
    from .assistance import apply_assistance, read_assistance
    from ..model import read_model

    profile = read_assistance(path)
    if trial_window.cycle is not None:
        cycle_s, source = (trial_window.cycle["start_s"], trial_window.cycle["end_s"]), "gait cycle of the solve"
    elif cycle_s is not None:
        cycle_s, source = (float(cycle_s[0]), float(cycle_s[1])), "given"
    else:
        cycle_s, source = (trial_window.start_s, trial_window.end_s), "solve window"
    mass = read_model(model_path, cache_dir=cache_dir).body_mass_kg if check_units else None
    moments = apply_assistance(id_time, id_moments, dofs, profile, gain,
                               window_s=(trial_window.start_s, trial_window.end_s), cycle_s=cycle_s, side=side,
                               model_coordinates=[c["name"] for c in layout.coordinates], body_mass_kg=mass,
                               check_units=check_units)
    return moments, (profile, cycle_s, source)


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
            f"--exclude-muscles: {name_list(unknown)} {'is' if len(unknown) == 1 else 'are'} not among the "
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


def _mapping_without(mapping: dict, excluded: Sequence[str]) -> dict:
    """The EMG mapping without the excluded muscles (a warning names those that had EMG)."""
    import warnings

    from ..errors import MusclemetabWarning

    dropped = [m for m in mapping if m in set(excluded)]
    if dropped:
        warnings.warn(f"--exclude-muscles {name_list(dropped, sep=' ')}: the EMG of {name_list(dropped)} "
                      f"({name_list([c for m in dropped for c in mapping[m]])}) is not used (the muscle is out of the "
                      "problem)", MusclemetabWarning, stacklevel=3)
    return {m: c for m, c in mapping.items() if m not in set(excluded)}


def _fiber_lengths_without(measured: dict, excluded) -> dict:
    """Measured fiber lengths without the excluded muscles (a warning names those dropped)."""
    import warnings

    from ..errors import MusclemetabWarning

    dropped = [m for m in measured if m in set(excluded)]
    if dropped:
        warnings.warn(f"--exclude-muscles {name_list(dropped, sep=' ')}: the measured fiber lengths of {name_list(dropped)} "
                      "are not used (the muscle is out of the problem)", MusclemetabWarning, stacklevel=3)
    return {m: v for m, v in measured.items() if m not in set(excluded)}


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
