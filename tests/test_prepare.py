"""``musclemetab prepare``: generic model, static and walking markers -> scaled model and IK, then the
solver's inputs. OpenSim's gait2392 subject01 with OpenSim's setups (the ``gait2392_prepared``
fixture), against what OpenSim made of the same files: ``subject01_walk1_ik.mot`` and the inverse
dynamics ``subject01_walk1_id.sto``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from musclemetab.commands import main
from musclemetab.io import read_storage

pytestmark = pytest.mark.opensim


def test_prepare_writes_the_model_ik_and_marker_errors(gait2392_prepared):
    inputs, out = gait2392_prepared
    for name in ("model.osim", "ik.mot", "ik_marker_errors.csv", "static_marker_errors.csv", "static_pose.sto",
                 "prepare.json"):
        assert (out / name).is_file(), name
    rec = json.loads((out / "prepare.json").read_text())
    assert rec["mass_kg"] == 72.6 and rec["height_from"] == "Top.Head"
    import pandas as pd
    from test_datadict_columns import undocumented

    for name in ("ik_marker_errors.csv", "static_marker_errors.csv"):  # columns in the data dictionary
        assert not undocumented(out / name, pd.read_csv(out / name, nrows=1).columns)
    assert rec["ik"]["time_range"] == [0.5, 2.5] and rec["ik"]["summary"]["frames"] == 121


def test_prepared_ik_matches_opensims(gait2392_prepared, gait2392):
    """Within 2 degrees RMS of OpenSim's IK for hip flexion, knee and ankle and 8 for hip adduction and
    rotation, on OpenSim's time grid (0.5 s + i/60: the trial's rounded times restored)."""
    _, out = gait2392_prepared
    ours = read_storage(out / "ik.mot")
    ref = read_storage(gait2392.ik)
    ref = ref.loc[ours.index[0] - 1e-9: ours.index[-1] + 1e-9]
    assert len(ref) == len(ours) == 121
    assert np.allclose(ours.index.to_numpy(), ref.index.to_numpy(), atol=1e-6)
    for side in "rl":
        for c, limit in (("hip_flexion", 2), ("knee_angle", 2), ("ankle_angle", 2), ("hip_adduction", 8),
                         ("hip_rotation", 8)):
            d = ours[f"{c}_{side}"].to_numpy() - ref[f"{c}_{side}"].to_numpy()
            assert np.sqrt(np.mean(d ** 2)) < limit, (c, side)


def test_inputs_folder_untouched_and_nothing_in_the_working_folder(gait2392_prepared, gait2392):
    inputs, out = gait2392_prepared
    assert sorted(p.name for p in inputs.iterdir()) == sorted(
        p.name for p in (gait2392.generic_model, gait2392.static, gait2392.markers, gait2392.scale_setup,
                         gait2392.scale_marker_set, gait2392.ik_setup))
    assert list((inputs.parent / "cwd").iterdir()) == []
    assert not (out / "opensim.log").exists()


def test_inverse_dynamics_of_the_prepared_model_matches_opensims(gait2392_prepared, gait2392):
    """The solver's next step: OpenSim's inverse dynamics of the prepared model and IK with the trial's
    ground forces (as ``solve --external-loads`` computes it) against OpenSim's stored inverse
    dynamics of the same subject: hip, knee and ankle moments within 3 N m RMS (measured 0.2-2.0,
    peaks 42-128 N m)."""
    from musclemetab.external_loads import compute_inverse_dynamics

    _, out = gait2392_prepared
    ours = read_storage(compute_inverse_dynamics(out / "model.osim", out / "ik.mot", gait2392.external_loads, 0.6, 1.5))
    ref = read_storage(gait2392.id).reindex(ours.index, method="nearest", tolerance=2e-3)
    cols = [c for c in ours.columns if c.startswith(("hip_", "knee_", "ankle_"))]
    assert len(cols) == 10
    for c in cols:
        assert np.sqrt(np.mean((ours[c] - ref[c]) ** 2)) < 3.0, c


def test_prepare_again_is_found_in_the_cache(gait2392_prepared, tmp_path, capsys, monkeypatch):
    """A second run with the same inputs (another output folder) takes scaling and IK from the cache,
    without OpenSim: the same files."""
    import musclemetab.opensim_bridge as bridge

    def no_opensim(target, *a, **k):
        raise AssertionError(f"OpenSim called: {target}")

    monkeypatch.setattr(bridge, "call", no_opensim)
    inputs, out = gait2392_prepared
    assert main(["prepare", "--model", str(inputs / "gait2392_thelen2003muscle.osim"), "--static",
                 str(inputs / "subject01_static.trc"), "--markers", str(inputs / "subject01_walk1.trc"), "--mass",
                 "72.6", "--scale-setup", str(inputs / "subject01_Setup_Scale.xml"), "--ik-setup",
                 str(inputs / "subject01_Setup_IK.xml"), "--out", str(tmp_path / "again")]) == 0
    for name in ("model.osim", "ik.mot", "ik_marker_errors.csv", "static_marker_errors.csv"):
        assert (tmp_path / "again" / name).read_bytes() == (out / name).read_bytes()
    captured = capsys.readouterr()
    assert "IK 121 frames 0.500-2.500 s" in captured.out
    assert "121 of 121 IK frames exceed OpenSim's best practice" in captured.err  # warned again from the cache


@pytest.mark.parametrize("change, message", [
    (("--static", "missing.trc"), "missing.trc: no such static trial"),
    (("--mass", "-3"), "--mass"),
    (("--window", "2:1"), "--window 2:1: T0 must be finite and before T1"),
])
def test_bad_input_one_line_nothing_written(gait2392, tmp_path, capsys, change, message):
    args = {"--model": str(gait2392.generic_model), "--static": str(gait2392.static),
            "--markers": str(gait2392.markers), "--mass": "72.6"}
    key, value = change
    args[key] = str(tmp_path / value) if value.endswith(".trc") else value
    argv = ["prepare", *[x for kv in args.items() for x in kv], "--out", str(tmp_path / "out")]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "out").exists()


def _prepare_error(gait2392, tmp_path, capsys, *extra, **files) -> str:
    """The one error line of ``musclemetab prepare`` of gait2392's files (``files`` replace
    ``model``, ``static``, ``markers``), checking that nothing was written."""
    args = {"--model": str(files.get("model", gait2392.generic_model)),
            "--static": str(files.get("static", gait2392.static)),
            "--markers": str(files.get("markers", gait2392.markers)), "--mass": "72.6"}
    argv = ["prepare", *[x for kv in args.items() for x in kv], *map(str, extra), "--out", str(tmp_path / "out")]
    assert main(argv) == 1
    err = [line for line in capsys.readouterr().err.strip().splitlines() if "warning:" not in line]
    assert len(err) == 1 and err[0].startswith("musclemetab: error: "), err
    assert not (tmp_path / "out").exists()
    return err[0]


def _no_opensim(monkeypatch):
    from musclemetab import opensim_bridge as bridge

    def no_opensim(target, *a, **k):
        raise AssertionError(f"OpenSim called: {target}")

    monkeypatch.setattr(bridge, "call", no_opensim)


def test_a_file_opensim_cannot_load_as_model_is_named_as_solve_names_it(gait2392, walking2_c3d, tmp_path, capsys):
    """prepare (a .trc or a C3D trial) and c3d --model say what solve says of the same file."""
    bad = tmp_path / "notamodel.osim"
    bad.write_text("hello")
    err = _prepare_error(gait2392, tmp_path, capsys, model=bad)
    assert err.startswith(f"musclemetab: error: {bad}: OpenSim cannot load this model (")
    assert err.endswith("check that it is a valid .osim file") and "lab:" not in err
    assert main(["solve", "--model", str(bad), "--ik", str(gait2392.ik), "--external-loads",
                 str(gait2392.external_loads), "--out", str(tmp_path / "s")]) == 1
    assert capsys.readouterr().err.strip() == err  # the same message, from the same function
    assert _prepare_error(gait2392, tmp_path, capsys, model=bad, static=walking2_c3d, markers=walking2_c3d) == err
    assert main(["c3d", str(walking2_c3d), "--model", str(bad), "--out", str(tmp_path / "c")]) == 1
    assert capsys.readouterr().err.strip().splitlines()[-1] == err and not (tmp_path / "c").exists()


@pytest.mark.parametrize("option, setup, message", [
    ("--scale-setup", "ik_setup", "--scale-setup needs OpenSim's ScaleTool setup, but this file holds an "
     "InverseKinematicsTool (give it as --ik-setup); give a ScaleTool setup"),
    ("--ik-setup", "scale_setup", "--ik-setup needs OpenSim's InverseKinematicsTool setup, but this file holds a "
     "ScaleTool (give it as --scale-setup); give an InverseKinematicsTool setup"),
    ("--scale-setup", "scale_marker_set", "--scale-setup needs OpenSim's ScaleTool setup, but this file holds a "
     "MarkerSet (give it as --marker-set); give a ScaleTool setup"),
])
def test_the_wrong_kind_of_setup_is_named_before_opensim_runs(gait2392, tmp_path, capsys, monkeypatch, option,
                                                               setup, message):
    _no_opensim(monkeypatch)
    path = getattr(gait2392, setup)
    assert _prepare_error(gait2392, tmp_path, capsys, option, path) == f"musclemetab: error: {path}: {message}"


@pytest.mark.parametrize("window, message", [
    ("1:4", "the marker data (0.000-2.500 s) ends 1.500 s before the --window end 4.000 s (this file and the "
     "--window share 1.000-2.500 s); choose a --window inside the marker data"),
    ("2.6:3", "the marker data (0.000-2.500 s) ends 0.500 s before the --window end 3.000 s; choose a --window "
     "inside the marker data"),
])
def test_a_window_outside_the_markers_is_refused_before_scaling(gait2392, tmp_path, capsys, monkeypatch, window,
                                                                 message):
    """As solve refuses a --window outside its files, never clipped, never a reversed range."""
    _no_opensim(monkeypatch)
    err = _prepare_error(gait2392, tmp_path, capsys, "--window", window)
    assert err == f"musclemetab: error: {gait2392.markers}: {message}"


def test_a_c3d_static_trial_the_model_cannot_match_names_the_c3d_and_both_remedies(gait2392, walking2_c3d, tmp_path,
                                                                                   capsys):
    """gait2392's generic model has no markers: the remedy is a marker set (or a ScaleTool setup); with
    gait2392's marker set, walking2's markers (Plug-in Gait names) still match none of them."""
    err = _prepare_error(gait2392, tmp_path, capsys, static=walking2_c3d, markers=walking2_c3d)
    assert err.startswith(f"musclemetab: error: {walking2_c3d}: the model {gait2392.generic_model} has no markers to "
                          "match the static trial's (RTH1, RFHD, RTH3, LTH2, LTH3, LTB1 ... and 38 more); give it a "
                          "marker-set file whose markers are named as the trial's (--marker-set FILE, e.g. OpenSim's "
                          "gait2392_Scale_MarkerSet.xml")
    assert err.endswith("or a ScaleTool setup whose measurements use the trial's markers (--scale-setup)")
    err = _prepare_error(gait2392, tmp_path, capsys, "--marker-set", gait2392.scale_marker_set, static=walking2_c3d,
                         markers=walking2_c3d)
    assert err.startswith(f"musclemetab: error: {walking2_c3d}: the model's markers (Sternum, R.Acromium, L.Acromium, "
                          "Top.Head, R.ASIS, L.ASIS ... and 33 more) and the static trial's (RTH1, ")
    assert "(--marker-set FILE), or a ScaleTool setup" in err and "musclemetab-prepare-" not in err


MARKER_STUDY = """
name = "from markers"
output = "out"
workflows = ["effort-gen"]
models = ["UM10"]

