"""Read and write OpenSim storage files (``.mot`` / ``.sto``).

Two header dialects occur in practice and are both read:

* OpenSim 4 style: a table name, ``version=1``, ``nRows=``, ``nColumns=``,
  ``inDegrees=yes|no``, free comment lines, then ``endheader``;
* legacy SIMM style: a path or name line, ``nRows=``/``nColumns=``, ``name <...>``,
  ``datacolumns N``, ``datarows M``, ``range t0 t1``, then ``endheader``.

The line after ``endheader`` holds the column names (the first is ``time``); the rest are
whitespace-separated numbers. :func:`read_table` parses and checks a file into a
:class:`StorageTable` (NumPy arrays, no pandas: the solver's start-up reads its files this
way); :func:`read_storage` returns the same contents as a pandas DataFrame indexed by time.
Both carry the header metadata in ``attrs``:

``name``        the table name (first header line), or ``None``
``in_degrees``  ``True``/``False`` from ``inDegrees``, ``None`` when the header has none
``path``        the file read
``header``      the header lines, verbatim

Values are returned exactly as stored: no unit conversion happens here (use
:func:`rotational_to_radians` where the caller knows which columns are angles).

**Rounded time stamps.** OpenSim's tools write time with a fixed number of decimals: IK at
60 Hz rounded to the millisecond steps by 16 and 17 ms. A time column whose stamps all lie
within :func:`rounding_tolerance_s` (half a millisecond plus 1 % of the step, at most a
quarter of the step) of the constant rate fitted to them (least squares of time against
sample index, :func:`constant_rate`) is read as that constant rate: :func:`read_table`
replaces the stamps by the fitted ones (the largest change is within the tolerance; stamps
already within :data:`EXACT_TIME_TOLERANCE_S` of it are kept as written). A time column
further from any constant rate is read as it is, and refused (naming the file, the stamp
and its distance) only where a constant rate is needed: the zero-lag filters of the IK, the
inverse dynamics and the EMG.
:func:`write_storage` writes an OpenSim 4 ``.sto`` atomically (temporary file, then rename)
from either kind of table.
"""

from __future__ import annotations

import io as _io
import os
import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pandas is imported where a DataFrame is built
    import pandas as pd

from ..errors import DataMismatchError, MissingColumnError, StorageFormatError, TimeColumnError, TruncatedFileWarning
from ..messages import name_list
from .atomic import atomic_write_text

__all__ = [
    "StorageTable",
    "read_table",
    "as_table",
    "read_storage",
    "write_storage",
    "require_columns",
    "storage_from_arrays",
    "check_time_stamps",
    "table_path",
    "constant_rate",
    "rounding_tolerance_s",
    "MAX_SAMPLE_STEP_S",
    "ROUNDING_S",
    "EXACT_TIME_TOLERANCE_S",
    "SAMPLE_TIME_TOLERANCE_S",
    "check_times_inside",
]

#: A time step this long (a sampling rate of 2 Hz or less) is not a motion recording in
#: seconds: the time column is in milliseconds or counts frames.
MAX_SAMPLE_STEP_S = 0.5
#: Time stamps rounded to the millisecond lie up to half of one from the exact ones.
ROUNDING_S = 0.5e-3
#: Stamps this close (s) to their fitted constant rate are kept as written: the precision of
#: the decimals a file holds (OpenSim writes eight).
EXACT_TIME_TOLERANCE_S = 1e-7


def rounding_tolerance_s(step_s: float) -> float:
    """How far (s) a time stamp may lie from a constant rate of step ``step_s`` and be taken
    as that rate rounded: :data:`ROUNDING_S` plus 1 % of the step (the fitted rate's own
    error), at most a quarter of the step (a stamp further off is a sample out of place)."""
    return min(ROUNDING_S + 0.01 * step_s, 0.25 * step_s)


def _fit_constant_rate(t: np.ndarray) -> tuple[np.ndarray, float, int, float]:
    """``(fitted stamps t0 + k step, step, index of the stamp furthest from them, its
    distance)``: least squares of time against sample index ``k``."""
    k = np.arange(t.size, dtype=float)
    kc = k - k.mean()
    step = float(kc @ (t - t.mean()) / (kc @ kc))
    fitted = t.mean() + step * kc
    far = int(np.argmax(np.abs(t - fitted)))
    return fitted, step, far, float(abs(t[far] - fitted[far]))


