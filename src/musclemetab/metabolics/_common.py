"""What every metabolic energy model shares: inputs, checks, the result type, the rules
that close a model (non-negativity, basal heat).

All models take the same arguments (see :data:`SHARED_PARAMETERS_DOC`):

* seven muscle-state arrays of any common (broadcastable) shape, conventionally
  ``(muscles, time)``;
* five muscle parameters, scalars or arrays whose shape matches the *leading* axes of the
  states (``(M,)`` for states of shape ``(M, T)``) and which are broadcast along the
  trailing (time) axes. This differs from NumPy's trailing-axis rule on purpose: a
  per-muscle array can never be matched against the time axis by accident.

Sign conventions (``docs/metabolics.md``): fibre velocity is positive when the fibre
lengthens; the mechanical work rate ``W_CE = -F_CE V_CE`` is positive when the muscle does
work (shortening).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from ..errors import DataMismatchError, OptionError

__all__ = [
    "BASAL_RATE_W_PER_KG",
    "MetabolicRates",
    "COMPONENTS",
    "STATE_ARGUMENTS",
    "PARAMETER_ARGUMENTS",
    "MuscleInputs",
    "prepare_inputs",
    "apply_non_negativity",
    "basal_rate",
    "shared_doc",
    "full_shape",
    "run_kernel",
    "recruitment_terms",
    "CHUNK_SIZE",
    "check_flag",
    "model_function",
]

#: Basal metabolic rate (W/kg), Umberger et al. (2003). The study's code adds it per kg of
#: *muscle* mass to every muscle; the paper adds it per kg of *body* mass (see
#: :mod:`musclemetab.metabolics.whole_body`).
BASAL_RATE_W_PER_KG = 1.2

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

SHARED_PARAMETERS_DOC = """\
    excitation : array_like
        Neural excitation ``e`` (-), 0..1.
    activation : array_like
        Muscle activation ``a`` (-), 0..1.
    normalized_fiber_length : array_like
        ``l~M = lM / lMo`` (-).
    normalized_fiber_velocity : array_like
        ``vbar = v~M / vmax`` (-), fibre velocity in optimal lengths per second divided by
        the maximal contraction velocity (OpenSim's definition; -1..1); positive =
        lengthening. The fibre velocity in m/s is ``V_CE = vbar * vmax * lMo``.
    active_force_length_multiplier : array_like
        ``fL(l~M)`` (-).
    force_velocity_multiplier : array_like
        ``fV(vbar)`` (-).
    passive_fiber_force_N : array_like
        Passive fibre force ``F0 * fPE(l~M)`` along the fibre (N).
    max_isometric_force_N, optimal_fiber_length_m : array_like
        ``F0`` (N) and ``lMo`` (m), per muscle.
    max_contraction_velocity : array_like
        ``vmax`` in optimal fibre lengths per second (10 in the study), per muscle.
    muscle_mass_kg : array_like
        Muscle mass ``m`` (kg), per muscle.
    slow_twitch_fraction : array_like
        Fraction of slow-twitch fibres ``f_ST`` (-), per muscle; ``f_FT = 1 - f_ST``.
    time_s : array_like, optional
        Time (s) along the last axis; used only by models with a time-dependent term.
    basal : bool
        Add the basal heat ``basal_rate_W_per_kg * m`` to the muscle's rate (after the
        non-negativity rule), as the study's code does (``basalOn = 1``). The paper instead
        adds 1.2 W/kg of *body* mass to the whole-body rate: see
        :func:`musclemetab.metabolics.whole_body_rate`, which removes this component
        under that rule.
    basal_rate_W_per_kg : float
        Basal rate per kg of muscle mass (1.2).
    check : bool
        Check shapes and values (finite states, positive parameters). Turn off only for
        inputs already checked.

    Arguments are matched by name; states broadcast against each other, parameters are
    aligned with the leading axes of the states (``(M,)`` for ``(M, T)`` states).

    Returns
    -------
    MetabolicRates
        ``work``, ``activation_maintenance``, ``shortening_lengthening``, ``basal`` and
        ``total`` (W), arrays of the broadcast shape, plus model-specific ``extras`` (W)."""


def shared_doc(func):
    """Insert the shared parameter documentation at ``%(shared)s`` in a docstring."""
    if func.__doc__:
        func.__doc__ = func.__doc__.replace("%(shared)s", SHARED_PARAMETERS_DOC)
    return func


@dataclass(frozen=True, eq=False)
class MetabolicRates:
    """Metabolic rates of one model, per component, in W (arrays of one shape).

    ``total = work + activation_maintenance + shortening_lengthening + basal``, where
    ``work`` is the mechanical work rate the model counts (for UM10 only the positive,
    concentric part) and the heats are those after the model's non-negativity rule.
    ``extras`` holds model-specific sub-components in W (for instance BH04's and HO06's
    separate ``activation`` and ``maintenance`` heats).
    """

    model: str
    work: np.ndarray
    activation_maintenance: np.ndarray
    shortening_lengthening: np.ndarray
    basal: np.ndarray
    total: np.ndarray
    extras: Mapping[str, np.ndarray] = field(default_factory=dict)

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
        """``total - basal`` (W): the muscle's rate without any basal heat."""
        return self.total - self.basal


