"""The problem core: one or several trials, goals and shared parameters in one NLP (``docs/problem.md``).

EFFORT-GEN/CAL/TEN are one trial with the effort goals; EMG-TEN is several trials with the EMG
goals and shared tendon-stiffness factors. **Per trial** (muscles, DOFs and side may differ): the
variables, bounds and constraints of the single-trial problem (:mod:`.ipopt`), node blocks
``z_k = [a, l~M, lp, e, aT, v~M]_k`` then ``[a, l~M, lp]_N``, each interval's equality rows
followed by its EMG bound rows. **Goals** (:class:`Goals`; each term one class of
:mod:`.objective`, summed into each interval's cost), per trial normalised by its ``N``::

    wAct/2 (sum e^2 + sum a^2)/(N M) + wTres sum aT^2/(N D) + wVm sum v~M^2/(N M)
    + wEMG sum (e - s_EMG E)^2/(nEMG N) + wUS sum ((l~M s_lMo lMo - lUS)/lMo)^2/(nUS N)
    + wE sum_k sum_m Edot_m(e_k, a_k, l~M_k, v~M_k)/(m_body N)

(the energy goal, :mod:`.energy`: a smooth metabolic model's rate without basal heat, W)
and EMG bounds ``|e_k - s_EMG E_k| <= tol`` (``tol = 0``: EMG-driven). **Shared parameters**
(:class:`ParameterSpec`): scale factors of ``kT`` (``shift(kT)`` recomputed), ``lMo`` (``w =
lMo sin(alpha_0)`` scales with it) and ``lTs`` per muscle, and EMG scale factors, with bounds and
couplings (one variable per coupled group, or equality rows after all trials).

**Transcription.** Trials with the same muscles, DOFs and goal data form a group whose
per-interval functions (SX: constraints, objective, Jacobian, Hessian of the Lagrangian) are
built once per process for each :class:`GroupStructure` (the muscle values enter as an input,
like the node data: :func:`group_functions`, ``docs/solver.md``) and mapped over the group's
nodes; their nonzeros are placed into the global sparse
matrices handed to IPOPT (block banded Jacobian with dense factor columns; block diagonal
Hessian with a border and a factor block summed over all nodes). The node data and muscle
values are the NLP's parameter ``p``: the symbolic NLP is built once per process for each
:class:`ProblemStructure` (:func:`symbolic_problem`). Moment arms zero at every node
of a group are removed from its expressions, and with them their structural zeros. The fiber
dynamics (``Goals.fiber_dynamics``) are forward Euler with the Hill equilibrium at each
interval's start node, or backward Euler with it at the end node: then the interval's rows are
nonlinear in the next node's ``[a, l~M, lp]``, its Hessian blocks couple ``z_k`` with them, and
the entries of two intervals at one place of the Hessian are summed.
"""

from __future__ import annotations

import copy
import functools
from dataclasses import dataclass

import numpy as np

from ..errors import DataMismatchError, OptionError, SolverError, UnknownMuscleError
from ..messages import name_list
from ..muscle import activation_rate, hill_residual, tendon_force_length
from ._checks import COUPLINGS, check_option
from .bounds import (  # noqa: F401  (re-exported)
    ACTIVATION_BOUNDS, FIBER_LENGTH_BOUNDS, FIBER_LENGTH_MARGIN, FIBER_VELOCITY_BOUNDS, MIN_PROJECTED_LENGTH_M,
    RESERVE_BOUNDS, bounds_and_guess, fiber_length_upper_bounds, node_bounds,
)
from .objective import EmgTracking, find_term, goal_terms, last_node_cost, node_cost
from .parameters import MuscleTendonParameters
from .goals import (  # noqa: F401  (re-exported)
    EFFORT_WEIGHTS, FIBER_DYNAMICS, PARAMETER_KINDS, Goals, ParameterSpec, TrialBlock, check_fiber_dynamics,
    coupling_pairs,
)

__all__ = ["Goals", "EFFORT_WEIGHTS", "ParameterSpec", "coupling_pairs", "TrialBlock", "PARAMETER_KINDS",
           "FIBER_DYNAMICS", "build_problem", "node_bounds", "fiber_length_upper_bounds", "check_fiber_dynamics",
           "GroupStructure", "group_functions", "MUSCLE_VALUES"]

