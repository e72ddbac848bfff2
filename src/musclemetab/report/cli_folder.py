"""Reading what the command line wrote: ``analyse`` output folders as a study of their trials.

``musclemetab solve`` -> ``metabolics`` -> ``analyse`` leaves three folders per trial; the
last records the other two (``analyse.json``, :data:`~musclemetab.analysis.unit.ANALYSE_RECORD`:
each leg's solution and metabolics folders, its gait cycle, the body mass and height).
:func:`read_analyse_folders` reads one or more ``analyse`` output folders (of one leg, or the
parent of ``r/`` and ``l/`` of a both-legs solve) into a :class:`AnalyseFolders`: a
:class:`~.folder.StudyFolder` whose unit files are found through those records, so the
report's figures and tables are drawn from it as from a study folder:

* one unit per folder: subject and trial from the model's and the IK file's names
  (:func:`unit_names`: ``subject01_simbody.osim`` and ``subject01_walk1_ik.mot`` are subject
  ``subject01``, trial ``walk1``; the folder's name added to the trial when two folders share
  both), workflow the solve's;
* the results rows: the folder's ``results.csv`` (the study's columns, the legs added), with
  the ``quality`` a study gives (:func:`musclemetab.metabolics.plausibility.add_quality` of the legs'
  ``summary.json``);
* the per-muscle table: the folder's ``per_muscle.csv``;
* the settings ``study.json`` would record: the subjects' model, body mass, height and legs.

:func:`read_report_input` decides between a study folder and ``analyse`` folders, and says
in one line what to pass when a folder is neither.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputFileError, OptionError
from ..messages import name_list
from ..study_layout import PER_MUSCLE_FILE, RESULTS_CSV, STUDY_JSON, TIMESERIES_FILE, UNITS_FOLDER
from .folder import (
    RENAMED_PER_MUSCLE_COLUMNS,
    REQUIRED_COLUMNS,
    StudyFolder,
    _FAILURE_COLUMNS,
    _renamed,
    read_study_folder,
    with_figure_models,
)

__all__ = ["AnalyseFolders", "LegFiles", "read_analyse_folders", "read_report_input", "is_analyse_folder"]


@dataclass(frozen=True)
class LegFiles:
    """Where one leg's files are: its ``analyse`` folder (``timeseries.csv``), solution folder
    (``solution.sto``, ``summary.json``) and metabolics folder (``metabolics.sto``; ``None``
    when ``analyse`` was not given one), and its gait cycle (s)."""

    analysis: Path
    solution: Path
    metabolics: Path | None
    cycle: tuple[float, float, float]


@dataclass
class AnalyseFolders(StudyFolder):
    """``analyse`` output folders read as a study (:func:`read_analyse_folders`)."""

    #: ``{(subject, trial, workflow): {side or "": LegFiles}}``; ``""``: one leg, doubled
    units_legs: dict = field(default_factory=dict)
    per_muscle: object = None  # pandas.DataFrame, the folders' per_muscle.csv

    def _leg(self, folder: Path) -> LegFiles:
        for legs in self.units_legs.values():
            for leg in legs.values():
                if leg.analysis == folder:
                    return leg
        raise InputFileError(f"{folder}: not a leg of the analyse folders read")

    def leg_folders(self, row) -> dict[str, Path]:
        key = (str(row["subject"]), str(row["trial"]), str(row["workflow"]))
        return {side: leg.analysis for side, leg in self.units_legs[key].items()}

    def solution_folder(self, folder: Path) -> Path:
        return self._leg(folder).solution

    def metabolics_folder(self, folder: Path) -> Path:
        leg = self._leg(folder)
        if leg.metabolics is None:
            raise InputFileError(f"{folder.parent if folder.name in ('r', 'l') else folder}: analysed without "
                                 "--metabolics, so no metabolics.sto is known; run 'musclemetab analyse' again "
                                 "with --metabolics DIR")
        return leg.metabolics

    def unit_cycle(self, folder: Path) -> tuple[float, float, float]:
        return self._leg(folder).cycle

    def read_per_muscle(self):
        return self.per_muscle

    def report_inputs(self) -> list[tuple[str, Path]]:
        from ..analysis.unit import ANALYSE_RECORD
        from ..metabolics.solution import METABOLICS_STO
        from ..redundancy.solution import SOLUTION_FILE, SUMMARY_FILE

        named = []
        for source in self.sources:
            named += [(str(source / n), source / n) for n in (ANALYSE_RECORD, RESULTS_CSV, PER_MUSCLE_FILE)]
        for legs in self.units_legs.values():
            for leg in legs.values():
                named += [(str(leg.analysis / TIMESERIES_FILE), leg.analysis / TIMESERIES_FILE)]
                named += [(str(leg.solution / n), leg.solution / n) for n in (SUMMARY_FILE, SOLUTION_FILE)]
                if leg.metabolics is not None:
                    named.append((str(leg.metabolics / METABOLICS_STO), leg.metabolics / METABOLICS_STO))
        return named


def is_analyse_folder(path: str | os.PathLike) -> bool:
    """Whether ``path`` holds the record of ``musclemetab analyse``."""
    from ..analysis.unit import ANALYSE_RECORD

    return (Path(path) / ANALYSE_RECORD).is_file()


def _analysed(path: Path) -> bool:
    """Whether ``path`` holds the tables of ``musclemetab analyse`` (of one leg, or of ``r/``, ``l/``)."""
    from ..analysis.unit import ANALYSIS_FILE

    return any((path / leg / ANALYSIS_FILE).is_file() for leg in ("", "r", "l"))


def _not_readable(path: Path) -> str:
    """Why ``path`` is neither a study folder nor an ``analyse`` folder, and what to pass."""
    from ..analysis.unit import ANALYSE_RECORD

    if path.is_dir() and path.name in ("r", "l") and is_analyse_folder(path.parent):
        return (f"{path}: one leg of the analyse output folder {path.parent}, whose {ANALYSE_RECORD} records both "
                f"legs: pass {path.parent}")
    if path.is_dir() and _analysed(path):
        return (f"{path}: analysed by an earlier version, which left no {ANALYSE_RECORD} naming the solution and "
                "metabolics folders: run 'musclemetab analyse' again")
    what = "no such folder" if not path.is_dir() else "neither a study folder (results.csv, study.json)" \
        f" nor an analyse output folder ({ANALYSE_RECORD})"
    return (f"{path}: {what}; pass the output folder of 'musclemetab run STUDY.toml', or one or more output "
            "folders of 'musclemetab analyse --out'")


def read_report_input(paths, models=None) -> StudyFolder:
    """What a report is drawn from: a study folder (:func:`~.folder.read_study_folder`), or one
    or more ``analyse`` output folders (:func:`read_analyse_folders`). ``paths``: a folder or a
    list of folders. Raises :class:`InputFileError` in one line, naming the folder and what to
    pass, when a folder is neither."""
    paths = [Path(p) for p in ([paths] if isinstance(paths, (str, os.PathLike)) else paths)]
    if not paths:
        raise OptionError("give a study folder or one or more analyse output folders")
    if all(is_analyse_folder(p) for p in paths):
        return read_analyse_folders(paths, models=models)
    bad = next(p for p in paths if not is_analyse_folder(p))
    analysed = _analysed(bad) or (bad.name in ("r", "l") and is_analyse_folder(bad.parent))
    if len(paths) == 1 and not analysed:  # a study folder, or what says it is none
        return read_study_folder(bad, models=models)
    if (bad / STUDY_JSON).is_file() or (bad / UNITS_FOLDER).is_dir():
        raise OptionError(f"{bad}: a study folder among other folders; report a study alone, or pass only "
                          "output folders of 'musclemetab analyse --out'")
    raise InputFileError(_not_readable(bad))


def _read_table(path: Path, what: str):
    from ..io.csvfile import read_csv_file

    if not path.is_file():
        raise InputFileError(f"{path}: missing; run 'musclemetab analyse' again to write it")
    return read_csv_file(path, "run 'musclemetab analyse' again", what, dtype={"model": str, "muscle": str, "side": str})


def _leg_record(rec: dict, path: Path, record: Path) -> tuple[str, LegFiles, dict]:
    try:
        c = rec["cycle"]
        cycle = (float(c["start_s"]), float(c["toe_off_s"]), float(c["end_s"]))
        folder = str(rec["folder"])
        leg = LegFiles(analysis=path if folder == "." else path / folder, solution=Path(rec["solution"]),
                       metabolics=Path(rec["metabolics"]) if rec.get("metabolics") else None, cycle=cycle)
    except (KeyError, TypeError, ValueError):
        raise InputFileError(f"{record}: a leg without its folders or gait cycle; run 'musclemetab analyse' "
                             "again to rewrite it") from None
    _check_solution_unchanged(leg.solution, rec.get("solution_sha256"), path)
    return ("" if folder == "." else folder), leg, rec


def _check_solution_unchanged(solution: Path, digest, path: Path) -> None:
    """:class:`InputFileError` when the solution an ``analyse`` folder records (``digest``, the
    SHA-256 of its ``solution.sto``; absent in folders of earlier versions) has been solved again
    since: the folder's tables are of the former solution, the figures would mix the two."""
    from ..io.atomic import file_sha256
    from ..redundancy.solution import SOLUTION_FILE

    file = solution / SOLUTION_FILE
    if digest and file.is_file() and file_sha256(file) != digest:
        raise InputFileError(f"{path}: analysed from {solution}, which has been solved again since; run "
                             "'musclemetab metabolics' and 'musclemetab analyse' of it again")


