"""Figures of a study: pure functions from tables and solutions to matplotlib figures.

Every function takes DataFrames or solver objects, returns a :class:`matplotlib.figure.Figure`
(drawn with the non-interactive Agg canvas, never through ``pyplot``) and does no file I/O;
:func:`save_figure` writes a figure as PNG and SVG. A function raises
:class:`~musclemetab.errors.OptionError` when its data cannot make the figure (no measured
rates, a model absent from the table, ...); the report shows the message instead.

Colours are fixed by name, from one place (:mod:`musclemetab.colours`, the Okabe-Ito palette
that colour-blind readers can tell apart): each metabolic model has one colour (the same as in
the Figure-2 plot of :mod:`musclemetab.metabolics.figure2`), each workflow one colour and each
muscle group one colour, in every figure. Names not known in advance get a colour derived from the name,
so they too keep it from one figure to the next.

Units: metabolic rates in W (one leg, summed muscles, no basal heat) over the gait cycle,
whole-body averages in W/kg of body mass (both legs, with basal heat), shares in %, speeds in
m/s, the gait cycle in % from initial contact to the next initial contact of the same leg.
"""

from __future__ import annotations

import io
import math
import os
import sys
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..analysis.groups import GROUP_NAMES as _GROUP_NAMES
from ..analysis.groups import GROUPS_WITH_OTHER, OTHER
from ..colours import OKABE_ITO
from ..colours import GROUP_COLOURS as _GROUP_COLOURS
from ..colours import MODEL_COLOURS as _MODEL_COLOURS
from ..colours import WORKFLOW_COLOURS as _WORKFLOW_COLOURS
from ..errors import MusclemetabError, OptionError, UnknownMuscleError
from ..messages import name_list

__all__ = [
    "MODEL_COLOURS",
    "WORKFLOW_COLOURS",
    "GROUP_COLOURS",
    "GROUPS",
    "DEFAULT_MUSCLES",
    "PLATEAU_BAND",
    "DESCENDING_LIMB",
    "model_colour",
    "workflow_colour",
    "group_colour",
    "trial_order",
    "preferred_trial",
    "main_workflow",
    "excitations_and_fiber_lengths",
    "estimated_vs_measured",
    "group_rates_over_cycle",
    "whole_body_over_cycle",
    "phase_shares",
    "phase_pies",
    "group_shares",
    "per_muscle_ranked",
    "rates_against_speed",
    "save_figure",
    "group_stats",
    "stat_cell",
]

#: One colour per metabolic model, per workflow and per muscle group (:mod:`musclemetab.colours`:
#: the Okabe-Ito palette, safe for colour-blind readers).
MODEL_COLOURS = _MODEL_COLOURS
WORKFLOW_COLOURS = _WORKFLOW_COLOURS
GROUP_COLOURS = _GROUP_COLOURS

#: Muscle function groups (``docs/analysis.md``): ankle, knee, hip, then the remainder.
GROUPS = GROUPS_WITH_OTHER
GROUP_NAMES = {**_GROUP_NAMES, OTHER: "other"}


def default_muscles(available: Sequence[str], side: str = "r") -> list[str]:
    """Muscles of the excitation and fiber-length figure: the report list of the anatomical
    muscle table (column ``report_order``) placed on ``available`` (``side`` leg, else all)."""
    from ..properties import report_muscles, split_side

    on_side = [m for m in available if split_side(m)[1] == side]
    return report_muscles(on_side or list(available))


def _study_model_default_muscles() -> tuple[str, ...]:
    from ..properties import alias_table, split_side

    a = alias_table()
    names = [f"{n}_r" for n, f in zip(a["model_name"], a["families"]) if "rajagopal" in f]
    return tuple(split_side(m)[0] for m in default_muscles(names))


def __getattr__(name: str):
    # DEFAULT_MUSCLES: side-free names of the figure's muscles in the study's model
    # (``default_muscles`` of it), read from the muscle table when first asked for
    if name == "DEFAULT_MUSCLES":
        value = globals()["DEFAULT_MUSCLES"] = _study_model_default_muscles()
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

#: Normalised fiber lengths of the plateau of the active force-length curve (shaded).
PLATEAU_BAND = (0.75, 1.05)
#: Normalised fiber length above which a fiber works on the descending limb.
DESCENDING_LIMB = 1.05

