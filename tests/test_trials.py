"""Per-leg solution folders in metabolics: legs added instead of doubled, cycle-based trimming.

The solution folders are synthetic, in the solver's file format (see test_metabolics_solution).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from test_metabolics_solution import HEIGHT, MASS, make_solution


def _cli(*argv):
    from musclemetab.commands import main

    return main(list(map(str, argv)))


def test_metabolics_adds_two_legs_and_doubles_one(tmp_path, capsys):
    import pandas as pd

    from musclemetab.metabolics.solution import metabolics_from_solution

    parent = tmp_path / "both"
    make_solution(parent / "r")
    make_solution(parent / "l", n=40)  # another cycle length: each leg averaged over its own
    for side in "rl":
        s = json.loads((parent / side / "summary.json").read_text())
        (parent / side / "summary.json").write_text(json.dumps(s | {"side": side}))
    one = {s: metabolics_from_solution(parent / s, MASS, HEIGHT, models="UM10,BH04", legs=1) for s in "rl"}
    assert _cli("metabolics", "--solution", parent, "--mass", MASS, "--height", HEIGHT, "--models", "UM10,BH04",
                "--out", tmp_path / "m") == 0
    assert "legs r + l added" in capsys.readouterr().out
    wb = pd.read_csv(tmp_path / "m" / "whole_body.csv").set_index("model")
    for m in ("UM10", "BH04"):
        # basal rule "body": 1.2 W/kg once, the two legs' muscle averages added
        expected = (one["r"].whole_body[m].one_leg_mean_W + one["l"].whole_body[m].one_leg_mean_W) / MASS + 1.2
        assert wb.loc[m, "whole_body_W_per_kg"] == pytest.approx(expected, rel=1e-9)
        assert wb.loc[m, "legs"] == "r+l"
    assert (tmp_path / "m" / "r" / "metabolics.sto").is_file() and (tmp_path / "m" / "l" / "metabolics.sto").is_file()
    # each leg's folder: that leg's muscles alone, no basal heat, and no whole-body figure of one leg
    for side in "rl":
        leg_dir = tmp_path / "m" / side
        assert not (leg_dir / "whole_body.csv").exists()
        leg = pd.read_csv(leg_dir / "leg_muscles.csv").set_index("model")
        assert not [c for c in leg.columns if "whole_body" in c or "basal" in c]
        per = pd.read_csv(leg_dir / "per_muscle.csv")
        for m in ("UM10", "BH04"):
            # the muscles' rates without basal heat add up to the leg; the body's 1.2 W/kg is not in it
            assert leg.loc[m, "leg_muscles_W"] == pytest.approx(per[per.model == m]["muscle_W"].sum(), rel=1e-9)
            assert leg.loc[m, "leg_muscles_W_per_kg"] == pytest.approx(leg.loc[m, "leg_muscles_W"] / MASS, rel=1e-9)
            assert wb.loc[m, f"{side}_leg_muscles_W"] == pytest.approx(leg.loc[m, "leg_muscles_W"], rel=1e-9)
        assert leg["side"].tolist() == [side, side]
    for m in ("UM10", "BH04"):  # the sum of the legs, with and without the basal heat
        assert wb.loc[m, "whole_body_no_basal_W_per_kg"] == pytest.approx(
            (wb.loc[m, "r_leg_muscles_W"] + wb.loc[m, "l_leg_muscles_W"]) / MASS, rel=1e-9)
        assert wb.loc[m, "whole_body_W_per_kg"] - wb.loc[m, "whole_body_no_basal_W_per_kg"] == pytest.approx(1.2)
    # one leg: doubled, and the output says which
    assert _cli("metabolics", "--solution", parent / "l", "--mass", MASS, "--height", HEIGHT, "--models", "UM10",
                "--out", tmp_path / "one") == 0
    assert "whole body = 2 x the left leg" in capsys.readouterr().out
    from musclemetab.errors import InputFileError
    from musclemetab.metabolics.solution import solution_folders

    with pytest.raises(InputFileError, match="neither a solution folder"):
        solution_folders(tmp_path / "one")
    # a result of several trials (EMG-TEN, estimate): its trial folders are named
    several = tmp_path / "several"
    for trial in ("walk_b", "walk_a"):
        (several / trial).mkdir(parents=True)
        (several / trial / "summary.json").write_text("{}")
    with pytest.raises(InputFileError, match=rf"several: a result of several trials, one solution folder each; give one "
                                             rf"of them \({several / 'walk_a'}, {several / 'walk_b'}\)$"):
        solution_folders(several)


def test_metabolics_trims_to_the_recorded_gait_cycle(tmp_path):
    from musclemetab.metabolics.solution import metabolics_from_solution

    folder = make_solution(tmp_path / "s")  # nodes 0.57, 0.58, ..., 0.87 s
    s = json.loads((folder / "summary.json").read_text())
    s["window"] = {"gait_cycle": {"start_s": 0.6149, "toe_off_s": 0.7, "end_s": 0.8555}}
    (folder / "summary.json").write_text(json.dumps(s))
    res = metabolics_from_solution(folder, MASS, HEIGHT, models="UM10")
    # the nodes inside the cycle: 0.62 ... 0.85 s (instead of the study's 5 and 6 padding nodes)
    np.testing.assert_allclose(res.time_s[[0, -1]], [0.62, 0.85])


@pytest.mark.opensim
def test_calibration_coordinates_and_trials_found_by_content(example, gait2392, tmp_path):
    from musclemetab.calibration.trials import CALIBRATION_JOINTS, calibration_dofs, trial_files
    from musclemetab.errors import InputFileError

    # the joint tree gives the study's coordinates for its model, and gait2392's left ones
    assert calibration_dofs(example.calibration_model, "r") == CALIBRATION_JOINTS
    assert calibration_dofs(gait2392.model, "l") == {"ankle": "ankle_angle_l", "knee": "knee_angle_l",
                                                     "hip": "hip_flexion_l"}
    # the example folder (with IK, ID and EMG files beside the trials): each trial found by its moments
    folder = example.calibration_trials["ankle"]["motion"].parent
    assert trial_files(folder) == example.calibration_trials
    # renamed, left-side copies: found by the coordinate they move, not by their names
    left = {"ankle": "ankle_angle_l", "knee": "knee_angle_l", "hip": "hip_flexion_l"}
    for joint, files in example.calibration_trials.items():
        for kind, path in files.items():
            text = path.read_text().replace("_r\t", "_l\t").replace("_r_moment", "_l_moment").replace("_r\n", "_l\n")
            (tmp_path / f"sweep_{joint}{path.suffix}").write_text(text)
    got = trial_files(tmp_path, left)
    assert {j: f["moments"].name for j, f in got.items()} == {j: f"sweep_{j}.sto" for j in left}
    (tmp_path / "sweep_knee.sto").unlink()
    with pytest.raises(InputFileError, match="no calibration trial for knee_angle_l"):
        trial_files(tmp_path, left)


# ------------------------------------------------------------------ a 2D lumped-muscle model
@pytest.fixture(scope="session")
def lumped_model(gait2392, tmp_path_factory):
    """gait2392's subject as a sagittal 18-muscle model (DeGrooteFregly right, Millard left)."""
    return _build(gait2392, tmp_path_factory.mktemp("lumped") / "lumped2d.osim")


