"""OpenSim's side of the lab data (run inside the OpenSim worker only): how OpenSim reads the
marker and ground-force files the package writes."""

from __future__ import annotations

import os

import opensim as osim


def read_lab_files(trc_path: str | None = None, external_loads_path: str | None = None) -> dict:
    """What OpenSim reads from a ``.trc`` (marker names, frames, rate, units) and an
    ExternalLoads file (its forces: name, body, identifiers; the number of rows of its data)."""
    out = {}
    if trc_path:
        table = osim.TimeSeriesTableVec3(os.path.abspath(trc_path))
        out["markers"] = list(table.getColumnLabels())
        out["frames"] = int(table.getNumRows())
        out["units"] = table.getTableMetaDataAsString("Units")
        out["rate"] = float(table.getTableMetaDataAsString("DataRate"))
        first = table.getRowAtIndex(0)
        out["first_row_m"] = [[first[i][k] for k in range(3)] for i in range(first.size())]
    if external_loads_path:
        loads = osim.ExternalLoads(os.path.abspath(external_loads_path), True)
        forces = []
        for i in range(loads.getSize()):
            f = loads.get(i)
            forces.append({"name": f.getName(), "body": f.get_applied_to_body(),
                           "force_identifier": f.get_force_identifier(),
                           "point_identifier": f.get_point_identifier(),
                           "torque_identifier": f.get_torque_identifier()})
        datafile = loads.getDataFileName()
        if not os.path.isabs(datafile):
            datafile = os.path.join(os.path.dirname(os.path.abspath(external_loads_path)), datafile)
        data = osim.Storage(datafile)
        out["forces"] = forces
        out["data_rows"] = int(data.getSize())
    return out


def _absolute(name: str, folder: str) -> str:
    """A file name of a setup, resolved against the setup's folder; ``""`` for none."""
    name = (name or "").strip()
    if not name or name == "Unassigned":
        return ""
    return name if os.path.isabs(name) else os.path.normpath(os.path.join(folder, name))


def _array_double(values) -> "osim.ArrayDouble":
    a = osim.ArrayDouble()
    for v in values:
        a.append(float(v))
    return a


def _array_str(values) -> "osim.ArrayStr":
    a = osim.ArrayStr()
    for v in values:
        a.append(str(v))
    return a


def _marker_tasks(task_set, weights: dict) -> None:
    for name, w in weights.items():
        t = osim.IKMarkerTask()
        t.setName(name)
        t.setWeight(float(w))
        t.setApply(True)
        task_set.cloneAndAppend(t)


def _coordinate_tasks(task_set, model_path: str, weight: float) -> list:
    """Hold every coordinate of the model that is not the root joint's (the joint attached to
    the ground) at its default value with ``weight``; returns the coordinates."""
    model = osim.Model(os.path.abspath(model_path))
    ground = model.getGround().getAbsolutePathString()
    names = []
    for i in range(model.getJointSet().getSize()):
        joint = model.getJointSet().get(i)
        if joint.getParentFrame().findBaseFrame().getAbsolutePathString() == ground:
            continue
        for k in range(joint.numCoordinates()):
            c = joint.get_coordinates(k)
            if c.get_locked():
                continue
            t = osim.IKCoordinateTask()
            t.setName(c.getName())
            t.setWeight(float(weight))
            t.setValueType(osim.IKCoordinateTask.DefaultValue)
            t.setApply(True)
            task_set.cloneAndAppend(t)
            names.append(c.getName())
    return names


def _task_weights(task_set) -> dict:
    out = {}
    for i in range(task_set.getSize()):
        t = task_set.get(i)
        if osim.IKMarkerTask.safeDownCast(t) is not None and t.getApply() and t.getWeight() > 0:
            out[t.getName()] = float(t.getWeight())
    return out


def model_marker_names(model_path: str, marker_set: str | None = None) -> list[str]:
    """The markers of a model (with a marker-set file added, as the ScaleTool adds it)."""
    model = osim.Model(os.path.abspath(model_path))
    if marker_set:
        model.updateMarkerSet(osim.MarkerSet(os.path.abspath(marker_set)))
    return [model.getMarkerSet().get(i).getName() for i in range(model.getMarkerSet().getSize())]


