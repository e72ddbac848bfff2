"""OpenSim model operations (run inside the OpenSim worker process only).

* :func:`read_model_info`: muscles and their five Hill parameters, body mass, coordinates
  and coordinate couplers of a ``.osim`` model.
* :func:`muscle_geometry`: muscle-tendon lengths and moment arms along a trajectory.

Coordinates are set as OpenSim's own tools set them: rotational values are converted from
degrees when the motion file says so, translational ones are left alone, and coupled
(dependent) coordinates, such as the Rajagopal model's ``knee_angle_r_beta`` and the
patellar coordinates, are never read from the file: they are computed from their
``CoordinateCouplerConstraint`` function of the independent coordinates. (In the example
IK files the ``knee_angle_r_beta`` column is in radians although the header says degrees,
so converting every column would be wrong.)

Moment arms follow OpenSim's definition: the moment a unit tension along the path exerts
about the coordinate, with every coordinate coupled to it moving through its coupler.
Three methods give them:

* ``"velocity"`` (default): give the coordinate a unit speed (coupled coordinates the
  speed their coupler implies), realise velocities, and read the path's lengthening speed:
  ``r = -dl/dt`` per unit speed. This is the same virtual-work identity OpenSim's moment-arm
  solver uses, for all muscles at once: one velocity realisation per DOF instead of one
  moment-arm solve per muscle and DOF. Paths that wrap over more than one object (the
  gastrocnemii) still go through ``computeMomentArm``: OpenSim's wrapping solution for them
  depends on the previous solution kept in the state, and its moment-arm solver works on a
  copy of the state with its own history, so only the solver itself reproduces what
  OpenSim's tools report (the lengthening-speed value differs by up to 1.7 mm).
* ``"opensim"``: ``Muscle.computeMomentArm`` itself (slow; for checking).
* ``"finite_difference"``: central differences of the path length. Not the default: for
  paths wrapping over several objects (the gastrocnemii) OpenSim's wrapped path length is
  not smooth in the way its moment-arm solver assumes, and differences reach 17 mm.

Only the (muscle, DOF) pairs whose moment arm is not identically zero are evaluated.
"""

from __future__ import annotations

import math
import os

import numpy as np
import opensim as osim

from ..errors import ModelError, UnknownCoordinateError, UnknownMuscleError
from ..messages import name_list

#: OpenSim's ``Coordinate.MotionType`` values (``getMotionType()``)
ROTATIONAL, TRANSLATIONAL, COUPLED = 1, 2, 3
_MODELS: dict = {}


class LoadedModel:
    """A model with its initialised state and the maps used to set coordinates fast
    (``model``: an ``opensim.Model`` already in memory, read from ``path`` and changed)."""

    def __init__(self, path: str, model=None):
        try:
            model = osim.Model(path) if model is None else model
            cset = model.getCoordinateSet()
            # locks as the file gives them; this process's copy is unlocked, so that every
            # coordinate follows the motion (OpenSim refuses a new value for a locked one)
            locked = {cset.get(i).getName(): bool(cset.get(i).get_locked()) for i in range(cset.getSize())}
            for i in range(cset.getSize()):
                cset.get(i).set_locked(False)
            state = model.initSystem()
        except Exception as exc:
            msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise ModelError(
                f"{path}: OpenSim cannot load this model ({msg}); check that it is a valid .osim file"
            ) from None
        self.model = model
        self.state = state
        cset = model.getCoordinateSet()
        self.coords = {cset.get(i).getName(): cset.get(i) for i in range(cset.getSize())}
        self.motion = {n: int(c.getMotionType()) for n, c in self.coords.items()}
        self.locked = locked
        self.couplers = []  # (dependent, [independents], function, scale)
        cons = model.getConstraintSet()
        for i in range(cons.getSize()):
            cc = osim.CoordinateCouplerConstraint.safeDownCast(cons.get(i))
            if cc is None or not cc.get_isEnforced():
                continue
            ind = cc.getIndependentCoordinateNames()
            names = [ind.get(j) for j in range(ind.getSize())]
            try:
                scale = float(cc.getPropertyByName("scale_factor").toString())
            except Exception:
                scale = 1.0
            self.couplers.append((cc.getDependentCoordinateName(), names, cc.getFunction(), scale))
        self.dependent = {c[0] for c in self.couplers}
        mset = model.getMuscles()
        self.muscles = {mset.get(i).getName(): mset.get(i) for i in range(mset.getSize())}
        self.muscle_order = [mset.get(i).getName() for i in range(mset.getSize())]

    def coupled_values(self, values: dict) -> dict:
        """Values of the dependent coordinates given the independent ones."""
        out = {}
        for dep, ind, fun, scale in self.couplers:
            vec = osim.Vector(len(ind), 0.0)
            for j, n in enumerate(ind):
                vec.set(j, values[n] if n in values else out.get(n, self.coords[n].getDefaultValue()))
            out[dep] = scale * fun.calcValue(vec)
        return out