def constant_rate(time, what: str = "the file") -> tuple[np.ndarray, float]:
    """``(time stamps, sampling rate in Hz)`` of a signal that must be sampled at a constant rate.

    The rate is the least-squares fit of the stamps against their index. Stamps within
    :func:`rounding_tolerance_s` of it are rounded stamps of that rate: the fitted stamps are
    returned in their place (``time`` itself when it is within
    :data:`EXACT_TIME_TOLERANCE_S`). Raises :class:`DataMismatchError`, its message starting
    with ``what``, for fewer than two stamps and for a stamp further off (a dropped or
    repeated sample, a gap, a changed rate): the zero-lag filters need a constant rate.
    """
    t = np.asarray(time, dtype=float)
    if t.size < 2:
        raise DataMismatchError(f"{what} has {t.size} sample(s); a signal sampled at a constant rate is needed")
    fitted, step, far, off = _fit_constant_rate(t)
    tol = rounding_tolerance_s(step)
    if not step > 0 or off > tol:
        raise DataMismatchError(
            f"{what}: the time stamps are not evenly spaced: t = {t[far]:.6g} s (sample {far + 1}) lies "
            f"{off * 1e3:.3g} ms from the constant rate fitted to them ({1 / step if step > 0 else 0:.6g} Hz), "
            f"and rounding explains at most {tol * 1e3:.3g} ms; the zero-lag filter needs a constant sampling "
            "rate: resample the file"
        )
    return (t if off <= EXACT_TIME_TOLERANCE_S else fitted), 1.0 / step


def _parse_header(lines: list[str], path: Path) -> dict:
    meta: dict = {"name": None, "in_degrees": None, "n_rows": None, "n_columns": None}
    if lines:
        first = lines[0].strip()
        if first and "=" not in first:
            meta["name"] = first
    for raw in lines:
        line = raw.strip()
        low = line.lower()
        key, sep, value = line.partition("=")
        if sep:
            k = key.strip().lower()
            v = value.strip()
            if k == "indegrees":
                if v.lower() not in ("yes", "no"):
                    raise StorageFormatError(
                        f"{path}: header line '{line}' must say inDegrees=yes or inDegrees=no"
                    )
                meta["in_degrees"] = v.lower() == "yes"
            elif k in ("nrows", "ncolumns"):
                try:
                    meta["n_rows" if k == "nrows" else "n_columns"] = int(v)
                except ValueError:
                    raise StorageFormatError(
                        f"{path}: header line '{line}' must give a whole number"
                    ) from None
        elif low.startswith("datarows "):
            try:
                meta["n_rows"] = int(line.split()[1])
            except (IndexError, ValueError):
                raise StorageFormatError(f"{path}: header line '{line}' must give a whole number") from None
        elif low.startswith("datacolumns "):
            try:
                meta["n_columns"] = int(line.split()[1])
            except (IndexError, ValueError):
                raise StorageFormatError(f"{path}: header line '{line}' must give a whole number") from None
        elif low.startswith("name ") and meta["name"] is None:
            meta["name"] = line[5:].strip()
    return meta


class StorageTable:
    """The contents of a storage file as NumPy arrays.

    ``index`` is the time column ``(F,)`` (s), ``columns`` the data column names (``time``
    excluded), ``values`` the data ``(F, C)``, ``attrs`` the header metadata (as for
    :func:`read_storage`). ``table[name]`` is one column ``(F,)``, ``table.to_numpy()`` all of
    them, and :meth:`to_dataframe` the pandas DataFrame :func:`read_storage` returns.
    """

    __slots__ = ("index", "columns", "values", "attrs", "_position")

    def __init__(self, time, columns: Sequence[str], values, attrs: dict | None = None):
        self.index = np.asarray(time, dtype=float)
        self.columns = tuple(columns)
        self.values = np.asarray(values, dtype=float).reshape(self.index.size, len(self.columns))
        self.attrs = dict(attrs or {})
        self._position = {c: j for j, c in enumerate(self.columns)}

    def __len__(self) -> int:
        return self.index.size

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.values[:, self._position[name]]
        except KeyError:
            raise MissingColumnError(f"{self.attrs.get('path', '<table>')}: no column '{name}'") from None

    def to_numpy(self, dtype=float) -> np.ndarray:
        return self.values.astype(dtype, copy=False)

    def to_dataframe(self) -> "pd.DataFrame":
        """A time-indexed DataFrame with the same columns and ``attrs``."""
        import pandas as pd

        df = pd.DataFrame(self.values, columns=list(self.columns), index=pd.Index(self.index, name="time"))
        df.attrs.update(self.attrs)
        return df


