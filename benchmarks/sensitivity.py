"""Sensitivities of the example's normal trial (EFFORT-GEN) against central finite differences
of re-solves (``docs/uncertainty.md``, "Sensitivities").

    python benchmarks/sensitivity.py NORMAL_SOLUTION_FOLDER [STEP]

NORMAL_SOLUTION_FOLDER: ``musclemetab solve --workflow effort-gen`` of the example subject's
normal trial. For F0, lMo, lTs, kT of soleus and vastus lateralis and the UM10 and BH04 rates:
``d rate / d log p`` from the KKT system at the polished optimum
(:func:`musclemetab.redundancy.sensitivity.trial_sensitivity`) and ``[R(p (1 + h)) -
R(p (1 - h))] / 2h`` from two re-solves from that optimum at tolerance 1e-10
(:func:`~musclemetab.redundancy.sensitivity.finite_difference`), ``h`` = STEP (default 1e-3):
the whole-body rate (W/kg) and the muscle's own rate (W), per unit log of the parameter.
"""

import sys
import time

from musclemetab.redundancy.sensitivity import finite_difference, problem_of_solution, trial_sensitivity

MASS, HEIGHT = 72.6, 1.743
MODELS = "UM10,BH04"
PAIRS = [(p, m) for p in ("F0", "lMo", "lTs", "kT") for m in ("soleus_r", "vaslat_r")]


def main(folder, step=1e-3):
    prob = problem_of_solution(folder)
    t = time.perf_counter()
    sens = trial_sensitivity(prob.solution, prob.inputs, prob.params, prob.goals, body_mass_kg=MASS, height_m=HEIGHT,
                             models=MODELS, parameters=PAIRS)
    print(f"sensitivities of {len(PAIRS)} parameters (polish included): {time.perf_counter() - t:.1f} s; active set "
          f"{sens.active}")
    print("| parameter | muscle | model | whole body KKT | whole body FD | difference | muscle KKT | muscle FD |")
    print("|---|---|---|---|---|---|---|---|")
    worst = 0.0
    for p, m in PAIRS:
        wb, per = finite_difference(prob.inputs, prob.params, prob.goals, sens.x, p, m, prob.solution.summary,
                                    step=step, body_mass_kg=MASS, height_m=HEIGHT, models=MODELS)
        i = sens.muscles.index(m)
        for model in wb:
            k = sens.derivative(model, p, m)
            worst = max(worst, abs(k - wb[model]) / (0.05 * abs(wb[model]) + 0.01))
            print(f"| {p} | {m} | {model} | {k:+.4f} | {wb[model]:+.4f} | {k - wb[model]:+.4f} | "
                  f"{sens.derivative(model, p, m, rate=m):+.3f} | {per[model][i]:+.3f} |")
    print(f"largest |KKT - FD| / (5 % |FD| + 0.01 W/kg) of the whole-body rates: {worst:.2f}")


if __name__ == "__main__":
    main(sys.argv[1], *(float(a) for a in sys.argv[2:3]))
