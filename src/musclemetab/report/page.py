"""The report's HTML page: one self-contained file.

:func:`page_tables` makes the parts of the page that do not depend on the figures (the
numbers of the result, per-muscle, settings, failure, solver-run and software tables, as
:class:`Table` objects and plain values); :func:`render_page` puts them and the figures
(embedded as base64 PNG) into the page through the Jinja2 template ``templates/report.html``,
which holds the page's structure and prose. Every value from the study folder is
HTML-escaped by the template. The page needs nothing else: no external resource, no script.
"""

from __future__ import annotations

import base64
import datetime as _dt
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..analysis.groups import GROUPS_WITH_OTHER as GROUPS
from ..errors import MusclemetabError
from .folder import StudyFolder

__all__ = ["Table", "page_tables", "render_page", "solver_runs", "legs_text", "uncertainty_section", "RUN_COLUMNS", "TEMPLATE"]

#: The page's template (package data of :mod:`musclemetab.report`).
TEMPLATE = "report.html"

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
_SIDES = {"r": "right", "l": "left"}
#: Muscles of each model in the per-muscle tables.
TOP_MUSCLES = 10


@dataclass
class Table:
    """An HTML table: ``header`` rows of ``(text, colspan)``; the first ``n_index`` cells of a
    body row are row headings."""

    header: list[list[tuple[str, int]]]
    body: list[list[str]]
    n_index: int
    cls: str = ""


def _fmt(mean: float, sd: float, digits: int) -> str:
    if not np.isfinite(mean):
        return "–"
    if np.isfinite(sd):
        return f"{mean:.{digits}f} [{sd:.{digits}f}]"
    return f"{mean:.{digits}f}"


# ------------------------------------------------------------------ results
def _pivot(ok, value: str, trials: Sequence[str], labels: Sequence[str], workflows: Sequence[str],
           models: Sequence[str], digits: int) -> Table | None:
    """Rows: trial (headed by ``labels``) × model; columns: workflow; cells: mean [SD] over
    subjects; ``None`` when the results have no value of the column."""
    from .figures import group_stats, stat_cell

    if value not in ok.columns or not ok[value].notna().any():
        return None
    stats = group_stats(ok, ["trial", "model", "workflow"], [value])
    present = set(zip(ok["trial"].astype(str), ok["model"].astype(str)))
    body = []
    for t, lab in zip(trials, labels):
        first = True
        for m in models:
            if (t, m) not in present:
                continue
            body.append([lab if first else "", m] + [_fmt(*stat_cell(stats, (t, m, w), value)[:2], digits)
                                                     for w in workflows])
            first = False
    return Table([[("trial (speed)", 1), ("model", 1)] + [(w, 1) for w in workflows]], body, 2, "results")


def _trial_heading(ok, trials) -> list[str]:
    from .figures import group_stats, stat_cell

    if "speed_m_per_s" not in ok.columns:
        return [str(t) for t in trials]
    stats = group_stats(ok, ["trial"], ["speed_m_per_s"])
    out = []
    for t in trials:
        m = stat_cell(stats, t, "speed_m_per_s")[0]
        out.append(f"{t} ({m:.2f} m/s)" if np.isfinite(m) else t)
    return out


