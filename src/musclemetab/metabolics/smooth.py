"""Smooth (twice differentiable) versions of every metabolic model, written once for NumPy
and CasADi.

Each exact model (:mod:`musclemetab.metabolics`) switches between branches (shortening or
lengthening, below or above optimal length, excitation above or below activation, the
non-negativity and minimum-heat rules, caps). For gradient-based optimisation every switch
is replaced by a smooth one with **one** smoothing parameter ``s`` (dimensionless):

* ``step(x) = (1 + tanh(x/s))/2`` for a branch chosen on the sign of a normalised quantity
  ``x`` (velocity ``vbar``, ``l~M - 1``, ``e - a``, ``fV - 1``, a power over ``P0``);
* ``pos(x) = (x + sqrt(x^2 + s^2))/2`` for ``max(x, 0)`` (the non-negativity rule sets the
  total to ``max(total, 0)``; the cap ``max(VCE~, -vmax_ST)``); its error is at most ``s/2``;
* ``|A| -> sqrt(A^2 + s^2)`` under ``A^0.6`` (whose slope is infinite at 0), and
  ``a^2 -> a^2 + s^2`` in HO06's ``18.2/(a^2 nu_max)``.

Powers are normalised by ``P0 = F0 lMo vmax`` (W), the muscle's maximal power scale. As
``s -> 0`` every smooth model converges to its exact model (except exactly on a branch
boundary, where ``step`` gives the mean of the two branches). The functions take the
exact models' twelve arguments as NumPy arrays or CasADi expressions (the math namespace is
chosen from the arguments, as for the muscle curves, :mod:`musclemetab.muscle.curves`) and
return a dict of the components (W): ``work``, ``activation_maintenance``,
``shortening_lengthening``, ``basal``, ``total``.

Terms that need time are data here: BH04's and LW05's stimulation time
(``stimulation_time_s``, default: the steady-state limit ``inf``) and LW05's ``dF_CE/dt``
(``fiber_force_rate_N_per_s``, default 0). The default smoothing and the differences from
the exact models are in ``docs/metabolics.md``.
"""

from __future__ import annotations

import math

from ..errors import OptionError
from ..messages import name_list
from ..muscle.curves import math_for
from ._common import BASAL_RATE_W_PER_KG, STATE_ARGUMENTS
from .bhargava import BHARGAVA_CONSTANTS
from .houdijk import HOUDIJK_CONSTANTS
from .lichtwark import LICHTWARK_2005_CONSTANTS, LICHTWARK_CONSTANTS
from .margaria import MARGARIA_CONSTANTS
from .umberger import AEROBIC_FACTOR, LENGTHENING_FACTOR_2003, LENGTHENING_FACTOR_2010, SLOW_TWITCH_VMAX_RATIO

__all__ = ["SMOOTHING", "SMOOTH_MODELS", "WORK_AND_HEAT", "smooth_rates"]

#: Default smoothing parameter ``s`` (dimensionless).
SMOOTHING = 1e-4
#: ``non_negative=WORK_AND_HEAT``: the non-negativity rule of UM03, BH04, HO06 and UC16 applied
#: to the work plus the shortening/lengthening heat instead of the total (the energy goal's form,
#: ``docs/energy_objective.md``): ``Edot = H_AM + max(W + H_SL, 0)``.
WORK_AND_HEAT = "work-and-heat"


class _Smooth:
    """The smooth switches for one smoothing parameter and math namespace."""

    def __init__(self, s: float, m):
        self.s, self.m = s, m

    def step(self, x):
        return 0.5 * (1.0 + self.m.tanh(x / self.s))

    def select(self, x, positive, other):
        """``positive`` where ``x > 0``, ``other`` where ``x < 0``, blended smoothly."""
        return other + self.step(x) * (positive - other)

    def pos(self, x):
        return 0.5 * (x + self.m.sqrt(x * x + self.s * self.s))

    def abs(self, x):
        return self.m.sqrt(x * x + self.s * self.s)


def _activation_and_curves(x):
    """``a``, ``vbar``, ``fL``, ``fV`` of the arguments ``x``."""
    return (x["activation"], x["normalized_fiber_velocity"], x["active_force_length_multiplier"],
            x["force_velocity_multiplier"])


