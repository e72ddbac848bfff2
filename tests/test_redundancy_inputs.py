"""Input preparation, static optimisation, workflow parameters and bad input of the solver.

These tests need no optimal control solve. Where geometry is needed they use the study's
own OpenSim MuscleAnalysis of the normal trial (``reference_muscle_analysis``), so they run
without OpenSim.
"""

from __future__ import annotations

import dataclasses
import json
import types

import numpy as np
import pytest
from scipy.signal import butter, filtfilt

from musclemetab.errors import (
    DataMismatchError,
    InputFileError,
    MissingColumnError,
    OptionError,
    SolverError,
    UnknownMuscleError,
)
from musclemetab.io import read_storage, write_storage
from musclemetab.redundancy import inputs as I
from musclemetab.redundancy import workflows as W
from musclemetab.redundancy.record import SolveRecord

DOFS = I.DEFAULT_DOFS


@pytest.fixture(scope="module")
def ref_geometry(example):
    folder = example.reference_muscle_analysis
    L = read_storage(folder / "IK_sub1_normal_MuscleAnalysis_Length.sto")
    names = list(L.columns)
    r = np.stack([read_storage(folder / f"IK_sub1_normal_MuscleAnalysis_MomentArm_{d}.sto")[names].to_numpy()
                  for d in DOFS], axis=1)
    return types.SimpleNamespace(time=L.index.to_numpy(), muscles=names, dofs=DOFS, lmt_m=L.to_numpy(), moment_arms_m=r)


@pytest.fixture(scope="module")
def model_params(reference_table):
    from test_energy_goal import reference_model_parameters

    return reference_model_parameters(reference_table)


@pytest.fixture(scope="module")
def normal_inputs(example, ref_geometry, model_params):
    """The normal trial's IK frame times, prepared inputs and EFFORT-GEN parameters."""
    t_ik, _ = I.read_kinematics(example.ik["normal"])
    t_id, mom = I.read_inverse_dynamics(example.id["normal"])
    km, _ = I.select_muscles(ref_geometry.muscles, ref_geometry.moment_arms_m, DOFS)
    names = [ref_geometry.muscles[i] for i in km]
    geo = types.SimpleNamespace(time=ref_geometry.time, muscles=names, dofs=DOFS,
                                lmt_m=ref_geometry.lmt_m[:, km], moment_arms_m=ref_geometry.moment_arms_m[:, :, km])
    params, _ = W.workflow_parameters("effort-gen", model_params, names)
    inp = I.trial_inputs(geo, t_id, mom, ik_time_s=t_ik)
    return t_ik, inp, params


# --------------------------------------------------------------------------- preparation
def test_mesh_of_the_three_trials(example):
    for trial, n in (("slow", 158), ("normal", 118), ("fast", 99)):
        t, _ = I.read_kinematics(example.ik[trial])
        mesh = I.mesh_for_window(t[0], t[-1])
        assert mesh.size == n + 1 and mesh[0] == t[0] and mesh[-1] == pytest.approx(t[-1], abs=1e-12)
        np.testing.assert_allclose(np.diff(mesh), (t[-1] - t[0]) / n)


def test_filter_uses_matlab_padding():
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.normal(size=(120, 3)), axis=0)
    b, a = butter(6, 0.12)
    np.testing.assert_allclose(I.lowpass_filtfilt(x, 100.0), filtfilt(b, a, x, axis=0, padtype="odd", padlen=18))
    # SciPy's default padding (21) gives visibly different edges
    assert np.max(np.abs(I.lowpass_filtfilt(x, 100.0) - filtfilt(b, a, x, axis=0))) > 1e-4
    with pytest.raises(DataMismatchError, match="too short"):
        I.lowpass_filtfilt(x[:18], 100.0)
    with pytest.raises(DataMismatchError, match="sampled at 10 Hz.*above 12 Hz"):
        I.lowpass_filtfilt(x, 10.0, what="the IK file ik.mot")


