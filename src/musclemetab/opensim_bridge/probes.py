"""OpenSim's muscle metabolic probes at exact muscle states (OpenSim worker only).

Used to cross-check :mod:`musclemetab.metabolics` against
``Umberger2010MuscleMetabolicsProbe`` and ``Bhargava2004MuscleMetabolicsProbe``.

Set-up: a one-muscle model. The muscle (a clone of a model's muscle, or a new
``Millard2012EquilibriumMuscle``) spans from the ground to a body on a slider joint, so
that the path length is the slider coordinate; its tendon is rigid. With
``h = lMo sin(alpha_opt)`` (constant-thickness pennation), the muscle-tendon length
``lMT = lTs + sqrt(lM^2 - h^2)`` and lengthening speed ``vMT = vM lM / sqrt(lM^2 - h^2)``
give exactly the fiber length ``lM`` and velocity ``vM`` asked for. Activation is set as a
state, excitation as the muscle's control; the model is realised to accelerations and
every probe's outputs are read, with the muscle quantities OpenSim used (fiber length and
velocity, activation, excitation, curve multipliers, forces), so that a re-implementation
can be fed the very same values.

Probe settings are plain dicts (see :func:`evaluate_probes`). Basal heat and the 1 W/kg
minimum heat rate are off unless asked for.
"""

from __future__ import annotations

import math
import time

import numpy as np
import opensim as osim

from ..errors import ModelError, OptionError, UnknownMuscleError

__all__ = ["evaluate_probes", "UMBERGER_SWITCHES", "BHARGAVA_SWITCHES"]

UMBERGER_SWITCHES = (
    "use_Bhargava_recruitment_model",
    "include_negative_mechanical_work",
    "forbid_negative_total_power",
    "enforce_minimum_heat_rate_per_muscle",
    "basal_rate_on",
    "activation_maintenance_rate_on",
    "shortening_rate_on",
    "mechanical_work_rate_on",
)
BHARGAVA_SWITCHES = (
    "use_force_dependent_shortening_prop_constant",
    "include_negative_mechanical_work",
    "forbid_negative_total_power",
    "enforce_minimum_heat_rate_per_muscle",
    "basal_rate_on",
    "activation_rate_on",
    "maintenance_rate_on",
    "shortening_rate_on",
    "mechanical_work_rate_on",
)
_DEFAULT_OFF = {"enforce_minimum_heat_rate_per_muscle": False, "basal_rate_on": False}


def _muscle(model_path: str | None, muscle_name: str | None, parameters: dict | None):
    if model_path is not None:
        full = osim.Model(str(model_path))
        muscles = full.getMuscles()
        idx = muscles.getIndex(muscle_name)
        if idx < 0:
            raise UnknownMuscleError(f"{model_path}: the model has no muscle '{muscle_name}'")
        src = muscles.get(idx)
        mil = osim.Millard2012EquilibriumMuscle.safeDownCast(src)
        if mil is None:
            raise ModelError(
                f"{model_path}: muscle '{muscle_name}' is a {src.getConcreteClassName()}; the probe "
                "cross-check needs a Millard2012EquilibriumMuscle"
            )
        mus = mil.clone()
    else:
        p = parameters or {}
        try:
            mus = osim.Millard2012EquilibriumMuscle(
                "muscle",
                float(p["max_isometric_force_N"]),
                float(p["optimal_fiber_length_m"]),
                float(p.get("tendon_slack_length_m", 0.2)),
                float(p.get("pennation_angle_at_optimal_rad", 0.0)),
            )
        except KeyError as exc:
            raise OptionError(f"probe cross-check: muscle parameter {exc} is missing") from None
        mus.setMaxContractionVelocity(float(p.get("max_contraction_velocity", 10.0)))
    mus.setName("muscle")
    mus.set_path(osim.GeometryPath())
    return mus