#: the muscle values the per-interval functions take as their input ``q``: these rows of
#: :func:`_muscle_values`, one entry per muscle each (``w2``: the squared fiber width ``lMo sin(alpha_0)``)
MUSCLE_VALUES = ("lmo", "lts", "vmax", "kT", "kpe", "s0", "sm", "f0", "w2")


def _muscle_values(params: MuscleTendonParameters) -> np.ndarray:
    """The input ``q`` of a group's functions: :data:`MUSCLE_VALUES` of ``params``' muscles, row by row."""
    rows = dict(
        lmo=params.optimal_fiber_length_m, lts=params.tendon_slack_length_m, vmax=params.max_contraction_velocity,
        kT=params.tendon_stiffness, kpe=params.passive_kpe, s0=params.passive_s0, sm=params.passive_sm,
        f0=params.max_isometric_force_N, w2=np.asarray(params.width_m, dtype=float) ** 2)
    return np.concatenate([np.asarray(rows[k], dtype=float).reshape(-1) for k in MUSCLE_VALUES])


def _node_expressions(sym, M: int, D: int, h, P: dict, optimal_reserve_Nm: float, ca, backward: bool = False):
    """Symbols and constraint expressions of one mesh interval (:mod:`.ipopt`); with
    ``backward`` the Hill equilibrium holds at the end node (``a1, lm1, lp1, lmt1``) with ``vm``."""
    a, lm, lp = sym("a", M), sym("lm", M), sym("lp", M)
    e, aT, vm = sym("e", M), sym("aT", D), sym("vm", M)
    a1, lm1, lp1 = sym("a1", M), sym("lm1", M), sym("lp1", M)
    lmt, rflat, mom, lmt1 = sym("lmt", M), sym("r", D * M), sym("id", D), sym("lmt1", M)
    penn = (lm * P["lmo"]) ** 2 - P["w2"] - lp**2
    dyn_a = a1 - a - h * activation_rate(e, a)
    dyn_lm = lm1 - lm - h * vm
    hill = hill_residual(
        *((a1, lm1, vm, lp1, lmt1) if backward else (a, lm, vm, lp, lmt)),
        optimal_fiber_length_m=P["lmo"], tendon_slack_length_m=P["lts"],
        max_contraction_velocity=P["vmax"], kT=P["kT"], kpe=P["kpe"], s0=P["s0"], sm=P["sm"],
    )
    ft = tendon_force_length((lmt - lp) / P["lts"], P["kT"])
    R = ca.reshape(rflat, D, M)
    moment = mom - ca.mtimes(R, P["f0"] * ft) - optimal_reserve_Nm * aT
    syms = dict(a=a, lm=lm, lp=lp, e=e, aT=aT, vm=vm, a1=a1, lm1=lm1, lp1=lp1, lmt=lmt, r=rflat, id=mom, lmt1=lmt1)
    return syms, ca.vertcat(dyn_a, dyn_lm, penn, hill, moment), penn


