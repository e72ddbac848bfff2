"""Uncertainty samples of a study's trial units: which there are, and the bands they give the
study's tables (``docs/uncertainty.md``; one sample's key and run: :mod:`.samples`).

A study file's ``[uncertainty]`` table (or ``musclemetab run|demo --uncertainty N``) asks for
``samples`` samples of every trial unit of an effort workflow (EMG-TEN units and the
EMG-informed solves of a subject's ``emg_mode`` have none)::

    [uncertainty]
    samples = 64          # per trial unit (and leg)
    seed = 1              # of the Sobol' sequence (default 1)
    priors = "mine.csv"   # optional: rows replacing the package's priors (musclemetab.uncertainty)
    keep_flagged = false  # optional: the bands also take samples with a plausibility flag

Sample ``k`` of a trial unit is a unit of its own, folder ``<unit>/samples/<kkkk>``, run after
its trial unit on the same executors (processes, Dask) and resumable like any other.

:func:`add_study_bands` adds to ``results.csv`` and ``per_muscle.csv`` the band of each rate
over the plausible samples (converged, no plausibility flag; every converged one with
``keep_flagged = true``): ``<rate>_p05``, ``_p50``, ``_p95`` beside the rate (the 5-95 %
quantiles, the min-max below :data:`~musclemetab.uncertainty.QUANTILE_SAMPLES`),
``uncertainty_samples``, ``uncertainty_rejected``, ``uncertainty_band``; in ``results.csv`` the
flagged samples, where the nominal whole-body rate lies in its band and why; with sensitivities
the parameters that make each band's width. A study without samples keeps its tables as they
were.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Callable

from ..errors import OptionError
from ..uncertainty import DEFAULT_SEED
from .spec import Study
from .units import Unit, is_sampled, plan_units, read_unit_record

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
                     priors: str | Path | None = None, *, keep_flagged: bool | None = None) -> Study:
    """``study`` with its ``[uncertainty]`` settings replaced by those given (``None``: kept; the
    command line's ``--uncertainty N``, ``--uncertainty-seed``, ``--uncertainty-priors``,
    ``--keep-flagged-samples``)."""
    current = dict(study.settings.get("uncertainty") or {})
    if samples is not None:
        current["samples"] = int(samples)
    if keep_flagged is not None:
        current["keep_flagged"] = bool(keep_flagged)
    if seed is not None:
        current["seed"] = int(seed)
    if priors is not None:
        from ..uncertainty import read_priors

        read_priors(priors)
        current["priors"] = str(Path(priors).resolve())
    if current and "samples" not in current:
        raise OptionError("--uncertainty-seed, --uncertainty-priors and --keep-flagged-samples need --uncertainty N (the number of samples) "
                          "or a study file with [uncertainty] samples")
    current.setdefault("seed", DEFAULT_SEED)
    settings = {k: v for k, v in study.settings.items() if k != "uncertainty"}
    if current.get("samples"):
        settings["uncertainty"] = current
    return replace(study, settings=settings)


# ---------------------------------------------------------------------------------------- units
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
def _solve_flags(rec: dict) -> list:
    """The solve's plausibility flags of a sample's record (``None``: not recorded, an earlier version)."""
    from ..quality import flags_from_records

    if "plausibility" not in rec:
        return None
    return [f for f in flags_from_records(rec["plausibility"]) if f.model is None]


def sample_tables(study: Study, trial_result_rows: Callable, add_leg_rows: Callable, leg_basal_energy_J: Callable):
    """Every sample's rows: ``(results rows, per-muscle rows)`` with the columns ``sample`` and
    ``sample_flags``, made as the study's results rows are, by the functions of :mod:`.runner`
    given (a ``side = "both"`` subject's legs added per sample, as its trial units' are).

    ``sample_flags`` is ``""`` for a plausible sample, else the flags of the row as the nominal
    row's ``quality`` has them (:func:`~musclemetab.quality.quality_text`: the solve's flags, every
    leg's, and the row's metabolic flags); :data:`~musclemetab.uncertainty.NOT_CONVERGED` for a
    sample a leg of which did not converge (a row per model with no values), ``not_checked`` for
    a sample written by a version that did not record its flags."""
    import pandas as pd

    from ..metabolics.per_muscle import PER_MUSCLE_FILE
    from ..metabolics.plausibility import results_rows_flags
    from ..quality import quality_text
    from ..uncertainty import NOT_CONVERGED

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
        group[unit.side] = (rows, pm, _solve_flags(rec))
        for k, (col, val) in enumerate((("subject", unit.subject), ("trial", unit.trial),
                                        ("workflow", unit.workflow), ("sample", unit.sample))):
            pm.insert(k, col, val)
        muscles.append(pm)
    frames = []
    for (subject, trial, workflow, sample), group in legs.items():
        if any(v is None for v in group.values()):  # a leg's sample did not converge: rejected
            df = pd.DataFrame({"model": list(study.models)})
            df["sample_flags"] = NOT_CONVERGED
        else:
            if None in group:
                df = group[None][0]
            else:
                rows = {side: df for side, (df, _, _) in group.items()}
                basal = {side: leg_basal_energy_J(pm, df["duration_s"].iloc[0]) for side, (df, pm, _) in group.items()}
                df = add_leg_rows(rows, basal)
            df = df.copy().reset_index(drop=True)
            solve = [v[2] for v in group.values()]
            if any(f is None for f in solve):
                df["sample_flags"] = "not_checked"
            else:
                solve = [f for fl in solve for f in fl]
                df["sample_flags"] = ["" if not (fl := solve + [f for f in results_rows_flags(df.iloc[[i]])])
                                      else quality_text(fl) for i in range(len(df))]
        for k, (col, val) in enumerate((("subject", subject), ("trial", trial), ("workflow", workflow),
                                        ("sample", sample))):
            df.insert(k, col, val)
        frames.append(df)
    results = pd.concat(frames, ignore_index=True) if frames else None
    per_muscle = pd.concat(muscles, ignore_index=True) if muscles else None
    if per_muscle is not None and results is not None:  # a muscle's sample is rejected with its row's
        verdict = results[[*_RESULT_KEYS, "sample", "sample_flags"]]
        per_muscle = per_muscle.merge(verdict, on=[*_RESULT_KEYS, "sample"], how="left")
        rejected = verdict[verdict["sample_flags"] == NOT_CONVERGED]
        if len(rejected):  # the muscles of samples that did not converge: counted as rejected
            names = per_muscle[[*_MUSCLE_KEYS]].drop_duplicates()
            per_muscle = pd.concat([per_muscle, rejected.merge(names, on=list(_RESULT_KEYS))], ignore_index=True)
    return results, per_muscle


def _top_parameters(study: Study, table, kind: str):
    """``uncertainty_top_parameters`` of each row of ``table`` (``None`` without sensitivities):
    the :data:`~musclemetab.uncertainty.TOP_PARAMETERS` parameters whose priors give the row's rate
    (``whole_body_W_per_kg`` in results.csv, ``muscle_W`` in per_muscle.csv) the largest
    linearised SD, from the trial unit's ``sensitivity.csv``
    (:func:`musclemetab.uncertainty.width_contributions`)."""
    import pandas as pd

    from ..redundancy.sensitivity import SENSITIVITY_CSV
    from ..uncertainty import top_parameters_text, width_contributions
    from .samples import study_priors

    priors = study_priors(study)
    texts = {}
    units = [u for u in plan_units(study)[1] if is_sampled(study, u)]
    by_trial: dict[tuple, list] = {}
    for unit in units:
        path = Path(study.output) / unit.folder / SENSITIVITY_CSV
        if path.is_file():
            by_trial.setdefault((unit.subject, unit.trial, unit.workflow), []).append(pd.read_csv(path))
    if not by_trial:
        return None
    for key, tables in by_trial.items():
        sens = pd.concat(tables, ignore_index=True)
        if kind == "results":
            contrib = width_contributions(sens, priors)
            for model, d in contrib.groupby("model", sort=False):
                texts[(*key, model)] = top_parameters_text(d)
        else:
            sens = sens[sens["rate"].astype(str) != "whole_body"]
            for rate, d in sens.groupby(sens["rate"].astype(str), sort=False):
                contrib = width_contributions(d, priors, rate)
                for model, dm in contrib.groupby("model", sort=False):
                    texts[(*key, model, rate)] = top_parameters_text(dm)
    keys = _RESULT_KEYS if kind == "results" else _MUSCLE_KEYS
    return [texts.get(tuple(r), "") for r in table[list(keys)].astype(str).itertuples(index=False)]


def add_study_bands(study: Study, table, kind: str, builders: tuple[Callable, Callable, Callable]):
    """``table`` (``kind``: ``"results"`` or ``"per_muscle"``) with the bands of its rates over
    the study's plausible samples beside them (every converged sample with ``[uncertainty]
    keep_flagged``), the counts of used and rejected samples, the band's kind, in results.csv the
    list of flagged samples and where the nominal whole-body rate lies in its band, and the
    parameters that make the width when the trial units have sensitivities (``builders``: the
    row functions of :func:`sample_tables`); unchanged for a study without samples."""
    from ..uncertainty import band_table, with_bands

    settings = study.settings.get("uncertainty") or {}
    if not settings or not sample_units(study):
        return table
    results, per_muscle = sample_tables(study, *builders)
    keep = bool(settings.get("keep_flagged", False))
    if kind == "results":
        samples, keys = results, _RESULT_KEYS
        columns = [c for c in RESULT_BAND_COLUMNS if c in table] + [
            c for c in table.columns if c.startswith("share_") and c.endswith("_pct")]
        extra = {"nominal": table, "note_column": "whole_body_W_per_kg", "listing": True}
    else:
        samples, keys = per_muscle, _MUSCLE_KEYS
        columns = [c for c in MUSCLE_BAND_COLUMNS if c in table]
        extra = {}
    if not len(table):
        return table
    bands = band_table(samples, keys, columns, keep_flagged=keep, **extra) if samples is not None else None
    out = with_bands(table, bands, keys)
    top = _top_parameters(study, out, kind)
    if top is not None:
        out["uncertainty_top_parameters"] = top
    return out
