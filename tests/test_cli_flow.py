"""The command line goes as far as a study does, and says what it is doing while it runs.

* ``solve`` -> ``metabolics`` -> ``analyse`` -> ``report`` on gait2392's subject (both legs,
  the cycle found from the ground forces, inverse dynamics computed by OpenSim) asks for nothing
  the solution records and gives every number the two-subject study gives for that subject (the
  session's ``two_subjects``, run by ``musclemetab run --report``; the solve memo makes the
  command line's solves the study's), the report's tables included;
* ``musclemetab run`` prints no Python source line and no file of the package's cache;
* ``metabolics`` after ``solve`` says each of the solve's plausibility flags once (the solve
  said them; ``--show-solve-flags`` says them again), and ``-q`` prints nothing but errors;
* a running solve prints progress lines from IPOPT's iteration callback, throttled, also when
  its legs are solved in two processes (each line labelled with its leg);
* the study's progress lines carry an estimate of the time left.
"""

from __future__ import annotations

import io
import json
import re
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from musclemetab.commands import main

RTOL = 1e-9
#: before any OpenSim worker of this test process ran
_STARTED = time.time()
#: the study's per-leg tables are read back from CSV files written with 10 significant digits
#: before the legs are added; the command line adds the legs before writing
CSV_RTOL = 2e-9


def _compare(got: pd.DataFrame, want: pd.DataFrame, keys: list[str], what: str, rtol: float = RTOL) -> int:
    """Every column the two tables share, row by row in the order of ``keys`` (numbers within
    ``rtol``, or within ``rtol`` of the column's largest magnitude; text equal); returns the
    number of finite numbers compared."""
    got = got.sort_values(keys, kind="stable", ignore_index=True)
    want = want.sort_values(keys, kind="stable", ignore_index=True)
    assert len(got) == len(want), what
    n = 0
    for c in got.columns.intersection(want.columns):
        a, b = got[c], want[c]
        if pd.api.types.is_numeric_dtype(a) and pd.api.types.is_numeric_dtype(b) and a.dtype != bool:
            x, y = a.to_numpy(float), b.to_numpy(float)
            scale = float(np.nanmax(np.abs(y))) if np.isfinite(y).any() else 0.0
            # a value near zero within rtol of the column's largest (a group's rate of 6e-4 W among
            # rates of 150 W differs by 3e-11 W between the solution object and its folder)
            np.testing.assert_allclose(x, y, rtol=rtol, atol=rtol * scale, equal_nan=True, err_msg=f"{what}: {c}")
            n += int(np.isfinite(x).sum())
        else:
            assert a.astype(str).tolist() == b.astype(str).tolist(), f"{what}: {c}"
    return n


def _solve_argv(gait2392) -> list[str]:
    """``solve`` of gait2392's subject, both legs, the cycle found from the ground forces (no ``--out``)."""
    return ["solve", "--model", str(gait2392.model), "--ik", str(gait2392.ik), "--external-loads",
            str(gait2392.external_loads), "--side", "both", "--cycle", "auto"]


@pytest.fixture(scope="module")
def cli_flow(gait2392, tmp_path_factory):
    """solve (both legs, cycle auto), metabolics (UM10, BH04; mass; height 1.8 m as in the study
    file), analyse with nothing but the two folders. What solve and metabolics printed on
    standard error is in ``solve.err`` and ``metabolics.err`` beside the folders."""
    from conftest import _captured_fds

    root = tmp_path_factory.mktemp("cli_flow")
    s, m, a = root / "S", root / "M", root / "A"
    with _captured_fds(root / "solve.out", root / "solve.err"):
        assert main([*_solve_argv(gait2392), "--out", str(s)]) == 0
    with _captured_fds(root / "metabolics.out", root / "metabolics.err"):
        assert main(["metabolics", "--solution", str(s), "--mass", str(gait2392.body_mass_kg), "--height", "1.8",
                     "--models", "UM10,BH04", "--out", str(m)]) == 0
    return s, m, a


def _flag_lines(s: Path) -> list[str]:
    """The warning line of each plausibility flag the solve of ``s`` recorded (both legs)."""
    return [f"musclemetab: warning: {s / side}: {' '.join(f['message'].split())}"
            for side in "rl" for f in json.loads((s / side / "summary.json").read_text())["plausibility"]]


