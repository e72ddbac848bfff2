"""Which figures the report draws, in what order, from what data.

:func:`plan_figures` gives one :class:`FigurePlan` per name of :data:`FIGURE_NAMES`: the
function drawing it (returning the figure and its caption) or the note saying why the
study's data cannot support it. The figures showing one unit or one workflow show the same
:class:`Selection` of the study: the preferred trial, the main workflow (EFFORT-TEN when
present) and the first subject with the preferred trial done. The drawing functions read
the unit files they need through the :class:`~.folder.StudyFolder` when called (in the
process that draws the figure) and raise a :class:`~musclemetab.errors.MusclemetabError`
when they cannot: its message becomes the figure's note.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np

from ..errors import MusclemetabError, OptionError
from .folder import StudyFolder
from .uncertainty import band_caption

__all__ = ["FIGURE_NAMES", "FIGURE_TITLES", "FIGURE2_CAPTION", "FigurePlan", "Selection", "select",
           "plan_figures", "measured_emg"]

#: File names (without extension) of the figures, in the order of the report.
FIGURE_NAMES = (
    "excitations_fiber_lengths",
    "estimated_vs_measured",
    "group_rates_over_cycle",
    "muscle_heat_map",
    "whole_body_over_cycle",
    "phase_shares",
    "phase_pies",
    "group_shares",
    "rates_against_speed",
    "per_muscle_ranked",
    "structural_spread",
    "figure2_soleus",
)

#: The title of each figure in the report.
FIGURE_TITLES = {
    "figure2_soleus": "The six metabolic models on a soleus (the paper's Figure 2)",
    "excitations_fiber_lengths": "Muscle excitations and normalised fiber lengths",
    "estimated_vs_measured": "Estimated vs measured whole-body metabolic rate",
    "group_rates_over_cycle": "Metabolic rate of the muscle groups over the gait cycle",
    "whole_body_over_cycle": "Whole-body metabolic rate over the gait cycle across speeds",
    "muscle_heat_map": "Every muscle over the gait cycle",
    "phase_shares": "Stance and swing shares",
    "phase_pies": "Stance and swing shares, scaled by the total cost",
    "group_shares": "Muscle-group shares",
    "per_muscle_ranked": "The muscles costing most energy, across speeds",
    "rates_against_speed": "Whole-body and muscle-group rates against walking speed",
    "structural_spread": "Structural spread: energy models, workflows and trials",
    "assistance": "Assisted walking: metabolic saving against device work",
}
#: Figures drawn only when the study's data hold what they show (after :data:`FIGURE_NAMES`):
#: ``assistance`` for a study with assisted trials (:mod:`.assistance_figure`).
OPTIONAL_FIGURES = ("assistance",)

FIGURE2_CAPTION = (
    "The metabolic rate (W) and efficiency of one soleus under each of the paper's six energy models "
    "(columns), in steady states (excitation equal to activation) at four activations (light: low, dark: "
    "full): over the fiber velocity at the optimal length (rows 1-2; shortening negative) and over the fiber "
    "length at a slow shortening (rows 3-4); the panels of a row share their axes, so the models compare "
    "across it. Efficiency: mechanical power over metabolic rate, shortening only. Settings and open "
    "choices: docs/metabolics.md (musclemetab.metabolics.figure2.figure2 draws every model with them "
    "printed). It depends on no data of the study: it is drawn once per version of the models and kept in "
    "the package's cache."
)

#: The figures showing one unit of the study (the selected subject's).
UNIT_FIGURES = ("excitations_fiber_lengths", "group_rates_over_cycle", "muscle_heat_map", "whole_body_over_cycle")


@dataclass(frozen=True)
class FigurePlan:
    """One figure of the report: ``draw()`` returns ``(figure, caption)``; ``None`` and a
    ``note`` when the study's data cannot support it."""

    name: str
    draw: Callable[[], tuple[object, str]] | None = None
    note: str | None = None

    @property
    def title(self) -> str:
        return FIGURE_TITLES[self.name]


