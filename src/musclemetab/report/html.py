"""The report of a study folder: its figures and one self-contained HTML page.

:func:`write_report` reads a study folder (``study.json``, ``results.csv``, ``failures.csv``
and the unit folders ``units/<subject>/<trial>/<workflow>``), draws every figure of
:mod:`musclemetab.report.figures` that the data support, writes them to ``figures/`` (PNG and
SVG) and writes ``report.html``: settings, method, result tables, figures (embedded as
base64 PNG), failures and software versions. A figure the data cannot support (no measured
rates, one speed only, missing unit files) is replaced by a short note saying why. The page
needs nothing else: no external resource, no script. Every file is written atomically.
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
import json
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..analysis.groups import GROUPS_WITH_OTHER as GROUPS
from ..errors import InputFileError, MissingColumnError, MusclemetabError, OptionError

__all__ = [
    "StudyFolder",
    "FigureEntry",
    "read_study_folder",
    "make_figures",
    "render_html",
    "write_report",
    "generate_report",
    "REPORT_FILE",
    "FIGURES_FOLDER",
    "FIGURE_NAMES",
    "REQUIRED_COLUMNS",
    "report_key",
]

REPORT_FILE = "report.html"
FIGURES_FOLDER = "figures"
STUDY_JSON = "study.json"
RESULTS_CSV = "results.csv"
FAILURES_CSV = "failures.csv"
TIMESERIES_FILE = "timeseries.csv"
UNIT_FILE = "unit.json"

#: Columns ``results.csv`` must have; the others are used when present.
REQUIRED_COLUMNS = ("subject", "trial", "workflow", "model", "status", "mean_W_per_kg")

#: File names (without extension) of the figures, in the order of the report.
FIGURE_NAMES = (
    "excitations_fiber_lengths",
    "estimated_vs_measured",
    "group_rates_over_cycle",
    "whole_body_over_cycle",
    "phase_shares",
    "phase_pies",
    "group_shares",
    "rates_against_speed",
    "per_muscle_ranked",
    "figure2_soleus",
)



# ------------------------------------------------------------------------------ reading
@dataclass
class StudyFolder:
    """A study folder's contents: settings, the results (all rows) and the failures."""

    path: Path
    settings: dict
    results: object  # pandas.DataFrame
    failures: object  # pandas.DataFrame: subject, trial, workflow, reason
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self):
        """Rows of the results whose status is ``ok``."""
        r = self.results
        return r[r["status"].astype(str).str.lower() == "ok"]

    def leg_folders(self, row) -> dict[str, Path]:
        """The row's unit folders by leg: ``{"": folder}`` for one leg solved (and doubled),
        ``{"r": ..., "l": ...}`` for a row adding both legs (``unit_dir`` holds the legs' folders)."""
        rel = row.get("unit_dir") if hasattr(row, "get") else None
        if isinstance(rel, str) and rel.strip():
            folder = self.path / rel
        else:
            folder = self.path / "units" / str(row["subject"]) / str(row["trial"]) / str(row["workflow"])
        legs = {s: folder / s for s in ("r", "l") if (folder / s / UNIT_FILE).is_file()}
        return legs if legs and not (folder / UNIT_FILE).is_file() else {"": folder}

    def unit_folder(self, row) -> Path:
        """The row's unit folder; for a row adding both legs, the first leg's (right)."""
        return next(iter(self.leg_folders(row).values()))

    @property
    def name(self) -> str:
        return str(self.settings.get("name") or self.path.name)


def read_study_folder(study_dir: str | os.PathLike) -> StudyFolder:
    """Read ``study.json``, ``results.csv`` and ``failures.csv`` of a study folder.

    Raises :class:`InputFileError` when the folder or ``results.csv`` is missing or
    unreadable, or ``study.json`` is not JSON; :class:`MissingColumnError` when
    ``results.csv`` lacks one of :data:`REQUIRED_COLUMNS`. A missing ``study.json`` or
    ``failures.csv`` gives a note in the report.
    """
    import pandas as pd

    path = Path(study_dir)
    if not path.is_dir():
        raise InputFileError(
            f"{path}: no such study folder; give the output folder of 'musclemetab run' "
            "(the folder holding results.csv and study.json)"
        )
    rpath = path / RESULTS_CSV
    if not rpath.is_file():
        raise InputFileError(
            f"{rpath}: missing; {path} is not a finished study folder. Run the study first "
            "('musclemetab run STUDY.toml'), or give the folder holding results.csv"
        )
    try:
        results = pd.read_csv(rpath, dtype={"subject": str, "trial": str, "workflow": str, "model": str})
    except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise InputFileError(f"{rpath}: not a readable results table ({exc}); run the study again") from None
    missing = [c for c in REQUIRED_COLUMNS if c not in results.columns]
    if missing:
        raise MissingColumnError(
            f"{rpath}: missing column{'s' if len(missing) > 1 else ''} {', '.join(missing)}; "
            "the file was not written by the study runner of this version; run the study again"
        )
    for c in results.columns:
        if c.endswith(("_pct", "_W_per_kg", "_per_m", "_m_per_s")) or c in ("mean_W_per_kg",):
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
    cols = ["subject", "trial", "workflow", "reason"]
    failures = pd.DataFrame(columns=cols)
    if fpath.is_file():
        try:
            failures = pd.read_csv(fpath, dtype=str, keep_default_na=False)
        except pd.errors.EmptyDataError:
            pass
        except (pd.errors.ParserError, UnicodeDecodeError) as exc:
            raise InputFileError(f"{fpath}: not a readable table ({exc}); run the study again") from None
        for c in cols:
            if c not in failures.columns:
                failures[c] = ""
        failures = failures[cols]
    else:
        notes.append(f"{FAILURES_CSV} is missing: only failures recorded in the results table are listed.")
    return StudyFolder(path=path, settings=settings, results=results, failures=failures, notes=notes)


# ------------------------------------------------------------------------------ figures
@dataclass
class FigureEntry:
    """One figure of the report: its files, or the note saying why it is not drawn."""

    name: str
    title: str
    caption: str = ""
    paths: dict | None = None
    note: str | None = None


def _workflows(study: StudyFolder) -> list[str]:
    from .figures import _ordered_workflows

    listed = [str(w) for w in study.settings.get("workflows") or []]
    present = _ordered_workflows(study.results["workflow"].astype(str))
    return listed + [w for w in present if w not in listed] if listed else present


def _models(study: StudyFolder) -> list[str]:
    from .figures import _ordered_models

    listed = study.settings.get("models")
    present = _ordered_models(study.results["model"].astype(str))
    if isinstance(listed, (list, tuple)) and listed:
        listed = [str(m) for m in listed]
        return listed + [m for m in present if m not in listed]
    return present


def _subjects(study: StudyFolder) -> list[str]:
    listed = list((study.settings.get("subjects") or {}).keys()) if isinstance(study.settings.get("subjects"), dict) else []
    present = []
    for s in study.results["subject"].astype(str):
        if s not in present:
            present.append(s)
    return [s for s in listed if s in present] + [s for s in present if s not in listed]


def _preferred(study: StudyFolder, ok) -> str:
    from .figures import preferred_trial

    pt = study.settings.get("preferred_trial")
    if isinstance(pt, str) and pt in set(ok["trial"].astype(str)):
        return pt
    return preferred_trial(ok)


def _read_unit_json(folder: Path) -> dict:
    from ..io.jsonfile import read_json_object

    return read_json_object(folder / UNIT_FILE, missing="missing", remedy="run the study again to rewrite it")


def _cycle(rec: dict, where: Path) -> tuple[float, float, float]:
    c = rec.get("cycle") or {}
    try:
        vals = (float(c["start_s"]), float(c["toe_off_s"]), float(c["end_s"]))
    except (KeyError, TypeError, ValueError):
        raise InputFileError(f"{where / UNIT_FILE}: no gait cycle (cycle.start_s, toe_off_s, end_s)") from None
    return vals


def _body_mass(study: StudyFolder, subject) -> float | None:
    """The subject's body mass (kg) recorded in study.json, or ``None``."""
    subjects = study.settings.get("subjects")
    rec = subjects.get(str(subject)) if isinstance(subjects, dict) else None
    try:
        mass = float((rec or {}).get("body_mass_kg"))
    except (TypeError, ValueError):
        return None
    return mass if np.isfinite(mass) and mass > 0 else None


def _read_timeseries(folder: Path):
    import pandas as pd

    p = folder / TIMESERIES_FILE
    if not p.is_file():
        raise InputFileError(f"{p}: missing")
    try:
        return pd.read_csv(p)
    except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise InputFileError(f"{p}: not a readable table ({exc})") from None


