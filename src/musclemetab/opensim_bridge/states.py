"""A model's states along an IK motion, and OpenSim's probes over a states file (worker only).

:func:`model_states_along_motion` gives what an OpenSim states trajectory of a model needs:
every state variable's name (``/jointset/<joint>/<coord>/value|speed``,
``/forceset/<muscle>/activation|fiber_length``, ...) with the model's default value, and
the coordinate values (model units: rad or m) and speeds of the IK motion at given times.
Coordinates are set as :mod:`.model_ops` sets them: rotational values from degrees when the
file says so, coupled coordinates from their coupler functions, locked coordinates at
their default, independent coordinates of a nonlinear joint motion (OpenSim's "coupled"
motion type without a coupler, such as gait2392's pelvis translations) as the file gives them. Values at the requested times come from a cubic spline through the IK
frames; speeds are its derivative.

:func:`probes_over_states` loads a states file with
``StatesTrajectory.createFromStatesTable`` (no missing or extra columns allowed), sets the
muscles' excitations from a controls file, and evaluates OpenSim's
``Umberger2010MuscleMetabolicsProbe`` / ``Bhargava2004MuscleMetabolicsProbe`` per muscle at
every state, with the muscle quantities OpenSim used. Only the evaluated muscles apply
force (the others' dynamics are not computed); a state at which OpenSim cannot solve a
muscle's equilibrium is reported in ``failed_states`` and its values are NaN.

OpenSim 4.6's ``createFromStatesTable`` cannot set a locked coordinate (``Coordinate``
refuses a new value while locked) and leaves it NaN; such coordinates are set here from the
file's column, unlocked for the assignment and locked again.
"""

from __future__ import annotations

import math

import numpy as np
import opensim as osim

from ..errors import DataMismatchError, UnknownMuscleError
from ..messages import name_list
from .model_ops import COUPLED, ROTATIONAL, load_model
from .probes import BHARGAVA_SWITCHES, UMBERGER_SWITCHES, _DEFAULT_OFF
from .trajectory import MUSCLE_GETTERS, set_locked_coordinates

__all__ = ["model_states_along_motion", "states_along_motion", "probes_over_states"]


def model_states_along_motion(model_path: str, ik_time, columns: dict, in_degrees: bool, times) -> dict:
    """State names, defaults and coordinate values/speeds of the motion at ``times``.

    Returns ``state_names`` (model order), ``defaults`` (one per name), ``values``
    (``{state name: array over times}`` for every coordinate value and speed),
    ``muscle_states`` (``{muscle: [its state names]}``), ``muscles_with_fiber_length``,
    ``defaulted_coordinates`` (unlocked, independent coordinates absent from the motion)
    and ``motion_types`` (``{coordinate: rotational|translational|coupled}``).
    """
    return states_along_motion(load_model(model_path), ik_time, columns, in_degrees, times)