def _build(mus, fiber_damping: float, probes: list, slow_twitch_fraction: float, muscle_mass_kg: float,
           rigid_tendon: bool = True):
    model = osim.Model()
    model.setName("one_muscle")
    body = osim.Body("slider_body", 1.0, osim.Vec3(0), osim.Inertia(1))
    model.addBody(body)
    model.addJoint(osim.SliderJoint("slider", model.getGround(), body))
    mus.addNewPathPoint("origin", model.getGround(), osim.Vec3(0, 0, 0))
    mus.addNewPathPoint("insertion", body, osim.Vec3(0, 0, 0))
    mus.set_ignore_tendon_compliance(bool(rigid_tendon))
    mus.set_ignore_activation_dynamics(False)
    mus.set_fiber_damping(float(fiber_damping))
    model.addForce(mus)
    made = []
    for cfg in probes:
        cfg = dict(cfg)
        kind = cfg.pop("probe")
        name = cfg.pop("name")
        if kind == "Umberger2010":
            pr = osim.Umberger2010MuscleMetabolicsProbe()
            switches = UMBERGER_SWITCHES
            pr.addMuscle("muscle", slow_twitch_fraction, muscle_mass_kg)
            if "aerobic_factor" in cfg:
                pr.set_aerobic_factor(float(cfg.pop("aerobic_factor")))
        elif kind == "Bhargava2004":
            pr = osim.Bhargava2004MuscleMetabolicsProbe()
            switches = BHARGAVA_SWITCHES
            pr.addMuscle("muscle", slow_twitch_fraction, 40.0, 133.0, 74.0, 111.0, muscle_mass_kg)
            dep = cfg.pop("maintenance_length_dependence", "published")
            if dep == "identity":
                identity = osim.PiecewiseLinearFunction()
                identity.addPoint(0.0, 0.0)
                identity.addPoint(10.0, 10.0)
                pr.set_normalized_fiber_length_dependence_on_maintenance_rate(identity)
            elif dep != "published":
                raise OptionError(f"maintenance_length_dependence must be 'identity' or 'published', not {dep!r}")
        else:
            raise OptionError(f"unknown probe {kind!r}; use 'Umberger2010' or 'Bhargava2004'")
        pr.setName(name)
        settings = {**_DEFAULT_OFF, **cfg}
        for key, value in settings.items():
            if key not in switches:
                raise OptionError(f"{kind} probe has no switch {key!r}; switches: {', '.join(switches)}")
            getattr(pr, f"set_{key}")(bool(value))
        pr.set_report_total_metabolics_only(False)
        model.addProbe(pr)
        made.append((name, pr))
    state = model.initSystem()
    return model, state, made


