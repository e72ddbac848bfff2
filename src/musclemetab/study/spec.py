"""Study files: subjects, trials, workflows and metabolic models in one TOML file.

A study file names everything a study needs; paths are relative to the file::

    name = "speeds"
    output = "results"                 # folder for the study's results
    workflows = ["effort-gen", "effort-ten"]
    models = "all"                     # or ["UM10", "BH04", ...]
    basal = "body"                     # whole-body basal rule: body | muscle | none
    basal_coefficient = 1.2            # optional, W/kg: OpenSim's basal_coefficient (body rule:
    basal_exponent = 1.0               #  coefficient * body mass^exponent W; muscle rule: W per kg of muscle)

    [energy_goal]                      # optional: the effort workflows' solves minimise energy too
    model = "UM10"                     # smooth metabolic model (docs/energy_objective.md)
    weight = 1.0                       # weight of the leg's mean rate, W/kg of body mass
    effort_weight = 0.0                # optional: weight of the effort goal (default: the workflow's, 1)

    [uncertainty]                      # optional: uncertainty bands (docs/uncertainty.md)
    samples = 64                       # samples of every trial unit (0: none)
    seed = 1                           # seed of the Sobol' sequence
    priors = "priors.csv"              # optional: rows replacing the package's priors
    sensitivity = true                 # optional: each effort trial unit writes sensitivity.csv
                                       #  (default false; samples may then be left out)
    keep_flagged = false               # optional: bands also from samples with plausibility flags

    [[subjects]]
    name = "sub1"
    model = "data/sub1.osim"
    body_mass_kg = 72.6
    height_m = 1.743                      # optional: without it each muscle's mass comes from the
                                          # model, F0 / specific tension x density x lMo (muscle_mass_rule)
    passive = "data/passiveMoments.mat"   # optional: calibration for effort-cal / effort-ten
    tendon_stiffness = "emg-ten"          # optional, effort-ten: "emg-ten" (the subject's own
                                          # EMG-TEN estimate), a parameters.json, a table
                                          # {soleus = 10.6, ...} or "example" (the example
                                          # subject's estimates); default: literature values
                                          # converted through the model (docs/muscles.md)
    muscle_properties = "muscles.csv"     # optional: per-muscle overrides (docs/muscles.md)
    emg_mapping = "default"               # EMG channel mapping (EMG-TEN, emg_mode): default | authors
    emg_mode = "constrained"              # optional: the effort workflows' solves EMG-informed
                                          # (constrained | driven | tracking), with the trials' emg
    emg_tolerance = 0.01                  # optional: half-width of the EMG band (constrained)
    emg_processing = "envelope"           # optional: the trials' emg files are processed envelopes
                                          # (envelope, default) or raw EMG processed by the package
                                          # (raw: musclemetab.emg.process_raw_emg); a trial may say too;
                                          # a table sets the raw processing, e.g. {band_hz = [10, 450],
                                          # lowpass_hz = 4, order = 4, delay_s = 0.04}
    side = "r"                            # leg to solve: r | l | both (both: each leg over its own
                                          # gait cycle, the legs' rates added; needs 'cycle')
    dofs = ["hip_flexion_r", "knee_angle_r", "ankle_angle_r"]   # optional (r or l): default from the model
    # [subjects.estimate]: a parameter estimation (musclemetab.study.estimation)
    # instead of 'model', a generic model the study scales (docs/lab_data.md):
    # generic_model = "data/gait2392.osim"
    # static = "data/static.trc"          # the static trial (.trc or .c3d)
    # scale_setup = "data/Setup_Scale.xml"  # optional: OpenSim ScaleTool setup
    # marker_set = "data/MarkerSet.xml"   # optional: markers added to the generic model


    [[subjects.trials]]
    name = "normal"
    ik = "data/IK_normal.mot"
    id = "data/ID_normal.sto"
    # instead of 'ik', the trial's markers (.trc or .c3d), IK computed by OpenSim:
    # markers = "data/walk.trc"
    # ik_setup = "data/Setup_IK.xml"      # optional: OpenSim InverseKinematicsTool setup
    # (a .c3d with force plates also gives the ground forces when neither 'id' nor
    #  'external_loads' is given)
    emg = "data/EMG_normal.mot"           # needed by emg-ten and emg_mode
    emg_processing = "raw"                # optional: this trial's emg (default the subject's)
    ultrasound = "data/US_normal.mot"     # optional: fiber lengths (mm) for [subjects.estimate]
    grf = "data/GRF_normal.mot"           # optional: gait events from the vertical force
    grf_column = "ground_force_vy"        # optional
    grf_threshold_N = 20.0                # optional
    external_loads = "data/GRF.xml"       # optional: OpenSim ExternalLoads; without 'id', inverse
                                          # dynamics is computed from it by OpenSim
    cycle = "auto"                        # optional: solve the first gait cycle of the leg inside
                                          # every input file (or N: the N-th)
    # window = "0.6:1.9"                  # optional, instead of 'cycle': solve that window (s), as
                                          # `musclemetab solve --window 0.6:1.9` (or [0.6, 1.9])
    speed_m_per_s = 1.33                  # optional: default from the pelvis in the IK file
    vo2_mL_per_min = 1050.0               # optional calorimetry (or vo2_mL_per_s / vco2_mL_per_s,
    vco2_mL_per_min = 900.0               #  or measured_W_per_kg)
    toe_off_s = 1.29                      # optional event overrides (start_s, toe_off_s, end_s)
    assistance = "data/exo.sto"           # optional: a device torque profile (docs/assistance.md); or a
                                          # table {file = "data/exo.sto", gains = [0.5, 1.0, 1.5]}: the
                                          # trial solved unassisted and once per gain, as the trials
                                          # <name>_assist-<gain> (a study-level [assistance] table of the
                                          # same form applies to every trial without its own)
    # states = "data/states.sto"          # optional: an OpenSim states file of the subject's model
    # controls = "data/controls.sto"      # (and its controls): the trial's rates from them, as
                                          # `musclemetab metabolics --states` gives them; one unit,
                                          # workflow "states", instead of a solve per workflow
    # fiber_velocity = "equilibrium"      # optional, with states: as --fiber-velocity (default
    # muscle_parameters = "package"       # "auto") and --muscle-parameters (default "probes")

Every key is checked: an unknown key, a missing file or a wrong type raises
:class:`~musclemetab.errors.OptionError` or :class:`~musclemetab.errors.InputFileError`
naming the file, the subject, the trial and the key. Subject and trial names become
folder names, so they must be plain names (letters, digits, ``-``, ``_``, ``.``, not
starting with a dot). Every numeric key is checked against :data:`NUMBER_KEYS` (its unit
and the range of physically possible values, e.g. ``body_mass_kg`` 20 to 300 kg, a human
body mass in kilograms); ``cycle`` is ``"auto"`` or a whole number from 1; ``window`` is
``"T0:T1"`` or ``[T0, T1]``, finite times in seconds with T0 before T1 (:func:`check_window`). Rows of
``muscle_properties`` and names in ``dofs`` must name muscles and coordinates of the model.
A study file may hold :data:`MAX_STUDY_FILE_BYTES` bytes, nested :data:`MAX_STUDY_DEPTH` deep.
"""

