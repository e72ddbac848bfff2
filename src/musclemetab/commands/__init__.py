"""The ``musclemetab`` command line: one module per command, argparse only.

Each command module adds its parser (``add_parser``) and runs the command (``run``) by calling
the library; it holds no method of its own, so that everything a command does can be done from
Python as well. Nothing in the library imports this package. Options several commands share
(the basal heat, the study runs) are in :mod:`.options`.

Every command takes ``-q``/``--quiet`` (nothing printed but errors) and ``-v``/``--verbose``
(debug records too), before or after the command's name: the package logs with :mod:`logging`
(logger ``musclemetab``), and :func:`musclemetab.messages.configure` prints the records and the
package's warnings, each warning once per run.

Every error, a usage error included, is printed as one line (``musclemetab: error: ...``) and
the command exits with status 1; Ctrl-C exits with status 130, SIGTERM (a batch scheduler
stopping the job) stops the work the same way (workers ended, units marked interrupted) with
status 143. Every warning is printed as one
line, ``musclemetab: warning: ...``, without a Python source line (:mod:`musclemetab.messages`;
the package's worker processes print theirs the same way). When the reader of the output goes
away early (``musclemetab report DIR | head -1``), the command stops quietly, without a
traceback, with status 141 (128 + SIGPIPE, what a shell reports for a Unix tool stopped that way).
An output stream that cannot be written otherwise (closed, ``2>&-``; full, ``>/dev/full``) never
stops the computation: the lines are lost, the command runs to its end, and a standard output
that could not be written makes the exit status 1 with one line saying so on standard error
(when that can be written); no traceback.
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
    ("emg", "musclemetab.commands.emg", "add_parser"),
    ("prepare", "musclemetab.commands.prepare", "add_parser"),
    ("geometry", "musclemetab.commands.geometry", "add_parser"),
    ("solve", "musclemetab.commands.solve", "add_parser"),
    ("estimate", "musclemetab.commands.estimate", "add_parser"),
    ("metabolics", "musclemetab.commands.metabolics", "add_parser"),
    ("analyse", "musclemetab.commands.analyse", "add_parser"),
    ("export", "musclemetab.commands.export", "add_parser"),
    ("calibrate-passive", "musclemetab.commands.calibrate_passive", "add_parser"),
    ("run", "musclemetab.commands.run", "add_parser"),
    ("demo", "musclemetab.commands.demo", "add_parser"),
    ("report", "musclemetab.commands.report", "add_parser"),
    ("cache", "musclemetab.commands.cache", "add_parser"),
)


class _Parser(argparse.ArgumentParser):
    """argparse with the package's error convention: one line, exit status 1.

    An option the command does not know is named as such, with the closest option it does know
    (``--modle``: "did you mean --model?", :func:`difflib.get_close_matches`), before any
    required option it hid is said to be missing, and the line points to the command's own
    ``--help``."""

    _args: list = []

    def parse_known_args(self, args=None, namespace=None):
        self._args = list(sys.argv[1:] if args is None else args)  # what this parser (or command) was given
        return super().parse_known_args(args, namespace)

    def _commands(self) -> dict:
        """The commands of this (top-level) parser by name, ``{}`` for a command's parser."""
        actions = self._subparsers._group_actions if self._subparsers is not None else ()
        return next((a.choices for a in actions if isinstance(a.choices, dict)), {})

    def _command_parser(self):
        """The parser of the command named by the arguments (for the top-level parser), or ``None``."""
        return self._commands().get(_command_name(self._args))

    def _unknown_command(self) -> str | None:
        """The line for a first word that names no command (``solv``: "did you mean solve?",
        pointing to that command's ``--help``), or ``None``."""
        import difflib

        commands, name = self._commands(), _command_name(self._args)
        if not commands or name is None or name.startswith("-") or name in commands:
            return None
        close = difflib.get_close_matches(name, list(commands), n=1)
        if close:
            return f"unknown command '{name}' (did you mean {close[0]}?); see '{self.prog} {close[0]} --help'"
        return f"unknown command '{name}' (the commands: {', '.join(commands)}); see '{self.prog} --help'"

    def _unknown_options(self) -> list[str]:
        """Each option given that this parser does not know (nor abbreviates), with the closest it knows."""
        import difflib

        known = [o for o in self._option_string_actions if o.startswith("--")]
        unknown = []
        for token in self._args:
            if token == "--":
                break
            name = token.split("=", 1)[0]
            if (not name.startswith("-") or self._negative_number_matcher.match(name)
                    or name in self._option_string_actions or (name.startswith("--") and any(o.startswith(name) for o in known))):
                continue
            close = difflib.get_close_matches(name, known, n=1)
            unknown.append(f"{name} (did you mean {close[0]}?)" if close else name)
        return unknown

    def error(self, message):  # noqa: D401 - argparse's hook
        command = self._command_parser()
        if command is not None and command is not self:  # an argument the command refused: its parser says so
            command.error(message)
        line = self._unknown_command()
        if line is not None:
            sys.stderr.write(f"musclemetab: error: {line}\n")
            sys.exit(1)
        unknown = self._unknown_options()
        if unknown:
            message = f"unrecognized option{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}"
        msg = " ".join(str(message).split())
        sys.stderr.write(f"musclemetab: error: {msg}; see '{self.prog} --help'\n")
        sys.exit(1)


