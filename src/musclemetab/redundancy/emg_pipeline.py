"""EMG-TEN and EMG-informed solves from files or arrays: inputs checked, trials prepared (mesh
inputs, EMG at the nodes, initial guess), the problem of :mod:`.emg_ten` solved, the result
assembled (:mod:`.estimates`)."""

from __future__ import annotations

import os
import time as _time
from dataclasses import replace
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import DataMismatchError, OptionError, UnknownMuscleError
from .emg_inputs import (
    check_emg_range,
    check_emg_window,
    emg_at_nodes,
    mapped_emg_table,
    mapping_for_muscles,
    one_model,
    path_list,
    resolve_emg_mapping,
    trial_labels,
)
from .emg_ten import EmgTenSettings, EmgTenTrial, settings_for_muscles, solve_emg_ten_ocp
from .estimates import EMG_TEN, EmgTenResult, assemble_result
from .inputs import (
    check_id_coordinates,
    check_moment_magnitudes,
    check_time_ranges,
    prepare_inputs,
    read_inverse_dynamics,
    read_kinematics,
    restrict_geometry,
)
from .parameters import MuscleTendonParameters
from .problem import SolverOptions
from .static_opt import initial_guess, static_optimisation

__all__ = ["solve_emg_ten", "solve_emg_ten_arrays", "prepare_emg_ten_trials", "emg_ten_options"]


