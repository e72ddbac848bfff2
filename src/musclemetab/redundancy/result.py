"""The result of a problem over one or more trials: the solutions, the parameters it estimated
and ``parameters.json`` (:class:`Result`; EMG-TEN, EMG-informed solves and parameter estimation).

**Tendon stiffness in N/mm.** ``kT`` is dimensionless; the stiffness reported in N/mm is the
tangent slope of the tendon force-length curve where the tendon carries its maximal isometric
force ``F0`` (``fT = 1``)::

    k = dFT/dlT |_(fT = 1) = F0 kT (1.25 - shift(kT)) / lTs

(``docs/method.md``: ``dFT/dlT = F0 kT exp(kT (l~T - 0.995))/(5 lTs)`` and
``exp(kT (l~T - 0.995))/5 = fT + 0.25 - shift``). The slope at each trial's peak walking
tendon force is reported too. The Achilles tendon stiffness is the sum over the muscles of
the Achilles tendon in the anatomical muscle table (three tendons in parallel on the example).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..muscle import KT_GENERIC, tendon_length_from_force, tendon_stiffness_N_per_m
from .parameters import MuscleTendonParameters
from .record import ProblemRecord
from ..io.jsonfile import json_ready

__all__ = ["EMG_TEN", "Result", "EmgTenResult", "assemble_result", "PARAMETERS_FILE",
           "tendon_stiffness_at_force_N_per_mm"]

EMG_TEN = "emg-ten"
PARAMETERS_FILE = "parameters.json"
PARAMETERS_FORMAT = "musclemetab.redundancy.emg_ten_parameters"
PARAMETERS_VERSION = 1
#: ``format`` of the ``parameters.json`` of a parameter estimation (``musclemetab estimate``)
ESTIMATE_FORMAT = "musclemetab.redundancy.estimated_parameters"


def tendon_stiffness_at_force_N_per_mm(force_norm, max_isometric_force_N, tendon_slack_length_m, kT):
    """Tangent slope ``dFT/dlT`` (N/mm) of the tendon curve where ``FT = force_norm F0``.

    With ``force_norm = 1``: ``F0 kT (1.25 - shift(kT)) / lTs`` (the module's definition of
    the stiffness in N/mm).
    """
    lt = tendon_length_from_force(np.asarray(force_norm, dtype=float), kT)
    return tendon_stiffness_N_per_m(lt, max_isometric_force_N, tendon_slack_length_m, kT) / 1000.0


@dataclass
class Result:
    """Solutions of all trials of one problem and the parameters it estimated.

    ``solutions`` maps the trial labels (IK file stems by default) to :class:`~.solution.Solution`
    objects in the solver's format, computed with the estimated parameters; ``parameters`` are
    those parameters (the estimates applied to the nominal ones). ``factors`` holds the estimated
    scale factors by kind and muscle (``tendon_stiffness``, ``optimal_fiber_length``,
    ``tendon_slack_length``, ``emg_scale``); ``record`` the solve record
    (:class:`~.record.ProblemRecord`); ``emg_channels`` the
    EMG channels of the tracked muscles; ``settings`` the :class:`~.emg_ten.EmgTenSettings` of an
    EMG-TEN or EMG-informed problem. ``document``: the content of ``parameters.json`` when it is
    fixed when the result is assembled (parameter estimation); ``None`` (EMG-TEN): built from
    the fields by :meth:`parameters_document`.

    :meth:`write` writes one solution folder per trial and ``parameters.json``; :meth:`load`
    reads them back.
    """

    solutions: dict
    parameters: MuscleTendonParameters
    factors: dict
    record: ProblemRecord
    emg_channels: dict = field(default_factory=dict)
    settings: object = None
    document: dict | None = field(default=None, repr=False)
    trials: tuple = field(default=(), repr=False)
    #: the :class:`~.problem.Problem` solved (:func:`.problem.solve`), or ``None``
    problem: "Problem | None" = field(default=None, repr=False, compare=False)  # noqa: F821 (a layer above)

    #: trials a printed summary lists one by one
    TRIALS_SHOWN = 8

    def __repr__(self) -> str:
        """A summary of at most about 20 lines (workflow, trials with their muscles x nodes, IPOPT's
        outcome, the stop and the rates' convergence, the estimated factors), not the arrays."""
        from ..messages import name_list

        rec = self.record
        lines = [f"Result{f' ({rec.workflow})' if rec.workflow else ''}: {len(self.solutions)} trial"
                 f"{'s' if len(self.solutions) != 1 else ''}, {len(self.parameters.names)} muscles",
                 *(f"  {line}" for line in rec.outcome_lines())]
        for kind, values in self.factors.items():
            if values:
                shown = name_list([f"{m} x{v:.3g}" for m, v in values.items()], 4)
                lines.append(f"  estimated {kind} ({len(values)}): {shown}")
        for label, sol in list(self.solutions.items())[:self.TRIALS_SHOWN]:
            t = sol.time_s
            flags = sol.record.plausibility
            quality = "" if flags is None else f", {len(flags)} plausibility flag{'s' if len(flags) != 1 else ''}"
            lines.append(f"  trial {label}: {len(sol.muscles)} muscles x {t.size} nodes ({t[0]:.3f}-{t[-1]:.3f} s)"
                         f"{quality}")
        if len(self.solutions) > self.TRIALS_SHOWN:
            lines.append(f"  ... and {len(self.solutions) - self.TRIALS_SHOWN} more trials")
        lines.append("  solutions[label] (Solution), parameters, factors; write(folder), to_mat(path)")
        return "\n".join(lines)

    __str__ = __repr__

    def to_mat(self, path) -> "Path":
        """Write the result to the MATLAB file ``path`` (:mod:`musclemetab.io.matlab`; the
        layout: ``docs/matlab.md``): ``trials`` (the labels), one solution struct per trial
        (field: the label as a MATLAB name), ``estimated`` (per kind of factor: ``muscles`` and
        ``factor``) and the problem's ``solve`` outcome."""
        from ..io.matlab import names_cell, number_column, field_name, solution_struct, write_mat

        rec = self.record
        struct = {"trials": names_cell(self.solutions),
                  **{field_name(label): solution_struct(sol) for label, sol in self.solutions.items()},
                  "estimated": {field_name(kind): {"muscles": names_cell(values), "factor": number_column(list(values.values()))}
                                for kind, values in self.factors.items() if values},
                  "solve": {"workflow": rec.workflow or "", "status": str(rec.status), "success": bool(rec.success),
                            "objective": self.objective, "iterations": self.iterations}}
        return write_mat(path, struct)

    @property
    def labels(self) -> tuple[str, ...]:
        return tuple(self.solutions)

    @property
    def tendon_scale(self) -> dict:
        """Estimated scale factors of the tendon stiffness ``kT`` by muscle."""
        return dict(self.factors.get("tendon_stiffness", {}))

    @property
    def tendon_stiffness(self) -> dict:
        """Estimated tendon stiffness ``kT`` (dimensionless) by muscle."""
        p = self.parameters
        return {m: float(p.tendon_stiffness[p.names.index(m)]) for m in self.factors.get("tendon_stiffness", {})}

    @property
    def emg_scale(self) -> dict:
        """Estimated EMG scale factors by muscle."""
        return dict(self.factors.get("emg_scale", {}))

    @property
    def run_record(self):
        """The :class:`~.record.RunRecord` of the solve."""
        return self.record.run_record

    @property
    def success(self) -> bool:
        return bool(self.record.success)

    @property
    def status(self) -> str:
        return str(self.record.status)

    @property
    def objective(self) -> float:
        return math.nan if self.record.objective is None else float(self.record.objective)

    @property
    def iterations(self) -> int:
        return -1 if self.record.iterations is None else int(self.record.iterations)

    def tendon_stiffness_N_per_mm(self) -> dict:
        """Tangent stiffness (N/mm) at ``FT = F0`` of every muscle whose ``kT`` was estimated."""
        p = self.parameters
        out = {}
        for m in self.tendon_stiffness:
            i = p.names.index(m)
            out[m] = float(tendon_stiffness_at_force_N_per_mm(
                1.0, p.max_isometric_force_N[i], p.tendon_slack_length_m[i], p.tendon_stiffness[i]))
        return out

    def tendon_stiffness_at_peak_force_N_per_mm(self) -> dict:
        """``{trial: {muscle: {peak_force_N, stiffness_N_per_mm}}}`` at each trial's peak tendon force."""
        p = self.parameters
        out = {}
        for label, sol in self.solutions.items():
            rec = {}
            for m in self.tendon_stiffness:
                i, j = p.names.index(m), sol.muscles.index(m)
                peak = float(np.max(sol.tendon_force_N[:, j]))
                rec[m] = {"peak_force_N": peak, "stiffness_N_per_mm": float(tendon_stiffness_at_force_N_per_mm(
                    peak / p.max_isometric_force_N[i], p.max_isometric_force_N[i], p.tendon_slack_length_m[i],
                    p.tendon_stiffness[i]))}
            out[label] = rec
        return out

    def achilles_stiffness_N_per_mm(self) -> dict | None:
        """Achilles tendon stiffness in N/mm: the muscles of the Achilles tendon in the
        anatomical muscle table (triceps surae) in parallel.

        ``{"at_max_isometric_force": k, "at_peak_walking_force": {trial: k}}``, or ``None``
        when no Achilles-tendon muscle's stiffness was estimated.
        """
        from ..properties import tendon_groups

        groups = [g for k, g in tendon_groups(list(self.tendon_stiffness)).items() if k.split("_")[0] == "achilles"]
        if not groups:
            return None
        members = groups[0]
        at_f0 = self.tendon_stiffness_N_per_mm()
        peak = self.tendon_stiffness_at_peak_force_N_per_mm()
        return {
            "at_max_isometric_force": float(sum(at_f0[m] for m in members)),
            "at_peak_walking_force": {t: float(sum(v[m]["stiffness_N_per_mm"] for m in members))
                                      for t, v in peak.items()},
        }

    def parameters_document(self) -> dict:
        """The content of ``parameters.json``."""
        if self.document is not None:
            return json_ready(self.document)
        return json_ready({
            "format": PARAMETERS_FORMAT,
            "format_version": PARAMETERS_VERSION,
            "workflow": EMG_TEN,
            "tendon_stiffness": dict(self.tendon_stiffness),
            "tendon_stiffness_scale": dict(self.tendon_scale),
            "tendon_stiffness_nominal": KT_GENERIC,
            "tendon_stiffness_other_muscles": KT_GENERIC,
            "tendon_stiffness_N_per_mm": self.tendon_stiffness_N_per_mm(),
            "tendon_stiffness_N_per_mm_definition": (
                "tangent slope dFT/dlT of the tendon force-length curve where the tendon carries its maximal "
                "isometric force (fT = 1): F0*kT*(1.25 - shift(kT))/lTs, converted from N/m to N/mm"),
            "tendon_stiffness_N_per_mm_at_peak_walking_force": self.tendon_stiffness_at_peak_force_N_per_mm(),
            "achilles_tendon_stiffness_N_per_mm": self.achilles_stiffness_N_per_mm(),
            "emg_scale": dict(self.emg_scale),
            "emg_channels": dict(self.emg_channels),
            "solve": self.record.to_dict(),
        })

    def write(self, out_dir: str | os.PathLike, opensim_files: bool = True) -> Path:
        """Write one solution folder per trial and ``parameters.json`` into ``out_dir``.

        ``problem.json`` holds the problem solved (:mod:`.problem_file`) when the result has it. A
        single-trial effort solve's result is refused (write its solution instead). Each folder
        is written atomically; ``parameters.json`` is removed first and written last
        (atomically), so its presence means that all trial folders belong to it. With
        ``opensim_files`` each trial folder also gets the OpenSim model, states, controls and
        forces of its solution (:func:`.export.write_solution_opensim_files`; trials solved
        from files).
        """
        from .export import write_solution_opensim_files

        from ..io.atomic import check_replaceable

        if self.document is None and self.record.trials is None:  # a single-trial effort solve (problem.solve)
            from ..errors import OptionError

            raise OptionError("the result of a single-trial solve has no parameters.json: write its solution "
                              "(musclemetab.redundancy.write_solution_folder(result.solutions[label], folder))")
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        from .problem_file import PROBLEM_FILE

        check_replaceable(out_dir, [PARAMETERS_FILE, PROBLEM_FILE])  # a parameters.json of the user is not removed
        (out_dir / PARAMETERS_FILE).unlink(missing_ok=True)
        for label, sol in self.solutions.items():
            sol.write(out_dir / label)
            if opensim_files:
                write_solution_opensim_files(sol, out_dir / label)
        if self.problem is not None:
            self.problem.write(out_dir)
        return self.write_parameters(out_dir)

    def write_parameters(self, out_dir: str | os.PathLike) -> Path:
        """Write (atomically) ``parameters.json`` alone into ``out_dir`` (e.g. again, after a
        validation re-solve added its fit to the document)."""
        from ..io import atomic_write_text

        out_dir = Path(out_dir)
        text = json.dumps(self.parameters_document(), indent=2, allow_nan=True)
        atomic_write_text(out_dir / PARAMETERS_FILE, text + "\n", mark=True)
        return out_dir

    @classmethod
    def load(cls, out_dir: str | os.PathLike, *, require_success: bool = True) -> "Result":
        """Read a folder written by :meth:`write` (EMG-TEN, an EMG-informed solve of several
        trials, or ``musclemetab estimate``); :func:`.problem.load_result` rebuilds its problem too.

        Raises :class:`~musclemetab.errors.InputFileError` when ``parameters.json`` or a trial
        folder is missing or is not of this package, and the solve's
        :class:`~musclemetab.errors.SolverError` when it did not succeed (unless
        ``require_success=False``).
        """
        from ..errors import InputFileError
        from ..io.jsonfile import read_json_object
        from .solution import Solution

        out_dir = Path(out_dir)
        path = out_dir / PARAMETERS_FILE
        if not path.is_file():
            raise InputFileError(f"{path}: no such file; give the folder written by an EMG-TEN solve or by "
                                 "musclemetab estimate")
        doc = read_json_object(path)
        fmt = doc.get("format")
        try:
            record = ProblemRecord.from_dict(dict(doc["solve"]))
            if fmt == PARAMETERS_FORMAT:
                from .emg_ten import EmgTenSettings

                labels = [t["label"] for t in record.trials]
                factors = {"tendon_stiffness": dict(doc["tendon_stiffness_scale"]), "emg_scale": dict(doc["emg_scale"])}
                emg_channels = {m: list(c) for m, c in doc["emg_channels"].items()}
                settings, document = EmgTenSettings.from_dict(record.settings), None
            elif fmt == ESTIMATE_FORMAT:
                labels = list(doc["trials"])
                factors = {k: dict(v) for k, v in doc["factors"].items()}
                emg = doc.get("emg")
                if emg:
                    factors["emg_scale"] = dict(emg["scale"])
                emg_channels = {m: list(c) for m, c in (emg or {}).get("mapping", {}).items()}
                settings, document = None, doc
            else:
                raise InputFileError(f"{path}: format {fmt!r} is not a result of this package (expected "
                                     f"{PARAMETERS_FORMAT} or {ESTIMATE_FORMAT})")
        except (KeyError, TypeError, AttributeError) as exc:
            raise InputFileError(f"{path}: the entry {exc} is missing or malformed; the file was not written by "
                                 "this package") from None
        if require_success and not record.success:
            raise record.run_record.failure(f"the solve stored in {out_dir}")
        solutions = {lab: Solution.load(out_dir / lab, require_success=False) for lab in labels}
        parameters = next(iter(solutions.values())).parameters if solutions else None
        return cls(solutions=solutions, parameters=parameters, factors=factors, record=record,
                   emg_channels=emg_channels, settings=settings, document=document)


#: EMG-TEN's result: a :class:`Result` (the name the EMG-TEN functions are documented with).
EmgTenResult = Result


def assemble_result(trials, params, wf_record, ocp, settings, options, t_prep, t_start,
                    name: str = EMG_TEN) -> Result:
    """The :class:`Result` of a solved EMG-TEN problem: per-trial solutions with the
    estimated tendon stiffness, the estimates and the solve record."""
    import time as _time

    from .ipopt import solver_record
    from .record import RunRecord
    from .records_build import input_preparation, trial_solution

    tendon_scale = dict(ocp.factors.get("tendon_stiffness", {}))
    emg_scale = dict(ocp.factors["emg_scale"])
    kt_est = {m: float(params.tendon_stiffness[params.names.index(m)] * s) for m, s in tendon_scale.items()}
    est_params = params.replace(tendon_stiffness=kt_est)
    emg_channels = dict(trials[0].emg_channels)
    run = RunRecord.from_result(ocp, {f"{t.label}/{k}": v for t in trials for k, v in t.sources.items()})
    n_tot = sum(t.inputs.n_intervals for t in trials)
    record = {
        "workflow": name,
        **run.to_dict(),
        "preparation_time_s": t_prep,
        "max_coupling_violation": ocp.max_coupling_violation,
        "problem_size": {"variables": ocp.n_variables, "equality_constraints": ocp.n_equality_constraints,
                         "inequality_constraints": ocp.n_inequality_constraints, "mesh_intervals": n_tot},
        "trials": [{"label": t.label, "time_window_s": list(t.inputs.window_s), "n_intervals": t.inputs.n_intervals,
                    "inputs": {k: str(v) for k, v in t.sources.items()}} for t in trials],
        "emg_mapping": emg_channels,
        "max_emg_deviation": {t.label: float(np.max(np.abs(d))) if d.size else 0.0
                              for t, d in zip(trials, ocp.emg_deviation)},
        "settings": settings.to_dict(),
        "passive_source": wf_record.get("passive_source"),
        "solver_options": solver_record(options, settings.goals.effort()),
        "ipopt_options": ocp.ipopt_options,
        "initial_guess": "static optimisation (rigid tendons) per trial, reserve divided by Topt; scale factors 1",
    }
    workflow = {
        "name": name,
        "description": "EMG-informed multi-trial estimation of triceps-surae and vasti tendon stiffness"
        if name == EMG_TEN else f"EMG-informed solve ({settings.emg_mode}) with the {name.split()[0]} muscle parameters",
        "passive_source": wf_record.get("passive_source"),
        "weights": settings.to_dict()["weights"],
        "tendon_stiffness": kt_est,
        "tendon_stiffness_scale": tendon_scale,
        "tendon_stiffness_other_muscles": KT_GENERIC,
        "emg_scale": emg_scale,
        "emg_channels": emg_channels,
        "trials": [t.label for t in trials],
    }
    solutions = {}
    for t, o, dev in zip(trials, ocp.trials, ocp.emg_deviation):
        sol = trial_solution(
            "emg-ten", run, t.inputs, params, options, settings.goals, o, solved=est_params,
            fiber_dynamics=settings.fiber_scheme, sources=t.sources,
            input_hashes={k.split("/", 1)[1]: v for k, v in run.input_hashes.items() if k.startswith(f"{t.label}/")},
            preparation_time_s=t_prep, problem_size=dict(record["problem_size"]),
            static_optimisation_objective=t.static_optimisation_objective, initial_guess=record["initial_guess"],
            workflow=dict(workflow, trial=t.label),
            emg_tracking={
                m: {"channels": t.emg_channels[m], "scale": emg_scale[m],
                    "max_abs_deviation": float(np.max(np.abs(dev[:, j]))) if dev.size else 0.0,
                    "rms_deviation": float(np.sqrt(np.mean(dev[:, j] ** 2))) if dev.size else 0.0}
                for j, m in enumerate(t.emg_muscles)
            },
            emg_tolerance=settings.emg_tolerance,
            input_preparation=input_preparation(mesh_frequency_hz=100, emg=True))
        solutions[t.label] = replace(sol, record=sol.record.with_(total_time_s=_time.perf_counter() - t_start))
    if ocp.success:  # doubts, warned and recorded (docs/problem.md, "Doubts of the estimates")
        from .identifiability import BOUND_TOLERANCE, check_informed, factors_on_bounds, warn_on_bounds
        from .transcription import ParameterSpec, coupling_pairs

        on_bounds = factors_on_bounds({"tendon_stiffness": tendon_scale, "emg_scale": emg_scale},
                                      {"tendon_stiffness": settings.tendon_scale_bounds,
                                       "emg_scale": settings.emg_scale_bounds})
        warn_on_bounds(on_bounds)
        kt = tuple(tendon_scale)
        uninformed = check_informed(trials, [ParameterSpec("tendon_stiffness", kt, settings.tendon_scale_bounds,
                                                           coupling_pairs(settings.tendon_groups, kt, True))], "warn",
                                    "map EMG to a muscle of its tendon group (--emg-mapping) or leave {muscle} out of "
                                    "the tendon groups")
        record["doubts"] = {"on_bounds": on_bounds, "bound_tolerance": BOUND_TOLERANCE,
                            "uninformed": [{"kind": k, "muscle": m} for k, m in uninformed]}
    record["max_moment_residual_Nm"] = max(s.record.max_moment_residual_Nm for s in solutions.values())
    record["max_hill_residual"] = max(s.record.max_hill_residual for s in solutions.values())
    record["total_time_s"] = _time.perf_counter() - t_start
    return Result(
        solutions=solutions, parameters=est_params,
        factors={"tendon_stiffness": tendon_scale, "emg_scale": emg_scale}, emg_channels=emg_channels,
        record=ProblemRecord.from_dict(record), settings=settings, trials=tuple(trials),
    )
