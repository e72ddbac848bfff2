"""A :class:`~.problem.Problem` kept beside its result: ``problem.json``
(:meth:`.result.Result.write`; :func:`.problem.load_result` and :func:`.problem.read_problem`
read it back).

``problem.json`` names the input files with their SHA-256 hashes and holds the keywords of
:func:`~.problem.load_problem` (window, side, DOFs, workflow, EMG mapping...), the solver
options, goals and EMG settings given, the options the problem was solved with and its muscle
parameters (which a sample or an estimate may have changed). :func:`.problem.read_problem` calls
:func:`~.problem.load_problem` again with them, so the rebuilt problem went through every
check of the first one and its geometry comes from the cache; its parameters and options are
then set to those recorded. The arrays themselves are not stored: the files are the source of
the problem, the folder stays small, and a changed input file is noticed (its hash) instead of
standing beside a result it did not give. A folder whose files are gone or changed loads
without its problem (``None``, with a warning naming the file); one written before
``problem.json`` existed loads without it.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from pathlib import Path

import numpy as np

from ..errors import MusclemetabWarning

__all__ = ["PROBLEM_FILE", "PROBLEM_FORMAT", "problem_document", "write_problem", "problem_keywords"]

PROBLEM_FILE = "problem.json"
PROBLEM_FORMAT = "musclemetab.redundancy.problem"
PROBLEM_VERSION = 1
#: the keywords of load_problem that name files (besides the model and the trials')
_FILE_KEYS = ("passive", "tendon_stiffness_file", "external_loads", "grf", "assistance", "emg_mapping")
#: the keywords that are pairs (JSON lists in the file)
_TUPLES = ("window", "cycle_duration_s", "assistance_cycle_s")


class _NotKept(Exception):
    """A setting that ``problem.json`` cannot hold (an in-memory object)."""


def _plain(value, what: str):
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if type(value) in (type(Path()), Path):
        return str(value)
    if isinstance(value, (list, tuple)):
        return [_plain(v, what) for v in value]
    if isinstance(value, dict):
        return {str(k): _plain(v, what) for k, v in value.items()}
    raise _NotKept(f"{what} is an in-memory {type(value).__name__}")


def _fields(obj, what: str) -> dict | None:
    """The fields of a frozen settings dataclass (``None`` stays ``None``); an energy goal is not kept."""
    if obj is None:
        return None
    if getattr(obj, "energy", None) is not None:
        raise _NotKept(f"{what} holds an energy goal")
    return {f.name: _plain(getattr(obj, f.name), what) for f in dataclasses.fields(obj) if f.name != "energy"}


def problem_document(problem) -> dict:
    """The content of ``problem.json`` of ``problem``; ``{"kept": false, "reason": ...}`` when
    a setting is an in-memory object (e.g. an energy goal, a :class:`~musclemetab.emg.RawEmgPath`)."""
    from ..io.atomic import file_sha256

    inputs = dict(problem.inputs)
    try:
        emg = inputs.pop("emg", None)
        keywords = {k: _plain(v, k) for k, v in inputs.items() if k not in ("options", "goals")}
        goals = inputs.get("goals")
        doc = {"format": PROBLEM_FORMAT, "format_version": PROBLEM_VERSION, "kept": True, "keywords": keywords,
               "options": _fields(inputs.get("options"), "the options"),
               "goals": _fields(goals and goals.resolved(problem.emg_mode), "the goals"),  # the scheme solved
               "emg": None if emg is None else emg.to_dict(),
               "solved_options": _fields(problem.options, "the options"),
               "parameters": {"names": list(problem.parameters.names),
                              **{f: [float(v) for v in np.asarray(getattr(problem.parameters, f))]
                                 for f in _parameter_fields()}}}
    except _NotKept as exc:
        return {"format": PROBLEM_FORMAT, "format_version": PROBLEM_VERSION, "kept": False,
                "reason": f"{exc}; load_problem again to rebuild it"}
    keywords["model"] = _absolute(keywords["model"])
    keywords["trials"] = [{k: v if k == "label" else _absolute(v) for k, v in t.items()} for t in keywords["trials"]]
    keywords.update({k: _absolute(keywords.get(k)) for k in _FILE_KEYS})
    files = [keywords["model"], *(v for t in keywords["trials"] for k, v in t.items() if k != "label" and v),
             *(keywords.get(k) for k in _FILE_KEYS)]
    doc["sha256"] = {f: file_sha256(f) for f in files if isinstance(f, str) and Path(f).is_file()}
    return doc


def _absolute(value):
    """A file's absolute path, as the solve's record names it (the folder may be read from
    elsewhere; links kept as named: :func:`musclemetab.io.source_path`); other values as they are."""
    from ..io import source_path

    return str(source_path(value)) if isinstance(value, str) and Path(value).is_file() else value


def _parameter_fields():
    from .parameters import PARAMETER_FIELDS

    return tuple(PARAMETER_FIELDS)


def write_problem(problem, out_dir) -> Path:
    """Write ``out_dir/problem.json`` (atomically, listed as the package's)."""
    import json

    from ..io import atomic_write_text
    from ..io.jsonfile import json_ready

    path = Path(out_dir) / PROBLEM_FILE
    atomic_write_text(path, json.dumps(json_ready(problem_document(problem)), indent=1) + "\n", mark=True)
    return path


def problem_keywords(out_dir) -> dict | None:
    """What ``out_dir/problem.json`` records, checked: ``{"keywords", "options", "goals", "emg",
    "solved_options", "parameters"}`` (the settings as dataclasses, the parameters as
    :class:`~.parameters.MuscleTendonParameters`), or ``None`` with a
    :class:`~musclemetab.errors.MusclemetabWarning` saying why (no such file, a setting not kept,
    an input file gone or changed). :func:`.problem.read_problem` rebuilds the problem from it."""
    from ..io.atomic import file_sha256
    from ..io.jsonfile import read_json_object
    from .emg_ten import EmgTenSettings
    from .goals import Goals
    from .ipopt import SolverOptions
    from .parameters import MuscleTendonParameters

    path = Path(out_dir) / PROBLEM_FILE
    if not path.is_file():
        warnings.warn(f"{out_dir}: no {PROBLEM_FILE} (written before results kept their problem); the result loads "
                      "without its problem: solve again to keep it", MusclemetabWarning, stacklevel=3)
        return None
    doc = read_json_object(path)
    if doc.get("format") != PROBLEM_FORMAT or not doc.get("kept"):
        warnings.warn(f"{path}: the problem was not kept ({doc.get('reason', 'not a problem file')}); the result "
                      "loads without it", MusclemetabWarning, stacklevel=3)
        return None
    for name, digest in doc["sha256"].items():
        if not Path(name).is_file() or file_sha256(name) != digest:
            warnings.warn(f"{path}: the input file {name} is {'gone' if not Path(name).is_file() else 'changed'} "
                          "since the solve; the result loads without its problem (solve again where the files are)",
                          MusclemetabWarning, stacklevel=3)
            return None
    keywords = {k: tuple(v) if isinstance(v, list) and k in _TUPLES else v for k, v in doc["keywords"].items()}
    p = doc["parameters"]
    return {"keywords": keywords,
            "options": None if doc["options"] is None else SolverOptions(**doc["options"]),
            "goals": None if doc["goals"] is None else Goals(**doc["goals"]),
            "emg": None if doc["emg"] is None else EmgTenSettings.from_dict(doc["emg"]),
            "solved_options": SolverOptions(**doc["solved_options"]),
            "parameters": MuscleTendonParameters(names=tuple(p["names"]),
                                                 **{f: np.asarray(p[f], dtype=float) for f in _parameter_fields()})}
