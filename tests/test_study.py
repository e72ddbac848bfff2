"""Studies: the study file, walking speed, resumable runs, failures, process pool and Dask."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from musclemetab.errors import InputFileError, OptionError
from musclemetab.study import load_study, run_study, study_from_dict


def _study_dict(example, trials=("slow", "normal"), workflows=("effort-gen",), models=("UM10", "BH04")):
    return {
        "name": "test study",
        "workflows": list(workflows),
        "models": list(models),
        "subjects": [{
            "name": "sub1",
            "model": str(example.model),
            "body_mass_kg": example.body_mass_kg,
            "height_m": example.height_m,
            "trials": [{"name": t, "ik": str(example.ik[t]), "id": str(example.id[t])} for t in trials],
        }],
    }


# ----------------------------------------------------------------------------- study file
def test_study_file_round_trip(tmp_path, example):
    text = f"""
name = "two speeds"
output = "out"
workflows = ["effort-gen", "effort-ten"]
models = ["UM10", "bh04"]

[[subjects]]
name = "sub1"
model = "{example.model}"
body_mass_kg = 72.6
height_m = 1.743
tendon_stiffness = {{soleus = 12.0}}

[[subjects.trials]]
name = "normal"
ik = "{example.ik['normal']}"
id = "{example.id['normal']}"
vo2_mL_per_min = 1200.0
vco2_mL_per_min = 1020.0
"""
    path = tmp_path / "study.toml"
    path.write_text(text)
    study = load_study(path)
    assert study.output == tmp_path / "out"
    assert study.models == ("UM10", "BH04")
    s = study.subject("sub1")
    assert s.tendon_stiffness == {"soleus": 12.0}
    t = s.trial("normal")
    assert t.vo2_mL_per_s == pytest.approx(20.0) and t.vco2_mL_per_s == pytest.approx(17.0)


@pytest.mark.parametrize(
    "edit, error, words",
    [
        (lambda d: d.update(colour="red"), OptionError, ["unknown key", "colour"]),
        (lambda d: d.update(workflows=["effort-xyz"]), OptionError, ["effort-xyz", "effort-gen"]),
        (lambda d: d.update(models=["UM99"]), OptionError, ["models", "UM99"]),
        (lambda d: d.update(basal="lots"), OptionError, ["basal"]),
        (lambda d: d["subjects"][0].pop("body_mass_kg"), OptionError, ["sub1", "body_mass_kg"]),
        (lambda d: d["subjects"][0].update(height_m=174.3), OptionError, ["height_m", "metres"]),
        (lambda d: d["subjects"][0]["trials"][0].update(ik="nowhere.mot"), InputFileError,
         ["trial 'slow'", "'ik'", "nowhere.mot"]),
        (lambda d: d["subjects"][0]["trials"][0].update(vo2_mL_per_s=10.0), OptionError, ["VO2", "VCO2"]),
        (lambda d: d["subjects"][0]["trials"][0].update(speed_m_per_s="fast"), OptionError, ["speed_m_per_s"]),
        (lambda d: d["subjects"][0]["trials"].append(dict(d["subjects"][0]["trials"][0])), OptionError,
         ["slow", "more than once"]),
        (lambda d: d.update(workflows=["emg-ten"]), OptionError, ["emg", "slow"]),
        (lambda d: d.update(subjects=[]), OptionError, ["no subjects"]),
    ],
)
def test_study_file_errors_name_the_key(example, edit, error, words):
    data = _study_dict(example)
    edit(data)
    with pytest.raises(error) as info:
        study_from_dict(data, base="/")
    for w in words:
        assert w in str(info.value)


def test_study_file_not_toml(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("name = \n")
    with pytest.raises(InputFileError, match="bad.toml"):
        load_study(bad)
    with pytest.raises(InputFileError, match="not found"):
        load_study(tmp_path / "none.toml")


# ----------------------------------------------------------------------------- speed
def test_walking_speed_of_a_synthetic_pelvis():
    from musclemetab.analysis.speed import walking_speed_from_ik
    from musclemetab.io import storage_from_arrays

    # 0.05 s padding, a 1.0 s cycle from 0.05 to 1.05 s. The pelvis moves at 1.2 m/s along x
    # and -0.5 m/s along z (speed sqrt(1.2^2 + 0.5^2) = 1.3 m/s) and sways with the gait
    # period, which drops out over a whole cycle.
    t = np.arange(0.0, 1.1001, 0.01)
    sway = 0.03 * np.sin(2 * np.pi * (t - 0.05) / 1.0)
    df = storage_from_arrays(t, {"pelvis_tx": 1.2 * t + sway, "pelvis_tz": -0.5 * t, "pelvis_ty": 0.9 + sway})
    assert walking_speed_from_ik(df) == pytest.approx(1.3, rel=1e-9)


def test_a_study_trial_speed_is_taken_over_the_cycle_of_its_rates(tmp_path):
    """A pelvis at 1.0 m/s until 1.5 s, then 2.0 m/s, to 3.0 s: over the gait cycle 0.6-1.4 s the
    speed is 1.0 m/s, as ``musclemetab analyse`` takes it over the cycle it analyses; over the IK file
    less the padding (0.05-2.95 s) it would be (1.45 x 1 + 1.45 x 2) / 2.9 = 1.5 m/s, which a trial
    without a cycle of its own still gets; a given ``speed_m_per_s`` wins."""
    from musclemetab.events import GaitCycle
    from musclemetab.io import storage_from_arrays, write_storage
    from musclemetab.study.events import trial_speed
    from musclemetab.study.spec import Trial

    t = np.round(np.arange(0.0, 3.0001, 0.01), 2)
    x = np.where(t <= 1.5, t, 1.5 + 2.0 * (t - 1.5))
    ik = write_storage(tmp_path / "ik.mot", storage_from_arrays(t, {"pelvis_tx": x, "pelvis_tz": 0 * t}))
    trial = Trial(name="walk", ik=ik, id=None)
    assert trial_speed(trial, cycle=GaitCycle(0.6, 1.0, 1.4)) == pytest.approx(1.0, rel=1e-9)
    assert trial_speed(trial) == pytest.approx(1.5, rel=1e-9)
    assert trial_speed(Trial(name="walk", ik=ik, id=None, speed_m_per_s=1.3), cycle=GaitCycle(0.6, 1.0, 1.4)) == 1.3


def test_example_speeds_follow_the_protocol(example):
    # The protocol: 55 %, 100 % and 145 % of the preferred walking speed (analysis.md §1).
    from musclemetab.analysis.speed import walking_speed_from_ik

    v = {s: walking_speed_from_ik(example.ik[s]) for s in ("slow", "normal", "fast")}
    assert 1.0 < v["normal"] < 1.6
    assert v["slow"] / v["normal"] == pytest.approx(0.55, rel=0.10)
    assert v["fast"] / v["normal"] == pytest.approx(1.45, rel=0.10)


# ----------------------------------------------------------------------------- runs
@pytest.fixture(scope="module")
def pool_run(example, tmp_path_factory):
    """Two trials, EFFORT-GEN, two models, in a pool of two processes."""
    out = tmp_path_factory.mktemp("pool")
    study = study_from_dict(_study_dict(example), base="/", output=out)
    run = run_study(study, workers=2, progress=False)
    return study, run


def test_pool_run_results_table(pool_run):
    study, run = pool_run
    assert not run.failed, run.failed
    assert sorted(run.ran) == ["sub1/normal/effort-gen", "sub1/slow/effort-gen"]
    table = run.results
    assert len(table) == 2 * 2  # trials x models
    assert set(table["model"]) == {"UM10", "BH04"}
    on_disk = pd.read_parquet(study.output / "results.parquet")
    pd.testing.assert_frame_equal(on_disk, pd.read_csv(study.output / "results.csv"), check_dtype=False, rtol=1e-9)
    for col in ("whole_body_W_per_kg", "gross_cost_of_transport_J_per_kg_per_m", "stance_energy_share_pct", "swing_energy_share_pct", "share_PF_pct",
                "toe_off_pct", "speed_m_per_s"):
        assert table[col].notna().all(), col
    # the study's trials are explained by the muscles: no large-reserve flag (the flagged case
    # is tests/test_robustness_inputs.py::test_large_reserves_are_flagged)
    assert table["large_reserve"].dtype == bool and not table["large_reserve"].any()
    # nor any plausibility flag (docs/quality.md): the example subject's muscles and rates are walking's
    assert (table["quality"] == "ok").all()
    for d in set(table["unit_dir"]):
        assert json.loads((study.output / d / "unit.json").read_text())["plausibility"] == []
        assert json.loads((study.output / d / "summary.json").read_text())["plausibility"] == []
    # the whole-body rate of the table is the unit's whole_body.csv
    row = table[(table.trial == "normal") & (table.model == "UM10")].iloc[0]
    wb = pd.read_csv(study.output / row.unit_dir / "whole_body.csv").set_index("model")
    assert row.whole_body_W_per_kg == pytest.approx(wb.loc["UM10", "whole_body_W_per_kg"], rel=1e-12)


def test_swing_share_recomputed_from_the_unit_files(pool_run):
    """Stance and swing shares of the table, recomputed here from metabolics.parquet."""
    import json

    study, run = pool_run
    row = run.results[(run.results.trial == "normal") & (run.results.model == "BH04")].iloc[0]
    folder = study.output / row.unit_dir
    cycle = json.loads((folder / "unit.json").read_text())["cycle"]
    m = pd.read_parquet(folder / "metabolics.parquet")
    m = m[(m.model == "BH04") & (m.component.isin(["total_no_basal"]))]
    wide = m.pivot_table(index="time", columns="component", values="value_W", aggfunc="sum")
    t = wide.index.to_numpy()
    rate = wide["total_no_basal"].to_numpy()  # one leg, without basal heat

    def energy(a, b):  # over the nodes there are: the kept nodes end 10 ms before the next contact
        a, b = max(a, t[0]), min(b, t[-1])
        tt = np.concatenate([[a], t[(t > a) & (t < b)], [b]])
        return np.trapezoid(np.interp(tt, t, rate), tt)

    stance = energy(cycle["start_s"], cycle["toe_off_s"])
    swing = energy(cycle["toe_off_s"], cycle["end_s"])
    assert row.swing_energy_share_pct == pytest.approx(100 * swing / (stance + swing), abs=1e-6)
    assert row.stance_energy_share_pct + row.swing_energy_share_pct == pytest.approx(100.0)


def test_second_run_does_no_solver_work_and_corrupt_output_is_redone(pool_run, monkeypatch):
    import musclemetab.redundancy.run as pipeline

    study, _ = pool_run
    calls = []
    real = pipeline.solve_files

    def counting(*args, **kwargs):
        calls.append(args[1])
        return real(*args, **kwargs)

    monkeypatch.setattr(pipeline, "solve_files", counting)
    run2 = run_study(study, workers=1, progress=False)
    assert calls == [] and run2.ran == [] and len(run2.skipped) == 2
    assert len(run2.results) == 4

    # corrupt one output file: that unit (only) is recomputed
    target = study.output / "units" / "sub1" / "slow" / "effort-gen" / "per_muscle.csv"
    target.write_text(target.read_text()[:1000])
    before = pd.read_csv(study.output / "results.csv")
    run3 = run_study(study, workers=1, progress=False)
    assert run3.ran == ["sub1/slow/effort-gen"] and len(calls) == 1
    pd.testing.assert_frame_equal(run3.results, before, check_dtype=False, rtol=1e-9)


def test_failing_unit_is_reported_and_the_rest_complete(pool_run, example, tmp_path, capsys):
    from musclemetab.commands import main
    from musclemetab.io import read_storage, write_storage

    study, _ = pool_run
    df = read_storage(example.id["fast"])  # the knee moment in N mm: refused by the unit check
    df["knee_angle_r_moment"] *= 1000.0
    broken = tmp_path / "ID_broken.sto"
    write_storage(broken, df, in_degrees=False)
    data = _study_dict(example, trials=("slow", "normal", "fast"))
    data["subjects"][0]["trials"][2]["id"] = str(broken)
    bad_study = study_from_dict(data, base="/", output=study.output)
    run = run_study(bad_study, workers=1, progress=False)
    assert list(run.failed) == ["sub1/fast/effort-gen"]
    assert "knee_angle_r_moment" in run.failed["sub1/fast/effort-gen"]
    assert sorted(run.skipped) == ["sub1/normal/effort-gen", "sub1/slow/effort-gen"]
    assert len(run.results) == 4
    failures = pd.read_csv(study.output / "failures.csv")
    assert failures.trial.tolist() == ["fast"] and "knee_angle_r_moment" in failures.reason[0]
    rec = (study.output / "units" / "sub1" / "fast" / "effort-gen" / "unit.json").read_text()
    assert '"failed"' in rec
    # the command line: one line per failure, exit status 1
    toml = tmp_path / "study.toml"
    trials = "".join(
        f'\n[[subjects.trials]]\nname = "{t["name"]}"\nik = "{t["ik"]}"\nid = "{t["id"]}"\n'
        for t in data["subjects"][0]["trials"]
    )
    toml.write_text(
        f'workflows = ["effort-gen"]\nmodels = ["UM10", "BH04"]\n[[subjects]]\nname = "sub1"\n'
        f'model = "{example.model}"\nbody_mass_kg = 72.6\nheight_m = 1.743\n' + trials
    )
    capsys.readouterr()
    code = main(["run", str(toml), "--out", str(study.output), "--workers", "1", "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 1
    assert "2 up to date" in out and "1 failed" in out
    assert "failed sub1/fast/effort-gen" in err and "knee_angle_r_moment" in err  # the failure on standard error
    # then the units' whole-body rates, as results.csv has them, rounded to 0.01 W/kg
    printed = out.split("whole-body metabolic rate, W/kg (two legs + basal heat):\n")[1].splitlines()
    table = pd.read_csv(study.output / "results.csv")
    trials = printed[1].split()[1:]
    assert sorted(trials) == ["normal", "slow"]
    for line in printed[4:]:
        model, *values = line.split()
        want = [table[(table.model == model) & (table.trial == t)]["whole_body_W_per_kg"].item() for t in trials]
        assert [float(v) for v in values] == pytest.approx(want, abs=0.005), (model, values, want)


def test_a_trial_naming_its_cycle_is_averaged_over_it_as_analyse_does(pool_run, example, tmp_path):
    """The normal trial (IK 0.57-1.75 s, solved whole; its own span 0.62-1.70 s) with the events
    ``start_s = 0.8, toe_off_s = 1.2, end_s = 1.5``: the study averages the rates over 0.8-1.5 s and
    says so in ``unit.json`` (``rates_over_s``), as ``musclemetab analyse --cycle 0.8,1.2,1.5`` of the
    same solve does (it used to average them over 0.62-1.70 s and split only the phases at the
    events); the solve is the pool run's (its result comes from the same solve)."""
    from musclemetab.commands import main

    study, _ = pool_run
    data = _study_dict(example, trials=("normal",), models=("UM10", "BH04"))
    data["subjects"][0]["trials"][0].update(start_s=0.8, toe_off_s=1.2, end_s=1.5, speed_m_per_s=1.3)
    named = study_from_dict(data, base="/", output=tmp_path / "named")
    run = run_study(named, workers=1, progress=False)
    assert not run.failed, run.failed
    unit = tmp_path / "named" / "units" / "sub1" / "normal" / "effort-gen"
    assert json.loads((unit / "unit.json").read_text())["rates_over_s"] == [0.8, 1.5]
    solved = study.output / "units" / "sub1" / "normal" / "effort-gen"
    assert json.loads((unit / "summary.json").read_text())["objective"] == \
        json.loads((solved / "summary.json").read_text())["objective"]
    assert main(["analyse", "--solution", str(solved), "--mass", str(example.body_mass_kg), "--height",
                 str(example.height_m), "--models", "UM10,BH04", "--cycle", "0.8,1.2,1.5", "--speed", "1.3",
                 "--out", str(tmp_path / "A")]) == 0
    want = pd.read_csv(tmp_path / "A" / "results.csv").set_index("model").sort_index()
    got = pd.read_csv(tmp_path / "named" / "results.csv").set_index("model").sort_index()
    columns = ["whole_body_W_per_kg", "cycle_start_s", "cycle_end_s", "duration_s", "swing_energy_share_pct",
               "share_PF_pct", "gross_cost_of_transport_J_per_kg_per_m"]
    pd.testing.assert_frame_equal(got[columns], want[columns], rtol=1e-9)
    assert got.loc["UM10", "duration_s"] == pytest.approx(0.7, abs=1e-9)
    # a named cycle the solved window (0.57-1.75 s) does not hold: the unit fails naming the trial and the remedies
    data["subjects"][0]["trials"][0].update(start_s=0.5, toe_off_s=1.0, end_s=1.5)
    outside = run_study(study_from_dict(data, base="/", output=tmp_path / "outside"), workers=1, progress=False)
    assert list(outside.failed) == ["sub1/normal/effort-gen"]
    assert ("trial 'normal': its gait cycle 0.500-1.500 s (from its start_s and end_s) does not lie inside the solved "
            "window 0.570-1.750 s") in outside.failed["sub1/normal/effort-gen"]


