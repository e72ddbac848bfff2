"""The solution of a muscle redundancy problem: arrays, derived forces, files.

A solution folder holds two files:

``solution.sto``
    OpenSim storage, one row per mesh node ``t_0 ... t_N``, columns
    ``/forceset/<muscle>/<quantity>`` with quantity

    ==================================  =====================================================
    ``excitation``                      ``e`` (-)
    ``activation``                      ``a`` (-)
    ``normalized_fiber_length``         ``l~M = lM/lMo`` (-)
    ``normalized_fiber_velocity``       ``v~M/vmax``: fiber velocity in units of ``lMo vmax``
                                        (OpenSim's definition, in [-1, 1]; positive =
                                        lengthening). Multiply by ``vmax`` for ``lMo/s``, by
                                        ``lMo vmax`` for m/s.
    ``tendon_force``                    ``F0 fT(l~T)`` (N), with ``lT = lMT - sqrt(lM^2 - w^2)``
                                        from the geometry (``docs/method.md``)
    ``active_fiber_force``              ``a fL fV F0`` (N), along the fiber
    ``passive_fiber_force``             ``F0 fPE(l~M)`` (N), along the fiber
    ``active_force_length_multiplier``  ``fL(l~M)``
    ``force_velocity_multiplier``       ``fV(v~M/vmax)``
    ==================================  =====================================================

    plus ``/forceset/reserve_<dof>`` (N m). Controls (excitation, fiber velocity, and what
    depends on them: ``fV`` and the active fiber force) and reserves live on the intervals,
    i.e. at nodes ``0 ... N-1``; at node ``N`` the file repeats the value of node ``N-1``.
    With the backward fiber dynamics (``record.fiber_dynamics``, ``docs/problem.md``) the
    velocity of interval ``k`` is that of its end node: the fiber velocity, ``fV`` and the
    active fiber force are at nodes ``1 ... N`` and node ``0`` repeats node ``1``.
``summary.json``
    Status, objective, iterations, times, residuals, reserve RMS per DOF (and
    ``reserve_share_of_peak_moment``, the largest reserve RMS over the peak joint moment;
    ``large_reserve`` is true, with a :class:`~musclemetab.errors.LargeReserveWarning` for a converged solve,
    above :data:`LARGE_RESERVE_SHARE`, 1 %), muscles, DOFs,
    the muscle parameters used, the window, ``N`` and the workflow settings: the entries of
    :attr:`Solution.record` (:class:`~.record.SolveRecord`), in the order they were recorded.

Both files are written together (:func:`musclemetab.io.atomic_directory`): a reader never
sees one without the other.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import LargeReserveWarning, MissingColumnError
from ..io.jsonfile import json_ready
from ..io.solution_folder import SOLUTION_FILE, SUMMARY_FILE, read_solution_folder
from ..muscle import (
    active_force_length,
    activation_rate,
    force_velocity,
    passive_force_length,
    tendon_force_length,
)
from .parameters import MuscleTendonParameters
from .record import SolveRecord
from ..messages import name_list, user_stacklevel

__all__ = [
    "Solution",
    "MUSCLE_QUANTITIES",
    "SOLUTION_FILE",
    "SUMMARY_FILE",
    "muscle_column",
    "reserve_column",
    "derived_quantities",
    "read_flags",
    "read_summary",
]

SUMMARY_FORMAT = "musclemetab.redundancy.solution"
SUMMARY_VERSION = 1
#: Largest reserve RMS (over DOFs), as a share of the peak joint moment (over DOFs and
#: nodes), above which a solution is flagged: the study's solutions stay below 0.1 %; moments
#: three times too large (muscles at their limits) give about 4 %.
LARGE_RESERVE_SHARE = 0.01

MUSCLE_QUANTITIES = (
    "excitation",
    "activation",
    "normalized_fiber_length",
    "normalized_fiber_velocity",
    "tendon_force",
    "active_fiber_force",
    "passive_fiber_force",
    "active_force_length_multiplier",
    "force_velocity_multiplier",
)

CONVENTIONS = {
    "normalized_fiber_velocity": "v~M / vmax: fiber velocity in units of lMo*vmax (OpenSim's "
    "definition), positive = lengthening; the optimisation variable v~M (lMo/s) is this times vmax",
    "controls_at_last_node": "excitation, normalized_fiber_velocity, force_velocity_multiplier, "
    "active_fiber_force and the reserves are defined at nodes 0..N-1; the row of node N repeats node N-1",
    "tendon_force": "F0*fT(l~T) with lT = lMT - sqrt(lM^2 - w^2) from the geometry, w = lMo*sin(alpha0)",
    "active_fiber_force": "a*fL*fV*F0 along the fiber (not projected on the tendon)",
    "passive_fiber_force": "F0*fPE(l~M) along the fiber (not projected on the tendon)",
    "residuals": "moment residual = ID - sum(r*tendon_force) - reserve at nodes 0..N-1 (N m); "
    "hill residual = (a fL fV + fPE) cos(alpha) - fT at nodes 0..N-1 (normalised); activation "
    "residual = a_{k+1} - a_k - h*da/dt(e_k, a_k)",
}
#: the conventions that differ with the backward fiber dynamics (the Hill equilibrium of each
#: interval at its end node)
BACKWARD_CONVENTIONS = {
    "controls_at_last_node": "excitation and the reserves are defined at nodes 0..N-1, the row of node N repeats "
    "node N-1; normalized_fiber_velocity, force_velocity_multiplier and active_fiber_force at nodes 1..N (the "
    "velocity of interval k is that of its end node k+1), the row of node 0 repeats node 1",
    "residuals": "moment residual = ID - sum(r*tendon_force) - reserve at nodes 0..N-1 (N m); "
    "hill residual = (a fL fV + fPE) cos(alpha) - fT at nodes 1..N (normalised); activation "
    "residual = a_{k+1} - a_k - h*da/dt(e_k, a_k)",
}


def muscle_column(muscle: str, quantity: str) -> str:
    return f"/forceset/{muscle}/{quantity}"


def reserve_column(dof: str) -> str:
    return f"/forceset/reserve_{dof}"


def derived_quantities(
    params: MuscleTendonParameters,
    activation: np.ndarray,
    lm_norm: np.ndarray,
    fiber_velocity_lmo_per_s: np.ndarray,
    lmt_m: np.ndarray,
) -> dict:
    """Forces and multipliers from the states (``docs/method.md``), NumPy.

    Arrays are ``(nodes, M)``; ``fiber_velocity_lmo_per_s`` is ``v~M`` in lMo/s at the same nodes.
    """
    lmo = params.optimal_fiber_length_m
    f0 = params.max_isometric_force_N
    lm_m = lm_norm * lmo
    lm_proj = np.sqrt(np.maximum(lm_m**2 - params.width_m**2, 0.0))
    lt_norm = (lmt_m - lm_proj) / params.tendon_slack_length_m
    ft = tendon_force_length(lt_norm, params.tendon_stiffness)
    fl = active_force_length(lm_norm)
    fv = force_velocity(fiber_velocity_lmo_per_s / params.max_contraction_velocity)
    fpe = passive_force_length(lm_norm, params.passive_kpe, params.passive_s0, params.passive_sm)
    return {
        "tendon_force_norm": ft,
        "tendon_force_N": f0 * ft,
        "active_force_length_multiplier": fl,
        "force_velocity_multiplier": fv,
        "passive_force_length_multiplier": fpe,
        "active_fiber_force_N": activation * fl * fv * f0,
        "passive_fiber_force_N": f0 * fpe,
        "cos_pennation": lm_proj / lm_m,
        "lt_norm": lt_norm,
    }


def _hold_last(x: np.ndarray) -> np.ndarray:
    return np.vstack([x, x[-1:]])


@dataclass
class Solution:
    """Muscle states, controls and forces on the mesh, time-first arrays ``(N+1, M)``.

    Controls (``excitation``, ``fiber_velocity_lmo_per_s``), ``force_velocity_multiplier``,
    ``active_fiber_force_N`` and ``reserve_Nm`` repeat node ``N-1`` at node ``N`` (with the
    backward fiber dynamics ``fiber_velocity_lmo_per_s``, ``force_velocity_multiplier`` and
    ``active_fiber_force_N`` are those of nodes ``1 ... N`` and node ``0`` repeats node ``1``).
    ``fiber_velocity_lmo_per_s`` is ``v~M`` in lMo/s (the optimisation variable); the file stores
    ``v~M/vmax`` (see :attr:`normalized_fiber_velocity`). ``record`` is the solve's
    :class:`~.record.SolveRecord` (frozen; a stage that adds an entry makes a new solution with
    ``dataclasses.replace(solution, record=solution.record.with_(...))``).
    """

    time_s: np.ndarray
    muscles: tuple[str, ...]
    dofs: tuple[str, ...]
    excitation: np.ndarray
    activation: np.ndarray
    lm_norm: np.ndarray
    fiber_velocity_lmo_per_s: np.ndarray
    tendon_force_N: np.ndarray
    active_fiber_force_N: np.ndarray
    passive_fiber_force_N: np.ndarray
    active_force_length_multiplier: np.ndarray
    force_velocity_multiplier: np.ndarray
    reserve_Nm: np.ndarray
    parameters: MuscleTendonParameters
    record: SolveRecord = field(default_factory=SolveRecord)
    #: the :class:`~.problem.Problem` solved (:func:`.problem.solve`), or ``None`` (not kept in the folder)
    problem: "Problem | None" = field(default=None, repr=False, compare=False)  # noqa: F821 (a layer above)
    #: the solve's optimum as IPOPT left it (variables ``x``, multipliers ``lam_x``, ``lam_g``), in
    #: memory only (not written to the folder): a warm start from this solution starts from it
    #: (:func:`.static_opt.guess_from_solution`); ``None`` for a solution read from files
    multipliers: dict | None = field(default=None, repr=False, compare=False)

    #: the arrays of a solution, time-first ``(nodes, muscles)`` (``reserve_Nm``: ``(nodes, DOFs)``)
    ARRAYS = ("excitation", "activation", "lm_norm", "fiber_velocity_lmo_per_s", "tendon_force_N",
              "active_fiber_force_N", "passive_fiber_force_N", "active_force_length_multiplier",
              "force_velocity_multiplier", "reserve_Nm")

    def __repr__(self) -> str:
        """A summary of a few lines (workflow, leg, muscles x nodes, IPOPT's outcome, the stop and
        the rates' convergence, the plausibility flags), not the arrays."""
        import textwrap

        from ..messages import name_list

        rec = self.record
        where = ", ".join(x for x in (rec.workflow_name, f"side {rec.side}" if rec.side else "") if x)
        t = self.time_s
        span = f"{t[0]:.3f}-{t[-1]:.3f} s" if t.size else "no nodes"
        lines = [f"Solution{f' ({where})' if where else ''}: {len(self.muscles)} muscles x {t.size} nodes "
                 f"({span}, {self.n_intervals} intervals), {len(self.dofs)} DOFs",
                 *(f"  {line}" for line in rec.outcome_lines()),
                 f"  muscles: {name_list(self.muscles, 6)}",
                 f"  DOFs: {name_list(self.dofs, 6)}",
                 *textwrap.wrap(f"arrays (nodes x muscles): {', '.join(self.ARRAYS)}; write(folder), to_dataframe(), "
                                "to_mat(path)", 100, initial_indent="  ", subsequent_indent="    ")]
        return "\n".join(lines)

    __str__ = __repr__

    # ------------------------------------------------------------------ properties
    @property
    def summary(self) -> dict:
        """The record as the dictionary of ``summary.json`` (a copy: :attr:`record` is the solve's record)."""
        return self.record.to_dict()

    @property
    def run_record(self):
        """The :class:`~.record.RunRecord` of the solve (the IPOPT outcome of :attr:`record`)."""
        return self.record.run_record

    @property
    def status(self) -> str:
        return str(self.record.status)

    @property
    def success(self) -> bool:
        return bool(self.record.success)

    @property
    def objective(self) -> float:
        return math.nan if self.record.objective is None else float(self.record.objective)

    @property
    def n_intervals(self) -> int:
        return self.time_s.size - 1

    @property
    def normalized_fiber_velocity(self) -> np.ndarray:
        """``v~M / vmax`` (OpenSim's normalised fiber velocity)."""
        return self.fiber_velocity_lmo_per_s / self.parameters.max_contraction_velocity

    @property
    def fiber_length_m(self) -> np.ndarray:
        return self.lm_norm * self.parameters.optimal_fiber_length_m

    @property
    def fiber_velocity_m_per_s(self) -> np.ndarray:
        return self.fiber_velocity_lmo_per_s * self.parameters.optimal_fiber_length_m

    def muscle_index(self, name: str) -> int:
        try:
            return self.muscles.index(name)
        except ValueError:
            from ..errors import UnknownMuscleError

            raise UnknownMuscleError(
                f"muscle '{name}' is not in this solution; it has {name_list(self.muscles)}"
            ) from None

    # ------------------------------------------------------------------ files
    def to_mat(self, path: str | os.PathLike, metabolics=None) -> Path:
        """Write the solution (and, given, its :class:`~musclemetab.metabolics.solution.SolutionMetabolics`)
        to the MATLAB file ``path`` (:mod:`musclemetab.io.matlab`; the layout: ``docs/matlab.md``)."""
        from ..io.matlab import write_mat
        from ..metabolics.matlab import results_struct

        side = self.record.side or ""
        return write_mat(path, results_struct({side: self}, None if metabolics is None else {side: metabolics}))

    def to_dataframe(self):
        """The ``solution.sto`` table as a time-indexed pandas DataFrame."""
        return self._table().to_dataframe()

    def _table(self):
        """The ``solution.sto`` table (:class:`~musclemetab.io.StorageTable`, no pandas)."""
        from ..io import StorageTable

        cols: dict[str, np.ndarray] = {}
        per_quantity = {
            "excitation": self.excitation,
            "activation": self.activation,
            "normalized_fiber_length": self.lm_norm,
            "normalized_fiber_velocity": self.normalized_fiber_velocity,
            "tendon_force": self.tendon_force_N,
            "active_fiber_force": self.active_fiber_force_N,
            "passive_fiber_force": self.passive_fiber_force_N,
            "active_force_length_multiplier": self.active_force_length_multiplier,
            "force_velocity_multiplier": self.force_velocity_multiplier,
        }
        for q in MUSCLE_QUANTITIES:
            arr = per_quantity[q]
            for i, m in enumerate(self.muscles):
                cols[muscle_column(m, q)] = arr[:, i]
        for j, d in enumerate(self.dofs):
            cols[reserve_column(d)] = self.reserve_Nm[:, j]
        return StorageTable(self.time_s, list(cols), np.column_stack(list(cols.values())),
                            {"name": "musclemetab muscle redundancy solution", "in_degrees": False})

    def file_record(self) -> SolveRecord:
        """:attr:`record` as :meth:`write` stores it: with the file's format, muscles, DOFs,
        parameters and conventions (what :meth:`load` gives back)."""
        rec = self.record
        missing = {k: v for k, v in (("format", SUMMARY_FORMAT), ("format_version", SUMMARY_VERSION)) if k not in rec}
        rec = rec.with_(**missing, muscles=list(self.muscles), dofs=list(self.dofs),
                        parameters=self.parameters.to_records())
        return rec if "conventions" in rec else rec.with_(conventions=CONVENTIONS)

    def write(self, directory: str | os.PathLike) -> Path:
        """Write ``solution.sto`` and ``summary.json`` into ``directory`` (atomically)."""
        from ..io import atomic_directory, write_storage

        directory = Path(directory)
        summary = self.file_record().to_dict()
        text = json.dumps(json_ready(summary), indent=2, allow_nan=True)
        with atomic_directory(directory, mark=True) as tmp:
            write_storage(
                tmp / SOLUTION_FILE,
                self._table(),
                name="musclemetab muscle redundancy solution",
                in_degrees=False,
                comments=[f"status={summary.get('status', 'unknown')}",
                          f"workflow={summary.get('workflow', {}).get('name', '')}"],
            )
            (tmp / SUMMARY_FILE).write_text(text + "\n", encoding="utf-8")
        return directory

    @classmethod
    def load(cls, directory: str | os.PathLike, *, require_success: bool = True) -> "Solution":
        """Read a solution folder written by :meth:`write`.

        Raises :class:`SolverError` when the stored solve did not succeed (unless
        ``require_success=False``), :class:`InputFileError` when a file is missing or
        inconsistent.
        """
        directory = Path(directory)
        df, summary = read_solution_folder(
            directory, require_success=require_success, required_keys=("muscles", "dofs", "parameters", "status")
        )
        spath, jpath = directory / SOLUTION_FILE, directory / SUMMARY_FILE
        muscles = tuple(summary["muscles"])
        dofs = tuple(summary["dofs"])
        params = MuscleTendonParameters.from_records(summary["parameters"]).subset(muscles)
        need = [muscle_column(m, q) for q in MUSCLE_QUANTITIES for m in muscles]
        need += [reserve_column(d) for d in dofs]
        missing = [c for c in need if c not in df.columns]
        if missing:
            raise MissingColumnError(
                f"{spath}: missing column{'s' if len(missing) > 1 else ''} {', '.join(missing[:5])}"
                f"{' ...' if len(missing) > 5 else ''}; the file does not match {jpath}"
            )

        def block(q):
            return df[[muscle_column(m, q) for m in muscles]].to_numpy(dtype=float)

        return cls(
            time_s=df.index.to_numpy(dtype=float),
            muscles=muscles,
            dofs=dofs,
            excitation=block("excitation"),
            activation=block("activation"),
            lm_norm=block("normalized_fiber_length"),
            fiber_velocity_lmo_per_s=block("normalized_fiber_velocity") * params.max_contraction_velocity,
            tendon_force_N=block("tendon_force"),
            active_fiber_force_N=block("active_fiber_force"),
            passive_fiber_force_N=block("passive_fiber_force"),
            active_force_length_multiplier=block("active_force_length_multiplier"),
            force_velocity_multiplier=block("force_velocity_multiplier"),
            reserve_Nm=df[[reserve_column(d) for d in dofs]].to_numpy(dtype=float),
            parameters=params,
            record=SolveRecord.from_dict(summary),
        )


def _moments_source(inputs: dict) -> str:
    """How a message names the inverse dynamics of a solve: the ID file the user gave, or, for
    the moments computed from ground forces (a file of the package's cache, beside its
    checksum ``<name>.sha256``, which the user never named), the trial they were computed for."""
    id_path = inputs.get("id")
    if not id_path:
        return "the inverse dynamics"
    path = Path(str(id_path))
    if inputs.get("external_loads") and path.with_name(path.name + ".sha256").is_file():
        return f"the inverse dynamics computed from {inputs.get('ik', 'the IK motion')} and {inputs['external_loads']}"
    return str(id_path)


def read_summary(folder, *, missing: str = "not found", remedy: str = "") -> SolveRecord:
    """The typed record (:class:`~.record.SolveRecord`) of a solution folder's ``summary.json``,
    for readers that need the record and not the arrays (the report, the analysis);
    :class:`InputFileError` naming the file (``missing`` and ``remedy`` as
    :func:`~musclemetab.io.read_json_object` words them) when it cannot be read."""
    from ..io import read_json_object

    return SolveRecord.from_dict(read_json_object(Path(folder) / SUMMARY_FILE, missing=missing, remedy=remedy))


def read_flags(folder) -> list:
    """The plausibility flags (:class:`~.plausibility.Flag`) a solution folder's ``summary.json``
    recorded (``[]``: none, or not checked)."""
    return read_summary(folder).flags


def build_solution(
    inputs,
    params: MuscleTendonParameters,
    ocp,
    summary: dict,
) -> Solution:
    """Assemble a :class:`Solution` from an :class:`~.ipopt.OcpResult` and the trial inputs.

    Its :attr:`~Solution.record` is ``summary`` (the builder's entries) with the residuals
    (moment, Hill equilibrium, activation dynamics) and reserve statistics computed here in NumPy from the reported quantities. With
    ``summary["fiber_dynamics"] == "backward"`` the fiber velocity of interval ``k`` is placed
    at node ``k+1`` and the Hill equilibrium checked at nodes ``1 ... N``.
    """
    N = inputs.n_intervals
    h = inputs.step_s
    backward = summary.get("fiber_dynamics", "forward") == "backward"
    vm_nodes = np.vstack([ocp.fiber_velocity_lmo_per_s[:1], ocp.fiber_velocity_lmo_per_s]) if backward else _hold_last(ocp.fiber_velocity_lmo_per_s)
    d = derived_quantities(params, ocp.activation, ocp.lm_norm, vm_nodes, inputs.lmt_m)
    reserve_Nm = _hold_last(ocp.reserve * summary.get("optimal_reserve_Nm", 150.0))
    # residuals at the constrained nodes 0..N-1, from the reported (geometry-based) forces
    muscle_moment = np.einsum("kdm,km->kd", inputs.moment_arms_m[:N], d["tendon_force_N"][:N])
    moment_res = inputs.moments_Nm[:N] - muscle_moment - reserve_Nm[:N]
    fiber = (ocp.activation * d["active_force_length_multiplier"] * d["force_velocity_multiplier"]
             + d["passive_force_length_multiplier"])
    hill_res = (fiber * d["cos_pennation"] - d["tendon_force_norm"])[1:] if backward else \
        (fiber * d["cos_pennation"] - d["tendon_force_norm"])[:N]
    act_res = ocp.activation[1:] - ocp.activation[:-1] - h * activation_rate(ocp.excitation, ocp.activation[:N])
    reserve_rms = np.sqrt(np.mean(ocp.reserve**2, axis=0)) * summary.get("optimal_reserve_Nm", 150.0)
    peak_moment = float(np.max(np.abs(inputs.moments_Nm))) if inputs.moments_Nm.size else 0.0
    share = float(np.max(reserve_rms)) / peak_moment if peak_moment > 0 else 0.0
    large = share > LARGE_RESERVE_SHARE
    if large and summary.get("success", True):  # an unconverged solve is reported as such instead
        dof = inputs.dofs[int(np.argmax(reserve_rms))]
        peak_dof = inputs.dofs[int(np.argmax(np.max(np.abs(inputs.moments_Nm), axis=0)))]
        warnings.warn(
            f"{_moments_source(summary.get('inputs') or {})}: the reserve about {dof} has an RMS of "
            f"{float(np.max(reserve_rms)):.3g} N m, {100 * share:.2g} % of the largest peak joint moment "
            f"({peak_dof}, {peak_moment:.4g} N m), above {100 * LARGE_RESERVE_SHARE:g} %: the muscles do not explain "
            "the moments; check the moments' scale and that the inverse dynamics belongs to this model and trial",
            LargeReserveWarning, stacklevel=user_stacklevel(),
        )
    summary = dict(summary)
    if backward:
        summary["conventions"] = {**CONVENTIONS, **BACKWARD_CONVENTIONS}
    summary.update(
        max_moment_residual_Nm=float(np.max(np.abs(moment_res))),
        max_moment_residual_by_dof_Nm=dict(zip(inputs.dofs, np.max(np.abs(moment_res), axis=0).tolist())),
        max_hill_residual=float(np.max(np.abs(hill_res))),
        max_activation_dynamics_residual=float(np.max(np.abs(act_res))),
        reserve_rms_Nm=dict(zip(inputs.dofs, reserve_rms.tolist())),
        reserve_max_abs_Nm=dict(zip(inputs.dofs, np.max(np.abs(reserve_Nm), axis=0).tolist())),
        reserve_share_of_peak_moment=share,
        large_reserve=bool(large),
        peak_moment_by_dof_Nm=dict(zip(inputs.dofs, np.max(np.abs(inputs.moments_Nm), axis=0).tolist())),
    )
    solution = Solution(
        time_s=inputs.mesh_time_s.copy(),
        muscles=tuple(inputs.muscles),
        dofs=tuple(inputs.dofs),
        excitation=_hold_last(ocp.excitation),
        activation=ocp.activation.copy(),
        lm_norm=ocp.lm_norm.copy(),
        fiber_velocity_lmo_per_s=vm_nodes,
        tendon_force_N=d["tendon_force_N"],
        active_fiber_force_N=d["active_fiber_force_N"],
        passive_fiber_force_N=d["passive_fiber_force_N"],
        active_force_length_multiplier=d["active_force_length_multiplier"],
        force_velocity_multiplier=d["force_velocity_multiplier"],
        reserve_Nm=reserve_Nm,
        parameters=params,
        record=SolveRecord.from_dict(summary),
        multipliers=dict(getattr(ocp, "kkt", None) or {}) or None,
    )
    from .convergence import convergence_record
    from .plausibility import solution_flags  # the checks after the solve (docs/quality.md)

    opts = summary.get("solver_options") or {}
    solution = replace(solution, record=solution.record.with_(convergence=convergence_record(
        solution, stop=opts.get("stop"), tolerance=opts.get("tol"),
        final_barrier_parameter=getattr(ocp, "final_barrier_parameter", None),
        w_activation=float(opts.get("w_activation", 1.0)))))
    flags = [f.to_dict() for f in solution_flags(solution)]
    return replace(solution, record=solution.record.with_(plausibility=flags))
