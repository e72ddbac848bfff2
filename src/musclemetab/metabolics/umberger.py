"""The Umberger family: UM03, UM10 and UC16.

One formulation (:func:`_umberger_family`) with three settings. Shared equations (W for one
muscle; ``VCE~ = V_CE / lMo`` in optimal lengths per second, negative = shortening)::

    A    = e              if e > a          (excitation/activation blend)
    A    = (e + a)/2      if e <= a
    A_AM = A^0.6
    A_S  = A^2 if VCE~ <= 0 (shortening, isometric), A if VCE~ > 0 (lengthening)
    S    = 1.5                               (aerobic scaling factor)
    vmax_ST = vmax/2.5;  alpha_S_ST = 100/vmax_ST;  alpha_S_FT = 153/vmax
    h_AM = 128 f_FT' + 25                                          (W/kg)
    h_SL = -(alpha_S_ST VCE~ f_ST' + alpha_S_FT VCE~ f_FT') A_S    if VCE~ <= 0
    h_SL =  alpha_L VCE~ A                                         if VCE~ >  0
    H_AM = h_AM A_AM S m            (x (0.4 + 0.6 fL) if lM > lMo)
    H_SL = h_SL S m                 (x fL             if lM > lMo)
    W_CE = -F_CE V_CE,   F_CE = a fL fV F0   (no passive force, along the fibre)

``f_ST'`` and ``f_FT' = 1 - f_ST'`` are the muscle's constant fibre fractions (UM03, UM10)
or the excitation-dependent recruited fractions (UC16).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ._common import (
    BASAL_RATE_W_PER_KG,
    HALF,
    ONE,
    QUARTER_PI,
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
    select_into,
    total_into,
)

__all__ = ["umberger2003", "umberger2010", "uchida2016", "AEROBIC_FACTOR"]

#: Aerobic scaling factor S (multiplies the activation-maintenance and the
#: shortening-lengthening heat).
AEROBIC_FACTOR = 1.5
#: vmax of slow-twitch fibres is vmax / 2.5.
SLOW_TWITCH_VMAX_RATIO = 2.5
#: alpha_L = factor * alpha_S_ST: 4 in Umberger et al. (2003) (and UC16), 0.3 in Umberger (2010).
LENGTHENING_FACTOR_2003 = 4.0
LENGTHENING_FACTOR_2010 = 0.3


def _umberger_family(
    model: str,
    values: dict,
    *,
    lengthening_factor: float,
    include_negative_work: bool,
    recruitment: bool,
    non_negative: bool,
    strict: bool,
    slow_twitch_shortening_cap: bool,
    basal: bool,
    basal_rate_W_per_kg: float,
    check: bool,
) -> MetabolicRates:
    for flag in ("include_negative_work", "non_negative", "slow_twitch_shortening_cap", "basal"):
        check_flag(model, flag, locals()[flag])
    inp = prepare_inputs(model, values, check=check, defer_large=True)

    # per-muscle constants (parameter-shaped)
    vmax = inp.max_contraction_velocity
    f_st = inp.slow_twitch_fraction
    vmax_st = vmax / SLOW_TWITCH_VMAX_RATIO
    alpha_st = 100.0 / vmax_st
    alpha_ft = 153.0 / vmax
    alpha_l = lengthening_factor * alpha_st
    s_m = AEROBIC_FACTOR * inp.muscle_mass_kg
    basal_w = basal_rate(inp, basal, basal_rate_W_per_kg)
    if recruitment:
        am_coef = s_m  # h_AM depends on the recruited fractions: computed per sample
        st_coef, ft_coef = alpha_st, alpha_ft
    else:
        am_coef = (128.0 * (1.0 - f_st) + 25.0) * s_m
        st_coef = alpha_st * f_st
        ft_coef = alpha_ft * (1.0 - f_st)
    cap = slow_twitch_shortening_cap
    # -(st + ft) VCE~ A^2 without the cap; -(F_CE V_CE) = F_CE (VCE~ (-lMo)) exactly
    neg_coef = -(st_coef + ft_coef)
    neg_lmo = -inp.optimal_fiber_length_m
    neg_vmax_st = -vmax_st

    def kernel(out, s, p, tmp, i):
        work, h_am, h_sl, total = out
        e, a, lm, vb, fl, fv = s
        vmax, f0, neg_lmo, f_st, s_m, am_coef, st_coef, ft_coef, neg_coef, alpha_l, neg_vmax_st, basal_w = p
        vt, blend, t1, t2, f_st_r, f_ft_r, shortening, longer, m3 = tmp
        np.multiply(vb, vmax, vt)  # VCE~ (lMo/s)
        as_mask(np.less_equal(vt, ZERO, shortening))
        as_mask(np.greater(lm, ONE, longer))
        np.maximum(e, a, out=blend)  # e if e > a, else (e + a)/2 (exact: 0.5 (e + e) = e)
        np.add(e, blend, blend)
        np.multiply(blend, HALF, blend)
        np.power(blend, _C.am_exponent, t1)
        if recruitment:
            _recruited_slow_twitch_fraction_into(e, f_st, f_st_r, t2, m3)
            np.subtract(ONE, f_st_r, f_ft_r)
            np.multiply(f_ft_r, _C.am_fast, h_am)
            np.add(h_am, _C.am_base, h_am)
            np.multiply(h_am, am_coef, h_am)
            np.multiply(h_am, t1, h_am)
            np.multiply(f_st_r, st_coef, f_st_r)  # st
            np.multiply(f_ft_r, ft_coef, f_ft_r)  # ft
        else:
            np.multiply(t1, am_coef, h_am)
        # above optimal length: h_am (0.4 + 0.6 fL)
        np.multiply(fl, _C.am_length_slope, t1)
        np.add(t1, _C.am_length_base, t1)
        np.multiply(t1, h_am, t1)
        select_into(h_am, longer, t1, t2)
        # lengthening heat (t2), replaced by the shortening heat where VCE~ <= 0
        np.multiply(vt, alpha_l, t2)
        np.multiply(t2, blend, t2)
        np.multiply(blend, blend, blend)
        if recruitment:
            if cap:
                np.maximum(vt, neg_vmax_st, out=t1)
                np.multiply(f_st_r, t1, t1)
                np.multiply(f_ft_r, vt, h_sl)
                np.add(t1, h_sl, h_sl)
                np.negative(h_sl, h_sl)
            else:
                np.add(f_st_r, f_ft_r, h_sl)
                np.negative(h_sl, h_sl)
                np.multiply(h_sl, vt, h_sl)
        elif cap:
            np.maximum(vt, neg_vmax_st, out=t1)
            np.multiply(t1, st_coef, t1)
            np.multiply(vt, ft_coef, h_sl)
            np.add(t1, h_sl, h_sl)
            np.negative(h_sl, h_sl)
        else:
            np.multiply(vt, neg_coef, h_sl)
        np.multiply(h_sl, blend, h_sl)  # times A^2
        select_into(t2, shortening, h_sl, t1)
        np.multiply(t2, s_m, h_sl)
        np.multiply(h_sl, fl, t1)  # above optimal length: times fL
        select_into(h_sl, longer, t1, t2)
        # work rate
        np.multiply(a, fl, work)
        np.multiply(work, fv, work)
        np.multiply(work, f0, work)
        np.multiply(vt, neg_lmo, t1)
        np.multiply(work, t1, work)
        if not include_negative_work:  # 0 where VCE~ > 0
            keep_where(work, shortening)
        if non_negative:
            non_negativity_into(work, h_am, h_sl, t1, total, m3, t2, strict=strict)
        else:
            np.add(work, h_am, t1)
        total_into(total, t1, h_sl, basal_w)

    work, h_am, h_sl, total = evaluate_chunked(
        kernel,
        inp.shape,
        [
            inp.excitation, inp.activation, inp.normalized_fiber_length, inp.normalized_fiber_velocity,
            inp.active_force_length_multiplier, inp.force_velocity_multiplier,
        ],
        [
            vmax, inp.max_isometric_force_N, neg_lmo, f_st, s_m, am_coef, st_coef, ft_coef, neg_coef, alpha_l,
            neg_vmax_st, basal_w,
        ],
        4,
        scratch="ddddddqqq",
        inputs=inp,
    )
    return MetabolicRates(
        model=model, work=work, activation_maintenance=h_am, shortening_lengthening=h_sl,
        basal=basal_view(basal_w, inp.shape), total=total,
    )


def _recruited_slow_twitch_fraction(excitation, slow_twitch_fraction):
    """UC16's recruited slow-twitch fraction (orderly recruitment from excitation).

    ``u_f = 1 - cos(pi e/2)``, ``u_s = sin(pi e/2)``,
    ``f_ST' = f_ST u_s / (f_ST u_s + f_FT u_f)``, and ``f_ST' = 1`` where the denominator
    is zero (``e = 0``; the reference implementation tests ``e == 0``).

    With ``t = tan(pi e/4)``, ``u_f = t u_s`` (see
    :func:`~musclemetab.metabolics._common.recruitment_terms`), so where ``u_s != 0`` the
    fraction is ``f_ST / (f_ST + f_FT t)``. That form is evaluated, with 1 where its
    denominator is zero; at ``e = 0`` (``t = 0``) it gives 1 for every ``f_ST``, as the
    definition does.
    """
    t = np.tan(QUARTER_PI * np.asarray(excitation, dtype=float))
    den = slow_twitch_fraction + (1.0 - slow_twitch_fraction) * t
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den == 0, 1.0, slow_twitch_fraction / den)


def _recruited_slow_twitch_fraction_into(excitation, slow_twitch_fraction, out, tmp, mask) -> None:
    """:func:`_recruited_slow_twitch_fraction` into ``out`` (chunk kernels; ``tmp`` (float)
    and ``mask`` (int64) are scratch arrays), with the same arithmetic."""
    np.multiply(QUARTER_PI, excitation, tmp)
    np.tan(tmp, tmp)
    np.multiply(ONE - slow_twitch_fraction, tmp, tmp)
    np.add(slow_twitch_fraction, tmp, tmp)  # den
    with np.errstate(divide="ignore", invalid="ignore"):
        np.divide(slow_twitch_fraction, tmp, out)
    np.equal(tmp, ZERO, mask)
    if mask.any():
        select_into(out, as_mask(mask), ONE, tmp)


#: Constants of the kernel as 0-d arrays (cheaper ufunc operands, same arithmetic).
_C = SimpleNamespace(
    am_exponent=np.array(0.6),
    am_fast=np.array(128.0),
    am_base=np.array(25.0),
    am_length_slope=np.array(0.6),
    am_length_base=np.array(0.4),
)


@model_function("UM03")
def umberger2003(
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
    include_negative_work: bool = True,
    slow_twitch_shortening_cap: bool = False,
    basal: bool = True,
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    check: bool = True,
) -> MetabolicRates:
    """UM03: Umberger, Gerritsen & Martin (2003), as implemented in the study.

    Reference: Umberger BR, Gerritsen KGM, Martin PE (2003) A model of human muscle energy
    expenditure. Comput Methods Biomech Biomed Engin 6:99-111.

    Equations: the Umberger family (module :mod:`musclemetab.metabolics.umberger`) with
    constant fibre fractions and the lengthening coefficient
    ``alpha_L = 4 alpha_S_ST`` (100 W/kg per lMo/s for vmax = 10)::

        Edot = W_CE + H_AM + H_SL (+ basal)

    The full (signed) work rate ``W_CE`` is counted. Non-negativity (paper Eq. 3; study
    setting on): where ``W_CE + H_AM + H_SL < 0`` (strict), ``H_SL := -H_AM - W_CE`` so that
    the rate is zero; the basal heat is added afterwards. Units: W.

    Quirks of the study's implementation reproduced by default: the slow-twitch cap of
    the shortening heat is off (``slow_twitch_shortening_cap``); the passive force is not
    used; the minimum heat rate of 1 W/kg is not enforced.

    Parameters
    ----------
