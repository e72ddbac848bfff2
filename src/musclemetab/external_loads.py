"""Ground forces as users have them: OpenSim ExternalLoads files, gait events, inverse dynamics.

* :func:`read_external_loads` reads an OpenSim ``ExternalLoads`` XML file: which body each
  force acts on, its column identifiers, and the data file (a relative ``datafile`` is
  resolved against the XML file's folder, where OpenSim's GUI puts it).
* :func:`vertical_force` sums the vertical component of the forces applied to the bodies of
  one leg. Which leg a body belongs to is read from the model (:mod:`musclemetab.layout`), not
  from column or body names. Forces must be expressed in the ground frame (OpenSim's usual
  set-up); the vertical is the direction opposite to the model's gravity.
* :func:`compute_inverse_dynamics` runs OpenSim's InverseDynamicsTool (in the OpenSim worker)
  with the model's muscles excluded and the coordinates low-pass filtered at
  :data:`ID_COORDINATE_FILTER_HZ` (6 Hz, the value of OpenSim's example setup for this kind of
  data and the study's cut-off for every input signal). The solver then filters the
  resulting moments once more with its own 6 Hz zero-phase filter, exactly as it filters a
  user's ID file. Results are cached on disk, keyed by the content of the inputs.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import DataMismatchError, InputFileError, MissingColumnError, ModelError
from .messages import name_list
# the window check lives with the time columns it checks (mocap, a layer below, uses it too)
from .io.storage import SAMPLE_TIME_TOLERANCE_S
from .io.storage import check_times_inside as check_inside

__all__ = [
    "ID_COORDINATE_FILTER_HZ",
    "ExternalForceSpec",
    "ExternalLoads",
    "read_external_loads",
    "vertical_force",
    "compute_inverse_dynamics",
]

#: Low-pass cut-off (Hz) the InverseDynamicsTool applies to the coordinates.
ID_COORDINATE_FILTER_HZ = 6.0


@dataclass(frozen=True)
class ExternalForceSpec:
    """One ``ExternalForce`` of an ExternalLoads file."""

    name: str
    body: str
    force_identifier: str
    point_identifier: str
    torque_identifier: str
    force_expressed_in_body: str
    point_expressed_in_body: str


@dataclass(frozen=True)
class ExternalLoads:
    """An ExternalLoads file: its forces and its (absolute) data file."""

    path: Path
    datafile: Path
    forces: tuple[ExternalForceSpec, ...]

    def check_bodies(self, layout) -> None:
        """Raise :class:`ModelError` naming a force whose body the model lacks."""
        known = set(layout.bodies) | {layout.ground, "ground"}
        for f in self.forces:
            for what, body in (("applied_to_body", f.body), ("force_expressed_in_body", f.force_expressed_in_body),
                               ("point_expressed_in_body", f.point_expressed_in_body)):
                if body and body not in known:
                    raise ModelError(
                        f"{self.path}: ExternalForce '{f.name}' {what} '{body}' is not a body of the model "
                        f"{layout.path}; use one of {', '.join(layout.bodies)}"
                    )


def _text(el, tag: str, default: str = "") -> str:
    child = el.find(tag)
    return (child.text or "").strip() if child is not None and child.text else default


def read_external_loads(path: str | os.PathLike) -> ExternalLoads:
    """Read an OpenSim ExternalLoads XML file and check its data file and columns.

    Raises
    ------
    InputFileError
        The XML is missing or malformed, holds no enabled ExternalForce, or its data file is
        missing.
    MissingColumnError
        The data file lacks a force, point or torque column an ExternalForce names.
    """
    from .io import read_storage

    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: no such ExternalLoads file; check the path")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise InputFileError(f"{path}: not a readable XML file ({exc}); give an OpenSim ExternalLoads file") from None
    loads = root if root.tag == "ExternalLoads" else root.find(".//ExternalLoads")
    if loads is None:
        raise InputFileError(f"{path}: no <ExternalLoads> element; give an OpenSim ExternalLoads file")
    forces = []
    for ef in loads.iter("ExternalForce"):
        if _text(ef, "isDisabled", "false").lower() == "true" or _text(ef, "appliesForce", "true").lower() == "false":
            continue
        forces.append(ExternalForceSpec(
            name=ef.get("name", ""),
            body=_text(ef, "applied_to_body"),
            force_identifier=_text(ef, "force_identifier"),
            point_identifier=_text(ef, "point_identifier"),
            torque_identifier=_text(ef, "torque_identifier"),
            force_expressed_in_body=_text(ef, "force_expressed_in_body", "ground"),
            point_expressed_in_body=_text(ef, "point_expressed_in_body", "ground"),
        ))
    if not forces:
        raise InputFileError(f"{path}: the ExternalLoads file holds no enabled ExternalForce")
    for f in forces:
        if not f.body or not f.force_identifier:
            raise InputFileError(
                f"{path}: ExternalForce '{f.name}' lacks applied_to_body or force_identifier; complete the file"
            )
    name = _text(loads, "datafile")
    if not name:
        raise InputFileError(f"{path}: the ExternalLoads file names no <datafile>; add the ground-force file")
    datafile = Path(name)
    if not datafile.is_absolute():
        datafile = path.parent / datafile
    if not datafile.is_file():
        raise InputFileError(
            f"{path}: its data file {datafile} does not exist; put the ground-force file beside the XML or fix "
            "<datafile>"
        )
    table = read_storage(datafile)
    for f in forces:
        needed = [f"{f.force_identifier}{a}" for a in "xyz"]
        if f.point_identifier:
            needed += [f"{f.point_identifier}{a}" for a in "xyz"]
        if f.torque_identifier:
            needed += [f"{f.torque_identifier}{a}" for a in "xyz"]
        missing = [c for c in needed if c not in table.columns]
        if missing:
            raise MissingColumnError(
                f"{datafile}: no column {name_list(missing)} for ExternalForce '{f.name}' of {path}; fix the "
                "identifiers in the XML or the column names"
            )
        check_force_columns(table, datafile, needed, points=[c for c in needed if f.point_identifier
                                                               and c.startswith(f.point_identifier)])
    return ExternalLoads(path=path, datafile=datafile.resolve(), forces=tuple(forces))


#: Largest distance (m) of a centre of pressure from the lab's origin: beyond it the
#: point columns are in other units (mm) or hold a filler value.
MAX_POINT_DISTANCE_M = 20.0


def check_force_columns(table, path, columns, points=()) -> None:
    """Raise :class:`InputFileError` for a NaN or infinite value in any of ``columns``, or a
    point (centre of pressure) column farther than :data:`MAX_POINT_DISTANCE_M` from the origin;
    the message names the file, the column and the times."""
    t = table.index.to_numpy(dtype=float)
    for c in columns:
        v = table[c].to_numpy(dtype=float)
        bad = ~np.isfinite(v)
        if bad.any():
            raise InputFileError(f"{path}: column '{c}' holds {int(bad.sum())} NaN or infinite value(s) "
                                 f"{_times(t[bad])}; fill the gaps (zeros when the foot is off the plate)")
        if c in points:
            far = np.abs(v) > MAX_POINT_DISTANCE_M
            if far.any():
                raise InputFileError(
                    f"{path}: point column '{c}' reaches {np.abs(v).max():g} {_times(t[far])}, more than "
                    f"{MAX_POINT_DISTANCE_M:g} m from the origin; centres of pressure must be in metres (not mm)"
                )


def _times(t) -> str:
    head = ", ".join(f"{x:.4f}" for x in t[:3])
    return f"at t = {head}{' ...' if len(t) > 3 else ''} s"


def vertical_force(loads: ExternalLoads, layout, side: str):
    """Time (s) and summed vertical force (N) on the bodies of ``side``.

    Raises :class:`DataMismatchError` when no force acts on a body of that side, or a force on
    that side is not expressed in the ground frame.
    """
    from .io import read_storage
    from .layout import SIDE_NAMES, check_side

    check_side(side)
    loads.check_bodies(layout)
    mine = [f for f in loads.forces if layout.body_side(f.body) == side]
    if not mine:
        raise DataMismatchError(
            f"{loads.path}: no ExternalForce acts on a body of the {SIDE_NAMES[side]} leg (forces act on "
            f"{', '.join(f.body for f in loads.forces)}); choose the other side or fix the file"
        )
    g = np.asarray(layout.gravity, dtype=float)
    up = -g / np.linalg.norm(g)
    table = read_storage(loads.datafile)
    total = np.zeros(len(table.index))
    for f in mine:
        if f.force_expressed_in_body not in (layout.ground, "ground"):
            raise DataMismatchError(
                f"{loads.path}: ExternalForce '{f.name}' is expressed in body '{f.force_expressed_in_body}', not in "
                "the ground; gait events need ground-frame forces"
            )
        xyz = table[[f"{f.force_identifier}{a}" for a in "xyz"]].to_numpy(dtype=float)
        total += xyz @ up
    return table.index.to_numpy(dtype=float), total


def _cache_dir() -> Path:
    from .cache import cache_folder

    return cache_folder("inverse_dynamics")


def compute_inverse_dynamics(
    model_path: str | os.PathLike,
    ik_path: str | os.PathLike,
    external_loads: str | os.PathLike | ExternalLoads,
    start_s: float,
    end_s: float,
    *,
    lowpass_cutoff_hz: float = ID_COORDINATE_FILTER_HZ,
    use_cache: bool = True,
    cache_dir: str | os.PathLike | None = None,
) -> Path:
    """Inverse dynamics over ``[start_s, end_s]`` by OpenSim's InverseDynamicsTool; returns the ``.sto`` path.

    The file lives in the package cache (``$MUSCLEMETAB_CACHE/inverse_dynamics``, or
    ``cache_dir`` when given, named ``id-<key>.sto``) with its SHA-256 checksum beside it
    (:mod:`musclemetab.cache`): an entry that fails its checksum is deleted and computed again
    with a :class:`~musclemetab.errors.CacheWarning`; one that is a folder is left alone and the
    result is computed outside the cache. Copy the file where it is needed. The window must lie
    inside the IK motion and the ground-force data.
    """
    from .io import atomic_path, read_storage
    from .io.atomic import file_sha256
    from .opensim_bridge import call

    loads = external_loads if isinstance(external_loads, ExternalLoads) else read_external_loads(external_loads)
    from .model import check_model_path

    model_path, ik_path = check_model_path(model_path), Path(ik_path)
    from .layout import read_layout

    loads.check_bodies(read_layout(model_path))
    ik = read_storage(ik_path)
    grf = read_storage(loads.datafile)
    for what, p, t in (("inverse kinematics", ik_path, ik.index), ("ground forces", loads.datafile, grf.index)):
        check_inside((start_s, end_s), float(t[0]), float(t[-1]), p, what)
    spec = dict(
        model=file_sha256(model_path), ik=file_sha256(ik_path), xml=file_sha256(loads.path),
        data=file_sha256(loads.datafile), t=[round(float(start_s), 9), round(float(end_s), 9)],
        cutoff=float(lowpass_cutoff_hz), fmt=1,
    )
    from .cache import discard_file_entry, entry_path, read_file_entry, seal_file_entry

    out = entry_path(spec, cache_dir or _cache_dir(), "inverse dynamics", prefix="id-", suffix=".sto") \
        if use_cache else None
    cached = out is not None
    if cached:
        problem = read_file_entry(out)
        if not problem:
            return out
        if problem != "missing":
            discard_file_entry(out, problem, "inverse dynamics")
    else:
        import tempfile

        out = Path(tempfile.mkdtemp(prefix="musclemetab-id-")) / "inverse_dynamics.sto"
    # OpenSim resolves a relative <datafile> against the working directory: give it a copy of
    # the XML that names the data file by its absolute path.
    tree = ET.parse(loads.path)
    root = tree.getroot()
    el = (root if root.tag == "ExternalLoads" else root.find(".//ExternalLoads")).find("datafile")
    el.text = str(loads.datafile)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out, suffix=".sto") as tmp:
        xml = Path(str(tmp) + ".xml")
        tree.write(xml)
        try:
            call("dynamics:inverse_dynamics", str(model_path.resolve()), str(ik_path.resolve()), str(xml),
                 float(start_s), float(end_s), str(tmp), float(lowpass_cutoff_hz))
        finally:
            xml.unlink(missing_ok=True)
    if cached:
        seal_file_entry(out, "inverse dynamics")
    return out
