"""The record of one solve: status, IPOPT statistics, timings, software versions, input hashes.

:class:`RunRecord` is the IPOPT outcome of every solve (one trial or several in one problem): the
solver writes it into ``summary.json``/``parameters.json`` (:meth:`RunRecord.to_dict`), a
:class:`~.solution.Solution` and the EMG-TEN result give it back (``.run_record``), and the study
runner turns a failed one into the one-line reason of ``failures.csv`` (:meth:`RunRecord.failure`).
:class:`SolveRecord` is the whole record of one trial's solution, every entry of its
``summary.json`` typed (``Solution.record``); :class:`ProblemRecord` the record of a problem over
one or more trials, the ``solve`` section of ``parameters.json`` typed (``Result.record``).
"""

from __future__ import annotations

import math
import os
import platform
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from .entries import (
    AssistanceRecord, ConvergenceRecord, EmgRecord, EnergyFormRecord, EnergyGoalRecord, FiberLengthBounds,
    InputPreparation, InverseDynamicsRecord, ProblemSize, SolverOptionsRecord, TrialRecord, WindowRecord, WorkflowRecord,
    _Typed, entry, frozen, records, thaw,
)

if TYPE_CHECKING:
    from .diagnosis import Diagnosis

__all__ = ["RunRecord", "SolveRecord", "ProblemRecord", "solver_versions", "input_hashes"]

def solver_versions() -> dict:
    """Versions of musclemetab, Python and (when importable) CasADi."""
    from .. import __version__

    out = {"musclemetab": __version__, "python": platform.python_version()}
    try:
        import casadi

        out["casadi"] = casadi.__version__
    except Exception:  # pragma: no cover
        pass
    return out


def input_hashes(sources: dict) -> dict:
    """SHA-256 of each input file named in ``sources`` (``{role: path}``); other entries are skipped."""
    from ..io.atomic import file_sha256

    out = {}
    for role, p in (sources or {}).items():
        if isinstance(p, (str, os.PathLike)) and Path(p).is_file():
            out[str(role)] = file_sha256(p)
    return out


@dataclass(frozen=True)
class RunRecord:
    """Outcome and cost of one solve."""

    status: str
    success: bool
    iterations: int = -1
    objective: float = math.nan
    objective_terms: dict = field(default_factory=dict)
    solve_time_s: float = math.nan
    solve_cpu_time_s: float = math.nan
    build_time_s: float = math.nan
    function_evaluation_time_s: dict = field(default_factory=dict)
    max_constraint_violation: float = math.nan
    software: dict = field(default_factory=dict)
    input_hashes: dict = field(default_factory=dict)

    def __post_init__(self):
        for name in ("objective_terms", "function_evaluation_time_s", "software", "input_hashes"):
            object.__setattr__(self, name, frozen(getattr(self, name)))

    @property
    def message(self) -> str:
        """What the status means and what to do (:func:`~.ipopt.failure_advice`)."""
        from .ipopt import failure_advice

        return "converged" if self.success else failure_advice(self.status)

    @classmethod
    def from_result(cls, result, sources: dict | None = None) -> "RunRecord":
        """From a raw optimum (:class:`~.ipopt.OcpResult` or :class:`~.ipopt.ProblemResult`)."""
        return cls(
            status=result.status, success=result.success, iterations=result.iterations,
            objective=result.objective, objective_terms=dict(result.objective_terms),
            solve_time_s=result.solve_time_s, solve_cpu_time_s=result.solve_cpu_s,
            build_time_s=result.build_time_s, function_evaluation_time_s=dict(result.function_time_s),
            max_constraint_violation=result.max_constraint_violation, software=solver_versions(),
            input_hashes=input_hashes(sources or {}),
        )

    @classmethod
    def from_dict(cls, d: dict) -> "RunRecord":
        """From a ``summary.json`` or ``parameters.json`` ``solve`` section (missing fields: unknown)."""
        names = cls.__dataclass_fields__
        kw = {k: d[k] for k in names if k in d}
        kw.setdefault("status", "unknown")
        kw.setdefault("success", False)
        return cls(**kw)

    def to_dict(self) -> dict:
        return {
            "status": self.status, "success": self.success, "message": self.message,
            "objective": self.objective, "objective_terms": thaw(self.objective_terms), "iterations": self.iterations,
            "solve_time_s": self.solve_time_s, "solve_cpu_time_s": self.solve_cpu_time_s,
            "build_time_s": self.build_time_s, "function_evaluation_time_s": thaw(self.function_evaluation_time_s),
            "ms_per_iteration": 1e3 * self.solve_time_s / max(self.iterations, 1),
            "max_constraint_violation": self.max_constraint_violation,
            "software": thaw(self.software), "input_hashes": thaw(self.input_hashes),
        }

    def failure(self, what: str):
        """The :class:`~musclemetab.errors.SolverError` of a solve that did not succeed."""
        from ..errors import SolverError

        return SolverError(f"{what} did not converge: IPOPT status {self.status} after {self.iterations} "
                           f"iterations ({self.message})")


