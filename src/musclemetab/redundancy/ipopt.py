"""The muscle redundancy optimal control problem (De Groote et al. 2016), CasADi + IPOPT.

Variables (``M`` muscles, ``D`` DOFs, ``N`` mesh intervals, ``h = (tf - t0)/N``):

========================  ==========  ===================
variable                  size        bounds
========================  ==========  ===================
activation ``a``          M x (N+1)   0 ... 1
fiber length ``l~M``      M x (N+1)   0.1 ... 1.7 [#]_
projected length ``lp``   M x (N+1)   >= 1e-4 m
excitation ``e``          M x N       0 ... 1
reserve ``aT``            D x N       -1 ... 1 (x Topt = 150 N m)
fiber velocity ``v~M``    M x N       -10 ... 10 lMo/s
========================  ==========  ===================

.. [#] or, for a muscle the geometry stretches further, its longest rigid-tendon fiber length
   plus 0.05 (:func:`.bounds.fiber_length_upper_bounds`).

Constraints at nodes ``k = 0 ... N-1`` (forward Euler; with ``fiber_dynamics="backward"`` the
Hill equilibrium holds at node ``k+1`` with ``v~M_k``, ``docs/problem.md``)::

    a_{k+1} - a_k - h ADyn(e_k, a_k) = 0
    l~M_{k+1} - l~M_k - h v~M_k = 0
    (l~M_k lMo)^2 - w^2 - lp_k^2 = 0                       (also at node N)
    [a_k fL fV(v~M_k/vmax) + fPE] lp_k/(l~M_k lMo) - fT((lMT_k - lp_k)/lTs) = 0
    ID_j(t_k) - sum_m F0_m fT_mk r_jm(t_k) - Topt aT_jk = 0

Objective::

    J = wAct/2 (sum e^2 + sum a^2)/(N M) + wTres sum aT^2/(N D) + wVm sum v~M^2/(N M)

(``a`` has N+1 columns but is divided by N, as in the study; the terms are those of
:mod:`.objective`, with the energy, EMG and fiber-length goals of :class:`.goals.Goals`.) Simple bounds are passed to
IPOPT as variable bounds (``lbx``/``ubx``), not as constraint rows. The per-node constraint
function is built once from symbolic expressions and mapped over the mesh, so the expression
graph (and its derivatives) does not grow with ``N``.

Variables are ordered node by node, ``[a_k, l~M_k, lp_k, e_k, aT_k, v~M_k]`` for
``k = 0 ... N-1`` then ``[a_N, l~M_N, lp_N]``, and constraints likewise, which keeps the KKT
matrix banded.
"""

from __future__ import annotations

import functools
import time as _time
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import OptionError, SolverError
from ..processes import sigint_noted
from ._checks import check_option
from .objective import EmgTracking, find_term, goal_terms, node_arrays, term_values
from .transcription import Goals, TrialBlock, build_problem
from .inputs import TrialInputs
from .parameters import MuscleTendonParameters
from .static_opt import InitialGuess
from .stops import DEFAULT_STOP, STOPS
from .linear_solvers import (  # noqa: F401  (re-exported)
    BUILTIN_LINEAR_SOLVERS, LIBRARY_ENV, LINEAR_SOLVER_SYMBOLS, RUNTIME_LINEAR_SOLVERS, check_linear_solver,
    exported_symbols, linear_solver_library,
)
from .progress import PROGRESS_INTERVAL_S, ProgressLines, progress_interval, solve_progress  # noqa: F401
from .progress import _progress_callback
from .resources import (  # noqa: F401  (re-exported)
    MAX_PROBLEM_MEMORY_MB, check_problem_memory, problem_memory_mb, problem_size, set_blas_threads, tune_malloc,
)

__all__ = [
    "SolverOptions",
    "STOPS",
    "DEFAULT_STOP",
    "OcpResult",
    "solve_ocp",
    "solver_record",
    "single_trial_goals",
    "build_nlp",
    "problem_size",
    "failure_advice",
    "INFEASIBLE_STATUSES",
    "tune_malloc",
    "set_blas_threads",
    "check_linear_solver",
    "exported_symbols",
    "problem_memory_mb",
    "check_problem_memory",
    "MAX_PROBLEM_MEMORY_MB",
    "LIBRARY_ENV",
    "solve_progress",
    "progress_interval",
    "PROGRESS_INTERVAL_S",
]





