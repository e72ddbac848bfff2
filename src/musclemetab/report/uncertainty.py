"""The report's uncertainty bands in the figures: the shaded bands and their captions
(``docs/uncertainty.md``; the tables with intervals and the priors: :mod:`.page`).

A study run with uncertainty samples (:mod:`musclemetab.study.uncertainty`) has ``<rate>_p05``,
``_p50`` and ``_p95`` columns beside its rates; without them nothing here draws or writes anything.
"""

from __future__ import annotations

import numpy as np

__all__ = ["has_band", "shade_band", "band_caption", "samples_text", "band_rows", "flagged_rows", "BAND_HEADER",
           "FLAGGED_HEADER"]

#: the columns of the report's table of each whole-body band with its nominal
BAND_HEADER = ("subject", "trial", "workflow", "model", "nominal (W/kg)", "band (W/kg)", "band is", "samples used",
               "rejected", "nominal's quantile", "where the nominal lies", "parameters making the width (SD, W/kg)")
#: the columns of the report's table of the samples left out of (or kept in) the bands
FLAGGED_HEADER = ("subject", "trial", "workflow", "models", "flagged samples (sample: flags)")


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


def samples_text(table) -> str:
    """``"16 samples"``, ``"9-14 samples"``: the plausible samples behind the bands of ``table``."""
    n = table["uncertainty_samples"].to_numpy(float) if "uncertainty_samples" in table else np.array([np.nan])
    n = n[np.isfinite(n)]
    if not n.size:
        return "the samples"
    lo, hi = int(n.min()), int(n.max())
    return f"{lo} sample{'s' if lo != 1 else ''}" if lo == hi else f"{lo}-{hi} samples"


def _kind_text(table) -> str:
    kinds = list(dict.fromkeys(table["uncertainty_band"].dropna().astype(str))) if "uncertainty_band" in table else []
    if not kinds or kinds == ["5-95 %"]:
        return "5-95 % uncertainty band"
    if all(k.startswith("min-max") for k in kinds):
        return "min-max uncertainty band (too few samples for 5 and 95 % quantiles)"
    return "uncertainty band (5-95 % quantiles, min-max where too few samples)"


def band_caption(table, column: str) -> str:
    """The sentence a figure's caption gets when ``table`` has the band of ``column``."""
    if not has_band(table, column):
        return ""
    kept = ("uncertainty_flagged_samples" in table
            and table["uncertainty_flagged_samples"].map(_text).str.contains("(kept)", regex=False).any())
    return (f" Shaded: the {_kind_text(table)} over {samples_text(table)} of the muscle properties per unit, "
            f"samples with a plausibility flag {'kept (keep_flagged)' if kept else 'left out'} (mean over subjects "
            "of each subject's band; priors in the Method section).")


def _text(value) -> str:
    """A table cell's text (``""`` for an empty CSV cell, read back as NaN)."""
    import pandas as pd

    return "" if value is None or (not isinstance(value, str) and pd.isna(value)) else str(value)


def _number(value, digits: int = 3) -> str:
    value = float(value)
    return f"{value:.{digits}f}" if np.isfinite(value) else "–"


def band_rows(ok) -> list[list[str]]:
    """One row per results row (:data:`BAND_HEADER`): the whole-body rate, its band and what it is
    made of, where the nominal lies (quantile, in words) and the parameters that make the width."""
    col = "whole_body_W_per_kg"
    if not has_band(ok, col):
        return []
    rows = []
    for _, r in ok.iterrows():
        q = float(r.get(f"{col}_nominal_quantile", np.nan))
        rows.append([str(r["subject"]), str(r["trial"]), str(r["workflow"]), str(r["model"]), _number(r[col]),
                     f"[{_number(r[f'{col}_p05'])}, {_number(r[f'{col}_p95'])}]", _text(r.get("uncertainty_band")),
                     str(int(r.get("uncertainty_samples", 0))), str(int(r.get("uncertainty_rejected", 0) or 0)),
                     f"{100 * q:.0f} %" if np.isfinite(q) else "–", _text(r.get("uncertainty_note")),
                     (_text(r.get("uncertainty_top_parameters")) or "–") if "uncertainty_top_parameters" in ok
                     else "– (run with --sensitivity)"])
    return rows


def flagged_rows(ok) -> list[list[str]]:
    """The samples with a plausibility flag (:data:`FLAGGED_HEADER`), one row per subject, trial,
    workflow and list (the models sharing it together)."""
    if "uncertainty_flagged_samples" not in ok:
        return []
    text = ok["uncertainty_flagged_samples"].map(_text)
    d = ok[text != ""]
    rows = []
    for key, g in d.groupby(["subject", "trial", "workflow", text[text != ""]], sort=False):
        rows.append([str(key[0]), str(key[1]), str(key[2]), ", ".join(g["model"].astype(str)), key[3]])
    return rows
