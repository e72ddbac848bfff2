"""OpenSim MocoInverse baseline for the solver benchmark (imports opensim only, never casadi).

Run as a separate process by ``benchmarks/solver.py --baseline moco``; prints one JSON line.
The set-up follows ``docs/solver.md`` (a one-leg stand-in for a full-body
MocoInverse, because the example data has no ground reaction forces):

1. keep the 40 right-leg muscles, remove every other force;
2. the quadriceps' patella path points become MovingPathPoints on the femur and tibia whose
   locations are splines of the knee angle (with prescribed kinematics Moco drops the
   patella coupler, and the quadriceps would otherwise not act on the knee);
3. weld every joint except the right hip, knee, patellofemoral and ankle joints;
4. DeGroote-Fregly 2016 muscles, rigid tendons or implicit compliant tendons, reserves of
   optimal force 1;
5. per free coordinate, a CoordinateActuator driven by a PrescribedController with
   ``tau_leg(t) - tau_ID(t)`` (``tau_leg``: the reduced model's own inverse dynamics along
   the kinematics; the knee takes knee + beta), weight 0 in the effort goal, so that muscles
   plus reserves produce the study's ID moments;
6. kinematics in radians, low-pass 6 Hz (4th-order zero-phase Butterworth).

Usage::

    python benchmarks/_moco_baseline.py --model M.osim --ik IK.mot --id ID.sto \\
        [--mesh-interval 0.01] [--tendons compliant|rigid] [--window T0:T1] [--workdir DIR] \\
        [--write-trajectory DIR]

``--write-trajectory DIR`` (for ``benchmarks/moco_states.py``) writes the solved model
(``model.osim``), the solution as a MocoTrajectory file with the free coordinates' values and
speeds added from the filtered kinematics (a MocoInverse solution has none) and the prescribed
loads' controls (``moco_solution.sto``: states, controls and the tendon-force derivatives), and
the muscle outputs Moco reports along it (``moco_outputs.sto``, ``analyzeMocoTrajectory``:
normalized fiber velocity, force-velocity multiplier, passive fiber force).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time

import numpy as np

FREE_JOINTS = ("hip_r", "walker_knee_r", "patellofemoral_r", "ankle_r")
FREE_COORDS = ("hip_flexion_r", "hip_adduction_r", "hip_rotation_r", "knee_angle_r", "knee_angle_r_beta",
               "ankle_angle_r")
DOFS = ("ankle_angle_r", "knee_angle_r", "hip_flexion_r", "hip_adduction_r", "hip_rotation_r")


def _read_storage(path):
    with open(path) as f:
        lines = f.read().splitlines()
    end = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader")
    header = [ln.strip().lower() for ln in lines[:end]]
    names = lines[end + 1].split()
    data = np.array([[float(x) for x in ln.split()] for ln in lines[end + 2:] if ln.strip()])
    in_degrees = "indegrees=yes" in header
    return names, data, in_degrees


def _lowpass(x, fs, cutoff=6.0, order=4):
    from scipy.signal import butter, filtfilt

    b, a = butter(order, cutoff / (fs / 2.0))
    return filtfilt(b, a, x, axis=0, padtype="odd", padlen=3 * (max(len(a), len(b)) - 1))


def _patella_to_moving_points(osim, model, grid_rad):
    """Replace the right quadriceps' patella points by MovingPathPoints (femur/tibia)."""
    state = model.initSystem()
    cs = model.getCoordinateSet()
    knee, beta = cs.get("knee_angle_r"), cs.get("knee_angle_r_beta")
    bodies = {n: model.getBodySet().get(n) for n in ("patella_r", "femur_r", "tibia_r")}
    edits = []  # (muscle, index, point name, target body, locations (G, 3))
    for muscle in model.getMuscles():
        if not muscle.getName().endswith("_r"):
            continue
        pps = muscle.getGeometryPath().getPathPointSet()
        frames = [pps.get(i).getParentFrame().getName() for i in range(pps.getSize())]
        i = 0
        while i < len(frames):
            if frames[i] != "patella_r":
                i += 1
                continue
            j = i
            while j + 1 < len(frames) and frames[j + 1] == "patella_r":
                j += 1
            # alternate from the end of the run so that no segment has both ends on one body
            nxt = frames[j + 1] if j + 1 < len(frames) else "tibia_r"
            body = "femur_r" if nxt == "tibia_r" else "tibia_r"
            targets = {}
            for k in range(j, i - 1, -1):
                targets[k] = body
                body = "tibia_r" if body == "femur_r" else "femur_r"
            for k in range(i, j + 1):
                edits.append((muscle.getName(), k, pps.get(k).getName(), targets[k],
                              np.array(osim.PathPoint.safeDownCast(pps.get(k)).get_location().to_numpy())))
            i = j + 1
    if not edits:
        return [], {}
    samples = {e[2]: np.zeros((grid_rad.size, 3)) for e in edits}
    for g, q in enumerate(grid_rad):
        knee.setValue(state, float(q), False)
        beta.setValue(state, float(q), False)
        model.realizePosition(state)
        for _, _, name, target, loc in edits:
            v = bodies["patella_r"].findStationLocationInAnotherFrame(state, osim.Vec3(*loc), bodies[target])
            samples[name][g] = [v.get(0), v.get(1), v.get(2)]
    return edits, samples


