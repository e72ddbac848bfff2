"""How converged a solve's metabolic rates are (``docs/solver.md``, "Where the solver stops").

IPOPT is an interior-point method: it minimises the objective less ``mu`` times the logarithms
of the distances to the bounds, and lowers the barrier parameter ``mu`` towards zero. A muscle
that is off at the optimum (activation and excitation on their bound of zero) is held above it
by the barrier: with the effort cost ``w/2 a^2/(N M)`` (``N`` intervals, ``M`` muscles, weight
``w``) the barrier problem is stationary at ``w a/(N M) = mu/a``, so at

    a_mu = sqrt(mu N M / w)

(0.02 at the study's stop on the example subject, where ``mu`` ends at 9e-8; 2e-4 at the
package's default stop, where it ends at IPOPT's floor of 1e-11). The energy models turn this
residue into watts: the activation heat of Umberger et al. (2003, 2010) grows with ``A^0.6``,
so an activation of 0.02 already counts for 10 % of a muscle's full activation heat.

The record of a solve (``summary.json``, ``convergence``) holds ``stop`` and ``tolerance``
(where IPOPT was told to stop, :data:`.stops.STOPS`), ``final_barrier_parameter`` (IPOPT's ``mu``
at the last iterate), ``off_level`` (``a_mu`` above), ``largest_off_activation`` (the largest
activation or excitation below it) and ``rate_residue``: for each energy model of the study, the
share of the leg's muscle rate (basal heat left out) that the activations and excitations below
``a_mu`` carry, i.e. by how much the rate falls when they are set to zero, as they are at the
optimum. It estimates how far the rates lie above the optimum's: on the example subject at the
study's stop 10.8 % for UM10 on the normal trial with EFFORT-GEN and 18.7 % (UM03) on the slow
trial with EFFORT-TEN, against 10.7 % and 18.1 % measured by re-solving at tolerance 1e-10; at the
default stop at most 0.15 %. ``max_rate_residue`` is the largest share; above :data:`UNCONVERGED_RATE_SHARE` the
solution gets the plausibility flag ``unconverged_rates`` (:func:`unconverged_rates_flag`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..errors import MusclemetabError

__all__ = ["UNCONVERGED_RATE_SHARE", "RESIDUE_MODELS", "off_level", "rate_residue", "convergence_record",
           "unconverged_rates_flag"]

#: Share of a model's leg rate carried by activations below :data:`OFF_LEVEL` above which the
#: rates are flagged as not converged (``unconverged_rates``): the 1 % a reported rate may differ
#: from the optimum's.
UNCONVERGED_RATE_SHARE = 0.01
#: A body mass for the energy models' call: the shares do not depend on it (muscle masses by
#: the model rule, no basal heat)
REFERENCE_BODY_MASS_KG = 70.0
#: The energy models whose rates the record checks (the study's six)
RESIDUE_MODELS = "all"


def off_level(final_barrier_parameter: float, n_intervals: int, n_muscles: int, w_activation: float) -> float:
    """``a_mu = sqrt(mu N M / w)``: the activation at which the barrier term alone holds a muscle
    that is off at the optimum (see the module's docstring)."""
    return math.sqrt(max(final_barrier_parameter, 0.0) * n_intervals * n_muscles / w_activation)


def rate_residue(solution, level: float) -> dict[str, float]:
    """``{model: share}`` of each study model's leg muscle rate (no basal heat; muscle masses by
    the model rule, so no body size is needed: the share does not depend on it) carried by the
    activations and excitations of ``solution`` below ``level``."""
    from ..metabolics.solution import metabolics_from_solution

    def leg_rates(sol):
        met = metabolics_from_solution(sol, REFERENCE_BODY_MASS_KG, None, models=RESIDUE_MODELS, basal="none", require_success=False)
        return {m: float(met.whole_body[m].leg_no_basal_mean_W) for m in met.models}

    off = dataclasses.replace(solution, activation=np.where(solution.activation < level, 0.0, solution.activation),
                              excitation=np.where(solution.excitation < level, 0.0, solution.excitation))
    full, floor = leg_rates(solution), leg_rates(off)
    return {m: (full[m] - floor[m]) / full[m] if full[m] > 0 else 0.0 for m in full}


def convergence_record(solution, *, stop: str | None, tolerance: float | None, final_barrier_parameter: float | None,
                       w_activation: float = 1.0) -> dict:
    """The ``convergence`` entry of a solve's record (see the module's docstring)."""
    mu = (float(final_barrier_parameter) if final_barrier_parameter is not None
          and math.isfinite(final_barrier_parameter) else None)
    rec = {"stop": stop, "tolerance": tolerance, "final_barrier_parameter": mu}
    if mu is None or not w_activation > 0:
        return {**rec, "note": "IPOPT reported no barrier parameter (or the effort weight is zero): not evaluated"}
    level = off_level(mu, len(solution.time_s) - 1, len(solution.muscles), w_activation)
    values = np.concatenate([np.asarray(solution.activation, float).ravel(),
                             np.asarray(solution.excitation, float).ravel()])
    below = values[values < level]
    rec.update(off_level=level, largest_off_activation=float(below.max()) if below.size else 0.0)
    try:
        residue = rate_residue(solution, level)
    except MusclemetabError as exc:  # a solution the energy models refuse (e.g. a muscle they do not know)
        return {**rec, "note": f"rates not evaluated: {exc}"}
    return {**rec, "rate_residue": residue, "max_rate_residue": max(residue.values()) if residue else 0.0}


def unconverged_rates_flag(convergence: dict | None, limit: float = UNCONVERGED_RATE_SHARE):
    """The plausibility flag ``unconverged_rates`` when the record's ``max_rate_residue`` is
    above ``limit`` (:data:`UNCONVERGED_RATE_SHARE`), else ``None``."""
    from ..quality import Flag

    worst = (convergence or {}).get("max_rate_residue")
    if worst is None or not math.isfinite(worst) or worst <= limit:
        return None
    residue = convergence.get("rate_residue") or {}
    model = max(residue, key=residue.get) if residue else "?"
    items = {m: float(v) for m, v in sorted(residue.items(), key=lambda kv: -kv[1]) if v > limit}
    return Flag("unconverged_rates",
                f"activations below {convergence.get('off_level', 0):.2g} (muscles the barrier holds above zero) "
                f"carry {100 * worst:.1f} % of the {model} leg rate, above {100 * limit:g} %: the solver stopped short of the optimum "
                f"(stop {convergence.get('stop')!r}, final barrier parameter "
                f"{convergence.get('final_barrier_parameter')}); solve with the default stop (optimum)",
                items, threshold=limit)
