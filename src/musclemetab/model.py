"""The musculoskeletal model: muscle parameters by name, body mass, degrees of freedom.

The ``.osim`` file is read by OpenSim in the worker process
(:mod:`musclemetab.opensim_bridge`); this module holds the result as plain arrays.
Only five Hill parameters are taken from the model (see ``docs/method.md`` and
``docs/muscles.md``): maximal isometric force, optimal fiber length, tendon slack length,
pennation angle at optimal fiber length and maximal contraction velocity (optimal lengths
per second; OpenSim's default of 10 when the model does not give it). They are read
through OpenSim's common ``Muscle`` interface, so every muscle class reads the same way
(Thelen2003, Millard2012 equilibrium and acceleration, DeGrooteFregly2016, ...); the
class-specific curves and time constants are not used: the study's muscle curves
(:mod:`musclemetab.muscle`) apply to every class. ``ModelInfo.muscle_classes`` records
each muscle's class.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import ModelError, OptionError, UnknownMuscleError

__all__ = [
    "MuscleParameters",
    "ModelInfo",
    "read_model",
    "read_muscle_parameters",
    "model_is_cached",
    "check_body_mass",
    "BODY_MASS_TOLERANCE",
    "default_dofs",
    "SIDES",
]

SIDES = ("r", "l")
_DOF_STEMS = ("ankle_angle", "knee_angle", "hip_flexion", "hip_adduction", "hip_rotation")


def default_dofs(side: str = "r") -> list[str]:
    """The five lower-limb DOFs of the study for one side, in the solver's order."""
    if side not in SIDES:
        raise OptionError(f"side must be 'r' or 'l', not {side!r}")
    return [f"{s}_{side}" for s in _DOF_STEMS]


