"""Phase and group analysis of the metabolic rates of one solved gait cycle.

Puts :mod:`~musclemetab.analysis.phases` and :mod:`~musclemetab.analysis.groups`
together for a :class:`~musclemetab.metabolics.solution.SolutionMetabolics` (per-muscle
rates of several models on the trimmed solver nodes) and the muscle geometry of the
trial (moment arms at the IK frames, linearly interpolated to the nodes).

Reported without basal heat by default (``docs/analysis.md``: the per-muscle basal term
adds a constant that dilutes phase and group differences); the phase shares with the
per-muscle basal heat (``MetabolicRates.total``) are given alongside.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np

from ..errors import DataMismatchError, OptionError
from ..events import as_time
from ..events import GaitCycle
from ..messages import name_list
from .groups import DEFAULT_THRESHOLD_M, GROUPS, GROUPS_WITH_OTHER, OTHER, group_rates, group_shares, group_weights
from .phases import phase_shares

__all__ = ["MetabolicAnalysis", "TrialAnalysis", "RecordedTrial", "analyse", "write_analysis",
           "analyse_metabolics", "analyse_solution_folder", "interpolate_moment_arms", "recorded_trial",
           "recorded_cycle", "averaged_by_default", "ANALYSIS_FILE", "TIMESERIES_FILE", "GROUP_KEY_FILE",
           "ANALYSE_RECORD"]

#: files of :func:`write_analysis` (beside ``whole_body.csv`` and ``per_muscle.csv``)
ANALYSIS_FILE = "analysis.csv"
TIMESERIES_FILE = "timeseries.csv"
GROUP_KEY_FILE = "muscle_groups.csv"
#: The files :func:`write_analysis` may write into a folder (one of the two whole-body tables)
ANALYSIS_FILES = ("whole_body.csv", "leg_muscles.csv", ANALYSIS_FILE, TIMESERIES_FILE, "per_muscle.csv", GROUP_KEY_FILE)
#: The record ``musclemetab analyse`` leaves in its output folder: the solution and metabolics
#: folders of each leg, the gait cycle, body mass and height (read by :mod:`musclemetab.report`).
ANALYSE_RECORD = "analyse.json"


class MetabolicAnalysis(NamedTuple):
    """``summary``: one row per model; ``timeseries``: long table of leg and group rates."""

    summary: "object"
    timeseries: "object"


def interpolate_moment_arms(time_s, moment_arm_time_s, moment_arms_m, *, tolerance_s: float = 1e-6) -> np.ndarray:
    """Moment arms ``(F, D, M)`` at times ``moment_arm_time_s`` linearly interpolated to
    ``time_s`` -> ``(T, D, M)``. Times outside the geometry's span (beyond
    ``tolerance_s``) raise :class:`DataMismatchError`."""
    t = as_time(time_s, "time_s", min_samples=1)
    tg = as_time(moment_arm_time_s, "moment_arm_time_s")
    r = np.asarray(moment_arms_m, dtype=float)
    if r.ndim != 3 or r.shape[0] != tg.size:
        raise DataMismatchError(
            f"moment_arms_m must have shape (time, dofs, muscles) with {tg.size} times, not {r.shape}"
        )
    if t[0] < tg[0] - tolerance_s or t[-1] > tg[-1] + tolerance_s:
        raise DataMismatchError(
            f"the rates span {t[0]:g}-{t[-1]:g} s but the moment arms only {tg[0]:g}-{tg[-1]:g} s; "
            "compute the geometry on the IK file of the solved trial"
        )
    tq = np.clip(t, tg[0], tg[-1])
    k = np.clip(np.searchsorted(tg, tq, side="right") - 1, 0, tg.size - 2)
    w = ((tq - tg[k]) / (tg[k + 1] - tg[k]))[:, None, None]
    return r[k] * (1.0 - w) + r[k + 1] * w


def _match_muscles(wanted: Sequence[str], available: Sequence[str]) -> list[int]:
    pos = {m: i for i, m in enumerate(available)}
    missing = [m for m in wanted if m not in pos]
    if missing:
        raise DataMismatchError(
            f"no moment arms for muscle{'s' if len(missing) > 1 else ''} {name_list(missing)} of the metabolic "
            f"rates; the geometry has {', '.join(list(available)[:8])}{' ...' if len(available) > 8 else ''}. "
            "Compute the geometry for the solution's muscles (same model)"
        )
    return [pos[m] for m in wanted]


def analyse_metabolics(
    result,
    moment_arm_time_s,
    moment_arms_m,
    dofs: Sequence[str],
    muscles: Sequence[str],
    cycle: GaitCycle,
    *,
    models: Sequence[str] | None = None,
    threshold_m: float = DEFAULT_THRESHOLD_M,
    dof_groups: Mapping[str, tuple[str, str]] | None = None,
    coverage_tolerance_s: float | None = None,
) -> MetabolicAnalysis:
    """Stance/swing and group shares of every model of a metabolic result.

    Parameters
    ----------
    result : SolutionMetabolics
        ``rates[model]`` of arrays ``(muscles, time)`` (W) on ``result.time_s``.
    moment_arm_time_s : (F,) s
    moment_arms_m : (F, D, M_g) m, OpenSim convention (e.g. ``Geometry.moment_arms_m``,
        filtered or not as the caller chooses; the study used the solver's 6 Hz filtered
        moment arms)
    dofs : D DOF names; muscles : M_g muscle names of the geometry (matched by name)
    cycle : GaitCycle
    models : subset of ``result.models`` (default all)
    threshold_m, dof_groups : see :func:`~musclemetab.analysis.groups.group_weights`
    coverage_tolerance_s : see :func:`~musclemetab.analysis.phases.phase_shares`

    Returns
    -------
    MetabolicAnalysis
        ``summary`` (pandas.DataFrame, one row per model): ``model``, ``cycle_start_s``,
        ``toe_off_s``, ``cycle_end_s``, ``toe_off_pct``, ``leg_energy_J`` (one leg, no
        basal, over the sampled cycle), ``stance_energy_share_pct``,
        ``swing_energy_share_pct`` (shares of the cycle's energy, no basal),
        ``stance_energy_share_with_basal_pct``, ``swing_energy_share_with_basal_pct``
        (per-muscle basal heat included), ``share_<G>_pct`` for the ten groups and ``share_other_pct`` (no basal;
        the eleven sum to 100).

        ``timeseries`` (pandas.DataFrame, long): ``time_s``, ``cycle_pct``, ``model``,
        ``series``, ``value_W`` with ``series`` = ``leg_muscles`` (the leg's summed muscle
        rate without basal heat) and ``group/<G>`` for the ten groups and
        ``group/other``, which sum to ``leg_muscles`` at every time.
    """
    import pandas as pd

    t = as_time(result.time_s, "result.time_s")
    if not isinstance(cycle, GaitCycle):
        raise DataMismatchError(f"cycle must be a GaitCycle, not {type(cycle).__name__}")
    idx = _match_muscles(list(result.muscles), [str(m) for m in muscles])
    r = np.asarray(moment_arms_m, dtype=float)
    if r.ndim != 3 or r.shape[2] != len(muscles):
        raise DataMismatchError(
            f"moment_arms_m has shape {r.shape}; expected (time, dofs, muscles) with {len(muscles)} muscles"
        )
    r_nodes = interpolate_moment_arms(t, moment_arm_time_s, r[:, :, idx])
    weights = group_weights(r_nodes, dofs, threshold_m, dof_groups=dof_groups)

    chosen = list(result.models) if models is None else [str(m).upper() for m in models]
    unknown = [m for m in chosen if m not in result.rates]
    if unknown:
        raise OptionError(
            f"model{'s' if len(unknown) > 1 else ''} {name_list(unknown)} not in the result; it has "
            f"{', '.join(result.models)}"
        )
    pct = cycle.percent(t)
    rows, frames = [], []
    for model in chosen:
        rates = result.rates[model]
        no_basal = np.asarray(rates.total_without_basal(), dtype=float)
        with_basal = np.asarray(rates.total, dtype=float)
        if no_basal.shape != (len(result.muscles), t.size):
            raise DataMismatchError(
                f"{model}: rates have shape {no_basal.shape}; expected (muscles, time) = "
                f"({len(result.muscles)}, {t.size})"
            )
        leg = no_basal.sum(axis=0)
        ph = phase_shares(t, leg, cycle, coverage_tolerance_s=coverage_tolerance_s)
        ph_b = phase_shares(t, with_basal.sum(axis=0), cycle, coverage_tolerance_s=coverage_tolerance_s)
        g = group_rates(no_basal, weights)
        shares = group_shares(t, g, leg, GROUPS_WITH_OTHER, cycle=cycle, coverage_tolerance_s=coverage_tolerance_s)
        row = dict(
            model=model,
            cycle_start_s=cycle.start_s,
            toe_off_s=cycle.toe_off_s,
            cycle_end_s=cycle.end_s,
            toe_off_pct=cycle.toe_off_pct,
            leg_energy_J=ph["cycle_J"],
            stance_energy_share_pct=ph["stance_pct"],
            swing_energy_share_pct=ph["swing_pct"],
            stance_energy_share_with_basal_pct=ph_b["stance_pct"],
            swing_energy_share_with_basal_pct=ph_b["swing_pct"],
        )
        row.update({f"share_{name}_pct": shares[name] for name in GROUPS})
        row["share_other_pct"] = shares[OTHER]
        rows.append(row)
        names = ["leg_muscles"] + [f"group/{name}" for name in GROUPS_WITH_OTHER]
        values = np.vstack([leg[None, :], g])
        frames.append(pd.DataFrame({
            "time_s": np.tile(t, len(names)),
            "cycle_pct": np.tile(pct, len(names)),
            "model": model,
            "series": np.repeat(np.asarray(names, dtype=object), t.size),
            "value_W": values.reshape(-1),
        }))
    return MetabolicAnalysis(pd.DataFrame(rows), pd.concat(frames, ignore_index=True))


def filtered_moment_arms(geometry, filter_cutoff_hz: float | None = 6.0) -> tuple[np.ndarray, np.ndarray]:
    """The geometry's time and moment arms ``(frames, dofs, muscles)``, low-pass filtered
    like the solver's inputs (zero-phase Butterworth, order 6, ``filter_cutoff_hz`` = 6 Hz;
    ``None`` returns them unfiltered)."""
    r = np.asarray(geometry.moment_arms_m, dtype=float)
    tg = as_time(geometry.time, "geometry.time")
    if filter_cutoff_hz is not None:
        from ..redundancy.inputs import FILTER_ORDER, lowpass_filtfilt

        from ..io import constant_rate

        shape = r.shape
        what = f"the moment arms along {getattr(geometry, 'source', {}).get('ik', 'the IK motion')}"
        fs = constant_rate(tg, f"{what} (the geometry's frames; pass filter_cutoff_hz=None not to filter)")[1]
        r = lowpass_filtfilt(r.reshape(shape[0], -1), fs, float(filter_cutoff_hz), FILTER_ORDER,
                             what=what).reshape(shape)
    return tg, r


def _metabolics_of(solution, body_mass_kg, height_m, models, metabolics_options):
    """``solution`` if it is a metabolic result already, else its rates by
    :func:`musclemetab.metabolics.solution.metabolics_from_solution`."""
    if hasattr(solution, "rates") and hasattr(solution, "whole_body"):
        if metabolics_options:
            raise OptionError(f"{', '.join(metabolics_options)}: options of the metabolic rates, which a metabolic "
                              "result already has; give the solution instead to evaluate them again")
        return solution
    from ..metabolics.solution import metabolics_from_solution

    if body_mass_kg is None:
        raise OptionError("give the body mass (and the height, or None for muscle masses from the model) to "
                          "evaluate the metabolic rates of a solution")
    return metabolics_from_solution(solution, body_mass_kg, height_m, models=models, **metabolics_options)


def analyse_solution_folder(
    folder,
    geometry,
    cycle: GaitCycle,
    body_mass_kg: float,
    height_m: float | None,
    models="all",
    *,
    filter_cutoff_hz: float | None = 6.0,
    threshold_m: float = DEFAULT_THRESHOLD_M,
    dof_groups: Mapping[str, tuple[str, str]] | None = None,
    coverage_tolerance_s: float | None = None,
    **metabolics_options,
) -> MetabolicAnalysis:
    """:func:`analyse_metabolics` of a solver solution: a folder, a
    :class:`musclemetab.redundancy.Solution` (the same numbers as its folder) or the metabolic
    result of one (:class:`~musclemetab.metabolics.solution.SolutionMetabolics`).

    The metabolic rates of a solution come from
    :func:`musclemetab.metabolics.solution.metabolics_from_solution` (``models`` and any
    ``metabolics_options`` are passed on). ``geometry`` is a
    :class:`musclemetab.geometry.Geometry` of the trial; its moment arms are low-pass
    filtered like the solver's inputs (zero-phase Butterworth, order 6, ``filter_cutoff_hz``
    = 6 Hz; ``None`` skips the filter) before interpolation to the nodes.
    """
    result = _metabolics_of(folder, body_mass_kg, height_m, models, metabolics_options)
    tg, r = filtered_moment_arms(geometry, filter_cutoff_hz)
    return analyse_metabolics(
        result, tg, r, list(geometry.dofs), list(geometry.muscles), cycle,
        threshold_m=threshold_m, dof_groups=dof_groups, coverage_tolerance_s=coverage_tolerance_s,
    )


class TrialAnalysis(NamedTuple):
    """What :func:`analyse` finds for one leg of a solved trial (the tables :func:`write_analysis` writes).

    ``whole_body``: :meth:`SolutionMetabolics.whole_body_table` (one row per model; for a leg
    evaluated with ``legs=1``, to be added to the other, its :meth:`~SolutionMetabolics.leg_table`:
    no whole-body figure of one leg);
    ``summary`` and ``timeseries``: :class:`MetabolicAnalysis`; ``per_muscle``:
    :func:`musclemetab.metabolics.per_muscle.per_muscle_table`; ``metabolics``: the metabolic
    result analysed; ``side``: the leg.
    """

    whole_body: "object"
    summary: "object"
    timeseries: "object"
    per_muscle: "object"
    metabolics: "object"
    side: str
    #: DOFs of the solution that belong to no muscle function group (a subtalar or toe joint,
    #: :func:`~musclemetab.analysis.groups.has_function_group`): left out of the group analysis
    excluded_dofs: tuple = ()


class RecordedTrial(NamedTuple):
    """What a solution records of its trial (``summary.json``; :func:`recorded_trial`).

    ``model`` and ``ik``: the files it was solved from (``inputs``), ``id``: the inverse
    dynamics it was solved with (the user's file, or the one OpenSim computed for it);
    ``side``: the solved leg; ``cycle``: the gait cycle the solve's window was taken from
    (``--cycle``; :func:`recorded_cycle`) and ``cycle_source`` where its events came from (the
    words of a study's ``cycle_source``); ``dofs``: the solved DOFs; ``window_s``: the solved
    window ``(start, end)`` and ``window_source`` what chose it (``"--window"``, a gait cycle, or
    ``None`` for the whole IK file); ``external_loads``: the OpenSim ExternalLoads file the inverse
    dynamics was computed from (``--external-loads``). An entry the solution does not record is ``None``.
    """

    model: "str | None"
    ik: "str | None"
    id: "str | None"
    side: "str | None"
    cycle: "GaitCycle | None"
    dofs: "tuple[str, ...] | None"
    cycle_source: "str | None" = None
    window_s: "tuple[float, float] | None" = None
    window_source: "str | None" = None
    external_loads: "str | None" = None

    @property
    def window_named_by_events(self) -> bool:
        """Whether gait events bound the solved window: a solve over a gait cycle (``--cycle``) or
        over the whole IK file (which holds one cycle and its padding, the study's rule), not over
        an explicit ``--window`` that nothing shows to be one gait cycle."""
        return self.cycle is not None or self.window_source != "--window"


def recorded_excluded_muscles(solution) -> list[str]:
    """The muscles the solve left out (``--exclude-muscles``; ``summary.json``
    ``excluded_muscles``) of a solution folder, :class:`~musclemetab.redundancy.Solution` or
    its record; ``[]`` when none."""
    record = getattr(solution, "record", solution)
    if isinstance(solution, (str, os.PathLike)):
        from ..redundancy.solution import read_summary

        record = read_summary(solution)
    return list(getattr(record, "excluded_muscles", None) or [])


def averaged_by_default(recorded: RecordedTrial, cycle: GaitCycle) -> bool:
    """Whether the metabolic rates of the solution are averaged over ``cycle`` without being told
    (:func:`musclemetab.metabolics.solution.metabolics_from_solution`): the gait cycle the solve
    recorded, else the solved window less the padding at each end (its nodes up to, not including,
    the window's end less the padding: the study's rule); ``False`` when the solution records
    neither (an earlier version's), so that the cycle is given."""
    from ..redundancy.window import PADDING_S

    if recorded.cycle is not None:
        span = (recorded.cycle.start_s, recorded.cycle.end_s)
    elif recorded.window_s is not None:
        span = (recorded.window_s[0] + PADDING_S, recorded.window_s[1] - PADDING_S)
    else:
        return False
    return abs(span[0] - cycle.start_s) < 1e-6 and abs(span[1] - cycle.end_s) < 1e-6


def recorded_cycle(gait_cycle: Mapping | None) -> GaitCycle | None:
    """The :class:`GaitCycle` of a solve's recorded ``window["gait_cycle"]`` (the dictionary of
    :attr:`musclemetab.redundancy.record.SolveRecord.gait_cycle`), or ``None`` without one."""
    if not gait_cycle:
        return None
    try:
        return GaitCycle(float(gait_cycle["start_s"]), float(gait_cycle["toe_off_s"]), float(gait_cycle["end_s"]))
    except (KeyError, TypeError, ValueError):
        return None


def recorded_trial(solution) -> RecordedTrial:
    """The trial a solution records (:class:`RecordedTrial`): ``solution`` is a solution folder
    (its ``summary.json``), a :class:`musclemetab.redundancy.Solution` or its
    :class:`~musclemetab.redundancy.record.SolveRecord`; anything else records nothing."""
    record = getattr(solution, "record", solution)
    if isinstance(solution, (str, os.PathLike)):
        from ..redundancy.solution import read_summary

        record = read_summary(solution, missing="missing", remedy="give a folder written by 'musclemetab solve'")
    if not hasattr(record, "gait_cycle"):
        return RecordedTrial(None, None, None, None, None, None)
    inputs = record.inputs or {}
    dofs = record.dofs if record.dofs is not None else getattr(solution, "dofs", None)
    cycle = recorded_cycle(record.gait_cycle)
    source = f"ground reaction forces ({record.gait_cycle.get('source') or 'found by the solve'})" if cycle else None
    window_source = record.window.source if record.window is not None else None
    window = record.time_window_s
    return RecordedTrial(inputs.get("model"), inputs.get("ik"), inputs.get("id"), record.side, cycle,
                         tuple(dofs) if dofs is not None else None, source,
                         (float(window[0]), float(window[1])) if window else None, window_source,
                         inputs.get("external_loads"))


def analyse(
    solution,
    model: str | os.PathLike | None = None,
    ik: str | os.PathLike | None = None,
    cycle: GaitCycle | None = None,
    body_mass_kg: float | None = None,
    height_m: float | None = None,
    *,
    models="all",
    side: str | None = None,
    dofs: Sequence[str] | None = None,
    **metabolics_options,
) -> TrialAnalysis:
    """Whole-body, phase, group and per-muscle results of one leg of a solved trial
    (``musclemetab analyse``).

    Parameters
    ----------
    solution
        A solution folder, a :class:`musclemetab.redundancy.Solution` (the same numbers as the
        folder it is written to) or its metabolic result
        (:class:`~musclemetab.metabolics.solution.SolutionMetabolics`, used as it is: then
        ``body_mass_kg``, ``height_m``, ``models`` and ``metabolics_options`` are not needed).
    model, ik
        The OpenSim model and the IK motion of the trial: the moment arms of the solution's
        muscles (:func:`musclemetab.geometry.compute_geometry`, filtered like the solver's
        inputs by :func:`filtered_moment_arms`). Default: the files the solution records
        (:func:`recorded_trial`).
    cycle
        The gait cycle (:class:`GaitCycle`; e.g. :func:`~musclemetab.events.cycle_of_trial`).
        Default: the cycle the solve recorded (a solve over ``--cycle``).
    body_mass_kg, height_m, models, metabolics_options
        Passed to :func:`musclemetab.metabolics.solution.metabolics_from_solution` (``basal``,
        ``basal_rate_W_per_kg``, ``basal_exponent``, ``speed_m_per_s``, ...).
    side
        The leg; default: the one the solution recorded, else the suffix its muscles share,
        else ``"r"``.
    dofs
        The DOFs of the moment arms; default: those the solution records, else those of the
        leg in the model (:func:`musclemetab.layout.side_dofs`). A DOF that belongs to no muscle
        function group (a subtalar or toe joint) is left out of the group analysis and named in
        :attr:`TrialAnalysis.excluded_dofs` (``docs/analysis.md``).
    """
    from ..errors import OptionError as _OptionError
    from ..geometry import compute_geometry
    from ..properties import split_side
    from ..metabolics.per_muscle import per_muscle_table
    from .groups import has_function_group

    recorded = recorded_trial(solution)
    model = model if model is not None else recorded.model
    ik = ik if ik is not None else recorded.ik
    cycle = cycle if cycle is not None else recorded.cycle
    missing = [name for name, value in (("model", model), ("ik", ik), ("cycle", cycle)) if value is None]
    if missing:
        raise _OptionError(f"the solution records no {name_list(missing)}: give {' and '.join(missing)} "
                           "(the OpenSim model, the IK motion and the gait cycle of the solved trial)")
    if (not (hasattr(solution, "rates") and hasattr(solution, "whole_body")) and "trim" not in metabolics_options
            and not averaged_by_default(recorded, cycle)):  # the rates over the cycle the analysis names
        metabolics_options = {**metabolics_options, "cycle_s": (cycle.start_s, cycle.end_s)}
    result = _metabolics_of(solution, body_mass_kg, height_m, models, metabolics_options)
    if side is None:
        side = getattr(result, "side", None) or recorded.side
    if side is None:
        sides = {split_side(m)[1] for m in result.muscles} - {""}
        side = sides.pop() if len(sides) == 1 else "r"
    muscles = list(result.muscles)
    if dofs is None and recorded.dofs is not None:
        # the solve's own geometry call (its DOFs, the muscles spanning them): found in the cache
        dofs, muscles = list(recorded.dofs), None
    geometry = compute_geometry(model, ik, dofs=list(dofs) if dofs is not None else None, side=side, muscles=muscles)
    tg, r = filtered_moment_arms(geometry)
    keep = [j for j, d in enumerate(geometry.dofs) if has_function_group(d)]
    excluded = tuple(d for d in geometry.dofs if not has_function_group(d))
    analysis = analyse_metabolics(result, tg, r[:, keep, :], [geometry.dofs[j] for j in keep],
                                  list(geometry.muscles), cycle)
    one_leg = any(wb.legs != 2 for wb in result.whole_body.values())
    return TrialAnalysis(result.leg_table() if one_leg else result.whole_body_table(), analysis.summary,
                         analysis.timeseries, per_muscle_table(result, cycle, side=side), result, side, excluded)


def write_analysis(analysis: TrialAnalysis, out_dir: str | os.PathLike) -> dict:
    """Write the tables of :func:`analyse` into ``out_dir``, together
    (:func:`musclemetab.io.atomic_directory`): ``whole_body.csv`` (``leg_muscles.csv`` for a
    leg evaluated with ``legs=1``), ``analysis.csv``, ``timeseries.csv``, ``per_muscle.csv`` and
    the key of the group abbreviations, ``muscle_groups.csv``. Returns the paths by file name."""
    from pathlib import Path

    from ..io import atomic_directory
    from ..metabolics.solution import LEG_CSV, WHOLE_BODY_CSV
    from .groups import group_key_table
    from ..metabolics.per_muscle import PER_MUSCLE_FILE

    whole = WHOLE_BODY_CSV if "whole_body_W_per_kg" in analysis.whole_body.columns else LEG_CSV
    tables = {whole: analysis.whole_body, ANALYSIS_FILE: analysis.summary,
              TIMESERIES_FILE: analysis.timeseries, PER_MUSCLE_FILE: analysis.per_muscle}
    with atomic_directory(out_dir, mark=True) as tmp:
        for name, table in tables.items():
            table.to_csv(tmp / name, index=False, float_format="%.10g")
        group_key_table().to_csv(tmp / GROUP_KEY_FILE, index=False)
    return {name: Path(out_dir) / name for name in (*tables, GROUP_KEY_FILE)}
