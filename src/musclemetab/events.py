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
    "cycle_from_inverse_dynamics",
    "cycle_from_id_file",
    "cycle_of_trial",
    "read_grf",
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


def cycle_from_grf(
    time_s,
    vertical_force_N,
    threshold_N: float = DEFAULT_GRF_THRESHOLD_N,
    min_duration_s: float = DEFAULT_MIN_DURATION_S,
    *,
    at_time_s: float | None = None,
) -> GaitCycle:
    """The gait cycle (heel strike, toe-off, next heel strike) from a vertical force record.

    By default the first complete cycle of the record; with ``at_time_s`` the cycle that
    contains that time (``start_s <= at_time_s < end_s``). Events as in
    :func:`gait_events_from_grf`.

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
        "of the same foot; give the events with GaitCycle.from_times or use cycle_from_inverse_dynamics"
    )


def cycle_from_inverse_dynamics(
    id_time_s,
    ankle_moment_Nm,
    window_s: tuple[float, float] | None = None,
    padding_s: float = DEFAULT_PADDING_S,
    *,
    toe_off_fraction: float = DEFAULT_TOE_OFF_FRACTION,
    plantarflexion_sign: float = -1.0,
) -> GaitCycle:
    """The gait cycle of a padded simulation window, toe-off from the ankle moment.

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
        )
    level = frac * peak
    after = inside[inside > k_peak]
    below = after[p[after] <= level]
    if below.size == 0:
        raise DataMismatchError(
            f"the plantarflexion moment does not fall to {frac:g} of its peak ({peak:.1f} N m at "
            f"{t[k_peak]:.3f} s) before the end of the cycle ({end:g} s); toe-off cannot be placed. "
            "Give the events with GaitCycle.from_times"
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
        toe_off_fraction=toe_off_fraction, plantarflexion_sign=plantarflexion_sign,
    )


def cycle_of_trial(ik: str | os.PathLike, *, grf: str | os.PathLike | None = None,
                   id_file: str | os.PathLike | None = None, side: str = "r") -> tuple[GaitCycle, str]:
    """The gait cycle of a solved trial and where it came from: ``(cycle, source)``.

    With ``grf``: the cycle of the side's vertical ground reaction force that holds the middle
    of the IK window (:func:`cycle_from_grf`); otherwise from the inverse dynamics ``id_file``
    and the IK window (:func:`cycle_from_id_file`: the window less the padding at each end,
    toe-off from the ankle moment; estimated events).
    """
    from .io import read_storage

    t = read_storage(ik).index.to_numpy(float)
    if grf is not None:
        force = read_grf(grf, side=side)
        return (cycle_from_grf(force.index.to_numpy(float), force.to_numpy(float), at_time_s=0.5 * (t[0] + t[-1])),
                "ground reaction forces")
    if id_file is None:
        raise OptionError("give the ground reaction forces (grf) or the inverse dynamics (id_file) of the trial")
    return (cycle_from_id_file(id_file, side=side, window_s=(float(t[0]), float(t[-1]))),
            "estimated from the IK window and the ankle moment (no ground reaction forces)")


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
    """Times of the local maxima of ``x`` (parabola through each peak and its neighbours)."""
    from scipy.signal import find_peaks

    peaks, _ = find_peaks(x, prominence=prominence)
    out = []
    for k in peaks:
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


def kinematic_gait_events(model_path, ik_path, side: str, layout=None) -> GaitEvents:
    """:func:`gait_events_from_kinematics` of one leg from a model and its IK file (or its
    :class:`~musclemetab.io.StorageTable`, already read): the origins of the side's heel and
    toe bodies and of the root body, computed by OpenSim in the worker process."""
    from .io import as_table
    from .layout import foot_bodies, read_layout
    from .opensim_bridge import call

    layout = layout or read_layout(model_path)
    heel, toe = foot_bodies(layout, side)
    root = next(j["child"] for j in layout.joints if j["parent"] == layout.ground)
    ik = as_table(ik_path)
    in_degrees = ik.attrs.get("in_degrees")
    if in_degrees is None:  # no header flag: angles beyond 2 pi are degrees
        in_degrees = bool(np.nanmax(np.abs(ik.to_numpy(dtype=float))) > 2 * np.pi)
    raw = call("model_ops:body_origins", str(model_path), {c: np.ascontiguousarray(ik[c]) for c in ik.columns},
               in_degrees, [heel, toe, root])
    pos = np.asarray(raw["positions_m"], dtype=float)
    g = np.asarray(layout.gravity, dtype=float)
    up = -g if np.linalg.norm(g) > 0 else (0.0, 1.0, 0.0)
    return gait_events_from_kinematics(np.asarray(ik.index, dtype=float), pos[:, 0], pos[:, 1], pos[:, 2], up=up)


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
