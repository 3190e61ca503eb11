"""Solve K u = f: sparse direct (SuperLU) for small models, PyAMG smoothed aggregation + CG for large.

AMG: on P1 systems PyAMG smoothed aggregation (six rigid-body modes as near-nullspace B, 3×3
nodal blocks) preconditions CG; on P2 systems a two-level p-multigrid (block Gauss–Seidel on P2,
Galerkin P1-vertex coarse system, one aggregation-AMG V-cycle, direct below PMG_MAX_COARSE unknowns)
preconditions CG; with numba the load cases are solved together (flexure.multirhs: the smoother
and A·X read the matrix once for all cases, the first sweep and its residual one pass over the lower
triangle; the coarse V-cycle on all columns at once, flexure.vcycle; same iterations and answers as
one CG per case), with one BLAS thread (flexure.blas).
``info`` reports the solver, iterations, relative residual ‖b − A q‖/‖b‖, dofs, timings and named
conditioning warnings:
* ``near_incompressible``: ν ≥ NU_LOCKING[order]. P1 (ν ≥ 0.49, λ/μ ≥ 49): linear tetrahedra lock
  (displacements too small: 7 % at ν = 0.49, 20 % at 0.499 on the Lamé cylinder); use P2 or a mixed
  formulation. P2 (ν ≥ 0.49999, λ/μ ≥ 5·10⁴): measured on the plane-strain Lamé cylinder, the bore
  strain error of P2 is 1.9e-4, 3.6e-4, 4.5e-4, 4.8e-4 at ν = 0.49, 0.499, 0.4999, 0.49999 (1.5k–5k
  DOFs: no locking), but the condition estimate grows ×10 per decade of 1 − 2ν (1.6e9 at 0.49999 on
  5k DOFs, so ~1e11 on a 300k-DOF model): past the measured range the numbers are not trusted.
* ``sliver_elements``: a sliver-rich mesh — more than 1 % of the elements with a dihedral angle
  < 5°, or any below 1° (near-zero volume): K is ill-conditioned and stresses there unreliable.
  (A handful of 2–5° slivers, as tetgen leaves, are counted in ``n_slivers`` but not flagged.)
* ``ill_conditioned``: the 1-norm condition estimate of the reduced system exceeds 1e12 (direct only).
* ``large_residual``: relative residual above 1e-6 (solver did not converge).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from userio.errors import InputError
from flexure import blas, rss
from flexure.fem import stiffness_matrix
from flexure.mesh import SLIVER_DIHEDRAL_DEG, element_shape_metrics

#: "auto" uses the direct solver up to this many unknowns, AMG-CG above.
DIRECT_MAX_DOFS = 12_000
NU_LOCKING = {1: 0.49, 2: 0.49999}      # by element order: see the module docstring
SLIVER_FRACTION = 0.01
DEGENERATE_DIHEDRAL_DEG = 1.0
COND_LIMIT = 1e12
RESIDUAL_LIMIT = 1e-6
#: P2 load cases solved together (flexure.multirhs, numba); False: one CG per case (the reference)
MULTI_RHS = True
#: block Gauss–Seidel sweeps before and after the coarse correction of the P2 p-multigrid
PMG_SWEEPS = 1
#: the P2 sweeps in flexure.split_gs's order, its two parts side by side (block storages, one sweep)
SPLIT_SWEEPS = True
#: largest system the P2 p-multigrid's coarse AMG solves directly, in nodes (pyamg counts the 3 × 3 block
#: rows: a last level of up to 18,000 unknowns; 13,263 on the thick disc's first mesh). The CG iterations grew with the
#: number of AMG levels, not with h or the geometry: on the paper disc (smoothed coarse) 26–36
#: iterations at 72k DOFs and 22–31 at 145k (2 levels), 39–46 at 317k (3 levels with 1000);
#: with 6000 the 317k model keeps 2 levels and needs 22–30 (benchmarks/bench_fem.py --only ladder).
PMG_MAX_COARSE = 6000
#: the P2 smoother's copy of the matrix (``_pmg_multi``): "block32", 3 × 3 blocks of float32 values
#: (flexure.block_sparse; sums in float64), "block64" the same in float64, "csr" the scalar CSR itself.
#: The sweeps are bound by reading the matrix: 12 bytes an entry in the CSR, 4.4 in "block32" (thick
#: disc, 354 k dofs, one column: forward sweep with its residual 95 → 33-48 ms, backward 130 → 65-83 ms,
#: 2026-11-27 under load 2.8). The blocks' rounding (6e-8 relative) only changes the preconditioner,
#: not the system CG solves (its products stay on the float64 CSR); same CG iterations
#: (tests/test_fem_multirhs.py)
SMOOTHER_STORAGE = "block32"
#: the 3×3 diagonal blocks by one compiled pass over the rows (False: nine scipy diagonals, the reference)
BLOCKS_COMPILED = True


@dataclass
class Solution:
    """Nodal displacements ``u`` (n,3) in m, coupling reference motions, and solver ``info``."""

    u: np.ndarray
    info: dict
    reference: list = field(default_factory=list)   # per kinematic coupling: dict(U_m, theta_rad)
    K: sp.csr_matrix | None = None

    @property
    def ok(self) -> bool:
        """False when a conditioning warning was raised (treat the numbers as NaN)."""
        return not self.info["warnings"]


def conditioning_warnings(mesh, material) -> tuple[list[str], dict]:
    """Named warnings from the material (ν) and element shapes; plus the metrics used."""
    warnings = []
    q = element_shape_metrics(mesh.points, mesh.corner_tets)
    dmin = q["dihedral_deg"].min(axis=1)
    n_sliver = int(np.count_nonzero(dmin < SLIVER_DIHEDRAL_DEG))
    if material.nu >= NU_LOCKING[mesh.order]:
        warnings.append("near_incompressible")
    if n_sliver > SLIVER_FRACTION * len(dmin) or dmin.min() < DEGENERATE_DIHEDRAL_DEG:
        warnings.append("sliver_elements")
    return warnings, dict(min_dihedral_deg=float(dmin.min()), n_slivers=n_sliver,
                          lambda_over_mu=material.lame_lambda_Pa / material.shear_modulus_Pa)


def _check_restrained(system) -> None:
    """Refuse a system whose constraints leave a rigid-body mode free (K singular)."""
    Bf = system.B[system.fixed_q]
    if len(system.fixed_q) == 0 or np.linalg.matrix_rank(Bf, tol=1e-9 * max(1.0, np.abs(Bf).max())) < 6:
        raise InputError("boundary conditions: the model is not restrained against all six "
                         "rigid-body motions (fix more dofs)")


def _sa_hierarchy(A, B, smoothed: bool = True, max_coarse: int = 1000):
    """PyAMG (smoothed) aggregation on 3×3 nodal blocks with the rigid-body near-nullspace B. pyamg
    estimates the Jacobi smoothing's spectral radius from ``np.random.rand``: the global generator is
    seeded for the set-up (and given back as it was), so one matrix gives one hierarchy, run after run
    (unseeded, two set-ups of one matrix gave V-cycles 8e-5 apart, and an adaptive run could refine
    differently from one run to the next)."""
    import pyamg

    Ab = A.tobsr(blocksize=(3, 3)) if A.shape[0] % 3 == 0 else A
    state = np.random.get_state()
    np.random.seed(HIERARCHY_SEED)
    try:
        C, agg = _first_aggregates(Ab)
        return pyamg.smoothed_aggregation_solver(
            Ab, B=B, symmetry="hermitian", strength=[("predefined", {"C": C}), ("symmetric", {"theta": 0.1})],
            aggregate=[("predefined", {"AggOp": agg}), "standard"],
            smooth=("jacobi", {"omega": 4.0 / 3.0}) if smoothed else None, improve_candidates=None,
            presmoother=("block_gauss_seidel", {"sweep": "forward"}),
            postsmoother=("block_gauss_seidel", {"sweep": "backward"}),
            max_coarse=max_coarse, coarse_solver="splu")
    finally:
        np.random.set_state(state)


#: the seed of pyamg's spectral-radius estimate (``_sa_hierarchy``)
HIERARCHY_SEED = 0


def _first_aggregates(Ab):
    """(C, AggOp) of the first coarsening: pyamg's symmetric strength (θ = 0.1) and its standard
    (greedy) aggregation visiting the nodes in a seeded random order, the aggregates then numbered by
    their first node. The greedy pass depends on the visiting order: along a space-filling curve
    (flexure.node_order's numbering) it leaves more, smaller aggregates than in a random one (thick disc
    at 354 k P2 DOFs: 1549 against 1302; six_spoke_thick at 811 k: a last level of 20.8 k unknowns against
    16 k, its factor 1.77 against 1.02 s); a random order gives about what gmsh's own numbering gave (1226)."""
    from pyamg.aggregation.aggregate import standard_aggregation
    from pyamg.strength import symmetric_strength_of_connection

    C = symmetric_strength_of_connection(Ab, theta=0.1).tocsr()
    n = C.shape[0]
    visit = np.random.default_rng(HIERARCHY_SEED).permutation(n)
    back = np.empty(n, np.int64)
    back[visit] = np.arange(n)
    agg_v = standard_aggregation(C[visit][:, visit].tocsr())[0].tocsr()
    agg = agg_v[back].tocsr()                               # rows back in the nodes' own order
    rows = np.repeat(np.arange(n), np.diff(agg.indptr))
    first = np.full(agg.shape[1], n, np.int64)
    np.minimum.at(first, agg.indices, rows)
    label = np.empty(agg.shape[1], np.int64)
    label[np.argsort(first, kind="stable")] = np.arange(agg.shape[1])
    agg = sp.csr_matrix((agg.data, label[agg.indices], agg.indptr), shape=agg.shape)
    agg.sort_indices()
    return C, agg


