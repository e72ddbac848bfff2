"""Sensitivities of the example's normal trial (EFFORT-GEN) against central finite differences
of re-solves (``docs/uncertainty.md``, "Sensitivities").

    python benchmarks/sensitivity.py NORMAL_SOLUTION_FOLDER [STEP]
    python benchmarks/sensitivity.py NORMAL_SOLUTION_FOLDER [STEP] --default-resolves
    python benchmarks/sensitivity.py --quick

NORMAL_SOLUTION_FOLDER: ``musclemetab solve --workflow effort-gen`` of the example subject's
normal trial. For F0, lMo, lTs, kT of soleus and vastus lateralis and the UM10 and BH04 rates:
``d rate / d log p`` from the KKT system at the polished optimum
(:func:`musclemetab.redundancy.sensitivity.trial_sensitivity`) and ``[R(p (1 + h)) -
R(p (1 - h))] / 2h`` from two re-solves from that optimum at tolerance 1e-10
(:func:`~musclemetab.redundancy.sensitivity.finite_difference`), ``h`` = STEP (default 1e-3):
the whole-body rate (W/kg) and the muscle's own rate (W), per unit log of the parameter.

``--default-resolves``: the finite differences instead come from cold solves of the trial with
the package's default settings (``solve_files`` from the files the folder's ``summary.json``
names, the parameter scaled through ``parameter_transform``), for the soleus ``lTs`` and the
vastus lateralis ``kT`` rows (step 1e-2 for ``kT``, whose derivative is small): the check that
the sensitivities at the default solve are those of the default solves.

``--quick``: the soleus ``lTs`` row alone, on a solution of the window 0.6-0.8 s of the normal
trial solved first (geometry from the package's cache; a check that the script runs).
"""

import sys
import time

from musclemetab.redundancy.sensitivity import finite_difference, problem_of_solution, trial_sensitivity

MASS, HEIGHT = 72.6, 1.743
MODELS = "UM10,BH04"
PAIRS = [(p, m) for p in ("F0", "lMo", "lTs", "kT") for m in ("soleus_r", "vaslat_r")]


def main(folder, step=1e-3, pairs=PAIRS):
    prob = problem_of_solution(folder)
    t = time.perf_counter()
    sens = trial_sensitivity(prob.solution, prob.inputs, prob.params, prob.goals, body_mass_kg=MASS, height_m=HEIGHT,
                             models=MODELS, parameters=pairs)
    print(f"sensitivities of {len(pairs)} parameters (polish included): {time.perf_counter() - t:.1f} s; active set "
          f"{sens.active}")
    print("| parameter | muscle | model | whole body KKT | whole body FD | difference | muscle KKT | muscle FD |")
    print("|---|---|---|---|---|---|---|---|")
    worst = 0.0
    for p, m in pairs:
        wb, per = finite_difference(prob.inputs, prob.params, prob.goals, sens.x, p, m, prob.solution.summary,
                                    step=step, body_mass_kg=MASS, height_m=HEIGHT, models=MODELS)
        i = sens.muscles.index(m)
        for model in wb:
            k = sens.derivative(model, p, m)
            worst = max(worst, abs(k - wb[model]) / (0.05 * abs(wb[model]) + 0.01))
            print(f"| {p} | {m} | {model} | {k:+.4f} | {wb[model]:+.4f} | {k - wb[model]:+.4f} | "
                  f"{sens.derivative(model, p, m, rate=m):+.3f} | {per[model][i]:+.3f} |")
    print(f"largest |KKT - FD| / (5 % |FD| + 0.01 W/kg) of the whole-body rates: {worst:.2f}")


def default_resolves(folder, step=1e-3):
    import dataclasses
    import warnings

    import numpy as np

    from musclemetab.metabolics.solution import metabolics_from_solution
    from musclemetab.redundancy import solve_files
    from musclemetab.redundancy.sensitivity import PARAMETERS

    prob = problem_of_solution(folder)
    pairs = [("lTs", "soleus_r", step), ("kT", "vaslat_r", max(step, 1e-2))]
    sens = trial_sensitivity(prob.solution, prob.inputs, prob.params, prob.goals, body_mass_kg=MASS, height_m=HEIGHT,
                             models=MODELS, parameters=[(p, m) for p, m, _ in pairs])
    files = prob.solution.summary["inputs"]
    workflow = prob.solution.summary["workflow"]["name"]

    def rates(p, m, factor):
        def transform(params):
            i = params.names.index(m)
            values = np.asarray(getattr(params, PARAMETERS[p]), dtype=float).copy()
            values[i] *= factor
            return dataclasses.replace(params, **{PARAMETERS[p]: values})

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sol = solve_files(files["model"], files["ik"], files["id"], workflow, parameter_transform=transform)
        met = metabolics_from_solution(sol, MASS, HEIGHT, models=MODELS)
        return {k: met.whole_body[k].mean_W_per_kg for k in met.models}

    print("| parameter | muscle | step | model | whole body KKT | whole body FD (default re-solves) | difference |")
    print("|---|---|---|---|---|---|---|")
    worst = 0.0
    for p, m, h in pairs:
        up, down = rates(p, m, 1 + h), rates(p, m, 1 - h)
        for model in up:
            fd = (up[model] - down[model]) / (2 * h)
            k = sens.derivative(model, p, m)
            worst = max(worst, abs(k - fd) / abs(fd))
            print(f"| {p} | {m} | {h:g} | {model} | {k:+.4f} | {fd:+.4f} | {100 * (k / fd - 1):+.1f} % |")
    print(f"largest |KKT - FD| / |FD|: {100 * worst:.1f} %")


def quick() -> None:
    """``--quick``: EFFORT-GEN of the normal trial's quick window, written to a temporary folder,
    and its soleus ``lTs`` row."""
    import tempfile
    import warnings
    from pathlib import Path

    from _quick import WINDOW
    from solver import _example

    from musclemetab.redundancy import solve_files

    ex = _example()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = solve_files(ex.model, ex.ik["normal"], ex.id["normal"], "effort-gen", window=WINDOW)
    folder = Path(tempfile.mkdtemp(prefix="mm-sensitivity-")) / "normal"
    sol.write(folder)
    main(folder, pairs=[("lTs", "soleus_r")])


if __name__ == "__main__":
    if not sys.argv[1:] or sys.argv[1] in ("-h", "--help"):
        sys.exit(print(__doc__))
    if sys.argv[1:] == ["--quick"]:
        sys.exit(quick())
    args = [a for a in sys.argv[1:] if a != "--default-resolves"]
    run = default_resolves if "--default-resolves" in sys.argv else main
    run(args[0], *(float(a) for a in args[1:2]))
