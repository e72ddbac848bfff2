"""LW07: Lichtwark & Wilson (2007), as implemented in the study; LW05: Lichtwark & Wilson
(2005), made definite (``docs/metabolics.md``)."""

from __future__ import annotations

import numpy as np

from ..errors import DataMismatchError, OptionError
from ._common import (
    BASAL_RATE_W_PER_KG,
    MetabolicRates,
    apply_non_negativity,
    basal_rate,
    basal_view,
    check_flag,
    model_function,
    prepare_inputs,
    select,
)

__all__ = ["lichtwark2007", "lichtwark2005", "LICHTWARK_CONSTANTS", "LICHTWARK_2005_CONSTANTS", "loess_smooth"]

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
    and fiber type are not used, except for the basal heat)::

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
    %(energy_model_arguments)s

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
    G, gamma = k["G"], k["gamma"]
    a, f_l, P = inp.activation, inp.active_force_length_multiplier, inp.force_velocity_multiplier
    v_max, l_mo, F0 = inp.max_contraction_velocity, inp.optimal_fiber_length_m, inp.max_isometric_force_N
    N0 = F0 * l_mo  # N m
    # (the arrays that are no longer needed are freed as we go: less memory in use at once)
    X = a * f_l
    v_tilde = inp.normalized_fiber_velocity * v_max  # VCE~ (lMo/s)
    W_CE = X * P * v_tilde * -(F0 * l_mo)
    # shortening / lengthening heat (1/s, times X N0)
    h_SL = select(v_tilde <= 0, v_tilde * (-1.0 / G), k["lengthening_heat_factor"] * P * v_tilde)
    del v_tilde
    H_SL = h_SL * X * N0
    del h_SL

    # maintenance heat (1/s, times N0); the branch is taken on fV, not on the velocity: for
    # fV < 1 the decay's exponent is 0 and 0.3 + 0.7 exp(0) = 1
    h_iso = gamma * v_max / G**2
    decay = k["activation_share"] + k["force_share"] * np.exp(-k["lengthening_decay"] * v_max * np.maximum(P - 1.0, 0.0))
    H_M = (k["activation_share"] * a + k["force_share"] * X) * decay * (h_iso * N0)
    del decay, X

    rest = W_CE + H_M
    if non_negative:
        H_SL = apply_non_negativity(rest, H_SL)
    B = basal_rate(inp, basal, basal_rate_W_per_kg)
    return MetabolicRates(
        model=model, work=W_CE, activation_maintenance=H_M, shortening_lengthening=H_SL,
        basal=basal_view(B, inp.shape), total=rest + H_SL + B,
    )


#: Lichtwark & Wilson (2005): G (curvature of the force-velocity relation), the labile heat's
#: two exponentials (amplitudes, rates in 1/s), the thermoelastic coefficient (-) and the
#: lengthening heat's split and decay (times the lengthening force ratio fV - 1).
LICHTWARK_2005_CONSTANTS = {
    "G": 4.0,
    "labile_amplitudes": (0.8, 0.175),
    "labile_rates_per_s": (0.72, 0.022),
    "thermoelastic": 0.014,
    "lengthening_rest": 0.3,
    "lengthening_decaying": 0.7,
    "lengthening_decay": 8.0,
    "excitation_threshold": 0.1,
}


