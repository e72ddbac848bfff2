"""Analyses downstream of the metabolic rates: gait events, phase costs, muscle groups,
statistics.

Pure functions on NumPy arrays and pandas tables, SI units (s, N, N m, m, W, J):

* gait events and the cycle (:class:`GaitCycle`; from vertical ground reaction forces or,
  without forces, from the padded simulation window and the ankle moment) are defined in
  :mod:`musclemetab.events`, where the solver's window takes them from; their names are
  importable from here too;
* :mod:`.phases` -- relative metabolic cost of stance and swing;
* :mod:`.groups` -- ten muscle function groups and the moment-arm-ratio distribution of
  each muscle's rate;
* :mod:`.stats` -- repeated-measures correlation, Bland-Altman limits of agreement;
* :mod:`.unit` -- all of it for one solved cycle and its metabolic rates (:func:`analyse`).

See ``docs/analysis.md`` for the methods and the choices the study leaves open.
"""

from ..events import (
    DEFAULT_GRF_THRESHOLD_N,
    DEFAULT_MIN_DURATION_S,
    DEFAULT_PADDING_S,
    DEFAULT_TOE_OFF_FRACTION,
    GaitCycle,
    GaitEvents,
    cycle_from_grf,
    cycle_from_id_file,
    cycle_from_inverse_dynamics,
    cycle_of_trial,
    gait_events_from_grf,
    read_grf,
)
from .groups import (
    DEFAULT_THRESHOLD_M,
    DOF_GROUPS,
    GROUP_NAMES,
    GROUPS,
    GROUPS_WITH_OTHER,
    OTHER,
    dof_group_pair,
    group_rates,
    group_shares,
    group_weights,
    membership_table,
    muscle_membership,
)
from .phases import phase_shares
from .stats import BlandAltman, RmCorr, bland_altman, rmcorr
from .unit import (
    MetabolicAnalysis,
    TrialAnalysis,
    analyse,
    analyse_metabolics,
    analyse_solution_folder,
    interpolate_moment_arms,
    write_analysis,
)

__all__ = [
    "GaitCycle",
    "GaitEvents",
    "gait_events_from_grf",
    "cycle_from_grf",
    "cycle_from_inverse_dynamics",
    "cycle_from_id_file",
    "cycle_of_trial",
    "read_grf",
    "DEFAULT_GRF_THRESHOLD_N",
    "DEFAULT_MIN_DURATION_S",
    "DEFAULT_PADDING_S",
    "DEFAULT_TOE_OFF_FRACTION",
    "phase_shares",
    "GROUPS",
    "OTHER",
    "GROUPS_WITH_OTHER",
    "GROUP_NAMES",
    "DOF_GROUPS",
    "DEFAULT_THRESHOLD_M",
    "dof_group_pair",
    "group_weights",
    "group_rates",
    "group_shares",
    "muscle_membership",
    "membership_table",
    "RmCorr",
    "rmcorr",
    "BlandAltman",
    "bland_altman",
    "MetabolicAnalysis",
    "TrialAnalysis",
    "analyse",
    "write_analysis",
    "analyse_metabolics",
    "analyse_solution_folder",
    "interpolate_moment_arms",
]