class _Version(argparse.Action):
    """``--version``: the package's version, read only when asked for."""

    def __call__(self, parser, namespace, values, option_string=None):
        from .. import __version__

        print(f"musclemetab {__version__}")
        parser.exit()


def add_verbosity_arguments(parser, top: bool = False) -> None:
    """``-q``/``--quiet`` and ``-v``/``--verbose``, on the top-level parser (``top``) and on each
    command's: given after the command's name they default to nothing, so that the top-level
    ones given before it are kept."""
    group = parser.add_mutually_exclusive_group()
    default = False if top else argparse.SUPPRESS
    group.add_argument("-q", "--quiet", action="store_true", default=default,
                       help="print nothing but errors (no notes, warnings, progress or summary)")
    group.add_argument("-v", "--verbose", action="store_true", default=default,
                       help="also print debug lines (caches used, each solve's outcome)")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``musclemetab`` parser; with ``command``, only that subcommand (its module alone is
    imported, which keeps the start of a command short)."""
    parser = _Parser(
        prog="musclemetab",
        description="Muscle-by-muscle, moment-by-moment metabolic energy of walking.",
    )
    parser.add_argument("--version", action=_Version, nargs=0, help="show the version and exit")
    add_verbosity_arguments(parser, top=True)
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
        add_verbosity_arguments(sub.choices[name])
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
    _occupy_closed_descriptors()
    real = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = out, _ = _GuardedOutput(sys.stdout, pipe_stops=True), _GuardedOutput(sys.stderr)
    unraisable, sys.unraisablehook = sys.unraisablehook, _interrupt_not_raisable(sys.unraisablehook)
    try:
        try:
            status = _main(argv)
        finally:  # write out what is buffered while a closed pipe can still be caught here
            sys.stdout.flush()
    except BrokenPipeError:
        _silence_stdout()
        return BROKEN_PIPE_STATUS
    finally:
        sys.stdout, sys.stderr = real
        sys.unraisablehook = unraisable
        if argv is None:
            gc.freeze()
    if out.error is not None:
        _silence_stdout()  # what stays buffered is not written again at exit
        _GuardedOutput(sys.stderr).write(
            f"musclemetab: error: standard output could not be written ({out.error}), so the command's "
            "messages are lost; run it again with standard output to a terminal or a file that can be written\n")
        status = status or 1
    if argv is None and status in (INTERRUPTED_STATUS, TERMINATED_STATUS):
        _end_interrupted(status)
    return status


def _interrupt_not_raisable(previous):
    """A :data:`sys.unraisablehook` that drops a :class:`KeyboardInterrupt` Python could not raise
    (Ctrl-C or SIGTERM landing in code Python runs and ignores the errors of, such as the weakref
    callback of an import's module lock: it printed "Exception ignored in ..." and a traceback);
    the handlers in place have noted the interrupt, and the command says it once, its own way.
    Every other unraisable error goes to ``previous``."""
    def hook(unraisable):
        if not isinstance(unraisable.exc_value, KeyboardInterrupt):
            previous(unraisable)
    return hook


#: Exit status after Ctrl-C (128 + SIGINT).
INTERRUPTED_STATUS = 130
#: Exit status after SIGTERM (128 + SIGTERM), which stops a command as Ctrl-C does.
TERMINATED_STATUS = 143


def interrupted_status() -> int:
    """The exit status of a command stopped by Ctrl-C (130) or SIGTERM (143), and its line on
    standard error (``musclemetab: interrupted`` or ``musclemetab: terminated``) printed."""
    from ..processes import terminated

    stopped = terminated()
    print(f"musclemetab: {'terminated' if stopped else 'interrupted'}", file=sys.stderr)
    return TERMINATED_STATUS if stopped else INTERRUPTED_STATUS


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


def _end_interrupted(status: int = INTERRUPTED_STATUS) -> None:
    """End the program after Ctrl-C or SIGTERM with ``status`` (130 or 143), Ctrl-C ignored from here on.

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
    os._exit(status)


class _GuardedOutput:
    """Standard output or error as the commands write to it: a write or flush that fails (the
    stream closed or full) is dropped and its reason kept in :attr:`error`, never raised, so that
    no message stops a computation. With ``pipe_stops`` a reader gone away (``BrokenPipeError``)
    is raised still, which ends the command quietly with status 141 (:func:`main`)."""

    def __init__(self, stream, pipe_stops: bool = False):
        self._stream, self._pipe_stops, self.error = stream, pipe_stops, None

    def _guarded(self, method: str, *args):
        if self._stream is None:
            self.error = self.error or "it is closed"
            return len(args[0]) if args else None
        try:
            return getattr(self._stream, method)(*args)
        except BrokenPipeError:
            if self._pipe_stops:
                raise
            self.error = self.error or "its reader went away"
        except (OSError, ValueError) as exc:  # full (OSError), closed (ValueError)
            self.error = self.error or (exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc))
        return len(args[0]) if args else None

    def write(self, text):
        return self._guarded("write", text)

    def flush(self):
        self._guarded("flush")

    def __getattr__(self, name):  # fileno, isatty, encoding...: the stream's own
        return getattr(self._stream, name)


