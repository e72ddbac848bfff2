"""The files of a problem's trials read and checked (:func:`.problem.load_problem`): every
option and file is checked before OpenSim is asked anything, then the geometry
(:func:`musclemetab.geometry.compute_geometry`, OpenSim in its worker process, cached), the
model's muscle parameters and the workflow's, and each trial's diagnosis (:mod:`.diagnosis`).

:func:`read_effort_trial`: one trial of an effort workflow (window or gait cycle, inverse
dynamics from a file or computed from ground forces, an assistance device);
:func:`read_emg_trials`: the trials of an EMG problem (EMG-TEN, an EMG-informed solve). Both
return arrays (:class:`TrialArrays`); :mod:`.problem` makes the :class:`~.problem.Problem` of them.
"""

from __future__ import annotations

import os
import time as _time
from pathlib import Path
from typing import NamedTuple, Sequence

import numpy as np

from ..errors import OptionError
from ..io import source_path
from ..messages import name_list
from .inputs import (
    GeometryArrays,
    check_id_coordinates,
    check_moments_per_body_mass,
    check_time_ranges,
    read_inverse_dynamics,
    read_kinematics,
)
from .ipopt import SolverOptions

__all__ = ["TrialArrays", "read_effort_trial", "read_emg_trials", "exclude_from_geometry", "diagnosis_record",
           "mapping_without", "fiber_lengths_without", "trial_dofs"]


class TrialArrays(NamedTuple):
    """What the readers give for each trial: the label, the geometry (cropped, muscles left
    out removed), ID time and moments (a device's torque taken off), IK time, the EMG table
    mapped to muscles (or ``None``), the source files, the entries of the trial's record known
    before the solve (window, computed inverse dynamics, assistance), the diagnosis and the
    measured fiber lengths (``{muscle: (time s, length m)}``, parameter estimation)."""

    label: str
    geometry: GeometryArrays
    id_time_s: np.ndarray
    id_moments_Nm: np.ndarray
    ik_time_s: np.ndarray
    emg: object
    sources: dict
    record: dict
    diagnosis: object
    fiber_lengths: dict = {}


def _arrays(geometry) -> GeometryArrays:
    return GeometryArrays(np.asarray(geometry.time), geometry.muscles, geometry.dofs, np.asarray(geometry.lmt_m),
                          np.asarray(geometry.moment_arms_m))


