"""What every metabolic energy model shares: inputs, checks, the result type and the rules
that close a model (non-negativity, minimum heat rate, basal heat).

All models take the same arguments (``energy_model_arguments`` of :data:`musclemetab._docs.docdict`):

* seven muscle-state arrays of any common (broadcastable) shape, conventionally
  ``(muscles, time)``;
* five muscle parameters, scalars or arrays whose shape matches the *leading* axes of the
  states (``(M,)`` for states of shape ``(M, T)``) and which are broadcast along the
  trailing (time) axes. This differs from NumPy's trailing-axis rule on purpose: a
  per-muscle array can never be matched against the time axis by accident.

Sign conventions (``docs/metabolics.md``): fiber velocity is positive when the fiber
lengthens; the mechanical work rate ``W_CE = -F_CE V_CE`` is positive when the muscle does
work (shortening).

Each model is one plain NumPy function whose body reads like its equations (one array
expression per term; per-muscle constants formed first; a branch as the larger of its two
values where that is exact, or as :func:`select`; see ``docs/metabolics.md``, Speed).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from .._docs import fill_doc
from ..errors import DataMismatchError, OptionError

__all__ = [
    "BASAL_RATE_W_PER_KG",
    "MINIMUM_HEAT_RATE_W_PER_KG",
    "FIBER_FRACTIONS",
    "MetabolicRates",
    "COMPONENTS",
    "STATE_ARGUMENTS",
    "PARAMETER_ARGUMENTS",
    "MuscleInputs",
    "prepare_inputs",
    "apply_non_negativity",
    "select",
    "apply_minimum_heat_rate",
    "basal_rate",
    "basal_view",
    "recruitment_terms",
    "recruited_slow_twitch_fraction",
    "check_flag",
    "check_choice",
    "check_number",
    "model_function",
]

#: Basal metabolic rate (W/kg), Umberger et al. (2003). The study's code adds it per kg of
#: *muscle* mass to every muscle; the paper adds it per kg of *body* mass (see
#: :mod:`musclemetab.metabolics.whole_body`).
BASAL_RATE_W_PER_KG = 1.2

#: Minimum total heat rate of a muscle (W/kg of muscle mass), Umberger et al. (2003) p. 104;
#: OpenSim's probes enforce it by default (``enforce_minimum_heat_rate_per_muscle``), the
#: study's code does not (an option of the Umberger family and BH04).
MINIMUM_HEAT_RATE_W_PER_KG = 1.0

#: Fiber-type fractions of a model's heats (option ``fiber_fractions`` of BH04 and HO06):
#: the muscle's (the study's ``option = 1``) or those recruited at the excitation (Uchida
#: et al. 2016; the study's ``option = 2``, :func:`recruited_slow_twitch_fraction`).
FIBER_FRACTIONS = ("constant", "recruited")

#: The five components every model returns, in W.
COMPONENTS = ("work", "activation_maintenance", "shortening_lengthening", "basal", "total")

STATE_ARGUMENTS = (
    "excitation",
    "activation",
    "normalized_fiber_length",
    "normalized_fiber_velocity",
    "active_force_length_multiplier",
    "force_velocity_multiplier",
    "passive_fiber_force_N",
)

PARAMETER_ARGUMENTS = (
    "max_isometric_force_N",
    "optimal_fiber_length_m",
    "max_contraction_velocity",
    "muscle_mass_kg",
    "slow_twitch_fraction",
)

@dataclass(frozen=True, eq=False)
class MetabolicRates:
    """Metabolic rates of one model, per component, in W (arrays of one shape).

    ``total = work + activation_maintenance + shortening_lengthening + basal``, where
    ``work`` is the mechanical work rate the model counts (for UM10 only the positive,
    concentric part) and the heats are those after the model's non-negativity rule.
    ``extras`` holds model-specific sub-components in W (for instance BH04's and HO06's
    separate ``activation`` and ``maintenance`` heats). ``basal`` is constant in time: a
    read-only broadcast view of the per-muscle value (copy it to modify it).
    """

    model: str
    work: np.ndarray
    activation_maintenance: np.ndarray
    shortening_lengthening: np.ndarray
    basal: np.ndarray
    total: np.ndarray
    extras: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __repr__(self) -> str:
        """One line per component: its mean and range (W) over every muscle and sample, not the arrays."""
        lines = [f"MetabolicRates {self.model}: components of shape {self.shape} (W; mean, min to max)"]
        for name, arr in self.components().items():
            a = np.asarray(arr, dtype=float)
            lines.append(f"  {name:<24} {a.mean():10.4g} {a.min():10.4g} to {a.max():.4g}" if a.size else f"  {name}: empty")
        return "\n".join(lines)

    __str__ = __repr__

    @property
    def heat(self) -> np.ndarray:
        """Total heat rate (W): activation/maintenance + shortening/lengthening + basal."""
        return self.activation_maintenance + self.shortening_lengthening + self.basal

    @property
    def shape(self) -> tuple[int, ...]:
        return self.total.shape

    def components(self) -> dict[str, np.ndarray]:
        """All components, the five standard ones first, then the extras (W)."""
        out = {name: getattr(self, name) for name in COMPONENTS}
        out.update(self.extras)
        return out

    def __getitem__(self, name: str) -> np.ndarray:
        comps = self.components()
        if name not in comps:
            raise OptionError(
                f"model {self.model} has no component '{name}'; it has {', '.join(comps)}"
            )
        return comps[name]

    def total_without_basal(self) -> np.ndarray:
        """``work + activation_maintenance + shortening_lengthening`` (W): the muscle's rate
        without any basal heat, ``total - basal`` but for rounding. Summed from the other
        components, it does not depend on the basal heat at all."""
        return self.work + self.activation_maintenance + self.shortening_lengthening


class MuscleInputs:
    """Checked inputs of a model call: NumPy arrays, parameters aligned for broadcasting."""

    __slots__ = STATE_ARGUMENTS + PARAMETER_ARGUMENTS + ("shape", "ndim", "model")

    def states(self) -> dict[str, np.ndarray]:
        """The seven state arrays by name, in argument order."""
        return {name: getattr(self, name) for name in STATE_ARGUMENTS}


def _as_float(name: str, value, model: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise OptionError(
            f"{model}: argument '{name}' must be numeric (a number or an array of numbers), "
            f"not {type(value).__name__}"
        ) from None
    return arr


def _check_finite(name: str, arr: np.ndarray, model: str) -> None:
    # one reduction over the array: a NaN or an infinity makes the sum non-finite (a sum can
    # also overflow with finite values; the element-wise test below then finds nothing)
    if np.isfinite(np.sum(arr)):
        return
    finite = np.isfinite(arr)
    if finite.all():
        return
    bad = ~finite
    n_bad = int(bad.sum())
    where = np.unravel_index(int(np.flatnonzero(bad.ravel())[0]), arr.shape) if arr.ndim else ()
    kind = "NaN" if np.isnan(arr).any() else "infinite"
    raise OptionError(
        f"{model}: argument '{name}' holds {kind} values ({n_bad} of {arr.size}, first at index "
        f"{tuple(int(i) for i in where)}); remove or interpolate them before computing metabolic rates"
    )


def prepare_inputs(model: str, values: Mapping[str, object], check: bool = True) -> MuscleInputs:
    """Convert, check and align the shared model arguments.

    Raises
    ------
    DataMismatchError
        State arrays do not broadcast together, or a parameter's shape is not the leading
        part of the states' shape.
    OptionError
        A value is not numeric, not finite, or out of its range (``F0``, ``lMo``, ``vmax``
        > 0; mass >= 0; ``0 <= f_ST <= 1``).
    """
    out = MuscleInputs()
    states = {}
    for name in STATE_ARGUMENTS:
        states[name] = arr = _as_float(name, values[name], model)
        if check:
            _check_finite(name, arr, model)
    try:
        shape = np.broadcast_shapes(*(a.shape for a in states.values()))
    except ValueError:
        shapes = ", ".join(f"{k} {v.shape}" for k, v in states.items())
        raise DataMismatchError(
            f"{model}: the muscle-state arrays do not have compatible shapes ({shapes}); give them "
            "one shape, e.g. (muscles, time)"
        ) from None
    ndim = len(shape)
    full = shape
    for name in PARAMETER_ARGUMENTS:
        arr = _as_float(name, values[name], model)
        if arr.ndim > ndim:
            raise DataMismatchError(
                f"{model}: parameter '{name}' has shape {arr.shape} but the muscle states have shape "
                f"{shape}; give one value per muscle (shape {shape[:1]}) or a scalar"
            )
        lead = shape[: arr.ndim]
        if any(p != s and p != 1 and s != 1 for p, s in zip(arr.shape, lead)):
            raise DataMismatchError(
                f"{model}: parameter '{name}' has shape {arr.shape}, which does not match the leading "
                f"axes {lead} of the muscle states (shape {shape}); give one value per muscle"
            )
        if check:
            _check_finite(name, arr, model)
            if name == "slow_twitch_fraction":
                if np.any((arr < 0) | (arr > 1)):
                    raise OptionError(f"{model}: slow_twitch_fraction must lie in [0, 1]")
            elif name == "muscle_mass_kg":
                if np.any(arr < 0):
                    raise OptionError(f"{model}: muscle_mass_kg must not be negative (kg)")
            elif np.any(arr <= 0):
                raise OptionError(f"{model}: parameter '{name}' must be positive")
        arr = arr.reshape(arr.shape + (1,) * (ndim - arr.ndim))
        full = np.broadcast_shapes(full, arr.shape)
        setattr(out, name, arr)
    for name, arr in states.items():
        setattr(out, name, arr)
    out.shape = full
    out.ndim = len(full)
    out.model = model
    return out


def apply_non_negativity(rest, h_sl):
    """Paper Eq. 3: where the total rate ``rest + H_SL`` is negative, raise ``H_SL`` so that
    the total is zero (``rest``: the work rate plus the other heats, W).

    The study's UM03 tests ``total < 0``, its UC16, BH04 and HO06 ``total <= 0``: the two
    differ only where the total is exactly zero, where ``H_SL = -rest`` either way. A rounded
    sum has the sign of the exact sum, so ``total < 0`` exactly where ``H_SL < -rest``: the
    rule is ``H_SL := max(H_SL, -rest)``. Returns the new ``H_SL``.
    """
    return np.maximum(h_sl, -rest)


def select(condition, if_true, if_false):
    """``np.where(condition, if_true, if_false)`` for finite values, as arithmetic:
    ``if_true * condition + if_false * ~condition`` (``x * 1 + y * 0 = x`` exactly, but for
    the sign of a zero). ``np.where`` takes a branch per sample, whose cost grows with how
    unpredictable the condition is; this does not."""
    return if_true * condition + if_false * ~condition


def apply_minimum_heat_rate(heats, muscle_mass_kg, minimum_W_per_kg):
    """OpenSim's minimum heat rate: where the heat rate ``sum(heats)`` of a muscle is below
    ``minimum m`` (W), it becomes ``minimum m``, given to the first heat, the others 0 (the
    split OpenSim reports).

    ``minimum_W_per_kg = None`` (or 0) leaves the heats as they are. Returns the new heats.
    """
    if not minimum_W_per_kg:
        return tuple(heats)
    floor = minimum_W_per_kg * muscle_mass_kg
    low = sum(heats) < floor
    return (np.where(low, floor, heats[0]),) + tuple(np.where(low, 0.0, h) for h in heats[1:])


def basal_view(basal_w: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """The basal component of a result: the per-muscle basal heat (W, parameter-shaped)
    as a read-only view of the states' ``shape`` (constant in time: no memory per sample)."""
    return np.broadcast_to(basal_w, shape)