[[subjects]]
name = "{name}"
{model}
body_mass_kg = 72.6
height_m = 1.8

[[subjects.trials]]
name = "walk1"
{kinematics}
external_loads = "{loads}"
cycle = "auto"
"""


@pytest.mark.slow
def test_study_from_markers_runs_to_results(gait2392_prepared, gait2392, tmp_path, capsys):
    """A study file with a generic model, a static trial, the walk's markers and its ground forces only
    (no IK, no ID): the study scales, computes IK (into prepared/), has OpenSim compute the ID and
    runs to results.csv. Its model and IK are those of ``musclemetab prepare`` byte for byte, and its
    results those of the same study given the prepared files as 'model' and 'ik' (one solve: the
    memo); run again, nothing is redone."""
    import pandas as pd

    inputs, prepared = gait2392_prepared
    study = tmp_path / "markers.toml"
    study.write_text(MARKER_STUDY.format(
        name="s01", loads=gait2392.external_loads,
        model=f'generic_model = "{inputs / "gait2392_thelen2003muscle.osim"}"\n'
              f'static = "{inputs / "subject01_static.trc"}"\nscale_setup = "{inputs / "subject01_Setup_Scale.xml"}"',
        kinematics=f'markers = "{inputs / "subject01_walk1.trc"}"\nik_setup = "{inputs / "subject01_Setup_IK.xml"}"'))
    files = tmp_path / "files.toml"
    files.write_text(MARKER_STUDY.format(name="s01", loads=gait2392.external_loads,
                                         model=f'model = "{prepared / "model.osim"}"',
                                         kinematics=f'ik = "{prepared / "ik.mot"}"'))
    assert main(["run", str(study), "--workers", "1", "--no-progress"]) == 0
    out = tmp_path / "out"
    for name in ("model.osim", "static_marker_errors.csv"):
        assert (out / "prepared" / "s01" / name).read_bytes() == (prepared / name).read_bytes()
    for name in ("ik.mot", "ik_marker_errors.csv"):
        assert (out / "prepared" / "s01" / "walk1" / name).read_bytes() == (prepared / name).read_bytes()
    ours = pd.read_csv(out / "results.csv")
    assert len(ours) == 1 and 3 < ours["whole_body_W_per_kg"].iloc[0] < 12
    assert main(["run", str(files), "--workers", "1", "--no-progress", "--out", str(tmp_path / "ref")]) == 0
    row = pd.read_csv(tmp_path / "ref" / "results.csv").iloc[0]
    for c in ("whole_body_W_per_kg", "leg_muscles_W", "cycle_start_s", "cycle_end_s", "stance_energy_share_pct"):
        assert ours[c].iloc[0] == pytest.approx(row[c], rel=1e-9), c
    capsys.readouterr()
    assert main(["run", str(study), "--workers", "1", "--no-progress"]) == 0
    assert "0 run, 1 up to date" in capsys.readouterr().out



def test_study_keys_of_markers_checked_when_read(gait2392, walking2_c3d, tmp_path):
    """The keys of a study from markers, and their conflicts, refused when the file is read; where the
    study's own files will be."""
    from musclemetab.errors import OptionError
    from musclemetab.study.spec import study_from_dict

    def study(subject: dict, trial: dict):
        data = {"name": "s", "output": str(tmp_path / "out"), "workflows": ["effort-gen"], "models": ["UM10"],
                "subjects": [{"name": "s01", "body_mass_kg": 72.6, **subject,
                              "trials": [{"name": "walk1", **trial}]}]}
        return study_from_dict(data, base=tmp_path)

    generic = {"generic_model": str(gait2392.generic_model), "static": str(gait2392.static)}
    walk = {"markers": str(gait2392.markers), "external_loads": str(gait2392.external_loads)}
    s = study(generic, walk).subjects[0]
    assert s.model == tmp_path / "out" / "prepared" / "s01" / "model.osim"
    assert s.trials[0].ik == tmp_path / "out" / "prepared" / "s01" / "walk1" / "ik.mot"
    assert s.trials[0].external_loads == gait2392.external_loads.resolve()
    for subject, trial, message in (
        ({**generic, "model": str(gait2392.model)}, walk, "not both"),
        ({"model": str(gait2392.model), "static": str(gait2392.static)}, walk, "'static' scale a 'generic_model'"),
        ({"generic_model": str(gait2392.generic_model)}, walk, "'static' is required"),
        (generic, {**walk, "ik": str(gait2392.ik)}, "give 'ik' or 'markers'"),
        (generic, {"ik": str(gait2392.ik), "ik_setup": str(gait2392.ik_setup), "id": str(gait2392.id)},
         "'ik_setup' needs 'markers'"),
        (generic, {"markers": str(gait2392.markers)}, "'id' is required"),
    ):
        with pytest.raises(OptionError, match=message):
            study(subject, trial)
    # a setup of the other OpenSim tool: refused when the file is read, naming the study's keys
    from musclemetab.errors import InputFileError

    for subject, trial, key, other in (({**generic, "scale_setup": str(gait2392.ik_setup)}, walk, "'scale_setup'",
                                        "'ik_setup'"),
                                       (generic, {**walk, "ik_setup": str(gait2392.scale_setup)}, "'ik_setup'",
                                        "'scale_setup'")):
        with pytest.raises(InputFileError, match=rf"subject 's01'.*: {key} needs OpenSim's \w+ setup, but this file "
                                                 rf"holds an? \w+ \(give it as {other}\)"):
            study(subject, trial)
    # a C3D trial with force plates and no forces given: its ExternalLoads will be the study's own
    c3d = study({"model": str(gait2392.model)}, {"markers": str(walking2_c3d)}).subjects[0].trials[0]
    assert c3d.external_loads == tmp_path / "out" / "prepared" / "s01" / "walk1" / "markers_grf.xml"
    assert c3d.ik == tmp_path / "out" / "prepared" / "s01" / "walk1" / "ik.mot"