class MuscleInputs:
    """Checked inputs of a model call: NumPy arrays, parameters aligned for broadcasting."""

    __slots__ = STATE_ARGUMENTS + PARAMETER_ARGUMENTS + ("shape", "ndim")


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
    if arr.ndim == 0:
        ok = bool(np.isfinite(arr))
    else:
        ok = bool(np.isfinite(arr).all())
    if not ok:
        bad = ~np.isfinite(arr)
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
        arr = _as_float(name, values[name], model)
        if check:
            _check_finite(name, arr, model)
        states[name] = arr
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
    return out


def apply_non_negativity(work, heats_other, h_sl, *, strict: bool):
    """Paper Eq. 3: where the total rate is negative, raise ``H_SL`` so the total is zero.

    ``strict=True`` tests ``total < 0`` (UM03), otherwise ``total <= 0`` (UC16, BH04,
    HO06); the two differ only where the total is exactly zero, where the result is the
    same up to rounding.
    """
    rest = work + heats_other
    total = rest + h_sl
    neg = total < 0 if strict else total <= 0
    return np.where(neg, -rest, h_sl)


def basal_rate(inp: MuscleInputs, basal: bool, basal_rate_W_per_kg: float) -> np.ndarray:
    """Basal heat ``rate * m`` (W), parameter-shaped (zeros when off)."""
    if not basal:
        return np.zeros_like(inp.muscle_mass_kg)
    rate = float(basal_rate_W_per_kg)
    if not np.isfinite(rate) or rate < 0:
        raise OptionError(f"basal_rate_W_per_kg must be a non-negative number, not {basal_rate_W_per_kg!r}")
    return rate * inp.muscle_mass_kg


#: Samples per chunk when evaluating a model (about 256 kB per array: the temporaries of a
#: chunk stay in the processor cache).
CHUNK_SIZE = 8192


def run_kernel(kernel, operands: list, n_outputs: int, chunk_size: int = CHUNK_SIZE) -> list[np.ndarray]:
    """Evaluate ``kernel`` over broadcast operands in cache-sized 1-D chunks.

    ``kernel(*chunks)`` receives one 1-D array per operand (all of one length, or
    broadcastable to it) and returns ``n_outputs`` arrays (or scalars) broadcastable to
    that length. Returns the outputs, arrays of the operands' broadcast shape.
    """
    n_in = len(operands)
    it = np.nditer(
        list(operands) + [None] * n_outputs,
        flags=["external_loop", "buffered", "zerosize_ok"],
        op_flags=[["readonly"]] * n_in + [["writeonly", "allocate"]] * n_outputs,
        op_dtypes=[np.float64] * (n_in + n_outputs),
        buffersize=chunk_size,
    )
    with it:
        for chunk in it:
            results = kernel(*chunk[:n_in])
            for out, res in zip(chunk[n_in:], results):
                out[...] = res
        return list(it.operands[n_in:])


def recruitment_terms(excitation):
    """``u_s = sin(pi e/2)`` and ``u_f = 1 - cos(pi e/2)`` (Bhargava et al. 2004).

    ``u_f`` is computed as ``u_s^2 / (1 + sqrt(1 - u_s^2))``, equal to ``1 - cos`` for
    ``|e| <= 1`` and free of its cancellation near ``e = 0`` (one sine instead of a sine
    and a cosine); outside ``[-1, 1]`` the cosine is used.
    """
    x = (0.5 * np.pi) * excitation
    u_s = np.sin(x)
    s2 = u_s * u_s
    u_f = s2 / (1.0 + np.sqrt(1.0 - s2))
    outside = np.abs(excitation) > 1.0
    if np.any(outside):
        u_f = np.where(outside, 1.0 - np.cos(x), u_f)
    return u_s, u_f


def full_shape(x, shape: tuple[int, ...]) -> np.ndarray:
    """``x`` as a float array of exactly ``shape`` (a broadcast copy when needed)."""
    x = np.asarray(x, dtype=float)
    return x if x.shape == shape else np.broadcast_to(x, shape).copy()


def check_flag(model: str, name: str, value) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise OptionError(f"{model}: option '{name}' must be True or False, not {value!r}")
    return bool(value)


def model_function(name: str):
    """Mark a function as the implementation of the model ``name`` (sets ``.model_name``)."""

    def deco(func):
        func.model_name = name
        return shared_doc(func)

    return deco

