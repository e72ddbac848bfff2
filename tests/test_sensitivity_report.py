"""The sensitivity ranking of a study: the study key ``[uncertainty] sensitivity`` and
``--sensitivity``, the trial unit's call of the writer of ``metabolics --sensitivity`` (a fake
writer here: the sensitivities themselves are checked in tests/test_sensitivity.py), and the
report's section from a synthetic study folder with a hand-written ``sensitivity.csv``."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_report import make_study

from musclemetab.errors import OptionError
from musclemetab.redundancy.sensitivity import SENSITIVITY_COLUMNS
from musclemetab.study import load_study

STUDY_TOML = """
name = "sens"
output = "out"
workflows = ["effort-gen"]
models = ["UM10", "BH04"]
{extra}
[[subjects]]
name = "sub1"
model = "{model}"
body_mass_kg = 72.6
height_m = 1.743

[[subjects.trials]]
name = "normal"
ik = "{ik}"
id = "{id}"
"""


def _load(tmp_path, example, extra=""):
    path = tmp_path / "study.toml"
    path.write_text(STUDY_TOML.format(extra=extra, model=example.model, ik=example.ik["normal"],
                                      id=example.id["normal"]))
    return load_study(path)


# ------------------------------------------------------------------------------ the study
def test_study_key_option_and_unit_key(tmp_path, example):
    """``[uncertainty] sensitivity = true`` needs no samples; off by default; a bad value names the
    key; ``--sensitivity`` turns it on; the trial unit's key changes with it, not without it."""
    from musclemetab.commands import build_parser
    from musclemetab.commands.run import apply_uncertainty_arguments
    from musclemetab.study.units import Unit, unit_key

    plain = _load(tmp_path, example)
    on = _load(tmp_path, example, "[uncertainty]\nsensitivity = true\n")
    off = _load(tmp_path, example, "[uncertainty]\nsensitivity = false\n")
    assert (plain.sensitivity, on.sensitivity, off.sensitivity) == (False, True, False)
    assert "uncertainty" not in on.settings  # no samples asked for
    with pytest.raises(OptionError, match=r"\[uncertainty\]: 'sensitivity' must be true or false"):
        _load(tmp_path, example, '[uncertainty]\nsensitivity = "yes"\n')
    with pytest.raises(OptionError, match="'samples' is required"):  # the samples' own keys still need samples
        _load(tmp_path, example, "[uncertainty]\nseed = 3\nsensitivity = true\n")
    unit = Unit("sub1", "normal", "effort-gen")
    assert unit_key(off, unit) == unit_key(plain, unit) != unit_key(on, unit)
    args = build_parser().parse_args(["run", str(tmp_path / "study.toml"), "--sensitivity"])
    assert apply_uncertainty_arguments(plain, args).sensitivity
    assert not apply_uncertainty_arguments(plain, build_parser().parse_args(["run", "x.toml"])).sensitivity
    assert build_parser().parse_args(["demo", "--sensitivity"]).sensitivity


def test_trial_unit_calls_the_writer_of_metabolics_sensitivity(tmp_path, example, monkeypatch):
    """A trial unit of an effort workflow hands its folder, trial, body, models and basal rule to
    ``write_folder_sensitivity`` (the function behind ``metabolics --sensitivity``); EMG-TEN units,
    energy goals and the cases the sensitivities refuse are recorded as skipped with the reason."""
    import musclemetab.redundancy.sensitivity as sensitivity
    from musclemetab.study.spec import sensitivity_study
    from musclemetab.study.units import Unit, unit_sensitivity

    calls = []

    def fake(folder, out, **kw):
        calls.append((Path(folder), Path(out), kw))
        path = Path(out) / "sensitivity.csv"
        pd.DataFrame([dict.fromkeys(SENSITIVITY_COLUMNS, 0.0)]).to_csv(path, index=False)
        return path, type("S", (), {"parameters": [("lTs", "soleus_r")] * 3, "models": ("UM10", "BH04")})()

    monkeypatch.setattr(sensitivity, "write_folder_sensitivity", fake)
    study = sensitivity_study(_load(tmp_path, example), True)
    record = unit_sensitivity(study, Unit("sub1", "normal", "effort-gen"), tmp_path)
    assert record == {"file": "sensitivity.csv", "parameters": 3, "models": ["UM10", "BH04"]}
    (folder, out, kw), = calls
    assert folder == out == tmp_path and (tmp_path / "sensitivity.csv").is_file()
    assert kw == {"trial": "normal", "body_mass_kg": 72.6, "height_m": 1.743, "models": ["UM10", "BH04"],
                  "basal": "body", "basal_rate_W_per_kg": 1.2, "basal_exponent": 1.0, "muscle_properties": None}
    skipped = unit_sensitivity(study, Unit("sub1", "normal", "emg-ten"), tmp_path)
    assert "effort workflows" in skipped["skipped"] and "emg-ten" in skipped["skipped"]
    energy = sensitivity_study(_load(tmp_path, example, '[energy_goal]\nmodel = "UM10"\n'), True)
    assert "energy goal" in unit_sensitivity(energy, Unit("sub1", "normal", "effort-gen"), tmp_path)["skipped"]
    assert len(calls) == 1

    def refuses(folder, out, **kw):
        raise OptionError(f"{folder}: the sensitivities need the forward fiber dynamics")

    monkeypatch.setattr(sensitivity, "write_folder_sensitivity", refuses)
    assert "forward fiber dynamics" in unit_sensitivity(study, Unit("sub1", "normal", "effort-gen"),
                                                        tmp_path)["skipped"]


