"""KKT systems of the example trials: block elimination against general sparse solvers.

For each trial (EFFORT-GEN) the NLP is built as the solver builds it and IPOPT is run for
``k`` iterations (``--iterations``, default 1, 10 and the iteration count of the full solve
is reached by ``0`` = to convergence). At each such iterate ``(x, lambda_g, z)`` the matrix
IPOPT factorises is assembled::

    K = [ H + Sigma    J^T ]        H: Hessian of the Lagrangian, J: constraint Jacobian,
        [ J            0   ]        Sigma = zL/(x - l) + zU/(u - x) (primal-dual barrier term)

with the bound multipliers ``z`` of that iterate (``lam_x``, split by sign) and IPOPT's
barrier parameter ``mu`` as a floor (``z >= mu/d``), unscaled (IPOPT also applies its
gradient-based scaling, the same for every method). One right-hand side (the KKT residual
of the iterate) is solved with:

* ``mumps``: CasADi's MUMPS linear solver (``Linsol``; symbolic analysis done once, not timed),
  the factoriser IPOPT uses;
* ``superlu``: SciPy's ``splu`` (ordering and factorisation timed together, as it does both);
* ``block``: the structure-exploiting elimination. Each muscle's variables and the
  constraints that involve only that muscle (activation dynamics, fiber kinematics,
  pennation identity, Hill equilibrium) form one block ordered node by node: a banded
  matrix (a time chain). The reserves and the moment equations (the only rows that couple
  muscles) form the coupling set ``C``. Each muscle block is factorised with banded LU
  (LAPACK ``dgbtrf``), its contribution ``B_m A_m^-1 B_m^T`` to the Schur complement of
  ``C`` is formed from ``A_m^-1`` applied to the unit vectors of the few local variables
  the coupling rows touch (the projected fiber lengths, one per node), and the dense
  Schur complement of the ``D N`` moment rows (the reserves, a diagonal block, are
  eliminated first) is factorised with LU (``getrf``); the time of forming it and of the
  symmetric-indefinite factorisation that would also give its inertia are printed apart.

The reference is MUMPS inside IPOPT over the full solve: the factorisations counted in IPOPT's
detailed log (:func:`count_factorisations`) and IPOPT's time outside the NLP functions
per factorisation, an upper bound of one factorisation (IPOPT's own timers book neither of its
factorisations: IPOPT 3.14 has MUMPS factorise and solve in one call).

Times are the median of ``--repeat`` runs; the residual is
``||K x - b||_inf / (||K||_inf ||x||_inf + ||b||_inf)``.

    python benchmarks/kkt.py [--trials normal] [--iterations 1 10 0] [--repeat 5] [--no-superlu]
    python benchmarks/kkt.py --quick

``--quick``: the window 0.6-0.8 s of the normal trial (geometry from the package's cache), the first
iterate alone, one repeat, no SuperLU: a check that the script runs (the test suite runs it so).
"""

from __future__ import annotations

import argparse
import re
import os
import statistics
import sys
import time
from pathlib import Path

# one BLAS thread for every method (MUMPS runs with one in the solver): on a shared machine
# threaded BLAS on these small dense blocks only spins
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import scipy.linalg as sla  # noqa: E402
import scipy.sparse as sp  # noqa: E402
import scipy.sparse.linalg as spla  # noqa: E402
from scipy.linalg import lapack  # noqa: E402

HERE = Path(__file__).resolve().parent


def _example():
    sys.path.insert(0, str(HERE))
    from solver import _example as example  # the benchmarks' one way to locate the example data

    return example()


def build_problem(ex, trial, window=None):
    """NLP of the trial's EFFORT-GEN problem exactly as the solver builds it (``window``: the IK
    frames of that time range, as ``solve_files(window=...)`` keeps them)."""
    import dataclasses

    from musclemetab.geometry import compute_geometry
    from musclemetab.model import read_muscle_parameters
    from musclemetab.redundancy.inputs import DEFAULT_DOFS, read_inverse_dynamics, restrict_geometry, trial_inputs
    from musclemetab.redundancy.ipopt import SolverOptions, build_nlp
    from musclemetab.redundancy.static_opt import initial_guess, static_optimisation
    from musclemetab.redundancy.workflows import workflow_parameters

    geom = restrict_geometry(compute_geometry(ex.model, ex.ik[trial], dofs=list(DEFAULT_DOFS)))
    if window is not None:
        t = np.asarray(geom.time)
        keep = np.flatnonzero((t >= window[0] - 1e-6) & (t <= window[1] + 1e-6))
        geom = dataclasses.replace(geom, time=t[keep], lmt_m=np.asarray(geom.lmt_m)[keep],
                                   moment_arms_m=np.asarray(geom.moment_arms_m)[keep])
    id_time, id_mom = read_inverse_dynamics(ex.id[trial], geom.dofs)
    params, _ = workflow_parameters("effort-gen", read_muscle_parameters(ex.model), geom.muscles)
    params = params.subset(geom.muscles)
    inputs = trial_inputs(geom, id_time, id_mom)
    guess = initial_guess(inputs, params, static_optimisation(inputs, params))
    options = SolverOptions()
    return build_nlp(inputs, params, guess, options), options