@dataclass(frozen=True)
class SolverOptions:
    """Numerical settings of the optimal control problem; the objective's weights are a
    :class:`.goals.Goals` (``docs/solver.md``).

    ``stop`` names where IPOPT stops (:data:`STOPS`, ``docs/solver.md``): ``"optimum"`` (default)
    at the optimum of the problem (tolerance 1e-8 with IPOPT's adaptive barrier parameter: the
    activations of muscles that are off reach their bound and the energy models' activation heat
    no longer counts the barrier's residue); ``"authors"``: the study's settings (tolerance 1e-6,
    IPOPT's default monotone barrier strategy), which stop where the rates are 4-18 % above
    those of the optimum. ``tol`` overrides the stop's tolerance. The other defaults are the
    study's: ``Topt = 150 N m``, IPOPT with exact Hessian, MUMPS, gradient-based NLP scaling,
    ``max_iter = 10000``, ``mu_init = 0.1`` (the problem has several local optima; other barrier
    settings can end in a different one).

    ``derivatives="explicit"`` (default) gives IPOPT the constraint Jacobian and the Hessian
    of the Lagrangian assembled from per-interval symbolic derivatives (the Jacobian is block
    banded, the Hessian block diagonal); ``"auto"`` lets CasADi differentiate the whole mapped
    expression graph. Both compute the same derivatives; the explicit form builds and
    evaluates faster.

    ``linear_solver`` is IPOPT's solver of the KKT systems: ``"mumps"`` (default) and
    ``"spral"`` are part of CasADi's IPOPT; ``"ma27"``, ``"ma57"``, ``"ma77"``, ``"ma86"``,
    ``"ma97"`` (HSL) and ``"pardiso"`` (pardiso-project.org) are loaded by IPOPT at run time
    from ``linear_solver_library`` (else the environment variable :data:`LIBRARY_ENV`, else
    ``libhsl.so`` / ``libpardiso.so`` on the library search path); when the options are made the
    library's symbol table is checked and only then is it loaded, so a missing or foreign one is
    reported before any problem is built (:func:`check_linear_solver`). Another solver can end in another local optimum.

    ``tune_malloc`` raises glibc's ``malloc`` thresholds for the process before solving
    (MUMPS reallocates its work arrays every iteration). ``blas_threads`` sets the number of
    threads of the BLAS used by MUMPS (CasADi's OpenBLAS); the dense blocks here are small, so
    one thread is fastest and leaves the other cores to other solves (``None`` leaves the
    library default). ``ipopt`` holds further IPOPT options, e.g. ``{"mu_init": 1e-6}`` for a
    warm start; anything there may change which optimum is found.

    What the problem asks (the objective's weights, the energy goal, the transcription of the
    fiber dynamics) is a :class:`.goals.Goals`, not these options. ``optimal_reserve_Nm`` is no
    weight either: it is the strength of the reserve actuators (``Topt aT`` in the moment rows).
    """

    optimal_reserve_Nm: float = 150.0
    tol: float | None = None
    max_iter: int = 10000
    linear_solver: str = "mumps"
    linear_solver_library: str | None = None
    print_level: int = 0
    derivatives: str = "explicit"
    tune_malloc: bool = True
    blas_threads: int | None = 1
    ipopt: dict = field(default_factory=dict)
    stop: str = DEFAULT_STOP

    def __post_init__(self):
        check_option("stop", self.stop, tuple(STOPS))
        if self.tol is not None and not (0 < self.tol < 1):
            raise OptionError(f"tol must lie between 0 and 1 (an IPOPT tolerance), not {self.tol!r}")
        check_option("derivatives", self.derivatives, ("explicit", "auto"))
        if self.optimal_reserve_Nm <= 0:
            raise OptionError(f"optimal_reserve_Nm must be positive, not {self.optimal_reserve_Nm}")
        if self.max_iter < 1:
            raise OptionError(f"max_iter must be at least 1, not {self.max_iter}")
        check_linear_solver(self.linear_solver, self.linear_solver_library)

    def with_(self, **kw) -> "SolverOptions":
        return replace(self, **kw)

    @property
    def tolerance(self) -> float:
        """IPOPT's ``tol`` of the solve: ``tol`` when given, else the stop's."""
        return float(self.tol) if self.tol is not None else float(STOPS[self.stop]["tol"])

    def to_dict(self) -> dict:
        return {
            "stop": self.stop,
            "optimal_reserve_Nm": self.optimal_reserve_Nm,
            "tol": self.tolerance,
            "max_iter": self.max_iter,
            "linear_solver": self.linear_solver,
            "linear_solver_library": self.linear_solver_library,
            "derivatives": self.derivatives,
            "tune_malloc": self.tune_malloc,
            "blas_threads": self.blas_threads,
            "ipopt": dict(self.ipopt),
        }


