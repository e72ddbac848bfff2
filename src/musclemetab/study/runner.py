"""Run a study: every unit, in parallel processes or on a Dask cluster, resumable.

:func:`run_study` plans the units (:mod:`musclemetab.study.units`), skips those that are
complete with an unchanged key, runs the others — EMG-TEN estimations first, then the
trial units — and gathers every complete unit into one results table:

``DIR/results.csv`` and ``DIR/results.parquet``
    one row per subject × trial × workflow × model: whole-body rate (W/kg, with and
    without basal heat), cost of transport, stance and swing shares, muscle-group shares,
    toe-off (% of the cycle), speed and measured rate when the study gives calorimetry.
``DIR/per_muscle.csv`` and ``DIR/per_muscle.parquet``
    one row per subject × trial × workflow × model × muscle (with its side): the
    per-muscle table of every unit (:mod:`musclemetab.analysis.per_muscle`).
``DIR/muscle_groups.csv``
    the key of the muscle-group abbreviations of the ``share_<G>_pct`` columns.
``DIR/data_dictionary.csv``
    every column of every table the package writes, with its unit and meaning.
``DIR/failures.csv``
    one row per failed unit with its reason.
``DIR/study.json``
    the study's settings, subjects and the software versions.

Executors: ``workers=1`` runs the units in this process, one after the other;
``workers=N`` in a pool of N processes (started with ``spawn``; each runs its own OpenSim
worker); ``scheduler="tcp://host:port"`` on a Dask cluster (``pip install
musclemetab[dask]``; the workers need musclemetab installed and the study's files at the
same paths). A unit failure is recorded and the other units go on.
"""

from __future__ import annotations

import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

from .. import __version__
from ..errors import OptionError
from ..io.atomic import atomic_path, atomic_write_text
from .spec import Study
from .units import Unit, execute_unit, is_complete, plan_units, read_unit_record, unit_key

__all__ = ["run_study", "StudyRun", "collect_results", "software_versions", "RESULTS_CSV", "RESULTS_PARQUET"]

RESULTS_CSV = "results.csv"
RESULTS_PARQUET = "results.parquet"
FAILURES_CSV = "failures.csv"
PER_MUSCLE_PARQUET = "per_muscle.parquet"
GROUP_KEY_CSV = "muscle_groups.csv"
DATA_DICTIONARY_CSV = "data_dictionary.csv"
STUDY_JSON = "study.json"

#: columns of the results table that identify a row
ID_COLUMNS = ("subject", "trial", "workflow", "model")


@dataclass
class StudyRun:
    """What a run did: the units run, skipped and failed, and the results table."""

    output: Path
    ran: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    wall_time_s: float = 0.0
    results: object = None  # pandas.DataFrame
    report: Path | None = None

    @property
    def n_units(self) -> int:
        return len(self.ran) + len(self.skipped)

    def summary_line(self) -> str:
        return (f"{self.n_units} units: {len(self.ran)} run, {len(self.skipped)} up to date, "
                f"{len(self.failed)} failed; {0 if self.results is None else len(self.results)} result rows "
                f"in {self.wall_time_s:.1f} s -> {self.output}")