def model_muscles(model, names, path, remedy: str) -> dict:
    """``{name: muscle}`` of ``model`` (an ``osim.Model``) for ``names``; a name the model lacks
    raises :class:`UnknownMuscleError` naming the model file ``path`` and ``remedy``."""
    ms = model.getMuscles()
    have = {ms.get(i).getName() for i in range(ms.getSize())}
    missing = [n for n in names if n not in have]
    if missing:
        raise UnknownMuscleError(f"{path}: the model has no muscle {name_list(missing)}; {remedy}")
    return {n: ms.get(n) for n in names}


def load_model(path: str) -> LoadedModel:
    """The model at ``path``, loaded once while the file is unchanged (the last one is kept)."""
    path = os.path.abspath(path)
    if not os.path.isfile(path):
        raise ModelError(f"{path}: no such model file; check the path")
    key = (path, os.path.getmtime(path), os.path.getsize(path))
    if key not in _MODELS:
        _MODELS.clear()
        _MODELS[key] = LoadedModel(path)
    return _MODELS[key]


def read_model_info(model_path: str) -> dict:
    """Muscles (name, class, F0, lMo, lTs, alpha0, vmax), body mass, coordinates, couplers."""
    m = load_model(model_path)
    muscles = []
    for name in m.muscle_order:
        mu = m.muscles[name]
        muscles.append(
            dict(
                name=name,
                class_name=mu.getConcreteClassName(),
                max_isometric_force_N=mu.getMaxIsometricForce(),
                optimal_fiber_length_m=mu.getOptimalFiberLength(),
                tendon_slack_length_m=mu.getTendonSlackLength(),
                pennation_angle_at_optimal_rad=mu.getPennationAngleAtOptimalFiberLength(),
                max_contraction_velocity=mu.getMaxContractionVelocity(),
            )
        )
    bodies = m.model.getBodySet()
    mass = sum(bodies.get(i).getMass() for i in range(bodies.getSize()))
    coordinates = [
        dict(
            name=n,
            motion_type={ROTATIONAL: "rotational", TRANSLATIONAL: "translational", COUPLED: "coupled"}.get(
                m.motion[n], "unknown"
            ),
            locked=m.locked[n],
            dependent=n in m.dependent,
            range=(c.getRangeMin(), c.getRangeMax()),
            default_value=c.getDefaultValue(),
        )
        for n, c in m.coords.items()
    ]
    return dict(
        path=os.path.abspath(model_path),
        name=m.model.getName(),
        muscles=muscles,
        body_mass_kg=mass,
        coordinates=coordinates,
        couplers=[dict(dependent=d, independent=i) for d, i, _, _ in m.couplers],
        opensim_version=osim.__version__,
    )


