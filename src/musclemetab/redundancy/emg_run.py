"""EMG-TEN, or an effort workflow's EMG-informed solve, from files (the pipeline the command line,
the study and Python users call): :func:`solve_emg_ten` over one or more trials, a
:class:`~.result.Result`; :func:`emg_mappings_of_legs`: the EMG mapping of each leg of an EMG
problem of both legs. It reads and checks every file before OpenSim is asked anything, like
:func:`.run.solve_files`."""

from __future__ import annotations

import dataclasses
import os
import time as _time
from pathlib import Path
from typing import Sequence

from ..errors import OptionError
from ..messages import name_list
from .._docs import fill_doc
from .emg_inputs import (
    check_emg_range,
    check_emg_window,
    mapped_emg_table,
    one_model,
    path_list,
    resolve_emg_mapping,
    trial_labels,
)
from .emg_pipeline import solve_emg_ten_arrays
from .emg_ten import EmgTenSettings
from .result import EMG_TEN, Result
from .inputs import (
    check_time_ranges,
    read_inverse_dynamics,
    read_kinematics,
)
from .ipopt import SolverOptions
from .run import (
    _diagnosis_record, _mapping_without, _trial_dofs, exclude_from_geometry,
)

__all__ = ["solve_emg_ten", "emg_mappings_of_legs"]


@fill_doc
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
    exclude_muscles: Sequence[str] = (),
    exclude_missing_ok: bool = False,
    diagnose_only: bool = False,
    before_solve=None,
) -> Result:
    """EMG-TEN from files: one model, and per trial an IK ``.mot``, an ID ``.sto`` and an EMG file.

    Parameters
    ----------
    model_path
        The ``.osim`` model (a list with one path per trial is accepted; they must be the
        same model).
    ik_paths, id_paths, emg_paths
        One file of each per trial, in the same order. EMG files hold processed, normalised
        envelopes (``musclemetab.emg.read_processed_emg``).
    %(emg_mapping)s
    %(labels)s
    %(passive)s
    %(side_dofs)s
    settings
        :class:`~.emg_ten.EmgTenSettings`: weights, bounds, couplings, EMG mode (default the study's).
    %(options)s
    %(cache_dir)s
    %(check_units)s
    exclude_muscles
        Muscles left out of the problem (as :func:`solve_files`). Their EMG channels are not
        used and their tendon stiffness is not estimated (each with a warning naming them).

    Each trial is diagnosed before the problem is built (:mod:`.diagnosis`): blocking
    findings raise :class:`~.diagnosis.InfeasibleInputError` naming muscles and times; with
    ``diagnose_only`` the list of the trials' :class:`~.diagnosis.Diagnosis` is returned,
    unchecked, and nothing is solved. ``before_solve``: called for each trial as by
    :func:`solve_files`, once the problem is known and before IPOPT starts, when the solve
    estimates no muscle parameter (an EMG-informed solve of an effort workflow; not EMG-TEN,
    whose tendon stiffness is known only after the solve).
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
    excluded = []
    if exclude_muscles:
        from .emg_ten import settings_without
        from .inputs import restrict_geometry

        settings = settings_without(settings, restrict_geometry(geometries[0]).muscles, exclude_muscles)
        pairs = [exclude_from_geometry(g, exclude_muscles, exclude_missing_ok) for g in geometries]
        geometries, excluded = [g for g, _ in pairs], pairs[0][1]
        mapping = _mapping_without(mapping, excluded)
        emg_tables = [_columns_without(t, excluded) for t in emg_tables]
    diagnoses = _diagnose_emg_trials(geometries, model_parameters, id_data, ik_times, labels, passive, settings,
                                     options, workflow, tendon_stiffness, check=not diagnose_only)
    if diagnose_only:
        return diagnoses
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
        workflow=workflow, tendon_stiffness=tendon_stiffness, before_solve=before_solve,
    )
    # the leg, in each trial's record as the single-trial solve's record holds it
    trial_entries = {label: {"side": side, "diagnosis": _diagnosis_record(diagnosis, solution, g, t, m, ik),
                             **({"excluded_muscles": list(excluded)} if excluded else {})}
                     for (label, solution), diagnosis, g, (t, m), ik in zip(result.solutions.items(), diagnoses,
                                                                          geometries, id_data, ik_times)}
    solutions = {label: dataclasses.replace(solution, record=solution.record.with_(**trial_entries[label]))
                 for label, solution in result.solutions.items()}
    return dataclasses.replace(result, solutions=solutions,
                               record=result.record.with_(geometry_time_s=t_geometry, side=side))


def _columns_without(table, excluded):
    """An EMG table mapped to muscles without the excluded muscles' columns (its attributes kept)."""
    out = table.drop(columns=[c for c in excluded if c in table.columns])
    out.attrs.update(table.attrs)
    return out


