"""Force plates: offsets, foot contacts, and which foot stands on each.

* :func:`remove_offsets`: a plate that is not zeroed reads a constant force and moment while
  unloaded (walking2.c3d: -14 N and -20 N). The offset is the median of each component over the
  samples where the plate is unloaded (vertical force within :data:`CONTACT_THRESHOLD_N` of the
  plate's lowest readings) and is subtracted from every sample.
* :func:`assign_feet`: each contact of a plate (a run of samples whose vertical force exceeds
  :data:`CONTACT_THRESHOLD_N`) goes to the foot nearest to the centre of pressure, by the data,
  never by the plate's number: at every marker frame of the contact, the horizontal distance from
  the centre of pressure to each foot (the segments from its heel marker to its other foot
  markers) is measured; the foot nearest at most of the contact's vertical impulse takes it. A
  contact where the other foot is nearest for more than :data:`TWO_FEET_SHARE` of the impulse, or
  where both feet stand on the plate at once (a marker of each foot over the plate, moving
  slower than :data:`STANDING_SPEED_M_S`, for :data:`TWO_FEET_MIN_S` or longer), is flagged: it
  carries both feet, its force cannot be split between them, and it is given to the foot nearer
  for most of it with a warning; the record says so (``two_feet``).
* A contact whose foot stands partly off the plate is flagged too (``partly_off``): while the
  foot stands (a marker of it slower than :data:`STANDING_SPEED_M_S`) from
  :data:`LANDING_S` before the plate is loaded to the contact's end, one of its markers at rest lies
  more than :data:`OFF_PLATE_M` outside the plate's outline, so part of the foot's load is
  elsewhere (the floor, another plate) and the plate's force is not the whole foot's.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import asdict, dataclass

import numpy as np

from ..errors import DataMismatchError, MusclemetabWarning, OptionError
from .trial import Markers, Plate, horizontal
from ..messages import name_list

__all__ = ["CONTACT_THRESHOLD_N", "PlateContact", "remove_offsets", "contacts", "foot_marker_sets",
           "assign_feet", "check_plate_feet", "TwoFeetWarning", "PartlyOffPlateWarning", "SameFootOverlapWarning"]

#: vertical force (N) above which a plate is loaded (the package's gait-event threshold)
CONTACT_THRESHOLD_N = 20.0
#: runs of load shorter than this (s) are noise, not contacts
MIN_CONTACT_S = 0.02
#: share of a contact's impulse at which the other foot's presence flags it
TWO_FEET_SHARE = 0.10
#: a foot over a plate and slower than this (m/s) stands on it
STANDING_SPEED_M_S = 0.3
#: both feet standing on one plate this long (s) flag the contact
TWO_FEET_MIN_S = 0.02
#: the nearest foot must be this close (m) to the centre of pressure
MAX_FOOT_DISTANCE_M = 0.25
#: a marker of the standing foot this far (m) outside the plate's outline puts the foot partly off
#: it (the heel and toe markers sit within about 2 cm of the sole's outline, seen from above)
OFF_PLATE_M = 0.04
#: how long (s) before a plate is loaded its foot is looked at: a heel landing off the plate lands
#: before the plate feels the forefoot
LANDING_S = 0.1

SIDES = ("r", "l")
_SIDE_WORDS = {"r": ("R", "RIGHT"), "l": ("L", "LEFT")}


class TwoFeetWarning(MusclemetabWarning):
    """A force-plate contact carries both feet at once: its force is given to one foot."""


class PartlyOffPlateWarning(MusclemetabWarning):
    """A foot stands partly off the force plate that carries it: the plate misses part of its load."""


class SameFootOverlapWarning(MusclemetabWarning):
    """Two force plates given to one foot by hand (``--plate-feet``) are loaded at the same time:
    that foot gets the sum of both plates' forces there."""


