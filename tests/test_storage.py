"""OpenSim storage files: both header styles, writing for OpenSim, every malformed case."""

from __future__ import annotations

import numpy as np
import pytest

from musclemetab.errors import MissingColumnError, StorageFormatError, TimeColumnError
from musclemetab.io import StorageTable, read_storage, read_table, require_columns, storage_from_arrays, write_storage


def test_modern_header_ik(example):
    df = read_storage(example.ik["normal"])
    assert df.attrs["name"] == "Coordinates"
    assert df.attrs["in_degrees"] is True
    assert df.shape == (119, 39)
    assert df.index[0] == pytest.approx(0.57) and df.index[-1] == pytest.approx(1.75)
    # first data row as printed in the file
    assert df["pelvis_tilt"].iloc[0] == pytest.approx(2.14633367)
    assert df["hip_flexion_r"].iloc[0] == pytest.approx(34.34281872)
    assert list(df.columns[:3]) == ["pelvis_tilt", "pelvis_list", "pelvis_rotation"]


def test_modern_header_radians(example):
    df = read_storage(example.id["normal"])
    assert df.attrs["in_degrees"] is False
    assert df.attrs["name"] == "Inverse Dynamics Generalized Forces"
    # normal-speed ranges stated with the data set
    assert df["ankle_angle_r_moment"].min() == pytest.approx(-103.9, abs=0.05)
    assert df["knee_angle_r_moment"].max() == pytest.approx(35.6, abs=0.05)


def test_legacy_header_emg(example):
    df = read_storage(example.emg["normal"])
    assert df.attrs["in_degrees"] is None  # the legacy header has no inDegrees line
    assert df.attrs["name"].endswith("P1S100W01_EMG(MVC)_40ms.mot")
    assert df.shape == (2460, 15)
    assert list(df.columns) == "BF ST VL VM RF TFL GE GA TA GL GM SO ES MF VI_a".split()
    assert df.index[0] == pytest.approx(0.040) and df.index[-1] == pytest.approx(2.499)
    assert df["BF"].iloc[0] == pytest.approx(-0.0071125277)
    # VI_a is documented as the mean of VL and VM
    np.testing.assert_allclose(df["VI_a"], (df["VL"] + df["VM"]) / 2, atol=1e-9)


def test_legacy_header_with_trailing_tabs(example):
    df = read_storage(example.calibration_trials["ankle"]["moments"])
    assert df.shape == (150, 3)
    assert df["ankle_angle_r_moment"].iloc[0] == pytest.approx(-0.63964)
    assert df.index[1] == pytest.approx(0.0202040816)


