"""Plausibility flags after the solve: each check against a case worked by hand on small arrays,
the record's round trip, the quality column, --strict; the example subject's normal trial gives
no flag (the gait2392 subject's flags: tests/test_gait2392.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from musclemetab.errors import ImplausibleResultError, PlausibilityWarning
from musclemetab.metabolics.plausibility import (
    metabolic_flags,
    negative_group_flag,
    ralston_gross_rate_W_per_kg,
    results_rows_flags,
    SPEED_FREE_UPPER_W_PER_KG,
    whole_body_rate_flag,
)
from musclemetab.redundancy.plausibility import (
    Flag,
    check_strict,
    fiber_length_flag,
    passive_force_flag,
    quality_text,
    reserve_flag,
    saturation_flag,
    warn_flags,
)
from musclemetab.redundancy.record import SolveRecord


def test_passive_force_flag_names_the_muscles_above_half_f0():
    # peaks over the nodes, in F0: a 300/1000 = 0.30, b 600/1000 = 0.60, c 900/1500 = 0.60
    force = np.array([[100.0, 600.0, 900.0], [300.0, 200.0, 100.0]])
    f = passive_force_flag(["a", "b", "c"], force, np.array([1000.0, 1000.0, 1500.0]))
    assert f.code == "passive_force" and list(f.items) == ["b", "c"]
    assert f.items == pytest.approx({"b": 0.6, "c": 0.6}) and f.threshold == 0.5
    assert "b 0.60" in f.message and "0.5 F0" in f.message
    # exactly at the limit is not above it; a lower limit flags a as well
    assert passive_force_flag(["a"], np.array([[500.0]]), np.array([1000.0])) is None
    assert list(passive_force_flag(["a", "b", "c"], force, np.array([1000.0, 1000.0, 1500.0]), limit=0.25).items) == \
        ["b", "c", "a"]


def test_fiber_length_flag_beyond_the_default_bound_names_the_widened_one():
    lm = np.array([[1.0, 1.69, 1.2], [1.3, 1.72, 1.9]])
    f = fiber_length_flag(["a", "b", "c"], lm, widened_upper={"c": 2.05})
    assert list(f.items) == ["c", "b"] and f.items == pytest.approx({"c": 1.9, "b": 1.72}) and f.threshold == 1.7
    assert "c 1.90 (bound widened to 2.05)" in f.message and "b 1.72;" in f.message
    assert fiber_length_flag(["a"], np.array([[1.7]])) is None


def test_saturation_flag_counts_the_share_of_nodes():
    # 20 nodes: a at >= 0.95 on 3 (15 %), b on 2 (10 %, not above), c never
    a = np.zeros((20, 3))
    a[:3, 0] = [0.95, 1.0, 0.97]
    a[5:7, 1] = 1.0
    a[:, 2] = 0.94
    f = saturation_flag(["a", "b", "c"], a)
    assert list(f.items) == ["a"] and f.items["a"] == pytest.approx(0.15) and "a 15%" in f.message
    assert list(saturation_flag(["a", "b", "c"], a, limit=0.05).items) == ["a", "b"]
    assert list(saturation_flag(["a", "b", "c"], a, level=0.9, limit=0.5).items) == ["c"]


def test_saturation_share_counts_the_gait_cycle_not_its_padding():
    """A 1.1 s window on a 100 Hz mesh (111 nodes): a 1.0 s cycle padded by 0.05 s at each end.
    Muscle a is saturated over the padding alone (5 + 6 nodes): not flagged; b over 12 nodes of the
    cycle, 12 % of its 100 nodes (t = 0.05 ... 1.04 s): flagged at 0.12, where a share over every
    node would give 12/111 = 10.8 %; c over 10 cycle nodes (10 %, not above) and the padding: not
    flagged, where every node would give 21/111 = 18.9 %."""
    from musclemetab.redundancy.plausibility import cycle_nodes

    t = np.round(np.arange(111) * 0.01, 10)
    act = np.full((111, 3), 0.2)
    act[:5, 0] = act[-6:, 0] = 1.0
    act[40:52, 1] = 0.96
    act[:5, 2] = act[-6:, 2] = act[60:70, 2] = 0.99
    inside = cycle_nodes(t)
    assert inside.sum() == 100 and t[inside][0] == pytest.approx(0.05) and t[inside][-1] == pytest.approx(1.04)
    f = saturation_flag(["a", "b", "c"], act, in_cycle=inside)
    assert list(f.items) == ["b"] and f.items["b"] == pytest.approx(0.12) and "of the gait cycle" in f.message
    assert list(saturation_flag(["a", "b", "c"], act).items) == ["c", "b"]  # the padding counted: other muscles
    # a recorded gait cycle (a solve over --cycle): its nodes, ends included; b's 12 nodes of 0.31 ... 0.90 s
    rec = cycle_nodes(t, (0.31, 0.90))
    assert rec.sum() == 60 and saturation_flag(["a", "b", "c"], act, in_cycle=rec).items == pytest.approx(
        {"b": 12 / 60, "c": 10 / 60})
    # a window too short for its padding is taken whole
    assert cycle_nodes(t[:10]).all()


def test_saturation_while_lengthening_counts_the_cycle_nodes_where_both_hold():
    """100 cycle nodes and 5 + 6 padding nodes. a: full activation on 30 cycle nodes, lengthening on
    3 of them (3 %: flagged), shortening on the rest; b: full activation on 10 nodes, lengthening
    on 2 (2 %, not above the limit); c: lengthening at full activation in the padding alone (not
    flagged); d: lengthening throughout at activation 0.94 (below the level)."""
    from musclemetab.redundancy.plausibility import (LENGTHENING_SATURATION_SHARE_LIMIT, cycle_nodes,
                                                     lengthening_saturation_flag)

    t = np.round(np.arange(111) * 0.01, 10)
    act, vel = np.full((111, 4), 0.2), np.full((111, 4), -0.5)
    act[20:50, 0] = 1.0
    vel[30:33, 0] = 0.4
    act[60:70, 1] = 0.97
    vel[60:62, 1] = 0.1
    act[:5, 2] = act[-6:, 2] = 1.0
    vel[:5, 2] = vel[-6:, 2] = 1.0
    act[:, 3], vel[:, 3] = 0.94, 1.0
    inside = cycle_nodes(t)
    f = lengthening_saturation_flag(["a", "b", "c", "d"], act, vel, in_cycle=inside)
    assert LENGTHENING_SATURATION_SHARE_LIMIT == 0.02 and f.code == "saturated_lengthening"
    assert f.items == pytest.approx({"a": 0.03}) and "a 3%" in f.message and "lengthens" in f.message
    assert list(lengthening_saturation_flag(["a", "b", "c", "d"], act, vel, in_cycle=inside, limit=0.01).items) == \
        ["a", "b"]
    assert list(lengthening_saturation_flag(["a", "b", "c", "d"], act, vel, limit=0.01).items) == ["c", "a", "b"]
    assert lengthening_saturation_flag(["a", "b", "c", "d"], act, vel, in_cycle=inside, level=0.9).items == \
        pytest.approx({"d": 1.0, "a": 0.03})
    # a solve whose muscles never lengthen at full activation (saturated while shortening only)
    assert lengthening_saturation_flag(["a"], act[:, :1], -np.abs(vel[:, :1]), in_cycle=inside) is None


def test_reserve_flag_per_dof_share_of_its_peak_moment():
    # 4 intervals + the repeated last node; RMS over the intervals: knee sqrt((9+9+16+16)/4) = 3.5355
    r = np.array([[3.0, 0.2], [-3.0, 0.2], [4.0, -0.2], [-4.0, 0.2], [-4.0, 0.2]])
    peaks = {"knee": 50.0, "toe": 0.1}
    f = reserve_flag(["knee", "toe"], r, peaks)
    # knee 3.54/50 = 7.1 % > 5 %; toe 0.2/0.1 = 200 % but 0.2 N m below the 1 N m floor
    assert list(f.items) == ["knee"] and f.items["knee"] == pytest.approx(math.sqrt(12.5) / 50)
    assert "knee 3.54 N m RMS = 7.1% of 50 N m" in f.message
    assert reserve_flag(["knee", "toe"], r, {"knee": 80.0, "toe": 0.1}) is None  # 4.4 %
    assert list(reserve_flag(["knee", "toe"], r, peaks, floor_Nm=0.1).items) == ["toe", "knee"]


def test_ralston_rate_and_the_band_of_walking():
    # Ralston 1958: 29 + 0.0053 v^2 cal/(kg min), v in m/min; 1.25 m/s = 75 m/min:
    # 29 + 0.0053 * 5625 = 58.8125 cal/(kg min) = 58.8125 * 4.184 / 60 W/kg = 4.1013 W/kg
    assert float(ralston_gross_rate_W_per_kg(1.25)) == pytest.approx(58.8125 * 4.184 / 60, rel=1e-12)
    ref = 58.8125 * 4.184 / 60
    assert whole_body_rate_flag("UM10", 2 * ref - 1e-6, 1.25) is None
    high = whole_body_rate_flag("UM10", 10.8, 1.25)
    assert high.code == "metabolic_rate" and high.model == "UM10" and "above" in high.message
    assert f"{0.5 * ref:.2f}-{2 * ref:.2f} W/kg" in high.message
    assert "below" in whole_body_rate_flag("BH04", 0.5 * ref - 0.01, 1.25).message
    # a speed outside Ralston's range: not checked
    assert whole_body_rate_flag("UM10", 50.0, 3.0) is None
    assert whole_body_rate_flag("UM10", 10.8, 1.25, band=(0.5, 3.0)) is None


def test_without_a_speed_a_rate_above_the_fastest_walking_is_flagged():
    """No speed (a treadmill trial without one, gait2392's trial): the rate is held against
    Ralston's gross rate at 2.0 m/s, the top of his range: 29 + 0.0053 x 120^2 = 105.32
    cal/(kg min) = 105.32 x 4.184 / 60 = 7.3443 W/kg. gait2392's UM10 rate, 10.76 W/kg
    (docs/quality.md), is flagged; a rate at it is not; a results row without a speed likewise."""
    bound = 105.32 * 4.184 / 60
    assert whole_body_rate_flag("UM10", bound - 1e-9, None) is None
    high = whole_body_rate_flag("UM10", 10.76, None)
    assert high.code == "metabolic_rate" and high.model == "UM10" and high.threshold == pytest.approx(bound, rel=1e-12)
    assert "10.76 W/kg is above 7.34 W/kg" in high.message and "speed is unknown" in high.message
    assert whole_body_rate_flag("UM10", 10.76, float("nan")).code == "metabolic_rate"
    rows = pd.DataFrame({"model": ["UM10", "BH04"], "whole_body_W_per_kg": [10.76, 6.0], "speed_m_per_s": [None, None]})
    assert quality_text(results_rows_flags(rows)) == "metabolic_rate(UM10)"


def test_negative_group_rates_and_the_metabolic_flags_of_a_table():
    assert negative_group_flag("UM10", {"PF": 20.0, "KE": 0.0}) is None
    f = negative_group_flag("UM10", {"PF": 20.0, "HAD": -0.4, "KF": -2.5})
    assert list(f.items) == ["KF", "HAD"] and "KF -2.5 %" in f.message and f.model == "UM10"
    groups = pd.DataFrame({"model": ["UM10", "BH04"], "share_PF_pct": [30.0, 40.0], "share_KF_pct": [-1.0, 5.0],
                           "share_other_pct": [-3.0, 0.0], "swing_energy_share_with_basal_pct": [-1.0, 1.0]})
    flags = metabolic_flags({"UM10": 4.0, "BH04": 12.0}, 1.25, groups)
    # BH04 above the band; UM10's KF negative (share_other and the basal-weighted phase share are not groups)
    assert [(f.code, f.model, list(f.items)) for f in flags] == [
        ("metabolic_rate", "BH04", ["BH04"]), ("negative_group_rate", "UM10", ["KF"])]
    assert quality_text(flags) == "metabolic_rate(BH04); negative_group_rate(KF)"
    assert quality_text([]) == "ok"


def test_flags_round_trip_through_the_record_and_strict():
    flags = [Flag("passive_force", "m", {"tfl_l": 1.98, "rect_fem_l": 1.77}, 0.5)]
    rec = SolveRecord.from_dict({"status": "Solve_Succeeded", "success": True,
                                 "plausibility": [f.to_dict() for f in flags]})
    back = SolveRecord.from_dict(json.loads(json.dumps(rec.to_dict())))
    assert back.plausibility == rec.plausibility and back.flags == flags and back.to_dict() == rec.to_dict()
    assert "plausibility" not in back.extra
    assert SolveRecord.from_dict({"status": "x"}).flags == []
    with pytest.warns(PlausibilityWarning, match=r"^DIR/l: m$"):
        warn_flags(flags, "DIR/l")
    check_strict([], "solve")
    with pytest.raises(ImplausibleResultError, match=r"solve --strict: implausible .*passive_force\(tfl_l rect_fem_l\)"
                       r".* in OUT"):
        check_strict(flags, "solve --strict", written="OUT")


def test_one_legs_rate_flags_and_their_file(tmp_path):
    from types import SimpleNamespace

    from musclemetab.metabolics.plausibility import PLAUSIBILITY_FILE, legs_rate_flags, write_plausibility

    # one leg: its doubled whole-body rate as the metabolics wrote it; 10.8 W/kg at 1.25 m/s is above 2 x 4.10
    leg = SimpleNamespace(models=("UM10", "BH04"), whole_body={"UM10": SimpleNamespace(mean_W_per_kg=10.8),
                                                               "BH04": SimpleNamespace(mean_W_per_kg=5.0)})
    flags = legs_rate_flags({"r": leg}, 1.25)
    assert [(f.code, f.model) for f in flags] == [("metabolic_rate", "UM10")]
    # without a speed: above the speed-free bound, 7.34 W/kg, as well
    assert [(f.code, f.threshold) for f in legs_rate_flags({"r": leg}, None)] == [("metabolic_rate",
                                                                                    SPEED_FREE_UPPER_W_PER_KG)]
    path = write_plausibility(flags, tmp_path)
    assert path.name == PLAUSIBILITY_FILE and [Flag.from_dict(d) for d in json.loads(path.read_text())] == flags


@pytest.mark.slow
def test_the_example_study_raises_no_flag(demo):
    """The example subject at three speeds, EFFORT-GEN and EFFORT-TEN, six models: no flag. The
    closest is LW07's slow EFFORT-GEN rate, 5.48 W/kg against the band's top at 0.77 m/s,
    2 x 2.80 = 5.61 W/kg (docs/quality.md); the solves' largest passive force is 0.3 F0."""
    out, table = demo
    assert (table["quality"] == "ok").all(), table["quality"].unique()
    top = 2 * ralston_gross_rate_W_per_kg(table["speed_m_per_s"].to_numpy())
    assert (table["whole_body_W_per_kg"] < top).all() and (table["whole_body_W_per_kg"] > top / 4).all()
    for d in set(table["unit_dir"]):
        summary = json.loads((out / d / "summary.json").read_text())
        assert summary["plausibility"] == [] and len(summary["peak_moment_by_dof_Nm"]) == len(summary["dofs"])


@pytest.mark.opensim
def test_analyse_prints_records_and_enforces_the_flags(example, tmp_path, capsys):
    """``analyse`` on a two-muscle solution folder (``tests/test_analysis.py``) whose summary.json
    records a passive-force flag, at 2.0 m/s: Ralston's rate there is (29 + 0.0053 x 120^2) x
    4.184/60 = 7.344 W/kg, the band's floor 3.672 W/kg, above the two muscles' whole-body rate,
    which is flagged for every model; the cycle, 0.15 s, is no gait cycle's (walking's last
    0.8-2.0 s), which every row says too. One warning line per flag, ``plausibility.json``, the
    ``quality`` column; ``--strict``: exit status 1 after the files are written."""
    from test_analysis import _solution_folder

    from musclemetab.commands import main

    folder = _solution_folder(tmp_path / "sol")
    summary = json.loads((folder / "summary.json").read_text())
    solve_flag = Flag("passive_force", "passive fiber force above 0.5 F0 (peak, in F0): soleus_r 0.61", {"soleus_r": 0.61},
                      0.5)
    (folder / "summary.json").write_text(json.dumps({**summary, "plausibility": [solve_flag.to_dict()]}))
    base = ["analyse", "--solution", str(folder), "--model", str(example.model), "--ik", str(example.ik["normal"]),
            "--cycle", "0.62,0.70,0.77", "--mass", "72.6", "--height", "1.743", "--models", "UM10,BH04",
            "--speed", "2.0"]
    out = tmp_path / "an"
    assert main([*base, "--out", str(out)]) == 0
    printed = capsys.readouterr().err.splitlines()
    err = [line for line in printed
           if line.startswith((f"musclemetab: warning: {folder}", f"musclemetab: warning: {out}"))]
    wb = pd.read_csv(out / "whole_body.csv").set_index("model")
    floor = 0.5 * (29 + 0.0053 * 120.0**2) * 4.184 / 60
    assert floor == pytest.approx(3.672, abs=1e-3) and (wb["whole_body_W_per_kg"] < floor).all()
    # the solve's flag, which solve warned of, is counted in a note, not repeated
    assert not any(e.startswith(f"musclemetab: warning: {folder}") for e in err)
    assert f"musclemetab: note: the solve's 1 plausibility flag ({folder}: summary.json) not repeated; " \
           "--show-solve-flags repeats them" in printed
    rates = [e for e in err if "below the band" in e]
    assert [e.split(": ")[3] for e in rates] == ["UM10", "BH04"]
    cycle = [e for e in err if "not shown to be one gait cycle" in e]
    # the same message for both rows: Python's warnings print it once
    assert len(cycle) == 1 and "0.62-0.77 s" in cycle[0] and "duration 0.15 s" in cycle[0]
    recorded = [Flag.from_dict(d) for d in json.loads((out / "plausibility.json").read_text())]
    assert recorded[0] == solve_flag and [(f.code, f.model) for f in recorded[1:]] == [
        ("metabolic_rate", "UM10"), ("not_a_gait_cycle", None), ("metabolic_rate", "BH04"), ("not_a_gait_cycle", None)]
    results = pd.read_csv(out / "results.csv").set_index("model")
    assert results.loc["UM10", "quality"] == "passive_force(soleus_r); metabolic_rate(UM10); not_a_gait_cycle(0.62-0.77 s)"
    assert main([*base, "--strict", "--show-solve-flags", "--out", str(tmp_path / "strict")]) == 1
    printed = capsys.readouterr().err.strip().splitlines()
    assert printed.count(f"musclemetab: warning: {folder}: {solve_flag.message}") == 1
    last = printed[-1]
    assert last.startswith("musclemetab: error: analyse --strict: implausible result refused (strict): passive_force(")
    assert (tmp_path / "strict" / "plausibility.json").is_file()
    # at a speed whose band holds the rates, the solve's flag alone
    assert main([*base[:-1], "0.8", "--out", str(tmp_path / "slow")]) == 0
    assert pd.read_csv(tmp_path / "slow" / "results.csv")["quality"].tolist() == [
        "passive_force(soleus_r); not_a_gait_cycle(0.62-0.77 s)"] * 2


def test_estimate_prints_the_flags_of_its_solutions(monkeypatch, tmp_path, capsys):
    """``estimate`` prints one warning line per flag of each trial's solution (as recorded in its
    summary.json), and of a validation re-solve's folder; ``--strict`` fails after the output."""
    from types import SimpleNamespace

    import musclemetab.redundancy.estimate_run as run_module
    from musclemetab.commands import main
    from musclemetab.redundancy.record import SolveRecord

    flag = Flag("saturated_activation", "1 muscle at activation >= 0.95 ...: soleus_r 20%", {"soleus_r": 0.2}, 0.1)
    other = Flag("reserve", "reserve above 5% ...: knee_angle_r", {"knee_angle_r": 0.07}, 0.05)
    record = SolveRecord.from_dict({"status": "Solve_Succeeded", "success": True, "plausibility": [flag.to_dict()]})
    clean = SolveRecord.from_dict({"status": "Solve_Succeeded", "success": True, "plausibility": []})
    (tmp_path / "out" / "validation" / "fast").mkdir(parents=True)
    (tmp_path / "out" / "validation" / "fast" / "summary.json").write_text(
        json.dumps({"plausibility": [other.to_dict()]}))
    result = SimpleNamespace(factors={"tendon_stiffness": {"soleus_r": 0.5}}, emg_scale={}, labels=("slow", "fast"),
                             run_record=SimpleNamespace(status="Solve_Succeeded", iterations=12), document={},
                             solutions={"slow": SimpleNamespace(record=record), "fast": SimpleNamespace(record=clean)})
    monkeypatch.setattr(run_module, "estimate_files", lambda *a, **k: result)
    argv = ["estimate", "--model", "m.osim", "--ik", "a.mot", "b.mot", "--id", "a.sto", "b.sto", "--ultrasound",
            "a.mot", "b.mot", "--estimate", "tendon_stiffness=soleus_r", "--validate", "--out", str(tmp_path / "out")]
    assert main(argv) == 0
    err = [e for e in capsys.readouterr().err.splitlines() if e.startswith("musclemetab: warning:")]
    assert err == [f"musclemetab: warning: {tmp_path / 'out' / 'slow'}: {flag.message}",
                   f"musclemetab: warning: {tmp_path / 'out' / 'validation' / 'fast'}: {other.message}"]
    assert main([*argv, "--strict"]) == 1
    assert "estimate --strict: implausible result refused (strict): saturated_activation(soleus_r); reserve(" \
        in capsys.readouterr().err
