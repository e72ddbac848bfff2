"""Exact sensitivities of the reported metabolic rates to each muscle parameter (``docs/uncertainty.md``).

At the optimum ``z*`` of a trial's problem (multipliers ``lam``) the KKT conditions
``F(y, p) = [grad_z L(z, lam; p); g_A(z; p)] = 0`` (``L = f + lam' g``, ``g_A`` the active rows,
``y = (z_free, lam_A)``) hold for every muscle parameter ``p`` near its value. With the active
set fixed the implicit-function theorem gives the parametric sensitivity of the NLP::

    K dy/dp = -dF/dp,     K = [[H, A'], [A, 0]]

(``H`` the Hessian of the Lagrangian on the free variables, ``A`` the Jacobian of the active
rows: the KKT matrix of :class:`.identifiability.KKTSystem`, factorised once). ``dF/dp`` holds the
mixed derivative ``d(grad_z L)/dp`` and ``dg_A/dp``, from the problem's per-interval expressions
(:func:`.transcription._node_expressions`) with the parameters as CasADi symbols. A reported rate
``R(z, p)`` (the whole-body rate, W/kg, and each muscle's cycle-average rate without basal heat,
W, of each energy model: :func:`musclemetab.metabolics.solution.metabolics_from_solution`)
changes by::

    dR/dp = dR/dz . dz/dp + dR/dp|_z

The second term is the explicit dependence of the rate formula on the parameter (``F0`` and
``lMo`` in the forces and in the muscle mass ``F0/sigma rho lMo``, ``vmax`` in ``v~M/vmax``, the
passive parameters in the passive force). Both are taken at once as the directional derivative
of the closed-form rate along ``(dz/dp, p)``, by a central difference of step
:data:`RATE_STEP` in ``log p`` (the rate formulas are evaluated, nothing is solved; where a
formula has a kink, ``max(0, .)``, the result is the mean of the two one-sided derivatives).

Every derivative is reported per log of the parameter, ``dR/dlog p = p dR/dp``: the change of
the rate per 1 % of the parameter is ``dR/dlog p / 100``. The parameters are those of
:data:`PARAMETERS` for each muscle (``alpha0`` through the fiber width ``w = lMo sin(alpha0)``).

**The optimum.** The solves stop at IPOPT's tolerance 1e-6, where the activations and
excitations of muscles that are off still sit about 1e-4 above their bound of zero: the active
set is blurred, and a step of the linearised system would let them go negative. The solution is
therefore first polished (:func:`polish`): re-solved from itself at tolerance
:data:`POLISH_TOL` (barrier parameter from :data:`POLISH_MU_INIT`), the same optimum with sharp
bounds and IPOPT's multipliers. Such bounds are *weakly* active (their multipliers vanish with
the barrier parameter): a variable within :data:`BOUND_SLACK` of a bound is held on it. Where a
parameter's change would lift such a muscle off zero, the derivative is one-sided and the
fixed-active-set sensitivity is that of the side where it stays off; the check against
re-solves (:func:`finite_difference`, ``docs/uncertainty.md``) measures what this costs.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import DataMismatchError, OptionError, SolverError
from ..messages import name_list

__all__ = ["PARAMETERS", "RATE_STEP", "BOUND_SLACK", "POLISH_TOL", "POLISH_MU_INIT", "Sensitivity", "polish",
           "finite_difference", "parameter_derivatives", "state_sensitivities", "trial_sensitivity", "problem_of_solution",
           "sensitivity_refusal", "sensitivity_of_folder", "ranked_table", "write_sensitivity",
           "write_folder_sensitivity", "SENSITIVITY_CSV", "SENSITIVITY_COLUMNS"]

#: parameter -> field of :class:`.parameters.MuscleTendonParameters`
PARAMETERS = {"F0": "max_isometric_force_N", "lMo": "optimal_fiber_length_m", "lTs": "tendon_slack_length_m",
              "kT": "tendon_stiffness", "kPE": "passive_kpe", "s0": "passive_s0", "sM": "passive_sm",
              "vmax": "max_contraction_velocity", "alpha0": "pennation_angle_at_optimal_rad"}
#: step in log p of the central difference of the closed-form rates along (dz/dp, p)
RATE_STEP = 1e-6
#: a variable closer than this to a bound is on it in the active set, whatever its multiplier:
#: at the polished optimum an activation or excitation of a muscle that is off sits about 3e-6
#: above zero with a multiplier of the same size (a weakly active bound); an activation in use
#: is above 1e-3
BOUND_SLACK = 1e-4
#: IPOPT's tolerance and starting barrier parameter of the re-solve that polishes an optimum
#: before its sensitivities are taken (:func:`polish`; the solves' own tolerance, 1e-6, leaves
#: the activations of muscles that are off about 1e-4 above their bound, the active set blurred)
POLISH_TOL = 1e-10
POLISH_MU_INIT = 1e-7
SENSITIVITY_CSV = "sensitivity.csv"
#: the columns of ``sensitivity.csv`` (``docs/data_dictionary.md``)
SENSITIVITY_COLUMNS = ("solution", "parameter_rank", "parameter", "muscle", "parameter_value", "model", "rate",
                       "rate_value", "d_rate_d_log_p", "change_per_1pct", "relative_change_per_1pct")


def _symbolic_parameters(ca, params, s, columns):
    """The problem's muscle values (:data:`.transcription.MUSCLE_VALUES`) as expressions of
    the symbols ``s``, one per ``(parameter, muscle)`` of ``columns``: that parameter
    ``p0 (1 + s)``, the others their values."""
    rel = {name: ca.SX.zeros(len(params.names)) for name in PARAMETERS}
    for j, (name, muscle) in enumerate(columns):
        rel[name][params.names.index(muscle)] = s[j]
    val = {name: ca.DM(np.asarray(getattr(params, f), dtype=float)) * (1 + rel[name]) for name, f in PARAMETERS.items()}
    width = val["lMo"] * ca.sin(val["alpha0"])
    return {"lmo": val["lMo"], "lts": val["lTs"], "vmax": val["vmax"], "kT": val["kT"], "kpe": val["kPE"],
            "s0": val["s0"], "sm": val["sM"], "f0": val["F0"], "w2": width ** 2}


def parameter_derivatives(inputs, params, goals, optimal_reserve_Nm, x, lam_g, n_rows_per_interval, columns):
    """``(d grad_z L / ds, dg / ds)`` (SciPy sparse, variables x parameters and rows x
    parameters) of a single-trial problem at ``(x, lam_g)``, ``s`` the relative changes of the
    parameters ``columns`` (``[(parameter, muscle)]``, :data:`PARAMETERS`): per log of each."""
    import casadi as ca
    import scipy.sparse as sp

    from .objective import goal_terms, node_cost
    from .transcription import _node_expressions

    M, D, N = len(inputs.muscles), len(inputs.dofs), inputs.n_intervals
    n_s = len(columns)
    s = ca.SX.sym("s", n_s)
    P = _symbolic_parameters(ca, params, s, columns)
    h = ca.SX.sym("h")
    S, gk, _ = _node_expressions(ca.SX.sym, M, D, h, P, optimal_reserve_Nm, ca)
    z = ca.vertcat(S["a"], S["lm"], S["lp"], S["e"], S["aT"], S["vm"])
    xn = ca.vertcat(S["a1"], S["lm1"])
    d = ca.vertcat(S["lmt"], S["r"], S["id"], h)
    lam = ca.SX.sym("lam", gk.shape[0])
    v = {**S, **P}
    if goals.energy is not None:
        mass, fst = goals.energy.muscle_values(inputs.muscles, params.max_isometric_force_N,
                                               params.optimal_fiber_length_m)
        v.update(mass=ca.DM(mass), fst=ca.DM(fst))
    # the objective's terms (those that depend on the parameters: the energy goal) at the node
    lag = ca.dot(lam, gk) + node_cost(goal_terms(goals), v) / N
    v = ca.vertcat(z, xn)
    node = ca.Function("sens_node", [z, xn, d, lam, s], [ca.jacobian(ca.gradient(lag, v), s), ca.jacobian(gk, s)],
                       {"cse": True})
    nz, nxn = 5 * M + D, 2 * M
    Z = x[:nz * N].reshape(N, nz).T
    xl = x[nz * N:nz * N + 3 * M]
    Xn = np.hstack([Z[:nxn, 1:], xl[:nxn, None]])
    rr = inputs.moment_arms_m[:N].transpose(0, 2, 1).reshape(N, D * M)
    data = np.hstack([inputs.lmt_m[:N], rr, inputs.moments_Nm[:N], np.full((N, 1), inputs.step_s)]).T
    ng = n_rows_per_interval
    L = np.asarray(lam_g[:ng * N]).reshape(N, ng).T[:gk.shape[0]]
    Hs, Gs = (ca.DM(m) for m in node.map(N)(Z, Xn, data, L, np.zeros(n_s)))
    # each node's block comes whole after the previous one among the nonzeros (column-major)
    r1, c1 = (np.asarray(a, dtype=np.int64) for a in node.sparsity_out(0).get_triplet())
    r2, c2 = (np.asarray(a, dtype=np.int64) for a in node.sparsity_out(1).get_triplet())
    k = np.arange(N)[:, None]
    n_var, n_con = x.size, np.asarray(lam_g).size
    dL = sp.coo_matrix((np.asarray(Hs.nonzeros()), ((np.where(r1 < nz, k * nz + r1, (k + 1) * nz + r1 - nz)).ravel(),
                                                    np.tile(c1, N))), shape=(n_var, n_s))
    dg = sp.coo_matrix((np.asarray(Gs.nonzeros()), ((k * ng + r2).ravel(), np.tile(c2, N))), shape=(n_con, n_s))
    # the last node: the pennation identity (l~M lMo)^2 - w^2 - lp^2 = 0 and its multiplier
    xs, lam_l = ca.SX.sym("xl", 3 * M), ca.SX.sym("lam_l", M)
    penn = (xs[M:2 * M] * P["lmo"]) ** 2 - P["w2"] - xs[2 * M:] ** 2
    last = ca.Function("sens_last", [xs, lam_l, s], [ca.jacobian(ca.gradient(ca.dot(lam_l, penn), xs), s),
                                                     ca.jacobian(penn, s)])
    HL, GL = (sp.coo_matrix(ca.DM(m).full()) for m in last(xl, np.asarray(lam_g)[ng * N:ng * N + M], np.zeros(n_s)))
    dL = dL + sp.coo_matrix((HL.data, (HL.row + nz * N, HL.col)), shape=(n_var, n_s))
    dg = dg + sp.coo_matrix((GL.data, (GL.row + ng * N, GL.col)), shape=(n_con, n_s))
    return dL.tocsc(), dg.tocsc()


def state_sensitivities(nlp: dict, kkt: dict, dL, dg, bound_slack: float = None) -> tuple[np.ndarray, dict]:
    """``dx/ds`` (variables x parameters) at the KKT point ``kkt`` (``x``, ``lam_g``,
    ``lam_x``) of ``nlp`` given ``d grad L/ds`` and ``dg/ds`` (:func:`parameter_derivatives`):
    the KKT matrix (:class:`.identifiability.KKTSystem`, active set fixed) solved for ``-dF/ds``.
    Returns ``(dx/ds, active counts)``."""
    from .identifiability import KKTSystem, lagrangian_derivatives

    x, lam_g, lam_x = kkt["x"], kkt["lam_g"], kkt["lam_x"]
    H, J, g = lagrangian_derivatives(nlp, x, lam_g)
    system = KKTSystem(H, J, x, g, nlp["lbx"], nlp["ubx"], nlp["lbg"], nlp["ubg"], lam_g, lam_x,
                       bound_slack=BOUND_SLACK if bound_slack is None else bound_slack)
    rhs = -np.vstack([dL[system.free].toarray(), dg[system.rows].toarray()])
    y = system.solve(rhs)
    if y is None or not np.all(np.isfinite(y)):
        raise SolverError("the KKT matrix at the optimum is singular: the sensitivities are not defined (a muscle "
                          "whose force is not determined by the problem); check the solution's convergence")
    dx = np.zeros((x.size, dL.shape[1]))
    dx[system.free] = y[:system.free.size]
    return dx, system.active


def _scaled(params, fields_scale: dict):
    """``params`` with each field multiplied by ``1 + scale`` (``{field: (M,) array}``)."""
    from .parameters import PARAMETER_FIELDS, MuscleTendonParameters

    kw = {f: np.asarray(getattr(params, f), dtype=float) * (1.0 + fields_scale.get(f, 0.0)) for f in PARAMETER_FIELDS}
    return MuscleTendonParameters(names=params.names, sources=dict(params.sources), **kw)


def _trial_rates(x, params, inputs, record, metabolics: dict, nominal=None):
    """The reported rates at the variables ``x`` of the trial's problem with ``params``:
    ``({model: whole-body W/kg}, {model: (M,) muscle W}, SolutionMetabolics or None)``.
    ``nominal``: the :class:`~musclemetab.metabolics.solution.SolutionMetabolics` at the
    optimum, whose muscle masses, slow-twitch fractions and kept nodes are taken as they are
    (for a parameter they do not depend on: not ``F0``, ``lMo``); otherwise
    :func:`~musclemetab.metabolics.solution.metabolics_from_solution` finds them."""
    from ..metabolics.registry import ALL_MODELS
    from ..metabolics.solution import SolutionStates, metabolics_from_solution
    from ..metabolics.whole_body import whole_body_rate
    from .solution import derived_quantities

    M, D, N = len(inputs.muscles), len(inputs.dofs), inputs.n_intervals
    nz = 5 * M + D
    Z = x[:nz * N].reshape(N, nz)
    xl = x[nz * N:nz * N + 3 * M]
    a, lm = np.clip(np.vstack([Z[:, :M], xl[:M]]), 0.0, 1.0), np.vstack([Z[:, M:2 * M], xl[M:2 * M]])
    e = np.clip(np.vstack([Z[:, 3 * M:4 * M], Z[-1:, 3 * M:4 * M]]), 0.0, 1.0)  # a step off a bound held on it
    vm = np.vstack([Z[:, 4 * M + D:], Z[-1:, 4 * M + D:]])
    d = derived_quantities(params, a, lm, vm, inputs.lmt_m)
    arrays = {"excitation": e, "activation": a, "normalized_fiber_length": lm,
              "normalized_fiber_velocity": vm / params.max_contraction_velocity,
              "active_force_length_multiplier": d["active_force_length_multiplier"],
              "force_velocity_multiplier": d["force_velocity_multiplier"],
              "passive_fiber_force_N": d["passive_fiber_force_N"]}
    if nominal is None:
        p = {m: {"max_isometric_force_N": float(params.max_isometric_force_N[i]),
                 "optimal_fiber_length_m": float(params.optimal_fiber_length_m[i]),
                 "max_contraction_velocity": float(params.max_contraction_velocity[i])}
             for i, m in enumerate(params.names)}
        window = record.get("window") or {}
        cycle = window.get("gait_cycle") if isinstance(window, Mapping) else None
        states = SolutionStates(time_s=inputs.mesh_time_s, muscles=tuple(inputs.muscles),
                                states={k: np.asarray(v).T for k, v in arrays.items()}, parameters=p,
                                cycle_s=(float(cycle["start_s"]), float(cycle["end_s"])) if cycle else None,
                                side=record.get("side") if record.get("side") in ("r", "l") else None)
        res = metabolics_from_solution(states, **metabolics)
        rates, wb, t = res.rates, res.whole_body, res.time_s
    else:  # the models and the whole-body rule as metabolics_from_solution applies them
        res, t = None, nominal.time_s
        keep = np.searchsorted(inputs.mesh_time_s, t)
        values = {k: np.asarray(v).T[:, keep] for k, v in arrays.items()}
        values.update(max_isometric_force_N=params.max_isometric_force_N,
                      optimal_fiber_length_m=params.optimal_fiber_length_m,
                      max_contraction_velocity=params.max_contraction_velocity,
                      muscle_mass_kg=nominal.muscle_mass_kg, slow_twitch_fraction=nominal.slow_twitch_fraction)
        options = {k.upper(): v for k, v in (metabolics.get("model_options") or {}).items()}
        rates = {m: ALL_MODELS[m](**values, time_s=t, basal=True, basal_rate_W_per_kg=nominal.basal_rate_W_per_kg,
                                  **options.get(m, {})) for m in nominal.models}
        wb = {m: whole_body_rate(r, t, nominal.body_mass_kg, basal=nominal.basal_rule,
                                 basal_rate_W_per_kg=nominal.basal_rate_W_per_kg,
                                 basal_exponent=nominal.basal_exponent,
                                 cycle_duration_s=nominal.whole_body[m].duration_s,
                                 legs=nominal.whole_body[m].legs) for m, r in rates.items()}
    per = {m: np.trapezoid(np.asarray(rates[m].total_without_basal(), dtype=float), t, axis=-1)
           / wb[m].duration_s for m in rates}
    return {m: wb[m].mean_W_per_kg for m in rates}, per, res


@dataclass
class Sensitivity:
    """Sensitivities of one trial's reported rates: ``parameters`` ``[(parameter, muscle)]``
    (:data:`PARAMETERS`), their values ``values``; per model the nominal whole-body rate (W/kg)
    and its derivatives ``whole_body[model]`` ``(P,)``, the nominal muscle rates (W, cycle
    average without basal heat) and their derivatives ``per_muscle[model]`` ``(M, P)``, all per
    log of the parameter. ``active``: the active set's counts."""

    trial: str
    muscles: tuple
    models: tuple
    parameters: list
    values: np.ndarray
    nominal_whole_body: dict
    nominal_per_muscle: dict
    whole_body: dict
    per_muscle: dict
    active: dict = field(default_factory=dict)
    #: the (polished) optimum the derivatives were taken at
    x: np.ndarray | None = field(default=None, repr=False)

    def derivative(self, model: str, parameter: str, muscle: str, rate: str = "whole_body") -> float:
        """``d rate / d log p`` of ``parameter`` of ``muscle``; ``rate`` ``"whole_body"`` (W/kg) or
        a muscle (W)."""
        try:
            j = self.parameters.index((parameter, muscle))
        except ValueError:
            raise OptionError(f"no sensitivity to {parameter} of {muscle}: computed for "
                              f"{', '.join(sorted({p for p, _ in self.parameters}))} of "
                              f"{len({m for _, m in self.parameters})} muscles") from None
        if rate == "whole_body":
            return float(self.whole_body[model][j])
        return float(self.per_muscle[model][self.muscles.index(rate), j])

    def table(self):
        """Long table, one row per parameter, muscle, model and rate (:data:`SENSITIVITY_COLUMNS`,
        ``parameter_rank`` 0: see :func:`ranked_table`)."""
        import pandas as pd

        frames = []
        P = len(self.parameters)
        names = [p for p, _ in self.parameters]
        owners = [m for _, m in self.parameters]
        for model in self.models:
            rates = ["whole_body", *self.muscles]
            nominal = np.concatenate([[self.nominal_whole_body[model]], self.nominal_per_muscle[model]])
            deriv = np.vstack([self.whole_body[model][None, :], self.per_muscle[model]])  # (1+M, P)
            frames.append(pd.DataFrame({
                "solution": self.trial, "parameter": np.tile(names, len(rates)),
                "muscle": np.tile(owners, len(rates)), "parameter_value": np.tile(self.values, len(rates)), "model": model, "rate": np.repeat(rates, P),
                "rate_value": np.repeat(nominal, P), "d_rate_d_log_p": deriv.reshape(-1)}))
        df = pd.concat(frames, ignore_index=True)
        df["change_per_1pct"] = df["d_rate_d_log_p"] / 100.0
        with np.errstate(divide="ignore", invalid="ignore"):
            df["relative_change_per_1pct"] = np.where(df["rate_value"] != 0, df["change_per_1pct"] / df["rate_value"],
                                                      np.nan)
        df["parameter_rank"] = 0
        return df[list(SENSITIVITY_COLUMNS)]


