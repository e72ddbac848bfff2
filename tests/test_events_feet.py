"""Gait events: the foot of a ground force found from its centre of pressure, ground-force and
kinematic heel strikes cross-checked, implausible cycle durations refused, heel strikes near the
end of a record. Data: OpenSim's gait2392 walking example (both feet on force plates; the README
gives the force-defined events) and synthetic arrays."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from musclemetab.errors import DataMismatchError, WindowWarning
from musclemetab.events import (
    GaitCycle,
    check_cycle_duration,
    foot_kinematics,
    gait_events_from_grf,
    gait_events_from_kinematics,
    grf_of_side,
)
from musclemetab.io import read_storage, write_storage

#: README of the gait2392 data (vertical force above 20 N): right heel strikes, left heel strikes (s).
RIGHT_HS, LEFT_HS = (0.618, 1.853), (1.247, 2.460)


@pytest.fixture(scope="module")
def layout(gait2392):
    from musclemetab.layout import read_layout

    return read_layout(gait2392.model)


@pytest.fixture(scope="module")
def feet(gait2392, layout):
    return foot_kinematics(gait2392.model, gait2392.ik, layout)


def _grf_file(gait2392):
    return gait2392.grf


def _swapped(gait2392, tmp_path):
    """The gait2392 forces with the two plates' columns exchanged: ``ground_force_*`` (the name
    rule's right foot) now holds the left foot, as in another lab's files."""
    df = read_storage(_grf_file(gait2392))
    first = [c for c in df.columns if c.startswith("ground_")]
    swap = {c: "1_" + c for c in first} | {"1_" + c: c for c in first}
    out = tmp_path / "swapped_grf.mot"
    write_storage(out, df.rename(columns=swap)[list(df.columns)], name="swapped")
    return out


def test_the_centre_of_pressure_names_the_foot(gait2392, feet):
    s, notes, found = grf_of_side(_grf_file(gait2392), "r", feet=feet)
    assert s.name == "ground_force_vy" and not notes
    # the right foot's own CoP lies a few cm from its heel-toe segment, the left foot half a metre away
    assert found.side == "r" and found.distance_m["r"] < 0.05 and found.distance_m["l"] > 0.3
    s, notes, found = grf_of_side(_grf_file(gait2392), "l", feet=feet)
    assert s.name == "1_ground_force_vy" and found.side == "l" and not notes


def test_a_column_named_for_the_wrong_foot_is_found_out(gait2392, layout, feet, tmp_path):
    from musclemetab.redundancy.window import resolve_window

    path = _swapped(gait2392, tmp_path)
    # the name rule would take ground_force_vy for the right foot: the data say it is the left one
    s, notes, found = grf_of_side(path, "r", feet=feet)
    assert s.name == "1_ground_force_vy" and found.side == "r"
    assert "column ground_force_vy is not the right foot's force" in notes[0] and "left foot" in notes[0]
    with pytest.warns(WindowWarning, match="ground_force_vy is not the right foot"):
        w = resolve_window(gait2392.ik, side="r", cycle="auto", grf_path=path, layout=layout)
    assert (w.cycle["start_s"], w.cycle["end_s"]) == pytest.approx(RIGHT_HS, abs=3e-3)
    assert any("1_ground_force_vy is used" in m for m in w.warnings)
    # the user naming that column for the right foot is told what the data show
    with pytest.raises(DataMismatchError, match=r"lies under the left foot \(.*right foot's force is column 1_gr"):
        resolve_window(gait2392.ik, side="r", cycle="auto", grf_path=path, grf_column="ground_force_vy",
                       layout=layout)


def test_a_study_trial_and_analyse_check_the_foot_too(gait2392, tmp_path):
    from musclemetab.events import cycle_of_trial
    from musclemetab.study.events import trial_cycle
    from musclemetab.study.spec import Trial

    path = _swapped(gait2392, tmp_path)
    ik = read_storage(gait2392.ik)
    short = tmp_path / "ik_0.5-2.0.mot"  # its middle, 1.25 s, lies in the right foot's first cycle
    write_storage(short, ik[ik.index <= 2.0], name="ik", in_degrees=True)
    trial = Trial(name="walk", ik=short, id=None, grf=path)
    with pytest.warns(WindowWarning, match="trial 'walk': .*ground_force_vy is not the right foot"):
        cycle = trial_cycle(trial, "r", gait2392.model)
    assert (cycle.start_s, cycle.end_s) == pytest.approx(RIGHT_HS, abs=3e-3)
    with pytest.warns(WindowWarning, match="ground_force_vy is not the right foot"):
        again, source = cycle_of_trial(short, grf=path, side="r", model=gait2392.model)
    assert again == cycle and source == "ground reaction forces"


def test_applied_to_body_is_checked_against_the_centre_of_pressure(gait2392, layout, feet, tmp_path):
    from musclemetab.events import check_applied_feet as check_feet
    from musclemetab.external_loads import read_external_loads

    loads = read_external_loads(gait2392.external_loads)
    assert check_feet(loads, layout, feet) == []
    text = gait2392.external_loads.read_text()
    xml = tmp_path / "swapped.xml"
    xml.write_text(text.replace("calcn_r", "CALCN_X").replace("calcn_l", "calcn_r").replace("CALCN_X", "calcn_l")
                   .replace("subject01_walk1_grf.mot", str(_grf_file(gait2392))))
    notes = check_feet(read_external_loads(xml), layout, feet)
    assert len(notes) == 2
    assert "'ExternalForce_1' is applied to calcn_l (left leg) but its centre of pressure lies under the right foot" \
        in notes[0]


def test_force_and_kinematic_heel_strikes_are_cross_checked(gait2392, layout, tmp_path):
    from musclemetab.redundancy.window import resolve_window

    # agreeing (19-26 ms apart on these data): no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error", WindowWarning)
        w = resolve_window(gait2392.ik, side="r", cycle="auto", grf_path=_grf_file(gait2392), layout=layout)
    assert not w.warnings
    # the force file's clock 0.1 s late: both heel-strike pairs are named, with both times
    df = read_storage(_grf_file(gait2392))
    df.index = df.index + 0.1
    late = tmp_path / "late_grf.mot"
    write_storage(late, df, name="late")
    with pytest.warns(WindowWarning) as rec:
        w = resolve_window(gait2392.ik, side="r", cycle="auto", grf_path=late, layout=layout)
    msgs = [str(r.message) for r in rec if "kinematic heel strike" in str(r.message)]
    assert len(msgs) == 2
    assert f"initial contact at {RIGHT_HS[0] + 0.1:.3f} s" in msgs[0] and "at 0.599 s" in msgs[0]
    assert "more than 50 ms" in msgs[0] and msgs[0] in w.warnings


def test_implausible_cycle_durations_are_refused(gait2392, layout):
    from musclemetab.redundancy.window import resolve_window

    # an extra contact (a second plate) splits a 1.2 s stride into 0.66 + 0.54 s
    t = np.arange(0.0, 3.0, 0.001)
    f = np.where(((t > 0.10) & (t < 0.70)) | ((t > 0.76) & (t < 0.85)) | ((t > 1.30) & (t < 2.00)), 700.0, 0.0)
    ev = gait_events_from_grf(t, f)
    np.testing.assert_allclose(ev.heel_strikes_s, [0.1, 0.76, 1.3], atol=2e-3)
    cycle = GaitCycle(ev.heel_strikes_s[0], ev.toe_offs_s[0], ev.heel_strikes_s[1])
    with pytest.raises(DataMismatchError, match=r"heel strike at 0\.100 s.*next at 0\.76. s lasts 0\.66. s, outside "
                                                r"0\.8-2 s.*--cycle-duration MIN:MAX"):
        check_cycle_duration(cycle)
    check_cycle_duration(cycle, (0.5, 2.0))  # the override
    check_cycle_duration(cycle, None)
    # through the solve window: gait2392's right stride (1.234 s) against a range that excludes it
    with pytest.raises(DataMismatchError, match=r"cycle auto of the right leg: the gait cycle from the heel strike at "
                                                r"0\.618 s .* lasts 1\.234 s, outside 1\.3-2 s"):
        resolve_window(gait2392.ik, side="r", cycle="auto", grf_path=_grf_file(gait2392), layout=layout,
                       cycle_duration_s=(1.3, 2.0))


def _heel_ahead(t, strikes, stride=1.2):
    """Synthetic heel, toe and pelvis positions: the heel furthest ahead of the pelvis (0.35 m) at
    each time of ``strikes``, a sinusoidal excursion of one stride."""
    pelvis = np.stack([1.2 * t, np.full_like(t, 0.9), np.zeros_like(t)], axis=1)
    phase = 2 * np.pi * (t - strikes[0]) / stride
    heel = pelvis + np.stack([0.35 * np.cos(phase), -0.85 + 0 * t, 0 * t], axis=1)
    toe = pelvis + np.stack([0.35 * np.cos(phase - 2.3) + 0.2, -0.9 + 0 * t, 0 * t], axis=1)
    return heel, toe, pelvis


def test_a_heel_strike_65_ms_before_the_end_of_the_record_is_found(gait2392, feet):
    # synthetic: heel strikes at 0.3 and 1.5 s, the record (100 Hz) cut 65 ms after the second
    t = np.arange(0.0, 1.5 + 0.065 + 1e-9, 0.01)
    heel, toe, pelvis = _heel_ahead(t, [0.3, 1.5])
    ev = gait_events_from_kinematics(t, heel, toe, pelvis)
    np.testing.assert_allclose(ev.heel_strikes_s, [0.3, 1.5], atol=2e-3)
    # gait2392 (60 Hz): the IK cut 65 ms after the right heel strike at 1.829 s (kinematics)
    k = feet.time_s <= 1.829 + 0.065
    cut = gait_events_from_kinematics(feet.time_s[k], feet.heel_m["r"][k], feet.toe_m["r"][k], feet.root_m[k],
                                      up=feet.up)
    whole = feet.events("r")
    np.testing.assert_allclose(cut.heel_strikes_s, whole.heel_strikes_s[:2], atol=1e-9)
    # the ground force cut 65 ms after the right heel strike (0.618 s): found, at the same time
    df = read_storage(_grf_file(gait2392))
    tf, fz = df.index.to_numpy(float), df["ground_force_vy"].to_numpy(float)
    k = tf <= RIGHT_HS[0] + 0.065
    assert gait_events_from_grf(tf[k], fz[k]).heel_strikes_s[-1] == pytest.approx(RIGHT_HS[0], abs=3e-3)


def test_the_solve_command_takes_the_cycle_duration_range(gait2392, tmp_path, capsys):
    from musclemetab.commands import main

    common = ["solve", "--model", str(gait2392.model), "--ik", str(gait2392.ik), "--id", str(gait2392.id),
              "--grf", str(gait2392.grf), "--cycle", "auto", "--out", str(tmp_path / "out")]
    # refused before any solve: the right stride of 1.234 s lies outside the range given
    assert main(common + ["--cycle-duration", "1.3:2.0"]) == 1
    assert "lasts 1.234 s, outside 1.3-2 s" in capsys.readouterr().err
    assert main(common + ["--cycle-duration", "2:1"]) == 1
    assert "--cycle-duration 2:1: T0 must be finite and before T1" in capsys.readouterr().err
    assert main(common[:-4] + ["--out", str(tmp_path / "o"), "--cycle-duration", "0.5:2"]) == 1
    assert "--cycle-duration bounds the --cycle" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
