"""Muscle-tendon lengths and moment arms along an inverse-kinematics trajectory.

:func:`compute_geometry` asks OpenSim (in the worker process) for the length of every
selected muscle-tendon unit and its moment arms about the chosen degrees of freedom at
each frame of an IK motion, and caches the result on disk, keyed by the content of the
model file, the motion file, the DOF list, the muscle list and the method: a second call
on the same inputs reads a small ``.npz`` file and does no OpenSim work.

Muscle selection (when ``muscles`` is not given): every model muscle whose moment arm
about at least one of the DOFs exceeds 1e-4 m in magnitude at the first frame, in model
order. For the Rajagopal model and the five right-leg DOFs this gives the 40 right-leg
muscles.

Before any OpenSim work the IK file is checked by :func:`check_kinematics` (the same
check the solver applies): DOF columns present, every value finite, time stamps in
seconds, and angle units that agree with the header. A cache entry is used only if the
SHA-256 of its arrays equals the checksum stored with it and its shape and time stamps
match the IK file and the DOFs asked for; otherwise it is deleted and recomputed, with a
:class:`~musclemetab.errors.CacheWarning`. A cache folder that cannot be used (the cache
path is a file, or cannot be written) gives a warning and the geometry is computed
without the cache.

Moment arms follow OpenSim's convention ``r = -dl/dq`` (a positive moment arm means that
muscle tension produces a positive generalised moment); coupled coordinates (the
Rajagopal knee's ``knee_angle_r_beta``, the patella) move with their independent
coordinate as OpenSim's couplers say. All results in SI units (m).
"""

from __future__ import annotations

import json
import math
import os
import time as _time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .cache import default_cache_dir, discard_entry, entry_path, existing_entry, read_entry, write_entry
from .io.atomic import file_sha256
from .errors import DataMismatchError, OptionError, UnknownCoordinateError
from .io import StorageTable, as_table, table_path, write_storage
from .model import default_dofs

__all__ = ["Geometry", "compute_geometry", "geometry_is_cached", "default_cache_dir", "write_geometry", "check_kinematics",
           "GEOMETRY_FORMAT"]

GEOMETRY_FORMAT = 4  # bump when the cached content changes meaning (4: locked coordinates follow the IK)
#: Rotations in radians beyond this are not joint angles (model ranges are below pi).
MAX_PLAUSIBLE_ANGLE_RAD = math.pi
#: With ``inDegrees=yes``, DOF angles all below this many "degrees" while the joints move
#: (range above :data:`MIN_MOTION_RANGE`) are radians mislabelled as degrees.
MIN_PEAK_ANGLE_DEG = 2.5
MIN_MOTION_RANGE = 0.05
MOMENT_ARM_METHODS = ("velocity", "opensim", "finite_difference")


@dataclass(frozen=True)
class Geometry:
    """Muscle-tendon geometry along a trajectory.

    Attributes
    ----------
    time : (F,) s
    muscles : muscle names (M), model order
    dofs : DOF names (D)
    lmt_m : (F, M) muscle-tendon length, m
    moment_arms_m : (F, D, M) moment arms, m
    source : a description of where the numbers came from (model, motion, method)
    """

    time: np.ndarray
    muscles: tuple[str, ...]
    dofs: tuple[str, ...]
    lmt_m: np.ndarray
    moment_arms_m: np.ndarray
    source: dict

    def moment_arm(self, dof: str) -> np.ndarray:
        """(F, M) moment arms about one DOF."""
        if dof not in self.dofs:
            raise UnknownCoordinateError(f"no moment arms about '{dof}'; computed for {', '.join(self.dofs)}")
        return self.moment_arms_m[:, self.dofs.index(dof), :]

    def subset(self, muscles) -> "Geometry":
        idx = [self.muscles.index(m) for m in muscles]
        return Geometry(self.time, tuple(muscles), self.dofs, self.lmt_m[:, idx], self.moment_arms_m[:, :, idx], self.source)


def _columns(table, names) -> np.ndarray:
    """``(F, len(names))`` float array of the named columns of a DataFrame or a StorageTable."""
    return np.column_stack([np.asarray(table[c], dtype=float) for c in names])


