"""Calibration of muscle parameters from passive joint moments.

:mod:`.trials` reads the calibration trials into arrays (:class:`CalibrationData`),
:mod:`.problem` builds and solves the passive NLP (:func:`solve_passive`), :mod:`.equilibrium`
checks single equilibria by root finding, :mod:`.result` holds the results and the folder
they are written to (:class:`PassiveCalibration`), and :mod:`.passive` is the workflow
(:func:`calibrate_passive`) with the parameter files.
"""

from .equilibrium import equilibrium_fiber_length
from .passive import (
    calibrate_passive,
    mirror_to_left,
    read_passive_parameters,
    write_calibration,
    write_passive_parameters,
)
from .problem import PassiveSolution, parameter_groups, passive_moments, solve_passive
from .result import CalibrationResult, PassiveCalibration
from .trials import CalibrationData, CalibrationTrial, load_calibration_data

__all__ = [
    "CalibrationData",
    "CalibrationResult",
    "CalibrationTrial",
    "PassiveCalibration",
    "PassiveSolution",
    "calibrate_passive",
    "equilibrium_fiber_length",
    "load_calibration_data",
    "mirror_to_left",
    "parameter_groups",
    "passive_moments",
    "read_passive_parameters",
    "solve_passive",
    "write_calibration",
    "write_passive_parameters",
]
