"""Figures and the HTML report of a study folder.

:mod:`.figures` holds the figure functions (pure: tables and solutions in, a matplotlib
figure out) and :func:`save_figure`; :mod:`.html` reads a study folder and writes
``figures/`` and ``report.html`` (:func:`write_report`); ``musclemetab report`` is
:mod:`musclemetab.commands.report`.
OpenSim is never imported here.
"""

from .figures import (
    GROUP_COLOURS,
    GROUPS,
    MODEL_COLOURS,
    WORKFLOW_COLOURS,
    estimated_vs_measured,
    excitations_and_fiber_lengths,
    group_rates_over_cycle,
    group_shares,
    phase_shares,
    save_figure,
    whole_body_over_cycle,
)
from .html import FIGURE_NAMES, read_study_folder, write_report


def __getattr__(name: str):
    # DEFAULT_MUSCLES is read from the muscle table only when asked for
    if name == "DEFAULT_MUSCLES":
        from . import figures

        return figures.DEFAULT_MUSCLES
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = [
    "excitations_and_fiber_lengths",
    "estimated_vs_measured",
    "group_rates_over_cycle",
    "whole_body_over_cycle",
    "phase_shares",
    "group_shares",
    "save_figure",
    "write_report",
    "read_study_folder",
    "FIGURE_NAMES",
    "DEFAULT_MUSCLES",
    "GROUPS",
    "MODEL_COLOURS",
    "WORKFLOW_COLOURS",
    "GROUP_COLOURS",
]