def _rel(study: StudyFolder, path) -> str:
    """A path as the report shows it: relative to the study folder (``.`` for the folder)."""
    if path is None or str(path) == "":
        return "–"
    p = Path(str(path))
    if not p.is_absolute():
        return str(p)
    try:
        return os.path.relpath(p, study.path.resolve())
    except ValueError:  # another drive
        return p.name


def _short(study: StudyFolder, exc: BaseException) -> str:
    """An error message on one line, with paths relative to the study folder."""
    text = " ".join(str(exc).split())
    return text.replace(str(study.path) + os.sep, "").replace(str(study.path.resolve()) + os.sep, "")


def _measured_emg(study: StudyFolder, subject: str, trial: str, sols: dict, cycles: dict, rows
                  ) -> tuple[dict, str, str]:
    """The trial's measured EMG to draw over the excitations: ``({muscle: (cycle_pct, value)},
    legend label, caption sentence)``.

    The EMG file is the one ``study.json`` records for the trial (``emg_files``), mapped to
    the muscles by the subject's ``emg_mapping``. Scaled by the EMG-TEN factors when the
    trial's EMG-TEN unit succeeded (each muscle's ``scale`` in its ``summary.json``, the
    channels it tracked), otherwise so that its peak over the cycle equals the excitation's
    peak of the workflow shown first (EFFORT-TEN when present). No EMG: an empty mapping and a
    sentence saying why.
    """
    from ..emg.processing import emg_at, map_channels, read_processed_emg
    from ..io.jsonfile import read_json_object
    from ..redundancy.emg_inputs import mapping_for_muscles, resolve_emg_mapping
    from .figures import main_workflow

    rec = (study.settings.get("subjects") or {}).get(subject) if isinstance(study.settings.get("subjects"), dict) else None
    path = ((rec or {}).get("emg_files") or {}).get(trial) if isinstance(rec, dict) else None
    if not path:
        return {}, "", "No measured EMG is recorded for this trial (study.json, emg_files)."
    wf = main_workflow(list(sols))
    sol, (start, _, end) = sols[wf], cycles[wf]
    t = np.asarray(sol.time_s, float)
    t = t[(t >= start - 1e-9) & (t <= end + 1e-9)]
    pct = 100.0 * (t - start) / (end - start)
    scales: dict[str, float] = {}
    mapping: dict = {}
    emg_rows = rows[rows["workflow"].astype(str).str.lower() == "emg-ten"]
    if not emg_rows.empty:
        try:
            tracking = read_json_object(study.unit_folder(emg_rows.iloc[0]) / "summary.json").get("emg_tracking") or {}
            mapping = {m: v["channels"] for m, v in tracking.items()}
            scales = {m: float(v["scale"]) for m, v in tracking.items()}
        except (MusclemetabError, KeyError, TypeError, ValueError):
            mapping, scales = {}, {}
    try:
        emg_df = read_processed_emg(_resolve(study, path))
        if not mapping:
            named = (rec or {}).get("emg_mapping") or "default"
            mapping = mapping_for_muscles(named, resolve_emg_mapping(named), list(sol.muscles))
        mapping = {m: c for m, c in mapping.items() if m in sol.muscles}
        table = emg_at(map_channels(emg_df, mapping), t)
    except MusclemetabError as exc:
        return {}, "", f"Measured EMG not shown: {_short(study, exc)}."
    full_t = np.asarray(sol.time_s, float)
    excitation = np.asarray(sol.excitation)[(full_t >= start - 1e-9) & (full_t <= end + 1e-9)]
    out = {}
    for m in table.columns:
        v = table[m].to_numpy(float)
        if scales:
            v = scales.get(m, math.nan) * v
        elif np.max(v) > 0:
            v = v * (float(np.max(excitation[:, list(sol.muscles).index(m)])) / float(np.max(v)))
        if np.all(np.isfinite(v)):
            out[m] = (pct, v)
    if scales:
        return out, "measured EMG x EMG-TEN scale", (
            "Dashed grey: the measured EMG of the muscles EMG-TEN tracked, times the scale factor EMG-TEN "
            "estimated for each.")
    return out, f"measured EMG, peak = {wf} excitation peak", (
        f"Dashed grey: the measured EMG (processed envelope, mapped to the muscles by the subject's channel "
        f"mapping), scaled so that its peak over the cycle equals the peak of the {wf} excitation (no EMG-TEN "
        "scale factors for this trial); its shape, not its amplitude, is the measurement.")


def _solves_both_legs(study: StudyFolder, subject) -> bool:
    """Whether ``study.json`` records ``side = "both"`` for the subject."""
    subjects = study.settings.get("subjects")
    rec = subjects.get(str(subject)) if isinstance(subjects, dict) else None
    return isinstance(rec, dict) and rec.get("side") == "both"


def _add_leg_timeseries(tables: dict):
    """One unit's long time-series table, or both legs' added: each leg's series on its own
    gait cycle (``cycle_pct``), the second interpolated onto the first's cycle percentages."""
    if len(tables) == 1:
        return next(iter(tables.values()))
    first, *others = tables.values()
    out = first.copy()
    for other in others:
        for (model, series), rows in out.groupby(["model", "series"], sort=False):
            o = other[(other["model"] == model) & (other["series"] == series)].sort_values("cycle_pct")
            if o.empty:
                continue
            out.loc[rows.index, "value_W"] += np.interp(rows["cycle_pct"].to_numpy(float),
                                                        o["cycle_pct"].to_numpy(float), o["value_W"].to_numpy(float))
    out["time_s"] = np.nan  # the legs' cycles have different times
    return out


def _resolve(study: StudyFolder, path) -> Path:
    """A path recorded in study.json: as given when absolute, else relative to the study folder."""
    p = Path(str(path))
    return p if p.is_absolute() else study.path / p


#: The title of each figure in the report.
FIGURE_TITLES = {
    "figure2_soleus": "The metabolic models on a soleus (the paper's Figure 2)",
    "excitations_fiber_lengths": "Muscle excitations and normalised fiber lengths",
    "estimated_vs_measured": "Estimated vs measured whole-body metabolic rate",
    "group_rates_over_cycle": "Metabolic rate of the muscle groups over the gait cycle",
    "whole_body_over_cycle": "Whole-body metabolic rate over the gait cycle across speeds",
    "phase_shares": "Stance and swing shares",
    "phase_pies": "Stance and swing shares, scaled by the total cost",
    "group_shares": "Muscle-group shares",
    "per_muscle_ranked": "The muscles costing most energy, across speeds",
    "rates_against_speed": "Whole-body and muscle-group rates against walking speed",
}


