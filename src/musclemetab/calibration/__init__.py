"""Calibration of muscle parameters from passive joint moments."""

from .passive import (
    CalibrationData,
    CalibrationResult,
    CalibrationTrial,
    PassiveSolution,
    calibrate_passive,
    equilibrium_fiber_length,
    load_calibration_data,
    mirror_to_left,
    parameter_groups,
    passive_moments,
    read_passive_parameters,
    solve_passive,
    write_calibration,
    write_passive_parameters,
)

__all__ = [
    "CalibrationData",
    "CalibrationResult",
    "CalibrationTrial",
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
