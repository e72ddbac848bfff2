"""Run a study: every unit, in parallel processes or on a Dask cluster, resumable.

:func:`run_study` plans the units (:mod:`musclemetab.study.units`), skips those that are
complete with an unchanged key, runs the others — EMG-TEN estimations first, then the
trial units — and gathers every complete unit into one results table:

``DIR/results.csv`` (and ``DIR/results.parquet`` with the ``parquet`` extra)
    one row per subject × trial × workflow × model: whole-body rate (W/kg, with and
    without basal heat), cost of transport, stance and swing shares, muscle-group shares,
    toe-off (% of the cycle), speed and measured rate when the study gives calorimetry, and
    ``large_reserve`` (the solve's reserves exceed 1 % of the peak joint moment, see
    :data:`musclemetab.redundancy.solution.LARGE_RESERVE_SHARE`) and ``quality`` (``ok`` or
    the plausibility flags of the unit and the row, :func:`~musclemetab.metabolics.plausibility.add_quality`; ``docs/quality.md``).
``DIR/per_muscle.csv`` (and ``DIR/per_muscle.parquet`` with the ``parquet`` extra)
    one row per subject × trial × workflow × model × muscle (with its side): the
    per-muscle table of every unit (:mod:`musclemetab.metabolics.per_muscle`).
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
worker; the BLAS/OpenMP thread pools of each process are limited to its share of the cores,
``cpu_count // N``, through ``OMP_NUM_THREADS`` and its siblings unless the caller set them); ``scheduler="tcp://host:port"`` on a Dask cluster (``pip install
musclemetab[dask]``; the workers need musclemetab installed and the study's files at the
same paths). A unit failure is recorded and the other units go on. The warnings of a unit run
by a worker are raised in this process when the unit ends
(:func:`~musclemetab.processes.call_recording_warnings`), above the progress bar: the command
line says each once per run, however many workers met it, and a notebook shows them.

Safety: the options (``workers``, ``scheduler``) and the output folder are checked, and the
cluster connected, before anything is written. While a run works on a study folder it holds
the lock file ``DIR/.musclemetab.lock`` (process id, host, boot id, start time); a second run on the
same folder refuses with a message naming the lock. A lock left by a process that no longer
runs (on this host, since its boot) is stale and taken over atomically (one of many runs starting
at once takes it). Temporary unit folders a killed run left are
removed at the next run. Ctrl-C stops the run: the running units are recorded as
``interrupted`` (their folders stay as they were), no new unit starts, and the results table
is written from the complete units.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from concurrent.futures import as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

from ..errors import OptionError
from ..metabolics.plausibility import add_quality
from ..messages import write_quietly
from ..io.atomic import FolderLock, _boot_id, _process_alive  # noqa: F401  (public here before)
from ..io.atomic import atomic_directory, atomic_path, atomic_write_text, check_output_folder, check_replaceable
from ..processes import THREAD_VARIABLES  # noqa: F401  (public here before)
from ..processes import call_recording_warnings, spawn_pool, warn_again
from ..processes import pin_threads as _pin_threads  # noqa: F401
from .spec import Study
from .units import (
    INTERRUPTED,
    WARM_CHAIN,
    Unit,
    check_assistance,
    execute_unit,
    is_complete,
    plan_units,
    prepare_leg_folder,
    read_unit_record,
    remove_stale_partials,
    unit_folder,
    unit_key,
)

__all__ = ["run_study", "StudyRun", "collect_results", "add_quality", "trial_result_rows", "add_leg_rows", "leg_basal_energy_J", "software_versions", "study_lock", "check_scheduler_address",
           "RESULTS_CSV", "RESULTS_PARQUET", "LOCK_FILE"]

from ..study_layout import (  # noqa: E402,F401  (the names of the study folder's files, defined once)
    DATA_DICTIONARY_CSV,
    FAILURES_CSV,
    GROUP_KEY_CSV,
    LOCK_FILE,
    PER_MUSCLE_PARQUET,
    RESULTS_CSV,
    RESULTS_PARQUET,
    STUDY_JSON,
    software_versions,
)
#: Seconds to wait for a Dask scheduler that has a valid address.
SCHEDULER_TIMEOUT_S = 5

#: columns of the results table that identify a row
ID_COLUMNS = ("subject", "trial", "workflow", "model")
_LEG_NAMES = {"r": "right", "l": "left"}


@dataclass
class StudyRun:
    """What a run did: the units run, skipped and failed, and the results table."""

    output: Path
    ran: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    blocked: list[str] = field(default_factory=list)
    interrupted: list[str] = field(default_factory=list)
    n_planned: int = 0
    wall_time_s: float = 0.0
    results: object = None  # pandas.DataFrame
    report: Path | None = None
    removed_partials: list[Path] = field(default_factory=list)

    @property
    def n_units(self) -> int:
        return self.n_planned or len(self.ran) + len(self.skipped) + len(self.blocked)

    def summary_line(self) -> str:
        """``N units: a run, b up to date, c not run (...), d interrupted; e failed; ...``.

        Every planned unit is counted once among run, up to date, not run because a unit it
        needs failed, and not started (after an interruption); ``failed`` counts the run
        units that failed plus the units not run because of a failure.
        """
        parts = [f"{len(self.ran)} run", f"{len(self.skipped)} up to date"]
        if self.blocked:
            parts.append(f"{len(self.blocked)} not run (a unit they need failed)")
        not_started = self.n_units - len(self.ran) - len(self.skipped) - len(self.blocked)
        if self.interrupted or not_started:
            parts.append(f"{not_started} not started")
        failed = len([u for u in self.failed if u not in self.interrupted])
        tail = f"; {failed} failed"
        if self.interrupted:
            tail += f", {len(self.interrupted)} interrupted"
        return (f"{self.n_units} unit{'s' if self.n_units != 1 else ''}: {', '.join(parts)}{tail}; "
                f"{0 if self.results is None else len(self.results)} result rows "
                f"in {self.wall_time_s:.1f} s -> {self.output}")


# ---------------------------------------------------------------------------------------
class _Progress:
    """A one-line progress bar on a terminal; one line per unit otherwise.

    Each line counts the units done, failed and interrupted, the time so far and, once a unit
    has run, the time left: the units not done times the mean measured time of the units run so
    far (their ``times.total_s``; units found up to date do not count), divided by the units
    that run at once (``parallel``). A unit stopped by Ctrl-C is shown ``interrupted``, not failed.
    """

    def __init__(self, total: int, enabled: bool, stream=None, parallel: int = 1):
        self.total, self.done, self.failed, self.interrupted = total, 0, 0, 0
        self.enabled = enabled and total > 0
        self.stream = stream or sys.stderr
        try:
            self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        except ValueError:  # a closed stream: its lines are lost (write_quietly)
            self.tty = False
        self.t0 = time.perf_counter()
        self.parallel = max(1, int(parallel or 1))
        self.costs: list[float] = []  # measured seconds of the units run

    def eta_s(self) -> float | None:
        """Seconds left (estimate), or ``None`` before any unit has run."""
        if not self.costs:
            return None
        left = self.total - self.done
        if left <= 0:
            return 0.0
        return sum(self.costs) / len(self.costs) * left / min(self.parallel, left)

    def clear_line(self) -> None:
        """Blank the bar on a terminal (before other lines, e.g. a unit's warnings; the next
        :meth:`update` draws it again below them)."""
        if self.enabled and self.tty and self.done:
            write_quietly(self.stream, "\r" + " " * 160 + "\r")

    def update(self, label: str, record: dict, ran: bool = False) -> None:
        status = record.get("status")
        self.done += 1
        self.failed += status not in ("ok", INTERRUPTED)
        self.interrupted += status == INTERRUPTED
        cost = (record.get("times") or {}).get("total_s")
        if ran and status == "ok" and isinstance(cost, (int, float)):
            self.costs.append(float(cost))
        if not self.enabled:
            return
        width = 24
        filled = int(width * self.done / self.total)
        bar = "#" * filled + "." * (width - filled)
        state = "ok" if status == "ok" else INTERRUPTED if status == INTERRUPTED else "FAILED"
        eta = self.eta_s()
        left = f", about {_duration(eta)} left" if eta is not None and self.done < self.total else ""
        stopped = f", {self.interrupted} interrupted" if self.interrupted else ""
        line = (f"[{bar}] {self.done}/{self.total} units, {self.failed} failed{stopped}, "
                f"{time.perf_counter() - self.t0:.0f} s{left} | {label} {state}")
        text = "\r" + line[:160].ljust(160) + ("\n" if self.done == self.total else "") if self.tty else line + "\n"
        write_quietly(self.stream, text)  # a closed or full stream loses the line, not the study


def _duration(seconds: float) -> str:
    """``45 s``, ``3 min``, ``1 h 05 min``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    minutes = int(round(seconds / 60))
    return f"{minutes} min" if minutes < 60 else f"{minutes // 60} h {minutes % 60:02d} min"


