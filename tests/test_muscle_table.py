"""The anatomical muscle table, its aliases per model family, and the placement rules.

Oracles: the study's published per-muscle table (reference_table), hand computations from the
package tables' numbers (Handsfield volume shares, Uchida slow-twitch fractions) and the
maximal isometric forces OpenSim reads from the gait2392 model.
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

from musclemetab.errors import InputFileError, MuscleTableWarning, OptionError, UnknownMuscleError
from musclemetab.properties import (
    MUSCLE_DENSITY_KG_PER_M3,
    alias_table,
    anatomical_table,
    coupling_groups,
    emg_scale_groups,
    model_family,
    muscle_masses_kg,
    read_muscle_properties,
    report_muscles,
    resolve_muscles,
    slow_twitch_fraction,
    split_side,
    tendon_groups,
    total_muscle_volume_m3,
)

MASS, HEIGHT = 72.6, 1.8  # gait2392 subject: 72.6 kg; its height is not recorded, 1.8 m assumed here
RHO = MUSCLE_DENSITY_KG_PER_M3


def _rajagopal(side="r"):
    a = alias_table()
    return [f"{n}_{side}" for n, f in zip(a["model_name"], a["families"]) if "rajagopal" in f]


@pytest.fixture(scope="module")
def g2392(gait2392):
    from musclemetab.model import read_model

    return read_model(gait2392.model)


def test_tables_are_consistent():
    anat = anatomical_table()
    assert len(anat) == 30 and anat["volume_percent"].sum() == pytest.approx(97.0, abs=1e-9)
    assert anat["slow_twitch_fraction"].between(0, 1).all()
    ids = {a for t in alias_table()["anatomical"] for a in t}
    assert ids <= set(anat.index)
    # every anatomical muscle has a name in the study's model family
    raj = resolve_muscles(_rajagopal())
    assert {a for r in raj for a in r.anatomical} == set(anat.index)


def test_study_model_keeps_the_published_shares(reference_table):
    names = list(reference_table.index)
    recs = {r.name: r for r in resolve_muscles(names)}
    # the study's coded shares: equal splits, and 7.86/3 % for each of the four adductor magnus parts
    for name, percent in (("glmax2_r", 11.93 / 3), ("glmin3_r", 1.47 / 3), ("addmagIsch_r", 7.86 / 3),
                          ("perlong_r", 1.83 / 2), ("soleus_r", 6.21)):
        assert recs[name].volume_percent == pytest.approx(percent, rel=1e-14), name
    # no model forces needed for the study's model (explicit shares), and no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        masses = muscle_masses_kg(names, 72.6, 1.743)
    np.testing.assert_allclose(masses, reference_table["mass_kg_sub1"].to_numpy(), rtol=1e-5)


def test_families_are_recognised(g2392):
    assert model_family(_rajagopal("l")) == "rajagopal"
    assert model_family(g2392.muscles.names) == "gait2392"
    lumped = ["hamstrings_r", "bifemsh_r", "glut_max_r", "iliopsoas_r", "rect_fem_r", "vasti_r", "gastroc_r",
              "soleus_r", "tib_ant_r"]
    assert model_family(lumped) == "gait10dof18musc"


def test_gait2392_split_muscles_share_by_force(g2392):
    # glut_med1..3: gluteus medius is 4.54 % of V_total, split by the model's F0 (819, 573, 653 N)
    names = ["glut_med1_r", "glut_med2_r", "glut_med3_r", "add_mag1_l", "add_mag2_l", "add_mag3_l", "soleus_r"]
    mp = g2392.muscles.subset(names)
    f0 = dict(zip(names, mp.max_isometric_force_N))
    assert [f0[n] for n in names[:3]] == [819.0, 573.0, 653.0]
    masses = muscle_masses_kg(names, MASS, HEIGHT, mp.max_isometric_force_N, mp.optimal_fiber_length_m)
    v_total_cm3 = 47 * MASS * HEIGHT + 1285  # 7427.08 cm^3
    assert total_muscle_volume_m3(MASS, HEIGHT) == pytest.approx(v_total_cm3 * 1e-6, rel=1e-12)
    expected = {
        "glut_med1_r": 0.0454 * 819 / (819 + 573 + 653),
        "glut_med3_r": 0.0454 * 653 / (819 + 573 + 653),
        "add_mag2_l": 0.0786 * f0["add_mag2_l"] / (f0["add_mag1_l"] + f0["add_mag2_l"] + f0["add_mag3_l"]),
        "soleus_r": 0.0621,
    }
    for n, share in expected.items():
        assert masses[names.index(n)] == pytest.approx(RHO * share * v_total_cm3 * 1e-6, rel=1e-12), n
    # the parts of one side add up to the anatomical muscle
    assert sum(masses[:3]) == pytest.approx(RHO * 0.0454 * v_total_cm3 * 1e-6, rel=1e-12)
    assert sum(masses[3:6]) == pytest.approx(RHO * 0.0786 * v_total_cm3 * 1e-6, rel=1e-12)


def test_gait2392_unplaced_muscles_fall_back_with_one_warning(g2392):
    right = [n for n in g2392.muscles.names if n.endswith("_r")]
    mp = g2392.muscles.subset(right)
    with pytest.warns(MuscleTableWarning) as rec:
        masses = muscle_masses_kg(right, MASS, HEIGHT, mp.max_isometric_force_N, mp.optimal_fiber_length_m)
    assert len(rec) == 1
    msg = str(rec[0].message)
    named = set(re.findall(r"\b\w+_r\b", msg))
    assert named == {"pect_r", "quad_fem_r", "gem_r", "per_tert_r", "ercspn_r", "intobl_r", "extobl_r"}
    assert "--muscle-properties" in msg
    i = right.index("pect_r")
    # OpenSim's probe rule: F0 / sigma * rho * lMo
    assert masses[i] == pytest.approx(mp.max_isometric_force_N[i] / 0.6e6 * RHO * mp.optimal_fiber_length_m[i],
                                      rel=1e-12)
    fst = slow_twitch_fraction(right, default=0.5)
    assert fst[i] == 0.5 and fst[right.index("soleus_r")] == 0.803
    with pytest.raises(UnknownMuscleError, match="pect_r.*quad_fem_r|quad_fem_r.*pect_r"):
        muscle_masses_kg(right, MASS, HEIGHT, mp.max_isometric_force_N, mp.optimal_fiber_length_m, strict=True)
    # without the model's parameters the fallback cannot be computed: a clear error
    with pytest.raises(UnknownMuscleError, match="pect_r"):
        muscle_masses_kg(["pect_r"], MASS, HEIGHT)


def test_lumped_muscles_take_the_sum_of_their_parts():
    v = total_muscle_volume_m3(MASS, HEIGHT)
    ham, vasti, gastroc = muscle_masses_kg(["hamstrings_l", "vasti_l", "gastroc_l"], MASS, HEIGHT)
    assert ham == pytest.approx(RHO * (0.0346 + 0.0260 + 0.0292) * v, rel=1e-12)
    assert vasti == pytest.approx(RHO * (0.0384 + 0.1166 + 0.0606) * v, rel=1e-12)
    assert gastroc == pytest.approx(RHO * (0.0362 + 0.0211) * v, rel=1e-12)
    # slow-twitch fraction weighted by the parts' volumes
    fst = slow_twitch_fraction(["hamstrings_l", "gastroc_l"])
    assert fst[0] == pytest.approx((3.46 * 0.4925 + 2.60 * 0.425 + 2.92 * 0.5425) / 8.98, rel=1e-12)
    assert fst[1] == pytest.approx((3.62 * 0.566 + 2.11 * 0.507) / 5.73, rel=1e-12)
    (r,) = resolve_muscles(["vasti_l"])
    assert r.tendon == "patellar" and r.emg_scale_group == "vasti" and r.coupling_group == "P6"


def test_sides_and_case():
    assert split_side("soleus_R") == ("soleus", "r") and split_side("Soleus_l") == ("Soleus", "l")
    assert split_side("soleus") == ("soleus", "")
    a = muscle_masses_kg(["soleus_r", "TIB_ANT_L", "vas_lat_R"], MASS, HEIGHT)
    b = muscle_masses_kg(["soleus_l", "tib_ant_r", "vas_lat_l"], MASS, HEIGHT)
    np.testing.assert_allclose(a, b, rtol=1e-15)
    # a split muscle needs the model's forces; the message says which
    with pytest.raises(OptionError, match="glut_med1_r.*max_isometric_force_N"):
        muscle_masses_kg(["glut_med1_r", "glut_med2_r"], MASS, HEIGHT)


def test_groups_from_the_table_for_any_model_and_side(g2392):
    names = list(g2392.muscles.names)
    cg = coupling_groups(names)
    assert cg["P8_l"] == ("glut_med1_l", "glut_med2_l", "glut_med3_l")
    assert set(cg["P5_r"]) == {"semimem_r", "semiten_r", "bifemlh_r"}
    assert set(cg["P1_r"]) == {"per_brev_r", "per_long_r"}
    tg = tendon_groups(names)
    assert set(tg) == {"achilles_r", "achilles_l", "patellar_r", "patellar_l"}
    assert set(tg["achilles_l"]) == {"soleus_l", "med_gas_l", "lat_gas_l"}
    assert set(emg_scale_groups(names)["gastrocnemii_r"]) == {"med_gas_r", "lat_gas_r"}
    # the study's model: the same groups as the study's right-leg names
    raj = _rajagopal()
    assert set(tendon_groups(raj)["patellar_r"]) == {"vasint_r", "vaslat_r", "vasmed_r"}
    assert report_muscles([n for n in names if n.endswith("_l")])[:4] == ["soleus_l", "med_gas_l", "lat_gas_l",
                                                                           "tib_ant_l"]


def test_calibration_groups_follow_the_table(g2392):
    from musclemetab.calibration.problem import parameter_groups
    from musclemetab.calibration.trials import default_tendon_stiffness

    names = ["glut_med1_l", "soleus_l", "glut_med2_l", "med_gas_l", "tib_ant_l", "pect_l"]
    assert parameter_groups(names) == [("glut_med1_l", "glut_med2_l"), ("soleus_l",), ("med_gas_l",),
                                       ("tib_ant_l",), ("pect_l",)]
    assert default_tendon_stiffness(names).tolist() == [35, 20, 35, 20, 35, 35]


def test_override_file(tmp_path, g2392):
    p = tmp_path / "muscles.csv"
    p.write_text("muscle,anatomical_muscles,mass_kg,slow_twitch_fraction\n"
                 "pect,adductor_longus,,\n"
                 "quad_fem_r,,0.08,0.6\n"
                 "gem_r,,0.02,0.5\n"
                 "per_tert_r,,0.01,0.5\n")
    names = ["pect_r", "pect_l", "quad_fem_r", "gem_r", "per_tert_r", "soleus_r"]
    mp = g2392.muscles.subset(names)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # every muscle placed or given: no warning, strict passes
        masses = muscle_masses_kg(names, MASS, HEIGHT, mp.max_isometric_force_N, mp.optimal_fiber_length_m,
                                  overrides=p, strict=True)
    v = total_muscle_volume_m3(MASS, HEIGHT)
    # a side-free name covers both sides; pect alone stands for adductor longus on each side
    assert masses[0] == masses[1] == pytest.approx(RHO * 0.0226 * v, rel=1e-12)
    assert masses[2] == 0.08
    assert slow_twitch_fraction(names, overrides=p)[2] == 0.6
    for text, match in (("muscle,colour\nx,red\n", "unknown column colour"),
                        ("name,mass_kg\nx,1\n", "no 'muscle' column"),
                        ("muscle,mass_kg\npect_r,-1\n", "muscle 'pect_r', column 'mass_kg'"),
                        ("muscle,slow_twitch_fraction\npect_r,1.5\n", r"fraction in \[0, 1\]"),
                        ("muscle,anatomical_muscles\npect_r,pectineus\n", "unknown anatomical muscle pectineus"),
                        ("muscle,mass_kg\npect_r,1\npect_r,2\n", "appears twice")):
        p.write_text(text)
        with pytest.raises(InputFileError, match=match):
            read_muscle_properties(p)
    with pytest.raises(InputFileError, match="no such muscle-properties file"):
        read_muscle_properties(tmp_path / "absent.csv")


# ------------------------------------------------------------------ metabolics on a gait2392 solution
@pytest.fixture(scope="module")
def g2392_solution(gait2392, g2392, tmp_path_factory):
    """EFFORT-GEN on the gait2392 right leg, 0.7-1.3 s (inside the stored ID file's 0.4-1.6 s), all
    43 muscles spanning the five DOFs (``tfl_r``'s fiber-length bound widened from the geometry)."""
    from musclemetab.geometry import compute_geometry
    from musclemetab.io import read_storage, write_storage
    from musclemetab.redundancy.inputs import read_inverse_dynamics, read_kinematics
    from musclemetab.redundancy.solve import solve_trial

    folder = tmp_path_factory.mktemp("g2392_solution")
    ik = read_storage(gait2392.ik)
    write_storage(folder / "ik.mot", ik.loc[(ik.index > 0.7 - 1e-6) & (ik.index < 1.3 + 1e-6)], in_degrees=True)
    dofs = ["ankle_angle_r", "knee_angle_r", "hip_flexion_r", "hip_adduction_r", "hip_rotation_r"]
    geometry = compute_geometry(gait2392.model, folder / "ik.mot", dofs=dofs, cache_dir=folder / "cache")
    muscles = list(geometry.muscles)
    ik_time, _ = read_kinematics(folder / "ik.mot", dofs)
    id_time, id_moments = read_inverse_dynamics(gait2392.id, dofs)
    sol = solve_trial(geometry, g2392.muscles, id_time, id_moments, "effort-gen", ik_time_s=ik_time)
    sol.write(folder / "sol")

    def solve(workflow, **kw):
        return solve_trial(geometry, g2392.muscles, id_time, id_moments, workflow, ik_time_s=ik_time, **kw)

    return sol, folder / "sol", muscles, solve


@pytest.mark.opensim
@pytest.mark.slow
def test_metabolics_cli_on_a_gait2392_solution(g2392_solution, g2392, tmp_path, capsys):
    import pandas as pd

    from musclemetab.commands import main

    sol, folder, muscles, _ = g2392_solution
    assert sol.summary["success"] and sol.summary["max_moment_residual_Nm"] <= 1e-4
    assert len(muscles) == 43 and "tfl_r" in muscles
    base = ["metabolics", "--solution", str(folder), "--mass", str(MASS), "--height", str(HEIGHT)]
    # --strict: one line naming the unplaced muscles, exit 1, nothing written
    assert main(base + ["--strict", "--out", str(tmp_path / "strict")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("musclemetab: error:")
    assert all(m in err[0] for m in ("pect_r", "quad_fem_r", "gem_r", "per_tert_r"))
    assert not (tmp_path / "strict").exists()
    # default: one warning line, every metabolic model runs
    assert main(base + ["--out", str(tmp_path / "out")]) == 0
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    # one line for the muscles the table does not place, then the rates' plausibility flags; the
    # solution's, which solve printed, are counted in one note
    flags = sol.summary["plausibility"]
    notes = [ln for ln in err if ln.startswith("musclemetab: note: ")]
    assert notes == ([f"musclemetab: note: the solve's {len(flags)} plausibility flag{'s' if len(flags) > 1 else ''} "
                      f"({folder}: summary.json) not repeated; --show-solve-flags repeats them"] if flags else [])
    assert all(ln.startswith("musclemetab: warning:") for ln in err if ln not in notes)
    assert "pect_r" in err[0] and "not in the anatomical muscle table" in err[0]
    wb = pd.read_csv(tmp_path / "out" / "whole_body.csv")
    assert sorted(wb["model"]) == sorted(["UM03", "BH04", "HO06", "LW07", "UM10", "UC16"])
    assert np.isfinite(wb.select_dtypes("number").to_numpy()).all() and (wb["whole_body_no_basal_W_per_kg"] > 0).all()
    # the per-muscle basal heat is 1.2 W per kg of the muscle's mass: the masses by hand
    per_muscle = pd.read_csv(tmp_path / "out" / "per_muscle.csv")
    basal = per_muscle[per_muscle.model == "UM10"].set_index("muscle")["basal_heat_mean_W"]
    v = (47 * MASS * HEIGHT + 1285) * 1e-6
    mp = g2392.muscles.subset(muscles)
    f0 = dict(zip(muscles, mp.max_isometric_force_N))
    lmo = dict(zip(muscles, mp.optimal_fiber_length_m))
    glut_med = f0["glut_med1_r"] + f0["glut_med2_r"] + f0["glut_med3_r"]
    expected = {"glut_med2_r": RHO * 0.0454 * f0["glut_med2_r"] / glut_med * v,
                "vas_lat_r": RHO * 0.1166 * v,
                "per_long_r": RHO * 0.0183 * f0["per_long_r"] / (f0["per_long_r"] + f0["per_brev_r"]) * v,
                "pect_r": f0["pect_r"] / 0.6e6 * RHO * lmo["pect_r"]}
    for m, mass in expected.items():
        assert basal[m] == pytest.approx(1.2 * mass, rel=1e-6), m
    # placing them with an override file: no warning of the muscle table (the solution's own
    # plausibility flags remain: gait2392's over-stretched muscles, docs/quality.md)
    p = tmp_path / "muscles.csv"
    p.write_text("muscle,anatomical_muscles,mass_kg,slow_twitch_fraction\npect,adductor_longus,,\n"
                 "quad_fem,,0.1,0.5\ngem,,0.03,0.5\nper_tert,,0.02,0.7\n")
    assert main(base + ["--muscle-properties", str(p), "--out", str(tmp_path / "placed")]) == 0
    err = capsys.readouterr().err
    assert "not in the anatomical muscle table" not in err


def test_study_file_muscle_properties_key(tmp_path, example):
    from musclemetab.study.spec import load_study

    def study(csv_text):
        (tmp_path / "muscles.csv").write_text(csv_text)
        path = tmp_path / "study.toml"
        path.write_text(f'''name = "s"
output = "out"
workflows = ["effort-gen"]
[[subjects]]
name = "sub1"
model = "{example.model}"
body_mass_kg = 72.6
height_m = 1.743
muscle_properties = "muscles.csv"
[[subjects.trials]]
name = "normal"
ik = "{example.ik['normal']}"
id = "{example.id['normal']}"
''')
        return load_study(path)

    assert study("muscle,mass_kg\nsoleus,0.5\n").subjects[0].muscle_properties == tmp_path / "muscles.csv"
    # a bad file is refused when the study is read, before anything runs
    with pytest.raises(InputFileError, match="muscles.csv: unknown column colour"):
        study("muscle,colour\nsoleus,red\n")


@pytest.mark.opensim
@pytest.mark.slow
def test_effort_ten_on_gait2392_takes_the_literature_default(g2392_solution, g2392, tmp_path):
    import json

    from musclemetab.muscle import tendon_length_from_force, tendon_stiffness_N_per_m
    from musclemetab.redundancy.workflows import generic_passive_parameters

    _, _, muscles, solve = g2392_solution
    ten = solve("effort-ten", passive=generic_passive_parameters(muscles))
    assert ten.summary["success"] and ten.summary["max_moment_residual_Nm"] <= 1e-4
    ten.write(tmp_path / "ten")
    wf = json.loads((tmp_path / "ten" / "summary.json").read_text())["workflow"]
    assert wf["tendon_stiffness_source"] == ["literature"]
    kt = wf["tendon_stiffness"]
    assert set(kt) == {"soleus_r", "med_gas_r", "lat_gas_r", "vas_int_r", "vas_lat_r", "vas_med_r"}
    # the Achilles group's summed slope at a quarter of F0 is the tabulated 155 N/mm
    mp = g2392.muscles
    k = kt["soleus_r"]
    lt = tendon_length_from_force(0.25, k)
    slope = sum(float(tendon_stiffness_N_per_m(lt, mp.max_isometric_force_N[mp.index(m)],
                                               mp.tendon_slack_length_m[mp.index(m)], k))
                for m in ("soleus_r", "med_gas_r", "lat_gas_r"))
    assert slope == pytest.approx(155e3, rel=1e-9)
    assert all(v.startswith("literature (achilles") for m, v in wf["tendon_stiffness_sources"].items()
               if m in ("soleus_r", "med_gas_r", "lat_gas_r"))