@dataclass(frozen=True)
class MuscleParameters:
    """Hill-model parameters of a set of muscles, one array entry per muscle (by name)."""

    names: tuple[str, ...]
    max_isometric_force_N: np.ndarray
    optimal_fiber_length_m: np.ndarray
    tendon_slack_length_m: np.ndarray
    pennation_angle_at_optimal_rad: np.ndarray
    max_contraction_velocity: np.ndarray  # optimal fiber lengths per second

    def __len__(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise UnknownMuscleError(
                f"muscle '{name}' is not among the model's muscles ({', '.join(self.names[:6])}, ...)"
            ) from None

    def subset(self, names) -> "MuscleParameters":
        """The parameters of ``names``, in that order (matched by name)."""
        idx = [self.index(n) for n in names]
        return MuscleParameters(
            tuple(names),
            *(getattr(self, f)[idx] for f in _ARRAY_FIELDS),
        )

    def to_dict(self) -> dict:
        return {n: {f: float(getattr(self, f)[i]) for f in _ARRAY_FIELDS} for i, n in enumerate(self.names)}


_ARRAY_FIELDS = (
    "max_isometric_force_N",
    "optimal_fiber_length_m",
    "tendon_slack_length_m",
    "pennation_angle_at_optimal_rad",
    "max_contraction_velocity",
)


@dataclass(frozen=True)
class ModelInfo:
    """What the package needs to know of an ``.osim`` model."""

    path: str
    name: str
    muscles: MuscleParameters
    body_mass_kg: float
    coordinates: tuple[dict, ...] = field(repr=False)
    couplers: tuple[dict, ...] = field(repr=False)
    opensim_version: str = ""
    muscle_classes: dict = field(default_factory=dict, repr=False)  # muscle -> OpenSim class name

    def coordinate_names(self, unlocked_only: bool = True) -> list[str]:
        return [c["name"] for c in self.coordinates if not (unlocked_only and c["locked"])]


_CACHE: dict = {}


def check_model_path(path: str | os.PathLike) -> Path:
    """``path`` as a Path; :class:`ModelError` when it is a folder or does not exist."""
    path = Path(path)
    if path.is_dir():
        raise ModelError(f"{path} is a folder, not a model file; give the path of the .osim file")
    if not path.is_file():
        raise ModelError(f"{path}: no such model file; check the path")
    return path


def model_is_cached(model_path: str | os.PathLike, cache_dir: str | os.PathLike | None = None) -> bool:
    """Whether the model parameters (:func:`read_model`) and the layout
    (:func:`musclemetab.layout.read_layout`) would come without OpenSim (memory or disk cache)."""
    from .cache import model_call_is_cached

    path = Path(model_path)
    try:
        key = (str(path.resolve()), path.stat().st_mtime_ns, path.stat().st_size)
    except OSError:
        return False
    return ((key in _CACHE or model_call_is_cached(path, "model_ops:read_model_info", cache_dir))
            and model_call_is_cached(path, "model_ops:model_layout", cache_dir))


def read_model(model_path: str | os.PathLike, *, cache_dir: str | os.PathLike | None = None,
               use_cache: bool = True) -> ModelInfo:
    """Read muscles, body mass and coordinates of an ``.osim`` model (through OpenSim).

    The result is cached on disk, keyed by the file's content, beside the geometry
    (:func:`musclemetab.cache.cached_model_call`, same integrity rules; ``cache_dir`` as for
    :func:`musclemetab.geometry.compute_geometry`): another process reading the same model
    does not start OpenSim.
    """
    from .cache import cached_model_call
    from .opensim_bridge import call

    path = check_model_path(model_path)
    key = (str(path.resolve()), path.stat().st_mtime_ns, path.stat().st_size)
    if key in _CACHE:
        return _CACHE[key]
    raw = cached_model_call(path, "model_ops:read_model_info", cache_dir, use_cache, compute=call)
    raw["path"] = str(path.resolve())
    ms = raw["muscles"]
    if not ms:
        raise ModelError(f"{path}: the model has no muscles")
    params = MuscleParameters(
        tuple(m["name"] for m in ms),
        *(np.array([m[f] for m in ms], dtype=float) for f in _ARRAY_FIELDS),
    )
    info = ModelInfo(
        path=raw["path"],
        name=raw["name"],
        muscles=params,
        body_mass_kg=float(raw["body_mass_kg"]),
        coordinates=tuple(raw["coordinates"]),
        couplers=tuple(raw["couplers"]),
        opensim_version=raw["opensim_version"],
        muscle_classes={m["name"]: m.get("class_name", "") for m in ms},
    )
    _CACHE[key] = info
    return info


#: A body mass given for a subject further than this share from its model's mass is said (a typing
#: slip, or another subject's model: scaling gives the model the subject's mass).
BODY_MASS_TOLERANCE = 0.10


def check_body_mass(mass_kg: float, model_path: str | os.PathLike, given: str = "--mass", *,
                    cache_dir: str | os.PathLike | None = None) -> None:
    """Warn (:class:`~musclemetab.errors.MusclemetabWarning`) when ``mass_kg``, the body mass
    ``given`` (an option or a study key), differs from the mass of the model at ``model_path``
    (:func:`read_model`, from the cache after a solve) by more than :data:`BODY_MASS_TOLERANCE`:
    the rates per kilogram, the muscles' masses and the basal heat take the mass given."""
    import warnings

    from .errors import MusclemetabWarning

    model_kg = read_model(model_path, cache_dir=cache_dir).body_mass_kg
    if model_kg > 0 and abs(float(mass_kg) / model_kg - 1.0) > BODY_MASS_TOLERANCE:
        warnings.warn(f"{given} {float(mass_kg):g} kg differs from the mass of the model {model_path} "
                      f"({model_kg:.4g} kg) by {100 * abs(float(mass_kg) / model_kg - 1.0):.0f} %: the rates per kg, the "
                      f"muscles' masses and the basal heat take {given}; check that both are this subject's",
                      MusclemetabWarning, stacklevel=2)


def read_muscle_parameters(model_path: str | os.PathLike, *,
                           cache_dir: str | os.PathLike | None = None) -> MuscleParameters:
    """The five Hill parameters of every muscle of the model, in model order."""
    return read_model(model_path, cache_dir=cache_dir).muscles
