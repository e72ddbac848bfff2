"""Parameter estimation with the problem core: recovery of known changes from fiber lengths.

"Measured" fiber lengths are made by solving the normal trial up to 1.3 s (the right leg's stance,
push-off and toe-off at 1.28 s: an IK file of those rows, ``stance_ik``) with EFFORT-CAL goals and the optimal
fiber length of tibialis anterior and biceps femoris long head x1.10 and the tendon stiffness of the
triceps surae x0.5; the factors are then estimated back from those fiber lengths with the
unchanged model.

Fiber lengths alone identify the tendon stiffness (with the fiber length and the muscle-tendon
length, the tendon length and hence the tendon force follow, and the moments must be met) but
hardly the optimal fiber length: for any lMo the measured fiber length gives the same tendon
force and the activation absorbs the change of fL(lM/lMo); only the effort tells the factors apart
(the fiber-only estimate ends at about 1.06 and 1.12). Adding the excitations of the generating
solve as EMG of the two muscles (tracked, scale fixed at 1) pins the activation, and the
force-length relation then gives lMo. Tolerances: kT 1 %, lMo 2 % (at the true factors the
tracking errors are zero and the effort is that of the generating solve; the estimate moves away
only as far as lowering the effort pays against the tracking costs, weights 100 and 10).

The doubts of the estimates (``docs/problem.md``): with lTs estimated beside lMo the two are not
identifiable together (correlation above the threshold at the optimum, warned), a factor bounded
away from its truth ends on the bound (warned), a factor no measurement informs is refused, and
the validation re-solve's fit is checked against a hand computation; the reduced-Hessian
algebra on a least-squares problem whose answer is known in closed form.
"""

from __future__ import annotations

import numpy as np
import pytest
from mrs_reference import DOFS

TS = ("soleus_r", "gasmed_r", "gaslat_r")
LMO = ("tibant_r", "bflh_r")


@pytest.fixture(scope="module")
def stance_ik(example, tmp_path_factory):
    """The normal trial's IK up to 1.3 s (the right leg's stance, push-off and toe-off): the
    estimates solve the whole IK file, this one is 62 % of the trial."""
    from musclemetab.io import read_storage, write_storage

    full = read_storage(example.ik["normal"])
    return write_storage(tmp_path_factory.mktemp("stance") / "ik_stance_r.mot", full[full.index <= 1.3], name="ik",
                         in_degrees=True)


@pytest.fixture(scope="module")
def generated(example, stance_ik, geometry_cache):
    """The generating solve with the changed parameters and the unchanged model's trial (its
    geometry from the test run's cache: OpenSim once per trial)."""
    from musclemetab.geometry import compute_geometry
    from musclemetab.model import read_muscle_parameters
    from musclemetab.redundancy import SolverOptions
    from musclemetab.redundancy.inputs import read_inverse_dynamics, read_kinematics
    from musclemetab.redundancy.solve import prepare_trial, solve_with_parameters
    from musclemetab.redundancy.static_opt import initial_guess
    from musclemetab.redundancy.workflows import get_workflow, workflow_parameters

    g = compute_geometry(example.model, stance_ik, dofs=list(DOFS), cache_dir=geometry_cache)
    t_ik, _ = read_kinematics(stance_ik, DOFS)
    t_id, mom = read_inverse_dynamics(example.id["normal"], DOFS)
    wf = get_workflow("effort-cal")
    options = SolverOptions()
    nominal, _ = workflow_parameters(wf, read_muscle_parameters(example.model), g.muscles)
    i = {m: nominal.names.index(m) for m in (*TS, *LMO)}
    truth = nominal.replace(optimal_fiber_length_m={m: 1.10 * nominal.optimal_fiber_length_m[i[m]] for m in LMO},
                            tendon_stiffness={m: 0.5 * nominal.tendon_stiffness[i[m]] for m in TS})
    made = solve_with_parameters(g, truth, t_id, mom, ik_time_s=t_ik, options=options, goals=wf.goals)
    assert made.success
    lmo_true = dict(zip(truth.names, truth.optimal_fiber_length_m))
    measured = {m: (made.time_s, made.lm_norm[:, made.muscles.index(m)] * lmo_true[m]) for m in (*LMO, *TS)}
    inputs, params, so = prepare_trial(g, nominal, t_id, mom, ik_time_s=t_ik, options=options)
    return made, measured, inputs, params, initial_guess(inputs, params, so), options, wf, nominal


def _estimate(generated, with_emg: bool):
    from musclemetab.redundancy.transcription import Goals, ParameterSpec
    from musclemetab.redundancy.estimate import estimate_parameters, fiber_length_trial, parameter_specs

    made, measured, inputs, params, guess, options, wf, _ = generated
    N = inputs.n_intervals
    emg = {}
    specs = parameter_specs({"optimal_fiber_length": LMO, "tendon_stiffness": TS}, couple=[TS])
    if with_emg:
        emg = dict(emg_muscles=LMO, emg_nodes=made.excitation[:N, [made.muscles.index(m) for m in LMO]])
        specs.append(ParameterSpec("emg_scale", LMO, (1.0, 1.0)))
    trial = fiber_length_trial("normal", inputs, guess, measured, **emg)
    goals = Goals(**wf.goals.effort_weights(), w_fiber_length=100.0, w_emg=10.0 if with_emg else 0.0)
    return estimate_parameters([trial], params, specs, goals, options=options)


@pytest.fixture(scope="module")
def fiber_only(generated):
    return _estimate(generated, with_emg=False)