def _diagnose_emg_trials(geometries, model_parameters, id_data, ik_times, labels, passive, settings, options,
                         workflow, tendon_stiffness, check=True) -> list:
    """The diagnosis of each trial of an EMG problem before it is built (the estimated tendon
    stiffness within its bounds)."""
    from .diagnosis import diagnose_geometry
    from .emg_ten import settings_for_muscles
    from .inputs import restrict_geometry
    from .transcription import ParameterSpec
    from .workflows import workflow_parameters

    muscles = restrict_geometry(geometries[0]).muscles
    settings = settings_for_muscles(settings or EmgTenSettings(), muscles)
    params, _ = workflow_parameters("effort-cal" if workflow == EMG_TEN else workflow, model_parameters, muscles,
                                    passive=passive, tendon_stiffness=tendon_stiffness)
    kt = [m for m in settings.tendon_muscles if m in muscles]
    specs = [ParameterSpec("tendon_stiffness", tuple(kt), settings.tendon_scale_bounds)] if kt else []
    reserve = (options or SolverOptions()).optimal_reserve_Nm
    out = [diagnose_geometry(g, params, t, m, ik_time_s=ik, specs=specs, optimal_reserve_Nm=reserve, trial=lab)
           for g, (t, m), ik, lab in zip(geometries, id_data, ik_times, labels)]
    return [d.check(f"trial {d.trial}") for d in out] if check else out


def emg_mappings_of_legs(model, ik_path, emg_mapping, side: str, dofs=None, cache_dir=None) -> dict:
    """``{side: EMG mapping}`` of the legs to solve (``side`` ``"r"``, ``"l"`` or ``"both"``).
    With both legs the mapping must be a ``{muscle: [channels]}`` JSON file naming the muscles of
    both legs (the named mappings are one leg's electrodes); each leg takes the entries of its
    muscles (those spanning its DOFs, as its problem selects them, from the geometry of
    ``ik_path``)."""
    from ..errors import UnknownMuscleError
    from ..geometry import compute_geometry

    named = emg_mapping is None or str(emg_mapping).strip().lower() in ("default", "authors")
    if side != "both":
        return {side: emg_mapping or "default"}
    if named:
        raise OptionError("--side both with EMG needs --emg-mapping MAP.json: a JSON object naming each leg's "
                          "muscles and their EMG channels, e.g. {\"soleus_r\": [\"SOL_R\"], \"soleus_l\": "
                          "[\"SOL_L\"]} (the named mappings are one leg's electrodes)")
    if dofs:
        raise OptionError("--dofs names one leg's DOFs; with --side both leave it out (each leg's DOFs are discovered)")
    mapping = resolve_emg_mapping(emg_mapping)
    legs, placed = {}, set()
    for leg in ("r", "l"):
        muscles = set(compute_geometry(model, ik_path, side=leg, cache_dir=cache_dir).muscles)
        legs[leg] = {m: c for m, c in mapping.items() if m in muscles}
        placed |= set(legs[leg])
        if not legs[leg]:
            raise UnknownMuscleError(f"--emg-mapping {emg_mapping} names no muscle of the "
                                     f"{'right' if leg == 'r' else 'left'} leg; map its muscles to their channels")
    unplaced = sorted(set(mapping) - placed)
    if unplaced:
        raise UnknownMuscleError(f"--emg-mapping {emg_mapping}: {name_list(unplaced)} in neither leg's "
                                 "muscles; check the names")
    return legs
