"""A figure's texts checked for being readable: none cut by the figure's edge, none over another.

:func:`figure_problems` measures every visible text of a drawn matplotlib figure (the
figure's title and legend, each panel's title, axis labels, tick labels, legend and
annotations) with the figure's renderer (``Text.get_window_extent``) and returns one line per
problem: a text reaching past the figure's edge (it is clipped in the saved image), and two
texts whose boxes overlap (one is drawn over the other). The report runs it on every figure
it draws (:func:`~.draw.draw_figure`) and names the problems it finds; the test suite asserts
that the report's figures have none.
"""

from __future__ import annotations

import numpy as np

__all__ = ["figure_problems", "figure_texts", "TOLERANCE_PX", "GAP_PX"]

#: Pixels a text may reach past the edge before it counts (antialiasing, the rounding of a
#: box to pixels).
TOLERANCE_PX = 1.0
#: The least space between two texts (pixels): closer, two tick labels of neighbouring
#: panels read as one ("1-1").
GAP_PX = 2.0


def _drawn_ticks(axis) -> list:
    """The ticks of ``axis`` that matplotlib draws: those inside the axis's view interval."""
    lo, hi = sorted(axis.get_view_interval())
    tol = 1e-9 * max(abs(hi - lo), 1e-300)
    ticks = []
    for tick in axis.get_major_ticks() + axis.get_minor_ticks():
        loc = tick.get_loc()
        if loc is not None and lo - tol <= loc <= hi + tol:
            ticks.append(tick)
    return ticks


def _legend_texts(legend) -> list:
    if legend is None or not legend.get_visible():
        return []
    return [legend.get_title(), *legend.get_texts()]


def figure_texts(fig) -> list[tuple[str, object]]:
    """``(where, text artist)`` of every visible, non-empty text of ``fig`` (``where`` names it:
    ``suptitle``, ``panel 2 title``, ``panel 1 y tick``, ...)."""
    out: list[tuple[str, object]] = []
    if getattr(fig, "_suptitle", None) is not None:
        out.append(("figure title", fig._suptitle))
    for t in fig.texts:
        if t is not getattr(fig, "_suptitle", None):
            out.append(("figure text", t))
    for leg in fig.legends:
        out += [("figure legend", t) for t in _legend_texts(leg)]
    for i, ax in enumerate(fig.axes, start=1):
        if not ax.get_visible():
            continue
        name = f"panel {i}"
        for attr in ("title", "_left_title", "_right_title"):
            t = getattr(ax, attr, None)
            if t is not None:
                out.append((f"{name} title", t))
        out.append((f"{name} x label", ax.xaxis.label))
        out.append((f"{name} y label", ax.yaxis.label))
        for axis, which in ((ax.xaxis, "x"), (ax.yaxis, "y")):
            if not axis.get_visible():
                continue
            for tick in _drawn_ticks(axis):
                for label in (tick.label1, tick.label2):
                    out.append((f"{name} {which} tick", label))
        out += [(f"{name} legend", t) for t in _legend_texts(ax.get_legend())]
        out += [(f"{name} text", t) for t in ax.texts]
    return [(w, t) for w, t in out if t.get_visible() and str(t.get_text()).strip()]


def figure_problems(fig, *, drawn: bool = False) -> list[str]:
    """The readability problems of a figure's texts, one line each (``[]``: none).

    * a text whose box reaches past the figure's edge by more than :data:`TOLERANCE_PX`
      (clipped in the saved image);
    * two texts whose boxes come closer than :data:`GAP_PX` (overlap, or touch) in both
      directions (titles, axis labels, tick labels, legend entries and annotations alike).

    ``drawn``: the figure was drawn as it is (saved): its tick labels are placed and are
    measured as they are; otherwise it is laid out as the report saves it and drawn once
    without rendering.
    """
    if not drawn:
        from .figures import _apply_layout

        _apply_layout(fig)
        fig.draw_without_rendering()
    renderer = fig.canvas.get_renderer()
    texts = figure_texts(fig)
    if not texts:
        return []
    boxes = np.array([t.get_window_extent(renderer).extents for _, t in texts], float)  # x0, y0, x1, y1
    W, H = fig.bbox.width, fig.bbox.height
    tol = TOLERANCE_PX
    problems = []
    for (where, t), (x0, y0, x1, y1) in zip(texts, boxes):
        sides = [s for s, out in (("left", x0 < -tol), ("right", x1 > W + tol), ("bottom", y0 < -tol),
                                  ("top", y1 > H + tol)) if out]
        if sides:
            problems.append(f"{where} '{_short(t)}' is cut by the figure's {' and '.join(sides)} edge")
    # every pair at once: overlap in x and in y by more than the tolerance
    ox = np.minimum(boxes[:, None, 2], boxes[None, :, 2]) - np.maximum(boxes[:, None, 0], boxes[None, :, 0])
    oy = np.minimum(boxes[:, None, 3], boxes[None, :, 3]) - np.maximum(boxes[:, None, 1], boxes[None, :, 1])
    hit = (ox > -GAP_PX) & (oy > -GAP_PX)
    for i, j in zip(*np.nonzero(np.triu(hit, k=1))):
        (wi, ti), (wj, tj) = texts[i], texts[j]
        problems.append(f"{wi} '{_short(ti)}' overlaps {wj} '{_short(tj)}'")
    return problems


def _short(text) -> str:
    s = " ".join(str(text.get_text()).split())
    return s if len(s) <= 40 else s[:37] + "..."
