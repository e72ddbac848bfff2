"""BH04: Bhargava, Pandy & Anderson (2004), as implemented in the study."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from ..errors import DataMismatchError, OptionError
from . import _common
from ._common import (
    BASAL_RATE_W_PER_KG,
    ZERO,
    ChunkPlan,
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
    recruitment_terms_into,
    run_chunks,
    select_into,
    total_into,
)

__all__ = ["bhargava2004", "bhargava_stimulation_time_s", "BHARGAVA_CONSTANTS"]

#: Bhargava et al. (2004) constants: activation and maintenance heat (W/kg) per fibre
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

#: Shortening-heat coefficients of the kernel as 0-d arrays (cheaper ufunc operands).
_C = SimpleNamespace(short_iso=np.array(0.16), short_total=np.array(0.18), lengthening=np.array(0.157))


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
    dt_mean = _mean_sampling_interval(e.shape, time_s)
    if e.size < _common.PARALLEL_MIN_SIZE:
        return _stimulation_count(e, threshold) * dt_mean
    return _stimulation_time(e, threshold, dt_mean)


def _mean_sampling_interval(shape: tuple[int, ...], time_s):
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


def _stimulation_count(e: np.ndarray, threshold) -> np.ndarray:
    """Consecutive samples with ``e > threshold`` up to each sample, along the last axis."""
    on = e > threshold
    count = np.cumsum(on, axis=-1)
    reset = np.maximum.accumulate(np.where(on, 0, count), axis=-1)
    return count - reset


class _StimulationCounter:
    """The stimulation count of :func:`_stimulation_count`, chunk by chunk of a
    :class:`~musclemetab.metabolics._common.ChunkPlan` whose rows run along the last axis.

    Pieces of a row are counted independently: a cumulative sum of 1 per sample above the
    threshold and, per sample at or below it, minus the run before it. The count carried
    into a piece from the pieces before it in the row comes from a first pass over the
    excitation (each piece's first sample at or below the threshold and its trailing run)
    and is added to the piece's leading run. The counts are integers, so the result equals
    the direct evaluation exactly, however the rows are cut.
    """

    def __init__(self, e2: np.ndarray, threshold, plan: ChunkPlan):
        self.e2, self.threshold, self.plan = e2, threshold, plan
        self.carry = None
        if not plan.pieces or plan.pieces == 1:
            return
        first_off = np.empty(plan.n_chunks, dtype=np.int64)  # first sample at or below the threshold
        trailing = np.empty(plan.n_chunks, dtype=np.int64)  # run of samples above it at the end

        def scan(i, arrays):
            r, _, t0, t1 = plan.bounds(i)
            on = arrays[0][: t1 - t0]
            np.greater(e2[r, t0:t1], threshold, on)
            k = int(on.argmin())
            if on[k]:  # all above the threshold
                first_off[i] = trailing[i] = t1 - t0
            else:
                first_off[i] = k
                trailing[i] = int(on[::-1].argmin())

        run_chunks(plan.n_chunks, scan, scratch="?", scratch_size=plan.chunk_size)
        self.carry = carry = np.zeros(plan.n_chunks, dtype=np.int64)
        for r in range(plan.n_rows):
            c = 0
            for j in range(plan.pieces):
                i = r * plan.pieces + j
                carry[i] = c
                _, _, t0, t1 = plan.bounds(i)
                c = c + (t1 - t0) if first_off[i] == t1 - t0 else int(trailing[i])

    def count_into(self, i: int, e: np.ndarray, count: np.ndarray, on: np.ndarray) -> None:
        """The count of chunk ``i`` (excitation ``e``) into the int64 array ``count``; ``on``
        (bool) receives ``e > threshold``."""
        np.greater(e, self.threshold, on)
        if not self.plan.pieces:  # blocks of whole rows
            np.copyto(count, _stimulation_count(e, self.threshold))
            return
        offs = np.flatnonzero(~on)
        np.copyto(count, on)
        if offs.size:  # at each sample at or below the threshold, minus the run before it
            neg_runs = np.empty_like(offs)
            neg_runs[0] = -offs[0]
            np.subtract(offs[:-1], offs[1:], neg_runs[1:])
            np.add(neg_runs[1:], 1, neg_runs[1:])
            count[offs] = neg_runs
        np.cumsum(count, out=count)
        carry = 0 if self.carry is None else int(self.carry[i])
        if carry:
            count[: offs[0] if offs.size else count.size] += carry


def _stimulation_time(e: np.ndarray, threshold, dt_mean) -> np.ndarray:
    """``_stimulation_count(e, threshold) * dt_mean`` for large arrays, in chunks on threads."""
    n = e.shape[-1]
    plan = ChunkPlan((e.size // n, n), [], min_lead=1)
    e2 = e.reshape(plan.n_rows, n)
    out = np.empty(e.shape)
    o2 = out.reshape(plan.n_rows, n)
    counter = _StimulationCounter(e2, threshold, plan)
    dt = np.asarray(dt_mean)

    def work(i, arrays):
        r0, r1, t0, t1 = plan.bounds(i)
        if plan.pieces:  # a piece of row r0 (1-D, as in evaluate_chunked)
            rows, shape = r0, (t1 - t0,)
        else:
            rows, shape = slice(r0, r1), (r1 - r0, t1 - t0)
        count, on = (a[: math.prod(shape)].reshape(shape) for a in arrays)
        counter.count_into(i, e2[rows, t0:t1], count, on)
        np.multiply(count, dt, o2[rows, t0:t1])

    run_chunks(plan.n_chunks, work, scratch="q?", scratch_size=plan.chunk_size)
    return out


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
    non_negative: bool = True,
    basal: bool = True,
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    check: bool = True,
) -> MetabolicRates:
    """BH04: Bhargava, Pandy & Anderson (2004), as implemented in the study.

    Reference: Bhargava LJ, Pandy MG, Anderson FC (2004) A phenomenological model for
    estimating metabolic energy consumption in muscle contraction. J Biomech 37:81-88.

    Equations (W for one muscle; ``V_CE = vbar vmax lMo`` in m/s, negative = shortening;
    constant fibre fractions ``f_ST``, ``f_FT = 1 - f_ST``)::

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
%(shared)s

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
    non_negative : bool
        Apply the non-negativity rule (default True, the study's setting).
    """
    model = "BH04"
    for flag in ("activation_heat_decay", "non_negative", "basal"):
        check_flag(model, flag, locals()[flag])
    if maintenance_length_dependence not in _LENGTH_DEPENDENCE:
        raise OptionError(
            f"BH04: maintenance_length_dependence must be one of {', '.join(_LENGTH_DEPENDENCE)}, "
            f"not {maintenance_length_dependence!r}"
        )
    inp = prepare_inputs(model, locals(), check=check, defer_large=True)
    k = BHARGAVA_CONSTANTS
    e = inp.excitation
    mass = inp.muscle_mass_kg
    f_st = inp.slow_twitch_fraction
    f_ft = 1.0 - f_st

    counting = False  # count the stimulation time chunk by chunk in the kernel
    if activation_heat_decay:
        if stimulation_time_s is not None:
            t_stim = np.asarray(stimulation_time_s, dtype=float)
            if np.any(np.isnan(t_stim)) or np.any(t_stim < 0):
                raise OptionError(
                    "BH04: stimulation_time_s must not be NaN or negative (s; inf is the steady-state limit)"
                )
            try:
                np.broadcast_shapes(t_stim.shape, inp.shape)
            except ValueError:
                raise DataMismatchError(
                    f"BH04: stimulation_time_s has shape {t_stim.shape}, not broadcastable to the "
                    f"muscle states {inp.shape}"
                ) from None
        elif time_s is not None:
            dt_mean = _mean_sampling_interval(inp.shape, time_s)
            counting = True
            t_stim = np.zeros(())
        else:
            raise OptionError(
                "BH04: the activation-heat decay needs time: pass time_s (s, along the last axis) or "
                "stimulation_time_s, or set activation_heat_decay=False"
            )
    else:
        t_stim = np.zeros(())
    decay = bool(activation_heat_decay)
    infinite = bool(np.any(np.isinf(t_stim)))
    floor = k["decay_floor"]
    rate = 1.0 / k["decay_time_constant_s"]
    published = maintenance_length_dependence == "published"

    # per-muscle constants
    act_fast = k["activation_fast_W_per_kg"] * f_ft * mass
    act_slow = k["activation_slow_W_per_kg"] * f_st * mass
    main_fast = k["maintenance_fast_W_per_kg"] * f_ft * mass
    main_slow = k["maintenance_slow_W_per_kg"] * f_st * mass
    neg_v_scale = -(inp.max_contraction_velocity * inp.optimal_fiber_length_m)  # -V_CE / vbar
    basal_w = basal_rate(inp, basal, basal_rate_W_per_kg)
    params = [inp.max_isometric_force_N, act_fast, act_slow, main_fast, main_slow, neg_v_scale, basal_w]
    neg_rate = np.array(-rate)
    floor = np.array(floor)

    plan = ChunkPlan(inp.shape, params, min_lead=max(0, inp.ndim - 1))
    counter = None
    if counting:
        if plan.lead == inp.ndim - 1:  # rows along the last axis: count in the kernel
            e2 = np.broadcast_to(e, inp.shape).reshape(plan.n_rows, plan.n_cols)
            counter = _StimulationCounter(e2, excitation_threshold, plan)
            neg_rate_dt = np.asarray(-rate * dt_mean)
        else:  # parameters vary along the last axis: count first
            t_stim = bhargava_stimulation_time_s(np.broadcast_to(e, inp.shape), time_s, excitation_threshold)

    def kernel(out, s, p, tmp, i):
        work, h_am, h_sl, total, h_a, h_m = out
        e, a, lm, vb, fl, fv, fpe, t_stim = s
        f0, act_fast, act_slow, main_fast, main_slow, neg_v_scale, basal_w = p
        u_s, tan_q, t1, t2, t3, m1, m2, count, on = tmp
        # u_f = t u_s: h = (c_fast u_f + c_slow u_s) = (c_fast t + c_slow) u_s
        recruitment_terms_into(e, tan_q, u_s, t1)
        np.multiply(tan_q, act_fast, h_a)
        np.add(h_a, act_slow, h_a)
        np.multiply(h_a, u_s, h_a)
        if decay:
            if counter is not None:  # t_stim = count * dt_mean, > 0 exactly where e > threshold
                counter.count_into(i, e, count, on)
                np.multiply(count, neg_rate_dt, t1)  # -t_stim / 0.045
                np.multiply(t1, e, t1)
                np.negative(on.view(np.int8), m1)
            else:
                np.multiply(t_stim, e, t1)
                if infinite:  # inf * 0: no excitation, no activation heat either way
                    keep_where(t1, as_mask(np.equal(t1, t1, m1)))  # 0 where NaN
                as_mask(np.greater(t_stim, ZERO, m1))
                np.multiply(t1, neg_rate, t1)
            np.exp(t1, t1)
            np.add(t1, floor, t1)
            keep_where(t1, m1)  # phi = 0 where t_stim = 0
            np.multiply(h_a, t1, h_a)
        np.multiply(tan_q, main_fast, h_m)
        np.add(h_m, main_slow, h_m)
        np.multiply(h_m, u_s, h_m)
        if published:
            np.multiply(h_m, np.interp(lm, [0.5, 1.0, 1.5], [0.5, 1.0, 0.0]), h_m)
        else:
            np.multiply(h_m, lm, h_m)
        np.multiply(vb, neg_v_scale, t3)  # -V_CE
        as_mask(np.greater_equal(t3, ZERO, m2))  # shortening or isometric: V_CE <= 0
        np.multiply(a, fl, t1)
        np.multiply(t1, f0, t1)  # F_iso
        np.multiply(t1, fv, work)  # F_CE
        np.add(work, fpe, t2)  # F_M
        np.multiply(t1, _C.short_iso, t1)
        np.multiply(t2, _C.short_total, u_s)
        np.add(t1, u_s, t1)  # shortening coefficient
        np.multiply(t2, _C.lengthening, h_sl)  # lengthening coefficient
        select_into(h_sl, m2, t1, t2)
        np.multiply(h_sl, t3, h_sl)
        np.multiply(work, t3, work)  # -F_CE V_CE
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
            e, inp.activation, inp.normalized_fiber_length, inp.normalized_fiber_velocity,
            inp.active_force_length_multiplier, inp.force_velocity_multiplier, inp.passive_fiber_force_N, t_stim,
        ],
        params,
        6,
        scratch="dddddqqq?",
        plan=plan,
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
