"""Uncertainty samples: their cost, and the coverage of their bands (docs/uncertainty.md).

Three parts, on the example subject's normal trial with EFFORT-GEN (``--parts`` picks some):

``warm``
    For samples 0 .. ``--compare``-1 of the package's priors: the solve of the sampled
    parameters from the static-optimisation guess (cold) and warm-started from the nominal
    solution's optimum and multipliers (:func:`musclemetab.uncertainty.sample_start`, as a study's
    samples are). Prints IPOPT's iterations, solve time and CPU time of each and the mean ratio
    warm / cold of the solve times.
``study``
    ``musclemetab run`` of a one-trial study with ``--uncertainty N`` (default 64) on
    ``--workers`` processes (default 2): the wall time of the samples (the nominal unit run
    before, not timed) and the band of the whole-body rate.
``coverage``
    Synthetic truths: ``--truths`` (default 30) further samples with another seed stand for
    subjects whose parameters are drawn from the prior; each one's rates (whole body per model,
    and per muscle) are compared with the bands of the nominal model from the ``study`` part.
    Prints the share of truths inside the 5-95 % band (stated rate 90 %), per model and over
    the muscles.

    python benchmarks/uncertainty.py [--parts warm study coverage] [--samples 64] [--truths 30]
        [--compare 4] [--workers 2] [--out DIR]
    python benchmarks/uncertainty.py --quick

``--quick``: every part on the window 0.6-0.8 s of the normal trial (``warm``: ``solve_files(window=...)``;
the study: the trial cut to that window, ``benchmarks/_quick.py``), one sample compared, 2 samples on
one worker, whose own samples stand for the truths of ``coverage`` (no second study), the package's
cache (``$MUSCLEMETAB_CACHE``): a check that the script runs (the test suite runs it so); its numbers
say nothing of a whole trial's.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
MODELS = ["UM10", "BH04", "UC16", "LW07"]

STUDY = """name = "uncertainty benchmark"
output = "out"
workflows = ["effort-gen"]
models = {models}

[uncertainty]
samples = {samples}
seed = {seed}

[[subjects]]
name = "sub1"
model = "{model}"
body_mass_kg = {mass}
height_m = {height}