def _figure_builders(study: StudyFolder) -> dict[str, Callable[[], tuple[object, str]] | str]:
    """Figure name -> a function drawing it (returning the figure and its caption), or the
    note saying why the study's data cannot support it."""
    from . import figures as F

    ok = study.ok
    if ok.empty:
        return {name: "no unit of the study succeeded: nothing to draw." for name in FIGURE_NAMES}

    def fig_soleus():
        from ..metabolics.figure2 import figure2

        return figure2(), FIGURE2_CAPTION

    workflows = [w for w in _workflows(study) if w in set(ok["workflow"].astype(str))]
    models = [m for m in _models(study) if m in set(ok["model"].astype(str))]
    trial = _preferred(study, ok)
    main_wf = F.main_workflow(workflows)
    # the subject shown in the single-unit figures: the first with the preferred trial done
    pref = ok[ok["trial"].astype(str) == trial]
    subject = next((s for s in _subjects(study) if s in set(pref["subject"].astype(str))), None)

    def unit_rows(subject, trial=None, workflow=None):
        d = ok[ok["subject"].astype(str) == subject]
        if trial is not None:
            d = d[d["trial"].astype(str) == trial]
        if workflow is not None:
            d = d[d["workflow"].astype(str) == workflow]
        return d

    def fig1():
        from ..redundancy.solution import Solution

        sols, cycles, skipped = {}, {}, []
        rows = unit_rows(subject, trial)
        for w in workflows:
            d = rows[rows["workflow"].astype(str) == w]
            if d.empty:
                continue
            folder = study.unit_folder(d.iloc[0])
            try:
                rec = _read_unit_json(folder)
                cycles[w] = _cycle(rec, folder)
                sols[w] = Solution.load(folder)
            except MusclemetabError as exc:
                cycles.pop(w, None)
                skipped.append(f"{w} ({_short(study, exc)})")
        if not sols:
            raise OptionError(
                f"no solution could be read for {subject}, trial {trial}"
                + (f": {'; '.join(skipped)}" if skipped else "")
            )
        emg, emg_label, emg_text = _measured_emg(study, subject, trial, sols, cycles, rows)
        fig = F.excitations_and_fiber_lengths(
            sols, cycles, emg=emg, emg_label=emg_label,
            title=f"Muscle excitation and normalised fiber length over the gait cycle: subject {subject}, "
            f"trial {trial}",
        )
        cap = (f"Subject {subject}, trial {trial} (preferred speed). Excitation (-) and fiber length "
               "normalised by the optimal fiber length (-), one line per workflow; dotted line: toe-off; "
               "grey band: plateau of the active force-length curve (0.75-1.05); dashed line: start of "
               f"the descending limb (1.05). {emg_text}")
        if _solves_both_legs(study, subject):
            cap += " Both legs were solved; the right leg is shown."
        if skipped:
            cap += f" Not shown: {'; '.join(skipped)}."
        return fig, cap

    def unit_timeseries(subject, trial, workflow):
        d = unit_rows(subject, trial, workflow)
        if d.empty:
            raise OptionError(f"no successful unit for {subject}, trial {trial}, workflow {workflow}")
        folders = study.leg_folders(d.iloc[0])
        ts = _add_leg_timeseries({s: _read_timeseries(f) for s, f in folders.items()})
        to = d["toe_off_pct"].iloc[0] if "toe_off_pct" in d.columns else math.nan
        if not np.isfinite(to):
            folder = next(iter(folders.values()))
            rec = _read_unit_json(folder)
            s, t, e = _cycle(rec, folder)
            to = 100.0 * (t - s) / (e - s)
        sp = d["speed_m_per_s"].iloc[0] if "speed_m_per_s" in d.columns else math.nan
        return ts, float(to), float(sp)

    mass = _body_mass(study, subject)
    both = _solves_both_legs(study, subject)
    doubled = "the two solved legs added, each over its own cycle" if both else "twice the simulated leg"
    scale, unit, legs = ((1.0 if both else 2.0) / mass, "W/kg", "both legs") if mass else (
        (1.0, "W", "both legs") if both else (1.0, "W", "one leg"))

    def fig3():
        ts, to, _ = unit_timeseries(subject, trial, main_wf)
        fig = F.group_rates_over_cycle(
            ts, to, [m for m in models if m in set(ts["model"].astype(str).unique())] or None,
            title=f"Metabolic rate of the muscle groups over the gait cycle ({unit}, {legs}, no basal heat): "
            f"subject {subject}, trial {trial}, {main_wf}", scale=scale, unit=unit,
        )
        cap = (f"Subject {subject}, trial {trial} (preferred speed), workflow {main_wf}. Muscle metabolic "
               f"rates ({unit}, {legs}: {doubled}{' per kg of body mass' if mass else ''}, "
               "without basal heat) distributed to the muscle groups by moment-arm ratio; same axes in every "
               f"panel; dotted line: toe-off ({to:.1f} % of the cycle).")
        return fig, cap

    def fig4():
        trials = [t for t in F.trial_order(ok) if not unit_rows(subject, t, main_wf).empty]
        if len(trials) < 2:
            raise OptionError(
                f"one speed only ({', '.join(trials) or 'no trial'} for subject {subject}, {main_wf}): "
                "nothing to compare across speeds"
            )
        tables, speeds, toes, skipped = {}, {}, {}, []
        for t in trials:
            try:
                ts, to, sp = unit_timeseries(subject, t, main_wf)
            except MusclemetabError as exc:
                skipped.append(f"{t} ({_short(study, exc)})")
                continue
            if not np.isfinite(sp):
                skipped.append(f"{t} (no walking speed)")
                continue
            tables[t], speeds[t], toes[t] = ts, sp, to
        if len(tables) < 2:
            raise OptionError(
                "fewer than two speeds with time series" + (f": {'; '.join(skipped)}" if skipped else "")
            )
        present = {v for x in tables.values() for v in x["model"].astype(str).unique()}
        fig = F.whole_body_over_cycle(
            tables, speeds, [m for m in models if m in present],
            toe_off_pct=toes,
            title=f"Whole-body metabolic rate over the gait cycle across speeds ({unit}, {legs}, summed "
            f"muscles, no basal heat): subject {subject}, {main_wf}", scale=scale, unit=unit,
        )
        cap = (f"Subject {subject}, workflow {main_wf}. Summed muscle metabolic rate ({unit}, {legs}: "
               f"{doubled}{' per kg of body mass' if mass else ''}, without basal heat) over the gait "
               "cycle, one line per walking speed; same axes in every panel; marks at the bottom: toe-off of "
               "each trial.")
        if skipped:
            cap += f" Not shown: {'; '.join(skipped)}."
        return fig, cap

    def fig7():
        import pandas as pd

        path = study.path / "per_muscle.csv"
        if not path.is_file():
            raise OptionError("per_muscle.csv is missing: run the study with this version to get it")
        pm = pd.read_csv(path, dtype={"subject": str, "trial": str, "workflow": str, "model": str})
        if "speed_m_per_s" in ok.columns:
            sp = ok.drop_duplicates(["subject", "trial"])[["subject", "trial", "speed_m_per_s"]]
            pm = pm.merge(sp.astype({"subject": str, "trial": str}), on=["subject", "trial"], how="left")
        fig = F.per_muscle_ranked(pm, workflow=main_wf if main_wf in set(pm["workflow"].astype(str).unique()) else None,
                                  models=[m for m in models if m in set(pm["model"].astype(str).unique())] or None)
        cap = (f"Workflow {main_wf}. The 15 muscles with the largest cycle-average metabolic rate of each model "
               "(W per kg of body mass, one leg, without basal heat; mean over subjects), one bar per trial "
               "(light: slow, dark: fast); every muscle is in per_muscle.csv.")
        return fig, cap

    def drawn(function, caption: str, **kwargs):
        """A builder of a figure drawn from the successful rows alone, with a fixed caption."""
        return lambda: (function(ok, **kwargs), caption)

    builders = {
        "figure2_soleus": fig_soleus,
        "excitations_fiber_lengths": fig1,
        "estimated_vs_measured": drawn(
            F.estimated_vs_measured,
            "Whole-body average metabolic rate (W/kg of body mass, both legs, with basal heat) estimated by "
            "each model against the measured rate, one point per subject and trial; lines: repeated-measures "
            "correlation of each workflow (common slope m, one intercept per subject); dashed: identity."),
        "group_rates_over_cycle": fig3,
        "whole_body_over_cycle": fig4,
        "phase_shares": drawn(
            F.phase_shares,
            "Share of the cycle's muscle metabolic energy (one leg, without basal heat) spent in stance (initial "
            "contact to toe-off) and swing, mean over subjects (error bar: SD). Left: at the preferred speed "
            f"(trial {trial}); right: swing share against walking speed for {main_wf}, with the "
            "repeated-measures slope (% per m/s).",
            trial=trial, workflow=main_wf),
        "phase_pies": drawn(
            F.phase_pies,
            f"Workflow {main_wf}. Each pie splits the cycle's muscle metabolic energy (one leg, without basal "
            "heat) into stance (dark) and swing (light); its area is proportional to the whole-body rate without "
            "basal heat (W/kg of body mass, both legs; printed under the pie), so the pies grow with walking "
            "speed (rows) and differ between models (columns); means over subjects.",
            workflow=main_wf, models=models),
        "group_shares": drawn(
            F.group_shares,
            "Share of each muscle group in the cycle's muscle metabolic energy (%, one leg, without basal heat; "
            "mean over subjects), one bar per trial (walking speed in m/s).",
            workflows=workflows, models=models),
        "per_muscle_ranked": fig7,
        "rates_against_speed": drawn(
            F.rates_against_speed,
            f"Workflow {main_wf}. Whole-body metabolic rate without basal heat (black) and each muscle group's "
            "part of it (group share × whole-body rate), W per kg of body mass, both legs; means over subjects "
            "at each trial's mean walking speed; same axes in every panel.",
            workflow=main_wf, models=models),
    }
    if subject is None:
        for name in ("excitations_fiber_lengths", "group_rates_over_cycle", "whole_body_over_cycle"):
            builders[name] = f"no successful unit for trial {trial}."
    return builders


