"""HO06: Houdijk et al. (2006), as implemented in the study."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ._common import (
    BASAL_RATE_W_PER_KG,
    ONE,
    ZERO,
    MetabolicRates,
    as_mask,
    basal_rate,
    basal_view,
    check_flag,
    evaluate_chunked,
    keep_where,
    model_function,
    non_negativity_into,
    prepare_inputs,
    total_into,
)

__all__ = ["houdijk2006", "HOUDIJK_CONSTANTS"]

#: Per fibre type (fast, slow): activation and maintenance heat coefficients (W/kg; Hatze's
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


#: Constants of Hatze's activation-heat ratio as 0-d arrays (cheaper ufunc operands).
_C = SimpleNamespace(rate=np.array(18.2), offset=np.array(-0.25))


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
    non_negative: bool = True,
    basal: bool = True,
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    check: bool = True,
) -> MetabolicRates:
    """HO06: Houdijk, Bobbert & de Haan (2006), as implemented in the study.

    Reference: Houdijk H, Bobbert MF, de Haan A (2006) Evaluation of a Hill based muscle
    model for the energy cost and efficiency of muscular contraction. J Biomech
    39:536-543 (heat terms after Hatze & Buys 1977).

    Equations (W for one muscle; fibre-weighted constants with ``f_FT = 1 - f_ST``)::

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
    (0.35 for fast-twitch, 0.45 for slow-twitch fibres), i.e. far from optimal length; it
    is not clipped.

    Parameters
    ----------
%(shared)s

    Other parameters
    ----------------
    non_negative : bool
        Apply the non-negativity rule (default True, the study's setting).
    """
    model = "HO06"
    for flag in ("non_negative", "basal"):
        check_flag(model, flag, locals()[flag])
    inp = prepare_inputs(model, locals(), check=check, defer_large=True)
    k = HOUDIJK_CONSTANTS
    mass = inp.muscle_mass_kg
    f_st = inp.slow_twitch_fraction
    f_ft = 1.0 - f_st

    # per-muscle constants
    h_a_coef = k["activation_fast_W_per_kg"] * f_ft + k["activation_slow_W_per_kg"] * f_st
    h_m_coef = k["maintenance_fast_W_per_kg"] * f_ft + k["maintenance_slow_W_per_kg"] * f_st
    act_m = mass * h_a_coef
    total_m = mass * (h_a_coef + h_m_coef)
    k3 = k["k3_fast"] * f_ft + k["k3_slow"] * f_st
    k4 = k["k4_fast"] * f_ft + k["k4_slow"] * f_st
    a_short = (k["shortening_fast"] * f_ft + k["shortening_slow"] * f_st) * inp.max_isometric_force_N
    v_scale = inp.max_contraction_velocity * inp.optimal_fiber_length_m
    basal_w = basal_rate(inp, basal, basal_rate_W_per_kg)

    neg_a_short = -a_short

    def kernel(out, s, p, tmp, i):
        work, h_am, h_sl, total, h_a, h_m = out
        a, vb, fl, fv = s
        f0, act_m, total_m, k3, k4, neg_a_short, v_scale, basal_w = p
        t1, t2, t3, m1 = tmp
        np.multiply(a, k4, t1)
        np.add(t1, k3, t1)  # nu_max
        np.multiply(a, a, t2)  # nu_rel
        np.multiply(t2, t1, t3)
        # nu_rel = 0 gives exp(-inf) = 0 in the numerator and h_a = 0
        with np.errstate(divide="ignore"):
            np.divide(_C.rate, t3, t3)
            np.divide(_C.rate, t1, t1)
        np.subtract(_C.offset, t3, t3)
        np.exp(t3, t3)
        np.subtract(ONE, t3, t3)
        np.subtract(_C.offset, t1, t1)
        np.exp(t1, t1)
        np.subtract(ONE, t1, t1)
        np.divide(t3, t1, t3)  # ratio
        np.multiply(t2, act_m, h_a)
        np.multiply(h_a, t3, h_a)
        np.multiply(fl, total_m, h_m)
        np.subtract(h_m, act_m, h_m)
        np.multiply(h_m, a, h_m)
        np.multiply(vb, v_scale, t1)  # V_CE
        np.multiply(a, fl, t2)
        np.multiply(t2, neg_a_short, h_sl)
        np.multiply(h_sl, t1, h_sl)
        keep_where(h_sl, as_mask(np.less_equal(t1, ZERO, m1)))  # no heat unless V_CE <= 0
        np.multiply(t2, fv, work)
        np.multiply(work, f0, work)
        np.negative(t1, t1)
        np.multiply(work, t1, work)
        np.add(h_a, h_m, h_am)
        if non_negative:
            non_negativity_into(work, h_am, h_sl, t1, total, m1, t2, strict=False)
        else:
            np.add(work, h_am, t1)
        total_into(total, t1, h_sl, basal_w)

    work, h_am, h_sl, total, h_a, h_m = evaluate_chunked(
        kernel,
        inp.shape,
        [
            inp.activation, inp.normalized_fiber_velocity, inp.active_force_length_multiplier,
            inp.force_velocity_multiplier,
        ],
        [inp.max_isometric_force_N, act_m, total_m, k3, k4, neg_a_short, v_scale, basal_w],
        6,
        scratch="dddq",
        inputs=inp,
    )
    return MetabolicRates(
        model=model,
        work=work,
        activation_maintenance=h_am,
        shortening_lengthening=h_sl,
        basal=basal_view(basal_w, inp.shape),
        total=total,
        extras={"activation": h_a, "maintenance": h_m},
    )
