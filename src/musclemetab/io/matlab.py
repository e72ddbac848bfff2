"""MATLAB ``.mat`` files of a solve and its metabolic rates (:func:`scipy.io.savemat`).

For users of MATLAB code (the MuscleRedundancySolver, the study's own scripts): one struct per
leg with the time, the muscle and DOF names, the solution's arrays (time in rows, one column per
muscle), the muscle parameters, the solve's outcome and, when evaluated, the metabolic rates of
each energy model (time x muscles, per component) with the whole-body and per-muscle tables as
structs of columns. The layout is documented in ``docs/matlab.md``; names and units are those of
the package's files (``solution.sto``, ``metabolics.sto``, ``whole_body.csv``,
``per_muscle.csv``), so that a script written against one reads the other.

The same struct comes from objects (:meth:`~musclemetab.redundancy.solution.Solution.to_mat`,
:meth:`~musclemetab.redundancy.result.Result.to_mat`,
:meth:`~musclemetab.metabolics.solution.SolutionMetabolics.to_mat`, ``metabolics --mat``) and
from folders the package wrote (:func:`musclemetab.commands.export.folder_struct`, ``musclemetab export --mat``);
the structs of metabolic rates are built in :mod:`musclemetab.metabolics.matlab`.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

__all__ = ["MAT_FORMAT", "solution_struct", "metabolics_struct", "table_struct",
           "legs_struct", "field_name", "names_cell", "number_column", "check_mat_path",
           "write_mat"]

#: the value of every file's ``format`` field (the layout's version follows it)
MAT_FORMAT = "musclemetab mat 1"

#: solution struct field -> the Solution's attribute (arrays, time in rows)
_SOLUTION_ARRAYS = {
    "excitation": "excitation",
    "activation": "activation",
    "normalized_fiber_length": "lm_norm",
    "fiber_length_m": "fiber_length_m",
    "normalized_fiber_velocity": "normalized_fiber_velocity",
    "fiber_velocity_m_per_s": "fiber_velocity_m_per_s",
    "tendon_force_N": "tendon_force_N",
    "active_fiber_force_N": "active_fiber_force_N",
    "passive_fiber_force_N": "passive_fiber_force_N",
    "active_force_length_multiplier": "active_force_length_multiplier",
    "force_velocity_multiplier": "force_velocity_multiplier",
    "reserve_Nm": "reserve_Nm",
}


def field_name(text: str) -> str:
    """``text`` as a MATLAB field name: letters, digits and underscores, starting with a letter
    (a trial label ``IK_sub1-normal`` becomes ``IK_sub1_normal``, ``1a`` becomes ``x1a``)."""
    name = re.sub(r"\W", "_", str(text))
    return name if re.match(r"[A-Za-z]", name) else f"x{name}"


def names_cell(names) -> np.ndarray:
    """Names as a column cell array of MATLAB (an object array of str)."""
    out = np.empty((len(names), 1), dtype=object)
    for i, n in enumerate(names):
        out[i, 0] = str(n)
    return out


def number_column(values) -> np.ndarray:
    """Numbers as a column vector (n x 1 double)."""
    return np.asarray(values, dtype=float).reshape(-1, 1)


def _plain(value):
    """A record's value as savemat takes it (``None``: an empty matrix)."""
    if value is None:
        return np.zeros((0, 0))
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    return value


def solution_struct(solution) -> dict:
    """The struct of one :class:`~musclemetab.redundancy.solution.Solution`: ``time_s``
    (N x 1), ``muscles`` and ``dofs`` (cells), the arrays (N x muscles; ``reserve_Nm`` N x DOFs),
    ``parameters`` (one M x 1 column per parameter, SI) and ``solve`` (workflow, side, status,
    success, objective, iterations, stop, window)."""
    p = solution.parameters
    rec = solution.record
    out = {"time_s": number_column(solution.time_s), "muscles": names_cell(solution.muscles), "dofs": names_cell(solution.dofs)}
    for key, attr in _SOLUTION_ARRAYS.items():
        out[key] = np.asarray(getattr(solution, attr), dtype=float)
    index = [p.names.index(m) for m in solution.muscles]
    out["parameters"] = {
        "max_isometric_force_N": number_column(p.max_isometric_force_N[index]),
        "optimal_fiber_length_m": number_column(p.optimal_fiber_length_m[index]),
        "tendon_slack_length_m": number_column(p.tendon_slack_length_m[index]),
        "pennation_angle_at_optimal_rad": number_column(p.pennation_angle_at_optimal_rad[index]),
        "max_contraction_velocity_lMo_per_s": number_column(p.max_contraction_velocity[index]),
        "tendon_stiffness": number_column(p.tendon_stiffness[index]),
        "passive_kpe": number_column(p.passive_kpe[index]),
        "passive_s0": number_column(p.passive_s0[index]),
        "passive_sm": number_column(p.passive_sm[index]),
    }
    conv = rec.convergence or {}  # a read-only mapping of its entries
    out["solve"] = {
        "workflow": rec.workflow_name, "side": rec.side or "", "status": str(rec.status),
        "success": bool(rec.success), "objective": _plain(rec.objective), "iterations": _plain(rec.iterations),
        "stop": str(conv.get("stop", "")), "max_rate_residue": _plain(conv.get("max_rate_residue")),
        "time_window_s": _plain(None if rec.time_window_s is None else np.asarray(rec.time_window_s, dtype=float)),
        "plausibility": names_cell([f.code for f in rec.flags]),
    }
    return out


