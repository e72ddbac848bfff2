"""Gait cycle and walking speed of a study trial, from what the trial provides.

Order of preference for the cycle (initial contact, toe-off, next initial contact):

1. times given in the study file (``start_s``, ``toe_off_s``, ``end_s``; any subset: the
   rest is found as below);
2. ground reaction forces (``grf``, or with the subject's model those ``external_loads``
   applies to the foot of the side): threshold crossings of the vertical force
   (``grf_threshold_N``, 20 N by default), the cycle holding the middle of the IK window;
3. otherwise: the cycle is the IK window less 0.05 s of padding at both ends (the
   example data carry five extra frames at 100 Hz at each end) and toe-off is found
   from the ankle moment of inverse dynamics (see
   :func:`musclemetab.events.cycle_from_inverse_dynamics`), the column
   ``ankle_angle_<side>_moment`` of the subject's side (the naming of the Rajagopal and
   gait2392 families; for other models give the trial ``cycle = "auto"``, which finds the
   events from ground forces or from the kinematics, ground forces, or the events).

A trial with a ``window`` (the solve of ``musclemetab solve --window``) has its window in
place of the IK window in 2. and 3. (the solved window, snapped to IK frames), as
``musclemetab analyse`` finds the cycle of such a solve.

Speed: the study file's ``speed_m_per_s``, else the displacement of the model's forward
translation coordinates over the cycle (:func:`musclemetab.analysis.speed.walking_speed_from_ik`;
the IK file less the padding, or ``start_s`` to ``end_s``; a trial with a ``window``: its cycle).
"""

from __future__ import annotations

from ..events import GaitCycle, cycle_from_grf, cycle_from_id_file, read_grf
from ..analysis.speed import walking_speed_from_ik
from .spec import Trial

__all__ = ["trial_cycle", "trial_speed", "rates_span_s", "PADDING_S", "ankle_moment_column"]

PADDING_S = 0.05


def ankle_moment_column(side: str = "r") -> str:
    """The ankle moment column of the Rajagopal and gait2392 naming for one side."""
    return f"ankle_angle_{side}_moment"


def _ik_window(trial: Trial) -> tuple[float, float]:
    """The simulated window: the IK file's, or the trial's ``window`` snapped outwards to IK
    frames as the solve snaps it (:func:`musclemetab.redundancy.window.resolve_window`)."""
    from ..io import read_storage

    if trial.window is not None:
        from ..redundancy.window import resolve_window

        w = resolve_window(trial.ik, window=trial.window)
        return w.start_s, w.end_s
    t = read_storage(trial.ik).index.to_numpy(float)
    return float(t[0]), float(t[-1])