def _build(gait2392, out, *flags):
    import subprocess
    import sys
    from pathlib import Path

    subprocess.run([sys.executable, str(Path(__file__).with_name("opensim_models.py")), str(gait2392.model), str(out),
                    *flags], check=True, capture_output=True)
    return out


@pytest.fixture(scope="session")
def lumped_ik(lumped_model, gait2392, tmp_path_factory):
    """gait2392's walk as OpenSim's IK of the sagittal model writes it: each coordinate the model
    locks held at the value it is locked at (a motion moving them is refused)."""
    from musclemetab.io import read_storage, write_storage
    from musclemetab.opensim_bridge import call

    ik = read_storage(gait2392.ik)
    for c in call("model_ops:read_model_info", str(lumped_model))["coordinates"]:
        if c["locked"] and c["name"] in ik.columns:
            held = c["default_value"]
            ik[c["name"]] = np.degrees(held) if c["motion_type"] == "rotational" else held
    return write_storage(tmp_path_factory.mktemp("lumped_ik") / "walk1_sagittal_ik.mot", ik, in_degrees=True)


@pytest.fixture(scope="session")
def lumped_both(lumped_model, lumped_ik, gait2392, tmp_path_factory):
    out = tmp_path_factory.mktemp("lumped_solve") / "both"
    code = _cli("solve", "--model", lumped_model, "--ik", lumped_ik, "--external-loads", gait2392.external_loads,
                "--cycle", "auto", "--side", "both", "--out", out)
    assert code == 0
    return out