def _columns(params, parameters):
    """``[(parameter, muscle)]`` checked (default: every parameter of every muscle)."""
    if parameters is None:
        parameters = [(p, m) for p in PARAMETERS for m in params.names]
    out = []
    for p, m in parameters:
        if p not in PARAMETERS:
            raise OptionError(f"unknown muscle parameter {p!r}; use one of {', '.join(PARAMETERS)}")
        if m not in params.names:
            raise OptionError(f"no muscle {m!r} in the problem; its muscles are {', '.join(params.names[:6])} ...")
        out.append((p, m))
    return out


def _guess_of(x, inputs):
    """The :class:`.static_opt.InitialGuess` that is the variables ``x`` of a trial's problem."""
    from .static_opt import InitialGuess

    M, D, N = len(inputs.muscles), len(inputs.dofs), inputs.n_intervals
    nz = 5 * M + D
    Z = np.asarray(x, dtype=float)[:nz * N].reshape(N, nz)
    xl = np.asarray(x, dtype=float)[nz * N:nz * N + 3 * M]
    return InitialGuess(activation=np.vstack([Z[:, :M], xl[:M]]), lm_norm=np.vstack([Z[:, M:2 * M], xl[M:2 * M]]),
                        lm_projected_m=np.vstack([Z[:, 2 * M:3 * M], xl[2 * M:]]), excitation=Z[:, 3 * M:4 * M],
                        reserve=Z[:, 4 * M:4 * M + D], fiber_velocity_lmo_per_s=Z[:, 4 * M + D:])


