"""Values a careful or a hostile user may give: physically impossible numbers, wrong types,
names that match nothing, nested or huge study files, damaged ground forces, files ending a
hair early, tampered caches. Each is refused with one line naming the file, key or column, or
handled with a documented warning; nothing is written outside the output folder."""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from musclemetab.errors import (
    CacheWarning,
    DataMismatchError,
    InputFileError,
    OptionError,
    UnknownCoordinateError,
    UnknownMuscleError,
)
from musclemetab.study import load_study, study_from_dict
from musclemetab.study.spec import MAX_STUDY_DEPTH, MAX_STUDY_FILE_BYTES, NUMBER_KEYS


def _study(example, **subject_keys):
    return {
        "name": "values",
        "workflows": ["effort-gen"],
        "models": ["UM10"],
        "subjects": [{
            "name": "sub1", "model": str(example.model),
            "body_mass_kg": example.body_mass_kg, "height_m": example.height_m,
            "trials": [{"name": "normal", "ik": str(example.ik["normal"]), "id": str(example.id["normal"])}],
            **subject_keys,
        }],
    }


def _refused(data, tmp_path, error=OptionError):
    """The one-line message of the refusal; the output folder and a decoy beside it untouched."""
    decoy = tmp_path / "decoy.txt"
    decoy.write_text("keep")
    with pytest.raises(error) as info:
        study_from_dict(data, base="/", source=tmp_path / "study.toml", output=tmp_path / "out")
    assert not (tmp_path / "out").exists() and decoy.read_text() == "keep"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["decoy.txt"]
    message = str(info.value)
    assert "\n" not in message and str(tmp_path / "study.toml") in message
    return message


def _set(where, key, value):
    def edit(d):
        target = {"study": d, "subject": d["subjects"][0], "trial": d["subjects"][0]["trials"][0]}[where]
        if "." in key:
            table, sub = key.split(".")
            target[table] = {sub: value} if table != "energy_goal" else {"model": "UM10", sub: value}
        else:
            target[key] = value
        if key == "vo2_mL_per_min":
            target["vco2_mL_per_min"] = 900.0
    return edit


# where, key, value, what the message must say (besides the file and the key)
IMPOSSIBLE = [
    ("subject", "body_mass_kg", 1e300, "from 20 to 300 kg"),
    ("subject", "body_mass_kg", 72_600.0, "from 20 to 300 kg"),
    ("subject", "height_m", 0.0, "from 0.5 to 2.7 m"),
    ("subject", "emg_tolerance", 1e308, "from 0 to 1"),
    ("trial", "speed_m_per_s", 1e308, "at most 15 m/s"),
    ("trial", "speed_m_per_s", 0.0, "above 0"),
    ("trial", "measured_W_per_kg", 1e308, "at most 50 W/kg"),
    ("trial", "vo2_mL_per_min", 1e308, "at most 9000 mL/min"),
    ("trial", "vo2_mL_per_s", -3.0, "above 0"),
    ("trial", "grf_threshold_N", -5.0, "above 0"),
    ("trial", "end_s", 1e300, "a time"),
    ("study", "basal_exponent", 1e308, "from 0 to 2"),
    ("study", "basal_coefficient", 1e3, "from 0 to 10 W/kg"),
    ("subject", "tendon_stiffness.soleus", 1e308, "at most 1000"),
    ("study", "solver.max_iter", 1.5, "whole number"),
    ("study", "solver.tol", 0.0, "above 0"),
    ("study", "energy_goal.weight", -1.0, "not be negative"),
]


@pytest.mark.parametrize("where, key, value, words", IMPOSSIBLE, ids=[f"{c[1]}={c[2]}" for c in IMPOSSIBLE])
def test_physically_impossible_values_are_refused_with_the_range(example, tmp_path, where, key, value, words):
    data = _study(example)
    _set(where, key, value)(data)
    if key == "vo2_mL_per_s":
        data["subjects"][0]["trials"][0]["vco2_mL_per_s"] = 15.0
    message = _refused(data, tmp_path)
    shown = key if key.startswith("tendon") else f"[{key.split('.')[0]}]: '{key.split('.')[1]}'" if "." in key \
        else f"'{key}'"
    assert shown in message and words in message, message


