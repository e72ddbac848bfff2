"""The NLP build of a study's worker process: this tree against another, the same solves in turn.

    python benchmarks/nlp_build.py --baseline-src OTHER/src [--repeat 2] [--samples 4]
    python benchmarks/nlp_build.py --quick

A study's worker process solves unit after unit. Each problem's per-interval functions (the
symbolic derivatives of the constraints and objective) depend on its structure only (muscles,
DOFs, goals, estimated factors), not on the trial's length, data or muscle parameters, and are
built once per process and structure (``musclemetab.redundancy.transcription.group_functions``).
This measures what that saves where a user pays it: in one new process per source tree (this
tree, and ``--baseline-src``, e.g. the previous version, alternating so both see the same
machine load), the units a worker of the demo's study solves (the example subject's three
trials, EFFORT-GEN then EFFORT-TEN, cold starts as the study's default), followed by
``--samples`` uncertainty samples of the normal trial's EFFORT-GEN unit (muscle parameters
drawn from the package's priors, each warm-started from the nominal solution adapted to them,
as ``musclemetab study --samples`` does). Printed per tree: the sum of the solves' NLP build
times (``build_time_s``: from the start of the build to IPOPT's solver object), the sum of
IPOPT's times, and the build's share; then the ratio of this tree's build time and of its
build + solve time to the baseline's, and the largest objective difference between the trees.

``--quick``: this tree against itself (``--baseline-src`` defaults to it), one process each, the
window 0.6-0.8 s of the normal trial alone (EFFORT-GEN, EFFORT-TEN, one sample), the package's
geometry cache: a check that the script runs (the test suite runs it so).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent

_WORKER = """
import json, sys, warnings
warnings.simplefilter("ignore")
from musclemetab.redundancy import solve_files
model, samples = sys.argv[1], int(sys.argv[2])
trials = json.loads(sys.argv[3])
window = tuple(json.loads(sys.argv[4])) if len(sys.argv) > 4 else None
units = []
def keep(name, sol):
    r = sol.record
    units.append({"unit": name, "build_s": r.build_time_s, "solve_s": r.solve_time_s, "objective": r.objective})
nominal = None
for trial, (ik, idf) in trials.items():
    for wf, kt in (("effort-gen", None), ("effort-ten", "example")):
        sol = solve_files(model, ik, idf, wf, tendon_stiffness=kt, window=window)
        keep(f"{trial} {wf}", sol)
        if trial == "normal" and wf == "effort-gen":
            nominal = sol
if samples:
    from musclemetab.uncertainty import adapted_start, default_priors, draw
    ik, idf = trials["normal"]
    for i in range(samples):
        factors = draw(default_priors(), nominal.muscles, i + 1, 0)
        start = adapted_start(nominal, factors.parameters(nominal.parameters))
        keep(f"sample {i + 1}", solve_files(model, ik, idf, "effort-gen", warm_start=start,
                                            parameter_transform=factors.parameters, window=window))
print(json.dumps(units))
"""


def _example():
    sys.path.insert(0, str(HERE))
    from solver import _example as example  # the benchmarks' one way to locate the example data

    return example()


def run_tree(src: Path, ex, samples: int, cache: Path | None, window=None) -> list[dict]:
    """The worker's solves in a new process of the tree ``src`` (``cache`` None: the package's
    cache; ``window``: the normal trial's alone, over that window)."""
    env = dict(os.environ, PYTHONPATH=str(src), **({"MUSCLEMETAB_CACHE": str(cache)} if cache else {}))
    trials = {t: (str(ex.ik[t]), str(ex.id[t])) for t in (("normal",) if window else ("slow", "normal", "fast"))}
    proc = subprocess.run([sys.executable, "-c", _WORKER, str(ex.model), str(samples), json.dumps(trials),
                           *([json.dumps(list(window))] if window else [])], capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        sys.exit(f"the solves failed with {src}:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline-src", type=Path, help="the src folder of the tree to compare with (required but "
                    "with --quick)")
    ap.add_argument("--repeat", type=int, default=2, help="processes per tree, alternating (median reported)")
    ap.add_argument("--samples", type=int, default=4, help="uncertainty samples after the demo's units")
    ap.add_argument("--quick", action="store_true", help="this tree against itself on the normal trial's window "
                    "0.6-0.8 s, one process each, one sample")
    args = ap.parse_args(argv)
    this = HERE.parent / "src"
    window = None
    if args.quick:
        from _quick import WINDOW

        args.baseline_src, args.repeat, args.samples, window = args.baseline_src or this, 1, 1, WINDOW
    elif args.baseline_src is None:
        ap.error("--baseline-src is required (or --quick)")
    ex = _example()
    if args.quick:
        cache = None  # the package's cache: the build is measured, not OpenSim
    else:
        cache = Path(tempfile.mkdtemp(prefix="mm-build-"))
        run_tree(this, ex, 0, cache)  # fills the geometry cache: OpenSim is not what is measured
    load = os.getloadavg()
    print(f"NLP build: {os.cpu_count()} cores, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    runs = {"this tree": [], "baseline": []}
    for _ in range(args.repeat):
        runs["this tree"].append(run_tree(this, ex, args.samples, cache, window))
        runs["baseline"].append(run_tree(args.baseline_src, ex, args.samples, cache, window))
    totals = {}
    print(f"{'tree':10s} {'units':>5s} {'build s':>8s} {'solve s':>8s} {'build share':>11s}")
    for tree, rs in runs.items():
        build = statistics.median(sum(u["build_s"] for u in r) for r in rs)
        solve = statistics.median(sum(u["solve_s"] for u in r) for r in rs)
        totals[tree] = (build, solve)
        print(f"{tree:10s} {len(rs[0]):5d} {build:8.2f} {solve:8.2f} {build / (build + solve):11.1%}")
    print("per unit, build s (first process of each tree):")
    for a, b in zip(runs["this tree"][0], runs["baseline"][0]):
        print(f"  {a['unit']:22s} {a['build_s']:6.3f} {b['build_s']:6.3f}")
    (b1, s1), (b0, s0) = totals["this tree"], totals["baseline"]
    diff = max(abs(a["objective"] - b["objective"]) / abs(b["objective"])
               for r1, r0 in zip(runs["this tree"], runs["baseline"]) for a, b in zip(r1, r0))
    print(f"this tree / baseline: build {b1 / b0:.2f}x, build + solve {(b1 + s1) / (b0 + s0):.2f}x; "
          f"largest relative objective difference {diff:.1e}")
    load = os.getloadavg()
    print(f"(medians of {args.repeat}; load average at the end {load[0]:.2f} {load[1]:.2f} {load[2]:.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
