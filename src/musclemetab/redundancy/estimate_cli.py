"""``musclemetab estimate``: muscle-tendon parameters from measured fiber lengths and/or EMG
over trials (EMG: the goals of ``--emg-mode``, the EMG scale factors estimated with the others,
coupled as in EMG-TEN).

Writes ``DIR/<trial>/`` (the solutions with the estimates), ``DIR/parameters.json``,
``DIR/<model>_personalised.osim`` and, with ``--validate``, ``DIR/validation/<trial>/``: the
effort problem re-solved with the estimated parameters.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass

from ..errors import OptionError

__all__ = ["add_estimate_parser", "estimate_command", "estimate_files", "EstimateRun", "parse_assignments"]

WEIGHT_NAMES = {"activation": "w_activation", "reserve": "w_reserve", "velocity": "w_velocity",
                "fiber_length": "w_fiber_length", "emg": "w_emg"}
#: default bounds of the EMG scale factors (those of EMG-TEN)
EMG_SCALE_BOUNDS = (0.05, 2.5)


def add_estimate_parser(subparsers) -> argparse.ArgumentParser:
    from .cli import add_emg_goal_arguments

    p = subparsers.add_parser(
        "estimate", help="estimate tendon stiffness, optimal fiber and tendon slack lengths from fiber lengths",
        description="Estimate scale factors of the tendon stiffness, optimal fiber length and tendon slack length "
        "of named muscles over one or more trials, tracking measured fiber lengths (ultrasound), with the "
        "effort goals of a workflow; writes the solutions, parameters.json and <model>_personalised.osim.")
    p.add_argument("--model", required=True, metavar="M.osim")
    p.add_argument("--ik", required=True, nargs="+", metavar="IK.mot", help="one per trial")
    p.add_argument("--id", required=True, nargs="+", metavar="ID.sto", help="one per trial, same order")
    p.add_argument("--ultrasound", nargs="+", metavar="US.mot",
                   help="measured fiber lengths, one file per trial: time in s, one column per muscle in mm")
    p.add_argument("--emg", nargs="+", metavar="EMG.mot",
                   help="processed, normalised EMG envelopes, one file per trial, same order as --ik (with or "
                   "without --ultrasound; at least one of the two)")
    p.add_argument("--emg-mapping", metavar="default|authors|MAP.json",
                   help="EMG channels of the muscles, as for solve (default: default)")
    add_emg_goal_arguments(
        p, "with --emg: 'constrained' (each tracked excitation within --emg-tolerance of its scaled EMG, plus the "
        "tracking cost; the default), 'driven' (equal to its scaled EMG) or 'tracking' (the cost only)",
        "weight of the EMG tracking cost (default 10; also --weights emg=W)")
    p.add_argument("--estimate", required=True, nargs="+", metavar="KIND=MUSCLE[,MUSCLE...]",
                   help="kinds: tendon_stiffness, optimal_fiber_length, tendon_slack_length")
    p.add_argument("--couple", nargs="+", default=[], metavar="MUSCLE,MUSCLE[,...]",
                   help="muscles sharing one factor of every estimated kind")
    p.add_argument("--bounds", nargs="+", default=[], metavar="KIND=LOW:HIGH",
                   help="bounds of the factors (default tendon_stiffness 0.1:2, lengths 0.5:1.5, emg_scale "
                   "0.05:2.5; emg_scale=1:1 takes the EMG as it is)")
    p.add_argument("--weights", metavar="NAME=W[,...]",
                   help="activation, reserve, velocity (default: the workflow's), fiber_length (default 100), "
                   "emg (default 10)")
    p.add_argument("--workflow", default="effort-cal", choices=("effort-gen", "effort-cal", "effort-ten"),
                   help="muscle parameters and effort weights (default effort-cal)")
    p.add_argument("--passive", metavar="FILE", help="calibrated passive parameters (as for solve)")
    p.add_argument("--side", default="r", choices=("r", "l"), help="leg whose muscles are estimated (default r)")
    p.add_argument("--dofs", nargs="+", metavar="DOF",
                   help="degrees of freedom (default: the side's unlocked coordinates that the inverse dynamics "
                   "holds, as for solve)")
    p.add_argument("--labels", nargs="+", metavar="NAME", help="trial names (default: the IK file stems)")
    p.add_argument("--validate", action="store_true",
                   help="re-solve each trial with the estimates and the effort goals only (DIR/validation)")
    p.add_argument("--cache-dir", metavar="DIR")
    p.add_argument("--max-iter", type=int, default=10000)
    p.add_argument("--out", required=True, metavar="DIR")
    p.set_defaults(func=estimate_command)
    return p


def parse_assignments(items, what: str, value=str) -> dict:
    """``["key=value", ...]`` (or one comma-separated string for numbers) as a dict."""
    out = {}
    for item in items:
        key, sep, val = item.partition("=")
        if not sep or not key.strip() or not val.strip():
            raise OptionError(f"{what}: '{item}' is not NAME=VALUE")
        try:
            out[key.strip()] = value(val.strip())
        except ValueError:
            raise OptionError(f"{what}: the value of '{key.strip()}' ({val.strip()!r}) is not valid") from None
    return out


def _bounds(text: str) -> tuple[float, float]:
    lo, sep, hi = text.partition(":")
    if not sep:
        raise ValueError(text)
    return float(lo), float(hi)


def estimate_command(args) -> int:
    """Run ``musclemetab estimate`` with parsed arguments: the options read, then
    :func:`estimate_files`; prints one line."""
    us_files, emg_files = args.ultrasound or [], getattr(args, "emg", None) or []
    emg_options = [o for o, v in (("--emg-mapping", args.emg_mapping), ("--emg-mode", args.emg_mode),
                                  ("--emg-weight", args.emg_weight)) if v is not None]
    if emg_options and not emg_files:
        raise OptionError(f"{', '.join(emg_options)} need EMG: give --emg files, or drop them")
    weights = parse_assignments(args.weights.split(",") if args.weights else [], "--weights", float)
    if args.emg_weight is not None:
        weights["emg"] = args.emg_weight
    result = estimate_files(
        args.model, args.ik, args.id, args.out,
        estimate=parse_assignments(args.estimate, "--estimate", lambda v: [m for m in v.split(",") if m]),
        ultrasound=us_files, emg=emg_files, labels=args.labels,
        couple=[[m for m in g.split(",") if m] for g in args.couple],
        bounds=parse_assignments(args.bounds, "--bounds", _bounds), weights=weights, workflow=args.workflow,
        side=args.side, dofs=args.dofs, emg_mode=args.emg_mode, emg_mapping=args.emg_mapping,
        emg_tolerance=args.emg_tolerance, passive=args.passive, max_iter=args.max_iter, validate=args.validate,
        cache_dir=args.cache_dir,
    )
    values = ", ".join(f"{k} {m} x{v:.4f}" for k, by in result.factors.items() for m, v in by.items())
    if result.emg_scale:
        values += "; EMG scale " + ", ".join(f"{m} {v:.3g}" for m, v in result.emg_scale.items())
    run = result.run
    print(f"estimate: {len(result.labels)} trial(s), {run.status} in {run.iterations} iterations; {values} -> "
          f"{args.out}")
    return 0


@dataclass(frozen=True)
class EstimateRun:
    """What :func:`estimate_files` did: the solve's run record, the trials' labels, the
    estimated scale factors ``{kind: {muscle: factor}}`` and the EMG scale factors."""

    run: object  # RunRecord
    labels: tuple[str, ...]
    factors: dict
    emg_scale: dict


def estimate_files(
    model, ik, id, out, *, estimate, ultrasound=(), emg=(), labels=None, couple=(), bounds=None, weights=None,
    workflow: str = "effort-cal", side: str = "r", dofs=None, emg_mode: str | None = None,
    emg_mapping: str | None = None, emg_tolerance: float = 0.01, passive=None, max_iter: int = 10000,
    validate: bool = False, cache_dir=None,
) -> EstimateRun:
    """Estimate muscle-tendon parameters over trials from files, and write them to ``out``.

    ``ik``, ``id`` and ``ultrasound`` / ``emg`` hold one file per trial, in the same order (at
    least one kind of measurement). ``estimate`` maps a kind (``tendon_stiffness``,
    ``optimal_fiber_length``, ``tendon_slack_length``) to its muscles; ``couple`` lists
    muscles sharing one factor; ``bounds`` maps a kind (or ``emg_scale``) to ``(low, high)``;
    ``weights`` maps ``activation``, ``reserve``, ``velocity``, ``fiber_length`` and ``emg`` to
    their weights (defaults: the workflow's, 100 and 10). The other options are those of
    ``musclemetab estimate`` (``docs/problem.md``). Writes ``out/<trial>/``,
    ``out/parameters.json``, ``out/<model>_personalised.osim`` and with ``validate``
    ``out/validation/<trial>/``; raises :class:`~musclemetab.errors.SolverError` (after
    writing) when the solve did not converge.
    """
    from ..io import atomic_write_text, check_output_folder
    from .bounds import fiber_length_bounds_record
    from .core import Goals, ParameterSpec, coupling_pairs
    from .emg_inputs import emg_at_nodes, mapping_for_muscles, resolve_emg_mapping, trial_labels
    from .estimate import (
        FIELDS,
        estimate_parameters,
        fiber_length_trial,
        parameter_specs,
        read_fiber_lengths,
        write_personalised_model,
    )
    from .problem import SolverOptions
    from .record import RunRecord
    from .solution import build_solution
    from .solve import prepare_trial, solve_with_parameters
    from .static_opt import initial_guess
    from .workflows import get_workflow, workflow_parameters

    weights_given = weights
    check_output_folder(out)
    ik, id_files = [str(p) for p in ik], [str(p) for p in id]
    n = len(ik)
    us_files, emg_files = [str(p) for p in ultrasound or ()], [str(p) for p in emg or ()]
    if not (us_files or emg_files):
        raise OptionError("estimate needs measurements: give --ultrasound (fiber lengths) or --emg files, or both")
    counts = [("--ultrasound", len(us_files)), ("--emg", len(emg_files))]
    if len(id_files) != n or any(k not in (0, n) for _, k in counts):
        given = ", ".join(f"{k} {o}" for o, k in counts if k)
        raise OptionError(f"{n} --ik, {len(id_files)} --id and {given} files; give one of each per trial, in the "
                          "same order")
    estimate = {k: list(v) for k, v in estimate.items()}
    bounds = {k: (float(lo), float(hi)) for k, (lo, hi) in (bounds or {}).items()}
    bad = [k for k in bounds if k not in (*FIELDS, "emg_scale")]
    if bad:
        raise OptionError(f"--bounds: unknown kind '{bad[0]}'; use {', '.join((*FIELDS, 'emg_scale'))}")
    couple = [list(g) for g in couple]
    specs = parameter_specs(estimate, couple, bounds)
    wf = get_workflow(workflow)
    weights = {"w_activation": wf.w_activation, "w_reserve": wf.w_reserve, "w_velocity": wf.w_velocity,
               "w_fiber_length": 100.0, "w_emg": 10.0 if emg_files else 0.0}
    for k, v in (weights_given or {}).items():
        if k not in WEIGHT_NAMES:
            raise OptionError(f"--weights: unknown weight '{k}'; use {', '.join(WEIGHT_NAMES)}")
        weights[WEIGHT_NAMES[k]] = float(v)
    mode = emg_mode or "constrained"
    if emg_files:
        if not (emg_tolerance >= 0):
            raise OptionError(f"--emg-tolerance must be a non-negative number, not {emg_tolerance}")
        if mode == "tracking" and not weights["w_emg"] > 0:
            raise OptionError("--emg-mode tracking needs a positive EMG weight (--emg-weight)")
    tolerance = {"constrained": emg_tolerance, "driven": 0.0}.get(mode) if emg_files else None
    # the driven mode transcribes the fiber dynamics with backward Euler (docs/problem.md)
    fiber_dynamics = "backward" if emg_files and mode == "driven" else "forward"
    goals = Goals(**weights, emg_tolerance=tolerance, fiber_dynamics=fiber_dynamics)
    labels = trial_labels(ik, labels)
    measured = [read_fiber_lengths(p) for p in us_files] or [{} for _ in range(n)]
    mapping = resolve_emg_mapping(emg_mapping or "default") if emg_files else {}
    emg_muscles = ()
    options = SolverOptions(max_iter=max_iter, w_activation=goals.w_activation, w_reserve=goals.w_reserve,
                            w_velocity=goals.w_velocity)

    from ..geometry import compute_geometry
    from ..io import read_storage
    from ..model import read_muscle_parameters
    from ..layout import discover_dofs, read_layout
    from .inputs import read_inverse_dynamics, read_kinematics

    model_parameters = read_muscle_parameters(model)
    trials, prepared, params = [], [], None
    layout = read_layout(model)
    for i, (ik, idp, lab, us) in enumerate(zip(ik, id_files, labels, measured)):
        dofs = list(dofs) if dofs else discover_dofs(layout, side, list(read_storage(idp).columns))
        t_ik, _ = read_kinematics(ik, dofs)
        t_id, mom = read_inverse_dynamics(idp, dofs)
        g = compute_geometry(model, ik, dofs=list(dofs), side=side, cache_dir=cache_dir)
        nominal, wf_record = workflow_parameters(wf, model_parameters, g.muscles, passive=passive)
        inputs, p, so = prepare_trial(g, nominal, t_id, mom, ik_time_s=t_ik, options=options,
                                      sources={"model": model, "ik": ik, "id": idp})
        params = p if params is None else params
        emg = {}
        if emg_files:
            mapping = mapping_for_muscles(emg_mapping or "default", mapping, inputs.muscles)
            emg_muscles = tuple(sorted(mapping))
            emg = dict(emg_muscles=emg_muscles,
                       emg_nodes=emg_at_nodes(emg_files[i], mapping, inputs, emg_muscles, str(emg_files[i]), str(ik)))
        trials.append(fiber_length_trial(lab, inputs, initial_guess(inputs, p, so), us, **emg))
        prepared.append((g, nominal, t_id, mom, t_ik))
    if emg_files:
        from .emg_ten import EmgTenSettings, settings_for_muscles

        groups = settings_for_muscles(EmgTenSettings(), params.names).emg_groups
        specs.append(ParameterSpec("emg_scale", emg_muscles, bounds.get("emg_scale", EMG_SCALE_BOUNDS),
                                   coupling_pairs(groups, emg_muscles, consecutive=False)))
    res, est = estimate_parameters(trials, params, specs, goals, options=options)
    run = RunRecord.from_result(res, {"model": model})
    estimated = est.parameters()
    emg_record = {}
    if emg_files:
        emg_record = {"emg": {"mode": mode, "tolerance": tolerance, "weight": goals.w_emg, "mapping": mapping,
                              "scale": dict(res.factors.get("emg_scale", {})),
                              "bounds": list(bounds.get("emg_scale", EMG_SCALE_BOUNDS)),
                              "max_deviation": {t.label: float(abs(d).max()) if d.size else 0.0
                                                for t, d in zip(trials, res.emg_deviation)}}}
    for t, o in zip(trials, res.trials):
        summary = {**run.to_dict(), **emg_record, "objective_trial": o.objective, "objective_terms": o.objective_terms,
                   "time_window_s": list(t.inputs.window_s), "n_intervals": t.inputs.n_intervals,
                   "mesh_step_s": t.inputs.step_s, "optimal_reserve_Nm": options.optimal_reserve_Nm,
                   "fiber_dynamics": fiber_dynamics,
                   "fiber_length_bounds": fiber_length_bounds_record(t.inputs, params, specs),
                   "workflow": {"name": f"{workflow} estimate", "estimate": est.to_dict()["factors"]},
                   "solver_options": options.to_dict()}
        build_solution(t.inputs, estimated.subset(t.inputs.muscles), o, summary).write(f"{out}/{t.label}")
    doc = {"format": "musclemetab.redundancy.estimated_parameters", "format_version": 1, **est.to_dict(),
           **emg_record, "solve": run.to_dict(), "trials": labels}
    if run.success:
        path, report = write_personalised_model(model, estimated, estimate, out)
        doc["personalised_model"] = {"path": path.name, "muscles": report}
    atomic_write_text(f"{out}/parameters.json", json.dumps(doc, indent=2, default=float) + "\n")
    if not run.success:
        from .emg_ten import emg_failure

        raise emg_failure(run, mode if emg_files else None, f"the estimation (written to {out})")
    if validate:
        for lab, (g, _, t_id, mom, t_ik) in zip(labels, prepared):
            sol = solve_with_parameters(g, estimated, t_id, mom, ik_time_s=t_ik, options=options,
                                        workflow_record={"name": f"{workflow} validation"})
            sol.write(f"{out}/validation/{lab}")
            if not sol.success:
                raise sol.run_record.failure(f"the validation re-solve of {lab}")
    return EstimateRun(run=run, labels=tuple(labels), factors={k: dict(v) for k, v in est.factors.items()},
                       emg_scale=dict(res.factors.get("emg_scale", {})) if emg_files else {})