def _results(study: StudyFolder) -> dict | None:
    """The result tables (``None`` when no unit succeeded)."""
    from .figures import group_stats, stat_cell, trial_order

    ok = study.ok
    if ok.empty:
        return None
    trials = trial_order(ok)
    workflows = [w for w in study.workflows() if w in set(ok["workflow"].astype(str))]
    models = [m for m in study.models() if m in set(ok["model"].astype(str))]
    labels = _trial_heading(ok, trials)
    label = dict(zip(trials, labels))
    out = {"n_subjects": len(set(ok["subject"].astype(str)))}
    for key, value in (("whole_body", "whole_body_W_per_kg"), ("gross_cost", "gross_cost_of_transport_J_per_kg_per_m"),
                       ("net_cost", "net_cost_of_transport_J_per_kg_per_m")):
        out[key] = _pivot(ok, value, trials, labels, workflows, models, 2)
    out["measured"] = None
    if "measured_W_per_kg" in ok.columns and ok["measured_W_per_kg"].notna().any():
        meas = group_stats(ok.drop_duplicates(["subject", "trial"]), ["trial"], ["measured_W_per_kg"])
        body = [["measured"] + [_fmt(*stat_cell(meas, t, "measured_W_per_kg")[:2], 2) for t in trials]]
        out["measured"] = Table([[("", 1)] + [(lab, 1) for lab in labels]], body, 1, "results")

    # stance and swing shares
    have = [c for c in ("stance_energy_share_pct", "swing_energy_share_pct", "swing_energy_share_with_basal_pct")
            if c in ok.columns]
    out["phase_shares"] = None
    if "swing_energy_share_pct" in have:
        names = {"stance_energy_share_pct": "stance", "swing_energy_share_pct": "swing",
                 "swing_energy_share_with_basal_pct": "swing, with basal"}
        header = [[("trial (speed)", 1), ("model", 1)] + [(w, len(have)) for w in workflows],
                  [("", 1), ("", 1)] + [(names[c], 1) for _ in workflows for c in have]]
        stats = group_stats(ok, ["trial", "model", "workflow"], have)
        present = set(zip(ok["trial"].astype(str), ok["model"].astype(str)))
        body = []
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
        out["phase_shares"] = Table(header, body, 2, "results")

    # muscle-group shares
    gcols = [(g, f"share_{g}_pct") for g in GROUPS if f"share_{g}_pct" in ok.columns]
    out["group_shares"] = None
    if gcols:
        stats = group_stats(ok, ["workflow", "model", "trial"], [c for _, c in gcols])
        present = set(zip(ok["workflow"].astype(str), ok["model"].astype(str), ok["trial"].astype(str)))
        body = [[w, m, label[t]] + [_fmt(*stat_cell(stats, (w, m, t), c)[:2], 1) for _, c in gcols]
                for w in workflows for m in models for t in trials if (w, m, t) in present]
        out["group_shares"] = Table([[("workflow", 1), ("model", 1), ("trial", 1)] + [(g, 1) for g, _ in gcols]],
                                    body, 3, "results")
    out["spread"] = _spread(ok)
    return out


def _spread(ok) -> Table:
    """The structural spread of each subject's trial (:func:`musclemetab.analysis.spread.structural_spread`):
    the whole-body rate and each group's part of it, the ranges across models, workflows, trials."""
    from ..analysis.spread import WHOLE_BODY, structural_spread

    spread = structural_spread(ok)
    names = {WHOLE_BODY: "whole body"}
    body = []
    last = None
    for r in spread.itertuples(index=False):
        unit = (r.subject, r.trial)
        q = names.get(r.quantity, r.quantity[len("group_"):-len("_W_per_kg")] if r.quantity.startswith("group_")
                      else r.quantity)
        body.append([f"{r.subject} {r.trial}" if unit != last else "", q, _fmt(r.mean_W_per_kg, np.nan, 2)]
                    + [_fmt(v, np.nan, 2) for v in (r.range_across_models_W_per_kg, r.range_across_workflows_W_per_kg,
                                                   r.range_across_trials_W_per_kg)] + [r.largest or "–"])
        last = unit
    header = [[("subject, trial", 1), ("quantity", 1), ("mean", 1), ("range across models", 1),
               ("range across workflows", 1), ("range across trials", 1), ("largest", 1)]]
    return Table(header, body, 2, "results")


def _estimation_notes(study: StudyFolder) -> list[str]:
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
    return notes