_FALLBACK = ("#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e", "#e6ab02", "#a6761d",
             "#666666", "#8dd3c7", "#fb8072", "#80b1d3", "#b3de69")
_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*", "<", ">", "h", "p")
_LINESTYLES = ("-", "--", "-.", ":")


def _named_colour(table: Mapping[str, str], name: str) -> str:
    key = str(name)
    for k in (key, key.upper(), key.lower()):
        if k in table:
            return table[k]
    return _FALLBACK[zlib.crc32(key.encode("utf-8")) % len(_FALLBACK)]


def model_colour(model: str) -> str:
    """The colour of a metabolic model (known models fixed, others derived from the name)."""
    return _named_colour(MODEL_COLOURS, model)


def workflow_colour(workflow: str) -> str:
    """The colour of a workflow (known workflows fixed, others derived from the name)."""
    return _named_colour(WORKFLOW_COLOURS, workflow)


def group_colour(group: str) -> str:
    """The colour of a muscle group."""
    return _named_colour(GROUP_COLOURS, group)


# ---------------------------------------------------------------------------------- helpers
#: Margins of the fixed layout (inches): left, right, top (title), bottom (one legend row).
_MARGINS_IN = {"left": 0.75, "right": 0.2, "top": 0.55, "bottom": 0.75, "wspace": 0.28, "hspace": 0.32}


