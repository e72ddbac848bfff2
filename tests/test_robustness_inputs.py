"""Adversarial input files for geometry, solve and metabolics: wrong units, non-finite values,
time stamps that are not seconds, moments normalised by body mass, extreme passive
parameters, damaged or foreign cache entries, unusable cache folders, outputs that cannot
be written. Each case is refused with a one-line error naming the file, column, muscle,
option or cache entry, or handled with a warning; the cheap ones fail before OpenSim or the
solver does any work (an empty geometry cache proves it)."""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from musclemetab.commands import main
from musclemetab.errors import (
    CacheWarning,
    DataMismatchError,
    InputFileError,
    LargeReserveWarning,
    StorageFormatError,
    TimeColumnError,
)
from musclemetab.geometry import compute_geometry
from musclemetab.io import read_storage, write_storage
from musclemetab.redundancy.inputs import DEFAULT_DOFS, read_kinematics

FRAMES = slice(48, 70)  # 22 frames (late stance) of the example's normal trial: cheap geometry, enough for the filter


@pytest.fixture(scope="module")
def short_trial(example, tmp_path_factory):
    """A 0.21 s piece of the normal trial: IK (degrees), ID covering it, and ID x3."""
    folder = tmp_path_factory.mktemp("short")
    ik = read_storage(example.ik["normal"]).iloc[FRAMES]
    idd = read_storage(example.id["normal"])
    idd = idd.loc[ik.index[0] - 0.05: ik.index[-1] + 0.05]
    paths = {
        "ik": write_storage(folder / "ik.mot", ik, in_degrees=True),
        "id": write_storage(folder / "id.sto", idd, in_degrees=False),
        "id_x3": write_storage(folder / "id_x3.sto", idd * 3.0, in_degrees=False),
        "id_per_kg": write_storage(folder / "id_per_kg.sto", idd / example.body_mass_kg, in_degrees=False),
    }
    return paths


def _edited_ik(example, tmp_path, edit):
    ik = read_storage(example.ik["normal"])
    in_degrees = edit(ik)
    return write_storage(tmp_path / "edited.mot", ik, in_degrees=in_degrees)


def _degrees_labelled_radians(ik):
    return False


def _radians_labelled_degrees(ik):
    for c in ik.columns:
        if not c.endswith(("_tx", "_ty", "_tz")):
            ik[c] = np.deg2rad(ik[c])
    return True


def _one_inf(ik):
    ik.iloc[40, ik.columns.get_loc("knee_angle_r")] = np.inf
    return True


def _time_inf(ik):
    t = ik.index.to_numpy().copy()
    t[-1] = np.inf
    ik.index = t
    return True


def _milliseconds(ik):
    ik.index = ik.index.to_numpy() * 1000.0
    return True


IK_CASES = [
    (_degrees_labelled_radians, DataMismatchError, "inDegrees=no but column 'knee_angle_r' reaches 64.85"),
    (_radians_labelled_degrees, DataMismatchError, "look like radians"),
    (_one_inf, DataMismatchError, "column 'knee_angle_r' is inf at data row 41"),
    (_time_inf, TimeColumnError, "column 'time' is inf at data row 119"),
    (_milliseconds, TimeColumnError, "look like milliseconds"),
]


@pytest.mark.parametrize("edit, error, words", IK_CASES, ids=[c[0].__name__ for c in IK_CASES])
def test_geometry_and_solver_refuse_the_same_ik_files(example, tmp_path, edit, error, words):
    path = _edited_ik(example, tmp_path, edit)
    cache = tmp_path / "cache"
    with pytest.raises(error, match=words) as info:
        compute_geometry(example.model, path, cache_dir=cache)
    assert str(path) in str(info.value)
    with pytest.raises(error, match=words):
        read_kinematics(path, DEFAULT_DOFS)
    assert not cache.exists() or not any(cache.iterdir())  # nothing cached, no OpenSim work