def _write_moving_points(model_path, out_path, edits, samples, grid_rad):
    """Rewrite the model file with the patella points replaced by MovingPathPoints."""
    import xml.etree.ElementTree as ET

    tree = ET.parse(model_path)
    root = tree.getroot()
    targets = {name: target for _, _, name, target, _ in edits}
    knee = "/jointset/walker_knee_r/knee_angle_r"
    xs = " ".join(f"{q:.17g}" for q in grid_rad)
    for parent in root.iter("objects"):
        for i, child in enumerate(list(parent)):
            name = child.get("name")
            if child.tag != "PathPoint" or name not in targets:
                continue
            mpp = ET.Element("MovingPathPoint", {"name": name})
            ET.SubElement(mpp, "socket_parent_frame").text = f"/bodyset/{targets[name]}"
            for axis, tag in enumerate(("x_location", "y_location", "z_location")):
                loc = ET.SubElement(mpp, tag)
                spline = ET.SubElement(loc, "SimmSpline", {"name": tag})
                ET.SubElement(spline, "x").text = xs
                ET.SubElement(spline, "y").text = " ".join(f"{v:.17g}" for v in samples[name][:, axis])
            for tag in ("socket_x_coordinate", "socket_y_coordinate", "socket_z_coordinate"):
                ET.SubElement(mpp, tag).text = knee
            parent.remove(child)
            parent.insert(i, mpp)
    tree.write(out_path, xml_declaration=True, encoding="UTF-8")


