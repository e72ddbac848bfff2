"""Doubts of estimated parameters: factors on their bounds, parameters no measurement
informs, and the identifiability at the optimum (``docs/problem.md``, "Doubts of the estimates").

**Identifiability.** At the optimum ``x*`` of the estimation NLP (multipliers ``lam_g``,
``lam_x``) the active set holds the equality rows, the inequality rows (EMG bounds) whose
multiplier exceeds their slack, and the variable bounds likewise; the scale factors themselves
are always kept free. With ``H`` the Hessian of the Lagrangian ``f + lam_g' g`` on the free
variables and ``A`` the Jacobian of the active rows, the KKT matrix ``K = [[H, A'], [A, 0]]``
is solved for the unit vectors of the parameters:
``C = (K^-1)_pp = P' Z (Z' H Z)^-1 Z' P``, the inverse of the reduced Hessian (``Z`` a basis of
the null space of ``A``) on the parameters, i.e. of the Hessian of the objective minimised over
all other variables. The parameters' rows and columns of ``K`` are dense (a factor enters every
node of every trial), so they are taken apart: with ``K = [[B, E], [E', K_pp]]`` (``B`` the KKT
matrix with the parameters held fixed, factorised once by sparse LU) ``C = S^-1`` where ``S = K_pp
- E' B^-1 E`` is the Schur complement, as small as the number of parameters (block elimination:
the same ``C`` as a factorisation of the whole ``K``, whose fill the dense rows more than double). With the tracked data weighted as inverse variances up to a common factor
``s^2`` (the objective's tracking terms are ``J_track = 1/2 sum_j c_j r_j^2``, ``c_j = 2 w /
(n N)``), the covariance of the parameters is::

    Cov = s^2 C,    s^2 = 2 J_track / (n_data - n_p)

(``n_data`` tracked values: nodes times tracked muscles, summed over trials and kinds;
``n_p`` estimated parameters), the standard error ``SE_i = sqrt(Cov_ii)`` and the correlation
``R_ij = C_ij / sqrt(C_ii C_jj)`` (independent of ``s^2``). The reduced Hessian is reported
near singular when ``C`` has a non-positive diagonal (no strict minimum along a parameter) or
the reciprocal condition number of ``C`` scaled to unit diagonal (that of ``R``) is below
:data:`SINGULAR_RCOND`; a pair is poorly identifiable together when ``|R_ij| >=``
:data:`CORRELATION_THRESHOLD`, and the factors are collinear as a whole when the condition index
of ``R`` (``sqrt`` of its largest over its smallest eigenvalue) exceeds :data:`CONDITION_INDEX_LIMIT`.

**Factors on a bound.** A factor within :data:`BOUND_TOLERANCE` of its bounds' width of a bound
gets no standard error (the estimate cannot move beyond the bound, so ``+- SE`` would claim values
the problem excludes) but a one-sided 95 % interval from the bound inwards, ``[b, b + d]`` (lower
bound) or ``[b - d, b]``: ``d`` where the profile of the objective, to second order, rises by
``s^2 z^2/2`` (``z = 1.645``): ``g d + h d^2/2 = s^2 z^2/2`` with ``h = 1/C_ii`` its curvature and
``g`` its slope inwards at the bound (the bound's multiplier, IPOPT's ``lam_x``), clipped to the
other bound. Without a slope it is ``z SE``; the slope shortens it.

**Validation.** :func:`validation_warnings` turns the fit of a validation re-solve
(:func:`tracking_fit`) into warning lines: a fiber length off its measurement by more than
:data:`VALIDATION_RMS_MM` (RMS) or correlating below :data:`VALIDATION_MIN_R`, an excitation
correlating with its scaled EMG below :data:`VALIDATION_MIN_R`.
"""

from __future__ import annotations

import warnings
from typing import Sequence

import numpy as np

from ..errors import MusclemetabWarning, OptionError

