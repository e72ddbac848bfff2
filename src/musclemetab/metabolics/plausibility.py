"""Plausibility checks of the metabolic results: whole-body rate against walking speed, and
negative muscle-group rates.

Pure functions giving a :class:`~musclemetab.quality.Flag` (``model`` set) or
``None``; the thresholds are documented constants, overridable by keyword. The solver-level
checks are in :mod:`musclemetab.redundancy.plausibility`; ``docs/quality.md`` lists them all.

The whole-body band is built on Ralston's regression of gross metabolic rate on walking speed
from indirect calorimetry (Ralston HJ 1958, *Energy-speed relation and optimal speed during
level walking*, Int Z Angew Physiol 17:277-283):
``E = 29 + 0.0053 v^2`` cal/(kg min), ``v`` in m/min, i.e. ``E(v) = (29 + 0.0053 (60 v)^2) 4.184 / 60``
W/kg with ``v`` in m/s (4.27 W/kg at 1.3 m/s; the study's own calorimetry at preferred speed,
4.5 [1.1] W/kg, agrees). A model's gross whole-body rate is flagged outside
``[RATE_BAND[0] E(v), RATE_BAND[1] E(v)]``. Without a speed, a rate above
:data:`SPEED_FREE_UPPER_W_PER_KG` is flagged: Ralston's rate at the fastest walking speed of his
range, 2.0 m/s, ``E(2.0) = 7.34`` W/kg, which no level walking exceeds.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from ..quality import Flag
from .solution import PLAUSIBILITY_FILE, add_legs
from ..messages import name_list

__all__ = ["PLAUSIBILITY_FILE", "legs_rate_flags", "results_rows_flags", "write_plausibility", "RATE_BAND",
           "ralston_gross_rate_W_per_kg", "whole_body_rate_flag", "negative_group_flag", "metabolic_flags", "add_quality",
           "SPEED_RANGE_M_PER_S", "SPEED_FREE_UPPER_W_PER_KG", "is_gait_cycle", "excluded_muscles_flag",
           "gait_cycle_flag"]

#: The plausible band of the gross whole-body rate, as factors of Ralston's rate at the speed.
#: Low: half (a rate below it is below standing rest plus a little walking). High: twice, which
#: holds the subjects' spread (the study's calorimetry: SD 24 % of the mean at preferred speed)
#: on top of the models' known overestimation with the effort workflows (Luis et al. 2024,
#: Table 2: up to 1.76 x the measured mean, LW07 with EFFORT-GEN, 7.9 against 4.5 W/kg); their
#: EMG-TEN rates reach 2.7 x (LW07, 12.2 W/kg) and lie above it (``docs/quality.md``).
RATE_BAND = (0.5, 2.0)
#: Speeds (m/s) over which Ralston's regression was fitted (about 0.5 to 2.0 m/s, level walking);
#: outside them the check is not made.
SPEED_RANGE_M_PER_S = (0.5, 2.0)
_CAL_J = 4.184


def ralston_gross_rate_W_per_kg(speed_m_per_s) -> np.ndarray:
    """Ralston's (1958) gross metabolic rate of level walking at ``speed_m_per_s`` (W/kg)."""
    v = 60.0 * np.asarray(speed_m_per_s, dtype=float)  # m/min
    return (29.0 + 0.0053 * v**2) * _CAL_J / 60.0


#: The gross whole-body rate (W/kg) above which a rate is flagged when the walking speed is not
#: known: Ralston's rate at the top of his speed range, 2.0 m/s (about where people change from
#: walking to running), ``(29 + 0.0053 x 120^2) x 4.184 / 60 = 7.34`` W/kg; no level walking costs
#: more. It is a bound on the walking, not on the models' overestimation: with a speed the band
#: is used instead (``docs/quality.md``).
SPEED_FREE_UPPER_W_PER_KG = float(ralston_gross_rate_W_per_kg(SPEED_RANGE_M_PER_S[1]))


