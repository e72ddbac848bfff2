"""The effort-based workflows of the study and their muscle parameters.

==============  =====================================  ===================================
workflow        passive force-length (kPE, s0, sM)     tendon stiffness kT
==============  =====================================  ===================================
``effort-gen``  generic: 4, 1, 0.6 for every muscle    35 for every muscle
``effort-cal``  calibrated                             35 for every muscle
``effort-ten``  calibrated                             personalised for the muscles of the Achilles
                                                       (triceps surae) and patellar (vasti)
                                                       tendons, 35 for the others
==============  =====================================  ===================================

EFFORT-TEN's personalised ``kT``, in this order of precedence (``summary.json`` records the
source of every value, ``tendon_stiffness_sources``, and their kinds,
``tendon_stiffness_source``):

* ``--tendon-stiffness muscle=kT,...`` (names with or without side suffix);
* the subject's own EMG-TEN estimate (``--parameters parameters.json``);
* ``--tendon-stiffness example``: the example subject's estimates (triceps surae 10.617977,
  vasti 4.695786), placed through the anatomical muscle table; used only when asked for;
* otherwise a literature default per anatomical tendon, given in N/mm and converted into
  ``kT`` through the model's maximal isometric forces and tendon slack lengths
  (``data/tendon_stiffness_literature.csv``, ``docs/muscles.md``).

All three use the weights ``[wAct, wTres, wVm] = [1, 1000, 0.01]`` (``Workflow.goals``, ``docs/solver.md``).

Calibrated passive parameters come from, in this order of preference:

* a file given by the user: the package's calibration output ``passive_parameters.csv``
  (columns ``muscle,kPE,s0,sM``) or the study's ``passiveMoments.mat``
  (``sim.Results.onlyParam.calParam.kpe/ksf``, ``sM = 0.6``);
* otherwise the published calibration of the example subject shipped with the package
  (``musclemetab/data/study_passive_parameters.csv``, names of the study's model). ``summary.json`` records which was used.

Names are matched by muscle name; a table without side suffix (``soleus``) applies to both
``soleus_r`` and ``soleus_l``, and a value for one side is used for the other when the table
has no value for it (the study copies right-leg values to the left leg).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import InputFileError, OptionError, UnknownMuscleError
from ..messages import name_list
from ..muscle import KT_GENERIC
from ..passive import (  # noqa: F401  (read_passive_parameters: a name of this package too)
    PassiveParameters,
    base_name,
    generic_passive_parameters,
    read_passive_parameters,
    reference_passive_parameters,
)
from .parameters import MuscleTendonParameters
from .transcription import Goals

__all__ = [
    "Workflow",
    "WORKFLOWS",
    "get_workflow",
    "PassiveParameters",
    "read_passive_parameters",
    "reference_passive_parameters",
    "generic_passive_parameters",
    "read_tendon_stiffness_json",
    "parse_tendon_stiffness",
    "EXAMPLE",
    "example_tendon_stiffness",
    "literature_tendon_stiffness",
    "workflow_parameters",
    "check_workflow_options",
    "base_name",
]

#: ``--tendon-stiffness example``: the example subject's estimates, only when asked for.
EXAMPLE = "example"
#: Example-subject EMG-informed tendon stiffness (``docs/solver.md``).
KT_TRICEPS_SURAE = 10.617977
KT_VASTI = 4.695786


@dataclass(frozen=True)
class Workflow:
    """A named preset: which passive parameters and tendon stiffness, and the objective's
    weights (``goals``, default ``Goals()``: ``[wAct, wTres, wVm] = [1, 1000, 0.01]``)."""

    name: str
    passive: str  # "generic" | "calibrated"
    tendon: str  # "generic" | "personalised"
    goals: Goals = Goals()
    description: str = ""

    def __post_init__(self):
        if not isinstance(self.goals, Goals):
            raise OptionError(f"the goals of workflow '{self.name}' must be a Goals, not {type(self.goals).__name__}")


WORKFLOWS = {
    "effort-gen": Workflow("effort-gen", "generic", "generic",
                           description="generic passive force-length, generic tendons (kT = 35)"),
    "effort-cal": Workflow("effort-cal", "calibrated", "generic",
                           description="calibrated passive force-length, generic tendons (kT = 35)"),
    "effort-ten": Workflow("effort-ten", "calibrated", "personalised",
                           description="calibrated passive force-length, personalised triceps-surae "
                           "and vasti tendon stiffness"),
}


def get_workflow(name: str | Workflow) -> Workflow:
    if isinstance(name, Workflow):
        return name
    key = str(name).strip().lower().replace("_", "-")
    if key not in WORKFLOWS:
        raise OptionError(f"unknown workflow '{name}'; choose one of {', '.join(WORKFLOWS)}")
    return WORKFLOWS[key]


def example_tendon_stiffness(muscles: Sequence[str]) -> dict[str, float]:
    """The example subject's EMG-TEN estimates, placed by tendon (Achilles: triceps surae
    10.617977, patellar: vasti 4.695786) on the muscles of any model and side."""
    from ..properties import resolve_muscles

    values = {"achilles": KT_TRICEPS_SURAE, "patellar": KT_VASTI}
    return {r.name: values[r.tendon] for r in resolve_muscles(muscles, warn=False) if r.tendon in values}


def literature_tendon_stiffness(muscles: Sequence[str], max_isometric_force_N, tendon_slack_length_m
                                ) -> tuple[dict[str, float], dict[str, str], dict]:
    """The literature default: per anatomical tendon and side, the shared ``kT`` that gives the
    muscles of the tendon the tabulated stiffness (N/mm) at the tabulated force.

    Returns ``({muscle: kT}, {muscle: source}, {tendon_side: details})``.
    """
    from ..muscle import tendon_stiffness_for_slope
    from ..properties import tendon_groups, tendon_literature

    lit = tendon_literature()
    pos = {m: i for i, m in enumerate(muscles)}
    f0 = np.asarray(max_isometric_force_N, dtype=float)
    lts = np.asarray(tendon_slack_length_m, dtype=float)
    kt, src, details = {}, {}, {}
    for key, members in tendon_groups(muscles).items():
        tendon = key.rsplit("_", 1)[0] if key not in lit else key
        if tendon not in lit:
            continue
        k_mm, frac, source = lit[tendon]
        idx = [pos[m] for m in members]
        value = tendon_stiffness_for_slope(k_mm * 1000.0, f0[idx], lts[idx], frac)
        details[key] = {"muscles": list(members), "stiffness_N_per_mm": k_mm, "reference_force_fraction": frac,
                        "kT": value, "source": source}
        for m in members:
            kt[m] = value
            src[m] = f"literature ({tendon} tendon {k_mm:g} N/mm at {frac:g} F0)"
    return kt, src, details


def parse_tendon_stiffness(text: str) -> dict[str, float] | str:
    """Parse ``"soleus_r=10.6,gasmed_r=10.6"`` into ``{muscle: kT}``; ``"example"`` is kept
    as the request for the example subject's estimates."""
    if str(text).strip().lower() == EXAMPLE:
        return EXAMPLE
    out: dict[str, float] = {}
    for item in (s.strip() for s in str(text).split(",")):
        if not item:
            continue
        name, sep, value = item.partition("=")
        try:
            kt = float(value)
        except ValueError:
            kt = math.nan
        if not sep or not name.strip() or not (kt > 0 and math.isfinite(kt)):
            raise OptionError(
                f"--tendon-stiffness: '{item}' is not 'muscle=kT' with a positive number, e.g. soleus_r=10.6"
            )
        out[name.strip()] = kt
    if not out:
        raise OptionError("--tendon-stiffness is empty; give e.g. soleus_r=10.6,vaslat_r=4.7")
    return out


