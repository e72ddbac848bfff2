"""The OpenSim model of a solution, its states and the moment arms it needs (worker only).

:func:`solution_model` turns a model into the one a muscle redundancy solution was solved
with, in OpenSim's own classes, and writes it:

* every muscle becomes a ``DeGrooteFregly2016Muscle`` (OpenSim's ``replaceMuscles``); each
  solved muscle gets the solution's parameters (``docs/opensim_files.md`` gives the mapping:
  F0, lMo, lTs, pennation, vmax as they are; the tendon and passive curves through their
  strain at one normalised force; fiber damping 0; activation time constants 15/60 ms);
* every locked coordinate becomes a prescribed coordinate (OpenSim 4.6's
  ``StatesTrajectory.createFromStatesTable`` cannot set a locked coordinate and leaves it NaN;
  a prescribed one it sets, and dynamics holds it as the lock did): at the constant value it
  was locked at, or, when the motion moves it (a locked coordinate off the solved leg, whose
  muscle paths the geometry took at the motion's values), along the motion's values at the
  node times;
* every other coordinate gets a ``CoordinateActuator`` ``reserve_<coordinate>`` of optimal
  force 1, so that its control is the generalised force (N m or N) in the forces file.

Along the solution's node times it returns the state names and defaults of that model, the
coordinate values and speeds of the IK motion (as :mod:`.states` computes them; locked
coordinates at their value), and the moment arms of the solved muscles about the model's
other free coordinates (``Muscle.computeMomentArm``, only the pairs the muscle spans).

None of this needs the solution's values: :func:`prepare_solution_model` does it while the
solution is solved and keeps the model for the :func:`solution_model` call with the same inputs,
which then only writes the file.
"""

from __future__ import annotations

import hashlib
import math
import os
import pickle

import numpy as np
import opensim as osim

from ..errors import ModelError, UnknownMuscleError
from ..messages import name_list
from .model_ops import LoadedModel, model_muscles
from .model_xml import MUSCLE_PROPERTIES
from .states import states_along_motion

__all__ = ["solution_model", "prepare_solution_model", "prepared_models", "RESERVE_PREFIX"]

RESERVE_PREFIX = "reserve_"


_CONVERTED: dict = {}


def _with_degroote_muscles(model_path: str):
    """A copy of the model with every muscle a ``DeGrooteFregly2016Muscle`` (OpenSim's
    ``replaceMuscles``, about a second for 80 muscles, done once while the file is unchanged;
    a copy takes a few milliseconds)."""
    path = os.path.abspath(model_path)
    if not os.path.isfile(path):
        raise ModelError(f"{model_path}: no such model file; check the path")
    key = (path, os.path.getmtime(path), os.path.getsize(path))
    if key not in _CONVERTED:
        try:
            model = osim.Model(path)
        except Exception as exc:
            msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise ModelError(f"{model_path}: OpenSim cannot load this model ({msg}); check that it is a valid .osim "
                             "file") from None
        # muscles already of the class (and any class OpenSim cannot convert) are kept as they are:
        # the solved ones are checked below
        osim.DeGrooteFregly2016Muscle.replaceMuscles(model, True)
        _CONVERTED.clear()
        _CONVERTED[key] = model
    model = osim.Model(_CONVERTED[key])
    model.finalizeFromProperties()  # the copy's component lists (coordinates, muscles) are its own
    return model


def _set_parameters(mu, p: dict) -> None:
    for key, prop in MUSCLE_PROPERTIES.items():
        getattr(mu, f"set_{prop}")(float(p[key]))
    mu.set_fiber_damping(0.0)
    mu.set_active_force_width_scale(1.0)
    mu.set_ignore_tendon_compliance(False)
    mu.set_ignore_activation_dynamics(False)
    mu.set_ignore_passive_fiber_force(False)
    mu.set_tendon_compliance_dynamics_mode("explicit")


#: models prepared by :func:`prepare_solution_model` (or written by :func:`solution_model`),
#: by :func:`_inputs_key`: the last few, e.g. both legs of a ``--side both`` solve
_PREPARED: dict = {}
_PREPARED_KEEP = 2