def table_struct(table) -> dict:
    """A table (pandas DataFrame) as a struct of columns: numbers as n x 1 doubles (empty cells
    NaN), text as n x 1 cells."""
    import pandas as pd

    out = {}
    for c in table.columns:
        col = table[c]
        if pd.api.types.is_bool_dtype(col) or not pd.api.types.is_numeric_dtype(col):
            out[field_name(c)] = names_cell(col.fillna("").astype(str).tolist())
        else:
            out[field_name(c)] = number_column(col.to_numpy(dtype=float))
    return out


def metabolics_struct(time_s, columns: dict, tables: dict | None = None) -> dict:
    """The struct of one leg's metabolic rates from the columns of ``metabolics.sto``
    (``{"<model>/<muscle>/<component>": array}``, W): ``time_s`` (K x 1), ``muscles``,
    ``models`` and ``components`` (cells), one struct per model with one K x muscles array per
    component, and ``tables`` (``{"whole_body" or "leg_muscles", "per_muscle": DataFrame}``) as
    structs of columns (:func:`table_struct`)."""
    models, muscles, components = {}, {}, {}
    for key in columns:  # dictionaries as ordered sets: the file's order
        model, muscle, component = key.split("/")
        models.setdefault(model)
        muscles.setdefault(muscle)
        components.setdefault(component)
    out = {"time_s": number_column(time_s), "muscles": names_cell(muscles), "models": names_cell(models),
           "components": names_cell(components)}
    for model in models:
        out[field_name(model)] = {
            field_name(c): np.column_stack([np.asarray(columns[f"{model}/{m}/{c}"], dtype=float) for m in muscles])
            for c in components if f"{model}/{next(iter(muscles))}/{c}" in columns}
    for name, table in (tables or {}).items():
        if table is not None:
            out[name] = table_struct(table)
    return out


def legs_struct(legs: dict, whole_body=None) -> dict:
    """The file's struct of the legs' structs ``{side: struct}``: one leg's fields at the top;
    two legs (``solve --side both``) as fields ``r`` and ``l``, ``legs`` naming them, and
    ``whole_body`` the table of the legs added (:func:`~musclemetab.metabolics.solution.legs_table`)."""
    if len(legs) == 1:
        return {"format": MAT_FORMAT, **next(iter(legs.values()))}
    out = {"format": MAT_FORMAT, "legs": names_cell(legs), **{field_name(side): leg for side, leg in legs.items()}}
    if whole_body is not None:
        out["whole_body"] = table_struct(whole_body)
    return out


def check_mat_path(path: str | os.PathLike, option: str = "--mat") -> Path:
    """Check, before any work, that ``path`` can take a ``.mat`` file of the package: it ends in
    ``.mat``, its folder can be written, and no folder or file of the user's is there
    (:func:`~musclemetab.io.atomic.check_replaceable`); :class:`~musclemetab.errors.OptionError`
    naming ``option`` otherwise."""
    from ..errors import OptionError
    from .atomic import check_output_folder, check_replaceable

    path = Path(path)
    if path.suffix.lower() != ".mat":
        raise OptionError(f"{option} {path}: a MATLAB file's name ends in .mat; give e.g. {path.with_suffix('.mat')}")
    check_output_folder(path.parent, option=option)
    check_replaceable(path.parent, [path.name], elsewhere=f"give another file name ({option})")
    return path


def write_mat(path: str | os.PathLike, struct: dict) -> Path:
    """Write ``struct`` (:func:`legs_struct` and the like: one MATLAB variable per field) to the
    MATLAB file ``path`` (version 5, compressed), atomically, listed as the package's file in its
    folder (:func:`check_mat_path` first); ``format`` is :data:`MAT_FORMAT`."""
    from scipy.io import savemat

    from ..errors import OutputError
    from .atomic import atomic_path

    path = check_mat_path(path, option="path")
    try:
        with atomic_path(path, suffix=".mat", mark=True) as tmp:
            savemat(tmp, {"format": MAT_FORMAT, **struct}, do_compression=True, oned_as="column",
                    long_field_names=True)
    except OSError as exc:
        raise OutputError(f"cannot write {path} ({exc.strerror or exc}); choose a folder you can write to") from None
    return path
