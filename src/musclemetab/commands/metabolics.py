"""``musclemetab metabolics``: metabolic rates of every muscle of a solver solution.

    musclemetab metabolics --solution DIR|PARENT | --states FILE [--controls FILE]
                           [--muscle-parameters probes|package]
                           --model M.osim --mass KG [--height M]
                           [--models all|UM10,BH04,...|all,LW05,MA68] [--basal body|muscle|none]
                           [--basal-coefficient 1.2] [--basal-exponent 1]
                           [--speed M_PER_S] --out DIR

Writes ``OUT/metabolics.sto``, ``OUT/whole_body.csv`` and ``OUT/per_muscle.csv`` (and
``OUT/metabolics.parquet`` with the ``parquet`` extra) (:func:`musclemetab.metabolics.solution.write_legs_metabolics`). One leg
solved: the whole-body rate doubles it (the study's rule, and the output says so). ``--solution``
may also be the parent written by ``solve --side both`` (``PARENT/r``, ``PARENT/l``): each leg
is evaluated over its own cycle into ``OUT/r`` and ``OUT/l``, and ``OUT/whole_body.csv`` adds
the two legs (basal heat once); :func:`musclemetab.metabolics.solution.metabolics_from_legs`.
``--states`` evaluates an OpenSim states file of ``--model`` instead
(:mod:`musclemetab.metabolics.opensim_states`).
"""

from __future__ import annotations

from pathlib import Path

from ..messages import name_list, note
from .options import (
    add_basal_arguments,
    add_solve_flags_argument,
    check_basal_arguments,
    check_body,
    check_speed,
    warn_solve_flags,
)

__all__ = ["add_parser", "run"]


