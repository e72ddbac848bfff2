"""``musclemetab metabolics``: metabolic rates of every muscle of a solver solution.

    musclemetab metabolics --solution DIR|PARENT --model M.osim --mass KG --height M
                           [--models all|UM10,BH04,...|all,LW05,MA68] [--basal body|muscle|none]
                           [--basal-coefficient 1.2] [--basal-exponent 1]
                           [--speed M_PER_S] --out DIR

Writes ``OUT/metabolics.sto``, ``OUT/metabolics.parquet``, ``OUT/whole_body.csv`` and
``OUT/per_muscle.csv`` (see
:mod:`musclemetab.metabolics.solution`). One leg solved: the whole-body rate doubles it (the
study's rule, and the output says so). ``--solution`` may also be the parent written by
``solve --side both`` (``PARENT/r``, ``PARENT/l``): each leg is evaluated over its own cycle
into ``OUT/r`` and ``OUT/l``, and ``OUT/whole_body.csv`` adds the two legs (basal heat once).
"""

from __future__ import annotations

import sys

import numpy as np

from ..errors import OptionError

__all__ = ["add_metabolics_parser", "metabolics_command", "add_basal_arguments", "check_basal_arguments"]


def add_basal_arguments(parser, recorded: str | None = None) -> None:
    """The whole-body basal heat options, ``--basal``, ``--basal-coefficient`` and
    ``--basal-exponent``, of the commands that compute whole-body rates (``metabolics``,
    ``analyse``); :func:`check_basal_arguments` checks their values. With ``recorded`` (where
    the command finds earlier settings, e.g. ``"--metabolics"``) the options default to
    ``None``: the command takes the recorded values, else :data:`BASAL_DEFAULTS`."""
    default = (lambda key: None) if recorded else BASAL_DEFAULTS.get
    also = f" (default: as recorded in {recorded}, else %s)" if recorded else " (default %s)"
    parser.add_argument(
        "--basal", default=default("basal"), choices=("body", "muscle", "none"),
        help="whole-body basal heat: 1.2 W/kg of body mass (body, the paper), 1.2 W/kg of muscle mass in every "
        "muscle (muscle, the study's code) or none" + also % "body",
    )
    parser.add_argument(
        "--basal-coefficient", type=float, default=default("basal_coefficient"), metavar="W_PER_KG",
        help="basal heat coefficient as OpenSim's probes write it (basal_coefficient): under --basal body the "
        "basal heat is COEFFICIENT * mass^EXPONENT W; it is also the per-muscle basal heat, W per kg of muscle "
        "mass" + also % "1.2",
    )
    parser.add_argument(
        "--basal-exponent", type=float, default=default("basal_exponent"), metavar="X",
        help="basal heat exponent of the body mass (OpenSim's basal_exponent; --basal body only)" + also % "1",
    )


#: the basal options' defaults: the paper's 1.2 W per kg of body mass
BASAL_DEFAULTS = {"basal": "body", "basal_coefficient": 1.2, "basal_exponent": 1.0}


def check_basal_arguments(args) -> None:
    """Raise :class:`OptionError` naming the option for a basal coefficient that is not a
    non-negative number, an exponent that is not finite, or an exponent with ``--basal muscle``."""
    if not (np.isfinite(args.basal_coefficient) and args.basal_coefficient >= 0):
        raise OptionError(f"--basal-coefficient must be a non-negative number of W/kg, not {args.basal_coefficient}")
    if not np.isfinite(args.basal_exponent):
        raise OptionError(f"--basal-exponent must be a finite number, not {args.basal_exponent}")
    if args.basal == "muscle" and args.basal_exponent != 1:
        raise OptionError("--basal-exponent applies to --basal body only (the muscle rule is linear in each "
                          "muscle's mass); drop it or use --basal body")