def check_scheduler_address(address: str) -> str:
    """Check a Dask scheduler address without connecting; :class:`OptionError` if unusable.

    Accepted: ``tcp://host:port``, and ``tls://host:port`` when the Dask configuration
    holds the TLS settings (``distributed.comm.tls.ca-file`` and the client's certificate).
    """
    hint = "give the scheduler's address as tcp://host:port (Dask's default port is 8786)"
    if not isinstance(address, str) or "://" not in address:
        raise OptionError(f"--scheduler {address!r} is not an address; {hint}")
    scheme, _, rest = address.partition("://")
    scheme = scheme.lower()
    if scheme in ("http", "https"):
        raise OptionError(f"--scheduler {address}: {scheme}:// is the dashboard's web address, not the scheduler's; "
                          f"{hint}")
    if scheme not in ("tcp", "tls"):
        raise OptionError(f"--scheduler {address}: unknown protocol {scheme}://; {hint}")
    host, sep, port = rest.rstrip("/").rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536 or "/" in host:
        raise OptionError(f"--scheduler {address}: no host and port number; {hint}")
    if scheme == "tls":
        try:
            import dask.config
        except ImportError:
            raise OptionError("--scheduler needs Dask's distributed scheduler: pip install 'musclemetab[dask]'") from None
        tls = dask.config.get("distributed.comm.tls", {}) or {}
        client = tls.get("client") or {}
        if not tls.get("ca-file") or not client.get("cert"):
            raise OptionError(
                f"--scheduler {address}: tls:// needs Dask's TLS settings (distributed.comm.tls.ca-file and "
                "distributed.comm.tls.client.cert/key in the Dask configuration); set them, or use tcp://"
            )
    return address


