"""``musclemetab estimate``: muscle-tendon parameters from measured fiber lengths and/or EMG
over trials (EMG: the goals of ``--emg-mode``, the EMG scale factors estimated with the others,
coupled as in EMG-TEN).

Writes ``DIR/<trial>/`` (the solutions with the estimates), ``DIR/parameters.json``,
``DIR/<model>_personalised.osim`` and, with ``--validate``, ``DIR/validation/<trial>/``: the
effort problem re-solved with the estimated parameters. Each converged trial folder, and each
validation folder, also holds the OpenSim files of a solve folder (``model.osim``,
``states.sto``, ``controls.sto``, ``forces.sto``; ``docs/opensim_files.md``). IPOPT's progress
lines go to stderr every 5 s unless ``--no-progress``. Prints the estimates with their doubts
(factors on bounds, standard errors and correlated pairs) and the validation fit
(``docs/problem.md``, "Doubts of the estimates"), then one ``musclemetab: warning:`` line per
plausibility flag of a trial's solution (``docs/quality.md``; each recorded in the trial's
``summary.json``); ``--strict`` makes a flag a failure.
"""

from __future__ import annotations

import argparse

from ..errors import OptionError
from .options import add_stop_argument, number_option

__all__ = ["add_parser", "run", "run_with_progress", "parse_assignments"]


def add_parser(subparsers) -> argparse.ArgumentParser:
    from .solve import add_emg_goal_arguments, add_emg_processing_argument, add_progress_argument

    p = subparsers.add_parser(
        "estimate", help="estimate tendon stiffness, optimal fiber and tendon slack lengths from fiber lengths",
        description="Estimate scale factors of the tendon stiffness, optimal fiber length and tendon slack length "
        "of named muscles over one or more trials, tracking measured fiber lengths (ultrasound), with the "
        "effort goals of a workflow; writes the solutions, parameters.json and <model>_personalised.osim.")
    p.add_argument("--model", required=True, metavar="M.osim")
    p.add_argument("--ik", required=True, nargs="+", metavar="IK.mot", help="one per trial")
    p.add_argument("--id", required=True, nargs="+", metavar="ID.sto", help="one per trial, same order")
    p.add_argument("--ultrasound", nargs="+", metavar="US.mot",
                   help="measured fiber lengths, one file per trial: time in s, one column per muscle in mm")
    p.add_argument("--emg", nargs="+", metavar="EMG.mot",
                   help="processed, normalised EMG envelopes (or raw EMG with --emg-processing raw), one file per "
                   "trial, same order as --ik (with or without --ultrasound; at least one of the two)")
    add_emg_processing_argument(p)
    p.add_argument("--emg-mapping", metavar="default|authors|MAP.json",
                   help="EMG channels of the muscles, as for solve (default: default)")
    add_emg_goal_arguments(
        p, "with --emg: 'constrained' (each tracked excitation within --emg-tolerance of its scaled EMG, plus the "
        "tracking cost; the default), 'driven' (equal to its scaled EMG) or 'tracking' (the cost only)",
        "weight of the EMG tracking cost (default 10; also --weights emg=W)")
    p.add_argument("--estimate", required=True, nargs="+", metavar="KIND=MUSCLE[,MUSCLE...]",
                   help="kinds: tendon_stiffness, optimal_fiber_length, tendon_slack_length")
    p.add_argument("--couple", nargs="+", default=[], metavar="[KIND:]MUSCLE,MUSCLE[,...]",
                   help="muscles sharing one factor of every estimated kind, or with KIND: of that kind alone "
                   "(e.g. tendon_stiffness:soleus_r,gasmed_r; emg_scale:vaslat_r,vasmed_r replaces the EMG-TEN "
                   "groups of the EMG scale factors)")
    p.add_argument("--bounds", nargs="+", default=[], metavar="KIND=LOW:HIGH",
                   help="bounds of the factors (default tendon_stiffness 0.1:2, lengths 0.5:1.5, emg_scale "
                   "0.05:2.5; emg_scale=1:1 takes the EMG as it is)")
    p.add_argument("--weights", metavar="NAME=W[,...]",
                   help="activation, reserve, velocity (default: the workflow's), fiber_length (default 100), "
                   "emg (default 10)")
    p.add_argument("--workflow", default="effort-cal", choices=("effort-gen", "effort-cal", "effort-ten"),
                   help="muscle parameters and effort weights (default effort-cal)")
    p.add_argument("--passive", metavar="FILE", help="calibrated passive parameters (as for solve)")
    p.add_argument("--side", default="r", choices=("r", "l"), help="leg whose muscles are estimated (default r)")
    p.add_argument("--dofs", nargs="+", metavar="DOF",
                   help="degrees of freedom (default: the side's unlocked coordinates that the inverse dynamics "
                   "holds, as for solve)")
    p.add_argument("--labels", nargs="+", metavar="NAME", help="trial names (default: the IK file stems)")
    p.add_argument("--exclude-muscles", nargs="+", metavar="MUSCLE",
                   help="leave these muscles out of every trial's problem (e.g. one the diagnosis before the solve "
                   "names); their EMG and fiber lengths are not used; they cannot be estimated")
    p.add_argument("--validate", action="store_true",
                   help="re-solve each trial with the estimates and the effort goals only (DIR/validation)")
    p.add_argument("--strict", action="store_true",
                   help="a plausibility flag of a trial's solution (over-stretched or saturated muscles, large "
                   "reserves; one warning line each, docs/quality.md) fails the command (exit status 1; the files "
                   "are still written)")
    p.add_argument("--cache-dir", metavar="DIR")
    number_option(p, "--max-iter", "max_iter", default=10000, help="IPOPT iteration limit (default 10000)")
    add_stop_argument(p)
    p.add_argument("--out", required=True, metavar="DIR")
    add_progress_argument(p)
    p.set_defaults(func=run_with_progress)
    return p