@pytest.fixture(scope="module")
def recovery(generated):
    res, est = _estimate(generated, with_emg=True)
    return res, est, generated[7], generated[0]


@pytest.mark.opensim
@pytest.mark.slow
def test_tendon_stiffness_recovered_from_fiber_lengths_alone(fiber_only):
    res, est = fiber_only
    assert res.success, res.status
    ts = [est.factors["tendon_stiffness"][m] for m in TS]
    assert np.ptp(ts) < 1e-9 and ts[0] == pytest.approx(0.5, rel=0.01)


@pytest.mark.opensim
@pytest.mark.slow
def test_parameters_recovered_from_fiber_lengths_and_emg(recovery):
    res, est, nominal, made = recovery
    assert res.success, res.status
    f = est.factors
    print("recovered factors:", f)
    for m in LMO:
        assert f["optimal_fiber_length"][m] == pytest.approx(1.10, rel=0.02), m
    ts = [f["tendon_stiffness"][m] for m in TS]
    assert np.ptp(ts) < 1e-9  # one coupled factor
    assert ts[0] == pytest.approx(0.5, rel=0.01)
    # the estimated parameters are the nominal ones scaled by the factors
    values = est.values()
    for m in LMO:
        j = nominal.names.index(m)
        assert values["optimal_fiber_length"][m] == pytest.approx(
            f["optimal_fiber_length"][m] * nominal.optimal_fiber_length_m[j], rel=1e-12)
    p = est.parameters()
    assert p.tendon_stiffness[p.names.index("soleus_r")] == pytest.approx(ts[0] * 35.0, rel=1e-12)
    # the tracked fiber lengths are reproduced (RMS error below 1 % of lMo)
    assert res.objective_terms["normal"]["fiber_length_tracking"] / 100.0 < 1e-4
    # with lTs known the parameters are identifiable: no pair correlates above the threshold, no factor on a bound
    rep = est.doubts["identifiability"]
    assert rep["correlated_pairs"] == [] and not rep["near_singular"] and est.doubts["on_bounds"] == []
    assert rep["parameters"] == ["optimal_fiber_length:tibant_r", "optimal_fiber_length:bflh_r",
                                 "tendon_stiffness:soleus_r,gasmed_r,gaslat_r"]  # the EMG scales are held at 1


def _cli(argv):
    import contextlib
    import io

    from musclemetab.commands import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue() + err.getvalue()


def _ultrasound(example, path, scale_mm=1.0):
    import pandas as pd

    from musclemetab.io import read_storage, write_storage

    t = read_storage(example.ik["normal"]).index
    df = pd.DataFrame({"soleus_r": np.full(len(t), 40.0 * scale_mm), "gasmed_r": np.full(len(t), 55.0 * scale_mm)},
                      index=t)
    write_storage(path, df, in_degrees=False)
    return path


@pytest.mark.opensim
def test_estimate_command_records_a_stopped_solve(example, tmp_path, monkeypatch, builder_entries):
    """Plumbing of ``musclemetab estimate`` (3 iterations): the solutions and parameters.json are
    written with IPOPT's status, no personalised model, no OpenSim files (no solution to
    reproduce), exit status 1 with one line; IPOPT's progress lines while it runs (the
    throttle at 0 s: one per iterate, the starting point and the 3 iterations)."""
    import json
    import re

    import musclemetab.redundancy.progress as progress

    monkeypatch.setattr(progress, "PROGRESS_INTERVAL_S", 0.0)
    us = _ultrasound(example, tmp_path / "us.mot")
    out = tmp_path / "est"
    code, text = _cli(["estimate", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
                       str(example.id["normal"]), "--ultrasound", str(us), "--estimate",
                       "tendon_stiffness=soleus_r,gasmed_r", "--couple", "soleus_r,gasmed_r", "--max-iter", "3",
                       "--labels", "normal", "--out", str(out)])
    assert code == 1 and "Maximum_Iterations_Exceeded" in text and "after 3 iterations" in text
    doc = json.loads((out / "parameters.json").read_text())
    assert doc["solve"]["status"] == "Maximum_Iterations_Exceeded" and doc["solve"]["success"] is False
    f = doc["factors"]["tendon_stiffness"]
    assert set(f) == {"soleus_r", "gasmed_r"} and f["soleus_r"] == f["gasmed_r"]  # coupled
    # the trial's record: the builder's entries, in the order of before one builder made them
    assert builder_entries(json.loads((out / "normal" / "summary.json").read_text())) == builder_entries.before["estimate"]
    assert not list(out.glob("*_personalised.osim")) and not (out / "normal" / "model.osim").exists()
    assert re.findall(r"^musclemetab: solving: iteration (\d+), ", text, flags=re.M) == ["0", "1", "2", "3"]


def test_estimate_command_bad_input(example, tmp_path):
    us = _ultrasound(example, tmp_path / "us_m.mot", scale_mm=1e-3)  # metres, not mm
    base = ["estimate", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
            str(example.id["normal"]), "--out", str(tmp_path / "o")]
    code, text = _cli(base + ["--ultrasound", str(us), str(us), "--estimate", "tendon_stiffness=soleus_r"])
    assert code == 1 and "--ultrasound" in text and "one of each per trial" in text
    code, text = _cli(base + ["--ultrasound", str(us), "--estimate", "stiffness=soleus_r"])
    assert code == 1 and "stiffness" in text and "tendon_stiffness" in text
    code, text = _cli(base + ["--ultrasound", str(us), "--estimate", "tendon_stiffness=soleus_r"])
    assert code == 1 and "us_m.mot" in text and "mm" in text
    assert not (tmp_path / "o").exists()