from __future__ import annotations

import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from ..errors import InputFileError, OptionError
from ..messages import name_list
from ..settings import MAX_ITERATIONS, MESH_FREQUENCY_RANGE_HZ, NUMBER_KEYS, NumberKey, check_number  # noqa: F401

__all__ = ["Study", "Subject", "Trial", "load_study", "study_from_dict", "EMG_TEN", "KNOWN_WORKFLOWS", "BOTH", "strict_study",
           "warm_start_study", "best_start_study", "sensitivity_study"]

EMG_TEN = "emg-ten"
#: ``side = "both"``: the two legs solved as independent problems, their rates added
BOTH = "both"
SIDES = ("r", "l", BOTH)
KNOWN_WORKFLOWS = ("effort-gen", "effort-cal", "effort-ten", EMG_TEN)
BASAL_RULES = ("body", "muscle", "none")
#: Plausible human body mass, kg: outside it the number is in other units (g, lb) or a typo.
BODY_MASS_RANGE_KG = (20.0, 300.0)  # NUMBER_KEYS["body_mass_kg"]
#: Limits of a study file: its size and how deep its tables and lists nest
MAX_STUDY_FILE_BYTES = 1_000_000
MAX_STUDY_DEPTH = 16
_PLAIN_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")


#: ``cycle``: ``"auto"`` or the number (from 1) of the leg's gait cycle
CYCLE_HELP = "\"auto\" or a gait cycle number (1, 2, ...)"