class _Executor:
    """``submit``/``completed`` for the chosen executor, with ``interrupt`` and ``close``."""

    def __init__(self, workers: int, scheduler: str | None):
        self.submit = self.completed = None
        self.capacity = None  # units run at once (None: no limit)
        self._pool = self._client = None
        self._restore_env = None
        if scheduler:
            try:
                from distributed import Client
                from distributed import as_completed as dask_completed
            except ImportError:
                raise OptionError(
                    "--scheduler needs Dask's distributed scheduler: pip install 'musclemetab[dask]'"
                ) from None
            try:
                self._client = Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT_S}s")
            except (OSError, TimeoutError, ValueError, TypeError) as exc:
                raise OptionError(f"cannot connect to the Dask scheduler at {scheduler} ({exc}); "
                                  "check the address (tcp://host:port) and that the scheduler runs") from None
            client = self._client
            self.submit = lambda fn, *args: client.submit(fn, *args, pure=False)
            self.completed = dask_completed
        elif workers > 1:
            self._pool, self._restore_env = spawn_pool(workers)
            self.capacity = workers
            self.submit, self.completed = self._pool.submit, as_completed

    def interrupt(self, futures) -> None:
        """Ctrl-C: cancel what has not started and interrupt the units running."""
        for fut in futures:
            fut.cancel()
        if self._client is not None:
            self._client.cancel(list(futures))
        if self._pool is not None:
            for proc in list((getattr(self._pool, "_processes", None) or {}).values()):
                try:
                    os.kill(proc.pid, signal.SIGINT)
                except OSError:
                    pass

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
        if self._pool is not None:
            try:
                self._pool.shutdown(wait=True, cancel_futures=True)
            finally:
                self._restore_env()




def unit_batches(study: Study) -> list[list[Unit]]:
    """The units in the order they are submitted: every unit that needs no EMG-TEN estimate
    (all subjects, trials, sides and workflows together) with the estimations, longest
    first; then the units that use an estimate, once the estimations are done (with warm
    starts, the effort workflows are ordered as their chain, :data:`~.units.WARM_CHAIN`, so
    that a unit comes after the unit whose solution it starts from); then the uncertainty
    samples of the trial units (:mod:`.uncertainty`)."""
    stage1, stage2 = plan_units(study)
    if study.warm_start or study.best_start:
        stage2.sort(key=lambda u: WARM_CHAIN.index(u.workflow) if u.workflow in WARM_CHAIN else -1)  # stable
    independent = [u for u in stage2 if u.depends_on(study) is None]
    dependent = [u for u in stage2 if u.depends_on(study) is not None]
    from .uncertainty import sample_units  # the uncertainty samples, once their trial units are done

    return [b for b in (stage1 + independent, dependent, sample_units(study)) if b]


def _next_ready(queue: list, waiting: set) -> int | None:
    """The index of the first job of ``queue`` whose warm-start source is not in ``waiting``
    (the units of this batch not finished yet), or ``None``."""
    for i, job in enumerate(queue):
        if job[4] is None or job[4] not in waiting:
            return i
    return None


def _say_warnings(caught, progress: _Progress) -> None:
    """A unit's warnings (:func:`~musclemetab.processes.call_recording_warnings`), raised in this
    process when the unit ends, above the progress bar."""
    if caught:
        progress.clear_line()
        warn_again(caught, stacklevel=2)