def _muscle_names(per_muscle) -> dict[str, str]:
    """Model muscle -> the name the figures give it (:func:`~.figures.muscle_names`: the
    anatomical muscle with the model's name), each subject's muscles placed in its model family."""
    from .figures import muscle_names

    names: dict[str, str] = {}
    by = per_muscle.groupby(per_muscle["subject"].astype(str)) if "subject" in per_muscle.columns else [(None, per_muscle)]
    for _, ds in by:
        names.update(muscle_names(ds["muscle"].astype(str).unique()))
    return names


def _per_muscle(study: StudyFolder) -> dict:
    """The muscles costing most energy: ``{"note": ...}``, or the workflow and one table per model."""
    from ..study_layout import PER_MUSCLE_FILE
    from .figures import main_workflow, trial_order

    try:
        pm = study.read_per_muscle()
    except MusclemetabError as exc:
        return {"note": f"{exc}."}
    if pm is None:
        return {"note": f"{PER_MUSCLE_FILE} is missing: run the study with this version to get it."}
    if pm.empty or "muscle_W_per_kg" not in pm.columns:
        return {"note": f"{PER_MUSCLE_FILE} holds no rows."}
    ok = study.ok
    trials = [t for t in trial_order(ok) if t in set(pm["trial"].astype(str))] if not ok.empty else []
    wf = main_workflow(list(dict.fromkeys(pm["workflow"].astype(str))))
    d = pm[pm["workflow"].astype(str) == wf]
    names = _muscle_names(d)
    tables = {}
    for m in [m for m in study.models() if m in set(d["model"].astype(str))]:
        dm = d[d["model"].astype(str) == m]
        mean = dm.groupby(["muscle", "trial"])["muscle_W_per_kg"].mean().unstack("trial")
        cols = [t for t in trials if t in mean.columns] or list(mean.columns)
        mean = mean[cols]
        order = mean.mean(axis=1).sort_values(ascending=False).index[:TOP_MUSCLES]
        body = [[names.get(mu, mu)] + [f"{mean.loc[mu, t]:.3f}" if np.isfinite(mean.loc[mu, t]) else "–"
                                       for t in cols] for mu in order]
        tables[m] = Table([[("muscle", 1)] + [(t, 1) for t in cols]], body, 1, "results")
    return {"note": None, "workflow": wf, "top": TOP_MUSCLES, "file": PER_MUSCLE_FILE, "tables": tables}


# ------------------------------------------------------------------ settings, failures, runs, software
def _settings(study: StudyFolder) -> dict:
    s = study.settings
    items = [("study", study.name), ("folder", ". (the folder holding this report)"),
             ("workflows", ", ".join(study.workflows())), ("metabolic models", ", ".join(study.models()))]
    if s.get("basal") is not None:
        items.append(("whole-body basal rule", str(s["basal"])))
    subjects = s.get("subjects") if isinstance(s.get("subjects"), dict) else {}
    names = list(subjects) + [n for n in study.subjects() if n not in subjects]
    body = []
    for n in names:
        rec = subjects.get(n) or {}
        mass, height = rec.get("body_mass_kg"), rec.get("height_m")
        trials = rec.get("trials")
        if not trials:
            trials = sorted(set(study.results.loc[study.results["subject"].astype(str) == n, "trial"].astype(str)))
        body.append([n, "–" if mass is None else f"{float(mass):g}", "–" if height is None else f"{float(height):g}",
                     study.relative(rec.get("model")), ", ".join(map(str, trials))])
    subjects_table = Table([[("subject", 1), ("body mass (kg)", 1), ("height (m)", 1), ("model", 1), ("trials", 1)]],
                           body, 1, "settings")
    other = {k: (study.relative(v) if k in ("source", "output") and v else v) for k, v in s.items()
             if k not in ("name", "workflows", "models", "subjects", "software")}
    return {"notes": study.notes, "fields": items, "subjects": subjects_table,
            "other": json.dumps(other, indent=2, default=str) if other else None}