def check_cycle(value, where: str = "", option: str = "'cycle'"):
    """``"auto"`` or a positive whole number; :class:`OptionError` for anything else
    (``1.5``, ``true``, ``0``, ``"2"`` in a study file)."""
    at = f"{where}: " if where else ""
    if value == "auto" or (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
        return value
    raise OptionError(f"{at}{option} must be {CYCLE_HELP}, not {value!r}")


#: ``window``: the solved window, as the command line's ``--window``
WINDOW_HELP = "\"T0:T1\", two finite times in seconds with T0 before T1, e.g. window = \"0.6:1.9\" (or [0.6, 1.9])"


def check_window(value, where: str = "", option: str = "'window'") -> tuple[float, float]:
    """``"T0:T1"`` (read by :func:`musclemetab.redundancy.window.parse_window`, as ``--window``)
    or a two-number array ``[T0, T1]`` -> ``(T0, T1)``; :class:`OptionError` naming ``where`` and
    ``option`` for anything else (``"1.5"``, ``"2:1"``, ``"nan:1"``, ``[1]``, ``true``)."""
    from ..redundancy.window import parse_window

    text = value
    if isinstance(value, list) and len(value) == 2 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        text = f"{float(value[0])!r}:{float(value[1])!r}"
    if isinstance(text, str):
        try:
            return parse_window(text, option)
        except OptionError:
            pass
    at = f"{where}: " if where else ""
    raise OptionError(f"{at}{option} must be {WINDOW_HELP}, not {value!r}")


def check_plain_name(name: str, what: str) -> str:
    """Return ``name`` if it can be used as one folder name; raise :class:`OptionError` otherwise.

    Accepted: letters, digits, ``_``, ``-`` and ``.``, not starting with ``.`` or ``-``,
    at most 100 characters. ``..``, ``/``, ``\\``, absolute paths and hidden names are refused.
    """
    if not isinstance(name, str) or not _PLAIN_NAME.fullmatch(name) or len(name) > 100:
        raise OptionError(
            f"{what} {name!r} is not a plain folder name; use letters, digits, '_', '-' and '.' "
            "(not starting with '.'), without '/' or '..'"
        )
    return name


@dataclass(frozen=True)
class Trial:
    """One gait cycle of a subject: files, speed, events and calorimetry."""

    name: str
    ik: Path
    id: Path | None
    emg: Path | None = None
    grf: Path | None = None
    grf_column: str | None = None
    grf_threshold_N: float = 20.0
    speed_m_per_s: float | None = None
    measured_W_per_kg: float | None = None
    vo2_mL_per_s: float | None = None
    vco2_mL_per_s: float | None = None
    start_s: float | None = None
    toe_off_s: float | None = None
    end_s: float | None = None
    #: OpenSim ExternalLoads file: ground forces for ``cycle`` and, without ``id``, for inverse dynamics
    external_loads: Path | None = None
    #: ``"auto"`` or N: solve that gait cycle of the subject's side (see ``musclemetab.redundancy.window``)
    cycle: str | int | None = None
    #: ``(T0, T1)``: solve that window, s (``--window``; see ``musclemetab.redundancy.window``)
    window: tuple[float, float] | None = None
    #: measured fiber lengths (mm, MuscleRedundancySolver convention) for the subject's estimation
    ultrasound: Path | None = None
    #: the markers the IK is computed from (``ik`` is then the study's own, under ``prepared/``)
    markers: Path | None = None
    ik_setup: Path | None = None
    #: a device torque profile taken off the ID moments (``docs/assistance.md``), times ``assistance_gain``
    assistance: Path | None = None
    assistance_gain: float = 1.0
    #: the unassisted trial this assisted trial is compared with (the same files, no device)
    assisted_from: str | None = None
    #: an OpenSim states file of the subject's model (and its controls): the rates from them, no solve
    states: Path | None = None
    controls: Path | None = None
    #: with ``states``: a compliant-tendon muscle's fiber velocity, ``"auto"``, ``"trajectory"``,
    #: ``"derivative"`` or ``"equilibrium"`` (``--fiber-velocity``; ``None``: the command's default, auto)
    fiber_velocity: str | None = None
    #: with ``states``: the muscle masses of the model's metabolic probes or of the package's tables,
    #: ``"probes"`` or ``"package"`` (``--muscle-parameters``; ``None``: the command's default, probes)
    muscle_parameters: str | None = None

    def files(self) -> dict[str, Path]:
        out = {k: v for k, v in (("ik", self.ik), ("id", self.id), ("emg", self.emg), ("grf", self.grf),
                                 ("external_loads", self.external_loads), ("ultrasound", self.ultrasound),
                                 ("markers", self.markers), ("ik_setup", self.ik_setup),
                                 ("assistance", self.assistance), ("states", self.states),
                                 ("controls", self.controls)) if v}
        if self.external_loads is not None:
            from ..external_loads import read_external_loads

            out["ground_forces"] = read_external_loads(self.external_loads).datafile
        return out


@dataclass(frozen=True)
class Subject:
    """A participant: model, anthropometry, personalisation sources and trials."""

    name: str
    model: Path
    body_mass_kg: float
    #: ``None``: no height; the muscle masses of the metabolic models and of the energy goal come
    #: from the model (``muscle_mass_rule``), the height entering nothing else
    height_m: float | None
    trials: tuple[Trial, ...]
    passive: Path | None = None
    tendon_stiffness: str | Path | Mapping[str, float] | None = None
    emg_mapping: str = "default"
    muscle_properties: Path | None = None
    side: str = "r"
    dofs: tuple[str, ...] | None = None
    #: ``constrained`` | ``driven`` | ``tracking``: the effort workflows' solves are EMG-informed
    emg_mode: str | None = None
    emg_tolerance: float = 0.01
    #: the subject's parameter estimation (:class:`~musclemetab.study.estimation.EstimateSpec`)
    estimate: Any = None
    #: muscles left out of every problem of the subject (``--exclude-muscles``)
    exclude_muscles: tuple[str, ...] = ()
    #: the generic model the study scales to ``static`` (``model`` is then the study's own)
    generic_model: Path | None = None
    static: Path | None = None
    scale_setup: Path | None = None
    marker_set: Path | None = None

    @property
    def sides(self) -> tuple[str, ...]:
        """The legs solved: ``("r", "l")`` for ``side = "both"``, else the one side."""
        return ("r", "l") if self.side == BOTH else (self.side,)

    def trial(self, name: str) -> Trial:
        for t in self.trials:
            if t.name == name:
                return t
        raise OptionError(f"subject '{self.name}' has no trial '{name}'; it has {', '.join(t.name for t in self.trials)}")

    @property
    def uses_emg_ten_estimate(self) -> bool:
        return isinstance(self.tendon_stiffness, str) and self.tendon_stiffness == EMG_TEN


@dataclass(frozen=True)
class Study:
    """A study: subjects × trials × workflows, evaluated with a set of metabolic models."""

    name: str
    subjects: tuple[Subject, ...]
    workflows: tuple[str, ...]
    models: tuple[str, ...]
    output: Path
    basal: str = "body"
    source: Path | None = None
    #: OpenSim's basal_coefficient (W/kg) and basal_exponent
    basal_coefficient: float = 1.2
    basal_exponent: float = 1.0
    settings: dict = field(default_factory=dict)
    #: a unit with a plausibility flag fails (``docs/quality.md``)
    strict: bool = False

    @property
    def warm_start(self) -> bool:
        """Whether a trial's effort solves start from the solve of the workflow before them
        (the study file's ``[solver] warm_start``, default false; ``docs/study.md``)."""
        from ..settings import SWITCH_KEYS

        return bool(self.settings.get("warm_start", SWITCH_KEYS["warm_start"].default))

    @property
    def best_start(self) -> bool:
        """Whether a trial's effort solve that has a workflow before it is solved from both starts,
        static optimisation and that workflow's solution, the lower objective kept (the study
        file's ``[solver] best_start``, default false; ``docs/study.md``, Which optimum)."""
        from ..settings import SWITCH_KEYS

        return bool(self.settings.get("best_start", SWITCH_KEYS["best_start"].default))

    @property
    def sensitivity(self) -> bool:
        """Whether each effort trial unit writes ``sensitivity.csv`` (the study file's
        ``[uncertainty] sensitivity``, default false; ``docs/study.md``)."""
        from ..settings import SWITCH_KEYS

        return bool(self.settings.get("sensitivity", SWITCH_KEYS["sensitivity"].default))

    def subject(self, name: str) -> Subject:
        for s in self.subjects:
            if s.name == name:
                return s
        raise OptionError(f"the study has no subject '{name}'; it has {', '.join(s.name for s in self.subjects)}")


# ---------------------------------------------------------------------------------------
_STUDY_KEYS = {"name", "output", "workflows", "models", "basal", "basal_coefficient", "basal_exponent", "subjects",
               "solver", "energy_goal", "strict", "uncertainty", "report", "assistance"}
#: keys of an ``assistance`` table (of a trial, or of the study: every trial's)
_ASSISTANCE_KEYS = {"file", "gain", "gains"}
#: keys of the study file's [energy_goal] table (the energy goal of every effort-workflow solve)
_ENERGY_KEYS = {"model", "weight", "effort_weight", "smoothing", "form"}
#: keys of the study file's [uncertainty] table (docs/uncertainty.md)
_UNCERTAINTY_KEYS = {"samples", "seed", "priors", "sensitivity", "keep_flagged"}
#: keys of the study file's [solver] table (IPOPT settings of every solve)
_SOLVER_KEYS = {"max_iter", "tol", "stop", "linear_solver", "warm_start", "best_start"}
#: the [solver] keys that say how the solves start, not IPOPT settings: kept beside [solver]
_START_KEYS = ("warm_start", "best_start")
_SUBJECT_KEYS = {"name", "model", "body_mass_kg", "height_m", "passive", "tendon_stiffness", "emg_mapping", "trials",
                 "muscle_properties", "side", "dofs", "emg_mode", "emg_tolerance", "estimate", "exclude_muscles",
                 "emg_processing", "generic_model", "static", "scale_setup", "marker_set"}
#: subject keys of a generic model the study scales
_SCALING_KEYS = ("static", "scale_setup", "marker_set")
_TRIAL_KEYS = {
    "name", "ik", "id", "emg", "grf", "grf_column", "grf_threshold_N", "speed_m_per_s",
    "measured_W_per_kg", "vo2_mL_per_s", "vco2_mL_per_s", "vo2_mL_per_min", "vco2_mL_per_min",
    "start_s", "toe_off_s", "end_s", "external_loads", "cycle", "window", "ultrasound", "emg_processing", "markers", "ik_setup",
    "assistance", "states", "controls", "fiber_velocity", "muscle_parameters",
}
#: the keys of a trial with ``states`` only: ``musclemetab metabolics --states``'s options
_STATES_KEYS = ("fiber_velocity", "muscle_parameters")
#: the workflow of a trial whose rates come from an OpenSim states file (its ``states`` key)
STATES = "states"


def load_study(path: str | os.PathLike, *, output: str | os.PathLike | None = None) -> Study:
    """Read and check a study file (TOML). ``output`` overrides the file's ``output``."""
    path = Path(path)
    if path.is_dir():
        inside = sorted(p.name for p in path.glob("*.toml"))
        raise InputFileError(f"{path} is a folder; give the study file itself"
                             + (f" ({', '.join(str(path / n) for n in inside[:3])})" if inside else ", a .toml file")
                             + (": the study's output folder is read by 'musclemetab report'"
                                if (path / "study.json").is_file() else ""))
    if not path.is_file():
        raise InputFileError(f"study file {path} not found; give the path of a .toml study file")
    size = path.stat().st_size
    if size > MAX_STUDY_FILE_BYTES:
        raise InputFileError(f"{path}: {size} bytes, more than a study file may hold ({MAX_STUDY_FILE_BYTES} bytes); "
                             "give the study file, not a data file")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))  # a byte-order mark (Windows editors) is no TOML
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputFileError(f"{path}: not a valid TOML file ({exc}); fix the syntax at the position given") from None
    except RecursionError:
        data = None
    if data is None or _depth(data) > MAX_STUDY_DEPTH:
        raise InputFileError(f"{path}: tables or lists nested more than {MAX_STUDY_DEPTH} deep, more than a study "
                             "file has; check the file")
    return study_from_dict(data, base=path.parent, source=path, output=output)


def _depth(data) -> int:
    """How deep tables and lists nest in ``data`` (a scalar is 0), without recursion."""
    deepest, stack = 0, [(data, 0)]
    while stack:
        value, level = stack.pop()
        if isinstance(value, Mapping):
            value = list(value.values())
        if isinstance(value, list):
            level += 1
            deepest = max(deepest, level)
            if level > MAX_STUDY_DEPTH:
                return level
            stack.extend((v, level) for v in value)
    return deepest