def states_along_motion(m, ik_time, columns: dict, in_degrees: bool, times) -> dict:
    """:func:`model_states_along_motion` of a loaded model (:class:`.model_ops.LoadedModel`)."""
    from scipy.interpolate import CubicSpline

    model, state = m.model, m.state
    sv = model.getStateVariableNames()
    names = [sv.get(i) for i in range(sv.getSize())]
    defaults = [float(v) for v in model.getStateVariableValues(state).to_numpy()]
    ik_time = np.asarray(ik_time, dtype=float)
    times = np.asarray(times, dtype=float)
    if times[0] < ik_time[0] - 1e-9 or times[-1] > ik_time[-1] + 1e-9:
        raise DataMismatchError(
            f"the solution spans {times[0]:g}-{times[-1]:g} s but the IK motion only {ik_time[0]:g}-{ik_time[-1]:g} s; "
            "give the IK file of the solved trial"
        )
    from .model_ops import frame_values

    frames = [frame_values(m, columns, in_degrees, k) for k in range(ik_time.size)]
    # independent coordinates of nonlinear joint motion (gait2392's pelvis translations) are
    # the motion's too, in the file's units as OpenSim's tools take them (only rotational
    # coordinates are converted from degrees)
    nonlinear = [n for n in m.coords if m.motion[n] == COUPLED and n not in m.dependent and not m.locked[n]
                 and n in columns]
    for k, f in enumerate(frames):
        for n in nonlinear:
            f[n] = float(columns[n][k])
    values: dict[str, np.ndarray] = {}
    defaulted = []
    for n, c in m.coords.items():
        path = c.getAbsolutePathString()
        if m.locked[n] or n not in frames[0]:
            if not m.locked[n] and n not in m.dependent:
                defaulted.append(n)
            values[f"{path}/value"] = np.full(times.size, c.getDefaultValue())
            values[f"{path}/speed"] = np.zeros(times.size)
            continue
        spline = CubicSpline(ik_time, np.array([f[n] for f in frames]), bc_type="not-a-knot")
        values[f"{path}/value"] = spline(times)
        values[f"{path}/speed"] = spline(times, 1)
    muscle_states = {}
    for mu in m.muscle_order:
        prefix = m.muscles[mu].getAbsolutePathString() + "/"
        muscle_states[mu] = [s for s in names if s.startswith(prefix)]
    kinds = {ROTATIONAL: "rotational", COUPLED: "coupled"}
    return dict(
        state_names=names,
        defaults=defaults,
        values=values,
        muscle_states=muscle_states,
        muscles_with_fiber_length=[mu for mu, s in muscle_states.items()
                                   if f"{m.muscles[mu].getAbsolutePathString()}/fiber_length" in s],
        muscle_paths={mu: m.muscles[mu].getAbsolutePathString() for mu in m.muscle_order},
        defaulted_coordinates=defaulted,
        motion_types={n: kinds.get(m.motion[n], "translational") for n in m.coords},
        opensim_version=osim.__version__,
    )


