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
from musclemetab.study.runner import _next_ready, _unit_rows, unit_batches
from musclemetab.study.spec import best_start_study, load_study, warm_start_study
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


def test_the_best_start_switch_from_the_file_and_the_command_line(example):
    """``[solver] best_start = true`` and ``musclemetab run --best-start`` (and ``demo``) set it; the
    chain's units then have their source (as with warm starts) and a study without it keeps its keys;
    a value that is not true or false names the key."""
    from musclemetab.commands import build_parser
    from musclemetab.commands.run import apply_start_arguments

    ten, gen = Unit("sub1", "normal", "effort-ten"), Unit("sub1", "normal", "effort-gen")
    study = _study(example, ["effort-gen", "effort-ten"], solver={"best_start": True})
    assert study.best_start and not study.warm_start and ten.warm_source(study) == gen
    assert "best_start" not in study.settings.get("solver", {})  # not an IPOPT setting
    plain = _study(example, ["effort-gen", "effort-ten"])
    assert not plain.best_start and unit_key(plain, gen) == unit_key(study, gen)
    for command in ("run", "demo"):
        args = build_parser(command).parse_args([command, "study.toml", "--best-start"] if command == "run"
                                                else [command, "--best-start"])
        assert apply_start_arguments(plain, args).best_start
        assert not apply_start_arguments(plain, build_parser(command).parse_args(
            [command, "study.toml"] if command == "run" else [command])).best_start
    with pytest.raises(OptionError, match=r"\[solver\]: 'best_start' must be true or false"):
        _study(example, ["effort-gen"], solver={"best_start": "yes"})


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


def test_a_best_start_unit_keeps_the_lower_of_the_cold_and_warm_objectives(demo, tmp_path):
    """``[solver] best_start``: the demo's normal-speed EFFORT-TEN unit solved from both starts. Its
    cold solve is the demo's own (the same objective), the warm one starts from the demo's EFFORT-GEN
    solution; the unit keeps the lower objective and ``starts`` records both, and the other start's
    whole-body rate differences, which are those of the two solutions' whole_body.csv files. The
    switch is in the unit key (a cold or warm unit is not taken for it)."""
    out, _ = demo
    unit, gen = Unit("sub1", "normal", "effort-ten"), Unit("sub1", "normal", "effort-gen")
    cold_summary = json.loads((out / unit.folder / "summary.json").read_text())
    loaded = load_study(out / "study.toml", output=tmp_path)
    best = best_start_study(loaded, True)
    assert best.best_start and not best.warm_start and unit.warm_source(best) == gen
    key = unit_key(best, unit, None, unit_key(best, gen))
    warm_study = warm_start_study(loaded, True)
    assert key != unit_key(warm_study, unit, None, unit_key(warm_study, gen)) != unit_key(loaded, unit)
    rec = execute_unit(best, unit, key, None, str(out / gen.folder))
    assert rec["status"] == "ok", rec.get("error")
    starts = rec["starts"]
    assert starts["cold"]["objective"] == pytest.approx(cold_summary["objective"], rel=1e-9)
    warm = starts["warm from effort-gen"]
    assert warm["status"] == "Solve_Succeeded"
    kept = min(("cold", "warm from effort-gen"), key=lambda k: starts[k]["objective"])
    assert rec["start"] == starts["kept"] == kept
    summary = json.loads((tmp_path / unit.folder / "summary.json").read_text())
    assert summary["objective"] == pytest.approx(starts[kept]["objective"], rel=1e-12)
    other = "cold" if kept != "cold" else "warm from effort-gen"
    assert starts["other_objective_difference"] == pytest.approx(
        starts[other]["objective"] / starts[kept]["objective"] - 1, abs=1e-15)
    mine = pd.read_csv(tmp_path / unit.folder / "whole_body.csv").set_index("model")["whole_body_W_per_kg"]
    cold_wb = pd.read_csv(out / unit.folder / "whole_body.csv").set_index("model")["whole_body_W_per_kg"]
    diff = starts["other_whole_body_difference"]
    if kept == "cold":
        assert mine.to_numpy() == pytest.approx(cold_wb.to_numpy(), rel=1e-9)
    else:
        for model in mine.index:
            assert diff[model] == pytest.approx(cold_wb[model] / mine[model] - 1, abs=1e-9)
    assert starts["largest_rate_difference"] == max(abs(v) for v in diff.values()) < RATE_RTOL  # one optimum here
    rows = _unit_rows(tmp_path / unit.folder, unit, rec).set_index("model")  # the unit's rows of results.csv
    assert rows["solve_start"].tolist() == [kept] * len(rows)
    assert rows["other_start_rate_difference"].to_dict() == diff


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
    sol, start, other = _chain_solve(solve, Unit("sub1", "slow", "effort-gen"), out / "units/sub1/slow/effort-gen",
                                     times, both=True)
    assert calls == [True, False]
    assert start.startswith("cold: the solution of effort-gen does not fit this problem")
    assert "mesh" in start
    assert sol.success and sol.record.initial_guess == "static optimisation (rigid tendons)" and other is None

    calls.clear()
    missing = out / "units/sub1/normal/no-such-unit"
    sol, start, other = _chain_solve(solve, Unit("sub1", "normal", "effort-gen"), missing, times)
    assert calls == [False] and start == "cold: effort-gen did not succeed, no warm start" and other is None
