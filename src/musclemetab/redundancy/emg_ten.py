"""EMG-TEN: EMG-informed estimation of tendon stiffness over several trials in one NLP.

One optimal control problem holds, for every trial, the variables and constraints of the
single-trial problem (:mod:`.ipopt`: same mesh, bounds, forward-Euler scheme and node
conventions) plus shared parameters (``docs/solver.md``):

==================  =========================================  ==============================
parameter           size                                       bounds
==================  =========================================  ==============================
``s_kT``            one per estimated muscle (default soleus,  0.1 ... 1.2; ``kT = 35 s_kT``,
                    gasmed, gaslat, vasint, vaslat, vasmed)    ``shift(kT)`` recomputed
``s_EMG``           one per EMG-tracked muscle (alphabetical)  0.05 ... 2.5
==================  =========================================  ==============================

Couplings: ``s_kT(vaslat) = s_kT(vasmed) = s_kT(vasint)`` and
``s_kT(gaslat) = s_kT(gasmed) = s_kT(soleus)`` (consecutive pairs of each group);
``s_EMG(vaslat) = s_EMG(vasmed)``, ``s_EMG(vaslat) = s_EMG(vasint)``,
``s_EMG(gaslat) = s_EMG(gasmed)``. By default (``EmgTenSettings.coupling = "shared"``) each
coupled group is one variable (2 tendon factors and 6 EMG factors on the example). These
defaults name the study's right-leg model; for other models or the left leg the groups come
from the anatomical muscle table (tendon ``achilles`` / ``patellar``, EMG scale groups
``gastrocnemii`` / ``vasti``; :func:`settings_for_muscles`, ``docs/muscles.md``);
``coupling = "constraints"`` keeps the study's 6 + 9 factors with the 4 + 3 equalities. Same
objective, feasible set and bounds; the shared form took 133 IPOPT iterations on the example
against 158-177 for the constraint form (same optimum).

For each trial, tracked muscle ``m`` and control node ``k = 0 ... N-1`` (EMG ``E`` linearly
interpolated at ``t_k``)::

    -0.01 <= e_mk - s_EMG,m E_m(t_k) <= 0.01

Objective (trials summed, each normalised by its own ``N``)::

    J = sum_trials [ wEMG sum (e - s E)^2/(nEMG N) + wAct/2 (sum e^2 + sum a^2)/(N M)
                     + wTres sum aT^2/(N D) + wVm sum v~M^2/(N M) ]

with ``[wEMG, wAct, wTres, wVm] = [10, 0.1, 1000, 0.01]``. The Hill equilibrium and the
joint moments use ``kT = s_kT 35`` (symbolic) for the estimated muscles.

**Transcription.** The problem core (:mod:`.transcription`): the trials' blocks of the single-trial
problem with the EMG goals (tracking cost and bound rows after each interval's equality rows)
and the shared factors ``[s_kT, s_EMG]`` last; couplings (constraint form) after all trials.
IPOPT settings are those of :class:`~.ipopt.SolverOptions` plus :data:`EMG_TEN_MUMPS_OPTIONS`.

**Initial guess.** Per trial the static-optimisation guess of the single-trial problem with
the reserve divided by ``Topt``; all scale factors 1.

The estimates and ``parameters.json``: :mod:`.result`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np

from ..errors import DataMismatchError, OptionError, UnknownMuscleError
from ..messages import name_list
from ._checks import COUPLINGS, EMG_MODES, check_factor_bounds, check_non_negative, check_option
from .transcription import Goals, ParameterSpec, TrialBlock, build_problem, coupling_pairs
from .inputs import TrialInputs
from .parameters import MuscleTendonParameters
from .ipopt import ProblemResult, SolverOptions, solve_problem
from .static_opt import InitialGuess

__all__ = [
    "EmgTenSettings",
    "EMG_TEN_GOALS",
    "EmgTenTrial",
    "informed_settings",
    "emg_bound",
    "emg_failure",
    "settings_for_muscles",
    "settings_without",
    "build_emg_ten_nlp",
    "solve_emg_ten_ocp",
    "emg_ten_problem",
    "EMG_TEN_MUMPS_OPTIONS",
]

#: Linear-algebra settings of IPOPT for EMG-TEN (``SolverOptions.ipopt`` overrides them):
#: MUMPS's approximate-minimum-fill ordering (on the three example trials it factorises in about
#: two thirds of the time of MUMPS's automatic choice) and no iterative refinement of a linear
#: solve whose residual already meets IPOPT's accuracy test (IPOPT's default is at least one
#: step; here that saves a quarter of the solve time with identical iterates to 1e-11). They
#: change the round-off of the KKT solves, not the problem.
EMG_TEN_MUMPS_OPTIONS = {"mumps_pivot_order": 2, "min_refinement_steps": 0}
#: The study's EMG-TEN weights: EMG tracking 10, activation 0.1, reserve 1000, fiber velocity 0.01.
EMG_TEN_GOALS = Goals(w_activation=0.1, w_reserve=1000.0, w_velocity=0.01, w_emg=10.0)


def emg_bound(mode: str, tolerance: float) -> float | None:
    """Half-width of the EMG bound rows of an EMG ``mode``: ``tolerance`` when constrained, 0 when
    driven (each tracked excitation is its scaled EMG), ``None`` (no bound rows) when tracking."""
    return {"constrained": tolerance, "driven": 0.0}.get(mode)


@dataclass(frozen=True)
class EmgTenSettings:
    """Goals, bounds and couplings of the EMG-TEN problem (defaults: the study's).

    ``goals``: the objective's weights (:class:`.goals.Goals`; default
    :data:`EMG_TEN_GOALS`, ``wEMG 10, wAct 0.1, wTres 1000, wVm 0.01``), which also hold the
    transcription of the fiber dynamics (``goals.fiber_dynamics``; ``None``, the default, is
    ``"backward"`` in the driven mode and ``"forward"`` in the others: with the excitations
    fixed, the forward-Euler fiber recurrence of weakly excited muscles amplifies a change of
    fiber length by up to 1e4 per step, the backward-Euler one damps it, ``docs/problem.md``);
    the EMG bound of the problem comes from ``emg_mode`` and ``emg_tolerance`` below.

    ``tendon_groups``: muscles whose ``kT`` is estimated; the muscles of a group share one
    factor (couplings between consecutive members). ``emg_groups``: tracked muscles sharing one
    EMG scale factor (couplings between the first member and each other one); members that
    are not tracked are ignored. ``emg_tolerance``: half-width of the EMG tracking band.
    ``emg_range_tolerance``: how far the mapped EMG may lie outside ``[0, 1]`` in the trial
    window before the input is rejected (0: not at all). ``coupling``: ``"shared"`` (default)
    gives each coupled group one variable; ``"constraints"`` keeps one variable per muscle and
    imposes the couplings as equality constraints, the study's NLP (77 250 variables and 62 002
    equalities on the example instead of 77 243 and 61 995). Both are the same problem (same
    objective, feasible set, bounds); they take different paths to the same optimum.

    ``emg_mode``: ``"constrained"`` (the EMG bound rows with ``emg_tolerance`` and the tracking
    cost ``goals.w_emg``), ``"driven"`` (bound rows with tolerance 0: each tracked excitation is its
    scaled EMG) or ``"tracking"`` (the cost only). With ``tendon_groups`` empty no tendon
    stiffness is estimated: an EMG-informed solve of one or more trials.
    """

    goals: Goals = EMG_TEN_GOALS
    emg_tolerance: float = 0.01
    tendon_scale_bounds: tuple[float, float] = (0.1, 1.2)
    emg_scale_bounds: tuple[float, float] = (0.05, 2.5)
    tendon_groups: tuple[tuple[str, ...], ...] = (
        ("vaslat_r", "vasmed_r", "vasint_r"), ("gaslat_r", "gasmed_r", "soleus_r"))
    emg_groups: tuple[tuple[str, ...], ...] = (("vaslat_r", "vasmed_r", "vasint_r"), ("gaslat_r", "gasmed_r"))
    emg_range_tolerance: float = 0.0
    coupling: str = "shared"
    emg_mode: str = "constrained"

    def __post_init__(self):
        if not isinstance(self.goals, Goals):
            raise OptionError(f"goals must be a Goals, not {type(self.goals).__name__}")
        if self.goals.energy is not None or self.goals.w_fiber_length:
            raise OptionError("the EMG-TEN and EMG-informed goals take no energy goal and no fiber-length weight; "
                              "drop them from goals")
        check_non_negative("emg_tolerance", self.emg_tolerance)
        check_non_negative("emg_range_tolerance", self.emg_range_tolerance)
        for name in ("tendon_scale_bounds", "emg_scale_bounds"):
            object.__setattr__(self, name, check_factor_bounds(name, getattr(self, name)))
        for name in ("tendon_groups", "emg_groups"):
            groups = tuple(tuple(str(m) for m in g) for g in getattr(self, name))
            flat = [m for g in groups for m in g]
            if len(set(flat)) != len(flat):
                raise OptionError(f"{name}: a muscle appears in more than one group ({groups})")
            object.__setattr__(self, name, groups)
        check_option("coupling", self.coupling, COUPLINGS)
        check_option("the EMG mode", self.emg_mode, EMG_MODES)
        if self.emg_mode == "tracking" and not self.goals.w_emg > 0:
            raise OptionError("the EMG mode 'tracking' needs a positive EMG weight w_emg")

    @property
    def problem_goals(self) -> Goals:
        """The goals of the problem: ``goals`` resolved for ``emg_mode`` (:meth:`.goals.Goals.resolved`)
        with the EMG bound of the mode (:attr:`emg_bound`)."""
        return replace(self.goals.resolved(self.emg_mode), emg_tolerance=self.emg_bound)

    @property
    def fiber_scheme(self) -> str:
        """The transcription of the fiber dynamics used: ``goals.fiber_dynamics`` or the mode's default."""
        return self.goals.resolved(self.emg_mode).fiber_dynamics

    @property
    def emg_bound(self) -> float | None:
        """Half-width of the EMG bound rows (``None``: no bound rows)."""
        return emg_bound(self.emg_mode, self.emg_tolerance)

    @property
    def tendon_muscles(self) -> tuple[str, ...]:
        return tuple(m for g in self.tendon_groups for m in g)

    def to_dict(self) -> dict:
        return {
            "weights": {"w_emg": self.goals.w_emg, **self.goals.effort_weights()},
            "emg_tolerance": self.emg_tolerance,
            "tendon_scale_bounds": list(self.tendon_scale_bounds),
            "emg_scale_bounds": list(self.emg_scale_bounds),
            "tendon_groups": [list(g) for g in self.tendon_groups],
            "emg_groups": [list(g) for g in self.emg_groups],
            "emg_range_tolerance": self.emg_range_tolerance,
            "coupling": self.coupling,
            "emg_mode": self.emg_mode,
            "fiber_dynamics": self.fiber_scheme,
        }

    @classmethod
    def from_dict(cls, d: dict) -> "EmgTenSettings":
        """The settings :meth:`to_dict` recorded (``summary.json``, ``parameters.json``); the goals
        hold the recorded (resolved) fiber dynamics."""
        return cls(goals=Goals(**d["weights"], fiber_dynamics=d["fiber_dynamics"]), emg_tolerance=d["emg_tolerance"],
                   tendon_scale_bounds=tuple(d["tendon_scale_bounds"]), emg_scale_bounds=tuple(d["emg_scale_bounds"]),
                   tendon_groups=tuple(tuple(g) for g in d["tendon_groups"]),
                   emg_groups=tuple(tuple(g) for g in d["emg_groups"]), emg_range_tolerance=d["emg_range_tolerance"],
                   coupling=d["coupling"], emg_mode=d["emg_mode"])


