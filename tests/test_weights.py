"""The objective's weights reach the objective through each public way of setting them: Python
(``solve_files(..., goals=...)``), the command line (``solve --effort-weight``, ``--emg-weight``)
and the study file (``[energy_goal] effort_weight``). Each term of the recorded objective is
recomputed here from the written solution with the weight given (muscle_redundancy.md §5.4):

* activation ``w_act * 0.5 * sum(a^2) / (N M)`` over the nodes 0..N,
* excitation ``w_act * 0.5 * sum(e^2) / (N M)`` over the nodes 0..N-1,
* reserve ``w_res * sum((R / Topt)^2) / (N D)`` over the nodes 0..N-1,
* EMG tracking ``w_emg * sum(d^2) / (n_EMG N)``, i.e. ``w_emg`` times the mean of the squared
  per-muscle RMS deviations.

A weight that did not reach the objective leaves the default in the term (1, 1000, 10), which
these checks tell apart from the weight given.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from musclemetab.errors import OptionError


def _effort_terms(summary, sol, w_activation, w_reserve, topt=150.0):
    n, M, D = summary["n_intervals"], len(sol.muscles), len(sol.dofs)
    return {
        "activation": w_activation * 0.5 * np.sum(sol.activation ** 2) / (n * M),
        "excitation": w_activation * 0.5 * np.sum(sol.excitation[:n] ** 2) / (n * M),
        "reserve": w_reserve * np.sum((sol.reserve_Nm[:n] / topt) ** 2) / (n * D),
    }


def _check_terms(summary, expected):
    for term, value in expected.items():
        assert summary["objective_terms"][term] == pytest.approx(value, rel=1e-9), term


@pytest.mark.opensim
def test_python_goals_reach_the_objective(example, geometry_cache):
    """Solved on the window 0.6-0.8 s of the normal trial: the terms' sums hold on any window."""
    from musclemetab.redundancy import Goals, solve_files

    goals = Goals(w_activation=2.0, w_reserve=250.0)
    sol = solve_files(example.model, example.ik["normal"], example.id["normal"], "effort-gen", goals=goals,
                      window=(0.6, 0.8), cache_dir=geometry_cache)
    s = sol.summary
    assert s["success"]
    _check_terms(s, _effort_terms(s, sol, 2.0, 250.0))
    assert (s["solver_options"]["w_activation"], s["solver_options"]["w_reserve"]) == (2.0, 250.0)
    assert s["solver_options"]["w_velocity"] == 0.01
    # the workflow's record keeps the preset's weights
    assert s["workflow"]["weights"] == {"w_activation": 1.0, "w_reserve": 1000.0, "w_velocity": 0.01}


@pytest.fixture(scope="module")
def short_ik(example, tmp_path_factory):
    """The normal trial's IK from 0.6 to 0.9 s, a file of those rows (OpenSim's geometry once):
    the command line's and the study's solves cover their whole IK file."""
    from musclemetab.io import read_storage, write_storage

    full = read_storage(example.ik["normal"])
    rows = full[(full.index >= 0.6) & (full.index <= 0.9)]
    return write_storage(tmp_path_factory.mktemp("weights") / "IK_sub1_normal.mot", rows, name="ik", in_degrees=True)


@pytest.mark.opensim
def test_command_line_effort_weight_reaches_the_objective(example, short_ik, geometry_cache, tmp_path):
    from musclemetab.commands import main
    from musclemetab.redundancy import Solution

    out = tmp_path / "energy"
    assert main(["solve", "--model", str(example.model), "--ik", str(short_ik), "--id",
                 str(example.id["normal"]), "--workflow", "effort-cal", "--cache-dir", str(geometry_cache),
                 "--energy-model", "UM10", "--energy-weight", "0.001", "--energy-smoothing", "0.01",
                 "--effort-weight", "0.5", "--mass", "72.6", "--height", "1.743", "--out", str(out)]) == 0
    sol = Solution.load(out)
    s = json.loads((out / "summary.json").read_text())
    _check_terms(s, _effort_terms(s, sol, 0.5, 1000.0))
    assert s["solver_options"]["w_activation"] == 0.5 and s["energy_goal"]["w_activation"] == 0.5


@pytest.mark.opensim
def test_command_line_emg_weight_reaches_the_objective(example, short_ik, geometry_cache, tmp_path):
    """An EMG-informed tracking solve (effort-gen's effort weights, EMG weight 3) of the normal
    trial's IK from 0.6 to 0.9 s (``short_ik``)."""
    from musclemetab.commands import main
    from musclemetab.redundancy import Solution

    out = tmp_path / "tracking"
    assert main(["solve", "--model", str(example.model), "--ik", str(short_ik), "--id",
                 str(example.id["normal"]), "--emg", str(example.emg["normal"]), "--emg-mapping", "authors",
                 "--workflow", "effort-gen",
                 "--emg-mode", "tracking", "--emg-weight", "3", "--cache-dir", str(geometry_cache),
                 "--out", str(out)]) == 0
    sol = Solution.load(out)
    s = json.loads((out / "summary.json").read_text())
    rms = np.array([v["rms_deviation"] for v in s["emg_tracking"].values()])
    assert s["objective_terms"]["emg_tracking"] == pytest.approx(3.0 * np.mean(rms ** 2), rel=1e-9)
    assert s["objective_terms"]["emg_tracking"] > 0
    _check_terms(s, _effort_terms(s, sol, 1.0, 1000.0))
    assert s["workflow"]["weights"]["w_emg"] == 3.0 and s["solver_options"]["w_activation"] == 1.0