def _draw_figure(study: StudyFolder, fig_dir: Path, formats: Sequence[str], name: str,
                 build: Callable[[], tuple[object, str]] | str | None = None) -> FigureEntry:
    """Draw and save one figure of the report (``build``: its entry of :func:`_figure_builders`,
    made here when not given, as in a worker process)."""
    from .figures import save_figure

    if build is None:
        build = _figure_builders(study)[name]
    if isinstance(build, str):
        return FigureEntry(name, FIGURE_TITLES[name], note=build)
    cache = _figure_cache(name, formats)
    if cache is not None:
        formats = tuple(cache)  # PNG only: the figure is the package's (save_figure2 writes SVG or PDF)
    cached = _read_cache(cache) if cache is not None else None
    if cached is not None:
        from ..io.atomic import atomic_write_bytes

        paths = {fmt: atomic_write_bytes(fig_dir / f"{name}.{fmt}", data) for fmt, data in cached.items()}
        return FigureEntry(name, FIGURE_TITLES[name], caption=FIGURE2_CAPTION, paths=paths)
    try:
        fig, caption = build()
    except MusclemetabError as exc:
        return FigureEntry(name, FIGURE_TITLES[name], note=_short(study, exc))
    paths = save_figure(fig, fig_dir, name, formats=formats)
    if cache is not None:
        _store_in_cache(paths, cache)
    return FigureEntry(name, FIGURE_TITLES[name], caption=caption, paths=paths)


FIGURE2_CAPTION = (
    "The metabolic rate (W) and efficiency of one soleus under each energy model, in steady states "
    "(excitation equal to activation) at four activations: over the fiber velocity at the optimal "
    "length and over the fiber length at a slow shortening; the last row compares the models at full "
    "activation. The settings and the open choices are printed on the figure (docs/metabolics.md). It "
    "depends on no data of the study: it is drawn once per version of the models and kept in the "
    "package's cache."
)


def _figure_cache(name: str, formats: Sequence[str]) -> dict[str, Path] | None:
    """The cache file of a figure that depends only on the package (Figure 2, as PNG whatever
    ``formats``), keyed by the source of the modules drawing it and the matplotlib version;
    ``None`` for other figures."""
    if name != "figure2_soleus":
        return None
    import hashlib
    from importlib.metadata import version

    from .. import colours, metabolics, muscle
    from ..cache import default_cache_dir

    h = hashlib.sha256(f"{name} matplotlib {version('matplotlib')}\n".encode())
    sources = [Path(colours.__file__)]
    for package in (metabolics, muscle):
        sources += sorted(Path(package.__file__).parent.glob("*.py"))
    for src in sources:
        h.update(src.name.encode() + b"\0" + src.read_bytes())
    folder = default_cache_dir().parent / "figures"
    return {"png": folder / f"{name}-{h.hexdigest()[:32]}.png"}


def draw_package_figures() -> None:
    """Draw the figures that depend only on the package (the Figure-2 plot) into the cache,
    unless it holds them already; a report then copies them instead of drawing them.
    ``musclemetab demo`` calls it while the study's units run, so that its report does not
    wait for the plot the first time."""
    import tempfile

    from ..metabolics.figure2 import figure2
    from .figures import save_figure

    name = "figure2_soleus"
    cache = _figure_cache(name, ("png",))
    if _read_cache(cache) is not None:
        return
    with tempfile.TemporaryDirectory() as tmp:
        _store_in_cache(save_figure(figure2(), tmp, name, formats=tuple(cache)), cache)


def _checksum_file(path: Path) -> Path:
    """The file beside a cached figure holding the SHA-256 of its content."""
    return path.with_name(path.name + ".sha256")


def _read_cache(cache: dict) -> dict[str, bytes] | None:
    """The content of a figure's cache files (format -> bytes), or ``None`` when one is
    missing or does not match the SHA-256 stored beside it (truncated, corrupted, or written
    by a version without the checksum): the figure is then drawn again and the cache rewritten."""
    import hashlib

    out = {}
    for fmt, path in cache.items():
        try:
            data = path.read_bytes()
            expected = _checksum_file(path).read_text(encoding="ascii").strip()
        except (OSError, UnicodeDecodeError):
            return None
        if hashlib.sha256(data).hexdigest() != expected:
            return None
        out[fmt] = data
    return out


def _store_in_cache(paths: dict, cache: dict) -> None:
    """Copy a drawn figure's files into the cache, each with the SHA-256 of its content
    beside it (see :func:`_read_cache`); a cache that cannot be written is skipped."""
    import hashlib
    import warnings

    from ..errors import CacheWarning
    from ..io.atomic import atomic_write_bytes, atomic_write_text

    try:
        for fmt, target in cache.items():
            target.parent.mkdir(parents=True, exist_ok=True)
            data = Path(paths[fmt]).read_bytes()
            atomic_write_bytes(target, data)
            atomic_write_text(_checksum_file(target), hashlib.sha256(data).hexdigest() + "\n")
    except OSError as exc:
        warnings.warn(f"figure cache {target.parent}: not written ({exc}); the figure is drawn again next time",
                      CacheWarning, stacklevel=3)


def default_workers(figures: int | None = None) -> int:
    """Processes drawing the figures by default: the cores this process may use, at most one
    per figure (``figures``), at least 1.

    The machine's load is not read: a snapshot of it changes from one moment to the next,
    and the load average counts the last minute's work (a report drawn just before among
    it). Another process costs little (it starts as a copy of this one and draws its share;
    this process draws too), so on a busy machine two processes take turns with the others
    no slower than one.
    """
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return max(1, min(cores, figures if figures is not None else cores))


#: Processor time (s) of each figure in the demo's report (drawn and saved as PNG, the least
#: of four drawings in one process): the figures are handed out largest first, so that the
#: processes end together.
_DRAW_COST_S = {
    "excitations_fiber_lengths": 0.68,
    "per_muscle_ranked": 0.41,
    "group_shares": 0.38,
    "estimated_vs_measured": 0.35,  # not in the demo (no measured rates): like the panels over the cycle
    "group_rates_over_cycle": 0.34,
    "rates_against_speed": 0.31,
    "whole_body_over_cycle": 0.25,
    "phase_shares": 0.22,
    "phase_pies": 0.16,
    "figure2_soleus": 0.01,  # a copy from the cache after its first drawing
}
#: Processor time (s) of the Figure-2 plot when it is not in the cache.
_FIGURE2_DRAW_COST_S = 1.5


def _prepare_fork() -> None:
    """Load, once before forking, what every drawing process needs: the PNG writer, the font
    and its metrics (the drawing modules are loaded by :func:`make_figures`)."""
    import matplotlib
    from PIL import PngImagePlugin  # noqa: F401

    from .figures import _new_figure

    fig = _new_figure(1.0, 1.0)
    fig.text(0.5, 0.5, "0123456789.-% (W/kg)", fontsize=9)
    with matplotlib.rc_context({"text.hinting": "no_hinting"}):  # as save_figure draws
        fig.canvas.draw()


def _draw_share(study: StudyFolder, fig_dir: Path, formats: Sequence[str], order: Sequence[str], builders: dict,
                counter, send: Callable[[str, FigureEntry | None], None]) -> None:
    """Draw the figures of ``order`` claimed one at a time through the shared ``counter``
    (so that every process takes the next figure when it is free); ``send`` each entry, or
    ``None`` for a figure that raised (the report's process then draws it and raises)."""
    while True:
        with counter.get_lock():
            i = counter.value
            counter.value += 1
        if i >= len(order):
            return
        try:
            entry = _draw_figure(study, fig_dir, formats, order[i], builders[order[i]])
        except Exception:  # noqa: BLE001 - drawn again where the error reaches the caller
            entry = None
        send(order[i], entry)


def _child_share(conn, *args) -> None:
    """A forked process's part of :func:`_draw_share`: entries sent through ``conn``. Ctrl-C
    (which reaches every process of the command) or the report's process gone end it quietly:
    the report's process says what happened."""
    try:
        _draw_share(*args, send=lambda name, entry: conn.send((name, entry)))
    except (KeyboardInterrupt, BrokenPipeError):
        pass
    finally:
        conn.close()


