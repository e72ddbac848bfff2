"""Uncertainty samples of a study's trial units: which there are, and the bands they give the
study's tables (``docs/uncertainty.md``; one sample's key and run: :mod:`.samples`).

A study file's ``[uncertainty]`` table (or ``musclemetab run|demo --uncertainty N``) asks for
``samples`` samples of every trial unit of an effort workflow (EMG-TEN units and the
EMG-informed solves of a subject's ``emg_mode`` have none)::

    [uncertainty]
    samples = 64          # per trial unit (and leg)
    seed = 1              # of the Sobol' sequence (default 1)
    priors = "mine.csv"   # optional: rows replacing the package's priors (musclemetab.uncertainty)

Sample ``k`` of a trial unit is a unit of its own, folder ``<unit>/samples/<kkkk>``, run after
its trial unit on the same executors (processes, Dask) and resumable like any other.

:func:`add_study_bands` adds to ``results.csv`` and ``per_muscle.csv`` the 5 %, 50 % and
95 % quantiles of each rate over the converged samples (``<rate>_p05``, ``_p50``, ``_p95``
beside the rate) and ``uncertainty_samples``; a study without samples keeps its tables as
they were.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Callable

from ..errors import OptionError
from ..uncertainty import DEFAULT_SEED
from .spec import EMG_TEN, STATES, Study
from .units import Unit, plan_units, read_unit_record

__all__ = ["with_uncertainty", "sample_units", "is_sampled", "add_study_bands", "RESULT_BAND_COLUMNS",
           "MUSCLE_BAND_COLUMNS"]

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
def with_uncertainty(study: Study, samples: int | None = None, seed: int | None = None,
                     priors: str | Path | None = None) -> Study:
    """``study`` with its ``[uncertainty]`` settings replaced by those given (``None``: kept; the
    command line's ``--uncertainty N``, ``--uncertainty-seed``, ``--uncertainty-priors``)."""
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


# ---------------------------------------------------------------------------------------- units
def is_sampled(study: Study, unit: Unit) -> bool:
    """Whether a trial unit has uncertainty samples: an effort workflow solved from its files."""
    subject = study.subject(unit.subject)
    return unit.trial is not None and unit.workflow not in (EMG_TEN, STATES) and subject.emg_mode is None


def sample_units(study: Study) -> list[Unit]:
    """The uncertainty samples of the study's trial units, sample by sample (the first samples of
    every trial first)."""
    settings = study.settings.get("uncertainty") or {}
    n = int(settings.get("samples", 0))
    if not n:
        return []
    trials = [u for u in plan_units(study)[1] if is_sampled(study, u)]
    return [replace(u, sample=k) for k in range(n) for u in trials]


# ---------------------------------------------------------------------------------------- bands
def sample_tables(study: Study, trial_result_rows: Callable, add_leg_rows: Callable, leg_basal_energy_J: Callable):
    """The converged samples' rows: ``(results rows, per-muscle rows)`` with a ``sample`` column,
    made as the study's results rows are, by the functions of :mod:`.runner` given (a ``side =
    "both"`` subject's legs added per sample, as its trial units' are)."""
    import pandas as pd

    from ..metabolics.per_muscle import PER_MUSCLE_FILE

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
                                 speed_m_per_s=rec.get("speed_m_per_s"), toe_off_pct=rec.get("toe_off_pct"),
                                 excluded_muscles=study.subject(unit.subject).exclude_muscles)
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


def add_study_bands(study: Study, table, kind: str, builders: tuple[Callable, Callable, Callable]):
    """``table`` (``kind``: ``"results"`` or ``"per_muscle"``) with the bands of its rates over
    the study's converged samples beside them (``builders``: the row functions of
    :func:`sample_tables`); unchanged for a study without samples."""
    from ..uncertainty import band_table, with_bands

    if not study.settings.get("uncertainty") or not sample_units(study):
        return table
    results, per_muscle = sample_tables(study, *builders)
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