@pytest.mark.parametrize("value", [1.5, True, 0, -1, "2", "first"])
def test_cycle_is_auto_or_a_positive_whole_number(example, tmp_path, value):
    data = _study(example)
    data["subjects"][0]["trials"][0]["cycle"] = value
    message = _refused(data, tmp_path)
    assert "'cycle'" in message and "\"auto\" or a gait cycle number" in message and repr(value) in message


@pytest.mark.parametrize("key", ["body_mass_kg", "emg_tolerance", "speed_m_per_s", "basal_exponent"])
@pytest.mark.parametrize("value", [True, "72"])
def test_numbers_of_the_wrong_type_are_refused(example, tmp_path, key, value):
    where = {"body_mass_kg": "subject", "emg_tolerance": "subject", "speed_m_per_s": "trial"}.get(key, "study")
    data = _study(example)
    _set(where, key, value)(data)
    message = _refused(data, tmp_path)
    assert f"'{key}' must be a number" in message and NUMBER_KEYS[key].range_text() in message


def test_every_numeric_key_of_the_study_file_is_in_the_table():
    from musclemetab.study import spec

    numeric = {k for k in spec._TRIAL_KEYS if k.endswith(("_s", "_per_s", "_per_min", "_per_kg", "_N"))}
    numeric |= {"body_mass_kg", "height_m", "emg_tolerance", "basal_coefficient", "basal_exponent",
                "tendon_stiffness", "max_iter", "tol"} | (spec._ENERGY_KEYS - {"model", "form"})
    assert numeric <= set(NUMBER_KEYS)
    for k in NUMBER_KEYS.values():  # a usual value passes, the bounds are ordered
        assert k.low < k.high and k.help


@pytest.mark.parametrize("option, check, value, words", [
    ("--speed", "speed", 1e308, "at most 15 m/s"),
    ("--mass", "mass", 1e300, "from 20 to 300 kg"),
    ("--height", "height", 17.4, "from 0.5 to 2.7 m"),
    ("--basal-exponent", "basal_exponent", 1e308, "from 0 to 2"),
    ("--basal-coefficient", "basal_coefficient", float("nan"), "from 0 to 10 W/kg"),
])
def test_command_line_refuses_what_the_study_file_refuses(option, check, value, words):
    from types import SimpleNamespace

    from musclemetab.commands.options import check_basal_arguments, check_body, check_speed

    with pytest.raises(OptionError) as info:
        if check == "speed":
            check_speed(value)
        elif check in ("mass", "height"):
            check_body(value if check == "mass" else 70.0, value if check == "height" else 1.7)
        else:
            args = SimpleNamespace(basal="body", basal_coefficient=1.2, basal_exponent=1.0)
            setattr(args, check, value)
            check_basal_arguments(args)
    assert str(info.value).startswith(option) and words in str(info.value)


# ----------------------------------------------------------------------------- names matching nothing
def test_muscle_properties_row_naming_no_muscle_is_refused_with_the_near_names(example, tmp_path):
    csv = tmp_path / "muscles.csv"
    csv.write_text("muscle,slow_twitch_fraction\nsolues_r,0.8\n")
    data = _study(example, muscle_properties=str(csv))
    decoy_before = csv.read_text()
    with pytest.raises(UnknownMuscleError) as info:
        study_from_dict(data, base="/", source=tmp_path / "study.toml", output=tmp_path / "out")
    message = str(info.value)
    assert "'solues_r'" in message and "soleus_r" in message and str(csv) in message and "muscle_properties" in message
    assert not (tmp_path / "out").exists() and csv.read_text() == decoy_before