def _new_figure(width: float, height: float, **margins_in):
    """An Agg figure with a fixed layout: margins in inches (:data:`_MARGINS_IN`, overridden
    by ``margins_in``), applied once when the figure is saved.

    A fixed layout is drawn once; matplotlib's constrained layout draws every figure an
    extra time to measure it, which doubled the report's drawing time.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    fig._musclemetab_margins = {**_MARGINS_IN, **margins_in}
    return fig


def _in_view_locator(nbins: int = 4):
    """At most ``nbins`` + 1 major ticks, none outside the axis limits.

    matplotlib's automatic locators also return a tick beyond each limit, and a tick object
    (two lines, two texts) is made for each before those outside are dropped at drawing.
    """
    from matplotlib.ticker import MaxNLocator

    class InView(MaxNLocator):
        def __call__(self):
            vmin, vmax = sorted(self.axis.get_view_interval())
            locs = np.asarray(super().__call__())
            tol = 1e-9 * max(abs(vmax - vmin), 1e-300)
            return locs[(locs >= vmin - tol) & (locs <= vmax + tol)]

    return InView(nbins=nbins, steps=[1, 2, 2.5, 5, 10])


def _fewer_ticks(fig) -> None:
    """At most five (x) and six (y) major ticks, none outside the limits (:func:`_in_view_locator`), on every
    axis left to matplotlib's automatic locator.

    Every tick is a set of lines and a text drawn and measured at each save; the default
    locator puts up to nine on a panel of this size.
    """
    from matplotlib.ticker import AutoLocator

    for ax in fig.axes:
        # one more interval on the rate axes: 0 to 19 W/kg is numbered 0, 5, 10, 15, not 0, 10
        for axis, nbins in ((ax.xaxis, 4), (ax.yaxis, 5)):
            if type(axis.get_major_locator()) is AutoLocator:
                axis.set_major_locator(_in_view_locator(nbins))


def _apply_layout(fig) -> None:
    """Place the panels inside the figure's margins (see :func:`_new_figure`); fewer ticks.

    The texts are fitted first (:func:`_fit_texts`): the figure's title wrapped to the
    figure's width, the legend below the panels given as many columns as fit, the panel
    titles wrapped to their panel, and the margins grown to hold them and the tick labels
    of fixed text (muscle or trial names), so that no text is cut by the figure's edge or
    drawn over another (:func:`~.layout_check.figure_problems` checks it)."""
    m = getattr(fig, "_musclemetab_margins", None)
    if m is None or fig.get_layout_engine() is not None:
        return
    _fewer_ticks(fig)
    _adjust(fig, m)
    _fit_texts(fig, m)


def _adjust(fig, m) -> None:
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=m["left"] / w, right=1.0 - m["right"] / w, top=1.0 - m["top"] / h,
                        bottom=m["bottom"] / h, wspace=m["wspace"], hspace=m["hspace"])


def _wrap_to(text, width_px: float, renderer) -> int:
    """Wrap a text artist at its spaces so that each line is at most ``width_px`` wide (a
    word longer than that stays whole; its own line breaks kept); returns its number of lines."""
    if text.get_window_extent(renderer).width <= width_px:
        return str(text.get_text()).count("\n") + 1
    lines: list[str] = []
    for para in str(text.get_text()).split("\n"):
        line = ""
        for word in para.split(" "):
            longer = f"{line} {word}" if line else word
            text.set_text(longer)
            if line and text.get_window_extent(renderer).width > width_px:
                lines.append(line)
                line = word
            else:
                line = longer
        lines.append(line)
    text.set_text("\n".join(lines))
    return len(lines)


def _fit_texts(fig, m) -> None:
    """See :func:`_apply_layout`: wrap the titles, fit the legend's columns, grow the margins."""
    renderer = fig.canvas.get_renderer()
    px = fig.dpi
    w_in, h_in = fig.get_size_inches()
    changed = False
    # the figure's legend below the panels: as many columns as fit in the figure's width
    below = getattr(fig, "_musclemetab_legend", None)
    if below is not None:
        legend, handles, ncol, kw = below
        while ncol > 1 and legend.get_window_extent(renderer).width > (w_in - 0.2) * px:
            ncol -= 1
            legend.remove()
            legend = fig.legend(handles=handles, ncol=ncol, **kw)
        fig._musclemetab_legend = (legend, handles, ncol, kw)
        need = legend.get_window_extent(renderer).height / px + 0.55
        if need > m["bottom"]:
            m["bottom"], changed = need, True
    # the tick labels of fixed text on the outer panels (names): the left margin holds them and the axis label
    visible = [ax for ax in fig.axes if ax.get_visible() and ax.get_label() != "<colorbar>"]
    need_left = 0.0
    for ax in visible:
        if ax.get_subplotspec() is None or not ax.get_subplotspec().is_first_col():
            continue
        labels = [t for t in ax.get_yticklabels() if t.get_visible() and t.get_text()]
        if not labels or ax.yaxis.get_ticks_position() == "right":
            continue
        wide = max(t.get_window_extent(renderer).width for t in labels) / px
        ylab = ax.yaxis.label
        extra = ylab.get_window_extent(renderer).width / px + 0.1 if ylab.get_text() else 0.0
        need_left = max(need_left, wide + extra + 0.2)
    if need_left > m["left"]:
        m["left"], changed = need_left, True
    if changed:
        _adjust(fig, m)
    # panel titles wrapped to their panel; the top margin holds the figure's title above the
    # top row's titles (and tick labels drawn on top)
    top_row = 0.0
    for ax in visible:
        ax_w = ax.get_window_extent(renderer).width
        title = ax.title
        if title.get_text():
            _wrap_to(title, ax_w + 0.5 * m["wspace"] * ax_w, renderer)
        spec = ax.get_subplotspec()
        if spec is not None and spec.is_first_row():
            high = title.get_window_extent(renderer).height / px + 0.08 if title.get_text() else 0.0
            if ax.xaxis.get_ticks_position() in ("top", "unknown") or getattr(ax.xaxis, "_musclemetab_top", False):
                labels = [t for t in ax.get_xticklabels() if t.get_text()]
                if labels:
                    high += max(t.get_window_extent(renderer).height for t in labels) / px + 0.1
            top_row = max(top_row, high)
    sup = getattr(fig, "_suptitle", None)
    sup_h = 0.0
    if sup is not None and sup.get_text():
        _wrap_to(sup, (w_in - 0.3) * px, renderer)
        sup.set_y(1.0 - 0.08 / h_in)
        sup.set_va("top")
        sup_h = sup.get_window_extent(renderer).height / px + 0.08
    need_top = sup_h + top_row + 0.1
    if need_top > m["top"]:
        m["top"] = need_top
        _adjust(fig, m)


def _panel_title(ax, text: str, **kw) -> None:
    """A panel title at a fixed height above the panel.

    A title left to matplotlib's automatic placement measures the panel's tick labels at
    every draw to dodge them; these panels have none on top, so the measurement is skipped.
    """
    ax.set_title(text, y=1.0, **kw)