def study_from_dict(data: Mapping[str, Any], *, base: str | os.PathLike = ".", source: Path | None = None,
                    output: str | os.PathLike | None = None) -> Study:
    """Build a :class:`Study` from a mapping with the structure of a study file."""
    where = str(source) if source else "study"
    base = Path(base)
    _unknown(data, _STUDY_KEYS, where)
    solver_table = data.get("solver")
    if isinstance(solver_table, Mapping) and "linear_solver_library" in solver_table:  # before anything is read
        from ..redundancy.ipopt import LIBRARY_ENV

        raise OptionError(f"{where}: [solver] linear_solver_library: a study file names a linear solver, not a library "
                          "to load (a library is native code); remove the key and give the library's path in the "
                          f"environment variable {LIBRARY_ENV} (for one solve: musclemetab solve "
                          "--linear-solver-library LIB)")
    from ..metabolics.registry import parse_models
    from ..metabolics._common import BASAL_RATE_W_PER_KG

    name = str(data.get("name", source.stem if source else "study"))
    workflows = data.get("workflows", ["effort-gen", "effort-ten"])
    if isinstance(workflows, str):
        workflows = [workflows]
    if not isinstance(workflows, (list, tuple)) or not all(isinstance(w, str) for w in workflows):
        raise OptionError(f"{where}: 'workflows' must be a list of workflow names such as "
                          f"[\"effort-gen\", \"effort-ten\"], not {workflows!r}; choose from {', '.join(KNOWN_WORKFLOWS)}")
    workflows = tuple(str(w).strip().lower().replace("_", "-") for w in workflows)
    bad = [w for w in workflows if w not in KNOWN_WORKFLOWS]
    if bad or not workflows:
        raise OptionError(f"{where}: 'workflows' has unknown workflow(s) {bad or '[]'}; choose from {', '.join(KNOWN_WORKFLOWS)}")
    models_value = data.get("models", "all")
    if not isinstance(models_value, str) and not (
            isinstance(models_value, (list, tuple)) and all(isinstance(m, str) for m in models_value)):
        raise OptionError(f"{where}: 'models' must be \"all\" or a list of model names such as "
                          f"[\"UM10\", \"BH04\"], not {models_value!r}")
    try:
        models = tuple(parse_models(models_value))
    except OptionError as exc:
        raise OptionError(f"{where}: 'models': {exc}") from None
    basal = str(data.get("basal", "body"))
    if basal not in BASAL_RULES:
        raise OptionError(f"{where}: 'basal' must be one of {', '.join(BASAL_RULES)}, not {basal!r}")
    basal_coefficient = _number(data.get("basal_coefficient", BASAL_RATE_W_PER_KG), where, "basal_coefficient")
    basal_exponent = _number(data.get("basal_exponent", 1.0), where, "basal_exponent")
    if basal == "muscle" and basal_exponent != 1:
        raise OptionError(f"{where}: 'basal_exponent' applies to basal = \"body\" only (the muscle rule is linear "
                          "in each muscle's mass); remove it or set basal = \"body\"")
    out_value = data.get("output", "results")
    if output is None and (not isinstance(out_value, str) or not out_value.strip()):
        raise OptionError(f"{where}: 'output' must be a folder path (text), not {out_value!r}")
    out = Path(output) if output is not None else base / out_value
    subjects_data = data.get("subjects")
    if not isinstance(subjects_data, list) or not subjects_data:
        raise OptionError(f"{where}: no subjects; add at least one [[subjects]] table with its [[subjects.trials]]")
    assistance = _assistance(data.get("assistance"), base, f"{where}: [assistance]")
    subjects = tuple(_subject(s, base, where, workflows, assistance) for s in subjects_data)
    names = [s.name for s in subjects]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise OptionError(f"{where}: subject name(s) {name_list(dup)} used more than once; names must be unique")
    settings = {"name": name, "workflows": list(workflows), "models": list(models), "basal": basal}
    if "basal_coefficient" in data or "basal_exponent" in data:
        settings.update(basal_coefficient=basal_coefficient, basal_exponent=basal_exponent)
    solver = _solver(data.get("solver"), where)
    for key in _START_KEYS:  # how the solves start, not IPOPT settings: kept beside [solver]
        if key in solver:
            settings[key] = solver.pop(key)
    if solver:
        settings["solver"] = solver
    energy = _energy_goal(data.get("energy_goal"), where)
    if energy:
        settings["energy_goal"] = energy
    if _sensitivity(data.get("uncertainty"), where):  # [uncertainty] sensitivity = true
        settings["sensitivity"] = True
    uncertainty = _uncertainty(data.get("uncertainty"), base, where)
    if uncertainty:  # [uncertainty]: samples of every trial unit (musclemetab.study.uncertainty)
        settings["uncertainty"] = uncertainty
    report = _report(data.get("report"), where)
    if report:  # [report] models: the report's figures (docs/report.md)
        settings["report"] = report
    strict = data.get("strict", False)
    if not isinstance(strict, bool):
        raise OptionError(f"{where}: 'strict' must be true or false, not {strict!r}")
    if strict:
        settings["strict"] = True
    subjects = tuple(_planned_files(s, out) for s in subjects)
    return Study(name=name, subjects=subjects, workflows=workflows, models=models, output=out,
                 basal=basal, source=source, settings=settings, basal_coefficient=basal_coefficient,
                 basal_exponent=basal_exponent, strict=strict)


def _planned_files(subject: Subject, out: Path) -> Subject:
    """The subject with the files the study makes from markers named where they will be
    (``prepared/`` in the study folder, :func:`musclemetab.study.lab.prepare_study`): the scaled
    model, each trial's IK, a C3D trial's ExternalLoads."""
    from dataclasses import replace

    from ..study_layout import prepared_path

    if subject.generic_model is None and not any(t.markers for t in subject.trials):
        return subject
    trials = []
    for t in subject.trials:
        if t.markers is not None:
            folder = out / prepared_path(subject.name, t.name)
            loads = t.external_loads
            if loads is None and t.id is None and t.grf is None:
                loads = folder / "markers_grf.xml"  # from the C3D's force plates (checked by _trial)
            t = replace(t, ik=folder / "ik.mot", external_loads=loads)
        trials.append(t)
    model = out / prepared_path(subject.name) / "model.osim" if subject.generic_model is not None else subject.model
    return replace(subject, model=model, trials=tuple(trials))


def strict_study(study: Study) -> Study:
    """``study`` with strict plausibility checking (``--strict``: the study file's ``strict = true``)."""
    from dataclasses import replace

    return replace(study, strict=True, settings={**study.settings, "strict": True})


def best_start_study(study: Study, best_start: bool) -> Study:
    """``study`` with each chained effort solve solved from both starts, the lower objective kept
    (``--best-start``: the study file's ``[solver] best_start = true``)."""
    from dataclasses import replace

    return replace(study, settings={**study.settings, "best_start": bool(best_start)})


def warm_start_study(study: Study, warm_start: bool) -> Study:
    """``study`` with warm-started chains on or off (``--warm-start``/``--cold-start``: the study
    file's ``[solver] warm_start = true|false``)."""
    from dataclasses import replace

    return replace(study, settings={**study.settings, "warm_start": bool(warm_start)})


