"""Every muscle's state along an OpenSim states trajectory, from OpenSim's own muscle dynamics
(OpenSim worker only).

:func:`muscles_along_states` loads a states file (a CMC, Moco or forward-dynamics
``states.sto``: columns ``/jointset/<joint>/<coord>/value|speed``,
``/forceset/<muscle>/activation`` and ``fiber_length`` or ``normalized_tendon_force``; pre-4.0
labels such as ``soleus_r.activation`` are converted by OpenSim's
``StatesTrajectory.createFromStatesStorage``; a file in degrees is converted to radians) into
the model, sets every muscle's excitation, realises each state to ``Dynamics`` and reads
OpenSim's fiber length and velocity, activation, excitation, active force-length and
force-velocity multipliers and passive fiber force. Rigid-tendon muscles (no fiber-length
state) take their fiber length and velocity from the model's geometry, as OpenSim computes
them. A compliant-tendon DeGrooteFregly2016Muscle takes, with ``fiber_velocity="auto"`` (the
default), the velocity of the trajectory's own tendon-force derivative when the file holds it (a
MocoTrajectory's ``implicitderiv_normalized_tendon_force``, set in the muscle in implicit mode, as
Moco does), else the time derivative of its fiber length along the states instead of its force
equilibrium's velocity (see :func:`muscles_along_states`).

Excitation: with a controls file, each muscle's control from its column (``/forceset/<muscle>``
or ``<muscle>``), linearly interpolated to the state times; without one, the muscle's
activation (the state of its activation dynamics), so that ``excitation = activation``.

The model's own ``Umberger2010MuscleMetabolicsProbe`` and ``Bhargava2004MuscleMetabolicsProbe``
are read (their switches and, per muscle, slow-twitch ratio, specific tension, density and the
mass they use) and evaluated at every state, per muscle.
"""

from __future__ import annotations

import math

import numpy as np
import opensim as osim

from ..errors import DataMismatchError, InputFileError, ModelError
from .probes import BHARGAVA_SWITCHES, UMBERGER_SWITCHES

__all__ = ["muscles_along_states", "set_locked_coordinates", "MUSCLE_GETTERS"]

#: quantity -> the OpenSim ``Muscle`` getter read at each state (realised to Dynamics)
MUSCLE_GETTERS = {
    "normalized_fiber_length": "getNormalizedFiberLength",
    "normalized_fiber_velocity": "getNormalizedFiberVelocity",
    "fiber_velocity_m_per_s": "getFiberVelocity",
    "activation": "getActivation",
    "excitation": "getExcitation",
    "active_force_length_multiplier": "getActiveForceLengthMultiplier",
    "force_velocity_multiplier": "getForceVelocityMultiplier",
    "passive_fiber_force_N": "getPassiveFiberForce",
    "fiber_length_m": "getFiberLength",
}
_PROBES = {"Umberger2010MuscleMetabolicsProbe": (osim.Umberger2010MuscleMetabolicsProbe, UMBERGER_SWITCHES),
           "Bhargava2004MuscleMetabolicsProbe": (osim.Bhargava2004MuscleMetabolicsProbe, BHARGAVA_SWITCHES)}


def set_locked_coordinates(locked, state, s: int) -> None:
    """Set the locked coordinates ``[(coordinate, column)]`` at state ``s``: OpenSim 4.6's
    trajectory loaders cannot set a locked coordinate (``Coordinate`` refuses a new value while
    locked) and leave it NaN; it is unlocked for the assignment and locked again."""
    for c, col in locked:
        if math.isnan(c.getValue(state)):
            c.setLocked(state, False)
            c.setValue(state, float(col[s]), False)
            c.setLocked(state, True)


def _opensim_message(exc, n: int = 4) -> str:
    """OpenSim's message of ``exc`` without the C++ signature and the source line: its first
    ``n`` lines (e.g. the first missing columns), on one line."""
    text = str(exc).strip()
    if "': " in text and text.startswith("std::exception"):
        text = text.split("': ", 1)[1]
    lines = [x.strip() for x in text.splitlines() if x.strip() and not x.strip().startswith("Thrown at")]
    return "; ".join(lines[:n]) + (" ..." if len(lines) > n else "")


