"""The benchmark scripts run: every one in a new process with ``--quick`` (a small problem, seconds),
exit status 0 and its result lines printed, the ratios it measures among them. The numbers
themselves are not checked (they are the machine's); ``benchmarks/*.py`` say what the full runs
measure and docs/solver.md and docs/study.md hold the measured values. The quick runs use the test
run's cache (``$MUSCLEMETAB_CACHE``, passed on): the geometry other tests computed is not computed
again."""

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
    "solver.py": [r"^normal effort-gen N=\s*\d+ Solve_Succeeded", r"^time split: NLP function evaluations \d+ %",
                  r"^cold 'musclemetab solve' \(normal, effort-gen"],
    "capacity.py": [r"^   CPU [\d.]+ s per unit \(IPOPT [\d.]+ s of it\), wall [\d.]+ s; peak memory",
                    r"^   process pool of 2 \(--workers 2\)\s+[\d.]+\s+[\d.]+$", r"^\s+512\s+[\d.]+\s+[\d.]+\s+[\d.]+$"],
    "cold_start.py": [r"^this tree\s+cold\s+[\d.]+\s+[\d.]+", r"^this tree\s+warm\s+[\d.]+\s+[\d.]+",
                      r"^this tree\s+-?[\d.]+\s+-?[\d.]+\s+-?[\d.]+$"],
    "inertia.py": [r"^normal\s+default\s+Solve_Succeeded\s+\d+\s+\d+\s+\d+",
                   r"^normal\s+first_pert_1e-2\s+\S+\s+\d+\s+\d+\s+\d+\s+\d+\s+[\d.]+\s+\d+\s+[\d.]+\s+\S+\s+[+-][\d.]+e[+-]\d+$"],
    "nlp_build.py": [r"^this tree\s+3\s+[\d.]+\s+[\d.]+\s+[\d.]+%$", r"^baseline\s+3\s+",
                     r"^this tree / baseline: build [\d.]+x, build \+ solve [\d.]+x; largest relative objective difference "],
    "report.py": [r"^this version, default workers\s+[\d.]+\s+[\d.]+\s+[\d.]+$", r"^report, nothing changed\s+[\d.]+"],
    "sensitivity.py": [r"^\| lTs \| soleus_r \| (UM10|BH04) \| [+-][\d.]+ \| [+-][\d.]+ \| [+-][\d.]+ \|",
                       r"^largest \|KKT - FD\| / \(5 % \|FD\| \+ 0.01 W/kg\) of the whole-body rates: [\d.]+$"],
    "sides.py": [r"^speed-up of 2 workers over 1: [\d.]+x$", r"^solutions of 1 and 2 workers identical: True$"],
    "study.py": [r"^speed-up of 2 workers over 1 \(same run\): [\d.]+x$", r"^3\. resumed run, every unit up to date: [\d.]+ s"],
    "uncertainty.py": [r"^mean solve time of a warm-started sample / cold solve: [\d.]+ ",
                       r"^trial unit alone: [\d.]+ s; then 2 samples of it on 1 workers: ",
                       r"^  UM10 whole body: \d+ % inside ", r"^  UM10 per muscle \(muscle_W, \d+ truth x muscle pairs\): "],
    "warm_start.py": [r"^warm from GEN, mu_init 1e-6 \(the package's\)\s+\d+\s+[\d.]+\s+[\d.]+\s+[+-]",
                      r"^warm from EFFORT-TEN's own cold optimum\s+\d+\s+[\d.]+"],
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
