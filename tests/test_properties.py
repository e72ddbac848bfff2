"""Muscle property table, volumes, masses and individualised strength."""

from __future__ import annotations

import numpy as np
import pytest

from musclemetab.errors import OptionError, UnknownMuscleError
from musclemetab.model import read_model
from musclemetab.properties import (
    individualised_max_isometric_force_N,
    muscle_masses_kg,
    muscle_volumes_m3,
    property_table,
    slow_twitch_fraction,
    total_muscle_volume_m3,
)

MASS, HEIGHT = 72.6, 1.743


def test_total_volume_worked_by_hand():
    # 47 * 72.6 * 1.743 + 1285 = 5947.4646 + 1285 = 7232.4646 cm^3
    assert total_muscle_volume_m3(MASS, HEIGHT) == pytest.approx(7232.4646e-6, rel=1e-12)


def test_soleus_mass_worked_by_hand():
    # soleus share 6.21 %: 0.0621 * 7232.4646 cm^3 = 449.136 cm^3; * 1059.7 kg/m^3 = 0.47595 kg
    vol = muscle_volumes_m3(["soleus_r"], MASS, HEIGHT)[0]
    assert vol == pytest.approx(0.0621 * 7232.4646e-6, rel=1e-12)
    assert muscle_masses_kg(["soleus_r"], MASS, HEIGHT)[0] == pytest.approx(0.47595, abs=1e-5)


def test_adductor_magnus_quirk_and_sum():
    # each of the four adductor magnus parts takes 7.86/3 %; the 40 shares sum to 99.62 %
    parts = ["addmagDist_r", "addmagIsch_r", "addmagMid_r", "addmagProx_r"]
    np.testing.assert_allclose(muscle_volumes_m3(parts, MASS, HEIGHT), 0.0262 * 7232.4646e-6, rtol=1e-12)
    assert property_table()["volume_percent"].sum() == pytest.approx(99.62, abs=1e-9)
    # summed right-leg muscle mass of the example subject: 0.9962 * 7232.4646e-6 * 1059.7
    total = muscle_masses_kg([f"{m}_r" for m in property_table().index], MASS, HEIGHT).sum()
    assert total == pytest.approx(0.9962 * 7232.4646e-6 * 1059.7, rel=1e-12)
    assert total == pytest.approx(7.635, abs=1e-3)


def test_masses_agree_with_published_table(reference_table):
    names = list(reference_table.index)
    np.testing.assert_allclose(
        muscle_masses_kg(names, MASS, HEIGHT), reference_table["mass_kg_sub1"].to_numpy(), rtol=1e-5
    )


def test_model_forces_follow_the_06_MPa_rule(example):
    info = read_model(example.model)
    right = info.muscles.subset([n for n in info.muscles.names if n.endswith("_r")])
    assert len(right) == 40
    f0 = individualised_max_isometric_force_N(right.names, right.optimal_fiber_length_m, MASS, HEIGHT)
    np.testing.assert_allclose(f0, right.max_isometric_force_N, rtol=1e-6)
    # soleus by hand: 0.6e6 Pa * 449.136e-6 m^3 / lMo
    sol = right.subset(["soleus_r"])
    assert sol.max_isometric_force_N[0] == pytest.approx(0.6e6 * 0.0621 * 7232.4646e-6 / sol.optimal_fiber_length_m[0], rel=1e-6)


def test_names_matched_by_name_and_side_not_position():
    a = muscle_masses_kg(["soleus_r", "tibant_l", "glmax1_r"], MASS, HEIGHT)
    b = muscle_masses_kg(["glmax1_l", "soleus_l", "tibant_r"], MASS, HEIGHT)
    np.testing.assert_allclose(a, b[[1, 2, 0]])
    np.testing.assert_allclose(slow_twitch_fraction(["soleus_r", "tibant_r", "recfem_l"]), [0.803, 0.70, 0.3865])


def test_unknown_muscles_are_named():
    with pytest.raises(UnknownMuscleError, match="bogus_r"):
        muscle_masses_kg(["soleus_r", "bogus_r"], MASS, HEIGHT)
    assert slow_twitch_fraction(["bogus_r"], default=0.5)[0] == 0.5
    with pytest.raises(UnknownMuscleError, match="bogus_r"):
        slow_twitch_fraction(["bogus_r"])


def test_implausible_subject_rejected():
    with pytest.raises(OptionError, match="kilograms"):
        total_muscle_volume_m3(72600, HEIGHT)
    with pytest.raises(OptionError, match="metres"):
        total_muscle_volume_m3(MASS, 174.3)
    with pytest.raises(OptionError, match="optimal fiber lengths"):
        individualised_max_isometric_force_N(["soleus_r"], [0.0], MASS, HEIGHT)