@dataclass(frozen=True)
class Selection:
    """What the figures of one unit or one workflow show (see :func:`select`)."""

    ok: object  # pandas.DataFrame: the successful rows
    workflows: list[str]
    models: list[str]
    trial: str  # the preferred trial
    workflow: str  # the main workflow
    subject: str | None  # the first subject with the preferred trial done
    mass: float | None  # the subject's body mass (kg)
    both_legs: bool  # the subject was solved on both sides

    @property
    def n_trials(self) -> int:
        return len(set(self.ok["trial"].astype(str)))

    @property
    def n_subjects(self) -> int:
        return len(set(self.ok["subject"].astype(str)))

    def trial_text(self, trial: str | None = None) -> str:
        """``trial T`` with what is known of it: ``(preferred speed, 1.33 m/s)`` when the study
        has other trials, its speed when known."""
        trial = self.trial if trial is None else trial
        sp = math.nan
        if "speed_m_per_s" in self.ok.columns:
            v = self.ok.loc[self.ok["trial"].astype(str) == trial, "speed_m_per_s"].to_numpy(float)
            sp = float(np.nanmean(v)) if np.isfinite(v).any() else math.nan
        known = (["preferred speed"] if self.n_trials > 1 else []) + ([f"{sp:.2f} m/s"] if np.isfinite(sp) else [])
        return f"trial {trial}" + (f" ({', '.join(known)})" if known else "")

    def rows(self, subject, trial=None, workflow=None):
        """The successful rows of a subject (and trial, and workflow)."""
        ok = self.ok
        d = ok[ok["subject"].astype(str) == subject]
        if trial is not None:
            d = d[d["trial"].astype(str) == trial]
        if workflow is not None:
            d = d[d["workflow"].astype(str) == workflow]
        return d

    @property
    def rate_scale(self) -> tuple[float, str, str, str]:
        """``(scale, unit, legs, how)`` of the rates over the cycle (both legs,
        :meth:`~.folder.StudyFolder.timeseries`): W/kg when the body mass is known, else W."""
        how = ("the two solved legs added at each instant, each leg on its own gait cycle aligned on the first "
               "leg's heel strike" if self.both_legs else
               "the simulated leg plus the same leg half a cycle later, standing for the other leg (a symmetric "
               "gait)")
        if self.mass:
            return 1.0 / self.mass, "W/kg", "both legs", how
        return 1.0, "W", "both legs", how


def select(study: StudyFolder) -> Selection:
    """The :class:`Selection` of a study with successful rows."""
    from .figures import main_workflow

    ok = study.ok
    models = [m for m in study.shown_models() if m in set(ok["model"].astype(str))]
    ok = ok[ok["model"].astype(str).isin(models)]
    workflows = [w for w in study.workflows() if w in set(ok["workflow"].astype(str))]
    trial = study.preferred_trial(ok)
    pref = ok[ok["trial"].astype(str) == trial]
    subject = next((s for s in study.subjects() if s in set(pref["subject"].astype(str))), None)
    return Selection(ok=ok, workflows=workflows, models=models, trial=trial, workflow=main_workflow(workflows),
                     subject=subject, mass=study.body_mass(subject), both_legs=study.solves_both_legs(subject))