def _legend_below(fig, handles, ncol: int, fontsize: float, **kw) -> None:
    """The figure's legend centred below the panels (``kw``: more of ``fig.legend``'s
    options, e.g. its title), the bottom margin grown to fit its rows under the axis labels;
    when saved, given as many columns as fit in the figure's width (:func:`_fit_texts`)."""
    rows = int(math.ceil(len(handles) / max(ncol, 1)))
    m = getattr(fig, "_musclemetab_margins", None)
    if m is not None:
        m["bottom"] = max(m["bottom"], 0.55 + rows * fontsize / 72.0 * 1.7)
    kw = {"loc": "lower center", "fontsize": fontsize, "frameon": False, **kw}
    legend = fig.legend(handles=handles, ncol=ncol, **kw)
    fig._musclemetab_legend = (legend, handles, ncol, kw)


def _grid(n: int, max_cols: int = 3) -> tuple[int, int]:
    ncol = max(1, min(max_cols, n))
    return int(math.ceil(n / ncol)), ncol


def _add_bars(ax, x, y, width, height, colours, gids, **kw) -> list:
    """Bars with lower-left corners ``(x, y)`` and sizes ``width`` x ``height`` (data units;
    scalars or one per bar), coloured one by one: one polygon collection per name in ``gids``
    (its ``gid``), added to ``ax`` without updating its data limits (the caller sets the axis
    limits, see :func:`_bar_limits`); ``kw``: edge colour and width. Returns the collections.

    ``ax.bar`` adds a patch per bar and measures its limits, about 1 ms a bar, and each patch
    is drawn on its own: the report's bar figures have some 700 bars.
    """
    from matplotlib.collections import PolyCollection

    n = len(colours)
    x, y, width, height = (np.broadcast_to(np.asarray(v, float), (n,)) for v in (x, y, width, height))
    corners = np.stack([np.stack([x, y], 1), np.stack([x + width, y], 1), np.stack([x + width, y + height], 1),
                        np.stack([x, y + height], 1)], 1)
    out = []
    for gid in dict.fromkeys(gids):
        pick = [i for i in range(n) if gids[i] == gid]
        bars = PolyCollection(corners[pick], facecolors=[colours[i] for i in pick], gid=gid,
                              edgecolors=kw.get("edgecolor", "none"), linewidths=kw.get("linewidth", 0.0))
        ax.add_collection(bars, autolim=False)
        out.append(bars)
    return out


def _vline(ax, x: float, ymin: float = 0.0, ymax: float = 1.0, **kw):
    """A vertical line at ``x`` (data) from ``ymin`` to ``ymax`` (fractions of the panel's
    height), as ``ax.axvline`` draws it. ``axvline`` reads the axis limits to decide whether to
    rescale, which recomputes the automatic limits of every panel sharing the axis: on the
    24 shared panels of the excitation figure, a third of its drawing time."""
    from matplotlib.lines import Line2D

    line = Line2D([x, x], [ymin, ymax], transform=ax.get_xaxis_transform(which="grid"), **kw)
    ax.add_line(line)
    return line


def _hline(ax, y: float, **kw):
    """A horizontal line across the panel at ``y`` (data), as ``ax.axhline`` (see :func:`_vline`)."""
    from matplotlib.lines import Line2D

    line = Line2D([0.0, 1.0], [y, y], transform=ax.get_yaxis_transform(which="grid"), **kw)
    ax.add_line(line)
    return line


def _hspan(ax, lo: float, hi: float, **kw):
    """A band across the panel from ``lo`` to ``hi`` (data), as ``ax.axhspan`` (see :func:`_vline`)."""
    from matplotlib.patches import Rectangle

    band = Rectangle((0.0, lo), 1.0, hi - lo, transform=ax.get_yaxis_transform(which="grid"), **kw)
    ax.add_patch(band)
    return band


def _bar_limits(lo: float, hi: float, start: float | None = None) -> tuple[float, float]:
    """Axis limits over bars spanning ``lo``-``hi``: 5 % of the span added on either side, as
    matplotlib's automatic limits do, but not past ``start`` (the value the bars start from)."""
    pad = 0.05 * (hi - lo)
    a, b = lo - pad, hi + pad
    if start is not None:
        a = start if lo >= start else a
        b = start if hi <= start else b
    return a, b


from .uncertainty import has_band, shade_band  # noqa: E402  (the uncertainty bands, when the study has them)


def _require_columns(df, columns: Sequence[str], what: str) -> None:
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise OptionError(f"{what} lacks the column{'s' if len(missing) > 1 else ''} {name_list(missing)}")


def _ok_rows(results):
    _require_columns(results, ("subject", "trial", "workflow", "model"), "the results table")
    if "status" in results.columns:
        results = results[results["status"].astype(str).str.lower() == "ok"]
    return results