def test_selection_keeps_the_40_right_leg_muscles(ref_geometry, reference_table):
    km, kd = I.select_muscles(ref_geometry.muscles, ref_geometry.moment_arms_m, DOFS)
    assert [ref_geometry.muscles[i] for i in km] == list(reference_table.index)
    assert list(kd) == [0, 1, 2, 3, 4]


def test_id_is_filtered_on_the_full_file_then_interpolated(example, ref_geometry):
    t_ik, _ = I.read_kinematics(example.ik["normal"])
    t_id, mom = I.read_inverse_dynamics(example.id["normal"])
    km, _ = I.select_muscles(ref_geometry.muscles, ref_geometry.moment_arms_m, DOFS)
    geo = types.SimpleNamespace(time=ref_geometry.time, muscles=[ref_geometry.muscles[i] for i in km], dofs=DOFS,
                                lmt_m=ref_geometry.lmt_m[:, km], moment_arms_m=ref_geometry.moment_arms_m[:, :, km])
    # an ID file longer than the IK window: filtered over its whole length
    t_long = np.concatenate([t_id[0] - 0.01 * np.arange(20, 0, -1), t_id])
    mom_long = np.vstack([np.repeat(mom[:1], 20, axis=0), mom])
    inp = I.trial_inputs(geo, t_long, mom_long, ik_time_s=t_ik)
    b, a = butter(6, 0.12)
    expected = filtfilt(b, a, mom_long, axis=0, padtype="odd", padlen=18)[20:]
    np.testing.assert_allclose(inp.moments_frames_Nm, expected, atol=1e-9)
    assert inp.n_intervals == 118 and inp.moments_Nm.shape == (119, 5)
    assert inp.moment_arms_m.shape == (119, 5, 40) and inp.lmt_m.shape == (119, 40)
    # mesh nodes coincide with the IK frames here: the spline reproduces the filtered samples
    np.testing.assert_allclose(inp.lmt_m, inp.lmt_frames_m, atol=1e-12)


# --------------------------------------------------------------------------- static optimisation
def test_static_optimisation_satisfies_its_kkt_conditions(normal_inputs):
    from musclemetab.redundancy.static_opt import initial_guess, rigid_tendon_forces, static_optimisation

    _, inp, params = normal_inputs
    so = static_optimisation(inp, params)
    f_act, f_pas, _ = rigid_tendon_forces(inp.lmt_frames_m, inp.lmt_velocity_frames_m_per_s, params)
    for k in range(inp.frame_time_s.size):  # every frame of the example's normal trial
        r = inp.moment_arms_frames_m[k]
        a = so.activation[k]
        # constraint: ID = r (a Fact + Fpas) + ar
        np.testing.assert_allclose(r @ (a * f_act[k] + f_pas[k]) + so.reserve_Nm[k], inp.moments_frames_Nm[k], atol=1e-8)
        # gradient of a^2 + 1000 |b - A a|^2: zero inside, >= 0 at a = 0, <= 0 at a = 1
        grad = 2 * a - 2000 * (r * f_act[k]).T @ so.reserve_Nm[k]
        scale = max(1.0, np.max(np.abs(grad)))
        inside = (a > 1e-9) & (a < 1 - 1e-9)
        assert np.all(np.abs(grad[inside]) < 1e-6 * scale)
        assert np.all(grad[a <= 1e-9] > -1e-6 * scale)
        assert np.all(grad[a >= 1 - 1e-9] < 1e-6 * scale)
    g = initial_guess(inp, params, so)
    n = inp.n_intervals
    assert g.activation.shape == (n + 1, 40) and g.excitation.shape == (n, 40) and g.reserve.shape == (n, 5)
    # the reserve guess is in N m (not divided by Topt), as in the study
    np.testing.assert_allclose(g.reserve, so.reserve_Nm[:n], atol=1e-9)
    # fiber guess from the inverted compliant tendon curve: back to the static tendon force
    lt = (inp.lmt_m - g.lm_projected_m) / params.tendon_slack_length_m
    ft = np.exp(35 * (lt - 0.995)) / 5 - 0.25
    np.testing.assert_allclose(np.abs(ft + 0.25), np.abs(so.tendon_force_norm + 0.25), rtol=1e-9)