@dataclass(frozen=True, kw_only=True)
class SolveOutcome:
    """IPOPT's outcome of one solve (shared by all trials of a problem)."""

    status: str
    success: bool
    iterations: int
    solve_time_s: float
    solve_cpu_s: float
    build_time_s: float
    n_variables: int
    max_constraint_violation: float
    function_time_s: dict = field(default_factory=dict)
    #: IPOPT's barrier parameter at the last iterate (``nan``: not reported)
    final_barrier_parameter: float = float("nan")
    #: IPOPT started from a previous optimum's variables and multipliers (``InitialGuess.start``)
    started_from_optimum: bool = False


@dataclass(frozen=True, kw_only=True)
class OcpResult(SolveOutcome):
    """Raw optimum of one trial: states ``(N+1, M)``, controls ``(N, M)`` / ``(N, D)``, IPOPT statistics."""

    activation: np.ndarray
    lm_norm: np.ndarray
    lm_projected_m: np.ndarray
    excitation: np.ndarray
    reserve: np.ndarray
    fiber_velocity_lmo_per_s: np.ndarray
    objective: float
    objective_terms: dict
    n_constraints: int
    #: the optimum's variables ``x`` and multipliers ``lam_g``, ``lam_x`` (a start for a problem
    #: of the same structure: :data:`WARM_START_MULTIPLIER_OPTIONS`)
    kkt: dict = field(default_factory=dict, repr=False, compare=False)


#: IPOPT statuses that mean the constraints cannot be met (not a matter of iterations).
INFEASIBLE_STATUSES = ("Infeasible_Problem_Detected", "Restoration_Failed", "Not_Enough_Degrees_Of_Freedom",
                       "Search_Direction_Becomes_Too_Small", "Diverging_Iterates")


def failure_advice(status: str) -> str:
    """What to do about a solve that ended with IPOPT status ``status`` (one sentence)."""
    if status in INFEASIBLE_STATUSES:
        return ("the problem is infeasible: the muscles and reserves cannot reproduce the inverse-dynamics "
                "moments within their bounds; check the inputs (moment units and scale, the IK/ID pair, the "
                "muscle and passive parameters); more iterations will not help")
    if status in ("Maximum_Iterations_Exceeded", "Maximum_CpuTime_Exceeded", "Maximum_WallTime_Exceeded"):
        return "the iteration or time limit was reached; raise --max-iter, or check the inputs"
    if status in ("Invalid_Number_Detected", "Error_In_Step_Computation"):
        return ("the solver met NaN or infinite values; check the inputs and parameters for extreme values "
                "(passive parameters, tendon stiffness, moments)")
    if status == "Invalid_Option":
        return ("IPOPT refused an option: most often it could not load the linear solver's library (the "
                "linear-solver library, or the environment variable " + LIBRARY_ENV + "); check that library, or "
                "use mumps")
    if status in ("User_Requested_Stop", "NonIpopt_Exception_Thrown"):
        return "the solve was stopped (interrupt or an error in a callback); run it again"
    return "check the inputs (units, time ranges, parameters)"


def build_nlp(
    inputs: TrialInputs,
    params: MuscleTendonParameters,
    guess: InitialGuess,
    options: SolverOptions | None = None,
    goals: Goals | None = None,
) -> dict:
    """The NLP of the single-trial problem, without solving it: the problem core
    (:func:`.transcription.build_problem`) with one trial and ``goals`` (default ``Goals()``)."""
    options = options or SolverOptions()
    return build_problem([TrialBlock("trial", inputs, guess)], params, single_trial_goals(goals),
                         optimal_reserve_Nm=options.optimal_reserve_Nm,
                         explicit_derivatives=options.derivatives == "explicit")


