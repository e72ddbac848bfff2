"""The energy goal of the muscle redundancy problem (``docs/energy_objective.md``).

* its value is the NumPy smooth model, evaluated here on the mesh variables with the
  independent muscle curves of ``mrs_reference`` and summed by hand;
* its gradient and Hessian, as assembled for IPOPT, against central finite differences;
* one converged solve of the example's normal trial, window 0.6-0.8 s (EFFORT-CAL settings): residuals within
  1e-4 N m, the recorded term equal to the smooth model summed over the solution, less
  energy than the effort-minimising optimum; the command line's options.
"""

from __future__ import annotations

import types
import warnings
from pathlib import Path

import numpy as np
import pytest
from mrs_reference import fl_ref, fpe_ref, fv_ref

from musclemetab.errors import MusclemetabWarning, OptionError
from musclemetab.metabolics.smooth import WORK_AND_HEAT
from musclemetab.io import read_storage
from musclemetab.redundancy import inputs as I
from musclemetab.redundancy import workflows as W

DOFS = I.DEFAULT_DOFS
MASS, HEIGHT = 72.6, 1.743  # the example subject


def _goal(model="UM10", weight=2.0, **kw):
    from musclemetab.redundancy.energy import EnergyGoal

    return EnergyGoal(model, weight, MASS, HEIGHT, **kw)


def _rates_by_hand(model, smoothing, muscles, params, e, a, lm, vm, **options):
    """Summed smooth rate (W, no basal) per node: states ``(nodes, muscles)``, curves of
    ``mrs_reference``, masses and slow-twitch fractions of the muscle table; ``options`` of the
    smooth model (the objective form of UM03, BH04, HO06, UC16: ``non_negative=WORK_AND_HEAT``)."""
    from musclemetab.metabolics.smooth import smooth_rates
    from musclemetab.properties import metabolic_properties

    p = params.subset(muscles)
    mass, fst = metabolic_properties(muscles, MASS, HEIGHT, p.max_isometric_force_N, p.optimal_fiber_length_m)
    vbar = vm / p.max_contraction_velocity
    f0 = p.max_isometric_force_N
    r = smooth_rates(model, e, a, lm, vbar, fl_ref(lm), fv_ref(vbar),
                     f0 * fpe_ref(lm, p.passive_kpe, p.passive_s0, p.passive_sm), f0, p.optimal_fiber_length_m,
                     p.max_contraction_velocity, mass, fst, smoothing=smoothing, basal=False, **options)
    return r["total"].sum(axis=1)


def reference_model_parameters(t):
    """The example subject's muscle parameters of the published table (``reference_table``), as
    a model's parameters (names, F0, lMo, lTs, pennation, vmax)."""
    return types.SimpleNamespace(
        names=list(t.index), max_isometric_force_N=t.max_isometric_force_N_sub1.to_numpy(),
        optimal_fiber_length_m=t.optimal_fiber_length_m_sub1.to_numpy(),
        tendon_slack_length_m=t.tendon_slack_length_m_sub1.to_numpy(),
        pennation_angle_at_optimal_rad=t.pennation_angle_at_optimal_rad.to_numpy(),
        max_contraction_velocity=t.max_contraction_velocity_lMo_per_s.to_numpy())


@pytest.fixture(scope="module")
def small_problem(example, reference_table):
    """The normal trial's first 31 frames (EFFORT-CAL muscles, geometry of the study's
    MuscleAnalysis): inputs, parameters and guess, without OpenSim."""
    from musclemetab.redundancy.static_opt import initial_guess, static_optimisation

    folder = example.reference_muscle_analysis
    L = read_storage(folder / "IK_sub1_normal_MuscleAnalysis_Length.sto")
    names = list(L.columns)
    r = np.stack([read_storage(folder / f"IK_sub1_normal_MuscleAnalysis_MomentArm_{d}.sto")[names].to_numpy()
                  for d in DOFS], axis=1)
    model_params = reference_model_parameters(reference_table)
    t_ik, _ = I.read_kinematics(example.ik["normal"])
    t_id, mom = I.read_inverse_dynamics(example.id["normal"])
    km, _ = I.select_muscles(names, r, DOFS)
    muscles = [names[i] for i in km]
    F = 31
    geo = types.SimpleNamespace(time=L.index.to_numpy()[:F], muscles=muscles, dofs=DOFS,
                                lmt_m=L.to_numpy()[:F, km], moment_arms_m=r[:F, :, km])
    params, _ = W.workflow_parameters("effort-cal", model_params, muscles)
    inp = I.trial_inputs(geo, t_id, mom, ik_time_s=t_ik[:F])
    return inp, params, initial_guess(inp, params, static_optimisation(inp, params))