def scale_model(generic_model: str, static_trc: str, mass_kg: float, out_dir: str, *, setup: str | None = None,
                marker_set: str | None = None, measurements: list | None = None, marker_weights: dict | None = None,
                time_range: tuple | None = None, coordinate_weight: float = 0.0) -> dict:
    """Scale ``generic_model`` to the static trial with OpenSim's ScaleTool and place its markers.

    With ``setup`` (a ScaleTool XML) the tool is that setup, its relative file names resolved
    against the setup's folder; the model, the static trial, the mass and every output are the
    caller's (outputs in ``out_dir``: ``model.osim``, ``static_pose.sto``, ``scale_set.xml``).
    Without it, the tool scales by ``measurements`` (``[{"name", "pairs": [[m1, m2], ...], "bodies":
    [...]}]``, every axis) and places the markers of ``marker_weights``, holding every coordinate but
    the root joint's at its default value with ``coordinate_weight`` (a static trial stands in the
    model's neutral pose). Returns the files, the
    scale factors by body, and the static pose's marker errors: the distance of every weighted
    marker of the scaled model (before the marker placer moves its markers onto the
    experimental ones) in the pose the placer found from its experimental position averaged over
    ``time_range`` (the errors OpenSim's ScaleTool reports) are measured by the caller from the
    model's markers in that pose (``static_model_markers``).
    """
    folder = os.path.dirname(os.path.abspath(setup)) if setup else ""
    tool = osim.ScaleTool(os.path.abspath(setup)) if setup else osim.ScaleTool()
    gmm = tool.getGenericModelMaker()
    gmm.setModelFileName(os.path.abspath(generic_model))
    ms_file = os.path.abspath(marker_set) if marker_set else _absolute(gmm.getMarkerSetFileName(), folder)
    gmm.setMarkerSetFileName(ms_file or "Unassigned")
    tool.setSubjectMass(float(mass_kg))
    tool.setPathToSubject("")
    scaler = tool.getModelScaler()
    placer = tool.getMarkerPlacer()
    if not setup:
        tool.setName("musclemetab")
        scaler.setApply(True)
        scaler.setScalingOrder(_array_str(["measurements"]))
        mset = scaler.getMeasurementSet()
        for m in measurements or []:
            meas = osim.Measurement()
            meas.setName(m["name"])
            meas.setApply(True)
            for a, b in m["pairs"]:
                meas.getMarkerPairSet().cloneAndAppend(osim.MarkerPair(a, b))
            for body in m["bodies"]:
                bs = osim.BodyScale()
                bs.setName(body)
                bs.setAxisNames(_array_str(["X", "Y", "Z"]))
                meas.getBodyScaleSet().cloneAndAppend(bs)
            mset.cloneAndAppend(meas)
        scaler.setPreserveMassDist(True)
        placer.setApply(True)
        _marker_tasks(placer.getIKTaskSet(), marker_weights or {})
        if coordinate_weight:
            _coordinate_tasks(placer.getIKTaskSet(), generic_model, coordinate_weight)
    else:
        coords = _absolute(placer.getCoordinateFileName(), folder)
        placer.setCoordinateFileName(coords or "Unassigned")
    static = os.path.abspath(static_trc)
    scaler.setMarkerFileName(static)
    placer.setStaticPoseFileName(static)
    if time_range is not None:
        scaler.setTimeRange(_array_double(time_range))
        placer.setTimeRange(_array_double(time_range))
    model_out = os.path.join(out_dir, "model.osim")
    pose_out = os.path.join(out_dir, "static_pose.sto")
    scaled_only = os.path.join(out_dir, "scaled_only.osim")
    scaler.setOutputModelFileName(scaled_only)
    scaler.setOutputScaleFileName(os.path.join(out_dir, "scale_set.xml"))
    placer.setOutputModelFileName(model_out)
    placer.setOutputMotionFileName(pose_out)
    placer.setOutputMarkerFileName("")
    ran, log = _run_logging_info(tool)
    if not ran:
        raise RuntimeError("OpenSim's ScaleTool reported a failure")
    if not os.path.isfile(model_out):
        raise RuntimeError("OpenSim's ScaleTool wrote no model (is the marker placer switched off in the setup?)")
    weights = _task_weights(placer.getIKTaskSet())
    tr = placer.getTimeRange()
    window = (tr.get(0), tr.get(1))
    return {
        "model": model_out, "static_pose": pose_out, "scale_set": os.path.join(out_dir, "scale_set.xml"),
        "marker_set": ms_file, "time_range": list(window), "mass_kg": float(tool.getSubjectMass()),
        "scale_factors": _scale_factors(os.path.join(out_dir, "scale_set.xml")),
        "static_model_markers": static_model_markers(scaled_only, pose_out, weights),
        "setup_model_file": gmm.getModelFileName(),
        "log": log,
    }


def _run_logging_info(tool) -> tuple[bool, str]:
    """``tool.run()`` with OpenSim's messages down to the info level collected: ``(its result,
    the messages)``; the log level of the worker is restored after it."""
    sink, level = osim.StringLogSink(), osim.Logger.getLevelString()
    osim.Logger.addSink(sink)
    osim.Logger.setLevelString("info")
    try:
        ran = tool.run()
    finally:
        osim.Logger.setLevelString(level)
        osim.Logger.removeSink(sink)
    return bool(ran), sink.getString()


def _scale_factors(path: str) -> dict:
    if not os.path.isfile(path):
        return {}
    scales = osim.ScaleSet(path)
    out = {}
    for i in range(scales.getSize()):
        s = scales.get(i)
        f = s.getScaleFactors()
        out[s.getSegmentName()] = [f.get(0), f.get(1), f.get(2)]
    return out