# --------------------------------------------------------------------------- workflows
def test_workflow_presets_and_options(model_params):
    names = ["soleus_r", "gasmed_r", "vaslat_r", "tibant_r"]
    gen, rec = W.workflow_parameters("effort-gen", model_params, names)
    assert np.all(gen.passive_kpe == 4) and np.all(gen.tendon_stiffness == 35)
    # the example subject's estimates only when asked for by name
    ten, rec = W.workflow_parameters("EFFORT_TEN", model_params, names, tendon_stiffness="example")
    np.testing.assert_array_equal(ten.tendon_stiffness, [10.617977, 10.617977, 4.695786, 35])
    assert rec["tendon_stiffness_source"] == ["example"]
    assert rec["passive_source"].startswith("package:")
    assert ten.passive_s0[0] == pytest.approx(1.107804)
    ten2, rec2 = W.workflow_parameters("effort-ten", model_params, names, tendon_stiffness={"soleus": 12.0, "vaslat_r": 5})
    # gasmed_r keeps the literature default (155 N/mm for the Achilles tendon at 0.25 F0, shared
    # here by soleus_r and gasmed_r): k = kT (0.25 + 0.25 - shift(kT)) (F0_so/lTs_so + F0_gm/lTs_gm)
    kt = ten2.tendon_stiffness[1]
    i, j = (list(model_params.names).index(m) for m in ("soleus_r", "gasmed_r"))
    c = sum(model_params.max_isometric_force_N[k] / model_params.tendon_slack_length_m[k] for k in (i, j))
    shift = (np.exp(0.175) - np.exp(0.005 * kt)) / 5
    assert kt * (0.5 - shift) * c == pytest.approx(155e3, rel=1e-9)
    np.testing.assert_array_equal(ten2.tendon_stiffness[[0, 2, 3]], [12.0, 5.0, 35])
    assert rec2["tendon_stiffness_sources"]["gasmed_r"].startswith("literature (achilles tendon 155 N/mm")
    assert rec2["tendon_stiffness_source"] == ["literature", "option"]
    assert rec2["tendon_stiffness_sources"]["soleus_r"] == "option"
    with pytest.raises(OptionError, match="generic passive"):
        W.workflow_parameters("effort-gen", model_params, names, passive="x.csv")
    with pytest.raises(OptionError, match="effort-ten"):
        W.workflow_parameters("effort-cal", model_params, names, tendon_stiffness={"soleus_r": 10})
    with pytest.raises(UnknownMuscleError, match="soleos_r"):
        W.workflow_parameters("effort-ten", model_params, names, tendon_stiffness={"soleos_r": 10})
    with pytest.raises(OptionError, match="unknown workflow"):
        W.get_workflow("emg-ten")
    with pytest.raises(UnknownMuscleError, match="notamuscle_r"):
        W.workflow_parameters("effort-gen", model_params, names + ["notamuscle_r"])


def test_tendon_stiffness_parsing(tmp_path):
    assert W.parse_tendon_stiffness("soleus_r=10.6, gasmed_r=9") == {"soleus_r": 10.6, "gasmed_r": 9.0}
    for bad in ("soleus_r", "soleus_r=abc", "soleus_r=-1", "=3", ""):
        with pytest.raises(OptionError, match="tendon-stiffness"):
            W.parse_tendon_stiffness(bad)
    p = tmp_path / "parameters.json"
    p.write_text(json.dumps({"tendon_stiffness": {"soleus_r": 10.6}}))
    assert W.read_tendon_stiffness_json(p) == {"soleus_r": 10.6}
    p.write_text(json.dumps({"kT": {"soleus_r": 10.6}}))
    with pytest.raises(InputFileError, match="tendon_stiffness"):
        W.read_tendon_stiffness_json(p)
    p.write_text(json.dumps({"tendon_stiffness": {"soleus_r": "stiff"}}))
    with pytest.raises(InputFileError, match="soleus_r"):
        W.read_tendon_stiffness_json(p)
    p.write_text("{not json")
    with pytest.raises(InputFileError, match="JSON"):
        W.read_tendon_stiffness_json(p)
    with pytest.raises(InputFileError, match="no such"):
        W.read_tendon_stiffness_json(tmp_path / "missing.json")