def _nlp(small_problem, goal):
    from musclemetab.redundancy.ipopt import SolverOptions, build_nlp
    from musclemetab.redundancy.goals import Goals

    inp, params, guess = small_problem
    return build_nlp(inp, params, guess, SolverOptions(), Goals(energy=goal))


def _point(nlp, seed=3):
    rng = np.random.default_rng(seed)
    return np.clip(nlp["x0"] + 0.01 * rng.normal(size=nlp["x0"].size), nlp["lbx"] + 1e-3,
                   np.minimum(nlp["ubx"], 1e3) - 1e-3)


VALUE_CASES = [("UM10", "objective", {}), ("BH04", "objective", {"non_negative": WORK_AND_HEAT}),
               ("BH04", "model", {}), ("MA68", "objective", {})]


@pytest.mark.parametrize("model, form, options", VALUE_CASES, ids=[f"{m}-{f}" for m, f, _ in VALUE_CASES])
def test_goal_value_is_the_smooth_model_summed_by_hand(small_problem, model, form, options):
    """With and without the goal, the objectives differ by ``w (1/N) sum_k sum_m Edot / m_body``;
    BH04's objective form is the smooth model with its rule on the work plus the
    shortening/lengthening heat, its model form the smooth model as defined."""

    inp, params, _ = small_problem
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MusclemetabWarning)  # the model form's warning (tested below)
        goal = _goal(model, weight=2.0, form=form)
    with_goal, without = _nlp(small_problem, goal), _nlp(small_problem, None)
    x = _point(with_goal)
    f1 = float(with_goal["grad_f"](x, with_goal["p_values"])[0])
    f0 = float(without["grad_f"](x, without["p_values"])[0])
    M, D, N = len(inp.muscles), len(inp.dofs), inp.n_intervals
    Z = x[:(5 * M + D) * N].reshape(N, 5 * M + D)
    a, lm, e, vm = Z[:, 0:M], Z[:, M:2 * M], Z[:, 3 * M:4 * M], Z[:, 4 * M + D:]
    by_hand = 2.0 * np.sum(_rates_by_hand(model, goal.smoothing, inp.muscles, params, e, a, lm, vm, **options)) / (N * MASS)
    assert by_hand > 0.1  # a real metabolic rate: W/kg of body mass, one leg
    assert f1 - f0 == pytest.approx(by_hand, rel=1e-9)


@pytest.mark.parametrize("model", ["UM10", "BH04"])
def test_goal_derivatives_against_finite_differences(small_problem, model):
    """Gradient and Hessian of the objective with the goal, as assembled for IPOPT from the
    per-interval derivatives, against central differences along random directions."""

    nlp = _nlp(small_problem, _goal(model, weight=2.0, effort_weight=0.0))
    x = _point(nlp, seed=5)
    p = nlp["p_values"]
    n = x.size
    lam = np.zeros(nlp["n_constraints"])

    def f(y):
        return float(nlp["grad_f"](y, p)[0])

    def grad(y):
        return np.asarray(nlp["grad_f"](y, p)[1]).ravel()

    U = nlp["hess_lag"](x, p, 1.0, lam).sparse()  # upper triangle
    H = (U + U.T).toarray() - np.diag(U.diagonal())
    g = grad(x)
    rng = np.random.default_rng(11)
    lo, hi = nlp["lbx"], np.minimum(nlp["ubx"], 1e3)
    for _ in range(3):
        d = rng.normal(size=n)
        d /= np.linalg.norm(d)
        eps = 1e-6
        assert np.all(x + eps * d < hi) and np.all(x - eps * d > lo)
        fd = (f(x + eps * d) - f(x - eps * d)) / (2 * eps)
        assert fd == pytest.approx(g @ d, rel=1e-6, abs=1e-9)
        hd = (grad(x + eps * d) - grad(x - eps * d)) / (2 * eps)
        np.testing.assert_allclose(H @ d, hd, rtol=1e-5, atol=1e-6 * np.max(np.abs(hd)))


def test_energy_goal_options_are_checked():
    with pytest.raises(OptionError, match="unknown metabolic model 'XX99'"):
        _goal("XX99")
    with pytest.raises(OptionError, match="weight"):
        _goal(weight=-1.0)
    with pytest.raises(OptionError, match="effort weight"):
        _goal(effort_weight=float("nan"))
    with pytest.raises(OptionError, match="smoothing"):
        _goal(smoothing=0.0)
    with pytest.raises(OptionError, match="kilograms"):
        from musclemetab.redundancy.energy import EnergyGoal

        EnergyGoal("UM10", 1.0, 72600.0, HEIGHT)
    with pytest.raises(OptionError, match="unknown form 'exact'; choose one of objective, model"):
        _goal(form="exact")
    with pytest.raises(OptionError, match="drop the option non_negative"):
        _goal("BH04", options={"non_negative": False})


