"""The muscle redundancy optimal control problem (De Groote et al. 2016), CasADi + IPOPT.

Variables (``M`` muscles, ``D`` DOFs, ``N`` mesh intervals, ``h = (tf - t0)/N``):

========================  ==========  ===================
variable                  size        bounds
========================  ==========  ===================
activation ``a``          M x (N+1)   0 ... 1
fibre length ``l~M``      M x (N+1)   0.1 ... 1.7
projected length ``lp``   M x (N+1)   >= 1e-4 m
excitation ``e``          M x N       0 ... 1
reserve ``aT``            D x N       -1 ... 1 (x Topt = 150 N m)
fibre velocity ``v~M``    M x N       -10 ... 10 lMo/s
========================  ==========  ===================

Constraints at nodes ``k = 0 ... N-1`` (forward Euler)::

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
import time as _time
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import OptionError, SolverError
from ..muscle import activation_rate, hill_residual, tendon_force_length
from .inputs import TrialInputs
from .parameters import MuscleTendonParameters
from .static_opt import InitialGuess

__all__ = [
    "SolverOptions",
    "OcpResult",
    "solve_ocp",
    "build_nlp",
    "problem_size",
    "failure_advice",
    "INFEASIBLE_STATUSES",
    "tune_malloc",
    "set_blas_threads",
]

ACTIVATION_BOUNDS = (0.0, 1.0)
FIBRE_LENGTH_BOUNDS = (0.1, 1.7)
FIBRE_VELOCITY_BOUNDS = (-10.0, 10.0)
RESERVE_BOUNDS = (-1.0, 1.0)
MIN_PROJECTED_LENGTH_M = 1e-4


@dataclass(frozen=True)
class SolverOptions:
    """Weights and numerical settings of the optimal control problem.

    The defaults reproduce the study: weights ``[wAct, wTres, wVm] = [1, 1000, 0.01]``,
    ``Topt = 150 N m``, IPOPT with exact Hessian, MUMPS, gradient-based NLP scaling,
    ``tol = 1e-6``, ``max_iter = 10000`` and IPOPT's default monotone barrier strategy with
    ``mu_init = 0.1`` (the problem has several local optima; other barrier settings can end
    in a different one).

    ``derivatives="explicit"`` (default) gives IPOPT the constraint Jacobian and the Hessian
    of the Lagrangian assembled from per-interval symbolic derivatives (the Jacobian is block
    banded, the Hessian block diagonal); ``"auto"`` lets CasADi differentiate the whole mapped
    expression graph. Both compute the same derivatives; the explicit form builds and
    evaluates faster. ``node_function`` chooses the symbolic type of the per-interval
    constraint function used for the constraint values: ``"MX"`` (default) or ``"SX"``.

    ``linear_solver`` is IPOPT's solver of the KKT systems: ``"mumps"`` (default) and
    ``"spral"`` are part of CasADi's IPOPT; ``"ma27"``, ``"ma57"``, ``"ma77"``, ``"ma86"``,
    ``"ma97"`` (HSL) and ``"pardiso"`` (pardiso-project.org) are loaded by IPOPT at run time
    from ``linear_solver_library`` (default ``libhsl.so`` / ``libpardiso.so`` on the library
    search path); the library is loaded when the options are made, so a missing one is
    reported before any problem is built. Another solver can end in another local optimum.

    ``tune_malloc`` raises glibc's ``malloc`` thresholds for the process before solving
    (MUMPS reallocates its work arrays every iteration). ``blas_threads`` sets the number of
    threads of the BLAS used by MUMPS (CasADi's OpenBLAS); the dense blocks here are small, so
    one thread is fastest and leaves the other cores to other solves (``None`` leaves the
    library default). ``ipopt`` holds further IPOPT options, e.g. ``{"mu_init": 1e-6}`` for a
    warm start; anything there may change which optimum is found.
    """

    w_activation: float = 1.0
    w_reserve: float = 1000.0
    w_velocity: float = 0.01
    optimal_reserve_Nm: float = 150.0
    tol: float = 1e-6
    max_iter: int = 10000
    linear_solver: str = "mumps"
    linear_solver_library: str | None = None
    print_level: int = 0
    node_function: str = "MX"
    derivatives: str = "explicit"
    tune_malloc: bool = True
    blas_threads: int | None = 1
    ipopt: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.derivatives not in ("explicit", "auto"):
            raise OptionError(f"derivatives must be 'explicit' or 'auto', not {self.derivatives!r}")
        if self.node_function not in ("MX", "SX"):
            raise OptionError(f"node_function must be 'MX' or 'SX', not {self.node_function!r}")
        for name in ("w_activation", "w_reserve", "w_velocity"):
            if getattr(self, name) < 0:
                raise OptionError(f"the weight {name} must be non-negative, not {getattr(self, name)}")
        if self.optimal_reserve_Nm <= 0:
            raise OptionError(f"optimal_reserve_Nm must be positive, not {self.optimal_reserve_Nm}")
        if self.max_iter < 1:
            raise OptionError(f"max_iter must be at least 1, not {self.max_iter}")
        check_linear_solver(self.linear_solver, self.linear_solver_library)

    def with_(self, **kw) -> "SolverOptions":
        return replace(self, **kw)

    def to_dict(self) -> dict:
        return {
            "w_activation": self.w_activation,
            "w_reserve": self.w_reserve,
            "w_velocity": self.w_velocity,
            "optimal_reserve_Nm": self.optimal_reserve_Nm,
            "tol": self.tol,
            "max_iter": self.max_iter,
            "linear_solver": self.linear_solver,
            "linear_solver_library": self.linear_solver_library,
            "node_function": self.node_function,
            "derivatives": self.derivatives,
            "tune_malloc": self.tune_malloc,
            "blas_threads": self.blas_threads,
            "ipopt": dict(self.ipopt),
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


def check_linear_solver(name: str, library: str | None = None) -> None:
    """Raise :class:`OptionError` unless IPOPT can use the linear solver ``name``.

    For the solvers IPOPT loads at run time, the library (``library`` or the default name on
    the search path) is loaded here, so that a missing one is reported before the problem
    is built.
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
    option, default = RUNTIME_LINEAR_SOLVERS[name]
    lib = library or default
    try:
        ctypes.CDLL(lib)
    except OSError as exc:
        what = "the HSL library (www.hsl.rl.ac.uk/ipopt)" if option == "hsllib" else "the Pardiso library"
        raise OptionError(
            f"linear solver {name}: IPOPT loads it from {lib}, which cannot be loaded ({exc}); install {what} "
            f"and give its path as the linear-solver library (--linear-solver-library), or use mumps or spral"
        ) from None


@dataclass(frozen=True)
class OcpResult:
    """Raw optimum: states ``(N+1, M)``, controls ``(N, M)`` / ``(N, D)``, IPOPT statistics."""

    activation: np.ndarray
    lm_norm: np.ndarray
    lm_projected_m: np.ndarray
    excitation: np.ndarray
    reserve: np.ndarray
    vm_norm: np.ndarray
    objective: float
    objective_terms: dict
    status: str
    success: bool
    iterations: int
    solve_time_s: float
    solve_cpu_s: float
    build_time_s: float
    n_variables: int
    n_constraints: int
    max_constraint_violation: float
    function_time_s: dict = field(default_factory=dict)


def ipopt_statistics(result) -> dict:
    """Status, objective and IPOPT statistics of an optimum (:class:`OcpResult` or the
    EMG-TEN result), as recorded in ``summary.json``."""
    return {
        "status": result.status,
        "success": result.success,
        "objective": result.objective,
        "objective_terms": result.objective_terms,
        "iterations": result.iterations,
        "solve_time_s": result.solve_time_s,
        "solve_cpu_time_s": result.solve_cpu_s,
        "build_time_s": result.build_time_s,
        "function_evaluation_time_s": result.function_time_s,
        "ms_per_iteration": 1e3 * result.solve_time_s / max(result.iterations, 1),
        "max_constraint_violation": result.max_constraint_violation,
    }


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
    if status in ("User_Requested_Stop", "NonIpopt_Exception_Thrown"):
        return "the solve was stopped (interrupt or an error in a callback); run it again"
    return "check the inputs (units, time ranges, parameters)"


def problem_size(n_muscles: int, n_dofs: int, n_intervals: int) -> tuple[int, int]:
    """Number of variables and equality constraints (``205 N + 120`` and ``165 N + 40`` for 40/5)."""
    M, D, N = n_muscles, n_dofs, n_intervals
    return (5 * M + D) * N + 3 * M, (4 * M + D) * N + M


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


def _constants(params: MuscleTendonParameters, ca):
    P = {k: ca.DM(np.asarray(v, dtype=float)) for k, v in dict(
        lmo=params.optimal_fiber_length_m,
        lts=params.tendon_slack_length_m,
        vmax=params.max_contraction_velocity,
        kT=params.tendon_stiffness,
        kpe=params.passive_kpe,
        s0=params.passive_s0,
        sm=params.passive_sm,
        f0=params.max_isometric_force_N,
    ).items()}
    P["w2"] = ca.DM(np.asarray(params.width_m, dtype=float) ** 2)
    return P


def _node_expressions(sym, M: int, D: int, h: float, P: dict, optimal_reserve_Nm: float, ca):
    """Symbols and constraint expressions of one mesh interval (see module docstring)."""
    a, lm, lp = sym("a", M), sym("lm", M), sym("lp", M)
    e, aT, vm = sym("e", M), sym("aT", D), sym("vm", M)
    a1, lm1 = sym("a1", M), sym("lm1", M)
    lmt, rflat, mom = sym("lmt", M), sym("r", D * M), sym("id", D)
    penn = (lm * P["lmo"]) ** 2 - P["w2"] - lp**2
    dyn_a = a1 - a - h * activation_rate(e, a)
    dyn_lm = lm1 - lm - h * vm
    hill = hill_residual(
        a, lm, vm, lp, lmt,
        optimal_fiber_length_m=P["lmo"], tendon_slack_length_m=P["lts"],
        max_contraction_velocity=P["vmax"], kT=P["kT"], kpe=P["kpe"], s0=P["s0"], sm=P["sm"],
    )
    ft = tendon_force_length((lmt - lp) / P["lts"], P["kT"])
    R = ca.reshape(rflat, D, M)
    moment = mom - ca.mtimes(R, P["f0"] * ft) - optimal_reserve_Nm * aT
    syms = dict(a=a, lm=lm, lp=lp, e=e, aT=aT, vm=vm, a1=a1, lm1=lm1, lmt=lmt, r=rflat, id=mom)
    return syms, ca.vertcat(dyn_a, dyn_lm, penn, hill, moment), penn


def _node_functions(inputs: TrialInputs, params: MuscleTendonParameters, options: SolverOptions, ca):
    M, D = len(inputs.muscles), len(inputs.dofs)
    sym = ca.MX.sym if options.node_function == "MX" else ca.SX.sym
    P = _constants(params, ca)
    S, g, penn = _node_expressions(sym, M, D, inputs.step_s, P, options.optimal_reserve_Nm, ca)
    order = ("a", "lm", "lp", "e", "aT", "vm", "a1", "lm1", "lmt", "r", "id")
    node = ca.Function("node", [S[k] for k in order], [g])
    last = ca.Function("last", [S["lm"], S["lp"]], [penn])
    return node, last


def _explicit_derivatives(inputs, params, options, ca, w, g, weights, data):
    """Gradient, constraint Jacobian and (upper-triangular) Lagrangian Hessian, assembled.

    Each mesh interval's constraints depend on its own node block ``z_k`` and linearly on the
    next node's ``a, l~M``; the objective is a separable quadratic. So the Jacobian is made of
    per-interval blocks and the Hessian of the Lagrangian is block diagonal. Per-interval
    derivatives are computed once symbolically (SX), mapped over the mesh and their nonzeros
    placed into the global sparse matrices: cheaper to build and to evaluate than
    differentiating the whole mapped expression graph, and exactly the same numbers.
    """
    M, D, N = len(inputs.muscles), len(inputs.dofs), inputs.n_intervals
    nz = 5 * M + D
    P = _constants(params, ca)
    S, gk, penn = _node_expressions(ca.SX.sym, M, D, inputs.step_s, P, options.optimal_reserve_Nm, ca)
    z = ca.vertcat(S["a"], S["lm"], S["lp"], S["e"], S["aT"], S["vm"])
    xn = ca.vertcat(S["a1"], S["lm1"])
    d = ca.vertcat(S["lmt"], S["r"], S["id"])
    lam = ca.SX.sym("lam", gk.shape[0])
    sigma = ca.SX.sym("sigma")
    cz = ca.DM(weights[:nz])
    jac_node = ca.Function("jac_node", [z, xn, d], [ca.jacobian(gk, ca.vertcat(z, xn))])
    lag = sigma * ca.dot(cz, z**2) + ca.dot(lam, gk)
    hess_node = ca.Function("hess_node", [z, d, lam, sigma], [ca.triu(ca.hessian(lag, z)[0])])
    xl = ca.vertcat(S["a"], S["lm"], S["lp"])
    laml = ca.SX.sym("laml", M)
    jac_last = ca.Function("jac_last", [xl], [ca.jacobian(penn, xl)])
    hess_last = ca.Function("hess_last", [xl, laml, sigma],
                            [ca.triu(ca.hessian(sigma * ca.dot(ca.DM(weights[nz * N:]), xl**2)
                                                + ca.dot(laml, penn), xl)[0])])

    Wm = ca.reshape(w[: nz * N], nz, N)
    xN = w[nz * N:]
    Xn = ca.horzcat(Wm[0:2 * M, 1:], xN[0:2 * M])
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", g.shape[0])
    ng = gk.shape[0]
    Lg = ca.reshape(lam_g[: ng * N], ng, N)

    def assemble(blocks_nz, block_sp, last_nz, last_sp, row_step, col_step, shape):
        rb, cb = (np.asarray(v, dtype=np.int64) for v in block_sp.get_triplet())
        rl, cl = (np.asarray(v, dtype=np.int64) for v in last_sp.get_triplet())
        k = np.repeat(np.arange(N), rb.size)
        rows = np.concatenate([np.tile(rb, N) + row_step * k, rl + row_step * N])
        cols = np.concatenate([np.tile(cb, N) + col_step * k, cl + col_step * N])
        perm = np.lexsort((rows, cols))
        sp = ca.Sparsity.triplet(shape[0], shape[1], rows[perm].tolist(), cols[perm].tolist())
        values = ca.vertcat(blocks_nz, last_nz)
        if not np.array_equal(perm, np.arange(perm.size)):
            values = values.nz[perm.tolist()]
        return ca.MX(sp, values)

    n_var, n_con = w.shape[0], g.shape[0]
    Jb = jac_node.map(N)(Wm, Xn, data)
    Jl = jac_last(xN)
    jac = assemble(Jb.nz[:], jac_node.sparsity_out(0), Jl.nz[:], jac_last.sparsity_out(0), ng, nz, (n_con, n_var))
    Hb = hess_node.map(N)(Wm, data, Lg, lam_f)
    Hl = hess_last(xN, lam_g[ng * N:], lam_f)
    hess = assemble(Hb.nz[:], hess_node.sparsity_out(0), Hl.nz[:], hess_last.sparsity_out(0), nz, nz, (n_var, n_var))
    cw = ca.DM(weights)
    p = ca.MX.sym("p", 0, 1)
    f = ca.dot(cw, w**2)
    return {
        "grad_f": ca.Function("nlp_grad_f", [w, p], [f, 2 * cw * w], ["x", "p"], ["f", "grad_f_x"]),
        "jac_g": ca.Function("nlp_jac_g", [w, p], [g, jac], ["x", "p"], ["g", "jac_g_x"]),
        "hess_lag": ca.Function("nlp_hess_l", [w, p, lam_f, lam_g], [hess],
                                ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"]),
    }


def node_bounds(M: int, D: int) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of one node's variables ``[a, l~M, lM cos(alpha), e, reserve, v~M]``."""
    lb = np.concatenate([
        np.full(M, ACTIVATION_BOUNDS[0]), np.full(M, FIBRE_LENGTH_BOUNDS[0]), np.full(M, MIN_PROJECTED_LENGTH_M),
        np.full(M, ACTIVATION_BOUNDS[0]), np.full(D, RESERVE_BOUNDS[0]), np.full(M, FIBRE_VELOCITY_BOUNDS[0]),
    ])
    ub = np.concatenate([
        np.full(M, ACTIVATION_BOUNDS[1]), np.full(M, FIBRE_LENGTH_BOUNDS[1]), np.full(M, np.inf),
        np.full(M, ACTIVATION_BOUNDS[1]), np.full(D, RESERVE_BOUNDS[1]), np.full(M, FIBRE_VELOCITY_BOUNDS[1]),
    ])
    return lb, ub


def build_nlp(
    inputs: TrialInputs,
    params: MuscleTendonParameters,
    guess: InitialGuess,
    options: SolverOptions | None = None,
) -> dict:
    """The NLP of the optimal control problem, without solving it.

    Returns a dict with the CasADi symbols and expressions ``x``, ``f``, ``g``, the objective
    ``terms``, the bounds and initial guess ``lbx``, ``ubx``, ``x0`` (node-major layout, see
    the module docstring), the sizes, and, for ``derivatives="explicit"``, the functions
    ``grad_f``, ``jac_g`` and ``hess_lag`` handed to IPOPT.
    """
    import casadi as ca

    options = options or SolverOptions()
    if tuple(params.names) != tuple(inputs.muscles):
        params = params.subset(inputs.muscles)
    M, D, N = len(inputs.muscles), len(inputs.dofs), inputs.n_intervals
    nx, nu = 3 * M, 2 * M + D
    nz = nx + nu
    n_var, n_con = problem_size(M, D, N)

    node, last = _node_functions(inputs, params, options, ca)
    w = ca.MX.sym("w", n_var)
    W = ca.reshape(w[: nz * N], nz, N)
    xN = w[nz * N:]
    A, LM, LP = W[0:M, :], W[M:2 * M, :], W[2 * M:3 * M, :]
    E, AT, VM = W[3 * M:4 * M, :], W[4 * M:4 * M + D, :], W[4 * M + D:, :]
    A1 = ca.horzcat(A[:, 1:], xN[0:M])
    LM1 = ca.horzcat(LM[:, 1:], xN[M:2 * M])
    lmt = ca.DM(inputs.lmt_m[:N].T)
    rr = ca.DM(inputs.moment_arms_m[:N].transpose(0, 2, 1).reshape(N, D * M).T)  # column-major D x M
    mom = ca.DM(inputs.moments_Nm[:N].T)
    data = ca.vertcat(lmt, rr, mom)
    G = node.map(N)(A, LM, LP, E, AT, VM, A1, LM1, lmt, rr, mom)
    g = ca.vertcat(ca.vec(G), last(xN[M:2 * M], xN[2 * M:3 * M]))

    a_all = ca.vertcat(ca.vec(A), xN[0:M])
    terms = {
        "activation": options.w_activation * 0.5 * ca.sumsqr(a_all) / (N * M),
        "excitation": options.w_activation * 0.5 * ca.sumsqr(E) / (N * M),
        "reserve": options.w_reserve * ca.sumsqr(AT) / (N * D),
        "fibre_velocity": options.w_velocity * ca.sumsqr(VM) / (N * M),
    }
    J = terms["activation"] + terms["excitation"] + terms["reserve"] + terms["fibre_velocity"]
    # the same objective as one weighted sum of squares: J = sum(c * w^2)
    c_node = np.concatenate([
        np.full(M, options.w_activation * 0.5 / (N * M)), np.zeros(2 * M),
        np.full(M, options.w_activation * 0.5 / (N * M)), np.full(D, options.w_reserve / (N * D)),
        np.full(M, options.w_velocity / (N * M)),
    ])
    weights = np.concatenate([np.tile(c_node, N), c_node[:M], np.zeros(2 * M)])

    # bounds and initial guess, node-major layout
    lb_node, ub_node = node_bounds(M, D)
    lbx = np.concatenate([np.tile(lb_node, N), lb_node[:nx]])
    ubx = np.concatenate([np.tile(ub_node, N), ub_node[:nx]])
    Z0 = np.vstack([
        guess.activation[:N].T, guess.lm_norm[:N].T, guess.lm_projected_m[:N].T,
        guess.excitation.T, guess.reserve.T, guess.vm_norm.T,
    ])
    x0 = np.concatenate([Z0.T.reshape(-1), guess.activation[N], guess.lm_norm[N], guess.lm_projected_m[N]])
    if x0.size != n_var or g.shape[0] != n_con:
        raise SolverError(f"internal error: problem size {x0.size}/{g.shape[0]}, expected {n_var}/{n_con}")
    if not np.all(np.isfinite(x0)):
        raise SolverError("the initial guess holds NaN or infinite values; check the muscle geometry and parameters")

    out = {"x": w, "f": J, "g": g, "terms": terms, "x0": x0, "lbx": lbx, "ubx": ubx,
           "n_variables": n_var, "n_constraints": n_con, "layout": (M, D, N, nz)}
    if options.derivatives == "explicit":
        out.update(_explicit_derivatives(inputs, params, options, ca, w, g, weights, data))
    return out


#: IPOPT linear-algebra settings used with MUMPS (``SolverOptions.ipopt`` overrides them): no
#: iterative refinement of a linear solve whose residual already meets IPOPT's accuracy test
#: (IPOPT's default is at least one step). On the example trials the iterations and optimum
#: are the same and the solve about 10 % faster. It changes the round-off of the KKT solves,
#: not the problem.
LINEAR_SOLVER_OPTIONS = {"min_refinement_steps": 0}


def ipopt_options(options: SolverOptions, mumps_settings: dict | None = None) -> dict:
    """IPOPT's options for a problem: tolerances, scaling, exact Hessian, the linear solver
    (with ``mumps_settings`` when it is MUMPS), then the user's ``options.ipopt``."""
    ipopt = {
        "tol": options.tol,
        "max_iter": int(options.max_iter),
        "nlp_scaling_method": "gradient-based",
        "linear_solver": options.linear_solver,
        "print_level": int(options.print_level),
        "hessian_approximation": "exact",
        "sb": "yes",  # no banner
    }
    if options.linear_solver in RUNTIME_LINEAR_SOLVERS:
        option, default = RUNTIME_LINEAR_SOLVERS[options.linear_solver]
        ipopt[option] = options.linear_solver_library or default
    if options.linear_solver == "mumps" and mumps_settings:
        ipopt.update(mumps_settings)
    ipopt.update(options.ipopt)
    return ipopt


def run_ipopt(solver, options: SolverOptions, x0, lbx, ubx, lbg, ubg):
    """Apply the process settings of ``options`` (``tune_malloc``, ``blas_threads``) and run
    an IPOPT ``nlpsol``; returns ``(x, g, f, stats, wall time s, CPU time s)``."""
    if options.tune_malloc:
        tune_malloc()
    if options.blas_threads is not None:
        set_blas_threads(options.blas_threads)
    t0 = _time.perf_counter()
    c0 = _time.process_time()
    try:
        sol = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    except RuntimeError as exc:
        raise SolverError(f"IPOPT stopped with an error: {exc}") from None
    return (np.asarray(sol["x"]).reshape(-1), np.asarray(sol["g"]).reshape(-1), float(sol["f"]), solver.stats(),
            _time.perf_counter() - t0, _time.process_time() - c0)


def solve_ocp(
    inputs: TrialInputs,
    params: MuscleTendonParameters,
    guess: InitialGuess,
    options: SolverOptions | None = None,
) -> OcpResult:
    """Build and solve the optimal control problem; never raises on non-convergence.

    The returned ``status`` is IPOPT's return status (``Solve_Succeeded`` on success) and
    ``success`` says whether IPOPT reported success. Errors while building the problem raise
    :class:`SolverError`.
    """
    import casadi as ca

    options = options or SolverOptions()
    if tuple(params.names) != tuple(inputs.muscles):
        params = params.subset(inputs.muscles)
    t_build = _time.perf_counter()
    nlp = build_nlp(inputs, params, guess, options)
    M, D, N, nz = nlp["layout"]
    n_var, n_con = nlp["n_variables"], nlp["n_constraints"]
    w, terms = nlp["x"], nlp["terms"]
    ipopt = ipopt_options(options, LINEAR_SOLVER_OPTIONS)
    nlp_options = {"ipopt": ipopt, "print_time": False, "error_on_fail": False}
    nlp_options.update({k: nlp[k] for k in ("grad_f", "jac_g", "hess_lag") if k in nlp})
    try:
        solver = ca.nlpsol("mrs", "ipopt", {"x": w, "f": nlp["f"], "g": nlp["g"]}, nlp_options)
    except RuntimeError as exc:
        raise SolverError(f"the optimal control problem could not be built: {exc}") from None
    terms_f = ca.Function("terms", [w], list(terms.values()))
    build_time = _time.perf_counter() - t_build

    x, gval, f_opt, stats, solve_time, solve_cpu = run_ipopt(solver, options, nlp["x0"], nlp["lbx"], nlp["ubx"], 0.0, 0.0)
    Z = x[: nz * N].reshape(N, nz)
    xNv = x[nz * N:]
    return OcpResult(
        activation=np.vstack([Z[:, 0:M], xNv[0:M]]),
        lm_norm=np.vstack([Z[:, M:2 * M], xNv[M:2 * M]]),
        lm_projected_m=np.vstack([Z[:, 2 * M:3 * M], xNv[2 * M:3 * M]]),
        excitation=Z[:, 3 * M:4 * M].copy(),
        reserve=Z[:, 4 * M:4 * M + D].copy(),
        vm_norm=Z[:, 4 * M + D:].copy(),
        objective=f_opt,
        objective_terms={k: float(v) for k, v in zip(terms, terms_f(x))},
        status=str(stats.get("return_status", "unknown")),
        success=bool(stats.get("success", False)),
        iterations=int(stats.get("iter_count", -1)),
        solve_time_s=solve_time,
        solve_cpu_s=solve_cpu,
        build_time_s=build_time,
        n_variables=n_var,
        n_constraints=n_con,
        max_constraint_violation=float(np.max(np.abs(gval))) if gval.size else 0.0,
        function_time_s={k[len("t_wall_"):]: float(v) for k, v in stats.items()
                         if k.startswith("t_wall_nlp") and v},
    )
