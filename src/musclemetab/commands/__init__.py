"""The ``musclemetab`` command line: one module per command, argparse only.

Each command module adds its parser (``add_parser``) and runs the command (``run``) by calling
the library; it holds no method of its own, so that everything a command does can be done from
Python as well. Nothing in the library imports this package. Options several commands share
(the basal heat, the study runs) are in :mod:`.options`.

Every error, a usage error included, is printed as one line (``musclemetab: error: ...``) and
the command exits with status 1; Ctrl-C exits with status 130. Every warning is printed as one
line, ``musclemetab: warning: ...``, without a Python source line (:mod:`musclemetab.messages`;
the package's worker processes print theirs the same way). When the reader of the output goes
away early (``musclemetab report DIR | head -1``), the command stops quietly, without a
traceback, with status 141 (128 + SIGPIPE, what a shell reports for a Unix tool stopped that way).
"""

from __future__ import annotations

import argparse
import gc
import importlib
import os
import sys
import warnings

from ..errors import MusclemetabError

__all__ = ["main", "build_parser", "SUBCOMMANDS", "BROKEN_PIPE_STATUS"]

#: The commands: (name, module, function adding its parser). A module is imported only when its
#: command is run (or the full help is asked for), which keeps the start of a command short.
SUBCOMMANDS = (
    ("c3d", "musclemetab.commands.c3d", "add_parser"),
    ("prepare", "musclemetab.commands.prepare", "add_parser"),
    ("geometry", "musclemetab.commands.geometry", "add_parser"),
    ("solve", "musclemetab.commands.solve", "add_parser"),
    ("estimate", "musclemetab.commands.estimate", "add_parser"),
    ("metabolics", "musclemetab.commands.metabolics", "add_parser"),
    ("analyse", "musclemetab.commands.analyse", "add_parser"),
    ("calibrate-passive", "musclemetab.commands.calibrate_passive", "add_parser"),
    ("run", "musclemetab.commands.run", "add_parser"),
    ("demo", "musclemetab.commands.demo", "add_parser"),
    ("report", "musclemetab.commands.report", "add_parser"),
)


class _Parser(argparse.ArgumentParser):
    """argparse with the package's error convention: one line, exit status 1."""

    def error(self, message):  # noqa: D401 - argparse's hook
        msg = " ".join(str(message).split())
        sys.stderr.write(f"musclemetab: error: {msg}; see '{self.prog} --help'\n")
        sys.exit(1)


class _Version(argparse.Action):
    """``--version``: the package's version, read only when asked for."""

    def __call__(self, parser, namespace, values, option_string=None):
        from .. import __version__

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
    names = {name for name, _, _ in SUBCOMMANDS}
    for name, module, func in SUBCOMMANDS:
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
            status = _main(argv)
        finally:  # write out what is buffered while a closed pipe can still be caught here
            sys.stdout.flush()
    except BrokenPipeError:
        _silence_stdout()
        return BROKEN_PIPE_STATUS
    finally:
        if argv is None:
            gc.freeze()
    if argv is None and status == INTERRUPTED_STATUS:
        _end_interrupted()
    return status


#: Exit status after Ctrl-C (128 + SIGINT).
INTERRUPTED_STATUS = 130


def _caused_by_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` was raised while a KeyboardInterrupt was being handled (its cause or
    context, at any depth): an error that Ctrl-C turned into another (e.g. the ImportError of
    a compiled module whose import the interrupt stopped)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, KeyboardInterrupt):
            return True
        exc = exc.__cause__ or exc.__context__
    return False


def _end_interrupted() -> None:
    """End the program after Ctrl-C with status 130, Ctrl-C ignored from here on.

    The interpreter is ended here rather than by returning: a KeyboardInterrupt that ran
    through an import (SciPy's modules import each other while the signal comes) can leave the
    interpreter marked as stopped by an unhandled interrupt, and it then ends itself by SIGINT
    (status -2 to the caller) although the interrupt was handled. The exit functions run and
    the output is flushed first, as at a normal exit.
    """
    import atexit
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(INTERRUPTED_STATUS)


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
    from ..messages import show_warning

    previous, warnings.showwarning = warnings.showwarning, show_warning
    try:
        with warnings.catch_warnings():
            warnings.showwarning = show_warning
            from .options import check_exclusive, check_number_options

            check_number_options(args)  # every command's numeric options, by the table of the study file
            check_exclusive(args)
            return int(args.func(args) or 0)
    except MusclemetabError as exc:
        msg = " ".join(str(exc).split())
        print(f"musclemetab: error: {msg}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # pragma: no cover
        print("musclemetab: interrupted", file=sys.stderr)
        return INTERRUPTED_STATUS
    except Exception as exc:
        if not _caused_by_interrupt(exc):
            raise
        # Ctrl-C during an import of a compiled module comes back as that import's error
        print("musclemetab: interrupted", file=sys.stderr)
        return INTERRUPTED_STATUS
    finally:
        warnings.showwarning = previous
