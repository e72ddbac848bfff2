"""Figures of shares and of speed: stance and swing shares (bars, pies), the muscle groups' shares, the rates against walking speed.

Part of :mod:`musclemetab.report.figures`, which gathers the figure functions (see its text).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..errors import OptionError
from ..messages import name_list
from .fig_data import (
    GROUPS, GROUP_NAMES, model_colour, workflow_colour, group_colour, _require_columns, _ok_rows, _unique,
    _ordered_models, _ordered_workflows, trial_order, preferred_trial, main_workflow, group_stats, stat_cell,
    _one_workflow, _rmcorr,
)
from .fig_layout import _new_figure, _panel_title, _legend_below, _grid, _add_bars, _bar_limits
from .uncertainty import has_band, shade_band


def _over_subjects(table) -> str:
    """``"; mean over subjects"`` for a title, when the table has two subjects or more."""
    return "; mean over subjects" if table["subject"].astype(str).nunique() > 1 else ""


# --------------------------------------------------------------------- 5. phase shares
def _speed_table(res, value: str):
    """Per trial (in speed order): ``(trial, mean speed, mean, SD, n)`` of ``value`` over subjects."""
    stats = group_stats(res, ["trial"], ["speed_m_per_s", value])
    rows = []
    for t in trial_order(res):
        sp = stat_cell(stats, t, "speed_m_per_s")[0]
        rows.append((t, sp, *stat_cell(stats, t, value)))
    return rows


def phase_shares(results, *, trial: str | None = None, workflow: str | None = None, title: str | None = None):
    """Stance and swing shares of the cycle's muscle energy (%; one leg, no basal heat).

    Left: at the preferred speed (``trial``, default :func:`preferred_trial`), stacked bars
    (stance solid, swing hatched, mean over subjects, error bar = SD of the swing share) per
    model (groups of bars) and workflow (bar colour); the error bar only where a cell has two
    subjects or more. Right, when the workflow has two speeds or more: swing share against
    walking speed (m/s) for ``workflow`` (default :func:`main_workflow`), one line per model
    and subject through the subject's trials in the order of its speeds (line style and marker:
    the subject; trials of different subjects never matched by name); the legend gives the
    repeated-measures slope (% per m/s) where it can be estimated.

    ``fig.shown`` says what was drawn, for the caption: ``{"sd": error bars drawn, "speeds":
    number of speeds of the workflow (the right panel when 2 or more), "slopes": models whose
    slope the legend gives}``.
    """
    res = _ok_rows(results)
    _require_columns(res, ("stance_energy_share_pct", "swing_energy_share_pct", "speed_m_per_s"), "the results table")
    if res.empty:
        raise OptionError("no successful unit in the results")
    trial = preferred_trial(res) if trial is None else str(trial)
    if trial not in set(res["trial"].astype(str)):
        raise OptionError(f"trial '{trial}' is not in the results")
    models = _ordered_models(res["model"])
    workflows = _ordered_workflows(res["workflow"])
    wf_line = main_workflow(workflows) if workflow is None else str(workflow)
    if wf_line not in workflows:
        raise OptionError(f"workflow '{wf_line}' is not in the results; it has {', '.join(workflows)}")
    dl = res[res["workflow"].astype(str) == wf_line]
    n_speeds = len(_unique(dl["trial"].astype(str)))
    bars_w = 0.5 * len(models) * max(1, len(workflows)) + 2.5
    fig = _new_figure(min(15.0, max(10.0, bars_w + 3.5)) if n_speeds > 1 else min(10.0, max(6.5, bars_w)), 5.4,
                      bottom=1.2, top=0.75)
    if n_speeds > 1:
        ax_b, ax_s = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.5, 1.0]})
    else:  # one speed: no trend to draw, no panel
        ax_b, ax_s = fig.subplots(1, 1), None
    shown = {"sd": False, "speeds": n_speeds, "slopes": []}
    pref = res[res["trial"].astype(str) == trial]
    nw = len(workflows)
    width = 0.8 / max(nw, 1)
    pref_stats = group_stats(pref, ["workflow", "model"], ["swing_energy_share_pct", "stance_energy_share_pct"])
    for i, w in enumerate(workflows):
        col = workflow_colour(w)
        xs, stance, swing, sd = [], [], [], []
        for j, m in enumerate(models):
            sw, sw_sd, n = stat_cell(pref_stats, (w, m), "swing_energy_share_pct")
            st = stat_cell(pref_stats, (w, m), "stance_energy_share_pct")[0]
            if n == 0:
                continue
            xs.append(j - 0.4 + width * (i + 0.5))
            stance.append(st)
            swing.append(sw)
            sd.append(sw_sd)
        if not xs:
            continue
        xs, stance, swing = np.array(xs), np.array(stance), np.array(swing)
        ax_b.bar(xs, stance, width=width * 0.92, color=col, label=f"{w}", gid=f"stance:{w}")
        ax_b.bar(xs, swing, width=width * 0.92, bottom=stance, color=col, alpha=0.35, hatch="///",
                 edgecolor=col, label="_swing", gid=f"swing:{w}")
        sd = np.array(sd)
        if np.any(np.isfinite(sd)):
            ax_b.errorbar(xs, stance, yerr=np.nan_to_num(sd), fmt="none", ecolor="k", elinewidth=0.8, capsize=2)
            shown["sd"] = True
        if has_band(pref, "stance_energy_share_pct"):  # uncertainty samples: the stance share's 5-95 % band
            band = group_stats(pref, ["workflow", "model"], ["stance_energy_share_pct_p05", "stance_energy_share_pct_p95"])
            lo = [stat_cell(band, (w, m), "stance_energy_share_pct_p05")[0] for m in models
                  if stat_cell(pref_stats, (w, m), "swing_energy_share_pct")[2]]
            hi = [stat_cell(band, (w, m), "stance_energy_share_pct_p95")[0] for m in models
                  if stat_cell(pref_stats, (w, m), "swing_energy_share_pct")[2]]
            ax_b.bar(xs, np.subtract(hi, lo), bottom=lo, width=width * 0.35, color="white", alpha=0.6,
                     edgecolor="0.3", lw=0.6, gid=f"band:stance:{w}")
        for x, s in zip(xs, swing):
            ax_b.text(x, 101.0, f"{s:.0f}", ha="center", va="bottom", fontsize=6.5, rotation=90)
    ax_b.set_xticks(range(len(models)), models)
    for lab in ax_b.get_xticklabels():
        lab.set_color(model_colour(lab.get_text()))
    ax_b.set_ylim(0, 112)
    ax_b.set_ylabel("share of the cycle's muscle energy (%)")
    speed_txt = ""
    sp = pref["speed_m_per_s"].to_numpy(float)
    if np.any(np.isfinite(sp)):
        speed_txt = f", {np.nanmean(sp):.2f} m/s"
    where = (f"at the preferred speed ({trial}{speed_txt})" if len(trial_order(res)) > 1
             else f"of trial {trial}{speed_txt}")  # one trial: its speed is no one's preference
    _panel_title(ax_b, f"Stance (solid) and swing (hatched; % above the bar) {where}", fontsize=9)
    ax_b.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=max(1, min(nw, 6)),
                frameon=False, title="workflow (stance solid, swing hatched)", title_fontsize=8)

    fig.shown = shown
    if ax_s is None:
        fig.suptitle(title or "Relative phase cost: stance and swing shares of the muscle metabolic energy "
                     "(one leg, no basal heat)", fontsize=11)
        return fig
    for k, m in enumerate(models):
        d = dl[dl["model"].astype(str) == m]
        if d.empty:
            continue
        col = model_colour(m)
        label = m
        rm, _ = _rmcorr(d["speed_m_per_s"], d["swing_energy_share_pct"], d["subject"].astype(str))
        if rm is not None:
            label = f"{m}: {rm.slope:+.1f} %/(m/s), r = {rm.r:.2f}"
            shown["slopes"].append(m)
        for i, subject in enumerate(_unique(d["subject"].astype(str))):  # never matched by trial name
            ds = d[d["subject"].astype(str) == subject].sort_values("speed_m_per_s")
            ax_s.plot(ds["speed_m_per_s"].to_numpy(float), ds["swing_energy_share_pct"].to_numpy(float), color=col,
                      marker="os^Dvx"[i % 6], ms=4, lw=1.2, ls=("-", "--", ":", "-.")[i % 4],
                      label=label if i == 0 else "_" + m, gid=f"model:{m}:{subject}", zorder=3)
            if has_band(ds, "swing_energy_share_pct"):
                shade_band(ax_s, ds["speed_m_per_s"], ds["swing_energy_share_pct_p05"], ds["swing_energy_share_pct_p95"],
                           col, f"band:swing:{m}:{subject}")
    ax_s.yaxis.get_major_formatter().set_useOffset(False)
    ax_s.set_xlabel("walking speed (m/s)")
    ax_s.set_ylabel("swing share (%)")
    _panel_title(ax_s, f"Swing share against speed ({wf_line})", fontsize=9)
    ax_s.legend(fontsize=7, frameon=False)
    fig.suptitle(title or "Relative phase cost: stance and swing shares of the muscle metabolic energy "
                 "(one leg, no basal heat)", fontsize=11)
    return fig


def phase_pies(results, *, workflow: str | None = None, models: Sequence[str] | None = None,
               title: str | None = None):
    """Stance and swing shares as pies whose area is proportional to the total cost.

    One pie per model (row) and trial (column, in speed order) for ``workflow`` (default
    :func:`main_workflow`): the stance wedge in the model's colour, the swing wedge lighter
    (``stance_energy_share_pct``, ``swing_energy_share_pct``; one leg, no basal heat), the
    pie's area proportional to the whole-body rate without basal heat
    (``whole_body_no_basal_W_per_kg``, W/kg); means over subjects. The largest pie has radius
    0.46 in units of the grid spacing.
    """
    from ..colours import lighter

    res = _ok_rows(results)
    _require_columns(res, ("stance_energy_share_pct", "swing_energy_share_pct", "whole_body_no_basal_W_per_kg"),
                     "the results table")
    if res.empty:
        raise OptionError("no successful unit in the results")
    wf, d = _one_workflow(res, workflow, "the results")
    models = _ordered_models(d["model"]) if models is None else [str(m) for m in models]
    trials = trial_order(d)
    cols = ["stance_energy_share_pct", "swing_energy_share_pct", "whole_body_no_basal_W_per_kg"]
    stats = group_stats(d, ["model", "trial"], cols + (["speed_m_per_s"] if "speed_m_per_s" in d.columns else []))
    cost = {(m, t): stat_cell(stats, (m, t), "whole_body_no_basal_W_per_kg")[0] for m in models for t in trials}
    finite = [v for v in cost.values() if np.isfinite(v) and v > 0]
    if not finite:
        raise OptionError("no positive whole-body rate (whole_body_no_basal_W_per_kg) to size the pies")
    top = max(finite)
    pitch = 1.3  # rows: trials; columns: models; the text under each pie fits between the rows
    fig = _new_figure(1.5 * len(models) + 1.3, 1.5 * pitch * len(trials) + 1.1, left=1.0, right=0.2, bottom=0.3,
                      top=0.75)
    ax = fig.add_subplot()
    for i, t in enumerate(trials):
        y = pitch * (len(trials) - 1 - i)
        for j, m in enumerate(models):
            colour = model_colour(m)
            st = stat_cell(stats, (m, t), "stance_energy_share_pct")[0]
            sw = stat_cell(stats, (m, t), "swing_energy_share_pct")[0]
            v = cost[(m, t)]
            if not (np.isfinite(st) and np.isfinite(sw) and np.isfinite(v) and v > 0):
                continue
            r = 0.46 * math.sqrt(v / top)
            wedges, *_ = ax.pie([st, sw], center=(j, y), radius=r, colors=[colour, lighter(colour, 0.6)],
                                startangle=90, counterclock=False,
                                wedgeprops={"linewidth": 0.6, "edgecolor": "white"})
            wedges[0].set_gid(f"stance:{m}:{t}")
            wedges[1].set_gid(f"swing:{m}:{t}")
            ax.text(j, y - 0.49, f"{v:.2f} W/kg, swing {sw:.0f} %", ha="center", va="top", fontsize=6.5)
    ax.set_aspect("equal")
    ax.set_xlim(-0.55, len(models) - 0.45)
    ax.set_ylim(-0.75, pitch * (len(trials) - 1) + 0.5)
    ax.set_frame_on(False)
    speed = "speed_m_per_s" in d.columns
    labels = []
    for t in trials:
        sp = next((x for x in (stat_cell(stats, (m, t), "speed_m_per_s")[0] for m in models) if np.isfinite(x)),
                  math.nan) if speed else math.nan
        labels.append(f"{t}\n{sp:.2f} m/s" if np.isfinite(sp) else t)
    ax.set_yticks([pitch * (len(trials) - 1 - i) for i in range(len(trials))], labels, fontsize=8)
    ax.set_xticks(range(len(models)), models, fontsize=9)
    ax.xaxis.tick_top()
    for lab in ax.get_xticklabels():
        lab.set_color(model_colour(lab.get_text()))
        lab.set_fontweight("bold")
    ax.tick_params(length=0)
    import textwrap

    heading = title or (f"Stance (dark) and swing (light) shares of the muscle energy; pie area proportional to the "
                        f"whole-body rate without basal heat (W/kg; {wf}{_over_subjects(d)})")
    fig.suptitle(textwrap.fill(heading, int(12 * fig.get_figwidth())), fontsize=10)
    return fig


# --------------------------------------------------------------------- 6. group shares
def group_shares(results, *, workflows: Sequence[str] | None = None, models: Sequence[str] | None = None,
                 title: str | None = None):
    """Share of each muscle group in the cycle's muscle energy (%), stacked bars.

    One row of panels per workflow, one panel per model, one bar per trial (ordered by speed;
    mean over subjects of ``share_<G>_pct``), stacked in the order of :data:`GROUPS`.
    """
    res = _ok_rows(results)
    cols = [c for c in (f"share_{g}_pct" for g in GROUPS) if c in res.columns]
    if not cols:
        raise OptionError("the results table has no group-share column (share_<G>_pct)")
    if res.empty:
        raise OptionError("no successful unit in the results")
    groups = [c[len("share_"):-len("_pct")] for c in cols]
    all_wf = _ordered_workflows(res["workflow"])
    workflows = all_wf if workflows is None else [str(w) for w in workflows]
    absent = [w for w in workflows if w not in all_wf]
    if absent:
        raise OptionError(f"workflow {name_list(absent)} is not in the results; it has {', '.join(all_wf)}")
    models = _ordered_models(res["model"]) if models is None else [str(m) for m in models]
    trials = trial_order(res)
    speeds = {t: r[1] for t, r in zip(trials, _speed_table(res, cols[0]))}
    stats = group_stats(res, ["workflow", "model", "trial"], cols)
    panel_w = max(1.8, 0.3 * len(trials) + 0.9)
    fig = _new_figure(min(20.0, max(6.5, panel_w * len(models) + 1.2)), 2.9 * len(workflows) + 1.8, left=0.9, bottom=1.3,
                      hspace=0.45, wspace=0.1)
    # the same trials and scale in every panel: numbers on the outer panels only
    axes = fig.subplots(len(workflows), len(models), squeeze=False, sharex=True, sharey=True)
    xt = [f"{t}\n{speeds[t]:.2f}" if np.isfinite(speeds[t]) else t for t in trials]
    width = 0.75
    colours = [group_colour(g) for g in groups for _ in trials]
    gids = [f"group:{g}" for g in groups for _ in trials]
    for i, w in enumerate(workflows):
        for j, m in enumerate(models):
            ax = axes[i, j]
            # a bar per group and trial, group by group, stacked
            vals = np.nan_to_num([[stat_cell(stats, (w, m, t), c)[0] for t in trials] for c in cols])
            bottoms = np.vstack([np.zeros(len(trials)), np.cumsum(vals, axis=0)[:-1]])
            _add_bars(ax, np.tile(np.arange(len(trials)), len(groups)) - width / 2, bottoms.ravel(), width,
                      vals.ravel(), colours, gids, edgecolor="white", linewidth=0.4)
            if has_band(res, cols[0]):  # uncertainty samples: each share's 5-95 % band at its segment's top
                band = group_stats(res, ["workflow", "model", "trial"], [c + s for c in cols for s in ("_p05", "_p95")])
                lo = np.array([[stat_cell(band, (w, m, t), c + "_p05")[0] for t in trials] for c in cols])
                hi = np.array([[stat_cell(band, (w, m, t), c + "_p95")[0] for t in trials] for c in cols])
                ok = np.isfinite(lo) & np.isfinite(hi)
                x = np.tile(np.arange(len(trials)), (len(groups), 1))
                # a thin whisker from the 5 % to the 95 % value, at the segment's top (where its share ends)
                whisk = ax.errorbar(x[ok], (bottoms + vals)[ok], yerr=np.vstack([(vals - lo)[ok], (hi - vals)[ok]]).clip(0),
                                    fmt="none", ecolor="0.15", elinewidth=0.7, capsize=1.5, capthick=0.7)
                for part in whisk.lines[2]:
                    part.set_gid(f"band:groups:{w}:{m}")
            if i == 0:
                _panel_title(ax, m, color=model_colour(m), fontsize=11, fontweight="bold")
            if j == 0:
                ax.set_ylabel(f"{w}\nshare (%)", color=workflow_colour(w))
            if i == len(workflows) - 1:
                ax.set_xticks(np.arange(len(trials)), xt, fontsize=6.5 if len(trials) > 4 else 7,
                              rotation=90 if len(trials) > 4 else 0)
                ax.set_xlabel("trial, speed (m/s)" if any(np.isfinite(speeds[t]) for t in trials) else "trial",
                              fontsize=8)
    axes[0, 0].set_ylim(0, 100)
    axes[0, 0].set_xlim(*_bar_limits(-width / 2, len(trials) - 1 + width / 2))
    from matplotlib.patches import Patch

    # the groups with a share somewhere (an empty `other` has no entry)
    handles = [Patch(color=group_colour(g), label=f"{g} ({GROUP_NAMES.get(g, g)})") for g, c in zip(groups, cols)
               if np.nanmax(np.abs(res[c].to_numpy(float)), initial=0.0) > 0.0]
    _legend_below(fig, handles, min(len(handles), 6), 8)
    fig.suptitle(title or "Shares of the muscle groups in the cycle's muscle metabolic energy "
                 f"(%, one leg, no basal heat{_over_subjects(res)})", fontsize=11)
    return fig


# ------------------------------------------------------------- 8. rates against speed
def rates_against_speed(results, *, workflow: str | None = None, models: Sequence[str] | None = None,
                        title: str | None = None):
    """Whole-body and muscle-group rates (W/kg of body mass, both legs, no basal) against speed.

    Per model two panels, one above the other: the whole-body rate without basal heat
    (``whole_body_no_basal_W_per_kg``, black) and, on a scale of its own, one line per group
    (``share_<G>_pct / 100 * whole_body_no_basal_W_per_kg``), so that the groups' rates, a
    tenth of the whole body's, are not pressed flat under it; the panels of a kind share their
    axes. Lines go through each subject's trials in the order of its own walking speeds: the
    trials of different subjects are never matched by name. Subjects differ by line style and
    marker (gids ``whole-body:<subject>``, ``group:<G>:<subject>``). Groups without energy in
    any row (all shares zero) are not drawn.
    """
    res = _ok_rows(results)
    _require_columns(res, ("subject", "speed_m_per_s", "whole_body_no_basal_W_per_kg"), "the results table")
    cols = [c for c in (f"share_{g}_pct" for g in GROUPS) if c in res.columns]
    wf, d = _one_workflow(res, workflow, "the results")
    subjects = _unique(d["subject"].astype(str))
    per_subject = d.groupby(d["subject"].astype(str))["trial"].nunique()
    if per_subject.max() < 2:
        raise OptionError("one speed only (per subject): nothing to draw against speed")
    models = _ordered_models(d["model"]) if models is None else [str(m) for m in models]
    cols = [c for c in cols if np.nanmax(np.abs(d[c].to_numpy(float)), initial=0.0) > 0.0]
    groups = [c[len("share_"):-len("_pct")] for c in cols]
    nrow, ncol = _grid(len(models))
    fig = _new_figure(4.4 * ncol, 4.6 * nrow + 1.0, hspace=0.3)
    grid = fig.add_gridspec(2 * nrow, ncol, height_ratios=[1.0, 1.3] * nrow)
    styles = {s: (("-", "--", ":", "-.")[i % 4], "os^Dvx"[i % 6]) for i, s in enumerate(subjects)}
    speeds: list[float] = []
    first_w = first_g = None
    for k, m in enumerate(models):
        i, j = divmod(k, ncol)
        ax_w = fig.add_subplot(grid[2 * i, j], sharex=first_w, sharey=first_w)
        ax_g = fig.add_subplot(grid[2 * i + 1, j], sharex=ax_w if first_g is None else first_g, sharey=first_g)
        first_w, first_g = first_w or ax_w, first_g or ax_g
        dm = d[d["model"].astype(str) == m].copy()
        for g, c in zip(groups, cols):
            dm[f"rate_{g}"] = dm[c].astype(float) / 100.0 * dm["whole_body_no_basal_W_per_kg"].astype(float)
        for subject in subjects:
            ds = dm[dm["subject"].astype(str) == subject].sort_values("speed_m_per_s")
            if ds.empty:
                continue
            ls, mk = styles[subject]
            x = ds["speed_m_per_s"].to_numpy(float)
            ax_w.plot(x, ds["whole_body_no_basal_W_per_kg"].to_numpy(float), color="k", lw=1.8, ls=ls, marker=mk,
                      ms=4, label="whole body", gid=f"whole-body:{subject}")
            if has_band(ds, "whole_body_no_basal_W_per_kg"):  # uncertainty samples: their 5-95 % band
                shade_band(ax_w, x, ds["whole_body_no_basal_W_per_kg_p05"], ds["whole_body_no_basal_W_per_kg_p95"],
                           "k", f"band:whole-body:{subject}")
            for g in groups:
                ax_g.plot(x, ds[f"rate_{g}"].to_numpy(float), color=group_colour(g), lw=1.1, ls=ls, marker=mk, ms=3,
                          label=g, gid=f"group:{g}:{subject}")
            speeds += [v for v in x if np.isfinite(v)]
        _panel_title(ax_w, m, color=model_colour(m), fontsize=11, fontweight="bold")
        ax_w.tick_params(labelbottom=False)
        if j == 0:
            ax_w.set_ylabel("whole body\n(W/kg)")
            ax_g.set_ylabel("muscle groups\n(W/kg)")
        else:
            ax_w.tick_params(labelleft=False)
            ax_g.tick_params(labelleft=False)
        if k + ncol >= len(models):
            ax_g.set_xlabel("walking speed (m/s)")
        else:
            ax_g.tick_params(labelbottom=False)
    # one speed axis in every panel, over the trials' speeds
    first_w.set_xlim(min(speeds) - 0.05, max(speeds) + 0.05)
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color="k", lw=1.8, label="whole body (both legs, no basal)")]
    handles += [Line2D([], [], color=group_colour(g), lw=1.2, label=f"{g} ({GROUP_NAMES.get(g, g)})")
                for g in groups]
    if len(subjects) > 1:
        handles += [Line2D([], [], color="0.4", lw=1.2, ls=styles[s][0], marker=styles[s][1], label=f"subject {s}")
                    for s in subjects]
    _legend_below(fig, handles, min(len(handles), 6), 8)
    fig.suptitle(title or f"Whole-body and muscle-group metabolic rates against walking speed ({wf}; W/kg of body "
                 "mass, both legs, no basal heat; one line per subject)", fontsize=11)
    return fig
