"""Figure of a study's assisted trials (``docs/assistance.md``): what the device saves, for how much work.

Three panels, of the first assisted trial of the results (its subject, unassisted trial and
the report's main workflow):

* the design curve: the whole-body metabolic saving (W/kg) against the device's average positive
  power (W/kg, both legs), one line per energy model through the gains (each gain marked);
* the change per muscle at the largest gain (J per cycle, one leg, no basal heat; the muscles
  changing most, the first model);
* the change of the leg, per phase and per muscle group at the same gain and model (horizontal
  bars, the leg on top).

Drawn from the results table and ``assistance.csv`` (:mod:`musclemetab.analysis.assistance`);
the Agg canvas.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["assistance_figure", "assistance_caption", "has_assistance", "MAX_MUSCLES"]

#: the muscles shown in the per-muscle panel (those changing most)
MAX_MUSCLES = 12


def has_assistance(results) -> bool:
    """Whether the results table holds assisted trials."""
    return "assisted_from" in results and bool(results["assisted_from"].notna().any())


def _breakdown(folder: Path):
    from ..analysis.assistance import ASSISTANCE_CSV
    from ..errors import InputFileError
    from ..io.csvfile import read_csv_file

    path = Path(folder) / ASSISTANCE_CSV
    if not path.is_file():
        raise InputFileError(f"{path}: missing; run the study again (musclemetab run) to write it")
    return read_csv_file(path, "run the study again (musclemetab run) to write it", "assistance table")


def assistance_figure(results, folder, workflow: str | None = None, models=None):
    """The figure (module docstring) of a study's results table and its folder (``assistance.csv``)."""
    from ..errors import OptionError
    from .figures import _new_figure, _ordered_models, _panel_title, main_workflow, model_colour

    rows = results[results["assisted_from"].notna()] if "assisted_from" in results else results.iloc[0:0]
    rows = rows[rows["metabolic_saving_W_per_kg"].notna()] if "metabolic_saving_W_per_kg" in rows else rows.iloc[0:0]
    if rows.empty:
        raise OptionError("no assisted trial with its unassisted trial in the results: nothing to compare")
    workflow = workflow or main_workflow(list(dict.fromkeys(rows["workflow"].astype(str))))
    rows = rows[rows["workflow"].astype(str) == workflow]
    first = rows.iloc[0]
    subject, base = str(first["subject"]), str(first["assisted_from"])
    rows = rows[(rows["subject"].astype(str) == subject) & (rows["assisted_from"].astype(str) == base)]
    shown = _ordered_models(rows["model"]) if models is None else [m for m in _ordered_models(rows["model"])
                                                                   if m in set(models)]
    if not shown:
        raise OptionError("none of the report's models has assisted rows")
    fig = _new_figure(14.0, 4.6, bottom=0.75, wspace=0.45, left=0.8)
    ax_curve, ax_muscles, ax_groups = fig.subplots(1, 3, gridspec_kw={"width_ratios": [1.0, 1.1, 1.2]})
    for model in shown:
        r = rows[rows["model"].astype(str) == model].sort_values("assistance_gain")
        x = np.concatenate(([0.0], r["device_positive_power_W_per_kg"].to_numpy(float)))
        y = np.concatenate(([0.0], r["metabolic_saving_W_per_kg"].to_numpy(float)))
        ax_curve.plot(x, y, marker="o", markersize=4, color=model_colour(model), label=model, gid=f"model:{model}")
        for xi, yi, g in zip(x[1:], y[1:], r["assistance_gain"]):
            ax_curve.annotate(f"{g:g}", (xi, yi), textcoords="offset points", xytext=(3, 3), fontsize=6,
                              color=model_colour(model))
    ax_curve.axhline(0.0, color="0.6", linewidth=0.5)
    ax_curve.set_xlabel("device positive power (W/kg, both legs)")
    ax_curve.set_ylabel("metabolic saving (W/kg, whole body)")
    ax_curve.grid(linewidth=0.3, alpha=0.5)
    ax_curve.legend(fontsize=7, frameon=False, loc="upper left")
    _panel_title(ax_curve, f"{subject} {base}, {workflow}: saving against device work\n(labels: gain)", fontsize=8)

    model = shown[0]
    gain = float(rows["assistance_gain"].max())
    table = _breakdown(folder)
    b = table[(table["subject"].astype(str) == subject) & (table["assisted_from"].astype(str) == base)
              & (table["workflow"].astype(str) == workflow) & (table["model"].astype(str) == model)
              & np.isclose(table["assistance_gain"].astype(float), gain)]
    muscles = b[b["level"] == "muscle"]
    muscles = muscles.reindex(muscles["change_J"].abs().sort_values(ascending=False).index).head(MAX_MUSCLES)[::-1]
    colours = ["#1f77b4" if c < 0 else "#d62728" for c in muscles["change_J"]]
    ax_muscles.barh(range(len(muscles)), muscles["change_J"], color=colours)
    ax_muscles.set_yticks(range(len(muscles)), muscles["part"].astype(str), fontsize=7)
    ax_muscles.axvline(0.0, color="0.3", linewidth=0.6)
    ax_muscles.set_xlabel("change (J per cycle, one leg)")
    _panel_title(ax_muscles, f"muscles changing most, gain {gain:g}, {model}", fontsize=8)

    parts = b[b["level"].isin(["group", "phase", "leg"])]
    parts = parts[parts["unassisted_J"].abs() > 0]
    labels = [f"{p}" if lv != "phase" else f"{p} (phase)" for lv, p in zip(parts["level"], parts["part"])]
    colours = ["#1f77b4" if c < 0 else "#d62728" for c in parts["change_J"]]
    # horizontal bars, the leg on top: labels read level, one per row (slanted under vertical bars,
    # the boxes of neighbouring labels overlapped)
    rows = np.arange(len(parts))[::-1]
    ax_groups.barh(rows, parts["change_J"], color=colours)
    ax_groups.set_yticks(rows, labels, fontsize=7)
    ax_groups.axvline(0.0, color="0.3", linewidth=0.6)
    ax_groups.set_xlabel("change (J per cycle, one leg)")
    ax_groups.grid(axis="x", linewidth=0.3, alpha=0.5)
    _panel_title(ax_groups, f"leg, phases and muscle groups, gain {gain:g}, {model}", fontsize=8)
    fig.suptitle("Assisted walking: metabolic change against the unassisted trial (blue: saved, red: added)",
                 fontsize=11)
    return fig


def assistance_caption() -> str:
    return ("An assistive device's torque taken off the inverse-dynamics moments before the muscles are solved "
            "(docs/assistance.md). Left: the design curve, the whole-body metabolic saving (unassisted less assisted "
            "rate, W per kg of body mass, with basal heat) against the device's average positive power over the gait "
            "cycle (W/kg, both legs), through the gains of the study (labels), one line per energy model. Middle: "
            "the muscles whose metabolic energy over the cycle (J, one leg, without basal heat) changes most at the "
            "largest gain; right: the change of the leg, the stance and swing phases and the muscle groups "
            "(muscle_groups.csv) at that gain. The whole tables are results.csv (saving, device work, saving per "
            "unit positive work, augmentation factor) and assistance.csv.")
