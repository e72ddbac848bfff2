"""Benchmark: muscle geometry for one gait cycle, cold and cached, against OpenSim's AnalyzeTool.

    python benchmarks/geometry.py [--trial normal] [--repeats 3]

Measured in the same run, on the example subject (119 frames of the normal trial, 40
muscles, 5 DOFs):

* AnalyzeTool with MuscleAnalysis (lengths, moment arms and moments of all 80 muscles),
  in a fresh process: OpenSim import and model load reported apart from the run;
* musclemetab cold: a fresh OpenSim worker (its start-up, i.e. process start and
  ``import opensim``, reported apart), model load, lengths and moment arms;
* musclemetab cached: the same call again (reads the on-disk cache).

Prints seconds and ratios; asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trial", default="normal", choices=("slow", "normal", "fast"))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true",
                    help="one run over the trial's first 10 frames (seconds; the test suite runs it so)")
    args = ap.parse_args()
    if args.quick:
        args.repeats = 1

    from musclemetab import opensim_bridge
    from musclemetab.datasets import example_subject
    from musclemetab.geometry import compute_geometry
    from musclemetab.io import read_storage
    from musclemetab.model import default_dofs

    ex = example_subject()
    ik_path = ex.ik[args.trial]
    ik = read_storage(ik_path)
    if args.quick:  # the first 10 frames, for AnalyzeTool and musclemetab alike
        from musclemetab.io import write_storage

        ik, ik_path = ik.iloc[:10], Path(tempfile.mkdtemp(prefix="geometry_bench_")) / Path(ik_path).name
        write_storage(ik_path, ik, in_degrees=bool(read_storage(ex.ik[args.trial]).attrs.get("in_degrees")))
        ik = read_storage(ik_path)
    dofs = default_dofs("r")

    base_runs, cold_runs, start_runs, cached_runs, load_runs = [], [], [], [], []
    for _ in range(args.repeats):
        r = subprocess.run(
            [sys.executable, str(Path(__file__).with_name("_analyzetool_baseline.py")), str(ex.model), str(ik_path),
             str(ik.index[0]), str(ik.index[-1]), ",".join(dofs)],
            capture_output=True, text=True, check=True,
        )
        base_runs.append(json.loads(r.stdout.strip().splitlines()[-1]))

        opensim_bridge.shutdown()
        with tempfile.TemporaryDirectory() as cache:
            t0 = time.perf_counter()
            opensim_bridge.call("model_ops:read_model_info", str(ex.model))  # starts the worker, loads the model
            t_first = time.perf_counter() - t0
            start_runs.append(opensim_bridge.worker_startup_s())
            load_runs.append(t_first - opensim_bridge.worker_startup_s())
            t1 = time.perf_counter()
            g = compute_geometry(ex.model, ik_path, cache_dir=cache)
            cold_runs.append(time.perf_counter() - t1)
            t2 = time.perf_counter()
            g2 = compute_geometry(ex.model, ik_path, cache_dir=cache)
            cached_runs.append(time.perf_counter() - t2)
            assert g2.source["cached"]

    med = statistics.median
    at_run = med(b["run_s"] for b in base_runs)
    at_start = med(b["import_s"] + b["load_s"] for b in base_runs)
    cold = med(cold_runs)
    print(f"trial {args.trial}: {len(g.time)} frames, {len(g.muscles)} muscles, {len(g.dofs)} DOFs; "
          f"median of {args.repeats} runs")
    print(f"  OpenSim AnalyzeTool MuscleAnalysis run      {at_run:8.3f} s   (+ import and model load {at_start:.3f} s)")
    print(f"  musclemetab cold (lengths + moment arms)    {cold:8.3f} s   "
          f"(+ worker start {med(start_runs):.3f} s, model load {med(load_runs):.3f} s)")
    print(f"  musclemetab cached                          {med(cached_runs):8.4f} s")
    print(f"  ratio AnalyzeTool / cold                    {at_run / cold:8.1f} x")
    print(f"  ratio AnalyzeTool / cold incl. model load   {at_run / (cold + med(load_runs)):8.1f} x")
    print(f"  ratio AnalyzeTool / cached                  {at_run / med(cached_runs):8.0f} x")


if __name__ == "__main__":
    main()