def whole_body_rate_flag(model: str, mean_W_per_kg: float, speed_m_per_s: float | None, *,
                         band: tuple[float, float] = RATE_BAND,
                         speed_free_upper: float = SPEED_FREE_UPPER_W_PER_KG) -> Flag | None:
    """``model``'s gross whole-body rate (W/kg, with basal heat) outside ``band`` x Ralston's rate
    at the speed; with the speed unknown, above ``speed_free_upper`` (the rate of the fastest
    walking, :data:`SPEED_FREE_UPPER_W_PER_KG`); ``None`` when the speed is outside
    :data:`SPEED_RANGE_M_PER_S` (or the rate is not a number)."""
    if not np.isfinite(mean_W_per_kg):
        return None
    if speed_m_per_s is None or not np.isfinite(speed_m_per_s):
        if mean_W_per_kg <= speed_free_upper:
            return None
        return Flag("metabolic_rate", f"{model}: whole-body rate {mean_W_per_kg:.2f} W/kg is above "
                    f"{speed_free_upper:.2f} W/kg, the gross rate of walking at {SPEED_RANGE_M_PER_S[1]:g} m/s "
                    "(Ralston 1958), which no level walking exceeds (the speed is unknown: give it for the band at "
                    "the trial's speed); look at the solver flags of the unit and at the muscles costing most",
                    {model: float(mean_W_per_kg)}, speed_free_upper, model=model)
    if not SPEED_RANGE_M_PER_S[0] <= speed_m_per_s <= SPEED_RANGE_M_PER_S[1]:
        return None
    ref = float(ralston_gross_rate_W_per_kg(speed_m_per_s))
    lo, hi = band[0] * ref, band[1] * ref
    if lo <= mean_W_per_kg <= hi:
        return None
    word = "above" if mean_W_per_kg > hi else "below"
    return Flag("metabolic_rate", f"{model}: whole-body rate {mean_W_per_kg:.2f} W/kg is {word} the band of walking "
                f"at {speed_m_per_s:.2f} m/s, {lo:.2f}-{hi:.2f} W/kg ({band[0]:g}-{band[1]:g} x Ralston 1958, "
                f"{ref:.2f} W/kg); look at the solver flags of the unit and at the muscles costing most",
                {model: float(mean_W_per_kg)}, band[1] if word == "above" else band[0], model=model)


def negative_group_flag(model: str, group_share_pct: Mapping[str, float]) -> Flag | None:
    """Muscle groups of ``model`` whose share of the cycle's muscle energy is negative
    (``{group: share_<G>_pct}``): the group's muscles return more energy than they spend,
    which muscles do not (positive work costs more than negative work returns)."""
    items = {g: float(v) for g, v in sorted(group_share_pct.items(), key=lambda kv: kv[1])
             if np.isfinite(v) and v < 0}
    if not items:
        return None
    listing = ", ".join(f"{g} {v:.1f} %" for g, v in items.items())
    return Flag("negative_group_rate", f"{model}: negative muscle-group rates (share of the leg's muscle energy): "
                f"{listing}; the model's negative-work term dominates these muscles' rates", items, 0.0, model=model)


def is_gait_cycle(duration_s: float, named_by_events: bool = True) -> bool:
    """Whether rates averaged over ``duration_s`` seconds are a gait cycle's: gait events bound the
    span (``named_by_events``: not a solve over an explicit ``--window`` taken as it is) and its
    duration lies within walking's, 0.8-2.0 s (:data:`musclemetab.events.WALKING_CYCLE_DURATION_S`)."""
    from ..events import WALKING_CYCLE_DURATION_S

    lo, hi = WALKING_CYCLE_DURATION_S
    return bool(named_by_events) and bool(np.isfinite(duration_s)) and lo <= float(duration_s) <= hi


def gait_cycle_flag(start_s, end_s, duration_s: float, named_by_events: bool) -> Flag | None:
    """The rates of a results row averaged over a span that is not one gait cycle
    (:func:`is_gait_cycle`): a window no gait event bounds, or one of a duration walking's
    cycle does not have; ``None`` for a gait cycle."""
    if is_gait_cycle(duration_s, named_by_events):
        return None
    from ..events import WALKING_CYCLE_DURATION_S

    span = f"{start_s:g}-{end_s:g} s" if np.isfinite(start_s) and np.isfinite(end_s) else f"{duration_s:g} s"
    why = ("no gait event bounds it (a solve over a window)" if not named_by_events else
           f"its duration {duration_s:.3g} s is outside walking's {WALKING_CYCLE_DURATION_S[0]:g}-"
           f"{WALKING_CYCLE_DURATION_S[1]:g} s")
    return Flag("not_a_gait_cycle", f"the rates are averaged over {span}, which is not shown to be one gait cycle: "
                f"{why}; for a gait cycle's rates give its events (analyse --cycle START,TOE_OFF,END or --grf; a "
                "study trial's start_s, toe_off_s and end_s, or grf) or solve over a cycle (--cycle, a study "
                "trial's cycle)", {span: float(duration_s)}, None)


def excluded_muscles_flag(names) -> Flag | None:
    """Rates that leave out the muscles a solve excluded (``--exclude-muscles``): the leg's and
    the whole body's rates are those of the other muscles; ``None`` when none was excluded."""
    names = [n for n in (names or ()) if n]
    if not names:
        return None
    return Flag("excluded_muscles", f"the rates leave out {len(names)} muscle{'s' if len(names) != 1 else ''} the "
                f"solve excluded ({name_list(names)}): the leg's and the whole body's rates are those of the other "
                "muscles", {n: 1.0 for n in names}, None)