def make_figures(study: StudyFolder, fig_dir: str | os.PathLike, formats: Sequence[str] = ("png",),
                 workers: int | None = None, meanwhile: Callable[[], object] | None = None) -> list[FigureEntry]:
    """Draw the figures the study's data support and save them in ``fig_dir`` (``formats``:
    PNG, and SVG when asked for).

    ``workers`` processes draw the figures side by side (default :func:`default_workers`):
    this process and ``workers - 1`` copies of it (the ``fork`` start method; where it is not
    available, this process draws every figure). Each takes the next figure, largest first,
    when it is free; this process first runs ``meanwhile`` (the page's tables). Returns one
    :class:`FigureEntry` per name of :data:`FIGURE_NAMES`, with the file paths or the note
    saying why the figure is not drawn (the files of a figure not drawn are removed from
    ``fig_dir``, so that no figure of an earlier report remains).
    """
    import gc
    import multiprocessing

    fig_dir = Path(fig_dir)
    builders = _figure_builders(study)
    drawn = [n for n in FIGURE_NAMES if not isinstance(builders[n], str)]
    workers = default_workers(len(drawn)) if workers is None else int(workers)
    if workers < 1:
        raise OptionError(f"workers (--workers) must be at least 1, not {workers}")
    workers = min(workers, len(drawn))
    cost = dict(_DRAW_COST_S)
    cache = _figure_cache("figure2_soleus", formats)
    if cache is not None and not all(f.is_file() for f in cache.values()):
        cost["figure2_soleus"] = _FIGURE2_DRAW_COST_S  # not in the cache yet: drawn
    order = sorted(drawn, key=lambda n: -cost.get(n, 0.3))
    formats = tuple(formats)
    entries: dict[str, FigureEntry] = {}
    children = []
    # The objects made so far (modules, the study's tables) live until the end: frozen, the
    # garbage collector does not go through them at every full collection while the figures'
    # objects come and go (half a second in one process), and the forked copies do not
    # touch (and so copy) their memory pages. Unfrozen at the end.
    if drawn:
        import matplotlib.backends.backend_agg  # noqa: F401  - the drawing modules among them
        import matplotlib.figure  # noqa: F401
        import matplotlib.legend  # noqa: F401
    gc.freeze()
    try:
        if workers > 1 and "fork" in multiprocessing.get_all_start_methods():
            ctx = multiprocessing.get_context("fork")
            counter = ctx.Value("i", 0)
            _prepare_fork()
            for _ in range(workers - 1):
                receive, send = ctx.Pipe(duplex=False)
                child = ctx.Process(target=_child_share, args=(send, study, fig_dir, formats, order, builders,
                                                               counter), daemon=True)
                child.start()
                send.close()
                children.append((child, receive))
        if meanwhile is not None:
            meanwhile()
        if children:
            _draw_share(study, fig_dir, formats, order, builders, counter,
                        send=lambda name, entry: entries.__setitem__(name, entry))
            for child, receive in children:
                while True:
                    try:
                        name, entry = receive.recv()
                    except EOFError:  # the process is done (or died: its figures are drawn below)
                        break
                    entries[name] = entry
                receive.close()
                child.join()
        for n in FIGURE_NAMES:
            if entries.get(n) is None:
                entries[n] = _draw_figure(study, fig_dir, formats, n, builders[n])
    finally:
        for child, _ in children:
            if child.is_alive():
                child.terminate()
                child.join()
        gc.unfreeze()
    for e in entries.values():
        for ext in ("png", "svg"):
            if e.paths is None or ext not in e.paths:
                stale = fig_dir / f"{e.name}.{ext}"
                if stale.is_file():
                    stale.unlink()
    return [entries[n] for n in FIGURE_NAMES]


# ------------------------------------------------------------------------------ tables
def _esc(x) -> str:
    return html.escape(str(x), quote=True)


def _fmt(mean: float, sd: float, digits: int) -> str:
    if not np.isfinite(mean):
        return "–"
    if np.isfinite(sd):
        return f"{mean:.{digits}f} [{sd:.{digits}f}]"
    return f"{mean:.{digits}f}"


def _table(header: list[list[tuple[str, int]]], body: list[list[str]], n_index: int, cls: str = "") -> str:
    """HTML table; ``header`` rows of ``(text, colspan)``; the first ``n_index`` body cells are <th>."""
    out = [f'<table class="{_esc(cls)}">' if cls else "<table>", "<thead>"]
    for row in header:
        out.append("<tr>" + "".join(
            f'<th colspan="{span}">{_esc(text)}</th>' if span > 1 else f"<th>{_esc(text)}</th>" for text, span in row
        ) + "</tr>")
    out.append("</thead><tbody>")
    for row in body:
        cells = [f'<th scope="row">{_esc(c)}</th>' if i < n_index else f"<td>{_esc(c)}</td>" for i, c in enumerate(row)]
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def _pivot(ok, value: str, trials: Sequence[str], labels: Sequence[str], workflows: Sequence[str],
           models: Sequence[str], digits: int) -> str:
    """Rows: trial (headed by ``labels``) × model; columns: workflow; cells: mean [SD] over subjects."""
    from .figures import stat_cell, group_stats

    header = [[("trial (speed)", 1), ("model", 1)] + [(w, 1) for w in workflows]]
    stats = group_stats(ok, ["trial", "model", "workflow"], [value])
    present = set(zip(ok["trial"].astype(str), ok["model"].astype(str)))
    body = []
    for t, lab in zip(trials, labels):
        first = True
        for m in models:
            if (t, m) not in present:
                continue
            row = [lab if first else "", m]
            first = False
            for w in workflows:
                row.append(_fmt(*stat_cell(stats, (t, m, w), value)[:2], digits))
            body.append(row)
    return _table(header, body, 2, "results")


def _trial_heading(ok, trials) -> list[str]:
    from .figures import stat_cell, group_stats

    if "speed_m_per_s" not in ok.columns:
        return [str(t) for t in trials]
    stats = group_stats(ok, ["trial"], ["speed_m_per_s"])
    out = []
    for t in trials:
        m = stat_cell(stats, t, "speed_m_per_s")[0]
        out.append(f"{t} ({m:.2f} m/s)" if np.isfinite(m) else t)
    return out


def _estimation_notes(study: StudyFolder) -> str:
    """A note for every trial whose gait events or walking speed were estimated."""
    ok = study.ok
    notes = []
    for col, what in (("cycle_source", "gait events"), ("speed_source", "walking speed")):
        if col not in ok.columns:
            continue
        d = ok.drop_duplicates(["subject", "trial"])
        est = d[d[col].astype(str).str.startswith("estimated")]
        for source, rows in est.groupby(col, sort=False):
            units = ", ".join(f"{r.subject}/{r.trial}" for r in rows.itertuples())
            notes.append(f"The {what} of {units} were {source}.")
    return "\n".join(f'<p class="note">{_esc(n)}</p>' for n in notes)


def _per_muscle_section(study: StudyFolder) -> str:
    """The muscles costing most energy: the study's per_muscle.csv, top muscles per model."""
    import pandas as pd

    from ..analysis.per_muscle import PER_MUSCLE_FILE

    path = study.path / PER_MUSCLE_FILE
    if not path.is_file():
        return f'<p class="note">{PER_MUSCLE_FILE} is missing: run the study with this version to get it.</p>'
    try:
        pm = pd.read_csv(path, dtype={"subject": str, "trial": str, "workflow": str, "model": str})
    except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError) as exc:
        return f'<p class="note">{PER_MUSCLE_FILE} is not readable ({_esc(exc)}).</p>'
    if pm.empty or "mean_W_per_kg" not in pm.columns:
        return f'<p class="note">{PER_MUSCLE_FILE} holds no rows.</p>'
    from .figures import main_workflow, trial_order

    ok = study.ok
    trials = [t for t in trial_order(ok) if t in set(pm["trial"].astype(str))] if not ok.empty else []
    wf = main_workflow(_ordered(pm["workflow"]))
    d = pm[pm["workflow"].astype(str) == wf]
    models = [m for m in _models(study) if m in set(d["model"].astype(str))]
    top = 10
    parts = [f"<p>The {top} muscles with the largest cycle-average metabolic rate (W/kg of body mass, one leg, "
             f"without basal heat; mean over subjects) for workflow {_esc(wf)}, by model and trial; all muscles, "
             f"sides, workflows, components and stance/swing energies are in {PER_MUSCLE_FILE}.</p>"]
    for m in models:
        dm = d[d["model"].astype(str) == m]
        mean = dm.groupby(["muscle", "trial"])["mean_W_per_kg"].mean().unstack("trial")
        cols = [t for t in trials if t in mean.columns] or list(mean.columns)
        mean = mean[cols]
        order = mean.mean(axis=1).sort_values(ascending=False).index[:top]
        body = [[mu] + [f"{mean.loc[mu, t]:.3f}" if np.isfinite(mean.loc[mu, t]) else "–" for t in cols]
                for mu in order]
        parts.append(f"<h3>{_esc(m)}</h3>")
        parts.append(_table([[("muscle", 1)] + [(t, 1) for t in cols]], body, 1, "results"))
    return "\n".join(parts)


def _ordered(values) -> list[str]:
    out = []
    for v in values.astype(str):
        if v not in out:
            out.append(v)
    return out


