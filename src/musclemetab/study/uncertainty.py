"""Uncertainty samples of a study's trial units, and the bands they give its tables.

A study file's ``[uncertainty]`` table (or ``musclemetab run|demo --uncertainty N``) asks for
``samples`` samples of every trial unit of an effort workflow (EMG-TEN units and the
EMG-informed solves of a subject's ``emg_mode`` have none)::

    [uncertainty]
    samples = 64          # per trial unit (and leg)
    seed = 1              # of the Sobol' sequence (default 1)
    priors = "mine.csv"   # optional: rows replacing the package's priors (musclemetab.uncertainty)

Sample ``k`` of a trial unit is a unit of its own, folder ``<unit>/samples/<kkkk>``, run after
its trial unit on the same executors (processes, Dask) and resumable like any other: its key
is the trial unit's key, the priors' values, the seed and ``k``. It draws the factors of
sample ``k`` (:func:`musclemetab.uncertainty.draw`), solves the trial again with the
muscle-tendon parameters multiplied by them, warm-started from the trial unit's solution
adapted to them (:func:`musclemetab.uncertainty.adapted_start`: the same tendon forces;
:func:`musclemetab.redundancy.run.solve_files`, ``warm_start`` and ``parameter_transform``),
evaluates every metabolic model of the study with the sampled muscle masses, slow-twitch
fractions and height, and writes ``whole_body.csv``, ``analysis.csv`` and ``per_muscle.csv``
(the trial unit's columns) and ``factors.csv`` (the factors of every muscle). A sample whose
solve does not converge is recorded (``converged: false``) and left out of the bands.

:func:`add_study_bands` adds to ``results.csv`` and ``per_muscle.csv`` the 5 %, 50 % and
95 % quantiles of each rate over the converged samples (``<rate>_p05``, ``_p50``, ``_p95``
beside the rate) and ``uncertainty_samples``; a study without samples keeps its tables as
they were.
"""

from __future__ import annotations

import functools
import hashlib
import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Mapping

from ..errors import OptionError
from .spec import EMG_TEN, Study
from .units import Unit, plan_units, read_unit_record

__all__ = ["uncertainty_settings", "with_uncertainty", "study_priors", "sample_units", "sample_key", "run_sample",
           "add_study_bands", "add_uncertainty_arguments", "apply_uncertainty_arguments", "RESULT_BAND_COLUMNS",
           "MUSCLE_BAND_COLUMNS", "FACTORS_FILE", "DEFAULT_SEED"]

UNCERTAINTY_KEYS = {"samples", "seed", "priors"}
DEFAULT_SEED = 1
FACTORS_FILE = "factors.csv"
#: the sampling rule, part of every sample's key
METHOD = "sobol (owen scrambling) -> inverse normal cdf; factors of musclemetab.uncertainty"
#: results.csv columns given a band (and the share_<G>_pct family)
RESULT_BAND_COLUMNS = (
    "whole_body_W_per_kg", "whole_body_no_basal_W_per_kg", "leg_muscles_W", "gross_cost_of_transport_J_per_kg_per_m",
    "net_cost_of_transport_J_per_kg_per_m", "leg_energy_J", "stance_energy_share_pct", "swing_energy_share_pct",
    "stance_energy_share_with_basal_pct", "swing_energy_share_with_basal_pct",
)
#: per_muscle.csv columns given a band
MUSCLE_BAND_COLUMNS = ("muscle_W", "muscle_W_per_kg", "energy_per_cycle_J", "share_of_leg_pct", "stance_J", "swing_J")
_MUSCLE_KEYS = ("subject", "trial", "workflow", "model", "muscle")
_RESULT_KEYS = ("subject", "trial", "workflow", "model")


# ---------------------------------------------------------------------------------------- settings
def uncertainty_settings(data, base: Path, where: str) -> dict:
    """The ``[uncertainty]`` table checked: ``{"samples", "seed"[, "priors"]}`` (``{}`` for 0 samples)."""
    from ..settings import check_number
    from .spec import _path, _unknown

    if not isinstance(data, Mapping):
        raise OptionError(f"{where}: 'uncertainty' must be a table such as [uncertainty] samples = 64, seed = 1")
    here = f"{where}: [uncertainty]"
    _unknown(data, UNCERTAINTY_KEYS, here)
    if "samples" not in data:
        raise OptionError(f"{here}: 'samples' is required (the number of samples of every trial unit, e.g. 64)")
    samples = check_number("samples", data["samples"], here)
    seed = check_number("seed", data.get("seed", DEFAULT_SEED), here)
    out = {"samples": samples, "seed": seed}
    priors = _path(data.get("priors"), base, here, "priors", required=False)
    if priors is not None:
        from ..uncertainty import read_priors

        read_priors(priors)  # checked now, before anything runs
        out["priors"] = str(priors)
    return out if samples else {}