def test_the_printed_rates_carry_the_uncertainty_bands(capsys):
    """With uncertainty samples the printed table gives each rate with its 5-95 % band and says how
    many samples are behind the bands and how many were left out, summed over the units."""
    from musclemetab.commands.run import print_whole_body

    rows = pd.DataFrame({"subject": "s", "trial": ["slow", "slow", "fast", "fast"], "workflow": "effort-gen",
                         "model": ["UM10", "BH04"] * 2, "whole_body_W_per_kg": [4.5, 3.1, 6.25, 4.0],
                         "whole_body_W_per_kg_p05": [4.2, 2.9, 5.9, 3.8], "whole_body_W_per_kg_p95": [4.9, 3.4, 6.6, 4.3],
                         "uncertainty_samples": [7, 7, 8, 8], "uncertainty_rejected": [1, 1, 0, 0]})
    print_whole_body(rows)
    out = capsys.readouterr().out.splitlines()
    assert out[1] == "whole-body metabolic rate, W/kg (two legs + basal heat), [5-95 % band of the uncertainty samples]:"
    assert out[6].split() == ["UM10", "4.50", "[4.20-4.90]", "6.25", "[5.90-6.60]"]
    assert out[7].split() == ["BH04", "3.10", "[2.90-3.40]", "4.00", "[3.80-4.30]"]
    assert out[8].startswith("uncertainty: 15 samples behind the bands, 1 left out")


