"""A solve over an explicit ``--window`` through ``analyse``: the cycle the analysis names is the
one the solve recorded (its window less the padding at each end), the rates are averaged over the
cycle the row names, and the row says when that is not one gait cycle and which muscles the
solve left out (columns ``gait_cycle`` and ``excluded_muscles``, their flags in ``quality``)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from musclemetab.commands import main

pytestmark = pytest.mark.opensim

#: a window no other test solves, holding the normal trial's toe-off (about 1.28 s)
WINDOW = (1.1, 1.45)


@pytest.fixture(scope="module")
def window_solve(example, tmp_path_factory):
    """``solve --window 1.1:1.45 --exclude-muscles psoas_r`` of the example's normal trial."""
    out = tmp_path_factory.mktemp("window") / "s"
    assert main(["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
                 str(example.id["normal"]), "--window", f"{WINDOW[0]}:{WINDOW[1]}", "--exclude-muscles", "psoas_r",
                 "--no-progress", "--out", str(out)]) == 0
    return out


def _mean_over(folder, example, start_s, end_s, end_included):
    """Each model's whole-body rate (W/kg) averaged over the solved nodes from ``start_s`` to
    ``end_s`` (the end node included or not), worked here from the per-node rates of those nodes
    (evaluated from the first of them: BH04's activation heat decays from there): trapezoids over
    the nodes, over their span."""
    from musclemetab.redundancy import Solution
    from musclemetab.metabolics.solution import metabolics_from_solution

    t = Solution.load(folder).time_s
    keep = np.flatnonzero((t >= start_s - 1e-9) & ((t <= end_s + 1e-9) if end_included else (t < end_s - 1e-9)))
    nodes = metabolics_from_solution(folder, example.body_mass_kg, example.height_m,
                                     trim=(int(keep[0]), t.size - 1 - int(keep[-1])))
    tk = nodes.time_s
    assert tk.tolist() == t[keep].tolist()
    return {m: float(np.sum(0.5 * (wb.rate_W_per_kg[1:] + wb.rate_W_per_kg[:-1]) * np.diff(tk)) / (tk[-1] - tk[0]))
            for m, wb in nodes.whole_body.items()}


def _analyse(window_solve, example, out, *extra):
    assert main(["analyse", "--solution", str(window_solve), "--mass", str(example.body_mass_kg), "--height",
                 str(example.height_m), "--out", str(out), *extra]) == 0
    return pd.read_csv(out / "results.csv").set_index("model")


def test_analyse_of_a_window_solve_takes_the_solved_window_and_averages_over_its_cycle(window_solve, example,
                                                                                       tmp_path):
    """Without ``--cycle``: the cycle is the solved window less 0.05 s at each end, 1.15-1.40 s
    (it used to be taken from the whole IK file, 0.62-1.70 s, which the window does not cover:
    an error); each row's rate is the mean over that cycle's nodes (up to, not including, its end:
    the study's rule, the last instant being the first again), worked from the per-node rates;
    the row says the span is not one gait cycle and names the excluded muscle."""
    rows = _analyse(window_solve, example, tmp_path / "a")
    assert rows["cycle_start_s"].tolist() == pytest.approx([WINDOW[0] + 0.05] * len(rows), abs=1e-9)
    assert rows["cycle_end_s"].tolist() == pytest.approx([WINDOW[1] - 0.05] * len(rows), abs=1e-9)
    want = _mean_over(window_solve, example, WINDOW[0] + 0.05, WINDOW[1] - 0.05, end_included=False)
    for model, rate in want.items():
        assert rows.loc[model, "whole_body_W_per_kg"] == pytest.approx(rate, rel=1e-9), model
    assert not rows["gait_cycle"].any() and (rows["excluded_muscles"] == "psoas_r").all()
    for quality in rows["quality"]:
        assert "not_a_gait_cycle(1.15-1.4 s)" in quality and "excluded_muscles(psoas_r)" in quality
    codes = [f["code"] for f in json.loads((tmp_path / "a" / "plausibility.json").read_text())]
    assert codes.count("not_a_gait_cycle") == len(rows) and codes.count("excluded_muscles") == len(rows)


def test_a_cycle_given_to_analyse_is_the_one_the_rates_are_averaged_over(window_solve, example, tmp_path):
    """``--cycle 1.2,1.28,1.4``: the rates are the means over that cycle's nodes (ends included,
    as for a cycle a solve recorded), not over the solved window's; the row names that cycle."""
    rows = _analyse(window_solve, example, tmp_path / "a", "--cycle", "1.2,1.28,1.4")
    assert (rows["cycle_start_s"] == 1.2).all() and (rows["cycle_end_s"] == 1.4).all()
    want = _mean_over(window_solve, example, 1.2, 1.4, end_included=True)
    window = _mean_over(window_solve, example, WINDOW[0] + 0.05, WINDOW[1] - 0.05, end_included=False)
    for model, rate in want.items():
        assert rows.loc[model, "whole_body_W_per_kg"] == pytest.approx(rate, rel=1e-9), model
        assert abs(rate - window[model]) > 1e-3 * rate  # the two spans give rates apart
    assert rows["duration_s"].tolist() == pytest.approx([0.2] * len(rows), abs=1e-9)


