"""``musclemetab analyse``: phases, groups, per-muscle and whole-body results of a solved trial.

    musclemetab analyse --solution DIR [--metabolics DIR] --out DIR
                        [--model M.osim] [--ik IK.mot] [--id ID.sto | --grf GRF.mot | --cycle S,TO,E]
                        [--mass KG --height M] [--models all]
                        [--basal body|muscle|none] [--basal-coefficient 1.2] [--basal-exponent 1]
                        [--speed M_PER_S] [--strict]

The command-line path ``solve`` -> ``metabolics`` -> ``analyse`` gives what a study unit
gives: in ``OUT`` the whole-body table (``whole_body.csv``, with gross and net cost of
transport), the stance/swing and muscle-group analysis (``analysis.csv``), the leg and
group rates over the cycle (``timeseries.csv``), the per-muscle table (``per_muscle.csv``),
the key of the group abbreviations (``muscle_groups.csv``) and ``results.csv``, the study's
results rows of the trial (one per model: :func:`musclemetab.study.runner.trial_result_rows`):
:func:`musclemetab.analysis.analyse` and :func:`musclemetab.analysis.write_analysis`; and
``analyse.json``, each leg's solution and metabolics folders, cycle, body mass and height, from
which ``musclemetab report OUT`` draws the page a study gives (:mod:`musclemetab.report.cli_folder`).

What the solution records is not asked again (:func:`musclemetab.analysis.recorded_trial`):
the model and the IK motion it was solved from, the leg, the DOFs and the gait cycle of a
solve over ``--cycle``; the options override them. DOFs that belong to no muscle function
group (a subtalar or toe joint) are left out of the group analysis, with a note. The speed is
``--speed``, else the pelvis displacement over the cycle; when the kinematics cannot give it
(a treadmill trial) the cost of transport is left empty, with a note, as in a study.

``--solution`` may also be the parent of one folder per side (``DIR/r`` and ``DIR/l``, each
a solution folder, as ``solve --side both`` writes it), and ``--metabolics`` the folder
``metabolics`` wrote from it (``M/r``, ``M/l``): each side is analysed into ``OUT/r`` and
``OUT/l``, the per-muscle tables of both sides are gathered in ``OUT/per_muscle.csv`` and
``OUT/results.csv`` adds the legs as a study does (:func:`musclemetab.study.runner.add_leg_rows`).

The plausibility flags (``docs/quality.md``) of the solve(s) and of the results rows (each
model's whole-body rate against the speed, negative group shares) are printed as one
``musclemetab: warning:`` line each, written to ``OUT/plausibility.json`` and summed up in the
``quality`` column of ``results.csv``, as in a study; ``--strict`` makes a flag a failure.

Body mass, height, models and the basal settings default to those recorded in ``--metabolics``'s
``metabolics.sto`` (written by ``musclemetab metabolics``); the rates are evaluated again
from the solution (they take milliseconds) with those settings.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InputFileError, OptionError
from .options import (
    BASAL_DEFAULTS,
    add_basal_arguments,
    add_solve_flags_argument,
    check_basal_arguments,
    check_body,
    check_speed,
    warn_solve_flags,
)

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
            "per_muscle.csv, muscle_groups.csv, results.csv (the study's results rows) and analyse.json (the solution "
            "and metabolics folders of each leg, for 'musclemetab report OUT'). The model, IK motion, "
            "leg, DOFs and gait cycle the solution records are used unless given. DIR may hold one solution folder "
            "per side (DIR/r, DIR/l; --metabolics likewise): OUT/r and OUT/l are written, OUT/per_muscle.csv gathers "
            "both sides and OUT/results.csv adds the legs. Every column is described in docs/data_dictionary.md."
        ),
    )
    p.add_argument("--solution", required=True, metavar="DIR",
                   help="solution folder (solution.sto, summary.json), or the parent of DIR/r and DIR/l")
    p.add_argument("--metabolics", metavar="DIR",
                   help="folder written by 'musclemetab metabolics' (its metabolics.sto gives the body mass, height "
                   "and models when they are not given)")
    p.add_argument("--model", metavar="M.osim",
                   help="OpenSim model the solution was solved with (default: the one its summary.json records)")
    p.add_argument("--ik", metavar="IK.mot",
                   help="inverse kinematics of the trial, for the moment arms and the speed (default: the one its "
                   "summary.json records)")
    cyc = p.add_mutually_exclusive_group()
    cyc.add_argument("--id", metavar="ID.sto", help="inverse dynamics: toe-off from the ankle moment, the cycle "
                     "from the IK window less 0.05 s at each end (estimated events)")
    cyc.add_argument("--grf", metavar="GRF.mot", help="ground reaction forces: events from the vertical force")
    cyc.add_argument("--cycle", metavar="START,TOE_OFF,END",
                     help="the gait events (s) (default: the cycle a solve over --cycle recorded, else from the "
                     "inverse dynamics the solution was solved with, as --id)")
    p.add_argument("--mass", type=float, metavar="KG", help="body mass (kg)")
    p.add_argument("--height", type=float, metavar="M", help="body height (m)")
    p.add_argument("--models", metavar="LIST", help="'all' or a comma-separated list (default: those of --metabolics, "
                   "else all)")
    add_basal_arguments(p, recorded="--metabolics")
    p.add_argument("--speed", type=float, metavar="M_PER_S",
                   help="walking speed (default: estimated from the pelvis displacement over the cycle)")
    p.add_argument("--strict", action="store_true",
                   help="a plausibility flag of the solve or of a whole-body rate (one warning line each, "
                   "docs/quality.md) fails the command (exit status 1; the files are still written)")
    add_solve_flags_argument(p)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.set_defaults(func=run)


def _cycle(args, side: str, ik, recorded):
    """The gait cycle and where it came from: the options, else the solution's record."""
    from ..events import GaitCycle, cycle_of_trial

    if args.cycle:
        try:
            vals = [float(v) for v in args.cycle.split(",")]
        except ValueError:
            vals = []
        if len(vals) != 3:
            raise OptionError(f"--cycle must be three times in seconds, START,TOE_OFF,END, not '{args.cycle}'")
        return GaitCycle(*vals), "given on the command line"
    window = "" if recorded.window_s is None else f" inside the solved {recorded.window_s[0]:g}-{recorded.window_s[1]:g} s"
    remedy = f"give the cycle's events{window} (--cycle START,TOE_OFF,END) or the ground forces (--grf GRF.mot)"
    model = args.model or recorded.model
    if args.grf or args.id:  # within the window the solve recorded
        return cycle_of_trial(ik, grf=args.grf, id_file=args.id, side=side, model=model,
                              window_s=recorded.window_s, remedy=remedy)
    if recorded.cycle is not None:
        return recorded.cycle, recorded.cycle_source
    if recorded.external_loads is not None and Path(recorded.external_loads).is_file() and model is not None:
        return cycle_of_trial(ik, external_loads=recorded.external_loads, side=side, model=model,
                              window_s=recorded.window_s, remedy=remedy)
    if recorded.id is not None and Path(recorded.id).is_file():
        return cycle_of_trial(ik, id_file=recorded.id, side=side, window_s=recorded.window_s, remedy=remedy)
    raise OptionError("the solution records no gait cycle (it was not solved over --cycle) and no inverse dynamics "
                      "file that still exists: give --cycle START,TOE_OFF,END, --grf GRF.mot or --id ID.sto")


