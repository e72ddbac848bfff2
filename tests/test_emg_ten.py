"""EMG-TEN on the example subject: the slow, normal and fast trials in one problem.

The three-trial problem is solved once per session, through the command line
(``musclemetab solve --workflow emg-ten --emg-mapping authors``), and the checks read the
written files. What is verified is recomputed here from the method documents
(``muscle_model.md``, ``muscle_redundancy.md`` §5-§6) with formulas written in this file:

* the problem has the study's size (77 250 variables, 62 002 equalities, 3 375 EMG bounds);
* the triceps-surae and vasti tendon-stiffness factors agree with the study's estimates
  (§6.8; 10 % asserted, the reproduction is much closer) and their couplings hold;
* the EMG scale factors agree with §6.8 (2 %) and their couplings hold;
* joint moments, Hill equilibrium and activation dynamics hold at every constrained node;
* the EMG tracking band ``|e - s E| <= 0.01`` holds at every control node, with ``E``
  interpolated here from the EMG files;
* the objective recomputed from the files equals the reported one;
* EFFORT-TEN runs from the written ``parameters.json``;
* bad inputs raise package errors naming the file, channel or muscle.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from mrs_reference import (
    DOFS,
    check_solution_satisfies_problem,
    mesh_inputs,
    params_of,
    shift_ref,
)

TRIALS = ("slow", "normal", "fast")
N_MESH = {"slow": 158, "normal": 118, "fast": 99}
TRICEPS_SURAE = ("soleus_r", "gasmed_r", "gaslat_r")
VASTI = ("vasint_r", "vaslat_r", "vasmed_r")
# muscle_redundancy.md §6.8 (authors' mapping: vasint tracks the ES channel)
STUDY_KT_SCALE = {"triceps_surae": 0.303371, "vasti": 0.134165}
STUDY_KT = {"triceps_surae": 10.617977, "vasti": 4.695786}
STUDY_EMG_SCALE = {"bflh_r": 0.46443, "gaslat_r": 0.51219, "gasmed_r": 0.51219, "semiten_r": 0.41215,
                   "soleus_r": 2.32622, "tibant_r": 1.84726, "vasint_r": 0.39787, "vaslat_r": 0.39787,
                   "vasmed_r": 0.39787}
AUTHORS_CHANNELS = {"bflh_r": "BF", "semiten_r": "ST", "vaslat_r": "VL", "vasmed_r": "VM", "tibant_r": "TA",
                    "gaslat_r": "GL", "gasmed_r": "GM", "soleus_r": "SO", "vasint_r": "ES"}
W_EMG, W_ACT, W_RES, W_VM = 10.0, 0.1, 1000.0, 0.01


# --------------------------------------------------------------------------- the solve (once)
@pytest.fixture(scope="module")
def cache_dir(geometry_cache):
    return geometry_cache


@pytest.fixture(scope="module")
def geometries(example, cache_dir):
    from musclemetab.geometry import compute_geometry

    return {t: compute_geometry(example.model, example.ik[t], dofs=list(DOFS), cache_dir=cache_dir) for t in TRIALS}


@pytest.fixture(scope="module")
def emg_ten(example, geometries, cache_dir, tmp_path_factory):
    """The authors'-mapping EMG-TEN solve, through the command line, with the study's stop
    (``--stop authors``: its estimates are compared with the study's); returns (folder, stdout)."""
    from musclemetab.commands import main

    out = tmp_path_factory.mktemp("emg_ten") / "result"
    argv = ["solve", "--workflow", "emg-ten", "--model", str(example.model),
            "--ik", *[str(example.ik[t]) for t in TRIALS], "--id", *[str(example.id[t]) for t in TRIALS],
            "--emg", *[str(example.emg[t]) for t in TRIALS], "--emg-mapping", "authors",
            "--labels", *TRIALS, "--stop", "authors", "--cache-dir", str(cache_dir), "--out", str(out)]
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(argv)
    assert code == 0, buf.getvalue()
    return out, buf.getvalue()


@pytest.fixture(scope="module")
def parameters(emg_ten):
    return json.loads((emg_ten[0] / "parameters.json").read_text())


@pytest.fixture(scope="module")
def solutions(emg_ten):
    from musclemetab.redundancy import Solution

    return {t: Solution.load(emg_ten[0] / t) for t in TRIALS}


# --------------------------------------------------------------------------- results
@pytest.mark.opensim
@pytest.mark.slow
def test_each_trials_record_keeps_its_entries_and_their_order(emg_ten, builder_entries):
    """The entries of each trial's ``summary.json`` that the record builder writes are those the
    package wrote before one builder made the records of the three kinds of solve, in order."""
    for t in TRIALS:
        raw = json.loads((emg_ten[0] / t / "summary.json").read_text())
        assert builder_entries(raw) == builder_entries.before["emg-ten"], t


@pytest.mark.opensim
@pytest.mark.slow
def test_result_load_and_write_round_trip(emg_ten, parameters, solutions, tmp_path):
    """``Result.load`` reads what the solve wrote (estimates, settings, solutions), and writing
    the loaded result again gives the same files: the solutions byte for byte, ``parameters.json``
    the same document (the slopes at the peak tendon forces recomputed from the 12-digit
    forces of the files, to 1e-9)."""
    from dataclasses import replace

    from musclemetab.errors import InputFileError
    from musclemetab.redundancy import EmgTenSettings, Result
    from musclemetab.redundancy.emg_ten import EMG_TEN_GOALS

    out = emg_ten[0]
    result = Result.load(out)
    assert result.labels == TRIALS and result.success
    assert result.tendon_scale == parameters["tendon_stiffness_scale"]
    assert result.tendon_stiffness == pytest.approx(parameters["tendon_stiffness"], rel=1e-12)
    assert result.emg_scale == parameters["emg_scale"] and result.emg_channels == parameters["emg_channels"]
    assert result.settings.to_dict() == parameters["solve"]["settings"]
    assert result.settings == EmgTenSettings(goals=replace(EMG_TEN_GOALS, fiber_dynamics="forward"))
    for t in TRIALS:
        np.testing.assert_array_equal(result.solutions[t].tendon_force_N, solutions[t].tendon_force_N)
    again = result.write(tmp_path / "again")
    for t in TRIALS:
        for name in ("solution.sto", "summary.json"):
            assert (again / t / name).read_bytes() == (out / t / name).read_bytes(), (t, name)

    def same(a, b, where=""):
        if isinstance(a, dict):
            assert set(a) == set(b), where
            for k in a:
                same(a[k], b[k], f"{where}/{k}")
        elif isinstance(a, list):
            assert len(a) == len(b), where
            for i, (x, y) in enumerate(zip(a, b)):
                same(x, y, f"{where}/{i}")
        elif isinstance(a, float):
            assert a == pytest.approx(b, rel=1e-9, nan_ok=True), where
        else:
            assert a == b, where

    same(json.loads((again / "parameters.json").read_text()), parameters)
    # the solve record is typed (ProblemRecord) and gives back the file's section entry for entry
    from musclemetab.redundancy.record import ProblemRecord

    assert isinstance(result.record, ProblemRecord) and list(result.record.to_dict()) == list(parameters["solve"])
    assert result.record.iterations == parameters["solve"]["iterations"] == result.iterations
    assert [dict(t) for t in result.record.trials] == [{**t, "time_window_s": tuple(t["time_window_s"])}
                                                      for t in parameters["solve"]["trials"]]
    assert result.record.to_dict()["trials"] == parameters["solve"]["trials"] and not result.record.extra
    assert Result.load(again).record == result.record
    # printed: a summary of at most 20 lines; as a MATLAB file: each trial's arrays as its solution.sto holds them
    lines = str(result).splitlines()
    assert len(lines) <= 20 and "array(" not in str(result)
    assert lines[0] == f"Result (emg-ten): {len(TRIALS)} trials, {len(result.parameters.names)} muscles"
    assert any(line.startswith(f"  estimated tendon_stiffness ({len(parameters['tendon_stiffness_scale'])}): ")
               for line in lines)
    import scipy.io

    from musclemetab.io import read_storage

    mat = scipy.io.loadmat(result.to_mat(tmp_path / "result.mat"), simplify_cells=True)
    assert list(mat["trials"]) == list(TRIALS)
    est = mat["estimated"]["tendon_stiffness"]
    assert dict(zip(est["muscles"], est["factor"])) == pytest.approx(parameters["tendon_stiffness_scale"], rel=1e-15)
    for t in TRIALS:
        sto = read_storage(out / t / "solution.sto")
        muscles = mat[t]["muscles"]
        np.testing.assert_allclose(mat[t]["time_s"], sto.index.to_numpy(), atol=1e-12)
        np.testing.assert_allclose(mat[t]["activation"], sto[[f"/forceset/{m}/activation" for m in muscles]].to_numpy(),
                                   rtol=1e-9, atol=1e-12)
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputFileError, match="parameters.json: no such file"):
        Result.load(tmp_path / "empty")


