"""A subject without a height: the study file, the energy goal and the command line.

The height enters only the volume rule of the muscle masses; without it every muscle's mass
comes from the model, ``F0 / sigma * rho * lMo`` (``muscle_mass_rule``, ``docs/metabolics.md``).

* a study unit of a subject without ``height_m`` gives the numbers that ``musclemetab
  metabolics`` without ``--height`` gives on the unit's own solution folder (the solve is the
  one of the example's normal trial, EFFORT-GEN, that other tests make: solved once per run);
* the energy goal without a height takes the masses ``F0 / 0.6 MPa * 1059.7 kg/m^3 * lMo``
  worked here from the muscle parameters, and records the rule;
* ``solve --energy-model`` needs ``--mass`` alone (``tests/test_energy_goal.py``).
"""

from __future__ import annotations

import json
import types

import numpy as np
import pandas as pd
import pytest

from musclemetab.errors import OptionError

RHO, SIGMA = 1059.7, 0.6e6  # muscle density (kg/m^3) and the table's specific tension (Pa)


def test_study_file_without_height(example):
    from musclemetab.study import study_from_dict

    data = {"name": "h", "workflows": ["effort-gen"], "models": ["UM10"], "subjects": [{
        "name": "s", "model": str(example.model), "body_mass_kg": 72.6,
        "trials": [{"name": "normal", "ik": str(example.ik["normal"]), "id": str(example.id["normal"])}]}]}
    assert study_from_dict(data, base="/", output="/tmp/x").subjects[0].height_m is None
    data["subjects"][0]["height_m"] = 174.3  # given, it is still checked
    with pytest.raises(OptionError, match="height_m.*metres"):
        study_from_dict(data, base="/", output="/tmp/x")


@pytest.mark.opensim
def test_study_unit_without_height_equals_metabolics_without_height(example, tmp_path, capsys):
    from musclemetab.commands import main
    from musclemetab.metabolics.solution import MASS_RULE_MODEL
    from musclemetab.study import run_study, study_from_dict

    models = ["UM10", "BH04", "MA68"]
    data = {"name": "no height", "workflows": ["effort-gen"], "models": models, "subjects": [{
        "name": "sub1", "model": str(example.model), "body_mass_kg": example.body_mass_kg,
        "trials": [{"name": "normal", "ik": str(example.ik["normal"]), "id": str(example.id["normal"])}]}]}
    study = study_from_dict(data, base="/", output=tmp_path / "study")
    run = run_study(study, workers=1, progress=False)
    assert not run.failed, run.failed
    table = run.results
    assert (table["muscle_mass_rule"] == MASS_RULE_MODEL).all()
    unit = study.output / table["unit_dir"].iloc[0]
    assert json.loads((study.output / "study.json").read_text())["subjects"]["sub1"]["height_m"] is None
    # the command line on the unit's solution folder, no --height
    out = tmp_path / "metabolics"
    assert main(["metabolics", "--solution", str(unit), "--mass", str(example.body_mass_kg), "--models",
                 ",".join(models), "--out", str(out)]) == 0
    assert "no --height" in capsys.readouterr().err
    cli = pd.read_csv(out / "whole_body.csv").set_index("model")
    wb = pd.read_csv(unit / "whole_body.csv").set_index("model")
    assert (cli["muscle_mass_rule"] == MASS_RULE_MODEL).all() and (wb["muscle_mass_rule"] == MASS_RULE_MODEL).all()
    for m in models:
        assert table.set_index("model").loc[m, "whole_body_W_per_kg"] == pytest.approx(
            cli.loc[m, "whole_body_W_per_kg"], rel=1e-9)
    per_cli = pd.read_csv(out / "per_muscle.csv").set_index(["model", "muscle"]).sort_index()
    per_unit = pd.read_csv(unit / "per_muscle.csv").set_index(["model", "muscle"]).sort_index()
    for col in ("muscle_W", "basal_heat_mean_W", "work_mean_W"):
        np.testing.assert_allclose(per_unit[col].to_numpy(), per_cli.loc[per_unit.index, col].to_numpy(), rtol=1e-9)
    # and the masses are the model's: the per-muscle basal heat, 1.2 W per kg of muscle mass, is
    # 1.2 F0 / sigma * rho * lMo of the solution's recorded parameters
    params = json.loads((unit / "summary.json").read_text())["parameters"]
    one = per_unit.loc["UM10"]
    for muscle in ("soleus_r", "vaslat_r", "glmax1_r"):
        p = params[muscle]
        assert one.loc[muscle, "basal_heat_mean_W"] == pytest.approx(1.2 * p["F0_N"] / SIGMA * RHO * p["lMo_m"],
                                                                     rel=1e-9)