def test_round_trip_through_opensim(tmp_path, example):
    from musclemetab.opensim_bridge import call

    ik = read_storage(example.ik["fast"])
    out = write_storage(tmp_path / "copy.sto", ik, name="roundtrip", in_degrees=True)
    back = call("model_ops:read_time_series_table", str(out))
    assert back["labels"] == list(ik.columns)
    np.testing.assert_allclose(back["time"], ik.index.to_numpy(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(back["values"], ik.to_numpy(), rtol=1e-11, atol=1e-12)
    assert back["metadata"]["inDegrees"] == "yes"
    # and through our own reader
    again = read_storage(out)
    assert again.attrs["in_degrees"] is True and again.attrs["name"] == "roundtrip"
    np.testing.assert_allclose(again.to_numpy(), ik.to_numpy(), rtol=1e-11)


def test_written_columns_with_slashes_and_nan(tmp_path):
    from musclemetab.opensim_bridge import call

    df = storage_from_arrays([0.0, 0.01, 0.02], {"/forceset/soleus_r/activation": [0.1, 0.2, np.nan]})
    out = write_storage(tmp_path / "s.sto", df)
    back = call("model_ops:read_time_series_table", str(out))
    assert back["labels"] == ["/forceset/soleus_r/activation"]
    assert np.isnan(back["values"][2, 0]) and back["values"][1, 0] == pytest.approx(0.2)


def test_written_numbers_are_twelve_significant_digits_and_nan_as_opensim_writes_it(tmp_path):
    df = storage_from_arrays([0.0, 1.0 / 3.0], {"a": [np.nan, -np.inf], "b": [-0.0, 2.0 ** 0.5 * 1e-300]})
    lines = (write_storage(tmp_path / "n.sto", df).read_text().split("endheader\n")[1]).splitlines()
    assert lines == ["time\ta\tb", "0\tNaN\t-0", "0.333333333333\t-inf\t1.41421356237e-300"]


def test_write_is_atomic(tmp_path, monkeypatch):
    target = tmp_path / "keep.sto"
    target.write_text("old content")
    df = storage_from_arrays([0.0, 1.0], {"x": [1.0, 2.0]})

    from pathlib import Path

    real_write_text = Path.write_text

    def half_then_full_disk(self, text, *a, **k):  # the temporary file gets half the text
        real_write_text(self, text[:len(text) // 2], *a, **k)
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Path, "write_text", half_then_full_disk)
    with pytest.raises(OSError):
        write_storage(target, df)
    monkeypatch.undo()
    assert target.read_text() == "old content"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.sto"]  # no temporary left


GOOD = "Coordinates\nversion=1\nnRows=3\nnColumns=3\ninDegrees=yes\nendheader\ntime\ta\tb\n0\t1\t2\n0.01\t3\t4\n0.02\t5\t6\n"


@pytest.mark.parametrize(
    "text, error, phrase",
    [
        ("", StorageFormatError, "no 'endheader'"),
        (GOOD.replace("endheader\n", ""), StorageFormatError, "no 'endheader'"),
        (GOOD.split("time")[0], StorageFormatError, "truncated"),
        (GOOD.rsplit("0.02", 1)[0], StorageFormatError, "announces 3 rows"),
        (GOOD.replace("0.01\t3\t4", "0.01\t3"), StorageFormatError, "has 2 values"),
        (GOOD.replace("0.01\t3\t4", "0.01\tthree\t4"), StorageFormatError, "'three'"),
        (GOOD.replace("0.01\t3", "nan\t3"), TimeColumnError, "NaN"),
        (GOOD.replace("0.02\t5", "0.005\t5"), TimeColumnError, "not strictly increasing"),
        (GOOD.replace("0.01\t3", "0\t3"), TimeColumnError, "not strictly increasing"),
        (GOOD.replace("time\ta\tb", "t\ta\tb"), TimeColumnError, "expected 'time'"),
        (GOOD.replace("time\ta\tb", "time\ta\ta"), StorageFormatError, "duplicate"),
        (GOOD.replace("inDegrees=yes", "inDegrees=maybe"), StorageFormatError, "inDegrees"),
        (GOOD.replace("nRows=3", "nRows=three"), StorageFormatError, "whole number"),
    ],
)
def test_malformed_files_name_the_file(tmp_path, text, error, phrase):
    path = tmp_path / "bad.mot"
    path.write_text(text)
    with pytest.raises(error) as info:
        read_storage(path)
    assert str(path) in str(info.value)
    assert phrase in str(info.value)


def test_a_row_with_the_wrong_number_of_values_is_refused_naming_the_file_and_line(tmp_path):
    path = tmp_path / "cut.sto"
    # the header takes lines 1-6, the column names line 7, the data rows lines 8-10
    path.write_text(GOOD.replace("0.02\t5\t6\n", "0.02\t5\n"))
    with pytest.raises(StorageFormatError) as info:
        read_table(path)
    assert str(info.value).startswith(f"{path}: data row 3 (line 10, the last) has 2 values but there are 3 columns")
    # blank lines between the rows count in the line number
    path.write_text(GOOD.replace("0.01\t3\t4\n", "0.01\t3\t4\n\n\n").replace("0.02\t5\t6", "0.02\t5\t6\t7"))
    with pytest.raises(StorageFormatError, match=r"data row 3 \(line 12, the last\) has 4 values"):
        read_table(path)
    path.write_text(GOOD.replace("0.01\t3\t4", "0.01\t3"))
    with pytest.raises(StorageFormatError, match=r"data row 2 \(line 9\) has 2 values"):
        read_table(path)


def test_a_last_row_without_line_end_reads_with_a_warning(tmp_path):
    import warnings

    from musclemetab.errors import TruncatedFileWarning

    path = tmp_path / "no_end.sto"
    path.write_text(GOOD.rstrip("\n"))
    with pytest.warns(TruncatedFileWarning) as caught:
        table = read_table(path)
    assert len(caught) == 1
    assert str(caught[0].message).startswith(f"{path}: the last data row (line 10, t = 0.02 s) has no line end")
    np.testing.assert_array_equal(table.values, [[1, 2], [3, 4], [5, 6]])
    # cut inside the last number: the number cannot be seen to be short, the missing line end can
    path.write_text(GOOD.replace("0.02\t5\t6\n", "0.02\t5\t6.25\n")[:-3])
    with pytest.warns(TruncatedFileWarning, match="line 10"):
        assert read_table(path)["b"][-1] == 6.0
    # whole files, with Unix or Windows line ends or a blank last line, read without a warning
    for text in (GOOD, GOOD.replace("\n", "\r\n"), GOOD + "  "):
        path.write_bytes(text.encode())
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            np.testing.assert_array_equal(read_table(path).values, [[1, 2], [3, 4], [5, 6]])


def test_missing_file(tmp_path):
    with pytest.raises(StorageFormatError, match="no such file"):
        read_storage(tmp_path / "absent.mot")


def test_require_columns(example):
    df = read_storage(example.id["normal"])
    require_columns(df, ["ankle_angle_r_moment"])
    with pytest.raises(MissingColumnError) as info:
        require_columns(df, ["ankle_angle_r_moment", "ankle_angle_x_moment"])
    assert "ankle_angle_x_moment" in str(info.value) and "ID_sub1_normal.sto" in str(info.value)
    df.loc[df.index[3], "ankle_angle_r_moment"] = np.nan
    with pytest.raises(MissingColumnError, match="NaN"):
        require_columns(df, ["ankle_angle_r_moment"])


def test_numpy_table_holds_what_the_dataframe_holds(example, tmp_path):
    """read_table (no pandas) and read_storage give the same numbers, names and header; the
    checks accept both; a table written with write_storage reads back the same."""
    for path in (example.ik["normal"], example.emg["normal"], example.calibration_trials["ankle"]["moments"]):
        table, df = read_table(path), read_storage(path)
        assert isinstance(table, StorageTable) and len(table) == len(df)
        assert list(table.columns) == list(df.columns) and table.attrs == df.attrs
        np.testing.assert_array_equal(table.index, df.index.to_numpy())
        np.testing.assert_array_equal(table.to_numpy(), df.to_numpy())
        np.testing.assert_array_equal(table[df.columns[1]], df[df.columns[1]].to_numpy())
    table = read_table(example.ik["normal"])
    assert table["hip_flexion_r"][0] == pytest.approx(34.34281872)  # first data row as printed in the file
    with pytest.raises(MissingColumnError, match="no column 'hip_flexion_x'"):
        table["hip_flexion_x"]
    require_columns(table, ["knee_angle_r"])
    with pytest.raises(MissingColumnError, match="knee_angle_x"):
        require_columns(table, ["knee_angle_r", "knee_angle_x"])
    table.values[2, 0] = np.nan
    with pytest.raises(MissingColumnError, match="NaN"):
        require_columns(table, [table.columns[0]])
    out = write_storage(tmp_path / "t.sto", read_table(example.id["normal"]))
    again, ref = read_table(out), read_table(example.id["normal"])
    assert again.columns == ref.columns and again.attrs["in_degrees"] is False
    np.testing.assert_allclose(again.to_numpy(), ref.to_numpy(), rtol=1e-11)


def test_written_files_have_a_normal_mode(tmp_path):
    import os

    mask = os.umask(0o022)
    try:
        out = write_storage(tmp_path / "m.sto", storage_from_arrays([0.0], {"x": [1.0]}))
    finally:
        os.umask(mask)
    assert (out.stat().st_mode & 0o777) == 0o644


def test_read_json_object_names_the_file_and_what_to_do(tmp_path):
    from musclemetab.errors import InputFileError
    from musclemetab.io import read_json_object

    good = tmp_path / "good.json"
    good.write_text('{"kT": 10.6, "muscles": ["soleus_r"]}', encoding="utf-8")
    assert read_json_object(good) == {"kT": 10.6, "muscles": ["soleus_r"]}
    with pytest.raises(InputFileError, match=r"absent\.json: no such file; check the path$"):
        read_json_object(tmp_path / "absent.json", missing="no such file; check the path")
    bad = tmp_path / "bad.json"
    bad.write_text('{"kT": 10.6,', encoding="utf-8")
    with pytest.raises(InputFileError, match=r"bad\.json: not a readable JSON file \(.*line 1.*\); solve again$"):
        read_json_object(bad, remedy="solve again")
    latin = tmp_path / "latin.json"
    latin.write_bytes(b'{"name": "\xe9"}')
    with pytest.raises(InputFileError, match=r"latin\.json: not a readable JSON file"):
        read_json_object(latin)
    arr = tmp_path / "list.json"
    arr.write_text("[1, 2]", encoding="utf-8")
    with pytest.raises(InputFileError, match=r"list\.json: a JSON object is expected, not list; solve again$"):
        read_json_object(arr, remedy="solve again")