def polish(inputs, params, goals, guess, *, optimal_reserve_Nm: float = 150.0, trial: str = "trial"):
    """Re-solve a trial's problem from ``guess`` (an optimum) with IPOPT's tolerance
    :data:`POLISH_TOL`, its barrier parameter starting at :data:`POLISH_MU_INIT`: the same
    optimum, its active bounds sharp and its multipliers those of the solve. Returns the
    :class:`.ipopt.ProblemResult`; a failed solve raises :class:`SolverError`."""
    from .ipopt import SolverOptions, solve_problem
    from .transcription import TrialBlock

    options = SolverOptions(stop="authors", tol=POLISH_TOL, optimal_reserve_Nm=optimal_reserve_Nm,
                            ipopt={"mu_init": POLISH_MU_INIT})  # the monotone barrier from a small mu
    res = solve_problem([TrialBlock(trial, inputs, guess)], params, goals.resolved(), options=options)
    if not res.success:
        raise SolverError(f"{trial}: the re-solve at tolerance {POLISH_TOL:g} from the optimum ended with "
                          f"{res.status}; the sensitivities need a converged optimum: check the solution")
    return res


def trial_sensitivity(solution, inputs, params, goals, *, body_mass_kg: float, height_m: float | None,
                      models="all", parameters: Sequence[tuple[str, str]] | None = None, kkt: dict | None = None,
                      optimal_reserve_Nm: float = 150.0, trial: str = "", **metabolic_options) -> "Sensitivity":
    """Sensitivities of the rates of a single-trial ``solution`` (a :class:`.solution.Solution`
    of ``inputs``, ``params``, ``goals``) to ``parameters`` (``[(parameter, muscle)]``, default
    every parameter of :data:`PARAMETERS` of every muscle). ``kkt``: the optimum and its
    multipliers (``ProblemResult.kkt`` of a solve at tolerance :data:`POLISH_TOL`); default: the
    solution polished (:func:`polish`). The rates are those of
    :func:`~musclemetab.metabolics.solution.metabolics_from_solution` with ``body_mass_kg``,
    ``height_m``, ``models`` and ``metabolic_options``, at the polished optimum."""
    import warnings

    from .static_opt import guess_from_solution
    from .transcription import TrialBlock, build_problem

    goals = goals.resolved()  # a solve without EMG: forward unless given
    if goals.fiber_dynamics != "forward":
        raise OptionError("the sensitivities need the forward fiber dynamics; solve without --fiber-dynamics "
                          "backward")
    params = params.subset(inputs.muscles)
    chosen = _columns(params, parameters)
    guess = guess_from_solution(solution, inputs, params, optimal_reserve_Nm)
    if kkt is None:
        kkt = polish(inputs, params, goals, guess, optimal_reserve_Nm=optimal_reserve_Nm, trial=trial or "trial").kkt
    nlp = build_problem([TrialBlock(trial or "trial", inputs, guess)], params, goals,
                        optimal_reserve_Nm=optimal_reserve_Nm, explicit_derivatives=True)
    x = np.asarray(kkt["x"], dtype=float)
    ng = nlp["layout"]["trials"][0]["ng"]
    dL, dg = parameter_derivatives(inputs, params, goals, optimal_reserve_Nm, x, np.asarray(kkt["lam_g"]), ng, chosen)
    dx, active = state_sensitivities(nlp, kkt, dL, dg)
    metabolics = dict(body_mass_kg=body_mass_kg, height_m=height_m, models=models, **metabolic_options)
    record = solution.summary
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a muscle the table cannot place is warned about by the metabolics
        wb0, per0, nominal = _trial_rates(x, params, inputs, record, metabolics)
        model_names = tuple(wb0)
        P, M = len(chosen), len(inputs.muscles)
        dwb = {m: np.zeros(P) for m in model_names}
        dper = {m: np.zeros((M, P)) for m in model_names}
        for j, (p, muscle) in enumerate(chosen):
            scale = np.zeros(M)
            scale[params.names.index(muscle)] = RATE_STEP
            f = PARAMETERS[p]
            fixed = None if p in ("F0", "lMo") else nominal  # the masses follow F0 and lMo
            up = _trial_rates(x + RATE_STEP * dx[:, j], _scaled(params, {f: scale}), inputs, record, metabolics, fixed)
            down = _trial_rates(x - RATE_STEP * dx[:, j], _scaled(params, {f: -scale}), inputs, record, metabolics,
                                fixed)
            for m in model_names:
                dwb[m][j] = (up[0][m] - down[0][m]) / (2 * RATE_STEP)
                dper[m][:, j] = (up[1][m] - down[1][m]) / (2 * RATE_STEP)
    values = np.array([float(getattr(params, PARAMETERS[p])[params.names.index(m)]) for p, m in chosen])
    return Sensitivity(trial=trial, muscles=tuple(inputs.muscles), models=model_names, parameters=chosen,
                       values=values, nominal_whole_body=wb0, nominal_per_muscle=per0, whole_body=dwb,
                       per_muscle=dper, active=active, x=x)


