"""OpenSim files that reproduce a solution: a model, its states, controls and forces.

Written into a solution folder by :func:`write_opensim_files` (``docs/opensim_files.md``):

``model.osim``
    the solved model with every muscle a ``DeGrooteFregly2016Muscle`` (OpenSim's own De
    Groote et al. 2016 muscle); the solved muscles carry the solution's parameters (F0, lMo,
    lTs, pennation, vmax as they are; kT and the passive parameters through the strains at
    which the solution's curves reach one normalised force, :func:`opensim_muscle_parameters`;
    no fiber damping). Locked coordinates are prescribed at the value they are locked at;
    every other coordinate has a ``CoordinateActuator`` ``reserve_<coordinate>`` of optimal
    force 1. Where a parameter has no exact counterpart the file says so in a comment.
``states.sto``
    one row per mesh node at which the solution's Hill equilibrium holds (:func:`equilibrium_nodes`:
    every node but the last, ``N``, with the forward fiber dynamics) and one column per state
    variable of ``model.osim``, so that
    ``StatesTrajectory.createFromStatesTable(model, TimeSeriesTable("states.sto"))`` accepts it
    with no missing or extra columns and no assembly: coordinate values and speeds of the IK
    motion at the node times (rad or m; rad/s or m/s; coupled coordinates from their couplers,
    locked ones at their value); ``/forceset/<muscle>/activation`` and
    ``/forceset/<muscle>/normalized_tendon_force`` (``tendon force / F0``; a slack tendon
    below OpenSim's curve, :data:`SLACK_TENDON_FORCE`, at OpenSim's force for the solution's
    tendon length) of the solution;
    the model's default for every other state.
``controls.sto``
    the muscles' excitations (``/forceset/<muscle>``) and the reserves' controls
    (``/forceset/reserve_<coordinate>``, the generalised forces of ``forces.sto``).
``forces.sto``
    the actuator forces at the same nodes, in the format of OpenSim's static optimisation output, as
    ``JointReaction``'s ``forces_file`` wants them (one column per actuator of ``model.osim``,
    labelled with the actuator's name): the solved muscles' tendon forces (N), zero for the
    other muscles, and the generalised forces of the reserves: the solution's reserve on a
    solved DOF; on every other free coordinate the inverse dynamics less what the solved
    muscles apply to it (``ID - sum(r F)``), so that muscles and reserves together give every
    coordinate its inverse-dynamics force.

Every file holds the nodes :func:`equilibrium_nodes` gives, and says so in its header. At the
node the forward Euler step reaches last (``N``) the transcription constrains no Hill
equilibrium: its fiber length is the step from node ``N-1`` and its tendon force is whatever
the tendon curve gives there, down to a slack, compressive value (-0.22 F0 on the example's fast
trial), which OpenSim and ``JointReaction`` would take for a pushing tendon. The solution keeps
that node (its arrays are the optimum's); the files leave it out.

The coordinates are those the solve used: the IK frames of the solved window, low-pass
filtered as the solve filtered the muscle-tendon lengths (``input_preparation`` in
``summary.json``) and interpolated with not-a-knot cubic splines. The model work runs in the
OpenSim worker (:mod:`musclemetab.opensim_bridge.solution_model`) and is kept in the package's
on-disk cache (:mod:`musclemetab.cache`), keyed by the content of the model, the motion, the
solved muscles and DOFs but not by the muscles' parameter values, which are placed into the
cached model text: a write that finds the entry starts no OpenSim. Without it,
:func:`prepare_opensim_files` starts the work while the solution is being solved (``musclemetab
solve`` does), so that after the solve only the solution's values are placed and the files written.
"""

from __future__ import annotations

import functools
import json
import os
from pathlib import Path

import numpy as np

from ..errors import DataMismatchError, InputFileError
from ..messages import name_list