def block_diagonal_inverse(A) -> np.ndarray:
    """(n/3, 3, 3) pseudo-inverses of the 3×3 diagonal blocks of A (as pyamg's get_block_diag), read
    from its five central diagonals: no BSR copy of the matrix."""
    A = sp.csr_matrix(A)
    nb = A.shape[0] // 3
    D = np.zeros((nb, 3, 3))
    if BLOCKS_COMPILED and _multirhs_available():       # one pass over the rows (duplicates summed, as diagonal())
        from flexure._reduce_kernels import diagonal_blocks

        diagonal_blocks(A.indptr, A.indices, A.data, D)
    else:
        for a in range(3):
            for b in range(3):
                d = A.diagonal(b - a)                  # k ≥ 0: A[r, r + k];  k < 0: A[r − k, r]
                D[:, a, b] = d[3 * np.arange(nb) + min(a, b)]
    # LU where a block is regular (every block but a constrained or empty one): pinv's SVD per block
    # costs several times more; the rest by pinv, as before
    det = np.linalg.det(D)
    ok = np.abs(det) > 1e-12 * np.abs(D).max(axis=(1, 2)) ** 3
    Dinv = np.empty_like(D)
    Dinv[ok] = np.linalg.inv(D[ok])
    if not ok.all():
        Dinv[~ok] = np.linalg.pinv(D[~ok])
    return Dinv


