"""The pipeline from files to results: the one way the command line, the study and Python
users solve.

* :func:`solve_files` / :func:`solve_sides`: one trial with an effort workflow (model, IK, ID or
  ground forces; window or gait cycle), a :class:`~.solution.Solution`;
* :func:`.emg_run.solve_emg_ten`: EMG-TEN, or an effort workflow's EMG-informed solve, over one
  or more trials, a :class:`~.result.Result` (and :func:`.emg_run.emg_mappings_of_legs`);
* :func:`.estimate_run.estimate_files`: muscle-tendon parameters from fiber lengths and/or EMG
  over trials, written to a folder, a :class:`~.result.Result`;
* :func:`write_solution_folder`: a solution and the inverse dynamics computed for it.

Each is ``solve(load_problem(...))`` (:mod:`.problem`): the files are read and checked once,
before OpenSim is asked anything (:mod:`.trial_files`), into a :class:`~.problem.Problem` that
the result keeps.
"""

from __future__ import annotations

import os
from typing import Mapping, Sequence

from ..errors import OptionError
from ..events import WALKING_CYCLE_DURATION_S
from .._docs import fill_doc
from .inputs import MESH_FREQUENCY_HZ
from .ipopt import SolverOptions
from .estimate_problem import EMG_SCALE_BOUNDS, WEIGHT_NAMES
from .solution import Solution
from .trial_files import exclude_from_geometry

__all__ = ["solve_files", "solve_sides", "write_solution_folder", "check_solution_folders", "exclude_from_geometry",
           "WEIGHT_NAMES", "EMG_SCALE_BOUNDS"]


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
    assistance_both_legs: bool = False,
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
    else onto the cycle a study takes for the same files (the ground forces' ``grf``, else the
    window less 0.05 s at each end, toe-off from the ankle moment); the device's work is over that
    cycle; ``summary.json``'s ``assistance`` records it with the cycle and its source. A profile
    naming none of the leg's coordinates is refused unless ``assistance_both_legs`` (the other
    leg is solved too and takes its columns; :func:`solve_sides` sets it for both legs).

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
    from .problem import TrialFiles, load_problem, solve

    problem = load_problem(
        model_path, TrialFiles(ik_path, id_path), workflow=workflow, side=side, dofs=dofs, window=window, cycle=cycle,
        external_loads=external_loads, grf=grf, grf_column=grf_column, grf_threshold_N=grf_threshold_N,
        cycle_duration_s=cycle_duration_s, mesh_frequency_hz=mesh_frequency_hz, passive=passive,
        tendon_stiffness=tendon_stiffness, tendon_stiffness_file=tendon_stiffness_file, options=options, goals=goals,
        cache_dir=cache_dir, check_units=check_units, exclude_muscles=exclude_muscles,
        exclude_missing_ok=exclude_missing_ok, diagnose_only=diagnose_only, assistance=assistance,
        assistance_gain=assistance_gain, assistance_cycle_s=assistance_cycle_s,
        assistance_both_legs=assistance_both_legs)
    if diagnose_only:
        return problem
    if parameter_transform is not None:
        problem, before_solve = problem.with_parameters(parameter_transform(problem.parameters)), None
    return next(iter(solve(problem, warm_start=warm_start, before_solve=before_solve).solutions.values()))


def _solve_files_recording_warnings(args, kwargs, progress_s=None):
    """:func:`solve_files` in a pool worker: the solution and the warnings it raised; with
    ``progress_s`` the progress lines every ``progress_s`` seconds on this process's standard
    error (the caller's), labelled with the leg (:class:`~.ipopt.solve_progress`)."""
    import contextlib

    from ..processes import call_recording_warnings
    from .ipopt import solve_progress

    progress = contextlib.nullcontext() if progress_s is None else \
        solve_progress(progress_s, label=f" side {kwargs.get('side')}")
    with progress:
        return call_recording_warnings(solve_files, *args, **kwargs)


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
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise OptionError(f"--workers must be a whole number of at least 1, not {workers!r}")
    sides = tuple(sides)
    if kwargs.get("assistance") is not None:  # a profile of one leg's coordinates is that leg's
        kwargs.setdefault("assistance_both_legs", set(sides) == {"r", "l"})
    if workers == 1 or len(sides) == 1:
        return {side: solve_files(model_path, ik_path, id_path, workflow, side=side, **kwargs) for side in sides}
    kwargs.pop("before_solve", None)  # it would run in the leg's process, not in this one
    from ..processes import spawn_pool, stop_pool, warn_again

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
        warn_again(caught, stacklevel=2)  # at the line that called solve_sides
    return {side: solution for side, (solution, _) in results.items()}


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


def write_solution_folder(solution, out, opensim_files: bool = True, cache_dir=None) -> None:
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

        write_solution_opensim_files(solution, out, cache_dir=cache_dir)