def solve_emg_ten(
    model_path,
    ik_paths: Sequence[str | os.PathLike],
    id_paths: Sequence[str | os.PathLike],
    emg_paths: Sequence[str | os.PathLike],
    *,
    emg_mapping="default",
    labels: Sequence[str] | None = None,
    passive=None,
    dofs: Sequence[str] | None = None,
    side: str = "r",
    settings: EmgTenSettings | None = None,
    options: SolverOptions | None = None,
    cache_dir: str | os.PathLike | None = None,
    check_units: bool = True,
    workflow: str = EMG_TEN,
    tendon_stiffness=None,
) -> EmgTenResult:
    """EMG-TEN from files: one model, and per trial an IK ``.mot``, an ID ``.sto`` and an EMG file.

    Parameters
    ----------
    model_path
        The ``.osim`` model (a list with one path per trial is accepted; they must be the
        same model).
    ik_paths, id_paths, emg_paths
        One file of each per trial, in the same order. EMG files hold processed, normalised
        envelopes (``musclemetab.emg.read_processed_emg``).
    emg_mapping
        ``"default"`` (vastus intermedius tracks ``VI_a`` = mean of VL and VM, as the study
        describes), ``"authors"`` (vastus intermedius tracks ``ES``, as in the published example
        results), a ``{muscle: [channels]}`` mapping or a JSON file holding one.
    labels
        Trial names (folder names in :meth:`EmgTenResult.write`); default the IK file stems.
    passive
        Calibrated passive parameters as for EFFORT-CAL (default the published calibration).
    dofs, side
        The leg (``"r"``/``"l"``) and its DOFs. ``dofs=None`` (default) discovers them from the
        model as the single-trial solves do (:func:`musclemetab.layout.discover_dofs`): the
        side's unlocked coordinates that every trial's ID file holds a moment for (for the
        example subject the study's five right-leg DOFs).

    Input errors (package exceptions naming the file, channel or muscle) are raised before
    OpenSim is started: unequal numbers of IK/ID/EMG files, different models, EMG channels
    missing for the mapping, EMG not covering a trial's IK window, EMG outside ``[0, 1]`` in
    the window, besides the IK/ID checks of the single-trial solver (columns, units, time
    ranges). Muscles of a custom mapping that the model lacks are reported after the geometry.
    """
    from ..io import read_table
    from ..model import read_muscle_parameters
    from ..processes import BackgroundCall
    from .workflows import read_passive_parameters

    ik_paths = path_list(ik_paths, "ik_paths")
    id_paths = path_list(id_paths, "id_paths")
    emg_paths = path_list(emg_paths, "emg_paths")
    if not ik_paths:
        raise OptionError("EMG-TEN needs at least one trial (IK, ID and EMG file)")
    if not (len(ik_paths) == len(id_paths) == len(emg_paths)):
        raise OptionError(
            f"{len(ik_paths)} IK, {len(id_paths)} ID and {len(emg_paths)} EMG files; give one of each per trial, "
            "in the same order"
        )
    model = one_model(model_path, len(ik_paths))
    labels = trial_labels(ik_paths, labels)
    mapping = resolve_emg_mapping(emg_mapping)
    settings = settings or EmgTenSettings()
    if passive is not None and not hasattr(passive, "for_muscles"):
        passive = read_passive_parameters(passive)
    # each file is read once; every file is checked before OpenSim is asked anything
    id_tables = [read_table(p) for p in id_paths]
    dofs = _trial_dofs(model, id_tables, dofs, side, cache_dir)
    id_data, emg_tables, ik_times, ik_tables = [], [], [], []
    for ik, idp, id_table, emg, lab in zip(ik_paths, id_paths, id_tables, emg_paths, labels):
        ik_tables.append(read_table(ik))
        ik_time, _ = read_kinematics(ik_tables[-1], dofs, check_units=check_units)
        id_time, id_moments = read_inverse_dynamics(id_table, dofs)
        check_time_ranges(ik_time, id_time, ik, idp)
        table = mapped_emg_table(emg, mapping, f"EMG of trial {lab}")
        what = str(table.attrs.get("path", f"EMG of trial {lab}"))
        check_emg_window(table, ik_time, what, str(ik))
        check_emg_range(table, float(ik_time[0]), float(ik_time[-1]), settings.emg_range_tolerance, what)
        id_data.append((id_time, id_moments))
        emg_tables.append(table)
        ik_times.append(ik_time)
    params_request = BackgroundCall(read_muscle_parameters, model)
    from ..geometry import compute_geometry

    t0 = _time.perf_counter()
    geometries = [compute_geometry(model, ik, dofs=list(dofs), side=side, cache_dir=cache_dir) for ik in ik_tables]
    t_geometry = _time.perf_counter() - t0
    model_parameters = params_request.result()
    if check_units:
        from ..model import read_model
        from .inputs import check_moments_per_body_mass

        mass = read_model(model).body_mass_kg
        for (_, moments), idp in zip(id_data, id_paths):
            check_moments_per_body_mass(moments, dofs, mass, idp, model)
    sources = [{"model": Path(model), "ik": Path(ik), "id": Path(idp),
                "emg": Path(emg) if isinstance(emg, (str, os.PathLike)) else f"EMG table of trial {lab}"}
               for ik, idp, emg, lab in zip(ik_paths, id_paths, emg_paths, labels)]
    result = solve_emg_ten_arrays(
        geometries, model_parameters, id_data, emg_tables, labels=labels, ik_times=ik_times, passive=passive,
        emg_mapping=mapping, settings=settings, options=options, sources=sources, check_units=check_units,
        workflow=workflow, tendon_stiffness=tendon_stiffness,
    )
    result.record["geometry_time_s"] = t_geometry
    result.record["side"] = side
    for solution in result.solutions.values():  # as the single-trial solve's summary records it
        solution.summary["side"] = side
    return result


def _trial_dofs(model, id_files, dofs, side: str, cache_dir) -> tuple[str, ...]:
    """``dofs`` checked against the model, or the side's DOFs that every ID file (or its table,
    already read) holds."""
    from ..io import as_table, table_path
    from ..layout import check_dofs_in_model, check_side, discover_dofs, read_layout

    check_side(side)
    layout = read_layout(model, cache_dir=cache_dir)
    common = None
    for source in id_files:
        columns = list(as_table(source).columns)
        check_id_coordinates(table_path(source), columns, layout)
        common = [c for c in columns if common is None or c in common]
    if dofs:
        dofs = tuple(dofs)
        check_dofs_in_model(layout, dofs)
        return dofs
    return tuple(discover_dofs(layout, side, common))


