"""Structural spread: how much one result moves with the choice of energy model, of workflow
and with the data (``docs/uncertainty.md``, "Structural spread").

From a study's results table (``results.csv``: one row per subject, trial, workflow and
energy model), for each subject and trial and each quantity (the whole-body rate with basal
heat, ``whole_body_W_per_kg``, and each muscle group's part of the rate without basal heat,
``whole_body_no_basal_W_per_kg x share_<G>_pct / 100``, W per kg of body mass, both legs):

``range_across_models_W_per_kg``
    max - min over the energy models, for each workflow, averaged over the workflows;
``range_across_workflows_W_per_kg``
    max - min over the workflows (EFFORT-GEN/CAL/TEN, EMG modes, energy objective: every
    ``workflow`` label the study ran), for each model, averaged over the models;
``range_across_trials_W_per_kg``
    max - min over the subject's trials (the data: speeds, conditions), for each model and
    workflow, averaged over them; the same on every trial of the subject;
``largest``
    which of the three is largest: ``energy model``, ``workflow`` or ``trials`` (a range that
    needs two of a kind the study does not have is empty and left out).

Where ``largest`` is ``energy model``, the choice of model moves the result more than the
workflows and the data do. Pure pandas on the results table; the report draws it
(:func:`musclemetab.report.spread_figure.spread_figure`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import MissingColumnError
from ..messages import name_list

__all__ = ["WHOLE_BODY", "SPREAD_COLUMNS", "spread_values", "structural_spread", "read_results"]

#: the quantity name of the whole-body rate (with basal heat)
WHOLE_BODY = "whole_body_W_per_kg"
#: the columns of :func:`structural_spread`
SPREAD_COLUMNS = ("subject", "trial", "quantity", "n_models", "n_workflows", "mean_W_per_kg", "min_W_per_kg",
                  "max_W_per_kg", "range_across_models_W_per_kg", "range_across_workflows_W_per_kg",
                  "range_across_trials_W_per_kg", "largest")
_KEYS = ("subject", "trial", "workflow", "model")


def spread_values(results):
    """The values the spread is of: a long table ``subject, trial, workflow, model, quantity,
    value_W_per_kg`` from the successful rows of ``results`` (quantities: :data:`WHOLE_BODY`
    and ``group_<G>_W_per_kg`` for each ``share_<G>_pct`` column)."""
    import pandas as pd

    missing = [c for c in (*_KEYS, WHOLE_BODY) if c not in results.columns]
    if missing:
        raise MissingColumnError(f"the results table has no column {name_list(missing)}; give a study's results.csv")
    ok = results[results["status"].astype(str) == "ok"] if "status" in results.columns else results
    keys = {k: ok[k].astype(str).to_numpy() for k in _KEYS}
    frames = [pd.DataFrame({**keys, "quantity": WHOLE_BODY, "value_W_per_kg": ok[WHOLE_BODY].to_numpy(float)})]
    shares = [c for c in ok.columns if c.startswith("share_") and c.endswith("_pct")]
    if shares and "whole_body_no_basal_W_per_kg" in ok.columns:
        nb = ok["whole_body_no_basal_W_per_kg"].to_numpy(float)
        for c in shares:
            frames.append(pd.DataFrame({**keys, "quantity": f"group_{c[len('share_'):-len('_pct')]}_W_per_kg",
                                        "value_W_per_kg": nb * ok[c].to_numpy(float) / 100.0}))
    return pd.concat(frames, ignore_index=True)


def _mean_ranges(values, by, within, across):
    """For each group of ``by``: the mean over its groups of ``within`` of (max - min over
    ``across``), groups with two or more values of ``across`` only; a group of ``by`` without
    such groups is absent (NaN when looked up). All groups at once: one pass over the table."""
    g = values.groupby([*by, *within], sort=False)
    r = (g["value_W_per_kg"].max() - g["value_W_per_kg"].min())[g[across].nunique() >= 2]
    return r.groupby(level=list(range(len(by))), sort=False).mean()


def structural_spread(results):
    """One row per subject, trial and quantity (:data:`SPREAD_COLUMNS`; module docstring),
    in the order of the results table, the whole-body rate first."""
    import pandas as pd

    values = spread_values(results)
    keys = ["subject", "trial", "quantity"]
    g = values.groupby(keys, sort=False)
    mean = g["value_W_per_kg"].mean()  # its index: the groups in the order of the table
    df = pd.DataFrame({
        "n_models": g["model"].nunique(), "n_workflows": g["workflow"].nunique(),
        "mean_W_per_kg": mean, "min_W_per_kg": g["value_W_per_kg"].min(), "max_W_per_kg": g["value_W_per_kg"].max(),
        "range_across_models_W_per_kg": _mean_ranges(values, keys, ["workflow"], "model"),
        "range_across_workflows_W_per_kg": _mean_ranges(values, keys, ["model"], "workflow"),
    }, index=mean.index)
    trials = _mean_ranges(values, ["subject", "quantity"], ["workflow", "model"], "trial")
    df["range_across_trials_W_per_kg"] = trials.reindex(
        pd.MultiIndex.from_arrays([df.index.get_level_values("subject"), df.index.get_level_values("quantity")])
    ).to_numpy()
    df = df.reset_index()
    named = {"energy model": "range_across_models_W_per_kg", "workflow": "range_across_workflows_W_per_kg",
             "trials": "range_across_trials_W_per_kg"}
    largest = []
    for ranges in zip(*(df[c].to_numpy(float) for c in named.values())):
        known = {k: r for k, r in zip(named, ranges) if np.isfinite(r)}
        largest.append(max(known, key=known.get) if known else "")
    df["largest"] = largest
    df = df.astype({"n_models": int, "n_workflows": int})[list(SPREAD_COLUMNS)]
    order = {q: i for i, q in enumerate(dict.fromkeys([WHOLE_BODY, *values["quantity"]]))}
    first = {k: i for i, k in enumerate(dict.fromkeys(zip(df["subject"], df["trial"])))}
    df["_o"] = [first[(s, t)] * 1000 + order[q] for s, t, q in zip(df["subject"], df["trial"], df["quantity"])]
    return df.sort_values("_o", kind="stable").drop(columns="_o").reset_index(drop=True)


def read_results(study_dir: str | os.PathLike):
    """The results table of a study folder (``results.csv``)."""
    import pandas as pd

    from ..errors import InputFileError
    from ..study_layout import RESULTS_CSV

    path = Path(study_dir) / RESULTS_CSV
    if not path.is_file():
        raise InputFileError(f"{path}: no results table; give a study folder written by musclemetab run")
    return pd.read_csv(path)