def iterate(nlp, options, k):
    """IPOPT's iterate after ``k`` iterations (0: converged) and its barrier parameter."""
    import casadi as ca

    from musclemetab.redundancy.ipopt import MUMPS_OPTIONS, ipopt_options

    ipopt = ipopt_options(options.with_(max_iter=k if k > 0 else options.max_iter), MUMPS_OPTIONS)
    opts = {"ipopt": ipopt, "print_time": False, "error_on_fail": False}
    opts.update({key: nlp[key] for key in ("grad_f", "jac_g", "hess_lag")})
    solver = ca.nlpsol("kkt", "ipopt", {"x": nlp["x"], "p": nlp["p"], "f": nlp["f"], "g": nlp["g"]}, opts)
    sol = solver(x0=nlp["x0"], p=nlp["p_values"], lbx=nlp["lbx"], ubx=nlp["ubx"], lbg=nlp["lbg"], ubg=nlp["ubg"])
    st = solver.stats()
    mu = float(st["iterations"]["mu"][-1])
    return (np.asarray(sol["x"]).ravel(), np.asarray(sol["lam_g"]).ravel(), np.asarray(sol["lam_x"]).ravel(),
            mu, int(st["iter_count"]))


_ITERATION = re.compile(r"^\s*(\d+)r?\s+[-+0-9.e]+\s+[0-9.e+-]+\s+[0-9.e+-]+\s+[-0-9.]+\s+[0-9.e+-]+\s+(\S+)\s")
_EXCESS = re.compile(r"negevals_ = (\d+), but numberOfNegEVals = (\d+)")


def count_factorisations(log: str) -> dict:
    """Factorisations and inertia corrections in an IPOPT log written at print level 6."""
    ok = log.count("Factorization successful.")
    wrong_inertia = log.count("Factorization failed with retval = 2")
    perturbed = sum(1 for line in log.splitlines() if (m := _ITERATION.match(line)) and m.group(2) != "-")
    excess = [int(a) - int(b) for a, b in _EXCESS.findall(log)]
    return {"factorisations": ok + wrong_inertia, "wrong_inertia": wrong_inertia,
            "perturbed_iterations": perturbed, "max_excess_negative": max(excess, default=0)}


def ipopt_linear_algebra_time(nlp, options):
    """What MUMPS costs inside IPOPT over a full solve: the number of factorisations (counted
    in IPOPT's detailed log, those refused for wrong inertia included) and the time IPOPT
    spends outside the NLP's functions (its linear algebra: MUMPS' factorisations and solves,
    and IPOPT's own vector work) per factorisation, an upper bound of one MUMPS factorisation.

    IPOPT's own timers are not used: IPOPT 3.14 calls MUMPS to factorise and solve in one call
    and books neither under ``LinearSystemFactorization``, so they show a few ms per iteration
    where MUMPS works for tens of ms."""
    import tempfile

    import casadi as ca

    from musclemetab.redundancy.ipopt import MUMPS_OPTIONS, ipopt_options

    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "ipopt.log"
        ipopt = ipopt_options(options, MUMPS_OPTIONS)
        ipopt.update({"output_file": str(log), "file_print_level": 6})
        opts = {"ipopt": ipopt, "print_time": False, "error_on_fail": False}
        opts.update({key: nlp[key] for key in ("grad_f", "jac_g", "hess_lag")})
        solver = ca.nlpsol("kkt_timing", "ipopt", {"x": nlp["x"], "p": nlp["p"], "f": nlp["f"], "g": nlp["g"]}, opts)
        t0 = time.perf_counter()
        solver(x0=nlp["x0"], p=nlp["p_values"], lbx=nlp["lbx"], ubx=nlp["ubx"], lbg=nlp["lbg"], ubg=nlp["ubg"])
        total = time.perf_counter() - t0
        counts = count_factorisations(log.read_text())
    st = solver.stats()
    functions = sum(v for k, v in st.items() if k.startswith("t_wall_nlp_"))
    linear_algebra = total - functions
    return {"iterations": int(st["iter_count"]), "total_s": total, "functions_s": functions,
            "linear_algebra_s": linear_algebra, **counts,
            "per_factorisation_ms": 1e3 * linear_algebra / max(counts["factorisations"], 1)}


