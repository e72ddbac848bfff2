"""Structural spread (``musclemetab.analysis.spread``): ranges across the energy models, the
workflows and the trials, worked by hand on a small table and checked against the demo study's
own ``results.csv``, and its figure and table in the study's report."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from musclemetab.analysis.spread import SPREAD_COLUMNS, WHOLE_BODY, structural_spread


def _table():
    """Two trials x two workflows x two models of one subject, and a failed row."""
    rows = []
    values = {("slow", "effort-gen", "UM10"): 5.0, ("slow", "effort-gen", "BH04"): 3.0,
              ("slow", "effort-ten", "UM10"): 5.5, ("slow", "effort-ten", "BH04"): 3.2,
              ("fast", "effort-gen", "UM10"): 9.0, ("fast", "effort-gen", "BH04"): 6.0,
              ("fast", "effort-ten", "UM10"): 8.0, ("fast", "effort-ten", "BH04"): 6.4}
    for (trial, wf, model), v in values.items():
        rows.append({"subject": "s1", "trial": trial, "workflow": wf, "model": model, "status": "ok",
                     "whole_body_W_per_kg": v, "whole_body_no_basal_W_per_kg": v - 1.2,
                     "share_PF_pct": 50.0 if model == "UM10" else 25.0, "share_KE_pct": 10.0})
    rows.append({"subject": "s1", "trial": "slow", "workflow": "emg-ten", "model": "UM10", "status": "failed",
                 "whole_body_W_per_kg": 100.0})
    return pd.DataFrame(rows)


def test_ranges_worked_by_hand():
    s = structural_spread(_table())
    assert tuple(s.columns) == SPREAD_COLUMNS
    assert list(s.quantity[:3]) == [WHOLE_BODY, "group_PF_W_per_kg", "group_KE_W_per_kg"]
    slow = s[(s.trial == "slow") & (s.quantity == WHOLE_BODY)].iloc[0]
    # models: gen 5.0-3.0 = 2.0, ten 5.5-3.2 = 2.3 -> 2.15; workflows: UM10 0.5, BH04 0.2 -> 0.35
    # trials: (gen UM10 4.0, gen BH04 3.0, ten UM10 2.5, ten BH04 3.2) -> 3.175; the failed row left out
    assert slow.range_across_models_W_per_kg == pytest.approx(2.15)
    assert slow.range_across_workflows_W_per_kg == pytest.approx(0.35)
    assert slow.range_across_trials_W_per_kg == pytest.approx(3.175)
    assert slow.largest == "trials" and slow.n_workflows == 2 and slow.max_W_per_kg == 5.5
    assert slow.mean_W_per_kg == pytest.approx((5.0 + 3.0 + 5.5 + 3.2) / 4)
    fast = s[(s.trial == "fast") & (s.quantity == WHOLE_BODY)].iloc[0]
    assert fast.range_across_models_W_per_kg == pytest.approx((3.0 + 1.6) / 2) and fast.largest == "trials"
    # a group's part: (whole body without basal) x share; fast, effort-gen: UM10 7.8 x 0.5, BH04 4.8 x 0.25
    pf = s[(s.trial == "fast") & (s.quantity == "group_PF_W_per_kg")].iloc[0]
    assert pf.range_across_models_W_per_kg == pytest.approx(((7.8 * 0.5 - 4.8 * 0.25) + (6.8 * 0.5 - 5.2 * 0.25)) / 2)
    # one workflow, one trial: those ranges are empty and the model's range is the largest
    one = structural_spread(_table().query("workflow == 'effort-gen' and trial == 'slow'"))
    row = one[one.quantity == WHOLE_BODY].iloc[0]
    assert np.isnan(row.range_across_workflows_W_per_kg) and np.isnan(row.range_across_trials_W_per_kg)
    assert row.largest == "energy model" and row.range_across_models_W_per_kg == pytest.approx(2.0)


def _by_hand(rows, within, across):
    """Mean over the groups of ``within`` of max - min over ``across`` (plain loops)."""
    groups = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in within), {}).setdefault(r[across], r["value"])
    spans = [max(g.values()) - min(g.values()) for g in groups.values() if len(g) >= 2]
    return sum(spans) / len(spans) if spans else float("nan")


def test_spread_of_the_demo_study_and_its_report(demo):
    """Against the numbers of the demo study's results.csv (plain loops over its rows), and the
    report the demo wrote: the figure and the table with those numbers."""
    out, results = demo
    spread = structural_spread(results)
    ok = results[results["status"] == "ok"]
    assert ok["workflow"].nunique() >= 2 and ok["model"].nunique() >= 2 and ok["trial"].nunique() >= 2
    html = (out / "report.html").read_text(encoding="utf-8")
    assert 'id="table-structural-spread"' in html and (out / "figures" / "structural_spread.png").is_file()
    for quantity, value in ((WHOLE_BODY, lambda r: r["whole_body_W_per_kg"]),
                            ("group_PF_W_per_kg", lambda r: r["whole_body_no_basal_W_per_kg"] * r["share_PF_pct"] / 100)):
        every = [{"trial": r["trial"], "workflow": r["workflow"], "model": r["model"], "value": value(r)}
                 for _, r in ok.iterrows()]
        trials_range = _by_hand(every, ("workflow", "model"), "trial")
        for trial in ok["trial"].unique():
            rows = [r for r in every if r["trial"] == trial]
            got = spread[(spread.trial == trial) & (spread.quantity == quantity)].iloc[0]
            assert got.range_across_models_W_per_kg == pytest.approx(_by_hand(rows, ("workflow",), "model"), rel=1e-12)
            assert got.range_across_workflows_W_per_kg == pytest.approx(_by_hand(rows, ("model",), "workflow"),
                                                                        rel=1e-12)
            assert got.range_across_trials_W_per_kg == pytest.approx(trials_range, rel=1e-12)
            assert got.mean_W_per_kg == pytest.approx(np.mean([r["value"] for r in rows]), rel=1e-12)
            if quantity == WHOLE_BODY:
                assert f"<td>{got.range_across_models_W_per_kg:.2f}</td>" in html