def add_parser(subparsers) -> None:
    """Add the ``metabolics`` subcommand to an ``argparse`` subparsers object."""
    from ..metabolics.registry import ADDITIONAL_MODELS, MODELS

    p = subparsers.add_parser(
        "metabolics",
        help="metabolic rates of every muscle of a solution or an OpenSim motion, for several energy models",
        description=(
            "Evaluate muscle metabolic energy models on a muscle redundancy solution (the padding nodes "
            "trimmed: 5 at the start, 6 at the end) or on an OpenSim states file of a model (--states: every state, "
            "OpenSim's own muscle dynamics), muscle by muscle and node by node. Writes "
            "OUT/metabolics.sto (columns <model>/<muscle>/<component>, W), OUT/metabolics.parquet (tidy: time, "
            "model, muscle, component, value_W; with the parquet extra) and OUT/whole_body.csv (one row per model: whole-body "
            f"average in W/kg). Models: the study's {', '.join(MODELS)} ('all', the default) and, when "
            f"named, {', '.join(ADDITIONAL_MODELS)}."
        ),
    )
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--solution", metavar="DIR",
                        help="solution folder (solution.sto, summary.json), or the parent of r/ and l/ written by "
                        "solve --side both (the legs are then added instead of doubling one)")
    source.add_argument("--states", metavar="FILE",
                        help="an OpenSim states file of --model (CMC, Moco or forward dynamics states.sto): every "
                        "muscle's fiber velocity, force-length and force-velocity multipliers, passive force and "
                        "activation from OpenSim's own muscle dynamics at each state (docs/metabolics.md, Energy "
                        "of an OpenSim motion); every state kept, no padding trimmed")
    p.add_argument("--controls", metavar="FILE",
                   help="with --states: the simulation's controls file (muscle excitations, columns /forceset/<muscle> "
                   "or <muscle>); the model's muscles it lacks are not evaluated. Without it excitation = activation")
    p.add_argument("--fiber-velocity", choices=("auto", "trajectory", "derivative", "equilibrium"), default="auto",
                   help="with --states: a compliant-tendon DeGrooteFregly2016Muscle's fiber velocity from the "
                   "trajectory's own tendon-force derivatives ('trajectory': the implicitderiv_normalized_tendon_force "
                   "columns of a Moco solution file, the velocity Moco solved with), from the time derivative of "
                   "OpenSim's fiber lengths along the states ('derivative': right for states made with other curves, "
                   "such as a musclemetab solution's states.sto) or from OpenSim's force equilibrium ('equilibrium': "
                   "as OpenSim's own probes take it); 'auto' (the default): the trajectory's where the file holds "
                   "them, else the derivative. Other muscles always take OpenSim's (docs/metabolics.md, Energy of an "
                   "OpenSim motion)")
    p.add_argument("--cycle", metavar="START,TOE_OFF,END",
                   help="with --states: the gait events (s) of the cycle the rates are averaged over (and the stance "
                   "and swing of per_muscle.csv); default: every state of the file")
    p.add_argument("--muscle-parameters", choices=("probes", "package"), default="probes",
                   help="with --states and a model carrying OpenSim metabolic probes: 'probes' (default) takes each "
                   "muscle's mass and slow-twitch ratio from the model's probes (its specific tension, density, "
                   "provided masses), so that the package and OpenSim agree; 'package' keeps the package's tables")
    p.add_argument(
        "--model", metavar="M.osim",
        help="OpenSim model the solution was computed with: F0, lMo and vmax are taken from it, by muscle "
        "name (default: the values recorded in the solution's summary.json)",
    )
    p.add_argument("--mass", required=True, type=float, metavar="KG", help="body mass (kg)")
    p.add_argument("--height", type=float, metavar="M",
                   help="body height (m), for the muscle masses by the volume rule; without it each muscle's mass "
                   "comes from the model, F0 / specific tension x density x lMo (as OpenSim's probes), and the "
                   "outputs say so (muscle_mass_rule)")
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
        "slow-twitch fraction 0.5, with a warning naming them), and fail (exit status 1, the files written) on a "
        "plausibility flag of the solve or of the whole-body rate against --speed (one warning line each, "
        "docs/quality.md)",
    )
    p.add_argument(
        "--sensitivity", nargs="?", const="all", metavar="PARAMETERS",
        help="also write OUT/sensitivity.csv: the derivative of each rate (whole body and each muscle, each model) "
        "per log of each muscle parameter at the optimum, ranked (docs/uncertainty.md, Sensitivities). The problem "
        "is rebuilt from the files summary.json names and re-solved once at a tight tolerance. PARAMETERS: 'all' "
        "(default: F0,lMo,lTs,kT,kPE,s0,sM,vmax,alpha0) or a comma-separated list of them; effort workflows, one "
        "leg's solution folder; a few minutes for all parameters of 40 muscles",
    )
    add_solve_flags_argument(p)
    p.add_argument("--mat", metavar="FILE.mat",
                   help="also write a MATLAB file: the solution's arrays (time x muscles) and parameters, the rates of "
                   "each model per muscle and component, the whole-body and per-muscle tables (docs/matlab.md)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (may be the solution folder)")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``musclemetab metabolics`` (``args`` from :func:`add_parser`)."""
    from ..io import check_output_folder
    from ..metabolics.registry import parse_models
    from ..metabolics.solution import (
        check_metabolics_outputs,
        metabolics_from_legs,
        parameter_differences,
        read_solution_states,
        solution_folders,
        write_legs_metabolics,
    )

    models = parse_models(args.models)
    check_output_folder(args.out)
    if args.mat is not None:
        from ..io.matlab import check_mat_path

        check_mat_path(args.mat)
    check_speed(args.speed)
    check_body(args.mass, args.height)
    check_basal_arguments(args)
    if args.states is not None:
        return _run_states(args, models)
    if args.controls is not None or args.cycle is not None:
        from ..errors import OptionError

        option = "--controls" if args.controls is not None else "--cycle"
        raise OptionError(f"{option} goes with --states (a solution folder carries its excitations and the cycle "
                          "a solve over --cycle recorded; musclemetab analyse --cycle averages a solution over another)")
    folders = solution_folders(args.solution)
    check_metabolics_outputs(args.out, folders)
    sensitivity = _sensitivity_parameters(args.sensitivity, folders)
    if sensitivity is not None:
        from ..io.atomic import check_replaceable
        from ..redundancy.sensitivity import SENSITIVITY_CSV

        check_replaceable(args.out, [SENSITIVITY_CSV])
    params = None
    if args.model:
        from ..model import read_muscle_parameters

        params = read_muscle_parameters(args.model)
    states = {side: read_solution_states(folder, require_success=not args.allow_failed)
              for side, folder in folders.items()}
    _check_mass(args.mass, args.model, next(iter(folders.values())))
    if params is not None:
        for leg in states.values():
            _note(parameter_differences(leg, params), args.model)
    if args.muscle_properties:  # a row naming no muscle would be ignored: refuse it
        from ..properties import read_muscle_properties

        solved = [m for leg in states.values() for m in leg.muscles]
        read_muscle_properties(args.muscle_properties).check_names(
            params.names if params is not None else solved, tables=params is None)
    results = metabolics_from_legs(
        states, args.mass, args.height, models=models, muscle_parameters=params, basal=args.basal,
        basal_rate_W_per_kg=args.basal_coefficient, basal_exponent=args.basal_exponent, speed_m_per_s=args.speed,
        muscle_properties=args.muscle_properties, strict=args.strict,
    )
    files = write_legs_metabolics(results, args.out)
    _write_mat(args, results, folders)
    if args.height is None:
        note("no --height: muscle masses from the model (F0 / specific tension x density x lMo), not from the "
             "volume rule of body mass and height (a study subject with height_m); give --height for those")
    if len(results) == 1:
        (side, result), = results.items()
        means = ", ".join(f"{m} {result.whole_body[m].mean_W_per_kg:.2f}" for m in result.models)
        leg = {"r": "the right leg", "l": "the left leg"}.get(side, "the solved leg")
        print(
            f"metabolics: {len(result.models)} models x {len(result.muscles)} muscles x {result.time_s.size} nodes "
            f"-> {args.out} ({', '.join(p.name for p in files.values())}); whole body = 2 x {leg} "
            f"(W/kg, basal {args.basal}): {means}"
        )
        _plausibility(args, folders, results)
        if sensitivity is not None:
            _write_sensitivity(args, folders[side], sensitivity, models)
        return 0
    from ..metabolics.solution import add_legs

    out = files["whole_body_csv"].parent
    means = ", ".join(f"{m} {v:.2f}" for m, v in add_legs(results).items())
    print(f"metabolics: legs {' + '.join(results)} added (each over its own cycle) -> {out}/whole_body.csv and "
          f"{', '.join(f'{out}/{s}' for s in results)} (each leg's muscles, no basal); whole body (W/kg, basal "
          f"{args.basal}): {means}")
    _plausibility(args, folders, results)
    return 0


def _run_states(args, models) -> int:
    """``musclemetab metabolics --states FILE --model M.osim``: the energy of an OpenSim motion."""
    from ..errors import OptionError
    from ..metabolics.opensim_states import read_opensim_states, split_sides, states_metabolics
    from ..metabolics.solution import check_metabolics_outputs, write_legs_metabolics

    if not args.model:
        raise OptionError("--states needs --model: the OpenSim model the states belong to")
    if args.sensitivity is not None:
        raise OptionError("--sensitivity needs a solution folder (--solution), not --states")
    cycle = _states_cycle(args.cycle)
    read = read_opensim_states(args.model, args.states, args.controls, fiber_velocity=args.fiber_velocity)
    legs = split_sides(read.states)
    check_metabolics_outputs(args.out, legs)
    results, used = states_metabolics(
        read, legs, args.mass, args.height, models=models, basal=args.basal,
        basal_rate_W_per_kg=args.basal_coefficient, basal_exponent=args.basal_exponent, speed_m_per_s=args.speed,
        muscle_properties=args.muscle_properties, strict=args.strict, muscle_parameters=args.muscle_parameters,
        cycle_s=None if cycle is None else (cycle.start_s, cycle.end_s))
    if used:
        for r in results.values():
            r.muscle_parameters = f"OpenSim metabolic probes of the model: {used}"
        note(f"muscle masses and slow-twitch ratios from the model's metabolic probes ({used}); "
             "--muscle-parameters package for the package's tables")
    files = write_legs_metabolics(results, args.out, cycle=cycle)
    _write_mat(args, results)
    n_cl = int(read.clamped.sum()) if read.clamped is not None else 0
    if n_cl:
        act = read.states.states["activation"][read.clamped]
        words = {"trajectory": "the trajectory's tendon-force derivative", "equilibrium": "OpenSim's equilibrium",
                 "derivative": "the derivative of OpenSim's fiber length"}
        clamped_muscles = read.clamped.any(axis=1).tolist()
        used = sorted({src for src, c in zip(read.velocity_sources, clamped_muscles) if c} & words.keys())
        how = " or ".join(words[u] for u in used) or "OpenSim"
        note(f"{n_cl} of {read.clamped.size} muscle-states of DeGrooteFregly2016 muscles have a "
             f"fiber velocity from {how} off the force-velocity curve (activation there up to {act.max():.3g}); "
             "taken at the curve's bound")
    excitation = ("from " + str(args.controls)) if read.excitation_source == "controls" else "= activation"
    skipped = ""
    if read.skipped_muscles:
        why = ("without controls" if read.skipped_reason == "no controls"
               else "whose states are the model's defaults at every state")
        skipped = f", {len(read.skipped_muscles)} muscles {why} not evaluated"
        if read.skipped_reason != "no controls":
            note(f"{len(read.skipped_muscles)} muscles of {args.model} ({read.skipped_muscles[0]}, ...) hold the "
                 f"model's default states all along {args.states} (not simulated, e.g. the other leg of a one-leg "
                 "solution): not evaluated")
    over = "" if cycle is None else f", averaged over the cycle {cycle.start_s:g}-{cycle.end_s:g} s"
    from collections import Counter

    velocity = ", ".join(f"{k} {n}" for k, n in sorted(Counter(read.velocity_sources).items()))
    first = next(iter(results.values()))
    if len(results) == 1:
        (side, result), = results.items()
        whole = f"whole body = 2 x the {'right' if side == 'r' else 'left' if side == 'l' else 'evaluated'} leg"
        means = ", ".join(f"{m} {result.whole_body[m].mean_W_per_kg:.2f}" for m in result.models)
    else:
        from ..metabolics.solution import add_legs

        whole = f"legs {' + '.join(results)} added"
        means = ", ".join(f"{m} {v:.2f}" for m, v in add_legs(results).items())
    print(f"metabolics: {len(first.models)} models x {len(read.states.muscles)} muscles x {read.states.time_s.size} "
          f"states of {args.states} (excitation {excitation}, fiber velocity: {velocity}{skipped}{over}) -> {args.out} "
          f"({', '.join(sorted({p.name for p in files.values()}))}); {whole} (W/kg, basal {args.basal}): {means}")
    _plausibility(args, {}, results)
    return 0


def _states_cycle(text):
    """``--cycle START,TOE_OFF,END`` of ``metabolics --states``: a :class:`~musclemetab.events.GaitCycle`
    (``None`` without the option)."""
    from ..errors import DataMismatchError, OptionError
    from ..events import GaitCycle

    if text is None:
        return None
    try:
        start, toe_off, end = (float(v) for v in text.split(","))
    except ValueError:
        raise OptionError(f"--cycle must be three times in seconds, START,TOE_OFF,END, not '{text}'") from None
    try:
        return GaitCycle(start, toe_off, end)
    except (DataMismatchError, OptionError) as exc:
        raise OptionError(f"--cycle {text}: {exc}; give START < TOE_OFF < END in seconds") from None


def _write_mat(args, results, folders=None) -> None:
    """``--mat FILE``: the solutions of ``folders`` (``{side: folder}``; none for ``--states``) and
    their rates ``results`` as a MATLAB file (:mod:`musclemetab.io.matlab`)."""
    if args.mat is None:
        return
    from ..io.matlab import write_mat
    from ..metabolics.matlab import results_struct
    from ..redundancy.solution import Solution

    solutions = {side: Solution.load(folder, require_success=False) for side, folder in (folders or {}).items()}
    note(f"MATLAB file {write_mat(args.mat, results_struct(solutions or None, results))}")


def _sensitivity_parameters(value, folders) -> list | None:
    """The parameter names of ``--sensitivity`` (``None`` without it), checked before any work."""
    if value is None:
        return None
    from ..errors import OptionError
    from ..redundancy.sensitivity import PARAMETERS

    if len(folders) != 1:
        raise OptionError("--sensitivity takes one leg's solution folder (e.g. PARENT/r), not the parent of both legs")
    names = list(PARAMETERS) if value.strip().lower() == "all" else [v.strip() for v in value.split(",") if v.strip()]
    bad = [n for n in names if n not in PARAMETERS]
    if bad or not names:
        raise OptionError(f"--sensitivity: unknown muscle parameter(s) {name_list(bad) or repr(value)}; give 'all' or "
                          f"a comma-separated list of {', '.join(PARAMETERS)}")
    # the sensitivities are derivatives at the optimum: a failed solve has none, --allow-failed or not
    from ..io import read_json_object
    from ..io.solution_folder import SUMMARY_FILE

    folder, = folders.values()
    summary = read_json_object(Path(folder) / SUMMARY_FILE, remedy="solve again")
    if not summary.get("success", False):
        raise OptionError(
            f"--sensitivity: the stored solve of {folder} did not succeed (status '{summary.get('status')}'), and "
            "the sensitivities are derivatives at the optimum, which a failed solve has not reached (--allow-failed "
            "lets its rates be computed, not its sensitivities); solve again, or drop --sensitivity"
        )
    from ..redundancy.sensitivity import sensitivity_refusal

    why = sensitivity_refusal(summary)
    if why is not None:  # said before anything is written
        raise OptionError(f"--sensitivity: {folder}: {why}; drop --sensitivity")
    return names


def _write_sensitivity(args, folder, names, models) -> None:
    """``OUT/sensitivity.csv`` of the solution ``folder`` (:mod:`musclemetab.redundancy.sensitivity`)."""
    from ..redundancy.sensitivity import write_folder_sensitivity

    path, sens = write_folder_sensitivity(folder, args.out, names=names, body_mass_kg=args.mass, height_m=args.height,
                                          models=models, basal=args.basal, basal_rate_W_per_kg=args.basal_coefficient,
                                          basal_exponent=args.basal_exponent, muscle_properties=args.muscle_properties)
    pairs = sens.parameters
    top = max(((p, m, mod, float(sens.whole_body[mod][j])) for mod in sens.models
               for j, (p, m) in enumerate(sens.parameters)), key=lambda r: abs(r[3]))
    print(f"sensitivity: {len(pairs)} parameters x {len(sens.models)} models -> {path}; largest: whole-body {top[2]} "
          f"{top[3] / 100:+.3g} W/kg per 1 % of {top[0]} of {top[1]}")


def _plausibility(args, folders, results) -> None:
    """Warn (one line each) of whole-body rates outside the band of walking at ``--speed`` (and of
    the solves' plausibility flags with ``--show-solve-flags``); write them all to
    ``OUT/plausibility.json``; with ``--strict`` fail."""
    from ..metabolics.plausibility import legs_rate_flags, write_plausibility
    from ..quality import check_strict, warn_flags
    from ..redundancy.solution import read_flags

    solve = {folder: read_flags(folder) for folder in folders.values()}
    warn_solve_flags(args, solve)
    flags = [f for found in solve.values() for f in found]
    rates = legs_rate_flags(results, args.speed)
    warn_flags(rates, str(args.out))
    write_plausibility(flags + rates, args.out)
    if args.strict:
        check_strict(flags + rates, "metabolics --strict", written=str(args.out))


def _check_mass(mass_kg: float, model, folder) -> None:
    """The warning of :func:`musclemetab.model.check_body_mass` for ``--mass`` against ``--model``,
    else the model the solution in ``folder`` was solved with (when it is still there)."""
    from ..analysis.unit import recorded_trial
    from ..model import check_body_mass

    model = model or recorded_trial(folder).model
    if model and Path(model).is_file():
        check_body_mass(mass_kg, model)


def _note(differences: list[str], model_path) -> None:
    """Say (on stderr) when the model's parameters differ from those the solve recorded."""
    if differences:
        note(f"{model_path} differs from the solution's recorded parameters "
             f"({'; '.join(differences[:3])}{' ...' if len(differences) > 3 else ''}); using the model's values")