@pytest.mark.opensim
@pytest.mark.slow
def test_estimate_command_with_emg_recovers_the_parameters(example, stance_ik, generated, recovery, tmp_path):
    """``musclemetab estimate --ultrasound ... --emg ...``: the recovery problem above from files
    (fiber lengths in mm, the generating excitations as EMG channels TA and BF, scale fixed at 1):
    the same factors as the Python path, hence the known changes, and the EMG written beside them."""
    import json

    import pandas as pd

    from musclemetab.io import write_storage

    made, measured, inputs, params, *_ = generated
    _, est, _, _ = recovery
    N = inputs.n_intervals
    us = pd.DataFrame({m: 1000.0 * lm for m, (_, lm) in measured.items()}, index=made.time_s)
    write_storage(tmp_path / "us.mot", us, in_degrees=False)
    exc = made.excitation[:N, [made.muscles.index(m) for m in LMO]]
    exc = np.vstack([exc, exc[-1]])  # the file covers the window; the last node has no control
    emg = pd.DataFrame({"TA": exc[:, 0], "BF": exc[:, 1]}, index=made.time_s)
    write_storage(tmp_path / "emg.mot", emg, in_degrees=False)
    (tmp_path / "map.json").write_text(json.dumps({"tibant_r": ["TA"], "bflh_r": ["BF"]}))
    out = tmp_path / "est"
    code, text = _cli(["estimate", "--model", str(example.model), "--ik", str(stance_ik), "--id",
                       str(example.id["normal"]), "--ultrasound", str(tmp_path / "us.mot"), "--emg",
                       str(tmp_path / "emg.mot"), "--emg-mapping", str(tmp_path / "map.json"), "--emg-mode",
                       "tracking", "--emg-scale-bounds", "1:1", "--estimate", "optimal_fiber_length=tibant_r,bflh_r",
                       "tendon_stiffness=soleus_r,gasmed_r,gaslat_r", "--couple",
                       "tendon_stiffness:soleus_r,gasmed_r,gaslat_r", "--validate", "--labels", "normal",
                       "--out", str(out)])
    assert code == 0, text
    doc = json.loads((out / "parameters.json").read_text())
    for kind, by in est.factors.items():
        for m, v in by.items():
            assert doc["factors"][kind][m] == pytest.approx(v, rel=1e-5), (kind, m)
    for m in LMO:
        assert doc["factors"]["optimal_fiber_length"][m] == pytest.approx(1.10, rel=0.02), m
    assert doc["factors"]["tendon_stiffness"]["soleus_r"] == pytest.approx(0.5, rel=0.01)
    assert doc["emg"]["mode"] == "tracking" and doc["emg"]["tolerance"] is None and doc["emg"]["weight"] == 10.0
    assert doc["emg"]["scale"] == {"bflh_r": 1.0, "tibant_r": 1.0}
    assert doc["emg"]["bounds"] == [1.0, 1.0]  # --emg-scale-bounds 1:1 (as --bounds emg_scale=1:1)
    assert doc["emg"]["mapping"] == {"tibant_r": ["TA"], "bflh_r": ["BF"]}
    assert (out / "normal" / "summary.json").is_file() and list(out.glob("*_personalised.osim"))
    # the OpenSim files of a solve folder, in the trial's folder and its validation's: the model
    # carries the solution's (estimated) optimal fiber lengths
    import xml.etree.ElementTree as ET

    from musclemetab.redundancy.export import OPENSIM_FILES
    from musclemetab.redundancy.solution import Solution

    for folder in (out / "normal", out / "validation" / "normal"):
        assert all((folder / f).is_file() for f in OPENSIM_FILES), folder
        sol = Solution.load(folder)
        lmo = dict(zip(sol.parameters.names, sol.parameters.optimal_fiber_length_m))
        muscles = {m.get("name"): m for m in ET.parse(folder / "model.osim").iter("DeGrooteFregly2016Muscle")}
        for m in LMO:
            assert float(muscles[m].findtext("optimal_fiber_length")) == pytest.approx(lmo[m], rel=1e-9), (folder, m)
    # the validation re-solve's fit, against the measurements at its nodes 0 ... N-1 by hand
    from musclemetab.redundancy.solution import Solution

    val = Solution.load(out / "validation" / "normal")
    lmo = dict(zip(val.parameters.names, val.parameters.optimal_fiber_length_m))
    fit = doc["validation"]["normal"]
    for m, (_, lm) in measured.items():
        model, meas = val.lm_norm[:N, val.muscles.index(m)] * lmo[m], lm[:N]
        rms_mm = 1000.0 * np.sqrt(sum((a - b) ** 2 for a, b in zip(model, meas)) / N)
        dm, dd = model - model.mean(), meas - meas.mean()
        r = float(np.sum(dm * dd) / np.sqrt(np.sum(dm**2) * np.sum(dd**2)))
        # (the solution file holds 10 significant digits)
        assert fit["fiber_length"][m]["rms_mm"] == pytest.approx(rms_mm, rel=1e-6), m
        assert fit["fiber_length"][m]["r"] == pytest.approx(r, rel=1e-6), m
        assert f"{m} RMS {rms_mm:.3g} mm r {r:.2f}" in text
    for j, m in enumerate(LMO):
        e = val.excitation[:N, val.muscles.index(m)]
        assert fit["emg"][m]["rms"] == pytest.approx(np.sqrt(np.mean((e - exc[:N, j]) ** 2)), rel=1e-6), m
    assert "standard errors: optimal_fiber_length:tibant_r" in text
    # a misfit beyond the limits is a warning line, recorded and printed
    from musclemetab.redundancy.identifiability import VALIDATION_MIN_R, VALIDATION_RMS_MM, validation_warnings

    assert doc["validation_warnings"] == validation_warnings(doc["validation"])
    for m, v in fit["fiber_length"].items():
        warned = f"warning: validation of normal: the fiber length of {m} misfits its ultrasound" in text
        assert warned == (v["rms_mm"] > VALIDATION_RMS_MM or v["r"] < VALIDATION_MIN_R), m
    # the folder read back as a Result, and written again: the same files
    from musclemetab.redundancy import Result

    result = Result.load(out)
    assert result.labels == ("normal",) and result.settings is None
    assert result.factors == {**doc["factors"], "emg_scale": doc["emg"]["scale"]}
    assert result.emg_channels == doc["emg"]["mapping"]
    again = result.write(tmp_path / "again")
    assert json.loads((again / "parameters.json").read_text()) == doc
    for name in ("solution.sto", "summary.json"):
        assert (again / "normal" / name).read_bytes() == (out / "normal" / name).read_bytes(), name
    # the fiber-length bounds, recorded as a single-trial solve records them; those of the muscles whose lMo is
    # estimated are taken at the factor's lower bound 0.5 (lMo and w halved): the longest rigid-tendon fiber,
    # max sqrt((lMT - lTs)^2 + w^2) / lMo over the mesh nodes, plus 0.05 where that exceeds 1.7
    bounds = json.loads((out / "normal" / "summary.json").read_text())["fiber_length_bounds"]
    p = params.subset(inputs.muscles)
    scale = np.array([0.5 if m in LMO else 1.0 for m in inputs.muscles])
    lmo, w = scale * p.optimal_fiber_length_m, scale * p.optimal_fiber_length_m * np.sin(p.pennation_angle_at_optimal_rad)
    rigid = np.max(np.sqrt((inputs.lmt_m - p.tendon_slack_length_m) ** 2 + w**2), axis=0) / lmo + 0.05
    widened = {m: float(b) for m, b in zip(inputs.muscles, rigid) if b > 1.7}
    assert bounds["default"] == [0.1, 1.7] and set(bounds["widened_upper"]) == set(widened) == set(LMO)
    for m, b in widened.items():
        assert bounds["widened_upper"][m] == pytest.approx(b, rel=1e-9), m


