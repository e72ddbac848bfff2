"""How the package's warnings, notes and progress reach a person: one line each on standard error.

The package logs with the standard :mod:`logging` module, under the logger ``musclemetab``
and its children (``musclemetab.progress`` for the solver's progress lines, the module's
name elsewhere); a library does not configure logging, so in a Python session these records
go where the application sends them (nowhere by default: the package's logger holds a
:class:`logging.NullHandler`). The command line sends them to standard error
(:func:`configure`): ``-q``/``--quiet`` keeps errors only, ``-v``/``--verbose`` adds the
debug records (caches, each solve's outcome). The package's warnings are Python warnings
(categories of :class:`musclemetab.errors.MusclemetabWarning`), so that a script can filter or
turn them into errors; the command line routes them to the logger, and a warning is said once
per run, however many times it was raised.

A warning the command line shows (and one raised in a worker process the package started:
a study's units, the legs of ``solve --side both``) is printed as one line::

    musclemetab: warning: <message>

with the message's white space collapsed; a warning of another library raised while the
package runs names its category (``musclemetab: warning: RuntimeWarning: ...``). No Python
source line and no file path of the package's code is printed: a warning says what was
found in the user's data and what to do, not where in the package it was noticed. In a
Python session the warnings keep Python's own format unless :func:`install` is called, and the
data's warnings (window, diagnosis, reserves, muscle table) name the line of the session's own code
that led to them (:func:`user_stacklevel`), not the package's.
"""

from __future__ import annotations

import logging
import os
import sys
import warnings

__all__ = ["PREFIX", "NAMES_SHOWN", "LOGGER", "LEVEL_ENV", "name_list", "warning_line", "show_warning", "install",
           "user_stacklevel",
           "write_quietly", "logger", "note", "configure", "verbosity_level", "LineHandler", "OncePerRun"]

#: name of the package's logger (its children: ``musclemetab.progress``, ``musclemetab.<module>``)
LOGGER = "musclemetab"
#: environment variable carrying the command line's logging level to the package's worker processes
LEVEL_ENV = "MUSCLEMETAB_LOG_LEVEL"

#: first words of every warning line
PREFIX = "musclemetab: warning: "
#: names a message lists before it counts the rest (:func:`name_list`)
NAMES_SHOWN = 10


_PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__)) + os.sep


def user_stacklevel() -> int:
    """The ``stacklevel`` of :func:`warnings.warn` that names the first caller outside the package,
    for a warning raised by the function that calls this one: a Python session sees the line of
    its own script that led to it, not the package's source (the command line shows no location)."""
    frame, level = sys._getframe(2), 2  # the caller of the function that warns
    while frame.f_back is not None and frame.f_code.co_filename.startswith(_PACKAGE_DIR):
        frame, level = frame.f_back, level + 1
    return level


def name_list(names, shown: int = NAMES_SHOWN, sep: str = ", ") -> str:
    """The names (muscles, columns, channels, keys...) a message lists: the first ``shown``,
    joined by ``sep``, and a count of the others (``a, b, ... and 149 990 more``), so that a
    message stays one readable line however many names the input holds."""
    names = [str(n) for n in names]
    if len(names) <= shown:
        return sep.join(names)
    rest = f"{len(names) - shown:,}".replace(",", " ")
    return f"{sep.join(names[:shown])} ... and {rest} more"


def warning_line(message, category=UserWarning) -> str:
    """The one line of a warning (no trailing newline)."""
    from .errors import MusclemetabWarning

    text = " ".join(str(message).split())
    if not issubclass(category, MusclemetabWarning) and category is not UserWarning:
        text = f"{category.__name__}: {text}"
    return PREFIX + text


def show_warning(message, category, filename=None, lineno=None, file=None, line=None) -> None:
    """A replacement for :func:`warnings.showwarning`: the warning as a record of the package's
    logger at level WARNING (:func:`configure` prints it as :func:`warning_line`); with ``file``,
    the line written to that stream instead."""
    if file is not None:
        write_quietly(file, warning_line(message, category) + "\n")
        return
    logging.getLogger(LOGGER).warning(warning_line(message, category)[len(PREFIX):])


