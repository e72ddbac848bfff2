"""The text of a solution's model file as OpenSim writes it, edited without OpenSim.

Plain text, no ``opensim`` import: used on both sides of the worker boundary. The OpenSim
worker (:mod:`.solution_model`) sets the solved muscles' parameters through
:data:`MUSCLE_PROPERTIES`; the package (:mod:`musclemetab.redundancy.export`) places other
parameter values into a model text that OpenSim wrote before (:func:`with_muscle_properties`,
numbers written as OpenSim 4.6 writes a double: ``%.17g``), so that a model kept in the cache
serves a solve with other parameters, and adds the file's comments (:func:`with_comments`).
"""

from __future__ import annotations

import re

__all__ = ["MUSCLE_PROPERTIES", "opensim_double", "with_muscle_properties", "with_comments"]

#: ``{parameter key of a solution's muscle: DeGrooteFregly2016Muscle property}``, the values a
#: solution gives a muscle of its model (``docs/opensim_files.md``)
MUSCLE_PROPERTIES = {
    "max_isometric_force_N": "max_isometric_force",
    "optimal_fiber_length_m": "optimal_fiber_length",
    "tendon_slack_length_m": "tendon_slack_length",
    "pennation_angle_at_optimal_rad": "pennation_angle_at_optimal",
    "max_contraction_velocity": "max_contraction_velocity",
    "tendon_strain_at_one_norm_force": "tendon_strain_at_one_norm_force",
    "passive_fiber_strain_at_one_norm_force": "passive_fiber_strain_at_one_norm_force",
    "activation_time_constant_s": "activation_time_constant",
    "deactivation_time_constant_s": "deactivation_time_constant",
}

_MUSCLE = re.compile(r'<DeGrooteFregly2016Muscle name="([^"]*)">.*?</DeGrooteFregly2016Muscle>', re.DOTALL)


def opensim_double(value: float) -> str:
    """A double as OpenSim 4.6 writes a property's value (17 significant digits, ``%.17g``)."""
    return "%.17g" % float(value)


def with_muscle_properties(text: str, parameters: dict) -> str:
    """``text`` (a model file OpenSim wrote) with the :data:`MUSCLE_PROPERTIES` of each muscle of
    ``parameters`` (``{muscle: {parameter key: value}}``) set to the values given, as OpenSim
    writes them. :class:`ValueError` when a muscle element or one of its properties is not
    found exactly once (a text that OpenSim did not write this way)."""
    done = set()

    def muscle(match):
        name = match.group(1)
        if name not in parameters:
            return match.group(0)
        if name in done:
            raise ValueError(f"muscle {name} appears twice in the model text")
        done.add(name)
        element = match.group(0)
        for key, prop in MUSCLE_PROPERTIES.items():
            element, n = re.subn(f"<{prop}>[^<]*</{prop}>", f"<{prop}>{opensim_double(parameters[name][key])}</{prop}>",
                                 element)
            if n != 1:
                raise ValueError(f"muscle {name} has {n} {prop} elements in the model text, not one")
        return element

    out = _MUSCLE.sub(muscle, text)
    missing = set(parameters) - done
    if missing:
        raise ValueError(f"no DeGrooteFregly2016Muscle element of {sorted(missing)} in the model text")
    return out


def with_comments(text: str, comments: dict) -> str:
    """XML comments in a model text: ``comments[""]`` after the XML declaration, each muscle's
    (``comments[muscle]``) before its ``DeGrooteFregly2016Muscle`` element (OpenSim ignores
    comments when it reads the file)."""
    def clean(text: str) -> str:
        return text.replace("--", "- -")

    lines = text.split("\n")
    out = []
    for i, line in enumerate(lines):
        s = line.strip()
        if s.startswith("<DeGrooteFregly2016Muscle name=\""):
            name = s.split("\"")[1]
            if name in comments:
                indent = line[: len(line) - len(line.lstrip())]
                out.append(f"{indent}<!-- {clean(comments[name])} -->")
        out.append(line)
        if i == 0 and s.startswith("<?xml") and "" in comments:
            out.append(f"<!-- {clean(comments[''])} -->")
    return "\n".join(out)
