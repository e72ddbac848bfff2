"""``musclemetab solve``: the muscle redundancy problem of one trial, or EMG-TEN over several.

::

    musclemetab solve --model M.osim --ik IK.mot --id ID.sto \\
        --workflow effort-gen|effort-cal|effort-ten [--passive FILE] \\
        [--tendon-stiffness soleus_r=10.6,...] [--parameters parameters.json] --out DIR

    musclemetab solve --model M.osim --ik IK.mot --id ID.sto --workflow effort-cal \\
        --energy-model UM10 [--energy-weight 1] [--effort-weight 0] --mass KG [--height M] --out DIR

    musclemetab solve --workflow emg-ten --model M.osim --ik A.mot B.mot C.mot \\
        --id A.sto B.sto C.sto --emg A.mot B.mot C.mot [--emg-mapping default|authors|MAP.json] \\
        [--labels a b c] [--passive FILE] --out DIR

The effort workflows write ``DIR/solution.sto`` and ``DIR/summary.json`` (see
:mod:`.solution`); EMG-TEN writes one such folder per trial (``DIR/<IK file stem>``) and
``DIR/parameters.json`` (estimated tendon stiffness and EMG scale factors, see
:mod:`.emg_ten`), which ``--workflow effort-ten --parameters DIR/parameters.json`` reads. The
muscle geometry comes from :func:`musclemetab.geometry.compute_geometry`, which runs OpenSim in
its own process and caches the result; this process only runs CasADi.

Exit status: 0 on success; 1 on a package error (bad input, or a solve that did not
converge, in which case the folder is still written with ``"success": false`` and IPOPT's
status, for inspection).
"""

from __future__ import annotations

import functools

import argparse

from ..errors import OptionError, SolverError, UnknownMuscleError
from ..messages import name_list
from .options import add_stop_argument, number_option

