"""Study file keys for EMG-informed solves (subject ``emg_mode``) and parameter estimation
(``[subjects.estimate]``, trial ``ultrasound``): what is planned, keyed and run."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from musclemetab.errors import OptionError
from musclemetab.study import run_study, study_from_dict
from musclemetab.study.runner import unit_batches
from musclemetab.study.units import Unit, unit_key

ESTIMATE = {"estimate": {"tendon_stiffness": ["soleus_r", "gasmed_r"]}, "couple": [["soleus_r", "gasmed_r"]],
            "bounds": {"tendon_stiffness": [0.2, 1.5], "emg_scale": [0.5, 2.0]}, "weights": {"fiber_length": 50.0},
            "emg_mode": "tracking", "validate": True}


def _ultrasound(example, path):
    """Fiber lengths in mm (MuscleRedundancySolver convention) over the normal trial's IK window."""
    from musclemetab.io import read_storage, write_storage

    t = read_storage(example.ik["normal"]).index
    write_storage(path, pd.DataFrame({"soleus_r": np.full(len(t), 40.0), "gasmed_r": np.full(len(t), 55.0)}, index=t),
                  in_degrees=False)
    return path


def _data(example, tmp_path, workflows=("effort-cal",), trials=("normal",), **subject):
    us = _ultrasound(example, tmp_path / "us_normal.mot")
    return {
        "name": "emg modes", "workflows": list(workflows), "models": ["BH04"],
        "subjects": [{"name": "sub1", "model": str(example.model), "body_mass_kg": example.body_mass_kg,
                      "height_m": example.height_m, "emg_mapping": "authors", **subject,
                      "trials": [{"name": t, "ik": str(example.ik[t]), "id": str(example.id[t]),
                                  "emg": str(example.emg[t]), **({"ultrasound": str(us)} if t == "normal" else {})}
                                 for t in trials]}],
    }


def test_emg_mode_and_estimate_plan_their_units_and_keys(example, tmp_path):
    data = _data(example, tmp_path, workflows=("effort-gen", "effort-cal"), trials=("slow", "normal"),
                 emg_mode="constrained", emg_tolerance=0.02, estimate=ESTIMATE)
    study = study_from_dict(data, base="/", output=tmp_path / "out")
    s = study.subject("sub1")
    assert s.emg_mode == "constrained" and s.emg_tolerance == 0.02
    assert s.estimate.estimate == {"tendon_stiffness": ("soleus_r", "gasmed_r")}
    assert s.estimate.bounds == {"tendon_stiffness": (0.2, 1.5), "emg_scale": (0.5, 2.0)}
    assert s.trial("normal").ultrasound == (tmp_path / "us_normal.mot").resolve() and s.trial("slow").ultrasound is None
    (first,) = unit_batches(study)  # nothing depends on the estimation
    est = Unit("sub1", None, "estimate")
    assert first[0] == est and str(est.folder) == "units/sub1/_estimate"
    assert sorted((u.trial, u.workflow) for u in first[1:]) == [
        ("normal", "effort-cal"), ("normal", "effort-gen"), ("slow", "effort-cal"), ("slow", "effort-gen")]
    # the EMG mode is part of the effort units' keys, the estimate table of the estimation's only
    unit = Unit("sub1", "slow", "effort-cal")
    keys = {u: unit_key(study, u) for u in (unit, est)}
    for edit, changes in ((lambda d: d.update(emg_mode="tracking", emg_tolerance=None), {unit}),
                          (lambda d: d["estimate"]["weights"].update(fiber_length=10.0), {est}),
                          (lambda d: d.update(emg_mapping="default"), {unit, est})):
        changed = json.loads(json.dumps(data))
        edit(changed["subjects"][0])
        changed["subjects"][0] = {k: v for k, v in changed["subjects"][0].items() if v is not None}
        other = study_from_dict(changed, base="/", output=tmp_path / "out")
        assert {u for u in keys if unit_key(other, u) != keys[u]} == changes, edit
    # without the new keys nothing is added to what the unit keys hash: earlier studies keep their keys
    from musclemetab.study.units import _subject_record, _trial_record

    plain = _data(example, tmp_path, workflows=("effort-cal",), trials=("slow",))
    s = study_from_dict(plain, base="/", output=tmp_path / "out").subject("sub1")
    assert not {"emg_mode", "emg_tolerance", "estimate"} & set(_subject_record(s, "effort-cal"))
    assert "ultrasound" not in _trial_record(s.trial("slow"))