def single_trial_goals(goals: Goals | None) -> Goals:
    """The goals of a single-trial solve: ``goals`` (default ``Goals()``: the effort goal),
    checked and resolved (:meth:`.goals.Goals.resolved`: the forward fiber dynamics unless
    given). A single-trial solve has no EMG or measured fiber lengths: ``goals`` asking to track
    them (``w_emg``, ``emg_tolerance``, ``w_fiber_length``) is an
    :class:`~musclemetab.errors.OptionError` saying where they are tracked
    (:func:`~musclemetab.redundancy.solve_emg_ten`, :func:`~musclemetab.redundancy.estimate_files`)."""
    goals = goals or Goals()
    tracked = [f"{name}={getattr(goals, name)}" for name, unset in (("w_emg", 0.0), ("emg_tolerance", None),
                                                                     ("w_fiber_length", 0.0))
               if getattr(goals, name) != unset]
    if tracked:
        raise OptionError(f"the goals ask to track measurements ({', '.join(tracked)}) but a single-trial solve has "
                          "no EMG or measured fiber lengths; track EMG with solve_emg_ten (musclemetab solve --emg) "
                          "and fiber lengths with estimate_files (musclemetab estimate), or leave these goals out")
    return goals.resolved()


def solver_record(options: SolverOptions, goals: Goals | None = None) -> dict:
    """The ``solver_options`` record of a solve: the effort weights of ``goals`` (default
    ``Goals()``) under ``w_activation``, ``w_reserve``, ``w_velocity``, the numerical settings of
    ``options``, then the energy goal (``energy``) and the backward fiber dynamics
    (``fiber_dynamics``) when ``goals`` has them (EMG-TEN and ``estimate`` record their fiber
    dynamics beside their settings and pass ``goals.effort()``)."""
    goals = goals or Goals()
    return {**goals.effort_weights(), **options.to_dict(),
            **({"energy": goals.energy.record()} if goals.energy is not None else {}),
            **({"fiber_dynamics": "backward"} if goals.fiber_dynamics == "backward" else {})}


#: IPOPT linear-algebra settings used with MUMPS (``SolverOptions.ipopt`` overrides them): no
#: iterative refinement of a linear solve whose residual already meets IPOPT's accuracy test
#: (IPOPT's default is at least one step), and MUMPS' pivot tolerance from 1e-4 instead of
#: 1e-6, which spares the factorisations IPOPT repeats with a raised tolerance when a solve is
#: not accurate enough (docs/solver.md, "Inertia corrections"). On the example trials the
#: iterations and optimum are the same; they change the round-off of the KKT solves, not the
#: problem.
MUMPS_OPTIONS = {"min_refinement_steps": 0, "mumps_pivtol": 1e-4}

#: IPOPT's start from a previous optimum's variables and multipliers (``InitialGuess.start``): its
#: warm start, with its default pushes off the bounds (1e-3; 1e-4 cost more per iteration and
#: once ended at another optimum). The example's uncertainty samples take half the iterations of
#: a cold solve from it (docs/solver.md, "Warm starts at the optimum").
WARM_START_MULTIPLIER_OPTIONS = {"warm_start_init_point": "yes"}


def ipopt_options(options: SolverOptions, mumps_settings: dict | None = None) -> dict:
    """IPOPT's options for a problem: tolerances, scaling, exact Hessian, the linear solver
    (with ``mumps_settings`` when it is MUMPS), then the user's ``options.ipopt``."""
    ipopt = {
        **STOPS[options.stop],
        "tol": options.tolerance,
        "max_iter": int(options.max_iter),
        "nlp_scaling_method": "gradient-based",
        "linear_solver": options.linear_solver,
        "print_level": int(options.print_level),
        "hessian_approximation": "exact",
        "sb": "yes",  # no banner
    }
    if options.linear_solver in RUNTIME_LINEAR_SOLVERS:
        option, _ = RUNTIME_LINEAR_SOLVERS[options.linear_solver]
        ipopt[option] = linear_solver_library(options.linear_solver, options.linear_solver_library)
    if options.linear_solver == "mumps" and mumps_settings:
        ipopt.update(mumps_settings)
    ipopt.update(options.ipopt)
    return ipopt