__all__ = ["CORRELATION_THRESHOLD", "CONDITION_INDEX_LIMIT", "VALIDATION_RMS_MM", "VALIDATION_MIN_R",
           "validation_warnings", "warn_validation", "one_sided_interval", "SINGULAR_RCOND", "BOUND_TOLERANCE", "factors_on_bounds", "informing_muscles",
           "uninformed_factors", "check_informed", "identifiability", "warn_identifiability", "warn_on_bounds",
           "tracking_fit", "reduced_inverse_hessian", "correlation", "KKTSystem", "lagrangian_derivatives"]

#: |correlation| from which two estimated parameters are reported as not identifiable together
#: (on the synthetic problem of ``tests/test_estimate.py`` the lMo and lTs factors of one muscle
#: correlate at 0.94 and their lMo factors come back 6-8 % off the truth; on the example's
#: ultrasound-shaped estimate they correlate at 0.88, which 0.9 let pass: 0.8, the usual mark
#: of strong collinearity between two regressors)
CORRELATION_THRESHOLD = 0.8
#: condition index of the factors' correlation matrix (sqrt of largest / smallest eigenvalue)
#: above which the estimated factors are reported collinear as a whole (Belsley, Kuh and Welsch
#: 1980, Regression Diagnostics: indices above 30 mark strong dependencies)
CONDITION_INDEX_LIMIT = 30.0
#: one-sided 95 % normal quantile of the interval of a factor on its bound
ONE_SIDED_Z = 1.6448536269514722
#: RMS misfit (mm) of a validation re-solve's fiber length above which it is warned: about 10 %
#: of the triceps surae's and tibialis anterior's optimal fiber lengths (about 40-70 mm), this
#: package's choice
VALIDATION_RMS_MM = 5.0
#: Pearson r of a validation re-solve's fiber length (or excitation against the EMG) below which
#: it is warned (this package's choice)
VALIDATION_MIN_R = 0.7
#: reciprocal condition number of the parameters' correlation matrix below which the reduced
#: Hessian is reported near singular
SINGULAR_RCOND = 1e-8
#: a factor within this fraction of its bounds' width of a bound is reported on the bound
BOUND_TOLERANCE = 1e-3


def factors_on_bounds(factors: dict, bounds: dict, tolerance: float = BOUND_TOLERANCE) -> list[dict]:
    """The factors (``{kind: {muscle: factor}}``) within ``tolerance`` x (high - low) of a bound
    of their kind (``bounds``: ``{kind: (low, high)}``); a kind whose bounds are equal (a factor
    held fixed) is left out. ``[{kind, muscle, factor, bound, side}]``."""
    out = []
    for kind, by_muscle in factors.items():
        if kind not in bounds:
            continue
        lo, hi = (float(b) for b in bounds[kind])
        if hi <= lo:
            continue
        tol = tolerance * (hi - lo)
        for m, v in by_muscle.items():
            for side, b in (("lower", lo), ("upper", hi)):
                if abs(float(v) - b) <= tol:
                    out.append({"kind": kind, "muscle": m, "factor": float(v), "bound": b, "side": side})
    return out


def warn_on_bounds(on_bounds: Sequence[dict]) -> None:
    """One warning per factor on a bound (:func:`factors_on_bounds`; a factor coupled over
    several muscles once, naming them)."""
    shared = {}
    for b in on_bounds:
        shared.setdefault((b["kind"], b["factor"], b["side"]), []).append(b)
    for group in shared.values():
        b = dict(group[0], muscle=", ".join(g["muscle"] for g in group))
        option = "--emg-scale-bounds LOW:HIGH" if b["kind"] == "emg_scale" else f"--bounds {b['kind']}=LOW:HIGH"
        warnings.warn(f"the estimated {b['kind']} factor of {b['muscle']} is on its {b['side']} bound "
                      f"({b['factor']:.4g}, bound {b['bound']:g}): the data ask for a value beyond it; widen the "
                      f"bounds ({option}) or check the data and the estimated muscles", MusclemetabWarning,
                      stacklevel=3)