def informed_settings(workflow: str, mode: str = "constrained", tolerance: float = 0.01,
                      w_emg: float | None = None, fiber_dynamics: str | None = None) -> EmgTenSettings:
    """Settings of an effort workflow's EMG-informed solve: the workflow's effort weights, the
    EMG goals of ``mode`` (tracking weight ``w_emg``, default 10 for ``tracking`` and 0 for
    ``constrained``/``driven``), the goals' ``fiber_dynamics`` (``None``: the mode's default),
    no tendon stiffness estimated."""
    from .workflows import get_workflow

    wf = get_workflow(workflow)
    w_emg = w_emg if w_emg is not None else (10.0 if mode == "tracking" else 0.0)
    return EmgTenSettings(goals=Goals(**wf.goals.effort_weights(), w_emg=w_emg, fiber_dynamics=fiber_dynamics),
                          emg_tolerance=tolerance, tendon_groups=(), emg_mode=mode)


def emg_failure(record, mode: str, what: str, fiber_dynamics: str = "backward"):
    """The :class:`~musclemetab.errors.SolverError` of an EMG-informed solve that did not
    succeed (``record``: its :class:`~.record.RunRecord`). An infeasible EMG-driven solve says
    why: with every tracked excitation fixed, the forward-Euler fiber dynamics of weakly excited
    muscles amplify errors by orders of magnitude per mesh step (``docs/problem.md``); with the
    backward-Euler ones the scaled EMG cannot explain the moments within the bounds."""
    from ..errors import SolverError
    from .ipopt import INFEASIBLE_STATUSES

    if mode != "driven" or record.status not in INFEASIBLE_STATUSES:
        return record.failure(what)
    head = (f"{what} did not converge: IPOPT status {record.status} after {record.iterations} iterations. The "
            "EMG-driven problem is infeasible in practice: ")
    if fiber_dynamics == "forward":
        why = ("with the tracked excitations fixed to the scaled EMG, the forward-Euler fiber lengths of weakly "
               "excited muscles follow an unstable recurrence on the mesh, so no iterate meets the constraints to "
               "the solver's tolerance; more iterations will not help. Drop --fiber-dynamics forward (the driven "
               "mode's default is backward), or use --emg-mode constrained with a small --emg-tolerance")
    else:
        why = ("with the tracked excitations fixed to the scaled EMG (scale factors within their bounds), the "
               "muscles and reserves cannot meet the joint moments and muscle equilibria; more iterations will not "
               "help. Check the EMG files and --emg-mapping, or use --emg-mode constrained with an --emg-tolerance")
    return SolverError(head + why + ", see docs/problem.md")