def build(model_path, ik_path, id_path, mesh_interval, tendons, workdir, window=None):
    import opensim as osim

    osim.Logger.setLevelString("error")
    t_setup = time.perf_counter()
    model = osim.Model(str(model_path))
    model.initSystem()

    # kinematics (radians), filtered; beta follows the knee (identity coupler)
    names, data, in_deg = _read_storage(ik_path)
    t = data[:, 0]
    fs = 1.0 / np.mean(np.diff(t))
    cols = {n: data[:, i] for i, n in enumerate(names)}
    q = {}
    for c in FREE_COORDS:
        src = "knee_angle_r" if c == "knee_angle_r_beta" else c
        q[c] = np.deg2rad(cols[src]) if in_deg else cols[src]
    qf = _lowpass(np.column_stack([q[c] for c in FREE_COORDS]), fs)

    # reference lengths of the coupled model at a few knee angles, to check the patella fix
    grid = np.linspace(-0.2, 2.1, 47)
    check_q = np.linspace(0.0, 1.2, 7)
    state = model.initSystem()

    def lengths(m, st, names_):
        cs = m.getCoordinateSet()
        out = []
        for qq in check_q:
            cs.get("knee_angle_r").setValue(st, float(qq), False)
            cs.get("knee_angle_r_beta").setValue(st, float(qq), False)
            m.realizePosition(st)
            out.append([m.getMuscles().get(n).getLength(st) for n in names_])
        return np.array(out)

    quads = ["recfem_r", "vasint_r", "vaslat_r", "vasmed_r"]
    before = lengths(model, state, quads)
    edits, samples = _patella_to_moving_points(osim, model, grid)
    moved_path = os.path.join(workdir, "model_patella_moving_points.osim")
    _write_moving_points(str(model_path), moved_path, edits, samples, grid)
    geometry_dir = os.path.join(os.path.dirname(os.path.abspath(str(model_path))), "Geometry")
    if os.path.isdir(geometry_dir):
        osim.ModelVisualizer.addDirToGeometrySearchPaths(geometry_dir)
    model = osim.Model(moved_path)
    state = model.initSystem()
    after = lengths(model, state, quads)
    patella_check_mm = float(np.max(np.abs(after - before)) * 1e3)

    # keep the 40 right-leg muscles only, no constraints
    fs_set = model.updForceSet()
    for i in range(fs_set.getSize() - 1, -1, -1):
        f = fs_set.get(i)
        if not (osim.Muscle.safeDownCast(f) is not None and f.getName().endswith("_r")):
            fs_set.remove(i)
    cset = model.updConstraintSet()
    for i in range(cset.getSize() - 1, -1, -1):
        cset.remove(i)
    model.finalizeConnections()
    welds = osim.StdVectorString()
    for j in model.getJointSet():
        if j.getName() not in FREE_JOINTS:
            welds.append(j.getName())

    # tau_leg: inverse dynamics of the reduced skeleton (no forces) along the kinematics
    skel = osim.Model(model)
    sfs = skel.updForceSet()
    for i in range(sfs.getSize() - 1, -1, -1):
        sfs.remove(i)
    skel.finalizeConnections()
    skel = osim.ModelProcessor(skel)
    skel.append(osim.ModOpReplaceJointsWithWelds(welds))
    skel = skel.process()
    sstate = skel.initSystem()
    from scipy.interpolate import CubicSpline

    spl = CubicSpline(t, qf, axis=0)
    qd, qdd = spl(t, 1), spl(t, 2)
    coords = {c.getName(): c for c in skel.getCoordinateSet()}
    uidx = {}
    for c in FREE_COORDS:  # mobility index of each coordinate: set its speed alone to 1
        for other in coords.values():
            other.setSpeedValue(sstate, 0.0)
        coords[c].setSpeedValue(sstate, 1.0)
        u = sstate.getU().to_numpy()
        uidx[c] = int(np.argmax(u))
        assert u[uidx[c]] == 1.0 and np.count_nonzero(u) == 1, c
    solver = osim.InverseDynamicsSolver(skel)
    tau_leg = np.zeros((t.size, len(FREE_COORDS)))
    for k in range(t.size):
        for j, c in enumerate(FREE_COORDS):
            coords[c].setValue(sstate, float(qf[k, j]), False)
            coords[c].setSpeedValue(sstate, float(qd[k, j]))
        skel.realizeVelocity(sstate)
        udot = osim.Vector(sstate.getNU(), 0.0)
        for j, c in enumerate(FREE_COORDS):
            udot.set(uidx[c], float(qdd[k, j]))
        tau = solver.solve(sstate, udot)
        for j, c in enumerate(FREE_COORDS):
            tau_leg[k, j] = tau.get(uidx[c])

    # study ID moments (filtered like the solver's), the knee takes knee + beta
    inames, idata, _ = _read_storage(id_path)
    it = idata[:, 0]
    icol = {n: idata[:, i] for i, n in enumerate(inames)}
    fs_id = 1.0 / np.mean(np.diff(it))
    tau_id = {}
    for c in FREE_COORDS:
        if c == "knee_angle_r_beta":
            v = np.zeros_like(it)
        elif c == "knee_angle_r":
            v = icol["knee_angle_r_moment"] + icol.get("knee_angle_r_beta_force", 0.0 * it)
        else:
            v = icol[f"{c}_moment"]
        b = _lowpass(v[:, None], fs_id, 6.0, 6)[:, 0]
        tau_id[c] = np.interp(t, it, b)

    proc = osim.ModelProcessor(model)
    proc.append(osim.ModOpReplaceJointsWithWelds(welds))
    proc.append(osim.ModOpReplaceMusclesWithDeGrooteFregly2016())
    if tendons == "rigid":
        proc.append(osim.ModOpIgnoreTendonCompliance())
    else:
        proc.append(osim.ModOpTendonComplianceDynamicsModeDGF("implicit"))
    proc.append(osim.ModOpAddReserves(1.0))
    reduced = proc.process()
    pc = osim.PrescribedController()
    pc.setName("applied_loads")
    for j, c in enumerate(FREE_COORDS):
        act = osim.CoordinateActuator(c)
        act.setName(f"applied_{c}")
        act.setOptimalForce(1.0)
        act.setMinControl(-math.inf)
        act.setMaxControl(math.inf)
        reduced.addForce(act)
        pc.addActuator(act)
        f = osim.PiecewiseLinearFunction()
        for k in range(t.size):
            f.addPoint(float(t[k]), float(tau_leg[k, j] - tau_id[c][k]))
        pc.prescribeControlForActuator(act.getName(), f)
    reduced.addController(pc)
    reduced.finalizeConnections()
    reduced.initSystem()

    table = osim.TimeSeriesTable()
    labels = osim.StdVectorString()
    path_of = {c.getName(): c.getAbsolutePathString() for c in reduced.getCoordinateSet()}
    for c in FREE_COORDS:
        labels.append(path_of[c] + "/value")
    table.setColumnLabels(labels)
    table.addTableMetaDataString("inDegrees", "no")
    for k in range(t.size):
        row = osim.RowVector(len(FREE_COORDS), 0.0)
        for j in range(len(FREE_COORDS)):
            row[j] = float(qf[k, j])
        table.appendRow(float(t[k]), row)

    inverse = osim.MocoInverse()
    inverse.setName("moco_baseline")
    inverse.setModel(osim.ModelProcessor(reduced))
    inverse.setKinematics(osim.TableProcessor(table))
    inverse.set_initial_time(float(t[0]) if window is None else float(window[0]))
    inverse.set_final_time(float(t[-1]) if window is None else float(window[1]))
    inverse.set_mesh_interval(float(mesh_interval))
    inverse.set_kinematics_allow_extra_columns(True)
    study = inverse.initialize()
    problem = study.updProblem()
    effort = osim.MocoControlGoal.safeDownCast(problem.updGoal("excitation_effort"))
    for c in FREE_COORDS:
        effort.setWeightForControl(f"/forceset/applied_{c}", 0.0)
    setup_s = time.perf_counter() - t_setup
    return study, reduced, {"patella_points_moved": len(edits), "patella_length_check_mm": patella_check_mm,
                            "setup_s": setup_s, "kinematics": (t, qf)}


