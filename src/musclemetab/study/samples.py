"""One uncertainty sample of a trial unit: its key and its run (:mod:`.uncertainty` plans the
samples and gathers their bands; ``docs/uncertainty.md``).

Sample ``k`` of a trial unit draws the factors of sample ``k`` (:func:`musclemetab.uncertainty.draw`),
solves the trial again with the muscle-tendon parameters multiplied by them, warm-started from the
trial unit's optimum and IPOPT multipliers (its ``ipopt_start.npz``, :data:`START_FILE`), or, without
them, from its solution adapted to the sample's parameters
(:func:`musclemetab.uncertainty.sample_start`; :func:`musclemetab.redundancy.run.solve_files`,
``warm_start`` and ``parameter_transform``; the record's ``start`` says which),
evaluates every metabolic model of the study with the sampled muscle masses, slow-twitch fractions
and height, and writes ``whole_body.csv``, ``analysis.csv`` and ``per_muscle.csv`` (the trial unit's
columns) and ``factors.csv`` (the factors of every muscle). Its record (``unit.json``) keeps the
solve's plausibility flags and convergence record as a trial unit's does; a sample whose solve does
not converge (``converged: false``), or that has a flag, is left out of the bands
(:func:`.uncertainty.sample_tables`). Its key is the trial unit's key, the
priors' values, the seed and ``k``.
"""

from __future__ import annotations

import functools
import hashlib
import json
import time
from pathlib import Path
from typing import Mapping

from ..errors import OptionError
from ..uncertainty import DEFAULT_SEED
from .spec import Study

__all__ = ["study_priors", "sample_key", "run_sample", "FACTORS_FILE", "METHOD", "START_FILE", "write_start",
           "read_start"]

FACTORS_FILE = "factors.csv"
#: a sampled trial unit's optimum as IPOPT left it (``x``, ``lam_x``, ``lam_g``): its samples' start
START_FILE = "ipopt_start.npz"
#: the sampling rule, part of every sample's key
METHOD = "sobol (owen scrambling) -> inverse normal cdf; factors of musclemetab.uncertainty; solve flags recorded"


@functools.lru_cache(maxsize=8)
def _priors(path: str | None, mtime_ns: int | None):
    from ..uncertainty import read_priors

    return read_priors(path)


def study_priors(study: Study):
    """The :class:`~musclemetab.uncertainty.Priors` of the study (the package's, with its file's rows)."""
    path = (study.settings.get("uncertainty") or {}).get("priors")
    return _priors(path, Path(path).stat().st_mtime_ns if path else None)


def check_priors_muscles(study: Study) -> None:
    """Refuse, before any unit runs, a priors file of the study (``[uncertainty] priors``,
    ``--uncertainty-priors``) with a row naming no muscle of a subject's model
    (:class:`~musclemetab.errors.UnknownMuscleError` naming the file, the muscle and the model);
    a sample would otherwise find it only when it runs."""
    if not (study.settings.get("uncertainty") or {}).get("priors"):
        return
    from ..model import read_model

    priors = study_priors(study)
    for subject in study.subjects:
        priors.check_muscles(read_model(subject.model).muscles.names, f"subject {subject.name}'s model {subject.model}")


def sample_key(study: Study, unit, nominal_key: str | None) -> str:
    """SHA-256 of what sample ``unit.sample`` depends on: its trial unit's key, the priors' values,
    the seed and the sampling rule."""
    from .. import __version__

    settings = study.settings.get("uncertainty") or {}
    content = {"musclemetab": __version__, "trial_unit": nominal_key, "sample": int(unit.sample),
               "seed": int(settings.get("seed", DEFAULT_SEED)), "priors": study_priors(study).digest(),
               "method": METHOD}
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()


def write_start(solution, folder: Path) -> None:
    """Write ``solution``'s optimum and multipliers (:attr:`Solution.multipliers
    <musclemetab.redundancy.solution.Solution.multipliers>`, when it has them) to ``folder``/:data:`START_FILE`."""
    import numpy as np

    if getattr(solution, "multipliers", None):
        np.savez(Path(folder) / START_FILE, **{k: np.asarray(solution.multipliers[k], dtype=float)
                                               for k in ("x", "lam_x", "lam_g")})


def read_start(solution, folder: Path):
    """``solution`` (read from ``folder``) with the optimum and multipliers of ``folder``/:data:`START_FILE`
    (unchanged when the file is absent or unreadable: a trial unit of an earlier version)."""
    from dataclasses import replace

    import numpy as np

    try:
        with np.load(Path(folder) / START_FILE) as data:
            return replace(solution, multipliers={k: data[k] for k in ("x", "lam_x", "lam_g")})
    except (OSError, ValueError, KeyError):
        return solution


