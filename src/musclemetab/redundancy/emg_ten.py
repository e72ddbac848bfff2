"""EMG-TEN: EMG-informed estimation of tendon stiffness over several trials in one NLP.

One optimal control problem holds, for every trial, the variables and constraints of the
single-trial problem (:mod:`.problem`: same mesh, bounds, forward-Euler scheme and node
conventions) plus shared parameters (``muscle_redundancy.md`` §6):

==================  =========================================  ==============================
parameter           size                                       bounds
==================  =========================================  ==============================
``s_kT``            one per estimated muscle (default soleus,  0.1 ... 1.2; ``kT = 35 s_kT``,
                    gasmed, gaslat, vasint, vaslat, vasmed)    ``shift(kT)`` recomputed
``s_EMG``           one per EMG-tracked muscle (alphabetical)  0.05 ... 2.5
==================  =========================================  ==============================

Couplings: ``s_kT(vaslat) = s_kT(vasmed) = s_kT(vasint)`` and
``s_kT(gaslat) = s_kT(gasmed) = s_kT(soleus)`` (consecutive pairs of each group);
``s_EMG(vaslat) = s_EMG(vasmed)``, ``s_EMG(vaslat) = s_EMG(vasint)``,
``s_EMG(gaslat) = s_EMG(gasmed)``. By default (``EmgTenSettings.coupling = "shared"``) each
coupled group is one variable (2 tendon factors and 6 EMG factors on the example). These
defaults name the study's right-leg model; for other models or the left leg the groups come
from the anatomical muscle table (tendon ``achilles`` / ``patellar``, EMG scale groups
``gastrocnemii`` / ``vasti``; :func:`settings_for_muscles`, ``docs/muscles.md``);
``coupling = "constraints"`` keeps the study's 6 + 9 factors with the 4 + 3 equalities. Same
objective, feasible set and bounds; the shared form took 133 IPOPT iterations on the example
against 158-177 for the constraint form (same optimum).

For each trial, tracked muscle ``m`` and control node ``k = 0 ... N-1`` (EMG ``E`` linearly
interpolated at ``t_k``)::

    -0.01 <= e_mk - s_EMG,m E_m(t_k) <= 0.01

Objective (trials summed, each normalised by its own ``N``)::

    J = sum_trials [ wEMG sum (e - s E)^2/(nEMG N) + wAct/2 (sum e^2 + sum a^2)/(N M)
                     + wTres sum aT^2/(N D) + wVm sum v~M^2/(N M) ]

with ``[wEMG, wAct, wTres, wVm] = [10, 0.1, 1000, 0.01]``. The Hill equilibrium and the
joint moments use ``kT = s_kT 35`` (symbolic) for the estimated muscles.

**Transcription.** Variables are ordered trial by trial, node by node as in the single-trial
problem (``[a, l~M, lp, e, aT, v~M]_k``, then ``[a, l~M, lp]_N``), the shared parameters last;
constraints likewise, each interval's equality rows followed by its EMG-tracking rows, the
couplings (constraint form) last. The per-interval expressions are those of :mod:`.problem` (the tendon
stiffness of the estimated muscles replaced by ``35 s_kT``); their Jacobian and the Hessian of
the Lagrangian are differentiated once per interval (SX), mapped over the nodes of all trials
and placed into the global sparse matrices handed to IPOPT. The Jacobian is block banded
with dense columns for the shared parameters; the Hessian is block diagonal with a border
(``s_kT`` couples with the projected fibre lengths of its muscles, ``s_EMG`` with the
excitations of its muscle) and a parameter block summed over all nodes. Moment arms that are
zero at every node (muscles not crossing a DOF) are dropped from the expressions, which
removes their structural zeros from the derivatives. Simple bounds are IPOPT variable bounds;
the EMG tracking rows are two-sided constraints. IPOPT settings are those of
:class:`~.problem.SolverOptions` plus :data:`LINEAR_SOLVER_OPTIONS`.

**Initial guess.** Per trial the static-optimisation guess of the single-trial problem with
the reserve divided by ``Topt``; all scale factors 1.

**Tendon stiffness in N/mm.** ``kT`` is dimensionless; the stiffness reported in N/mm is the
tangent slope of the tendon force-length curve where the tendon carries its maximal isometric
force ``F0`` (``fT = 1``)::

    k = dFT/dlT |_(fT = 1) = F0 kT (1.25 - shift(kT)) / lTs

(``muscle_model.md`` §7: ``dFT/dlT = F0 kT exp(kT (l~T - 0.995))/(5 lTs)`` and
``exp(kT (l~T - 0.995))/5 = fT + 0.25 - shift``). The slope at each trial's peak walking
tendon force is reported too. The Achilles tendon stiffness is the sum over soleus, gasmed
and gaslat (three tendons in parallel).
"""

from __future__ import annotations

import json
import math
import os
import platform
import time as _time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import (
    DataMismatchError,
    InputFileError,
    OptionError,
    SolverError,
    UnknownMuscleError,
)
from ..muscle import KT_GENERIC, tendon_length_from_force, tendon_stiffness_N_per_m
from .inputs import (
    DEFAULT_DOFS,
    TrialInputs,
    check_moment_magnitudes,
    check_time_ranges,
    prepare_inputs,
    read_inverse_dynamics,
    read_kinematics,
)
from .parameters import MuscleTendonParameters
from .problem import (
    OcpResult,
    ipopt_options,
    ipopt_statistics,
    node_bounds,
    run_ipopt,
    SolverOptions,
    _constants,
    _node_expressions,
)
from .solution import _jsonable, build_solution
from .static_opt import InitialGuess, initial_guess, static_optimisation

__all__ = [
    "EMG_TEN",
    "EmgTenSettings",
    "EmgTenTrial",
    "EmgTenOcpResult",
    "EmgTenResult",
    "PARAMETERS_FILE",
    "settings_for_muscles",
    "mapping_for_muscles",
    "resolve_emg_mapping",
    "build_emg_ten_nlp",
    "solve_emg_ten_ocp",
    "solve_emg_ten_arrays",
    "prepare_emg_ten_trials",
    "emg_ten_options",
    "LINEAR_SOLVER_OPTIONS",
    "solve_emg_ten",
    "tendon_stiffness_at_force_N_per_mm",
]

EMG_TEN = "emg-ten"
PARAMETERS_FILE = "parameters.json"
PARAMETERS_FORMAT = "musclemetab.redundancy.emg_ten_parameters"
PARAMETERS_VERSION = 1
#: Linear-algebra settings of IPOPT for EMG-TEN (``SolverOptions.ipopt`` overrides them):
#: MUMPS's approximate-minimum-fill ordering (on the three example trials it factorises in about
#: two thirds of the time of MUMPS's automatic choice) and no iterative refinement of a linear
#: solve whose residual already meets IPOPT's accuracy test (IPOPT's default is at least one
#: step; here that saves a quarter of the solve time with identical iterates to 1e-11). They
#: change the round-off of the KKT solves, not the problem.
LINEAR_SOLVER_OPTIONS = {"mumps_pivot_order": 2, "min_refinement_steps": 0}


