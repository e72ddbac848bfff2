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
def cache_dir(geometry_cache):
    """The test run's geometry cache: the normal trial through OpenSim once per run."""
    return geometry_cache


def _solve(example, cache_dir, out, mode, *extra):
    """The solve as the command line makes it; labelled as a study labels its trial units, so that
    the test run solves the problem once for this module and ``test_study_emg_modes``."""
    from musclemetab.commands import main

    argv = ["solve", "--workflow", "effort-cal", "--model", str(example.model), "--ik", str(example.ik["normal"]),
            "--id", str(example.id["normal"]), "--emg", str(example.emg["normal"]), "--emg-mapping", "authors",
            "--emg-mode", mode, "--labels", "normal", "--cache-dir", str(cache_dir), "--out", str(out), *extra]
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
def test_emg_driven_excitations_equal_the_scaled_emg(example, driven, cache_dir):
    """EMG-driven (tolerance 0) converges with the backward-Euler fiber dynamics: every tracked
    excitation is its scaled EMG (interpolated here from the EMG file) at every control node, and
    the problem of that scheme holds, checked with the independent equations of ``mrs_reference``."""
    from musclemetab.geometry import compute_geometry

    sol = driven
    assert sol.success and sol.summary["workflow"]["name"] == "effort-cal emg-driven"
    assert sol.summary["fiber_dynamics"] == "backward"
    dev, muscles, s = _deviation(example, sol)
    assert muscles == sorted(AUTHORS_CHANNELS)
    assert np.max(np.abs(dev)) <= 1e-8
    assert s[muscles.index("vaslat_r")] == pytest.approx(s[muscles.index("vasmed_r")], abs=1e-9)
    assert np.all((s >= 0.05 - 1e-9) & (s <= 2.5 + 1e-9))
    assert sol.summary["max_hill_residual"] < 1e-4  # recomputed with the scheme's pairing
    g = compute_geometry(example.model, example.ik["normal"], dofs=list(DOFS), cache_dir=cache_dir)
    t, lmt, r, mom = mesh_inputs(example, g, "normal", N)
    check_solution_satisfies_problem(sol, t, lmt, r, mom, N, backward=True)


@pytest.mark.opensim
@pytest.mark.slow
def test_fixed_excitations_make_the_fiber_recurrence_unstable(example, constrained, cache_dir):
    """Why EMG-driven (tolerance 0) needs the backward-Euler fiber dynamics (docs/problem.md):
    with the activation fixed, the Hill equilibrium gives the fiber velocity as a function of the
    fiber length, and the forward-Euler step ``l_k+1 = l_k + h vmax vbar(l_k)`` multiplies a change
    of ``l_k`` by ``g_k = 1 - h vmax (dH/dl)/(dH/dvbar)``. Worked here with the independent curves of
    ``mrs_reference`` on the constrained solution: for the weakly excited vasti and the soleus
    ``|g_k| > 1`` at (nearly) every node and the product exceeds 1/eps, i.e. forward-Euler driven
    trajectories are fixed by their initial fiber lengths beyond double precision. The backward
    step ``l_k+1 = l_k + h vmax vbar(l_k+1)`` multiplies the change by ``1/(2 - g_k)``, below 1."""
    from mrs_reference import fl_ref, fpe_ref, ft_ref, fv_ref, params_of

    from musclemetab.geometry import compute_geometry

    sol = constrained
    P = params_of(sol)
    h = sol.time_s[1] - sol.time_s[0]
    g = compute_geometry(example.model, example.ik["normal"], dofs=list(DOFS), cache_dir=cache_dir)
    _, lmt, _, _ = mesh_inputs(example, g, "normal", N)
    for m in ("vaslat_r", "vasmed_r", "soleus_r"):
        j = sol.muscles.index(m)
        lmo, w = P["lMo_m"][j], P["lMo_m"][j] * np.sin(P["alpha0_rad"][j])
        lm, a, vbar = sol.lm_norm[:N, j], sol.activation[:N, j], sol.normalized_fiber_velocity[:N, j]
        lmt_m = lmt[:N, j]

        def H(l_norm, vb):
            l_m = l_norm * lmo
            proj = np.sqrt(l_m**2 - w**2)
            fiber = a * fl_ref(l_norm) * fv_ref(vb) + fpe_ref(l_norm, P["kPE"][j], P["s0"][j], P["sM"][j])
            return fiber * proj / l_m - ft_ref((lmt_m - proj) / P["lTs_m"][j], P["kT"][j])

        d = 1e-7
        dH_dl = (H(lm + d, vbar) - H(lm - d, vbar)) / (2 * d)
        dH_dv = (H(lm, vbar + d) - H(lm, vbar - d)) / (2 * d)
        g = 1.0 - h * P["vmax_lMo_per_s"][j] * dH_dl / dH_dv
        print(m, "nodes with |g| > 1:", int(np.sum(np.abs(g) > 1)), "of", N, "g from", g.min(), "to", g.max(),
              "log10 prod |g|:", np.sum(np.log10(np.abs(g))), "backward max |1/(2-g)|:", np.max(np.abs(1 / (2 - g))))
        assert np.mean(np.abs(g) > 1.0) > 0.95, m
        assert np.sum(np.log10(np.abs(g))) > 16, m  # product of |g_k| above 1e16 > 1/eps
        assert np.all(g < 1.0), m  # lambda = (g - 1)/h < 0: the fiber dynamics are stable at every node
        assert np.all(np.abs(1.0 / (2.0 - g)) < 1.0), m  # backward Euler: every step damps


