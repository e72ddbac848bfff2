"""The report's sensitivity ranking: the muscle parameters that move the whole-body rate most.

A study run with ``[uncertainty] sensitivity = true`` (``--sensitivity``) has a ``sensitivity.csv``
in the folder of each effort trial unit (one per leg; columns in ``docs/data_dictionary.md``):
the derivative of each rate per log of each muscle parameter at the polished optimum, by the
implicit-function theorem on the optimality conditions (``docs/uncertainty.md``, Sensitivities).
:func:`sensitivity_section` gives the report's section from them: per unit a ranked table of the
whole-body rows and one figure, the largest changes per 1 % of the parameter under one model;
without such files it gives ``None`` and the report has no such section.
"""

from __future__ import annotations

import base64
import io

import numpy as np

from ..errors import InputFileError
from ..io.csvfile import read_csv_file
from ..messages import name_list
from ..redundancy.sensitivity import SENSITIVITY_COLUMNS, SENSITIVITY_CSV

__all__ = ["HEADER", "TOP_TABLE", "TOP_FIGURE", "FIGURE_MODEL", "unit_sensitivities", "whole_body_ranking",
           "sensitivity_figure", "sensitivity_section"]

#: Parameters of each model in a unit's ranked table.
TOP_TABLE = 10
#: Bars of the figure.
TOP_FIGURE = 15
#: The model of the figure when the study has it (Umberger 2010), else the first model shown.
FIGURE_MODEL = "UM10"
_WHOLE_BODY = "whole_body"
#: The columns of a unit's ranked table.
HEADER = ("model", "rank", "parameter", "muscle", "value (SI)", "change per 1 % (W/kg)",
          "change per 1 % (% of the rate)")


def unit_sensitivities(study) -> list[tuple[str, object]]:
    """``(label, table)`` of every ``sensitivity.csv`` in the unit folders of the study's results
    (a :class:`~.folder.StudyFolder`), in the order of the results; ``label``: subject / trial /
    workflow (and leg). Raises :class:`InputFileError` naming a file that lacks the columns."""
    out = []
    for (subject, trial, workflow), row in study.units():
        for leg, folder in study.leg_folders(row).items():
            path = folder / SENSITIVITY_CSV
            if not path.is_file():
                continue
            table = read_csv_file(path, "write it again with musclemetab run --sensitivity (or metabolics --sensitivity)")
            missing = [c for c in SENSITIVITY_COLUMNS if c not in table.columns]
            if missing:
                raise InputFileError(f"{path}: no column(s) {name_list(missing)}; write it again with "
                                     "musclemetab run --sensitivity (or metabolics --sensitivity)")
            label = f"{subject} / {trial} / {workflow}" + (f" ({leg} leg)" if leg else "")
            out.append((label, table))
    return out


def whole_body_ranking(table, models, top: int | None = None):
    """The whole-body rows of a ``sensitivity.csv`` table for ``models`` (in that order, those
    present), each model's rows ranked by ``|d_rate_d_log_p|`` (largest first), ``top`` of each."""
    import pandas as pd

    d = table[table["rate"].astype(str) == _WHOLE_BODY]
    parts = []
    for m in models:
        dm = d[d["model"].astype(str) == m]
        dm = dm.iloc[np.argsort(-np.abs(dm["d_rate_d_log_p"].to_numpy(float)), kind="stable")]
        parts.append(dm.head(top) if top is not None else dm)
    return pd.concat(parts, ignore_index=True) if parts else d.iloc[:0]


def _models(study, tables) -> list[str]:
    present = set().union(*(set(t["model"].astype(str)) for _, t in tables))
    shown = [m for m in study.shown_models() if m in present]
    return shown or sorted(present)


def sensitivity_figure(label: str, ranking, model: str):
    """Horizontal bars of the change of the whole-body rate (W/kg) per 1 % of each parameter of
    ``ranking`` (:func:`whole_body_ranking` of one model), the largest on top."""
    from .figures import _new_figure

    names = [f"{p} {m}" for p, m in zip(ranking["parameter"].astype(str), ranking["muscle"].astype(str))]
    values = ranking["change_per_1pct"].to_numpy(float)
    fig = _new_figure(6.5, 0.9 + 0.28 * max(len(values), 1), left=1.9)
    ax = fig.add_subplot(1, 1, 1)
    y = np.arange(len(values))[::-1]
    ax.barh(y, values, color=["#b2182b" if v > 0 else "#2166ac" for v in values], gid="sensitivity-bars")
    ax.set_yticks(y, names, fontsize=8)
    ax.axvline(0.0, color="0.3", lw=0.8)
    ax.set_xlabel("change of the whole-body rate per 1 % of the parameter (W/kg)")
    ax.set_title(f"{label}: {model}", fontsize=9)
    return fig


def _png(fig) -> str:
    from .figures import _apply_layout

    _apply_layout(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def sensitivity_section(study) -> dict | None:
    """The report's sensitivity section, or ``None`` when no unit folder holds ``sensitivity.csv``:
    per unit its ``label`` and a ranked table, ``header`` and ``body`` rows (model, rank, parameter,
    muscle, value, change per 1 % in W/kg and in % of the rate; :mod:`.page` makes the HTML table),
    the figure of the first unit with :data:`FIGURE_MODEL` (a PNG, base64) and its caption."""
    tables = unit_sensitivities(study)
    if not tables:
        return None
    models = _models(study, tables)
    units = []
    for label, table in tables:
        ranked = whole_body_ranking(table, models, TOP_TABLE)
        body, last, rank = [], None, 0
        for r in ranked.itertuples(index=False):
            rank = rank + 1 if r.model == last else 1
            last = r.model
            rel = float(r.relative_change_per_1pct)
            body.append([str(r.model), f"{rank:d}", str(r.parameter), str(r.muscle), f"{float(r.parameter_value):.4g}",
                         f"{float(r.change_per_1pct):+.4f}", f"{100 * rel:+.3f}" if np.isfinite(rel) else "–"])
        units.append({"label": label, "header": HEADER, "body": body})
    model = FIGURE_MODEL if FIGURE_MODEL in models else models[0]
    label, table = next(((lb, t) for lb, t in tables if model in set(t["model"].astype(str))), tables[0])
    ranking = whole_body_ranking(table, [model], TOP_FIGURE)
    png = _png(sensitivity_figure(label, ranking, model))
    caption = (f"The {len(ranking)} muscle parameters that move the whole-body rate (W/kg, with basal heat) of {label} "
               f"most under {model}: its change when the parameter grows by 1 % (red: the rate rises, blue: it "
               "falls), the derivative per log of the parameter at the optimum divided by 100.")
    return {"units": units, "top": TOP_TABLE, "models": models, "figure": png, "caption": caption,
            "figure_model": model}
