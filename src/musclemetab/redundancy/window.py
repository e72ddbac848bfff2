"""The time window of a solve: the IK file, an explicit ``T0:T1``, or a gait cycle from ground forces.

* No window and no cycle: the whole IK file (the study's rule, ``docs/solver.md``).
* ``window=(T0, T1)``: that window; it must lie inside every input (IK, ID, ground forces),
  otherwise :class:`DataMismatchError` names the file that falls short and by how much.
* ``cycle="auto"``: the first complete gait cycle of the solved leg that lies inside every
  input file; ``cycle=N``: the N-th (from 1) complete cycle of the leg. Heel strike to heel
  strike, from the vertical ground force of that leg
  (:func:`musclemetab.external_loads.vertical_force` with an ExternalLoads file; or a
  ground-force file whose column is chosen by :func:`musclemetab.events.read_grf`),
  events by :func:`musclemetab.events.gait_events_from_grf` (20 N threshold); with
  no ground forces, from the kinematics and the model
  (:func:`musclemetab.events.kinematic_gait_events`). With the model at hand, the foot of a
  ground force is found from its centre of pressure (:func:`musclemetab.events.grf_of_side`;
  an ExternalLoads file's ``applied_to_body`` is checked the same way,
  :func:`musclemetab.events.check_applied_feet`), and the force's heel strikes are compared
  with the kinematic ones (within :data:`~musclemetab.events.HEEL_STRIKE_TOLERANCE_S`, 50 ms);
  disagreements are warnings, recorded like those of the padding. A cycle whose duration lies
  outside ``cycle_duration_s`` (0.8-2.0 s for walking) is refused, naming its events. The
  window is the cycle plus the study's padding (:data:`PADDING_S` = 5 frames at 100 Hz at each
  end) so that the free initial and final states do not fall inside the cycle. Where the data
  end before the padding does, the padding is clipped at the edge of the data, a warning is
  issued and recorded (``TrialWindow.warnings``, written to ``summary.json``); only a cycle
  that is itself not inside every input is refused.

The window is then snapped outwards to IK frames (never beyond the data).
"""

from __future__ import annotations

import math
import os
import warnings as _warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DataMismatchError, OptionError, WindowWarning
from ..messages import user_stacklevel
from ..events import WALKING_CYCLE_DURATION_S
from ..io import StorageTable
from ..layout import SIDE_NAMES

__all__ = ["PADDING_S", "TrialWindow", "parse_window", "parse_cycle", "resolve_window", "frames_in_window"]

#: The study's padding of a gait cycle at each end (5 frames at 100 Hz), s.
PADDING_S = 0.05
_TOL = 1e-6


@dataclass(frozen=True)
class TrialWindow:
    """The solved window (s), with the gait cycle it pads when it came from one."""

    start_s: float
    end_s: float
    source: str
    cycle: dict | None = None
    padding_s: tuple[float, float] | None = None
    warnings: tuple[str, ...] = field(default_factory=tuple)

    def record(self) -> dict:
        """JSON-ready description for ``summary.json``."""
        out = {"start_s": self.start_s, "end_s": self.end_s, "source": self.source}
        if self.cycle is not None:
            out["gait_cycle"] = dict(self.cycle)
        if self.padding_s is not None:
            out["padding_s"] = list(self.padding_s)
        out["warnings"] = list(self.warnings)
        return out


def parse_window(text: str, option: str = "--window") -> tuple[float, float]:
    """``"T0:T1"`` (seconds) -> ``(T0, T1)``; :class:`OptionError` naming ``option`` otherwise."""
    try:
        a, b = str(text).split(":")
        t0, t1 = float(a), float(b)
    except ValueError:
        raise OptionError(f"{option} must be T0:T1 in seconds, e.g. 0.6:1.9, not {text!r}") from None
    if not (math.isfinite(t0) and math.isfinite(t1) and t0 < t1):
        raise OptionError(f"{option} {text}: T0 must be finite and before T1")
    return t0, t1


def parse_cycle(text) -> str | int:
    """``"auto"`` or a cycle number from 1; :class:`OptionError` otherwise."""
    if text is None or text == "auto":
        return text
    whole = isinstance(text, int) and not isinstance(text, bool)
    if not whole and isinstance(text, str) and text.strip().isdigit():
        text, whole = int(text), True
    if not whole:  # 1.5, True, "1.5": never read as cycle 1
        raise OptionError(f"--cycle must be 'auto' or a cycle number (1, 2, ...), not {text!r}")
    n = int(text)
    if n < 1:
        raise OptionError(f"--cycle counts from 1, not {n}")
    return n


def _extent(source) -> tuple[float, float]:
    from ..io import as_table

    t = as_table(source).index
    return float(t[0]), float(t[-1])