def _model_probes(model):
    """The model's metabolic probes: ``[(name, probe, kind, switches)]``; each probe set to
    report per muscle."""
    out = []
    pset = model.getProbeSet()
    for i in range(pset.getSize()):
        kind = pset.get(i).getConcreteClassName()
        if kind not in _PROBES:
            continue
        cls, switches = _PROBES[kind]
        pr = cls.safeDownCast(model.updProbeSet().get(i))
        pr.set_report_total_metabolics_only(False)
        out.append((pr.getName(), pr, kind, {k: bool(getattr(pr, f"get_{k}")()) for k in switches}))
    return out


def _read_controls(controls_path):
    try:
        table = osim.TimeSeriesTable(str(controls_path))
    except RuntimeError as exc:
        raise InputFileError(f"{controls_path}: OpenSim cannot read the controls file "
                             f"({_opensim_message(exc)})") from None
    return table, [str(x) for x in table.getColumnLabels()]


def _controls(controls_path, table, labels, muscles, times):
    """``(muscles, states)`` excitations from a controls file, interpolated to ``times``."""
    t = np.asarray(table.getIndependentColumn(), dtype=float)
    mat = table.getMatrix().to_numpy()
    if times[0] < t[0] - 1e-6 or times[-1] > t[-1] + 1e-6:
        raise DataMismatchError(f"{controls_path}: the controls span {t[0]:g}-{t[-1]:g} s but the states "
                                f"{times[0]:g}-{times[-1]:g} s; give the controls file of the same motion")
    out = np.empty((len(muscles), times.size))
    for i, mu in enumerate(muscles):
        col = next(j for j, lab in enumerate(labels) if lab in (mu.getAbsolutePathString(), mu.getName()))
        out[i] = np.interp(times, t, mat[:, col]) if t.size > 1 else mat[0, col]
    return out


#: a DeGrooteFregly2016Muscle's discrete variable in implicit tendon dynamics: the derivative of its
#: normalized tendon force, from which OpenSim computes the fiber velocity (Moco's trajectories hold it)
IMPLICIT_DERIVATIVE = "implicitderiv_normalized_tendon_force"


def _implicit_derivative_muscles(mus, sto, fiber_velocity: str, states_path) -> dict:
    """``{muscle: column}``: the compliant-tendon DeGrooteFregly2016 muscles among ``mus`` whose
    tendon-force derivative the states file ``sto`` holds (``<path>/implicitderiv_normalized_tendon_force``),
    switched to implicit tendon dynamics so that OpenSim takes their fiber velocity from it (before
    the model's system is made); none unless ``fiber_velocity`` is ``"auto"`` or ``"trajectory"``.
    With ``"trajectory"`` a compliant-tendon DeGrooteFregly2016 muscle without the column is an error."""
    if fiber_velocity not in ("auto", "trajectory"):
        return {}
    labels = sto.getColumnLabels()
    labels = {labels.get(i) for i in range(labels.getSize())}
    found, missing = {}, []
    for m in mus:
        dgf = osim.DeGrooteFregly2016Muscle.safeDownCast(m)
        if dgf is None or m.get_ignore_tendon_compliance():
            continue
        column = f"{m.getAbsolutePathString()}/{IMPLICIT_DERIVATIVE}"
        if column in labels:
            dgf.set_tendon_compliance_dynamics_mode("implicit")
            found[m.getName()] = column
        else:
            missing.append(m.getName())
    if fiber_velocity == "trajectory" and missing:
        raise DataMismatchError(
            f"{states_path}: no column {IMPLICIT_DERIVATIVE} for {', '.join(missing[:6])}"
            f"{' ...' if len(missing) > 6 else ''} (the tendon-force derivatives a Moco solution file holds); give "
            "the file MocoTrajectory.write() wrote, or take the derivative of the fiber lengths "
            "(--fiber-velocity derivative)")
    return found


