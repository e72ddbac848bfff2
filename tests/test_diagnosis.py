"""The diagnosis before the solve (``musclemetab.redundancy.diagnosis``, ``docs/solver.md``).

Each check on a one-muscle synthetic trial against a value worked from the published curves
(De Groote et al. 2016: ``fL(1) = 0.99943``, ``fV(0) = 1.002119``, ``fPE(1) = 0.018567``) or
against the Hill equilibrium of the solver itself; then the example model with the soleus's
tendon slack length lengthened: the diagnosis names the soleus and the times before any IPOPT
call, IPOPT (asked without the diagnosis) ends infeasible at the same times, and EMG-TEN
solves the trial with ``exclude_muscles``.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

LMO, LTS, F0 = 0.1, 0.2, 1000.0
KPE, S0, SM = 4.0, 1.0, 0.6
DT = 0.01


def _fpe(lm):
    """Passive force-length of the study (kPE 4, s0 1, sM 0.6), written from its equation."""
    p1 = math.exp(KPE * (0.2 - 1.0) / 0.6) - 1.0
    return (math.exp(KPE * (lm - S0) / SM) - 1.0 - p1) / (math.exp(KPE) - 1.0)


def _tendon_length(force):
    """Normalised tendon length at a normalised force, kT = 35 (no shift): the inverse of
    fT = exp(35 (lT - 0.995))/5 - 0.25."""
    return math.log(5.0 * (force + 0.25)) / 35.0 + 0.995


def _params(names=("soleus_r",), alpha=0.0, vmax=10.0):
    from musclemetab.redundancy.parameters import MuscleTendonParameters

    n = len(names)
    return MuscleTendonParameters(names=names, max_isometric_force_N=np.full(n, F0),
                                  optimal_fiber_length_m=np.full(n, LMO), tendon_slack_length_m=np.full(n, LTS),
                                  pennation_angle_at_optimal_rad=np.full(n, alpha),
                                  max_contraction_velocity=np.full(n, vmax), tendon_stiffness=np.full(n, 35.0),
                                  passive_kpe=np.full(n, KPE), passive_s0=np.full(n, S0), passive_sm=np.full(n, SM))


def _inputs(lmt, muscles=("soleus_r",), dofs=("ankle_angle_r",), r=None, moments=None):
    from musclemetab.redundancy.inputs import TrialInputs

    lmt = np.asarray(lmt, dtype=float).reshape(-1, len(muscles))
    K = lmt.shape[0]
    t = np.arange(K) * DT
    r = np.full((K, len(dofs), len(muscles)), -0.04) if r is None else np.broadcast_to(r, (K, len(dofs), len(muscles)))
    moments = np.zeros((K, len(dofs))) if moments is None else np.broadcast_to(moments, (K, len(dofs)))
    return TrialInputs(tuple(muscles), tuple(dofs), t, lmt, np.zeros_like(lmt), r, moments, t, lmt, r, moments, {})


def _only(diagnosis, check):
    rows = [f for f in diagnosis.findings if f.check == check]
    assert len(rows) == 1, diagnosis.table()
    return rows[0]


# --------------------------------------------------------------------------- muscle-tendon length
def test_too_short_against_the_hand_worked_shortest_length():
    """Shortest fiber 0.1 lMo (no pennation), inactive: its passive force fPE(0.1) < 0 and the
    tendon at that force: lMT_min = 0.1 lMo + lTs lT(fPE(0.1)) = 0.210274 m."""
    from musclemetab.redundancy.diagnosis import InfeasibleInputError, diagnose

    shortest = 0.1 * LMO + LTS * _tendon_length(_fpe(0.1))
    assert shortest == pytest.approx(0.210274, abs=1e-6)
    lmt = shortest + np.array([1e-3, -5e-4, -1e-3, 2e-3, -1e-4, 1e-3])
    d = diagnose(_inputs(lmt), _params())
    row = _only(d, "muscle_tendon_too_short")
    assert row.subject == "soleus_r" and row.severity == "blocking"
    assert row.intervals == ((0.01, 0.02), (0.04, 0.04))
    assert row.worst_time_s == pytest.approx(0.02) and row.value == pytest.approx(shortest - 1e-3, rel=1e-12)
    assert row.bound == pytest.approx(shortest, rel=1e-12)
    with pytest.raises(InfeasibleInputError, match=r"soleus_r muscle tendon too short at 0\.01-0\.02 s, 0\.04 s.*"
                                                   r"--exclude-muscles soleus_r"):
        d.check("the test trial")


def test_too_short_with_pennation_and_estimated_slack_length():
    """With w = lMo sin(alpha0) = 0.3 lMo the shortest fiber is the one whose projection is the
    smallest admissible (1e-4 m): lM = sqrt(w^2 + 1e-8), force fPE(lM/lMo) cos(alpha). A
    tendon slack length estimated within [0.9, 1.1] admits 10 % shorter tendons: no finding."""
    from musclemetab.redundancy.diagnosis import diagnose
    from musclemetab.redundancy.transcription import ParameterSpec

    w = 0.3 * LMO
    lm = math.sqrt(w**2 + 1e-8)
    shortest = 1e-4 + LTS * _tendon_length(_fpe(lm / LMO) * 1e-4 / lm)
    lmt = np.array([shortest + 1e-3, shortest - 2e-4, shortest + 1e-3])
    row = _only(diagnose(_inputs(lmt), _params(alpha=math.asin(0.3))), "muscle_tendon_too_short")
    assert row.bound == pytest.approx(shortest, rel=1e-12) and row.intervals == ((0.01, 0.01),)
    spec = ParameterSpec("tendon_slack_length", ("soleus_r",), (0.9, 1.1))
    assert not diagnose(_inputs(lmt), _params(alpha=math.asin(0.3)), specs=[spec]).blocking


def test_too_long_is_the_solver_equilibrium_at_the_upper_bound():
    """With a fixed upper bound 1.2 the longest muscle-tendon length is that of the fiber at
    1.2 lMo, fully active, lengthening at the velocity bound (10 lMo/s = vmax): the solver's Hill
    residual vanishes there."""
    from musclemetab.muscle import hill_residual
    from musclemetab.redundancy.diagnosis import diagnose, length_range

    _, longest = length_range(_params(), ["soleus_r"], [1.2])
    res = hill_residual(1.0, 1.2, 10.0, 1.2 * LMO, longest[0], optimal_fiber_length_m=LMO, tendon_slack_length_m=LTS,
                        max_contraction_velocity=10.0)
    assert abs(res) < 1e-9
    row = _only(diagnose(_inputs(longest[0] + np.array([-1e-3, 1e-3])), _params(), lm_upper=1.2),
                "muscle_tendon_too_long")
    assert row.intervals == ((0.01, 0.01),) and row.bound == pytest.approx(longest[0], rel=1e-12)
    # the solver's own (widened) bound admits every length
    assert not [f for f in diagnose(_inputs(longest[0] + np.array([-1e-3, 1e-3])), _params()).findings
                if f.severity == "blocking"]


def test_fiber_too_long_at_every_activation():
    """lMT = lTs + 2 lMo (rigid-tendon fiber 2.0 lMo): the isometric equilibrium at full
    activation (Hill residual 0) is above 1.7; at lTs + 1.5 lMo it is not."""
    from musclemetab.muscle import hill_residual
    from musclemetab.redundancy.diagnosis import diagnose, isometric_fiber_length

    lmt = np.array([LTS + 1.5 * LMO, LTS + 2.0 * LMO])
    upper = [2.05]  # the solver's widened bound: 2.0 + 0.05
    lm = isometric_fiber_length(_params(), ["soleus_r"], upper, lmt[:, None], 1.0)[:, 0]
    res = hill_residual(1.0, lm, 0.0, lm * LMO, lmt, optimal_fiber_length_m=LMO, tendon_slack_length_m=LTS,
                        max_contraction_velocity=10.0)
    assert np.max(np.abs(res)) < 1e-9
    assert lm[0] < 1.5 and 1.7 < lm[1] < 2.0
    row = _only(diagnose(_inputs(lmt), _params()), "fiber_too_long_at_every_activation")
    assert row.severity == "warning" and row.intervals == ((0.01, 0.01),)
    assert row.value == pytest.approx(lm[1], rel=1e-9) and row.bound == 1.7


# --------------------------------------------------------------------------- moment arms and moments
def test_moment_arm_vanishing_on_a_dof_the_table_gives_the_muscle():
    """gasmed (PF KF in the muscle table) with 0.5 mm about the ankle and none about the knee:
    two findings; tibant (DF) with none about the knee: none (it does not span the knee)."""
    from musclemetab.redundancy.diagnosis import diagnose

    lmt = np.full((3, 2), LTS + LMO)
    r = np.zeros((3, 2, 2))
    r[:, 0, 0] = 5e-4  # gasmed_r about the ankle
    r[:, 0, 1] = 0.04  # tibant_r about the ankle
    d = diagnose(_inputs(lmt, muscles=("gasmed_r", "tibant_r"), dofs=("ankle_angle_r", "knee_angle_r"), r=r),
                 _params(("gasmed_r", "tibant_r")))
    rows = [(f.subject, f.value, f.bound) for f in d.findings if f.check == "moment_arm_vanishes"]
    assert rows == [("gasmed_r about ankle_angle_r", 5e-4, 1e-3), ("gasmed_r about knee_angle_r", 0.0, 1e-3)]


def test_muscle_left_out_of_the_problem_named():
    """soleus (PF) with no moment arm about the ankle at the first frame is left out of the
    problem (the study's selection rule, 0.1 mm); the diagnosis of the geometry names it."""
    from musclemetab.redundancy.diagnosis import diagnose_geometry
    from musclemetab.redundancy.inputs import GeometryArrays

    t = np.arange(60) / 100.0
    r = np.zeros((60, 1, 2))
    r[:, 0, 0] = 0.04  # tibant_r
    r[1:, 0, 1] = 0.03  # soleus_r: none at the first frame
    g = GeometryArrays(t, ["tibant_r", "soleus_r"], ["ankle_angle_r"], np.full((60, 2), LTS + LMO), r)
    d = diagnose_geometry(g, _params(("tibant_r", "soleus_r")), t, np.zeros((60, 1)), ik_time_s=t)
    row = _only(d, "muscle_left_out")
    assert (row.subject, row.value, row.bound, row.severity) == ("soleus_r about ankle_angle_r", 0.0, 1e-4, "warning")


def test_unreachable_moment_against_the_hand_worked_isometric_force():
    """lMT chosen for the equilibrium at l~M = 1 at full activation: tendon force
    F0 (fL(1) fV(0) + fPE(1)) = F0 (0.99943 x 1.002119 + 0.018567), moment arm 0.05 m: at most
    51.006 N m; 60 N m is beyond it, -1 N m below the passive muscle's moment."""
    from musclemetab.redundancy.diagnosis import diagnose

    force = 0.99943 * 1.002119 + 0.018567
    lmt = LMO + LTS * _tendon_length(force)
    moments = np.array([[50.0], [60.0], [-1.0]])
    d = diagnose(_inputs(np.full(3, lmt), muscles=("tibant_r",), r=0.05, moments=moments), _params(("tibant_r",)))
    up = [f for f in d.findings if f.subject == "ankle_angle_r (positive)"]
    down = [f for f in d.findings if f.subject == "ankle_angle_r (negative)"]
    assert len(up) == 1 and len(down) == 1, d.table()
    assert up[0].bound == pytest.approx(0.05 * F0 * force, rel=1e-4) and up[0].value == 60.0
    assert up[0].intervals == ((0.01, 0.01),) and up[0].severity == "warning"
    assert 0.05 * F0 * _fpe(1.0) < down[0].bound < 0.05 * F0 * _fpe(1.1) and down[0].intervals == ((0.02, 0.02),)
    assert "150 N m" in up[0].remedy


def test_diagnosis_round_trips_through_the_solve_record():
    from musclemetab.redundancy.diagnosis import diagnose
    from musclemetab.redundancy.record import SolveRecord

    lmt = 0.1 * LMO + LTS * _tendon_length(_fpe(0.1)) + np.array([1e-3, -1e-3])
    d = diagnose(_inputs(lmt), _params(), trial="t")
    summary = {"status": "Solve_Succeeded", "success": True, "diagnosis": d.to_dict()}
    record = SolveRecord.from_dict(summary)
    assert record.to_dict() == summary
    assert record.pre_solve_diagnosis.findings == d.findings and "muscle_tendon_too_short" in d.table()
    # a stage adds an entry by its name; a misspelt one is refused, not written unread
    assert record.with_(side="l").to_dict() == {**summary, "side": "l"}
    with pytest.raises(TypeError, match="no entry 'sides'"):
        record.with_(sides="l")


# --------------------------------------------------------------------------- the example model
def _long_soleus(example, path):
    """The example model with the soleus's tendon slack length 0.325 m (0.2835 m in the model):
    longer than the shortest muscle-tendon length of the normal trial (0.322 m at 1.33 s)."""
    text = example.model.read_text()
    i = text.index("<tendon_slack_length>", text.index('name="soleus_r"'))
    j = text.index("</tendon_slack_length>", i)
    path.write_text(text[:i] + "<tendon_slack_length>0.325" + text[j:])
    return path


@pytest.fixture(scope="module")
def long_soleus(example, tmp_path_factory):
    return _long_soleus(example, tmp_path_factory.mktemp("diagnosis") / "long_soleus.osim")


@pytest.mark.opensim
def test_long_tendon_named_before_any_solve(example, long_soleus, geometry_cache, monkeypatch, tmp_path, capsys):
    import casadi

    from musclemetab.commands import main
    from musclemetab.redundancy import ipopt
    from musclemetab.redundancy.diagnosis import InfeasibleInputError
    from musclemetab.redundancy.emg_run import solve_emg_ten

    def no_ipopt(*a, **k):
        raise AssertionError("IPOPT was called")

    monkeypatch.setattr(casadi, "nlpsol", no_ipopt)
    monkeypatch.setattr(ipopt, "run_ipopt", no_ipopt)  # a solver kept from an earlier solve of the process
    with pytest.raises(InfeasibleInputError, match=r"trial normal cannot be solved: soleus_r muscle tendon too short "
                                                   r"at 1\.29-1\.39 s .*shortest admissible 0\.3255 m"):
        solve_emg_ten(long_soleus, [example.ik["normal"]], [example.id["normal"]], [example.emg["normal"]],
                      labels=["normal"], cache_dir=geometry_cache)
    out = tmp_path / "out"
    trial = ["--model", str(long_soleus), "--ik", str(example.ik["normal"]), "--id", str(example.id["normal"]),
             "--cache-dir", str(geometry_cache), "--out", str(out)]
    assert main(["solve", *trial]) == 1
    assert "soleus_r muscle tendon too short at 1.29-1.39 s" in capsys.readouterr().err
    emg = ["--workflow", "emg-ten", "--emg", str(example.emg["normal"]), "--labels", "normal", "--diagnose-only"]
    assert main(["solve", *trial, *emg]) == 1
    said = capsys.readouterr()
    table = [line.split() for line in said.out.splitlines()]
    assert ["soleus_r", "muscle_tendon_too_short", "blocking", "1.29-1.39", "s", "0.322", "m", "0.3255", "m",
            "exclude"] in [row[:10] for row in table]
    assert "trial normal (side r) cannot be solved" in said.err
    assert main(["solve", *trial, *emg, "--exclude-muscles", "soleus_r"]) == 0
    assert "side r: diagnosis of normal: no findings" in capsys.readouterr().out
    assert not out.exists()


@pytest.mark.opensim
@pytest.mark.slow
def test_ipopt_ends_infeasible_where_the_diagnosis_says(example, long_soleus, geometry_cache):
    """Asked without the diagnosis (the arrays API), IPOPT ends infeasible; the constraints its
    last iterate leaves violated are the soleus's Hill equilibrium inside the diagnosed times."""
    from musclemetab.geometry import compute_geometry
    from musclemetab.model import read_muscle_parameters
    from musclemetab.redundancy.diagnosis import diagnose, last_iterate_violations, violation_text
    from musclemetab.redundancy.inputs import (GeometryArrays, read_inverse_dynamics, read_kinematics,
                                               restrict_geometry, trial_inputs)
    from musclemetab.redundancy.solve import solve_trial
    from musclemetab.redundancy.workflows import get_workflow, workflow_parameters

    g = compute_geometry(long_soleus, example.ik["normal"], side="r", cache_dir=geometry_cache)
    t_ik, _ = read_kinematics(example.ik["normal"], g.dofs)
    keep = (t_ik >= 1.2) & (t_ik <= 1.5)
    g = GeometryArrays(t_ik[keep], g.muscles, g.dofs, np.asarray(g.lmt_m)[keep], np.asarray(g.moment_arms_m)[keep])
    t_id, moments = read_inverse_dynamics(example.id["normal"], g.dofs)
    mp = read_muscle_parameters(long_soleus)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        solution = solve_trial(g, mp, t_id, moments, "effort-gen", ik_time_s=t_ik[keep])
    assert solution.record.status == "Infeasible_Problem_Detected"
    g = restrict_geometry(g)
    inputs = trial_inputs(g, t_id, moments, ik_time_s=t_ik[keep])
    params, _ = workflow_parameters(get_workflow("effort-gen"), mp, g.muscles)
    diagnosed = _only(diagnose(inputs, params), "muscle_tendon_too_short")
    violated = last_iterate_violations(solution, inputs)
    hill = [f for f in violated if f.check == "hill_violated"]
    assert [f.subject for f in hill] == ["soleus_r"]
    (a, b), = diagnosed.intervals
    assert a <= hill[0].worst_time_s <= b and hill[0].value > 10 * hill[0].bound
    text = violation_text({"diagnosis": {"last_iterate": [f.to_dict() for f in violated]}})
    assert "soleus_r (Hill equilibrium off by" in text


@pytest.mark.opensim
@pytest.mark.slow
def test_exclude_muscles_solves_the_emg_ten_trial(example, long_soleus, geometry_cache, tmp_path):
    """Without the soleus the trial solves (the normal trial's IK from 1.15 s on, a file of those
    rows: half of the trial's nodes); its EMG is not used and the Achilles tendon's
    stiffness is the two gastrocnemii's (warnings say so); the EMG band holds."""
    from musclemetab.errors import MusclemetabWarning
    from musclemetab.io import read_storage, write_storage
    from musclemetab.redundancy.emg_run import solve_emg_ten

    full = read_storage(example.ik["normal"])
    ik = write_storage(tmp_path / "IK_sub1_normal.mot", full[full.index >= 1.15], name="ik", in_degrees=True)
    with pytest.warns(MusclemetabWarning) as caught:
        result = solve_emg_ten(long_soleus, [ik], [example.id["normal"]], [example.emg["normal"]],
                               labels=["normal"], cache_dir=geometry_cache, exclude_muscles=["soleus_r"])
    said = " ".join(str(w.message) for w in caught)
    assert "the EMG of soleus_r (SO) is not used" in said and "tendon stiffness of soleus_r is not estimated" in said
    assert result.success
    solution = result.solutions["normal"]
    assert "soleus_r" not in solution.muscles and len(solution.muscles) == 39
    assert solution.record.excluded_muscles == ("soleus_r",) and solution.record.diagnosis.findings == ()
    assert "soleus_r" not in result.emg_scale and "soleus_r" not in result.tendon_stiffness
    assert result.tendon_stiffness["gaslat_r"] == result.tendon_stiffness["gasmed_r"]
    from musclemetab.io import read_storage

    emg = read_storage(example.emg["normal"])
    n = len(solution.time_s) - 1
    tracked = list(result.emg_scale)
    assert "soleus_r" not in result.emg_channels and len(tracked) == 8
    E = np.column_stack([np.mean([np.interp(solution.time_s[:n], emg.index.to_numpy(), emg[c].to_numpy())
                                  for c in result.emg_channels[m]], axis=0) for m in tracked])
    e = solution.excitation[:n, [solution.muscles.index(m) for m in tracked]]
    assert np.max(np.abs(e - np.array([result.emg_scale[m] for m in tracked]) * E)) <= 0.01 + 1e-6
    assert solution.record.max_hill_residual < 1e-5


def test_estimate_refuses_an_excluded_estimated_muscle(example, tmp_path, capsys):
    from musclemetab.commands import main

    code = main(["estimate", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
                 str(example.id["normal"]), "--emg", str(example.emg["normal"]), "--estimate",
                 "tendon_stiffness=soleus_r,gasmed_r", "--exclude-muscles", "soleus_r", "--out", str(tmp_path / "o")])
    assert code == 1
    assert "--exclude-muscles soleus_r and --estimate/--couple name the same muscle" in capsys.readouterr().err


def test_study_key_exclude_muscles(example):
    """``exclude_muscles`` of a subject: kept in the spec and in the units' keys; a name the
    model lacks is refused before anything runs."""
    from musclemetab.errors import OptionError, UnknownMuscleError
    from musclemetab.study.spec import study_from_dict
    from musclemetab.study.units import _subject_record

    def data(excluded):
        return {"name": "s", "workflows": ["effort-gen"], "models": ["UM10"], "subjects": [{
            "name": "sub1", "model": str(example.model), "body_mass_kg": example.body_mass_kg,
            "height_m": example.height_m, "exclude_muscles": excluded,
            "trials": [{"name": "normal", "ik": str(example.ik["normal"]), "id": str(example.id["normal"])}]}]}

    subject = study_from_dict(data(["soleus_r"]), base="/").subjects[0]
    assert subject.exclude_muscles == ("soleus_r",)
    assert _subject_record(subject, "effort-gen")["exclude_muscles"] == ["soleus_r"]
    assert "exclude_muscles" not in _subject_record(study_from_dict(data([]), base="/").subjects[0], "effort-gen")
    with pytest.raises(UnknownMuscleError, match="'exclude_muscles' soleus_x not a muscle of"):
        study_from_dict(data(["soleus_x"]), base="/")
    with pytest.raises(OptionError, match="'exclude_muscles' must be a list"):
        study_from_dict(data("soleus_r"), base="/")