def test_bad_scheduler_address_is_an_option_error(pool_run, tmp_path, monkeypatch):
    pytest.importorskip("distributed")
    import musclemetab.study.runner as runner

    # port 1 refuses at once; Dask retries until its connect timeout, so keep that short
    monkeypatch.setattr(runner, "SCHEDULER_TIMEOUT_S", 0.5)
    study, _ = pool_run
    with pytest.raises(OptionError, match="scheduler"):
        run_study(study, scheduler="tcp://127.0.0.1:1", progress=False, force=True)


def test_workers_must_be_positive(pool_run):
    study, _ = pool_run
    with pytest.raises(OptionError, match="workers"):
        run_study(study, workers=0, progress=False)


def test_emg_ten_in_a_study(example, tmp_path):
    """A subject's EMG-TEN estimate feeds its EMG-TEN trial units and its EFFORT-TEN units."""
    import json

    data = _study_dict(example, trials=("slow", "normal", "fast"), workflows=("emg-ten", "effort-ten"),
                       models=("BH04",))
    data["subjects"][0]["tendon_stiffness"] = "emg-ten"
    data["subjects"][0]["emg_mapping"] = "authors"
    data["solver"] = {"stop": "authors"}  # the study's stop: its estimate is compared with the study's
    for t in data["subjects"][0]["trials"]:
        t["emg"] = str(example.emg[t["name"]])
    study = study_from_dict(data, base="/", output=tmp_path)
    run = run_study(study, workers=1, progress=False)
    assert not run.failed, run.failed
    assert run.ran[0] == "sub1/all trials/emg-ten" and len(run.ran) == 7
    summary = json.loads((tmp_path / "units" / "sub1" / "normal" / "effort-ten" / "summary.json").read_text())
    assert summary["solver_options"]["stop"] == "authors"
    params = json.loads((tmp_path / "units" / "sub1" / "_emg-ten" / "parameters.json").read_text())
    kt = params["tendon_stiffness"]
    # the study's published EMG-TEN estimate with the authors' channel mapping (§6.8)
    assert kt["soleus_r"] == pytest.approx(10.617977, rel=0.02)
    # the EFFORT-TEN units used this estimate, not the package defaults
    summary = json.loads((tmp_path / "units" / "sub1" / "normal" / "effort-ten" / "summary.json").read_text())
    assert summary["workflow"]["tendon_stiffness"]["soleus_r"] == pytest.approx(kt["soleus_r"], rel=1e-12)
    assert "parameters.json" in summary["workflow"]["tendon_stiffness_sources"]["soleus_r"]
    assert len(run.results) == 3 * 2
    # a changed EMG-TEN setting changes the key of the estimate and of the units using it
    from musclemetab.study.units import Unit, unit_key

    est, ten, gen = Unit("sub1", None, "emg-ten"), Unit("sub1", "normal", "effort-ten"), Unit("sub1", "normal", "effort-gen")
    data["subjects"][0]["emg_mapping"] = "default"
    changed = study_from_dict(data, base="/", output=tmp_path)
    assert unit_key(changed, est) != unit_key(study, est)
    assert unit_key(changed, ten, unit_key(changed, est)) != unit_key(study, ten, unit_key(study, est))
    assert unit_key(changed, gen) == unit_key(study, gen)  # EFFORT-GEN does not use EMG