def _pmg_setup(A, coarse, B_coarse, smoothed: bool):
    """The parts of the two-level p-multigrid: the 3×3 block-diagonal inverses of the P2 system,
    and the coarse V-cycle M₁ on the Galerkin P1-vertex system A₁ = Iᵀ A I
    (aggregation AMG with the rigid-body modes; plain keeps the wide-stencil A₁ sparse)."""
    Dinv = block_diagonal_inverse(A)
    It = coarse.T.tocsr()
    A1 = ((It @ sp.csr_matrix(A)) @ coarse).tocsr()      # CSR products: Iᵀ as CSC would copy A to CSC first
    ml = _sa_hierarchy(A1, B_coarse, smoothed=smoothed, max_coarse=PMG_MAX_COARSE)
    return Dinv, ml, ml.aspreconditioner(cycle="V"), It


def _pmg_preconditioner(A, coarse, B_coarse, smoothed: bool = False):
    """Two-level p-multigrid for P2: block Gauss–Seidel (forward before, backward after) on the
    P2 system, coarse correction on the Galerkin P1-vertex system A₁ = Iᵀ A I by one V-cycle of
    aggregation AMG with the rigid-body modes (plain, or ``smoothed``: denser coarse levels, which
    pay off on layered, flat-element meshes). Symmetric, so it preconditions CG."""
    from pyamg.relaxation.relaxation import block_gauss_seidel

    Dinv, ml, M1, It = _pmg_setup(A, coarse, B_coarse, smoothed)
    Ab = A.tobsr(blocksize=(3, 3))

    def apply(r):
        r = np.asarray(r).ravel()
        x = np.zeros_like(r)
        block_gauss_seidel(Ab, x, r, iterations=1, sweep="forward", blocksize=3, Dinv=Dinv)
        x += coarse @ (M1 @ (It @ (r - Ab @ x)))
        block_gauss_seidel(Ab, x, r, iterations=1, sweep="backward", blocksize=3, Dinv=Dinv)
        return x

    n = A.shape[0]
    return spla.LinearOperator((n, n), matvec=apply, dtype=np.float64), ml