def read_effort_trial(model_path, ik_path, id_path, wf, *, dofs, side, window, cycle, external_loads, grf, grf_column,
                      grf_threshold_N, cycle_duration_s, mesh_frequency_hz, passive, tendon_stiffness,
                      tendon_stiffness_file, options, cache_dir, check_units, exclude_muscles, exclude_missing_ok,
                      diagnose_only, assistance, assistance_gain, assistance_cycle_s, assistance_both_legs=False):
    """One trial of an effort workflow ``wf`` from files (the keywords of :func:`.run.solve_files`):
    ``(TrialArrays, workflow parameters, their record, DOFs, muscles left out, geometry time)``,
    or with ``diagnose_only`` the unchecked :class:`~.diagnosis.Diagnosis`."""
    from ..geometry import compute_geometry, geometry_is_cached
    from ..io import read_table
    from ..layout import check_dofs_in_model, discover_dofs, read_layout
    from ..model import model_is_cached
    from ..opensim_bridge import start_in_background
    from ..processes import BackgroundCall
    from .window import frames_in_window, resolve_window

    if id_path is None and external_loads is None:
        raise OptionError("give the inverse dynamics (--id ID.sto) or the ground forces to compute it "
                          "(--external-loads GRF.xml)")
    # Model parameters and geometry come from the on-disk cache when it holds them: no
    # OpenSim work at all then. Otherwise the OpenSim worker is started as soon as it is
    # known to be needed, so that its start-up overlaps with reading the files and the
    # imports of pandas and CasADi; the model parameters are asked for in a
    # background thread.
    model_cached = model_is_cached(model_path, cache_dir)
    if not model_cached:
        start_in_background()
    params_request = None if model_cached else BackgroundCall(read_model_parameters, model_path, cache_dir)
    layout = read_layout(model_path, cache_dir=cache_dir)
    loads = None
    if external_loads is not None:
        from ..external_loads import read_external_loads

        loads = read_external_loads(external_loads)
        loads.check_bodies(layout)
    # Each input file is read once; the tables go on to the window, the checks and the geometry.
    id_table = id_columns = None
    if id_path is not None:
        id_table = read_table(id_path)
        id_columns = list(id_table.columns)
        check_id_coordinates(id_path, id_columns, layout)
    if dofs:
        dofs = tuple(dofs)
        check_dofs_in_model(layout, dofs)
    else:
        dofs = tuple(discover_dofs(layout, side, id_columns, source=id_path))
    if model_cached and (id_path is None or not geometry_is_cached(model_path, ik_path, list(dofs),
                                                                   cache_dir=cache_dir)):
        start_in_background()
    ik_table = read_table(ik_path)
    # the coordinates first: the gait events of the window come from the kinematics, and a
    # missing coordinate would show there as events far from the forces' (warnings before the error)
    ik_time, ik_angles = read_kinematics(ik_table, dofs, check_units=check_units)
    trial_window = resolve_window(ik_table, side=side, window=window, cycle=cycle, id_path=id_table,
                                  external_loads=loads, grf_path=grf, layout=layout, grf_column=grf_column,
                                  grf_threshold_N=grf_threshold_N, cycle_duration_s=cycle_duration_s)
    id_record = None
    if id_path is None:
        from ..external_loads import ID_COORDINATE_FILTER_HZ, compute_inverse_dynamics

        id_path = compute_inverse_dynamics(model_path, ik_path, loads, trial_window.start_s, trial_window.end_s,
                                           cache_dir=cache_dir)
        id_table = read_table(id_path)
        id_record = {"computed_by": "OpenSim InverseDynamicsTool (muscles excluded)",
                     "coordinate_lowpass_hz": ID_COORDINATE_FILTER_HZ, "external_loads": str(loads.path),
                     "ground_force_data": str(loads.datafile)}
    id_time, id_moments = read_inverse_dynamics(id_table, dofs)
    keep = frames_in_window(ik_time, trial_window)
    ik_time, ik_angles = ik_time[keep], ik_angles[keep]
    check_time_ranges(ik_time, id_time, ik_path, id_path)
    device, file_moments = None, id_moments
    if assistance is not None:  # the muscles supply what the device does not (musclemetab.redundancy.assistance)
        id_moments, device = _assisted_moments(assistance, assistance_gain, assistance_cycle_s, trial_window, layout,
                                               model_path, cache_dir, side, dofs, id_time, id_moments,
                                               check_units, assistance_both_legs,
                                               (ik_table, id_path, grf, grf_column, grf_threshold_N, loads))

    t0 = _time.perf_counter()
    geometry = compute_geometry(model_path, ik_table, dofs=list(dofs), side=side, cache_dir=cache_dir)
    if keep.size != len(geometry.time):
        geometry = GeometryArrays(np.asarray(geometry.time)[keep], geometry.muscles, geometry.dofs,
                                  np.asarray(geometry.lmt_m)[keep], np.asarray(geometry.moment_arms_m)[keep])
    geometry, excluded = exclude_from_geometry(_arrays(geometry), exclude_muscles, exclude_missing_ok)
    t_geometry = _time.perf_counter() - t0
    import casadi  # noqa: F401  (imported while the worker answers)

    model_parameters = (params_request.result() if params_request is not None
                        else read_model_parameters(model_path, cache_dir))
    if check_units:
        from ..model import read_model

        check_moments_per_body_mass(file_moments, dofs, read_model(model_path, cache_dir=cache_dir).body_mass_kg,
                                    id_path, model_path)
    sources = {"model": source_path(model_path), "ik": source_path(ik_path), "id": source_path(id_path)}
    if loads is not None:
        sources["external_loads"] = source_path(loads.path)
    label = Path(ik_path).stem
    params, wf_record = _workflow_parameters(wf, model_parameters, geometry, passive, tendon_stiffness,
                                             tendon_stiffness_file)
    diagnosis = _diagnose(geometry, params, id_time, id_moments, ik_time, options, label, (),
                          mesh_frequency_hz=mesh_frequency_hz, sources={k: str(v) for k, v in sources.items()})
    if diagnose_only:
        return diagnosis
    diagnosis = diagnosis.check(f"trial {label}")
    record = {}
    if trial_window.source != "inverse-kinematics file":
        record["window"] = trial_window.record()
    if id_record is not None:
        record["inverse_dynamics"] = id_record
    if device is not None:
        from .assistance import assistance_record
        from .inputs import mesh_for_window

        profile, cycle_s, cycle_source = device
        mesh = mesh_for_window(float(ik_time[0]), float(ik_time[-1]), mesh_frequency_hz)
        record["assistance"] = assistance_record(profile, assistance_gain, dofs, ik_time, ik_angles, mesh, cycle_s,
                                                 cycle_source)
    trial = TrialArrays(label, geometry, id_time, id_moments, ik_time, None, sources, record, diagnosis)
    return trial, params, wf_record, dofs, tuple(excluded), t_geometry