def _recorded_file(given, recorded, option: str, sol_dir) -> str:
    """An input file: the option's, else the one the solution records (which must still exist)."""
    if given is not None:
        return given
    if recorded is None:
        raise OptionError(f"{sol_dir}: the solution records no {option[2:]} file; give {option}")
    if not Path(recorded).is_file():
        if not Path(recorded).is_absolute():  # recorded by an earlier version, as the solve was given it
            raise InputFileError(f"{sol_dir}: the solution was solved from {recorded}, a name relative to the folder "
                                 f"the solve ran in and not found from this one; run this command from that folder "
                                 f"or give {option}")
        raise InputFileError(f"{sol_dir}: the solution was solved from {recorded}, which is not there any more; "
                             f"give {option}")
    return recorded


def _metabolics_folder(root, side):
    """The metabolics folder of one leg: ``root``, or ``root/<side>`` of a both-legs folder."""
    from ..metabolics.solution import METABOLICS_STO

    root = Path(root)
    if side is not None and not (root / METABOLICS_STO).is_file() and (root / side / METABOLICS_STO).is_file():
        return root / side
    return root


def run(args) -> int:
    """Run ``musclemetab analyse`` (``args`` from :func:`add_parser`)."""
    import json

    import pandas as pd

    from ..analysis.unit import analyse, recorded_excluded_muscles, recorded_trial, write_analysis
    from ..errors import DataMismatchError
    from ..io import atomic_path
    from ..messages import note
    from ..metabolics.per_muscle import PER_MUSCLE_FILE
    from ..metabolics.solution import check_metabolics_of, read_metabolics_settings
    from ..model import check_body_mass
    from ..redundancy.solution import SOLUTION_FILE, read_flags
    from ..metabolics.plausibility import add_quality
    from ..study.runner import RESULTS_CSV, add_leg_rows, leg_basal_energy_J, trial_result_rows

    root = Path(args.solution)
    if (root / SOLUTION_FILE).is_file():
        jobs = [(None, root, Path(args.out))]
    else:
        jobs = [(s, root / s, Path(args.out) / s) for s in SIDES if (root / s / SOLUTION_FILE).is_file()]
        if not jobs:
            raise InputFileError(f"{root}: no {SOLUTION_FILE} in it, nor in {root / 'r'} or {root / 'l'}; "
                                 "give a solution folder written by 'musclemetab solve'")
    check_speed(args.speed)
    from ..analysis.unit import ANALYSIS_FILES
    from ..io.atomic import check_output_folder, check_replaceable

    check_output_folder(args.out)  # a file, or a folder that cannot be written: one line before any work
    for side, _, out in jobs:  # a file of the user, or changed since written, is not replaced: refused before any work
        check_replaceable(out, ANALYSIS_FILES)
    from ..analysis.unit import ANALYSE_RECORD
    from ..metabolics.plausibility import PLAUSIBILITY_FILE

    check_replaceable(Path(args.out), [RESULTS_CSV, ANALYSE_RECORD, PLAUSIBILITY_FILE]
                      + ([PER_MUSCLE_FILE] if jobs[0][0] is not None else []))
    basal_given = {key: getattr(args, key) for key in BASAL_DEFAULTS}
    rows, basal_J, tables, legs, solve_flags = {}, {}, [], [], {}
    for side, sol_dir, out in jobs:
        recorded = recorded_trial(sol_dir)
        met_dir = _metabolics_folder(args.metabolics, side or recorded.side) if args.metabolics else None
        settings = read_metabolics_settings(met_dir) if met_dir else {}
        digest = check_metabolics_of(sol_dir, met_dir, settings)
        try:
            mass = args.mass if args.mass is not None else settings["body_mass_kg"]
            height = args.height if args.height is not None else settings.get("height_m")
        except KeyError:
            raise OptionError("give --mass (and --height, or none for muscle masses from the model), or "
                              "--metabolics, the folder written by 'musclemetab metabolics', which records them") from None
        models = args.models or settings.get("models") or "all"
        for key, rec in (("basal", "basal_rule"), ("basal_coefficient", "basal_coefficient"),
                         ("basal_exponent", "basal_exponent")):
            given = basal_given[key]
            setattr(args, key, given if given is not None else settings.get(rec, BASAL_DEFAULTS[key]))
        check_basal_arguments(args)
        check_body(mass, height)
        model = _recorded_file(args.model, recorded.model, "--model", sol_dir)
        if args.mass is not None and not legs:  # once: one subject's mass for both legs
            check_body_mass(mass, model)
        ik = _recorded_file(args.ik, recorded.ik, "--ik", sol_dir)
        leg = side or recorded.side or "r"
        cycle, source = _cycle(args, leg, ik, recorded)
        speed, speed_note = args.speed, "given"
        if speed is None:
            from ..analysis.speed import walking_speed_from_ik

            try:
                speed = walking_speed_from_ik(ik, start_s=cycle.start_s, end_s=cycle.end_s, model=model)
                speed_note = "estimated from the pelvis displacement over the cycle (IK)"
            except DataMismatchError as exc:
                speed, speed_note = None, "not available"
                note(f"no walking speed, no cost of transport ({exc})")
        result = analyse(sol_dir, model, ik, cycle, mass, height, models=models, side=side,
                         basal=args.basal, basal_rate_W_per_kg=args.basal_coefficient,
                         basal_exponent=args.basal_exponent, speed_m_per_s=speed)
        write_analysis(result, out)
        legs.append({"side": leg, "folder": side or ".", "solution": str(Path(sol_dir).resolve()),
                     "solution_sha256": digest,
                     "metabolics": str(Path(met_dir).resolve()) if met_dir else None, "model": str(model),
                     "ik": str(ik), "cycle": {"start_s": cycle.start_s, "toe_off_s": cycle.toe_off_s,
                                              "end_s": cycle.end_s}, "cycle_source": source,
                     "body_mass_kg": float(mass), "height_m": None if height is None else float(height),
                     "basal": args.basal})
        per = result.per_muscle
        tables.append(per)
        rows[side] = trial_result_rows(result.whole_body, result.summary, speed_m_per_s=speed,
                                       toe_off_pct=cycle.toe_off_pct, cycle_source=source,
                                       speed_source=speed_note if speed is not None else "not available",
                                       large_reserve=_large_reserve(sol_dir), unit_dir=side or ".",
                                       excluded_muscles=recorded_excluded_muscles(sol_dir),
                                       named_by_events=(bool(args.cycle) or source == "ground reaction forces"
                                                        or recorded.window_named_by_events))
        basal_J[side] = leg_basal_energy_J(per, rows[side]["duration_s"].iloc[0])
        solve_flags[str(sol_dir)] = read_flags(sol_dir)
        label = f"side {side}: " if side else ""
        speed_text = f"{speed:.2f} m/s ({speed_note})" if speed is not None else "not available"
        print(f"analyse: {label}cycle {cycle.start_s:.3f}-{cycle.end_s:.3f} s, toe-off {cycle.toe_off_pct:.1f} % "
              f"({source}); speed {speed_text} -> {out}")
        if result.excluded_dofs:
            print(f"  DOFs of no muscle function group, left out of the group analysis: "
                  f"{', '.join(result.excluded_dofs)} (docs/analysis.md)")
        merged = result.whole_body.merge(result.summary, on="model")
        for row in merged.itertuples():
            top = per[per.model == row.model].nsmallest(3, "rank")["muscle"].tolist()
            cot = row.gross_cost_of_transport_J_per_kg_per_m if hasattr(row, "gross_cost_of_transport_J_per_kg_per_m") \
                else float("nan")
            cot_text = f"gross CoT {cot:.2f} J/(kg m)" if speed is not None else "no CoT (no speed)"
            print(f"  {row.model}: {row.whole_body_W_per_kg:.2f} W/kg, {cot_text}, swing {row.swing_energy_share_pct:.1f} % "
                  f"of the leg's energy, PF {row.share_PF_pct:.1f} %; largest: {', '.join(top)}")
    if jobs[0][0] is not None:  # the sides' parent: one table of every side, the legs added
        with atomic_path(Path(args.out) / PER_MUSCLE_FILE, mark=True) as tmp:
            pd.concat(tables, ignore_index=True).to_csv(tmp, index=False, float_format="%.10g")
        if len(rows) > 1:
            table = add_leg_rows(rows, basal_J)
        else:
            (side, table), = rows.items()
            table = table.assign(legs=f"2 x {side}")
        table = add_quality(table, [{"plausibility": [f.to_dict() for f in fl]} for fl in solve_flags.values()])
        with atomic_path(Path(args.out) / RESULTS_CSV, mark=True) as tmp:
            table.to_csv(tmp, index=False, float_format="%.10g")
        if len(rows) > 1:
            print(f"analyse: legs {' + '.join(rows)} added -> {Path(args.out) / RESULTS_CSV}: "
                  + ", ".join(f"{r.model} {r.whole_body_W_per_kg:.2f} W/kg" for r in table.itertuples()))
    else:
        (side, table), = rows.items()
        table = add_quality(table.assign(legs=f"2 x {recorded.side or 'r'}"),
                            [{"plausibility": [f.to_dict() for f in fl]} for fl in solve_flags.values()])
        with atomic_path(Path(args.out) / RESULTS_CSV, mark=True) as tmp:
            table.to_csv(tmp, index=False, float_format="%.10g")
    from ..io.atomic import atomic_write_text

    atomic_write_text(Path(args.out) / ANALYSE_RECORD, json.dumps(
        {"format": "musclemetab analyse", "format_version": 1, "legs": legs}, indent=1) + "\n", mark=True)
    _plausibility(args, solve_flags, table)
    return 0


def _plausibility(args, solve_flags, table) -> None:
    """Warn (one line each) of the results rows' metabolic plausibility flags (each model's
    whole-body rate against its speed, its negative group shares; the ``quality`` column of
    ``results.csv``) and, with ``--show-solve-flags``, of the solves' (``{folder: [Flag]}``);
    write them all to ``OUT/plausibility.json``; with ``--strict`` fail."""
    from ..metabolics.plausibility import results_rows_flags, write_plausibility
    from ..quality import check_strict, warn_flags

    warn_solve_flags(args, solve_flags)
    flags = [f for found in solve_flags.values() for f in found]
    rates = results_rows_flags(table)
    warn_flags(rates, str(args.out))
    write_plausibility(flags + rates, args.out)
    if args.strict:
        check_strict(flags + rates, "analyse --strict", written=str(args.out))


def _large_reserve(sol_dir) -> bool:
    """Whether the solve's reserves exceed 1 % of the peak joint moment (its ``summary.json``)."""
    from ..redundancy.solution import read_summary

    return bool(read_summary(sol_dir).large_reserve)