def probes_over_states(model_path: str, states_path: str, controls_path: str, muscles: list,
                       muscle_mass_kg: list, slow_twitch_fraction: list, probes: list) -> dict:
    """OpenSim's metabolic probes on every muscle of ``muscles`` at every exported state.

    ``probes``: dicts as in :func:`.probes.evaluate_probes` (``probe``, ``name``, switches;
    ``maintenance_length_dependence`` for Bhargava). The states file is loaded without
    allowances; a file OpenSim refuses raises its error. Returns per probe
    ``<name>`` -> array ``(muscles, states)`` of the per-muscle totals (W), the muscle
    quantities OpenSim used as arrays ``(muscles, states)``, the muscle parameters and the
    state times. ``activation_state``, ``fiber_length_state_m`` and
    ``normalized_tendon_force_state`` are the state variables as loaded (NaN for a muscle
    without that state; ``activation`` is the muscle's, clamped to its minimum activation).
    """
    model = osim.Model(str(model_path))
    mset = model.getMuscles()
    missing = [mu for mu in muscles if mset.getIndex(mu) < 0]
    if missing:
        raise UnknownMuscleError(f"{model_path}: no muscle {name_list(missing)}")
    # only the muscles evaluated apply force: the others' dynamics are not computed
    wanted = set(muscles)
    for i in range(mset.getSize()):
        if mset.get(i).getName() not in wanted:
            mset.get(i).set_appliesForce(False)
    made = []
    for cfg in probes:
        cfg = dict(cfg)
        kind, name = cfg.pop("probe"), cfg.pop("name")
        if kind == "Umberger2010":
            pr, switches = osim.Umberger2010MuscleMetabolicsProbe(), UMBERGER_SWITCHES
            for mu, mass, fst in zip(muscles, muscle_mass_kg, slow_twitch_fraction):
                pr.addMuscle(mu, float(fst), float(mass))
        else:
            pr, switches = osim.Bhargava2004MuscleMetabolicsProbe(), BHARGAVA_SWITCHES
            for mu, mass, fst in zip(muscles, muscle_mass_kg, slow_twitch_fraction):
                pr.addMuscle(mu, float(fst), 40.0, 133.0, 74.0, 111.0, float(mass))
            if cfg.pop("maintenance_length_dependence", "published") == "identity":
                identity = osim.PiecewiseLinearFunction()
                identity.addPoint(0.0, 0.0)
                identity.addPoint(10.0, 10.0)
                pr.set_normalized_fiber_length_dependence_on_maintenance_rate(identity)
        pr.setName(name)
        for key, value in {**_DEFAULT_OFF, **cfg}.items():
            if key not in switches:
                raise ValueError(f"{kind} probe has no switch {key!r}")
            getattr(pr, f"set_{key}")(bool(value))
        pr.set_report_total_metabolics_only(False)
        model.addProbe(pr)
        made.append((name, pr))
    model.initSystem()
    table = osim.TimeSeriesTable(str(states_path))
    traj = osim.StatesTrajectory.createFromStatesTable(model, table)
    controls_table = osim.TimeSeriesTable(str(controls_path))
    clabels = [str(x) for x in controls_table.getColumnLabels()]
    cmat = controls_table.getMatrix().to_numpy()
    # index of each muscle's control in the model's controls vector
    acts = model.getActuators()
    index, k = {}, 0
    for i in range(acts.getSize()):
        index[acts.get(i).getAbsolutePathString()] = k
        k += acts.get(i).numControls()
    col_of = {}
    for j, lab in enumerate(clabels):
        if lab not in index:
            raise DataMismatchError(f"{controls_path}: column {lab} is not an actuator of {model_path}")
        col_of[index[lab]] = j
    n = traj.getSize()
    mus = [mset.get(mu) for mu in muscles]
    getters = MUSCLE_GETTERS
    state_vars = {"activation_state": "activation", "fiber_length_state_m": "fiber_length",
                  "normalized_tendon_force_state": "normalized_tendon_force"}
    sv_names = model.getStateVariableNames()
    sv_names = {sv_names.get(i) for i in range(sv_names.getSize())}
    has_state = [{key: f"{mu.getAbsolutePathString()}/{sv}" in sv_names for key, sv in state_vars.items()}
                 for mu in mus]
    out = {key: np.empty((len(mus), n)) for key in (*getters, *state_vars)}
    labels = {}
    for name, pr in made:
        lab = pr.getProbeOutputLabels()
        labels[name] = [lab.get(i) for i in range(lab.getSize())]
        out[name] = np.empty((len(mus), n))
    times = np.empty(n)
    failed = []
    cset = model.getCoordinateSet()
    locked = []
    for i in range(cset.getSize()):
        c = cset.get(i)
        if c.get_locked():
            col = table.getDependentColumn(f"{c.getAbsolutePathString()}/value").to_numpy()
            locked.append((c, col))
    for s in range(n):
        state = traj.get(s)
        times[s] = state.getTime()
        set_locked_coordinates(locked, state, s)  # createFromStatesTable leaves them at NaN
        model.realizeVelocity(state)
        controls = model.updControls(state)
        for ci, j in col_of.items():
            controls.set(ci, float(cmat[s, j]))
        model.setControls(state, controls)
        try:
            model.realizeDynamics(state)
        except RuntimeError as exc:  # a muscle whose equilibrium OpenSim cannot solve here
            failed.append((float(state.getTime()), str(exc).strip().splitlines()[-1][:200]))
            for key in out:
                out[key][:, s] = math.nan
            continue
        for i, mu in enumerate(mus):
            for key, g in getters.items():
                out[key][i, s] = getattr(mu, g)(state)
            for key, sv in state_vars.items():
                out[key][i, s] = mu.getStateVariableValue(state, sv) if has_state[i][key] else math.nan
        for name, pr in made:
            vals = pr.getProbeOutputs(state)
            by_label = {labels[name][i]: vals.get(i) for i in range(vals.size())}
            for i, mu in enumerate(muscles):
                out[name][i, s] = by_label[f"{name}_{mu}"] if f"{name}_{mu}" in by_label else math.nan
    out["time_s"] = times
    out["failed_states"] = failed
    out["labels"] = labels
    out["parameters"] = dict(
        max_isometric_force_N=[m.getMaxIsometricForce() for m in mus],
        optimal_fiber_length_m=[m.getOptimalFiberLength() for m in mus],
        max_contraction_velocity=[m.getMaxContractionVelocity() for m in mus],
    )
    out["n_states"] = n
    out["n_state_variables"] = int(model.getNumStateVariables())
    return out
