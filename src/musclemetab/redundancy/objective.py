"""The objective's terms, each written once (``docs/problem.md``, "Adding a goal").

A term is one small class whose :meth:`Term.node` gives its value at mesh nodes from the
node values ``v`` (a mapping of the names below) with one formula that works on CasADi
expressions and on NumPy arrays alike: for the NLP (:mod:`.transcription`) ``v`` holds one
node's symbols (columns ``(rows, 1)``) and the term is a scalar expression; for the terms
reported after a solve (:func:`term_values`, ``objective_terms`` in ``summary.json``) ``v``
holds arrays ``(rows, nodes)`` and the term is a row of values, one per node. The only place
the two differ is :func:`column_sums` (CasADi's ``sum1``, NumPy's sum over axis 0, through the
math namespace the muscle curves and energy models are written with). A trial's
term is ``(1/N) sum_k node(v_k)`` over its nodes ``k = 0 ... N-1`` (and the last node ``N`` for
a term with ``at_last_node``)::

    activation        wAct/2 sum a^2 / M                 (also at node N)
    excitation        wAct/2 sum e^2 / M
    reserve           wTres sum aT^2 / D
    fiber_velocity    wVm sum v~M^2 / M
    emg_tracking      wEMG sum (e - s_EMG E)^2 / nEMG
    fiber_length_tracking  wUS sum ((l~M s_lMo lMo - lUS)/lMo)^2 / nUS
    energy            wE sum_m Edot_m(e, a, l~M, v~M) / m_body

Node values: ``a, lm, e, aT, vm`` (activation, normalised fiber length, excitation, reserve,
fiber velocity), ``emg`` (the tracked muscles' EMG) and ``emg_scale`` (their scale factors),
``lus`` (measured fiber lengths, m), the muscle values ``lmo`` (optimal fiber length with its
factor), ``lmo0`` (without), ``f0, vmax, kpe, s0, sm``, and the energy goal's ``mass, fst``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..muscle.curves import math_for
from .energy import EnergyGoal, node_rates

__all__ = ["Term", "Activation", "Excitation", "Reserve", "FiberVelocity", "EmgTracking", "FiberLengthTracking",
           "Energy", "TERMS", "goal_terms", "column_sums", "node_cost", "last_node_cost", "term_values",
           "node_arrays", "find_term", "leg_rate_W_per_kg"]


def column_sums(x):
    """Sums over the first axis (muscles, DOFs), one per node: NumPy's sum over axis 0, CasADi's
    ``sum1`` (the math namespace of :func:`musclemetab.muscle.curves.math_for`)."""
    return math_for(x).sum1(x)


def _mean_square(x, weight):
    """``weight sum x^2 / rows`` at each node (the coefficient ``weight / rows`` first)."""
    return (weight / x.shape[0]) * column_sums(x**2)


@dataclass(frozen=True)
class Term:
    """One term of the objective: its ``name`` (the key of ``objective_terms``), its
    ``weight`` and :meth:`node`, its value at mesh nodes (weight included). ``at_last_node``:
    the term also counts the last node ``N`` (a state's term), where only ``a, lm`` are given.
    :meth:`of` gives the term of a problem's goals and tracked muscles, or ``None``."""

    name: ClassVar[str]
    at_last_node: ClassVar[bool] = False
    weight: float

    def node(self, v):
        raise NotImplementedError

    @classmethod
    def of(cls, goals, emg_index: tuple, fiber_index: tuple) -> "Term | None":
        raise NotImplementedError


class _MeanSquare(Term):
    """A term ``factor * weight * sum x^2 / rows`` of one node value ``x = v[key]``, weighted by
    the goals' ``weight_name``."""

    key: ClassVar[str]
    weight_name: ClassVar[str]
    factor: ClassVar[float] = 1.0

    def node(self, v):
        return _mean_square(v[self.key], self.weight * self.factor)

    @classmethod
    def of(cls, goals, emg_index, fiber_index):
        return cls(getattr(goals, cls.weight_name))


class Activation(_MeanSquare):
    """The activations' share of the effort goal: ``wAct/2 sum a^2 / M`` (nodes ``0 ... N``)."""

    name, key, weight_name, factor, at_last_node = "activation", "a", "w_activation", 0.5, True


class Excitation(_MeanSquare):
    """The excitations' share of the effort goal: ``wAct/2 sum e^2 / M``."""

    name, key, weight_name, factor = "excitation", "e", "w_activation", 0.5


class Reserve(_MeanSquare):
    """The reserve actuators: ``wTres sum aT^2 / D``."""

    name, key, weight_name = "reserve", "aT", "w_reserve"


class FiberVelocity(_MeanSquare):
    """The fiber velocities: ``wVm sum v~M^2 / M``."""

    name, key, weight_name = "fiber_velocity", "vm", "w_velocity"


@dataclass(frozen=True)
class _Tracking(Term):
    """A tracking term ``weight * sum r^2 / n`` of the :meth:`residual` ``r`` of the ``n``
    tracked muscles at positions ``index`` (the trial's EMG-tracked muscles, or those with
    measured fiber lengths: ``tracked``); a trial without them has no such term."""

    weight_name: ClassVar[str]
    tracked: ClassVar[str]
    index: tuple[int, ...] = ()

    def residual(self, v):
        raise NotImplementedError

    def node(self, v):
        return _mean_square(self.residual(v), self.weight)

    @classmethod
    def of(cls, goals, emg_index, fiber_index):
        index = tuple(emg_index if cls.tracked == "emg" else fiber_index)
        return cls(getattr(goals, cls.weight_name), index) if index else None


class EmgTracking(_Tracking):
    """EMG tracking: ``wEMG sum (e - s_EMG E)^2 / nEMG``; the :meth:`residual` ``e - s_EMG E``
    is also what the EMG bound rows bound."""

    name, weight_name, tracked = "emg_tracking", "w_emg", "emg"

    def residual(self, v):
        return v["e"][list(self.index)] - v["emg_scale"] * v["emg"]


class FiberLengthTracking(_Tracking):
    """Tracking measured fiber lengths: ``wUS sum ((l~M s_lMo lMo - lUS)/lMo)^2 / nUS``, the
    :meth:`residual` in optimal fiber lengths without their factor."""

    name, weight_name, tracked = "fiber_length_tracking", "w_fiber_length", "fiber"

    def residual(self, v):
        i = list(self.index)
        return (v["lm"][i] * v["lmo"][i] - v["lus"]) / v["lmo0"][i]


@dataclass(frozen=True)
class Energy(Term):
    """The energy goal (:mod:`.energy`): ``wE sum_m Edot_m / m_body``, the smooth model's
    rates without basal heat (W) per kg of body mass."""

    name: ClassVar[str] = "energy"
    weight: float = 0.0
    goal: EnergyGoal | None = None

    def _leg_rate_W(self, v):
        """The summed rate of the muscles (W) at each node."""
        return column_sums(node_rates(self.goal, v["e"], v["a"], v["lm"], v["vm"], F0=v["f0"], lMo=v["lmo"],
                                      vmax=v["vmax"], kpe=v["kpe"], s0=v["s0"], sm=v["sm"], mass=v["mass"],
                                      fst=v["fst"]))

    def leg_rate(self, v):
        """The summed rate of the muscles per kg of body mass (W/kg) at each node."""
        return self._leg_rate_W(v) / float(self.goal.body_mass_kg)

    def node(self, v):
        return (self.weight / float(self.goal.body_mass_kg)) * self._leg_rate_W(v)

    @classmethod
    def of(cls, goals, emg_index, fiber_index):
        return cls(goals.energy.weight, goals.energy) if goals.energy is not None else None


#: the terms of the objective, in the order ``objective_terms`` lists them
TERMS = (EmgTracking, Activation, Excitation, Reserve, FiberVelocity, FiberLengthTracking, Energy)


def goal_terms(goals, emg_index=(), fiber_index=()) -> tuple[Term, ...]:
    """The terms of a trial with ``goals`` (:class:`.goals.Goals`) whose EMG-tracked muscles
    and muscles with measured fiber lengths are at positions ``emg_index``, ``fiber_index``."""
    return tuple(t for cls in TERMS if (t := cls.of(goals, tuple(emg_index), tuple(fiber_index))) is not None)


def find_term(terms, cls):
    """The term of class ``cls`` among ``terms``, or ``None``."""
    return next((t for t in terms if isinstance(t, cls)), None)


def node_cost(terms, v):
    """The NLP's cost at one interval's start node: the sum of the terms of nonzero weight."""
    return sum((t.node(v) for t in terms if t.weight), 0)


def last_node_cost(terms, v):
    """The NLP's cost at the last node: the terms ``at_last_node`` of nonzero weight."""
    return sum((t.node(v) for t in terms if t.at_last_node and t.weight), 0)


def term_values(terms, nodes: dict, last: dict, n_intervals: int) -> dict:
    """Each term's value ``{name: float}`` over a trial's NumPy node values ``nodes`` (arrays
    ``(rows, N)``, :func:`node_arrays`) and ``last`` (node ``N``): ``(1/N) sum_k node(v_k)``."""
    out = {}
    for t in terms:
        total = float(np.sum(t.node(nodes)))
        if t.at_last_node:
            total += float(np.sum(t.node(last)))
        out[t.name] = total / n_intervals
    return out


def node_arrays(params, muscles, *, excitation, activation, lm_norm, fiber_velocity_lmo_per_s, reserve=None,
                lmo_factor=None, energy: EnergyGoal | None = None, emg=None, emg_scale=None, lus=None) -> dict:
    """The NumPy node values of a trial: its states and controls given as arrays ``(nodes,
    rows)`` (as a solution holds them) transposed to ``(rows, nodes)``, with ``params``' muscle
    values of ``muscles`` as columns; ``lmo_factor`` the optimal fiber lengths' scale factors
    (default 1); ``energy`` the goal whose muscle masses and slow-twitch fractions to add;
    ``emg`` ``(nodes, nEMG)`` with ``emg_scale`` ``(nEMG,)``; ``lus`` ``(nodes, nUS)`` in m."""
    p = params.subset(list(muscles))

    def col(x):
        return np.asarray(x, dtype=float).reshape(-1, 1)

    def rows(x):
        return np.asarray(x, dtype=float).T

    lmo0 = col(p.optimal_fiber_length_m)
    v = {"e": rows(excitation), "a": rows(activation), "lm": rows(lm_norm), "vm": rows(fiber_velocity_lmo_per_s),
         "lmo0": lmo0, "lmo": lmo0 * (1.0 if lmo_factor is None else col(lmo_factor)),
         "f0": col(p.max_isometric_force_N), "vmax": col(p.max_contraction_velocity), "kpe": col(p.passive_kpe),
         "s0": col(p.passive_s0), "sm": col(p.passive_sm)}
    if reserve is not None:
        v["aT"] = rows(reserve)
    if energy is not None:
        mass, fst = energy.muscle_values(list(muscles), p.max_isometric_force_N, p.optimal_fiber_length_m)
        v.update(mass=col(mass), fst=col(fst))
    if emg is not None:
        v.update(emg=rows(emg), emg_scale=col(emg_scale))
    if lus is not None:
        v["lus"] = rows(lus)
    return v


def leg_rate_W_per_kg(goal: EnergyGoal, params, muscles, excitation, activation, lm_norm, fiber_velocity_lmo_per_s,
                      lmo_factor=None) -> np.ndarray:
    """The summed smooth rate of ``muscles`` per kg of body mass (W/kg, no basal heat) at each
    node, from NumPy arrays ``(nodes, muscles)``; ``params`` the problem's
    :class:`~.parameters.MuscleTendonParameters`, ``lmo_factor`` the optimal fiber lengths'
    scale factors (default 1). The goal's value is ``weight`` times its mean over nodes ``0 ... N-1``
    (the formula of :class:`Energy`)."""
    v = node_arrays(params, muscles, excitation=excitation, activation=activation, lm_norm=lm_norm,
                    fiber_velocity_lmo_per_s=fiber_velocity_lmo_per_s, lmo_factor=lmo_factor, energy=goal)
    return np.asarray(Energy(goal.weight, goal).leg_rate(v), dtype=float)
