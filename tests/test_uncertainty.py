"""Uncertainty bands: the priors, the samples' factors, the warm start adapted to a sample, the
samples as study units (resumable, the same on one and two workers), the bands of results.csv and
per_muscle.csv (collapsing to the nominal result with every spread zero) and the report's bands.

One study (the example subject's normal trial, EFFORT-GEN, two models, two samples with every
spread zero) is run once on two worker processes; its samples are the only solves here.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from musclemetab.errors import InputFileError, OptionError, UnknownMuscleError
from musclemetab.uncertainty import (
    MUSCLE_PARAMETERS,
    band,
    default_priors,
    draw,
    read_priors,
)

STUDY = """name = "uncertainty"
output = "out"
workflows = ["effort-gen"]
models = ["UM10", "BH04"]

[uncertainty]
samples = 2
seed = 7
priors = "zero.csv"

[[subjects]]
name = "sub1"
model = "{ex.model}"
body_mass_kg = {ex.body_mass_kg}
height_m = {ex.height_m}

[[subjects.trials]]
name = "normal"
ik = "{ex.ik[normal]}"
id = "{ex.id[normal]}"
"""


def _zero_priors_csv(path: Path) -> Path:
    rows = ["parameter,spread"] + [f"{p},0" for p in (*MUSCLE_PARAMETERS, "height")]
    path.write_text("\n".join(rows) + "\n")
    return path


# ------------------------------------------------------------------------------------- priors
def test_package_priors_name_every_parameter_with_a_source():
    priors = default_priors()
    assert {r.parameter for r in priors.rows} == {*MUSCLE_PARAMETERS, "height"}
    # every row says where its number comes from, who was measured, what was taken and how
    for r in priors.rows:
        assert r.source and r.population and r.value_taken and r.note, r


def test_the_example_subjects_triceps_surae_tendon_lies_inside_its_prior():
    """The tendon-stiffness prior of the triceps surae holds, within its 95 % range around the
    generic kT = 35 (EFFORT-GEN's value), the example subject's own EMG-TEN estimate (10.6,
    workflows.KT_TRICEPS_SURAE) and the in-vivo Achilles stiffness converted for the model (155
    N/mm at a quarter of F0: kT 10.1, docs/muscles.md); the other tendons keep 0.30. The vasti's
    estimate (4.7, bound-limited) lies outside the patellar prior, which holds the patellar
    tendon's literature value (kT 78.6) instead: docs/uncertainty.md says why."""
    from musclemetab.muscle import KT_GENERIC
    from musclemetab.redundancy.workflows import KT_TRICEPS_SURAE, KT_VASTI

    priors = default_priors()

    def sds(value, muscle):
        return math.log(value / KT_GENERIC) / priors.prior("kT", muscle).spread

    for m in ("soleus_r", "gasmed_l", "gaslat_r"):
        assert abs(sds(KT_TRICEPS_SURAE, m)) < 1.96 and abs(sds(10.09, m)) < 1.96
    assert abs(sds(78.6, "vaslat_r")) < 1.96 and sds(KT_VASTI, "vasmed_r") < -1.96
    assert priors.prior("kT", "tibant_r").spread == 0.30
    # the draws give the triceps surae the Achilles row's spread: factor exp(0.65 z)
    d = draw(priors, ("soleus_r", "tibant_r"), 5, 1)
    from musclemetab.uncertainty import sobol_normal

    z = sobol_normal(len(MUSCLE_PARAMETERS) * 2 + 1, 5, 1)
    kt = MUSCLE_PARAMETERS.index("kT")
    assert d.factors["kT"] == pytest.approx(np.exp(np.array([0.65, 0.30]) * z[2 * kt:2 * kt + 2]))
    assert all(r.source and r.spread > 0 for r in priors.rows)
    assert priors.prior("kT", "soleus_r").distribution == "lognormal"


def test_priors_file_replaces_rows_and_refuses_unknown_names(tmp_path):
    own = tmp_path / "own.csv"
    own.write_text("parameter,distribution,spread,muscle\nkT,lognormal,0.5,soleus\nF0,normal,0.1,\n")
    priors = read_priors(own)
    assert priors.prior("kT", "soleus_r").spread == 0.5  # the side-free row covers both sides
    # the side-free row wins over the package's tendon row; the tendon's other muscles keep it
    assert priors.prior("kT", "gasmed_r").spread == default_priors().prior("kT", "gasmed_r").spread == 0.65
    own.write_text("parameter,spread,muscle\nkT,0.1,tendon:patellar\n")
    assert read_priors(own).prior("kT", "vasmed_l").spread == 0.1
    own.write_text("parameter,spread\nkT,0\n")  # a row for every muscle replaces the tendons' rows too
    assert read_priors(own).prior("kT", "soleus_r").spread == read_priors(own).prior("kT", "vaslat_r").spread == 0
    own.write_text("parameter,spread,muscle\nkT,0.1,tendon:quadriceps\n")
    with pytest.raises(InputFileError, match="line 2: 'tendon:quadriceps' names no anatomical tendon; the tendons "
                                             "are tendon:achilles, tendon:patellar"):
        read_priors(own)
    assert priors.prior("F0", "gasmed_r").distribution == "normal"
    bad = tmp_path / "bad.csv"
    bad.write_text("parameter,spread\ntendon_stifness,0.3\n")
    with pytest.raises(InputFileError, match=r"bad.csv: line 2: unknown parameter 'tendon_stifness'"):
        read_priors(bad)
    bad.write_text("parameter,spread,colour\nkT,0.3,red\n")
    with pytest.raises(InputFileError, match="unknown column colour"):
        read_priors(bad)
    bad.write_text("a,b\n1,2\n")  # the columns it has, then those a priors file has
    with pytest.raises(InputFileError, match=r"bad.csv: no column parameter, spread \(its columns: a, b\); a priors "
                                             r"file has the columns parameter,distribution,spread,"):
        read_priors(bad)
    bad.write_text("parameter,spread\nkT,-0.1\n")
    with pytest.raises(InputFileError, match="spread '-0.1' of kT"):
        read_priors(bad)
    own.write_text("parameter,spread,muscle\nkT,0.5,solues\n")
    with pytest.raises(UnknownMuscleError, match="solues"):
        draw(read_priors(own), ["soleus_r", "gasmed_r"], 0, 1)


# ------------------------------------------------------------------------------------- samples
def test_sample_factors_are_sobol_points_through_the_normal_quantile():
    """Factor = exp(spread z) (lognormal) or 1 + spread z (normal), z the inverse normal CDF of the
    sample's point of the scrambled Sobol' sequence, computed here from scipy's whole sequence."""
    from scipy.stats import norm, qmc

    muscles = ["soleus_r", "gasmed_r", "vaslat_r"]
    priors = default_priors()
    points = qmc.Sobol(len(MUSCLE_PARAMETERS) * 3 + 1, scramble=True, seed=5).random(8)
    for k in (0, 5):
        d = draw(priors, muscles, k, 5)
        z = norm.ppf(points[k])
        s = priors.prior("F0").spread
        np.testing.assert_allclose(d.factors["F0"], np.exp(s * z[0:3]), rtol=1e-12)
        j = MUSCLE_PARAMETERS.index("slow_twitch_fraction")
        np.testing.assert_allclose(d.factors["slow_twitch_fraction"],
                                   1 + priors.prior("slow_twitch_fraction").spread * z[3 * j:3 * j + 3], rtol=1e-12)
        assert d.height == pytest.approx(1 + priors.prior("height").spread * z[-1], rel=1e-12)
    # another seed, other factors; the same seed, the same factors in any process
    assert not np.allclose(draw(priors, muscles, 5, 6).factors["F0"], draw(priors, muscles, 5, 5).factors["F0"])


def test_band_is_the_5_50_95_quantiles_or_the_min_max_of_few_samples():
    from musclemetab.uncertainty import QUANTILE_SAMPLES, band_kind, expected_coverage

    # 0, 1, ..., 100: the 5 % quantile with linear interpolation is 5 (worked by hand: position 0.05 x 100)
    assert band(np.arange(101.0)) == (5.0, 50.0, 95.0)
    # below 20 samples the band is the min and max (their 5/95 % quantiles would be little more than them)
    assert QUANTILE_SAMPLES == 20
    assert band([2.0, np.nan, 4.0]) == (2.0, 3.0, 4.0)
    assert band(np.arange(19.0)) == (0.0, 9.0, 18.0)
    assert band(np.arange(20.0)) == pytest.approx((0.95, 9.5, 18.05))  # positions 0.05 x 19 and 0.95 x 19
    assert [band_kind(n) for n in (0, 4, 12, 20)] == ["none", "min-max, few samples", "min-max", "5-95 %"]
    # a new exchangeable draw falls between the min and max of n with probability (n-1)/(n+1)
    assert expected_coverage(16) == pytest.approx(15 / 17)
    assert expected_coverage(64) == pytest.approx(0.9 * 63 / 65)  # 87.2 %
    assert all(math.isnan(x) for x in band([]))


def test_bands_leave_out_flagged_samples_and_say_where_the_nominal_lies():
    """The band of five plausible samples (1.0-1.3) leaves out the flagged and unconverged ones,
    counts them, lists them; the nominal 0.9 lies below it, said with the count of samples above it
    and the flagged samples' side; with keep_flagged the flagged ones make the band."""
    from musclemetab.uncertainty import band_table, nominal_quantile

    keys = ["subject", "trial", "workflow", "model"]
    s = pd.DataFrame({"subject": "s", "trial": "t", "workflow": "w", "model": "UM10", "sample": range(8),
                      "x": [1.0, 1.1, 1.2, 1.15, 1.3, 5.0, 6.0, np.nan],
                      "sample_flags": ["", "", "", "", "", "large_reserve(hip)", "saturation(soleus_r)",
                                       "not_converged"]})
    nominal = pd.DataFrame({"subject": ["s"], "trial": ["t"], "workflow": ["w"], "model": ["UM10"], "x": [0.9],
                            "quality": ["ok"]})
    b = band_table(s, keys, ["x"], nominal=nominal, note_column="x", listing=True).iloc[0]
    assert (b["x_p05"], b["x_p50"], b["x_p95"]) == (1.0, 1.15, 1.3)
    assert (b["uncertainty_samples"], b["uncertainty_rejected"]) == (5, 3)
    assert b["uncertainty_band"] == "min-max, few samples"
    assert b["uncertainty_flagged_samples"] == "5: large_reserve(hip); 6: saturation(soleus_r); 7: not_converged"
    assert b["x_nominal_quantile"] == 0.0
    assert b["uncertainty_note"].startswith("below its band (min-max, few samples, 5 samples): 5 of 5 plausible "
                                            "samples lie above it")
    assert "2 flagged samples left out, 0 of them below the band" in b["uncertainty_note"]
    assert "only 5 plausible samples" in b["uncertainty_note"]
    kept = band_table(s, keys, ["x"], keep_flagged=True, listing=True).iloc[0]
    assert (kept["x_p05"], kept["x_p95"], kept["uncertainty_samples"], kept["uncertainty_rejected"]) == (1.0, 6.0, 7, 1)
    assert kept["uncertainty_flagged_samples"].startswith("5: large_reserve(hip) (kept); ")
    assert nominal_quantile([1.0, 2.0, 3.0, 4.0], 2.0) == pytest.approx(1.5 / 4)  # one below, one tie (half)
    from musclemetab.uncertainty import nominal_note

    assert nominal_note(0.9995, [1.0, 1.1]).startswith("at the low end of its band (min-max, few samples, 2 samples), "
                                                       "within 0.1 %")
    assert nominal_note(1.5, [1.0, 1.1, 1.2] * 4).startswith("above its band (min-max, 12 samples): 12 of 12 "
                                                             "plausible samples lie below it")


def test_bands_of_samples_none_flagged_as_read_from_a_table(tmp_path):
    """Samples with no flag, their ``sample_flags`` column written empty and read back by pandas
    as all-missing numbers: every sample makes the band (1.0-1.3, median 1.15), none is listed,
    and no pandas warning (a missing text cell filled with text in a number column warns in
    pandas 3 and is an error in pandas 4)."""
    import warnings

    from musclemetab.uncertainty import band_table

    keys = ["subject", "trial", "workflow", "model"]
    pd.DataFrame({"subject": "s", "trial": "t", "workflow": "w", "model": "UM10", "sample": range(5),
                  "x": [1.0, 1.1, 1.2, 1.15, 1.3], "sample_flags": ""}).to_csv(tmp_path / "samples.csv", index=False)
    s = pd.read_csv(tmp_path / "samples.csv")
    assert s["sample_flags"].isna().all() and s["sample_flags"].dtype == float
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        b = band_table(s, keys, ["x"], listing=True).iloc[0]
    assert (b["x_p05"], b["x_p50"], b["x_p95"]) == (1.0, 1.15, 1.3)
    assert (b["uncertainty_samples"], b["uncertainty_rejected"], b["uncertainty_flagged_samples"]) == (5, 0, "")


def test_width_contributions_are_the_derivative_times_the_prior_spread():
    """|dR/dlog p| x spread, per parameter and muscle, ranked; vmax has no prior (no width)."""
    from musclemetab.uncertainty import top_parameters_text, width_contributions

    sens = pd.DataFrame({"model": "UM10", "rate": "whole_body", "parameter": ["lTs", "F0", "kT", "vmax"],
                         "muscle": ["soleus_r", "soleus_r", "vaslat_r", "soleus_r"],
                         "d_rate_d_log_p": [-2.4, 0.05, 0.07, 3.0]})
    priors = default_priors()
    c = width_contributions(sens, priors)
    expected = {("lTs", "soleus_r"): 2.4 * priors.prior("lTs", "soleus_r").spread,
                ("F0", "soleus_r"): 0.05 * priors.prior("F0", "soleus_r").spread,
                ("kT", "vaslat_r"): 0.07 * priors.prior("kT", "vaslat_r").spread}
    assert {(p, m): sd for p, m, sd in c[["parameter", "muscle", "sd"]].itertuples(index=False)} == pytest.approx(expected)
    assert list(c["sd"]) == sorted(expected.values(), reverse=True)
    assert top_parameters_text(c, top=1) == f"{c['parameter'][0]} {c['muscle'][0]} {c['sd'][0]:.3g}"


def test_study_file_uncertainty_table(tmp_path, example):
    from musclemetab.study.spec import load_study

    _zero_priors_csv(tmp_path / "zero.csv")
    path = tmp_path / "study.toml"
    path.write_text(STUDY.format(ex=example))
    study = load_study(path)
    assert study.settings["uncertainty"] == {"samples": 2, "seed": 7, "priors": str((tmp_path / "zero.csv").resolve())}
    path.write_text(STUDY.format(ex=example).replace("seed = 7", "seed = 7\nsampels = 3"))
    with pytest.raises(OptionError, match=r"\[uncertainty\]: unknown key\(s\) sampels"):
        load_study(path)
    path.write_text(STUDY.format(ex=example).replace("samples = 2", "samples = 2\nkeep_flagged = true"))
    assert load_study(path).settings["uncertainty"]["keep_flagged"] is True
    path.write_text(STUDY.format(ex=example).replace("samples = 2", "samples = 2\nkeep_flagged = 1"))
    with pytest.raises(OptionError, match="'keep_flagged' must be true or false"):
        load_study(path)
    path.write_text(STUDY.format(ex=example).replace("samples = 2", "samples = -2"))
    with pytest.raises(OptionError, match="'samples' = -2 is not a number of uncertainty samples"):
        load_study(path)


def test_command_line_options(tmp_path, example):
    from musclemetab.commands import build_parser
    from musclemetab.study.spec import load_study
    from musclemetab.commands.run import apply_uncertainty_arguments
    from musclemetab.study.uncertainty import sample_units

    _zero_priors_csv(tmp_path / "zero.csv")
    path = tmp_path / "study.toml"
    path.write_text(STUDY.format(ex=example))
    study = load_study(path)
    args = build_parser("run").parse_args(["run", str(path), "--uncertainty", "5", "--uncertainty-seed", "3"])
    changed = apply_uncertainty_arguments(study, args)
    assert changed.settings["uncertainty"]["samples"] == 5 and changed.settings["uncertainty"]["seed"] == 3
    assert [u.sample for u in sample_units(changed)] == [0, 1, 2, 3, 4]
    none = apply_uncertainty_arguments(study, build_parser("run").parse_args(["run", str(path), "--uncertainty", "0"]))
    assert "uncertainty" not in none.settings and sample_units(none) == []
    with pytest.raises(OptionError, match="--uncertainty = -1"):
        apply_uncertainty_arguments(study, build_parser("run").parse_args(["run", str(path), "--uncertainty", "-1"]))
    keep = apply_uncertainty_arguments(study, build_parser("run").parse_args(["run", str(path),
                                                                              "--keep-flagged-samples"]))
    assert keep.settings["uncertainty"]["keep_flagged"] is True and keep.settings["uncertainty"]["samples"] == 2
    demo = build_parser("demo").parse_args(["demo", "--uncertainty", "4", "--keep-flagged-samples"])
    assert apply_uncertainty_arguments(study, demo).settings["uncertainty"]["keep_flagged"] is True


# ------------------------------------------------------------------------------------- the study
@pytest.fixture(scope="module")
def zero_study(example, tmp_path_factory):
    from musclemetab.study.runner import run_study
    from musclemetab.study.spec import load_study

    root = tmp_path_factory.mktemp("uncertainty")
    _zero_priors_csv(root / "zero.csv")
    (root / "study.toml").write_text(STUDY.format(ex=example))
    study = load_study(root / "study.toml")
    run = run_study(study, workers=2, progress=False)
    assert not run.failed, run.failed
    return study, run


def test_zero_spreads_collapse_the_bands_to_the_nominal_result(zero_study):
    study, run = zero_study
    out = Path(study.output)
    results = pd.read_csv(out / "results.csv")
    per_muscle = pd.read_csv(out / "per_muscle.csv")
    assert (results["uncertainty_samples"] == 2).all() and (per_muscle["uncertainty_samples"] == 2).all()
    # every sample is checked as any solve is: its record keeps its flags (none here) and convergence
    rec = json.loads((out / "units/sub1/normal/effort-gen/samples/0000/unit.json").read_text())
    assert rec["plausibility"] == [] and rec["convergence"]["max_rate_residue"] < 0.01
    # a sample starts from the trial unit's optimum and multipliers (its ipopt_start.npz) and, being
    # the trial unit's problem here, needs fewer iterations than the trial unit's cold solve
    nominal = json.loads((out / "units/sub1/normal/effort-gen/summary.json").read_text())
    assert rec["start"] == "warm start from effort-gen (its optimum and multipliers)"
    assert rec["iterations"] < 0.75 * nominal["iterations"]
    with np.load(out / "units/sub1/normal/effort-gen/ipopt_start.npz") as start:
        assert start["x"].size == nominal["problem_size"]["variables"]
        assert start["lam_x"].size == start["x"].size and start["lam_g"].size == nominal["problem_size"]["equality_constraints"]
    assert (results["uncertainty_rejected"] == 0).all() and (per_muscle["uncertainty_rejected"] == 0).all()
    assert (results["uncertainty_band"] == "min-max, few samples").all()
    assert results["whole_body_W_per_kg_nominal_quantile"].between(0, 1).all()
    # the samples repeat the nominal solve: it lies in its band or at an end within the solver's tolerance
    assert results["uncertainty_note"].str.match(r"(inside|at the (low|high) end of) its band \(min-max, few samples, "
                                                 r"2 samples\)").all()
    # the columns of a band stand beside the rate
    cols = list(results.columns)
    i = cols.index("whole_body_W_per_kg")
    assert cols[i + 1:i + 4] == ["whole_body_W_per_kg_p05", "whole_body_W_per_kg_p50", "whole_body_W_per_kg_p95"]
    # the samples solve the nominal problem again (warm-started): the bands are the nominal values
    # to the solver's tolerance
    for c in ("whole_body_W_per_kg", "stance_energy_share_pct", "share_PF_pct"):
        for s in ("_p05", "_p50", "_p95"):
            np.testing.assert_allclose(results[c + s], results[c], rtol=1e-4, atol=1e-4)
    big = per_muscle["muscle_W"] > 1.0
    np.testing.assert_allclose(per_muscle.loc[big, "muscle_W_p95"], per_muscle.loc[big, "muscle_W"], rtol=2e-3)
    # every factor of the samples is 1
    factors = pd.read_csv(out / "units/sub1/normal/effort-gen/samples/0001/factors.csv")
    assert (factors.drop(columns="muscle").to_numpy() == 1.0).all()
    # every column is in the data dictionary, for its file
    from test_datadict_columns import undocumented

    assert not undocumented(out / "results.csv", results.columns)
    assert not undocumented(out / "per_muscle.csv", per_muscle.columns)
    assert not undocumented(out / "factors.csv", factors.columns)


def test_samples_are_resumable_and_the_same_in_this_process(zero_study):
    """A sample run again in this process (one worker) gives the files its pool worker wrote, bit for
    bit; a second run finds every unit up to date."""
    from musclemetab.study.runner import run_study
    from musclemetab.study.units import execute_unit, read_unit_record, unit_key
    from musclemetab.study.uncertainty import sample_units

    study, run = zero_study
    out = Path(study.output)
    assert len(run.ran) == 3  # the trial unit and its two samples
    again = run_study(study, workers=1, progress=False)
    assert again.ran == [] and len(again.skipped) == 3
    unit = sample_units(study)[1]
    folder = out / unit.folder
    before = read_unit_record(folder)["outputs"]
    nominal = unit.depends_on(study)
    key = unit_key(study, unit, unit_key(study, nominal))
    assert key == read_unit_record(folder)["key"]
    import solve_memo

    with solve_memo.solved_again():  # solved here, not the pool worker's result from the test run's memo
        rec = execute_unit(study, unit, key, str(out / nominal.folder))
    assert rec["status"] == "ok" and rec["converged"]
    assert rec["outputs"] == before


def test_samples_on_a_dask_cluster_give_the_process_pool_bands(zero_study, example, tmp_path):
    """The same study on a local Dask cluster of two worker processes: the trial unit and its
    samples (units that wait for another unit) run there as on the process pool, and results.csv
    (bands included) and per_muscle.csv are the pool's. The suite's one run of a study on Dask."""
    distributed = pytest.importorskip("distributed")
    import solve_memo

    from musclemetab.study.runner import run_study
    from musclemetab.study.spec import load_study

    study, run = zero_study
    _zero_priors_csv(tmp_path / "zero.csv")
    (tmp_path / "study.toml").write_text(STUDY.format(ex=example))
    dask_study = load_study(tmp_path / "study.toml")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        client.run(solve_memo.install_in_worker)  # the test run's solves, once (tests/solve_memo.py)
        dask_run = run_study(dask_study, scheduler=cluster.scheduler_address, progress=False)
    assert not dask_run.failed and sorted(dask_run.ran) == sorted(run.ran)
    assert sorted(dask_run.ran) == ["sub1/normal/effort-gen", "sub1/normal/effort-gen/sample 0",
                                    "sub1/normal/effort-gen/sample 1"]
    for name in ("results.csv", "per_muscle.csv"):
        a = pd.read_csv(Path(study.output) / name).drop(columns=["unit_dir"], errors="ignore")
        b = pd.read_csv(Path(dask_study.output) / name).drop(columns=["unit_dir"], errors="ignore")
        assert any(c.endswith("_p95") for c in b.columns)
        pd.testing.assert_frame_equal(a, b, check_dtype=False, rtol=1e-8)


def test_adapted_start_keeps_the_tendon_forces(zero_study):
    """The warm start of a sample keeps the nominal tendon forces under the sample's parameters: the
    forces recomputed from its fiber lengths (derived_quantities) equal the solution's; with the
    solution's own parameters it gives back the solution's fiber lengths."""
    from musclemetab.redundancy.solution import Solution, derived_quantities
    from musclemetab.muscle import tendon_length_from_force
    from musclemetab.uncertainty import adapted_start

    study, _ = zero_study
    sol = Solution.load(Path(study.output) / "units/sub1/normal/effort-gen")
    p0 = sol.parameters.subset(sol.muscles)
    same = adapted_start(sol, p0)
    inside = (sol.lm_norm > 0.2) & (sol.lm_norm < 1.6)
    np.testing.assert_allclose(same.lm_norm[inside], sol.lm_norm[inside], rtol=1e-8)
    factors = draw(default_priors(), sol.muscles, 3, 1)
    p1 = factors.parameters(p0)
    start = adapted_start(sol, p1)
    lm0 = sol.lm_norm * p0.optimal_fiber_length_m
    lmt = np.sqrt(lm0**2 - p0.width_m**2) + p0.tendon_slack_length_m * tendon_length_from_force(
        sol.tendon_force_N / p0.max_isometric_force_N, p0.tendon_stiffness)
    d = derived_quantities(p1, start.activation, start.lm_norm, start.fiber_velocity_lmo_per_s, lmt)
    ok = (start.lm_norm > 0.2 + 1e-9) & (start.lm_norm < 1.6 - 1e-9) & (sol.tendon_force_N > 1.0)
    assert ok.mean() > 0.9
    np.testing.assert_allclose(d["tendon_force_N"][ok], sol.tendon_force_N[ok], rtol=1e-6)


@pytest.mark.opensim
@pytest.mark.slow
def test_a_sample_from_the_nominal_optimum_and_multipliers_gives_the_cold_rates(example, geometry_cache):
    """A sample started from the nominal optimum and its IPOPT multipliers (what a study's samples
    do, ``sample_start``) ends at the optimum of the sample's cold solve: the six study models'
    whole-body rates within 0.2 %, in fewer iterations than cold and than the adapted start of a
    solution without multipliers (one read from files). 0.3 s of the normal trial, EFFORT-GEN."""
    from dataclasses import replace

    from musclemetab.metabolics.solution import metabolics_from_solution
    from musclemetab.redundancy import solve_files
    from musclemetab.uncertainty import sample_start

    files = (example.model, example.ik["normal"], example.id["normal"])
    kw = dict(window=(0.6, 0.9), cache_dir=geometry_cache)
    nominal = solve_files(*files, "effort-gen", **kw)
    assert nominal.multipliers["x"].size == nominal.record.problem_size["variables"]
    sample = draw(default_priors(), nominal.muscles, 1, 1)
    params = sample.parameters(nominal.parameters)

    def solve(start=None):
        return solve_files(*files, "effort-gen", parameter_transform=sample.parameters,
                           **({} if start is None else {"warm_start": start}), **kw)

    cold, warm = solve(), solve(sample_start(nominal, params))
    adapted = solve(sample_start(replace(nominal, multipliers=None), params))
    assert "its optimum and multipliers" in warm.record.initial_guess
    assert "mu_init" in adapted.record.initial_guess and "static optimisation" in cold.record.initial_guess
    assert cold.success and warm.success and adapted.success
    assert warm.record.iterations < min(cold.record.iterations, adapted.record.iterations)
    models = ["UM03", "BH04", "HO06", "LW07", "UM10", "UC16"]
    rates = [metabolics_from_solution(s, example.body_mass_kg, example.height_m, models=models).whole_body
             for s in (cold, warm)]
    for m in models:
        assert rates[1][m].mean_W_per_kg == pytest.approx(rates[0][m].mean_W_per_kg, rel=2e-3)


def test_report_draws_the_bands(zero_study):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from musclemetab.report.figures import group_shares, phase_shares
    from musclemetab.report.folder import read_study_folder
    from musclemetab.report.page import uncertainty_section

    study, _ = zero_study
    folder = read_study_folder(study.output)
    section = uncertainty_section(folder)
    assert section["samples"] == 2 and section["seed"] == 7 and section["converged"] == "2"
    row = folder.ok[folder.ok["model"] == "UM10"].iloc[0]
    cell = section["whole_body"].body[[r[1] for r in section["whole_body"].body].index("UM10")][2]
    assert cell.startswith(f"{row['whole_body_W_per_kg']:.3f} [")
    assert [r[0] for r in section["priors"].body] == [r.parameter for r in read_priors(
        json.loads((Path(study.output) / "study.json").read_text())["uncertainty"]["priors"]).rows]
    assert "[" in section["muscles"]["UM10"].body[0][1]
    # each band with its nominal: one row per results row, the counts, the band's kind, the quantile
    assert len(section["bands"].body) == len(folder.ok) and section["flagged"] is None
    um10 = next(r for r in section["bands"].body if r[3] == "UM10")
    assert um10[6:9] == ["min-max, few samples", "2", "0"] and um10[9].endswith(" %")
    from musclemetab.report.uncertainty import band_caption

    caption = band_caption(folder.ok, "whole_body_no_basal_W_per_kg")
    assert "min-max uncertainty band" in caption and "over 2 samples" in caption
    from musclemetab.report.layout_check import figure_problems

    fig = phase_shares(folder.ok)
    gids = {a.get_gid() for ax in fig.axes for a in ax.get_children()}
    # one trial: the stance share's band on its bar; no speed panel (at one speed a vertical stripe)
    assert "band:stance:effort-gen" in gids and len(fig.axes) == 1
    fig2 = group_shares(folder.ok)
    assert any(str(a.get_gid()).startswith("band:groups:effort-gen:UM10") for ax in fig2.axes for a in ax.get_children())
    assert figure_problems(fig) == [] and figure_problems(fig2) == []
    plt.close("all")


def test_a_legs_samples_live_in_its_leg_unit(tmp_path):
    """A sample of a leg unit (side = both) is a folder inside that leg's unit folder, which the run
    prepares for the leg unit alone (the sample's parent is the leg unit, replaced as a whole)."""
    from musclemetab.study.units import Unit, prepare_leg_folder

    sample = Unit("sub", "walk", "effort-gen", "l", sample=3)
    assert sample.folder == Path("units/sub/walk/effort-gen/l/samples/0003")
    assert sample.label == "sub/walk/effort-gen/l/sample 3"
    prepare_leg_folder(tmp_path, sample)
    assert not any(tmp_path.iterdir())
    assert sample.depends_on(None) == Unit("sub", "walk", "effort-gen", "l")


def test_priors_naming_an_unknown_muscle_are_refused_when_the_study_starts(example, tmp_path):
    """A priors file naming a muscle no subject's model has is refused by ``run_study`` before
    any unit runs (nothing written), naming the file, the muscle and the model; a sample found it
    only when it ran."""
    from musclemetab.study import load_study, run_study

    (tmp_path / "zero.csv").write_text("parameter,spread,muscle\nkT,0.3,soleus\nkT,0.2,solues_r\n")
    (tmp_path / "study.toml").write_text(STUDY.format(ex=example))
    study = load_study(tmp_path / "study.toml")
    with pytest.raises(UnknownMuscleError, match=r"zero\.csv: muscle solues_r of the uncertainty priors names no "
                                                 r"muscle of subject sub1's model"):
        run_study(study, workers=1, progress=False)
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------------------------- coverage
@pytest.mark.opensim
def test_bands_cover_independent_truths_at_their_stated_rate(example):
    """Truths drawn independently of the sampler (NumPy's PCG64 with its own seed, against the
    bands' Sobol' points) and solved cold fall inside the band of the plausible samples at the rate
    the band states for its number of samples, (n-1)/(n+1) for a min-max band: not below the 0.5 %
    binomial quantile of that rate. A small problem (the ankle, 0.3 s of the normal trial), 9
    samples and 10 truths; the larger run is in docs/uncertainty.md."""
    from scipy.stats import binom

    from musclemetab.uncertainty_coverage import coverage, independent_draws, summary

    priors = default_priors()
    muscles = ("soleus_r", "tibant_r")
    truths = independent_draws(priors, muscles, 2, seed=3)
    assert not np.allclose(truths[0].factors["lTs"], draw(priors, muscles, 0, 3).factors["lTs"])
    table = coverage((example.model, example.ik["normal"], example.id["normal"]), body_mass_kg=example.body_mass_kg,
                     height_m=example.height_m, models=("UM10", "BH04"), samples=9, truths=10, window=(0.6, 0.9),
                     dofs=["ankle_angle_r"])
    print(table.to_string())
    s = summary(table)
    print(s.to_string())
    for row in s.itertuples(index=False):
        n = row.samples_used
        assert n >= 5 and row.plausible_truths >= 5
        assert row.expected_share == pytest.approx((n - 1) / (n + 1))
        assert row.inside >= binom.ppf(0.005, row.plausible_truths, row.expected_share)
    # a truth with a flag is left out, never counted inside
    assert not table.loc[~table["plausible"], "inside"].any()


def test_a_flagged_sample_is_left_out_of_the_bands_and_listed(zero_study, tmp_path):
    """The zero study's results gathered again from a copy in which sample 1 records a flag (as a
    sample whose reserve carried much of a moment would): its bands are sample 0's alone, the rows
    count one sample used and one rejected and list it with its flag; with keep_flagged both are
    used again and the list marks it kept. Nothing is solved."""
    import shutil
    from dataclasses import replace

    from musclemetab.study.runner import collect_results

    study, _ = zero_study
    out = tmp_path / "out"
    shutil.copytree(study.output, out)
    flag = {"code": "large_reserve", "message": "reserve", "items": {"hip_flexion_r": 0.3}, "threshold": 0.1}
    unit = out / "units/sub1/normal/effort-gen/samples/0001/unit.json"
    rec = json.loads(unit.read_text())
    unit.write_text(json.dumps({**rec, "plausibility": [flag]}))
    copy = replace(study, output=str(out))
    collect_results(copy)
    results = pd.read_csv(out / "results.csv")
    pm = pd.read_csv(out / "per_muscle.csv")
    s0 = pd.read_csv(out / "units/sub1/normal/effort-gen/samples/0000/whole_body.csv")
    assert (results["uncertainty_samples"] == 1).all() and (results["uncertainty_rejected"] == 1).all()
    assert (pm["uncertainty_samples"] == 1).all() and (pm["uncertainty_rejected"] == 1).all()
    assert (results["uncertainty_flagged_samples"] == "1: large_reserve(hip_flexion_r)").all()
    for model in ("UM10", "BH04"):
        row = results[results["model"] == model].iloc[0]
        value = float(s0.loc[s0["model"] == model, "whole_body_W_per_kg"].iloc[0])
        assert row["whole_body_W_per_kg_p05"] == row["whole_body_W_per_kg_p95"]  # one sample: a point
        assert row["whole_body_W_per_kg_p05"] == pytest.approx(value, rel=1e-8)
    kept = replace(copy, settings={**copy.settings, "uncertainty": {**copy.settings["uncertainty"], "keep_flagged": True}})
    collect_results(kept)
    results = pd.read_csv(out / "results.csv")
    assert (results["uncertainty_samples"] == 2).all() and (results["uncertainty_rejected"] == 0).all()
    assert (results["uncertainty_flagged_samples"] == "1: large_reserve(hip_flexion_r) (kept)").all()
