"""Calibration of the passive fiber force-length parameters from passive joint moments.

Per muscle, the shape parameters ``kPE`` and ``s0`` of the passive curve

    fPE(l~M) = [exp(kPE (l~M - s0)/sM) - 1 - P1] / P2,
    P1 = exp(kPE (0.2 - 1)/0.6) - 1,   P2 = exp(kPE) - 1      (sM = 0.6 fixed)

(:func:`musclemetab.muscle.passive_force_length`) are chosen so that the passive joint
moments of all muscles spanning a joint reproduce in-vivo passive moment-angle targets
(Silder et al. 2007) at the ankle, knee and hip.

Each frame of each calibration trial is an independent static equilibrium (activation 0,
fiber velocity 0). For trial ``t``, frame ``k`` and muscle ``m`` (compliant tendon,
constant-thickness pennation, ``w = lMo sin(alpha0)``):

    (l~M lMo)^2 - w^2 - lM_proj^2 = 0                              (pennation)
    fPE(l~M; kPE, s0, sM) lM_proj / (l~M lMo) - fT(l~T) = 0         (equilibrium)
    l~T = (lMT - lM_proj) / lTs
    T_target,k = sum_m F0_m fT_m,k r_m,k + Topt aT_k,   Topt = 150 N m

with ``0.05 <= l~M <= 2`` (or, for a muscle the trial's geometry stretches further, its
longest rigid-tendon fiber length plus 0.05: :func:`musclemetab.muscle.longest_fiber_length_bound`),
``lM_proj >= 1e-4 m``, ``-1 <= aT <= 1``, ``3 <= kPE <= 5``,
``0.8 <= s0 <= 1.2``. The objective is ``J = sum_t sum_k aT_t,k^2``: least squares of the
passive-moment error divided by 150 N m over every frame of the three trials.

A muscle spanning two calibrated joints has one ``kPE`` and one ``s0``; muscles of one
coupling group (anatomical muscle table column ``passive_coupling_group``, P1-P10) share them.
Shared values are single NLP variables (equivalent to equality constraints between
per-trial copies).

Tendon stiffness: ``kT = 20`` for soleus and both gastrocnemii, 35 otherwise (the tendon
curve with its stiffness-dependent shift, :func:`musclemetab.muscle.tendon_force_length`).

The same NLP with the parameters imposed gives the passive moments of any parameter set
(generic ``kPE = 4, s0 = 1``, or a published set); every fit-quality figure is computed
this way, on the same geometry.
"""

from __future__ import annotations

import json
import math
import os
import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import DataMismatchError, InputFileError, MissingColumnError, OptionError, SolverError, UnknownMuscleError
from ..muscle import (
    fiber_width,
    hill_residual,
    longest_fiber_length_bound,
    passive_force_length,
    tendon_force_length,
)

__all__ = [
    "CALIBRATION_JOINTS",
    "KPE_BOUNDS",
    "S0_BOUNDS",
    "SM_FIXED",
    "KPE_GENERIC",
    "S0_GENERIC",
    "TOPT_NM",
    "CalibrationTrial",
    "CalibrationData",
    "PassiveSolution",
    "CalibrationResult",
    "trial_files",
    "calibration_dofs",
    "load_calibration_data",
    "default_tendon_stiffness",
    "parameter_groups",
    "solve_passive",
    "passive_moments",
    "equilibrium_fiber_length",
    "calibrate_passive",
    "write_calibration",
    "read_passive_parameters",
    "write_passive_parameters",
    "mirror_to_left",
]

#: Calibrated joint -> target DOF of the study's model, in the order the trials enter the NLP
#: (other models and the left side: :func:`calibration_dofs`).
CALIBRATION_JOINTS = {"ankle": "ankle_angle_r", "knee": "knee_angle_r", "hip": "hip_flexion_r"}
KPE_BOUNDS = (3.0, 5.0)
S0_BOUNDS = (0.8, 1.2)
SM_FIXED = 0.6
KPE_GENERIC = 4.0
S0_GENERIC = 1.0
TOPT_NM = 150.0
LM_NORM_BOUNDS = (0.05, 2.0)
LM_PROJ_MIN_M = 1e-4
KT_COMPLIANT = 20.0
KT_DEFAULT = 35.0
#: Tendon (column ``tendon`` of the anatomical muscle table) calibrated with ``KT_COMPLIANT``.
COMPLIANT_TENDON = "achilles"