def _csc(dm):
    """CasADi DM (sparse) -> SciPy CSC."""
    s = dm.sparsity()
    colind, row = np.asarray(s.colind()), np.asarray(s.row())
    return sp.csc_matrix((np.asarray(dm.nonzeros()), row, colind), shape=dm.shape)


def kkt_matrix(nlp, x, lam_g, lam_x, mu):
    """The primal-dual KKT matrix of the iterate and its right-hand side (the KKT residual)."""
    lbx, ubx = np.asarray(nlp["lbx"], float).ravel(), np.asarray(nlp["ubx"], float).ravel()
    jf = nlp["jac_g"](x, nlp["p_values"])
    g, J = np.asarray(jf[0]).ravel(), _csc(jf[1])
    hu = _csc(nlp["hess_lag"](x, nlp["p_values"], 1.0, lam_g))  # upper triangle
    H = hu + sp.triu(hu, 1).T
    grad = np.asarray(nlp["grad_f"](x, nlp["p_values"])[1]).ravel()
    zl, zu = np.maximum(-lam_x, 0.0), np.maximum(lam_x, 0.0)
    sigma = np.zeros_like(x)
    lo, up = np.isfinite(lbx), np.isfinite(ubx)
    dl = np.where(lo, np.maximum(x - lbx, 1e-12), 1.0)
    du = np.where(up, np.maximum(ubx - x, 1e-12), 1.0)
    sigma += np.where(lo, np.maximum(zl, mu / dl) / dl, 0.0)
    sigma += np.where(up, np.maximum(zu, mu / du) / du, 0.0)
    n, m = x.size, g.size
    K = sp.bmat([[H + sp.diags(sigma), J.T], [J, None]], format="csc")
    b = -np.concatenate([grad + J.T @ lam_g - zl + zu, g])
    return K, b, n, m


def residual(K, x, b):
    return float(np.max(np.abs(K @ x - b)) / (spla.norm(K, np.inf) * np.max(np.abs(x)) + np.max(np.abs(b))))


