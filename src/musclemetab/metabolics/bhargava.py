"""BH04: Bhargava, Pandy & Anderson (2004), as implemented in the study."""

from __future__ import annotations

import numpy as np

from ..errors import DataMismatchError, OptionError
from ._common import (
    BASAL_RATE_W_PER_KG,
    FIBER_FRACTIONS,
    MetabolicRates,
    apply_minimum_heat_rate,
    apply_non_negativity,
    basal_rate,
    basal_view,
    check_choice,
    check_flag,
    check_number,
    model_function,
    prepare_inputs,
    recruited_slow_twitch_fraction,
    recruitment_terms,
    select,
)

__all__ = ["bhargava2004", "bhargava_stimulation_time_s", "BHARGAVA_CONSTANTS"]

#: Bhargava et al. (2004) constants: activation and maintenance heat (W/kg) per fiber
#: type, time constant of the activation-heat decay (s), and the excitation threshold of
#: the study's stimulation-time counter.
BHARGAVA_CONSTANTS = {
    "activation_slow_W_per_kg": 40.0,
    "activation_fast_W_per_kg": 133.0,
    "maintenance_slow_W_per_kg": 74.0,
    "maintenance_fast_W_per_kg": 111.0,
    "decay_time_constant_s": 0.045,
    "decay_floor": 0.06,
    "excitation_threshold": 0.1,
}

_LENGTH_DEPENDENCE = ("study", "published")


def bhargava_stimulation_time_s(excitation, time_s, threshold: float = 0.1) -> np.ndarray:
    """Time since stimulation onset as the study's BH04 code counts it (s).

    Along the last axis, a counter increases by one at every sample where
    ``excitation > threshold`` (strict) and is reset to 0 where it is not;
    ``t_stim = counter * dt_mean`` with ``dt_mean = (t_last - t_first)/(n - 1)``. The first
    supra-threshold sample therefore has ``t_stim = dt_mean``, and samples at or below the
    threshold have ``t_stim = 0``. The counter starts at the first sample given (no memory
    of earlier, e.g. trimmed, samples).

    Parameters
    ----------
    excitation : array_like
        Excitation, time along the last axis.
    time_s : array_like
        1-D time (s), one value per sample of the last axis, increasing.
    threshold : float
        Excitation threshold (0.1).
    """
    e = np.asarray(excitation, dtype=float)
    dt_mean = mean_sampling_interval(e.shape, time_s)
    return stimulation_count(e, threshold) * dt_mean


def mean_sampling_interval(shape: tuple[int, ...], time_s):
    """``dt_mean = (t_last - t_first)/(n - 1)`` of ``time_s`` for excitation of ``shape``,
    after checking ``time_s`` (one value per sample of the last axis, increasing)."""
    t = np.asarray(time_s, dtype=float)
    if len(shape) == 0:
        raise DataMismatchError("BH04: the excitation needs a time axis (its last axis) to count stimulation time")
    if t.ndim != 1 or t.size != shape[-1]:
        raise DataMismatchError(
            f"BH04: time_s must be 1-D with one value per sample of the last (time) axis: "
            f"{shape[-1]} samples, but time_s has shape {t.shape}"
        )
    if t.size < 2:
        raise OptionError(
            "BH04: one time sample gives no sampling interval for the stimulation time; "
            "pass stimulation_time_s explicitly"
        )
    if not np.all(np.isfinite(t)) or not np.all(np.diff(t) > 0):
        raise OptionError("BH04: time_s must be finite and strictly increasing (s)")
    return (t[-1] - t[0]) / (t.size - 1)


def stimulation_count(e: np.ndarray, threshold) -> np.ndarray:
    """Consecutive samples with ``e > threshold`` up to each sample, along the last axis:
    ``n - n_off``, with ``n`` the 1-based sample number and ``n_off`` that of the last sample
    at or below the threshold so far (0 if none)."""
    n = np.arange(1, e.shape[-1] + 1, dtype=np.min_scalar_type(e.shape[-1]))  # the smallest type that holds n
    n_off = np.maximum.accumulate(n * (e <= threshold), axis=-1)
    return n - n_off