def solve_emg_ten_arrays(
    geometries: Sequence,
    model_parameters,
    id_data: Sequence[tuple[np.ndarray, np.ndarray]],
    emg_tables: Sequence,
    *,
    labels: Sequence[str] | None = None,
    ik_times: Sequence[np.ndarray] | None = None,
    passive=None,
    emg_mapping="default",
    settings: EmgTenSettings | None = None,
    options: SolverOptions | None = None,
    sources: Sequence[dict] | None = None,
    check_units: bool = True,
    workflow: str = EMG_TEN,
    tendon_stiffness=None,
) -> EmgTenResult:
    """EMG-TEN from arrays: per trial a geometry-like object, ``(ID time, ID moments)`` with
    columns in the order of ``geometry.dofs``, and an EMG table (time-indexed ``DataFrame``,
    channels as columns, or already mapped to muscles by ``musclemetab.emg.map_channels``)."""
    t_start = _time.perf_counter()
    settings = settings_for_muscles(settings, restrict_geometry(list(geometries)[0]).muscles) if geometries \
        else (settings or EmgTenSettings())
    options = emg_ten_options(options, settings)
    trials, params, wf_record = prepare_emg_ten_trials(
        geometries, model_parameters, id_data, emg_tables, labels=labels, ik_times=ik_times, passive=passive,
        emg_mapping=emg_mapping, settings=settings, options=options, sources=sources, check_units=check_units,
        workflow="effort-cal" if workflow == EMG_TEN else workflow, tendon_stiffness=tendon_stiffness)
    t_prep = _time.perf_counter() - t_start
    ocp = solve_emg_ten_ocp(trials, params, settings, options)
    name = EMG_TEN if workflow == EMG_TEN else f"{workflow} emg-{settings.emg_mode}"
    return assemble_result(trials, params, wf_record, ocp, settings, options, t_prep, t_start, name=name)


def emg_ten_options(options: SolverOptions | None, settings: EmgTenSettings) -> SolverOptions:
    """``options`` with the weights of ``settings`` (EMG-TEN: ``wAct 0.1, wTres 1000, wVm 0.01``)."""
    if options is not None and options.energy is not None:
        raise OptionError("the energy goal is for the effort workflows' solves; EMG-TEN and EMG-informed solves "
                          "do not take it: drop SolverOptions(energy=...)")
    return (options or SolverOptions()).with_(
        w_activation=settings.w_activation, w_reserve=settings.w_reserve, w_velocity=settings.w_velocity)


