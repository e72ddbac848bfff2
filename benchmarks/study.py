"""Benchmark: the demo end to end, and study throughput with 1 and 2 worker processes.

    python benchmarks/study.py [--repeats 1] [--study STUDY.toml | --two-subjects]
    python benchmarks/study.py --quick

1. ``musclemetab demo`` in a new process, with an empty geometry cache and an empty output
   folder: the wall time a new user waits (OpenSim worker start-up, geometry, six solves,
   metabolics, analysis, figures and the report). Target: under 60 s on 2 cores.
2. The demo's study (3 trials x 2 workflows = 6 units) run again with ``--force`` (warm
   geometry cache) with 1 worker process and with 2: units per minute and the speed-up of
   2 workers over 1 measured in the same run.
3. A resumed run (nothing to do): the cost of checking that every unit is up to date.

With ``--study STUDY.toml`` only 2 and 3 are measured, on that study (after one run that fills
the geometry and inverse-dynamics caches). ``--two-subjects`` writes and measures a study of two
subjects with different models and legs: the example subject's normal trial (Rajagopal model,
right leg, ID file) and OpenSim's gait2392 subject (its own model, ``side = "both"``: each leg
over its own gait cycle, inverse dynamics from the ground forces, the legs added), EFFORT-GEN
with every study model: three units (the example's right leg, gait2392's right and left legs)
scheduled together.

4. Warm-started chains against cold starts, in the same run (``--warm`` measures only this):
   the demo's study and a validation study of both shared subjects with the whole chain
   EFFORT-GEN -> EFFORT-CAL -> EFFORT-TEN (the example subject's three trials with its passive
   calibration and tendon stiffness; gait2392's subject on both legs, its triceps surae's
   tendons at kT = 20), each run with ``--warm-start`` and with ``--cold-start``. Prints
   per unit how it started, IPOPT's iterations and CPU time (``solve_cpu_time_s``, plus a failed
   warm attempt's), the objective's relative difference, and for each study the total IPOPT
   CPU time warm over cold, the same over the warm-started units alone,
   the NLP build's share of the units' time, and the largest differences of results.csv (rates
   relative, shares in percentage points) against the tolerance a warm start would have to meet
   to reproduce the cold study (:data:`WARM_TOLERANCE`, docs/study.md), then the largest
   relative differences of the whole-body rates and of the rates of the muscles above 1 % of
   their leg's against the 0.2 % a warm start would need to be the default
   (:data:`WARM_DEFAULT_RTOL`); the exit status is 1 when one is not met (gait2392's warm starts
   end in other optima: docs/study.md).

``--quick``: 2 and 3 alone, on a study of one unit (EFFORT-GEN of the normal trial cut to 0.6-0.8 s:
``benchmarks/_quick.py``) with the package's cache (``$MUSCLEMETAB_CACHE``) and
no run to fill it: a check that the script runs (the test suite runs it so).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _musclemetab(*args, env) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "musclemetab", *args], env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"musclemetab {' '.join(args)} failed:\n{proc.stdout}\n{proc.stderr}")
    return dt


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=1, help="repeats of each measurement (median reported)")
    ap.add_argument("--study", metavar="STUDY.toml", help="measure this study's throughput instead of the demo's")
    ap.add_argument("--warm", action="store_true", help="measure only the warm-started chains against cold starts (4.)")
    ap.add_argument("--two-subjects", action="store_true",
                    help="measure a two-subject study (example subject and gait2392, different models and legs)")
    ap.add_argument("--quick", action="store_true", help="2. and 3. on a study of one short unit, the package's cache")
    args = ap.parse_args(argv)
    import statistics

    tmp = Path(tempfile.mkdtemp(prefix="musclemetab-bench-study-"))
    env = dict(os.environ)
    print(f"machine: {os.cpu_count()} CPUs; output under {tmp}")

    if args.warm:
        return _warm_against_cold(tmp, env)
    if args.quick:
        from _quick import tiny_study
        from solver import _example

        return _throughput(tiny_study(_example(), tmp / "quick"), 1, env, 1)
    if args.two_subjects:
        args.study = _two_subject_study(tmp / "two-subjects.toml")
    if args.study:
        from musclemetab.study import load_study
        from musclemetab.study.units import plan_units

        env["MUSCLEMETAB_CACHE"] = str(tmp / "cache0")
        study = Path(args.study).resolve()
        n_units = sum(len(stage) for stage in plan_units(load_study(study)))
        _musclemetab("run", str(study), "--no-progress", "--workers", "2", env=env)  # fill the caches
        return _throughput(study, n_units, env, args.repeats)
    demo_times = []
    for i in range(args.repeats):
        env["MUSCLEMETAB_CACHE"] = str(tmp / f"cache{i}")  # cold geometry cache
        demo_times.append(_musclemetab("demo", "--out", str(tmp / f"demo{i}"), "--no-progress", env=env))
    demo_s = statistics.median(demo_times)
    print(f"\n1. demo end to end (cold cache, new process): {demo_s:.1f} s "
          f"(target < 60 s; {'met' if demo_s < 60 else 'NOT met'})")

    env["MUSCLEMETAB_CACHE"] = str(tmp / "cache0")
    code = _throughput(tmp / "demo0" / "study.toml", 6, env, args.repeats)
    return code or _warm_against_cold(tmp, env)


#: The agreement of a warm-started study with the cold one (docs/study.md, "Warm-started chains"):
#: objectives relative; rates, energies and costs of transport (results.csv) relative; shares
#: and toe-off in percentage points (absolute).
WARM_TOLERANCE = {"objective": 1e-4, "rates": 1e-3, "shares_pct": 0.1}


def _validation_study(path: Path) -> Path:
    """Both shared subjects with the chain EFFORT-GEN -> EFFORT-CAL -> EFFORT-TEN."""
    import json

    from musclemetab.datasets import SPEEDS, example_subject, gait2392_subject01

    ex, g = example_subject(), gait2392_subject01()

    def table(values: dict) -> list[str]:
        return [f"{k} = {json.dumps(v if isinstance(v, (int, float)) else str(v))}" for k, v in values.items()]

    lines = table({"name": "warm-start validation", "output": "out"})
    lines += ['workflows = ["effort-gen", "effort-cal", "effort-ten"]', "",
              "[[subjects]]", *table({"name": "example", "model": ex.model, "body_mass_kg": ex.body_mass_kg,
                                      "height_m": ex.height_m, "passive": ex.passive_moments_mat,
                                      "tendon_stiffness": "example"})]
    for speed in SPEEDS:
        lines += ["", "[[subjects.trials]]", *table({"name": speed, "ik": ex.ik[speed], "id": ex.id[speed]})]
    passive = _gait2392_passive(g.model, path.parent / "gait2392_passive.csv")
    lines += ["", "[[subjects]]", *table({"name": "gait2392", "model": g.model, "body_mass_kg": g.body_mass_kg,
                                          "height_m": g.height_m or 1.8, "side": "both", "passive": passive}),
              "[subjects.tendon_stiffness]",
              *[f"{m} = 20" for m in ("soleus", "med_gas", "lat_gas")],  # both legs' (base names)
              "", "[[subjects.trials]]",
              *table({"name": "walk1", "ik": g.ik, "external_loads": g.external_loads, "cycle": "auto"})]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def _gait2392_passive(model, path: Path) -> Path:
    """A passive calibration for gait2392's muscles (the data set has none): the published
    calibration where a muscle has the same name in the Rajagopal model, the generic parameters
    elsewhere, so that its EFFORT-CAL differs from EFFORT-GEN."""
    from musclemetab.model import read_muscle_parameters
    from musclemetab.passive import GENERIC_KPE, GENERIC_S0, GENERIC_SM, reference_passive_parameters

    names = list(read_muscle_parameters(model).names)
    published = reference_passive_parameters()
    rows = ["muscle,kPE,s0,sM"]
    for m in names:
        kpe, s0, sm = published.lookup(m) or (GENERIC_KPE, GENERIC_S0, GENERIC_SM)
        rows.append(f"{m},{kpe!r},{s0!r},{sm!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(rows) + "\n")
    return path


def _unit_solves(out: Path) -> dict:
    """``{unit folder: (start, iterations, IPOPT CPU s with a failed warm attempt, objective)}``."""
    import json

    units = {}
    for rec_file in sorted((out / "units").rglob("unit.json")):
        rec = json.loads(rec_file.read_text())
        summary = rec_file.with_name("summary.json")
        if rec.get("trial") is None or not summary.is_file():
            continue
        s = json.loads(summary.read_text())
        cpu = float(s["solve_cpu_time_s"]) + float((rec.get("times") or {}).get("warm_attempt_ipopt_cpu_s") or 0.0)
        units[str(rec_file.parent.relative_to(out / "units"))] = (rec.get("start", "cold"), s["iterations"], cpu,
                                                                  float(s["objective"]))
        _BUILD.setdefault(out, []).append((float(s["build_time_s"]), float(s["solve_time_s"]),
                                           float(rec["times"]["total_s"])))
    return units


#: ``{study folder: [(NLP build s, IPOPT solve s, unit total s)]}`` of the units read by :func:`_unit_solves`
_BUILD: dict = {}


def _compare_results(warm: Path, cold: Path) -> dict:
    """The largest differences of the two results tables: ``{"rates": relative, "shares_pct": points}``."""
    import numpy as np
    import pandas as pd

    key = ["subject", "trial", "workflow", "model"]
    a = pd.read_csv(warm / "results.csv").sort_values(key, ignore_index=True)
    b = pd.read_csv(cold / "results.csv").sort_values(key, ignore_index=True)
    assert (a[key].values == b[key].values).all(), "the two studies have other rows"
    worst = {"rates": (0.0, ""), "shares_pct": (0.0, "")}
    for c in a.columns:
        if c in key or not pd.api.types.is_numeric_dtype(a[c]) or a[c].dtype == bool:
            continue
        x, y = a[c].to_numpy(float), b[c].to_numpy(float)
        if c.endswith("_pct"):
            d = np.abs(x - y)
            kind = "shares_pct"
        else:
            d = np.abs(x - y) / np.maximum(np.abs(y), 1e-12)
            kind = "rates"
        d = np.nan_to_num(d, nan=0.0)
        if d.size and d.max() > worst[kind][0]:
            i = int(d.argmax())
            worst[kind] = (float(d.max()), f"{c} of {'/'.join(str(a.loc[i, k]) for k in key)}")
    return worst


#: The agreement a warm start needs to be the default of a study, with the default stop: each whole-body
#: rate (six models, basal heat included) and the rate of each muscle above 1 % of its leg's within
#: 0.2 % relative of the cold study's (docs/study.md, "Warm-started chains")
WARM_DEFAULT_RTOL = 2e-3


def _compare_rates(warm: Path, cold: Path) -> dict:
    """The largest relative differences of the whole-body rates (results.csv) and of the rates of the
    muscles above 1 % of their leg's (per_muscle.csv, by the cold study's shares), with where."""
    import pandas as pd

    worst = {}
    for name, table, key, column in (
            ("whole-body rates", "results.csv", ["subject", "trial", "workflow", "model"], "whole_body_W_per_kg"),
            ("muscles above 1 % of the leg", "per_muscle.csv",
             ["subject", "trial", "workflow", "model", "muscle", "side"], "muscle_W")):
        a = pd.read_csv(warm / table).set_index(key).sort_index()
        b = pd.read_csv(cold / table).set_index(key).sort_index()
        assert a.index.equals(b.index), f"the two studies' {table} have other rows"
        if column == "muscle_W":
            a, b = a[b["share_of_leg_pct"] > 1.0], b[b["share_of_leg_pct"] > 1.0]
        d = ((a[column] - b[column]) / b[column]).abs()
        worst[name] = (float(d.max()), "/".join(str(v) for v in d.idxmax()))
    return worst


def _warm_against_cold(tmp: Path, env) -> int:
    """4.: every study run warm and cold; IPOPT CPU time and the agreement of the results."""
    ok = True
    env = dict(env, MUSCLEMETAB_CACHE=env.get("MUSCLEMETAB_CACHE") or str(tmp / "cache0"))
    studies = {"demo": None, "both subjects, GEN -> CAL -> TEN": _validation_study(tmp / "validation" / "study.toml")}
    print("\n4. warm-started chains against cold starts (IPOPT CPU time: summary.json solve_cpu_time_s)")
    for name, study in studies.items():
        outs = {}
        for start in ("cold", "warm"):
            flags = ["--cold-start"] if start == "cold" else ["--warm-start"]
            out = tmp / f"{'demo' if study is None else 'validation'}-{start}"
            if study is None:
                _musclemetab("demo", "--out", str(out), "--workers", "2", "--no-progress", *flags, env=env)
            else:
                _musclemetab("run", str(study), "--out", str(out), "--workers", "2", "--no-progress", *flags, env=env)
            outs[start] = out
        warm, cold = _unit_solves(outs["warm"]), _unit_solves(outs["cold"])
        print(f"\n   {name}")
        print(f"   {'unit':<34} {'start (warm run)':<22} {'iter w/c':>9} {'CPU s w/c':>12} {'objective rel diff':>19}")
        worst_obj, cpu, chained = 0.0, {"warm": 0.0, "cold": 0.0}, {"warm": 0.0, "cold": 0.0}
        for unit, (start, it, c, f) in warm.items():
            _, it0, c0, f0 = cold[unit]
            rel = abs(f - f0) / abs(f0)
            worst_obj = max(worst_obj, rel)
            cpu["warm"] += c
            cpu["cold"] += c0
            if start != "cold":
                chained["warm"] += c
                chained["cold"] += c0
            print(f"   {unit:<34} {start[:22]:<22} {it:>4}/{it0:<4} {c:>5.2f}/{c0:<6.2f} {rel:>19.1e}")
        worst = _compare_results(outs["warm"], outs["cold"])
        for start in ("warm", "cold"):  # docs/solver.md: is building the NLP once per worker worth it?
            build, solve, total = (sum(x) for x in zip(*_BUILD[outs[start]]))
            print(f"   {start} run: NLP build {build:.1f} s, IPOPT {solve:.1f} s, units {total:.1f} s (wall, "
                  f"--workers 2): build {100 * build / total:.1f} % of the units' time")
        ratio = cpu["warm"] / cpu["cold"]
        print(f"   total IPOPT CPU time: warm {cpu['warm']:.1f} s, cold {cpu['cold']:.1f} s: {ratio:.2f}x")
        if chained["cold"]:
            print(f"   the warm-started units alone: {chained['warm']:.1f} s against {chained['cold']:.1f} s cold: "
                  f"{chained['warm'] / chained['cold']:.2f}x")
        checks = [("objective", worst_obj, "every unit"), ("rates", *worst["rates"]),
                  ("shares_pct", *worst["shares_pct"])]
        for what, value, where in checks:
            met = value <= WARM_TOLERANCE[what]
            ok = ok and met
            unit = " points" if what == "shares_pct" else " relative"
            print(f"   largest difference, {what}: {value:.2e}{unit} ({where}); tolerance {WARM_TOLERANCE[what]:g}: "
                  f"{'met' if met else 'NOT met'}")
        for what, (value, where) in _compare_rates(outs["warm"], outs["cold"]).items():
            met = value <= WARM_DEFAULT_RTOL
            ok = ok and met
            print(f"   largest difference, {what}: {100 * value:.4f} % ({where}); a default warm start needs "
                  f"{100 * WARM_DEFAULT_RTOL:g} %: {'met' if met else 'NOT met'}")
    return 0 if ok else 1


def _two_subject_study(path: Path) -> Path:
    """Write the two-subject study file (data from :mod:`musclemetab.datasets`)."""
    import json

    from musclemetab.datasets import example_subject, gait2392_subject01

    ex, g = example_subject(), gait2392_subject01()
    subjects = [
        ({"name": "example", "model": ex.model, "body_mass_kg": ex.body_mass_kg, "height_m": ex.height_m},
         {"name": "normal", "ik": ex.ik["normal"], "id": ex.id["normal"]}),
        # the data set gives no height (used for the speed normalisation only): 1.8 m
        ({"name": "gait2392", "model": g.model, "body_mass_kg": g.body_mass_kg, "height_m": g.height_m or 1.8,
          "side": "both"},
         {"name": "walk1", "ik": g.ik, "external_loads": g.external_loads, "cycle": "auto"}),
    ]

    def table(values: dict) -> list[str]:  # TOML values: JSON strings and numbers are valid TOML
        return [f"{k} = {json.dumps(v if isinstance(v, (int, float)) else str(v))}" for k, v in values.items()]

    lines = table({"name": "two subjects", "output": "out"}) + ['workflows = ["effort-gen"]']
    for subject, trial in subjects:
        lines += ["", "[[subjects]]", *table(subject), "", "[[subjects.trials]]", *table(trial)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _throughput(study, n_units, env, repeats) -> int:
    import statistics

    rates = {}
    for workers in (1, 2):
        times = [_musclemetab("run", str(study), "--force", "--no-progress", "--workers", str(workers), env=env)
                 for _ in range(repeats)]
        rates[workers] = statistics.median(times)
    print(f"\n2. study throughput ({n_units} units of {study}; warm geometry cache)")
    print(f"{'workers':>8} {'wall s':>8} {'units/min':>10} {'s/unit':>8}")
    for w, s in rates.items():
        print(f"{w:>8} {s:>8.1f} {60 * n_units / s:>10.1f} {s / n_units:>8.2f}")
    print(f"speed-up of 2 workers over 1 (same run): {rates[1] / rates[2]:.2f}x")

    resumed = statistics.median(
        [_musclemetab("run", str(study), "--no-progress", env=env) for _ in range(max(1, repeats))]
    )
    print(f"\n3. resumed run, every unit up to date: {resumed:.2f} s "
          f"({rates[1] / resumed:.0f}x faster than recomputing with 1 worker)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
