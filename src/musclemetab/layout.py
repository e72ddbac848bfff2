"""Where things are in a model: the legs, their degrees of freedom, the forward coordinate.

Nothing here depends on names: sides, DOFs and the direction of travel are read from the
model's joint tree and its default pose (through OpenSim in the worker process,
:func:`musclemetab.opensim_bridge.model_ops.model_layout`).

Rules (documented in ``docs/trials.md``):

* **Side of a body.** OpenSim models use a ground frame with ``x`` forward, ``y`` up and
  ``z`` to the right. A body belongs to the right (left) side when its origin, in the default
  pose, lies more than :data:`SIDE_OFFSET_M` to the right (left) of the origin of the body
  the root joint moves (the pelvis). ``side`` is ``"r"`` or ``"l"``.
* **DOFs of a side.** The unlocked, independent (not coupler-driven) coordinates of the
  joints whose child body is on that side, ordered from the most distal joint to the most
  proximal, and within a joint in the joint's own order (for the lower-limb models this is
  ankle, knee, then the hip's flexion, adduction and rotation, the study's order). Locked
  arms and coupled coordinates (the Rajagopal knee's ``knee_angle_r_beta``) drop out. A
  motion that moves a locked coordinate of the side's joints is refused, naming it
  (:func:`check_locked_coordinates`): a locked knee would drop the knee and the vasti.
  :func:`discover_dofs` then keeps those the inverse dynamics holds a ``<dof>_moment``
  column for; the muscle selection (``|moment arm| > 1e-4 m``) drops DOFs no muscle spans.
* **Forward coordinate.** The coordinates of the joint(s) attached to the ground whose unit
  increase translates the root body along a horizontal axis (perpendicular to gravity);
  speed is the net horizontal displacement they describe over the gait cycle
  (:mod:`musclemetab.analysis.speed`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from .errors import DataMismatchError, ModelError, OptionError
from .messages import name_list
from .settings import LOCKED_TOLERANCE

__all__ = [
    "SIDE_OFFSET_M",
    "ModelLayout",
    "read_layout",
    "check_side",
    "side_dofs",
    "discover_dofs",
    "check_locked_coordinates",
    "foot_bodies",
]

#: A body is on a side when its origin lies this far (m) to that side of the root body's origin.
SIDE_OFFSET_M = 0.02
#: The ground's lateral axis in OpenSim models (z, positive to the right).
LATERAL_AXIS = 2
SIDE_NAMES = {"r": "right", "l": "left"}


def check_side(side: str, *, allow_both: bool = False) -> str:
    """Return ``side`` if it is ``r``, ``l`` (or ``both`` when allowed), else raise :class:`OptionError`."""
    ok = ("r", "l", "both") if allow_both else ("r", "l")
    if side not in ok:
        raise OptionError(f"side must be one of {', '.join(ok)}, not {side!r}")
    return side


@dataclass(frozen=True)
class ModelLayout:
    """The joint tree of a model in its default pose (see :func:`read_layout`)."""

    path: str
    gravity: tuple[float, float, float]
    ground: str
    bodies: tuple[str, ...]
    joints: tuple[dict, ...]
    coordinates: tuple[dict, ...]
    root_translations: dict

    def _root_origin(self) -> np.ndarray:
        roots = [j for j in self.joints if j["parent"] == self.ground]
        if not roots:
            raise ModelError(f"{self.path}: no joint attaches a body to the ground")
        return np.asarray(roots[0]["child_origin_m"], dtype=float)

    def body_side(self, body: str) -> str | None:
        """``"r"``, ``"l"`` or ``None`` (on the mid-line, or the ground) for a body name."""
        if body == self.ground:
            return None
        if body not in self.bodies:
            raise ModelError(
                f"{self.path}: the model has no body '{body}'; bodies: {', '.join(self.bodies)}"
            )
        child = {j["child"]: j for j in self.joints}
        if body not in child:
            return None
        offset = float(child[body]["child_origin_m"][LATERAL_AXIS] - self._root_origin()[LATERAL_AXIS])
        if offset > SIDE_OFFSET_M:
            return "r"
        if offset < -SIDE_OFFSET_M:
            return "l"
        return None

    def forward_coordinates(self) -> tuple[str, ...]:
        """Root coordinates that translate the root body horizontally (see the module docstring)."""
        g = np.asarray(self.gravity, dtype=float)
        up = -g / np.linalg.norm(g) if np.linalg.norm(g) > 0 else np.array([0.0, 1.0, 0.0])
        out = []
        for name, d in self.root_translations.items():
            d = np.asarray(d, dtype=float)
            n = float(np.linalg.norm(d))
            if n > 0.5 and abs(float(d @ up)) < 0.1 * n:
                out.append(name)
        if not out:
            raise ModelError(
                f"{self.path}: the joint attached to the ground has no horizontal translation, so the walking "
                "speed cannot be read from the kinematics; give the trial's speed"
            )
        return tuple(out)


def read_layout(model_path: str | os.PathLike, *, cache_dir: str | os.PathLike | None = None) -> ModelLayout:
    """The model's :class:`ModelLayout`, computed by OpenSim in the worker process and cached
    by the file's content (:func:`musclemetab.cache.cached_model_call`)."""
    from .cache import cached_model_call
    from .opensim_bridge import call
    from .model import check_model_path

    path = check_model_path(model_path)
    raw = cached_model_call(path, "model_ops:model_layout", cache_dir, compute=call)
    return ModelLayout(
        path=str(path),
        gravity=tuple(raw["gravity"]),
        ground=raw["ground"],
        bodies=tuple(raw["bodies"]),
        joints=tuple(raw["joints"]),
        coordinates=tuple(raw["coordinates"]),
        root_translations=dict(raw["root_translations"]),
    )


