"""Figure of the structural spread (:mod:`musclemetab.analysis.spread`): the whole-body rate of
each trial under every energy model and workflow of the study.

One panel per subject and trial (at most :data:`MAX_PANELS`, in the order of the results):
the energy models along the axis, one marker per workflow (its colour), the whole-body
metabolic rate (W/kg of body mass, both legs, with basal heat) up; the panel's title gives the
mean ranges across the energy models (M), the workflows (W) and the subject's trials (T) and
names the largest. Drawn from the results table alone (no file I/O, the Agg canvas).
"""

from __future__ import annotations

import numpy as np

__all__ = ["spread_figure", "spread_caption", "MAX_PANELS"]

#: Most panels drawn (the first subjects' trials; the table of the report has them all).
MAX_PANELS = 12


def _range_text(label: str, value: float) -> str:
    return f"{label} {value:.2f}" if np.isfinite(value) else f"{label} -"


def spread_figure(results):
    """The figure (module docstring) of a study's results table."""
    from ..analysis.spread import WHOLE_BODY, spread_values, structural_spread
    from .figures import (_grid, _legend_below, _new_figure, _ordered_models, _ordered_workflows, _panel_title,
                          model_colour, workflow_colour)

    values = spread_values(results)
    values = values[values["quantity"] == WHOLE_BODY]
    if values.empty:
        from ..errors import OptionError

        raise OptionError("no successful unit in the results: no spread to draw")
    table = structural_spread(results)
    table = table[table["quantity"] == WHOLE_BODY].head(MAX_PANELS)
    models = _ordered_models(values["model"])
    workflows = _ordered_workflows(values["workflow"])
    nrow, ncol = _grid(len(table), 4)
    fig = _new_figure(min(16.0, 0.45 * len(models) * ncol + 1.4 * ncol + 0.6), 2.6 * nrow + 1.3, bottom=1.0,
                      hspace=0.75, wspace=0.3)
    axes = fig.subplots(nrow, ncol, squeeze=False, sharey=True)
    markers = ("o", "s", "^", "D", "v", "P", "X")
    offsets = np.linspace(-0.2, 0.2, len(workflows)) if len(workflows) > 1 else np.zeros(1)
    for k, row in enumerate(table.itertuples(index=False)):
        ax = axes[k // ncol, k % ncol]
        v = values[(values["subject"] == row.subject) & (values["trial"] == row.trial)]
        for i, w in enumerate(workflows):
            vw = v[v["workflow"] == w]
            x = [models.index(m) + offsets[i] for m in vw["model"]]
            ax.plot(x, vw["value_W_per_kg"], linestyle="none", marker=markers[i % len(markers)], markersize=5,
                    color=workflow_colour(w), gid=f"workflow:{w}")
        ax.set_xticks(range(len(models)), models, fontsize=7, rotation=90 if len(models) > 4 else 0)
        for t, m in zip(ax.get_xticklabels(), models):
            t.set_color(model_colour(m))
        ax.grid(axis="y", linewidth=0.3, alpha=0.5)
        ranges = ", ".join([_range_text("M", row.range_across_models_W_per_kg),
                            _range_text("W", row.range_across_workflows_W_per_kg),
                            _range_text("T", row.range_across_trials_W_per_kg)])
        _panel_title(ax, f"{row.subject} {row.trial}\n{ranges}" + (f" ({row.largest})" if row.largest else ""),
                     fontsize=8)
        if k % ncol == 0:
            ax.set_ylabel("whole body (W/kg)")
    for k in range(len(table), nrow * ncol):
        axes[k // ncol, k % ncol].set_visible(False)
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], linestyle="none", marker=markers[i % len(markers)], color=workflow_colour(w), label=w)
               for i, w in enumerate(workflows)]
    _legend_below(fig, handles, min(len(handles), 6), 8)
    fig.suptitle("Whole-body metabolic rate under each energy model and workflow (W/kg, both legs, basal heat)",
                 fontsize=11)
    return fig


def spread_caption() -> str:
    return ("Structural spread: the whole-body metabolic rate of each subject's trial (W per kg of body mass, both "
            "legs, with basal heat) under every energy model (along each panel; colour: the model) and workflow "
            "(marker). Panel titles: the mean range (max - min, W/kg) across the energy models (M, within each "
            "workflow), across the workflows (W, within each model) and across the subject's trials (T, the data), "
            "and which is largest; '-' where the study has fewer than two of a kind. Where the energy model's range "
            "is the largest, the choice of model moves the result more than the data do (table: Structural spread; "
            "docs/uncertainty.md).")