@pytest.mark.opensim
@pytest.mark.slow
def test_the_problem_is_kept_beside_the_result(example, emg_ten, parameters, solutions, cache_dir, tmp_path):
    """The folder's ``problem.json`` gives the problem solved back (``load_result``): the trials,
    their windows and mesh, the EMG settings and solver options of the solve's record, the
    nominal parameters; a folder without it (written before results kept their problem) loads
    with ``problem`` None and a warning."""
    import shutil

    from musclemetab.errors import MusclemetabWarning
    from musclemetab.muscle import KT_GENERIC
    from musclemetab.redundancy.problem import load_result

    result = load_result(emg_ten[0], cache_dir=cache_dir)
    problem = result.problem
    assert problem.kind == "emg" and problem.workflow == "emg-ten" and problem.labels == TRIALS
    assert problem.emg.to_dict() == parameters["solve"]["settings"] and problem.options.stop == "authors"
    assert {s.kind for s in problem.specs} == {"tendon_stiffness", "emg_scale"}
    assert dict(problem.emg_mapping) == parameters["emg_channels"]
    np.testing.assert_array_equal(problem.parameters.tendon_stiffness, KT_GENERIC)  # the nominal kT, estimated after
    from musclemetab.redundancy.inputs import mesh_for_window

    for trial in problem.trials:
        np.testing.assert_allclose(mesh_for_window(trial.ik_time_s[0], trial.ik_time_s[-1]),
                                   solutions[trial.label].time_s, rtol=0, atol=1e-9)
    old = tmp_path / "old"
    shutil.copytree(emg_ten[0], old)
    (old / "problem.json").unlink()
    with pytest.warns(MusclemetabWarning, match="no problem.json"):
        assert load_result(old).problem is None


@pytest.mark.opensim
@pytest.mark.slow
def test_converges_with_the_study_problem_size(example, emg_ten, parameters, solutions):
    out, stdout = emg_ten
    rec = parameters["solve"]
    assert rec["status"] == "Solve_Succeeded" and rec["success"] is True
    assert 0 < rec["iterations"] < 10000
    # muscle_redundancy.md §6.7 with one variable per coupled group (2 kT + 6 EMG factors instead of
    # 6 + 9 with 4 + 3 coupling equalities; see test_study_problem_size_with_coupling_constraints)
    assert rec["settings"]["coupling"] == "shared"
    assert rec["problem_size"]["variables"] == 77250 - 7
    assert rec["problem_size"]["equality_constraints"] == 62002 - 7
    assert rec["problem_size"]["inequality_constraints"] == 3375
    assert sorted(p.name for p in out.iterdir()) == sorted([*TRIALS, "parameters.json", "problem.json",
                                                            ".musclemetab-files", f"{example.model.stem}_personalised.osim"])
    for t in TRIALS:
        s = solutions[t].summary
        assert s["workflow"]["name"] == "emg-ten" and s["workflow"]["trial"] == t
        assert s["status"] == "Solve_Succeeded" and s["success"] is True
        assert s["n_intervals"] == N_MESH[t] and solutions[t].time_s.size == N_MESH[t] + 1
        for key in ("objective", "iterations", "solve_time_s", "max_moment_residual_Nm", "max_hill_residual",
                    "reserve_rms_Nm", "emg_tracking", "objective_terms"):
            assert key in s
        assert s["objective"] == pytest.approx(rec["objective"], rel=1e-12)
        assert solutions[t].muscles == solutions["slow"].muscles and len(solutions[t].muscles) == 40
    assert "emg-ten 3 trials" in stdout and "Solve_Succeeded" in stdout


@pytest.mark.opensim
@pytest.mark.slow
def test_tendon_stiffness_matches_the_study(parameters, solutions):
    kt, scale = parameters["tendon_stiffness"], parameters["tendon_stiffness_scale"]
    assert set(kt) == set(TRICEPS_SURAE + VASTI) == set(scale)
    for group, muscles in (("triceps_surae", TRICEPS_SURAE), ("vasti", VASTI)):
        values = np.array([scale[m] for m in muscles])
        assert np.ptp(values) < 1e-7, f"{group} coupling"
        assert values[0] == pytest.approx(STUDY_KT_SCALE[group], rel=0.10)
        for m in muscles:
            assert kt[m] == pytest.approx(35.0 * scale[m], rel=1e-12)
            assert kt[m] == pytest.approx(STUDY_KT[group], rel=0.10)
    # the solutions were computed with the estimates; the other muscles keep kT = 35
    for sol in solutions.values():
        P = params_of(sol)
        for i, m in enumerate(sol.muscles):
            assert P["kT"][i] == pytest.approx(kt.get(m, 35.0), rel=1e-12)


@pytest.mark.opensim
@pytest.mark.slow
def test_estimates_equal_those_before_the_problem_core(parameters):
    """EMG-TEN as an instance of the problem core gives the objective, tendon stiffness and EMG
    scale factors of the version with its own builder (``tests/data/pre_core_results.json``; the
    iteration count is not compared: it changes with the MUMPS/BLAS build)."""
    from pathlib import Path

    ref = json.loads((Path(__file__).resolve().parent / "data" / "pre_core_results.json").read_text())["emg-ten"]
    assert parameters["solve"]["objective"] == pytest.approx(ref["objective"], rel=1e-6)
    for key in ("tendon_stiffness", "emg_scale"):
        assert set(parameters[key]) == set(ref[key])
        for m, v in ref[key].items():
            assert parameters[key][m] == pytest.approx(v, rel=1e-6), (key, m)


