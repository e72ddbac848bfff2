"""A subject's parameter estimation in a study: the ``[subjects.estimate]`` table and its unit.

::

    [subjects.estimate]
    estimate = {tendon_stiffness = ["soleus_r", "gasmed_r", "gaslat_r"], optimal_fiber_length = ["tibant_r"]}
    couple = [["soleus_r", "gasmed_r", "gaslat_r"]]     # optional: muscles sharing one factor
                                                       #   of every kind, or of one kind:
                                                       #   {kind = "tendon_stiffness", muscles = [...]}
    bounds = {tendon_stiffness = [0.1, 2.0]}            # optional (kinds, and emg_scale)
    weights = {fiber_length = 100.0}                   # optional: activation, reserve, velocity,
                                                       #   fiber_length, emg
    workflow = "effort-cal"                            # optional: effort-gen | effort-cal | effort-ten
    emg_mode = "constrained"                           # optional: track the trials' EMG too
    validate = true                                    # optional: re-solve with the estimates

The estimation runs over the subject's trials that have an ``ultrasound`` file (fiber
lengths, ``musclemetab estimate --ultrasound``) and, with ``emg_mode``, their ``emg``; with
``emg_mode`` and no ultrasound at all, over the trials with EMG. It is the command
``musclemetab estimate`` on those files, written to ``units/<subject>/_estimate/``
(``parameters.json``, ``<model>_personalised.osim``, the solutions per trial).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

from ..errors import OptionError
from ..messages import name_list
from ..redundancy._checks import EMG_MODES

__all__ = ["ESTIMATE", "ESTIMATE_FOLDER", "EstimateSpec", "estimate_spec", "estimation_trials",
           "run_parameter_estimation"]

#: workflow name of a subject's parameter-estimation unit, and its folder
ESTIMATE = "estimate"
ESTIMATE_FOLDER = "_estimate"
_KEYS = {"estimate", "couple", "bounds", "weights", "workflow", "emg_mode", "validate"}


@dataclass(frozen=True)
class EstimateSpec:
    """What a subject's estimation unit estimates, and how (the ``musclemetab estimate`` options)."""

    estimate: dict
    couple: tuple = ()  # muscle tuples (every kind) and "KIND:M1,M2" strings (one kind)
    bounds: dict = field(default_factory=dict)
    weights: dict = field(default_factory=dict)
    workflow: str = "effort-cal"
    emg_mode: str | None = None
    validate: bool = False

    def to_dict(self) -> dict:
        from ..redundancy.estimate import parse_coupling

        return {"estimate": {k: list(v) for k, v in self.estimate.items()},
                "couple": [parse_coupling(g) if isinstance(g, str) else list(g) for g in self.couple],
                "bounds": {k: list(v) for k, v in self.bounds.items()}, "weights": dict(self.weights),
                "workflow": self.workflow, "emg_mode": self.emg_mode, "validate": self.validate}


def _names(value, here: str, key: str) -> tuple[str, ...]:
    if not isinstance(value, list) or not value or not all(isinstance(m, str) and m for m in value):
        raise OptionError(f"{here}: '{key}' must be a list of muscle names such as [\"soleus_r\", \"gasmed_r\"]")
    return tuple(value)


def _coupling(group, here: str):
    """A ``couple`` entry: a list of muscles (every kind), or ``{kind, muscles}`` (that kind),
    held as ``"KIND:M1,M2"``."""
    from ..redundancy.estimate import FIELDS

    if not isinstance(group, Mapping):
        return _names(group, here, "couple")
    kinds = (*FIELDS, "emg_scale")
    if set(group) != {"kind", "muscles"} or group["kind"] not in kinds:
        raise OptionError(f"{here}: a 'couple' table must be {{kind = KIND, muscles = [...]}} with KIND one of "
                          f"{', '.join(kinds)}, not {dict(group)!r}")
    return f"{group['kind']}:{','.join(_names(group['muscles'], here, 'couple.muscles'))}"  # parse_coupling's form