def _results_section(study: StudyFolder) -> str:
    from .figures import group_stats, stat_cell, trial_order

    ok = study.ok
    parts = []
    if ok.empty:
        parts.append('<p class="note">No unit of the study succeeded: no results to tabulate.</p>')
        return "\n".join(parts)
    trials = trial_order(ok)
    workflows = [w for w in _workflows(study) if w in set(ok["workflow"].astype(str))]
    models = [m for m in _models(study) if m in set(ok["model"].astype(str))]
    n_sub = len(set(ok["subject"].astype(str)))
    tlabels = _trial_heading(ok, trials)
    label = dict(zip(trials, tlabels))
    parts.append(
        f"<p>Values are the mean [SD] over the {n_sub} subject{'s' if n_sub != 1 else ''} with a successful "
        "unit (SD shown when at least two subjects contribute); trials are ordered by walking speed "
        "(mean over subjects, m/s).</p>"
    )

    def pivot_section(hid, title, value, digits, text):
        parts.append(f'<h3 id="{hid}">{_esc(title)}</h3>')
        if value not in ok.columns or not ok[value].notna().any():
            parts.append(f'<p class="note">The results table has no values of {_esc(value)}.</p>')
            return
        parts.append(f"<p>{_esc(text)}</p>")
        parts.append(_pivot(ok, value, trials, tlabels, workflows, models, digits))

    pivot_section("table-whole-body", "Whole-body metabolic rate (W/kg)", "mean_W_per_kg", 2,
                  "Whole-body average metabolic rate over the gait cycle, W per kg of body mass: both legs "
                  f"({legs_text(study)}), with basal heat; rows: trial and metabolic model; columns: workflow.")
    if "measured_W_per_kg" in ok.columns and ok["measured_W_per_kg"].notna().any():
        meas = group_stats(ok.drop_duplicates(["subject", "trial"]), ["trial"], ["measured_W_per_kg"])
        body = [["measured"] + [_fmt(*stat_cell(meas, t, "measured_W_per_kg")[:2], 2) for t in trials]]
        parts.append("<p>Measured whole-body metabolic rate (W/kg, indirect calorimetry):</p>")
        parts.append(_table([[("", 1)] + [(lab, 1) for lab in tlabels]], body, 1, "results"))
    else:
        parts.append('<p class="note">No measured metabolic rate in the results.</p>')
    pivot_section("table-cost-of-transport", "Gross cost of transport (J/(kg·m))",
                  "gross_cost_of_transport_J_per_kg_per_m", 2,
                  "Gross metabolic cost of transport: the whole-body rate with basal heat (W/kg) divided by the "
                  "walking speed (m/s), in J per kg of body mass per metre.")
    pivot_section("table-net-cost-of-transport", "Net cost of transport (J/(kg·m))",
                  "net_cost_of_transport_J_per_kg_per_m", 2,
                  "Net metabolic cost of transport: the whole-body rate without basal heat (W/kg) divided by the "
                  "walking speed (m/s).")

    # phase shares
    parts.append('<h3 id="table-phase-shares">Stance and swing shares (%)</h3>')
    have = [c for c in ("stance_energy_share_pct", "swing_energy_share_pct", "swing_energy_share_with_basal_pct") if c in ok.columns]
    if "swing_energy_share_pct" not in have:
        parts.append('<p class="note">The results table has no phase shares.</p>')
    else:
        parts.append(
            "<p>Share of the cycle's muscle metabolic energy (one leg) spent in stance (initial contact to "
            "toe-off) and in swing (toe-off to the next initial contact), %, without basal heat; the column "
            "'swing, with basal' counts the basal heat as well.</p>"
        )
        names = {"stance_energy_share_pct": "stance", "swing_energy_share_pct": "swing", "swing_energy_share_with_basal_pct": "swing, with basal"}
        header = [[("trial (speed)", 1), ("model", 1)] + [(w, len(have)) for w in workflows],
                  [("", 1), ("", 1)] + [(names[c], 1) for _ in workflows for c in have]]
        body = []
        stats = group_stats(ok, ["trial", "model", "workflow"], have)
        present = set(zip(ok["trial"].astype(str), ok["model"].astype(str)))
        for t in trials:
            first = True
            for m in models:
                if (t, m) not in present:
                    continue
                row = [label[t] if first else "", m]
                first = False
                for w in workflows:
                    row += [_fmt(*stat_cell(stats, (t, m, w), c)[:2], 1) for c in have]
                body.append(row)
        parts.append(_table(header, body, 2, "results"))

    # group shares
    parts.append('<h3 id="table-group-shares">Muscle-group shares (%)</h3>')
    gcols = [(g, f"share_{g}_pct") for g in GROUPS if f"share_{g}_pct" in ok.columns]
    if not gcols:
        parts.append('<p class="note">The results table has no group shares.</p>')
    else:
        parts.append(
            "<p>Share of each muscle group in the cycle's muscle metabolic energy (one leg, without basal heat), "
            "%; each muscle's rate is distributed over the degrees of freedom it spans by moment-arm ratio. "
            "PF/DF: ankle plantar-/dorsiflexors; KE/KF: knee extensors/flexors; HE/HF: hip extensors/flexors; "
            "HAD/HAB: hip adductors/abductors; HIR/HER: hip internal/external rotators.</p>"
        )
        header = [[("workflow", 1), ("model", 1), ("trial", 1)] + [(g, 1) for g, _ in gcols]]
        body = []
        stats = group_stats(ok, ["workflow", "model", "trial"], [c for _, c in gcols])
        present = set(zip(ok["workflow"].astype(str), ok["model"].astype(str), ok["trial"].astype(str)))
        for w in workflows:
            for m in models:
                for t in trials:
                    if (w, m, t) not in present:
                        continue
                    body.append([w, m, label[t]] + [_fmt(*stat_cell(stats, (w, m, t), c)[:2], 1) for _, c in gcols])
        parts.append(_table(header, body, 3, "results"))
    return "\n".join(parts)


def _settings_section(study: StudyFolder) -> str:
    s = study.settings
    parts = ['<h2 id="settings">Settings</h2>']
    for n in study.notes:
        parts.append(f'<p class="note">{_esc(n)}</p>')
    items = [("study", study.name), ("folder", ". (the folder holding this report)"),
             ("workflows", ", ".join(_workflows(study))), ("metabolic models", ", ".join(_models(study)))]
    if s.get("basal") is not None:
        items.append(("whole-body basal rule", str(s["basal"])))
    parts.append("<dl>" + "".join(f"<dt>{_esc(k)}</dt><dd>{_esc(v)}</dd>" for k, v in items) + "</dl>")
    subjects = s.get("subjects") if isinstance(s.get("subjects"), dict) else {}
    names = _subjects(study)
    names = list(subjects) + [n for n in names if n not in subjects]
    body = []
    for n in names:
        rec = subjects.get(n) or {}
        mass, height = rec.get("body_mass_kg"), rec.get("height_m")
        trials = rec.get("trials")
        if not trials:
            trials = sorted(set(study.results.loc[study.results["subject"].astype(str) == n, "trial"].astype(str)))
        body.append([n, "–" if mass is None else f"{float(mass):g}", "–" if height is None else f"{float(height):g}",
                     _rel(study, rec.get("model")), ", ".join(map(str, trials))])
    parts.append("<h3>Subjects</h3>")
    parts.append(_table([[("subject", 1), ("body mass (kg)", 1), ("height (m)", 1), ("model", 1), ("trials", 1)]],
                        body, 1, "settings"))
    other = {k: (_rel(study, v) if k in ("source", "output") and v else v) for k, v in s.items()
             if k not in ("name", "workflows", "models", "subjects", "software")}
    if other:
        parts.append("<h3>Other settings (study.json)</h3>")
        parts.append(f"<pre>{_esc(json.dumps(other, indent=2, default=str))}</pre>")
    return "\n".join(parts)


def _failures_section(study: StudyFolder) -> str:
    parts = ['<h2 id="failures">Failures</h2>']
    rows = []
    seen = set()
    for _, r in study.failures.iterrows():
        key = (str(r["subject"]), str(r["trial"]), str(r["workflow"]))
        seen.add(key)
        rows.append([key[0], key[1] or "(all trials)", key[2], str(r["reason"])])
    bad = study.results[study.results["status"].astype(str).str.lower() != "ok"]
    for _, r in bad.drop_duplicates(["subject", "trial", "workflow"]).iterrows():
        key = (str(r["subject"]), str(r["trial"]), str(r["workflow"]))
        if key not in seen:
            rows.append([key[0], key[1], key[2], f"status '{r['status']}'"])
    if not rows:
        parts.append("<p>None: every unit of the study succeeded.</p>")
    else:
        parts.append(f"<p>{len(rows)} unit{'s' if len(rows) != 1 else ''} did not succeed; "
                     f"{'they are' if len(rows) != 1 else 'it is'} left out of the tables and figures.</p>")
        parts.append(_table([[("subject", 1), ("trial", 1), ("workflow", 1), ("reason", 1)]], rows, 0, "failures"))
    return "\n".join(parts)