def _pmg_multi(A, coarse, B_coarse, smoothed: bool = False, sweeps: int = 1):
    """The same two-level p-multigrid as ``_pmg_preconditioner`` applied to k columns at once
    (flexure.multirhs: one pass over the matrix per Gauss–Seidel sweep for all columns); the
    coarse V-cycle too (flexure.vcycle); the first forward sweep (from zero) and the residual it
    leaves take one pass over the lower triangle (``multirhs.forward_gauss_seidel_residual``).
    Returns (M(R) → Z for R (n, k), the coarse hierarchy)."""
    from flexure import multirhs
    from flexure.block_sparse import BlockMatrix
    from flexure.vcycle import MultiVCycle

    Ac = A.tocsr()
    Ac.sort_indices()
    Dinv, ml, _, It = _pmg_setup(Ac, coarse, B_coarse, smoothed)
    rss.now_gb(trim=True)                   # the coarse set-up's free heap pages, before the smoother's copy
    Dinv = np.ascontiguousarray(Dinv)
    V = MultiVCycle(ml)                     # the coarse V-cycle on all columns at once
    if SMOOTHER_STORAGE == "csr":
        Ab, gs0, gs = Ac, multirhs.forward_gauss_seidel_residual, multirhs.block_gauss_seidel
    else:                                   # 3 × 3 blocks: fewer bytes read per sweep
        dtype = np.float32 if SMOOTHER_STORAGE == "block32" else np.float64
        if SPLIT_SWEEPS and sweeps == 1:
            return _pmg_split(Ac, Dinv, coarse, V, dtype)
        Ab = BlockMatrix.from_csr(Ac, dtype)
        gs0, gs = multirhs.forward_gauss_seidel_residual_bsr, multirhs.block_gauss_seidel_bsr

    def apply(R):
        X, res = gs0(Ab, Dinv, R)
        for _ in range(sweeps - 1):
            gs(Ab, Dinv, X, R, forward=True)
        if sweeps > 1:
            res = R - multirhs.spmm(Ac, X)
        X += coarse @ V(It @ res)
        for _ in range(sweeps):
            gs(Ab, Dinv, X, R, forward=False)
        return X

    apply.blocks = Ab if SMOOTHER_STORAGE != "csr" else None     # flexure.enriched: its A x on the blocks
    return apply, V


def _pmg_split(A, Dinv, coarse, V, dtype):
    """``_pmg_multi``'s cycle with flexure.split_gs's sweeps (two parts side by side) in its order of
    the rows, on 3 × 3 blocks of ``dtype`` built from the CSR A; the coarse interpolation's rows
    renumbered with them."""
    from flexure.split_gs import SplitSmoother

    H = SplitSmoother.from_csr(A, Dinv, dtype)
    coarse_p = coarse.tocsr()[H.perm]
    It_p = coarse_p.T.tocsr()

    def apply(R):
        Rp = np.ascontiguousarray(np.asarray(R)[H.perm])
        X, res = H.forward_from_zero(Rp)
        X += coarse_p @ V(It_p @ res)
        H.backward(X, Rp)
        return X[H.inv]

    apply.blocks = H                        # flexure.enriched: its A x on the parts' blocks
    return apply, V


