"""Passive force-length calibration.

Independent checks: a hand-worked single-muscle equilibrium, a root-finding equilibrium
per muscle and frame, the reference implementation's stored passive moments (same
geometry, same parameters), its stored fit quality (passive_calibration.md §5.1) and its
calibrated parameters (§5.2).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil

import numpy as np
import pandas as pd
import pytest
import scipy.io

from musclemetab.calibration import (
    CalibrationData,
    CalibrationTrial,
    PassiveCalibration,
    calibrate_passive,
    equilibrium_fiber_length,
    mirror_to_left,
    parameter_groups,
    read_passive_parameters,
    solve_passive,
    write_calibration,
)
from musclemetab.commands.calibrate_passive import add_parser as add_calibrate_parser
from musclemetab.errors import InputFileError, MissingColumnError, SolverError, UnknownMuscleError
from musclemetab.muscle import passive_force_length, tendon_force_length, tendon_length_from_force

MAT_TRIAL = {"ankle": 0, "hip": 1, "knee": 2}  # order of the trials in passiveMoments.mat

# passive_calibration.md §5.1
STORED_RMS_GENERIC = {"ankle": 8.90, "hip": 12.67, "knee": 24.52}
STORED_RMS_GENERIC_BLOCKS = {"ankle": [7.00, 10.86, 8.39], "hip": [16.63, 6.67], "knee": [21.67, 25.36, 26.27]}
STORED_RMS_CALIBRATED = {"ankle": 1.96, "hip": 2.93, "knee": 3.34}


@pytest.fixture(scope="module")
def sim(example):
    return scipy.io.loadmat(example.passive_moments_mat, squeeze_me=True, struct_as_record=False)["sim"]


@pytest.fixture(scope="module")
def result(example):
    return calibrate_passive(example.calibration_model, example.calibration_trials)


@pytest.fixture(scope="module")
def data(result):
    return result.data


@pytest.fixture(scope="module")
def authors(example):
    return read_passive_parameters(example.passive_moments_mat)


@pytest.fixture(scope="module")
def authors_solution(data, authors):
    return solve_passive(data, authors)


def _sse(sol, data):
    return sum(float(np.sum((sol.moments_Nm[t.joint] - t.target_Nm) ** 2)) for t in data.trials)


# ----------------------------------------------------------------- data and couplings


def test_trials_muscles_and_blocks(data, sim):
    spec = {
        "ankle": "edl ehl fdl fhl gaslat gasmed perbrev perlong soleus tibant tibpost",
        "knee": "bflh bfsh gaslat gasmed grac recfem sart semimem semiten tfl vasint vaslat vasmed",
        "hip": "addbrev addlong addmagDist addmagIsch addmagMid addmagProx bflh glmax1 glmax2 glmax3 glmed1 "
        "glmed2 glmed3 glmin1 glmin2 glmin3 grac iliacus piri psoas recfem sart semimem semiten tfl",
    }
    for t in data.trials:
        assert sorted(t.muscles) == sorted(f"{m}_r" for m in spec[t.joint].split())
        assert t.muscles == tuple(sim.DatStore[MAT_TRIAL[t.joint]].MuscleNames)
        n_blocks = 2 if t.joint == "hip" else 3
        np.testing.assert_array_equal(t.block, np.repeat(np.arange(n_blocks), 50))
        # angles in rad, targets in N m as stored by the reference
        ds = sim.DatStore[MAT_TRIAL[t.joint]]
        np.testing.assert_allclose(np.degrees(t.target_angle_rad), ds.q_exp, atol=1e-9)
        np.testing.assert_allclose(t.target_Nm, ds.T_exp, atol=1e-9)
        # OpenSim geometry agrees with the reference MuscleAnalysis
        np.testing.assert_allclose(t.lmt_m, ds.LMT, atol=2e-4)
        np.testing.assert_allclose(t.moment_arms_m, ds.dM, atol=5e-4)
    assert len(data.muscles) == 40
    kT = dict(zip(data.muscles, data.tendon_stiffness))
    assert kT["soleus_r"] == kT["gasmed_r"] == kT["gaslat_r"] == 20 and kT["tibant_r"] == 35
    ref_kT = dict(zip([str(n) for n in sim.Misc.allMuscleList[:40]], np.asarray(sim.Misc.kT[:40], dtype=float)))
    assert all(kT[m] == ref_kT[m] for m in data.muscles)


def test_coupling_groups(data):
    groups = {frozenset(g) for g in parameter_groups(data.muscles) if len(g) > 1}
    r = lambda s: frozenset(f"{m}_r" for m in s.split())  # noqa: E731
    assert groups == {
        r("perbrev perlong"), r("fdl fhl"), r("edl ehl"), r("gasmed gaslat"), r("semimem semiten bflh"),
        r("vasmed vasint vaslat"), r("glmax1 glmax2 glmax3"), r("glmed1 glmed2 glmed3"),
        r("glmin1 glmin2 glmin3"), r("addmagDist addmagIsch addmagMid addmagProx"),
    }
    assert sum(len(g) for g in parameter_groups(data.muscles)) == 40


# ---------------------------------------------------- passive moments: independent checks


def test_hand_worked_single_muscle():
    # l~M = 1.2, kPE = 4, s0 = 1, sM = 0.6: fPE = 0.0706898 (muscle_model.md §6.1). No
    # pennation: fT = fPE, l~T from the inverse tendon curve, lMT = 1.2 lMo + l~T lTs.
    lmo, lts, F0, r, kT = 0.05, 0.25, 3000.0, 0.04, 20.0
    fpe = float(passive_force_length(1.2))
    assert fpe == pytest.approx(0.0706898, abs=1e-7)
    lt = float(tendon_length_from_force(fpe, kT))
    assert float(tendon_force_length(lt, kT)) == pytest.approx(fpe, abs=1e-12)
    lmt = 1.2 * lmo + lt * lts
    n = 3
    trial = CalibrationTrial(
        joint="ankle", dof="ankle_angle_r", angles_rad=np.zeros((n, 1)), angle_names=("ankle_angle_r",),
        target_Nm=np.zeros(n), block=np.zeros(n, dtype=int), muscles=("soleus_r",),
        lmt_m=np.full((n, 1), lmt), moment_arms_m=np.full((n, 1), r),
    )
    data = CalibrationData(
        trials=(trial,), muscles=("soleus_r",), max_isometric_force_N=np.array([F0]),
        optimal_fiber_length_m=np.array([lmo]), tendon_slack_length_m=np.array([lts]),
        pennation_angle_at_optimal_rad=np.array([0.0]), tendon_stiffness=np.array([kT]),
    )
    sol = solve_passive(data, {"soleus_r": (4.0, 1.0, 0.6)})
    np.testing.assert_allclose(sol.lm_norm["ankle"], 1.2, atol=1e-7)
    np.testing.assert_allclose(sol.moments_Nm["ankle"], F0 * fpe * r, atol=1e-4)  # 8.4828 N m
    np.testing.assert_allclose(sol.reserve_Nm["ankle"], -F0 * fpe * r, atol=1e-4)
    lm, ft = equilibrium_fiber_length(lmt, optimal_fiber_length_m=lmo, tendon_slack_length_m=lts,
                                      pennation_angle_at_optimal_rad=0.0, kT=kT)
    assert lm == pytest.approx(1.2, abs=1e-9) and ft == pytest.approx(fpe, abs=1e-9)


def test_generic_equilibrium_matches_root_finding(result, data):
    # every muscle and frame of the generic solve equals an independent scalar root find
    t = data.trials[0]
    idx = data.index(t.muscles)
    for j, i in enumerate(idx):
        for k in range(0, t.n_frames, 7):
            lm, _ = equilibrium_fiber_length(
                t.lmt_m[k, j], optimal_fiber_length_m=data.optimal_fiber_length_m[i],
                tendon_slack_length_m=data.tendon_slack_length_m[i],
                pennation_angle_at_optimal_rad=data.pennation_angle_at_optimal_rad[i],
                kT=data.tendon_stiffness[i],
            )
            assert result.generic.lm_norm[t.joint][k, j] == pytest.approx(lm, abs=1e-6)


@pytest.mark.parametrize("key", ["genParam", "calParam"])
def test_reproduces_stored_passive_moments_on_stored_geometry(data, sim, key):
    trials = tuple(
        dataclasses.replace(t, lmt_m=sim.DatStore[MAT_TRIAL[t.joint]].LMT, moment_arms_m=sim.DatStore[MAT_TRIAL[t.joint]].dM)
        for t in data.trials
    )
    only = getattr(sim.Results.onlyParam, key)
    params = {str(m): (float(k), float(s), 0.6) for m, k, s in zip(sim.Results.onlyParam.MuscleNames, only.kpe, only.ksf)}
    sol = solve_passive(dataclasses.replace(data, trials=trials), params)
    for t in trials:
        stored = getattr(sim.Results, key)[MAT_TRIAL[t.joint]]
        # the stored reserve is target - Tsim; Tsim itself is stored to ~1e-4 N m at the hip
        np.testing.assert_allclose(sol.reserve_Nm[t.joint], stored.aTk, atol=1e-5)
        np.testing.assert_allclose(sol.moments_Nm[t.joint], stored.Tsim, atol=2e-4)


def test_generic_fit_quality_matches_stored(result, data):
    rms = result.generic.rms_Nm(data)
    blocks = result.generic.rms_per_block_Nm(data)
    for j, v in STORED_RMS_GENERIC.items():
        assert rms[j] == pytest.approx(v, abs=0.02)
        np.testing.assert_allclose(blocks[j], STORED_RMS_GENERIC_BLOCKS[j], atol=0.02)


# ------------------------------------------------------------------- the calibration


def test_calibration_fits_at_least_as_well_as_published(result, data, authors_solution):
    cal, pub = result.calibrated, authors_solution
    assert cal.stats["success"] and pub.stats["success"]
    rms_cal, rms_pub = cal.rms_Nm(data), pub.rms_Nm(data)
    for j, v in STORED_RMS_CALIBRATED.items():
        assert rms_pub[j] == pytest.approx(v, abs=0.02)
    # the objective (all frames of all trials) is at least as low as with the published values
    assert _sse(cal, data) <= _sse(pub, data) * (1 + 1e-6)
    # per joint within 0.005 N m (shared bi-articular parameters trade joints off)
    for j in rms_cal:
        assert rms_cal[j] <= rms_pub[j] + 0.005
        assert rms_cal[j] < 0.25 * result.generic.rms_Nm(data)[j]


def test_calibrated_parameters_close_to_published(result, authors, reference_table):
    cal = result.calibrated.parameters
    assert set(cal) == {m for m in authors if m.endswith("_r")}
    dk = {m: abs(cal[m][0] - authors[m][0]) for m in cal}
    ds = {m: abs(cal[m][1] - authors[m][1]) for m in cal}
    assert max(dk.values()) < 0.05, max(dk.items(), key=lambda kv: kv[1])
    assert max(ds.values()) < 0.005, max(ds.items(), key=lambda kv: kv[1])
    assert all(v[2] == 0.6 for v in cal.values())
    # published values in the reference table equal the MAT file's
    for m, (k, s, _) in authors.items():
        assert k == pytest.approx(reference_table.at[m, "kpe_calibrated"], abs=1e-6)
        assert s == pytest.approx(reference_table.at[m, "s0_calibrated"], abs=1e-6)
    # couplings hold exactly
    for g in parameter_groups(list(cal)):
        assert len({cal[m][:2] for m in g}) == 1


def test_solver_options_reach_ipopt(data):
    """IPOPT's settings come from the package's SolverOptions: three iterations stop the
    calibration, which is reported as not converged."""
    from musclemetab.redundancy.ipopt import SolverOptions

    with pytest.raises(SolverError, match="calibration NLP did not converge .IPOPT: Maximum_Iterations_Exceeded"):
        solve_passive(data, None, options=SolverOptions(max_iter=3))


# ------------------------------------------------------------------------ files and CLI


def test_write_and_read_outputs(result, tmp_path):
    files = write_calibration(result, tmp_path / "out")
    csv = pd.read_csv(files["passive_parameters.csv"])
    assert list(csv.columns) == ["muscle", "kPE", "s0", "sM"]
    back = read_passive_parameters(files["passive_parameters.csv"])
    assert set(back) == set(result.calibrated.parameters)
    for m, p in result.calibrated.parameters.items():
        np.testing.assert_allclose(back[m], p, rtol=1e-9)
    fit = json.loads(files["fit.json"].read_text())
    for j in ("ankle", "knee", "hip"):
        assert fit["rms_calibrated_Nm"][j] == pytest.approx(result.calibrated.rms_Nm(result.data)[j])
        assert fit["rms_generic_Nm"][j] == pytest.approx(result.generic.rms_Nm(result.data)[j])
    assert fit["solver"]["calibrated"]["return_status"] == "Solve_Succeeded"
    assert fit["solver"]["calibrated"]["iterations"] > 0
    assert files["passive_fit.png"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not [p for p in (tmp_path / "out").iterdir() if p.name.startswith(".partial")]
    both = mirror_to_left(back)
    assert both["soleus_l"] == both["soleus_r"] and len(both) == 80


def test_passive_calibration_round_trip(result, tmp_path):
    """The typed folder content: written, read back (parameters to the file's 10 digits, the
    fit summary exactly), written again byte for byte; no figure unless one is given."""
    cal = result.record()
    files = cal.write(tmp_path / "a")
    assert sorted(files) == ["fit.json", "passive_parameters.csv"]
    assert not (tmp_path / "a" / "passive_fit.png").exists()
    back = PassiveCalibration.load(tmp_path / "a")
    assert list(back.parameters) == list(result.calibrated.parameters) and len(back.parameters) == 40
    for m, p in result.calibrated.parameters.items():
        np.testing.assert_allclose(back.parameters[m], p, rtol=1e-9)
    assert back.fit == cal.fit
    assert back.fit["rms_calibrated_Nm"] == result.calibrated.rms_Nm(result.data)
    assert back.fit["solver"]["calibrated"]["iterations"] == result.calibrated.stats["iterations"]
    back.write(tmp_path / "b")
    for name in files:
        assert (tmp_path / "b" / name).read_bytes() == (tmp_path / "a" / name).read_bytes()
    (tmp_path / "c").mkdir()
    with pytest.raises(InputFileError, match="no passive_parameters.csv and no fit.json"):
        PassiveCalibration.load(tmp_path / "c")


def test_passive_figure_shows_every_block(result):
    """One row per trial, one panel per block (the hip has two: its third panel is blank),
    each with the target, generic and calibrated moments of that block's frames."""
    from musclemetab.report.passive_figure import passive_fit_figure

    d = result.data
    fig = passive_fit_figure(d.trials, result.generic.moments_Nm, result.calibrated.moments_Nm)
    axes = np.array(fig.axes).reshape(3, 3)
    for r, t in enumerate(d.trials):
        for c in range(3):
            ax = axes[r, c]
            if c >= len(np.unique(t.block)):
                assert not ax.axison and not ax.lines
                continue
            sel = t.block == c
            target, generic, calibrated = (line.get_ydata() for line in ax.lines)
            np.testing.assert_array_equal(target, t.target_Nm[sel])
            np.testing.assert_array_equal(generic, result.generic.moments_Nm[t.joint][sel])
            np.testing.assert_array_equal(calibrated, result.calibrated.moments_Nm[t.joint][sel])
            np.testing.assert_allclose(ax.lines[0].get_xdata(), np.degrees(t.target_angle_rad[sel]))
            assert ax.get_title().startswith(f"{t.joint} block {c + 1} (")
    assert [t.joint for t in d.trials] == ["ankle", "knee", "hip"]


