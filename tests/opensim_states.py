"""OpenSim inputs of tests/test_metabolics_states.py, made with OpenSim's API (run as a script in its
own process: OpenSim only).

``python tests/opensim_states.py probes MODEL.osim OUT.osim [--rigid-left]`` writes the model with an
``Umberger2010MuscleMetabolicsProbe`` named ``UM10`` (Bhargava recruitment, negative work and
forbidding negative power off: the UM10 settings of docs/metabolics.md section 6) and a
``Bhargava2004MuscleMetabolicsProbe`` named ``BH04`` (force-dependent shortening constant on,
maintenance length dependence = identity, negative work on, negative power forbidden) on every
muscle; basal heat and the minimum heat rate off. Slow-twitch ratio 0.3 + 0.5 k / (n - 1) for the
k-th of the model's n muscles; OpenSim's default specific tension (0.25 MPa) and density
(1059.7 kg/m^3), so that the probes compute each mass, except the first muscle's, provided as 0.321 kg.
With ``--rigid-left`` the left leg's muscles (names ending ``_l``) ignore tendon compliance (no
fiber-length state: their fiber length and velocity from the model's geometry).

``python tests/opensim_states.py thelen MODEL.osim IK.mot OUT.sto T0 T1 N`` writes the states of
``N`` equally spaced times from ``T0`` to ``T1`` of the IK motion: coordinates and speeds (a cubic
spline of the IK frames), every muscle's activation ``0.02 + 0.5 (1 + sin(k + 5 t)) / 2`` (muscle
``k``), and the fiber lengths of OpenSim's muscle equilibrium (``equilibrateMuscles``).
"""

from __future__ import annotations

import sys

PROVIDED_MASS_KG = 0.321


def slow_twitch(k: int, n: int) -> float:
    return 0.3 + 0.5 * k / (n - 1)


def activation(k: int, t):
    import numpy as np

    return 0.02 + 0.5 * (1 + np.sin(k + 5 * np.asarray(t))) / 2


def add_probes(source: str, out: str, rigid_left: bool = False) -> None:
    import opensim as osim

    model = osim.Model(source)
    mset = model.getMuscles()
    names = [mset.get(i).getName() for i in range(mset.getSize())]
    for i in range(mset.getSize()):
        if rigid_left and names[i].endswith("_l"):
            mset.get(i).set_ignore_tendon_compliance(True)
    um = osim.Umberger2010MuscleMetabolicsProbe(True, True, True, True)
    um.setName("UM10")
    bh = osim.Bhargava2004MuscleMetabolicsProbe(True, True, True, True, True)
    bh.setName("BH04")
    for k, mu in enumerate(names):
        mass = (PROVIDED_MASS_KG,) if k == 0 else ()
        um.addMuscle(mu, slow_twitch(k, len(names)), *mass)
        bh.addMuscle(mu, slow_twitch(k, len(names)), 40.0, 133.0, 74.0, 111.0, *mass)
    for pr in (um, bh):
        pr.set_basal_rate_on(False)
        pr.set_enforce_minimum_heat_rate_per_muscle(False)
    um.set_use_Bhargava_recruitment_model(False)
    um.set_include_negative_mechanical_work(False)
    um.set_forbid_negative_total_power(False)
    bh.set_use_force_dependent_shortening_prop_constant(True)
    bh.set_include_negative_mechanical_work(True)
    bh.set_forbid_negative_total_power(True)
    identity = osim.PiecewiseLinearFunction()
    identity.addPoint(0.0, 0.0)
    identity.addPoint(10.0, 10.0)
    bh.set_normalized_fiber_length_dependence_on_maintenance_rate(identity)
    model.addProbe(um)
    model.addProbe(bh)
    model.finalizeConnections()
    model.printToXML(out)


def thelen_states(model_path: str, ik_path: str, out: str, t0: float, t1: float, n: int) -> None:
    import numpy as np
    import opensim as osim
    from scipy.interpolate import CubicSpline

    model = osim.Model(model_path)
    state = model.initSystem()
    ik = osim.Storage(ik_path)
    if ik.isInDegrees():
        model.getSimbodyEngine().convertDegreesToRadians(ik)
    time = osim.ArrayDouble()
    ik.getTimeColumn(time)
    tik = np.array([time.get(i) for i in range(time.getSize())])
    times = np.linspace(t0, t1, n)
    cset = model.getCoordinateSet()
    splines = {}
    for i in range(cset.getSize()):
        c = cset.get(i)
        col = osim.ArrayDouble()
        if c.get_locked():
            continue
        ik.getDataColumn(c.getName(), col)
        if col.getSize() == 0:
            continue
        splines[c.getName()] = CubicSpline(tik, [col.get(k) for k in range(col.getSize())])
    mset = model.getMuscles()
    traj = osim.StatesTrajectory()
    for t in times:
        state.setTime(float(t))
        for name, sp in splines.items():
            cset.get(name).setValue(state, float(sp(t)), False)
            cset.get(name).setSpeedValue(state, float(sp(t, 1)))
        model.assemble(state)
        for k in range(mset.getSize()):
            mset.get(k).setActivation(state, float(activation(k, t)))
        model.equilibrateMuscles(state)
        traj.append(osim.State(state))
    osim.STOFileAdapter.write(traj.exportToTable(model), out)


if __name__ == "__main__":
    osim_log = __import__("opensim").Logger
    osim_log.setLevelString("error")
    if sys.argv[1] == "probes":
        add_probes(sys.argv[2], sys.argv[3], "--rigid-left" in sys.argv[4:])
    else:
        thelen_states(sys.argv[2], sys.argv[3], sys.argv[4], float(sys.argv[5]), float(sys.argv[6]), int(sys.argv[7]))