def _solver(data, where: str) -> dict:
    """The ``[solver]`` table: ``max_iter``, ``tol``, ``stop``, ``linear_solver``, ``warm_start`` and ``best_start``, checked (the
    library of a run-time linear solver comes from the command line or the environment, never from the file)."""
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        raise OptionError(f"{where}: 'solver' must be a table such as [solver] max_iter = 3000")
    weights = sorted(k for k in data if str(k).startswith("w_"))
    if weights:
        raise OptionError(f"{where}: [solver] {', '.join(weights)}: [solver] holds numerical settings only "
                          f"({', '.join(sorted(_SOLVER_KEYS))}); the objective's weights are the workflow's: give the "
                          "effort weight beside an energy goal as [energy_goal] effort_weight and an estimation's "
                          "weights as [subjects.estimate] weights (docs/study.md)")
    _unknown(data, _SOLVER_KEYS, f"{where}: [solver]")
    for key in ("max_iter", "tol"):
        if key in data:
            _number(data[key], f"{where}: [solver]", key)
    for key in _START_KEYS:
        if key in data:
            from ..settings import check_switch

            check_switch(key, data[key], f"{where}: [solver]")
    from ..redundancy import SolverOptions

    try:
        SolverOptions(**{k: v for k, v in data.items() if k not in _START_KEYS})
    except (TypeError, ValueError, OptionError) as exc:
        raise OptionError(f"{where}: [solver]: {exc}") from None
    return dict(data)


def _energy_goal(data, where: str) -> dict:
    """The ``[energy_goal]`` table: ``model`` (required), ``weight`` (1), ``effort_weight`` (the
    workflow's), ``smoothing``; checked with a plausible subject."""
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        raise OptionError(f"{where}: 'energy_goal' must be a table such as [energy_goal] model = \"UM10\"")
    here = f"{where}: [energy_goal]"
    _unknown(data, _ENERGY_KEYS, here)
    if "model" not in data:
        raise OptionError(f"{here}: 'model' is required (a metabolic model such as \"UM10\")")
    for key in ("weight", "effort_weight", "smoothing"):
        if key in data:
            _number(data[key], here, key)
    from ..redundancy.energy import CLAMPED_MODELS, EnergyGoal

    try:
        goal = EnergyGoal(str(data["model"]), float(data.get("weight", 1.0)), 70.0, 1.75,
                          effort_weight=data.get("effort_weight"),
                          **({"smoothing": float(data["smoothing"])} if "smoothing" in data else {}),
                          **({"form": str(data["form"])} if "form" in data else {}))
    except OptionError as exc:
        raise OptionError(f"{here}: {exc}") from None
    out = {"model": goal.model, "weight": goal.weight, "smoothing": goal.smoothing}
    if "form" in data or goal.model in CLAMPED_MODELS:  # the form changes what these models' goals minimise
        out["form"] = goal.form
    if goal.effort_weight is not None:
        out["effort_weight"] = float(goal.effort_weight)
    return out


def _sensitivity(data, where: str) -> bool:
    """The ``[uncertainty]`` table's ``sensitivity`` switch, checked (false when absent)."""
    if not isinstance(data, Mapping) or "sensitivity" not in data:
        return False
    from ..settings import check_switch

    return check_switch("sensitivity", data["sensitivity"], f"{where}: [uncertainty]")


def sensitivity_study(study: Study, sensitivity: bool) -> Study:
    """``study`` with the sensitivities of its effort trial units on or off (``--sensitivity``: the
    study file's ``[uncertainty] sensitivity = true``)."""
    from dataclasses import replace

    settings = {k: v for k, v in study.settings.items() if k != "sensitivity"}
    return replace(study, settings={**settings, "sensitivity": True} if sensitivity else settings)


def _report(data, where: str) -> dict:
    """The ``[report]`` table checked: ``{"models": ...}`` (the metabolic models of the report's
    figures, as its ``--models`` takes them: ``"all,LW05"`` or a list); ``{}`` for none."""
    if data is None:
        return {}
    here = f"{where}: [report]"
    if not isinstance(data, Mapping):
        raise OptionError(f"{where}: 'report' must be a table such as [report] models = [\"all\", \"LW05\"]")
    _unknown(data, {"models"}, here)
    models = data.get("models")
    if models is None:
        return {}
    if not (isinstance(models, str) or (isinstance(models, list) and all(isinstance(m, str) for m in models))):
        raise OptionError(f"{here}: 'models' must be a list of model names such as [\"all\", \"LW05\"], not {models!r}")
    from ..errors import MusclemetabError
    from ..metabolics.registry import parse_models

    try:
        parse_models(models)
    except MusclemetabError as exc:
        raise OptionError(f"{here}: models: {exc}") from None
    return {"models": models if isinstance(models, str) else list(models)}


def _uncertainty(data, base: Path, where: str) -> dict:
    """The ``[uncertainty]`` table checked: ``{"samples", "seed"[, "priors", "keep_flagged"]}`` (``{}`` for none or 0 samples;
    its ``sensitivity`` switch: :func:`_sensitivity`)."""
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        raise OptionError(f"{where}: 'uncertainty' must be a table such as [uncertainty] samples = 64, seed = 1")
    here = f"{where}: [uncertainty]"
    _unknown(data, _UNCERTAINTY_KEYS, here)
    if "sensitivity" in data and set(data) <= {"sensitivity"}:
        return {}  # the sensitivities alone: no samples
    if "samples" not in data:
        raise OptionError(f"{here}: 'samples' is required (the number of samples of every trial unit, e.g. 64)")
    from ..uncertainty import DEFAULT_SEED, read_priors

    out = {"samples": _number(data["samples"], here, "samples"), "seed": _number(data.get("seed", DEFAULT_SEED),
                                                                                here, "seed")}
    priors = _path(data.get("priors"), base, here, "priors", required=False)
    if priors is not None:
        read_priors(priors)  # checked now, before anything runs
        out["priors"] = str(priors)
    if "keep_flagged" in data:
        from ..settings import check_switch

        out["keep_flagged"] = check_switch("keep_flagged", data["keep_flagged"], here)
    return out if out["samples"] else {}


def _unknown(data: Mapping, allowed: set, where: str) -> None:
    if not isinstance(data, Mapping):
        raise OptionError(f"{where}: expected a table, got {type(data).__name__}")
    extra = sorted(set(data) - allowed)
    if extra:
        raise OptionError(f"{where}: unknown key(s) {name_list(extra)}; allowed: {', '.join(sorted(allowed))}")


def _path(value, base: Path, where: str, key: str, required: bool = True) -> Path | None:
    if value is None:
        if required:
            raise OptionError(f"{where}: '{key}' is required (a file path)")
        return None
    if not isinstance(value, str) or not value.strip():
        raise OptionError(f"{where}: '{key}' must be a file path (text), not {value!r}")
    p = Path(value)
    p = p if p.is_absolute() else base / p
    if p.is_dir():
        raise InputFileError(f"{where}: '{key}' is the folder {p}, not a file; give the path of the file in it")
    if not p.is_file():
        raise InputFileError(f"{where}: '{key}' file {p} not found; check the path (relative to the study file)")
    return p.resolve()