def unit_names(model: str, ik: str) -> tuple[str, str]:
    """``(subject, trial)`` of a trial given on the command line, from its model's and IK file's
    names: the words (parted by ``_``, ``-``, ``.`` or a space) both names begin with name the
    subject, the IK file's other words the trial, less a word ``ik``
    (``subject01_simbody.osim``, ``subject01_walk1_ik.mot``: ``subject01``, ``walk1``). Names
    without a common beginning, or an IK name with nothing else: the model's name and the IK
    file's name."""
    import re

    m, t = Path(model).stem, Path(ik).stem
    mw, tw = re.split(r"[_\-. ]+", m), re.split(r"[_\-. ]+", t)
    n = 0
    while n < min(len(mw), len(tw)) and mw[n] and mw[n].lower() == tw[n].lower():
        n += 1
    rest = [w for w in tw[n:] if w and w.lower() != "ik"]
    if n == 0 or not rest:
        return m, t
    return "_".join(tw[:n]), "_".join(rest)


def named_files(model: str, ik: str) -> tuple[str, str]:
    """The files a command-line trial is named by (:func:`unit_names`): its model and IK files, or,
    when the IK file is the one ``musclemetab prepare`` wrote (its record ``prepare.json`` beside
    it), the lab's static trial and walking markers that record names (``subject01_static.trc``,
    ``subject01_walk1.trc``: subject ``subject01``, trial ``walk1``, not ``model`` and ``ik``)."""
    import json

    from ..mocap.prepare import PREPARE_RECORD

    record = Path(ik).parent / PREPARE_RECORD
    if record.is_file():
        try:
            doc = json.loads(record.read_text(encoding="utf-8"))
            if Path(doc["files"]["ik"]).name == Path(ik).name:
                return str(doc["inputs"]["static"]), str(doc["inputs"]["markers"])
        except (OSError, ValueError, KeyError, TypeError):  # not a record this version reads: the files' names
            pass
    return model, ik


