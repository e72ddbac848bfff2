"""Solve one trial with one workflow: inputs -> static optimisation -> OCP -> :class:`Solution`.

:func:`solve_trial` works on arrays (a geometry-like object, model parameters, the ID
moments); :func:`solve_files` starts from the model, IK and ID files and gets the geometry from
:func:`musclemetab.geometry.compute_geometry` (OpenSim in its own worker process; this
process never imports ``opensim``).
"""

from __future__ import annotations

import os
import threading
import time as _time
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from .inputs import (
    DEFAULT_DOFS,
    check_moment_magnitudes,
    check_moments_per_body_mass,
    check_time_ranges,
    prepare_inputs,
    read_inverse_dynamics,
    read_kinematics,
    select_muscles,
)
from .parameters import MuscleTendonParameters
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

__all__ = ["solve_trial", "solve_files", "solve_with_parameters", "WARM_START_MU_INIT"]

#: Barrier parameter at the start of a warm-started solve (the default start uses IPOPT's 0.1).
WARM_START_MU_INIT = 1e-6


class _Geometry:
    def __init__(self, time, muscles, dofs, lmt_m, moment_arms_m):
        self.time, self.muscles, self.dofs = time, tuple(muscles), tuple(dofs)
        self.lmt_m, self.moment_arms_m = lmt_m, moment_arms_m


def _restrict_geometry(geometry):
    """Apply the muscle/DOF selection rule (no-op for a geometry that already follows it).

    DOFs that no selected muscle crosses are dropped (their ID columns must be dropped too).
    """
    r = np.asarray(geometry.moment_arms_m, dtype=float)
    km, kd = select_muscles(geometry.muscles, r, geometry.dofs)
    if km.size == len(geometry.muscles) and kd.size == len(geometry.dofs):
        return geometry
    return _Geometry(
        np.asarray(geometry.time, dtype=float),
        [geometry.muscles[i] for i in km],
        [geometry.dofs[j] for j in kd],
        np.asarray(geometry.lmt_m, dtype=float)[:, km],
        r[:, kd][:, :, km],
    )


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
    all_dofs = tuple(geometry.dofs)
    geometry = _restrict_geometry(geometry)
    if tuple(geometry.dofs) != all_dofs:
        keep = [all_dofs.index(d) for d in geometry.dofs]
        id_moments_Nm = np.asarray(id_moments_Nm, dtype=float).reshape(len(id_time_s), -1)[:, keep]
    params = params.subset(geometry.muscles)
    inputs = prepare_inputs(geometry, id_time_s, id_moments_Nm, ik_time_s=ik_time_s,
                            filter_inputs=filter_inputs, sources=dict(sources or {}))
    if check_units:
        check_moment_magnitudes(inputs.moments_frames_Nm, inputs.dofs, inputs.moment_arms_frames_m,
                                params.max_isometric_force_N, (sources or {}).get("id", "inverse dynamics"),
                                options.optimal_reserve_Nm)
    so = static_optimisation(inputs, params)
    if warm_start is None:
        guess = initial_guess(inputs, params, so)
    else:
        guess = guess_from_solution(warm_start, inputs, params, options.optimal_reserve_Nm)
        options = options.with_(ipopt={"mu_init": WARM_START_MU_INIT, **options.ipopt})
    t_prep = _time.perf_counter() - t_start
    ocp = solve_ocp(inputs, params, guess, options)
    summary = {
        **RunRecord.from_result(ocp, sources).to_dict(),
        "preparation_time_s": t_prep,
        "problem_size": {"variables": ocp.n_variables, "equality_constraints": ocp.n_constraints},
        "time_window_s": list(inputs.window_s),
        "n_intervals": inputs.n_intervals,
        "mesh_step_s": inputs.step_s,
        "optimal_reserve_Nm": options.optimal_reserve_Nm,
        "static_optimisation_objective": so.objective,
        "initial_guess": "static optimisation (rigid tendons)" if warm_start is None else
        f"warm start from {warm_start.summary.get('workflow', {}).get('name', 'a previous solution')} "
        f"(mu_init {WARM_START_MU_INIT:g})",
        "workflow": dict(workflow_record or {"name": "custom"}),
        "solver_options": options.to_dict(),
        "input_preparation": {"filter": "butterworth 6th order 6 Hz zero-phase (MATLAB filtfilt padding)"
                              if filter_inputs else "none",
                              "mesh_intervals_per_second": 100, "interpolation": "not-a-knot cubic spline"},
        "inputs": {k: str(v) for k, v in (sources or {}).items()},
    }
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
) -> Solution:
    """Solve one trial with a named workflow (``effort-gen``, ``effort-cal``, ``effort-ten``).

    See :func:`musclemetab.redundancy.workflows.workflow_parameters` for ``passive`` and the
    tendon-stiffness arguments; the workflow's weights override those of ``options``.
    """
    wf = get_workflow(workflow)
    params, record = workflow_parameters(
        wf, model_parameters, _restrict_geometry(geometry).muscles, passive=passive,
        tendon_stiffness=tendon_stiffness, tendon_stiffness_file=tendon_stiffness_file,
    )
    options = (options or SolverOptions()).with_(
        w_activation=wf.w_activation, w_reserve=wf.w_reserve, w_velocity=wf.w_velocity
    )
    return solve_with_parameters(
        geometry, params, id_time_s, id_moments_Nm, ik_time_s=ik_time_s, options=options,
        workflow_record=record, sources=sources, check_units=check_units, warm_start=warm_start,
    )


