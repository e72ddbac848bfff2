"""A C3D file to OpenSim's files: markers, ground forces, ExternalLoads, the feet on the plates.

walking2.c3d (OpenSim's test suite, ``MUSCLEMETAB_DATA/c3d_walking``): 44 markers at 250 Hz in mm,
two force plates at 2000 Hz, z up. No body mass is recorded with it (neither in the file's
parameters nor in its README); the body weight the forces must add up to is taken from the one foot
contact the plates hold whole (see test_total_vertical_force_is_body_weight).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from musclemetab.errors import DataMismatchError, OptionError
from musclemetab.mocap import Markers, Plate, assign_feet, convert_c3d, foot_marker_sets, read_c3d, read_trc
from musclemetab.mocap.export import ground_force_table
from musclemetab.mocap.plates import TwoFeetWarning, remove_offsets

G = 9.81


@pytest.fixture(scope="module")
def walking2():
    from musclemetab.datasets import c3d_walking

    return c3d_walking()


@pytest.fixture(scope="module")
def converted(walking2, tmp_path_factory):
    out = tmp_path_factory.mktemp("c3d")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")  # this trial's plates each carry one foot: no two-feet warning
        record = convert_c3d(walking2, out)
    assert [type(w.message).__name__ for w in caught] == ["PartlyOffPlateWarning"], [str(w.message) for w in caught]
    return out, record, str(caught[0].message)


def test_a_foot_partly_off_its_plate_is_flagged(converted):
    """walking2's left heel lands behind plate 2 (its heel marker comes to rest 0.16-0.18 m behind
    the plate's edge before the plate is loaded, the load arriving under the forefoot): the
    contact is flagged partly off, by the heel marker; plate 1, which holds the right foot whole,
    is not."""
    record, message = converted[1], converted[2]
    off = {c["plate"]: c["partly_off"] for c in record["contacts"]}
    assert off[1] is None
    assert off[2]["marker"] == "LCAL" and 0.14 < off[2]["outside_m"] < 0.2 and 2.1 < off[2]["time_s"] < 2.25
    assert "left foot stands partly off force plate 2" in message and "LCAL" in message


def test_markers_in_opensim_frame_and_metres(walking2, converted):
    import ezc3d

    out, record, _ = converted
    markers = read_trc(out / "walking2.trc")
    assert len(markers.names) == 44 and markers.rate_hz == pytest.approx(250.0)
    raw = ezc3d.c3d(str(walking2))["data"]["points"]  # mm, lab frame x forward, y left, z up
    i = markers.names.index("RCAL")
    ok = np.isfinite(raw[0, i])
    # OpenSim: x forward, y up, z right = -lab y; mm -> m
    assert np.allclose(markers.xyz[ok, i, 0], raw[0, i, ok] / 1000, atol=1e-6)
    assert np.allclose(markers.xyz[ok, i, 1], raw[2, i, ok] / 1000, atol=1e-6)
    assert np.allclose(markers.xyz[ok, i, 2], -raw[1, i, ok] / 1000, atol=1e-6)
    # the heel marker rests a few cm above the floor during stance, and the subject walks along +x
    stance = (markers.time > 2.75) & (markers.time < 3.0)
    assert 0.02 < np.nanmedian(markers.xyz[stance, i, 1]) < 0.08
    sacrum = markers.marker("LPSI")
    good = np.isfinite(sacrum[:, 0])
    assert sacrum[good, 0][-1] - sacrum[good, 0][0] > 2.0
    assert record["lab_up"] == "z" and record["lab_forward"] == "x"


def test_opensim_reads_the_written_files(converted):
    from musclemetab.opensim_bridge import call

    out, record, _ = converted
    seen = call("lab:read_lab_files", str(out / "walking2.trc"), str(out / "walking2_grf.xml"))
    assert seen["units"] == "m" and seen["frames"] == 1249 and len(seen["markers"]) == 44
    assert {(f["name"], f["body"]) for f in seen["forces"]} == {("plate1_r", "calcn_r"), ("plate2_l", "calcn_l")}
    assert seen["data_rows"] == 9992
    from musclemetab.external_loads import read_external_loads

    loads = read_external_loads(out / "walking2_grf.xml")  # the package's own reader: columns all there
    assert [f.body for f in loads.forces] == ["calcn_r", "calcn_l"]


def test_each_plate_is_given_the_foot_standing_on_it(converted):
    """Plate 1 is stepped on by the right foot, plate 2 by the left: the heel marker of that foot
    stands still (under 0.3 m/s) over the plate in mid-contact, the other foot's swings past."""
    out, record, _ = converted
    markers = read_trc(out / "walking2.trc")
    by_plate = {c["plate"]: c for c in record["contacts"]}
    assert by_plate[1]["side"] == "r" and by_plate[2]["side"] == "l"
    assert not any(c["two_feet"] for c in record["contacts"])
    for plate, heel, other in ((1, "RCAL", "LCAL"), (2, "LCAL", "RCAL")):
        c = by_plate[plate]
        mid = np.argmin(np.abs(markers.time - 0.5 * (c["start_s"] + c["end_s"])))
        speed = lambda n: np.linalg.norm(np.gradient(markers.marker(n), markers.time, axis=0)[mid])  # noqa: E731
        assert speed(heel) < 0.3 < 1.0 < speed(other)
    assert [f["body"] for f in record["forces"]] == ["calcn_r", "calcn_l"]