@pytest.mark.opensim
@pytest.mark.slow
def test_personalised_model_holds_the_tendon_stiffness(example, emg_ten, parameters):
    """The written .osim (Millard muscles) holds each estimated kT as the tendon strain at F0, the
    strain where the tendon curve reaches fT = 1 (muscle_model.md §7), read back by OpenSim."""
    import math

    from musclemetab.opensim_bridge.client import call

    kt = parameters["tendon_stiffness"]
    values = call("personalise:read_muscle_values", str(emg_ten[0] / f"{example.model.stem}_personalised.osim"),
                  [*kt, "tibant_r"])
    for m, k in kt.items():
        strain = math.log(5.0 * (1.25 - shift_ref(k))) / k - 0.005
        assert values[m]["tendon_strain_at_one_norm_force"] == pytest.approx(strain, rel=1e-12), m
    original = call("personalise:read_muscle_values", str(example.model), ["tibant_r"])
    assert values["tibant_r"] == original["tibant_r"]


@pytest.mark.opensim
@pytest.mark.slow
def test_emg_scale_factors_match_the_study(parameters):
    s = parameters["emg_scale"]
    assert list(s) == sorted(STUDY_EMG_SCALE)  # one per tracked muscle, alphabetical
    assert s["vaslat_r"] == pytest.approx(s["vasmed_r"], abs=1e-7)
    assert s["vaslat_r"] == pytest.approx(s["vasint_r"], abs=1e-7)
    assert s["gaslat_r"] == pytest.approx(s["gasmed_r"], abs=1e-7)
    for m, v in s.items():
        assert 0.05 - 1e-9 <= v <= 2.5 + 1e-9
        assert v == pytest.approx(STUDY_EMG_SCALE[m], rel=0.02), m
    assert parameters["emg_channels"]["vasint_r"] == ["ES"]


@pytest.mark.opensim
@pytest.mark.slow
@pytest.mark.parametrize("trial", TRIALS)
def test_solution_satisfies_the_problem(example, geometries, solutions, trial):
    sol = solutions[trial]
    n = N_MESH[trial]
    t, lmt, r, mom = mesh_inputs(example, geometries[trial], trial, n)
    P, _ = check_solution_satisfies_problem(sol, t, lmt, r, mom, n)
    # calibrated passive parameters (EMG-TEN uses the EFFORT-CAL passive muscle)
    i = sol.muscles.index("soleus_r")
    assert P["kPE"][i] == pytest.approx(4.999928, abs=1e-5) and P["s0"][i] == pytest.approx(1.107804, abs=1e-5)


@pytest.mark.opensim
@pytest.mark.slow
@pytest.mark.parametrize("trial", TRIALS)
def test_fiber_length_bounds_recorded_as_by_a_single_trial_solve(example, geometries, solutions, trial):
    """Each trial's summary.json records the fiber-length bounds under ``fiber_length_bounds``, as
    a single-trial solve does: the default box [0.1, 1.7] and the muscles whose longest
    rigid-tendon fiber, ``max sqrt((lMT - lTs)^2 + w^2) / lMo + 0.05`` over the mesh nodes (worked
    here from the filtered, interpolated lMT), is longer than 1.7, with that bound."""
    sol = solutions[trial]
    _, lmt, _, _ = mesh_inputs(example, geometries[trial], trial, N_MESH[trial])
    P = params_of(sol)
    w = P["lMo_m"] * np.sin(P["alpha0_rad"])
    rigid = np.max(np.sqrt((lmt - P["lTs_m"]) ** 2 + w**2), axis=0) / P["lMo_m"] + 0.05
    bounds = sol.summary["fiber_length_bounds"]
    assert bounds["default"] == [0.1, 1.7]
    widened = {m: float(b) for m, b in zip(sol.muscles, rigid) if b > 1.7}
    assert set(bounds["widened_upper"]) == set(widened)
    for m, b in widened.items():
        assert bounds["widened_upper"][m] == pytest.approx(b, rel=1e-6), m
    assert rigid.max() < 1.7  # on the example subject no muscle needs a wider bound


def _emg_at_nodes(example, trial, t_nodes, muscles):
    from musclemetab.io import read_storage

    emg = read_storage(example.emg[trial])
    te = emg.index.to_numpy()
    return np.column_stack([np.interp(t_nodes, te, emg[AUTHORS_CHANNELS[m]].to_numpy()) for m in muscles])


@pytest.mark.opensim
@pytest.mark.slow
@pytest.mark.parametrize("trial", TRIALS)
def test_emg_tracking_band_holds(example, parameters, solutions, trial):
    sol = solutions[trial]
    n = N_MESH[trial]
    muscles = list(parameters["emg_scale"])
    s = np.array([parameters["emg_scale"][m] for m in muscles])
    E = _emg_at_nodes(example, trial, sol.time_s[:n], muscles)
    e = sol.excitation[:n, [sol.muscles.index(m) for m in muscles]]
    dev = e - s * E
    assert np.max(np.abs(dev)) <= 0.01 + 1e-6
    # the band is active somewhere (the tracking shapes the solution)
    assert np.max(np.abs(dev)) > 0.009
    rec = sol.summary["emg_tracking"]
    assert set(rec) == set(muscles)
    for j, m in enumerate(muscles):
        assert rec[m]["max_abs_deviation"] == pytest.approx(np.max(np.abs(dev[:, j])), abs=1e-9)
        assert rec[m]["channels"] == [AUTHORS_CHANNELS[m]]


@pytest.mark.opensim
@pytest.mark.slow
def test_objective_recomputed_from_files(example, parameters, solutions):
    """muscle_redundancy.md §6.4: trials summed, each normalised by its own N."""
    muscles = list(parameters["emg_scale"])
    s = np.array([parameters["emg_scale"][m] for m in muscles])
    total = 0.0
    for trial in TRIALS:
        sol = solutions[trial]
        n, M, D = N_MESH[trial], len(sol.muscles), len(sol.dofs)
        P = params_of(sol)
        E = _emg_at_nodes(example, trial, sol.time_s[:n], muscles)
        e_tr = sol.excitation[:n, [sol.muscles.index(m) for m in muscles]]
        J = (W_EMG * np.sum((e_tr - s * E) ** 2) / (len(muscles) * n)
             + W_ACT * 0.5 * (np.sum(sol.excitation[:n] ** 2) + np.sum(sol.activation**2)) / (n * M)
             + W_RES * np.sum((sol.reserve_Nm[:n] / 150) ** 2) / (n * D)
             + W_VM * np.sum((sol.normalized_fiber_velocity[:n] * P["vmax_lMo_per_s"]) ** 2) / (n * M))
        assert J == pytest.approx(sol.summary["objective_trial"], rel=1e-6)
        total += J
    assert total == pytest.approx(parameters["solve"]["objective"], rel=1e-6)


