"""The passive calibration problem: an NLP over the static equilibria of every pose, CasADi + IPOPT.

Per muscle, the shape parameters ``kPE`` and ``s0`` of the passive curve

    fPE(l~M) = [exp(kPE (l~M - s0)/sM) - 1 - P1] / P2,
    P1 = exp(kPE (0.2 - 1)/0.6) - 1,   P2 = exp(kPE) - 1      (sM = 0.6 fixed)

(:func:`musclemetab.muscle.passive_force_length`) are chosen so that the passive joint
moments of all muscles spanning a joint reproduce in-vivo passive moment-angle targets
(Silder et al. 2007) at the ankle, knee and hip.

Each frame of each calibration trial is an independent static equilibrium (activation 0,
fiber velocity 0). For trial ``t``, frame ``k`` and muscle ``m`` (compliant tendon,
constant-thickness pennation, ``w = lMo sin(alpha0)``):

    (l~M lMo)^2 - w^2 - lM_proj^2 = 0                              (pennation)
    fPE(l~M; kPE, s0, sM) lM_proj / (l~M lMo) - fT(l~T) = 0         (equilibrium)
    l~T = (lMT - lM_proj) / lTs
    T_target,k = sum_m F0_m fT_m,k r_m,k + Topt aT_k,   Topt = 150 N m

with ``0.05 <= l~M <= 2`` (or, for a muscle the trial's geometry stretches further, its
longest rigid-tendon fiber length plus 0.05: :func:`musclemetab.muscle.longest_fiber_length_bound`),
``lM_proj >= 1e-4 m``, ``-1 <= aT <= 1``, ``3 <= kPE <= 5``,
``0.8 <= s0 <= 1.2``. The objective is ``J = sum_t sum_k aT_t,k^2``: least squares of the
passive-moment error divided by 150 N m over every frame of the three trials.

A muscle spanning two calibrated joints has one ``kPE`` and one ``s0``; muscles of one
coupling group (anatomical muscle table column ``passive_coupling_group``, P1-P10) share them
(:func:`parameter_groups`). Shared values are single NLP variables (equivalent to equality
constraints between per-trial copies).

Tendon stiffness: the data's ``kT`` (:func:`.trials.default_tendon_stiffness`; the tendon
curve with its stiffness-dependent shift, :func:`musclemetab.muscle.tendon_force_length`).

The same NLP with the parameters imposed gives the passive moments of any parameter set
(generic ``kPE = 4, s0 = 1``, or a published set); every fit-quality figure is computed
this way, on the same geometry.

The NLP's variables are, in this order, the group parameters ``kPE``, ``s0`` (calibration
only), then per trial ``l~M``, ``lM_proj`` (frames x muscles, column by column) and ``aT``;
every bound (the parameters', the states' and the reserve's) is a constraint row, as are the
pennation, equilibrium and moment equations, per trial in that order. IPOPT's options come
from :class:`musclemetab.redundancy.ipopt.SolverOptions`, as for every problem of the
package (exact Hessian, gradient-based NLP scaling, MUMPS, ``tol = 1e-6`` by default).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np

from ..errors import SolverError, UnknownMuscleError
from ..messages import name_list
from ..muscle import fiber_width, hill_residual, longest_fiber_length_bound, tendon_force_length
from .trials import CalibrationData

if TYPE_CHECKING:
    from ..redundancy.ipopt import SolverOptions

__all__ = [
    "KPE_BOUNDS",
    "S0_BOUNDS",
    "SM_FIXED",
    "KPE_GENERIC",
    "S0_GENERIC",
    "TOPT_NM",
    "LM_NORM_BOUNDS",
    "LM_PROJ_MIN_M",
    "parameter_groups",
    "PassiveSolution",
    "solve_passive",
    "passive_moments",
]

KPE_BOUNDS = (3.0, 5.0)
S0_BOUNDS = (0.8, 1.2)
SM_FIXED = 0.6
KPE_GENERIC = 4.0
S0_GENERIC = 1.0
TOPT_NM = 150.0
LM_NORM_BOUNDS = (0.05, 2.0)
LM_PROJ_MIN_M = 1e-4


def parameter_groups(muscles: Sequence[str]) -> list[tuple[str, ...]]:
    """Muscles sharing one (kPE, s0) pair: the coupling groups P1-P10 of the anatomical
    muscle table, per side; every other muscle is its own group. Order: first appearance in
    ``muscles``."""
    from ..properties import resolve_muscles

    groups: dict[str, list[str]] = {}
    for r in resolve_muscles(muscles, warn=False):
        key = f"{r.coupling_group}_{r.side}" if r.coupling_group else r.name
        groups.setdefault(key, []).append(r.name)
    return [tuple(v) for v in groups.values()]


@dataclass(frozen=True)
class PassiveSolution:
    """Result of one passive NLP solve (calibration or imposed parameters).

    ``parameters``: muscle -> (kPE, s0, sM). ``moments_Nm``: joint -> (F,) muscle passive
    moment; ``reserve_Nm``: joint -> (F,) reserve moment (target - muscles);
    ``lm_norm``: joint -> (F, M) normalised fiber lengths; ``stats``: solver status,
    iterations, wall time, objective.
    """

    parameters: dict
    moments_Nm: dict
    reserve_Nm: dict
    lm_norm: dict
    stats: dict

    def rms_Nm(self, data: CalibrationData) -> dict:
        """RMS of (muscle passive moment - target) per joint, N m."""
        return {t.joint: float(np.sqrt(np.mean((self.moments_Nm[t.joint] - t.target_Nm) ** 2))) for t in data.trials}

    def rms_per_block_Nm(self, data: CalibrationData) -> dict:
        out = {}
        for t in data.trials:
            e = self.moments_Nm[t.joint] - t.target_Nm
            out[t.joint] = [float(np.sqrt(np.mean(e[t.block == b] ** 2))) for b in np.unique(t.block)]
        return out


def _initial_states(lmt, lts, lmo, w, upper):
    """Rigid-tendon guess: ``l~M = (lMT - lTs)/lMo``, ``lM_proj = sqrt((lMT - lTs)^2 - w^2)``."""
    lm = np.clip((lmt - lts) / lmo, LM_NORM_BOUNDS[0] + 1e-3, upper - 1e-3)
    proj = np.sqrt(np.maximum((lm * lmo) ** 2 - w**2, (2 * LM_PROJ_MIN_M) ** 2))
    return lm, proj


@dataclass
class _Nlp:
    """Variables with their initial values, constraint rows with their bounds, in the order added."""

    variables: list = field(default_factory=list)
    x0: list = field(default_factory=list)
    rows: list = field(default_factory=list)
    lbg: list = field(default_factory=list)
    ubg: list = field(default_factory=list)

    def variable(self, name: str, shape: tuple[int, int], initial) -> object:
        import casadi as ca

        v = ca.MX.sym(name, *shape)
        self.variables.append(ca.vec(v))
        self.x0.append(np.broadcast_to(np.asarray(initial, dtype=float), shape).ravel(order="F"))
        return v

    def constrain(self, expr, lower, upper) -> None:
        """Rows ``lower <= expr <= upper`` (``expr`` a column; bounds scalars or one per row)."""
        n = expr.shape[0]
        self.rows.append(expr)
        self.lbg.append(np.broadcast_to(np.asarray(lower, dtype=float).reshape(-1), (n,)))
        self.ubg.append(np.broadcast_to(np.asarray(upper, dtype=float).reshape(-1), (n,)))


def _imposed(data: CalibrationData, parameters: Mapping[str, Sequence[float]]):
    missing = [m for m in data.muscles if m not in parameters]
    if missing:
        raise UnknownMuscleError(
            f"no passive parameters for {name_list(missing)}; the calibration trials involve these muscles"
        )
    kpe_of = {m: float(parameters[m][0]) for m in data.muscles}
    s0_of = {m: float(parameters[m][1]) for m in data.muscles}
    sm_of = {m: float(parameters[m][2]) if len(parameters[m]) > 2 else SM_FIXED for m in data.muscles}
    return kpe_of, s0_of, sm_of


def solve_passive(
    data: CalibrationData,
    parameters: Mapping[str, Sequence[float]] | None = None,
    *,
    options: SolverOptions | None = None,
) -> PassiveSolution:
    """Build the passive NLP of the module docstring and solve it with IPOPT.

    With ``parameters=None`` the coupled ``kPE``, ``s0`` are free (calibration, initial
    guess 4 and 1); with ``parameters = {muscle: (kPE, s0[, sM])}`` (covering every
    muscle of the trials) they are imposed and only the equilibrium states and reserves
    are free, which gives that parameter set's passive moments. ``options``: IPOPT's
    settings (:class:`musclemetab.redundancy.ipopt.SolverOptions`: ``tol``, ``max_iter``,
    ``linear_solver``, ``print_level``, ``ipopt``, ...; default ``SolverOptions()``); the
    weights of the muscle redundancy problem in it play no part here.

    Raises :class:`SolverError` if IPOPT does not converge.
    """
    import casadi as ca

    from ..redundancy.ipopt import SolverOptions, ipopt_options, run_ipopt

    options = options or SolverOptions()
    nlp = _Nlp()
    free = parameters is None
    if free:
        groups = parameter_groups(data.muscles)
        kpe_g = nlp.variable("kpe", (len(groups), 1), KPE_GENERIC)
        s0_g = nlp.variable("s0", (len(groups), 1), S0_GENERIC)
        nlp.constrain(kpe_g, *KPE_BOUNDS)
        nlp.constrain(s0_g, *S0_BOUNDS)
        gidx = {m: i for i, g in enumerate(groups) for m in g}
        kpe_of = {m: kpe_g[gidx[m]] for m in data.muscles}
        s0_of = {m: s0_g[gidx[m]] for m in data.muscles}
        sm_of = {m: SM_FIXED for m in data.muscles}
    else:
        kpe_of, s0_of, sm_of = _imposed(data, parameters)

    objective = 0
    handles = []
    for t in data.trials:
        idx = data.index(t.muscles)
        F, M = t.lmt_m.shape
        F0 = data.max_isometric_force_N[idx]
        lmo = data.optimal_fiber_length_m[idx]
        lts = data.tendon_slack_length_m[idx]
        w = np.asarray(fiber_width(lmo, data.pennation_angle_at_optimal_rad[idx]))
        kT = data.tendon_stiffness[idx]
        upper = longest_fiber_length_bound(t.lmt_m, lts, lmo, w, LM_NORM_BOUNDS[1])
        lm0, proj0 = _initial_states(t.lmt_m, lts, lmo, w, upper)
        lm = nlp.variable(f"lm_{t.joint}", (F, M), lm0)
        proj = nlp.variable(f"proj_{t.joint}", (F, M), proj0)
        aT = nlp.variable(f"aT_{t.joint}", (F, 1), 0.0)
        nlp.constrain(ca.vec(lm), LM_NORM_BOUNDS[0], np.tile(upper, (F, 1)).ravel(order="F"))
        nlp.constrain(ca.vec(proj), LM_PROJ_MIN_M, np.inf)
        if free:  # with imposed parameters the reserve is the moment error, unbounded
            nlp.constrain(aT, -1.0, 1.0)
        # per-muscle column expressions; parameters broadcast over frames
        ones = ca.DM.ones(F, 1)
        kpe_mat = ca.mtimes(ones, ca.horzcat(*[kpe_of[m] for m in t.muscles]))
        s0_mat = ca.mtimes(ones, ca.horzcat(*[s0_of[m] for m in t.muscles]))
        sm_mat = ca.mtimes(ones, ca.DM(np.array([[sm_of[m] for m in t.muscles]])))
        lmo_mat = ca.DM(np.tile(lmo, (F, 1)))
        nlp.constrain(ca.vec((lm * lmo_mat) ** 2 - ca.DM(np.tile(w**2, (F, 1))) - proj**2), 0.0, 0.0)
        lts_mat, kt_mat, lmt = ca.DM(np.tile(lts, (F, 1))), ca.DM(np.tile(kT, (F, 1))), ca.DM(t.lmt_m)
        # the Hill equilibrium of the redundancy problem at rest (activation 0, fiber velocity 0)
        nlp.constrain(ca.vec(hill_residual(0.0, lm, 0.0, proj, lmt, optimal_fiber_length_m=lmo_mat,
                                           tendon_slack_length_m=lts_mat, max_contraction_velocity=1.0,
                                           kT=kt_mat, kpe=kpe_mat, s0=s0_mat, sm=sm_mat)), 0.0, 0.0)
        fT = tendon_force_length((lmt - proj) / lts_mat, kt_mat)
        moment = ca.sum2(fT * ca.DM(np.tile(F0, (F, 1))) * ca.DM(t.moment_arms_m))
        nlp.constrain(moment + TOPT_NM * aT, t.target_Nm, t.target_Nm)
        objective = objective + ca.sumsqr(aT)
        handles.append((t, lm, aT, moment))

    x = ca.vertcat(*nlp.variables)
    try:
        solver = ca.nlpsol("passive", "ipopt", {"x": x, "f": objective, "g": ca.vertcat(*nlp.rows)},
                           {"ipopt": ipopt_options(options), "print_time": False, "error_on_fail": False})
    except RuntimeError as exc:
        raise SolverError(f"the passive calibration problem could not be built: {exc}") from None
    n = x.shape[0]
    xv, _, f_opt, stats, wall, _ = run_ipopt(solver, options, np.concatenate(nlp.x0), np.full(n, -np.inf),
                                             np.full(n, np.inf), np.concatenate(nlp.lbg), np.concatenate(nlp.ubg))
    stats = dict(stats)
    if not stats.get("success"):
        raise SolverError(
            f"the passive {'calibration' if free else 'equilibrium'} NLP did not converge "
            f"(IPOPT: {stats.get('return_status')}); check the trials and the model"
        )
    outputs = [e for _, lm, aT, moment in handles for e in (lm, aT, moment)]
    if free:
        outputs += [kpe_g, s0_g]
    values = [np.asarray(v, dtype=float) for v in ca.Function("passive_values", [x], outputs)(xv)]
    if free:
        kv, sv = values[-2].ravel(), values[-1].ravel()
        params = {m: (float(kv[gidx[m]]), float(sv[gidx[m]]), SM_FIXED) for m in data.muscles}
    else:
        params = {m: (kpe_of[m], s0_of[m], sm_of[m]) for m in data.muscles}
    moments, reserves, lms = {}, {}, {}
    for i, (t, _, _, _) in enumerate(handles):
        lm_v, aT_v, moment_v = values[3 * i: 3 * i + 3]
        moments[t.joint] = moment_v.reshape(-1)
        reserves[t.joint] = TOPT_NM * aT_v.reshape(-1)
        lms[t.joint] = lm_v.reshape(t.lmt_m.shape)
    info = {
        "return_status": stats.get("return_status"),
        "success": bool(stats.get("success")),
        "iterations": int(stats.get("iter_count", -1)),
        "wall_time_s": round(wall, 3),
        "objective": float(f_opt),
    }
    return PassiveSolution(params, moments, reserves, lms, info)


def passive_moments(data: CalibrationData, parameters: Mapping[str, Sequence[float]]) -> PassiveSolution:
    """Passive moments of an imposed parameter set (``{muscle: (kPE, s0[, sM])}``)."""
    return solve_passive(data, parameters)