def test_emg_ten_that_does_not_converge_is_a_failure_with_ipopt_status(example, tmp_path):
    """An EMG-TEN estimate stopped by the study's iteration limit is recorded in failures.csv with
    IPOPT's status and its meaning (not a Python exception); the units that need it are not run."""
    data = _study_dict(example, trials=("normal",), workflows=("emg-ten",), models=("BH04",))
    data["subjects"][0]["emg_mapping"] = "authors"
    data["subjects"][0]["trials"][0]["emg"] = str(example.emg["normal"])
    data["solver"] = {"max_iter": 3}
    study = study_from_dict(data, base="/", output=tmp_path)
    run = run_study(study, workers=1, progress=False)
    reason = run.failed["sub1/all trials/emg-ten"]
    assert "Maximum_Iterations_Exceeded" in reason and "after 3 iterations" in reason
    assert "limit was reached" in reason and "AttributeError" not in reason
    failures = pd.read_csv(tmp_path / "failures.csv")
    row = failures[(failures.workflow == "emg-ten") & failures.trial.isna()]
    assert len(row) == 1 and "Maximum_Iterations_Exceeded" in row.reason.iloc[0]
    # nothing of the failed estimate is written
    assert not (tmp_path / "units" / "sub1" / "_emg-ten" / "parameters.json").exists()


