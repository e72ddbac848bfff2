"""Muscle metabolic energy models, muscle by muscle and instant by instant.

Six literature models as the reference study implements them, each a pure function of
NumPy arrays with one shared signature (:data:`MODELS`):

======  ==================================  =============================================
name    function                            reference
======  ==================================  =============================================
UM03    :func:`umberger2003`                Umberger, Gerritsen & Martin (2003)
BH04    :func:`bhargava2004`                Bhargava, Pandy & Anderson (2004)
HO06    :func:`houdijk2006`                 Houdijk, Bobbert & de Haan (2006)
LW07    :func:`lichtwark2007`               Lichtwark & Wilson (2007)
UM10    :func:`umberger2010`                Umberger (2010)
UC16    :func:`uchida2016`                  Uchida et al. (2016)
======  ==================================  =============================================

and two additional models, evaluated only when named (:data:`ADDITIONAL_MODELS`):

======  ==================================  =============================================
LW05    :func:`lichtwark2005`               Lichtwark & Wilson (2005), made definite
MA68    :func:`margaria1968`                Margaria (1968), work efficiencies
======  ==================================  =============================================

Each returns a :class:`MetabolicRates` (``work``, ``activation_maintenance``,
``shortening_lengthening``, ``basal``, ``total``; W). Whole-body averages, cost of
transport and indirect calorimetry are in :mod:`.whole_body`; rates of a solver solution in
:mod:`.solution`; the paper's Figure 2 in :mod:`.figure2`. See ``docs/metabolics.md``.

Importing this package imports NumPy only (neither ``opensim`` nor ``casadi``).
"""

from ._common import (
    BASAL_RATE_W_PER_KG,
    COMPONENTS,
    FIBER_FRACTIONS,
    MINIMUM_HEAT_RATE_W_PER_KG,
    PARAMETER_ARGUMENTS,
    STATE_ARGUMENTS,
    MetabolicRates,
)
from .bhargava import BHARGAVA_CONSTANTS, bhargava2004, bhargava_stimulation_time_s
from .houdijk import HOUDIJK_CONSTANTS, houdijk2006
from .lichtwark import LICHTWARK_2005_CONSTANTS, LICHTWARK_CONSTANTS, lichtwark2005, lichtwark2007
from .margaria import MARGARIA_CONSTANTS, margaria1968
from .registry import ADDITIONAL_MODELS, ALL_MODELS, MODELS, STUDY_MODELS, compute_models, get_model, parse_models
from .umberger import AEROBIC_FACTOR, ANAEROBIC_FACTOR, uchida2016, umberger2003, umberger2010
from .whole_body import (
    WholeBodyRate,
    brockway_rate_W,
    cost_of_transport_J_per_kg_per_m,
    whole_body_rate,
)

__all__ = [
    "MODELS",
    "STUDY_MODELS",
    "ADDITIONAL_MODELS",
    "ALL_MODELS",
    "COMPONENTS",
    "STATE_ARGUMENTS",
    "PARAMETER_ARGUMENTS",
    "BASAL_RATE_W_PER_KG",
    "MINIMUM_HEAT_RATE_W_PER_KG",
    "FIBER_FRACTIONS",
    "AEROBIC_FACTOR",
    "ANAEROBIC_FACTOR",
    "MetabolicRates",
    "umberger2003",
    "umberger2010",
    "uchida2016",
    "bhargava2004",
    "bhargava_stimulation_time_s",
    "houdijk2006",
    "lichtwark2007",
    "lichtwark2005",
    "margaria1968",
    "BHARGAVA_CONSTANTS",
    "HOUDIJK_CONSTANTS",
    "LICHTWARK_CONSTANTS",
    "LICHTWARK_2005_CONSTANTS",
    "MARGARIA_CONSTANTS",
    "get_model",
    "parse_models",
    "compute_models",
    "WholeBodyRate",
    "whole_body_rate",
    "cost_of_transport_J_per_kg_per_m",
    "brockway_rate_W",
]