def read_storage(path: str | os.PathLike) -> "pd.DataFrame":
    """Read an OpenSim ``.mot``/``.sto`` file into a time-indexed DataFrame.

    The file is parsed and checked by :func:`read_table`; this is its
    :meth:`StorageTable.to_dataframe`.

    Parameters
    ----------
    path
        The storage file.

    Returns
    -------
    pandas.DataFrame
        Index ``time`` (s), one float column per data column, header metadata in ``.attrs``.

    Raises
    ------
    StorageFormatError, TimeColumnError
        As :func:`read_table`.
    """
    return read_table(path).to_dataframe()


def read_table(path: str | os.PathLike) -> StorageTable:
    """Read an OpenSim ``.mot``/``.sto`` file into a :class:`StorageTable` (no pandas).

    Raises
    ------
    StorageFormatError
        The file is missing, has no ``endheader`` line, no column names, non-numeric or
        ragged rows (a row with more or fewer values than there are columns, the message
        naming its line), fewer rows than its header announces, or duplicate column names.
    TimeColumnError
        The first column is not ``time``, holds NaN or infinite values, or is not strictly
        increasing.

    Warns
    -----
    TruncatedFileWarning
        The last data row has no line end (every program that writes these files ends each
        row with one): the file may have been cut inside that row. The row is read; a number
        cut short cannot be told from a whole one, so check the row or write the file again.
    """
    path = Path(path)
    if path.is_dir():
        raise StorageFormatError(f"{path} is a folder, not a file; give the path of the .mot/.sto file in it")
    try:
        text = path.read_text(encoding="utf-8-sig", errors="replace")  # with or without a byte-order mark
    except FileNotFoundError:
        raise StorageFormatError(f"{path}: no such file; check the path") from None
    except OSError as exc:
        raise StorageFormatError(f"{path}: cannot be read ({exc.strerror})") from None

    lines = text.splitlines()
    end = next((i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader"), None)
    if end is None:
        raise StorageFormatError(
            f"{path}: no 'endheader' line; this is not an OpenSim storage file (.mot/.sto)"
        )
    header = lines[:end]
    meta = _parse_header(header, path)

    body_start = end + 1
    while body_start < len(lines) and not lines[body_start].strip():
        body_start += 1
    if body_start >= len(lines):
        raise StorageFormatError(f"{path}: no column-name line after 'endheader'; the file is truncated")
    names = lines[body_start].split()
    if not names:
        raise StorageFormatError(f"{path}: empty column-name line after 'endheader'")
    if names[0].lower() != "time":
        raise TimeColumnError(f"{path}: the first column is '{names[0]}', expected 'time'")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise StorageFormatError(f"{path}: duplicate column names {dup}; each column must be unique")

    # (line number in the file, from 1; text) of each data row: blank lines are skipped
    data_lines = [(i + 1, ln) for i, ln in enumerate(lines[body_start + 1:], start=body_start + 1) if ln.strip()]
    if not data_lines:
        raise StorageFormatError(f"{path}: no data rows after the column names; the file is truncated")
    ncol = len(names)
    values = np.empty((len(data_lines), ncol), dtype=float)
    for r, (line_no, ln) in enumerate(data_lines):
        fields = ln.split()
        if len(fields) != ncol:
            last = ", the last" if r == len(data_lines) - 1 else ""
            raise StorageFormatError(
                f"{path}: data row {r + 1} (line {line_no}{last}) has {len(fields)} values but there are "
                f"{ncol} columns; the file is truncated or malformed: write it again or remove the row"
            )
        try:
            values[r] = [float(x) for x in fields]
        except ValueError:
            bad = next(x for x in fields if not _is_float(x))
            raise StorageFormatError(
                f"{path}: data row {r + 1} (line {line_no}) holds '{bad}', which is not a number"
            ) from None

    n_rows = meta.get("n_rows")
    if n_rows is not None and len(data_lines) < n_rows:
        raise StorageFormatError(
            f"{path}: the header announces {n_rows} rows but only {len(data_lines)} are present; "
            "the file is truncated"
        )
    t = values[:, 0]
    if not np.isfinite(t).all():
        row = int(np.flatnonzero(~np.isfinite(t))[0]) + 1
        raise TimeColumnError(f"{path}: column 'time' is {'NaN' if np.isnan(t[row - 1]) else f'{t[row - 1]:g}'} at data row {row}; every time stamp must "
                              "be a finite number of seconds: fix or remove that row")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        row = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 2
        raise TimeColumnError(
            f"{path}: column 'time' is not strictly increasing (data row {row}, t = {t[row - 1]:g} s)"
        )

    if t.size > 2:  # rounded stamps of a constant rate are read as that rate (module docstring)
        fitted, step, _, off = _fit_constant_rate(t)
        if EXACT_TIME_TOLERANCE_S < off <= rounding_tolerance_s(step):
            t = values[:, 0] = fitted

    if data_lines[-1][0] == len(lines) and text[-1:].splitlines() != [""]:  # no line break after the last row
        warnings.warn(
            f"{path}: the last data row (line {data_lines[-1][0]}, t = {t[-1]:g} s) has no line end; the file may "
            "have been cut inside that row: check its last values, or write the file again",
            TruncatedFileWarning, stacklevel=2,
        )
    return StorageTable(t, names[1:], values[:, 1:],
                        dict(name=meta["name"], in_degrees=meta["in_degrees"], path=str(path), header=list(header)))


def as_table(source: "str | os.PathLike | StorageTable") -> StorageTable:
    """``source`` itself when it is a :class:`StorageTable` already read, else
    :func:`read_table` of that path.

    The stages of a solve take either, so that each input file is read once and the table
    passed on; the file's path stays in ``table.attrs["path"]``.
    """
    return source if isinstance(source, StorageTable) else read_table(source)


def table_path(source: "str | os.PathLike | StorageTable") -> Path:
    """The file behind ``source``: the path itself, or the file a :class:`StorageTable` was read from."""
    return Path(str(source.attrs.get("path", "<table>"))) if isinstance(source, StorageTable) else Path(source)


def check_time_stamps(df: "pd.DataFrame | StorageTable", what: str = "file") -> None:
    """Refuse a time column that cannot be seconds of a motion recording.

    Raises :class:`TimeColumnError` (naming the file) when the median time step is
    :data:`MAX_SAMPLE_STEP_S` or more: the stamps are milliseconds or frame numbers.
    """
    t = np.asarray(df.index, dtype=float)
    if t.size < 2:
        return
    step = float(np.median(np.diff(t)))
    if step >= MAX_SAMPLE_STEP_S:
        raise TimeColumnError(
            f"{df.attrs.get('path', what)}: the time column steps by {step:g} (a sampling rate of {1 / step:.3g} Hz); "
            "time must be in seconds: the values look like milliseconds or frame numbers, convert them to seconds"
        )


def _is_float(x: str) -> bool:
    try:
        float(x)
    except ValueError:
        return False
    return True


def require_columns(
    df: "pd.DataFrame | StorageTable", columns: Iterable[str], *, allow_nan: bool = False, what: str = "column"
) -> None:
    """Raise :class:`MissingColumnError` naming the file and every absent (or NaN) column
    of a DataFrame or a :class:`StorageTable`."""
    source = df.attrs.get("path", "<table>")
    columns = list(columns)
    missing = [c for c in columns if c not in df.columns]
    if missing:
        import difflib

        near = sorted({n for c in missing for n in difflib.get_close_matches(c, list(map(str, df.columns)), n=3)})
        raise MissingColumnError(
            f"{source}: missing {what}{'s' if len(missing) > 1 else ''} {name_list(missing)}; "
            + (f"near names: {', '.join(near)}; " if near else "")
            + f"the file has {', '.join(map(str, df.columns[:12]))}{' ...' if len(df.columns) > 12 else ''}"
        )
    if not allow_nan:
        bad = [c for c in columns if _has_nan(df[c])]
        if bad:
            rows = _nan_rows(df[bad[0]])
            times = np.asarray(df.index)[rows] if rows.size else ()
            at = (f" (at t = {', '.join(f'{t:.4f}' for t in times[:3])}{' ...' if len(times) > 3 else ''} s)"
                  if len(times) and np.issubdtype(np.asarray(times).dtype, np.number) else "")
            raise MissingColumnError(f"{source}: {what} {name_list(bad)} holds NaN values{at}; fill or remove them")


def _nan_rows(column) -> np.ndarray:
    isna = getattr(column, "isna", None)
    mask = np.asarray(isna()) if isna is not None else np.isnan(np.asarray(column, dtype=float))
    return np.flatnonzero(mask)


def _has_nan(column) -> bool:
    isna = getattr(column, "isna", None)  # a pandas Series (any dtype) or a NumPy column
    return bool(isna().any()) if isna is not None else bool(np.isnan(np.asarray(column, dtype=float)).any())


def storage_from_arrays(
    time: Sequence[float] | np.ndarray,
    columns: dict[str, np.ndarray] | None = None,
    *,
    names: Sequence[str] | None = None,
    data: np.ndarray | None = None,
    name: str = "musclemetab",
    in_degrees: bool = False,
) -> "pd.DataFrame":
    """Build a time-indexed DataFrame in the layout :func:`write_storage` expects."""
    import pandas as pd

    time = np.asarray(time, dtype=float)
    if columns is not None:
        df = pd.DataFrame({k: np.asarray(v, dtype=float) for k, v in columns.items()}, index=time)
    else:
        df = pd.DataFrame(np.asarray(data, dtype=float), columns=list(names), index=time)
    df.index.name = "time"
    df.attrs.update(name=name, in_degrees=in_degrees)
    return df


def write_storage(
    path: str | os.PathLike,
    df: "pd.DataFrame | StorageTable",
    *,
    name: str | None = None,
    in_degrees: bool | None = None,
    comments: Sequence[str] = (),
) -> Path:
    """Write a time-indexed DataFrame (or a :class:`StorageTable`) as an OpenSim 4 ``.sto``
    file, atomically.

    The file is first written to a temporary file beside ``path`` and renamed into place,
    so a failure never leaves a half-written file. OpenSim 4.6 reads the result with
    ``opensim.TimeSeriesTable``.
    """
    path = Path(path)
    name = name if name is not None else (df.attrs.get("name") or path.stem)
    if in_degrees is None:
        in_degrees = bool(df.attrs.get("in_degrees") or False)
    values = np.column_stack([np.asarray(df.index, dtype=float), df.to_numpy(dtype=float)])
    buf = _io.StringIO()
    buf.write(f"{name}\nversion=1\nnRows={values.shape[0]}\nnColumns={values.shape[1]}\n")
    buf.write(f"inDegrees={'yes' if in_degrees else 'no'}\n")
    for c in comments:
        buf.write(f"{c}\n")
    buf.write("endheader\n")
    buf.write("\t".join(["time", *map(str, df.columns)]) + "\n")
    # 12 significant digits; a missing value as OpenSim writes it ("NaN": Python's "nan" is the
    # only text of a formatted number that holds "nan")
    row_format = "\t".join(["{:.12g}"] * values.shape[1]) + "\n"
    rows = "".join(row_format.format(*row) for row in values.tolist())
    buf.write(rows.replace("nan", "NaN") if np.isnan(values).any() else rows)
    atomic_write_text(path, buf.getvalue())
    return path


#: Times closer than this (s) are the same sample: files written at different precisions
#: (e.g. 1.5 us apart at the end of a 1 kHz record) cover the same window.
SAMPLE_TIME_TOLERANCE_S = 1e-5


def check_times_inside(window, t_first: float, t_last: float, path, what: str,
                       tol: float = SAMPLE_TIME_TOLERANCE_S, span: str = "the window",
                       remedy: str = "choose a window inside every input file") -> None:
    """Raise :class:`DataMismatchError` unless ``window`` lies inside ``[t_first, t_last]``
    (give or take ``tol``, :data:`SAMPLE_TIME_TOLERANCE_S`).

    The message names the file and by how much it falls short of ``span`` (what the times
    ``window`` are; to the microsecond when the shortfall is under a millisecond), the times they
    share, then ``remedy``.
    """
    t0, t1 = float(window[0]), float(window[1])
    short_start = t_first - t0
    short_end = t1 - t_last
    if short_start > tol or short_end > tol:
        parts = []
        if short_start > tol:
            parts.append(f"starts {_seconds(short_start)} s after {span} start {t0:.3f} s")
        if short_end > tol:
            parts.append(f"ends {_seconds(short_end)} s before {span} end {t1:.3f} s")
        a, b = max(t0, t_first), min(t1, t_last)
        shared = f" (this file and {span} share {a:.3f}-{b:.3f} s)" if b > a else ""
        raise DataMismatchError(
            f"{path}: the {what} ({t_first:.3f}-{t_last:.3f} s) {' and '.join(parts)}{shared}; {remedy}"
        )


def _seconds(x: float) -> str:
    """``x`` with 3 to 6 decimals: as many as it takes to the microsecond."""
    for digits in (3, 4, 5):
        if abs(round(x, digits) - x) < 5e-7:
            return f"{x:.{digits}f}"
    return f"{x:.6f}"
