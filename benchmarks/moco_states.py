"""The energy of a Moco trajectory: the fiber velocity of each source against Moco's own.

    python benchmarks/moco_states.py [--mesh-interval 0.01]
    python benchmarks/moco_states.py --quick

A MocoInverse of the example subject's normal trial (the one-leg set-up of
``benchmarks/_moco_baseline.py``: 40 DeGrooteFregly2016 muscles with implicit compliant tendons,
run in a process of its own, OpenSim only) is written as a Moco solution file (with the
coordinates added from the filtered kinematics) together with the muscle outputs Moco reports
along it (``analyzeMocoTrajectory``). ``musclemetab metabolics --states`` then reads the
trajectory with each ``--fiber-velocity`` source:

* ``trajectory`` (what ``auto`` takes from a Moco solution file): its tendon-force derivatives,
  set in the muscles as Moco solved them;
* ``derivative``: the time derivative of the fiber lengths (what ``auto`` takes from a states file
  without the derivatives);
* ``equilibrium``: OpenSim's force equilibrium.

Printed per source: the distance of its normalized fiber velocity from Moco's (median, 99th
percentile, largest; ``vmax``) and the six study models' whole-body rates (W/kg, basal heat
included, 72.6 kg) averaged over 0.62-1.70 s, with those of Moco's own velocity, force-velocity
multiplier and passive force as the reference. docs/metabolics.md 4.1 holds the full run.

``--quick``: mesh 0.05 s over 1.0-1.3 s (a check that the script runs).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SOURCES = ("trajectory", "derivative", "equilibrium")
MODELS = ("UM10", "BH04", "UM03", "LW07", "HO06", "UC16")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh-interval", type=float, default=0.01, help="Moco's mesh interval, s (default 0.01)")
    ap.add_argument("--quick", action="store_true", help="mesh 0.05 s over 1.0-1.3 s")
    args = ap.parse_args(argv)
    from musclemetab.datasets import example_subject
    from musclemetab.io import read_table
    from musclemetab.metabolics.opensim_states import read_opensim_states, split_sides, states_metabolics

    ex = example_subject()
    out = Path(tempfile.mkdtemp(prefix="moco_states-"))
    mesh, window, cycle = (0.05, "1.0:1.3", (1.0, 1.3)) if args.quick else (args.mesh_interval, None, (0.62, 1.70))
    cmd = [sys.executable, str(HERE / "_moco_baseline.py"), "--model", str(ex.model), "--ik", str(ex.ik["normal"]),
           "--id", str(ex.id["normal"]), "--mesh-interval", str(mesh), "--workdir", str(out / "work"),
           "--write-trajectory", str(out), *(["--window", window] if window else [])]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        print(done.stdout[-2000:], done.stderr[-2000:], file=sys.stderr)
        return 1
    print(f"MocoInverse of the normal trial, mesh {mesh:g} s: {done.stdout.strip().splitlines()[-1]}")
    solution, model = out / "moco_solution.sto", out / "model.osim"
    moco = read_table(out / "moco_outputs.sto")
    warnings.simplefilter("ignore")  # the reserves and notes of the states route, the same for each source
    reads = {s: read_opensim_states(model, solution, solution, fiber_velocity=s) for s in SOURCES}
    first = reads["trajectory"].states

    def of_moco(quantity):
        return np.array([np.asarray(moco[f"/forceset/{m}|{quantity}"], dtype=float) for m in first.muscles])

    v_moco = of_moco("normalized_fiber_velocity")
    own = replace(reads["trajectory"], states=replace(first, states={
        **first.states, "normalized_fiber_velocity": v_moco,
        "force_velocity_multiplier": of_moco("force_velocity_multiplier"),
        "passive_fiber_force_N": of_moco("passive_fiber_force")}))
    rows = {"Moco's own outputs": own, **{s: reads[s] for s in SOURCES}}
    print(f"\n{'fiber velocity':20s} {'|v - v_Moco| / vmax: median':>28s} {'p99':>9s} {'max':>9s}  "
          + "  ".join(f"{m:>6s}" for m in MODELS) + "   (W/kg)")
    for name, read in rows.items():
        e = np.abs(read.states.states["normalized_fiber_velocity"] - v_moco)
        res, _ = states_metabolics(read, split_sides(read.states), ex.body_mass_kg, ex.height_m, models=list(MODELS),
                                   cycle_s=cycle)
        rate = next(iter(res.values())).whole_body_table().set_index("model")["whole_body_W_per_kg"]
        print(f"{name:20s} {np.median(e):28.1e} {np.percentile(e, 99):9.1e} {e.max():9.1e}  "
              + "  ".join(f"{rate[m]:6.3f}" for m in MODELS))
    return 0


if __name__ == "__main__":
    sys.exit(main())