def add_metabolics_parser(subparsers) -> None:
    """Add the ``metabolics`` subcommand to an ``argparse`` subparsers object."""
    from .registry import ADDITIONAL_MODELS, MODELS

    p = subparsers.add_parser(
        "metabolics",
        help="metabolic rates of every muscle of a solution, for several energy models",
        description=(
            "Evaluate muscle metabolic energy models on a muscle redundancy solution (the padding nodes "
            "trimmed: 5 at the start, 6 at the end), muscle by muscle and node by node. Writes "
            "OUT/metabolics.sto (columns <model>/<muscle>/<component>, W), OUT/metabolics.parquet (tidy: time, "
            "model, muscle, component, value_W) and OUT/whole_body.csv (one row per model: whole-body "
            f"average in W/kg). Models: the study's {', '.join(MODELS)} ('all', the default) and, when "
            f"named, {', '.join(ADDITIONAL_MODELS)}."
        ),
    )
    p.add_argument("--solution", required=True, metavar="DIR",
                   help="solution folder (solution.sto, summary.json), or the parent of r/ and l/ written by "
                   "solve --side both (the legs are then added instead of doubling one)")
    p.add_argument(
        "--model", metavar="M.osim",
        help="OpenSim model the solution was computed with: F0, lMo and vmax are taken from it, by muscle "
        "name (default: the values recorded in the solution's summary.json)",
    )
    p.add_argument("--mass", required=True, type=float, metavar="KG", help="body mass (kg)")
    p.add_argument("--height", required=True, type=float, metavar="M", help="body height (m)")
    p.add_argument(
        "--models", default="all", metavar="LIST",
        help=f"'all' (default: the study's {', '.join(MODELS)}) or a comma-separated list of these and "
        f"{', '.join(ADDITIONAL_MODELS)}, e.g. all,LW05,MA68",
    )
    add_basal_arguments(p)
    p.add_argument("--speed", type=float, metavar="M_PER_S", help="walking speed, for the cost of transport")
    p.add_argument(
        "--allow-failed", action="store_true",
        help="evaluate a solution whose solve did not succeed (default: refuse)",
    )
    p.add_argument(
        "--muscle-properties", metavar="FILE",
        help="CSV of per-muscle overrides (columns muscle and any of anatomical_muscles, mass_kg, "
        "slow_twitch_fraction, specific_tension_Pa, function_groups; docs/muscles.md)",
    )
    p.add_argument(
        "--strict", action="store_true",
        help="refuse muscles the anatomical muscle table cannot place (default: fallback mass and "
        "slow-twitch fraction 0.5, with a warning naming them)",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (may be the solution folder)")
    p.set_defaults(func=metabolics_command)


def metabolics_command(args) -> int:
    """Run the ``metabolics`` subcommand (``args`` from :func:`add_metabolics_parser`)."""
    import warnings

    from ..errors import MuscleTableWarning
    from ..properties import unplaced_muscles, warn_unplaced
    from .registry import parse_models
    from .solution import metabolics_from_solution, read_solution_states, write_metabolics

    from ..io import check_output_folder

    models = parse_models(args.models)
    check_output_folder(args.out)
    if args.speed is not None and not (np.isfinite(args.speed) and args.speed > 0):
        raise OptionError(f"--speed must be a positive number of m/s, not {args.speed}")
    check_basal_arguments(args)
    from pathlib import Path

    folders = _solution_folders(Path(args.solution))
    params = None
    if args.model:
        from ..model import read_muscle_parameters

        params = read_muscle_parameters(args.model)
    legs = 1 if len(folders) > 1 else 2
    results = {}
    with warnings.catch_warnings():  # one warning for both legs, below
        warnings.simplefilter("ignore", MuscleTableWarning)
        for side, folder in folders.items():
            states = read_solution_states(folder, require_success=not args.allow_failed)
            if params is not None:
                _note_parameter_differences(states, params, args.model)
            results[side] = metabolics_from_solution(
                states, args.mass, args.height, models=models, muscle_parameters=params, basal=args.basal,
                basal_rate_W_per_kg=args.basal_coefficient, basal_exponent=args.basal_exponent,
                speed_m_per_s=args.speed, legs=legs, muscle_properties=args.muscle_properties, strict=args.strict,
            )
    warn_unplaced(list(dict.fromkeys(
        m for r in results.values() for m in unplaced_muscles(r.muscles, args.muscle_properties))))
    if legs == 2:
        (side, result), = results.items()
        files = write_metabolics(result, args.out)
        means = ", ".join(f"{m} {result.whole_body[m].mean_W_per_kg:.2f}" for m in result.models)
        leg = {"r": "the right leg", "l": "the left leg"}.get(side, "the solved leg")
        print(
            f"metabolics: {len(result.models)} models x {len(result.muscles)} muscles x {result.time_s.size} nodes "
            f"-> {args.out} ({', '.join(p.name for p in files.values())}); whole body = 2 x {leg} "
            f"(W/kg, basal {args.basal}): {means}"
        )
        return 0
    from ..io import atomic_write_text
    from .solution import add_legs

    total = add_legs(results)
    out = Path(args.out)
    for side, result in results.items():
        write_metabolics(result, out / side)
    rows = ["model,legs,mean_W_per_kg," + ",".join(f"{s}_leg_mean_W" for s in results)]
    for m, v in total.items():
        rows.append(f"{m},{'+'.join(results)},{v:.10g}," + ",".join(
            f"{r.whole_body[m].one_leg_mean_W:.10g}" for r in results.values()))
    atomic_write_text(out / "whole_body.csv", "\n".join(rows) + "\n")
    means = ", ".join(f"{m} {v:.2f}" for m, v in total.items())
    print(f"metabolics: legs {' + '.join(results)} added (each over its own cycle) -> {out}/whole_body.csv and "
          f"{', '.join(f'{out}/{s}' for s in results)}; whole body (W/kg, basal {args.basal}): {means}")
    return 0


def _solution_folders(path) -> dict:
    """``{side: folder}``: the folder itself if it is a solution, else its ``r``/``l`` solution sub-folders."""
    from ..errors import InputFileError
    from ..redundancy.solution import SUMMARY_FILE

    if (path / SUMMARY_FILE).is_file():
        from ..io import read_json_object

        side = read_json_object(path / SUMMARY_FILE).get("side")
        return {side if side in ("r", "l") else "": path}
    found = {s: path / s for s in ("r", "l") if (path / s / SUMMARY_FILE).is_file()}
    if not found:
        raise InputFileError(
            f"{path}: neither a solution folder (summary.json) nor a folder of per-leg solutions (r/, l/); "
            "give the folder written by musclemetab solve"
        )
    return found


def _note_parameter_differences(states, params, model_path) -> None:
    """Say (on stderr) when the model's parameters differ from those the solve recorded."""
    if not states.parameters:
        return
    pos = {n: i for i, n in enumerate(params.names)}
    differ = []
    for m, rec in states.parameters.items():
        if m not in pos:
            continue
        for k, v in rec.items():
            ref = float(np.asarray(getattr(params, k))[pos[m]])
            if not np.isclose(v, ref, rtol=1e-6, atol=0.0):
                differ.append(f"{m} {k} {v:g} (solution) vs {ref:g} (model)")
    if differ:
        print(
            f"musclemetab: note: {model_path} differs from the solution's recorded parameters "
            f"({'; '.join(differ[:3])}{' ...' if len(differ) > 3 else ''}); using the model's values",
            file=sys.stderr,
        )