def check_kinematics(ik, dofs, check_units: bool = True) -> bool:
    """Check an IK table (from :func:`~musclemetab.io.read_table` or
    :func:`~musclemetab.io.read_storage`); return whether it is in degrees.

    Raises, naming the file and column: :class:`~musclemetab.errors.MissingColumnError` when a
    DOF column is absent; :class:`~musclemetab.errors.InputFileError` for fewer than 2 frames;
    :class:`~musclemetab.errors.TimeColumnError` for time stamps that are not seconds;
    :class:`DataMismatchError` for a NaN or infinite value in any column (OpenSim is given
    every column) and, unless ``check_units=False``, for angles whose size contradicts the
    header: with ``inDegrees=no`` an angle beyond pi rad means degrees; with ``inDegrees=yes``
    all angles of the DOFs and of the legs' main joints (:func:`~musclemetab.model.default_dofs`,
    when in the file) below 2.5 "degrees" while the joints move (a walking knee flexes by
    some 60 degrees) means radians. Without the flag, angles beyond pi are taken as degrees and
    others as radians.
    """
    from .errors import InputFileError
    from .io import check_time_stamps, require_columns

    path = ik.attrs.get("path", "IK")
    require_columns(ik, dofs, what="DOF column")
    if len(ik.index) < 2:
        raise InputFileError(f"{path}: the IK file has fewer than 2 frames")
    check_time_stamps(ik, "IK")
    values = ik.to_numpy(dtype=float)
    bad = ~np.isfinite(values)
    if bad.any():
        row, col = (int(i) for i in np.argwhere(bad)[0])
        raise DataMismatchError(
            f"{path}: column '{ik.columns[col]}' is {values[row, col]:g} at data row {row + 1} (t = "
            f"{ik.index[row]:g} s); every coordinate must be finite: fix or remove the frame"
        )
    q = _columns(ik, dofs)
    in_degrees = ik.attrs.get("in_degrees")
    peak_by_dof = np.max(np.abs(q), axis=0)
    peak = float(peak_by_dof.max())
    if check_units and in_degrees is False and peak > MAX_PLAUSIBLE_ANGLE_RAD:
        col = dofs[int(np.argmax(peak_by_dof))]
        raise DataMismatchError(
            f"{path}: the header says inDegrees=no but column '{col}' reaches {peak:.4g}, which is "
            "not an angle in radians; the values look like degrees: fix the header to inDegrees=yes"
        )
    if in_degrees is None:
        in_degrees = peak > MAX_PLAUSIBLE_ANGLE_RAD
    # The radians-as-degrees test looks at the leg's main joints too when the file has them
    # (a coupled coordinate alone, such as a knee's beta angle, moves by a few degrees).
    legs = [c for c in dict.fromkeys([*dofs, *default_dofs("r"), *default_dofs("l")]) if c in ik.columns]
    q = _columns(ik, legs)
    peak = float(np.max(np.abs(q)))
    if check_units and in_degrees and peak < MIN_PEAK_ANGLE_DEG and float(np.ptp(q, axis=0).max()) > MIN_MOTION_RANGE:
        raise DataMismatchError(
            f"{path}: the header says inDegrees=yes but no DOF angle exceeds {MIN_PEAK_ANGLE_DEG:g} degrees "
            f"while the joints move (peak {peak:.3g}); the values look like radians: fix the header to inDegrees=no"
        )
    return bool(in_degrees)


def _cache_spec(model_path, ik_path, dofs, muscles, method) -> dict:
    return dict(
        fmt=GEOMETRY_FORMAT,
        model=file_sha256(model_path),
        ik=file_sha256(ik_path),
        dofs=list(dofs),
        muscles=list(muscles) if muscles else None,
        method=method,
    )


