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

Moment arms follow OpenSim's convention ``r = -dl/dq`` (a positive moment arm means that
muscle tension produces a positive generalised moment); coupled coordinates (the
Rajagopal knee's ``knee_angle_r_beta``, the patella) move with their independent
coordinate as OpenSim's couplers say. All results in SI units (m).
"""

from __future__ import annotations

import json
import os
import time as _time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .cache import cache_file as _cache_file, default_cache_dir, load_entry, save_entry
from .io.atomic import file_sha256
from .errors import DataMismatchError, OptionError, UnknownCoordinateError
from .io import read_storage, write_storage
from .model import default_dofs

__all__ = ["Geometry", "compute_geometry", "geometry_is_cached", "default_cache_dir", "write_geometry", "GEOMETRY_FORMAT"]

GEOMETRY_FORMAT = 1  # bump when the cached content changes meaning
MOMENT_ARM_METHODS = ("velocity", "opensim", "finite_difference")
_ENTRY_ARRAYS = ("time", "muscles", "dofs", "lmt_m", "moment_arms_m", "source")


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


def _entry_path(model_path, ik_path, dofs, muscles, method, cache_dir) -> Path:
    spec = dict(
        fmt=GEOMETRY_FORMAT,
        model=file_sha256(model_path),
        ik=file_sha256(ik_path),
        dofs=list(dofs),
        muscles=list(muscles) if muscles else None,
        method=method,
    )
    return _cache_file(spec, cache_dir)


def geometry_is_cached(
    model_path: str | os.PathLike,
    ik_path: str | os.PathLike,
    dofs: list[str] | None = None,
    side: str = "r",
    muscles: list[str] | None = None,
    *,
    cache_dir: str | os.PathLike | None = None,
    method: str = "velocity",
) -> bool:
    """Whether :func:`compute_geometry` with these arguments would find a cache entry.

    Lets a caller start the OpenSim worker early only when it will be needed. Files that
    cannot be read count as not cached (:func:`compute_geometry` reports them).
    """
    try:
        dofs = list(dofs) if dofs else default_dofs(side)
        return _entry_path(Path(model_path), Path(ik_path), dofs, muscles, method, cache_dir).is_file()
    except (OSError, OptionError):
        return False


def compute_geometry(
    model_path: str | os.PathLike,
    ik_path: str | os.PathLike,
    dofs: list[str] | None = None,
    side: str = "r",
    muscles: list[str] | None = None,
    *,
    cache_dir: str | os.PathLike | None = None,
    use_cache: bool = True,
    method: str = "velocity",
) -> Geometry:
    """Muscle-tendon lengths and moment arms at every frame of an IK motion.

    Parameters
    ----------
    model_path
        The ``.osim`` model.
    ik_path
        The IK motion (``.mot``); rotational coordinates in degrees when its header says
        ``inDegrees=yes`` (coupled coordinates are computed from their couplers).
    dofs
        DOFs for the moment arms; default the five of ``side``
        (ankle, knee, hip flexion, hip adduction, hip rotation).
    muscles
        Muscle names; default: the muscles spanning the DOFs (see module docstring).
    cache_dir
        Where to cache results (default :func:`default_cache_dir`).
    method
        Moment-arm method, see :mod:`musclemetab.opensim_bridge.model_ops`.

    Raises
    ------
    StorageFormatError, TimeColumnError
        The IK file is malformed.
    ModelError, UnknownCoordinateError, UnknownMuscleError
        The model cannot be loaded or lacks a DOF or muscle.
    MissingColumnError
        The IK file lacks a DOF column.
    """
    from .opensim_bridge import call

    if method not in MOMENT_ARM_METHODS:
        raise OptionError(f"moment-arm method must be one of {', '.join(MOMENT_ARM_METHODS)}, not {method!r}")
    model_path, ik_path = Path(model_path), Path(ik_path)
    dofs = list(dofs) if dofs else default_dofs(side)
    if len(set(dofs)) != len(dofs):
        raise OptionError(f"DOF list {dofs} names a DOF twice")
    if not model_path.is_file():
        from .errors import ModelError

        raise ModelError(f"{model_path}: no such model file; check the path")
    ik = read_storage(ik_path)  # validates the file before any cache lookup
    from .io import require_columns

    require_columns(ik, dofs, what="DOF column")

    entry_path = None
    if use_cache:
        entry_path = _entry_path(model_path, ik_path, dofs, muscles, method, cache_dir)
        z = load_entry(entry_path, required=_ENTRY_ARRAYS)
        if z is not None:
            return Geometry(
                time=z["time"],
                muscles=tuple(z["muscles"].tolist()),
                dofs=tuple(z["dofs"].tolist()),
                lmt_m=z["lmt_m"],
                moment_arms_m=z["moment_arms_m"],
                source=json.loads(str(z["source"])) | {"cached": True},
            )

    in_degrees = ik.attrs.get("in_degrees")
    if in_degrees is None:
        in_degrees = True  # OpenSim's convention for motion files without the flag
    t0 = _time.perf_counter()
    raw = call(
        "model_ops:muscle_geometry",
        str(model_path),
        ik.index.to_numpy(),
        {c: ik[c].to_numpy() for c in ik.columns},
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
        time=ik.index.to_numpy(),
        muscles=tuple(raw["muscles"]),
        dofs=tuple(raw["dofs"]),
        lmt_m=raw["lmt_m"],
        moment_arms_m=raw["moment_arms_m"],
        source=source | {"cached": False},
    )
    if entry_path is not None:
        save_entry(
            entry_path,
            time=geom.time,
            muscles=np.array(geom.muscles),
            dofs=np.array(geom.dofs),
            lmt_m=geom.lmt_m,
            moment_arms_m=geom.moment_arms_m,
            source=json.dumps(source),
        )
    return geom


def write_geometry(geom: Geometry, out_dir: str | os.PathLike) -> list[Path]:
    """Write ``muscle_tendon_lengths.sto`` and ``moment_arms_<dof>.sto`` (m) into ``out_dir``.

    All files are written to a temporary folder first and moved into place together.
    """
    from .io import atomic_directory, storage_from_arrays

    out_dir = Path(out_dir)
    names = list(geom.muscles)
    written = []
    with atomic_directory(out_dir) as tmp:
        df = storage_from_arrays(geom.time, names=names, data=geom.lmt_m, name="muscle_tendon_lengths")
        write_storage(tmp / "muscle_tendon_lengths.sto", df, comments=["units=m"])
        written.append(out_dir / "muscle_tendon_lengths.sto")
        for j, d in enumerate(geom.dofs):
            df = storage_from_arrays(geom.time, names=names, data=geom.moment_arms_m[:, j, :], name=f"moment_arms_{d}")
            write_storage(tmp / f"moment_arms_{d}.sto", df, comments=["units=m"])
            written.append(out_dir / f"moment_arms_{d}.sto")
    return written