__all__ = ["STATES_FILE", "CONTROLS_FILE", "FORCES_FILE", "MODEL_FILE", "OPENSIM_FILES", "equilibrium_nodes",
           "tendon_strain_at_one_norm_force", "passive_fiber_strain_at_one_norm_force",
           "opensim_muscle_parameters", "normalized_tendon_force_state", "inverse_dynamics_at", "opensim_tables",
           "prepare_opensim_files", "model_work_is_cached", "write_opensim_files", "write_solution_opensim_files",
           "write_opensim_states", "joint_reaction"]

STATES_FILE = "states.sto"
CONTROLS_FILE = "controls.sto"
FORCES_FILE = "forces.sto"
MODEL_FILE = "model.osim"
OPENSIM_FILES = (MODEL_FILE, STATES_FILE, CONTROLS_FILE, FORCES_FILE)


def tendon_strain_at_one_norm_force(kT):
    """The tendon strain at which the package's tendon curve reaches one normalised force.

    ``fT(l~T) = exp(kT (l~T - 0.995))/5 - 0.25 + shift(kT) = 1`` gives
    ``l~T = 0.995 + ln(5 (1.25 - shift(kT)))/kT``; the strain is ``l~T - 1``
    (0.047362 for the generic ``kT = 35``). OpenSim's DeGrooteFregly2016Muscle takes it as
    ``tendon_strain_at_one_norm_force``; its curve ``0.2 (exp(k (l~T - 1)) - 1)``,
    ``k = ln 6 / strain``, passes through the same point but is not the same curve.
    """
    from ..muscle import tendon_shift

    k = np.asarray(kT, dtype=float)
    return 0.995 + np.log(5.0 * (1.25 - tendon_shift(k))) / k - 1.0


def passive_fiber_strain_at_one_norm_force(kpe, s0, sm):
    """The fiber strain at which the package's passive curve reaches one normalised force.

    ``fPE(l~M) = [exp(kPE (l~M - s0)/sM) - 1 - P1]/P2 = 1`` with ``P1 = exp(-4 kPE/3) - 1``,
    ``P2 = exp(kPE) - 1`` gives ``l~M = s0 + (sM/kPE) ln(exp(kPE) - 1 + exp(-4 kPE/3))``; the
    strain is ``l~M - 1`` (0.597233 for the generic 4, 1, 0.6). OpenSim's
    DeGrooteFregly2016Muscle takes it as ``passive_fiber_strain_at_one_norm_force``; its
    curve has the fixed ``kPE = 4`` and no ``s0``.
    """
    kpe, s0, sm = (np.asarray(x, dtype=float) for x in (kpe, s0, sm))
    return s0 + (sm / kpe) * np.log(np.exp(kpe) - 1.0 + np.exp(-4.0 * kpe / 3.0)) - 1.0


def opensim_muscle_parameters(params) -> dict:
    """``{muscle: DeGrooteFregly2016Muscle property values}`` of a
    :class:`~.parameters.MuscleTendonParameters` (the mapping of ``docs/opensim_files.md``)."""
    from ..muscle import TAU_ACTIVATION_S, TAU_DEACTIVATION_S

    strain_t = tendon_strain_at_one_norm_force(params.tendon_stiffness)
    strain_p = passive_fiber_strain_at_one_norm_force(params.passive_kpe, params.passive_s0, params.passive_sm)
    bad = [params.names[i] for i in np.flatnonzero(~(strain_t > 0) | ~(strain_p > 0))]
    if bad:
        raise DataMismatchError(
            f"the tendon or passive curve of {name_list(bad)} reaches one normalised force before its slack or "
            "optimal length (a strain at one normalised force of zero or less), which OpenSim's "
            "DeGrooteFregly2016Muscle cannot represent; check the tendon stiffness and passive parameters"
        )
    out = {}
    for i, m in enumerate(params.names):
        out[m] = dict(
            max_isometric_force_N=float(params.max_isometric_force_N[i]),
            optimal_fiber_length_m=float(params.optimal_fiber_length_m[i]),
            tendon_slack_length_m=float(params.tendon_slack_length_m[i]),
            pennation_angle_at_optimal_rad=float(params.pennation_angle_at_optimal_rad[i]),
            max_contraction_velocity=float(params.max_contraction_velocity[i]),
            tendon_strain_at_one_norm_force=float(strain_t[i]),
            passive_fiber_strain_at_one_norm_force=float(strain_p[i]),
            activation_time_constant_s=TAU_ACTIVATION_S,
            deactivation_time_constant_s=TAU_DEACTIVATION_S,
        )
    return out