@pytest.mark.slow
@pytest.mark.opensim
def test_lumped_2d_model_with_degroote_and_millard_muscles_both_legs(lumped_model, lumped_both, gait2392, tmp_path):
    import pandas as pd

    from musclemetab.metabolics.solution import metabolics_from_solution
    from musclemetab.opensim_bridge import call

    kinds = {m["name"][-1]: m["class_name"] for m in call("model_ops:read_model_info", str(lumped_model))["muscles"]}
    for side in "rl":
        s = json.loads((lumped_both / side / "summary.json").read_text())
        assert s["success"] and s["max_moment_residual_Nm"] <= 1e-4
        # only the sagittal DOFs are free: discovered from the joint tree, distal to proximal
        assert s["dofs"] == [f"ankle_angle_{side}", f"knee_angle_{side}", f"hip_flexion_{side}"]
        assert sorted(s["muscles"]) == sorted(f"{m}_{side}" for m in (
            "hamstrings", "bifemsh", "glut_max", "iliopsoas", "rect_fem", "vasti", "gastroc", "soleus", "tib_ant"))
        assert (lumped_both / side / "inverse_dynamics.sto").is_file()
    assert kinds == {"r": "DeGrooteFregly2016Muscle", "l": "Millard2012EquilibriumMuscle"}
    # both legs added, each over its own cycle; every model in the plausible walking range
    assert _cli("metabolics", "--solution", lumped_both, "--mass", gait2392.body_mass_kg, "--height", 1.8,
                "--out", tmp_path / "m") == 0
    wb = pd.read_csv(tmp_path / "m" / "whole_body.csv").set_index("model")
    one = {s: metabolics_from_solution(lumped_both / s, gait2392.body_mass_kg, 1.8, legs=1) for s in "rl"}
    for m, row in wb.iterrows():
        total = (one["r"].whole_body[m].one_leg_mean_W + one["l"].whole_body[m].one_leg_mean_W) / gait2392.body_mass_kg
        assert row["whole_body_W_per_kg"] == pytest.approx(total + 1.2, rel=1e-9)
        assert 2.6 < row["whole_body_W_per_kg"] < 15.8, m


# ------------------------------------------------------------------ a two-subject study
#: The two-subject study file (``str.format`` with the ``example`` and ``gait2392`` data sets).
TWO_SUBJECTS = """
name = "two subjects"
output = "out"
workflows = ["effort-gen"]
models = ["UM10", "BH04"]

[[subjects]]
name = "example"
model = "{example.model}"
body_mass_kg = {example.body_mass_kg}
height_m = {example.height_m}

[[subjects.trials]]
name = "normal"
ik = "{example.ik[normal]}"
id = "{example.id[normal]}"

[[subjects]]
name = "gait2392"
model = "{gait2392.model}"
body_mass_kg = {gait2392.body_mass_kg}
height_m = 1.8
side = "both"

[[subjects.trials]]
name = "walk1"
ik = "{gait2392.ik}"
external_loads = "{gait2392.external_loads}"
cycle = "auto"
"""


