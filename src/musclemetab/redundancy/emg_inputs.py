"""Inputs of EMG-informed problems: the EMG mapping, EMG tables, trial labels and checks."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import DataMismatchError, InputFileError, OptionError, UnknownMuscleError
from ..messages import name_list
from .result import PARAMETERS_FILE

__all__ = ["resolve_emg_mapping", "mapping_for_muscles", "emg_at_nodes", "path_list", "trial_labels", "one_model",
           "mapped_emg_table", "check_emg_window", "check_emg_range"]


def resolve_emg_mapping(mapping: str | Mapping[str, Sequence[str] | str] | os.PathLike = "default") -> dict:
    """``"default"`` (vastus intermedius <- ``VI_a``), ``"authors"`` (<- ``ES``, the mapping
    of the published example results), a ``{muscle: [channel, ...]}`` mapping, or a JSON
    file holding one. Returns ``{muscle: [channels]}``."""
    from ..emg import AUTHORS_EMG_MAPPING, DEFAULT_EMG_MAPPING

    if isinstance(mapping, (str, os.PathLike)):
        key = str(mapping).strip()
        if key.lower() == "default":
            return {m: list(c) for m, c in DEFAULT_EMG_MAPPING.items()}
        if key.lower() == "authors":
            return {m: list(c) for m, c in AUTHORS_EMG_MAPPING.items()}
        path = Path(key)
        if path.suffix.lower() == ".json" or path.is_file():
            from ..io.jsonfile import read_json_object

            form = 'a JSON object {"muscle": ["channel", ...]}'
            mapping = read_json_object(
                path, missing=f"no such EMG mapping file; give 'default', 'authors' or {form}",
                remedy=f"an EMG mapping is {form}")
        else:
            raise OptionError(f"EMG mapping '{key}' is not 'default', 'authors' or a JSON file; "
                              "give one of these")
    if not isinstance(mapping, Mapping) or not mapping:
        raise OptionError("the EMG mapping is empty; give {muscle: [channel, ...]} for at least one muscle")
    out = {}
    for m, chans in mapping.items():
        chans = [chans] if isinstance(chans, str) else list(chans or [])
        if not chans or not all(isinstance(c, str) and c for c in chans):
            raise OptionError(f"EMG mapping: muscle '{m}' needs one or more channel names, not {chans!r}")
        out[str(m)] = chans
    return out


def mapping_for_muscles(emg_mapping, mapping: dict, muscles: Sequence[str]) -> dict:
    """The named mappings (``default``, ``authors``) placed on other models' muscle names
    through the anatomical muscle table when the study's names are not in the problem. Muscles
    of a mapping that the problem lacks are refused (:class:`UnknownMuscleError`)."""
    from ..properties import default_emg_mapping, resolve_muscles

    named = isinstance(emg_mapping, str) and emg_mapping.strip().lower() in ("default", "authors")
    if named and not set(mapping) <= set(muscles):
        mapping = default_emg_mapping(muscles)
        if emg_mapping.strip().lower() == "authors":
            mapping.update({r.name: ["ES"] for r in resolve_muscles(muscles, warn=False)
                            if r.anatomical == ("vastus_intermedius",)})
    unknown = [m for m in mapping if m not in muscles]
    if unknown:
        raise UnknownMuscleError(
            f"EMG mapping: muscle{'s' if len(unknown) > 1 else ''} {name_list(unknown)} not among the muscles of "
            f"the problem ({', '.join(list(muscles)[:6])} ...); map channels to model muscle names such as soleus_r"
        )
    return mapping


def path_list(x, what: str) -> list:
    """One path or a sequence of them as a list (``None`` gives ``[]``); :class:`OptionError`
    naming ``what`` for anything else."""
    if x is None:
        return []
    if isinstance(x, (str, os.PathLike)):
        return [x]
    try:
        return list(x)
    except TypeError:
        raise OptionError(f"{what} must be a path or a list of paths, not {x!r}") from None


def trial_labels(ik_paths, labels) -> list[str]:
    """The trials' names, one per IK file: ``labels`` checked (as many, distinct, usable as
    folder names, not the parameters file's name), or the IK files' stems."""
    if labels is None:
        labels = [Path(p).stem for p in ik_paths]
    labels = [str(x) for x in path_list(labels, "labels")]
    if len(labels) != len(ik_paths):
        raise OptionError(f"{len(labels)} trial labels for {len(ik_paths)} trials; give one label per trial")
    bad = [x for x in labels if not x or x in (".", "..") or "/" in x or "\\" in x]
    if bad:
        raise OptionError(f"trial label {bad[0]!r} cannot name a folder; use plain names")
    dup = sorted({x for x in labels if labels.count(x) > 1})
    if dup:
        raise OptionError(f"trial label{'s' if len(dup) > 1 else ''} {name_list(dup)} used twice (IK files with "
                          "the same name?); give distinct labels")
    if PARAMETERS_FILE in labels:
        raise OptionError(f"'{PARAMETERS_FILE}' cannot be a trial label")
    return labels


def check_emg_range(df, t0: float, tf: float, tol: float, what: str) -> None:
    """Reject mapped EMG outside ``[0, 1]`` (by more than ``tol``) inside ``[t0, tf]``."""
    t = np.asarray(df.index, dtype=float)
    sel = (t >= t0 - 1e-9) & (t <= tf + 1e-9)
    channels = df.attrs.get("channels", {})
    for m in df.columns:
        x = df[m].to_numpy(dtype=float)[sel]
        if x.size == 0:
            continue
        bad = np.flatnonzero((x < -tol) | (x > 1.0 + tol))
        if bad.size:
            k = bad[np.argmax(np.abs(x[bad] - 0.5))]
            chans = channels.get(m, [m])
            raise DataMismatchError(
                f"{what}: EMG of {m} (channel{'s' if len(chans) > 1 else ''} {', '.join(chans)}) is "
                f"{x[k]:.4g} at t = {t[sel][k]:.4g} s, outside [0, 1]; EMG-TEN tracks normalised envelopes: "
                "normalise the channel (e.g. to its MVC peak), clip small filtering undershoots to 0, or map "
                "another channel"
            )


def mapped_emg_table(emg, mapping, path_label: str):
    """Read (if a path: raw EMG processed when it is a :class:`~musclemetab.emg.RawEmgPath`,
    :func:`~musclemetab.emg.read_emg`) and map an EMG table to ``{muscle: signal}``; errors
    name the file."""
    from ..emg import map_channels, read_emg

    if isinstance(emg, (str, os.PathLike)):
        p = Path(emg)
        if not p.is_file():
            raise InputFileError(f"{p}: no such EMG file; check the --emg paths")
        df = read_emg(emg)
    else:
        df = emg.copy()
        df.attrs.update(emg.attrs)
        df.attrs.setdefault("path", path_label)
    if "channels" in df.attrs and set(df.columns) == set(mapping):
        return df  # already mapped
    return map_channels(df, mapping)


def one_model(model_path, n_trials: int) -> Path:
    """One model for all trials; a list with one path per trial must name the same model."""
    from ..io.atomic import file_sha256

    if isinstance(model_path, (str, os.PathLike)):
        return Path(model_path)
    paths = [Path(p) for p in path_list(model_path, "model_path")]
    if len(paths) not in (1, n_trials):
        raise OptionError(f"{len(paths)} models for {n_trials} trials; give one model (or one per trial)")
    from ..model import check_model_path

    for p in paths:
        check_model_path(p)
    digests = [file_sha256(p) for p in paths]
    for p, d in zip(paths[1:], digests[1:]):
        if d != digests[0]:
            raise DataMismatchError(
                f"the trials come from different models ({paths[0]} and {p} differ); EMG-TEN estimates one set of "
                "parameters per subject model: solve trials of different models separately"
            )
    return paths[0]


def check_emg_window(table, ik_time, emg_label: str, ik_label: str) -> None:
    """Raise :class:`DataMismatchError` unless the EMG ``table`` covers the trial's IK frames."""
    t = np.asarray(table.index, dtype=float)
    t0, tf = float(ik_time[0]), float(ik_time[-1])
    if t.size == 0 or t[0] > t0 + 1e-6 or t[-1] < tf - 1e-6:
        have = f"{t[0]:g}-{t[-1]:g} s" if t.size else "no samples"
        raise DataMismatchError(
            f"{emg_label}: the EMG covers {have} but the trial window (the IK file {ik_label}) is "
            f"{t0:g}-{tf:g} s; the EMG must cover the whole window: use the EMG of the same trial, or crop the IK"
        )


def emg_at_nodes(emg, mapping: dict, inputs, muscles: Sequence[str], what: str, ik_label: str,
                 range_tolerance: float = 0.0) -> np.ndarray:
    """EMG of ``muscles`` at the control nodes ``0 ... N-1`` of a trial, ``(N, len(muscles))``.

    ``emg`` is a file or a time-indexed table (mapped with ``mapping`` when it is not already);
    the EMG must cover the trial's window and lie within ``[0, 1]`` (by ``range_tolerance``)
    there. It is linearly interpolated at the node times. Errors name ``what``.
    """
    table = mapped_emg_table(emg, mapping, what)
    t0, tf = inputs.window_s
    check_emg_window(table, inputs.frame_time_s, what, ik_label)
    check_emg_range(table, t0, tf, range_tolerance, what)
    N = inputs.n_intervals
    te = np.asarray(table.index, dtype=float)
    return np.column_stack([np.interp(inputs.mesh_time_s[:N], te, table[m].to_numpy(dtype=float)) for m in muscles])