#: OpenSim's DeGrooteFregly2016Muscle tendon curve ``0.2 (exp(k (l~T - 1)) - 1)`` stays above
#: -0.2; a solution's slack tendon (the package's curve goes down to ``-0.25 + shift(kT)``)
#: below this normalised force is written as OpenSim's force at the solution's tendon length
SLACK_TENDON_FORCE = -0.19


def normalized_tendon_force_state(solution) -> np.ndarray:
    """The ``normalized_tendon_force`` states of a solution ``(nodes, muscles)``: its tendon
    force over F0; where that is below :data:`SLACK_TENDON_FORCE` (a slack tendon, beyond the
    range of OpenSim's curve), OpenSim's curve at the solution's tendon length."""
    from ..muscle import tendon_length_from_force

    p = solution.parameters
    f = np.asarray(solution.tendon_force_N, dtype=float) / p.max_isometric_force_N
    slack = f < SLACK_TENDON_FORCE
    if slack.any():
        strain = tendon_strain_at_one_norm_force(p.tendon_stiffness)
        k = np.broadcast_to(np.log(6.0) / strain, f.shape)
        lt = tendon_length_from_force(f, p.tendon_stiffness)
        f = np.where(slack, 0.2 * (np.exp(k * (lt - 1.0)) - 1.0), f)
    return f


def _model_comments(solution, model_path) -> dict:
    p = solution.parameters
    comments = {"": (
        f"Model of a musclemetab muscle redundancy solution ({solution.record.workflow_name or 'solve'}, "
        f"{solution.time_s[0]:g}-{solution.time_s[-1]:g} s), made from {Path(model_path).name}. Every muscle is "
        "OpenSim's DeGrooteFregly2016Muscle (OpenSim's replaceMuscles); the solved muscles carry the solution's "
        "parameters. No exact counterpart in this class: the tendon curve (kT and its shift) and the passive "
        "curve (kPE, s0, sM) are given by the strains at which the solution's curves reach one normalised force "
        "(the curves differ in shape away from that point); OpenSim's active force-length and force-velocity "
        "constants differ from the solution's (fL(1) = 1 and fV(0) = 1 instead of 0.99943 and 1.00212) and its "
        "activation dynamics switches between the time constants with tanh(10 (e - a)) instead of "
        "tanh(0.1 (e - a)). Locked coordinates are prescribed at the value they are locked at. "
        "reserve_<coordinate>: CoordinateActuators of optimal force 1 (the reserves and the remaining "
        "generalised forces of forces.sto). See docs/opensim_files.md of musclemetab."
    )}
    strain_t = tendon_strain_at_one_norm_force(p.tendon_stiffness)
    strain_p = passive_fiber_strain_at_one_norm_force(p.passive_kpe, p.passive_s0, p.passive_sm)
    for i, m in enumerate(p.names):
        comments[m] = (
            f"solved: kT {p.tendon_stiffness[i]:.6g} -> tendon_strain_at_one_norm_force {strain_t[i]:.6g}; "
            f"passive kPE {p.passive_kpe[i]:.6g}, s0 {p.passive_s0[i]:.6g}, sM {p.passive_sm[i]:.6g} -> "
            f"passive_fiber_strain_at_one_norm_force {strain_p[i]:.6g} (no exact counterpart: same strain at "
            "one normalised force, other curve shape)"
        )
    return comments


