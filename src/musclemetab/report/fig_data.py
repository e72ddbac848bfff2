"""Names, colours and the tables' helpers of the report's figures: the colour of each model, workflow and muscle group, the trials' order, the preferred trial, the main workflow, statistics by group.

Part of :mod:`musclemetab.report.figures`, which gathers the figure functions (see its text).
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Mapping, Sequence

import numpy as np

from ..analysis.groups import GROUP_NAMES as _GROUP_NAMES
from ..analysis.groups import GROUPS_WITH_OTHER, OTHER
from ..colours import GROUP_COLOURS as _GROUP_COLOURS
from ..colours import MODEL_COLOURS as _MODEL_COLOURS
from ..colours import WORKFLOW_COLOURS as _WORKFLOW_COLOURS
from ..errors import MusclemetabError, OptionError
from ..messages import name_list


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