def read_emg_trials(model, ik_paths, id_paths, emg_paths, labels, *, mapping, settings, workflow, passive, dofs, side,
                    options, cache_dir, check_units, tendon_stiffness, exclude_muscles, exclude_missing_ok,
                    diagnose_only):
    """The trials of an EMG problem from files (the keywords of :func:`.emg_run.solve_emg_ten`):
    ``(trials, workflow parameters, their record, settings, mapping, DOFs, muscles left out,
    geometry time)``, or with ``diagnose_only`` the list of unchecked diagnoses."""
    from ..geometry import compute_geometry
    from ..io import read_table
    from ..model import read_muscle_parameters
    from ..processes import BackgroundCall
    from .emg_inputs import check_emg_range, check_emg_window, mapped_emg_table

    # each file is read once; every file is checked before OpenSim is asked anything
    id_tables = [read_table(p) for p in id_paths]
    dofs = trial_dofs(model, id_tables, dofs, side, cache_dir)
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
    t0 = _time.perf_counter()
    geometries = [_arrays(compute_geometry(model, ik, dofs=list(dofs), side=side, cache_dir=cache_dir))
                  for ik in ik_tables]
    t_geometry = _time.perf_counter() - t0
    model_parameters = params_request.result()
    excluded = []
    if exclude_muscles:
        from .emg_ten import settings_without
        from .inputs import restrict_geometry

        settings = settings_without(settings, restrict_geometry(geometries[0]).muscles, exclude_muscles)
        pairs = [exclude_from_geometry(g, exclude_muscles, exclude_missing_ok) for g in geometries]
        geometries, excluded = [g for g, _ in pairs], pairs[0][1]
        mapping = mapping_without(mapping, excluded)
        emg_tables = [_columns_without(t, excluded) for t in emg_tables]
    from .emg_ten import settings_for_muscles
    from .goals import ParameterSpec
    from .inputs import restrict_geometry
    from .result import EMG_TEN

    muscles = restrict_geometry(geometries[0]).muscles
    params, wf_record = _workflow_parameters("effort-cal" if workflow == EMG_TEN else workflow, model_parameters,
                                             geometries[0], passive, tendon_stiffness, None)
    checked = settings_for_muscles(settings, muscles)  # the estimated tendon stiffness within its bounds
    kt = tuple(m for m in checked.tendon_muscles if m in muscles)
    kt_spec = [ParameterSpec("tendon_stiffness", kt, checked.tendon_scale_bounds)] if kt else []
    diagnoses = [_diagnose(g, params, t, m, ik, options, lab, kt_spec)
                 for g, (t, m), ik, lab in zip(geometries, id_data, ik_times, labels)]
    if diagnose_only:
        return diagnoses
    diagnoses = [d.check(f"trial {d.trial}") for d in diagnoses]
    if check_units:
        from ..model import read_model

        mass = read_model(model).body_mass_kg
        for (_, moments), idp in zip(id_data, id_paths):
            check_moments_per_body_mass(moments, dofs, mass, idp, model)
    sources = [{"model": source_path(model), "ik": source_path(ik), "id": source_path(idp),
                "emg": source_path(emg) if isinstance(emg, (str, os.PathLike)) else f"EMG table of trial {lab}"}
               for ik, idp, emg, lab in zip(ik_paths, id_paths, emg_paths, labels)]
    trials = [TrialArrays(lab, g, t, m, ik, table, src, {}, diag) for lab, g, (t, m), ik, table, src, diag
              in zip(labels, geometries, id_data, ik_times, emg_tables, sources, diagnoses)]
    return trials, params, wf_record, settings, mapping, dofs, tuple(excluded), t_geometry


