"""The ``musclemetab`` command.

Thin by design: each subcommand parses its arguments, calls the library and prints what
it wrote. Every error, a usage error included, is printed as one line
(``musclemetab: error: ...``) and the command exits with status 1; Ctrl-C exits with
status 130. The package's warnings are printed as one line each,
``musclemetab: warning: ...``. When the reader of the output goes away early
(``musclemetab report DIR | head -1``), the command stops quietly, without a traceback, with
status 141 (128 + SIGPIPE, what a shell reports for a Unix tool stopped that way).
"""

from __future__ import annotations

import argparse
import gc
import importlib
import os
import sys
import warnings

from .errors import MuscleTableWarning, MusclemetabError

# Subcommands provided by the stages of the method: (name, module, function adding the parser).
_SUBCOMMANDS = (
    ("geometry", "musclemetab.cli", "add_geometry_parser"),
    ("solve", "musclemetab.commands.solve", "add_solve_parser"),
    ("estimate", "musclemetab.commands.estimate", "add_estimate_parser"),
    ("metabolics", "musclemetab.metabolics.cli", "add_metabolics_parser"),
    ("analyse", "musclemetab.analysis.cli", "add_analyse_parser"),
    ("calibrate-passive", "musclemetab.calibration.cli", "add_calibrate_parser"),
    ("run", "musclemetab.study.cli", "add_run_parser"),
    ("demo", "musclemetab.study.cli", "add_demo_parser"),
    ("report", "musclemetab.report.cli", "add_report_parser"),
)


def _dof_list(text: str) -> list[str]:
    return [d for d in text.replace(",", " ").split() if d]


def add_geometry_parser(sub) -> None:
    p = sub.add_parser(
        "geometry",
        help="muscle-tendon lengths and moment arms along an IK motion",
        description=(
            "Compute muscle-tendon lengths and moment arms (m) of the muscles spanning the chosen "
            "DOFs at every frame of an inverse-kinematics motion, with OpenSim. Writes "
            "DIR/muscle_tendon_lengths.sto and DIR/moment_arms_<dof>.sto (one column per muscle). "
            "Results are cached: a second run on the same inputs does no OpenSim work."
        ),
    )
    p.add_argument("--model", required=True, metavar="M.osim", help="OpenSim model")
    p.add_argument("--ik", required=True, metavar="IK.mot", help="inverse kinematics motion")
    p.add_argument(
        "--dofs", nargs="+", metavar="DOF",
        help="coordinates for the moment arms (default: the unlocked coordinates of the --side leg's joints, "
        "from the model)",
    )
    p.add_argument("--side", default="r", choices=("r", "l", "both"),
                   help="leg (default r); both: DIR/r and DIR/l")
    p.add_argument("--muscles", nargs="+", metavar="MUSCLE", help="muscles (default: those spanning the DOFs)")
    p.add_argument(
        "--method", default="velocity", choices=("velocity", "opensim", "finite_difference"),
        help="moment-arm method (default velocity; see the documentation)",
    )
    p.add_argument("--no-cache", action="store_true", help="do not read or write the geometry cache")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.set_defaults(func=geometry_command)


def geometry_command(args) -> int:
    from .geometry import compute_geometry, write_geometry
    from .io import check_output_folder

    check_output_folder(args.out)
    from pathlib import Path

    from .errors import OptionError

    dofs = [d for item in args.dofs for d in _dof_list(item)] if args.dofs else None
    if args.side == "both" and (dofs or args.muscles):
        raise OptionError("--dofs and --muscles name one leg's; with --side both leave them out")
    sides = ("r", "l") if args.side == "both" else (args.side,)
    geoms = {s: compute_geometry(args.model, args.ik, dofs=dofs, side=s, muscles=args.muscles,
                                 use_cache=not args.no_cache, method=args.method) for s in sides}
    for side, geom in geoms.items():
        out = Path(args.out) / side if args.side == "both" else Path(args.out)
        files = write_geometry(geom, out)
        print(
            f"geometry: side {side}, {len(geom.muscles)} muscles x {len(geom.dofs)} DOFs x {len(geom.time)} frames"
            f"{' (cached)' if geom.source.get('cached') else ''} -> {out} ({len(files)} files)"
        )
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse with the package's error convention: one line, exit status 1."""

    def error(self, message):  # noqa: D401 - argparse's hook
        msg = " ".join(str(message).split())
        sys.stderr.write(f"musclemetab: error: {msg}; see '{self.prog} --help'\n")
        sys.exit(1)


