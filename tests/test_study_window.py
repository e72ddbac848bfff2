"""A study trial's ``window`` (``"T0:T1"`` or ``[T0, T1]``, as ``musclemetab solve --window``):
how it is read and refused, the unit keys, and the gait cycle of the analysis in the window.
No solve here: ``tests/test_window_solves.py`` runs a windowed study unit against the command."""

from __future__ import annotations

import pytest

from musclemetab.errors import DataMismatchError, OptionError
from musclemetab.study import load_study, plan_units, study_from_dict
from musclemetab.study.units import unit_key

ESTIMATE = {"estimate": {"tendon_stiffness": ["soleus_r"]}, "emg_mode": "tracking"}


def _data(example, workflows=("effort-gen",), subject=None, **trial):
    return {"workflows": list(workflows), "models": ["UM10"],
            "subjects": [{"name": "sub1", "model": str(example.model), "body_mass_kg": example.body_mass_kg,
                          "height_m": example.height_m, **(subject or {}),
                          "trials": [{"name": "normal", "ik": str(example.ik["normal"]),
                                      "id": str(example.id["normal"]), **trial}]}]}


def _toml(example, window: str) -> str:
    """A study file of the example's normal trial with ``window = <window>`` (TOML text)."""
    trial = f'name = "normal", ik = "{example.ik["normal"]}", id = "{example.id["normal"]}", window = {window}'
    return f'subjects = [{{name = "sub1", model = "{example.model}", body_mass_kg = 72.6, trials = [{{{trial}}}]}}]\n'


@pytest.mark.parametrize("window", ['"0.6:1.0"', "[0.6, 1.0]", "[0.6, 1]", '" 0.6 : 1.0 "'])
def test_a_window_is_read_from_text_or_an_array(example, tmp_path, window):
    path = tmp_path / "study.toml"
    path.write_text(_toml(example, window))
    assert load_study(path).subject("sub1").trial("normal").window == (0.6, 1.0)


@pytest.mark.parametrize("window", ['"1.5"', '"2:1"', '"1:1"', '"nan:1"', '"0.6:inf"', "[inf, 2.0]", "[1.0]",
                                    "[0.6, 1.0, 1.4]", "1.5", "true", '"0.6-1.0"', "[true, 2]", '["0.6", "1"]'])
def test_a_bad_window_is_refused_when_the_file_is_read(example, tmp_path, window):
    """One message naming the study file, the subject and trial and the key, saying what to write."""
    path = tmp_path / "study.toml"
    path.write_text(_toml(example, window))
    with pytest.raises(OptionError) as info:
        load_study(path)
    text = str(info.value)
    for words in (str(path), "subject 'sub1', trial 'normal'", "'window' must be \"T0:T1\"", "finite",
                  "T0 before T1", 'window = "0.6:1.9"', "[0.6, 1.9]"):
        assert words in text, text


@pytest.mark.parametrize("subject, workflows, trial, words", [
    ({}, ("effort-gen",), {"cycle": "auto"}, ["trial 'normal'", "give 'window'", "or 'cycle'", "not both",
                                              "--window or --cycle"]),
    ({}, ("effort-gen",), {"states": "IK"}, ["trial 'normal'", "'states'", "'window'", "drop one of them"]),
    ({"emg_mode": "constrained"}, ("effort-gen",), {"emg": "EMG"},
     ["subject 'sub1'", "EMG-informed solve covers the whole IK window", "'window'", "normal"]),
    ({}, ("effort-gen", "emg-ten"), {"emg": "EMG"},
     ["subject 'sub1'", "the emg-ten workflow", "whole IK file", "'window' cannot apply", "normal", "drop it"]),
    ({"tendon_stiffness": "emg-ten"}, ("effort-ten",), {"emg": "EMG"},
     ["tendon_stiffness = \"emg-ten\"", "whole IK file", "'window' cannot apply", "normal"]),
    ({"estimate": ESTIMATE}, ("effort-gen",), {"emg": "EMG"},
     ["subject 'sub1'", "the estimation solves the trials' whole IK window", "'window'", "normal"]),
])
def test_a_window_is_refused_where_it_cannot_apply(example, subject, workflows, trial, words):
    """With 'cycle' (as --window with --cycle); with 'states' (no solve); with the solves over every
    trial's whole IK file: EMG-informed solves, EMG-TEN (workflow or estimate), parameter estimation."""
    trial = {k: {"IK": str(example.ik["normal"]), "EMG": str(example.emg["normal"])}.get(v, v) for k, v in trial.items()}
    with pytest.raises(OptionError) as info:
        study_from_dict(_data(example, workflows, subject, window="0.6:1.0", **trial), base="/")
    assert all(w in str(info.value) for w in words), str(info.value)