def read_analyse_folders(paths, models=None) -> AnalyseFolders:
    """Read ``analyse`` output folders (each with ``analyse.json``) as a study of their trials
    (see the module's text). ``models``: the models the figures show, as for
    :func:`~.folder.read_study_folder`. Raises :class:`InputFileError` when a folder, its
    record, its tables or a leg's ``summary.json`` cannot be read."""
    import pandas as pd

    from ..analysis.unit import ANALYSE_RECORD
    from ..io.jsonfile import read_json_object
    from ..metabolics.plausibility import add_quality
    from ..redundancy.solution import read_summary

    paths = [Path(p) for p in ([paths] if isinstance(paths, (str, os.PathLike)) else paths)]
    remedy = "run 'musclemetab analyse' again to rewrite it"
    units, keys, rows, muscles, subjects, notes = {}, [], [], [], {}, []
    software: dict = {}
    basal = None
    for path in paths:
        record = path / ANALYSE_RECORD
        doc = read_json_object(record, remedy=remedy)
        legs_rec = doc.get("legs")
        if not isinstance(legs_rec, list) or not legs_rec:
            raise InputFileError(f"{record}: no legs recorded; {remedy}")
        legs = dict(_leg_record(r, path, record)[:2] for r in legs_rec if isinstance(r, dict))
        first = legs_rec[0]
        summaries = {side: read_summary(leg.solution, missing="missing",
                                        remedy=f"the solution {path} was analysed from is gone; solve again")
                     for side, leg in legs.items()}
        summary = next(iter(summaries.values()))
        software = software or dict(summary.software or {})
        workflow = summary.workflow_name or "solve"
        subject, trial = unit_names(*named_files(str(first.get("model")), str(first.get("ik"))))
        if (subject, trial, workflow) in units:
            trial = f"{trial} ({path.name})"
        key = (subject, trial, workflow)
        keys.append(key)
        units[key] = legs
        table = _read_table(path / RESULTS_CSV, "results table")
        for k, (col, val) in enumerate(zip(("subject", "trial", "workflow"), key)):
            table.insert(k, col, val)
        missing = [c for c in REQUIRED_COLUMNS if c not in table.columns]
        if missing:
            raise InputFileError(f"{path / RESULTS_CSV}: missing column{'s' if len(missing) > 1 else ''} "
                                 f"{name_list(missing)}; {remedy}")
        rows.append(add_quality(table, list(summaries.values())))
        pm = _renamed(_read_table(path / PER_MUSCLE_FILE, "per-muscle table"), RENAMED_PER_MUSCLE_COLUMNS)
        for k, (col, val) in enumerate(zip(("subject", "trial", "workflow"), key)):
            pm.insert(k, col, val)
        muscles.append(pm)
        sides = [str(r.get("side")) for r in legs_rec]
        mass, height = first.get("body_mass_kg"), first.get("height_m")
        rec = subjects.setdefault(subject, {"model": first.get("model"), "body_mass_kg": mass, "height_m": height,
                                            "side": "both" if len(sides) > 1 else sides[0], "trials": [],
                                            "emg_files": {}, "analyse_folders": []})
        if (rec["body_mass_kg"], rec["height_m"]) != (mass, height):
            notes.append(f"{path}: analysed with body mass {mass} kg and height {height} m, the first folder of "
                         f"subject {subject} with {rec['body_mass_kg']} kg and {rec['height_m']} m; the "
                         "settings show the first")
        rec["trials"].append(trial)
        rec["analyse_folders"].append(str(path))
        basal = basal or first.get("basal")
    results = pd.concat(rows, ignore_index=True)
    for c in results.columns:
        if c.endswith(("_pct", "_W_per_kg", "_per_m", "_m_per_s", "_W")):
            results[c] = pd.to_numeric(results[c], errors="coerce")
    settings = {"name": f"subject {keys[0][0]}, trial {keys[0][1]}" if len(paths) == 1 else
                f"{len(paths)} analyse folders",
                "workflows": list(dict.fromkeys(k[2] for k in keys)),
                "models": list(dict.fromkeys(results["model"].astype(str))),  # as metabolics --models gave them
                "basal": basal, "subjects": subjects, "software": software,
                "analyse_folders": {str(p): {side or "one leg": {"solution": str(leg.solution),
                                                                 "metabolics": leg.metabolics and str(leg.metabolics)}
                                             for side, leg in units[k].items()} for p, k in zip(paths, keys)}}
    base = paths[0] if len(paths) == 1 else Path(os.path.commonpath([p.resolve() for p in paths]))
    study = AnalyseFolders(path=base, settings=settings, results=results,
                           failures=pd.DataFrame(columns=_FAILURE_COLUMNS), notes=notes, sources=paths,
                           units_legs=units, per_muscle=pd.concat(muscles, ignore_index=True))
    return with_figure_models(study, models, ", ".join(str(p / RESULTS_CSV) for p in paths))