def side_dofs(layout: ModelLayout, side: str) -> list[str]:
    """Unlocked independent coordinates of the joints on ``side``, distal to proximal.

    Raises :class:`DataMismatchError` when the model has no such coordinate (e.g. no leg on
    that side).
    """
    coords = {c["name"]: c for c in layout.coordinates}
    dofs = [n for n in _side_coordinates(layout, side) if not coords[n]["locked"]]
    if not dofs:
        raise DataMismatchError(
            f"{layout.path}: the model has no unlocked joint on the {SIDE_NAMES[side]} side (side '{side}'); "
            "choose the other side or give --dofs"
        )
    return dofs


def _side_coordinates(layout: ModelLayout, side: str) -> list[str]:
    """Independent (not coupler-driven) coordinates of the joints on ``side``, locked or not,
    distal to proximal."""
    check_side(side)
    coords = {c["name"]: c for c in layout.coordinates}
    on_side = [j for j in layout.joints if j["child"] in layout.bodies and layout.body_side(j["child"]) == side]
    # stable sort: deepest joint first, model order among equals
    on_side = sorted(on_side, key=lambda j: -j["depth"])
    return [n for j in on_side for n in j["coordinates"] if n in coords and not coords[n]["dependent"]]




def check_locked_coordinates(layout: ModelLayout, side: str, ik, in_degrees: bool) -> None:
    """Refuse a motion that moves a coordinate the model locks on ``side``'s leg.

    A locked coordinate is no degree of freedom: the moment arms about it, its moment and the
    muscles that cross only its joint (a locked knee drops the vasti) would be left out of the
    geometry and the solve, and the other muscles balanced at a pose the model cannot take. Raises :class:`DataMismatchError`
    naming each coordinate of the side's joints that the model locks and that the motion
    ``ik`` (a :class:`~musclemetab.io.StorageTable`; rotations in degrees when ``in_degrees``)
    takes further than :data:`LOCKED_TOLERANCE` from the value it is locked at (its default
    value), and saying what to do. A locked coordinate the motion holds at that value (as
    OpenSim's IK of the same model writes it), or leaves out, is fine.
    """
    coords = {c["name"]: c for c in layout.coordinates}
    ik_path = ik.attrs.get("path", "the IK motion")
    moved = []
    for n in _side_coordinates(layout, side):
        c = coords[n]
        if not c["locked"] or n not in ik.columns:
            continue
        rotational = c["motion_type"] == "rotational"
        q = np.asarray(ik[n], dtype=float)
        q = np.deg2rad(q) if in_degrees and rotational else q
        held = float(c.get("default_value", 0.0))
        if float(np.max(np.abs(q - held))) > LOCKED_TOLERANCE:
            unit, scale = ("deg", math.degrees(1.0)) if rotational else ("m", 1.0)
            moved.append(f"{n} (locked at {held * scale:.4g} {unit}; the motion takes it over "
                         f"{q.min() * scale:.4g} to {q.max() * scale:.4g} {unit})")
    if moved:
        raise DataMismatchError(
            f"{ik_path}: the model {layout.path} locks {'; '.join(moved)}. A locked coordinate is no degree of "
            f"freedom, so its moment and the muscles that cross only its joint would be left out; "
            "unlock it in the model (<locked>false</locked> in its Coordinate) or give the motion computed "
            "with this model"
        )


