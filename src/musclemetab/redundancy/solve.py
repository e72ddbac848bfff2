"""Solve one trial with one workflow: inputs -> static optimisation -> OCP -> :class:`Solution`.

:func:`solve_trial` works on arrays (a geometry-like object, model parameters, the ID
moments); :func:`solve_files` starts from the model, IK and ID files and gets the geometry from
:func:`musclemetab.geometry.compute_geometry` (OpenSim in its own worker process; this
process never imports ``opensim``).
"""

from __future__ import annotations

import os
import time as _time
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from .inputs import (
    MESH_FREQUENCY_HZ,
    GeometryArrays,
    check_id_coordinates,
    check_moment_magnitudes,
    check_moments_per_body_mass,
    check_time_ranges,
    prepare_inputs,
    read_inverse_dynamics,
    read_kinematics,
    restrict_geometry,
)
from .parameters import MuscleTendonParameters
from ..errors import OptionError
from ..processes import BackgroundCall
from .problem import SolverOptions, solve_ocp
from .record import RunRecord
from .solution import Solution, build_solution
from .static_opt import guess_from_solution, initial_guess, static_optimisation
from .workflows import (
    PassiveParameters,
    check_workflow_options,
    get_workflow,
    read_passive_parameters,
    read_tendon_stiffness_json,
    workflow_parameters,
)

