"""Metabolic rates of a solver solution: trimming, files, whole-body average, calorimetry, CLI.

The solution folders are built here from synthetic arrays in the solver's file format
(``solution.sto`` + ``summary.json``).
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from musclemetab.errors import (
    DataMismatchError,
    MissingColumnError,
    MuscleTableWarning,
    OptionError,
    SolverError,
    UnknownMuscleError,
)
from musclemetab.io import read_storage, storage_from_arrays, write_storage
from musclemetab.metabolics import (
    MODELS,
    MetabolicRates,
    brockway_rate_W,
    cost_of_transport_J_per_kg_per_m,
    whole_body_rate,
)
from musclemetab.metabolics.solution import metabolics_from_solution, read_solution_states, write_metabolics
from musclemetab.model import MuscleParameters
from musclemetab.muscle import active_force_length, force_velocity, passive_force_length

MASS, HEIGHT = 72.6, 1.743
MUSCLES = ("soleus_r", "gasmed_r", "tibant_r")
F0 = {"soleus_r": 5978.0, "gasmed_r": 3000.0, "tibant_r": 1500.0}
LMO = {"soleus_r": 0.045, "gasmed_r": 0.06, "tibant_r": 0.07}
N = 30  # intervals: N + 1 = 31 nodes


def _quantities(t, i, f0):
    e = np.clip(0.35 + 0.3 * np.sin(2 * np.pi * t + i), 0.0, 1.0)
    a = np.clip(0.35 + 0.3 * np.sin(2 * np.pi * t + i - 0.3), 0.01, 1.0)
    lm = 1.0 + 0.2 * np.sin(4 * np.pi * t + i)
    vb = 0.3 * np.cos(4 * np.pi * t + i)
    fl, fv = active_force_length(lm), force_velocity(vb)
    return {
        "excitation": e,
        "activation": a,
        "normalized_fiber_length": lm,
        "normalized_fiber_velocity": vb,
        "tendon_force": np.zeros_like(t),
        "active_fiber_force": a * fl * fv * f0,
        "passive_fiber_force": f0 * passive_force_length(lm),
        "active_force_length_multiplier": fl,
        "force_velocity_multiplier": fv,
    }


def make_solution(folder, muscles=MUSCLES, n=N, success=True, drop=None):
    folder.mkdir(parents=True, exist_ok=True)
    t = 0.57 + 0.01 * np.arange(n + 1)
    cols, params = {}, {}
    for i, m in enumerate(muscles):
        f0 = F0.get(m, 1000.0)
        for q, v in _quantities(t, i, f0).items():
            cols[f"/forceset/{m}/{q}"] = v
        params[m] = dict(F0_N=f0, lMo_m=LMO.get(m, 0.05), lTs_m=0.3, alpha0_rad=0.1, vmax_lMo_per_s=10.0,
                         kT=35.0, kPE=4.0, s0=1.0, sM=0.6)
    cols["/forceset/reserve_ankle_angle_r"] = np.zeros_like(t)
    if drop:
        del cols[drop]
    write_storage(folder / "solution.sto", storage_from_arrays(t, cols))
    summary = dict(status="Solve_Succeeded" if success else "Infeasible_Problem_Detected", success=success,
                   muscles=list(muscles), dofs=["ankle_angle_r"], parameters=params)
    (folder / "summary.json").write_text(json.dumps(summary))
    return folder


@pytest.fixture(scope="module")
def solution_dir(tmp_path_factory):
    return make_solution(tmp_path_factory.mktemp("solution"))


# ----------------------------------------------------------------------------- whole body
def _rates(no_basal, basal):
    no_basal, basal = np.asarray(no_basal, float), np.asarray(basal, float)
    zeros = np.zeros_like(no_basal)
    return MetabolicRates("X", zeros, no_basal, zeros, basal, no_basal + basal)


def test_whole_body_rate_worked_by_hand():
    t = np.array([0.0, 0.1, 0.2, 0.3])
    r = _rates([[10, 20, 30, 40], [5, 5, 5, 5]], [[1, 1, 1, 1], [0.5, 0.5, 0.5, 0.5]])
    # one leg without basal: 15, 25, 35, 45 W; trapezoid: 0.1*(15/2 + 25 + 35 + 45/2) = 9 J over 0.3 s = 30 W
    wb = whole_body_rate(r, t, 75.0)
    assert wb.one_leg_mean_W == pytest.approx(30.0, rel=1e-12)
    assert wb.mean_W_per_kg == pytest.approx(2 * 30 / 75 + 1.2, rel=1e-12)  # 2.0 W/kg
    assert wb.mean_W_per_kg_no_basal == pytest.approx(0.8, rel=1e-12)
    np.testing.assert_allclose(wb.rate_W_per_kg, 2 * np.array([15, 25, 35, 45]) / 75 + 1.2)
    # the study's code: 1.2 W/kg of muscle mass kept in every muscle (here 1 + 0.5 W), nothing added
    wm = whole_body_rate(r, t, 75.0, basal="muscle")
    assert wm.one_leg_mean_W == pytest.approx(31.5, rel=1e-12)
    assert wm.mean_W_per_kg == pytest.approx(2 * 31.5 / 75, rel=1e-12)
    assert wm.mean_W_per_kg_no_basal == pytest.approx(0.8, rel=1e-12)
    assert whole_body_rate(r, t, 75.0, basal="none").mean_W_per_kg == pytest.approx(0.8, rel=1e-12)
    # an explicit cycle duration divides the same integral: 9 J / 0.6 s = 15 W
    assert whole_body_rate(r, t, 75.0, cycle_duration_s=0.6).mean_W_per_kg == pytest.approx(0.4 + 1.2)
    # cost of transport: 2.0 W/kg at 1.25 m/s = 1.6 J/kg/m
    assert wb.cost_of_transport_J_per_kg_per_m(1.25) == pytest.approx(1.6, rel=1e-12)
    assert cost_of_transport_J_per_kg_per_m(4.5, 1.5) == pytest.approx(3.0)


def test_whole_body_errors():
    t = np.array([0.0, 0.1, 0.2])
    r = _rates([[1.0, 2.0, 3.0]], [[0.0, 0.0, 0.0]])
    with pytest.raises(OptionError, match="basal=True"):
        whole_body_rate(r, t, 70.0, basal="muscle")
    with pytest.raises(OptionError, match="basal rule"):
        whole_body_rate(r, t, 70.0, basal="paper")
    with pytest.raises(DataMismatchError, match="samples"):
        whole_body_rate(r, t[:2], 70.0)
    with pytest.raises(OptionError, match="speed"):
        cost_of_transport_J_per_kg_per_m(4.0, 0.0)


def test_brockway_worked_by_hand():
    # 16.58 J/mL O2 * 15 mL/s + 4.51 J/mL CO2 * 12 mL/s = 248.7 + 54.12 = 302.82 W
    assert brockway_rate_W(15.0, 12.0) == pytest.approx(302.82, rel=1e-12)
    # urinary nitrogen 0.1 mg/s: - 5.90 * 0.1 = -0.59 W
    assert brockway_rate_W(15.0, 12.0, urinary_nitrogen_mg_per_s=0.1) == pytest.approx(302.23, rel=1e-12)
    # 1.2 L/min O2, 1.0 L/min CO2 -> 20 and 16.67 mL/s: 331.6 + 75.17 = 406.77 W
    assert brockway_rate_W(1200 / 60, 1000 / 60) == pytest.approx(331.6 + 4.51 * 1000 / 60, rel=1e-12)
    np.testing.assert_allclose(brockway_rate_W(np.array([10.0, 20.0]), np.array([8.0, 16.0])),
                               [16.58 * 10 + 4.51 * 8, 16.58 * 20 + 4.51 * 16])
    with pytest.raises(OptionError, match="vo2_mL_per_s"):
        brockway_rate_W(-1.0, 1.0)


# ----------------------------------------------------------------------------- from a solution
def test_trimming_and_values_match_direct_evaluation(solution_dir):
    res = metabolics_from_solution(solution_dir, MASS, HEIGHT)
    t_all = 0.57 + 0.01 * np.arange(N + 1)
    # kept nodes t_5 ... t_{N-6}: N - 10 samples
    assert res.time_s.size == N - 10
    np.testing.assert_allclose(res.time_s, t_all[5:N - 5])
    assert res.time_s[0] == pytest.approx(0.62) and res.time_s[-1] == pytest.approx(0.57 + 0.01 * (N - 6))
    assert res.models == ("UM03", "BH04", "HO06", "LW07", "UM10", "UC16")
    # masses from the volume rule: soleus 6.21 % of (47*72.6*1.743 + 1285) cm^3 * 1059.7 kg/m^3
    assert res.muscle_mass_kg[0] == pytest.approx(0.0621 * 7232.4646e-6 * 1059.7, rel=1e-9)
    assert list(res.slow_twitch_fraction) == [0.803, 0.566, 0.70]
    # the UM10 rate of the gastrocnemius at kept sample 3 = node 8, evaluated directly
    i, k = 1, 3
    q = _quantities(t_all, i, 3000.0)
    node = 5 + k
    direct = MODELS["UM10"](
        q["excitation"][node], q["activation"][node], q["normalized_fiber_length"][node],
        q["normalized_fiber_velocity"][node], q["active_force_length_multiplier"][node],
        q["force_velocity_multiplier"][node], q["passive_fiber_force"][node],
        3000.0, 0.06, 10.0, res.muscle_mass_kg[i], 0.566,
    )
    assert res.rates["UM10"].total[i, k] == pytest.approx(float(direct.total), rel=1e-9)
    # BH04's stimulation counter starts at the first kept node (no memory of the trimmed ones)
    from musclemetab.metabolics import bhargava2004

    q0 = _quantities(t_all, 0, 5978.0)
    assert q0["excitation"][4] > 0.1 and q0["excitation"][5] > 0.1  # stimulated across the cut
    keep = slice(5, N - 5)
    args = [q0[k][keep] for k in ("excitation", "activation", "normalized_fiber_length",
                                   "normalized_fiber_velocity", "active_force_length_multiplier",
                                   "force_velocity_multiplier", "passive_fiber_force")]
    bh = bhargava2004(*args, 5978.0, 0.045, 10.0, res.muscle_mass_kg[0], 0.803, time_s=t_all[keep])
    np.testing.assert_allclose(res.rates["BH04"].total[0], bh.total, rtol=1e-9)  # file: 12 digits
    assert res.rates["BH04"].extras["activation"][0, 0] > 0
    # whole body: the paper's rule equals 2 * mean(sum of muscle rates without basal) / mass + 1.2
    wb = res.whole_body["LW07"]
    leg = res.rates["LW07"].total_without_basal().sum(axis=0)
    mean = np.trapezoid(leg, res.time_s) / (res.time_s[-1] - res.time_s[0])
    assert wb.mean_W_per_kg == pytest.approx(2 * mean / MASS + 1.2, rel=1e-12)


def test_files(solution_dir, tmp_path):
    res = metabolics_from_solution(solution_dir, MASS, HEIGHT, models="UM10,BH04", speed_m_per_s=1.3)
    files = write_metabolics(res, tmp_path / "out")
    sto = read_storage(files["metabolics_sto"])
    assert sto.shape == (N - 10, 3 * (5 + 7))  # UM10: 5 components, BH04: 5 + activation, maintenance
    assert "UM10/soleus_r/total_no_basal" in sto.columns and "BH04/tibant_r/maintenance" in sto.columns
    np.testing.assert_allclose(sto["BH04/gasmed_r/total_no_basal"], res.rates["BH04"].total_without_basal()[1], rtol=1e-10)
    np.testing.assert_allclose(sto.index, res.time_s, rtol=1e-12)
    tidy = pd.read_parquet(files["metabolics_parquet"])
    assert list(tidy.columns) == ["time", "model", "muscle", "component", "value_W"]
    assert len(tidy) == (N - 10) * 3 * (5 + 7)
    row = tidy[(tidy.model == "UM10") & (tidy.muscle == "tibant_r") & (tidy.component == "basal")]
    np.testing.assert_allclose(row.value_W, 1.2 * res.muscle_mass_kg[2], rtol=1e-9)
    pivot = tidy[(tidy.model == "BH04") & (tidy.component == "total_no_basal") & (tidy.muscle == "gasmed_r")]
    np.testing.assert_allclose(pivot.value_W, res.rates["BH04"].total_without_basal()[1], rtol=1e-9)
    wb = pd.read_csv(files["whole_body_csv"])
    assert list(wb.columns[:4]) == ["model", "whole_body_W_per_kg", "whole_body_no_basal_W_per_kg", "leg_muscles_W"]
    assert list(wb.model) == ["UM10", "BH04"]
    assert wb.whole_body_W_per_kg.iloc[0] == pytest.approx(res.whole_body["UM10"].mean_W_per_kg, rel=1e-9)
    assert wb.whole_body_W_per_kg.iloc[0] - wb.whole_body_no_basal_W_per_kg.iloc[0] == pytest.approx(1.2, rel=1e-9)
    assert wb.gross_cost_of_transport_J_per_kg_per_m.iloc[1] == pytest.approx(wb.whole_body_W_per_kg.iloc[1] / 1.3, rel=1e-9)
    assert wb.net_cost_of_transport_J_per_kg_per_m.iloc[1] == pytest.approx(
        wb.whole_body_no_basal_W_per_kg.iloc[1] / 1.3, rel=1e-9)
    per = pd.read_csv(files["per_muscle_csv"])
    assert len(per) == 2 * len(MUSCLES) and per["stance_J"].isna().all()  # no gait cycle given
    for model in ("UM10", "BH04"):
        d = per[per.model == model]
        assert 2 * d.muscle_W.sum() / MASS == pytest.approx(wb.set_index("model").whole_body_no_basal_W_per_kg[model], rel=1e-9)


def test_without_the_parquet_extra_the_csv_and_storage_files_are_the_same(solution_dir, tmp_path, monkeypatch):
    """pyarrow is an optional extra: without it no Parquet copy is written (and a study's stale
    copy is removed), and every other file is byte for byte what it is with it."""
    import musclemetab.io.parquet as parquet
    from musclemetab.study.runner import _write_parquet_copy

    res = metabolics_from_solution(solution_dir, MASS, HEIGHT, models="UM10,BH04", speed_m_per_s=1.3)
    with_extra = write_metabolics(res, tmp_path / "with")
    monkeypatch.setattr(parquet, "parquet_available", lambda: False)
    without = write_metabolics(res, tmp_path / "without")
    assert "metabolics_parquet" in with_extra and "metabolics_parquet" not in without
    assert not (tmp_path / "without" / "metabolics.parquet").exists()
    for key, path in without.items():
        assert path.read_bytes() == with_extra[key].read_bytes(), key
    stale = tmp_path / "results.parquet"
    stale.write_bytes(b"an earlier run's copy")
    _write_parquet_copy(pd.DataFrame({"a": [1.0]}), stale)
    assert not stale.exists()
    monkeypatch.undo()
    _write_parquet_copy(pd.DataFrame({"a": [1.0, 2.5]}), stale)
    assert pd.read_parquet(stale)["a"].tolist() == [1.0, 2.5]


def test_parameters_matched_by_name(solution_dir):
    base = metabolics_from_solution(solution_dir, MASS, HEIGHT, models="HO06")
    # a model's parameter set in another order (and with an extra muscle) gives the same rates
    names = ("tibant_r", "recfem_r", "soleus_r", "gasmed_r")
    mp = MuscleParameters(
        names,
        np.array([F0.get(n, 800.0) for n in names]),
        np.array([LMO.get(n, 0.08) for n in names]),
        np.full(4, 0.3), np.full(4, 0.1), np.full(4, 10.0),
    )
    other = metabolics_from_solution(solution_dir, MASS, HEIGHT, models="HO06", muscle_parameters=mp)
    np.testing.assert_array_equal(base.rates["HO06"].total, other.rates["HO06"].total)
    with pytest.raises(DataMismatchError, match="gasmed_r"):
        metabolics_from_solution(solution_dir, MASS, HEIGHT, muscle_parameters=mp.subset(["soleus_r", "tibant_r"]))


def test_overrides_and_basal_rule(solution_dir):
    res = metabolics_from_solution(solution_dir, MASS, HEIGHT, models=["UM03"], basal="muscle",
                                   muscle_masses_kg={"soleus_r": 1.0}, slow_twitch_fractions={"tibant_r": 0.5})
    assert res.muscle_mass_kg[0] == 1.0 and res.slow_twitch_fraction[2] == 0.5
    leg = res.rates["UM03"].total.sum(axis=0)
    mean = np.trapezoid(leg, res.time_s) / (res.time_s[-1] - res.time_s[0])
    assert res.whole_body["UM03"].mean_W_per_kg == pytest.approx(2 * mean / MASS, rel=1e-12)


def test_bad_solutions(tmp_path):
    bad = make_solution(tmp_path / "unknown", muscles=("soleus_r", "mystery_r"))
    # a muscle the anatomical table cannot place: an error under strict, else one warning
    with pytest.raises(UnknownMuscleError, match="mystery_r"):
        metabolics_from_solution(bad, MASS, HEIGHT, strict=True)
    with pytest.warns(MuscleTableWarning, match="mystery_r"):
        res = metabolics_from_solution(bad, MASS, HEIGHT)
    assert res.slow_twitch_fraction[1] == 0.5
    missing = make_solution(tmp_path / "missing", drop="/forceset/gasmed_r/force_velocity_multiplier")
    with pytest.raises(MissingColumnError, match="gasmed_r/force_velocity_multiplier"):
        metabolics_from_solution(missing, MASS, HEIGHT)
    failed = make_solution(tmp_path / "failed", success=False)
    with pytest.raises(SolverError, match="did not succeed"):
        read_solution_states(failed)
    assert read_solution_states(failed, require_success=False).time_s.size == N + 1
    short = make_solution(tmp_path / "short", n=10)
    with pytest.raises(DataMismatchError, match="11 nodes"):
        metabolics_from_solution(short, MASS, HEIGHT)
    with pytest.raises(OptionError, match="UM11"):
        metabolics_from_solution(tmp_path / "unknown", MASS, HEIGHT, models="UM10,UM11")
    with pytest.raises(Exception, match="not a solution folder"):
        read_solution_states(tmp_path / "nowhere")


def test_cli(solution_dir, tmp_path, capsys):
    from musclemetab.commands import main

    out = tmp_path / "cli"
    code = main(["metabolics", "--solution", str(solution_dir), "--mass", "72.6", "--height", "1.743",
                 "--models", "UM10,BH04", "--speed", "1.3", "--out", str(out)])
    assert code == 0
    assert {p.name for p in out.iterdir()} >= {"metabolics.sto", "metabolics.parquet", "whole_body.csv", "per_muscle.csv"}
    assert "UM10" in capsys.readouterr().out
    # the whole-body rates against Ralston's band at 1.3 m/s (docs/quality.md), from whole_body.csv
    from musclemetab.metabolics.plausibility import metabolic_flags

    wb = pd.read_csv(out / "whole_body.csv").set_index("model")["whole_body_W_per_kg"]
    expected = [f.to_dict() for f in metabolic_flags(wb.to_dict(), 1.3)]
    assert json.loads((out / "plausibility.json").read_text()) == json.loads(json.dumps(expected))
    code = main(["metabolics", "--solution", str(solution_dir), "--mass", "72.6", "--height", "1.743",
                 "--models", "UM10,XX99", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1 and "unknown metabolic model 'XX99'" in err and "UM03, BH04" in err


@pytest.mark.opensim
def test_cli_with_model(example, tmp_path, capsys):
    from musclemetab.commands import main

    sol = make_solution(tmp_path / "sol")
    out = tmp_path / "out"
    code = main(["metabolics", "--solution", str(sol), "--model", str(example.model), "--mass", "72.6",
                 "--height", "1.743", "--models", "LW07", "--out", str(out)])
    assert code == 0
    assert "differs from the solution's recorded parameters" in capsys.readouterr().err
    sto = read_storage(out / "metabolics.sto")
    # LW07 shortening heat scales with F0*lMo: with the model's soleus (F0 5978.47 N,
    # lMo 0.04508 m), not the summary's (5978 N, 0.045 m)
    res = metabolics_from_solution(sol, MASS, HEIGHT, models="LW07")
    ratio = sto["LW07/soleus_r/activation_maintenance"].to_numpy() / res.rates["LW07"].activation_maintenance[0]
    np.testing.assert_allclose(ratio, 5978.474277147492 * 0.04507531830087219 / (5978.0 * 0.045), rtol=1e-9)


# ----------------------------------------------------------------------------- basal coefficient and exponent
def test_basal_coefficient_and_exponent_reach_the_whole_body_rate(solution_dir):
    """OpenSim's basal rule ``basal_coefficient * m^basal_exponent`` W, worked by hand on the
    solution's own muscle rates: only the basal heat changes."""
    ref = metabolics_from_solution(solution_dir, MASS, HEIGHT, models=["UM10"])
    res = metabolics_from_solution(solution_dir, MASS, HEIGHT, models=["UM10"], basal_rate_W_per_kg=1.5,
                                   basal_exponent=0.75)
    wb, wb0 = res.whole_body["UM10"], ref.whole_body["UM10"]
    assert wb0.basal_W_per_kg == pytest.approx(1.2, rel=1e-15)
    # 1.5 * 72.6^0.75 W = 1.5 * 24.8715 W = 37.3073 W over 72.6 kg = 0.513875 W/kg
    by_hand = 1.5 * 72.6**0.75 / 72.6
    assert by_hand == pytest.approx(0.513875, rel=1e-5)
    assert wb.basal_W_per_kg == pytest.approx(by_hand, rel=1e-14)
    assert wb.mean_W_per_kg == pytest.approx(wb0.mean_W_per_kg - 1.2 + by_hand, rel=1e-13)
    assert wb.mean_W_per_kg_no_basal == wb0.mean_W_per_kg_no_basal
    # the coefficient is also the per-muscle basal heat, W per kg of muscle mass
    np.testing.assert_allclose(res.rates["UM10"].basal[:, 0], 1.5 * res.muscle_mass_kg, rtol=1e-14)
    np.testing.assert_array_equal(res.rates["UM10"].total_without_basal(), ref.rates["UM10"].total_without_basal())
    table = res.whole_body_table().set_index("model")
    assert table.loc["UM10", "basal_W_per_kg"] == pytest.approx(by_hand, rel=1e-14)
    # the muscle rule with another coefficient: 1.5 W per kg of each muscle's mass, both legs
    mus = metabolics_from_solution(solution_dir, MASS, HEIGHT, models=["UM10"], basal="muscle",
                                   basal_rate_W_per_kg=1.5)
    assert mus.whole_body["UM10"].mean_W_per_kg == pytest.approx(
        wb0.mean_W_per_kg_no_basal + 2 * 1.5 * mus.muscle_mass_kg.sum() / MASS, rel=1e-12)
    with pytest.raises(OptionError, match="exponent"):
        metabolics_from_solution(solution_dir, MASS, HEIGHT, models=["UM10"], basal="muscle", basal_exponent=0.75)
    with pytest.raises(OptionError, match="basal coefficient"):
        metabolics_from_solution(solution_dir, MASS, HEIGHT, models=["UM10"], basal_rate_W_per_kg=-1.0)


