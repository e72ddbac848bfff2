"""The input stage of ``solve_files``: from the file names to the call of the solver.

Times :func:`musclemetab.redundancy.solve_files` on one example trial (EFFORT-GEN) up to the
point where it hands its arrays to :func:`~musclemetab.redundancy.solve.solve_with_parameters` (the
model's joint tree and parameters, reading and checking the IK and ID files, the window, the
geometry from the cache): ``solve_with_parameters`` is replaced by a stub that stops the call there. Each
source tree runs in its own process, this tree and ``--baseline-src`` (e.g. the previous
version) in turn, ``--rounds`` times, so that both see the same machine load; in each process
the stage is run once untimed (imports, caches) and then ``--repeat`` times. Prints per tree
the median time of the stage, how often each input file was parsed (calls of
:func:`musclemetab.io.read_table`) and the ratio of the medians.

    python benchmarks/input_stage.py --baseline-src OTHER/src [--trial normal] [--repeat 50] [--rounds 3]
    python benchmarks/input_stage.py --quick

``--quick``: this tree against itself (unless ``--baseline-src``), one round of 3 timed runs, the
package's cache (``$MUSCLEMETAB_CACHE``: the geometry other runs computed) instead of a new one:
a check that the script runs (the test suite runs it so).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent

_STAGE = r"""
import collections, json, sys, time
import musclemetab.io as mio
import musclemetab.io.storage as storage

parses = collections.Counter()
_read = storage.read_table


def counting_read(path):
    parses[str(path).rsplit("/", 1)[-1]] += 1
    return _read(path)


storage.read_table = mio.read_table = counting_read  # before any module imports the name
import musclemetab.redundancy.problem as problem
import musclemetab.redundancy.run as run


class Stop(Exception):
    pass


def stop(*args, **kwargs):
    raise Stop


problem.solve_with_parameters = stop
model, ik, idf, repeat = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])


def stage():
    try:
        run.solve_files(model, ik, idf, "effort-gen")
    except Stop:
        pass


stage()  # imports, the OpenSim worker if needed, the caches: untimed
first = dict(parses)
times = []
for _ in range(repeat):
    t0 = time.perf_counter()
    stage()
    times.append(time.perf_counter() - t0)
print(json.dumps({"times_s": times, "parses": first}))
"""


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline-src", type=Path, help="the src folder of the tree to compare with (required "
                    "unless --quick)")
    ap.add_argument("--trial", default="normal", choices=("slow", "normal", "fast"))
    ap.add_argument("--repeat", type=int, default=50, help="timed runs of the stage per process")
    ap.add_argument("--rounds", type=int, default=3, help="processes per tree, alternating")
    ap.add_argument("--quick", action="store_true",
                    help="this tree against itself (unless --baseline-src), one round of 3 runs (the test suite runs "
                    "it so)")
    args = ap.parse_args(argv)
    if args.quick:
        args.baseline_src, args.repeat, args.rounds = args.baseline_src or HERE.parent / "src", 3, 1
    if args.baseline_src is None:
        ap.error("--baseline-src is required (or --quick)")
    sys.path.insert(0, str(HERE))
    from cold_start import run_in_tree
    from solver import _example

    ex = _example()
    trees = {"this tree": HERE.parent / "src", "baseline": args.baseline_src.resolve()}
    cache = None if args.quick else Path(tempfile.mkdtemp(prefix="mm-input-stage-"))  # quick: the package's
    times: dict[str, list[float]] = {k: [] for k in trees}
    parses = {}
    for _ in range(args.rounds):
        for name, src in trees.items():
            out = run_in_tree(_STAGE, src, ex, args.trial, cache, args.repeat, "the input stage")
            times[name] += out["times_s"]
            parses[name] = out["parses"]
    print(f"input stage of solve_files, example subject '{args.trial}', EFFORT-GEN, geometry and model cached; "
          f"median of {args.rounds} x {args.repeat} runs")
    for name in trees:
        files = ", ".join(f"{f} x{n}" for f, n in sorted(parses[name].items()))
        print(f"  {name:10s} {1e3 * statistics.median(times[name]):8.2f} ms   files parsed: {files}")
    ratio = statistics.median(times["this tree"]) / statistics.median(times["baseline"])
    print(f"  ratio this tree / baseline: {ratio:.3f}")


if __name__ == "__main__":
    main()
