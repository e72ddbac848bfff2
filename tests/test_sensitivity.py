"""Sensitivities of the rates to the muscle parameters (``musclemetab.redundancy.sensitivity``):
the parameter derivatives of the problem against finite differences of the problem built with
other parameters, the rates' derivatives against central differences of re-solves (the full
table of F0, lMo, lTs, kT of soleus and vastus lateralis is ``benchmarks/sensitivity.py``),
the nominal rates against the metabolics of the polished solution, the ranked table and the
command line."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

MASS, HEIGHT = 72.6, 1.743
PAIRS = [("lTs", "soleus_r"), ("kT", "vaslat_r"), ("F0", "vaslat_r"), ("sM", "soleus_r")]


@pytest.fixture(scope="module")
def normal(example, tmp_path_factory):
    """The normal trial's EFFORT-GEN solution (solved once per test run), its folder, the rebuilt
    problem and the sensitivities of UM10 and BH04 to :data:`PAIRS`."""
    from musclemetab.redundancy import solve_files
    from musclemetab.redundancy.sensitivity import problem_of_solution, trial_sensitivity

    solution = solve_files(example.model, example.ik["normal"], example.id["normal"], "effort-gen")
    folder = solution.write(tmp_path_factory.mktemp("sens") / "normal")
    prob = problem_of_solution(folder)
    sens = trial_sensitivity(prob.solution, prob.inputs, prob.params, prob.goals, body_mass_kg=MASS, height_m=HEIGHT,
                             models="UM10,BH04", parameters=PAIRS, trial="normal")
    return folder, prob, sens


@pytest.mark.opensim
def test_parameter_derivatives_are_those_of_the_problem(normal):
    """d(grad L)/ds and dg/ds against central differences of the problem built with the
    parameter scaled by 1 +- 1e-6 (constraints and Lagrangian gradient at the same point)."""
    import casadi as ca

    from musclemetab.redundancy.sensitivity import PARAMETERS, _scaled, parameter_derivatives
    from musclemetab.redundancy.static_opt import guess_from_solution
    from musclemetab.redundancy.transcription import TrialBlock, build_problem

    _, prob, sens = normal
    params = prob.params.subset(prob.inputs.muscles)
    guess = guess_from_solution(prob.solution, prob.inputs, params)
    rng = np.random.default_rng(0)
    lam = rng.normal(size=build_problem([TrialBlock("t", prob.inputs, guess)], params, prob.goals)["lbg"].size)
    x = sens.x
    pairs = [("lMo", "soleus_r"), ("alpha0", "gasmed_r")]
    ng = 4 * len(params.names) + len(prob.inputs.dofs)
    dL, dg = parameter_derivatives(prob.inputs, params, prob.goals, 150.0, x, lam, ng, pairs)
    h = 1e-6
    for c, (p, m) in enumerate(pairs):
        values = []
        for sign in (1, -1):
            scale = np.zeros(len(params.names))
            scale[params.names.index(m)] = sign * h
            nlp = build_problem([TrialBlock("t", prob.inputs, guess)], _scaled(params, {PARAMETERS[p]: scale}),
                                prob.goals)
            g, J = nlp["jac_g"](x, nlp["p_values"])
            grad = nlp["grad_f"](x, nlp["p_values"])[1]
            values.append((np.asarray(g).ravel(), np.asarray(grad + ca.mtimes(J.T, ca.DM(lam))).ravel()))
        fd_g = (values[0][0] - values[1][0]) / (2 * h)
        fd_L = (values[0][1] - values[1][1]) / (2 * h)
        assert np.max(np.abs(fd_g)) > 1e-4, (p, m)  # the parameter is in the problem
        assert np.max(np.abs(dg[:, c].toarray().ravel() - fd_g)) <= 1e-5 * np.max(np.abs(fd_g)), (p, m)
        # (w = lMo sin(alpha0) enters the pennation identity alone, whose gradient it leaves: 0 for alpha0)
        assert (np.max(np.abs(fd_L)) > 1e-6) == (p != "alpha0"), (p, m)
        assert np.max(np.abs(dL[:, c].toarray().ravel() - fd_L)) <= 1e-5 * np.max(np.abs(fd_L)) + 1e-12, (p, m)


@pytest.mark.opensim
def test_rate_derivatives_agree_with_resolves(normal):
    """d rate/d log p of the tendon slack length of soleus (the largest of the benchmark's table)
    against [R(1.001 p) - R(0.999 p)]/0.002 of two re-solves at tolerance 1e-10: the whole-body
    rates of UM10 and BH04 within 5 % + 0.01 W/kg (per unit log p; the benchmark's worst,
    BH04, differs by 2.6 %) and soleus' own rate within 15 % (the weakly active bounds of
    muscles that are off make the re-solves' derivative one-sided, docs/uncertainty.md)."""
    from musclemetab.redundancy.sensitivity import finite_difference

    _, prob, sens = normal
    wb, per = finite_difference(prob.inputs, prob.params, prob.goals, sens.x, "lTs", "soleus_r",
                                prob.solution.summary, step=1e-3, body_mass_kg=MASS, height_m=HEIGHT,
                                models="UM10,BH04")
    i = sens.muscles.index("soleus_r")
    for model in ("UM10", "BH04"):
        k = sens.derivative(model, "lTs", "soleus_r")
        assert abs(wb[model]) > 1.0  # the check is not of a vanishing derivative
        assert abs(k - wb[model]) <= 0.05 * abs(wb[model]) + 0.01, (model, k, wb[model])
        ks = sens.derivative(model, "lTs", "soleus_r", rate="soleus_r")
        assert abs(ks - per[model][i]) <= 0.15 * abs(per[model][i]), (model, ks, per[model][i])


@pytest.mark.opensim
def test_nominal_rates_are_the_metabolics_of_the_polished_optimum(normal):
    """The rates the derivatives are of: metabolics_from_solution of the solution at the
    polished optimum (its states written into a Solution), to 1e-9."""
    from dataclasses import replace

    from musclemetab.metabolics.solution import metabolics_from_solution
    from musclemetab.redundancy.sensitivity import _guess_of

    _, prob, sens = normal
    g = _guess_of(sens.x, prob.inputs)
    N = prob.inputs.n_intervals
    sol = prob.solution
    polished = replace(sol, activation=g.activation, lm_norm=g.lm_norm,
                       excitation=np.vstack([g.excitation, g.excitation[-1:]]),
                       fiber_velocity_lmo_per_s=np.vstack([g.fiber_velocity_lmo_per_s, g.fiber_velocity_lmo_per_s[-1:]]))
    from musclemetab.redundancy.solution import derived_quantities

    d = derived_quantities(sol.parameters, polished.activation, polished.lm_norm, polished.fiber_velocity_lmo_per_s,
                           prob.inputs.lmt_m)
    polished = replace(polished, active_force_length_multiplier=d["active_force_length_multiplier"],
                       force_velocity_multiplier=d["force_velocity_multiplier"],
                       passive_fiber_force_N=d["passive_fiber_force_N"])
    res = metabolics_from_solution(polished, MASS, HEIGHT, models="UM10,BH04")
    assert g.activation.shape == (N + 1, len(sol.muscles))
    for model in ("UM10", "BH04"):
        assert sens.nominal_whole_body[model] == pytest.approx(res.whole_body[model].mean_W_per_kg, rel=1e-9)
        t = res.time_s
        mean = np.trapezoid(res.rates[model].total_without_basal(), t, axis=-1) / res.whole_body[model].duration_s
        np.testing.assert_allclose(sens.nominal_per_muscle[model], mean, rtol=1e-9)


@pytest.mark.opensim
def test_ranked_table_and_command_line(normal, tmp_path, capsys):
    """The ranked table: per model and rate the rows by |d rate/d log p|, change per 1 % the
    derivative over 100, written as sensitivity.csv; ``metabolics --sensitivity`` refuses unknown
    parameters before any work (its run on the normal trial: docs/uncertainty.md)."""
    from musclemetab.commands import main
    from musclemetab.redundancy.sensitivity import SENSITIVITY_COLUMNS, ranked_table, write_sensitivity

    folder, prob, sens = normal
    df = ranked_table([sens])
    assert tuple(df.columns) == SENSITIVITY_COLUMNS
    assert len(df) == 2 * (1 + len(sens.muscles)) * len(PAIRS)
    wb = df[(df.model == "UM10") & (df.rate == "whole_body")]
    assert list(wb.parameter_rank) == [1, 2, 3, 4]
    assert list(wb.d_rate_d_log_p.abs()) == sorted(wb.d_rate_d_log_p.abs(), reverse=True)
    row = wb[(wb.parameter == "lTs") & (wb.muscle == "soleus_r")].iloc[0]
    assert row.d_rate_d_log_p == sens.derivative("UM10", "lTs", "soleus_r")
    assert row.change_per_1pct == pytest.approx(row.d_rate_d_log_p / 100, rel=1e-15)
    assert row.parameter_value == prob.params.tendon_slack_length_m[prob.params.names.index("soleus_r")]
    assert main(["metabolics", "--solution", str(folder), "--mass", "72.6", "--sensitivity", "F0,tau",
                 "--out", str(tmp_path / "bad")]) != 0
    assert "unknown muscle parameter(s) tau" in capsys.readouterr().err and not (tmp_path / "bad").exists()
    path = write_sensitivity([sens], tmp_path / "met")
    csv = pd.read_csv(path)
    assert path.name == "sensitivity.csv" and len(csv) == len(df)
    got = csv[(csv.model == "BH04") & (csv.rate == "soleus_r") & (csv.parameter == "lTs")].iloc[0]
    assert got.d_rate_d_log_p == pytest.approx(sens.derivative("BH04", "lTs", "soleus_r", rate="soleus_r"), rel=1e-9)


def test_sensitivity_of_a_failed_solve_is_refused_without_pointing_to_allow_failed(normal, tmp_path, capsys):
    """``metabolics --sensitivity --allow-failed`` on a failed solve told the user to pass
    ``--allow-failed``: the sensitivities are derivatives at an optimum the solve did not reach,
    so the option is refused before any work, saying so; the rates alone are still computed."""
    import json
    import shutil

    from musclemetab.commands import main

    folder, _, _ = normal
    failed = shutil.copytree(folder, tmp_path / "failed")
    summary = json.loads((failed / "summary.json").read_text())
    summary.update(success=False, status="Maximum_Iterations_Exceeded")
    (failed / "summary.json").write_text(json.dumps(summary))
    base = ["metabolics", "--solution", str(failed), "--mass", "72.6", "--height", "1.743"]
    for extra in (["--allow-failed"], []):
        assert main(base + ["--sensitivity", "F0", *extra, "--out", str(tmp_path / "s")]) != 0
        err = capsys.readouterr().err
        assert "--sensitivity: the stored solve" in err and "Maximum_Iterations_Exceeded" in err
        assert "use --allow-failed" not in err and not (tmp_path / "s").exists()
    assert main(base + ["--allow-failed", "--out", str(tmp_path / "m")]) == 0
    assert (tmp_path / "m" / "whole_body.csv").is_file()