def write_trajectory(osim, sol, reduced, kinematics, out_dir):
    """The files of ``--write-trajectory`` (module docstring) in ``out_dir``."""
    from scipy.interpolate import CubicSpline

    os.makedirs(out_dir, exist_ok=True)
    reduced.printToXML(os.path.join(out_dir, "model.osim"))
    t_k, qf = kinematics
    spline = CubicSpline(t_k, qf, axis=0)
    t = np.array(sol.getTimeMat()).ravel()
    path_of = {c.getName(): c.getAbsolutePathString() for c in reduced.getCoordinateSet()}
    coords = osim.TimeSeriesTable()
    labels = osim.StdVectorString()
    for suffix in ("value", "speed"):
        for c in FREE_COORDS:
            labels.append(f"{path_of[c]}/{suffix}")
    coords.setColumnLabels(labels)
    values, speeds = spline(t), spline(t, 1)
    for k in range(t.size):
        row = osim.RowVector(2 * len(FREE_COORDS), 0.0)
        for j in range(len(FREE_COORDS)):
            row[j], row[len(FREE_COORDS) + j] = float(values[k, j]), float(speeds[k, j])
        coords.appendRow(float(t[k]), row)
    sol.insertStatesTrajectory(coords, True)
    sol.generateControlsFromModelControllers(reduced)
    sol.write(os.path.join(out_dir, "moco_solution.sto"))
    paths = osim.StdVectorString()
    for name in ("normalized_fiber_velocity", "force_velocity_multiplier", "passive_fiber_force"):
        paths.append(f".*{name}")
    osim.STOFileAdapter.write(osim.analyzeMocoTrajectory(reduced, sol, paths),
                              os.path.join(out_dir, "moco_outputs.sto"))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True)
    p.add_argument("--ik", required=True)
    p.add_argument("--id", required=True)
    p.add_argument("--mesh-interval", type=float, default=0.01)
    p.add_argument("--tendons", choices=("compliant", "rigid"), default="compliant")
    p.add_argument("--workdir")
    p.add_argument("--window", metavar="T0:T1", help="solve this window of the kinematics (default: all of it)")
    p.add_argument("--write-trajectory", metavar="DIR", help="write the solution's files there (module docstring)")
    args = p.parse_args(argv)
    window = tuple(float(v) for v in args.window.split(":")) if args.window else None
    workdir = args.workdir or tempfile.mkdtemp(prefix="moco-baseline-")
    os.makedirs(workdir, exist_ok=True)
    cwd = os.getcwd()
    os.chdir(workdir)  # Moco writes its own files into the working directory
    try:
        study, reduced, info = build(args.model, args.ik, args.id, args.mesh_interval, args.tendons, workdir, window)
        kinematics = info.pop("kinematics")
        t0, c0 = time.perf_counter(), time.process_time()  # CPU time of every thread of the process
        sol = study.solve()
        solve_s, solve_cpu_s = time.perf_counter() - t0, time.process_time() - c0
        out = dict(info, tendons=args.tendons, mesh_interval=args.mesh_interval, solve_s=solve_s, solve_cpu_s=solve_cpu_s,
                   success=bool(sol.success()), status=sol.getStatus(), iterations=int(sol.getNumIterations()),
                   objective=float(sol.getObjective()))
        try:
            sol.unseal()
            reserves = [n for n in sol.getControlNames() if "reserve" in n]
            out["max_reserve_control"] = max(float(np.max(np.abs(sol.getControl(n).to_numpy()))) for n in reserves)
        except Exception:  # noqa: BLE001 - diagnostics only
            pass
        if args.write_trajectory:
            import opensim as osim

            write_trajectory(osim, sol, reduced, kinematics, os.path.abspath(os.path.join(cwd, args.write_trajectory)))
    finally:
        os.chdir(cwd)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