def _group_index(n: int, pairs) -> list[int]:
    """Index of the shared variable of each of ``n`` factors coupled by ``pairs`` (union-find)."""
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in pairs:
        ra, rb = root(a), root(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    roots = sorted({root(i) for i in range(n)})
    return [roots.index(root(i)) for i in range(n)]


def _hess_blocks(ca, expr, x, p):
    """Upper triangle of d2/dx2, the full d2/dxdp and the upper triangle of d2/dp2."""
    n = x.shape[0]
    H = ca.hessian(expr, ca.vertcat(x, p))[0]
    return ca.triu(H[:n, :n]), H[:n, n:], ca.triu(H[n:, n:])


@dataclass(frozen=True)
class GroupStructure:
    """What a group's per-interval functions depend on besides the values they are called with:
    sizes, the positions of tracked muscles, the goals, the factors' places, the moment arms
    removed as zero. Groups of equal structure (any trial length, muscle values, data) share
    their functions (:func:`group_functions`)."""

    n_muscles: int
    n_dofs: int
    emg_index: tuple[int, ...]  # positions of the EMG-tracked muscles among the group's muscles
    fiber_index: tuple[int, ...]  # positions of the muscles with measured fiber lengths
    goals: Goals
    optimal_reserve_Nm: float
    factor_of: tuple  # ((kind, ((muscle position, factor index), ...)), ...)
    emg_factor: tuple[int, ...]  # factor index of each tracked muscle
    n_full: int
    p_index: tuple[int, ...] | None
    zero_r: tuple[int, ...]  # entries of the column-major D x M moment arms that are zero at every node


def group_functions(structure: GroupStructure, energy_values=None) -> dict:
    """The per-interval and last-node functions of a group (:func:`_group_functions`), built once
    per process for each :class:`GroupStructure` (the symbolic derivatives are most of a
    problem's build time, ``docs/solver.md``). With the energy goal they are built for the
    problem: its muscle masses and slow-twitch fractions (``energy_values``) are constants."""
    if structure.goals.energy is not None:
        return _group_functions(structure, energy_values)
    return _shared_group_functions(structure)


@functools.lru_cache(maxsize=8)
def _shared_group_functions(structure: GroupStructure) -> dict:
    """A group's functions, once per process; a new process reads them from the package cache
    (:mod:`.function_cache`) when an earlier one built them."""
    from .function_cache import cached_functions

    return cached_functions("group functions", structure, lambda: _group_functions(structure))


def _group_functions(structure: GroupStructure, energy_values=None) -> dict:
    """Per-interval and last-node functions (SX) of one group of trials; see the module docstring.

    Node inputs: ``z`` (5M+D), ``xn = [a, l~M]`` of the next node (backward fiber dynamics:
    ``[a, l~M, lp]``), data ``d = [lMT, r (column-major D x M), ID, EMG, lUS, h, 1/N]`` (backward:
    then ``lMT`` of the next node), the shared variables ``p``, the muscle values ``q``
    (:func:`_muscle_values`). With the backward fiber dynamics
    the constraints are nonlinear in ``xn``: the Hessian functions take ``xn`` and return the
    blocks of ``[z, xn]``. ``factor_of[kind]`` lists
    ``(muscle index, factor index)``; ``emg_factor`` the factor index of each tracked muscle.
    """
    import casadi as ca

    st = structure
    goals, M, D = st.goals, st.n_muscles, st.n_dofs
    nE, nU = len(st.emg_index), len(st.fiber_index)
    q = ca.SX.sym("q", len(MUSCLE_VALUES) * M)
    P = {k: q[i * M:(i + 1) * M] for i, k in enumerate(MUSCLE_VALUES)}
    lmo0 = P["lmo"]
    p = ca.SX.sym("p", st.n_full if st.p_index is None else (max(st.p_index) + 1 if st.p_index else 0))
    full = [p[j] for j in (st.p_index if st.p_index is not None else range(st.n_full))]
    factor_of = dict(st.factor_of)
    for kind, key in PARAMETER_KINDS.items():
        if key and factor_of.get(kind):
            v = ca.SX(P[key])
            for i, j in factor_of[kind]:
                v[i] = P[key][i] * full[j]
            if key == "lmo":
                w2 = ca.SX(P["w2"])
                for i, j in factor_of[kind]:
                    w2[i] = P["w2"][i] * full[j] ** 2
                P["w2"] = w2
            P[key] = v
    h, inv_n = ca.SX.sym("h"), ca.SX.sym("inv_n")
    emg, lus = ca.SX.sym("emg", nE), ca.SX.sym("lus", nU)
    backward = goals.fiber_dynamics == "backward"
    S, gk, _ = _node_expressions(ca.SX.sym, M, D, h, P, st.optimal_reserve_Nm, ca, backward)
    if len(st.zero_r):
        gk = ca.substitute(gk, S["r"][list(st.zero_r)], ca.SX.zeros(len(st.zero_r)))
    terms = goal_terms(goals, st.emg_index, st.fiber_index)
    v = {**S, **P, "lmo0": lmo0, "emg": emg, "lus": lus,
         "emg_scale": ca.vertcat(*[full[j] for j in st.emg_factor]) if nE else ca.SX(0, 1)}
    if energy_values is not None:
        v.update(mass=ca.DM(energy_values[0]), fst=ca.DM(energy_values[1]))
    track = find_term(terms, EmgTracking).residual(v) if nE else ca.SX(0, 1)
    g = ca.vertcat(gk, track) if goals.emg_tolerance is not None else gk
    z = ca.vertcat(S["a"], S["lm"], S["lp"], S["e"], S["aT"], S["vm"])
    xn = ca.vertcat(S["a1"], S["lm1"], S["lp1"]) if backward else ca.vertcat(S["a1"], S["lm1"])
    d = ca.vertcat(S["lmt"], S["r"], S["id"], emg, lus, h, inv_n, *([S["lmt1"]] if backward else []))
    cost = node_cost(terms, v)
    f = inv_n * cost
    lam, sigma = ca.SX.sym("lam", g.shape[0]), ca.SX.sym("sigma")
    cse = {"cse": True}
    fn = {
        "g": ca.Function("core_g", [z, xn, d, p, q], [g], cse),
        "f": ca.Function("core_f", [z, d, p, q], [f, ca.gradient(f, z), ca.gradient(f, p)], cse),
        # the constraint values come with the Jacobian (shared subexpressions)
        "jac": ca.Function("core_jac", [z, xn, d, p, q], [g, ca.jacobian(g, ca.vertcat(z, xn, p))], cse),
        "hess": ca.Function("core_hess", [z, xn, d, p, q, lam, sigma],
                            list(_hess_blocks(ca, sigma * f + ca.dot(lam, g), ca.vertcat(z, xn) if backward else z,
                                              p)), cse),
    }
    # last node: pennation identity and the activation cost of a_N
    xl = ca.SX.sym("xl", 3 * M)
    penn = (xl[M:2 * M] * P["lmo"]) ** 2 - P["w2"] - xl[2 * M:] ** 2
    f_last = inv_n * last_node_cost(terms, {"a": xl[0:M], "lm": xl[M:2 * M]})
    lam_l = ca.SX.sym("lam_l", M)
    fn["g_last"] = ca.Function("core_g_last", [xl, p, q], [penn])
    fn["f_last"] = ca.Function("core_f_last", [xl, inv_n], [f_last, ca.gradient(f_last, xl)])
    fn["jac_last"] = ca.Function("core_jac_last", [xl, p, q], [ca.jacobian(penn, ca.vertcat(xl, p))])
    fn["hess_last"] = ca.Function("core_hess_last", [xl, p, q, inv_n, lam_l, sigma],
                                  list(_hess_blocks(ca, sigma * f_last + ca.dot(lam_l, penn), xl, p)))
    return fn


def _triplets(sp):
    r, c = sp.get_triplet()
    return np.asarray(r, dtype=np.int64), np.asarray(c, dtype=np.int64)


def _sparse(ca, shape, rows, cols, values, add_duplicates: bool = False):
    """An MX sparse matrix from global triplets and the MX vector of their values (entries at
    one place summed with ``add_duplicates``, else refused)."""
    rows, cols = np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)
    perm = np.lexsort((rows, cols))
    rs, cs = rows[perm], cols[perm]
    dup = (np.diff(rs) == 0) & (np.diff(cs) == 0) if rs.size > 1 else np.zeros(0, dtype=bool)
    if np.any(dup) and not add_duplicates:
        raise SolverError("internal error: duplicate entries in an assembled derivative matrix")
    if np.any(dup):  # sum the entries of each place: a sparse 0/1 matrix times the values
        place = np.concatenate([[0], np.cumsum(~dup)])
        S = ca.DM(ca.Sparsity.triplet(int(place[-1]) + 1, perm.size, place.tolist(), perm.tolist()), 1.0)
        values = ca.mtimes(S, values)
        keep = np.concatenate([[True], ~dup])
        rs, cs, perm = rs[keep], cs[keep], np.arange(int(keep.sum()))
    sp = ca.Sparsity.triplet(int(shape[0]), int(shape[1]), rs.tolist(), cs.tolist())
    if not np.array_equal(perm, np.arange(perm.size)):
        values = values.nz[perm.tolist()]
    return ca.MX(sp, values)