@dataclass(frozen=True)
class EmgTenSettings:
    """Weights, bounds and couplings of the EMG-TEN problem (defaults: the study's).

    ``tendon_groups``: muscles whose ``kT`` is estimated; the muscles of a group share one
    factor (couplings between consecutive members). ``emg_groups``: tracked muscles sharing one
    EMG scale factor (couplings between the first member and each other one); members that
    are not tracked are ignored. ``emg_tolerance``: half-width of the EMG tracking band.
    ``emg_range_tolerance``: how far the mapped EMG may lie outside ``[0, 1]`` in the trial
    window before the input is rejected (0: not at all). ``coupling``: ``"shared"`` (default)
    gives each coupled group one variable; ``"constraints"`` keeps one variable per muscle and
    imposes the couplings as equality constraints, the study's NLP (77 250 variables and 62 002
    equalities on the example instead of 77 243 and 61 995). Both are the same problem (same
    objective, feasible set, bounds); they take different paths to the same optimum.
    """

    w_emg: float = 10.0
    w_activation: float = 0.1
    w_reserve: float = 1000.0
    w_velocity: float = 0.01
    emg_tolerance: float = 0.01
    tendon_scale_bounds: tuple[float, float] = (0.1, 1.2)
    emg_scale_bounds: tuple[float, float] = (0.05, 2.5)
    tendon_groups: tuple[tuple[str, ...], ...] = (
        ("vaslat_r", "vasmed_r", "vasint_r"), ("gaslat_r", "gasmed_r", "soleus_r"))
    emg_groups: tuple[tuple[str, ...], ...] = (("vaslat_r", "vasmed_r", "vasint_r"), ("gaslat_r", "gasmed_r"))
    emg_range_tolerance: float = 0.0
    coupling: str = "shared"

    def __post_init__(self):
        for name in ("w_emg", "w_activation", "w_reserve", "w_velocity"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise OptionError(f"the weight {name} must be a non-negative number, not {v!r}")
        if not (math.isfinite(self.emg_tolerance) and self.emg_tolerance >= 0):
            raise OptionError(f"emg_tolerance must be a non-negative number, not {self.emg_tolerance!r}")
        if not (math.isfinite(self.emg_range_tolerance) and self.emg_range_tolerance >= 0):
            raise OptionError(f"emg_range_tolerance must be non-negative, not {self.emg_range_tolerance!r}")
        for name in ("tendon_scale_bounds", "emg_scale_bounds"):
            lo, hi = (float(v) for v in getattr(self, name))
            if not (0 < lo <= hi and math.isfinite(hi)):
                raise OptionError(f"{name} must be (low, high) with 0 < low <= high, not {getattr(self, name)!r}")
            object.__setattr__(self, name, (lo, hi))
        for name in ("tendon_groups", "emg_groups"):
            groups = tuple(tuple(str(m) for m in g) for g in getattr(self, name))
            flat = [m for g in groups for m in g]
            if len(set(flat)) != len(flat):
                raise OptionError(f"{name}: a muscle appears in more than one group ({groups})")
            object.__setattr__(self, name, groups)
        if self.coupling not in ("constraints", "shared"):
            raise OptionError(f"coupling must be 'constraints' or 'shared', not {self.coupling!r}")
        if not any(self.tendon_groups):
            raise OptionError("tendon_groups is empty: EMG-TEN needs at least one muscle whose kT is estimated")

    @property
    def tendon_muscles(self) -> tuple[str, ...]:
        return tuple(m for g in self.tendon_groups for m in g)

    def to_dict(self) -> dict:
        return {
            "weights": {"w_emg": self.w_emg, "w_activation": self.w_activation,
                        "w_reserve": self.w_reserve, "w_velocity": self.w_velocity},
            "emg_tolerance": self.emg_tolerance,
            "tendon_scale_bounds": list(self.tendon_scale_bounds),
            "emg_scale_bounds": list(self.emg_scale_bounds),
            "tendon_groups": [list(g) for g in self.tendon_groups],
            "emg_groups": [list(g) for g in self.emg_groups],
            "emg_range_tolerance": self.emg_range_tolerance,
            "coupling": self.coupling,
        }


def resolve_emg_mapping(mapping: str | Mapping[str, Sequence[str] | str] | os.PathLike = "default") -> dict:
    """``"default"`` (vastus intermedius <- ``VI_a``), ``"authors"`` (<- ``ES``, the mapping
    of the published example results), a ``{muscle: [channel, ...]}`` mapping, or a JSON
    file holding one. Returns ``{muscle: [channels]}``."""
    from ..emg import AUTHORS_EMG_MAPPING, DEFAULT_EMG_MAPPING

    if isinstance(mapping, (str, os.PathLike)):
        key = str(mapping).strip()
        if key.lower() == "default":
            return {m: list(c) for m, c in DEFAULT_EMG_MAPPING.items()}
        if key.lower() == "authors":
            return {m: list(c) for m, c in AUTHORS_EMG_MAPPING.items()}
        path = Path(key)
        if path.suffix.lower() == ".json" or path.is_file():
            from ..io.jsonfile import read_json_object

            form = 'a JSON object {"muscle": ["channel", ...]}'
            mapping = read_json_object(
                path, missing=f"no such EMG mapping file; give 'default', 'authors' or {form}",
                remedy=f"an EMG mapping is {form}")
        else:
            raise OptionError(f"EMG mapping '{key}' is not 'default', 'authors' or a JSON file; "
                              "give one of these")
    if not isinstance(mapping, Mapping) or not mapping:
        raise OptionError("the EMG mapping is empty; give {muscle: [channel, ...]} for at least one muscle")
    out = {}
    for m, chans in mapping.items():
        chans = [chans] if isinstance(chans, str) else list(chans or [])
        if not chans or not all(isinstance(c, str) and c for c in chans):
            raise OptionError(f"EMG mapping: muscle '{m}' needs one or more channel names, not {chans!r}")
        out[str(m)] = chans
    return out


def settings_for_muscles(settings: EmgTenSettings | None, muscles: Sequence[str]) -> EmgTenSettings:
    """``settings`` whose default tendon and EMG groups (the study's right-leg model) are
    replaced, when the problem lacks those muscles, by the groups of the anatomical muscle
    table for ``muscles`` (any model family, either side; see ``docs/muscles.md``)."""
    from ..properties import emg_scale_groups, tendon_groups

    settings = settings or EmgTenSettings()
    default = EmgTenSettings()
    present = set(muscles)
    changes = {}
    if settings.tendon_groups == default.tendon_groups and not set(settings.tendon_muscles) <= present:
        changes["tendon_groups"] = tuple(tendon_groups(muscles).values())
    if settings.emg_groups == default.emg_groups and not {m for g in settings.emg_groups for m in g} <= present:
        changes["emg_groups"] = tuple(emg_scale_groups(muscles).values())
    return replace(settings, **changes) if changes else settings


def mapping_for_muscles(emg_mapping, mapping: dict, muscles: Sequence[str]) -> dict:
    """The named mappings (``default``, ``authors``) placed on other models' muscle names
    through the anatomical muscle table when the study's names are not in the problem."""
    from ..properties import default_emg_mapping, resolve_muscles

    named = isinstance(emg_mapping, str) and emg_mapping.strip().lower() in ("default", "authors")
    if not named or set(mapping) <= set(muscles):
        return mapping
    out = default_emg_mapping(muscles)
    if emg_mapping.strip().lower() == "authors":
        out.update({r.name: ["ES"] for r in resolve_muscles(muscles, warn=False)
                    if r.anatomical == ("vastus_intermedius",)})
    return out


# ----------------------------------------------------------------------------- problem
@dataclass(frozen=True)
class EmgTenTrial:
    """One trial of the EMG-TEN problem: mesh inputs, EMG at the control nodes, guess."""

    label: str
    inputs: TrialInputs
    emg_muscles: tuple[str, ...]
    emg_nodes: np.ndarray  # (N, nEMG), E_m(t_k) at k = 0..N-1
    emg_channels: dict
    guess: InitialGuess | None = None
    sources: dict = field(default_factory=dict)
    static_optimisation_objective: float = math.nan


def _coupling_pairs(groups, names, consecutive: bool) -> list[tuple[int, int]]:
    pos = {n: i for i, n in enumerate(names)}
    pairs = []
    for g in groups:
        members = [m for m in g if m in pos]
        if consecutive:
            pairs += [(pos[a], pos[b]) for a, b in zip(members[:-1], members[1:])]
        else:
            pairs += [(pos[members[0]], pos[b]) for b in members[1:]]
    return pairs


def _group_index(n: int, pairs) -> list[int]:
    """Index of the shared variable of each of ``n`` parameters coupled by ``pairs`` (union-find)."""
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in pairs:
        ra, rb = root(a), root(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    roots = sorted({root(i) for i in range(n)})
    return [roots.index(root(i)) for i in range(n)]


def _layout(trials: Sequence[EmgTenTrial], M: int, D: int, nE: int, nK: int):
    nz = 5 * M + D
    ng = 4 * M + D + nE
    N = [t.inputs.n_intervals for t in trials]
    var_off, con_off = [], []
    o = r = 0
    for n in N:
        var_off.append(o)
        con_off.append(r)
        o += nz * n + 3 * M
        r += ng * n + M
    return dict(nz=nz, ng=ng, N=N, var_off=var_off, con_off=con_off, P0=o, R0=r, n_p=nK + nE)


def _node_functions(params: MuscleTendonParameters, M, D, emg_idx, kt_idx, settings: EmgTenSettings,
                    optimal_reserve_Nm: float, ca, p_index=None, zero_moment_arms=()):
    """Per-interval constraint, objective and derivative functions (SX), shared by all trials.

    Inputs: node block ``z`` (5M+D), next node ``xn = [a, l~M]`` (2M), data ``d = [lMT (M),
    r (D*M, column-major D x M), ID (D), EMG (nE), h, 1/N]`` and parameters ``p = [s_kT, s_EMG]``.
    """
    nE, nK = len(emg_idx), len(kt_idx)
    P = _constants(params, ca)
    if p_index is None:
        skt = ca.SX.sym("skt", nK)
        semg = ca.SX.sym("semg", nE)
        p = ca.vertcat(skt, semg)
    else:  # one variable per coupled group: full parameter vector = p[p_index]
        p = ca.SX.sym("p", max(p_index) + 1)
        full = [p[j] for j in p_index]
        skt, semg = ca.vertcat(*full[:nK]), ca.vertcat(*full[nK:])
    kT = ca.SX(P["kT"])
    for j, i in enumerate(kt_idx):
        kT[i] = P["kT"][i] * skt[j]
    h = ca.SX.sym("h")
    inv_n = ca.SX.sym("inv_n")
    emg = ca.SX.sym("emg", nE)
    S, gk, _ = _node_expressions(ca.SX.sym, M, D, h, dict(P, kT=kT), optimal_reserve_Nm, ca)
    if len(zero_moment_arms):
        # moment arms that are zero at every node of every trial (muscles not crossing a DOF):
        # removing them from the expressions removes their structural entries from the
        # derivatives (the values are unchanged)
        gk = ca.substitute(gk, S["r"][list(zero_moment_arms)], ca.SX.zeros(len(zero_moment_arms)))
    track = S["e"][list(emg_idx)] - semg * emg
    g = ca.vertcat(gk, track)
    z = ca.vertcat(S["a"], S["lm"], S["lp"], S["e"], S["aT"], S["vm"])
    xn = ca.vertcat(S["a1"], S["lm1"])
    d = ca.vertcat(S["lmt"], S["r"], S["id"], emg, h, inv_n)
    c_base = np.concatenate([
        np.full(M, settings.w_activation * 0.5 / M), np.zeros(2 * M),
        np.full(M, settings.w_activation * 0.5 / M), np.full(D, settings.w_reserve / D),
        np.full(M, settings.w_velocity / M),
    ])
    f = inv_n * (ca.dot(ca.DM(c_base), z**2) + (settings.w_emg / max(nE, 1)) * ca.sumsqr(track))
    nz = z.shape[0]
    lam = ca.SX.sym("lam", g.shape[0])
    sigma = ca.SX.sym("sigma")
    H = ca.hessian(sigma * f + ca.dot(lam, g), ca.vertcat(z, p))[0]
    cse = {"cse": True}
    fn = {
        "g": ca.Function("emg_ten_g", [z, xn, d, p], [g], cse),
        "f": ca.Function("emg_ten_f", [z, d, p], [f, ca.gradient(f, z), ca.gradient(f, p)], cse),
        # the constraint values come with the Jacobian (shared subexpressions)
        "jac": ca.Function("emg_ten_jac", [z, xn, d, p], [g, ca.jacobian(g, ca.vertcat(z, xn, p))], cse),
        "hess": ca.Function("emg_ten_hess", [z, d, p, lam, sigma],
                            [ca.triu(H[:nz, :nz]), H[:nz, nz:], ca.triu(H[nz:, nz:])], cse),
    }
    # last node: pennation identity and the activation cost of a_N
    xl = ca.SX.sym("xl", 3 * M)
    a_n, lm_n, lp_n = xl[0:M], xl[M:2 * M], xl[2 * M:]
    penn = (lm_n * P["lmo"]) ** 2 - P["w2"] - lp_n**2
    f_last = inv_n * (settings.w_activation * 0.5 / M) * ca.sumsqr(a_n)
    lam_l = ca.SX.sym("lam_l", M)
    fn["g_last"] = ca.Function("emg_ten_g_last", [xl], [penn])
    fn["f_last"] = ca.Function("emg_ten_f_last", [xl, inv_n], [f_last, ca.gradient(f_last, xl)])
    fn["jac_last"] = ca.Function("emg_ten_jac_last", [xl], [ca.jacobian(penn, xl)])
    fn["hess_last"] = ca.Function("emg_ten_hess_last", [xl, inv_n, lam_l, sigma],
                                  [ca.triu(ca.hessian(sigma * f_last + ca.dot(lam_l, penn), xl)[0])])
    return fn


def _triplets(sp):
    r, c = sp.get_triplet()
    return np.asarray(r, dtype=np.int64), np.asarray(c, dtype=np.int64)


def _sparse(ca, shape, rows, cols, values):
    """An MX sparse matrix from global triplets and the MX vector of their values."""
    rows = np.asarray(rows, dtype=np.int64)
    cols = np.asarray(cols, dtype=np.int64)
    perm = np.lexsort((rows, cols))
    rs, cs = rows[perm], cols[perm]
    if rs.size > 1 and np.any((np.diff(rs) == 0) & (np.diff(cs) == 0)):
        raise SolverError("internal error: duplicate entries in an assembled derivative matrix")
    sp = ca.Sparsity.triplet(int(shape[0]), int(shape[1]), rs.tolist(), cs.tolist())
    if not np.array_equal(perm, np.arange(perm.size)):
        values = values.nz[perm.tolist()]
    return ca.MX(sp, values)


def build_emg_ten_nlp(
    trials: Sequence[EmgTenTrial],
    params: MuscleTendonParameters,
    settings: EmgTenSettings | None = None,
    options: SolverOptions | None = None,
) -> dict:
    """The EMG-TEN NLP over all ``trials`` (see the module docstring), without solving it.

    Every trial must have the same muscles and DOFs as ``params`` and the same tracked
    muscles; ``trial.guess`` is the initial guess (reserve already divided by ``Topt``).
    Returns the CasADi symbols/expressions ``x``, ``f``, ``g``, the bounds ``lbx, ubx, lbg,
    ubg``, ``x0``, the functions ``grad_f``, ``jac_g``, ``hess_lag`` and the layout.
    """
    import casadi as ca

    settings = settings_for_muscles(settings, params.names)
    options = options or SolverOptions()
    if not trials:
        raise OptionError("EMG-TEN needs at least one trial")
    muscles = tuple(trials[0].inputs.muscles)
    dofs = tuple(trials[0].inputs.dofs)
    emg_muscles = tuple(trials[0].emg_muscles)
    for t in trials:
        if tuple(t.inputs.muscles) != muscles or tuple(t.inputs.dofs) != dofs:
            raise DataMismatchError(f"trial {t.label} has other muscles or DOFs than trial {trials[0].label}")
        if tuple(t.emg_muscles) != emg_muscles:
            raise DataMismatchError(f"trial {t.label} tracks other muscles than trial {trials[0].label}")
        if t.emg_nodes.shape != (t.inputs.n_intervals, len(emg_muscles)):
            raise DataMismatchError(f"trial {t.label}: EMG at the nodes has shape {t.emg_nodes.shape}, expected "
                                    f"({t.inputs.n_intervals}, {len(emg_muscles)})")
        if t.guess is None:
            raise OptionError(f"trial {t.label} has no initial guess")
    if tuple(params.names) != muscles:
        params = params.subset(muscles)
    M, D, nE = len(muscles), len(dofs), len(emg_muscles)
    pos = {m: i for i, m in enumerate(muscles)}
    missing = [m for m in settings.tendon_muscles if m not in pos] + [m for m in emg_muscles if m not in pos]
    if missing:
        raise UnknownMuscleError(
            f"muscle{'s' if len(missing) > 1 else ''} {', '.join(missing)} of the EMG-TEN settings or EMG mapping "
            f"not among the muscles of the problem ({', '.join(muscles[:6])} ...)"
        )
    kt_muscles = tuple(m for m in muscles if m in settings.tendon_muscles)
    kt_idx = [pos[m] for m in kt_muscles]
    emg_idx = [pos[m] for m in emg_muscles]
    nK = len(kt_idx)
    L = _layout(trials, M, D, nE, nK)
    nz, ng, P0, R0, n_p = L["nz"], L["ng"], L["P0"], L["R0"], L["n_p"]
    kt_pairs = _coupling_pairs(settings.tendon_groups, kt_muscles, consecutive=True)
    emg_pairs = [(nK + a, nK + b) for a, b in _coupling_pairs(settings.emg_groups, emg_muscles, consecutive=False)]
    pairs = kt_pairs + emg_pairs
    p_index = None
    if settings.coupling == "shared":
        p_index = _group_index(nK + nE, pairs)
        pairs = []
        L["n_p"] = n_p = max(p_index) + 1
    n_var = P0 + n_p
    n_con = R0 + len(pairs)

    # moment arms (column-major D x M) that are exactly zero everywhere
    crosses = np.zeros((D, M), dtype=bool)
    for t in trials:
        crosses |= np.any(t.inputs.moment_arms_m != 0.0, axis=0)
    zero_r = np.flatnonzero(~crosses.T.reshape(-1))  # index j + D*m
    fn = _node_functions(params, M, D, emg_idx, kt_idx, settings, options.optimal_reserve_Nm, ca, p_index,
                         zero_r)

    # ---- data and node indices of all trials, concatenated
    n_tot = sum(L["N"])
    data_cols = []
    node_trial, node_k = [], []
    for i, t in enumerate(trials):
        inp, N = t.inputs, t.inputs.n_intervals
        rr = inp.moment_arms_m[:N].transpose(0, 2, 1).reshape(N, D * M)  # column-major D x M per node
        data_cols.append(np.hstack([inp.lmt_m[:N], rr, inp.moments_Nm[:N], t.emg_nodes,
                                    np.full((N, 1), inp.step_s), np.full((N, 1), 1.0 / N)]))
        node_trial.append(np.full(N, i))
        node_k.append(np.arange(N))
    data = ca.DM(np.vstack(data_cols).T)
    node_trial = np.concatenate(node_trial)
    node_k = np.concatenate(node_k)
    var_off = np.asarray(L["var_off"])
    con_off = np.asarray(L["con_off"])
    Narr = np.asarray(L["N"])
    zc = var_off[node_trial] + node_k * nz           # first column of z_k
    xc = var_off[node_trial] + (node_k + 1) * nz     # first column of the next node (a, l~M first)
    rb_node = con_off[node_trial] + node_k * ng      # first row of interval k
    last_var = var_off + Narr * nz                   # [a, l~M, lp] of node N
    last_con = con_off + Narr * ng
    inv_n = ca.DM((1.0 / Narr).reshape(1, -1))

    # ---- symbolic variables
    w = ca.MX.sym("w", n_var)
    p = w[P0:]
    Zs, Xns, XLs = [], [], []
    for i, N in enumerate(L["N"]):
        o = L["var_off"][i]
        Z = ca.reshape(w[o:o + nz * N], nz, N)
        xl = w[o + nz * N:o + nz * N + 3 * M]
        Zs.append(Z)
        Xns.append(ca.horzcat(Z[0:2 * M, 1:], xl[0:2 * M]))
        XLs.append(xl)
    Z = ca.horzcat(*Zs)
    Xn = ca.horzcat(*Xns)
    XL = ca.horzcat(*XLs)
    T = len(trials)

    def per_trial(mat):
        """Split the columns of a (rows x n_tot) matrix by trial, vectorised."""
        out, c = [], 0
        for N in L["N"]:
            out.append(ca.vec(mat[:, c:c + N]))
            c += N
        return out

    # constraints
    GL = fn["g_last"].map(T)(XL)

    def assemble_g(G):
        parts = []
        for i, gi in enumerate(per_trial(G)):
            parts += [gi, GL[:, i]]
        parts += [ca.vertcat(*[p[a] - p[b] for a, b in pairs])] if pairs else []
        return ca.vertcat(*parts)

    g = assemble_g(fn["g"].map(n_tot)(Z, Xn, data, p))

    # objective and gradient
    F, Gz, Gp = fn["f"].map(n_tot)(Z, data, p)
    FL, GLx = fn["f_last"].map(T)(XL, inv_n)
    f = ca.sum2(F) + ca.sum2(FL)
    grad_parts = []
    for i, gzi in enumerate(per_trial(Gz)):
        grad_parts += [gzi, GLx[:, i]]
    grad = ca.vertcat(*grad_parts, ca.sum2(Gp))

    # Jacobian
    rb, cb = _triplets(fn["jac"].sparsity_out(1))
    cmap = np.where(cb < nz, zc[:, None] + cb,
                    np.where(cb < nz + 2 * M, xc[:, None] + (cb - nz), P0 + (cb - nz - 2 * M)))
    rows = [(rb_node[:, None] + rb).ravel()]
    cols = [cmap.ravel()]
    G_j, J_nodes = fn["jac"].map(n_tot)(Z, Xn, data, p)
    vals = [J_nodes.nz[:]]
    rl, cl = _triplets(fn["jac_last"].sparsity_out(0))
    rows.append((last_con[:, None] + rl).ravel())
    cols.append((last_var[:, None] + cl).ravel())
    vals.append(fn["jac_last"].map(T)(XL).nz[:])
    if pairs:
        rows.append(np.repeat(R0 + np.arange(len(pairs)), 2))
        cols.append(np.array([P0 + j for ab in pairs for j in ab]))
        vals.append(ca.DM([v for _ in pairs for v in (1.0, -1.0)]))
    jac = _sparse(ca, (n_con, n_var), np.concatenate(rows), np.concatenate(cols), ca.vertcat(*vals))

    # Hessian of the Lagrangian (upper triangle)
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", n_con)
    Ls, LLs = [], []
    for i, N in enumerate(L["N"]):
        r0 = L["con_off"][i]
        Ls.append(ca.reshape(lam_g[r0:r0 + ng * N], ng, N))
        LLs.append(lam_g[r0 + ng * N:r0 + ng * N + M])
    Hzz, Hzp, Hpp = fn["hess"].map(n_tot)(Z, data, p, ca.horzcat(*Ls), lam_f)
    HL = fn["hess_last"].map(T)(XL, inv_n, ca.horzcat(*LLs), lam_f)
    r1, c1 = _triplets(fn["hess"].sparsity_out(0))
    r2, c2 = _triplets(fn["hess"].sparsity_out(1))
    r3, c3 = _triplets(fn["hess"].sparsity_out(2))
    r4, c4 = _triplets(fn["hess_last"].sparsity_out(0))
    rows = [(zc[:, None] + r1).ravel(), (zc[:, None] + r2).ravel(), P0 + r3,
            (last_var[:, None] + r4).ravel()]
    cols = [(zc[:, None] + c1).ravel(), np.tile(P0 + c2, n_tot), P0 + c3, (last_var[:, None] + c4).ravel()]
    hpp = ca.sum2(ca.reshape(Hpp.nz[:], r3.size, n_tot)) if r3.size else ca.MX(0, 1)
    vals = ca.vertcat(Hzz.nz[:], Hzp.nz[:], hpp, HL.nz[:])
    hess = _sparse(ca, (n_var, n_var), np.concatenate(rows), np.concatenate(cols), vals)

    # ---- bounds, initial guess
    lb_node, ub_node = node_bounds(M, D)
    lbx, ubx, x0, lbg, ubg = [], [], [], [], []
    tol = settings.emg_tolerance
    lbg_node = np.concatenate([np.zeros(ng - nE), np.full(nE, -tol)])
    ubg_node = np.concatenate([np.zeros(ng - nE), np.full(nE, tol)])
    for t in trials:
        N, gs = t.inputs.n_intervals, t.guess
        lbx += [np.tile(lb_node, N), lb_node[:3 * M]]
        ubx += [np.tile(ub_node, N), ub_node[:3 * M]]
        Z0 = np.hstack([gs.activation[:N], gs.lm_norm[:N], gs.lm_projected_m[:N],
                        gs.excitation[:N], gs.reserve[:N], gs.vm_norm[:N]])
        x0 += [Z0.reshape(-1), gs.activation[N], gs.lm_norm[N], gs.lm_projected_m[N]]
        lbg += [np.tile(lbg_node, N), np.zeros(M)]
        ubg += [np.tile(ubg_node, N), np.zeros(M)]
    lo_k, hi_k = settings.tendon_scale_bounds
    lo_e, hi_e = settings.emg_scale_bounds
    lb_p = np.concatenate([np.full(nK, lo_k), np.full(nE, lo_e)])
    ub_p = np.concatenate([np.full(nK, hi_k), np.full(nE, hi_e)])
    if p_index is not None:
        first = [p_index.index(j) for j in range(n_p)]
        lb_p, ub_p = lb_p[first], ub_p[first]
    lbx.append(lb_p)
    ubx.append(ub_p)
    x0.append(np.ones(n_p))
    lbg.append(np.zeros(len(pairs)))
    ubg.append(np.zeros(len(pairs)))
    x0 = np.concatenate(x0)
    if x0.size != n_var or g.shape[0] != n_con:
        raise SolverError(f"internal error: problem size {x0.size}/{g.shape[0]}, expected {n_var}/{n_con}")
    if not np.all(np.isfinite(x0)):
        raise SolverError("the initial guess holds NaN or infinite values; check the muscle geometry and parameters")

    pp = ca.MX.sym("p", 0, 1)
    n_ineq = nE * n_tot
    return {
        "x": w, "f": f, "g": g,
        "x0": x0, "lbx": np.concatenate(lbx), "ubx": np.concatenate(ubx),
        "lbg": np.concatenate(lbg), "ubg": np.concatenate(ubg),
        "n_variables": n_var, "n_constraints": n_con,
        "n_equality_constraints": n_con - n_ineq, "n_inequality_constraints": n_ineq,
        "layout": dict(L, M=M, D=D, nE=nE, nK=nK, muscles=muscles, dofs=dofs, emg_muscles=emg_muscles,
                       kt_muscles=kt_muscles, kt_idx=kt_idx, emg_idx=emg_idx, pairs=pairs,
                       p_index=p_index),
        "params": params,
        "grad_f": ca.Function("nlp_grad_f", [w, pp], [f, grad], ["x", "p"], ["f", "grad_f_x"]),
        "jac_g": ca.Function("nlp_jac_g", [w, pp], [assemble_g(G_j), jac], ["x", "p"], ["g", "jac_g_x"]),
        "hess_lag": ca.Function("nlp_hess_l", [w, pp, lam_f, lam_g], [hess],
                                ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"]),
    }


@dataclass(frozen=True)
class EmgTenOcpResult:
    """Raw optimum of the EMG-TEN NLP: one :class:`OcpResult` per trial and the parameters."""

    trials: tuple[OcpResult, ...]
    tendon_muscles: tuple[str, ...]
    tendon_scale: np.ndarray
    emg_muscles: tuple[str, ...]
    emg_scale: np.ndarray
    objective: float
    objective_terms: dict  # per trial label: {term: value}
    status: str
    success: bool
    iterations: int
    solve_time_s: float
    solve_cpu_s: float
    build_time_s: float
    n_variables: int
    n_equality_constraints: int
    n_inequality_constraints: int
    max_constraint_violation: float
    max_coupling_violation: float
    emg_deviation: tuple[np.ndarray, ...]  # per trial (N, nEMG): e - s E
    function_time_s: dict = field(default_factory=dict)
    ipopt_options: dict = field(default_factory=dict)


def _trial_terms(settings: EmgTenSettings, ocp: OcpResult, dev: np.ndarray, M: int, D: int) -> dict:
    N = ocp.excitation.shape[0]
    nE = max(dev.shape[1], 1)
    return {
        "emg_tracking": settings.w_emg * float(np.sum(dev**2)) / (nE * N),
        "activation": settings.w_activation * 0.5 * float(np.sum(ocp.activation**2)) / (N * M),
        "excitation": settings.w_activation * 0.5 * float(np.sum(ocp.excitation**2)) / (N * M),
        "reserve": settings.w_reserve * float(np.sum(ocp.reserve**2)) / (N * D),
        "fibre_velocity": settings.w_velocity * float(np.sum(ocp.vm_norm**2)) / (N * M),
    }


def solve_emg_ten_ocp(
    trials: Sequence[EmgTenTrial],
    params: MuscleTendonParameters,
    settings: EmgTenSettings | None = None,
    options: SolverOptions | None = None,
) -> EmgTenOcpResult:
    """Build and solve the EMG-TEN NLP; never raises on non-convergence (see ``success``)."""
    import casadi as ca

    settings = settings_for_muscles(settings, params.names)
    options = options or SolverOptions()
    t_build = _time.perf_counter()
    nlp = build_emg_ten_nlp(trials, params, settings, options)
    L = nlp["layout"]
    M, D, nz, nK = L["M"], L["D"], L["nz"], L["nK"]
    ipopt = ipopt_options(options, LINEAR_SOLVER_OPTIONS)
    nlp_options = {"ipopt": ipopt, "print_time": False, "error_on_fail": False,
                   "grad_f": nlp["grad_f"], "jac_g": nlp["jac_g"], "hess_lag": nlp["hess_lag"]}
    try:
        solver = ca.nlpsol("emg_ten", "ipopt", {"x": nlp["x"], "f": nlp["f"], "g": nlp["g"]}, nlp_options)
    except RuntimeError as exc:
        raise SolverError(f"the EMG-TEN problem could not be built: {exc}") from None
    build_time = _time.perf_counter() - t_build
    x, gval, f_opt, stats, solve_time, solve_cpu = run_ipopt(
        solver, options, nlp["x0"], nlp["lbx"], nlp["ubx"], nlp["lbg"], nlp["ubg"])
    lbg, ubg = nlp["lbg"], nlp["ubg"]
    viol = np.maximum(lbg - gval, 0.0) + np.maximum(gval - ubg, 0.0)
    p = x[L["P0"]:]
    if L["p_index"] is not None:
        p = p[L["p_index"]]
    s_kt, s_emg = p[:nK], p[nK:]
    pairs = L["pairs"]
    ocps, devs, terms = [], [], {}
    for i, t in enumerate(trials):
        N, o = L["N"][i], L["var_off"][i]
        Zv = x[o:o + nz * N].reshape(N, nz)
        xl = x[o + nz * N:o + nz * N + 3 * M]
        ocp = OcpResult(
            activation=np.vstack([Zv[:, 0:M], xl[0:M]]),
            lm_norm=np.vstack([Zv[:, M:2 * M], xl[M:2 * M]]),
            lm_projected_m=np.vstack([Zv[:, 2 * M:3 * M], xl[2 * M:]]),
            excitation=Zv[:, 3 * M:4 * M].copy(),
            reserve=Zv[:, 4 * M:4 * M + D].copy(),
            vm_norm=Zv[:, 4 * M + D:].copy(),
            objective=math.nan,
            objective_terms={},
            status=str(stats.get("return_status", "unknown")),
            success=bool(stats.get("success", False)),
            iterations=int(stats.get("iter_count", -1)),
            solve_time_s=solve_time,
            solve_cpu_s=solve_cpu,
            build_time_s=build_time,
            n_variables=nlp["n_variables"],
            n_constraints=nlp["n_equality_constraints"],
            max_constraint_violation=float(np.max(viol)) if viol.size else 0.0,
        )
        dev = ocp.excitation[:, L["emg_idx"]] - s_emg[None, :] * t.emg_nodes
        tt = _trial_terms(settings, ocp, dev, M, D)
        ocp = replace(ocp, objective=float(sum(tt.values())), objective_terms=tt)
        ocps.append(ocp)
        devs.append(dev)
        terms[t.label] = tt
    return EmgTenOcpResult(
        trials=tuple(ocps),
        tendon_muscles=tuple(L["kt_muscles"]),
        tendon_scale=s_kt.copy(),
        emg_muscles=tuple(L["emg_muscles"]),
        emg_scale=s_emg.copy(),
        objective=f_opt,
        objective_terms=terms,
        status=str(stats.get("return_status", "unknown")),
        success=bool(stats.get("success", False)),
        iterations=int(stats.get("iter_count", -1)),
        solve_time_s=solve_time,
        solve_cpu_s=solve_cpu,
        build_time_s=build_time,
        n_variables=nlp["n_variables"],
        n_equality_constraints=nlp["n_equality_constraints"],
        n_inequality_constraints=nlp["n_inequality_constraints"],
        max_constraint_violation=float(np.max(viol)) if viol.size else 0.0,
        max_coupling_violation=float(max((abs(p[a] - p[b]) for a, b in pairs), default=0.0)),
        emg_deviation=tuple(devs),
        function_time_s={k[len("t_wall_"):]: float(v) for k, v in stats.items()
                         if k.startswith("t_wall_nlp") and v},
        ipopt_options=dict(ipopt),
    )


# ----------------------------------------------------------------------------- results
def tendon_stiffness_at_force_N_per_mm(force_norm, max_isometric_force_N, tendon_slack_length_m, kT):
    """Tangent slope ``dFT/dlT`` (N/mm) of the tendon curve where ``FT = force_norm F0``.

    With ``force_norm = 1``: ``F0 kT (1.25 - shift(kT)) / lTs`` (the module's definition of
    the stiffness in N/mm).
    """
    lt = tendon_length_from_force(np.asarray(force_norm, dtype=float), kT)
    return tendon_stiffness_N_per_m(lt, max_isometric_force_N, tendon_slack_length_m, kT) / 1000.0


@dataclass
class EmgTenResult:
    """Solutions of all trials and the estimated parameters of one EMG-TEN solve.

    ``solutions`` maps the trial labels (IK file stems by default) to :class:`Solution`
    objects in the solver's format (``summary['workflow']['name'] == 'emg-ten'``), computed
    with the estimated tendon stiffness. ``tendon_stiffness``/``tendon_scale`` and
    ``emg_scale`` hold the estimates by muscle; ``record`` the solve record.
    """

    solutions: dict
    parameters: MuscleTendonParameters
    tendon_scale: dict
    tendon_stiffness: dict
    emg_scale: dict
    emg_channels: dict
    record: dict
    settings: EmgTenSettings
    trials: tuple = field(default=(), repr=False)

    @property
    def success(self) -> bool:
        return bool(self.record.get("success", False))

    @property
    def status(self) -> str:
        return str(self.record.get("status", "unknown"))

    @property
    def objective(self) -> float:
        return float(self.record.get("objective", math.nan))

    @property
    def iterations(self) -> int:
        return int(self.record.get("iterations", -1))

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
        return _jsonable({
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
            "solve": dict(self.record),
        })

    def write(self, out_dir: str | os.PathLike) -> Path:
        """Write one solution folder per trial and ``parameters.json`` into ``out_dir``.

        Each folder is written atomically; ``parameters.json`` is removed first and written last
        (atomically), so its presence means that all trial folders belong to it.
        """
        from ..io import atomic_write_text

        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / PARAMETERS_FILE).unlink(missing_ok=True)
        for label, sol in self.solutions.items():
            sol.write(out_dir / label)
        text = json.dumps(self.parameters_document(), indent=2, allow_nan=True)
        atomic_write_text(out_dir / PARAMETERS_FILE, text + "\n")
        return out_dir


# ----------------------------------------------------------------------------- pipeline
def _as_list(x, what: str) -> list:
    if x is None:
        return []
    if isinstance(x, (str, os.PathLike)):
        return [x]
    try:
        return list(x)
    except TypeError:
        raise OptionError(f"{what} must be a path or a list of paths, not {x!r}") from None


def _labels(ik_paths, labels) -> list[str]:
    if labels is None:
        labels = [Path(p).stem for p in ik_paths]
    labels = [str(x) for x in _as_list(labels, "labels")]
    if len(labels) != len(ik_paths):
        raise OptionError(f"{len(labels)} trial labels for {len(ik_paths)} trials; give one label per trial")
    bad = [x for x in labels if not x or x in (".", "..") or "/" in x or "\\" in x]
    if bad:
        raise OptionError(f"trial label {bad[0]!r} cannot name a folder; use plain names")
    dup = sorted({x for x in labels if labels.count(x) > 1})
    if dup:
        raise OptionError(f"trial label{'s' if len(dup) > 1 else ''} {', '.join(dup)} used twice (IK files with "
                          "the same name?); give distinct labels")
    if PARAMETERS_FILE in labels:
        raise OptionError(f"'{PARAMETERS_FILE}' cannot be a trial label")
    return labels


def _check_emg_range(df, t0: float, tf: float, tol: float, what: str) -> None:
    """Reject mapped EMG outside ``[0, 1]`` (by more than ``tol``) inside ``[t0, tf]``."""
    t = np.asarray(df.index, dtype=float)
    sel = (t >= t0 - 1e-9) & (t <= tf + 1e-9)
    channels = df.attrs.get("channels", {})
    for m in df.columns:
        x = df[m].to_numpy(dtype=float)[sel]
        if x.size == 0:
            continue
        bad = np.flatnonzero((x < -tol) | (x > 1.0 + tol))
        if bad.size:
            k = bad[np.argmax(np.abs(x[bad] - 0.5))]
            chans = channels.get(m, [m])
            raise DataMismatchError(
                f"{what}: EMG of {m} (channel{'s' if len(chans) > 1 else ''} {', '.join(chans)}) is "
                f"{x[k]:.4g} at t = {t[sel][k]:.4g} s, outside [0, 1]; EMG-TEN tracks normalised envelopes: "
                "normalise the channel (e.g. to its MVC peak), clip small filtering undershoots to 0, or map "
                "another channel"
            )


def _emg_table(emg, mapping, path_label: str):
    """Read (if a path) and map an EMG table to ``{muscle: signal}``; errors name the file."""
    from ..emg import map_channels, read_processed_emg

    if isinstance(emg, (str, os.PathLike)):
        p = Path(emg)
        if not p.is_file():
            raise InputFileError(f"{p}: no such EMG file; check the --emg paths")
        df = read_processed_emg(p)
    else:
        df = emg.copy()
        df.attrs.update(emg.attrs)
        df.attrs.setdefault("path", path_label)
    if "channels" in df.attrs and set(df.columns) == set(mapping):
        return df  # already mapped
    return map_channels(df, mapping)


def _check_models(model_path, n_trials: int) -> Path:
    """One model for all trials; a list with one path per trial must name the same model."""
    from ..io.atomic import file_sha256

    if isinstance(model_path, (str, os.PathLike)):
        return Path(model_path)
    paths = [Path(p) for p in _as_list(model_path, "model_path")]
    if len(paths) not in (1, n_trials):
        raise OptionError(f"{len(paths)} models for {n_trials} trials; give one model (or one per trial)")
    for p in paths:
        if not p.is_file():
            from ..errors import ModelError

            raise ModelError(f"{p}: no such model file; check the path")
    digests = [file_sha256(p) for p in paths]
    for p, d in zip(paths[1:], digests[1:]):
        if d != digests[0]:
            raise DataMismatchError(
                f"the trials come from different models ({paths[0]} and {p} differ); EMG-TEN estimates one set of "
                "parameters per subject model: solve trials of different models separately"
            )
    return paths[0]


def solve_emg_ten(
    model_path,
    ik_paths: Sequence[str | os.PathLike],
    id_paths: Sequence[str | os.PathLike],
    emg_paths: Sequence[str | os.PathLike],
    *,
    emg_mapping="default",
    labels: Sequence[str] | None = None,
    passive=None,
    dofs: Sequence[str] = DEFAULT_DOFS,
    settings: EmgTenSettings | None = None,
    options: SolverOptions | None = None,
    cache_dir: str | os.PathLike | None = None,
    check_units: bool = True,
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

    Input errors (package exceptions naming the file, channel or muscle) are raised before
    OpenSim is started: unequal numbers of IK/ID/EMG files, different models, EMG channels
    missing for the mapping, EMG not covering a trial's IK window, EMG outside ``[0, 1]`` in
    the window, besides the IK/ID checks of the single-trial solver (columns, units, time
    ranges). Muscles of a custom mapping that the model lacks are reported after the geometry.
    """
    from .solve import _Background, _read_model_parameters
    from .workflows import read_passive_parameters

    ik_paths = _as_list(ik_paths, "ik_paths")
    id_paths = _as_list(id_paths, "id_paths")
    emg_paths = _as_list(emg_paths, "emg_paths")
    if not ik_paths:
        raise OptionError("EMG-TEN needs at least one trial (IK, ID and EMG file)")
    if not (len(ik_paths) == len(id_paths) == len(emg_paths)):
        raise OptionError(
            f"{len(ik_paths)} IK, {len(id_paths)} ID and {len(emg_paths)} EMG files; give one of each per trial, "
            "in the same order"
        )
    model = _check_models(model_path, len(ik_paths))
    labels = _labels(ik_paths, labels)
    mapping = resolve_emg_mapping(emg_mapping)
    settings = settings or EmgTenSettings()
    if passive is not None and not hasattr(passive, "for_muscles"):
        passive = read_passive_parameters(passive)

    # every file is checked before OpenSim is asked anything
    id_data, emg_tables, ik_times = [], [], []
    for ik, idp, emg, lab in zip(ik_paths, id_paths, emg_paths, labels):
        ik_time, _ = read_kinematics(ik, dofs, check_units=check_units)
        id_time, id_moments = read_inverse_dynamics(idp, dofs)
        check_time_ranges(ik_time, id_time, ik, idp)
        table = _emg_table(emg, mapping, f"EMG of trial {lab}")
        what = str(table.attrs.get("path", f"EMG of trial {lab}"))
        _require_emg_window(table, ik_time, what, str(ik))
        _check_emg_range(table, float(ik_time[0]), float(ik_time[-1]), settings.emg_range_tolerance, what)
        id_data.append((id_time, id_moments))
        emg_tables.append(table)
        ik_times.append(ik_time)
    params_request = _Background(_read_model_parameters, model)
    from ..geometry import compute_geometry

    t0 = _time.perf_counter()
    geometries = [compute_geometry(model, ik, dofs=list(dofs), side="r", cache_dir=cache_dir) for ik in ik_paths]
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
    )
    result.record["geometry_time_s"] = t_geometry
    return result


def _require_emg_window(table, ik_time, emg_label: str, ik_label: str) -> None:
    t = np.asarray(table.index, dtype=float)
    t0, tf = float(ik_time[0]), float(ik_time[-1])
    if t.size == 0 or t[0] > t0 + 1e-6 or t[-1] < tf - 1e-6:
        have = f"{t[0]:g}-{t[-1]:g} s" if t.size else "no samples"
        raise DataMismatchError(
            f"{emg_label}: the EMG covers {have} but the trial window (the IK file {ik_label}) is "
            f"{t0:g}-{tf:g} s; the EMG must cover the whole window: use the EMG of the same trial, or crop the IK"
        )


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
) -> EmgTenResult:
    """EMG-TEN from arrays: per trial a geometry-like object, ``(ID time, ID moments)`` with
    columns in the order of ``geometry.dofs``, and an EMG table (time-indexed ``DataFrame``,
    channels as columns, or already mapped to muscles by ``musclemetab.emg.map_channels``)."""
    from .solve import _restrict_geometry

    t_start = _time.perf_counter()
    settings = settings_for_muscles(settings, _restrict_geometry(list(geometries)[0]).muscles) if geometries \
        else (settings or EmgTenSettings())
    options = emg_ten_options(options, settings)
    trials, params, wf_record = prepare_emg_ten_trials(
        geometries, model_parameters, id_data, emg_tables, labels=labels, ik_times=ik_times, passive=passive,
        emg_mapping=emg_mapping, settings=settings, options=options, sources=sources, check_units=check_units)
    t_prep = _time.perf_counter() - t_start
    ocp = solve_emg_ten_ocp(trials, params, settings, options)
    return _assemble_result(trials, params, wf_record, ocp, settings, options, t_prep, t_start)


def emg_ten_options(options: SolverOptions | None, settings: EmgTenSettings) -> SolverOptions:
    """``options`` with the weights of ``settings`` (EMG-TEN: ``wAct 0.1, wTres 1000, wVm 0.01``)."""
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
) -> tuple[list[EmgTenTrial], MuscleTendonParameters, dict]:
    """The trials of an EMG-TEN problem (mesh inputs, EMG at the nodes, initial guess), the
    muscle parameters (calibrated passive muscle, nominal ``kT``) and their record; the
    arguments are those of :func:`solve_emg_ten_arrays`. Nothing is solved."""
    from .solve import _restrict_geometry
    from .workflows import workflow_parameters

    settings = settings or EmgTenSettings()
    options = emg_ten_options(options, settings)
    geometries, id_data, emg_tables = list(geometries), list(id_data), list(emg_tables)
    n = len(geometries)
    if not (n == len(id_data) == len(emg_tables)) or n == 0:
        raise OptionError(f"{n} geometries, {len(id_data)} ID and {len(emg_tables)} EMG tables; give one of each "
                          "per trial (at least one trial)")
    labels = [f"trial_{i + 1}" for i in range(n)] if labels is None else _labels(list(range(n)), labels)
    sources = [dict(s) for s in (sources or [{} for _ in range(n)])]
    mapping = resolve_emg_mapping(emg_mapping)
    ik_times = list(ik_times) if ik_times is not None else [None] * n

    # same model (hence the same muscles and DOFs) for all trials
    all_dofs = [tuple(g.dofs) for g in geometries]
    restricted = [_restrict_geometry(g) for g in geometries]
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
    unknown = [m for m in mapping if m not in muscles]
    if unknown:
        raise UnknownMuscleError(
            f"EMG mapping: muscle{'s' if len(unknown) > 1 else ''} {', '.join(unknown)} not among the muscles of "
            f"the problem ({', '.join(muscles[:6])} ...); map channels to model muscle names such as soleus_r"
        )
    missing_kt = [m for m in settings.tendon_muscles if m not in muscles]
    if missing_kt:
        raise UnknownMuscleError(
            f"the tendon stiffness of {', '.join(missing_kt)} is to be estimated but the problem has no such muscle "
            f"({', '.join(muscles[:6])} ...); change EmgTenSettings.tendon_groups"
        )
    params, wf_record = workflow_parameters("effort-cal", model_parameters, muscles, passive=passive)
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
        what = str(src.get("emg", f"EMG of trial {lab}"))
        table = _emg_table(emg, mapping, what)
        t0, tf = inputs.window_s
        _require_emg_window(table, inputs.frame_time_s, what, str(src.get("ik", f"trial {lab}")))
        _check_emg_range(table, t0, tf, settings.emg_range_tolerance, what)
        N = inputs.n_intervals
        te = np.asarray(table.index, dtype=float)
        emg_nodes = np.column_stack([np.interp(inputs.mesh_time_s[:N], te, table[m].to_numpy(dtype=float))
                                     for m in emg_muscles])
        so = static_optimisation(inputs, params)
        guess = initial_guess(inputs, params, so)
        guess = replace(guess, reserve=guess.reserve / options.optimal_reserve_Nm)
        trials.append(EmgTenTrial(label=lab, inputs=inputs, emg_muscles=emg_muscles, emg_nodes=emg_nodes,
                                  emg_channels={m: list(mapping[m]) for m in emg_muscles}, guess=guess,
                                  sources=src, static_optimisation_objective=so.objective))
    return trials, params, wf_record


def _assemble_result(trials, params, wf_record, ocp: EmgTenOcpResult, settings, options, t_prep, t_start):
    from .. import __version__

    kt_est = {m: float(params.tendon_stiffness[params.names.index(m)] * s)
              for m, s in zip(ocp.tendon_muscles, ocp.tendon_scale)}
    est_params = params.replace(tendon_stiffness=kt_est)
    emg_scale = {m: float(s) for m, s in zip(ocp.emg_muscles, ocp.emg_scale)}
    tendon_scale = {m: float(s) for m, s in zip(ocp.tendon_muscles, ocp.tendon_scale)}
    emg_channels = dict(trials[0].emg_channels)
    software = {"musclemetab": __version__, "python": platform.python_version()}
    try:
        import casadi

        software["casadi"] = casadi.__version__
    except Exception:  # pragma: no cover
        pass
    n_tot = sum(t.inputs.n_intervals for t in trials)
    record = {
        "workflow": EMG_TEN,
        **ipopt_statistics(ocp),
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
        "solver_options": options.to_dict(),
        "ipopt_options": ocp.ipopt_options,
        "initial_guess": "static optimisation (rigid tendons) per trial, reserve divided by Topt; scale factors 1",
        "software": software,
    }
    workflow = {
        "name": EMG_TEN,
        "description": "EMG-informed multi-trial estimation of triceps-surae and vasti tendon stiffness",
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
        inp = t.inputs
        summary = {
            "status": ocp.status,
            "success": ocp.success,
            "objective": ocp.objective,
            "objective_trial": o.objective,
            "objective_terms": o.objective_terms,
            "iterations": ocp.iterations,
            "solve_time_s": ocp.solve_time_s,
            "solve_cpu_time_s": ocp.solve_cpu_s,
            "build_time_s": ocp.build_time_s,
            "function_evaluation_time_s": ocp.function_time_s,
            "preparation_time_s": t_prep,
            "max_constraint_violation": ocp.max_constraint_violation,
            "problem_size": dict(record["problem_size"]),
            "time_window_s": list(inp.window_s),
            "n_intervals": inp.n_intervals,
            "mesh_step_s": inp.step_s,
            "optimal_reserve_Nm": options.optimal_reserve_Nm,
            "static_optimisation_objective": t.static_optimisation_objective,
            "initial_guess": record["initial_guess"],
            "workflow": dict(workflow, trial=t.label),
            "emg_tracking": {
                m: {"channels": t.emg_channels[m], "scale": emg_scale[m],
                    "max_abs_deviation": float(np.max(np.abs(dev[:, j]))) if dev.size else 0.0,
                    "rms_deviation": float(np.sqrt(np.mean(dev[:, j] ** 2))) if dev.size else 0.0}
                for j, m in enumerate(t.emg_muscles)
            },
            "emg_tolerance": settings.emg_tolerance,
            "solver_options": options.to_dict(),
            "input_preparation": {"filter": "butterworth 6th order 6 Hz zero-phase (MATLAB filtfilt padding)",
                                  "mesh_intervals_per_second": 100, "interpolation": "not-a-knot cubic spline",
                                  "emg": "linear interpolation at nodes 0..N-1"},
            "inputs": {k: str(v) for k, v in t.sources.items()},
            "software": software,
        }
        sol = build_solution(inp, est_params.subset(inp.muscles), o, summary)
        sol.summary["total_time_s"] = _time.perf_counter() - t_start
        solutions[t.label] = sol
    record["max_moment_residual_Nm"] = max(s.summary["max_moment_residual_Nm"] for s in solutions.values())
    record["max_hill_residual"] = max(s.summary["max_hill_residual"] for s in solutions.values())
    record["total_time_s"] = _time.perf_counter() - t_start
    return EmgTenResult(
        solutions=solutions, parameters=est_params, tendon_scale=tendon_scale, tendon_stiffness=kt_est,
        emg_scale=emg_scale, emg_channels=emg_channels, record=record, settings=settings, trials=tuple(trials),
    )