def _unique(values) -> list:
    """The distinct values in order of appearance (of a table column: through its ``unique``,
    not element by element)."""
    if hasattr(values, "unique"):
        values = values.unique()
    return list(dict.fromkeys(values))


def _ordered_models(names) -> list[str]:
    names = _unique(str(n) for n in _unique(names))
    known = [m for m in MODEL_COLOURS if m in names]
    return known + [m for m in names if m not in known]


def _ordered_workflows(names) -> list[str]:
    names = _unique(str(n) for n in _unique(names))
    known = [w for w in WORKFLOW_COLOURS if w in names]
    return known + [w for w in names if w not in known]


def trial_order(results) -> list[str]:
    """Trials ordered by mean walking speed over subjects (trials without a speed last, by name)."""
    _require_columns(results, ("trial",), "the results table")
    trials = _unique(str(t) for t in _unique(results["trial"]))
    if "speed_m_per_s" not in results.columns:
        return sorted(trials)
    speeds = results.assign(trial=results["trial"].astype(str)).groupby("trial")["speed_m_per_s"].mean()

    def key(t):
        v = speeds.get(t, math.nan)
        return (0, float(v), t) if np.isfinite(v) else (1, 0.0, t)

    return sorted(trials, key=key)


def preferred_trial(results) -> str:
    """The trial at the preferred walking speed.

    The trial named ``normal`` (or ``preferred``, ``pws``; case-insensitive) if there is one,
    otherwise the middle trial in speed order (the slower of the two middle ones for an even
    number of trials).
    """
    order = trial_order(results)
    if not order:
        raise OptionError("the results table has no trial")
    for name in ("normal", "preferred", "pws"):
        for t in order:
            if t.lower() == name:
                return t
    return order[(len(order) - 1) // 2]


def main_workflow(workflows: Sequence[str]) -> str:
    """The workflow shown when a figure shows one: EFFORT-TEN if present, otherwise the first."""
    workflows = [str(w) for w in workflows]
    if not workflows:
        raise OptionError("no workflow given")
    for w in workflows:
        if w.lower() == "effort-ten":
            return w
    return workflows[0]


def group_stats(df, by: Sequence[str], columns: Sequence[str]) -> dict:
    """Mean, sample SD and count of the finite values of ``columns`` in each group of ``by``.

    Returns ``{group: {column: (mean, sd, n)}}``; a group is the text of its ``by`` value
    (one column) or the tuple of them; the SD of a group with one value is NaN. One pass
    over the table, where a filter per cell of a results table would take one each.
    """
    import pandas as pd

    columns = list(columns)
    keys = {k: df[k].astype(str) for k in by}
    values = df[columns].apply(pd.to_numeric, errors="coerce").replace([np.inf, -np.inf], np.nan)
    grouped = values.assign(**keys).groupby(list(by), sort=False)[columns]
    mean, sd, n = grouped.mean(), grouped.std(ddof=1), grouped.count()
    m, s, c = mean.to_numpy(float), sd.reindex(mean.index).to_numpy(float), n.reindex(mean.index).to_numpy(int)
    return {key: {col: (float(m[i, j]), float(s[i, j]), int(c[i, j])) for j, col in enumerate(columns)}
            for i, key in enumerate(mean.index)}


def stat_cell(stats: dict, key, column: str) -> tuple[float, float, int]:
    """``(mean, sd, n)`` of ``column`` in the group ``key`` of :func:`group_stats` (NaN, NaN, 0 if absent)."""
    return stats.get(key, {}).get(column, (math.nan, math.nan, 0))


def _one_workflow(table, workflow: str | None, what: str):
    """``(workflow, its rows)``: ``workflow``, or :func:`main_workflow` of the table's when
    ``None``; raises :class:`OptionError` when the table has no row of it."""
    wfs = _ordered_workflows(table["workflow"])
    wf = main_workflow(wfs) if workflow is None else str(workflow)
    d = table[table["workflow"].astype(str) == wf]
    if d.empty:
        raise OptionError(f"workflow '{wf}' is not in {what}; it has {', '.join(wfs)}")
    return wf, d


def _rmcorr(x, y, subject):
    """Repeated-measures correlation (``docs/analysis.md``): ``(result, None)`` or ``(None, reason)``."""
    from ..analysis.stats import rmcorr

    try:
        res = rmcorr(np.asarray(x, float), np.asarray(y, float), np.asarray(subject, dtype=object))
    except MusclemetabError as exc:
        return None, " ".join(str(exc).split())
    if not np.isfinite(res.slope):
        return None, "the slope is not finite"
    return res, None


def _p_text(p: float) -> str:
    if not np.isfinite(p):
        return "p = n/a"
    return "p < 0.001" if p < 0.001 else f"p = {p:.3f}"


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


def _models_and_toe_off(available: Sequence[str], models, toe_off_pct, what: str, having: str
                        ) -> tuple[list[str], float]:
    """The models to draw (``models`` or every one ``available``) and the toe-off (% of the
    cycle); :class:`OptionError` for a model without data or a toe-off outside the cycle."""
    models = list(available) if models is None else [str(m) for m in models]
    absent = [m for m in models if m not in available]
    if absent:
        raise OptionError(f"no {what} for model {name_list(absent)} ({having} {', '.join(available)})")
    to = float(toe_off_pct)
    if not (0.0 < to < 100.0):
        raise OptionError(f"toe-off must be inside the cycle (0-100 %), not {toe_off_pct}")
    return models, to


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
                        f"whole-body rate without basal heat (W/kg; {wf}; mean over subjects)")
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
                ax.set_xlabel("trial, speed (m/s)", fontsize=8)
    axes[0, 0].set_ylim(0, 100)
    axes[0, 0].set_xlim(*_bar_limits(-width / 2, len(trials) - 1 + width / 2))
    from matplotlib.patches import Patch

    handles = [Patch(color=group_colour(g), label=f"{g} ({GROUP_NAMES.get(g, g)})") for g in groups]
    _legend_below(fig, handles, min(len(handles), 6), 8)
    fig.suptitle(title or "Shares of the muscle groups in the cycle's muscle metabolic energy "
                 "(%, one leg, no basal heat; mean over subjects)", fontsize=11)
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
    import textwrap

    fig.suptitle(textwrap.fill(title or f"The {top} muscles with the largest metabolic rate, across walking speeds "
                               f"({wf}; W/kg of body mass, one leg, no basal heat; mean over subjects)",
                               int(fig.get_figwidth() * 11)), fontsize=11)
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


