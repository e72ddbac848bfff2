"""Figures over the gait cycle: excitations and fiber lengths, the muscle groups' rates, the whole body across speeds.

Part of :mod:`musclemetab.report.figures`, which gathers the figure functions (see its text).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from ..errors import OptionError, UnknownMuscleError
from ..messages import name_list
from .fig_data import (
    _models_and_toe_off,
    GROUPS, GROUP_NAMES, default_muscles, PLATEAU_BAND, DESCENDING_LIMB, model_colour, workflow_colour,
    _require_columns, _unique, _ordered_models, _ordered_workflows,
)
from .fig_layout import _new_figure, _panel_title, _legend_below, _grid, _vline, _hline, _hspan


# ---------------------------------------------------------------- 1. excitations, fiber lengths
def _match_muscle(name: str, available: Sequence[str], side: str) -> str | None:
    if name in available:
        return name
    for s in (side, "l" if side == "r" else "r"):
        cand = f"{name}_{s}"
        if cand in available:
            return cand
    return None


def excitations_and_fiber_lengths(
    solutions: Mapping[str, object],
    cycles: Mapping[str, Sequence[float]],
    muscles: Sequence[str] | None = None,
    *,
    side: str = "r",
    title: str | None = None,
    emg: Mapping[str, tuple[Sequence[float], Sequence[float]]] | None = None,
    emg_label: str = "measured EMG",
):
    """Excitation and normalised fiber length of selected muscles over the gait cycle.

    Parameters
    ----------
    solutions
        Workflow name -> :class:`~musclemetab.redundancy.Solution` (one trial).
    cycles
        Workflow name -> ``(start_s, toe_off_s, end_s)``: initial contact, toe-off and the next
        initial contact (s). Nodes outside ``[start_s, end_s]`` (the solver's padding) are not
        drawn.
    muscles
        Muscle names, with or without the side suffix (``soleus`` matches ``soleus_r``, the
        ``side`` leg first). Default: :func:`default_muscles` of the solutions' muscles (the
        report list of the anatomical muscle table); named muscles absent from every solution
        raise :class:`UnknownMuscleError`.

    emg
        Muscle column name -> ``(cycle_pct, value)``: measured EMG drawn over the excitation
        (grey, dashed), already scaled as it should be shown; ``emg_label`` names it in the
        legend (e.g. how it was scaled).

    Per muscle, an excitation panel (-) above a fiber-length panel (``lM/lMo``), one line per
    workflow, a vertical line at toe-off; the fiber-length panels shade the plateau of the
    active force-length curve (0.75-1.05) and draw the start of the descending limb (1.05);
    every excitation panel spans 0-1.02 (or up to the largest EMG shown) and every
    fiber-length panel the same range.
    """
    if not solutions:
        raise OptionError("no solution given for the excitation and fiber-length figure")
    workflows = _ordered_workflows(solutions)
    missing = [w for w in workflows if w not in cycles]
    if missing:
        raise OptionError(f"no gait cycle (start, toe-off, end) given for workflow {name_list(missing)}")
    cyc = {}
    for w in workflows:
        vals = tuple(float(v) for v in cycles[w])
        if len(vals) != 3 or not (vals[0] < vals[1] < vals[2]):
            raise OptionError(
                f"gait cycle of workflow {w} must be (start_s, toe_off_s, end_s) increasing, not {cycles[w]}"
            )
        cyc[w] = vals
    explicit = muscles is not None
    wanted = list(muscles) if explicit else default_muscles(
        list(dict.fromkeys(m for w in workflows for m in solutions[w].muscles)), side)
    rows: list[tuple[str, dict]] = []  # (label, {workflow: column name})
    for name in wanted:
        found = {}
        for w in workflows:
            col = _match_muscle(name, tuple(solutions[w].muscles), side)
            if col is not None:
                found[w] = col
        if not found:
            if explicit:
                some = tuple(solutions[workflows[0]].muscles)
                raise UnknownMuscleError(
                    f"muscle '{name}' is in none of the solutions; they have {', '.join(some)}"
                )
            continue
        rows.append((_unique(found.values())[0], found))
    if not rows:
        raise OptionError(f"none of the muscles {', '.join(wanted)} is in the solutions")

    n = len(rows)
    ncol = min(6, n)
    nmrow = int(math.ceil(n / ncol))
    fig = _new_figure(2.6 * ncol + 0.9, 2 * 2.0 * nmrow + 1.3, left=0.95, bottom=0.8, hspace=0.25)
    # only the panels drawn are made (row by row); one cycle axis in every panel, one
    # excitation scale in every excitation panel and one fiber-length scale in every
    # fiber-length panel: numbers on the outer panels only
    grid = fig.add_gridspec(2 * nmrow, ncol)
    axes = np.full((2 * nmrow, ncol), None, dtype=object)
    for r in range(2 * nmrow):
        for j in range(ncol):
            if (r // 2) * ncol + j < n:
                first = axes[r % 2, 0]
                axes[r, j] = fig.add_subplot(grid[r, j], sharex=axes[0, 0], sharey=first)
                if j > 0:
                    axes[r, j].tick_params(labelleft=False)
    toe_offs = _unique(round(100.0 * (c[1] - c[0]) / (c[2] - c[0]), 6) for c in cyc.values())
    lm_data = [PLATEAU_BAND[0], DESCENDING_LIMB]
    # one excitation scale in every panel: 0-1, or up to the largest scaled EMG shown
    e_top = max([1.02] + [1.02 * float(np.nanmax(v)) for _, v in (emg or {}).values() if np.size(v)])
    from .fig_muscles import muscle_names  # (which draws with this module's helpers)

    names = muscle_names([label for label, _ in rows])  # the anatomical muscle with the model's name
    for k, (label, found) in enumerate(rows):
        i, j = divmod(k, ncol)
        ax_e, ax_l = axes[2 * i, j], axes[2 * i + 1, j]
        _hspan(ax_l, *PLATEAU_BAND, color="0.88", zorder=0, label="_plateau", gid="plateau")
        _hline(ax_l, DESCENDING_LIMB, color="0.35", lw=0.8, ls="--", label="_descending", gid="descending-limb")
        for w in workflows:
            if w not in found:
                continue
            sol = solutions[w]
            start, _, end = cyc[w]
            t = np.asarray(sol.time_s, dtype=float)
            keep = (t >= start - 1e-9) & (t <= end + 1e-9)
            pct = 100.0 * (t[keep] - start) / (end - start)
            idx = tuple(sol.muscles).index(found[w])
            kw = dict(color=workflow_colour(w), lw=1.3, label=w, gid=f"workflow:{w}")
            ax_e.plot(pct, np.asarray(sol.excitation)[keep, idx], **kw)
            lm = np.asarray(sol.lm_norm)[keep, idx]
            ax_l.plot(pct, lm, **kw)
            if np.any(np.isfinite(lm)):
                lm_data += [float(np.nanmin(lm)), float(np.nanmax(lm))]
        measured = (emg or {}).get(label)
        if measured is not None:
            ax_e.plot(np.asarray(measured[0], float), np.asarray(measured[1], float), color="0.45", lw=1.1,
                      ls="--", label="_emg", gid="emg", zorder=1)
        for ax in (ax_e, ax_l):
            for to in toe_offs:
                _vline(ax, to, color="k", lw=0.8, ls=":", label="_toe-off", gid="toe-off")
        _panel_title(ax_e, names[label], fontsize=9)
        if j == 0:
            ax_e.set_ylabel("excitation (-)")
            ax_l.set_ylabel("fiber length\nlᴹ/lᴹₒ (-)")  # no mathtext: its parser takes 0.15 s to start
    axes[0, 0].set_xlim(0, 100)  # shared: every panel
    axes[0, 0].set_ylim(0, e_top)
    # one fiber-length scale in every panel, so that the muscles compare at a glance: the
    # data, the plateau and the descending limb with 5 % of the span on either side
    lo, hi = min(lm_data), max(lm_data)
    axes[1, 0].set_ylim(min(lo - 0.05 * (hi - lo), PLATEAU_BAND[0] - 0.05),
                        max(hi + 0.05 * (hi - lo), DESCENDING_LIMB + 0.05))
    for j in range(ncol):
        last = max(i for i in range(2 * nmrow) if axes[i, j] is not None)
        for i in range(last):
            if axes[i, j] is not None:
                axes[i, j].tick_params(labelbottom=False)
        axes[last, j].set_xlabel("gait cycle (%)")
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [Line2D([], [], color=workflow_colour(w), lw=1.5, label=w) for w in workflows]
    if emg:
        handles.append(Line2D([], [], color="0.45", lw=1.1, ls="--", label=emg_label))
    handles += [
        Line2D([], [], color="k", lw=0.8, ls=":", label="toe-off"),
        Patch(color="0.88", label=f"plateau {PLATEAU_BAND[0]:g}-{PLATEAU_BAND[1]:g}"),
        Line2D([], [], color="0.35", lw=0.8, ls="--", label=f"descending limb > {DESCENDING_LIMB:g}"),
    ]
    _legend_below(fig, handles, min(len(handles), 8), 9)
    fig.suptitle(title or "Muscle excitation and normalised fiber length over the gait cycle", fontsize=11)
    return fig


# ------------------------------------------------------------- 3. group rates over the cycle
def _long_table(timeseries, what: str):
    _require_columns(timeseries, ("cycle_pct", "model", "series", "value_W"), what)
    return timeseries


def _cycle_panels(n: int):
    """A figure with one panel per model over the gait cycle (shared axes): ``(fig, axes)``."""
    nrow, ncol = _grid(n)
    fig = _new_figure(4.4 * ncol, 3.0 * nrow + 1.0)
    return fig, fig.subplots(nrow, ncol, squeeze=False, sharex=True, sharey=True)


def _label_cycle_panels(axes, models: Sequence[str], ylabel: str = "metabolic rate (W)", *,
                        xlim: tuple[float, float] = (0.0, 100.0), xlabel: str = "gait cycle (%)") -> None:
    """Titles, axis labels and the x limits (the gait cycle, 0-100 %, unless given) of the
    panels of :func:`_cycle_panels`; unused panels hidden."""
    nrow, ncol = axes.shape
    for k, ax in enumerate(axes.flat):
        if k >= len(models):
            ax.set_visible(False)
            continue
        m = models[k]
        if k == 0:
            ax.set_xlim(*xlim)  # shared: every panel
        _panel_title(ax, m, color=model_colour(m), fontsize=11, fontweight="bold")
        if k % ncol == 0:
            ax.set_ylabel(ylabel)
        if k // ncol == nrow - 1 or k + ncol >= len(models):
            ax.set_xlabel(xlabel)
            ax.tick_params(labelbottom=True)


def group_rates_over_cycle(timeseries, toe_off_pct: float, models: Sequence[str] | None = None,
                           *, title: str | None = None, scale: float = 1.0, unit: str = "W"):
    """Metabolic rate of each muscle group over the gait cycle: small multiples, one panel per
    group (shared axes), one line per model (its colour).

    ``timeseries`` is a unit's long table (``cycle_pct``, ``model``, ``series``, ``value_W``;
    series ``group/<G>``), drawn times ``scale`` in ``unit``; a dotted vertical line at
    ``toe_off_pct`` (%). A group whose rate is zero throughout has no panel.
    """
    ts = _long_table(timeseries, "the time-series table")
    ts = ts[ts["series"].astype(str).str.startswith("group/")]
    if ts.empty:
        raise OptionError("the time-series table has no group series (group/<G>)")
    models, to = _models_and_toe_off(_ordered_models(ts["model"]), models, toe_off_pct, "group rates", "the table has")
    # the groups with energy at some instant (a group no muscle belongs to, e.g. other with
    # every DOF of the muscles solved, is left out: an empty panel)
    peak = ts.assign(v=ts["value_W"].abs()).groupby(ts["series"].astype(str))["v"].max()
    present = _unique(s.split("/", 1)[1] for s in _unique(ts["series"].astype(str)) if peak.get(s, 0.0) > 0.0)
    if not present:
        raise OptionError("every muscle group's rate is zero in the time-series table")
    groups = [g for g in GROUPS if g in present] + [g for g in present if g not in GROUPS]
    nrow, ncol = _grid(len(groups), 4)
    fig = _new_figure(2.9 * ncol, 2.0 * nrow + 1.2)
    axes = fig.subplots(nrow, ncol, squeeze=False, sharex=True, sharey=True)
    series = ts["series"].astype(str)
    model_col = ts["model"].astype(str)
    for k, g in enumerate(groups):
        ax = axes.flat[k]
        dg = ts[series == f"group/{g}"]
        for m in models:
            d = dg[model_col[dg.index] == m].sort_values("cycle_pct")
            if d.empty:
                continue
            ax.plot(d["cycle_pct"], scale * d["value_W"], color=model_colour(m), lw=1.2, label=m,
                    gid=f"model:{m}")
        _vline(ax, to, color="k", lw=0.8, ls=":", label="_toe-off", gid="toe-off")
        _hline(ax, 0.0, color="0.7", lw=0.6, label="_zero")
        _panel_title(ax, f"{g}: {GROUP_NAMES.get(g, g)}", fontsize=9, gid=f"group:{g}")
    for k, ax in enumerate(axes.flat):
        if k >= len(groups):
            ax.set_visible(False)
            continue
        if k == 0:
            ax.set_xlim(0.0, 100.0)
        if k % ncol == 0:
            ax.set_ylabel(f"rate ({unit})")
        if k + ncol >= len(groups):
            ax.set_xlabel("gait cycle (%)")
            ax.tick_params(labelbottom=True)
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=model_colour(m), lw=1.5, label=m) for m in models]
    handles.append(Line2D([], [], color="k", lw=0.8, ls=":", label=f"toe-off ({to:.1f} %)"))
    _legend_below(fig, handles, min(len(handles), 7), 8)
    fig.suptitle(title or "Metabolic rate of the muscle groups over the gait cycle (no basal heat)", fontsize=11)
    return fig


# ------------------------------------------------------- 4. whole body over the cycle, speeds
def whole_body_over_cycle(timeseries_by_trial: Mapping[str, object], speeds: Mapping[str, float],
                          models: Sequence[str] | None = None, *,
                          toe_off_pct: Mapping[str, float] | None = None, title: str | None = None,
                          scale: float = 1.0, unit: str = "W"):
    """Whole-body (one leg, summed muscles, no basal) metabolic rate over the cycle across speeds.

    ``timeseries_by_trial``: trial label -> the unit's long table (series ``leg_muscles``);
    ``speeds``: trial label -> walking speed (m/s). One panel per model, one line per trial
    coloured by speed (slow = light, fast = dark); ``toe_off_pct`` (label -> %) adds a short
    mark at each trial's toe-off.
    """
    if not timeseries_by_trial:
        raise OptionError("no time series given for the whole-body figure")
    labels = list(timeseries_by_trial)
    missing = [t for t in labels if t not in speeds or not np.isfinite(float(speeds[t]))]
    if missing:
        raise OptionError(f"no walking speed given for trial {name_list(missing)}")
    labels.sort(key=lambda t: float(speeds[t]))
    tables = {}
    for t in labels:
        ts = _long_table(timeseries_by_trial[t], f"the time series of trial {t}")
        tables[t] = ts[ts["series"].astype(str) == "leg_muscles"]
        if tables[t].empty:
            raise OptionError(f"the time series of trial {t} has no leg_muscles series")
    in_trial = {t: _unique(tables[t]["model"].astype(str)) for t in labels}
    available = _ordered_models(m for t in labels for m in in_trial[t])
    models = available if models is None else [str(m) for m in models]
    absent = [m for m in models if all(m not in in_trial[t] for t in labels)]
    if absent:
        raise OptionError(f"no whole-body rate for model {name_list(absent)}")
    from matplotlib import colormaps

    cmap = colormaps["viridis_r"]
    shades = np.linspace(0.15, 0.9, len(labels)) if len(labels) > 1 else np.array([0.6])
    colour = {t: cmap(float(s)) for t, s in zip(labels, shades)}
    fig, axes = _cycle_panels(len(models))
    for k, m in enumerate(models):
        ax = axes.flat[k]
        for t in labels:
            d = tables[t][tables[t]["model"].astype(str) == m].sort_values("cycle_pct")
            if d.empty:
                continue
            ax.plot(d["cycle_pct"], scale * d["value_W"], color=colour[t], lw=1.4,
                    label=f"{t} ({float(speeds[t]):.2f} m/s)", gid=f"trial:{t}")
            if toe_off_pct is not None and t in toe_off_pct and np.isfinite(float(toe_off_pct[t])):
                _vline(ax, float(toe_off_pct[t]), 0.0, 0.06, color=colour[t], lw=1.5,
                           label="_toe-off", gid="toe-off")
    _label_cycle_panels(axes, models, f"metabolic rate ({unit})")
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=colour[t], lw=1.6, label=f"{t} ({float(speeds[t]):.2f} m/s)") for t in labels]
    if toe_off_pct:
        handles.append(Line2D([], [], color="0.3", lw=1.5, marker="|", ls="", markersize=9,
                              label="toe-off (marks at the bottom)"))
    _legend_below(fig, handles, min(len(handles), 8), 8)
    fig.suptitle(title or "Whole-body metabolic rate over the gait cycle across walking speeds "
                 "(one leg, summed muscles, no basal heat)", fontsize=11)
    return fig
