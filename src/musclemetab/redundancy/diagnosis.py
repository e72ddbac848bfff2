"""Diagnosis of a trial before its solve: muscles and times that make the problem infeasible.

The checks use the trial's mesh inputs (:class:`~.inputs.TrialInputs`: the filtered
muscle-tendon lengths, moment arms and moments at the nodes), the muscle parameters of the
solve and the same bounds and curves as the problem (:mod:`.bounds`, :mod:`musclemetab.muscle`;
``docs/solver.md``, section *Diagnosis before the solve*). Nothing is solved: each check is a
closed formula or a bisection in NumPy. Per muscle ``m`` and node ``t_k``:

``muscle_tendon_too_short`` (blocking)
    The shortest muscle-tendon length the bounds admit is that of the shortest fiber,
    ``l~M = max(0.1, sqrt(w^2 + lp_min^2)/lMo)``, inactive (``a = 0``): its projection
    ``lp = sqrt(lM^2 - w^2)`` (constant width ``w = lMo sin(alpha0)``) plus the tendon at the
    force of that fiber, ``lTs l~T(fPE(l~M) cos(alpha))`` (:func:`~musclemetab.muscle.tendon_length_from_force`;
    the fiber's force is slightly negative there, so the tendon is a little shorter than at
    zero force). ``lMT(t_k)`` below it: the Hill equilibrium has no solution at that node.
``muscle_tendon_too_long`` (blocking)
    The longest muscle-tendon length: the largest, over fiber lengths up to the upper bound
    (:func:`.bounds.fiber_length_upper_bounds`), of the projection plus the tendon at the
    largest force the bounds allow there (``a = 1``, the fastest lengthening the velocity bound
    allows). The solver widens each muscle's upper bound beyond its longest rigid-tendon fiber, so
    this check holds by construction for the trial the bound is computed from; it guards bounds
    given explicitly (``lm_upper`` of :func:`diagnose`).
``fiber_too_long_at_every_activation`` (warning)
    The fiber length of the isometric equilibrium (``v = 0``) at full activation, the shortest
    fiber any activation gives, above the default upper bound 1.7: the fiber is that long whatever
    the muscle does (the solver has widened the muscle's bound, ``fiber_length_bounds``), its
    passive force is large; the tendon slack length is likely too short for the muscle-tendon
    length (the rigid-tendon estimate ``sqrt((lMT - lTs)^2 + w^2)/lMo`` is an upper bound of it).
``moment_arm_vanishes`` (warning)
    A muscle the anatomical muscle table places in a function group of a DOF of the problem
    (:func:`musclemetab.properties.dof_group_pair`) has ``|r| <`` :data:`MOMENT_ARM_THRESHOLD_M` about it
    at every node.
``muscle_left_out`` (warning)
    A muscle the problem leaves out (no moment arm above 0.1 mm at the first frame,
    :func:`.inputs.select_muscles`) though the table has it act about a DOF of the problem
    (:func:`diagnose_geometry`).
``moment_unreachable`` (warning)
    Per DOF and direction, the ID moment beyond what the muscles give at full activation with
    the fiber at rest (``sum r F0 fT`` with each muscle's tendon force at its isometric
    equilibrium at ``a = 1`` on the side it helps and ``a = 0`` on the other; the reserve,
    ``Topt`` times its bound 1, is not counted: the row gives it).

A finding is a :class:`Finding`; all of them a :class:`Diagnosis` (a table, a record for
``summary.json``). :func:`last_iterate_violations` names the muscles and DOFs whose
constraints an unconverged solve left violated.
"""

from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..errors import MusclemetabWarning, SolverError
from ..messages import user_stacklevel
from ..muscle import active_force_length, force_velocity, passive_force_length, tendon_length_from_force
from .bounds import FIBER_LENGTH_BOUNDS, FIBER_VELOCITY_BOUNDS, MIN_PROJECTED_LENGTH_M, fiber_length_upper_bounds

