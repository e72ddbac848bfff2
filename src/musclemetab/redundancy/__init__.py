"""Muscle redundancy solver with compliant tendons (De Groote et al. 2016).

The workflows of Luis et al. (PLoS Comput Biol 2024): the effort-based EFFORT-GEN, EFFORT-CAL
and EFFORT-TEN, and EMG-TEN, the EMG-informed estimation of tendon stiffness over several trials.
From inverse kinematics, inverse dynamics and muscle geometry, an optimal control problem
(CasADi + IPOPT) finds muscle excitations, activations, fibre lengths and velocities and
tendon forces that reproduce the joint moments with minimal effort.

Modules: :mod:`.inputs` (filtering, splines, mesh), :mod:`.static_opt` (initial guess),
:mod:`.core` (one problem: trials, goals, shared parameters; ``docs/problem.md``),
:mod:`.problem` (solving it; the single-trial problem), :mod:`.solution` (results, files),
:mod:`.record` (the run record), :mod:`.workflows` (presets, passive and tendon parameters),
:mod:`.solve` (the pipeline), :mod:`.emg_ten` and :mod:`.emg_pipeline` (EMG-TEN and EMG-informed
solves), :mod:`.estimates` (their results), :mod:`.estimate` (parameter estimation, personalised
model), :mod:`.cli` and :mod:`.estimate_cli` (``musclemetab solve``, ``musclemetab estimate``).
Importing this package does not
import CasADi; solving does. OpenSim is never imported here.
"""

from .emg_ten import EmgTenResult, EmgTenSettings, solve_emg_ten
from .parameters import MuscleTendonParameters
from .problem import SolverOptions
from .solution import Solution
from .solve import solve_files, solve_trial, solve_with_parameters
from .workflows import WORKFLOWS, Workflow, get_workflow, read_passive_parameters, workflow_parameters

__all__ = [
    "MuscleTendonParameters",
    "SolverOptions",
    "Solution",
    "solve_trial",
    "solve_files",
    "solve_with_parameters",
    "WORKFLOWS",
    "Workflow",
    "get_workflow",
    "read_passive_parameters",
    "workflow_parameters",
    "solve_emg_ten",
    "EmgTenResult",
    "EmgTenSettings",
]