def test_study_solver_table_is_checked(example):
    data = _study_dict(example)
    data["solver"] = {"max_iter": 0}
    with pytest.raises(OptionError, match=r"\[solver\].*max_iter"):
        study_from_dict(data, base="/")
    data["solver"] = {"max_iterations": 3}
    with pytest.raises(OptionError, match="max_iterations"):
        study_from_dict(data, base="/")


def test_study_basal_coefficient_and_exponent(example):
    """OpenSim's basal rule in the study file: read, checked, and part of each trial unit's key
    (a changed coefficient redoes the metabolics); absent, the keys of earlier studies stay."""
    from musclemetab.study.units import plan_units, unit_key

    plain = study_from_dict(_study_dict(example), base="/")
    assert (plain.basal_coefficient, plain.basal_exponent) == (1.2, 1.0)
    data = _study_dict(example)
    data.update(basal_coefficient=1.5, basal_exponent=0.75)
    study = study_from_dict(data, base="/")
    assert (study.basal_coefficient, study.basal_exponent) == (1.5, 0.75)
    unit = plan_units(study)[1][0]
    data["basal_coefficient"] = 1.2
    other = study_from_dict(data, base="/")
    assert unit_key(study, unit) != unit_key(other, unit)
    data.update(basal_exponent=1.0)
    explicit_default = study_from_dict(data, base="/")
    assert unit_key(explicit_default, unit) != unit_key(plain, unit)  # recorded once named
    for bad, words in (({"basal_coefficient": -1.0}, ["basal_coefficient", "negative"]),
                       ({"basal_exponent": "three quarters"}, ["basal_exponent", "number"]),
                       ({"basal": "muscle", "basal_exponent": 0.75}, ["basal_exponent", "body"])):
        data = _study_dict(example)
        data.update(bad)
        with pytest.raises(OptionError) as info:
            study_from_dict(data, base="/")
        assert all(w in str(info.value) for w in words)


