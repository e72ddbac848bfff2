"""``musclemetab metabolics``: metabolic rates of every muscle of a solver solution.

    musclemetab metabolics --solution DIR --model M.osim --mass KG --height M
                           [--models all|UM10,BH04,...] [--basal body|muscle|none]
                           [--speed M_PER_S] --out DIR

Writes ``OUT/metabolics.sto``, ``OUT/metabolics.csv`` and ``OUT/whole_body.csv`` (see
:mod:`musclemetab.metabolics.solution`).
"""

from __future__ import annotations

import sys

import numpy as np

from ..errors import OptionError

__all__ = ["add_metabolics_parser", "metabolics_command"]


def add_metabolics_parser(subparsers) -> None:
    """Add the ``metabolics`` subcommand to an ``argparse`` subparsers object."""
    from .registry import MODELS

    p = subparsers.add_parser(
        "metabolics",
        help="metabolic rates of every muscle of a solution, for several energy models",
        description=(
            "Evaluate muscle metabolic energy models on a muscle redundancy solution (the padding nodes "
            "trimmed: 5 at the start, 6 at the end), muscle by muscle and node by node. Writes "
            "OUT/metabolics.sto (columns <model>/<muscle>/<component>, W), OUT/metabolics.csv (tidy: time, "
            "model, muscle, component, value_W) and OUT/whole_body.csv (one row per model: whole-body "
            f"average in W/kg). Models: {', '.join(MODELS)}."
        ),
    )
    p.add_argument("--solution", required=True, metavar="DIR", help="solution folder (solution.sto, summary.json)")
    p.add_argument(
        "--model", metavar="M.osim",
        help="OpenSim model the solution was computed with: F0, lMo and vmax are taken from it, by muscle "
        "name (default: the values recorded in the solution's summary.json)",
    )
    p.add_argument("--mass", required=True, type=float, metavar="KG", help="body mass (kg)")
    p.add_argument("--height", required=True, type=float, metavar="M", help="body height (m)")
    p.add_argument(
        "--models", default="all", metavar="LIST",
        help=f"'all' (default) or a comma-separated list of {', '.join(MODELS)}",
    )
    p.add_argument(
        "--basal", default="body", choices=("body", "muscle", "none"),
        help="whole-body basal heat: 1.2 W/kg of body mass (body, default, the paper), 1.2 W/kg of muscle "
        "mass in every muscle (muscle, the study's code) or none",
    )
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
    from .registry import parse_models
    from .solution import metabolics_from_solution, read_solution_states, write_metabolics

    from ..io import check_output_folder

    models = parse_models(args.models)
    check_output_folder(args.out)
    if args.speed is not None and not (np.isfinite(args.speed) and args.speed > 0):
        raise OptionError(f"--speed must be a positive number of m/s, not {args.speed}")
    states = read_solution_states(args.solution, require_success=not args.allow_failed)
    params = None
    if args.model:
        from ..model import read_muscle_parameters

        params = read_muscle_parameters(args.model)
        _note_parameter_differences(states, params, args.model)
    result = metabolics_from_solution(
        states,
        args.mass,
        args.height,
        models=models,
        muscle_parameters=params,
        basal=args.basal,
        speed_m_per_s=args.speed,
        muscle_properties=args.muscle_properties,
        strict=args.strict,
    )
    files = write_metabolics(result, args.out)
    means = ", ".join(f"{m} {result.whole_body[m].mean_W_per_kg:.2f}" for m in result.models)
    print(
        f"metabolics: {len(result.models)} models x {len(result.muscles)} muscles x {result.time_s.size} nodes "
        f"-> {args.out} ({', '.join(p.name for p in files.values())}); whole body (W/kg, basal {args.basal}): {means}"
    )
    return 0


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
