"""Coverage of the uncertainty bands: do truths drawn from the priors fall inside the bands at
the rate the bands state? (``docs/uncertainty.md``, "Coverage").

A *truth* is a subject whose muscle properties are a draw from the priors: its factors come
from another generator than the bands' samples (NumPy's PCG64 pseudo-random normals with their
own seed, :func:`independent_draws`, against the scrambled Sobol' points of
:func:`musclemetab.uncertainty.draw`), and its problem is solved cold (from static
optimisation), where the bands' samples start from the nominal solution
(:func:`musclemetab.uncertainty.sample_start`). Each
truth's whole-body rate is compared with the band of the plausible samples (converged, no
plausibility flag) of the nominal problem; truths with a flag are left out as the samples are
(the band speaks of plausible subjects). With ``n`` plausible samples a truth exchangeable with
them lies inside the band with probability :func:`musclemetab.uncertainty.expected_coverage`:
``(n - 1)/(n + 1)`` for the min-max of fewer than 20, ``0.9 (n - 1)/(n + 1)`` for the 5-95 %
quantiles.

``python -m musclemetab.uncertainty_coverage --samples 32 --truths 32`` runs it on the example
subject's normal trial (EFFORT-GEN; ``--window``, ``--dofs`` for a smaller problem) and prints
the share of truths inside per model.
"""

from __future__ import annotations

import argparse
import warnings
from dataclasses import dataclass
from typing import Sequence

import numpy as np

__all__ = ["TRUTH_SEED", "independent_draws", "Outcome", "solve_draw", "coverage", "summary", "main"]

#: the seed of the truths' generator (not the bands' Sobol' seed)
TRUTH_SEED = 20261202


def independent_draws(priors, muscles: Sequence[str], n: int, seed: int = TRUTH_SEED):
    """``n`` draws of the factors of ``muscles`` from NumPy's PCG64 generator seeded ``seed``
    (independent standard normal values through the same priors as the samples)."""
    from .uncertainty import dimension, draw_from_normal

    rng = np.random.Generator(np.random.PCG64(int(seed)))
    return [draw_from_normal(priors, muscles, k, rng.standard_normal(dimension(muscles))) for k in range(n)]


@dataclass(frozen=True)
class Outcome:
    """One solve of a draw: ``rates`` (whole-body W/kg by energy model), converged or not, and
    its plausibility flags' ``quality`` text (``"ok"``: none)."""

    index: int
    converged: bool
    rates: dict
    quality: str

    @property
    def plausible(self) -> bool:
        return self.converged and self.quality == "ok"


def solve_draw(problem, draw, *, body_mass_kg: float, height_m: float | None, models, start=None) -> Outcome:
    """Solve ``problem`` (the nominal :class:`~musclemetab.redundancy.problem.Problem`, e.g.
    ``nominal.problem``) with the parameters of ``draw``; from ``start`` (the nominal solution:
    :func:`~musclemetab.uncertainty.sample_start`) or cold; its whole-body rates with the draw's muscle
    masses and fiber types and its flags (the solve's and the rates' against the band of walking
    rates, without a speed)."""
    from .metabolics.plausibility import metabolic_flags
    from .metabolics.solution import metabolics_from_solution
    from .quality import quality_text
    from .redundancy.problem import solve
    from .uncertainty import sample_start, sampled_properties

    warm = None if start is None else sample_start(start, draw.parameters(start.parameters))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the flags are recorded below
        result = solve(problem.with_parameters(draw.parameters(problem.parameters)), warm_start=warm)
    sol = next(iter(result.solutions.values()))
    if not sol.success:
        return Outcome(draw.index, False, {}, "not_converged")
    masses, fst = sampled_properties(draw, sol, body_mass_kg, height_m)
    result = metabolics_from_solution(sol, body_mass_kg, height_m, models=list(models), muscle_masses_kg=masses,
                                      slow_twitch_fractions=fst)
    rates = {m: float(result.whole_body[m].mean_W_per_kg) for m in result.models}
    flags = list(sol.record.flags) + metabolic_flags(rates, None)
    return Outcome(draw.index, True, rates, quality_text(flags))