def test_passive_parameter_files(example, tmp_path, model_params):
    mat = W.read_passive_parameters(example.passive_moments_mat)
    # passive_calibration.md §5.2
    assert mat.lookup("soleus_r") == pytest.approx((4.999928, 1.107804, 0.6), abs=1e-6)
    assert mat.lookup("glmed1_l") == pytest.approx((3.000055, 0.800021, 0.6), abs=1e-6)  # left copied from right
    csv = tmp_path / "passive_parameters.csv"
    csv.write_text("muscle,kPE,s0,sM\nsoleus_r,4.5,1.1,0.6\ngasmed,3.5,0.9,0.6\n")
    pp = W.read_passive_parameters(csv)
    assert pp.lookup("soleus_r") == (4.5, 1.1, 0.6) and pp.lookup("gasmed_r") == (3.5, 0.9, 0.6)
    with pytest.raises(UnknownMuscleError, match="vaslat_r"):
        W.workflow_parameters("effort-cal", model_params, ["soleus_r", "vaslat_r"], passive=csv)
    params, rec = W.workflow_parameters("effort-cal", model_params, ["soleus_r", "gasmed_r"], passive=csv)
    assert rec["passive_source"] == str(csv) and params.passive_kpe.tolist() == [4.5, 3.5]
    csv.write_text("muscle,k,s0\nsoleus_r,4.5,1.1\n")
    with pytest.raises(MissingColumnError, match="kPE"):
        W.read_passive_parameters(csv)
    csv.write_text("muscle,kPE,s0,sM\nsoleus_r,four,1.1,0.6\n")
    with pytest.raises(InputFileError, match="not a number"):
        W.read_passive_parameters(csv)
    with pytest.raises(InputFileError, match="format"):
        W.read_passive_parameters(example.ik["normal"])
    with pytest.raises(InputFileError, match="no such"):
        W.read_passive_parameters(tmp_path / "none.csv")


def test_calibration_output_is_accepted(tmp_path):
    from musclemetab.calibration.passive import write_passive_parameters

    path = write_passive_parameters(tmp_path / "passive_parameters.csv", {"soleus_r": (4.2, 1.05, 0.6)})
    assert W.read_passive_parameters(path).lookup("soleus_r") == pytest.approx((4.2, 1.05, 0.6))


# --------------------------------------------------------------------------- bad input
def _copy_with(src, dst, transform):
    df = read_storage(src)
    out = transform(df.copy())
    write_storage(dst, out, name=df.attrs.get("name"), in_degrees=df.attrs.get("in_degrees"))
    return dst


def test_ik_units_and_columns(example, tmp_path):
    text = example.ik["normal"].read_text()
    bad = tmp_path / "ik_nodeg.mot"
    bad.write_text(text.replace("inDegrees=yes", "inDegrees=no"))
    with pytest.raises(DataMismatchError, match="look like degrees"):
        I.read_kinematics(bad)
    rad = _copy_with(example.ik["normal"], tmp_path / "ik_rad.mot", lambda d: d.apply(np.deg2rad))
    with pytest.raises(DataMismatchError, match="look like radians"):
        I.read_kinematics(rad)
    nodof = _copy_with(example.ik["normal"], tmp_path / "ik_nodof.mot", lambda d: d.drop(columns=["knee_angle_r"]))
    with pytest.raises(MissingColumnError, match="knee_angle_r"):
        I.read_kinematics(nodof)


