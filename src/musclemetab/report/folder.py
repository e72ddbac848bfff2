"""Reading a study folder: the one place of the report that knows its layout.

:func:`read_study_folder` reads ``study.json``, ``results.csv`` and ``failures.csv``; the
:class:`StudyFolder` it returns reads the rest on demand: the unit folders
(``units/<subject>/<trial>/<workflow>``, one per leg for a subject solved on both sides) with
their ``unit.json``, ``timeseries.csv`` and ``summary.json``, ``per_muscle.csv``, and what
``study.json`` records of each subject (body mass, solved side, EMG files and mapping). The
file names are those of :mod:`musclemetab.study_layout`. :func:`input_files` lists every
file the report is drawn from (the content key of :mod:`.build` hashes them).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputFileError, MissingColumnError, OptionError
from ..io.csvfile import read_csv_file
from ..messages import name_list
from ..redundancy.record import SolveRecord
from ..redundancy.solution import SUMMARY_FILE, read_summary
from ..study_layout import (
    FAILURES_CSV,
    PER_MUSCLE_FILE,
    RESULTS_CSV,
    STUDY_JSON,
    TIMESERIES_FILE,
    UNIT_FILE,
    UNITS_FOLDER,
    unit_path,
)

__all__ = ["StudyFolder", "read_study_folder", "with_figure_models", "input_files", "add_leg_timeseries", "REQUIRED_COLUMNS",
           "RENAMED_RESULTS_COLUMNS", "RENAMED_PER_MUSCLE_COLUMNS"]

#: Columns ``results.csv`` must have; the others are used when present.
REQUIRED_COLUMNS = ("subject", "trial", "workflow", "model", "status", "whole_body_W_per_kg")
#: Column names of ``results.csv`` written by earlier releases (one name then stood for
#: rates of different scope in different files) and their names now: a study folder of an
#: older version is read through this mapping. ``one_leg_mean_W`` held the per-muscle basal
#: heat under the muscle basal rule: it is renamed only for rows of the other rules.
RENAMED_RESULTS_COLUMNS = {
    "mean_W_per_kg": "whole_body_W_per_kg",
    "mean_W_per_kg_no_basal": "whole_body_no_basal_W_per_kg",
    "one_leg_mean_W": "leg_muscles_W",
}
#: The same for ``per_muscle.csv``.
RENAMED_PER_MUSCLE_COLUMNS = {"mean_W": "muscle_W", "mean_W_per_kg": "muscle_W_per_kg"}
_FAILURE_COLUMNS = ["subject", "trial", "workflow", "status", "reason"]


@dataclass
class StudyFolder:
    """A study folder's contents: settings, the results (all rows) and the failures; the
    other files are read by the methods."""

    path: Path
    settings: dict
    results: object  # pandas.DataFrame
    failures: object  # pandas.DataFrame: subject, trial, workflow, status (failed, interrupted), reason
    notes: list[str] = field(default_factory=list)
    #: The models the figures show (:func:`report_models`): ``None`` for the default.
    figure_models: list[str] | None = None
    #: The folders read: the study folder, or the ``analyse`` output folders (:mod:`.cli_folder`).
    sources: list[Path] = field(default_factory=list)

    # ------------------------------------------------------------------ the tables
    @property
    def ok(self):
        """Rows of the results whose status is ``ok``."""
        r = self.results
        return r[r["status"].astype(str).str.lower() == "ok"]

    @property
    def name(self) -> str:
        return str(self.settings.get("name") or self.path.name)

    def workflows(self) -> list[str]:
        """The workflows of ``study.json`` in its order, then those only in the results."""
        from .figures import _ordered_workflows

        listed = [str(w) for w in self.settings.get("workflows") or []]
        present = _ordered_workflows(self.results["workflow"].astype(str))
        return listed + [w for w in present if w not in listed] if listed else present

    def models(self) -> list[str]:
        """The metabolic models of ``study.json`` in its order, then those only in the results."""
        from .figures import _ordered_models

        listed = self.settings.get("models")
        present = _ordered_models(self.results["model"].astype(str))
        if isinstance(listed, (list, tuple)) and listed:
            listed = [str(m) for m in listed]
            return listed + [m for m in present if m not in listed]
        return present

    def shown_models(self) -> list[str]:
        """The models the figures show, in the order of :meth:`models`: those asked for
        (``figure_models``: the report's ``--models``, else ``[report] models`` of the study
        file as ``study.json`` records it), else the paper's six
        (:data:`~musclemetab.metabolics.registry.STUDY_MODELS`) present; all present when none of
        the six is."""
        from ..metabolics.registry import STUDY_MODELS

        present = self.models()
        asked = self.figure_models if self.figure_models is not None else _recorded_report_models(self.settings)
        if asked is None:
            six = [m for m in present if m in STUDY_MODELS]
            return six or present
        return [m for m in present if m in asked]

    def subjects(self) -> list[str]:
        """The subjects of the results, in the order of ``study.json``."""
        subjects = self.settings.get("subjects")
        listed = list(subjects) if isinstance(subjects, dict) else []
        present = _unique(self.results["subject"])
        return [s for s in listed if s in present] + [s for s in present if s not in listed]

    def preferred_trial(self, ok) -> str:
        """``preferred_trial`` of ``study.json`` when among the rows ``ok``, else
        :func:`musclemetab.report.figures.preferred_trial`."""
        from .figures import preferred_trial

        pt = self.settings.get("preferred_trial")
        if isinstance(pt, str) and pt in set(ok["trial"].astype(str)):
            return pt
        return preferred_trial(ok)

    def read_per_muscle(self):
        """``per_muscle.csv`` as a table, or ``None`` when the study has none; raises
        :class:`InputFileError` when it cannot be read."""
        import pandas as pd

        path = self.path / PER_MUSCLE_FILE
        if not path.is_file():
            return None
        table = read_csv_file(path, "run the study again to rewrite it", dtype={"subject": str, "trial": str,
                                                                               "workflow": str, "model": str})
        return _renamed(table, RENAMED_PER_MUSCLE_COLUMNS)

    # ------------------------------------------------------------------ study.json
    def subject_record(self, subject) -> dict:
        """What ``study.json`` records of a subject (``{}`` when nothing)."""
        subjects = self.settings.get("subjects")
        rec = subjects.get(str(subject)) if isinstance(subjects, dict) else None
        return rec if isinstance(rec, dict) else {}

    def body_mass(self, subject) -> float | None:
        """The subject's body mass (kg) recorded in ``study.json``, or ``None``."""
        try:
            mass = float(self.subject_record(subject).get("body_mass_kg"))
        except (TypeError, ValueError):
            return None
        return mass if np.isfinite(mass) and mass > 0 else None

    def solves_both_legs(self, subject) -> bool:
        """Whether ``study.json`` records ``side = "both"`` for the subject."""
        return self.subject_record(subject).get("side") == "both"

    def emg_file(self, subject, trial) -> Path | None:
        """The trial's EMG file recorded in ``study.json`` (``emg_files``), or ``None``; a
        :class:`~musclemetab.emg.RawEmgPath` when its ``emg_processing`` is ``raw``."""
        from ..emg import emg_source

        record = self.subject_record(subject)
        path = (record.get("emg_files") or {}).get(trial)
        return emg_source(self.resolve(path), (record.get("emg_processing") or {}).get(trial, "envelope")) \
            if path else None

    def emg_mapping(self, subject):
        """The subject's EMG mapping recorded in ``study.json`` (a name or a file; ``"default"``)."""
        return self.subject_record(subject).get("emg_mapping") or "default"

    def resolve(self, path) -> Path:
        """A path recorded in study.json: as given when absolute, else relative to the study folder."""
        p = Path(str(path))
        return p if p.is_absolute() else self.path / p

    # ------------------------------------------------------------------ unit folders
    def leg_folders(self, row) -> dict[str, Path]:
        """The row's unit folders by leg: ``{"": folder}`` for one leg solved (and doubled),
        ``{"r": ..., "l": ...}`` for a row adding both legs (``unit_dir`` holds the legs' folders)."""
        rel = row.get("unit_dir") if hasattr(row, "get") else None
        if isinstance(rel, str) and rel.strip():
            folder = self.path / rel
        else:
            folder = self.path / unit_path(row["subject"], row["trial"], row["workflow"])
        legs = {s: folder / s for s in ("r", "l") if (folder / s / UNIT_FILE).is_file()}
        return legs if legs and not (folder / UNIT_FILE).is_file() else {"": folder}

    def unit_folder(self, row) -> Path:
        """The row's unit folder; for a row adding both legs, the first leg's (right)."""
        return next(iter(self.leg_folders(row).values()))

    def solution_folder(self, folder: Path) -> Path:
        """The folder of a leg's solution (``solution.sto``, ``summary.json``): the unit folder itself."""
        return folder

    def metabolics_folder(self, folder: Path) -> Path:
        """The folder of a leg's ``metabolics.sto``: the unit folder itself."""
        return folder

    def load_solution(self, folder: Path):
        """The :class:`~musclemetab.redundancy.solution.Solution` of a leg's unit folder."""
        from ..redundancy.solution import Solution

        return Solution.load(self.solution_folder(folder))

    def unit_cycle(self, folder: Path) -> tuple[float, float, float]:
        """The gait cycle (start, toe-off, end; s) recorded in the unit's ``unit.json``."""
        from ..io.jsonfile import read_json_object

        rec = read_json_object(folder / UNIT_FILE, missing="missing", remedy="run the study again to rewrite it")
        c = rec.get("cycle") or {}
        try:
            return float(c["start_s"]), float(c["toe_off_s"]), float(c["end_s"])
        except (KeyError, TypeError, ValueError):
            raise InputFileError(f"{folder / UNIT_FILE}: no gait cycle (cycle.start_s, toe_off_s, end_s)") from None

    def timeseries(self, row):
        """The row's rates over the cycle (``timeseries.csv``) of both legs, on the first leg's
        cycle (:func:`add_leg_timeseries`: the solved leg and itself half a cycle later, or the
        two solved legs)."""
        return add_leg_timeseries({s: _read_timeseries(f) for s, f in self.leg_folders(row).items()})

    def muscle_rates(self, row) -> dict:
        """Each muscle's metabolic rate without basal heat (W) over the gait cycle of the row's
        (first) leg, from the unit's ``metabolics.sto``: ``{model: table}``, each table indexed
        by the cycle percentage (the nodes inside the cycle), one column per muscle
        (``total_no_basal`` of the file; ``total - basal`` in the files of earlier releases,
        whose ``total`` held the per-muscle basal heat)."""
        from ..io.storage import read_storage
        from ..metabolics.solution import METABOLICS_STO, TOTAL_NO_BASAL

        folder = self.unit_folder(row)
        start, _, end = self.unit_cycle(folder)
        path = self.metabolics_folder(folder) / METABOLICS_STO
        if not path.is_file():
            raise InputFileError(f"{path}: missing; run the unit again to write it")
        table = read_storage(path)
        t = np.asarray(table.index, float)
        table = table[(t >= start - 1e-9) & (t <= end + 1e-9)]
        pct = 100.0 * (np.asarray(table.index, float) - start) / (end - start)
        out: dict = {}
        for col in table.columns:
            parts = str(col).split("/")
            if len(parts) == 3 and parts[2] == TOTAL_NO_BASAL:
                out.setdefault(parts[0], {})[parts[1]] = table[col].to_numpy(float)
            elif len(parts) == 3 and parts[2] == "total" and f"{parts[0]}/{parts[1]}/basal" in table.columns:
                out.setdefault(parts[0], {})[parts[1]] = (
                    table[col].to_numpy(float) - table[f"{parts[0]}/{parts[1]}/basal"].to_numpy(float))
        if not out:
            raise InputFileError(f"{path}: no columns <model>/<muscle>/{TOTAL_NO_BASAL}; run the unit again")
        import pandas as pd

        return {m: pd.DataFrame(v, index=pd.Index(pct, name="cycle_pct")) for m, v in out.items()}

    def summary(self, folder: Path) -> SolveRecord:
        """The typed record of the unit's ``summary.json`` (the solver's run record and the
        solution's residuals; :func:`~musclemetab.redundancy.solution.read_summary`)."""
        return read_summary(self.solution_folder(folder), missing="missing", remedy="run the unit again")

    def emg_tracking(self, row) -> Mapping:
        """``emg_tracking`` of the row's unit (an EMG-TEN unit): ``{muscle: {"channels", "scale"}}``."""
        return self.summary(self.unit_folder(row)).emg_tracking or {}

    def units(self) -> list[tuple[tuple[str, str, str], dict]]:
        """``((subject, trial, workflow), row)`` of every unit of the results, then of the failures."""
        units: dict[tuple[str, str, str], dict] = {}
        for table in (self.results, self.failures):
            rows = table.drop_duplicates(["subject", "trial", "workflow"]).to_dict("records") if len(table) else []
            for r in rows:
                units.setdefault((str(r["subject"]), str(r["trial"]), str(r["workflow"])), r)
        return list(units.items())

    def report_inputs(self) -> list[tuple[str, Path]]:
        """``(name, path)`` of every file the report is drawn from (:func:`input_files`; the
        content key of :mod:`.build` hashes them)."""
        files, source = input_files(self.path)
        named = [(f.relative_to(self.path).as_posix(), f) for f in files]
        return named + ([("study file", source)] if source is not None else [])

    # ------------------------------------------------------------------ paths as the page shows them
    def relative(self, path) -> str:
        """A path as the report shows it: relative to the study folder (``–`` for none)."""
        if path is None or str(path) == "":
            return "–"
        p = Path(str(path))
        if not p.is_absolute():
            return str(p)
        try:
            return os.path.relpath(p, self.path.resolve())
        except ValueError:  # another drive
            return p.name

    def short(self, exc: BaseException) -> str:
        """An error message on one line, with paths relative to the study folder."""
        text = " ".join(str(exc).split())
        return text.replace(str(self.path) + os.sep, "").replace(str(self.path.resolve()) + os.sep, "")