def logger(name: str = "") -> logging.Logger:
    """The package's logger ``musclemetab`` or its child ``musclemetab.<name>``."""
    return logging.getLogger(f"{LOGGER}.{name}" if name else LOGGER)


def note(text: str, name: str = "") -> None:
    """A note to the user (``musclemetab: note: <text>`` on the command line; level INFO)."""
    logger(name).info("note: %s", text)


class LineHandler(logging.Handler):
    """Writes each record as one line to the standard error in force when it is emitted (so that
    a test capturing ``sys.stderr`` sees it), with :func:`write_quietly`: a closed or full
    stream loses the line, never the computation. A record of level INFO reads
    ``musclemetab: <message>``, one of another level names it: ``musclemetab: warning: <message>``
    (``debug``, ``error``); the message's white space is collapsed."""

    def __init__(self, level=logging.NOTSET, stream=None):
        super().__init__(level)
        self.stream = stream

    def format(self, record) -> str:
        text = " ".join(record.getMessage().split())
        if record.levelno == logging.INFO:
            return f"musclemetab: {text}"
        return f"musclemetab: {record.levelname.lower()}: {text}"

    def emit(self, record) -> None:
        try:
            line = self.format(record)
        except Exception:  # a message that cannot be formatted is logging's to report
            self.handleError(record)
            return
        write_quietly(self.stream if self.stream is not None else sys.stderr, line + "\n")


class OncePerRun(logging.Filter):
    """Lets each warning (a record of level WARNING, by its message) through once: a run says a
    warning once however many times its cause is met (a flag of a solve read again by
    ``metabolics``, the same fallback met by each leg)."""

    def __init__(self):
        super().__init__()
        self.seen: set[str] = set()

    def filter(self, record) -> bool:
        if record.levelno != logging.WARNING:
            return True
        key = " ".join(record.getMessage().split())
        if key in self.seen:
            return False
        self.seen.add(key)
        return True


def verbosity_level(quiet: bool = False, verbose: bool = False) -> int:
    """The logging level of ``-q`` (ERROR), ``-v`` (DEBUG) or neither (INFO)."""
    return logging.ERROR if quiet else logging.DEBUG if verbose else logging.INFO


def configure(level: int | None = None) -> callable:
    """Print the package's log records and warnings on standard error, one line each, at
    ``level`` (default: the level in the environment variable :data:`LEVEL_ENV`, else INFO),
    each warning once (:class:`OncePerRun`); the level is put in the environment for the
    worker processes the package starts. Returns the function that undoes it all."""
    log = logging.getLogger(LOGGER)
    if level is None:
        level = int(os.environ.get(LEVEL_ENV) or logging.INFO)
    handler = LineHandler()
    handler.addFilter(OncePerRun())
    before = (log.level, log.propagate, os.environ.get(LEVEL_ENV), warnings.showwarning)
    log.addHandler(handler)
    log.setLevel(level)
    log.propagate = False  # an application's root handlers do not print the lines a second time
    os.environ[LEVEL_ENV] = str(level)
    warnings.showwarning = show_warning

    def restore():
        log.removeHandler(handler)
        log.setLevel(before[0])
        log.propagate = before[1]
        if before[2] is None:
            os.environ.pop(LEVEL_ENV, None)
        else:
            os.environ[LEVEL_ENV] = before[2]
        warnings.showwarning = before[3]

    return restore


def write_quietly(stream, text: str) -> bool:
    """Write ``text`` to ``stream`` and flush it; ``False`` when it could not be written.

    A message is never worth a computation: a stream that is missing (``None``: standard error
    closed, ``2>&-``, or pythonw), closed, full (``2>/dev/full``) or whose reader went away is
    passed over without an exception, so that a progress line or a warning cannot stop a
    solve or a study.
    """
    if stream is None:
        return False
    try:
        stream.write(text)
        stream.flush()
    except (OSError, ValueError):  # full, or the reader went away (OSError); closed (ValueError)
        return False
    return True


def install() -> callable:
    """Print every warning and log record of this process as one line (:func:`configure` at the
    level the command line put in :data:`LEVEL_ENV`: a worker process of the package speaks as
    the command that started it); returns the function that undoes it."""
    return configure()