def static_model_markers(model_path: str, pose_path: str, weights: dict) -> list:
    """``[{"marker", "position_m", "weight"}]``: where each weighted marker of ``model_path`` (that
    the model has) lies in ground in the static pose of ``pose_path``; the caller measures the
    static marker errors against the experimental markers (:mod:`musclemetab.mocap.scaling`)."""
    model = osim.Model(os.path.abspath(model_path))
    state = model.initSystem()
    pose = osim.TimeSeriesTable(os.path.abspath(pose_path))
    labels = list(pose.getColumnLabels())
    row = pose.getRowAtIndex(0)
    for c in range(model.getCoordinateSet().getSize()):
        coord = model.getCoordinateSet().get(c)
        key = f"{coord.getAbsolutePathString()}/value"
        if key in labels:
            coord.setValue(state, row[labels.index(key)], False)
    model.realizePosition(state)
    out = []
    mset = model.getMarkerSet()
    for name, w in weights.items():
        if not mset.contains(name):
            continue
        p = mset.get(name).getLocationInGround(state)
        out.append({"marker": name, "position_m": [p.get(0), p.get(1), p.get(2)], "weight": w})
    return out


def inverse_kinematics(model_path: str, trc_path: str, out_dir: str, *, setup: str | None = None,
                       marker_weights: dict | None = None, time_range: tuple | None = None,
                       accuracy: float | None = None) -> dict:
    """OpenSim's InverseKinematicsTool on a marker file; writes ``ik.mot`` (degrees) into ``out_dir``
    and returns, per frame, OpenSim's RMS and maximum marker error and where the model's markers
    are (``model_marker_m``: frames x markers x 3, the caller finds the worst marker).

    With ``setup`` (an InverseKinematicsTool XML) its marker and coordinate tasks, accuracy and
    constraint weight are used and its coordinate file resolved against its folder; the model, the
    marker file and the outputs are the caller's. Without it every marker of ``marker_weights`` is
    a task with that weight.
    """
    import numpy as np

    folder = os.path.dirname(os.path.abspath(setup)) if setup else ""
    tool = osim.InverseKinematicsTool(os.path.abspath(setup)) if setup else osim.InverseKinematicsTool()
    model = osim.Model(os.path.abspath(model_path))
    tool.setModel(model)
    tool.setMarkerDataFileName(os.path.abspath(trc_path))
    if setup:
        coords = _absolute(tool.getCoordinateFileName(), folder)
        tool.setCoordinateFileName(coords or "")
    else:
        tool.setName("musclemetab")
        _marker_tasks(tool.getIKTaskSet(), marker_weights or {})
    if accuracy is not None:
        tool.set_accuracy(float(accuracy))
    if time_range is not None:
        tool.setStartTime(float(time_range[0]))
        tool.setEndTime(float(time_range[1]))
    out = os.path.join(out_dir, "ik.mot")
    tool.setOutputMotionFileName(out)
    tool.set_report_errors(True)
    tool.set_report_marker_locations(True)
    tool.setResultsDir(out_dir)
    if not tool.run():
        raise RuntimeError("OpenSim's InverseKinematicsTool reported a failure")
    name = tool.getName()
    errors = osim.TimeSeriesTable(os.path.join(out_dir, f"{name}_ik_marker_errors.sto"))
    cols = list(errors.getColumnLabels())
    err = errors.getMatrix().to_numpy()
    locs = osim.TimeSeriesTable(os.path.join(out_dir, f"{name}_ik_model_marker_locations.sto"))
    labels = list(locs.getColumnLabels())
    loc = locs.getMatrix().to_numpy()
    t = np.asarray(errors.getIndependentColumn(), dtype=float)
    names = list(dict.fromkeys(c[:-3] for c in labels if c.endswith(("_tx", "_ty", "_tz"))))
    return {
        "ik": out, "time": t.tolist(), "rms_m": err[:, cols.index("marker_error_RMS")].tolist(),
        "max_m": err[:, cols.index("marker_error_max")].tolist(), "markers": names,
        "model_marker_m": np.stack([loc[:, [labels.index(f"{n}_t{a}") for a in "xyz"]] for n in names], axis=1),
        "start_s": float(tool.getStartTime()), "end_s": float(tool.getEndTime()),
    }


def model_marker_positions(model_path: str) -> dict:
    """``{marker: [x, y, z]}`` (m, ground frame) of a model's markers in its default pose."""
    model = osim.Model(os.path.abspath(model_path))
    state = model.initSystem()
    model.realizePosition(state)
    out = {}
    for i in range(model.getMarkerSet().getSize()):
        m = model.getMarkerSet().get(i)
        p = m.getLocationInGround(state)
        out[m.getName()] = [p.get(0), p.get(1), p.get(2)]
    return out
