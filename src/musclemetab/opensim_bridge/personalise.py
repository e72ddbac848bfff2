"""Worker side of the personalised model: set and read muscle-tendon parameters in an ``.osim``.

The tendon-stiffness parameter of each muscle type is its tendon strain at the maximal
isometric force: ``FmaxTendonStrain`` (Thelen2003Muscle), the tendon force-length curve's
``strain_at_one_norm_force`` (Millard2012EquilibriumMuscle, Millard2012AccelerationMuscle) and
``tendon_strain_at_one_norm_force`` (DeGrooteFregly2016Muscle). Other types have none.
"""

from __future__ import annotations

import os

import opensim as osim

from ..errors import ModelError
from .model_ops import model_muscles


def _tendon_strain(mu):
    """``(getter, setter)`` of the muscle type's tendon strain at F0, or ``None``."""
    cls = mu.getConcreteClassName()
    if cls == "Thelen2003Muscle":
        m = osim.Thelen2003Muscle.safeDownCast(mu)
        return m.get_FmaxTendonStrain, m.set_FmaxTendonStrain
    if cls in ("Millard2012EquilibriumMuscle", "Millard2012AccelerationMuscle"):
        m = getattr(osim, cls).safeDownCast(mu)
        curve = m.upd_TendonForceLengthCurve()
        return curve.get_strain_at_one_norm_force, curve.set_strain_at_one_norm_force
    if cls == "DeGrooteFregly2016Muscle":
        m = osim.DeGrooteFregly2016Muscle.safeDownCast(mu)
        return m.get_tendon_strain_at_one_norm_force, m.set_tendon_strain_at_one_norm_force
    return None


def _muscles(model, names, path):
    return model_muscles(model, names, path, "estimate muscles of this model")


def write_model_with_parameters(model_path: str, out_path: str, values: dict) -> dict:
    """Write ``out_path``: ``model_path`` with ``values`` (``{muscle: {optimal_fiber_length_m,
    tendon_slack_length_m, tendon_strain_at_one_norm_force}}``, each optional) set. Returns per
    muscle what was set and which values the muscle type could not take."""
    if not os.path.isfile(model_path):
        raise ModelError(f"{model_path}: no such model file; check the path")
    model = osim.Model(model_path)
    muscles = _muscles(model, list(values), model_path)
    report = {}
    for name, v in values.items():
        mu, done = muscles[name], {"class_name": muscles[name].getConcreteClassName(), "set": [], "not_set": []}
        if "optimal_fiber_length_m" in v:
            mu.setOptimalFiberLength(float(v["optimal_fiber_length_m"]))
            done["set"].append("optimal_fiber_length_m")
        if "tendon_slack_length_m" in v:
            mu.setTendonSlackLength(float(v["tendon_slack_length_m"]))
            done["set"].append("tendon_slack_length_m")
        if "tendon_strain_at_one_norm_force" in v:
            acc = _tendon_strain(mu)
            if acc is None:
                done["not_set"].append("tendon_strain_at_one_norm_force")
            else:
                acc[1](float(v["tendon_strain_at_one_norm_force"]))
                done["set"].append("tendon_strain_at_one_norm_force")
        report[name] = done
    model.setName(model.getName() + "_personalised")
    model.finalizeConnections()
    model.printToXML(out_path)
    return report


def read_muscle_values(model_path: str, names: list) -> dict:
    """``{muscle: {class_name, optimal_fiber_length_m, tendon_slack_length_m,
    tendon_strain_at_one_norm_force (None where the type has none)}}`` of a model file."""
    model = osim.Model(model_path)
    model.initSystem()
    out = {}
    for name, mu in _muscles(model, list(names), model_path).items():
        acc = _tendon_strain(mu)
        out[name] = {"class_name": mu.getConcreteClassName(), "optimal_fiber_length_m": mu.getOptimalFiberLength(),
                     "tendon_slack_length_m": mu.getTendonSlackLength(),
                     "tendon_strain_at_one_norm_force": None if acc is None else float(acc[0]())}
    return out