def test_energy_goal_without_height_takes_the_model_masses(tmp_path):
    import warnings

    from musclemetab.redundancy.energy import EnergyGoal

    f0, lmo = np.array([3549.0, 1294.0, 700.0]), np.array([0.044, 0.084, 0.1])
    muscles = ("soleus_r", "vaslat_r", "not_a_muscle_r")
    goal = EnergyGoal("UM10", 1.0, 72.6, None)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the model rule places every muscle without a warning
        mass, fst = goal.muscle_values(muscles, f0, lmo)
    np.testing.assert_allclose(mass, f0 / SIGMA * RHO * lmo, rtol=1e-12)
    assert fst[2] == 0.5  # a muscle the table cannot place: the study's fraction
    record = goal.record()
    assert record["height_m"] is None and record["muscle_mass_rule"].startswith("model")
    assert "muscle_mass_rule" not in EnergyGoal("UM10", 1.0, 72.6, 1.743).record()  # as before
    # the same rate as the smooth model with those masses
    from musclemetab.redundancy.objective import leg_rate_W_per_kg

    params = types.SimpleNamespace(subset=lambda names: types.SimpleNamespace(
        max_isometric_force_N=f0, optimal_fiber_length_m=lmo, max_contraction_velocity=np.full(3, 10.0),
        passive_kpe=np.full(3, 4.0), passive_s0=np.full(3, 1.0), passive_sm=np.full(3, 0.6)))
    states = [np.full((4, 3), v) for v in (0.3, 0.25, 1.0, 0.0)]
    with_model = leg_rate_W_per_kg(goal, params, list(muscles), *states)
    csv = tmp_path / "muscles.csv"
    csv.write_text(f"muscle,mass_kg\nsoleus_r,{float(2 * mass[0])!r}\n")
    heavier = EnergyGoal("UM10", 1.0, 72.6, None, muscle_properties=csv)  # an override mass is used as given
    np.testing.assert_allclose(heavier.muscle_values(muscles, f0, lmo)[0], [2 * mass[0], *mass[1:]], rtol=1e-12)
    assert np.all(leg_rate_W_per_kg(heavier, params, list(muscles), *states) > with_model)
    # the same override as a mapping gives the same masses; the goal keeps its own copy
    given = {"soleus_r": {"mass_kg": float(2 * mass[0])}}
    as_mapping = EnergyGoal("UM10", 1.0, 72.6, None, muscle_properties=given)
    given["soleus_r"]["mass_kg"] = 99.0
    np.testing.assert_array_equal(as_mapping.muscle_values(muscles, f0, lmo)[0], heavier.muscle_values(muscles, f0, lmo)[0])
    assert as_mapping.record()["muscle_properties"] == {"soleus_r": {"mass_kg": float(2 * mass[0])}}
    # checked as a CSV's rows are, when the goal is made: the muscle and column named
    with pytest.raises(OptionError, match="muscle 'soleus_r', column 'mass_kg'"):
        EnergyGoal("UM10", 1.0, 72.6, None, muscle_properties={"soleus_r": {"mass_kg": -1.0}})
    with pytest.raises(OptionError, match="muscle 'soleus_r': unknown column mas_kg"):
        EnergyGoal("UM10", 1.0, 72.6, None, muscle_properties={"soleus_r": {"mas_kg": 1.0}})
    with pytest.raises(OptionError, match="kilograms"):
        EnergyGoal("UM10", 1.0, 72600.0, None)