@pytest.mark.parametrize("edit, words", [
    (lambda s: s.update(emg_mode="free"), ["emg_mode", "constrained"]),
    (lambda s: s.update(emg_tolerance=0.02), ["emg_tolerance", "emg_mode"]),
    (lambda s: (s.update(emg_mode="driven"), s["trials"][0].update(cycle="auto")), ["emg_mode", "cycle", "normal"]),
    (lambda s: (s.update(emg_mode="driven"), s["trials"][0].pop("emg")), ["emg_mode", "'emg'", "normal"]),
    (lambda s: s.update(estimate={"estimate": {"stiffness": ["soleus_r"]}}), ["[subjects.estimate]", "stiffness",
                                                                            "tendon_stiffness"]),
    (lambda s: s.update(estimate={"estimate": {"tendon_stiffness": "soleus_r"}}), ["estimate.tendon_stiffness",
                                                                                 "list of muscle names"]),
    (lambda s: s.update(estimate={**ESTIMATE, "bounds": {"tendon_stiffness": [2.0, 1.0]}}),
     ["bounds.tendon_stiffness", "low <= high"]),
    (lambda s: s.update(estimate={**ESTIMATE, "weights": {"ultrasound": 1.0}}), ["weights", "ultrasound",
                                                                                "fiber_length"]),
    (lambda s: s.update(estimate={**ESTIMATE, "colour": 1}), ["unknown key", "colour"]),
    (lambda s: (s.update(estimate={"estimate": {"tendon_stiffness": ["soleus_r"]}}), s["trials"][0].pop("ultrasound")),
     ["needs measurements", "ultrasound", "emg_mode"]),
])
def test_emg_mode_and_estimate_keys_are_checked(example, tmp_path, edit, words):
    data = _data(example, tmp_path)
    edit(data["subjects"][0])
    with pytest.raises(OptionError) as info:
        study_from_dict(data, base="/")
    for w in words:
        assert w in str(info.value)


def test_estimation_unit_runs_musclemetab_estimate_on_the_subjects_files(example, tmp_path, monkeypatch):
    """The estimation unit is ``musclemetab estimate`` with the table's options on the trials that
    have fiber lengths (their EMG too with emg_mode); its folder is units/<subject>/_estimate."""
    import musclemetab.redundancy.estimate_run as run

    seen = {}

    def estimate(model, ik, id, out, **kwargs):
        seen.update(kwargs, model=model, ik=[str(p) for p in ik], id=[str(p) for p in id])
        from pathlib import Path

        (Path(out) / "parameters.json").write_text("{}\n")

    monkeypatch.setattr(run, "estimate_files", estimate)
    data = _data(example, tmp_path, workflows=("effort-gen",), trials=("slow", "normal"), estimate=ESTIMATE)
    data["solver"] = {"max_iter": 50}
    study = study_from_dict(data, base="/", output=tmp_path / "out")
    from musclemetab.errors import SolverError

    def no_trial(*a):
        raise SolverError("trial units are not run here")

    monkeypatch.setattr("musclemetab.study.units._run_trial", no_trial)
    run = run_study(study, workers=1, progress=False)
    assert run.ran[0] == "sub1/all trials/estimate" and "sub1/all trials/estimate" not in run.failed, run.failed
    assert seen["ik"] == [str(example.ik["normal"])] and seen["id"] == [str(example.id["normal"])]
    assert seen["labels"] == ["normal"] and seen["ultrasound"] == [(tmp_path / "us_normal.mot").resolve()]
    assert seen["emg"] == [example.emg["normal"]] and seen["emg_mode"] == "tracking"
    assert seen["emg_mapping"] == "authors" and seen["workflow"] == "effort-cal"
    assert {k: list(v) for k, v in seen["estimate"].items()} == {"tendon_stiffness": ["soleus_r", "gasmed_r"]}
    assert [list(g) for g in seen["couple"]] == [["soleus_r", "gasmed_r"]]
    assert seen["bounds"] == {"emg_scale": (0.5, 2.0), "tendon_stiffness": (0.2, 1.5)}
    assert seen["weights"] == {"fiber_length": 50.0} and seen["validate"] is True and seen["options"].max_iter == 50
    assert seen["side"] == "r" and seen["dofs"] is None  # the subject's side; DOFs discovered from the model
    folder = tmp_path / "out" / "units" / "sub1" / "_estimate"
    assert (folder / "parameters.json").is_file()
    assert json.loads((folder / "unit.json").read_text())["trials"] == ["normal"]