def test_centre_of_pressure_matches_ezc3d(walking2):
    """The centre of pressure from force and moment (trial.py) equals ezc3d's own, turned into
    OpenSim's frame, wherever a plate is loaded."""
    import ezc3d

    trial = read_c3d(walking2)
    raw = ezc3d.c3d(str(walking2), extract_forceplat_data=True)["data"]["platform"]
    for plate, fp in zip(trial.plates, raw):
        cop, _ = plate.centre_of_pressure(50.0)
        theirs = (fp["center_of_pressure"].T / 1000) @ trial.rotation.T
        on = plate.vertical() > 50.0
        assert on.sum() > 500
        assert np.allclose(cop[on], theirs[on], atol=1e-6)
        free = np.asarray(fp["Tz"]).T / 1000 @ trial.rotation.T
        assert np.allclose(plate.centre_of_pressure(50.0)[1][on], free[on, 1], atol=1e-6)


def test_offsets_removed(converted, walking2):
    out, record, _ = converted
    offsets = {p["number"]: p["offset_force_n"][1] for p in record["plates"]}
    trial = read_c3d(walking2)
    for plate in trial.plates:  # unloaded in the first second: the raw reading is the offset
        quiet = plate.time < 1.0
        raw = plate.vertical()[quiet].mean()
        assert abs(raw) > 10 and offsets[plate.number] == pytest.approx(raw, abs=1.0)
    from musclemetab.io import read_storage

    grf = read_storage(out / "walking2_grf.mot")
    assert np.all(grf.loc[:1.0, ["ground_force_vy", "1_ground_force_vy"]].to_numpy() == 0)


def _heel_strikes(markers, name, slow_m_s=0.6, swing_m_s=2.0):
    """Times the heel marker lands: its horizontal speed falls below ``slow_m_s`` within 0.1 s of
    exceeding ``swing_m_s`` (the foot's swing)."""
    v = np.linalg.norm(np.gradient(markers.marker(name)[:, [0, 2]], markers.time, axis=0), axis=1)
    n = int(round(0.1 * markers.rate_hz))
    return np.array([markers.time[i] for i in range(n, len(v))
                     if np.isfinite(v[i - n:i + 1]).all() and v[i] < slow_m_s <= v[i - 1]
                     and v[i - n:i].max() > swing_m_s])