@model_function("LW05")
def lichtwark2005(
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
    stimulation_time_s=None,
    fiber_force_rate_N_per_s=None,
    force_smoothing_span: float | None = None,
    excitation_threshold: float = 0.1,
    basal: bool = True,
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    check: bool = True,
) -> MetabolicRates:
    """LW05: Lichtwark & Wilson (2005), made definite (an additional model, not the study's).

    Reference: Lichtwark GA, Wilson AM (2005) A modified Hill muscle model that predicts
    muscle power output and efficiency during sinusoidal length changes. J Exp Biol
    208:2831-2843. The study's code holds an uncalled version with defects; the choices
    made here are listed in ``docs/metabolics.md``.

    Equations (W for one muscle; ``V = -V_CE`` the fiber *shortening* velocity (m/s),
    ``N0 = F0 lMo`` (N m), ``G = 4``, ``vmax`` in lMo/s)::

        F_CE = a fL fV F0,   W_CE = F_CE V            (work rate, counted once)
        h_M  = a vmax/G^2 N0                                        stable maintenance
        h_L  = h_M (0.8 exp(-0.72 t_stim) + 0.175 exp(-0.022 t_stim))   labile maintenance
        h_S  = a (V/lMo)/G N0                                       shortening, V > 0
        h_T  = -0.014 dF_CE/dt lMo                                  thermoelastic
        V >= 0:  h = h_M + h_L + h_S + h_T
        V <  0:  h = h_M (0.3 + 0.7 exp(-8 (fV - 1))) + h_T         (fV: lengthening force ratio)
        Edot = h + W_CE (+ basal)

    No non-negativity rule (negative work is returned, as in LW07). ``t_stim`` (s) is the
    time since the excitation last rose above 0.1, counted as BH04 counts it
    (:func:`~musclemetab.metabolics.bhargava_stimulation_time_s`; 0 while ``e <= 0.1``).
    ``dF_CE/dt`` is the central difference of ``F_CE`` along the time axis
    (``numpy.gradient``). Isometric, ``t_stim = 0``, ``a = 1``: ``Edot = 1.975 vmax/G^2 N0``.

    Components: ``activation_maintenance`` = ``h_M + h_L`` (``V >= 0``) or the lengthening
    heat (``V < 0``); ``shortening_lengthening`` = ``h_S + h_T``; ``extras``:
    ``labile`` (``h_L``) and ``thermoelastic`` (``h_T``).

    Parameters
    ----------
    %(energy_model_arguments)s

    Other parameters
    ----------------
    stimulation_time_s : array_like, optional
        ``t_stim`` (s), broadcastable to the states; replaces the count from ``time_s``.
    fiber_force_rate_N_per_s : array_like, optional
        ``dF_CE/dt`` (N/s), broadcastable to the states; replaces the difference along
        ``time_s``.
    force_smoothing_span : float or None
        Smooth ``F_CE`` along time before differentiating, by a local quadratic regression
        with tricube weights over this fraction of the samples (the authors use 0.05).
        Default None: no smoothing.
    excitation_threshold : float
        Threshold of the stimulation counter (0.1).
    """
    model = "LW05"
    check_flag(model, "basal", basal)
    inp = prepare_inputs(model, locals(), check=check)
    k = LICHTWARK_2005_CONSTANTS
    G = k["G"]
    a, f_l, f_v = inp.activation, inp.active_force_length_multiplier, inp.force_velocity_multiplier
    v_max, l_mo, F0 = inp.max_contraction_velocity, inp.optimal_fiber_length_m, inp.max_isometric_force_N
    N0 = F0 * l_mo
    # (the arrays that are no longer needed are freed as we go: less memory in use at once)
    h_M = a * (v_max / G**2 * N0)
    h_L = h_M * _lw05_labile_factor(model, inp, time_s, stimulation_time_s, excitation_threshold)

    V = inp.normalized_fiber_velocity * -(v_max * l_mo)  # shortening velocity (m/s)
    F_CE = a * f_l * f_v * F0
    W_CE = F_CE * V
    h_T = _lw05_force_rate(model, inp, F_CE, time_s, fiber_force_rate_N_per_s, force_smoothing_span) \
        * (-k["thermoelastic"] * l_mo)
    del F_CE
    h_S = a * np.maximum(V, 0.0) * (N0 / (G * l_mo))  # a (V/lMo)/G N0 where V > 0, else 0
    H_SL = h_S + h_T  # h_S = 0 where lengthening
    del h_S
    lengthening = V < 0
    del V

    h_lengthening = h_M * (k["lengthening_rest"] + k["lengthening_decaying"] * np.exp(-k["lengthening_decay"] * (f_v - 1.0)))
    H_AM = select(lengthening, h_lengthening, h_M + h_L)
    del h_lengthening, h_M
    B = basal_rate(inp, basal, basal_rate_W_per_kg)

    def full(x):  # every component has the shape of the states (a copy where it is broadcast)
        return x if np.shape(x) == inp.shape else np.broadcast_to(x, inp.shape).copy()

    return MetabolicRates(
        model=model, work=full(W_CE), activation_maintenance=full(H_AM), shortening_lengthening=full(H_SL),
        basal=basal_view(B, inp.shape), total=full(W_CE + H_AM + H_SL + B),
        extras={"labile": full(h_L * ~lengthening), "thermoelastic": full(h_T)},
    )


def _lw05_labile_factor(model, inp, time_s, stimulation_time_s, threshold):
    """``0.8 exp(-0.72 t_stim) + 0.175 exp(-0.022 t_stim)`` (-), with ``t_stim`` given or
    counted from ``time_s`` as BH04 counts it (:func:`bhargava_stimulation_time_s`)."""
    from .bhargava import mean_sampling_interval, stimulation_count

    (c1, c2), (r1, r2) = LICHTWARK_2005_CONSTANTS["labile_amplitudes"], LICHTWARK_2005_CONSTANTS["labile_rates_per_s"]

    def labile(t_stim):
        return c1 * np.exp(-r1 * t_stim) + c2 * np.exp(-r2 * t_stim)

    if stimulation_time_s is not None:
        t = np.asarray(stimulation_time_s, dtype=float)
        if np.any(np.isnan(t)) or np.any(t < 0):
            raise OptionError(f"{model}: stimulation_time_s must not be NaN or negative (s)")
        _check_broadcast(model, "stimulation_time_s", t, inp.shape)
        return labile(t)
    if time_s is None:
        raise OptionError(
            f"{model}: the labile heat needs the time since stimulation: pass time_s (s, along the last axis) "
            "or stimulation_time_s"
        )
    dt_mean = mean_sampling_interval(inp.shape, time_s)
    count = stimulation_count(np.broadcast_to(inp.excitation, inp.shape), threshold)
    # t_stim = count dt_mean takes one value per count of samples: the factor of each count,
    # computed once and looked up
    return labile(dt_mean * np.arange(inp.shape[-1] + 1))[count]