def test_the_window_is_part_of_the_unit_keys_and_studies_without_it_keep_theirs(example):
    from musclemetab.study.units import _trial_record

    def key(**trial):
        study = study_from_dict(_data(example, **trial), base="/", output="/tmp/out")
        (unit,) = plan_units(study)[1]
        return study, unit_key(study, unit)

    plain, k0 = key()
    assert "window" not in _trial_record(plain.subjects[0].trials[0])  # absent: earlier keys unchanged
    _, k1 = key(window="0.6:1.0")
    _, k2 = key(window=[0.6, 1.0])
    _, k3 = key(window="0.6:1.1")
    assert k1 == k2 and len({k0, k1, k3}) == 3


def test_both_legs_take_a_window_in_place_of_a_cycle(example):
    """``side = "both"`` needs each trial's 'cycle' or a 'window' both legs are solved over (as
    ``solve --side both --window``); one unit per leg, each with its own key."""
    with pytest.raises(OptionError, match=r'cycle = "auto".*or a window = "T0:T1" that both legs are solved over'):
        study_from_dict(_data(example, subject={"side": "both"}), base="/")
    study = study_from_dict(_data(example, subject={"side": "both"}, window="0.6:1.0"), base="/", output="/tmp/o")
    units = plan_units(study)[1]
    assert [u.side for u in units] == ["r", "l"] and len({unit_key(study, u) for u in units}) == 2


def test_the_gait_cycle_and_speed_of_a_windowed_trial_are_in_its_window(example):
    """Without events: the solved window (snapped to IK frames) less 0.05 s at each end, toe-off
    from the ankle moment inside it, the speed over that cycle, as ``analyse`` has them for a solve
    over ``--window``; given times override; no toe-off in the window: a message saying what to give."""
    from musclemetab.analysis.speed import walking_speed_from_ik
    from musclemetab.events import cycle_of_trial
    from musclemetab.study.events import trial_cycle, trial_speed
    from musclemetab.study.units import _cycle_source

    trial = study_from_dict(_data(example, window="1.1:1.45"), base="/").subjects[0].trials[0]
    cycle = trial_cycle(trial, "r")
    want, source = cycle_of_trial(example.ik["normal"], id_file=example.id["normal"], window_s=(1.1, 1.45))
    assert cycle == want and (cycle.start_s, cycle.end_s) == pytest.approx((1.15, 1.40), abs=1e-9)
    assert 1.15 < cycle.toe_off_s < 1.40 and _cycle_source(trial) == source
    assert trial_speed(trial, example.model, cycle) == walking_speed_from_ik(
        example.ik["normal"], start_s=1.15, end_s=1.40, model=example.model)
    named = study_from_dict(_data(example, window="1.1:1.45", start_s=1.2, end_s=1.4), base="/").subjects[0].trials[0]
    assert trial_cycle(named, "r") == type(cycle)(1.2, cycle.toe_off_s, 1.4)
    early = study_from_dict(_data(example, window="0.6:0.9"), base="/").subjects[0].trials[0]
    with pytest.raises(DataMismatchError) as info:
        trial_cycle(early, "r")
    for words in ("trial 'normal': no gait events inside its window 0.600-0.900 s from the ankle moment: ",
                  "no plantarflexion moment inside the cycle 0.65-0.85 s", "(a window without stance has none: "
                  "give the trial's start_s, toe_off_s and end_s inside its window 0.600-0.900 s, or a 'grf' file)"):
        assert words in str(info.value), str(info.value)
    assert "GaitCycle" not in str(info.value)  # the Python remedy is not a study's