def _interrupted(study: StudyFolder) -> Table | None:
    """The units a run stopped by Ctrl-C did not finish (``failures.csv`` with status
    ``interrupted``; their previous folders are kept), or ``None``."""
    rows = [[str(r["subject"]), str(r["trial"]) or "(all trials)", str(r["workflow"]), str(r["reason"])]
            for _, r in study.failures.iterrows() if str(r["status"]) == "interrupted"]
    if not rows:
        return None
    return Table([[("subject", 1), ("trial", 1), ("workflow", 1), ("reason", 1)]], rows, 0, "failures")


def _failures(study: StudyFolder) -> Table | None:
    """The units that did not succeed (``failures.csv``, then the results' status), or ``None``;
    the interrupted ones apart (:func:`_interrupted`)."""
    rows = []
    seen = set()
    for _, r in study.failures.iterrows():
        key = (str(r["subject"]), str(r["trial"]), str(r["workflow"]))
        seen.add(key)
        if str(r["status"]) != "interrupted":
            rows.append([key[0], key[1] or "(all trials)", key[2], str(r["reason"])])
    bad = study.results[study.results["status"].astype(str).str.lower() != "ok"]
    for _, r in bad.drop_duplicates(["subject", "trial", "workflow"]).iterrows():
        key = (str(r["subject"]), str(r["trial"]), str(r["workflow"]))
        if key not in seen:
            rows.append([key[0], key[1], key[2], f"status '{r['status']}'"])
    if not rows:
        return None
    return Table([[("subject", 1), ("trial", 1), ("workflow", 1), ("reason", 1)]], rows, 0, "failures")


#: Flags of a unit's record (``results.csv`` column = ``summary.json`` key) and what they say.
FLAGS = {
    "large_reserve": "large reserve actuators: the reserves carry a large share of the peak joint moment "
                     "(reserve share of peak moment {reserve_share_of_peak_moment})",
}


def flagged_units(study: StudyFolder) -> Table | None:
    """The successful units with a flag, or ``None``: one row per unit and flag, the units with
    plausibility flags first (the ``quality`` column of ``results.csv``, ``docs/quality.md``: the
    solve's flags with their messages from each leg's ``summary.json``, the metabolic ones
    worked again from the row), then those with a flag of :data:`FLAGS` (a true value in ``results.csv``)."""
    ok = study.ok
    rows = _plausibility_rows(study, ok)
    for flag, text in FLAGS.items():
        if flag not in ok.columns:
            continue
        set_ = ok[ok[flag].astype(str).str.strip().str.lower().isin(("true", "1", "yes"))]
        for _, r in set_.drop_duplicates(["subject", "trial", "workflow"]).iterrows():
            try:
                share = study.summary(study.unit_folder(r)).reserve_share_of_peak_moment
                share = f"{100 * float(share):.1f} %" if np.isfinite(float(share)) else "not recorded"
            except (MusclemetabError, TypeError, ValueError):
                share = "not recorded"
            rows.append([str(r["subject"]), str(r["trial"]), str(r["workflow"]), flag,
                         text.format(reserve_share_of_peak_moment=share)])
    if not rows:
        return None
    return Table([[("subject", 1), ("trial", 1), ("workflow", 1), ("flag", 1), ("meaning", 1)]], rows, 0, "failures")


#: ``quality`` values of ``results.csv`` that carry no flag
_NO_FLAG = ("ok", "not checked", "nan", "")


def _plausibility_rows(study: StudyFolder, ok) -> list[list[str]]:
    """Rows of :func:`flagged_units` for the units whose ``quality`` is not ``ok``."""
    from ..metabolics.plausibility import results_rows_flags

    if "quality" not in ok.columns:
        return []
    flagged = ok[~ok["quality"].astype(str).str.strip().isin(_NO_FLAG)]
    rows = []
    for key, unit in flagged.groupby(["subject", "trial", "workflow"], sort=False):
        key = [str(k) for k in key]
        first = unit.iloc[0]
        for side, folder in study.leg_folders(first).items():
            try:
                flags = study.summary(folder).flags
            except MusclemetabError as exc:
                rows.append(key + ["(solve)", study.short(exc)])
                continue
            rows += [key + [f.code, f.message] for f in flags]
        rows += [key + [f.code, f.message] for f in results_rows_flags(unit)]  # the rows' own, as in quality
    return rows


