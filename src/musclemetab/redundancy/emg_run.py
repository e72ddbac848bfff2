"""EMG-TEN, or an effort workflow's EMG-informed solve, from files (the pipeline the command line,
the study and Python users call): :func:`solve_emg_ten` over one or more trials, a
:class:`~.result.Result`; :func:`emg_mappings_of_legs`: the EMG mapping of each leg of an EMG
problem of both legs. It reads and checks every file before OpenSim is asked anything, like
:func:`.run.solve_files`."""

from __future__ import annotations

import os
from typing import Sequence

from ..errors import OptionError
from ..messages import name_list
from .._docs import fill_doc
from .emg_inputs import resolve_emg_mapping
from .emg_ten import EmgTenSettings
from .ipopt import SolverOptions
from .result import EMG_TEN, Result

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
    from .emg_inputs import path_list
    from .problem import TrialFiles, load_problem, solve

    ik_paths, id_paths, emg_paths = (path_list(p, what) for p, what in ((ik_paths, "ik_paths"), (id_paths, "id_paths"),
                                                                        (emg_paths, "emg_paths")))
    if not (len(ik_paths) == len(id_paths) == len(emg_paths)):
        raise OptionError(f"{len(ik_paths)} IK, {len(id_paths)} ID and {len(emg_paths)} EMG files; give one of each "
                          "per trial, in the same order")
    problem = load_problem(
        model_path, [TrialFiles(*files) for files in zip(ik_paths, id_paths, emg_paths)], workflow=workflow,
        labels=labels, side=side, dofs=dofs, emg=settings or EmgTenSettings(), emg_mapping=emg_mapping, passive=passive,
        tendon_stiffness=tendon_stiffness, options=options, cache_dir=cache_dir, check_units=check_units,
        exclude_muscles=exclude_muscles, exclude_missing_ok=exclude_missing_ok, diagnose_only=diagnose_only)
    return problem if diagnose_only else solve(problem, before_solve=before_solve)


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