__all__ = ["Finding", "Diagnosis", "DiagnosisWarning", "InfeasibleInputError", "diagnose", "diagnose_geometry",
           "last_iterate_violations", "violation_text", "trials_violation_text", "length_range",
           "isometric_fiber_length", "isometric_tendon_force", "MOMENT_ARM_THRESHOLD_M", "HILL_VIOLATION",
           "MOMENT_VIOLATION_NM", "BLOCKING", "WARNING"]

BLOCKING = "blocking"
WARNING = "warning"
#: A moment arm at or below this magnitude (m) counts as zero (that of the function groups).
MOMENT_ARM_THRESHOLD_M = 1e-3
#: Normalised Hill-equilibrium residual above which an unconverged solve names the muscle.
HILL_VIOLATION = 1e-3
#: Moment residual (N m) above which an unconverged solve names the DOF.
MOMENT_VIOLATION_NM = 1e-2
_GRID = 201
_BISECTIONS = 44

REMEDY_LENGTH = ("exclude the muscle (--exclude-muscles {m}), estimate its tendon slack length (musclemetab "
                 "estimate --estimate tendon_slack_length={m}) or check the model's scaling")
REMEDY_MOMENT_ARM = ("check the muscle's path (wrapping surfaces, via points) and the scaling; exclude the muscle "
                     "(--exclude-muscles {m}) if it should not act about {d}")
REMEDY_MOMENT = ("check the inverse dynamics (scale, body mass, that it belongs to this model and trial) and the "
                 "maximal isometric forces; the reserve (up to {t:g} N m) carries the rest")


class DiagnosisWarning(MusclemetabWarning):
    """The diagnosis before the solve found something that may make the solve fail or lean on
    the reserve (``summary.json`` ``diagnosis`` names it)."""


class InfeasibleInputError(SolverError):
    """The trial's inputs make the problem infeasible (muscles and times named); nothing was solved."""


@dataclass(frozen=True)
class Finding:
    """One row of the diagnosis: ``subject`` (a muscle or a DOF, with the direction for
    moments), the ``check``, its ``severity`` (``blocking`` or ``warning``), the time
    ``intervals`` in s where it holds (first and last node of each run of nodes),
    the ``value`` at the worst node ``worst_time_s`` and the ``bound`` it breaks, in ``unit``, and the ``remedy``."""

    subject: str
    check: str
    severity: str
    intervals: tuple
    worst_time_s: float
    value: float
    bound: float
    unit: str
    remedy: str

    @property
    def first_time_s(self) -> float:
        return float(self.intervals[0][0]) if self.intervals else float("nan")

    def times_text(self) -> str:
        return ", ".join(f"{a:g} s" if a == b else f"{a:g}-{b:g} s" for a, b in self.intervals)

    def to_dict(self) -> dict:
        return {"subject": self.subject, "check": self.check, "severity": self.severity,
                "intervals_s": [list(map(float, iv)) for iv in self.intervals], "worst_time_s": self.worst_time_s,
                "value": self.value, "bound": self.bound, "unit": self.unit, "remedy": self.remedy}

    @classmethod
    def from_dict(cls, d: dict) -> "Finding":
        return cls(d["subject"], d["check"], d["severity"], tuple(tuple(iv) for iv in d.get("intervals_s", ())),
                   float(d["worst_time_s"]), float(d["value"]), float(d["bound"]), d["unit"], d["remedy"])