%(shared)s

    Other parameters
    ----------------
    non_negative : bool
        Apply the non-negativity rule (default True, the study's setting).
    include_negative_work : bool
        Count negative (eccentric) work (default True). False gives UM10's work term.
    slow_twitch_shortening_cap : bool
        Cap the slow-twitch shortening term at ``alpha_S_ST vmax_ST`` (100 W/kg, reached
        when shortening faster than ``vmax/2.5``), as Umberger et al. (2003) and OpenSim's
        ``Umberger2010MuscleMetabolicsProbe`` do. Default False: the study's code has the
        cap commented out.
    """
    return _umberger_family(
        "UM03",
        locals(),
        lengthening_factor=LENGTHENING_FACTOR_2003,
        include_negative_work=include_negative_work,
        recruitment=False,
        non_negative=non_negative,
        strict=True,
        slow_twitch_shortening_cap=slow_twitch_shortening_cap,
        basal=basal,
        basal_rate_W_per_kg=basal_rate_W_per_kg,
        check=check,
    )


@model_function("UM10")
def umberger2010(
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
    non_negative: bool = False,
    include_negative_work: bool = False,
    slow_twitch_shortening_cap: bool = False,
    basal: bool = True,
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    check: bool = True,
) -> MetabolicRates:
    """UM10: Umberger (2010), as implemented in the study.

    Reference: Umberger BR (2010) Stance and swing phase costs in human walking.
    J R Soc Interface 7:1329-1340.

    Equations: UM03 (module :mod:`musclemetab.metabolics.umberger`) except

    * lengthening coefficient ``alpha_L = 0.3 alpha_S_ST`` (7.5 W/kg per lMo/s for
      vmax = 10);
    * only concentric work is counted: ``W = -F_CE V_CE`` where ``V_CE <= 0``, else 0;
    * no non-negativity rule (the rate is never negative since ``W >= 0`` and the heats
      are non-negative; during lengthening it is the heat alone).

    ``Edot = W + H_AM + H_SL (+ basal)``, W. The Umberger (2010) rule that the total heat
    rate be at least 1 W/kg is not applied (commented out in the study's code); nor is the
    slow-twitch cap (option).

    Parameters
    ----------
%(shared)s

    Other parameters
    ----------------
    non_negative : bool
        Apply the non-negativity rule (default False, the study's setting).
    include_negative_work : bool
        Count negative work (default False, the UM10 formulation).
    slow_twitch_shortening_cap : bool
        Cap the slow-twitch shortening term at ``alpha_S_ST vmax_ST`` (100 W/kg, reached
        when shortening faster than ``vmax/2.5``), as Umberger et al. (2003) and OpenSim's
        ``Umberger2010MuscleMetabolicsProbe`` do. Default False: the study's code has the
        cap commented out.
    """
    return _umberger_family(
        "UM10",
        locals(),
        lengthening_factor=LENGTHENING_FACTOR_2010,
        include_negative_work=include_negative_work,
        recruitment=False,
        non_negative=non_negative,
        strict=False,
        slow_twitch_shortening_cap=slow_twitch_shortening_cap,
        basal=basal,
        basal_rate_W_per_kg=basal_rate_W_per_kg,
        check=check,
    )


@model_function("UC16")
def uchida2016(
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
    include_negative_work: bool = True,
    slow_twitch_shortening_cap: bool = False,
    basal: bool = True,
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    check: bool = True,
) -> MetabolicRates:
    """UC16: Uchida et al. (2016), the Umberger formulation with orderly recruitment.

    Reference: Uchida TK, Hicks JL, Dembia CL, Delp SL (2016) Stretching your energetic
    budget: how tendon compliance affects the metabolic cost of running. PLoS ONE
    11:e0150378.

    Equations: UM03 (module :mod:`musclemetab.metabolics.umberger`) with the fibre
    fractions replaced by excitation-dependent recruited fractions::

        u_f = 1 - cos(pi e/2),   u_s = sin(pi e/2)
        f_ST' = f_ST u_s / (f_ST u_s + f_FT u_f)      (1 where e = 0),  f_FT' = 1 - f_ST'

    used in ``h_AM = 128 f_FT' + 25`` and in the shortening heat. Lengthening coefficient
    ``alpha_L = 4 alpha_S_ST`` (UM03's value, as in the paper's Table 1). Full work rate.
    Non-negativity (``total <= 0`` -> ``H_SL := -H_AM - W_CE``) is applied always in the
    study's code (here the default). Units: W.

    Parameters
    ----------
%(shared)s

    Other parameters
    ----------------
    non_negative : bool
        Apply the non-negativity rule (default True).
    include_negative_work : bool
        Count negative work (default True).
    slow_twitch_shortening_cap : bool
        Cap the slow-twitch shortening term at ``alpha_S_ST vmax_ST`` (100 W/kg, reached
        when shortening faster than ``vmax/2.5``), as Umberger et al. (2003) and OpenSim's
        ``Umberger2010MuscleMetabolicsProbe`` do. Default False: the study's code has the
        cap commented out.
    """
    return _umberger_family(
        "UC16",
        locals(),
        lengthening_factor=LENGTHENING_FACTOR_2003,
        include_negative_work=include_negative_work,
        recruitment=True,
        non_negative=non_negative,
        strict=False,
        slow_twitch_shortening_cap=slow_twitch_shortening_cap,
        basal=basal,
        basal_rate_W_per_kg=basal_rate_W_per_kg,
        check=check,
    )