def frame_values(m: LoadedModel, columns: dict, in_degrees: bool, k: int, *, coupled_motion: bool = False) -> dict:
    """The values (rad, m) of the model's independent coordinates at frame ``k`` of the motion
    ``columns`` (``{coordinate: values}``; rotations in degrees when ``in_degrees``), and those
    of its coupled coordinates computed from them. ``coupled_motion``: also set the independent
    coordinates OpenSim reports as of coupled motion type (gait2392's pelvis translations), as
    OpenSim does, without a degree conversion. A coordinate the model locks follows the motion
    like the others (:class:`LoadedModel` unlocks this process's copy): the muscle paths are
    those of the pose the motion gives, and a solve refuses a motion that moves a locked
    coordinate of the solved leg (:func:`musclemetab.layout.check_locked_coordinates`)."""
    vals = {}
    for n, col in columns.items():
        if n not in m.coords or n in m.dependent or (m.motion[n] == COUPLED and not coupled_motion):
            continue
        v = float(col[k])
        if in_degrees and m.motion[n] == ROTATIONAL:
            v = math.radians(v)
        vals[n] = v
    vals.update(m.coupled_values(vals))
    return vals


def muscle_geometry(
    model_path: str,
    time: np.ndarray,
    columns: dict,
    in_degrees: bool,
    dofs: list,
    muscles: list | None = None,
    selection_threshold_m: float = 1e-4,
    method: str = "velocity",
    step_rad: float = 1e-5,
) -> dict:
    """Muscle-tendon lengths and moment arms along a coordinate trajectory.

    Parameters
    ----------
    columns
        Coordinate name -> values (file units), one value per frame.
    in_degrees
        Whether rotational values are in degrees (the file's ``inDegrees``).
    dofs
        Coordinates for the moment arms.
    muscles
        Muscles to evaluate; ``None`` selects every model muscle whose moment arm about
        at least one of ``dofs`` exceeds ``selection_threshold_m`` in magnitude at the first
        frame (model order).

    Returns
    -------
    dict with ``muscles``, ``dofs``, ``lmt_m`` (frames x muscles), ``moment_arms_m``
    (frames x dofs x muscles), ``defaulted_coordinates`` (unlocked coordinates absent from
    ``columns``, held at their default value).
    """
    m = load_model(model_path)
    for d in dofs:
        if d not in m.coords:
            raise UnknownCoordinateError(
                f"{model_path}: the model has no coordinate '{d}'; available: "
                f"{', '.join(n for n in m.coords if not m.locked[n])}"
            )
        if m.locked[d] or d in m.dependent:
            raise UnknownCoordinateError(
                f"{model_path}: coordinate '{d}' is locked or coupled and cannot be a degree of freedom"
            )
    if method not in ("velocity", "finite_difference", "opensim"):
        raise ValueError(f"unknown moment-arm method {method!r}")
    n_frames = len(time)
    defaulted = [
        n for n in m.coords if not m.locked[n] and n not in m.dependent and n not in columns
    ]
    if any(d not in columns for d in dofs):
        raise UnknownCoordinateError(
            f"the motion has no column for {name_list([d for d in dofs if d not in columns])}"
        )
    model, state = m.model, m.state
    coords = m.coords
    # dependents moved with each DOF
    deps_of = {d: [c for c in m.couplers if d in c[1]] for d in dofs}

    def apply(values: dict) -> None:
        for n, v in values.items():
            coords[n].setValue(state, v, False)
        model.realizePosition(state)

    if muscles is None:
        apply(frame_values(m, columns, in_degrees, 0))
        selected = []
        for name in m.muscle_order:
            mu = m.muscles[name]
            r = [mu.computeMomentArm(state, coords[d]) for d in dofs]
            if max(abs(x) for x in r) > selection_threshold_m:
                selected.append(name)
        muscles = selected
    else:
        unknown = [x for x in muscles if x not in m.muscles]
        if unknown:
            raise UnknownMuscleError(
                f"{model_path}: the model has no muscle {name_list(unknown)}; "
                "check the names (they carry the side suffix, e.g. soleus_r)"
            )
    mus = [m.muscles[x] for x in muscles]
    n_mus, n_dofs = len(mus), len(dofs)
    lmt = np.empty((n_frames, n_mus))
    arms = np.zeros((n_frames, n_dofs, n_mus))
    h = step_rad
    # Which muscles span which DOF: a muscle with no path point on a body the coordinate
    # moves has a moment arm of exactly zero (to round-off) at every frame.
    apply(frame_values(m, columns, in_degrees, 0))
    spans = np.array(
        [[abs(mu.computeMomentArm(state, coords[d])) > 1e-12 for mu in mus] for d in dofs], dtype=bool
    ).reshape(n_dofs, n_mus)
    sets = [np.flatnonzero(spans[j]) for j in range(n_dofs)]
    multi_wrap = np.array([mu.getGeometryPath().getWrapSet().getSize() > 1 for mu in mus], dtype=bool)
    if method == "velocity":  # paths over several wrap objects: OpenSim's solver (see above)
        api_sets = [np.flatnonzero(spans[j] & multi_wrap) for j in range(n_dofs)]
        sets = [np.flatnonzero(spans[j] & ~multi_wrap) for j in range(n_dofs)]
    for k in range(n_frames):
        vals = frame_values(m, columns, in_degrees, k)
        apply(vals)
        lmt[k] = [mu.getLength(state) for mu in mus]
        if method == "velocity":
            for j, d in enumerate(dofs):
                arms[k, j, api_sets[j]] = [mus[i].computeMomentArm(state, coords[d]) for i in api_sets[j]]
        for j, d in enumerate(dofs):
            idx = sets[j]
            if idx.size == 0:
                continue
            if method == "velocity":
                # unit generalised speed of d, coupled coordinates moving with it
                state.updU().setToZero()
                coords[d].setSpeedValue(state, 1.0)
                if deps_of[d]:
                    up = m.coupled_values({**vals, d: vals[d] + h})
                    down = m.coupled_values({**vals, d: vals[d] - h})
                    for c in deps_of[d]:
                        coords[c[0]].setSpeedValue(state, (up[c[0]] - down[c[0]]) / (2 * h))
                model.realizeVelocity(state)
                arms[k, j, idx] = [-mus[i].getLengtheningSpeed(state) for i in idx]
            elif method == "opensim":
                arms[k, j, idx] = [mus[i].computeMomentArm(state, coords[d]) for i in idx]
            else:
                q0 = vals[d]
                plus_minus = []
                for q in (q0 + h, q0 - h):
                    pert = {d: q}
                    if deps_of[d]:
                        pert.update(m.coupled_values({**vals, d: q}))
                    apply(pert)
                    plus_minus.append([mus[i].getLength(state) for i in idx])
                arms[k, j, idx] = -(np.asarray(plus_minus[0]) - np.asarray(plus_minus[1])) / (2 * h)
                coords[d].setValue(state, q0, False)
                for c in deps_of[d]:
                    coords[c[0]].setValue(state, vals[c[0]], False)
    return dict(
        muscles=list(muscles),
        dofs=list(dofs),
        time=np.asarray(time, dtype=float),
        lmt_m=lmt,
        moment_arms_m=arms,
        defaulted_coordinates=defaulted,
        opensim_version=osim.__version__,
    )


