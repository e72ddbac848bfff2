"""Read a C3D file (markers and force plates) into OpenSim's frame and SI units.

The file is read with ``ezc3d`` (PyPI), which also turns each plate's analog channels into
force and moment in the lab's frame (plate types 1-4, calibration matrix included). OpenSim's
own ``C3DFileAdapter`` is not part of the ``opensim`` wheel. What this module adds:

* units: marker and plate coordinates from the file's units (``mm``, ``cm``, ``m``) to metres,
  moments from ``Nmm`` to N m;
* frame: the lab's vertical axis becomes OpenSim's y and the walking direction its x (a
  rotation by multiples of 90 degrees, ``p_osim = R p_lab``; the third axis follows, z = x cross y).
  The vertical is the file's ``POINT:Y_SCREEN`` axis (the axis a lab's software shows upward),
  else the normal of the plates' surfaces, else the lab's z; the walking direction is the
  horizontal axis along which the markers' mean moves farthest (over 0.5 m), else the file's
  ``POINT:X_SCREEN`` axis, else the lab's x. Both can be given.

:func:`read_c3d_analogs` reads the analog channels that are not force-plate channels (EMG) as a
table of raw signals, in volts when the file says V, mV or uV.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from ..errors import DataMismatchError, InputFileError, MusclemetabWarning, OptionError
from .trial import UP, LabTrial, Markers, Plate

__all__ = ["read_c3d", "read_c3d_analogs", "lab_rotation", "LENGTH_UNITS", "VOLTAGE_UNITS"]

#: metres per unit of length
LENGTH_UNITS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
#: N m per unit of moment
MOMENT_UNITS = {"nmm": 1e-3, "n.mm": 1e-3, "n mm": 1e-3, "nm": 1.0, "n.m": 1.0, "n m": 1.0}
#: the markers' mean must move this far (m) for its direction to be taken as the walking direction
MIN_PROGRESSION_M = 0.5

_AXES = {"x": 0, "y": 1, "z": 2}


def _axis(text: str, option: str) -> np.ndarray:
    t = str(text).strip().lower()
    sign = -1.0 if t.startswith("-") else 1.0
    t = t.lstrip("+-")
    if t not in _AXES:
        raise OptionError(f"{option} '{text}' is not a lab axis; use x, y, z, -x, -y or -z")
    v = np.zeros(3)
    v[_AXES[t]] = sign
    return v


def _param(params: dict, group: str, name: str):
    try:
        return params[group][name]["value"]
    except KeyError:
        return None


def lab_rotation(up: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """The rotation taking lab coordinates to OpenSim's: rows forward, up, forward x up."""
    up, forward = np.asarray(up, float), np.asarray(forward, float)
    if abs(float(up @ forward)) > 1e-9:
        raise OptionError("the walking direction must be horizontal: choose a lab axis other than the vertical")
    return np.vstack([forward, up, np.cross(forward, up)])


def _unit(value, table: dict, path, what: str) -> float:
    key = str(value or "").strip().lower()
    if key not in table:
        raise InputFileError(f"{path}: {what} unit '{value}' is not known ({', '.join(table)}); convert the file")
    return table[key]