def test_id_columns_time_and_units(example, tmp_path, ref_geometry, model_params):
    nocol = _copy_with(example.id["normal"], tmp_path / "id.sto", lambda d: d.drop(columns=["hip_rotation_r_moment"]))
    with pytest.raises(MissingColumnError, match="hip_rotation_r_moment"):
        I.read_inverse_dynamics(nocol)
    t_ik, _ = I.read_kinematics(example.ik["normal"])
    t_id, mom = I.read_inverse_dynamics(example.id["normal"])
    km, _ = I.select_muscles(ref_geometry.muscles, ref_geometry.moment_arms_m, DOFS)
    geo = types.SimpleNamespace(time=ref_geometry.time, muscles=[ref_geometry.muscles[i] for i in km], dofs=DOFS,
                                lmt_m=ref_geometry.lmt_m[:, km], moment_arms_m=ref_geometry.moment_arms_m[:, :, km])
    with pytest.raises(DataMismatchError, match="do not overlap"):
        I.trial_inputs(geo, t_id + 10.0, mom, ik_time_s=t_ik)
    with pytest.raises(DataMismatchError, match="must cover the whole IK window"):
        I.trial_inputs(geo, t_id[:60], mom[:60], ik_time_s=t_ik)
    with pytest.raises(DataMismatchError, match="geometry has 119 frames"):
        I.trial_inputs(geo, t_id, mom, ik_time_s=t_ik[:-1])
    uneven = t_id.copy()
    uneven[50:] += 0.004
    with pytest.raises(DataMismatchError, match="not evenly spaced"):
        I.trial_inputs(geo, uneven, mom, ik_time_s=t_ik)
    inp = I.trial_inputs(geo, t_id, mom, ik_time_s=t_ik)
    f0 = np.asarray(model_params.max_isometric_force_N)
    I.check_moment_magnitudes(inp.moments_frames_Nm, DOFS, inp.moment_arms_frames_m, f0)
    with pytest.raises(DataMismatchError, match="N mm"):
        I.check_moment_magnitudes(1000 * inp.moments_frames_Nm, DOFS, inp.moment_arms_frames_m, f0)
    with pytest.raises(DataMismatchError, match="normalised"):
        I.check_moment_magnitudes(inp.moments_frames_Nm / 72.6 / 2, DOFS, inp.moment_arms_frames_m, f0)


def _cli(example, tmp_path, *extra, ik=None, id_=None):
    from musclemetab.commands import main

    return main(["solve", "--model", str(example.model), "--ik", str(ik or example.ik["normal"]),
                 "--id", str(id_ or example.id["normal"]), "--out", str(tmp_path / "out"), *extra])


def test_cli_rejects_bad_input_before_solving(example, tmp_path, capsys):
    """Each of these fails before the geometry and the solve, with a one-line message."""
    cases = [
        (("--workflow", "effort-gen", "--passive", str(example.passive_moments_mat)), {}, "generic passive"),
        (("--workflow", "effort-cal", "--tendon-stiffness", "soleus_r=10"), {}, "belong to effort-ten"),
        (("--workflow", "effort-ten", "--tendon-stiffness", "soleus_r:10"), {}, "muscle=kT"),
        (("--workflow", "effort-cal", "--passive", str(tmp_path / "missing.csv")), {}, "no such"),
        (("--workflow", "effort-ten", "--parameters", str(tmp_path / "missing.json")), {}, "no such"),
        ((), {"id_": example.id["slow"]}, "do not overlap|must cover|inside every input"),
        ((), {"id_": example.ik["normal"]}, "_moment"),
    ]
    bad_ik = tmp_path / "ik.mot"
    bad_ik.write_text(example.ik["normal"].read_text().replace("inDegrees=yes", "inDegrees=no"))
    cases.append(((), {"ik": bad_ik}, "look like degrees"))
    import re

    for extra, kw, pattern in cases:
        assert _cli(example, tmp_path, *extra, **kw) == 1, (extra, kw)
        err = capsys.readouterr().err
        assert err.startswith("musclemetab: error:") and re.search(pattern, err), err
        assert not (tmp_path / "out" / "summary.json").exists()