def geometry_is_cached(model_path, ik_path, dofs, *, cache_dir=None, muscles=None, method="velocity") -> bool:
    """Whether :func:`compute_geometry` with these arguments would find a cache entry.

    Lets a caller start the OpenSim worker early only when it will be needed. Nothing is
    created or read but the two files' content; files that cannot be read count as not
    cached (:func:`compute_geometry` reports them).
    """
    try:
        return existing_entry(_cache_spec(Path(model_path), Path(ik_path), dofs, muscles, method), cache_dir)
    except (OSError, OptionError):
        return False


def compute_geometry(
    model_path: str | os.PathLike,
    ik_path: "str | os.PathLike | StorageTable",
    dofs: list[str] | None = None,
    side: str = "r",
    muscles: list[str] | None = None,
    *,
    cache_dir: str | os.PathLike | None = None,
    use_cache: bool = True,
    method: str = "velocity",
    check_units: bool = True,
) -> Geometry:
    """Muscle-tendon lengths and moment arms at every frame of an IK motion.

    Parameters
    ----------
    model_path
        The ``.osim`` model.
    ik_path
        The IK motion (``.mot``), or its :class:`~musclemetab.io.StorageTable` already read by
        :func:`~musclemetab.io.read_table` (the cache key is the content of the file it was
        read from); rotational coordinates in degrees when its header says ``inDegrees=yes``
        (coupled coordinates are computed from their couplers).
    dofs
        DOFs for the moment arms; default the DOFs of ``side`` found in the model's joint
        tree (:func:`musclemetab.layout.side_dofs`; for the study's model the five of the
        study: ankle, knee, hip flexion, hip adduction, hip rotation).
    muscles
        Muscle names; default: the muscles spanning the DOFs (see module docstring).
    cache_dir
        Where to cache results (default :func:`default_cache_dir`).
    method
        Moment-arm method, see :mod:`musclemetab.opensim_bridge.model_ops`.
    check_units
        Refuse angles whose size contradicts the header (see :func:`check_kinematics`).

    Raises
    ------
    StorageFormatError, TimeColumnError
        The IK file is malformed.
    ModelError, UnknownCoordinateError, UnknownMuscleError
        The model cannot be loaded or lacks a DOF or muscle.
    DataMismatchError
        The motion moves a coordinate of ``side``'s leg that the model locks
        (:func:`musclemetab.layout.check_locked_coordinates`). Locked coordinates the motion
        holds still are set to the motion's values like the others.
    MissingColumnError
        The IK file lacks a DOF column.
    """
    from .opensim_bridge import call

    if method not in MOMENT_ARM_METHODS:
        raise OptionError(f"moment-arm method must be one of {', '.join(MOMENT_ARM_METHODS)}, not {method!r}")
    from .layout import check_locked_coordinates, read_layout, side_dofs
    from .model import check_model_path

    ik_source, model_path, ik_path = ik_path, Path(model_path), table_path(ik_path)
    check_model_path(model_path)
    layout = None
    if not dofs:
        layout = read_layout(model_path)
        dofs = side_dofs(layout, side)
    dofs = list(dofs)
    if len(set(dofs)) != len(dofs):
        raise OptionError(f"DOF list {dofs} names a DOF twice")
    ik = as_table(ik_source)  # validates the file before any cache lookup
    in_degrees = check_kinematics(ik, dofs, check_units)
    check_locked_coordinates(layout or read_layout(model_path, cache_dir=cache_dir), side, ik, in_degrees)

    cache_file = None
    if use_cache:
        cache_file = entry_path(_cache_spec(model_path, ik_path, dofs, muscles, method), cache_dir, "geometry")
        if cache_file is not None:
            arrays, problem = read_entry(cache_file)
            if arrays is not None:
                geom, problem = _geometry_from_entry(arrays, ik.index.copy(), dofs)
                if geom is not None:
                    return geom
            if problem:
                discard_entry(cache_file, problem, "geometry")

    t0 = _time.perf_counter()
    raw = call(
        "model_ops:muscle_geometry",
        str(model_path),
        ik.index.copy(),
        {c: np.ascontiguousarray(ik[c]) for c in ik.columns},
        bool(in_degrees),
        dofs,
        list(muscles) if muscles else None,
        method=method,
    )
    if not raw["muscles"]:
        raise DataMismatchError(
            f"{model_path}: no muscle has a moment arm above 0.1 mm about {', '.join(dofs)}; "
            "check the DOF names and the side"
        )
    for name, arr in (("muscle-tendon lengths", raw["lmt_m"]), ("moment arms", raw["moment_arms_m"])):
        if not np.all(np.isfinite(arr)):
            raise DataMismatchError(
                f"OpenSim gave NaN or infinite {name} for {model_path} along {ik_path}; check that the "
                "IK file belongs to this model (coordinate values within the model's ranges)"
            )
    source = dict(
        model=str(model_path.resolve()),
        ik=str(ik_path.resolve()),
        in_degrees=bool(in_degrees),
        method=method,
        opensim_version=raw["opensim_version"],
        defaulted_coordinates=raw["defaulted_coordinates"],
        compute_time_s=_time.perf_counter() - t0,
    )
    geom = Geometry(
        time=ik.index.copy(),
        muscles=tuple(raw["muscles"]),
        dofs=tuple(raw["dofs"]),
        lmt_m=raw["lmt_m"],
        moment_arms_m=raw["moment_arms_m"],
        source=source | {"cached": False},
    )
    if cache_file is not None:
        write_entry(cache_file, "geometry", time=geom.time, muscles=np.array(geom.muscles), dofs=np.array(geom.dofs),
                    lmt_m=geom.lmt_m, moment_arms_m=geom.moment_arms_m, source=np.array(json.dumps(source)))
    return geom