def plan_figures(study: StudyFolder) -> dict[str, FigurePlan]:
    """Figure name -> its :class:`FigurePlan`, in the order of :data:`FIGURE_NAMES`, then those
    of :data:`OPTIONAL_FIGURES` the study's data hold."""
    if study.ok.empty:
        return {n: FigurePlan(n, note="no unit of the study succeeded: nothing to draw.") for n in FIGURE_NAMES}
    sel = select(study)
    draws = {
        "excitations_fiber_lengths": partial(excitations_figure, study, sel),
        "estimated_vs_measured": partial(estimated_vs_measured_figure, sel),
        "group_rates_over_cycle": partial(group_rates_figure, study, sel),
        "whole_body_over_cycle": partial(whole_body_figure, study, sel),
        "muscle_heat_map": partial(heat_map_figure, study, sel),
        "phase_shares": partial(phase_shares_figure, sel),
        "phase_pies": partial(phase_pies_figure, sel),
        "group_shares": partial(group_shares_figure, sel),
        "rates_against_speed": partial(rates_against_speed_figure, sel),
        "per_muscle_ranked": partial(per_muscle_figure, study, sel),
        "structural_spread": partial(spread_figure, sel),
        "figure2_soleus": figure2_figure,
    }
    plans = {}
    for name in FIGURE_NAMES:
        if sel.subject is None and name in UNIT_FIGURES:
            plans[name] = FigurePlan(name, note=f"no successful unit for trial {sel.trial}.")
        else:
            plans[name] = FigurePlan(name, draw=draws[name])
    from .assistance_figure import has_assistance

    if has_assistance(sel.ok):
        plans["assistance"] = FigurePlan("assistance", draw=partial(assistance_figure, study, sel))
    return plans


# ------------------------------------------------------------------ figures of the results table
def estimated_vs_measured_figure(sel: Selection):
    from .figures import estimated_vs_measured

    return estimated_vs_measured(sel.ok), (
        "Whole-body average metabolic rate (W/kg of body mass, both legs, with basal heat) estimated by "
        "each model against the measured rate, one point per subject and trial; lines: repeated-measures "
        "correlation of each workflow (common slope m, one intercept per subject); dashed: identity.")


def phase_shares_figure(sel: Selection):
    from .figures import phase_shares

    fig = phase_shares(sel.ok, trial=sel.trial, workflow=sel.workflow)
    # what was drawn (nothing claimed of a figure that does not say)
    shown = getattr(fig, "shown", {"sd": False, "speeds": 1, "slopes": []})
    cap = ("Share of the cycle's muscle metabolic energy (one leg, without basal heat) spent in stance (initial "
           "contact to toe-off) and swing" + (", mean over subjects" if sel.n_subjects > 1 else "")
           + (" (error bar: SD over subjects)" if shown["sd"] else "")
           + (", per model and workflow, " if shown["speeds"] < 2 else "; left: ") + sel.trial_text())
    if shown["speeds"] > 1:
        cap += f"; right: swing share against walking speed for {sel.workflow}"
        if shown["slopes"]:
            cap += (", the legend giving the repeated-measures slope (% per m/s) and correlation"
                    + ("" if len(shown["slopes"]) == len(sel.models) else f" of {', '.join(shown['slopes'])}"))
    cap += "." + band_caption(sel.ok, "stance_energy_share_pct")
    return fig, cap


def phase_pies_figure(sel: Selection):
    from .figures import phase_pies

    return phase_pies(sel.ok, workflow=sel.workflow, models=sel.models), (
        f"Workflow {sel.workflow}. Each pie splits the cycle's muscle metabolic energy (one leg, without basal "
        "heat) into stance (dark) and swing (light); its area is proportional to the whole-body rate without "
        "basal heat (W/kg of body mass, both legs; printed under the pie), so the pies "
        + ("grow with walking speed (rows) and " if sel.n_trials > 1 else "")
        + "differ between models (columns)" + ("; means over subjects." if sel.n_subjects > 1 else
                                               f"; {sel.trial_text()}." if sel.n_trials == 1 else "."))


def group_shares_figure(sel: Selection):
    from .figures import group_shares

    return group_shares(sel.ok, workflows=sel.workflows, models=sel.models), (
        "Share of each muscle group in the cycle's muscle metabolic energy (%, one leg, without basal heat"
        + ("; mean over subjects" if sel.n_subjects > 1 else "") + "), "
        + ("one bar per trial (walking speed in m/s where known)." if sel.n_trials > 1 else f"{sel.trial_text()}.")
        + band_caption(sel.ok, "share_PF_pct").replace("Shaded:", "Whisker at the top of each segment:"))