_ABSENT = None


def _flags(records) -> tuple:
    from ..quality import flags_from_records

    return tuple(flags_from_records(records))


def _diagnosis(d):
    from .diagnosis import Diagnosis

    return Diagnosis.from_dict(d)


class _FileRecord(_Typed):
    """The round trip of a typed record to the JSON dictionary it was read from or is written as:
    the dataclass fields are the known entries (the structured ones typed, :mod:`.entries`),
    ``extra`` holds the others (older or newer files, kept as read) and ``keys`` the file's order
    of entries, so that :meth:`to_dict` gives back exactly the dictionary :meth:`from_dict` read.
    A dictionary given for a typed entry (by a builder) becomes that entry's record. A stage that
    adds an entry makes a new record (:meth:`with_`)."""

    _ORDER = "keys"

    def get(self, key: str, default=None):
        """The entry ``key`` of the file's dictionary, ``default`` when the record has none."""
        if key not in self.keys:
            return default
        return self._value(key)

    def __contains__(self, key: str) -> bool:
        return key in self.keys

    @property
    def run_record(self) -> RunRecord:
        """The IPOPT outcome (:class:`RunRecord`)."""
        return RunRecord.from_dict(self.to_dict())


@dataclass(frozen=True)
class _OutcomeRecord(_FileRecord):
    """The entries of :class:`RunRecord` (IPOPT's outcome) that every solve record holds."""

    # the IPOPT outcome (RunRecord)
    status: str = "unknown"
    success: bool = False
    message: str | None = _ABSENT
    objective: float | None = _ABSENT
    objective_terms: Mapping | None = _ABSENT
    iterations: int | None = _ABSENT
    solve_time_s: float | None = _ABSENT
    solve_cpu_time_s: float | None = _ABSENT
    build_time_s: float | None = _ABSENT
    function_evaluation_time_s: Mapping | None = _ABSENT
    ms_per_iteration: float | None = _ABSENT
    max_constraint_violation: float | None = _ABSENT
    software: Mapping | None = _ABSENT
    input_hashes: Mapping | None = _ABSENT
    #: how converged the rates are (:func:`~.convergence.convergence_record`): stop, tolerance,
    #: final barrier parameter, the share of each model's rate carried by muscles that are off
    convergence: ConvergenceRecord | None = entry(ConvergenceRecord)

    def outcome_lines(self) -> list[str]:
        """The lines of a printed summary: IPOPT's outcome (status, iterations, objective, time),
        where it stopped and how converged the rates are (:mod:`~.convergence`), and (a solve's
        record) the plausibility flags by code."""
        from .convergence import UNCONVERGED_RATE_SHARE

        run = str(self.status) + (f" in {int(self.iterations)} iterations" if self.iterations is not None else "")
        if self.objective is not None:
            run += f", objective {float(self.objective):.6g}"
        if self.solve_time_s is not None:
            run += f", solve {float(self.solve_time_s):.1f} s"
        conv, options = self.convergence, self.solver_options
        where = conv.stop if conv is not None and "stop" in conv else options.stop if options is not None else None
        tol = conv.tolerance if conv is not None and "tolerance" in conv else options.tol if options is not None else None
        where = "?" if where is None else where
        stop = f"stop {where}" + (f" (tolerance {tol:g})" if tol is not None else "")
        worst = None if conv is None else conv.max_rate_residue
        if worst is None:
            rates = "rates' convergence not checked"
        else:
            state = "converged" if worst <= UNCONVERGED_RATE_SHARE else "NOT converged"
            rates = f"rates {state} (off muscles carry {100 * worst:.2g} % of a leg's rate)"
        if not hasattr(self, "plausibility"):  # a problem of several trials: each solution holds its own
            return [run, f"{stop}; {rates}"]
        flags = self.plausibility
        if flags is None:
            quality = "plausibility not checked"
        elif not flags:
            quality = "plausibility ok"
        else:
            codes = list(dict.fromkeys(f.code for f in flags))
            quality = f"{len(flags)} plausibility flag{'s' if len(flags) > 1 else ''} ({', '.join(codes)})"
        return [run, f"{stop}; {rates}", quality]