# ---------------------------------------------------------------------------- block elimination
class BlockElimination:
    """Per-muscle banded LU + dense Schur complement of the coupling rows (see module doc)."""

    def __init__(self, K, n, M, D, N):
        nz = 5 * M + D
        K = K.tocsr()
        size = K.shape[0]
        # muscle of every variable (-1: reserve) from the node-major layout
        owner = np.full(size, -2)
        for k in range(N):
            base = k * nz
            for blk in range(4):  # a, lM, lp, e
                owner[base + blk * M: base + (blk + 1) * M] = np.arange(M)
            owner[base + 4 * M: base + 4 * M + D] = -1
            owner[base + 4 * M + D: base + nz] = np.arange(M)
        for blk in range(3):
            owner[N * nz + blk * M: N * nz + (blk + 1) * M] = np.arange(M)
        node = np.concatenate([np.repeat(np.arange(N), nz), np.full(3 * M, N)]).astype(float)
        # constraint rows: local to one muscle if every variable they involve is that muscle's
        Jr = K[n:, :n]
        row_owner = np.empty(size - n, dtype=int)
        row_node = np.empty(size - n)
        for i in range(size - n):
            cols = Jr.indices[Jr.indptr[i]:Jr.indptr[i + 1]]
            owners = np.unique(owner[cols])
            row_owner[i] = owners[0] if owners.size == 1 and owners[0] >= 0 else -1
            row_node[i] = node[cols].min() + 0.5
        owner[n:] = row_owner
        node = np.concatenate([node[:n], row_node])
        self.R = np.flatnonzero((owner == -1) & (np.arange(size) >= n))  # coupling rows
        self.V = np.flatnonzero((owner == -1) & (np.arange(size) < n))   # reserves
        K_VV = K[self.V][:, self.V]
        if (K_VV - sp.diags(K_VV.diagonal())).nnz and np.any((K_VV - sp.diags(K_VV.diagonal())).data):
            raise ValueError("the reserve block is not diagonal")
        self.d_V = K_VV.diagonal()
        self.K_RV = K[self.R][:, self.V].tocsr()
        self.K_RR = K[self.R][:, self.R].toarray()
        self.blocks = []
        for m in range(M):
            idx = np.flatnonzero(owner == m)
            idx = idx[np.argsort(node[idx], kind="stable")]  # time order: a banded chain
            A = K[idx][:, idx].tocoo()
            kl = int(np.max(A.row - A.col))
            ku = int(np.max(A.col - A.row))
            B = K[self.R][:, idx].tocsc()
            if K[self.V][:, idx].nnz:
                raise ValueError("a reserve couples directly with a muscle variable")
            touched = np.flatnonzero(np.diff(B.indptr))
            Bt = B[:, touched].tocsr()
            rows = np.flatnonzero(np.diff(Bt.indptr))  # coupling rows this muscle enters
            ab = np.zeros((2 * kl + ku + 1, idx.size), order="F")
            self.blocks.append(dict(idx=idx, A=A, kl=kl, ku=ku, B=B, touched=touched, rows=rows,
                                    Bc=Bt[rows].tocsr(), ab=ab))
        self.size = size
        self.bandwidths = [(b["kl"], b["ku"]) for b in self.blocks]

    def factorize(self):
        t_form = time.perf_counter()  # banded factorisations and the Schur complement's forming
        # reserves: diagonal block, eliminated exactly
        S = self.K_RR - (self.K_RV @ sp.diags(1.0 / self.d_V) @ self.K_RV.T).toarray()
        for b in self.blocks:
            A, kl, ku, nloc, ab = b["A"], b["kl"], b["ku"], b["idx"].size, b["ab"]
            ab[:] = 0.0
            ab[kl + ku + A.row - A.col, A.col] = A.data
            lub, piv, info = lapack.dgbtrf(ab, kl, ku)
            if info != 0:
                raise np.linalg.LinAlgError(f"banded LU failed ({info})")
            t = b["touched"]
            E = np.zeros((nloc, t.size), order="F")
            E[t, np.arange(t.size)] = 1.0
            W = lapack.dgbtrs(lub, kl, ku, E, piv)[0]
            Bc, rows = b["Bc"], b["rows"]
            # B_m A_m^-1 B_m^T (B_m has one non-zero per coupling row; the result is dense in time)
            P = Bc @ np.asarray(Bc @ W[t, :].T).T
            if rows.size == S.shape[0]:
                S -= P
            else:
                S[np.ix_(rows, rows)] -= P
            b["lub"], b["piv"] = lub, piv
        self.schur_form_s = time.perf_counter() - t_form
        # dense LU of the Schur complement (LAPACK getrf), and for comparison the symmetric
        # indefinite factorisation (sytrf via scipy.linalg.ldl) that would also give its inertia,
        # which an interior-point method needs
        t0 = time.perf_counter()
        self.S_lu = sla.lu_factor(S, check_finite=False)
        self.schur_lu_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        sla.ldl(S, check_finite=False)
        self.schur_ldl_s = time.perf_counter() - t0

    def solve(self, rhs):
        x = np.empty(self.size)
        rv = rhs[self.V]
        rr = rhs[self.R] - self.K_RV @ (rv / self.d_V)
        ys = []
        for b in self.blocks:
            y = lapack.dgbtrs(b["lub"], b["kl"], b["ku"], rhs[b["idx"]], b["piv"])[0]
            ys.append(y)
            rr -= b["B"] @ y
        xr = sla.lu_solve(self.S_lu, rr, check_finite=False)
        x[self.R] = xr
        x[self.V] = (rv - self.K_RV.T @ xr) / self.d_V
        for b, y in zip(self.blocks, ys):
            corr = lapack.dgbtrs(b["lub"], b["kl"], b["ku"], b["B"].T @ xr, b["piv"])[0]
            x[b["idx"]] = y - corr
        return x


def _time(func, repeat):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = func()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times), out