def test_add_legs_adds_the_basal_rule_it_was_given(solution_dir):
    """Both legs solved: the body rule's basal heat, with its coefficient and exponent, is added
    once (not the default 1.2 W/kg)."""
    from musclemetab.errors import DataMismatchError
    from musclemetab.metabolics.solution import add_legs

    kw = dict(models=["MA68"], legs=1, basal_rate_W_per_kg=2.0, basal_exponent=0.5)
    legs = {"r": metabolics_from_solution(solution_dir, MASS, HEIGHT, **kw),
            "l": metabolics_from_solution(solution_dir, MASS, HEIGHT, **kw)}
    one_leg = legs["r"].whole_body["MA68"].one_leg_mean_W
    # 2 * 72.6^0.5 W / 72.6 kg = 2 / sqrt(72.6) W/kg = 0.23473 W/kg
    assert add_legs(legs)["MA68"] == pytest.approx(2 * one_leg / MASS + 2.0 / np.sqrt(72.6), rel=1e-13)
    legs["l"] = metabolics_from_solution(solution_dir, MASS, HEIGHT, models=["MA68"], legs=1)
    with pytest.raises(DataMismatchError, match="coefficient"):
        add_legs(legs)


def test_cli_basal_options(solution_dir, tmp_path, capsys):
    from musclemetab.commands import main

    common = ["metabolics", "--solution", str(solution_dir), "--mass", "72.6", "--height", "1.743", "--models", "UM03"]
    assert main(common + ["--out", str(tmp_path / "a")]) == 0
    assert main(common + ["--basal-coefficient", "1.5", "--basal-exponent", "0.75", "--out", str(tmp_path / "b")]) == 0
    a = pd.read_csv(tmp_path / "a" / "whole_body.csv").iloc[0]
    b = pd.read_csv(tmp_path / "b" / "whole_body.csv").iloc[0]
    assert b["basal_W_per_kg"] == pytest.approx(1.5 * 72.6**0.75 / 72.6, rel=1e-9)
    assert b["whole_body_W_per_kg"] - a["whole_body_W_per_kg"] == pytest.approx(1.5 * 72.6**0.75 / 72.6 - 1.2, rel=1e-8)
    capsys.readouterr()
    code = main(common + ["--basal", "muscle", "--basal-exponent", "0.75", "--out", str(tmp_path / "c")])
    err = capsys.readouterr().err
    assert code != 0 and "--basal-exponent" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "c").exists()
    code = main(common + ["--basal-coefficient", "-1", "--out", str(tmp_path / "d")])
    assert code != 0 and "--basal-coefficient" in capsys.readouterr().err


