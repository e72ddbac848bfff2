"""Muscle geometry against the authors' OpenSim 4.1 MuscleAnalysis and OpenSim 4.6 itself."""

from __future__ import annotations

import numpy as np
import pytest

from musclemetab.errors import ModelError, MissingColumnError, UnknownCoordinateError, UnknownMuscleError
from musclemetab.geometry import compute_geometry
from musclemetab.io import read_storage
from musclemetab.model import default_dofs, read_model

DOFS = ["ankle_angle_r", "knee_angle_r", "hip_flexion_r", "hip_adduction_r", "hip_rotation_r"]
RIGHT_LEG = (
    "addbrev_r addlong_r addmagDist_r addmagIsch_r addmagMid_r addmagProx_r bflh_r bfsh_r edl_r ehl_r "
    "fdl_r fhl_r gaslat_r gasmed_r glmax1_r glmax2_r glmax3_r glmed1_r glmed2_r glmed3_r glmin1_r "
    "glmin2_r glmin3_r grac_r iliacus_r perbrev_r perlong_r piri_r psoas_r recfem_r sart_r semimem_r "
    "semiten_r soleus_r tfl_r tibant_r tibpost_r vasint_r vaslat_r vasmed_r"
).split()


@pytest.fixture(scope="module")
def normal_geometry(example, geometry_cache):
    """The normal trial's geometry, through OpenSim once per test run (the session's cache)."""
    return compute_geometry(example.model, example.ik["normal"], cache_dir=geometry_cache)


def test_selection_is_the_forty_right_leg_muscles(normal_geometry):
    assert default_dofs("r") == DOFS
    assert list(normal_geometry.muscles) == RIGHT_LEG
    assert list(normal_geometry.dofs) == DOFS
    assert normal_geometry.lmt_m.shape == (119, 40)
    assert normal_geometry.moment_arms_m.shape == (119, 5, 40)


def test_lengths_match_opensim41_muscle_analysis(example, normal_geometry):
    ref = read_storage(example.reference_muscle_analysis / "IK_sub1_normal_MuscleAnalysis_Length.sto")
    np.testing.assert_allclose(normal_geometry.time, ref.index.to_numpy(), atol=1e-9)
    diff = np.abs(ref[RIGHT_LEG].to_numpy() - normal_geometry.lmt_m)
    assert diff.max() < 0.1e-3, f"largest length difference {diff.max() * 1e3:.4f} mm"


@pytest.mark.parametrize("dof", DOFS)
def test_moment_arms_match_opensim41_muscle_analysis(example, normal_geometry, dof):
    ref = read_storage(example.reference_muscle_analysis / f"IK_sub1_normal_MuscleAnalysis_MomentArm_{dof}.sto")
    diff = np.abs(ref[RIGHT_LEG].to_numpy() - normal_geometry.moment_arm(dof))
    worst = RIGHT_LEG[int(np.unravel_index(diff.argmax(), diff.shape)[1])]
    assert diff.max() < 0.3e-3, f"{dof}: {diff.max() * 1e3:.4f} mm ({worst})"


