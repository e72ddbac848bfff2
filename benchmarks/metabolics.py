"""Benchmark: metabolic energy models on a large array, against OpenSim's probes.

    python benchmarks/metabolics.py [--muscles 40] [--samples 50000] [--probe-states all] [--repeats 5]
                                    [--baseline-src PATH] [--no-pipeline]

Measured in the same run, on the same states:

* each model of :mod:`musclemetab.metabolics` (the study's six and the additional ones) on
  arrays of shape (muscles, samples) (default 40 x 50 000 = 2 million muscle-samples;
  realistic states: fiber lengths, velocities and activations drawn at random, curve values
  from the package's curves), input checks included; ``--repeats`` timed calls after one
  untimed warm-up call;
* OpenSim 4.6's ``Umberger2010MuscleMetabolicsProbe`` (UM10 settings) and
  ``Bhargava2004MuscleMetabolicsProbe`` (BH04 settings), each alone in a one-muscle model
  (the example soleus on a slider, rigid tendon), evaluated in the OpenSim worker process at
  the same states (fiber length, velocity, activation and excitation of every muscle-sample,
  in order): per state, set the fiber length, velocity, activation and excitation, realise to
  accelerations and read the probe's output (the least work OpenSim needs to evaluate a probe
  at a given state; process start, model building and the transfer of arrays are not
  counted). The states are cut into ``--repeats`` blocks, one per repeat, so that the probes
  evaluate every state once (``--probe-states N``: only the first N states, for a quick run),
  after one untimed warm-up call on 1000 states.

``--baseline-src PATH``: the models of another source tree (``PATH/src/musclemetab``, e.g. a
``git worktree`` of an earlier commit) are imported in the same process under another name and
timed in the same repeats, on the same arrays (which of the two goes first alternates from
repeat to repeat); printed: this tree's time over the other
tree's (new/old, < 1 is faster), median to median and best to best, and the largest
difference of any component between the two, relative to the size of the muscle-sample's
components (``|new - old| / max(|old|, sum of |component|)``, every component but ``total``,
extras included: a heat that is the difference of two large terms is compared with them). A ratio of the same run does not depend on the
machine's load as much as a rate does.

Pipeline row (unless ``--no-pipeline``): one example trial (``normal``, EFFORT-GEN) is solved
once (not timed; casadi in this process, OpenSim in its worker), written to a temporary
folder, then per repeat: :func:`~musclemetab.metabolics.solution.metabolics_from_solution`
with every model (``all,LW05,MA68``) from that folder plus
:func:`~musclemetab.metabolics.solution.write_metabolics` (``metabolics.sto``,
``metabolics.parquet``, ``whole_body.csv``, ``per_muscle.csv``), in ms (and against the
other tree with ``--baseline-src``).

The repeats are interleaved (per repeat: one block per probe, one untimed call, then one
call per model), so that changes of the machine's load during the run
affect the package and the probes alike; the untimed call absorbs the slower first call
after the OpenSim worker has run (this process's caches are then cold). Prints
muscle-samples (states) per second, median and best of the repeats, and the ratio of each
model to the probe of its family, median to median and best to best (HO06, LW07, LW05 and
MA68 have no OpenSim counterpart: compared with the Umberger probe). Asserts nothing; timings on a shared
machine vary by tens of percent from run to run.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _states(n_muscles: int, n_samples: int, seed: int = 0) -> dict:
    from musclemetab.muscle import active_force_length, force_velocity, passive_force_length

    rng = np.random.default_rng(seed)
    shape = (n_muscles, n_samples)
    lm = rng.uniform(0.5, 1.5, shape)
    vb = rng.uniform(-1.0, 1.0, shape)
    f0 = rng.uniform(300.0, 6000.0, n_muscles)
    return dict(
        excitation=rng.uniform(0.0, 1.0, shape),
        activation=rng.uniform(0.01, 1.0, shape),
        normalized_fiber_length=lm,
        normalized_fiber_velocity=vb,
        active_force_length_multiplier=active_force_length(lm),
        force_velocity_multiplier=force_velocity(vb),
        passive_fiber_force_N=f0[:, None] * passive_force_length(lm),
        max_isometric_force_N=f0,
        optimal_fiber_length_m=rng.uniform(0.03, 0.2, n_muscles),
        max_contraction_velocity=np.full(n_muscles, 10.0),
        muscle_mass_kg=rng.uniform(0.05, 1.0, n_muscles),
        slow_twitch_fraction=rng.uniform(0.4, 0.8, n_muscles),
    )


def _load_baseline(path):
    """The ``musclemetab`` package of the source tree ``path`` (``path/src/musclemetab``),
    imported as ``_baseline_musclemetab`` beside this tree's package (relative imports inside
    it stay in it); returns the package with ``.metabolics`` and ``.solution`` loaded."""
    root = Path(path).resolve() / "src" / "musclemetab"
    if not (root / "__init__.py").is_file():
        raise SystemExit(f"--baseline-src {path}: no src/musclemetab/__init__.py there; give a source tree of the project")
    name = "_baseline_musclemetab"
    spec = importlib.util.spec_from_file_location(name, root / "__init__.py", submodule_search_locations=[str(root)])
    pkg = importlib.util.module_from_spec(spec)
    sys.modules[name] = pkg
    spec.loader.exec_module(pkg)
    pkg.metabolics = importlib.import_module(name + ".metabolics")
    pkg.solution = importlib.import_module(name + ".metabolics.solution")
    return pkg


def _largest_difference(new, old) -> float:
    """Largest ``|new - old|`` of any component, relative to the muscle-sample's components."""
    cn, co = new.components(), old.components()
    scale = sum(np.abs(v) for c, v in co.items() if c != "total")
    worst = 0.0 if list(cn) == list(co) else np.inf
    for c in co:
        a, b = np.asarray(co[c]), np.asarray(cn.get(c, np.nan))
        if a.shape != b.shape:
            return np.inf
        with np.errstate(invalid="ignore", divide="ignore"):
            d = np.abs(b - a) / np.maximum(np.abs(a), scale)
        d[(a == b) | (np.isnan(a) & np.isnan(b))] = 0.0
        worst = max(worst, float(np.max(d, initial=0.0)) if not np.isnan(d).any() else np.inf)
    return worst


