"""Figures comparing the energy models: estimated against measured rates, the paper's Figure 2 in one compact grid.

Part of :mod:`musclemetab.report.figures`, which gathers the figure functions (see its text).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import OptionError
from ..messages import name_list
from .fig_data import (
    _MARKERS, model_colour, workflow_colour, _require_columns, _ok_rows, _unique, _ordered_models,
    _ordered_workflows, _rmcorr, _p_text,
)
from .fig_layout import _new_figure, _panel_title, _legend_below, _grid, _hline


# ------------------------------------------------------------- 2. estimated vs measured rate
def estimated_vs_measured(results, *, models: Sequence[str] | None = None, title: str | None = None):
    """Estimated against measured whole-body metabolic rate (W/kg), one panel per model.

    Points: one per subject and trial (marker per subject, colour per workflow). Lines: the
    repeated-measures correlation of each workflow (``docs/analysis.md``; estimated on measured),
    one parallel segment per subject over that subject's measured range; the legend gives the
    slope ``m``, ``r`` and ``p``. The dashed line is the identity. Rows with status other than
    ``ok`` or without a measured rate are left out; raises :class:`OptionError` when no row has
    a measured rate.
    """
    res = _ok_rows(results)
    _require_columns(res, ("whole_body_W_per_kg", "measured_W_per_kg"), "the results table")
    res = res[np.isfinite(res["measured_W_per_kg"].astype(float)) & np.isfinite(res["whole_body_W_per_kg"].astype(float))]
    if res.empty:
        raise OptionError(
            "no measured metabolic rate in the results (column measured_W_per_kg is empty); "
            "give measured rates to the study to compare estimates with measurements"
        )
    models = _ordered_models(res["model"]) if models is None else [str(m) for m in models]
    absent = [m for m in models if m not in set(res["model"].astype(str))]
    if absent:
        raise OptionError(f"no measured comparison for model {name_list(absent)}")
    workflows = _ordered_workflows(res["workflow"])
    subjects = _unique(str(s) for s in res["subject"])
    marker = {s: _MARKERS[i % len(_MARKERS)] for i, s in enumerate(subjects)}
    nrow, ncol = _grid(len(models))
    fig = _new_figure(4.3 * ncol, 4.2 * nrow + 1.0)
    axes = fig.subplots(nrow, ncol, squeeze=False)
    notes: list[str] = []
    allv = np.concatenate([res["measured_W_per_kg"].to_numpy(float), res["whole_body_W_per_kg"].to_numpy(float)])
    lo, hi = float(np.min(allv)), float(np.max(allv))
    pad = 0.06 * max(hi - lo, 0.5)
    lim = (max(0.0, lo - pad), hi + pad)
    for k, m in enumerate(models):
        ax = axes.flat[k]
        ax.plot(lim, lim, color="0.4", ls="--", lw=0.9, label="identity", gid="identity")
        dm = res[res["model"].astype(str) == m]
        for w in workflows:
            dw = dm[dm["workflow"].astype(str) == w]
            if dw.empty:
                continue
            col = workflow_colour(w)
            for s in subjects:
                ds = dw[dw["subject"].astype(str) == s]
                if not ds.empty:
                    ax.scatter(ds["measured_W_per_kg"], ds["whole_body_W_per_kg"], color=col, marker=marker[s],
                               s=26, zorder=3, label="_" + s)
            x = dw["measured_W_per_kg"].to_numpy(float)
            y = dw["whole_body_W_per_kg"].to_numpy(float)
            subj = dw["subject"].astype(str).to_numpy()
            rm, why = _rmcorr(x, y, subj)
            if rm is None:
                ax.plot([], [], color=col, label=f"{w}: no repeated-measures correlation")
                notes.append(f"{m}, {w}: {why}")
                continue
            first = True
            for s in _unique(subj.tolist()):
                xs = x[subj == s]
                if xs.size < 2 or s not in rm.intercepts:
                    continue
                xx = np.array([xs.min(), xs.max()])
                ax.plot(xx, rm.intercepts[s] + rm.slope * xx, color=col, lw=1.2, gid=f"rmcorr:{w}:{s}",
                        label=(f"{w}: m = {rm.slope:.2f}, r = {rm.r:.2f}, {_p_text(rm.p)}" if first else "_" + w))
                first = False
        ax.set_xlim(lim)
        ax.set_ylim(lim)
        _panel_title(ax, m, color=model_colour(m), fontsize=11, fontweight="bold")
        ax.set_xlabel("measured (W/kg)")
        ax.set_ylabel("estimated (W/kg)")
        ax.legend(fontsize=7, loc="best", framealpha=0.8)
    for k in range(len(models), nrow * ncol):
        axes.flat[k].set_visible(False)
    if len(subjects) > 1:
        from matplotlib.lines import Line2D

        handles = [Line2D([], [], ls="", marker=marker[s], color="0.3", label=s) for s in subjects]
        _legend_below(fig, handles, min(len(subjects), 10), 8, title="subject", title_fontsize=8)
    heading = title or ("Estimated vs measured whole-body metabolic rate (W/kg, with basal heat); "
                        "lines: repeated-measures correlation")
    if notes:  # why a correlation is missing, once per distinct reason
        import textwrap

        reasons = _unique(n.split(": ", 1)[1] for n in notes)
        heading += "\n" + textwrap.fill("Lines not drawn: " + "; ".join(reasons), 150)
    fig.suptitle(heading, fontsize=11)
    return fig


# ------------------------------------------------------------- the paper's Figure 2, compact
def figure2_compact(data: dict):
    """The paper's Figure 2 in one compact grid: columns one model each, rows the metabolic rate
    (W) and the efficiency over the fiber velocity (at the length plane) and over the fiber length
    (at the velocity plane); every panel of a row shares its axes, so that the models compare
    across the row. One line per activation (light: low, dark: full).

    ``data``: :func:`musclemetab.metabolics.figure2.figure2_data`.
    """
    models, acts = list(data["models"]), np.asarray(data["activations"], float)
    v, ln = data["velocity"], data["length"]
    rows = (("rate_W", v, "vbar", "rate (W)"), ("efficiency", v, "vbar", "efficiency (-)"),
            ("rate_W", ln, "normalized_fiber_length", "rate (W)"), ("efficiency", ln, "normalized_fiber_length",
                                                                     "efficiency (-)"))
    ncol = len(models)
    fig = _new_figure(1.75 * ncol + 1.0, 1.55 * len(rows) + 1.7, left=0.8, top=0.85, wspace=0.1, hspace=0.45)
    axes = fig.subplots(len(rows), ncol, squeeze=False, sharey="row")
    shades = np.linspace(0.3, 1.0, len(acts))
    for j, m in enumerate(models):
        for i, (key, plane, x, ylabel) in enumerate(rows):
            ax = axes[i, j]
            first = axes[0, 0] if plane is v else axes[2, 0]  # one abscissa per plane
            if ax is not first:
                ax.sharex(first)
            for k, a in enumerate(acts):
                ax.plot(plane[x], plane[key][m][k], color=model_colour(m), alpha=float(shades[k]), lw=1.1,
                        gid=f"{key}:{'velocity' if plane is v else 'length'}:{m}:a={a:g}")
            _hline(ax, 0.0, color="0.7", lw=0.5)
            if j == 0:
                ax.set_ylabel(ylabel, fontsize=8)
            else:
                ax.tick_params(labelleft=False)
            ax.tick_params(labelsize=7)
            if i == 0:
                _panel_title(ax, m, color=model_colour(m), fontsize=10, fontweight="bold")
    for i, (_, plane, x, _) in enumerate(rows):
        if i in (0, 2):
            axes[i, 0].set_xlim(float(np.min(plane[x])), float(np.max(plane[x])))
            # none at the panels' edges, where the next panel's would meet it
            axes[i, 0].set_xticks([-0.5, 0.0, 0.5] if plane is v else [0.75, 1.0, 1.25])
        if i in (1, 3):
            axes[i, 0].set_xlabel("fiber velocity (vmax; < 0: shortening)" if plane is v
                                  else "fiber length (optimal lengths)", fontsize=7, loc="left")
    eff_lim = max(float(np.nanmax(data[p]["efficiency"][m])) for p in ("velocity", "length") for m in models)
    # every curve inside its panel (HO06's efficiency exceeds 1 at low activation off the plateau)
    axes[1, 0].set_ylim(0.0, 1.05 * eff_lim)
    axes[3, 0].set_ylim(0.0, 1.05 * eff_lim)
    cfg = data["config"]
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color="0.2", alpha=float(sh), lw=1.5, label=f"activation {a:g}")
               for a, sh in zip(acts, shades)]
    _legend_below(fig, handles, len(handles), 8)
    fig.suptitle(f"The metabolic models on one soleus in steady states (the paper's Figure 2)\nrows 1-2: over the "
                 f"fiber velocity at l/lo = {v['normalized_fiber_length']:g}; rows 3-4: over the fiber length at "
                 f"v = {ln['vbar']:g} vmax; slow-twitch fraction {cfg['slow_twitch_fraction']:g}, "
                 f"{cfg['muscle_mass_kg']:g} kg", fontsize=9.5)
    return fig
