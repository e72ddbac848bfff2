"""LW07: Lichtwark & Wilson (2007), as implemented in the study.

LW05 (Lichtwark & Wilson 2005) is not implemented: see ``docs/metabolics.md`` for why.
"""

from __future__ import annotations

import numpy as np

from ._common import (
    BASAL_RATE_W_PER_KG,
    MetabolicRates,
    apply_non_negativity,
    basal_rate,
    check_flag,
    model_function,
    prepare_inputs,
    run_kernel,
)

__all__ = ["lichtwark2007", "LICHTWARK_CONSTANTS"]

#: G (curvature of the force-velocity relation), gamma (scales the maintenance heat), the
#: split of the maintenance heat between activation (0.3) and force (0.7), the decay rate of
#: the lengthening maintenance heat (7, times vmax) and the lengthening heat factor (0.5).
LICHTWARK_CONSTANTS = {
    "G": 4.0,
    "gamma": 1.5,
    "activation_share": 0.3,
    "force_share": 0.7,
    "lengthening_decay": 7.0,
    "lengthening_heat_factor": 0.5,
}


@model_function("LW07")
def lichtwark2007(
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
    basal: bool = True,
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    check: bool = True,
) -> MetabolicRates:
    """LW07: Lichtwark & Wilson (2007), as implemented in the study.

    Reference: Lichtwark GA, Wilson AM (2007) Is Achilles tendon compliance optimised for
    maximum muscle efficiency during locomotion? J Biomech 40:1768-1775.

    Equations (W for one muscle; rates in 1/s scaled by ``N0 = F0 lMo`` (N m); muscle mass
    and fibre type are not used, except for the basal heat)::

        G = 4,  gamma = 1.5,  X = a fL,  P = fV,  VCE~ = V_CE / lMo (lMo/s)
        h_M = gamma vmax / G^2                                                if P <  1
        h_M = gamma vmax / G^2 (0.3 + 0.7 exp(-7 vmax (P - 1)))               if P >= 1
        H_M = (0.3 a + 0.7 X) h_M N0
        H_SL = -VCE~/G X N0            if V_CE <= 0
        H_SL = 0.5 P VCE~ X N0         if V_CE >  0     (= -0.5 W_CE)
        W_CE = -a fL fV F0 V_CE
        Edot = W_CE + H_M + H_SL (+ basal)

    During lengthening ``Edot = 0.5 W_CE + H_M``: half of the negative work is returned as
    energy, so the rate can be negative. No non-negativity rule in the study.

    Quirk reproduced: the maintenance branch is chosen on ``fV >= 1``, not on the sign of
    the velocity. Because ``fV(0) = 1.0021`` for the De Groote curve, isometric and very
    slow shortening (``vbar > -8.7e-4``) take the lengthening branch (about 10 % less
    maintenance heat at isometric).

    Parameters
    ----------
%(shared)s

    Other parameters
    ----------------
    non_negative : bool
        Apply the non-negativity rule (default False, the study's setting).
    """
    model = "LW07"
    for flag in ("non_negative", "basal"):
        check_flag(model, flag, locals()[flag])
    inp = prepare_inputs(model, locals(), check=check)
    k = LICHTWARK_CONSTANTS
    vmax = inp.max_contraction_velocity
    # per-muscle constants
    n0 = inp.max_isometric_force_N * inp.optimal_fiber_length_m  # N m
    h_iso = k["gamma"] * vmax / (k["G"] * k["G"]) * n0  # W per unit of (0.3 a + 0.7 X)
    decay = k["lengthening_decay"] * vmax
    inv_g = 1.0 / k["G"]
    half = k["lengthening_heat_factor"]
    share_a, share_x = k["activation_share"], k["force_share"]
    basal_w = basal_rate(inp, basal, basal_rate_W_per_kg)

    def kernel(a, vb, fl, fv, f0, lmo, vmax, n0, h_iso, decay, basal_w):
        x = a * fl
        h_rate = np.where(fv < 1.0, h_iso, h_iso * (0.3 + 0.7 * np.exp(-decay * (fv - 1.0))))
        h_m = (share_a * a + share_x * x) * h_rate
        vt = vb * vmax  # VCE~ (lMo/s)
        h_sl = np.where(vt <= 0, -inv_g * vt, half * fv * vt) * (x * n0)
        work = -(x * fv * f0) * (vt * lmo)
        if non_negative:
            h_sl = apply_non_negativity(work, h_m, h_sl, strict=False)
        return work, h_m, h_sl, basal_w, work + h_m + h_sl + basal_w

    work, h_m, h_sl, b, total = run_kernel(
        kernel,
        [
            inp.activation, inp.normalized_fiber_velocity, inp.active_force_length_multiplier,
            inp.force_velocity_multiplier, inp.max_isometric_force_N, inp.optimal_fiber_length_m, vmax, n0,
            h_iso, decay, basal_w,
        ],
        5,
    )
    return MetabolicRates(
        model=model, work=work, activation_maintenance=h_m, shortening_lengthening=h_sl, basal=b, total=total
    )