# ------------------------------------------------------------------------------ the report
#: whole-body rows of UM10 (change per 1 %, W/kg) in file order, not in rank order
UM10_ROWS = [("F0", "soleus_r", -0.010), ("lTs", "soleus_r", 0.045), ("kT", "gasmed_r", -0.030),
             ("lMo", "vaslat_r", 0.002), ("vmax", "tibant_r", 0.020)]
BH04_ROWS = [("F0", "soleus_r", 0.005), ("lTs", "soleus_r", -0.001)]
RATE = 3.2  # W/kg


def _sensitivity_csv(folder: Path) -> None:
    rows = []
    for model, entries in (("UM10", UM10_ROWS), ("BH04", BH04_ROWS)):
        for p, m, change in entries:
            rows.append({"solution": "normal", "parameter_rank": 0, "parameter": p, "muscle": m, "parameter_value": 1.5,
                         "model": model, "rate": "whole_body", "rate_value": RATE, "d_rate_d_log_p": 100 * change,
                         "change_per_1pct": change, "relative_change_per_1pct": change / RATE})
    # a muscle's own rate with a larger change: not a whole-body row, never in the ranking
    rows.append({"solution": "normal", "parameter_rank": 1, "parameter": "F0", "muscle": "recfem_r",
                 "parameter_value": 900.0, "model": "UM10", "rate": "recfem_r", "rate_value": 20.0,
                 "d_rate_d_log_p": 900.0, "change_per_1pct": 9.0, "relative_change_per_1pct": 0.45})
    pd.DataFrame(rows, columns=list(SENSITIVITY_COLUMNS)).to_csv(folder / "sensitivity.csv", index=False)


def _section_rows(page: str, label: str) -> list[list[str]]:
    start = page.index(f"<h3>{label}</h3>")
    table = page[start:page.index("</table>", start)]
    rows = re.findall(r"<tr>(.*?)</tr>", table, flags=re.S)
    return [[re.sub(r"<.*?>", "", c).strip() for c in re.findall(r"<t[hd][^>]*>(.*?)</t[hd]>", r, flags=re.S)]
            for r in rows if "<td" in r]


def test_report_section_ranks_the_whole_body_rate(tmp_path):
    """The section appears only with sensitivity.csv files: per unit the whole-body rows of each
    model ranked by the size of the change, the change per 1 % in W/kg and in % of the rate; the
    figure's bars are the UM10 changes, largest on top."""
    from musclemetab.report.folder import read_study_folder
    from musclemetab.report.page import page_tables, render_page
    from musclemetab.report.sensitivity import sensitivity_figure, sensitivity_section, whole_body_ranking

    root = make_study(tmp_path / "study", measured=False, trials={"normal": 1.25}, solutions=False)
    assert sensitivity_section(read_study_folder(root)) is None
    _sensitivity_csv(root / "units" / "s1" / "normal" / "effort-ten")
    folder = read_study_folder(root)
    tables = page_tables(folder)
    page = render_page(folder, [], tables=tables)
    assert '<a href="#sensitivity">Sensitivity</a>' in page and 'id="sensitivity"' in page
    assert "implicit-function theorem" in page and "docs/uncertainty.md" in page
    rows = _section_rows(page, "s1 / normal / effort-ten")
    um10 = [r for r in rows if r[0] == "UM10"]
    assert [(r[1], r[2], r[3]) for r in um10] == [("1", "lTs", "soleus_r"), ("2", "kT", "gasmed_r"),
                                                  ("3", "vmax", "tibant_r"), ("4", "F0", "soleus_r"),
                                                  ("5", "lMo", "vaslat_r")]
    assert [float(r[5]) for r in um10] == [0.045, -0.030, 0.020, -0.010, 0.002]
    assert float(um10[0][6]) == pytest.approx(100 * 0.045 / RATE, abs=5e-4)
    assert [(r[1], r[2]) for r in rows if r[0] == "BH04"] == [("1", "F0"), ("2", "lTs")]
    assert "recfem_r" not in page[page.index('id="sensitivity"'):page.index('id="settings"')]
    section = tables["sensitivity"]
    assert section["figure_model"] == "UM10" and [u["label"] for u in section["units"]] == ["s1 / normal / effort-ten"]
    table = pd.read_csv(root / "units" / "s1" / "normal" / "effort-ten" / "sensitivity.csv")
    fig = sensitivity_figure("s1", whole_body_ranking(table, ["UM10"], 3), "UM10")
    bars = fig.axes[0].patches
    assert [round(b.get_width(), 6) for b in sorted(bars, key=lambda b: -b.get_y())] == [0.045, -0.030, 0.020]
    assert np.allclose([b.get_y() + b.get_height() / 2 for b in bars], [2, 1, 0])