def _recorded_report_models(settings: dict) -> list[str] | None:
    """``models`` of the ``[report]`` table as ``study.json`` records it, checked; ``None``
    when absent."""
    from ..metabolics.registry import parse_models

    report = settings.get("report")
    if not isinstance(report, dict) or report.get("models") in (None, "", []):
        return None
    return parse_models(report["models"])


def _renamed(table, names: dict):
    """``table`` with the columns of an older version renamed (``names``: old -> new), unless
    the new name is already there. ``one_leg_mean_W`` is renamed only when no row is of the
    muscle basal rule (it then held the per-muscle basal heat); otherwise it is dropped."""
    rename = {old: new for old, new in names.items() if old in table.columns and new not in table.columns}
    if "one_leg_mean_W" in rename and "basal_rule" in table.columns and \
            (table["basal_rule"].astype(str) == "muscle").any():
        del rename["one_leg_mean_W"]
        table = table.drop(columns="one_leg_mean_W")
    return table.rename(columns=rename)


def _unique(values) -> list[str]:
    return list(dict.fromkeys(values.astype(str)))


def _read_timeseries(folder: Path):
    import pandas as pd

    p = folder / TIMESERIES_FILE
    if not p.is_file():
        raise InputFileError(f"{p}: missing")
    table = read_csv_file(p, "run the study again to rewrite it")
    if "series" in table.columns:  # earlier releases named the leg's summed muscles "whole_body"
        table["series"] = table["series"].replace({"whole_body": "leg_muscles"})
    return table