def test_read_passive_parameters_from_mat(example):
    cal = read_passive_parameters(example.passive_moments_mat)
    assert len(cal) == 40 and all(m.endswith("_r") for m in cal)
    assert cal["psoas_r"] == pytest.approx((4.935357, 0.800004, 0.6), abs=1e-6)


def test_read_passive_parameters_errors(tmp_path):
    bad = tmp_path / "p.csv"
    bad.write_text("muscle,s0,sM\nsoleus_r,1,0.6\n")
    with pytest.raises(MissingColumnError, match="kPE"):
        read_passive_parameters(bad)
    bad.write_text("muscle,kPE,s0,sM\nsoleus_r,4,x,0.6\n")
    with pytest.raises(InputFileError, match="soleus_r"):
        read_passive_parameters(bad)
    with pytest.raises(InputFileError, match="no such"):
        read_passive_parameters(tmp_path / "none.csv")


def test_imposed_parameters_must_cover_muscles(data):
    with pytest.raises(UnknownMuscleError, match="psoas_r"):
        solve_passive(data, {m: (4, 1, 0.6) for m in data.muscles if m != "psoas_r"})


def test_cli(example, tmp_path, result):
    parser = argparse.ArgumentParser(prog="musclemetab")
    sub = parser.add_subparsers(dest="command")
    add_calibrate_parser(sub)
    trials = example.calibration_trials["ankle"]["motion"].parent
    args = parser.parse_args(
        ["calibrate-passive", "--model", str(example.calibration_model), "--trials", str(trials),
         "--out", str(tmp_path / "cal")]
    )
    assert args.func(args) == 0
    got = read_passive_parameters(tmp_path / "cal" / "passive_parameters.csv")
    for m, p in result.calibrated.parameters.items():
        np.testing.assert_allclose(got[m], p, atol=1e-6)
    args = parser.parse_args(
        ["calibrate-passive", "--model", str(example.calibration_model), "--trials", str(tmp_path),
         "--out", str(tmp_path / "x")]
    )
    with pytest.raises(InputFileError, match="no calibration trial for ankle_angle_r"):
        args.func(args)


