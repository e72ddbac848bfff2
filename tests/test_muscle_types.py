"""Muscle classes: Thelen2003, Millard2012 (equilibrium, acceleration) and DeGrooteFregly2016
muscles read the same way.

A copy of the gait2392 model (Thelen2003 muscles) is rewritten in a temporary folder with three
muscles turned into the other classes, one of them with its own maximal contraction velocity.
Oracle: the values OpenSim reads from the unmodified model and the numbers written into the
copy; and OpenSim's own path geometry, which must not depend on the class.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from musclemetab.model import read_model

FIELDS = ("max_isometric_force_N", "optimal_fiber_length_m", "tendon_slack_length_m",
          "pennation_angle_at_optimal_rad", "max_contraction_velocity")
CLASSES = {"soleus_r": "Millard2012EquilibriumMuscle", "med_gas_r": "Millard2012AccelerationMuscle",
           "tib_ant_r": "DeGrooteFregly2016Muscle"}


def _as_class(text: str, muscle: str, cls: str, vmax: float | None = None) -> str:
    pat = re.compile(r'<Thelen2003Muscle name="%s">(.*?)</Thelen2003Muscle>' % muscle, re.S)
    m = pat.search(text)
    assert m, muscle
    body = re.sub(r"\s*<optimal_force>[^<]*</optimal_force>", "", m.group(1))  # not a Muscle property
    if vmax is not None:
        body, n = re.subn(r"<max_contraction_velocity>[^<]*</max_contraction_velocity>",
                          f"<max_contraction_velocity>{vmax}</max_contraction_velocity>", body)
        assert n == 1
    return text[:m.start()] + f'<{cls} name="{muscle}">' + body + f"</{cls}>" + text[m.end():]


@pytest.fixture(scope="module")
def models(gait2392, tmp_path_factory):
    text = gait2392.model.read_text()
    for muscle, cls in CLASSES.items():
        text = _as_class(text, muscle, cls, vmax=12.5 if muscle == "tib_ant_r" else None)
    path = tmp_path_factory.mktemp("muscle_types") / "mixed_classes.osim"
    path.write_text(text)
    return read_model(gait2392.model), read_model(path), path


@pytest.mark.opensim
def test_every_class_reads_the_five_parameters(models):
    base, mixed, _ = models
    assert base.muscle_classes["soleus_r"] == "Thelen2003Muscle"
    for muscle, cls in CLASSES.items():
        assert mixed.muscle_classes[muscle] == cls
    names = list(CLASSES) + ["lat_gas_r", "glut_med1_l"]
    a, b = base.muscles.subset(names), mixed.muscles.subset(names)
    for f in FIELDS[:4]:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    # the written value for the DeGrooteFregly muscle, the file's 10 for the others
    assert b.max_contraction_velocity.tolist() == [10.0, 10.0, 12.5, 10.0, 10.0]
    # the values of the file (gait2392 soleus: 3549 N, 0.05 m, 0.25 m, 25 degrees)
    i = names.index("soleus_r")
    assert (b.max_isometric_force_N[i], b.optimal_fiber_length_m[i], b.tendon_slack_length_m[i]) == (3549.0, 0.05, 0.25)
    assert b.pennation_angle_at_optimal_rad[i] == pytest.approx(np.deg2rad(25.0), abs=1e-8)


@pytest.mark.opensim
def test_geometry_does_not_depend_on_the_class(models, gait2392, tmp_path):
    from musclemetab.geometry import compute_geometry

    _, _, path = models
    muscles = list(CLASSES)
    g0 = compute_geometry(gait2392.model, gait2392.ik, muscles=muscles, cache_dir=tmp_path / "a")
    g1 = compute_geometry(path, gait2392.ik, muscles=muscles, cache_dir=tmp_path / "b")
    assert tuple(g1.muscles) == tuple(muscles)
    np.testing.assert_allclose(g1.lmt_m, g0.lmt_m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(g1.moment_arms_m, g0.moment_arms_m, rtol=0, atol=1e-12)