@dataclass(frozen=True)
class SolveRecord(_OutcomeRecord):
    """Everything ``summary.json`` says about one solve, typed; built once, complete.

    The fields are those the builders of a solution write (:func:`~.solve.solve_with_parameters`,
    the EMG-TEN and estimation problems, :func:`~.solution.build_solution` for the residuals and
    reserve statistics, :func:`~.run.solve_files` for side, window and geometry time, and
    :meth:`~.solution.Solution.write` for the file's muscles, DOFs, parameters and conventions).
    An optional entry the solve did not record is ``None``. ``keys`` lists the entries the record holds,
    in the file's order; ``extra`` holds entries of other (older or newer) files, kept as read.
    :meth:`to_dict` gives back exactly the file's dictionary and :meth:`from_dict` reads it, so that
    a folder loads and writes again unchanged. A stage that adds an entry makes a new record
    (:meth:`with_`).
    """

    # the problem
    workflow: WorkflowRecord | None = entry(WorkflowRecord)
    objective_trial: float | None = _ABSENT
    preparation_time_s: float | None = _ABSENT
    problem_size: ProblemSize | None = entry(ProblemSize)
    time_window_s: tuple | None = _ABSENT
    n_intervals: int | None = _ABSENT
    mesh_step_s: float | None = _ABSENT
    optimal_reserve_Nm: float | None = _ABSENT
    static_optimisation_objective: float | None = _ABSENT
    fiber_dynamics: str | None = _ABSENT
    fiber_length_bounds: FiberLengthBounds | None = entry(FiberLengthBounds)
    initial_guess: str | None = _ABSENT
    solver_options: SolverOptionsRecord | None = entry(SolverOptionsRecord)
    input_preparation: InputPreparation | None = entry(InputPreparation)
    inputs: Mapping | None = _ABSENT
    energy_goal: EnergyGoalRecord | None = entry(EnergyGoalRecord)
    #: the energy goal's form and smoothing (``EnergyGoal.form_record``): model, form, the
    #: non-negativity rule minimised, smoothing ``s``
    energy_form: EnergyFormRecord | None = entry(EnergyFormRecord)
    emg: EmgRecord | None = entry(EmgRecord)
    emg_tracking: Mapping | None = _ABSENT
    emg_tolerance: float | None = _ABSENT
    # the solution's residuals and reserves (build_solution)
    conventions: Mapping | None = _ABSENT
    max_moment_residual_Nm: float | None = _ABSENT
    max_moment_residual_by_dof_Nm: Mapping | None = _ABSENT
    max_hill_residual: float | None = _ABSENT
    max_activation_dynamics_residual: float | None = _ABSENT
    reserve_rms_Nm: Mapping | None = _ABSENT
    reserve_max_abs_Nm: Mapping | None = _ABSENT
    reserve_share_of_peak_moment: float | None = _ABSENT
    large_reserve: bool | None = _ABSENT
    peak_moment_by_dof_Nm: Mapping | None = _ABSENT
    #: the solver-level plausibility flags (:mod:`.plausibility`), each ``Flag.to_dict()``; ``[]``: none
    plausibility: tuple | None = entry(_flags)
    # the trial (solve_files)
    total_time_s: float | None = _ABSENT
    geometry_time_s: float | None = _ABSENT
    side: str | None = _ABSENT
    excluded_muscles: tuple | None = _ABSENT
    #: the diagnosis before the solve (:mod:`.diagnosis`): ``thresholds``, ``findings`` and, for a
    #: solve that did not converge, the constraints its last iterate left violated (``last_iterate``)
    diagnosis: Diagnosis | None = entry(_diagnosis)
    window: WindowRecord | None = entry(WindowRecord)
    inverse_dynamics: InverseDynamicsRecord | None = entry(InverseDynamicsRecord)
    assistance: AssistanceRecord | None = entry(AssistanceRecord)
    # the file (Solution.write)
    format: str | None = _ABSENT
    format_version: int | None = _ABSENT
    muscles: tuple | None = _ABSENT
    dofs: tuple | None = _ABSENT
    parameters: Mapping | None = _ABSENT
    extra: Mapping = field(default_factory=dict)
    keys: tuple = ()

    @property
    def workflow_name(self) -> str:
        return str(self.workflow.name or "") if self.workflow is not None else ""

    @property
    def gait_cycle(self) -> Mapping | None:
        """The gait cycle the window was taken from (``window.gait_cycle``), if recorded."""
        return self.window.gait_cycle if self.window is not None else None

    @property
    def flags(self) -> list:
        """The plausibility flags (:class:`~.plausibility.Flag`) the solve recorded (``[]``: none, or not checked)."""
        return list(self.plausibility or ())

    @property
    def pre_solve_diagnosis(self) -> "Diagnosis":
        """The diagnosis before the solve (:class:`~.diagnosis.Diagnosis`; empty when not recorded)."""
        from .diagnosis import Diagnosis

        return self.diagnosis if self.diagnosis is not None else Diagnosis()


