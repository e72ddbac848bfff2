"""An independent implementation of the muscle redundancy problem's equations, for tests.

Written from ``muscle_model.md`` §4-§9 and ``muscle_redundancy.md`` §3, deliberately not
importing :mod:`musclemetab.muscle` or :mod:`musclemetab.redundancy`: the solver's output is
checked against these functions.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import butter, filtfilt

DOFS = ("ankle_angle_r", "knee_angle_r", "hip_flexion_r", "hip_adduction_r", "hip_rotation_r")


def fl_ref(l):
    b = ((0.814483478343008, 1.05503342897057, 0.162384573599574, 0.0633034484654646),
         (0.433004984392647, 0.716775413397760, -0.0299471169706956, 0.200356847296188),
         (0.1, 1.0, 0.3535533905932738, 0.0))
    return sum(b1 * np.exp(-0.5 * (l - b2) ** 2 / (b3 + b4 * l) ** 2) for b1, b2, b3, b4 in b)


def fv_ref(vbar):
    d1, d2, d3, d4 = -0.3183234368991278, -8.14915604347525, -0.37412150864786, 0.885644059915004
    return d1 * np.arcsinh(d2 * vbar + d3) + d4


def fpe_ref(l, kpe, s0, sm):
    return (np.exp(kpe * (l - s0) / sm) - np.exp(-4.0 * kpe / 3.0)) / (np.exp(kpe) - 1.0)


def shift_ref(kt):
    return (np.exp(0.175) - np.exp(0.005 * kt)) / 5.0


def ft_ref(lt, kt):
    return np.exp(kt * (lt - 0.995)) / 5.0 - 0.25 + shift_ref(kt)


def dadt_ref(e, a):
    f = 0.5 * np.tanh(0.1 * (e - a))
    d1 = 1.0 / (0.015 * (0.5 + 1.5 * a))
    d2 = (0.5 + 1.5 * a) / 0.060
    return (d1 * (f + 0.5) + d2 * (0.5 - f)) * (e - a)


def filt_ref(x, fs):
    b, a = butter(6, 6.0 / (fs / 2.0))
    return filtfilt(b, a, x, axis=0, padtype="odd", padlen=18)


def mesh_inputs(example, geometry, trial, n):
    """Filtered, spline-interpolated lMT (N+1, M), moment arms (N+1, D, M) and ID (N+1, D)."""
    from musclemetab.io import read_storage

    ik = read_storage(example.ik[trial])
    idf = read_storage(example.id[trial])
    t_ik, t_id = ik.index.to_numpy(), idf.index.to_numpy()
    fs_ik, fs_id = 1.0 / np.mean(np.diff(t_ik)), 1.0 / np.mean(np.diff(t_id))
    mom = filt_ref(idf[[f"{d}_moment" for d in DOFS]].to_numpy(), fs_id)
    mom = np.column_stack([np.interp(t_ik, t_id, mom[:, j]) for j in range(len(DOFS))])
    lmt = filt_ref(geometry.lmt_m, fs_ik)
    F, D, M = geometry.moment_arms_m.shape
    r = filt_ref(geometry.moment_arms_m.reshape(F, D * M), fs_ik)
    t = np.linspace(t_ik[0], t_ik[-1], n + 1)
    return (t, CubicSpline(t_ik, lmt, bc_type="not-a-knot")(t),
            CubicSpline(t_ik, r, bc_type="not-a-knot")(t).reshape(n + 1, D, M),
            CubicSpline(t_ik, mom, bc_type="not-a-knot")(t))


def params_of(sol):
    """The per-muscle parameters recorded in a solution's summary, as arrays by key."""
    p = sol.summary["parameters"]
    return {k: np.array([p[m][k] for m in sol.muscles]) for k in next(iter(p.values()))}


def check_solution_satisfies_problem(sol, t, lmt, r, mom, n, backward=False):
    """Assert the specified problem holds on the solution (muscle_redundancy.md §5): tendon
    force from the geometry, moment equilibrium and normalised Hill equilibrium at nodes
    0..N-1 within 1e-4, forward-Euler activation dynamics and fiber kinematics, bounds.
    With ``backward``: backward-Euler fiber kinematics, ``l_k+1 = l_k + h v_k+1``, the
    velocity written at node k+1 and the Hill equilibrium at nodes 1..N.
    Returns the parameters, the normalised fiber velocity and the projected fiber length."""
    np.testing.assert_allclose(sol.time_s, t, atol=1e-9)
    P = params_of(sol)
    h = (t[-1] - t[0]) / n

    # the tendon force written is F0 fT(l~T) with lT = lMT - sqrt(lM^2 - w^2) from the geometry
    lm = sol.lm_norm * P["lMo_m"]
    w = P["lMo_m"] * np.sin(P["alpha0_rad"])
    lm_proj = np.sqrt(lm**2 - w**2)
    ft = ft_ref((lmt - lm_proj) / P["lTs_m"], P["kT"])
    np.testing.assert_allclose(sol.tendon_force_N, P["F0_N"] * ft, rtol=1e-8, atol=1e-6)

    # moment equilibrium at the constrained nodes 0..N-1
    rebuilt = np.einsum("kdm,km->kd", r[:n], sol.tendon_force_N[:n]) + sol.reserve_Nm[:n]
    assert np.max(np.abs(rebuilt - mom[:n])) < 1e-4

    # Hill equilibrium at nodes 0..N-1 (normalised)
    vbar = sol.normalized_fiber_velocity
    fiber = sol.activation * fl_ref(sol.lm_norm) * fv_ref(vbar) + fpe_ref(sol.lm_norm, P["kPE"], P["s0"], P["sM"])
    hill = fiber * lm_proj / lm - sol.tendon_force_N / P["F0_N"]
    assert np.max(np.abs(hill[1:] if backward else hill[:n])) < 1e-4

    # activation dynamics and fiber kinematics (forward Euler) on the mesh
    act = sol.activation[1:] - sol.activation[:-1] - h * dadt_ref(sol.excitation[:n], sol.activation[:n])
    assert np.max(np.abs(act)) < 1e-5
    lm_step = sol.lm_norm[1:] - sol.lm_norm[:-1] - h * (vbar[1:] if backward else vbar[:n]) * P["vmax_lMo_per_s"]
    assert np.max(np.abs(lm_step)) < 1e-5

    # bounds
    assert sol.activation.min() >= -1e-8 and sol.activation.max() <= 1 + 1e-8
    assert sol.excitation.min() >= -1e-8 and sol.excitation.max() <= 1 + 1e-8
    assert sol.lm_norm.min() >= 0.1 - 1e-8 and sol.lm_norm.max() <= 1.7 + 1e-8
    assert np.max(np.abs(vbar)) <= 1 + 1e-8
    assert np.max(np.abs(sol.reserve_Nm)) <= 150 + 1e-6
    return P, vbar