def test_total_vertical_force_is_body_weight(converted):
    """The plates hold the whole load from the right heel strike on plate 1 to the next left heel
    strike (the left foot pushes off plate 2 with its forefoot, then swings): one step, over which
    the mean vertical force is body weight. The body weight comes from elsewhere: the vertical
    impulse of the right foot's whole contact, which in steady walking is body weight times half
    the stride time, the stride timed by the right heel marker (1.0 s)."""
    from musclemetab.io import read_storage

    out, record, _ = converted
    markers = read_trc(out / "walking2.trc")
    grf = read_storage(out / "walking2_grf.mot")
    t = grf.index.to_numpy()
    total = grf["ground_force_vy"].to_numpy() + grf["1_ground_force_vy"].to_numpy()
    right = [c for c in record["contacts"] if c["side"] == "r"][0]
    r_hs = _heel_strikes(markers, "RCAL")
    l_hs = _heel_strikes(markers, "LCAL")
    (k,) = np.flatnonzero(np.abs(r_hs - right["start_s"]) < 0.05)  # the heel strike on plate 1
    stride = r_hs[k] - r_hs[k - 1]
    assert 0.9 < stride < 1.1
    weight = right["impulse_ns"] / (stride / 2)
    step_end = l_hs[l_hs > right["start_s"]][0]
    window = (t >= right["start_s"]) & (t < step_end)
    mean = total[window].mean()
    assert mean == pytest.approx(weight, rel=0.05)
    assert 55 < weight / G < 80  # an adult's mass (kg)


def _plate(forces, cops, time):
    """A 1 m x 1 m plate at the origin with the given vertical forces and centres of pressure."""
    corners = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], dtype=float)
    centre = corners.mean(axis=0)
    force = np.zeros((len(time), 3))
    force[:, 1] = forces
    moment = np.cross(cops - centre, force)
    return Plate(number=1, time=time, force=force, moment=moment, centre=centre, corners=corners)


def _foot(time, x_heel, on, z):
    """Heel and toe markers of a foot resting at ``x_heel`` while ``on``, elsewhere far away and moving."""
    heel = np.column_stack([np.where(on, x_heel, -2.0 + time), np.full(len(time), 0.05), np.full(len(time), z)])
    toe = heel + np.array([0.22, -0.02, 0.0])
    return heel, toe


def _feet_markers(time, right_on, left_on, right_x=0.2, left_x=0.6):
    rh, rt = _foot(time, right_x, right_on, 0.6)
    lh, lt = _foot(time, left_x, left_on, 0.4)
    return Markers(time=time, names=["RHEE", "RTOE", "LHEE", "LTOE"], xyz=np.stack([rh, rt, lh, lt], axis=1))


def test_a_plate_under_two_feet_at_once_is_flagged():
    """Right foot on the plate 0-0.6 s, left foot lands on it at 0.4 s: the plate's one force is
    both feet's, which no assignment can split."""
    time = np.arange(0, 1.0, 0.002)
    right_on, left_on = time < 0.6, time >= 0.4
    markers = _feet_markers(time, right_on, left_on)
    fr, fl = np.where(right_on, 400.0, 0.0), np.where(left_on, 400.0, 0.0)
    cop_r = np.array([0.3, 0, 0.6])
    cop_l = np.array([0.7, 0, 0.4])
    cops = (fr[:, None] * cop_r + fl[:, None] * cop_l) / np.maximum(fr + fl, 1e-9)[:, None]
    plate = _plate(fr + fl, cops, time)
    with pytest.warns(TwoFeetWarning, match="plate 1 carries both feet"):
        (contact,) = assign_feet([plate], markers, source="synthetic")
    assert contact.two_feet
    assert contact.share["r"] > 0.1 and contact.share["l"] > 0.1


def test_a_plate_stepped_on_by_each_foot_in_turn_is_two_forces():
    """Right foot 0-0.4 s, left foot 0.6-1.0 s on the same plate: two contacts, each its own
    foot's, written as two forces each zero outside its contact; not flagged."""
    time = np.arange(0, 1.0, 0.002)
    right_on, left_on = time < 0.4, time >= 0.6
    markers = _feet_markers(time, right_on, left_on)
    fv = np.where(right_on | left_on, 700.0, 0.0)
    cops = np.where(right_on[:, None], [0.3, 0, 0.6], [0.7, 0, 0.4])
    plate = _plate(fv, cops, time)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        contacts = assign_feet([plate], markers, source="synthetic")
    assert [(c.side, c.two_feet) for c in contacts] == [("r", False), ("l", False)]
    table, forces = ground_force_table([plate], contacts)
    assert [(pre, side) for pre, _, side in forces] == [("", "r"), ("1_", "l")]
    assert table["ground_force_vy"].to_numpy()[time >= 0.6].max() == 0
    assert table["1_ground_force_vy"].to_numpy()[time >= 0.6].min() == 700
    assert np.allclose(table.loc[0.1, ["ground_force_px", "ground_force_pz"]].to_numpy(dtype=float), [0.3, 0.6])