def _periodic(pct, values, at):
    """``values`` over the cycle (``pct``, %) at the cycle percentages ``at``, the cycle
    repeated (100 % is 0 % of the next cycle: a point at or past 100 % is left out)."""
    pct, values = np.asarray(pct, float), np.asarray(values, float)
    keep = pct < 100.0 - 1e-9
    return np.interp(np.mod(np.asarray(at, float), 100.0), pct[keep], values[keep], period=100.0)


def _cycle_times(table) -> tuple[float, float]:
    """``(start, end)`` (s) of a leg's gait cycle from its table's ``time_s`` and ``cycle_pct``."""
    t, p = table["time_s"].to_numpy(float), table["cycle_pct"].to_numpy(float)
    ok = np.isfinite(t) & np.isfinite(p)
    if np.unique(p[ok]).size < 2:
        raise InputFileError(f"{TIMESERIES_FILE}: no times (time_s) to align the two legs' cycles on; "
                             "run the study again to rewrite it")
    slope, start = np.polyfit(p[ok], t[ok], 1)  # time = start + pct * (end - start) / 100
    return float(start), float(start + 100.0 * slope)


def add_leg_timeseries(tables: dict):
    """Both legs' rates over the gait cycle of the first leg (its ``cycle_pct``): every series
    (model, series) of the first leg plus the other leg's at the same instant.

    One leg solved (one table): the other leg is the solved leg half a cycle later (a
    symmetric gait): ``x(p) + x(p + 50 %)``, the cycle repeated. Both legs solved: the
    other leg's own series, each leg on its own cycle (its ``time_s``), taken at the first
    leg's instants: the other leg's phase ``((t - start) / (end - start)) mod 1``, aligned on
    the first leg's heel strike. The cycle average of either is the sum of the legs' averages.
    """
    first, *others = tables.values()
    out = first.copy()
    groups = out.groupby(["model", "series"], sort=False)
    if not others:
        for _, rows in groups:
            r = rows.sort_values("cycle_pct")
            pct, v = r["cycle_pct"].to_numpy(float), r["value_W"].to_numpy(float)
            out.loc[r.index, "value_W"] = v + _periodic(pct, v, pct + 50.0)
        return out
    start, end = _cycle_times(first)
    for other in others:
        o_start, o_end = _cycle_times(other)
        for (model, series), rows in groups:
            o = other[(other["model"] == model) & (other["series"] == series)].sort_values("cycle_pct")
            if o.empty:
                continue
            t = start + rows["cycle_pct"].to_numpy(float) / 100.0 * (end - start)
            phase = 100.0 * (t - o_start) / (o_end - o_start)
            out.loc[rows.index, "value_W"] += _periodic(o["cycle_pct"], o["value_W"], phase)
    return out


