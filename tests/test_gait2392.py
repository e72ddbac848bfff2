"""A second subject as a user has it: OpenSim's gait2392 walking example (both legs, 60 Hz, ground forces).

Oracles: the gait events of the data set's README (vertical force, 20 N), OpenSim's own stored
inverse dynamics (over the time it covers), the model's joint tree as OpenSim reports it, and the
solver's own constraint residual. One left-leg solve per session (46 muscles, 7 DOFs).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from musclemetab.errors import DataMismatchError, InputFileError, ModelError, UnknownCoordinateError


pytestmark = pytest.mark.opensim


@pytest.fixture(scope="module")
def layout(gait2392):
    from musclemetab.layout import read_layout

    return read_layout(gait2392.model)


def test_sides_and_dofs_from_the_joint_tree(layout, example):
    from musclemetab.layout import discover_dofs, read_layout, side_dofs
    from musclemetab.redundancy.inputs import DEFAULT_DOFS

    # gait2392: subtalar and mtp joints are unlocked; distal to proximal
    stems = ["mtp_angle", "subtalar_angle", "ankle_angle", "knee_angle", "hip_flexion", "hip_adduction", "hip_rotation"]
    for side in "rl":
        assert side_dofs(layout, side) == [f"{s}_{side}" for s in stems]
    assert layout.body_side("calcn_l") == "l" and layout.body_side("torso") is None
    assert layout.forward_coordinates() == ("pelvis_tx", "pelvis_tz")
    # the study's model: locked subtalar/mtp and the coupled knee_angle_r_beta drop out, giving the
    # study's five DOFs in the study's order
    ex = read_layout(example.model)
    from musclemetab.io import read_storage

    cols = read_storage(example.id["normal"]).columns
    assert tuple(discover_dofs(ex, "r", cols)) == DEFAULT_DOFS


def test_gait_events_of_either_leg_from_the_external_loads(gait2392, layout):
    from musclemetab.events import gait_events_from_grf
    from musclemetab.external_loads import read_external_loads, vertical_force

    loads = read_external_loads(gait2392.external_loads)
    ev = {s: gait_events_from_grf(*vertical_force(loads, layout, s)) for s in "rl"}
    # README: right HS 0.618, TO 1.410, HS 1.853; left TO 0.788, HS 1.247, TO 2.018, HS 2.460
    np.testing.assert_allclose(ev["r"].heel_strikes_s, [0.618, 1.853], atol=3e-3)
    np.testing.assert_allclose(ev["r"].toe_offs_s[-1], 1.410, atol=3e-3)
    np.testing.assert_allclose(ev["l"].heel_strikes_s, [1.247, 2.460], atol=3e-3)
    np.testing.assert_allclose(ev["l"].toe_offs_s, [0.788, 2.018], atol=3e-3)


#: Kinematic events against the force-defined events of the README: 0.04 s, 2.4 frames of the
#: 60 Hz IK. The rule places heel strike where the heel is furthest ahead of the pelvis, which
#: on these data comes 19-28 ms before the vertical force passes 20 N (toe-offs within 3 ms);
#: 0.04 s stays inside the study's 0.05 s padding, so a window padded around the kinematic
#: cycle still holds the force-defined one.
KINEMATIC_EVENT_TOLERANCE_S = 0.04


def test_gait_events_of_either_leg_from_kinematics_alone(gait2392, layout):
    from musclemetab.events import kinematic_gait_events
    from musclemetab.layout import foot_bodies
    from musclemetab.redundancy.window import resolve_window

    tol = KINEMATIC_EVENT_TOLERANCE_S
    assert foot_bodies(layout, "r") == ("calcn_r", "toes_r") and foot_bodies(layout, "l") == ("calcn_l", "toes_l")
    ev = {s: kinematic_gait_events(gait2392.model, gait2392.ik, s, layout) for s in "rl"}
    # README (forces, 20 N): right HS 0.618, TO 1.410, HS 1.853; left TO 0.788, HS 1.247, TO 2.018, HS 2.460;
    # the IK runs on to 4.0 s, so a third cycle follows (no force reference there)
    np.testing.assert_allclose(ev["r"].heel_strikes_s[:2], [0.618, 1.853], atol=tol)
    np.testing.assert_allclose(ev["r"].toe_offs_s[0], 1.410, atol=tol)
    np.testing.assert_allclose(ev["l"].heel_strikes_s[:2], [1.247, 2.460], atol=tol)
    np.testing.assert_allclose(ev["l"].toe_offs_s[:2], [0.788, 2.018], atol=tol)
    # heel strikes alternate between the legs, one stride apart
    assert np.all(np.diff(ev["r"].heel_strikes_s) > 1.0) and np.all(np.diff(ev["l"].heel_strikes_s) > 1.0)
    # no forces given: --cycle comes from the kinematics, and the record says so
    w = resolve_window(gait2392.ik, side="l", cycle="auto", layout=layout)
    assert (w.cycle["start_s"], w.cycle["end_s"]) == pytest.approx((1.247, 2.460), abs=tol)
    assert "kinematics" in w.cycle["source"] and not w.warnings
    with pytest.raises(DataMismatchError, match="left leg.s kinematics gives 2 complete gait cycles.*cycle 3 does not"):
        resolve_window(gait2392.ik, side="l", cycle=3, layout=layout)


def test_inverse_dynamics_computed_by_opensim_matches_the_stored_file(gait2392):
    """Computed ID against OpenSim's stored file over their common time (0.5-1.6 s).

    Tolerance: 0.1 N m plus 2 % of each moment's range. The stored file was written by an
    older OpenSim (setup file version 20302) from the same model, IK, forces and 6 Hz filter;
    knee and ankle agree to 0.05 N m, the hips to 1.5 N m (1.7 % of range), a difference that
    grows from zero at the first common frame, as from the upper body's dynamics. A wrong
    side, force, filter or unit shows up as tens of N m.
    """
    from musclemetab.external_loads import compute_inverse_dynamics
    from musclemetab.io import read_storage

    ours = read_storage(compute_inverse_dynamics(gait2392.model, gait2392.ik, gait2392.external_loads, 0.5, 1.6))
    stored = read_storage(gait2392.id)
    t = ours.index.to_numpy()
    assert t[0] == pytest.approx(0.5, abs=1e-5) and t[-1] == pytest.approx(1.6, abs=1e-5)
    for side in "rl":
        for stem in ("hip_flexion", "hip_adduction", "hip_rotation", "knee_angle", "ankle_angle", "subtalar_angle"):
            c = f"{stem}_{side}_moment"
            ref = np.interp(t, stored.index.to_numpy(), stored[c].to_numpy())
            tol = 0.1 + 0.02 * np.ptp(stored[c].to_numpy())
            assert np.max(np.abs(ours[c].to_numpy() - ref)) < tol, c
        for stem in ("knee_angle", "ankle_angle"):
            c = f"{stem}_{side}_moment"
            ref = np.interp(t, stored.index.to_numpy(), stored[c].to_numpy())
            assert np.max(np.abs(ours[c].to_numpy() - ref)) < 0.1, c


def test_cycle_windows_and_clipping(gait2392, layout):
    from musclemetab.external_loads import read_external_loads
    from musclemetab.redundancy.window import resolve_window

    loads = read_external_loads(gait2392.external_loads)
    r = resolve_window(gait2392.ik, side="r", cycle="auto", external_loads=loads, layout=layout)
    assert r.cycle["start_s"] == pytest.approx(0.618, abs=3e-3) and r.cycle["end_s"] == pytest.approx(1.853, abs=3e-3)
    # padding 0.05 s, snapped outwards to 60 Hz frames
    assert r.start_s <= r.cycle["start_s"] - 0.05 < r.start_s + 1 / 60 and not r.warnings
    with pytest.warns(UserWarning, match="clipped"):
        left = resolve_window(gait2392.ik, side="l", cycle="auto", external_loads=loads, layout=layout)
    # the ground forces end at 2.5 s, 40 ms after the left heel strike: padding clipped there
    assert left.end_s == pytest.approx(2.5, abs=1e-6) and left.padding_s[1] < 0.05
    assert "clipped" in left.record()["warnings"][0]
    with pytest.raises(DataMismatchError, match="1 complete gait cycle.*cycle 2 does not exist"):
        resolve_window(gait2392.ik, side="l", cycle=2, external_loads=loads, layout=layout)
    with pytest.raises(DataMismatchError, match=r"subject01_walk1_grf.mot.*ends 0.500 s before the window end 3.000 s"):
        resolve_window(gait2392.ik, side="r", window=(1.0, 3.0), external_loads=loads, layout=layout)
    with pytest.raises(DataMismatchError, match=r"subject01_walk1_ik.mot.*starts 0.100 s after"):
        resolve_window(gait2392.ik, side="r", window=(0.4, 1.0), external_loads=loads, layout=layout)


def test_external_loads_errors(gait2392, layout, tmp_path):
    from musclemetab.external_loads import read_external_loads

    text = gait2392.external_loads.read_text()
    bad_body = tmp_path / "body.xml"
    bad_body.write_text(text.replace("<applied_to_body> calcn_l </applied_to_body>",
                                     "<applied_to_body> foot_left </applied_to_body>"))
    (tmp_path / gait2392.grf.name).write_bytes(gait2392.grf.read_bytes())
    with pytest.raises(ModelError, match="ExternalForce_2.*'foot_left' is not a body"):
        read_external_loads(bad_body).check_bodies(layout)
    missing = tmp_path / "missing.xml"
    missing.write_text(text.replace("subject01_walk1_grf.mot", "nowhere.mot"))
    with pytest.raises(InputFileError, match="nowhere.mot does not exist"):
        read_external_loads(missing)


def _cli(*argv):
    from musclemetab.commands import main

    return main(list(map(str, argv)))


def test_bad_trial_input_one_line_no_output(gait2392, tmp_path, capsys):
    # the knee's moment asked for but absent
    id_alien = tmp_path / "id.sto"
    id_alien.write_text(gait2392.id.read_text().replace("knee_angle_r_moment", "knee_angle_r_torque"))
    out = tmp_path / "out"
    cases = [
        (["--id", id_alien, "--dofs", "knee_angle_r", "hip_flexion_r", "--window", "0.6:1.4"],
         "missing inverse-dynamics column knee_angle_r_moment"),
        (["--id", gait2392.id, "--dofs", "knee_angle_r", "wrist_flex_r"], "has no coordinate wrist_flex_r"),
        # the kinematics given as the inverse dynamics: named, and said to look like kinematics
        (["--id", gait2392.ik], f"the inverse dynamics {gait2392.ik} holds no moment for the right side's DOFs"),
        (["--id", gait2392.ik], "as in a kinematics file: check that --id names the inverse dynamics and --ik the "
                                "kinematics"),
        (["--external-loads", gait2392.external_loads, "--window", "2.0:3.0"], "ends 0.500 s before"),
        (["--external-loads", gait2392.external_loads, "--side", "l", "--cycle", "3"], "cycle 3 does not exist"),
        # no forces: neither cycle from the kinematics (0.60-1.83, 1.83-3.05 s) fits the stored ID (0.4-1.6 s);
        # the remedy names the options that fit, not --window alone
        (["--id", gait2392.id, "--cycle", "auto"],
         "subject01_walk1_id.sto: the inverse dynamics (0.400-1.600 s) ends 0.228989 s before the right leg's gait "
         "cycle end 1.829 s (this file and the right leg's gait cycle share 0.599-1.600 s); no later cycle of the "
         "leg (1.829-3.050 s) lies inside every input file either; give a --window inside every input file, or give "
         "the ground forces (--external-loads) instead of --id: the inverse dynamics is then computed over the whole "
         "trial"),
    ]
    # ExternalLoads naming a body the model lacks, or a data file that does not exist; forces that
    # hold no complete gait cycle of the leg (cut at 1.5 s: one right heel strike, 0.618 s)
    text = gait2392.external_loads.read_text()
    (tmp_path / "body.xml").write_text(text.replace("<applied_to_body> calcn_l </applied_to_body>",
                                                    "<applied_to_body> foot_left </applied_to_body>"))
    (tmp_path / gait2392.grf.name).write_bytes(gait2392.grf.read_bytes())
    (tmp_path / "missing.xml").write_text(text.replace("subject01_walk1_grf.mot", "nowhere.mot"))
    lines = gait2392.grf.read_text().splitlines()
    end = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader")
    rows = [r for r in lines[end + 2:] if r.strip() and float(r.split()[0]) <= 1.5]
    head = [f"nRows={len(rows)}" if h.startswith("nRows=") else h for h in lines[: end + 2]]
    (tmp_path / "short.mot").write_text("\n".join(head + rows) + "\n")
    (tmp_path / "short.xml").write_text(text.replace("subject01_walk1_grf.mot", "short.mot"))
    cases += [
        (["--external-loads", tmp_path / "body.xml", "--cycle", "auto"], "'foot_left' is not a body"),
        (["--external-loads", tmp_path / "missing.xml", "--cycle", "auto"], "nowhere.mot does not exist"),
        (["--external-loads", tmp_path / "short.xml", "--cycle", "auto"], "gives 0 complete gait cycles"),
    ]
    for extra, message in cases:
        code = _cli("solve", "--model", gait2392.model, "--ik", gait2392.ik, *extra, "--out", out)
        err = capsys.readouterr().err.strip()
        assert code != 0 and message in err and "\n" not in err, (extra, err)
        assert not out.exists()


def test_a_missing_coordinate_is_the_one_line_before_any_event_check(gait2392, tmp_path, capsys):
    """An IK file without the right knee's column: the error names the column, and nothing else
    is said first (the gait events of ``--cycle`` come from the kinematics too, where the missing
    knee made the heel strikes 87-172 ms from the forces' and warned of the foot and time axes)."""
    lines = gait2392.ik.read_text().splitlines()
    end = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader")
    drop = lines[end + 1].split("\t").index("knee_angle_r")
    rows = ["\t".join(c for j, c in enumerate(r.split("\t")) if j != drop) for r in lines[end + 1:]]
    (tmp_path / "ik.mot").write_text("\n".join(lines[: end + 1] + rows) + "\n")
    code = _cli("solve", "--model", gait2392.model, "--ik", tmp_path / "ik.mot", "--external-loads",
                gait2392.external_loads, "--cycle", "auto", "--out", tmp_path / "out")
    err = capsys.readouterr().err
    assert code == 1 and err.startswith(f"musclemetab: error: {tmp_path / 'ik.mot'}: missing DOF column knee_angle_r")
    assert err.count("\n") == 1 and not (tmp_path / "out").exists()


@pytest.fixture(scope="session")
def both_solutions(gait2392, tmp_path_factory):
    """EFFORT-GEN on each leg's gait cycle, inverse dynamics computed by OpenSim (one solve per leg),
    every muscle kept (the fiber-length bound of tfl, rect_fem and semimem is widened). The contact
    threshold is given as the study file's default (20 N, also the command's), so that the
    two-subject study (conftest) makes the same solve calls (solved once per run: solve_memo)."""
    out = tmp_path_factory.mktemp("g2392") / "both"
    code = _cli("solve", "--model", gait2392.model, "--ik", gait2392.ik, "--external-loads",
                gait2392.external_loads, "--cycle", "auto", "--side", "both", "--grf-threshold", "20", "--out", out)
    assert code == 0
    return out


@pytest.fixture(scope="session")
def left_solution(both_solutions):
    return both_solutions / "l"


@pytest.mark.slow
def test_fiber_length_bound_widened_from_the_geometry(both_solutions, gait2392):
    """The right tensor fasciae latae, kept: its fiber needs more than the default 1.7 optimal lengths.

    Oracle: the rigid-tendon fiber length worked by hand from OpenSim's muscle-tendon lengths
    (the geometry of the IK frames in the solved window) and the model's parameters:
    ``sqrt((max lMT - lTs)^2 + (lMo sin alpha0)^2) / lMo + 0.05``. Tolerance 5e-3: the solver
    takes the maximum over the filtered, spline-interpolated mesh nodes, not the raw frames.
    """
    from musclemetab.geometry import compute_geometry
    from musclemetab.model import read_muscle_parameters
    from musclemetab.redundancy import Solution

    sol = Solution.load(both_solutions / "r")
    bounds = sol.summary["fiber_length_bounds"]
    assert bounds["default"] == [0.1, 1.7]
    widened = bounds["widened_upper"]
    assert set(widened) == {"tfl_r", "rect_fem_r", "semimem_r"}
    geo = compute_geometry(gait2392.model, gait2392.ik, side="r", dofs=sol.summary["dofs"])
    a, b = sol.summary["time_window_s"]
    t = np.asarray(geo.time)
    frames = (t > a - 1e-6) & (t < b + 1e-6)
    p = read_muscle_parameters(gait2392.model)
    for m, bound in widened.items():
        k = list(p.names).index(m)
        lmo, lts = p.optimal_fiber_length_m[k], p.tendon_slack_length_m[k]
        w = lmo * np.sin(p.pennation_angle_at_optimal_rad[k])
        lmt = np.max(np.asarray(geo.lmt_m)[frames, list(geo.muscles).index(m)])
        assert bound == pytest.approx(np.sqrt((lmt - lts) ** 2 + w**2) / lmo + 0.05, abs=5e-3), m
    # the widening is used: tfl_r's fiber goes beyond 1.7 (its passive force balances the stretched
    # tendon near 1.71) and stays inside its bound; every other fiber within the default bound
    i = sol.muscles.index("tfl_r")
    assert 1.7 < sol.lm_norm[:, i].max() < widened["tfl_r"]
    others = [j for j, m in enumerate(sol.muscles) if m not in widened]
    assert sol.lm_norm[:, others].max() <= 1.7 + 1e-6


@pytest.mark.slow
def test_both_legs_effort_gen(both_solutions):
    cycles = {"r": (0.618, 1.853), "l": (1.247, 2.460)}  # README
    for side in "rl":
        folder = both_solutions / side
        s = json.loads((folder / "summary.json").read_text())
        assert s["success"] and s["max_moment_residual_Nm"] <= 1e-4
        assert s["side"] == side and s["dofs"] == [f"{d}_{side}" for d in (
            "mtp_angle", "subtalar_angle", "ankle_angle", "knee_angle", "hip_flexion", "hip_adduction", "hip_rotation")]
        assert len(s["muscles"]) == 43 and "excluded_muscles" not in s
        c = s["window"]["gait_cycle"]
        assert (c["start_s"], c["end_s"]) == pytest.approx(cycles[side], abs=3e-3)
        # 60 Hz frames, 100 mesh intervals per second
        a, b = s["time_window_s"]
        assert s["n_intervals"] == round((b - a) * 100)
        assert s["inverse_dynamics"]["coordinate_lowpass_hz"] == 6.0
        assert (folder / "inverse_dynamics.sto").is_file()
    left = json.loads((both_solutions / "l" / "summary.json").read_text())
    # the ground forces end 40 ms after the left heel strike: padding clipped there, and recorded
    assert left["time_window_s"][1] == pytest.approx(2.5, abs=1e-6) and "clipped" in left["window"]["warnings"][0]
    right = json.loads((both_solutions / "r" / "summary.json").read_text())
    assert right["window"]["warnings"] == [] and right["window"]["padding_s"][0] >= 0.05


@pytest.mark.slow
def test_plausibility_flags_of_the_two_subject_study(two_subjects, both_solutions, gait2392, tmp_path, capsys):
    """The over-stretched and saturated muscles of gait2392 flagged by name: in each leg's
    summary.json (worked again here from solution.sto and the recorded F0), in the study's
    results.csv (quality) and report (at the top), and by metabolics on the command line (one
    warning line per flag; --strict: exit status 1); a strict study fails both units. The example
    subject's normal trial in the same study raises no flag.

    The two-subject study (conftest) and ``both_solutions`` make the same solve calls (solved once
    per run: solve_memo). Oracles: passive force over F0 and the share of nodes at activation >=
    0.95 over the recorded gait cycle from the stored arrays; the tfl and rect_fem of both legs carry 1.7-2.2 F0 passively and the
    hamstrings sit at full activation for 12-23 % of the cycle (docs/quality.md).
    """
    import re

    import pandas as pd

    from musclemetab.redundancy import Solution
    from musclemetab.study import run_study, study_from_dict
    from musclemetab.study.spec import strict_study

    expected = {}
    for side in "rl":
        sol = Solution.load(both_solutions / side)
        flags = {f.code: f for f in sol.record.flags}
        share = sol.passive_fiber_force_N.max(axis=0) / sol.parameters.max_isometric_force_N
        over = {m for m, v in zip(sol.muscles, share) if v > 0.5}
        assert set(flags["passive_force"].items) == over and {f"tfl_{side}", f"rect_fem_{side}"} <= over
        assert flags["passive_force"].items[f"rect_fem_{side}"] == pytest.approx(
            share[sol.muscles.index(f"rect_fem_{side}")], rel=1e-9)
        assert min(share[sol.muscles.index(f"{m}_{side}")] for m in ("tfl", "rect_fem")) > 1.7
        cycle = sol.record.gait_cycle  # the share of the gait cycle, its padding left out
        inside = (sol.time_s >= cycle["start_s"] - 1e-9) & (sol.time_s <= cycle["end_s"] + 1e-9)
        saturated = {m for m, v in zip(sol.muscles, (sol.activation[inside] >= 0.95).mean(axis=0)) if v > 0.1}
        assert set(flags["saturated_activation"].items) == saturated and f"semimem_{side}" in saturated
        expected[side] = over, saturated
    # the study: gait2392's row names them all (both legs), the example's is ok
    out, _ = two_subjects
    results = pd.read_csv(out / "results.csv")
    assert (results.loc[results.subject == "example", "quality"] == "ok").all()
    for quality in results.loc[results.subject == "gait2392", "quality"]:
        entries = dict(e[:-1].split("(") for e in quality.split("; "))
        assert set(entries["passive_force"].split()) == expected["r"][0] | expected["l"][0]
        assert set(entries["saturated_activation"].split()) == expected["r"][1] | expected["l"][1]
    # the report: at the top, before the figures, one row per flag of each leg, the passive force first
    page = (out / "report.html").read_text(encoding="utf-8")
    top = page[page.index('id="attention"'):page.index('id="figures"')]
    rows = re.findall(r"<tr><td>gait2392</td><td>walk1</td><td>effort-gen</td><td>(\w+)</td><td>([^<]*)</td></tr>",
                      top.replace('<th scope="row">', "<td>").replace("</th>", "</td>"))
    assert [c for c, _ in rows][:1] == ["passive_force"] and "example" not in top
    passive = [text for c, text in rows if c == "passive_force"]
    assert len(passive) == 2 and all(f"rect_fem_{s}" in t and f"tfl_{s}" in t for t, s in zip(passive, "rl"))
    saturated = " ".join(text for c, text in rows if c == "saturated_activation")
    assert all(m in saturated for m in expected["r"][1] | expected["l"][1])
    # the command line: one warning line per flag of each leg, then the strict failure (the same solves)
    code = _cli("solve", "--model", gait2392.model, "--ik", gait2392.ik, "--external-loads", gait2392.external_loads,
                "--cycle", "auto", "--side", "both", "--grf-threshold", "20", "--strict", "--out", tmp_path / "solve")
    err = capsys.readouterr().err.splitlines()
    n_flags = sum(len(Solution.load(both_solutions / s).record.flags) for s in "rl")
    assert code == 1 and len([e for e in err if e.startswith(f"musclemetab: warning: {tmp_path / 'solve'}")]) == n_flags
    assert err[-1].startswith("musclemetab: error: solve --strict: implausible result refused (strict): passive_force(")
    assert all((tmp_path / "solve" / s / "summary.json").is_file() for s in "rl")  # written, for inspection
    code = _cli("metabolics", "--solution", both_solutions, "--mass", gait2392.body_mass_kg, "--height",
                GAIT2392_HEIGHT_M, "--models", "UM10", "--strict", "--muscle-properties", _placed(tmp_path),
                "--out", tmp_path / "met")
    err = capsys.readouterr().err.splitlines()
    lines = [e for e in err if e.startswith("musclemetab: warning:") and "passive fiber force" in e]
    assert len(lines) == 2 and all(f"rect_fem_{s}" in e for e, s in zip(lines, "rl"))
    assert code == 1 and err[-1].startswith("musclemetab: error: metabolics --strict: implausible result")
    assert json.loads((tmp_path / "met" / "plausibility.json").read_text())[0]["code"] == "passive_force"
    # a strict study of the subject: both units fail after the (same) solves, the flags their reason
    study = study_from_dict({
        "name": "gait2392", "workflows": ["effort-gen"], "models": ["UM10"], "strict": True,
        "subjects": [{"name": "subject01", "model": str(gait2392.model), "body_mass_kg": gait2392.body_mass_kg,
                      "height_m": GAIT2392_HEIGHT_M, "side": "both",
                      "trials": [{"name": "walk1", "ik": str(gait2392.ik), "external_loads": str(gait2392.external_loads),
                                  "cycle": "auto"}]}]}, base="/", output=tmp_path / "strict")
    assert study.strict and strict_study(study) == study
    run = run_study(study, workers=1, progress=False)
    fails = pd.read_csv(tmp_path / "strict" / "failures.csv")
    assert len(run.failed) == 2 and len(fails) == 2 and len(pd.read_csv(tmp_path / "strict" / "results.csv")) == 0
    assert all("ImplausibleResultError" in r and "passive_force(" in r and "rect_fem_" in r for r in fails["reason"])


def _placed(folder):
    """A muscle-properties file placing gait2392's muscles that the anatomical table does not
    (so that --strict refuses for the flags alone): 0.1 kg and slow-twitch fraction 0.5 each (these
    four small muscles' values do not change which flags the solves raise)."""
    path = folder / "placed.csv"
    rows = [f"{m}_{s},0.1,0.5" for m in ("pect", "quad_fem", "gem", "per_tert") for s in "rl"]
    path.write_text("muscle,mass_kg,slow_twitch_fraction\n" + "\n".join(rows) + "\n")
    return path


#: Body height is not recorded with gait2392's subject01; the volume regression needs one. The
#: generic gait2392 model represents a subject about 1.8 m tall (OpenSim's model documentation);
#: the package never guesses a height, the user gives it (--height, height_m).
GAIT2392_HEIGHT_M = 1.8
#: Plausible whole-body rates (W/kg) of the models for walking: the lowest and highest mean of the
#: study's Table 2 (all models and workflows, 4.1 to 12.2 W/kg), less and plus three SD (0.5, 1.2).
PLAUSIBLE_W_PER_KG = (4.1 - 3 * 0.5, 12.2 + 3 * 1.2)


@pytest.mark.slow
def test_metabolics_phases_and_groups_of_both_legs(both_solutions, gait2392):
    from musclemetab.events import GaitCycle
    from musclemetab.analysis.unit import analyse_solution_folder
    from musclemetab.geometry import compute_geometry
    from musclemetab.analysis.groups import has_function_group  # subtalar and mtp: no function group
    from musclemetab.metabolics import MODELS
    from musclemetab.metabolics.solution import add_legs, metabolics_from_solution

    legs = {}
    for side in "rl":
        folder = both_solutions / side
        s = json.loads((folder / "summary.json").read_text())
        c = s["window"]["gait_cycle"]
        with pytest.warns(UserWarning, match="not in the anatomical muscle table"):
            res = metabolics_from_solution(folder, gait2392.body_mass_kg, GAIT2392_HEIGHT_M, models="all", legs=1)
        assert res.models == tuple(MODELS)
        # trimmed to the recorded cycle, not to the study's 5 + 6 padding nodes
        assert c["start_s"] <= res.time_s[0] < c["start_s"] + 0.01
        assert c["end_s"] - 0.01 < res.time_s[-1] <= c["end_s"]
        legs[side] = res
        geo = compute_geometry(gait2392.model, gait2392.ik, dofs=[d for d in s["dofs"] if has_function_group(d)])
        with pytest.warns(UserWarning, match="not in the anatomical muscle table"):
            a = analyse_solution_folder(folder, geo, GaitCycle(c["start_s"], c["toe_off_s"], c["end_s"]),
                                        gait2392.body_mass_kg, GAIT2392_HEIGHT_M).summary.set_index("model")
        stance, swing = a["stance_energy_share_pct"], a["swing_energy_share_pct"]
        np.testing.assert_allclose(stance + swing, 100.0, atol=1e-9)
        # EFFORT-GEN swing share of the study: 36.5 % (BH04), 36.7 % (HO06); a quarter to a half here
        assert ((swing > 25) & (swing < 50)).all(), side
        shares = a[[col for col in a.columns if col.startswith("share_")]]
        np.testing.assert_allclose(shares.sum(axis=1), 100.0, atol=1e-6)
        assert (shares.drop(columns="share_other_pct") > 0).all().all()
    total = add_legs(legs)
    lo, hi = PLAUSIBLE_W_PER_KG
    for m in MODELS:
        # whole body = both legs' muscles + 1.2 W/kg basal, in the plausible range
        assert lo < total[m] < hi, (m, total[m])
        assert total[m] == pytest.approx(sum(legs[x].whole_body[m].one_leg_mean_W for x in "rl")
                                         / gait2392.body_mass_kg + 1.2, rel=1e-12)


def test_geometry_of_both_legs_against_opensims_moment_arm_solver(gait2392, tmp_path, capsys):
    from musclemetab.geometry import compute_geometry
    from musclemetab.io import read_storage

    assert _cli("geometry", "--model", gait2392.model, "--ik", gait2392.ik, "--side", "both", "--out", tmp_path / "g") == 0
    assert "side l, 43 muscles x 7 DOFs x 211 frames" in capsys.readouterr().out
    # OpenSim's own moment-arm solver (Muscle.computeMomentArm) on a few frames and muscles of each leg
    ik = read_storage(gait2392.ik)
    short = tmp_path / "short.mot"
    lines = gait2392.ik.read_text().splitlines()
    end = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader")
    rows = lines[end + 2 :: 3][:10]  # 20 Hz, 0.50-0.95 s
    head = [f"nRows={len(rows)}" if line.startswith("nRows=") else line for line in lines[: end + 2]]
    short.write_text("\n".join(head + rows) + "\n")
    frames = np.isin(np.round(ik.index.to_numpy(), 6), np.round(read_storage(short).index.to_numpy(), 6))
    for side in "rl":
        muscles = [f"{m}_{side}" for m in ("med_gas", "soleus", "rect_fem", "glut_med1", "semimem")]
        ref = compute_geometry(gait2392.model, short, side=side, muscles=muscles, method="opensim", use_cache=False)
        for j, dof in enumerate(ref.dofs):
            ours = read_storage(tmp_path / "g" / side / f"moment_arms_{dof}.sto")[muscles].to_numpy()[frames]
            np.testing.assert_allclose(ours, ref.moment_arms_m[:, j, :], atol=2e-3, err_msg=dof)
        lmt = read_storage(tmp_path / "g" / side / "muscle_tendon_lengths.sto")[muscles].to_numpy()[frames]
        np.testing.assert_allclose(lmt, ref.lmt_m, atol=1e-9)


@pytest.mark.slow
def test_both_legs_in_two_processes_give_the_same_solutions(gait2392, tmp_path, capsys, monkeypatch):
    """``--workers 2`` solves the legs in a pool of processes: the same solutions as one after the
    other, bit for bit (a short window, 0.3 s, both feet on the ground part of it). The pool's
    processes solve for themselves: the test run's memo of solves is kept from them."""
    import solve_memo

    from musclemetab.redundancy import Solution

    base = ["solve", "--model", gait2392.model, "--ik", gait2392.ik, "--external-loads", gait2392.external_loads,
            "--side", "both"]
    assert _cli(*base, "--window", "1.2:1.5", "--workers", 1, "--out", tmp_path / "w1") == 0
    with monkeypatch.context() as mp:
        mp.delenv(solve_memo.MEMO_ENV)  # the pool's initialiser installs the memo only when this names it
        assert _cli(*base, "--window", "1.2:1.5", "--workers", 2, "--out", tmp_path / "w2") == 0
    out = capsys.readouterr().out
    assert out.count("Solve_Succeeded") == 4
    for side in "rl":
        a, b = Solution.load(tmp_path / "w1" / side), Solution.load(tmp_path / "w2" / side)
        assert a.summary["side"] == b.summary["side"] == side
        assert a.summary["solve_time_s"] != b.summary["solve_time_s"]  # solved again, not the memo's copy
        for k in ("excitation", "activation", "lm_norm", "fiber_velocity_lmo_per_s", "reserve_Nm", "tendon_force_N"):
            np.testing.assert_array_equal(getattr(a, k), getattr(b, k), err_msg=f"{side} {k}")
    # an error in a worker process: one line, nothing written (0.8-1.1 s: the left leg swings, its
    # moments are below 0.2 N m/kg)
    assert _cli(*base, "--window", "0.8:1.1", "--workers", 2, "--out", tmp_path / "bad") != 0
    err = capsys.readouterr().err.strip().splitlines()
    errors = [line for line in err if line.startswith("musclemetab: error:")]
    assert len(errors) == 1 and "N m per kg" in errors[0] and not (tmp_path / "bad").exists()
    assert _cli(*base, "--window", "1.2:1.5", "--workers", 0, "--out", tmp_path / "zero") != 0
    assert "--workers = 0 is not a number of worker processes: it must be from 1 to 1024" in capsys.readouterr().err


def _trials_for_gait2392(example, folder, side):
    """The study's in-vivo passive trials in gait2392's conventions: knee flexion negative (angle and
    target moment negated), coordinates of ``side``; file names unrelated to the coordinates."""
    from musclemetab.io import read_storage, write_storage

    folder.mkdir(parents=True, exist_ok=True)
    for joint, files in example.calibration_trials.items():
        for kind, path in files.items():
            df = read_storage(path)
            for c in ("knee_angle_r", "knee_angle_r_moment"):
                if c in df.columns:
                    df[c] = -df[c]
            df = df.rename(columns={c: c.replace("_r", f"_{side}", 1) for c in df.columns})
            write_storage(folder / f"sweep_{joint}{path.suffix}", df, in_degrees=True if kind == "motion" else None)
    return folder


def test_passive_calibration_refuses_trials_in_another_sign_convention(example, gait2392, tmp_path, capsys):
    # the study's trials flex the knee positively (Rajagopal); gait2392's knee flexion is negative
    out = tmp_path / "cal"
    folder = example.calibration_trials["ankle"]["motion"].parent
    assert _cli("calibrate-passive", "--model", gait2392.model, "--trials", folder, "--out", out) != 0
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "knee_angle_r spans 0 to 60 deg, outside the range of knee_angle_r" in err
    assert "(-120 to 10 deg)" in err and "negate the knee_angle_r column" in err and not out.exists()


@pytest.mark.slow
def test_passive_calibration_of_the_left_leg(example, gait2392, tmp_path):
    """``calibrate-passive --side l`` on gait2392 with the study's trials in its conventions.

    Oracles: the root-finding equilibrium of single muscles (independent of the NLP), the
    coupling groups of the anatomical table, and the least-squares property (the calibrated
    parameters fit at least as well as the generic ones they start from).
    """
    from musclemetab.calibration import calibrate_passive, equilibrium_fiber_length

    res = calibrate_passive(gait2392.model, _trials_for_gait2392(example, tmp_path / "trials", "l"), side="l")
    d, cal, gen = res.data, res.calibrated, res.generic
    assert [t.dof for t in d.trials] == ["ankle_angle_l", "knee_angle_l", "hip_flexion_l"]
    assert len(d.muscles) == 43 and all(m.endswith("_l") for m in d.muscles)
    assert cal.stats["success"] and gen.stats["success"]

    def sse(sol):
        return sum(float(np.sum((sol.moments_Nm[t.joint] - t.target_Nm) ** 2)) for t in d.trials)

    assert sse(cal) < 0.2 * sse(gen)
    # coupling groups from the anatomical table: the three parts of gluteus medius share (kPE, s0)
    assert cal.parameters["glut_med1_l"] == cal.parameters["glut_med2_l"] == cal.parameters["glut_med3_l"]
    assert cal.parameters["vas_lat_l"] == cal.parameters["vas_int_l"]
    # rect_fem_l and tfl_l: with a rigid tendon the knee trial would stretch their fibers beyond 2
    # optimal lengths (their bound is widened); their equilibria, as the vasti's, match root finding
    knee = next(t for t in d.trials if t.joint == "knee")
    for m in ("rect_fem_l", "tfl_l", "vas_lat_l"):
        j, i = knee.muscles.index(m), d.muscles.index(m)
        k = int(np.argmax(cal.lm_norm["knee"][:, j]))
        kpe, s0, sm = cal.parameters[m]
        lm, _ = equilibrium_fiber_length(
            knee.lmt_m[k, j], optimal_fiber_length_m=d.optimal_fiber_length_m[i],
            tendon_slack_length_m=d.tendon_slack_length_m[i],
            pennation_angle_at_optimal_rad=d.pennation_angle_at_optimal_rad[i], kpe=kpe, s0=s0, sm=sm,
            kT=d.tendon_stiffness[i])
        assert cal.lm_norm["knee"][k, j] == pytest.approx(lm, abs=1e-5), m


def test_time_stamps_rounded_to_the_millisecond_read_as_the_constant_rate(gait2392, tmp_path):
    """OpenSim's tools round time to the millisecond: the 60 Hz IK then steps by 16 and 17 ms,
    and the ID's stamps too. Such files give the inputs of the files with exact stamps, and a
    truly uneven file (a frame dropped) is still refused."""
    import pandas as pd

    from musclemetab.geometry import compute_geometry
    from musclemetab.io import read_storage, read_table, write_storage
    from musclemetab.redundancy.inputs import GeometryArrays, read_inverse_dynamics, read_kinematics, trial_inputs

    dofs = ["knee_angle_r", "hip_flexion_r"]

    def rounded(path, name):
        df = read_storage(path)
        df.index = pd.Index(np.round(df.index.to_numpy(), 3), name="time")
        return write_storage(tmp_path / name, df, in_degrees=df.attrs["in_degrees"])

    ik_rounded, id_rounded = rounded(gait2392.ik, "ik_ms.mot"), rounded(gait2392.id, "id_ms.sto")
    lines = ik_rounded.read_text().splitlines()
    written = [float(line.split()[0]) for line in lines[lines.index("endheader") + 2:] if line.strip()]
    assert set(np.round(np.diff(written), 6)) == {0.016, 0.017}
    inputs = []
    for ik_path, id_path in ((gait2392.ik, gait2392.id), (ik_rounded, id_rounded)):
        ik = read_table(ik_path)
        t_ik, _ = read_kinematics(ik, dofs)
        t_id, moments = read_inverse_dynamics(read_table(id_path), dofs)
        g = compute_geometry(gait2392.model, ik, dofs=dofs, muscles=["semiten_r", "vas_int_r", "rect_fem_r"],
                             cache_dir=tmp_path)
        keep = (t_ik > 0.708) & (t_ik < 1.308)  # between frames
        window = GeometryArrays(t_ik[keep], g.muscles, g.dofs, g.lmt_m[keep], g.moment_arms_m[keep])
        inputs.append(trial_inputs(window, t_id, moments, ik_time_s=t_ik[keep]))
    exact, from_rounded = inputs
    # the rate fitted to the rounded stamps: within 4 microseconds of the exact stamps
    np.testing.assert_allclose(from_rounded.frame_time_s, exact.frame_time_s, rtol=0, atol=4e-6)
    np.testing.assert_allclose(from_rounded.mesh_time_s, exact.mesh_time_s, rtol=0, atol=4e-6)
    np.testing.assert_allclose(from_rounded.lmt_frames_m, exact.lmt_frames_m, rtol=0, atol=1e-6)  # m, filtered
    np.testing.assert_allclose(from_rounded.lmt_m, exact.lmt_m, rtol=0, atol=1e-6)  # m
    np.testing.assert_allclose(from_rounded.moment_arms_m, exact.moment_arms_m, rtol=0, atol=1e-6)
    np.testing.assert_allclose(from_rounded.moments_Nm, exact.moments_Nm, rtol=0, atol=0.05)  # of up to 100 N m
    # one frame dropped: no rounding explains it
    df = read_storage(gait2392.ik)
    df = df[df.index < 1.5].drop(index=df.index[40])
    dropped = read_table(write_storage(tmp_path / "dropped.mot", df, in_degrees=True))
    with pytest.raises(DataMismatchError, match=r"dropped\.mot: the time stamps are not evenly spaced"):
        trial_inputs(GeometryArrays(dropped.index, ["m"], ["knee_angle_r"], np.ones((len(dropped), 1)),
                                    np.ones((len(dropped), 1, 1))),
                     *read_inverse_dynamics(gait2392.id, ["knee_angle_r"]), ik_time_s=dropped.index,
                     sources={"ik": dropped.attrs["path"]})


@pytest.mark.parametrize("side, column, window", [("r", "ground_force_vy", (0.5, 2.0)),
                                                  ("l", "1_ground_force_vy", (1.0, 2.4))])
def test_a_solve_with_external_loads_has_its_cycle_from_their_forces_in_analyse_and_a_study(gait2392, side,
                                                                                          column, window):
    """A solve over ``--window`` with ``--external-loads`` (no cycle recorded): ``analyse`` takes the
    gait cycle of the vertical force the ExternalLoads file applies to the leg's foot (calcn_r: the
    data file's ``ground_force_vy``, calcn_l: ``1_ground_force_vy``), the cycle holding the middle of
    the solved window, as the same times found from that column of the data file by
    ``cycle_from_grf`` (events at 20 N); a study trial with the same window and ``external_loads``
    takes the same cycle. The ankle moment (the rule without forces) places it elsewhere."""
    from types import SimpleNamespace

    from musclemetab.analysis.unit import RecordedTrial
    from musclemetab.commands.analyse import _cycle
    from musclemetab.events import cycle_from_grf, read_grf
    from musclemetab.study import study_from_dict
    from musclemetab.study.events import trial_cycle

    force = read_grf(gait2392.grf, column)
    want = cycle_from_grf(force.index.to_numpy(float), force.to_numpy(float), 20.0, at_time_s=sum(window) / 2)
    recorded = RecordedTrial(str(gait2392.model), str(gait2392.ik), str(gait2392.id), side, None, None, None,
                             window, "--window", str(gait2392.external_loads))
    args = SimpleNamespace(cycle=None, grf=None, id=None, model=None)
    got, source = _cycle(args, side, gait2392.ik, recorded)
    assert source == "ground reaction forces"
    assert (got.start_s, got.toe_off_s, got.end_s) == pytest.approx((want.start_s, want.toe_off_s, want.end_s),
                                                                     abs=1e-12)
    study = study_from_dict({"workflows": ["effort-gen"], "subjects": [{
        "name": "s", "model": str(gait2392.model), "body_mass_kg": 72.6, "side": side,
        "trials": [{"name": "w", "ik": str(gait2392.ik), "external_loads": str(gait2392.external_loads),
                    "window": list(window)}]}]}, base="/")
    trial = study.subjects[0].trials[0]
    mine = trial_cycle(trial, side, study.subjects[0].model, window_s=window)
    assert (mine.start_s, mine.toe_off_s, mine.end_s) == (got.start_s, got.toe_off_s, got.end_s)
    # without forces the cycle would be the window less 0.05 s at each end (toe-off from the ankle moment)
    assert abs(got.start_s - (window[0] + 0.05)) > 0.02 and abs(got.end_s - (window[1] - 0.05)) > 0.02