def _run_units(study: Study, jobs: list[tuple[Unit, str, str | None, str | None, Unit | None]],
               executor: _Executor, progress: _Progress) -> tuple[dict, bool]:
    """Run ``(unit, key, dependency folder, warm-start folder, warm-start unit)`` jobs; a job starts
    once its warm-start unit (when it is one of ``jobs``) has finished. Returns
    ``({unit: record}, interrupted)``."""
    records = {}
    if executor.submit is None:
        try:
            for unit, key, dep, warm, _ in jobs:  # a warm-start unit comes before the units it starts
                # its warnings said as they come (recording them here would change the warnings state of
                # the whole process while the demo draws in another thread; the log says each once)
                rec = execute_unit(study, unit, key, dep, warm)
                records[unit] = rec
                progress.update(unit.label, rec, ran=True)
                if rec.get("status") == INTERRUPTED:
                    return records, True
        except KeyboardInterrupt:  # between two units
            return records, True
        return records, False
    # no more units submitted than the executor runs at once (a process pool queues what it is
    # given and would start it even after Ctrl-C); a Dask cluster takes them all
    queue = list(jobs)
    limit = executor.capacity or len(queue)
    futures: dict = {}
    pending: list = []
    waiting = {job[0] for job in jobs}  # the units of this batch not finished
    interrupted = False
    while pending or (queue and not interrupted):
        try:
            while queue and not interrupted and len(pending) < limit:
                i = _next_ready(queue, waiting)
                if i is None:
                    if pending:
                        break  # every job left waits for a running unit's solution
                    i = 0  # cannot happen (a warm-start source is planned before its units): run in order
                unit, key, dep, warm, _ = queue.pop(i)
                fut = executor.submit(call_recording_warnings, execute_unit, study, unit, key, dep, warm)
                futures[fut] = unit
                pending.append(fut)
            fut = next(iter(executor.completed(pending)))
            pending.remove(fut)
            unit = futures[fut]
            waiting.discard(unit)
            try:
                rec, caught = fut.result()
            except BaseException as exc:  # the worker process died, the cluster lost the task, or cancelled
                if interrupted:
                    continue
                rec = {"status": "failed", "error": f"{type(exc).__name__}: {exc} (worker lost)"}
            else:  # the unit's warnings said here, each once per run (not once per worker)
                _say_warnings(caught, progress)
            records[unit] = rec
            interrupted = interrupted or rec.get("status") == INTERRUPTED
            progress.update(unit.label, rec, ran=True)
        except KeyboardInterrupt:
            if interrupted:  # a second Ctrl-C: stop waiting
                break
            interrupted = True
            executor.interrupt(pending)
            pending = [f for f in pending if not f.cancelled()]
    for fut, unit in futures.items():  # running when interrupted and not returned
        if unit not in records and interrupted and not fut.cancelled():
            records[unit] = {"status": INTERRUPTED, "error": "interrupted (Ctrl-C) before it finished"}
    return records, interrupted


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
    stages = unit_batches(study)
    n_total = sum(len(s) for s in stages)
    # Everything that can be checked is checked before anything is written.
    if scheduler is not None:
        check_scheduler_address(scheduler)
    if workers is None:
        workers = min(os.cpu_count() or 1, n_total) if not scheduler else 0
    if not scheduler and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise OptionError(f"--workers must be a whole number of at least 1, not {workers}")
    for stage in stages:
        for unit in stage:
            unit_folder(out, unit)
    from .samples import check_priors_muscles

    check_priors_muscles(study)
    check_assistance(study)  # the device profiles against the subjects' models (the scaled ones once scaled)
    check_output_folder(out, "the study's output folder")
    check_replaceable(out, study_root_files())  # a file of the user there is refused before any unit runs
    run = StudyRun(output=out, n_planned=n_total)
    keys: dict[Unit, str] = {}
    executor = _Executor(workers, scheduler)
    try:
        with study_lock(out):
            run.removed_partials = remove_stale_partials(out)
            from .lab import prepare_study

            study = prepare_study(study)  # models scaled and IK computed from markers, into prepared/
            check_assistance(study, prepared=True)
            for stage in stages:
                for unit in stage:
                    prepare_leg_folder(out, unit)
            _write_study_json(study, out)
            bar = _Progress(n_total, progress, stream, parallel=workers if not scheduler else 1)
            for stage in stages:
                jobs = []
                for unit in stage:
                    dep = unit.depends_on(study)
                    dep_key = keys.get(dep) if dep is not None else None
                    warm = unit.warm_source(study)
                    keys[unit] = key = unit_key(study, unit, dep_key, keys.get(warm) if warm is not None else None)
                    if dep is not None and dep.label in run.failed:
                        rec = {"status": "failed", "error": f"needs {dep.label}, which failed"}
                        run.failed[unit.label] = rec["error"]
                        run.blocked.append(unit.label)
                        bar.update(unit.label, rec)
                        continue
                    if not force and is_complete(out / unit.folder, key):
                        run.skipped.append(unit.label)
                        bar.update(unit.label, {"status": "ok"})
                        continue
                    jobs.append((unit, key, str(out / dep.folder) if dep is not None else None,
                                 str(out / warm.folder) if warm is not None else None, warm))
                records, stopped = _run_units(study, jobs, executor, bar)
                for unit, rec in records.items():
                    run.ran.append(unit.label)
                    if rec.get("status") == INTERRUPTED:
                        run.interrupted.append(unit.label)
                    if rec.get("status") != "ok":
                        run.failed[unit.label] = rec.get("error") or "unknown error"
                if stopped:
                    if not run.interrupted:
                        run.interrupted.append("(between units)")
                    break
            run.results = collect_results(study, failed=run.failed, interrupted=run.interrupted)
    finally:
        executor.close()
    run.wall_time_s = time.perf_counter() - t0
    return run


