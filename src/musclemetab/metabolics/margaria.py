"""MA68: Margaria (1968), a whole-muscle efficiency model (an additional model, not the study's)."""

from __future__ import annotations

import numpy as np

from ._common import (
    BASAL_RATE_W_PER_KG,
    MetabolicRates,
    basal_rate,
    basal_view,
    check_flag,
    model_function,
    prepare_inputs,
)

__all__ = ["margaria1968", "MARGARIA_CONSTANTS"]

#: Margaria (1968): the efficiency of positive work (0.25) and the factor of the negative
#: work rate (-1.2), as the KU Leuven muscle redundancy solver and Koelewijn et al. (2019)
#: write the model (Margaria measured an efficiency of about -120 % for negative work).
MARGARIA_CONSTANTS = {
    "positive_work_efficiency": 0.25,
    "negative_work_factor": -1.2,
}


@model_function("MA68")
def margaria1968(
    excitation,
    activation,
    normalized_fiber_length,
    normalized_fiber_velocity,
    active_force_length_multiplier,
    force_velocity_multiplier,
    passive_fiber_force_N,
    max_isometric_force_N,
    optimal_fiber_length_m,
    max_contraction_velocity,
    muscle_mass_kg,
    slow_twitch_fraction,
    *,
    time_s=None,
    basal: bool = True,
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    check: bool = True,
) -> MetabolicRates:
    """MA68: Margaria (1968), metabolic rate from the fiber's mechanical work rate alone.

    Reference: Margaria R (1968) Positive and negative work performances and their
    efficiencies in human locomotion. Int Z Angew Physiol 25:339-351; in the form of
    Koelewijn AD, Heinrich D, van den Bogert AJ (2019) Metabolic cost calculations of gait
    using musculoskeletal energy models, a comparison study. PLoS ONE 14:e0222037.

    Equations (W for one muscle; ``W_CE = -a fL fV F0 V_CE``, positive when the fiber
    shortens)::

        Edot = W_CE / 0.25        if W_CE >= 0     (positive work, efficiency 25 %)
        Edot = -1.2 W_CE          if W_CE <  0     (negative work)
        (+ basal)

    Isometric contraction costs nothing (no heat model). The factor of negative work is
    -1.2 as the KU Leuven solver and Koelewijn et al. (2019) write it (a cost of 1.2 J per
    J absorbed); dividing by Margaria's efficiency of -1.2 instead would give 1/1.2.
    Excitation, length and fiber type are not used.

    Components: ``work`` = ``W_CE``; ``shortening_lengthening`` = ``Edot - W_CE``, the heat
    the efficiency implies (3 ``W_CE`` in shortening, -2.2 ``W_CE`` in lengthening);
    ``activation_maintenance`` = 0.

    Parameters
    ----------
%(shared)s
    """
    model = "MA68"
    check_flag(model, "basal", basal)
    inp = prepare_inputs(model, locals(), check=check)
    k = MARGARIA_CONSTANTS
    F_CE = inp.activation * inp.active_force_length_multiplier * inp.force_velocity_multiplier * inp.max_isometric_force_N
    W_CE = F_CE * inp.normalized_fiber_velocity * -(inp.max_contraction_velocity * inp.optimal_fiber_length_m)
    if np.shape(W_CE) != inp.shape:
        W_CE = np.broadcast_to(W_CE, inp.shape).copy()
    # W_CE / 0.25 where W_CE >= 0, -1.2 W_CE where W_CE < 0: each is >= 0 in its branch and <= 0
    # in the other, so the cost is the larger of the two
    Edot = np.maximum(W_CE / k["positive_work_efficiency"], k["negative_work_factor"] * W_CE)
    B = basal_rate(inp, basal, basal_rate_W_per_kg)
    return MetabolicRates(
        model=model, work=W_CE, activation_maintenance=np.zeros(inp.shape),
        shortening_lengthening=Edot - W_CE, basal=basal_view(B, inp.shape), total=Edot + B,
    )
