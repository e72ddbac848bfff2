"""Gait events and the gait cycle: from ground reaction forces, or from inverse dynamics.

The gait cycle runs from an initial contact (IC, heel strike) of the analysed foot to its
next initial contact; stance is IC -> toe-off (TO), swing is TO -> next IC
(``docs/analysis.md``). All times are in seconds.

Three ways to obtain a :class:`GaitCycle`:

* :meth:`GaitCycle.from_times` (or the constructor): events known from elsewhere; this
  always overrides the detection below.
* :func:`cycle_from_grf`: threshold crossings of the vertical ground reaction force
  (:func:`gait_events_from_grf`). The study's threshold is not reported (a 10-20 N
  threshold is usual); the default is 20 N, a parameter.
* :func:`gait_events_from_kinematics` (:func:`kinematic_gait_events` from a model and IK
  file): data without forces. The coordinate-based rule of Zeni et al. (2008, Gait &
  Posture 27:710-714): heel strike where the heel lies furthest ahead of the pelvis, toe-off
  where the toe lies furthest behind it, along the direction of travel (the heel and toe are
  the origins of the foot's rearmost and foremost bodies, :func:`musclemetab.layout.foot_bodies`).
* :func:`cycle_from_inverse_dynamics`: the fallback for data without force files, such as
  the example subject. The simulated window is the cycle padded by about five frames
  at each end (``docs/solver.md``), so IC = window start + padding and next
  IC = window end - padding (padding 0.05 s at 100 Hz); toe-off is the instant at which
  the ankle plantarflexion moment, after its stance peak, has fallen to a small fraction
  of that peak (default 1 %). These are estimates, not measured events.

OpenSim sign conventions (Rajagopal / gait2392 family): ``ankle_angle`` positive =
dorsiflexion, so the stance plantarflexion moment is *negative* in the inverse-dynamics
file; the sign is a parameter (``plantarflexion_sign``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from .errors import DataMismatchError, MissingColumnError, OptionError

__all__ = [
    "GaitCycle",
    "GaitEvents",
    "gait_events_from_grf",
    "gait_events_from_kinematics",
    "kinematic_gait_events",
    "cycle_from_grf",
    "cycle_from_external_loads",
    "cycle_from_inverse_dynamics",
    "EVENTS_REMEDY",
    "cycle_from_id_file",
    "cycle_of_trial",
    "read_grf",
    "grf_of_side",
    "force_columns",
    "foot_kinematics",
    "feet_for_checks",
    "foot_of_force",
    "FootKinematics",
    "ForceFoot",
    "check_against_kinematics",
    "check_applied_feet",
    "check_cycle_duration",
    "FOOT_DISTANCE_M",
    "HEEL_STRIKE_TOLERANCE_S",
    "WALKING_CYCLE_DURATION_S",
    "DEFAULT_GRF_THRESHOLD_N",
    "DEFAULT_MIN_DURATION_S",
    "DEFAULT_PADDING_S",
    "DEFAULT_TOE_OFF_FRACTION",
]

def as_time(time_s, what: str = "time_s", min_samples: int = 2) -> np.ndarray:
    """A 1-D, finite, strictly increasing time axis (s)."""
    t = np.asarray(time_s, dtype=float)
    if t.ndim != 1:
        raise DataMismatchError(f"{what} must be 1-D (one time per sample), not of shape {t.shape}")
    if t.size < min_samples:
        raise DataMismatchError(f"{what} has {t.size} samples; at least {min_samples} are needed")
    if not np.all(np.isfinite(t)):
        raise OptionError(f"{what} holds NaN or infinite values; give finite times in seconds")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise OptionError(
            f"{what} is not strictly increasing (sample {k + 1}, t = {t[k + 1]:g} s follows {t[k]:g} s); "
            "sort the samples and remove repeated times"
        )
    return t


def as_signal(values, t: np.ndarray, what: str) -> np.ndarray:
    """A float array whose last axis matches the time axis ``t``, without NaN."""
    y = np.asarray(values, dtype=float)
    if y.ndim == 0 or y.shape[-1] != t.size:
        raise DataMismatchError(
            f"{what} has {y.shape[-1] if y.ndim else 0} samples along its last (time) axis "
            f"but the time axis has {t.size}"
        )
    if not np.all(np.isfinite(y)):
        raise OptionError(f"{what} holds NaN or infinite values; fill or remove those samples first")
    return y


#: Vertical-force threshold for contact (N); 10-20 N is usual, the study's is not reported.
DEFAULT_GRF_THRESHOLD_N = 20.0
#: Shortest contact or non-contact period accepted as real (s); shorter excursions are noise.
DEFAULT_MIN_DURATION_S = 0.05
#: Padding of the example's IK window beyond the cycle at each end: 5 frames at 100 Hz (s).
DEFAULT_PADDING_S = 0.05
#: Toe-off when the plantarflexion moment has fallen to this fraction of its stance peak.
DEFAULT_TOE_OFF_FRACTION = 0.01


def _finite(x, name: str) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise OptionError(f"{name} must be a number of seconds, not {x!r}") from None
    if not np.isfinite(v):
        raise OptionError(f"{name} must be finite, not {x!r}")
    return v


@dataclass(frozen=True)
class GaitCycle:
    """One gait cycle of the analysed foot: initial contact, toe-off, next initial contact (s).

    Raises :class:`OptionError` for non-finite times and :class:`DataMismatchError` unless
    ``start_s < toe_off_s < end_s``.
    """

    start_s: float
    toe_off_s: float
    end_s: float

    def __post_init__(self):
        for name in ("start_s", "toe_off_s", "end_s"):
            object.__setattr__(self, name, _finite(getattr(self, name), name))
        if not self.start_s < self.end_s:
            raise DataMismatchError(
                f"gait cycle start ({self.start_s:g} s) must precede its end ({self.end_s:g} s)"
            )
        if not self.start_s < self.toe_off_s < self.end_s:
            raise DataMismatchError(
                f"toe-off ({self.toe_off_s:g} s) must lie strictly inside the gait cycle "
                f"{self.start_s:g}-{self.end_s:g} s; check the events"
            )

    @classmethod
    def from_times(cls, start_s: float, toe_off_s: float, end_s: float | None = None, *,
                   duration_s: float | None = None) -> "GaitCycle":
        """A cycle from known event times; give either ``end_s`` or ``duration_s``."""
        if (end_s is None) == (duration_s is None):
            raise OptionError("give exactly one of end_s (next initial contact) and duration_s")
        if end_s is None:
            end_s = _finite(start_s, "start_s") + _finite(duration_s, "duration_s")
        return cls(start_s, toe_off_s, end_s)

    @property
    def duration_s(self) -> float:
        """Cycle duration (s)."""
        return self.end_s - self.start_s

    @property
    def stance_fraction(self) -> float:
        """Stance duration over cycle duration (-)."""
        return (self.toe_off_s - self.start_s) / self.duration_s

    @property
    def swing_fraction(self) -> float:
        """Swing duration over cycle duration (-)."""
        return 1.0 - self.stance_fraction

    @property
    def toe_off_pct(self) -> float:
        """Toe-off in percent of the cycle."""
        return 100.0 * self.stance_fraction

    def percent(self, time_s):
        """Time (s) -> percent of the cycle (0 at initial contact, 100 at the next)."""
        out = (np.asarray(time_s, dtype=float) - self.start_s) / self.duration_s * 100.0
        return float(out) if out.ndim == 0 else out


@dataclass(frozen=True)
class GaitEvents:
    """Events of one foot found in a vertical force record (s, ascending)."""

    heel_strikes_s: np.ndarray
    toe_offs_s: np.ndarray
    threshold_N: float
    min_duration_s: float


def _crossing(t, f, k, level):
    """Time at which the segment ``(t[k], f[k]) - (t[k+1], f[k+1])`` crosses ``level``."""
    df = f[k + 1] - f[k]
    w = 0.5 if df == 0 else (level - f[k]) / df
    return float(t[k] + w * (t[k + 1] - t[k]))


def gait_events_from_grf(
    time_s,
    vertical_force_N,
    threshold_N: float = DEFAULT_GRF_THRESHOLD_N,
    min_duration_s: float = DEFAULT_MIN_DURATION_S,
) -> GaitEvents:
    """Heel strikes and toe-offs from threshold crossings of the vertical ground reaction force.

    Contact is ``F > threshold_N``. Each crossing time is found by linear interpolation
    between the two samples on either side of the threshold. Noise is handled by
    requiring every contact and every non-contact period to last at least
    ``min_duration_s``: periods shorter than that (measured between crossings, or
    between a crossing and the start/end of the record) are merged into their
    neighbours, shortest first, so a noisy crossing counts once, at its first crossing
    of the threshold. A period cut by the start or end of the record is exempt when the
    force at that edge is clearly on its side (contact: at least twice the threshold; no
    contact: zero or below), so a heel strike 40 ms before the record ends is reported;
    otherwise an event closer than ``min_duration_s`` to either end is not.

    Parameters
    ----------
    time_s : (T,) s, strictly increasing
    vertical_force_N : (T,) N, the analysed foot's vertical force (filter it first if noisy;
        the study low-passes GRF at 35 Hz, ``docs/analysis.md``)
    threshold_N : contact threshold (N), default 20
    min_duration_s : shortest accepted contact or non-contact period (s), default 0.05

    Returns
    -------
    GaitEvents
        ``heel_strikes_s`` (upward crossings) and ``toe_offs_s`` (downward crossings).
    """
    t = as_time(time_s, "time_s")
    f = as_signal(vertical_force_N, t, "vertical_force_N")
    if f.ndim != 1:
        raise DataMismatchError(f"vertical_force_N must be 1-D, not of shape {f.shape}")
    thr = _finite(threshold_N, "threshold_N")
    min_dur = _finite(min_duration_s, "min_duration_s")
    if min_dur < 0:
        raise OptionError(f"min_duration_s must not be negative, not {min_duration_s!r}")

    contact = f > thr
    change = np.flatnonzero(contact[1:] != contact[:-1])
    bounds = [_crossing(t, f, int(k), thr) for k in change]  # run boundaries
    states = [bool(contact[0])] + [bool(contact[k + 1]) for k in change]  # one per run
    # A run cut by the start or end of the record is real whatever its length when the force
    # at that edge is clearly on its side of the threshold (contact: at least twice the
    # threshold; no contact: at most zero): a heel strike shortly before the record ends.
    clear_start = (f[0] >= 2 * thr) if contact[0] else (f[0] <= 0.0)
    clear_end = (f[-1] >= 2 * thr) if contact[-1] else (f[-1] <= 0.0)
    while len(states) > 1:
        edges = [float(t[0])] + bounds + [float(t[-1])]
        dur = np.diff(edges)
        if clear_start:
            dur[0] = np.inf
        if clear_end:
            dur[-1] = np.inf
        j = int(np.argmin(dur))
        if dur[j] >= min_dur:
            break
        if j == 0:  # leading run: take the state of the next run
            del states[0], bounds[0]
        elif j == len(states) - 1:  # trailing run
            del states[-1], bounds[-1]
        else:  # interior run: merge it and its two neighbours into one run
            del states[j:j + 2], bounds[j - 1:j + 1]
    hs = [b for b, s in zip(bounds, states[1:]) if s]
    to = [b for b, s in zip(bounds, states[1:]) if not s]
    return GaitEvents(np.array(hs), np.array(to), thr, min_dur)


#: What the errors of :func:`cycle_from_grf` and :func:`cycle_from_inverse_dynamics` say to do
#: by default (the Python functions; the command line and a study give their options' remedy).
EVENTS_REMEDY = "give the events with GaitCycle.from_times"


def cycle_from_grf(
    time_s,
    vertical_force_N,
    threshold_N: float = DEFAULT_GRF_THRESHOLD_N,
    min_duration_s: float = DEFAULT_MIN_DURATION_S,
    *,
    at_time_s: float | None = None,
    remedy: str | None = None,
) -> GaitCycle:
    """The gait cycle (heel strike, toe-off, next heel strike) from a vertical force record.

    By default the first complete cycle of the record; with ``at_time_s`` the cycle that
    contains that time (``start_s <= at_time_s < end_s``). Events as in
    :func:`gait_events_from_grf`. ``remedy``: what the error says to do (default
    :data:`EVENTS_REMEDY`, this module's functions; the command line and a study name their own).

    Raises
    ------
    DataMismatchError
        The record holds no complete cycle (two heel strikes of the foot), or none
        containing ``at_time_s``; the message lists the events found.
    """
    ev = gait_events_from_grf(time_s, vertical_force_N, threshold_N, min_duration_s)
    hs, to = ev.heel_strikes_s, ev.toe_offs_s
    found = (
        f"heel strikes at {', '.join(f'{x:.3f}' for x in hs) or 'none'} s, toe-offs at "
        f"{', '.join(f'{x:.3f}' for x in to) or 'none'} s (threshold {ev.threshold_N:g} N)"
    )
    at = None if at_time_s is None else _finite(at_time_s, "at_time_s")
    for a, b in zip(hs[:-1], hs[1:]):
        if at is not None and not (a <= at < b):
            continue
        between = to[(to > a) & (to < b)]
        if between.size:
            return GaitCycle(float(a), float(between[0]), float(b))
    where = "" if at is None else f" containing {at:g} s"
    raise DataMismatchError(
        f"no complete gait cycle{where} in the force record: {found}. A cycle needs two heel strikes "
        f"of the same foot; {remedy or EVENTS_REMEDY + ' or use cycle_from_inverse_dynamics'}"
    )


def cycle_from_inverse_dynamics(
    id_time_s,
    ankle_moment_Nm,
    window_s: tuple[float, float] | None = None,
    padding_s: float = DEFAULT_PADDING_S,
    *,
    toe_off_fraction: float = DEFAULT_TOE_OFF_FRACTION,
    plantarflexion_sign: float = -1.0,
    remedy: str | None = None,
) -> GaitCycle:
    """The gait cycle of a padded simulation window, toe-off from the ankle moment
    (``remedy``: what the error of a toe-off that cannot be placed says to do, as for
    :func:`cycle_from_grf`).

    Fallback for data without ground reaction forces (``docs/analysis.md``):

    * initial contact = ``window_s[0] + padding_s``, next initial contact =
      ``window_s[1] - padding_s`` (the IK window of the example spans the cycle plus
      five frames at each end);
    * the plantarflexion moment is ``P(t) = plantarflexion_sign * ankle_moment_Nm``
      (OpenSim: ankle angle positive = dorsiflexion, hence ``-1``); its stance peak
      ``P_max`` is the largest value inside the cycle;
    * toe-off is the first time after the peak at which ``P`` falls to
      ``toe_off_fraction * P_max`` (linear interpolation between samples). With the
      default 1 % this is the instant the moment "returns to about zero"; 0 gives the
      zero crossing itself.

    Parameters
    ----------
    id_time_s : (T,) s
    ankle_moment_Nm : (T,) N m, the analysed side's ankle moment from inverse dynamics
    window_s : (t0, tf) s, the simulated (IK) window; default the span of ``id_time_s``
    padding_s : s removed at each end of the window (0.05)
    toe_off_fraction : fraction of the peak plantarflexion moment defining toe-off (0..1)
    plantarflexion_sign : +1 or -1, the sign of a plantarflexion moment in the file

    Raises
    ------
    DataMismatchError
        The window less the padding is empty or not covered by ``id_time_s``; the cycle
        holds no plantarflexion moment; or the moment does not fall back after its peak.
    OptionError
        Invalid parameters.
    """
    t = as_time(id_time_s, "id_time_s", min_samples=3)
    m = as_signal(ankle_moment_Nm, t, "ankle_moment_Nm")
    if m.ndim != 1:
        raise DataMismatchError(f"ankle_moment_Nm must be 1-D, not of shape {m.shape}")
    if plantarflexion_sign not in (1, -1, 1.0, -1.0):
        raise OptionError(f"plantarflexion_sign must be +1 or -1, not {plantarflexion_sign!r}")
    frac = _finite(toe_off_fraction, "toe_off_fraction")
    if not 0.0 <= frac < 1.0:
        raise OptionError(f"toe_off_fraction must be in [0, 1), not {toe_off_fraction!r}")
    pad = _finite(padding_s, "padding_s")
    if pad < 0:
        raise OptionError(f"padding_s must not be negative, not {padding_s!r}")
    if window_s is None:
        w0, wf = float(t[0]), float(t[-1])
    else:
        try:
            w0, wf = (_finite(x, "window_s") for x in window_s)
        except (TypeError, ValueError):
            raise OptionError(f"window_s must be a pair (t0, tf) in seconds, not {window_s!r}") from None
    start, end = w0 + pad, wf - pad
    if not start < end:
        raise DataMismatchError(
            f"the window {w0:g}-{wf:g} s less {pad:g} s of padding at each end leaves no cycle"
        )
    eps = 1e-9
    if start < t[0] - eps or end > t[-1] + eps:
        raise DataMismatchError(
            f"the inverse-dynamics samples span {t[0]:g}-{t[-1]:g} s but the cycle is {start:g}-{end:g} s; "
            "give the ID file of the simulated window"
        )
    p = float(plantarflexion_sign) * m
    inside = np.flatnonzero((t >= start - eps) & (t <= end + eps))
    k_peak = int(inside[np.argmax(p[inside])])
    peak = float(p[k_peak])
    if not peak > 0:
        raise DataMismatchError(
            f"the ankle moment has no plantarflexion moment inside the cycle {start:g}-{end:g} s "
            f"(largest {peak:g} N m with plantarflexion_sign={plantarflexion_sign:+g}); check the column and the sign"
            + (f" (a window without stance has none: {remedy})" if remedy else "")
        )
    level = frac * peak
    after = inside[inside > k_peak]
    below = after[p[after] <= level]
    if below.size == 0:
        raise DataMismatchError(
            f"the plantarflexion moment does not fall to {frac:g} of its peak ({peak:.1f} N m at "
            f"{t[k_peak]:.3f} s) before the end of the cycle ({end:g} s); toe-off cannot be placed: "
            f"{remedy or EVENTS_REMEDY}"
        )
    k = int(below[0])
    to = _crossing(t, p, k - 1, level)
    return GaitCycle(start, to, end)


def cycle_from_id_file(
    path: str | os.PathLike,
    column: str | None = None,
    *,
    side: str = "r",
    window_s: tuple[float, float] | None = None,
    padding_s: float = DEFAULT_PADDING_S,
    toe_off_fraction: float = DEFAULT_TOE_OFF_FRACTION,
    plantarflexion_sign: float = -1.0,
    remedy: str | None = None,
) -> GaitCycle:
    """:func:`cycle_from_inverse_dynamics` on an OpenSim inverse-dynamics file.

    ``column`` defaults to ``ankle_angle_<side>_moment``; ``window_s`` to the file's time
    span (pass the IK window if the two differ).
    """
    from .io import read_storage, require_columns

    if side not in ("r", "l"):
        raise OptionError(f"side must be 'r' or 'l', not {side!r}")
    df = read_storage(path)
    col = column or f"ankle_angle_{side}_moment"
    require_columns(df, [col], what="ankle moment column")
    return cycle_from_inverse_dynamics(
        df.index.to_numpy(), df[col].to_numpy(), window_s, padding_s,
        toe_off_fraction=toe_off_fraction, plantarflexion_sign=plantarflexion_sign, remedy=remedy,
    )


def cycle_from_external_loads(external_loads, model, side: str, at_time_s: float,
                              threshold_N: float | None = None, remedy: str | None = None) -> GaitCycle:
    """The gait cycle holding ``at_time_s`` of the vertical ground force an OpenSim ExternalLoads
    file (a path, or :class:`~musclemetab.external_loads.ExternalLoads`) applies to the bodies of
    ``side`` of ``model`` (a path or its layout; :func:`musclemetab.external_loads.vertical_force`),
    found as :func:`cycle_from_grf` finds it (``threshold_N``, default 20 N), lasting 0.8-2.0 s
    (:func:`check_cycle_duration`)."""
    from .external_loads import read_external_loads, vertical_force
    from .layout import read_layout

    loads = external_loads if hasattr(external_loads, "datafile") else read_external_loads(external_loads)
    layout = model if hasattr(model, "body_side") else read_layout(model)
    t, force = vertical_force(loads, layout, side)
    cycle = cycle_from_grf(t, force, DEFAULT_GRF_THRESHOLD_N if threshold_N is None else threshold_N,
                           at_time_s=at_time_s, remedy=remedy)
    check_cycle_duration(cycle, where=f"{loads.path} (the forces on the {'right' if side == 'r' else 'left'} foot)")
    return cycle


def cycle_of_trial(ik: str | os.PathLike, *, grf: str | os.PathLike | None = None,
                   id_file: str | os.PathLike | None = None, side: str = "r", model=None,
                   window_s: tuple[float, float] | None = None, remedy: str | None = None,
                   grf_column: str | None = None, threshold_N: float | None = None,
                   external_loads=None) -> tuple[GaitCycle, str]:
    """The gait cycle of a solved trial and where it came from: ``(cycle, source)``.

    With ``grf``: the cycle of the side's vertical ground reaction force that holds the middle
    of the IK window (:func:`cycle_from_grf`; with the ``model``, the force's foot checked against
    its centre of pressure, :func:`grf_of_side`, and the cycle's duration,
    :func:`check_cycle_duration`); else with ``external_loads`` (an OpenSim ExternalLoads file, and
    the ``model``), the cycle of the vertical force it applies to the side's foot that holds the
    middle of the IK window (:func:`cycle_from_external_loads`); otherwise from the inverse
    dynamics ``id_file`` and the IK window (:func:`cycle_from_id_file`: the window less the
    padding at each end, toe-off from the ankle moment; estimated events). ``window_s``: the
    window the solve recorded (``summary.json`` ``time_window_s``), which stands for the IK
    window: a solve over part of the IK file has its cycle in that part. ``remedy``: what an
    error finding the events says to do (:func:`cycle_from_grf`); ``grf_column`` and
    ``threshold_N``: the foot's vertical force column and the contact threshold (default the
    name rule of :func:`read_grf` and 20 N).
    """
    from .io import as_table

    t = np.asarray(as_table(ik).index, dtype=float)  # a path, or the table a solve has read
    part = window_s is not None and (abs(window_s[0] - t[0]) > 1e-6 or abs(window_s[1] - t[-1]) > 1e-6)
    if window_s is not None:
        t = np.asarray(window_s, dtype=float)
    if grf is None and external_loads is not None:
        if model is None:
            raise OptionError("the gait events from an ExternalLoads file need the model (which body is which foot)")
        return (cycle_from_external_loads(external_loads, model, side, 0.5 * (t[0] + t[-1]), threshold_N, remedy),
                "ground reaction forces")
    if grf is not None:
        if model is None:
            force = read_grf(grf, grf_column, side=side)
        else:
            import warnings

            from .errors import WindowWarning

            feet, why = feet_for_checks(model, ik)
            force, notes, _ = grf_of_side(grf, side, grf_column, feet=feet)
            for msg in notes + ([why] if why else []):
                warnings.warn(msg, WindowWarning, stacklevel=2)
        cycle = cycle_from_grf(force.index.to_numpy(float), force.to_numpy(float),
                               DEFAULT_GRF_THRESHOLD_N if threshold_N is None else threshold_N,
                               at_time_s=0.5 * (t[0] + t[-1]), remedy=remedy)
        if model is not None:
            check_cycle_duration(cycle, where=f"{grf} column {force.name}")
        return cycle, "ground reaction forces"
    if id_file is None:
        raise OptionError("give the ground reaction forces (grf) or the inverse dynamics (id_file) of the trial")
    return (cycle_from_id_file(id_file, side=side, window_s=(float(t[0]), float(t[-1])), remedy=remedy),
            f"estimated from the {'solved' if part else 'IK'} window and the ankle moment "
            "(no ground reaction forces)")


def _grf_candidates(side: str) -> list[str]:
    if side == "r":
        return ["ground_force_r_vy", "r_ground_force_vy", "R_ground_force_vy", "ground_force_right_vy",
                "calcn_r_ground_force_vy", "ground_force_vy"]
    return ["ground_force_l_vy", "l_ground_force_vy", "L_ground_force_vy", "ground_force_left_vy",
            "calcn_l_ground_force_vy", "1_ground_force_vy"]


def read_grf(path: str | os.PathLike, column: str | None = None, *, side: str = "r"):
    """The vertical ground reaction force of one foot from an OpenSim ``.mot``/``.sto`` file.

    Column choice when ``column`` is not given: the first present of the side's usual
    names (right: ``ground_force_r_vy``, ``r_ground_force_vy``, ``R_ground_force_vy``,
    ``ground_force_right_vy``, ``calcn_r_ground_force_vy``, then ``ground_force_vy``, the
    first force of OpenSim's example files, which is the right foot; left: the ``_l``/
    ``l_``/``L_`` forms, then ``1_ground_force_vy``); otherwise the only column ending in
    ``ground_force_vy``, if exactly one exists. Anything else raises
    :class:`MissingColumnError` naming the candidate columns: pass ``column=``.

    Returns
    -------
    pandas.Series
        Index ``time`` (s), values in N, name = the column used.
    """
    from .io import read_storage, require_columns

    if side not in ("r", "l"):
        raise OptionError(f"side must be 'r' or 'l', not {side!r}")
    from .external_loads import check_force_columns

    df = read_storage(path)
    check_force_columns(df, path, list(df.columns))  # NaN or inf in any column: named with its times
    if column is not None:
        require_columns(df, [column], what="vertical force column")
        return df[column].rename(column)
    for name in _grf_candidates(side):
        if name in df.columns:
            return df[name].rename(name)
    vy = [c for c in df.columns if c.endswith("ground_force_vy")]
    if len(vy) == 1:
        return df[vy[0]].rename(vy[0])
    cand = [c for c in df.columns if c.lower().endswith("vy") or "force" in c.lower()]
    raise MissingColumnError(
        f"{path}: cannot tell which column is the {'right' if side == 'r' else 'left'} foot's vertical force; "
        f"candidates: {', '.join(cand) or 'none'} (columns: {', '.join(map(str, df.columns[:12]))}"
        f"{' ...' if len(df.columns) > 12 else ''}). Pass column='<name>'"
    )


#: Least prominence (m) of a heel or toe excursion relative to the pelvis that counts as a
#: gait event in :func:`gait_events_from_kinematics` (walking gives 0.4-0.8 m).
KINEMATIC_PROMINENCE_M = 0.1
#: Net horizontal pelvis travel (m) below which the direction of travel is the model's +x.
_MIN_TRAVEL_M = 0.1


def _refined_extrema(t, x, prominence):
    """Times of the local maxima of ``x`` at least ``prominence`` high (parabola through each
    peak and its neighbours).

    The prominence of a peak is its height above the lowest point between it and the nearest
    higher sample on each side, the smaller of the two (as :func:`scipy.signal.find_peaks`).
    Where the record ends before any higher sample (the excursion is cut by the end or the
    start of the record), only the other side counts: a heel strike one sample before the end
    of the record is found as soon as the signal has turned down.
    """
    from scipy.signal import find_peaks

    peaks, _ = find_peaks(x)
    out = []
    for k in peaks:
        higher_left = np.flatnonzero(x[:k] > x[k])
        higher_right = np.flatnonzero(x[k + 1:] > x[k])
        lb = int(higher_left[-1]) if higher_left.size else 0
        rb = k + 1 + int(higher_right[0]) if higher_right.size else x.size - 1
        left, right = x[k] - x[lb:k + 1].min(), x[k] - x[k:rb + 1].min()
        if higher_left.size and not higher_right.size:
            prom = left
        elif higher_right.size and not higher_left.size:
            prom = right
        elif not higher_left.size and not higher_right.size:
            prom = max(left, right)
        else:
            prom = min(left, right)
        if prom < prominence:
            continue
        y0, y1, y2 = x[k - 1], x[k], x[k + 1]
        den = y0 - 2 * y1 + y2
        d = 0.0 if den == 0 else 0.5 * (y0 - y2) / den
        d = min(max(d, -0.5), 0.5)
        out.append(float(t[k] + d * (t[k + 1] - t[k] if d > 0 else t[k] - t[k - 1])))
    return np.array(out)


def gait_events_from_kinematics(time_s, heel_m, toe_m, pelvis_m, up=(0.0, 1.0, 0.0),
                                prominence_m: float = KINEMATIC_PROMINENCE_M) -> GaitEvents:
    """Heel strikes and toe-offs of one foot from positions (Zeni et al. 2008).

    ``heel_m``, ``toe_m``, ``pelvis_m``: ``(T, 3)`` positions in the ground frame (m). The
    direction of travel is the horizontal part of the pelvis's net displacement over the
    record (the model's +x when it travels less than 0.1 m, as on a treadmill). Heel strikes
    are the maxima of the heel's distance ahead of the pelvis along it, toe-offs the minima
    of the toe's; extrema less prominent than ``prominence_m`` are ignored, and so are those at
    the first and last frame (the record may cut an excursion). Times are refined by a
    parabola through the extreme frame and its neighbours. ``threshold_N`` of the result is
    NaN (no force threshold).
    """
    t = as_time(time_s, "time_s")
    heel, toe, pelvis = (np.asarray(a, dtype=float).reshape(t.size, 3) for a in (heel_m, toe_m, pelvis_m))
    up = np.asarray(up, dtype=float) / np.linalg.norm(up)
    travel = pelvis[-1] - pelvis[0]
    travel = travel - (travel @ up) * up
    if np.linalg.norm(travel) < _MIN_TRAVEL_M:
        travel = np.array([1.0, 0.0, 0.0]) - up[0] * up
    fwd = travel / np.linalg.norm(travel)
    hs = _refined_extrema(t, (heel - pelvis) @ fwd, prominence_m)
    to = _refined_extrema(t, -((toe - pelvis) @ fwd), prominence_m)
    return GaitEvents(hs, to, float("nan"), 0.0)


@dataclass(frozen=True)
class FootKinematics:
    """Origins of both feet's heel and toe bodies and of the root body along an IK record
    (ground frame, m), as OpenSim computes them from the model: the input of
    :func:`gait_events_from_kinematics` and :func:`foot_of_force`."""

    time_s: np.ndarray
    heel_m: dict  # side -> (T, 3)
    toe_m: dict  # side -> (T, 3)
    root_m: np.ndarray  # (T, 3)
    up: np.ndarray
    bodies: dict  # side -> (heel body, toe body)

    def events(self, side: str) -> GaitEvents:
        """:func:`gait_events_from_kinematics` of one leg."""
        return gait_events_from_kinematics(self.time_s, self.heel_m[side], self.toe_m[side], self.root_m, up=self.up)


#: Body positions already computed in this process, by model file and IK content (a few entries).
_POSITIONS: dict = {}


def foot_kinematics(model_path, ik_path, layout=None, sides=("r", "l")) -> FootKinematics:
    """:class:`FootKinematics` of a model and its IK file (or its :class:`~musclemetab.io.StorageTable`,
    already read): the origins of each side's heel and toe bodies
    (:func:`musclemetab.layout.foot_bodies`) and of the root body, computed by OpenSim in the
    worker process (one call for all of them)."""
    from .io import as_table
    from .layout import foot_bodies, read_layout
    from .opensim_bridge import call

    layout = layout or read_layout(model_path)
    bodies = {s: foot_bodies(layout, s) for s in sides}
    root = next(j["child"] for j in layout.joints if j["parent"] == layout.ground)
    ik = as_table(ik_path)
    in_degrees = ik.attrs.get("in_degrees")
    if in_degrees is None:  # no header flag: angles beyond 2 pi are degrees
        in_degrees = bool(np.nanmax(np.abs(ik.to_numpy(dtype=float))) > 2 * np.pi)
    names = [b for s in sides for b in bodies[s]] + [root]
    import hashlib

    stat = os.stat(model_path)
    key = (str(model_path), stat.st_mtime_ns, stat.st_size, tuple(ik.columns), bool(in_degrees), tuple(names),
           hashlib.sha256(np.ascontiguousarray(ik.to_numpy(dtype=float)).tobytes()
                          + np.asarray(ik.index, dtype=float).tobytes()).hexdigest())
    pos = _POSITIONS.get(key)
    if pos is None:
        raw = call("model_ops:body_origins", str(model_path), {c: np.ascontiguousarray(ik[c]) for c in ik.columns},
                   in_degrees, names)
        pos = np.asarray(raw["positions_m"], dtype=float)
        if len(_POSITIONS) >= 8:
            _POSITIONS.pop(next(iter(_POSITIONS)))
        _POSITIONS[key] = pos
    g = np.asarray(layout.gravity, dtype=float)
    up = -g / np.linalg.norm(g) if np.linalg.norm(g) > 0 else np.array([0.0, 1.0, 0.0])
    heel = {s: pos[:, 2 * i] for i, s in enumerate(sides)}
    toe = {s: pos[:, 2 * i + 1] for i, s in enumerate(sides)}
    return FootKinematics(np.asarray(ik.index, dtype=float), heel, toe, pos[:, -1], up, bodies)


def feet_for_checks(model_path, ik_path, layout=None) -> tuple[FootKinematics | None, str]:
    """:func:`foot_kinematics` for the checks of ground-force events, or ``(None, why)`` when the
    model's feet cannot be told (e.g. a foot of one body): the checks are then skipped."""
    try:
        return foot_kinematics(model_path, ik_path, layout), ""
    except DataMismatchError as exc:
        return None, f"the force's foot and events are not checked against the kinematics: {exc}"


def kinematic_gait_events(model_path, ik_path, side: str, layout=None) -> GaitEvents:
    """:func:`gait_events_from_kinematics` of one leg from a model and its IK file (or its
    :class:`~musclemetab.io.StorageTable`, already read): the origins of the side's heel and
    toe bodies and of the root body, computed by OpenSim in the worker process."""
    return foot_kinematics(model_path, ik_path, layout, sides=(side,)).events(side)


# --- which foot a ground force belongs to; plausibility of the events

#: A force belongs to a foot when, at contact, its centre of pressure lies at most this far
#: (median horizontal distance, m) from the segment joining the foot's heel and toe body
#: origins, and the other foot is at least twice as far. Walking puts the other foot
#: 0.3-0.6 m away (step length, step width); the foot's own distance is a few cm.
FOOT_DISTANCE_M = 0.15
#: Heel strikes of the ground forces and of the kinematics (Zeni et al. 2008) further apart
#: than this (s) are reported. The coordinate rule precedes force contact by 10-30 ms
#: (gait2392 subject: 19-26 ms).
HEEL_STRIKE_TOLERANCE_S = 0.05
#: Gait-cycle durations (s) accepted as walking: stride times of adults range from about
#: 0.9 s (fast) to 1.6 s (very slow); a shorter or longer "cycle" is a missed or an extra
#: heel strike. Override per solve (``--cycle-duration MIN:MAX``).
WALKING_CYCLE_DURATION_S = (0.8, 2.0)

_SIDE = {"r": "right", "l": "left"}


@dataclass(frozen=True)
class ForceFoot:
    """Which foot a ground force belongs to: ``side`` ('r', 'l' or None when the data do not
    tell), from the median horizontal distance (m) of its centre of pressure at contact to
    each foot (``distance_m``), over ``samples`` contact samples."""

    side: str | None
    distance_m: dict
    samples: int

    def describe(self) -> str:
        """``"0.025 m from the right foot, 0.463 m from the left"`` (median at contact)."""
        parts = [f"{d:.3f} m from the {_SIDE[s]} foot" for s, d in self.distance_m.items()]
        return ", ".join(parts) + f" (median over {self.samples} contact samples)" if parts else "no contact sample"


def _segment_distance(p, a, b, up):
    """Horizontal distance of points ``p`` to the segments ``a``-``b`` (all ``(N, 3)``)."""
    def flat(v):
        return v - np.outer(v @ up, up)

    ab, ap = flat(b - a), flat(p - a)
    den = np.einsum("ij,ij->i", ab, ab)
    u = np.clip(np.einsum("ij,ij->i", ap, ab) / np.where(den > 0, den, 1.0), 0.0, 1.0)
    return np.linalg.norm(ap - u[:, None] * ab, axis=1)


def foot_of_force(time_s, vertical_force_N, cop_m, feet: FootKinematics,
                  contact_fraction: float = 0.1) -> ForceFoot:
    """The foot under a ground force, from its centre of pressure (CoP).

    At the samples where the vertical force exceeds ``contact_fraction`` of its peak (the
    CoP is unreliable at small forces) and that lie within the kinematics, the horizontal
    distance of the CoP from each foot's heel-toe segment (body origins interpolated to the
    force's times) is taken; the medians decide (:data:`FOOT_DISTANCE_M`). ``cop_m``:
    ``(T, 3)`` in the ground frame (m).
    """
    t = as_time(time_s, "time_s")
    f = as_signal(vertical_force_N, t, "vertical_force_N")
    cop = np.asarray(cop_m, dtype=float).reshape(t.size, 3)
    tk = feet.time_s
    on = (f > contact_fraction * max(float(np.max(f)), 0.0)) & (t >= tk[0]) & (t <= tk[-1]) & (f > 0)
    on &= np.all(np.isfinite(cop), axis=1)
    dist = {}
    for s in feet.heel_m:
        a, b = (np.stack([np.interp(t[on], tk, x[:, i]) for i in range(3)], axis=1)
                for x in (feet.heel_m[s], feet.toe_m[s]))
        if on.any():
            dist[s] = float(np.median(_segment_distance(cop[on], a, b, feet.up)))
    side = None
    if dist:
        near = min(dist, key=dist.get)
        others = [d for s, d in dist.items() if s != near]
        if dist[near] <= FOOT_DISTANCE_M and all(d >= 2 * dist[near] for d in others):
            side = near
    return ForceFoot(side, dist, int(on.sum()))


def force_columns(columns) -> dict:
    """The force sets of a ground-force table: ``{vertical column: centre-of-pressure columns
    (x, y, z) or None}``. OpenSim's naming: force ``<P>vx, <P>vy, <P>vz`` and point
    ``<P'>px, <P'>py, <P'>pz`` with ``<P'>`` = ``<P>`` (e.g. ``ground_force_``, ``1_ground_force_``)."""
    cols = set(columns)
    out = {}
    for c in columns:
        if c.endswith("vy") and {c[:-1] + "x", c[:-1] + "z"} <= cols:
            p = [c[:-2] + "p" + a for a in "xyz"]
            out[c] = p if set(p) <= cols else None
    return out


def grf_of_side(path: str | os.PathLike, side: str, column: str | None = None, *,
                feet: FootKinematics | None = None):
    """The vertical ground force of one foot, its foot found from the data when the kinematics
    are given.

    Without ``feet``: :func:`read_grf` (the column name rule, or ``column``). With ``feet``,
    every force set of the file with a centre of pressure is assigned to the foot it lies under
    (:func:`foot_of_force`); the column name is not trusted:

    * ``column`` given and under the other foot: :class:`DataMismatchError` naming what was found;
    * the name rule's column under the other foot while exactly one column lies under this
      foot: that column is used, with a note saying so;
    * no column under this foot while the name rule's one lies under the other:
      :class:`DataMismatchError`.

    Returns ``(series, notes, found)``: the force (index time, s; name = the column), the notes
    (warnings for the record) and the :class:`ForceFoot` of the column used (None when not checked).
    """
    from .io import read_storage

    try:
        named = read_grf(path, column, side=side)
    except MissingColumnError:
        if feet is None or column is not None:
            raise
        named = None
    if feet is None:
        return named, [], None
    df = read_storage(path)
    t = df.index.to_numpy(dtype=float)
    found = {c: foot_of_force(t, df[c].to_numpy(dtype=float), df[p].to_numpy(dtype=float), feet)
             for c, p in force_columns(list(df.columns)).items() if p is not None}
    mine = [c for c, ff in found.items() if ff.side == side]
    other = "l" if side == "r" else "r"
    if named is not None and named.name in found:
        ff = found[named.name]
        if ff.side in (side, None):
            return named, [], ff
        where = (f"; the {_SIDE[side]} foot's force is column {mine[0]} ({found[mine[0]].describe()})"
                 if len(mine) == 1 else f"; no column of the file lies under the {_SIDE[side]} foot")
        msg = (f"{path}: column {named.name} is not the {_SIDE[side]} foot's force: at contact its centre of "
               f"pressure lies under the {_SIDE[other]} foot ({ff.describe()}){where}")
        if column is not None or len(mine) != 1:
            raise DataMismatchError(
                msg + f"; give --grf-column of the {_SIDE[side]} foot's force or solve --side {other}")
        return df[mine[0]].rename(mine[0]), [msg + f": {mine[0]} is used"], found[mine[0]]
    if named is None:
        if len(mine) == 1:
            return df[mine[0]].rename(mine[0]), [], found[mine[0]]
        raise MissingColumnError(
            f"{path}: no column name marks the {_SIDE[side]} foot's force and "
            f"{len(mine)} force columns lie under that foot ("
            + "; ".join(f"{c}: {ff.describe()}" for c, ff in found.items()) + "); pass --grf-column")
    return named, [], None


def check_applied_feet(loads, layout, feet: FootKinematics) -> list[str]:
    """The ExternalForces whose ``applied_to_body`` contradicts their centre of pressure: messages
    for the record (empty when they agree or cannot be checked).

    Each force with a point identifier, expressed in the ground, is assigned to the foot its
    centre of pressure lies under at contact (:func:`foot_of_force`, ``feet`` the
    :class:`FootKinematics` of both feet); a force applied to a body of the other leg is
    reported with what was found. ``loads``: a :class:`musclemetab.external_loads.ExternalLoads`.
    """
    from .io import read_storage
    from .layout import SIDE_NAMES

    g = np.asarray(layout.gravity, dtype=float)
    up = -g / np.linalg.norm(g)
    table = read_storage(loads.datafile)
    t = table.index.to_numpy(dtype=float)
    notes = []
    for f in loads.forces:
        body_side = layout.body_side(f.body)
        if (not f.point_identifier or body_side not in SIDE_NAMES
                or {f.force_expressed_in_body, f.point_expressed_in_body} - {layout.ground, "ground"}):
            continue
        vertical = table[[f"{f.force_identifier}{a}" for a in "xyz"]].to_numpy(dtype=float) @ up
        cop = table[[f"{f.point_identifier}{a}" for a in "xyz"]].to_numpy(dtype=float)
        found = foot_of_force(t, vertical, cop, feet)
        if found.side is not None and found.side != body_side:
            notes.append(
                f"{loads.path}: ExternalForce '{f.name}' is applied to {f.body} ({SIDE_NAMES[body_side]} leg) but its "
                f"centre of pressure lies under the {SIDE_NAMES[found.side]} foot ({found.describe()}); check "
                "applied_to_body and the force identifiers")
    return notes


def check_against_kinematics(cycle: GaitCycle, events: GaitEvents, tolerance_s: float = HEEL_STRIKE_TOLERANCE_S,
                             span_s: tuple[float, float] | None = None) -> list[str]:
    """Disagreements (messages) between the heel strikes of a force-defined ``cycle`` and the
    kinematic heel strikes ``events`` of the same leg: each of the cycle's two heel strikes
    that lies inside ``span_s`` (the kinematics' time span) must have a kinematic heel strike
    within ``tolerance_s`` (:data:`HEEL_STRIKE_TOLERANCE_S`)."""
    hs = np.asarray(events.heel_strikes_s, dtype=float)
    notes = []
    for what, x in (("initial contact", cycle.start_s), ("next initial contact", cycle.end_s)):
        if span_s is not None and not (span_s[0] <= x <= span_s[1]):
            continue
        if hs.size == 0:
            notes.append(f"the ground forces' {what} at {x:.3f} s has no kinematic heel strike (heel furthest ahead "
                         "of the pelvis) to compare with: the kinematics show none")
            continue
        near = float(hs[np.argmin(np.abs(hs - x))])
        if abs(near - x) > tolerance_s:
            notes.append(
                f"the ground forces' {what} at {x:.3f} s and the nearest kinematic heel strike at {near:.3f} s differ "
                f"by {1000 * abs(near - x):.0f} ms, more than {1000 * tolerance_s:.0f} ms: check which foot the force "
                "belongs to and the time axes of the two files")
    return notes


def check_cycle_duration(cycle: GaitCycle, duration_s=WALKING_CYCLE_DURATION_S, where: str = "") -> None:
    """Raise :class:`DataMismatchError` unless the cycle lasts ``duration_s[0]`` to ``duration_s[1]``
    seconds (:data:`WALKING_CYCLE_DURATION_S`); ``duration_s=None`` accepts any duration."""
    if duration_s is None:
        return
    lo, hi = (float(x) for x in duration_s)
    if not lo <= cycle.duration_s <= hi:
        raise DataMismatchError(
            f"{where + ': ' if where else ''}the gait cycle from the heel strike at {cycle.start_s:.3f} s (toe-off "
            f"{cycle.toe_off_s:.3f} s) to the next at {cycle.end_s:.3f} s lasts {cycle.duration_s:.3f} s, outside "
            f"{lo:g}-{hi:g} s, the range of walking: a heel strike is missed or an extra one found (another plate, "
            "the other foot). Check the events, give --window T0:T1, or widen the range with --cycle-duration MIN:MAX"
        )


# --- integrals over (a part of) the gait cycle: shared by the per-muscle, phase and group analyses


def interp_at(t: np.ndarray, y: np.ndarray, tq: float) -> np.ndarray:
    """Linear interpolation of ``y`` (last axis = time) at one time ``tq`` within ``t``."""
    k = int(np.searchsorted(t, tq, side="right")) - 1
    k = min(max(k, 0), t.size - 2)
    w = (tq - t[k]) / (t[k + 1] - t[k])
    return y[..., k] * (1.0 - w) + y[..., k + 1] * w


def integrate_interval(t: np.ndarray, y: np.ndarray, a: float, b: float) -> np.ndarray:
    """``integral_a^b y dt`` by the trapezoidal rule, ``a <= b`` inside ``[t[0], t[-1]]``.

    The samples strictly inside ``(a, b)`` are used as they are; the values at ``a`` and
    ``b`` are linearly interpolated between their neighbouring samples, so that the
    integral is exactly that of the piecewise-linear interpolant of the samples. Works
    along the last axis of ``y``.
    """
    if b < a:
        raise OptionError(f"integration interval [{a:g}, {b:g}] s runs backwards")
    if b == a:
        return np.zeros(y.shape[:-1])
    inside = (t > a) & (t < b)
    tt = np.concatenate(([a], t[inside], [b]))
    yy = np.concatenate(
        (interp_at(t, y, a)[..., None], y[..., inside], interp_at(t, y, b)[..., None]), axis=-1
    )
    return np.trapezoid(yy, tt, axis=-1)


def coverage(t: np.ndarray, start_s: float, end_s: float, tolerance_s: float | None, what: str):
    """The part ``[a, b]`` of the cycle ``[start_s, end_s]`` that the samples cover.

    The samples may miss at most ``tolerance_s`` at either end (default: 1.5 times the
    largest sample interval); the missing part is not extrapolated. Raises
    :class:`DataMismatchError` when more is missing.
    """
    if tolerance_s is None:
        tolerance_s = 1.5 * float(np.max(np.diff(t)))
    if not (np.isfinite(tolerance_s) and tolerance_s >= 0):
        raise OptionError(f"coverage tolerance must be a non-negative number of seconds, not {tolerance_s!r}")
    miss_start = t[0] - start_s
    miss_end = end_s - t[-1]
    if miss_start > tolerance_s or miss_end > tolerance_s:
        raise DataMismatchError(
            f"{what} spans {t[0]:g}-{t[-1]:g} s but the gait cycle spans {start_s:g}-{end_s:g} s "
            f"(more than {tolerance_s:g} s is missing); give samples that cover the cycle, or another cycle"
        )
    return max(start_s, float(t[0])), min(end_s, float(t[-1]))
