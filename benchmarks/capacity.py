"""Capacity plan of a study: per-unit CPU and memory, the executors' overhead per unit, and the
projected wall time and memory of a 1000-trial study on 8, 64 and 512 cores.

    python benchmarks/capacity.py [--small-units 200]
    python benchmarks/capacity.py --quick

1. Per unit (the demo's study: the example subject's 3 trials x EFFORT-GEN -> EFFORT-TEN,
   warm-started, a new geometry cache): ``musclemetab run --workers 1`` in a new process; its CPU
   time (the process and every process it started, OpenSim's worker included) per unit, and the
   peak memory of the process tree (resident set, sampled every 50 ms with psutil). The IPOPT CPU
   time of each unit from its ``summary.json``; the time of gathering the results table
   (``collect_results``, serial in the calling process) per unit.
2. Overhead per unit of the executors on a study of many small units: ``N`` trial units whose
   IK file is not a motion file, so that each unit fails at once after the whole path of a unit
   (planning, key, submission, the unit's folder and record, the result sent back): run with
   ``--workers 1`` (in process), a process pool of 2 and a Dask ``LocalCluster`` of 2 worker
   processes (one thread each). The wall time per unit of each is the executor's cost per unit,
   with nothing else in it; the CPU time of the calling process per unit (with Dask, the
   scheduler's too: a ``LocalCluster`` runs it in the calling process) is the serial part that
   more cores do not shorten.
3. The projection of a 1000-trial study (2000 units: EFFORT-GEN then EFFORT-TEN warm-started, the
   demo's units) on 8, 64 and 512 cores, one worker process per core: wall time =
   units x CPU per unit / cores + the serial parts (planning and gathering per unit, the
   scheduler's cost per unit) and the tail of the last units; memory = cores x the peak memory of
   one worker (its OpenSim worker included) + the client's.

``--quick``: 1. on a study of two units (EFFORT-GEN -> EFFORT-TEN of the normal trial cut to
0.6-0.8 s: ``benchmarks/_quick.py``) with the package's cache (``$MUSCLEMETAB_CACHE``), 2. on 4 units
without Dask (the process pool's cost stands for the scheduler's in 3.): a check that the script
runs (the test suite runs it so); its numbers say nothing of the demo's.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path


def _tree_peak_rss(proc: subprocess.Popen, stop: threading.Event, out: list) -> None:
    """Sample the resident memory of ``proc`` and its descendants until ``stop``; the peak in ``out``."""
    import psutil

    peak = 0
    try:
        root = psutil.Process(proc.pid)
    except psutil.NoSuchProcess:
        out.append(0)
        return
    while not stop.is_set():
        total = 0
        try:
            procs = [root] + root.children(recursive=True)
        except psutil.NoSuchProcess:
            break
        for p in procs:
            try:
                total += p.memory_info().rss
            except psutil.NoSuchProcess:
                pass
        peak = max(peak, total)
        stop.wait(0.05)
    out.append(peak)


def _measured_run(args: list[str], env) -> tuple[float, float, int]:
    """``(wall s, CPU s of the process tree, peak resident bytes of the tree)`` of ``musclemetab ARGS``."""
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "musclemetab", *args], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    stop, peak = threading.Event(), []
    sampler = threading.Thread(target=_tree_peak_rss, args=(proc, stop, peak))
    sampler.start()
    stdout, stderr = proc.communicate()
    stop.set()
    sampler.join()
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        sys.exit(f"musclemetab {' '.join(args)} failed:\n{stdout}\n{stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, peak[0] if peak else 0


def per_unit(tmp: Path, env, quick: bool = False) -> dict:
    """1.: the demo's study with one worker, a new geometry cache (``quick``: a study of two short
    units, the package's cache)."""
    from musclemetab.study import load_study
    from musclemetab.study.demo import demo_study
    from musclemetab.study.runner import collect_results
    from musclemetab.study.units import plan_units

    if quick:
        from _quick import tiny_study
        from solver import _example

        study = load_study(tiny_study(_example(), tmp / "units", workflows=("effort-gen", "effort-ten"), models="all"))
    else:
        env = dict(env, MUSCLEMETAB_CACHE=str(tmp / "cache-units"))
        study = demo_study(tmp / "units", models="all")
    n = sum(len(s) for s in plan_units(study))
    wall, cpu, peak = _measured_run(["run", str(study.source), "--workers", "1", "--no-progress", "--warm-start"], env)
    ipopt = []
    for f in sorted((study.output / "units").rglob("summary.json")):
        ipopt.append(float(json.loads(f.read_text())["solve_cpu_time_s"]))
    collect_results(load_study(study.source))  # the imports (pandas, the data dictionary's tables): once
    t0, c0 = time.perf_counter(), time.process_time()
    collect_results(load_study(study.source))
    gather, gather_cpu = (time.perf_counter() - t0) / n, (time.process_time() - c0) / n
    return {"units": n, "wall_s": wall / n, "cpu_s": cpu / n, "ipopt_cpu_s": sum(ipopt) / len(ipopt),
            "peak_bytes": peak, "gather_s": gather_cpu, "gather_wall_s": gather}