study_lock = FolderLock  # the study folder's lock (the name it had before ``FolderLock``)


def _write_study_json(study: Study, out: Path) -> None:
    from ..emg import processing_record

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
            "side": s.side,
            **({"emg_mode": s.emg_mode, "emg_tolerance": s.emg_tolerance} if s.emg_mode else {}),
            **({"estimate": s.estimate.to_dict()} if s.estimate is not None else {}),
            "trials": [t.name for t in s.trials],
            "emg_files": {t.name: str(t.emg) if t.emg else None for t in s.trials},
            "emg_processing": {t.name: processing_record(t.emg) for t in s.trials if t.emg},
            **({"generic_model": str(s.generic_model), "static": str(s.static)} if s.generic_model else {}),
            **({"markers": {t.name: str(t.markers) for t in s.trials if t.markers}}
               if any(t.markers for t in s.trials) else {}),
        }
        for s in study.subjects
    }
    info["software"] = software_versions()
    atomic_write_text(out / STUDY_JSON, json.dumps(info, indent=2, default=str) + "\n", mark=True)


def study_root_files() -> list[str]:
    """The files the runner writes at the study's output root (:func:`_write_study_json`,
    :func:`collect_results`): each is listed in the root's
    :data:`~musclemetab.io.atomic.FILES_MANIFEST` and replaces only a file the list holds
    unchanged (:func:`musclemetab.io.atomic.check_replaceable`)."""
    from ..metabolics.per_muscle import PER_MUSCLE_FILE

    from ..analysis.assistance import ASSISTANCE_CSV

    return [STUDY_JSON, RESULTS_CSV, RESULTS_PARQUET, PER_MUSCLE_FILE, PER_MUSCLE_PARQUET, GROUP_KEY_CSV,
            DATA_DICTIONARY_CSV, FAILURES_CSV, ASSISTANCE_CSV]


def _unit_rows(folder: Path, unit: Unit, rec: dict):
    """One unit's rows of the results table (a row per model), as the unit wrote them."""
    import pandas as pd

    df = trial_result_rows(
        pd.read_csv(folder / "whole_body.csv"), pd.read_csv(folder / "analysis.csv"),
        speed_m_per_s=rec.get("speed_m_per_s"), toe_off_pct=rec.get("toe_off_pct"),
        measured_W_per_kg=rec.get("measured_W_per_kg"), cycle_source=rec.get("cycle_source"),
        speed_source=rec.get("speed_source"), large_reserve=bool(rec.get("large_reserve", False)),
        unit_dir=str(unit.folder), excluded_muscles=rec.get("excluded_muscles"),
        named_by_events=(rec.get("window") or {}).get("named_by_events", True))  # False: a trial's window alone
    df["solve_start"] = rec.get("start") or "cold"  # a record without it: a unit of an earlier version, cold
    spread = (rec.get("starts") or {}).get("other_whole_body_difference")
    if spread:  # solved from both starts ([solver] best_start): how far the other start's rates are
        df["other_start_rate_difference"] = df["model"].map(spread)
    if rec.get("assistance"):  # an assisted trial: its device (musclemetab.analysis.assistance)
        from ..analysis.assistance import device_columns

        for column, value in device_columns(rec["assistance"]).items():
            df[column] = value
    df.insert(0, "subject", unit.subject)
    df.insert(1, "trial", unit.trial)
    df.insert(2, "workflow", unit.workflow)
    return df


