"""What a problem asks (``docs/problem.md``): its goals (:class:`Goals`: the objective's weights,
the EMG bound, the energy goal and the fiber dynamics), its shared parameters
(:class:`ParameterSpec`: scale factors of one kind, with bounds and couplings) and its trials
(:class:`TrialBlock`: mesh inputs, initial guess and goal data). :mod:`.transcription` turns them
into the NLP."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from ..errors import OptionError
from ._checks import check_factor_bounds, check_non_negative, check_weights
from .energy import EnergyGoal
from .inputs import TrialInputs
from .static_opt import InitialGuess

__all__ = ["Goals", "EFFORT_WEIGHTS", "ParameterSpec", "coupling_pairs", "TrialBlock", "PARAMETER_KINDS",
           "FIBER_DYNAMICS", "check_fiber_dynamics"]


#: kinds of shared scale factors; the muscle parameters a factor multiplies
PARAMETER_KINDS = {"tendon_stiffness": "kT", "optimal_fiber_length": "lmo", "tendon_slack_length": "lts",
                   "emg_scale": None}
#: transcriptions of the fiber dynamics: the Hill equilibrium of interval k at its start node
#: (forward Euler) or at its end node (backward Euler)
FIBER_DYNAMICS = ("forward", "backward")


def check_fiber_dynamics(value, energy=None) -> None:
    """Refuse a transcription of the fiber dynamics that is not one of :data:`FIBER_DYNAMICS`
    (or ``None``, the problem's default, :meth:`Goals.resolved`), and the backward one with the
    energy goal (whose rates pair each node's velocity with its own state, the forward scheme's
    pairing)."""
    if value is not None and value not in FIBER_DYNAMICS:
        raise OptionError(f"the fiber dynamics (--fiber-dynamics) must be one of {', '.join(FIBER_DYNAMICS)}, "
                          f"not {value!r}")
    if value == "backward" and energy is not None:
        raise OptionError("the energy goal (--energy-model) needs the forward fiber dynamics; drop "
                          "--fiber-dynamics backward or the energy goal")


#: the weights of the effort goal (activation and excitation, reserve, fiber velocity)
EFFORT_WEIGHTS = ("w_activation", "w_reserve", "w_velocity")


@dataclass(frozen=True)
class Goals:
    """The objective's weights, the one place they are held (workflow presets, EMG-TEN
    settings and every solve take a ``Goals``; :class:`.ipopt.SolverOptions` holds numerics
    only), and the EMG bound (``None``: no bound rows); ``energy``: the
    energy goal (:class:`.energy.EnergyGoal`), or ``None``; ``fiber_dynamics``: the
    transcription of ``dl~M/dt = v~M`` (:data:`FIBER_DYNAMICS`, ``docs/problem.md``) of every
    kind of solve (effort, EMG-TEN and EMG-informed, estimation), or ``None`` (default): the
    problem's default, which :meth:`resolved` gives. Problems are built from resolved goals."""

    w_activation: float = 1.0
    w_reserve: float = 1000.0
    w_velocity: float = 0.01
    w_emg: float = 0.0
    emg_tolerance: float | None = None
    w_fiber_length: float = 0.0
    energy: EnergyGoal | None = None
    fiber_dynamics: str | None = None

    def __post_init__(self):
        check_fiber_dynamics(self.fiber_dynamics, self.energy)
        check_weights(self, (*EFFORT_WEIGHTS, "w_emg", "w_fiber_length"))
        if self.emg_tolerance is not None:
            check_non_negative("the EMG tolerance", self.emg_tolerance, " (0: EMG-driven)")
        if self.energy is not None and not isinstance(self.energy, EnergyGoal):
            raise OptionError(f"the energy goal must be an EnergyGoal, not {type(self.energy).__name__}")

    def resolved(self, emg_mode: str | None = None) -> "Goals":
        """These goals with the transcription of the fiber dynamics the problem is built with:
        ``fiber_dynamics`` when given, else the default of the EMG mode ``emg_mode`` (``None``: a
        solve without EMG): backward Euler in the EMG-driven mode, whose forward recurrence is
        unstable (``docs/problem.md``), forward Euler otherwise."""
        if self.fiber_dynamics is not None:
            return self
        return replace(self, fiber_dynamics="backward" if emg_mode == "driven" else "forward")

    def effort_weights(self) -> dict:
        """``{"w_activation", "w_reserve", "w_velocity"}``: the weights of the effort goal (the
        keys under which records hold them)."""
        return {name: getattr(self, name) for name in EFFORT_WEIGHTS}

    def effort(self) -> "Goals":
        """The effort goal alone: these effort weights, no EMG, fiber-length or energy goal."""
        return Goals(**self.effort_weights())


@dataclass(frozen=True)
class ParameterSpec:
    """Scale factors of one kind (:data:`PARAMETER_KINDS`), one per muscle, shared by all
    trials; ``couplings`` are pairs of positions in ``muscles`` whose factors are equal."""

    kind: str
    muscles: tuple[str, ...]
    bounds: tuple[float, float]
    couplings: tuple[tuple[int, int], ...] = ()

    def __post_init__(self):
        if self.kind not in PARAMETER_KINDS:
            raise OptionError(f"unknown parameter kind {self.kind!r}; use one of {', '.join(PARAMETER_KINDS)}")
        object.__setattr__(self, "bounds", check_factor_bounds(f"the bounds of the {self.kind} factors", self.bounds))
        object.__setattr__(self, "muscles", tuple(str(m) for m in self.muscles))
        n = len(self.muscles)
        if any(not (0 <= a < n and 0 <= b < n) for a, b in self.couplings):
            raise OptionError(f"a coupling of the {self.kind} factors names a muscle outside {self.muscles}")


def coupling_pairs(groups: Sequence[Sequence[str]], muscles: Sequence[str], consecutive: bool
                   ) -> tuple[tuple[int, int], ...]:
    """The :attr:`ParameterSpec.couplings` that make the factors of each group of muscles equal.

    ``groups`` name muscles; those not in ``muscles`` are left out of their group. Pairs are
    positions in ``muscles``: with ``consecutive`` each member to the next one of its group
    (``[a, b, c]`` gives ``(a, b), (b, c)``), otherwise the group's first member to each of the
    others (``(a, b), (a, c)``). Either way a group of ``n`` present members gives ``n - 1``
    equalities; a group with one present member gives none.
    """
    pos = {n: i for i, n in enumerate(muscles)}
    pairs = []
    for g in groups:
        members = [m for m in g if m in pos]
        if consecutive:
            pairs += [(pos[a], pos[b]) for a, b in zip(members[:-1], members[1:])]
        else:
            pairs += [(pos[members[0]], pos[b]) for b in members[1:]]
    return tuple(pairs)


@dataclass(frozen=True)
class TrialBlock:
    """One trial of a problem: mesh inputs, initial guess and goal data at nodes ``0 ... N-1``
    (EMG ``(N, nEMG)`` of ``emg_muscles``; measured fiber lengths in m ``(N, nUS)``)."""

    label: str
    inputs: TrialInputs
    guess: InitialGuess
    emg_muscles: tuple[str, ...] = ()
    emg_nodes: np.ndarray | None = None
    fiber_muscles: tuple[str, ...] = ()
    fiber_length_nodes_m: np.ndarray | None = None

    def signature(self):
        return (tuple(self.inputs.muscles), tuple(self.inputs.dofs), tuple(self.emg_muscles),
                tuple(self.fiber_muscles))
