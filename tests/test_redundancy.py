"""Muscle redundancy solver on the example subject: three trials x three workflows.

Every (trial, workflow) pair is solved once per test session, through the command line
(``musclemetab solve``), and read back with ``Solution.load``. The checks recompute what they
verify from the written files with formulas written here from the method documents
(``muscle_model.md``, ``muscle_redundancy.md``), not with the package's own functions:

* joint moments rebuilt from tendon forces, moment arms and reserves equal the filtered ID
  moments at every constrained node (1e-4 N m);
* Hill equilibrium (1e-4, normalised) and activation dynamics hold on the mesh;
* the EFFORT-GEN objectives are within 3 % of the values logged by the study's solver.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mrs_reference import (
    DOFS,
    check_solution_satisfies_problem,
    fl_ref,
    fpe_ref,
    fv_ref,
    mesh_inputs,
    params_of,
)

TEST_DATA = Path(__file__).resolve().parent / "data"
TRIALS = ("slow", "normal", "fast")
WORKFLOWS = ("effort-gen", "effort-cal", "effort-ten")
# Final objectives of the study's EFFORT-GEN runs (IPOPT logs), muscle_redundancy.md §5.5.
REFERENCE_OBJECTIVE = {"slow": 1.4137e-2, "normal": 2.3170e-2, "fast": 3.2867e-2}
# Mesh intervals and NLP sizes of the study (muscle_redundancy.md §3.4, §5.5).
REFERENCE_SIZE = {"slow": (158, 32510, 26110), "normal": (118, 24310, 19510), "fast": (99, 20415, 16375)}
TRICEPS_SURAE = ("soleus_r", "gasmed_r", "gaslat_r")
KT_TS, KT_VA = 10.617977, 4.695786


# --------------------------------------------------------------------------- session solves
@pytest.fixture(scope="session")
def solve_root(tmp_path_factory):
    return tmp_path_factory.mktemp("solves")


@pytest.fixture(scope="session")
def geometries(example, geometry_cache):
    """Geometry of the three trials (OpenSim in its worker; cached for the CLI runs)."""
    from musclemetab.geometry import compute_geometry

    return {t: compute_geometry(example.model, example.ik[t], dofs=list(DOFS), cache_dir=geometry_cache)
            for t in TRIALS}


@pytest.fixture(scope="session")
def tendon_json(tmp_path_factory):
    path = tmp_path_factory.mktemp("params") / "parameters.json"
    path.write_text(json.dumps({"tendon_stiffness": {
        "soleus_r": KT_TS, "gasmed_r": KT_TS, "gaslat_r": KT_TS,
        "vasint_r": KT_VA, "vaslat_r": KT_VA, "vasmed_r": KT_VA}}))
    return path


@pytest.fixture(scope="session")
def solved(example, geometries, geometry_cache, solve_root, passive_csv, tendon_json):
    """``solved(trial, workflow)`` -> (Solution, folder); each pair is solved at most once, with
    the study's stop (``--stop authors``: these solves are compared with the study's logs and the
    package's results before the stop had a name).

    The calibration and tendon-stiffness sources vary over the trials so that every input
    path is exercised while solving the same problems: effort-cal uses the study's .mat for
    slow, the package CSV format for normal and the shipped published calibration for fast;
    effort-ten takes its kT from a parameters.json (slow), the command line (normal) or the
    example subject's estimates asked for by name (fast).
    """
    from musclemetab.commands import main
    from musclemetab.redundancy import Solution

    cache: dict = {}

    def run(trial: str, workflow: str):
        key = (trial, workflow)
        if key not in cache:
            out = solve_root / f"{trial}_{workflow}"
            argv = ["solve", "--model", str(example.model), "--ik", str(example.ik[trial]),
                    "--id", str(example.id[trial]), "--workflow", workflow, "--stop", "authors",
                    "--cache-dir", str(geometry_cache), "--out", str(out)]
            if workflow == "effort-cal":
                argv += {"slow": ["--passive", str(example.passive_moments_mat)],
                         "normal": ["--passive", str(passive_csv)], "fast": []}[trial]
            if workflow == "effort-ten":
                argv += {"slow": ["--parameters", str(tendon_json)],
                         "normal": ["--tendon-stiffness",
                                    f"soleus_r={KT_TS},gasmed={KT_TS},gaslat_r={KT_TS},"
                                    f"vasint_r={KT_VA},vaslat_r={KT_VA},vasmed_r={KT_VA}",
                                    "--passive", str(passive_csv)],
                         "fast": ["--tendon-stiffness", "example"]}[trial]
            assert main(argv) == 0
            cache[key] = (Solution.load(out), out)
        return cache[key]

    return run


# --------------------------------------------------------------------------- the solves
@pytest.mark.opensim
@pytest.mark.slow
@pytest.mark.parametrize("workflow", WORKFLOWS)
@pytest.mark.parametrize("trial", TRIALS)
def test_solution_satisfies_the_problem(example, geometries, solved, trial, workflow):
    sol, folder = solved(trial, workflow)
    s = sol.summary
    assert s["status"] == "Solve_Succeeded" and s["success"] is True
    assert 0 < s["iterations"] < 10000
    n, n_var, n_con = REFERENCE_SIZE[trial]
    assert s["n_intervals"] == n and sol.time_s.size == n + 1
    assert s["problem_size"] == {"variables": n_var, "equality_constraints": n_con}
    assert sol.muscles == geometries[trial].muscles and len(sol.muscles) == 40
    assert sol.dofs == DOFS

    t, lmt, r, mom = mesh_inputs(example, geometries[trial], trial, n)
    P, vbar = check_solution_satisfies_problem(sol, t, lmt, r, mom, n)

    # derived columns
    np.testing.assert_allclose(sol.active_force_length_multiplier, fl_ref(sol.lm_norm), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(sol.force_velocity_multiplier, fv_ref(vbar), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(sol.active_fiber_force_N,
                               sol.activation * fl_ref(sol.lm_norm) * fv_ref(vbar) * P["F0_N"], rtol=1e-8, atol=1e-6)
    np.testing.assert_allclose(sol.passive_fiber_force_N,
                               P["F0_N"] * fpe_ref(sol.lm_norm, P["kPE"], P["s0"], P["sM"]), rtol=1e-8, atol=1e-6)

    # controls hold node N-1 at node N
    for arr in (sol.excitation, vbar, sol.reserve_Nm, sol.force_velocity_multiplier):
        np.testing.assert_array_equal(arr[n], arr[n - 1])

    # the objective recomputed from the file (muscle_redundancy.md §5.4)
    M, D = len(sol.muscles), len(sol.dofs)
    J = (0.5 * (np.sum(sol.excitation[:n] ** 2) + np.sum(sol.activation**2)) / (n * M)
         + 1000 * np.sum((sol.reserve_Nm[:n] / 150) ** 2) / (n * D)
         + 0.01 * np.sum((vbar[:n] * P["vmax_lMo_per_s"]) ** 2) / (n * M))
    assert J == pytest.approx(s["objective"], rel=1e-8)

    # summary residuals agree with the files
    assert s["max_moment_residual_Nm"] < 1e-4 and s["max_hill_residual"] < 1e-4
    assert set(s["reserve_rms_Nm"]) == set(DOFS)
    rms = np.sqrt(np.mean(sol.reserve_Nm[:n] ** 2, axis=0))
    np.testing.assert_allclose([s["reserve_rms_Nm"][d] for d in DOFS], rms, rtol=1e-8, atol=1e-12)


@pytest.mark.opensim
@pytest.mark.slow
@pytest.mark.parametrize("trial", TRIALS)
def test_effort_gen_objective_matches_the_study(solved, trial):
    sol, _ = solved(trial, "effort-gen")
    assert sol.objective == pytest.approx(REFERENCE_OBJECTIVE[trial], rel=0.03)
    # no rigid-tendon fiber of the example reaches 1.65 optimal lengths: every bound is the study's 1.7
    assert sol.summary["fiber_length_bounds"]["widened_upper"] == {}


#: Table 2 of the study, EFFORT-TEN at the preferred speed: mean [SD] over 8 subjects, W/kg.
TABLE2_EFFORT_TEN = {"UM03": (6.4, 0.5), "BH04": (5.0, 0.6), "HO06": (4.3, 0.5),
                     "LW07": (7.7, 0.9), "UM10": (7.2, 0.6), "UC16": (4.5, 0.5)}


@pytest.mark.opensim
def test_effort_ten_rates_within_table2_at_the_study_stop(example, solved):
    """At the study's stop (where the paper's numbers were made) the example subject's normal
    EFFORT-TEN rates lie within two between-subject SDs of Table 2's means (one subject here,
    eight in the paper)."""
    from musclemetab.metabolics.solution import metabolics_from_solution

    sol, _ = solved("normal", "effort-ten")
    assert sol.record.solver_options["stop"] == "authors"
    met = metabolics_from_solution(sol, example.body_mass_kg, example.height_m, models="all")
    for model, (mean, sd) in TABLE2_EFFORT_TEN.items():
        rate = met.whole_body[model].mean_W_per_kg
        assert abs(rate - mean) <= 2 * sd, (model, rate)


@pytest.mark.opensim
@pytest.mark.slow
@pytest.mark.parametrize("workflow", WORKFLOWS)
@pytest.mark.parametrize("trial", TRIALS)
def test_results_equal_those_before_the_problem_core(solved, trial, workflow):
    """The named workflows as instances of the problem core give the objectives of the version
    with separate builders (``tests/data/pre_core_results.json``). The iteration counts are not
    compared: they change with the MUMPS/BLAS build, the optimum does not."""
    ref = json.loads((TEST_DATA / "pre_core_results.json").read_text())["effort"][f"{trial}/{workflow}"]
    sol, _ = solved(trial, workflow)
    assert sol.objective == pytest.approx(ref["objective"], rel=1e-6)


@pytest.mark.opensim
@pytest.mark.slow
@pytest.mark.parametrize("trial", TRIALS)
def test_workflow_parameters_recorded(solved, example, passive_csv, tendon_json, trial):
    gen, _ = solved(trial, "effort-gen")
    cal, _ = solved(trial, "effort-cal")
    ten, _ = solved(trial, "effort-ten")
    pg, pc, pt = params_of(gen), params_of(cal), params_of(ten)
    assert np.all(pg["kPE"] == 4) and np.all(pg["s0"] == 1) and np.all(pg["sM"] == 0.6) and np.all(pg["kT"] == 35)
    # calibrated values of passive_calibration.md §5.2 (soleus, glmed1, addbrev)
    i = {m: cal.muscles.index(m) for m in ("soleus_r", "glmed1_r", "addbrev_r")}
    assert pc["kPE"][i["soleus_r"]] == pytest.approx(4.999928, abs=1e-5)
    assert pc["s0"][i["soleus_r"]] == pytest.approx(1.107804, abs=1e-5)
    assert pc["kPE"][i["glmed1_r"]] == pytest.approx(3.000055, abs=1e-5)
    assert pc["s0"][i["addbrev_r"]] == pytest.approx(0.800005, abs=1e-5)
    assert np.all(pc["kT"] == 35)
    np.testing.assert_allclose(pt["kPE"], pc["kPE"], atol=1e-5)
    expected_kt = np.array([KT_TS if m in TRICEPS_SURAE else KT_VA if m in ("vasint_r", "vaslat_r", "vasmed_r")
                            else 35.0 for m in ten.muscles])
    np.testing.assert_array_equal(pt["kT"], expected_kt)
    source = cal.summary["workflow"]["passive_source"]
    assert {"slow": str(example.passive_moments_mat), "normal": str(passive_csv)}.get(trial, "package:") in source
    assert gen.summary["workflow"]["name"] == "effort-gen" and ten.summary["workflow"]["name"] == "effort-ten"
    # model parameters as in the study's table
    for sol in (gen, cal, ten):
        p = sol.summary["parameters"]["soleus_r"]
        assert p["F0_N"] == pytest.approx(5978.474277, rel=1e-6)
        assert p["vmax_lMo_per_s"] == 10


def _stance_mean(sol, muscles, start=0.20, end=0.50):
    """Mean normalised fiber length over a share of the gait cycle.

    The IK window holds one cycle plus 5 frames (50 ms) at each end (data.md §2.3).
    """
    t0, tf = sol.time_s[0] + 0.05, sol.time_s[-1] - 0.05
    sel = (sol.time_s >= t0 + start * (tf - t0)) & (sol.time_s <= t0 + end * (tf - t0))
    return {m: sol.lm_norm[sel, sol.muscles.index(m)] for m in muscles}


@pytest.mark.opensim
@pytest.mark.slow
def test_compliant_tendons_shorten_plantarflexor_fibers(solved):
    """What the reproduction shows (normal trial, 40-60 % of the cycle, push-off).

    With the stiffer generic tendon (kT = 35) the triceps-surae fibers stay long (above 1.05),
    with the personalised compliant tendon (kT = 10.6) the tendon takes up more of the
    muscle-tendon length and the fibers are shorter.
    """
    gen, _ = solved("normal", "effort-gen")
    ten, _ = solved("normal", "effort-ten")
    lg = _stance_mean(gen, TRICEPS_SURAE, 0.40, 0.55)
    lt = _stance_mean(ten, TRICEPS_SURAE, 0.40, 0.55)
    for m in TRICEPS_SURAE:
        assert np.mean(lt[m]) < np.mean(lg[m]) - 0.05, m
    assert np.all(lg["soleus_r"] > 1.05)


# --------------------------------------------------------------------------- files
@pytest.mark.opensim
@pytest.mark.slow
def test_solution_record_round_trip(solved, tmp_path):
    """A solution written and loaded gives back its record (the typed entries of ``summary.json``,
    exactly the dictionary of the file) and its arrays (to the file's 12 digits); written again,
    both files are the same bytes. The record's reserve statistics are those of the arrays."""
    from musclemetab.redundancy import Solution

    sol, folder = solved("normal", "effort-gen")
    back = Solution.load(folder)
    assert back.record == sol.file_record()
    assert back.record.to_dict() == json.loads((folder / "summary.json").read_text())
    rec = back.record
    assert rec.success and rec.status == "Solve_Succeeded" and rec.side == "r"
    assert rec.muscles == tuple(sol.muscles) and rec.dofs == tuple(DOFS) and rec.n_intervals == sol.time_s.size - 1
    assert rec.time_window_s == pytest.approx([0.57, 1.75]) and rec.workflow_name == "effort-gen"
    assert rec.run_record.iterations == rec.iterations > 0
    for f in ("time_s", "excitation", "activation", "lm_norm", "fiber_velocity_lmo_per_s", "tendon_force_N",
              "active_fiber_force_N", "passive_fiber_force_N", "reserve_Nm"):
        a, b = getattr(back, f), getattr(sol, f)
        np.testing.assert_allclose(a, b, rtol=1e-11, atol=1e-11 * np.max(np.abs(b)), err_msg=f)
    # reserves (nodes 0..N-1) worked from the arrays
    rms = np.sqrt(np.mean(sol.reserve_Nm[:-1] ** 2, axis=0))
    assert [rec.reserve_rms_Nm[d] for d in sol.dofs] == pytest.approx(rms, rel=1e-9)
    assert rec.reserve_max_abs_Nm == pytest.approx(dict(zip(sol.dofs, np.max(np.abs(sol.reserve_Nm), axis=0))),
                                                   rel=1e-9)
    assert rec.large_reserve is False and rec.reserve_share_of_peak_moment < 0.01
    again = back.write(tmp_path / "again")
    for name in ("solution.sto", "summary.json"):
        assert (again / name).read_bytes() == (folder / name).read_bytes(), name


@pytest.mark.opensim
@pytest.mark.slow
def test_solution_files(solved):
    from musclemetab.io import read_storage

    sol, folder = solved("normal", "effort-gen")
    assert sorted(p.name for p in folder.iterdir()) == [".musclemetab-files", "controls.sto", "forces.sto", "model.osim",
                                                        "solution.sto", "states.sto", "summary.json"]  # docs/opensim_files.md
    df = read_storage(folder / "solution.sto")
    assert df.attrs["in_degrees"] is False
    quantities = ("excitation", "activation", "normalized_fiber_length", "normalized_fiber_velocity",
                  "tendon_force", "active_fiber_force", "passive_fiber_force",
                  "active_force_length_multiplier", "force_velocity_multiplier")
    expected = [f"/forceset/{m}/{q}" for q in quantities for m in sol.muscles] + [f"/forceset/reserve_{d}" for d in DOFS]
    assert sorted(df.columns) == sorted(expected)
    summary = json.loads((folder / "summary.json").read_text())
    for key in ("status", "objective", "iterations", "solve_time_s", "max_moment_residual_Nm", "reserve_rms_Nm",
                "muscles", "dofs", "parameters", "time_window_s", "n_intervals", "workflow"):
        assert key in summary
    assert summary["time_window_s"] == pytest.approx([0.57, 1.75])
    assert set(summary["parameters"]["soleus_r"]) == {"F0_N", "lMo_m", "lTs_m", "alpha0_rad", "vmax_lMo_per_s",
                                                      "kT", "kPE", "s0", "sM"}
    # normalised fiber velocity is OpenSim's v/(lMo vmax): within [-1, 1]
    v = df[[f"/forceset/{m}/normalized_fiber_velocity" for m in sol.muscles]].to_numpy()
    assert np.max(np.abs(v)) <= 1 + 1e-9


@pytest.mark.opensim
@pytest.mark.slow
def test_solution_sto_opens_in_opensim(solved):
    """OpenSim reads solution.sto (in a separate process: opensim and casadi cannot share one)."""
    sol, folder = solved("normal", "effort-gen")
    code = ("import sys, opensim; t = opensim.TimeSeriesTable(sys.argv[1]); "
            "print(t.getNumRows(), t.getNumColumns(), t.getColumnLabel(0))")
    out = subprocess.run([sys.executable, "-c", code, str(folder / "solution.sto")],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    rows, cols, first = out.stdout.split()[-3:]
    assert int(rows) == sol.time_s.size and int(cols) == 9 * 40 + 5
    assert first.startswith("/forceset/")


# --------------------------------------------------------------------------- input stage
@pytest.mark.opensim
def test_solve_files_reads_each_input_once_and_hands_on_the_same_arrays(example, geometries, geometry_cache,
                                                                         monkeypatch):
    """``solve_files`` parses the IK and the ID file once each; what it hands to the solver is
    what the readers give when each reads its file by path."""
    import collections
    import inspect

    import musclemetab.io as mio
    import musclemetab.io.storage as storage
    import musclemetab.redundancy.problem as problem
    import musclemetab.redundancy.run as run
    from musclemetab.redundancy.inputs import read_inverse_dynamics, read_kinematics

    parses = collections.Counter()
    read = storage.read_table

    def counting_read(path):
        parses[Path(path).name] += 1
        return read(path)

    handed = {}

    class Handed(Exception):
        pass

    def capture(geometry, params, id_time, id_moments, **kwargs):
        handed.update(geometry=geometry, id_time=id_time, id_moments=id_moments, ik_time=kwargs["ik_time_s"])
        raise Handed

    monkeypatch.setattr(storage, "read_table", counting_read)
    monkeypatch.setattr(mio, "read_table", counting_read)
    monkeypatch.setattr(problem, "solve_with_parameters", capture)
    with pytest.raises(Handed):  # the memo of the test run wraps solve_files: call the function itself
        inspect.unwrap(run.solve_files)(example.model, example.ik["normal"], example.id["normal"],
                                          cache_dir=geometry_cache)
    assert parses == {example.ik["normal"].name: 1, example.id["normal"].name: 1}
    monkeypatch.undo()
    ik_time, _ = read_kinematics(example.ik["normal"], DOFS)
    id_time, id_moments = read_inverse_dynamics(example.id["normal"], DOFS)
    np.testing.assert_array_equal(handed["ik_time"], ik_time)
    np.testing.assert_array_equal(handed["id_time"], id_time)
    np.testing.assert_array_equal(handed["id_moments"], id_moments)
    geometry = geometries["normal"]
    assert tuple(handed["geometry"].muscles) == tuple(geometry.muscles)
    np.testing.assert_array_equal(handed["geometry"].lmt_m, geometry.lmt_m)
    np.testing.assert_array_equal(handed["geometry"].moment_arms_m, geometry.moment_arms_m)


# --------------------------------------------------------------------------- failures
@pytest.mark.opensim
def test_unconverged_solve_is_reported_not_hidden(example, geometry_cache, tmp_path, capsys):
    from musclemetab.commands import main
    from musclemetab.errors import SolverError
    from musclemetab.redundancy import Solution

    out = tmp_path / "out"
    code = main(["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]),
                 "--id", str(example.id["normal"]), "--cache-dir", str(geometry_cache),
                 "--max-iter", "3", "--out", str(out)])
    assert code == 1
    err = capsys.readouterr().err
    assert "did not converge" in err and "Maximum_Iterations_Exceeded" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["success"] is False and summary["status"] == "Maximum_Iterations_Exceeded"
    with pytest.raises(SolverError, match="did not succeed"):
        Solution.load(out)
    assert Solution.load(out, require_success=False).status == "Maximum_Iterations_Exceeded"


@pytest.mark.opensim
@pytest.mark.slow
def test_warm_start_option_reaches_the_same_optimum(example, geometry_cache, solved, tmp_path):
    """--warm-start (an option for speed): EFFORT-TEN of the normal trial from EFFORT-GEN, both
    with the study's stop, as the cold solves of this module."""
    from musclemetab.commands import main
    from musclemetab.redundancy import Solution

    _, gen_dir = solved("normal", "effort-gen")
    cold, _ = solved("normal", "effort-ten")
    out = tmp_path / "warm"
    assert main(["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]),
                 "--id", str(example.id["normal"]), "--workflow", "effort-ten", "--cache-dir", str(geometry_cache),
                 "--tendon-stiffness", "example", "--warm-start", str(gen_dir), "--stop", "authors",
                 "--out", str(out)]) == 0
    warm = Solution.load(out)
    assert "warm start from effort-gen" in warm.summary["initial_guess"]
    assert "static optimisation" in cold.summary["initial_guess"]
    assert warm.objective == pytest.approx(cold.objective, rel=1e-4)
    assert warm.summary["max_moment_residual_Nm"] < 1e-4


@pytest.mark.opensim
@pytest.mark.slow
def test_problems_of_one_structure_share_their_functions(solved):
    """The per-interval functions (the symbolic derivatives) are built once per process for
    problems of one structure, the whole symbolic NLP once for problems of one structure and
    mesh: the fast trial's EFFORT-CAL problem, built after the normal trial's EFFORT-GEN problem
    (other mesh, data, passive parameters), reuses the normal trial's per-interval functions
    with its own values, and its NLP (objective, constraints and their derivatives at the initial
    guess, random multipliers) equals the one built afresh; the fast trial's EFFORT-GEN problem
    reuses the whole NLP of its EFFORT-CAL problem with its own values. Other goals build their own."""
    import dataclasses

    from musclemetab.redundancy import transcription as tr
    from musclemetab.redundancy.sensitivity import problem_of_solution
    from musclemetab.redundancy.static_opt import guess_from_solution

    def problem(trial, workflow, **goals):
        prob = problem_of_solution(solved(trial, workflow)[1])
        params = prob.params.subset(prob.inputs.muscles)
        guess = guess_from_solution(prob.solution, prob.inputs, params)
        return tr.build_problem([tr.TrialBlock("t", prob.inputs, guess)], params,
                                dataclasses.replace(prob.goals, **goals))

    def values(nlp):
        x, p = nlp["x0"], nlp["p_values"]
        lam = np.random.default_rng(1).normal(size=nlp["lbg"].size)
        f, grad = nlp["grad_f"](x, p)
        g, jac = nlp["jac_g"](x, p)
        hess = nlp["hess_lag"](x, p, 1.0, lam)
        return [np.asarray(v).ravel() for v in (f, grad, g)] + [np.asarray(m.nonzeros()) for m in (jac, hess)]

    def built():  # (per-interval functions, whole NLPs) built, and reused
        a, b = tr._shared_group_functions.cache_info(), tr.symbolic_problem.cache_info()
        return (a.misses, b.misses), (a.hits, b.hits)

    def clear():
        tr._shared_group_functions.cache_clear()
        tr.symbolic_problem.cache_clear()

    for pair in (("normal", "effort-gen"), ("fast", "effort-cal"), ("fast", "effort-gen")):
        solved(*pair)  # the solves first: they build problems too
    clear()
    problem("normal", "effort-gen")
    shared = values(problem("fast", "effort-cal"))
    assert built() == ((1, 2), (1, 0))
    gen = values(problem("fast", "effort-gen"))  # the fast trial's mesh again: its NLP, other values
    assert built() == ((1, 2), (1, 1))
    assert not np.array_equal(gen[2], shared[2])  # the passive curves differ
    clear()
    fresh = values(problem("fast", "effort-cal"))
    assert built() == ((1, 1), (0, 0))
    for a, b in zip(shared, fresh, strict=True):
        np.testing.assert_array_equal(a, b)
    problem("fast", "effort-gen", w_reserve=500.0)  # other goals: other functions
    assert built() == ((2, 2), (0, 0))


@pytest.mark.opensim
@pytest.mark.filterwarnings("ignore:trial IK_sub1_normal. psoas_r about hip_rotation_r moment arm vanishes")
def test_problems_of_one_size_share_their_solver(example, geometry_cache):
    """Problems of one structure and mesh (0.3 s of the normal trial: its EFFORT-CAL and
    EFFORT-TEN, other muscle values) share their NLP and IPOPT's solver object within a process.
    The solver that has just solved EFFORT-CAL, given EFFORT-TEN's values, gives the solution a
    new solver gives: the same iterations, objective and states."""
    from musclemetab.redundancy import ipopt
    from musclemetab.redundancy import run

    solve = getattr(run.solve_files, "__wrapped__", run.solve_files)  # not the test run's store of solves
    files = (example.model, example.ik["normal"], example.id["normal"])
    kw = dict(window=(0.6, 0.9), cache_dir=geometry_cache)
    ipopt._shared_solver.cache_clear()
    cal = solve(*files, "effort-cal", **kw)
    ten = solve(*files, "effort-ten", tendon_stiffness="example", **kw)
    assert ipopt._shared_solver.cache_info().hits == 1
    ipopt._shared_solver.cache_clear()
    fresh = solve(*files, "effort-ten", tendon_stiffness="example", **kw)
    assert ipopt._shared_solver.cache_info().hits == 0
    assert cal.success and ten.success and fresh.success
    assert abs(ten.objective - cal.objective) > 1e-3 * cal.objective  # two problems, not one answer twice
    assert ten.record.iterations == fresh.record.iterations
    assert ten.objective == pytest.approx(fresh.objective, rel=1e-12)
    for name in ("activation", "lm_norm", "excitation", "reserve_Nm"):
        np.testing.assert_allclose(getattr(ten, name), getattr(fresh, name), rtol=0, atol=1e-9, err_msg=name)