def _small_study(folder: Path, n: int) -> Path:
    """A study of ``n`` trial units that each fail at once (the IK file is not a motion file)."""
    from musclemetab.datasets import example_subject

    ex = example_subject()
    folder.mkdir(parents=True, exist_ok=True)
    bad = folder / "not_a_motion.mot"
    bad.write_text("this is not a motion file\n")
    lines = ['name = "small units"', 'output = "out"', 'workflows = ["effort-gen"]', 'models = ["UM10"]', "",
             "[[subjects]]", 'name = "s"', f'model = "{ex.model}"', "body_mass_kg = 70", "height_m = 1.7"]
    for i in range(n):
        lines += ["", "[[subjects.trials]]", f'name = "t{i:04d}"', f'ik = "{bad}"', f'id = "{ex.id["normal"]}"']
    path = folder / "study.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def executor_overhead(tmp: Path, n: int, dask: bool = True) -> dict:
    """2.: wall time per unit of units that do nothing, in process, on a pool of 2, on Dask (2 processes)."""
    from musclemetab.study import load_study
    from musclemetab.study.runner import run_study

    study = load_study(_small_study(tmp / "small", n))
    result = {}
    run_study(study, workers=1, progress=False)  # the model's names and the file hashes: read once
    for label, kwargs in (("in process (--workers 1)", {"workers": 1}),
                          ("process pool of 2 (--workers 2)", {"workers": 2})):
        t0, c0 = time.perf_counter(), time.process_time()
        run = run_study(study, force=True, progress=False, **kwargs)
        result[label] = ((time.perf_counter() - t0) / n, (time.process_time() - c0) / n)
        assert len(run.failed) == n
    try:
        if not dask:
            return result
        from distributed import LocalCluster
    except ImportError:
        return result
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        run_study(study, scheduler=cluster.scheduler_address, force=True, progress=False)  # workers import
        t0, c0 = time.perf_counter(), time.process_time()  # the scheduler runs in this process: its CPU counts
        run = run_study(study, scheduler=cluster.scheduler_address, force=True, progress=False)
        result["Dask LocalCluster, 2 worker processes"] = ((time.perf_counter() - t0) / n, (time.process_time() - c0) / n)
        assert len(run.failed) == n
    return result


def projection(unit: dict, overhead: dict, trials: int = 1000, units_per_trial: int = 2) -> list[tuple]:
    """3.: ``[(cores, wall h, memory GiB)]`` for a study of ``trials`` x ``units_per_trial`` units."""
    n = trials * units_per_trial
    # the calling process's CPU per unit (the Dask scheduler's included): the part no added core shortens
    sched = overhead.get("Dask LocalCluster, 2 worker processes", overhead.get("process pool of 2 (--workers 2)"))[1]
    rows = []
    for cores in (8, 64, 512):
        # every unit's CPU spread over the cores (a trial's chain is 2 units deep, 1000 chains: no core idles
        # for lack of ready units until the last round), the last round's tail (one unit), and the serial
        # parts in the calling process: the scheduler's cost per unit and the gathering of the results
        work = n * unit["cpu_s"] / cores
        tail = unit["cpu_s"] * units_per_trial
        serial = n * (sched + unit["gather_s"])
        wall_h = (work + tail + serial) / 3600
        memory = cores * unit["peak_bytes"] + 2 * 1024**3  # + the client and the scheduler
        rows.append((cores, wall_h, memory / 1024**3, work / 3600, serial / 3600))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--small-units", type=int, default=200, help="units of the overhead study (2.)")
    ap.add_argument("--quick", action="store_true", help="two short units in 1., 4 units and no Dask in 2.")
    args = ap.parse_args(argv)
    if args.quick:
        args.small_units = 4
    tmp = Path(tempfile.mkdtemp(prefix="musclemetab-bench-capacity-"))
    env = dict(os.environ)
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}; output under {tmp}")
    unit = per_unit(tmp, env, args.quick)
    print(f"\n1. per unit ({'a quick study' if args.quick else 'the demo'}'s {unit['units']} units, EFFORT-GEN -> "
          f"EFFORT-TEN warm-started, --workers 1, {'the package' if args.quick else 'new geometry'} cache)")
    print(f"   CPU {unit['cpu_s']:.2f} s per unit (IPOPT {unit['ipopt_cpu_s']:.2f} s of it), wall {unit['wall_s']:.2f} s; "
          f"peak memory of the run (one unit at a time, its OpenSim worker included) "
          f"{unit['peak_bytes'] / 1024**2:.0f} MiB; gathering the results {1000 * unit['gather_s']:.1f} CPU ms "
          f"({1000 * unit['gather_wall_s']:.1f} ms wall) per unit")
    overhead = executor_overhead(tmp, args.small_units, dask=not args.quick)
    print(f"\n2. cost per unit of the executors ({args.small_units} units that fail at once)")
    print(f"   {'executor':<40} {'wall ms':>8} {'calling process CPU ms':>23}  (per unit)")
    for label, (wall, cpu) in overhead.items():
        print(f"   {label:<40} {1000 * wall:8.1f} {1000 * cpu:23.1f}")
    print("\n3. a 1000-trial study (2000 units: EFFORT-GEN -> EFFORT-TEN), one worker process per core")
    print(f"   {'cores':>6} {'wall h':>8} {'of it serial h':>15} {'memory GiB':>11}")
    for cores, wall_h, mem, _, serial_h in projection(unit, overhead):
        print(f"   {cores:>6} {wall_h:>8.2f} {serial_h:>15.3f} {mem:>11.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