def coverage(files: tuple, workflow: str = "effort-gen", *, body_mass_kg: float, height_m: float | None,
             models=("UM10", "BH04"), samples: int = 16, truths: int = 16, seed: int = 1,
             truth_seed: int = TRUTH_SEED, priors=None, **solve_kw):
    """The bands of ``samples`` samples (seed ``seed``, warm-started as a study's) and ``truths``
    independent truths (seed ``truth_seed``, cold) of the problem ``files``; one row per truth and
    model: ``truth``, ``model``, ``value``, ``low``, ``high`` (the band of the plausible
    samples), ``n_samples`` (how many), ``plausible`` (the truth's), ``quality`` and ``inside``."""
    import pandas as pd

    from .redundancy.run import solve_files
    from .uncertainty import band, draw, read_priors

    priors = read_priors() if priors is None else priors
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        nominal = solve_files(*files, workflow, **solve_kw)
    kw = dict(body_mass_kg=body_mass_kg, height_m=height_m, models=models)
    sampled = [solve_draw(nominal.problem, draw(priors, nominal.muscles, k, seed), start=nominal, **kw)
               for k in range(samples)]
    truth = [solve_draw(nominal.problem, d, **kw) for d in independent_draws(priors, nominal.muscles, truths,
                                                                             truth_seed)]
    rows = []
    for model in models:
        used = [o.rates[model] for o in sampled if o.plausible]
        lo, _, hi = band(used)
        for o in truth:
            value = o.rates.get(model, float("nan"))
            rows.append({"truth": o.index, "model": model, "value": value, "low": lo, "high": hi,
                         "n_samples": len(used), "plausible": o.plausible, "quality": o.quality,
                         "inside": bool(o.plausible and lo <= value <= hi)})
    return pd.DataFrame(rows)


def summary(table):
    """Per model: plausible truths, inside, the share inside and the expected share for the number
    of plausible samples (:func:`musclemetab.uncertainty.expected_coverage`)."""
    import pandas as pd

    from .uncertainty import expected_coverage

    out = []
    for model, d in table.groupby("model", sort=False):
        p = d[d["plausible"]]
        n = int(d["n_samples"].iloc[0])
        out.append({"model": model, "plausible_truths": len(p), "inside": int(p["inside"].sum()),
                    "share_inside": float(p["inside"].mean()) if len(p) else float("nan"),
                    "samples_used": n, "expected_share": expected_coverage(n)})
    return pd.DataFrame(out)


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=32)
    ap.add_argument("--truths", type=int, default=32)
    ap.add_argument("--trial", default="normal")
    ap.add_argument("--workflow", default="effort-gen")
    ap.add_argument("--models", default="UM10,BH04,UC16,LW07")
    ap.add_argument("--window", help="T0:T1 (s), a part of the trial")
    ap.add_argument("--dofs", nargs="+")
    ap.add_argument("--csv", help="write the table of truths here")
    args = ap.parse_args(argv)
    from .datasets import example_subject

    ex = example_subject()
    kw = {}
    if args.window:
        t0, t1 = (float(v) for v in args.window.split(":"))
        kw["window"] = (t0, t1)
    if args.dofs:
        kw["dofs"] = args.dofs
    if args.workflow == "effort-ten":
        kw["tendon_stiffness"] = "example"
    table = coverage((ex.model, ex.ik[args.trial], ex.id[args.trial]), args.workflow, body_mass_kg=ex.body_mass_kg,
                     height_m=ex.height_m, models=args.models.split(","), samples=args.samples, truths=args.truths,
                     **kw)
    if args.csv:
        table.to_csv(args.csv, index=False)
    print(summary(table).to_string(index=False))
    flagged = table[~table["plausible"]].drop_duplicates("truth")
    print(f"truths left out (flagged or not converged): {len(flagged)} of {table['truth'].nunique()}")


if __name__ == "__main__":
    main()