def trial_result_rows(whole_body, analysis, *, speed_m_per_s=None, toe_off_pct=None, measured_W_per_kg=None,
                      cycle_source=None, speed_source=None, large_reserve=False, unit_dir=".", excluded_muscles=None,
                      named_by_events=True):
    """The results rows of one leg of a trial (one per model) from its whole-body table and its
    analysis (``whole_body.csv`` and ``analysis.csv`` of a unit, or the tables of
    :func:`musclemetab.analysis.analyse`), with the trial's speed, toe-off, measured rate,
    sources, reserve flag, status ``ok`` and folder (``musclemetab analyse`` writes them too).

    ``excluded_muscles``: the muscles the solve left out (column ``excluded_muscles``, their names
    separated by spaces, empty (NaN) when none). ``named_by_events``: whether gait events bound the
    span the rates are averaged over (``False`` for a solve over an explicit ``--window`` analysed
    without a cycle of its own); with the span's duration (``duration_s``) inside walking's
    0.8-2.0 s it gives the column ``gait_cycle`` (:func:`is_gait_cycle`). Both columns raise a
    plausibility flag in the ``quality`` column (``docs/quality.md``)."""
    from ..metabolics.plausibility import is_gait_cycle

    df = whole_body.merge(analysis, on="model", how="left", validate="one_to_one")
    df["speed_m_per_s"] = speed_m_per_s
    df["toe_off_pct"] = toe_off_pct
    df["measured_W_per_kg"] = measured_W_per_kg
    df["cycle_source"] = cycle_source
    df["speed_source"] = speed_source
    df["large_reserve"] = bool(large_reserve)
    df["excluded_muscles"] = " ".join(excluded_muscles or ()) or float("nan")  # empty, as the CSV reads back
    df["gait_cycle"] = [is_gait_cycle(d, named_by_events) for d in df["duration_s"]] if "duration_s" in df else \
        bool(named_by_events)
    df["status"] = "ok"
    df["unit_dir"] = unit_dir
    return df


#: results columns averaged over the legs (each leg doubled, then averaged: the legs added)
_LEG_MEAN_COLUMNS = ("whole_body_W_per_kg", "whole_body_no_basal_W_per_kg", "leg_muscles_W", "duration_s", "leg_energy_J",
                     "toe_off_pct", "speed_m_per_s")
#: per-leg events: no single value for both legs (each leg's are in its unit folder)
_LEG_EVENT_COLUMNS = ("cycle_start_s", "toe_off_s", "cycle_end_s")


