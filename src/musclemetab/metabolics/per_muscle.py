"""Per-muscle metabolic results of one solved gait cycle: which muscles cost the energy.

One row per model and muscle (``docs/analysis.md`` §6):

``muscle_W``
    the muscle's cycle-average metabolic rate without basal heat (W), computed exactly as the
    whole-body figure averages the leg (trapezoidal integral over the kept solver nodes
    divided by the averaging duration), so that
    ``legs * sum(muscle_W) / body_mass + basal`` is the whole-body ``whole_body_W_per_kg``
    under the ``body`` basal rule, and ``legs * sum(muscle_W + basal_heat_mean_W) / body_mass``
    under the ``muscle`` rule, and ``sum(muscle_W)`` the leg's ``leg_muscles_W``;
``muscle_W_per_kg``
    ``muscle_W`` per kg of body mass (this muscle of one leg, no basal heat);
``energy_per_cycle_J``, ``stance_J``, ``swing_J``
    the muscle's energy (J, no basal heat) over the sampled part of the gait cycle and its
    stance (initial contact to toe-off) and swing parts (given a gait cycle; empty without);
``share_of_leg_pct``
    the muscle's part of the leg's summed ``muscle_W`` (%; the muscles of a leg sum to 100);
``work_mean_W``, ``activation_maintenance_heat_mean_W``, ``shortening_lengthening_heat_mean_W``
    the components that add up to ``muscle_W`` (each counted once: a model's finer split,
    such as separate activation and maintenance heats, is not repeated here);
``basal_heat_mean_W``
    the per-muscle basal heat (1.2 W/kg of muscle mass), apart and never inside ``muscle_W``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import DataMismatchError
from ..events import as_time, coverage, integrate_interval
from ..events import GaitCycle

__all__ = ["PER_MUSCLE_FILE", "PER_MUSCLE_COLUMNS", "COMPONENT_COLUMNS", "per_muscle_table"]

PER_MUSCLE_FILE = "per_muscle.csv"

#: The standard components of :class:`~musclemetab.metabolics.MetabolicRates` and their
#: per-muscle column; the first three add up to ``muscle_W``.
COMPONENT_COLUMNS = {
    "work": "work_mean_W",
    "activation_maintenance": "activation_maintenance_heat_mean_W",
    "shortening_lengthening": "shortening_lengthening_heat_mean_W",
    "basal": "basal_heat_mean_W",
}

#: Columns of :func:`per_muscle_table`, in order.
PER_MUSCLE_COLUMNS = (
    "model", "muscle", "side", "muscle_W", "muscle_W_per_kg", "energy_per_cycle_J", "share_of_leg_pct",
    "stance_J", "swing_J", *COMPONENT_COLUMNS.values(), "rank",
)


def _side_of(name: str) -> str:
    from ..properties import split_side

    return split_side(name)[1]


def per_muscle_table(result, cycle: GaitCycle | None = None, *, side: str | None = None,
                     models: Sequence[str] | None = None, coverage_tolerance_s: float | None = None):
    """Per-muscle results of a :class:`~musclemetab.metabolics.solution.SolutionMetabolics`.

    Parameters
    ----------
    result
        Metabolic rates of one solution (``rates[model]`` of arrays ``(muscles, time)``, W)
        and their whole-body averages.
    cycle
        The gait cycle, for the stance/swing split and the energy per cycle; without it
        those columns are empty (NaN) and ``energy_per_cycle_J`` is ``muscle_W`` times the
        averaging duration.
    side
        ``"r"`` or ``"l"`` for every row (default: the suffix of each muscle name, ``''``
        when it has none).
    models
        A subset of ``result.models`` (default all).

    Returns
    -------
    pandas.DataFrame
        One row per model and muscle with :data:`PER_MUSCLE_COLUMNS`; ``rank`` is 1 for the
        muscle with the largest ``muscle_W`` of each model.
    """
    import pandas as pd

    t = as_time(result.time_s, "result.time_s")
    chosen = list(result.models) if models is None else [str(m).upper() for m in models]
    if cycle is not None:
        if not isinstance(cycle, GaitCycle):
            raise DataMismatchError(f"cycle must be a GaitCycle, not {type(cycle).__name__}")
        a, b = coverage(t, cycle.start_s, cycle.end_s, coverage_tolerance_s, "the metabolic rates")
        if not a < cycle.toe_off_s < b:
            raise DataMismatchError(
                f"toe-off ({cycle.toe_off_s:g} s) is outside the sampled part of the cycle ({a:g}-{b:g} s)"
            )
    sides = [side if side is not None else _side_of(m) for m in result.muscles]
    frames = []
    for model in chosen:
        rates = result.rates[model]
        wb = result.whole_body[model]
        duration = float(wb.duration_s)

        def mean(x):
            x = np.broadcast_to(np.asarray(x, dtype=float), (len(result.muscles), t.size))
            return np.trapezoid(x, t, axis=-1) / duration

        comps = {col: mean(getattr(rates, name)) for name, col in COMPONENT_COLUMNS.items()}
        no_basal = np.asarray(rates.total_without_basal(), dtype=float)
        mean_w = mean(no_basal)
        if cycle is not None:
            stance = integrate_interval(t, no_basal, a, cycle.toe_off_s)
            swing = integrate_interval(t, no_basal, cycle.toe_off_s, b)
            energy = stance + swing
        else:
            stance = swing = np.full(len(result.muscles), np.nan)
            energy = mean_w * duration
        leg = float(mean_w.sum())
        df = pd.DataFrame({
            "model": model,
            "muscle": list(result.muscles),
            "side": sides,
            "muscle_W": mean_w,
            "muscle_W_per_kg": mean_w / result.body_mass_kg,
            "energy_per_cycle_J": energy,
            "share_of_leg_pct": 100.0 * mean_w / leg if leg != 0 else np.nan,
            "stance_J": stance,
            "swing_J": swing,
            **comps,
        })
        df["rank"] = df["muscle_W"].rank(ascending=False, method="first").astype(int)
        frames.append(df)
    return pd.concat(frames, ignore_index=True)[list(PER_MUSCLE_COLUMNS)]