def resolve_window(
    ik: str | os.PathLike | StorageTable,
    *,
    side: str = "r",
    window: tuple[float, float] | None = None,
    cycle: str | int | None = None,
    id_path: str | os.PathLike | StorageTable | None = None,
    external_loads=None,
    grf_path: str | os.PathLike | None = None,
    layout=None,
    padding_s: float = PADDING_S,
    grf_column: str | None = None,
    grf_threshold_N: float | None = None,
    cycle_duration_s: tuple[float, float] | None = WALKING_CYCLE_DURATION_S,
) -> TrialWindow:
    """The solve window for one leg (see the module docstring); ``grf_column`` names the foot's
    vertical force column of ``grf_path`` (default: the name rule of
    :func:`~musclemetab.events.read_grf`), ``grf_threshold_N`` the contact threshold
    (default 20 N), ``cycle_duration_s`` the accepted cycle durations (default
    :data:`~musclemetab.events.WALKING_CYCLE_DURATION_S`, 0.8-2.0 s; None: any).

    ``ik`` and ``id_path`` are the files or their :class:`~musclemetab.io.StorageTable`, already
    read by :func:`~musclemetab.io.read_table` (a solve reads each file once).
    """
    from ..external_loads import check_inside
    from ..io import as_table, table_path

    if window is not None and cycle is not None:
        raise OptionError("give either --window or --cycle, not both")
    ik_table = as_table(ik)
    ik_t = ik_table.index.copy()
    inputs = [(table_path(ik), "inverse kinematics", (float(ik_t[0]), float(ik_t[-1])))]
    if id_path is not None:
        inputs.append((table_path(id_path), "inverse dynamics", _extent(id_path)))
    if external_loads is not None:
        inputs.append((external_loads.datafile, "ground forces", _extent(external_loads.datafile)))
    elif grf_path is not None:
        inputs.append((Path(grf_path), "ground forces", _extent(grf_path)))
    lo = max(e[0] for _, _, e in inputs)
    hi = min(e[1] for _, _, e in inputs)

    cycle_rec, pads, notes = None, None, []
    if cycle is None:
        if window is None:
            t0, t1 = float(ik_t[0]), float(ik_t[-1])
            source = "inverse-kinematics file"
        else:
            t0, t1 = float(window[0]), float(window[1])
            source = "--window"
        for path, what, (a, b) in inputs:
            check_inside((t0, t1), a, b, path, what)
    else:
        gc, number, cycles, where, event_notes = _cycle(side, cycle, external_loads, grf_path, layout, ik_table,
                                                        grf_column, grf_threshold_N, cycle_duration_s, (lo, hi))
        for msg in event_notes:
            notes.append(msg)
            _warnings.warn(msg, WindowWarning, stacklevel=user_stacklevel())
        leg = "right" if side == "r" else "left"
        span = f"the {leg} leg's gait cycle" + ("" if cycle == "auto" else f" {cycle}")
        if cycle != "auto":
            remedy = "choose another --cycle, or a --window inside every input file"
        else:  # "auto" took the first cycle inside every input file: here none is
            later = ", ".join(f"{c.start_s:.3f}-{c.end_s:.3f}" for c in cycles[1:])
            remedy = ((f"no later cycle of the leg ({later} s) lies inside every input file either; " if later else "")
                      + "give a --window inside every input file")
        for path, what, (a, b) in inputs:
            check_inside((gc.start_s, gc.end_s), a, b, path, what, span=span, remedy=remedy + (
                ", or give the ground forces (--external-loads) instead of --id: the inverse dynamics is then "
                "computed over the whole trial" if what == "inverse dynamics" else ""))
        t0, t1 = gc.start_s - padding_s, gc.end_s + padding_s
        edge_files = [p for p, _, (a, b) in inputs if (t0 < a - _TOL) or (t1 > b + _TOL)]
        t0, t1 = max(t0, lo), min(t1, hi)  # clipped at the edge of the data (said below, once snapped)
        cycle_rec = dict(start_s=gc.start_s, toe_off_s=gc.toe_off_s, end_s=gc.end_s, side=side,
                         number=cycle, index=number, source=where)
        source = f"gait cycle {cycle} of the {leg} leg" + (f" (cycle {number}, the first inside every input file)"
                                                           if cycle == "auto" else "")
    # snap outwards to IK frames, never past the data
    ok = (ik_t >= lo - _TOL) & (ik_t <= hi + _TOL)
    before = np.flatnonzero(ok & (ik_t <= t0 + _TOL))
    after = np.flatnonzero(ok & (ik_t >= t1 - _TOL))
    i0 = int(before[-1]) if before.size else int(np.flatnonzero(ok)[0])
    i1 = int(after[0]) if after.size else int(np.flatnonzero(ok)[-1])
    start, end = float(ik_t[i0]), float(ik_t[i1])
    if cycle_rec is not None:
        pads = (cycle_rec["start_s"] - start, end - cycle_rec["end_s"])
        if edge_files:
            msg = (f"the padding of the gait cycle {gc.start_s:.3f}-{gc.end_s:.3f} s ({padding_s:g} s at each end) runs "
                   f"past the data of {', '.join(map(str, edge_files))}; the solved window, clipped there and on the "
                   f"IK frames, is {start:.3f}-{end:.3f} s: {pads[0]:.3f} s before the cycle and {pads[1]:.3f} s "
                   "after it")
            notes.append(msg)
            _warnings.warn(msg, WindowWarning, stacklevel=user_stacklevel())
    return TrialWindow(start, end, source, cycle_rec, pads, tuple(notes))