def _check_trials(trials, params, specs):
    if not trials:
        raise OptionError("a muscle redundancy problem needs at least one trial")
    labels = [t.label for t in trials]
    if len(set(labels)) != len(labels):
        raise OptionError(f"trial labels must be distinct, not {labels}")
    names = set(params.names)
    for t in trials:
        N, inp = t.inputs.n_intervals, t.inputs
        missing = [m for m in inp.muscles if m not in names]
        if missing:
            raise UnknownMuscleError(f"trial {t.label}: no muscle parameters for {name_list(missing)}")
        for what, ms, arr in (("EMG", t.emg_muscles, t.emg_nodes), ("fiber lengths", t.fiber_muscles,
                                                                      t.fiber_length_nodes_m)):
            bad = [m for m in ms if m not in inp.muscles]
            if bad:
                raise UnknownMuscleError(f"trial {t.label}: {what} of {name_list(bad)}, which the trial's "
                                         "problem does not have; map them to muscles of the model and side")
            if ms and (arr is None or np.shape(arr) != (N, len(ms))):
                raise DataMismatchError(f"trial {t.label}: {what} at the nodes has shape {np.shape(arr)}, "
                                        f"expected ({N}, {len(ms)})")
    have = {m for t in trials for m in t.inputs.muscles}
    tracked = {m for t in trials for m in t.emg_muscles}
    for s in specs:
        pool = tracked if s.kind == "emg_scale" else have
        bad = [m for m in s.muscles if m not in pool]
        if bad:
            raise UnknownMuscleError(f"{s.kind} factors of {name_list(bad)}: no trial of the problem has "
                                     f"{'EMG of ' if s.kind == 'emg_scale' else ''}such a muscle")