@dataclass(frozen=True)
class ProblemRecord(_OutcomeRecord):
    """The ``solve`` section of ``parameters.json``: the record of one problem over one or more
    trials (EMG-TEN, an EMG-informed solve of several trials, ``musclemetab estimate``), typed
    like :class:`SolveRecord` (``Result.record``, ``EstimatedParameters.record``).

    The IPOPT outcome (:class:`RunRecord`), the problem (``problem_size``, ``trials``, the EMG
    mapping and deviations, ``settings``, solver and IPOPT options, the factors' ``bounds``), the
    estimate's ``doubts`` (factors on bounds, uninformed factors, identifiability) and the
    worst residuals over the trials. An entry the problem did not record is ``None``.
    """

    workflow: str | None = _ABSENT
    # the problem
    preparation_time_s: float | None = _ABSENT
    max_coupling_violation: float | None = _ABSENT
    problem_size: ProblemSize | None = entry(ProblemSize)
    #: ``[{"label", "time_window_s", "n_intervals", "inputs"}]``, one per trial
    trials: tuple | None = entry(records(TrialRecord))
    emg_mapping: Mapping | None = _ABSENT
    max_emg_deviation: Mapping | None = _ABSENT
    #: the :class:`~.emg_ten.EmgTenSettings` as a dictionary (EMG-TEN and EMG-informed problems)
    settings: Mapping | None = _ABSENT
    passive_source: str | None = _ABSENT
    solver_options: SolverOptionsRecord | None = entry(SolverOptionsRecord)
    ipopt_options: Mapping | None = _ABSENT
    initial_guess: str | None = _ABSENT
    #: ``{kind: [low, high]}`` of the estimated factors (parameter estimation)
    bounds: Mapping | None = _ABSENT
    #: what makes the estimates doubtful: factors on bounds, uninformed factors, identifiability
    doubts: Mapping | None = _ABSENT
    # the worst over the trials' solutions, and the files
    max_moment_residual_Nm: float | None = _ABSENT
    max_hill_residual: float | None = _ABSENT
    total_time_s: float | None = _ABSENT
    geometry_time_s: float | None = _ABSENT
    side: str | None = _ABSENT
    extra: Mapping = field(default_factory=dict)
    keys: tuple = ()