def test_offsets_of_a_synthetic_plate():
    time = np.arange(0, 2.0, 0.001)
    fv = np.where((time > 0.5) & (time < 1.1), 600.0, 0.0) - 15.0
    plate = _plate(fv, np.tile([0.5, 0, 0.5], (len(time), 1)), time)
    assert remove_offsets(plate)
    assert plate.offset_force[1] == pytest.approx(-15.0)
    assert plate.vertical()[time < 0.4].max() == pytest.approx(0.0)


def test_foot_markers_recognised_by_name():
    gait2392 = ["R.Heel", "R.Toe.Tip", "R.Midfoot.Sup", "R.Ankle.Lat", "L.Heel", "L.Toe.Tip", "L.ASIS"]
    feet = foot_marker_sets(gait2392)
    assert feet["r"] == {"heel": ["R.Heel"], "fore": ["R.Toe.Tip", "R.Midfoot.Sup"]}
    assert feet["l"] == {"heel": ["L.Heel"], "fore": ["L.Toe.Tip"]}
    pig = foot_marker_sets(["RHEE", "RTOE", "LHEE", "LTOE", "LMMAL", "RMT5", "calc_r"])
    assert pig["r"]["heel"] == ["RHEE", "calc_r"] and pig["r"]["fore"] == ["RTOE", "RMT5"]
    assert pig["l"] == {"heel": ["LHEE"], "fore": ["LTOE"]}
    rajagopal = foot_marker_sets(["RHEE", "RFMH", "RVMH", "LHEE", "LFMH", "LVMH", "RANK", "RMED", "LM5"])
    assert rajagopal["r"] == {"heel": ["RHEE"], "fore": ["RFMH", "RVMH"]}
    assert rajagopal["l"] == {"heel": ["LHEE"], "fore": ["LFMH", "LVMH", "LM5"]}


def test_no_foot_markers_is_an_error_naming_the_option():
    time = np.arange(0, 1.0, 0.01)
    markers = Markers(time=time, names=["A", "B"], xyz=np.zeros((len(time), 2, 3)))
    plate = _plate(np.full(len(time), 500.0), np.tile([0.5, 0, 0.5], (len(time), 1)), time)
    with pytest.raises(DataMismatchError, match="--plate-feet"):
        assign_feet([plate], markers, source="x.c3d")
    (contact,) = assign_feet([plate], markers, plate_feet={1: "l"})
    assert contact.side == "l" and contact.how == "given"


