"""The energy goal of the muscle redundancy problem: the integrated metabolic rate of a smooth
energy model (``docs/energy_objective.md``).

At every mesh node ``k = 0 ... N-1`` the smooth model ``E`` (:mod:`musclemetab.metabolics.smooth`,
one function for CasADi and NumPy) gives each muscle's rate from the node's states and controls:
excitation ``e_k``, activation ``a_k``, fiber length ``l~M_k`` (``fL``, ``fPE``) and fiber
velocity ``v~M_k`` (``vbar = v~M/vmax``, ``fV``). Without basal heat (a constant), the goal is::

    wE * (1/N) * sum_k sum_m Edot_m(k) / m_body

the leg's mean metabolic rate over the mesh in W/kg of body mass (rectangle rule; the
integral ``sum_k h Edot_k`` over the duration ``N h``), normalised by ``N`` like the other goals
of :mod:`.transcription`. Muscle masses and slow-twitch fractions are those of the metabolic rates
of a solution (:func:`musclemetab.metabolics.masses.muscle_masses_and_fractions`): the anatomical
muscle table's volume rule with the body height, the model's ``F0 / sigma * rho * lMo`` without it.

UM03, BH04, HO06 and UC16 raise a negative total to zero (Umberger et al. 2003, Eq. 3), which
makes a muscle that absorbs more work than its heat cost nothing at any activation. The goal's
default form (``form="objective"``) applies that rule to the work plus the
shortening/lengthening heat, ``Edot = H_AM + max(W + H_SL, 0)``: equal to the model wherever
``W + H_SL >= 0`` (every shortening state), larger by at most the activation and maintenance
heat ``H_AM`` while lengthening, which a lengthening muscle thus always pays.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from ..errors import OptionError

__all__ = ["EnergyGoal", "ENERGY_SMOOTHING", "GOAL_FORMS", "CLAMPED_MODELS", "node_rates"]

#: Default smoothing parameter of the energy goal's model (dimensionless;
#: :data:`musclemetab.metabolics.smooth.SMOOTHING` is the default of the smooth models).
ENERGY_SMOOTHING = 1e-3
#: The models whose total is raised to zero where it is negative (non-negativity rule,
#: Umberger et al. 2003 Eq. 3): a muscle that absorbs more work than its heat costs nothing.
CLAMPED_MODELS = ("UM03", "BH04", "HO06", "UC16")
#: The goal's forms of a model: ``"objective"`` (default) applies the non-negativity rule of the
#: models of :data:`CLAMPED_MODELS` to the work plus the shortening/lengthening heat, so that the
#: activation and maintenance heat is always paid; ``"model"`` keeps the model's rule on the
#: total. The other models have no rule: both forms are the model.
GOAL_FORMS = ("objective", "model")


@dataclass(frozen=True)
class EnergyGoal:
    """Minimise the integrated metabolic rate of the smooth ``model`` with weight ``weight``.

    ``effort_weight``: weight of the effort goal on excitations and activations beside it
    (``None``: the workflow's, 1; 0: energy alone, the reserve and fiber-velocity terms stay).
    ``body_mass_kg``, ``height_m`` and ``muscle_properties`` (an override CSV, or a mapping
    ``{muscle: {"mass_kg": ..., "slow_twitch_fraction": ...}}``) give the muscle masses and
    slow-twitch fractions by the muscle table's rules; ``height_m=None``: every mass from the
    model, ``F0 / sigma * rho * lMo``, as ``musclemetab metabolics`` without ``--height``
    (``muscle_mass_rule`` in the record). ``options``: options of the smooth model
    (:func:`musclemetab.metabolics.smooth.smooth_rates`) other than ``non_negative``, which
    ``form`` sets (:data:`GOAL_FORMS`): ``"objective"`` (default) minimises
    ``H_AM + max(W + H_SL, 0)`` for UM03, BH04, HO06 and UC16 instead of their
    ``max(W + H_AM + H_SL, 0)``, whose zero cost of lengthening muscles lets the optimum
    saturate them; ``"model"`` keeps the model's rule and warns for those four.
    """

    model: str
    weight: float
    body_mass_kg: float
    height_m: float | None
    effort_weight: float | None = None
    smoothing: float = ENERGY_SMOOTHING
    muscle_properties: str | Mapping | None = None
    options: dict = field(default_factory=dict)
    form: str = "objective"

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
        check_subject(float(self.body_mass_kg), 1.0 if self.height_m is None else float(self.height_m))
        if isinstance(self.muscle_properties, os.PathLike):
            object.__setattr__(self, "muscle_properties", os.fspath(self.muscle_properties))
        elif isinstance(self.muscle_properties, Mapping):  # checked now, and a copy: not the caller's to change
            from ..properties import as_overrides

            checked = as_overrides(self.muscle_properties)
            object.__setattr__(self, "muscle_properties", {m: dict(v) for m, v in checked.values.items()})
        object.__setattr__(self, "options", dict(self.options))
        if self.form not in GOAL_FORMS:
            raise OptionError(f"energy goal: unknown form {self.form!r}; choose one of {', '.join(GOAL_FORMS)} "
                              "(docs/energy_objective.md)")
        if "non_negative" in self.options:
            raise OptionError(f"energy goal {key}: the form sets the non-negativity rule; drop the option "
                              f"non_negative and give form='objective' or form='model'")
        if self.form == "model" and key in CLAMPED_MODELS:
            import warnings

            from ..errors import MusclemetabWarning

            warnings.warn(f"energy goal {key} in its model form: the model raises a negative total to zero, so a "
                          "lengthening muscle that absorbs more work than its heat costs nothing and the optimum "
                          "may activate it fully; form='objective' keeps its activation and maintenance heat "
                          "(docs/energy_objective.md)", MusclemetabWarning, stacklevel=3)

    @property
    def non_negative(self):
        """The smooth model's ``non_negative`` option for this form (``None``: the model's own)."""
        from ..metabolics.smooth import WORK_AND_HEAT

        return WORK_AND_HEAT if self.form == "objective" and self.model in CLAMPED_MODELS else None

    def smooth_options(self) -> dict:
        """The options given to :func:`~musclemetab.metabolics.smooth.smooth_rates`."""
        nn = self.non_negative
        return {**self.options, **({"non_negative": nn} if nn is not None else {})}

    def form_record(self) -> dict:
        """Which energy form and smoothing the goal minimises, as the run record keeps it."""
        nn = self.non_negative
        rule = ("max(W + H_SL, 0): work plus shortening/lengthening heat" if nn is not None else
                "max(total, 0): the model's" if self.model in CLAMPED_MODELS else "none (the model has none)")
        return {"model": self.model, "form": self.form, "non_negativity": rule, "smoothing": self.smoothing}

    def muscle_values(self, muscles, max_isometric_force_N, optimal_fiber_length_m):
        """Masses (kg) and slow-twitch fractions of ``muscles`` (arrays). The problem, its
        solution and its summary ask for the same muscles: they are placed (and a muscle the
        table cannot place is warned about) once."""
        overrides = self.muscle_properties
        if isinstance(overrides, Mapping):  # a mapping of the caller: nothing to cache it by
            from ..metabolics.masses import muscle_masses_and_fractions

            mass, fst = muscle_masses_and_fractions(
                list(muscles), float(self.body_mass_kg), None if self.height_m is None else float(self.height_m),
                np.asarray(max_isometric_force_N, dtype=float).ravel(),
                np.asarray(optimal_fiber_length_m, dtype=float).ravel(), overrides)
            return np.asarray(mass, dtype=float), np.asarray(fst, dtype=float)
        stamp = os.stat(overrides).st_mtime_ns if overrides is not None and os.path.isfile(overrides) else None
        mass, fst = _muscle_values(tuple(muscles), float(self.body_mass_kg),
                                   None if self.height_m is None else float(self.height_m),
                                   tuple(np.asarray(max_isometric_force_N, dtype=float).ravel()),
                                   tuple(np.asarray(optimal_fiber_length_m, dtype=float).ravel()), overrides, stamp)
        return mass.copy(), fst.copy()

    def record(self) -> dict:
        """The goal's settings, as ``summary.json`` records them (without a height also the
        ``muscle_mass_rule``; a goal with one records what it always did)."""
        from ..metabolics.masses import mass_rule

        return {"model": self.model, "weight": self.weight, "effort_weight": self.effort_weight,
                "smoothing": self.smoothing, "body_mass_kg": self.body_mass_kg, "height_m": self.height_m,
                **({"muscle_mass_rule": mass_rule(None)} if self.height_m is None else {}),
                "muscle_properties": self.muscle_properties, "options": dict(self.options), "form": self.form,
                "term": "weight * (1/N) * sum over nodes k < N and muscles of Edot (W, no basal) / body mass"}


@functools.lru_cache(maxsize=16)
def _muscle_values(muscles, body_mass_kg, height_m, f0, lmo, overrides, overrides_stamp):
    from ..metabolics.masses import muscle_masses_and_fractions

    mass, fst = muscle_masses_and_fractions(list(muscles), body_mass_kg, height_m, np.asarray(f0), np.asarray(lmo),
                                            overrides)
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
                     smoothing=goal.smoothing, basal=False, **goal.smooth_options())
    return r["total"]
