"""The personalised model: estimated optimal fiber length, tendon slack length and tendon
stiffness written into a copy of the .osim, read back through OpenSim (the worker).

The tendon stiffness becomes each muscle type's tendon strain at the maximal isometric force;
the expected strain is worked out here from the tendon curve of ``muscle_model.md`` §7:
``exp(kT (l - 0.995))/5 - 0.25 + shift(kT) = 1``  =>  ``l - 1 = ln(5 (1.25 - shift))/kT - 0.005``.
"""

from __future__ import annotations

import math

import pytest
from mrs_reference import shift_ref


def _strain(kt):
    return math.log(5.0 * (1.25 - shift_ref(kt))) / kt - 0.005


def _nominal(model, muscles):
    from musclemetab.model import read_muscle_parameters
    from musclemetab.redundancy.workflows import workflow_parameters

    params, _ = workflow_parameters("effort-gen", read_muscle_parameters(model), muscles)
    return params


@pytest.mark.opensim
@pytest.mark.parametrize("dataset, muscles, kind", [
    ("example", ("tibant_r", "bflh_r", "soleus_r"), "Millard2012EquilibriumMuscle"),
    ("gait2392", ("tib_ant_r", "bifemlh_r", "soleus_r"), "Thelen2003Muscle"),
])
def test_personalised_model_holds_the_estimates(request, tmp_path, dataset, muscles, kind):
    from musclemetab.opensim_bridge.client import call
    from musclemetab.redundancy.estimate import write_personalised_model

    data = request.getfixturevalue(dataset)
    model = data.model
    a, b, c = muscles
    nominal = _nominal(model, muscles)
    i = {m: nominal.names.index(m) for m in muscles}
    est = nominal.replace(optimal_fiber_length_m={a: 1.1 * nominal.optimal_fiber_length_m[i[a]]},
                          tendon_slack_length_m={b: 0.95 * nominal.tendon_slack_length_m[i[b]]},
                          tendon_stiffness={c: 17.5})
    path, report = write_personalised_model(
        model, est, {"optimal_fiber_length": [a], "tendon_slack_length": [b], "tendon_stiffness": [c]}, tmp_path)
    assert path == tmp_path / f"{model.stem}_personalised.osim" and path.is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == [".musclemetab-files", path.name]  # no temporary left
    assert report[c]["set"] == ["tendon_strain_at_one_norm_force"] and report[c]["class_name"] == kind
    before = call("personalise:read_muscle_values", str(model), list(muscles))
    after = call("personalise:read_muscle_values", str(path), list(muscles))
    assert after[a]["optimal_fiber_length_m"] == pytest.approx(1.1 * before[a]["optimal_fiber_length_m"], rel=1e-12)
    assert after[a]["tendon_slack_length_m"] == before[a]["tendon_slack_length_m"]
    assert after[b]["tendon_slack_length_m"] == pytest.approx(0.95 * before[b]["tendon_slack_length_m"], rel=1e-12)
    assert after[b]["optimal_fiber_length_m"] == before[b]["optimal_fiber_length_m"]
    assert after[c]["tendon_strain_at_one_norm_force"] == pytest.approx(_strain(17.5), rel=1e-12)
    assert after[a]["tendon_strain_at_one_norm_force"] == before[a]["tendon_strain_at_one_norm_force"]
    # kT = 35 corresponds to a strain of about 4.9 %, OpenSim's usual default
    assert _strain(35.0) == pytest.approx(0.049, abs=0.002)


@pytest.mark.opensim
def test_personalised_model_unknown_muscle(example, tmp_path):
    from musclemetab.errors import UnknownMuscleError
    from musclemetab.redundancy.estimate import write_personalised_model

    nominal = _nominal(example.model, ("soleus_r",)).replace()
    renamed = type(nominal)(names=("soleus_x",), **{k: getattr(nominal, k) for k in (
        "max_isometric_force_N", "optimal_fiber_length_m", "tendon_slack_length_m", "pennation_angle_at_optimal_rad",
        "max_contraction_velocity", "tendon_stiffness", "passive_kpe", "passive_s0", "passive_sm")})
    with pytest.raises(UnknownMuscleError, match="soleus_x"):
        write_personalised_model(example.model, renamed, {"tendon_stiffness": ["soleus_x"]}, tmp_path)
    assert list(tmp_path.iterdir()) == []
