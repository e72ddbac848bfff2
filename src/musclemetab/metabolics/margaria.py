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

#: Margaria (1968): the efficiency of positive work (0.25) and of negative work (-1.2: a muscle
#: absorbing negative work W < 0 at an efficiency W/E = -1.2 spends E = |W|/1.2).
MARGARIA_CONSTANTS = {
    "positive_work_efficiency": 0.25,
    "negative_work_efficiency": -1.2,
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
    efficiencies in human locomotion. Int Z Angew Physiol 25:339-351. Margaria measured the
    metabolic cost of walking up and down slopes and found an efficiency (mechanical work over
    metabolic energy) of about 25 % for positive work and about -120 % for negative work; the
    model charges each sign of the fiber's work at that efficiency. Koelewijn AD, Heinrich D,
    van den Bogert AJ (2019) PLoS ONE 14:e0222037 include it, applied to each muscle, in their
    comparison of energy models for gait.

    Equations (W for one muscle; ``W_CE = -a fL fV F0 V_CE``, positive when the fiber
    shortens)::

        Edot = W_CE / 0.25        if W_CE >= 0     (positive work, efficiency 25 %)
        Edot = W_CE / (-1.2)      if W_CE <  0     (negative work, efficiency -120 %)
        (+ basal)

    So 100 W of positive work costs 400 W and 100 W of negative work (``W_CE = -100 W``)
    costs 83.3 W. Isometric contraction costs nothing (no heat model). Excitation, length and
    fiber type are not used.

    Components: ``work`` = ``W_CE``; ``shortening_lengthening`` = ``Edot - W_CE``, the heat
    the efficiency implies (3 ``W_CE`` in shortening, ``-(1 + 1/1.2) W_CE`` in lengthening);
    ``activation_maintenance`` = 0.

    Parameters
    ----------
    %(energy_model_arguments)s
    """
    model = "MA68"
    check_flag(model, "basal", basal)
    inp = prepare_inputs(model, locals(), check=check)
    k = MARGARIA_CONSTANTS
    F_CE = inp.activation * inp.active_force_length_multiplier * inp.force_velocity_multiplier * inp.max_isometric_force_N
    W_CE = F_CE * inp.normalized_fiber_velocity * -(inp.max_contraction_velocity * inp.optimal_fiber_length_m)
    if np.shape(W_CE) != inp.shape:
        W_CE = np.broadcast_to(W_CE, inp.shape).copy()
    # W_CE / 0.25 where W_CE >= 0, W_CE / -1.2 where W_CE < 0: each is >= 0 in its branch and <= 0
    # in the other, so the cost is the larger of the two
    Edot = np.maximum(W_CE / k["positive_work_efficiency"], W_CE / k["negative_work_efficiency"])
    B = basal_rate(inp, basal, basal_rate_W_per_kg)
    return MetabolicRates(
        model=model, work=W_CE, activation_maintenance=np.zeros(inp.shape),
        shortening_lengthening=Edot - W_CE, basal=basal_view(B, inp.shape), total=Edot + B,
    )