# --------------------------------------------------------------------------- solution object
def _toy_solution():
    from musclemetab.redundancy.parameters import MuscleTendonParameters
    from musclemetab.redundancy.solution import Solution

    t = np.linspace(0.0, 0.05, 6)
    M = 2
    p = MuscleTendonParameters(names=("a_r", "b_r"), max_isometric_force_N=[1000, 2000], optimal_fiber_length_m=[0.1, 0.05],
                               tendon_slack_length_m=[0.2, 0.3], pennation_angle_at_optimal_rad=[0.1, 0.2],
                               max_contraction_velocity=10, tendon_stiffness=[35, 10], passive_kpe=4, passive_s0=1,
                               passive_sm=0.6)
    x = np.linspace(0.1, 0.9, 12).reshape(6, M)
    return Solution(time_s=t, muscles=p.names, dofs=("ankle_angle_r",), excitation=x, activation=x * 0.9, lm_norm=x + 0.5,
                    fiber_velocity_lmo_per_s=x - 0.5, tendon_force_N=100 * x, active_fiber_force_N=50 * x, passive_fiber_force_N=5 * x,
                    active_force_length_multiplier=x, force_velocity_multiplier=x + 0.1, reserve_Nm=x[:, :1],
                    parameters=p, record=SolveRecord.from_dict({"status": "Solve_Succeeded", "success": True, "objective": 0.1}))


def test_solution_round_trip(tmp_path):
    from musclemetab.redundancy.solution import Solution

    sol = _toy_solution()
    sol.write(tmp_path / "s")
    back = Solution.load(tmp_path / "s")
    for f in ("excitation", "activation", "lm_norm", "fiber_velocity_lmo_per_s", "tendon_force_N", "reserve_Nm"):
        np.testing.assert_allclose(getattr(back, f), getattr(sol, f), rtol=1e-11)
    np.testing.assert_allclose(back.parameters.tendon_stiffness, [35, 10])
    assert back.muscles == ("a_r", "b_r") and back.objective == 0.1
    # the file holds v~M/vmax
    df = read_storage(tmp_path / "s" / "solution.sto")
    np.testing.assert_allclose(df["/forceset/a_r/normalized_fiber_velocity"], sol.fiber_velocity_lmo_per_s[:, 0] / 10)


def test_solution_record_entries_round_trip(tmp_path):
    """Every kind of entry of a record (typed, optional and absent, one of a newer file) is written
    and read back unchanged, in the file's order; a stage's added entry comes last, the rest kept."""
    from musclemetab.redundancy.solution import Solution

    entries = {"status": "Solve_Succeeded", "success": True, "objective": 0.1, "iterations": 12,
               "objective_terms": {"activation": 0.1}, "time_window_s": [0.0, 0.5], "n_intervals": 5,
               "workflow": {"name": "effort-gen", "passive_source": None}, "fiber_dynamics": "backward",
               "a_newer_entry": {"x": [1, 2]}, "reserve_share_of_peak_moment": 0.002, "large_reserve": False}
    sol = dataclasses.replace(_toy_solution(), record=SolveRecord.from_dict(entries))
    # typed and read-only: a record's lists are tuples, its mappings read-only, its entries records
    assert sol.record.extra == {"a_newer_entry": {"x": (1, 2)}} and sol.record.side is None
    assert sol.record.time_window_s == (0.0, 0.5) and sol.record.workflow.name == "effort-gen"
    with pytest.raises(TypeError):
        sol.record.objective_terms["activation"] = 0.0
    assert "side" not in sol.record and sol.record.get("side", "absent") == "absent"
    sol = dataclasses.replace(sol, record=sol.record.with_(side="l", n_intervals=5))
    assert list(sol.summary) == [*entries, "side"] and sol.record.side == "l"
    sol.write(tmp_path / "s")
    text = (tmp_path / "s" / "summary.json").read_text()
    back = Solution.load(tmp_path / "s")
    assert back.record == sol.file_record()
    assert list(back.summary) == [*entries, "side", "format", "format_version", "muscles", "dofs", "parameters",
                                  "conventions"]
    assert back.record.workflow == {"name": "effort-gen", "passive_source": None}
    assert back.record.muscles == ("a_r", "b_r") and back.record.parameters["b_r"]["kT"] == 10
    back.write(tmp_path / "again")
    assert (tmp_path / "again" / "summary.json").read_text() == text
    with pytest.raises(dataclasses.FrozenInstanceError):
        back.record.side = "r"