def test_an_infeasible_emg_driven_solve_says_so():
    """The message of an EMG-driven solve that IPOPT finds infeasible names the cause and the
    remedy, not an iteration limit."""
    from musclemetab.redundancy.emg_ten import emg_failure
    from musclemetab.redundancy.record import RunRecord

    rec = RunRecord(status="Infeasible_Problem_Detected", success=False, iterations=991)
    msg = str(emg_failure(rec, "driven", "the EMG-informed effort-cal solve"))
    assert "infeasible" in msg and "after 991 iterations" in msg and "--emg-mode constrained" in msg
    assert "--max-iter" not in msg and "more iterations will not help" in msg
    forward = str(emg_failure(rec, "driven", "x", "forward"))  # the unstable recurrence, and the remedy
    assert "unstable recurrence" in forward and "--fiber-dynamics" in forward and "unstable" not in msg
    stopped = RunRecord(status="Maximum_Iterations_Exceeded", success=False, iterations=3)
    assert "--max-iter" in str(emg_failure(stopped, "driven", "x"))  # a stopped solve: the limit
    assert "infeasible" in str(emg_failure(rec, "constrained", "x"))


def test_emg_options_without_emg_are_refused(example, tmp_path):
    from musclemetab.commands import main

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


def test_backward_fiber_dynamics_with_the_energy_goal_is_refused(example, tmp_path):
    """The energy goal's rates pair each node's velocity with its own state (the forward
    scheme): ``--fiber-dynamics backward --energy-model`` is refused in one line, nothing written."""
    from musclemetab.commands import main

    argv = ["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
            str(example.id["normal"]), "--fiber-dynamics", "backward", "--energy-model", "UM10", "--mass", "70",
            "--height", "1.7", "--out", str(tmp_path / "x")]
    buf = io.StringIO()
    with contextlib.redirect_stderr(buf), contextlib.redirect_stdout(buf):
        code = main(argv)
    text = buf.getvalue().strip()
    assert code != 0 and len(text.splitlines()) == 1
    assert "--fiber-dynamics" in text and "--energy-model" in text
    assert not (tmp_path / "x").exists()