def test_study_energy_goal_table(example):
    """[energy_goal]: checked, part of the effort units' keys, and the subject's own mass and
    height in each solve's goal."""
    from musclemetab.study.units import _goals, plan_units, unit_key

    data = _study_dict(example, workflows=("effort-gen", "emg-ten"))
    data["subjects"][0]["trials"][0]["emg"] = str(example.emg["slow"])
    data["subjects"][0]["trials"][1]["emg"] = str(example.emg["normal"])
    plain = study_from_dict(data, base="/")
    data["energy_goal"] = {"model": "um10", "weight": 0.5, "effort_weight": 0.0}
    study = study_from_dict(data, base="/")
    assert study.settings["energy_goal"] == {"model": "UM10", "weight": 0.5, "effort_weight": 0.0,
                                             "smoothing": 0.001}
    units = plan_units(study)[1]
    effort = next(u for u in units if u.workflow == "effort-gen")
    emg = next(u for u in units if u.workflow == "emg-ten")
    assert unit_key(study, effort) != unit_key(plain, effort)
    assert unit_key(study, emg) == unit_key(plain, emg)  # EMG-TEN solves have no energy goal
    goals = _goals(study, study.subject("sub1"), "effort-gen")
    assert goals.effort_weights() == {"w_activation": 1.0, "w_reserve": 1000.0, "w_velocity": 0.01}
    goal = goals.energy
    assert (goal.model, goal.weight, goal.effort_weight) == ("UM10", 0.5, 0.0)
    assert (goal.body_mass_kg, goal.height_m) == (example.body_mass_kg, example.height_m)
    assert _goals(plain, plain.subject("sub1"), "effort-gen") is None
    for table, words in (({"weight": 1.0}, ["energy_goal", "'model' is required"]),
                         ({"model": "UM99"}, ["energy_goal", "UM99"]),
                         ({"model": "UM10", "weight": -2.0}, ["energy_goal", "weight"]),
                         ({"model": "UM10", "smoothing": "small"}, ["energy_goal", "smoothing"]),
                         ({"model": "UM10", "wieght": 1.0}, ["energy_goal", "wieght"])):
        data["energy_goal"] = table
        with pytest.raises(OptionError) as info:
            study_from_dict(data, base="/")
        assert all(w in str(info.value) for w in words), str(info.value)


