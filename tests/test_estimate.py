"""Parameter estimation with the problem core: recovery of known changes from fiber lengths.

"Measured" fiber lengths are made by solving the normal trial (EFFORT-CAL goals) with the optimal
fiber length of tibialis anterior and biceps femoris long head x1.10 and the tendon stiffness of the
triceps surae x0.5; the factors are then estimated back from those fiber lengths with the
unchanged model.

Fiber lengths alone identify the tendon stiffness (with the fiber length and the muscle-tendon
length, the tendon length and hence the tendon force follow, and the moments must be met) but
hardly the optimal fiber length: for any lMo the measured fiber length gives the same tendon
force and the activation absorbs the change of fL(lM/lMo); only the effort tells the factors apart
(the fiber-only estimate ends at about 1.04 and 1.15). Adding the excitations of the generating
solve as EMG of the two muscles (tracked, scale fixed at 1) pins the activation, and the
force-length relation then gives lMo. Tolerances: kT 1 %, lMo 2 % (at the true factors the
tracking errors are zero and the effort is that of the generating solve; the estimate moves away
only as far as lowering the effort pays against the tracking costs, weights 100 and 10).
"""

from __future__ import annotations

import numpy as np
import pytest
from mrs_reference import DOFS

TS = ("soleus_r", "gasmed_r", "gaslat_r")
LMO = ("tibant_r", "bflh_r")


@pytest.fixture(scope="module")
def generated(example, tmp_path_factory):
    """The generating solve with the changed parameters and the unchanged model's trial."""
    from musclemetab.geometry import compute_geometry
    from musclemetab.model import read_muscle_parameters
    from musclemetab.redundancy import SolverOptions
    from musclemetab.redundancy.inputs import read_inverse_dynamics, read_kinematics
    from musclemetab.redundancy.solve import prepare_trial, solve_with_parameters
    from musclemetab.redundancy.static_opt import initial_guess
    from musclemetab.redundancy.workflows import get_workflow, workflow_parameters

    g = compute_geometry(example.model, example.ik["normal"], dofs=list(DOFS),
                         cache_dir=tmp_path_factory.mktemp("estimate_geometry"))
    t_ik, _ = read_kinematics(example.ik["normal"], DOFS)
    t_id, mom = read_inverse_dynamics(example.id["normal"], DOFS)
    wf = get_workflow("effort-cal")
    options = SolverOptions(w_activation=wf.w_activation, w_reserve=wf.w_reserve, w_velocity=wf.w_velocity)
    nominal, _ = workflow_parameters(wf, read_muscle_parameters(example.model), g.muscles)
    i = {m: nominal.names.index(m) for m in (*TS, *LMO)}
    truth = nominal.replace(optimal_fiber_length_m={m: 1.10 * nominal.optimal_fiber_length_m[i[m]] for m in LMO},
                            tendon_stiffness={m: 0.5 * nominal.tendon_stiffness[i[m]] for m in TS})
    made = solve_with_parameters(g, truth, t_id, mom, ik_time_s=t_ik, options=options)
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
    goals = Goals(w_activation=wf.w_activation, w_reserve=wf.w_reserve, w_velocity=wf.w_velocity,
                  w_fiber_length=100.0, w_emg=10.0 if with_emg else 0.0)
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
def test_estimate_command_records_a_stopped_solve(example, tmp_path):
    """Plumbing of ``musclemetab estimate`` (3 iterations): the solutions and parameters.json are
    written with IPOPT's status, no personalised model, exit status 1 with one line."""
    import json

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
    assert (out / "normal" / "summary.json").is_file()
    assert not list(out.glob("*_personalised.osim"))


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
def test_estimate_command_with_emg_recovers_the_parameters(example, generated, recovery, tmp_path):
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
    code, text = _cli(["estimate", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
                       str(example.id["normal"]), "--ultrasound", str(tmp_path / "us.mot"), "--emg",
                       str(tmp_path / "emg.mot"), "--emg-mapping", str(tmp_path / "map.json"), "--emg-mode",
                       "tracking", "--bounds", "emg_scale=1:1", "--estimate", "optimal_fiber_length=tibant_r,bflh_r",
                       "tendon_stiffness=soleus_r,gasmed_r,gaslat_r", "--couple", "soleus_r,gasmed_r,gaslat_r",
                       "--labels", "normal", "--out", str(out)])
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
    assert doc["emg"]["mapping"] == {"tibant_r": ["TA"], "bflh_r": ["BF"]}
    assert (out / "normal" / "summary.json").is_file() and list(out.glob("*_personalised.osim"))
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
    assert not (tmp_path / "o").exists()


@pytest.mark.opensim
@pytest.mark.slow
def test_estimate_command_on_the_left_leg_recovers_the_tendon_stiffness(example, tmp_path):
    """``musclemetab estimate --side l``: fiber lengths made by solving the example's left leg
    (its DOFs discovered from the model and the ID file) with the triceps surae's tendon
    stiffness x0.5 give that factor back (1 %, as on the right leg)."""
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
    ik, idp = example.ik["normal"], example.id["normal"]
    dofs = discover_dofs(read_layout(example.model), "l", list(read_storage(idp).columns))
    assert dofs and all(d.endswith("_l") for d in dofs)
    g = compute_geometry(example.model, ik, dofs=dofs, side="l", cache_dir=tmp_path / "cache")
    t_ik, _ = read_kinematics(ik, dofs)
    t_id, mom = read_inverse_dynamics(idp, dofs)
    wf = get_workflow("effort-gen")
    nominal, _ = workflow_parameters(wf, read_muscle_parameters(example.model), g.muscles)
    truth = nominal.replace(tendon_stiffness={m: 0.5 * nominal.tendon_stiffness[nominal.names.index(m)] for m in ts})
    made = solve_with_parameters(g, truth, t_id, mom, ik_time_s=t_ik, options=SolverOptions(
        w_activation=wf.w_activation, w_reserve=wf.w_reserve, w_velocity=wf.w_velocity))
    assert made.success
    lmo = dict(zip(truth.names, truth.optimal_fiber_length_m))
    us = pd.DataFrame({m: 1000.0 * made.lm_norm[:, made.muscles.index(m)] * lmo[m] for m in ts}, index=made.time_s)
    write_storage(tmp_path / "us.mot", us, in_degrees=False)
    out = tmp_path / "est"
    code, text = _cli(["estimate", "--model", str(example.model), "--ik", str(ik), "--id", str(idp), "--side", "l",
                       "--workflow", "effort-gen", "--ultrasound", str(tmp_path / "us.mot"), "--estimate",
                       "tendon_stiffness=" + ",".join(ts), "--couple", ",".join(ts), "--labels", "normal",
                       "--cache-dir", str(tmp_path / "cache"), "--out", str(out)])
    assert code == 0, text
    f = json.loads((out / "parameters.json").read_text())["factors"]["tendon_stiffness"]
    assert set(f) == set(ts)
    assert f["soleus_l"] == pytest.approx(0.5, rel=0.01)
    summary = json.loads((out / "normal" / "summary.json").read_text())
    assert summary["dofs"] == dofs