def settings_for_muscles(settings: EmgTenSettings | None, muscles: Sequence[str]) -> EmgTenSettings:
    """``settings`` whose default tendon and EMG groups (the study's right-leg model) are
    replaced, when the problem lacks those muscles, by the groups of the anatomical muscle
    table for ``muscles`` (any model family, either side; see ``docs/muscles.md``)."""
    from ..properties import emg_scale_groups, tendon_groups

    settings = settings or EmgTenSettings()
    default = EmgTenSettings()
    present = set(muscles)
    changes = {}
    if settings.tendon_groups == default.tendon_groups and not set(settings.tendon_muscles) <= present:
        changes["tendon_groups"] = tuple(tendon_groups(muscles).values())
    if settings.emg_groups == default.emg_groups and not {m for g in settings.emg_groups for m in g} <= present:
        changes["emg_groups"] = tuple(emg_scale_groups(muscles).values())
    return replace(settings, **changes) if changes else settings


def settings_without(settings: EmgTenSettings | None, muscles: Sequence[str], excluded: Sequence[str]) -> EmgTenSettings:
    """``settings`` for the problem's ``muscles`` (:func:`settings_for_muscles`, before the
    exclusion) with the ``excluded`` muscles taken out of the tendon and EMG scale groups: the
    group's other members keep their shared factor; a group left empty is dropped. A
    :class:`~musclemetab.errors.MusclemetabWarning` names the muscles whose tendon stiffness is
    then not estimated."""
    import warnings

    from ..errors import MusclemetabWarning

    settings = settings_for_muscles(settings, muscles)
    gone = set(excluded)
    dropped = [m for m in settings.tendon_muscles if m in gone]
    if not gone & ({m for g in settings.tendon_groups for m in g} | {m for g in settings.emg_groups for m in g}):
        return settings
    if dropped:
        warnings.warn(f"--exclude-muscles {' '.join(dropped)}: the tendon stiffness of {name_list(dropped)} is not "
                      "estimated (the muscle is out of the problem); the other muscles of its tendon group share "
                      "their factor", MusclemetabWarning, stacklevel=3)

    def keep(groups):
        return tuple(g for g in (tuple(m for m in grp if m not in gone) for grp in groups) if g)

    return replace(settings, tendon_groups=keep(settings.tendon_groups), emg_groups=keep(settings.emg_groups))


