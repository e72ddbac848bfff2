"""The record of one solve: status, IPOPT statistics, timings, software versions, input hashes.

One :class:`RunRecord` describes every solve (one trial or several in one problem). The solver
writes it into ``summary.json``/``parameters.json`` (:meth:`RunRecord.to_dict`), a
:class:`~.solution.Solution` and the EMG-TEN result give it back (``.run_record``), and the study
runner turns a failed one into the one-line reason of ``failures.csv``
(:meth:`RunRecord.failure`).
"""

from __future__ import annotations

import math
import os
import platform
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["RunRecord", "solver_versions", "input_hashes"]

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
            "objective": self.objective, "objective_terms": self.objective_terms, "iterations": self.iterations,
            "solve_time_s": self.solve_time_s, "solve_cpu_time_s": self.solve_cpu_time_s,
            "build_time_s": self.build_time_s, "function_evaluation_time_s": self.function_evaluation_time_s,
            "ms_per_iteration": 1e3 * self.solve_time_s / max(self.iterations, 1),
            "max_constraint_violation": self.max_constraint_violation,
            "software": dict(self.software), "input_hashes": dict(self.input_hashes),
        }

    def failure(self, what: str):
        """The :class:`~musclemetab.errors.SolverError` of a solve that did not succeed."""
        from ..errors import SolverError

        return SolverError(f"{what} did not converge: IPOPT status {self.status} after {self.iterations} "
                           f"iterations ({self.message})")
