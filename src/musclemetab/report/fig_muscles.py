"""Figures of single muscles: the muscles costing most energy, each muscle over the gait cycle (heat map); the muscles' anatomical names and groups.

Part of :mod:`musclemetab.report.figures`, which gathers the figure functions (see its text).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from ..analysis.groups import OTHER
from ..colours import OKABE_ITO
from ..errors import OptionError
from .fig_data import (GROUPS, model_colour, _require_columns, _unique, _ordered_models, trial_order, _one_workflow,
                       _models_and_toe_off)
from .fig_layout import _new_figure, _panel_title, _legend_below, _grid, _add_bars, _vline, _hline, _bar_limits


# ------------------------------------------------------------- 7. per-muscle ranking
def per_muscle_ranked(per_muscle, *, workflow: str | None = None, models: Sequence[str] | None = None,
                      top: int = 15, title: str | None = None):
    """The muscles costing most energy, ranked, across speeds (W/kg of body mass, one leg, no basal).

    ``per_muscle``: the study's per-muscle table (``trial``, ``workflow``, ``model``,
    ``muscle``, ``muscle_W_per_kg``; ``speed_m_per_s`` orders the trials when present). The
    model muscles are summed into anatomical muscles per subject (:func:`harmonise_muscles`), so
    subjects of different model families are ranked together. One panel per model (shared
    axis), the ``top`` muscles by their mean over trials (largest at the top), one bar per
    trial coloured by speed (light = slow), means over subjects.
    """
    _require_columns(per_muscle, ("trial", "workflow", "model", "muscle", "muscle_W_per_kg"), "the per-muscle table")
    if len(per_muscle) == 0:
        raise OptionError("the per-muscle table has no rows")
    wf, d = _one_workflow(per_muscle, workflow, "the per-muscle table")
    models = _ordered_models(d["model"]) if models is None else [str(m) for m in models]
    d = harmonise_muscles(d)
    trials = trial_order(d) if "speed_m_per_s" in d.columns else _unique(str(t) for t in d["trial"])
    from matplotlib import colormaps

    cmap = colormaps["viridis_r"]
    shades = np.linspace(0.15, 0.9, len(trials)) if len(trials) > 1 else np.array([0.6])
    colour = {t: cmap(float(x)) for t, x in zip(trials, shades)}
    nrow, ncol = _grid(len(models))
    fig = _new_figure(4.2 * ncol + 1.6, (0.19 * top * max(1, len(trials)) / 2 + 1.0) * nrow + 1.5,
                      left=1.6, top=0.8, wspace=0.75, hspace=0.3)
    axes = fig.subplots(nrow, ncol, squeeze=False, sharex=True)
    height = 0.8 / max(len(trials), 1)
    x_lo = x_hi = 0.0
    for k, m in enumerate(models):
        ax = axes.flat[k]
        dm = d[d["model"].astype(str) == m]
        mean = dm.groupby(["muscle", dm["trial"].astype(str)])["muscle_W_per_kg"].mean().unstack()
        order = list(mean.mean(axis=1).sort_values(ascending=False).index[:top])
        y = np.arange(len(order))[::-1]
        y_lo, y_hi = math.inf, -math.inf
        for i, t in enumerate(trials):
            if t not in mean.columns:
                continue
            vals = mean.loc[order, t].to_numpy(float)
            centre = y + 0.4 - height * (i + 0.5)
            _add_bars(ax, 0.0, centre - height * 0.95 / 2, vals, height * 0.95, [colour[t]] * len(vals),
                      [f"trial:{t}"] * len(vals))
            y_lo = min(y_lo, float(np.min(centre)) - height * 0.95 / 2)
            y_hi = max(y_hi, float(np.max(centre)) + height * 0.95 / 2)
            finite = vals[np.isfinite(vals)]
            if finite.size:
                x_lo, x_hi = min(x_lo, float(finite.min())), max(x_hi, float(finite.max()))
        if np.isfinite(y_lo):
            ax.set_ylim(*_bar_limits(y_lo, y_hi))
        ax.set_yticks(y, order, fontsize=7)
        _panel_title(ax, m, color=model_colour(m), fontsize=11, fontweight="bold")
        ax.grid(axis="x", color="0.9", lw=0.6)
        ax.set_axisbelow(True)
    axes[0, 0].set_xlim(*_bar_limits(x_lo, x_hi, start=0.0))  # one scale (shared axis), from 0
    for k in range(len(models), nrow * ncol):
        axes.flat[k].set_visible(False)
    for j in range(ncol):
        axes[-1, j].set_xlabel("metabolic rate (W/kg, one leg, no basal)")
        axes[-1, j].tick_params(labelbottom=True)
    from matplotlib.patches import Patch

    sp = {}
    if "speed_m_per_s" in d.columns:
        sp = d.assign(trial=d["trial"].astype(str)).groupby("trial")["speed_m_per_s"].mean().to_dict()
    handles = [Patch(color=colour[t], label=f"{t} ({sp[t]:.2f} m/s)" if np.isfinite(sp.get(t, np.nan)) else t)
               for t in trials]
    _legend_below(fig, handles, min(len(handles), 8), 8)
    several = "subject" in d.columns and d["subject"].astype(str).nunique() > 1
    fig.suptitle(title or f"The {top} muscles with the largest metabolic rate"
                 + (", across walking speeds" if len(trials) > 1 else f", trial {trials[0]}" if trials else "")
                 + f" ({wf}; W/kg of body mass, one leg, no basal heat" + ("; mean over subjects)" if several else ")"),
                 fontsize=11)
    return fig


# ------------------------------------------------------------- muscles by anatomy
def anatomical_muscles(names: Sequence[str]) -> dict[str, tuple[str, str]]:
    """Each model muscle name -> ``(label, group)``: the label names the anatomical muscle(s)
    of the package's muscle table (:func:`musclemetab.properties.resolve_muscles`) and the
    side, so that the names of two model families for one muscle (``gasmed_r`` of Rajagopal
    and ``med_gas_r`` of gait2392: ``gastrocnemius medialis (r)``) and the bundles of one
    muscle (``addmagDist_r``, ``addmagMid_r``) share a label; ``group``: the muscle group of
    its main action (``primary_group`` of the muscle table; :data:`GROUPS`; ``other`` when it
    has none). A name the table cannot place keeps its own name. ``names`` of one model family
    (one subject's model)."""
    from ..properties import anatomical_table, resolve_muscles

    names = list(dict.fromkeys(str(n) for n in names))
    anat = anatomical_table()
    out = {}
    for rec in resolve_muscles(names, warn=False):
        if not rec.anatomical:
            out[rec.name] = (rec.name, OTHER)
            continue
        label = " + ".join(str(anat.loc[a, "name"]) for a in rec.anatomical)
        group = rec.primary_group or OTHER
        out[rec.name] = (f"{label} ({rec.side})" if rec.side else label, group if group in GROUPS else OTHER)
    return out


def muscle_names(names: Sequence[str]) -> dict[str, str]:
    """Each model muscle name -> the name the report gives it: the anatomical muscle of the
    package's muscle table with the model's name, ``"soleus (soleus_r)"``, ``"adductor magnus
    (addmagDist_r)"`` (:func:`anatomical_muscles`); a muscle the table cannot place keeps its
    model name. The figures and the page's tables name a model muscle so."""
    labels = anatomical_muscles(names)
    out = {}
    for n, (label, _) in labels.items():
        anat = label.rsplit(" (", 1)[0] if label != n else ""
        out[n] = f"{anat} ({n})" if anat else n
    return out


def harmonise_muscles(per_muscle, value: str = "muscle_W_per_kg"):
    """The per-muscle table with the model muscles of each subject summed into anatomical
    muscles (:func:`anatomical_muscles`, per subject: each subject's model family), column
    ``muscle`` the anatomical label, ``group`` its muscle group. With a ``side`` column, the
    label drops the side and a subject solved on both legs gets the mean of its legs (one leg)."""
    import pandas as pd

    d = per_muscle.copy()
    d["muscle"] = d["muscle"].astype(str)
    by = [c for c in ("subject",) if c in d.columns]
    parts = []
    for _, ds in (d.groupby(by, sort=False) if by else [(None, d)]):
        labels = anatomical_muscles(ds["muscle"].unique())
        parts.append(ds.assign(muscle=ds["muscle"].map(lambda n: labels[n][0]),
                               group=ds["muscle"].map(lambda n: labels[n][1])))
    d = pd.concat(parts, ignore_index=True)
    if "side" in d.columns:  # a subject solved on both legs: one leg is the mean of its two
        d["muscle"] = d["muscle"].str.replace(r" \([rl]\)$", "", regex=True)
        d["side"] = d["side"].astype(str)
    keys = [c for c in ("subject", "trial", "workflow", "model", "muscle", "group") if c in d.columns]
    leg = keys + (["side"] if "side" in d.columns else [])
    summed = d.groupby(leg, sort=False, dropna=False)[value].sum(min_count=1).reset_index()
    summed = summed.groupby(keys, sort=False, dropna=False)[value].mean().reset_index()
    rest = [c for c in d.columns if c not in keys and c != value]
    if "speed_m_per_s" in rest:
        sp = d.groupby([k for k in ("subject", "trial") if k in d.columns], sort=False)["speed_m_per_s"].first()
        summed = summed.join(sp, on=[k for k in ("subject", "trial") if k in d.columns])
    return summed


def muscle_heat_map(rates: Mapping[str, object], toe_off_pct, models: Sequence[str] | None = None, *,
                    scale: float = 1.0, unit: str = "W", title: str | None = None):
    """Each muscle's metabolic rate over the gait cycle as a heat map: muscles (rows, ordered by
    the muscle group of their main action, :data:`GROUPS`, then by anatomical name) x cycle
    (columns), one panel per trial and model; one colour scale per row of panels (a trial),
    with its colour bar beside the row (a rate below -2 % of the row's peak sky blue); a dashed
    line at the toe-off (the stance/swing boundary). Muscles are named by
    :func:`muscle_names` (the anatomical muscle with the model's name), tagged with their group.

    ``rates``: model -> table indexed by the cycle percentage, one column per muscle (W), for one
    trial (``toe_off_pct`` a number; panels titled by model); or trial -> such a mapping, for
    several (``toe_off_pct`` a number or trial -> number; one row of panels per trial, in the
    given order, titled ``trial: model``). Drawn times ``scale`` in ``unit``. The panels' images
    keep the drawn array (``AxesImage.get_array()``: rows in the order of the tick labels, top
    first).
    """
    if not rates:
        raise OptionError("no per-muscle rates given for the heat map")
    several = all(isinstance(v, Mapping) for v in rates.values())
    per_trial = {str(t): r for t, r in rates.items()} if several else {"": rates}
    rows: list[list] = []  # per trial: [(title, model, table, toe-off %)]
    for trial, by_model in per_trial.items():
        if not by_model:
            raise OptionError(f"no per-muscle rates given for the heat map of trial {trial}")
        to_pct = toe_off_pct[trial] if isinstance(toe_off_pct, Mapping) else toe_off_pct
        ms, to = _models_and_toe_off(_ordered_models(list(by_model)), models, to_pct, "per-muscle rates", "given:")
        rows.append([(f"{trial}: {m}" if several else m, m, by_model[m], to) for m in ms])
    panels = [p for row in rows for p in row]
    muscles = list(dict.fromkeys(str(c) for _, _, tab, _ in panels for c in tab.columns))
    labels = anatomical_muscles(muscles)
    rank = {g: i for i, g in enumerate(GROUPS)}
    order = sorted(muscles, key=lambda n: (rank.get(labels[n][1], len(GROUPS)), labels[n][0], n))
    names = muscle_names(order)
    group_of = [labels[n][1] for n in order]

    def array(tab):
        pct = np.asarray(tab.index, float)
        return pct, scale * np.vstack([tab[n].to_numpy(float) if n in tab.columns else np.full(pct.size, np.nan)
                                       for n in order])

    arrays = [[array(tab) for _, _, tab, _ in row] for row in rows]
    from matplotlib import colormaps

    cmap = colormaps["magma_r"].with_extremes(under=OKABE_ITO["sky blue"])  # a negative rate: sky blue
    ncol = max(len(r) for r in rows) if several else min(len(rows[0]), 3)
    grid_rows = [(i, row[k:k + ncol], arr[k:k + ncol]) for i, (row, arr) in enumerate(zip(rows, arrays))
                 for k in range(0, len(row), ncol)]
    nrow = len(grid_rows)
    row_in = max(0.16 * len(order), 1.6)  # a few muscles: the colour bar still tall enough for its numbers
    fig = _new_figure(1.7 * ncol + 3.9, (row_in + 0.45) * nrow + 1.0, left=2.7, right=0.95, wspace=0.08,
                      hspace=0.45 / row_in * 1.0 + 0.04)
    grid = fig.add_gridspec(nrow, ncol + 1, width_ratios=[1.0] * ncol + [0.07])
    first = None
    negative_any = False
    for r, (i, row, arr) in enumerate(grid_rows):
        # one colour scale per trial: its peak (and its floor, -2 % of it, under which a rate shows apart)
        hi = max(float(np.nanmax(a)) for _, a in arrays[i])
        floor = -0.02 * hi
        negative = any(float(np.nanmin(a)) < floor for _, a in arrays[i])
        negative_any |= negative
        image = None
        for j, ((head, m, _, to), (pct, a)) in enumerate(zip(row, arr)):
            ax = fig.add_subplot(grid[r, j], sharex=first)
            first = first or ax
            image = ax.imshow(a, aspect="auto", interpolation="nearest", cmap=cmap, vmin=floor, vmax=hi,
                              extent=(float(pct[0]), float(pct[-1]), len(order) - 0.5, -0.5), gid=f"heat:{head}")
            _vline(ax, to, color=OKABE_ITO["bluish green"], lw=1.3, ls="--", label="_toe-off", gid="toe-off")
            _panel_title(ax, head, color=model_colour(m), fontsize=10, fontweight="bold")
            if j == 0:
                ax.set_yticks(range(len(order)), [f"{t} [{g}]" for t, g in zip((names[n] for n in order), group_of)],
                              fontsize=8)
            else:
                ax.set_yticks([])
            for k in range(1, len(order)):  # a thin line between the muscle groups
                if group_of[k] != group_of[k - 1]:
                    _hline(ax, k - 0.5, color="white", lw=0.8)
            if r == nrow - 1:
                ax.set_xlabel("gait cycle (%)")
            else:
                ax.tick_params(labelbottom=False)
        cax = fig.add_subplot(grid[r, ncol])
        bar = fig.colorbar(image, cax=cax, extend="min" if negative else "neither")
        bar.set_label(f"{'rate' if several else 'metabolic rate'} ({unit})", fontsize=8)
        cax.tick_params(labelsize=7)
    first.set_xlim(0.0, 100.0)
    first.set_xticks([25, 50, 75])  # none at the edges, where the next panel's would meet it
    heading = title or "Metabolic rate of each muscle over the gait cycle (no basal heat)"
    if negative_any:
        heading += "; sky blue: a rate below -2 % of the peak"
    fig.suptitle(heading, fontsize=10)
    return fig
