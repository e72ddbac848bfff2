"""Input preparation for the muscle redundancy problem.

From inverse kinematics (IK), inverse dynamics (ID) and muscle geometry (muscle-tendon
lengths and moment arms at the IK frames) this module builds the data the optimal control
problem needs on its mesh:

1. **Time window** = the IK file, ``[t_first, t_last]``.
2. **Filtering**: 6th-order, 6 Hz low-pass Butterworth applied forward and backward
   (zero phase), with the padding of MATLAB's ``filtfilt`` (odd reflection of
   ``3 (max(len(a), len(b)) - 1) = 18`` samples). Muscle-tendon lengths and moment arms
   are filtered at the IK frames; the ID moments are filtered **on the full ID file**,
   then linearly interpolated onto the IK time stamps.
3. **Mesh**: ``N = round((tf - t0) * 100)`` intervals, ``h = (tf - t0)/N``,
   ``t_k = t0 + k h``. Lengths, moment arms and moments are evaluated at the nodes with
   not-a-knot cubic splines through the filtered frames.

Layouts are time-first: ``(frames, muscles)``, ``(frames, dofs, muscles)``,
``(frames, dofs)``. Moment arms follow OpenSim, ``r = -dlMT/dq``.

Reference: De Groote F, Kinney AL, Rao AV, Fregly BJ (2016) Ann Biomed Eng 44:2922-2936;
Luis I, Afschrift M, De Groote F, Gutierrez-Farewik EM (2024) PLoS Comput Biol.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, Sequence

import numpy as np

if TYPE_CHECKING:
    from ..io import StorageTable

from ..errors import DataMismatchError, InputFileError, MissingColumnError

# SciPy (filter, splines) is imported inside the functions that use it, so that importing the
# solver stays cheap; the files are read into NumPy arrays (musclemetab.io.read_table).

__all__ = [
    "DEFAULT_DOFS",
    "MESH_FREQUENCY_HZ",
    "FILTER_CUTOFF_HZ",
    "FILTER_ORDER",
    "MUSCLE_SELECTION_THRESHOLD_M",
    "GeometryLike",
    "GeometryArrays",
    "restrict_geometry",
    "check_id_coordinates",
    "TrialInputs",
    "lowpass_filtfilt",
    "mesh_for_window",
    "read_kinematics",
    "read_inverse_dynamics",
    "select_muscles",
    "trial_inputs",
    "check_moment_magnitudes",
    "check_moments_per_body_mass",
    "MIN_PEAK_MOMENT_NM_PER_KG",
    "check_time_ranges",
]

#: The five right-leg degrees of freedom of the study, in the order of the moment arms.
DEFAULT_DOFS = (
    "ankle_angle_r",
    "knee_angle_r",
    "hip_flexion_r",
    "hip_adduction_r",
    "hip_rotation_r",
)
MESH_FREQUENCY_HZ = 100.0
FILTER_CUTOFF_HZ = 6.0
FILTER_ORDER = 6
#: A muscle is kept if ``|r| > 1e-4 m`` about a DOF at the first frame.
MUSCLE_SELECTION_THRESHOLD_M = 1e-4
#: The largest joint moment of a walking trial, per kilogram of the model's body mass, is
#: about 1-1.7 N m/kg (ankle plantarflexion; hip and knee near 1); below this value the
#: moments are normalised to body mass (N m/kg), which gives a peak near 0.02 "N m/kg".
MIN_PEAK_MOMENT_NM_PER_KG = 0.2


class GeometryLike(Protocol):
    """What the solver needs from a muscle-geometry source (e.g. ``musclemetab.geometry``)."""

    time: np.ndarray  # (F,) s, the IK frames
    muscles: Sequence[str]  # (M,)
    dofs: Sequence[str]  # (D,)
    lmt_m: np.ndarray  # (F, M) muscle-tendon length
    moment_arms_m: np.ndarray  # (F, D, M), r = -dlMT/dq


@dataclass(frozen=True)
class TrialInputs:
    """Filtered trial data at the IK frames and on the optimisation mesh.

    Attributes
    ----------
    muscles, dofs
        Names, in the order of the array axes.
    frame_time_s
        ``(F,)`` IK frame times (the window is ``frame_time_s[[0, -1]]``).
    lmt_frames_m, lmt_velocity_frames_m_per_s
        ``(F, M)`` filtered muscle-tendon length and its time derivative (analytic
        derivative of the not-a-knot spline), used by the static optimisation.
    moment_arms_frames_m
        ``(F, D, M)`` filtered moment arms.
    moments_frames_Nm
        ``(F, D)`` filtered ID moments at the IK frames.
    mesh_time_s
        ``(N+1,)`` nodes ``t_k = t0 + k h``.
    lmt_m, moment_arms_m, moments_Nm
        The same quantities at the mesh nodes: ``(N+1, M)``, ``(N+1, D, M)``, ``(N+1, D)``.
    sources
        Paths or labels of the inputs, for the record.
    """

    muscles: tuple[str, ...]
    dofs: tuple[str, ...]
    frame_time_s: np.ndarray
    lmt_frames_m: np.ndarray
    lmt_velocity_frames_m_per_s: np.ndarray
    moment_arms_frames_m: np.ndarray
    moments_frames_Nm: np.ndarray
    mesh_time_s: np.ndarray
    lmt_m: np.ndarray
    moment_arms_m: np.ndarray
    moments_Nm: np.ndarray
    sources: dict

    @property
    def n_intervals(self) -> int:
        """``N``, the number of mesh intervals."""
        return self.mesh_time_s.size - 1

    @property
    def step_s(self) -> float:
        """``h = (tf - t0)/N``."""
        return float(self.mesh_time_s[-1] - self.mesh_time_s[0]) / self.n_intervals

    @property
    def window_s(self) -> tuple[float, float]:
        return float(self.mesh_time_s[0]), float(self.mesh_time_s[-1])


def lowpass_filtfilt(
    x: np.ndarray,
    sample_rate_hz: float,
    cutoff_hz: float = FILTER_CUTOFF_HZ,
    order: int = FILTER_ORDER,
    what: str = "a signal",
) -> np.ndarray:
    """Zero-phase Butterworth low-pass along axis 0, padded like MATLAB's ``filtfilt``.

    The filter is designed with ``butter(order, cutoff/(fs/2))`` and applied forward and
    backward, so the magnitude response is that of a ``2*order`` filter. MATLAB pads both
    ends with an odd reflection of ``3 (max(len(a), len(b)) - 1)`` samples (18 for order 6)
    and starts from steady-state initial conditions; SciPy's ``filtfilt`` does the same with
    ``padtype='odd'`` and that ``padlen`` (SciPy's default would be 21).

    Raises :class:`DataMismatchError` if the signal has no more samples than the padding or
    is sampled at no more than twice the cut-off; its message starts with ``what`` (the file
    or signal, as far as the caller knows it).
    """
    from scipy.signal import butter, filtfilt

    x = np.asarray(x, dtype=float)
    if not 0.0 < cutoff_hz < sample_rate_hz / 2.0:
        raise DataMismatchError(
            f"{what} is sampled at {sample_rate_hz:g} Hz; the {cutoff_hz:g} Hz low-pass filter needs a "
            f"sampling rate above {2 * cutoff_hz:g} Hz: resample the file"
        )
    b, a = butter(order, cutoff_hz / (sample_rate_hz / 2.0))
    padlen = 3 * (max(len(a), len(b)) - 1)
    if x.shape[0] <= padlen:
        raise DataMismatchError(
            f"{what} is too short: {x.shape[0]} samples, and the {order}th-order "
            f"{cutoff_hz:g} Hz zero-phase filter needs more than {padlen} (at {sample_rate_hz:g} Hz, "
            f"{(padlen + 1) / sample_rate_hz:.3g} s); use a longer trial or a wider window"
        )
    return filtfilt(b, a, x, axis=0, padtype="odd", padlen=padlen)


def mesh_for_window(t0: float, tf: float, mesh_frequency_hz: float = MESH_FREQUENCY_HZ) -> np.ndarray:
    """Mesh nodes ``t_k = t0 + k h``, ``k = 0..N``, ``N = round((tf - t0) f)``, ``h = (tf - t0)/N``."""
    n = int(round((tf - t0) * mesh_frequency_hz))
    if n < 2:
        raise DataMismatchError(
            f"the time window {t0:g}-{tf:g} s gives {n} mesh intervals at {mesh_frequency_hz:g} per "
            "second; at least 2 are needed (use a longer trial)"
        )
    return t0 + (tf - t0) * np.arange(n + 1) / n


def _sample_rate(time: np.ndarray, what: str) -> float:
    """The constant sampling rate (Hz) of ``time``; rounded stamps of one are accepted
    (:func:`musclemetab.io.constant_rate`)."""
    from ..io import constant_rate

    return constant_rate(time, what)[1]


def read_kinematics(path: "str | os.PathLike | StorageTable", dofs: Sequence[str] = DEFAULT_DOFS,
                    check_units: bool = True):
    """Read an IK ``.mot`` file (or its :class:`~musclemetab.io.StorageTable`, already read by
    :func:`~musclemetab.io.read_table`): its time stamps and the DOF angles in radians.

    The file is checked by :func:`musclemetab.geometry.check_kinematics`, the same check the
    geometry applies: DOF columns present, values finite, time in seconds, and angle units
    that agree with the header (``check_units=False`` skips the unit check).

    Returns
    -------
    time_s : (F,) array
    angles_rad : (F, D) array
    """
    from ..geometry import check_kinematics
    from ..io import as_table

    ik = as_table(path)
    in_degrees = check_kinematics(ik, dofs, check_units)
    q = np.column_stack([ik[d] for d in dofs])
    if in_degrees:
        q = np.deg2rad(q)
    return ik.index.copy(), q


def read_inverse_dynamics(path: "str | os.PathLike | StorageTable", dofs: Sequence[str] = DEFAULT_DOFS):
    """Read the ``<dof>_moment`` columns (N m) of an inverse-dynamics ``.sto`` file (or of its
    :class:`~musclemetab.io.StorageTable`, already read by :func:`~musclemetab.io.read_table`).

    Returns
    -------
    time_s : (T,) array
    moments_Nm : (T, D) array
    """
    from ..io import as_table, check_time_stamps, require_columns, table_path

    table = as_table(path)
    path = table_path(path)
    check_time_stamps(table, "inverse dynamics")
    cols = [f"{d}_moment" for d in dofs]
    try:
        require_columns(table, cols, what="inverse-dynamics column")
    except MissingColumnError as exc:
        raise MissingColumnError(
            f"{exc.message}. The inverse dynamics must give one '<dof>_moment' column (N m) per "
            f"degree of freedom: {', '.join(cols)}"
        ) from None
    if len(table.index) < 2:
        raise InputFileError(f"{path}: the inverse-dynamics file has fewer than 2 rows")
    moments = np.column_stack([table[c] for c in cols])
    bad = ~np.isfinite(moments)
    if bad.any():
        row, col = (int(i) for i in np.argwhere(bad)[0])
        raise DataMismatchError(f"{path}: column '{cols[col]}' is {moments[row, col]:g} at data row {row + 1}; "
                                "every moment must be finite: fix or remove the row")
    return table.index.copy(), moments


def select_muscles(
    muscles: Sequence[str],
    moment_arms_m: np.ndarray,
    dofs: Sequence[str],
    threshold_m: float = MUSCLE_SELECTION_THRESHOLD_M,
):
    """Muscles and DOFs of the problem (study rule, ``docs/solver.md``).

    A muscle is kept when ``|r| > threshold`` about at least one DOF **at the first frame**
    (raw moment arms); a DOF is kept when at least one kept muscle has ``|r| > threshold``
    about it at some frame. Order is preserved.

    Returns ``(muscle_indices, dof_indices)``.
    """
    r = np.asarray(moment_arms_m, dtype=float)
    keep_m = np.flatnonzero(np.any(np.abs(r[0]) > threshold_m, axis=0))
    if keep_m.size == 0:
        raise DataMismatchError(
            f"no muscle has a moment arm above {threshold_m:g} m about {', '.join(dofs)}; "
            "check the model and the DOF names"
        )
    keep_d = np.flatnonzero(np.any(np.abs(r[:, :, keep_m]) > threshold_m, axis=(0, 2)))
    return keep_m, keep_d


class GeometryArrays:
    """A :class:`GeometryLike` made of given arrays (a part of another geometry's frames,
    muscles or DOFs)."""

    def __init__(self, time, muscles, dofs, lmt_m, moment_arms_m):
        self.time, self.muscles, self.dofs = time, tuple(muscles), tuple(dofs)
        self.lmt_m, self.moment_arms_m = lmt_m, moment_arms_m


def restrict_geometry(geometry: GeometryLike) -> GeometryLike:
    """The geometry of the muscles and DOFs :func:`select_muscles` keeps (``geometry`` itself
    when it keeps them all).

    DOFs that no selected muscle crosses are dropped (their ID columns must be dropped too).
    """
    r = np.asarray(geometry.moment_arms_m, dtype=float)
    km, kd = select_muscles(geometry.muscles, r, geometry.dofs)
    if km.size == len(geometry.muscles) and kd.size == len(geometry.dofs):
        return geometry
    return GeometryArrays(
        np.asarray(geometry.time, dtype=float),
        [geometry.muscles[i] for i in km],
        [geometry.dofs[j] for j in kd],
        np.asarray(geometry.lmt_m, dtype=float)[:, km],
        r[:, kd][:, :, km],
    )


def check_id_coordinates(id_path, columns: Sequence[str], layout) -> None:
    """Warn (:class:`~musclemetab.errors.MusclemetabWarning`, naming the file and columns)
    when ID columns (``<coordinate>_moment`` or ``<coordinate>_force``) are for coordinates
    the model (``layout``, :func:`musclemetab.layout.read_layout`) lacks: they are ignored
    (inverse dynamics of a model with more coordinates, e.g. arms or a knee's
    varus-valgus). Only the solved DOFs' moments are needed, and a missing one is refused
    where they are read (:func:`read_inverse_dynamics`)."""
    import warnings

    from ..errors import MusclemetabWarning
    from ..messages import name_list

    coords = {c["name"] for c in layout.coordinates}
    alien = []
    for c in columns:
        for suffix in ("_moment", "_force"):
            if c.endswith(suffix) and c[: -len(suffix)] not in coords:
                alien.append(c)
    if alien:
        warnings.warn(
            f"{id_path}: {'column' if len(alien) == 1 else 'columns'} {name_list(alien)} "
            f"{'is' if len(alien) == 1 else 'are'} for coordinates the model {layout.path} lacks and "
            "ignored; check that the inverse dynamics comes from this subject", MusclemetabWarning, stacklevel=2,
        )


def check_time_ranges(ik_time: np.ndarray, id_time: np.ndarray, ik_path="IK", id_path="ID") -> None:
    """Raise :class:`DataMismatchError` unless the ID covers the whole IK window (half a frame of slack)."""
    t0, tf = float(ik_time[0]), float(ik_time[-1])
    tol = 0.5 * float(np.min(np.diff(ik_time)))
    if id_time[-1] < t0 or id_time[0] > tf:
        raise DataMismatchError(
            f"the inverse dynamics {id_path} ({id_time[0]:g}-{id_time[-1]:g} s) and the inverse "
            f"kinematics {ik_path} ({t0:g}-{tf:g} s) do not overlap in time; use files of the same trial"
        )
    if id_time[0] > t0 + tol or id_time[-1] < tf - tol:
        raise DataMismatchError(
            f"the inverse dynamics {id_path} covers {id_time[0]:g}-{id_time[-1]:g} s but the inverse "
            f"kinematics {ik_path} (the analysis window) covers {t0:g}-{tf:g} s; the ID must cover "
            "the whole IK window: use files of the same trial or crop the IK"
        )


def check_moment_magnitudes(
    moments_Nm: np.ndarray,
    dofs: Sequence[str],
    moment_arms_m: np.ndarray,
    max_isometric_force_N: np.ndarray,
    id_path="inverse dynamics",
    reserve_Nm: float = 150.0,
) -> None:
    """Reject ID moments whose size cannot be N m of a walking-like trial.

    Too large: a moment beyond what the muscles crossing the DOF can produce
    (``sum F0 * 2 * |r|``, force-velocity peak below 1.8) plus the reserve, typically N mm.
    Too small: every DOF stays below 1 N m, typically moments normalised to body mass
    (N m/kg) or in kN m.
    """
    M = np.asarray(moments_Nm, dtype=float)
    r = np.abs(np.asarray(moment_arms_m, dtype=float))  # (F, D, M)
    capacity = 2.0 * np.einsum("fdm,m->fd", r, np.asarray(max_isometric_force_N, float)) + reserve_Nm
    ratio = np.abs(M) / capacity
    if np.max(ratio) > 1.0:
        f, d = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
        raise DataMismatchError(
            f"{id_path}: '{dofs[d]}_moment' reaches {M[f, d]:.6g}, more than the muscles crossing "
            f"{dofs[d]} and the reserve can produce ({capacity[f, d]:.4g} N m); the moments must be "
            "in N m (not N mm) and belong to this model and trial"
        )
    if np.max(np.abs(M)) < 1.0:
        raise DataMismatchError(
            f"{id_path}: all joint moments stay below 1 N m (peak {np.max(np.abs(M)):.3g}); they look "
            "normalised (e.g. N m/kg) or in kN m. The solver needs moments in N m"
        )


def check_moments_per_body_mass(
    moments_Nm: np.ndarray, dofs: Sequence[str], body_mass_kg: float, id_path="inverse dynamics",
    model_path="the model",
) -> None:
    """Reject ID moments that look normalised to body mass.

    The largest moment over all DOFs and frames, divided by the model's body mass, must reach
    :data:`MIN_PEAK_MOMENT_NM_PER_KG` (0.2 N m/kg; walking gives 1-1.7 N m/kg). Moments
    divided by the mass give about 1/70 of that and are refused with a message naming the
    file and the column of the largest moment.
    """
    M = np.abs(np.asarray(moments_Nm, dtype=float))
    if not body_mass_kg or body_mass_kg <= 0 or M.size == 0:
        return
    peak = float(M.max())
    per_kg = peak / float(body_mass_kg)
    if per_kg < MIN_PEAK_MOMENT_NM_PER_KG:
        col = dofs[int(np.argmax(M.max(axis=0)))]
        raise DataMismatchError(
            f"{id_path}: the largest joint moment ('{col}_moment', {peak:.3g}) is {per_kg:.3g} N m per kg of the "
            f"{body_mass_kg:.4g} kg of {model_path}, below the {MIN_PEAK_MOMENT_NM_PER_KG:g} N m/kg any walking "
            "trial reaches; the moments look normalised to body mass (N m/kg): multiply them by the body mass"
        )


def trial_inputs(
    geometry: GeometryLike,
    id_time_s: np.ndarray,
    id_moments_Nm: np.ndarray,
    *,
    ik_time_s: np.ndarray | None = None,
    dofs: Sequence[str] | None = None,
    filter_inputs: bool = True,
    cutoff_hz: float = FILTER_CUTOFF_HZ,
    filter_order: int = FILTER_ORDER,
    mesh_frequency_hz: float = MESH_FREQUENCY_HZ,
    sources: dict | None = None,
) -> TrialInputs:
    """Filter the trial data and evaluate it on the optimisation mesh.

    Parameters
    ----------
    geometry
        Muscle-tendon lengths ``(F, M)`` and moment arms ``(F, D, M)`` at the IK frames.
    id_time_s, id_moments_Nm
        The full ID file ``(T,)``, ``(T, D)`` with columns in the order of ``dofs``.
    ik_time_s
        IK frame times; the window is ``[ik_time_s[0], ik_time_s[-1]]``. Defaults to the
        geometry's time (which must equal the IK frames).
    dofs
        DOF names of the ID columns; defaults to ``geometry.dofs``.
    filter_inputs
        The study filters everything (6 Hz, order 6); ``False`` skips filtering.
    """
    from scipy.interpolate import CubicSpline

    sources = dict(sources or {})
    g_time = np.asarray(geometry.time, dtype=float)
    dofs = tuple(dofs if dofs is not None else geometry.dofs)
    if tuple(geometry.dofs) != dofs:
        raise DataMismatchError(
            f"the geometry has DOFs {list(geometry.dofs)} but the moments are for {list(dofs)}; "
            "compute the geometry for the same DOFs"
        )
    muscles = tuple(geometry.muscles)
    lmt = np.asarray(geometry.lmt_m, dtype=float)
    r = np.asarray(geometry.moment_arms_m, dtype=float)
    F, M, D = g_time.size, len(muscles), len(dofs)
    if lmt.shape != (F, M) or r.shape != (F, D, M):
        raise DataMismatchError(
            f"geometry arrays have shapes {lmt.shape} and {r.shape}; expected ({F}, {M}) and ({F}, {D}, {M})"
        )
    if not (np.all(np.isfinite(lmt)) and np.all(np.isfinite(r))):
        bad = [m for j, m in enumerate(muscles) if not (np.isfinite(lmt[:, j]).all() and np.isfinite(r[:, :, j]).all())]
        raise DataMismatchError(
            f"the muscle geometry of {sources.get('ik', 'the IK motion')} holds NaN or infinite values for "
            f"{', '.join(bad[:5])}{' ...' if len(bad) > 5 else ''}; check that the IK file belongs to "
            f"{sources.get('model', 'the model')}"
        )
    if ik_time_s is None:
        ik_time_s = g_time
    ik_time_s = np.asarray(ik_time_s, dtype=float)
    if ik_time_s.size != F or np.max(np.abs(ik_time_s - g_time)) > 1e-6:
        raise DataMismatchError(
            f"the muscle geometry has {F} frames ({g_time[0]:g}-{g_time[-1]:g} s) but the IK has "
            f"{ik_time_s.size} ({ik_time_s[0]:g}-{ik_time_s[-1]:g} s); compute the geometry from this IK file"
        )
    id_time_s = np.asarray(id_time_s, dtype=float)
    id_moments_Nm = np.asarray(id_moments_Nm, dtype=float).reshape(id_time_s.size, -1)
    if id_moments_Nm.shape[1] != D:
        raise DataMismatchError(f"{id_moments_Nm.shape[1]} ID moment columns for {D} DOFs")
    if not np.all(np.isfinite(id_moments_Nm)):
        raise DataMismatchError(f"the inverse dynamics {sources.get('id', '')} holds NaN or infinite values")
    check_time_ranges(ik_time_s, id_time_s, sources.get("ik", "IK"), sources.get("id", "ID"))

    fs_ik = _sample_rate(ik_time_s, str(sources.get("ik", "IK")))
    if filter_inputs:
        fs_id = _sample_rate(id_time_s, str(sources.get("id", "ID")))
        ik_what = (f"the solved window {ik_time_s[0]:.3f}-{ik_time_s[-1]:.3f} s of the IK file "
                   f"{sources.get('ik', '')}").rstrip()
        lmt_f = lowpass_filtfilt(lmt, fs_ik, cutoff_hz, filter_order, what=ik_what)
        r_f = lowpass_filtfilt(r.reshape(F, D * M), fs_ik, cutoff_hz, filter_order, what=ik_what).reshape(F, D, M)
        id_f = lowpass_filtfilt(id_moments_Nm, fs_id, cutoff_hz, filter_order,
                                what=f"the inverse dynamics {sources.get('id', '')}".rstrip())
    else:
        lmt_f, r_f, id_f = lmt, r, id_moments_Nm
    # ID: filtered on the full file, linearly interpolated onto the IK frames.
    id_frames = np.column_stack([np.interp(ik_time_s, id_time_s, id_f[:, j]) for j in range(D)])

    mesh = mesh_for_window(float(ik_time_s[0]), float(ik_time_s[-1]), mesh_frequency_hz)
    lmt_spline = CubicSpline(ik_time_s, lmt_f, axis=0, bc_type="not-a-knot")
    r_spline = CubicSpline(ik_time_s, r_f.reshape(F, D * M), axis=0, bc_type="not-a-knot")
    id_spline = CubicSpline(ik_time_s, id_frames, axis=0, bc_type="not-a-knot")
    return TrialInputs(
        muscles=muscles,
        dofs=dofs,
        frame_time_s=ik_time_s,
        lmt_frames_m=lmt_f,
        lmt_velocity_frames_m_per_s=lmt_spline(ik_time_s, 1),
        moment_arms_frames_m=r_f,
        moments_frames_Nm=id_frames,
        mesh_time_s=mesh,
        lmt_m=lmt_spline(mesh),
        moment_arms_m=r_spline(mesh).reshape(mesh.size, D, M),
        moments_Nm=id_spline(mesh),
        sources=sources,
    )

