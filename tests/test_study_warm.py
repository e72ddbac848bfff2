"""Warm-started chains of a study: a trial's EFFORT-TEN (or EFFORT-CAL) solve starts from the
solution of the workflow before it, agrees with the cold solve within docs/study.md's tolerance,
and falls back to a cold solve when the warm start cannot be used.

Warm starts are opt-in (``[solver] warm_start = true``, ``--warm-start``). The demo (``demo``
fixture, run once per test run) is cold; one of its EFFORT-TEN units is run again warm-started from
the demo's EFFORT-GEN solution and compared; the whole comparison on both shared subjects and every
unit is ``python benchmarks/study.py --warm``.
"""

from __future__ import annotations

import json

import pandas as pd
import pytest

from musclemetab.errors import OptionError
from musclemetab.study import study_from_dict
from musclemetab.study.runner import _next_ready, unit_batches
from musclemetab.study.spec import load_study, warm_start_study
from musclemetab.study.units import Unit, _chain_solve, execute_unit, unit_key

#: docs/study.md, "Warm-started chains": objectives relative, rates relative, shares in points
OBJECTIVE_RTOL, RATE_RTOL, SHARE_ATOL_PCT = 1e-4, 1e-3, 0.1


def _study(example, workflows, solver=None, **subject):
    data = {
        "name": "s", "workflows": list(workflows), "models": ["UM10"],
        "subjects": [{"name": "sub1", "model": str(example.model), "body_mass_kg": 70.0, "height_m": 1.7, **subject,
                      "trials": [{"name": t, "ik": str(example.ik[t]), "id": str(example.id[t])}
                                 for t in ("slow", "normal")]}],
    }
    if solver is not None:
        data["solver"] = solver
    return study_from_dict(data, base="/")


def test_chain_order_keys_and_the_switch(example):
    passive = str(example.passive_moments_mat)
    study = _study(example, ["effort-ten", "effort-gen", "effort-cal"], solver={"warm_start": True}, passive=passive)
    gen, cal, ten = (Unit("sub1", "normal", w) for w in ("effort-gen", "effort-cal", "effort-ten"))
    # the chain's order is GEN -> CAL -> TEN whatever the file's order; without CAL, TEN starts from GEN
    assert study.warm_start and gen.warm_source(study) is None
    assert cal.warm_source(study) == gen and ten.warm_source(study) == cal
    assert ten.warm_source(warm_start_study(_study(example, ["effort-gen", "effort-ten"]), True)) == gen
    # cold is the default; a cold study's keys are those of a study without the key
    plain = _study(example, ["effort-ten", "effort-gen", "effort-cal"], passive=passive)
    cold = warm_start_study(study, False)
    assert not plain.warm_start and ten.warm_source(plain) is None and ten.warm_source(cold) is None
    assert unit_key(plain, ten) == unit_key(cold, ten) != unit_key(study, ten, None, unit_key(study, cal))
    assert unit_key(study, gen) == unit_key(plain, gen)  # the chain's first unit starts cold either way
    assert "warm_start" not in study.settings.get("solver", {})  # not an IPOPT setting
    with pytest.raises(OptionError, match=r"\[solver\]: 'warm_start' must be true or false"):
        _study(example, ["effort-gen"], solver={"warm_start": "yes"})


def test_a_unit_waits_for_the_solution_it_starts_from(example):
    study = _study(example, ["effort-gen", "effort-ten"], solver={"warm_start": True})
    (batch,) = unit_batches(study)
    jobs = [(u, "", None, None, u.warm_source(study)) for u in batch]
    waiting = {u for u, *_ in jobs}
    assert _next_ready(jobs[2:], waiting) is None  # both EFFORT-TEN units wait
    waiting.discard(batch[1])  # normal's EFFORT-GEN finished: normal's EFFORT-TEN starts
    assert jobs[2:][_next_ready(jobs[2:], waiting)][0] == Unit("sub1", "normal", "effort-ten")
    assert _next_ready(jobs[:2], waiting) == 0  # a unit with no source is always ready
    # a study file listing EFFORT-TEN first: its units still come after the EFFORT-GEN units they start from
    batches = unit_batches(_study(example, ["effort-ten", "effort-gen"], solver={"warm_start": True}))
    assert [u.workflow for u in batches[0]] == ["effort-gen", "effort-gen", "effort-ten", "effort-ten"]