def test_the_legs_added_keep_the_excluded_muscles_and_the_cycle_check():
    """``add_leg_rows``: the excluded muscles of both legs named once each; the rows are over a
    gait cycle only when both legs' are."""
    from musclemetab.study.runner import add_leg_rows

    def leg(excluded, cycle):
        return pd.DataFrame({"model": ["UM10"], "whole_body_W_per_kg": [4.0], "duration_s": [1.1],
                             "large_reserve": [False], "excluded_muscles": [excluded], "gait_cycle": [cycle],
                             "unit_dir": ["u/r"]})

    both = add_leg_rows({"r": leg("tfl_r psoas_r", True), "l": leg("tfl_l", False)})
    assert both["excluded_muscles"].tolist() == ["tfl_r psoas_r tfl_l"] and both["gait_cycle"].tolist() == [False]


def test_a_study_trial_window_gives_the_numbers_of_solve_window_and_analyse(window_solve, example, tmp_path):
    """A study trial with ``window = "1.1:1.45"`` (the subject excluding psoas_r) is the solve of
    ``solve --window 1.1:1.45``, the same problem (its result comes from the same solve): the same
    objective, and the rows of ``analyse`` of that solve, with the cycle in the window, its flags
    and the rates over it; a trial naming ``start_s``, ``toe_off_s`` and ``end_s`` inside the
    window has the rows of ``analyse --cycle`` with those times."""
    from musclemetab.study import run_study, study_from_dict

    files = {"ik": str(example.ik["normal"]), "id": str(example.id["normal"])}
    study = study_from_dict({
        "workflows": ["effort-gen"],
        "subjects": [{"name": "sub1", "model": str(example.model), "body_mass_kg": example.body_mass_kg,
                      "height_m": example.height_m, "exclude_muscles": ["psoas_r"],
                      "trials": [{"name": "window", **files, "window": f"{WINDOW[0]}:{WINDOW[1]}"},
                                 {"name": "named", **files, "window": list(WINDOW), "start_s": 1.2, "toe_off_s": 1.28,
                                  "end_s": 1.4}]}]}, base="/", output=tmp_path / "study")
    run = run_study(study, workers=1, progress=False)
    assert not run.failed, run.failed
    rows = pd.read_csv(tmp_path / "study" / "results.csv").set_index("model")
    columns = ["whole_body_W_per_kg", "speed_m_per_s", "cycle_start_s", "toe_off_s", "cycle_end_s", "duration_s",
               "swing_energy_share_pct", "share_PF_pct", "gait_cycle", "excluded_muscles", "quality"]
    for trial, extra, source in (("window", (), "estimated from the solved window and the ankle moment (no ground "
                                               "reaction forces)"),
                                 ("named", ("--cycle", "1.2,1.28,1.4"), "study file")):
        unit = tmp_path / "study" / "units" / "sub1" / trial / "effort-gen"
        assert json.loads((unit / "summary.json").read_text())["objective"] == \
            json.loads((window_solve / "summary.json").read_text())["objective"]
        got = rows[rows["trial"] == trial].sort_index()
        want = _analyse(window_solve, example, tmp_path / trial, *extra).sort_index()
        pd.testing.assert_frame_equal(got[columns], want[columns], rtol=1e-9)
        assert (got["cycle_source"] == source).all()
        assert not got["gait_cycle"].any() and got["quality"].str.contains("not_a_gait_cycle").all()


def test_analyse_of_a_window_without_toe_off_names_the_options_that_give_the_cycle(example):
    """A solve over 0.57-1.00 s of the normal trial (mid-stance: the plantarflexion moment still
    rising at 0.95 s): ``analyse`` cannot place toe-off in the window less its padding, and says
    what to give on the command line (the Python remedy, ``GaitCycle.from_times``, is not its)."""
    from types import SimpleNamespace

    from musclemetab.analysis.unit import RecordedTrial
    from musclemetab.commands.analyse import _cycle
    from musclemetab.errors import DataMismatchError

    recorded = RecordedTrial(str(example.model), str(example.ik["normal"]), str(example.id["normal"]), "r", None,
                             None, None, (0.57, 1.0), "--window")
    args = SimpleNamespace(cycle=None, grf=None, id=None, model=None)
    with pytest.raises(DataMismatchError) as info:
        _cycle(args, "r", example.ik["normal"], recorded)
    assert str(info.value).endswith("toe-off cannot be placed: give the cycle's events inside the solved 0.57-1 s "
                                    "(--cycle START,TOE_OFF,END) or the ground forces (--grf GRF.mot)"), info.value