def _inputs_key(model_path: str, parameters: dict, ik_time, columns: dict, in_degrees: bool, times,
                solved_dofs) -> str:
    """A digest of everything the prepared model depends on (the model file by path, time of
    change and size; the values of every other input)."""
    path = os.path.abspath(model_path)
    stat = (os.path.getmtime(path), os.path.getsize(path)) if os.path.isfile(path) else None
    data = pickle.dumps((path, stat, parameters, np.asarray(ik_time, dtype=float),
                         {c: np.asarray(v, dtype=float) for c, v in columns.items()}, bool(in_degrees),
                         np.asarray(times, dtype=float), list(solved_dofs)), protocol=pickle.HIGHEST_PROTOCOL)
    return hashlib.sha256(data).hexdigest()


def prepare_solution_model(model_path: str, parameters: dict, ik_time, columns: dict, in_degrees: bool, times,
                           solved_dofs: list = ()) -> None:
    """Do the work of :func:`solution_model` that needs no solution values, and keep its result
    for the next :func:`solution_model` call with the same inputs: the model's conversion, the
    muscle parameters, the reserves, the states along the motion and the moment arms. Asked for
    while the solution is solved (the parameters and the mesh are known before), so that after
    the solve only the file is written."""
    _prepared(model_path, parameters, ik_time, columns, in_degrees, times, solved_dofs)


def prepared_models() -> list:
    """The digests (:func:`_inputs_key`) of the models kept, oldest first: which inputs a
    :func:`solution_model` call finds prepared."""
    return list(_PREPARED)


def _prepared(model_path, parameters, ik_time, columns, in_degrees, times, solved_dofs):
    """``(model, info)`` of :func:`_prepare`, from :data:`_PREPARED` when the inputs are the same."""
    key = _inputs_key(model_path, parameters, ik_time, columns, in_degrees, times, solved_dofs)
    if key not in _PREPARED:
        entry = _prepare(model_path, parameters, ik_time, columns, in_degrees, times, solved_dofs)
        while len(_PREPARED) >= _PREPARED_KEEP:
            _PREPARED.pop(next(iter(_PREPARED)))
        _PREPARED[key] = entry
    return _PREPARED[key]


def solution_model(model_path: str, out_path: str, parameters: dict, ik_time, columns: dict, in_degrees: bool,
                   times, solved_dofs: list = ()) -> dict:
    """Write the solution's model to ``out_path``; its states and moment arms along ``times``.

    ``parameters``: ``{muscle: {max_isometric_force_N, optimal_fiber_length_m,
    tendon_slack_length_m, pennation_angle_at_optimal_rad, max_contraction_velocity,
    tendon_strain_at_one_norm_force, passive_fiber_strain_at_one_norm_force,
    activation_time_constant_s, deactivation_time_constant_s}}``. Moment arms are given about
    the free, independent coordinates other than ``solved_dofs``.

    Returns what :func:`.states.states_along_motion` returns for the new model, plus
    ``reserves`` (``{coordinate: actuator name}``), ``actuators`` (names in the model's
    order), ``dependent_coordinates``, ``prescribed_coordinates`` (the locked ones) and
    ``moment_arms_m`` (``{coordinate: {muscle: array over times}}``, spanned pairs only).
    The model work is that of :func:`prepare_solution_model` with the same inputs when it ran
    before (done once).
    """
    model, info = _prepared(str(model_path), parameters, ik_time, columns, in_degrees, times, solved_dofs)
    model.printToXML(str(out_path))
    return dict(info)