@dataclass(frozen=True)
class GroupPlan:
    """One group of trials in a :class:`ProblemStructure`: its per-interval functions'
    structure, its trials (positions in the problem) and their mesh intervals."""

    structure: GroupStructure
    members: tuple[int, ...]
    n_intervals: tuple[int, ...]
    n_data: int  # rows of the group's node data d (:func:`_group_functions`)


@dataclass(frozen=True)
class ProblemStructure:
    """All the symbolic NLP depends on: the trials' sizes, the groups, the shared factors'
    places. Problems of equal structure (same sizes and muscle sets: the workflows of one trial,
    its uncertainty samples) have the same NLP with other parameter values (node data, muscle
    values) and share it (:func:`symbolic_problem`)."""

    sizes: tuple[tuple[int, int, int, int], ...]  # per trial (M, D, N, EMG bound rows per interval)
    groups: tuple[GroupPlan, ...]
    n_full: int
    p_index: tuple[int, ...] | None
    pairs: tuple[tuple[int, int], ...]
    spec_off: tuple[int, ...]
    explicit_derivatives: bool


def build_problem(trials, params: MuscleTendonParameters, goals: Goals, specs=(), *, optimal_reserve_Nm=150.0,
                  coupling: str = "shared", explicit_derivatives: bool = True) -> dict:
    """The NLP of ``trials`` with ``goals`` and the shared factors ``specs``, without solving it.
    ``goals`` are resolved (:meth:`.goals.Goals.resolved`: the fiber dynamics given).

    Returns the CasADi symbols/expressions ``x``, ``f``, ``g`` and the NLP parameter ``p``
    (the groups' node data and muscle values) with its values ``p_values``, the bounds ``lbx,
    ubx, lbg, ubg``, ``x0`` (factors 1), the sizes, the ``layout``, the ``structure``
    (:class:`ProblemStructure`) and, with ``explicit_derivatives``, the functions ``grad_f``,
    ``jac_g``, ``hess_lag`` (inputs ``x, p, ...``) handed to IPOPT. The symbolic part is built
    once per process for each structure (:func:`symbolic_problem`), except with the energy goal.
    """
    trials, specs = list(trials), list(specs)
    if goals.fiber_dynamics is None:
        raise OptionError("the goals' fiber dynamics are the problem's default (None): build the problem from "
                          "goals.resolved(emg_mode), which gives the scheme of the EMG mode")
    check_option("coupling", coupling, COUPLINGS)
    _check_trials(trials, params, specs)
    spec_off = np.cumsum([0] + [len(s.muscles) for s in specs])
    n_full = int(spec_off[-1])
    pairs = [(int(spec_off[i]) + a, int(spec_off[i]) + b) for i, s in enumerate(specs) for a, b in s.couplings]
    p_index = None
    if coupling == "shared":
        p_index = _group_index(n_full, pairs)
        pairs = []
    backward = goals.fiber_dynamics == "backward"
    sizes = []
    for t in trials:
        nb = len(t.emg_muscles) if goals.emg_tolerance is not None else 0
        sizes.append((len(t.inputs.muscles), len(t.inputs.dofs), t.inputs.n_intervals, nb))

    grouped = {}
    for i, t in enumerate(trials):
        grouped.setdefault(t.signature(), []).append(i)
    groups, values, energy = [], [], []
    for members in grouped.values():
        t0 = trials[members[0]]
        muscles, dofs = tuple(t0.inputs.muscles), tuple(t0.inputs.dofs)
        M, D = len(muscles), len(dofs)
        gp = params.subset(muscles)
        pos = {m: k for k, m in enumerate(muscles)}
        factor_of = {s.kind: [(pos[m], int(spec_off[i]) + k) for k, m in enumerate(s.muscles) if m in pos]
                     for i, s in enumerate(specs) if s.kind != "emg_scale"}
        emg_pos = {m: int(spec_off[i]) + k for i, s in enumerate(specs) if s.kind == "emg_scale"
                   for k, m in enumerate(s.muscles)}
        missing = [m for m in t0.emg_muscles if m not in emg_pos]
        if missing:
            raise OptionError(f"the EMG of {name_list(missing)} is tracked but has no EMG scale factor")
        crosses = np.zeros((D, M), dtype=bool)
        for i in members:
            crosses |= np.any(trials[i].inputs.moment_arms_m != 0.0, axis=0)
        zero_r = np.flatnonzero(~crosses.T.reshape(-1))
        structure = GroupStructure(
            n_muscles=M, n_dofs=D, emg_index=tuple(pos[m] for m in t0.emg_muscles),
            fiber_index=tuple(pos[m] for m in t0.fiber_muscles), goals=goals,
            optimal_reserve_Nm=float(optimal_reserve_Nm),
            factor_of=tuple((kind, tuple(pairs_)) for kind, pairs_ in factor_of.items()),
            emg_factor=tuple(emg_pos[m] for m in t0.emg_muscles), n_full=n_full,
            p_index=None if p_index is None else tuple(p_index), zero_r=tuple(int(i) for i in zero_r))
        energy.append(goals.energy.muscle_values(muscles, gp.max_isometric_force_N, gp.optimal_fiber_length_m)
                      if goals.energy is not None and goals.energy.weight else None)
        data = []
        for i in members:
            t, N = trials[i], trials[i].inputs.n_intervals
            inp = t.inputs
            rr = inp.moment_arms_m[:N].transpose(0, 2, 1).reshape(N, D * M)
            emg = t.emg_nodes if t.emg_muscles else np.zeros((N, 0))
            lus = t.fiber_length_nodes_m if t.fiber_muscles else np.zeros((N, 0))
            data.append(np.hstack([inp.lmt_m[:N], rr, inp.moments_Nm[:N], emg, lus, np.full((N, 1), inp.step_s),
                                   np.full((N, 1), 1.0 / N), *([inp.lmt_m[1:N + 1]] if backward else [])]))
        data = np.vstack(data)  # (nodes, n_data): the parameter holds its transpose, column-major
        values += [data.reshape(-1), _muscle_values(gp)]
        groups.append(GroupPlan(structure=structure, members=tuple(members),
                                n_intervals=tuple(sizes[i][2] for i in members), n_data=int(data.shape[1])))
    structure = ProblemStructure(sizes=tuple(sizes), groups=tuple(groups), n_full=n_full,
                                 p_index=None if p_index is None else tuple(p_index), pairs=tuple(pairs),
                                 spec_off=tuple(int(v) for v in spec_off), explicit_derivatives=explicit_derivatives)
    if goals.energy is None:  # the process's shared NLP: its layout copied, so that no caller changes the shared one
        out = dict(symbolic_problem(structure))
        out["layout"] = copy.deepcopy(out["layout"])
    else:  # the energy goal's muscle masses are constants of its functions: built for this problem
        out = _symbolic_problem(structure, tuple(energy))
    L = out["layout"]
    out.update(p_values=np.concatenate(values) if values else np.zeros(0), structure=structure)
    out.update(bounds_and_guess(trials, params, L["trials"], specs, goals, p_index, L["n_p"], pairs))
    n_var, n_con = out["n_variables"], out["n_constraints"]
    if out["x0"].size != n_var or out["g"].shape[0] != n_con or out["p_values"].size != out["p"].numel():
        raise SolverError(f"internal error: problem size {out['x0'].size}/{out['g'].shape[0]}, expected {n_var}/{n_con}")
    if not np.all(np.isfinite(out["x0"])):
        raise SolverError("the initial guess holds NaN or infinite values; check the muscle geometry and parameters")
    n_ineq = sum(d["nb"] * d["N"] for d in L["trials"])
    out.update(n_equality_constraints=n_con - n_ineq, n_inequality_constraints=n_ineq)
    return out


