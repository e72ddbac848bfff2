"""Figures of a study: pure functions from tables and solutions to matplotlib figures.

Every function takes DataFrames or solver objects, returns a :class:`matplotlib.figure.Figure`
(drawn with the non-interactive Agg canvas, never through ``pyplot``) and does no file I/O;
:func:`save_figure` writes a figure as PNG and SVG. A function raises
:class:`~musclemetab.errors.OptionError` when its data cannot make the figure (no measured
rates, a model absent from the table, ...); the report shows the message instead.

Colours are fixed by name, from one place (:mod:`musclemetab.colours`, the Okabe-Ito palette
that colour-blind readers can tell apart): each metabolic model has one colour (the same as in
the Figure-2 plot of :mod:`musclemetab.metabolics.figure2`), each workflow one colour and each
muscle group one colour, in every figure. Names not known in advance get a colour derived from the name,
so they too keep it from one figure to the next.

Units: metabolic rates in W (one leg, summed muscles, no basal heat) over the gait cycle,
whole-body averages in W/kg of body mass (both legs, with basal heat), shares in %, speeds in
m/s, the gait cycle in % from initial contact to the next initial contact of the same leg.

The functions live in modules by topic, all of them gathered here, from where the report
(:mod:`.plan`) and users import them: :mod:`.fig_data` (names, colours, the tables' helpers),
:mod:`.fig_layout` (the fixed layout, texts fitted when saved, :func:`save_figure`),
:mod:`.fig_cycle` (over the gait cycle), :mod:`.fig_models` (the energy models compared),
:mod:`.fig_shares` (shares and speed), :mod:`.fig_muscles` (single muscles). A figure of another
module (``passive_figure``, ``spread_figure``) draws with the same helpers and joins the report
through :mod:`.plan`.
"""

from __future__ import annotations

from .fig_data import (  # noqa: F401
    MODEL_COLOURS,
    WORKFLOW_COLOURS,
    GROUP_COLOURS,
    GROUPS,
    GROUP_NAMES,
    default_muscles,
    _study_model_default_muscles,
    PLATEAU_BAND,
    DESCENDING_LIMB,
    _FALLBACK,
    _MARKERS,
    _LINESTYLES,
    _named_colour,
    model_colour,
    workflow_colour,
    group_colour,
    _require_columns,
    _ok_rows,
    _unique,
    _ordered_models,
    _ordered_workflows,
    trial_order,
    preferred_trial,
    main_workflow,
    group_stats,
    stat_cell,
    _one_workflow,
    _rmcorr,
    _p_text,
)
from .fig_layout import (  # noqa: F401
    _MARGINS_IN,
    _new_figure,
    _in_view_locator,
    _fewer_ticks,
    _apply_layout,
    _adjust,
    _wrap_to,
    _fit_texts,
    _panel_title,
    _legend_below,
    _grid,
    _add_bars,
    _vline,
    _hline,
    _hspan,
    _bar_limits,
    save_figure,
)
from .fig_cycle import (  # noqa: F401
    _match_muscle,
    excitations_and_fiber_lengths,
    _long_table,
    _cycle_panels,
    _label_cycle_panels,
    _models_and_toe_off,
    group_rates_over_cycle,
    whole_body_over_cycle,
)
from .fig_models import (  # noqa: F401
    estimated_vs_measured,
    figure2_compact,
)
from .fig_shares import (  # noqa: F401
    _speed_table,
    phase_shares,
    phase_pies,
    group_shares,
    rates_against_speed,
)
from .fig_muscles import (  # noqa: F401
    per_muscle_ranked,
    anatomical_muscles,
    muscle_names,
    harmonise_muscles,
    muscle_heat_map,
)

__all__ = [
    "MODEL_COLOURS",
    "WORKFLOW_COLOURS",
    "GROUP_COLOURS",
    "GROUPS",
    "DEFAULT_MUSCLES",
    "PLATEAU_BAND",
    "DESCENDING_LIMB",
    "model_colour",
    "workflow_colour",
    "group_colour",
    "trial_order",
    "preferred_trial",
    "main_workflow",
    "excitations_and_fiber_lengths",
    "estimated_vs_measured",
    "group_rates_over_cycle",
    "whole_body_over_cycle",
    "phase_shares",
    "phase_pies",
    "group_shares",
    "per_muscle_ranked",
    "rates_against_speed",
    "save_figure",
    "group_stats",
    "stat_cell",
]


def __getattr__(name: str):
    # DEFAULT_MUSCLES: side-free names of the figure's muscles in the study's model
    # (``default_muscles`` of it), read from the muscle table when first asked for
    if name == "DEFAULT_MUSCLES":
        value = globals()["DEFAULT_MUSCLES"] = _study_model_default_muscles()
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
