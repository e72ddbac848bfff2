"""``musclemetab analyse``: phases, groups, per-muscle and whole-body results of a solved trial.

    musclemetab analyse --solution DIR --model M.osim --ik IK.mot (--id ID.sto | --grf GRF.mot | --cycle S,TO,E)
                        [--metabolics DIR] [--mass KG --height M] [--models all]
                        [--basal body|muscle|none] [--basal-coefficient 1.2] [--basal-exponent 1]
                        [--speed M_PER_S] --out DIR

The command-line path ``solve`` -> ``metabolics`` -> ``analyse`` gives what a study unit
gives: in ``OUT`` the whole-body table (``whole_body.csv``, with gross and net cost of
transport), the stance/swing and muscle-group analysis (``analysis.csv``), the leg and
group rates over the cycle (``timeseries.csv``), the per-muscle table (``per_muscle.csv``),
and the key of the group abbreviations (``muscle_groups.csv``).

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

__all__ = ["add_analyse_parser", "analyse_command", "analyse_trial", "SIDES"]

SIDES = ("r", "l")


def add_analyse_parser(subparsers) -> None:
    from ..metabolics.cli import add_basal_arguments

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
    p.set_defaults(func=analyse_command)


def _recorded_settings(folder: Path) -> dict:
    """``models``, ``body_mass_kg``, ``height_m`` and the basal settings from a metabolics
    folder's metabolics.sto header."""
    from ..metabolics.solution import METABOLICS_STO

    path = folder / METABOLICS_STO
    if not path.is_file():
        raise InputFileError(f"{path}: missing; give the folder written by 'musclemetab metabolics' as --metabolics")
    out = {}
    with path.open(encoding="utf-8", errors="replace") as f:
        for line in f:
            line = line.strip()
            if line == "endheader":
                break
            key, _, value = line.partition("=")
            if key in ("models", "body_mass_kg", "height_m", "basal_rule", "basal_coefficient",
                       "basal_exponent") and value:
                out[key] = value
    return out


def _cycle(args, side: str):
    from .events import GaitCycle, cycle_from_grf, cycle_from_id_file, read_grf

    if args.cycle:
        try:
            vals = [float(v) for v in args.cycle.split(",")]
        except ValueError:
            vals = []
        if len(vals) != 3:
            raise OptionError(f"--cycle must be three times in seconds, START,TOE_OFF,END, not '{args.cycle}'")
        return GaitCycle(*vals), "given on the command line"
    from ..io import read_storage

    t = read_storage(args.ik).index.to_numpy(float)
    if args.grf:
        force = read_grf(args.grf, side=side)
        return (cycle_from_grf(force.index.to_numpy(float), force.to_numpy(float), at_time_s=0.5 * (t[0] + t[-1])),
                "ground reaction forces")
    return (cycle_from_id_file(args.id, side=side, window_s=(float(t[0]), float(t[-1]))),
            "estimated from the IK window and the ankle moment (no ground reaction forces)")


def analyse_trial(solution_dir, model, ik, cycle, body_mass_kg: float, height_m: float, out_dir, *,
                  models="all", basal: str = "body", speed_m_per_s: float | None = None, side: str | None = None,
                  basal_rate_W_per_kg: float | None = None, basal_exponent: float = 1.0):
    """Analyse one solution folder into ``out_dir``; returns ``(whole_body, analysis, per_muscle)`` tables.

    ``basal``, ``basal_rate_W_per_kg`` (default 1.2) and ``basal_exponent``: the whole-body basal
    rule of :func:`musclemetab.metabolics.solution.metabolics_from_solution`."""
    from ..geometry import compute_geometry
    from ..io import atomic_directory
    from ..metabolics import BASAL_RATE_W_PER_KG
    from ..metabolics.solution import WHOLE_BODY_CSV, metabolics_from_solution
    from ..properties import split_side
    from .groups import group_key_table
    from .per_muscle import PER_MUSCLE_FILE, per_muscle_table
    from .unit import analyse_metabolics, filtered_moment_arms

    result = metabolics_from_solution(
        solution_dir, body_mass_kg, height_m, models=models, basal=basal, speed_m_per_s=speed_m_per_s,
        basal_rate_W_per_kg=BASAL_RATE_W_PER_KG if basal_rate_W_per_kg is None else basal_rate_W_per_kg,
        basal_exponent=basal_exponent)
    if side is None:
        sides = {split_side(m)[1] for m in result.muscles} - {""}
        side = sides.pop() if len(sides) == 1 else "r"
    geometry = compute_geometry(model, ik, side=side, muscles=list(result.muscles))
    tg, r = filtered_moment_arms(geometry)
    analysis = analyse_metabolics(result, tg, r, list(geometry.dofs), list(geometry.muscles), cycle)
    whole = result.whole_body_table()
    per = per_muscle_table(result, cycle, side=side)
    with atomic_directory(out_dir) as tmp:
        whole.to_csv(tmp / WHOLE_BODY_CSV, index=False, float_format="%.10g")
        analysis.summary.to_csv(tmp / "analysis.csv", index=False, float_format="%.10g")
        analysis.timeseries.to_csv(tmp / "timeseries.csv", index=False, float_format="%.10g")
        per.to_csv(tmp / PER_MUSCLE_FILE, index=False, float_format="%.10g")
        group_key_table().to_csv(tmp / "muscle_groups.csv", index=False)
    return whole, analysis.summary, per