def with_uncertainty(study: Study, samples: int | None = None, seed: int | None = None,
                     priors: str | Path | None = None) -> Study:
    """``study`` with its ``[uncertainty]`` settings replaced by those given (``None``: kept)."""
    current = dict(study.settings.get("uncertainty") or {})
    if samples is not None:
        current["samples"] = int(samples)
    if seed is not None:
        current["seed"] = int(seed)
    if priors is not None:
        from ..uncertainty import read_priors

        read_priors(priors)
        current["priors"] = str(Path(priors).resolve())
    if current and "samples" not in current:
        raise OptionError("--uncertainty-seed and --uncertainty-priors need --uncertainty N (the number of samples) "
                          "or a study file with [uncertainty] samples")
    current.setdefault("seed", DEFAULT_SEED)
    settings = {k: v for k, v in study.settings.items() if k != "uncertainty"}
    if current.get("samples"):
        settings["uncertainty"] = current
    return replace(study, settings=settings)


def add_uncertainty_arguments(parser) -> None:
    """``--uncertainty N``, ``--uncertainty-seed SEED`` and ``--uncertainty-priors FILE`` of the
    commands that run a study; :func:`apply_uncertainty_arguments` applies them."""
    from ..commands.options import number_option

    number_option(parser, "--uncertainty", "samples", metavar="N",
                  help="uncertainty bands: N samples of the muscle properties for every trial (the study file's "
                  "[uncertainty] samples; docs/uncertainty.md)")
    number_option(parser, "--uncertainty-seed", "seed", metavar="SEED",
                  help="seed of the uncertainty samples (default: the study file's, else 1)")
    parser.add_argument("--uncertainty-priors", metavar="FILE",
                        help="CSV of priors (parameter,distribution,spread,muscle,source) replacing the package's rows")


def apply_uncertainty_arguments(study: Study, args) -> Study:
    """``study`` with the ``--uncertainty...`` options of ``args`` (checked) applied."""
    from ..commands.options import check_number_options

    check_number_options(args)
    samples, seed, priors = (getattr(args, k, None) for k in ("uncertainty", "uncertainty_seed", "uncertainty_priors"))
    if samples is None and seed is None and priors is None:
        return study
    return with_uncertainty(study, samples, seed, priors)


@functools.lru_cache(maxsize=8)
def _priors(path: str | None, mtime_ns: int | None):
    from ..uncertainty import read_priors

    return read_priors(path)


def study_priors(study: Study):
    """The :class:`~musclemetab.uncertainty.Priors` of the study (the package's, with its file's rows)."""
    path = (study.settings.get("uncertainty") or {}).get("priors")
    return _priors(path, Path(path).stat().st_mtime_ns if path else None)


# ---------------------------------------------------------------------------------------- units
def is_sampled(study: Study, unit: Unit) -> bool:
    """Whether a trial unit has uncertainty samples: an effort workflow solved from its files."""
    subject = study.subject(unit.subject)
    return unit.trial is not None and unit.workflow != EMG_TEN and subject.emg_mode is None


def sample_units(study: Study) -> list[Unit]:
    """The uncertainty samples of the study's trial units, sample by sample (the first samples of
    every trial first)."""
    settings = study.settings.get("uncertainty") or {}
    n = int(settings.get("samples", 0))
    if not n:
        return []
    trials = [u for u in plan_units(study)[1] if is_sampled(study, u)]
    return [replace(u, sample=k) for k in range(n) for u in trials]


def sample_key(study: Study, unit: Unit, nominal_key: str | None) -> str:
    """SHA-256 of what sample ``unit.sample`` depends on: its trial unit's key, the priors' values,
    the seed and the sampling rule."""
    from .. import __version__

    settings = study.settings.get("uncertainty") or {}
    content = {"musclemetab": __version__, "trial_unit": nominal_key, "sample": int(unit.sample),
               "seed": int(settings.get("seed", DEFAULT_SEED)), "priors": study_priors(study).digest(),
               "method": METHOD}
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()


