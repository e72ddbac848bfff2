"""EMG-informed single-trial solves on the example's normal trial (the problem core with the EMG goals).

``musclemetab solve --workflow effort-cal --emg E.mot --emg-mode constrained|driven``: every tracked
excitation must lie within the tolerance of its scaled EMG at every control node (0.01 constrained,
0 driven), with the EMG interpolated here from the EMG file; the joint moments, Hill equilibrium and
activation dynamics are checked with the independent equations of ``mrs_reference``.
"""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest
from mrs_reference import DOFS, check_solution_satisfies_problem, mesh_inputs

N = 118  # mesh intervals of the normal trial (100 per second)
AUTHORS_CHANNELS = {"bflh_r": "BF", "semiten_r": "ST", "vaslat_r": "VL", "vasmed_r": "VM", "tibant_r": "TA",
                    "gaslat_r": "GL", "gasmed_r": "GM", "soleus_r": "SO", "vasint_r": "ES"}


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("informed_geometry")


def _solve(example, cache_dir, out, mode, *extra):
    from musclemetab.cli import main

    argv = ["solve", "--workflow", "effort-cal", "--model", str(example.model), "--ik", str(example.ik["normal"]),
            "--id", str(example.id["normal"]), "--emg", str(example.emg["normal"]), "--emg-mapping", "authors",
            "--emg-mode", mode, "--cache-dir", str(cache_dir), "--out", str(out), *extra]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(argv)
    assert code == 0, buf.getvalue()
    from musclemetab.redundancy import Solution

    return Solution.load(out)


@pytest.fixture(scope="module")
def constrained(example, cache_dir, tmp_path_factory):
    return _solve(example, cache_dir, tmp_path_factory.mktemp("constrained") / "sol", "constrained")


@pytest.fixture(scope="module")
def driven(example, cache_dir, tmp_path_factory):
    return _solve(example, cache_dir, tmp_path_factory.mktemp("driven") / "sol", "driven")


def _deviation(example, sol):
    from musclemetab.io import read_storage

    rec = sol.summary["emg_tracking"]
    muscles = sorted(rec)
    emg = read_storage(example.emg["normal"])
    te = emg.index.to_numpy()
    E = np.column_stack([np.interp(sol.time_s[:N], te, emg[AUTHORS_CHANNELS[m]].to_numpy()) for m in muscles])
    s = np.array([rec[m]["scale"] for m in muscles])
    e = sol.excitation[:N, [sol.muscles.index(m) for m in muscles]]
    return e - s * E, muscles, s


@pytest.mark.opensim
@pytest.mark.slow
def test_emg_constrained_excitations_stay_in_the_band(example, constrained):
    sol = constrained
    assert sol.success and sol.summary["workflow"]["name"] == "effort-cal emg-constrained"
    dev, muscles, s = _deviation(example, sol)
    assert muscles == sorted(AUTHORS_CHANNELS)
    assert np.max(np.abs(dev)) <= 0.01 + 1e-6
    assert np.max(np.abs(dev)) > 0.009  # the band is active: the EMG shapes the solution
    # the couplings of the EMG scale factors (vasti, gastrocnemii) hold and the bounds are kept
    assert s[muscles.index("vaslat_r")] == pytest.approx(s[muscles.index("vasmed_r")], abs=1e-9)
    assert s[muscles.index("gaslat_r")] == pytest.approx(s[muscles.index("gasmed_r")], abs=1e-9)
    assert np.all((s >= 0.05 - 1e-9) & (s <= 2.5 + 1e-9))
    # effort-cal weights, nominal tendon stiffness, calibrated passive muscle
    assert sol.summary["solver_options"]["w_activation"] == 1.0
    assert "emg_tracking" in sol.summary["objective_terms"]
    assert sol.summary["objective_terms"]["emg_tracking"] == 0.0  # no tracking cost in this mode


@pytest.mark.opensim
@pytest.mark.slow
def test_emg_constrained_solution_satisfies_the_problem(example, constrained, cache_dir):
    from musclemetab.geometry import compute_geometry

    g = compute_geometry(example.model, example.ik["normal"], dofs=list(DOFS), cache_dir=cache_dir)
    t, lmt, r, mom = mesh_inputs(example, g, "normal", N)
    check_solution_satisfies_problem(constrained, t, lmt, r, mom, N)


@pytest.mark.opensim
@pytest.mark.slow
@pytest.mark.xfail(run=False, reason="EMG-driven (tolerance 0) with the authors' mapping on the normal trial ends "
                   "in Infeasible_Problem_Detected after 633 iterations (effort-cal, free EMG scale factors); "
                   "not yet understood, see docs/problem.md")
def test_emg_driven_excitations_equal_the_scaled_emg(example, driven):
    assert driven.success and driven.summary["workflow"]["name"] == "effort-cal emg-driven"
    dev, _, _ = _deviation(example, driven)
    assert np.max(np.abs(dev)) <= 1e-6


def test_emg_options_without_emg_are_refused(example, tmp_path):
    from musclemetab.cli import main

    argv = ["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
            str(example.id["normal"]), "--emg-mode", "driven", "--out", str(tmp_path / "x")]
    buf = io.StringIO()
    with contextlib.redirect_stderr(buf), contextlib.redirect_stdout(buf):
        code = main(argv)
    assert code != 0 and "--emg-mode" in buf.getvalue() and "--emg" in buf.getvalue()
    assert not (tmp_path / "x").exists()


@pytest.mark.opensim
@pytest.mark.slow
def test_metabolics_of_a_solution_object_equal_those_of_its_folder(example, constrained, tmp_path):
    """``metabolics_from_solution`` takes the Solution object as well as the folder it writes."""
    from musclemetab.metabolics.solution import metabolics_from_solution

    folder = constrained.write(tmp_path / "sol")
    kw = dict(models="UM10,BH04", speed_m_per_s=1.3)
    a = metabolics_from_solution(constrained, example.body_mass_kg, example.height_m, **kw)
    b = metabolics_from_solution(folder, example.body_mass_kg, example.height_m, **kw)
    assert a.muscles == b.muscles and a.models == b.models
    ca, cb = a.columns(), b.columns()
    assert list(ca) == list(cb)
    for k in ca:  # the folder holds the same states to the storage file's precision
        np.testing.assert_allclose(ca[k], cb[k], rtol=1e-7, atol=1e-9, err_msg=k)