def read_c3d(path: str | os.PathLike, *, up: str = "auto", forward: str = "auto") -> LabTrial:
    """Markers and force plates of a C3D file, in OpenSim's frame (y up), metres and newtons.

    Parameters
    ----------
    up, forward
        The lab's vertical axis and walking direction (``"x"``, ``"-y"``, ...); ``"auto"``
        reads them from the file (module docstring).

    Raises
    ------
    InputFileError
        The file is missing, not a C3D file, or uses units not known here.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: no such C3D file; check the path")
    try:
        import ezc3d
    except ImportError:  # pragma: no cover - installed with the package
        raise InputFileError("reading C3D files needs the 'ezc3d' package: pip install ezc3d") from None
    try:
        c3d = ezc3d.c3d(str(path), extract_forceplat_data=True)
    except Exception as exc:
        raise InputFileError(f"{path}: not a readable C3D file ({type(exc).__name__}: {exc})") from None
    params = c3d["parameters"]
    head = c3d["header"]
    rate = float(head["points"]["frame_rate"])
    first = int(head["points"]["first_frame"])
    names = [str(n).strip() for n in (_param(params, "POINT", "LABELS") or [])]
    pts = np.asarray(c3d["data"]["points"], dtype=float)[:3]  # 3 x markers x frames
    n_markers = pts.shape[1]
    names = (names + [f"M{i + 1:03d}" for i in range(len(names), n_markers)])[:n_markers]
    length = _unit((_param(params, "POINT", "UNITS") or ["mm"])[0], LENGTH_UNITS, path, "POINT:UNITS") \
        if n_markers else 1.0
    lab_xyz = np.transpose(pts, (2, 1, 0)) * length  # frames x markers x 3
    time = (first + np.arange(lab_xyz.shape[0])) / rate if rate > 0 else np.zeros(lab_xyz.shape[0])

    plates_raw = []
    for k, fp in enumerate(c3d["data"].get("platform", []) or []):
        pos = _unit(fp["unit_position"], LENGTH_UNITS, path, f"force plate {k + 1} position")
        mom = _unit(fp["unit_moment"], MOMENT_UNITS, path, f"force plate {k + 1} moment")
        corners = np.asarray(fp["corners"], dtype=float).T * pos  # 4 x 3
        plates_raw.append((k + 1, np.asarray(fp["force"], float).T, np.asarray(fp["moment"], float).T * mom,
                           corners))
    a_rate = float(head["analogs"]["frame_rate"] or 0.0)
    n_analog = plates_raw[0][1].shape[0] if plates_raw else 0
    a_time = first / rate + np.arange(n_analog) / a_rate if a_rate > 0 else np.zeros(n_analog)

    up_v = _up_axis(params, plates_raw, path) if up == "auto" else _axis(up, "--lab-up")
    fwd_v = _forward_axis(params, lab_xyz, up_v) if forward == "auto" else _axis(forward, "--lab-forward")
    rot = lab_rotation(up_v, fwd_v)

    plates = []
    for number, force, moment, corners in plates_raw:
        centre = corners.mean(axis=0)
        plates.append(Plate(number=number, time=a_time, force=force @ rot.T, moment=moment @ rot.T,
                            centre=rot @ centre, corners=corners @ rot.T))
    _check_surfaces(plates, path)
    flipped = _orient_forces(plates, path)
    markers = Markers(time=time, names=names, xyz=lab_xyz @ rot.T, data_rate_hz=rate or None)
    notes = {"source": str(path), "marker_rate_hz": rate, "analog_rate_hz": a_rate,
             "marker_units": (_param(params, "POINT", "UNITS") or ["mm"])[0],
             "lab_up": _axis_name(up_v), "lab_forward": _axis_name(fwd_v), "forces_reversed": flipped}
    return LabTrial(path=path, markers=markers, plates=plates, rotation=rot, notes=notes)


def _axis_name(v: np.ndarray) -> str:
    i = int(np.argmax(np.abs(v)))
    return ("-" if v[i] < 0 else "") + "xyz"[i]


def _screen_axis(params, name: str) -> np.ndarray | None:
    value = _param(params, "POINT", name)
    if not value:
        return None
    try:
        return _axis(str(value[0]), name)
    except OptionError:
        return None


def _up_axis(params, plates_raw, path) -> np.ndarray:
    v = _screen_axis(params, "Y_SCREEN")
    if v is not None:
        return v
    for _, force, _, corners in plates_raw:
        normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
        if np.linalg.norm(normal) > 0:
            i = int(np.argmax(np.abs(normal)))
            v = np.zeros(3)
            loaded = force[np.abs(force[:, i]) > 20.0, i]
            v[i] = 1.0 if loaded.size == 0 or loaded.mean() >= 0 else -1.0
            return v
    return np.array([0.0, 0.0, 1.0])


def _forward_axis(params, lab_xyz: np.ndarray, up: np.ndarray) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(lab_xyz, axis=1) if lab_xyz.size else np.zeros((0, 3))
    ok = np.all(np.isfinite(mean), axis=1)
    if ok.sum() > 1:
        move = mean[ok][-1] - mean[ok][0]
        move = move - (move @ up) * up
        i = int(np.argmax(np.abs(move)))
        if abs(move[i]) > MIN_PROGRESSION_M:
            v = np.zeros(3)
            v[i] = np.sign(move[i])
            return v
    v = _screen_axis(params, "X_SCREEN")
    if v is not None and abs(float(v @ up)) < 0.5:
        return v
    for cand in (np.array([1.0, 0, 0]), np.array([0, 1.0, 0])):
        if abs(float(cand @ up)) < 0.5:
            return cand
    return np.array([0.0, 0.0, 1.0])  # pragma: no cover


def _check_surfaces(plates: list[Plate], path) -> None:
    for p in plates:
        heights = p.corners @ UP
        if np.ptp(heights) > 0.01:
            raise DataMismatchError(
                f"{path}: force plate {p.number}'s corners are not level (heights "
                f"{', '.join(f'{h:.3f}' for h in heights)} m); give the lab's vertical axis (--lab-up)"
            )


def _orient_forces(plates: list[Plate], path) -> bool:
    """Make the forces those of the ground on the body (upward while loaded); ``True`` when
    the file's were the body's on the plate and were reversed (with a warning)."""
    total = [p.vertical()[np.abs(p.vertical()) > 50.0] for p in plates]
    loaded = np.concatenate(total) if total else np.zeros(0)
    if loaded.size and np.median(loaded) < 0:
        for p in plates:
            p.force, p.moment = -p.force, -p.moment
        warnings.warn(f"{path}: the force plates' vertical force points down while loaded: read as the force on "
                      "the plates and reversed into the ground's force on the feet", MusclemetabWarning, stacklevel=3)
        return True
    return False


#: volts per unit of an analog channel (EMG amplifiers write V, mV or uV)
VOLTAGE_UNITS = {"v": 1.0, "mv": 1e-3, "uv": 1e-6, "µv": 1e-6, "μv": 1e-6}


def read_c3d_analogs(path: str | os.PathLike, channels=None) -> "pd.DataFrame":
    """The analog channels of a C3D file that are not force-plate channels (EMG, usually), as a
    time-indexed table (s) at the analog rate, one column per channel label.

    Channels whose ``ANALOG:UNITS`` is a voltage (V, mV, uV) are converted to volts; others are
    kept in the file's units (EMG is normalised after processing, so the unit does not change
    the envelope); ``attrs["units"]`` holds each column's unit after conversion. The force
    plates' channels (``FORCE_PLATFORM:CHANNEL``) are left out. ``channels``: labels to keep
    (default all); a label the file lacks raises
    :class:`~musclemetab.errors.MissingColumnError` naming it.

    Raises
    ------
    InputFileError
        The file is missing or unreadable, or has no analog channel besides the plates'.
    """
    import pandas as pd

    from ..errors import MissingColumnError
    from ..messages import name_list

    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: no such C3D file; check the path")
    import ezc3d

    try:
        c3d = ezc3d.c3d(str(path))
    except Exception as exc:
        raise InputFileError(f"{path}: not a readable C3D file ({type(exc).__name__}: {exc})") from None
    params, head = c3d["parameters"], c3d["header"]
    labels = [str(n).strip() for n in (_param(params, "ANALOG", "LABELS") or [])]
    units = [str(u).strip() for u in (_param(params, "ANALOG", "UNITS") or [])]
    units = (units + [""] * len(labels))[:len(labels)]
    data = np.asarray(c3d["data"]["analogs"], dtype=float)
    data = data.reshape(data.shape[-2], data.shape[-1]) if data.size else np.zeros((0, 0))
    plate_channels = np.asarray(_param(params, "FORCE_PLATFORM", "CHANNEL") if "FORCE_PLATFORM" in params else [],
                                dtype=float).ravel()
    on_plates = {int(c) - 1 for c in plate_channels if c > 0}
    keep = [i for i in range(min(len(labels), data.shape[0])) if i not in on_plates]
    if channels is not None:
        by_label = {labels[i]: i for i in keep}
        missing = [c for c in channels if c not in by_label]
        if missing:
            raise MissingColumnError(f"{path}: no analog channel {name_list(missing)} besides the force plates'; the "
                                     f"file has {name_list([labels[i] for i in keep]) or 'none'}")
        keep = [by_label[c] for c in channels]
    if not keep:
        raise InputFileError(f"{path}: no analog channel besides the force plates' (no EMG in this file); give the "
                             "EMG as a .sto/.mot file")
    rate = float(head["analogs"]["frame_rate"] or 0.0)
    first = int(head["points"]["first_frame"])
    point_rate = float(head["points"]["frame_rate"] or 0.0)
    if rate <= 0:
        raise InputFileError(f"{path}: the analog rate is {rate:g} Hz; the file's header is damaged")
    start = first / point_rate if point_rate > 0 else 0.0
    time = start + np.arange(data.shape[1]) / rate
    columns, out_units = {}, {}
    for i in keep:
        scale = VOLTAGE_UNITS.get(units[i].lower())
        columns[labels[i]] = data[i] * (scale if scale is not None else 1.0)
        out_units[labels[i]] = "V" if scale is not None else units[i]
    df = pd.DataFrame(columns, index=pd.Index(time, name="time"))
    df.attrs.update(path=str(path), units=out_units, analog_rate_hz=rate)
    return df