def parse_assignments(items, what: str, value=str) -> dict:
    """``["key=value", ...]`` (or one comma-separated string for numbers) as a dict."""
    out = {}
    for item in items:
        key, sep, val = item.partition("=")
        if not sep or not key.strip() or not val.strip():
            raise OptionError(f"{what}: '{item}' is not NAME=VALUE")
        try:
            out[key.strip()] = value(val.strip())
        except ValueError:
            raise OptionError(f"{what}: the value of '{key.strip()}' ({val.strip()!r}) is not valid") from None
    return out


def _bounds(text: str) -> tuple[float, float]:
    lo, sep, hi = text.partition(":")
    if not sep:
        raise ValueError(text)
    return float(lo), float(hi)


def run(args) -> int:
    """Run ``musclemetab estimate`` with parsed arguments: the options read, then
    :func:`~musclemetab.redundancy.estimate_run.estimate_files`; prints one line, then one per doubt
    of the estimate and per validated trial and kind of measurement (:func:`doubt_lines`).

    While it runs it holds the lock of the output folder (``DIR/.musclemetab.lock``,
    :class:`~musclemetab.io.atomic.FolderLock`), as ``solve`` does: a second run on the same
    ``--out`` refuses, naming the lock and the process."""
    from ..io import check_output_folder
    from ..io.atomic import FolderLock

    from ..processes import sigint_noted

    check_output_folder(args.out)
    with FolderLock(args.out, "output folder"), sigint_noted():  # Ctrl-C raised even if swallowed on its way
        return _estimate(args)


def _estimate(args) -> int:
    from ..redundancy.estimate import parse_coupling
    from ..redundancy.estimate_run import estimate_files
    from .options import emg_scale_bounds
    from .solve import emg_files as marked_emg_files

    us_files, emg_files = args.ultrasound or [], marked_emg_files(args)
    emg_options = [o for o, v in (("--emg-mapping", args.emg_mapping), ("--emg-mode", args.emg_mode),
                                  ("--emg-weight", args.emg_weight), ("--emg-scale-bounds", args.emg_scale_bounds))
                   if v is not None]
    if emg_options and not emg_files:
        raise OptionError(f"{', '.join(emg_options)} need EMG: give --emg files, or drop them")
    weights = parse_assignments(args.weights.split(",") if args.weights else [], "--weights", float)
    if args.emg_weight is not None:
        weights["emg"] = args.emg_weight
    bounds = parse_assignments(args.bounds, "--bounds", _bounds)
    scale_bounds = emg_scale_bounds(args)
    if scale_bounds is not None:
        if "emg_scale" in bounds:
            raise OptionError("--emg-scale-bounds and --bounds emg_scale=... both set the EMG scale bounds; give one")
        bounds["emg_scale"] = scale_bounds
    from ..redundancy.ipopt import SolverOptions

    result = estimate_files(
        args.model, args.ik, args.id, args.out,
        estimate=parse_assignments(args.estimate, "--estimate", lambda v: [m for m in v.split(",") if m]),
        ultrasound=us_files, emg=emg_files, labels=args.labels,
        couple=[parse_coupling(g) for g in args.couple],
        bounds=bounds, weights=weights, workflow=args.workflow,
        side=args.side, dofs=args.dofs, emg_mode=args.emg_mode, emg_mapping=args.emg_mapping,
        emg_tolerance=args.emg_tolerance, passive=args.passive, validate=args.validate,
        options=SolverOptions(max_iter=args.max_iter, stop=args.stop),
        cache_dir=args.cache_dir,
        exclude_muscles=[m for item in (args.exclude_muscles or []) for m in item.replace(",", " ").split()],
    )
    _write_opensim_files(args, result.labels)
    values = ", ".join(f"{k} {m} x{v:.4f}" for k, by in result.factors.items() if k != "emg_scale"
                       for m, v in by.items())
    if result.emg_scale:
        values += "; EMG scale " + ", ".join(f"{m} {v:.3g}" for m, v in result.emg_scale.items())
    record = result.run_record
    for solution in result.solutions.values():
        if solution.record.pre_solve_diagnosis.findings:
            print(solution.record.pre_solve_diagnosis.table())
    print(f"estimate: {len(result.labels)} trial(s), {record.status} in {record.iterations} iterations; {values} -> "
          f"{args.out}")
    for line in doubt_lines(result.document or {}):
        print(line)
    _plausibility(args, result)
    return 0