def test_solution_load_errors(tmp_path):
    from musclemetab.redundancy.solution import Solution

    with pytest.raises(InputFileError, match="not a solution folder"):
        Solution.load(tmp_path)
    sol = _toy_solution()
    sol = dataclasses.replace(sol, record=sol.record.with_(status="Infeasible_Problem_Detected", success=False))
    sol.write(tmp_path / "f")
    with pytest.raises(SolverError, match="Infeasible_Problem_Detected"):
        Solution.load(tmp_path / "f")
    (tmp_path / "f" / "summary.json").write_text("{")
    with pytest.raises(InputFileError, match="JSON"):
        Solution.load(tmp_path / "f")


def test_problem_size_formula():
    from musclemetab.redundancy.ipopt import problem_size

    assert [problem_size(40, 5, n) for n in (158, 118, 99)] == [(32510, 26110), (24310, 19510), (20415, 16375)]


def test_explicit_derivatives_equal_automatic_ones(example, ref_geometry, model_params):
    """The assembled Jacobian and Hessian given to IPOPT equal CasADi's AD of the whole NLP."""
    import casadi as ca

    from musclemetab.redundancy.ipopt import SolverOptions, build_nlp
    from musclemetab.redundancy.static_opt import initial_guess, static_optimisation

    t_ik, _ = I.read_kinematics(example.ik["normal"])
    t_id, mom = I.read_inverse_dynamics(example.id["normal"])
    km, _ = I.select_muscles(ref_geometry.muscles, ref_geometry.moment_arms_m, DOFS)
    names = [ref_geometry.muscles[i] for i in km]
    F = 31  # a short window keeps the automatic Hessian cheap
    geo = types.SimpleNamespace(time=ref_geometry.time[:F], muscles=names, dofs=DOFS,
                                lmt_m=ref_geometry.lmt_m[:F, km], moment_arms_m=ref_geometry.moment_arms_m[:F, :, km])
    params, _ = W.workflow_parameters("effort-ten", model_params, names)
    inp = I.trial_inputs(geo, t_id, mom, ik_time_s=t_ik[:F])
    guess = initial_guess(inp, params, static_optimisation(inp, params))
    nlp = build_nlp(inp, params, guess, SolverOptions())
    x, f, g = nlp["x"], nlp["f"], nlp["g"]
    rng = np.random.default_rng(1)
    x0 = np.clip(nlp["x0"] + 0.01 * rng.normal(size=x.shape[0]), nlp["lbx"] + 1e-3,
                 np.minimum(nlp["ubx"], 1e3) - 1e-3)
    lam = rng.normal(size=g.shape[0])
    sigma = 0.7
    p = nlp["p_values"]
    f_e, grad_e = nlp["grad_f"](x0, p)
    g_e, jac_e = nlp["jac_g"](x0, p)
    hess_e = nlp["hess_lag"](x0, p, sigma, lam)
    auto = ca.Function("auto", [x, nlp["p"]], [f, ca.gradient(f, x), g, ca.jacobian(g, x),
                                     ca.triu(ca.hessian(sigma * f + ca.dot(ca.DM(lam), g), x)[0])])
    f_a, grad_a, g_a, jac_a, hess_a = auto(x0, p)
    assert float(f_e) == pytest.approx(float(f_a), rel=1e-12)
    np.testing.assert_allclose(np.asarray(grad_e).ravel(), np.asarray(grad_a).ravel(), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.asarray(g_e).ravel(), np.asarray(g_a).ravel(), rtol=1e-12, atol=1e-12)
    scale_j = float(np.max(np.abs(np.asarray(jac_a.nonzeros()))))
    assert np.max(np.abs(np.asarray((jac_e - jac_a).nonzeros()))) <= 1e-12 * scale_j
    scale_h = float(np.max(np.abs(np.asarray(hess_a.nonzeros()))))
    assert np.max(np.abs(np.asarray((hess_e - hess_a).nonzeros()))) <= 1e-11 * scale_h