def compare(K, b, n, layout, repeat, superlu):
    import casadi as ca

    M, D, N = layout
    rows = []
    Kc = ca.DM(ca.Sparsity(K.shape[0], K.shape[1], K.indptr.tolist(), K.indices.tolist()), K.data)
    for name in ("mumps",):  # CasADi's LDL^T (no pivoting) fails on these indefinite matrices
        ls = ca.Linsol(f"kkt_{name}", name, Kc.sparsity())
        ls.sfact(Kc)

        def run(ls=ls):
            ls.nfact(Kc)
            return np.asarray(ls.solve(Kc, ca.DM(b))).ravel()

        ms, x = _time(run, repeat)
        rows.append(("CasADi Linsol MUMPS", ms, residual(K, x, b)))
    if superlu:
        ms, x = _time(lambda: spla.splu(K, permc_spec="MMD_AT_PLUS_A").solve(b), max(1, repeat // 5))
        rows.append(("superlu (MMD_AT_PLUS_A)", ms, residual(K, x, b)))
    t0 = time.perf_counter()
    be = BlockElimination(K, n, M, D, N)
    setup = time.perf_counter() - t0

    def run_block():
        be.factorize()
        return be.solve(b)

    ms, x = _time(run_block, repeat)
    rows.append(("block elimination", ms, residual(K, x, b)))
    rows.append(("  of which forming S", 1e3 * be.schur_form_s, float("nan")))
    rows.append(("  of which dense LU of S", 1e3 * be.schur_lu_s, float("nan")))
    rows.append(("  (LDL^T of S, with inertia)", 1e3 * be.schur_ldl_s, float("nan")))
    info = dict(coupling=be.R.size, block_sizes=sorted({bl["idx"].size for bl in be.blocks}),
                bandwidths=sorted(set(be.bandwidths)), touched=sorted({bl["touched"].size for bl in be.blocks}),
                setup_s=setup)
    return rows, info


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", nargs="+", default=["normal"], choices=("slow", "normal", "fast"))
    ap.add_argument("--iterations", nargs="+", type=int, default=[1, 10, 0],
                    help="IPOPT iterations before the matrix is taken (0: the converged iterate)")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--no-superlu", action="store_true", help="skip SciPy's SuperLU (slow)")
    ap.add_argument("--quick", action="store_true",
                    help="the normal trial's window 0.6-0.8 s, the first iterate alone, one repeat, no SuperLU "
                    "(the test suite runs it so)")
    args = ap.parse_args(argv)
    window = None
    if args.quick:
        from _quick import WINDOW

        args.trials, args.iterations, args.repeat, args.no_superlu, window = ["normal"], [1], 1, True, WINDOW
    ex = _example()
    print(f"KKT benchmark: {os.cpu_count()} cores, load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"{'matrix':<26} {'method':<26} {'factorise+solve ms':>19} {'residual':>10}")
    for trial in args.trials:
        nlp, options = build_problem(ex, trial, window)
        t = ipopt_linear_algebra_time(nlp, options)
        print(f"{trial}: IPOPT with MUMPS over the full solve: {t['iterations']} iterations, {t['factorisations']} "
              f"factorisations ({t['wrong_inertia']} refused for wrong inertia); IPOPT outside the NLP functions "
              f"{t['linear_algebra_s']:.2f} s of {t['total_s']:.2f} s = {t['per_factorisation_ms']:.1f} ms per "
              f"factorisation (an upper bound: MUMPS' solves and IPOPT's own work included), "
              f"{1e3 * t['linear_algebra_s'] / t['iterations']:.1f} ms per iteration", flush=True)
        for k in args.iterations:
            x, lam_g, lam_x, mu, it = iterate(nlp, options, k)
            K, b, n, m = kkt_matrix(nlp, x, lam_g, lam_x, mu)
            t0 = nlp["layout"]["trials"][0]  # one trial: node-major variables from offset 0
            rows, info = compare(K, b, n, (t0["M"], t0["D"], t0["N"]), args.repeat, not args.no_superlu)
            label = f"{trial} it {it} ({K.shape[0]}, {K.nnz // 1000}k nz)"
            for method, ms, res in rows:
                print(f"{label:<26} {method:<26} {ms:>19.1f} {res:>10.1e}", flush=True)
            ratio = rows[0][1] / rows[-4][1]
            print(f"    mu {mu:.1e}; coupling set {info['coupling']}, muscle blocks {info['block_sizes']} with "
                  f"(kl, ku) {info['bandwidths']}, {info['touched']} local variables touched by the coupling rows; "
                  f"CasADi-Linsol MUMPS / block = {ratio:.2f}x", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