def finite_difference(inputs, params, goals, x, parameter: str, muscle: str, record: dict, *, step: float = 1e-3,
                      optimal_reserve_Nm: float = 150.0, **metabolics) -> tuple[dict, dict]:
    """The check of a sensitivity: ``[R(p (1 + step)) - R(p (1 - step))] / (2 step)`` of the
    whole-body and muscle rates, ``R`` at the optimum of two re-solves with ``parameter`` of
    ``muscle`` scaled, each from the optimum ``x`` (:func:`polish`). ``({model: W/kg},
    {model: (M,) W})`` per log of the parameter; ``metabolics`` as :func:`trial_sensitivity`'s."""
    import warnings

    params = params.subset(inputs.muscles)
    _columns(params, [(parameter, muscle)])  # the names checked
    out = []
    for sign in (1.0, -1.0):
        scale = np.zeros(len(params.names))
        scale[params.names.index(muscle)] = sign * step
        scaled = _scaled(params, {PARAMETERS[parameter]: scale})
        res = polish(inputs, scaled, goals, _guess_of(x, inputs), optimal_reserve_Nm=optimal_reserve_Nm,
                     trial=f"{parameter} of {muscle} x {1 + sign * step:g}")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out.append(_trial_rates(res.kkt["x"], scaled, inputs, record, metabolics))
    wb = {m: (out[0][0][m] - out[1][0][m]) / (2 * step) for m in out[0][0]}
    per = {m: (out[0][1][m] - out[1][1][m]) / (2 * step) for m in out[0][1]}
    return wb, per