@pytest.fixture(scope="module")
def walking2_c3d():
    from musclemetab.datasets import c3d_walking

    return c3d_walking()


def _gait2392_as_c3d(gait2392, path):
    """OpenSim's gait2392 walk (markers at 60 Hz, 0-2.483 s, and its two ground-force sets at
    600 Hz) written as a lab would export it: a C3D file in mm, z up, the forces as two type-2 plates'
    analog channels (force and moment in each plate's own frame, z down), the left foot's forces on
    plate 1 and the right's on plate 2, the plates side by side (plate 1 on the left: lab y > 20 mm)."""
    import ezc3d
    from ezc3d import ezc3d as swig

    from musclemetab.mocap import read_trc

    markers = read_trc(gait2392.markers)
    grf = read_storage(gait2392.grf)
    n, ratio = 150, 10
    to_lab = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # OpenSim (x fwd, y up, z right) -> lab (z up)
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [60.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(markers.names)
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, len(markers.names), n))
    pts[:3] = np.transpose(markers.xyz[:n] @ to_lab.T * 1000, (2, 1, 0))
    c["data"]["points"] = pts
    c["parameters"]["ANALOG"]["RATE"]["value"] = [600.0]
    c["parameters"]["ANALOG"]["LABELS"]["value"] = tuple(f"{a}{k}" for k in (1, 2) for a in ("Fx", "Fy", "Fz", "Mx", "My", "Mz"))
    c["parameters"]["ANALOG"]["UNITS"]["value"] = ("N", "N", "N", "Nmm", "Nmm", "Nmm") * 2
    rows = slice(0, n * ratio)
    plate_of = {"1_": 0, "": 1}  # the left foot's forces on plate 1
    surface = -7.5  # mm: the centres of pressure's height in the file (py = -0.0075 m)
    corners = np.zeros((3, 4, 2))
    analog = np.zeros((1, 12, n * ratio))
    flip = np.diag([1.0, -1.0, -1.0])  # plate frame: x along the lab's, z down (corners' order below)
    for prefix, k in plate_of.items():
        y0, y1 = (20.0, 600.0) if k == 0 else (-600.0, 20.0)
        corners[:, :, k] = np.array([[1500, y0, surface], [-500, y0, surface], [-500, y1, surface], [1500, y1, surface]]).T
        centre = corners[:, :, k].mean(axis=1)
        f = grf[[f"{prefix}ground_force_v{a}" for a in "xyz"]].to_numpy()[rows] @ to_lab.T
        p = grf[[f"{prefix}ground_force_p{a}" for a in "xyz"]].to_numpy()[rows] @ to_lab.T * 1000
        free = grf[f"{prefix}ground_torque_y"].to_numpy()[rows] * 1000
        m = np.cross(p - centre, f) + free[:, None] * np.array([0, 0, 1.0])
        analog[0, 6 * k:6 * k + 3] = (f @ flip.T).T
        analog[0, 6 * k + 3:6 * k + 6] = (m @ flip.T).T
    c["data"]["analogs"] = analog
    for name, value in (("USED", np.array([2.0])), ("TYPE", np.array([2.0, 2.0])),
                        ("CHANNEL", np.arange(1.0, 13.0).reshape(2, 6).T), ("ZERO", np.array([0.0, 0.0]))):
        c.add_parameter("FORCE_PLATFORM", name, value)
        c["parameters"]["FORCE_PLATFORM"][name]["type"] = swig.INT
    c.add_parameter("FORCE_PLATFORM", "CORNERS", corners)
    c.add_parameter("FORCE_PLATFORM", "ORIGIN", np.zeros((3, 2)))
    c.write(str(path))
    return path


