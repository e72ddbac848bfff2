"""Metabolic rates of every muscle of a muscle-redundancy solution, and their files.

Input: a solution folder (``solution.sto`` with one row per mesh node ``t_0 ... t_N`` and
columns ``/forceset/<muscle>/<quantity>``; ``summary.json`` with ``muscles`` and the
per-muscle ``parameters`` of the solve; see :mod:`musclemetab.redundancy.solution`).

Trimming (``docs/metabolics.md``): the solver's first and last nodes are padding
(free initial and final states). The study keeps nodes ``t_5 ... t_{N-6}``
(0-based ``slice(5, N - 5)``, ``N - 10`` samples): 5 nodes dropped at the start and 6 at
the end (the last includes node ``N``, where the controls only repeat node ``N-1``).
Excitation and fiber velocity at node ``k`` pair with the states at node ``k``.

Muscle parameters (``F0``, ``lMo``, ``vmax``) are matched by muscle name, from the solution's
``summary.json`` (the values the solve used) or from a model; masses and slow-twitch
fractions come from :mod:`musclemetab.properties` (volume rule, body mass and height).

Outputs of :func:`write_metabolics` in a folder:

``metabolics.sto``
    time (trimmed nodes) and one column ``<model>/<muscle>/<component>`` (W) per model,
    muscle and component (``work``, ``activation_maintenance``, ``shortening_lengthening``,
    ``basal``, ``total_no_basal``, and model extras). ``total_no_basal`` is the muscle's rate
    without any basal heat (work + heats); ``basal`` is the per-muscle basal heat (1.2 W/kg of
    muscle mass), apart: their sum is the rate with the per-muscle basal heat (the study's code).
``metabolics.parquet``
    the same values as a tidy table (Parquet, full precision): ``time``, ``model``,
    ``muscle``, ``component``, ``value_W``.
``whole_body.csv``
    one row per model: ``model``, ``whole_body_W_per_kg`` (both legs, basal per the rule, by
    default 1.2 W/kg of body mass), ``whole_body_no_basal_W_per_kg``, ``leg_muscles_W`` (one
    leg, no basal), then ``basal_rule``, ``basal_W_per_kg`` (the basal heat added),
    ``duration_s`` and, when a speed is given, ``gross_cost_of_transport_J_per_kg_per_m`` (with
    the basal heat of the rule) and ``net_cost_of_transport_J_per_kg_per_m`` (without basal heat).
    A leg evaluated for adding to the other (``legs=1``) writes ``leg_muscles.csv`` instead: its
    muscles alone, no basal heat (:data:`LEG_CSV`).
``per_muscle.csv``
    one row per model and muscle: cycle-average rate, W/kg, energy per cycle, share of
    the leg, stance and swing energies (given a gait cycle), components, basal heat apart
    (:func:`musclemetab.metabolics.per_muscle.per_muscle_table`).

Every column is described in ``docs/data_dictionary.md``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import DataMismatchError, MissingColumnError, OptionError
from ._common import BASAL_RATE_W_PER_KG, MetabolicRates
from .masses import (  # noqa: F401  (the rules' names, importable from here as before)
    MASS_RULE_MODEL, MASS_RULE_VOLUME, mass_rule, model_muscle_masses_kg, muscle_masses_and_fractions)
from .registry import ALL_MODELS, parse_models
from .whole_body import BASAL_RULES, WholeBodyRate, check_basal_rule, whole_body_rate

__all__ = [
    "SolutionStates",
    "SolutionMetabolics",
    "read_solution_states",
    "states_of_solution",
    "trim_slice",
    "metabolics_from_solution",
    "metabolics_from_legs",
    "legs_table",
    "write_metabolics",
    "write_legs_metabolics",
    "add_legs",
    "solution_folders",
    "parameter_differences",
    "read_metabolics_settings",
    "check_metabolics_of",
    "SOLUTION_FILE",
    "SUMMARY_FILE",
    "METABOLICS_STO",
    "METABOLICS_PARQUET",
    "WHOLE_BODY_CSV",
    "LEG_CSV",
    "MASS_RULE_MODEL",
    "MASS_RULE_VOLUME",
    "model_muscle_masses_kg",
    "TOTAL_NO_BASAL",
]

from ..io.solution_folder import SOLUTION_FILE, SUMMARY_FILE  # noqa: E402  (one definition of the format)
from ..messages import name_list
METABOLICS_STO = "metabolics.sto"
METABOLICS_PARQUET = "metabolics.parquet"
WHOLE_BODY_CSV = "whole_body.csv"
#: The file ``musclemetab metabolics`` writes beside ``whole_body.csv``: the flags of the solve(s)
#: and of the whole-body rates, a JSON list of ``Flag.to_dict()`` (``[]``: none; written by
#: :func:`musclemetab.metabolics.plausibility.write_plausibility`).
PLAUSIBILITY_FILE = "plausibility.json"
#: A leg's file when the legs are added (``legs=1``): its muscles alone, no basal heat.
LEG_CSV = "leg_muscles.csv"


def check_metabolics_outputs(out_dir, sides) -> None:
    """Refuse (:class:`~musclemetab.errors.OptionError` naming the file), before any work, an
    ``out_dir`` where a file of :func:`write_legs_metabolics` for the legs ``sides`` (and
    ``plausibility.json``) would replace a folder, or a file the package did not write or that
    was changed since (:func:`musclemetab.io.atomic.check_replaceable`)."""
    from ..io.atomic import check_replaceable
    from .per_muscle import PER_MUSCLE_FILE

    out_dir, sides = Path(out_dir), list(sides)
    files = (METABOLICS_STO, METABOLICS_PARQUET, WHOLE_BODY_CSV, LEG_CSV, PER_MUSCLE_FILE)
    for folder in ([out_dir] if len(sides) <= 1 else [out_dir / s for s in sides]):
        check_replaceable(folder, files)
    check_replaceable(out_dir, [PLAUSIBILITY_FILE] + ([WHOLE_BODY_CSV] if len(sides) > 1 else []))
#: The component of the files for the muscle's rate without basal heat (``MetabolicRates.total``
#: holds the per-muscle basal heat; the files write the two apart).
TOTAL_NO_BASAL = "total_no_basal"

#: solution column quantity -> model argument
_QUANTITIES = {
    "excitation": "excitation",
    "activation": "activation",
    "normalized_fiber_length": "normalized_fiber_length",
    "normalized_fiber_velocity": "normalized_fiber_velocity",
    "active_force_length_multiplier": "active_force_length_multiplier",
    "force_velocity_multiplier": "force_velocity_multiplier",
    "passive_fiber_force": "passive_fiber_force_N",
}
#: summary.json parameter keys -> model argument
_SUMMARY_KEYS = {
    "F0_N": "max_isometric_force_N",
    "lMo_m": "optimal_fiber_length_m",
    "vmax_lMo_per_s": "max_contraction_velocity",
}
_PARAMETER_NAMES = ("max_isometric_force_N", "optimal_fiber_length_m", "max_contraction_velocity")


@dataclass
class SolutionStates:
    """Muscle states of a solution on its mesh: arrays ``(muscles, nodes)``.

    ``states`` maps the model arguments (``excitation``, ``activation``,
    ``normalized_fiber_length``, ``normalized_fiber_velocity``,
    ``active_force_length_multiplier``, ``force_velocity_multiplier``,
    ``passive_fiber_force_N``) to arrays; ``parameters`` maps muscle name to
    ``{max_isometric_force_N, optimal_fiber_length_m, max_contraction_velocity}`` (may be
    empty when the source has none).
    """

    time_s: np.ndarray
    muscles: tuple[str, ...]
    states: dict[str, np.ndarray]
    parameters: dict[str, dict[str, float]] = field(default_factory=dict)
    source: str = ""
    #: (start, end) of the gait cycle recorded by a solve over ``--cycle`` (s), else None
    cycle_s: tuple[float, float] | None = None
    #: the solved leg ("r"/"l") when the solve recorded it
    side: str | None = None
    #: SHA-256 of the folder's ``solution.sto`` (a folder read from files; else empty): recorded
    #: by :func:`write_metabolics`, so that ``analyse`` knows which solution the rates are of
    solution_sha256: str = ""


def read_solution_states(directory: str | os.PathLike, *, require_success: bool = True) -> SolutionStates:
    """Read the muscle states and parameters of a solution folder.

    Raises
    ------
    InputFileError
        A file is missing, or ``summary.json`` is not valid JSON or lacks ``muscles``.
    MissingColumnError
        ``solution.sto`` lacks a needed column.
    SolverError
        The summary says the solve did not succeed (unless ``require_success=False``).
    """
    from ..io.atomic import file_sha256
    from ..io.solution_folder import read_solution_folder

    directory = Path(directory)
    spath, jpath = directory / SOLUTION_FILE, directory / SUMMARY_FILE
    df, summary = read_solution_folder(directory, require_success=require_success)
    muscles = tuple(str(m) for m in summary["muscles"])
    need = [f"/forceset/{m}/{q}" for q in _QUANTITIES for m in muscles]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise MissingColumnError(
            f"{spath}: missing column{'s' if len(missing) > 1 else ''} {', '.join(missing[:6])}"
            f"{' ...' if len(missing) > 6 else ''} ({len(missing)} in all); the metabolic models need "
            f"{', '.join(_QUANTITIES)} for every muscle of {jpath.name}"
        )
    states = {
        arg: df[[f"/forceset/{m}/{q}" for m in muscles]].to_numpy(dtype=float).T for q, arg in _QUANTITIES.items()
    }
    params: dict[str, dict[str, float]] = {}
    records = summary.get("parameters") or {}
    if isinstance(records, Mapping):
        for m in muscles:
            rec = records.get(m)
            if isinstance(rec, Mapping) and all(k in rec for k in _SUMMARY_KEYS):
                params[m] = {arg: float(rec[k]) for k, arg in _SUMMARY_KEYS.items()}
    return SolutionStates(
        time_s=df.index.to_numpy(dtype=float), muscles=muscles, states=states, parameters=params, source=str(directory),
        cycle_s=_recorded_cycle(summary), side=_recorded_side(summary), solution_sha256=file_sha256(spath),
    )


def _recorded_cycle(summary) -> tuple[float, float] | None:
    """(start, end) of the gait cycle a solve recorded in its summary (``window.gait_cycle``; the file's
    dictionary or a :class:`~musclemetab.redundancy.record.SolveRecord`), else None."""
    window = summary.get("window")
    cycle = window.get("gait_cycle") if isinstance(window, Mapping) else None
    return (float(cycle["start_s"]), float(cycle["end_s"])) if isinstance(cycle, Mapping) else None


def _recorded_side(summary) -> str | None:
    """The leg (``"r"``/``"l"``) a solve recorded in its summary, else None."""
    side = summary.get("side")
    return side if side in ("r", "l") else None


def states_of_solution(solution, *, require_success: bool = True) -> SolutionStates:
    """The muscle states and parameters of an in-memory :class:`musclemetab.redundancy.Solution`:
    what :func:`read_solution_states` reads from the folder :meth:`Solution.write` makes of it,
    the recorded gait cycle and leg included (the folder rounds the values to 12 significant
    digits; the object keeps them whole)."""
    if require_success and not solution.success:
        raise solution.run_record.failure("the solve of this solution")
    arrays = {
        "excitation": solution.excitation, "activation": solution.activation,
        "normalized_fiber_length": solution.lm_norm, "normalized_fiber_velocity": solution.normalized_fiber_velocity,
        "active_force_length_multiplier": solution.active_force_length_multiplier,
        "force_velocity_multiplier": solution.force_velocity_multiplier,
        "passive_fiber_force_N": solution.passive_fiber_force_N,
    }
    p = solution.parameters.subset(solution.muscles)
    values = zip(p.max_isometric_force_N, p.optimal_fiber_length_m, p.max_contraction_velocity)
    params = {m: dict(zip(_PARAMETER_NAMES, (float(x) for x in v))) for m, v in zip(solution.muscles, values)}
    return SolutionStates(time_s=np.asarray(solution.time_s, dtype=float), muscles=tuple(solution.muscles),
                          states={k: np.asarray(v, dtype=float).T for k, v in arrays.items()}, parameters=params,
                          source="solution object", cycle_s=_recorded_cycle(solution.record),
                          side=_recorded_side(solution.record))


#: How far outside [0, 1] an activation or excitation may lie and still be taken as on its
#: bound (clipped): IPOPT relaxes bounds by up to 1e-8 (relative) and a file rounds to 12
#: digits; farther out the solution is refused
CONTROL_BOUND_TOLERANCE = 1e-6


def controls_in_bounds(states: SolutionStates) -> SolutionStates:
    """``states`` with the excitations and activations clipped to [0, 1] when they lie at most
    :data:`CONTROL_BOUND_TOLERANCE` outside (``0 ** 0.6`` where ``(-4e-9) ** 0.6`` is NaN);
    :class:`DataMismatchError` naming the muscle when one lies farther out."""
    out = dict(states.states)
    for name in ("excitation", "activation"):
        x = np.asarray(out[name], dtype=float)
        low, high = np.nanmin(x, axis=1), np.nanmax(x, axis=1)
        bad = np.flatnonzero((low < -CONTROL_BOUND_TOLERANCE) | (high > 1 + CONTROL_BOUND_TOLERANCE))
        if bad.size:
            i = int(bad[0])
            raise DataMismatchError(
                f"{states.source}: the {name} of {states.muscles[i]} spans {low[i]:.6g} to {high[i]:.6g}, outside "
                f"[0, 1] by more than {CONTROL_BOUND_TOLERANCE:g}"
                f"{f' ({bad.size} muscles in all)' if bad.size > 1 else ''}; an activation or excitation is a share of "
                "the maximum: check the file (column order, units)")
        out[name] = np.clip(x, 0.0, 1.0)
    return replace(states, states=out)


def solution_states(solution, *, require_success: bool = True) -> SolutionStates:
    """The :class:`SolutionStates` of a solution folder, a :class:`musclemetab.redundancy.Solution`
    or :class:`SolutionStates`, their excitations and activations in [0, 1] (:func:`controls_in_bounds`)."""
    if isinstance(solution, SolutionStates):
        return controls_in_bounds(solution)
    if hasattr(solution, "lm_norm") and hasattr(solution, "summary"):
        return controls_in_bounds(states_of_solution(solution, require_success=require_success))
    return controls_in_bounds(read_solution_states(solution, require_success=require_success))


def trim_slice(n_nodes: int, start: int = 5, end: int = 6) -> slice:
    """The kept nodes: drop ``start`` nodes at the beginning and ``end`` at the end.

    The study's default (5, 6) on ``N + 1`` nodes keeps ``t_5 ... t_{N-6}``, i.e.
    ``slice(5, N - 5)`` (``N - 10`` samples).
    """
    if start < 0 or end < 0:
        raise OptionError(f"trim counts must not be negative, not ({start}, {end})")
    if n_nodes - start - end < 2:
        raise DataMismatchError(
            f"the solution has {n_nodes} nodes; dropping {start} at the start and {end} at the end leaves fewer "
            "than two samples. Solve over a longer window (the study pads the cycle with 5 frames at each end)"
        )
    return slice(start, n_nodes - end)


def _parameters_for(muscles: Sequence[str], source, what: str) -> dict[str, np.ndarray]:
    """Per-muscle F0, lMo, vmax arrays matched by name from a MuscleParameters or a mapping."""
    if hasattr(source, "names") and hasattr(source, "max_isometric_force_N"):
        pos = {n: i for i, n in enumerate(source.names)}
        missing = [m for m in muscles if m not in pos]
        if missing:
            raise DataMismatchError(
                f"the {what} has no parameters for muscle{'s' if len(missing) > 1 else ''} {name_list(missing)}; "
                "check that the model is the one the solution was computed with"
            )
        idx = [pos[m] for m in muscles]
        return {k: np.asarray(getattr(source, k), dtype=float)[idx] for k in _PARAMETER_NAMES}
    missing = [m for m in muscles if m not in source]
    if missing:
        raise DataMismatchError(
            f"the {what} has no parameters for muscle{'s' if len(missing) > 1 else ''} {name_list(missing)}; "
            "give the model (.osim) the solution was computed with"
        )
    out = {}
    for k in _PARAMETER_NAMES:
        try:
            out[k] = np.array([float(source[m][k]) for m in muscles])
        except KeyError:
            raise OptionError(f"the {what} lacks '{k}' for some muscles") from None
    return out


@dataclass
class SolutionMetabolics:
    """Metabolic rates of every muscle of one solution, for several models.

    ``rates[model]`` is a :class:`MetabolicRates` of arrays ``(muscles, time)``;
    ``whole_body[model]`` a :class:`WholeBodyRate`.
    """

    time_s: np.ndarray
    muscles: tuple[str, ...]
    models: tuple[str, ...]
    rates: dict[str, MetabolicRates]
    whole_body: dict[str, WholeBodyRate]
    muscle_mass_kg: np.ndarray
    slow_twitch_fraction: np.ndarray
    parameters: dict[str, np.ndarray]
    body_mass_kg: float
    height_m: float | None
    basal_rule: str
    speed_m_per_s: float | None = None
    source: str = ""
    #: the basal rule's coefficient (W/kg; of muscle mass for the per-muscle basal heat) and exponent
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG
    basal_exponent: float = 1.0
    #: the solved leg ("r"/"l") when the solution recorded it
    side: str | None = None
    #: where the masses and slow-twitch fractions came from when not the package's own tables
    #: (e.g. the model's OpenSim metabolic probes), recorded in the header of ``metabolics.sto``
    muscle_parameters: str = ""
    #: SHA-256 of the ``solution.sto`` the rates were computed from (a solution folder; else
    #: empty), recorded in the header of ``metabolics.sto``
    solution_sha256: str = ""

    def __repr__(self) -> str:
        """A summary of a few lines (models x muscles x nodes, the leg, the body, the basal rule and
        each model's whole-body rate), not the arrays."""
        t = self.time_s
        span = f"{t[0]:.3f}-{t[-1]:.3f} s" if t.size else "no nodes"
        height = f", {self.height_m:g} m" if self.height_m is not None else ""
        lines = [f"SolutionMetabolics: {len(self.models)} models x {len(self.muscles)} muscles x {t.size} nodes "
                 f"({span}){f', side {self.side}' if self.side else ''}; body {self.body_mass_kg:g} kg{height}; "
                 f"muscle masses by {self.muscle_mass_rule}"]
        legs = {wb.legs for wb in self.whole_body.values()}
        if legs == {2}:
            lines.append(f"  whole body (W/kg; the leg doubled, basal {self.basal_rule}): model, rate, without basal heat")
            lines += [f"    {m:<5} {self.whole_body[m].mean_W_per_kg:7.3f} {self.whole_body[m].mean_W_per_kg_no_basal:7.3f}"
                      for m in self.models]
        else:
            lines.append("  the leg's muscles (W, no basal heat; a leg to add to the other):")
            lines += [f"    {m:<5} {self.whole_body[m].leg_no_basal_mean_W:8.2f}" for m in self.models]
        lines.append("  rates[model] (muscles x nodes, W), whole_body[model]; whole_body_table(), to_long(), to_mat(path)")
        return "\n".join(lines)

    __str__ = __repr__

    def mat_struct(self, cycle=None) -> dict:
        """The ``metabolics`` struct of a MATLAB file (:func:`musclemetab.io.matlab.metabolics_struct`;
        layout: ``docs/matlab.md``): the columns and tables :func:`write_metabolics` writes."""
        from ..io.matlab import metabolics_struct
        from .per_muscle import per_muscle_table

        one_leg = any(wb.legs != 2 for wb in self.whole_body.values())
        whole = {"leg_muscles": self.leg_table()} if one_leg else {"whole_body": self.whole_body_table()}
        return metabolics_struct(self.time_s, self.columns(), {**whole, "per_muscle": per_muscle_table(self, cycle)})

    def to_mat(self, path: str | os.PathLike) -> Path:
        """Write the rates to the MATLAB file ``path``: :meth:`mat_struct` at the top (layout:
        ``docs/matlab.md``)."""
        from ..io.matlab import write_mat

        return write_mat(path, self.mat_struct())

    @property
    def muscle_mass_rule(self) -> str:
        """How the muscle masses were found: :data:`MASS_RULE_VOLUME` (body mass and height) or
        :data:`MASS_RULE_MODEL` (no height: the model's ``F0 / sigma * rho * lMo``)."""
        return mass_rule(self.height_m)

    def file_components(self, model: str) -> dict[str, np.ndarray]:
        """The components written to the files, ``(muscles, time)`` arrays (W): those of
        :meth:`MetabolicRates.components` with ``total`` (which holds the per-muscle basal heat)
        replaced by :data:`TOTAL_NO_BASAL`, the rate without any basal heat."""
        comps = {}
        for c, arr in self.rates[model].components().items():
            if c == "total":
                comps[TOTAL_NO_BASAL] = np.asarray(self.rates[model].total_without_basal(), dtype=float)
            else:
                comps[c] = arr
        return comps

    def columns(self) -> dict[str, np.ndarray]:
        """``{"<model>/<muscle>/<component>": 1-D array (W)}`` in model, muscle, component order
        (components of :meth:`file_components`)."""
        out = {}
        for model in self.models:
            comps = self.file_components(model)
            for i, m in enumerate(self.muscles):
                for c, arr in comps.items():
                    out[f"{model}/{m}/{c}"] = arr[i]
        return out

    def to_dataframe(self):
        """Wide table indexed by time, columns ``<model>/<muscle>/<component>`` (W)."""
        from ..io import storage_from_arrays

        return storage_from_arrays(self.time_s, self.columns(), name="musclemetab metabolic rates")

    def to_long(self):
        """Tidy table: ``time``, ``model``, ``muscle``, ``component``, ``value_W``."""
        import pandas as pd

        frames = []
        t = self.time_s
        n_t = t.size
        for model in self.models:
            comps = self.file_components(model)
            names = list(comps)
            values = np.stack([comps[c] for c in names], axis=1)  # (M, C, T)
            n_m, n_c = values.shape[0], values.shape[1]
            frames.append(
                pd.DataFrame(
                    {
                        "time": np.tile(t, n_m * n_c),
                        "model": model,
                        "muscle": np.repeat(np.asarray(self.muscles, dtype=object), n_c * n_t),
                        "component": np.tile(np.repeat(np.asarray(names, dtype=object), n_t), n_m),
                        "value_W": values.reshape(-1),
                    }
                )
            )
        return pd.concat(frames, ignore_index=True)

    def whole_body_table(self):
        """One row per model: ``model``, ``whole_body_W_per_kg``, ``whole_body_no_basal_W_per_kg``,
        ``leg_muscles_W``, ``basal_rule``, ``basal_W_per_kg``, ``duration_s``, ``muscle_mass_rule``
        (and the gross and net costs of transport when a speed was given). A leg evaluated for adding to the other
        (``legs=1``) stands for no whole body: see :meth:`leg_table`."""
        import pandas as pd

        if any(wb.legs != 2 for wb in self.whole_body.values()):
            raise OptionError("a leg evaluated with legs=1 has no whole-body rate of its own: add the legs "
                              "(add_legs, write_legs_metabolics) or use its leg_table()")
        rows = []
        for model in self.models:
            wb = self.whole_body[model]
            row = {
                "model": model,
                "whole_body_W_per_kg": wb.mean_W_per_kg,
                "whole_body_no_basal_W_per_kg": wb.mean_W_per_kg_no_basal,
                "leg_muscles_W": wb.leg_no_basal_mean_W,
                "basal_rule": wb.basal_rule,
                "basal_W_per_kg": wb.basal_W_per_kg,
                "duration_s": wb.duration_s,
                "muscle_mass_rule": self.muscle_mass_rule,
            }
            if self.speed_m_per_s is not None:
                row["gross_cost_of_transport_J_per_kg_per_m"] = wb.cost_of_transport_J_per_kg_per_m(self.speed_m_per_s)
                row["net_cost_of_transport_J_per_kg_per_m"] = wb.net_cost_of_transport_J_per_kg_per_m(
                    self.speed_m_per_s)
            rows.append(row)
        return pd.DataFrame(rows)

    def leg_table(self):
        """One row per model of the solved leg's muscles alone (no basal heat): ``model``, ``side``,
        ``leg_muscles_W``, ``leg_muscles_W_per_kg`` (per kg of body mass), ``duration_s``,
        ``muscle_mass_rule``."""
        import pandas as pd

        return pd.DataFrame([{
            "model": model,
            "side": self.side or "",
            "leg_muscles_W": self.whole_body[model].leg_no_basal_mean_W,
            "leg_muscles_W_per_kg": self.whole_body[model].leg_no_basal_mean_W / self.body_mass_kg,
            "duration_s": self.whole_body[model].duration_s,
            "muscle_mass_rule": self.muscle_mass_rule,
        } for model in self.models])


def metabolics_from_solution(
    solution,
    body_mass_kg: float,
    height_m: float | None,
    *,
    models="all",
    muscle_parameters=None,
    basal: str = "body",
    trim: tuple[int, int] | None = None,
    model_options: Mapping[str, Mapping[str, object]] | None = None,
    muscle_masses_kg: Mapping[str, float] | None = None,
    slow_twitch_fractions: Mapping[str, float] | None = None,
    muscle_properties=None,
    strict: bool = False,
    cycle_duration_s: float | None = None,
    speed_m_per_s: float | None = None,
    require_success: bool = True,
    legs: int = 2,
    basal_rate_W_per_kg: float = BASAL_RATE_W_PER_KG,
    basal_exponent: float = 1.0,
    cycle_s: tuple[float, float] | None = None,
) -> SolutionMetabolics:
    """Metabolic rates of every muscle of a solution, for a set of models.

    Parameters
    ----------
    solution
        A solution folder, a :class:`musclemetab.redundancy.Solution` or :class:`SolutionStates`;
        a folder and the :class:`~musclemetab.redundancy.Solution` written to it give the same
        rates (the recorded gait cycle and leg are honoured both ways).
    body_mass_kg, height_m
        The subject (muscle masses from the volume rule of :mod:`musclemetab.properties`;
        whole-body rate per kg of body mass). ``height_m=None``: every muscle's mass from the
        model instead, ``F0 / sigma * rho * lMo`` (:func:`model_muscle_masses_kg`, the rule of
        OpenSim's metabolic probes); the outputs say which rule was used (``muscle_mass_rule``).
    models
        ``"all"`` (the six study models), ``"UM10,BH04"``, ``"all,LW05,MA68"`` or a list.
    muscle_parameters
        ``F0``, ``lMo``, ``vmax`` by muscle name: a
        :class:`musclemetab.model.MuscleParameters` (e.g. from
        :func:`musclemetab.model.read_muscle_parameters`) or ``{muscle: {name: value}}``.
        Default: the parameters recorded in the solution's ``summary.json``.
    basal
        Whole-body basal rule (:func:`whole_body_rate`): ``"body"`` (1.2 W/kg of body
        mass, the paper), ``"muscle"`` (1.2 W/kg of muscle mass in every muscle, the
        study's code) or ``"none"``. The per-muscle rates always carry the per-muscle
        ``basal`` component (the study's code), apart from the other components.
    basal_rate_W_per_kg, basal_exponent
        The basal rule as OpenSim's probes write it (``basal_coefficient``, ``basal_exponent``):
        ``basal_rate_W_per_kg * m_body^basal_exponent`` W under the ``"body"`` rule (defaults
        1.2 and 1: 1.2 W/kg). The coefficient is also the per-muscle basal heat, W per kg of
        *muscle* mass (the ``basal`` component, and the ``"muscle"`` rule); the exponent
        belongs to the ``"body"`` rule alone (another value with ``"muscle"`` is refused).
    trim
        Nodes dropped at the start and at the end. Default: every node outside the gait cycle
        ``cycle_s``; else, for a solve over a gait cycle found from ground forces
        (``summary.json`` ``window.gait_cycle``), every node outside that cycle; otherwise the
        study's (5, 6).
    cycle_s
        ``(start, end)`` (s) of the gait cycle the rates are averaged over (the cycle an analysis
        names, :func:`musclemetab.analysis.analyse`); the solved nodes must cover it (to within
        1.5 mesh steps at either end, :func:`musclemetab.events.coverage`), otherwise
        :class:`DataMismatchError`.
    legs
        Legs the solved muscles stand for in the whole-body rate: 2 (one leg solved, doubled)
        or 1 (each leg solved; add the legs, see :func:`add_legs`).
    model_options
        Per-model options, e.g. ``{"BH04": {"activation_heat_decay": False}}``.
    muscle_masses_kg, slow_twitch_fractions
        Overrides by muscle name (they take precedence over ``muscle_properties``).
    muscle_properties
        Override CSV path, :class:`musclemetab.properties.MuscleOverrides` or mapping
        (:func:`musclemetab.properties.read_muscle_properties`). Otherwise masses and
        slow-twitch fractions come from the anatomical muscle table; a muscle it cannot
        place takes ``F0 / sigma * rho * lMo`` and 0.5, named in one warning.
    strict
        Unplaced muscles raise :class:`~musclemetab.errors.UnknownMuscleError` instead.
    cycle_duration_s
        ``T`` of the whole-body average (default: the span of the kept nodes).
    speed_m_per_s
        Walking speed, for the cost of transport in the whole-body table.
    """
    from ..properties import as_overrides

    names = parse_models(models)
    if basal not in BASAL_RULES:
        raise OptionError(f"basal rule must be one of {', '.join(BASAL_RULES)}, not {basal!r}")
    check_basal_rule(basal_rate_W_per_kg, basal_exponent)
    if basal == "muscle" and basal_exponent != 1:
        raise OptionError(f"the basal exponent ({basal_exponent:g}) applies to the body basal rule only: the muscle "
                          "rule is linear in each muscle's mass; use basal 'body' or exponent 1")
    model_options = {k.upper(): dict(v) for k, v in (model_options or {}).items()}
    unknown = [k for k in model_options if k not in ALL_MODELS]
    if unknown:
        raise OptionError(f"options given for unknown model(s) {name_list(unknown)}; known: {', '.join(ALL_MODELS)}")
    sol = solution_states(solution, require_success=require_success)
    muscles = sol.muscles
    if muscle_parameters is not None:
        params = _parameters_for(muscles, muscle_parameters, "model")
    elif sol.parameters:
        params = _parameters_for(muscles, sol.parameters, "solution summary")
    else:
        raise OptionError(
            f"{sol.source or 'the solution'}: no muscle parameters recorded; pass muscle_parameters "
            "(e.g. read_muscle_parameters('model.osim'))"
        )
    n_nodes = sol.time_s.size
    for arg, arr in sol.states.items():
        if arr.shape != (len(muscles), n_nodes):
            raise DataMismatchError(
                f"solution state '{arg}' has shape {arr.shape}; expected (muscles, nodes) = ({len(muscles)}, {n_nodes})"
            )
    if trim is None and cycle_s is not None:
        from ..events import coverage

        coverage(sol.time_s, float(cycle_s[0]), float(cycle_s[1]), None,
                 f"{sol.source or 'the solution'}: the solved nodes")
    span = cycle_s if cycle_s is not None else sol.cycle_s
    if trim is None and span is not None:
        inside = np.flatnonzero((sol.time_s >= span[0] - 1e-9) & (sol.time_s <= span[1] + 1e-9))
        keep = trim_slice(n_nodes, int(inside[0]), n_nodes - 1 - int(inside[-1]))
    else:
        keep = trim_slice(n_nodes, *(trim if trim is not None else (5, 6)))
    time = sol.time_s[keep]
    states = {arg: arr[:, keep] for arg, arr in sol.states.items()}
    for arg, arr in states.items():  # named here, where the solution and the muscles are known
        bad = ~np.isfinite(arr)
        if bad.any():
            m, k = (int(i) for i in np.argwhere(bad)[0])
            raise DataMismatchError(
                f"{sol.source or 'the solution'}: '{arg}' of muscle {muscles[m]} is {arr[m, k]:g} at t = {time[k]:g} s "
                f"({int(bad.sum())} non-finite values); the solution is damaged or did not converge: solve again"
            )

    overrides = (as_overrides(muscle_properties).with_column("mass_kg", muscle_masses_kg)
                 .with_column("slow_twitch_fraction", slow_twitch_fractions))
    masses, fst = muscle_masses_and_fractions(muscles, body_mass_kg, height_m, params["max_isometric_force_N"],
                                              params["optimal_fiber_length_m"], overrides, strict=strict)

    inputs = dict(states)
    inputs.update(params)
    inputs.update(muscle_mass_kg=masses, slow_twitch_fraction=fst)
    rates = {}
    for name in names:
        opts = {"basal": True, "basal_rate_W_per_kg": float(basal_rate_W_per_kg)}
        opts.update(model_options.get(name, {}))
        try:
            rates[name] = ALL_MODELS[name](**inputs, time_s=time, **opts)
        except TypeError as exc:
            raise OptionError(f"{name}: invalid option ({exc})") from None
    wb = {
        name: whole_body_rate(r, time, body_mass_kg, basal=basal, basal_rate_W_per_kg=basal_rate_W_per_kg,
                              basal_exponent=basal_exponent, cycle_duration_s=cycle_duration_s, legs=legs)
        for name, r in rates.items()
    }
    return SolutionMetabolics(
        time_s=time,
        muscles=tuple(muscles),
        models=tuple(names),
        rates=rates,
        whole_body=wb,
        muscle_mass_kg=masses,
        slow_twitch_fraction=fst,
        parameters=params,
        body_mass_kg=float(body_mass_kg),
        height_m=None if height_m is None else float(height_m),
        basal_rule=basal,
        speed_m_per_s=None if speed_m_per_s is None else float(speed_m_per_s),
        source=sol.source,
        basal_rate_W_per_kg=float(basal_rate_W_per_kg),
        basal_exponent=float(basal_exponent),
        side=sol.side,
        solution_sha256=sol.solution_sha256,
    )


def write_metabolics(result: SolutionMetabolics, out_dir: str | os.PathLike, cycle=None) -> dict[str, Path]:
    """Write ``metabolics.sto``, ``whole_body.csv``, ``per_muscle.csv`` and, with the optional
    ``parquet`` extra installed, ``metabolics.parquet`` into ``out_dir``.

    ``cycle`` (a :class:`~musclemetab.analysis.GaitCycle`) adds the stance and swing
    energies to ``per_muscle.csv``. The files are written together
    (:func:`musclemetab.io.atomic_directory`).
    """
    from .per_muscle import PER_MUSCLE_FILE, per_muscle_table
    from ..io import atomic_directory, write_parquet, write_storage

    out_dir = Path(out_dir)
    comments = [
        f"models={','.join(result.models)}",
        f"body_mass_kg={result.body_mass_kg:g}",
        *([] if result.height_m is None else [f"height_m={result.height_m:g}"]),
        f"muscle_mass_rule={result.muscle_mass_rule}",
        f"basal_rule={result.basal_rule}",
        f"basal_coefficient={result.basal_rate_W_per_kg:g}",
        f"basal_exponent={result.basal_exponent:g}",
        *([f"muscle_parameters={result.muscle_parameters}"] if result.muscle_parameters else []),
        *([f"solution_sha256={result.solution_sha256}"] if result.solution_sha256 else []),
        f"units=W; total_no_basal is without basal heat, basal the per-muscle basal heat "
        f"({result.basal_rate_W_per_kg:g} W/kg of muscle mass), apart",
    ]
    with atomic_directory(out_dir, mark=True) as tmp:
        write_storage(tmp / METABOLICS_STO, result.to_dataframe(), name="musclemetab metabolic rates",
                      in_degrees=False, comments=comments)
        parquet = write_parquet(result.to_long(), tmp / METABOLICS_PARQUET)
        one_leg = any(wb.legs != 2 for wb in result.whole_body.values())
        table, name = (result.leg_table(), LEG_CSV) if one_leg else (result.whole_body_table(), WHOLE_BODY_CSV)
        table.to_csv(tmp / name, index=False, float_format="%.10g")
        per_muscle_table(result, cycle).to_csv(tmp / PER_MUSCLE_FILE, index=False, float_format="%.10g")
    files = {
        "metabolics_sto": out_dir / METABOLICS_STO,
        ("leg_muscles_csv" if one_leg else "whole_body_csv"): out_dir / name,
        "per_muscle_csv": out_dir / PER_MUSCLE_FILE,
    }
    if parquet is not None:
        files["metabolics_parquet"] = out_dir / METABOLICS_PARQUET
    return files


def add_legs(results: Mapping[str, SolutionMetabolics]) -> dict[str, float]:
    """Whole-body rate (W/kg) of both legs solved separately: the legs' cycle averages added.

    ``results`` maps the side (``"r"``, ``"l"``) to its :class:`SolutionMetabolics`, each
    computed with ``legs=1`` for the same subject and basal rule (coefficient and exponent
    included). Each leg's muscles are averaged over that leg's own cycle; the basal heat of the
    ``"body"`` rule (:attr:`WholeBodyRate.basal_W_per_kg`) is added once.
    """
    res = list(results.values())
    if not res:
        raise OptionError("no leg to add")
    if any(wb.legs != 1 for r in res for wb in r.whole_body.values()):
        raise OptionError("add_legs needs each leg's metabolics computed with legs=1")
    first = res[0]
    for r in res[1:]:
        if (r.body_mass_kg != first.body_mass_kg or r.basal_rule != first.basal_rule or r.models != first.models
                or any(r.whole_body[m].basal_W_per_kg != first.whole_body[m].basal_W_per_kg for m in r.models)):
            raise DataMismatchError("the legs were evaluated with different body mass, basal rule (coefficient, "
                                    "exponent) or models; evaluate both with the same settings")
    return {
        m: sum(r.whole_body[m].one_leg_mean_W for r in res) / first.body_mass_kg + first.whole_body[m].basal_W_per_kg
        for m in first.models
    }


def solution_folders(path: str | os.PathLike) -> dict[str, Path]:
    """``{side: folder}`` of a solution folder (side ``"r"``/``"l"`` as its summary records it,
    else ``""``) or of the parent of per-leg solution folders ``r/`` and ``l/`` written by
    ``musclemetab solve --side both``.

    Raises :class:`~musclemetab.errors.InputFileError` when ``path`` is neither.
    """
    from ..errors import InputFileError
    from ..io import read_json_object

    path = Path(path)
    if (path / SUMMARY_FILE).is_file():
        return {_recorded_side(read_json_object(path / SUMMARY_FILE)) or "": path}
    found = {s: path / s for s in ("r", "l") if (path / s / SUMMARY_FILE).is_file()}
    if not found:
        trials = sorted(p.parent for p in path.glob(f"*/{SUMMARY_FILE}")) if path.is_dir() else []
        if trials:  # the result of several trials (EMG-TEN, estimate): one solution folder per trial
            names = ", ".join(map(str, trials[:3])) + (", ..." if len(trials) > 3 else "")
            raise InputFileError(f"{path}: a result of several trials, one solution folder each; give one of them "
                                 f"({names})")
        raise InputFileError(
            f"{path}: neither a solution folder (summary.json) nor a folder of per-leg solutions (r/, l/); "
            "give the folder written by musclemetab solve"
        )
    return found


def _legs_of(solutions) -> dict:
    """``{side: solution}`` of a mapping, a parent folder of per-leg solutions or one solution."""
    if isinstance(solutions, Mapping):
        if not solutions:
            raise OptionError("no leg's solution given")
        return dict(solutions)
    if isinstance(solutions, (str, os.PathLike)):
        return solution_folders(solutions)
    summary = getattr(solutions, "summary", None)
    side = _recorded_side(summary) if isinstance(summary, Mapping) else getattr(solutions, "side", None)
    return {side or "": solutions}


def metabolics_from_legs(solutions, body_mass_kg: float, height_m: float | None, **options) -> dict[str, SolutionMetabolics]:
    """Metabolic rates of the legs of a trial: ``{side: SolutionMetabolics}``.

    ``solutions`` is one solution (folder, :class:`musclemetab.redundancy.Solution` or
    :class:`SolutionStates`), the parent folder of per-leg solution folders ``r/`` and ``l/``
    (``musclemetab solve --side both``) or a mapping ``{side: solution}`` (what
    :func:`musclemetab.redundancy.solve_sides` returns). One leg stands for both in the
    whole-body rate (``legs=2``); two legs are each evaluated over their own cycle with
    ``legs=1``, for :func:`add_legs`. The other ``options`` are those of
    :func:`metabolics_from_solution`; the muscles the anatomical muscle table cannot place are
    named in one warning for all legs.
    """
    import warnings

    from ..errors import MuscleTableWarning
    from ..properties import unplaced_muscles, warn_unplaced

    if "legs" in options:
        raise OptionError("metabolics_from_legs sets legs itself (2 for one leg, 1 for each of two)")
    legs = _legs_of(solutions)
    results = {}
    with warnings.catch_warnings():  # one warning for every leg, below
        warnings.simplefilter("ignore", MuscleTableWarning)
        for side, solution in legs.items():
            results[side] = metabolics_from_solution(solution, body_mass_kg, height_m,
                                                     legs=1 if len(legs) > 1 else 2, **options)
    if not options.get("strict"):
        from ..properties import as_overrides

        overrides = (as_overrides(options.get("muscle_properties"))
                     .with_column("mass_kg", options.get("muscle_masses_kg"))
                     .with_column("slow_twitch_fraction", options.get("slow_twitch_fractions")))
        warn_unplaced(list(dict.fromkeys(
            m for r in results.values() for m in unplaced_muscles(r.muscles, overrides))))
    return results


def write_legs_metabolics(results: Mapping[str, SolutionMetabolics], out_dir: str | os.PathLike,
                          cycle=None) -> dict[str, Path]:
    """Write the results of :func:`metabolics_from_legs`: one leg as :func:`write_metabolics`
    into ``out_dir``; two legs each into ``out_dir/<side>`` (its muscles alone, no basal heat:
    ``leg_muscles.csv``, no whole-body file) and, in ``out_dir/whole_body.csv``, one row per
    model of the legs added (:func:`add_legs`): ``model``, ``legs`` (``r+l``),
    ``whole_body_W_per_kg``, ``whole_body_no_basal_W_per_kg``, ``basal_rule``, ``basal_W_per_kg``,
    ``muscle_mass_rule`` and ``<side>_leg_muscles_W`` (each leg, no basal; :func:`legs_table`).
    Returns the files written (by name)."""
    from ..io import atomic_path

    out_dir = Path(out_dir)
    if len(results) == 1:
        (result,) = results.values()
        return write_metabolics(result, out_dir, cycle=cycle)
    files = {}
    for side, result in results.items():
        files.update({f"{side}/{k}": v for k, v in write_metabolics(result, out_dir / side, cycle=cycle).items()})
    with atomic_path(out_dir / WHOLE_BODY_CSV, mark=True) as tmp:
        legs_table(results).to_csv(tmp, index=False, float_format="%.10g")
    files["whole_body_csv"] = out_dir / WHOLE_BODY_CSV
    return files


def legs_table(results: Mapping[str, SolutionMetabolics]):
    """The whole-body table of two legs evaluated apart (:func:`metabolics_from_legs`), one row
    per model of the legs added (:func:`add_legs`): ``model``, ``legs`` (``r+l``),
    ``whole_body_W_per_kg``, ``whole_body_no_basal_W_per_kg``, ``basal_rule``, ``basal_W_per_kg``,
    ``muscle_mass_rule`` and ``<side>_leg_muscles_W`` (each leg, no basal)."""
    import pandas as pd

    first = next(iter(results.values()))
    return pd.DataFrame([{
        "model": m, "legs": "+".join(results), "whole_body_W_per_kg": v,
        "whole_body_no_basal_W_per_kg": sum(r.whole_body[m].leg_no_basal_mean_W for r in results.values())
        / first.body_mass_kg,
        "basal_rule": first.basal_rule, "basal_W_per_kg": first.whole_body[m].basal_W_per_kg,
        "muscle_mass_rule": first.muscle_mass_rule,
        **{f"{s}_leg_muscles_W": r.whole_body[m].leg_no_basal_mean_W for s, r in results.items()},
    } for m, v in add_legs(results).items()])


def parameter_differences(states: SolutionStates, muscle_parameters, rtol: float = 1e-6) -> list[str]:
    """The muscle parameters (``F0``, ``lMo``, ``vmax``) of ``muscle_parameters`` (a
    :class:`musclemetab.model.MuscleParameters`) that differ from those the solve recorded, one
    ``"<muscle> <parameter> <solution value> (solution) vs <value> (model)"`` each."""
    pos = {n: i for i, n in enumerate(muscle_parameters.names)}
    differ = []
    for m, rec in states.parameters.items():
        if m not in pos:
            continue
        for k, v in rec.items():
            ref = float(np.asarray(getattr(muscle_parameters, k))[pos[m]])
            if not np.isclose(v, ref, rtol=rtol, atol=0.0):
                differ.append(f"{m} {k} {v:g} (solution) vs {ref:g} (model)")
    return differ


#: the settings :func:`write_metabolics` records in the header of metabolics.sto, and their types
METABOLICS_SETTINGS = {"models": str, "body_mass_kg": float, "height_m": float, "basal_rule": str,
                       "basal_coefficient": float, "basal_exponent": float, "muscle_mass_rule": str,
                       "muscle_parameters": str, "solution_sha256": str}


def check_metabolics_of(solution_dir: str | os.PathLike, metabolics_dir: str | os.PathLike | None,
                        settings: Mapping | None = None) -> str:
    """SHA-256 of the ``solution.sto`` of ``solution_dir``; :class:`DataMismatchError` when the
    metabolics folder ``metabolics_dir`` (its :func:`read_metabolics_settings`, or ``settings``)
    records the rates of another solution: the solution solved again since ``metabolics`` ran, or
    another trial's or leg's folder given. A folder written by an earlier version records none and
    passes."""
    from ..io.atomic import file_sha256

    digest = file_sha256(Path(solution_dir) / SOLUTION_FILE)
    if metabolics_dir is not None:
        settings = read_metabolics_settings(metabolics_dir) if settings is None else settings
        if settings.get("solution_sha256", digest) != digest:
            raise DataMismatchError(
                f"{metabolics_dir}: its rates are of another solution than {solution_dir}'s (solved again since "
                f"'musclemetab metabolics' wrote it, or another trial or leg); run 'musclemetab metabolics --solution "
                f"{solution_dir} --out {metabolics_dir}' again, or give the metabolics folder of this solution")
    return digest


def read_metabolics_settings(folder: str | os.PathLike) -> dict:
    """The settings recorded in the header of a metabolics folder's ``metabolics.sto``
    (:func:`write_metabolics`): those of :data:`METABOLICS_SETTINGS` it holds, e.g.
    ``{"models": "UM10,BH04", "body_mass_kg": 72.6, ..., "basal_rule": "body"}``."""
    from ..errors import InputFileError

    path = Path(folder) / METABOLICS_STO
    if not path.is_file():
        raise InputFileError(f"{path}: missing; give the folder written by 'musclemetab metabolics' as --metabolics")
    out = {}
    with path.open(encoding="utf-8", errors="replace") as f:
        for line in f:
            line = line.strip()
            if line == "endheader":
                break
            key, _, value = line.partition("=")
            if key in METABOLICS_SETTINGS and value:
                try:
                    out[key] = METABOLICS_SETTINGS[key](value)
                except ValueError:
                    raise InputFileError(f"{path}: '{key}={value}' in the header is not a number; write the "
                                         "folder again with 'musclemetab metabolics'") from None
    return out