@functools.lru_cache(maxsize=4)
def symbolic_problem(structure: ProblemStructure) -> dict:
    """The symbolic NLP of a :class:`ProblemStructure` (no energy goal), built once per process:
    ``x``, ``p``, ``f``, ``g``, the sizes, the ``layout`` and the explicit derivative functions.
    Do not change the dictionary it returns (:func:`build_problem` copies it)."""
    return _symbolic_problem(structure)


def _symbolic_problem(structure: ProblemStructure, energy_values=None) -> dict:
    import casadi as ca

    st = structure
    info, var_off, con_off, o, r = [], [], [], 0, 0
    for M, D, N, nb in st.sizes:
        nz, ng = 5 * M + D, 4 * M + D + nb
        var_off.append(o)
        con_off.append(r)
        info.append(dict(M=M, D=D, N=N, nz=nz, ng=ng, nb=nb))
        o += nz * N + 3 * M
        r += ng * N + M
    P0, R0 = o, r
    n_full, p_index, pairs = st.n_full, st.p_index, list(st.pairs)
    n_p = n_full if p_index is None else (max(p_index) + 1 if p_index else 0)
    n_var, n_con = P0 + n_p, R0 + len(pairs)
    w = ca.MX.sym("w", n_var)
    p = w[P0:]
    lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", n_con)
    n_values = sum(sum(g.n_intervals) * g.n_data + len(MUSCLE_VALUES) * g.structure.n_muscles for g in st.groups)
    values = ca.MX.sym("p", n_values)  # the NLP parameter: each group's node data, then its muscle values

    g_parts = [None] * len(st.sizes)
    gj_parts = [None] * len(st.sizes)
    f_terms, grad_parts, grad_p = [], [None] * len(st.sizes), []
    jr, jc, jv, hr, hc, hv, hpp = [], [], [], [], [], [], []
    v_off = 0
    for gi, group in enumerate(st.groups):
        members = list(group.members)
        M, D = group.structure.n_muscles, group.structure.n_dofs
        fn = group_functions(group.structure, None if energy_values is None else energy_values[gi])
        nz, ng = info[members[0]]["nz"], info[members[0]]["ng"]
        backward = group.structure.goals.fiber_dynamics == "backward"
        nxn = (3 if backward else 2) * M
        n_nodes, T = sum(group.n_intervals), len(members)
        data = ca.reshape(values[v_off:v_off + n_nodes * group.n_data], group.n_data, n_nodes)
        v_off += n_nodes * group.n_data
        qv = values[v_off:v_off + len(MUSCLE_VALUES) * M]
        v_off += len(MUSCLE_VALUES) * M
        zc, xc, rbn, Zs, Xns, XLs, Ls, LLs = [], [], [], [], [], [], [], []
        for i in members:
            N = info[i]["N"]
            k = np.arange(N)
            zc.append(var_off[i] + k * nz)
            xc.append(var_off[i] + (k + 1) * nz)
            rbn.append(con_off[i] + k * ng)
            Z = ca.reshape(w[var_off[i]:var_off[i] + nz * N], nz, N)
            xl = w[var_off[i] + nz * N:var_off[i] + nz * N + 3 * M]
            Zs.append(Z)
            Xns.append(ca.horzcat(Z[0:nxn, 1:], xl[0:nxn]))
            XLs.append(xl)
            Ls.append(ca.reshape(lam_g[con_off[i]:con_off[i] + ng * N], ng, N))
            LLs.append(lam_g[con_off[i] + ng * N:con_off[i] + ng * N + M])
        zc, xc, rbn = np.concatenate(zc), np.concatenate(xc), np.concatenate(rbn)
        last_var = np.array([var_off[i] + info[i]["N"] * nz for i in members])
        last_con = np.array([con_off[i] + info[i]["N"] * ng for i in members])
        inv_n = ca.DM([[1.0 / info[i]["N"]] for i in members]).T
        Z, Xn, XL = ca.horzcat(*Zs), ca.horzcat(*Xns), ca.horzcat(*XLs)
        bounds = [0]
        for i in members:
            bounds.append(bounds[-1] + info[i]["N"])

        def split(mat):
            return [ca.vec(mat[:, bounds[j]:bounds[j + 1]]) for j in range(T)]

        GL = fn["g_last"].map(T)(XL, p, qv)
        G = split(fn["g"].map(n_nodes)(Z, Xn, data, p, qv))
        G_j, J_nodes = fn["jac"].map(n_nodes)(Z, Xn, data, p, qv)
        G_j = split(G_j)
        for j, i in enumerate(members):
            g_parts[i] = ca.vertcat(G[j], GL[:, j])
            gj_parts[i] = ca.vertcat(G_j[j], GL[:, j])
        F, Gz, Gp = fn["f"].map(n_nodes)(Z, data, p, qv)
        FL, GLx = fn["f_last"].map(T)(XL, inv_n)
        f_terms += [ca.sum2(F), ca.sum2(FL)]
        grad_p.append(ca.sum2(Gp))
        Gz = split(Gz)
        for j, i in enumerate(members):
            grad_parts[i] = ca.vertcat(Gz[j], GLx[:, j])
        # Jacobian
        rb, cb = _triplets(fn["jac"].sparsity_out(1))
        cmap = np.where(cb < nz, zc[:, None] + cb,
                        np.where(cb < nz + nxn, xc[:, None] + (cb - nz), P0 + (cb - nz - nxn)))
        jr.append((rbn[:, None] + rb).ravel())
        jc.append(cmap.ravel())
        jv.append(J_nodes.nz[:])
        rl, cl = _triplets(fn["jac_last"].sparsity_out(0))
        jr.append((last_con[:, None] + rl).ravel())
        jc.append(np.where(cl < 3 * M, last_var[:, None] + cl, P0 + (cl - 3 * M)).ravel())
        jv.append(fn["jac_last"].map(T)(XL, p, qv).nz[:])
        # Hessian of the Lagrangian
        # (backward fiber dynamics: the blocks of [z_k, xn_k]; an entry of xn_k adds to node k+1's)
        for (f_h, args, zcol, xcol, n) in (
                (fn["hess"], (Z, Xn, data, p, qv, ca.horzcat(*Ls), lam_f), zc, xc, n_nodes),
                (fn["hess_last"], (XL, p, qv, inv_n, ca.horzcat(*LLs), lam_f), last_var, last_var, T)):
            Hzz, Hzp, Hpp = f_h.map(n)(*args)
            r1, c1 = _triplets(f_h.sparsity_out(0))
            r2, c2 = _triplets(f_h.sparsity_out(1))
            r3, c3 = _triplets(f_h.sparsity_out(2))

            def place(i):
                return np.where(i < nz, zcol[:, None] + i, xcol[:, None] + (i - nz)).ravel()

            hr += [place(r1), place(r2)]
            hc += [place(c1), np.tile(P0 + c2, n)]
            hv += [Hzz.nz[:], Hzp.nz[:]]
            if r3.size:
                hpp.append(ca.MX(ca.Sparsity.triplet(n_p, n_p, r3.tolist(), c3.tolist()),
                                 ca.sum2(ca.reshape(Hpp.nz[:], r3.size, n))))

    coup = [ca.vertcat(*[p[a] - p[b] for a, b in pairs])] if pairs else []
    g = ca.vertcat(*g_parts, *coup)
    f = sum(f_terms[1:], f_terms[0])
    out = {"x": w, "f": f, "g": g, "n_variables": n_var, "n_constraints": n_con,
           "layout": dict(trials=info, var_off=var_off, con_off=con_off, P0=P0, R0=R0, n_p=n_p, n_full=n_full,
                          p_index=None if p_index is None else list(p_index), pairs=pairs,
                          spec_off=list(st.spec_off)),
           "p": values}
    if st.explicit_derivatives:
        if pairs:
            jr.append(np.repeat(R0 + np.arange(len(pairs)), 2))
            jc.append(np.array([P0 + j for ab in pairs for j in ab]))
            jv.append(ca.DM([v for _ in pairs for v in (1.0, -1.0)]))
        jac = _sparse(ca, (n_con, n_var), np.concatenate(jr), np.concatenate(jc), ca.vertcat(*jv))
        if hpp:
            Hp = sum(hpp[1:], hpp[0])
            r3, c3 = _triplets(Hp.sparsity())
            hr.append(P0 + r3)
            hc.append(P0 + c3)
            hv.append(Hp.nz[:])
        hess = _sparse(ca, (n_var, n_var), np.concatenate(hr), np.concatenate(hc), ca.vertcat(*hv),
                       add_duplicates=st.groups[0].structure.goals.fiber_dynamics == "backward")
        grad = ca.vertcat(*grad_parts, sum(grad_p[1:], grad_p[0]) if n_p else ca.MX(0, 1))
        out.update({
            "grad_f": ca.Function("nlp_grad_f", [w, values], [f, grad], ["x", "p"], ["f", "grad_f_x"]),
            "jac_g": ca.Function("nlp_jac_g", [w, values], [ca.vertcat(*gj_parts, *coup), jac], ["x", "p"],
                                 ["g", "jac_g_x"]),
            "hess_lag": ca.Function("nlp_hess_l", [w, values, lam_f, lam_g], [hess], ["x", "p", "lam_f", "lam_g"],
                                    ["triu_hess_gamma_x_x"]),
        })
    return out