@pytest.mark.slow
@pytest.mark.opensim
def test_warm_unit_agrees_with_the_demo_cold_unit(demo, tmp_path):
    """The demo's normal-speed EFFORT-TEN unit (cold, the default) against the same unit run again,
    warm-started from the demo's EFFORT-GEN solution (its own folder, same study settings):
    objective, every whole-body rate and the group shares within the stated tolerance; each record
    says how it started."""
    out, table = demo
    assert set(table.solve_start) == {"cold"}
    unit, gen = Unit("sub1", "normal", "effort-ten"), Unit("sub1", "normal", "effort-gen")
    cold_summary = json.loads((out / unit.folder / "summary.json").read_text())
    assert cold_summary["initial_guess"] == "static optimisation (rigid tendons)"

    warm_study = warm_start_study(load_study(out / "study.toml", output=tmp_path), True)
    assert unit.warm_source(warm_study) == gen
    key = unit_key(warm_study, unit, None, unit_key(warm_study, gen))
    warm_rec = execute_unit(warm_study, unit, key, None, str(out / gen.folder))
    assert warm_rec["status"] == "ok", warm_rec.get("error")
    assert warm_rec["start"] == "warm from effort-gen"
    warm_summary = json.loads((tmp_path / unit.folder / "summary.json").read_text())
    assert warm_summary["initial_guess"].lower().startswith("warm start from effort-gen")
    assert warm_summary["objective"] == pytest.approx(cold_summary["objective"], rel=OBJECTIVE_RTOL)
    # both at the optimum (the default stop); with it a warm start saves no iterations (docs/study.md)
    assert warm_summary["solver_options"]["stop"] == cold_summary["solver_options"]["stop"] == "optimum"

    warm_wb = pd.read_csv(tmp_path / unit.folder / "whole_body.csv").set_index("model")
    cold_wb = pd.read_csv(out / unit.folder / "whole_body.csv").set_index("model")
    for column in ("whole_body_W_per_kg", "whole_body_no_basal_W_per_kg", "leg_muscles_W"):
        assert warm_wb[column].to_numpy() == pytest.approx(cold_wb[column].to_numpy(), rel=RATE_RTOL), column
    warm_an = pd.read_csv(tmp_path / unit.folder / "analysis.csv").set_index("model")
    cold_an = pd.read_csv(out / unit.folder / "analysis.csv").set_index("model")
    shares = [c for c in warm_an.columns if c.endswith("_pct")]
    assert shares
    assert (warm_an[shares] - cold_an[shares]).abs().to_numpy().max() <= SHARE_ATOL_PCT


@pytest.mark.slow
@pytest.mark.opensim
def test_a_warm_start_that_does_not_fit_falls_back_to_cold(demo, example):
    """A source solution over another mesh (the slow trial's, offered to the normal trial) is not
    used: the unit solves cold (the demo's own solve) and the record says why;
    a source unit that did not succeed gives a cold start too."""
    from musclemetab.redundancy.run import solve_files

    out, _ = demo
    calls = []

    def solve(warm_start=None):
        calls.append(warm_start is not None)
        kwargs = {"warm_start": warm_start} if warm_start is not None else {}
        return solve_files(example.model, example.ik["normal"], example.id["normal"], "effort-ten", side="r",
                           passive=example.passive_moments_mat, tendon_stiffness="example", **kwargs)

    times = {}
    sol, start = _chain_solve(solve, Unit("sub1", "slow", "effort-gen"), out / "units/sub1/slow/effort-gen", times)
    assert calls == [True, False]
    assert start.startswith("cold: the solution of effort-gen does not fit this problem")
    assert "mesh" in start
    assert sol.success and sol.record.initial_guess == "static optimisation (rigid tendons)"

    calls.clear()
    missing = out / "units/sub1/normal/no-such-unit"
    sol, start = _chain_solve(solve, Unit("sub1", "normal", "effort-gen"), missing, times)
    assert calls == [False] and start == "cold: effort-gen did not succeed, no warm start"