def solve_files(
    model_path: str | os.PathLike,
    ik_path: str | os.PathLike,
    id_path: str | os.PathLike,
    workflow: str = "effort-gen",
    *,
    dofs: Sequence[str] = DEFAULT_DOFS,
    passive=None,
    tendon_stiffness: Mapping[str, float] | None = None,
    tendon_stiffness_file=None,
    options: SolverOptions | None = None,
    cache_dir: str | os.PathLike | None = None,
    check_units: bool = True,
    warm_start: Solution | None = None,
) -> Solution:
    """Solve from files: model ``.osim``, IK ``.mot`` and ID ``.sto``.

    The inputs are checked (columns, units, time ranges) before the geometry is computed.
    """
    # Cheap checks of the options and parameter files first.
    wf = check_workflow_options(workflow, passive, tendon_stiffness, tendon_stiffness_file)
    if passive is not None and not isinstance(passive, PassiveParameters):
        passive = read_passive_parameters(passive)
    if tendon_stiffness_file is not None:
        read_tendon_stiffness_json(tendon_stiffness_file)
    # The model parameters come from the OpenSim worker process: ask now, in a background
    # thread, so that the worker's start-up overlaps with reading the IK/ID files, the
    # geometry and the imports of pandas, SciPy and CasADi.
    params_request = _Background(_read_model_parameters, model_path)
    ik_time, _ = read_kinematics(ik_path, dofs, check_units=check_units)
    id_time, id_moments = read_inverse_dynamics(id_path, dofs)
    check_time_ranges(ik_time, id_time, ik_path, id_path)
    from ..geometry import compute_geometry

    t0 = _time.perf_counter()
    geometry = compute_geometry(model_path, ik_path, dofs=list(dofs), side="r", cache_dir=cache_dir)
    t_geometry = _time.perf_counter() - t0
    import casadi  # noqa: F401  (imported while the worker answers)
    import scipy.interpolate  # noqa: F401
    import scipy.optimize  # noqa: F401
    import scipy.signal  # noqa: F401

    model_parameters = params_request.result()
    if check_units:
        from ..model import read_model

        check_moments_per_body_mass(id_moments, dofs, read_model(model_path).body_mass_kg, id_path, model_path)
    sources = {"model": Path(model_path), "ik": Path(ik_path), "id": Path(id_path)}
    solution = solve_trial(
        geometry, model_parameters, id_time, id_moments, wf,
        ik_time_s=ik_time, passive=passive, tendon_stiffness=tendon_stiffness,
        tendon_stiffness_file=tendon_stiffness_file, options=options, sources=sources,
        check_units=check_units, warm_start=warm_start,
    )
    solution.summary["geometry_time_s"] = t_geometry
    return solution



def _read_model_parameters(model_path):
    from ..model import read_muscle_parameters

    return read_muscle_parameters(model_path)


class _Background:
    """Run ``func(*args)`` in a daemon thread; :meth:`result` waits and re-raises its error."""

    def __init__(self, func, *args):
        self._value = self._error = None
        self._thread = threading.Thread(target=self._run, args=(func, args), daemon=True)
        self._thread.start()

    def _run(self, func, args):
        try:
            self._value = func(*args)
        except BaseException as exc:  # re-raised in the caller's thread
            self._error = exc

    def result(self):
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._value