@pytest.fixture(scope="module")
def c3d_prepared(gait2392, tmp_path_factory):
    import warnings

    from musclemetab.errors import MarkerErrorWarning

    root = tmp_path_factory.mktemp("c3d")
    walk = _gait2392_as_c3d(gait2392, root / "walk1.c3d")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MarkerErrorWarning)
        assert main(["prepare", "--model", str(gait2392.generic_model), "--static", str(gait2392.static),
                     "--markers", str(walk), "--mass", "72.6", "--scale-setup", str(gait2392.scale_setup),
                     "--ik-setup", str(gait2392.ik_setup), "--out", str(root / "out")]) == 0
    return root / "out"


def test_c3d_walk_plates_given_to_their_feet_as_opensim_does(c3d_prepared, gait2392):
    """The C3D's plates, left foot on plate 1: each given to its foot from the data, as OpenSim's own
    ExternalLoads of this trial applies the two force sets (left on calcn_l, right on calcn_r); the
    forces and centres of pressure those of OpenSim's file."""
    from musclemetab.external_loads import read_external_loads

    rec = json.loads((c3d_prepared / "prepare.json").read_text())
    assert {c["plate"]: c["side"] for c in rec["c3d"]["contacts"]} == {1: "l", 2: "r"}
    assert not any(c["two_feet"] for c in rec["c3d"]["contacts"])
    loads = read_external_loads(c3d_prepared / "markers_grf.xml")
    theirs = {f.body: f.force_identifier for f in read_external_loads(gait2392.external_loads).forces}
    ours = read_storage(loads.datafile)
    ref = read_storage(gait2392.grf)
    for f in loads.forces:
        t = ours.index.to_numpy()
        on = ours[f"{f.force_identifier}y"].to_numpy() > 100
        r = ref.reindex(t, method="nearest", tolerance=1e-3)
        for a in "xyz":
            assert np.allclose(ours[f"{f.force_identifier}{a}"].to_numpy()[on],
                               r[f"{theirs[f.body]}{a}"].to_numpy()[on], atol=0.05), (f.body, a)
            pid, their_p = f.point_identifier, theirs[f.body].replace("_v", "_p")
            assert np.allclose(ours[f"{pid}{a}"].to_numpy()[on], r[f"{their_p}{a}"].to_numpy()[on], atol=2e-3), (f.body, a)


