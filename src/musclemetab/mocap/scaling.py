"""Scale a generic OpenSim model to a subject from a static trial (OpenSim's ScaleTool).

:func:`scale_model` runs OpenSim's ScaleTool in the OpenSim worker
(:func:`musclemetab.opensim_bridge.lab.scale_model`) in one of two ways:

* with the user's ScaleTool setup (``.xml``): its measurements, marker weights, time range and
  marker-set file, every relative file name resolved against the setup's folder (as OpenSim's
  GUI does), and the model, static trial and body mass given here in place of the setup's;
* without one, with a measurement set the package ships for the model families it knows
  (``data/scale_measurements.csv``: gait2392/gait2354 marker names such as ``R.ASIS``, the
  Rajagopal family's such as ``RASI``), chosen by the marker names the model and the static
  trial share; every shared marker is placed with weight 1, over the whole static trial, every
  coordinate but the root joint's held at its default value (the standing pose of the model) with
  weight :data:`STATIC_COORDINATE_WEIGHT`.

Body mass is the caller's; height, when not given, is estimated from the static trial
(:func:`estimate_height`). The static pose's marker errors (RMS, maximum, worst marker) are the
distances of the scaled model's markers, in the pose the marker placer finds, from the
experimental markers averaged over the time range, the numbers OpenSim's ScaleTool reports; above OpenSim's best-practice limits (2 cm RMS, 4 cm
maximum) they give a :class:`~musclemetab.errors.MarkerErrorWarning`.
Results are cached by the content of every input (``$MUSCLEMETAB_CACHE/scale``). Nothing is
written next to the user's files.
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
import shutil
import tempfile
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from ..errors import DataMismatchError, InputFileError, MarkerErrorWarning, MusclemetabWarning
from .trc import read_trc
from .trial import MAX_LIMIT_M, RMS_LIMIT_M

__all__ = ["ScaleResult", "scale_model", "measurement_sets", "choose_measurements", "estimate_height",
           "setup_files", "setup_tool", "SETUP_OPTIONS", "marker_error_summary", "HEAD_MARKER_WORDS"]

#: bump when a cached scaling result changes meaning
SCALE_CACHE_FORMAT = 2  # 2: the record holds OpenSim's own line on the static pose
#: without a setup, the weight holding each coordinate (but the root joint's) at its default value
#: in the static pose: without it the pose trades pelvis tilt against hip and lumbar flexion
#: (gait2392's static trial: pelvis 15 degrees forward, hips 25 degrees extended)
STATIC_COORDINATE_WEIGHT = 0.1
#: words of marker names on the top of the head (for the height estimate)
HEAD_MARKER_WORDS = ("HEAD", "VERTEX", "TOP", "HD", "TEMPLE")


@dataclass
class ScaleResult:
    """A scaled model: its text, the static pose, the marker errors and the record."""

    model_text: str
    static_pose_text: str
    record: dict = field(default_factory=dict)

    @property
    def marker_errors(self) -> list[dict]:
        return self.record["static_marker_errors"]

    def write(self, folder: str | os.PathLike) -> dict:
        """Write ``model.osim``, ``static_pose.sto`` and ``static_marker_errors.csv`` into ``folder``
        (an existing folder); returns their paths."""
        folder = Path(folder)
        (folder / "model.osim").write_text(self.model_text, encoding="utf-8")
        (folder / "static_pose.sto").write_text(self.static_pose_text, encoding="utf-8")
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["marker", "error_m", "weight"])
        for e in sorted(self.marker_errors, key=lambda e: -e["error_m"]):
            w.writerow([e["marker"], f"{e['error_m']:.6f}", f"{e['weight']:g}"])
        (folder / "static_marker_errors.csv").write_text(buf.getvalue(), encoding="utf-8")
        return {k: str(folder / n) for k, n in (("model", "model.osim"), ("static_pose", "static_pose.sto"),
                                                 ("static_marker_errors", "static_marker_errors.csv"))}


def marker_error_summary(errors: list[dict]) -> dict:
    """RMS and maximum (m) of marker errors, and the worst marker."""
    e = np.array([x["error_m"] for x in errors], dtype=float)
    if not len(e):
        return {"rms_m": float("nan"), "max_m": float("nan"), "worst_marker": ""}
    k = int(np.argmax(e))
    return {"rms_m": float(np.sqrt(np.mean(e ** 2))), "max_m": float(e[k]), "worst_marker": errors[k]["marker"]}


#: OpenSim's marker placer's line on the static pose (ScaleTool, info level)
_OPENSIM_PLACER_LINE = re.compile(
    r"total squared error = (?P<sq>\S+), marker error: RMS = (?P<rms>\S+), max = (?P<max>\S+) \((?P<worst>[^)]*)\)")


def opensim_marker_error_summary(log: str) -> dict | None:
    """The static pose's marker errors as OpenSim's marker placer prints them (``"total squared
    error = ..., marker error: RMS = ..., max = ... (marker)"``), from its log ``log``:
    ``{"rms_m", "max_m", "worst_marker", "total_squared_error_m2"}`` of the last such line, or
    ``None`` when the log has none (the placer switched off)."""
    found = list(_OPENSIM_PLACER_LINE.finditer(log or ""))
    if not found:
        return None
    m = found[-1]
    return {"rms_m": float(m["rms"]), "max_m": float(m["max"]), "worst_marker": m["worst"],
            "total_squared_error_m2": float(m["sq"])}


def measurement_sets() -> dict[str, list[dict]]:
    """The shipped measurement sets: ``{family: [{"name", "pairs", "bodies"}]}``, sides expanded."""
    text = resources.files("musclemetab").joinpath("data/scale_measurements.csv").read_text()
    rows = csv.DictReader(line for line in text.splitlines() if line and not line.startswith("#"))
    out: dict[str, list[dict]] = {}
    for row in rows:
        sides = (("R", "r"), ("L", "l")) if "{s}" in row["measurement"] or "{S}" in row["pairs"] else ((None, None),)
        for big, small in sides:
            def sub(t):
                return t.replace("{S}", big).replace("{s}", small) if big else t
            out.setdefault(row["family"], []).append({
                "name": sub(row["measurement"]),
                "pairs": [sub(p).split() for p in row["pairs"].split(";")],
                "bodies": sub(row["bodies"]).split(),
            })
    return out


def choose_measurements(model_markers: list[str], trial_markers: list[str], bodies: list[str],
                        source: str = "", model: str = "") -> tuple[str, list[dict], list[str]]:
    """The family whose marker pairs the model and the trial share most, its usable measurements
    (pairs with both markers present, bodies the model has) and the bodies left unscaled.

    Raises :class:`DataMismatchError` when no family has a usable pair, naming the static trial
    ``source`` and the model file ``model``, with the remedies: a marker-set file (``--marker-set``)
    for a model without markers or with other marker names, or a ScaleTool setup.
    """
    from ..messages import name_list

    have = set(model_markers) & set(trial_markers)
    best = None
    for family, items in measurement_sets().items():
        usable, unscaled = [], []
        for m in items:
            pairs = [p for p in m["pairs"] if set(p) <= have]
            bods = [b for b in m["bodies"] if b in bodies]
            if pairs and bods:
                usable.append({"name": m["name"], "pairs": pairs, "bodies": bods})
            else:
                unscaled += bods
        n = sum(len(m["pairs"]) for m in usable)
        if best is None or n > best[0]:
            best = (n, family, usable, unscaled)
    if best is None or best[0] == 0:
        trial = name_list(trial_markers, 6)
        setup = "or a ScaleTool setup whose measurements use the trial's markers (--scale-setup)"
        if not model_markers:
            raise DataMismatchError(
                f"{source}: the model {model} has no markers to match the static trial's ({trial}); give it a "
                "marker-set file whose markers are named as the trial's (--marker-set FILE, e.g. OpenSim's "
                f"gait2392_Scale_MarkerSet.xml for gait2392's names R.ASIS, R.Knee.Lat ...), {setup}"
            )
        raise DataMismatchError(
            f"{source}: the model's markers ({name_list(model_markers, 6)}) and the static trial's ({trial}) share no "
            "marker pair of a known model family (gait2392: R.ASIS, R.Knee.Lat ...; Rajagopal: RASI, RKNE ...); "
            f"give a marker-set file whose markers are named as the trial's (--marker-set FILE), {setup}"
        )
    return best[1], best[2], best[3]


def estimate_height(trc_path: str | os.PathLike, time_range=None, source: str | None = None) -> tuple[float, str]:
    """Standing height (m) from a static trial: the height above the floor of the highest marker
    (median over ``time_range``). The floor is y = 0 when the lowest marker lies between 0 and
    0.15 m (the lab's origin on the floor, as OpenSim's files have it), else 3 cm below the lowest
    marker. Returns ``(height, marker)``; warns when the highest marker is not a head marker
    (the height is then too short: give it). ``source``: the file the messages name (default
    ``trc_path``)."""
    m = read_trc(trc_path)
    source = source or str(trc_path)
    sel = np.ones(len(m.time), dtype=bool) if time_range is None else \
        (m.time >= time_range[0] - 1e-9) & (m.time <= time_range[1] + 1e-9)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        y = np.nanmedian(m.xyz[sel, :, 1], axis=0)
    ok = np.isfinite(y)
    if not ok.any():
        raise DataMismatchError(f"{source}: no marker is seen in the static trial's time range")
    low, k = float(np.nanmin(y)), int(np.nanargmax(y))
    floor = 0.0 if 0.0 <= low <= 0.15 else low - 0.03
    name = m.names[k]
    if not any(w in name.upper().replace(".", "") for w in HEAD_MARKER_WORDS):
        warnings.warn(f"{source}: the highest marker, {name}, is not on the head: the height estimated from it "
                      f"({float(y[k]) - floor:.3f} m) is too short; give the height", MusclemetabWarning, stacklevel=2)
    return float(y[k]) - floor, name


#: the file-name elements of OpenSim's ScaleTool and InverseKinematicsTool setups
_SETUP_FILE_TAGS = ("model_file", "marker_set_file", "marker_file", "coordinate_file")


#: the option of ``musclemetab prepare`` that takes each kind of OpenSim file
SETUP_OPTIONS = {"ScaleTool": "--scale-setup", "InverseKinematicsTool": "--ik-setup", "MarkerSet": "--marker-set"}


def setup_tool(root: ET.Element) -> str | None:
    """The OpenSim object an XML file holds: the first element inside ``<OpenSimDocument>`` (or
    the root itself in a file without one), e.g. ``ScaleTool``; ``None`` for an empty document."""
    if root.tag != "OpenSimDocument":
        return root.tag
    return next((el.tag for el in root if isinstance(el.tag, str)), None)


def setup_files(setup: str | os.PathLike, tool: str | None = None, names: dict | None = None) -> dict[str, Path]:
    """The input files a setup names (``{tag/index: absolute path}``), each relative name resolved
    against the setup's folder; raises :class:`InputFileError` for a setup that is not readable,
    or (``tool``: ``"ScaleTool"``, ``"InverseKinematicsTool"``) that holds another OpenSim object,
    naming the option (``names``, by tool: default :data:`SETUP_OPTIONS`, the command line's; a
    study names its keys) and what the file holds."""
    setup = Path(setup)
    if not setup.is_file():
        raise InputFileError(f"{setup}: no such setup file; check the path")
    try:
        root = ET.parse(setup).getroot()
    except ET.ParseError as exc:
        raise InputFileError(f"{setup}: not a readable XML file ({exc})") from None
    held = setup_tool(root)
    if tool is not None and held != tool:
        def a(name):
            return f"{'an' if name[0] in 'AEIOU' else 'a'} {name}"

        names = names or SETUP_OPTIONS
        hint = f" (give it as {names[held]})" if held in names else ""
        raise InputFileError(f"{setup}: {names.get(tool, 'the setup')} needs OpenSim's {tool} setup, but this "
                             f"file holds {a(held) if held else 'no OpenSim object'}{hint}; give {a(tool)} setup")
    out = {}
    for tag in _SETUP_FILE_TAGS:
        for i, el in enumerate(root.iter(tag)):
            name = (el.text or "").strip()
            if name and name != "Unassigned":
                p = Path(name)
                out[f"{tag}/{i}"] = p if p.is_absolute() else (setup.parent / p)
    return out


def _cache_dir() -> Path:
    from ..cache import cache_folder

    return cache_folder("scale")


def _sha(path) -> str:
    from ..io.atomic import file_sha256

    return file_sha256(path)


def _static_trc(static: Path, tmp: Path) -> Path:
    """The static trial as a ``.trc`` (a C3D file is converted into ``tmp``)."""
    if static.suffix.lower() == ".c3d":
        from .c3d import read_c3d
        from .trc import write_trc

        trial = read_c3d(static)
        return write_trc(tmp / f"{static.stem}.trc", trial.markers)
    if not static.is_file():
        raise InputFileError(f"{static}: no such static trial; check the path")
    return static


def scale_model(generic_model: str | os.PathLike, static: str | os.PathLike, mass_kg: float, *,
                setup: str | os.PathLike | None = None, marker_set: str | os.PathLike | None = None,
                height_m: float | None = None, use_cache: bool = True,
                cache_dir: str | os.PathLike | None = None, source: str | None = None) -> ScaleResult:
    """Scale ``generic_model`` to the static trial (``.trc`` or ``.c3d``) with body mass ``mass_kg``
    (module docstring). ``marker_set``: a marker-set file added to the model (OpenSim's
    ``marker_set_file``), for a generic model without markers; a setup's own is used otherwise.
    ``source``: the file the warnings name (default ``static``).
    """
    from ..cache import cached_texts
    from ..layout import read_layout
    from ..model import check_model_path

    generic_model = check_model_path(generic_model)
    static = Path(static)
    if not (mass_kg and float(mass_kg) > 0):
        raise InputFileError(f"body mass {mass_kg!r} is not a positive number of kg; give --mass")
    referenced = setup_files(setup, "ScaleTool") if setup else {}
    marker_set = Path(marker_set) if marker_set else None
    inputs = {"model": generic_model, "static": static}
    if setup:
        inputs["setup"] = Path(setup)
        ms = [p for k, p in referenced.items() if k.startswith("marker_set_file")]
        if marker_set is None and ms:
            marker_set = ms[0]
        for k, p in referenced.items():
            if k.startswith("coordinate_file") and not p.is_file():
                raise InputFileError(f"{setup}: its coordinate file {p} does not exist; fix the setup")
    if marker_set is not None:
        if not marker_set.is_file():
            raise InputFileError(f"{marker_set}: no such marker-set file (named by "
                                 f"{'--marker-set' if not setup else setup}); check the path")
        inputs["marker_set"] = marker_set
    for what, p in inputs.items():
        if not Path(p).is_file():
            raise InputFileError(f"{p}: no such {what.replace('_', ' ')} file; check the path")
    read_layout(generic_model)  # a file OpenSim cannot load is named as solve names it, before any tool runs
    spec = {"fmt": SCALE_CACHE_FORMAT, "static_weight": STATIC_COORDINATE_WEIGHT, "mass": float(mass_kg), "height": height_m,
            **{k: _sha(p) for k, p in inputs.items()},
            "coords": sorted(_sha(p) for k, p in referenced.items() if k.startswith("coordinate_file")),
            "measurements": None if setup else json.dumps(measurement_sets(), sort_keys=True)}
    def compute():
        r = _scale(generic_model, static, mass_kg, setup, marker_set, height_m, source or str(static))
        return {"model": r.model_text, "pose": r.static_pose_text, "record": json.dumps(r.record)}

    texts = cached_texts(spec, cache_dir or _cache_dir(), "scaling", "scale-", compute, ("model", "pose", "record"),
                         use_cache)
    result = ScaleResult(texts["model"], texts["pose"], json.loads(texts["record"]))
    # the files of this call (a cached entry keeps those of the call that computed it; ``static``
    # may be a temporary conversion of the user's C3D, ``source``)
    result.record.update(generic_model=str(generic_model.resolve()), static=str(Path(source or static).resolve()),
                         setup=str(Path(setup).resolve()) if setup else None,
                         marker_set=str(marker_set.resolve()) if marker_set else None)
    s = result.record["static_summary"]
    if s["rms_m"] > RMS_LIMIT_M or s["max_m"] > MAX_LIMIT_M:
        warnings.warn(f"{source or static}: the scaled model's markers in the static pose are {100 * s['rms_m']:.1f} cm RMS and "
                      f"up to {100 * s['max_m']:.1f} cm ({s['worst_marker']}) from the experimental ones, above OpenSim's "
                      f"best practice ({100 * RMS_LIMIT_M:g} cm RMS, {100 * MAX_LIMIT_M:g} cm maximum): check the "
                      "measurements and that marker's placement (static_marker_errors.csv)",
                      MarkerErrorWarning, stacklevel=2)
    return result


def _scale(generic_model: Path, static: Path, mass_kg: float, setup, marker_set, height_m, source: str) -> ScaleResult:
    """OpenSim's scaling (:func:`scale_model`); ``source``: the user's static trial, which the
    messages name (``static`` may be a temporary conversion of it)."""
    from ..opensim_bridge import call

    tmp = Path(tempfile.mkdtemp(prefix="musclemetab-scale-"))
    try:
        trc = _static_trc(static, tmp)
        kwargs = {"setup": str(Path(setup).resolve()) if setup else None,
                  "marker_set": str(marker_set.resolve()) if marker_set else None}
        record = {"generic_model": str(generic_model.resolve()), "static": str(static.resolve()),
                  "setup": kwargs["setup"], "marker_set": kwargs["marker_set"]}
        times = read_trc(trc).time
        if not setup:
            model_markers = call("lab:model_marker_names", str(generic_model.resolve()), kwargs["marker_set"])
            from ..layout import read_layout

            bodies = list(read_layout(generic_model).bodies)
            trial_markers = read_trc(trc).names
            family, measurements, unscaled = choose_measurements(model_markers, trial_markers, bodies,
                                                                 source, str(generic_model))
            if unscaled:
                warnings.warn(f"{source}: no marker pair of the {family} measurement set for "
                              f"{', '.join(unscaled)}; these bodies keep the generic model's size (give a ScaleTool "
                              "setup to scale them)", MusclemetabWarning, stacklevel=2)
            weights = {n: 1.0 for n in model_markers if n in set(trial_markers)}
            kwargs.update(measurements=measurements, marker_weights=weights, coordinate_weight=STATIC_COORDINATE_WEIGHT,
                          time_range=(float(times[0]), float(times[-1])))
            record.update(family=family, measurements=measurements, unscaled_bodies=unscaled)
        else:
            tr = _setup_time_range(Path(setup))
            if tr is not None:
                kwargs["time_range"] = (max(tr[0], float(times[0])), min(tr[1], float(times[-1])))
        res = call("lab:scale_model", str(generic_model.resolve()), str(Path(trc).resolve()), float(mass_kg),
                   str(tmp), **kwargs)
        height, marker = (float(height_m), "given") if height_m else estimate_height(trc, res["time_range"], source)
        errors = static_marker_errors(read_trc(trc), res["static_model_markers"], res["time_range"])
        record.update(mass_kg=res["mass_kg"], height_m=height, height_from=marker, time_range=res["time_range"],
                      scale_factors={k: v for k, v in res["scale_factors"].items() if not k.endswith("_offset")},
                      static_marker_errors=errors, static_summary=marker_error_summary(errors),
                      opensim_static_summary=opensim_marker_error_summary(res.get("log", "")))
        result = ScaleResult(Path(res["model"]).read_text(encoding="utf-8"),
                             Path(res["static_pose"]).read_text(encoding="utf-8"), record)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return result


def static_marker_errors(markers, model_markers: list, window) -> list:
    """``[{"marker", "error_m", "weight"}]``: the distance of each model marker in the static
    pose (``[{"marker", "position_m", "weight"}]``, OpenSim's) from its experimental position
    averaged over ``window`` (as OpenSim's marker placer averages it), the errors OpenSim's
    ScaleTool reports; markers the trial lacks are left out."""
    sel = (markers.time >= window[0] - 1e-9) & (markers.time <= window[1] + 1e-9)
    out = []
    for m in model_markers:
        if m["marker"] not in markers.names:
            continue
        exp = np.nanmean(markers.marker(m["marker"])[sel], axis=0)
        out.append({"marker": m["marker"], "error_m": float(np.linalg.norm(np.asarray(m["position_m"]) - exp)),
                    "weight": m["weight"]})
    return out


def _setup_time_range(setup: Path):
    """The first ``time_range`` of a setup (the scaler's), or ``None``."""
    root = ET.parse(setup).getroot()
    for el in root.iter("time_range"):
        vals = (el.text or "").split()
        if len(vals) == 2:
            try:
                return float(vals[0]), float(vals[1])
            except ValueError:
                return None
    return None