def test_goal_forms_and_their_record():
    """The objective form moves the non-negativity rule of UM03, BH04, HO06, UC16 to the work
    plus shortening/lengthening heat; the model form keeps it and warns; the other models have
    no rule and one form."""
    for model in ("UM03", "BH04", "HO06", "UC16"):
        goal = _goal(model)
        assert goal.form == "objective" and goal.smooth_options() == {"non_negative": WORK_AND_HEAT}
        assert goal.form_record() == {"model": model, "form": "objective", "smoothing": 1e-3,
                                      "non_negativity": "max(W + H_SL, 0): work plus shortening/lengthening heat"}
        with pytest.warns(MusclemetabWarning, match=f"energy goal {model} in its model form.*lengthening muscle"):
            model_form = _goal(model, form="model")
        assert model_form.smooth_options() == {} and model_form.form_record()["non_negativity"].startswith("max(total")
    for model in ("UM10", "LW07", "LW05", "MA68"):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no warning in either form
            assert _goal(model).smooth_options() == _goal(model, form="model").smooth_options() == {}
        assert _goal(model, smoothing=1e-2).form_record()["non_negativity"] == "none (the model has none)"


#: the metabolic models' arguments on the example's normal trial (EFFORT-GEN solution, 40
#: muscles x 108 nodes; see tests/test_metabolics_smooth.py)
STATES_NPZ = Path(__file__).parent / "data" / "example_normal_effort_gen_metabolic_inputs.npz"


def test_goal_smoothing_bias_below_two_percent_on_the_example_states():
    """At the goal's default smoothing, each model's smooth goal form summed over the example's
    muscles and nodes is within 2 % of the exact model functions (``musclemetab.metabolics``) in
    the same form: the model itself, or ``H_AM + max(W + H_SL, 0)`` of the model without its rule.
    BH04 and LW05 at the steady-state stimulation time, LW05 at ``dF_CE/dt = 0``, as the goal."""
    from musclemetab.metabolics import ALL_MODELS
    from musclemetab.metabolics.smooth import smooth_rates
    from musclemetab.redundancy.energy import CLAMPED_MODELS, ENERGY_SMOOTHING

    data = np.load(STATES_NPZ)
    s = {k: data[k] for k in data.files if k != "time_s"}
    columns = {k: (v[:, None] if v.ndim == 1 else v) for k, v in s.items()}
    assert ENERGY_SMOOTHING == 1e-3
    for model in ALL_MODELS:
        goal = _goal(model)
        smooth = smooth_rates(model, **columns, smoothing=goal.smoothing, basal=False, **goal.smooth_options())
        kw = {"basal": False}
        if model == "BH04":  # heat off below e = 0.1, as the smooth model's gate
            kw["stimulation_time_s"] = np.where(s["excitation"] > 0.1, np.inf, 0.0)
        if model == "LW05":
            kw.update(stimulation_time_s=np.inf, fiber_force_rate_N_per_s=0.0)
        if model in CLAMPED_MODELS:
            r = ALL_MODELS[model](**s, non_negative=False, **kw)
            exact = r.activation_maintenance + np.maximum(r.work + r.shortening_lengthening, 0.0)
        else:
            exact = ALL_MODELS[model](**s, **kw).total
        assert np.sum(exact) > 1000.0  # W summed over 108 nodes: a real rate
        bias = np.sum(smooth["total"]) / np.sum(exact) - 1.0
        assert abs(bias) < 0.02, (model, bias)


#: the solved window of the normal trial (s): a fifth of a second of stance, a quick problem
WINDOW = (0.6, 0.8)