def _number(value, where: str, key: str, required: bool = False, table_key: str | None = None) -> float | None:
    """The value of the numeric key ``key`` checked by :data:`NUMBER_KEYS` (``table_key``: its
    entry there when the key's name differs, e.g. ``tendon_stiffness.soleus``)."""
    if value is None:
        if required:
            entry = NUMBER_KEYS[table_key or key]
            raise OptionError(f"{where}: '{key}' is required ({entry.help}, {entry.range_text()})")
        return None
    entry = NUMBER_KEYS[table_key or key]
    if table_key:
        entry = NumberKey(key, entry.unit, entry.low, entry.high, entry.help, entry.low_open, entry.integer)
    return entry.check(value, where)


def _subject(data, base: Path, where: str, workflows, assistance=None) -> Subject:
    name = str(data.get("name", "")) if isinstance(data, Mapping) else ""
    here = f"{where}: subject '{name or '?'}'"
    _unknown(data, _SUBJECT_KEYS, here)
    if not name:
        raise OptionError(f"{here}: 'name' is required")
    check_plain_name(name, f"{where}: subject name")
    generic = _path(data.get("generic_model"), base, here, "generic_model", required=False)
    if generic is not None:
        if data.get("model") is not None:
            raise OptionError(f"{here}: give 'model' (a model of the subject) or 'generic_model' with 'static' (scaled "
                              "by the study), not both")
        scaling = {k: _path(data.get(k), base, here, k, required=k == "static") for k in _SCALING_KEYS}
        if scaling["scale_setup"] is not None:
            _check_setup(scaling["scale_setup"], "ScaleTool", here)
        model = None
    else:
        given = [k for k in _SCALING_KEYS if data.get(k) is not None]
        if given:
            raise OptionError(f"{here}: {', '.join(repr(k) for k in given)} scale a 'generic_model'; add it (and drop "
                              "'model'), or drop them")
        scaling = {}
        model = _path(data.get("model"), base, here, "model")
    mass = _number(data.get("body_mass_kg"), here, "body_mass_kg", required=True)
    height = _number(data.get("height_m"), here, "height_m")  # optional: the muscle masses from the model
    passive = _path(data.get("passive"), base, here, "passive", required=False)
    kt = data.get("tendon_stiffness")
    if isinstance(kt, str):
        if kt.strip().lower() == EMG_TEN:
            kt = EMG_TEN
        elif kt.strip().lower() == "example":
            kt = "example"
        else:
            kt = _path(kt, base, here, "tendon_stiffness")
    elif isinstance(kt, Mapping):
        kt = {str(k): _number(v, here, f"tendon_stiffness.{k}", required=True, table_key="tendon_stiffness")
              for k, v in kt.items()}
    elif kt is not None:
        raise OptionError(f"{here}: 'tendon_stiffness' must be \"emg-ten\", \"example\", a parameters.json path or a table")
    mapping = str(data.get("emg_mapping", "default"))
    if mapping not in ("default", "authors"):
        raise OptionError(f"{here}: 'emg_mapping' must be default or authors, not {mapping!r}")
    side = data.get("side", "r")
    if side not in SIDES:
        raise OptionError(f"{here}: 'side' must be \"r\", \"l\" or \"both\", not {side!r}")
    dofs = data.get("dofs")
    if dofs is not None:
        if side == BOTH:
            raise OptionError(f"{here}: 'dofs' names one leg's DOFs; with side = \"both\" leave it out (each leg's "
                              "DOFs are discovered from the model), or list each leg as its own subject")
        if not isinstance(dofs, list) or not dofs or not all(isinstance(d, str) and d for d in dofs):
            raise OptionError(f"{here}: 'dofs' must be a list of coordinate names, e.g. [\"knee_angle_l\"]")
        dofs = tuple(dofs)
    excluded = data.get("exclude_muscles", [])
    if not isinstance(excluded, list) or not all(isinstance(m, str) and m for m in excluded):
        raise OptionError(f"{here}: 'exclude_muscles' must be a list of muscle names, e.g. [\"tfl_r\"]")
    trials_data = data.get("trials")
    if not isinstance(trials_data, list) or not trials_data:
        raise OptionError(f"{here}: no trials; add [[subjects.trials]] tables with name, ik and id")
    processing = _emg_processing(data, here, "envelope")
    trials = tuple(a for t in trials_data for a in _assisted_trials(_trial(t, base, here, processing), t, base, here,
                                                                    assistance))
    if any(t.assistance is not None for t in trials):
        _check_assisted_subject(data, here, workflows)
        _check_profiles(trials, side, mass, dofs, here)
    names = [t.name for t in trials]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise OptionError(f"{here}: trial name(s) {name_list(dup)} used more than once")
    if EMG_TEN in workflows or kt == EMG_TEN:
        missing = [t.name for t in trials if t.emg is None]
        if missing:
            raise OptionError(f"{here}: the emg-ten workflow needs an 'emg' file for every trial; missing for "
                              f"{name_list(missing)}")
        windowed = [t.name for t in trials if t.window is not None]
        if windowed:
            what = "the emg-ten workflow" if EMG_TEN in workflows else "tendon_stiffness = \"emg-ten\""
            raise OptionError(f"{here}: {what} needs the subject's EMG-TEN estimation, which solves every trial over "
                              f"its whole IK file, so a 'window' cannot apply to it; trial(s) {name_list(windowed)} "
                              "set 'window': drop it, or put the windowed trials in a subject of their own without "
                              "emg-ten (tendon_stiffness may name the estimate's parameters.json)")
    emg_mode, emg_tolerance = _emg_mode(data, here, trials)
    muscle_properties = _path(data.get("muscle_properties"), base, here, "muscle_properties", required=False)
    if muscle_properties is not None or dofs is not None or excluded:
        _check_model_names(model or generic, here, muscle_properties, dofs, excluded)  # scaling keeps the names
    if side == BOTH:
        _check_both_legs(data, here, trials, workflows, kt)
    subject = Subject(name=name, model=model, body_mass_kg=mass, height_m=height, trials=trials,
                      passive=passive, tendon_stiffness=kt, emg_mapping=mapping, muscle_properties=muscle_properties,
                      side=side, dofs=dofs, emg_mode=emg_mode, emg_tolerance=emg_tolerance,
                      exclude_muscles=tuple(excluded), generic_model=generic, **scaling)
    if data.get("estimate") is not None:
        from dataclasses import replace

        from .estimation import estimate_spec, estimation_trials

        subject = replace(subject, estimate=estimate_spec(data["estimate"], here))
        estimation_trials(subject, here)
    return subject