def test_emg_processing_key_marks_raw_emg(example):
    """``emg_processing = "raw"`` (subject, or a trial overriding it) makes the trial's EMG a raw
    EMG path, which every reader of the trial's EMG processes (``musclemetab.emg.read_emg``);
    another word is refused naming the key."""
    import pickle

    from musclemetab.emg import RawEmgPath
    from musclemetab.errors import OptionError

    data = _study_dict(example, trials=("slow", "normal"))
    subject = data["subjects"][0]
    for t in subject["trials"]:
        t["emg"] = str(example.emg[t["name"]])
    subject["emg_processing"] = "raw"
    subject["trials"][1]["emg_processing"] = "envelope"
    s = study_from_dict(data).subject("sub1")
    slow, normal = (s.trial(n) for n in ("slow", "normal"))
    assert isinstance(slow.emg, RawEmgPath) and str(slow.emg) == str(example.emg["slow"])
    assert isinstance(pickle.loads(pickle.dumps(slow.emg)), RawEmgPath)  # as it travels to a worker process
    assert not isinstance(normal.emg, RawEmgPath) and normal.emg == example.emg["normal"]
    # the processing is part of what a unit's result depends on
    from musclemetab.study.units import _trial_record

    assert _trial_record(slow)["emg_processing"] == "raw" and "emg_processing" not in _trial_record(normal)
    subject["trials"][1]["emg_processing"] = "rectified"
    with pytest.raises(OptionError, match="trial 'normal'.*'emg_processing' must be envelope or raw or a table of raw-EMG settings.*not 'rectified'"):
        study_from_dict(data)