def estimate_spec(data, here: str) -> EstimateSpec:
    """The checked ``[subjects.estimate]`` table (``here`` names the file and subject)."""
    from ..redundancy.estimate import FIELDS
    from ..redundancy.run import WEIGHT_NAMES

    here = f"{here}: [subjects.estimate]"
    if not isinstance(data, Mapping):
        raise OptionError(f"{here}: expected a table such as estimate = {{tendon_stiffness = [\"soleus_r\"]}}")
    extra = sorted(set(data) - _KEYS)
    if extra:
        raise OptionError(f"{here}: unknown key(s) {name_list(extra)}; allowed: {', '.join(sorted(_KEYS))}")
    what = data.get("estimate")
    if not isinstance(what, Mapping) or not what:
        raise OptionError(f"{here}: 'estimate' is required: a table {{kind = [muscle, ...]}} with kinds "
                          f"{', '.join(FIELDS)}")
    bad = [k for k in what if k not in FIELDS]
    if bad:
        raise OptionError(f"{here}: cannot estimate '{bad[0]}'; estimate one of {', '.join(FIELDS)}")
    estimate = {k: _names(v, here, f"estimate.{k}") for k, v in what.items()}
    couple = data.get("couple", [])
    if not isinstance(couple, list):
        raise OptionError(f"{here}: 'couple' must be a list of muscle lists such as [[\"soleus_r\", \"gasmed_r\"]]")
    couple = tuple(_coupling(g, here) for g in couple)
    for key in ("bounds", "weights"):
        if not isinstance(data.get(key, {}), Mapping):
            raise OptionError(f"{here}: '{key}' must be a table such as {key} = {{tendon_stiffness = [0.1, 2.0]}}"
                              if key == "bounds" else f"{here}: 'weights' must be a table such as weights = "
                              "{fiber_length = 100.0}")
    bounds = {}
    for k, v in data.get("bounds", {}).items():
        if k not in (*FIELDS, "emg_scale"):
            raise OptionError(f"{here}: 'bounds': unknown kind '{k}'; use {', '.join((*FIELDS, 'emg_scale'))}")
        ok = (isinstance(v, list) and len(v) == 2 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                         and math.isfinite(x) for x in v) and 0 < v[0] <= v[1])
        if not ok:
            raise OptionError(f"{here}: 'bounds.{k}' must be [low, high] with 0 < low <= high, not {v!r}")
        bounds[k] = (float(v[0]), float(v[1]))
    weights = {}
    for k, v in data.get("weights", {}).items():
        if k not in WEIGHT_NAMES:
            raise OptionError(f"{here}: 'weights': unknown weight '{k}'; use {', '.join(WEIGHT_NAMES)}")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
            raise OptionError(f"{here}: 'weights.{k}' must be a non-negative number, not {v!r}")
        weights[k] = float(v)
    workflow = data.get("workflow", "effort-cal")
    if workflow not in ("effort-gen", "effort-cal", "effort-ten"):
        raise OptionError(f"{here}: 'workflow' must be effort-gen, effort-cal or effort-ten, not {workflow!r}")
    mode = data.get("emg_mode")
    if mode is not None and mode not in EMG_MODES:
        raise OptionError(f"{here}: 'emg_mode' must be one of {', '.join(EMG_MODES)}, not {mode!r}")
    validate = data.get("validate", False)
    if not isinstance(validate, bool):
        raise OptionError(f"{here}: 'validate' must be true or false, not {validate!r}")
    return EstimateSpec(estimate=estimate, couple=couple, bounds=bounds, weights=weights, workflow=workflow,
                        emg_mode=mode, validate=validate)


def estimation_trials(subject, here: str | None = None) -> list:
    """The trials a subject's estimation uses (see the module docstring); with ``here``, a
    subject whose trials cannot serve is refused naming it."""
    spec = subject.estimate
    with_us = [t for t in subject.trials if t.ultrasound is not None]
    trials = with_us or ([t for t in subject.trials if t.emg is not None] if spec.emg_mode else [])
    if here is not None:
        if not trials:
            raise OptionError(f"{here}: the estimation needs measurements: give trials an 'ultrasound' file "
                              "(fiber lengths in mm) or set estimate.emg_mode and give them 'emg' files")
        if spec.emg_mode:
            missing = [t.name for t in trials if t.emg is None]
            if missing:
                raise OptionError(f"{here}: estimate.emg_mode needs an 'emg' file for every estimation trial; "
                                  f"missing for {name_list(missing)}")
        bad = [t.name for t in trials if t.id is None or t.cycle is not None or t.window is not None]
        if bad:
            raise OptionError(f"{here}: the estimation solves the trials' whole IK window with their 'id' file; "
                              f"trial(s) {name_list(bad)} have no 'id' or set 'cycle' or 'window' (drop them, or "
                              "give the estimation other trials)")
    return trials


def run_parameter_estimation(study, unit, tmp: Path) -> dict:
    """The subject's estimation unit: :func:`~musclemetab.redundancy.estimate_run.estimate_files`
    (``musclemetab estimate``) on its trials, written to ``tmp``."""
    import time

    from ..redundancy import estimate_run as run

    subject = study.subject(unit.subject)
    spec = subject.estimate
    trials = estimation_trials(subject)
    with_us = any(t.ultrasound is not None for t in trials)
    t0 = time.perf_counter()
    run.estimate_files(
        subject.model, [t.ik for t in trials], [t.id for t in trials], tmp,
        estimate=spec.estimate, labels=[t.name for t in trials],
        ultrasound=[t.ultrasound for t in trials] if with_us else (),
        emg=[t.emg for t in trials] if spec.emg_mode else (),
        emg_mode=spec.emg_mode, emg_mapping=subject.emg_mapping if spec.emg_mode else None,
        couple=spec.couple, bounds=spec.bounds, weights=spec.weights, workflow=spec.workflow,
        side=subject.side, dofs=subject.dofs,
        passive=subject.passive if spec.workflow != "effort-gen" else None,
        options=_estimation_options(study), validate=spec.validate,
        exclude_muscles=subject.exclude_muscles,
    )
    return {"times": {"solve_s": time.perf_counter() - t0}, "trials": [t.name for t in trials]}


def _estimation_options(study):
    """The study's ``[solver]`` settings (stop, tolerance, iterations, linear solver) for its estimation."""
    from ..redundancy import SolverOptions

    return SolverOptions(**{k: v for k, v in (study.settings.get("solver") or {}).items() if k != "warm_start"})
