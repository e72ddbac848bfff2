"""The Umberger family: UM03, UM10 and UC16.

One formulation (:func:`_umberger_family`) with three settings. Shared equations (W for one
muscle; ``VCE~ = V_CE / lMo`` in optimal lengths per second, negative = shortening)::

    A    = e              if e > a          (excitation/activation blend)
    A    = (e + a)/2      if e <= a
    A_AM = A^0.6
    A_S  = A^2 if VCE~ <= 0 (shortening, isometric), A if VCE~ > 0 (lengthening)
    S    = 1.5 (aerobic) or 1.0 (anaerobic)  (effort scaling, option effort_scaling)
    vmax_ST = vmax/2.5;  alpha_S_ST = 100/vmax_ST;  alpha_S_FT = 153/vmax
    h_AM = 128 f_FT' + 25                                          (W/kg)
    h_SL = -(alpha_S_ST VCE~ f_ST' + alpha_S_FT VCE~ f_FT') A_S    if VCE~ <= 0
    h_SL =  alpha_L VCE~ A                                         if VCE~ >  0
    H_AM = h_AM A_AM S m            (x (0.4 + 0.6 fL) if lM > lMo)
    H_SL = h_SL S m                 (x fL             if lM > lMo)
    W_CE = -F_CE V_CE,   F_CE = a fL fV F0   (no passive force, along the fiber)

``f_ST'`` and ``f_FT' = 1 - f_ST'`` are the muscle's constant fiber fractions (UM03, UM10)
or the excitation-dependent recruited fractions (UC16).
"""

from __future__ import annotations

import numpy as np

from ._common import (
    BASAL_RATE_W_PER_KG,
    MetabolicRates,
    apply_minimum_heat_rate,
    apply_non_negativity,
    basal_rate,
    basal_view,
    check_flag,
    check_number,
    model_function,
    prepare_inputs,
    recruited_slow_twitch_fraction,
    select,
)

__all__ = ["umberger2003", "umberger2010", "uchida2016", "AEROBIC_FACTOR", "ANAEROBIC_FACTOR"]

#: Effort scaling factor S (multiplies the activation-maintenance and the
#: shortening-lengthening heat): 1.5 for mostly aerobic activity such as walking (the
#: study's value and OpenSim's default), 1.0 for anaerobic activity (Umberger et al. 2003).
AEROBIC_FACTOR = 1.5
ANAEROBIC_FACTOR = 1.0
#: vmax of slow-twitch fibers is vmax / 2.5.
SLOW_TWITCH_VMAX_RATIO = 2.5
#: alpha_L = factor * alpha_S_ST: 4 in Umberger et al. (2003) (and UC16), 0.3 in Umberger (2010).
LENGTHENING_FACTOR_2003 = 4.0
LENGTHENING_FACTOR_2010 = 0.3