def rates_against_speed_figure(sel: Selection):
    from .figures import rates_against_speed

    return rates_against_speed(sel.ok, workflow=sel.workflow, models=sel.models), (
        f"Workflow {sel.workflow}. Per model, the whole-body metabolic rate without basal heat (black, upper "
        "panel) and each muscle group's part of it (group share × whole-body rate, lower panel, on a scale of "
        "its own), W per kg of body mass, both legs; one line per subject through its trials in the order of "
        "its walking speeds (line style and marker: the subject); the panels of a kind share their axes; "
        "groups with no energy are not drawn." + band_caption(sel.ok, "whole_body_no_basal_W_per_kg"))


def spread_figure(sel: Selection):
    from .spread_figure import spread_caption, spread_figure

    return spread_figure(sel.ok), spread_caption()


def assistance_figure(study: StudyFolder, sel: Selection):
    from .assistance_figure import assistance_caption, assistance_figure

    return assistance_figure(sel.ok, study.path, sel.workflow if sel.workflow in set(sel.ok["workflow"]) else None,
                             sel.models), assistance_caption()


def figure2_figure():
    from ..metabolics.figure2 import figure2_data
    from ..metabolics.registry import STUDY_MODELS
    from .figures import figure2_compact

    return figure2_compact(figure2_data(models=STUDY_MODELS)), FIGURE2_CAPTION


# ------------------------------------------------------------------ figures of the unit files
def excitations_figure(study: StudyFolder, sel: Selection):
    """Excitations and fiber lengths of the selected subject's preferred trial, one line per
    workflow, with the measured EMG (:func:`measured_emg`)."""
    from .figures import excitations_and_fiber_lengths

    subject, trial = sel.subject, sel.trial
    sols, cycles, skipped = {}, {}, []
    rows = sel.rows(subject, trial)
    for w in sel.workflows:
        d = rows[rows["workflow"].astype(str) == w]
        if d.empty:
            continue
        folder = study.unit_folder(d.iloc[0])
        try:
            cycles[w] = study.unit_cycle(folder)
            sols[w] = study.load_solution(folder)
        except MusclemetabError as exc:
            cycles.pop(w, None)
            skipped.append(f"{w} ({study.short(exc)})")
    if not sols:
        raise OptionError(
            f"no solution could be read for {subject}, trial {trial}" + (f": {'; '.join(skipped)}" if skipped else "")
        )
    emg, emg_label, emg_text = measured_emg(study, subject, trial, sols, cycles, rows)
    fig = excitations_and_fiber_lengths(
        sols, cycles, emg=emg, emg_label=emg_label,
        title=f"Muscle excitation and normalised fiber length over the gait cycle: subject {subject}, trial {trial}",
    )
    cap = (f"Subject {subject}, {sel.trial_text(trial)}. Excitation (-) and fiber length "
           "normalised by the optimal fiber length (-), one line per workflow; dotted line: toe-off; "
           "grey band: plateau of the active force-length curve (0.75-1.05); dashed line: start of "
           f"the descending limb (1.05). {emg_text}")
    if sel.both_legs:
        cap += " Both legs were solved; the right leg is shown."
    if skipped:
        cap += f" Not shown: {'; '.join(skipped)}."
    return fig, cap