def _assisted_moments(path, gain, cycle_s, trial_window, layout, model_path, cache_dir, side, dofs, id_time,
                      id_moments, check_units, both_legs=False, events=(None, None, None, None, None, None)):
    """``(moments less the device torque, (profile, gait cycle, its source))`` of :func:`read_effort_trial`.

    The gait cycle the profile is mapped onto and the device's work integrated over: the solve's
    (``--cycle``), else the one given (``--assistance-cycle``), else the one a study takes for the
    same files (:func:`_events_cycle`); ``events``: ``(IK, ID file, ground forces, their column, threshold,
    ExternalLoads)``."""
    from ..model import read_model
    from .assistance import apply_assistance, check_profile_against_model, read_assistance

    profile = read_assistance(path)
    mass = read_model(model_path, cache_dir=cache_dir).body_mass_kg if check_units else None
    window_s = (trial_window.start_s, trial_window.end_s)
    coordinates = [c["name"] for c in layout.coordinates]
    # the profile against the problem first: a cycle is looked for only for a profile that is used
    check_profile_against_model(profile, dofs, side, coordinates, mass, window_s, check_units=check_units,
                                other_leg_solved=both_legs)
    if trial_window.cycle is not None:
        cycle_s = (trial_window.cycle["start_s"], trial_window.cycle["end_s"])
        source = "the solve's (its window is the cycle)"
    elif cycle_s is not None:
        cycle_s, source = (float(cycle_s[0]), float(cycle_s[1])), "given"
    else:
        cycle_s, source = _events_cycle(profile, trial_window, side, layout, *events)
    moments = apply_assistance(id_time, id_moments, dofs, profile, gain, window_s=window_s, cycle_s=cycle_s,
                               side=side, model_coordinates=coordinates, body_mass_kg=mass, check_units=check_units,
                               other_leg_solved=both_legs)
    return moments, (profile, cycle_s, source)


def _events_cycle(profile, trial_window, side, layout, ik, id_path, grf, grf_column, grf_threshold_N, loads):
    """``((start, end), source)``: the gait cycle a study takes for a trial of these files, found as
    ``analyse`` finds it in the solve window (:func:`musclemetab.events.cycle_of_trial`: from the
    ground forces ``grf`` or the ExternalLoads ``loads`` on the foot of ``side`` of ``layout``, the
    cycle holding the middle of the window, else the window less 0.05 s at each end with toe-off
    from the ankle moment). A time profile without one is integrated
    over the solve window (said in the source); a cycle profile is refused (it needs a cycle)."""
    from ..errors import MusclemetabError
    from ..events import cycle_of_trial

    t0, t1 = trial_window.start_s, trial_window.end_s
    try:
        found, source = cycle_of_trial(ik, grf=grf, id_file=id_path, side=side, window_s=(t0, t1),
                                       remedy="give the gait cycle: --assistance-cycle T0:T1 (or --cycle)",
                                       grf_column=grf_column, threshold_N=grf_threshold_N, external_loads=loads,
                                       model=layout if grf is None else None)
    except MusclemetabError as exc:
        if profile.axis == "cycle_pct":
            raise type(exc)(f"{profile.path}: a profile over the gait cycle needs the gait cycle, and none was found "
                            f"in the solve window {t0:g}-{t1:g} s: {exc}") from None
        return (t0, t1), "solve window (no gait cycle found in it)"
    return (found.start_s, found.end_s), source


def exclude_from_geometry(geometry, exclude_muscles: Sequence[str] = (), missing_ok: bool = False):
    """``(geometry without the muscles of exclude_muscles, the excluded muscles it had)``;
    :class:`~musclemetab.errors.UnknownMuscleError` for a name the geometry lacks (unless
    ``missing_ok``: a muscle of the other leg)."""
    if not exclude_muscles:
        return geometry, []
    from ..errors import UnknownMuscleError

    unknown = [m for m in exclude_muscles if m not in geometry.muscles]
    excluded = [m for m in exclude_muscles if m in geometry.muscles]
    if unknown and not missing_ok:
        raise UnknownMuscleError(
            f"--exclude-muscles: {name_list(unknown)} {'is' if len(unknown) == 1 else 'are'} not among the "
            f"muscles of the problem ({', '.join(geometry.muscles[:8])}, ...); check the names and the side"
        )
    kept = [i for i, m in enumerate(geometry.muscles) if m not in set(excluded)]
    kept_geometry = GeometryArrays(np.asarray(geometry.time), [geometry.muscles[i] for i in kept], geometry.dofs,
                                   np.asarray(geometry.lmt_m)[:, kept], np.asarray(geometry.moment_arms_m)[:, :, kept])
    return kept_geometry, excluded


