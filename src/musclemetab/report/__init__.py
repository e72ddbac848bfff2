"""Figures and the HTML report of a study folder.

One module per job, each using only those before it:

* :mod:`.figures`: the figure functions (pure: tables and solutions in, a matplotlib figure
  out) and :func:`save_figure`;
* :mod:`.folder`: reading a study folder (:func:`read_study_folder`), the one reader of its layout;
* :mod:`.cli_folder`: reading the output folders of ``musclemetab analyse`` into the same
  :class:`~.folder.StudyFolder` (:func:`~.cli_folder.read_report_input` decides which);
* :mod:`.plan`: which figures, in what order, from what data (:data:`FIGURE_NAMES`);
* :mod:`.draw`: drawing them side by side in forked processes, largest first;
* :mod:`.page`: the HTML page (the template ``templates/report.html``);
* :mod:`.build`: :func:`write_report`, and the content key deciding whether to rebuild;
``musclemetab report`` is :mod:`musclemetab.commands.report`.

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
from .build import write_report
from .folder import read_study_folder
from .plan import FIGURE_NAMES


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