__all__ = ["add_parser", "add_emg_goal_arguments", "add_emg_processing_argument", "emg_files",
           "add_progress_argument", "run", "run_with_progress",
           "progress_lines"]


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``solve`` subcommand to an ``argparse`` sub-parser collection."""
    p = subparsers.add_parser(
        "solve",
        help="muscle redundancy problem of one trial (effort workflows) or of several (emg-ten)",
        description=(
            "Solve the muscle redundancy problem with compliant tendons (De Groote et al. 2016) for "
            "one trial: muscle excitations, activations, fiber lengths and velocities and tendon forces "
            "that reproduce the inverse-dynamics moments of the five right-leg DOFs with minimal effort. "
            "Workflows: effort-gen (generic passive muscle, kT = 35), effort-cal (calibrated passive "
            "muscle), effort-ten (calibrated passive muscle and personalised triceps-surae and vasti "
            "tendon stiffness). Writes DIR/solution.sto and DIR/summary.json. emg-ten solves several "
            "trials in one problem with EMG tracking and estimates the triceps-surae and vasti tendon "
            "stiffness and EMG scale factors: one solution folder per trial and DIR/parameters.json."
        ),
    )
    p.add_argument("--model", required=True, metavar="M.osim", help="OpenSim model")
    p.add_argument("--ik", required=True, nargs="+", metavar="IK.mot",
                   help="inverse kinematics (defines the time window); emg-ten: one per trial")
    p.add_argument("--id", nargs="+", metavar="ID.sto",
                   help="inverse dynamics with '<dof>_moment' columns in N m; emg-ten: one per trial, same order. "
                   "Without it, --external-loads computes it with OpenSim")
    p.add_argument("--external-loads", metavar="GRF.xml",
                   help="OpenSim ExternalLoads file (its data file beside it): the ground forces for --cycle and, "
                   "without --id, for inverse dynamics computed by OpenSim's InverseDynamicsTool (coordinates "
                   "low-pass filtered at 6 Hz), written to the output folder as inverse_dynamics.sto")
    p.add_argument("--grf", metavar="GRF.mot",
                   help="ground-force file for --cycle when there is no ExternalLoads file (the foot's vertical "
                   "force column is found by the documented name rule of musclemetab.events.read_grf)")
    p.add_argument("--grf-column", metavar="COLUMN",
                   help="with --grf: the solved foot's vertical force column (default: the name rule)")
    number_option(p, "--grf-threshold", "grf_threshold_N", metavar="N",
                  help="with --cycle: contact when the vertical ground force exceeds N newtons (default 20)")
    p.add_argument("--cycle-duration", metavar="MIN:MAX",
                   help="with --cycle: the accepted gait-cycle durations in s (default 0.8:2.0, walking); a cycle "
                   "outside is refused, naming its events")
    p.add_argument("--side", default="r", choices=("r", "l", "both"),
                   help="leg to solve (default r); both: two independent problems written to DIR/r and DIR/l")
    number_option(p, "--workers", "workers", default=1, metavar="N",
                  help="with --side both: solve the two legs in N processes at once (default 1: one after the "
                   "other; the solutions are the same)")
    p.add_argument("--window", metavar="T0:T1",
                   help="time window (s) to solve; must lie inside every input (default: the whole IK file)")
    p.add_argument("--cycle", metavar="auto|N",
                   help="solve a gait cycle of the leg, heel strike to heel strike from the ground forces, padded "
                   "by 0.05 s at each end (clipped at the edge of the data, with a warning): auto = the first "
                   "complete cycle inside every input file, N = the N-th complete cycle")
    p.add_argument("--exclude-muscles", nargs="+", metavar="MUSCLE",
                   help="leave these muscles out of the problem (e.g. a muscle that cannot reach force equilibrium "
                   "within the fiber-length bounds, named by the diagnosis before the solve or by a failed solve); "
                   "in every workflow, with or without EMG (an excluded muscle's EMG is not used)")
    p.add_argument("--diagnose-only", action="store_true",
                   help="diagnose the trials (muscle-tendon lengths the fiber bounds cannot balance, vanishing "
                   "moment arms, moments beyond the muscles; docs/solver.md), print the table and stop: nothing is "
                   "solved or written; exit status 1 when a finding blocks the solve")
    number_option(p, "--mesh-frequency", "mesh_frequency_hz", default=100.0, metavar="PER_S",
                  help="mesh intervals per second (default 100, the study's)")
    p.add_argument("--workflow", default="effort-gen", choices=("effort-gen", "effort-cal", "effort-ten", "emg-ten"),
                   help="workflow preset (default effort-gen)")
    p.add_argument("--emg", nargs="+", metavar="EMG.mot",
                   help="processed, normalised EMG envelopes (or raw EMG with --emg-processing raw), one file per "
                   "trial, same order as --ik: needed by emg-ten; with an effort workflow an EMG-informed solve of "
                   "the trials (see --emg-mode)")
    add_emg_processing_argument(p)
    add_emg_goal_arguments(
        p, "with --emg: 'constrained' (each tracked excitation within --emg-tolerance of its scaled EMG; the "
        "default), 'driven' (equal to its scaled EMG) or 'tracking' (a cost on the difference, weight "
        "--emg-weight); the EMG scale factors are estimated",
        "weight of the EMG tracking cost (default: 10 for emg-ten and tracking, 0 for an effort workflow's "
        "constrained or driven solve)")
    p.add_argument("--emg-mapping", metavar="default|authors|MAP.json",
                   help="emg-ten: EMG channels of the muscles: 'default' (vastus intermedius <- VI_a, the mean of "
                   "VL and VM), 'authors' (vastus intermedius <- ES, as in the published example results) or a "
                   "JSON file {\"muscle\": [\"channel\", ...]} (default: default)")
    p.add_argument("--labels", nargs="+", metavar="NAME",
                   help="emg-ten: trial names, i.e. the output sub-folders (default: the IK file stems)")
    p.add_argument("--fiber-dynamics", choices=("forward", "backward"),
                   help="transcription of the fiber dynamics: 'forward' Euler with the Hill equilibrium at each "
                   "interval's start node (the study's), or 'backward' Euler with it at the end node (default: "
                   "backward with --emg-mode driven, where the forward recurrence is unstable, else forward; "
                   "docs/problem.md)")
    p.add_argument("--passive", metavar="FILE",
                   help="calibrated passive parameters for effort-cal/effort-ten/emg-ten: passive_parameters.csv "
                   "(muscle,kPE,s0,sM) or the study's passiveMoments.mat (default: the published "
                   "calibration shipped with the package)")
    p.add_argument("--tendon-stiffness", metavar="MUSCLE=KT[,...]|example",
                   help="effort-ten: tendon stiffness per muscle, e.g. soleus_r=10.6,vaslat_r=4.7, or 'example' "
                   "for the example subject's estimates (triceps surae 10.617977, vasti 4.695786) "
                   "(default: the subject's --parameters, else the literature Achilles and patellar tendon "
                   "stiffness converted through the model; docs/muscles.md)")
    p.add_argument("--parameters", metavar="parameters.json",
                   help="effort-ten: JSON file with {\"tendon_stiffness\": {muscle: kT}}, e.g. the "
                   "parameters.json written by --workflow emg-ten (or the folder holding it)")
    p.add_argument("--dofs", nargs="+", metavar="DOF",
                   help="degrees of freedom (default: discovered from the model: the unlocked coordinates of "
                   "the leg's joints that the inverse dynamics holds, e.g. ankle_angle_r knee_angle_r "
                   "hip_flexion_r hip_adduction_r hip_rotation_r for the study's model)")
    p.add_argument("--cache-dir", metavar="DIR", help="geometry cache folder (default: the package's)")
    number_option(p, "--max-iter", "max_iter", default=10000, help="IPOPT iteration limit (default 10000)")
    add_stop_argument(p)
    p.add_argument("--linear-solver", default="mumps", metavar="NAME",
                   help="IPOPT's linear solver: mumps (default) or spral (built in), ma27/ma57/ma77/ma86/ma97 (HSL) "
                   "or pardiso (loaded at run time from --linear-solver-library); another solver can end in "
                   "another local optimum")
    p.add_argument("--linear-solver-library", metavar="LIB",
                   help="library IPOPT loads the linear solver from (default libhsl.so for the HSL solvers, "
                   "libpardiso.so for pardiso, on the library search path)")
    number_option(p, "--print-level", "print_level", default=0, help="IPOPT print level (default 0)")
    p.add_argument("--warm-start", metavar="DIR",
                   help="start from the solution in DIR (same trial, e.g. another workflow) with IPOPT's "
                   "barrier parameter at 1e-6: faster, but may end in another local optimum than the "
                   "study's start from static optimisation")
    p.add_argument("--skip-unit-checks", action="store_true",
                   help="do not reject inverse-dynamics moments whose size looks like wrong units")
    p.add_argument("--strict", action="store_true",
                   help="a plausibility flag (over-stretched or saturated muscles, large reserves; one warning line "
                   "each, docs/quality.md) fails the command (exit status 1; the solution is still written)")
    g = p.add_argument_group(
        "energy goal", "effort workflows: minimise the integrated metabolic rate of a smooth energy model "
        "(docs/energy_objective.md), alone (--effort-weight 0) or beside the effort goal")
    g.add_argument("--energy-model", metavar="MODEL",
                   help="smooth metabolic model of the goal: UM03, BH04, HO06, LW07, UM10, UC16, LW05 or MA68")
    number_option(g, "--energy-weight", "weight", metavar="W",
                   help="weight of the goal, the leg's mean metabolic rate in W/kg of body mass (default 1)")
    number_option(g, "--effort-weight", "effort_weight", metavar="W",
                   help="weight of the effort goal on excitations and activations beside it (default: the "
                   "workflow's, 1; 0: energy alone)")
    number_option(g, "--energy-smoothing", "smoothing", metavar="S",
                   help="smoothing parameter of the model's switches (default 0.001; smaller is closer to the exact "
                   "model and slower to solve)")
    g.add_argument("--energy-form", choices=("objective", "model"),
                   help="objective (default): UM03, BH04, HO06 and UC16 with their non-negativity rule on the work "
                   "plus shortening/lengthening heat, so that lengthening muscles pay their activation and "
                   "maintenance heat; model: the rule on the total, as the model defines it (warns)")
    number_option(g, "--mass", "body_mass_kg", metavar="KG", help="body mass (kg), for the muscle masses and the goal's W/kg")
    number_option(g, "--height", "height_m", metavar="M", help="body height (m), for the muscle masses by the "
                  "volume rule (without it: each muscle's mass from the model, F0 / specific tension x density x lMo)")
    g.add_argument("--muscle-properties", metavar="FILE",
                   help="CSV of per-muscle overrides of mass and slow-twitch fraction (docs/muscles.md)")
    a = p.add_argument_group(
        "assistive device", "effort workflows: a device's joint torque taken off the inverse-dynamics moments before the "
        "muscles are solved (docs/assistance.md)")
    a.add_argument("--assistance", metavar="DEVICE.sto",
                   help="device torque profile (.sto/.mot/.csv): a column per coordinate (N m; positive in the "
                   "coordinate's positive direction, as the ID moment), over time (s) or over the gait cycle (%%); the "
                   "muscles supply ID - gain x device")
    number_option(a, "--assistance-gain", "assistance_gain", metavar="G",
                  help="factor on the device torque (default 1)")
    a.add_argument("--assistance-cycle", metavar="T0:T1",
                   help="the gait cycle (s) a profile over the cycle is mapped onto and the device's work is over "
                   "(default: the cycle of --cycle, else the one a study takes: of --grf, else the window less 0.05 s "
                   "at each end with toe-off from the ankle moment)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    add_progress_argument(p, "; with --side both --workers 2 each leg's, 'solving side r: ...'")
    p.set_defaults(func=run_with_progress)
    return p


def add_progress_argument(p, more: str = "") -> None:
    """``--no-progress`` (:func:`progress_lines`)."""
    p.add_argument("--no-progress", action="store_true",
                   help="no progress lines while IPOPT runs (default: one line on stderr at most every 5 s: "
                   f"iteration, objective, constraint violation, time{more})")


def add_emg_processing_argument(p) -> None:
    """``--emg-processing envelope|raw`` and the raw processing's settings (``solve``,
    ``estimate`` and ``emg``)."""
    p.add_argument("--emg-processing", choices=("envelope", "raw"), default="envelope",
                   help="how the --emg files are read: 'envelope' (default) processed, normalised envelopes used as "
                   "stored; 'raw' raw (signed) EMG (a .sto/.mot table, or a C3D file's analog channels), processed "
                   "here: zero-lag band-pass 20-400 Hz, full-wave rectification, zero-lag low-pass 6 Hz, normalised "
                   "to each channel's peak in the file (each step set by the options below)")
    add_raw_emg_arguments(p)


def add_raw_emg_arguments(p) -> None:
    """The settings of the raw EMG processing (:class:`musclemetab.emg.EmgProcessing`)."""
    p.add_argument("--emg-band", metavar="LOW:HIGH", help="raw EMG: the band-pass edges in Hz (default 20:400)")
    from .options import number_option

    number_option(p, "--emg-lowpass", "emg_lowpass_hz", metavar="HZ",
                  help="raw EMG: the envelope's low-pass cut-off (default 6)")
    number_option(p, "--emg-order", "emg_order", metavar="N",
                  help="raw EMG: the effective order of each zero-lag filter (default 4: a 2nd-order design run "
                  "forward and backward)")
    p.add_argument("--emg-maximum", metavar="peak|MAX.csv",
                   help="raw EMG: normalise to each channel's peak in the file (default) or to the maxima of a CSV "
                   "file with columns channel,maximum (e.g. the envelope peaks of maximal voluntary contractions, in "
                   "the raw signal's units)")
    number_option(p, "--emg-delay", "emg_delay_s", metavar="S",
                  help="raw EMG: electromechanical delay added to the EMG's time (s, default 0)")


def raw_emg_processing(args):
    """The :class:`musclemetab.emg.EmgProcessing` of the ``--emg-*`` options, ``None`` when none
    is given; :class:`~musclemetab.errors.OptionError` when they are given for envelopes."""
    from ..emg import EmgProcessing
    from ..errors import OptionError

    given = {k: getattr(args, f"emg_{k}", None) for k in ("band", "lowpass", "order", "maximum", "delay")}
    given = {k: v for k, v in given.items() if v is not None}
    if not given:
        return None
    if getattr(args, "emg_processing", "raw") != "raw":
        raise OptionError(f"{', '.join(f'--emg-{k}' for k in given)} set(s) the processing of raw EMG: add "
                          "--emg-processing raw, or drop them for processed envelopes")
    settings = {}
    if "band" in given:
        low, sep, high = str(given["band"]).partition(":")
        try:
            settings["band_hz"] = (float(low), float(high))
        except ValueError:
            raise OptionError(f"--emg-band '{given['band']}' must be LOW:HIGH in Hz, e.g. 20:400") from None
    if "lowpass" in given:
        settings["lowpass_hz"] = given["lowpass"]
    if "order" in given:
        settings["order"] = given["order"]
    if "delay" in given:
        settings["delay_s"] = given["delay"]
    if "maximum" in given and given["maximum"] != "peak":
        settings["maximum"] = _emg_maxima(given["maximum"])
    return EmgProcessing(**settings)


def _emg_maxima(path) -> dict:
    """``{channel: maximum}`` of a CSV file with columns channel,maximum."""
    import csv
    from pathlib import Path

    from ..errors import InputFileError

    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"--emg-maximum {path}: no such file; give 'peak' or a CSV file of channel,maximum")
    with path.open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    if not rows or not {"channel", "maximum"} <= set(rows[0]):
        raise InputFileError(f"{path}: the EMG maxima need the columns channel,maximum (one row per channel)")
    out = {}
    for i, r in enumerate(rows, start=2):
        try:
            out[r["channel"].strip()] = float(r["maximum"])
        except (TypeError, ValueError):
            raise InputFileError(f"{path}: line {i}: maximum {r['maximum']!r} of channel {r['channel']!r} is not a "
                                 "number") from None
    return out


def emg_files(args) -> list:
    """The ``--emg`` files, each marked with ``--emg-processing`` and the raw processing's
    settings (:func:`musclemetab.emg.emg_source`)."""
    from ..emg import emg_source

    processing = getattr(args, "emg_processing", "envelope")
    settings = raw_emg_processing(args)
    if settings is not None:
        processing = settings
    return [emg_source(p, processing) for p in _as_list(getattr(args, "emg", None))]


def add_emg_goal_arguments(p, mode_help: str, weight_help: str) -> None:
    """``--emg-mode``, ``--emg-tolerance``, ``--emg-weight`` and ``--emg-scale-bounds`` (``solve`` and ``estimate``)."""
    from .options import add_emg_scale_bounds_argument

    from ..redundancy._checks import EMG_MODES

    p.add_argument("--emg-mode", choices=EMG_MODES, help=mode_help)
    number_option(p, "--emg-tolerance", "emg_tolerance", default=0.01,
                  help="with --emg-mode constrained: half-width of the EMG band (default 0.01)")
    number_option(p, "--emg-weight", "emg_weight", help=weight_help)
    add_emg_scale_bounds_argument(p)


def run(args) -> int:
    """Run ``musclemetab solve`` with parsed arguments; returns the exit status.

    Raises a :class:`~musclemetab.errors.MusclemetabError` on bad input and
    :class:`~musclemetab.errors.SolverError` when IPOPT did not converge (after writing the
    folder with ``success: false``). While it runs it holds the lock of the output folder
    (``DIR/.musclemetab.lock``, :class:`~musclemetab.io.atomic.FolderLock`): a second ``solve``
    on the same ``--out`` refuses, naming the lock.
    """
    from ..io import check_output_folder
    from ..io.atomic import FolderLock
    from ..processes import sigint_noted

    check_output_folder(args.out)
    _check_outputs(args)
    with FolderLock(args.out, "output folder"), sigint_noted():  # Ctrl-C raised even if swallowed on its way
        return _solve(args)


def _check_outputs(args) -> None:
    """Refuse (:class:`OptionError` naming the file), before any work, a ``--out`` where a file the
    command writes would replace a folder, or a file the package did not write (or that was
    changed since): the solution folders of the legs, with EMG of the trials, and the
    parameters and personalised model of an EMG-TEN solve."""
    from pathlib import Path

    from ..io.atomic import check_replaceable
    from ..redundancy.emg_inputs import trial_labels
    from ..redundancy.result import PARAMETERS_FILE
    from ..redundancy.run import check_solution_folders

    if getattr(args, "diagnose_only", False):
        return  # writes nothing
    ik = _as_list(args.ik)
    emg_ten, emg = args.workflow == "emg-ten", bool(getattr(args, "emg", None))
    for leg in (("r", "l") if args.side == "both" else ("",)):
        out = Path(args.out) / leg
        if (emg_ten or emg) and (emg_ten or len(ik) > 1):
            labels = trial_labels(ik, args.labels)
            check_replaceable(out, [PARAMETERS_FILE] + ([f"{Path(args.model).stem}_personalised.osim"] if emg_ten
                                                       else []))
            check_solution_folders(out / label for label in labels)
        else:
            check_solution_folders([out])


def _solve(args) -> int:
    from ..redundancy.diagnosis import violation_text
    from ..redundancy.ipopt import failure_advice
    from ..redundancy.run import solve_sides, write_solution_folder
    from ..redundancy.window import parse_cycle, parse_window
    from ..redundancy.workflows import parse_tendon_stiffness

    ik, idf = _as_list(args.ik), _as_list(args.id)
    energy = _energy_goal(args)
    if args.workflow == "emg-ten" or getattr(args, "emg", None):
        if energy is not None:
            raise OptionError("--energy-model works with the effort workflows (effort-gen, effort-cal, effort-ten) "
                              "without --emg; drop it or the EMG")
        if getattr(args, "assistance", None):
            raise OptionError("--assistance works with the effort workflows (effort-gen, effort-cal, effort-ten) "
                              "without --emg; drop it or the EMG")
        return _emg_ten_command(args, ik, idf)
    assistance = _assistance(args)
    extra = [o for o, attr in (("--emg-mapping", "emg_mapping"), ("--labels", "labels"), ("--emg-mode", "emg_mode"),
                               ("--emg-weight", "emg_weight"), ("--emg-scale-bounds", "emg_scale_bounds"))
             if getattr(args, attr, None) is not None]
    if extra:
        raise OptionError(f"{name_list(extra)} need{'s' if len(extra) == 1 else ''} EMG: give --emg files, or "
                          f"drop {'it' if len(extra) == 1 else 'them'}")
    if len(ik) != 1 or len(idf) > 1:
        raise OptionError(
            f"--workflow {args.workflow} solves one trial: give one --ik and one --id file (got {len(ik)} and "
            f"{len(idf)}); solve trials one by one, or use --workflow emg-ten for a multi-trial problem"
        )
    args.ik, args.id = ik[0], (idf[0] if idf else None)
    kt = parse_tendon_stiffness(args.tendon_stiffness) if args.tendon_stiffness else None
    dofs = tuple(d for item in args.dofs for d in item.replace(",", " ").split()) if args.dofs else None
    if args.side == "both" and args.grf_column:
        raise OptionError("--grf-column names one foot's force column; with --side both leave it out (each foot's "
                          "column is found by the name rule) or solve the legs one at a time")
    if args.grf_column and not args.grf:
        raise OptionError("--grf-column names a column of the --grf file; give --grf GRF.mot, or drop it")
    if args.side == "both" and dofs:
        raise OptionError("--dofs names one leg's DOFs; with --side both leave it out (each leg's DOFs are discovered)")
    window = parse_window(args.window) if args.window else None
    cycle = parse_cycle(args.cycle)
    if args.cycle_duration and not args.cycle:
        raise OptionError("--cycle-duration bounds the --cycle found from the events; give --cycle, or drop it")
    cycle_duration = parse_window(args.cycle_duration, "--cycle-duration") if args.cycle_duration else None
    options = _solver_options(args)
    goals = None  # the workflow's
    if energy is not None or args.fiber_dynamics:
        from dataclasses import replace

        from ..redundancy.workflows import get_workflow

        goals = replace(get_workflow(args.workflow).goals, energy=energy, fiber_dynamics=args.fiber_dynamics)
    warm = None
    if args.warm_start:
        from ..redundancy.solution import Solution

        warm = Solution.load(args.warm_start)
    sides = ("r", "l") if args.side == "both" else (args.side,)
    from pathlib import Path

    excluded = _excluded(args)
    # the solution folder gets OpenSim's files of the solution, which the OpenSim worker writes:
    # its start-up (a separate process) and the model work that needs no solution values
    # (prepare_opensim_files, asked for once each leg's problem is known) overlap with the solve
    # instead of following it
    from ..redundancy.export import prepare_opensim_files

    # every leg is solved before anything is written, so bad input on one leg leaves no output
    solutions = solve_sides(
        args.model, args.ik, args.id, args.workflow, sides=sides, workers=args.workers,
        dofs=dofs, window=window, cycle=cycle, external_loads=args.external_loads, grf=args.grf,
        grf_column=args.grf_column, grf_threshold_N=args.grf_threshold,
        **({"cycle_duration_s": cycle_duration} if cycle_duration else {}),
        mesh_frequency_hz=args.mesh_frequency,
        passive=args.passive, tendon_stiffness=kt, tendon_stiffness_file=args.parameters,
        options=options, goals=goals, cache_dir=args.cache_dir, check_units=not args.skip_unit_checks, warm_start=warm,
        exclude_muscles=excluded, exclude_missing_ok=args.side == "both",
        diagnose_only=getattr(args, "diagnose_only", False),
        before_solve=functools.partial(prepare_opensim_files, cache_dir=args.cache_dir), **assistance,
    )
    if getattr(args, "diagnose_only", False):
        return _report_diagnoses(solutions)
    _check_excluded_used(excluded, solutions.values())
    from ..processes import sigint_deferred

    with sigint_deferred():  # Ctrl-C leaves the previous legs' folders or all the new ones
        for side, solution in solutions.items():
            out = Path(args.out) / side if args.side == "both" else Path(args.out)
            write_solution_folder(solution, out, cache_dir=args.cache_dir)
    for side, solution in solutions.items():
        out = Path(args.out) / side if args.side == "both" else Path(args.out)
        s = solution.record
        if not solution.success:
            raise SolverError(
                f"the {args.workflow} solve did not converge (IPOPT status '{s.status}' after "
                f"{s.iterations} iterations): {failure_advice(s.status)}.{violation_text(s)}"
                f"{_bound_note(solution)} The "
                f"unconverged result is in {out} with \"success\": false"
            )
        _print_findings(s)
        worst_reserve = max(s.reserve_rms_Nm.values()) if s.reserve_rms_Nm else 0.0
        print(
            f"solve: {args.workflow} side {side}, {len(solution.muscles)} muscles x {len(solution.dofs)} DOFs, "
            f"N = {s.n_intervals}: {s.status} in {s.iterations} iterations, "
            f"objective {s.objective:.6e}, solve {s.solve_time_s:.2f} s, "
            f"max moment residual {s.max_moment_residual_Nm:.1e} N m, max reserve RMS "
            f"{worst_reserve:.3g} N m{_energy_note(s)}{_device_note(s)} -> {out}"
        )
    _plausibility(args, {str(Path(args.out) / side if args.side == "both" else Path(args.out)): sol
                         for side, sol in solutions.items()})
    return 0


def _assistance(args) -> dict:
    """The ``solve_files`` keywords of ``--assistance``, ``--assistance-gain`` and ``--assistance-cycle``."""
    from ..redundancy.window import parse_window

    path = getattr(args, "assistance", None)
    gain, cycle = getattr(args, "assistance_gain", None), getattr(args, "assistance_cycle", None)
    if path is None:
        given = [o for o, v in (("--assistance-gain", gain), ("--assistance-cycle", cycle)) if v is not None]
        if given:
            raise OptionError(f"{', '.join(given)} belong{'s' if len(given) == 1 else ''} to a device: give "
                              "--assistance DEVICE.sto, or drop them")
        return {}
    from ..redundancy.assistance import check_gain

    out = {"assistance": path, "assistance_gain": check_gain(1.0 if gain is None else gain)}
    if cycle is not None:
        out["assistance_cycle_s"] = parse_window(cycle, "--assistance-cycle")
    return out


def _device_note(record) -> str:
    """``, device +W J / -W J per gait cycle T0-T1 s (its source)`` of an assisted solve's record
    (empty otherwise): the cycle the work is over, and a profile over the cycle mapped onto."""
    device = record.assistance
    if not device:
        return ""
    c0, c1 = device.cycle_s
    mapped = "profile mapped onto and work over" if device.axis == "cycle_pct" else "work over"
    return (f", device (gain {device.gain:g}) {device.positive_work_J:.3g} J positive / "
            f"{device.negative_work_J:.3g} J negative work per cycle ({mapped} the gait cycle {c0:.3f}-{c1:.3f} s: "
            f"{device.cycle_source})")


def _plausibility(args, solutions) -> None:
    """One warning line per plausibility flag of each solution (``{folder: Solution}``); with
    ``--strict`` a flag fails the command."""
    from ..quality import check_strict, warn_flags

    flags = []
    for where, solution in solutions.items():
        warn_flags(solution.record.flags, where)
        flags += solution.record.flags
    if getattr(args, "strict", False):
        check_strict(flags, "solve --strict", written=str(args.out))


_ENERGY_OPTIONS = (("--energy-weight", "energy_weight"), ("--effort-weight", "effort_weight"),
                   ("--energy-smoothing", "energy_smoothing"), ("--mass", "mass"), ("--height", "height"),
                   ("--muscle-properties", "muscle_properties"), ("--energy-form", "energy_form"))


def _energy_goal(args):
    """The :class:`.energy.EnergyGoal` of the command line, or ``None`` without ``--energy-model``."""
    from ..redundancy.energy import ENERGY_SMOOTHING, EnergyGoal

    given = [o for o, attr in _ENERGY_OPTIONS if getattr(args, attr, None) is not None]
    if getattr(args, "energy_model", None) is None:
        if given:
            raise OptionError(f"{', '.join(given)} belong{'s' if len(given) == 1 else ''} to the energy goal: give "
                              "--energy-model MODEL (e.g. UM10), or drop them")
        return None
    if args.mass is None:
        raise OptionError("--energy-model needs the subject's --mass (kg) for the goal's W/kg and the muscle masses "
                          "(with --height by the volume rule, without it from the model's F0 and lMo)")
    if args.muscle_properties is not None:
        from ..properties import read_muscle_properties

        read_muscle_properties(args.muscle_properties)  # checked before any work
    try:
        return EnergyGoal(args.energy_model, 1.0 if args.energy_weight is None else args.energy_weight, args.mass,
                          args.height, effort_weight=args.effort_weight,
                          smoothing=ENERGY_SMOOTHING if args.energy_smoothing is None else args.energy_smoothing,
                          muscle_properties=args.muscle_properties,
                          **({"form": args.energy_form} if getattr(args, "energy_form", None) else {}))
    except OptionError as exc:
        raise OptionError(f"--energy-model: {exc}") from None


def _energy_note(record) -> str:
    goal = record.energy_goal
    if not goal:
        return ""
    return (f", {goal.model} (smooth, one leg, no basal) {goal.leg_mean_W_per_kg:.3f} W/kg of body mass "
            f"(energy weight {goal.weight:g}, effort weight {goal.w_activation:g})")


def _solver_options(args):
    """The ``SolverOptions`` of the command line (the linear solver checked before any work)."""
    from ..redundancy.ipopt import SolverOptions

    try:
        return SolverOptions(max_iter=args.max_iter, print_level=args.print_level, stop=args.stop,
                             linear_solver=args.linear_solver, linear_solver_library=args.linear_solver_library)
    except OptionError as exc:
        raise OptionError(f"--linear-solver: {exc}") from None


def _bound_note(solution) -> str:
    from ..redundancy.solve import muscles_at_fiber_length_bound

    at = muscles_at_fiber_length_bound(solution)
    if not at:
        return ""
    return (f" Fibers at their longest allowed length (1.7 optimal lengths, or their longest rigid-tendon length "
            f"plus 0.05): {name_list(at)}; if the model's tendon slack length is too short for them, leave them out "
            f"with --exclude-muscles {name_list(at, sep=' ')}.")


def _excluded(args) -> list:
    """The muscles of ``--exclude-muscles`` (spaces or commas between them)."""
    return [m for item in (getattr(args, "exclude_muscles", None) or []) for m in item.replace(",", " ").split()]


def _check_excluded_used(excluded, solutions) -> None:
    """:class:`UnknownMuscleError` for an excluded muscle that no leg's problem had."""
    unused = [m for m in excluded if not any(m in (x.record.excluded_muscles or []) for x in solutions)]
    if unused:
        raise UnknownMuscleError(f"--exclude-muscles: {name_list(unused)} is in neither leg's problem; check the names")


