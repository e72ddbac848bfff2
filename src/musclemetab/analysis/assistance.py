"""Assisted against unassisted: the change a device makes, whole body, per muscle, group and phase.

A study trial with an ``assistance`` key is solved unassisted and once per gain (the trials
``<trial>_assist-<gain>``, ``assisted_from`` naming the unassisted one; ``docs/assistance.md``).
:func:`device_columns` gives an assisted unit's device columns of the results table,
:func:`add_assistance_changes` the whole-body change of each assisted row against its
unassisted row (same subject, workflow and model), and :func:`assistance_breakdown` the
per-muscle, per-group and per-phase table (``assistance.csv``).

Definitions (``docs/assistance.md``):

* metabolic saving = unassisted - assisted ``whole_body_W_per_kg`` (positive: the device saves);
* device power per kg: the device's average positive (negative) power over the gait cycle, both
  legs per kg of body mass, counted as the whole-body rate counts the legs (one leg's device
  doubled, or the two legs' devices added);
* saving per unit positive work = metabolic saving / device positive power (J of metabolic energy
  saved per J of positive device work);
* augmentation factor (Mooney, Rouse & Herr 2014, J NeuroEng Rehabil 11:80) =
  ``(P+ - |P-|) / 0.41`` (:func:`musclemetab.assistance.augmentation_factor_W_per_kg`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["ASSISTANCE_CSV", "DEVICE_COLUMNS", "CHANGE_COLUMNS", "device_columns", "add_assistance_changes",
           "assistance_breakdown", "BREAKDOWN_COLUMNS"]

#: the study's per-muscle, per-group and per-phase table of the assisted trials
ASSISTANCE_CSV = "assistance.csv"
#: the device columns of an assisted row of the results table (:func:`device_columns`)
DEVICE_COLUMNS = ("assisted_from", "assistance_gain", "device_positive_work_J", "device_negative_work_J",
                  "device_positive_work_J_per_kg", "device_negative_work_J_per_kg",
                  "device_positive_power_W_per_kg", "device_negative_power_W_per_kg")
#: the columns :func:`add_assistance_changes` adds
CHANGE_COLUMNS = ("metabolic_saving_W_per_kg", "metabolic_saving_pct", "saving_per_positive_work",
                  "augmentation_factor_W_per_kg")
BREAKDOWN_COLUMNS = ("subject", "trial", "workflow", "model", "assisted_from", "assistance_gain", "level", "part",
                     "unassisted_J", "assisted_J", "change_J", "change_pct")
#: legs the whole-body columns count per leg solved (one leg doubled; each of two legs' rows doubled and averaged)
_LEGS = 2.0


def device_columns(device: dict) -> dict:
    """The device columns of an assisted unit's rows from its record's ``assistance``
    (:func:`musclemetab.study.units._device_record`): this leg's device work (J and J/kg per
    cycle) and both legs' average powers per kg."""
    mass = float(device["body_mass_kg"])
    pos, neg = float(device["positive_work_J"]), float(device["negative_work_J"])
    duration = float(device["duration_s"])
    return {"assisted_from": device["assisted_from"], "assistance_gain": float(device["gain"]),
            "device_positive_work_J": pos, "device_negative_work_J": neg,
            "device_positive_work_J_per_kg": pos / mass, "device_negative_work_J_per_kg": neg / mass,
            "device_positive_power_W_per_kg": _LEGS * pos / duration / mass,
            "device_negative_power_W_per_kg": _LEGS * neg / duration / mass}


def _base_rows(table, keys=("subject", "workflow", "model")):
    """``{(subject, trial, workflow, model): row}`` of ``table``."""
    return {tuple(r[k] for k in ("subject", "trial", *keys[1:])): r for _, r in table.iterrows()}