def _prepare(model_path: str, parameters: dict, ik_time, columns: dict, in_degrees: bool, times,
             solved_dofs) -> tuple:
    """The solution's model (not written) and what :func:`solution_model` returns."""
    model = _with_degroote_muscles(str(model_path))
    muscles = model_muscles(model, list(parameters), model_path,
                            "give the model the solution was solved with")
    for name, p in parameters.items():
        muscle = osim.DeGrooteFregly2016Muscle.safeDownCast(muscles[name])
        if muscle is None:
            raise ModelError(f"{model_path}: OpenSim cannot turn muscle {name} ({muscles[name].getConcreteClassName()}) "
                             "into a DeGrooteFregly2016Muscle, so no OpenSim model of the solution is written for it; "
                             "solve with a model of Millard, Thelen or DeGroote-Fregly muscles")
        _set_parameters(muscle, p)
    cset = model.getCoordinateSet()
    locked, prescribed, follows = {}, [], {}
    for i in range(cset.getSize()):
        c = cset.get(i)
        locked[c.getName()] = bool(c.get_locked())
        if c.get_locked():
            c.set_locked(False)
            c.setDefaultLocked(False)
            c.set_prescribed(True)
            moved = _locked_motion(c, ik_time, columns, in_degrees, times)
            if moved is None:
                c.setPrescribedFunction(osim.Constant(c.getDefaultValue()))
            else:  # the motion moves it (off the solved leg): the model and states follow the motion
                c.setPrescribedFunction(_held_outside(times, moved))
                follows[c.getName()] = moved
            prescribed.append(c.getName())
    dependent = set()
    cons = model.getConstraintSet()
    for i in range(cons.getSize()):
        cc = osim.CoordinateCouplerConstraint.safeDownCast(cons.get(i))
        if cc is not None and cc.get_isEnforced():
            dependent.add(cc.getDependentCoordinateName())
    reserves = {}
    for i in range(cset.getSize()):
        c = cset.get(i)
        if locked[c.getName()]:
            continue
        act = osim.CoordinateActuator(c.getName())
        act.setName(RESERVE_PREFIX + c.getName())
        act.setOptimalForce(1.0)
        act.setMinControl(-math.inf)
        act.setMaxControl(math.inf)
        model.addForce(act)
        reserves[c.getName()] = act.getName()
    model.setName(model.getName() + "_solution")
    model.finalizeConnections()
    m = LoadedModel(str(model_path), model=model)
    # held at the value they are locked at, as in the solved model, unless the motion moves them
    m.locked.update({n: v and n not in follows for n, v in locked.items()})
    info = states_along_motion(m, ik_time, columns, in_degrees, times)
    # moment arms of the solved muscles about the other free coordinates, at the node times
    coords = [c for c in m.coords if not locked[c] and c not in dependent and c not in set(solved_dofs)]
    mus = {n: m.muscles[n] for n in parameters}
    model, state = m.model, m.state
    times = np.asarray(times, dtype=float)

    def pose(k: int) -> None:
        for n, c in m.coords.items():
            path = c.getAbsolutePathString()
            c.setValue(state, float(info["values"][f"{path}/value"][k]), False)
        model.realizePosition(state)

    arms: dict = {}
    spans = [(c, n) for c in coords for n in mus if _spans(model, mus[n], c, m)]
    for c, n in spans:
        arms.setdefault(c, {})[n] = np.empty(times.size)
    for k in range(times.size if spans else 0):
        pose(k)
        for c, n in spans:
            arms[c][n][k] = mus[n].computeMomentArm(state, m.coords[c])
    acts = model.getActuators()
    info.update(
        reserves=reserves,
        actuators=[acts.get(i).getName() for i in range(acts.getSize())],
        dependent_coordinates=sorted(dependent),
        prescribed_coordinates=prescribed,
        moment_arms_m=arms,
    )
    return model, info


def _locked_motion(c, ik_time, columns: dict, in_degrees: bool, times):
    """The values (model units) at ``times`` of a locked coordinate ``c`` that the motion takes
    further than :data:`~musclemetab.settings.LOCKED_TOLERANCE` from the value it is locked at, or
    None (held by the motion, or not in it). The geometry of a solve follows the motion there
    (:mod:`.model_ops`), so the written model prescribes the same values."""
    from scipy.interpolate import CubicSpline

    from ..settings import LOCKED_TOLERANCE

    name = c.getName()
    if name not in columns:
        return None
    q = np.asarray(columns[name], dtype=float)
    if in_degrees and c.getMotionType() == osim.Coordinate.Rotational:
        q = np.deg2rad(q)
    if float(np.max(np.abs(q - c.getDefaultValue()))) <= LOCKED_TOLERANCE:
        return None
    return CubicSpline(np.asarray(ik_time, dtype=float), q, bc_type="not-a-knot")(np.asarray(times, dtype=float))


def _held_outside(times, values):
    """OpenSim function through ``values`` at ``times``: linear between the nodes (the states
    are written at the nodes), held at the end values outside them, so that the model assembles
    at any time (a spline's extrapolation at time 0 took a knee out of its range)."""
    times = np.asarray(times, dtype=float)
    f = osim.PiecewiseLinearFunction()
    f.addPoint(float(times[0]) - 1e6, float(values[0]))
    for t, q in zip(times, values):
        f.addPoint(float(t), float(q))
    f.addPoint(float(times[-1]) + 1e6, float(values[-1]))
    return f


