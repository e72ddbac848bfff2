"""HO06: Houdijk et al. (2006), as implemented in the study."""

from __future__ import annotations

import numpy as np

from ._common import (
    BASAL_RATE_W_PER_KG,
    FIBER_FRACTIONS,
    MetabolicRates,
    apply_non_negativity,
    basal_rate,
    basal_view,
    check_choice,
    check_flag,
    model_function,
    prepare_inputs,
    recruited_slow_twitch_fraction,
)

__all__ = ["houdijk2006", "HOUDIJK_CONSTANTS"]

#: Per fiber type (fast, slow): activation and maintenance heat coefficients (W/kg; Hatze's
#: stable heat 150 / 24.4 W/kg split 0.35 / 0.45 into activation heat), Hatze's
#: stimulation-frequency constants k3 and k4 (1/s), and the shortening-heat coefficient
#: (times F0).
HOUDIJK_CONSTANTS = {
    "activation_fast_W_per_kg": 0.35 * 150.0,  # 52.50
    "activation_slow_W_per_kg": 0.45 * 24.4,  # 10.98
    "maintenance_fast_W_per_kg": 0.65 * 150.0,  # 97.50
    "maintenance_slow_W_per_kg": 0.55 * 24.4,  # 13.42
    "k3_fast": 12.0,
    "k3_slow": 6.0,
    "k4_fast": 14.0,
    "k4_slow": 8.0,
    "shortening_fast": 0.28,
    "shortening_slow": 0.16,
}


@model_function("HO06")
def houdijk2006(
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
    fiber_fractions: str = "constant",
    non_negative: bool = True,
    basal: bool = True,
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    check: bool = True,
) -> MetabolicRates:
    """HO06: Houdijk, Bobbert & de Haan (2006), as implemented in the study.

    Reference: Houdijk H, Bobbert MF, de Haan A (2006) Evaluation of a Hill based muscle
    model for the energy cost and efficiency of muscular contraction. J Biomech
    39:536-543 (heat terms after Hatze & Buys 1977).

    Equations (W for one muscle; fiber-weighted constants with ``f_FT = 1 - f_ST``)::

        hA = 52.50 f_FT + 10.98 f_ST,  hM = 97.50 f_FT + 13.42 f_ST         (W/kg)
        k3 = 12 f_FT + 6 f_ST,  k4 = 14 f_FT + 8 f_ST,  a~ = (0.28 f_FT + 0.16 f_ST) F0
        nu_max = k3 + k4 a,   nu_rel = a^2
        H_A  = m hA nu_rel [1 - exp(-0.25 - 18.2/(nu_rel nu_max))]
                           / [1 - exp(-0.25 - 18.2/nu_max)]                (0 at a = 0)
        H_M  = m (hA + hM) a (fL - hA/(hA + hM))
        H_SL = -a~ a fL V_CE      if V_CE <= 0,   0 if V_CE > 0   (V_CE in m/s)
        W_CE = -a fL fV F0 V_CE
        Edot = W_CE + H_A + H_M + H_SL (+ basal)

    Non-negativity (study setting on): where ``Edot <= 0``, ``H_SL := -H_A - H_M - W_CE``.
    Only activation drives the heats (excitation unused); no lengthening heat.
    ``activation_maintenance = H_A + H_M``; ``extras`` gives ``activation`` and
    ``maintenance`` separately.

    Quirk reproduced: the maintenance heat is **negative** where ``fL < hA/(hA + hM)``
    (0.35 for fast-twitch, 0.45 for slow-twitch fibers), i.e. far from optimal length; it
    is not clipped.

    Parameters
    ----------
    %(energy_model_arguments)s

    Other parameters
    ----------------
    fiber_fractions : {"constant", "recruited"}
        ``f_ST`` and ``f_FT`` in the fiber-weighted constants: the muscle's (default, the
        study's setting) or Uchida et al. (2016)'s recruited fractions at the excitation of
        each sample (the study's ``option = 2``; the excitation then enters the heats).
    non_negative : bool
        Apply the non-negativity rule (default True, the study's setting).
    """
    model = "HO06"
    for flag in ("non_negative", "basal"):
        check_flag(model, flag, locals()[flag])
    check_choice(model, "fiber_fractions", fiber_fractions, FIBER_FRACTIONS)
    inp = prepare_inputs(model, locals(), check=check)
    k = HOUDIJK_CONSTANTS
    a, f_l, f_v = inp.activation, inp.active_force_length_multiplier, inp.force_velocity_multiplier
    m, F0 = inp.muscle_mass_kg, inp.max_isometric_force_N
    if fiber_fractions == "recruited":
        f_st = recruited_slow_twitch_fraction(inp.excitation, inp.slow_twitch_fraction)
    else:
        f_st = inp.slow_twitch_fraction
    f_ft = 1.0 - f_st

    # fiber-weighted constants
    h_A = k["activation_fast_W_per_kg"] * f_ft + k["activation_slow_W_per_kg"] * f_st
    h_M = k["maintenance_fast_W_per_kg"] * f_ft + k["maintenance_slow_W_per_kg"] * f_st
    k3 = k["k3_fast"] * f_ft + k["k3_slow"] * f_st
    k4 = k["k4_fast"] * f_ft + k["k4_slow"] * f_st
    a_tilde = (k["shortening_fast"] * f_ft + k["shortening_slow"] * f_st) * F0  # N

    # (the arrays that are no longer needed are freed as we go: less memory in use at once)
    minus_V_CE = inp.normalized_fiber_velocity * -(inp.max_contraction_velocity * inp.optimal_fiber_length_m)  # m/s
    X = a * f_l
    W_CE = X * f_v * F0 * minus_V_CE
    H_SL = a_tilde * X * np.maximum(minus_V_CE, 0.0)  # -a~ a fL V_CE where V_CE <= 0, else 0
    del X, minus_V_CE
    H_M = m * (h_A + h_M) * a * (f_l - h_A / (h_A + h_M))

    nu_max = k3 + k4 * a
    nu_rel = a * a
    # ratio = [1 - exp(-0.25 - 18.2/(nu_rel nu_max))] / [1 - exp(-0.25 - 18.2/nu_max)]: each
    # 1 - exp(x) is -expm1(x), and the two signs cancel
    with np.errstate(divide="ignore"):  # nu_rel = 0: expm1(-inf) = -1 and H_A = 0
        ratio = np.expm1(-0.25 - 18.2 / (nu_rel * nu_max)) / np.expm1(-0.25 - 18.2 / nu_max)
    del nu_max
    H_A = m * h_A * nu_rel * ratio
    del nu_rel, ratio

    H_AM = H_A + H_M
    rest = W_CE + H_AM
    if non_negative:
        H_SL = apply_non_negativity(rest, H_SL)
    B = basal_rate(inp, basal, basal_rate_W_per_kg)
    return MetabolicRates(
        model=model,
        work=W_CE,
        activation_maintenance=H_AM,
        shortening_lengthening=H_SL,
        basal=basal_view(B, inp.shape),
        total=rest + H_SL + B,
        extras={"activation": H_A, "maintenance": H_M},
    )
