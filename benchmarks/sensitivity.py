"""Sensitivities of the example's normal trial (EFFORT-GEN) against central finite differences
of warm-started re-solves (``docs/uncertainty.md``, "Sensitivities").

    python benchmarks/sensitivity.py NORMAL_SOLUTION_FOLDER [STEP]

For F0, lMo, lTs, kT of soleus and vastus lateralis and the UM10 and BH04 whole-body rates:
``d rate / d log p`` from the KKT system (:mod:`musclemetab.redundancy.sensitivity`) and
``[R(p (1 + h)) - R(p (1 - h))] / 2h`` from two re-solves warm-started at the nominal optimum
(IPOPT tol 1e-9), ``h`` = STEP (default 0.01).
"""

import sys
import time

import numpy as np

from musclemetab.metabolics.solution import metabolics_from_solution
from musclemetab.redundancy.ipopt import SolverOptions
from musclemetab.redundancy.sensitivity import PARAMETERS, _scaled, problem_of_solution, trial_sensitivity
from musclemetab.redundancy.solve import solve_with_parameters

MASS, HEIGHT = 72.6, 1.743
MODELS = "UM10,BH04"
PAIRS = [(p, m) for p in ("F0", "lMo", "lTs", "kT") for m in ("soleus_r", "vaslat_r")]


def finite_difference(prob, parameter, muscle, step, options):
    out = []
    for sign in (1, -1):
        scale = np.zeros(len(prob.params.names))
        scale[prob.params.names.index(muscle)] = sign * step
        sol = solve_with_parameters(prob.geometry, _scaled(prob.params, {PARAMETERS[parameter]: scale}),
                                    prob.id_time_s, prob.id_moments_Nm, ik_time_s=prob.ik_time_s, options=options,
                                    goals=prob.goals, warm_start=prob.solution, check_units=False,
                                    filter_inputs=prob.filter_inputs, mesh_frequency_hz=prob.mesh_frequency_hz)
        assert sol.success, sol.status
        res = metabolics_from_solution(sol, MASS, HEIGHT, models=MODELS)
        out.append({m: res.whole_body[m].mean_W_per_kg for m in res.models})
    return {m: (out[0][m] - out[1][m]) / (2 * step) for m in out[0]}


def main(folder, step=0.01):
    prob = problem_of_solution(folder)
    t = time.perf_counter()
    sens = trial_sensitivity(prob.solution, prob.inputs, prob.params, prob.goals, body_mass_kg=MASS, height_m=HEIGHT,
                             models=MODELS, parameters=PAIRS)
    print(f"sensitivities of {len(PAIRS)} parameters: {time.perf_counter() - t:.1f} s; multipliers' stationarity "
          f"{sens.stationarity:.2g}")
    options = SolverOptions(tol=1e-9)
    print("parameter muscle model KKT FD diff rel")
    for p, m in PAIRS:
        t = time.perf_counter()
        fd = finite_difference(prob, p, m, step, options)
        for model in fd:
            k = sens.derivative(model, p, m)
            print(f"{p} {m} {model} {k:+.5f} {fd[model]:+.5f} {k - fd[model]:+.2e} "
                  f"{abs(k - fd[model]) / max(abs(fd[model]), 1e-12):.2e}  ({time.perf_counter() - t:.1f} s)")


if __name__ == "__main__":
    main(sys.argv[1], *(float(a) for a in sys.argv[2:3]))
