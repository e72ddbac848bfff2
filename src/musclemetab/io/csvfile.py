"""The CSV tables the package wrote, read back whole or refused."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import InputFileError

__all__ = ["read_csv_file"]


def read_csv_file(path: str | os.PathLike, remedy: str, what: str = "table", **kwargs):
    """Read a CSV table the package wrote (``kwargs``: those of :func:`pandas.read_csv`).

    Raises :class:`InputFileError` naming the file and saying what to do (``remedy``) when it
    cannot be parsed, or when it is cut short: every table the package writes ends with a
    newline, so a last line without one is a file whose writing stopped part-way (a full disk,
    a copy cut short), whose last row pandas would otherwise fill with empty values. A file
    cut at the end of a line shows as fewer rows; callers that know how many rows to expect
    check that.
    """
    import pandas as pd

    path = Path(path)
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            size = f.tell()
            if size:
                f.seek(size - 1)
                last = f.read(1)
    except OSError as exc:
        raise InputFileError(f"{path}: cannot be read ({exc.strerror or exc}); {remedy}") from None
    if size and last not in (b"\n", b"\r"):
        raise InputFileError(f"{path}: cut short (its last line is incomplete); {remedy}")
    try:
        return pd.read_csv(path, **kwargs)
    except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise InputFileError(f"{path}: not a readable {what} ({exc}); {remedy}") from None