def test_muscle_properties_row_naming_no_muscle_is_refused_by_the_check():
    from musclemetab.properties import MuscleOverrides, resolve_muscles

    typo = MuscleOverrides({"solues_r": {"slow_twitch_fraction": 0.8}}, "m.csv")
    for tables in (False, True):
        with pytest.raises(UnknownMuscleError, match=r"^m.csv: muscle row 'solues_r' \(near: soleus_r\)"):
            typo.check_names(["soleus_r", "gasmed_r"], tables=tables)
    # a side-free row, or the other side's row, names the muscle
    rows = MuscleOverrides({"soleus": {"slow_twitch_fraction": 0.7}, "soleus_l": {"slow_twitch_fraction": 0.1}})
    rows.check_names(["soleus_r"])
    # a muscle of the tables the solve did not include passes when only the solved muscles are known
    MuscleOverrides({"glmax1_r": {"mass_kg": 0.3}}).check_names(["soleus_r"], tables=True)
    with pytest.raises(UnknownMuscleError):
        MuscleOverrides({"glmax1_r": {"mass_kg": 0.3}}).check_names(["soleus_r"])
    assert resolve_muscles(["soleus_r"], overrides=rows, warn=False)[0].slow_twitch_fraction == 0.7


@pytest.mark.parametrize("row, words", [
    ("soleus_r,,1e300", "a muscle mass in kg"),
    ("soleus_r,,-1", "a muscle mass in kg"),
    ("soleus_r,1e30,", "a specific tension in Pa"),
])
def test_muscle_properties_impossible_values(tmp_path, row, words):
    from musclemetab.properties import read_muscle_properties

    csv = tmp_path / "m.csv"
    csv.write_text(f"muscle,specific_tension_Pa,mass_kg\n{row}\n")
    with pytest.raises(InputFileError) as info:
        read_muscle_properties(csv)
    assert str(csv) in str(info.value) and "soleus_r" in str(info.value) and words in str(info.value)


def test_dofs_naming_no_coordinate_are_refused_with_the_near_names(example, tmp_path):
    data = _study(example, dofs=["knee_angel_r"])
    message = _refused(data, tmp_path, UnknownCoordinateError)
    assert "'dofs'" in message and "'knee_angel_r'" in message and "knee_angle_r" in message


