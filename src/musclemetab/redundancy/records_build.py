"""The record of one trial's solve (``summary.json``, :class:`~.record.SolveRecord`), built once
for the three kinds of solve: a single-trial effort solve (:func:`.solve.solve_with_parameters`),
an EMG-TEN or EMG-informed problem (:func:`.result.assemble_result`) and a parameter estimation
(:func:`.estimate_problem.solve_estimate`).

A trial's record is the solve's :class:`~.record.RunRecord` followed by the entries of
:data:`TRIAL_ENTRIES` of its kind, in that order (the file's order). The entries that follow from
the problem (the trial's mesh inputs, the nominal parameters, the numerical settings, the goals)
and from the trial's IPOPT outcome are computed here (:func:`trial_record`); the few that belong
to one kind (its workflow record, EMG record, estimated factors, timings) are given by the caller.
"""

from __future__ import annotations

from .inputs import MESH_FREQUENCY_HZ

__all__ = ["TRIAL_ENTRIES", "OPTIONAL_ENTRIES", "trial_record", "trial_solution", "input_preparation"]

#: the entries of a trial's ``summary.json`` after the run's, in the file's order, by kind of solve;
#: an entry of the run's (``objective_terms``, ``input_hashes``) keeps its place and takes the trial's value
TRIAL_ENTRIES = {
    "effort": ("preparation_time_s", "problem_size", "time_window_s", "n_intervals", "mesh_step_s",
               "optimal_reserve_Nm", "static_optimisation_objective", "fiber_dynamics", "fiber_length_bounds",
               "initial_guess", "workflow", "solver_options", "input_preparation", "inputs", "energy_goal",
               "energy_form"),
    "emg-ten": ("objective_trial", "objective_terms", "input_hashes", "preparation_time_s", "problem_size",
                "time_window_s", "n_intervals", "mesh_step_s", "optimal_reserve_Nm", "static_optimisation_objective",
                "initial_guess", "workflow", "emg_tracking", "emg_tolerance", "fiber_dynamics", "fiber_length_bounds",
                "solver_options", "input_preparation", "inputs"),
    "estimate": ("emg", "objective_trial", "objective_terms", "time_window_s", "n_intervals", "mesh_step_s",
                 "optimal_reserve_Nm", "fiber_dynamics", "fiber_length_bounds", "workflow", "solver_options",
                 "diagnosis", "excluded_muscles"),
}
#: entries written only when the solve has them (an energy goal, EMG, excluded muscles)
OPTIONAL_ENTRIES = frozenset({"energy_goal", "energy_form", "emg", "excluded_muscles"})
#: kinds whose ``solver_options`` record the effort weights alone (their fiber dynamics and EMG
#: goal are recorded beside them)
_EFFORT_ONLY_SOLVER_OPTIONS = frozenset({"emg-ten", "estimate"})


def input_preparation(filtered: bool = True, mesh_frequency_hz: float = MESH_FREQUENCY_HZ, emg: bool = False) -> dict:
    """The ``input_preparation`` entry: the inputs' filter (``docs/method.md``), the mesh and the
    interpolation; with ``emg``, how the EMG is taken at the nodes."""
    return {"filter": "butterworth 6th order 6 Hz zero-phase (MATLAB filtfilt padding)" if filtered else "none",
            "mesh_intervals_per_second": mesh_frequency_hz, "interpolation": "not-a-knot cubic spline",
            **({"emg": "linear interpolation at nodes 0..N-1"} if emg else {})}


def trial_record(kind: str, run, inputs, params, options, goals, *, fiber_dynamics: str, outcome=None,
                 sources: dict | None = None, specs=(), **entries) -> dict:
    """The entries of one trial's ``summary.json`` (before the residuals and conventions that
    :func:`.solution.build_solution` adds): ``run`` (:class:`~.record.RunRecord`), then
    :data:`TRIAL_ENTRIES` of ``kind`` in order.

    Computed here: the mesh entries of ``inputs`` (window, intervals, step), the optimal reserve of
    ``options``, the fiber-length bounds of the nominal ``params`` (with the estimated ``specs``),
    the ``solver_options`` of ``options`` and ``goals`` (their effort weights alone for EMG-TEN and
    estimation), ``inputs`` from ``sources`` and the trial's ``objective_trial``/``objective_terms``
    from its IPOPT ``outcome``. ``entries`` gives the others (and may override these); an entry
    of :data:`OPTIONAL_ENTRIES` that is not given is left out.
    """
    from .bounds import fiber_length_bounds_record
    from .ipopt import solver_record

    derived = {
        "time_window_s": lambda: list(inputs.window_s),
        "n_intervals": lambda: inputs.n_intervals,
        "mesh_step_s": lambda: inputs.step_s,
        "optimal_reserve_Nm": lambda: options.optimal_reserve_Nm,
        "fiber_dynamics": lambda: fiber_dynamics,
        "fiber_length_bounds": lambda: fiber_length_bounds_record(inputs, params, specs),
        "solver_options": lambda: solver_record(options, goals.effort() if kind in _EFFORT_ONLY_SOLVER_OPTIONS
                                                else goals),
        "inputs": lambda: {k: str(v) for k, v in (sources or {}).items()},
        "objective_trial": lambda: outcome.objective,
        "objective_terms": lambda: outcome.objective_terms,
    }
    unknown = set(entries) - set(TRIAL_ENTRIES[kind])
    if unknown:
        raise TypeError(f"trial_record: {kind} records no {', '.join(sorted(unknown))}")
    summary = run.to_dict()
    for key in TRIAL_ENTRIES[kind]:
        if key in entries:
            summary[key] = entries[key]
        elif key in derived:
            summary[key] = derived[key]()
        elif key not in OPTIONAL_ENTRIES:
            raise TypeError(f"trial_record: the {kind} record needs its {key}")
    return summary


def trial_solution(kind: str, run, inputs, params, options, goals, outcome, *, solved=None, **entries):
    """The :class:`~.solution.Solution` of one trial: its IPOPT ``outcome`` with the parameters it
    was ``solved`` with (default ``params``, restricted to the trial's muscles) and the record of
    :func:`trial_record` (same arguments)."""
    from .solution import build_solution

    summary = trial_record(kind, run, inputs, params, options, goals, outcome=outcome, **entries)
    return build_solution(inputs, (params if solved is None else solved).subset(inputs.muscles), outcome, summary)