@pytest.mark.parametrize("keys", [("grf",), ("grf_column",), ("grf", "grf_column")])
def test_trial_with_external_loads_and_grf_is_refused(example, gait2392, keys):
    """``external_loads`` gives the ground forces; a ``grf`` or ``grf_column`` beside it would be
    ignored (``solve`` refuses the pair too), so the study refuses it naming the trial and keys."""
    from musclemetab.errors import OptionError

    data = _study_dict(example, trials=("normal",))
    trial = data["subjects"][0]["trials"][0]
    trial["external_loads"] = str(gait2392.external_loads)
    values = {"grf": str(gait2392.grf), "grf_column": "ground_force_vy"}
    trial.update({k: values[k] for k in keys})
    named = " and ".join(f"'{k}'" for k in keys)
    with pytest.raises(OptionError, match=f"trial 'normal': 'external_loads' and {named} both give the ground forces"):
        study_from_dict(data)
    del trial["external_loads"]
    if "grf" in keys:
        assert study_from_dict(data).subject("sub1").trial("normal").grf == gait2392.grf


def test_report_table_gives_the_figures_models(example):
    """The ``[report]`` table docs/report.md describes: ``models`` checked when the study file is
    read, kept in the settings ``study.json`` records, read back by the report."""
    from musclemetab.errors import OptionError
    from musclemetab.metabolics.registry import STUDY_MODELS
    from musclemetab.report.folder import _recorded_report_models

    data = _study_dict(example, trials=("normal",))
    data["report"] = {"models": ["all", "LW05"]}
    study = study_from_dict(data)
    assert study.settings["report"] == {"models": ["all", "LW05"]}
    assert _recorded_report_models(study.settings) == [*STUDY_MODELS, "LW05"]
    data["report"] = {"models": "UM10,XX99"}
    with pytest.raises(OptionError, match=r"\[report\]: models: unknown metabolic model .XX99."):
        study_from_dict(data)
    data["report"] = {"model": "UM10"}
    with pytest.raises(OptionError, match=r"\[report\]: unknown key\(s\) model"):
        study_from_dict(data)


def test_files_with_a_byte_order_mark_are_read(example, tmp_path):
    """Windows editors start UTF-8 files with a byte-order mark: a study file, a JSON mapping and
    a storage file saved so are read as without it (the study file gave "Invalid statement
    (line 1, column 1)")."""
    import json

    from musclemetab.io import read_json_object, read_table

    text = f"""name = "bom"
[[subjects]]
name = "sub1"
model = "{example.model}"
body_mass_kg = 72.6
[[subjects.trials]]
name = "normal"
ik = "{example.ik['normal']}"
id = "{example.id['normal']}"
"""
    (tmp_path / "bom.toml").write_text(text, encoding="utf-8-sig")
    assert (tmp_path / "bom.toml").read_bytes()[:3] == b"\xef\xbb\xbf"
    assert load_study(tmp_path / "bom.toml").subject("sub1").trial("normal").ik == example.ik["normal"]
    (tmp_path / "map.json").write_text(json.dumps({"soleus_r": ["SO"]}), encoding="utf-8-sig")
    assert read_json_object(tmp_path / "map.json") == {"soleus_r": ["SO"]}
    (tmp_path / "bom.sto").write_text(example.id["normal"].read_text(), encoding="utf-8-sig")
    a, b = read_table(example.id["normal"]), read_table(tmp_path / "bom.sto")
    assert a.attrs["name"] == b.attrs["name"] and a.columns == b.columns
    np.testing.assert_array_equal(a.values, b.values)