def _spans(model, muscle, coordinate: str, m: LoadedModel) -> bool:
    """Whether ``muscle`` spans ``coordinate``: some but not all of its path points lie on the
    bodies the coordinate moves (its joint's child and the bodies beyond, and those of the
    coordinates coupled to it). A muscle with every point beyond the coordinate (a leg muscle
    and the pelvis' coordinates) has no moment arm about it, whatever its wrapping gives."""
    if not hasattr(m, "_moved"):
        jset = model.getJointSet()
        parent, child_of = {}, {}
        for i in range(jset.getSize()):
            j = jset.get(i)
            child = j.getChildFrame().findBaseFrame().getName()
            parent[child] = j.getParentFrame().findBaseFrame().getName()
            for k in range(j.numCoordinates()):
                child_of[j.get_coordinates(k).getName()] = child

        def beyond(body: str) -> set:
            out = set()
            for b in parent:
                x, seen = b, 0
                while x in parent and seen < 1000:
                    if x == body:
                        out.add(b)
                        break
                    x, seen = parent[x], seen + 1
            return out

        m._moved = {}
        for c in m.coords:
            moved = beyond(child_of[c]) if c in child_of else set()
            for dep, independents, _, _ in m.couplers:
                if c in independents and dep in child_of:
                    moved |= beyond(child_of[dep])
            m._moved[c] = moved
    points = muscle.getGeometryPath().getPathPointSet()
    bodies = {points.get(i).getParentFrame().findBaseFrame().getName() for i in range(points.getSize())}
    moved = m._moved.get(coordinate, set())
    return bool(bodies & moved) and bool(bodies - moved)


def muscles_over_states(model_path: str, states_path: str, muscles: list, fiber_length_m=None) -> dict:
    """What OpenSim computes for ``muscles`` of a model over a states file.

    The states are loaded with ``StatesTrajectory.createFromStatesTable`` (no missing or
    extra columns, no assembly) and realised to ``Dynamics`` with every other force off.
    Returns arrays ``(muscles, states)``: ``tendon_force_N``, ``fiber_length_m``,
    ``muscle_tendon_length_m``, ``pennation_angle_rad``, ``active_fiber_force_N``,
    ``passive_fiber_force_N``, ``normalized_fiber_velocity``, ``activation``; ``time_s``;
    ``n_nan_states`` (state values NaN after loading). With ``fiber_length_m``
    (``(muscles, states)``, m) also ``tendon_force_at_fiber_length_N``: OpenSim's tendon
    curve at the tendon length those fibers leave, ``lMT - sqrt(lM^2 - w^2)``, and
    ``passive_fiber_force_at_fiber_length_N``: OpenSim's passive curve at those fibers. (In
    the explicit tendon mode OpenSim's fiber velocity is ``-inf`` where its fiber cannot
    balance the tendon force, and its passive fiber force, which adds damping times
    velocity, is NaN there.)
    """
    model = osim.Model(str(model_path))
    mset = model.getMuscles()
    missing = [mu for mu in muscles if mset.getIndex(mu) < 0]
    if missing:
        raise UnknownMuscleError(f"{model_path}: no muscle {name_list(missing)}")
    model.initSystem()
    table = osim.TimeSeriesTable(str(states_path))
    traj = osim.StatesTrajectory.createFromStatesTable(model, table)
    mus = [osim.DeGrooteFregly2016Muscle.safeDownCast(mset.get(mu)) for mu in muscles]
    if any(mu is None for mu in mus):
        raise ModelError(f"{model_path}: the muscles must be DeGrooteFregly2016Muscle")
    n = traj.getSize()
    keys = ("tendon_force_N", "fiber_length_m", "muscle_tendon_length_m", "pennation_angle_rad",
            "active_fiber_force_N", "passive_fiber_force_N", "normalized_fiber_velocity", "activation")
    out = {k: np.empty((len(mus), n)) for k in keys}
    if fiber_length_m is not None:
        lm = np.asarray(fiber_length_m, dtype=float)
        for key in ("tendon_force_at_fiber_length_N", "passive_fiber_force_at_fiber_length_N"):
            out[key] = np.empty((len(mus), n))
    times, nan_states = np.empty(n), 0
    for s in range(n):
        state = traj.get(s)
        times[s] = state.getTime()
        nan_states += int(np.isnan(model.getStateVariableValues(state).to_numpy()).sum())
        model.realizeDynamics(state)
        for i, mu in enumerate(mus):
            out["tendon_force_N"][i, s] = mu.getTendonForce(state)
            out["fiber_length_m"][i, s] = mu.getFiberLength(state)
            out["muscle_tendon_length_m"][i, s] = mu.getLength(state)
            out["pennation_angle_rad"][i, s] = mu.getPennationAngle(state)
            out["active_fiber_force_N"][i, s] = mu.getActiveFiberForce(state)
            out["passive_fiber_force_N"][i, s] = mu.getPassiveFiberForce(state)
            out["normalized_fiber_velocity"][i, s] = mu.getNormalizedFiberVelocity(state)
            out["activation"][i, s] = mu.getActivation(state)
            if fiber_length_m is not None:
                w = mu.getOptimalFiberLength() * math.sin(mu.getPennationAngleAtOptimalFiberLength())
                lt = mu.getLength(state) - math.sqrt(max(lm[i, s] ** 2 - w * w, 0.0))
                out["tendon_force_at_fiber_length_N"][i, s] = (
                    mu.getMaxIsometricForce() * mu.calcTendonForceMultiplier(lt / mu.getTendonSlackLength()))
                out["passive_fiber_force_at_fiber_length_N"][i, s] = (
                    mu.getMaxIsometricForce() * mu.calcPassiveForceMultiplier(lm[i, s] / mu.getOptimalFiberLength()))
    out["time_s"] = times
    out["n_nan_states"] = nan_states
    return out


