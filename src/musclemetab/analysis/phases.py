"""Relative metabolic cost of stance and swing (``docs/analysis.md``).

::

    C_stance = integral_IC^TO Edot dt / integral_IC^IC2 Edot dt * 100 %
    C_swing  = 100 % - C_stance

``Edot`` is the summed metabolic rate of the simulated leg's muscles (W). Integrals use
the trapezoidal rule on the samples, with the rate at IC, TO and IC2 linearly
interpolated between the neighbouring samples (the integral of the piecewise-linear
interpolant of the samples), so event times need not fall on samples.

Basal heat: the caller chooses the rate. The study's paper does not say whether its
phase costs included basal heat; a per-muscle basal term adds a constant to ``Edot`` and
dilutes phase differences. The recommended (and :mod:`musclemetab.analysis.unit`'s
default) reporting is *without* basal heat (``MetabolicRates.total_without_basal()``),
with the basal-inclusive value (``MetabolicRates.total``) given alongside.
"""

from __future__ import annotations

import numpy as np

from ..errors import DataMismatchError
from ..events import as_signal, as_time, coverage, integrate_interval
from ..events import GaitCycle

__all__ = ["phase_shares"]


def phase_shares(time_s, rate_W, cycle: GaitCycle, *, coverage_tolerance_s: float | None = None) -> dict:
    """Shares of stance and swing in the metabolic energy of one gait cycle.

    Parameters
    ----------
    time_s : (T,) s, strictly increasing
    rate_W : (T,) W, or (muscles, T) summed over the leading axes first
        Metabolic rate of the leg, with or without basal heat (the caller's choice).
    cycle : GaitCycle
    coverage_tolerance_s : s
        How much of the cycle the samples may miss at either end (default 1.5 times the
        largest sample interval). The solver's trimmed nodes, for instance, end one mesh
        interval before the next initial contact. The missing part is not extrapolated:
        the integrals run over the part of the cycle the samples cover.

    Returns
    -------
    dict
        ``stance_pct``, ``swing_pct`` (%), ``stance_J``, ``swing_J``, ``cycle_J`` (J, one
        leg), and ``start_s``, ``end_s``, the integration limits used.

    Raises
    ------
    DataMismatchError
        Shapes disagree, the samples do not cover the cycle (or toe-off), or the cycle's
        energy is zero.
    OptionError
        NaN or non-increasing times.
    """
    t = as_time(time_s, "time_s")
    y = as_signal(rate_W, t, "rate_W")
    if y.ndim > 1:
        y = y.reshape(-1, t.size).sum(axis=0)
    if not isinstance(cycle, GaitCycle):
        raise DataMismatchError(f"cycle must be a GaitCycle, not {type(cycle).__name__}")
    a, b = coverage(t, cycle.start_s, cycle.end_s, coverage_tolerance_s, "rate_W")
    if not a < cycle.toe_off_s < b:
        raise DataMismatchError(
            f"toe-off ({cycle.toe_off_s:g} s) is outside the sampled part of the cycle ({a:g}-{b:g} s)"
        )
    stance = float(integrate_interval(t, y, a, cycle.toe_off_s))
    swing = float(integrate_interval(t, y, cycle.toe_off_s, b))
    whole = stance + swing
    if whole == 0 or not np.isfinite(whole):
        raise DataMismatchError(
            f"the metabolic energy of the cycle is {whole:g} J; relative phase costs are undefined"
        )
    return {
        "stance_pct": 100.0 * stance / whole,
        "swing_pct": 100.0 * swing / whole,
        "stance_J": stance,
        "swing_J": swing,
        "cycle_J": whole,
        "start_s": a,
        "end_s": b,
    }