def _solve_arguments(study: Study, subject, unit: Unit) -> dict:
    """The personalisation arguments of the trial unit's solve (passive calibration, tendon stiffness)."""
    kwargs = {}
    if unit.workflow != "effort-gen" and subject.passive is not None:
        kwargs["passive"] = subject.passive
    if unit.workflow == "effort-ten":
        kt = subject.tendon_stiffness
        if subject.uses_emg_ten_estimate:
            kwargs["tendon_stiffness_file"] = Path(study.output) / Unit(subject.name, None, EMG_TEN).folder / \
                "parameters.json"
        elif isinstance(kt, Path):
            kwargs["tendon_stiffness_file"] = kt
        elif isinstance(kt, (dict, str)):
            kwargs["tendon_stiffness"] = kt
    return kwargs


def run_sample(study: Study, unit: Unit, tmp: Path, nominal_folder: Path) -> dict:
    """Solve and evaluate sample ``unit.sample`` of its trial unit (folder ``nominal_folder``) into ``tmp``."""
    from ..analysis.events import GaitCycle
    from ..analysis.groups import has_function_group
    from ..analysis.unit import analyse_metabolics, filtered_moment_arms
    from ..geometry import compute_geometry
    from ..metabolics.per_muscle import PER_MUSCLE_FILE, per_muscle_table
    from ..metabolics.solution import WHOLE_BODY_CSV, metabolics_from_solution
    from ..properties import metabolic_properties
    from ..redundancy import run as redundancy_run
    from ..redundancy.solution import Solution
    from ..uncertainty import adapted_start, draw
    from .units import ANALYSIS_FILE, _solver_options

    nominal = read_unit_record(nominal_folder) or {}
    if nominal.get("status") != "ok":
        raise OptionError(f"{nominal_folder}: the trial unit of {unit.label} has no result; run the study again")
    subject = study.subject(unit.subject)
    trial = subject.trial(unit.trial)
    side = unit.leg(study)
    settings = study.settings.get("uncertainty") or {}
    t0 = time.perf_counter()
    start = Solution.load(nominal_folder)
    factors = draw(study_priors(study), start.muscles, unit.sample, int(settings.get("seed", DEFAULT_SEED)))
    factors.table().to_csv(tmp / FACTORS_FILE, index=False, float_format="%.17g")
    sol = redundancy_run.solve_files(
        subject.model, trial.ik, trial.id, unit.workflow, side=side, dofs=subject.dofs,
        external_loads=trial.external_loads, grf=trial.grf if trial.cycle is not None else None,
        grf_column=trial.grf_column, grf_threshold_N=trial.grf_threshold_N, cycle=trial.cycle,
        options=_solver_options(study, subject), exclude_muscles=subject.exclude_muscles,
        exclude_missing_ok=subject.side == "both", warm_start=adapted_start(start, factors.parameters(start.parameters)),
        parameter_transform=factors.parameters,
        **_solve_arguments(study, subject, unit))
    times = {"solve_s": sol.record.solve_time_s, "solution_s": time.perf_counter() - t0}
    record = {"times": times, "converged": bool(sol.success), "solve_status": sol.status,
              "iterations": sol.record.get("iterations"),
              "height_factor": factors.height}
    if not sol.success:  # recorded, left out of the bands
        return record
    t1 = time.perf_counter()
    params = sol.parameters.subset(sol.muscles)
    masses, fst = metabolic_properties(list(sol.muscles), subject.body_mass_kg, subject.height_m * factors.height,
                                       params.max_isometric_force_N, params.optimal_fiber_length_m,
                                       overrides=subject.muscle_properties)
    masses, fst = factors.metabolic_properties(masses, fst)
    speed = nominal.get("speed_m_per_s")
    result = metabolics_from_solution(
        sol, subject.body_mass_kg, subject.height_m, models=list(study.models), basal=study.basal,
        basal_rate_W_per_kg=study.basal_coefficient, basal_exponent=study.basal_exponent, speed_m_per_s=speed,
        muscle_properties=subject.muscle_properties, muscle_masses_kg=dict(zip(sol.muscles, masses.tolist())),
        slow_twitch_fractions=dict(zip(sol.muscles, fst.tolist())))
    cycle = GaitCycle(**{k: float(v) for k, v in nominal["cycle"].items()})
    result.whole_body_table().to_csv(tmp / WHOLE_BODY_CSV, index=False, float_format="%.10g")
    per_muscle_table(result, cycle).to_csv(tmp / PER_MUSCLE_FILE, index=False, float_format="%.10g")
    geometry = compute_geometry(subject.model, trial.ik, dofs=[d for d in sol.dofs if has_function_group(d)],
                                side=side)
    tg, r = filtered_moment_arms(geometry)
    analysis = analyse_metabolics(result, tg, r, list(geometry.dofs), list(geometry.muscles), cycle)
    analysis.summary.to_csv(tmp / ANALYSIS_FILE, index=False, float_format="%.10g")
    times["metabolics_s"] = time.perf_counter() - t1
    record.update(speed_m_per_s=speed, toe_off_pct=nominal.get("toe_off_pct"),
                  whole_body_W_per_kg={m: float(result.whole_body[m].mean_W_per_kg) for m in result.models})
    return record