def read_study_folder(study_dir: str | os.PathLike, models=None) -> StudyFolder:
    """Read ``study.json``, ``results.csv`` and ``failures.csv`` of a study folder.

    Raises :class:`InputFileError` when the folder or ``results.csv`` is missing,
    unreadable or cut short (its last line incomplete; or no row while ``failures.csv`` names
    no failed unit), or ``study.json`` is not JSON; :class:`MissingColumnError` when
    ``results.csv`` lacks one of :data:`REQUIRED_COLUMNS`. A missing ``study.json`` or
    ``failures.csv`` gives a note in the report. ``models`` (names, ``"UM10,LW05"`` or
    ``"all"``, see :func:`~musclemetab.metabolics.registry.parse_models`): the models the
    figures show (default: :meth:`StudyFolder.shown_models`; ``"all"``: those of the paper's
    six the study computed); raises :class:`OptionError` for an unknown name or a named model
    the study did not compute.
    """
    import pandas as pd

    path = Path(study_dir)
    if not path.is_dir():
        raise InputFileError(
            f"{path}: no such study folder or analyse output folder; pass the output folder of 'musclemetab run' "
            "(the folder holding results.csv and study.json) or of 'musclemetab analyse --out' (holding analyse.json)"
        )
    rpath = path / RESULTS_CSV
    if not rpath.is_file():
        raise InputFileError(
            f"{rpath}: missing; {path} is neither a finished study folder nor an analyse output folder. Run the "
            "study first ('musclemetab run STUDY.toml') and pass its output folder (holding results.csv), or pass "
            "the output folders of 'musclemetab analyse --out' (holding analyse.json)"
        )
    rerun = ("run the same 'musclemetab run STUDY.toml' again: it writes the table anew from the units' folders "
             "(complete units are not solved again)")
    results = read_csv_file(rpath, rerun, "results table",
                            dtype={"subject": str, "trial": str, "workflow": str, "model": str})
    results = _renamed(results, RENAMED_RESULTS_COLUMNS)
    missing = [c for c in REQUIRED_COLUMNS if c not in results.columns]
    if results.empty:  # every unit failed: the runner writes the key columns alone; the page lists the failures
        for c in missing:
            results[c] = pd.Series(dtype=float if c.endswith(("_W_per_kg", "_m_per_s")) else object)
        missing = []
    if missing:
        raise MissingColumnError(
            f"{rpath}: missing column{'s' if len(missing) > 1 else ''} {name_list(missing)}; "
            "the file was not written by the study runner of this version; run the study again"
        )
    for c in results.columns:
        if c.endswith(("_pct", "_W_per_kg", "_per_m", "_m_per_s", "_W")):
            results[c] = pd.to_numeric(results[c], errors="coerce")
    notes: list[str] = []
    settings: dict = {}
    spath = path / STUDY_JSON
    if spath.is_file():
        from ..io.jsonfile import read_json_object

        settings = read_json_object(spath, remedy="run the study again to rewrite it")
    else:
        notes.append(f"{STUDY_JSON} is missing: the settings below are taken from the results table.")
    fpath = path / FAILURES_CSV
    failures = pd.DataFrame(columns=_FAILURE_COLUMNS)
    if fpath.is_file():
        if fpath.stat().st_size:
            failures = read_csv_file(fpath, rerun, dtype=str, keep_default_na=False)
        for c in _FAILURE_COLUMNS:
            if c not in failures.columns:
                failures[c] = "failed" if c == "status" else ""  # status: written since interrupts are told apart
        failures = failures[_FAILURE_COLUMNS]
    else:
        notes.append(f"{FAILURES_CSV} is missing: only failures recorded in the results table are listed.")
    if results.empty and failures.empty:  # every unit failed gives no row, but then failures.csv names them
        raise InputFileError(f"{rpath}: holds no unit's row and {fpath} names no failed unit: the table was cut "
                             f"short; {rerun}")
    study = StudyFolder(path=path, settings=settings, results=results, failures=failures, notes=notes,
                        sources=[path])
    return with_figure_models(study, models, rpath)