def _software_section(study: StudyFolder) -> str:
    from ..study.runner import software_versions

    run = study.settings.get("software") if isinstance(study.settings.get("software"), dict) else {}
    now = software_versions()
    names = list(now) + [k for k in run if k not in now]
    body = [[n, str(run.get(n, "not recorded by the run")), now.get(n, "not installed here")] for n in names]
    parts = ['<h2 id="software">Software</h2>',
             "<p>Versions recorded by the study run (study.json) and those installed where this report was "
             "written (read from the packages' metadata; none is imported). OpenSim is used only by the study "
             "run (muscle geometry, states export); dask and distributed only to run units on a cluster.</p>",
             _table([[("package", 1), ("study run", 1), ("report", 1)]], body, 1, "software")]
    return "\n".join(parts)


#: Columns of the solver-run table: (heading, format) of the run record's status, iterations,
#: solve time and largest constraint violation, then of the solution's moment residual and
#: reserve share (summary.json).
RUN_COLUMNS = (
    ("solver status", "{}"),
    ("iterations", "{:d}"),
    ("solve time (s)", "{:.2f}"),
    ("max. constraint violation", "{:.1e}"),
    ("max. moment residual (N·m)", "{:.1e}"),
    ("reserve / peak moment", "{:.4f}"),
)


def solver_runs(study: StudyFolder) -> list[list[str]]:
    """One row per unit of the results and of the failures: subject, trial, workflow, side,
    then :data:`RUN_COLUMNS` from the unit's ``summary.json`` (its
    :class:`~musclemetab.redundancy.record.RunRecord` and the solution's residuals); ``–``
    where a value is not recorded, and why where the file cannot be read."""
    from ..io.jsonfile import read_json_object
    from ..redundancy.record import RunRecord

    units = []
    for table in (study.results, study.failures):
        for r in table.drop_duplicates(["subject", "trial", "workflow"]).to_dict("records") if len(table) else []:
            key = (str(r["subject"]), str(r["trial"]), str(r["workflow"]))
            if key not in [u[0] for u in units]:
                units.append((key, r))
    rows = []
    legs = [(key, folder) for key, r in units if key[1] and key[1] != "nan"  # else: no unit folder
            for folder in study.leg_folders(r).values()]
    for key, folder in legs:
        path = folder / "summary.json"
        try:
            summary = read_json_object(path, missing="missing", remedy="run the unit again")
        except MusclemetabError as exc:
            rows.append(list(key) + ["–", _short(study, exc)] + ["–"] * (len(RUN_COLUMNS) - 1))
            continue
        run = RunRecord.from_dict(summary)
        values = (run.status, run.iterations if run.iterations >= 0 else None, run.solve_time_s,
                  run.max_constraint_violation, summary.get("max_moment_residual_Nm"),
                  summary.get("reserve_share_of_peak_moment"))
        cells = []
        for (_, fmt), v in zip(RUN_COLUMNS, values):
            if v is None or (isinstance(v, float) and not np.isfinite(v)):
                cells.append("–")
                continue
            try:
                cells.append(fmt.format(v))
            except (TypeError, ValueError):
                cells.append(str(v))
        side = str(summary.get("side", "r"))
        rows.append(list(key) + [_SIDES.get(side, side)] + cells)
    return rows


def _runs_section(study: StudyFolder) -> str:
    rows = solver_runs(study)
    parts = ['<details id="solver-runs"><summary><h2>Solver runs</h2></summary>',
             "<p>The muscle redundancy solve of every unit, from its summary.json: the solver's status, "
             "its iterations and time, and how well the solution meets the dynamics (largest constraint "
             "violation, largest joint-moment residual) with how much of the peak joint moment the reserve "
             "actuators carry.</p>"]
    if rows:
        parts.append(_table([[("subject", 1), ("trial", 1), ("workflow", 1), ("side", 1)]
                             + [(h, 1) for h, _ in RUN_COLUMNS]], rows, 3, "runs"))
    else:
        parts.append("<p>No unit in the results.</p>")
    parts.append("</details>")
    return "\n".join(parts)


_SIDES = {"r": "right", "l": "left"}


def legs_text(study: StudyFolder) -> str:
    """How the whole-body rate counts the legs: the solved leg of each subject doubled, or
    the sum of both solved legs (``side = "both"``)."""
    subjects = study.settings.get("subjects") if isinstance(study.settings.get("subjects"), dict) else {}
    sides = {}
    for name in _subjects(study):
        rec = subjects.get(name) if isinstance(subjects.get(name), dict) else {}
        side = str(rec.get("side", "r"))
        key = "both" if side == "both" else _SIDES.get(side, side)
        sides.setdefault(key, []).append(name)
    both = "the sum of both solved legs, each averaged over its own gait cycle"
    if len(sides) == 1:
        side = next(iter(sides))
        return both if side == "both" else f"one leg doubled (the {side} leg was solved)"
    each = "; ".join(f"{both if side == 'both' else f'the {side} leg doubled'} for {', '.join(names)}"
                     for side, names in sides.items())
    return f"per subject: {each}"


def _method_section(study: StudyFolder) -> str:
    basal = study.settings.get("basal", "body")
    basal_txt = {
        "body": "plus a basal heat of 1.2 W per kg of body mass",
        "muscle": "with a basal heat of 1.2 W per kg of muscle mass in every muscle",
        "none": "without basal heat",
    }.get(str(basal), f"basal rule '{basal}'")
    text = (
        "For every subject, trial and workflow, muscle-tendon lengths and moment arms (m) of the solved leg "
        "were computed with OpenSim from the inverse kinematics; the muscle redundancy problem with compliant "
        "tendons was solved by direct collocation to reproduce the inverse-dynamics joint moments (N·m) with "
        "minimal effort (workflows EFFORT-GEN: generic passive and tendon properties; EFFORT-CAL: calibrated "
        "passive properties; EFFORT-TEN: calibrated passive properties and personalised tendon stiffness; "
        "EMG-TEN: EMG-informed). The metabolic models (UM03, BH04, HO06, LW07, UM10, UC16) give each muscle's "
        "metabolic rate (W) at every node of the gait cycle (initial contact to the next initial contact of the "
        "same leg). The whole-body average rate (W/kg) counts both legs as "
        f"{legs_text(study)} (a leg's rate: the sum of its muscles' rates averaged over its cycle), divided by the "
        f"body mass, {basal_txt}; the gross cost of transport (J/(kg·m)) is "
        "that rate divided by the walking speed (m/s), the net cost the same without the basal heat. Phase shares are the stance (initial contact to toe-off) and "
        "swing parts of the cycle's one-leg muscle energy (%, without basal heat). Group shares distribute "
        "each muscle's rate over the degrees of freedom it spans in proportion to the absolute moment arms, "
        "and to the group given by the sign of the moment arm (%). Estimated and measured rates, and shares "
        "against speed, are related by repeated-measures correlation (common within-subject slope, one "
        "intercept per subject)."
    )
    return f'<h2 id="method">Method</h2>\n<p>{_esc(text)}</p>'


def _figures_section(entries: Sequence[FigureEntry], figures_rel: str) -> str:
    parts = ['<h2 id="figures">Figures</h2>']
    for i, e in enumerate(entries, 1):
        parts.append(f'<h3 id="figure-{_esc(e.name)}">Figure {i}. {_esc(e.title)}</h3>')
        if e.paths is None:
            parts.append(f'<p class="note">Not drawn: {_esc(e.note or "no data")}</p>')
            continue
        data = base64.b64encode(Path(e.paths["png"]).read_bytes()).decode("ascii")
        files = ", ".join(f"{figures_rel}/{e.name}.{ext}" for ext in e.paths)
        parts.append(
            f'<figure><img alt="{_esc(e.title)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{_esc(e.caption)} File{'s' if len(e.paths) > 1 else ''}: {_esc(files)}.</figcaption></figure>"
        )
    return "\n".join(parts)


_CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 2em auto; max-width: 1200px;
       padding: 0 1em; color: #222; line-height: 1.45; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccc; margin-top: 2em; }
