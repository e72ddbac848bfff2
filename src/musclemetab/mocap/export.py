"""Write what OpenSim's tools read: ground forces (``.mot``), ExternalLoads (``.xml``), markers.

The ground-force file has OpenSim's column names (those of its gait examples): for the k-th
force (k = 0, 1, ...), with prefix ``""`` for the first and ``"k_"`` after,
``<prefix>ground_force_v{x,y,z}`` (N), ``<prefix>ground_force_p{x,y,z}`` (the centre of pressure,
m) and ``<prefix>ground_torque_{x,y,z}`` (the free moment about the vertical, N m), all in the
ground frame. One force is one plate under one foot: a plate stepped on by the right foot and
later by the left is two forces, each zero outside its own contacts. The ExternalLoads file
applies each force to the heel body of its foot (``calcn_r``/``calcn_l``, or the model's, read
from the model when one is given) and names the ``.mot`` by its file name (same folder).
"""

from __future__ import annotations

import json
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..io import atomic_directory, storage_from_arrays, write_storage
from .plates import CONTACT_THRESHOLD_N, PlateContact, assign_feet, remove_offsets
from .trc import write_trc
from .trial import UP, Plate

__all__ = ["force_prefix", "write_ground_forces", "convert_c3d", "DEFAULT_FOOT_BODIES"]

DEFAULT_FOOT_BODIES = {"r": "calcn_r", "l": "calcn_l"}


def force_prefix(k: int) -> str:
    """Column prefix of the k-th force: ``""``, ``"1_"``, ``"2_"`` ..."""
    return "" if k == 0 else f"{k}_"


def _groups(contacts: list[PlateContact]) -> list[tuple[int, str]]:
    seen = []
    for c in sorted(contacts, key=lambda c: (c.plate, c.start_s)):
        if (c.plate, c.side) not in seen:
            seen.append((c.plate, c.side))
    return seen


def ground_force_table(plates: list[Plate], contacts: list[PlateContact], threshold_n: float = CONTACT_THRESHOLD_N):
    """The ground-force table (time-indexed DataFrame) and its forces ``[(prefix, plate, side)]``."""
    by_number = {p.number: p for p in plates}
    time = plates[0].time
    cols: dict[str, np.ndarray] = {}
    forces = []
    for k, (number, side) in enumerate(_groups(contacts)):
        plate = by_number[number]
        cop, free = plate.centre_of_pressure(threshold_n)
        mask = np.zeros(len(time), dtype=bool)
        for c in contacts:
            if c.plate == number and c.side == side:
                mask |= (plate.time >= c.start_s) & (plate.time <= c.end_s)
        mask &= plate.vertical() > threshold_n
        pre = force_prefix(k)
        for i, a in enumerate("xyz"):
            cols[f"{pre}ground_force_v{a}"] = np.where(mask, plate.force[:, i], 0.0)
        for i, a in enumerate("xyz"):
            cols[f"{pre}ground_force_p{a}"] = np.where(mask, cop[:, i], 0.0)
        for i, a in enumerate("xyz"):
            cols[f"{pre}ground_torque_{a}"] = np.where(mask, free * UP[i], 0.0)
        forces.append((pre, number, side))
    return storage_from_arrays(time, cols, name="ground_forces"), forces


def _external_loads_xml(forces, bodies: dict, datafile: str) -> str:
    doc = ET.Element("OpenSimDocument", Version="40000")
    loads = ET.SubElement(doc, "ExternalLoads", name="external_loads")
    objects = ET.SubElement(loads, "objects")
    for pre, number, side in forces:
        ef = ET.SubElement(objects, "ExternalForce", name=f"plate{number}_{side}")
        for tag, text in (("applied_to_body", bodies[side]), ("force_expressed_in_body", "ground"),
                          ("point_expressed_in_body", "ground"), ("force_identifier", f"{pre}ground_force_v"),
                          ("point_identifier", f"{pre}ground_force_p"), ("torque_identifier", f"{pre}ground_torque_"),
                          ("data_source_name", "Unassigned")):
            ET.SubElement(ef, tag).text = text
    ET.SubElement(loads, "groups")
    ET.SubElement(loads, "datafile").text = datafile
    ET.indent(doc, space="    ")
    return '<?xml version="1.0" encoding="UTF-8" ?>\n' + ET.tostring(doc, encoding="unicode") + "\n"