def _geometry_from_entry(z: dict, ik_time: np.ndarray, dofs) -> tuple[Geometry | None, str]:
    """The cached geometry if the (intact) entry fits the IK file, else ``(None, reason)``."""
    try:
        time, lmt, r = z["time"], z["lmt_m"], z["moment_arms_m"]
        muscles, cdofs = tuple(z["muscles"].tolist()), tuple(z["dofs"].tolist())
        source = json.loads(str(z["source"]))
    except Exception as exc:  # missing arrays, bad JSON
        return None, f"cannot be read ({type(exc).__name__})"
    F, M, D = ik_time.size, len(muscles), len(cdofs)
    if (time.shape != (F,) or not np.allclose(time, ik_time, rtol=0, atol=1e-9) or list(cdofs) != list(dofs)
            or lmt.shape != (F, M) or r.shape != (F, D, M)):
        return None, (f"holds {time.size} frames x DOFs {list(cdofs)}, not the {F} frames x {list(dofs)} of the "
                      "IK file")
    if not (np.all(np.isfinite(lmt)) and np.all(np.isfinite(r))):
        return None, "holds NaN or infinite values"
    return Geometry(time=time, muscles=muscles, dofs=cdofs, lmt_m=lmt, moment_arms_m=r,
                    source=source | {"cached": True}), ""


def write_geometry(geom: Geometry, out_dir: str | os.PathLike) -> list[Path]:
    """Write ``muscle_tendon_lengths.sto`` and ``moment_arms_<dof>.sto`` (m) into ``out_dir``.

    All files are written to a temporary folder first and moved into place together, listed in
    the folder's ``.musclemetab-files``: a file the package did not write is not replaced.
    """
    from .io import atomic_directory, check_inside, storage_from_arrays

    out_dir = Path(out_dir)
    names = list(geom.muscles)
    written = []
    with atomic_directory(out_dir, mark=True) as tmp:
        df = storage_from_arrays(geom.time, names=names, data=geom.lmt_m, name="muscle_tendon_lengths")
        write_storage(tmp / "muscle_tendon_lengths.sto", df, comments=["units=m"])
        written.append(out_dir / "muscle_tendon_lengths.sto")
        for j, d in enumerate(geom.dofs):
            check_inside(tmp, f"moment_arms_{d}.sto", f"the moment arms about '{d}'")
            df = storage_from_arrays(geom.time, names=names, data=geom.moment_arms_m[:, j, :], name=f"moment_arms_{d}")
            write_storage(tmp / f"moment_arms_{d}.sto", df, comments=["units=m"])
            written.append(out_dir / f"moment_arms_{d}.sto")
    return written
