"""Inverse kinematics from markers (OpenSim's InverseKinematicsTool), with marker errors flagged.

:func:`inverse_kinematics` runs the tool in the OpenSim worker
(:func:`musclemetab.opensim_bridge.lab.inverse_kinematics`) with the user's setup (its marker and
coordinate weights, accuracy, constraint weight and time range; a relative coordinate file
resolved against the setup's folder) or, without one, every marker the model and the trial share
with weight 1 over the whole trial (accuracy 1e-5, OpenSim's default). The model, the marker file
and the outputs are the caller's; nothing is written next to the user's files. A marker file
whose times are its stated rate's grid rounded (OpenSim's gait2392 trials: 0.017, 0.033 ... at
60 Hz) is given to the tool on the exact grid, so that the IK is evenly sampled, as the solver's
filter needs (the record gives the largest shift, ``times_restored_s``).

Every frame's RMS and maximum marker error are OpenSim's; the worst marker is the one at the
maximum. A frame is flagged when its RMS exceeds :data:`RMS_LIMIT_M` (2 cm) or its maximum
:data:`MAX_LIMIT_M` (4 cm), the limits of OpenSim's best-practice guide for IK (Hicks et al.
2015, J Biomech Eng 137:020905); flagged frames give one warning. Results are cached by the
content of the inputs (``$MUSCLEMETAB_CACHE/ik``).
"""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import tempfile
import warnings
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DataMismatchError, InputFileError, MarkerErrorWarning
from .scaling import setup_files
from .trc import read_trc
from .trial import MAX_LIMIT_M, RMS_LIMIT_M

__all__ = ["IKResult", "inverse_kinematics", "check_window", "RMS_LIMIT_M", "MAX_LIMIT_M", "MarkerErrorWarning"]

#: bump when a cached IK result changes meaning
IK_CACHE_FORMAT = 3


@dataclass
class IKResult:
    """An IK motion (text of the ``.mot``, degrees) and its per-frame marker errors."""

    ik_text: str
    errors: dict
    record: dict = field(default_factory=dict)

    def flagged(self) -> np.ndarray:
        return (np.asarray(self.errors["rms_m"]) > RMS_LIMIT_M) | (np.asarray(self.errors["max_m"]) > MAX_LIMIT_M)

    def write(self, folder: str | os.PathLike) -> dict:
        """Write ``ik.mot`` and ``ik_marker_errors.csv`` (time, RMS, max, worst marker, flag) into ``folder``."""
        folder = Path(folder)
        (folder / "ik.mot").write_text(self.ik_text, encoding="utf-8")
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["time_s", "rms_m", "max_m", "worst_marker", "above_best_practice"])
        for t, r, m, n, f in zip(self.errors["time"], self.errors["rms_m"], self.errors["max_m"],
                                 self.errors["worst_marker"], self.flagged()):
            w.writerow([f"{t:.6f}", f"{r:.6f}", f"{m:.6f}", n, int(bool(f))])
        (folder / "ik_marker_errors.csv").write_text(buf.getvalue(), encoding="utf-8")
        return {"ik": str(folder / "ik.mot"), "ik_marker_errors": str(folder / "ik_marker_errors.csv")}


def summarise(errors: dict) -> dict:
    rms, mx = np.asarray(errors["rms_m"]), np.asarray(errors["max_m"])
    flagged = (rms > RMS_LIMIT_M) | (mx > MAX_LIMIT_M)
    worst = Counter(n for n, f in zip(errors["worst_marker"], flagged) if f).most_common(1)
    return {"frames": int(len(rms)), "flagged_frames": int(flagged.sum()), "rms_mean_m": float(rms.mean()),
            "rms_max_m": float(rms.max()), "max_max_m": float(mx.max()),
            "worst_marker": worst[0][0] if worst else (Counter(errors["worst_marker"]).most_common(1) or [("",)])[0][0],
            "limits_m": {"rms": RMS_LIMIT_M, "max": MAX_LIMIT_M}}