def _lw05_force_rate(model, inp, F_CE, time_s, rate, span):
    if rate is not None:
        r = np.asarray(rate, dtype=float)
        if not np.all(np.isfinite(r)):
            raise OptionError(f"{model}: fiber_force_rate_N_per_s must be finite (N/s)")
        _check_broadcast(model, "fiber_force_rate_N_per_s", r, inp.shape)
        return r
    if time_s is None:
        raise OptionError(
            f"{model}: the thermoelastic heat needs dF_CE/dt: pass time_s (s, along the last axis) or "
            "fiber_force_rate_N_per_s"
        )
    t = np.asarray(time_s, dtype=float)
    shape = inp.shape
    if not shape or t.ndim != 1 or t.size != shape[-1] or t.size < 2:
        raise DataMismatchError(
            f"{model}: time_s must be 1-D with one value per sample of the last (time) axis "
            f"({shape[-1] if shape else 0} samples, at least 2), but has shape {t.shape}"
        )
    if not np.all(np.isfinite(t)) or not np.all(np.diff(t) > 0):
        raise OptionError(f"{model}: time_s must be finite and strictly increasing (s)")
    force = np.broadcast_to(F_CE, shape)
    if span is not None:
        span = float(span)
        if not 0 < span <= 1:
            raise OptionError(f"{model}: force_smoothing_span must lie in (0, 1] (a fraction of the samples), not {span}")
        force = loess_smooth(t, force, span)
    return _time_derivative(force, t)


def _time_derivative(y, t):
    """``dy/dt`` along the last axis as ``numpy.gradient(y, t, axis=-1)`` computes it (the same
    arithmetic): second-order central differences inside (three-point weights for uneven
    steps, ``(y[i+1] - y[i-1]) / (2 dt)`` for even ones), first-order differences at both
    ends; written into one output array."""
    dt = np.diff(t)
    out = np.empty(y.shape)
    inner = out[..., 1:-1]
    if np.all(dt == dt[0]):
        np.subtract(y[..., 2:], y[..., :-2], out=inner)
        inner /= 2.0 * dt[0]
    else:
        d1, d2 = dt[:-1], dt[1:]
        np.multiply(y[..., :-2], -d2 / (d1 * (d1 + d2)), out=inner)
        inner += y[..., 1:-1] * ((d2 - d1) / (d1 * d2))
        inner += y[..., 2:] * (d1 / (d2 * (d1 + d2)))
    out[..., 0] = (y[..., 1] - y[..., 0]) / dt[0]
    out[..., -1] = (y[..., -1] - y[..., -2]) / dt[-1]
    return out


def _check_broadcast(model, name, arr, shape):
    try:
        np.broadcast_shapes(arr.shape, shape)
    except ValueError:
        raise DataMismatchError(f"{model}: {name} has shape {arr.shape}, not broadcastable to the muscle states {shape}") from None


def loess_smooth(x, y, span: float):
    """Local quadratic regression of ``y`` on ``x`` along the last axis (LOESS).

    At each sample, a quadratic in ``x`` is fitted by weighted least squares to the
    ``ceil(span n)`` nearest samples (at least 3), with tricube weights
    ``(1 - (d/d_max)^3)^3`` of the distance ``d`` relative to the farthest of them, and
    evaluated there (Cleveland 1979; the authors smoothed ``F_CE`` this way with span 0.05).
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    n = x.size
    k = min(n, max(3, int(np.ceil(span * n))))
    out = np.empty(y.shape)
    for i in range(n):
        d = np.abs(x - x[i])
        idx = np.argsort(d, kind="stable")[:k]
        d_max = d[idx].max()
        w = (1.0 - (d[idx] / d_max) ** 3) ** 3 if d_max > 0 else np.ones(k)
        X = np.vander(x[idx] - x[i], 3, increasing=True) * np.sqrt(w)[:, None]
        # the fitted value at x[i] is the intercept: one row of the pseudo-inverse
        row = np.linalg.pinv(X)[0] * np.sqrt(w)
        out[..., i] = y[..., idx] @ row
    return out