def _show_warning(message, category, filename, lineno, file=None, line=None):
    from .errors import MusclemetabWarning

    if issubclass(category, MusclemetabWarning):
        print(f"musclemetab: warning: {' '.join(str(message).split())}", file=file or sys.stderr)
    else:
        print(warnings.formatwarning(message, category, filename, lineno, line).rstrip(), file=file or sys.stderr)


class _Version(argparse.Action):
    """``--version``: the package's version, read only when asked for."""

    def __call__(self, parser, namespace, values, option_string=None):
        from . import __version__

        print(f"musclemetab {__version__}")
        parser.exit()


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``musclemetab`` parser; with ``command``, only that subcommand (its module alone is
    imported, which keeps the start of a command short)."""
    parser = _Parser(
        prog="musclemetab",
        description="Muscle-by-muscle, moment-by-moment metabolic energy of walking.",
    )
    parser.add_argument("--version", action=_Version, nargs=0, help="show the version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    names = {name for name, _, _ in _SUBCOMMANDS}
    for name, module, func in _SUBCOMMANDS:
        if command in names and name != command:
            continue
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as exc:  # a stage not installed in this build
            if exc.name and exc.name.startswith("musclemetab"):
                continue
            raise
        getattr(mod, func)(sub)
    return parser


def _one_line_warnings(default):
    """``warnings.showwarning`` printing package warnings as one line on stderr."""

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, MuscleTableWarning):
            print(f"musclemetab: warning: {' '.join(str(message).split())}", file=sys.stderr)
        else:
            default(message, category, filename, lineno, file, line)

    return show


#: Exit status when standard output is closed before the command is done (128 + SIGPIPE).
BROKEN_PIPE_STATUS = 141


def main(argv: list[str] | None = None) -> int:
    """Run the command line (``argv``: the arguments, default ``sys.argv[1:]``); return the exit status.

    Called without ``argv``, as the ``musclemetab`` program, it is the last thing the process
    does: the objects it made are then frozen out of the garbage collector's final pass over
    every object at exit (the memory returns to the system with the process), which takes
    0.2 s after a report.
    """
    try:
        try:
            return _main(argv)
        finally:  # write out what is buffered while a closed pipe can still be caught here
            sys.stdout.flush()
    except BrokenPipeError:
        _silence_stdout()
        return BROKEN_PIPE_STATUS
    finally:
        if argv is None:
            gc.freeze()


def _silence_stdout() -> None:
    """Point standard output at the null device, so that flushing it at exit raises nothing."""
    try:
        fd = os.open(os.devnull, os.O_WRONLY)
        os.dup2(fd, sys.stdout.fileno())
        os.close(fd)
    except (OSError, AttributeError, ValueError):  # no file descriptor (output captured in a test)
        pass


def _main(argv: list[str] | None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv[0] if argv else None)
    args = parser.parse_args(argv)
    previous, warnings.showwarning = warnings.showwarning, _show_warning
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warnings(warnings.showwarning)
            return int(args.func(args) or 0)
    except MusclemetabError as exc:
        msg = " ".join(str(exc).split())
        print(f"musclemetab: error: {msg}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # pragma: no cover
        print("musclemetab: interrupted", file=sys.stderr)
        return 130
    finally:
        warnings.showwarning = previous


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