def _print_findings(record) -> None:
    """The diagnosis table of a solve that has findings (``summary.json``'s ``diagnosis``)."""
    findings = record.pre_solve_diagnosis
    if findings.findings:
        print(findings.table())


def _report_diagnoses(by_side: dict) -> int:
    """``--diagnose-only``: each leg's (and trial's) diagnosis table; the error of the first
    blocking one (exit status 1), else 0."""
    diagnoses = [(side, d) for side, ds in by_side.items() for d in (ds if isinstance(ds, list) else [ds])]
    for side, d in diagnoses:
        print(f"side {side}: {d.table()}")
    for side, d in diagnoses:
        if d.blocking:
            raise d.error(f"trial {d.trial} (side {side})")
    return 0


def _violations_of(result) -> str:
    """The constraints the last iterate of a multi-trial solve left violated, per trial."""
    from ..redundancy.diagnosis import trials_violation_text

    return trials_violation_text(result.solutions)


def _as_list(value) -> list:
    if value is None:
        return []
    if isinstance(value, (list, tuple)):
        return list(value)
    return [value]


def _emg_ten_command(args, ik: list, idf: list) -> int:
    """``musclemetab solve --workflow emg-ten`` or ``--emg`` with an effort workflow: one NLP over
    all trials, then the files."""
    from dataclasses import replace

    from ..redundancy.emg_ten import EMG_TEN_GOALS, EmgTenSettings, informed_settings
    from ..redundancy.emg_run import emg_mappings_of_legs, solve_emg_ten
    from ..redundancy.ipopt import failure_advice
    from ..redundancy.workflows import parse_tendon_stiffness
    from .options import emg_scale_bounds

    if not idf:
        raise OptionError("EMG problems need --id: one inverse-dynamics file per trial, in the order of --ik")
    wrong = [o for o, v in (("--external-loads", args.external_loads), ("--grf", args.grf),
                            ("--grf-column", args.grf_column), ("--grf-threshold", args.grf_threshold),
                            ("--cycle-duration", getattr(args, "cycle_duration", None)),
                            ("--window", args.window),
                            ("--cycle", args.cycle))
             if v]
    if wrong:
        raise OptionError(f"{name_list(wrong)} are for the single-trial solves without EMG; drop them for "
                          f"{'--workflow emg-ten' if args.workflow == 'emg-ten' else '--emg'}")
    mode = args.emg_mode or "constrained"
    scale_bounds = {"emg_scale_bounds": b} if (b := emg_scale_bounds(args)) is not None else {}
    if args.workflow != "emg-ten":
        if args.parameters or args.warm_start:
            raise OptionError("--parameters and --warm-start cannot be used with an EMG-informed solve; give "
                              "--tendon-stiffness MUSCLE=KT,... instead of --parameters, and drop --warm-start")
        settings = replace(informed_settings(args.workflow, mode, args.emg_tolerance, args.emg_weight,
                                             fiber_dynamics=args.fiber_dynamics), **scale_bounds)
        return _informed_command(args, ik, idf, settings, parse_tendon_stiffness(args.tendon_stiffness)
                                 if args.tendon_stiffness else None)
    goals = replace(EMG_TEN_GOALS, fiber_dynamics=args.fiber_dynamics,
                    **({} if args.emg_weight is None else {"w_emg": args.emg_weight}))
    settings = EmgTenSettings(goals=goals, emg_tolerance=args.emg_tolerance, emg_mode=mode, **scale_bounds)
    wrong = [o for o, v in (("--tendon-stiffness", args.tendon_stiffness), ("--parameters", args.parameters),
                            ("--warm-start", args.warm_start)) if v]
    if wrong:
        raise OptionError(
            f"{name_list(wrong)} cannot be used with --workflow emg-ten (it estimates the tendon stiffness "
            "and starts from static optimisation); drop them"
        )
    emg = emg_files(args)
    if not emg:
        raise OptionError("--workflow emg-ten needs --emg: one processed EMG file per trial, in the order of --ik")
    dofs = tuple(d for item in args.dofs for d in item.replace(",", " ").split()) if args.dofs else None
    options = _solver_options(args)
    legs = emg_mappings_of_legs(args.model, ik[0], args.emg_mapping, args.side, dofs, args.cache_dir)
    # every leg is solved before anything is written
    excluded = _excluded(args)
    results = {side: solve_emg_ten(
        args.model, ik, idf, emg, emg_mapping=mapping, labels=args.labels,
        passive=args.passive, dofs=dofs, side=side, options=options, cache_dir=args.cache_dir,
        check_units=not args.skip_unit_checks, settings=settings,
        exclude_muscles=excluded, exclude_missing_ok=args.side == "both",
        diagnose_only=getattr(args, "diagnose_only", False),
    ) for side, mapping in legs.items()}
    if getattr(args, "diagnose_only", False):
        return _report_diagnoses(results)
    _check_excluded_used(excluded, [s for r in results.values() for s in r.solutions.values()])
    from ..processes import sigint_deferred

    with sigint_deferred():  # Ctrl-C leaves the previous legs' folders or all the new ones
        models = {side: _write_emg_ten(args, result, _leg_out(args, side)) for side, result in results.items()}
    for side, result in results.items():
        _emg_ten_done(args, result, _leg_out(args, side), side, models[side])
    _plausibility(args, {f"{_leg_out(args, side)}/{label}": sol for side, result in results.items()
                         for label, sol in result.solutions.items()})
    return 0