def test_estimate_command_emg_input_errors(example, tmp_path):
    base = ["estimate", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
            str(example.id["normal"]), "--estimate", "tendon_stiffness=soleus_r", "--out", str(tmp_path / "o")]
    code, text = _cli(base)
    assert code == 1 and "--ultrasound" in text and "--emg" in text
    code, text = _cli(base + ["--emg", str(example.emg["normal"]), str(example.emg["normal"])])
    assert code == 1 and "--emg" in text and "one of each per trial" in text
    us = _ultrasound(example, tmp_path / "us.mot")
    code, text = _cli(base + ["--ultrasound", str(us), "--emg-mode", "driven"])
    assert code == 1 and "--emg-mode" in text and "--emg files" in text
    code, text = _cli(base + ["--emg", str(example.emg["normal"]), "--bounds", "emg=1:1"])
    assert code == 1 and "'emg'" in text and "emg_scale" in text
    code, text = _cli(base + ["--emg", str(example.emg["normal"]), "--emg-scale-bounds", "2:1"])
    assert code == 1 and "--emg-scale-bounds" in text and "0 < LOW <= HIGH" in text
    code, text = _cli(base + ["--emg", str(example.emg["normal"]), "--emg-scale-bounds", "0.01:5", "--bounds",
                              "emg_scale=1:1"])
    assert code == 1 and "--emg-scale-bounds and --bounds emg_scale" in text
    code, text = _cli(base + ["--ultrasound", str(us), "--emg-scale-bounds", "0.01:5"])
    assert code == 1 and "--emg-scale-bounds" in text and "--emg files" in text
    code, text = _cli(["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
                       str(example.id["normal"]), "--emg-scale-bounds", "0.01:5", "--out", str(tmp_path / "o")])
    assert code == 1 and "--emg-scale-bounds needs EMG" in text
    assert not (tmp_path / "o").exists()