def measured_emg(study: StudyFolder, subject: str, trial: str, sols: dict, cycles: dict, rows
                 ) -> tuple[dict, str, str]:
    """The trial's measured EMG to draw over the excitations: ``({muscle: (cycle_pct, value)},
    legend label, caption sentence)``.

    The EMG file is the one ``study.json`` records for the trial (``emg_files``), mapped to
    the muscles by the subject's ``emg_mapping`` (:func:`musclemetab.redundancy.emg_inputs.resolve_emg_mapping`,
    :func:`~musclemetab.emg.map_channels`) and interpolated at the solution's nodes
    (:func:`~musclemetab.emg.emg_at`). Scaled by the EMG-TEN factors when the trial's EMG-TEN
    unit succeeded (each muscle's ``scale`` in its ``summary.json``, the channels it tracked),
    otherwise so that its peak over the cycle equals the excitation's peak of the workflow
    shown first (EFFORT-TEN when present). No EMG: an empty mapping and a sentence saying why.
    """
    from ..emg import emg_at, map_channels, read_emg
    from ..redundancy.emg_inputs import mapping_for_muscles, resolve_emg_mapping
    from .figures import main_workflow

    path = study.emg_file(subject, trial)
    if path is None:
        return {}, "", "No measured EMG is recorded for this trial (study.json, emg_files)."
    wf = main_workflow(list(sols))
    sol, (start, _, end) = sols[wf], cycles[wf]
    full_t = np.asarray(sol.time_s, float)
    in_cycle = (full_t >= start - 1e-9) & (full_t <= end + 1e-9)
    t = full_t[in_cycle]
    pct = 100.0 * (t - start) / (end - start)
    scales: dict[str, float] = {}
    mapping: dict = {}
    emg_rows = rows[rows["workflow"].astype(str).str.lower() == "emg-ten"]
    if not emg_rows.empty:
        try:
            tracking = study.emg_tracking(emg_rows.iloc[0])
            mapping = {m: v["channels"] for m, v in tracking.items()}
            scales = {m: float(v["scale"]) for m, v in tracking.items()}
        except (MusclemetabError, KeyError, TypeError, ValueError):
            mapping, scales = {}, {}
    try:
        emg_df = read_emg(path)
        if not mapping:
            named = study.emg_mapping(subject)
            mapping = mapping_for_muscles(named, resolve_emg_mapping(named), list(sol.muscles))
        mapping = {m: c for m, c in mapping.items() if m in sol.muscles}
        table = emg_at(map_channels(emg_df, mapping), t)
    except MusclemetabError as exc:
        return {}, "", f"Measured EMG not shown: {study.short(exc)}."
    excitation = np.asarray(sol.excitation)[in_cycle]
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


def unit_timeseries(study: StudyFolder, sel: Selection, subject, trial, workflow):
    """``(rates over the cycle, toe-off %, speed m/s)`` of a successful unit."""
    d = sel.rows(subject, trial, workflow)
    if d.empty:
        raise OptionError(f"no successful unit for {subject}, trial {trial}, workflow {workflow}")
    row = d.iloc[0]
    ts = study.timeseries(row)
    to = d["toe_off_pct"].iloc[0] if "toe_off_pct" in d.columns else math.nan
    if not np.isfinite(to):
        s, t, e = study.unit_cycle(study.unit_folder(row))
        to = 100.0 * (t - s) / (e - s)
    sp = d["speed_m_per_s"].iloc[0] if "speed_m_per_s" in d.columns else math.nan
    return ts, float(to), float(sp)


def group_rates_figure(study: StudyFolder, sel: Selection):
    """The muscle groups' rates over the cycle of the selected unit (main workflow)."""
    from .figures import group_rates_over_cycle

    subject, trial, wf = sel.subject, sel.trial, sel.workflow
    scale, unit, legs, how = sel.rate_scale
    ts, to, _ = unit_timeseries(study, sel, subject, trial, wf)
    fig = group_rates_over_cycle(
        ts, to, [m for m in sel.models if m in set(ts["model"].astype(str).unique())] or None,
        title=f"Metabolic rate of the muscle groups over the gait cycle ({unit}, {legs}, no basal heat): "
        f"subject {subject}, trial {trial}, {wf}", scale=scale, unit=unit,
    )
    drawn = [str(ax.title.get_gid())[len("group:"):] for ax in fig.axes
             if ax.get_visible() and str(ax.title.get_gid()).startswith("group:")]
    empty = [g for g in dict.fromkeys(s.split("/", 1)[1] for s in ts["series"].astype(str).unique()
                                      if s.startswith("group/")) if drawn and g not in drawn]
    cap = (f"Subject {subject}, {sel.trial_text(trial)}, workflow {wf}. Muscle metabolic "
           f"rates ({unit}, {legs}: {how}; "
           "without basal heat) distributed to the muscle groups by moment-arm ratio, over the first leg's gait "
           "cycle; one panel per muscle group, one line per metabolic model; same axes in every panel; dotted "
           f"line: toe-off ({to:.1f} % of the cycle).")
    if empty:
        cap += f" No energy, no panel: {', '.join(empty)}."
    return fig, cap