@dataclass
class TrialProblem:
    """A solved trial's problem rebuilt from its solution (:func:`problem_of_solution`): the
    solution, the geometry, inverse dynamics and IK times its inputs came from, the mesh inputs,
    the parameters, goals and reserve of the solve."""

    solution: object
    geometry: object
    id_time_s: np.ndarray
    id_moments_Nm: np.ndarray
    ik_time_s: np.ndarray
    inputs: object
    params: object
    goals: object
    optimal_reserve_Nm: float
    filter_inputs: bool
    mesh_frequency_hz: float


def sensitivity_refusal(summary) -> str | None:
    """Why the sensitivities of a solve with this ``summary.json`` (a mapping) are not computed
    from its folder, or ``None``: they are those of the effort workflows, forward fiber dynamics."""
    workflow = (summary.get("workflow") or {}).get("name", "custom")
    opts = summary.get("solver_options") or {}
    if summary.get("emg") or "emg" in str(workflow).lower() or opts.get("energy") or summary.get("energy_goal"):
        return (f"the sensitivities are computed for the effort workflows (effort-gen, -cal, -ten); this solve "
                f"({workflow}) has EMG or energy goals")
    if summary.get("fiber_dynamics", "forward") != "forward":
        return "the sensitivities need the forward fiber dynamics"
    return None


