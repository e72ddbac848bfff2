"""The benchmark scripts run: each in a new process with ``--quick`` (a small problem, seconds),
exit status 0 and its result lines printed, the ratios it measures among them. The numbers
themselves are not checked (they are the machine's); ``benchmarks/*.py`` say what the full runs
measure and docs/solver.md and docs/study.md hold the measured values."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parent.parent / "benchmarks"

#: script -> lines its --quick run must print (regular expressions, each matched on a line of its own)
EXPECTED = {
    "lock_takeover.py": [r"^3 rounds of 2 simultaneous starts after a crash: 3 round\(s\) with 1 holder\(s\) "],
    "metabolics.py": [r"^model\s+M samples/s median\s+best\s+x probe median",
                      *[rf"^{m}\s+[\d.]+\s+[\d.]+\s+\d+\s+\d+\s+\((Umberger2010|Bhargava2004)\)$"
                        for m in ("UM03", "BH04", "HO06", "LW07", "UM10", "UC16")]],
    "geometry.py": [r"^  ratio AnalyzeTool / cold\s+[\d.]+ x$", r"^  ratio AnalyzeTool / cached\s+\d+ x$"],
    "kkt.py": [r"CasADi-Linsol MUMPS / block = [\d.]+x$"],
    "emg_ten.py": [r"^  status Solve_Succeeded, \d+ iterations",
                   r"^  study's MATLAB run: 141-206 s, 135-235 iterations -> this run takes [\d.]+-[\d.]+ of its time "
                   r"\([\d.]+-[\d.]+x faster; IPOPT time\)$"],
    "input_stage.py": [r"^  this tree\s+[\d.]+ ms   files parsed: ", r"^  ratio this tree / baseline: [\d.]+$"],
    "stop.py": [r"^  authors\s+\d+ iterations, IPOPT CPU", r"^  optimum\s+\d+ iterations, IPOPT CPU",
                r"^  IPOPT CPU optimum / authors: [\d.]+x$"],
    "solver.py": [r"^normal effort-gen N=\d+ Solve_Succeeded", r"^time split: NLP function evaluations \d+ %",
                  r"^cold 'musclemetab solve' \(normal, effort-gen"],
}


@pytest.mark.opensim
@pytest.mark.slow
@pytest.mark.parametrize("script", sorted(EXPECTED))
def test_the_benchmark_runs_quick(script):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p), "PYTHONWARNINGS": "ignore"}
    proc = subprocess.run([sys.executable, str(BENCHMARKS / script), "--quick"], capture_output=True, text=True,
                          timeout=600, env=env)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    lines = proc.stdout.splitlines()
    for pattern in EXPECTED[script]:
        assert any(re.search(pattern, line) for line in lines), (pattern, proc.stdout[-2000:])