def _solution_inputs(solution, model_path, ik_path, id_path):
    inputs = dict(solution.record.inputs or {})
    paths = {"model": model_path or inputs.get("model"), "ik": ik_path or inputs.get("ik"),
             "id": id_path or inputs.get("id")}
    for key, option in (("model", "model_path"), ("ik", "ik_path")):
        if not paths[key]:
            raise InputFileError(f"the solution does not name its {key} file (summary.json 'inputs'); give {option}")
    for key, path in paths.items():
        if path and not Path(path).is_file():
            raise InputFileError(f"{path}: the solution's {key} file is missing; give the file it was solved with")
    return paths


def _coordinates_of_window(time_s, filtered: bool, ik, ik_path):
    """The IK columns over the frames of the solved window ``time_s``, filtered as the solve
    filtered the muscle-tendon lengths (``filtered``: ``input_preparation``'s filter)."""
    from ..io import constant_rate
    from .inputs import FILTER_CUTOFF_HZ, FILTER_ORDER, lowpass_filtfilt

    t = np.asarray(ik.index, dtype=float)
    keep = (t >= time_s[0] - 1e-6) & (t <= time_s[-1] + 1e-6)
    t = t[keep]
    columns = {c: np.asarray(ik[c], dtype=float)[keep] for c in ik.columns}
    if t.size > 1 and filtered:
        fs = constant_rate(t, f"the IK motion of {ik_path}")[1]
        names = list(columns)
        filtered_values = lowpass_filtfilt(np.column_stack([columns[c] for c in names]), fs, FILTER_CUTOFF_HZ,
                                           FILTER_ORDER, what=f"the IK motion of {ik_path}")
        columns = {c: filtered_values[:, j] for j, c in enumerate(names)}
    return t, columns


def _model_inputs(model_path, ik_path, time_s, filtered: bool, parameters, dofs):
    """The inputs of the OpenSim worker's model work
    (:func:`musclemetab.opensim_bridge.solution_model.prepare_solution_model`) for a solution
    over the mesh ``time_s`` with ``parameters`` (:class:`~.parameters.MuscleTendonParameters`)
    and the solved ``dofs``."""
    from ..io import read_table

    ik = read_table(ik_path)
    t = np.asarray(time_s, dtype=float)
    ik_t, columns = _coordinates_of_window(t, filtered, ik, ik_path)
    if ik_t.size < 2 or ik_t[0] > t[0] + 1e-6 or ik_t[-1] < t[-1] - 1e-6:
        raise DataMismatchError(
            f"the solution spans {t[0]:g}-{t[-1]:g} s but the IK motion {ik_path} does not; give the IK file of "
            "the solved trial"
        )
    return (str(model_path), opensim_muscle_parameters(parameters), ik_t, columns, bool(ik.attrs.get("in_degrees")),
            t, list(dofs))


def prepare_opensim_files(model_path, ik_path, time_s, parameters, dofs, filtered: bool = True, cache_dir=None) -> None:
    """Start the OpenSim work of :func:`write_opensim_files` that needs no solution values, for a
    solution about to be solved over the mesh ``time_s`` with ``parameters`` and the solved
    ``dofs`` (the IK filtered as the solve filters it when ``filtered``): unless the cache holds
    that work (:func:`model_work_is_cached`), the OpenSim worker converts the model, sets the
    parameters, adds the reserves and computes the states and moment arms along the motion while
    this process solves, and keeps the result for the files of that solution
    (:func:`musclemetab.opensim_bridge.call_in_background`). Nothing is written and the files are
    the same with or without it; bad input is left to the write, which reports it."""
    from ..errors import MusclemetabError
    from ..opensim_bridge import call_in_background

    try:
        args = _model_inputs(model_path, ik_path, time_s, filtered, parameters, dofs)
        if model_work_is_cached(*args, cache_dir=cache_dir):
            return
    except (MusclemetabError, OSError):
        return
    call_in_background("solution_model:prepare_solution_model", *args)


