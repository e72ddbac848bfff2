"""Coverage of the uncertainty bands on synthetic truths (docs/uncertainty.md).

Every sample of a study run with uncertainty samples is a solve of the trial with parameters
drawn from the prior. Taking each sample in turn as the truth (a subject whose properties are
that draw) and the 5-95 % band of the *other* samples of its trial unit as the estimate made
with the nominal model and its priors, the share of truths inside their band should be close to
the band's stated rate. For ``n`` exchangeable draws, the chance that a new draw falls between
the 5 and 95 % quantiles (linear interpolation) of ``n - 1`` others is a little below 90 % for
small ``n``; the script prints it (a Monte-Carlo of uniform draws) beside the observed share,
for the whole-body rate of every model and for every muscle's rate.

    python docs/scripts/uncertainty_coverage.py STUDY_FOLDER

(e.g. the folder of ``musclemetab demo --uncertainty 16``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np


def expected_coverage(n_others: int, trials: int = 200_000, seed: int = 0) -> float:
    """Chance that a new draw lies within the 5-95 % quantiles of ``n_others`` exchangeable draws."""
    rng = np.random.default_rng(seed)
    u = rng.random((trials, n_others + 1))
    lo, hi = np.quantile(u[:, 1:], [0.05, 0.95], axis=1)
    return float(np.mean((u[:, 0] >= lo) & (u[:, 0] <= hi)))


def leave_one_out(values_by_unit) -> tuple[int, int, list[int]]:
    """``(inside, total, sizes)``: each value against the 5-95 % band of the others of its unit."""
    inside = total = 0
    sizes = []
    for values in values_by_unit:
        v = np.asarray(values, dtype=float)
        v = v[np.isfinite(v)]
        if v.size < 3:
            continue
        sizes.append(v.size)
        for i in range(v.size):
            others = np.delete(v, i)
            lo, hi = np.quantile(others, [0.05, 0.95])
            inside += bool(lo <= v[i] <= hi)
            total += 1
    return inside, total, sizes


def main(folder: str) -> None:
    from musclemetab.study.runner import add_leg_rows, leg_basal_energy_J, trial_result_rows
    from musclemetab.study.spec import load_study
    from musclemetab.study.uncertainty import sample_tables

    import json

    from musclemetab.study.uncertainty import with_uncertainty

    folder = Path(folder)
    info = json.loads((folder / "study.json").read_text())  # the settings the study ran with
    study = load_study(info["source"], output=folder)
    recorded = info.get("uncertainty") or {}
    study = with_uncertainty(study, recorded.get("samples", 0), recorded.get("seed"), recorded.get("priors"))
    results, per_muscle = sample_tables(study, trial_result_rows, add_leg_rows, leg_basal_energy_J)
    if results is None:
        sys.exit(f"{folder}: no converged uncertainty samples")
    units = ["subject", "trial", "workflow"]
    n = results.groupby(units + ["model"])["sample"].nunique()
    print(f"{folder}: {n.index.droplevel('model').nunique()} trial units, {int(n.min())}-{int(n.max())} converged "
          "samples each; each sample in turn the truth, the band of the others its estimate")
    expected = {k: expected_coverage(k - 1) for k in sorted(set(n.to_numpy(int)))}
    print("expected share inside (exchangeable draws): "
          + ", ".join(f"{100 * v:.1f} % with {k - 1} others" for k, v in expected.items()))
    print(f"{'model':<6} {'whole body: inside / truths':>30} {'per muscle: inside / truths':>30}")
    all_in = all_n = 0
    for model, d in results.groupby("model"):
        inside, total, _ = leave_one_out(g["whole_body_W_per_kg"] for _, g in d.groupby(units))
        pm = per_muscle[per_muscle["model"] == model]
        m_in, m_total, _ = leave_one_out(g["muscle_W"] for _, g in pm.groupby(units + ["muscle"]))
        all_in, all_n = all_in + inside, all_n + total
        print(f"{model:<6} {f'{inside} / {total} = {100 * inside / total:.0f} %':>30} "
              f"{f'{m_in} / {m_total} = {100 * m_in / m_total:.0f} %':>30}")
    print(f"all models, whole body: {all_in} / {all_n} = {100 * all_in / all_n:.1f} %")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