# ------------------------------------------------------------------------------ saving
def save_figure(fig, out_dir: str | os.PathLike, name: str, *, dpi: int = 110,
                formats: Sequence[str] = ("png", "svg")) -> dict[str, Path]:
    """Write ``out_dir/name.<format>`` for each of ``formats`` (PNG, SVG) atomically; close the figure.

    Returns ``{format: path}``. The files carry no date or software stamp, so identical
    figures give identical files.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from ..io.atomic import atomic_write_bytes

    name = str(name)
    if not name or any(ch in name for ch in "/\\") or name.startswith("."):
        raise OptionError(f"figure name '{name}' must be a plain file name without an extension")
    unknown = [f for f in formats if f not in ("png", "svg")]
    if unknown or not formats:
        raise OptionError(f"figure formats must be png and/or svg, not {', '.join(map(str, formats)) or 'none'}")
    out_dir = Path(out_dir)
    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    # drawn at the saved resolution: what the figure measures afterwards (its texts' boxes,
    # :func:`~.layout_check.figure_problems`) is what the files show
    fig.set_dpi(dpi)
    _apply_layout(fig)
    import matplotlib

    paths = {}
    meta = {"png": {"Software": None}, "svg": {"Date": None}}
    # zlib level 3: a third faster than the default 6, files 2 % larger
    extra = {"png": {"pil_kwargs": {"compress_level": 3}}, "svg": {}}
    # text without hinting: the glyphs are not fitted to the pixel grid (a difference hard to
    # see at 110 dpi), which makes laying out and drawing the ~500 texts of the report a third faster
    with matplotlib.rc_context({"svg.hashsalt": "musclemetab", "svg.fonttype": "path", "text.hinting": "no_hinting"}):
        for fmt in formats:
            buf = io.BytesIO()
            fig.savefig(buf, format=fmt, dpi=dpi, metadata=meta[fmt], **extra[fmt])
            paths[fmt] = atomic_write_bytes(out_dir / f"{name}.{fmt}", buf.getvalue(), mark=True)
    if "matplotlib.pyplot" in sys.modules:
        sys.modules["matplotlib.pyplot"].close(fig)
    return paths