# ----------------------------------------------------------------------------- TOML limits
def test_study_file_nested_too_deep_is_refused_in_one_line(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text("x = " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(InputFileError) as info:
        load_study(path)
    assert str(info.value) == (f"{path}: tables or lists nested more than {MAX_STUDY_DEPTH} deep, more than a "
                               "study file has; check the file")


def test_study_file_nested_just_too_deep_without_recursion_error(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text("x = " + "[" * (MAX_STUDY_DEPTH + 1) + "]" * (MAX_STUDY_DEPTH + 1) + "\n")
    with pytest.raises(InputFileError, match=f"nested more than {MAX_STUDY_DEPTH} deep"):
        load_study(path)


def test_study_file_too_large_is_refused_in_one_line(tmp_path):
    path = tmp_path / "huge.toml"
    path.write_text("# " + "x" * MAX_STUDY_FILE_BYTES + "\n")
    with pytest.raises(InputFileError, match=rf"^{path}: \d+ bytes, more than a study file may hold "
                                             rf"\({MAX_STUDY_FILE_BYTES} bytes\)"):
        load_study(path)


# ----------------------------------------------------------------------------- ground forces
def _edit_mot(src: Path, dst: Path, column: str, rows: slice, value) -> np.ndarray:
    """Copy an OpenSim .mot with ``column`` set to ``value`` (a number or a function of the old
    values) on ``rows`` of data; returns the times of those rows."""
    lines = src.read_text().splitlines()
    end = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader")
    names = lines[end + 1].split()
    c = names.index(column)
    data = [ln.split() for ln in lines[end + 2:] if ln.strip()]
    times = []
    for cells in data[rows]:
        old = float(cells[c])
        cells[c] = repr(value(old) if callable(value) else value)
        times.append(float(cells[0]))
    dst.write_text("\n".join(lines[:end + 2] + ["\t".join(cells) for cells in data]) + "\n")
    return np.array(times)


def _loads_copy(gait2392, tmp_path, column, rows, value):
    folder = tmp_path / "loads"
    folder.mkdir()
    xml = folder / gait2392.external_loads.name
    shutil.copy(gait2392.external_loads, xml)
    times = _edit_mot(gait2392.grf, folder / gait2392.grf.name, column, rows, value)
    return xml, folder / gait2392.grf.name, times


@pytest.mark.parametrize("column", ["ground_force_px", "1_ground_force_vy", "ground_torque_y"])
def test_nan_anywhere_in_external_loads_data_is_refused_naming_column_and_times(gait2392, tmp_path, column):
    from musclemetab.external_loads import read_external_loads

    xml, data, times = _loads_copy(gait2392, tmp_path, column, slice(200, 210), float("nan"))
    with pytest.raises(InputFileError) as info:
        read_external_loads(xml)
    message = str(info.value)
    assert message.startswith(f"{data}: column '{column}' holds 10 NaN or infinite value(s) at t = "
                              f"{times[0]:.4f}, {times[1]:.4f}, {times[2]:.4f} ...")


def test_centre_of_pressure_in_millimetres_is_refused(gait2392, tmp_path):
    from musclemetab.external_loads import read_external_loads

    xml, data, _ = _loads_copy(gait2392, tmp_path, "ground_force_pz", slice(None), lambda v: v * 1000 + 25_000)
    with pytest.raises(InputFileError, match=r"point column 'ground_force_pz' reaches .* more than 20 m from "
                                             r"the origin; centres of pressure must be in metres \(not mm\)"):
        read_external_loads(xml)


def test_nan_in_a_ground_force_file_is_refused_naming_column_and_times(gait2392, tmp_path):
    from musclemetab.events import read_grf

    bad = tmp_path / "grf.mot"
    times = _edit_mot(gait2392.grf, bad, "ground_force_vy", slice(50, 52), float("inf"))
    with pytest.raises(InputFileError, match=rf"^{bad}: column 'ground_force_vy' holds 2 NaN or infinite "
                                             rf"value\(s\) at t = {times[0]:.4f}, {times[1]:.4f} s"):
        read_grf(bad, side="r")


# ----------------------------------------------------------------------------- time ranges
@pytest.mark.parametrize("short_s, accepted, shown", [(1.5e-6, True, ""), (9e-6, True, ""), (1.5e-5, False, "0.000015"),
                                                     (1.5e-3, False, "0.0015"), (0.02, False, "0.020")])
def test_file_ending_within_a_sample_tolerance_is_accepted(short_s, accepted, shown):
    from musclemetab.external_loads import check_inside

    if accepted:
        check_inside((0.5, 1.6), 0.5, 1.6 - short_s, "ID.sto", "inverse dynamics")
        return
    with pytest.raises(DataMismatchError) as info:
        check_inside((0.5, 1.6), 0.5, 1.6 - short_s, "ID.sto", "inverse dynamics")
    assert f"ends {shown} s before the window end 1.600 s" in str(info.value)
    # the remedy names the times the file and the window share (rounded to the millisecond)
    assert f"(this file and the window share 0.500-{1.6 - short_s:.3f} s)" in str(info.value)


def test_a_file_outside_the_window_names_no_shared_times():
    from musclemetab.external_loads import check_inside

    with pytest.raises(DataMismatchError) as info:
        check_inside((2.0, 3.0), 0.4, 1.6, "ID.sto", "inverse dynamics")
    assert str(info.value) == ("ID.sto: the inverse dynamics (0.400-1.600 s) ends 1.400 s before the window end "
                               "3.000 s; choose a window inside every input file")


# ----------------------------------------------------------------------------- inverse-dynamics cache
@pytest.fixture(scope="module")
def id_entry(gait2392, tmp_path_factory):
    """One computed inverse-dynamics entry in a cache folder given as ``cache_dir``."""
    from musclemetab.external_loads import compute_inverse_dynamics

    cache = tmp_path_factory.mktemp("idcache")
    path = compute_inverse_dynamics(gait2392.model, gait2392.ik, gait2392.external_loads, 0.6, 0.9,
                                    cache_dir=cache)
    return cache, path, path.read_bytes()


def test_inverse_dynamics_cache_honours_cache_dir(gait2392, id_entry):
    from musclemetab.cache import read_file_entry
    from musclemetab.external_loads import _cache_dir, compute_inverse_dynamics

    cache, path, _ = id_entry
    assert path.parent == cache and path.name.startswith("id-") and read_file_entry(path) == ""
    assert not _cache_dir().exists() or not any(_cache_dir().glob(f"*{path.name[3:]}"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        again = compute_inverse_dynamics(gait2392.model, gait2392.ik, gait2392.external_loads, 0.6, 0.9,
                                         cache_dir=cache)
    assert again == path


@pytest.mark.parametrize("damage", ["column_x1.5", "truncated", "no_checksum", "folder"])
def test_damaged_inverse_dynamics_entry_is_recomputed_with_one_warning(gait2392, id_entry, damage):
    from musclemetab.external_loads import compute_inverse_dynamics
    from musclemetab.io import read_storage

    cache, path, good = id_entry
    sidecar = path.with_name(path.name + ".sha256")
    if damage == "column_x1.5":
        _edit_mot(path, path, "knee_angle_r_moment", slice(None), lambda v: v * 1.5)
    elif damage == "truncated":
        path.write_bytes(good[: len(good) // 2])
    elif damage == "no_checksum":
        sidecar.unlink()
    else:
        path.unlink()
        path.mkdir()
    with pytest.warns(CacheWarning) as record:
        out = compute_inverse_dynamics(gait2392.model, gait2392.ik, gait2392.external_loads, 0.6, 0.9,
                                       cache_dir=cache)
    assert len(record) == 1 and str(path) in str(record[0].message)
    assert read_storage(out).equals(read_storage(_bytes_file(good, path.parent.parent / "good.sto")))
    if damage == "folder":
        assert out != path and path.is_dir()  # left alone, the result computed outside the cache
        path.rmdir()
        shutil.copy(out, path)
        sidecar.write_text(__import__("hashlib").sha256(good).hexdigest() + "\n")
    else:
        assert out == path and path.read_bytes() == good


def _bytes_file(data: bytes, path: Path) -> Path:
    path.write_bytes(data)
    return path


def test_dofs_of_the_model_are_accepted(example, tmp_path):
    data = _study(example, dofs=["knee_angle_r", "ankle_angle_r"])
    study = study_from_dict(data, base="/", source=tmp_path / "study.toml", output=tmp_path / "out")
    assert study.subjects[0].dofs == ("knee_angle_r", "ankle_angle_r")


def test_geometry_command_keeps_its_cache_in_cache_dir(example, tmp_path):
    """``--cache-dir``: the geometry entry and the model entries it needs land there."""
    from musclemetab.commands import main

    cache = tmp_path / "cache"
    assert main(["geometry", "--model", str(example.model), "--ik", str(example.ik["normal"]),
                 "--dofs", "knee_angle_r", "--muscles", "soleus_r", "bflh_r", "--cache-dir", str(cache),
                 "--out", str(tmp_path / "out")]) == 0
    names = sorted(p.name for p in cache.iterdir())
    assert any(not n.startswith("model-") and n.endswith(".npz") for n in names), names
    arrays = __import__("numpy").load(cache / next(n for n in names if not n.startswith("model-")))
    assert "checksum" in arrays.files


def test_missing_column_names_the_near_names_and_nan_the_times(gait2392, tmp_path):
    from musclemetab.errors import MissingColumnError
    from musclemetab.io import read_storage, require_columns

    grf = read_storage(gait2392.grf)
    with pytest.raises(MissingColumnError, match=rf"^{gait2392.grf}: missing column ground_force_yv; near names: "
                                                 r".*ground_force_vy"):
        require_columns(grf, ["ground_force_yv"])
    bad = tmp_path / "grf.mot"
    times = _edit_mot(gait2392.grf, bad, "ground_force_vy", slice(7, 9), float("nan"))
    with pytest.raises(MissingColumnError, match=rf"^{bad}: column ground_force_vy holds NaN values "
                                                 rf"\(at t = {times[0]:.4f}, {times[1]:.4f} s\)"):
        require_columns(read_storage(bad), ["ground_force_vy"])


@pytest.mark.parametrize("with_model", [False, True])
def test_metabolics_command_refuses_a_muscle_properties_row_naming_no_muscle(demo, example, tmp_path, capsys,
                                                                             with_model):
    from musclemetab.commands import main

    out, table = demo
    unit = out / table[table.workflow == "effort-gen"].unit_dir.iloc[0]
    csv = tmp_path / "m.csv"
    csv.write_text("muscle,slow_twitch_fraction\nsolues_r,0.8\n")
    args = ["metabolics", "--solution", str(unit), "--mass", "72.6", "--height", "1.743", "--models", "UM10",
            "--muscle-properties", str(csv), "--out", str(tmp_path / "out")]
    assert main(args + (["--model", str(example.model)] if with_model else [])) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{csv}: muscle row 'solues_r' (near: soleus_r" in err, err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("value", [1.5, True, "1.5", "x", 0, "0"])
def test_the_solvers_cycle_option_is_never_read_as_another_cycle(value):
    """``solve --cycle`` and Python callers: only "auto" or a whole number from 1 (1.5 or True
    were read as cycle 1)."""
    from musclemetab.errors import OptionError
    from musclemetab.redundancy.window import parse_cycle

    with pytest.raises(OptionError, match="cycle"):
        parse_cycle(value)
    assert parse_cycle("2") == 2 and parse_cycle(3) == 3 and parse_cycle("auto") == "auto"


def test_passive_parameters_that_are_not_finite_are_named_as_such():
    """kPE = inf was reported as 'no passive parameters'."""
    import math

    from musclemetab.errors import InputFileError, UnknownMuscleError
    from musclemetab.passive import PassiveParameters

    params = PassiveParameters({"soleus_r": (math.inf, 1.0, 0.6), "tibant_r": (4.0, 1.0, 0.6)}, "p.csv")
    with pytest.raises(InputFileError, match=r"p.csv: .*soleus_r are not finite"):
        params.for_muscles(["soleus_r", "tibant_r"])
    with pytest.raises(UnknownMuscleError, match="no passive parameters for vaslat_r") as info:
        params.for_muscles(["tibant_r", "vaslat_r"])
    # the remedy: a calibration of this model's muscles by the command that makes one, or no calibration
    assert "musclemetab calibrate-passive --model MODEL --trials FOLDER" in str(info.value)
    assert "--passive DIR/passive_parameters.csv" in str(info.value) and "effort-gen" in str(info.value)
    assert params.for_muscles(["tibant_r"]).tolist() == [[4.0, 1.0, 0.6]]


def test_report_of_a_study_whose_units_all_failed_says_so(tmp_path):
    """The runner writes the key columns alone when no unit finished; the report was refused as
    'not written by the study runner of this version'. It now shows the failures."""
    from musclemetab.report.build import write_report
    from musclemetab.study.runner import ID_COLUMNS

    root = tmp_path / "study"
    root.mkdir()
    (root / "results.csv").write_text(",".join(ID_COLUMNS) + "\n")
    (root / "failures.csv").write_text("subject,trial,workflow,reason\ns1,walk,effort-gen,IPOPT: Infeasible\n")
    decoy = tmp_path / "decoy.txt"
    decoy.write_text("keep")
    text = write_report(root).read_text(encoding="utf-8")
    assert "No unit of the study succeeded" in text and "IPOPT: Infeasible" in text
    assert decoy.read_text() == "keep" and sorted(p.name for p in tmp_path.iterdir()) == ["decoy.txt", "study"]


def test_the_documented_ranges_are_the_checked_ones():
    """docs/study.md's table of the numeric keys gives, for every key, the range the study file's
    check (``NUMBER_KEYS``) applies: no row promises what the code refuses (``[solver] max_iter``
    up to 1e7 while the check stops at 1e5)."""
    import re

    text = (Path(__file__).parents[1] / "docs" / "study.md").read_text()
    rows = re.findall(r"^\| `(?:\[\w+\] )?([a-z_0-9]+)(?:\.<muscle>)?` \| [^|]* \| ([^|]+) \|", text, re.M)
    assert len(rows) >= 15
    for name, documented in rows:
        key = NUMBER_KEYS[name]
        checked = key.range_text().replace(" (positive)", "")
        checked = checked[: -len(f" {key.unit}")] if key.unit else checked
        assert documented.strip() == checked + (" (whole number)" if key.integer else ""), name