def test_moment_arms_equal_opensim46_compute_moment_arm(example, normal_geometry, tmp_path):
    """The fast method against Muscle.computeMomentArm, OpenSim 4.6, on every frame."""
    api = compute_geometry(example.model, example.ik["normal"], method="opensim", use_cache=False)
    assert api.muscles == normal_geometry.muscles
    np.testing.assert_allclose(normal_geometry.moment_arms_m, api.moment_arms_m, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(normal_geometry.lmt_m, api.lmt_m)


def test_coupled_knee_coordinate_comes_from_its_coupler(example, tmp_path, geometry_cache):
    """Corrupting the knee_angle_r_beta column must change nothing: it is never read (the
    corrupted file's geometry computed by OpenSim, the fast trial's from the session's cache)."""
    ik = read_storage(example.ik["fast"])
    ik["knee_angle_r_beta"] = 57.0
    from musclemetab.io import write_storage

    path = write_storage(tmp_path / "ik_beta.mot", ik, in_degrees=True)
    a = compute_geometry(example.model, example.ik["fast"], cache_dir=geometry_cache)
    b = compute_geometry(example.model, path, use_cache=False)
    np.testing.assert_array_equal(a.lmt_m, b.lmt_m)
    np.testing.assert_array_equal(a.moment_arms_m, b.moment_arms_m)


def test_cache_second_call_does_no_opensim_work(example, tmp_path, monkeypatch):
    first = compute_geometry(example.model, example.ik["slow"], cache_dir=tmp_path)
    assert first.source["cached"] is False
    import musclemetab.opensim_bridge as bridge

    def forbidden(*a, **k):
        raise AssertionError("OpenSim was called although the result is cached")

    monkeypatch.setattr(bridge, "call", forbidden)
    second = compute_geometry(example.model, example.ik["slow"], cache_dir=tmp_path)
    assert second.source["cached"] is True
    np.testing.assert_array_equal(first.lmt_m, second.lmt_m)
    np.testing.assert_array_equal(first.moment_arms_m, second.moment_arms_m)
    assert second.muscles == first.muscles and second.dofs == first.dofs


def test_cache_key_follows_content(example, tmp_path):
    compute_geometry(example.model, example.ik["fast"], cache_dir=tmp_path)
    ik = read_storage(example.ik["fast"])
    ik["ankle_angle_r"] += 5.0
    from musclemetab.io import write_storage

    changed = write_storage(tmp_path / "ik.mot", ik, in_degrees=True)
    g = compute_geometry(example.model, changed, cache_dir=tmp_path)
    assert g.source["cached"] is False
    # a corrupted cache entry is recomputed, not trusted
    for f in tmp_path.glob("*.npz"):
        f.write_bytes(b"garbage")
    again = compute_geometry(example.model, changed, cache_dir=tmp_path)
    assert again.source["cached"] is False
    np.testing.assert_array_equal(again.lmt_m, g.lmt_m)


def test_explicit_muscles_by_name(example, normal_geometry):
    g = compute_geometry(example.model, example.ik["normal"], muscles=["soleus_r", "addbrev_r"], use_cache=False)
    assert g.muscles == ("soleus_r", "addbrev_r")
    np.testing.assert_array_equal(g.lmt_m[:, 0], normal_geometry.lmt_m[:, RIGHT_LEG.index("soleus_r")])


def test_model_facts(example):
    info = read_model(example.model)
    assert info.body_mass_kg == pytest.approx(72.6, abs=1e-9)
    assert len(info.muscles) == 80 and info.muscles.names[:2] == ("addbrev_r", "addlong_r")
    sol = info.muscles.subset(["soleus_r"])
    assert sol.max_contraction_velocity[0] == 10.0
    generic = read_model(example.calibration_model)  # no max_contraction_velocity element
    assert np.all(generic.muscles.max_contraction_velocity == 10.0)
    assert generic.muscles.subset(["soleus_r"]).max_isometric_force_N[0] == pytest.approx(6194.84, abs=0.01)
    assert {"dependent": "knee_angle_r_beta", "independent": ["knee_angle_r"]} in info.couplers


def test_bad_inputs(example, tmp_path):
    with pytest.raises(ModelError, match="no such model file"):
        compute_geometry(tmp_path / "none.osim", example.ik["normal"])
    junk = tmp_path / "junk.osim"
    junk.write_text("<OpenSimDocument><Model name='x'><broken")
    with pytest.raises(ModelError, match="junk.osim"):
        compute_geometry(junk, example.ik["normal"], use_cache=False)
    with pytest.raises(MissingColumnError, match="foo_r"):
        compute_geometry(example.model, example.ik["normal"], dofs=["foo_r"])
    ik = read_storage(example.ik["normal"])
    ik["foo_r"] = 0.0
    from musclemetab.io import write_storage

    path = write_storage(tmp_path / "extra.mot", ik, in_degrees=True)
    with pytest.raises(UnknownCoordinateError, match="no coordinate 'foo_r'"):
        compute_geometry(example.model, path, dofs=["foo_r"], use_cache=False)
    with pytest.raises(UnknownCoordinateError, match="locked or coupled"):
        compute_geometry(example.model, path, dofs=["knee_angle_r_beta"], use_cache=False)
    with pytest.raises(UnknownMuscleError, match="soleus_x"):
        compute_geometry(example.model, example.ik["normal"], muscles=["soleus_x"], use_cache=False)


def _cli(capsys, *args) -> tuple[int, str]:
    """The command line's ``main`` in this process (``python -m musclemetab`` in a process of its
    own is tests/test_cli.py's): ``(status, what it printed on standard error)``."""
    from musclemetab.commands import main

    status = main(list(args))
    return status, capsys.readouterr().err


def test_cli_geometry_writes_opensim_files(example, tmp_path, normal_geometry, capsys):
    out = tmp_path / "geom"
    status, err = _cli(capsys, "geometry", "--model", str(example.model), "--ik", str(example.ik["normal"]),
                       "--out", str(out))
    assert status == 0, err
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted([".musclemetab-files", "muscle_tendon_lengths.sto"]
                           + [f"moment_arms_{d}.sto" for d in DOFS])
    lengths = read_storage(out / "muscle_tendon_lengths.sto")
    assert list(lengths.columns) == RIGHT_LEG
    np.testing.assert_allclose(lengths.to_numpy(), normal_geometry.lmt_m, rtol=1e-11)
    knee = read_storage(out / "moment_arms_knee_angle_r.sto")
    np.testing.assert_allclose(knee.to_numpy(), normal_geometry.moment_arm("knee_angle_r"), rtol=1e-10, atol=1e-15)


@pytest.mark.parametrize(
    "args, phrase",
    [
        (["--ik", "{id}"], "missing DOF columns"),
        (["--ik", "{ik}", "--dofs", "ankle_angle_q"], "ankle_angle_q"),
        (["--ik", "{missing}"], "no such file"),
    ],
)
def test_cli_errors_one_line_no_output(example, tmp_path, capsys, args, phrase):
    out = tmp_path / "out"
    subs = {"{id}": str(example.id["normal"]), "{ik}": str(example.ik["normal"]), "{missing}": str(tmp_path / "x.mot")}
    args = [subs.get(a, a) for a in args]
    status, err = _cli(capsys, "geometry", "--model", str(example.model), *args, "--out", str(out))
    assert status == 1
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("musclemetab: error:") and phrase in lines[0]
    assert not out.exists() or not any(out.iterdir())


def test_locked_knee_follows_the_motion_and_is_refused_by_name(example, tmp_path):
    """A model locking knee_angle_r: the muscle paths still take the IK's knee angle (lengths
    equal OpenSim 4.1's MuscleAnalysis of the unlocked model along the same motion, which the
    authors stored), and the geometry and the solve refuse the motion, naming the knee, instead
    of dropping the knee and its muscles in silence."""
    from musclemetab.errors import DataMismatchError
    from musclemetab.io import read_table
    from musclemetab.opensim_bridge import call
    from musclemetab.redundancy.run import solve_files

    from model_edits import with_locked_coordinate

    locked = with_locked_coordinate(example.model, "knee_angle_r", tmp_path / "locked_knee.osim")
    ik = read_table(example.ik["normal"])
    muscles = ["semiten_r", "bfsh_r", "vasmed_r", "recfem_r"]
    raw = call("model_ops:muscle_geometry", str(locked), ik.index.copy(),
               {c: np.ascontiguousarray(ik[c]) for c in ik.columns}, True, ["hip_flexion_r"], muscles)
    ref = read_storage(example.reference_muscle_analysis / "IK_sub1_normal_MuscleAnalysis_Length.sto")
    diff = np.abs(ref[muscles].to_numpy() - raw["lmt_m"])
    assert diff.max() < 0.1e-3, f"largest length difference {diff.max() * 1e3:.4f} mm"
    assert np.ptp(ik["knee_angle_r"]) > 50  # the motion flexes the knee by more than 50 deg
    with pytest.raises(DataMismatchError, match=r"locks knee_angle_r \(locked at 0 deg; the motion takes it over"):
        compute_geometry(locked, example.ik["normal"], cache_dir=tmp_path)
    with pytest.raises(DataMismatchError, match="knee_angle_r"):
        solve_files(locked, example.ik["normal"], example.id["normal"], window=(0.6, 0.8), cache_dir=tmp_path)
    # locked coordinates the motion holds at their value (the example's subtalar and mtp) pass
    assert compute_geometry(example.model, example.ik["normal"], cache_dir=tmp_path).dofs == tuple(DOFS)


def test_a_message_lists_ten_names_and_counts_the_rest(example):
    """150 000 unknown muscle names gave an error line of close to a megabyte: every message
    listing names shows the first ten and how many more (messages.name_list)."""
    from musclemetab.messages import name_list

    assert name_list(["a", "b"]) == "a, b"
    assert name_list([f"m{i}" for i in range(12)]) == "m0, m1, m2, m3, m4, m5, m6, m7, m8, m9 ... and 2 more"
    names = [f"mystery{i}_r" for i in range(150_000)]
    with pytest.raises(UnknownMuscleError) as info:
        compute_geometry(example.model, example.ik["normal"], muscles=names, use_cache=False)
    text = str(info.value)
    assert "mystery0_r, mystery1_r" in text and text.count("mystery") == 10
    assert "... and 149 990 more" in text and len(text) < 500


def test_every_message_naming_muscles_lists_ten_and_counts_the_rest():
    """The same rule where the package names muscles of a problem: excluded names it lacks, a
    muscle a solution lacks, muscles without parameters, EMG and factors of unknown muscles."""
    import numpy as np

    from musclemetab.redundancy.inputs import GeometryArrays
    from musclemetab.redundancy.run import exclude_from_geometry
    from musclemetab.redundancy.solution import Solution

    muscles = [f"m{i}_r" for i in range(40)]
    geometry = GeometryArrays(np.linspace(0, 1, 5), muscles, ["knee_angle_r"], np.ones((5, 40)), np.zeros((5, 1, 40)))
    wrong = [f"x{i}_r" for i in range(25)]
    with pytest.raises(UnknownMuscleError) as info:
        exclude_from_geometry(geometry, wrong)
    text = str(info.value)
    assert text.count("x") - text.count("exclude") == 10 and "... and 15 more" in text
    sol = Solution.__new__(Solution)
    object.__setattr__(sol, "muscles", muscles)
    with pytest.raises(UnknownMuscleError) as info:
        sol.muscle_index("nothing_r")
    assert str(info.value).count("_r") == 11 and "... and 30 more" in str(info.value)
