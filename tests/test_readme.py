"""The README's Quick start runs as it is shown and prints what it says.

The Python block under "Quick start" is run in a new folder (the solve memo of the test run
gives the solve other tests make of the same call); the number it prints, UM10's whole-body
rate of the example subject's normal trial, is the demo's row of ``results.csv`` (the study
runner's path to the same number), the summary of the solution is short, and the files it
writes are there.
"""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def quick_start_block() -> str:
    """The first Python block of the README's "Quick start" section."""
    text = README.read_text()
    return re.search(r"^## Quick start\n.*?^```python\n(.*?)^```", text, re.S | re.M).group(1)


@pytest.mark.opensim
def test_the_quick_start_runs_and_prints_the_demos_number(demo, tmp_path, monkeypatch):
    import scipy.io

    _, results = demo
    monkeypatch.chdir(tmp_path)
    printed = io.StringIO()
    namespace: dict = {}
    with contextlib.redirect_stdout(printed):
        exec(compile(quick_start_block(), str(README), "exec"), namespace)
    lines = printed.getvalue().splitlines()
    assert lines[0] == "(119, 40) (119, 5, 40)"
    summary = lines[1:-1]
    assert summary[0].startswith("Solution (effort-gen, side r): 40 muscles x 119 nodes") and len(summary) <= 20
    row = results[(results.trial == "normal") & (results.workflow == "effort-gen") & (results.model == "UM10")]
    want = float(row["whole_body_W_per_kg"].iloc[0])
    assert namespace["rates"].whole_body["UM10"].mean_W_per_kg == pytest.approx(want, rel=1e-6)
    assert lines[-1] == f"{round(want, 2)}" == "5.58"  # the number the README's comment shows
    assert (tmp_path / "out" / "normal" / "solution.sto").is_file()
    mat = scipy.io.loadmat(tmp_path / "out" / "normal.mat", simplify_cells=True)
    wb = mat["metabolics"]["whole_body"]
    assert list(wb["model"]) == ["UM10", "BH04"] and wb["whole_body_W_per_kg"][0] == pytest.approx(want, rel=1e-6)