def read_time_series_table(path: str) -> dict:
    """Read a storage file with ``opensim.TimeSeriesTable`` (used to check our writer)."""
    table = osim.TimeSeriesTable(path)
    labels = list(table.getColumnLabels())
    mat = table.getMatrix().to_numpy()
    meta = {k: table.getTableMetaDataAsString(k) for k in table.getTableMetaDataKeys()}
    return dict(labels=labels, time=np.asarray(table.getIndependentColumn()), values=mat, metadata=meta)


def model_layout(model_path: str) -> dict:
    """Joints, bodies and coordinates of a model, with where each body sits in the default pose.

    Returns a dict with

    * ``gravity``: the gravity vector (m/s^2, ground frame);
    * ``bodies``: body names;
    * ``joints``: one dict per joint in model order: ``name``, ``parent`` and ``child``
      (base body names, ``ground`` for the ground), ``depth`` (number of joints between the
      child and the ground), ``child_origin_m`` (position of the child body's origin in the
      ground frame at the default pose), ``coordinates`` (names, joint order);
    * ``coordinates``: one dict per coordinate: ``name``, ``joint``, ``locked``,
      ``dependent`` (driven by a coupler), ``motion_type``, ``default_value`` (rad or m; the
      value a locked coordinate is held at);
    * ``root_translations``: for each coordinate of the joint(s) attached to the ground, the
      displacement (m, ground frame) of the child body's origin when that coordinate grows by
      one unit from its default (a translational coordinate gives its axis; a rotation about
      the body's origin gives zero).
    """
    m = load_model(model_path)
    model, state = m.model, m.state
    names = {ROTATIONAL: "rotational", TRANSLATIONAL: "translational", COUPLED: "coupled"}
    bodies = model.getBodySet()
    body_names = [bodies.get(i).getName() for i in range(bodies.getSize())]
    for n, c in m.coords.items():
        c.setValue(state, c.getDefaultValue(), False)
    model.realizePosition(state)

    def origin(name):
        if name not in body_names:
            return [0.0, 0.0, 0.0]
        p = bodies.get(name).getPositionInGround(state)
        return [p.get(0), p.get(1), p.get(2)]

    jset = model.getJointSet()
    joints, parent_of = [], {}
    for i in range(jset.getSize()):
        j = jset.get(i)
        parent = j.getParentFrame().findBaseFrame().getName()
        child = j.getChildFrame().findBaseFrame().getName()
        parent_of[child] = parent
        joints.append(dict(
            name=j.getName(), parent=parent, child=child, child_origin_m=origin(child),
            coordinates=[j.get_coordinates(k).getName() for k in range(j.numCoordinates())],
        ))
    ground = model.getGround().getName()

    def depth(body):
        d = 0
        while body in parent_of and body != ground and d < 1000:
            body, d = parent_of[body], d + 1
        return d

    for j in joints:
        j["depth"] = depth(j["child"])
    joint_of = {c: j["name"] for j in joints for c in j["coordinates"]}
    coordinates = [
        dict(name=n, joint=joint_of.get(n, ""), locked=m.locked[n], dependent=n in m.dependent,
             motion_type=names.get(m.motion[n], "unknown"), default_value=m.coords[n].getDefaultValue())
        for n in m.coords
    ]
    root_translations = {}
    for j in joints:
        if j["parent"] != ground:
            continue
        base = np.array(origin(j["child"]))
        for n in j["coordinates"]:
            c = m.coords[n]
            c.setValue(state, c.getDefaultValue() + 1.0, False)
            model.realizePosition(state)
            root_translations[n] = (np.array(origin(j["child"])) - base).tolist()
            c.setValue(state, c.getDefaultValue(), False)
            model.realizePosition(state)
    g = model.getGravity()
    return dict(
        gravity=[g.get(0), g.get(1), g.get(2)],
        ground=ground,
        bodies=body_names,
        joints=joints,
        coordinates=coordinates,
        root_translations=root_translations,
    )