def warn_flagged(summary: dict, source: str) -> None:
    if summary["flagged_frames"]:
        warnings.warn(
            f"{source}: {summary['flagged_frames']} of {summary['frames']} IK frames exceed OpenSim's best practice "
            f"(marker error RMS above {100 * RMS_LIMIT_M:g} cm or maximum above {100 * MAX_LIMIT_M:g} cm; largest RMS "
            f"{100 * summary['rms_max_m']:.1f} cm, largest error {100 * summary['max_max_m']:.1f} cm, most often "
            f"{summary['worst_marker']}): check that marker's placement and weight (ik_marker_errors.csv)",
            MarkerErrorWarning, stacklevel=3)


def _cache_dir() -> Path:
    from ..cache import cache_folder

    return cache_folder("ik")


def inverse_kinematics(model: str | os.PathLike, markers: str | os.PathLike, *,
                       setup: str | os.PathLike | None = None, time_range: tuple | None = None,
                       use_cache: bool = True, cache_dir: str | os.PathLike | None = None,
                       warn: bool = True, source: str | None = None) -> IKResult:
    """IK of ``markers`` (``.trc`` or ``.c3d``) with ``model`` (module docstring); ``source``: the
    file the messages name (default ``markers``). A ``time_range`` not inside the marker data is
    refused (:func:`check_window`); a setup's own time range is clipped to it."""
    from ..cache import cached_texts
    from ..io.atomic import file_sha256
    from ..layout import read_layout
    from ..model import check_model_path
    from ..opensim_bridge import call

    model = check_model_path(model)
    markers = Path(markers)
    if not markers.is_file():
        raise InputFileError(f"{markers}: no such marker file; check the path")
    source = source or str(markers)
    referenced = setup_files(setup, "InverseKinematicsTool") if setup else {}
    coords = [p for k, p in referenced.items() if k.startswith("coordinate_file")]
    for p in coords:
        if not p.is_file():
            raise InputFileError(f"{setup}: its coordinate file {p} does not exist; fix the setup")
    if time_range is not None:
        check_window(markers, time_range, source)
    read_layout(model)  # a file OpenSim cannot load is named as solve names it, before the tool runs
    spec = {"fmt": IK_CACHE_FORMAT, "model": file_sha256(model), "markers": file_sha256(markers),
            "setup": file_sha256(setup) if setup else None, "coords": [file_sha256(p) for p in coords],
            "window": list(time_range) if time_range else None}
    def compute():
        r = _run(model, markers, setup, time_range, call, source)
        return {"ik": r.ik_text, "errors": json.dumps(r.errors), "record": json.dumps(r.record)}

    texts = cached_texts(spec, cache_dir or _cache_dir(), "inverse kinematics", "ik-", compute,
                         ("ik", "errors", "record"), use_cache)
    result = IKResult(texts["ik"], json.loads(texts["errors"]), json.loads(texts["record"]))
    if warn:
        warn_flagged(result.record["summary"], source)
    return result


def _marker_times(markers: Path) -> np.ndarray:
    """The times of a marker file (``.trc`` or ``.c3d``), as the file gives them."""
    if markers.suffix.lower() == ".c3d":
        from .c3d import read_c3d

        return read_c3d(markers).markers.time
    return read_trc(markers).time


def check_window(markers: str | os.PathLike, time_range: tuple, source: str | None = None) -> None:
    """Refuse an IK time range (``--window``) that is not inside the times of the marker file, as
    ``musclemetab solve`` refuses a window outside its files
    (:func:`musclemetab.io.storage.check_times_inside`): the message names ``--window``, the file
    (``source``, default ``markers``) and its time range."""
    from ..io.storage import check_times_inside

    t = _marker_times(Path(markers))
    check_times_inside(time_range, float(t[0]), float(t[-1]), source or str(markers), "marker data",
                       span="the --window", remedy="choose a --window inside the marker data")