@pytest.mark.opensim
def test_study_effort_weight_reaches_the_objective(example, short_ik, tmp_path):
    from musclemetab.redundancy import Solution
    from musclemetab.study import run_study, study_from_dict

    data = {"name": "weights", "workflows": ["effort-cal"], "models": ["UM10"],
            "energy_goal": {"model": "UM10", "weight": 0.001, "smoothing": 0.01, "effort_weight": 0.5},
            "subjects": [{"name": "sub1", "model": str(example.model), "body_mass_kg": example.body_mass_kg,
                          "height_m": example.height_m,
                          "trials": [{"name": "normal", "ik": str(short_ik), "id": str(example.id["normal"])}]}]}
    study = study_from_dict(data, base="/", output=tmp_path)
    run_study(study, workers=1, progress=False)
    folder = next(p.parent for p in tmp_path.rglob("summary.json") if "effort-cal" in str(p))
    sol = Solution.load(folder)
    s = json.loads((folder / "summary.json").read_text())
    _check_terms(s, _effort_terms(s, sol, 0.5, 1000.0))


def test_study_solver_table_takes_no_weights(example):
    from musclemetab.study import study_from_dict

    data = {"name": "weights", "workflows": ["effort-gen"], "models": ["UM10"], "solver": {"w_reserve": 500.0},
            "subjects": [{"name": "sub1", "model": str(example.model), "body_mass_kg": example.body_mass_kg,
                          "height_m": example.height_m,
                          "trials": [{"name": "normal", "ik": str(example.ik["normal"]),
                                      "id": str(example.id["normal"])}]}]}
    with pytest.raises(OptionError) as info:
        study_from_dict(data, base="/")
    for words in ("[solver] w_reserve", "numerical settings only", "[energy_goal] effort_weight",
                  "[subjects.estimate] weights"):
        assert words in str(info.value)


def test_one_type_holds_the_weights():
    """Workflows and EMG-TEN settings hold a Goals; SolverOptions has no weight."""
    from dataclasses import fields, replace

    from musclemetab.redundancy import EmgTenSettings, Goals, SolverOptions, get_workflow
    from musclemetab.redundancy.emg_ten import informed_settings

    assert not [f.name for f in fields(SolverOptions) if f.name.startswith("w_")]
    with pytest.raises(TypeError):
        SolverOptions(w_reserve=500.0)
    assert get_workflow("effort-ten").goals == Goals(w_activation=1.0, w_reserve=1000.0, w_velocity=0.01)
    settings = EmgTenSettings()
    assert settings.to_dict()["weights"] == {"w_emg": 10.0, "w_activation": 0.1, "w_reserve": 1000.0,
                                             "w_velocity": 0.01}
    # the record holds the scheme the problem was built with: forward in the constrained mode
    assert EmgTenSettings.from_dict(settings.to_dict()).goals == replace(settings.goals, fiber_dynamics="forward")
    informed = informed_settings("effort-gen", "tracking", w_emg=3.0).goals
    assert (informed.w_activation, informed.w_emg) == (1.0, 3.0)
    with pytest.raises(OptionError, match="the weight w_reserve must be a non-negative number"):
        Goals(w_reserve=-1.0)


@pytest.mark.opensim
def test_goals_fiber_dynamics_and_tracking_weights_are_honoured_in_a_single_trial_solve(example, geometry_cache):
    """``Goals(fiber_dynamics="backward")`` solves the backward transcription (recorded in the
    summary and its ``solver_options``, as before the goals held it), not the forward one in
    silence; the solver options hold no fiber dynamics; goals that track EMG a single-trial solve
    does not have are refused by name."""
    from musclemetab.errors import OptionError
    from musclemetab.redundancy import Goals, SolverOptions, solve_files

    args = (example.model, example.ik["normal"], example.id["normal"], "effort-gen")
    kw = dict(window=(0.6, 0.8), cache_dir=geometry_cache)
    by_goals = solve_files(*args, goals=Goals(fiber_dynamics="backward"), **kw)
    forward = solve_files(*args, **kw)
    with pytest.raises(TypeError):
        SolverOptions(fiber_dynamics="backward")
    assert by_goals.summary["success"] and forward.summary["success"]
    assert by_goals.summary["fiber_dynamics"] == "backward"
    assert by_goals.summary["solver_options"]["fiber_dynamics"] == "backward"
    assert "fiber_dynamics" not in forward.summary["solver_options"]
    assert abs(by_goals.summary["objective"] / forward.summary["objective"] - 1) > 1e-4
    with pytest.raises(OptionError, match=r"w_emg=5.*solve_emg_ten"):
        solve_files(*args, goals=Goals(w_emg=5.0), **kw)
