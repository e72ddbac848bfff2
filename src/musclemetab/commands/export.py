"""``musclemetab export``: a solution folder (and its metabolic rates) as a MATLAB ``.mat`` file.

    musclemetab export --mat OUT.mat FOLDER [--metabolics DIR]

``FOLDER`` is a solution folder (``solution.sto``, ``summary.json``; the demo's and a study's
unit folders, which hold the metabolic rates beside it) or the parent of ``r/`` and ``l/``
written by ``solve --side both``. The layout of the file is in ``docs/matlab.md``
(:mod:`musclemetab.io.matlab`).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["add_parser", "run", "folder_struct"]


def add_parser(subparsers) -> None:
    """Add the ``export`` subcommand to an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "export",
        help="a solution folder and its metabolic rates as a MATLAB .mat file",
        description=(
            "Write a solution folder as a MATLAB .mat file (scipy.io.savemat, version 5): time, muscle and DOF "
            "names, activations, excitations, forces, fiber lengths and velocities (time x muscles), the muscle "
            "parameters and the solve's outcome, and, where the folder (or --metabolics) holds them, the "
            "per-muscle rates of each energy model (time x muscles, per component) with the whole-body and "
            "per-muscle tables. Two legs (the parent of r/ and l/) are the fields r and l. Layout: docs/matlab.md."
        ),
    )
    p.add_argument("folder", metavar="FOLDER",
                   help="solution folder (solution.sto, summary.json), or the parent of r/ and l/ (solve --side both)")
    p.add_argument("--metabolics", metavar="DIR",
                   help="folder written by musclemetab metabolics for FOLDER (default: FOLDER itself, where a study "
                   "or the demo writes them)")
    p.add_argument("--mat", required=True, metavar="OUT.mat", help="the MATLAB file to write")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``musclemetab export`` (``args`` from :func:`add_parser`)."""
    from ..io.matlab import check_mat_path, write_mat

    check_mat_path(args.mat)
    struct = folder_struct(args.folder, args.metabolics)
    path = write_mat(args.mat, struct)
    legs = [s for s in ("r", "l") if s in struct] or ["one leg"]
    rates = [leg for leg in ([struct] if "time_s" in struct else [struct[s] for s in ("r", "l") if s in struct])
             if "metabolics" in leg]
    print(f"export: {args.folder} ({', '.join(legs)}; {'with' if rates else 'without'} metabolic rates) -> {path}")
    return 0


def folder_struct(solution_folder, metabolics_folder=None) -> dict:
    """:func:`legs_struct` of a solution folder (``solution.sto``, ``summary.json``) or of the
    parent of ``r/`` and ``l/`` written by ``solve --side both``, with, when the folder (or
    ``metabolics_folder``) holds them, the metabolic rates ``metabolics`` wrote
    (``metabolics.sto``, ``whole_body.csv`` or ``leg_muscles.csv``, ``per_muscle.csv``; the
    legs' ``whole_body.csv`` of the parent), read from those files."""
    import pandas as pd

    from ..metabolics.solution import WHOLE_BODY_CSV, check_metabolics_of, solution_folders
    from ..io.matlab import legs_struct, solution_struct
    from ..metabolics.matlab import folder_metabolics
    from ..redundancy.solution import Solution

    folders = solution_folders(solution_folder)
    root = Path(metabolics_folder if metabolics_folder is not None else solution_folder)
    legs = {}
    for side, folder in folders.items():
        legs[side] = solution_struct(Solution.load(folder, require_success=False))
        where = Path(folder) if metabolics_folder is None else (root / side if len(folders) > 1 else root)
        metabolics = folder_metabolics(where)
        if metabolics is None and metabolics_folder is not None:  # given, so asked for: not left out unsaid
            from ..errors import InputFileError
            from ..metabolics.solution import METABOLICS_STO

            raise InputFileError(f"{where}: no {METABOLICS_STO} (--metabolics); give the folder written by "
                                 f"'musclemetab metabolics --solution {folder}'")
        if metabolics is not None and metabolics_folder is not None:  # a study unit's folder holds both
            check_metabolics_of(folder, where)
        if metabolics is not None:
            legs[side]["metabolics"] = metabolics
    whole = root / WHOLE_BODY_CSV
    return legs_struct(legs, pd.read_csv(whole) if len(folders) > 1 and whole.is_file() else None)