def analyse_command(args) -> int:
    import numpy as np
    import pandas as pd

    from ..analysis.per_muscle import PER_MUSCLE_FILE
    from ..io import atomic_path
    from ..metabolics.cli import BASAL_DEFAULTS, check_basal_arguments
    from ..redundancy.solution import SOLUTION_FILE

    root = Path(args.solution)
    if (root / SOLUTION_FILE).is_file():
        jobs = [(None, root, Path(args.out))]
    else:
        jobs = [(s, root / s, Path(args.out) / s) for s in SIDES if (root / s / SOLUTION_FILE).is_file()]
        if not jobs:
            raise InputFileError(f"{root}: no {SOLUTION_FILE} in it, nor in {root / 'r'} or {root / 'l'}; "
                                 "give a solution folder written by 'musclemetab solve'")
    recorded = _recorded_settings(Path(args.metabolics)) if args.metabolics else {}
    try:
        mass = args.mass if args.mass is not None else float(recorded["body_mass_kg"])
        height = args.height if args.height is not None else float(recorded["height_m"])
    except KeyError:
        raise OptionError("give --mass and --height (or --metabolics, the folder written by "
                          "'musclemetab metabolics', which records them)") from None
    models = args.models or recorded.get("models") or "all"
    for key, rec, kind in (("basal", "basal_rule", str), ("basal_coefficient", "basal_coefficient", float),
                           ("basal_exponent", "basal_exponent", float)):
        if getattr(args, key) is None:
            setattr(args, key, kind(recorded[rec]) if rec in recorded else BASAL_DEFAULTS[key])
    check_basal_arguments(args)
    if args.speed is not None and not (np.isfinite(args.speed) and args.speed > 0):
        raise OptionError(f"--speed must be a positive number of m/s, not {args.speed}")
    tables = []
    for side, sol_dir, out in jobs:
        cycle, source = _cycle(args, side or "r")
        speed = args.speed
        speed_note = "given"
        if speed is None:
            from .speed import walking_speed_from_ik

            speed = walking_speed_from_ik(args.ik, start_s=cycle.start_s, end_s=cycle.end_s)
            speed_note = "estimated from the pelvis displacement"
        whole, summary, per = analyse_trial(sol_dir, args.model, args.ik, cycle, mass, height, out, models=models,
                                            basal=args.basal, speed_m_per_s=speed, side=side,
                                            basal_rate_W_per_kg=args.basal_coefficient,
                                            basal_exponent=args.basal_exponent)
        tables.append(per)
        label = f"side {side}: " if side else ""
        print(f"analyse: {label}cycle {cycle.start_s:.3f}-{cycle.end_s:.3f} s, toe-off {cycle.toe_off_pct:.1f} % "
              f"({source}); speed {speed:.2f} m/s ({speed_note}) -> {out}")
        merged = whole.merge(summary, on="model")
        for row in merged.itertuples():
            top = per[per.model == row.model].nsmallest(3, "rank")["muscle"].tolist()
            print(f"  {row.model}: {row.mean_W_per_kg:.2f} W/kg, gross CoT {row.gross_cost_of_transport_J_per_kg_per_m:.2f} "
                  f"J/(kg m), swing {row.swing_energy_share_pct:.1f} % of the leg's energy, "
                  f"PF {row.share_PF_pct:.1f} %; largest: {', '.join(top)}")
    if jobs[0][0] is not None:  # the sides' parent: one table of every side
        with atomic_path(Path(args.out) / PER_MUSCLE_FILE) as tmp:
            pd.concat(tables, ignore_index=True).to_csv(tmp, index=False, float_format="%.10g")
    return 0