def trial_cycle(trial: Trial, side: str = "r", model=None, *, window_s: tuple[float, float] | None = None,
                id_file=None) -> GaitCycle:
    """The trial's gait cycle (see the module docstring for the order of preference). With the
    subject's ``model``, the foot of a ``grf`` force is checked against its centre of pressure
    (:func:`musclemetab.events.grf_of_side`, warnings for what it finds) and a cycle found from it
    must last 0.8-2.0 s (:func:`musclemetab.events.check_cycle_duration`).

    A trial with a ``window`` has its cycle in that window, which stands for the IK window
    (``window_s``: the window the solve recorded; default the trial's, snapped to IK frames), as
    ``musclemetab analyse`` finds the cycle of a solve over ``--window``
    (:func:`musclemetab.events.cycle_of_trial`); ``id_file``: the inverse dynamics for the events
    (default the trial's ``id``; the one OpenSim computed for a trial without it)."""
    if window_s is None and trial.window is not None:
        window_s = _ik_window(trial)
    given = (trial.start_s, trial.toe_off_s, trial.end_s)
    if all(v is not None for v in given):
        return GaitCycle(*given)
    if trial.grf is not None:
        if model is not None:
            import warnings

            from ..errors import WindowWarning
            from ..events import feet_for_checks, grf_of_side

            feet, why = feet_for_checks(model, trial.ik)
            force, notes, _ = grf_of_side(trial.grf, side, trial.grf_column, feet=feet)
            for msg in notes + ([why] if why else []):
                warnings.warn(f"trial '{trial.name}': {msg}", WindowWarning, stacklevel=2)
        else:
            force = read_grf(trial.grf, trial.grf_column, side=side)
        t0, tf = window_s or _ik_window(trial)  # the cycle that holds the middle of the simulated window
        from ..errors import DataMismatchError

        try:
            found = cycle_from_grf(force.index.to_numpy(float), force.to_numpy(float),
                                   threshold_N=trial.grf_threshold_N,
                                   at_time_s=trial.start_s if trial.start_s is not None else 0.5 * (t0 + tf),
                                   remedy="give the trial's start_s, toe_off_s and end_s, or cycle = \"auto\"")
        except DataMismatchError as exc:
            raise DataMismatchError(f"trial '{trial.name}': {trial.grf}: {exc}") from None
        if model is not None:
            from ..events import check_cycle_duration

            check_cycle_duration(found, where=f"trial '{trial.name}': {trial.grf} column {force.name}")
    elif trial.external_loads is not None and model is not None:
        from ..errors import DataMismatchError
        from ..events import cycle_from_external_loads

        t0, tf = window_s or _ik_window(trial)
        try:
            found = cycle_from_external_loads(
                trial.external_loads, model, side, trial.start_s if trial.start_s is not None else 0.5 * (t0 + tf),
                trial.grf_threshold_N, remedy="give the trial's start_s, toe_off_s and end_s, or cycle = \"auto\"")
        except DataMismatchError as exc:
            raise DataMismatchError(f"trial '{trial.name}': {exc}") from None
    else:
        from ..errors import DataMismatchError, MissingColumnError

        span = window_s or _ik_window(trial)
        inside = "" if trial.window is None else f" inside its window {span[0]:.3f}-{span[1]:.3f} s"
        try:
            found = cycle_from_id_file(id_file or trial.id, ankle_moment_column(side), window_s=span,
                                       padding_s=PADDING_S,
                                       remedy=f"give the trial's start_s, toe_off_s and end_s{inside}, or a 'grf' file")
        except MissingColumnError as exc:
            raise MissingColumnError(
                f"trial '{trial.name}': no gait events: {exc}; give the trial cycle = \"auto\" (events from "
                "ground forces or kinematics), a 'grf' file, or start_s, toe_off_s and end_s") from None
        except DataMismatchError as exc:
            raise DataMismatchError(f"trial '{trial.name}': no gait events{inside} from the ankle moment: {exc}") \
                from None
    start, toe_off, end = (g if g is not None else f for g, f in
                           zip(given, (found.start_s, found.toe_off_s, found.end_s)))
    return GaitCycle(start, toe_off, end)


def trial_speed(trial: Trial, model=None, cycle: GaitCycle | None = None) -> float:
    """Walking speed (m/s) of the trial: its ``speed_m_per_s``, else the root body's horizontal
    displacement over ``cycle`` (the cycle the rates are averaged over, as ``musclemetab analyse``
    takes it; without one, over the trial's ``start_s``-``end_s``, by default the IK file less the
    padding); ``model`` gives the forward coordinates."""
    if trial.speed_m_per_s is not None:
        return trial.speed_m_per_s
    start, end = (cycle.start_s, cycle.end_s) if cycle is not None else (trial.start_s, trial.end_s)
    return walking_speed_from_ik(trial.ik, start_s=start, end_s=end, padding_s=PADDING_S, model=model)


def rates_span_s(span) -> tuple[float, float] | None:
    """The span a trial unit's rates are averaged over, from its record's ``rates_over_s``
    (``None``: the solve's default, its gait cycle or its window less the padding)."""
    return (float(span[0]), float(span[1])) if span else None