def informing_muscles(trials) -> set:
    """Muscles with a measurement of their own: ultrasound fiber lengths or EMG in some trial."""
    return {m for t in trials for m in (*getattr(t, "fiber_muscles", ()), *t.emg_muscles)}


def uninformed_factors(trials, specs) -> list[tuple[str, str]]:
    """``[(kind, muscle)]`` of the estimated muscle-tendon factors no measurement informs.

    A factor of a muscle is *informed* when the muscle has fiber lengths or EMG of its own in
    some trial, or its factor is coupled (one shared factor of the same kind) to one of a muscle
    that has. Otherwise only the effort goal and the moments tell its value, and the estimate
    is the effort optimum, not a measurement's."""
    from .transcription import _group_index

    have = informing_muscles(trials)
    out = []
    for s in specs:
        if s.kind == "emg_scale":
            continue
        group = _group_index(len(s.muscles), s.couplings)
        informed_groups = {group[i] for i, m in enumerate(s.muscles) if m in have}
        out += [(s.kind, m) for i, m in enumerate(s.muscles) if group[i] not in informed_groups]
    return out


def check_informed(trials, specs, action: str = "error", remedy: str | None = None) -> list[tuple[str, str]]:
    """Refuse (``action="error"``) or warn (``"warn"``) about factors no measurement informs
    (:func:`uninformed_factors`); returns them. ``remedy`` replaces the advice of ``estimate``
    (``{kind}`` and ``{muscle}`` are filled in)."""
    bad = uninformed_factors(trials, specs)
    if not bad:
        return bad
    remedy = remedy or ("give its measurements, couple it (--couple {kind}:{muscle},MEASURED_MUSCLE) or drop it "
                        "from --estimate")
    for kind, m in bad:
        text = (f"the {kind} factor of {m} is informed by no measurement: {m} has no fiber lengths or EMG of its "
                f"own and is not coupled to a measured muscle; " + remedy.format(kind=kind, muscle=m))
        if action == "error":
            raise OptionError(text)
        warnings.warn(text, MusclemetabWarning, stacklevel=3)
    return bad


def _labels(specs, layout) -> tuple[list[str], list[int]]:
    """Label and the position in ``x`` of each estimated variable (a coupled group is one)."""
    from .transcription import _group_index

    full = [(s.kind, m) for s in specs for m in s.muscles]
    p_index, pairs, P0 = layout["p_index"], layout["pairs"], layout["P0"]
    if p_index is None:  # coupling by constraint rows: one representative of each group
        p_index = _group_index(len(full), pairs)
        col = {g: full.index(full[p_index.index(g)]) for g in set(p_index)}
    else:
        col = {g: g for g in set(p_index)}
    labels, cols = [], []
    for g in sorted(set(p_index)):
        members = [full[i] for i in range(len(full)) if p_index[i] == g]
        labels.append(f"{members[0][0]}:{','.join(m for _, m in members)}")
        cols.append(P0 + col[g])
    return labels, cols