def _recruitment(m, e):
    t = m.tan(0.25 * math.pi * e)
    u_s = (2.0 * t) / (1.0 + t * t)
    return t, u_s, t * u_s


def _umberger(k, x, *, lengthening_factor, include_negative_work, recruitment, non_negative, cap,
              effort_scaling, minimum_heat_rate_W_per_kg):
    m = k.m
    e, a, l_m, vbar, f_l, f_v = (x[n] for n in STATE_ARGUMENTS[:6])
    F0, l_mo, v_max, mass, f_st = x["F0"], x["lMo"], x["vmax"], x["mass"], x["fst"]
    if recruitment:
        t, _, _ = _recruitment(m, e)
        f_st = f_st / (f_st + (1.0 - f_st) * t)
    f_ft = 1.0 - f_st
    v_max_st = v_max / SLOW_TWITCH_VMAX_RATIO
    alpha_s_st, alpha_s_ft = 100.0 / v_max_st, 153.0 / v_max
    alpha_l = lengthening_factor * alpha_s_st
    S = effort_scaling
    v_tilde = vbar * v_max
    A = k.select(e - a, e, 0.5 * (e + a))
    above = k.step(l_m - 1.0)
    h_am = (128.0 * f_ft + 25.0) * k.abs(A) ** 0.6 * S * mass
    H_AM = h_am * (1.0 + above * (0.4 + 0.6 * f_l - 1.0))
    v_st = v_tilde
    if cap:  # max(VCE~, -vmax_ST) = -vmax_ST + vmax max(vbar + 1/2.5, 0)
        v_st = -v_max_st + v_max * k.pos(vbar + 1.0 / SLOW_TWITCH_VMAX_RATIO)
    h_short = -(alpha_s_st * v_st * f_st + alpha_s_ft * v_tilde * f_ft) * A**2
    h_long = alpha_l * v_tilde * A
    H_SL = k.select(-vbar, h_short, h_long) * S * mass * (1.0 + above * (f_l - 1.0))
    force = a * f_l * f_v * F0
    W = -force * (v_tilde * l_mo)
    if not include_negative_work:
        W = W * k.step(-vbar)
    if non_negative == WORK_AND_HEAT:
        # max(W + H_SL, 0): shortening, both terms are >= 0; lengthening, W + H_SL = VCE~ c with
        # c = alpha_L A f_SL - F_CE lMo of either sign, so max(W + H_SL, 0) = VCE~ max(c, 0), c
        # smoothed in units of F0 lMo
        f_sl = S * mass * (1.0 + above * (f_l - 1.0))
        if include_negative_work:
            N0 = F0 * l_mo
            net_long = v_tilde * N0 * k.pos((alpha_l * A * f_sl - force * l_mo) / N0)
        else:
            net_long = h_long * f_sl
        return _close(k, x, W, [H_AM, H_SL], non_negative, minimum_heat_rate_W_per_kg,
                      work_and_heat=k.select(-vbar, W + h_short * f_sl, net_long))
    return _close(k, x, W, [H_AM, H_SL], non_negative, minimum_heat_rate_W_per_kg)


def _close(k, x, W, heats, non_negative, minimum, work_and_heat=None):
    """Minimum heat rate, non-negativity and basal heat, smoothly; returns the components.

    ``non_negative``: False, True (the total raised to 0) or :data:`WORK_AND_HEAT` (the work
    plus the shortening/lengthening heat raised to 0: ``work_and_heat``, their smooth
    ``max(W + H_SL, 0)``, replaces ``W + H_SL``)."""
    P0 = x["F0"] * x["lMo"] * x["vmax"]
    if non_negative == WORK_AND_HEAT:
        if minimum:
            raise OptionError("the non-negativity of the work and shortening/lengthening heat does not take "
                              "minimum_heat_rate_W_per_kg; give one of the two")
        H_AM = heats[0] if len(heats) == 2 else heats[0] + heats[1]
        B = x["basal_W"]
        return {"work": W, "activation_maintenance": H_AM, "shortening_lengthening": work_and_heat - W, "basal": B,
                "total": H_AM + work_and_heat + B}
    if minimum:
        floor = minimum * x["mass"]
        heat = sum(heats)
        low = k.step((floor - heat) / P0)
        heats = [heats[0] + low * (floor - heats[0])] + [h * (1.0 - low) for h in heats[1:]]
    heat = sum(heats)
    H_AM, H_SL = (heats[0], heats[1]) if len(heats) == 2 else (heats[0] + heats[1], heats[2])
    if non_negative:  # total := max(total, 0), taken up by H_SL
        total = W + H_AM + H_SL
        H_SL = P0 * k.pos(total / P0) - W - H_AM
    B = x["basal_W"]
    return {"work": W, "activation_maintenance": H_AM, "shortening_lengthening": H_SL, "basal": B,
            "total": W + H_AM + H_SL + B}