def basal_rate(inp: MuscleInputs, basal: bool, basal_rate_W_per_kg: float) -> np.ndarray:
    """Basal heat ``rate * m`` (W), parameter-shaped (zeros when off)."""
    if not basal:
        return np.zeros_like(inp.muscle_mass_kg)
    rate = float(basal_rate_W_per_kg)
    if not np.isfinite(rate) or rate < 0:
        raise OptionError(f"basal_rate_W_per_kg must be a non-negative number, not {basal_rate_W_per_kg!r}")
    return rate * inp.muscle_mass_kg


def recruitment_terms(excitation):
    """``u_s = sin(pi e/2)`` and ``u_f = 1 - cos(pi e/2)`` (Bhargava et al. 2004).

    Both are computed from the half-angle tangent ``t = tan(pi e/4)``::

        u_s = 2 t / (1 + t^2),    u_f = 2 t^2 / (1 + t^2) = t u_s

    which are the two functions exactly; ``u_f`` then has no cancellation near ``e = 0``
    (as ``1 - cos`` has).
    """
    t = np.tan(0.25 * np.pi * np.asarray(excitation, dtype=float))
    u_s = (2.0 * t) / (1.0 + t * t)
    t *= u_s  # u_f
    return u_s, t


def recruited_slow_twitch_fraction(excitation, slow_twitch_fraction):
    """Uchida et al. (2016)'s recruited slow-twitch fraction (orderly recruitment).

    ``f_ST' = f_ST u_s / (f_ST u_s + f_FT u_f)`` with ``u_s``, ``u_f`` of
    :func:`recruitment_terms`, and ``f_ST' = 1`` where the denominator is zero (``e = 0``;
    the study's code tests ``e == 0``). With ``u_f = t u_s`` (``t = tan(pi e/4)``) this is
    ``f_ST / (f_ST + f_FT t)``, which is 1 at ``e = 0`` for every ``f_ST``.
    """
    t = np.tan(0.25 * np.pi * np.asarray(excitation, dtype=float))
    f_st = np.asarray(slow_twitch_fraction, dtype=float)
    den = f_st + (1.0 - f_st) * t
    with np.errstate(divide="ignore", invalid="ignore"):
        out = f_st / den
    if not np.all(den):
        out = np.where(den == 0, 1.0, out)
    return out


def check_flag(model: str, name: str, value) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise OptionError(f"{model}: option '{name}' must be True or False, not {value!r}")
    return bool(value)


def check_choice(model: str, name: str, value, choices) -> str:
    if value not in choices:
        raise OptionError(f"{model}: option '{name}' must be one of {', '.join(map(repr, choices))}, not {value!r}")
    return value


def check_number(model: str, name: str, value, *, minimum: float = 0.0, allow_none: bool = False):
    """A finite number >= ``minimum`` (or None where allowed), else :class:`OptionError`."""
    if value is None and allow_none:
        return None
    try:
        x = float(value)
    except (TypeError, ValueError):
        x = float("nan")
    if isinstance(value, bool) or not np.isfinite(x) or x < minimum:
        raise OptionError(f"{model}: option '{name}' must be a finite number >= {minimum:g}, not {value!r}")
    return x


def model_function(name: str):
    """Mark a function as the implementation of the model ``name`` (sets ``.model_name``)."""

    def deco(func):
        func.model_name = name
        return fill_doc(func)

    return deco
