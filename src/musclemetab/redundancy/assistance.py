"""Assistive devices: a joint torque taken off the biological moments before the muscles are solved.

An exoskeleton (or any device acting about the joints) is given as a torque per degree of
freedom over time, or over the gait cycle, and a gain. The muscles then supply what the device
does not (``docs/assistance.md``)::

    M_muscles(t) = M_ID(t) - g * tau_device(t)

**Sign convention.** A positive device torque acts in the coordinate's positive direction, as a
positive inverse-dynamics moment does (the ID moment is the net moment the body needs about the
coordinate; the device supplies part of it). A device torque equal to the ID moment of a DOF
leaves that DOF to no one: its muscles fall silent. For the Rajagopal and gait2392 families a
positive ``ankle_angle`` is dorsiflexion, so plantarflexion assistance is a negative torque.

**Profile files.** An OpenSim ``.sto``/``.mot`` or a ``.csv``:

* the first column is ``time`` (s; the profile must cover the solved window), or, for a
  profile over the gait cycle, ``cycle_pct`` (0-100 %, a ``.csv``), or ``time`` in a
  ``.sto``/``.mot`` whose header holds the line ``assistance_axis=cycle_pct`` (the column then
  holds % of the gait cycle). A cycle profile is periodic: it repeats every cycle and is
  mapped onto the solve's gait cycle (heel strike to heel strike);
* every other column is the torque (N m, not N m/kg) about one coordinate of the model, named
  as the coordinate (``ankle_angle_r``) or as its inverse-dynamics column
  (``ankle_angle_r_moment``). Coordinates without a column get no torque.

The device's power is ``P(t) = sum_d tau_d(t) * qdot_d(t)`` with the joint angular velocities
from the inverse kinematics (low-pass filtered at 6 Hz, as the solver filters its inputs);
its positive and negative work per cycle are the integrals of the positive and negative parts
of ``P`` over the gait cycle (:func:`device_work`).

The *augmentation factor* follows Mooney, Rouse & Herr (2014, J NeuroEng Rehabil 11:80):
the device's average positive power less the magnitude of its average negative power, over
the efficiency of positive muscle work (``eta = 0.41``), less the metabolic cost of carrying
the device's mass (``sum beta_i m_i``); the torque of a profile has no mass, so that term is 0
here (:func:`augmentation_factor_W_per_kg`). Beside it the *saving per unit positive work* is
the metabolic energy saved per joule of positive device work (metabolic saving rate over the
device's average positive power).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import DataMismatchError, InputFileError, MissingColumnError, OptionError, UnknownCoordinateError

__all__ = ["AssistanceProfile", "read_assistance", "CYCLE_AXIS_HEADER", "CYCLE_COLUMN", "MUSCLE_EFFICIENCY",
           "MAX_TORQUE_NM_PER_KG", "MIN_PEAK_TORQUE_NM", "apply_assistance", "device_work", "assistance_record",
           "plantarflexion_assistance", "augmentation_factor_W_per_kg", "check_gain", "check_profile_for_leg",
           "check_profile_against_model"]

#: header line of a ``.sto``/``.mot`` profile whose ``time`` column holds % of the gait cycle
CYCLE_AXIS_HEADER = "assistance_axis=cycle_pct"
#: first column of a ``.csv`` profile over the gait cycle (% of the cycle)
CYCLE_COLUMN = "cycle_pct"
#: efficiency of positive muscle work in the augmentation factor (Mooney et al. 2014)
MUSCLE_EFFICIENCY = 0.41
#: a device torque above this, per kg of body mass, is beyond any joint moment of walking
#: (1-1.7 N m/kg at the ankle): the file is in other units (N mm) or not a torque
MAX_TORQUE_NM_PER_KG = 5.0
#: a profile whose largest torque stays below this is refused as normalised (N m/kg)
MIN_PEAK_TORQUE_NM = 1.0
#: how much of the solve window a time profile may miss at either end (rounded time stamps), s
_COVER_TOLERANCE_S = 5e-4
#: the low-pass filter of the joint angles before their velocities are taken (the solver's)
_VELOCITY_FILTER_HZ = 6.0


@dataclass(frozen=True)
class AssistanceProfile:
    """A device torque profile read from ``path``: ``x`` is time (s, ``axis = "time_s"``) or % of
    the gait cycle (``axis = "cycle_pct"``), ``torque_Nm`` ``(len(x), len(coordinates))``."""

    path: Path
    axis: str
    x: np.ndarray = field(repr=False)
    coordinates: tuple[str, ...]
    columns: tuple[str, ...]
    torque_Nm: np.ndarray = field(repr=False)

    @property
    def peak_Nm(self) -> float:
        return float(np.max(np.abs(self.torque_Nm))) if self.torque_Nm.size else 0.0

    def torque_at(self, time_s, dofs: Sequence[str], gain: float = 1.0,
                  cycle_s: tuple[float, float] | None = None) -> np.ndarray:
        """``(T, D)`` device torque (N m, times ``gain``) at ``time_s`` about each of ``dofs``
        (zero for a DOF without a column). A time profile holds its first and last values outside
        its range; a cycle profile repeats with the period of ``cycle_s`` (start, end in s)."""
        t = np.asarray(time_s, dtype=float)
        out = np.zeros((t.size, len(dofs)))
        if self.axis == "cycle_pct":
            if cycle_s is None:
                raise OptionError(f"{self.path}: a profile over the gait cycle needs the gait cycle of the solve")
            c0, c1 = cycle_s
            where, period = 100.0 * (t - c0) / (c1 - c0), 100.0
        else:
            where, period = t, None
        for j, d in enumerate(dofs):
            if d in self.coordinates:
                k = self.coordinates.index(d)
                out[:, j] = np.interp(where, self.x, self.torque_Nm[:, k], period=period)
        return gain * out


def check_gain(gain, where: str = "", option: str | None = "--assistance-gain") -> float:
    """The gain as a float within :data:`musclemetab.settings.NUMBER_KEYS` ``["assistance_gain"]``
    (:class:`OptionError` naming ``option``, or the study key, otherwise; 0: no assistance)."""
    from ..settings import check_number

    return float(check_number("assistance_gain", gain, where, option))


def _header_lines(path: Path) -> list[str]:
    lines = []
    with open(path, encoding="utf-8-sig", errors="replace") as f:
        for line in f:
            if line.strip().lower() == "endheader":
                break
            lines.append(line.strip().lower().replace(" ", ""))
    return lines


def read_assistance(path: str | os.PathLike) -> AssistanceProfile:
    """Read a device torque profile (module docstring for the file's conventions).

    Raises :class:`~musclemetab.errors.InputFileError` for an unreadable file, one without torque
    columns or with non-finite values, and :class:`~musclemetab.errors.DataMismatchError` for a cycle
    profile outside 0-100 %, each naming the file (and column)."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"assistance profile {path} not found; give the path of a .sto, .mot or .csv file")
    if path.suffix.lower() == ".csv":
        from ..io.csvfile import read_csv_file

        df = read_csv_file(path, "write it again as a CSV table with a time or cycle_pct column", "assistance profile")
        if df.shape[1] < 2:
            raise InputFileError(f"{path}: an assistance profile needs a 'time' (s) or '{CYCLE_COLUMN}' (%) column "
                                 "and one torque column (N m) per assisted coordinate")
        first = str(df.columns[0]).strip()
        if first not in ("time", CYCLE_COLUMN):
            raise MissingColumnError(f"{path}: the first column is '{first}'; name it 'time' (s) or '{CYCLE_COLUMN}' "
                                     "(% of the gait cycle)")
        axis = "cycle_pct" if first == CYCLE_COLUMN else "time_s"
        try:
            x = df.iloc[:, 0].to_numpy(float)
            values = df.iloc[:, 1:].to_numpy(float)
        except ValueError:
            raise InputFileError(f"{path}: the assistance profile holds text where numbers belong; fix the file") \
                from None
        columns = tuple(str(c).strip() for c in df.columns[1:])
        if not (np.all(np.isfinite(x)) and np.all(np.diff(x) > 0)):
            raise InputFileError(f"{path}: column '{first}' must increase strictly, with finite values")
    else:
        from ..io import read_table

        table = read_table(path)
        axis = "cycle_pct" if CYCLE_AXIS_HEADER in _header_lines(path) else "time_s"
        x, values, columns = table.index, table.to_numpy(), table.columns
        if not columns:
            raise InputFileError(f"{path}: no torque column; give one column (N m) per assisted coordinate")
    bad = ~np.isfinite(values)
    if bad.any():
        row, col = (int(i) for i in np.argwhere(bad)[0])
        raise InputFileError(f"{path}: column '{columns[col]}' is {values[row, col]:g} at data row {row + 1}; every "
                             "torque must be finite (0 where the device is off)")
    if len(x) < 2:
        raise InputFileError(f"{path}: the assistance profile has fewer than 2 rows")
    if axis == "cycle_pct":
        if x[0] < -1e-9 or x[-1] > 100.0 + 1e-9:
            raise DataMismatchError(f"{path}: a profile over the gait cycle runs from 0 to 100 %, but its first column "
                                    f"spans {x[0]:g}-{x[-1]:g}; give % of the cycle, or drop the "
                                    f"'{CYCLE_AXIS_HEADER}' header (or the '{CYCLE_COLUMN}' column) for a time profile")
        if x[0] <= 1e-9 and x[-1] >= 100.0 - 1e-9:  # 0 and 100 are one instant of a periodic profile
            x, values = x[:-1], values[:-1]
    coordinates = tuple(c[: -len("_moment")] if c.endswith("_moment") else c for c in columns)
    dup = sorted({c for c in coordinates if coordinates.count(c) > 1})
    if dup:
        raise InputFileError(f"{path}: coordinate {dup[0]} has more than one column; give one torque per coordinate")
    return AssistanceProfile(path, axis, np.asarray(x, float), coordinates, tuple(columns), np.asarray(values, float))


def _check_profile(profile: AssistanceProfile, dofs: Sequence[str], side: str | None, model_coordinates,
                   body_mass_kg: float | None, window_s: tuple[float, float] | None, check_units: bool,
                   other_leg_solved: bool = False) -> None:
    """The profile against the problem: its columns name coordinates of the model, those of this
    leg are solved DOFs, one at least is (unless ``other_leg_solved``: the other leg's solve takes
    its columns), a time profile covers the window (``None``: not checked), and (``check_units``)
    its size is N m."""
    if model_coordinates is not None:
        alien = [c for c, k in zip(profile.columns, profile.coordinates) if k not in set(model_coordinates)]
        if alien:
            import difflib

            near = difflib.get_close_matches(alien[0].removesuffix("_moment"), list(model_coordinates), n=3)
            raise UnknownCoordinateError(
                f"{profile.path}: column '{alien[0]}' names no coordinate of the model"
                + (f" (near: {', '.join(near)})" if near else "")
                + "; name each torque column after the coordinate it acts about, e.g. ankle_angle_r")
    other = _other_leg(side)
    unsolved = [c for c, k in zip(profile.columns, profile.coordinates)
                if k not in set(dofs) and not (other and k.endswith(other))]
    if unsolved:
        raise OptionError(f"{profile.path}: column '{unsolved[0]}' is not a DOF of this problem "
                          f"({', '.join(dofs)}): the device torque about it would be lost; drop the column or "
                          "solve that DOF (--dofs)")
    if not other_leg_solved and not set(profile.coordinates) & set(dofs):
        raise OptionError(
            f"{profile.path}: its columns ({', '.join(profile.columns)}) name none of the solved leg's coordinates "
            f"({'side ' + side + ': ' if side else ''}{', '.join(dofs)}): the device would do nothing; name the "
            "solved leg's coordinates (e.g. ankle_angle_r), or solve the leg the profile assists (--side / side)")
    if profile.axis == "time_s" and window_s is not None:
        t0, tf = window_s
        tol = _COVER_TOLERANCE_S
        if profile.x[0] > t0 + tol or profile.x[-1] < tf - tol:
            raise DataMismatchError(
                f"{profile.path}: the assistance profile covers {profile.x[0]:g}-{profile.x[-1]:g} s but the solve "
                f"window is {t0:g}-{tf:g} s; give a profile over the whole window (times of the trial's files), or a "
                f"profile over the gait cycle (first column '{CYCLE_COLUMN}', or the header line "
                f"'{CYCLE_AXIS_HEADER}')")
    if check_units:
        _check_units(profile, body_mass_kg)


def _other_leg(side: str | None) -> str | None:
    """The suffix of the other leg's coordinates (``_l`` for ``r``), ``None`` without a leg."""
    return f"_{'l' if side == 'r' else 'r'}" if side in ("r", "l") else None


def check_profile_for_leg(profile: AssistanceProfile, side: str, body_mass_kg: float | None = None, *,
                          dofs: Sequence[str] | None = None, check_units: bool = True) -> None:
    """What can be checked of a profile without the model (a study file when it is read): for one
    leg (``side`` ``"r"``/``"l"``; ``"both"``: each leg takes its own columns) a profile whose
    columns all name the other leg's coordinates (``ankle_angle_l`` for ``r``), or none of
    ``dofs`` when they are given, is refused (the device would do nothing); and the units
    (``check_units``: N m, against ``body_mass_kg``). :func:`apply_assistance` checks the rest."""
    other = _other_leg(side)
    if dofs:
        useless = not set(profile.coordinates) & set(dofs)
    else:
        useless = other is not None and all(k.endswith(other) for k in profile.coordinates)
    if useless:
        solved = f"'{', '.join(dofs)}'" if dofs else f"the {'right' if side == 'r' else 'left'} leg's"
        raise OptionError(
            f"{profile.path}: its columns ({', '.join(profile.columns)}) name none of {solved} coordinates (side "
            f"\"{side}\"): the device would do nothing; name the solved leg's coordinates (e.g. ankle_angle_{side}), "
            "or solve the leg the profile assists (side)")
    if check_units:
        _check_units(profile, body_mass_kg)


def _check_units(profile: AssistanceProfile, body_mass_kg: float | None) -> None:
    """The profile's size is N m: its largest torque at least 1 N m, at most 5 N m per kg."""
    peak = profile.peak_Nm
    if peak < MIN_PEAK_TORQUE_NM:
        col = profile.columns[int(np.argmax(np.abs(profile.torque_Nm).max(axis=0)))]
        raise DataMismatchError(
            f"{profile.path}: the largest device torque (column '{col}') is {peak:.3g}, below "
            f"{MIN_PEAK_TORQUE_NM:g} N m; it looks normalised to body mass (N m/kg): multiply it by the body mass "
            "(the torque must be in N m)")
    if body_mass_kg and peak / float(body_mass_kg) > MAX_TORQUE_NM_PER_KG:
        col = profile.columns[int(np.argmax(np.abs(profile.torque_Nm).max(axis=0)))]
        raise DataMismatchError(
            f"{profile.path}: column '{col}' reaches {peak:.4g}, {peak / body_mass_kg:.3g} per kg of body mass, "
            f"beyond any joint moment of walking ({MAX_TORQUE_NM_PER_KG:g} N m/kg); the torque must be in N m "
            "(not N mm)")


def check_profile_against_model(profile: AssistanceProfile, dofs: Sequence[str], side: str, model_coordinates,
                                body_mass_kg: float | None = None, window_s: tuple[float, float] | None = None, *,
                                check_units: bool = True, other_leg_solved: bool = False) -> None:
    """The checks of :func:`apply_assistance` without the moments (a study before its units run):
    the columns against the model's coordinates and the leg's ``dofs``, a time profile against
    ``window_s`` (``None``: not checked), the units."""
    _check_profile(profile, dofs, side, model_coordinates, body_mass_kg, window_s, check_units, other_leg_solved)


def apply_assistance(id_time_s, id_moments_Nm, dofs: Sequence[str], profile: AssistanceProfile, gain: float,
                     *, window_s: tuple[float, float], cycle_s: tuple[float, float] | None = None,
                     side: str | None = None, model_coordinates=None, body_mass_kg: float | None = None,
                     check_units: bool = True, other_leg_solved: bool = False) -> np.ndarray:
    """The moments the muscles must supply, ``M_ID - gain * tau`` at the ID samples ``(T, D)``,
    after the checks of the profile against the problem (its columns, the window, the units).

    ``window_s``: the solved window (a time profile must cover it); ``cycle_s``: the gait cycle a
    cycle profile is mapped onto (default: the window). ``side``: columns of the other leg's
    coordinates are left to that leg's solve; a profile with none of this leg's coordinates is
    refused (it would do nothing) unless ``other_leg_solved`` (both legs are solved: the other
    leg's solve takes it). ``model_coordinates``: the model's coordinate names (a column naming
    none is refused)."""
    gain = check_gain(gain)
    _check_profile(profile, dofs, side, model_coordinates, body_mass_kg, window_s, check_units, other_leg_solved)
    tau = profile.torque_at(id_time_s, dofs, gain, cycle_s or window_s)
    return np.asarray(id_moments_Nm, dtype=float) - tau


def _angular_velocity(ik_time_s, angles_rad, at_s) -> np.ndarray:
    """``(T, D)`` joint angular velocities (rad/s) at ``at_s``: the angles low-pass filtered at 6 Hz
    (zero lag, as the solver's inputs) and differentiated through a not-a-knot cubic spline."""
    from scipy.interpolate import CubicSpline

    from ..io import constant_rate
    from .inputs import lowpass_filtfilt

    t = np.asarray(ik_time_s, dtype=float)
    q = np.asarray(angles_rad, dtype=float)
    fs = constant_rate(t, "the inverse kinematics")[1]
    if fs > 2 * _VELOCITY_FILTER_HZ and t.size > 18:
        q = lowpass_filtfilt(q, fs, _VELOCITY_FILTER_HZ, what="the inverse kinematics")
    return CubicSpline(t, q, axis=0, bc_type="not-a-knot")(np.asarray(at_s, dtype=float), 1)


def device_work(profile: AssistanceProfile, gain: float, dofs: Sequence[str], ik_time_s, angles_rad,
                cycle_s: tuple[float, float], *, samples: int = 2001) -> dict:
    """The device's work over the gait cycle ``cycle_s`` from its torque and the IK's joint
    angular velocities: ``{"positive_work_J", "negative_work_J" (<= 0), "net_work_J",
    "mean_positive_power_W", "mean_negative_power_W" (<= 0), "duration_s"}`` (one leg's
    device, the DOFs of ``dofs``), on ``samples`` instants of the cycle (trapezoidal rule)."""
    c0, c1 = (float(c) for c in cycle_s)
    t = np.linspace(c0, c1, samples)
    power = np.sum(profile.torque_at(t, dofs, gain, (c0, c1)) * _angular_velocity(ik_time_s, angles_rad, t), axis=1)
    positive = float(np.trapezoid(np.maximum(power, 0.0), t))
    negative = float(np.trapezoid(np.minimum(power, 0.0), t))
    duration = c1 - c0
    return {"positive_work_J": positive, "negative_work_J": negative, "net_work_J": positive + negative,
            "mean_positive_power_W": positive / duration, "mean_negative_power_W": negative / duration,
            "duration_s": duration}


def assistance_record(profile: AssistanceProfile, gain: float, dofs: Sequence[str], ik_time_s, angles_rad,
                      mesh_time_s, cycle_s: tuple[float, float], cycle_source: str) -> dict:
    """``summary.json``'s ``assistance``: the file, gain, axis, assisted DOFs, the gait cycle
    (and where it came from), the device's work over it (:func:`device_work`) and its torque
    (N m, gain applied) and power (W) at the mesh nodes."""
    assisted = [d for d in dofs if d in profile.coordinates]
    mesh = np.asarray(mesh_time_s, dtype=float)
    tau = profile.torque_at(mesh, assisted, gain, cycle_s)
    q = np.asarray(angles_rad)[:, [list(dofs).index(d) for d in assisted]]
    power = np.sum(tau * _angular_velocity(ik_time_s, q, mesh), axis=1) if assisted else np.zeros(mesh.size)
    work = device_work(profile, gain, assisted, ik_time_s, q, cycle_s) if assisted else \
        {"positive_work_J": 0.0, "negative_work_J": 0.0, "net_work_J": 0.0, "mean_positive_power_W": 0.0,
         "mean_negative_power_W": 0.0, "duration_s": float(cycle_s[1] - cycle_s[0])}
    return {"file": str(profile.path), "gain": float(gain), "axis": profile.axis, "dofs": assisted,
            "cycle_s": [float(cycle_s[0]), float(cycle_s[1])], "cycle_source": cycle_source, **work,
            "time_s": [float(v) for v in mesh],
            "torque_Nm": {d: [float(v) for v in tau[:, j]] for j, d in enumerate(assisted)},
            "power_W": [float(v) for v in power]}


def augmentation_factor_W_per_kg(mean_positive_power_W_per_kg: float, mean_negative_power_W_per_kg: float,
                                 efficiency: float = MUSCLE_EFFICIENCY, carried_cost_W_per_kg: float = 0.0) -> float:
    """The augmentation factor (W/kg) after Mooney, Rouse & Herr (2014): ``(P+ - |P-|) / eta -
    carried``, with ``P+`` and ``P-`` the device's average positive and negative power per kg of
    body mass, ``eta`` the efficiency of positive muscle work (0.41) and ``carried`` the metabolic
    cost of carrying the device (0 for a torque profile, which has no mass)."""
    return (float(mean_positive_power_W_per_kg) - abs(float(mean_negative_power_W_per_kg))) / efficiency \
        - float(carried_cost_W_per_kg)


def plantarflexion_assistance(path: str | os.PathLike, body_mass_kg: float, *, peak_Nm_per_kg: float = 0.2,
                              peak_percent: float = 50.0, onset_percent: float = 25.0, offset_percent: float = 62.5,
                              dof: str = "ankle_angle_r", plantarflexion_sign: float = -1.0,
                              points: int = 201) -> Path:
    """Write an ankle plantarflexion assistance profile over the gait cycle (a ``.sto`` with the
    header line ``assistance_axis=cycle_pct``) and return its path.

    The torque is zero until ``onset_percent`` of the cycle (heel strike = 0 %), rises as a
    half cosine to ``peak_Nm_per_kg * body_mass_kg`` at ``peak_percent``, falls as a half cosine
    to zero at ``offset_percent`` (near toe-off) and stays zero through swing: the shape of
    the ankle exoskeleton torques of the literature (e.g. a peak near 50 % of the cycle, late
    stance). ``plantarflexion_sign`` is the sign of a plantarflexion torque about ``dof``
    (-1 for the Rajagopal and gait2392 families, where positive ``ankle_angle`` is
    dorsiflexion)."""
    from ..io import storage_from_arrays, write_storage

    mass = float(body_mass_kg)
    if not (0 <= onset_percent < peak_percent < offset_percent <= 100):
        raise OptionError(f"plantarflexion assistance needs 0 <= onset ({onset_percent:g} %) < peak "
                          f"({peak_percent:g} %) < offset ({offset_percent:g} %) <= 100")
    if not (np.isfinite(mass) and mass > 0 and np.isfinite(peak_Nm_per_kg)):
        raise OptionError("plantarflexion assistance needs a positive body mass (kg) and a finite peak (N m/kg)")
    pct = np.linspace(0.0, 100.0, int(points))
    shape = np.zeros_like(pct)
    rise = (pct >= onset_percent) & (pct <= peak_percent)
    fall = (pct > peak_percent) & (pct <= offset_percent)
    shape[rise] = 0.5 * (1 - np.cos(np.pi * (pct[rise] - onset_percent) / (peak_percent - onset_percent)))
    shape[fall] = 0.5 * (1 + np.cos(np.pi * (pct[fall] - peak_percent) / (offset_percent - peak_percent)))
    torque = float(plantarflexion_sign) * float(peak_Nm_per_kg) * mass * shape
    table = storage_from_arrays(pct, {dof: torque}, name="plantarflexion_assistance")
    return write_storage(path, table, comments=[
        CYCLE_AXIS_HEADER,
        f"# plantarflexion assistance: peak {peak_Nm_per_kg:g} N m/kg x {mass:g} kg at {peak_percent:g} % of the "
        f"gait cycle, from {onset_percent:g} to {offset_percent:g} %; the time column is % of the cycle, torque in "
        "N m"])