def with_figure_models(study: StudyFolder, models, where) -> StudyFolder:
    """``study`` with the models its figures show set from ``models`` (the report's
    ``--models``; ``None``: the default); raises :class:`OptionError` for an unknown name or a
    named model not computed in ``where`` (the results it read)."""
    if models is None:
        return study
    from ..metabolics.registry import parse_models

    asked = parse_models(models)
    tokens = models.replace(";", ",").replace(" ", ",").split(",") if isinstance(models, str) else list(models)
    named = [t for t in tokens if t and str(t).strip().lower() != "all"]  # 'all': the six the study has
    computed = study.models()
    absent = [m for m in (parse_models(named) if named else []) if m not in computed]
    if absent:
        raise OptionError(
            f"--models: {name_list(absent)} not computed in {where} (the study has {', '.join(computed)}); "
            "name models of the study or run it with them")
    study.figure_models = asked
    return study


def study_file(study_dir: Path) -> Path | None:
    """The study file recorded as ``source`` in ``study.json`` (relative to the study folder
    when not absolute), or ``None``."""
    import json

    try:
        source = json.loads((study_dir / STUDY_JSON).read_text(encoding="utf-8")).get("source")
    except (OSError, ValueError, AttributeError):
        return None
    if not isinstance(source, str) or not source.strip():
        return None
    p = Path(source)
    return p if p.is_absolute() else study_dir / p


def input_files(study_dir: str | os.PathLike) -> tuple[list[Path], Path | None]:
    """The files a report of the folder is drawn from: the study's tables (``results.csv``,
    ``study.json``, ``failures.csv``, ``per_muscle.csv``; present or not) and every unit's
    ``unit.json`` (which records the hash of each of the unit's files, ``summary.json`` among
    them), in a fixed order; and the study file ``study.json`` names as its ``source`` (e.g.
    ``study.toml``, wherever it is), or ``None``."""
    path = Path(study_dir)
    files = [path / n for n in (RESULTS_CSV, STUDY_JSON, FAILURES_CSV, PER_MUSCLE_FILE)]
    units = path / UNITS_FOLDER
    files += sorted(units.glob(f"**/{UNIT_FILE}")) if units.is_dir() else []
    return files, study_file(path)