@pytest.mark.slow
@pytest.mark.opensim
def test_two_subject_study_different_models_and_sides(two_subjects, gait2392):
    """The study's subject (Rajagopal model, right leg, ID file) and gait2392's subject (its own
    gait2392 model, both legs, each over its own cycle, inverse dynamics from the ground forces)
    in one study file, run end to end by ``musclemetab run`` with the report.

    Oracles for the row adding gait2392's legs: the whole-body rate from the legs' metabolics
    evaluated apart (``legs=1``) and added by :func:`musclemetab.metabolics.add_legs`; the
    stance share from both legs' per-muscle stance energies."""
    import pandas as pd

    from musclemetab.metabolics.solution import add_legs, metabolics_from_solution

    out, printed = two_subjects  # the study run by ``musclemetab run --report`` (conftest)
    assert "3 units: 3 run" in printed
    res = pd.read_csv(out / "results.csv")
    assert sorted(set(res["subject"])) == ["example", "gait2392"] and len(res) == 4
    assert set(res.loc[res["subject"] == "example", "legs"]) == {"2 x r"}
    assert set(res.loc[res["subject"] == "gait2392", "legs"]) == {"r + l"}
    unit = out / "units" / "gait2392" / "walk1" / "effort-gen"
    legs = {}
    for side, start in (("r", 0.618), ("l", 1.247)):
        s = json.loads((unit / side / "summary.json").read_text())
        assert s["side"] == side and {f"ankle_angle_{side}", f"knee_angle_{side}", f"hip_flexion_{side}"} <= set(s["dofs"])
        assert all(m.endswith(f"_{side}") for m in s["muscles"]) and len(s["muscles"]) == 43
        assert s["window"]["gait_cycle"]["start_s"] == pytest.approx(start, abs=3e-3)
        assert (unit / side / "inverse_dynamics.sto").is_file()
        legs[side] = metabolics_from_solution(unit / side, gait2392.body_mass_kg, 1.8, models=["UM10", "BH04"], legs=1)
    added = add_legs(legs)
    g = res[res["subject"] == "gait2392"].set_index("model")
    for model, value in added.items():
        assert g.loc[model, "whole_body_W_per_kg"] == pytest.approx(value, rel=1e-9)
    pm = pd.read_csv(out / "per_muscle.csv")
    pm = pm[pm["subject"] == "gait2392"]
    assert set(pm["side"]) == {"r", "l"}
    for model, rows in pm.groupby("model"):
        stance = 100 * rows["stance_J"].sum() / (rows["stance_J"].sum() + rows["swing_J"].sum())
        assert g.loc[model, "stance_energy_share_pct"] == pytest.approx(stance, rel=1e-6)
    assert g["cycle_start_s"].isna().all() and g["unit_dir"].iloc[0] == "units/gait2392/walk1/effort-gen"
    ex = json.loads((out / "units" / "example" / "normal" / "effort-gen" / "summary.json").read_text())
    assert ex["side"] == "r" and len(ex["muscles"]) == 40
    html = (out / "report.html").read_text()
    assert "the sum of both solved legs" in html and "the right leg doubled for example" in html
    wkg = [c for c in res.columns if "W_per_kg" in c]
    assert wkg and res[wkg[0]].between(2.6, 15.8).all()


@pytest.mark.slow
@pytest.mark.opensim
def test_bad_input_no_muscles_on_the_side_and_unknown_muscles(gait2392, lumped_both, lumped_ik, tmp_path, capsys):
    model = _build(gait2392, tmp_path / "right_only.osim", "--right-only")
    out = tmp_path / "out"
    cases = [
        (["solve", "--model", model, "--ik", lumped_ik, "--external-loads", gait2392.external_loads,
          "--cycle", "auto", "--side", "l", "--out", out], "no muscle has a moment arm above 0.1 mm"),
        (["solve", "--model", model, "--ik", lumped_ik, "--external-loads", gait2392.external_loads,
          "--cycle", "auto", "--exclude-muscles", "tfl_r", "--out", out], "tfl_r is not among the muscles"),
        (["metabolics", "--solution", _renamed_muscle(lumped_both / "r", tmp_path / "renamed"), "--mass", 72.6,
          "--height", 1.8, "--strict", "--out", out], "muscle mystery_r not in the anatomical muscle table (--strict)"),
    ]
    for argv, message in cases:
        code = _cli(*argv)
        errors = [line for line in capsys.readouterr().err.splitlines() if line.startswith("musclemetab: error:")]
        assert code != 0 and len(errors) == 1 and message in errors[0], (argv[0], errors)
        assert not out.exists()