def test_cli_both_legs(example, tmp_path, result):
    """``--side both`` with a folder of both legs' trials (the study's right-leg trials and their
    copies on the left coordinates): the right leg's parameters are those of the right leg alone
    (the left trials do not enter it); the left leg of the generic model, a mirror image of the
    right up to small path-point differences, gets the same parameters to 1 %; both legs' rows
    are in DIR/passive_parameters.csv. A folder with one leg's trials is refused, nothing written."""
    from musclemetab.io import read_storage, write_storage

    trials = tmp_path / "trials"
    trials.mkdir()
    for files in example.calibration_trials.values():
        for kind, path in files.items():
            shutil.copy(path, trials)  # the same content: the geometry of the right leg from the cache
            df = read_storage(path)
            left = df.rename(columns={c: c.replace("_r", "_l") for c in df.columns})
            write_storage(trials / f"mirror_{path.name}", left, in_degrees=True if kind == "motion" else None)
    parser = argparse.ArgumentParser(prog="musclemetab")
    add_calibrate_parser(parser.add_subparsers(dest="command"))
    out = tmp_path / "cal"
    args = parser.parse_args(["calibrate-passive", "--model", str(example.calibration_model), "--trials", str(trials),
                              "--side", "both", "--out", str(out)])
    assert args.func(args) == 0
    right = read_passive_parameters(out / "r" / "passive_parameters.csv")
    left = read_passive_parameters(out / "l" / "passive_parameters.csv")
    both = read_passive_parameters(out / "passive_parameters.csv")
    assert set(both) == set(right) | set(left) and len(both) == 80
    for m, p in result.calibrated.parameters.items():
        np.testing.assert_allclose(right[m], p, atol=1e-6)
        np.testing.assert_allclose(left[m[:-2] + "_l"], p, rtol=1e-2)
    one_leg = example.calibration_trials["ankle"]["motion"].parent
    args = parser.parse_args(["calibrate-passive", "--model", str(example.calibration_model), "--trials",
                              str(one_leg), "--side", "both", "--out", str(tmp_path / "none")])
    with pytest.raises(InputFileError, match="ankle_angle_l"):
        args.func(args)
    assert not (tmp_path / "none").exists()