# ----------------------------------------------------------------------------- problem
@dataclass(frozen=True)
class EmgTenTrial:
    """One trial of the EMG-TEN problem: mesh inputs, EMG at the control nodes, guess."""

    label: str
    inputs: TrialInputs
    emg_muscles: tuple[str, ...]
    emg_nodes: np.ndarray  # (N, nEMG), E_m(t_k) at k = 0..N-1
    emg_channels: dict
    guess: InitialGuess | None = None
    sources: dict = field(default_factory=dict)
    static_optimisation_objective: float = math.nan


def emg_ten_problem(trials: Sequence[EmgTenTrial], params: MuscleTendonParameters,
                    settings: EmgTenSettings | None = None):
    """EMG-TEN as an instance of the problem core: ``(blocks, goals, specs)``.

    The trials with the EMG goals (tracking cost ``goals.w_emg``, bound ``emg_tolerance``) and the
    shared factors ``s_kT`` of ``settings.tendon_groups`` (model order, couplings between
    consecutive members of a group) and ``s_EMG`` of the tracked muscles (alphabetical,
    couplings between the first member of an EMG group and each other one).
    """
    settings = settings_for_muscles(settings, params.names)
    if not trials:
        raise OptionError("EMG-TEN needs at least one trial")
    muscles = tuple(trials[0].inputs.muscles)
    emg_muscles = tuple(trials[0].emg_muscles)
    for t in trials:
        if tuple(t.emg_muscles) != emg_muscles:
            raise DataMismatchError(f"trial {t.label} tracks other muscles than trial {trials[0].label}")
        if t.guess is None:
            raise OptionError(f"trial {t.label} has no initial guess")
    have = {m for t in trials for m in t.inputs.muscles}
    missing = [m for m in settings.tendon_muscles if m not in have]
    if missing:
        raise UnknownMuscleError(
            f"muscle{'s' if len(missing) > 1 else ''} {name_list(missing)} of the EMG-TEN settings "
            f"not among the muscles of the problem ({', '.join(muscles[:6])} ...)")
    specs = emg_ten_specs(settings, list(dict.fromkeys(m for t in trials for m in t.inputs.muscles)), emg_muscles)
    goals = settings.problem_goals
    blocks = [TrialBlock(t.label, t.inputs, t.guess, emg_muscles=emg_muscles, emg_nodes=t.emg_nodes)
              for t in trials]
    return blocks, goals, specs


