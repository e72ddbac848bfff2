"""The energy goal of the muscle redundancy problem: the integrated metabolic rate of a smooth
energy model (``docs/energy_objective.md``).

At every mesh node ``k = 0 ... N-1`` the smooth model ``E`` (:mod:`musclemetab.metabolics.smooth`,
one function for CasADi and NumPy) gives each muscle's rate from the node's states and controls:
excitation ``e_k``, activation ``a_k``, fiber length ``l~M_k`` (``fL``, ``fPE``) and fiber
velocity ``v~M_k`` (``vbar = v~M/vmax``, ``fV``). Without basal heat (a constant), the goal is::

    wE * (1/N) * sum_k sum_m Edot_m(k) / m_body

the leg's mean metabolic rate over the mesh in W/kg of body mass (rectangle rule; the
integral ``sum_k h Edot_k`` over the duration ``N h``), normalised by ``N`` like the other goals
of :mod:`.transcription`. Muscle masses and slow-twitch fractions come from the anatomical muscle table
(:func:`musclemetab.properties.metabolic_properties`), as for the metabolic rates of a solution.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field

import numpy as np

from ..errors import OptionError

__all__ = ["EnergyGoal", "ENERGY_SMOOTHING", "node_rates", "leg_rate_W_per_kg"]

#: Default smoothing parameter of the energy goal's model (dimensionless;
#: :data:`musclemetab.metabolics.smooth.SMOOTHING` is the default of the smooth models).
ENERGY_SMOOTHING = 1e-3


@dataclass(frozen=True)
class EnergyGoal:
    """Minimise the integrated metabolic rate of the smooth ``model`` with weight ``weight``.

    ``effort_weight``: weight of the effort goal on excitations and activations beside it
    (``None``: the workflow's, 1; 0: energy alone, the reserve and fiber-velocity terms stay).
    ``body_mass_kg``, ``height_m`` and ``muscle_properties`` (an override CSV, or a mapping
    ``{muscle: {"mass_kg": ..., "slow_twitch_fraction": ...}}``) give the muscle masses and
    slow-twitch fractions by the muscle table's rules. ``options``: options of the smooth model
    (:func:`musclemetab.metabolics.smooth.smooth_rates`).
    """

    model: str
    weight: float
    body_mass_kg: float
    height_m: float
    effort_weight: float | None = None
    smoothing: float = ENERGY_SMOOTHING
    muscle_properties: str | None = None
    options: dict = field(default_factory=dict)

    def __post_init__(self):
        from ..metabolics.smooth import SMOOTH_MODELS
        from ..properties import check_subject

        key = str(self.model).strip().upper()
        if key not in SMOOTH_MODELS:
            raise OptionError(f"energy goal: unknown metabolic model '{self.model}'; known models: "
                              f"{', '.join(SMOOTH_MODELS)}")
        object.__setattr__(self, "model", key)
        for name in ("weight", "effort_weight"):
            v = getattr(self, name)
            if v is None and name == "effort_weight":
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
                raise OptionError(f"energy goal: the {name.replace('_', ' ')} must be a non-negative number, "
                                  f"not {v!r}")
        s = self.smoothing
        if isinstance(s, bool) or not isinstance(s, (int, float)) or not (math.isfinite(s) and s > 0):
            raise OptionError(f"energy goal: the smoothing must be a positive number, not {s!r}")
        check_subject(float(self.body_mass_kg), float(self.height_m))
        if isinstance(self.muscle_properties, os.PathLike):
            object.__setattr__(self, "muscle_properties", os.fspath(self.muscle_properties))
        object.__setattr__(self, "options", dict(self.options))

    def muscle_values(self, muscles, max_isometric_force_N, optimal_fiber_length_m):
        """Masses (kg) and slow-twitch fractions of ``muscles`` (arrays). The problem, its
        solution and its summary ask for the same muscles: they are placed (and a muscle the
        table cannot place is warned about) once."""
        overrides = self.muscle_properties
        stamp = os.stat(overrides).st_mtime_ns if overrides is not None and os.path.isfile(overrides) else None
        mass, fst = _muscle_values(tuple(muscles), float(self.body_mass_kg), float(self.height_m),
                                   tuple(np.asarray(max_isometric_force_N, dtype=float).ravel()),
                                   tuple(np.asarray(optimal_fiber_length_m, dtype=float).ravel()), overrides, stamp)
        return mass.copy(), fst.copy()

    def record(self) -> dict:
        """The goal's settings, as ``summary.json`` records them."""
        return {"model": self.model, "weight": self.weight, "effort_weight": self.effort_weight,
                "smoothing": self.smoothing, "body_mass_kg": self.body_mass_kg, "height_m": self.height_m,
                "muscle_properties": self.muscle_properties, "options": dict(self.options),
                "term": "weight * (1/N) * sum over nodes k < N and muscles of Edot (W, no basal) / body mass"}


@functools.lru_cache(maxsize=16)
def _muscle_values(muscles, body_mass_kg, height_m, f0, lmo, overrides, overrides_stamp):
    from ..properties import metabolic_properties

    mass, fst = metabolic_properties(list(muscles), body_mass_kg, height_m, np.asarray(f0), np.asarray(lmo),
                                     overrides=overrides)
    return np.asarray(mass, dtype=float), np.asarray(fst, dtype=float)


def node_rates(goal: EnergyGoal, e, a, lm, vm, *, F0, lMo, vmax, kpe, s0, sm, mass, fst):
    """Each muscle's smooth metabolic rate (W, no basal heat) at mesh nodes: the states and
    controls ``e, a, l~M, v~M`` (NumPy arrays or CasADi expressions, muscles along the first
    axis) and per-muscle parameters of the same first axis (columns for ``(muscles, nodes)``)."""
    from ..metabolics.smooth import smooth_rates
    from ..muscle import active_force_length, force_velocity, passive_force_length

    vbar = vm / vmax
    r = smooth_rates(goal.model, e, a, lm, vbar, active_force_length(lm), force_velocity(vbar),
                     F0 * passive_force_length(lm, kpe, s0, sm), F0, lMo, vmax, mass, fst,
                     smoothing=goal.smoothing, basal=False, **goal.options)
    return r["total"]


def leg_rate_W_per_kg(goal: EnergyGoal, params, muscles, excitation, activation, lm_norm, fiber_velocity_lmo_per_s,
                      lmo_factor=None) -> np.ndarray:
    """The summed smooth rate of ``muscles`` per kg of body mass (W/kg, no basal heat) at each
    node, from NumPy arrays ``(nodes, muscles)``; ``params`` the problem's
    :class:`~.parameters.MuscleTendonParameters`, ``lmo_factor`` the optimal fiber lengths'
    scale factors (default 1). The goal's value is ``weight`` times its mean over nodes ``0 ... N-1``."""
    p = params.subset(list(muscles))
    mass, fst = goal.muscle_values(muscles, p.max_isometric_force_N, p.optimal_fiber_length_m)

    def col(v):
        return np.asarray(v, dtype=float).reshape(-1, 1)

    lmo = col(p.optimal_fiber_length_m) * (1.0 if lmo_factor is None else col(lmo_factor))
    rates = node_rates(goal, *(np.asarray(x, dtype=float).T for x in (excitation, activation, lm_norm, fiber_velocity_lmo_per_s)),
                       F0=col(p.max_isometric_force_N), lMo=lmo, vmax=col(p.max_contraction_velocity),
                       kpe=col(p.passive_kpe), s0=col(p.passive_s0), sm=col(p.passive_sm), mass=col(mass),
                       fst=col(fst))
    return np.asarray(rates).sum(axis=0) / float(goal.body_mass_kg)