@pytest.mark.opensim
def test_estimation_stopped_by_the_iteration_limit_is_a_recorded_failure(example, tmp_path):
    """A real estimation unit (fiber lengths of soleus and gastrocnemius medialis) stopped after 3
    iterations: failures.csv holds IPOPT's status, the other units complete."""
    data = _data(example, tmp_path, workflows=("effort-gen",), estimate={
        "estimate": {"tendon_stiffness": ["soleus_r", "gasmed_r"]}, "couple": [["soleus_r", "gasmed_r"]]})
    data["solver"] = {"max_iter": 3}
    study = study_from_dict(data, base="/", output=tmp_path / "out")
    run = run_study(study, workers=1, progress=False)
    reason = run.failed["sub1/all trials/estimate"]
    assert "Maximum_Iterations_Exceeded" in reason and "after 3 iterations" in reason
    failures = pd.read_csv(tmp_path / "out" / "failures.csv")
    row = failures[failures.workflow == "estimate"]
    assert len(row) == 1 and "Maximum_Iterations_Exceeded" in row.reason.iloc[0]
    # the estimate's solve record is kept for inspection, no personalised model is written
    folder = tmp_path / "out" / "units" / "sub1" / "_estimate"
    doc = json.loads((folder / "parameters.json").read_text())
    assert doc["solve"]["status"] == "Maximum_Iterations_Exceeded" and not list(folder.glob("*_personalised.osim"))


@pytest.mark.opensim
@pytest.mark.slow
def test_emg_constrained_trial_unit_keeps_the_excitations_in_the_band(example, tmp_path):
    """``emg_mode = "constrained"``: the effort-cal unit is the EMG-informed solve; every tracked
    excitation lies within 0.01 of its scaled EMG (the EMG read here from the file) at every node."""
    from musclemetab.io import read_storage
    from musclemetab.redundancy import Solution

    data = _data(example, tmp_path, emg_mode="constrained")
    run = run_study(study_from_dict(data, base="/", output=tmp_path / "out"), workers=1, progress=False)
    assert not run.failed, run.failed
    sol = Solution.load(tmp_path / "out" / "units" / "sub1" / "normal" / "effort-cal")
    assert sol.summary["workflow"]["name"] == "effort-cal emg-constrained"
    rec = sol.summary["emg_tracking"]
    channels = {"bflh_r": "BF", "semiten_r": "ST", "vaslat_r": "VL", "vasmed_r": "VM", "tibant_r": "TA",
                "gaslat_r": "GL", "gasmed_r": "GM", "soleus_r": "SO", "vasint_r": "ES"}
    assert sorted(rec) == sorted(channels)
    emg = read_storage(example.emg["normal"])
    N = sol.summary["n_intervals"]
    dev = [sol.excitation[:N, sol.muscles.index(m)]
           - rec[m]["scale"] * np.interp(sol.time_s[:N], emg.index.to_numpy(), emg[c].to_numpy())
           for m, c in channels.items()]
    assert np.max(np.abs(dev)) <= 0.01 + 1e-6
    assert len(run.results) == 1 and run.results.workflow.iloc[0] == "effort-cal"
