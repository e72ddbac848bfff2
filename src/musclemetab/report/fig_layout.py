"""The fixed layout of the report's figures and their saving: margins in inches, the texts fitted to the figure when it is saved (titles wrapped, the legend's columns, margins grown), bars, lines and bands drawn without rescaling the axes, :func:`save_figure`.

Part of :mod:`musclemetab.report.figures`, which gathers the figure functions (see its text).
"""

from __future__ import annotations

import io
import math
import os
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import OptionError


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