def _run(model: Path, markers: Path, setup, time_range, call, source: str) -> IKResult:
    tmp = Path(tempfile.mkdtemp(prefix="musclemetab-ik-"))
    try:
        trc = markers
        if markers.suffix.lower() == ".c3d":
            from .c3d import read_c3d
            from .trc import write_trc

            trc = write_trc(tmp / f"{markers.stem}.trc", read_c3d(markers).markers)
        trial = read_trc(trc)
        grid = trial.uniform_time()
        if grid is not None:  # times rounded in the file: OpenSim's IK would keep them, the solver refuses them
            from .trc import write_trc

            shift = float(np.max(np.abs(trial.time - grid)))
            trial.time = grid
            trc = write_trc(tmp / "markers_uniform_time.trc", trial)
        t0, t1 = float(trial.time[0]), float(trial.time[-1])
        kwargs = {}
        if setup:
            kwargs["setup"] = str(Path(setup).resolve())
            window = time_range or _ik_time_range(Path(setup))
        else:
            names = call("lab:model_marker_names", str(model.resolve()))
            shared = [n for n in names if n in set(trial.names)]
            if len(shared) < 3:
                raise DataMismatchError(
                    f"{source}: shares {len(shared)} marker(s) with the model {model} (at least 3 are needed); "
                    "check the marker names, or give an IK setup (--ik-setup)"
                )
            kwargs["marker_weights"] = {n: 1.0 for n in shared}
            window = time_range
        if window and min(window[1], t1) <= max(window[0], t0):  # a setup's time range (a --window was checked)
            what = f"{setup}: its IK time range" if time_range is None else f"{source}: the --window"
            raise DataMismatchError(f"{what} {window[0]:.3f}-{window[1]:.3f} s is not inside the marker data of "
                                    f"{source} ({t0:.3f}-{t1:.3f} s); give a --window inside the marker data"
                                    f"{', or fix the setup' if time_range is None else ''}")
        window = (max(window[0], t0), min(window[1], t1)) if window else (t0, t1)
        kwargs["time_range"] = window
        res = call("lab:inverse_kinematics", str(model.resolve()), str(Path(trc).resolve()), str(tmp), **kwargs)
        errors = {k: res[k] for k in ("time", "rms_m", "max_m")}
        errors["worst_marker"] = worst_markers(read_trc(trc), res["time"], res["markers"], res["model_marker_m"])
        record = {"model": str(model.resolve()), "markers": str(markers.resolve()),
                  "times_restored_s": shift if grid is not None else 0.0,
                  "setup": kwargs.get("setup"), "time_range": [res["start_s"], res["end_s"]],
                  "weights": kwargs.get("marker_weights", "setup"), "summary": summarise(errors)}
        text = Path(res["ik"]).read_text(encoding="utf-8")
        if grid is not None:
            text = _exact_times(text, grid)
        return IKResult(text, errors, record)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def worst_markers(markers, time, names, model_marker_m) -> list[str]:
    """Per IK frame at ``time``, the marker (of ``names``, the trial has it) farthest from its
    model marker (``model_marker_m``: frames x markers x 3, OpenSim's marker locations)."""
    worst = []
    for i, ti in enumerate(time):
        k = int(np.argmin(np.abs(markers.time - ti)))
        best, best_e = "", -1.0
        for j, n in enumerate(names):
            if n not in markers.names:
                continue
            e = float(np.linalg.norm(model_marker_m[i, j] - markers.marker(n)[k]))
            if np.isfinite(e) and e > best_e:
                best, best_e = n, e
        worst.append(best)
    return worst


def _exact_times(text: str, grid: np.ndarray) -> str:
    """OpenSim's IK text with each frame's time replaced by the grid time it was given, in full
    precision (OpenSim writes 8 decimals, steps then differ by 1e-8 s)."""
    lines = text.splitlines(keepends=True)
    try:
        start = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader") + 2
    except StopIteration:
        return text
    for i in range(start, len(lines)):
        head, sep, rest = lines[i].lstrip().partition("\t")
        if not sep:
            continue
        t = grid[int(np.argmin(np.abs(grid - float(head))))]
        lines[i] = f"{t:.12g}\t{rest}"
    return "".join(lines)


def _ik_time_range(setup: Path):
    from .scaling import _setup_time_range

    return _setup_time_range(setup)
