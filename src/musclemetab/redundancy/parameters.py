"""Muscle-tendon parameters of one solve, by muscle.

Five values come from the OpenSim model (``F0``, ``lMo``, ``lTs``, ``alpha0``, ``vmax``); the
tendon stiffness ``kT`` and the passive force-length shape ``kPE``, ``s0``, ``sM`` come from
the workflow (``docs/method.md``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from ..errors import DataMismatchError, UnknownMuscleError
from ..messages import name_list
from ..muscle import fiber_width, tendon_shift

__all__ = ["MuscleTendonParameters", "PARAMETER_FIELDS"]

#: Field name -> short key used in ``summary.json``.
PARAMETER_FIELDS = {
    "max_isometric_force_N": "F0_N",
    "optimal_fiber_length_m": "lMo_m",
    "tendon_slack_length_m": "lTs_m",
    "pennation_angle_at_optimal_rad": "alpha0_rad",
    "max_contraction_velocity": "vmax_lMo_per_s",
    "tendon_stiffness": "kT",
    "passive_kpe": "kPE",
    "passive_s0": "s0",
    "passive_sm": "sM",
}


@dataclass(frozen=True)
class MuscleTendonParameters:
    """Per-muscle parameters, arrays of shape ``(M,)`` in the order of ``names``.

    ``max_contraction_velocity`` is in optimal fiber lengths per second; ``tendon_stiffness``
    is the normalised ``kT`` (generic 35); ``passive_*`` are ``kPE``, ``s0``, ``sM``.
    """

    names: tuple[str, ...]
    max_isometric_force_N: np.ndarray
    optimal_fiber_length_m: np.ndarray
    tendon_slack_length_m: np.ndarray
    pennation_angle_at_optimal_rad: np.ndarray
    max_contraction_velocity: np.ndarray
    tendon_stiffness: np.ndarray
    passive_kpe: np.ndarray
    passive_s0: np.ndarray
    passive_sm: np.ndarray
    sources: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "names", tuple(self.names))
        m = len(self.names)
        for name in PARAMETER_FIELDS:
            arr = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            if arr.size == 1 and m != 1:
                arr = np.full(m, float(arr[0]))
            if arr.shape != (m,):
                raise DataMismatchError(f"muscle parameter '{name}' has {arr.size} values for {m} muscles")
            if not np.all(np.isfinite(arr)):
                bad = [self.names[i] for i in np.flatnonzero(~np.isfinite(arr))]
                raise DataMismatchError(f"muscle parameter '{name}' is not finite for {name_list(bad)}")
            object.__setattr__(self, name, arr)
        for name in ("max_isometric_force_N", "optimal_fiber_length_m", "tendon_slack_length_m",
                     "max_contraction_velocity", "tendon_stiffness", "passive_kpe", "passive_sm"):
            arr = getattr(self, name)
            if np.any(arr <= 0):
                bad = [self.names[i] for i in np.flatnonzero(arr <= 0)]
                raise DataMismatchError(f"muscle parameter '{name}' must be positive; it is not for {name_list(bad)}")

    @property
    def width_m(self) -> np.ndarray:
        """Constant fiber-height projection ``w = lMo sin(alpha0)`` (m)."""
        return fiber_width(self.optimal_fiber_length_m, self.pennation_angle_at_optimal_rad)

    @property
    def tendon_shift(self) -> np.ndarray:
        return tendon_shift(self.tendon_stiffness)

    def index(self, names: Sequence[str]) -> np.ndarray:
        pos = {n: i for i, n in enumerate(self.names)}
        missing = [n for n in names if n not in pos]
        if missing:
            raise UnknownMuscleError(
                f"no parameters for muscle{'s' if len(missing) > 1 else ''} {name_list(missing)}; "
                f"the parameter set has {', '.join(self.names[:6])}{' ...' if len(self.names) > 6 else ''}"
            )
        return np.array([pos[n] for n in names], dtype=int)

    def subset(self, names: Sequence[str]) -> "MuscleTendonParameters":
        idx = self.index(names)
        kw = {k: getattr(self, k)[idx] for k in PARAMETER_FIELDS}
        return MuscleTendonParameters(names=tuple(names), sources=dict(self.sources), **kw)

    def replace(self, **values: Mapping[str, float]) -> "MuscleTendonParameters":
        """Copy with some per-muscle values replaced, e.g. ``replace(tendon_stiffness={'soleus_r': 10})``."""
        kw = {k: getattr(self, k).copy() for k in PARAMETER_FIELDS}
        for fname, mapping in values.items():
            if fname not in PARAMETER_FIELDS:
                raise KeyError(fname)
            idx = self.index(list(mapping))
            kw[fname][idx] = [float(v) for v in mapping.values()]
        return MuscleTendonParameters(names=self.names, sources=dict(self.sources), **kw)

    def to_records(self) -> dict:
        """``{muscle: {F0_N, lMo_m, lTs_m, alpha0_rad, vmax_lMo_per_s, kT, kPE, s0, sM}}``."""
        return {
            n: {key: float(getattr(self, f)[i]) for f, key in PARAMETER_FIELDS.items()}
            for i, n in enumerate(self.names)
        }

    @classmethod
    def from_records(cls, records: Mapping[str, Mapping[str, float]], sources=None) -> "MuscleTendonParameters":
        names = tuple(records)
        kw = {f: np.array([float(records[n][key]) for n in names]) for f, key in PARAMETER_FIELDS.items()}
        return cls(names=names, sources=dict(sources or {}), **kw)