#: bump when the cached model work of the OpenSim files changes meaning
OPENSIM_FILES_CACHE_FORMAT = 1
#: the worker's modules that do the model work: their source is part of the cache key
_WORKER_MODULES = ("solution_model.py", "states.py", "model_ops.py")


@functools.lru_cache(maxsize=1)
def _opensim_version() -> str:
    """The installed OpenSim's version file (``opensim/version.py``), read as text: no ``import
    opensim``, and quicker than the package metadata."""
    from importlib.util import find_spec

    try:
        spec = find_spec("opensim")
        return Path(spec.origin).with_name("version.py").read_text(encoding="utf-8")
    except (AttributeError, TypeError, OSError, ValueError):  # no OpenSim: the worker will say so
        return "unknown"


def _model_work_spec(model, parameters, ik_t, columns, in_degrees, times, dofs) -> dict:
    """The cache key's description of the model work of :func:`_model_inputs`' inputs: the model
    file's content, the OpenSim version and the source of the worker's modules that do the work,
    the solved muscles (names, not parameter values: those are placed in the text,
    :func:`~musclemetab.opensim_bridge.model_xml.with_muscle_properties`), the DOFs and the motion
    (the IK window's values and the node times)."""
    import hashlib

    from ..io.atomic import file_sha256

    here = Path(__file__).resolve().parent.parent / "opensim_bridge"
    motion = hashlib.sha256()
    for name, a in (("ik time", ik_t), ("node times", times), *sorted(columns.items())):
        a = np.ascontiguousarray(a, dtype=float)
        motion.update(f"{name}:{a.shape}".encode())
        motion.update(a.tobytes())
    return {"fmt": OPENSIM_FILES_CACHE_FORMAT, "call": "opensim files", "model": file_sha256(model),
            "opensim": _opensim_version(), "worker": [file_sha256(here / m) for m in _WORKER_MODULES],
            "muscles": list(parameters), "dofs": list(dofs), "in_degrees": bool(in_degrees),
            "motion": motion.hexdigest()}


_PREFIX = "osimfiles-"
_WHAT = "OpenSim files"


def model_work_is_cached(model, parameters, ik_t, columns, in_degrees, times, dofs, cache_dir=None) -> bool:
    """Whether the cache (``cache_dir``, default the package's) holds the model work for these inputs
    (those of :func:`_model_inputs`; nothing is read or created)."""
    from ..cache import existing_entry

    return existing_entry(_model_work_spec(model, parameters, ik_t, columns, in_degrees, times, dofs), cache_dir,
                          prefix=_PREFIX)


def _info_json(info: dict) -> bytes:
    return json.dumps(info, default=lambda a: np.asarray(a).tolist()).encode()


def _info_from_json(data: bytes) -> dict:
    info = json.loads(data.decode())
    info["values"] = {k: np.asarray(v, dtype=float) for k, v in info["values"].items()}
    info["moment_arms_m"] = {c: {m: np.asarray(r, dtype=float) for m, r in arms.items()}
                             for c, arms in info["moment_arms_m"].items()}
    return info


def _model_work(model, model_out, parameters, ik_t, columns, in_degrees, t, dofs, cache_dir=None) -> tuple[str, dict]:
    """``(model text, info)`` of the solution's model: the text OpenSim writes for it (no comments)
    and what the worker's :func:`~musclemetab.opensim_bridge.solution_model.solution_model`
    returns. From the package's cache when it holds the work for these inputs (no OpenSim: the
    cached text gets these parameters); otherwise the worker writes ``model_out`` and the result
    is cached in ``cache_dir`` (default the package's; ``docs/opensim_files.md``)."""
    from ..cache import discard_entry, entry_path, read_entry, write_entry
    from ..opensim_bridge import call
    from ..opensim_bridge.model_xml import with_muscle_properties

    entry = entry_path(_model_work_spec(model, parameters, ik_t, columns, in_degrees, t, dofs), cache_dir, _WHAT,
                       prefix=_PREFIX)
    if entry is not None:
        arrays, problem = read_entry(entry)
        if arrays is not None:
            try:
                return (with_muscle_properties(arrays["model"].tobytes().decode(), parameters),
                        _info_from_json(arrays["info"].tobytes()))
            except (KeyError, ValueError, TypeError) as exc:
                problem = f"does not hold the model work of OpenSim files ({exc})"
        if problem:
            discard_entry(entry, problem, _WHAT)
    info = call("solution_model:solution_model", model, str(model_out), parameters, ik_t, columns, in_degrees, t,
                dofs)
    with open(model_out, encoding="utf-8", newline="") as fh:
        text = fh.read()
    if entry is not None:
        write_entry(entry, _WHAT, model=np.frombuffer(text.encode(), dtype=np.uint8),
                    info=np.frombuffer(_info_json(info), dtype=np.uint8))
    return text, info