__all__ = ["solve_trial", "solve_files", "solve_sides", "solve_with_parameters", "WARM_START_MU_INIT"]

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
    inputs = prepare_inputs(geometry, id_time_s, id_moments_Nm, ik_time_s=ik_time_s,
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
    workflow_record: dict | None = None,
    sources: dict | None = None,
    check_units: bool = True,
    filter_inputs: bool = True,
    warm_start: Solution | None = None,
    mesh_frequency_hz: float = MESH_FREQUENCY_HZ,
) -> Solution:
    """Solve the muscle redundancy problem with explicit muscle parameters.

    ``id_moments_Nm`` columns follow ``geometry.dofs``. Returns a :class:`Solution` whose
    ``summary['status']``/``success`` report IPOPT's outcome (a failed solve is returned, not
    raised, so that it can be inspected; :meth:`Solution.load` refuses it by default).

    ``warm_start``: a previous solution of the same trial (same mesh and muscles, e.g. another
    workflow) used as initial guess, with IPOPT's barrier parameter starting at 1e-6. This is
    an option for speed, not the study's procedure: the problem has several local optima and a
    warm-started solve may end in another one (``summary['initial_guess']`` records it).
    """
    t_start = _time.perf_counter()
    options = options or SolverOptions()
    inputs, params, so = prepare_trial(geometry, params, id_time_s, id_moments_Nm, ik_time_s=ik_time_s,
                                       options=options, sources=sources, check_units=check_units,
                                       filter_inputs=filter_inputs, mesh_frequency_hz=mesh_frequency_hz)
    if warm_start is None:
        guess = initial_guess(inputs, params, so)
    else:
        guess = guess_from_solution(warm_start, inputs, params, options.optimal_reserve_Nm)
        options = options.with_(ipopt={"mu_init": WARM_START_MU_INIT, **options.ipopt})
    t_prep = _time.perf_counter() - t_start
    ocp = solve_ocp(inputs, params, guess, options)
    from .bounds import fiber_length_bounds_record

    summary = {
        **RunRecord.from_result(ocp, sources).to_dict(),
        "preparation_time_s": t_prep,
        "problem_size": {"variables": ocp.n_variables, "equality_constraints": ocp.n_constraints},
        "time_window_s": list(inputs.window_s),
        "n_intervals": inputs.n_intervals,
        "mesh_step_s": inputs.step_s,
        "optimal_reserve_Nm": options.optimal_reserve_Nm,
        "static_optimisation_objective": so.objective,
        "fiber_dynamics": options.fiber_dynamics,
        "fiber_length_bounds": fiber_length_bounds_record(inputs, params),
        "initial_guess": "static optimisation (rigid tendons)" if warm_start is None else
        f"warm start from {warm_start.summary.get('workflow', {}).get('name', 'a previous solution')} "
        f"(mu_init {WARM_START_MU_INIT:g})",
        "workflow": dict(workflow_record or {"name": "custom"}),
        "solver_options": options.to_dict(),
        "input_preparation": {"filter": "butterworth 6th order 6 Hz zero-phase (MATLAB filtfilt padding)"
                              if filter_inputs else "none",
                              "mesh_intervals_per_second": mesh_frequency_hz, "interpolation": "not-a-knot cubic spline"},
        "inputs": {k: str(v) for k, v in (sources or {}).items()},
    }
    if options.energy is not None:
        from .energy import leg_rate_W_per_kg

        N = inputs.n_intervals
        rate = leg_rate_W_per_kg(options.energy, params, inputs.muscles, ocp.excitation, ocp.activation[:N],
                                 ocp.lm_norm[:N], ocp.fiber_velocity_lmo_per_s)
        summary["energy_goal"] = {**options.energy.record(), "w_activation": options.w_activation,
                                  "leg_mean_W_per_kg": float(np.mean(rate))}
    solution = build_solution(inputs, params, ocp, summary)
    solution.summary["total_time_s"] = _time.perf_counter() - t_start
    return solution


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
    sources: dict | None = None,
    check_units: bool = True,
    warm_start: Solution | None = None,
    mesh_frequency_hz: float = MESH_FREQUENCY_HZ,
) -> Solution:
    """Solve one trial with a named workflow (``effort-gen``, ``effort-cal``, ``effort-ten``).

    See :func:`musclemetab.redundancy.workflows.workflow_parameters` for ``passive`` and the
    tendon-stiffness arguments; the workflow's weights override those of ``options`` (the effort weight
    of ``options.energy``, when it has one, overrides the workflow's).
    """
    wf = get_workflow(workflow)
    params, record = workflow_parameters(
        wf, model_parameters, restrict_geometry(geometry).muscles, passive=passive,
        tendon_stiffness=tendon_stiffness, tendon_stiffness_file=tendon_stiffness_file,
    )
    options = options or SolverOptions()
    effort = options.energy.effort_weight if options.energy is not None else None
    options = options.with_(
        w_activation=wf.w_activation if effort is None else effort, w_reserve=wf.w_reserve, w_velocity=wf.w_velocity
    )
    return solve_with_parameters(
        geometry, params, id_time_s, id_moments_Nm, ik_time_s=ik_time_s, options=options,
        workflow_record=record, sources=sources, check_units=check_units, warm_start=warm_start,
        mesh_frequency_hz=mesh_frequency_hz,
    )


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
    mesh_frequency_hz: float = MESH_FREQUENCY_HZ,
    passive=None,
    tendon_stiffness: Mapping[str, float] | None = None,
    tendon_stiffness_file=None,
    options: SolverOptions | None = None,
    cache_dir: str | os.PathLike | None = None,
    check_units: bool = True,
    warm_start: Solution | None = None,
    exclude_muscles: Sequence[str] = (),
    exclude_missing_ok: bool = False,
) -> Solution:
    """Solve from files: model ``.osim``, IK ``.mot`` and ID ``.sto`` (or ground forces).

    ``side`` (``"r"``/``"l"``) chooses the leg; ``dofs`` default to the DOFs discovered from
    the model for that side (:func:`musclemetab.layout.discover_dofs`). The window is the IK
    file, ``window=(T0, T1)`` or ``cycle="auto"|N`` (:mod:`.window`; the foot's force from
    ``external_loads`` or from ``grf``, column ``grf_column``, contact above ``grf_threshold_N``,
    default 20 N). With ``id_path=None``
    and ``external_loads`` (an OpenSim ExternalLoads file), the inverse dynamics is computed
    by OpenSim over the window (:func:`musclemetab.external_loads.compute_inverse_dynamics`);
    its path is ``solution.summary["inputs"]["id"]``. The mesh has ``mesh_frequency_hz``
    intervals per second (the study's 100 by default). ``exclude_muscles`` leaves muscles out of
    the problem (e.g. one whose fiber cannot reach force equilibrium within the bounds).

    The inputs are checked (columns, units, time ranges) before the geometry is computed.
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
                                  grf_threshold_N=grf_threshold_N)
    id_record = None
    if id_path is None:
        from ..external_loads import ID_COORDINATE_FILTER_HZ, compute_inverse_dynamics

        id_path = compute_inverse_dynamics(model_path, ik_path, loads, trial_window.start_s, trial_window.end_s)
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
    if exclude_muscles:
        from ..errors import UnknownMuscleError

        unknown = [m for m in exclude_muscles if m not in geometry.muscles]
        exclude_muscles = [m for m in exclude_muscles if m in geometry.muscles]
        if unknown and not exclude_missing_ok:
            raise UnknownMuscleError(
                f"--exclude-muscles: {', '.join(unknown)} {'is' if len(unknown) == 1 else 'are'} not among the "
                f"muscles of the problem ({', '.join(geometry.muscles[:8])}, ...); check the names and the side"
            )
        kept = [i for i, m in enumerate(geometry.muscles) if m not in set(exclude_muscles)]
        geometry = GeometryArrays(np.asarray(geometry.time), [geometry.muscles[i] for i in kept], geometry.dofs,
                             np.asarray(geometry.lmt_m)[:, kept], np.asarray(geometry.moment_arms_m)[:, :, kept])
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
    solution = solve_trial(
        geometry, model_parameters, id_time, id_moments, wf,
        ik_time_s=ik_time, passive=passive, tendon_stiffness=tendon_stiffness,
        tendon_stiffness_file=tendon_stiffness_file, options=options, sources=sources,
        check_units=check_units, warm_start=warm_start, mesh_frequency_hz=mesh_frequency_hz,
    )
    solution.summary["geometry_time_s"] = t_geometry
    solution.summary["side"] = side
    if exclude_muscles:
        solution.summary["excluded_muscles"] = list(exclude_muscles)
    if trial_window.source != "inverse-kinematics file":
        solution.summary["window"] = trial_window.record()
    if id_record is not None:
        solution.summary["inverse_dynamics"] = id_record
    return solution


def _solve_files_recording_warnings(args, kwargs):
    """:func:`solve_files` in a pool worker: the solution and the warnings it raised."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        solution = solve_files(*args, **kwargs)
    return solution, [(w.category, str(w.message)) for w in caught]