@pytest.mark.opensim
@pytest.mark.slow
def test_estimate_command_on_the_left_leg_recovers_the_tendon_stiffness(example, geometry_cache, tmp_path):
    """``musclemetab estimate --side l``: fiber lengths made by solving the example's left leg
    (its DOFs discovered from the model and the ID file) with the triceps surae's tendon
    stiffness x0.5 give that factor back (1 %, as on the right leg). The estimate solves the
    whole IK file: the normal trial's IK from 1.35 s on (the left leg's push-off, its ankle
    moment rising to 59 N m), a third of the trial."""
    import json

    import pandas as pd

    from musclemetab.geometry import compute_geometry
    from musclemetab.io import read_storage, write_storage
    from musclemetab.layout import discover_dofs, read_layout
    from musclemetab.model import read_muscle_parameters
    from musclemetab.redundancy import SolverOptions
    from musclemetab.redundancy.inputs import read_inverse_dynamics, read_kinematics
    from musclemetab.redundancy.solve import solve_with_parameters
    from musclemetab.redundancy.workflows import get_workflow, workflow_parameters

    ts = ("soleus_l", "gasmed_l", "gaslat_l")
    idp = example.id["normal"]
    full = read_storage(example.ik["normal"])
    ik = write_storage(tmp_path / "ik_push-off_l.mot", full[full.index >= 1.35], name="ik", in_degrees=True)
    dofs = discover_dofs(read_layout(example.model), "l", list(read_storage(idp).columns))
    assert dofs and all(d.endswith("_l") for d in dofs)
    g = compute_geometry(example.model, ik, dofs=dofs, side="l", cache_dir=geometry_cache)
    t_ik, _ = read_kinematics(ik, dofs)
    t_id, mom = read_inverse_dynamics(idp, dofs)
    wf = get_workflow("effort-gen")
    nominal, _ = workflow_parameters(wf, read_muscle_parameters(example.model), g.muscles)
    truth = nominal.replace(tendon_stiffness={m: 0.5 * nominal.tendon_stiffness[nominal.names.index(m)] for m in ts})
    made = solve_with_parameters(g, truth, t_id, mom, ik_time_s=t_ik, options=SolverOptions(), goals=wf.goals)
    assert made.success
    lmo = dict(zip(truth.names, truth.optimal_fiber_length_m))
    us = pd.DataFrame({m: 1000.0 * made.lm_norm[:, made.muscles.index(m)] * lmo[m] for m in ts}, index=made.time_s)
    write_storage(tmp_path / "us.mot", us, in_degrees=False)
    out = tmp_path / "est"
    code, text = _cli(["estimate", "--model", str(example.model), "--ik", str(ik), "--id", str(idp), "--side", "l",
                       "--workflow", "effort-gen", "--ultrasound", str(tmp_path / "us.mot"), "--estimate",
                       "tendon_stiffness=" + ",".join(ts), "--couple", ",".join(ts), "--labels", "normal",
                       "--cache-dir", str(geometry_cache), "--out", str(out)])
    assert code == 0, text
    f = json.loads((out / "parameters.json").read_text())["factors"]["tendon_stiffness"]
    assert set(f) == set(ts)
    assert f["soleus_l"] == pytest.approx(0.5, rel=0.01)
    summary = json.loads((out / "normal" / "summary.json").read_text())
    assert summary["dofs"] == dofs


# ---------------------------------------------------------------------------- doubts of the estimates


def test_reduced_inverse_hessian_of_a_least_squares_problem():
    """``(K^-1)_pp`` at the optimum of ``min 1/2 |y - d|^2 + 1/2 z^2 + 1/2 (w - 1)^2`` subject to
    ``y = A p``, ``z >= 1`` (active) and ``y3 + w <= 100`` (inactive): the inverse of the
    reduced objective's Hessian ``A'A`` (worked by hand: the problem is ``min 1/2 |A p - d|^2``
    in ``p``), whatever the multipliers of the linear rows."""
    import scipy.sparse as sp

    from musclemetab.redundancy.identifiability import correlation, reduced_inverse_hessian

    A = np.array([[1.0, 1.0], [1.0, 1.05], [1.0, -1.0]])
    d = np.array([2.0, 2.1, 0.5])
    p = np.linalg.lstsq(A, d, rcond=None)[0]
    y = A @ p
    # variables [y1, y2, y3, p1, p2, z, w]; rows y - A p = 0 (3), y3 + w <= 100
    x = np.concatenate([y, p, [1.0, 1.0]])
    H = sp.diags([1.0, 1.0, 1.0, 0.0, 0.0, 1.0, 1.0])
    J = sp.csr_matrix(np.vstack([np.hstack([np.eye(3), -A, np.zeros((3, 2))]), [0, 0, 1, 0, 0, 0, 1]]))
    g = np.concatenate([np.zeros(3), [y[2] + 1.0]])
    lam_g = np.concatenate([-(y - d), [0.0]])  # grad f + J' lam_g + lam_x = 0
    lam_x = np.array([0, 0, 0, 0, 0, -1.0, 0])  # the bound z >= 1 pushes up
    inf = np.inf
    C, active = reduced_inverse_hessian(H, J, x, g, np.array([-inf] * 5 + [1.0, -inf]), np.array([inf] * 5 + [inf, 5]),
                                        np.array([0, 0, 0, -inf]), np.array([0, 0, 0, 100.0]), lam_g, lam_x, [3, 4])
    expected = np.linalg.inv(A.T @ A)
    np.testing.assert_allclose(C, expected, rtol=1e-9)
    assert active == {"constraint_rows": 3, "variable_bounds": 1}
    R, rcond = correlation(C)
    assert R[0, 1] == pytest.approx(expected[0, 1] / np.sqrt(expected[0, 0] * expected[1, 1]), rel=1e-9)
    ev = np.linalg.eigvalsh(R)
    assert rcond == pytest.approx(ev[0] / ev[1], rel=1e-9)