def _cycle(side, cycle, external_loads, grf_path, layout, ik=None, grf_column=None, threshold_N=None,
           duration_s=WALKING_CYCLE_DURATION_S, inside_s=(-math.inf, math.inf)):
    """The gait cycle ``cycle`` of the leg, its number (from 1), every complete cycle of the leg,
    where they came from, and the notes (warnings) on its events: the foot of the ground force
    checked against its centre of pressure, and the force's heel strikes against the kinematic
    ones, when the model and the IK are at hand. ``cycle="auto"``: the first complete cycle inside
    ``inside_s`` (the times every input file holds), else the first (which the caller refuses,
    naming the file that falls short)."""
    from ..events import (
        DEFAULT_GRF_THRESHOLD_N,
        GaitCycle,
        check_against_kinematics,
        check_cycle_duration,
        feet_for_checks,
        foot_kinematics,
        gait_events_from_grf,
        grf_of_side,
    )

    forces = external_loads is not None or grf_path is not None
    feet, notes = None, []
    if layout is not None and ik is not None:
        if forces:  # the checks of the force's foot and events: skipped (with a note) for a model without them
            feet, why = feet_for_checks(layout.path, ik, layout)
            notes += [why] if why else []
        else:
            feet = foot_kinematics(layout.path, ik, layout)
    if external_loads is not None:
        from ..events import check_applied_feet
        from ..external_loads import vertical_force

        t, f = vertical_force(external_loads, layout, side)
        where = str(external_loads.path)
        if feet is not None:
            notes += check_applied_feet(external_loads, layout, feet)
    elif grf_path is not None:
        s, found_notes, found = grf_of_side(grf_path, side, grf_column, feet=feet)
        notes += found_notes
        t, f = s.index.to_numpy(dtype=float), s.to_numpy(dtype=float)
        under = "" if found is None else f", centre of pressure under the {SIDE_NAMES[side]} foot"
        where = f"{grf_path} column {s.name}{under}"
    elif feet is not None:
        from ..io import table_path

        where = f"{table_path(ik)} (kinematics: heel and toe relative to the pelvis)"
    else:
        raise OptionError("--cycle needs ground forces (--external-loads GRF.xml or --grf GRF.mot) or the model "
                          "for gait events from kinematics")
    ev = (gait_events_from_grf(t, f, DEFAULT_GRF_THRESHOLD_N if threshold_N is None else threshold_N)
          if forces else feet.events(side))
    hs, to = ev.heel_strikes_s, ev.toe_offs_s
    cycles = []
    for a, b in zip(hs[:-1], hs[1:]):
        between = to[(to > a) & (to < b)]
        if between.size:
            cycles.append(GaitCycle(float(a), float(between[0]), float(b)))
    if cycle == "auto":  # inside as the caller's check_inside has it
        from ..external_loads import SAMPLE_TIME_TOLERANCE_S as tol

        fits = [k for k, c in enumerate(cycles, 1) if c.start_s >= inside_s[0] - tol and c.end_s <= inside_s[1] + tol]
        n = fits[0] if fits else 1
    else:
        n = int(cycle)
    if len(cycles) < n:
        found = (
            f"heel strikes at {', '.join(f'{x:.3f}' for x in hs) or 'none'} s, toe-offs at "
            f"{', '.join(f'{x:.3f}' for x in to) or 'none'} s"
        )
        rule = "ground force" if np.isfinite(ev.threshold_N) else "kinematics"
        how = f", threshold {ev.threshold_N:g} N" if np.isfinite(ev.threshold_N) else ""
        raise DataMismatchError(
            f"{where}: the {'right' if side == 'r' else 'left'} leg's {rule} gives "
            f"{len(cycles)} complete gait cycle{'s' if len(cycles) != 1 else ''} ({found}{how}), so cycle "
            f"{cycle} does not exist; give --window T0:T1"
        )
    gc = cycles[n - 1]
    check_cycle_duration(gc, duration_s, f"{where}: cycle {cycle} of the {SIDE_NAMES[side]} leg")
    if forces and feet is not None:
        span = (float(feet.time_s[1]), float(feet.time_s[-2]))  # an extreme needs a frame on either side
        notes += check_against_kinematics(gc, feet.events(side), span_s=span)
    return gc, n, cycles, where, notes


def frames_in_window(time_s: np.ndarray, window: TrialWindow) -> np.ndarray:
    """Indices of the frames inside the window (inclusive, 1 microsecond of slack)."""
    t = np.asarray(time_s, dtype=float)
    idx = np.flatnonzero((t >= window.start_s - _TOL) & (t <= window.end_s + _TOL))
    if idx.size < 2:
        raise DataMismatchError(
            f"the window {window.start_s:.3f}-{window.end_s:.3f} s holds fewer than two frames; widen it"
        )
    return idx