class KKTSystem:
    """The KKT matrix ``K = [[H_ff, A'], [A, 0]]`` at a KKT point, factorised once (sparse LU).

    ``free``: the variables kept free (those not on an active bound), ``rows``: the active
    constraint rows (equalities, and inequalities whose slack is below their multiplier) that
    hold a free variable; :meth:`solve` solves ``K y = rhs`` (``None`` when ``K`` is exactly
    singular). ``active``: ``{"constraint_rows", "variable_bounds"}``, the active counts.
    ``bound_slack``: a variable closer than this to a bound is on it whatever its multiplier
    (a weakly active bound, whose multiplier vanishes with the barrier parameter).

    ``apart``: free variables with dense rows and columns (e.g. estimated parameters) kept out of
    the sparse factorisation: ``K = [[B, E], [E', K_aa]]`` over (the others, these), ``B``
    factorised and the Schur complement ``S = K_aa - E' B^-1 E`` formed once; ``K y = r`` is then
    solved by block elimination, ``y_a = S^-1 (r_a - E' B^-1 r_b)``, ``y_b = B^-1 (r_b - E y_a)``.
    Where ``B`` is exactly singular (a constraint row on those variables alone) ``K`` is factorised
    whole."""

    def __init__(self, H, J, x, g, lbx, ubx, lbg, ubg, lam_g, lam_x, keep_free=(), bound_slack: float = 0.0,
                 apart=()):
        import scipy.sparse as sp

        slack_g = np.minimum(np.abs(g - lbg), np.abs(ubg - g))
        rows = np.flatnonzero((lbg == ubg) | (slack_g <= np.abs(lam_g)))
        slack_x = np.minimum(np.abs(x - lbx), np.abs(ubx - x))
        fixed = (lbx == ubx) | (slack_x <= np.abs(lam_x)) | (slack_x <= bound_slack)
        fixed[list(keep_free)] = False
        self.free = np.flatnonzero(~fixed)
        self.position = {int(c): k for k, c in enumerate(self.free)}
        A = sp.csr_matrix(J)[rows][:, self.free]
        nonempty = np.diff(A.indptr) > 0  # rows of bound variables alone (e.g. a = e = 0) hold nothing
        self.rows, A = rows[nonempty], A[nonempty]
        H = sp.csc_matrix(H)
        self.matrix = sp.bmat([[H[self.free][:, self.free], A.T], [A, None]], format="csc")
        self.active = {"constraint_rows": int(self.rows.size), "variable_bounds": int(fixed.sum())}
        self._schur = None
        if len(apart):
            self._schur = self._split([self.position[int(c)] for c in apart])
        self._lu = None if self._schur is not None else _factorised(self.matrix)

    def _split(self, apart: list[int]):
        """``(others, apart, LU of B, B^-1 E, E, S)`` of the block elimination, or ``None`` where
        ``B`` is exactly singular."""
        K = self.matrix
        a = np.asarray(apart, dtype=int)
        b = np.setdiff1d(np.arange(K.shape[0]), a)
        lu = _factorised(K[b][:, b].tocsc())
        if lu is None:
            return None
        E = K[b][:, a].toarray()
        Y = lu.solve(E)
        S = K[a][:, a].toarray() - E.T @ Y
        return b, a, lu, Y, E, S

    @property
    def size(self) -> int:
        return self.matrix.shape[0]

    def solve(self, rhs: np.ndarray) -> np.ndarray | None:
        """``K^-1 rhs`` (``rhs`` of :attr:`size` rows), or ``None`` when ``K`` is singular."""
        rhs = np.asarray(rhs, dtype=float)
        if self._schur is None:
            return None if self._lu is None else self._lu.solve(rhs)
        b, a, lu, Y, E, S = self._schur
        z = lu.solve(rhs[b])
        try:
            ya = np.linalg.solve(S, rhs[a] - E.T @ z)
        except np.linalg.LinAlgError:  # exactly singular Schur complement: K singular
            return None
        y = np.empty_like(rhs)
        y[a] = ya
        y[b] = z - Y @ ya
        return y


def _factorised(matrix):
    """SuperLU factors of a sparse square ``matrix``, or ``None`` when it is exactly singular."""
    from scipy.sparse.linalg import splu

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return splu(matrix)
    except RuntimeError:  # exactly singular
        return None


def lagrangian_derivatives(nlp: dict, x, lam_g):
    """The full symmetric Hessian of the Lagrangian ``f + lam_g' g``, the constraint Jacobian
    (SciPy sparse) and the constraint values at ``x`` of a problem built with explicit
    derivatives (:func:`.transcription.build_problem`)."""
    import casadi as ca
    import scipy.sparse as sp

    def scipy_matrix(m):
        m = ca.DM(m)
        r, c = m.sparsity().get_triplet()
        return sp.csc_matrix((np.asarray(m.nonzeros()).reshape(-1), (r, c)), shape=m.shape)

    Hu = scipy_matrix(nlp["hess_lag"](x, nlp["p_values"], 1.0, lam_g))
    H = (Hu + Hu.T - sp.diags(Hu.diagonal())).tocsc()
    g, J = nlp["jac_g"](x, nlp["p_values"])
    return H, scipy_matrix(J), np.asarray(g).reshape(-1)