def _plausibility(args, result) -> None:
    """One warning line per plausibility flag of each trial's solution (recorded in its
    ``summary.json``) and, with ``--validate``, of each validation re-solve; with ``--strict``
    a flag fails the command."""
    from pathlib import Path

    from ..quality import check_strict, warn_flags
    from ..redundancy.solution import SUMMARY_FILE, read_flags

    flags = []
    for label, solution in result.solutions.items():
        warn_flags(solution.record.flags, str(Path(args.out) / label))
        flags += solution.record.flags
        check = Path(args.out) / "validation" / label
        if args.validate and (check / SUMMARY_FILE).is_file():
            found = read_flags(check)
            warn_flags(found, str(check))
            flags += found
    if args.strict:
        check_strict(flags, "estimate --strict", written=str(args.out))


def _write_opensim_files(args, labels) -> None:
    """The OpenSim files of every trial's solution folder and of its validation re-solve
    (``model.osim``, ``states.sto``, ``controls.sto``, ``forces.sto``, as a solve folder has:
    :func:`~musclemetab.redundancy.export.write_opensim_files`, from the trial's IK and ID files)."""
    from pathlib import Path

    from ..redundancy.export import write_opensim_files
    from ..redundancy.solution import SOLUTION_FILE

    for label, ik, idf in zip(labels, args.ik, args.id):
        for folder in (Path(args.out) / label, Path(args.out) / "validation" / label):
            if (folder / SOLUTION_FILE).is_file():
                write_opensim_files(folder, model_path=args.model, ik_path=ik, id_path=idf)


def run_with_progress(args) -> int:
    """:func:`run` with IPOPT's progress lines on stderr unless ``--no-progress``
    (:func:`~musclemetab.commands.solve.progress_lines`)."""
    from .solve import progress_lines

    with progress_lines(args):
        return run(args)


def doubt_lines(doc: dict) -> list[str]:
    """The lines printed about the doubts and the validation fit recorded in ``parameters.json``."""
    doubts, lines = doc.get("doubts") or {}, []
    for b in doubts.get("on_bounds", []):
        lines.append(f"  on its {b['side']} bound: {b['kind']} {b['muscle']} x{b['factor']:.4g} (bound {b['bound']:g})")
    ident = doubts.get("identifiability")
    if ident:
        se = ident["standard_error"]
        bounded = ident.get("on_bound") or {}

        def estimate_text(p):
            if p in bounded:
                b = bounded[p]
                return (f"{p} x{ident['factor'][p]:.4g} (on its {b['side']} bound {b['bound']:g}: one-sided 95 % "
                        + (f"{b['interval'][0]:.4g} ... {b['interval'][1]:.4g})" if b["limit"] is not None
                           else "undetermined)"))
            return f"{p} x{ident['factor'][p]:.4g} +- {se[p]:.2g}" if se[p] is not None else \
                f"{p} x{ident['factor'][p]:.4g} (undetermined)"

        lines.append("  standard errors: " + ", ".join(estimate_text(p) for p in ident["parameters"]))
        for pair in ident["correlated_pairs"]:
            lines.append(f"  correlated: {pair['parameters'][0]} / {pair['parameters'][1]} r {pair['correlation']:+.3f}")
        if ident.get("collinear"):
            lines.append(f"  collinear: condition index {ident['condition_index']:.3g} (above "
                         f"{ident['condition_index_limit']:g})")
        if ident["near_singular"]:
            lines.append(f"  reduced Hessian near singular (reciprocal condition {ident['reduced_hessian_rcond']:.2g})")
    for trial, fit in (doc.get("validation") or {}).items():
        for kind, by_muscle in fit.items():
            unit = "mm" if kind == "fiber_length" else ""
            lines.append(f"  validation {trial} {kind.replace('_', ' ')}: " + ", ".join(
                f"{m} RMS {v['rms_mm' if unit else 'rms']:.3g}{(' ' + unit) if unit else ''} r {v['r']:.2f}"
                for m, v in by_muscle.items()))
    lines += [f"  warning: {w}" for w in doc.get("validation_warnings") or []]
    return lines