@model_function("BH04")
def bhargava2004(
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
    activation_heat_decay: bool = True,
    excitation_threshold: float = 0.1,
    maintenance_length_dependence: str = "study",
    fiber_fractions: str = "constant",
    non_negative: bool = True,
    minimum_heat_rate_W_per_kg: float | None = None,
    basal: bool = True,
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    check: bool = True,
) -> MetabolicRates:
    """BH04: Bhargava, Pandy & Anderson (2004), as implemented in the study.

    Reference: Bhargava LJ, Pandy MG, Anderson FC (2004) A phenomenological model for
    estimating metabolic energy consumption in muscle contraction. J Biomech 37:81-88.

    Equations (W for one muscle; ``V_CE = vbar vmax lMo`` in m/s, negative = shortening;
    constant fiber fractions ``f_ST``, ``f_FT = 1 - f_ST``)::

        u_f = 1 - cos(pi e/2),  u_s = sin(pi e/2)
        H_A  = phi m (133 f_FT u_f + 40 f_ST u_s)
        phi  = 0.06 + exp(-t_stim e / 0.045)   where t_stim > 0,  0 elsewhere
        H_M  = g(l~M) m (111 f_FT u_f + 74 f_ST u_s)
        F_iso = a fL F0,   F_M = a fL fV F0 + F_pe     (passive force included)
        H_SL = -(0.16 F_iso + 0.18 F_M) V_CE           if V_CE <= 0
        H_SL = -0.157 F_M V_CE                          if V_CE >  0
        W_CE = -a fL fV F0 V_CE
        Edot = W_CE + H_A + H_M + H_SL (+ basal)

    Non-negativity (study setting on): where ``Edot <= 0``, ``H_SL := -H_A - H_M - W_CE``.
    ``activation_maintenance = H_A + H_M``; ``extras`` gives ``activation`` and
    ``maintenance`` separately.

    Quirks of the study's implementation, reproduced by default:

    * the stimulation time ``t_stim`` is the count of consecutive samples with
      ``e > 0.1`` times the mean sampling interval (:func:`bhargava_stimulation_time_s`),
      so there is **no activation heat while e <= 0.1** and the count starts at the first
      sample given; it needs ``time_s`` (or pass ``stimulation_time_s``);
    * the maintenance length factor is ``g(l~M) = l~M`` (unbounded): the code builds
      Bhargava's piecewise factor and then overwrites it. ``maintenance_length_dependence=
      "published"`` uses the piecewise factor (0.5 for l~M <= 0.5, l~M to 1,
      ``-2 l~M + 3`` to 1.5, 0 beyond);
    * the shortening-heat coefficient is force dependent (``0.16 F_iso + 0.18 F_M``).

    OpenSim's ``Bhargava2004MuscleMetabolicsProbe`` has no activation-heat decay
    (``phi = 1``, no threshold): ``activation_heat_decay=False`` reproduces that.

    Parameters
    ----------
    %(energy_model_arguments)s

    Other parameters
    ----------------
    stimulation_time_s : array_like, optional
        Time since stimulation onset (s), broadcastable to the states; replaces the count
        from ``time_s``. ``phi = 0`` where it is 0; ``inf`` gives the steady-state limit
        ``phi = 0.06``.
    activation_heat_decay : bool
        False: ``phi = 1`` everywhere (no decay, no threshold; OpenSim's formulation).
    excitation_threshold : float
        Threshold of the stimulation counter (0.1).
    maintenance_length_dependence : {"study", "published"}
        ``g(l~M) = l~M`` (study's code) or Bhargava's piecewise-linear factor.
    fiber_fractions : {"constant", "recruited"}
        ``f_ST`` and ``f_FT`` in ``H_A`` and ``H_M``: the muscle's (default, the study's
        setting) or Uchida et al. (2016)'s recruited fractions ``f_ST'``, ``f_FT'`` at the
        excitation of each sample (the study's ``option = 2``; see UC16).
    non_negative : bool
        Apply the non-negativity rule (default True, the study's setting).
    minimum_heat_rate_W_per_kg : float or None
        Where ``H_A + H_M + H_SL`` falls below this many W per kg of muscle mass, raise it to
        that value (``H_A`` takes it, ``H_M = H_SL = 0``) before the non-negativity rule, as
        OpenSim's ``enforce_minimum_heat_rate_per_muscle`` (1 W/kg). Default None (not
        applied, the study's setting).
    """
    model = "BH04"
    for flag in ("activation_heat_decay", "non_negative", "basal"):
        check_flag(model, flag, locals()[flag])
    check_choice(model, "maintenance_length_dependence", maintenance_length_dependence, _LENGTH_DEPENDENCE)
    check_choice(model, "fiber_fractions", fiber_fractions, FIBER_FRACTIONS)
    minimum = check_number(model, "minimum_heat_rate_W_per_kg", minimum_heat_rate_W_per_kg, allow_none=True)
    inp = prepare_inputs(model, locals(), check=check)
    k = BHARGAVA_CONSTANTS
    e, a = inp.excitation, inp.activation
    l_m, f_l, f_v = inp.normalized_fiber_length, inp.active_force_length_multiplier, inp.force_velocity_multiplier
    m, F0 = inp.muscle_mass_kg, inp.max_isometric_force_N
    if fiber_fractions == "recruited":
        f_st = recruited_slow_twitch_fraction(e, inp.slow_twitch_fraction)
    else:
        f_st = inp.slow_twitch_fraction
    f_ft = 1.0 - f_st

    # work and shortening heat; the arrays that are no longer needed are freed as we go (less
    # memory in use at once: faster for long arrays)
    minus_V_CE = inp.normalized_fiber_velocity * -(inp.max_contraction_velocity * inp.optimal_fiber_length_m)  # m/s
    F_iso = a * f_l * F0
    F_CE = F_iso * f_v
    W_CE = F_CE * minus_V_CE
    F_M = F_CE + inp.passive_fiber_force_N
    del F_CE
    # H_SL = -alpha V_CE, alpha = 0.16 F_iso + 0.18 F_M (V_CE <= 0) or 0.157 F_M (V_CE > 0)
    H_SL = select(minus_V_CE >= 0, 0.16 * F_iso + 0.18 * F_M, 0.157 * F_M) * minus_V_CE
    del F_iso, F_M, minus_V_CE

    # activation and maintenance heats
    u_s, u_f = recruitment_terms(e)
    phi = _activation_heat_decay(e, inp.shape, time_s, stimulation_time_s, excitation_threshold) \
        if activation_heat_decay else 1.0
    H_A = phi * (k["activation_fast_W_per_kg"] * m * f_ft * u_f + k["activation_slow_W_per_kg"] * m * f_st * u_s)
    del phi
    g = np.interp(l_m, [0.5, 1.0, 1.5], [0.5, 1.0, 0.0]) if maintenance_length_dependence == "published" else l_m
    H_M = g * (k["maintenance_fast_W_per_kg"] * m * f_ft * u_f + k["maintenance_slow_W_per_kg"] * m * f_st * u_s)
    del u_s, u_f

    H_A, H_M, H_SL = apply_minimum_heat_rate((H_A, H_M, H_SL), m, minimum)
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