def inverse_dynamics_at(id_path, coordinates, times) -> dict:
    """``{coordinate: inverse-dynamics force at times}`` (``<coordinate>_moment`` or ``_force``
    columns; filtered as the solve filters the moments, cubic spline at the times)."""
    from scipy.interpolate import CubicSpline

    from ..io import constant_rate, read_table
    from .inputs import FILTER_CUTOFF_HZ, FILTER_ORDER, lowpass_filtfilt

    table = read_table(id_path)
    t = np.asarray(table.index, dtype=float)
    found = {}
    for c in coordinates:
        for suffix in ("_moment", "_force"):
            if f"{c}{suffix}" in table.columns:
                found[c] = np.asarray(table[f"{c}{suffix}"], dtype=float)
                break
    if not found:
        return {}
    names = list(found)
    values = np.column_stack([found[c] for c in names])
    if t.size > 13:
        what = f"the inverse dynamics {id_path}"
        values = lowpass_filtfilt(values, constant_rate(t, what)[1], FILTER_CUTOFF_HZ, FILTER_ORDER, what=what)
    spline = CubicSpline(t, values, axis=0, bc_type="not-a-knot")
    at = spline(np.clip(times, t[0], t[-1]))
    return {c: at[:, j] for j, c in enumerate(names)}


def equilibrium_nodes(solution) -> slice:
    """The nodes of ``solution`` at which its Hill equilibrium (tendon force = fiber force along
    the tendon) holds: ``0 ... N-1`` with the forward fiber dynamics, ``1 ... N`` with the backward
    (``summary.json`` ``fiber_dynamics``). The OpenSim files hold these nodes alone."""
    n = np.asarray(solution.time_s).size
    backward = (solution.record.get("fiber_dynamics") or "forward") == "backward"
    return slice(1, n) if backward else slice(0, n - 1)


def _table(t, columns: dict, name: str, rows: slice = slice(None)):
    from ..io import StorageTable

    values = np.column_stack([np.broadcast_to(np.asarray(v, dtype=float), t.shape) for v in columns.values()])
    return StorageTable(t[rows], list(columns), values[rows], {"name": name, "in_degrees": False})


