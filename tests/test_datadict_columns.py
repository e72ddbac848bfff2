"""One meaning per column name: every column of every CSV the package writes is documented
once in the data dictionary (``musclemetab.datadict``, ``docs/data_dictionary.md``), for that file."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pytest

from musclemetab.datadict import DATA_DICTIONARY, data_dictionary_markdown

DOCS = Path(__file__).resolve().parents[1] / "docs" / "data_dictionary.md"


def _entries(column: str) -> list[tuple[str, str, str, str]]:
    """The dictionary's entries for ``column``: the entry of that exact name, else those of the
    families (``share_<G>_pct``) it belongs to."""
    exact = [e for e in DATA_DICTIONARY if e[1] == column]
    if exact:
        return exact
    found = []
    for e in DATA_DICTIONARY:
        if "<" in e[1]:
            pattern = "^" + re.sub(r"<[^>]+>", "[^/]+", re.escape(e[1]).replace(r"\<", "<").replace(r"\>", ">")) + "$"
            if re.match(pattern, column):
                found.append(e)
    return found


def undocumented(path: Path, columns) -> list[str]:
    """The columns of the file ``path`` without exactly one dictionary entry that names the file."""
    stem = path.name.split(".")[0]
    bad = []
    for c in columns:
        entries = _entries(str(c))
        if len(entries) != 1:
            bad.append(f"{path.name}: {c} ({len(entries)} entries)")
        elif not re.search(rf"(^|[ ,/]){re.escape(stem)}\.(csv|parquet)", entries[0][0]):
            bad.append(f"{path.name}: {c} (documented for {entries[0][0]})")
    return bad


def test_each_column_name_has_one_entry():
    names = [e[1] for e in DATA_DICTIONARY]
    assert len(names) == len(set(names)), sorted({n for n in names if names.count(n) > 1})
    # the page is rendered from the dictionary, as it stands
    assert DOCS.read_text(encoding="utf-8") == data_dictionary_markdown()
    # the names say their scope: no bare mean_... column is left
    assert not [n for n in names if n in ("mean_W", "mean_W_per_kg", "mean_W_per_kg_no_basal", "one_leg_mean_W")]


def test_every_csv_column_the_study_writes_is_documented_once(demo, example):
    out, _ = demo
    files = sorted(out.rglob("*.csv"))
    stems = {p.name for p in files}
    # the study's tables and a unit's
    assert {"results.csv", "per_muscle.csv", "data_dictionary.csv", "muscle_groups.csv", "whole_body.csv",
            "analysis.csv", "timeseries.csv"} <= stems, stems
    bad = []
    for path in files:
        bad += undocumented(path, pd.read_csv(path, nrows=1).columns)
    for path in sorted(out.rglob("metabolics.parquet"))[:1]:
        bad += undocumented(path, pd.read_parquet(path).columns)
    assert not bad, bad
    # the whole-body rate of the results is twice the leg's muscles plus the basal heat: the names
    # say which figure is which (one leg, no basal; both legs, with basal)
    res = pd.read_csv(out / "results.csv")
    assert res["whole_body_no_basal_W_per_kg"].to_numpy() == pytest.approx(
        (2 * res["leg_muscles_W"] / example.body_mass_kg).to_numpy(), rel=1e-9)
    assert (res["whole_body_W_per_kg"] - res["whole_body_no_basal_W_per_kg"]).to_numpy() == pytest.approx(1.2)


def test_a_study_folder_of_the_former_names_is_read_with_the_present_ones(tmp_path):
    """results.csv and per_muscle.csv written before the rename: the report reads them through
    the mapping of musclemetab.report.folder (one_leg_mean_W only where it held no basal heat)."""
    from musclemetab.report.folder import read_study_folder

    old = pd.DataFrame({"subject": ["s1", "s1"], "trial": ["normal"] * 2, "workflow": ["effort-gen"] * 2,
                        "model": ["UM10", "BH04"], "status": ["ok", "ok"], "mean_W_per_kg": [4.1, 4.6],
                        "mean_W_per_kg_no_basal": [2.9, 3.4], "one_leg_mean_W": [105.3, 123.4],
                        "basal_rule": ["body", "body"]})
    old.to_csv(tmp_path / "results.csv", index=False)
    pd.DataFrame({"subject": ["s1"], "trial": ["normal"], "workflow": ["effort-gen"], "model": ["UM10"],
                  "muscle": ["soleus_r"], "mean_W": [20.5], "mean_W_per_kg": [20.5 / 72.6]}).to_csv(
        tmp_path / "per_muscle.csv", index=False)
    study = read_study_folder(tmp_path)
    assert study.results["whole_body_W_per_kg"].tolist() == [4.1, 4.6]
    assert study.results["whole_body_no_basal_W_per_kg"].tolist() == [2.9, 3.4]
    assert study.results["leg_muscles_W"].tolist() == [105.3, 123.4]
    pm = study.read_per_muscle()
    assert pm["muscle_W"].tolist() == [20.5] and pm["muscle_W_per_kg"].tolist() == pytest.approx([20.5 / 72.6])
    # under the muscle basal rule the former one_leg_mean_W held basal heat: it is not taken as leg_muscles_W
    old.assign(basal_rule="muscle").to_csv(tmp_path / "results.csv", index=False)
    study = read_study_folder(tmp_path)
    assert "leg_muscles_W" not in study.results and "one_leg_mean_W" not in study.results
    assert study.results["whole_body_W_per_kg"].tolist() == [4.1, 4.6]
