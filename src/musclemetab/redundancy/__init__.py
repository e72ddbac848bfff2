"""Muscle redundancy solver with compliant tendons (De Groote et al. 2016).

The workflows of Luis et al. (PLoS Comput Biol 2024): the effort-based EFFORT-GEN, EFFORT-CAL
and EFFORT-TEN, and EMG-TEN, the EMG-informed estimation of tendon stiffness over several trials.
From inverse kinematics, inverse dynamics and muscle geometry, an optimal control problem
(CasADi + IPOPT) finds muscle excitations, activations, fiber lengths and velocities and
tendon forces that reproduce the joint moments with minimal effort.

Modules: :mod:`.problem` (one problem: :func:`~.problem.load_problem` reads and checks its
files once, :func:`~.problem.solve` solves it, the result keeps it), :mod:`.run` (the pipeline
from files: what the command line, the study and Python users call), :mod:`.inputs` (filtering, splines, mesh), :mod:`.static_opt` (initial guess),
:mod:`.transcription` (one problem: trials, goals, shared parameters; ``docs/problem.md``),
:mod:`.ipopt` (solving it; the single-trial problem), :mod:`.solution` (results, files),
:mod:`.record` (the run record), :mod:`.workflows` (presets, passive and tendon parameters),
:mod:`.solve` (one trial from arrays), :mod:`.emg_ten` and :mod:`.emg_pipeline` (EMG-TEN and
EMG-informed solves from arrays), :mod:`.result` (their results), :mod:`.estimate`
(parameter estimation, personalised model). The commands ``musclemetab solve`` and
``musclemetab estimate`` are :mod:`musclemetab.commands.solve` and
:mod:`musclemetab.commands.estimate`. Importing this package does not
import CasADi; solving does. OpenSim is never imported here.
"""

import importlib

# Public names and the module that defines each: imported on first use, so that importing
# one stage (e.g. the single-trial solve) does not import the others (e.g. EMG-TEN).
_EXPORTS = {
    "Result": "result", "EmgTenResult": "result", "EmgTenSettings": "emg_ten", "solve_emg_ten": "emg_run",
    "MuscleTendonParameters": "parameters",
    "SolverOptions": "ipopt", "Goals": "transcription",
    "Solution": "solution",
    "solve_files": "run", "solve_sides": "run", "solve_trial": "solve", "solve_with_parameters": "solve",
    "WORKFLOWS": "workflows", "Workflow": "workflows", "get_workflow": "workflows",
    "read_passive_parameters": "workflows", "workflow_parameters": "workflows",
    "estimate_files": "estimate_run", "write_solution_folder": "run",
    "Problem": "problem", "TrialFiles": "problem", "load_problem": "problem", "load_result": "problem",
}


def __getattr__(name):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_EXPORTS))


__all__ = [
    "MuscleTendonParameters",
    "SolverOptions",
    "Goals",
    "Solution",
    "solve_trial",
    "solve_files",
    "solve_sides",
    "write_solution_folder",
    "solve_with_parameters",
    "WORKFLOWS",
    "Workflow",
    "get_workflow",
    "read_passive_parameters",
    "workflow_parameters",
    "solve_emg_ten",
    "Result",
    "EmgTenResult",
    "EmgTenSettings",
    "estimate_files",
    "Problem",
    "TrialFiles",
    "load_problem",
    "load_result",
]