def _bhargava(k, x, *, non_negative, activation_heat_decay, stimulation_time_s, minimum_heat_rate_W_per_kg,
              excitation_threshold=0.1):
    m = k.m
    c = BHARGAVA_CONSTANTS
    e, a, l_m, vbar, f_l, f_v, fpe = (x[n] for n in STATE_ARGUMENTS)
    mass, f_st = x["mass"], x["fst"]
    f_ft = 1.0 - f_st
    t, u_s, u_f = _recruitment(m, e)
    if activation_heat_decay:
        t_stim = stimulation_time_s
        decay = 0.0 if t_stim == math.inf else m.exp(-t_stim * e / c["decay_time_constant_s"])
        phi = (c["decay_floor"] + decay) * k.step(e - excitation_threshold)
    else:
        phi = 1.0
    H_A = phi * mass * (c["activation_fast_W_per_kg"] * f_ft * u_f + c["activation_slow_W_per_kg"] * f_st * u_s)
    H_M = l_m * mass * (c["maintenance_fast_W_per_kg"] * f_ft * u_f + c["maintenance_slow_W_per_kg"] * f_st * u_s)
    V = vbar * x["vmax"] * x["lMo"]
    F_iso = a * f_l * x["F0"]
    F_CE = F_iso * f_v
    F_M = F_CE + fpe
    H_SL = -k.select(-vbar, 0.16 * F_iso + 0.18 * F_M, 0.157 * F_M) * V
    # W + H_SL = -(F_CE + alpha) V: >= 0 shortening, <= 0 lengthening, so max(W + H_SL, 0) is its
    # shortening branch
    net = k.step(-vbar) * -(F_CE + 0.16 * F_iso + 0.18 * F_M) * V if non_negative == WORK_AND_HEAT else None
    return _close(k, x, -F_CE * V, [H_A, H_M, H_SL], non_negative, minimum_heat_rate_W_per_kg, work_and_heat=net)


def _houdijk(k, x, *, non_negative):
    m = k.m
    c = HOUDIJK_CONSTANTS
    a, vbar, f_l, f_v = _activation_and_curves(x)
    mass, f_st, F0 = x["mass"], x["fst"], x["F0"]
    f_ft = 1.0 - f_st
    h_A = c["activation_fast_W_per_kg"] * f_ft + c["activation_slow_W_per_kg"] * f_st
    h_M = c["maintenance_fast_W_per_kg"] * f_ft + c["maintenance_slow_W_per_kg"] * f_st
    k3 = c["k3_fast"] * f_ft + c["k3_slow"] * f_st
    k4 = c["k4_fast"] * f_ft + c["k4_slow"] * f_st
    a_tilde = (c["shortening_fast"] * f_ft + c["shortening_slow"] * f_st) * F0
    nu_max = k3 + k4 * a
    nu_rel = a * a
    ratio = (1.0 - m.exp(-0.25 - 18.2 / ((nu_rel + k.s**2) * nu_max))) / (1.0 - m.exp(-0.25 - 18.2 / nu_max))
    H_A = mass * h_A * nu_rel * ratio
    H_M = mass * (h_A + h_M) * a * (f_l - h_A / (h_A + h_M))
    V = vbar * x["vmax"] * x["lMo"]
    H_SL = -a_tilde * a * f_l * V * k.step(-vbar)
    W = -(a * f_l * f_v * F0) * V
    # W + H_SL: >= 0 shortening, W <= 0 lengthening, so max(W + H_SL, 0) is its shortening branch
    net = k.step(-vbar) * (W - a_tilde * a * f_l * V) if non_negative == WORK_AND_HEAT else None
    return _close(k, x, W, [H_A + H_M, H_SL], non_negative, None, work_and_heat=net)