def _renamed_muscle(solution, folder):
    """A copy of a solution folder in which vasti_r is called mystery_r (a muscle no table knows)."""
    import shutil

    shutil.copytree(solution, folder)
    for name in ("summary.json", "solution.sto"):
        path = folder / name
        path.write_text(path.read_text().replace("vasti_r", "mystery_r"))
    return folder


def test_report_adds_the_legs_time_series_on_the_cycle():
    """Both legs at the first leg's instants, worked by hand. Two solved legs, each on its own
    cycle: right 0.6-1.8 s, left 1.2-2.4 s (its heel strike half a cycle later); at the right
    leg's 0.6, 1.2 and 1.8 s the left leg is at 50, 0 and 50 % of its cycle (60 -> 90 W
    between 33.3 and 66.7 %: 75 W; 30 W at 0 %). One solved leg: the leg plus itself half a
    cycle later, x(p) + x(p + 50 %)."""
    import pandas as pd

    from musclemetab.report.folder import add_leg_timeseries as _add_leg_timeseries

    right = pd.DataFrame({"time_s": [0.6, 1.2, 1.8], "cycle_pct": [0.0, 50.0, 100.0], "model": "UM10",
                          "series": "leg_muscles", "value_W": [100.0, 200.0, 100.0]})
    left = pd.DataFrame({"time_s": [1.2, 1.6, 2.0, 2.4], "cycle_pct": [0.0, 100 / 3, 200 / 3, 100.0],
                         "model": "UM10", "series": "leg_muscles", "value_W": [30.0, 60.0, 90.0, 120.0]})
    both = _add_leg_timeseries({"r": right, "l": left})
    assert both["value_W"].tolist() == pytest.approx([175.0, 230.0, 175.0])
    assert both["cycle_pct"].tolist() == [0.0, 50.0, 100.0]
    # one leg: 100 + x(50) = 300, 200 + x(100 = 0 of the next cycle) = 300, 100 + x(150 = 50) = 300
    assert _add_leg_timeseries({"": right})["value_W"].tolist() == pytest.approx([300.0, 300.0, 300.0])
    # on a finer synthetic leg: a peak at 20 % gives the other leg's peak at 70 %; the cycle mean doubles
    pct = np.linspace(0.0, 100.0, 201)
    leg = pd.DataFrame({"time_s": 1 + pct / 100, "cycle_pct": pct, "model": "UM10", "series": "leg_muscles",
                        "value_W": 10 + 50 * np.exp(-0.5 * ((pct - 20) / 4) ** 2)})
    two = _add_leg_timeseries({"": leg})["value_W"].to_numpy()
    assert pct[np.argmax(two[pct > 45])+np.argmax(pct > 45)] == pytest.approx(70.0)
    assert np.mean(two[:-1]) == pytest.approx(2 * np.mean(leg["value_W"].to_numpy()[:-1]), rel=1e-9)


def test_the_grf_column_and_threshold_reach_the_cycle_search(gait2392):
    """gait2392's ground-force file holds the right foot (``ground_force_vy``) and the left foot
    (``1_ground_force_vy``). Naming the left foot's column for the right side gives the left
    foot's cycle (heel strike 1.247 s, OpenSim's stored events of the data set) instead of the
    right foot's (0.618 s): the column is the one the cycle search reads. A contact threshold
    above the foot's peak force finds no cycle, and says so with the threshold."""
    from musclemetab.errors import DataMismatchError
    from musclemetab.external_loads import read_external_loads
    from musclemetab.redundancy.window import resolve_window

    grf = read_external_loads(gait2392.external_loads).datafile
    right = resolve_window(gait2392.ik, side="r", cycle="auto", grf_path=grf)
    from musclemetab.errors import WindowWarning

    # the left foot's cycle 1.245-2.459 s padded runs past the forces' end (2.5 s): the warning says
    # the window solved, snapped outwards to the 60 Hz IK frames (0.5 + 41/60 = 1.183 s) and clipped at 2.5 s
    with pytest.warns(WindowWarning, match=r"the solved window, clipped there and on the IK frames, is 1\.183-2\.500 s: "
                                           r"0\.062 s before the cycle and 0\.041 s after it") as said:
        left_foot = resolve_window(gait2392.ik, side="r", cycle="auto", grf_path=grf, grf_column="1_ground_force_vy")
    assert said[0].filename == __file__  # a Python session sees its own line, not the package's source
    assert right.cycle["start_s"] == pytest.approx(0.618, abs=3e-3)
    assert left_foot.cycle["start_s"] == pytest.approx(1.247, abs=3e-3)
    assert "1_ground_force_vy" in left_foot.cycle["source"]
    with pytest.raises(DataMismatchError, match="threshold 5000 N"):
        resolve_window(gait2392.ik, side="r", cycle="auto", grf_path=grf, grf_threshold_N=5000.0)