def prepare_emg_ten_trials(
    geometries: Sequence,
    model_parameters,
    id_data: Sequence[tuple[np.ndarray, np.ndarray]],
    emg_tables: Sequence,
    *,
    labels: Sequence[str] | None = None,
    ik_times: Sequence[np.ndarray] | None = None,
    passive=None,
    emg_mapping="default",
    settings: EmgTenSettings | None = None,
    options: SolverOptions | None = None,
    sources: Sequence[dict] | None = None,
    check_units: bool = True,
    workflow: str = "effort-cal",
    tendon_stiffness=None,
) -> tuple[list[EmgTenTrial], MuscleTendonParameters, dict]:
    """The trials of an EMG-TEN problem (mesh inputs, EMG at the nodes, initial guess), the
    muscle parameters (calibrated passive muscle, nominal ``kT``) and their record; the
    arguments are those of :func:`solve_emg_ten_arrays`. Nothing is solved."""
    from .workflows import workflow_parameters

    settings = settings or EmgTenSettings()
    options = emg_ten_options(options, settings)
    geometries, id_data, emg_tables = list(geometries), list(id_data), list(emg_tables)
    n = len(geometries)
    if not (n == len(id_data) == len(emg_tables)) or n == 0:
        raise OptionError(f"{n} geometries, {len(id_data)} ID and {len(emg_tables)} EMG tables; give one of each "
                          "per trial (at least one trial)")
    labels = [f"trial_{i + 1}" for i in range(n)] if labels is None else trial_labels(list(range(n)), labels)
    sources = [dict(s) for s in (sources or [{} for _ in range(n)])]
    mapping = resolve_emg_mapping(emg_mapping)
    ik_times = list(ik_times) if ik_times is not None else [None] * n

    # same model (hence the same muscles and DOFs) for all trials
    all_dofs = [tuple(g.dofs) for g in geometries]
    restricted = [restrict_geometry(g) for g in geometries]
    ref = restricted[0]
    for lab, g in zip(labels[1:], restricted[1:]):
        if tuple(g.muscles) != tuple(ref.muscles) or tuple(g.dofs) != tuple(ref.dofs):
            only_a = sorted(set(ref.muscles) - set(g.muscles))
            only_b = sorted(set(g.muscles) - set(ref.muscles))
            raise DataMismatchError(
                f"trial {lab} has other muscles or DOFs than trial {labels[0]} (only in {labels[0]}: "
                f"{', '.join(only_a) or '-'}; only in {lab}: {', '.join(only_b) or '-'}; DOFs {list(g.dofs)} vs "
                f"{list(ref.dofs)}); are the trials from different models? All trials of one EMG-TEN problem "
                "need the same model"
            )
    muscles = tuple(ref.muscles)
    settings = settings_for_muscles(settings, muscles)
    mapping = mapping_for_muscles(emg_mapping, mapping, muscles)
    missing_kt = [m for m in settings.tendon_muscles if m not in muscles]
    if missing_kt:
        raise UnknownMuscleError(
            f"the tendon stiffness of {', '.join(missing_kt)} is to be estimated but the problem has no such muscle "
            f"({', '.join(muscles[:6])} ...); change EmgTenSettings.tendon_groups"
        )
    params, wf_record = workflow_parameters(workflow, model_parameters, muscles, passive=passive,
                                            tendon_stiffness=tendon_stiffness)
    emg_muscles = tuple(sorted(mapping))

    trials = []
    for i, (g, (id_time, id_moments), emg, lab) in enumerate(zip(restricted, id_data, emg_tables, labels)):
        id_moments = np.asarray(id_moments, dtype=float).reshape(len(id_time), -1)
        if tuple(g.dofs) != all_dofs[i]:
            keep = [all_dofs[i].index(d) for d in g.dofs]
            id_moments = id_moments[:, keep]
        src = sources[i]
        inputs = prepare_inputs(g, id_time, id_moments, ik_time_s=ik_times[i], sources=src)
        if check_units:
            check_moment_magnitudes(inputs.moments_frames_Nm, inputs.dofs, inputs.moment_arms_frames_m,
                                    params.max_isometric_force_N, src.get("id", f"inverse dynamics of {lab}"),
                                    options.optimal_reserve_Nm)
        emg_nodes = emg_at_nodes(emg, mapping, inputs, emg_muscles, str(src.get("emg", f"EMG of trial {lab}")),
                                 str(src.get("ik", f"trial {lab}")), settings.emg_range_tolerance)
        so = static_optimisation(inputs, params)
        guess = initial_guess(inputs, params, so)
        guess = replace(guess, reserve=guess.reserve / options.optimal_reserve_Nm)
        trials.append(EmgTenTrial(label=lab, inputs=inputs, emg_muscles=emg_muscles, emg_nodes=emg_nodes,
                                  emg_channels={m: list(mapping[m]) for m in emg_muscles}, guess=guess,
                                  sources=src, static_optimisation_objective=so.objective))
    return trials, params, wf_record