def muscles_along_states(model_path: str, states_path: str, controls_path: str | None = None,
                         fiber_velocity: str = "auto") -> dict:
    """OpenSim's muscle quantities of every muscle of ``model_path`` at every state of
    ``states_path`` (see the module's description).

    With a controls file, the muscles it has no column for apply no force and are not evaluated
    (``skipped_muscles``: e.g. the other leg's muscles of a one-leg solution's model); without one,
    the muscles whose every state variable is the model's default at every state (the same other
    leg), unless that is every muscle (``skipped_reason``: ``"no controls"``, ``"default states"``).
    ``fiber_velocity``: ``"auto"``, ``"trajectory"``, ``"derivative"`` or ``"equilibrium"`` for a
    compliant-tendon DeGrooteFregly2016Muscle (``velocity_sources`` per muscle: ``trajectory``,
    ``derivative``, ``equilibrium``, ``geometry``): ``trajectory`` takes the velocity of the tendon-force
    derivative the states file holds (column ``<muscle path>/implicitderiv_normalized_tendon_force``,
    as a MocoTrajectory file has it; the muscle in implicit mode, as Moco solves it; a muscle
    without the column is an error), ``auto`` does where the file has the column and takes the
    derivative elsewhere.

    Returns ``muscles`` (names, model order), ``time_s``, the quantities of
    :data:`MUSCLE_GETTERS` as arrays ``(muscles, states)`` (NaN at a state OpenSim cannot
    realise, listed in ``failed_states`` as ``(time, message)``), ``muscle_classes``,
    ``parameters`` (``max_isometric_force_N``, ``optimal_fiber_length_m``,
    ``max_contraction_velocity`` lists), ``clamped`` (``(muscles, states)`` booleans: a
    DeGrooteFregly2016Muscle's velocity off its force-velocity curve, set to the bound),
    ``excitation_source`` (``"controls"`` or
    ``"activation"``) and ``probes``: per metabolic probe of the model, ``name``, ``kind``,
    ``switches``, ``muscles`` (``{muscle: {slow_twitch_fraction, specific_tension_Pa,
    density_kg_per_m3, muscle_mass_kg, provided_mass}}``) and ``rates`` (``{muscle: array over
    states}``, W, OpenSim's per-muscle output).
    """
    try:
        model = osim.Model(str(model_path))
    except RuntimeError as exc:
        raise ModelError(f"{model_path}: OpenSim cannot load the model ({_opensim_message(exc)})") from None
    probes = _model_probes(model)
    mset = model.getMuscles()
    mus = [mset.get(i) for i in range(mset.getSize()) if mset.get(i).get_appliesForce()]
    if not mus:
        raise ModelError(f"{model_path}: the model has no muscle that applies force")
    skipped = []
    if controls_path is not None:  # the muscles the controls file drives; the others apply no force
        ctable, clabels = _read_controls(controls_path)
        driven = [m for m in mus if m.getAbsolutePathString() in clabels or m.getName() in clabels]
        if not driven:
            raise DataMismatchError(f"{controls_path}: no column is a muscle of {model_path} (columns "
                                    "/forceset/<muscle> or <muscle>); give the controls file of this model's motion")
        skipped = [m.getName() for m in mus if m not in driven]
        for m in mus:
            if m not in driven:
                m.set_appliesForce(False)
        mus = driven
    try:
        sto = osim.Storage(str(states_path))
    except RuntimeError as exc:
        raise InputFileError(f"{states_path}: OpenSim cannot read the states file "
                             f"({_opensim_message(exc)})") from None
    implicit = _implicit_derivative_muscles(mus, sto, fiber_velocity, states_path)
    default = model.initSystem()
    mset = model.getMuscles()
    mus = [mset.get(m.getName()) for m in mus]
    if sto.isInDegrees():
        model.getSimbodyEngine().convertDegreesToRadians(sto)
    try:
        traj = osim.StatesTrajectory.createFromStatesStorage(model, sto, False, True, False)
    except RuntimeError as exc:
        raise DataMismatchError(
            f"{states_path}: OpenSim cannot load these states into {model_path} ({_opensim_message(exc)}); every "
            "state variable of the model must be a column (the states file of a simulation of this model: CMC, "
            "Moco or forward dynamics)") from None
    n = traj.getSize()
    times = np.array([traj.get(s).getTime() for s in range(n)])
    labels = sto.getColumnLabels()
    labels = [labels.get(i) for i in range(labels.getSize())]
    derivatives = {}  # muscle index -> its tendon-force derivative at every state (a Moco trajectory's)
    for i, m in enumerate(mus):
        if m.getName() in implicit:
            col = osim.ArrayDouble()
            sto.getDataColumn(implicit[m.getName()], col)
            derivatives[i] = [col.get(k) for k in range(col.getSize())]
    locked = []
    cset = model.getCoordinateSet()
    for i in range(cset.getSize()):
        c = cset.get(i)
        if c.get_locked():
            col = osim.ArrayDouble()
            label = f"{c.getAbsolutePathString()}/value"
            if label in labels or c.getName() in labels:
                sto.getDataColumn(label if label in labels else c.getName(), col)
            locked.append((c, [col.get(k) for k in range(col.getSize())] if col.getSize() == n
                              else [c.getDefaultValue()] * n))
    sv = model.getStateVariableNames()
    sv = {sv.get(i) for i in range(sv.getSize())}
    at_default = []
    if controls_path is None and n:  # muscles whose every state is the model's default at every state
        # (the other leg of a one-leg solution's model): not evaluated
        for m in mus:
            names = m.getStateVariableNames()
            names = [names.get(i) for i in range(names.getSize())]
            want = [m.getStateVariableValue(default, x) for x in names]
            if names and all(m.getStateVariableValue(traj.get(s), x) == w
                             for s in range(n) for x, w in zip(names, want)):
                at_default.append(m)
        if len(at_default) < len(mus):
            skipped = [m.getName() for m in at_default]
            mus = [m for m in mus if m not in at_default]
        else:
            at_default = []
    if controls_path is not None:
        excitation, source = _controls(controls_path, ctable, clabels, mus, times), "controls"
    else:
        no_act = [m.getName() for m in mus if f"{m.getAbsolutePathString()}/activation" not in sv]
        if no_act:
            raise DataMismatchError(f"{model_path}: muscle{'s' if len(no_act) > 1 else ''} {', '.join(no_act[:6])} "
                                    "have no activation state (their activation is their excitation); give the "
                                    "controls file of the simulation")
        excitation, source = None, "activation"
    acts = model.getActuators()
    index, k = {}, 0
    for i in range(acts.getSize()):
        index[acts.get(i).getAbsolutePathString()] = k
        k += acts.get(i).numControls()
    control_of = [index[m.getAbsolutePathString()] for m in mus]
    out = {key: np.full((len(mus), n), np.nan) for key in MUSCLE_GETTERS}
    # the muscles of each probe, from its per-muscle output labels <probe>_<muscle> (its parameter
    # set is not reachable from Python)
    all_names = {mset.get(i).getName() for i in range(mset.getSize())}
    labels_of = []
    for j, (name, pr, kind, switches) in enumerate(probes):
        lab = pr.getProbeOutputLabels()
        labels_of.append([lab.get(i) for i in range(lab.getSize())])
        names = [x[len(name) + 1:] for x in labels_of[j] if x[len(name) + 1:] in all_names]
        probes[j] = (name, pr, names, kind, switches)
    probe_out = [{mu: np.full(n, np.nan) for mu in names} for _, _, names, _, _ in probes]
    failed = []
    for s in range(n):
        state = traj.get(s)
        set_locked_coordinates(locked, state, s)
        for i, values in derivatives.items():  # the velocity of the trajectory's own tendon dynamics
            mus[i].setDiscreteVariableValue(state, IMPLICIT_DERIVATIVE, float(values[s]))
        model.realizeVelocity(state)
        controls = model.updControls(state)
        for i, m in enumerate(mus):
            e = excitation[i, s] if excitation is not None else m.getStateVariableValue(state, "activation")
            controls.set(control_of[i], float(e))
        model.setControls(state, controls)
        try:
            model.realizeDynamics(state)
        except RuntimeError as exc:  # a muscle whose equilibrium OpenSim cannot solve here
            failed.append((float(times[s]), _opensim_message(exc, 2)))
            continue
        for i, m in enumerate(mus):
            for key, g in MUSCLE_GETTERS.items():
                out[key][i, s] = getattr(m, g)(state)
        for j, (name, pr, names, _, _) in enumerate(probes):
            vals = pr.getProbeOutputs(state)
            by_label = {labels_of[j][i]: vals.get(i) for i in range(vals.size())}
            for mu in names:
                probe_out[j][mu][s] = by_label.get(f"{name}_{mu}", math.nan)
    # a DeGrooteFregly2016Muscle with a compliant tendon takes its fiber velocity from its force
    # equilibrium: v = fV^-1((fT / cos(alpha) - fP) / (a fL)). That holds only for states that meet
    # OpenSim's own curves (a simulation of this model) and is ill-conditioned where a fL is all but
    # zero: states made with other curves (the package's own solutions, exported) land far off the
    # force-velocity curve. "derivative" takes the time derivative of OpenSim's fiber length along the
    # states instead (a not-a-knot cubic spline through the states' fiber lengths), and with it the
    # muscle's force-velocity multiplier and passive force; "equilibrium" keeps OpenSim's velocity. A
    # trajectory that holds its tendon-force derivatives (Moco's) gives OpenSim the velocity it was
    # solved with ("trajectory", and "auto" where the file has them): OpenSim's, kept.
    # Either way a velocity beyond the curve's -vmax..vmax (or not a number) takes the bound (0 when
    # not a number), the curve's multiplier and the passive force there; counted in ``clamped``
    v = out["normalized_fiber_velocity"]
    clamped = np.zeros(v.shape, dtype=bool)
    sources = []
    for i, m in enumerate(mus):
        dgf = osim.DeGrooteFregly2016Muscle.safeDownCast(m)
        if dgf is None:
            sources.append("geometry" if m.get_ignore_tendon_compliance() else "equilibrium")
            continue
        lmo, vmax = m.getOptimalFiberLength(), m.getMaxContractionVelocity()
        ok = ~np.isnan(out["activation"][i])
        if i in derivatives:
            sources.append("trajectory")
        elif fiber_velocity in ("auto", "derivative") and not m.get_ignore_tendon_compliance() and ok.sum() >= 2:
            from scipy.interpolate import CubicSpline

            if not np.all(np.diff(times[ok]) > 0):
                k = int(np.flatnonzero(np.diff(times[ok]) <= 0)[0])
                raise DataMismatchError(
                    f"{states_path}: the state times do not increase (t = {times[ok][k]:g} s, then "
                    f"{times[ok][k + 1]:g} s), so the fiber lengths cannot be differentiated in time; drop the "
                    "repeated rows, or take OpenSim's equilibrium velocity (--fiber-velocity equilibrium)")
            lm = out["fiber_length_m"][i]
            vel = CubicSpline(times[ok], lm[ok], bc_type="not-a-knot")(times[ok], 1)
            out["fiber_velocity_m_per_s"][i, ok] = vel
            out["normalized_fiber_velocity"][i, ok] = vel / (lmo * vmax)
            sources.append("derivative")
        else:
            sources.append("geometry" if m.get_ignore_tendon_compliance() else "equilibrium")
        row = out["normalized_fiber_velocity"][i]
        off = ok & ~(np.abs(row) <= 1.0)
        # the derivative's states take the multiplier and passive force at their velocity; OpenSim's own
        # (equilibrium) are kept where on the curve
        for s in np.flatnonzero(ok if sources[-1] == "derivative" else off):
            vb = 0.0 if math.isnan(row[s]) else float(np.clip(row[s], -1.0, 1.0))
            out["normalized_fiber_velocity"][i, s] = vb
            out["fiber_velocity_m_per_s"][i, s] = vb * lmo * vmax
            out["force_velocity_multiplier"][i, s] = dgf.calcForceVelocityMultiplier(vb)
            out["passive_fiber_force_N"][i, s] = m.getMaxIsometricForce() * (  # the muscle's passive force there
                dgf.calcPassiveForceMultiplier(out["normalized_fiber_length"][i, s]) + dgf.get_fiber_damping() * vb)
        clamped[i] = off
    probe_info = []
    for j, (name, pr, names, kind, switches) in enumerate(probes):
        probe_info.append(dict(name=name, kind=kind, switches=switches, rates=probe_out[j], muscles={
            mu: dict(slow_twitch_fraction=pr.getRatioSlowTwitchFibers(mu),
                     specific_tension_Pa=pr.getSpecificTension(mu),
                     density_kg_per_m3=pr.getDensity(mu), muscle_mass_kg=pr.getMuscleMass(mu),
                     provided_mass=bool(pr.isUsingProvidedMass(mu)))
            for mu in names}))
    out.update(
        muscles=[m.getName() for m in mus],
        skipped_muscles=skipped,
        skipped_reason="no controls" if controls_path is not None else "default states",
        clamped=clamped,
        muscle_classes=[m.getConcreteClassName() for m in mus],
        velocity_sources=sources,
        time_s=times,
        failed_states=failed,
        excitation_source=source,
        probes=probe_info,
        parameters=dict(max_isometric_force_N=[m.getMaxIsometricForce() for m in mus],
                        optimal_fiber_length_m=[m.getOptimalFiberLength() for m in mus],
                        max_contraction_velocity=[m.getMaxContractionVelocity() for m in mus]),
        opensim_version=osim.__version__,
    )
    return out