def problem_of_solution(solution, cache_dir: str | os.PathLike | None = None) -> TrialProblem:
    """The problem of a single-trial effort solve (EFFORT-GEN/CAL/TEN): from the
    :class:`~.problem.Problem` the solution keeps (``solution.problem``, a solve of this
    process) with the solution's parameters, else rebuilt from its solution folder (or
    :class:`.solution.Solution`): the input files its ``summary.json`` names, its window,
    muscles, DOFs, mesh and parameters. The geometry comes from the cache (OpenSim only when it
    is not there)."""
    from ..geometry import compute_geometry
    from ..io import read_table
    from .inputs import GeometryArrays, read_inverse_dynamics, read_kinematics
    from .solution import Solution
    from .solve import prepare_trial
    from .transcription import Goals

    where = str(solution) if isinstance(solution, (str, os.PathLike)) else "the solution"
    if isinstance(solution, (str, os.PathLike)):
        solution = Solution.load(solution)
    rec = solution.summary
    why = sensitivity_refusal(rec)
    if why is not None:
        remedy = ("call musclemetab.redundancy.sensitivity.trial_sensitivity with its goals" if "goals" in why
                  else "solve without --fiber-dynamics backward")
        raise OptionError(f"{where}: {why}; {remedy}")
    if getattr(solution, "problem", None) is not None:
        return _problem_of_problem(solution, where)
    files = rec.get("inputs") or {}
    missing = [k for k in ("model", "ik", "id") if not files.get(k) or not Path(files[k]).is_file()]
    if missing:
        raise DataMismatchError(f"{where}: the {name_list(missing)} file(s) its summary.json names "
                                f"({name_list([files.get(k) for k in missing])}) cannot be found; the sensitivities "
                                "rebuild the problem from them: solve again where the files are")
    dofs = list(solution.dofs)
    ik_table = read_table(files["ik"])
    ik_time, _ = read_kinematics(ik_table, dofs, check_units=False)
    t0, t1 = (float(v) for v in rec["time_window_s"])
    keep = np.flatnonzero((ik_time >= t0 - 1e-6) & (ik_time <= t1 + 1e-6))
    geo = compute_geometry(files["model"], ik_table, dofs=dofs, side=rec.get("side", "r"), cache_dir=cache_dir)
    absent = [m for m in solution.muscles if m not in geo.muscles]
    if absent:
        raise DataMismatchError(f"{where}: the model has no muscle {name_list(absent)} of the solution")
    cols = [list(geo.muscles).index(m) for m in solution.muscles]
    rows = [list(geo.dofs).index(d) for d in dofs]
    geometry = GeometryArrays(np.asarray(geo.time)[keep], list(solution.muscles), dofs,
                              np.asarray(geo.lmt_m)[keep][:, cols],
                              np.asarray(geo.moment_arms_m)[keep][:, rows][:, :, cols])
    id_time, id_moments = read_inverse_dynamics(read_table(files["id"]), dofs)
    device = rec.get("assistance")
    if device:  # an assisted solve: the muscles' moments are the ID's less the device's (musclemetab.redundancy.assistance)
        from .assistance import read_assistance

        id_moments = id_moments - read_assistance(device["file"]).torque_at(id_time, dofs, device["gain"],
                                                                            tuple(device["cycle_s"]))
    prep = rec.get("input_preparation") or {}
    filter_inputs = prep.get("filter", "") != "none"
    mesh = float(prep.get("mesh_intervals_per_second", 100.0))
    inputs, params, _ = prepare_trial(geometry, solution.parameters, id_time, id_moments, ik_time_s=ik_time[keep],
                                      check_units=False, filter_inputs=filter_inputs, mesh_frequency_hz=mesh)
    if tuple(inputs.muscles) != tuple(solution.muscles) or inputs.n_intervals != solution.n_intervals:
        raise DataMismatchError(f"{where}: the rebuilt problem ({len(inputs.muscles)} muscles, {inputs.n_intervals} "
                                f"intervals) is not the solved one ({len(solution.muscles)}, {solution.n_intervals}); "
                                "the input files changed since the solve: solve again")
    opts = rec.get("solver_options") or {}
    goals = Goals(**{k: float(opts[k]) for k in ("w_activation", "w_reserve", "w_velocity") if k in opts}).resolved()
    return TrialProblem(solution=solution, geometry=geometry, id_time_s=id_time, id_moments_Nm=id_moments,
                        ik_time_s=ik_time[keep], inputs=inputs, params=params, goals=goals,
                        optimal_reserve_Nm=float(rec.get("optimal_reserve_Nm", 150.0)),
                        filter_inputs=filter_inputs, mesh_frequency_hz=mesh)


