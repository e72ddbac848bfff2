"""The benchmark scripts run: every one with ``--quick`` (a small problem, seconds) as
``python benchmarks/X.py --quick`` runs it, exit status 0 and its result lines printed, the ratios
it measures among them. The numbers themselves are not checked (they are the machine's);
``benchmarks/*.py`` say what the full runs measure and docs/solver.md and docs/study.md hold the
measured values. The quick runs use the test run's cache (``$MUSCLEMETAB_CACHE``, passed on): the
geometry other tests computed is not computed again.

Each script runs in a new process of its own, as ``__main__`` with ``sys.argv`` ``[script,
"--quick"]`` and the benchmarks folder first on ``sys.path``: a child forked from one launcher
process of this module that has imported the libraries every script imports (NumPy, pandas,
SciPy, CasADi with its IPOPT plugin, the package), so that the twenty scripts do not import them
twenty times; the processes a script starts (``musclemetab`` commands, process pools, worker
trees) are new interpreters, as in any run of the script."""

from __future__ import annotations

import json
import os
import re
import select
import signal
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parent.parent / "benchmarks"

#: script -> lines its --quick run must print (regular expressions, each matched on a line of its own)
EXPECTED = {
    "local_optima.py": [r"^  cold \(the reference\)\s+\+0\.0e\+00\s+\d+\s+[\d.]+\s+0\.000 %",
                        r"^  warm from EFFORT-GEN\s+[+-][\d.]+e[+-]\d+\s+\d+\s+[\d.]+\s+[\d.]+ % \(\w+\)\s+[\d.]+ %"],
    "moco_states.py": [r"^MocoInverse of the normal trial, mesh 0.05 s: .*\"success\": true",
                       r"^Moco's own outputs\s+0\.0e\+00\s+0\.0e\+00\s+0\.0e\+00(\s+[\d.]+){6}$",
                       *[rf"^{s}\s+[\d.]+e[+-]\d+\s+[\d.]+e[+-]\d+\s+[\d.]+e[+-]\d+(\s+[\d.]+){{6}}$"
                         for s in ("trajectory", "derivative", "equilibrium")]],
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


#: the launcher: imports the libraries once; per line ``[script, stdout file, stderr file]`` read from
#: stdin, a forked child runs the script as ``__main__``; it writes the child's process id, then
#: its exit status, one line each
_LAUNCHER = r"""
import atexit, json, os, runpy, sys, threading, traceback
import numpy, pandas, scipy.interpolate, scipy.linalg, scipy.signal, scipy.sparse, scipy.stats, casadi
import musclemetab.datasets, musclemetab.geometry, musclemetab.metabolics.solution, musclemetab.redundancy.run
import musclemetab.study.runner, musclemetab.uncertainty
x = casadi.SX.sym("x")  # the IPOPT plugin loaded
casadi.nlpsol("s", "ipopt", {"x": x, "f": x * x}, {"ipopt": {"print_level": 0}, "print_time": False})
folder = sys.argv[1]


def run(script, out, err):
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    for fd, path in ((1, out), (2, err)):
        f = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
        os.dup2(f, fd)
    sys.argv, sys.path[0] = [script, "--quick"], folder
    code = 0
    try:
        runpy.run_path(script, run_name="__main__")
    except SystemExit as exc:  # as the interpreter treats it
        if exc.code is None or isinstance(exc.code, int):
            code = exc.code or 0
        else:
            print(exc.code, file=sys.stderr)
            code = 1
    except BaseException:
        traceback.print_exc()
        code = 1
    threading._shutdown()  # as at exit: the threads the script left running joined, then the exit functions
    atexit._run_exitfuncs()  # (the OpenSim worker shut down, temporary folders removed)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


for line in sys.stdin:
    script, out, err = json.loads(line)
    sys.stdout.flush()
    pid = os.fork()
    if pid == 0:
        run(os.path.join(folder, script), out, err)
    print(pid, flush=True)
    print(os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]), flush=True)
"""


@pytest.fixture(scope="module")
def launcher():
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p), "PYTHONWARNINGS": "ignore"}
    # unbuffered: a line read is a line taken from the pipe, so that select() sees what is left
    proc = subprocess.Popen([sys.executable, "-c", _LAUNCHER, str(BENCHMARKS)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, bufsize=0, env=env)
    yield proc
    proc.stdin.close()
    proc.wait(timeout=60)


def run_quick(launcher, script: str, folder: Path, timeout: float = 600) -> tuple[int, str, str]:
    """``(exit status, stdout, stderr)`` of ``script --quick`` in a child of the launcher."""
    out, err = folder / "stdout.txt", folder / "stderr.txt"
    launcher.stdin.write((json.dumps([script, str(out), str(err)]) + "\n").encode())
    line = launcher.stdout.readline()
    assert line, f"the launcher ended (exit status {launcher.wait()}): see its standard error"
    pid = int(line)
    if not select.select([launcher.stdout], [], [], timeout)[0]:
        os.kill(pid, signal.SIGKILL)  # the launcher then reports its end (-9)
    code = int(launcher.stdout.readline())
    return code, out.read_text(), err.read_text()


@pytest.mark.opensim
@pytest.mark.slow
@pytest.mark.parametrize("script", sorted(EXPECTED))
def test_the_benchmark_runs_quick(script, launcher, tmp_path):
    code, stdout, stderr = run_quick(launcher, script, tmp_path)
    assert code == 0, stdout[-2000:] + stderr[-2000:]
    lines = stdout.splitlines()
    for pattern in EXPECTED[script]:
        assert any(re.search(pattern, line) for line in lines), (pattern, stdout[-2000:])