def software_versions() -> dict[str, str]:
    """Versions of the package and of the libraries its numbers depend on (no imports)."""
    from importlib.metadata import PackageNotFoundError, version

    out = {"musclemetab": __version__, "python": sys.version.split()[0]}
    for name in ("opensim", "casadi", "numpy", "scipy", "pandas", "matplotlib", "dask", "distributed"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            pass
    return out


# ---------------------------------------------------------------------------------------
class _Progress:
    """A one-line progress bar on a terminal; one line per unit otherwise."""

    def __init__(self, total: int, enabled: bool, stream=None):
        self.total, self.done, self.failed = total, 0, 0
        self.enabled = enabled and total > 0
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.t0 = time.perf_counter()

    def update(self, label: str, record: dict) -> None:
        self.done += 1
        self.failed += record.get("status") != "ok"
        if not self.enabled:
            return
        width = 24
        filled = int(width * self.done / self.total)
        bar = "#" * filled + "." * (width - filled)
        state = "ok" if record.get("status") == "ok" else "FAILED"
        line = (f"[{bar}] {self.done}/{self.total} units, {self.failed} failed, "
                f"{time.perf_counter() - self.t0:.0f} s | {label} {state}")
        if self.tty:
            self.stream.write("\r" + line[:160].ljust(160))
            if self.done == self.total:
                self.stream.write("\n")
        else:
            self.stream.write(line + "\n")
        self.stream.flush()


def _executor(workers: int, scheduler: str | None):
    """A ``submit``/``as_completed`` pair for the chosen executor, and a closer."""
    if scheduler:
        try:
            from distributed import Client
            from distributed import as_completed as dask_completed
        except ImportError:
            raise OptionError(
                "--scheduler needs Dask's distributed scheduler: pip install 'musclemetab[dask]'"
            ) from None
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise OptionError(f"cannot connect to the Dask scheduler at {scheduler} ({exc}); "
                              "check the address (tcp://host:port) and that the scheduler runs") from None

        def submit(fn, *args):
            return client.submit(fn, *args, pure=False)

        return submit, dask_completed, client.close
    if workers <= 1:
        return None, None, lambda: None
    import multiprocessing

    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    return pool.submit, as_completed, lambda: pool.shutdown(wait=True, cancel_futures=True)


def _run_units(study: Study, jobs: list[tuple[Unit, str, str | None]], submit, completed, progress: _Progress) -> dict:
    """Run ``(unit, key, dependency folder)`` jobs; returns ``{unit: record}``."""
    records = {}
    if submit is None:
        for unit, key, dep in jobs:
            rec = execute_unit(study, unit, key, dep)
            records[unit] = rec
            progress.update(unit.label, rec)
        return records
    futures = {submit(execute_unit, study, unit, key, dep): unit for unit, key, dep in jobs}
    for fut in completed(list(futures)):
        unit = futures[fut]
        try:
            rec = fut.result()
        except BaseException as exc:  # the worker process died, or the cluster lost the task
            rec = {"status": "failed", "error": f"{type(exc).__name__}: {exc} (worker lost)"}
        records[unit] = rec
        progress.update(unit.label, rec)
    return records


def run_study(
    study: Study,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    force: bool = False,
    progress: bool = True,
    stream=None,
) -> StudyRun:
    """Run every unit of ``study`` that is not already complete; write the results table.

    Parameters
    ----------
    workers
        Processes (default: the number of CPUs, at most the number of units); 1 runs in
        this process.
    scheduler
        Address of a Dask scheduler; the units run on its workers.
    force
        Run every unit again, complete or not.
    progress
        Show a progress bar (on ``stream``, default standard error).
    """
    t0 = time.perf_counter()
    out = Path(study.output)
    out.mkdir(parents=True, exist_ok=True)
    _write_study_json(study, out)
    stages = plan_units(study)
    n_total = sum(len(s) for s in stages)
    if workers is None:
        workers = min(os.cpu_count() or 1, n_total) if not scheduler else 0
    if not scheduler and workers < 1:
        raise OptionError(f"--workers must be at least 1, not {workers}")
    run = StudyRun(output=out)
    keys: dict[Unit, str] = {}
    bar = _Progress(n_total, progress, stream)
    submit, completed, close = _executor(workers, scheduler)
    try:
        for stage in stages:
            jobs = []
            for unit in stage:
                dep = unit.depends_on(study)
                dep_key = keys.get(dep) if dep is not None else None
                keys[unit] = key = unit_key(study, unit, dep_key)
                if dep is not None and dep.label in run.failed:
                    rec = {"status": "failed", "error": f"needs {dep.label}, which failed"}
                    run.failed[unit.label] = rec["error"]
                    bar.update(unit.label, rec)
                    continue
                if not force and is_complete(out / unit.folder, key):
                    run.skipped.append(unit.label)
                    bar.update(unit.label, {"status": "ok"})
                    continue
                jobs.append((unit, key, str(out / dep.folder) if dep is not None else None))
            for unit, rec in _run_units(study, jobs, submit, completed, bar).items():
                run.ran.append(unit.label)
                if rec.get("status") != "ok":
                    run.failed[unit.label] = rec.get("error") or "unknown error"
    finally:
        close()
    run.results = collect_results(study, failed=run.failed)
    run.wall_time_s = time.perf_counter() - t0
    return run


def _write_study_json(study: Study, out: Path) -> None:
    info = dict(study.settings)
    info["source"] = str(study.source) if study.source else None
    info["subjects"] = {
        s.name: {
            "model": str(s.model),
            "body_mass_kg": s.body_mass_kg,
            "height_m": s.height_m,
            "passive": str(s.passive) if s.passive else None,
            "tendon_stiffness": s.tendon_stiffness if not isinstance(s.tendon_stiffness, Path) else str(s.tendon_stiffness),
            "emg_mapping": s.emg_mapping,
            "trials": [t.name for t in s.trials],
        }
        for s in study.subjects
    }
    info["software"] = software_versions()
    atomic_write_text(out / STUDY_JSON, json.dumps(info, indent=2, default=str) + "\n")


def collect_results(study: Study, failed: dict[str, str] | None = None):
    """Gather the complete trial units of ``study`` into the results table (and write it)."""
    import pandas as pd

    from ..analysis.per_muscle import PER_MUSCLE_FILE

    out = Path(study.output)
    frames, failures, muscles = [], [], []
    for unit in plan_units(study)[1]:
        folder = out / unit.folder
        rec = read_unit_record(folder)
        if not rec or rec.get("status") != "ok":
            reason = (failed or {}).get(unit.label) or (rec or {}).get("error") or "not run"
            failures.append({"subject": unit.subject, "trial": unit.trial, "workflow": unit.workflow, "reason": reason})
            continue
        wb = pd.read_csv(folder / "whole_body.csv")
        an = pd.read_csv(folder / "analysis.csv")
        df = wb.merge(an, on="model", how="left", validate="one_to_one")
        df.insert(0, "subject", unit.subject)
        df.insert(1, "trial", unit.trial)
        df.insert(2, "workflow", unit.workflow)
        df["speed_m_per_s"] = rec.get("speed_m_per_s")
        df["toe_off_pct"] = rec.get("toe_off_pct")
        df["measured_W_per_kg"] = rec.get("measured_W_per_kg")
        df["cycle_source"] = rec.get("cycle_source")
        df["speed_source"] = rec.get("speed_source")
        df["status"] = "ok"
        df["unit_dir"] = str(unit.folder)
        frames.append(df)
        if (folder / PER_MUSCLE_FILE).is_file():
            pm = pd.read_csv(folder / PER_MUSCLE_FILE)
            for k, (col, val) in enumerate((("subject", unit.subject), ("trial", unit.trial),
                                            ("workflow", unit.workflow))):
                pm.insert(k, col, val)
            muscles.append(pm)
    for unit in plan_units(study)[0]:
        rec = read_unit_record(out / unit.folder)
        if not rec or rec.get("status") != "ok":
            reason = (failed or {}).get(unit.label) or (rec or {}).get("error") or "not run"
            failures.append({"subject": unit.subject, "trial": "", "workflow": unit.workflow, "reason": reason})
    table = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=list(ID_COLUMNS))
    if "measured_W_per_kg" in table:
        table["measured_W_per_kg"] = pd.to_numeric(table["measured_W_per_kg"], errors="coerce")
    table = table.sort_values(list(ID_COLUMNS), kind="stable", ignore_index=True)
    with atomic_path(out / RESULTS_CSV) as tmp:
        table.to_csv(tmp, index=False, float_format="%.10g")
    try:
        with atomic_path(out / RESULTS_PARQUET) as tmp:
            table.to_parquet(tmp, index=False)
    except ImportError:  # pragma: no cover - pyarrow missing
        pass
    per_muscle = pd.concat(muscles, ignore_index=True) if muscles else pd.DataFrame(columns=list(ID_COLUMNS))
    per_muscle = per_muscle.sort_values(list(ID_COLUMNS) + (["rank"] if "rank" in per_muscle else []),
                                        kind="stable", ignore_index=True)
    with atomic_path(out / PER_MUSCLE_FILE) as tmp:
        per_muscle.to_csv(tmp, index=False, float_format="%.10g")
    with atomic_path(out / PER_MUSCLE_PARQUET) as tmp:
        per_muscle.to_parquet(tmp, index=False)
    from ..analysis.groups import write_group_key
    from ..datadict import write_data_dictionary

    write_group_key(out / GROUP_KEY_CSV)
    write_data_dictionary(out / DATA_DICTIONARY_CSV)
    fail = pd.DataFrame(failures, columns=["subject", "trial", "workflow", "reason"])
    with atomic_path(out / FAILURES_CSV) as tmp:
        fail.to_csv(tmp, index=False)
    return table
