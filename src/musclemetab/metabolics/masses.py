"""The muscle masses and slow-twitch fractions of the metabolic models and of the energy goal.

With the body height: the anatomical volume rule (:func:`musclemetab.properties.metabolic_properties`);
without it: each muscle's mass from the model, ``F0 / sigma * rho * lMo`` (``docs/metabolics.md``).
The outputs name the rule used (``muscle_mass_rule``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["MASS_RULE_VOLUME", "MASS_RULE_MODEL", "muscle_masses_and_fractions", "mass_rule",
           "model_muscle_masses_kg"]


#: ``muscle_mass_rule`` of the outputs: masses from body mass and height (the anatomical volume rule).
MASS_RULE_VOLUME = "volume (body mass, height)"
#: ``muscle_mass_rule`` without a height: every mass from the model, ``F0 / sigma * rho * lMo``.
MASS_RULE_MODEL = "model (F0 / specific tension x density x lMo)"


def muscle_masses_and_fractions(names, body_mass_kg: float, height_m: float | None, max_isometric_force_N,
                                optimal_fiber_length_m, overrides=None, *, strict: bool = False):
    """Each muscle's mass (kg) and slow-twitch fraction as the metabolic models and the energy
    goal take them: with a height the anatomical volume rule
    (:func:`musclemetab.properties.metabolic_properties`, :data:`MASS_RULE_VOLUME`); without one
    (``height_m=None``) the model's ``F0 / sigma * rho * lMo`` (:func:`model_muscle_masses_kg`,
    :data:`MASS_RULE_MODEL`), the body mass checked alone. The height enters nothing else."""
    from ..properties import (FALLBACK_SLOW_TWITCH_FRACTION, as_overrides, check_subject, metabolic_properties,
                              slow_twitch_fraction)

    overrides = as_overrides(overrides)
    if height_m is not None:
        return metabolic_properties(list(names), body_mass_kg, height_m, max_isometric_force_N,
                                    optimal_fiber_length_m, overrides=overrides, strict=strict)
    check_subject(float(body_mass_kg), 1.0)  # the body mass alone (1 m: any plausible height)
    masses = model_muscle_masses_kg(names, max_isometric_force_N, optimal_fiber_length_m, overrides)
    fst = slow_twitch_fraction(list(names), FALLBACK_SLOW_TWITCH_FRACTION, overrides=overrides,
                               max_isometric_force_N=max_isometric_force_N)
    return masses, fst


def mass_rule(height_m: float | None) -> str:
    """``muscle_mass_rule`` of the outputs: :data:`MASS_RULE_VOLUME` with a height, else :data:`MASS_RULE_MODEL`."""
    return MASS_RULE_MODEL if height_m is None else MASS_RULE_VOLUME


def model_muscle_masses_kg(names, max_isometric_force_N, optimal_fiber_length_m, overrides=None) -> np.ndarray:
    """Each muscle's mass (kg) from the model alone: ``F0 / sigma * rho * lMo``, the rule of
    OpenSim's metabolic probes (``muscle mass = (F0 / specific tension) x density x lMo``), with
    ``rho`` = 1059.7 kg/m^3 and ``sigma`` the muscle's specific tension of the anatomical muscle
    table (0.6 MPa for a muscle it cannot place); override masses are used as given. Used when
    no body height is given: the volume rule needs it."""
    from ..properties import MUSCLE_DENSITY_KG_PER_M3, resolve_muscles

    recs = resolve_muscles(list(names), max_isometric_force_N, overrides, warn=False)
    f0 = np.asarray(max_isometric_force_N, dtype=float)
    lmo = np.asarray(optimal_fiber_length_m, dtype=float)
    return np.array([r.mass_kg_override if r.mass_kg_override is not None
                     else f0[i] / r.specific_tension_Pa * MUSCLE_DENSITY_KG_PER_M3 * lmo[i]
                     for i, r in enumerate(recs)])
