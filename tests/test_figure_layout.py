"""Every text of the report's figures can be read: none cut by the figure's edge, none over another.

:func:`musclemetab.report.layout_check.figure_problems` measures each text with matplotlib's
renderer; the report runs it on every figure it saves and records what it finds in
``figures/report.json``. Here it is checked on figures whose texts are placed by hand (where
the answer is known), and then the reports the test run makes anyway are read: the demo's
(``demo`` fixture), the two-subject study's (``two_subjects``) and, in ``test_cli_flow.py``,
the one-trial report of the command line. No figure is drawn twice but the Figure-2 plot,
which the report copies from the package's cache.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from musclemetab.report.layout_check import figure_problems


def _figure(w=4.0, h=3.0):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h), dpi=100)
    FigureCanvasAgg(fig)
    return fig


def test_figure_problems_finds_texts_cut_by_the_edge_and_over_one_another():
    # a 400 x 300 px figure: a title twice as wide as the figure, centred, is cut on both sides
    fig = _figure()
    fig.suptitle("x" * 150, fontsize=10)
    problems = figure_problems(fig)
    assert problems == [f"figure title '{'x' * 37}...' is cut by the figure's left and right edge"]
    # a label starting 20 px left of the figure is cut on the left alone
    fig = _figure()
    fig.text(-0.05, 0.5, "left")
    assert figure_problems(fig) == ["figure text 'left' is cut by the figure's left edge"]
    # two panel titles drawn at the same place overlap; a tidy figure has no problem
    fig = _figure(6.0, 3.0)
    ax1, ax2 = fig.subplots(1, 2)
    for a in (ax1, ax2):
        a.set_xticks([])
        a.set_yticks([])
    ax1.set_title("a long title of the first panel, longer")
    ax2.set_title("second", loc="left")
    fig.subplots_adjust(wspace=0.05)
    assert figure_problems(fig) == ["panel 1 title 'a long title of the first panel, longer' overlaps panel 2 title 'second'"]
    fig = _figure()
    ax = fig.add_subplot()
    ax.set_xlim(0, 100)
    ax.set_ylim(0, 10)
    ax.set_xticks([25, 50, 75])
    ax.set_title("title")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    fig.subplots_adjust(left=0.2, bottom=0.2)
    assert figure_problems(fig) == []
    # tick labels of neighbouring panels meeting at their common edge ("100" against "0")
    fig = _figure(3.0, 2.0)
    axes = fig.subplots(1, 2, sharey=True)
    for a in axes:
        a.set_xlim(0, 100)
        a.set_xticks([0, 100])
    for a in axes:
        a.set_yticks([])
    fig.subplots_adjust(wspace=0.0, bottom=0.3)
    assert figure_problems(fig) == ["panel 1 x tick '100' overlaps panel 2 x tick '0'"]


def test_the_report_fits_a_long_title_legend_and_panel_titles_into_its_figures(tmp_path):
    """What the report's figures are given when saved (``save_figure``): the title wrapped to
    the figure, the legend below in as many columns as fit, the panel titles wrapped to their
    panel; the same texts in a plain matplotlib figure are cut or overlap."""
    from matplotlib.lines import Line2D

    from musclemetab.report.figures import _legend_below, _new_figure, _panel_title, save_figure

    def draw(fig, axes):
        handles = [Line2D([], [], label=f"muscle group number {i} (long name)") for i in range(8)]
        for a in axes:
            a.plot([0, 100], [0, 10])
            a.set_xlim(0, 100)
            a.set_ylim(0, 10)
            _panel_title(a, "Stance and swing shares at the preferred speed (normal, 1.33 m/s)", fontsize=9)
        fig.suptitle("Whole-body metabolic rate over the gait cycle across walking speeds (one leg, summed muscles, "
                     "no basal heat): subject subject01, trial walk1, effort-gen", fontsize=11)
        return handles

    plain = _figure(6.0, 4.0)
    axes = plain.subplots(1, 2)
    handles = draw(plain, axes)
    plain.legend(handles=handles, loc="lower center", ncol=8, fontsize=8)
    cut = figure_problems(plain)
    assert any("figure title" in p and "cut" in p for p in cut)
    assert any("figure legend" in p and "cut" in p for p in cut)
    assert any("panel 1 title" in p and "overlaps panel 2 title" in p for p in cut)

    fig = _new_figure(6.0, 4.0)
    axes = fig.subplots(1, 2)
    _legend_below(fig, draw(fig, axes), 8, 8)
    save_figure(fig, tmp_path, "fitted", formats=("png",))
    assert figure_problems(fig, drawn=True) == []
    assert fig._suptitle.get_text().count("\n") >= 1 and "\n" in axes[0].get_title()


def _recorded_problems(report_dir: Path) -> dict[str, list[str]]:
    """Each drawn figure of a report -> the layout problems its drawing recorded."""
    record = json.loads((report_dir / "figures" / "report.json").read_text())
    return {e["name"]: e["layout_problems"] for e in record["entries"] if e["paths"] is not None}


def _figure2_problems() -> list[str]:
    """The Figure-2 plot (copied from the package's cache by the report): drawn and checked."""
    from musclemetab.report.plan import figure2_figure

    fig, _ = figure2_figure()
    return figure_problems(fig)


@pytest.mark.slow
def test_every_figure_of_the_demo_report_is_readable(demo, capsys):
    out, _ = demo
    problems = _recorded_problems(out)
    with capsys.disabled():
        print(f"\nlayout checked, demo report: {', '.join(problems)}")
    # the demo's data support every figure but the comparison with measured rates
    assert set(problems) == {"excitations_fiber_lengths", "group_rates_over_cycle", "muscle_heat_map",
                             "whole_body_over_cycle", "phase_shares", "phase_pies", "group_shares",
                             "rates_against_speed", "per_muscle_ranked", "structural_spread", "figure2_soleus"}
    assert {n: p for n, p in problems.items() if p} == {}
    assert _figure2_problems() == []


@pytest.mark.slow
def test_every_figure_of_the_two_subject_report_is_readable(two_subjects, capsys):
    out, _ = two_subjects
    problems = _recorded_problems(out)
    with capsys.disabled():
        print(f"\nlayout checked, two-subject report: {', '.join(problems)}")
    assert len(problems) >= 9
    assert {n: p for n, p in problems.items() if p} == {}


# ------------------------------------------------------------------- what the figures show
def test_each_muscle_is_tagged_with_the_group_of_its_main_action():
    """The heat map's tag of a muscle: the group of its main action in the textbooks (the
    muscle table's ``primary_group``), not the first group in a fixed order (which put the
    adductors and gluteus minimus under the hip flexors and gluteus medius under the hip
    extensors)."""
    from musclemetab.properties import anatomical_table
    from musclemetab.report.figures import anatomical_muscles, muscle_names

    groups = {n: g for n, (_, g) in anatomical_muscles(
        ["addlong_r", "addbrev_r", "addmagDist_r", "glmin1_r", "glmed1_r", "glmax1_r", "bflh_r", "recfem_r",
         "iliacus_r", "soleus_r", "tibant_r"]).items()}
    assert groups == {"addlong_r": "HAD", "addbrev_r": "HAD", "addmagDist_r": "HAD", "glmin1_r": "HAB",
                      "glmed1_r": "HAB", "glmax1_r": "HE", "bflh_r": "KF", "recfem_r": "KE", "iliacus_r": "HF",
                      "soleus_r": "PF", "tibant_r": "DF"}
    # gait2392's names of the same muscles: the same groups
    assert anatomical_muscles(["glut_med1_r", "add_long_r"]) == {"glut_med1_r": ("gluteus medius (r)", "HAB"),
                                                                 "add_long_r": ("adductor longus (r)", "HAD")}
    # every muscle's main action is one of its actions
    table = anatomical_table()
    for name, row in table.iterrows():
        assert row["primary_group"] in row["function_groups"].replace("/", " ").split(), name
    # one naming everywhere: the anatomical muscle with the model's name
    assert muscle_names(["med_gas_r", "addmagDist_r", "not_a_muscle"]) == {
        "med_gas_r": "gastrocnemius medialis (med_gas_r)", "addmagDist_r": "adductor magnus (addmagDist_r)",
        "not_a_muscle": "not_a_muscle"}


def test_the_heat_map_has_one_colour_scale_per_trial():
    """A fast trial's rates three times a slow one's: each row of panels (a trial) is scaled
    to its own peak, with its own colour bar, so that the slow row is not left pale."""
    from musclemetab.report.figures import muscle_heat_map

    pct = np.linspace(0.0, 100.0, 21)
    slow = pd.DataFrame({"soleus_r": 10 + 50 * np.sin(np.pi * pct / 100), "tibant_r": np.full(pct.size, 5.0)},
                        index=pct)
    rates = {"slow": {"UM10": slow, "BH04": 0.8 * slow}, "fast": {"UM10": 3 * slow, "BH04": 2.4 * slow}}
    fig = muscle_heat_map(rates, {"slow": 62.0, "fast": 58.0})
    panels = [ax for ax in fig.axes if ax.images]
    peaks = {ax.get_title(): ax.images[0].get_clim()[1] for ax in panels}
    assert peaks == pytest.approx({"slow: UM10": 60.0, "slow: BH04": 60.0, "fast: UM10": 180.0, "fast: BH04": 180.0})
    colour_bars = [ax for ax in fig.axes if not ax.images and ax.get_ylabel().startswith("rate")]
    assert len(colour_bars) == 2
    assert figure_problems(fig) == []


def test_a_group_without_energy_has_no_panel():
    """The ``other`` bucket is empty when every DOF of the muscles is solved: no empty panel."""
    from test_report import GROUPS, TOE_OFF_PCT, make_timeseries

    from musclemetab.report.figures import group_rates_over_cycle

    ts = make_timeseries(1.25)
    zero = ts["series"] == "group/HIR"
    ts.loc[zero, "value_W"] = 0.0
    fig = group_rates_over_cycle(ts, TOE_OFF_PCT)
    titles = [ax.get_title() for ax in fig.axes if ax.get_visible()]
    assert len(titles) == len(GROUPS) - 1 and not any(t.startswith("HIR") for t in titles)


def test_the_command_lines_subject_and_trial_come_from_the_file_names():
    from musclemetab.report.cli_folder import unit_names

    assert unit_names("/d/subject01_simbody.osim", "/d/subject01_walk1_ik.mot") == ("subject01", "walk1")
    assert unit_names("P/model.osim", "P/ik.mot") == ("model", "ik")  # nothing in common: the files' names
    assert unit_names("s2-scaled.osim", "s2-fast-ik.mot") == ("s2", "fast")
    assert unit_names("s2.osim", "s2_ik.mot") == ("s2", "s2_ik")  # nothing but the subject: the IK file's name


def test_a_trial_prepared_from_the_labs_files_is_named_after_them(tmp_path):
    """``prepare`` writes model.osim and ik.mot; the report names the trial after the static and
    walking trials its record names, not after those two files."""
    import json

    from musclemetab.report.cli_folder import named_files, unit_names

    prep = tmp_path / "P"
    prep.mkdir()
    (prep / "ik.mot").write_text("")
    model, ik = str(prep / "model.osim"), str(prep / "ik.mot")
    assert unit_names(*named_files(model, ik)) == ("model", "ik")  # no record: the files' names
    (prep / "prepare.json").write_text(json.dumps({
        "inputs": {"static": "/lab/subject01_static.trc", "markers": "/lab/subject01_walk1.c3d"},
        "files": {"model": "model.osim", "ik": "ik.mot"}}))
    assert unit_names(*named_files(model, ik)) == ("subject01", "walk1")
    other = prep / "ik_filtered.mot"  # an IK file the record does not name keeps its own name
    assert named_files(model, str(other)) == (model, str(other))
    (prep / "prepare.json").write_text("{not json")  # a record this version cannot read: the files' names
    assert unit_names(*named_files(model, ik)) == ("model", "ik")