def reduced_inverse_hessian(H, J, x, g, lbx, ubx, lbg, ubg, lam_g, lam_x, columns) -> tuple[np.ndarray, dict]:
    """``(K^-1)_pp``: the inverse of the reduced Hessian on the variables ``columns`` at a KKT
    point (see the module docstring). ``H``: the full symmetric Hessian of the Lagrangian and
    ``J`` the constraint Jacobian (SciPy sparse), ``g`` the constraint values; the other
    arguments as IPOPT's. The variables of ``columns`` are kept free, and taken apart of the
    sparse factorisation (Schur complement); other variables on a bound
    (slack below its multiplier) are fixed, and constraint rows left without a free variable
    dropped (:class:`KKTSystem`). NaN where the KKT matrix is singular. Returns ``(C,
    {"constraint_rows", "variable_bounds"})`` (the active counts)."""
    kkt = KKTSystem(H, J, x, g, lbx, ubx, lbg, ubg, lam_g, lam_x, keep_free=columns, apart=columns)
    rhs = np.zeros((kkt.size, len(columns)))
    for j, c in enumerate(columns):
        rhs[kkt.position[int(c)], j] = 1.0
    X = kkt.solve(rhs)
    if X is None:
        return np.full((len(columns), len(columns)), np.nan), kkt.active
    C = X[[kkt.position[int(c)] for c in columns], :]
    return 0.5 * (C + C.T), kkt.active


def correlation(C: np.ndarray) -> tuple[np.ndarray | None, float]:
    """The correlation matrix of ``C`` and its reciprocal condition number (smallest over
    largest eigenvalue); ``(None, 0)`` when ``C`` is not finite or has a non-positive diagonal."""
    d = np.diag(C)
    if not (np.all(np.isfinite(C)) and np.all(d > 0)):
        return None, 0.0
    R = C / np.sqrt(np.outer(d, d))
    ev = np.linalg.eigvalsh(R)
    return R, float(max(ev[0], 0.0) / ev[-1])


