"""MATLAB files of metabolic rates and of solutions with their rates (``.mat``, written with
:func:`musclemetab.io.matlab.write_mat`; layout in docs/matlab.md): the structs of a
:class:`~.solution.SolutionMetabolics`, of the files ``musclemetab metabolics`` wrote, and of the
legs of a solve with their rates. The generic pieces (names, tables, a solution's struct) are in
:mod:`musclemetab.io.matlab`."""

from __future__ import annotations

from pathlib import Path

from ..io.matlab import legs_struct, metabolics_struct, solution_struct

__all__ = ["metabolics_struct_of", "folder_metabolics", "results_struct"]


def metabolics_struct_of(result, cycle=None) -> dict:
    """:func:`metabolics_struct` of a :class:`~musclemetab.metabolics.solution.SolutionMetabolics`
    (:meth:`~musclemetab.metabolics.solution.SolutionMetabolics.mat_struct`: its columns and tables
    as :func:`~musclemetab.metabolics.solution.write_metabolics` writes them)."""
    return result.mat_struct(cycle)


def folder_metabolics(folder: Path) -> dict | None:
    """:func:`metabolics_struct` of the files ``metabolics`` wrote into ``folder`` (``None``: none)."""
    import pandas as pd

    from .per_muscle import PER_MUSCLE_FILE
    from .solution import LEG_CSV, METABOLICS_STO, WHOLE_BODY_CSV
    from ..io.storage import read_table

    if not (folder / METABOLICS_STO).is_file():
        return None
    table = read_table(folder / METABOLICS_STO)
    files = {"whole_body": WHOLE_BODY_CSV, "leg_muscles": LEG_CSV, "per_muscle": PER_MUSCLE_FILE}
    tables = {name: pd.read_csv(folder / file) for name, file in files.items() if (folder / file).is_file()}
    return metabolics_struct(table.index, {c: table[c] for c in table.columns}, tables)


def results_struct(solutions: dict | None, metabolics: dict | None = None) -> dict:
    """:func:`legs_struct` of ``{side: Solution}`` and, optionally, their metabolic rates
    ``{side: SolutionMetabolics}`` (what :func:`~musclemetab.metabolics.solution.metabolics_from_legs`
    returns); without solutions (the rates of an OpenSim motion), each leg's struct holds its
    ``metabolics`` alone."""
    from .solution import legs_table

    legs = {side: solution_struct(solution) for side, solution in (solutions or {}).items()}
    for side, result in (metabolics or {}).items():
        legs.setdefault(side, {})["metabolics"] = metabolics_struct_of(result)
    return legs_struct(legs, legs_table(metabolics) if metabolics is not None and len(metabolics) > 1 else None)
