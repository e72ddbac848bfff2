"""The two files of a solution folder (``solution.sto``, ``summary.json``), read and checked.

The solver writes them (:meth:`musclemetab.redundancy.Solution.write`); the solver's
:class:`~musclemetab.redundancy.Solution` and the metabolics stage both read them through
:func:`read_solution_folder` (``docs/solver.md``, "Output").
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import InputFileError, SolverError
from .jsonfile import read_json_object
from .storage import read_storage

__all__ = ["SOLUTION_FILE", "SUMMARY_FILE", "read_solution_folder"]

SOLUTION_FILE = "solution.sto"
SUMMARY_FILE = "summary.json"


def read_solution_folder(
    directory: str | os.PathLike, *, require_success: bool = True, required_keys=("muscles",)
):
    """Read ``solution.sto`` and ``summary.json`` of a solution folder, checked.

    Returns ``(table, summary)``. Raises :class:`InputFileError` when a file is missing, the
    summary is not JSON or lacks one of ``required_keys``; :class:`SolverError` when the
    stored solve did not succeed (unless ``require_success=False``).
    """
    directory = Path(directory)
    spath, jpath = directory / SOLUTION_FILE, directory / SUMMARY_FILE
    for p in (spath, jpath):
        if not p.is_file():
            raise InputFileError(f"{p}: missing; {directory} is not a solution folder (run 'musclemetab solve')")
    summary = read_json_object(jpath, remedy="solve again")
    for key in required_keys:
        if not summary.get(key):
            raise InputFileError(f"{jpath}: no '{key}' entry; the summary is incomplete, solve again")
    if require_success and not summary.get("success", False):
        raise SolverError(
            f"{directory}: the stored solve did not succeed (status '{summary.get('status')}'); "
            "its values are not a solution. Solve again, or to inspect it anyway use --allow-failed "
            "(musclemetab metabolics) or require_success=False (Python)"
        )
    return read_storage(spath), summary