def _hierarchy_info(ml) -> dict:
    """Levels and operator complexity of a pyamg hierarchy or a flexure.vcycle.MultiVCycle."""
    if hasattr(ml, "n_levels"):
        return {"amg_levels": ml.n_levels, "operator_complexity": ml.operator_complexity}
    return {"amg_levels": len(ml.levels), "operator_complexity": float(ml.operator_complexity())}


def _multirhs_available() -> bool:
    from flexure import multirhs

    return MULTI_RHS and multirhs.available()


@blas.single_threaded
def solve_system(A: sp.csr_matrix, b: np.ndarray, B: np.ndarray | None = None, method: str = "auto",
                 rtol: float = 1e-10, maxiter: int = 2000, condition_estimate: bool = True,
                 coarse: sp.csr_matrix | None = None, B_coarse: np.ndarray | None = None,
                 smoothed_coarse: bool = False, x0: np.ndarray | None = None):
    """Solve A q = b (b (n,) or (n, k) for k load cases); returns (q, info).

    ``B`` near-nullspace (rigid modes) for AMG; the factorization / AMG hierarchy is built once
    for all columns. ``x0`` (shape of b): initial guess of the iterative solvers (the P2
    p-multigrid CG with all cases together; ignored by the others). ``residual_norm`` is the
    largest column's ‖b − A q‖/‖b‖.
    """
    n = A.shape[0]
    if method == "auto":
        method = "direct" if n <= DIRECT_MAX_DOFS else "amg"
    info: dict = dict(solver=method, dofs=int(n))
    t0 = time.perf_counter()
    if method == "direct":
        lu = spla.splu(A.tocsc(), permc_spec="COLAMD")
        q = lu.solve(b)
        info["iterations"] = 1
        info["solver"] = "direct (SuperLU)"
        if condition_estimate:
            op = spla.LinearOperator((n, n), matvec=lu.solve, rmatvec=lambda x: lu.solve(x, trans="T"),
                                     dtype=np.float64)
            norm1 = abs(A).sum(axis=0).max()
            info["condition_estimate"] = float(norm1 * spla.onenormest(op))
    elif method == "amg":
        cols = b[:, None] if b.ndim == 1 else b          # several right-hand sides: one hierarchy
        q = np.empty_like(cols)
        its, case_s = [], []
        if coarse is not None and A.shape[0] % 3 == 0 and _multirhs_available():
            from flexure import multirhs

            M, ml = _pmg_multi(A, coarse, B_coarse, smoothed_coarse, PMG_SWEEPS)
            info["setup_s"] = time.perf_counter() - t0
            tc = time.perf_counter()
            X0 = None if x0 is None else np.asarray(x0, dtype=np.float64).reshape(cols.shape)
            q, its, _ = multirhs.pcg(A.tocsr(), np.ascontiguousarray(cols, dtype=np.float64), M, rtol, maxiter, X0)
            info["cg_s"] = time.perf_counter() - tc
            info["solver"] = ("amg-cg (p-multigrid: P2 block Gauss-Seidel + pyamg "
                              f"{'smoothed ' if smoothed_coarse else ''}aggregation AMG "
                              "on the P1 vertex system, 6 rigid-body modes; all load cases together)")
        elif coarse is not None:
            M, ml = _pmg_preconditioner(A, coarse, B_coarse, smoothed_coarse)
            info["setup_s"] = time.perf_counter() - t0
            for j in range(cols.shape[1]):
                it = [0]

                def cb(_):
                    it[0] += 1

                tc = time.perf_counter()
                q[:, j], _ = spla.cg(A, cols[:, j], rtol=rtol, atol=0.0, maxiter=maxiter, M=M, callback=cb)
                its.append(it[0])
                case_s.append(time.perf_counter() - tc)
            info["solver"] = ("amg-cg (p-multigrid: P2 block Gauss-Seidel + pyamg "
                              f"{'smoothed ' if smoothed_coarse else ''}aggregation AMG "
                              "on the P1 vertex system, 6 rigid-body modes)")
        else:
            ml = _sa_hierarchy(A, B)
            info["setup_s"] = time.perf_counter() - t0
            for j in range(cols.shape[1]):
                res: list = []
                tc = time.perf_counter()
                q[:, j] = ml.solve(cols[:, j], tol=rtol, accel="cg", maxiter=maxiter, residuals=res)
                its.append(len(res) - 1)
                case_s.append(time.perf_counter() - tc)
            info["solver"] = "amg-cg (pyamg smoothed aggregation, 6 rigid-body modes)"
        q = q[:, 0] if b.ndim == 1 else q
        info["iterations"] = its[0] if b.ndim == 1 else its
        info["case_s"] = case_s                          # per case (one CG each); together: cg_s only
        info.setdefault("cg_s", float(sum(case_s)))
        info.update(_hierarchy_info(ml))
    elif method == "cg":
        it = [0]

        def cb(_):
            it[0] += 1

        M = sp.diags(1.0 / A.diagonal())
        q, _ = spla.cg(A, b, rtol=rtol, maxiter=maxiter * 10, M=M, callback=cb)
        info["iterations"] = it[0]
        info["solver"] = "jacobi-cg"
    else:
        raise InputError(f"solve: method must be 'auto', 'direct', 'amg' or 'cg', got {method!r}")
    info["solve_s"] = time.perf_counter() - t0
    r = np.linalg.norm((b - A @ q).reshape(n, -1), axis=0)
    bn = np.linalg.norm(b.reshape(n, -1), axis=0)
    rel = r / np.where(bn > 0, bn, 1.0)
    info["residual_norm"] = float(np.max(rel))
    info["case_residuals"] = rel.tolist()
    return q, info