table { border-collapse: collapse; margin: 0.6em 0 1.2em; font-size: 0.85em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.5em; text-align: right; }
thead th { background: #f0f0f0; text-align: center; } tbody th { text-align: left; background: #fafafa; }
table.failures td, table.settings td { text-align: left; }
figure { margin: 1em 0; } figure img { max-width: 100%; height: auto; border: 1px solid #eee; }
figcaption { font-size: 0.85em; color: #444; }
.note { color: #8a4b00; background: #fff6e5; padding: 0.3em 0.6em; border-left: 3px solid #e0a040; }
dl { display: grid; grid-template-columns: max-content auto; gap: 0.2em 1em; } dt { font-weight: bold; }
dd { margin: 0; } pre { background: #f7f7f7; padding: 0.6em; overflow-x: auto; font-size: 0.8em; }
.meta { color: #666; font-size: 0.9em; }
"""


def page_sections(study: StudyFolder) -> dict[str, str]:
    """The parts of the report page that do not depend on the figures (HTML by part name):
    estimation notes, result and per-muscle tables, settings, method, failures, solver runs
    and software."""
    return {
        "notes": _estimation_notes(study),
        "results": _results_section(study),
        "per_muscle": _per_muscle_section(study),
        "settings": _settings_section(study),
        "method": _method_section(study),
        "failures": _failures_section(study),
        "runs": _runs_section(study),
        "software": _software_section(study),
    }


def render_html(study: StudyFolder, entries: Sequence[FigureEntry], figures_rel: str = FIGURES_FOLDER,
                key: str | None = None, sections: dict[str, str] | None = None) -> str:
    """The report page as a string (figures embedded from the PNG files of ``entries``;
    ``key``: the content key of the inputs, recorded in the page, see :func:`report_key`;
    ``sections``: :func:`page_sections` of the study when already made)."""
    from .. import __version__

    sec = page_sections(study) if sections is None else sections
    ok = study.ok
    n_units = len(study.results.drop_duplicates(["subject", "trial", "workflow"])) if not study.results.empty else 0
    n_ok = len(ok.drop_duplicates(["subject", "trial", "workflow"])) if not ok.empty else 0
    when = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    title = f"musclemetab study report: {study.name}"
    drawn = sum(e.paths is not None for e in entries)
    summary = (f"{len(_subjects(study))} subject(s), {len(set(study.results['trial'].astype(str)))} trial(s), "
               f"{len(_workflows(study))} workflow(s), {len(_models(study))} metabolic model(s); "
               f"{n_ok} of {n_units} subject × trial × workflow units in the results succeeded; "
               f"{drawn} of {len(entries)} figures drawn.")
    toc = "".join(f'<li><a href="#{a}">{_esc(t)}</a></li>' for a, t in (
        ("figures", "Figures"), ("results", "Results (tables)"), ("per-muscle", "Per-muscle results"),
        ("settings", "Settings"), ("method", "Method"), ("failures", "Failures"), ("solver-runs", "Solver runs"),
        ("software", "Software")))
    body = "\n".join([
        f"<h1>{_esc(title)}</h1>",
        f'<p class="meta">Written {_esc(when)} by musclemetab {_esc(__version__)}; '
        "paths are relative to the study folder (the folder holding this page).</p>",
        f"<p>{_esc(summary)}</p>",
        sec["notes"],
        f"<nav><ul>{toc}</ul></nav>",
        _figures_section(entries, figures_rel),
        f'<details id="results" open><summary><h2>Results (tables)</h2></summary>{sec["results"]}</details>',
        f'<details id="per-muscle"><summary><h2>Per-muscle results</h2></summary>{sec["per_muscle"]}'
        "</details>",
        sec["settings"],
        sec["method"],
        sec["failures"],
        sec["runs"],
        sec["software"],
        f'<meta name="musclemetab-report-key" content="{_esc(key)}">' if key else "",
    ])
    return (
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        f"<title>{_esc(title)}</title>\n<style>{_CSS}</style>\n</head>\n<body>\n{body}\n</body>\n</html>\n"
    )


REPORT_RECORD = "report.json"


def report_key(study_dir: str | os.PathLike, formats: Sequence[str] = ("png",)) -> str:
    """SHA-256 of everything the report is drawn from.

    The study's tables (``results.csv``, ``study.json``, ``failures.csv``, ``per_muscle.csv``),
    the study file ``study.json`` names as its source (``study.toml``), every unit's
    ``unit.json`` (which records the hash of each of the unit's files, ``summary.json``
    among them), the figure formats, the package version and the source of the report's
    own modules.
    """
    import hashlib

    from .. import __version__
    from ..io.atomic import file_sha256
    from . import figures as _figures

    path = Path(study_dir)
    h = hashlib.sha256()
    h.update(f"musclemetab {__version__}; formats {','.join(formats)}\n".encode())
    for src in (Path(__file__), Path(_figures.__file__)):
        h.update(src.read_bytes())
    files = [path / n for n in (RESULTS_CSV, STUDY_JSON, FAILURES_CSV, "per_muscle.csv")]
    files += sorted((path / "units").glob(f"**/{UNIT_FILE}")) if (path / "units").is_dir() else []
    for f in files:
        digest = file_sha256(f) if f.is_file() else "absent"
        h.update(f"{f.relative_to(path).as_posix()} {digest}\n".encode())
    source = _study_file(path)
    if source is not None:  # the study file the settings came from (e.g. study.toml), wherever it is
        h.update(f"study file {file_sha256(source) if source.is_file() else 'absent'}\n".encode())
    return h.hexdigest()


def _study_file(study_dir: Path) -> Path | None:
    """The study file recorded as ``source`` in ``study.json`` (relative to the study folder
    when not absolute), or ``None``."""
    import json as _json

    try:
        source = _json.loads((study_dir / STUDY_JSON).read_text(encoding="utf-8")).get("source")
    except (OSError, ValueError, AttributeError):
        return None
    if not isinstance(source, str) or not source.strip():
        return None
    p = Path(source)
    return p if p.is_absolute() else study_dir / p


def _cached_entries(out: Path, key: str) -> list[FigureEntry] | None:
    """The figure entries of the report at ``out`` if it was written from inputs with ``key``."""
    from ..io.jsonfile import read_json_object

    record = out.parent / FIGURES_FOLDER / REPORT_RECORD
    if not (out.is_file() and record.is_file()):
        return None
    try:
        rec = read_json_object(record, remedy="the report is rebuilt")
    except MusclemetabError:
        return None
    if rec.get("key") != key or rec.get("page") != out.name:
        return None
    try:
        entries = [FigureEntry(e["name"], e["title"], e.get("caption", ""),
                               None if e.get("paths") is None else {k: Path(v) for k, v in e["paths"].items()},
                               e.get("note")) for e in rec.get("entries") or []]
    except (KeyError, TypeError, AttributeError):
        return None
    if any(e.paths is not None and not all(p.is_file() for p in e.paths.values()) for e in entries):
        return None
    if f'content="{key}"' not in out.read_text(encoding="utf-8", errors="replace"):
        return None
    return entries


def generate_report(study_dir: str | os.PathLike, out: str | os.PathLike | None = None, *,
                    formats: Sequence[str] = ("png",), force: bool = False,
                    workers: int | None = None) -> tuple[Path, list[FigureEntry]]:
    """:func:`write_report`, also returning the figure entries (files written or notes)."""
    from ..io.atomic import atomic_write_text

    study_dir = Path(study_dir)
    study = read_study_folder(study_dir)
    out = Path(out) if out is not None else study.path / REPORT_FILE
    if out.is_dir():
        out = out / REPORT_FILE
    formats = tuple(dict.fromkeys(("png", *formats)))  # the page embeds the PNG
    key = report_key(study.path, formats)
    if not force:
        cached = _cached_entries(out, key)
        if cached is not None:
            return out, cached
    fig_dir = out.parent / FIGURES_FOLDER
    sections: dict[str, str] = {}
    entries = make_figures(study, fig_dir, formats, workers, meanwhile=lambda: sections.update(page_sections(study)))
    atomic_write_text(out, render_html(study, entries, figures_rel=FIGURES_FOLDER, key=key, sections=sections))
    record = {"key": key, "page": out.name, "entries": [
        {"name": e.name, "title": e.title, "caption": e.caption, "note": e.note,
         "paths": None if e.paths is None else {k: str(v) for k, v in e.paths.items()}} for e in entries]}
    atomic_write_text(fig_dir / REPORT_RECORD, json.dumps(record, indent=1) + "\n")
    return out, entries


def write_report(study_dir: str | os.PathLike, out: str | os.PathLike | None = None, *,
                 formats: Sequence[str] = ("png",), force: bool = False, workers: int | None = None) -> Path:
    """Write the figures and the HTML report of a study folder; return the report's path.

    ``out`` is the HTML file (default ``study_dir/report.html``); the figures are written to the
    folder ``figures`` beside it (PNG; ``formats=("png", "svg")`` adds SVG). Everything is
    written atomically. The report is rebuilt only when its inputs changed (their content
    hash, :func:`report_key`, is recorded in the page and in ``figures/report.json``) or
    when ``force`` is true. ``workers`` processes draw the figures (see :func:`make_figures`).
    Raises :class:`InputFileError` when the folder or its ``results.csv`` is missing.
    """
    return generate_report(study_dir, out, formats=formats, force=force, workers=workers)[0]