@pytest.mark.opensim
@pytest.mark.slow
def test_tendon_stiffness_in_newton_per_mm(parameters, solutions):
    """k = dFT/dlT at FT = F0 (muscle_model.md §7), and the Achilles tendon as the three in parallel."""
    P = params_of(solutions["normal"])
    names = solutions["normal"].muscles
    kmm = parameters["tendon_stiffness_N_per_mm"]
    for m, kt in parameters["tendon_stiffness"].items():
        i = names.index(m)
        lt = np.log(5.0 * (1.0 + 0.25 - shift_ref(kt))) / kt + 0.995  # fT = 1
        k = P["F0_N"][i] * kt * np.exp(kt * (lt - 0.995)) / (5.0 * P["lTs_m"][i]) / 1000.0
        assert kmm[m] == pytest.approx(k, rel=1e-9)
        assert np.isfinite(kmm[m]) and kmm[m] > 0
    ach = parameters["achilles_tendon_stiffness_N_per_mm"]
    assert ach["at_max_isometric_force"] == pytest.approx(sum(kmm[m] for m in TRICEPS_SURAE), rel=1e-12)
    assert set(ach["at_peak_walking_force"]) == set(TRIALS)
    for t, k in ach["at_peak_walking_force"].items():
        assert np.isfinite(k) and 0 < k < ach["at_max_isometric_force"]
        sol = solutions[t]
        expected = 0.0
        for m in TRICEPS_SURAE:
            i = sol.muscles.index(m)
            kt = parameters["tendon_stiffness"][m]
            peak = sol.tendon_force_N[:, i].max() / P["F0_N"][i]
            expected += P["F0_N"][i] * kt * (peak + 0.25 - shift_ref(kt)) / P["lTs_m"][i] / 1000.0
        assert k == pytest.approx(expected, rel=1e-6)
    assert "F0*kT*(1.25 - shift(kT))/lTs" in parameters["tendon_stiffness_N_per_mm_definition"]


@pytest.mark.opensim
@pytest.mark.slow
def test_effort_ten_runs_from_the_written_parameters(example, emg_ten, parameters, cache_dir, tmp_path):
    """EFFORT-TEN of a window of the normal trial from the written parameters.json: every muscle's kT
    is the estimate's (35 where none was estimated), by the command line and the Python API."""
    from musclemetab.commands import main
    from musclemetab.redundancy import Solution, solve_files

    out = tmp_path / "effort_ten"
    pfile = emg_ten[0] / "parameters.json"
    assert main(["solve", "--workflow", "effort-ten", "--model", str(example.model), "--ik", str(example.ik["normal"]),
                 "--id", str(example.id["normal"]), "--parameters", str(pfile), "--window", "0.6:0.8",
                 "--cache-dir", str(cache_dir), "--out", str(out)]) == 0
    sol = Solution.load(out)
    assert sol.success and sol.summary["workflow"]["name"] == "effort-ten"
    assert sol.summary["max_moment_residual_Nm"] < 1e-4
    P = params_of(sol)
    for i, m in enumerate(sol.muscles):
        assert P["kT"][i] == pytest.approx(parameters["tendon_stiffness"].get(m, 35.0), rel=1e-12)
    assert set(sol.summary["workflow"]["tendon_stiffness_sources"].values()) == {str(pfile)}
    # the Python API reads the same file (building the problem only: one iteration)
    from musclemetab.redundancy import SolverOptions

    quick = solve_files(example.model, example.ik["normal"], example.id["normal"], "effort-ten",
                        tendon_stiffness_file=pfile, cache_dir=cache_dir, options=SolverOptions(max_iter=1))
    np.testing.assert_array_equal(quick.parameters.tendon_stiffness, P["kT"])


def test_coupling_pairs_of_the_study_groups_worked_by_hand():
    """The equalities that couple the factors of a group: kT chains consecutive members, the
    EMG scales tie each member to the first; muscles the problem lacks drop out of a group."""
    from musclemetab.redundancy.transcription import coupling_pairs
    from musclemetab.redundancy.emg_ten import EmgTenSettings

    settings = EmgTenSettings()
    kt_muscles = ("soleus_r", "gasmed_r", "gaslat_r", "vasint_r", "vaslat_r", "vasmed_r")
    # vasti (vaslat 4, vasmed 5, vasint 3) then triceps surae (gaslat 2, gasmed 1, soleus 0), in the groups' order
    assert coupling_pairs(settings.tendon_groups, kt_muscles, consecutive=True) == ((4, 5), (5, 3), (2, 1), (1, 0))
    emg_muscles = ("gaslat_r", "gasmed_r", "vasint_r", "vaslat_r", "vasmed_r")  # alphabetical
    # vasti (vaslat 3 first, vasmed 4, vasint 2) and gastrocnemii (gaslat 0 first, gasmed 1)
    assert coupling_pairs(settings.emg_groups, emg_muscles, consecutive=False) == ((3, 4), (3, 2), (0, 1))
    # 4 + 3 equalities, the study's count; a member the problem lacks, and a group left with one, give none
    assert coupling_pairs([("a", "x", "b", "c"), ("d",), ("y", "d")], ("c", "b", "a", "d"), consecutive=False) == \
        ((2, 1), (2, 0))


@pytest.mark.opensim
def test_study_problem_size_with_coupling_constraints(example, geometries):
    """The constraint form of the couplings is the study's NLP: 77 250 variables, 62 002
    equalities (61 995 + 4 kT + 3 EMG couplings), 3 375 EMG bounds (§6.7). Built, not solved."""
    from musclemetab.io import read_storage
    from musclemetab.model import read_muscle_parameters
    from musclemetab.redundancy.emg_pipeline import prepare_emg_ten_trials
    from musclemetab.redundancy.emg_ten import EmgTenSettings, build_emg_ten_nlp
    from musclemetab.redundancy.inputs import read_inverse_dynamics

    settings = EmgTenSettings(coupling="constraints")
    trials, params, _ = prepare_emg_ten_trials(
        [geometries[t] for t in TRIALS], read_muscle_parameters(example.model),
        [read_inverse_dynamics(example.id[t], DOFS) for t in TRIALS],
        [read_storage(example.emg[t]) for t in TRIALS], emg_mapping="authors", settings=settings)
    nlp = build_emg_ten_nlp(trials, params, settings)
    assert (nlp["n_variables"], nlp["n_equality_constraints"], nlp["n_inequality_constraints"]) == (77250, 62002, 3375)
    assert len(nlp["layout"]["pairs"]) == 7
    lo, hi = nlp["lbx"][-15:], nlp["ubx"][-15:]
    np.testing.assert_array_equal(lo, [0.1] * 6 + [0.05] * 9)
    np.testing.assert_array_equal(hi, [1.2] * 6 + [2.5] * 9)
    np.testing.assert_array_equal(nlp["x0"][-15:], np.ones(15))
    # the reserve guess is divided by Topt (§6.6): within the bounds wherever the static
    # optimisation reserve is below 150 N m
    g = trials[1].guess
    assert np.max(np.abs(g.reserve)) < 1.0


