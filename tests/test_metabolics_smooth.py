"""Smooth versions of the metabolic models (musclemetab.metabolics.smooth): the limit as the
smoothing parameter goes to 0, the difference from the exact models at the default
smoothing on the example subject's solution states (the numbers stated in
docs/metabolics.md), one expression for NumPy and CasADi, and CasADi's first and second
derivatives against finite differences."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from musclemetab.errors import OptionError
from musclemetab.metabolics import ALL_MODELS, STATE_ARGUMENTS
from musclemetab.metabolics.smooth import SMOOTH_MODELS, SMOOTHING, WORK_AND_HEAT, smooth_rates
from musclemetab.muscle import active_force_length, force_velocity, passive_force_length

#: The metabolic models' arguments on the example subject's normal trial: the states of the
#: EFFORT-GEN solution (``musclemetab solve --workflow effort-gen`` on the example subject's
#: model, IK_sub1_normal.mot and ID_sub1_normal.sto: Solve_Succeeded, objective 2.316791e-02),
#: trimmed as ``metabolics_from_solution`` trims them (108 nodes), with the solution's F0,
#: lMo, vmax and the package's muscle masses (72.6 kg, 1.743 m) and slow-twitch fractions.
STATES_NPZ = Path(__file__).parent / "data" / "example_normal_effort_gen_metabolic_inputs.npz"

#: Largest |smooth - exact| total rate (W, one muscle, any sample) on those states at the
#: default smoothing, as stated in docs/metabolics.md (a margin of 10 % above the measured).
MAX_DIFFERENCE_W = {
    "UM03": 0.22, "BH04": 0.28, "HO06": 0.28, "LW07": 0.004, "UM10": 0.10, "UC16": 0.29, "LW05": 0.012, "MA68": 0.0078,
}


def _random_states(n=3000, seed=0, f0=2000.0):
    rng = np.random.default_rng(seed)
    lm = rng.uniform(0.5, 1.5, n)
    vb = rng.uniform(-1, 1, n)
    return dict(excitation=rng.uniform(0, 1, n), activation=rng.uniform(0.01, 1, n), normalized_fiber_length=lm,
                normalized_fiber_velocity=vb, active_force_length_multiplier=active_force_length(lm),
                force_velocity_multiplier=force_velocity(vb), passive_fiber_force_N=f0 * passive_force_length(lm),
                max_isometric_force_N=f0, optimal_fiber_length_m=0.06, max_contraction_velocity=10.0,
                muscle_mass_kg=0.4, slow_twitch_fraction=0.6)


def _exact(name, s, **options):
    """The exact model with the smooth model's time data: steady-state stimulation time
    (gated at e > 0.1 for BH04, as the study's counter), no force rate."""
    if name == "BH04":
        options.setdefault("stimulation_time_s", np.where(np.asarray(s["excitation"]) > 0.1, np.inf, 0.0))
    if name == "LW05":
        options = {"stimulation_time_s": np.inf, "fiber_force_rate_N_per_s": 0.0, **options}
    return ALL_MODELS[name](**s, **options)


CASES = [(name, {}) for name in SMOOTH_MODELS] + [
    ("UM10", {"slow_twitch_shortening_cap": True, "minimum_heat_rate_W_per_kg": 1.0, "effort_scaling": 1.0}),
    ("UM03", {"include_negative_work": False, "non_negative": False}),
    ("BH04", {"activation_heat_decay": False, "minimum_heat_rate_W_per_kg": 1.0}),
]


@pytest.mark.parametrize("name, options", CASES, ids=[f"{n}{'-' + '-'.join(o) if o else ''}" for n, o in CASES])
def test_converges_to_the_exact_model(name, options):
    s = _random_states()
    exact = _exact(name, s, **options)
    diffs = []
    for smoothing in (1e-2, 1e-4, 1e-6):
        smooth = smooth_rates(name, **s, smoothing=smoothing, **options)
        diffs.append(float(np.max(np.abs(smooth["total"] - exact.total))))
        for c in ("work", "basal"):
            np.testing.assert_allclose(smooth[c] * np.ones(3000), exact[c], atol=diffs[-1] + 1e-9)
    # power scale P0 = F0 lMo vmax = 1200 W: pos() errs by at most s P0/2, steps by less away from boundaries
    assert diffs[0] > diffs[1] > diffs[2]
    assert diffs[2] < 1e-2


@pytest.mark.parametrize("name", ["UM03", "BH04", "HO06", "UC16", "UM10"])
def test_work_and_heat_form_converges_to_its_definition(name):
    """``non_negative=WORK_AND_HEAT``: ``H_AM + max(W + H_SL, 0)`` of the exact model without its
    rule (for UM10, whose work and heats are never negative, the model itself)."""
    s = _random_states()
    exact = _exact(name, s, non_negative=False)
    target = exact.activation_maintenance + np.maximum(exact.work + exact.shortening_lengthening, 0.0)
    if name == "UM10":
        np.testing.assert_allclose(target, exact.total - exact.basal, rtol=1e-12)
    clamped = _exact(name, s) if name != "UM10" else exact
    # the rule on the total makes lengthening muscles free; on work plus heat it does not
    assert np.sum(target + exact.basal - clamped.total) > (10.0 if name != "UM10" else -1e-9)
    diffs = []
    for smoothing in (1e-2, 1e-4, 1e-6):
        smooth = smooth_rates(name, **s, smoothing=smoothing, non_negative=WORK_AND_HEAT, basal=False)
        diffs.append(float(np.max(np.abs(smooth["total"] - target))))
        np.testing.assert_allclose(smooth["work"], exact.work, atol=diffs[-1] + 1e-9)
    assert diffs[0] > diffs[1] > diffs[2] and diffs[2] < 1e-3


def test_example_solution_states_at_the_default_smoothing():
    data = np.load(STATES_NPZ)
    s = {k: data[k] for k in data.files if k != "time_s"}
    for name in SMOOTH_MODELS:
        params = {k: (v[:, None] if v.ndim == 1 else v) for k, v in s.items()}
        exact = _exact(name, s)
        smooth = smooth_rates(name, **params)
        diff = float(np.max(np.abs(smooth["total"] - exact.total)))
        assert diff <= MAX_DIFFERENCE_W[name], (name, diff)
        # and a finer smoothing is closer (the default is not the limit)
        finer = smooth_rates(name, **params, smoothing=SMOOTHING / 10)
        assert float(np.max(np.abs(finer["total"] - exact.total))) < diff


def _symbolic_total(name, smoothing=1e-2, **options):
    import casadi as ca

    x = ca.SX.sym("x", 4)  # e, a, l~M, vbar
    s = _random_states(1)
    s.update(excitation=x[0], activation=x[1], normalized_fiber_length=x[2], normalized_fiber_velocity=x[3],
             active_force_length_multiplier=active_force_length(x[2]), force_velocity_multiplier=force_velocity(x[3]),
             passive_fiber_force_N=2000.0 * passive_force_length(x[2]))
    total = smooth_rates(name, **s, smoothing=smoothing, **options)["total"]
    return ca.Function("f", [x], [total, ca.jacobian(total, x), ca.hessian(total, x)[0]])


def _numeric_total(name, z, smoothing=1e-2, **options):
    s = _random_states(1)
    e, a, lm, vb = z
    s.update(excitation=e, activation=a, normalized_fiber_length=lm, normalized_fiber_velocity=vb,
             active_force_length_multiplier=active_force_length(lm), force_velocity_multiplier=force_velocity(vb),
             passive_fiber_force_N=2000.0 * passive_force_length(lm))
    return float(smooth_rates(name, **s, smoothing=smoothing, **options)["total"])


# near every branch boundary (vbar ~ 0, l~M ~ 1, e ~ a) and away from them
POINTS = [(0.45, 0.4, 1.003, -0.002), (0.2, 0.5, 0.8, 0.3), (0.9, 0.7, 1.3, -0.6), (0.3, 0.302, 0.999, 0.004)]


DERIVATIVE_CASES = [(name, {}) for name in SMOOTH_MODELS] + [
    (name, {"non_negative": WORK_AND_HEAT}) for name in ("UM03", "BH04", "HO06", "UC16")]


@pytest.mark.parametrize("name, options", DERIVATIVE_CASES,
                         ids=[n + ("-work-and-heat" if o else "") for n, o in DERIVATIVE_CASES])
def test_casadi_derivatives_match_finite_differences(name, options):
    f = _symbolic_total(name, **options)
    h = 1e-6
    eye = np.eye(4)
    for z in map(np.array, POINTS):
        value, jac, hess = (np.array(o) for o in f(z))
        # one expression for both: CasADi's value is NumPy's
        assert value.item() == pytest.approx(_numeric_total(name, z, **options), rel=1e-13, abs=1e-10)
        jac_fd = np.array([(_numeric_total(name, z + h * eye[i], **options)
                            - _numeric_total(name, z - h * eye[i], **options)) / (2 * h)
                           for i in range(4)])
        np.testing.assert_allclose(jac.ravel(), jac_fd, rtol=1e-5, atol=1e-5 * np.max(np.abs(jac_fd)))
        grad = lambda y: np.array(f(y)[1]).ravel()  # noqa: E731
        hess_fd = np.array([(grad(z + h * eye[i]) - grad(z - h * eye[i])) / (2 * h) for i in range(4)])
        np.testing.assert_allclose(hess, hess_fd, rtol=1e-4, atol=1e-4 * np.max(np.abs(hess_fd)))


def test_bad_options():
    s = _random_states(3)
    with pytest.raises(OptionError, match="smoothing"):
        smooth_rates("UM10", **s, smoothing=0.0)
    with pytest.raises(OptionError, match="no option activation_heat_decay"):
        smooth_rates("UM10", **s, activation_heat_decay=False)
    with pytest.raises(OptionError, match="non_negative must be True, False or 'work-and-heat'"):
        smooth_rates("UM03", **s, non_negative="yes")
    with pytest.raises(OptionError, match="LW07: non_negative='work-and-heat'"):
        smooth_rates("LW07", **s, non_negative=WORK_AND_HEAT)
    with pytest.raises(OptionError, match="minimum_heat_rate_W_per_kg"):
        smooth_rates("BH04", **s, non_negative=WORK_AND_HEAT, minimum_heat_rate_W_per_kg=1.0)
    with pytest.raises(OptionError, match="unknown metabolic model 'XX'"):
        smooth_rates("XX", **s)
    assert SMOOTHING > 0 and math.isfinite(SMOOTHING)
    assert set(SMOOTH_MODELS) == set(ALL_MODELS) and len(STATE_ARGUMENTS) == 7