@dataclass
class PlateContact:
    """One contact of a plate: its time span, the foot given it and the evidence."""

    plate: int
    start_s: float
    end_s: float
    side: str
    share: dict
    two_feet: bool
    peak_vertical_n: float
    impulse_ns: float
    how: str = "centre of pressure"
    partly_off: dict | None = None
    #: the contacts of other plates given to the same foot loaded at the same time (``plate``,
    #: ``start_s``, ``end_s`` of the overlap), when a plate was given by hand
    overlaps: list | None = None

    def record(self) -> dict:
        return asdict(self)


def remove_offsets(plate: Plate, threshold_n: float = CONTACT_THRESHOLD_N) -> bool:
    """Subtract the unloaded reading of every component (module docstring); ``False`` when the
    plate is never unloaded for long enough (a tenth of a second), and nothing is changed."""
    fv = plate.vertical()
    low = np.median(np.sort(fv)[: max(1, len(fv) // 10)])
    quiet = np.abs(fv - low) < threshold_n / 2
    rate = 1.0 / np.median(np.diff(plate.time)) if len(plate.time) > 1 else 1.0
    if quiet.sum() < 0.1 * rate or low > threshold_n:
        return False
    plate.offset_force = np.median(plate.force[quiet], axis=0)
    plate.offset_moment = np.median(plate.moment[quiet], axis=0)
    plate.force = plate.force - plate.offset_force
    plate.moment = plate.moment - plate.offset_moment
    return True


def contacts(plate: Plate, threshold_n: float = CONTACT_THRESHOLD_N) -> list[tuple[int, int]]:
    """Index ranges ``[i0, i1)`` of the plate's contacts."""
    on = plate.vertical() > threshold_n
    edges = np.flatnonzero(np.diff(np.concatenate([[0], on.astype(int), [0]])))
    runs = list(zip(edges[::2], edges[1::2]))
    dt = float(np.median(np.diff(plate.time))) if len(plate.time) > 1 else 1.0
    return [(int(a), int(b)) for a, b in runs if (b - a) * dt >= MIN_CONTACT_S]


def _split_name(name: str) -> tuple[str | None, str]:
    """``(side, rest)`` of a marker name: ``RHEE``, ``R.Heel``, ``Right_Heel``, ``heel_r``."""
    m = re.match(r"^(right|left)[._\s-]*(.+)$", name, re.I) or re.match(r"^([RL])(?:[._\s-]+|(?=[A-Z0-9]))(.+)$",
                                                                          name)
    if m:
        return ("r" if m.group(1)[0] in "rR" else "l"), m.group(2)
    m = re.match(r"^(.+?)[._\s-]+(r|l|right|left)$", name, re.I)
    if m:
        return ("r" if m.group(2)[0] in "rR" else "l"), m.group(1)
    return None, name


def _role(rest: str) -> str | None:
    key = re.sub(r"[^A-Z0-9]", "", rest.upper())
    if key.startswith(("HEE", "CAL")):
        return "heel"
    if key.startswith(("TOE", "HAL", "MIDFOOT", "FOREFOOT", "FMH", "VMH")) \
            or re.match(r"^(MT|MET|MTH|MH|META|M)\d", key) or re.match(r"^(MT|MET)[HP]?\d?$", key):
        return "fore"
    return None


def foot_marker_sets(names: list[str], given: dict | None = None) -> dict[str, dict[str, list[str]]]:
    """``{side: {"heel": [...], "fore": [...]}}`` from the marker names (``RHEE``/``RCAL``/``R.Heel``
    heel; ``RTOE``/``RMT2``/``RFMH``/``RVMH``/``R.Toe.Tip``/``R.Midfoot.Sup`` forefoot), or from ``given``
    (``{side: [heel marker, other foot markers...]}``)."""
    out = {s: {"heel": [], "fore": []} for s in SIDES}
    if given:
        for side, items in given.items():
            missing = [n for n in items if n not in names]
            if missing:
                raise OptionError(f"foot markers {name_list(missing)} are not in the file's markers")
            out[side] = {"heel": [items[0]], "fore": list(items[1:])}
        return out
    for n in names:
        side, rest = _split_name(n)
        role = _role(rest) if side else None
        if role:
            out[side][role].append(n)
    return out


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance (rows) from points ``p`` to segments ``a``-``b`` (2-D, rows)."""
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12), 0, 1)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def _foot_distance(cop_h: np.ndarray, markers: Markers, feet: dict, frames: np.ndarray) -> np.ndarray:
    d = np.full(len(frames), np.inf)
    for heel in feet["heel"]:
        a = horizontal(markers.marker(heel)[frames])
        for fore in feet["fore"]:
            b = horizontal(markers.marker(fore)[frames])
            dist = _segment_distance(cop_h, a, b)
            d = np.fmin(d, np.where(np.isfinite(dist), dist, np.inf))
    return d


def _inside(points_h: np.ndarray, corners_h: np.ndarray) -> np.ndarray:
    """Whether horizontal points lie inside the plate's (convex) outline."""
    c = corners_h
    centre = c.mean(axis=0)
    inside = np.ones(len(points_h), dtype=bool)
    for i in range(len(c)):
        a, b = c[i], c[(i + 1) % len(c)]
        edge = b - a
        side_centre = np.sign(edge[0] * (centre - a)[1] - edge[1] * (centre - a)[0])
        cross = edge[0] * (points_h[:, 1] - a[1]) - edge[1] * (points_h[:, 0] - a[0])
        inside &= np.sign(cross) * side_centre >= 0
    return inside & np.all(np.isfinite(points_h), axis=1)


def _standing(markers: Markers, feet: dict, plate: Plate) -> np.ndarray:
    """Per marker frame: a marker of the foot lies over the plate and moves slower than
    :data:`STANDING_SPEED_M_S`."""
    names = feet["heel"] + feet["fore"]
    out = np.zeros(len(markers.time), dtype=bool)
    corners_h = horizontal(plate.corners)
    for n in names:
        xyz = markers.marker(n)
        speed = np.linalg.norm(np.gradient(xyz, markers.time, axis=0), axis=1) if len(markers.time) > 2 \
            else np.zeros(len(markers.time))
        out |= _inside(horizontal(xyz), corners_h) & (speed < STANDING_SPEED_M_S)
    return out


def _outside_by(points_h: np.ndarray, corners_h: np.ndarray) -> np.ndarray:
    """Horizontal distance (m) of points outside the plate's outline (0 inside, NaN unknown)."""
    d = np.full(len(points_h), np.inf)
    for i in range(len(corners_h)):
        a = np.tile(corners_h[i], (len(points_h), 1))
        b = np.tile(corners_h[(i + 1) % len(corners_h)], (len(points_h), 1))
        d = np.fmin(d, _segment_distance(points_h, a, b))
    out = np.where(_inside(points_h, corners_h), 0.0, d)
    return np.where(np.all(np.isfinite(points_h), axis=1), out, np.nan)


def partly_off(markers: Markers, foot: dict, plate: Plate, t0: float, t1: float) -> dict | None:
    """Where the foot ``foot`` (``{"heel": [...], "fore": [...]}``) stands partly off ``plate``
    during its contact ``t0``-``t1`` (module docstring): ``{"marker", "time_s", "outside_m"}`` of
    the standing marker farthest outside, or ``None``."""
    frames = np.flatnonzero((markers.time >= t0 - LANDING_S) & (markers.time <= t1))
    if len(frames) < 3 or len(markers.time) < 3:
        return None
    corners_h = horizontal(plate.corners)
    worst = None
    for name in foot["heel"] + foot["fore"]:
        xyz = markers.marker(name)
        speed = np.linalg.norm(np.gradient(xyz, markers.time, axis=0), axis=1)[frames]
        outside = _outside_by(horizontal(xyz[frames]), corners_h)
        at_rest = (speed < STANDING_SPEED_M_S) & np.isfinite(outside)
        if not at_rest.any():
            continue
        k = int(np.argmax(np.where(at_rest, outside, -1.0)))
        if outside[k] > OFF_PLATE_M and (worst is None or outside[k] > worst["outside_m"]):
            worst = {"marker": name, "time_s": float(markers.time[frames[k]]), "outside_m": float(outside[k])}
    return worst


def check_plate_feet(plate_feet: dict | None, plates: list[Plate], source: str = "") -> None:
    """Refuse a plate of ``plate_feet`` (``{plate number: side}``, ``--plate-feet``) that the file
    ``source`` does not have, naming the plates it has."""
    have = [p.number for p in plates]
    missing = sorted(int(n) for n in (plate_feet or {}) if int(n) not in have)
    if missing:
        plural = "s" if len(missing) > 1 else ""
        given = " ".join(f"{n}={plate_feet[n]}" for n in missing)
        has = f"its force plates are {name_list(have)}" if have else "it has no force plate"
        raise OptionError(f"--plate-feet {given}: {source} has no force plate{plural} {name_list(missing)}; {has}")


def _same_foot_overlaps(out: list[PlateContact], source: str) -> None:
    """Mark and warn about contacts of different plates given to one foot that overlap in time,
    where a plate was given by hand (:class:`SameFootOverlapWarning`)."""
    for i, a in enumerate(out):
        for b in out[i + 1:]:
            if a.side != b.side or a.plate == b.plate or "given" not in (a.how, b.how):
                continue
            t0, t1 = max(a.start_s, b.start_s), min(a.end_s, b.end_s)
            if t1 <= t0:
                continue
            for c, other in ((a, b), (b, a)):
                c.overlaps = (c.overlaps or []) + [{"plate": other.plate, "start_s": t0, "end_s": t1}]
            first, second = sorted((a, b), key=lambda c: c.plate)
            foot = "right" if a.side == "r" else "left"
            warnings.warn(
                f"{source}: force plates {first.plate} and {second.plate} are both given to the {foot} foot "
                f"(--plate-feet) and are loaded at the same time, {t0:.3f}-{t1:.3f} s (plate {first.plate} "
                f"{first.start_s:.3f}-{first.end_s:.3f} s, plate {second.plate} {second.start_s:.3f}-{second.end_s:.3f} "
                f"s): the {foot} foot gets both plates' forces together there, which is right only when it stands on "
                "both plates at once; else give one of them to the other foot",
                SameFootOverlapWarning, stacklevel=3)


def assign_feet(plates: list[Plate], markers: Markers, *, feet: dict | None = None,
                plate_feet: dict | None = None, threshold_n: float = CONTACT_THRESHOLD_N,
                source: str = "") -> list[PlateContact]:
    """The contacts of every plate with the foot each is given (module docstring).

    ``feet``: ``{side: {"heel": [...], "fore": [...]}}`` (default :func:`foot_marker_sets` of the
    marker names); ``plate_feet``: ``{plate number: side}`` to give whole plates by hand (the
    record says ``how="given"``; a plate the file lacks is refused, and two plates given to one
    foot loaded at the same time are flagged, ``overlaps``, with a :class:`SameFootOverlapWarning`).

    Raises :class:`DataMismatchError` when a foot has no heel or no forefoot marker, or no foot
    is near a contact's centre of pressure (markers missing).
    """
    plate_feet = {int(k): v for k, v in (plate_feet or {}).items()}
    check_plate_feet(plate_feet, plates, source)
    feet = feet or foot_marker_sets(markers.names)
    need = [p for p in plates if p.number not in plate_feet]
    for side in SIDES:
        if need and (not feet[side]["heel"] or not feet[side]["fore"]):
            raise DataMismatchError(
                f"{source}: no {'heel' if not feet[side]['heel'] else 'toe'} marker of the "
                f"{'right' if side == 'r' else 'left'} foot is recognised among the markers "
                f"({', '.join(markers.names[:12])}{' ...' if len(markers.names) > 12 else ''}); name the foot "
                "markers (--foot-markers r=RHEE,RTOE l=LHEE,LTOE) or the plates' feet (--plate-feet 1=r,2=l)"
            )
    out = []
    for plate in plates:
        cop, _ = plate.centre_of_pressure(threshold_n)
        fv = plate.vertical()
        standing = {s: _standing(markers, feet[s], plate) for s in SIDES} if plate.number not in plate_feet else {}
        for i0, i1 in contacts(plate, threshold_n):
            t0, t1 = float(plate.time[i0]), float(plate.time[i1 - 1])
            dt = float(np.median(np.diff(plate.time)))
            base = dict(plate=plate.number, start_s=t0, end_s=t1, peak_vertical_n=float(fv[i0:i1].max()),
                        impulse_ns=float(fv[i0:i1].sum() * dt))
            if plate.number in plate_feet:
                side = plate_feet[plate.number]
                out.append(PlateContact(side=side, share={side: 1.0}, two_feet=False, how="given", **base))
                continue
            frames = np.flatnonzero((markers.time >= t0) & (markers.time <= t1))
            if len(frames) == 0:  # a contact shorter than a marker frame: the nearest frame
                frames = np.array([int(np.argmin(np.abs(markers.time - 0.5 * (t0 + t1))))])
            idx = np.clip(np.searchsorted(plate.time, markers.time[frames]), i0, i1 - 1)
            cop_h = horizontal(cop[idx])
            w = fv[idx]
            dist = np.vstack([_foot_distance(cop_h, markers, feet[s], frames) for s in SIDES])
            near = np.argmin(dist, axis=0)
            known = np.isfinite(dist.min(axis=0)) & (dist.min(axis=0) <= MAX_FOOT_DISTANCE_M)
            if not known.any():
                raise DataMismatchError(
                    f"{source}: no foot marker lies within {MAX_FOOT_DISTANCE_M:g} m of force plate {plate.number}'s "
                    f"centre of pressure during its contact at {t0:.3f}-{t1:.3f} s (foot markers missing?); give the "
                    "plates' feet (--plate-feet 1=r,2=l)"
                )
            total = float(w[known].sum())
            share = {s: float(w[known & (near == k)].sum() / total) for k, s in enumerate(SIDES)}
            side = max(share, key=share.get)
            both = standing["r"][frames] & standing["l"][frames]
            rate = markers.rate_hz or 1.0
            two = min(share.values()) > TWO_FEET_SHARE or both.sum() / rate >= TWO_FEET_MIN_S
            off = partly_off(markers, feet[side], plate, t0, t1)
            contact = PlateContact(side=side, share=share, two_feet=bool(two), partly_off=off, **base)
            if off is not None:
                warnings.warn(
                    f"{source}: the {'right' if side == 'r' else 'left'} foot stands partly off force plate "
                    f"{plate.number} during its contact at {t0:.3f}-{t1:.3f} s (marker {off['marker']} at rest "
                    f"{100 * off['outside_m']:.0f} cm outside the plate at {off['time_s']:.3f} s): the plate misses "
                    "part of the foot's load; leave the gait cycles that hold this contact out",
                    PartlyOffPlateWarning, stacklevel=2)
            if two:
                warnings.warn(
                    f"{source}: force plate {plate.number} carries both feet at once during its contact at "
                    f"{t0:.3f}-{t1:.3f} s (the centre of pressure is nearer the right foot for "
                    f"{100 * share['r']:.0f} % and the left for {100 * share['l']:.0f} % of the impulse"
                    f"{'; both feet stand on it' if both.any() else ''}); its force cannot be split and is applied to "
                    f"the {'right' if side == 'r' else 'left'} foot: leave the gait cycles that hold it out",
                    TwoFeetWarning, stacklevel=2)
            out.append(contact)
    _same_foot_overlaps(out, source)
    return out