def identifiability(trials, params, goals, specs, result, *, optimal_reserve_Nm: float = 150.0,
                    coupling: str = "shared", threshold: float = CORRELATION_THRESHOLD) -> dict:
    """Standard errors and correlations of the estimated factors at the optimum of ``result``
    (a :class:`~.ipopt.ProblemResult` of the same problem; see the module docstring). A factor
    held by equal bounds is not an estimate and is left out.

    Returns ``{method, parameters, factor, standard_error, correlation, residual_scale,
    reduced_hessian_rcond, near_singular, correlated_pairs, threshold, active}``."""
    from .transcription import build_problem

    kkt = result.kkt
    if not kkt or "lam_g" not in kkt:
        raise OptionError("the identifiability needs the optimum's multipliers; give the ProblemResult of "
                          "solve_problem")
    nlp = build_problem(trials, params, goals, specs, optimal_reserve_Nm=optimal_reserve_Nm, coupling=coupling,
                        explicit_derivatives=True)
    x, lam_g, lam_x = kkt["x"], kkt["lam_g"], kkt["lam_x"]
    H, J, g = lagrangian_derivatives(nlp, x, lam_g)
    lbx, ubx = nlp["lbx"], nlp["ubx"]
    labels, pcols = _labels(specs, nlp["layout"])
    keep = [k for k, c in enumerate(pcols) if lbx[c] < ubx[c]]
    labels, pcols = [labels[k] for k in keep], [pcols[k] for k in keep]
    C, active = reduced_inverse_hessian(H, J, x, g, lbx, ubx, nlp["lbg"], nlp["ubg"], lam_g, lam_x, pcols)
    n_data = sum(t.inputs.n_intervals * (len(t.fiber_muscles) * (goals.w_fiber_length > 0)
                                         + len(t.emg_muscles) * (goals.w_emg > 0)) for t in trials)
    j_track = sum(v for terms in result.objective_terms.values() for k, v in terms.items()
                  if k in ("fiber_length_tracking", "emg_tracking"))
    s2 = 2.0 * j_track / max(n_data - len(pcols), 1)
    R, rcond = correlation(C)
    pairs = [{"parameters": [labels[i], labels[j]], "correlation": float(R[i, j])}
             for i in range(len(labels)) for j in range(i + 1, len(labels))
             if R is not None and abs(R[i, j]) >= threshold]
    index = float(np.sqrt(1.0 / rcond)) if rcond > 0 else float("inf")
    on_bound = {}
    for k, (lab, c) in enumerate(zip(labels, pcols)):
        lo, hi = float(lbx[c]), float(ubx[c])
        for side, b in (("lower", lo), ("upper", hi)):
            if abs(float(x[c]) - b) <= BOUND_TOLERANCE * (hi - lo):
                curvature = 1.0 / C[k, k] if R is not None else float("nan")
                on_bound[lab] = one_sided_interval(b, side, (lo, hi), curvature, abs(float(lam_x[c])), s2)
    return {
        "method": "inverse of the reduced Hessian of the Lagrangian on the parameters, (K^-1)_pp, scaled by "
                  "s^2 = 2 J_track/(n_data - n_p) (docs/problem.md)",
        "parameters": labels, "threshold": threshold, "active": active,
        "factor": {lab: float(x[c]) for lab, c in zip(labels, pcols)},
        "standard_error": {lab: float(np.sqrt(s2 * C[k, k])) if R is not None and lab not in on_bound else None
                           for k, lab in enumerate(labels)},
        "on_bound": on_bound,
        "correlation": R.tolist() if R is not None else None,
        "residual_scale": {"s2": s2, "tracking_objective": j_track, "n_data": int(n_data), "n_parameters": len(pcols)},
        "reduced_hessian_rcond": rcond, "near_singular": bool(R is None or rcond < SINGULAR_RCOND),
        "correlated_pairs": pairs, "condition_index": index,
        "condition_index_limit": CONDITION_INDEX_LIMIT,
        "collinear": bool(R is not None and index > CONDITION_INDEX_LIMIT),
    }


def one_sided_interval(bound: float, side: str, bounds: tuple[float, float], curvature: float, slope: float,
                       s2: float, z: float = ONE_SIDED_Z) -> dict:
    """The one-sided 95 % interval of a factor on its ``side`` (``"lower"``/``"upper"``) ``bound``
    (module docstring): ``{bound, side, limit, interval}``, ``limit`` ``None`` when the curvature
    is not positive and finite (no interval: the data do not bound the factor from inside)."""
    out = {"bound": float(bound), "side": side, "limit": None, "interval": None}
    if not (np.isfinite(curvature) and curvature > 0):
        return out
    g, h, target = max(float(slope), 0.0), float(curvature), 0.5 * float(s2) * z * z
    d = (-g + np.sqrt(g * g + 2.0 * h * target)) / h
    lo, hi = bounds
    limit = float(min(bound + d, hi) if side == "lower" else max(bound - d, lo))
    out.update(limit=limit, interval=sorted([float(bound), limit]))
    return out