@pytest.mark.opensim
def test_metabolics_after_solve_says_each_solve_flag_once(cli_flow, gait2392, tmp_path):
    """The solve of gait2392's subject records nine plausibility flags (weak hamstrings, large
    reserves...) and warns of each; ``metabolics`` of its folder used to warn of all nine again.
    Now each is said once over the two commands, ``metabolics`` counts them in one note and
    still lists them in its ``plausibility.json``; ``--show-solve-flags`` says them again, once each."""
    s, m, _ = cli_flow
    solve_err = (s.parent / "solve.err").read_text().splitlines()
    metabolics_err = (s.parent / "metabolics.err").read_text().splitlines()
    flags = _flag_lines(s)
    assert len(flags) == 9
    for line in flags:
        assert solve_err.count(line) == 1 and line not in metabolics_err, line
    assert "musclemetab: note: the solve's 9 plausibility flags" in "\n".join(metabolics_err)
    recorded = json.loads((m / "plausibility.json").read_text())
    assert [f["message"] for f in recorded if f["code"] != "metabolic_rate"] == [
        f["message"] for side in "rl" for f in json.loads((s / side / "summary.json").read_text())["plausibility"]]
    from conftest import _captured_fds

    with _captured_fds(tmp_path / "out.txt", tmp_path / "err.txt"):
        assert main(["metabolics", "--solution", str(s), "--mass", str(gait2392.body_mass_kg), "--height", "1.8",
                     "--models", "UM10", "--show-solve-flags", "--out", str(tmp_path / "M")]) == 0
    again = (tmp_path / "err.txt").read_text().splitlines()
    assert [again.count(line) for line in flags] == [1] * 9


@pytest.mark.opensim
def test_quiet_prints_nothing_but_errors(cli_flow, gait2392, tmp_path, capfd):
    """``-q`` before or after the command's name: the solve (the solve memo's stored result, whose
    warnings are raised again; the same solve without ``-q`` printed them, a summary and progress)
    writes its folders and prints nothing; an error is still its one line."""
    s, _, _ = cli_flow
    assert "musclemetab: warning: " in (s.parent / "solve.err").read_text()
    assert (s.parent / "solve.out").read_text().startswith("diagnosis:")
    assert main(["-q", *_solve_argv(gait2392), "--out", str(tmp_path / "S")]) == 0
    assert capfd.readouterr() == ("", "")
    assert (tmp_path / "S" / "l" / "summary.json").is_file()
    (tmp_path / "file").write_text("")
    assert main([*_solve_argv(gait2392), "--quiet", "--out", str(tmp_path / "file")]) == 1
    out, err = capfd.readouterr()
    assert out == "" and err.count("\n") == 1 and err.startswith("musclemetab: error: ") and "file" in err


def test_sensitivity_of_a_solve_that_has_none_is_refused_before_anything_is_written(cli_flow, tmp_path, capsys):
    """``metabolics --sensitivity`` of an EMG-TEN solve (here the right leg's folder relabelled so):
    refused in one line before the metabolic rates are written (they were written, and the success
    printed, before the error)."""
    import shutil

    s, _, _ = cli_flow
    emg = tmp_path / "emg"
    shutil.copytree(s / "r", emg)
    summary = json.loads((emg / "summary.json").read_text())
    summary["workflow"] = {**summary["workflow"], "name": "emg-ten"}
    (emg / "summary.json").write_text(json.dumps(summary))
    assert main(["metabolics", "--solution", str(emg), "--mass", "72.6", "--height", "1.8", "--sensitivity",
                 "--out", str(tmp_path / "M")]) == 1
    out, err = capsys.readouterr()
    assert out == "" and err == (f"musclemetab: error: --sensitivity: {emg}: the sensitivities are computed for the "
                                 "effort workflows (effort-gen, -cal, -ten); this solve (emg-ten) has EMG or energy "
                                 "goals; drop --sensitivity\n")
    assert not (tmp_path / "M").exists()


@pytest.mark.opensim
def test_a_mass_far_from_the_models_is_said(cli_flow, gait2392, tmp_path):
    """gait2392's scaled model weighs 72.6 kg: ``metabolics --mass 60`` (17 % less) is computed as
    asked, with one warning naming both masses; 70 kg (3.6 % less) passes unsaid."""
    from conftest import _captured_fds

    s, _, _ = cli_flow
    for mass, said in ((60, "--mass 60 kg differs from the mass of the model "), (70, None)):
        err = tmp_path / f"{mass}.err"
        with _captured_fds(tmp_path / f"{mass}.out", err):
            assert main(["metabolics", "--solution", str(s), "--mass", str(mass), "--height", "1.8", "--models", "UM10",
                         "--out", str(tmp_path / f"M{mass}")]) == 0
        lines = [ln for ln in err.read_text().splitlines() if "differs from the mass of the model" in ln]
        if said is None:
            assert lines == []
        else:
            assert len(lines) == 1 and said in lines[0] and "(72.6 kg) by 17 %" in lines[0], lines


