"""The chain from the lab's files to what the solver reads: scale, inverse kinematics, ground forces.

:func:`prepare` scales a generic model to a static trial (:func:`.scaling.scale_model`), runs
inverse kinematics of a walking trial with it (:func:`.kinematics.inverse_kinematics`) and, when
the walking trial is a C3D file with force plates, writes its ground forces and ExternalLoads
(:func:`.export.convert_c3d`, each plate given to its foot, the forces applied to the scaled
model's heel bodies). Everything is written together into the output folder, nothing next to the
inputs; the OpenSim steps are cached by content, so a run stopped half-way starts again where it
stopped.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

from ..errors import InputFileError

__all__ = ["prepare", "PREPARED_FILES", "PREPARE_RECORD"]

#: the record :func:`prepare` writes beside its files (inputs, scaling, IK, the files written)
PREPARE_RECORD = "prepare.json"
#: the files :func:`prepare` always writes
PREPARED_FILES = ("model.osim", "static_pose.sto", "static_marker_errors.csv", "ik.mot", "ik_marker_errors.csv",
                  PREPARE_RECORD)


def prepare(generic_model: str | os.PathLike, static: str | os.PathLike, markers: str | os.PathLike,
            mass_kg: float, out: str | os.PathLike, *, height_m: float | None = None,
            scale_setup: str | os.PathLike | None = None, ik_setup: str | os.PathLike | None = None,
            marker_set: str | os.PathLike | None = None, time_range: tuple | None = None,
            c3d_options: dict | None = None, use_cache: bool = True) -> dict:
    """Scale, IK and (C3D) ground forces into ``out``; returns the record written as ``prepare.json``.

    ``c3d_options``: ``up``, ``forward``, ``feet``, ``plate_feet`` of :func:`.export.convert_c3d`.
    """
    from ..io import atomic_directory
    from .export import convert_c3d
    from .kinematics import check_window, inverse_kinematics
    from .scaling import scale_model, setup_files

    static, markers = Path(static), Path(markers)
    for what, p in (("static trial", static), ("walking trial", markers)):
        if not p.is_file():
            raise InputFileError(f"{p}: no such {what}; check the path")
    for setup, tool in ((scale_setup, "ScaleTool"), (ik_setup, "InverseKinematicsTool")):
        if setup:
            setup_files(setup, tool)  # the wrong kind of setup is named before anything runs
    tmp = Path(tempfile.mkdtemp(prefix="musclemetab-prepare-"))
    try:
        files = {}
        c3d_record = None
        walk = markers
        if markers.suffix.lower() == ".c3d":
            c3d_record = convert_c3d(markers, tmp, stem="markers", model=generic_model, **(c3d_options or {}))
            walk = tmp / "markers.trc"
            files.update({k: Path(v).name for k, v in c3d_record["files"].items()})
        static_in = static
        if static.suffix.lower() == ".c3d":
            from .c3d import read_c3d
            from .trc import write_trc

            opts = c3d_options or {}
            static_in = write_trc(tmp / "static.trc", read_c3d(static, up=opts.get("up", "auto"),
                                                             forward=opts.get("forward", "auto")).markers)
            files["static_markers"] = "static.trc"
        if time_range is not None:
            check_window(walk, time_range, str(markers))  # before the scaling
        scaled = scale_model(generic_model, static_in, mass_kg, setup=scale_setup, marker_set=marker_set,
                             height_m=height_m, use_cache=use_cache, source=str(static))
        scaled.write(tmp)
        ik = inverse_kinematics(tmp / "model.osim", walk, setup=ik_setup, time_range=time_range, use_cache=use_cache,
                                source=str(markers))
        ik.write(tmp)
        files.update(model="model.osim", static_pose="static_pose.sto", static_marker_errors="static_marker_errors.csv",
                     ik="ik.mot", ik_marker_errors="ik_marker_errors.csv")
        record = {
            "inputs": {"generic_model": str(Path(generic_model).resolve()), "static": str(static.resolve()),
                       "markers": str(markers.resolve()), "mass_kg": float(mass_kg),
                       "scale_setup": str(Path(scale_setup).resolve()) if scale_setup else None,
                       "ik_setup": str(Path(ik_setup).resolve()) if ik_setup else None},
            "mass_kg": scaled.record["mass_kg"], "height_m": scaled.record["height_m"],
            "height_from": scaled.record["height_from"],
            "scaling": {k: v for k, v in scaled.record.items() if k != "static_marker_errors"},
            "ik": ik.record, "c3d": c3d_record and {k: v for k, v in c3d_record.items() if k != "files"},
            "files": files,
        }
        if c3d_record is not None:
            (tmp / "markers_c3d.json").unlink(missing_ok=True)
        (tmp / PREPARE_RECORD).write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
        with atomic_directory(out, mark=True) as final:
            for item in tmp.iterdir():
                if item.is_file() and not item.name.startswith("."):  # not a folder's list of written files
                    shutil.copy2(item, Path(final) / item.name)
        return record
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