def test_kkt_system_with_dense_variables_taken_apart_solves_as_a_dense_solve():
    """``KKTSystem(..., apart=...)`` (block elimination over a Schur complement) solves ``K y = r``
    as NumPy's dense solve of the whole KKT matrix does; with a constraint row on the variables
    taken apart alone (a coupling ``p1 = p2``: the rest of ``K`` is singular) it factorises ``K``
    whole, with the same answer."""
    import scipy.sparse as sp

    from musclemetab.redundancy.identifiability import KKTSystem

    rng = np.random.default_rng(3)
    n = 12
    L = rng.standard_normal((n, n))
    H = sp.csc_matrix(L @ L.T + n * np.eye(n))
    inf = np.full(n, np.inf)
    coupling = np.eye(n)[10] - np.eye(n)[11]
    for rows, split in ((rng.standard_normal((5, n)), True), (np.vstack([rng.standard_normal((4, n)), coupling]), False)):
        J = sp.csr_matrix(rows)
        m = rows.shape[0]
        zeros = np.zeros(m)
        K = np.block([[H.toarray(), rows.T], [rows, np.zeros((m, m))]])
        r = rng.standard_normal((n + m, 3))
        whole = KKTSystem(H, J, np.zeros(n), zeros, -inf, inf, zeros, zeros, zeros, np.zeros(n))
        apart = KKTSystem(H, J, np.zeros(n), zeros, -inf, inf, zeros, zeros, zeros, np.zeros(n), apart=[10, 11])
        assert (apart._schur is not None) == split
        for system in (whole, apart):
            np.testing.assert_allclose(system.solve(r), np.linalg.solve(K, r), rtol=1e-10, atol=1e-12)


def test_factors_on_bounds_and_uninformed_factors():
    """A factor within 1e-3 of its bounds' width of a bound is on it (fixed factors are not);
    a factor is informed by its muscle's own fiber lengths or EMG, or by coupling to such a muscle."""
    import warnings
    from types import SimpleNamespace

    from musclemetab.errors import MusclemetabWarning, OptionError
    from musclemetab.redundancy.identifiability import check_informed, factors_on_bounds, uninformed_factors
    from musclemetab.redundancy.transcription import ParameterSpec

    on = factors_on_bounds({"tendon_stiffness": {"soleus_r": 0.2001, "vaslat_r": 0.21},
                            "optimal_fiber_length": {"tibant_r": 1.4999}, "emg_scale": {"tibant_r": 1.0}},
                           {"tendon_stiffness": (0.2, 2.0), "optimal_fiber_length": (0.5, 1.5), "emg_scale": (1, 1)})
    assert on == [{"kind": "tendon_stiffness", "muscle": "soleus_r", "factor": 0.2001, "bound": 0.2, "side": "lower"},
                  {"kind": "optimal_fiber_length", "muscle": "tibant_r", "factor": 1.4999, "bound": 1.5,
                   "side": "upper"}]
    trials = [SimpleNamespace(fiber_muscles=("soleus_r",), emg_muscles=()),
              SimpleNamespace(fiber_muscles=(), emg_muscles=("tibant_r",))]
    specs = [ParameterSpec("tendon_stiffness", ("soleus_r", "gasmed_r", "vaslat_r"), (0.1, 2.0), ((0, 1),)),
             ParameterSpec("optimal_fiber_length", ("tibant_r", "gasmed_r"), (0.5, 1.5))]
    assert uninformed_factors(trials, specs) == [("tendon_stiffness", "vaslat_r"), ("optimal_fiber_length", "gasmed_r")]
    with pytest.raises(OptionError, match="tendon_stiffness factor of vaslat_r.*--couple tendon_stiffness:vaslat_r"):
        check_informed(trials, specs)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert len(check_informed(trials, specs, "warn")) == 2
    assert [w.category for w in caught] == [MusclemetabWarning] * 2 and "gasmed_r" in str(caught[1].message)
    # EMG-TEN's trials (EMG alone) and its tendon groups, with their own advice
    emg_only = [SimpleNamespace(emg_muscles=("gaslat_r", "soleus_r"))]
    kt = ParameterSpec("tendon_stiffness", ("vaslat_r", "vasmed_r", "soleus_r", "gasmed_r"), (0.1, 1.2),
                       ((0, 1), (2, 3)))
    with pytest.raises(OptionError, match="vaslat_r is informed by no measurement.*map EMG to vaslat_r"):
        check_informed(emg_only, [kt], remedy="map EMG to {muscle}")


def test_couplings_per_parameter_kind():
    """``--couple tendon_stiffness:soleus_r,gasmed_r`` couples that kind alone; a plain group every kind."""
    from musclemetab.errors import OptionError
    from musclemetab.redundancy.estimate import emg_couplings, parameter_specs, parse_coupling

    est = {"tendon_stiffness": ["soleus_r", "gasmed_r", "gaslat_r"], "optimal_fiber_length": ["soleus_r", "gasmed_r"]}
    specs = parameter_specs(est, [parse_coupling("tendon_stiffness:soleus_r,gasmed_r,gaslat_r")])
    assert [(s.kind, s.couplings) for s in specs] == [("tendon_stiffness", ((0, 1), (1, 2))),
                                                      ("optimal_fiber_length", ())]
    specs = parameter_specs(est, [parse_coupling("soleus_r,gasmed_r")])
    assert [s.couplings for s in specs] == [((0, 1),), ((0, 1),)]
    assert parse_coupling("emg_scale:vaslat_r,vasmed_r") == {"kind": "emg_scale", "muscles": ["vaslat_r", "vasmed_r"]}
    assert emg_couplings([{"kind": "emg_scale", "muscles": ["vaslat_r", "vasmed_r"]}, ["a", "b"]]) == [
        ("vaslat_r", "vasmed_r")]
    with pytest.raises(OptionError, match="optimal_fiber_length of gaslat_r is not estimated"):
        parameter_specs(est, [parse_coupling("optimal_fiber_length:soleus_r,gaslat_r")])
    with pytest.raises(OptionError, match="stiffness"):
        parameter_specs(est, [parse_coupling("stiffness:soleus_r,gasmed_r")])
    # the study file's equivalent: a {kind, muscles} table among the muscle lists
    from musclemetab.study.estimation import estimate_spec

    spec = estimate_spec({"estimate": est, "couple": [["soleus_r", "gasmed_r"], {
        "kind": "tendon_stiffness", "muscles": ["soleus_r", "gasmed_r", "gaslat_r"]}]}, "study.toml")
    assert [s.couplings for s in parameter_specs(spec.estimate, spec.couple)] == [((0, 1), (1, 2)), ((0, 1),)]
    assert spec.to_dict()["couple"] == [["soleus_r", "gasmed_r"], {"kind": "tendon_stiffness",
                                                                  "muscles": ["soleus_r", "gasmed_r", "gaslat_r"]}]
    with pytest.raises(OptionError, match="study.toml.*'couple' table"):
        estimate_spec({"estimate": est, "couple": [{"kind": "stiffness", "muscles": ["soleus_r"]}]}, "study.toml")


