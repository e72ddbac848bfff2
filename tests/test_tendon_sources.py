"""EFFORT-TEN tendon stiffness sources for any model and side, and EMG-TEN groups from the table.

Oracles: the tendon curve's slope computed independently from ``tendon_stiffness_N_per_m`` at
the length where the curve carries the reference force (the conversion must give back the
literature N/mm), the example subject's published estimates, and the gait2392 model's names.
"""

from __future__ import annotations

import numpy as np
import pytest

from musclemetab.errors import OptionError
from musclemetab.muscle import tendon_length_from_force, tendon_stiffness_for_slope, tendon_stiffness_N_per_m
from musclemetab.redundancy import workflows as W

KT_TS, KT_VA = 10.617977, 4.695786


@pytest.fixture(scope="module")
def g2392(gait2392):
    from musclemetab.model import read_model

    return read_model(gait2392.model).muscles


def _slope_N_per_m(mp, names, kt, force_fraction):
    lt = tendon_length_from_force(force_fraction, kt)
    return sum(float(tendon_stiffness_N_per_m(lt, mp.max_isometric_force_N[mp.index(n)],
                                              mp.tendon_slack_length_m[mp.index(n)], kt)) for n in names)


def test_conversion_gives_back_the_stiffness():
    f0, lts = np.array([3549.0, 1558.0, 683.0]), np.array([0.25, 0.39, 0.38])
    for k_mm, frac in ((155.0, 0.25), (3000.0, 0.5), (423.0, 1.0)):
        kt = tendon_stiffness_for_slope(k_mm * 1e3, f0, lts, frac)
        lt = tendon_length_from_force(frac, kt)
        # at that length each tendon carries frac * F0 ...
        assert float(np.exp(kt * (lt - 0.995)) / 5 - 0.25 + (np.exp(0.175) - np.exp(0.005 * kt)) / 5) == \
            pytest.approx(frac, abs=1e-12)
        # ... and the summed slope is the requested stiffness
        assert sum(tendon_stiffness_N_per_m(lt, f, s, kt) for f, s in zip(f0, lts)) == pytest.approx(k_mm * 1e3,
                                                                                                   rel=1e-9)
    # the generic kT = 35 is recovered from its own slope
    k35 = sum(tendon_stiffness_N_per_m(tendon_length_from_force(1.0, 35.0), f, s, 35.0) for f, s in zip(f0, lts))
    assert tendon_stiffness_for_slope(k35, f0, lts, 1.0) == pytest.approx(35.0, rel=1e-9)


def test_literature_default_on_gait2392_left_leg(g2392):
    names = ["soleus_l", "med_gas_l", "lat_gas_l", "vas_int_l", "vas_lat_l", "vas_med_l", "rect_fem_l", "tib_ant_l"]
    params, rec = W.workflow_parameters("effort-ten", g2392, names, passive=W.generic_passive_parameters(names))
    kt = dict(zip(names, params.tendon_stiffness))
    assert kt["soleus_l"] == kt["med_gas_l"] == kt["lat_gas_l"]
    assert kt["vas_int_l"] == kt["vas_lat_l"] == kt["vas_med_l"]
    assert kt["rect_fem_l"] == kt["tib_ant_l"] == 35.0
    assert _slope_N_per_m(g2392, names[:3], kt["soleus_l"], 0.25) == pytest.approx(155e3, rel=1e-9)
    assert _slope_N_per_m(g2392, names[3:6], kt["vas_lat_l"], 0.5) == pytest.approx(3000e3, rel=1e-9)
    assert rec["tendon_stiffness_source"] == ["literature"]
    assert rec["tendon_stiffness_literature"]["achilles_l"]["stiffness_N_per_mm"] == 155.0
    assert set(rec["tendon_stiffness_literature"]["patellar_l"]["muscles"]) == {"vas_int_l", "vas_lat_l", "vas_med_l"}


def test_example_estimates_only_when_asked(g2392):
    names = ["soleus_r", "med_gas_r", "vas_lat_r", "tib_ant_r"]
    passive = W.generic_passive_parameters(names)
    default, _ = W.workflow_parameters("effort-ten", g2392, names, passive=passive)
    assert KT_TS not in default.tendon_stiffness and KT_VA not in default.tendon_stiffness
    asked, rec = W.workflow_parameters("effort-ten", g2392, names, passive=passive,
                                       tendon_stiffness=W.parse_tendon_stiffness("example"))
    assert asked.tendon_stiffness.tolist() == [KT_TS, KT_TS, KT_VA, 35.0]
    assert rec["tendon_stiffness_source"] == ["example"]
    with pytest.raises(OptionError, match="'exmaple' is neither"):
        W.workflow_parameters("effort-ten", g2392, names, passive=passive, tendon_stiffness="exmaple")
    with pytest.raises(OptionError, match="generic tendons"):
        W.workflow_parameters("effort-gen", g2392, names, tendon_stiffness="example")


def test_study_file_asks_for_the_example_by_name(tmp_path, example):
    from musclemetab.study.spec import load_study

    for value, expected in (('"example"', "example"), ('"Example"', "example")):
        path = tmp_path / "study.toml"
        path.write_text(f'''name = "s"
output = "out"
workflows = ["effort-ten"]
[[subjects]]
name = "sub1"
model = "{example.model}"
body_mass_kg = 72.6
height_m = 1.743
tendon_stiffness = {value}
[[subjects.trials]]
name = "normal"
ik = "{example.ik['normal']}"
id = "{example.id['normal']}"
''')
        assert load_study(path).subjects[0].tendon_stiffness == expected


def test_emg_ten_groups_and_mapping_for_gait2392_left_leg(g2392):
    from musclemetab.redundancy.emg_inputs import mapping_for_muscles
    from musclemetab.redundancy.emg_ten import EmgTenSettings, settings_for_muscles

    names = [n for n in g2392.names if n.endswith("_l")]
    s = settings_for_muscles(None, names)
    assert {frozenset(g) for g in s.tendon_groups} == {frozenset({"soleus_l", "med_gas_l", "lat_gas_l"}),
                                                      frozenset({"vas_int_l", "vas_lat_l", "vas_med_l"})}
    assert {frozenset(g) for g in s.emg_groups} == {frozenset({"med_gas_l", "lat_gas_l"}),
                                                   frozenset({"vas_int_l", "vas_lat_l", "vas_med_l"})}
    # the study's model keeps the study's groups, in the study's order
    raj = ["vaslat_r", "vasmed_r", "vasint_r", "gaslat_r", "gasmed_r", "soleus_r", "tibant_r"]
    assert settings_for_muscles(None, raj) == EmgTenSettings()
    m = mapping_for_muscles("authors", {"vasint_r": ["ES"]}, names)
    assert m["vas_int_l"] == ["ES"] and m["soleus_l"] == ["SO"] and m["bifemlh_l"] == ["BF"]
    assert mapping_for_muscles("default", {"vasint_r": ["VI_a"]}, names)["vas_int_l"] == ["VI_a"]