def add_leg_rows(rows: Mapping[str, object], basal_energy_J: Mapping[str, object] | None = None):
    """The results rows of a ``side = "both"`` subject's trial and workflow: the two legs added.

    ``rows`` maps each side to its unit's rows (:func:`_unit_rows`; each leg's whole-body
    rate is that leg doubled, over its own gait cycle); ``basal_energy_J`` each side's
    per-muscle basal heat over its cycle (J, a number or a Series by model). Per model, the
    combined row holds:

    * the rates (``whole_body_W_per_kg``, ``whole_body_no_basal_W_per_kg``) as the mean of the two legs'
      doubled rates, which is the sum of the legs' cycle-average rates per kg plus the basal
      heat once: ``(2 L_r/m + B + 2 L_l/m + B) / 2 = (L_r + L_l)/m + B``;
      ``leg_muscles_W``, ``leg_energy_J``, ``duration_s``, ``toe_off_pct`` and the speed: the
      legs' means;
    * the costs of transport: the combined rates over the mean speed;
    * the energy shares (stance, swing, muscle groups) of both legs' muscle energy:
      each leg's share weighted by its ``leg_energy_J`` (the ``..._with_basal`` shares by
      its energy with the per-muscle basal heat, ``leg_energy_J + basal_energy_J[side]``);
    * the cycle's event times empty (each leg's are in its unit folder), ``large_reserve``
      when either leg's is, the sources of both legs, ``legs = "r + l"`` and ``unit_dir`` the
      folder holding the two legs' unit folders.
    """
    import numpy as np
    import pandas as pd

    sides = list(rows)
    frames = [rows[s].set_index("model") for s in sides]
    first = frames[0]
    out = first.copy()
    numeric = [c for c in first.columns if pd.api.types.is_numeric_dtype(first[c])
               and c not in ("large_reserve", "gait_cycle")]
    energy = [f["leg_energy_J"].astype(float) for f in frames] if "leg_energy_J" in first else None
    basal = [(basal_energy_J or {}).get(s, 0.0) for s in sides]
    for c in numeric:
        values = [f[c].astype(float) for f in frames]
        if c in _LEG_MEAN_COLUMNS:
            out[c] = sum(values) / len(values)
        elif c in _LEG_EVENT_COLUMNS:
            out[c] = np.nan
        elif c.endswith("_pct") and energy is not None:
            weights = energy
            if c.endswith("_with_basal_pct"):
                weights = [e.add(b, fill_value=0.0) if isinstance(b, pd.Series) else e + b
                           for e, b in zip(energy, basal)]
            out[c] = sum(v * w for v, w in zip(values, weights)) / sum(weights)
        elif c in ("gross_cost_of_transport_J_per_kg_per_m", "net_cost_of_transport_J_per_kg_per_m"):
            continue  # below, from the combined rates
        elif c == "measured_W_per_kg":
            continue  # the trial's, the same for both legs
        else:
            out[c] = sum(values) / len(values)
    speed = out.get("speed_m_per_s")
    if speed is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            if "gross_cost_of_transport_J_per_kg_per_m" in out:
                out["gross_cost_of_transport_J_per_kg_per_m"] = out["whole_body_W_per_kg"] / speed.astype(float)
            if "net_cost_of_transport_J_per_kg_per_m" in out:
                out["net_cost_of_transport_J_per_kg_per_m"] = out["whole_body_no_basal_W_per_kg"] / speed.astype(float)
    out["large_reserve"] = np.logical_or.reduce([f["large_reserve"].astype(bool) for f in frames])
    if "gait_cycle" in first:  # each leg over a gait cycle of its own
        out["gait_cycle"] = np.logical_and.reduce([f["gait_cycle"].astype(bool) for f in frames])
    if "excluded_muscles" in first:
        names = [n for f in frames for n in str(f["excluded_muscles"].astype(object).fillna("").iloc[0]).split()]
        out["excluded_muscles"] = " ".join(dict.fromkeys(names)) or float("nan")
    for c in ("cycle_source", "speed_source", "solve_start"):
        if c in out:
            texts = [str(f[c].iloc[0]) for f in frames]
            out[c] = texts[0] if len(set(texts)) == 1 else "; ".join(f"{s}: {t}" for s, t in zip(sides, texts))
    out["legs"] = " + ".join(sides)
    out["unit_dir"] = str(Path(str(first["unit_dir"].iloc[0])).parent)
    return out.reset_index()


def leg_basal_energy_J(per_muscle, duration_s):
    """A leg's per-muscle basal heat over its cycle (J) by model, from its per-muscle table
    (the ``basal_energy_J`` of :func:`add_leg_rows`)."""
    if per_muscle is None or "basal_heat_mean_W" not in per_muscle:
        return 0.0
    return per_muscle.groupby("model")["basal_heat_mean_W"].sum() * float(duration_s)