def test_a_factor_no_measurement_informs_is_refused(generated):
    """Tendon stiffness of vastus lateralis with fiber lengths of the soleus alone: refused
    before the solve, naming the muscle and the coupling that would inform it."""
    from musclemetab.errors import OptionError
    from musclemetab.redundancy.estimate import estimate_parameters, fiber_length_trial, parameter_specs
    from musclemetab.redundancy.transcription import Goals

    made, measured, inputs, params, guess, options, wf, _ = generated
    trial = fiber_length_trial("normal", inputs, guess, {"soleus_r": measured["soleus_r"]})
    with pytest.raises(OptionError, match="vaslat_r has no fiber lengths or EMG"):
        estimate_parameters([trial], params, parameter_specs({"tendon_stiffness": ["soleus_r", "vaslat_r"]}),
                            Goals(w_fiber_length=100.0), options=options)


@pytest.mark.opensim
@pytest.mark.slow
def test_lmo_and_lts_together_are_not_identifiable(generated):
    """The recovery problem (exact fiber lengths and EMG) with the tendon slack lengths of the two
    muscles estimated too: fiber lengths and forces still fit, but each muscle's lMo and lTs
    factors correlate above the threshold at the optimum, which is warned and recorded, and lMo
    leaves the truth 1.10 by more than the 2 % it is recovered within when lTs is known."""
    import warnings

    from musclemetab.errors import MusclemetabWarning
    from musclemetab.redundancy.estimate import estimate_parameters, fiber_length_trial, parameter_specs
    from musclemetab.redundancy.identifiability import CORRELATION_THRESHOLD
    from musclemetab.redundancy.transcription import Goals, ParameterSpec

    made, measured, inputs, params, guess, options, wf, _ = generated
    N = inputs.n_intervals
    specs = parameter_specs({"optimal_fiber_length": LMO, "tendon_slack_length": LMO, "tendon_stiffness": TS},
                            couple=[TS])
    specs.append(ParameterSpec("emg_scale", LMO, (1.0, 1.0)))
    trial = fiber_length_trial("normal", inputs, guess, measured, emg_muscles=LMO,
                               emg_nodes=made.excitation[:N, [made.muscles.index(m) for m in LMO]])
    goals = Goals(**wf.goals.effort_weights(), w_fiber_length=100.0, w_emg=10.0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res, est = estimate_parameters([trial], params, specs, goals, options=options)
    assert res.success, res.status
    text = [str(w.message) for w in caught if issubclass(w.category, MusclemetabWarning)]
    print("\n".join(text))
    rep = est.doubts["identifiability"]
    pairs = {tuple(p["parameters"]): p["correlation"] for p in rep["correlated_pairs"]}
    for m in LMO:
        r = pairs[(f"optimal_fiber_length:{m}", f"tendon_slack_length:{m}")]
        assert abs(r) > CORRELATION_THRESHOLD
        i, j = rep["parameters"].index(f"optimal_fiber_length:{m}"), rep["parameters"].index(f"tendon_slack_length:{m}")
        assert rep["correlation"][i][j] == r
        assert any(f"optimal_fiber_length:{m} and tendon_slack_length:{m} are not identifiable together" in t
                   for t in text)
    assert max(abs(est.factors["optimal_fiber_length"][m] - 1.10) / 1.10 for m in LMO) > 0.02
    assert res.objective_terms["normal"]["fiber_length_tracking"] / 100.0 < 1e-4  # the fiber lengths still fit
    assert all(v is not None and v > 0 for v in rep["standard_error"].values())  # no factor on a bound
    assert rep["on_bound"] == {}


@pytest.mark.opensim
def test_a_validation_misfit_is_a_warning_line_in_mm(generated):
    """The generating solve's fit to its own fiber lengths is exact (no warning); shifted by 6 mm
    (tibialis anterior) the RMS is 6 mm by hand, above the 5 mm limit: one line naming the trial,
    the muscle and the misfit in mm."""
    from musclemetab.redundancy.identifiability import VALIDATION_RMS_MM, tracking_fit, validation_warnings

    made, measured = generated[0], generated[1]
    n = made.lm_norm.shape[0]
    exact = {"normal": tracking_fit(made, {m: measured[m][1][:n] for m in LMO})}
    assert exact["normal"]["fiber_length"]["tibant_r"]["rms_mm"] < 1e-6 and validation_warnings(exact) == []
    shifted = {"normal": tracking_fit(made, {"tibant_r": measured["tibant_r"][1][:n] + 0.006,
                                             "bflh_r": measured["bflh_r"][1][:n]})}
    assert shifted["normal"]["fiber_length"]["tibant_r"]["rms_mm"] == pytest.approx(6.0, rel=1e-9)
    assert VALIDATION_RMS_MM == 5.0
    assert validation_warnings(shifted) == [
        "validation of normal: the fiber length of tibant_r misfits its ultrasound: RMS 6 mm (above 5 mm); the "
        "effort goal with the estimates does not reproduce it"]


@pytest.mark.opensim
@pytest.mark.slow
def test_a_factor_on_its_bound_warns(generated):
    """The triceps surae's tendon stiffness (truth x0.5) from their fiber lengths with its factor
    bounded at 0.6: it ends on that bound, warned once for the coupled factor and recorded; the
    vastus lateralis, estimated with ``uninformed="warn"``, is warned about and recorded."""
    import warnings

    from musclemetab.errors import MusclemetabWarning
    from musclemetab.redundancy.estimate import estimate_parameters, fiber_length_trial, parameter_specs
    from musclemetab.redundancy.transcription import Goals

    made, measured, inputs, params, guess, options, wf, _ = generated
    specs = parameter_specs({"tendon_stiffness": (*TS, "vaslat_r")}, couple=[{"kind": "tendon_stiffness",
                                                                             "muscles": TS}],
                            bounds={"tendon_stiffness": (0.6, 2.0)})
    trial = fiber_length_trial("normal", inputs, guess, {m: measured[m] for m in TS})
    goals = Goals(**wf.goals.effort_weights(), w_fiber_length=100.0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res, est = estimate_parameters([trial], params, specs, goals, options=options, uninformed="warn")
    assert res.success, res.status
    text = [str(w.message) for w in caught if issubclass(w.category, MusclemetabWarning)]
    print("\n".join(text))
    assert est.factors["tendon_stiffness"]["soleus_r"] == pytest.approx(0.6, abs=1e-3 * 1.4)
    # on its bound the factor has no symmetric standard error: a one-sided interval from the bound
    # inwards, whose length is z SE shortened by the slope at the bound (the objective rises from it)
    rep = est.doubts["identifiability"]
    label = "tendon_stiffness:soleus_r,gasmed_r,gaslat_r"
    assert rep["standard_error"][label] is None
    b = rep["on_bound"][label]
    assert b["side"] == "lower" and b["bound"] == 0.6 and b["interval"][0] == 0.6 and 0.6 < b["limit"] <= 2.0
    assert sum(f"{label} is on its lower bound 0.6: no symmetric standard error; one-sided 95 % interval" in t
               for t in text) == 1
    assert [b for b in est.doubts["on_bounds"] if b["muscle"] in TS] == [
        {"kind": "tendon_stiffness", "muscle": m, "factor": est.factors["tendon_stiffness"][m], "bound": 0.6,
         "side": "lower"} for m in TS]
    assert sum("tendon_stiffness factor of soleus_r, gasmed_r, gaslat_r is on its lower bound" in t for t in text) == 1
    assert est.doubts["uninformed"] == [{"kind": "tendon_stiffness", "muscle": "vaslat_r"}]
    assert sum("tendon_stiffness factor of vaslat_r is informed by no measurement" in t for t in text) == 1


@pytest.mark.parametrize("damage", ["ends early", "needed moment missing"])
def test_estimate_checks_each_inverse_dynamics_file_as_solve_does(example, tmp_path, damage):
    """An ID file that ends before its IK file, or lacks the moment of a DOF asked for, is
    refused by ``estimate_files`` before anything is solved, with the error (and file) that
    ``solve_files`` gives for it. Columns for coordinates the model lacks are not needed:
    ignored with a warning naming them."""
    from musclemetab.errors import DataMismatchError, MissingColumnError, MusclemetabWarning
    from musclemetab.io import read_storage, write_storage
    from musclemetab.redundancy.estimate_run import estimate_files
    from musclemetab.redundancy.run import solve_files

    table = read_storage(example.id["normal"]).assign(knee_vv_r_moment=0.0, arm_flex_moment=0.0)
    dofs = ["ankle_angle_r", "knee_angle_r", "hip_flexion_r"]
    if damage == "ends early":
        table = table[table.index <= table.index[-1] - 0.1]
        error, match = DataMismatchError, r"bad_id\.sto covers .* the ID must cover the whole IK window"
    else:
        table = table.drop(columns="knee_angle_r_moment")
        error, match = MissingColumnError, r"bad_id\.sto.*knee_angle_r_moment"
    bad = tmp_path / "bad_id.sto"
    write_storage(bad, table, name="inverse dynamics")
    alien = r"bad_id\.sto: columns knee_vv_r_moment, arm_flex_moment are for coordinates the model .* ignored"
    with pytest.raises(error, match=match), pytest.warns(MusclemetabWarning, match=alien):
        estimate_files(example.model, [example.ik["normal"]], [bad], tmp_path / "est", dofs=dofs,
                       estimate={"tendon_stiffness": ["soleus_r"]}, emg=[example.emg["normal"]])
    assert not (tmp_path / "est").exists()
    if damage != "ends early":  # the solve's check, the same line (the window crops the IK there)
        with pytest.raises(error, match=match):
            solve_files(example.model, example.ik["normal"], bad, "effort-gen", dofs=dofs)
        # with the DOFs' moments present, the columns of coordinates the model lacks are no obstacle
        write_storage(bad, read_storage(example.id["normal"]).assign(knee_vv_r_moment=0.0, arm_flex_moment=0.0))
        with pytest.warns(MusclemetabWarning, match=alien):
            diagnosis = solve_files(example.model, example.ik["normal"], bad, "effort-gen", dofs=dofs,
                                    window=(0.6, 0.9), diagnose_only=True)
        assert not diagnosis.blocking
