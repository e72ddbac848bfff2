"""The passive static equilibrium of one muscle by scalar root finding: a check of the NLP.

Independent of :func:`.problem.solve_passive` (no CasADi, no IPOPT): at rest (activation 0,
fiber velocity 0) the fiber's passive force along the tendon equals the tendon force,

    fPE(l~M) cos(alpha) = fT(l~T),
    cos(alpha) = sqrt(lM^2 - w^2)/lM,   l~T = (lMT - sqrt(lM^2 - w^2))/lTs,

one equation in ``l~M`` whose root is bracketed between the shortest fiber the pennation
allows and a length beyond any bound of the NLP, and found with Brent's method
(``scipy.optimize.brentq``).
"""

from __future__ import annotations

import math

from ..muscle import passive_force_length, tendon_force_length
from .problem import KPE_GENERIC, LM_NORM_BOUNDS, S0_GENERIC, SM_FIXED
from .trials import KT_DEFAULT

__all__ = ["equilibrium_fiber_length"]


def equilibrium_fiber_length(
    lmt_m: float,
    *,
    optimal_fiber_length_m: float,
    tendon_slack_length_m: float,
    pennation_angle_at_optimal_rad: float,
    kpe: float = KPE_GENERIC,
    s0: float = S0_GENERIC,
    sm: float = SM_FIXED,
    kT: float = KT_DEFAULT,
) -> tuple[float, float]:
    """Passive static equilibrium of one muscle by root finding (module docstring).

    Returns ``(l~M, fT)`` for the muscle-tendon length ``lmt_m`` (``fT`` the normalised
    tendon force).
    """
    from scipy.optimize import brentq

    lmo, lts = optimal_fiber_length_m, tendon_slack_length_m
    w = lmo * math.sin(pennation_angle_at_optimal_rad)

    def residual(lm):
        proj = math.sqrt(max((lm * lmo) ** 2 - w**2, 1e-16))
        return float(passive_force_length(lm, kpe, s0, sm)) * proj / (lm * lmo) - float(
            tendon_force_length((lmt_m - proj) / lts, kT)
        )

    lo = max(LM_NORM_BOUNDS[0], w / lmo + 1e-9)
    lm = brentq(residual, lo, 3.0, xtol=1e-14)  # beyond any bound of the NLP
    proj = math.sqrt((lm * lmo) ** 2 - w**2)
    return lm, float(tendon_force_length((lmt_m - proj) / lts, kT))