def test_without_a_height_the_masses_come_from_the_model(solution_dir, tmp_path, capsys):
    """No height: each muscle's mass is F0 / sigma * rho * lMo (OpenSim's probes' rule), worked
    by hand; the slow-twitch fractions and the basal heat of the body rule do not change, and the
    outputs say which mass rule was used."""
    from musclemetab.commands import main
    from musclemetab.metabolics.solution import MASS_RULE_MODEL, MASS_RULE_VOLUME, read_metabolics_settings

    res = metabolics_from_solution(solution_dir, MASS, None, models=["UM10", "BH04"])
    ref = metabolics_from_solution(solution_dir, MASS, HEIGHT, models=["UM10", "BH04"])
    # soleus: 5978 N / 0.6 MPa (the table's specific tension) x 1059.7 kg/m^3 x 0.045 m = 0.47512 kg
    assert res.muscle_mass_kg[0] == pytest.approx(5978.0 / 0.6e6 * 1059.7 * 0.045, rel=1e-12)
    assert res.muscle_mass_kg[0] == pytest.approx(0.475118, rel=1e-5)
    np.testing.assert_allclose(res.muscle_mass_kg, [F0[m] / 0.6e6 * 1059.7 * LMO[m] for m in MUSCLES], rtol=1e-12)
    np.testing.assert_array_equal(res.slow_twitch_fraction, ref.slow_twitch_fraction)
    assert not np.allclose(res.muscle_mass_kg, ref.muscle_mass_kg)  # another rule, other masses
    assert res.whole_body["UM10"].basal_W_per_kg == ref.whole_body["UM10"].basal_W_per_kg == 1.2
    assert (res.muscle_mass_rule, ref.muscle_mass_rule) == (MASS_RULE_MODEL, MASS_RULE_VOLUME)
    # the command without --height, and what its files say
    out = tmp_path / "no-height"
    assert main(["metabolics", "--solution", str(solution_dir), "--mass", "72.6", "--models", "UM10,BH04",
                 "--out", str(out)]) == 0
    assert "no --height" in capsys.readouterr().err
    wb = pd.read_csv(out / "whole_body.csv").set_index("model")
    assert (wb["muscle_mass_rule"] == MASS_RULE_MODEL).all()
    assert wb.loc["UM10", "whole_body_W_per_kg"] == pytest.approx(res.whole_body["UM10"].mean_W_per_kg, rel=1e-9)
    settings = read_metabolics_settings(out)
    assert "height_m" not in settings and settings["muscle_mass_rule"] == MASS_RULE_MODEL