def read_tendon_stiffness_json(path: str | os.PathLike) -> dict[str, float]:
    """Read ``{"tendon_stiffness": {muscle: kT}}`` from a ``parameters.json``.

    The ``parameters.json`` written by EMG-TEN (:mod:`.emg_ten`) has this section (the
    estimated muscles; its other sections are ignored here). A folder is read as the
    ``parameters.json`` inside it.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "parameters.json"
    from ..io.jsonfile import read_json_object

    data = read_json_object(path, missing="no such parameters file; check the --parameters path")
    solve = data.get("solve")
    if isinstance(solve, dict) and solve.get("success") is False:
        raise InputFileError(
            f"{path}: the solve that estimated these parameters did not converge (status "
            f"'{solve.get('status')}'); its tendon stiffness is not an estimate. Solve EMG-TEN again"
        )
    table = data.get("tendon_stiffness")
    if not isinstance(table, dict) or not table:
        raise InputFileError(
            f"{path}: no 'tendon_stiffness' object; expected {{\"tendon_stiffness\": {{\"soleus_r\": 10.6, ...}}}}"
        )
    out = {}
    for name, value in table.items():
        try:
            kt = float(value)
        except (TypeError, ValueError):
            kt = math.nan
        if not (kt > 0 and math.isfinite(kt)):
            raise InputFileError(f"{path}: tendon_stiffness of '{name}' is {value!r}; it must be a positive number")
        out[str(name)] = kt
    return out


def _apply_by_name(muscles: Sequence[str], table: Mapping[str, float], what: str,
                   strict: bool) -> dict[str, float]:
    """Resolve a ``{name: value}`` table (names with or without side suffix) onto ``muscles``."""
    resolved: dict[str, float] = {}
    unknown = []
    for name, value in table.items():
        hits = [m for m in muscles if m == name] or [m for m in muscles if base_name(m) == name]
        if not hits:
            unknown.append(name)
        for m in hits:
            resolved[m] = float(value)
    if unknown and strict:
        raise UnknownMuscleError(
            f"{what}: muscle{'s' if len(unknown) > 1 else ''} {name_list(unknown)} not among the muscles "
            f"of this problem ({', '.join(muscles[:6])}{' ...' if len(muscles) > 6 else ''})"
        )
    return resolved


def check_workflow_options(
    workflow: str | Workflow,
    passive=None,
    tendon_stiffness: Mapping[str, float] | str | None = None,
    tendon_stiffness_file=None,
) -> Workflow:
    """Reject option combinations a workflow does not accept; returns the :class:`Workflow`."""
    wf = get_workflow(workflow)
    if wf.passive == "generic" and passive is not None:
        raise OptionError(
            f"workflow {wf.name} uses the generic passive parameters (kPE = 4, s0 = 1, sM = 0.6); "
            "drop --passive or choose effort-cal / effort-ten"
        )
    if wf.tendon == "generic" and (tendon_stiffness or tendon_stiffness_file):
        raise OptionError(
            f"workflow {wf.name} uses generic tendons (kT = 35); tendon stiffness values "
            "(--tendon-stiffness / --parameters) belong to effort-ten"
        )
    return wf


def workflow_parameters(
    workflow: str | Workflow,
    model_parameters,
    muscles: Sequence[str],
    *,
    passive: str | os.PathLike | PassiveParameters | None = None,
    tendon_stiffness: Mapping[str, float] | str | None = None,
    tendon_stiffness_file: str | os.PathLike | None = None,
) -> tuple[MuscleTendonParameters, dict]:
    """Muscle parameters of a workflow for the given muscles, and a record of their sources.

    Parameters
    ----------
    workflow
        ``effort-gen``, ``effort-cal`` or ``effort-ten`` (or a :class:`Workflow`).
    model_parameters
        Object with arrays ``names``, ``max_isometric_force_N``, ``optimal_fiber_length_m``,
        ``tendon_slack_length_m``, ``pennation_angle_at_optimal_rad``,
        ``max_contraction_velocity`` (e.g. ``musclemetab.model.read_muscle_parameters``).
    passive
        Calibration for effort-cal/ten: a path (``passive_parameters.csv`` or
        ``passiveMoments.mat``) or :class:`PassiveParameters`. ``None`` uses the published
        calibration shipped with the package. Not allowed with effort-gen.
    tendon_stiffness, tendon_stiffness_file
        effort-ten only: ``{muscle: kT}`` overrides (names with or without side suffix) and
        a ``parameters.json`` with a ``tendon_stiffness`` object. Precedence: defaults <
        file < mapping.
    """
    wf = check_workflow_options(workflow, passive, tendon_stiffness, tendon_stiffness_file)
    muscles = tuple(muscles)
    base = _model_arrays(model_parameters, muscles)

    if wf.passive == "generic":
        pp = generic_passive_parameters(muscles)
    elif passive is None:
        pp = reference_passive_parameters()
    elif isinstance(passive, PassiveParameters):
        pp = passive
    else:
        pp = read_passive_parameters(passive)
    passive_arr = pp.for_muscles(muscles)

    kt = np.full(len(muscles), KT_GENERIC)
    record = {"name": wf.name, "description": wf.description, "passive_source": pp.source,
              "weights": wf.goals.effort_weights()}
    if wf.tendon == "personalised":
        use_example = isinstance(tendon_stiffness, str)
        if use_example and tendon_stiffness.strip().lower() != EXAMPLE:
            raise OptionError(f"--tendon-stiffness: '{tendon_stiffness}' is neither 'example' nor muscle=kT pairs")
        resolved, sources, record["tendon_stiffness_literature"] = literature_tendon_stiffness(
            muscles, base["max_isometric_force_N"], base["tendon_slack_length_m"])
        if use_example:
            example = example_tendon_stiffness(muscles)
            resolved.update(example)
            sources.update({m: "example (example subject's EMG-TEN estimate, asked for)" for m in example})
            tendon_stiffness = None
        if tendon_stiffness_file is not None:
            table = read_tendon_stiffness_json(tendon_stiffness_file)
            # values for the other leg's muscles (same name, other side) are not an error
            other_side = {n for n in table if not any(m == n or base_name(m) == n for m in muscles)
                          and any(base_name(m) == base_name(n) for m in muscles)}
            from_file = _apply_by_name(muscles, {n: v for n, v in table.items() if n not in other_side},
                                       str(tendon_stiffness_file), strict=True)
            resolved.update(from_file)
            sources.update({m: str(tendon_stiffness_file) for m in from_file})
            if other_side:
                record["tendon_stiffness_ignored"] = sorted(other_side)
        if tendon_stiffness:
            given = _apply_by_name(muscles, tendon_stiffness, "--tendon-stiffness", strict=True)
            resolved.update(given)
            sources.update({m: "option" for m in given})
        for m, v in resolved.items():
            kt[muscles.index(m)] = v
        record["tendon_stiffness"] = {m: resolved[m] for m in muscles if m in resolved}
        record["tendon_stiffness_sources"] = {m: sources[m] for m in muscles if m in sources}
        record["tendon_stiffness_source"] = sorted({s.split(" ")[0] for s in record["tendon_stiffness_sources"].values()})
    record["tendon_stiffness_other_muscles"] = KT_GENERIC

    params = MuscleTendonParameters(
        names=muscles,
        tendon_stiffness=kt,
        passive_kpe=passive_arr[:, 0],
        passive_s0=passive_arr[:, 1],
        passive_sm=passive_arr[:, 2],
        sources={"passive": pp.source},
        **base,
    )
    return params, record


def _model_arrays(model_parameters, muscles: Sequence[str]) -> dict:
    names = [str(n) for n in getattr(model_parameters, "names")]
    pos = {n: i for i, n in enumerate(names)}
    missing = [m for m in muscles if m not in pos]
    if missing:
        raise UnknownMuscleError(
            f"the model parameters have no muscle{'s' if len(missing) > 1 else ''} {name_list(missing)}; "
            "the geometry and the parameters must come from the same model"
        )
    idx = np.array([pos[m] for m in muscles], dtype=int)
    out = {}
    for f in ("max_isometric_force_N", "optimal_fiber_length_m", "tendon_slack_length_m",
              "pennation_angle_at_optimal_rad", "max_contraction_velocity"):
        out[f] = np.asarray(getattr(model_parameters, f), dtype=float)[idx]
    return out