def add_assistance_changes(table):
    """``table`` (the results table) with :data:`CHANGE_COLUMNS` for its assisted rows (NaN for
    the others, and for an assisted row whose unassisted row is missing); unchanged when it has
    no assisted row."""
    from ..redundancy.assistance import augmentation_factor_W_per_kg

    if "assisted_from" not in table or not table["assisted_from"].notna().any():
        return table
    table = table.copy()
    base = _base_rows(table)
    out = {c: np.full(len(table), np.nan) for c in CHANGE_COLUMNS}
    for i, (_, row) in enumerate(table.iterrows()):
        if not isinstance(row["assisted_from"], str):
            continue
        ref = base.get((row["subject"], row["assisted_from"], row["workflow"], row["model"]))
        if ref is None:
            continue
        saving = float(ref["whole_body_W_per_kg"]) - float(row["whole_body_W_per_kg"])
        out["metabolic_saving_W_per_kg"][i] = saving
        out["metabolic_saving_pct"][i] = 100.0 * saving / float(ref["whole_body_W_per_kg"])
        positive = float(row["device_positive_power_W_per_kg"])
        out["saving_per_positive_work"][i] = saving / positive if positive > 0 else np.nan
        out["augmentation_factor_W_per_kg"][i] = augmentation_factor_W_per_kg(
            positive, float(row["device_negative_power_W_per_kg"]))
    for c in CHANGE_COLUMNS:
        table[c] = out[c]
    return table


def _energies(row, muscles) -> list[tuple[str, str, float]]:
    """``(level, name, J)`` of one results row (one leg's energy per cycle, no basal heat) and
    its per-muscle rows: the leg, the stance and swing phases, the muscle groups and the muscles."""
    from .groups import GROUPS_WITH_OTHER

    leg = float(row["leg_energy_J"])
    out = [("leg", "leg", leg)]
    out += [("phase", p, leg * float(row[f"{p}_energy_share_pct"]) / 100.0) for p in ("stance", "swing")]
    out += [("group", g, leg * float(row[f"share_{g}_pct"]) / 100.0) for g in GROUPS_WITH_OTHER
            if f"share_{g}_pct" in row]
    out += [("muscle", str(m), float(j)) for m, j in zip(muscles["muscle"], muscles["energy_per_cycle_J"])]
    return out


def assistance_breakdown(table, per_muscle):
    """The ``assistance.csv`` table: per assisted row of ``table`` (the results table) and level
    (``leg``, ``phase``, ``group``, ``muscle``), each part's energy per gait cycle (J, one leg, no
    basal heat; the legs' mean for ``r + l``) unassisted and assisted, the change
    (assisted - unassisted) and the change in % of the unassisted energy. ``per_muscle`` is
    the study's per-muscle table."""
    import pandas as pd

    rows = []
    if "assisted_from" not in table:
        return pd.DataFrame(columns=list(BREAKDOWN_COLUMNS))
    base = _base_rows(table)
    groups = {k: g for k, g in per_muscle.groupby(["subject", "trial", "workflow", "model"], sort=False)} \
        if len(per_muscle) else {}
    empty = pd.DataFrame({"muscle": [], "energy_per_cycle_J": []})
    for _, row in table.iterrows():
        if not isinstance(row["assisted_from"], str):
            continue
        key = (row["subject"], row["assisted_from"], row["workflow"], row["model"])
        ref = base.get(key)
        if ref is None:
            continue
        before = {(lv, n): j for lv, n, j in _energies(ref, groups.get(key, empty))}
        after = _energies(row, groups.get((row["subject"], row["trial"], row["workflow"], row["model"]), empty))
        for level, name, j in after:
            if (level, name) not in before:
                continue
            j0 = before[(level, name)]
            rows.append({"subject": row["subject"], "trial": row["trial"], "workflow": row["workflow"],
                         "model": row["model"], "assisted_from": row["assisted_from"],
                         "assistance_gain": row["assistance_gain"], "level": level, "part": name,
                         "unassisted_J": j0, "assisted_J": j, "change_J": j - j0,
                         "change_pct": 100.0 * (j - j0) / j0 if j0 else np.nan})
    return pd.DataFrame(rows, columns=list(BREAKDOWN_COLUMNS))