def _activation_heat_decay(e, shape, time_s, stimulation_time_s, threshold):
    """``phi = 0.06 + exp(-t_stim e / 0.045)`` where ``t_stim > 0``, else 0; ``t_stim`` given,
    or counted from ``time_s`` (:func:`bhargava_stimulation_time_s`)."""
    k = BHARGAVA_CONSTANTS
    if stimulation_time_s is not None:
        t_stim = np.asarray(stimulation_time_s, dtype=float)
        if np.any(np.isnan(t_stim)) or np.any(t_stim < 0):
            raise OptionError("BH04: stimulation_time_s must not be NaN or negative (s; inf is the steady-state limit)")
        try:
            np.broadcast_shapes(t_stim.shape, shape)
        except ValueError:
            raise DataMismatchError(
                f"BH04: stimulation_time_s has shape {t_stim.shape}, not broadcastable to the muscle states {shape}"
            ) from None
    elif time_s is not None:  # t_stim = count dt_mean (bhargava_stimulation_time_s)
        dt_mean = mean_sampling_interval(shape, time_s)
        count = stimulation_count(np.broadcast_to(e, shape), threshold)
        decay = np.exp(count * e * (-dt_mean / k["decay_time_constant_s"]))
        return (k["decay_floor"] + decay) * (count > 0)  # 0 where t_stim = 0
    else:
        raise OptionError(
            "BH04: the activation-heat decay needs time: pass time_s (s, along the last axis) or "
            "stimulation_time_s, or set activation_heat_decay=False"
        )
    if np.isinf(t_stim).any():
        with np.errstate(invalid="ignore"):
            x = np.where(e == 0, 0.0, t_stim * e)  # inf * 0: no excitation, no activation heat either way
        decay = np.exp(-x / k["decay_time_constant_s"])
    else:
        decay = np.exp(t_stim * e * (-1.0 / k["decay_time_constant_s"]))
    return (k["decay_floor"] + decay) * (t_stim > 0)  # 0 where t_stim = 0
