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

(``a`` has N+1 columns but is divided by N, as in the study.) Simple bounds are passed to
IPOPT as variable bounds (``lbx``/``ubx``), not as constraint rows. The per-node constraint
function is built once from symbolic expressions and mapped over the mesh, so the expression
graph (and its derivatives) does not grow with ``N``.

Variables are ordered node by node, ``[a_k, l~M_k, lp_k, e_k, aT_k, v~M_k]`` for
``k = 0 ... N-1`` then ``[a_N, l~M_N, lp_N]``, and constraints likewise, which keeps the KKT
matrix banded.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import os
import struct
import time as _time
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import OptionError, SolverError
from ..processes import sigint_noted
from ._checks import check_option
from .transcription import Goals, TrialBlock, build_problem, check_fiber_dynamics
from .energy import EnergyGoal
from .inputs import TrialInputs
from .parameters import MuscleTendonParameters
from .static_opt import InitialGuess
from .stops import DEFAULT_STOP, STOPS

__all__ = [
    "SolverOptions",
    "STOPS",
    "DEFAULT_STOP",
    "OcpResult",
    "solve_ocp",
    "solver_record",
    "effort_goals",
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
    :class:`.transcription.Goals` (``docs/solver.md``).

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
    warm start; anything there may change which optimum is found. ``energy`` adds the energy
    goal (:class:`.energy.EnergyGoal`) to the objective. ``fiber_dynamics``: the transcription
    of the fiber dynamics (:data:`.transcription.FIBER_DYNAMICS`; ``"backward"``: the Hill equilibrium of
    each interval at its end node, ``docs/problem.md``; not with the energy goal).
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
    energy: EnergyGoal | None = None
    fiber_dynamics: str = "forward"
    stop: str = DEFAULT_STOP

    def __post_init__(self):
        check_option("stop", self.stop, tuple(STOPS))
        if self.tol is not None and not (0 < self.tol < 1):
            raise OptionError(f"tol must lie between 0 and 1 (an IPOPT tolerance), not {self.tol!r}")
        if self.energy is not None and not isinstance(self.energy, EnergyGoal):
            raise OptionError(f"energy must be an EnergyGoal, not {type(self.energy).__name__}")
        check_fiber_dynamics(self.fiber_dynamics, self.energy)
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
            **({"energy": self.energy.record()} if self.energy is not None else {}),
            **({"fiber_dynamics": self.fiber_dynamics} if self.fiber_dynamics != "forward" else {}),
        }


#: IPOPT's linear solvers: built into CasADi's IPOPT, or loaded at run time from a library
#: (IPOPT option naming the library, default file name).
BUILTIN_LINEAR_SOLVERS = ("mumps", "spral")
RUNTIME_LINEAR_SOLVERS = {
    "ma27": ("hsllib", "libhsl.so"),
    "ma57": ("hsllib", "libhsl.so"),
    "ma77": ("hsllib", "libhsl.so"),
    "ma86": ("hsllib", "libhsl.so"),
    "ma97": ("hsllib", "libhsl.so"),
    "pardiso": ("pardisolib", "libpardiso.so"),
}


#: Environment variable naming the library of a run-time linear solver, for runs whose options
#: come from a study file (which may name a solver but not a library).
LIBRARY_ENV = "MUSCLEMETAB_LINEAR_SOLVER_LIBRARY"
#: Symbols the library of each run-time solver must export (IPOPT's HSL and Pardiso loaders
#: look them up); Fortran names with or without the trailing underscore.
LINEAR_SOLVER_SYMBOLS = {
    "ma27": ("ma27ad_", "ma27bd_", "ma27cd_"),
    "ma57": ("ma57ad_", "ma57bd_", "ma57cd_"),
    "ma77": ("ma77_open_d", "ma77_factor_d", "ma77_solve_d"),
    "ma86": ("ma86_analyse_d", "ma86_factor_d", "ma86_solve_d"),
    "ma97": ("ma97_analyse_d", "ma97_factor_d", "ma97_solve_d"),
    "pardiso": ("pardisoinit", "pardiso"),
}
#: Folders searched for a library given by file name only (after ``LD_LIBRARY_PATH``)
LIBRARY_FOLDERS = ("/usr/local/lib", "/usr/lib/x86_64-linux-gnu", "/usr/lib64", "/usr/lib", "/lib/x86_64-linux-gnu",
                   "/lib64", "/lib")