def body_origins(model_path: str, columns: dict, in_degrees: bool, bodies: list) -> dict:
    """Positions (m, ground frame) of the origins of ``bodies`` along a coordinate trajectory.

    Coordinates are set frame by frame as for :func:`muscle_geometry` (degrees converted,
    coupled coordinates from their couplers, coordinates absent from ``columns`` at their
    default). Returns ``{"positions_m": (frames, bodies, 3)}``.
    """
    m = load_model(model_path)
    model, state = m.model, m.state
    body_set = model.getBodySet()
    names = [body_set.get(i).getName() for i in range(body_set.getSize())]
    missing = [b for b in bodies if b not in names]
    if missing:
        raise ModelError(f"{model_path}: the model has no body {name_list(missing)}")
    objs = [body_set.get(b) for b in bodies]
    n_frames = len(next(iter(columns.values()))) if columns else 0
    for n, c in m.coords.items():
        c.setValue(state, c.getDefaultValue(), False)
    out = np.zeros((n_frames, len(bodies), 3))
    for k in range(n_frames):
        for n, v in frame_values(m, columns, in_degrees, k, coupled_motion=True).items():
            m.coords[n].setValue(state, v, False)
        model.realizePosition(state)
        for j, b in enumerate(objs):
            p = b.getPositionInGround(state)
            out[k, j] = (p.get(0), p.get(1), p.get(2))
    return {"positions_m": out}
