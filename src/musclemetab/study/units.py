"""Units of work of a study, their keys, and how one unit is run.

A *trial unit* is one subject × trial × workflow: solve the muscle redundancy problem,
evaluate the metabolic models, find the gait cycle and analyse phases and muscle groups.
An *estimation unit* is one subject's EMG-TEN problem over all its trials at once; the
EMG-TEN trial units and EFFORT-TEN units that use the subject's own estimate depend on it.
A subject's ``[subjects.estimate]`` table adds a parameter-estimation unit
(:mod:`.estimation`); with the subject's ``emg_mode`` its effort workflows' trial units are
EMG-informed solves.

A subject with ``side = "both"`` has one trial unit per leg (``Unit.side``), scheduled with
all the others; the study's results add the two legs (:mod:`.runner`).

Every unit has a folder ``units/<subject>/<trial>/<workflow>``, ``.../<workflow>/<side>`` for
each leg of a ``side = "both"`` subject (estimation:
``units/<subject>/_emg-ten``, parameter estimation ``units/<subject>/_estimate``) and, when complete, a ``unit.json`` in it recording the unit's
key (a SHA-256 of everything its result depends on: input file contents, settings,
the package version and the keys of the units it depends on), its status and the SHA-256 of
each output file. A unit is complete when ``unit.json`` says ``ok``, its key equals the
current key and every output file is present with its recorded hash; otherwise it is
run again. A unit's folder is replaced as a whole: its outputs are written into a
temporary folder beside it which is renamed into place at the end.

Safety: every unit folder is resolved and must lie inside the study's output folder.
Each folder the package creates (the temporary ``.<name>.partial-*`` folders and the unit
folders they become) holds a marker file, :data:`MARKER_FILE`; the package deletes or
replaces only folders that carry it, so a study file can never make it delete a folder
it did not create. A folder in a unit's place without the marker makes the unit fail
with a message naming it. Temporary folders left by a killed run are removed by the
next run (:func:`remove_stale_partials`).

Run a unit with :func:`execute_unit`; it never raises: a failure is returned (and written)
as a record with ``status = "failed"`` and the reason.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import threading
import time
import traceback
import warnings
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from .. import __version__
from ..errors import DataMismatchError, MusclemetabError, OptionError
from ..io.atomic import FILES_MANIFEST, file_sha256
from .estimation import ESTIMATE, ESTIMATE_FOLDER, run_parameter_estimation
from .spec import EMG_TEN, STATES, Study, Subject, Trial

__all__ = [
    "Unit",
    "check_assistance",
    "UNIT_FILE",
    "plan_units",
    "is_sampled",
    "unit_key",
    "read_unit_record",
    "is_complete",
    "execute_unit",
    "ESTIMATION_FOLDER",
    "MARKER_FILE",
    "unit_folder",
    "remove_stale_partials",
    "prepare_leg_folder",
    "WARM_CHAIN",
    "SENSITIVITY_WORKFLOWS",
    "sensitivity_skipped",
    "unit_sensitivity",
]

from ..study_layout import TIMESERIES_FILE, UNIT_FILE, UNITS_FOLDER  # noqa: E402  (defined once)
#: Marker file in every folder the package creates for a unit (and may therefore delete).
MARKER_FILE = ".musclemetab-unit"
ESTIMATION_FOLDER = "_emg-ten"
#: folder of a trial unit's uncertainty samples (in the unit's folder)
SAMPLES_FOLDER = "samples"
ANALYSIS_FILE = "analysis.csv"
#: The effort workflows in the order a trial's warm-started solves run: each starts from the
#: solution of the one before it in the study (``docs/study.md``, "Warm-started chains").
WARM_CHAIN = ("effort-gen", "effort-cal", "effort-ten")


@dataclass(frozen=True)
class Unit:
    """One unit of work: ``trial`` is ``None`` for a subject's EMG-TEN estimation; ``side`` is
    the leg of a ``side = "both"`` subject (``None``: the subject's one side)."""

    subject: str
    trial: str | None
    workflow: str
    side: str | None = None
    #: the number of an uncertainty sample of the trial unit (:mod:`.uncertainty`), else ``None``
    sample: int | None = None

    @property
    def is_estimation(self) -> bool:
        return self.trial is None

    @property
    def folder(self) -> Path:
        if self.trial is None:
            return Path(UNITS_FOLDER) / self.subject / (ESTIMATION_FOLDER if self.workflow == EMG_TEN else ESTIMATE_FOLDER)
        folder = Path(UNITS_FOLDER) / self.subject / self.trial / self.workflow
        folder = folder / self.side if self.side else folder
        return folder if self.sample is None else folder / SAMPLES_FOLDER / f"{self.sample:04d}"

    @property
    def label(self) -> str:
        return (f"{self.subject}/{self.trial or 'all trials'}/{self.workflow}" + (f"/{self.side}" if self.side else "")
                + (f"/sample {self.sample}" if self.sample is not None else ""))

    def leg(self, study: Study) -> str:
        """The leg this unit solves: its own ``side``, else its subject's."""
        return self.side or study.subject(self.subject).side

    def depends_on(self, study: Study) -> "Unit | None":
        """The estimation unit this unit needs, if any."""
        if self.trial is None:
            return None
        if self.sample is not None:  # the trial unit it samples
            return Unit(self.subject, self.trial, self.workflow, self.side)
        subject = study.subject(self.subject)
        if self.workflow == EMG_TEN or (self.workflow == "effort-ten" and subject.uses_emg_ten_estimate):
            return Unit(self.subject, None, EMG_TEN)
        return None

    def warm_source(self, study: Study) -> "Unit | None":
        """The unit whose solution this unit's solve starts from, if any: with the study's
        ``warm_start`` (or ``best_start``: it is then one of the two starts), the same subject, trial
        and leg with the workflow before this one in :data:`WARM_CHAIN` among the study's workflows;
        an assisted trial's solve (its ``assisted_from``), whatever ``warm_start`` says, from the
        unassisted trial's solve with the same workflow. EMG-informed solves (the subject's ``emg_mode``), EMG-TEN and estimations start cold."""
        if self.trial is None or self.sample is not None or self.workflow not in WARM_CHAIN:
            return None
        subject = study.subject(self.subject)
        if subject.emg_mode is not None:
            return None
        assisted_from = subject.trial(self.trial).assisted_from
        if assisted_from is not None:  # an assisted solve starts from the unassisted one (docs/assistance.md)
            return Unit(self.subject, assisted_from, self.workflow, self.side)
        if not (study.warm_start or study.best_start):
            return None
        before = [w for w in WARM_CHAIN[:WARM_CHAIN.index(self.workflow)] if w in study.workflows]
        return Unit(self.subject, self.trial, before[-1], self.side) if before else None


def is_sampled(study: Study, unit: Unit) -> bool:
    """Whether a trial unit has uncertainty samples: an effort workflow solved from its files."""
    subject = study.subject(unit.subject)
    return unit.trial is not None and unit.workflow not in (EMG_TEN, STATES) and subject.emg_mode is None


def plan_units(study: Study) -> tuple[list[Unit], list[Unit]]:
    """The study's units in two stages: estimations first, then the trial units."""
    stage1 = [Unit(s.name, None, EMG_TEN) for s in study.subjects
              if EMG_TEN in study.workflows or s.uses_emg_ten_estimate]
    stage1 += [Unit(s.name, None, ESTIMATE) for s in study.subjects if s.estimate is not None]
    # Workflow by workflow: parallel workers start on different trials, so a trial's
    # geometry is computed once and found in the cache by its other workflows.
    stage2 = [Unit(s.name, t.name, w, side if len(s.sides) > 1 else None)
              for w in study.workflows for s in study.subjects for t in s.trials for side in s.sides
              if t.states is None]
    # a trial of an OpenSim states file: one unit, its rates from the states (no solve)
    stage2 += [Unit(s.name, t.name, STATES, side if len(s.sides) > 1 else None)
               for s in study.subjects for t in s.trials for side in s.sides if t.states is not None]
    return stage1, stage2


# ---------------------------------------------------------------------------------------
_HASHES: dict[tuple[str, int, int], str] = {}


def _file_hash(path: Path | None) -> str | None:
    """Content hash of an input file (memoised by path, size and modification time)."""
    if path is None:
        return None
    st = os.stat(path)
    key = (str(path), st.st_size, st.st_mtime_ns)
    if key not in _HASHES:
        _HASHES[key] = file_sha256(path)
    return _HASHES[key]


def _trial_record(trial: Trial) -> dict:
    rec = {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(trial).items()}
    rec["files"] = {k: _file_hash(p) for k, p in trial.files().items()}
    for k in ("ik", "id", "emg", "grf", "external_loads", "assistance", "states", "controls"):
        rec.pop(k, None)  # paths do not matter, contents do
    for k in ("cycle", "window", "ultrasound", "assisted_from", "fiber_velocity", "muscle_parameters"):
        if rec.get(k) is None:
            rec.pop(k, None)  # absent key: earlier studies keep their unit keys
    if trial.assistance is None:
        rec.pop("assistance_gain", None)
    from ..emg import RawEmgPath, processing_record

    if isinstance(trial.emg, RawEmgPath):  # raw EMG processed by the package (absent: envelopes, earlier keys)
        rec["emg_processing"] = processing_record(trial.emg)
    return rec


def _subject_record(subject: Subject, workflow: str) -> dict:
    kt = subject.tendon_stiffness
    if isinstance(kt, Path):
        kt = {"file": _file_hash(kt)}
    rec = {
        "model": _file_hash(subject.model),
        "body_mass_kg": subject.body_mass_kg,
        "height_m": subject.height_m,
        "passive": _file_hash(subject.passive) if workflow != "effort-gen" else None,
        "tendon_stiffness": kt if workflow in ("effort-ten",) else None,
        "emg_mapping": subject.emg_mapping if workflow == EMG_TEN else None,
    }
    if subject.emg_mode is not None and workflow not in (EMG_TEN, ESTIMATE):  # absent keys: as below
        rec.update(emg_mode=subject.emg_mode, emg_tolerance=subject.emg_tolerance, emg_mapping=subject.emg_mapping)
    if workflow == ESTIMATE:
        rec.update(estimate=subject.estimate.to_dict(), emg_mapping=subject.emg_mapping)
    if subject.muscle_properties is not None:  # absent key: earlier studies keep their unit keys
        rec["muscle_properties"] = _file_hash(subject.muscle_properties)
    if subject.exclude_muscles:  # absent key: earlier studies keep their unit keys
        rec["exclude_muscles"] = list(subject.exclude_muscles)
    if subject.side != "r" or subject.dofs is not None:  # absent keys: earlier studies keep their unit keys
        rec["side"] = subject.side
        rec["dofs"] = list(subject.dofs) if subject.dofs is not None else None
    return rec


def unit_key(study: Study, unit: Unit, dependency_key: str | None = None, warm_key: str | None = None) -> str:
    """SHA-256 of everything the unit's result depends on (``warm_key``: the key of the unit whose
    solution it starts from, :meth:`Unit.warm_source`)."""
    if unit.sample is not None:  # the sampled unit's key, the priors, the seed and the sample's number
        from .samples import sample_key

        return sample_key(study, unit, dependency_key)
    subject = study.subject(unit.subject)
    content = {
        "musclemetab": __version__,
        "unit": [unit.subject, unit.trial, unit.workflow] + ([unit.side] if unit.side else []),
        "subject": _subject_record(subject, unit.workflow),
        "dependency": dependency_key,
    }
    if study.settings.get("solver"):
        content["solver"] = study.settings["solver"]
    if warm_key is not None:  # absent for a cold start: cold studies keep their unit keys
        content["warm_start"] = warm_key
        if study.best_start:  # solved from both starts, the lower objective kept
            content["best_start"] = True
    if study.settings.get("energy_goal") and unit.workflow != EMG_TEN:
        content["energy_goal"] = study.settings["energy_goal"]
    if unit.trial is None:
        content["trials"] = [_trial_record(t) for t in subject.trials]
    else:
        content["trial"] = _trial_record(subject.trial(unit.trial))
        content["models"] = list(study.models)
        content["basal"] = study.basal
        if "basal_coefficient" in study.settings:  # absent: earlier studies keep their unit keys
            content["basal_coefficient_exponent"] = [study.basal_coefficient, study.basal_exponent]
        if study.strict:  # absent when false: earlier studies keep their unit keys
            content["strict"] = True
        if study.sensitivity:  # absent when false: earlier studies keep their unit keys
            content["sensitivity"] = True
    text = json.dumps(content, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def read_unit_record(folder: Path) -> dict | None:
    """The unit's ``unit.json``, or ``None`` when absent or unreadable."""
    try:
        return json.loads((Path(folder) / UNIT_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def is_complete(folder: Path, key: str) -> bool:
    """Whether the unit in ``folder`` finished with key ``key`` and its outputs are intact."""
    rec = read_unit_record(folder)
    if not rec or rec.get("status") != "ok" or rec.get("key") != key:
        return False
    outputs = rec.get("outputs") or {}
    if not outputs:
        return False
    for rel, digest in outputs.items():
        p = Path(folder) / rel
        if not p.is_file() or file_sha256(p) != digest:
            return False
    return True


# ---------------------------------------------------------------------------------------
def _outputs(folder: Path) -> dict[str, str]:
    return {
        str(p.relative_to(folder)): file_sha256(p)
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name not in (UNIT_FILE, MARKER_FILE, FILES_MANIFEST)
    }


def _list_unit_files(tmp: Path) -> None:
    """Write ``tmp/.musclemetab-files``: every file of the unit folder about to be put in
    place (the failed unit's too), by its path in the folder, with its SHA-256."""
    lines = [f"{file_sha256(p)}  {p.relative_to(tmp).as_posix()}\n" for p in sorted(tmp.rglob("*"))
             if p.is_file() and p.name != FILES_MANIFEST]
    (tmp / FILES_MANIFEST).write_text("".join(lines), encoding="utf-8")


def _foreign_file(folder: Path) -> Path | None:
    """A file in the unit folder ``folder`` that the package did not put there: not in the
    folder's :data:`~musclemetab.io.atomic.FILES_MANIFEST`, nor the package's marker and lists.
    A listed file changed since is the package's (the run redoes a unit whose outputs were
    altered); a folder without the list (written before the package kept it) has none."""
    from ..io.atomic import written_files

    if not (folder / FILES_MANIFEST).is_file() or folder.is_symlink():
        return None
    listed = written_files(folder)
    for p in sorted(folder.rglob("*")):
        if (p.is_file() or p.is_symlink()) and p.name not in (UNIT_FILE, MARKER_FILE, FILES_MANIFEST) \
                and p.relative_to(folder).as_posix() not in listed:
            return p
    return None


def unit_folder(output: Path, unit: Unit) -> Path:
    """The unit's folder, resolved; :class:`OptionError` if it would leave ``output``."""
    from ..io.atomic import check_inside

    return check_inside(output, unit.folder, f"the folder of unit {unit.label},")


def _is_ours(folder: Path) -> bool:
    """Whether ``folder`` is a real folder (not a link) that carries the package's marker."""
    return folder.is_dir() and not folder.is_symlink() and (folder / MARKER_FILE).is_file()


def _is_our_unit(folder: Path) -> bool:
    """A unit folder of ours: the marker, or the ``unit.json`` every unit folder gets."""
    return _is_ours(folder) or (folder.is_dir() and not folder.is_symlink() and (folder / UNIT_FILE).is_file())


def _replace_folder(tmp: Path, folder: Path) -> None:
    """Put ``tmp`` in the place of ``folder``; the old folder is removed only if it is ours."""
    from ..errors import OptionError

    old = None
    if folder.exists() or folder.is_symlink():
        if not _is_our_unit(folder):
            raise OptionError(
                f"{folder} exists but was not written by musclemetab (no {MARKER_FILE} in it); "
                "move it away or choose another output folder"
            )
        foreign = _foreign_file(folder)
        if foreign is not None:
            raise OptionError(
                f"{foreign} was not written by musclemetab (not listed in {folder / FILES_MANIFEST}); the unit's "
                "folder is not replaced: move the file away, or choose another output folder"
            )
        old = folder.with_name(f".{folder.name}.old-{os.getpid()}-{time.monotonic_ns()}")
        os.replace(folder, old)
    os.replace(tmp, folder)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def remove_stale_partials(output: Path) -> list[Path]:
    """Remove the temporary unit folders (``.*.partial-*``, ``.*.old-*``) a killed run left.

    Only folders carrying :data:`MARKER_FILE` are removed. Call it only while holding the
    study's lock (no other run is writing). Returns the folders removed.
    """
    units = Path(output) / "units"
    removed = []
    if not units.is_dir() or units.is_symlink():
        return removed
    for p in units.rglob(".*"):
        if (".partial-" in p.name or ".old-" in p.name) and _is_ours(p):
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    return removed


def prepare_leg_folder(output: Path, unit: Unit) -> None:
    """Make the folder holding a leg unit's folder (``.../<workflow>``) a container of ours.

    A single-leg unit of an earlier run of the study (before its subject's ``side`` became
    ``"both"``) in that place is removed, as any replaced unit folder of ours; a folder that
    is not ours makes :class:`OptionError` name it. The container carries
    :data:`MARKER_FILE`, so that a later single-leg unit may replace it. Call it before the
    units run (it is not safe while leg units of the same container run).
    """
    from ..errors import OptionError

    if not unit.side or unit.sample is not None:  # a sample's folder is inside its leg unit's
        return
    parent = unit_folder(Path(output), unit).parent
    if (parent / UNIT_FILE).is_file() and _is_our_unit(parent):
        old = parent.with_name(f".{parent.name}.old-{os.getpid()}-{time.monotonic_ns()}")
        os.replace(parent, old)
        shutil.rmtree(old, ignore_errors=True)
    elif parent.exists() and not _is_ours(parent) and any(
            p.name not in ("r", "l") and not p.name.startswith(".") for p in parent.iterdir()):
        raise OptionError(f"{parent} exists but was not written by musclemetab (no {MARKER_FILE} in it); "
                          "move it away or choose another output folder")
    parent.mkdir(parents=True, exist_ok=True)
    if not (parent / MARKER_FILE).is_file():
        (parent / MARKER_FILE).write_text("created by musclemetab\n", encoding="utf-8")


#: Status of a unit stopped by Ctrl-C.
INTERRUPTED = "interrupted"
_INTERRUPTED = threading.Event()


def _on_sigint(signum, frame):
    """SIGINT while a unit runs: remember it, then interrupt as Python does by default.

    A second SIGINT (the terminal's and the runner's) does not interrupt the clean-up."""
    if _INTERRUPTED.is_set():
        return
    _INTERRUPTED.set()
    raise KeyboardInterrupt


def execute_unit(study: Study, unit: Unit, key: str, dependency_folder: str | None = None,
                 warm_folder: str | None = None) -> dict:
    """Run one unit and write its folder; returns its record (never raises).

    ``warm_folder``: the folder of the unit whose solution the solve starts from
    (:meth:`Unit.warm_source`); the solve starts cold when that unit did not succeed, and is
    solved again cold when the warm-started solve does not succeed (the record's ``start``).

    Ctrl-C (SIGINT) during the unit gives a record with ``status = "interrupted"`` and
    leaves the unit's folder as it was, even when the solver caught the interrupt and
    returned a failure status.
    """
    import signal

    _INTERRUPTED.clear()
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGINT, _on_sigint)
    try:
        return _execute_unit(study, unit, key, dependency_folder, warm_folder)
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


def _execute_unit(study: Study, unit: Unit, key: str, dependency_folder: str | None = None,
                  warm_folder: str | None = None) -> dict:
    record = {
        "status": "failed",
        "key": key,
        "subject": unit.subject,
        "trial": unit.trial,
        "workflow": unit.workflow,
        **({"side": unit.side} if unit.side else {}),
        **({"sample": unit.sample} if unit.sample is not None else {}),
        "error": None,
        "times": {},
    }
    try:
        folder = unit_folder(Path(study.output), unit)
        folder.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.partial-", dir=folder.parent))
        (tmp / MARKER_FILE).write_text("created by musclemetab\n", encoding="utf-8")
    except (OSError, MusclemetabError) as exc:
        record["error"] = f"{type(exc).__name__}: {exc}"
        return record
    t0 = time.perf_counter()
    interrupted = False
    try:
        if unit.is_estimation and unit.workflow == ESTIMATE:
            record.update(run_parameter_estimation(study, unit, tmp))
        elif unit.is_estimation:
            record.update(_run_estimation(study, unit, tmp))
        elif unit.sample is not None:  # an uncertainty sample of the trial unit in dependency_folder
            from .samples import run_sample

            subject = study.subject(unit.subject)
            estimation = Path(study.output) / Unit(unit.subject, None, EMG_TEN).folder
            record.update(run_sample(study, unit, tmp, Path(dependency_folder),
                                     options=_solver_options(study),
                                     goals=_goals(study, subject, unit.workflow),
                                     arguments={**trial_solve_keywords(subject, subject.trial(unit.trial),
                                                                       unit.leg(study)),
                                                **solve_arguments(subject, unit.workflow, estimation),
                                                **_device_arguments(subject.trial(unit.trial), unit.leg(study),
                                                                    subject.model, subject.side == "both")},
                                     analysis_file=ANALYSIS_FILE))
        else:
            dep = Path(dependency_folder) if dependency_folder else None
            record.update(_run_trial(study, unit, tmp, dep, Path(warm_folder) if warm_folder else None))
        record["status"] = "ok"
    except KeyboardInterrupt:
        interrupted = True
    except MusclemetabError as exc:
        record["error"] = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
    except Exception as exc:  # a bug or a library failure: keep the traceback for the report
        record["error"] = f"{type(exc).__name__}: {exc}"
        record["traceback"] = traceback.format_exc(limit=8)
    record["times"]["total_s"] = time.perf_counter() - t0
    if interrupted or _INTERRUPTED.is_set():
        # Ctrl-C: the solver may have returned early with a failure status; nothing of this
        # unit is kept and its previous folder (if any) stays as it was.
        shutil.rmtree(tmp, ignore_errors=True)
        record.update(status=INTERRUPTED, error="interrupted (Ctrl-C) before it finished")
        record.pop("traceback", None)
        return record
    try:
        record["outputs"] = _outputs(tmp) if record["status"] == "ok" else {}
        (tmp / UNIT_FILE).write_text(json.dumps(record, indent=2, default=str) + "\n", encoding="utf-8")
        _list_unit_files(tmp)
        os.chmod(tmp, 0o777 & ~_umask())
        _replace_folder(tmp, folder)
    except (OSError, MusclemetabError) as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        record.update(status="failed", error=f"could not write {folder}: {exc}", outputs={})
    return record


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _run_estimation(study: Study, unit: Unit, tmp: Path) -> dict:
    """EMG-TEN over all the subject's trials: per-trial solutions and parameters.json."""
    from ..redundancy.emg_run import solve_emg_ten

    subject = study.subject(unit.subject)
    t0 = time.perf_counter()
    result = solve_emg_ten(
        subject.model,
        [t.ik for t in subject.trials],
        [t.id for t in subject.trials],
        [t.emg for t in subject.trials],
        emg_mapping=subject.emg_mapping,
        labels=[t.name for t in subject.trials],
        passive=subject.passive,
        side=subject.side,
        dofs=subject.dofs,
        options=_solver_options(study),
        exclude_muscles=subject.exclude_muscles,
    )
    if not result.success:  # nothing of a failed estimate is written
        raise result.run_record.failure(f"EMG-TEN of subject {subject.name}")
    result.write(tmp, opensim_files=False)  # each trial unit writes its own
    return {"times": {"solve_s": time.perf_counter() - t0}}


def _informed_solve(study: Study, subject: Subject, trial: Trial, workflow: str, kwargs: dict):
    """The EMG-informed solve of one trial with an effort workflow (the subject's ``emg_mode``)."""
    from ..redundancy.emg_ten import informed_settings
    from ..redundancy.emg_run import solve_emg_ten
    from ..redundancy.workflows import read_tendon_stiffness_json

    kt = kwargs.get("tendon_stiffness")
    if kwargs.get("tendon_stiffness_file") is not None:
        kt = read_tendon_stiffness_json(kwargs["tendon_stiffness_file"])
    result = solve_emg_ten(subject.model, [trial.ik], [trial.id], [trial.emg], emg_mapping=subject.emg_mapping,
                           labels=[trial.name], passive=kwargs.get("passive"), side=subject.side, dofs=subject.dofs,
                           options=_solver_options(study),
                           settings=informed_settings(workflow, subject.emg_mode, subject.emg_tolerance),
                           workflow=workflow, tendon_stiffness=kt, exclude_muscles=subject.exclude_muscles)
    return result.solutions[trial.name]


def _solver_options(study: Study):
    """The study's ``[solver]`` settings as :class:`~musclemetab.redundancy.SolverOptions` (or ``None``)."""
    from ..redundancy import SolverOptions

    settings = study.settings.get("solver") or {}
    return SolverOptions(**settings) if settings else None


def _goals(study: Study, subject: Subject, workflow: str):
    """The goals of ``subject``'s solves with the effort ``workflow``: the workflow's, with the
    study's ``[energy_goal]`` for the subject (its mass, height and muscle properties); ``None``
    (the workflow's) without an energy goal."""
    energy = study.settings.get("energy_goal")
    if not energy:
        return None
    from dataclasses import replace

    from ..redundancy.energy import EnergyGoal
    from ..redundancy.workflows import get_workflow

    goal = EnergyGoal(body_mass_kg=subject.body_mass_kg, height_m=subject.height_m,
                      muscle_properties=subject.muscle_properties, **energy)
    return replace(get_workflow(workflow).goals, energy=goal)


def _copy_solution(source: Path, target: Path) -> None:
    from ..redundancy.solution import SOLUTION_FILE, SUMMARY_FILE

    for name in (SOLUTION_FILE, SUMMARY_FILE):
        if not (source / name).is_file():
            from ..errors import InputFileError

            raise InputFileError(f"{source / name} is missing; the EMG-TEN estimation did not write it")
        shutil.copyfile(source / name, target / name)


def _cycle_source(trial: Trial, recorded: dict | None = None) -> str:
    """Where the trial's gait events come from (:func:`musclemetab.study.events.trial_cycle`,
    or ``recorded``: the gait cycle the solve found, from its summary's window)."""
    if all(v is not None for v in (trial.start_s, trial.toe_off_s, trial.end_s)):
        return "study file"
    if recorded and trial.start_s is None and trial.end_s is None:
        return f"ground reaction forces ({recorded.get('source') or 'found by the solve'})"
    if trial.grf is not None:
        return "ground reaction forces"
    if trial.external_loads is not None:
        return "ground reaction forces (external_loads)"
    return (f"estimated from the {'solved' if trial.window is not None else 'IK'} window and the ankle moment "
            "(no ground reaction forces)")


def trial_solve_keywords(subject: Subject, trial: Trial, side: str) -> dict:
    """The ``solve_files`` keywords of a trial's solve of the leg ``side`` that every workflow
    shares: its window (``cycle``, or ``window`` as ``--window``; the whole IK file without
    either), ground forces, DOFs and excluded muscles."""
    return dict(side=side, dofs=subject.dofs, external_loads=trial.external_loads,
                grf=trial.grf if trial.cycle is not None else None, grf_column=trial.grf_column,
                grf_threshold_N=trial.grf_threshold_N, cycle=trial.cycle, window=trial.window,
                exclude_muscles=subject.exclude_muscles, exclude_missing_ok=subject.side == "both")


def solve_arguments(subject: Subject, workflow: str, estimation: Path | None) -> dict:
    """The personalisation arguments of a trial's solve with ``workflow``: the subject's passive
    calibration and tendon stiffness (``estimation``: the folder of the subject's EMG-TEN estimate)."""
    kwargs = {}
    if workflow != "effort-gen" and subject.passive is not None:
        kwargs["passive"] = subject.passive
    if workflow == "effort-ten":
        kt = subject.tendon_stiffness
        if subject.uses_emg_ten_estimate:
            kwargs["tendon_stiffness_file"] = estimation / "parameters.json"
        elif isinstance(kt, Path):
            kwargs["tendon_stiffness_file"] = kt
        elif isinstance(kt, (dict, str)):  # a table, or "example"
            kwargs["tendon_stiffness"] = kt
    return kwargs


def _run_trial(study: Study, unit: Unit, tmp: Path, dependency: Path | None, warm: Path | None = None) -> dict:
    """Solve (or take the EMG-TEN solution), metabolics, gait cycle, phases and groups; ``warm``: the
    folder of the unit whose solution the solve starts from (:func:`_chain_solve`)."""
    import numpy as np

    from ..geometry import compute_geometry
    from ..metabolics.solution import metabolics_from_solution, write_metabolics
    from ..redundancy.run import solve_files, write_solution_folder
    from ..redundancy.solution import Solution
    from ..analysis.unit import averaged_by_default, recorded_trial
    from .events import rates_span_s, trial_cycle, trial_speed

    subject = study.subject(unit.subject)
    trial = subject.trial(unit.trial)
    side = unit.leg(study)
    times = {}
    start = COLD
    t0 = time.perf_counter()
    sol = states = other = None
    if unit.workflow == STATES:  # the rates of an OpenSim states file: no solve
        states = _states_metabolics(study, subject, trial, side)
    elif unit.workflow == EMG_TEN:
        _copy_solution(dependency / trial.name, tmp)
        sol = Solution.load(tmp, require_success=False)  # the estimation unit's output: its hand-off
        if not sol.run_record.success:
            raise sol.run_record.failure(f"EMG-TEN solution of trial {trial.name}")
    else:
        kwargs = solve_arguments(subject, unit.workflow, dependency)
        if subject.emg_mode is not None:
            sol = _informed_solve(study, subject, trial, unit.workflow, kwargs)
        else:
            device = _device_arguments(trial, side, subject.model, subject.side == "both")

            def solve(warm_start=None):
                return solve_files(subject.model, trial.ik, trial.id, unit.workflow, options=_solver_options(study),
                                   goals=_goals(study, subject, unit.workflow),
                                   **({"warm_start": warm_start} if warm_start is not None else {}), **device,
                                   **trial_solve_keywords(subject, trial, side), **kwargs)

            sol, start, other = _chain_solve(solve, unit.warm_source(study), warm, times, trial.name,
                                             both=study.best_start)
        write_solution_folder(sol, tmp, opensim_files=False)  # written below, for every workflow
        if (study.settings.get("uncertainty") or {}).get("samples") and is_sampled(study, unit):
            from .samples import write_start

            write_start(sol, tmp)  # its samples start from its optimum
        times["solve_s"] = sol.record.solve_time_s
        if not sol.success:
            from ..redundancy.emg_ten import emg_failure

            raise emg_failure(sol.run_record, subject.emg_mode, f"{unit.workflow} solve of {subject.name}/{trial.name}")
    times["solution_s"] = time.perf_counter() - t0
    if study.strict and sol is not None:  # the solve's flags fail the unit before the later stages run
        from ..quality import check_strict

        check_strict(sol.record.flags, unit.label)

    t1 = time.perf_counter()
    from ..model import check_body_mass

    check_body_mass(subject.body_mass_kg, subject.model, f"{subject.name}: body_mass_kg")
    # the stages after the solve take the solution object (the same numbers as its folder,
    # tests/test_stage_paths.py); each writes its files once
    recorded = sol.record.gait_cycle if sol is not None else None
    window = _window_record(trial, sol) if trial.window is not None else None
    if recorded and trial.start_s is None and trial.end_s is None:  # the cycle the solve found
        from ..events import GaitCycle

        toe_off = trial.toe_off_s if trial.toe_off_s is not None else recorded["toe_off_s"]
        cycle = GaitCycle(recorded["start_s"], toe_off, recorded["end_s"])
    elif window is not None:  # in the solved window, as analyse finds it
        cycle = trial_cycle(trial, side, subject.model, window_s=tuple(window["solved_s"]),
                            id_file=trial.id or recorded_trial(sol).id)
    else:
        cycle = trial_cycle(trial, side, subject.model)
    try:  # over the cycle the rates are averaged over, as 'musclemetab analyse' takes it
        speed = trial_speed(trial, subject.model, cycle)
    except DataMismatchError as exc:  # e.g. a treadmill trial without speed_m_per_s: no cost of transport
        from ..errors import MusclemetabWarning

        leg = f" ({'right' if side == 'r' else 'left'} leg)" if unit.side else ""  # each leg over its own cycle
        warnings.warn(f"{subject.name}/{trial.name}{leg}: no walking speed, no cost of transport ({exc})",
                      MusclemetabWarning, stacklevel=2)
        speed = None
    # the rates are averaged over the trial's cycle, as 'musclemetab analyse' averages them over the
    # cycle it is given: when events the trial names (start_s and end_s, its grf, a cycle inside its
    # window) bound another span than the solve's own (its cycle, or its window less the padding)
    rates_over_s = None if sol is None or averaged_by_default(recorded_trial(sol), cycle) else \
        [cycle.start_s, cycle.end_s]
    if rates_over_s is not None:
        _check_cycle_solved(trial, cycle, sol.time_s)
    result = states(speed, cycle) if states is not None else metabolics_from_solution(
        sol, subject.body_mass_kg, subject.height_m, models=list(study.models), basal=study.basal,
        basal_rate_W_per_kg=study.basal_coefficient, basal_exponent=study.basal_exponent,
        speed_m_per_s=speed, muscle_properties=subject.muscle_properties, cycle_s=rates_span_s(rates_over_s),
    )
    write_metabolics(result, tmp, cycle=cycle)
    starts = None if other is None else _starts_record(sol, start, other, result, lambda s: metabolics_from_solution(
        s, subject.body_mass_kg, subject.height_m, models=list(study.models), basal=study.basal,
        basal_rate_W_per_kg=study.basal_coefficient, basal_exponent=study.basal_exponent,
        speed_m_per_s=speed, muscle_properties=subject.muscle_properties, cycle_s=rates_span_s(rates_over_s)))
    times["metabolics_s"] = time.perf_counter() - t1

    t2 = time.perf_counter()
    from ..analysis.groups import has_function_group

    # DOFs with no muscle function group (a subtalar or toe joint) stay out of the group analysis
    dofs = sol.dofs if sol is not None else _model_dofs(subject, side)
    geometry = compute_geometry(subject.model, trial.ik, dofs=[d for d in dofs if has_function_group(d)],
                                side=side)
    from ..analysis.unit import analyse_metabolics, filtered_moment_arms

    tg, r = filtered_moment_arms(geometry)
    analysis = analyse_metabolics(result, tg, r, list(geometry.dofs), list(geometry.muscles), cycle)
    analysis.summary.to_csv(tmp / ANALYSIS_FILE, index=False, float_format="%.10g")
    analysis.timeseries.to_csv(tmp / TIMESERIES_FILE, index=False, float_format="%.10g")
    times["analysis_s"] = time.perf_counter() - t2

    if sol is not None:  # a states trial's OpenSim files are its own
        t3 = time.perf_counter()
        from ..redundancy.export import write_opensim_states

        write_opensim_states(sol, subject.model, trial.ik, tmp)
        times["opensim_states_s"] = time.perf_counter() - t3
    if study.sensitivity:
        t4 = time.perf_counter()
        sensitivity = unit_sensitivity(study, unit, tmp)
        times["sensitivity_s"] = time.perf_counter() - t4
    flags = _plausibility(study, unit, sol, result, speed, analysis.summary)
    measured = trial.measured_W_per_kg
    if measured is None and trial.vo2_mL_per_s is not None:
        from ..metabolics.whole_body import brockway_rate_W

        measured = float(brockway_rate_W(trial.vo2_mL_per_s, trial.vco2_mL_per_s)) / subject.body_mass_kg
    return {
        "times": times,
        "start": start,
        **({"starts": starts} if starts is not None else {}),
        "speed_m_per_s": speed,
        "measured_W_per_kg": measured,
        "cycle": {"start_s": cycle.start_s, "toe_off_s": cycle.toe_off_s, "end_s": cycle.end_s},
        "cycle_source": _cycle_source(trial, recorded),
        **({"window": window} if window is not None else {}),
        **({"rates_over_s": rates_over_s} if rates_over_s is not None else {}),
        "speed_source": "study file" if trial.speed_m_per_s is not None else (
            "not available" if speed is None else "estimated from the pelvis displacement over the cycle (IK)"),
        "toe_off_pct": float(100.0 * (cycle.toe_off_s - cycle.start_s) / (cycle.end_s - cycle.start_s)),
        "n_nodes": int(np.asarray(result.time_s).size),
        "large_reserve": bool(sol.record.large_reserve) if sol is not None else False,
        "excluded_muscles": list(sol.record.excluded_muscles or []) if sol is not None else [],
        "reserve_share_of_peak_moment": sol.record.reserve_share_of_peak_moment if sol is not None else None,
        **({"states": {"file": str(trial.states), "controls": str(trial.controls) if trial.controls else None}}
           if states is not None else {}),
        "plausibility": [f.to_dict() for f in flags],
        **({"sensitivity": sensitivity} if study.sensitivity else {}),
        **({"assistance": _device_record(trial, sol, subject.body_mass_kg)} if trial.assistance is not None else {}),
    }


def _check_cycle_solved(trial: Trial, cycle, nodes_s) -> None:
    """:class:`DataMismatchError` naming the trial when its gait cycle (its events, or its ``grf``'s)
    is not covered by the solved nodes ``nodes_s``, over which its rates are averaged (the rule of
    :func:`musclemetab.events.coverage`, as the metabolic rates apply it)."""
    import numpy as np

    from ..events import coverage

    t = np.asarray(nodes_s, dtype=float)
    try:
        coverage(t, cycle.start_s, cycle.end_s, None, "the solved nodes")
    except DataMismatchError:
        named = "its start_s and end_s" if trial.start_s is not None and trial.end_s is not None else (
            f"its ground forces ({trial.grf})" if trial.grf is not None else "its events")
        raise DataMismatchError(
            f"trial '{trial.name}': its gait cycle {cycle.start_s:.3f}-{cycle.end_s:.3f} s (from {named}) does not lie "
            f"inside the solved window {t[0]:.3f}-{t[-1]:.3f} s, over which the rates are averaged; give kinematics "
            "(ik) that cover the cycle, the trial's start_s, toe_off_s and end_s inside the window, or "
            "cycle = \"auto\" (the first cycle inside every input file)") from None


def _window_record(trial: Trial, sol) -> dict:
    """The unit record's ``window`` of a trial solved over its ``window``: the times given, the
    window solved (snapped to IK frames) and whether gait events bound the span the rates are
    averaged over (``named_by_events``: the trial's ``start_s`` and ``end_s``, or its ``grf``),
    as ``musclemetab analyse`` says of a solve over ``--window`` (``docs/quality.md``,
    ``not_a_gait_cycle``)."""
    from ..analysis.unit import recorded_trial

    return {"given_s": list(trial.window), "solved_s": list(recorded_trial(sol).window_s),
            "named_by_events": (trial.grf is not None or trial.external_loads is not None
                                or (trial.start_s is not None and trial.end_s is not None))}


def _states_metabolics(study: Study, subject: Subject, trial: Trial, side: str):
    """A function of the walking speed and the trial's gait cycle giving the trial's metabolic rates of
    ``side`` from its OpenSim states file averaged over that cycle, as ``musclemetab metabolics
    --states --cycle`` computes them
    (:func:`musclemetab.metabolics.opensim_states.states_metabolics`: the model's probes' muscle
    masses when it has any). The states are read (by OpenSim) at once, before the speed is known."""
    from ..metabolics.opensim_states import read_opensim_states, split_sides, states_metabolics

    read = read_opensim_states(subject.model, trial.states, trial.controls,
                               **({"fiber_velocity": trial.fiber_velocity} if trial.fiber_velocity else {}))
    legs = split_sides(read.states)
    if side not in legs:
        raise DataMismatchError(f"{trial.states}: no muscle of the {'right' if side == 'r' else 'left'} leg "
                                f"(the subject's side); it has the legs {', '.join(legs)}")

    def rates(speed, cycle):
        results, _ = states_metabolics(
            read, {side: legs[side]}, subject.body_mass_kg, subject.height_m, models=list(study.models),
            basal=study.basal, basal_rate_W_per_kg=study.basal_coefficient, basal_exponent=study.basal_exponent,
            speed_m_per_s=speed, muscle_properties=subject.muscle_properties,
            cycle_s=(cycle.start_s, cycle.end_s),
            **({"muscle_parameters": trial.muscle_parameters} if trial.muscle_parameters else {}))
        return results[side]

    return rates


def _model_dofs(subject: Subject, side: str) -> list[str]:
    """The subject's DOFs of ``side`` (its ``dofs``, else those discovered from the model)."""
    if subject.dofs is not None:
        return list(subject.dofs)
    from ..layout import discover_dofs, read_layout

    return list(discover_dofs(read_layout(subject.model), side, None))


def _device_arguments(trial: Trial, side: str, model, both_legs: bool = False) -> dict:
    """The ``solve_files`` keywords of an assisted trial: the profile, its gain, the gait cycle a
    profile over the cycle is mapped onto (the trial's, :func:`.events.trial_cycle`, inside its
    ``window`` when it has one; with ``cycle`` the solve's own) and whether the subject's other
    leg is solved too (``both_legs``: it takes a profile of its own coordinates)."""
    if trial.assistance is None:
        return {}
    out = {"assistance": trial.assistance, "assistance_gain": trial.assistance_gain,
           "assistance_both_legs": both_legs}
    if trial.cycle is None:
        from .events import trial_cycle

        c = trial_cycle(trial, side, model)
        out["assistance_cycle_s"] = (c.start_s, c.end_s)
    return out


def check_assistance(study: Study, prepared: bool = False) -> None:
    """Refuse, before any unit runs, an assistance profile that the solves would refuse: a column
    naming no coordinate of the subject's model, one of the leg's coordinates the solve leaves out,
    none of the leg's (unless both legs are solved), a time profile not covering the trial's
    window (a trial without ``cycle``), the units (:func:`~musclemetab.redundancy.assistance.
    check_profile_against_model`; each error names the subject, the trial and the file). The
    subjects whose model the study scales and the trials whose IK it computes are checked once
    they are (``prepared``); the others before (not ``prepared``)."""
    import warnings

    from ..errors import MusclemetabError
    from ..io import read_table
    from ..layout import discover_dofs, read_layout
    from ..redundancy.assistance import check_profile_against_model, read_assistance
    from .events import _ik_window

    for subject in study.subjects:
        for trial in subject.trials:
            if trial.assistance is None:
                continue
            later = subject.generic_model is not None or trial.markers is not None
            if later != prepared:
                continue
            here = (f"{study.source.name + ': ' if study.source else ''}subject '{subject.name}', trial "
                    f"'{trial.name}': 'assistance'")
            try:
                layout = read_layout(subject.model)
                profile = read_assistance(trial.assistance)
                window = _ik_window(trial) if trial.cycle is None else None
                id_columns = list(read_table(trial.id).columns) if trial.id is not None else None
                for side in (("r", "l") if subject.side == "both" else (subject.side,)):
                    try:
                        with warnings.catch_warnings():  # the solve warns of the DOFs left out
                            warnings.simplefilter("ignore")
                            dofs = subject.dofs or discover_dofs(layout, side, id_columns)
                    except MusclemetabError:
                        continue  # the trial's solves say why, unassisted too
                    check_profile_against_model(profile, dofs, side, [c["name"] for c in layout.coordinates],
                                                subject.body_mass_kg, window, other_leg_solved=subject.side == "both")
            except MusclemetabError as exc:
                raise type(exc)(f"{here}: {exc}") from None


def _device_record(trial: Trial, sol, body_mass_kg: float) -> dict:
    """The unit record's ``assistance``: the unassisted trial, the file, the gain and the device's
    work over the gait cycle (this leg's device; ``summary.json`` holds its torque and power)."""
    device = sol.record.assistance or {}
    keys = ("gain", "axis", "dofs", "cycle_s", "positive_work_J", "negative_work_J", "net_work_J",
            "mean_positive_power_W", "mean_negative_power_W", "duration_s")
    return {"assisted_from": trial.assisted_from, "file": Path(trial.assistance).name,
            **{k: device.get(k) for k in keys}, "body_mass_kg": body_mass_kg}


#: The workflows whose trial units write ``sensitivity.csv`` with the study's ``[uncertainty]
#: sensitivity`` (the effort workflows: :func:`musclemetab.redundancy.sensitivity.problem_of_solution`).
SENSITIVITY_WORKFLOWS = ("effort-gen", "effort-cal", "effort-ten")


def sensitivity_skipped(study: Study, unit: Unit) -> str | None:
    """Why the trial ``unit`` writes no ``sensitivity.csv`` (``None``: it writes one): the
    sensitivities are those of one leg's effort solve with the forward fiber dynamics."""
    if unit.trial is None or unit.sample is not None:
        return "not a trial unit"
    if unit.workflow not in SENSITIVITY_WORKFLOWS:
        return f"the sensitivities are computed for the effort workflows ({', '.join(SENSITIVITY_WORKFLOWS)}), " \
               f"not {unit.workflow}"
    if study.subject(unit.subject).emg_mode is not None:
        return "the solve is EMG-informed (emg_mode): the sensitivities are computed for the effort goal alone"
    if study.settings.get("energy_goal"):
        return "the solve has an energy goal ([energy_goal]): the sensitivities are computed for the effort goal alone"
    return None


def unit_sensitivity(study: Study, unit: Unit, folder: Path) -> dict:
    """Write ``sensitivity.csv`` of the trial ``unit``'s solution in ``folder`` (the function of
    ``musclemetab metabolics --sensitivity``, every parameter of every muscle, the study's models
    and basal rule); returns the unit record's ``sensitivity``: the file and its size, or why it
    was skipped (:func:`sensitivity_skipped`, or a case the sensitivities refuse)."""
    from ..redundancy.sensitivity import write_folder_sensitivity

    reason = sensitivity_skipped(study, unit)
    if reason is not None:
        return {"skipped": reason}
    subject = study.subject(unit.subject)
    try:
        path, sens = write_folder_sensitivity(
            folder, folder, trial=unit.trial, body_mass_kg=subject.body_mass_kg, height_m=subject.height_m,
            models=list(study.models), basal=study.basal, basal_rate_W_per_kg=study.basal_coefficient,
            basal_exponent=study.basal_exponent, muscle_properties=subject.muscle_properties)
    except OptionError as exc:  # a case the sensitivities do not support (e.g. backward fiber dynamics)
        return {"skipped": " ".join(str(exc).split())}
    return {"file": Path(path).name, "parameters": len(sens.parameters), "models": list(sens.models)}


#: The record's ``start`` of a solve started from static optimisation with no warm start planned.
COLD = "cold"


def _chain_solve(solve, source: Unit | None, folder: Path | None, times: dict, trial: str | None = None,
                 both: bool = False):
    """``(solution, start, other)``: ``solve(warm_start)`` started from the solution in ``folder``
    (the unit ``source``), with the fallback of ``docs/study.md`` ("Warm-started chains"):

    * no ``source``: a cold solve, start ``"cold"``;
    * ``source`` did not succeed (no ``ok`` record in ``folder``) or its solution has another
      mesh, muscles or DOFs than this problem: a cold solve, start ``"cold: ..."`` saying why;
    * the warm-started solve did not succeed (IPOPT's status): solved again cold, start
      ``"cold: ... solved again cold"`` with the warm attempt's status and iterations (its
      time in ``times["warm_attempt_s"]``);
    * otherwise start ``"warm from <workflow>"``.

    ``both`` (the study's ``best_start``): the warm-started solve that succeeded is solved cold too,
    and the one of lower objective is kept; ``other`` is then ``(the other's start, its solution)``
    (else ``None``), and ``times["other_start_s"]`` its time.
    """
    from ..errors import DataMismatchError, InputFileError, SolverError
    from ..redundancy.solution import Solution

    if source is None:
        return solve(), COLD, None
    if trial is not None and source.trial != trial:  # an assisted trial's unassisted solve
        source = replace(source, workflow=f"{source.trial} ({source.workflow})")
    rec = read_unit_record(folder) if folder is not None else None
    if not rec or rec.get("status") != "ok":
        return solve(), f"cold: {source.workflow} did not succeed, no warm start", None
    try:
        previous = Solution.load(folder)
    except (InputFileError, SolverError, OSError) as exc:
        return solve(), f"cold: the solution of {source.workflow} cannot be read ({' '.join(str(exc).split())})", None
    t0 = time.perf_counter()
    try:
        sol = solve(previous)
    except DataMismatchError as exc:  # another mesh (another gait cycle found), muscles or DOFs
        return solve(), f"cold: the solution of {source.workflow} does not fit this problem ({exc})", None
    if sol.success:
        warm = f"warm from {source.workflow}"
        if not both:
            return sol, warm, None
        t1 = time.perf_counter()
        cold = solve()
        times["other_start_s"] = time.perf_counter() - t1
        if cold.success and cold.run_record.objective < sol.run_record.objective:
            return cold, COLD, (warm, sol)
        return sol, warm, (COLD, cold)
    times["warm_attempt_s"] = time.perf_counter() - t0
    times["warm_attempt_ipopt_cpu_s"] = sol.record.solve_cpu_time_s
    failed = sol.run_record
    return solve(), (f"cold: the warm start from {source.workflow} did not succeed (IPOPT status {failed.status} "
                     f"after {failed.iterations} iterations); solved again cold"), None


def _starts_record(sol, start: str, other: tuple, result, rates_of) -> dict:
    """``unit.json`` ``starts`` of a unit solved from both starts (:func:`_chain_solve` with ``both``):
    per start its IPOPT status, iterations and objective, the start kept (the lower objective), the
    objective's relative difference of the other, and per model the relative difference of the other
    solution's whole-body rate from the kept one's (``rates_of(solution)``: its
    :class:`~musclemetab.metabolics.solution.SolutionMetabolics`, as the unit's ``result``), with the
    largest of them (``largest_rate_difference``); a start that did not succeed has no rates."""
    other_start, other_sol = other

    def run(s):
        r = s.run_record
        return {"status": r.status, "iterations": int(r.iterations), "objective": float(r.objective)}

    out = {"kept": start, start: run(sol), other_start: run(other_sol)}
    out["other_objective_difference"] = float(other_sol.run_record.objective / sol.run_record.objective - 1.0)
    if other_sol.success:
        theirs = rates_of(other_sol).whole_body
        diff = {m: float(theirs[m].mean_W_per_kg / result.whole_body[m].mean_W_per_kg - 1.0) for m in result.models}
        out["other_whole_body_difference"] = diff
        out["largest_rate_difference"] = max(abs(v) for v in diff.values())
    return out


def _plausibility(study: Study, unit: Unit, sol, result, speed, groups) -> list:
    """The unit's plausibility flags: the solve's (its record) and the metabolic ones (this leg's
    whole-body rate, doubled, against the speed; negative group rates); with the study's
    ``strict`` a flag fails the unit (:class:`~musclemetab.errors.ImplausibleResultError`)."""
    from ..metabolics.plausibility import metabolic_flags
    from ..quality import check_strict

    flags = metabolic_flags({m: result.whole_body[m].mean_W_per_kg for m in result.models}, speed, groups)
    if study.strict:  # the solve's flags were checked after the solve
        check_strict(flags, unit.label)
    return (list(sol.record.flags) if sol is not None else []) + flags