[[subjects.trials]]
name = "normal"
ik = "{ik}"
id = "{id}"
"""


def _example():
    sys.path.insert(0, str(HERE))
    from solver import _example as example  # the benchmarks' one way to locate the example data

    return example()


def warm_against_cold(ex, n: int, window=None) -> None:
    import functools

    from musclemetab.redundancy.run import solve_files
    from musclemetab.uncertainty import draw, read_priors, sample_start

    args = (ex.model, ex.ik["normal"], ex.id["normal"], "effort-gen")
    solve_files = functools.partial(solve_files, window=window)
    nominal = solve_files(*args)
    print(f"nominal solve: {nominal.record.iterations} iterations, {nominal.record.solve_time_s:.2f} s")
    priors = read_priors()
    ratios = []
    print(f"{'sample':>6} {'cold it':>8} {'cold s':>8} {'warm it':>8} {'warm s':>8} {'ratio':>6} {'objective cold / warm':>24}"
          f" {'CPU s cold / warm':>18}")
    for k in range(n):
        factors = draw(priors, nominal.muscles, k, 1)
        cold = solve_files(*args, parameter_transform=factors.parameters)
        warm = solve_files(*args, parameter_transform=factors.parameters,
                           warm_start=sample_start(nominal, factors.parameters(nominal.parameters)))
        ratio = warm.record.solve_time_s / cold.record.solve_time_s
        ratios.append(ratio)
        print(f"{k:>6} {cold.record.iterations:>8} {cold.record.solve_time_s:>8.2f} {warm.record.iterations:>8} "
              f"{warm.record.solve_time_s:>8.2f} {ratio:>6.2f} {cold.objective:>11.6g} / {warm.objective:<11.6g} "
              f"{cold.record.solve_cpu_time_s:>8.2f} / {warm.record.solve_cpu_time_s:<8.2f}")
    print(f"mean solve time of a warm-started sample / cold solve: {sum(ratios) / len(ratios):.2f} (target <= 0.5)",
          flush=True)


def _study(ex, root: Path, samples: int, seed: int, quick: bool = False) -> Path:
    if quick:
        from _quick import tiny_study

        # flagged samples kept: the quick run's samples of a 0.2 s window are a check of the code path, and
        # its bands must exist whatever the samples' flags
        return tiny_study(ex, root, models=MODELS,
                          extra=f"\n[uncertainty]\nsamples = {samples}\nseed = {seed}\nkeep_flagged = true")
    root.mkdir(parents=True, exist_ok=True)
    path = root / "study.toml"
    path.write_text(STUDY.format(models=str(MODELS).replace("'", '"'), samples=samples, seed=seed, model=ex.model,
                                 mass=ex.body_mass_kg, height=ex.height_m, ik=ex.ik["normal"], id=ex.id["normal"]))
    return path


def _run(path: Path, workers: int, extra=()) -> float:
    env = dict(os.environ, PYTHONPATH=str(HERE.parent / "src"))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "musclemetab", "run", str(path), "--workers", str(workers),
                           "--no-progress", *extra], capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"musclemetab run {path} failed:\n{proc.stdout}\n{proc.stderr[-3000:]}")
    return wall


def study_time(ex, root: Path, samples: int, workers: int, quick: bool = False) -> Path:
    path = _study(ex, root / "bands", samples, 1, quick)
    nominal = _run(path, workers, ["--uncertainty", "0"])  # the trial unit alone
    wall = _run(path, workers)
    import pandas as pd

    results = pd.read_csv(path.parent / "out" / "results.csv")
    print(f"trial unit alone: {nominal:.1f} s; then {samples} samples of it on {workers} workers: {wall:.1f} s wall "
          f"({wall / samples:.2f} s per sample)")
    cols = ["model", "whole_body_W_per_kg", "whole_body_W_per_kg_p05", "whole_body_W_per_kg_p50",
            "whole_body_W_per_kg_p95", "uncertainty_samples"]
    print(results[cols].round(3).to_string(index=False))
    return path.parent / "out"


def coverage(ex, root: Path, bands_out: Path, truths: int, workers: int, quick: bool = False) -> None:
    """The ``coverage`` part (``quick``: the truths are the samples of the study of ``bands_out``)."""
    import numpy as np
    import pandas as pd

    from musclemetab.study.runner import add_leg_rows, leg_basal_energy_J, trial_result_rows
    from musclemetab.study.spec import load_study
    from musclemetab.study.uncertainty import sample_tables

    if quick:  # the bands' own samples stand for the truths: the code path, not a coverage
        path = bands_out.parent / "study.toml"
    else:
        path = _study(ex, root / "truths", truths, 2)
        _run(path, workers)
    truth_wb, truth_pm = sample_tables(load_study(path), trial_result_rows, add_leg_rows, leg_basal_energy_J)
    # the bands speak of plausible subjects: flagged and unconverged truths are left out as samples are
    if not quick:
        truth_wb, truth_pm = (t[t["sample_flags"].fillna("").astype(str) == ""] for t in (truth_wb, truth_pm))
    results = pd.read_csv(bands_out / "results.csv").set_index("model")
    per_muscle = pd.read_csv(bands_out / "per_muscle.csv").set_index(["model", "muscle"])
    print(f"\ncoverage of the nominal model's bands over {truth_wb['sample'].nunique()} "
          f"{'' if quick else 'plausible '}truths "
          "(stated: musclemetab.uncertainty.expected_coverage of the band's samples):")
    for model in MODELS:
        t = truth_wb[truth_wb["model"] == model]["whole_body_W_per_kg"].to_numpy()
        if t.size == 0:
            print(f"  {model} whole body: no plausible truth")
            continue
        lo, hi = results.loc[model, "whole_body_W_per_kg_p05"], results.loc[model, "whole_body_W_per_kg_p95"]
        inside = np.mean((t >= lo) & (t <= hi))
        print(f"  {model} whole body: {100 * inside:.0f} % inside [{lo:.3f}, {hi:.3f}] W/kg "
              f"(nominal {results.loc[model, 'whole_body_W_per_kg']:.3f}; truths {t.min():.3f}-{t.max():.3f})")
    for model in MODELS:
        t = truth_pm[truth_pm["model"] == model].set_index(["model", "muscle"])
        b = per_muscle.loc[t.index]
        inside = (t["muscle_W"].to_numpy() >= b["muscle_W_p05"].to_numpy()) & \
                 (t["muscle_W"].to_numpy() <= b["muscle_W_p95"].to_numpy())
        print(f"  {model} per muscle (muscle_W, {inside.size} truth x muscle pairs): {100 * inside.mean():.0f} % inside")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parts", nargs="+", default=["warm", "study", "coverage"], choices=("warm", "study", "coverage"))
    ap.add_argument("--samples", type=int, default=64)
    ap.add_argument("--truths", type=int, default=30)
    ap.add_argument("--compare", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", help="folder for the studies (default: a new temporary folder)")
    ap.add_argument("--quick", action="store_true", help="every part on the normal trial's window 0.6-0.8 s, "
                    "1 sample compared, 2 samples (the truths too), one worker")
    args = ap.parse_args()
    window = None
    if args.quick:
        from _quick import WINDOW

        args.compare, args.samples, args.truths, args.workers, window = 1, 2, 2, 1, WINDOW
    warnings.simplefilter("ignore")
    ex = _example()
    root = Path(args.out or tempfile.mkdtemp(prefix="mm-uncertainty-"))
    print(f"studies in {root}")
    if "warm" in args.parts:
        warm_against_cold(ex, args.compare, window)
    bands = root / "bands" / "out"
    if "study" in args.parts:
        bands = study_time(ex, root, args.samples, args.workers, args.quick)
    if "coverage" in args.parts:
        coverage(ex, root, bands, args.truths, args.workers, args.quick)


if __name__ == "__main__":
    main()