#: Bodies of a side whose origin lies within this height (m) of the side's lowest body origin,
#: in the default pose, form the foot (:func:`foot_bodies`).
FOOT_HEIGHT_M = 0.15
#: The ground's forward axis in OpenSim models (x).
FORWARD_AXIS = 0


def foot_bodies(layout: ModelLayout, side: str) -> tuple[str, str]:
    """``(heel body, toe body)`` of a side: of the side's bodies whose origin lies, in the
    default pose, within :data:`FOOT_HEIGHT_M` of the side's lowest body origin (the foot),
    the one whose origin is furthest back and the one furthest forward (gait2392 and the
    Rajagopal family: ``calcn`` and ``toes``). Raises :class:`DataMismatchError` when the side
    has no body, and when the foot has one body only (heel and toe cannot be told apart)."""
    check_side(side)
    g = np.asarray(layout.gravity, dtype=float)
    up = -g / np.linalg.norm(g) if np.linalg.norm(g) > 0 else np.array([0.0, 1.0, 0.0])
    origin = {j["child"]: np.asarray(j["child_origin_m"], dtype=float) for j in layout.joints}
    bodies = [b for b in origin if b in layout.bodies and layout.body_side(b) == side]
    if not bodies:
        raise DataMismatchError(f"{layout.path}: the model has no body on the {SIDE_NAMES[side]} side")
    height = {b: float(origin[b] @ up) for b in bodies}
    low = min(height.values())
    foot = [b for b in bodies if height[b] <= low + FOOT_HEIGHT_M]
    heel = min(foot, key=lambda b: origin[b][FORWARD_AXIS])
    toe = max(foot, key=lambda b: origin[b][FORWARD_AXIS])
    if heel == toe:
        raise DataMismatchError(
            f"{layout.path}: the {SIDE_NAMES[side]} foot has one body ({heel}), so heel and toe cannot be told "
            "apart for gait events from kinematics; give the ground forces or --window T0:T1"
        )
    return heel, toe


def discover_dofs(layout: ModelLayout, side: str, id_columns: Iterable[str] | None = None,
                  source: str | os.PathLike | None = None) -> list[str]:
    """The side's DOFs (:func:`side_dofs`) that the inverse dynamics holds ``<dof>_moment`` for.

    The others are left out with a :class:`~musclemetab.errors.MusclemetabWarning` naming them.

    ``id_columns=None`` keeps them all (inverse dynamics computed by OpenSim holds every
    coordinate). ``source``: the inverse-dynamics file(s) the messages name.
    """
    dofs = side_dofs(layout, side)
    if id_columns is None:
        return dofs
    cols = set(id_columns)
    kept = [d for d in dofs if f"{d}_moment" in cols]
    missing = [d for d in dofs if d not in kept]
    what = f"the inverse dynamics {source}" if source is not None else "the inverse dynamics"
    if missing and kept:
        import warnings

        from .errors import MusclemetabWarning

        warnings.warn(
            f"{what} holds no moment for {name_list(missing)}: solved without "
            f"{'it' if len(missing) == 1 else 'them'} (give --dofs to choose the DOFs)", MusclemetabWarning, stacklevel=2,
        )
    if not kept:
        angles = [d for d in dofs if d in cols]  # the coordinates themselves: a kinematics file
        why = (f"; its columns are the coordinates ({name_list(angles)}), as in a kinematics file: check that --id "
               "names the inverse dynamics and --ik the kinematics") if angles else \
            "; check the side and the inverse-dynamics file"
        raise DataMismatchError(
            f"{what} holds no moment for the {SIDE_NAMES[side]} side's DOFs "
            f"({', '.join(f'{d}_moment' for d in dofs)}){why}"
        )
    return kept


def check_dofs_in_model(layout: ModelLayout, dofs: Sequence[str], where: str = "--dofs") -> None:
    """Raise :class:`UnknownCoordinateError` naming any DOF the model lacks or cannot move."""
    from .errors import UnknownCoordinateError

    coords = {c["name"]: c for c in layout.coordinates}
    missing = [d for d in dofs if d not in coords]
    if missing:
        raise UnknownCoordinateError(
            f"{where}: the model {layout.path} has no coordinate {name_list(missing)}; its unlocked coordinates: "
            f"{', '.join(n for n, c in coords.items() if not c['locked'])}"
        )
    fixed = [d for d in dofs if coords[d]["locked"] or coords[d]["dependent"]]
    if fixed:
        raise UnknownCoordinateError(
            f"{where}: coordinate {name_list(fixed)} of {layout.path} is locked or coupled and cannot be a "
            "degree of freedom; drop it"
        )