def _solved_trial(folder: Path) -> Path:
    """One example trial solved (EFFORT-GEN, ``normal``) and written to ``folder``."""
    from musclemetab.datasets import example_subject
    from musclemetab.redundancy import solve_files

    ex = example_subject()
    solve_files(ex.model, ex.ik["normal"], ex.id["normal"], "effort-gen").write(folder)
    return folder


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--muscles", type=int, default=40)
    ap.add_argument("--samples", type=int, default=50_000, help="samples per muscle")
    ap.add_argument("--probe-states", default="all", help="'all' (default) or the number of states for the probes")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--baseline-src", metavar="PATH",
                    help="another source tree (its src/musclemetab) whose models are timed in the same run")
    ap.add_argument("--no-pipeline", action="store_true", help="skip the pipeline row (one solved example trial)")
    ap.add_argument("--quick", action="store_true",
                    help="4 muscles x 500 samples, 200 probe states, one repeat, no pipeline row (seconds; the test "
                    "suite runs it so)")
    args = ap.parse_args()
    if args.quick:
        args.muscles, args.samples, args.probe_states, args.repeats, args.no_pipeline = 4, 500, "200", 1, True

    from musclemetab import opensim_bridge
    from musclemetab.datasets import example_subject
    from musclemetab.metabolics import ALL_MODELS as MODELS

    base = _load_baseline(args.baseline_src) if args.baseline_src else None
    base_models = base.metabolics.ALL_MODELS if base else {}
    inputs = _states(args.muscles, args.samples)
    n = args.muscles * args.samples
    time_s = np.linspace(0.0, 1.0, args.samples)
    repeats = max(1, args.repeats)

    # the probes' states: the package's states, muscle-sample by muscle-sample
    k = n if args.probe_states == "all" else min(n, int(args.probe_states))
    probe_states = [
        np.ascontiguousarray(inputs[key].ravel()[:k])
        for key in ("normalized_fiber_length", "normalized_fiber_velocity", "activation", "excitation")
    ]
    blocks = np.array_split(np.arange(k), repeats)
    model_path = str(example_subject().model)
    probes = {
        "Umberger2010": dict(probe="Umberger2010", name="UM10", use_Bhargava_recruitment_model=False,
                             include_negative_mechanical_work=False, forbid_negative_total_power=False),
        "Bhargava2004": dict(probe="Bhargava2004", name="BH04", use_force_dependent_shortening_prop_constant=True,
                             maintenance_length_dependence="identity"),
    }

    def run_probe(cfg, index):
        r = opensim_bridge.call("probes:evaluate_probes", *(x[index] for x in probe_states), probes=[cfg],
                                slow_twitch_fraction=0.8, muscle_mass_kg=0.48, model_path=model_path,
                                muscle_name="soleus_r", read_muscle_quantities=False)
        return r

    # the pipeline: one solved trial, its metabolics from the folder and their files
    work_dir = Path(tempfile.mkdtemp(prefix="metabolics-bench-"))
    pipeline = {}
    if not args.no_pipeline:
        from musclemetab.datasets import example_subject
        from musclemetab.metabolics import solution as new_solution

        subject = example_subject()
        solved = _solved_trial(work_dir / "solution")
        pipeline["this tree"] = new_solution
        if base:
            pipeline["baseline"] = base.solution

    def run_pipeline(module, out):
        r = module.metabolics_from_solution(solved, subject.body_mass_kg, subject.height_m, models="all,LW05,MA68")
        module.write_metabolics(r, out)
        return r

    # warm-up (not timed): worker start, OpenSim's first evaluations, thread pool, scratch arrays
    for cfg in probes.values():
        version = run_probe(cfg, slice(0, min(k, 1000)))["opensim_version"]
    differences = {}
    for name, f in MODELS.items():
        r = f(**inputs, time_s=time_s)
        if name in base_models:
            differences[name] = _largest_difference(r, base_models[name](**inputs, time_s=time_s))
    pipeline_s = {label: [] for label in pipeline}
    for label, module in pipeline.items():
        run_pipeline(module, work_dir / f"warm-{label}")

    probe_s = {label: [] for label in probes}  # seconds per state, per block
    model_s = {name: [] for name in MODELS}  # seconds per call
    base_s = {name: [] for name in base_models}
    for rep in range(repeats):
        for label, cfg in probes.items():
            if blocks[rep].size:
                probe_s[label].append(run_probe(cfg, blocks[rep])["seconds_per_state"])
        # untimed: the first call after the worker has run finds this process's caches cold
        next(iter(MODELS.values()))(**inputs, time_s=time_s)
        for name, f in MODELS.items():
            calls = [(f, model_s[name])] + ([(base_models[name], base_s[name])] if name in base_models else [])
            for func, seconds in calls[:: 1 if rep % 2 == 0 else -1]:  # which tree goes first alternates
                t0 = time.perf_counter()
                func(**inputs, time_s=time_s)
                seconds.append(time.perf_counter() - t0)
        for label, module in list(pipeline.items())[:: 1 if rep % 2 == 0 else -1]:
            t0 = time.perf_counter()
            run_pipeline(module, work_dir / f"{label}-{rep}")
            pipeline_s[label].append(time.perf_counter() - t0)

    def rates(seconds, per):
        s = np.asarray(seconds)
        return per / np.median(s), per / s.min()

    family = {"UM03": "Umberger2010", "UM10": "Umberger2010", "UC16": "Umberger2010", "BH04": "Bhargava2004",
              "HO06": "Umberger2010", "LW07": "Umberger2010", "LW05": "Umberger2010", "MA68": "Umberger2010"}
    probe_rate = {label: rates(s, 1.0) for label, s in probe_s.items()}
    print(f"musclemetab.metabolics: arrays of {args.muscles} muscles x {args.samples} samples = {n:,} "
          f"muscle-samples, {repeats} repeats, one thread")
    print(f"OpenSim {version} probes: the same states, {k:,} of them, in {repeats} blocks")
    print(f"  {'probe':40s} {'states/s median':>16s} {'best':>12s}")
    for label, (med, best) in probe_rate.items():
        print(f"  {label + 'MuscleMetabolicsProbe':40s} {med:16,.0f} {best:12,.0f}   ({1e6 / med:.1f} us per state)")
    print(f"{'model':6s} {'M samples/s median':>19s} {'best':>7s} {'x probe median':>15s} {'best':>6s}  (probe)")
    for name in MODELS:
        med, best = rates(model_s[name], n)
        p_med, p_best = probe_rate[family[name]]
        print(f"{name:6s} {med / 1e6:19.1f} {best / 1e6:7.1f} {med / p_med:15.0f} {best / p_best:6.0f}  ({family[name]})")
    if base_models:
        print(f"against {args.baseline_src} (the same arrays, the same repeats): time of this tree / time of that one")
        print(f"{'model':6s} {'new/old median':>15s} {'best':>6s} {'old x probe median':>19s} {'largest difference':>19s}")
        for name in MODELS:
            if name not in base_models:
                print(f"{name:6s} (not in the baseline)")
                continue
            ratio = np.median(model_s[name]) / np.median(base_s[name])
            ratio_best = np.min(model_s[name]) / np.min(base_s[name])
            old_x = rates(base_s[name], n)[0] / probe_rate[family[name]][0]
            print(f"{name:6s} {ratio:15.3f} {ratio_best:6.3f} {old_x:19.0f} {differences[name]:19.1e}")
    if pipeline:
        print("pipeline: one solved example trial (EFFORT-GEN, normal), metabolics_from_solution with all,LW05,MA68 "
              "from its folder + write_metabolics")
        for label, s in pipeline_s.items():
            print(f"  {label:10s} median {1e3 * np.median(s):8.1f} ms   best {1e3 * np.min(s):8.1f} ms")
        if len(pipeline_s) == 2:
            print(f"  new/old median {np.median(pipeline_s['this tree']) / np.median(pipeline_s['baseline']):.3f}")
    shutil.rmtree(work_dir, ignore_errors=True)


if __name__ == "__main__":
    main()
