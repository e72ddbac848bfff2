"""Plausibility checks of a solved trial: values a converged solve can reach that walking does not.

A solve can converge to a solution that balances the joint moments but is not a plausible
muscle state of walking (a fiber stretched far beyond its optimal length carrying the moment
passively, muscles fully active over much of the cycle, reserves doing the muscles' work).
Each check is a small pure function of arrays with its threshold a documented constant (a
keyword overrides it) and gives a :class:`~musclemetab.quality.Flag`, or ``None`` when nothing is
implausible.
:func:`solution_flags` runs them all on a :class:`~.solution.Solution`; the solve records the
result in ``summary.json`` (``plausibility``, :class:`~.record.SolveRecord`). The metabolic
checks (whole-body rate against walking speed, negative muscle-group rates) are in
:mod:`musclemetab.metabolics.plausibility`. ``docs/quality.md`` gives every flag, its threshold
and its source.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from ..quality import Flag, check_strict, flags_from_records, quality_text, warn_flags
from .bounds import FIBER_LENGTH_BOUNDS
from .convergence import unconverged_rates_flag
from .window import PADDING_S

__all__ = [
    "Flag",
    "PASSIVE_FORCE_LIMIT",
    "SATURATION_ACTIVATION",
    "SATURATION_SHARE_LIMIT",
    "LENGTHENING_SATURATION_SHARE_LIMIT",
    "RESERVE_SHARE_LIMIT",
    "RESERVE_FLOOR_NM",
    "passive_force_flag",
    "fiber_length_flag",
    "saturation_flag",
    "lengthening_saturation_flag",
    "cycle_nodes",
    "reserve_flag",
    "solution_flags",
    "solution_cycle_nodes",
    "flags_from_records",
    "quality_text",
    "warn_flags",
    "check_strict",
]

#: Passive fiber force, as a share of the maximal isometric force ``F0``, above which a muscle is
#: flagged (at any node). With the generic passive curve (``kPE = 4``, ``sM = 0.6``) 0.5 ``F0`` is
#: reached at ``l~M`` = 1.49, far on the descending limb (active ``fL`` < 0.3); in walking the
#: fibers of the leg muscles work between about 0.5 and 1.3 optimal lengths (Arnold et al. 2013,
#: J Exp Biol 216:2150) where the passive force is a few percent of ``F0``.
PASSIVE_FORCE_LIMIT = 0.5
#: Activation counted as saturated (the upper bound is 1).
SATURATION_ACTIVATION = 0.95
#: Share of the gait cycle's nodes (the padding around it left out, :func:`cycle_nodes`) at
#: :data:`SATURATION_ACTIVATION` or more above which a muscle is flagged. Walking EMG of the leg muscles peaks well below maximal voluntary contraction (about
#: 20-60 % MVC at preferred speed, e.g. Winter 1991, *The biomechanics and motor control of human
#: gait*); a muscle near full activation for more than a tenth of the cycle is not walking.
SATURATION_SHARE_LIMIT = 0.10
#: Share of the gait cycle's nodes at which a muscle is at :data:`SATURATION_ACTIVATION` or more
#: *while its fiber lengthens* above which it is flagged: two nodes of the study's 100-node
#: cycle. Lengthening leg muscles in walking act as brakes at low activation (Winter 1991); at
#: the effort optimum of the example subject no muscle comes near full activation while it
#: lengthens, whereas an energy goal's optimum can drive lengthening muscles to it, their force
#: being cheap in the models' heat while they lengthen (``docs/energy_objective.md``).
LENGTHENING_SATURATION_SHARE_LIMIT = 0.02
#: Reserve RMS of a DOF as a share of the peak absolute inverse-dynamics moment of that DOF
#: above which the DOF is flagged. Reserves should add little to the muscles' moments (Hicks et
#: al. 2015, J Biomech Eng 137:020905, who ask for reserve moments small against the net joint
#: moments, a few percent); the study's solutions stay below 0.1 % (``LARGE_RESERVE_SHARE`` of
#: :mod:`.solution` is the same ratio over all DOFs together, 1 %).
RESERVE_SHARE_LIMIT = 0.05
#: Reserve RMS (N m) below which a DOF is not flagged whatever its share: a DOF whose peak moment
#: is a fraction of a newton metre (gait2392's toes, 0.2 N m) would otherwise be flagged for a
#: reserve far below what any joint's reserve may be (OpenSim's guidance for reserve actuators
#: rates peaks up to 10 N m as good).
RESERVE_FLOOR_NM = 1.0


def _worst(names: Sequence[str], values: np.ndarray, mask: np.ndarray) -> dict:
    order = sorted((i for i in range(len(names)) if mask[i]), key=lambda i: -values[i])
    return {str(names[i]): float(values[i]) for i in order}


def _listing(items: dict, fmt: str) -> str:
    return ", ".join(f"{k} {fmt.format(v)}" for k, v in items.items())


def passive_force_flag(muscles: Sequence[str], passive_fiber_force_N, max_isometric_force_N, *,
                       limit: float = PASSIVE_FORCE_LIMIT) -> Flag | None:
    """Muscles whose passive fiber force exceeds ``limit`` x ``F0`` at some node.

    ``passive_fiber_force_N``: ``(nodes, muscles)``; ``max_isometric_force_N``: ``(muscles,)``.
    """
    share = np.max(np.asarray(passive_fiber_force_N, dtype=float), axis=0) / np.asarray(max_isometric_force_N, float)
    items = _worst(muscles, share, share > limit)
    if not items:
        return None
    return Flag("passive_force", f"passive fiber force above {limit:g} F0 (peak, in F0): {_listing(items, '{:.2f}')}; "
                "the moment is carried by over-stretched fibers: check the muscles' optimal fiber and tendon slack "
                "lengths (model scaling) and the passive parameters", items, limit)


def fiber_length_flag(muscles: Sequence[str], lm_norm, *, bound: float = FIBER_LENGTH_BOUNDS[1],
                      widened_upper: Mapping[str, float] | None = None) -> Flag | None:
    """Muscles whose normalised fiber length exceeds ``bound`` (the study's upper bound, 1.7).

    The solver widens a muscle's bound above 1.7 only where its fiber at slack tendon length
    (``lMT - lTs``, rigid tendon) is longer (:func:`.bounds.fiber_length_upper_bounds`), so that
    the problem stays feasible; ``widened_upper`` (``summary.json``'s
    ``fiber_length_bounds["widened_upper"]``) names those bounds in the message.
    """
    top = np.max(np.asarray(lm_norm, dtype=float), axis=0)
    items = _worst(muscles, top, top > bound)
    if not items:
        return None
    widened = widened_upper or {}
    parts = [f"{m} {v:.2f}" + (f" (bound widened to {widened[m]:.2f})" if m in widened else "") for m, v in items.items()]
    return Flag("fiber_length", f"fiber length beyond the study's bound {bound:g} optimal lengths (peak l~M): "
                f"{', '.join(parts)}; the bound was widened because the model's muscle-tendon length exceeds "
                "lTs + 1.7 lMo: check the model's scaling of the optimal fiber and tendon slack lengths", items, bound)


def cycle_nodes(time_s, cycle_s: tuple[float, float] | None = None, *, padding_s: float = PADDING_S) -> np.ndarray:
    """The nodes of the gait cycle among the solved ones (a boolean mask of ``time_s``).

    ``cycle_s``: the cycle ``(start, end)`` a solve over ``--cycle`` recorded
    (``summary.json`` ``window.gait_cycle``); its nodes from ``start`` to ``end``. Without it the
    solved window is the cycle padded by :data:`~.window.PADDING_S` (0.05 s) at each end, the
    study's rule: the nodes from ``t_0 + 0.05 s`` up to, not including, ``t_N - 0.05 s`` (the
    cycle's last instant is its first again); on the study's 100 Hz mesh the nodes the metabolic
    rates are averaged over (:func:`musclemetab.metabolics.solution.trim_slice`, 5 and 6 nodes
    dropped). A window too short to hold its padding is taken whole.
    """
    t = np.asarray(time_s, dtype=float)
    eps = 1e-9
    if cycle_s is not None:
        mask = (t >= cycle_s[0] - eps) & (t <= cycle_s[1] + eps)
    elif t.size:
        mask = (t >= t[0] + padding_s - eps) & (t < t[-1] - padding_s - eps)
    else:
        mask = np.zeros(0, dtype=bool)
    return mask if mask.sum() >= 2 else np.ones(t.size, dtype=bool)


def _share_above(muscles: Sequence[str], at, in_cycle, limit: float) -> dict:
    """``{muscle: share}`` of the muscles whose share of the cycle's nodes where ``at`` holds
    (``(nodes, muscles)`` booleans; ``in_cycle`` the cycle's nodes, default all) exceeds ``limit``."""
    if in_cycle is not None:
        at = at[np.asarray(in_cycle, dtype=bool)]
    share = np.mean(at, axis=0) if at.size else np.zeros(len(muscles))
    return _worst(muscles, share, share > limit)


def saturation_flag(muscles: Sequence[str], activation, *, level: float = SATURATION_ACTIVATION,
                    limit: float = SATURATION_SHARE_LIMIT, in_cycle=None) -> Flag | None:
    """Muscles whose activation is ``level`` or more at more than ``limit`` of the gait cycle's nodes
    (``activation``: ``(nodes, muscles)`` on a uniform mesh, so a share of nodes is a share of time;
    ``in_cycle``: the cycle's nodes, :func:`cycle_nodes`; default every node)."""
    items = _share_above(muscles, np.asarray(activation, dtype=float) >= level, in_cycle, limit)
    if not items:
        return None
    return Flag("saturated_activation", f"{len(items)} muscle{'s' if len(items) != 1 else ''} at activation >= "
                f"{level:g} for more than {100 * limit:g} % of the gait cycle (share of the cycle): "
                f"{_listing(items, '{:.0%}')}; the muscles are too weak for the moments (maximal isometric forces, "
                "model scaling) or the moments too large", items, limit)


def lengthening_saturation_flag(muscles: Sequence[str], activation, fiber_velocity, *,
                                level: float = SATURATION_ACTIVATION,
                                limit: float = LENGTHENING_SATURATION_SHARE_LIMIT, in_cycle=None) -> Flag | None:
    """Muscles whose activation is ``level`` or more *while their fiber lengthens* (fiber velocity
    above 0) at more than ``limit`` of the gait cycle's nodes (``activation``, ``fiber_velocity``:
    ``(nodes, muscles)``; ``in_cycle``: :func:`cycle_nodes`, default every node)."""
    at = (np.asarray(activation, dtype=float) >= level) & (np.asarray(fiber_velocity, dtype=float) > 0)
    items = _share_above(muscles, at, in_cycle, limit)
    if not items:
        return None
    return Flag("saturated_lengthening", f"{len(items)} muscle{'s' if len(items) != 1 else ''} at activation >= "
                f"{level:g} while the fiber lengthens, over more than {100 * limit:g} % of the gait cycle (share of "
                f"the cycle): {_listing(items, '{:.0%}')}; walking does not brake at full activation: an energy goal's "
                "optimum uses the models' low cost of lengthening muscles (keep the effort goal beside it, "
                "--effort-weight; docs/energy_objective.md), otherwise the muscles are too weak for the moments",
                items, limit)


def reserve_flag(dofs: Sequence[str], reserve_Nm, peak_moment_by_dof_Nm: Mapping[str, float], *,
                 limit: float = RESERVE_SHARE_LIMIT, floor_Nm: float = RESERVE_FLOOR_NM) -> Flag | None:
    """DOFs whose reserve RMS exceeds ``limit`` x the DOF's peak absolute inverse-dynamics moment
    and ``floor_Nm`` (``reserve_Nm``: ``(nodes, dofs)``, at nodes ``0 ... N-1``, node ``N``
    repeating ``N-1``)."""
    r = np.asarray(reserve_Nm, dtype=float)
    rms = np.sqrt(np.mean(r[:-1] ** 2, axis=0)) if r.shape[0] > 1 else np.abs(r).max(axis=0)
    peak = np.array([float(peak_moment_by_dof_Nm.get(d, np.nan)) for d in dofs])
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(peak > 0, rms / peak, np.where(rms > 0, np.inf, 0.0))
    share = np.nan_to_num(share, nan=0.0)
    items = _worst(dofs, share, (share > limit) & (rms > floor_Nm))
    if not items:
        return None
    parts = [f"{d} {rms[list(dofs).index(d)]:.3g} N m RMS = {v:.1%} of {peak[list(dofs).index(d)]:.3g} N m"
             for d, v in items.items()]
    return Flag("reserve", f"reserve above {limit:.0%} of the DOF's peak joint moment (and {floor_Nm:g} N m): "
                f"{'; '.join(parts)}; the "
                "muscles do not explain the moment: check the inverse dynamics and the muscles crossing the DOF",
                items, limit)


def solution_flags(solution, *, passive_limit: float = PASSIVE_FORCE_LIMIT,
                   saturation_level: float = SATURATION_ACTIVATION, saturation_limit: float = SATURATION_SHARE_LIMIT,
                   reserve_limit: float = RESERVE_SHARE_LIMIT) -> list[Flag]:
    """Every solver-level check on a :class:`~.solution.Solution` (its arrays and record).

    The reserve check needs the record's ``peak_moment_by_dof_Nm`` (written by this version's
    solves) and is left out without it; the fiber-length check uses its ``fiber_length_bounds``.
    """
    rec = solution.record
    in_cycle = solution_cycle_nodes(solution)
    flags = [
        passive_force_flag(solution.muscles, solution.passive_fiber_force_N,
                           solution.parameters.max_isometric_force_N, limit=passive_limit),
        fiber_length_flag(solution.muscles, solution.lm_norm,
                          widened_upper=(rec.fiber_length_bounds or {}).get("widened_upper")),
        saturation_flag(solution.muscles, solution.activation, level=saturation_level, limit=saturation_limit,
                        in_cycle=in_cycle),
        lengthening_saturation_flag(solution.muscles, solution.activation, solution.fiber_velocity_lmo_per_s,
                                    level=saturation_level, in_cycle=in_cycle),
    ]
    peaks = rec.get("peak_moment_by_dof_Nm")
    if peaks:
        flags.append(reserve_flag(solution.dofs, solution.reserve_Nm, peaks, limit=reserve_limit))
    flags.append(unconverged_rates_flag(rec.get("convergence")))
    return [f for f in flags if f is not None]


def solution_cycle_nodes(solution) -> np.ndarray:
    """:func:`cycle_nodes` of a :class:`~.solution.Solution`: its recorded gait cycle, else its
    window less the padding."""
    cycle = solution.record.gait_cycle
    return cycle_nodes(solution.time_s, (float(cycle["start_s"]), float(cycle["end_s"])) if cycle else None)
