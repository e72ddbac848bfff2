"""Bounds of the problem core's variables and rows, and its initial guess (``docs/problem.md``,
``docs/solver.md``)."""

from __future__ import annotations

import numpy as np

from ..muscle import longest_fiber_length_bound
from .inputs import TrialInputs
from .parameters import MuscleTendonParameters

__all__ = ["node_bounds", "fiber_length_upper_bounds", "fiber_length_bounds_record", "bounds_and_guess"]

ACTIVATION_BOUNDS = (0.0, 1.0)
FIBER_LENGTH_BOUNDS = (0.1, 1.7)
#: optimal lengths added to a muscle's longest rigid-tendon fiber length where that exceeds the
#: default upper bound less this margin (:func:`fiber_length_upper_bounds`)
FIBER_LENGTH_MARGIN = 0.05
FIBER_VELOCITY_BOUNDS = (-10.0, 10.0)
RESERVE_BOUNDS = (-1.0, 1.0)
MIN_PROJECTED_LENGTH_M = 1e-4


def fiber_length_upper_bounds(inputs: TrialInputs, params: MuscleTendonParameters, specs=()) -> np.ndarray:
    """Upper bound of each muscle's normalised fiber length in one trial (``docs/problem.md``).

    A fiber cannot be longer than with its tendon at slack length (a tendon shorter than its
    slack length carries no force, so neither can the fiber): ``l~M <= l~M_rigid =
    sqrt((lMT - lTs)^2 + w^2) / lMo``. The bound is ``FIBER_LENGTH_BOUNDS[1]`` (1.7), or
    ``max over the nodes of l~M_rigid + FIBER_LENGTH_MARGIN`` where that is larger, so that the
    box never excludes the muscle's only equilibria. With scale factors of ``lMo`` or ``lTs``
    in ``specs`` the longest rigid-tendon length is taken at their lower bounds.
    """
    p = params.subset(inputs.muscles)
    lmo = np.asarray(p.optimal_fiber_length_m, dtype=float).copy()
    lts = np.asarray(p.tendon_slack_length_m, dtype=float).copy()
    width = np.asarray(p.width_m, dtype=float).copy()
    pos = {m: k for k, m in enumerate(inputs.muscles)}
    for s in specs:
        if s.kind in ("optimal_fiber_length", "tendon_slack_length") and s.bounds[0] < 1.0:
            k = [pos[m] for m in s.muscles if m in pos]
            if s.kind == "optimal_fiber_length":
                lmo[k] *= s.bounds[0]
                width[k] *= s.bounds[0]
            else:
                lts[k] *= s.bounds[0]
    return longest_fiber_length_bound(inputs.lmt_m, lts, lmo, width, FIBER_LENGTH_BOUNDS[1], FIBER_LENGTH_MARGIN)


def fiber_length_bounds_record(inputs: TrialInputs, params: MuscleTendonParameters, specs=()) -> dict:
    """The fiber-length bounds of one trial as ``summary.json`` records them
    (``fiber_length_bounds``): ``default``, the bounds ``[0.1, 1.7]`` of the normalised fiber
    length, and ``widened_upper``, ``{muscle: upper bound}`` of the muscles whose bound
    :func:`fiber_length_upper_bounds` widens (the same arguments)."""
    upper = fiber_length_upper_bounds(inputs, params, specs)
    return {"default": list(FIBER_LENGTH_BOUNDS),
            "widened_upper": {m: float(u) for m, u in zip(inputs.muscles, upper) if u > FIBER_LENGTH_BOUNDS[1]}}


def node_bounds(M: int, D: int, lm_upper=None) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of one node's variables ``[a, l~M, lM cos(alpha), e, reserve, v~M]``
    (``lm_upper``: per-muscle upper bounds of ``l~M``, default ``FIBER_LENGTH_BOUNDS[1]``)."""
    lm_upper = np.full(M, FIBER_LENGTH_BOUNDS[1]) if lm_upper is None else np.asarray(lm_upper, dtype=float)
    lb = np.concatenate([
        np.full(M, ACTIVATION_BOUNDS[0]), np.full(M, FIBER_LENGTH_BOUNDS[0]), np.full(M, MIN_PROJECTED_LENGTH_M),
        np.full(M, ACTIVATION_BOUNDS[0]), np.full(D, RESERVE_BOUNDS[0]), np.full(M, FIBER_VELOCITY_BOUNDS[0]),
    ])
    ub = np.concatenate([
        np.full(M, ACTIVATION_BOUNDS[1]), lm_upper, np.full(M, np.inf),
        np.full(M, ACTIVATION_BOUNDS[1]), np.full(D, RESERVE_BOUNDS[1]), np.full(M, FIBER_VELOCITY_BOUNDS[1]),
    ])
    return lb, ub


def bounds_and_guess(trials, params, info, specs, goals, p_index, n_p, pairs) -> dict:
    """Bounds of the variables and rows of a problem (:func:`.transcription.build_problem`: its trials and
    per-trial layout ``info``) and its initial guess (the trials' guesses, factors 1)."""
    lbx, ubx, x0, lbg, ubg = [], [], [], [], []
    tol = goals.emg_tolerance or 0.0
    for t, d in zip(trials, info):
        M, D, N, nb, gs = d["M"], d["D"], d["N"], d["nb"], t.guess
        lb_node, ub_node = node_bounds(M, D, fiber_length_upper_bounds(t.inputs, params, specs))
        lbx += [np.tile(lb_node, N), lb_node[:3 * M]]
        ubx += [np.tile(ub_node, N), ub_node[:3 * M]]
        Z0 = np.hstack([gs.activation[:N], gs.lm_norm[:N], gs.lm_projected_m[:N],
                        gs.excitation[:N], gs.reserve[:N], gs.fiber_velocity_lmo_per_s[:N]])
        x0 += [Z0.reshape(-1), gs.activation[N], gs.lm_norm[N], gs.lm_projected_m[N]]
        n_eq = 4 * M + D
        lbg += [np.tile(np.concatenate([np.zeros(n_eq), np.full(nb, -tol)]), N), np.zeros(M)]
        ubg += [np.tile(np.concatenate([np.zeros(n_eq), np.full(nb, tol)]), N), np.zeros(M)]
    lb_p = np.concatenate([np.full(len(s.muscles), s.bounds[0]) for s in specs] or [np.zeros(0)])
    ub_p = np.concatenate([np.full(len(s.muscles), s.bounds[1]) for s in specs] or [np.zeros(0)])
    if p_index is not None:
        first = [p_index.index(j) for j in range(n_p)]
        lb_p, ub_p = lb_p[first], ub_p[first]
    return {"lbx": np.concatenate(lbx + [lb_p]), "ubx": np.concatenate(ubx + [ub_p]),
            "x0": np.concatenate(x0 + [np.ones(n_p)]),
            "lbg": np.concatenate(lbg + [np.zeros(len(pairs))]), "ubg": np.concatenate(ubg + [np.zeros(len(pairs))])}