def run_ipopt(solver, options: SolverOptions, x0, lbx, ubx, lbg, ubg, multipliers: dict | None = None, p=None,
              start: dict | None = None):
    """Apply the process settings of ``options`` (``tune_malloc``, ``blas_threads``) and run
    an IPOPT ``nlpsol`` (with the NLP parameter's values ``p``, if it has one); returns ``(x, g,
    f, stats, wall time s, CPU time s)``. A dict ``multipliers`` receives the optimum's
    ``lam_g`` and ``lam_x`` (CasADi's signs: ``grad f + J' lam_g + lam_x = 0``); ``start``, such a
    dict with ``x``, starts IPOPT from those variables and multipliers (``lam_x0``, ``lam_g0``)."""
    if options.tune_malloc:
        tune_malloc()
    if options.blas_threads is not None:
        set_blas_threads(options.blas_threads)
    t0 = _time.perf_counter()
    c0 = _time.process_time()
    try:
        with sigint_noted():  # Ctrl-C stops IPOPT with a failure status: raised as an interrupt
            sol = solver(x0=x0 if start is None else start["x"], lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg,
                         **({} if p is None else {"p": p}),
                         **({} if start is None else {"lam_x0": start["lam_x"], "lam_g0": start["lam_g"]}))
    except RuntimeError as exc:
        raise SolverError(f"IPOPT stopped with an error: {exc}") from None
    if multipliers is not None:
        multipliers.update(lam_g=np.asarray(sol["lam_g"]).reshape(-1), lam_x=np.asarray(sol["lam_x"]).reshape(-1))
    return (np.asarray(sol["x"]).reshape(-1), np.asarray(sol["g"]).reshape(-1), float(sol["f"]), solver.stats(),
            _time.perf_counter() - t0, _time.process_time() - c0)




@dataclass(frozen=True, kw_only=True)
class ProblemResult(SolveOutcome):
    """Raw optimum of a problem (:func:`solve_problem`): one :class:`OcpResult` per trial (its
    ``objective`` the trial's own terms), the factors by kind and muscle, IPOPT's outcome."""

    trials: tuple[OcpResult, ...]
    factors: dict  # kind -> {muscle: factor}
    objective_terms: dict  # trial label -> {term: value}
    emg_deviation: tuple[np.ndarray, ...]  # per trial (N, nEMG): e - s E
    objective: float
    n_equality_constraints: int
    n_inequality_constraints: int
    max_coupling_violation: float
    ipopt_options: dict = field(default_factory=dict)
    #: the optimum's variables ``x`` and multipliers ``lam_g``, ``lam_x`` (:mod:`.identifiability`)
    kkt: dict = field(default_factory=dict, repr=False, compare=False)


def _trial_values(goals: Goals, t: TrialBlock, Z, xl, factors: dict, params) -> tuple:
    """The NumPy node values (:func:`.objective.node_arrays`) of one trial at the optimum, at
    nodes ``0 ... N-1`` and at node ``N``, and its terms (:func:`.objective.goal_terms`)."""
    M, D = len(t.inputs.muscles), len(t.inputs.dofs)
    s_lmo = factors.get("optimal_fiber_length", {})
    pos = {m: k for k, m in enumerate(t.inputs.muscles)}
    emg = {"emg": t.emg_nodes, "emg_scale": [factors["emg_scale"][m] for m in t.emg_muscles]} if t.emg_muscles else {}
    nodes = node_arrays(params, t.inputs.muscles, excitation=Z[:, 3 * M:4 * M], activation=Z[:, 0:M],
                        lm_norm=Z[:, M:2 * M], fiber_velocity_lmo_per_s=Z[:, 4 * M + D:], reserve=Z[:, 4 * M:4 * M + D],
                        lmo_factor=[s_lmo.get(m, 1.0) for m in t.inputs.muscles], energy=goals.energy,
                        lus=t.fiber_length_nodes_m if t.fiber_muscles else None, **emg)
    last = {"a": xl[0:M, None], "lm": xl[M:2 * M, None]}
    terms = goal_terms(goals, [pos[m] for m in t.emg_muscles], [pos[m] for m in t.fiber_muscles])
    return nodes, last, terms


