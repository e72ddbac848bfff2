"""Whole-body metabolic rate, cost of transport, and indirect calorimetry (Brockway).

Whole-body average over a gait cycle (paper definition)::

    Edot_wb [W/kg] = legs * (1/T) * sum_i integral Edot_i dt / m_body  +  basal

with the integral over the cycle by the trapezoidal rule on the given samples, ``T`` the
cycle duration, ``legs = 2`` (one leg is simulated) and the sum over the simulated leg's
muscles. Three basal rules:

``"body"`` (default, the paper's text)
    muscle rates without any per-muscle basal heat, plus 1.2 W/kg of *body* mass (as
    OpenSim's probes write it: ``basal_coefficient * m_body^basal_exponent`` W, with
    coefficient 1.2 and exponent 1 by default);
``"muscle"`` (the study's code)
    the per-muscle basal heat 1.2 W/kg of *muscle* mass kept in every muscle's rate
    (the rates must have been computed with ``basal=True``), nothing added;
``"none"``
    no basal heat at all.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DataMismatchError, OptionError
from ._common import BASAL_RATE_W_PER_KG, MetabolicRates

__all__ = [
    "WholeBodyRate",
    "whole_body_rate",
    "cost_of_transport_J_per_kg_per_m",
    "brockway_rate_W",
    "BASAL_RULES",
    "body_basal_W_per_kg",
    "BROCKWAY_COEFFICIENTS",
]

BASAL_RULES = ("body", "muscle", "none")

#: Brockway (1987): J per mL of O2, J per mL of CO2, J per mg of urinary nitrogen
#: (numerically the kJ per litre / kJ per gram of the published equation).
BROCKWAY_COEFFICIENTS = {"o2_J_per_mL": 16.58, "co2_J_per_mL": 4.51, "urinary_nitrogen_J_per_mg": 5.90}


def _trapezoid(y: np.ndarray, x: np.ndarray) -> float:
    return float(np.trapezoid(y, x))


@dataclass(frozen=True)
class WholeBodyRate:
    """Whole-body metabolic rate over one gait cycle.

    Attributes
    ----------
    time_s
        Sample times (s).
    rate_W_per_kg
        Whole-body rate at each sample (W/kg of body mass; both legs, basal per the rule).
    one_leg_W
        Summed rate of the simulated leg's muscles at each sample (W), including the
        per-muscle basal heat only under the ``"muscle"`` rule.
    mean_W_per_kg
        Cycle average of ``rate_W_per_kg``.
    mean_W_per_kg_no_basal
        Cycle average without any basal heat (neither rule).
    one_leg_mean_W
        Cycle average of ``one_leg_W``.
    duration_s
        ``T`` used for the average.
    """

    time_s: np.ndarray
    rate_W_per_kg: np.ndarray
    one_leg_W: np.ndarray
    mean_W_per_kg: float
    mean_W_per_kg_no_basal: float
    one_leg_mean_W: float
    duration_s: float
    basal_rule: str
    body_mass_kg: float
    legs: int
    #: whole-body basal heat added to every sample (W/kg of body mass; 0 unless the rule is ``"body"``)
    basal_W_per_kg: float = 0.0
    #: cycle average of the simulated leg's summed muscle rates without any basal heat (W)
    leg_no_basal_mean_W: float = float("nan")

    def __repr__(self) -> str:
        """A summary of two lines (the cycle averages, the basal rule), not the arrays."""
        legs = "both legs" if self.legs == 2 else f"{self.legs} leg{'s' if self.legs != 1 else ''}"
        return (f"WholeBodyRate: {self.mean_W_per_kg:.4g} W/kg ({self.mean_W_per_kg_no_basal:.4g} without basal heat) "
                f"over {self.duration_s:.4g} s, {len(self.time_s)} samples\n"
                f"  {legs}, basal {self.basal_rule} ({self.basal_W_per_kg:g} W/kg), body {self.body_mass_kg:g} kg; "
                f"the simulated leg's muscles {self.one_leg_mean_W:.4g} W")

    __str__ = __repr__

    def cost_of_transport_J_per_kg_per_m(self, speed_m_per_s: float) -> float:
        """Gross cost of transport (J/kg/m) at the walking speed (basal heat of the rule included)."""
        return cost_of_transport_J_per_kg_per_m(self.mean_W_per_kg, speed_m_per_s)

    def net_cost_of_transport_J_per_kg_per_m(self, speed_m_per_s: float) -> float:
        """Net cost of transport (J/kg/m) at the walking speed: without any basal heat."""
        return cost_of_transport_J_per_kg_per_m(self.mean_W_per_kg_no_basal, speed_m_per_s)


def whole_body_rate(
    rates: MetabolicRates | np.ndarray,
    time_s,
    body_mass_kg: float,
    *,
    basal: str = "body",
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    basal_exponent: float = 1.0,
    legs: int = 2,
    cycle_duration_s: float | None = None,
) -> WholeBodyRate:
    """Whole-body metabolic rate (W/kg) over a gait cycle from one leg's muscle rates.

    Parameters
    ----------
    rates
        One model's :class:`MetabolicRates` of shape ``(muscles, time)`` (or ``(time,)``),
        or an array of muscle rates in W *without* basal heat.
    time_s
        1-D sample times (s), the cycle (e.g. the trimmed solver nodes).
    body_mass_kg
        Body mass (kg).
    basal
        ``"body"`` (default): add ``basal_rate_W_per_kg`` W per kg of body mass, muscle
        rates taken without their per-muscle basal component; ``"muscle"``: keep each
        muscle's basal component (the study's code); ``"none"``.
    basal_rate_W_per_kg
        1.2 W/kg (Umberger et al. 2003).
    basal_exponent
        Under the ``"body"`` rule the basal heat is ``basal_rate_W_per_kg *
        body_mass_kg**basal_exponent`` W, as OpenSim's probes write it (``basal_coefficient``,
        ``basal_exponent``, default 1: 1.2 W/kg; e.g. 0.75 for a Kleiber-type scaling).
    legs
        Number of legs the simulated leg stands for (2).
    cycle_duration_s
        ``T`` of the average. Default: the span of ``time_s``, so that the result is the
        time average over the samples given. (The study's choice is not recorded; the
        true cycle or ``t_{N-5} - t_5`` differ by about 1 %.)

    Returns
    -------
    WholeBodyRate
    """
    if basal not in BASAL_RULES:
        raise OptionError(f"basal rule must be one of {', '.join(BASAL_RULES)}, not {basal!r}")
    if not (np.isfinite(body_mass_kg) and body_mass_kg > 0):
        raise OptionError(f"body mass must be a positive number of kilograms, not {body_mass_kg!r}")
    check_basal_rule(basal_rate_W_per_kg, basal_exponent)
    if not (isinstance(legs, (int, np.integer)) and legs >= 1):
        raise OptionError(f"legs must be a positive whole number, not {legs!r}")
    t = np.asarray(time_s, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise DataMismatchError("time_s must be 1-D with at least two samples")
    if not (np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)):
        raise OptionError("time_s must be finite and strictly increasing (s)")
    if isinstance(rates, MetabolicRates):
        no_basal = rates.total_without_basal()
        with_muscle_basal = rates.total
        has_basal = bool(np.any(rates.basal != 0))
    else:
        no_basal = np.asarray(rates, dtype=float)
        with_muscle_basal = None
        has_basal = False
    if no_basal.shape[-1:] != t.shape:
        raise DataMismatchError(
            f"the rates have {no_basal.shape[-1] if no_basal.ndim else 0} samples along their last (time) axis "
            f"but time_s has {t.size}"
        )
    if not np.all(np.isfinite(no_basal)):
        raise OptionError("the muscle rates hold NaN or infinite values")
    if basal == "muscle":
        if not has_basal:
            raise OptionError(
                "basal rule 'muscle' needs rates computed with basal=True (per-muscle basal heat); "
                "these rates have none. Use basal='body' or recompute with basal=True"
            )
        leg = with_muscle_basal.reshape(-1, t.size).sum(axis=0)
    else:
        leg = no_basal.reshape(-1, t.size).sum(axis=0)
    leg_no_basal = no_basal.reshape(-1, t.size).sum(axis=0)

    duration = float(t[-1] - t[0]) if cycle_duration_s is None else float(cycle_duration_s)
    if not (np.isfinite(duration) and duration > 0):
        raise OptionError(f"cycle duration must be positive (s), not {cycle_duration_s!r}")
    add = body_basal_W_per_kg(body_mass_kg, basal_rate_W_per_kg, basal_exponent) if basal == "body" else 0.0
    rate = legs * leg / body_mass_kg + add
    leg_mean = _trapezoid(leg, t) / duration
    mean = legs * leg_mean / body_mass_kg + add
    leg_nb_mean = _trapezoid(leg_no_basal, t) / duration
    mean_nb = legs * leg_nb_mean / body_mass_kg
    return WholeBodyRate(
        time_s=t,
        rate_W_per_kg=rate,
        one_leg_W=leg,
        mean_W_per_kg=float(mean),
        mean_W_per_kg_no_basal=float(mean_nb),
        one_leg_mean_W=float(leg_mean),
        duration_s=duration,
        basal_rule=basal,
        body_mass_kg=float(body_mass_kg),
        legs=int(legs),
        basal_W_per_kg=float(add),
        leg_no_basal_mean_W=float(leg_nb_mean),
    )


def check_basal_rule(basal_rate_W_per_kg, basal_exponent) -> None:
    """Raise :class:`OptionError` unless the basal coefficient (W/kg) is a non-negative number
    and the exponent a finite number."""
    for name, v in (("basal_rate_W_per_kg (the basal coefficient)", basal_rate_W_per_kg),
                    ("basal_exponent", basal_exponent)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not np.isfinite(v):
            raise OptionError(f"{name} must be a finite number, not {v!r}")
    if basal_rate_W_per_kg < 0:
        raise OptionError(f"the basal coefficient must not be negative (W/kg), not {basal_rate_W_per_kg!r}")


def body_basal_W_per_kg(body_mass_kg: float, basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
                        basal_exponent: float = 1.0) -> float:
    """The ``"body"`` rule's basal heat per kg of body mass, as OpenSim's probes write it:
    ``basal_coefficient * m_body^basal_exponent / m_body`` (W/kg; 1.2 with the defaults)."""
    return float(basal_rate_W_per_kg) * float(body_mass_kg) ** float(basal_exponent) / float(body_mass_kg)


def cost_of_transport_J_per_kg_per_m(mean_W_per_kg, speed_m_per_s):
    """Cost of transport (J/kg/m): average metabolic rate (W/kg) divided by speed (m/s).

    Gross if the rate includes basal heat (as :func:`whole_body_rate`'s ``mean_W_per_kg``
    does by default), net if it does not.
    """
    rate = np.asarray(mean_W_per_kg, dtype=float)
    speed = np.asarray(speed_m_per_s, dtype=float)
    if not np.all(np.isfinite(speed)) or np.any(speed <= 0):
        raise OptionError(f"walking speed must be positive (m/s), not {speed_m_per_s!r}")
    if not np.all(np.isfinite(rate)):
        raise OptionError("the metabolic rate holds NaN or infinite values")
    out = rate / speed
    return float(out) if out.ndim == 0 else out


def brockway_rate_W(vo2_mL_per_s, vco2_mL_per_s, urinary_nitrogen_mg_per_s=0.0):
    """Metabolic rate (W) from respiratory gas exchange, Brockway (1987).

    Reference: Brockway JM (1987) Derivation of formulae used to calculate energy
    expenditure in man. Hum Nutr Clin Nutr 41:463-471.

    ``Edot [W] = 16.58 VO2 [mL/s] + 4.51 VCO2 [mL/s] - 5.90 N [mg/s]``

    (16.58 kJ per litre of O2 = 16.58 J/mL, 4.51 kJ/L of CO2, 5.90 kJ per gram of urinary
    nitrogen = 5.90 J/mg). The nitrogen term is usually neglected (default 0). For rates
    in mL/min divide by 60; for W/kg divide the result by body mass. The study averaged the
    last 3 min of each 6-min treadmill bout (gross rate).
    """
    vo2 = np.asarray(vo2_mL_per_s, dtype=float)
    vco2 = np.asarray(vco2_mL_per_s, dtype=float)
    n = np.asarray(urinary_nitrogen_mg_per_s, dtype=float)
    for name, x in (("vo2_mL_per_s", vo2), ("vco2_mL_per_s", vco2), ("urinary_nitrogen_mg_per_s", n)):
        if not np.all(np.isfinite(x)) or np.any(x < 0):
            raise OptionError(f"Brockway: {name} must be finite and not negative")
    c = BROCKWAY_COEFFICIENTS
    out = c["o2_J_per_mL"] * vo2 + c["co2_J_per_mL"] * vco2 - c["urinary_nitrogen_J_per_mg"] * n
    return float(out) if out.ndim == 0 else out
