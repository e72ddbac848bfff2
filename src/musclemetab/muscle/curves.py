"""Hill-type muscle-tendon curves (De Groote et al. 2016), written once.

Every function works on NumPy arrays *and* on CasADi symbols: the math namespace is chosen
from the type of the first argument, so the optimal control problems and the NumPy
post-processing evaluate the same expressions. Importing this module does not import
CasADi.

Normalisations and units (see ``docs/method.md``):

* ``lm_norm``  normalised fiber length l~M = lM / lMo (-)
* ``vbar``     fiber velocity divided by the maximal contraction velocity,
  vbar = v~M / vmax with v~M in optimal lengths per second; positive = lengthening
* ``lt_norm``  normalised tendon length l~T = lT / lTs (-)
* ``kT``       normalised tendon stiffness (-), generic 35

Reference: De Groote F, Kinney AL, Rao AV, Fregly BJ (2016) Evaluation of direct
collocation optimal control problem formulations for solving the muscle redundancy
problem. Ann Biomed Eng 44:2922-2936.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "math_for",
    "FL_COEFFICIENTS",
    "FV_COEFFICIENTS",
    "TAU_ACTIVATION_S",
    "TAU_DEACTIVATION_S",
    "ACTIVATION_SMOOTHING",
    "KT_GENERIC",
    "active_force_length",
    "force_velocity",
    "passive_force_length",
    "tendon_shift",
    "tendon_force_length",
    "tendon_length_from_force",
    "tendon_stiffness_N_per_m",
    "tendon_stiffness_for_slope",
    "activation_rate",
    "hill_residual",
    "fiber_width",
    "longest_fiber_length_bound",
]

# Active force-length: sum of three Gaussians, rows (b1, b2, b3, b4).
FL_COEFFICIENTS = (
    (0.814483478343008, 1.05503342897057, 0.162384573599574, 0.0633034484654646),
    (0.433004984392647, 0.716775413397760, -0.0299471169706956, 0.200356847296188),
    (0.1, 1.0, 0.5 * math.sqrt(0.5), 0.0),
)

# Force-velocity constants d1..d4 (the published values; the raw code constants
# -0.2158..., -32.59..., -1.1241..., 0.9126... transformed as 1.475*p1, 0.25*p2,
# p3 + 0.75, p4 - 0.027).
FV_COEFFICIENTS = (
    1.475 * -0.215812499592629,
    0.25 * -32.5966241739010,
    -1.12412150864786 + 0.75,
    0.912644059915004 - 0.027,
)

TAU_ACTIVATION_S = 0.015
TAU_DEACTIVATION_S = 0.060
ACTIVATION_SMOOTHING = 0.1  # b in tanh(b (e - a)); 0.1 as in the reference implementation
KT_GENERIC = 35.0


class _NumpyMath:
    exp = staticmethod(np.exp)
    log = staticmethod(np.log)
    sqrt = staticmethod(np.sqrt)
    tanh = staticmethod(np.tanh)
    tan = staticmethod(np.tan)
    arcsinh = staticmethod(np.arcsinh)

    @staticmethod
    def sum1(x):
        """Sums over the first axis (one per column)."""
        return np.sum(x, axis=0)


class _CasadiMath:
    def __init__(self):
        import casadi as ca

        self.exp = ca.exp
        self.log = ca.log
        self.sqrt = ca.sqrt
        self.tanh = ca.tanh
        self.tan = ca.tan
        self.arcsinh = ca.asinh
        self.sum1 = ca.sum1


_NUMPY = _NumpyMath()
_CASADI = None


def math_for(*xs):
    """The math namespace for the arguments: CasADi if any is a CasADi object, else NumPy.

    Every curve of this module, and the smooth energy models, are written once with it
    (``m.exp``, ``m.tanh``, ...), so that the same body serves CasADi and NumPy."""
    global _CASADI
    for x in xs:
        if type(x).__module__.startswith("casadi"):
            if _CASADI is None:
                _CASADI = _CasadiMath()
            return _CASADI
    return _NUMPY


def _arr(x, m):
    return np.asarray(x, dtype=float) if m is _NUMPY else x


def active_force_length(lm_norm):
    """Active force-length multiplier fL(l~M), a sum of three Gaussians.

    ``fL(1.0) = 0.99943``, maximum ``1.00050`` at ``l~M = 1.0133``.
    """
    m = math_for(lm_norm)
    lm = _arr(lm_norm, m)
    out = 0
    for b1, b2, b3, b4 in FL_COEFFICIENTS:
        out = out + b1 * m.exp(-0.5 * (lm - b2) ** 2 / (b3 + b4 * lm) ** 2)
    return out


def force_velocity(vbar):
    """Force-velocity multiplier fV(vbar), ``vbar = v~M / vmax`` (positive = lengthening).

    ``fV = d1 asinh(d2 vbar + d3) + d4``; note ``fV(0) = 1.002119``, not 1.
    """
    m = math_for(vbar)
    v = _arr(vbar, m)
    d1, d2, d3, d4 = FV_COEFFICIENTS
    return d1 * m.log((d2 * v + d3) + m.sqrt((d2 * v + d3) ** 2 + 1)) + d4


def passive_force_length(lm_norm, kpe=4.0, s0=1.0, sm=0.6):
    """Passive fiber force-length multiplier fPE(l~M) with per-muscle shape parameters.

    ``fPE = [exp(kPE (l - s0)/sM) - 1 - P1] / P2``, ``P1 = exp(kPE (0.2 - 1)/0.6) - 1``,
    ``P2 = exp(kPE) - 1``. The 0.6 inside ``P1`` is fixed (not ``sM``), as in the reference
    implementation; the curve is the published Eq. 1 plus a constant offset
    ``(1 - exp(-4 kPE/3)) / (exp(kPE) - 1)`` (0.018567 for kPE = 4).
    Generic parameters: ``kPE = 4, s0 = 1, sM = 0.6``.
    """
    m = math_for(lm_norm, kpe, s0, sm)
    lm = _arr(lm_norm, m)
    kpe, s0, sm = (_arr(p, m) for p in (kpe, s0, sm))
    p1 = m.exp(kpe * (0.2 - 1.0) / 0.6) - 1.0
    p2 = m.exp(kpe) - 1.0
    return (m.exp(kpe * (lm - s0) / sm) - 1.0 - p1) / p2


def tendon_shift(kT):
    """Shift added to the tendon curve so that ``fT(l~T = 1)`` does not depend on ``kT``.

    ``shift = [exp(0.175) - exp(0.005 kT)] / 5``; zero for ``kT = 35``.
    """
    m = math_for(kT)
    k = _arr(kT, m)
    return (math.exp(35 * 0.005) - m.exp(k * 0.005)) / 5.0


def tendon_force_length(lt_norm, kT=KT_GENERIC):
    """Normalised tendon force fT(l~T) = exp(kT (l~T - 0.995))/5 - 0.25 + shift(kT)."""
    m = math_for(lt_norm, kT)
    lt = _arr(lt_norm, m)
    k = _arr(kT, m)
    return m.exp(k * (lt - 0.995)) / 5.0 - 0.25 + tendon_shift(k)


def tendon_length_from_force(ft_norm, kT=KT_GENERIC):
    """Inverse of :func:`tendon_force_length` (NumPy only).

    Like the reference implementation, the logarithm of a negative argument is taken of
    its magnitude (the real part of the complex logarithm).
    """
    ft = np.asarray(ft_norm, dtype=float)
    k = np.asarray(kT, dtype=float)
    arg = 5.0 * (ft + 0.25 - tendon_shift(k))
    with np.errstate(divide="ignore"):
        return np.log(np.abs(arg)) / k + 0.995


def tendon_stiffness_N_per_m(lt_norm, max_isometric_force_N, tendon_slack_length_m, kT=KT_GENERIC):
    """Tendon stiffness dFT/dlT in N/m at a normalised tendon length."""
    lt = np.asarray(lt_norm, dtype=float)
    return (
        np.asarray(max_isometric_force_N) * np.asarray(kT) * np.exp(np.asarray(kT) * (lt - 0.995))
        / (5.0 * np.asarray(tendon_slack_length_m))
    )


def tendon_stiffness_for_slope(stiffness_N_per_m, max_isometric_force_N, tendon_slack_length_m,
                               force_fraction=1.0):
    """The ``kT`` that gives tendons in parallel a summed slope ``stiffness_N_per_m``.

    Every tendon carries ``force_fraction`` of its maximal isometric force (``fT``); there
    ``dFT/dlT = F0 kT (fT + 0.25 - shift(kT)) / lTs``, so the summed slope is
    ``kT (fT + 0.25 - shift(kT)) * sum(F0 / lTs)``, increasing in ``kT``; solved by
    bisection for one shared ``kT`` (NumPy only).
    """
    f0 = np.atleast_1d(np.asarray(max_isometric_force_N, dtype=float))
    lts = np.atleast_1d(np.asarray(tendon_slack_length_m, dtype=float))
    target = float(stiffness_N_per_m) / float(np.sum(f0 / lts))
    ft = float(force_fraction)

    def slope(k):
        return k * (ft + 0.25 - float(tendon_shift(k)))

    lo, hi = 1e-3, 1.0
    while slope(hi) < target and hi < 1e4:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if slope(mid) < target else (lo, mid)
        if hi - lo < 1e-12 * hi:
            break
    return 0.5 * (lo + hi)


def activation_rate(
    excitation,
    activation,
    tau_act_s=TAU_ACTIVATION_S,
    tau_deact_s=TAU_DEACTIVATION_S,
    b=ACTIVATION_SMOOTHING,
):
    """Smooth first-order activation dynamics da/dt (1/s), De Groote et al. (2016).

    ``f = 0.5 tanh(b (e - a))``, ``d1 = 1/(tau_a (0.5 + 1.5 a))``,
    ``d2 = (0.5 + 1.5 a)/tau_d``, ``da/dt = [d1 (f + 0.5) + d2 (0.5 - f)] (e - a)``.
    With the reference ``b = 0.1`` the switch between the two time constants is nearly
    absent (the rate is close to the mean of both); this is reproduced on purpose.
    """
    m = math_for(excitation, activation)
    e = _arr(excitation, m)
    a = _arr(activation, m)
    f = 0.5 * m.tanh(b * (e - a))
    d1 = 1.0 / (tau_act_s * (0.5 + 1.5 * a))
    d2 = (0.5 + 1.5 * a) / tau_deact_s
    return (d1 * (f + 0.5) + d2 * (0.5 - f)) * (e - a)


def fiber_width(optimal_fiber_length_m, pennation_angle_at_optimal_rad):
    """Constant muscle thickness w = lMo sin(alpha0) (m)."""
    m = math_for(optimal_fiber_length_m, pennation_angle_at_optimal_rad)
    if m is _NUMPY:
        return np.asarray(optimal_fiber_length_m) * np.sin(pennation_angle_at_optimal_rad)
    import casadi as ca

    return optimal_fiber_length_m * ca.sin(pennation_angle_at_optimal_rad)


def longest_fiber_length_bound(lmt_m, tendon_slack_length_m, optimal_fiber_length_m, width_m, default: float,
                               margin: float = 0.05):
    """Upper bound of each muscle's normalised fiber length over a motion (NumPy).

    No fiber is longer than with its tendon at slack length (a shorter tendon carries no
    force, and neither can the fiber then): ``l~M <= sqrt((lMT - lTs)^2 + w^2) / lMo``. The
    bound is ``default``, or this rigid-tendon length at the longest ``lMT`` (rows of
    ``lmt_m`` are frames) plus ``margin`` where that is larger, so that a box on the fiber
    length never excludes the only equilibria of a muscle the geometry stretches further.
    """
    along = np.max(np.atleast_2d(np.asarray(lmt_m, dtype=float)), axis=0) - np.asarray(tendon_slack_length_m)
    rigid = np.sqrt(np.maximum(along, 0.0) ** 2 + np.asarray(width_m) ** 2) / np.asarray(optimal_fiber_length_m)
    return np.maximum(default, rigid + margin)


def hill_residual(
    activation,
    lm_norm,
    vm_norm,
    lm_projected_m,
    lmt_m,
    *,
    optimal_fiber_length_m,
    tendon_slack_length_m,
    max_contraction_velocity,
    kT=KT_GENERIC,
    kpe=4.0,
    s0=1.0,
    sm=0.6,
):
    """Normalised force equilibrium between fiber (along the tendon) and tendon.

    ``res = [a fL(l~M) fV(v~M/vmax) + fPE(l~M)] cos(alpha) - fT(l~T)`` with
    ``cos(alpha) = lM_proj / lM`` and ``l~T = (lMT - lM_proj) / lTs``; ``v~M`` in optimal
    lengths per second. Zero at a consistent muscle state.
    """
    lm_m = lm_norm * optimal_fiber_length_m
    cos_alpha = lm_projected_m / lm_m
    fiber = activation * active_force_length(lm_norm) * force_velocity(vm_norm / max_contraction_velocity)
    fiber = fiber + passive_force_length(lm_norm, kpe, s0, sm)
    lt_norm = (lmt_m - lm_projected_m) / tendon_slack_length_m
    return fiber * cos_alpha - tendon_force_length(lt_norm, kT)