def test_tendon_stiffness_file_for_both_legs(model_params, tmp_path):
    p = tmp_path / "parameters.json"
    p.write_text(json.dumps({"tendon_stiffness": {"soleus_r": 9.0, "soleus_l": 8.0}}))
    params, rec = W.workflow_parameters("effort-ten", model_params, ["soleus_r", "gasmed_r"], tendon_stiffness_file=p,
                                        tendon_stiffness="example")
    assert params.tendon_stiffness.tolist() == [9.0, 10.617977]
    assert rec["tendon_stiffness_ignored"] == ["soleus_l"]
    assert rec["tendon_stiffness_sources"] == {"soleus_r": str(p),
                                               "gasmed_r": "example (example subject's EMG-TEN estimate, asked for)"}
    p.write_text(json.dumps({"tendon_stiffness": {"soleos_r": 9.0}}))
    with pytest.raises(UnknownMuscleError, match="soleos_r"):
        W.workflow_parameters("effort-ten", model_params, ["soleus_r"], tendon_stiffness_file=p)


def test_problem_record_round_trips_a_results_parameters_file(tmp_path):
    """The ``solve`` section of a result's ``parameters.json`` (EMG-TEN's format) is typed by
    :class:`ProblemRecord`: written by :meth:`Result.write` and read by :meth:`Result.load` entry for
    entry in the file's order, a newer file's entry kept; the result's outcome comes from it; a
    record that did not succeed is refused by ``load`` with IPOPT's status."""
    from musclemetab.errors import SolverError
    from musclemetab.redundancy import EmgTenSettings, Result
    from musclemetab.redundancy.record import ProblemRecord

    settings = EmgTenSettings()
    entries = {"workflow": "emg-ten", "status": "Solve_Succeeded", "success": True, "objective": 0.034,
               "iterations": 133, "trials": [{"label": "walk", "time_window_s": [0.0, 0.5], "n_intervals": 5,
                                              "inputs": {}}],
               "settings": settings.to_dict(), "doubts": {"on_bounds": [], "uninformed": []},
               "a_newer_entry": [1, 2]}
    record = ProblemRecord.from_dict(entries)
    assert record.extra == {"a_newer_entry": (1, 2)} and record.side is None and "side" not in record
    record = record.with_(side="r", geometry_time_s=1.5)
    assert list(record.to_dict()) == [*entries, "side", "geometry_time_s"] and record.side == "r"
    result = Result(solutions={"walk": _toy_solution()}, parameters=_toy_solution().parameters,
                    factors={"tendon_stiffness": {}, "emg_scale": {}}, record=record, settings=settings)
    assert (result.success, result.status, result.objective, result.iterations) == (True, "Solve_Succeeded", 0.034, 133)
    result.write(tmp_path / "r", opensim_files=False)
    back = Result.load(tmp_path / "r")
    assert back.record == record and back.labels == ("walk",) and back.settings.to_dict() == settings.to_dict()
    failed = record.with_(status="Maximum_Iterations_Exceeded", success=False)
    Result(solutions=result.solutions, parameters=result.parameters, factors=result.factors, record=failed,
           settings=settings).write(tmp_path / "f", opensim_files=False)
    with pytest.raises(SolverError, match="Maximum_Iterations_Exceeded"):
        Result.load(tmp_path / "f")
    assert Result.load(tmp_path / "f", require_success=False).record == failed
