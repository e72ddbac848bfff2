"""Each stage after the solve gives the same numbers from objects and from folders.

``metabolics`` and ``analyse`` take a :class:`~musclemetab.redundancy.Solution` (or the
metabolic result of one) or the folder the solution is written to, in Python and on the command
line. The folder holds the solution to 12 significant digits (``solution.sto``) and the command
line's tables hold 10 (``*.csv``), hence the tolerances below; everything else (the nodes kept,
the gait cycle, the leg, the muscles, the ranks) must be equal. The example subject's normal
trial is solved once per test run (``tests/solve_memo.py``): with the gait cycle a solve over a
cycle records, and on both legs.
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pandas as pd
import pytest

from musclemetab.analysis import analyse, analyse_solution_folder, cycle_from_id_file
from musclemetab.commands import main
from musclemetab.geometry import compute_geometry
from musclemetab.metabolics.solution import (
    add_legs,
    metabolics_from_legs,
    metabolics_from_solution,
    solution_folders,
)

pytestmark = pytest.mark.opensim  # the analysis computes the trial's moment arms with OpenSim

SPEED = 1.3  # m/s, given: the cost of transport columns take it
#: the folder's solution.sto rounds every value to 12 significant digits
RTOL = 1e-9


def _same_rates(a, b) -> None:
    """Two metabolic results: the same nodes, muscles, models and (to :data:`RTOL`) rates."""
    assert a.muscles == b.muscles and a.models == b.models and a.side == b.side
    np.testing.assert_allclose(a.time_s, b.time_s, rtol=0, atol=1e-12)
    for model in a.models:
        for name, x in a.rates[model].components().items():
            y = b.rates[model].components()[name]
            np.testing.assert_allclose(x, y, rtol=RTOL, atol=RTOL * np.abs(y).max(), err_msg=f"{model} {name}")
        wa, wb = a.whole_body[model], b.whole_body[model]
        assert wa.mean_W_per_kg == pytest.approx(wb.mean_W_per_kg, rel=RTOL)
        assert wa.one_leg_mean_W == pytest.approx(wb.one_leg_mean_W, rel=RTOL)
        assert wa.duration_s == pytest.approx(wb.duration_s, rel=RTOL)


def _same_table(a: pd.DataFrame, b: pd.DataFrame, rtol: float = RTOL) -> None:
    """Two tables: the same columns and rows, text and whole numbers equal, floats to ``rtol``."""
    a, b = a.reset_index(drop=True), b.reset_index(drop=True)
    assert list(a.columns) == list(b.columns) and len(a) == len(b) > 0
    for col in a.columns:
        x, y = a[col], b[col]
        if pd.api.types.is_float_dtype(x) or pd.api.types.is_float_dtype(y):
            x, y = x.to_numpy(float), y.to_numpy(float)
            scale = np.nanmax(np.abs(y)) if np.isfinite(y).any() else 0.0
            np.testing.assert_allclose(x, y, rtol=rtol, atol=rtol * scale, err_msg=col)
        else:
            assert x.tolist() == y.tolist(), col


def _same_analysis(a, b) -> None:
    for name in ("whole_body", "summary", "timeseries", "per_muscle"):
        _same_table(getattr(a, name), getattr(b, name))
    assert a.side == b.side


@pytest.fixture(scope="module")
def cycle_r(example):
    """The right leg's gait cycle of the normal trial: the IK window less 0.05 s at each end
    (0.62-1.70 s), toe-off from the ankle moment."""
    return cycle_from_id_file(example.id["normal"], side="r", window_s=(0.57, 1.75))


@pytest.fixture(scope="module")
def with_cycle(example, cycle_r, tmp_path_factory):
    """The normal trial's solution with the gait cycle recorded as a solve over ``--cycle`` records it
    (``summary['window']['gait_cycle']``), and the folder it is written to."""
    from musclemetab.redundancy import solve_files

    solution = copy.deepcopy(solve_files(example.model, example.ik["normal"], example.id["normal"], "effort-gen"))
    window = dict(solution.record.window or {})
    window["gait_cycle"] = {"start_s": cycle_r.start_s, "toe_off_s": cycle_r.toe_off_s, "end_s": cycle_r.end_s}
    solution = dataclasses.replace(solution, record=solution.record.with_(window=window))
    folder = tmp_path_factory.mktemp("stage_paths") / "solution"
    solution.write(folder)
    return solution, folder


def test_metabolics_of_a_solution_with_a_recorded_cycle_from_object_and_folder(example, with_cycle, cycle_r):
    solution, folder = with_cycle
    kw = dict(models="all,LW05,MA68", speed_m_per_s=SPEED)
    from_object = metabolics_from_solution(solution, example.body_mass_kg, example.height_m, **kw)
    from_folder = metabolics_from_solution(folder, example.body_mass_kg, example.height_m, **kw)
    _same_rates(from_object, from_folder)
    # both kept the nodes inside the recorded cycle, 0.62 ... 1.70 s (109 nodes at 100 Hz), not the
    # study's default trimming of 5 nodes at the start and 6 at the end (0.62 ... 1.69 s)
    t = np.asarray(solution.time_s)
    inside = t[(t >= cycle_r.start_s - 1e-9) & (t <= cycle_r.end_s + 1e-9)]
    assert inside.size == 109 and t[5:-6].size == 108
    np.testing.assert_allclose(from_object.time_s, inside, rtol=0, atol=1e-12)
    assert from_object.side == "r"
    # the metabolic result handed on is the result itself
    legs = metabolics_from_legs(solution, example.body_mass_kg, example.height_m, **kw)
    assert list(legs) == ["r"]
    _same_rates(legs["r"], from_object)


def test_analysis_of_a_solution_with_a_recorded_cycle_from_objects_folders_and_commands(example, with_cycle,
                                                                                          cycle_r, tmp_path):
    solution, folder = with_cycle
    mass, height = example.body_mass_kg, example.height_m
    kw = dict(models="UM10,BH04,HO06", speed_m_per_s=SPEED)
    trial = (example.model, example.ik["normal"], cycle_r)
    from_object = analyse(solution, *trial, mass, height, **kw)
    from_folder = analyse(folder, *trial, mass, height, **kw)
    from_result = analyse(from_object.metabolics, *trial)  # the metabolic result, as it is
    _same_analysis(from_object, from_folder)
    _same_analysis(from_result, from_object)
    assert from_object.side == "r" and from_object.summary["cycle_end_s"].iloc[0] == cycle_r.end_s
    # the lower-level entry, given the geometry: the same from the object and the folder
    geometry = compute_geometry(example.model, example.ik["normal"], muscles=list(solution.muscles))
    by_geometry = [analyse_solution_folder(s, geometry, cycle_r, mass, height, **kw) for s in (solution, folder)]
    for a, b in zip(*by_geometry):
        _same_table(a, b)
    _same_table(by_geometry[0].summary, from_object.summary)
    # the commands, from the folders: the same tables (written to 10 significant digits)
    met, out = tmp_path / "met", tmp_path / "analyse"
    assert main(["metabolics", "--solution", str(folder), "--mass", str(mass), "--height", str(height),
                 "--models", "UM10,BH04,HO06", "--speed", str(SPEED), "--out", str(met)]) == 0
    assert main(["analyse", "--solution", str(folder), "--metabolics", str(met), "--model", str(example.model),
                 "--ik", str(example.ik["normal"]), "--id", str(example.id["normal"]), "--speed", str(SPEED),
                 "--out", str(out)]) == 0
    _same_table(pd.read_csv(met / "whole_body.csv"), from_object.whole_body, rtol=1e-9)
    for name in ("whole_body", "per_muscle"):
        _same_table(pd.read_csv(out / f"{name}.csv"), getattr(from_object, name))
    _same_table(pd.read_csv(out / "analysis.csv"), from_object.summary)
    _same_table(pd.read_csv(out / "timeseries.csv"), from_object.timeseries)


@pytest.fixture(scope="module")
def both_legs(example, tmp_path_factory):
    """``solve --side both`` of the normal trial: ``{side: Solution}`` and the parent of their
    folders ``r/`` and ``l/``."""
    from musclemetab.redundancy.run import solve_sides

    solutions = solve_sides(example.model, example.ik["normal"], example.id["normal"], "effort-gen")
    parent = tmp_path_factory.mktemp("stage_paths_both") / "both"
    for side, solution in solutions.items():
        solution.write(parent / side)
    return solutions, parent


def test_both_legs_from_objects_and_folders(example, both_legs, tmp_path):
    solutions, parent = both_legs
    mass, height = example.body_mass_kg, example.height_m
    assert solution_folders(parent) == {"r": parent / "r", "l": parent / "l"}
    kw = dict(models="UM10,BH04", speed_m_per_s=SPEED)
    from_objects = metabolics_from_legs(solutions, mass, height, **kw)
    from_folders = metabolics_from_legs(parent, mass, height, **kw)
    assert list(from_objects) == list(from_folders) == ["r", "l"]
    for side in "rl":
        _same_rates(from_objects[side], from_folders[side])
        assert from_objects[side].side == side and all(m.endswith(f"_{side}") for m in from_objects[side].muscles)
        # each leg stands for itself: legs=1, the basal heat once for the two
        assert from_objects[side].whole_body["UM10"].legs == 1
    total_objects, total_folders = add_legs(from_objects), add_legs(from_folders)
    for m in ("UM10", "BH04"):
        assert total_objects[m] == pytest.approx(total_folders[m], rel=RTOL)
        by_hand = sum(r.whole_body[m].one_leg_mean_W for r in from_objects.values()) / mass + 1.2
        assert total_objects[m] == pytest.approx(by_hand, rel=1e-12)

    # the analysis of each leg, over its own gait cycle
    analysed = {}
    for side in "rl":
        cycle = cycle_from_id_file(example.id["normal"], side=side, window_s=(0.57, 1.75))
        trial = (example.model, example.ik["normal"], cycle)
        from_object = analyse(solutions[side], *trial, mass, height, legs=1, **kw)
        _same_analysis(from_object, analyse(parent / side, *trial, mass, height, legs=1, **kw))
        _same_analysis(analyse(from_objects[side], *trial), from_object)
        assert from_object.side == side and set(from_object.per_muscle["side"]) == {side}
        analysed[side] = (cycle, from_object)

    # the commands, from the parent folder: both legs added, each leg analysed into OUT/<side>
    met, out = tmp_path / "met", tmp_path / "analyse"
    assert main(["metabolics", "--solution", str(parent), "--mass", str(mass), "--height", str(height),
                 "--models", "UM10,BH04", "--out", str(met)]) == 0
    whole = pd.read_csv(met / "whole_body.csv").set_index("model")
    for m in ("UM10", "BH04"):
        assert whole.loc[m, "whole_body_W_per_kg"] == pytest.approx(total_objects[m], rel=1e-9)
        for side in "rl":
            assert whole.loc[m, f"{side}_leg_muscles_W"] == pytest.approx(
                from_objects[side].whole_body[m].leg_no_basal_mean_W, rel=1e-9)
    assert main(["analyse", "--solution", str(parent), "--metabolics", str(met), "--model",
                 str(example.model), "--ik", str(example.ik["normal"]), "--id", str(example.id["normal"]),
                 "--speed", str(SPEED), "--out", str(out)]) == 0
    for side, (cycle, result) in analysed.items():
        # the command evaluates each leg as one leg doubled (legs=2): the leg's own numbers agree
        _same_table(pd.read_csv(out / side / "per_muscle.csv"), result.per_muscle)
        _same_table(pd.read_csv(out / side / "analysis.csv"), result.summary)
        _same_table(pd.read_csv(out / side / "timeseries.csv"), result.timeseries)
        summary = pd.read_csv(out / side / "analysis.csv")
        assert summary["cycle_start_s"].iloc[0] == pytest.approx(cycle.start_s, abs=1e-12)
        assert summary["toe_off_s"].iloc[0] == pytest.approx(cycle.toe_off_s, rel=1e-9)
    _same_table(pd.read_csv(out / "per_muscle.csv"), pd.concat([analysed[s][1].per_muscle for s in "rl"]))


def test_a_solve_given_relative_names_is_analysed_from_another_folder(example, tmp_path, monkeypatch, capsys):
    """The solve records its input files as absolute paths (its folder put in front of the names
    it was given), so a later command run from another folder finds the model and IK it needs."""
    import json

    data = example.model.parent
    monkeypatch.chdir(data)
    out = tmp_path / "solved"
    assert main(["solve", "--model", example.model.name, "--ik", example.ik["normal"].name, "--id",
                 example.id["normal"].name, "--window", "0.6:0.8", "--out", str(out), "-q"]) == 0
    inputs = json.loads((out / "summary.json").read_text())["inputs"]
    assert inputs == {"model": str(data / example.model.name), "ik": str(data / example.ik["normal"].name),
                      "id": str(data / example.id["normal"].name)}
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    capsys.readouterr()
    assert main(["analyse", "--solution", str(out), "--cycle", "0.6,0.7,0.8", "--mass", "72.6", "--out", "a",
                 "-q"]) == 0, capsys.readouterr().err
    assert (elsewhere / "a" / "results.csv").is_file()