def solver_runs(study: StudyFolder) -> list[list[str]]:
    """One row per unit of the results and of the failures: subject, trial, workflow, side,
    then :data:`RUN_COLUMNS` from the unit's ``summary.json`` (its
    :class:`~musclemetab.redundancy.record.RunRecord` and the solution's residuals); ``–``
    where a value is not recorded, and why where the file cannot be read."""
    rows = []
    legs = [(key, folder) for key, r in study.units() if key[1] and key[1] != "nan"  # else: no unit folder
            for folder in study.leg_folders(r).values()]
    for key, folder in legs:
        try:
            summary = study.summary(folder)
        except MusclemetabError as exc:
            rows.append(list(key) + ["–", study.short(exc)] + ["–"] * (len(RUN_COLUMNS) - 1))
            continue
        run = summary.run_record
        values = (run.status, run.iterations if run.iterations >= 0 else None, run.solve_time_s,
                  run.max_constraint_violation, summary.max_moment_residual_Nm, summary.reserve_share_of_peak_moment)
        cells = []
        for (_, fmt), v in zip(RUN_COLUMNS, values):
            if v is None or (isinstance(v, float) and not np.isfinite(v)):
                cells.append("–")
                continue
            try:
                cells.append(fmt.format(v))
            except (TypeError, ValueError):
                cells.append(str(v))
        side = str(summary.side or "r")
        rows.append(list(key) + [_SIDES.get(side, side)] + cells)
    return rows


def _runs(study: StudyFolder) -> Table | None:
    rows = solver_runs(study)
    if not rows:
        return None
    return Table([[("subject", 1), ("trial", 1), ("workflow", 1), ("side", 1)] + [(h, 1) for h, _ in RUN_COLUMNS]],
                 rows, 3, "runs")


def _software(study: StudyFolder) -> Table:
    from ..study_layout import software_versions

    run = study.settings.get("software") if isinstance(study.settings.get("software"), dict) else {}
    now = software_versions()
    names = list(now) + [k for k in run if k not in now]
    body = [[n, str(run.get(n, "not recorded by the run")), now.get(n, "not installed here")] for n in names]
    return Table([[("package", 1), ("study run", 1), ("report", 1)]], body, 1, "software")


def legs_text(study: StudyFolder) -> str:
    """How the whole-body rate counts the legs: the solved leg of each subject doubled, or
    the sum of both solved legs (``side = "both"``)."""
    sides: dict[str, list[str]] = {}
    for name in study.subjects():
        side = str(study.subject_record(name).get("side", "r"))
        key = "both" if side == "both" else _SIDES.get(side, side)
        sides.setdefault(key, []).append(name)
    both = "the sum of both solved legs, each averaged over its own gait cycle"
    if len(sides) == 1:
        side = next(iter(sides))
        return both if side == "both" else f"one leg doubled (the {side} leg was solved)"
    each = "; ".join(f"{both if side == 'both' else f'the {side} leg doubled'} for {', '.join(names)}"
                     for side, names in sides.items())
    return f"per subject: {each}"


