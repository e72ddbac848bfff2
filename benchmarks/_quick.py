"""What the benchmarks' ``--quick`` runs share: the smallest problem that still exercises a
measurement (the test suite runs every benchmark so, ``tests/test_benchmarks.py``).

A quick run solves :data:`WINDOW` of the example subject's normal trial: ``solve_files(...,
window=window(ex))`` or ``musclemetab solve --window`` on the trial's own files, whose geometry
the package's cache (``$MUSCLEMETAB_CACHE``) holds once any run computed it; where a measurement
needs files that cover a short window only (a study, EMG-TEN), :func:`cropped_trial` writes them,
always with the same content, so that their geometry is computed by OpenSim once per cache.
"""

from __future__ import annotations

import json
from pathlib import Path

#: the quick window: seconds of the example subject's normal trial (its IK starts at 0.57 s)
WINDOW = (0.6, 0.8)
#: a cropped trial starts this long after its IK's first frame and lasts :data:`WINDOW`'s length
_START_AFTER_S = 0.03


def window_arg() -> str:
    """:data:`WINDOW` as the command line's ``--window T0:T1``."""
    return f"{WINDOW[0]:g}:{WINDOW[1]:g}"


def cropped_trial(ex, trial: str, folder: Path, kinds=("ik", "id")) -> dict:
    """``{kind: path}`` and ``window_s`` (first and last time kept): the trial's files (``kinds`` of ``ik``, ``id``, ``emg``) cut to
    :data:`WINDOW`'s length from 0.03 s into its motion (the normal trial: :data:`WINDOW`),
    written into ``folder``. The same trial gives files of the same content on every call."""
    from musclemetab.io import read_storage, write_storage

    folder.mkdir(parents=True, exist_ok=True)
    t0 = float(read_storage(ex.ik[trial]).index[0]) + _START_AFTER_S
    t1 = t0 + (WINDOW[1] - WINDOW[0])
    out = {"window_s": (t0, t1)}
    for kind in kinds:
        path = getattr(ex, kind)[trial]
        table = read_storage(path)
        keep = table[(table.index >= t0 - 1e-9) & (table.index <= t1 + 1e-9)]
        out[kind] = folder / Path(path).name
        write_storage(out[kind], keep, in_degrees=bool(table.attrs.get("in_degrees")))
    return out


def tiny_study(ex, folder: Path, workflows=("effort-gen",), models=("UM10",), extra: str = "") -> Path:
    """A study of the example subject's normal trial cropped to :data:`WINDOW`
    (:func:`cropped_trial`): its ``study.toml`` in ``folder``, output in ``folder/out``. Its
    subject has the example's passive calibration and tendon stiffness (for EFFORT-CAL and
    EFFORT-TEN); its gait events are the ends of the window the solve keeps (0.05 s
    in from each end of the files) and their middle (a window too short for the events' estimate
    from the ankle moment). ``extra``: more top-level TOML lines."""
    files = cropped_trial(ex, "normal", folder / "data")
    t0, t1 = files["window_s"]

    def value(v):  # TOML values: JSON strings and numbers are valid TOML
        return json.dumps(v if isinstance(v, (int, float)) else str(v))

    lines = ['name = "quick"', 'output = "out"', f"workflows = {json.dumps(list(workflows))}",
             f"models = {json.dumps(models if isinstance(models, str) else list(models))}", *([extra] if extra else []), "", "[[subjects]]",
             'name = "example"', f"model = {value(ex.model)}", f"body_mass_kg = {ex.body_mass_kg}",
             f"height_m = {ex.height_m}", f"passive = {value(ex.passive_moments_mat)}", 'tendon_stiffness = "example"',
             "", "[[subjects.trials]]", 'name = "normal"', f"ik = {value(files['ik'])}", f"id = {value(files['id'])}",
             *(f"{k} = {v:.4f}" for k, v in zip(("start_s", "toe_off_s", "end_s"), (t0 + 0.05, (t0 + t1) / 2, t1 - 0.05)))]
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "study.toml"
    path.write_text("\n".join(lines) + "\n")
    return path