# --------------------------------------------------------------------------- derivatives
def _short_trials(example, geometries, rng):
    """Two short trials cut from the example (normal: 3 intervals, fast: 4) with random EMG and
    a random initial guess, and their effort-cal muscle parameters."""
    from dataclasses import replace

    from musclemetab.model import read_muscle_parameters
    from musclemetab.redundancy.emg_ten import EmgTenTrial
    from musclemetab.redundancy.inputs import read_inverse_dynamics, trial_inputs
    from musclemetab.redundancy.static_opt import InitialGuess
    from musclemetab.redundancy.workflows import workflow_parameters

    trials = []
    for lab, n in (("normal", 3), ("fast", 4)):
        g = geometries[lab]
        inp = trial_inputs(g, *read_inverse_dynamics(example.id[lab], DOFS))
        inp = replace(inp, mesh_time_s=inp.mesh_time_s[:n + 1], lmt_m=inp.lmt_m[:n + 1],
                      moment_arms_m=inp.moment_arms_m[:n + 1], moments_Nm=inp.moments_Nm[:n + 1])
        M, D = len(inp.muscles), len(inp.dofs)
        guess = InitialGuess(activation=rng.random((n + 1, M)), lm_norm=0.8 + 0.4 * rng.random((n + 1, M)),
                             lm_projected_m=0.05 + 0.05 * rng.random((n + 1, M)), excitation=rng.random((n, M)),
                             reserve=rng.random((n, D)) - 0.5, fiber_velocity_lmo_per_s=rng.random((n, M)) - 0.5)
        trials.append(EmgTenTrial(label=lab, inputs=inp, emg_muscles=tuple(sorted(AUTHORS_CHANNELS)),
                                  emg_nodes=rng.random((n, 9)), emg_channels={}, guess=guess))
    params, _ = workflow_parameters("effort-cal", read_muscle_parameters(example.model), trials[0].inputs.muscles)
    return trials, params


@pytest.mark.opensim
@pytest.mark.parametrize("coupling, fiber_dynamics", [("constraints", "forward"), ("shared", "forward"),
                                                      ("shared", "backward")])