def emg_ten_specs(settings: EmgTenSettings, muscles: Sequence[str], emg_muscles: Sequence[str]) -> list[ParameterSpec]:
    """The shared factors of an EMG problem: ``s_kT`` of ``settings.tendon_groups`` (in the order
    of ``muscles``, couplings between consecutive members of a group) and ``s_EMG`` of the
    tracked ``emg_muscles`` (couplings between the first member of an EMG group and each other one)."""
    kt_muscles = tuple(m for m in muscles if m in settings.tendon_muscles)
    specs = [ParameterSpec("tendon_stiffness", kt_muscles, settings.tendon_scale_bounds,
                           coupling_pairs(settings.tendon_groups, kt_muscles, consecutive=True))] if kt_muscles else []
    emg_muscles = tuple(emg_muscles)
    specs.append(ParameterSpec("emg_scale", emg_muscles, settings.emg_scale_bounds,
                               coupling_pairs(settings.emg_groups, emg_muscles, consecutive=False)))
    return specs


def build_emg_ten_nlp(
    trials: Sequence[EmgTenTrial],
    params: MuscleTendonParameters,
    settings: EmgTenSettings | None = None,
    options: SolverOptions | None = None,
) -> dict:
    """The EMG-TEN NLP over all ``trials`` (:func:`.transcription.build_problem`), without solving it."""
    settings = settings_for_muscles(settings, params.names)
    options = options or SolverOptions()
    blocks, goals, specs = emg_ten_problem(trials, params, settings)
    return build_problem(blocks, params, goals, specs, optimal_reserve_Nm=options.optimal_reserve_Nm,
                         coupling=settings.coupling, explicit_derivatives=options.derivatives == "explicit")


def solve_emg_ten_ocp(
    trials: Sequence[EmgTenTrial],
    params: MuscleTendonParameters,
    settings: EmgTenSettings | None = None,
    options: SolverOptions | None = None,
) -> ProblemResult:
    """Build and solve the EMG-TEN NLP; never raises on non-convergence (see ``success``)."""
    settings = settings_for_muscles(settings, params.names)
    blocks, goals, specs = emg_ten_problem(trials, params, settings)
    return solve_problem(blocks, params, goals, specs, options=options, coupling=settings.coupling,
                         mumps_settings=EMG_TEN_MUMPS_OPTIONS)