def write_ground_forces(folder: str | os.PathLike, plates: list[Plate], contacts: list[PlateContact], *,
                        bodies: dict | None = None, stem: str = "grf",
                        threshold_n: float = CONTACT_THRESHOLD_N) -> tuple[Path, Path]:
    """Write ``<stem>.mot`` and ``<stem>.xml`` (ExternalLoads) into ``folder`` (an existing
    temporary or output folder); returns their paths."""
    folder = Path(folder)
    table, forces = ground_force_table(plates, contacts, threshold_n)
    mot = write_storage(folder / f"{stem}.mot", table, name=f"{stem}.mot")
    xml = folder / f"{stem}.xml"
    xml.write_text(_external_loads_xml(forces, bodies or DEFAULT_FOOT_BODIES, mot.name), encoding="utf-8")
    return mot, xml


def model_foot_bodies(model) -> dict:
    """``{side: heel body}`` of a model (:func:`musclemetab.layout.foot_bodies`)."""
    from ..layout import foot_bodies, read_layout

    layout = read_layout(model)
    return {s: foot_bodies(layout, s)[0] for s in ("r", "l")}


def _analog_channels(path):
    """The C3D file's analog channels other than the force plates' (raw EMG), or ``None``."""
    from ..errors import InputFileError
    from .c3d import read_c3d_analogs

    try:
        return read_c3d_analogs(path)
    except InputFileError:
        return None


def convert_c3d(path: str | os.PathLike, out: str | os.PathLike, *, stem: str | None = None, model=None,
                up: str = "auto", forward: str = "auto", feet: dict | None = None,
                plate_feet: dict | None = None, offsets: bool = True,
                threshold_n: float = CONTACT_THRESHOLD_N) -> dict:
    """Convert a C3D file into ``<stem>.trc`` (markers, m), and when it has force plates
    ``<stem>_grf.mot`` and ``<stem>_grf.xml`` (ExternalLoads), when it has other analog channels
    ``<stem>_emg.sto`` (those raw signals, volts where the file says V/mV/uV: EMG to be read with
    ``--emg-processing raw``), plus ``<stem>_c3d.json`` (the
    record: frame, offsets, every contact and its foot, flags), all written together into ``out``.
    Returns the record (with the paths under ``"files"``).
    """
    from .c3d import read_c3d
    from .plates import check_plate_feet, foot_marker_sets

    trial = read_c3d(path, up=up, forward=forward)
    check_plate_feet(plate_feet, trial.plates, str(path))  # also for a file without plates
    stem = stem or Path(path).stem
    record = {"source": str(Path(path).resolve()), **trial.notes, "threshold_n": threshold_n, "plates": [],
              "contacts": [], "forces": []}
    contacts = []
    if trial.plates:
        for p in trial.plates:
            zeroed = remove_offsets(p, threshold_n) if offsets else False
            record["plates"].append({"number": p.number, "offsets_removed": zeroed,
                                     "offset_force_n": p.offset_force.tolist(),
                                     "offset_moment_nm": p.offset_moment.tolist(),
                                     "centre_m": p.centre.tolist(), "corners_m": p.corners.tolist()})
        marker_feet = foot_marker_sets(trial.markers.names, feet)
        contacts = assign_feet(trial.plates, trial.markers, feet=marker_feet, plate_feet=plate_feet,
                               threshold_n=threshold_n, source=str(path))
        record["foot_markers"] = marker_feet
        record["contacts"] = [c.record() for c in contacts]
    bodies = model_foot_bodies(model) if model is not None and contacts else DEFAULT_FOOT_BODIES
    files = {}
    with atomic_directory(out, mark=True) as tmp:
        files["markers"] = str(Path(out) / write_trc(Path(tmp) / f"{stem}.trc", trial.markers).name)
        if contacts:
            mot, xml = write_ground_forces(tmp, trial.plates, contacts, bodies=bodies, stem=f"{stem}_grf",
                                           threshold_n=threshold_n)
            files["ground_forces"] = str(Path(out) / mot.name)
            files["external_loads"] = str(Path(out) / xml.name)
            _, forces = ground_force_table(trial.plates, contacts, threshold_n)
            record["forces"] = [{"name": f"plate{n}_{s}", "prefix": pre, "plate": n, "side": s, "body": bodies[s]}
                                for pre, n, s in forces]
        emg = _analog_channels(path)
        if emg is not None:
            from ..io import write_storage

            write_storage(Path(tmp) / f"{stem}_emg.sto", emg, name=f"{stem}_emg",
                          comments=[f"raw analog channels of {Path(path).name} other than the force plates', "
                                    f"{emg.attrs['analog_rate_hz']:g} Hz, units "
                                    + ", ".join(f"{c} {u or '?'}" for c, u in emg.attrs["units"].items())])
            files["emg"] = str(Path(out) / f"{stem}_emg.sto")
            record["emg_channels"] = list(emg.columns)
        record["files"] = files
        (Path(tmp) / f"{stem}_c3d.json").write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    return record