def _problem_of_problem(solution, where: str) -> TrialProblem:
    """:func:`problem_of_solution` from ``solution.problem``: its trial's geometry and moments
    restricted to the solution's muscles and DOFs, the mesh inputs with the solution's parameters."""
    from .inputs import GeometryArrays
    from .solve import prepare_trial
    from .transcription import Goals

    problem = solution.problem
    trial = problem.trials[0]
    g = trial.geometry
    absent = [m for m in solution.muscles if m not in g.muscles]
    if len(problem.trials) != 1 or absent:
        raise DataMismatchError(f"{where}: its problem is not the solution's (other trials or muscles)")
    cols = [list(g.muscles).index(m) for m in solution.muscles]
    rows = [list(g.dofs).index(d) for d in solution.dofs]
    geometry = GeometryArrays(np.asarray(g.time), list(solution.muscles), list(solution.dofs),
                              np.asarray(g.lmt_m)[:, cols], np.asarray(g.moment_arms_m)[:, rows][:, :, cols])
    moments = np.asarray(trial.id_moments_Nm, dtype=float).reshape(len(trial.id_time_s), -1)[:, rows]
    inputs, params, _ = prepare_trial(geometry, solution.parameters, trial.id_time_s, moments,
                                      ik_time_s=trial.ik_time_s, check_units=False,
                                      mesh_frequency_hz=problem.mesh_frequency_hz)
    return TrialProblem(solution=solution, geometry=geometry, id_time_s=trial.id_time_s, id_moments_Nm=moments,
                        ik_time_s=trial.ik_time_s, inputs=inputs, params=params,
                        goals=Goals(**problem.goals.effort_weights()).resolved(),
                        optimal_reserve_Nm=problem.options.optimal_reserve_Nm, filter_inputs=True,
                        mesh_frequency_hz=problem.mesh_frequency_hz)