def _lichtwark2007(k, x, *, non_negative):
    m = k.m
    c = LICHTWARK_CONSTANTS
    a, vbar, f_l, P = _activation_and_curves(x)
    v_max, l_mo, F0 = x["vmax"], x["lMo"], x["F0"]
    N0, X, v_tilde = F0 * l_mo, a * f_l, vbar * v_max
    h_iso = c["gamma"] * v_max / c["G"] ** 2
    decay = c["activation_share"] + c["force_share"] * m.exp(-c["lengthening_decay"] * v_max * (P - 1.0))
    h_M = k.select(P - 1.0, h_iso * decay, h_iso)
    H_M = (c["activation_share"] * a + c["force_share"] * X) * h_M * N0
    H_SL = k.select(-vbar, -v_tilde / c["G"], c["lengthening_heat_factor"] * P * v_tilde) * X * N0
    return _close(k, x, -(X * P * F0) * (v_tilde * l_mo), [H_M, H_SL], non_negative, None)


def _lichtwark2005(k, x, *, stimulation_time_s, fiber_force_rate_N_per_s):
    m = k.m
    c = LICHTWARK_2005_CONSTANTS
    a, vbar, f_l, f_v = _activation_and_curves(x)
    v_max, l_mo, F0 = x["vmax"], x["lMo"], x["F0"]
    G, N0 = c["G"], F0 * l_mo
    V = -vbar * v_max * l_mo
    F_CE = a * f_l * f_v * F0
    h_M = a * v_max / G**2 * N0
    t_stim = stimulation_time_s
    (c1, c2), (r1, r2) = c["labile_amplitudes"], c["labile_rates_per_s"]
    h_L = 0.0 if t_stim == math.inf else h_M * (c1 * math.exp(-r1 * t_stim) + c2 * math.exp(-r2 * t_stim))
    h_S = a * v_max * k.pos(-vbar) / G * N0  # a (V/lMo)/G N0 for V > 0
    h_T = -c["thermoelastic"] * fiber_force_rate_N_per_s * l_mo
    h_len = h_M * (c["lengthening_rest"] + c["lengthening_decaying"] * m.exp(-c["lengthening_decay"] * (f_v - 1.0)))
    H_AM = k.select(-vbar, h_M + h_L, h_len)
    H_SL = k.step(-vbar) * h_S + h_T
    return _close(k, x, F_CE * V, [H_AM, H_SL], False, None)


def _margaria(k, x):
    c = MARGARIA_CONSTANTS
    V = x["normalized_fiber_velocity"] * x["vmax"] * x["lMo"]
    W = -(x["activation"] * x["active_force_length_multiplier"] * x["force_velocity_multiplier"] * x["F0"]) * V
    w_pos = W * k.step(-x["normalized_fiber_velocity"])  # max(W, 0): W = -F_CE V has the sign of -V
    Edot = w_pos / c["positive_work_efficiency"] + (W - w_pos) / c["negative_work_efficiency"]
    B = x["basal_W"]
    return {"work": W, "activation_maintenance": 0.0 * W, "shortening_lengthening": Edot - W, "basal": B,
            "total": Edot + B}


#: Smooth model by name, with its options and the exact model's defaults.
SMOOTH_MODELS = {
    "UM03": (_umberger, dict(lengthening_factor=LENGTHENING_FACTOR_2003, include_negative_work=True,
                             recruitment=False, non_negative=True, cap=False)),
    "BH04": (_bhargava, dict(non_negative=True, activation_heat_decay=True, stimulation_time_s=math.inf)),
    "HO06": (_houdijk, dict(non_negative=True)),
    "LW07": (_lichtwark2007, dict(non_negative=False)),
    "UM10": (_umberger, dict(lengthening_factor=LENGTHENING_FACTOR_2010, include_negative_work=False,
                             recruitment=False, non_negative=False, cap=False)),
    "UC16": (_umberger, dict(lengthening_factor=LENGTHENING_FACTOR_2003, include_negative_work=True,
                             recruitment=True, non_negative=True, cap=False)),
    "LW05": (_lichtwark2005, dict(stimulation_time_s=math.inf, fiber_force_rate_N_per_s=0.0)),
    "MA68": (_margaria, {}),
}
_UMBERGER_OPTIONS = dict(effort_scaling=AEROBIC_FACTOR, minimum_heat_rate_W_per_kg=None)