def _check_model_names(model: Path, here: str, muscle_properties: Path | None, dofs, excluded=()) -> None:
    """Refuse, before anything runs, muscle-properties rows, ``dofs`` and ``exclude_muscles``
    that name nothing in the model."""
    import difflib

    from ..errors import UnknownCoordinateError, UnknownMuscleError
    from ..model import read_model
    from ..properties import read_muscle_properties

    overrides = read_muscle_properties(muscle_properties) if muscle_properties is not None else None
    info = read_model(model)
    if overrides is not None:
        try:
            overrides.check_names(info.muscles.names)
        except UnknownMuscleError as exc:
            raise UnknownMuscleError(f"{here}: 'muscle_properties': {exc} of {model}") from None
    alien = [m for m in excluded if m not in info.muscles.names]
    if alien:
        raise UnknownMuscleError(f"{here}: 'exclude_muscles' {', '.join(alien)} not a muscle of {model}; fix the name")
    coordinates = [c["name"] if isinstance(c, Mapping) else c for c in info.coordinates]
    unknown = [d for d in dofs or () if d not in coordinates]
    if unknown:
        near = {d: difflib.get_close_matches(d, coordinates, n=3, cutoff=0.6) for d in unknown}
        listed = "; ".join(f"'{d}'" + (f" (near: {', '.join(m)})" if m else "") for d, m in near.items())
        raise UnknownCoordinateError(f"{here}: 'dofs' {listed} not a coordinate of {model}; fix the name")


def _check_both_legs(data, here: str, trials, workflows, kt) -> None:
    """What ``side = "both"`` needs: each leg's own gait cycle, and no single-leg settings."""
    one_leg = [k for k in ("emg_mode", "estimate") if data.get(k) is not None]
    if EMG_TEN in workflows or kt == EMG_TEN:
        one_leg.append("the emg-ten workflow" if EMG_TEN in workflows else "tendon_stiffness = \"emg-ten\"")
    if one_leg:
        raise OptionError(f"{here}: side = \"both\" solves effort workflows only; {', '.join(one_leg)} use one leg's "
                          "EMG: list each leg as its own subject (side = \"r\" and side = \"l\") for them")
    for t in trials:
        events = [k for k in ("start_s", "toe_off_s", "end_s", "grf_column") if getattr(t, k) is not None]
        if events:
            raise OptionError(f"{here}, trial '{t.name}': {', '.join(events)} belong{'s' if len(events) == 1 else ''} "
                              "to one leg; with side = \"both\" drop "
                              f"{'it' if len(events) == 1 else 'them'} (each leg's gait cycle is found by 'cycle')")
    missing = [t.name for t in trials if t.cycle is None and t.window is None]
    if missing:
        raise OptionError(f"{here}: side = \"both\" solves each leg over its own gait cycle; set cycle = \"auto\" in "
                          f"trial(s) {name_list(missing)} (heel strike to heel strike of each leg, from the ground "
                          "forces of 'external_loads' or 'grf', or from the kinematics without them), or a "
                          "window = \"T0:T1\" that both legs are solved over")


#: the study keys of OpenSim's setups, by the tool each holds
SETUP_KEYS = {"ScaleTool": "'scale_setup'", "InverseKinematicsTool": "'ik_setup'"}


def _check_setup(path: Path | None, tool: str, here: str) -> Path | None:
    """``path``, a setup that holds OpenSim's ``tool`` (a setup of the other tool, or no setup,
    refused when the study file is read, naming ``here`` and the key)."""
    if path is not None:
        from ..mocap.scaling import setup_files

        try:
            setup_files(path, tool, names=SETUP_KEYS)
        except InputFileError as exc:
            raise InputFileError(f"{here}: {exc}") from None
    return path


def _emg_mode(data, here: str, trials) -> tuple[str | None, float]:
    """The subject's ``emg_mode`` and ``emg_tolerance``, checked against its trials."""
    mode = data.get("emg_mode")
    tol = _number(data.get("emg_tolerance"), here, "emg_tolerance")
    if mode is None:
        if tol is not None:
            raise OptionError(f"{here}: 'emg_tolerance' needs 'emg_mode' (constrained); set it or drop the tolerance")
        return None, 0.01
    from ..redundancy._checks import EMG_MODES

    if mode not in EMG_MODES:
        raise OptionError(f"{here}: 'emg_mode' must be one of {', '.join(EMG_MODES)}, not {mode!r}")
    missing = [t.name for t in trials if t.emg is None]
    if missing:
        raise OptionError(f"{here}: 'emg_mode' needs an 'emg' file for every trial; missing for {name_list(missing)}")
    bad = [t.name for t in trials if t.id is None or t.cycle is not None or t.window is not None]
    if bad:
        raise OptionError(f"{here}: an EMG-informed solve covers the whole IK window with the trial's 'id' file; "
                          f"trial(s) {name_list(bad)} have no 'id' or set 'cycle' or 'window' (drop 'cycle' and "
                          "'window', or 'emg_mode')")
    return mode, 0.01 if tol is None else tol


def _emg_processing(data, here: str, default):
    """The ``emg_processing`` key (``envelope``, ``raw``, or a table of raw-EMG settings:
    :class:`~musclemetab.emg.EmgProcessing`; ``default`` when absent)."""
    from ..emg import EMG_PROCESSING, EmgProcessing

    value = data.get("emg_processing", default) if isinstance(data, Mapping) else default
    if isinstance(value, Mapping):
        return EmgProcessing.from_record(value, f"{here}: 'emg_processing'")
    if value not in EMG_PROCESSING and not isinstance(value, EmgProcessing):
        raise OptionError(f"{here}: 'emg_processing' must be {' or '.join(EMG_PROCESSING)} or a table of raw-EMG "
                          f"settings (band_hz, lowpass_hz, order, maximum, delay_s), not {value!r}")
    return value


