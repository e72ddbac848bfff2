"""The report's uncertainty bands: the shaded bands of the figures, the per-muscle table with
intervals and the method text with the priors (``docs/uncertainty.md``).

A study run with uncertainty samples (:mod:`musclemetab.study.uncertainty`) has ``<rate>_p05``,
``_p50`` and ``_p95`` columns beside its rates; without them nothing here draws or writes anything.
"""

from __future__ import annotations

import numpy as np

__all__ = ["has_band", "shade_band", "band_caption", "uncertainty_section"]

#: muscles of each model in the table with intervals
TOP_MUSCLES = 10


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


def _cell(row, column: str, digits: int = 3) -> str:
    value = float(row[column])
    if not np.isfinite(value):
        return "–"
    lo, hi = float(row.get(f"{column}_p05", np.nan)), float(row.get(f"{column}_p95", np.nan))
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return f"{value:.{digits}f}"
    return f"{value:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"


def uncertainty_section(study) -> dict | None:
    """The report's uncertainty section, or ``None`` for a study without bands: the samples and
    seed, the priors (a table), the whole-body rates and the top muscles of each model with their
    5-95 % intervals."""
    from ..uncertainty import GLOBAL_PARAMETERS, read_priors
    from .figures import main_workflow, trial_order
    from .page import Table

    ok = study.ok
    if ok.empty or not has_band(ok, "whole_body_W_per_kg"):
        return None
    settings = study.settings.get("uncertainty") if isinstance(study.settings.get("uncertainty"), dict) else {}
    priors_path = settings.get("priors")
    note = None
    try:
        priors = read_priors(priors_path)
    except Exception as exc:  # noqa: BLE001 - a moved priors file: the package's table is shown, said so
        priors, note = read_priors(), f"the study's priors file could not be read ({exc}); the package's are shown"
    rows = [[r.parameter, r.distribution, f"{r.spread:g}",
             r.muscle or ("the subject" if r.parameter in GLOBAL_PARAMETERS else "every muscle"), r.source]
            for r in priors.rows]
    priors_table = Table([[("parameter", 1), ("distribution", 1), ("spread", 1), ("muscle", 1), ("source", 1)]],
                         rows, 1, "settings")
    trials = trial_order(ok)
    wb_rows = []
    for (wf, model), d in ok.groupby([ok["workflow"].astype(str), ok["model"].astype(str)], sort=False):
        d = d.groupby(d["trial"].astype(str)).mean(numeric_only=True)
        wb_rows.append([wf, model] + [_cell(d.loc[t], "whole_body_W_per_kg") if t in d.index else "–" for t in trials])
    whole_body = Table([[("workflow", 1), ("model", 1)] + [(t, 1) for t in trials]], wb_rows, 2, "results")
    muscles = {}
    pm = study.read_per_muscle()
    if pm is not None and "muscle_W_per_kg_p05" in pm.columns:
        wf = main_workflow(list(dict.fromkeys(pm["workflow"].astype(str))))
        d = pm[pm["workflow"].astype(str) == wf]
        cols = ["muscle_W_per_kg", "muscle_W_per_kg_p05", "muscle_W_per_kg_p95"]
        for m in [m for m in study.models() if m in set(d["model"].astype(str))]:
            dm = d[d["model"].astype(str) == m].groupby(["muscle", "trial"])[cols].mean()
            ts = [t for t in trials if t in set(dm.index.get_level_values("trial"))]
            order = dm["muscle_W_per_kg"].groupby("muscle").mean().sort_values(ascending=False).index[:TOP_MUSCLES]
            body = [[mu] + [_cell(dm.loc[(mu, t)], "muscle_W_per_kg") if (mu, t) in dm.index else "–" for t in ts]
                    for mu in order]
            muscles[m] = Table([[("muscle", 1)] + [(t, 1) for t in ts]], body, 1, "results")
        muscles_workflow = wf
    else:
        muscles_workflow = None
    n = ok["uncertainty_samples"].to_numpy(float) if "uncertainty_samples" in ok else np.array([np.nan])
    return {"samples": int(settings.get("samples", 0) or np.nanmax(n)), "seed": settings.get("seed"),
            "converged": f"{int(np.nanmin(n))}-{int(np.nanmax(n))}" if np.nanmin(n) != np.nanmax(n) else f"{int(n[0])}",
            "priors": priors_table, "priors_source": priors.source, "note": note, "whole_body": whole_body,
            "muscles": muscles, "muscles_workflow": muscles_workflow, "top": TOP_MUSCLES}