def _occupy_closed_descriptors() -> None:
    """Open the null device on standard input, output or error when they are closed (``2>&-``),
    so that no file the command opens takes their number and receives what the compiled
    libraries (OpenSim, IPOPT) print to them."""
    for fd in (0, 1, 2):
        try:
            os.fstat(fd)
        except OSError:
            try:
                null = os.open(os.devnull, os.O_RDWR)
                if null != fd:
                    os.dup2(null, fd)
                    os.close(null)
            except OSError:
                pass


def _silence_stdout() -> None:
    """Point standard output at the null device, so that flushing it at exit raises nothing."""
    try:
        fd = os.open(os.devnull, os.O_WRONLY)
        os.dup2(fd, sys.stdout.fileno())
        os.close(fd)
    except (OSError, AttributeError, ValueError):  # no file descriptor (output captured in a test)
        pass


def _command_name(argv: list[str]) -> str | None:
    """The command named in ``argv``: its first word that is not ``-q``/``-v`` (given before it)."""
    words = [a for a in argv if a not in ("-q", "--quiet", "-v", "--verbose")]
    return words[0] if words else None


class _Silent:
    """Standard output under ``--quiet``: what the commands print there is dropped."""

    def write(self, text):
        return len(text)

    def flush(self):
        pass

    def isatty(self):
        return False


def _main(argv: list[str] | None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command_name(argv))
    args = parser.parse_args(argv)
    from ..messages import configure, logger, verbosity_level

    if args.quiet and args.verbose:  # one before the command's name, one after it
        parser.error("argument -v/--verbose: not allowed with argument -q/--quiet")
    stdout = sys.stdout
    if args.quiet:
        sys.stdout = _Silent()
    try:
        with warnings.catch_warnings():
            restore = configure(verbosity_level(args.quiet, args.verbose))
            logger("commands").debug("musclemetab %s (Python %s)", " ".join(argv), sys.version.split()[0])
            from .options import check_exclusive, check_number_options

            check_number_options(args)  # every command's numeric options, by the table of the study file
            check_exclusive(args)
            from ..processes import sigterm_as_sigint

            with sigterm_as_sigint():  # a batch scheduler's SIGTERM stops the work as Ctrl-C does
                return int(args.func(args) or 0)
    except MusclemetabError as exc:
        msg = " ".join(str(exc).split())
        print(f"musclemetab: error: {msg}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # pragma: no cover
        return interrupted_status()
    except Exception as exc:
        if not _caused_by_interrupt(exc):
            raise
        # Ctrl-C during an import of a compiled module comes back as that import's error
        return interrupted_status()
    finally:
        if "restore" in locals():
            restore()
        sys.stdout = stdout
