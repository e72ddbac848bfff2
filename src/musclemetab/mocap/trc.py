"""OpenSim's marker files (``.trc``): read into metres, write in metres.

A TRC file is taken to be in OpenSim's frame already (y up), as OpenSim's tools read it; its
``Units`` (``mm``, ``cm``, ``m``) are honoured. A missing marker is an empty field (or ``NaN``)
and becomes NaN; it is written as an empty field, as OpenSim's ``TRCFileAdapter`` reads it.
"""

from __future__ import annotations

import io
import math
import os
from pathlib import Path

import numpy as np

from ..errors import InputFileError
from ..io import atomic_write_text
from .c3d import LENGTH_UNITS
from .trial import Markers

__all__ = ["read_trc", "write_trc"]


def read_trc(path: str | os.PathLike) -> Markers:
    """The markers of a ``.trc`` file, in metres.

    Raises :class:`InputFileError` naming the file and line for a file that is missing or does not
    follow the format.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: no such marker file; check the path")
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError as exc:
        raise InputFileError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if len(lines) < 6 or not lines[0].startswith("PathFileType"):
        raise InputFileError(f"{path}: not a TRC marker file (the first line must start with 'PathFileType')")
    keys, values = lines[1].split("\t"), lines[2].split("\t")
    header = {k.strip(): v.strip() for k, v in zip(keys, values)}
    unit = header.get("Units", "mm").lower()
    if unit not in LENGTH_UNITS:
        raise InputFileError(f"{path}: Units '{header.get('Units')}' is not one of {', '.join(LENGTH_UNITS)}")
    fields = lines[3].split("\t")
    if len(fields) < 3 or fields[0].strip() != "Frame#":
        raise InputFileError(f"{path}: line 4 must name the markers after 'Frame#' and 'Time'")
    names = [f.strip() for f in fields[2:] if f.strip()]
    if not names:
        raise InputFileError(f"{path}: names no marker on line 4")
    rows = []
    for n, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        parts = line.rstrip("\r\n").split("\t")
        vals = np.full(2 + 3 * len(names), np.nan)
        try:
            for i, p in enumerate(parts[: len(vals)]):
                p = p.strip()
                if p:
                    vals[i] = float(p)
        except ValueError:
            raise InputFileError(f"{path}: line {n} holds a value that is not a number ({line[:60]}...)") from None
        if not math.isfinite(vals[1]):
            raise InputFileError(f"{path}: line {n} has no time")
        rows.append(vals)
    if not rows:
        raise InputFileError(f"{path}: holds no frame")
    data = np.vstack(rows)
    time = data[:, 1]
    if np.any(np.diff(time) <= 0):
        raise InputFileError(f"{path}: the times are not increasing")
    xyz = data[:, 2:].reshape(len(time), len(names), 3) * LENGTH_UNITS[unit]
    try:
        rate = float(header.get("DataRate", "")) or None
    except ValueError:
        rate = None
    return Markers(time=time, names=names, xyz=xyz, data_rate_hz=rate)


def write_trc(path: str | os.PathLike, markers: Markers) -> Path:
    """Write ``markers`` as a TRC file in metres (atomically)."""
    path = Path(path)
    n, m = len(markers.time), len(markers.names)
    rate = markers.rate_hz
    buf = io.StringIO()
    buf.write(f"PathFileType\t4\t(X/Y/Z)\t{path.name}\n")
    buf.write("DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n")
    buf.write(f"{rate:.6g}\t{rate:.6g}\t{n}\t{m}\tm\t{rate:.6g}\t1\t{n}\n")
    buf.write("Frame#\tTime\t" + "".join(f"{name}\t\t\t" for name in markers.names).rstrip("\t") + "\n")
    buf.write("\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(m)) + "\n\n")
    flat = markers.xyz.reshape(n, 3 * m)
    for i in range(n):
        vals = "\t".join("NaN" if not math.isfinite(v) else f"{v:.6f}" for v in flat[i])
        buf.write(f"{i + 1}\t{markers.time[i]:.10g}\t{vals}\n")
    atomic_write_text(path, buf.getvalue())
    return path
