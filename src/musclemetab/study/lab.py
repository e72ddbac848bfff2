"""A study's subjects and trials given as the lab's files: the scaled models and IK it makes.

A subject with ``generic_model`` and ``static`` is scaled by :func:`musclemetab.mocap.scaling.scale_model`
(its ``scale_setup`` or the shipped measurements); a trial with ``markers`` gets its IK from
:func:`musclemetab.mocap.kinematics.inverse_kinematics` (its ``ik_setup`` or the defaults), and a C3D
trial without ``id``, ``external_loads`` or ``grf`` its ground forces and ExternalLoads from the
force plates (:func:`musclemetab.mocap.export.convert_c3d`). The files go to
``prepared/<subject>/[<trial>/]`` in the study folder (:func:`musclemetab.study_layout.prepared_path`),
where the study file's subjects and trials already point (:mod:`.spec`); a subject without a height
takes the one estimated from its static trial. Scaling and IK are cached by content, so a study run
again (or resumed) does no OpenSim work for them, and the units' keys (the files' content) are
unchanged.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from .spec import Study, Subject

__all__ = ["prepare_study", "needs_preparation"]


def needs_preparation(subject: Subject) -> bool:
    return subject.generic_model is not None or any(t.markers is not None for t in subject.trials)


def prepare_study(study: Study) -> Study:
    """Make every subject's scaled model and every trial's IK (module docstring); returns the study
    with the estimated heights filled in."""
    subjects = [prepare_subject(s, Path(study.output)) if needs_preparation(s) else s for s in study.subjects]
    return replace(study, subjects=tuple(subjects))


def prepare_subject(subject: Subject, out: Path) -> Subject:
    from ..io import atomic_directory
    from ..mocap.export import convert_c3d
    from ..mocap.kinematics import inverse_kinematics
    from ..mocap.scaling import scale_model
    from ..study_layout import prepared_path

    height = subject.height_m
    if subject.generic_model is not None:
        scaled = scale_model(subject.generic_model, _static_trc(subject, out), subject.body_mass_kg,
                             setup=subject.scale_setup, marker_set=subject.marker_set, height_m=subject.height_m,
                             source=str(subject.static))
        with atomic_directory(out / prepared_path(subject.name), mark=True) as tmp:
            scaled.write(tmp)
            _write_record(tmp, scaled.record)
        if height is None:
            height = scaled.record["height_m"]
    for t in subject.trials:
        if t.markers is None:
            continue
        folder = out / prepared_path(subject.name, t.name)
        ik = inverse_kinematics(subject.model, t.markers, setup=t.ik_setup)
        with atomic_directory(folder, mark=True) as tmp:
            ik.write(tmp)
            _write_record(tmp, ik.record)
        if t.external_loads is not None and t.external_loads.parent == folder:  # the C3D's force plates
            convert_c3d(t.markers, folder, stem="markers", model=subject.model)
    return replace(subject, height_m=height)


def _static_trc(subject: Subject, out: Path) -> Path:
    """The static trial as a ``.trc``: a C3D file is converted into the subject's prepared folder."""
    if subject.static.suffix.lower() != ".c3d":
        return subject.static
    from ..io import atomic_directory
    from ..mocap.c3d import read_c3d
    from ..mocap.trc import write_trc
    from ..study_layout import prepared_path

    folder = out / prepared_path(subject.name)
    with atomic_directory(folder, mark=True) as tmp:
        write_trc(Path(tmp) / "static.trc", read_c3d(subject.static).markers)
    return folder / "static.trc"


def _write_record(folder, record: dict) -> None:
    import json

    (Path(folder) / "prepare.json").write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