def solve(problem, method: str = "auto", rtol: float = 1e-10, K: sp.csr_matrix | None = None,
          keep_K: bool = False, condition_estimate: bool = True) -> Solution:
    """Assemble (unless ``K`` given), apply the boundary conditions and solve ``problem``."""
    t0 = time.perf_counter()
    if K is None:
        K = stiffness_matrix(problem.mesh, problem.material)
    assemble_s = time.perf_counter() - t0
    warnings, metrics = conditioning_warnings(problem.mesh, problem.material)
    system = problem.reduced_system(K)
    _check_restrained(system)
    q, info = solve_system(system.A, system.b, system.B, method, rtol,
                           condition_estimate=condition_estimate, coarse=system.coarse,
                           B_coarse=system.B_coarse)
    info["assemble_s"] = assemble_s
    info.update(metrics)
    if info.get("condition_estimate", 0.0) > COND_LIMIT:
        warnings.append("ill_conditioned")
    if not np.isfinite(info["residual_norm"]) or info["residual_norm"] > RESIDUAL_LIMIT:
        warnings.append("large_residual")
    info["warnings"] = warnings
    u = problem.expand(system, q)
    reference = [dict(U_m=q[s][:3].copy(), theta_rad=q[s][3:].copy()) for s in system.ref_slices]
    info["total_s"] = time.perf_counter() - t0
    return Solution(u=u, info=info, reference=reference, K=K if keep_K else None)


def solve_reduced(system, b: np.ndarray | None = None, method: str = "auto", rtol: float = 1e-10,
                  condition_estimate: bool = True, smoothed_coarse: bool = False, x0: np.ndarray | None = None):
    """Solve a ``Problem.reduced_system`` for its own b or for load cases ``b`` (n_q,) / (n_q, k).

    One factorization / AMG hierarchy for all columns; passes the P2 → P1 coarse space so P2
    systems get the p-multigrid preconditioner. Returns (q, info).
    """
    b = system.b if b is None else np.asarray(b, dtype=np.float64)
    if b.shape[0] != system.A.shape[0]:
        raise InputError(f"solve_reduced: b has {b.shape[0]} rows, the system {system.A.shape[0]}")
    return solve_system(system.A, b, system.B, method, rtol, condition_estimate=condition_estimate,
                        coarse=system.coarse, B_coarse=system.B_coarse, smoothed_coarse=smoothed_coarse, x0=x0)