def test_assembled_derivatives_equal_automatic_differentiation(example, geometries, coupling, fiber_dynamics):
    """The hand-assembled Jacobian and Hessian of the multi-trial NLP equal CasADi's AD (two
    short trials cut from the example, random point), with either transcription of the fiber
    dynamics (backward: the Hill equilibrium at the end node, second derivatives shared by two
    intervals' blocks)."""
    import casadi as ca
    from dataclasses import replace

    from musclemetab.redundancy.emg_ten import EMG_TEN_GOALS, EmgTenSettings, build_emg_ten_nlp

    rng = np.random.default_rng(0)
    trials, params = _short_trials(example, geometries, rng)
    settings = EmgTenSettings(goals=replace(EMG_TEN_GOALS, fiber_dynamics=fiber_dynamics), coupling=coupling)
    nlp = build_emg_ten_nlp(trials, params, settings)
    x, f, g = nlp["x"], nlp["f"], nlp["g"]
    n_p = 8 if coupling == "shared" else 15
    assert nlp["n_variables"] == sum(205 * n + 120 for n in (3, 4)) + n_p
    assert nlp["n_equality_constraints"] == sum(165 * n + 40 for n in (3, 4)) + (0 if coupling == "shared" else 7)
    assert nlp["n_inequality_constraints"] == 9 * 7
    x0 = np.array(nlp["x0"])
    x0[-n_p:] = 0.5 + rng.random(n_p)
    lam = rng.standard_normal(g.shape[0])
    sigma = 0.7
    lam_g = ca.MX.sym("lam_g", g.shape[0])
    p, pv = nlp["p"], nlp["p_values"]
    ad_jac = ca.Function("j", [x, p], [ca.jacobian(g, x)])
    ad_grad = ca.Function("gr", [x, p], [ca.gradient(f, x)])
    ad_hess = ca.Function("h", [x, p, lam_g], [ca.triu(ca.hessian(sigma * f + ca.dot(lam_g, g), x)[0])])
    f_val, grad = nlp["grad_f"](x0, pv)
    g_val, jac = nlp["jac_g"](x0, pv)
    hess = nlp["hess_lag"](x0, pv, sigma, lam)
    np.testing.assert_allclose(np.array(grad).ravel(), np.array(ad_grad(x0, pv)).ravel(), rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(ca.DM(jac).full(), ad_jac(x0, pv).full(), rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(ca.DM(hess).full(), ad_hess(x0, pv, lam).full(), rtol=1e-9, atol=1e-8)
    assert float(f_val) == pytest.approx(float(ca.Function("f", [x, p], [f])(x0, pv)), rel=1e-12)


@pytest.mark.opensim
def test_the_goals_hold_the_fiber_dynamics_of_every_emg_mode(example, geometries):
    """The transcription of the fiber dynamics is the goals' (``Goals.fiber_dynamics``; ``None``:
    the EMG mode's default). At a random point (two short trials) the constraints of the built
    NLP with the default are those of the explicit backward scheme in the driven mode and of the
    forward one in the constrained mode, and the recorded settings say so;
    ``Goals(fiber_dynamics="backward")`` gives the constrained mode the driven NLP's constraints
    (only its EMG bound rows are wider) and ``Goals(fiber_dynamics="forward")`` the driven mode
    the constrained ones. ``EmgTenSettings(fiber_dynamics=...)`` is a TypeError, and the problem
    is not built from goals whose scheme is not resolved."""
    from dataclasses import replace

    from musclemetab.errors import OptionError
    from musclemetab.redundancy.emg_ten import (EMG_TEN_GOALS, EmgTenSettings, build_emg_ten_nlp, emg_ten_problem,
                                                informed_settings)
    from musclemetab.redundancy.transcription import build_problem

    trials, params = _short_trials(example, geometries, np.random.default_rng(0))
    x0 = []

    def built(mode, scheme=None):
        """(recorded scheme, constraints at the random point, width of the constraint bounds)"""
        settings = EmgTenSettings(goals=replace(EMG_TEN_GOALS, fiber_dynamics=scheme), emg_mode=mode)
        nlp = build_emg_ten_nlp(trials, params, settings)
        x0.append(np.array(nlp["x0"]))
        g = np.array(nlp["jac_g"](x0[0], nlp["p_values"])[0]).ravel()
        return settings.to_dict()["fiber_dynamics"], g, np.asarray(nlp["ubg"]) - np.asarray(nlp["lbg"])

    driven, constrained = built("driven"), built("constrained")
    constrained_backward, driven_forward = built("constrained", "backward"), built("driven", "forward")
    assert all(np.array_equal(x, x0[0]) for x in x0)
    assert [r[0] for r in (driven, constrained, constrained_backward, driven_forward)] == [
        "backward", "forward", "backward", "forward"]
    assert EmgTenSettings(emg_mode="tracking").to_dict()["fiber_dynamics"] == "forward"
    assert [informed_settings("effort-cal", mode, fiber_dynamics=scheme).to_dict()["fiber_dynamics"]
            for mode, scheme in (("driven", None), ("constrained", None), ("constrained", "backward"))] == [
        "backward", "forward", "backward"]  # the command line's --fiber-dynamics of an EMG-informed solve
    np.testing.assert_array_equal(constrained_backward[1], driven[1])
    np.testing.assert_array_equal(driven_forward[1], constrained[1])
    assert np.max(np.abs(driven[1] - constrained[1])) > 1e-3  # the two schemes' constraints differ there
    assert np.max(driven[2]) == 0.0 and np.max(constrained_backward[2]) == pytest.approx(0.02)
    with pytest.raises(TypeError):
        EmgTenSettings(fiber_dynamics="backward")
    blocks, goals, specs = emg_ten_problem(trials, params, EmgTenSettings())
    assert goals.fiber_dynamics == "forward"
    with pytest.raises(OptionError, match=r"goals\.resolved\(emg_mode\)"):
        build_problem(blocks, params, replace(goals, fiber_dynamics=None), specs)


# --------------------------------------------------------------------------- bad inputs
def _write_emg(example, trial, path, edit):
    from musclemetab.io import read_storage, write_storage

    df = read_storage(example.emg[trial])
    df = edit(df)
    write_storage(path, df, name="edited EMG")
    return path


def _args(example, emg=None, ik=None, idf=None):
    return ([example.ik[t] for t in TRIALS] if ik is None else ik,
            [example.id[t] for t in TRIALS] if idf is None else idf,
            [example.emg[t] for t in TRIALS] if emg is None else emg)


def test_unequal_numbers_of_files(example):
    from musclemetab.errors import OptionError
    from musclemetab.redundancy import solve_emg_ten

    ik, idf, emg = _args(example)
    with pytest.raises(OptionError, match=r"3 IK, 2 ID and 3 EMG files"):
        solve_emg_ten(example.model, ik, idf[:2], emg)
    with pytest.raises(OptionError, match=r"3 IK, 3 ID and 1 EMG files"):
        solve_emg_ten(example.model, ik, idf, emg[:1])


def test_emg_channels_missing_for_the_mapping(example, tmp_path):
    from musclemetab.errors import MissingColumnError, OptionError
    from musclemetab.redundancy import solve_emg_ten

    bad = _write_emg(example, "normal", tmp_path / "no_vi.mot", lambda d: d.drop(columns=["VI_a", "SO"]))
    ik, idf, emg = _args(example)
    emg[1] = bad
    with pytest.raises(MissingColumnError) as err:
        solve_emg_ten(example.model, ik, idf, emg)
    msg = str(err.value)
    assert str(bad) in msg and "VI_a" in msg and "SO" in msg and "vasint_r" in msg and "soleus_r" in msg
    # the authors' mapping does not need VI_a but still needs SO
    with pytest.raises(MissingColumnError, match="SO") as err:
        solve_emg_ten(example.model, ik, idf, emg, emg_mapping="authors")
    assert "VI_a" not in str(err.value).split("the file has")[0]
    with pytest.raises(MissingColumnError, match="XY"):
        solve_emg_ten(example.model, *_args(example), emg_mapping={"soleus_r": ["SO"], "tibant_r": "XY"})
    with pytest.raises(OptionError, match="'default', 'authors'"):
        solve_emg_ten(example.model, *_args(example), emg_mapping="writers")


def test_emg_not_covering_the_window(example, tmp_path):
    from musclemetab.errors import DataMismatchError
    from musclemetab.redundancy import solve_emg_ten

    short = _write_emg(example, "fast", tmp_path / "short.mot", lambda d: d[d.index <= 1.2])
    ik, idf, emg = _args(example)
    emg[2] = short
    with pytest.raises(DataMismatchError) as err:
        solve_emg_ten(example.model, ik, idf, emg)
    msg = str(err.value)
    assert str(short) in msg and "0.48-1.47 s" in msg and str(example.ik["fast"]) in msg and "window" in msg


def test_emg_outside_unit_range(example, tmp_path):
    from musclemetab.errors import DataMismatchError
    from musclemetab.redundancy import solve_emg_ten

    def scale_ta(d):
        d = d.copy()
        d["TA"] = d["TA"] * 5.0  # peak 0.32 -> 1.6 in the window
        return d

    bad = _write_emg(example, "normal", tmp_path / "ta_x5.mot", scale_ta)
    ik, idf, emg = _args(example)
    emg[1] = bad
    with pytest.raises(DataMismatchError) as err:
        solve_emg_ten(example.model, ik, idf, emg)
    msg = str(err.value)
    assert str(bad) in msg and "tibant_r" in msg and "TA" in msg and "outside [0, 1]" in msg

    def negative_bf(d):
        d = d.copy()
        d["BF"] = d["BF"] - 0.1
        return d

    emg[1] = _write_emg(example, "normal", tmp_path / "bf_neg.mot", negative_bf)
    with pytest.raises(DataMismatchError, match="bflh_r .*BF"):
        solve_emg_ten(example.model, ik, idf, emg)


def test_trials_from_different_models(example, tmp_path):
    from musclemetab.errors import DataMismatchError
    from musclemetab.redundancy import solve_emg_ten

    other = tmp_path / "other_model.osim"
    text = example.model.read_text()
    other.write_text(text.replace("<max_isometric_force>", "<max_isometric_force>1", 1))
    same = tmp_path / "copy.osim"
    shutil.copy(example.model, same)
    with pytest.raises(DataMismatchError) as err:
        solve_emg_ten([example.model, same, other], *_args(example))
    assert "different models" in str(err.value) and str(other) in str(err.value)


def test_dofs_of_the_chosen_side_are_discovered(example, tmp_path, capsys):
    """EMG-TEN's DOFs come from the model and the ID files, like the other workflows': the study's
    five DOFs for the example's right leg, their left counterparts for its left leg."""
    from musclemetab.commands import main
    from musclemetab.errors import UnknownMuscleError
    from musclemetab.redundancy import solve_emg_ten
    from musclemetab.redundancy.trial_files import trial_dofs as _trial_dofs
    from musclemetab.redundancy.inputs import DEFAULT_DOFS

    ik, idf, emg = _args(example)
    assert _trial_dofs(example.model, idf, None, "r", None) == DEFAULT_DOFS
    assert _trial_dofs(example.model, idf, None, "l", None) == tuple(d[:-1] + "l" for d in DEFAULT_DOFS)
    # the left leg's problem is built (one trial: each trial's DOFs are found alike, checked above);
    # the example's EMG channels are mapped to right-leg muscles
    with pytest.raises(UnknownMuscleError, match=r"soleus_r.* not among the muscles of the problem \(addbrev_l"):
        solve_emg_ten(example.model, ik[1:2], idf[1:2], emg[1:2], side="l")
    code = main(["solve", "--workflow", "emg-ten", "--model", str(example.model), "--ik", *map(str, ik),
                 "--id", *map(str, idf), "--emg", *map(str, emg), "--side", "both", "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1 and "--side both" in err and not (tmp_path / "x").exists()


def test_cli_rejects_bad_input_on_one_line(example, tmp_path, capsys):
    from musclemetab.commands import main

    ik, idf, emg = _args(example)
    code = main(["solve", "--workflow", "emg-ten", "--model", str(example.model), "--ik", *map(str, ik),
                 "--id", *map(str, idf[:2]), "--emg", *map(str, emg), "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1 and err.startswith("musclemetab: error:") and "2 ID" in err
    code = main(["solve", "--workflow", "emg-ten", "--model", str(example.model), "--ik", *map(str, ik),
                 "--id", *map(str, idf), "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 1 and "needs --emg" in err
    code = main(["solve", "--workflow", "effort-gen", "--model", str(example.model), "--ik", *map(str, ik[:2]),
                 "--id", *map(str, idf[:2]), "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 1 and "one trial" in err
    # an effort workflow with --emg is an EMG-informed solve (tests/test_emg_informed.py); its
    # options are checked before any work
    code = main(["solve", "--workflow", "effort-gen", "--model", str(example.model), "--ik", str(ik[0]),
                 "--id", str(idf[0]), "--emg", str(emg[0]), "--parameters", "p.json", "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 1 and "--parameters" in err and "EMG-informed" in err
    code = main(["solve", "--workflow", "emg-ten", "--model", str(example.model), "--ik", *map(str, ik),
                 "--id", *map(str, idf), "--emg", *map(str, emg), "--parameters", "p.json",
                 "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 1 and "--parameters" in err
    assert not (tmp_path / "x").exists()


def test_unconverged_parameters_are_refused(tmp_path):
    from musclemetab.errors import InputFileError
    from musclemetab.redundancy.workflows import read_tendon_stiffness_json

    p = tmp_path / "parameters.json"
    p.write_text(json.dumps({"tendon_stiffness": {"soleus_r": 10.0},
                             "solve": {"success": False, "status": "Maximum_Iterations_Exceeded"}}))
    with pytest.raises(InputFileError, match="did not converge"):
        read_tendon_stiffness_json(p)
    p.write_text(json.dumps({"tendon_stiffness": {"soleus_r": 10.0}, "solve": {"success": True}}))
    assert read_tendon_stiffness_json(tmp_path) == {"soleus_r": 10.0}  # a folder means its parameters.json


@pytest.mark.opensim
def test_unconverged_emg_ten_is_reported(example, cache_dir, geometries, tmp_path, capsys):
    """An EMG-TEN stopped by the iteration limit (the normal trial alone, two iterations): exit
    status 1, IPOPT's status on standard error, the trial's folder and parameters.json written
    with ``success: false``, and EFFORT-TEN refuses those parameters."""
    from musclemetab.commands import main

    out = tmp_path / "out"
    ik, idf, emg = ([example.ik["normal"]], [example.id["normal"]], [example.emg["normal"]])
    code = main(["solve", "--workflow", "emg-ten", "--model", str(example.model), "--ik", *map(str, ik),
                 "--id", *map(str, idf), "--emg", *map(str, emg), "--max-iter", "2", "--cache-dir", str(cache_dir),
                 "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1 and "did not converge" in err and "Maximum_Iterations_Exceeded" in err
    doc = json.loads((out / "parameters.json").read_text())
    assert doc["solve"]["success"] is False
    assert sorted(p.name for p in out.iterdir()) == sorted([p.stem for p in ik] + ["parameters.json", "problem.json",
                                                                                ".musclemetab-files"])
    assert main(["solve", "--workflow", "effort-ten", "--model", str(example.model), "--ik", str(ik[0]),
                 "--id", str(idf[0]), "--parameters", str(out / "parameters.json"), "--out", str(tmp_path / "y")]) == 1
    assert "did not converge" in capsys.readouterr().err


def test_settings_checks_name_the_option_and_what_it_may_be():
    """The settings types check their options alike (``redundancy._checks``): the option, the
    allowed values or range, the value given; a weight that is not a finite number is refused
    by every type (the solver options once let NaN through)."""
    from musclemetab.errors import OptionError
    from musclemetab.redundancy.transcription import Goals, ParameterSpec
    from musclemetab.redundancy.emg_ten import EmgTenSettings
    from musclemetab.redundancy.ipopt import SolverOptions

    cases = [
        (lambda: EmgTenSettings(coupling="joint"), "coupling must be one of 'constraints', 'shared', not 'joint'"),
        (lambda: EmgTenSettings(emg_mode="free"), "the EMG mode must be one of 'constrained', 'driven', 'tracking'"),
        (lambda: EmgTenSettings(goals=Goals(w_emg=-1.0)), "the weight w_emg must be a non-negative number, not -1.0"),
        (lambda: EmgTenSettings(emg_scale_bounds=(2.0, 1.0)), "emg_scale_bounds must be (low, high) with 0 < low"),
        (lambda: Goals(w_activation=float("nan")), "the weight w_activation must be a non-negative number"),
        (lambda: EmgTenSettings(goals=Goals(energy=None, w_fiber_length=1.0)), "no fiber-length weight"),
        (lambda: EmgTenSettings(goals={"w_emg": 1.0}), "goals must be a Goals, not dict"),
        (lambda: SolverOptions(derivatives="numeric"), "derivatives must be one of 'explicit', 'auto'"),
        (lambda: Goals(emg_tolerance=-0.1), "the EMG tolerance must be a non-negative number (0: EMG-driven)"),
        (lambda: ParameterSpec("tendon_stiffness", ("soleus_r",), (0.0, 1.0)),
         "the bounds of the tendon_stiffness factors must be (low, high) with 0 < low <= high"),
    ]
    for make, message in cases:
        with pytest.raises(OptionError) as info:
            make()
        assert message in str(info.value)
    assert EmgTenSettings(emg_scale_bounds=(1, 2)).emg_scale_bounds == (1.0, 2.0)


# --------------------------------------------------------------------------- identifiability
@pytest.mark.opensim
@pytest.mark.slow
def test_identifiability_of_the_estimates_is_recorded(parameters):
    """The example's EMG-TEN records the identifiability report of its 8 factors (2 tendon, 6 EMG
    scale: the shared groups) in parameters.json (``solve.doubts.identifiability``): the factors
    are the estimates, the scale ``s^2`` comes from the EMG tracking term over every trial's nodes
    and tracked muscles. On the three trials the reduced Hessian on the factors comes out
    indefinite (a negative diagonal entry of its inverse; docs/problem.md): it is reported near
    singular (and warned), the standard errors undetermined (``None``), not made up. The values
    against finite differences: the small problem below."""
    ident = parameters["solve"]["doubts"]["identifiability"]
    labels = ident["parameters"]
    assert [lab.split(":")[0] for lab in labels] == ["tendon_stiffness"] * 2 + ["emg_scale"] * 6
    estimates = {"tendon_stiffness": parameters["tendon_stiffness_scale"], "emg_scale": parameters["emg_scale"]}
    for lab in labels:
        kind, muscles = lab.split(":")
        for m in muscles.split(","):
            assert ident["factor"][lab] == pytest.approx(estimates[kind][m], rel=1e-12)
    assert {frozenset(lab.split(":")[1].split(",")) for lab in labels[:2]} == {frozenset(TRICEPS_SURAE), frozenset(VASTI)}
    scale = ident["residual_scale"]
    tracking = sum(parameters["solve"]["objective_terms"][t]["emg_tracking"] for t in TRIALS)
    assert scale["n_data"] == sum(N_MESH.values()) * 9 and scale["n_parameters"] == 8
    assert scale["tracking_objective"] == pytest.approx(tracking, rel=1e-12)
    assert scale["s2"] == pytest.approx(2 * tracking / (scale["n_data"] - 8), rel=1e-12)
    if ident["correlation"] is None:  # the measured case: C not positive on its diagonal
        assert ident["near_singular"] and ident["reduced_hessian_rcond"] == 0.0
        assert all(v is None for v in ident["standard_error"].values()) and ident["correlated_pairs"] == []
    else:
        from musclemetab.redundancy.identifiability import CORRELATION_THRESHOLD

        R = np.array(ident["correlation"])
        assert np.allclose(R, R.T) and np.allclose(np.diag(R), 1.0)
        above = [[labels[i], labels[j]] for i in range(8) for j in range(i + 1, 8) if abs(R[i, j]) >= CORRELATION_THRESHOLD]
        assert [p["parameters"] for p in ident["correlated_pairs"]] == above
    assert ident["identifiability_time_s"] > 0


@pytest.fixture(scope="module")
def ankle_emg_ten(example, reference_table):
    """A small EMG-TEN problem with a known answer: the example's normal trial, first 31 frames, the
    ankle alone (its 11 muscles, the study's MuscleAnalysis geometry, no OpenSim), EMG made from the
    effort optimum with the triceps-surae tendon factor at 0.5 (excitations / 0.8, a small ripple),
    tracked with one EMG scale shared by the 11 muscles and the triceps-surae tendon factor
    estimated, EMG-TEN weights, the tracking goal alone (no band rows: a smooth value function)."""
    import types
    from dataclasses import replace

    from test_energy_goal import reference_model_parameters

    from musclemetab.io import read_storage
    from musclemetab.redundancy import inputs as I
    from musclemetab.redundancy import workflows as W
    from musclemetab.redundancy.emg_ten import EMG_TEN_GOALS, EmgTenSettings, EmgTenTrial, solve_emg_ten_ocp
    from musclemetab.redundancy.ipopt import SolverOptions
    from musclemetab.redundancy.static_opt import initial_guess, static_optimisation

    folder, t, F = example.reference_muscle_analysis, reference_table, 31
    lengths = read_storage(folder / "IK_sub1_normal_MuscleAnalysis_Length.sto")
    names = list(lengths.columns)
    r = read_storage(folder / "IK_sub1_normal_MuscleAnalysis_MomentArm_ankle_angle_r.sto")[names].to_numpy()[:, None]
    keep, _ = I.select_muscles(names, r, ("ankle_angle_r",))
    muscles = [names[i] for i in keep]
    model = reference_model_parameters(t)
    t_ik, _ = I.read_kinematics(example.ik["normal"])
    t_id, mom = I.read_inverse_dynamics(example.id["normal"])
    geo = types.SimpleNamespace(time=lengths.index.to_numpy()[:F], muscles=muscles, dofs=("ankle_angle_r",),
                                lmt_m=lengths.to_numpy()[:F, keep], moment_arms_m=r[:F, :, keep])
    params, _ = W.workflow_parameters("effort-cal", model, muscles)
    inp = I.trial_inputs(geo, t_id, np.asarray(mom)[:, [list(DOFS).index("ankle_angle_r")]], ik_time_s=t_ik[:F])
    options = SolverOptions(tol=1e-10)
    guess = initial_guess(inp, params, static_optimisation(inp, params))
    guess = replace(guess, reserve=guess.reserve / options.optimal_reserve_Nm)
    tracked, n = tuple(sorted(muscles)), inp.n_intervals

    def settings(kt=(0.1, 1.2), scale=(0.05, 2.5), w_emg=EMG_TEN_GOALS.w_emg):
        return EmgTenSettings(goals=replace(EMG_TEN_GOALS, w_emg=w_emg), emg_mode="tracking",
                              tendon_groups=(TRICEPS_SURAE,), emg_groups=(tracked,), tendon_scale_bounds=kt,
                              emg_scale_bounds=scale)

    def trial(emg):
        return EmgTenTrial("normal", inp, tracked, emg, {m: [m] for m in tracked}, guess)

    truth = solve_emg_ten_ocp([trial(np.zeros((n, len(tracked))))], params, settings((0.5, 0.5), (1, 1), 1e-9),
                              options)
    assert truth.success
    e = np.column_stack([truth.trials[0].excitation[:n, muscles.index(m)] for m in tracked])
    emg = e / 0.8 + 0.005 * np.outer(np.sin(np.arange(n)), np.cos(np.arange(len(tracked))))
    return trial(emg), params, settings, options


@pytest.mark.opensim
def test_emg_ten_standard_errors_agree_with_finite_differences_of_the_value_function(ankle_emg_ten):
    """The standard errors and correlation recorded for EMG-TEN's estimated factors
    (``doubts.identifiability``: the inverse reduced Hessian on the factors, scaled by
    ``s^2 = 2 J_track/(n_data - n_p)``) against central finite differences: the reduced Hessian
    is the Hessian of the value function ``V(p) = min J`` with the factors held at ``p``, whose
    gradient is minus the multipliers of the factors' (equal) bounds at that optimum (the
    envelope theorem); ``V''`` from that gradient at ``p* +- h e_j`` (four solves, h = 2e-3).
    The reduced Hessian holds the weakly active bounds (slack below multiplier) fixed, which
    the value function lets go: on this problem the tendon factor's error is 6 % below the
    finite differences' (measured: 0.0064 against 0.0069), the EMG scale's within 1 %, the
    correlation 0.18 against 0.14."""
    from musclemetab.redundancy.emg_pipeline import record_identifiability
    from musclemetab.redundancy.emg_ten import build_emg_ten_nlp, emg_ten_problem, solve_emg_ten_ocp
    from musclemetab.redundancy.identifiability import _labels
    from musclemetab.redundancy.result import assemble_result

    trial, params, settings, options = ankle_emg_ten
    ocp = solve_emg_ten_ocp([trial], params, settings(), options)
    assert ocp.success
    result = assemble_result([trial], params, {}, ocp, settings(), options, 0.0, 0.0)
    report = record_identifiability(result, [trial], params, settings(), options, ocp)
    from musclemetab.redundancy.entries import thaw

    assert thaw(result.record.doubts["identifiability"]) == thaw(report)  # recorded (read-only) as returned
    p = np.array([ocp.factors["tendon_stiffness"]["soleus_r"], ocp.factors["emg_scale"]["soleus_r"]])
    assert 0.15 < p[0] < 1.0 and 0.6 < p[1] < 1.0  # inside their bounds
    assert report["parameters"][0].startswith("tendon_stiffness:") and report["parameters"][1].startswith("emg_scale:")
    assert report["factor"] == pytest.approx(dict(zip(report["parameters"], p)), rel=1e-12)
    # the factors' columns in the NLP, then V'(p) = -lam_x of those columns with the factors fixed
    _, _, specs = emg_ten_problem([trial], params, settings())
    _, cols = _labels(specs, build_emg_ten_nlp([trial], params, settings(), options)["layout"])

    def gradient(q):
        fixed = solve_emg_ten_ocp([trial], params, settings((q[0], q[0]), (q[1], q[1])), options)
        assert fixed.success
        return -np.asarray(fixed.kkt["lam_x"]).reshape(-1)[cols]

    h = 2e-3
    hess = np.column_stack([(gradient(p + h * e) - gradient(p - h * e)) / (2 * h) for e in np.eye(2)])
    cov = report["residual_scale"]["s2"] * np.linalg.inv(0.5 * (hess + hess.T))
    se_fd = np.sqrt(np.diag(cov))
    se = np.array([report["standard_error"][k] for k in report["parameters"]])
    np.testing.assert_allclose(se, se_fd, rtol=0.1)
    assert se[1] == pytest.approx(se_fd[1], rel=0.02)
    assert report["correlation"][0][1] == pytest.approx(cov[0, 1] / np.sqrt(cov[0, 0] * cov[1, 1]), abs=0.08)
    assert report["correlated_pairs"] == [] and not report["near_singular"]
    # s^2 from the tracking term: 2 J_track / (nodes x muscles - 2)
    n_data = trial.inputs.n_intervals * len(trial.emg_muscles)
    assert report["residual_scale"]["s2"] == pytest.approx(
        2 * ocp.objective_terms["normal"]["emg_tracking"] / (n_data - 2), rel=1e-12)
