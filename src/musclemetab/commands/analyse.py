"""``musclemetab analyse``: phases, groups, per-muscle and whole-body results of a solved trial.

    musclemetab analyse --solution DIR --model M.osim --ik IK.mot (--id ID.sto | --grf GRF.mot | --cycle S,TO,E)
                        [--metabolics DIR] [--mass KG --height M] [--models all]
                        [--basal body|muscle|none] [--basal-coefficient 1.2] [--basal-exponent 1]
                        [--speed M_PER_S] --out DIR

The command-line path ``solve`` -> ``metabolics`` -> ``analyse`` gives what a study unit
gives: in ``OUT`` the whole-body table (``whole_body.csv``, with gross and net cost of
transport), the stance/swing and muscle-group analysis (``analysis.csv``), the leg and
group rates over the cycle (``timeseries.csv``), the per-muscle table (``per_muscle.csv``),
and the key of the group abbreviations (``muscle_groups.csv``):
:func:`musclemetab.analysis.analyse` and :func:`musclemetab.analysis.write_analysis`.

``--solution`` may also be the parent of one folder per side (``DIR/r`` and ``DIR/l``, each
a solution folder): each side is analysed into ``OUT/r`` and ``OUT/l`` and the per-muscle
tables of both sides are gathered in ``OUT/per_muscle.csv``.

Body mass, height, models and the basal settings default to those recorded in ``--metabolics``'s
``metabolics.sto`` (written by ``musclemetab metabolics``); the rates are evaluated again
from the solution (they take milliseconds) with those settings.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InputFileError, OptionError
from .options import BASAL_DEFAULTS, add_basal_arguments, check_basal_arguments, check_body, check_speed

__all__ = ["add_parser", "run", "SIDES"]

SIDES = ("r", "l")


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "analyse",
        help="stance/swing, muscle groups, per-muscle and whole-body results of a solved trial",
        description=(
            "Analyse a solution folder (and the metabolics folder written from it): whole-body rate (W/kg) and "
            "gross and net cost of transport, stance and swing energy shares, muscle-group shares and rates over "
            "the gait cycle, and one row per muscle and model (mean W, W/kg, J per cycle, share of the leg, stance "
            "and swing J, components, basal heat apart). Writes OUT/whole_body.csv, analysis.csv, timeseries.csv, "
            "per_muscle.csv, muscle_groups.csv. DIR may hold one solution folder per side (DIR/r, DIR/l): "
            "OUT/r and OUT/l are written and OUT/per_muscle.csv gathers both sides. Every column is described in "
            "docs/data_dictionary.md."
        ),
    )
    p.add_argument("--solution", required=True, metavar="DIR",
                   help="solution folder (solution.sto, summary.json), or the parent of DIR/r and DIR/l")
    p.add_argument("--metabolics", metavar="DIR",
                   help="folder written by 'musclemetab metabolics' (its metabolics.sto gives the body mass, height "
                   "and models when they are not given)")
    p.add_argument("--model", required=True, metavar="M.osim", help="OpenSim model the solution was solved with")
    p.add_argument("--ik", required=True, metavar="IK.mot", help="inverse kinematics of the trial (moment arms, speed)")
    cyc = p.add_mutually_exclusive_group(required=True)
    cyc.add_argument("--id", metavar="ID.sto", help="inverse dynamics: toe-off from the ankle moment, the cycle "
                     "from the IK window less 0.05 s at each end (estimated events)")
    cyc.add_argument("--grf", metavar="GRF.mot", help="ground reaction forces: events from the vertical force")
    cyc.add_argument("--cycle", metavar="START,TOE_OFF,END", help="the gait events (s)")
    p.add_argument("--mass", type=float, metavar="KG", help="body mass (kg)")
    p.add_argument("--height", type=float, metavar="M", help="body height (m)")
    p.add_argument("--models", metavar="LIST", help="'all' or a comma-separated list (default: those of --metabolics, "
                   "else all)")
    add_basal_arguments(p, recorded="--metabolics")
    p.add_argument("--speed", type=float, metavar="M_PER_S",
                   help="walking speed (default: estimated from the pelvis displacement over the cycle)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.set_defaults(func=run)


def _cycle(args, side: str):
    from ..analysis.events import GaitCycle, cycle_of_trial

    if args.cycle:
        try:
            vals = [float(v) for v in args.cycle.split(",")]
        except ValueError:
            vals = []
        if len(vals) != 3:
            raise OptionError(f"--cycle must be three times in seconds, START,TOE_OFF,END, not '{args.cycle}'")
        return GaitCycle(*vals), "given on the command line"
    return cycle_of_trial(args.ik, grf=args.grf, id_file=args.id, side=side, model=args.model)


def run(args) -> int:
    """Run ``musclemetab analyse`` (``args`` from :func:`add_parser`)."""
    import pandas as pd

    from ..metabolics.per_muscle import PER_MUSCLE_FILE
    from ..analysis.unit import analyse, write_analysis
    from ..io import atomic_path
    from ..metabolics.solution import read_metabolics_settings
    from ..redundancy.solution import SOLUTION_FILE

    root = Path(args.solution)
    if (root / SOLUTION_FILE).is_file():
        jobs = [(None, root, Path(args.out))]
    else:
        jobs = [(s, root / s, Path(args.out) / s) for s in SIDES if (root / s / SOLUTION_FILE).is_file()]
        if not jobs:
            raise InputFileError(f"{root}: no {SOLUTION_FILE} in it, nor in {root / 'r'} or {root / 'l'}; "
                                 "give a solution folder written by 'musclemetab solve'")
    recorded = read_metabolics_settings(args.metabolics) if args.metabolics else {}
    try:
        mass = args.mass if args.mass is not None else recorded["body_mass_kg"]
        height = args.height if args.height is not None else recorded.get("height_m")
    except KeyError:
        raise OptionError("give --mass (and --height, or none for muscle masses from the model), or --metabolics, "
                          "the folder written by 'musclemetab metabolics', which records them") from None
    models = args.models or recorded.get("models") or "all"
    for key, rec in (("basal", "basal_rule"), ("basal_coefficient", "basal_coefficient"),
                     ("basal_exponent", "basal_exponent")):
        if getattr(args, key) is None:
            setattr(args, key, recorded.get(rec, BASAL_DEFAULTS[key]))
    check_basal_arguments(args)
    check_speed(args.speed)
    check_body(mass, height)
    tables = []
    for side, sol_dir, out in jobs:
        cycle, source = _cycle(args, side or "r")
        speed = args.speed
        speed_note = "given"
        if speed is None:
            from ..analysis.speed import walking_speed_from_ik

            speed = walking_speed_from_ik(args.ik, start_s=cycle.start_s, end_s=cycle.end_s)
            speed_note = "estimated from the pelvis displacement"
        result = analyse(sol_dir, args.model, args.ik, cycle, mass, height, models=models, side=side,
                         basal=args.basal, basal_rate_W_per_kg=args.basal_coefficient,
                         basal_exponent=args.basal_exponent, speed_m_per_s=speed)
        write_analysis(result, out)
        per = result.per_muscle
        tables.append(per)
        label = f"side {side}: " if side else ""
        print(f"analyse: {label}cycle {cycle.start_s:.3f}-{cycle.end_s:.3f} s, toe-off {cycle.toe_off_pct:.1f} % "
              f"({source}); speed {speed:.2f} m/s ({speed_note}) -> {out}")
        merged = result.whole_body.merge(result.summary, on="model")
        for row in merged.itertuples():
            top = per[per.model == row.model].nsmallest(3, "rank")["muscle"].tolist()
            print(f"  {row.model}: {row.whole_body_W_per_kg:.2f} W/kg, gross CoT {row.gross_cost_of_transport_J_per_kg_per_m:.2f} "
                  f"J/(kg m), swing {row.swing_energy_share_pct:.1f} % of the leg's energy, "
                  f"PF {row.share_PF_pct:.1f} %; largest: {', '.join(top)}")
    if jobs[0][0] is not None:  # the sides' parent: one table of every side
        with atomic_path(Path(args.out) / PER_MUSCLE_FILE) as tmp:
            pd.concat(tables, ignore_index=True).to_csv(tmp, index=False, float_format="%.10g")
    return 0