def warn_identifiability(report: dict, remedy: str = "fix one of them (drop it from --estimate)") -> None:
    """One warning per correlated pair and one for a near-singular reduced Hessian (``remedy``:
    what to do about a pair, besides adding data that tells them apart)."""
    for p in report["correlated_pairs"]:
        a, b = p["parameters"]
        warnings.warn(f"{a} and {b} are not identifiable together: correlation {p['correlation']:+.3f} at the optimum "
                      f"(|r| >= {report['threshold']:g}); {remedy} or add data that tells them apart",
                      MusclemetabWarning, stacklevel=3)
    if report.get("collinear"):
        warnings.warn(f"the estimated factors are collinear: condition index {report['condition_index']:.3g} of their "
                      f"correlation matrix (above {report['condition_index_limit']:g}); some combination of them is "
                      "poorly determined by the data; estimate fewer parameters or couple them", MusclemetabWarning,
                      stacklevel=3)
    for lab, b in (report.get("on_bound") or {}).items():
        if b["limit"] is not None:
            warnings.warn(f"{lab} is on its {b['side']} bound {b['bound']:g}: no symmetric standard error; one-sided "
                          f"95 % interval {b['interval'][0]:.4g} ... {b['interval'][1]:.4g}", MusclemetabWarning,
                          stacklevel=3)
    if report["near_singular"]:
        warnings.warn(f"the reduced Hessian of the estimation is near singular (reciprocal condition "
                      f"{report['reduced_hessian_rcond']:.2g}): some combination of the estimated parameters is not "
                      "determined by the data; estimate fewer parameters or couple them", MusclemetabWarning,
                      stacklevel=3)


def tracking_fit(solution, fiber_lengths: dict | None = None, emg: dict | None = None) -> dict:
    """RMS error and Pearson r of a solution against measured data at its nodes ``0 ... N-1``:
    ``fiber_lengths`` ``{muscle: lengths m (N,)}`` against ``l~M lMo`` (RMS in mm) and ``emg``
    ``{muscle: scaled EMG (N,)}`` against the excitations. ``{"fiber_length": {muscle: {rms_mm,
    r}}, "emg": {muscle: {rms, r}}}``."""
    p = solution.parameters
    out = {}
    for kind, data in (("fiber_length", fiber_lengths or {}), ("emg", emg or {})):
        if not data:
            continue
        fit = {}
        for m, meas in data.items():
            meas = np.asarray(meas, dtype=float)
            n = meas.size
            j = solution.muscles.index(m)
            if kind == "fiber_length":
                model = solution.lm_norm[:n, j] * p.optimal_fiber_length_m[p.names.index(m)]
                scale, key = 1000.0, "rms_mm"
            else:
                model, scale, key = solution.excitation[:n, j], 1.0, "rms"
            err = model - meas
            r = float(np.corrcoef(model, meas)[0, 1]) if np.std(model) > 0 and np.std(meas) > 0 else float("nan")
            fit[m] = {key: float(scale * np.sqrt(np.mean(err**2))), "r": r}
        out[kind] = fit
    return out


def validation_warnings(fits: dict, rms_mm: float = VALIDATION_RMS_MM, min_r: float = VALIDATION_MIN_R) -> list[str]:
    """One line per measured muscle whose validation re-solve misfits its measurement
    (``fits``: ``{trial: tracking_fit(...)}``): a fiber length with RMS above ``rms_mm`` (mm) or
    Pearson r below ``min_r``; an excitation with r below ``min_r`` against its scaled EMG."""
    lines = []
    for trial, fit in (fits or {}).items():
        for m, v in (fit.get("fiber_length") or {}).items():
            bad = [f"RMS {v['rms_mm']:.3g} mm (above {rms_mm:g} mm)"] if v["rms_mm"] > rms_mm else []
            if not (v["r"] >= min_r):
                bad.append(f"r {v['r']:.2f} (below {min_r:g})")
            if bad:
                lines.append(f"validation of {trial}: the fiber length of {m} misfits its ultrasound: "
                             + ", ".join(bad) + "; the effort goal with the estimates does not reproduce it")
        for m, v in (fit.get("emg") or {}).items():
            if not (v["r"] >= min_r):
                lines.append(f"validation of {trial}: the excitation of {m} misfits its EMG: r {v['r']:.2f} (below "
                             f"{min_r:g}); the effort goal with the estimates does not reproduce it")
    return lines


def warn_validation(fits: dict) -> list[str]:
    """Warn each line of :func:`validation_warnings` (:class:`MusclemetabWarning`); returns them."""
    lines = validation_warnings(fits)
    for line in lines:
        warnings.warn(line, MusclemetabWarning, stacklevel=2)
    return lines