@pytest.mark.opensim
def test_analyse_and_report_refuse_rates_of_another_solution(cli_flow, tmp_path, capsys):
    """``metabolics`` records the SHA-256 of the ``solution.sto`` its rates are of; ``analyse``
    refuses a metabolics folder of another solution (here each leg's folder given the other
    leg's solution, as after ``solve --side l --out S`` into the folder ``metabolics`` read with
    ``--side r``), and so does ``export --mat``; ``report`` refuses an analysed folder whose
    solution was solved again since: the tables and figures would mix two solutions. The matching
    pair is analysed as before."""
    import shutil

    s, m, _ = cli_flow
    swapped = tmp_path / "swapped"
    for a, b in (("r", "l"), ("l", "r")):
        shutil.copytree(s / a, swapped / b)
    assert main(["analyse", "--solution", str(swapped), "--metabolics", str(m), "--out", str(tmp_path / "A1")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(
        f"musclemetab: error: {m / 'r'}: its rates are of another solution than {swapped / 'r'}'s (solved again since "
        f"'musclemetab metabolics' wrote it, or another trial or leg); run 'musclemetab metabolics --solution "
        f"{swapped / 'r'} --out {m / 'r'}' again"), err
    assert not (tmp_path / "A1").exists()
    assert main(["export", "--mat", str(tmp_path / "x.mat"), str(swapped), "--metabolics", str(m)]) == 1
    assert f"{m / 'r'}: its rates are of another solution" in capsys.readouterr().err
    assert not (tmp_path / "x.mat").exists()
    same = tmp_path / "same"
    shutil.copytree(s, same)
    assert main(["analyse", "--solution", str(same), "--metabolics", str(m), "--out", str(tmp_path / "A2")]) == 0
    shutil.copyfile(s / "l" / "solution.sto", same / "r" / "solution.sto")  # the right leg solved again
    capsys.readouterr()
    assert main(["report", str(tmp_path / "A2")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{tmp_path / 'A2'}: analysed from {same / 'r'}, which has been solved again" in err


@pytest.mark.slow
@pytest.mark.opensim
def test_solve_metabolics_analyse_give_the_study_numbers(cli_flow, two_subjects, capsys):
    s, m, a = cli_flow
    study, _ = two_subjects
    capsys.readouterr()
    assert main(["analyse", "--solution", str(s), "--metabolics", str(m), "--out", str(a)]) == 0
    said = capsys.readouterr()
    # the DOFs 'solve' chose that belong to no muscle group are named, not a stop
    assert "left out of the group analysis: mtp_angle_r, subtalar_angle_r" in said.out
    assert "left out of the group analysis: mtp_angle_l, subtalar_angle_l" in said.out
    assert "no walking speed" in said.err  # a treadmill trial: no cost of transport, as in the study

    unit = study / "units" / "gait2392" / "walk1" / "effort-gen"
    n = 0
    for side in "rl":
        # the solutions: the study's unit solved the same problem
        got = pd.read_csv(s / side / "solution.sto", sep="\t", skiprows=_header_rows(s / side / "solution.sto"))
        want = pd.read_csv(unit / side / "solution.sto", sep="\t", skiprows=_header_rows(unit / side / "solution.sto"))
        n += _compare(got, want, ["time"], f"solution.sto {side}")
        rec = json.loads((s / side / "summary.json").read_text())
        assert rec["window"]["gait_cycle"] == json.loads((unit / side / "summary.json").read_text())["window"]["gait_cycle"]
        for name in ("whole_body.csv", "analysis.csv", "per_muscle.csv"):
            keys = ["model", "muscle"] if name == "per_muscle.csv" else ["model"]
            n += _compare(pd.read_csv(a / side / name), pd.read_csv(unit / side / name), keys, f"{side}/{name}")
        n += _compare(pd.read_csv(a / side / "timeseries.csv"), pd.read_csv(unit / side / "timeseries.csv"),
                      ["model", "series", "time_s"], f"{side}/timeseries.csv")
    # the study's results rows of the subject: the legs added the same way
    results = pd.read_csv(study / "results.csv")
    # (and less how the study started the unit's solve, `solve_start`: a command-line solve starts cold)
    assert set(results.loc[results["subject"] == "gait2392", "solve_start"]) == {"cold"}
    want = results[results["subject"] == "gait2392"].drop(columns=["subject", "trial", "workflow", "unit_dir",
                                                                   "solve_start"])
    got = pd.read_csv(a / "results.csv").drop(columns=["unit_dir"])
    # the columns of the study's results, less the costs of transport it has for the other subject
    # (no speed here: empty in the study's rows too)
    # (the `quality` column too: `analyse` judges plausibility as the study does)
    assert set(got.columns) <= set(want.columns)
    assert all(want[c].isna().all() for c in set(want.columns) - set(got.columns))
    n += _compare(got, want, ["model"], "results.csv", rtol=CSV_RTOL)
    per = pd.read_csv(study / "per_muscle.csv")
    per = per[per["subject"] == "gait2392"].drop(columns=["subject", "trial", "workflow"])
    n += _compare(pd.read_csv(a / "per_muscle.csv"), per, ["model", "side", "muscle"], "per_muscle.csv")
    # metabolics' whole body (the legs added) is the study's
    whole = pd.read_csv(m / "whole_body.csv").set_index("model")
    study_rows = results[results["subject"] == "gait2392"].set_index("model")
    np.testing.assert_allclose(whole["whole_body_W_per_kg"], study_rows.loc[whole.index, "whole_body_W_per_kg"],
                               rtol=CSV_RTOL)
    assert n > 10000  # every number of the tables, not a handful

    # report: the analyse folder (and through it S and M) gives the tables the study's report gives
    assert main(["report", str(a)]) == 0
    printed = capsys.readouterr().out
    drawn, planned = map(int, re.search(r"report: (\d+) of (\d+) figures", printed).groups())
    not_drawn = re.findall(r"^  not drawn: (\w+): ", printed, flags=re.M)
    # the figures of one trial at one speed: all but those that compare trials, speeds or measurements
    assert drawn == planned - len(not_drawn) and "rates_against_speed" in not_drawn and drawn >= 8
    # every text of every figure drawn inside the figure and clear of the others
    # (layout_check.figure_problems of each figure as saved; the Figure-2 plot: test_figure_layout.py)
    record = json.loads((a / "figures" / "report.json").read_text())
    checked = {e["name"]: e["layout_problems"] for e in record["entries"] if e["paths"] is not None}
    assert len(checked) == drawn and {n: p for n, p in checked.items() if p} == {}
    with capsys.disabled():
        print(f"\nlayout checked, one-trial command-line report: {', '.join(checked)}")
    # no speed known, one trial: the captions claim neither a preferred speed nor a speed shading
    captions = " ".join(e["caption"] for e in record["entries"])
    assert "preferred speed" not in captions and "light: slow" not in captions
    # both legs solved: the per-muscle ranking's "one leg" is the legs' mean, and says so
    ranked = next(e["caption"] for e in record["entries"] if e["name"] == "per_muscle_ranked")
    assert "one leg: the mean of the two legs of a subject solved on both" in ranked
    n_report = _report_tables_are_the_studys(a, study)
    assert n_report > 5000
    # a folder that is neither a study nor an analyse output: one line naming it and what to pass
    for folder, said in ((a / "r", f"{a / 'r'}: one leg of the analyse output folder {a}, whose analyse.json "
                          f"records both legs: pass {a}"),
                         (s, f"{s / 'results.csv'}: missing; {s} is neither a finished study folder nor an analyse "
                          "output folder. Run the study first ('musclemetab run STUDY.toml') and pass its output "
                          "folder (holding results.csv), or pass the output folders of 'musclemetab analyse --out'")):
        assert main(["report", str(folder)]) == 1
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and said in err
    assert main(["report", str(a), str(a)]) == 1  # several folders, one page: where?
    assert "give --out DIR" in capsys.readouterr().err
    # several analyse folders: one study of their trials (the same trial twice: named apart by folder)
    import shutil

    from musclemetab.report.cli_folder import read_report_input
    from musclemetab.report.page import page_tables

    again = shutil.copytree(a, a.parent / "A again", ignore=shutil.ignore_patterns("figures", "report.html"))
    both = read_report_input([a, again])
    assert list(both.ok["trial"].drop_duplicates()) == ["walk1", "walk1 (A again)"]
    assert both.settings["subjects"]["subject01"]["trials"] == list(both.ok["trial"].drop_duplicates())
    rows = page_tables(both)["results"]["whole_body"].body
    assert len(rows) == 4 and [r[1:] for r in rows[:2]] == [r[1:] for r in rows[2:]]


def _report_tables_are_the_studys(a: Path, study: Path) -> int:
    """The report of the analyse folder ``a`` against the study's report, gait2392's rows: the
    data the report is drawn from (results rows with the study's ``quality``, per-muscle rows,
    both legs' rates over the cycle, each muscle's rate, the cycles) number by number, then the
    tables on the two pages cell by cell (the study's trial ``walk1`` is the command line's
    ``walk1``, from the IK file's name ``subject01_walk1_ik``); returns the number of numbers compared."""
    from musclemetab.report.cli_folder import read_report_input
    from musclemetab.report.page import page_tables

    cli, st = read_report_input(a), read_report_input(study)
    labels = ["subject", "trial", "workflow"]
    assert cli.ok[labels].drop_duplicates().values.tolist() == [["subject01", "walk1", "effort-gen"]]
    assert cli.settings["name"] == "subject subject01, trial walk1"
    mine = st.ok[st.ok["subject"] == "gait2392"]
    # the results rows: every column of the study's, `quality` (the plausibility flags) included
    got = cli.ok.drop(columns=labels + ["unit_dir"])
    want = mine.drop(columns=labels + ["unit_dir"])
    assert set(got.columns) <= set(want.columns) and "quality" in got.columns
    n = _compare(got, want, ["model"], "report: results", rtol=CSV_RTOL)
    pm = st.read_per_muscle()
    n += _compare(cli.read_per_muscle().drop(columns=labels), pm[pm["subject"] == "gait2392"].drop(columns=labels),
                  ["model", "side", "muscle"], "report: per-muscle")
    row_c, row_s = cli.ok.iloc[0], mine.iloc[0]
    assert list(cli.leg_folders(row_c)) == list(st.leg_folders(row_s)) == ["r", "l"]
    for fc, fs in zip(cli.leg_folders(row_c).values(), st.leg_folders(row_s).values()):
        np.testing.assert_allclose(cli.unit_cycle(fc), st.unit_cycle(fs), rtol=RTOL)
        assert cli.summary(fc).iterations == st.summary(fs).iterations > 0
    # the other leg is interpolated at the first leg's instants, its phase worked from the
    # files' times (10 significant digits; the left leg's differ by 1e-9 s in the last digit):
    # where the rate changes by 5e3 W/s that is 5e-6 W of 1000 W
    n += _compare(cli.timeseries(row_c), st.timeseries(row_s), ["model", "series", "time_s"],
                  "report: both legs over the cycle", rtol=1e-8)
    rates_c, rates_s = cli.muscle_rates(row_c), st.muscle_rates(row_s)
    assert list(rates_c) == list(rates_s) == ["UM10", "BH04"]
    for m in rates_c:
        pd.testing.assert_frame_equal(rates_c[m], rates_s[m], rtol=RTOL)
        n += rates_c[m].size
    # the pages' tables: the study's rows of gait2392's trial, without the trial's or subject's name
    tc, ts = page_tables(cli), page_tables(st)
    page = _page_rows(a / "report.html")
    for name, label in (("whole_body", 0), ("phase_shares", 0), ("group_shares", 2)):
        got, want = tc["results"][name].body, _rows_of_trial(ts["results"][name].body, label, "walk1")
        assert [r[:label] + r[label + 1:] for r in got] == [r[:label] + r[label + 1:] for r in want], name
        assert all(r in page for r in got), name
        n += sum(len(r) - 3 for r in got)
    for name in ("runs", "flagged"):
        got, want = tc[name].body, [r for r in ts[name].body if r[0] == "gait2392"]
        order = sorted if name == "flagged" else list  # the rows' flags come in the results table's model order
        assert order(r[3:] for r in got) == order(r[3:] for r in want) and len(got) >= 2, name
        assert all(r in page for r in got), name
    return n


def _rows_of_trial(body: list, label: int, trial: str) -> list:
    """The rows of a results table of the page whose trial column (``label``) is ``trial``; the
    tables with the trial first name it on its first row only."""
    rows, current = [], None
    for r in body:
        current = r[label] if (r[label] or label) else current
        if current == trial:
            rows.append(r)
    return rows


def _page_rows(path: Path) -> list[list[str]]:
    """Every row of every table of an HTML page, as the text of its cells."""
    from html.parser import HTMLParser

    class Rows(HTMLParser):
        def __init__(self):
            super().__init__()
            self.rows, self.cell = [], None

        def handle_starttag(self, tag, attrs):
            if tag == "tr":
                self.rows.append([])
            elif tag in ("td", "th"):
                self.cell = ""

        def handle_endtag(self, tag):
            if tag in ("td", "th") and self.cell is not None:
                self.rows[-1].append(self.cell)
                self.cell = None

        def handle_data(self, data):
            if self.cell is not None:
                self.cell += data

    parser = Rows()
    parser.feed(path.read_text(encoding="utf-8"))
    return parser.rows


def _header_rows(path) -> int:
    with open(path, encoding="utf-8") as f:
        for i, line in enumerate(f):
            if line.strip() == "endheader":
                return i + 1
    raise AssertionError(f"{path}: no endheader")


@pytest.mark.slow
@pytest.mark.opensim
def test_run_prints_no_source_line_and_no_cache_file(two_subjects, two_subjects_stderr):
    """``musclemetab run`` with two worker processes: every warning is one line
    ``musclemetab: warning: ...``, said once per run however many workers met it (gait2392's
    legs run in two workers: each finds no walking speed over its own cycle, said once per leg),
    none from another library (a pandas deprecation); no line names a file of the package's code
    with a line number, nor a file of the package's cache (which the user never gave)."""
    import os

    import musclemetab

    _, stdout = two_subjects
    stderr = two_subjects_stderr
    text = stdout + stderr
    package = os.path.dirname(musclemetab.__file__)
    source_lines = [ln for ln in text.splitlines() if re.search(r"\.py:\d+", ln) or package in ln]
    assert source_lines == []
    warnings_said = [ln for ln in stderr.splitlines() if "warning" in ln.lower()]
    assert warnings_said and all(ln.startswith("musclemetab: warning: ") for ln in warnings_said)
    assert len(warnings_said) == len(set(warnings_said))
    for leg in ("right", "left"):  # each leg's speed over its own cycle: said once for each
        assert len([ln for ln in warnings_said if f"gait2392/walk1 ({leg} leg): no walking speed" in ln]) == 1
    assert [ln for ln in warnings_said if re.match(r"musclemetab: warning: \w+Warning: ", ln)] == []
    # gait2392's knee reserve is large: said, naming the trial's files, not the cached inverse dynamics
    reserve = [ln for ln in warnings_said if "the reserve about knee_angle" in ln]
    assert reserve and all("subject01_walk1_grf.xml" in ln for ln in reserve)
    cache = os.environ["MUSCLEMETAB_CACHE"]
    assert cache not in text
    # the study's progress: one line per unit (not a terminal), the time left once a unit has run
    progress = [ln for ln in stderr.splitlines() if re.match(r"\[[#.]+\] \d+/3 units", ln)]
    assert len(progress) == 3 and "left |" in progress[0] and "left" not in progress[-1]
    # OpenSim computed gait2392's inverse dynamics in the worker started from this folder, and
    # wrote no log file there
    log = Path.cwd() / "opensim.log"
    assert not log.exists() or log.stat().st_mtime < _STARTED


def test_progress_lines_throttled_by_the_clock():
    """:class:`ProgressLines` with a clock worked by hand: a solve of 12 s, one iterate a second
    (IPOPT's first call back is the starting point, iteration 0), lines at most every 5 s: at
    5 s and at 10 s, i.e. at least one line before a solve of more than 10 s ends."""
    from musclemetab.redundancy.ipopt import PROGRESS_INTERVAL_S, ProgressLines

    assert PROGRESS_INTERVAL_S == 5.0
    now = [100.0]
    stream = io.StringIO()
    lines = ProgressLines(lbg=[0.0, -1.0], ubg=[0.0, 1.0], interval_s=PROGRESS_INTERVAL_S, stream=stream,
                          clock=lambda: now[0])
    for k in range(13):  # iterates at 0, 1, ..., 12 s
        now[0] = 100.0 + k
        lines.iteration(f=10.0 / (k + 1), g=[1e-3 / (k + 1), 2.0])  # second constraint 1.0 above its bound
    printed = stream.getvalue().splitlines()
    assert printed == [
        "musclemetab: solving: iteration 5, objective 1.6667e+00, constraint violation 1.0e+00, 5 s",
        "musclemetab: solving: iteration 10, objective 9.0909e-01, constraint violation 1.0e+00, 10 s",
    ]


@pytest.mark.opensim
def test_solve_prints_progress_while_ipopt_runs(example, tmp_path, capsys, monkeypatch):
    """``musclemetab solve`` of a short window (a problem no other test solves, so IPOPT runs)
    with the throttle at 0 s: a line for every iterate, the last of them before the final
    iteration IPOPT reports; no callback outside the command (``--no-progress``, a Python session)."""
    import musclemetab.redundancy.ipopt as ipopt
    import musclemetab.redundancy.progress as progress

    monkeypatch.setattr(progress, "PROGRESS_INTERVAL_S", 0.0)
    out = tmp_path / "s"
    argv = ["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
            str(example.id["normal"]), "--window", "0.6:0.81", "--out", str(out)]
    assert main(argv) == 0
    err = capsys.readouterr().err
    iterations = [int(x) for x in re.findall(r"^musclemetab: solving: iteration (\d+), objective \S+, "
                                             r"constraint violation \S+, \d+ s$", err, flags=re.M)]
    total = json.loads((out / "summary.json").read_text())["iterations"]
    assert iterations[:3] == [0, 1, 2] and iterations[-1] == total
    assert len(iterations) == total + 1
    assert ipopt._progress_callback(1, 1, [0.0], [0.0]) is None  # switched off after the command


@pytest.mark.opensim
def test_solve_both_legs_in_two_processes_prints_each_legs_progress(example, tmp_path, capfd, monkeypatch):
    """``solve --side both --workers 2`` of a short window (0.6-0.88 s, a problem no other test
    solves, so IPOPT runs in each leg's pool process) with the throttle at 0 s: each leg's
    process prints a line for every iterate, labelled with the leg, on the command's standard
    error: the interval in force in the command reaches the legs' processes."""
    import musclemetab.redundancy.ipopt as ipopt
    import musclemetab.redundancy.progress as progress

    monkeypatch.setattr(progress, "PROGRESS_INTERVAL_S", 0.0)
    out = tmp_path / "s"
    assert main(["solve", "--model", str(example.model), "--ik", str(example.ik["normal"]), "--id",
                 str(example.id["normal"]), "--window", "0.6:0.88", "--side", "both",
                 "--workers", "2", "--out", str(out)]) == 0
    err = capfd.readouterr().err
    lines = re.findall(r"^musclemetab: solving side ([rl]): iteration (\d+), objective \S+, "
                       r"constraint violation \S+, \d+ s$", err, flags=re.M)
    total = {side: json.loads((out / side / "summary.json").read_text())["iterations"] for side in "rl"}
    for side in "rl":
        assert [int(i) for s, i in lines if s == side] == list(range(total[side] + 1)), err
    assert not re.search(r"^musclemetab: solving: ", err, flags=re.M)  # every line names its leg


def test_study_progress_time_left_and_interrupted_units():
    """The study's progress lines worked by hand: 4 units, 2 at once; the first run took 30 s
    (3 units left: 30 x 3 / 2 = 45 s), one found up to date (costs nothing: 2 left, 30 s), one
    stopped by Ctrl-C (labelled and counted interrupted, not failed), one failed (the last: no time left)."""
    from musclemetab.study.runner import _Progress

    stream = io.StringIO()
    bar = _Progress(4, True, stream, parallel=2)
    bar.update("s/a/effort-gen", {"status": "ok", "times": {"total_s": 30.0}}, ran=True)
    bar.update("s/b/effort-gen", {"status": "ok"})
    bar.update("s/c/effort-gen", {"status": "interrupted", "times": {"total_s": 2.0}}, ran=True)
    bar.update("s/d/effort-gen", {"status": "failed", "times": {"total_s": 1.0}}, ran=True)
    lines = [re.sub(r", \d+ s", ", T s", ln, count=1) for ln in stream.getvalue().splitlines()]
    assert lines == [
        "[######..................] 1/4 units, 0 failed, T s, about 45 s left | s/a/effort-gen ok",
        "[############............] 2/4 units, 0 failed, T s, about 30 s left | s/b/effort-gen ok",
        "[##################......] 3/4 units, 0 failed, 1 interrupted, T s, about 30 s left | s/c/effort-gen interrupted",
        "[########################] 4/4 units, 1 failed, 1 interrupted, T s | s/d/effort-gen FAILED",
    ]


def test_a_units_warnings_come_above_the_progress_bar_on_a_terminal():
    """On a terminal the bar is one line redrawn in place (a carriage return, no newline): a
    unit's warnings, said when the unit ends, first blank it, and the next update draws it below
    them; the warnings are raised in order, with their categories."""
    import warnings

    from musclemetab.errors import WindowWarning
    from musclemetab.study.runner import _Progress, _say_warnings

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    stream = Terminal()
    bar = _Progress(2, True, stream)
    bar.update("s/a/effort-gen", {"status": "ok"})
    drawn = stream.getvalue()
    assert drawn.startswith("\r[############............] 1/2 units") and not drawn.endswith("\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _say_warnings([(WindowWarning, "first"), (UserWarning, "second")], bar)
    assert [(w.category, str(w.message)) for w in caught] == [(WindowWarning, "first"), (UserWarning, "second")]
    assert stream.getvalue() == drawn + "\r" + " " * 160 + "\r"
    _say_warnings([], bar)  # no warning: the bar stays
    assert stream.getvalue() == drawn + "\r" + " " * 160 + "\r"


@pytest.mark.opensim
def test_export_refuses_a_metabolics_folder_without_rates_and_names_its_own_option(cli_flow, tmp_path, capsys):
    """``export --metabolics`` given a folder without ``metabolics.sto`` (the solution folder
    itself) is refused, not exported without rates; a ``.mat`` of the user in the way is refused
    naming ``--mat`` (export has no ``--out``)."""
    s, _, _ = cli_flow
    assert main(["export", "--mat", str(tmp_path / "x.mat"), str(s / "r"), "--metabolics", str(s / "r")]) == 1
    assert capsys.readouterr().err == (f"musclemetab: error: {s / 'r'}: no metabolics.sto (--metabolics); give the "
                                       f"folder written by 'musclemetab metabolics --solution {s / 'r'}'\n")
    (tmp_path / "afile").write_text("x")  # analyse's --out where a file is: the option's one line
    m = cli_flow[1]
    assert main(["analyse", "--solution", str(s), "--metabolics", str(m), "--out", str(tmp_path / "afile")]) == 1
    assert capsys.readouterr().err == (f"musclemetab: error: --out {tmp_path / 'afile'} is an existing file, not a "
                                       "folder; give the path of a folder\n")
    (tmp_path / "mine.mat").write_text("the user's")
    assert main(["export", "--mat", str(tmp_path / "mine.mat"), str(s / "r")]) == 1
    assert capsys.readouterr().err.endswith("it is not replaced: move the file away, or give another file name "
                                            "(--mat)\n")
    assert not (tmp_path / "x.mat").exists() and (tmp_path / "mine.mat").read_text() == "the user's"


def test_mat_files_of_metabolics_and_export_hold_the_folders_tables(cli_flow, gait2392, tmp_path):
    """``metabolics --mat`` (from the objects in memory) and ``export --mat`` (from the folders'
    files) of the solve of both legs, read back with :func:`scipy.io.loadmat`: every array equals
    the folders' own tables (``solution.sto`` read by the storage reader, ``metabolics.sto``,
    ``whole_body.csv``, ``per_muscle.csv``), time in rows and one column per muscle, each
    component of each model; the two files agree."""
    import scipy.io

    from musclemetab.io import read_storage

    s, m, _ = cli_flow
    a = tmp_path / "M" / "rates.mat"
    assert main(["-q", "metabolics", "--solution", str(s), "--mass", str(gait2392.body_mass_kg), "--height", "1.8",
                 "--models", "UM10,BH04", "--mat", str(a), "--out", str(tmp_path / "M")]) == 0
    b = tmp_path / "export.mat"
    assert main(["-q", "export", str(s), "--metabolics", str(m), "--mat", str(b)]) == 0
    for path in (a, b):
        got = scipy.io.loadmat(path, simplify_cells=True)
        assert got["format"] == "musclemetab mat 1" and list(got["legs"]) == ["r", "l"]
        whole = pd.read_csv(m / "whole_body.csv")
        assert list(got["whole_body"]["model"]) == whole["model"].tolist() == ["UM10", "BH04"]
        np.testing.assert_allclose(got["whole_body"]["whole_body_W_per_kg"], whole["whole_body_W_per_kg"], rtol=1e-9)
        for side in "rl":
            leg = got[side]
            sto = read_storage(s / side / "solution.sto")
            muscles = json.loads((s / side / "summary.json").read_text())["muscles"]
            assert list(leg["muscles"]) == muscles and leg["solve"]["side"] == side
            np.testing.assert_allclose(leg["time_s"], sto.index.to_numpy(), rtol=0, atol=1e-12)
            for key, column in (("activation", "activation"), ("excitation", "excitation"),
                                ("tendon_force_N", "tendon_force"), ("normalized_fiber_length", "normalized_fiber_length"),
                                ("normalized_fiber_velocity", "normalized_fiber_velocity")):
                want = sto[[f"/forceset/{mu}/{column}" for mu in muscles]].to_numpy()
                np.testing.assert_allclose(leg[key], want, rtol=1e-9, atol=1e-12, err_msg=f"{path.name} {side} {key}")
            lmo = leg["parameters"]["optimal_fiber_length_m"]
            np.testing.assert_allclose(leg["fiber_length_m"], leg["normalized_fiber_length"] * lmo, rtol=1e-12)
            rates = read_storage(m / side / "metabolics.sto")
            np.testing.assert_allclose(leg["metabolics"]["time_s"], rates.index.to_numpy(), atol=1e-12)
            for model in ("UM10", "BH04"):
                for comp in ("work", "activation_maintenance", "shortening_lengthening", "basal", "total_no_basal"):
                    want = rates[[f"{model}/{mu}/{comp}" for mu in muscles]].to_numpy()
                    np.testing.assert_allclose(leg["metabolics"][model][comp], want, rtol=1e-9, atol=1e-9,
                                               err_msg=f"{path.name} {side} {model} {comp}")
            per = pd.read_csv(m / side / "per_muscle.csv")
            np.testing.assert_allclose(leg["metabolics"]["per_muscle"]["muscle_W"], per["muscle_W"], rtol=1e-9)
            assert list(leg["metabolics"]["per_muscle"]["muscle"]) == per["muscle"].tolist()
            legs_csv = pd.read_csv(m / side / "leg_muscles.csv")
            np.testing.assert_allclose(leg["metabolics"]["leg_muscles"]["leg_muscles_W"], legs_csv["leg_muscles_W"],
                                       rtol=1e-9)


@pytest.mark.opensim
def test_printing_a_solution_or_its_rates_gives_a_short_summary(cli_flow):
    """``print(solution)`` and ``print(rates)`` in a new Python process: at most 20 lines each,
    no array, the muscles x nodes of ``solution.sto``, the solve's status, stop and flags, and
    each model's whole-body rate of the leg (``leg_muscles.csv``, W)."""
    import subprocess
    import sys

    s, m, _ = cli_flow
    code = ("from musclemetab.redundancy import Solution\n"
            "from musclemetab.metabolics.solution import metabolics_from_legs\n"
            f"print(Solution.load({str(s / 'r')!r}))\n"
            "print('--')\n"
            f"print(metabolics_from_legs({str(s)!r}, 72.6, 1.8, models='UM10,BH04')['r'])\n")
    r = subprocess.run([sys.executable, "-W", "ignore", "-c", code], capture_output=True, text=True, check=True)
    solution, rates = (part.strip().splitlines() for part in r.stdout.split("--\n"))
    summary = json.loads((s / "r" / "summary.json").read_text())
    n_nodes = len(read_storage_index(s / "r" / "solution.sto"))
    assert len(solution) <= 20 and len(rates) <= 20
    assert solution[0] == (f"Solution (effort-gen, side r): {len(summary['muscles'])} muscles x {n_nodes} nodes "
                           f"({summary['time_window_s'][0]:.3f}-{summary['time_window_s'][1]:.3f} s, "
                           f"{n_nodes - 1} intervals), {len(summary['dofs'])} DOFs")
    assert solution[1].startswith(f"  {summary['status']} in {summary['iterations']} iterations")
    assert solution[2].startswith("  stop optimum (tolerance 1e-08); rates converged")
    assert solution[3] == "  5 plausibility flags (passive_force, fiber_length, saturated_activation, " \
                          "saturated_lengthening, reserve)"
    assert "array(" not in r.stdout  # no array printed (the dataclass repr printed every array)
    leg = pd.read_csv(m / "r" / "leg_muscles.csv").set_index("model")["leg_muscles_W"]
    assert rates[1] == "  the leg's muscles (W, no basal heat; a leg to add to the other):"
    assert rates[2:4] == [f"    {model:<5} {leg[model]:8.2f}" for model in ("UM10", "BH04")]


def read_storage_index(path):
    from musclemetab.io import read_table

    return read_table(path).index