def smooth_rates(
    model: str,
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
    smoothing: float = SMOOTHING,
    basal: bool = True,
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    **options,
) -> dict:
    """The smooth version of ``model``: its components (W) as NumPy arrays or CasADi
    expressions, for states and parameters of one common (broadcastable) shape.

    ``options`` are those of the exact model that the smooth one has (``non_negative``, which
    also takes :data:`WORK_AND_HEAT` for UM03, UM10, UC16, BH04 and HO06: the rule on the work
    plus the shortening/lengthening heat, ``H_AM + max(W + H_SL, 0)``, without a minimum heat rate;
    Umberger family: ``include_negative_work``, ``effort_scaling``,
    ``minimum_heat_rate_W_per_kg``, ``slow_twitch_shortening_cap`` (as ``cap``); BH04:
    ``activation_heat_decay``, ``stimulation_time_s`` (a number, s), ``minimum_heat_rate_W_per_kg``;
    LW05: ``stimulation_time_s``, ``fiber_force_rate_N_per_s``), with the exact model's
    defaults. Parameters broadcast as NumPy (or CasADi) does: give per-muscle parameters as
    column vectors for ``(muscles, time)`` states.
    """
    key = str(model).strip().upper()
    if key not in SMOOTH_MODELS:
        raise OptionError(f"unknown metabolic model '{model}'; known models: {', '.join(SMOOTH_MODELS)}")
    if not (isinstance(smoothing, (int, float)) and smoothing > 0 and math.isfinite(smoothing)):
        raise OptionError(f"{key}: smoothing must be a positive number, not {smoothing!r}")
    func, defaults = SMOOTH_MODELS[key]
    opts = dict(defaults)
    if func is _umberger or func is _bhargava:
        opts.update(_UMBERGER_OPTIONS if func is _umberger else {"minimum_heat_rate_W_per_kg": None})
    if "slow_twitch_shortening_cap" in options:
        options["cap"] = options.pop("slow_twitch_shortening_cap")
    allowed = [k for k in opts if k not in ("lengthening_factor", "recruitment")]
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise OptionError(f"{key}: the smooth model has no option {name_list(unknown)}; options: {', '.join(allowed)}")
    opts.update(options)
    if "non_negative" in opts and not (isinstance(opts["non_negative"], bool) or opts["non_negative"] == WORK_AND_HEAT):
        raise OptionError(f"{key}: non_negative must be True, False or '{WORK_AND_HEAT}', not {opts['non_negative']!r}")
    if opts.get("non_negative") == WORK_AND_HEAT and func is _lichtwark2007:
        raise OptionError(f"{key}: non_negative='{WORK_AND_HEAT}' needs a model with a shortening/lengthening heat "
                          "that the work can cancel (UM03, UM10, UC16, BH04, HO06)")
    states = (excitation, activation, normalized_fiber_length, normalized_fiber_velocity,
              active_force_length_multiplier, force_velocity_multiplier, passive_fiber_force_N)
    params = (max_isometric_force_N, optimal_fiber_length_m, max_contraction_velocity, muscle_mass_kg,
              slow_twitch_fraction)
    m = math_for(*states, *params)
    if m is math_for():  # NumPy
        import numpy as np

        states = tuple(np.asarray(v, dtype=float) for v in states)
        params = tuple(np.asarray(v, dtype=float) for v in params)
    x = dict(zip(STATE_ARGUMENTS, states))
    x.update(zip(("F0", "lMo", "vmax", "mass", "fst"), params))
    x["basal_W"] = (basal_rate_W_per_kg * x["mass"]) if basal else 0.0 * x["mass"]
    return func(_Smooth(float(smoothing), m), x, **opts)
