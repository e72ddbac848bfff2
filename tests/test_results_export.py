"""Per-muscle results and the OpenSim-ready states of a solved trial of the example subject.

The EFFORT-GEN unit of the example subject's preferred-speed trial in the demo (the
session's ``demo`` fixture) gives:

* the per-muscle table, whose rows add up to the whole-body figure of every model of the
  registry (per leg; basal heat as docs/analysis.md §6 says: apart from the muscles, added
  per kg of body mass under the ``body`` rule, per muscle under the ``muscle`` rule);
* ``states.sto`` / ``controls.sto``, which OpenSim loads into ``model.osim`` with
  ``StatesTrajectory.createFromStatesTable`` (no missing or extra columns allowed) and
  over which OpenSim's Umberger2010 and Bhargava2004 probes run muscle by muscle; the
  probes agree with this package's UM10 and BH04 fed the muscle quantities OpenSim used,
  to the tolerance of tests/test_metabolics_opensim.py (1e-6 relative, 1e-9 W absolute).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from musclemetab.metabolics import MODELS, bhargava2004, umberger2010
from musclemetab.metabolics.solution import metabolics_from_solution

TRIAL = "normal"


@pytest.fixture(scope="module")
def solved(demo):
    from musclemetab.redundancy.solution import Solution

    out, table = demo
    unit = table[(table.trial == TRIAL) & (table.workflow == "effort-gen")].unit_dir.iloc[0]
    folder = out / unit
    return Solution.load(folder), folder


@pytest.fixture(scope="module")
def cycle(solved):
    import json

    from musclemetab.analysis import GaitCycle

    c = json.loads((solved[1] / "unit.json").read_text(encoding="utf-8"))["cycle"]
    return GaitCycle(c["start_s"], c["toe_off_s"], c["end_s"])


@pytest.mark.parametrize("basal", ["body", "muscle"])
def test_per_muscle_table_sums_to_the_whole_body_rate(example, solved, cycle, basal):
    from musclemetab.metabolics.per_muscle import per_muscle_table

    _, folder = solved
    res = metabolics_from_solution(folder, example.body_mass_kg, example.height_m, models=list(MODELS), basal=basal)
    table = per_muscle_table(res, cycle)
    assert set(table["model"]) == set(MODELS)
    for model in MODELS:
        d = table[table["model"] == model]
        wb = res.whole_body[model]
        assert len(d) == len(res.muscles) and set(d["side"]) == {"r"}
        # components once: work + heats = the muscle's rate without basal heat
        parts = d[["work_mean_W", "activation_maintenance_heat_mean_W", "shortening_lengthening_heat_mean_W"]]
        np.testing.assert_allclose(parts.sum(axis=1), d["muscle_W"], rtol=1e-12, atol=1e-12)
        leg = d["muscle_W"].sum() + (d["basal_heat_mean_W"].sum() if basal == "muscle" else 0.0)
        added = 1.2 if basal == "body" else 0.0
        assert wb.legs * leg / example.body_mass_kg + added == pytest.approx(wb.mean_W_per_kg, rel=1e-12)
        assert wb.legs * d["muscle_W_per_kg"].sum() == pytest.approx(wb.mean_W_per_kg_no_basal, rel=1e-12)
        assert d["share_of_leg_pct"].sum() == pytest.approx(100.0)
        # basal heat of a muscle: 1.2 W per kg of its mass, never inside mean_W
        np.testing.assert_allclose(d["basal_heat_mean_W"], 1.2 * res.muscle_mass_kg, rtol=1e-12)
        # stance + swing = the energy of the sampled cycle; the phases sum to the leg's phase energy
        np.testing.assert_allclose(d["stance_J"] + d["swing_J"], d["energy_per_cycle_J"], rtol=1e-12)
        assert sorted(d["rank"]) == list(range(1, len(d) + 1))
        assert d.loc[d["rank"] == 1, "muscle_W"].iloc[0] == d["muscle_W"].max()


def test_study_per_muscle_table_sums_to_the_results_table(demo):
    # the study-level table of the demo: per unit and model, the muscles add up to the whole body
    out, table = demo
    pm = pd.read_csv(out / "per_muscle.csv")
    assert pd.read_parquet(out / "per_muscle.parquet").shape == pm.shape
    sums = pm.groupby(["subject", "trial", "workflow", "model"])["muscle_W_per_kg"].sum()
    for row in table.itertuples():
        assert 2 * sums[(row.subject, row.trial, row.workflow, row.model)] == pytest.approx(
            row.whole_body_no_basal_W_per_kg, rel=1e-8)
        assert row.whole_body_W_per_kg - row.whole_body_no_basal_W_per_kg == pytest.approx(1.2, rel=1e-9)  # basal "body"
    assert (out / "muscle_groups.csv").is_file() and (out / "data_dictionary.csv").is_file()


def test_per_muscle_phase_energies_match_the_leg_analysis(example, solved, cycle):
    from musclemetab.metabolics.per_muscle import per_muscle_table
    from musclemetab.analysis.phases import phase_shares

    _, folder = solved
    res = metabolics_from_solution(folder, example.body_mass_kg, example.height_m, models="UM10,BH04")
    table = per_muscle_table(res, cycle)
    for model in res.models:
        d = table[table["model"] == model]
        ph = phase_shares(res.time_s, res.rates[model].total_without_basal(), cycle)
        assert d["stance_J"].sum() == pytest.approx(ph["stance_J"], rel=1e-12)
        assert d["swing_J"].sum() == pytest.approx(ph["swing_J"], rel=1e-12)


# ------------------------------------------------------------------------------ OpenSim
UM10_PROBE = dict(probe="Umberger2010", name="UM10", use_Bhargava_recruitment_model=False,
                  include_negative_mechanical_work=False, forbid_negative_total_power=False)
BH04_PROBE = dict(probe="Bhargava2004", name="BH04", use_force_dependent_shortening_prop_constant=True,
                  include_negative_mechanical_work=True, maintenance_length_dependence="identity",
                  forbid_negative_total_power=True)


@pytest.fixture(scope="module")
def exported(example, solved):
    from musclemetab.opensim_bridge import call
    from musclemetab.redundancy.export import CONTROLS_FILE, MODEL_FILE, STATES_FILE

    sol, folder = solved
    files = {"states": folder / STATES_FILE, "controls": folder / CONTROLS_FILE}  # written by the study unit
    res = metabolics_from_solution(folder, example.body_mass_kg, example.height_m, models="UM10,BH04")
    run = call("states:probes_over_states", str(folder / MODEL_FILE), str(files["states"]), str(files["controls"]),
               list(sol.muscles), res.muscle_mass_kg.tolist(), res.slow_twitch_fraction.tolist(),
               [UM10_PROBE, BH04_PROBE])
    return sol, files, res, run


def _inputs(run, res):
    p = run["parameters"]
    col = lambda k: np.asarray(p[k], dtype=float)[:, None]  # noqa: E731
    return dict(
        excitation=run["excitation"], activation=run["activation"],
        normalized_fiber_length=run["normalized_fiber_length"],
        normalized_fiber_velocity=run["normalized_fiber_velocity"],
        active_force_length_multiplier=run["active_force_length_multiplier"],
        force_velocity_multiplier=run["force_velocity_multiplier"],
        passive_fiber_force_N=run["passive_fiber_force_N"],
        max_isometric_force_N=col("max_isometric_force_N"), optimal_fiber_length_m=col("optimal_fiber_length_m"),
        max_contraction_velocity=col("max_contraction_velocity"),
        muscle_mass_kg=res.muscle_mass_kg[:, None], slow_twitch_fraction=res.slow_twitch_fraction[:, None],
    )


def test_exported_states_load_in_opensim_with_the_solution_values(exported):
    from types import SimpleNamespace

    full, files, _, run = exported
    # the files hold the nodes where the Hill equilibrium holds, every node but the last (docs/opensim_files.md)
    sol = SimpleNamespace(time_s=full.time_s[:-1], activation=full.activation[:-1], excitation=full.excitation[:-1],
                          tendon_force_N=full.tendon_force_N[:-1], fiber_length_m=full.fiber_length_m[:-1],
                          parameters=full.parameters)
    assert run["n_states"] == sol.time_s.size and not run["failed_states"]
    np.testing.assert_allclose(run["time_s"], sol.time_s, atol=1e-12)
    # every state variable of the model is a column of the file (OpenSim refused none)
    head = files["states"].read_text().splitlines()
    header = pd.read_csv(files["states"], sep="\t", skiprows=head.index("endheader") + 1, nrows=0).columns
    assert len(header) - 1 == run["n_state_variables"]
    # OpenSim reads back the solution's activation, excitation and normalised tendon force into the
    # model's DeGrooteFregly2016Muscles, and derives fiber lengths within 0.03 lMo of the solution's
    # (tests/test_opensim_files.py, docs/opensim_files.md)
    np.testing.assert_allclose(run["activation_state"], sol.activation.T, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(run["normalized_tendon_force_state"],
                               sol.tendon_force_N.T / sol.parameters.max_isometric_force_N[:, None], rtol=1e-10,
                               atol=1e-12)
    np.testing.assert_allclose(run["activation"], sol.activation.T, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(run["excitation"], sol.excitation.T, rtol=1e-10, atol=1e-12)
    lm_err = np.abs(run["fiber_length_m"] - sol.fiber_length_m.T) / sol.parameters.optimal_fiber_length_m[:, None]
    assert lm_err.max() < 0.03
    np.testing.assert_allclose(run["parameters"]["optimal_fiber_length_m"], sol.parameters.optimal_fiber_length_m,
                               rtol=1e-12)


def test_opensim_probes_on_the_exported_states_agree_with_um10_and_bh04(exported):
    _, _, res, run = exported
    # OpenSim's DeGrooteFregly2016Muscle (explicit tendon) takes its fiber velocity from its own force
    # equilibrium, which its curves cannot meet at some states: where the muscle is off (activation 0 at
    # the optimum: no active force to balance the tendon's) and at a few others (the velocity then leaves
    # the force-velocity curve's -vmax..vmax, or is infinite); compared where it stays on the curve, which
    # is most states of the muscles in use
    v = run["normalized_fiber_velocity"]
    on_curve = np.isfinite(v) & (np.abs(v) <= 1.0)
    in_use = np.asarray(run["activation"]) > 1e-3
    assert on_curve[in_use].mean() > 0.9
    inp = _inputs(run, res)
    for k in ("normalized_fiber_velocity", "force_velocity_multiplier", "passive_fiber_force_N",
              "active_force_length_multiplier", "normalized_fiber_length"):  # OpenSim's NaN off the curve
        inp[k] = np.where(on_curve, np.asarray(inp[k], dtype=float), 0.0)  # the package's models take finite values
    um10 = umberger2010(**inp, slow_twitch_shortening_cap=True, basal=False).total
    bh04 = bhargava2004(**inp, activation_heat_decay=False, basal=False).total
    np.testing.assert_allclose(um10[on_curve], run["UM10"][on_curve], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(bh04[on_curve], run["BH04"][on_curve], rtol=1e-6, atol=1e-9)
    assert np.max(run["UM10"][on_curve]) > 50.0 and np.max(run["BH04"][on_curve]) > 50.0  # not zeros


# ------------------------------------------------------------------------------ analyse
def test_analyse_command_gives_what_the_study_unit_gives(example, demo, tmp_path, capsys):
    import shutil

    from musclemetab.commands import main

    out, table = demo
    unit = out / table[(table.trial == TRIAL) & (table.workflow == "effort-ten")].unit_dir.iloc[0]
    # the command-line path: metabolics, then analyse; the solution given as the parent of its side folder
    parent = tmp_path / "solution"
    (parent / "r").mkdir(parents=True)
    for name in ("solution.sto", "summary.json"):
        shutil.copyfile(unit / name, parent / "r" / name)
    assert main(["metabolics", "--solution", str(parent / "r"), "--mass", str(example.body_mass_kg),
                 "--height", str(example.height_m), "--out", str(tmp_path / "met")]) == 0
    assert main(["analyse", "--solution", str(parent), "--metabolics", str(tmp_path / "met"),
                 "--model", str(example.model), "--ik", str(example.ik[TRIAL]), "--id", str(example.id[TRIAL]),
                 "--out", str(tmp_path / "an")]) == 0
    printed = capsys.readouterr().out
    assert "side r" in printed and "estimated" in printed
    got = pd.read_csv(tmp_path / "an" / "r" / "analysis.csv").set_index("model")
    want = pd.read_csv(unit / "analysis.csv").set_index("model")
    for col in ("toe_off_pct", "stance_energy_share_pct", "swing_energy_share_pct", "share_PF_pct", "share_HAB_pct"):
        np.testing.assert_allclose(got[col], want.loc[got.index, col], rtol=1e-9, err_msg=col)
    per = pd.read_csv(tmp_path / "an" / "per_muscle.csv")  # both sides' table (here: the right side)
    ref = pd.read_csv(unit / "per_muscle.csv")
    pd.testing.assert_frame_equal(per.set_index(["model", "muscle"]).sort_index(),
                                  ref.set_index(["model", "muscle"]).sort_index(), rtol=1e-9)
    wb = pd.read_csv(tmp_path / "an" / "r" / "whole_body.csv").set_index("model")
    np.testing.assert_allclose(wb["whole_body_W_per_kg"], pd.read_csv(unit / "whole_body.csv").set_index("model")
                               .loc[wb.index, "whole_body_W_per_kg"], rtol=1e-9)
    assert (tmp_path / "an" / "r" / "muscle_groups.csv").is_file()


# ------------------------------------------------------------------------------ data dictionary
def test_every_column_the_demo_writes_is_in_the_data_dictionary(demo):
    from pathlib import Path

    from musclemetab.datadict import data_dictionary_markdown, describe
    from musclemetab.io import read_storage

    out, table = demo
    unit = out / table.unit_dir.iloc[0]
    tables = {name: pd.read_csv(out / name) for name in
              ("results.csv", "per_muscle.csv", "muscle_groups.csv", "data_dictionary.csv", "failures.csv")}
    tables.update({name: pd.read_csv(unit / name) for name in
                   ("whole_body.csv", "analysis.csv", "timeseries.csv", "per_muscle.csv")})
    tables["metabolics.parquet"] = pd.read_parquet(unit / "metabolics.parquet")
    for name in ("states.sto", "controls.sto", "solution.sto", "metabolics.sto"):
        tables[name] = read_storage(unit / name)
    missing = [(name, c) for name, t in tables.items() for c in t.columns if describe(str(c)) is None]
    assert missing == []
    # the group key names every share column of the results
    key = tables["muscle_groups.csv"]
    assert set(key["column"]) == {c for c in table.columns if c.startswith("share_")}
    # the documentation is the dictionary rendered
    doc = Path(__file__).resolve().parents[1] / "docs" / "data_dictionary.md"
    assert doc.read_text(encoding="utf-8") == data_dictionary_markdown()