def test_cycle_auto_takes_the_first_cycle_inside_every_input_file(tmp_path):
    """A ground force with three contacts of the right foot (heel strikes 0.20, 1.30 and 2.40 s,
    toe-offs 0.90 and 2.00 s: two complete cycles) and kinematics from 0.50 s: the first cycle
    starts before the kinematics, so ``cycle="auto"`` takes the second, 1.30-2.40 s (the force
    crosses the 20 N threshold 0.97 ms before each step), padded by 0.05 s and snapped outwards
    to the kinematics' 100 Hz frames: 1.24-2.45 s; ``cycle=1`` is refused naming the IK file and
    its shortfall, 0.5 - (0.199 + 20/700 ms) = 0.300971 s; kinematics from 1.50 s hold neither,
    and the message says so of both."""
    import pandas as pd

    from musclemetab.errors import DataMismatchError
    from musclemetab.io import write_storage
    from musclemetab.redundancy.window import resolve_window

    t = np.round(np.arange(0.0, 3.0 + 1e-9, 0.001), 3)
    stance = ((t >= 0.2) & (t < 0.9)) | ((t >= 1.3) & (t < 2.0)) | ((t >= 2.4) & (t < 2.9))
    grf = write_storage(tmp_path / "grf.mot", pd.DataFrame({"ground_force_vy": np.where(stance, 700.0, 0.0)}, index=t))
    ik_t = np.round(np.arange(0.5, 3.0 + 1e-9, 0.01), 2)
    ik = write_storage(tmp_path / "ik.mot", pd.DataFrame({"knee_angle_r": np.zeros(ik_t.size)}, index=ik_t),
                       in_degrees=True)
    window = resolve_window(ik, side="r", cycle="auto", grf_path=grf)
    assert (window.cycle["start_s"], window.cycle["toe_off_s"], window.cycle["end_s"]) == pytest.approx(
        (1.30, 2.00, 2.40), abs=1.5e-3)
    assert window.cycle["index"] == 2 and window.cycle["number"] == "auto"
    assert (window.start_s, window.end_s) == pytest.approx((1.24, 2.45), abs=1e-9)
    assert "cycle 2, the first inside every input file" in window.source
    with pytest.raises(DataMismatchError, match=r"ik.mot: the inverse kinematics \(0.500-3.000 s\) starts 0.300971 s after "
                                                r"the right leg's gait cycle 1 start 0.199 s.*choose another --cycle"):
        resolve_window(ik, side="r", cycle=1, grf_path=grf)
    late = write_storage(tmp_path / "late.mot", pd.DataFrame({"knee_angle_r": np.zeros(101)},
                                                             index=np.round(np.linspace(1.5, 2.5, 101), 2)), in_degrees=True)
    with pytest.raises(DataMismatchError, match=r"late.mot: .* starts 1.300971 s after the right leg's gait cycle start 0.199 s.*"
                                                r"no later cycle of the leg \(1.299-2.399 s\) lies inside every input file either; "
                                                r"give a --window"):
        resolve_window(late, side="r", cycle="auto", grf_path=grf)