def evaluate_probes(
    normalized_fiber_length,
    normalized_fiber_velocity,
    activation,
    excitation,
    *,
    probes: list,
    slow_twitch_fraction: float,
    muscle_mass_kg: float,
    model_path: str | None = None,
    muscle_name: str | None = None,
    muscle_parameters: dict | None = None,
    fiber_damping: float = 0.0,
    read_muscle_quantities: bool = True,
    tendon_strain: float | None = None,
) -> dict:
    """Evaluate OpenSim metabolic probes at the given muscle states.

    Parameters
    ----------
    normalized_fiber_length, normalized_fiber_velocity, activation, excitation
        1-D arrays, one entry per state; velocity as ``vM / (lMo vmax)`` (positive =
        lengthening).
    probes
        List of dicts: ``probe`` (``"Umberger2010"`` or ``"Bhargava2004"``), ``name``, and
        switches (:data:`UMBERGER_SWITCHES`, :data:`BHARGAVA_SWITCHES`; basal heat and
        the minimum heat rate default to off), plus ``aerobic_factor`` (Umberger) and
        ``maintenance_length_dependence`` (Bhargava: ``"identity"`` or ``"published"``).
    slow_twitch_fraction, muscle_mass_kg
        Passed to the probes (the mass as a provided mass).
    model_path, muscle_name
        Clone this muscle of this model; or give ``muscle_parameters`` (``F0``, ``lMo``,
        ``lTs``, ``alpha_opt``, ``vmax`` by their package names) for a new Millard muscle.
    fiber_damping
        Millard fiber damping (0 removes the damping force from the fiber force).
    read_muscle_quantities
        False reads only the probes' outputs (for timing the probes alone).
    tendon_strain
        ``None`` (default): rigid tendon, fiber length and velocity exactly as given.
        A number: compliant tendon stretched by this strain; the fiber length is set as
        given and ``normalized_fiber_velocity`` is then the muscle-tendon lengthening
        speed in ``lMo vmax``; OpenSim solves the fiber velocity from the force
        equilibrium (this is the set-up in which Millard's fiber damping acts). Read
        the achieved velocity from the result.

    Returns
    -------
    dict of 1-D arrays: the achieved muscle quantities (``normalized_fiber_length``,
    ``normalized_fiber_velocity``, ``fiber_velocity_m_per_s``, ``activation``,
    ``excitation``, ``active_force_length_multiplier``, ``force_velocity_multiplier``,
    ``active_fiber_force_N``, ``passive_fiber_force_N``, ``fiber_force_N``), each probe's
    outputs as ``<name>/<label>`` (W), the muscle parameters used, and
    ``seconds_per_state`` (wall time of setting a state, realising and reading the probes).
    """
    lm = np.asarray(normalized_fiber_length, dtype=float).ravel()
    vb = np.asarray(normalized_fiber_velocity, dtype=float).ravel()
    act = np.asarray(activation, dtype=float).ravel()
    exc = np.asarray(excitation, dtype=float).ravel()
    n = lm.size
    if not (vb.size == act.size == exc.size == n):
        raise OptionError("probe cross-check: the four state arrays must have the same length")
    mus = _muscle(model_path, muscle_name, muscle_parameters)
    rigid = tendon_strain is None
    model, state, made = _build(
        mus, fiber_damping, probes, float(slow_twitch_fraction), float(muscle_mass_kg), rigid_tendon=rigid
    )
    mus = osim.Millard2012EquilibriumMuscle.safeDownCast(model.getMuscles().get("muscle"))
    coord = model.getCoordinateSet().get(0)
    lopt = mus.getOptimalFiberLength()
    vmax = mus.getMaxContractionVelocity()
    lts = mus.getTendonSlackLength()
    h = lopt * math.sin(mus.getPennationAngleAtOptimalFiberLength())

    quantities = {
        "normalized_fiber_length": mus.getNormalizedFiberLength,
        "normalized_fiber_velocity": mus.getNormalizedFiberVelocity,
        "fiber_velocity_m_per_s": mus.getFiberVelocity,
        "activation": mus.getActivation,
        "excitation": mus.getExcitation,
        "active_force_length_multiplier": mus.getActiveForceLengthMultiplier,
        "force_velocity_multiplier": mus.getForceVelocityMultiplier,
        "active_fiber_force_N": mus.getActiveFiberForce,
        "passive_fiber_force_N": mus.getPassiveFiberForce,
        "fiber_force_N": mus.getFiberForce,
    }
    if not read_muscle_quantities:
        quantities = {}
    out = {k: np.empty(n) for k in quantities}
    labels = {}
    for name, pr in made:
        lab = pr.getProbeOutputLabels()
        labels[name] = [lab.get(i) for i in range(lab.getSize())]
        for label in labels[name]:
            out[f"{name}/{label}"] = np.empty(n)

    t0 = time.perf_counter()
    for k in range(n):
        l_m = lm[k] * lopt
        v_m = vb[k] * lopt * vmax
        along = math.sqrt(l_m * l_m - h * h)
        if rigid:
            coord.setValue(state, lts + along, False)
            coord.setSpeedValue(state, v_m * l_m / along)
        else:
            coord.setValue(state, lts * (1.0 + tendon_strain) + along, False)
            coord.setSpeedValue(state, v_m)
            mus.setFiberLength(state, l_m)
        mus.setActivation(state, float(act[k]))
        model.realizeVelocity(state)
        controls = model.updControls(state)
        controls.set(0, float(exc[k]))
        model.setControls(state, controls)
        model.realizeAcceleration(state)
        for key, getter in quantities.items():
            out[key][k] = getter(state)
        for name, pr in made:
            vals = pr.getProbeOutputs(state)
            for i, label in enumerate(labels[name]):
                out[f"{name}/{label}"][k] = vals.get(i)
    elapsed = time.perf_counter() - t0
    out["seconds_per_state"] = elapsed / max(n, 1)
    out["labels"] = labels
    out["muscle"] = dict(
        max_isometric_force_N=mus.getMaxIsometricForce(),
        optimal_fiber_length_m=lopt,
        max_contraction_velocity=vmax,
        tendon_slack_length_m=lts,
        pennation_angle_at_optimal_rad=mus.getPennationAngleAtOptimalFiberLength(),
        fiber_damping=mus.get_fiber_damping(),
    )
    out["opensim_version"] = osim.__version__
    return out