@pytest.mark.parametrize("edit, error, words", IK_CASES[:2], ids=["degrees_labelled_radians", "radians_labelled_degrees"])
def test_geometry_command_refuses_mislabelled_units_in_one_line(example, tmp_path, capsys, edit, error, words):
    path = _edited_ik(example, tmp_path, edit)
    assert main(["geometry", "--model", str(example.model), "--ik", str(path), "--out", str(tmp_path / "g")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("musclemetab: error: ") and str(path) in err
    assert not (tmp_path / "g").exists()


def test_id_time_in_milliseconds_and_inf_moments(example, tmp_path):
    from musclemetab.redundancy.inputs import read_inverse_dynamics

    idd = read_storage(example.id["normal"])
    ms = idd.copy()
    ms.index = ms.index.to_numpy() * 1000.0
    p = write_storage(tmp_path / "ms.sto", ms)
    with pytest.raises(TimeColumnError, match="ms.sto.*milliseconds"):
        read_inverse_dynamics(p)
    idd.iloc[3, idd.columns.get_loc("knee_angle_r_moment")] = -np.inf
    p = write_storage(tmp_path / "inf.sto", idd)
    with pytest.raises(DataMismatchError, match="inf.sto: column 'knee_angle_r_moment' is -inf at data row 4"):
        read_inverse_dynamics(p)


def test_a_folder_given_as_a_file_says_so(example, tmp_path):
    with pytest.raises(StorageFormatError, match="is a folder, not a file"):
        read_storage(tmp_path)
    from musclemetab.errors import ModelError

    with pytest.raises(ModelError, match="is a folder, not a model file"):
        compute_geometry(tmp_path, example.ik["normal"])


# ----------------------------------------------------------------------------- ID per kg, passive extremes
def test_id_normalised_by_body_mass_is_refused(example, short_trial):
    from musclemetab.redundancy import solve_files

    with pytest.raises(DataMismatchError, match="normalised to body mass") as info:
        solve_files(example.model, short_trial["ik"], short_trial["id_per_kg"], "effort-gen")
    msg = str(info.value)
    assert str(short_trial["id_per_kg"]) in msg and "72.6 kg" in msg


@pytest.mark.parametrize("row, words", [
    ("soleus_r,1e12,1.0,0.6", "'soleus_r' has kPE = 1e\\+12"),
    ("soleus_r,4.0,1e300,0.6", "'soleus_r' has s0 = 1e\\+300"),
    ("soleus_r,4.0,1.0,-0.6", "kPE and sM must be positive"),
])
def test_passive_parameters_outside_plausible_ranges_are_refused_before_solving(example, tmp_path, capsys, row, words):
    from musclemetab.redundancy.workflows import read_passive_parameters

    csv = tmp_path / "passive.csv"
    csv.write_text(f"muscle,kPE,s0,sM\n{row}\n")
    with pytest.raises(InputFileError, match=words):
        read_passive_parameters(csv)
    cache = tmp_path / "cache"
    code = main(["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
                 str(example.id["normal"]), "--workflow", "effort-cal", "--passive", str(csv),
                 "--cache-dir", str(cache), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1 and "passive.csv" in err
    assert not cache.exists() and not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- outputs
@pytest.mark.parametrize("command", ["geometry", "solve", "metabolics"])
@pytest.mark.parametrize("kind", ["file", "unwritable"])
def test_an_out_that_cannot_be_a_folder_is_refused_before_any_work(example, tmp_path, capsys, command, kind):
    existing = tmp_path / "taken.txt"
    existing.write_text("keep")
    out = str(existing) if kind == "file" else "/proc/musclemetab-out"
    cache = tmp_path / "cache"
    args = {
        "geometry": ["geometry", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--no-cache"],
        "solve": ["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
                  str(example.id["normal"]), "--cache-dir", str(cache)],
        "metabolics": ["metabolics", "--solution", str(tmp_path), "--mass", "72.6", "--height", "1.743"],
    }[command]
    assert main(args + ["--out", out]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--out {out}" in err
    assert existing.read_text() == "keep" and not cache.exists()


# ----------------------------------------------------------------------------- geometry cache
def _only_entry(folder: Path) -> Path:
    """The geometry entry of a cache folder (the model's layout has its own, ``model-*``)."""
    (entry,) = (p for p in folder.glob("*.npz") if not p.name.startswith("model-"))
    return entry


def test_cache_entries_are_checked_deleted_and_recomputed(example, short_trial, tmp_path):
    cache = tmp_path / "cache"
    first = compute_geometry(example.model, short_trial["ik"], cache_dir=cache)
    entry = _only_entry(cache)
    assert compute_geometry(example.model, short_trial["ik"], cache_dir=cache).source["cached"] is True

    # lengths x1.05, written back with the old checksum: detected, deleted, recomputed
    with np.load(entry) as z:
        arrays = dict(z)
    arrays["lmt_m"] = arrays["lmt_m"] * 1.05
    with open(entry, "wb") as f:
        np.savez(f, **arrays)
    with pytest.warns(CacheWarning, match=f"{entry.name} does not match its checksum"):
        again = compute_geometry(example.model, short_trial["ik"], cache_dir=cache)
    assert again.source["cached"] is False
    np.testing.assert_array_equal(again.lmt_m, first.lmt_m)

    # another trial's (intact) entry under this key: its shape does not fit the IK file
    other = compute_geometry(example.model, short_trial["ik"], cache_dir=tmp_path / "other", dofs=list(DEFAULT_DOFS[:2]))
    shutil.copyfile(_only_entry(tmp_path / "other"), entry)
    with pytest.warns(CacheWarning, match="not the 22 frames"):
        third = compute_geometry(example.model, short_trial["ik"], cache_dir=cache)
    assert other.dofs != third.dofs and third.source["cached"] is False
    np.testing.assert_array_equal(third.moment_arms_m, first.moment_arms_m)
    assert compute_geometry(example.model, short_trial["ik"], cache_dir=cache).source["cached"] is True


def test_unusable_cache_places_fall_back_to_no_cache(example, short_trial, tmp_path, monkeypatch):
    cache = tmp_path / "cache"
    compute_geometry(example.model, short_trial["ik"], cache_dir=cache)
    entry = _only_entry(cache)
    entry.unlink()
    entry.mkdir()  # an entry that is a folder
    (entry / "mine.txt").write_text("x")
    with pytest.warns(CacheWarning, match="is a folder or a link"):
        g = compute_geometry(example.model, short_trial["ik"], cache_dir=cache)
    assert g.source["cached"] is False and (entry / "mine.txt").is_file()

    not_a_folder = tmp_path / "cachefile"
    not_a_folder.write_text("x")
    monkeypatch.setenv("MUSCLEMETAB_CACHE", str(not_a_folder))
    with pytest.warns(CacheWarning, match="cannot be used .*MUSCLEMETAB_CACHE"):
        g = compute_geometry(example.model, short_trial["ik"])
    assert g.source["cached"] is False and not_a_folder.read_text() == "x"


# ----------------------------------------------------------------------------- messages that name their source
def test_messages_name_the_file_or_muscle():
    from musclemetab.redundancy.inputs import lowpass_filtfilt, trial_inputs

    with pytest.raises(DataMismatchError, match="the IK file a.mot is too short: 3 samples"):
        lowpass_filtfilt(np.zeros((3, 2)), 100.0, what="the IK file a.mot")

    class Geometry:
        time = np.arange(30) / 100.0
        muscles = ("soleus_r", "tibant_r")
        dofs = ("ankle_angle_r",)
        lmt_m = np.ones((30, 2))
        moment_arms_m = np.full((30, 1, 2), 0.04)

    Geometry.lmt_m = Geometry.lmt_m.copy()
    Geometry.lmt_m[4, 1] = np.nan
    with pytest.raises(DataMismatchError, match="geometry of ik.mot holds NaN .* for tibant_r"):
        trial_inputs(Geometry, Geometry.time, np.ones((30, 1)), sources={"ik": "ik.mot"})

    # a window of 1.0-1.2 s of a 60 Hz file: 13 frames, where the order-6 filter's padding needs more than
    # 3 (7 - 1) = 18, (18 + 1) / 60 = 0.317 s; the message names the window, not the file, as too short
    class Window(Geometry):
        time = 1.0 + np.arange(13) / 60.0
        lmt_m = np.ones((13, 2))
        moment_arms_m = np.full((13, 1, 2), 0.04)

    with pytest.raises(DataMismatchError, match=r"^the solved window 1\.000-1\.200 s of the IK file walk\.mot is too short: "
                                                r"13 samples, .* needs more than 18 \(at 60 Hz, 0\.317 s\); use a longer "
                                                r"trial or a wider window$"):
        trial_inputs(Window, Window.time, np.ones((13, 1)), sources={"ik": "walk.mot"})


def test_infeasible_solves_are_not_told_to_raise_max_iter():
    from musclemetab.redundancy.ipopt import failure_advice

    for status in ("Infeasible_Problem_Detected", "Restoration_Failed"):
        text = failure_advice(status)
        assert "infeasible" in text and "max-iter" not in text
    assert "--max-iter" in failure_advice("Maximum_Iterations_Exceeded")


def test_a_failed_solution_suggests_the_command_line_option(tmp_path):
    from musclemetab.errors import SolverError
    from musclemetab.redundancy.solution import SOLUTION_FILE, SUMMARY_FILE, read_solution_folder

    (tmp_path / SOLUTION_FILE).write_text("x\nendheader\ntime\n0\n")
    (tmp_path / SUMMARY_FILE).write_text('{"muscles": ["soleus_r"], "success": false, "status": "Restoration_Failed"}')
    with pytest.raises(SolverError, match="--allow-failed"):
        read_solution_folder(tmp_path)


# ----------------------------------------------------------------------------- one solve: large reserves
def test_large_reserves_are_flagged(example, short_trial, tmp_path):
    """Moments three times too large: the muscles cannot follow, the reserves take over."""
    import json

    from musclemetab.redundancy import solve_files

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sol = solve_files(example.model, short_trial["ik"], short_trial["id_x3"], "effort-gen")
    flagged = [w for w in caught if issubclass(w.category, LargeReserveWarning)]
    assert sol.success and len(flagged) == 1 and "id_x3.sto" in str(flagged[0].message)
    s = sol.summary
    worst = max(s["reserve_rms_Nm"].values())
    moments = np.abs(read_storage(short_trial["id_x3"])[[f"{d}_moment" for d in DEFAULT_DOFS]]
                     .loc[s["time_window_s"][0]:s["time_window_s"][1]].to_numpy())
    peak = float(np.max(moments))
    # the share is of the largest peak over the DOFs, and the message names that DOF's
    peak_dof = DEFAULT_DOFS[int(np.argmax(moments.max(axis=0)))]
    assert f"of the largest peak joint moment ({peak_dof}, " in str(flagged[0].message)
    assert s["large_reserve"] is True
    assert s["reserve_share_of_peak_moment"] == pytest.approx(worst / peak, rel=0.15) and worst / peak > 0.01
    sol.write(tmp_path / "sol")
    stored = json.loads((tmp_path / "sol" / "summary.json").read_text())
    assert stored["large_reserve"] is True