def _leg_out(args, side: str):
    """The output folder of one leg: ``--out``, or ``--out/<side>`` with ``--side both``."""
    from pathlib import Path

    return Path(args.out) / side if args.side == "both" else Path(args.out)


def _write_emg_ten(args, result, out):
    """Write one leg's EMG-TEN result to ``out`` and, when it converged, its personalised model
    (returned; ``None`` otherwise)."""
    from ..redundancy.estimate import write_personalised_model

    result.write(out)
    if not result.success:
        return None
    model_file, _ = write_personalised_model(args.model, result.parameters,
                                             {"tendon_stiffness": list(result.tendon_stiffness)}, out)
    return model_file


def _emg_ten_done(args, result, out, side: str, model_file) -> None:
    """Say what one leg's EMG-TEN solve found (:class:`SolverError` when it did not converge)."""
    from ..redundancy.ipopt import failure_advice

    r = result.record
    if not result.success:
        raise SolverError(
            f"the emg-ten solve did not converge (IPOPT status '{r.status}' after {r.iterations} "
            f"iterations): {failure_advice(r.status)}.{_violations_of(result)} The unconverged result is in "
            f"{out} with \"success\": false"
        )
    for solution in result.solutions.values():
        _print_findings(solution.record)
    groups = []
    for g in result.settings.tendon_groups:
        m = next((x for x in g if x in result.tendon_stiffness), None)
        if m is not None:
            groups.append(f"{'/'.join(x[:-2] if x.endswith(('_r', '_l')) else x for x in g)} "
                          f"kT {result.tendon_stiffness[m]:.4g} (x{result.tendon_scale[m]:.4f})")
    scales = ", ".join(f"{m} {v:.3g}" for m, v in result.emg_scale.items())
    size = r.problem_size
    print(
        f"solve: emg-ten{' side ' + side if args.side == 'both' else ''} "
        f"{len(result.solutions)} trials ({', '.join(result.solutions)}), "
        f"{size['variables']} variables, {size['equality_constraints']} equalities, "
        f"{size['inequality_constraints']} EMG bounds: {r.status} in {r.iterations} iterations, objective "
        f"{r.objective:.6e}, solve {r.solve_time_s:.1f} s, max moment residual "
        f"{r.max_moment_residual_Nm:.1e} N m; {'; '.join(groups)}; EMG scale {scales} -> {out} "
        f"(and {model_file.name})"
    )