def heat_map_figure(study: StudyFolder, sel: Selection):
    """Every muscle of the selected subject's first leg over its gait cycle (main workflow), one
    row of panels per trial (ordered by walking speed), one panel per model, from the units'
    ``metabolics.sto``."""
    from .figures import muscle_heat_map

    subject, wf = sel.subject, sel.workflow
    d = sel.rows(subject, workflow=wf)
    if d.empty:
        raise OptionError(f"no successful unit for {subject}, workflow {wf}")
    trials = list(dict.fromkeys(d["trial"].astype(str)))
    if "speed_m_per_s" in d.columns:  # by walking speed; trials without one keep the study's order, last
        speed = d.groupby(d["trial"].astype(str))["speed_m_per_s"].median()
        study_order = list(trials)

        def by_speed(trial):
            v = float(speed.get(trial, math.nan))
            return (0, v) if not math.isnan(v) else (1, study_order.index(trial))

        trials.sort(key=by_speed)
    rates, toe_off = {}, {}
    for trial in trials:
        row = d[d["trial"].astype(str) == trial].iloc[0]
        by_model = study.muscle_rates(row)
        by_model = {m: by_model[m] for m in sel.models if m in by_model}
        if not by_model:
            raise OptionError(f"the metabolic rates of trial {trial} hold none of the models "
                              f"{', '.join(sel.models)}")
        s, t, e = study.unit_cycle(study.unit_folder(row))
        rates[trial], toe_off[trial] = by_model, 100.0 * (t - s) / (e - s)
    models = list(dict.fromkeys(m for by_model in rates.values() for m in by_model))
    scale, unit = (1.0 / sel.mass, "W/kg") if sel.mass else (1.0, "W")
    side = "the right leg" if sel.both_legs else "the simulated leg"
    several = len(trials) > 1
    fig = muscle_heat_map(rates if several else rates[trials[0]], toe_off if several else toe_off[trials[0]],
                          models, scale=scale, unit=unit,
                          title=f"Each muscle over the gait cycle ({unit}, {side}, no basal heat): "
                          f"subject {subject}, {'trials ' + ', '.join(trials) if several else 'trial ' + trials[0]}, {wf}")
    marks = ", ".join(f"{tr} {to:.1f} %" for tr, to in toe_off.items())
    cap = (f"Subject {subject}, workflow {wf}; "
           + (f"one row of panels per trial ({', '.join(trials)}; by walking speed where known), "
              if several else f"trial {trials[0]}, ")
           + f"one panel per model. Metabolic rate of each muscle of {side} ({unit}, without "
           "basal heat) at every node of the gait cycle (initial contact to the next initial contact), "
           + ("one colour scale per row of panels (trial), its colour bar beside the row, so that the slow trials "
              "read as well as the fast; " if several else "one colour scale for every panel; ")
           + "muscles named by the anatomical muscle table with the model's name, ordered and tagged (in "
           "brackets) by the muscle group of their main action (primary_group of the muscle table); sky blue: a "
           f"rate below -2 % of the {'row' + chr(39) + 's ' if several else ''}peak (work absorbed); dashed line: toe-off "
           f"({marks}), the boundary between stance and swing.")
    return fig, cap


