"""The report's uncertainty bands in the figures: the shaded bands and their captions
(``docs/uncertainty.md``; the tables with intervals and the priors: :mod:`.page`).

A study run with uncertainty samples (:mod:`musclemetab.study.uncertainty`) has ``<rate>_p05``,
``_p50`` and ``_p95`` columns beside its rates; without them nothing here draws or writes anything.
"""

from __future__ import annotations

import numpy as np

__all__ = ["has_band", "shade_band", "band_caption"]


def has_band(table, column: str) -> bool:
    """Whether ``table`` has the band of ``column`` with at least one value."""
    return (f"{column}_p05" in table.columns and f"{column}_p95" in table.columns
            and bool(np.isfinite(table[f"{column}_p05"].to_numpy(float)).any()))


def shade_band(ax, x, lo, hi, colour, gid: str, **kw):
    """A shaded band from ``lo`` to ``hi`` over ``x`` (sorted); a single point gets a vertical bar."""
    x, lo, hi = (np.asarray(v, dtype=float) for v in (x, lo, hi))
    if x.size == 1:
        return ax.errorbar(x, (lo + hi) / 2, yerr=(hi - lo) / 2, fmt="none", ecolor=colour, alpha=0.45,
                           elinewidth=6, gid=gid)
    return ax.fill_between(x, lo, hi, color=colour, alpha=kw.pop("alpha", 0.18), lw=0, gid=gid, **kw)


def band_caption(table, column: str) -> str:
    """The sentence a figure's caption gets when ``table`` has the band of ``column``."""
    if not has_band(table, column):
        return ""
    n = table["uncertainty_samples"].to_numpy(float) if "uncertainty_samples" in table else np.array([np.nan])
    return (f" Shaded: the 5-95 % uncertainty band over {int(np.nanmin(n))}-{int(np.nanmax(n))} samples of the muscle "
            "properties (mean over subjects of each subject's band; priors in the Method section).")