def collect_results(study: Study, failed: dict[str, str] | None = None, interrupted=()):
    """Gather the complete trial units of ``study`` into the results table (and write it).

    One row per subject, trial, workflow and model; a ``side = "both"`` subject's two legs
    give one row with the legs added (:func:`add_leg_rows`), the column ``legs`` says which
    (``"2 x r"``: the right leg doubled; ``"r + l"``: both legs added). The units without a
    result go to ``failures.csv`` with their ``status``: ``interrupted`` for those stopped by
    Ctrl-C (labels ``interrupted``) and, when the run was interrupted, those it did not reach;
    ``failed`` for the others.
    """
    import pandas as pd

    from ..metabolics.per_muscle import PER_MUSCLE_FILE

    out = Path(study.output)
    frames, failures, muscles = [], [], []
    interrupted = set(interrupted)

    def status(unit, reason) -> str:
        stopped = unit.label in interrupted or (bool(interrupted) and reason == "not run")
        return INTERRUPTED if stopped else "failed"

    legs: dict[tuple, dict] = {}
    records: dict[tuple, list] = {}  # the unit records of each results row (one per leg)
    for unit in plan_units(study)[1]:
        folder = out / unit.folder
        rec = read_unit_record(folder)
        group = legs.setdefault((unit.subject, unit.trial, unit.workflow), {})
        if not rec or rec.get("status") != "ok":
            reason = (failed or {}).get(unit.label) or (rec or {}).get("error") or "not run"
            if unit.side:
                reason = f"{_LEG_NAMES[unit.side]} leg: {reason}"
            failures.append({"subject": unit.subject, "trial": unit.trial, "workflow": unit.workflow,
                             "status": status(unit, reason), "reason": reason})
            group[unit.side] = None
            continue
        records.setdefault((unit.subject, unit.trial, unit.workflow), []).append(rec)
        df = _unit_rows(folder, unit, rec)
        pm = pd.read_csv(folder / PER_MUSCLE_FILE) if (folder / PER_MUSCLE_FILE).is_file() else None
        group[unit.side] = (df, pm)
        if pm is not None:
            for k, (col, val) in enumerate((("subject", unit.subject), ("trial", unit.trial),
                                            ("workflow", unit.workflow))):
                pm.insert(k, col, val)
            muscles.append(pm)
    for (subject, trial, workflow), group in legs.items():
        if any(v is None for v in group.values()):
            continue  # a leg failed: its failure is listed; no whole-body row
        if None in group:  # one side, doubled
            df = group[None][0]
            df["legs"] = f"2 x {study.subject(subject).side}"
            frames.append(add_quality(df, records[(subject, trial, workflow)]))
            continue
        rows = {side: df for side, (df, _) in group.items()}
        basal = {side: leg_basal_energy_J(pm, df["duration_s"].iloc[0]) for side, (df, pm) in group.items()}
        frames.append(add_quality(add_leg_rows(rows, basal), records[(subject, trial, workflow)]))
    for unit in plan_units(study)[0]:
        rec = read_unit_record(out / unit.folder)
        if not rec or rec.get("status") != "ok":
            reason = (failed or {}).get(unit.label) or (rec or {}).get("error") or "not run"
            failures.append({"subject": unit.subject, "trial": "", "workflow": unit.workflow,
                             "status": status(unit, reason), "reason": reason})
    table = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=list(ID_COLUMNS))
    if "measured_W_per_kg" in table:
        table["measured_W_per_kg"] = pd.to_numeric(table["measured_W_per_kg"], errors="coerce")
    table = table.sort_values(list(ID_COLUMNS), kind="stable", ignore_index=True)
    from ..analysis.assistance import ASSISTANCE_CSV, add_assistance_changes, assistance_breakdown

    table = add_assistance_changes(table)  # assisted trials against their unassisted trial
    from .uncertainty import add_study_bands  # the uncertainty bands, when the study has samples

    builders = (trial_result_rows, add_leg_rows, leg_basal_energy_J)
    table = add_study_bands(study, table, "results", builders)
    per_muscle = pd.concat(muscles, ignore_index=True) if muscles else pd.DataFrame(columns=list(ID_COLUMNS))
    per_muscle = per_muscle.sort_values(list(ID_COLUMNS) + [c for c in ("side", "rank") if c in per_muscle],
                                        kind="stable", ignore_index=True)
    per_muscle = add_study_bands(study, per_muscle, "per_muscle", builders)
    from ..analysis.groups import write_group_key
    from ..datadict import write_data_dictionary
    from ..io.parquet import parquet_available

    fail = pd.DataFrame(failures, columns=["subject", "trial", "workflow", "status", "reason"])
    parquet = parquet_available()
    assisted = "assisted_from" in table and bool(table["assisted_from"].notna().any())
    if not parquet:  # an earlier run's copies would disagree with the CSV files: removed (if the package's)
        check_replaceable(out, [RESULTS_PARQUET, PER_MUSCLE_PARQUET])
    if not assisted:  # an earlier run's breakdown would not be of this study: removed (if the package's)
        check_replaceable(out, [ASSISTANCE_CSV])
    with atomic_directory(out, mark=True) as tmp:  # the root's files, listed in its FILES_MANIFEST
        table.to_csv(tmp / RESULTS_CSV, index=False, float_format="%.10g")
        per_muscle.to_csv(tmp / PER_MUSCLE_FILE, index=False, float_format="%.10g")
        _write_parquet_copy(table, tmp / RESULTS_PARQUET)
        _write_parquet_copy(per_muscle, tmp / PER_MUSCLE_PARQUET)
        write_group_key(tmp / GROUP_KEY_CSV)
        write_data_dictionary(tmp / DATA_DICTIONARY_CSV)
        fail.to_csv(tmp / FAILURES_CSV, index=False)
        if assisted:
            assistance_breakdown(table, per_muscle).to_csv(tmp / ASSISTANCE_CSV, index=False, float_format="%.10g")
    if not parquet:  # checked above: the package's own copies
        for name in (RESULTS_PARQUET, PER_MUSCLE_PARQUET):
            (out / name).unlink(missing_ok=True)
    if not assisted:
        (out / ASSISTANCE_CSV).unlink(missing_ok=True)
    return table


def _write_parquet_copy(frame, path: Path) -> None:
    """The Parquet copy of a results table, or (without the ``parquet`` extra) no copy: an
    earlier run's copy is removed then, so that it cannot disagree with the CSV file."""
    from ..io.parquet import parquet_available, write_parquet

    if not parquet_available():
        path.unlink(missing_ok=True)
        return
    with atomic_path(path) as tmp:
        write_parquet(frame, tmp)