def metabolic_flags(whole_body: Mapping[str, float], speed_m_per_s: float | None,
                    group_shares=None, *, band: tuple[float, float] = RATE_BAND) -> list[Flag]:
    """The metabolic checks of every model: ``whole_body`` ``{model: mean_W_per_kg}``;
    ``group_shares`` the analysis table (one row per ``model``, columns ``share_<G>_pct``), if any."""
    flags = [whole_body_rate_flag(m, v, speed_m_per_s, band=band) for m, v in whole_body.items()]
    if group_shares is not None and len(group_shares):
        cols = [c for c in group_shares.columns if c.startswith("share_") and c.endswith("_pct")
                and not c.endswith("_with_basal_pct") and c != "share_other_pct"]
        for _, row in group_shares.iterrows():
            flags.append(negative_group_flag(str(row["model"]), {c[6:-4]: float(row[c]) for c in cols}))
    return [f for f in flags if f is not None]


def results_rows_flags(rows, *, band: tuple[float, float] = RATE_BAND) -> list[Flag]:
    """The metabolic checks of a results table (``results.csv``: one row per ``model``, with
    ``whole_body_W_per_kg``, ``speed_m_per_s`` and the group shares ``share_<G>_pct``), row by row:
    what the ``quality`` column of each row adds to the solve's flags."""
    return [f for i in range(len(rows)) for f in _row_flags(rows.iloc[[i]], band)]


def _row_flags(row, band: tuple[float, float] = RATE_BAND) -> list[Flag]:
    """The metabolic flags of one results row (a one-row table)."""
    import pandas as pd

    speed = row["speed_m_per_s"].iloc[0] if "speed_m_per_s" in row else None
    speed = float(speed) if speed is not None and pd.notna(speed) else None
    flags = metabolic_flags({str(row["model"].iloc[0]): float(row["whole_body_W_per_kg"].iloc[0])}, speed, row,
                            band=band)
    if "gait_cycle" in row and not bool(row["gait_cycle"].iloc[0]):
        def value(c):
            return float(row[c].iloc[0]) if c in row and pd.notna(row[c].iloc[0]) else float("nan")

        # a duration walking's cycle has: no gait event bounds the span; otherwise its duration is said
        named = not is_gait_cycle(value("duration_s"))
        flags.append(gait_cycle_flag(value("cycle_start_s"), value("cycle_end_s"), value("duration_s"), named))
    if "excluded_muscles" in row:
        text = row["excluded_muscles"].iloc[0]
        flags.append(excluded_muscles_flag(str(text).split() if isinstance(text, str) else ()))
    return [f for f in flags if f is not None]


def legs_rate_flags(results: Mapping, speed_m_per_s: float | None, *, band: tuple[float, float] = RATE_BAND) -> list[Flag]:
    """The whole-body rate checks of :func:`~.solution.metabolics_from_legs`'s ``{side: SolutionMetabolics}``:
    one leg's rate (that leg doubled), or the two legs added (:func:`~.solution.add_legs`)."""
    if len(results) == 1:
        (result,) = results.values()
        rates = {m: result.whole_body[m].mean_W_per_kg for m in result.models}
    else:
        rates = add_legs(results)
    return metabolic_flags(rates, speed_m_per_s, band=band)


def write_plausibility(flags, out_dir):
    """Write ``out_dir/plausibility.json`` (:data:`PLAUSIBILITY_FILE`): the flags as a JSON list."""
    import json
    from pathlib import Path

    from ..io import atomic_write_text

    path = Path(out_dir) / PLAUSIBILITY_FILE
    atomic_write_text(path, json.dumps([f.to_dict() for f in flags], indent=2) + "\n", mark=True)
    return path


def add_quality(rows, unit_records):
    """``rows`` (one results row per model) with the column ``quality``: ``"ok"`` or the flags
    (:func:`musclemetab.quality.quality_text`) of the solve (every leg's, from the
    ``plausibility`` of ``unit_records``: ``unit.json`` dictionaries or solve records) and of the row's metabolic results (its whole-body rate
    against its speed, its negative group shares: :func:`musclemetab.metabolics.plausibility.metabolic_flags`);
    ``"not checked"`` when a unit record has no ``plausibility`` (written by an earlier version)."""
    from ..quality import flags_from_records, quality_text

    if any("plausibility" not in r for r in unit_records):
        rows["quality"] = "not checked"
        return rows
    solve = [f for r in unit_records for f in flags_from_records(r.get("plausibility")) if f.model is None]
    rows["quality"] = [quality_text(solve + _row_flags(rows.iloc[[i]])) for i in range(len(rows))]
    return rows
