"""Calibration trials: passive moment-angle files and the model's geometry at their poses, as arrays.

A calibration trial is a set of static poses (a ``.mot`` of joint angles, degrees unless
the header says ``inDegrees=no``) with a target passive moment about one joint per pose (a
``.sto`` with a ``<coordinate>_moment`` column, N m). :func:`load_calibration_data` reads
the ankle, knee and hip trials of one leg, checks them against the model (columns, time
stamps, the model's coordinate ranges and sign conventions), computes the muscle-tendon
lengths and moment arms at every pose with OpenSim (:func:`musclemetab.geometry.compute_geometry`)
and reads the Hill parameters of the muscles involved: :class:`CalibrationData`, the input of
the calibration problem (:mod:`.problem`).

The target DOFs are the side's hip, knee and ankle flexion coordinates, found in the model's
joint tree (:func:`calibration_dofs`); the trials of a folder are recognised by the
coordinate whose target moment they hold (:func:`trial_files`). The tendon stiffness of the
calibration is ``kT = 20`` for the triceps surae (Achilles tendon in the anatomical muscle
table) and 35 otherwise (:func:`default_tendon_stiffness`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import DataMismatchError, InputFileError, MissingColumnError, OptionError, UnknownMuscleError
from ..messages import name_list

__all__ = [
    "CALIBRATION_JOINTS",
    "KT_COMPLIANT",
    "KT_DEFAULT",
    "CalibrationTrial",
    "CalibrationData",
    "calibration_dofs",
    "trial_files",
    "default_tendon_stiffness",
    "load_calibration_data",
]

#: Calibrated joint -> target DOF of the study's model, in the order the trials enter the NLP
#: (other models and the left side: :func:`calibration_dofs`).
CALIBRATION_JOINTS = {"ankle": "ankle_angle_r", "knee": "knee_angle_r", "hip": "hip_flexion_r"}
KT_COMPLIANT = 20.0
KT_DEFAULT = 35.0
#: Tendon (column ``tendon`` of the anatomical muscle table) calibrated with ``KT_COMPLIANT``.
COMPLIANT_TENDON = "achilles"


@dataclass(frozen=True)
class CalibrationTrial:
    """One calibration trial: a set of static poses with a target passive moment.

    Attributes
    ----------
    joint : 'ankle', 'knee' or 'hip'
    dof : target DOF (e.g. ``ankle_angle_r``)
    angles_rad : (F, J) all joint angles of the motion file, rad (columns ``angle_names``)
    angle_names : names of the angle columns
    target_Nm : (F,) target passive moment about ``dof``, N m
    block : (F,) block index (0, 1, ...) of each frame; a block sweeps ``dof`` with the
        other joints fixed
    muscles : muscles spanning ``dof``
    lmt_m : (F, M) muscle-tendon lengths, m
    moment_arms_m : (F, M) moment arms about ``dof``, m
    """

    joint: str
    dof: str
    angles_rad: np.ndarray
    angle_names: tuple[str, ...]
    target_Nm: np.ndarray
    block: np.ndarray
    muscles: tuple[str, ...]
    lmt_m: np.ndarray
    moment_arms_m: np.ndarray

    @property
    def n_frames(self) -> int:
        return int(self.target_Nm.shape[0])

    @property
    def target_angle_rad(self) -> np.ndarray:
        return self.angles_rad[:, self.angle_names.index(self.dof)]


@dataclass(frozen=True)
class CalibrationData:
    """The calibration trials plus the Hill parameters of every muscle they involve."""

    trials: tuple[CalibrationTrial, ...]
    muscles: tuple[str, ...]  # union, model order as first met
    max_isometric_force_N: np.ndarray
    optimal_fiber_length_m: np.ndarray
    tendon_slack_length_m: np.ndarray
    pennation_angle_at_optimal_rad: np.ndarray
    tendon_stiffness: np.ndarray
    source: dict = field(default_factory=dict, compare=False)

    def index(self, names: Sequence[str]) -> np.ndarray:
        pos = {n: i for i, n in enumerate(self.muscles)}
        return np.array([pos[n] for n in names], dtype=int)


def calibration_dofs(model_path: str | os.PathLike, side: str = "r") -> dict:
    """``{"ankle": dof, "knee": dof, "hip": dof}``: the side's flexion coordinates, from the joint tree.

    Rule (no names involved): the hip is the joint on ``side`` whose parent is the body the
    ground joint moves (the pelvis); the knee is the joint with an unlocked independent
    coordinate whose parent is the hip's child; the ankle likewise from the knee's child. Each
    joint's flexion coordinate is its first unlocked independent coordinate (OpenSim's
    lower-limb models list flexion first). For the study's model: ``hip_flexion_r``,
    ``knee_angle_r``, ``ankle_angle_r``.
    """
    from ..layout import SIDE_NAMES, check_side, read_layout

    check_side(side)
    layout = read_layout(model_path)
    coords = {c["name"]: c for c in layout.coordinates}

    def free(j):
        return [n for n in j["coordinates"] if n in coords and not coords[n]["locked"] and not coords[n]["dependent"]]

    root = next((j["child"] for j in layout.joints if j["parent"] == layout.ground), None)
    parent, out = root, {}
    for joint in ("hip", "knee", "ankle"):
        nxt = [j for j in layout.joints if j["parent"] == parent and free(j)
               and layout.body_side(j["child"]) == side]
        if not nxt:
            raise DataMismatchError(
                f"{model_path}: no {joint} joint with a free coordinate on the {SIDE_NAMES[side]} side (after "
                f"{', '.join(out.values()) or 'the pelvis'}); the passive calibration needs hip, knee and ankle "
                "flexion coordinates"
            )
        out[joint] = free(nxt[0])[0]
        parent = nxt[0]["child"]
    return {j: out[j] for j in ("ankle", "knee", "hip")}


def trial_files(trials: str | os.PathLike | Mapping, dofs: Mapping[str, str] | None = None) -> dict:
    """``{joint: {'motion': Path, 'moments': Path}}`` from a folder or a mapping.

    ``dofs``: ``{joint: coordinate}`` (default :data:`CALIBRATION_JOINTS`, the study's right
    leg). A mapping may be keyed by joint (``"ankle"``) or by coordinate name. In a folder a
    trial is a ``.sto`` of target passive moments with a ``.mot`` of the same stem beside it;
    it belongs to the coordinate whose ``<coordinate>_moment`` column is its only calibration
    column that is not zero throughout (the in-vivo trials sweep one joint at a time). File
    names do not matter.
    """
    dofs = dict(dofs or CALIBRATION_JOINTS)
    if isinstance(trials, Mapping):
        out = {}
        for joint, dof in dofs.items():
            entry = trials.get(joint, trials.get(dof))
            if entry is None:
                raise OptionError(
                    f"calibration trials lack the {joint} trial ({dof}); give motion and moments files for "
                    f"{', '.join(dofs.values())}"
                )
            out[joint] = {"motion": Path(entry["motion"]), "moments": Path(entry["moments"])}
    else:
        folder = Path(trials)
        if not folder.is_dir():
            raise InputFileError(f"{folder}: no such folder of calibration trials; check --trials")
        out = _find_trials(folder, dofs)
    missing = [str(p) for j in out.values() for p in j.values() if not p.is_file()]
    if missing:
        raise InputFileError(
            f"missing calibration trial file{'s' if len(missing) > 1 else ''} {name_list(missing)}; each trial "
            "is a .mot of joint angles (deg) and a .sto of target passive moments (N m)"
        )
    return out


def _find_trials(folder: Path, dofs: Mapping[str, str]) -> dict:
    from ..io import read_storage

    cols = {f"{d}_moment": j for j, d in dofs.items()}
    found: dict = {}
    for sto in sorted(folder.glob("*.sto")):
        mot = sto.with_suffix(".mot")
        if not mot.is_file():
            continue
        try:
            table = read_storage(sto)
        except Exception:
            continue
        live = [c for c in cols if c in table.columns and np.any(table[c].to_numpy(dtype=float) != 0.0)]
        if len(live) == 1:
            found.setdefault(cols[live[0]], []).append(sto)
    out = {}
    for joint, dof in dofs.items():
        hits = found.get(joint, [])
        if len(hits) != 1:
            what = "no" if not hits else f"{len(hits)} ({', '.join(p.name for p in hits)})"
            raise InputFileError(
                f"{folder}: {what} calibration trial for {dof}; the folder needs one .sto of target passive "
                f"moments whose only non-zero moment column is {dof}_moment, with the .mot of the same name"
            )
        out[joint] = {"motion": hits[0].with_suffix(".mot"), "moments": hits[0]}
    return out


def _blocks(angles: np.ndarray, target_col: int) -> np.ndarray:
    """Block index per frame: a new block starts where any non-target joint angle changes
    or the target angle stops increasing."""
    n = angles.shape[0]
    block = np.zeros(n, dtype=int)
    others = [c for c in range(angles.shape[1]) if c != target_col]
    for k in range(1, n):
        new = np.diff(angles[k - 1:k + 1, target_col])[0] <= 0 or (
            others and np.any(np.abs(angles[k, others] - angles[k - 1, others]) > 1e-9)
        )
        block[k] = block[k - 1] + (1 if new else 0)
    return block


def default_tendon_stiffness(muscles: Sequence[str]) -> np.ndarray:
    """``kT`` per muscle for the calibration: 20 for the triceps surae (Achilles tendon in the
    anatomical muscle table), else 35."""
    from ..properties import resolve_muscles

    return np.array([KT_COMPLIANT if r.tendon == COMPLIANT_TENDON else KT_DEFAULT
                     for r in resolve_muscles(muscles, warn=False)])


def load_calibration_data(
    model_path: str | os.PathLike,
    trials: str | os.PathLike | Mapping,
    *,
    tendon_stiffness: Mapping[str, float] | None = None,
    use_cache: bool = True,
    side: str = "r",
) -> CalibrationData:
    """Read the three trials, compute their geometry with OpenSim, read the Hill parameters.

    Muscles per trial: those whose moment arm about the trial's DOF exceeds 1e-4 m at the
    first frame (:func:`musclemetab.geometry.compute_geometry`). Angles in the ``.mot``
    files are degrees (OpenSim's convention when the header has no ``inDegrees``).

    ``tendon_stiffness`` overrides ``kT`` for some muscles (default
    :func:`default_tendon_stiffness`). ``side`` (``"r"``/``"l"``): the target DOFs are that
    side's flexion coordinates of the model (:func:`calibration_dofs`; for the study's model
    and the right side, :data:`CALIBRATION_JOINTS`).
    """
    from ..geometry import compute_geometry
    from ..io import read_storage
    from ..model import read_muscle_parameters

    from ..model import read_model

    joints = calibration_dofs(model_path, side)
    files = trial_files(trials, joints)
    ranges = {c["name"]: c["range"] for c in read_model(model_path).coordinates
              if c.get("motion_type") == "rotational"}
    out = []
    for joint, dof in joints.items():
        mot = read_storage(files[joint]["motion"])
        sto = read_storage(files[joint]["moments"])
        _check_angle_ranges(mot, files[joint]["motion"], ranges, model_path)
        if dof not in mot.columns:
            raise MissingColumnError(
                f"{files[joint]['motion']}: missing column {dof} (the {joint} trial's target DOF); "
                f"the file has {name_list(mot.columns)}"
            )
        mcol = f"{dof}_moment"
        if mcol not in sto.columns:
            raise MissingColumnError(
                f"{files[joint]['moments']}: missing column {mcol} (target passive moment, N m); "
                f"the file has {name_list(sto.columns)}"
            )
        if len(mot) != len(sto) or not np.allclose(mot.index.to_numpy(), sto.index.to_numpy(), atol=1e-6):
            raise DataMismatchError(
                f"{files[joint]['motion']} ({len(mot)} rows) and {files[joint]['moments']} ({len(sto)} rows) "
                "must have the same time column, one target moment per pose"
            )
        in_deg = mot.attrs.get("in_degrees")
        scale = math.pi / 180.0 if (in_deg is None or in_deg) else 1.0
        names = tuple(mot.columns)
        angles = mot.to_numpy(dtype=float) * scale
        geom = compute_geometry(model_path, files[joint]["motion"], dofs=[dof], side=side, use_cache=use_cache)
        if geom.lmt_m.shape[0] != len(mot):
            raise DataMismatchError(f"geometry of {files[joint]['motion']} has {geom.lmt_m.shape[0]} frames, not {len(mot)}")
        out.append(
            CalibrationTrial(
                joint=joint,
                dof=dof,
                angles_rad=angles,
                angle_names=names,
                target_Nm=sto[mcol].to_numpy(dtype=float),
                block=_blocks(angles, names.index(dof)),
                muscles=tuple(geom.muscles),
                lmt_m=np.asarray(geom.lmt_m, dtype=float),
                moment_arms_m=np.asarray(geom.moment_arm(dof), dtype=float),
            )
        )
    union: list[str] = []
    for t in out:
        union += [m for m in t.muscles if m not in union]
    mp = read_muscle_parameters(model_path).subset(union)
    kT = default_tendon_stiffness(union)
    if tendon_stiffness:
        unknown = [m for m in tendon_stiffness if m not in union]
        if unknown:
            raise UnknownMuscleError(
                f"tendon stiffness given for {name_list(unknown)}, which no calibration trial involves; "
                f"the trials involve {', '.join(union[:6])} ..."
            )
        for m, v in tendon_stiffness.items():
            kT[union.index(m)] = float(v)
    return CalibrationData(
        trials=tuple(out),
        muscles=tuple(union),
        max_isometric_force_N=np.asarray(mp.max_isometric_force_N, dtype=float),
        optimal_fiber_length_m=np.asarray(mp.optimal_fiber_length_m, dtype=float),
        tendon_slack_length_m=np.asarray(mp.tendon_slack_length_m, dtype=float),
        pennation_angle_at_optimal_rad=np.asarray(mp.pennation_angle_at_optimal_rad, dtype=float),
        tendon_stiffness=kT,
        source={"model": str(model_path), "trials": {j: {k: str(v) for k, v in f.items()} for j, f in files.items()}},
    )


#: Slack (deg) of :func:`_check_angle_ranges` beyond a coordinate's range in the model.
RANGE_SLACK_DEG = 5.0


def _check_angle_ranges(mot, path, ranges: Mapping[str, Sequence[float]], model_path) -> None:
    """Refuse a trial whose joint angles lie outside the model's coordinate ranges.

    In-vivo passive trials are defined anatomically (knee flexed 60 degrees); models differ
    in sign conventions (knee flexion is positive in the Rajagopal family, negative in
    gait2392), and a trial in the other convention would put the joint far outside its
    range, where muscle geometry and passive forces mean nothing (IPOPT then reports an
    infeasible problem). Angles are degrees unless the header says ``inDegrees=no``.
    """
    in_deg = mot.attrs.get("in_degrees")
    to_deg = 1.0 if (in_deg is None or in_deg) else 180.0 / math.pi
    for col in mot.columns:
        if col not in ranges:
            continue
        lo, hi = (math.degrees(float(x)) for x in ranges[col])
        q = mot[col].to_numpy(dtype=float) * to_deg
        if q.min() >= lo - RANGE_SLACK_DEG and q.max() <= hi + RANGE_SLACK_DEG:
            continue
        flipped = (-q.max() >= lo - RANGE_SLACK_DEG) and (-q.min() <= hi + RANGE_SLACK_DEG)
        advice = (
            f"the trial seems to use the opposite sign convention for {col}: negate the {col} column of every "
            f"trial's .mot and the {col}_moment column of the target moments (.sto)"
            if flipped else f"give {col} in this model's convention and units"
        )
        raise DataMismatchError(
            f"{path}: column {col} spans {q.min():.0f} to {q.max():.0f} deg, outside the range of {col} in "
            f"{model_path} ({lo:.0f} to {hi:.0f} deg); {advice}"
        )
