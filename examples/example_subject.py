"""Muscle energetics of the example subject walking at three speeds.

For each speed (slow, normal, fast): muscle geometry from the OpenSim model, the muscle
redundancy problem with the EFFORT-TEN workflow (calibrated passive muscle, personalised
Achilles and patellar tendon stiffness), and the study's six metabolic energy models.
Writes one folder per trial under --out (solution.sto, summary.json, metabolics.sto,
metabolics.parquet, whole_body.csv, per_muscle.csv) and prints the whole-body metabolic rate per model.

    python examples/example_subject.py --out results [--workflow effort-ten] [--speeds normal]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

from musclemetab.datasets import SPEEDS, example_subject
from musclemetab.errors import MusclemetabError
from musclemetab.metabolics.solution import metabolics_from_solution, write_metabolics
from musclemetab.model import read_muscle_parameters
from musclemetab.redundancy import solve_files


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results", help="output folder (default results)")
    ap.add_argument("--workflow", default="effort-ten", choices=("effort-gen", "effort-cal", "effort-ten"))
    ap.add_argument("--speeds", nargs="+", default=list(SPEEDS), choices=SPEEDS)
    args = ap.parse_args(argv)

    ex = example_subject()
    params = read_muscle_parameters(ex.model)
    rows = []
    for speed in args.speeds:
        folder = Path(args.out) / f"{speed}_{args.workflow}"
        sol = solve_files(ex.model, ex.ik[speed], ex.id[speed], args.workflow)
        sol.write(folder)
        result = metabolics_from_solution(folder, ex.body_mass_kg, ex.height_m, muscle_parameters=params)
        write_metabolics(result, folder)
        wb = pd.read_csv(folder / "whole_body.csv").assign(speed=speed)
        rows.append(wb)
        print(f"{speed:>6}: solved in {sol.summary['solve_time_s']:.1f} s, "
              f"{sol.summary['iterations']} iterations -> {folder}")
    table = pd.concat(rows).pivot(index="model", columns="speed", values="whole_body_W_per_kg")[args.speeds]
    print(f"\nwhole-body metabolic rate, W/kg (two legs + 1.2 W/kg basal), {args.workflow}:")
    print(table.round(2).to_string())
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except MusclemetabError as exc:
        print(f"example_subject: error: {exc}", file=sys.stderr)
        sys.exit(1)