def page_tables(study: StudyFolder) -> dict:
    """The parts of the page that do not depend on the figures: estimation notes, result and
    per-muscle tables, settings, the method's choices, failures, solver runs and software."""
    ok = study.ok
    units = ["subject", "trial", "workflow"]
    flagged = flagged_units(study)
    return {
        "name": study.name,
        "n_subjects": len(study.subjects()),
        "n_trials": len(set(study.results["trial"].astype(str))),
        "n_workflows": len(study.workflows()),
        "n_models": len(study.models()),
        "n_units": len(study.results.drop_duplicates(units)) if not study.results.empty else 0,
        "n_ok": len(ok.drop_duplicates(units)) if not ok.empty else 0,
        "notes": _estimation_notes(study),
        "legs": legs_text(study),
        "basal": str(study.settings.get("basal", "body")),
        "results": _results(study),
        "per_muscle": _per_muscle(study),
        "uncertainty": uncertainty_section(study),
        "sensitivity": _sensitivity(study),
        "settings": _settings(study),
        "failures": _failures(study),
        "interrupted": _interrupted(study),
        "flagged": flagged,
        "n_flagged": len({tuple(r[:3]) for r in flagged.body}) if flagged is not None else 0,
        "runs": _runs(study),
        "software": _software(study),
    }


def _sensitivity(study: StudyFolder) -> dict | None:
    """The sensitivity section (:func:`.sensitivity.sensitivity_section`) with a :class:`Table` per unit."""
    from .sensitivity import sensitivity_section

    section = sensitivity_section(study)
    if section is not None:
        for u in section["units"]:
            u["table"] = Table([[(h, 1) for h in u.pop("header")]], u.pop("body"), 2, "results")
    return section


def _interval(row, column: str, digits: int = 3) -> str:
    """``value [5 %, 95 %]`` of ``column`` in ``row`` (the value alone without a band)."""
    value = float(row[column])
    if not np.isfinite(value):
        return "–"
    lo, hi = float(row.get(f"{column}_p05", np.nan)), float(row.get(f"{column}_p95", np.nan))
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return f"{value:.{digits}f}"
    return f"{value:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"