def nlp_solver(nlp: dict, ipopt: dict, callback=None):
    """IPOPT's ``nlpsol`` of a built problem (:func:`.transcription.build_problem`) with the IPOPT
    options ``ipopt`` and a progress ``callback`` (or ``None``). Problems of one structure
    (:func:`.transcription.symbolic_problem`) solved with the same options share one solver
    object within a process (the last one is kept), as they share their NLP; a problem with the
    energy goal or progress lines gets its own."""
    shared = callback is None and nlp["structure"].groups[0].structure.goals.energy is None
    if shared:
        try:
            return _shared_solver(nlp["structure"], tuple(sorted(ipopt.items())))
        except TypeError:  # an IPOPT option value that cannot be a key (a list, say): its own solver
            pass
    return _new_solver(nlp, ipopt, callback)


@functools.lru_cache(maxsize=2)  # a cold solver and a warm-started one (a trial unit and its samples)
def _shared_solver(structure, ipopt: tuple):
    from .transcription import symbolic_problem

    return _new_solver(symbolic_problem(structure), dict(ipopt))


def _new_solver(nlp: dict, ipopt: dict, callback=None):
    import casadi as ca

    nlp_options = {"ipopt": ipopt, "print_time": False, "error_on_fail": False}
    nlp_options.update({k: nlp[k] for k in ("grad_f", "jac_g", "hess_lag") if k in nlp})
    if callback is not None:  # kept referenced by the solver until the solve is done
        nlp_options["iteration_callback"] = callback
    try:
        return ca.nlpsol("mrs", "ipopt", {"x": nlp["x"], "p": nlp["p"], "f": nlp["f"], "g": nlp["g"]}, nlp_options)
    except RuntimeError as exc:
        raise SolverError(f"the optimal control problem could not be built: {exc}") from None


def _final_barrier_parameter(stats: dict) -> float:
    """IPOPT's barrier parameter at the last iterate, from CasADi's solver statistics."""
    mu = (stats.get("iterations") or {}).get("mu") or []
    return float(mu[-1]) if len(mu) else float("nan")