@pytest.mark.opensim
@pytest.mark.slow
def test_opensim_model_prepared_while_ipopt_solves(example, constrained, cache_dir, tmp_path, monkeypatch):
    """An EMG-informed solve tells ``before_solve`` (the command line's ``prepare_opensim_files``)
    the solution's mesh, muscle parameters and DOFs before IPOPT starts, so that the OpenSim
    worker prepares the solution's model while IPOPT solves and the write finds it prepared;
    EMG-TEN, whose tendon stiffness is known only after its solve, tells nothing."""
    import warnings

    from musclemetab.opensim_bridge import call
    from musclemetab.redundancy import emg_pipeline, emg_run
    from musclemetab.redundancy.emg_ten import informed_settings
    from musclemetab.redundancy.export import prepare_opensim_files, write_opensim_files
    from musclemetab.redundancy.parameters import PARAMETER_FIELDS

    class Stop(Exception):
        pass

    def stop(*args, **kwargs):
        raise Stop

    files = ([example.ik["normal"]], [example.id["normal"]], [example.emg["normal"]])
    informed = dict(emg_mapping="authors", workflow="effort-cal", cache_dir=cache_dir,
                    settings=informed_settings("effort-cal", "constrained"))
    # the command line's solution (the session's memo: the problem of the `constrained` fixture), with the
    # warnings that solve gives (caught here, not passed on)
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        sol = next(iter(emg_run.solve_emg_ten(example.model, *files, **informed).solutions.values()))
    np.testing.assert_allclose(sol.excitation, constrained.excitation, rtol=1e-9, atol=1e-12)  # (its file: 12 digits)
    monkeypatch.setattr(emg_pipeline, "solve_emg_ten_ocp", stop)  # the problem up to IPOPT, not solved again
    solve = getattr(emg_run.solve_emg_ten, "__wrapped__", emg_run.solve_emg_ten)
    told = []
    with pytest.raises(Stop):
        solve(example.model, *files, **informed, before_solve=lambda **o: told.append(o))
    assert len(told) == 1
    outline = told[0]
    np.testing.assert_array_equal(outline["time_s"], sol.time_s)
    assert tuple(outline["dofs"]) == tuple(sol.dofs) and outline["parameters"].names == sol.parameters.names
    for field in PARAMETER_FIELDS:
        np.testing.assert_array_equal(getattr(outline["parameters"], field), getattr(sol.parameters, field), field)
    assert str(outline["model_path"]) == sol.record.inputs["model"] and str(outline["ik_path"]) == sol.record.inputs["ik"]
    prepare_opensim_files(**outline)
    prepared = call("solution_model:prepared_models")  # (waits for the preparation)
    write_opensim_files(sol, tmp_path / "files")
    assert call("solution_model:prepared_models") == prepared  # the write found the model prepared
    told.clear()
    with pytest.raises(Stop):
        solve(example.model, *files, emg_mapping="authors", cache_dir=cache_dir, before_solve=lambda **o: told.append(o))
    assert told == []


def test_raw_emg_read_with_emg_processing_raw(example, cache_dir, tmp_path):
    """Raw EMG built by construction from the example's envelopes E (each channel a carrier of
    amplitude max(E, 0), signed, on an offset, at 2 kHz) is refused as envelopes (it leaves
    [0, 1]) and read with ``--emg-processing raw`` (the study file's ``emg_processing``) as its
    envelope: max(E, 0) through the 6 Hz low-pass (the envelope's own filter), over its peak,
    within 0.02 over the trial's window (a channel peaking at the file's end differs there)."""
    import pandas as pd

    from musclemetab.commands import main
    from musclemetab.emg import RawEmgPath, lowpass, read_processed_emg
    from musclemetab.io import read_storage, write_storage
    from musclemetab.redundancy.emg_inputs import mapped_emg_table, resolve_emg_mapping

    env = read_processed_emg(example.emg["normal"]).clip(lower=0.0)
    t = np.arange(env.index[0], env.index[-1], 1 / 2000.0)
    raw = pd.DataFrame({c: np.interp(t, env.index, env[c]) * np.sin(2 * np.pi * (90 + 5 * j) * t + j) - 0.05
                        for j, c in enumerate(env.columns)}, index=pd.Index(t, name="time"))
    path = write_storage(tmp_path / "raw_emg.mot", raw)
    mapping = resolve_emg_mapping("authors")
    got = mapped_emg_table(RawEmgPath(path), mapping, "raw")
    smooth = lowpass(pd.DataFrame({c: np.interp(t, env.index, env[c]) for c in env.columns}, index=raw.index))
    expected = mapped_emg_table(smooth / smooth.max(), mapping, "envelopes")
    ik_t = read_storage(example.ik["normal"]).index.to_numpy()
    for m in AUTHORS_CHANNELS:
        a = np.interp(ik_t, got.index, got[m])
        b = np.interp(ik_t, expected.index, expected[m])
        assert np.max(np.abs(a - b)) < 0.02, m
    base = ["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
            str(example.id["normal"]), "--emg", str(path), "--emg-mapping", "authors", "--emg-mode", "constrained",
            "--cache-dir", str(cache_dir), "--diagnose-only", "--out", str(tmp_path / "out")]
    for extra, ok in (([], False), (["--emg-processing", "raw"], True)):
        buf = io.StringIO()
        with contextlib.redirect_stderr(buf), contextlib.redirect_stdout(buf):
            code = main(base + extra)
        assert (code == 0) == ok, buf.getvalue()
        if not ok:
            assert "outside [0, 1]" in buf.getvalue()