# ------------------------------------------------------------------------------------
# Data
# ------------------------------------------------------------------------------------


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
            f"missing calibration trial file{'s' if len(missing) > 1 else ''} {', '.join(missing)}; each trial "
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
                f"the file has {', '.join(mot.columns)}"
            )
        mcol = f"{dof}_moment"
        if mcol not in sto.columns:
            raise MissingColumnError(
                f"{files[joint]['moments']}: missing column {mcol} (target passive moment, N m); "
                f"the file has {', '.join(sto.columns)}"
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
        geom = compute_geometry(model_path, files[joint]["motion"], dofs=[dof], use_cache=use_cache)
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
                f"tendon stiffness given for {', '.join(unknown)}, which no calibration trial involves; "
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


def parameter_groups(muscles: Sequence[str]) -> list[tuple[str, ...]]:
    """Muscles sharing one (kPE, s0) pair: the coupling groups P1-P10 of the anatomical
    muscle table, per side; every other muscle is its own group. Order: first appearance in
    ``muscles``."""
    from ..properties import resolve_muscles

    groups: dict[str, list[str]] = {}
    for r in resolve_muscles(muscles, warn=False):
        key = f"{r.coupling_group}_{r.side}" if r.coupling_group else r.name
        groups.setdefault(key, []).append(r.name)
    return [tuple(v) for v in groups.values()]


# ------------------------------------------------------------------------------------
# The NLP
# ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PassiveSolution:
    """Result of one passive NLP solve (calibration or imposed parameters).

    ``parameters``: muscle -> (kPE, s0, sM). ``moments_Nm``: joint -> (F,) muscle passive
    moment; ``reserve_Nm``: joint -> (F,) reserve moment (target - muscles);
    ``lm_norm``: joint -> (F, M) normalised fiber lengths; ``stats``: solver status,
    iterations, wall time.
    """

    parameters: dict
    moments_Nm: dict
    reserve_Nm: dict
    lm_norm: dict
    stats: dict

    def rms_Nm(self, data: CalibrationData) -> dict:
        """RMS of (muscle passive moment - target) per joint, N m."""
        return {t.joint: float(np.sqrt(np.mean((self.moments_Nm[t.joint] - t.target_Nm) ** 2))) for t in data.trials}

    def rms_per_block_Nm(self, data: CalibrationData) -> dict:
        out = {}
        for t in data.trials:
            e = self.moments_Nm[t.joint] - t.target_Nm
            out[t.joint] = [float(np.sqrt(np.mean(e[t.block == b] ** 2))) for b in np.unique(t.block)]
        return out


def _initial_states(lmt, lts, lmo, w, upper):
    """Rigid-tendon guess: ``l~M = (lMT - lTs)/lMo``, ``lM_proj = sqrt((lMT - lTs)^2 - w^2)``."""
    lm = np.clip((lmt - lts) / lmo, LM_NORM_BOUNDS[0] + 1e-3, upper - 1e-3)
    proj = np.sqrt(np.maximum((lm * lmo) ** 2 - w**2, (2 * LM_PROJ_MIN_M) ** 2))
    return lm, proj


def solve_passive(
    data: CalibrationData,
    parameters: Mapping[str, Sequence[float]] | None = None,
    *,
    tol: float = 1e-6,
    max_iter: int = 10000,
    print_level: int = 0,
) -> PassiveSolution:
    """Solve the passive NLP of the module docstring with CasADi ``Opti`` and IPOPT.

    With ``parameters=None`` the coupled ``kPE``, ``s0`` are free (calibration, initial
    guess 4 and 1); with ``parameters = {muscle: (kPE, s0[, sM])}`` (covering every
    muscle of the trials) they are imposed and only the equilibrium states and reserves
    are free, which gives that parameter set's passive moments. IPOPT options: exact
    Hessian, gradient-based NLP scaling, MUMPS, ``tol``, ``max_iter``.

    Raises :class:`SolverError` if IPOPT does not converge.
    """
    import casadi as ca

    opti = ca.Opti()
    free = parameters is None
    if free:
        groups = parameter_groups(data.muscles)
        kpe_g = opti.variable(len(groups))
        s0_g = opti.variable(len(groups))
        opti.subject_to(opti.bounded(KPE_BOUNDS[0], kpe_g, KPE_BOUNDS[1]))
        opti.subject_to(opti.bounded(S0_BOUNDS[0], s0_g, S0_BOUNDS[1]))
        opti.set_initial(kpe_g, KPE_GENERIC)
        opti.set_initial(s0_g, S0_GENERIC)
        gidx = {m: i for i, g in enumerate(groups) for m in g}
        kpe_of = {m: kpe_g[gidx[m]] for m in data.muscles}
        s0_of = {m: s0_g[gidx[m]] for m in data.muscles}
        sm_of = {m: SM_FIXED for m in data.muscles}
    else:
        missing = [m for m in data.muscles if m not in parameters]
        if missing:
            raise UnknownMuscleError(
                f"no passive parameters for {', '.join(missing)}; the calibration trials involve these muscles"
            )
        kpe_of = {m: float(parameters[m][0]) for m in data.muscles}
        s0_of = {m: float(parameters[m][1]) for m in data.muscles}
        sm_of = {m: float(parameters[m][2]) if len(parameters[m]) > 2 else SM_FIXED for m in data.muscles}

    objective = 0
    handles = []
    for t in data.trials:
        idx = data.index(t.muscles)
        F, M = t.lmt_m.shape
        F0 = data.max_isometric_force_N[idx]
        lmo = data.optimal_fiber_length_m[idx]
        lts = data.tendon_slack_length_m[idx]
        w = np.asarray(fiber_width(lmo, data.pennation_angle_at_optimal_rad[idx]))
        kT = data.tendon_stiffness[idx]
        lm = opti.variable(F, M)
        proj = opti.variable(F, M)
        aT = opti.variable(F)
        upper = longest_fiber_length_bound(t.lmt_m, lts, lmo, w, LM_NORM_BOUNDS[1])
        opti.subject_to(opti.bounded(LM_NORM_BOUNDS[0], ca.vec(lm), ca.vec(ca.DM(np.tile(upper, (F, 1))))))
        opti.subject_to(ca.vec(proj) >= LM_PROJ_MIN_M)
        if free:  # with imposed parameters the reserve is the moment error, unbounded
            opti.subject_to(opti.bounded(-1, aT, 1))
        lm0, proj0 = _initial_states(t.lmt_m, lts, lmo, w, upper)
        opti.set_initial(lm, lm0)
        opti.set_initial(proj, proj0)
        opti.set_initial(aT, 0)
        # per-muscle column expressions; parameters broadcast over frames
        kpe_row = ca.horzcat(*[kpe_of[m] for m in t.muscles])
        s0_row = ca.horzcat(*[s0_of[m] for m in t.muscles])
        sm_row = ca.DM(np.array([[sm_of[m] for m in t.muscles]]))
        ones = ca.DM.ones(F, 1)
        kpe_mat = ca.mtimes(ones, kpe_row)
        s0_mat = ca.mtimes(ones, s0_row)
        sm_mat = ca.mtimes(ones, sm_row)
        lmo_mat = ca.DM(np.tile(lmo, (F, 1)))
        lm_m = lm * lmo_mat
        opti.subject_to(ca.vec(lm_m**2 - ca.DM(np.tile(w**2, (F, 1))) - proj**2) == 0)
        lts_mat, kt_mat, lmt = ca.DM(np.tile(lts, (F, 1))), ca.DM(np.tile(kT, (F, 1))), ca.DM(t.lmt_m)
        # the Hill equilibrium of the redundancy problem at rest (activation 0, fiber velocity 0)
        opti.subject_to(ca.vec(hill_residual(0.0, lm, 0.0, proj, lmt, optimal_fiber_length_m=lmo_mat,
                                             tendon_slack_length_m=lts_mat, max_contraction_velocity=1.0,
                                             kT=kt_mat, kpe=kpe_mat, s0=s0_mat, sm=sm_mat)) == 0)
        fT = tendon_force_length((lmt - proj) / lts_mat, kt_mat)
        moment = ca.sum2(fT * ca.DM(np.tile(F0, (F, 1))) * ca.DM(t.moment_arms_m))
        opti.subject_to(moment + TOPT_NM * aT == ca.DM(t.target_Nm))
        objective = objective + ca.sumsqr(aT)
        handles.append((t, lm, aT, moment))
    opti.minimize(objective)
    opti.solver(
        "ipopt",
        {"print_time": False},
        {
            "hessian_approximation": "exact",
            "nlp_scaling_method": "gradient-based",
            "linear_solver": "mumps",
            "tol": tol,
            "max_iter": max_iter,
            "print_level": print_level,
            "sb": "yes",  # no banner
        },
    )
    t0 = _time.perf_counter()
    try:
        sol = opti.solve()
        value = sol.value
        stats = dict(sol.stats())
    except RuntimeError as exc:
        stats = dict(opti.stats())
        raise SolverError(
            f"the passive {'calibration' if free else 'equilibrium'} NLP did not converge "
            f"(IPOPT: {stats.get('return_status', exc)}); check the trials and the model"
        ) from None
    wall = _time.perf_counter() - t0

    if free:
        kv = np.atleast_1d(np.asarray(value(kpe_g), dtype=float)).ravel()
        sv = np.atleast_1d(np.asarray(value(s0_g), dtype=float)).ravel()
        params = {m: (float(kv[gidx[m]]), float(sv[gidx[m]]), SM_FIXED) for m in data.muscles}
    else:
        params = {m: (kpe_of[m], s0_of[m], sm_of[m]) for m in data.muscles}
    moments, reserves, lms = {}, {}, {}
    for t, lm, aT, moment in handles:
        moments[t.joint] = np.asarray(value(moment), dtype=float).reshape(-1)
        reserves[t.joint] = TOPT_NM * np.asarray(value(aT), dtype=float).reshape(-1)
        lms[t.joint] = np.asarray(value(lm), dtype=float).reshape(t.lmt_m.shape)
    info = {
        "return_status": stats.get("return_status"),
        "success": bool(stats.get("success")),
        "iterations": int(stats.get("iter_count", -1)),
        "wall_time_s": round(wall, 3),
        "objective": float(value(objective)),
    }
    return PassiveSolution(params, moments, reserves, lms, info)


def passive_moments(data: CalibrationData, parameters: Mapping[str, Sequence[float]]) -> PassiveSolution:
    """Passive moments of an imposed parameter set (``{muscle: (kPE, s0[, sM])}``)."""
    return solve_passive(data, parameters)


def equilibrium_fiber_length(
    lmt_m: float,
    *,
    optimal_fiber_length_m: float,
    tendon_slack_length_m: float,
    pennation_angle_at_optimal_rad: float,
    kpe: float = KPE_GENERIC,
    s0: float = S0_GENERIC,
    sm: float = SM_FIXED,
    kT: float = KT_DEFAULT,
) -> tuple[float, float]:
    """Passive static equilibrium of one muscle by root finding (NumPy/SciPy, no NLP).

    Solves ``fPE(l~M) cos(alpha) = fT(l~T)`` for ``l~M`` with
    ``cos(alpha) = sqrt(lM^2 - w^2)/lM`` and ``l~T = (lMT - sqrt(lM^2 - w^2))/lTs``.
    Returns ``(l~M, fT)`` (normalised tendon force). Independent of :func:`solve_passive`;
    used to check it.
    """
    from scipy.optimize import brentq

    lmo, lts = optimal_fiber_length_m, tendon_slack_length_m
    w = lmo * math.sin(pennation_angle_at_optimal_rad)

    def residual(lm):
        proj = math.sqrt(max((lm * lmo) ** 2 - w**2, 1e-16))
        return float(passive_force_length(lm, kpe, s0, sm)) * proj / (lm * lmo) - float(
            tendon_force_length((lmt_m - proj) / lts, kT)
        )

    lo = max(LM_NORM_BOUNDS[0], w / lmo + 1e-9)
    lm = brentq(residual, lo, 3.0, xtol=1e-14)  # beyond any bound of the NLP
    proj = math.sqrt((lm * lmo) ** 2 - w**2)
    return lm, float(tendon_force_length((lmt_m - proj) / lts, kT))


# ------------------------------------------------------------------------------------
# Workflow and files
# ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CalibrationResult:
    data: CalibrationData
    calibrated: PassiveSolution
    generic: PassiveSolution

    def fit_summary(self) -> dict:
        d = self.data
        at_bound = {}
        for m, (k, s, _) in self.calibrated.parameters.items():
            flags = []
            if k - KPE_BOUNDS[0] < 0.01:
                flags.append("kPE lower")
            if KPE_BOUNDS[1] - k < 0.01:
                flags.append("kPE upper")
            if s - S0_BOUNDS[0] < 0.01:
                flags.append("s0 lower")
            if S0_BOUNDS[1] - s < 0.01:
                flags.append("s0 upper")
            at_bound[m] = flags
        return {
            "units": "N m",
            "rms_generic_Nm": self.generic.rms_Nm(d),
            "rms_calibrated_Nm": self.calibrated.rms_Nm(d),
            "rms_per_block_generic_Nm": self.generic.rms_per_block_Nm(d),
            "rms_per_block_calibrated_Nm": self.calibrated.rms_per_block_Nm(d),
            "max_abs_reserve_generic_Nm": {j: float(np.abs(r).max()) for j, r in self.generic.reserve_Nm.items()},
            "max_abs_reserve_calibrated_Nm": {
                j: float(np.abs(r).max()) for j, r in self.calibrated.reserve_Nm.items()
            },
            "solver": {"calibrated": self.calibrated.stats, "generic": self.generic.stats},
            "parameters_at_bound": at_bound,
            "bounds": {"kPE": list(KPE_BOUNDS), "s0": list(S0_BOUNDS), "sM": SM_FIXED},
            "tendon_stiffness": {m: float(k) for m, k in zip(d.muscles, d.tendon_stiffness)},
            "muscles_per_trial": {t.joint: list(t.muscles) for t in d.trials},
            "source": d.source,
        }


def calibrate_passive(
    model_path: str | os.PathLike,
    trials: str | os.PathLike | Mapping,
    *,
    tendon_stiffness: Mapping[str, float] | None = None,
    use_cache: bool = True,
    print_level: int = 0,
    side: str = "r",
) -> CalibrationResult:
    """Load the trials, solve the calibration NLP and the generic-parameter reference (``side``: see
    :func:`load_calibration_data`)."""
    data = load_calibration_data(model_path, trials, tendon_stiffness=tendon_stiffness, use_cache=use_cache,
                                 side=side)
    generic = solve_passive(data, {m: (KPE_GENERIC, S0_GENERIC, SM_FIXED) for m in data.muscles})
    calibrated = solve_passive(data, None, print_level=print_level)
    return CalibrationResult(data, calibrated, generic)


def _parameters_csv(parameters: Mapping[str, Sequence[float]]) -> str:
    lines = ["muscle,kPE,s0,sM"]
    for m, p in parameters.items():
        k, s = float(p[0]), float(p[1])
        sm = float(p[2]) if len(p) > 2 else SM_FIXED
        lines.append(f"{m},{k:.10g},{s:.10g},{sm:.10g}")
    return "\n".join(lines) + "\n"


def write_passive_parameters(path: str | os.PathLike, parameters: Mapping[str, Sequence[float]]) -> Path:
    """Write ``muscle,kPE,s0,sM`` (one row per muscle, names with side suffix), atomically."""
    from ..io import atomic_write_text

    return atomic_write_text(path, _parameters_csv(parameters))


def _plot(result: CalibrationResult, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    trials = result.data.trials
    ncol = max(len(np.unique(t.block)) for t in trials)
    fig, axes = plt.subplots(len(trials), ncol, figsize=(4 * ncol, 3.2 * len(trials)), squeeze=False)
    for r, t in enumerate(trials):
        q = np.degrees(t.target_angle_rad)
        blocks = np.unique(t.block)
        for c in range(ncol):
            ax = axes[r, c]
            if c >= len(blocks):
                ax.axis("off")
                continue
            sel = t.block == blocks[c]
            ax.plot(q[sel], t.target_Nm[sel], "k-", lw=2, label="target")
            ax.plot(q[sel], result.generic.moments_Nm[t.joint][sel], "C0--", label="generic")
            ax.plot(q[sel], result.calibrated.moments_Nm[t.joint][sel], "C3-", label="calibrated")
            fixed = [
                f"{n.replace('_r', '').replace('_angle', '').replace('_flexion', '')} "
                f"{float(np.round(np.degrees(t.angles_rad[sel][0, i]))) + 0.0:.0f}°"
                for i, n in enumerate(t.angle_names) if n != t.dof
            ]
            ax.set_title(f"{t.joint} block {c + 1} ({', '.join(fixed)})", fontsize=9)
            ax.set_xlabel(f"{t.dof} (deg)")
            ax.set_ylabel("passive moment (N m)")
            ax.grid(alpha=0.3)
            if r == 0 and c == 0:
                ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_calibration(result: CalibrationResult, out_dir: str | os.PathLike) -> dict:
    """Write ``passive_parameters.csv``, ``fit.json`` and ``passive_fit.png`` atomically."""
    from ..io import atomic_directory

    out_dir = Path(out_dir)
    with atomic_directory(out_dir) as tmp:
        (tmp / "passive_parameters.csv").write_text(_parameters_csv(result.calibrated.parameters), encoding="utf-8")
        (tmp / "fit.json").write_text(json.dumps(result.fit_summary(), indent=2) + "\n", encoding="utf-8")
        _plot(result, tmp / "passive_fit.png")
    return {k: out_dir / k for k in ("passive_parameters.csv", "fit.json", "passive_fit.png")}


def read_passive_parameters(path: str | os.PathLike) -> dict:
    """Passive force-length parameters ``{muscle: (kPE, s0, sM)}`` from a file.

    Accepts the ``passive_parameters.csv`` written by :func:`write_calibration` (columns
    ``muscle,kPE,s0,sM``) or the reference implementation's ``passiveMoments.mat``
    (calibrated values of ``sim.Results.onlyParam``; ``sM = 0.6``). Parsing is done by
    :func:`musclemetab.passive.read_passive_parameters` (the reader the
    muscle redundancy solver uses); entries with non-finite values (the MAT file's left
    leg) are left out. Use :func:`mirror_to_left` to copy right-leg values to the left leg.
    """
    from ..passive import read_passive_parameters as _read

    values = _read(path).values
    return {
        str(m): (float(v[0]), float(v[1]), float(v[2]))
        for m, v in values.items()
        if all(math.isfinite(float(x)) for x in v)
    }


def mirror_to_left(parameters: Mapping[str, Sequence[float]]) -> dict:
    """Copy every ``*_r`` entry to ``*_l`` (symmetry), keeping existing ``*_l`` entries."""
    out = dict(parameters)
    for m, p in parameters.items():
        if m.endswith("_r"):
            out.setdefault(m[:-2] + "_l", tuple(p))
    return out
