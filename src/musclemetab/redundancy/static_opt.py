"""Static optimisation with rigid tendons: the initial guess of the optimal control problem.

At every IK frame (``docs/solver.md``, ``docs/method.md``)::

    min  sum_m a_m^2 + 1000 sum_j ar_j^2
    s.t. ID_j = sum_m r_jm (a_m Fact_m + Fpas_m) + ar_j,    0 <= a_m <= 1

with the rigid-tendon fiber state ``lM = sqrt((lMT - lTs)^2 + w^2)``,
``cos(alpha) = (lMT - lTs)/lM``, ``v~MT = (dlMT/dt)/lMo``,
``Fact = F0 fL(l~M) fV(v~MT/vmax) cos(alpha)`` and ``Fpas = F0 fPE(l~M) cos(alpha)``.
The reserve ``ar`` (N m, ``Topt = 1``) is free in practice (bounds +-1.5e6 never bind).

Eliminating ``ar = b - A a`` turns each frame into the bounded linear least-squares problem
``min ||a||^2 + 1000 ||b - A a||^2, 0 <= a <= 1``, a strictly convex QP whose unique optimum
is computed exactly with the bounded-variable least-squares method (Stark & Parker 1995,
``scipy.optimize.lsq_linear(method='bvls')`` on the stacked matrix ``[I; sqrt(1000) A]``);
the study solved the same QP with IPOPT (tolerance 1e-6).

From the static solution the OCP guess is built on the mesh: ``a``, ``ar`` and the normalised
tendon force ``F~T = (a fL fV + fPE) cos(alpha)`` are interpolated linearly onto the nodes, the
tendon curve is inverted with the *compliant* ``kT`` to get ``l~T``, then
``lM = sqrt(w^2 + (lMT - lTs l~T)^2)``; the fiber-velocity guess is the derivative of a
not-a-knot spline through that fiber-length guess.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..muscle import (
    active_force_length,
    force_velocity,
    passive_force_length,
    tendon_length_from_force,
)
from .inputs import TrialInputs
from .parameters import MuscleTendonParameters

__all__ = ["StaticOptimisation", "InitialGuess", "static_optimisation", "initial_guess", "guess_from_solution"]

RESERVE_WEIGHT_SO = 1000.0


@dataclass(frozen=True)
class StaticOptimisation:
    """Rigid-tendon static optimisation at the IK frames.

    ``activation`` ``(F, M)``, ``reserve_Nm`` ``(F, D)``, ``tendon_force_norm`` ``(F, M)``
    (``F~T``), ``objective`` summed over frames.
    """

    time_s: np.ndarray
    activation: np.ndarray
    reserve_Nm: np.ndarray
    tendon_force_norm: np.ndarray
    objective: float


@dataclass(frozen=True)
class InitialGuess:
    """Initial guess on the mesh: states ``(N+1, M)``, controls ``(N, M)`` / ``(N, D)``."""

    activation: np.ndarray
    lm_norm: np.ndarray
    lm_projected_m: np.ndarray
    excitation: np.ndarray
    reserve: np.ndarray
    fiber_velocity_lmo_per_s: np.ndarray
    #: an optimum of a problem of the same structure (variables ``x``, multipliers ``lam_x``,
    #: ``lam_g``; :attr:`.solution.Solution.multipliers`): IPOPT starts from it instead
    start: dict | None = field(default=None, repr=False, compare=False)


def rigid_tendon_forces(lmt_m, lmt_velocity_m_per_s, params: MuscleTendonParameters):
    """Per-unit-activation active force and passive force along the tendon (N), rigid tendon."""
    lmo = params.optimal_fiber_length_m
    along = lmt_m - params.tendon_slack_length_m
    lm = np.sqrt(along**2 + params.width_m**2)
    lm_norm = lm / lmo
    cos_alpha = along / lm
    vbar = lmt_velocity_m_per_s / lmo / params.max_contraction_velocity
    fl = active_force_length(lm_norm)
    fv = force_velocity(vbar)
    fpe = passive_force_length(lm_norm, params.passive_kpe, params.passive_s0, params.passive_sm)
    f0 = params.max_isometric_force_N
    return f0 * fl * fv * cos_alpha, f0 * fpe * cos_alpha, (fl * fv * cos_alpha, fpe * cos_alpha)


def static_optimisation(
    inputs: TrialInputs,
    params: MuscleTendonParameters,
    reserve_weight: float = RESERVE_WEIGHT_SO,
) -> StaticOptimisation:
    """Solve the rigid-tendon static optimisation at every IK frame (exactly)."""
    from scipy.optimize import lsq_linear

    F = inputs.frame_time_s.size
    M, D = len(inputs.muscles), len(inputs.dofs)
    f_act, f_pas, (act_norm, pas_norm) = rigid_tendon_forces(
        inputs.lmt_frames_m, inputs.lmt_velocity_frames_m_per_s, params
    )
    act = np.zeros((F, M))
    res = np.zeros((F, D))
    total = 0.0
    sw = np.sqrt(reserve_weight)
    eye = np.eye(M)
    for k in range(F):
        r = inputs.moment_arms_frames_m[k]  # (D, M)
        A = r * f_act[k]
        b = inputs.moments_frames_Nm[k] - r @ f_pas[k]
        sol = lsq_linear(np.vstack([eye, sw * A]), np.concatenate([np.zeros(M), sw * b]),
                         bounds=(0.0, 1.0), method="bvls", tol=1e-12)
        a = np.clip(sol.x, 0.0, 1.0)
        act[k] = a
        res[k] = b - A @ a
        total += float(a @ a + reserve_weight * res[k] @ res[k])
    ft = act * act_norm + pas_norm
    return StaticOptimisation(inputs.frame_time_s, act, res, ft, total)


def initial_guess(inputs: TrialInputs, params: MuscleTendonParameters, so: StaticOptimisation) -> InitialGuess:
    """The OCP initial guess on the mesh from the static optimisation (see module doc).

    As in the study, the reserve guess is the static-optimisation reserve in N m, not divided
    by the optimal reserve torque (only a starting point; IPOPT moves it into its bounds).
    """
    from scipy.interpolate import CubicSpline

    t = inputs.mesh_time_s
    N = inputs.n_intervals

    def lin(y):
        return np.column_stack([np.interp(t, so.time_s, y[:, j]) for j in range(y.shape[1])])

    a = lin(so.activation)
    ar = lin(so.reserve_Nm)
    ft = lin(so.tendon_force_norm)
    lt_norm = tendon_length_from_force(ft, params.tendon_stiffness)
    lm_proj = inputs.lmt_m - params.tendon_slack_length_m * lt_norm
    lm_m = np.sqrt(params.width_m**2 + lm_proj**2)
    lm_norm = lm_m / params.optimal_fiber_length_m
    vm = CubicSpline(t, lm_norm, axis=0, bc_type="not-a-knot")(t[:N], 1)
    lm_proj_guess = np.sqrt(np.maximum(lm_m**2 - params.width_m**2, 0.0))
    return InitialGuess(
        activation=a,
        lm_norm=lm_norm,
        lm_projected_m=lm_proj_guess,
        excitation=a[:N].copy(),
        reserve=ar[:N].copy(),
        fiber_velocity_lmo_per_s=vm,
    )


def guess_from_solution(solution, inputs: TrialInputs, params: MuscleTendonParameters,
                        optimal_reserve_Nm: float = 150.0) -> InitialGuess:
    """An initial guess from a previous solution on the same mesh and muscles (warm start).

    Raises :class:`~musclemetab.errors.DataMismatchError` when the mesh or the muscles differ.
    """
    from ..errors import DataMismatchError

    N = inputs.n_intervals
    if tuple(solution.muscles) != tuple(inputs.muscles) or tuple(solution.dofs) != tuple(inputs.dofs):
        raise DataMismatchError("the warm-start solution has other muscles or DOFs than this problem")
    if solution.time_s.size != N + 1 or np.max(np.abs(solution.time_s - inputs.mesh_time_s)) > 1e-9:
        raise DataMismatchError(
            f"the warm-start solution's mesh ({solution.time_s[0]:g}-{solution.time_s[-1]:g} s, "
            f"{solution.time_s.size - 1} intervals) differs from this trial's "
            f"({inputs.mesh_time_s[0]:g}-{inputs.mesh_time_s[-1]:g} s, {N} intervals)"
        )
    lm_m = solution.lm_norm * params.optimal_fiber_length_m
    return InitialGuess(
        activation=solution.activation.copy(),
        lm_norm=solution.lm_norm.copy(),
        lm_projected_m=np.sqrt(np.maximum(lm_m**2 - params.width_m**2, 0.0)),
        excitation=solution.excitation[:N].copy(),
        reserve=solution.reserve_Nm[:N] / optimal_reserve_Nm,
        # the intervals' velocities: nodes 1..N with the backward fiber dynamics (docs/problem.md)
        fiber_velocity_lmo_per_s=(solution.fiber_velocity_lmo_per_s[1:] if solution.record.fiber_dynamics == "backward"
                 else solution.fiber_velocity_lmo_per_s[:N]).copy(),
        start=getattr(solution, "multipliers", None),
    )