# ---------------------------------------------------------------------------------------- bands
def _sample_tables(study: Study):
    """The converged samples' rows: ``(results rows, per-muscle rows)`` with a ``sample`` column
    (a ``side = "both"`` subject's legs added per sample, as its trial units' are)."""
    import pandas as pd

    from ..metabolics.per_muscle import PER_MUSCLE_FILE
    from .runner import add_leg_rows, leg_basal_energy_J, trial_result_rows

    out = Path(study.output)
    legs: dict[tuple, dict] = {}
    muscles = []
    for unit in sample_units(study):
        folder = out / unit.folder
        rec = read_unit_record(folder)
        group = legs.setdefault((unit.subject, unit.trial, unit.workflow, unit.sample), {})
        if not rec or rec.get("status") != "ok" or not rec.get("converged"):
            group[unit.side] = None
            continue
        rows = trial_result_rows(pd.read_csv(folder / "whole_body.csv"), pd.read_csv(folder / "analysis.csv"),
                                 speed_m_per_s=rec.get("speed_m_per_s"), toe_off_pct=rec.get("toe_off_pct"))
        pm = pd.read_csv(folder / PER_MUSCLE_FILE)
        group[unit.side] = (rows, pm)
        for k, (col, val) in enumerate((("subject", unit.subject), ("trial", unit.trial),
                                        ("workflow", unit.workflow), ("sample", unit.sample))):
            pm.insert(k, col, val)
        muscles.append(pm)
    frames = []
    for (subject, trial, workflow, sample), group in legs.items():
        if any(v is None for v in group.values()):
            continue  # a leg's sample did not converge: no whole-body row of this sample
        if None in group:
            df = group[None][0]
        else:
            rows = {side: df for side, (df, _) in group.items()}
            basal = {side: leg_basal_energy_J(pm, df["duration_s"].iloc[0]) for side, (df, pm) in group.items()}
            df = add_leg_rows(rows, basal)
        df = df.copy()
        for k, (col, val) in enumerate((("subject", subject), ("trial", trial), ("workflow", workflow),
                                        ("sample", sample))):
            df.insert(k, col, val)
        frames.append(df)
    results = pd.concat(frames, ignore_index=True) if frames else None
    per_muscle = pd.concat(muscles, ignore_index=True) if muscles else None
    return results, per_muscle


def add_study_bands(study: Study, table, kind: str):
    """``table`` (``kind``: ``"results"`` or ``"per_muscle"``) with the bands of its rates over
    the study's converged samples beside them; unchanged for a study without samples."""
    from ..uncertainty import band_table, with_bands

    if not study.settings.get("uncertainty") or not sample_units(study):
        return table
    results, per_muscle = _sample_tables(study)
    if kind == "results":
        samples, keys = results, _RESULT_KEYS
        columns = [c for c in RESULT_BAND_COLUMNS if c in table] + [
            c for c in table.columns if c.startswith("share_") and c.endswith("_pct")]
    else:
        samples, keys = per_muscle, _MUSCLE_KEYS
        columns = [c for c in MUSCLE_BAND_COLUMNS if c in table]
    if not len(table):
        return table
    bands = band_table(samples, keys, columns) if samples is not None else None
    return with_bands(table, bands, keys)