@dataclass(frozen=True)
class Diagnosis:
    """The findings of one trial (:func:`diagnose`), in the order of the checks."""

    findings: tuple = ()
    trial: str = ""
    thresholds: dict = field(default_factory=dict)
    #: of a solve that did not converge, the constraints its last iterate left violated
    #: (:func:`last_iterate_violations`); ``None`` for a diagnosis before the solve only
    last_iterate: tuple | None = None

    @property
    def blocking(self) -> tuple:
        return tuple(f for f in self.findings if f.severity == BLOCKING)

    @property
    def warnings(self) -> tuple:
        return tuple(f for f in self.findings if f.severity == WARNING)

    def table(self) -> str:
        """The findings as a readable table (one line each)."""
        if not self.findings:
            return f"diagnosis{' of ' + self.trial if self.trial else ''}: no findings"
        rows = [("subject", "check", "severity", "times", "value", "bound", "remedy")]
        rows += [(f.subject, f.check, f.severity, f.times_text(), f"{f.value:.4g} {f.unit}", f"{f.bound:.4g} {f.unit}",
                  f.remedy) for f in self.findings]
        width = [max(len(r[i]) for r in rows) for i in range(6)]
        lines = ["  ".join(c.ljust(w) for c, w in zip(r[:6], width)) + "  " + r[6] for r in rows]
        return f"diagnosis{' of ' + self.trial if self.trial else ''}:\n" + "\n".join(lines)

    def to_dict(self) -> dict:
        """``summary.json``'s ``diagnosis``: ``thresholds``, ``findings`` and, after a solve that
        did not converge, ``last_iterate``."""
        out = {"thresholds": dict(self.thresholds), "findings": [f.to_dict() for f in self.findings]}
        if self.last_iterate is not None:
            out["last_iterate"] = [f.to_dict() for f in self.last_iterate]
        return out

    @classmethod
    def from_dict(cls, d, trial: str = "") -> "Diagnosis":
        """From ``summary.json``'s ``diagnosis`` (a :class:`Diagnosis` as it is)."""
        if isinstance(d, Diagnosis):
            return d
        last = d.get("last_iterate")
        return cls(tuple(Finding.from_dict(f) for f in d.get("findings", ())), trial, dict(d.get("thresholds", {})),
                   None if last is None else tuple(Finding.from_dict(f) for f in last))

    def error(self, what: str = "the trial") -> InfeasibleInputError:
        """The error of the blocking findings (muscles, times, bounds and remedies)."""
        rows = "; ".join(f"{f.subject} {f.check.replace('_', ' ')} at {f.times_text()} (muscle-tendon length "
                         f"{f.value:.4g} m, {'shortest' if 'short' in f.check else 'longest'} admissible "
                         f"{f.bound:.4g} m)" for f in self.blocking)
        names = " ".join(dict.fromkeys(f.subject for f in self.blocking))
        return InfeasibleInputError(
            f"{what} cannot be solved: {rows}. No fiber length within the bounds balances the tendon there. "
            f"Exclude the muscle{'s' if len(self.blocking) > 1 else ''} (--exclude-muscles {names}), estimate the "
            "tendon slack length (musclemetab estimate --estimate tendon_slack_length=...) or check the model's "
            "scaling")

    def check(self, what: str = "the trial") -> "Diagnosis":
        """Raise :meth:`error` when a finding is blocking; give the warnings as one
        :class:`DiagnosisWarning`; return the diagnosis."""
        if self.blocking:
            raise self.error(what)
        if self.warnings:
            warnings.warn(f"{what}: " + "; ".join(f"{f.subject} {f.check.replace('_', ' ')} at {f.times_text()} "
                                                 f"({f.value:.4g} vs {f.bound:.4g} {f.unit}): {f.remedy}"
                                                 for f in self.warnings), DiagnosisWarning,
                          stacklevel=user_stacklevel())
        return self


def _intervals(time: np.ndarray, mask: np.ndarray) -> tuple:
    """Runs of consecutive true nodes as ``((t_first, t_last), ...)``."""
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return ()
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts = np.concatenate([[idx[0]], idx[breaks + 1]])
    ends = np.concatenate([idx[breaks], [idx[-1]]])
    return tuple((round(float(time[a]), 6), round(float(time[b]), 6)) for a, b in zip(starts, ends))


def _shortest_fiber(lmo, width):
    """Shortest admissible normalised fiber length: the lower bound, or the fiber whose
    projection is the smallest admissible projected length."""
    return np.maximum(FIBER_LENGTH_BOUNDS[0], np.sqrt(width**2 + MIN_PROJECTED_LENGTH_M**2) / lmo)


def _along_tendon(lm_norm, activation, vbar, p):
    """Normalised fiber force along the tendon ``(a fL fV + fPE) cos(alpha)`` and the projection (m)."""
    lm_m = lm_norm * p["lmo"]
    proj = np.sqrt(np.maximum(lm_m**2 - p["w"] ** 2, 0.0))
    force = passive_force_length(lm_norm, p["kpe"], p["s0"], p["sm"])
    if activation:  # inactive: the passive force alone
        force = force + activation * active_force_length(lm_norm) * force_velocity(vbar)
    return force * proj / lm_m, proj


