"""The objective's terms (``musclemetab.redundancy.objective``, ``docs/problem.md``): each term's
one formula gives the same value as CasADi expression (the NLP) and over NumPy arrays (the
reported ``objective_terms``), and equals the term written out by hand here; the reported terms
of a solve add up to IPOPT's objective at the optimum, with every term in the problem at once.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_energy_goal import HEIGHT, MASS, small_problem  # noqa: F401  (the fixture)

from musclemetab.redundancy.energy import EnergyGoal
from musclemetab.redundancy.goals import Goals
from musclemetab.redundancy.objective import TERMS, goal_terms

M, D, N = 5, 3, 6
EMG_INDEX, FIBER_INDEX = (1, 3), (0, 4)
GOALS = Goals(w_activation=0.7, w_reserve=900.0, w_velocity=0.02, w_emg=3.0, w_fiber_length=50.0,
              energy=EnergyGoal("UM10", 2.0, MASS, HEIGHT))


def _random_nodes(seed=5) -> dict:
    """Node values ``(rows, N)`` and muscle values ``(M, 1)`` at a random point."""
    rng = np.random.default_rng(seed)

    def u(lo, hi, shape):
        return rng.uniform(lo, hi, size=shape)

    lmo0 = u(0.05, 0.15, (M, 1))
    lm = u(0.6, 1.4, (M, N))
    return {"a": u(0.01, 1.0, (M, N)), "lm": lm, "e": u(0.01, 1.0, (M, N)), "aT": u(-1.0, 1.0, (D, N)),
            "vm": u(-5.0, 5.0, (M, N)), "emg": u(0.0, 1.0, (len(EMG_INDEX), N)),
            "emg_scale": u(0.5, 2.0, (len(EMG_INDEX), 1)),
            "lus": (lm * lmo0)[list(FIBER_INDEX)] * u(0.9, 1.1, (len(FIBER_INDEX), N)),
            "lmo0": lmo0, "lmo": lmo0 * u(0.8, 1.2, (M, 1)), "f0": u(200.0, 3000.0, (M, 1)),
            "vmax": np.full((M, 1), 10.0), "kpe": np.full((M, 1), 4.0), "s0": u(0.9, 1.1, (M, 1)),
            "sm": np.full((M, 1), 0.6), "mass": u(0.05, 1.0, (M, 1)), "fst": u(0.3, 0.7, (M, 1))}


#: each term but the energy goal written out by hand (docs/problem.md) at every node; the energy
#: goal's rates are checked against independent muscle curves in tests/test_energy_goal.py
BY_HAND = {
    "activation": lambda v: 0.7 * 0.5 * np.sum(v["a"] ** 2, axis=0) / M,
    "excitation": lambda v: 0.7 * 0.5 * np.sum(v["e"] ** 2, axis=0) / M,
    "reserve": lambda v: 900.0 * np.sum(v["aT"] ** 2, axis=0) / D,
    "fiber_velocity": lambda v: 0.02 * np.sum(v["vm"] ** 2, axis=0) / M,
    "emg_tracking": lambda v: 3.0 * np.mean((v["e"][[1, 3]] - v["emg_scale"] * v["emg"]) ** 2, axis=0),
    "fiber_length_tracking": lambda v: 50.0 * np.mean(
        ((v["lm"][[0, 4]] * v["lmo"][[0, 4]] - v["lus"]) / v["lmo0"][[0, 4]]) ** 2, axis=0),
}


def test_each_term_is_the_same_in_casadi_and_numpy_and_by_hand():
    """At a random point, each term of :data:`TERMS` (all of them are in ``GOALS``) evaluated
    node by node as a CasADi function equals its NumPy value over all nodes at once (to 1e-12),
    and, but for the energy goal, the formula written out by hand; a term added to the objective
    without agreeing values, or without a hand-written formula here, fails."""
    import casadi as ca

    v = _random_nodes()
    terms = goal_terms(GOALS, EMG_INDEX, FIBER_INDEX)
    assert [t.name for t in terms] == [cls.name for cls in TERMS]
    assert set(BY_HAND) == {t.name for t in terms} - {"energy"}
    sym = {k: ca.SX.sym(k, x.shape[0]) for k, x in v.items()}
    for term in terms:
        f = ca.Function(term.name, list(sym.values()), [term.node(sym)])
        by_casadi = [float(f(*[x[:, k] if x.shape[1] == N else x[:, 0] for x in v.values()])) for k in range(N)]
        by_numpy = np.asarray(term.node(v), dtype=float)
        assert by_numpy.shape == (N,), term.name
        np.testing.assert_allclose(by_casadi, by_numpy, rtol=1e-12, atol=0, err_msg=term.name)
        if term.name in BY_HAND:
            np.testing.assert_allclose(by_numpy, BY_HAND[term.name](v), rtol=1e-12, atol=0, err_msg=term.name)
    energy = terms[-1]
    assert energy.name == "energy" and np.all(energy.node(v) > 0)
    # the last node: the activation alone, from the states there
    last = {"a": v["a"][:, :1], "lm": v["lm"][:, :1]}
    assert [t.name for t in terms if t.at_last_node] == ["activation"]
    assert float(terms[1].node(last)[0]) == pytest.approx(float(BY_HAND["activation"](v)[0]), rel=1e-14)


def test_terms_follow_the_goals_and_the_trial():
    """A trial without EMG or measured fiber lengths has no tracking terms, the goals without an
    energy goal no energy term; the effort terms are always reported (a zero weight: zero)."""
    names = [t.name for t in goal_terms(Goals(w_activation=0.0))]
    assert names == ["activation", "excitation", "reserve", "fiber_velocity"]
    assert [t.weight for t in goal_terms(Goals(w_activation=0.0))] == [0.0, 0.0, 1000.0, 0.01]
    assert [t.name for t in goal_terms(Goals(w_emg=1.0), emg_index=(0,))][0] == "emg_tracking"


def test_reported_terms_add_up_to_ipopts_objective(small_problem):  # noqa: F811
    """Two trials (the normal trial's first frames, EMG made of the initial guess's excitations,
    fiber lengths of its states lengthened by 5 %) solved with every term of the objective at once
    (the energy goal small, a quick solve) and EMG scale factors: the trials' reported terms
    (NumPy) add up to IPOPT's objective (CasADi) at the optimum, to 1e-9."""
    from musclemetab.redundancy.goals import ParameterSpec, TrialBlock
    from musclemetab.redundancy.ipopt import solve_problem

    inp, params, guess = small_problem
    n = inp.n_intervals
    emg_muscles, fiber_muscles = tuple(inp.muscles[:3]), tuple(inp.muscles[3:5])
    lmo = params.subset(list(fiber_muscles)).optimal_fiber_length_m
    blocks = [TrialBlock(label, inp, guess, emg_muscles=emg_muscles,
                         emg_nodes=scale * guess.excitation[:n, :3], fiber_muscles=fiber_muscles,
                         fiber_length_nodes_m=1.05 * guess.lm_norm[:n, 3:5] * lmo)
              for label, scale in (("one", 0.8), ("two", 1.2))]
    goals = Goals(w_emg=1.0, w_fiber_length=10.0, energy=EnergyGoal("BH04", 1e-3, MASS, HEIGHT, smoothing=0.01))
    res = solve_problem(blocks, params, goals.resolved(), [ParameterSpec("emg_scale", emg_muscles, (0.5, 2.0))])
    assert res.success, res.status
    assert list(res.objective_terms["one"]) == [cls.name for cls in TERMS]
    assert all(v > 0 for terms in res.objective_terms.values() for v in terms.values())
    total = sum(v for terms in res.objective_terms.values() for v in terms.values())
    assert total == pytest.approx(res.objective, rel=1e-9)
