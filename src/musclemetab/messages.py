"""How the package's warnings reach a person: one line each on standard error.

A warning the command line shows (and one raised in a worker process the package started:
a study's units, the legs of ``solve --side both``) is printed as one line::

    musclemetab: warning: <message>

with the message's white space collapsed; a warning of another library raised while the
package runs names its category (``musclemetab: warning: RuntimeWarning: ...``). No Python
source line and no file path of the package's code is printed: a warning says what was
found in the user's data and what to do, not where in the package it was noticed. In a
Python session the warnings keep Python's own format unless :func:`install` is called.
"""

from __future__ import annotations

import sys
import warnings

__all__ = ["PREFIX", "NAMES_SHOWN", "name_list", "warning_line", "show_warning", "install", "write_quietly"]

#: first words of every warning line
PREFIX = "musclemetab: warning: "
#: names a message lists before it counts the rest (:func:`name_list`)
NAMES_SHOWN = 10


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
    """A replacement for :func:`warnings.showwarning` printing :func:`warning_line`."""
    write_quietly(file if file is not None else sys.stderr, warning_line(message, category) + "\n")


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
    """Print every warning of this process as one line (:func:`show_warning`); returns the
    function restoring the previous ``warnings.showwarning``."""
    previous = warnings.showwarning
    warnings.showwarning = show_warning

    def restore():
        warnings.showwarning = previous

    return restore