@blas.single_threaded
def prepared(system, rtol: float = 1e-10, smoothed_coarse: bool = False):
    """A solver for ``system`` that is set up once and reused for further right-hand sides:
    → solve(B (n_q,) or (n_q, k), x0=None, rtol=None, goal_stop=None) → (q, info), ``rtol`` one number
    or one per column (the P2 p-multigrid's CG stops each column at its own; the others use the
    smallest), ``goal_stop`` the P2 p-multigrid CG's goal-oriented stop (flexure.multirhs.pcg; the
    direct and per-column solvers solve to their tolerance).
    The P2 p-multigrid (all columns together) keeps its hierarchy, a small system its LU factors;
    otherwise each call is ``solve_reduced``. An adaptive analysis solves its goals and, on its last mesh, the remaining
    load cases with one set-up."""
    A = system.A
    n = A.shape[0]
    t0 = time.perf_counter()
    if n <= DIRECT_MAX_DOFS:
        lu = spla.splu(A.tocsc(), permc_spec="COLAMD")
        setup_s = time.perf_counter() - t0

        @blas.single_threaded
        def solve_direct(B, x0=None, rtol_=None, goal_stop=None):
            t = time.perf_counter()
            q = lu.solve(np.asarray(B, dtype=np.float64))
            return q, _residual_info(A, B, q, {"solver": "direct (SuperLU)", "dofs": int(n), "iterations": 1,
                                              "setup_s": setup_s, "solve_s": time.perf_counter() - t})
        solve_direct.precond = lu.solve          # flexure.enriched: the P2 block of the enriched solve
        return solve_direct
    if system.coarse is not None and n % 3 == 0 and _multirhs_available():
        from flexure import multirhs

        M, ml = _pmg_multi(A, system.coarse, system.B_coarse, smoothed_coarse, PMG_SWEEPS)
        rss.now_gb(trim=True)                # the set-up's free heap pages, before the CG's columns
        Ac = A.tocsr()
        setup_s = time.perf_counter() - t0

        @blas.single_threaded
        def solve_pmg(B, x0=None, rtol_=None, goal_stop=None):
            t = time.perf_counter()
            B = np.asarray(B, dtype=np.float64)
            cols = np.ascontiguousarray(B[:, None] if B.ndim == 1 else B)
            X0 = None if x0 is None else np.asarray(x0, dtype=np.float64).reshape(cols.shape)
            q, its, _ = multirhs.pcg(Ac, cols, M, rtol if rtol_ is None else rtol_, 2000, X0, goal_stop)
            q = q[:, 0] if B.ndim == 1 else q
            return q, _residual_info(A, B, q, {
                "solver": ("amg-cg (p-multigrid: P2 block Gauss-Seidel + pyamg "
                           f"{'smoothed ' if smoothed_coarse else ''}aggregation AMG on the P1 vertex system, "
                           "6 rigid-body modes; all load cases together)"),
                "dofs": int(n), "iterations": its, "setup_s": setup_s, "cg_s": time.perf_counter() - t,
                "solve_s": time.perf_counter() - t, **_hierarchy_info(ml)})
        solve_pmg.precond = M                    # flexure.enriched: the P2 block of the enriched solve
        return solve_pmg

    def solve_each(B, x0=None, rtol_=None, goal_stop=None):
        return solve_reduced(system, B, rtol=rtol if rtol_ is None else float(np.min(rtol_)), condition_estimate=False,
                             smoothed_coarse=smoothed_coarse, x0=x0)
    return solve_each


def _residual_info(A, b, q, info: dict) -> dict:
    """``info`` with the largest column's relative residual ‖b − A q‖/‖b‖ and each column's."""
    n = A.shape[0]
    r = np.linalg.norm((b - A @ q).reshape(n, -1), axis=0)
    bn = np.linalg.norm(np.asarray(b).reshape(n, -1), axis=0)
    rel = r / np.where(bn > 0, bn, 1.0)
    info["residual_norm"] = float(np.max(rel))
    info["case_residuals"] = rel.tolist()
    return info