def _workflow_parameters(wf, model_parameters, geometry, passive, tendon_stiffness, tendon_stiffness_file):
    """``(parameters, record)`` of the workflow ``wf`` for the muscles the problem keeps."""
    from .inputs import restrict_geometry
    from .workflows import workflow_parameters

    return workflow_parameters(wf, model_parameters, restrict_geometry(geometry).muscles, passive=passive,
                               tendon_stiffness=tendon_stiffness, tendon_stiffness_file=tendon_stiffness_file)


def _diagnose(geometry, params, id_time, id_moments, ik_time, options, label, specs, **kwargs):
    """The diagnosis of one trial before its solve (:mod:`.diagnosis`), unchecked."""
    from .diagnosis import diagnose_geometry

    return diagnose_geometry(geometry, params, id_time, id_moments, ik_time_s=ik_time, specs=list(specs),
                             optimal_reserve_Nm=(options or SolverOptions()).optimal_reserve_Nm, trial=label,
                             **kwargs)


def diagnosis_record(diagnosis, solution, geometry, id_time, id_moments, ik_time, mesh_frequency_hz) -> dict:
    """``summary.json``'s ``diagnosis``: the findings before the solve and, when the solve did
    not converge, the constraints its last iterate left violated (``last_iterate``)."""
    record = diagnosis.to_dict()
    if not solution.success:
        from .diagnosis import last_iterate_violations
        from .inputs import restrict_geometry, trial_inputs

        g = restrict_geometry(geometry)
        moments = np.asarray(id_moments, dtype=float).reshape(len(id_time), -1)
        moments = moments[:, [list(geometry.dofs).index(d) for d in g.dofs]]
        inputs = trial_inputs(g, id_time, moments, ik_time_s=ik_time, mesh_frequency_hz=mesh_frequency_hz)
        record["last_iterate"] = [f.to_dict() for f in last_iterate_violations(solution, inputs)]
    return record


def read_model_parameters(model_path, cache_dir=None):
    from ..model import read_muscle_parameters

    return read_muscle_parameters(model_path, cache_dir=cache_dir)


def mapping_without(mapping: dict, excluded: Sequence[str]) -> dict:
    """The EMG mapping without the excluded muscles (a warning names those that had EMG)."""
    import warnings

    from ..errors import MusclemetabWarning

    dropped = [m for m in mapping if m in set(excluded)]
    if dropped:
        warnings.warn(f"--exclude-muscles {name_list(dropped, sep=' ')}: the EMG of {name_list(dropped)} "
                      f"({name_list([c for m in dropped for c in mapping[m]])}) is not used (the muscle is out of the "
                      "problem)", MusclemetabWarning, stacklevel=3)
    return {m: c for m, c in mapping.items() if m not in set(excluded)}


def fiber_lengths_without(measured: dict, excluded) -> dict:
    """Measured fiber lengths without the excluded muscles (a warning names those dropped)."""
    import warnings

    from ..errors import MusclemetabWarning

    dropped = [m for m in measured if m in set(excluded)]
    if dropped:
        warnings.warn(f"--exclude-muscles {name_list(dropped, sep=' ')}: the measured fiber lengths of {name_list(dropped)} "
                      "are not used (the muscle is out of the problem)", MusclemetabWarning, stacklevel=3)
    return {m: v for m, v in measured.items() if m not in set(excluded)}


def _columns_without(table, excluded):
    """An EMG table mapped to muscles without the excluded muscles' columns (its attributes kept)."""
    out = table.drop(columns=[c for c in excluded if c in table.columns])
    out.attrs.update(table.attrs)
    return out


def trial_dofs(model, id_files, dofs, side: str, cache_dir) -> tuple[str, ...]:
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