def test_kinematic_toe_off_on_treadmill_trials(example):
    """The example subject walked on a treadmill (the pelvis barely travels): the kinematic rule's
    toe-off against the toe-off of the ankle moment's drop (an independent signal, the study's
    rule without forces), 0.04 s as on gait2392. Its records hold one cycle with 5 frames
    beyond each heel strike: both heel strikes are found all the same (an excursion cut by the
    end of the record needs its prominence on one side only), each within 50 ms before the
    study's initial contacts (the IK window less 0.05 s at each end), as on gait2392 the
    kinematic heel strike precedes the force's by 19-28 ms."""
    from musclemetab.events import cycle_from_id_file, kinematic_gait_events
    from musclemetab.io import read_storage

    for trial in ("slow", "normal", "fast"):
        t = read_storage(example.ik[trial]).index.to_numpy(float)
        ev = kinematic_gait_events(example.model, example.ik[trial], "r")
        moment = cycle_from_id_file(example.id[trial], window_s=(t[0], t[-1]), padding_s=0.05)
        assert len(ev.toe_offs_s) == 1 and ev.toe_offs_s[0] == pytest.approx(moment.toe_off_s, abs=0.04), trial
        study = np.array([t[0] + 0.05, t[-1] - 0.05])
        assert len(ev.heel_strikes_s) == 2, trial
        assert np.all((study - ev.heel_strikes_s > 0) & (study - ev.heel_strikes_s < 0.05)), (trial, ev.heel_strikes_s)


@pytest.mark.slow
def test_emg_ten_of_both_legs(example, tmp_path, capsys, monkeypatch):
    """``solve --workflow emg-ten --side both`` with a mapping naming both legs' muscles: each leg is
    the EMG-TEN problem of that leg alone, with the mapping's entries of its muscles, written to
    OUT/r and OUT/l. (The example's EMG is of the right leg; its left-leg entries here reuse the
    same channels, which is enough to show how the legs are split, not a measurement: each leg's
    IPOPT run is stopped after three iterations, and the command reports that after writing both
    legs.) The named mappings, one leg's electrodes, are refused with both legs, in one line."""
    from musclemetab.emg import DEFAULT_EMG_MAPPING
    from musclemetab.redundancy import emg_run as run_module

    right = {m: list(c) for m, c in DEFAULT_EMG_MAPPING.items()}
    both = {**right, **{m[:-2] + "_l": c for m, c in right.items()}}
    mapping = tmp_path / "map.json"
    mapping.write_text(json.dumps(both))
    calls = []
    real = run_module.solve_emg_ten

    def recording(*args, **kwargs):  # the command imports it when it runs
        calls.append(kwargs)
        return real(*args, **kwargs)

    monkeypatch.setattr(run_module, "solve_emg_ten", recording)
    out = tmp_path / "out"
    assert _cli("solve", "--workflow", "emg-ten", "--model", example.model, "--ik", example.ik["normal"],
                "--id", example.id["normal"], "--emg", example.emg["normal"], "--emg-mapping", mapping,
                "--side", "both", "--max-iter", "3", "--out", out) == 1
    assert "did not converge" in capsys.readouterr().err
    assert [c["side"] for c in calls] == ["r", "l"]
    assert calls[0]["emg_mapping"] == right and calls[1]["emg_mapping"] == {m: c for m, c in both.items()
                                                                            if m.endswith("_l")}
    for side in "rl":
        summary = json.loads((out / side / "IK_sub1_normal" / "summary.json").read_text())
        assert summary["iterations"] == 3 and (out / side / "parameters.json").is_file()
        assert summary["side"] == side and all(m.endswith(f"_{side}") for m in summary["muscles"])
        assert set(summary["emg_tracking"]) == {m for m in both if m.endswith(f"_{side}")}
    capsys.readouterr()
    assert _cli("solve", "--workflow", "emg-ten", "--model", example.model, "--ik", example.ik["normal"], "--id",
                example.id["normal"], "--emg", example.emg["normal"], "--side", "both", "--out", tmp_path / "no") != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--emg-mapping MAP.json" in err and not (tmp_path / "no").exists()