@pytest.mark.opensim
def test_energy_solve_of_the_normal_trial_converges(example):
    """EFFORT-CAL settings, effort plus 0.001 x the BH04 goal (objective form, smoothing 0.01, a
    quick solve) on the window 0.6-0.8 s of the normal trial: converged, moments met, the recorded term is the smooth model over the solution,
    the mixed objective is lower than at the effort optimum, and so is BH04's rate, while no
    muscle that lengthens is saturated (activation >= 0.95) anywhere in the solved window: with
    the effort goal beside it, the energy goal shares the load (docs/energy_objective.md). The
    command line gives the same solve."""
    from musclemetab.redundancy import Goals, solve_files

    effort = solve_files(example.model, example.ik["normal"], example.id["normal"], "effort-cal", window=WINDOW)
    goal = _goal("BH04", weight=1e-3, smoothing=0.01)
    sol = solve_files(example.model, example.ik["normal"], example.id["normal"], "effort-cal",
                      goals=Goals(energy=goal), window=WINDOW)
    s = sol.summary
    assert s["success"] and s["max_moment_residual_Nm"] <= 1e-4
    N = s["n_intervals"]
    p = sol.parameters

    def leg_W_per_kg(x):
        return np.mean(_rates_by_hand("BH04", goal.smoothing, list(x.muscles), p, x.excitation[:N],
                                      x.activation[:N], x.lm_norm[:N], x.fiber_velocity_lmo_per_s[:N],
                                      non_negative=WORK_AND_HEAT)) / MASS

    energy = leg_W_per_kg(sol)
    assert s["objective_terms"]["energy"] == pytest.approx(1e-3 * energy, rel=1e-9)
    assert s["energy_goal"]["leg_mean_W_per_kg"] == pytest.approx(energy, rel=1e-9)
    assert s["energy_goal"]["model"] == "BH04" and s["solver_options"]["energy"]["weight"] == 1e-3
    assert sol.record.energy_form == s["energy_form"] == {
        "model": "BH04", "form": "objective", "smoothing": 0.01,
        "non_negativity": "max(W + H_SL, 0): work plus shortening/lengthening heat"}
    # less energy than the effort optimum it started from, and a lower mixed objective than there
    assert energy < leg_W_per_kg(effort) - 0.05
    assert s["objective"] == pytest.approx(sum(s["objective_terms"].values()), rel=1e-9)
    assert s["objective"] < effort.summary["objective"] + 1e-3 * leg_W_per_kg(effort)
    # no lengthening muscle saturated, at any node of the window (padding included), nor flagged
    lengthening = sol.fiber_velocity_lmo_per_s[:N] > 0
    saturated = (sol.activation[:N] >= 0.95) & lengthening
    assert lengthening.any(axis=0).sum() >= len(sol.muscles) // 2 and not saturated.any()
    assert "saturated_lengthening" not in {f.code for f in sol.record.flags}


@pytest.mark.opensim
def test_energy_goal_from_the_command_line(example, tmp_path, capsys):
    """``solve --energy-model``: the same problem as the Python call above (one solve per
    session), its goal in summary.json; bad combinations stop before any work."""
    import json

    from musclemetab.commands import main

    base = ["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
            str(example.id["normal"]), "--workflow", "effort-cal", "--window", f"{WINDOW[0]}:{WINDOW[1]}"]
    out = tmp_path / "energy"
    assert main(base + ["--energy-model", "bh04", "--energy-weight", "0.001", "--energy-smoothing", "0.01",
                        "--mass", "72.6", "--height", "1.743", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    s = json.loads((out / "summary.json").read_text())
    assert s["energy_goal"]["model"] == "BH04" and s["energy_goal"]["w_activation"] == 1.0
    assert f"BH04 (smooth, one leg, no basal) {s['energy_goal']['leg_mean_W_per_kg']:.3f} W/kg" in printed
    assert s["objective_terms"]["energy"] == pytest.approx(1e-3 * s["energy_goal"]["leg_mean_W_per_kg"], rel=1e-12)
    for extra, words in ((["--energy-weight", "1"], ["--energy-weight", "--energy-model"]),
                         (["--energy-form", "model"], ["--energy-form", "--energy-model"]),
                         (["--energy-model", "UM10", "--height", "1.743"], ["--mass"]),  # the height is optional
                         (["--energy-model", "UM99", "--mass", "72.6", "--height", "1.743"], ["UM99", "UM10"]),
                         (["--energy-model", "UM10", "--mass", "72.6", "--height", "1.743", "--energy-smoothing",
                           "0"], ["--energy-smoothing", "positive"]),
                         (["--energy-model", "UM10", "--mass", "72.6", "--height", "1.743", "--effort-weight",
                           "-1"], ["--effort-weight"])):
        bad = tmp_path / "bad"
        assert main(base + extra + ["--out", str(bad)]) != 0
        err = capsys.readouterr().err
        assert all(w in err for w in words), err
        assert len(err.strip().splitlines()) == 1 and not bad.exists()


def test_emg_solves_refuse_the_energy_goal():
    """The energy goal is one of the goals (``Goals.energy``), which EMG-TEN and EMG-informed
    settings refuse; the solver options hold none (a ``TypeError``, as for any unknown field)."""
    from musclemetab.redundancy import Goals, SolverOptions
    from musclemetab.redundancy.emg_ten import EmgTenSettings

    with pytest.raises(OptionError, match="no energy goal"):
        EmgTenSettings(goals=Goals(energy=_goal()))
    with pytest.raises(TypeError):
        SolverOptions(energy=_goal())