def sensitivity_of_folder(folder, *, body_mass_kg: float, height_m: float | None, models="all",
                          parameters=None, cache_dir=None, trial: str | None = None, **metabolic_options) -> Sensitivity:
    """:func:`trial_sensitivity` of a solution folder (:func:`problem_of_solution`)."""
    prob = problem_of_solution(folder, cache_dir=cache_dir)
    return trial_sensitivity(prob.solution, prob.inputs, prob.params, prob.goals, body_mass_kg=body_mass_kg,
                             height_m=height_m, models=models, parameters=parameters,
                             optimal_reserve_Nm=prob.optimal_reserve_Nm,
                             trial=trial if trial is not None else Path(folder).name, **metabolic_options)


def ranked_table(sensitivities: Sequence[Sensitivity], top: int | None = None):
    """The parameters that move a result most: the rows of each :meth:`Sensitivity.table`
    ranked within each solution, model and rate by ``|d_rate_d_log_p|`` (``parameter_rank`` 1:
    largest), the whole-body rows first; ``top`` keeps that many rows of each solution, model
    and rate."""
    import pandas as pd

    df = pd.concat([s.table() for s in sensitivities], ignore_index=True)
    df["_abs"] = df["d_rate_d_log_p"].abs()
    df["_wb"] = df["rate"] != "whole_body"
    df = df.sort_values(["solution", "model", "_wb", "rate", "_abs"], ascending=[True, True, True, True, False],
                        kind="stable")
    df["parameter_rank"] = df.groupby(["solution", "model", "rate"]).cumcount() + 1
    if top is not None:
        df = df[df["parameter_rank"] <= int(top)]
    return df.drop(columns=["_abs", "_wb"]).reset_index(drop=True)


def write_sensitivity(sensitivities: Sequence[Sensitivity], out: str | os.PathLike, top: int | None = None) -> Path:
    """Write :func:`ranked_table` as ``sensitivity.csv`` in the folder ``out`` (or to the file
    ``out`` when it ends in ``.csv``), listed in the folder's ``.musclemetab-files`` (a file the
    package did not write is not replaced, :func:`musclemetab.io.atomic.check_replaceable`);
    returns its path."""
    from ..io.atomic import atomic_write_text

    out = Path(out)
    path = out if out.suffix == ".csv" else out / SENSITIVITY_CSV
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, ranked_table(sensitivities, top).to_csv(index=False, float_format="%.10g"), mark=True)
    return path


def write_folder_sensitivity(folder, out: str | os.PathLike, *, names: Sequence[str] | None = None,
                             trial: str | None = None, cache_dir=None, **options) -> tuple[Path, Sensitivity]:
    """``sensitivity.csv`` (:func:`write_sensitivity`) in ``out`` of the solution ``folder``: each
    parameter of ``names`` (default every one of :data:`PARAMETERS`) of every muscle of the solve,
    ``options`` those of :func:`trial_sensitivity` (body mass, height, models, metabolic options).
    ``trial`` names the solution in the table (default: the folder's name). Returns the file's
    path and the :class:`Sensitivity`."""
    prob = problem_of_solution(folder, cache_dir=cache_dir)
    pairs = [(n, m) for n in (PARAMETERS if names is None else names) for m in prob.inputs.muscles]
    sens = trial_sensitivity(prob.solution, prob.inputs, prob.params, prob.goals, parameters=pairs,
                             optimal_reserve_Nm=prob.optimal_reserve_Nm,
                             trial=trial if trial is not None else Path(folder).resolve().name, **options)
    return write_sensitivity([sens], out), sens
