"""OpenSim-ready files of a solution: ``states.sto`` and ``controls.sto``.

``states.sto``
    one row per mesh node and one column per state variable of the model, named as
    OpenSim names them, in the model's units, so that
    ``StatesTrajectory.createFromStatesTable(model, TimeSeriesTable("states.sto"))``
    accepts it without allowing missing or extra columns:

    * ``/jointset/<joint>/<coordinate>/value`` and ``.../speed``: the IK motion at the node
      times (rad or m; rad/s or m/s), coupled coordinates from their couplers, locked ones
      at their default;
    * ``/forceset/<muscle>/activation``: the solution's activation;
    * ``/forceset/<muscle>/fiber_length``: the solution's fiber length in metres
      (``l~M lMo``) for muscles that have this state;
    * every other state (muscles not in the solution, other components): the model's
      default value.
``controls.sto``
    the muscles' excitations, one column per muscle named by its path
    (``/forceset/<muscle>``), at the same times.

The model work runs in the OpenSim worker (:mod:`musclemetab.opensim_bridge.states`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import DataMismatchError

__all__ = ["STATES_FILE", "CONTROLS_FILE", "opensim_states_table", "write_opensim_states"]

STATES_FILE = "states.sto"
CONTROLS_FILE = "controls.sto"


def opensim_states_table(solution, model_path, ik_path):
    """The states and controls tables (pandas, indexed by time) of a :class:`Solution`."""
    import pandas as pd

    from ..io import read_storage, storage_from_arrays
    from ..opensim_bridge import call

    ik = read_storage(ik_path)
    t = np.asarray(solution.time_s, dtype=float)
    info = call(
        "states:model_states_along_motion", str(model_path), ik.index.to_numpy(dtype=float),
        {c: ik[c].to_numpy(dtype=float) for c in ik.columns}, bool(ik.attrs.get("in_degrees")), t,
    )
    paths = info["muscle_paths"]
    unknown = [m for m in solution.muscles if m not in paths]
    if unknown:
        raise DataMismatchError(
            f"{model_path}: no muscle {', '.join(unknown)} of the solution; give the model the solution was solved with"
        )
    values = dict(info["values"])
    lm_m = solution.fiber_length_m
    with_length = set(info["muscles_with_fiber_length"])
    for i, m in enumerate(solution.muscles):
        values[f"{paths[m]}/activation"] = solution.activation[:, i]
        if m in with_length:
            values[f"{paths[m]}/fiber_length"] = lm_m[:, i]
    columns = {}
    for name, default in zip(info["state_names"], info["defaults"]):
        columns[name] = values[name] if name in values else np.full(t.size, default)
    states = storage_from_arrays(t, columns, name="musclemetab states")
    controls = storage_from_arrays(
        t, {paths[m]: solution.excitation[:, i] for i, m in enumerate(solution.muscles)}, name="musclemetab controls"
    )
    states.attrs["defaulted_coordinates"] = info["defaulted_coordinates"]
    assert isinstance(states, pd.DataFrame)
    return states, controls


def write_opensim_states(solution, model_path, ik_path, out_dir: str | os.PathLike | None = None) -> dict[str, Path]:
    """Write ``states.sto`` and ``controls.sto`` of a solution (a :class:`Solution` or its folder).

    ``out_dir`` defaults to the solution folder. Both files are written together, atomically.
    """
    from ..io import atomic_directory, write_storage
    from .solution import Solution

    if not isinstance(solution, Solution):
        folder = Path(solution)
        solution = Solution.load(folder)
        out_dir = folder if out_dir is None else out_dir
    if out_dir is None:
        raise DataMismatchError("give the folder to write states.sto and controls.sto into (out_dir)")
    out_dir = Path(out_dir)
    states, controls = opensim_states_table(solution, model_path, ik_path)
    with atomic_directory(out_dir) as tmp:
        write_storage(tmp / STATES_FILE, states, name="musclemetab states", in_degrees=False,
                      comments=["OpenSim states of the muscle redundancy solution (SI units: rad, m, rad/s, m/s)"])
        write_storage(tmp / CONTROLS_FILE, controls, name="musclemetab controls", in_degrees=False,
                      comments=["muscle excitations of the muscle redundancy solution"])
    return {"states": out_dir / STATES_FILE, "controls": out_dir / CONTROLS_FILE}