def whole_body_figure(study: StudyFolder, sel: Selection):
    """The selected subject's summed muscle rate over the cycle at every speed (main workflow)."""
    from .figures import trial_order, whole_body_over_cycle

    subject, wf = sel.subject, sel.workflow
    scale, unit, legs, how = sel.rate_scale
    trials = [t for t in trial_order(sel.ok) if not sel.rows(subject, t, wf).empty]
    if len(trials) < 2:
        raise OptionError(
            f"one speed only ({', '.join(trials) or 'no trial'} for subject {subject}, {wf}): "
            "nothing to compare across speeds"
        )
    tables, speeds, toes, skipped = {}, {}, {}, []
    for t in trials:
        try:
            ts, to, sp = unit_timeseries(study, sel, subject, t, wf)
        except MusclemetabError as exc:
            skipped.append(f"{t} ({study.short(exc)})")
            continue
        if not np.isfinite(sp):
            skipped.append(f"{t} (no walking speed)")
            continue
        tables[t], speeds[t], toes[t] = ts, sp, to
    if len(tables) < 2:
        raise OptionError("fewer than two speeds with time series" + (f": {'; '.join(skipped)}" if skipped else ""))
    present = {v for x in tables.values() for v in x["model"].astype(str).unique()}
    fig = whole_body_over_cycle(
        tables, speeds, [m for m in sel.models if m in present],
        toe_off_pct=toes,
        title=f"Whole-body metabolic rate over the gait cycle across speeds ({unit}, {legs}, summed "
        f"muscles, no basal heat): subject {subject}, {wf}", scale=scale, unit=unit,
    )
    cap = (f"Subject {subject}, workflow {wf}. Summed muscle metabolic rate ({unit}, {legs}: "
           f"{how}; without basal heat) over the gait "
           "cycle, one line per walking speed; same axes in every panel; marks at the bottom: toe-off of "
           "each trial.")
    if skipped:
        cap += f" Not shown: {'; '.join(skipped)}."
    return fig, cap


def per_muscle_figure(study: StudyFolder, sel: Selection):
    """The muscles costing most energy (``per_muscle.csv``), main workflow."""
    from ..study_layout import PER_MUSCLE_FILE
    from .figures import per_muscle_ranked

    pm = study.read_per_muscle()
    if pm is None:
        raise OptionError(f"{PER_MUSCLE_FILE} is missing: run the study with this version to get it")
    ok, wf = sel.ok, sel.workflow
    if "speed_m_per_s" in ok.columns:
        sp = ok.drop_duplicates(["subject", "trial"])[["subject", "trial", "speed_m_per_s"]]
        pm = pm.merge(sp.astype({"subject": str, "trial": str}), on=["subject", "trial"], how="left")
    fig = per_muscle_ranked(pm, workflow=wf if wf in set(pm["workflow"].astype(str).unique()) else None,
                            models=[m for m in sel.models if m in set(pm["model"].astype(str).unique())] or None)
    several = pm["trial"].astype(str).nunique() > 1
    two_legs = "side" in pm.columns and pm["side"].astype(str).nunique() > 1
    cap = (f"Workflow {wf}. The 15 anatomical muscles with the largest cycle-average metabolic rate of each model "
           "(W per kg of body mass, one leg" + (": the mean of the two legs of a subject solved on both" if two_legs
                                                else "") + ", without basal heat"
           + ("; mean over subjects" if pm["subject"].astype(str).nunique() > 1 else "") + "), "
           + ("one bar per trial (light: slow, dark: fast); " if several else f"{sel.trial_text()}; ")
           + "each subject's model muscles are summed into the anatomical muscles of the "
           "package's muscle table (bundles of one muscle together, the names of different model families "
           "merged); every model muscle is in per_muscle.csv.")
    return fig, cap