def joint_reaction(model_path: str, states_path: str, forces_path: str, joints: list, out_dir: str,
                   external_loads_path: str | None = None, on: str = "child", frame: str = "child") -> dict:
    """OpenSim's ``JointReaction`` analysis (``AnalyzeTool``) over a states file with the
    actuator forces of ``forces_path`` (its ``forces_file``).

    Returns ``time_s`` and ``{joint: (states, 3) force (N) on the ``on`` body, expressed in
    the ``frame`` body}`` under ``forces``, and the path of the analysis' output file.
    """
    model = osim.Model(str(model_path))
    if external_loads_path:  # AnalyzeTool(model) does not add the loads its setup names: the model gets them
        model.addModelComponent(osim.ExternalLoads(str(external_loads_path), True))
    state = model.initSystem()
    tool = osim.AnalyzeTool(model)
    tool.setName("joint_reaction")
    tool.setStatesFileName(str(states_path))
    table = osim.TimeSeriesTable(str(states_path))
    t = np.asarray(table.getIndependentColumn())
    tool.setInitialTime(float(t[0]))
    tool.setFinalTime(float(t[-1]))
    tool.setResultsDir(str(out_dir))
    jr = osim.JointReaction()
    jr.setName("JointReaction")
    jr.setForcesFileName(str(forces_path))
    names, ons, frames = osim.ArrayStr(), osim.ArrayStr(), osim.ArrayStr()
    for j in joints:
        names.append(j)
        ons.append(on)
        frames.append(frame)
    jr.setJointNames(names)
    jr.setOnBody(ons)
    jr.setInFrame(frames)
    jr.setStartTime(float(t[0]))
    jr.setEndTime(float(t[-1]))
    tool.getAnalysisSet().cloneAndAppend(jr)
    tool.setModel(model)
    tool.loadStatesFromFile(state)  # the file's columns matched to the model's states by name
    if not tool.run():
        raise RuntimeError("OpenSim's AnalyzeTool reported a failure")
    import glob
    import os

    files = glob.glob(os.path.join(str(out_dir), "joint_reaction_JointReaction_ReactionLoads.sto"))
    if not files:
        raise RuntimeError(f"OpenSim's JointReaction analysis wrote no ReactionLoads file into {out_dir}")
    result = osim.TimeSeriesTable(files[0])
    labels = list(result.getColumnLabels())
    mat = result.getMatrix().to_numpy()
    forces = {}
    for j in joints:
        cols = [next(k for k, lab in enumerate(labels) if lab.startswith(f"{j}_on_") and lab.endswith(f"_f{a}"))
                for a in "xyz"]
        forces[j] = mat[:, cols]
    return {"time_s": np.asarray(result.getIndependentColumn()), "forces": forces, "file": files[0],
            "labels": labels}