def _informed_command(args, ik: list, idf: list, settings, tendon_stiffness) -> int:
    """An effort workflow's EMG-informed solve of one or more trials: one trial is written to
    ``--out`` as a solution folder; several as one folder per trial and ``parameters.json``."""
    from ..redundancy.emg_ten import emg_failure
    from ..redundancy.emg_run import emg_mappings_of_legs, solve_emg_ten
    from ..redundancy.run import write_solution_folder

    emg = emg_files(args)
    dofs = tuple(d for item in args.dofs for d in item.replace(",", " ").split()) if args.dofs else None
    options = _solver_options(args)  # the linear solver checked before any work
    legs = emg_mappings_of_legs(args.model, ik[0], args.emg_mapping, args.side, dofs, args.cache_dir)
    # as for a solve without EMG: the OpenSim worker prepares a solution's model while IPOPT solves.
    # Only for one trial a leg: the worker keeps the last two prepared models, so the trials of a
    # multi-trial solve would push each other out before their files are written (work done twice)
    from ..opensim_bridge import start_in_background
    from ..redundancy.export import prepare_opensim_files

    if len(ik) > 1:  # one trial: prepare_opensim_files starts the worker unless the cache holds its work
        start_in_background()
    ahead = functools.partial(prepare_opensim_files, cache_dir=args.cache_dir) if len(ik) == 1 else None
    results = {side: solve_emg_ten(
        args.model, ik, idf, emg, emg_mapping=mapping, labels=args.labels,
        passive=args.passive, dofs=dofs, side=side,
        options=options,
        cache_dir=args.cache_dir, check_units=not args.skip_unit_checks, settings=settings,
        workflow=args.workflow, tendon_stiffness=tendon_stiffness,
        exclude_muscles=_excluded(args), exclude_missing_ok=args.side == "both",
        diagnose_only=getattr(args, "diagnose_only", False), before_solve=ahead,
    ) for side, mapping in legs.items()}
    if getattr(args, "diagnose_only", False):
        return _report_diagnoses(results)
    _check_excluded_used(_excluded(args), [s for r in results.values() for s in r.solutions.values()])
    from ..processes import sigint_deferred

    with sigint_deferred():  # Ctrl-C leaves the previous legs' folders or all the new ones
        for side, result in results.items():
            if len(result.solutions) == 1:
                write_solution_folder(next(iter(result.solutions.values())), _leg_out(args, side),
                                      cache_dir=args.cache_dir)
            else:
                result.write(_leg_out(args, side))
    for side, result in results.items():
        out = _leg_out(args, side)
        r = result.run_record
        if not r.success:
            err = emg_failure(r, settings.emg_mode, f"the EMG-informed {args.workflow} solve (written to {out})",
                              settings.fiber_scheme)
            raise type(err)(err.message + _violations_of(result))
        for solution in result.solutions.values():
            _print_findings(solution.record)
        scales = ", ".join(f"{m} {v:.3g}" for m, v in result.emg_scale.items())
        leg = f" side {side}" if args.side == "both" else ""
        print(f"solve: {args.workflow} EMG-{settings.emg_mode}{leg} {len(result.solutions)} trial(s): {r.status} in "
              f"{r.iterations} iterations, objective {r.objective:.6e}; EMG scale {scales} -> {out}")
    _plausibility(args, {f"{_leg_out(args, side)}" + (f"/{label}" if len(result.solutions) > 1 else ""): sol
                         for side, result in results.items() for label, sol in result.solutions.items()})
    return 0


def progress_lines(args):
    """IPOPT's progress lines on stderr while the block runs (:class:`~musclemetab.redundancy.ipopt.solve_progress`),
    unless ``--no-progress`` or ``-q`` (a context manager)."""
    import contextlib

    from ..redundancy.ipopt import solve_progress

    off = getattr(args, "no_progress", False) or getattr(args, "quiet", False)
    return contextlib.nullcontext() if off else solve_progress()


def run_with_progress(args) -> int:
    """:func:`run` with IPOPT's progress lines on stderr unless ``--no-progress`` (:func:`progress_lines`)."""
    with progress_lines(args):
        return run(args)