def test_command_line(walking2, tmp_path, capsys):
    from musclemetab.commands import main

    assert main(["c3d", str(walking2), "--plate-feet", "1=r", "2=l", "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "plate 1 2.672-3.248 s: right" in out and "plate 2 2.248-2.756 s: left" in out
    assert sorted(p.name for p in (tmp_path / "o").iterdir() if not p.name.startswith(".")) == [
        "walking2.trc", "walking2_c3d.json", "walking2_grf.mot", "walking2_grf.xml"]
    assert main(["c3d", str(walking2), "--plate-feet", "1=x", "--out", str(tmp_path / "p")]) == 1
    assert "--plate-feet '1=x'" in capsys.readouterr().err
    assert not (tmp_path / "p").exists()
    assert main(["c3d", str(tmp_path / "none.c3d"), "--out", str(tmp_path / "q")]) == 1
    assert "no such C3D file" in capsys.readouterr().err


def test_a_plate_the_file_lacks_is_refused(walking2, tmp_path, capsys):
    from musclemetab.commands import main

    assert main(["c3d", str(walking2), "--plate-feet", "3=r", "--out", str(tmp_path / "o")]) == 1
    assert capsys.readouterr().err.strip() == (
        f"musclemetab: error: --plate-feet 3=r: {walking2} has no force plate 3; its force plates are 1, 2")
    assert not (tmp_path / "o").exists()
    time = np.arange(0, 1.0, 0.01)
    markers = Markers(time=time, names=["A", "B"], xyz=np.zeros((len(time), 2, 3)))
    plate = _plate(np.full(len(time), 500.0), np.tile([0.5, 0, 0.5], (len(time), 1)), time)
    with pytest.raises(OptionError, match="--plate-feet 2=l 4=r: x.c3d has no force plates 2, 4; its force plates "
                                          "are 1$"):
        assign_feet([plate], markers, plate_feet={1: "r", 2: "l", 4: "r"}, source="x.c3d")


def test_two_plates_given_to_one_foot_loaded_at_once_are_flagged(walking2, tmp_path, capsys):
    """walking2's plate 1 carries the right foot 2.672-3.248 s and plate 2 the left 2.248-2.756 s:
    given both to the left foot, that foot would carry both at 2.672-2.756 s."""
    import json

    from musclemetab.commands import main

    assert main(["c3d", str(walking2), "--plate-feet", "1=l", "2=l", "--out", str(tmp_path / "o")]) == 0
    captured = capsys.readouterr()
    assert ("plate 1 2.672-3.248 s: left (loaded with plate 2!), plate 2 2.248-2.756 s: left (loaded with plate 1!)"
            in captured.out)
    assert (f"musclemetab: warning: {walking2}: force plates 1 and 2 are both given to the left foot (--plate-feet) "
            "and are loaded at the same time, 2.672-2.756 s (plate 1 2.672-3.248 s, plate 2 2.248-2.756 s): the left "
            "foot gets both plates' forces together there, which is right only when it stands on both plates at "
            "once; else give one of them to the other foot") in captured.err.splitlines()
    record = json.loads((tmp_path / "o" / "walking2_c3d.json").read_text())
    assert [[(o["plate"], round(o["start_s"], 3), round(o["end_s"], 3)) for o in c["overlaps"]]
            for c in record["contacts"]] == [[(2, 2.672, 2.756)], [(1, 2.672, 2.756)]]
    assert main(["c3d", str(walking2), "--plate-feet", "1=r", "2=l", "--out", str(tmp_path / "p")]) == 0
    captured = capsys.readouterr()  # each plate to its own foot: no overlap
    assert "loaded with" not in captured.out and "loaded at the same time" not in captured.err
    assert "plate 1 2.672-3.248 s: right, plate 2 2.248-2.756 s: left" in captured.out


def _c3d_with_emg(path, units=("mV", "uV")):
    """A C3D file as a lab with EMG writes it: 4 markers at 100 Hz (mm), one type-2 force plate
    and two EMG channels at 2000 Hz, 2 s. Each EMG channel is a 100 Hz carrier whose amplitude
    ``A(t)`` varies slowly (a known envelope): ``A(t) = 1 + 0.8 sin(2 pi t)`` (channel 1, in
    ``units[0]``) and ``2 + cos(pi t)`` (channel 2). The plate's channels come first, the EMG's
    after them, as labs order them."""
    import ezc3d
    from ezc3d import ezc3d as swig

    rate, n = 2000.0, 4000
    t = np.arange(n) / rate
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = ("RHEE", "RTOE", "LHEE", "LTOE")
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, 4, n // 20))
    pts[:3] = np.array([[0, 100, 0], [200, 100, 0], [0, -100, 0], [200, -100, 0]], float).T[:, :, None] \
        + np.arange(n // 20)[None, None, :] * np.array([10.0, 0, 0])[:, None, None]
    c["data"]["points"] = pts
    amp = np.vstack([1 + 0.8 * np.sin(2 * np.pi * t), 2 + np.cos(np.pi * t)])
    emg = amp * np.sin(2 * np.pi * 100 * t)
    analog = np.zeros((1, 8, n))
    analog[0, 2] = -700.0  # the plate's Fz (plate frame, z down): a foot standing on it
    analog[0, 6:] = emg
    c["parameters"]["ANALOG"]["RATE"]["value"] = [rate]
    c["parameters"]["ANALOG"]["LABELS"]["value"] = ("Fx1", "Fy1", "Fz1", "Mx1", "My1", "Mz1", "EMG_SOL", "EMG_TA")
    c["parameters"]["ANALOG"]["UNITS"]["value"] = ("N", "N", "N", "Nmm", "Nmm", "Nmm", *units)
    c["data"]["analogs"] = analog
    for name, value in (("USED", np.array([1.0])), ("TYPE", np.array([2.0])), ("CHANNEL", np.arange(1.0, 7.0)[:, None]),
                        ("ZERO", np.array([0.0, 0.0]))):
        c.add_parameter("FORCE_PLATFORM", name, value)
        c["parameters"]["FORCE_PLATFORM"][name]["type"] = swig.INT
    corners = np.array([[600, 300, 0], [0, 300, 0], [0, -300, 0], [600, -300, 0]], float).T[:, :, None]
    c.add_parameter("FORCE_PLATFORM", "CORNERS", corners)
    c.add_parameter("FORCE_PLATFORM", "ORIGIN", np.zeros((3, 1)))
    c.write(str(path))
    return t, emg, amp


def test_emg_from_a_c3d_files_analog_channels(tmp_path):
    """The analog channels that are not the plates' are the EMG: read in volts (mV and uV as the
    file says), processed from raw into the envelope the carriers were given (away from the ends,
    as for a .sto of raw EMG in tests/test_emg.py), and written by the conversion as a raw EMG
    file that reads back the same."""
    from musclemetab.emg import read_emg
    from musclemetab.emg.processing import RawEmgPath
    from musclemetab.errors import InputFileError, MissingColumnError
    from musclemetab.io import read_storage
    from musclemetab.mocap.c3d import read_c3d_analogs

    path = tmp_path / "walk_emg.c3d"
    t, emg, amp = _c3d_with_emg(path)
    raw = read_c3d_analogs(path)
    assert list(raw.columns) == ["EMG_SOL", "EMG_TA"]  # the plate's six channels left out
    np.testing.assert_allclose(raw.index.to_numpy(), t, atol=1e-12)
    np.testing.assert_allclose(raw["EMG_SOL"].to_numpy(), emg[0] * 1e-3, rtol=1e-5, atol=1e-9)  # mV -> V
    np.testing.assert_allclose(raw["EMG_TA"].to_numpy(), emg[1] * 1e-6, rtol=1e-5, atol=1e-12)  # uV -> V
    assert raw.attrs["units"] == {"EMG_SOL": "V", "EMG_TA": "V"}
    env = read_emg(RawEmgPath(path))
    inner = (env.index > 0.3) & (env.index < 1.7)
    for k, channel in enumerate(("EMG_SOL", "EMG_TA")):
        want = np.interp(env.index[inner], t, amp[k]) / amp[k].max()
        assert np.abs(env[channel].to_numpy()[inner] - want).max() < 0.01, channel
    with pytest.raises(MissingColumnError, match="EMG_GM"):
        read_c3d_analogs(path, channels=["EMG_GM"])
    out = tmp_path / "out"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        record = convert_c3d(path, out)
    assert record["emg_channels"] == ["EMG_SOL", "EMG_TA"]
    written = read_storage(out / "walk_emg_emg.sto")
    np.testing.assert_allclose(written["EMG_SOL"].to_numpy(), raw["EMG_SOL"].to_numpy(), rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(written.index.to_numpy(), t, atol=1e-9)


def test_a_c3d_without_emg_says_so(walking2, converted):
    from musclemetab.errors import InputFileError
    from musclemetab.mocap.c3d import read_c3d_analogs

    with pytest.raises(InputFileError, match="no analog channel besides the force plates'"):
        read_c3d_analogs(walking2)
    assert "emg" not in converted[1]["files"] and "emg_channels" not in converted[1]