def _record(folder: Path) -> dict:
    """The trial unit's ``unit.json`` (empty when absent or unreadable)."""
    from ..study_layout import UNIT_FILE

    try:
        return json.loads((Path(folder) / UNIT_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def run_sample(study: Study, unit, tmp: Path, nominal_folder: Path, *, options=None, goals=None,
               arguments: Mapping | None = None, analysis_file: str = "analysis.csv") -> dict:
    """Solve and evaluate sample ``unit.sample`` (a :class:`~.units.Unit`) of its trial unit (folder
    ``nominal_folder``) into ``tmp``; ``options``, ``goals`` and ``arguments`` are the trial unit's solver
    options, goals and the rest of its solve's keywords (its leg, window, ground forces and DOFs:
    :func:`~.units.trial_solve_keywords`; passive calibration, tendon stiffness; a device),
    ``analysis_file`` the name of its analysis table. The rates are averaged over the span of
    the trial unit's."""
    from ..events import GaitCycle
    from ..analysis.groups import has_function_group
    from ..analysis.unit import analyse_metabolics, filtered_moment_arms
    from ..geometry import compute_geometry
    from ..metabolics.per_muscle import PER_MUSCLE_FILE, per_muscle_table
    from ..metabolics.solution import WHOLE_BODY_CSV, metabolics_from_solution
    from ..redundancy import run as redundancy_run
    from ..redundancy.solution import Solution
    from ..uncertainty import draw, sample_start, sampled_properties
    from .events import rates_span_s

    nominal = _record(nominal_folder)
    if nominal.get("status") != "ok":
        raise OptionError(f"{nominal_folder}: the trial unit of {unit.label} has no result; run the study again")
    subject = study.subject(unit.subject)
    trial = subject.trial(unit.trial)
    side = unit.leg(study)
    settings = study.settings.get("uncertainty") or {}
    t0 = time.perf_counter()
    start = read_start(Solution.load(nominal_folder), nominal_folder)
    factors = draw(study_priors(study), start.muscles, unit.sample, int(settings.get("seed", DEFAULT_SEED)))
    factors.table().to_csv(tmp / FACTORS_FILE, index=False, float_format="%.17g")
    sol = redundancy_run.solve_files(
        subject.model, trial.ik, trial.id, unit.workflow, options=options, goals=goals,
        warm_start=sample_start(start, factors.parameters(start.parameters)), parameter_transform=factors.parameters,
        **dict(arguments or {}))
    times = {"solve_s": sol.record.solve_time_s, "solve_cpu_s": sol.record.solve_cpu_time_s,
             "solution_s": time.perf_counter() - t0}
    record = {"times": times, "converged": bool(sol.success), "solve_status": sol.status,
              "start": sol.record.initial_guess,  # from the trial unit's optimum and multipliers, or adapted
              "iterations": sol.record.get("iterations"),
              "height_factor": factors.height,
              # checked as any solve is (docs/quality.md): the bands leave a flagged sample out
              "plausibility": [f.to_dict() for f in sol.record.flags],
              "convergence": None if sol.record.convergence is None else sol.record.convergence.to_dict()}
    if not sol.success:  # recorded, left out of the bands
        return record
    t1 = time.perf_counter()
    masses, fst = sampled_properties(factors, sol, subject.body_mass_kg, subject.height_m, subject.muscle_properties)
    speed = nominal.get("speed_m_per_s")
    result = metabolics_from_solution(
        sol, subject.body_mass_kg, subject.height_m, models=list(study.models), basal=study.basal,
        basal_rate_W_per_kg=study.basal_coefficient, basal_exponent=study.basal_exponent, speed_m_per_s=speed,
        muscle_properties=subject.muscle_properties, muscle_masses_kg=masses, slow_twitch_fractions=fst,
        cycle_s=rates_span_s(nominal.get("rates_over_s")))
    cycle = GaitCycle(**{k: float(v) for k, v in nominal["cycle"].items()})
    result.whole_body_table().to_csv(tmp / WHOLE_BODY_CSV, index=False, float_format="%.10g")
    per_muscle_table(result, cycle).to_csv(tmp / PER_MUSCLE_FILE, index=False, float_format="%.10g")
    geometry = compute_geometry(subject.model, trial.ik, dofs=[d for d in sol.dofs if has_function_group(d)],
                                side=side)
    tg, r = filtered_moment_arms(geometry)
    analysis = analyse_metabolics(result, tg, r, list(geometry.dofs), list(geometry.muscles), cycle)
    analysis.summary.to_csv(tmp / analysis_file, index=False, float_format="%.10g")
    times["metabolics_s"] = time.perf_counter() - t1
    record.update(speed_m_per_s=speed, toe_off_pct=nominal.get("toe_off_pct"),
                  whole_body_W_per_kg={m: float(result.whole_body[m].mean_W_per_kg) for m in result.models})
    return record