def test_printed_rates_are_short_summaries_of_their_arrays():
    """``print`` of a model's rates and of a whole-body rate: a line per component with its mean
    and range (worked by hand here), two lines for the whole body; never the arrays (the
    dataclasses' own repr printed every value)."""
    from musclemetab.metabolics import MetabolicRates
    from musclemetab.metabolics.whole_body import WholeBodyRate

    work = np.array([[1.0, -2.0, 4.0], [0.0, 0.0, 3.0]])  # mean 1, min -2, max 4
    heat = np.full((2, 3), 0.5)
    rates = MetabolicRates("UM10", work, heat, 2 * heat, np.full((2, 3), 0.25), work + 3.25 * np.ones((2, 3)))
    assert str(rates).splitlines() == [
        "MetabolicRates UM10: components of shape (2, 3) (W; mean, min to max)",
        "  work                              1         -2 to 4",
        "  activation_maintenance          0.5        0.5 to 0.5",
        "  shortening_lengthening            1          1 to 1",
        "  basal                          0.25       0.25 to 0.25",
        "  total                          4.25       1.25 to 7.25"]
    t = np.linspace(0.0, 1.0, 201)
    wb = WholeBodyRate(time_s=t, rate_W_per_kg=np.full(t.size, 3.2), one_leg_W=np.full(t.size, 70.0),
                       mean_W_per_kg=3.2, mean_W_per_kg_no_basal=2.0, one_leg_mean_W=70.0, duration_s=1.0,
                       basal_rule="body", body_mass_kg=70.0, legs=2, basal_W_per_kg=1.2)
    assert repr(wb) == ("WholeBodyRate: 3.2 W/kg (2 without basal heat) over 1 s, 201 samples\n"
                        "  both legs, basal body (1.2 W/kg), body 70 kg; the simulated leg's muscles 70 W")
