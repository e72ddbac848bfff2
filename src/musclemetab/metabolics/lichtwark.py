"""LW07: Lichtwark & Wilson (2007), as implemented in the study.

LW05 (Lichtwark & Wilson 2005) is not implemented: see ``docs/metabolics.md`` for why.
"""

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
    model_function,
    non_negativity_into,
    prepare_inputs,
    select_into,
    total_into,
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
    inp = prepare_inputs(model, locals(), check=check, defer_large=True)
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

    neg_decay = -decay
    neg_lmo = -inp.optimal_fiber_length_m
    c = SimpleNamespace(
        share_a=np.array(share_a),
        share_x=np.array(share_x),
        neg_inv_g=np.array(-inv_g),
        half=np.array(half),
        rest=np.array(0.3),
        decaying=np.array(0.7),
    )

    def kernel(out, s, p, tmp, i):
        work, h_m, h_sl, total = out
        a, vb, fl, fv = s
        f0, neg_lmo, vmax, n0, h_iso, neg_decay, basal_w = p
        x, t1, t2, vt, m1, m2 = tmp
        np.multiply(a, fl, x)
        # h_iso where fV < 1, else h_iso (0.3 + 0.7 exp(-7 vmax (fV - 1))) (h_iso 1.0 = h_iso exactly)
        np.subtract(fv, ONE, t1)
        np.multiply(t1, neg_decay, t1)
        np.exp(t1, t1)
        np.multiply(t1, c.decaying, t1)
        np.add(t1, c.rest, t1)
        select_into(t1, as_mask(np.less(fv, ONE, m1)), ONE, t2)
        np.multiply(t1, h_iso, t1)
        np.multiply(a, c.share_a, h_m)
        np.multiply(x, c.share_x, t2)
        np.add(h_m, t2, h_m)
        np.multiply(h_m, t1, h_m)
        np.multiply(vb, vmax, vt)  # VCE~ (lMo/s)
        np.multiply(fv, c.half, h_sl)
        np.multiply(h_sl, vt, h_sl)
        np.multiply(vt, c.neg_inv_g, t1)
        select_into(h_sl, as_mask(np.less_equal(vt, ZERO, m1)), t1, t2)
        np.multiply(x, n0, t1)
        np.multiply(h_sl, t1, h_sl)
        np.multiply(x, fv, work)
        np.multiply(work, f0, work)
        np.multiply(vt, neg_lmo, t1)
        np.multiply(work, t1, work)
        if non_negative:
            non_negativity_into(work, h_m, h_sl, t1, total, m2, t2, strict=False)
        else:
            np.add(work, h_m, t1)
        total_into(total, t1, h_sl, basal_w)

    work, h_m, h_sl, total = evaluate_chunked(
        kernel,
        inp.shape,
        [
            inp.activation, inp.normalized_fiber_velocity, inp.active_force_length_multiplier,
            inp.force_velocity_multiplier,
        ],
        [inp.max_isometric_force_N, neg_lmo, vmax, n0, h_iso, neg_decay, basal_w],
        4,
        scratch="ddddqq",
        inputs=inp,
    )
    return MetabolicRates(
        model=model, work=work, activation_maintenance=h_m, shortening_lengthening=h_sl,
        basal=basal_view(basal_w, inp.shape), total=total,
    )