def test_c3d_walk_ik_matches_the_trc_walk(c3d_prepared, gait2392_prepared):
    """IK from the C3D's markers equals IK from the TRC within 0.2 degrees (the same markers, stored as
    32-bit floats in the C3D, solved to the setup's accuracy, 1e-5; measured 0.12 at most)."""
    _, from_trc = gait2392_prepared
    a, b = read_storage(c3d_prepared / "ik.mot"), read_storage(from_trc / "ik.mot")
    b = b.reindex(a.index, method="nearest", tolerance=1e-6)
    assert len(a) == 120  # 0.5-2.483 s: the setup's 0.5-2.5 s clipped to the file
    assert np.abs(a.to_numpy() - b.to_numpy()).max() < 0.2


@pytest.mark.slow
def test_study_from_a_c3d_file_alone_runs_to_results(c3d_prepared, gait2392_prepared, gait2392, tmp_path):
    """A study whose walking trial is a C3D file alone (markers and force plates; no IK, no ID, no
    ground-force file): the plates' forces are given to the feet, OpenSim computes the ID, and the
    rate is that of the same walk given as OpenSim's .trc and ground-force files (IK within 0.2 deg,
    forces within 0.05 N of them: within 1 %)."""
    import pandas as pd

    inputs, prepared = gait2392_prepared
    walk = c3d_prepared.parent / "walk1.c3d"
    study = tmp_path / "c3d.toml"
    study.write_text(f'''
name = "from a C3D file"
output = "out"
workflows = ["effort-gen"]
models = ["UM10"]

[[subjects]]
name = "s01"
generic_model = "{inputs / "gait2392_thelen2003muscle.osim"}"
static = "{inputs / "subject01_static.trc"}"
scale_setup = "{inputs / "subject01_Setup_Scale.xml"}"
body_mass_kg = 72.6
height_m = 1.8

[[subjects.trials]]
name = "walk1"
markers = "{walk}"
ik_setup = "{inputs / "subject01_Setup_IK.xml"}"
cycle = "auto"
''')
    files = tmp_path / "files.toml"
    files.write_text(MARKER_STUDY.format(name="s01", loads=gait2392.external_loads,
                                         model=f'model = "{prepared / "model.osim"}"',
                                         kinematics=f'ik = "{prepared / "ik.mot"}"'))
    import warnings

    from musclemetab.errors import MarkerErrorWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MarkerErrorWarning)
        assert main(["run", str(study), "--workers", "1", "--no-progress"]) == 0
    ours = pd.read_csv(tmp_path / "out" / "results.csv").iloc[0]
    assert (tmp_path / "out" / "prepared" / "s01" / "walk1").is_dir()
    assert main(["run", str(files), "--workers", "1", "--no-progress", "--out", str(tmp_path / "ref")]) == 0
    ref = pd.read_csv(tmp_path / "ref" / "results.csv").iloc[0]
    assert ours["cycle_start_s"] == pytest.approx(ref["cycle_start_s"], abs=0.005)
    assert ours["cycle_end_s"] == pytest.approx(ref["cycle_end_s"], abs=0.005)
    assert ours["whole_body_W_per_kg"] == pytest.approx(ref["whole_body_W_per_kg"], rel=0.01)