def opensim_tables(solution, model_out, model_path=None, ik_path=None, id_path=None, cache_dir=None):
    """Write the solution's model to ``model_out``; return its states, controls and forces
    tables (:class:`~musclemetab.io.StorageTable`, NumPy: no pandas) and what the worker reported
    (:func:`_model_work`: from the cache when it holds the model work, with no OpenSim)."""
    from ..opensim_bridge.model_xml import with_comments

    paths = _solution_inputs(solution, model_path, ik_path, id_path)
    t = np.asarray(solution.time_s, dtype=float)
    filtered = str((solution.record.input_preparation or {}).get("filter", "none")) != "none"
    model, parameters, ik_t, columns, in_degrees, _, dofs = _model_inputs(
        paths["model"], paths["ik"], t, filtered, solution.parameters, solution.dofs)
    text, info = _model_work(model, model_out, parameters, ik_t, columns, in_degrees, t, dofs, cache_dir)
    with open(model_out, "w", encoding="utf-8", newline="") as fh:
        fh.write(with_comments(text, _model_comments(solution, paths["model"])))
    paths_of = info["muscle_paths"]
    # states
    values = dict(info["values"])
    tendon = np.asarray(solution.tendon_force_N, dtype=float)
    norm_force = normalized_tendon_force_state(solution)
    for i, m in enumerate(solution.muscles):
        values[f"{paths_of[m]}/activation"] = solution.activation[:, i]
        values[f"{paths_of[m]}/normalized_tendon_force"] = norm_force[:, i]
    rows = equilibrium_nodes(solution)  # the model work runs on every node; the files hold these
    states = _table(t, {n: values[n] if n in values else np.full(t.size, d)
                        for n, d in zip(info["state_names"], info["defaults"])}, "musclemetab states", rows)
    states.attrs["defaulted_coordinates"] = info["defaulted_coordinates"]
    # forces: muscles, then the reserves' generalised forces
    reserve_of = info["reserves"]
    solved_dofs = list(solution.dofs)
    unknown = [d for d in solved_dofs if d not in reserve_of]
    if unknown:
        raise DataMismatchError(f"{paths['model']}: no free coordinate {name_list(unknown)} of the solution; give "
                                "the model the solution was solved with")
    others = [c for c in reserve_of if c not in solved_dofs]
    id_forces = inverse_dynamics_at(paths["id"], others, t) if paths["id"] else {}
    muscle_force = {m: tendon[:, i] for i, m in enumerate(solution.muscles)}
    generalized = {d: solution.reserve_Nm[:, j] for j, d in enumerate(solved_dofs)}
    for c in others:
        g = np.array(id_forces.get(c, np.zeros(t.size)), dtype=float)
        for m, r in info["moment_arms_m"].get(c, {}).items():
            g = g - np.asarray(r) * muscle_force[m]
        generalized[c] = g
    forces_cols = {}
    name_of_reserve = {v: k for k, v in reserve_of.items()}
    for a in info["actuators"]:
        if a in name_of_reserve:
            forces_cols[a] = generalized[name_of_reserve[a]]
        else:
            forces_cols[a] = muscle_force.get(a, np.zeros(t.size))
    forces = _table(t, forces_cols, "Static Optimization", rows)
    controls = _table(t, {**{paths_of[m]: solution.excitation[:, i] for i, m in enumerate(solution.muscles)},
                          **{f"/forceset/{reserve_of[c]}": generalized[c] for c in reserve_of}},
                      "musclemetab controls", rows)
    info["id_coordinates"] = sorted(id_forces)
    return states, controls, forces, info


def write_opensim_files(solution, out_dir: str | os.PathLike | None = None, *, model_path=None, ik_path=None,
                        id_path=None, cache_dir=None) -> dict[str, Path]:
    """Write ``model.osim``, ``states.sto``, ``controls.sto`` and ``forces.sto`` of a solution
    (a :class:`~.solution.Solution` or its folder) into ``out_dir`` (default: the solution
    folder), all four together (atomically).

    The model, IK and ID files default to those the solution names (``summary.json``
    ``inputs``); without an ID file the reserves of the coordinates outside the problem are
    ``-sum(r F)`` alone. The model work comes from the cache ``cache_dir`` (default the
    package's) when it holds it.
    """
    from ..io import atomic_directory, write_storage
    from .solution import Solution

    if not isinstance(solution, Solution):
        folder = Path(solution)
        solution = Solution.load(folder, require_success=False)
        out_dir = folder if out_dir is None else out_dir
    if out_dir is None:
        raise DataMismatchError("give the folder to write the OpenSim files into (out_dir)")
    out_dir = Path(out_dir)
    rows = equilibrium_nodes(solution)
    n = np.asarray(solution.time_s).size
    first, last = range(n)[rows][0], range(n)[rows][-1]
    left_out = n - 1 if last < n - 1 else 0
    nodes = (f"nodes {first}-{last} of the solution's {n} ({solution.time_s[first]:g}-{solution.time_s[last]:g} s), "
             f"those where its Hill equilibrium holds; node {left_out} ({solution.time_s[left_out]:g} s), which the "
             "fiber dynamics reaches without an equilibrium (its tendon force can be slack, compressive), is left out")
    with atomic_directory(out_dir, mark=True) as tmp:
        states, controls, forces, _ = opensim_tables(solution, tmp / MODEL_FILE, model_path, ik_path, id_path, cache_dir)
        write_storage(tmp / STATES_FILE, states, name="musclemetab states", in_degrees=False,
                      comments=[f"OpenSim states of the muscle redundancy solution for {MODEL_FILE} (SI units: rad, "
                                "m, rad/s, m/s)", nodes])
        write_storage(tmp / CONTROLS_FILE, controls, name="musclemetab controls", in_degrees=False,
                      comments=[f"muscle excitations and reserve controls of the solution for {MODEL_FILE}", nodes])
        write_storage(tmp / FORCES_FILE, forces, name="Static Optimization", in_degrees=False,
                      comments=[f"actuator forces of the solution (N; reserves N m or N) for {MODEL_FILE}, in the "
                                "format of OpenSim's static optimisation output", nodes])
    return {"model": out_dir / MODEL_FILE, "states": out_dir / STATES_FILE, "controls": out_dir / CONTROLS_FILE,
            "forces": out_dir / FORCES_FILE}