def _mt_length(lm_norm, activation, vbar, p):
    """The muscle-tendon length in equilibrium with a fiber of length ``lm_norm`` (m) and its force."""
    force, proj = _along_tendon(lm_norm, activation, vbar, p)
    return proj + p["lts"] * tendon_length_from_force(force, p["kT"]), force


def _arrays(params, muscles, lm_upper):
    p = params.subset(muscles)
    return {"lmo": p.optimal_fiber_length_m, "lts": p.tendon_slack_length_m, "w": p.width_m, "kT": p.tendon_stiffness,
            "kpe": p.passive_kpe, "s0": p.passive_s0, "sm": p.passive_sm,
            "vbar": FIBER_VELOCITY_BOUNDS[1] / p.max_contraction_velocity, "upper": np.asarray(lm_upper, dtype=float)}


def length_range(params, muscles: Sequence[str], lm_upper, *, velocity: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Shortest and longest muscle-tendon lengths (m) each muscle's bounds admit.

    Shortest: the shortest admissible fiber, inactive. Longest: the largest, over a grid of
    fiber lengths from the shortest to ``lm_upper`` (201 points, the bound included), of the
    length at full activation and (``velocity``) the fastest admissible lengthening, else at rest.
    """
    p = _arrays(params, muscles, lm_upper)
    lmin = _shortest_fiber(p["lmo"], p["w"])
    shortest, _ = _mt_length(lmin, 0.0, 0.0, p)
    grid = lmin + np.linspace(0.0, 1.0, _GRID)[:, None] * (p["upper"] - lmin)
    longest, _ = _mt_length(grid, 1.0, p["vbar"] if velocity else 0.0, p)
    return shortest, np.max(longest, axis=0)


def isometric_fiber_length(params, muscles: Sequence[str], lm_upper, lmt_m, activation: float) -> np.ndarray:
    """Normalised fiber length of each muscle's isometric equilibrium (``v = 0``) at
    ``activation`` for the muscle-tendon lengths ``lmt_m`` (nodes x muscles): where the
    muscle-tendon length of :func:`length_range`'s equation meets ``lmt_m``, by bisection
    between the shortest admissible fiber and ``lm_upper`` (a bound where none does)."""
    p = _arrays(params, muscles, lm_upper)
    lmt = np.atleast_2d(np.asarray(lmt_m, dtype=float))
    lo = np.broadcast_to(_shortest_fiber(p["lmo"], p["w"]), lmt.shape).copy()
    hi = np.broadcast_to(p["upper"], lmt.shape).copy()
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        longer = _mt_length(mid, activation, 0.0, p)[0] > lmt
        hi = np.where(longer, mid, hi)
        lo = np.where(longer, lo, mid)
    return 0.5 * (lo + hi)


def isometric_tendon_force(params, muscles: Sequence[str], lm_upper, lmt_m, activation: float) -> np.ndarray:
    """Normalised tendon force ``fT`` at the equilibrium of :func:`isometric_fiber_length`."""
    lm = isometric_fiber_length(params, muscles, lm_upper, lmt_m, activation)
    return _along_tendon(lm, activation, 0.0, _arrays(params, muscles, lm_upper))[0]


def _scaled(params, specs, end: int):
    """``params`` with the estimated factors of ``specs`` at their lower (0) or upper (1) bound
    for the lengths and the other bound for ``kT`` (the most permissive for the shortest (0) or
    longest (1) muscle-tendon length)."""
    values = {}
    for s in specs:
        field_name = {"tendon_slack_length": "tendon_slack_length_m", "optimal_fiber_length": "optimal_fiber_length_m",
                      "tendon_stiffness": "tendon_stiffness"}.get(s.kind)
        if field_name is None:
            continue
        factor = s.bounds[1 - end] if s.kind == "tendon_stiffness" else s.bounds[end]
        base = dict(zip(params.names, getattr(params, field_name)))
        values.setdefault(field_name, {}).update({m: base[m] * factor for m in s.muscles if m in base})
    return params.replace(**values) if values else params


def _length_findings(inputs, params, upper, specs, full_lm) -> list[Finding]:
    t, lmt, muscles = inputs.mesh_time_s, np.asarray(inputs.lmt_m, dtype=float), list(inputs.muscles)
    shortest, _ = length_range(_scaled(params, specs, 0), muscles, upper)
    _, longest = length_range(_scaled(params, specs, 1), muscles, upper)
    out = []
    for j, m in enumerate(muscles):
        for check, bad, bound in (("muscle_tendon_too_short", lmt[:, j] < shortest[j], shortest[j]),
                                  ("muscle_tendon_too_long", lmt[:, j] > longest[j], longest[j])):
            if bad.any():
                k = int(np.argmax(np.where(bad, np.abs(lmt[:, j] - bound), -1.0)))
                out.append(Finding(m, check, BLOCKING, _intervals(t, bad), float(t[k]), float(lmt[k, j]),
                                   float(bound), "m", REMEDY_LENGTH.format(m=m)))
    shortest_fiber = full_lm if not specs else isometric_fiber_length(_scaled(params, specs, 1), muscles, upper,
                                                                      lmt, 1.0)
    for j, m in enumerate(muscles):
        bad = shortest_fiber[:, j] > FIBER_LENGTH_BOUNDS[1]
        if bad.any():
            k = int(np.argmax(shortest_fiber[:, j]))
            out.append(Finding(m, "fiber_too_long_at_every_activation", WARNING, _intervals(t, bad), float(t[k]),
                               float(shortest_fiber[k, j]), FIBER_LENGTH_BOUNDS[1], "lMo", REMEDY_LENGTH.format(m=m)))
    return out


def _spanned_dofs(muscles, dofs) -> dict:
    """``{muscle: [DOF]}``: the DOFs of the problem whose function group the table gives the muscle."""
    return {m: list(d) for m, d in _spanned(tuple(muscles), tuple(dofs))}


@functools.lru_cache(maxsize=16)
def _spanned(muscles: tuple, dofs: tuple) -> tuple:
    from ..properties import dof_group_pair, has_function_group
    from ..properties import resolve_muscles

    out = []
    for rec in resolve_muscles(list(muscles), warn=False):
        groups = {g for item in rec.function_groups for g in item.split("/")}
        out.append((rec.name, tuple(d for d in dofs if has_function_group(d) and groups & set(dof_group_pair(d)))))
    return tuple(out)


def _moment_arm_findings(inputs, threshold) -> list[Finding]:
    r = np.asarray(inputs.moment_arms_m, dtype=float)
    t = inputs.mesh_time_s
    out = []
    for m, spans in _spanned_dofs(inputs.muscles, inputs.dofs).items():
        j = inputs.muscles.index(m)
        for d in spans:
            i = inputs.dofs.index(d)
            biggest = np.abs(r[:, i, j])
            if biggest.max() < threshold:
                k = int(np.argmax(biggest))
                out.append(Finding(f"{m} about {d}", "moment_arm_vanishes", WARNING, ((float(t[0]), float(t[-1])),),
                                   float(t[k]),
                                   float(biggest[k]), float(threshold), "m", REMEDY_MOMENT_ARM.format(m=m, d=d)))
    return out


def _moment_findings(inputs, params, upper, reserve_Nm, full_lm) -> list[Finding]:
    muscles = list(inputs.muscles)
    p = _arrays(params, muscles, upper)
    f0 = params.subset(muscles).max_isometric_force_N
    full = _along_tendon(full_lm, 1.0, 0.0, p)[0] * f0
    rest = isometric_tendon_force(params, muscles, upper, inputs.lmt_m, 0.0) * f0
    r = np.asarray(inputs.moment_arms_m, dtype=float)
    a, b = np.einsum("kdm,km->kdm", r, full), np.einsum("kdm,km->kdm", r, rest)
    highest, lowest = np.maximum(a, b).sum(axis=2), np.minimum(a, b).sum(axis=2)
    moments, t = np.asarray(inputs.moments_Nm, dtype=float), inputs.mesh_time_s
    out = []
    for i, d in enumerate(inputs.dofs):
        for direction, excess in (("positive", moments[:, i] - highest[:, i]),
                                  ("negative", lowest[:, i] - moments[:, i])):
            bad = excess > 0
            if bad.any():
                k = int(np.argmax(excess))
                bound = highest[k, i] if direction == "positive" else lowest[k, i]
                out.append(Finding(f"{d} ({direction})", "moment_unreachable", WARNING, _intervals(t, bad), float(t[k]),
                                   float(moments[k, i]), float(bound), "N m", REMEDY_MOMENT.format(t=reserve_Nm)))
    return out


def diagnose(inputs, params, *, specs=(), optimal_reserve_Nm: float = 150.0,
             moment_arm_threshold_m: float = MOMENT_ARM_THRESHOLD_M, trial: str = "", lm_upper=None) -> Diagnosis:
    """The diagnosis of one trial's mesh inputs with the problem's parameters (``specs``: the
    estimated factors of an estimation, whose bounds make the length checks more permissive;
    ``lm_upper``: upper bounds of the normalised fiber lengths, default the solver's,
    :func:`.bounds.fiber_length_upper_bounds`)."""
    params = params.subset(inputs.muscles)
    upper = fiber_length_upper_bounds(inputs, params, specs) if lm_upper is None else \
        np.broadcast_to(np.asarray(lm_upper, dtype=float), (len(inputs.muscles),))
    full_lm = isometric_fiber_length(params, inputs.muscles, upper, inputs.lmt_m, 1.0)
    findings = _length_findings(inputs, params, upper, specs, full_lm)
    findings += _moment_arm_findings(inputs, moment_arm_threshold_m)
    findings += _moment_findings(inputs, params, upper, optimal_reserve_Nm, full_lm)
    thresholds = {"fiber_length_bounds": list(FIBER_LENGTH_BOUNDS),
                  "fiber_velocity_bounds": list(FIBER_VELOCITY_BOUNDS),
                  "moment_arm_m": moment_arm_threshold_m, "reserve_Nm": optimal_reserve_Nm}
    return Diagnosis(tuple(findings), trial, thresholds)


def diagnose_geometry(geometry, params, id_time_s, id_moments_Nm, *, ik_time_s=None, mesh_frequency_hz=None,
                      specs=(), optimal_reserve_Nm: float = 150.0, trial: str = "", sources=None) -> Diagnosis:
    """:func:`diagnose` from a geometry and the ID (the mesh inputs built as the solve builds them)."""
    from .inputs import MESH_FREQUENCY_HZ, restrict_geometry, trial_inputs

    full = geometry
    dofs = tuple(geometry.dofs)
    geometry = restrict_geometry(geometry)
    moments = np.asarray(id_moments_Nm, dtype=float).reshape(len(id_time_s), -1)
    if tuple(geometry.dofs) != dofs:
        moments = moments[:, [dofs.index(d) for d in geometry.dofs]]
    inputs = trial_inputs(geometry, id_time_s, moments, ik_time_s=ik_time_s, sources=dict(sources or {}),
                          mesh_frequency_hz=mesh_frequency_hz or MESH_FREQUENCY_HZ)
    d = diagnose(inputs, params, specs=specs, optimal_reserve_Nm=optimal_reserve_Nm, trial=trial)
    dropped = [m for m in full.muscles if m not in geometry.muscles]
    if not dropped:
        return d
    return Diagnosis(tuple(_dropped_findings(full, dropped)) + d.findings, d.trial, d.thresholds)


def _dropped_findings(geometry, dropped) -> list[Finding]:
    """Muscles the problem leaves out (no moment arm above 0.1 mm at the first frame,
    :func:`.inputs.select_muscles`) though the muscle table has them act about one of its DOFs."""
    from .inputs import MUSCLE_SELECTION_THRESHOLD_M

    r = np.abs(np.asarray(geometry.moment_arms_m, dtype=float))
    t = np.asarray(geometry.time, dtype=float)
    out = []
    for m, spans in _spanned_dofs(dropped, list(geometry.dofs)).items():
        j = list(geometry.muscles).index(m)
        for d in spans:
            i = list(geometry.dofs).index(d)
            out.append(Finding(f"{m} about {d}", "muscle_left_out", WARNING, ((float(t[0]), float(t[0])),),
                               float(t[0]), float(r[0, i, j]), MUSCLE_SELECTION_THRESHOLD_M, "m",
                               REMEDY_MOMENT_ARM.format(m=m, d=d)))
    return out


def last_iterate_violations(solution, inputs=None) -> list[Finding]:
    """Muscles whose Hill equilibrium (normalised residual above :data:`HILL_VIOLATION`) and,
    with ``inputs``, DOFs whose moment balance (above :data:`MOMENT_VIOLATION_NM`) the last
    iterate of a solve leaves violated, at the nodes of the intervals (``check``
    ``hill_violated`` / ``moment_violated``; the bound is the threshold)."""
    p = solution.parameters.subset(solution.muscles)
    t = np.asarray(solution.time_s, dtype=float)
    f0 = p.max_isometric_force_N
    lm_m = np.asarray(solution.lm_norm, dtype=float) * p.optimal_fiber_length_m
    cos = np.sqrt(np.maximum(lm_m**2 - p.width_m**2, 0.0)) / lm_m
    fiber = (np.asarray(solution.active_fiber_force_N) + np.asarray(solution.passive_fiber_force_N)) / f0
    residual = np.abs(fiber * cos - np.asarray(solution.tendon_force_N) / f0)[:-1]
    out = []
    for j, m in enumerate(solution.muscles):
        bad = residual[:, j] > HILL_VIOLATION
        if bad.any():
            k = int(np.argmax(residual[:, j]))
            out.append(Finding(m, "hill_violated", BLOCKING, _intervals(t, np.append(bad, False)), float(t[k]),
                               float(residual[k, j]), HILL_VIOLATION, "F0", REMEDY_LENGTH.format(m=m)))
    if inputs is not None:
        N = t.size - 1
        muscle = np.einsum("kdm,km->kd", inputs.moment_arms_m[:N], np.asarray(solution.tendon_force_N)[:N])
        res = np.abs(inputs.moments_Nm[:N] - muscle - np.asarray(solution.reserve_Nm)[:N])
        for i, d in enumerate(solution.dofs):
            bad = res[:, i] > MOMENT_VIOLATION_NM
            if bad.any():
                k = int(np.argmax(res[:, i]))
                out.append(Finding(d, "moment_violated", BLOCKING, _intervals(t, np.append(bad, False)), float(t[k]),
                                   float(res[k, i]), MOMENT_VIOLATION_NM, "N m",
                                   REMEDY_MOMENT.format(t=solution.record.optimal_reserve_Nm or 150.0)))
    return out


def violation_text(record) -> str:
    """A sentence naming the muscles and DOFs (and times) a solve that did not converge left
    violated (``record``: a :class:`~.record.SolveRecord` or its dictionary), or ``""``."""
    diag = record.get("diagnosis") if isinstance(record, dict) else record.diagnosis
    rows = list(Diagnosis.from_dict(diag).last_iterate or ()) if diag else []
    if not rows:
        return ""
    rows.sort(key=lambda f: -f.value / f.bound)
    named = "; ".join(f"{f.subject} ({'Hill equilibrium' if f.check == 'hill_violated' else 'moment balance'} "
                      f"off by {f.value:.3g} {f.unit} at {f.worst_time_s:.3g} s, violated at {f.times_text()})"
                      for f in rows[:6])
    more = f" and {len(rows) - 6} more" if len(rows) > 6 else ""
    return f" The last iterate violates: {named}{more}."


def trials_violation_text(solutions: dict) -> str:
    """:func:`violation_text` of each trial of a multi-trial solve (``{label: Solution}``)."""
    return "".join(f" Trial {label}:{text}" for label, s in solutions.items() if (text := violation_text(s.record)))
