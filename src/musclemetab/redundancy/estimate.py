"""Estimation of muscle-tendon parameters over one or several trials (the problem core with
shared scale factors), and the validation re-solve with the estimates.

Scale factors of the tendon stiffness ``kT``, the optimal fiber length ``lMo`` and the tendon
slack length ``lTs`` of named muscles are variables of one problem over all trials
(:mod:`.transcription`); muscles of a coupled group share one factor. Measured fiber lengths
(ultrasound; :func:`read_fiber_lengths`: MRS file convention, millimetres) enter as the
fiber-length tracking goal ``wUS sum ((l~M s_lMo lMo - lUS)/lMo)^2/(nUS N)``, EMG as the EMG
goals. The estimate (:class:`EstimatedParameters`) gives the scaled parameters for a validation
re-solve with the effort goals only (:func:`~.solve.solve_with_parameters`), as the
MuscleRedundancySolver does after its estimation.

Default bounds of the factors: ``kT`` 0.1 ... 2, ``lMo`` and ``lTs`` 0.5 ... 1.5.

Couplings (:func:`parameter_specs`) are groups of muscles sharing one factor of every estimated
kind, or of one kind (``{"kind": "tendon_stiffness", "muscles": [...]}``, on the command line
``tendon_stiffness:soleus_r,gasmed_r``; :func:`parse_coupling`).

The estimate comes with its doubts (:mod:`.identifiability`, ``docs/problem.md``): factors on
(within :data:`~.identifiability.BOUND_TOLERANCE` of) a bound, factors of muscles no measurement
informs (refused), fiber-length bounds widened by the factor bounds beyond
:data:`FIBER_LENGTH_WIDENING_LIMIT`, and the standard errors and correlations at the optimum;
each is warned (one line) and recorded under ``doubts``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from ..errors import DataMismatchError, InputFileError, OptionError, UnknownMuscleError
from ..messages import name_list
from .transcription import Goals, ParameterSpec, TrialBlock
from .parameters import MuscleTendonParameters
from .ipopt import ProblemResult, SolverOptions, solve_problem
from .record import ProblemRecord

__all__ = ["EstimatedParameters", "DEFAULT_FACTOR_BOUNDS", "estimate_parameters", "parameter_specs",
           "fiber_length_trial", "read_fiber_lengths", "parse_coupling", "widened_fiber_bounds",
           "FIBER_LENGTH_WIDENING_LIMIT"]

#: bounds of the scale factors by kind
DEFAULT_FACTOR_BOUNDS = {"tendon_stiffness": (0.1, 2.0), "optimal_fiber_length": (0.5, 1.5),
                         "tendon_slack_length": (0.5, 1.5)}
#: the parameter field each kind of factor scales
FIELDS = {"tendon_stiffness": "tendon_stiffness", "optimal_fiber_length": "optimal_fiber_length_m",
          "tendon_slack_length": "tendon_slack_length_m"}
#: upper bound of the normalised fiber length (optimal lengths) beyond which a widening of the
#: fiber-length bounds by the factors' lower bounds (:func:`.bounds.fiber_length_upper_bounds`)
#: is warned: the problem's box then admits fibers far longer than muscles reach; raise the
#: lower bound of the ``lMo`` or ``lTs`` factor to narrow it
FIBER_LENGTH_WIDENING_LIMIT = 3.0


@dataclass(frozen=True)
class EstimatedParameters:
    """Estimated scale factors (``{kind: {muscle: factor}}``) on ``nominal`` parameters, the
    solve's ``record`` and the estimate's ``doubts`` (:func:`estimate_parameters`)."""

    factors: dict
    nominal: MuscleTendonParameters
    record: ProblemRecord = field(default_factory=ProblemRecord)
    #: what makes the estimate doubtful (:func:`estimate_parameters`)
    doubts: dict = field(default_factory=dict)

    def parameters(self) -> MuscleTendonParameters:
        """The nominal parameters with the estimated factors applied (for a validation re-solve)."""
        p = self.nominal
        for kind, by_muscle in self.factors.items():
            if kind in FIELDS:
                base = getattr(self.nominal, FIELDS[kind])
                p = p.replace(**{FIELDS[kind]: {m: float(base[self.nominal.names.index(m)] * s)
                                                for m, s in by_muscle.items()}})
        return p

    def values(self) -> dict:
        """``{kind: {muscle: estimated value}}`` (kT dimensionless, lengths in m)."""
        est = self.parameters()
        return {kind: {m: float(getattr(est, FIELDS[kind])[est.names.index(m)]) for m in by_muscle}
                for kind, by_muscle in self.factors.items() if kind in FIELDS}

    def to_dict(self) -> dict:
        return {"factors": {k: dict(v) for k, v in self.factors.items()}, "values": self.values(),
                "solve": self.record.to_dict(), "doubts": dict(self.doubts)}


def parse_coupling(text: str) -> dict:
    """A coupling of the command line: ``"MUSCLE,MUSCLE[,...]"`` (every estimated kind) or
    ``"KIND:MUSCLE,MUSCLE[,...]"`` (that kind alone), as ``{"kind": KIND or None, "muscles": [...]}``."""
    kind, sep, rest = str(text).rpartition(":")
    muscles = [m.strip() for m in (rest if sep else text).split(",") if m.strip()]
    return {"kind": kind.strip() if sep else None, "muscles": muscles}


def _coupling(group) -> tuple[str | None, tuple[str, ...]]:
    if isinstance(group, str):
        group = parse_coupling(group)
    if isinstance(group, Mapping):
        extra = set(group) - {"kind", "muscles"}
        muscles = group.get("muscles")
        if extra or not isinstance(muscles, (list, tuple)) or not all(isinstance(m, str) for m in muscles):
            raise OptionError(f"a coupling must name its muscles, as {{kind = \"tendon_stiffness\", muscles = "
                              f"[\"soleus_r\", \"gasmed_r\"]}}, not {dict(group)!r}")
        kind = group.get("kind")
        if kind is not None and kind not in (*FIELDS, "emg_scale"):
            raise OptionError(f"a coupling of '{kind}': couple one of {', '.join((*FIELDS, 'emg_scale'))} "
                              "(e.g. --couple tendon_stiffness:soleus_r,gasmed_r)")
        return kind, tuple(muscles)
    return None, tuple(str(m) for m in group)


def check_couplings(estimate: Mapping[str, Sequence[str]], groups) -> None:
    """Raise :class:`OptionError` for a coupled group (``--couple``, ``couple``; ``groups`` as
    ``(kind or None, muscles)``) with fewer than two muscles, or, for a group of every estimated
    kind, with a muscle no kind of ``estimate`` names or muscles estimated for different kinds
    (the group shares one factor of each kind, so its muscles must all be estimated for it)."""
    for kind, group in groups:
        group = list(dict.fromkeys(str(m) for m in group))
        label = f"{kind + ':' if kind else ''}{','.join(group)}"
        if len(group) < 2:
            raise OptionError(f"--couple {label}: a coupled group needs two or more muscles")
        if kind is not None:
            continue
        kinds = {m: sorted(k for k, ms in estimate.items() if m in ms) for m in group}
        alone = [m for m, k in kinds.items() if not k]
        if alone:
            raise OptionError(f"--couple {label}: {name_list(alone)} is estimated for no kind (--estimate names "
                              f"{', '.join(sorted({x for ms in estimate.values() for x in ms}))}); add it to "
                              "--estimate or drop it from the group")
        if len({tuple(k) for k in kinds.values()}) > 1:
            listed = "; ".join(f"{m}: {', '.join(k)}" for m, k in kinds.items())
            raise OptionError(f"--couple {label}: the muscles of a group share one factor of each kind, so they must "
                              f"be estimated for the same kinds ({listed}); estimate them alike, split the group or "
                              "couple one kind (KIND:MUSCLE,MUSCLE)")


def parameter_specs(estimate: Mapping[str, Sequence[str]], couple: Sequence = (),
                    bounds: Mapping[str, tuple[float, float]] | None = None) -> list[ParameterSpec]:
    """Shared factors of ``estimate`` (``{kind: [muscle, ...]}``). A group of ``couple`` is a
    list of muscles sharing one factor of every kind that names two or more of them, or
    ``{"kind": KIND, "muscles": [...]}`` (or ``"KIND:M1,M2"``) sharing the factor of ``KIND``
    alone, all of whose muscles must be estimated in that kind."""
    bounds = {**DEFAULT_FACTOR_BOUNDS, **(bounds or {})}
    groups = [_coupling(g) for g in couple]
    check_couplings(estimate, groups)
    for kind, members in groups:
        if kind in FIELDS:
            missing = [m for m in members if m not in estimate.get(kind, ())]
            if missing:
                raise OptionError(f"--couple {kind}:{','.join(members)}: the {kind} of {name_list(missing)} is not "
                                  f"estimated; add it to --estimate {kind}=... or drop it from the coupling")
    specs = []
    for kind, muscles in estimate.items():
        if kind not in FIELDS:
            raise OptionError(f"cannot estimate '{kind}'; estimate one of {', '.join(FIELDS)}")
        muscles = tuple(dict.fromkeys(str(m) for m in muscles))
        pos = {m: i for i, m in enumerate(muscles)}
        pairs = []
        for gkind, group in groups:
            if gkind not in (None, kind):
                continue
            members = [pos[m] for m in group if m in pos]
            pairs += [(a, b) for a, b in zip(members[:-1], members[1:])]
        specs.append(ParameterSpec(kind, muscles, bounds[kind], tuple(dict.fromkeys(pairs))))  # no pair twice
    return specs


def emg_couplings(couple: Sequence) -> list[tuple[str, ...]] | None:
    """The groups of ``couple`` of kind ``emg_scale`` (muscles sharing one EMG scale factor), or
    ``None`` when it has none (the EMG-TEN groups then apply)."""
    groups = [members for kind, members in (_coupling(g) for g in couple) if kind == "emg_scale"]
    return groups or None


def widened_fiber_bounds(trials, params: MuscleTendonParameters, specs) -> dict:
    """``{trial: {muscle: upper bound}}`` of the fiber-length bounds that the factors' lower
    bounds widen beyond those of the nominal parameters (:func:`.bounds.fiber_length_upper_bounds`)."""
    from .bounds import fiber_length_upper_bounds

    out = {}
    for t in trials:
        nominal = fiber_length_upper_bounds(t.inputs, params)
        wide = fiber_length_upper_bounds(t.inputs, params, specs)
        moved = {m: float(u) for m, u, u0 in zip(t.inputs.muscles, wide, nominal) if u > u0}
        if moved:
            out[t.label] = moved
    return out


def read_fiber_lengths(path) -> dict:
    """Measured fiber lengths of an MRS-convention file (a storage file with ``time`` in s
    and one column per muscle in mm): ``{muscle: (time s, length m)}``."""
    from pathlib import Path

    from ..io import read_storage

    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: no such fiber-length file; check the --ultrasound paths")
    df = read_storage(path)
    out = {}
    for m in df.columns:
        v = df[m].to_numpy(dtype=float)
        if not np.all(np.isfinite(v)) or np.any(v <= 0):
            raise DataMismatchError(f"{path}: column {m} holds non-positive or non-finite fiber lengths; "
                                    "give lengths in mm")
        if np.median(v) < 5.0:
            raise DataMismatchError(f"{path}: column {m} has a median of {np.median(v):.3g}, not a fiber length "
                                    "in mm (MRS convention); convert metres to millimetres")
        out[str(m)] = (df.index.to_numpy(dtype=float), v / 1000.0)
    return out


def fiber_length_trial(label: str, inputs, guess, fiber_lengths: Mapping[str, tuple], *,
                       emg_muscles=(), emg_nodes=None) -> TrialBlock:
    """A trial with measured fiber lengths (``{muscle: (time s, length m)}``, linearly
    interpolated at the nodes ``0 ... N-1``, which they must cover)."""
    N = inputs.n_intervals
    t = inputs.mesh_time_s[:N]
    unknown = [m for m in fiber_lengths if m not in inputs.muscles]
    if unknown:
        raise UnknownMuscleError(f"trial {label}: fiber lengths of {name_list(unknown)}, which the problem does "
                                 f"not have ({', '.join(inputs.muscles[:6])} ...); name model muscles")
    cols = []
    for m, (tm, lm) in fiber_lengths.items():
        tm = np.asarray(tm, dtype=float)
        if tm[0] > t[0] + 1e-9 or tm[-1] < t[-1] - 1e-9:
            raise DataMismatchError(f"trial {label}: the fiber lengths of {m} cover {tm[0]:g}-{tm[-1]:g} s, not the "
                                    f"window {t[0]:g}-{t[-1]:g} s; give measurements over the whole window")
        cols.append(np.interp(t, tm, np.asarray(lm, dtype=float)))
    return TrialBlock(label, inputs, guess, emg_muscles=tuple(emg_muscles), emg_nodes=emg_nodes,
                      fiber_muscles=tuple(fiber_lengths), fiber_length_nodes_m=np.column_stack(cols) if cols else None)


def estimate_parameters(trials: Sequence[TrialBlock], params: MuscleTendonParameters, specs, goals: Goals, *,
                        options: SolverOptions | None = None, coupling: str = "shared", uninformed: str = "error",
                        identify: bool = True) -> tuple[ProblemResult, EstimatedParameters]:
    """Solve the problem of ``trials`` with the shared factors ``specs`` and ``goals``; returns
    the raw result and the estimate (also when IPOPT did not converge: see ``result.success``).

    Before the solve, factors no measurement informs are refused (``uninformed="error"``) or
    warned about (``"warn"``), and fiber-length bounds widened beyond
    :data:`FIBER_LENGTH_WIDENING_LIMIT` are warned about; after a successful one, factors on a
    bound and (``identify``) poorly identifiable parameters. All are recorded in the estimate's
    ``doubts`` (``on_bounds``, ``uninformed``, ``widened_fiber_length_bounds``, ``identifiability``).
    ``goals`` without fiber dynamics get the forward ones (:meth:`.goals.Goals.resolved`; an
    estimation with EMG in the driven mode resolves them for its mode first, as
    :func:`.estimate_run.estimate_files` does)."""
    import warnings

    from ..errors import MusclemetabWarning
    from . import identifiability as ident

    if uninformed not in ("error", "warn"):
        raise OptionError(f"uninformed must be 'error' or 'warn', not {uninformed!r}")
    if not any(s.kind in FIELDS for s in specs):
        raise OptionError("nothing to estimate: name muscles whose tendon_stiffness, optimal_fiber_length or "
                          "tendon_slack_length is estimated")
    if not any(t.fiber_muscles or t.emg_muscles for t in trials):
        raise OptionError("parameter estimation needs measurements: give fiber lengths (ultrasound) or EMG")
    options, goals = options or SolverOptions(), goals.resolved()
    doubts = {"uninformed": [{"kind": k, "muscle": m} for k, m in ident.check_informed(trials, specs, uninformed)]}
    widened = widened_fiber_bounds(trials, params, specs)
    doubts["widened_fiber_length_bounds"] = {"limit": FIBER_LENGTH_WIDENING_LIMIT, "upper": widened}
    for label, by_muscle in widened.items():
        beyond = {m: u for m, u in by_muscle.items() if u > FIBER_LENGTH_WIDENING_LIMIT}
        if beyond:
            kinds = sorted({s.kind for s in specs if s.kind in ("optimal_fiber_length", "tendon_slack_length")
                            and set(s.muscles) & set(beyond)})
            warnings.warn(f"trial {label}: the lower bounds of the {' and '.join(kinds)} factors widen the fiber-length "
                          f"bounds beyond {FIBER_LENGTH_WIDENING_LIMIT:g} lMo ("
                          + ", ".join(f"{m} {u:.2f}" for m, u in beyond.items())
                          + "); raise those lower bounds (--bounds KIND=LOW:HIGH) to keep the fibers physiological",
                          MusclemetabWarning, stacklevel=2)
    res = solve_problem(trials, params, goals, specs, options=options, coupling=coupling)
    factors = {k: v for k, v in res.factors.items() if k in FIELDS}
    record = {"status": res.status, "success": res.success, "iterations": res.iterations,
              "objective": res.objective, "objective_terms": res.objective_terms,
              "max_constraint_violation": res.max_constraint_violation,
              "bounds": {s.kind: list(s.bounds) for s in specs}, "max_coupling_violation": res.max_coupling_violation}
    if res.success:
        on_bounds = ident.factors_on_bounds(res.factors, {s.kind: s.bounds for s in specs})
        ident.warn_on_bounds(on_bounds)
        doubts["on_bounds"] = on_bounds
        doubts["bound_tolerance"] = ident.BOUND_TOLERANCE
        if identify:
            report = ident.identifiability(trials, params, goals, specs, res, coupling=coupling,
                                           optimal_reserve_Nm=options.optimal_reserve_Nm)
            ident.warn_identifiability(report)
            doubts["identifiability"] = report
    return res, EstimatedParameters(factors=factors, nominal=params, record=ProblemRecord.from_dict(record),
                                    doubts=doubts)


def tendon_strain_at_one_norm_force(kT) -> float:
    """Tendon strain where the tendon force-length curve of stiffness ``kT`` reaches F0
    (``fT = 1``): ``ln(5 (1.25 - shift(kT)))/kT - 0.005``, the parameter OpenSim's muscle
    types take for the tendon stiffness (``docs/problem.md``)."""
    from ..muscle import tendon_length_from_force

    return float(tendon_length_from_force(1.0, float(kT))) - 1.0


def write_personalised_model(model_path, params: MuscleTendonParameters, estimated: Mapping[str, Sequence[str]],
                             out_dir) -> tuple:
    """Write ``out_dir/<model>_personalised.osim``: the model with the ``estimated`` values
    (``{kind: [muscle, ...]}``) of ``params``: optimal fiber length and tendon slack length, and
    the tendon stiffness as the tendon strain at F0 where the muscle type has that parameter
    (Thelen2003, Millard2012, DeGrooteFregly2016; others are reported under ``not_set``).
    Returns ``(path, {muscle: {class_name, set, not_set}})``; the file appears whole or not at all."""
    from pathlib import Path

    from ..io import atomic_path
    from ..opensim_bridge.client import call

    values = {}
    for kind, muscles in estimated.items():
        for m in muscles:
            i = params.names.index(m)
            v = values.setdefault(m, {})
            if kind == "optimal_fiber_length":
                v["optimal_fiber_length_m"] = float(params.optimal_fiber_length_m[i])
            elif kind == "tendon_slack_length":
                v["tendon_slack_length_m"] = float(params.tendon_slack_length_m[i])
            elif kind == "tendon_stiffness":
                v["tendon_strain_at_one_norm_force"] = tendon_strain_at_one_norm_force(params.tendon_stiffness[i])
    model_path, out_dir = Path(model_path), Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / f"{model_path.stem}_personalised.osim"
    with atomic_path(target, mark=True) as tmp:
        report = call("personalise:write_model_with_parameters", str(model_path.resolve()), str(tmp), values)
    return target, report