def uncertainty_section(study: StudyFolder) -> dict | None:
    """The report's uncertainty section, or ``None`` for a study without bands: the samples and
    seed, the priors (a table), the whole-body rates and the top muscles of each model with their
    bands (5-95 %, or min-max from few samples), each band with where its nominal lies and the parameters that make its width,
    the samples left out."""
    from ..uncertainty import GLOBAL_PARAMETERS, MIN_BAND_SAMPLES, QUANTILE_SAMPLES, read_priors
    from .figures import main_workflow, trial_order
    from .uncertainty import BAND_HEADER, FLAGGED_HEADER, band_rows, flagged_rows, has_band

    ok = study.ok
    if ok.empty or not has_band(ok, "whole_body_W_per_kg"):
        return None
    settings = study.settings.get("uncertainty") if isinstance(study.settings.get("uncertainty"), dict) else {}
    priors_path = settings.get("priors")
    note = None
    try:
        priors = read_priors(priors_path)
    except Exception as exc:  # noqa: BLE001 - a moved priors file: the package's table is shown, said so
        priors, note = read_priors(), f"the study's priors file could not be read ({exc}); the package's are shown"
    rows = [[r.parameter, r.distribution, f"{r.spread:g}",
             r.muscle or ("the subject" if r.parameter in GLOBAL_PARAMETERS else "every muscle"), r.source,
             r.population, r.value_taken, r.note]
            for r in priors.rows]
    priors_table = Table([[(h, 1) for h in ("parameter", "distribution", "spread", "muscle", "source", "population",
                                            "value taken", "note")]], rows, 1, "settings")
    trials = trial_order(ok)
    wb_rows = []
    for (wf, model), d in ok.groupby([ok["workflow"].astype(str), ok["model"].astype(str)], sort=False):
        d = d.groupby(d["trial"].astype(str)).mean(numeric_only=True)
        wb_rows.append([wf, model] + [_interval(d.loc[t], "whole_body_W_per_kg") if t in d.index else "–" for t in trials])
    whole_body = Table([[("workflow", 1), ("model", 1)] + [(t, 1) for t in trials]], wb_rows, 2, "results")
    muscles = {}
    pm = study.read_per_muscle()
    if pm is not None and "muscle_W_per_kg_p05" in pm.columns:
        wf = main_workflow(list(dict.fromkeys(pm["workflow"].astype(str))))
        d = pm[pm["workflow"].astype(str) == wf]
        names = _muscle_names(d)
        cols = ["muscle_W_per_kg", "muscle_W_per_kg_p05", "muscle_W_per_kg_p95"]
        for m in [m for m in study.models() if m in set(d["model"].astype(str))]:
            dm = d[d["model"].astype(str) == m].groupby(["muscle", "trial"])[cols].mean()
            ts = [t for t in trials if t in set(dm.index.get_level_values("trial"))]
            order = dm["muscle_W_per_kg"].groupby("muscle").mean().sort_values(ascending=False).index[:TOP_MUSCLES]
            body = [[names.get(mu, mu)] + [_interval(dm.loc[(mu, t)], "muscle_W_per_kg") if (mu, t) in dm.index
                                           else "–" for t in ts] for mu in order]
            muscles[m] = Table([[("muscle", 1)] + [(t, 1) for t in ts]], body, 1, "results")
        muscles_workflow = wf
    else:
        muscles_workflow = None
    n = ok["uncertainty_samples"].to_numpy(float) if "uncertainty_samples" in ok else np.array([np.nan])
    rejected = ok["uncertainty_rejected"].to_numpy(float) if "uncertainty_rejected" in ok else np.zeros(1)
    bands = Table([[(h, 1) for h in BAND_HEADER]], band_rows(ok), 4, "results")
    flagged = flagged_rows(ok)
    return {"samples": int(settings.get("samples", 0) or np.nanmax(n)), "seed": settings.get("seed"),
            "converged": f"{int(np.nanmin(n))}-{int(np.nanmax(n))}" if np.nanmin(n) != np.nanmax(n) else f"{int(n[0])}",
            "rejected": int(np.nanmax(rejected)) if rejected.size else 0,
            "keep_flagged": bool(settings.get("keep_flagged", False)), "min_samples": MIN_BAND_SAMPLES,
            "quantile_samples": QUANTILE_SAMPLES,
            "bands": bands, "flagged": Table([[(h, 1) for h in FLAGGED_HEADER]], flagged, 3, "results") if flagged
            else None,
            "priors": priors_table, "priors_source": priors.source, "note": note, "whole_body": whole_body,
            "muscles": muscles, "muscles_workflow": muscles_workflow, "top": TOP_MUSCLES}


# ------------------------------------------------------------------ the page
def _environment():
    import jinja2

    return jinja2.Environment(loader=jinja2.PackageLoader("musclemetab.report", "templates"),
                              autoescape=True, trim_blocks=True, lstrip_blocks=True,
                              undefined=jinja2.StrictUndefined)


def render_page(study: StudyFolder, entries: Sequence, figures_rel: str = "figures", key: str | None = None,
                tables: dict | None = None) -> str:
    """The report page as a string: the figures of ``entries`` (:class:`~.draw.FigureEntry`,
    embedded from their PNG files), ``tables`` (:func:`page_tables`, made here when not given)
    and ``key``, the content key of the inputs (:func:`~.build.report_key`), recorded in the page."""
    from .. import __version__

    figures = [{"name": e.name, "title": e.title, "note": e.note, "caption": e.caption,
                "png": None if e.paths is None else base64.b64encode(Path(e.paths["png"]).read_bytes()).decode("ascii"),
                "files": [] if e.paths is None else [f"{figures_rel}/{e.name}.{ext}" for ext in e.paths]}
               for e in entries]
    return _environment().get_template(TEMPLATE).render(
        page=page_tables(study) if tables is None else tables,
        figures=figures,
        n_drawn=sum(f["png"] is not None for f in figures),
        written=_dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        version=__version__,
        key=key,
    )