def _umberger_family(
    model: str,
    values: dict,
    *,
    lengthening_factor: float,
    recruitment: bool,
) -> MetabolicRates:
    """The Umberger family's equations (module docstring) with the options of ``values``."""
    for flag in ("include_negative_work", "non_negative", "slow_twitch_shortening_cap", "basal"):
        check_flag(model, flag, values[flag])
    S = check_number(model, "effort_scaling", values["effort_scaling"])
    minimum = check_number(model, "minimum_heat_rate_W_per_kg", values["minimum_heat_rate_W_per_kg"],
                           allow_none=True)
    inp = prepare_inputs(model, values, check=values["check"])
    e, a = inp.excitation, inp.activation
    l_m, f_l, f_v = inp.normalized_fiber_length, inp.active_force_length_multiplier, inp.force_velocity_multiplier
    m, F0, l_mo, v_max = (inp.muscle_mass_kg, inp.max_isometric_force_N, inp.optimal_fiber_length_m,
                          inp.max_contraction_velocity)

    # fiber-type fractions: the muscle's, or those recruited at this excitation (UC16)
    f_st = recruited_slow_twitch_fraction(e, inp.slow_twitch_fraction) if recruitment else inp.slow_twitch_fraction
    # velocity constants (per muscle)
    v_max_st = v_max / SLOW_TWITCH_VMAX_RATIO
    alpha_s_st = 100.0 / v_max_st
    alpha_s_ft = 153.0 / v_max
    alpha_l = lengthening_factor * alpha_s_st
    Sm = S * m  # W/kg -> W, with the effort scaling
    # the fiber-weighted coefficients times S m, with f_FT = 1 - f_ST so that recruited fractions
    # take one product and one sum: h_AM S m = (128 f_FT + 25) S m = (153 - 128 f_ST) S m, and
    # of the shortening heat -(alpha_S_ST f_ST + alpha_S_FT f_FT) S m
    #   = -(alpha_S_FT + (alpha_S_ST - alpha_S_FT) f_ST) S m
    h_am = f_st * (-128.0 * Sm) + 153.0 * Sm
    c_shortening = f_st * ((alpha_s_ft - alpha_s_st) * Sm) - alpha_s_ft * Sm

    # (the arrays that are no longer needed are freed as we go: less memory in use at once)
    v_tilde = inp.normalized_fiber_velocity * v_max  # VCE~ (lMo/s), positive = lengthening
    # mechanical work rate of the active fiber force (no passive force): -F_CE V_CE, or only
    # where the fiber shortens (F_CE times the shortening speed max(-VCE~, 0))
    if values["include_negative_work"]:
        W_CE = a * f_l * f_v * v_tilde * -(F0 * l_mo)
    else:
        W_CE = a * f_l * f_v * np.maximum(-v_tilde, 0.0) * (F0 * l_mo)

    A = np.maximum(e, 0.5 * (e + a))  # e where e > a, (e + a)/2 where e <= a: the larger of the two
    # length dependence: fL above optimal length (H_SL; 0.4 + 0.6 fL for H_AM), 1 at or below
    f_above = select(l_m > 1.0, f_l, 1.0)

    # shortening heat -(alpha_S_ST VCE~ f_ST + alpha_S_FT VCE~ f_FT) A^2 (VCE~ <= 0) and
    # lengthening heat alpha_L VCE~ A (VCE~ > 0): each is >= 0 in its branch and <= 0 in the
    # other (A >= 0), so the heat of the branch is the larger of the two
    if values["slow_twitch_shortening_cap"]:  # the slow-twitch term stops growing beyond vmax_ST
        v_st = np.maximum(v_tilde, -v_max_st)
        h_shortening = -(alpha_s_st * f_st * v_st + alpha_s_ft * (1.0 - f_st) * v_tilde) * Sm * A * A
        del v_st
    else:
        h_shortening = c_shortening * v_tilde * A * A
    del c_shortening
    H_SL = np.maximum(h_shortening, alpha_l * Sm * v_tilde * A) * f_above
    del h_shortening, v_tilde
    # activation and maintenance heat
    H_AM = h_am * A**0.6 * (0.4 + 0.6 * f_above)
    del A, f_above, h_am

    H_AM, H_SL = apply_minimum_heat_rate((H_AM, H_SL), m, minimum)
    rest = W_CE + H_AM
    if values["non_negative"]:  # total < 0 (UM03) or <= 0 (UM10, UC16): the same rates
        H_SL = apply_non_negativity(rest, H_SL)
    B = basal_rate(inp, values["basal"], values["basal_rate_W_per_kg"])
    total = rest + H_SL + B
    return MetabolicRates(
        model=model, work=W_CE, activation_maintenance=H_AM, shortening_lengthening=H_SL,
        basal=basal_view(B, inp.shape), total=total,
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
    effort_scaling: float = AEROBIC_FACTOR,
    minimum_heat_rate_W_per_kg: float | None = None,
    basal: bool = True,
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    check: bool = True,
) -> MetabolicRates:
    """UM03: Umberger, Gerritsen & Martin (2003), as implemented in the study.

    Reference: Umberger BR, Gerritsen KGM, Martin PE (2003) A model of human muscle energy
    expenditure. Comput Methods Biomech Biomed Engin 6:99-111.

    Equations: the Umberger family (module :mod:`musclemetab.metabolics.umberger`) with
    constant fiber fractions and the lengthening coefficient
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
    %(energy_model_arguments)s

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
    %(umberger_options)s
    """
    return _umberger_family("UM03", locals(), lengthening_factor=LENGTHENING_FACTOR_2003, recruitment=False)


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
    effort_scaling: float = AEROBIC_FACTOR,
    minimum_heat_rate_W_per_kg: float | None = None,
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
    %(energy_model_arguments)s

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
    %(umberger_options)s
    """
    return _umberger_family("UM10", locals(), lengthening_factor=LENGTHENING_FACTOR_2010, recruitment=False)


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
    effort_scaling: float = AEROBIC_FACTOR,
    minimum_heat_rate_W_per_kg: float | None = None,
    basal: bool = True,
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    check: bool = True,
) -> MetabolicRates:
    """UC16: Uchida et al. (2016), the Umberger formulation with orderly recruitment.

    Reference: Uchida TK, Hicks JL, Dembia CL, Delp SL (2016) Stretching your energetic
    budget: how tendon compliance affects the metabolic cost of running. PLoS ONE
    11:e0150378.

    Equations: UM03 (module :mod:`musclemetab.metabolics.umberger`) with the fiber
    fractions replaced by excitation-dependent recruited fractions::

        u_f = 1 - cos(pi e/2),   u_s = sin(pi e/2)
        f_ST' = f_ST u_s / (f_ST u_s + f_FT u_f)      (1 where e = 0),  f_FT' = 1 - f_ST'

    used in ``h_AM = 128 f_FT' + 25`` and in the shortening heat. Lengthening coefficient
    ``alpha_L = 4 alpha_S_ST`` (UM03's value, as in the paper's Table 1). Full work rate.
    Non-negativity (``total <= 0`` -> ``H_SL := -H_AM - W_CE``) is applied always in the
    study's code (here the default). Units: W.

    Parameters
    ----------
    %(energy_model_arguments)s

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
    %(umberger_options)s
    """
    return _umberger_family("UC16", locals(), lengthening_factor=LENGTHENING_FACTOR_2003, recruitment=True)