def linear_solver_library(name: str, library: str | None = None) -> str | None:
    """The library IPOPT loads the run-time solver ``name`` from: ``library`` (the command
    line), else the environment variable :data:`LIBRARY_ENV`, else the default file name of its
    family (``libhsl.so``, ``libpardiso.so``); ``None`` for the built-in solvers."""
    if name not in RUNTIME_LINEAR_SOLVERS:
        return None
    return library or os.environ.get(LIBRARY_ENV) or RUNTIME_LINEAR_SOLVERS[name][1]


def exported_symbols(path) -> set[str]:
    """Names of the functions and data a shared library (ELF) exports, read from its dynamic
    symbol table (``.dynsym``) without loading it; :class:`ValueError` when the file is not
    an ELF shared library."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"\x7fELF" or data[4] not in (1, 2) or data[5] not in (1, 2):
        raise ValueError("not an ELF file")
    is64, end = data[4] == 2, "<" if data[5] == 1 else ">"
    if struct.unpack_from(end + "H", data, 16)[0] != 3:  # e_type ET_DYN
        raise ValueError("not a shared library")
    if is64:
        shoff, = struct.unpack_from(end + "Q", data, 0x28)
        shentsize, shnum = struct.unpack_from(end + "HH", data, 0x3A)
        sh_fmt, sym_fmt = end + "IIQQQQIIQQ", end + "IBBHQQ"
    else:
        shoff, = struct.unpack_from(end + "I", data, 0x20)
        shentsize, shnum = struct.unpack_from(end + "HH", data, 0x2E)
        sh_fmt, sym_fmt = end + "IIIIIIIIII", end + "IIIBBH"
    sections = [struct.unpack_from(sh_fmt, data, shoff + i * shentsize) for i in range(shnum)]
    names = set()
    for sec in sections:
        if sec[1] != 11:  # SHT_DYNSYM
            continue
        offset, size, link, entsize = sec[4], sec[5], sec[6], sec[9]
        strtab = sections[link][4]
        for k in range(size // entsize if entsize else 0):
            fields = struct.unpack_from(sym_fmt, data, offset + k * entsize)
            st_name, info, shndx = (fields[0], fields[1], fields[3]) if is64 else (fields[0], fields[3], fields[5])
            if shndx == 0 or (info >> 4) not in (1, 2):  # undefined, or not global/weak
                continue
            stop = data.index(b"\0", strtab + st_name)
            names.add(data[strtab + st_name:stop].decode("utf-8", "replace"))
    return names


def _find_library(lib: str) -> str | None:
    """``lib`` when it is a path; a file name looked up in ``LD_LIBRARY_PATH`` and :data:`LIBRARY_FOLDERS`."""
    if os.sep in lib:
        return lib if os.path.isfile(lib) else None
    folders = [d for d in os.environ.get("LD_LIBRARY_PATH", "").split(os.pathsep) if d] + list(LIBRARY_FOLDERS)
    return next((os.path.join(d, lib) for d in folders if os.path.isfile(os.path.join(d, lib))), None)


def check_linear_solver(name: str, library: str | None = None) -> None:
    """Raise :class:`OptionError` unless IPOPT can use the linear solver ``name``.

    For the solvers IPOPT loads at run time, the library (:func:`linear_solver_library`) is
    found, its dynamic symbol table read (:func:`exported_symbols`) and, only when it exports
    the solver's functions (:data:`LINEAR_SOLVER_SYMBOLS`), loaded here: a missing or foreign
    library is reported before the problem is built, and no code of a library that is not
    the solver's runs.
    """
    if name in BUILTIN_LINEAR_SOLVERS:
        if library is not None:
            raise OptionError(f"linear solver {name} is built into IPOPT; drop the linear-solver library {library!r}")
        return
    if name not in RUNTIME_LINEAR_SOLVERS:
        raise OptionError(
            f"linear solver {name!r} is unknown; choose one of "
            f"{', '.join(BUILTIN_LINEAR_SOLVERS + tuple(RUNTIME_LINEAR_SOLVERS))}"
        )
    option, _ = RUNTIME_LINEAR_SOLVERS[name]
    lib = linear_solver_library(name, library)
    what = "the HSL library (www.hsl.rl.ac.uk/ipopt)" if option == "hsllib" else "the Pardiso library"
    remedy = (f"install {what} and give its path as the linear-solver library (--linear-solver-library, or the "
              f"environment variable {LIBRARY_ENV}), or use mumps or spral")
    path = _find_library(lib)
    if path is None:
        raise OptionError(f"linear solver {name}: IPOPT loads it from {lib}, which cannot be loaded (no such file"
                          f"{'' if os.sep in lib else ' on the library search path'}); {remedy}")
    try:
        symbols = exported_symbols(path)
    except (OSError, ValueError, IndexError, struct.error) as exc:
        raise OptionError(f"linear solver {name}: IPOPT loads it from {lib}, which cannot be loaded (not a readable "
                          f"shared library: {exc}); {remedy}") from None
    missing = [s for s in LINEAR_SOLVER_SYMBOLS[name] if not {s, s.rstrip("_"), s + "_"} & symbols]
    if missing:
        raise OptionError(f"linear solver {name}: {lib} does not export {', '.join(missing)}, so it is not {what} "
                          f"and was not loaded; {remedy}")
    try:
        ctypes.CDLL(path)
    except OSError as exc:
        raise OptionError(f"linear solver {name}: IPOPT loads it from {lib}, which cannot be loaded ({exc}); "
                          f"{remedy}") from None


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


def problem_size(n_muscles: int, n_dofs: int, n_intervals: int) -> tuple[int, int]:
    """Number of variables and equality constraints (``205 N + 120`` and ``165 N + 40`` for 40/5)."""
    M, D, N = n_muscles, n_dofs, n_intervals
    return (5 * M + D) * N + 3 * M, (4 * M + D) * N + M


#: Memory of a problem, measured on the example trial (40 muscles, 5 DOFs): 73 MB, plus 0.47 MB
#: per mesh interval (the peak resident memory of ``musclemetab solve`` was 202 MB with N = 118
#: and 312 MB with N = 354), scaled by the variables per interval for other sizes.
PROBLEM_BASE_MB = 73.0
PROBLEM_MB_PER_INTERVAL = 0.47
#: Largest problem built (estimated memory, MB): beyond it the mesh is refused before building
#: (e.g. a 30 s trial at 1000 intervals per second would need about 14 GB)
MAX_PROBLEM_MEMORY_MB = 8000.0


def problem_memory_mb(sizes) -> float:
    """Estimated memory (MB) of a problem over trials of ``sizes`` = ``[(muscles, DOFs, intervals), ...]``."""
    per_interval = sum(n * (5 * m + d) / 205.0 for m, d, n in sizes)
    return PROBLEM_BASE_MB + PROBLEM_MB_PER_INTERVAL * per_interval


def check_problem_memory(sizes) -> None:
    """Raise :class:`OptionError` when the problem of ``sizes`` (see :func:`problem_memory_mb`)
    would need more than :data:`MAX_PROBLEM_MEMORY_MB`, naming the estimate and the remedy."""
    mb = problem_memory_mb(sizes)
    if mb > MAX_PROBLEM_MEMORY_MB:
        n = sum(s[2] for s in sizes)
        raise OptionError(f"the problem would have {n} mesh intervals and need about {mb:.0f} MB of memory, more "
                          f"than the limit of {MAX_PROBLEM_MEMORY_MB:.0f} MB; solve a shorter window (--window, "
                          "--cycle) or a coarser mesh (--mesh-frequency, the study's is 100 per second)")


_MALLOC_TUNED = False


def tune_malloc(threshold_bytes: int = 512 * 1024 * 1024) -> bool:
    """Raise glibc's mmap/trim thresholds so freed work arrays are reused, not unmapped.

    Equivalent to ``MALLOC_MMAP_THRESHOLD_``/``MALLOC_TRIM_THRESHOLD_``/``MALLOC_TOP_PAD_``
    in the environment, set at run time with ``mallopt``. Returns ``False`` (and does
    nothing) where glibc is not available.
    """
    global _MALLOC_TUNED
    if _MALLOC_TUNED:
        return True
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD = -1, -2, -3
    ok = bool(mallopt(M_MMAP_THRESHOLD, min(threshold_bytes, 2**31 - 1)))
    ok &= bool(mallopt(M_TRIM_THRESHOLD, min(2 * threshold_bytes, 2**31 - 1)))
    ok &= bool(mallopt(M_TOP_PAD, 64 * 1024 * 1024))
    _MALLOC_TUNED = ok
    return ok


def set_blas_threads(n: int) -> bool:
    """Set the thread count of CasADi's bundled OpenBLAS (used by MUMPS).

    Acts on the library instance already loaded by the IPOPT plugin (found by its soname);
    returns ``False`` when it is not loaded or has no such function.
    """
    import os

    try:
        lib = ctypes.CDLL("libcasadi-tp-openblas.so.0", mode=getattr(os, "RTLD_NOLOAD", 4) | os.RTLD_LOCAL)
        lib.openblas_set_num_threads(int(n))
    except (OSError, AttributeError):
        return False
    return True


def build_nlp(
    inputs: TrialInputs,
    params: MuscleTendonParameters,
    guess: InitialGuess,
    options: SolverOptions | None = None,
    goals: Goals | None = None,
) -> dict:
    """The NLP of the single-trial problem, without solving it: the problem core
    (:func:`.transcription.build_problem`) with one trial and the effort goal of ``goals``
    (default ``Goals()``)."""
    options = options or SolverOptions()
    return build_problem([TrialBlock("trial", inputs, guess)], params, effort_goals(goals, options),
                         optimal_reserve_Nm=options.optimal_reserve_Nm,
                         explicit_derivatives=options.derivatives == "explicit")


def effort_goals(goals: Goals | None, options: SolverOptions) -> Goals:
    """The goals of a single-trial solve: the effort weights (activation, excitation, reserves,
    fiber velocity) of ``goals`` (default ``Goals()``), the energy goal of ``options`` if it has
    one and its fiber dynamics."""
    weights = (goals or Goals()).effort_weights()
    return Goals(**weights, energy=options.energy, fiber_dynamics=options.fiber_dynamics)


def solver_record(options: SolverOptions, goals: Goals | None = None) -> dict:
    """The ``solver_options`` record of a solve: the effort weights of ``goals`` (default
    ``Goals()``) under ``w_activation``, ``w_reserve``, ``w_velocity``, then the numerical
    settings of ``options``."""
    return {**(goals or Goals()).effort_weights(), **options.to_dict()}


#: IPOPT linear-algebra settings used with MUMPS (``SolverOptions.ipopt`` overrides them): no
#: iterative refinement of a linear solve whose residual already meets IPOPT's accuracy test
#: (IPOPT's default is at least one step), and MUMPS' pivot tolerance from 1e-4 instead of
#: 1e-6, which spares the factorisations IPOPT repeats with a raised tolerance when a solve is
#: not accurate enough (docs/solver.md, "Inertia corrections"). On the example trials the
#: iterations and optimum are the same; they change the round-off of the KKT solves, not the
#: problem.
MUMPS_OPTIONS = {"min_refinement_steps": 0, "mumps_pivtol": 1e-4}


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


#: Seconds between two progress lines of a running solve (:func:`solve_progress`).
PROGRESS_INTERVAL_S = 5.0
_PROGRESS: dict = {"stream": None, "interval_s": None, "label": ""}


class solve_progress:
    """While this context is active, every IPOPT solve of this process writes a progress line
    at most every ``interval_s`` seconds (default :data:`PROGRESS_INTERVAL_S`) to ``stream``
    (default: a record of level INFO of the logger ``musclemetab.progress``, which the command
    line prints on standard error unless ``-q``)::

        musclemetab: solving: iteration 40, objective 2.7012e-01, constraint violation 3.1e-05, 21 s

    The line comes from IPOPT's iteration callback (CasADi's ``iteration_callback`` option):
    the iteration number, the objective and the largest violation of a constraint's bounds
    (unscaled, at the current iterate) and the time since the solve started. It does not change
    the solve: the callback only reads the iterate. ``musclemetab solve`` and ``estimate`` use it
    unless given ``--no-progress``; the legs of ``solve --side both --workers 2``, solved in other
    processes, turn it on there with the interval of this process (:func:`progress_interval`)
    and ``label`` naming the leg (``musclemetab: solving side l: iteration 40, ...``).
    """

    def __init__(self, interval_s: float | None = None, stream=None, label: str = ""):
        self.interval_s, self.stream, self.label = interval_s, stream, label
        self._previous = None

    def __enter__(self):
        self._previous = dict(_PROGRESS)
        _PROGRESS.update(stream=self.stream, interval_s=PROGRESS_INTERVAL_S if self.interval_s is None
                         else float(self.interval_s), label=self.label)
        return self

    def __exit__(self, *exc):
        _PROGRESS.clear()
        _PROGRESS.update(self._previous)
        return False


def progress_interval() -> float | None:
    """The interval (s) of the progress lines :func:`solve_progress` turned on in this process,
    or ``None`` when they are off."""
    return _PROGRESS.get("interval_s")


class ProgressLines:
    """Writes the progress lines of :func:`solve_progress` for one solve: :meth:`iteration` is
    called with each iterate; a line is written when ``interval_s`` has passed since the start
    or the last line (``clock``: seconds, default :func:`time.perf_counter`); ``label`` follows
    ``solving`` (e.g. `` side r``)."""

    def __init__(self, lbg, ubg, interval_s: float, stream=None, clock=None, label: str = ""):
        self.lbg, self.ubg = np.asarray(lbg, dtype=float).reshape(-1), np.asarray(ubg, dtype=float).reshape(-1)
        self.interval_s = float(interval_s)
        self.stream = stream  # None: the package's logger ``musclemetab.progress``, level INFO
        self.clock = clock or _time.perf_counter
        self.t0 = self.last = self.clock()
        self.count = 0
        self.lines = 0
        self.label = label

    def iteration(self, f, g) -> None:
        """One IPOPT iterate: objective ``f`` and constraint values ``g``."""
        self.count += 1
        now = self.clock()
        if now - self.last < self.interval_s:
            return
        self.last = now
        g = np.asarray(g, dtype=float).reshape(-1)
        viol = float(np.max(np.maximum(self.lbg - g, 0.0) + np.maximum(g - self.ubg, 0.0))) if g.size else 0.0
        # IPOPT calls back once for the starting point (iteration 0); a stream that cannot be
        # written (closed, full) loses the line, never the solve
        text = (f"solving{self.label}: iteration {self.count - 1}, objective {float(f):.4e}, "
                f"constraint violation {viol:.1e}, {now - self.t0:.0f} s")
        if self.stream is None:
            from ..messages import logger

            logger("progress").info(text)
            self.lines += 1
            return
        from ..messages import write_quietly

        self.lines += write_quietly(self.stream, f"musclemetab: {text}\n")


def _progress_callback(n_x: int, n_g: int, lbg, ubg):
    """The CasADi ``iteration_callback`` of :func:`solve_progress`, or ``None`` when it is off."""
    if _PROGRESS.get("interval_s") is None:
        return None
    import casadi as ca

    lines = ProgressLines(lbg, ubg, _PROGRESS["interval_s"], _PROGRESS.get("stream"), label=_PROGRESS.get("label", ""))

    class _Callback(ca.Callback):
        def __init__(self):
            ca.Callback.__init__(self)
            self.construct("musclemetab_progress", {})

        def get_n_in(self):
            return ca.nlpsol_n_out()

        def get_n_out(self):
            return 1

        def get_name_in(self, i):
            return ca.nlpsol_out(i)

        def get_name_out(self, i):
            return "ret"

        def get_sparsity_in(self, i):
            n = ca.nlpsol_out(i)
            size = {"f": 1, "x": n_x, "lam_x": n_x, "g": n_g, "lam_g": n_g}.get(n, 0)
            return ca.Sparsity.dense(size, 1)

        def eval(self, arg):
            names = [ca.nlpsol_out(i) for i in range(ca.nlpsol_n_out())]
            values = dict(zip(names, arg))
            lines.iteration(float(values["f"]), np.asarray(values["g"]).reshape(-1))
            return [0]

    return _Callback()


def run_ipopt(solver, options: SolverOptions, x0, lbx, ubx, lbg, ubg, multipliers: dict | None = None, p=None):
    """Apply the process settings of ``options`` (``tune_malloc``, ``blas_threads``) and run
    an IPOPT ``nlpsol`` (with the NLP parameter's values ``p``, if it has one); returns ``(x, g,
    f, stats, wall time s, CPU time s)``. A dict ``multipliers`` receives the optimum's
    ``lam_g`` and ``lam_x`` (CasADi's signs: ``grad f + J' lam_g + lam_x = 0``)."""
    if options.tune_malloc:
        tune_malloc()
    if options.blas_threads is not None:
        set_blas_threads(options.blas_threads)
    t0 = _time.perf_counter()
    c0 = _time.process_time()
    try:
        with sigint_noted():  # Ctrl-C stops IPOPT with a failure status: raised as an interrupt
            sol = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, **({} if p is None else {"p": p}))
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


def _trial_terms(goals: Goals, t: TrialBlock, Z, xl, dev, lm_us, params=None, lmo_factor=None) -> dict:
    """The objective terms of one trial at the optimum (NumPy, the formulas of :mod:`.transcription`)."""
    M, D, N = len(t.inputs.muscles), len(t.inputs.dofs), t.inputs.n_intervals
    a = np.concatenate([Z[:, 0:M].ravel(), xl[0:M]])
    terms = {
        "activation": goals.w_activation * 0.5 * float(np.sum(a**2)) / (N * M),
        "excitation": goals.w_activation * 0.5 * float(np.sum(Z[:, 3 * M:4 * M] ** 2)) / (N * M),
        "reserve": goals.w_reserve * float(np.sum(Z[:, 4 * M:4 * M + D] ** 2)) / (N * D),
        "fiber_velocity": goals.w_velocity * float(np.sum(Z[:, 4 * M + D:] ** 2)) / (N * M),
    }
    if t.emg_muscles:
        terms = {"emg_tracking": goals.w_emg * float(np.sum(dev**2)) / (len(t.emg_muscles) * N), **terms}
    if t.fiber_muscles:
        terms["fiber_length_tracking"] = goals.w_fiber_length * float(np.sum(lm_us**2)) / (len(t.fiber_muscles) * N)
    if goals.energy is not None:
        from .energy import leg_rate_W_per_kg

        rate = leg_rate_W_per_kg(goals.energy, params, t.inputs.muscles, Z[:, 3 * M:4 * M], Z[:, 0:M],
                                 Z[:, M:2 * M], Z[:, 4 * M + D:], lmo_factor)
        terms["energy"] = goals.energy.weight * float(np.mean(rate))
    return terms


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


@functools.lru_cache(maxsize=1)
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
    ipopt = ipopt_options(options, MUMPS_OPTIONS if mumps_settings is None else mumps_settings)
    callback = _progress_callback(int(nlp["x"].numel()), int(nlp["g"].numel()), nlp["lbg"], nlp["ubg"])
    solver = nlp_solver(nlp, ipopt, callback)
    build_time = _time.perf_counter() - t_build
    kkt = {}
    x, gval, f_opt, stats, solve_time, solve_cpu = run_ipopt(
        solver, options, nlp["x0"], nlp["lbx"], nlp["ubx"], nlp["lbg"], nlp["ubg"], kkt, p=nlp["p_values"])
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
                   final_barrier_parameter=_final_barrier_parameter(stats))
    from ..messages import logger

    logger("redundancy").debug("IPOPT: %s in %d iterations, %d variables, build %.2f s, solve %.2f s, largest "
                               "constraint violation %.1e", outcome["status"], outcome["iterations"],
                               outcome["n_variables"], build_time, solve_time, max_viol)
    ocps, devs = [], []
    lmo = dict(zip(params.names, params.optimal_fiber_length_m))
    for i, t in enumerate(trials):
        d, o = L["trials"][i], L["var_off"][i]
        M, D, N, nz = d["M"], d["D"], d["N"], d["nz"]
        Z = x[o:o + nz * N].reshape(N, nz)
        xl = x[o + nz * N:o + nz * N + 3 * M]
        pos = {m: k for k, m in enumerate(t.inputs.muscles)}
        ie = [pos[m] for m in t.emg_muscles]
        dev = np.zeros((N, 0))
        if ie:
            dev = Z[:, 3 * M:4 * M][:, ie] - np.array([factors["emg_scale"][m] for m in t.emg_muscles]) * t.emg_nodes
        iu = [pos[m] for m in t.fiber_muscles]
        lm_us = np.zeros((N, 0))
        if iu:
            s_lmo = np.array([factors.get("optimal_fiber_length", {}).get(m, 1.0) for m in t.fiber_muscles])
            l0 = np.array([lmo[m] for m in t.fiber_muscles])
            lm_us = (Z[:, M:2 * M][:, iu] * s_lmo * l0 - t.fiber_length_nodes_m) / l0
        s_all = factors.get("optimal_fiber_length", {})
        terms = _trial_terms(goals, t, Z, xl, dev, lm_us, params,
                             np.array([s_all.get(m, 1.0) for m in t.inputs.muscles]))
        ocps.append(OcpResult(
            activation=np.vstack([Z[:, 0:M], xl[0:M]]), lm_norm=np.vstack([Z[:, M:2 * M], xl[M:2 * M]]),
            lm_projected_m=np.vstack([Z[:, 2 * M:3 * M], xl[2 * M:]]), excitation=Z[:, 3 * M:4 * M].copy(),
            reserve=Z[:, 4 * M:4 * M + D].copy(), fiber_velocity_lmo_per_s=Z[:, 4 * M + D:].copy(),
            objective=f_opt if len(trials) == 1 else float(sum(terms.values())), objective_terms=terms,
            n_constraints=nlp["n_equality_constraints"], **outcome))
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
    """Build and solve the single-trial problem with the effort goal of ``goals`` (default
    ``Goals()``) and the energy goal of ``options``; never
    raises on non-convergence (``status`` is IPOPT's return status, ``success`` whether IPOPT
    reported success). Errors while building the problem raise :class:`SolverError`."""
    options = options or SolverOptions()
    res = solve_problem([TrialBlock("trial", inputs, guess)], params, effort_goals(goals, options), options=options)
    return res.trials[0]