def solve_problem(trials, params: MuscleTendonParameters, goals: Goals, specs=(), *,
                  options: SolverOptions | None = None, coupling: str = "shared",
                  mumps_settings: dict | None = None) -> ProblemResult:
    """Build (:func:`.transcription.build_problem`) and solve a problem; never raises on
    non-convergence (see ``success``). Errors while building raise :class:`SolverError`."""
    options = options or SolverOptions()
    trials, specs = list(trials), list(specs)
    check_problem_memory([(len(t.inputs.muscles), len(t.inputs.dofs), t.inputs.n_intervals) for t in trials])
    t_build = _time.perf_counter()
    nlp = build_problem(trials, params, goals, specs, optimal_reserve_Nm=options.optimal_reserve_Nm,
                        coupling=coupling, explicit_derivatives=options.derivatives == "explicit")
    start = getattr(trials[0].guess, "start", None) if len(trials) == 1 else None
    if start is not None and (np.size(start["x"]), np.size(start["lam_g"])) != (np.size(nlp["x0"]), np.size(nlp["lbg"])):
        start = None  # an optimum of another structure: its variables do not map onto this problem's
    if start is not None:
        options = options.with_(ipopt={**WARM_START_MULTIPLIER_OPTIONS, **options.ipopt})
    ipopt = ipopt_options(options, MUMPS_OPTIONS if mumps_settings is None else mumps_settings)
    callback = _progress_callback(int(nlp["x"].numel()), int(nlp["g"].numel()), nlp["lbg"], nlp["ubg"])
    solver = nlp_solver(nlp, ipopt, callback)
    build_time = _time.perf_counter() - t_build
    kkt = {}
    x, gval, f_opt, stats, solve_time, solve_cpu = run_ipopt(
        solver, options, nlp["x0"], nlp["lbx"], nlp["ubx"], nlp["lbg"], nlp["ubg"], kkt, p=nlp["p_values"],
        **({} if start is None else {"start": start}))
    # IPOPT relaxes the bounds by up to bound_relax_factor (1e-8, relative) and may end a hair
    # outside them (activations of -4e-9): what leaves the solver lies inside its bounds
    x = np.clip(x, np.asarray(nlp["lbx"], dtype=float).reshape(-1), np.asarray(nlp["ubx"], dtype=float).reshape(-1))
    L = nlp["layout"]
    viol = np.maximum(nlp["lbg"] - gval, 0.0) + np.maximum(gval - nlp["ubg"], 0.0)
    max_viol = float(np.max(viol)) if viol.size else 0.0
    p = x[L["P0"]:]
    if L["p_index"] is not None:
        p = p[L["p_index"]] if L["p_index"] else np.zeros(0)
    factors, off = {}, L["spec_off"]
    for i, s in enumerate(specs):
        factors.setdefault(s.kind, {}).update({m: float(v) for m, v in zip(s.muscles, p[off[i]:off[i + 1]])})
    outcome = dict(status=str(stats.get("return_status", "unknown")), success=bool(stats.get("success", False)),
                   iterations=int(stats.get("iter_count", -1)), solve_time_s=solve_time, solve_cpu_s=solve_cpu,
                   build_time_s=build_time, n_variables=nlp["n_variables"], max_constraint_violation=max_viol,
                   function_time_s={k[len("t_wall_"):]: float(v) for k, v in stats.items()
                                    if k.startswith("t_wall_nlp") and v},
                   final_barrier_parameter=_final_barrier_parameter(stats), started_from_optimum=start is not None)
    from ..messages import logger

    logger("redundancy").debug("IPOPT: %s in %d iterations, %d variables, build %.2f s, solve %.2f s, largest "
                               "constraint violation %.1e", outcome["status"], outcome["iterations"],
                               outcome["n_variables"], build_time, solve_time, max_viol)
    ocps, devs = [], []
    for i, t in enumerate(trials):
        d, o = L["trials"][i], L["var_off"][i]
        M, D, N, nz = d["M"], d["D"], d["N"], d["nz"]
        Z = x[o:o + nz * N].reshape(N, nz)
        xl = x[o + nz * N:o + nz * N + 3 * M]
        nodes, last, trial_terms = _trial_values(goals, t, Z, xl, factors, params)
        terms = term_values(trial_terms, nodes, last, N)
        tracking = find_term(trial_terms, EmgTracking)
        dev = tracking.residual(nodes).T if tracking is not None else np.zeros((N, 0))
        ocps.append(OcpResult(
            activation=np.vstack([Z[:, 0:M], xl[0:M]]), lm_norm=np.vstack([Z[:, M:2 * M], xl[M:2 * M]]),
            lm_projected_m=np.vstack([Z[:, 2 * M:3 * M], xl[2 * M:]]), excitation=Z[:, 3 * M:4 * M].copy(),
            reserve=Z[:, 4 * M:4 * M + D].copy(), fiber_velocity_lmo_per_s=Z[:, 4 * M + D:].copy(),
            objective=f_opt if len(trials) == 1 else float(sum(terms.values())), objective_terms=terms,
            n_constraints=nlp["n_equality_constraints"], kkt={"x": x, **kkt} if len(trials) == 1 else {}, **outcome))
        devs.append(dev)
    full = x[L["P0"]:]
    return ProblemResult(
        trials=tuple(ocps), factors=factors,
        objective_terms={t.label: o.objective_terms for t, o in zip(trials, ocps)}, emg_deviation=tuple(devs), objective=f_opt,
        n_equality_constraints=nlp["n_equality_constraints"], n_inequality_constraints=nlp["n_inequality_constraints"],
        max_coupling_violation=float(max((abs(full[a] - full[b]) for a, b in L["pairs"]), default=0.0)),
        ipopt_options=dict(ipopt), kkt={"x": x, **kkt}, **outcome)


def solve_ocp(
    inputs: TrialInputs,
    params: MuscleTendonParameters,
    guess: InitialGuess,
    options: SolverOptions | None = None,
    goals: Goals | None = None,
) -> OcpResult:
    """Build and solve the single-trial problem with ``goals`` (default ``Goals()``: the effort
    goal; :func:`single_trial_goals`) and the numerical settings ``options``; never
    raises on non-convergence (``status`` is IPOPT's return status, ``success`` whether IPOPT
    reported success). Errors while building the problem raise :class:`SolverError`."""
    options = options or SolverOptions()
    res = solve_problem([TrialBlock("trial", inputs, guess)], params, single_trial_goals(goals), options=options)
    return res.trials[0]