def write_solution_opensim_files(solution, out_dir, cache_dir=None) -> dict[str, Path] | None:
    """:func:`write_opensim_files` of a converged solution that names its model and IK files (a
    solve from files); ``None`` (nothing written) for one solved from arrays alone or one that
    did not converge (its values are no solution to reproduce)."""
    inputs = solution.record.inputs or {}
    if not (inputs.get("model") and inputs.get("ik")) or not solution.success:
        return None
    return write_opensim_files(solution, out_dir, cache_dir=cache_dir)


def write_opensim_states(solution, model_path, ik_path, out_dir: str | os.PathLike | None = None) -> dict[str, Path]:
    """:func:`write_opensim_files` with the model and IK files given first (the study's call)."""
    return write_opensim_files(solution, out_dir, model_path=model_path, ik_path=ik_path)


def joint_reaction(folder, joints, out_dir, external_loads=None, frame: str = "child") -> dict:
    """OpenSim's ``JointReaction`` analysis over a solution folder's OpenSim files.

    Runs ``AnalyzeTool`` on ``model.osim`` over ``states.sto`` with ``forces.sto`` as the
    analysis' ``forces_file`` and the trial's ``external_loads`` (an ExternalLoads XML; its data
    file may be relative to the XML). Returns ``time_s`` and ``forces``: ``{joint: (states, 3)}``,
    the force (N) on the joint's child body expressed in the child's frame (``frame="child"``)
    or the ground's (``"ground"``); OpenSim's output files are in ``out_dir``.
    """
    import xml.etree.ElementTree as ET

    from ..opensim_bridge import call

    folder, out_dir = Path(folder), Path(out_dir)
    missing = [name for name in OPENSIM_FILES if not (folder / name).is_file()]
    if missing:
        raise InputFileError(f"{folder}: no {name_list(missing)}; write them with write_opensim_files")
    out_dir.mkdir(parents=True, exist_ok=True)
    xml = None
    if external_loads is not None:
        from ..external_loads import read_external_loads

        loads = read_external_loads(external_loads)
        tree = ET.parse(loads.path)  # the data file by its absolute path: OpenSim resolves it from the cwd
        root = tree.getroot()
        (root if root.tag == "ExternalLoads" else root.find(".//ExternalLoads")).find("datafile").text = str(
            loads.datafile)
        xml = out_dir / "external_loads.xml"
        tree.write(xml)
    return call("solution_model:joint_reaction", str(folder / MODEL_FILE), str(folder / STATES_FILE),
                str(folder / FORCES_FILE), list(joints), str(out_dir), None if xml is None else str(xml), "child", frame)