def _trial(data, base: Path, where: str, emg_processing="envelope") -> Trial:
    from ..emg import emg_source

    name = str(data.get("name", "")) if isinstance(data, Mapping) else ""
    here = f"{where}, trial '{name or '?'}'"
    _unknown(data, _TRIAL_KEYS, here)
    if not name:
        raise OptionError(f"{here}: 'name' is required")
    check_plain_name(name, f"{where}: trial name")
    num = {k: _number(data.get(k), here, k) for k in _TRIAL_KEYS if k.endswith(("_s", "_per_s", "_per_min", "_per_kg", "_N"))}
    vo2, vco2 = num["vo2_mL_per_s"], num["vco2_mL_per_s"]
    if num["vo2_mL_per_min"] is not None:
        vo2 = num["vo2_mL_per_min"] / 60.0
    if num["vco2_mL_per_min"] is not None:
        vco2 = num["vco2_mL_per_min"] / 60.0
    if (vo2 is None) != (vco2 is None):
        raise OptionError(f"{here}: give both VO2 and VCO2 (Brockway's equation needs both)")
    forces = [k for k in ("grf", "grf_column") if data.get(k) is not None]
    if data.get("external_loads") is not None and forces:
        raise OptionError(
            f"{here}: 'external_loads' and {' and '.join(repr(k) for k in forces)} both give the ground forces, and "
            f"{'it' if len(forces) == 1 else 'they'} would be ignored; keep 'external_loads' or 'grf' (with "
            "'grf_column'), not both"
        )
    markers = _path(data.get("markers"), base, here, "markers", required=False)
    if markers is not None and data.get("ik") is not None:
        raise OptionError(f"{here}: give 'ik' or 'markers' (IK computed by the study), not both")
    if markers is None and data.get("ik_setup") is not None:
        raise OptionError(f"{here}: 'ik_setup' needs 'markers'; add the trial's markers or drop it")
    c3d_forces = markers is not None and markers.suffix.lower() == ".c3d" and data.get("grf") is None
    states = _path(data.get("states"), base, here, "states", required=False)
    if states is None and data.get("controls") is not None:
        raise OptionError(f"{here}: 'controls' goes with 'states' (an OpenSim states file); add it or drop 'controls'")
    if states is not None and data.get("assistance") is not None:
        raise OptionError(f"{here}: 'states' gives the trial's muscle states, and 'assistance' needs a solve; "
                          "drop one of them")
    states_options = _states_options(data, states is not None, here)
    cycle = _cycle_key(data.get("cycle"), here)
    window = None if data.get("window") is None else check_window(data["window"], here)
    if window is not None and cycle is not None:
        raise OptionError(f"{here}: give 'window' (the times to solve) or 'cycle' (a gait cycle found from the "
                          "events), not both, as musclemetab solve takes --window or --cycle; drop one of them")
    if window is not None and states is not None:
        raise OptionError(f"{here}: 'states' gives the trial's muscle states, and 'window' the times of a solve; "
                          "drop one of them")
    return Trial(
        name=name,
        ik=_path(data.get("ik"), base, here, "ik") if markers is None else None,
        id=_path(data.get("id"), base, here, "id", required=data.get("external_loads") is None and not c3d_forces
                 and states is None),
        emg=emg_source(_path(data.get("emg"), base, here, "emg", required=False),
                       _emg_processing(data, here, emg_processing)),
        grf=_path(data.get("grf"), base, here, "grf", required=False),
        grf_column=data.get("grf_column"),
        grf_threshold_N=num["grf_threshold_N"] if num["grf_threshold_N"] is not None else 20.0,
        speed_m_per_s=num["speed_m_per_s"],
        measured_W_per_kg=num["measured_W_per_kg"],
        vo2_mL_per_s=vo2,
        vco2_mL_per_s=vco2,
        start_s=num["start_s"],
        toe_off_s=num["toe_off_s"],
        end_s=num["end_s"],
        external_loads=_path(data.get("external_loads"), base, here, "external_loads", required=False),
        cycle=cycle,
        window=window,
        ultrasound=_path(data.get("ultrasound"), base, here, "ultrasound", required=False),
        markers=markers,
        ik_setup=_check_setup(_path(data.get("ik_setup"), base, here, "ik_setup", required=False),
                              "InverseKinematicsTool", here),
        states=states,
        controls=_path(data.get("controls"), base, here, "controls", required=False),
        **states_options,
    )


def _states_options(data: Mapping, has_states: bool, here: str) -> dict:
    """A trial's ``fiber_velocity`` and ``muscle_parameters`` (the options of ``musclemetab
    metabolics --states``), checked: they go with ``states``."""
    from ..metabolics.opensim_states import FIBER_VELOCITY_SOURCES, MUSCLE_PARAMETER_SOURCES
    from ..redundancy._checks import check_option

    given = {k: data[k] for k in _STATES_KEYS if data.get(k) is not None}
    if given and not has_states:
        raise OptionError(f"{here}: {' and '.join(repr(k) for k in given)} {'go' if len(given) > 1 else 'goes'} "
                          "with 'states' (the rates of an OpenSim states file, as musclemetab metabolics --states "
                          "takes them); a solved trial's fiber velocity and muscle masses are the solve's: drop "
                          f"{'them' if len(given) > 1 else 'it'}")
    for key, allowed in (("fiber_velocity", FIBER_VELOCITY_SOURCES), ("muscle_parameters", MUSCLE_PARAMETER_SOURCES)):
        if key in given:
            check_option(f"{here}: {key}", given[key], allowed)
    return given


def _assistance(value, base: Path, here: str) -> tuple[Path, tuple[float, ...]] | None:
    """An ``assistance`` key: a profile's path (gain 1) or a table ``{file, gain}`` or ``{file,
    gains = [...]}``; ``(path, gains)`` or ``None``."""
    from ..redundancy.assistance import check_gain, read_assistance

    if value is None:
        return None
    if isinstance(value, str):
        path, gains = _path(value, base, here, "assistance"), (1.0,)
    elif isinstance(value, Mapping):
        _unknown(value, _ASSISTANCE_KEYS, here)
        path = _path(value.get("file"), base, here, "assistance.file")
        if "gain" in value and "gains" in value:
            raise OptionError(f"{here}: give 'gain' (one solve) or 'gains' (a sweep), not both")
        gains = value.get("gains", [value.get("gain", 1.0)])
        if not isinstance(gains, list) or not gains:
            raise OptionError(f"{here}: 'gains' must be a list of numbers, e.g. [0.5, 1.0, 1.5]")
        gains = tuple(check_gain(g, here, "'gain'") for g in gains)
        if len(set(gains)) != len(gains):
            raise OptionError(f"{here}: 'gains' lists a gain more than once: {list(gains)}")
    else:
        raise OptionError(f"{here}: 'assistance' must be a profile's path or a table {{file = \"exo.sto\", gains = "
                          f"[0.5, 1.0]}}, not {value!r}")
    read_assistance(path)  # checked now, before anything runs
    return path, gains


def _assisted_trials(trial: Trial, data, base: Path, where: str, default) -> list[Trial]:
    """The trial, and with an ``assistance`` key (its own, else the study's ``default``) one
    assisted trial per gain, named ``<trial>_assist-<gain>``."""
    from dataclasses import replace

    spec = _assistance(data.get("assistance"), base, f"{where}, trial '{trial.name}': 'assistance'") \
        if isinstance(data, Mapping) and data.get("assistance") is not None else default
    if spec is None:
        return [trial]
    path, gains = spec
    return [trial] + [replace(trial, name=check_plain_name(f"{trial.name}_assist-{g:g}", f"{where}: trial name"),
                              assistance=path, assistance_gain=g, assisted_from=trial.name) for g in gains]


def _check_assisted_subject(data, here: str, workflows) -> None:
    """Assistance is solved with the effort workflows, one trial at a time."""
    given = [k for k in ("emg_mode", "estimate") if data.get(k) is not None]
    if EMG_TEN in workflows:
        given.append("the emg-ten workflow")
    if str(data.get("tendon_stiffness", "")).strip().lower() == EMG_TEN:
        given.append("tendon_stiffness = \"emg-ten\"")
    if given:
        raise OptionError(f"{here}: 'assistance' is solved with the effort workflows (effort-gen, effort-cal, "
                          f"effort-ten) one trial at a time; {', '.join(given)} solve the subject's trials together: "
                          "put the assisted trials in a subject of their own without them")


def _check_profiles(trials, side: str, body_mass_kg: float, dofs, here: str) -> None:
    """Each assistance profile of a subject's trials checked for its leg and its units, as far as
    it can be without the model (:func:`~musclemetab.redundancy.assistance.check_profile_for_leg`;
    the rest before any unit runs: :func:`.units.check_assistance`)."""
    from ..errors import MusclemetabError
    from ..redundancy.assistance import check_profile_for_leg, read_assistance

    for path in dict.fromkeys(t.assistance for t in trials if t.assistance is not None):
        try:
            check_profile_for_leg(read_assistance(path), side, body_mass_kg, dofs=dofs)
        except MusclemetabError as exc:
            raise type(exc)(f"{here}: 'assistance': {exc}") from None


def _cycle_key(value, where: str):
    if value is None:
        return None
    return check_cycle(value, where)
