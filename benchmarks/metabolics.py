"""Benchmark: metabolic energy models on a large array, against OpenSim's probes.

    python benchmarks/metabolics.py [--muscles 40] [--samples 50000] [--probe-states 5000] [--repeats 5]

Measured in the same run:

* each model of :mod:`musclemetab.metabolics` on arrays of shape (muscles, samples)
  (default 40 x 50 000 = 2 million muscle-samples; realistic states: fibre lengths,
  velocities and activations drawn at random, curve values from the package's curves), input
  checks included; best of ``--repeats`` calls;
* OpenSim 4.6's ``Umberger2010MuscleMetabolicsProbe`` (UM10 settings) and
  ``Bhargava2004MuscleMetabolicsProbe`` (BH04 settings), each alone in a one-muscle model
  (the example soleus on a slider, rigid tendon), evaluated at ``--probe-states`` states in
  the OpenSim worker process: per state, set the fibre length, velocity, activation and
  excitation, realise to accelerations and read the probe's output (the least work OpenSim
  needs to evaluate a probe at a given state; process start, model building and the transfer
  of arrays are not counted).

Prints muscle-samples per second and the ratio of each model to the probe of its family
(HO06 and LW07 have no OpenSim counterpart: compared with the Umberger probe). Asserts
nothing; timings on a shared machine vary by tens of percent from run to run.
"""

from __future__ import annotations

import argparse
import time

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--muscles", type=int, default=40)
    ap.add_argument("--samples", type=int, default=50_000, help="samples per muscle")
    ap.add_argument("--probe-states", type=int, default=5000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()

    from musclemetab import opensim_bridge
    from musclemetab.datasets import example_subject
    from musclemetab.metabolics import MODELS

    inputs = _states(args.muscles, args.samples)
    n = args.muscles * args.samples
    time_s = np.linspace(0.0, 1.0, args.samples)

    # OpenSim probes first (the worker start and model build are not timed)
    rng = np.random.default_rng(1)
    k = args.probe_states
    lm, vb = rng.uniform(0.5, 1.5, k), rng.uniform(-1.0, 1.0, k)
    act, exc = rng.uniform(0.01, 1.0, k), rng.uniform(0.0, 1.0, k)
    model_path = str(example_subject().model)
    probes = {
        "Umberger2010": dict(probe="Umberger2010", name="UM10", use_Bhargava_recruitment_model=False,
                             include_negative_mechanical_work=False, forbid_negative_total_power=False),
        "Bhargava2004": dict(probe="Bhargava2004", name="BH04", use_force_dependent_shortening_prop_constant=True,
                             maintenance_length_dependence="identity"),
    }
    probe_rate = {}
    for label, cfg in probes.items():
        best = np.inf
        for _ in range(max(1, args.repeats // 2)):
            r = opensim_bridge.call("probes:evaluate_probes", lm, vb, act, exc, probes=[cfg],
                                    slow_twitch_fraction=0.8, muscle_mass_kg=0.48, model_path=model_path,
                                    muscle_name="soleus_r", read_muscle_quantities=False)
            best = min(best, r["seconds_per_state"])
        probe_rate[label] = 1.0 / best

    family = {"UM03": "Umberger2010", "UM10": "Umberger2010", "UC16": "Umberger2010", "BH04": "Bhargava2004",
              "HO06": "Umberger2010", "LW07": "Umberger2010"}
    print(f"musclemetab.metabolics: arrays of {args.muscles} muscles x {args.samples} samples = {n:,} muscle-samples, "
          f"best of {args.repeats}")
    print(f"OpenSim {r['opensim_version']} probes: {k} states each, best of {max(1, args.repeats // 2)}")
    for label, rate in probe_rate.items():
        print(f"  {label + 'MuscleMetabolicsProbe':40s} {rate:12,.0f} states/s   ({1e6 / rate:.1f} us per state)")
    print(f"{'model':6s} {'seconds':>9s} {'muscle-samples/s':>18s} {'x probe':>9s}  (probe)")
    for name, f in MODELS.items():
        best = np.inf
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            f(**inputs, time_s=time_s)
            best = min(best, time.perf_counter() - t0)
        rate = n / best
        p = family[name]
        print(f"{name:6s} {best:9.4f} {rate:18,.0f} {rate / probe_rate[p]:9.0f}  ({p})")


if __name__ == "__main__":
    main()