def solve_sides(model_path, ik_path, id_path, workflow: str = "effort-gen", *, sides=("r", "l"), workers: int = 1,
                **kwargs) -> dict:
    """:func:`solve_files` for each leg of ``sides``: ``{side: Solution}`` in the order of ``sides``.

    The legs are independent problems. With ``workers`` > 1 they are solved in a pool of
    ``min(workers, len(sides))`` processes (:func:`musclemetab.processes.spawn_pool`), each
    with its own OpenSim worker; the warnings of a leg are raised again here, in the order of
    ``sides``, and its errors as if it had been solved in this process. The solutions are the
    same either way (``tests/test_gait2392.py``; time: ``benchmarks/sides.py``).
    """
    import warnings

    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise OptionError(f"--workers must be a whole number of at least 1, not {workers!r}")
    sides = tuple(sides)
    if workers == 1 or len(sides) == 1:
        return {side: solve_files(model_path, ik_path, id_path, workflow, side=side, **kwargs) for side in sides}
    from ..processes import spawn_pool

    pool, restore = spawn_pool(min(workers, len(sides)))
    try:
        futures = {side: pool.submit(_solve_files_recording_warnings, (model_path, ik_path, id_path, workflow),
                                     {**kwargs, "side": side}) for side in sides}
        results = {side: fut.result() for side, fut in futures.items()}
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


def muscles_at_fiber_length_bound(solution: Solution, tolerance: float = 1e-3) -> list[str]:
    """Muscles whose normalised fiber length reaches the problem's upper bound somewhere
    (1.7, or the widened bound recorded in ``summary['fiber_length_bounds']``)."""
    from .bounds import FIBER_LENGTH_BOUNDS

    widened = solution.summary.get("fiber_length_bounds", {}).get("widened_upper", {})
    top = np.max(np.asarray(solution.lm_norm, dtype=float), axis=0)
    return [m for m, v in zip(solution.muscles, top) if v >= widened.get(m, FIBER_LENGTH_BOUNDS[1]) - tolerance]
