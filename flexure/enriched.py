"""The error of a P2 solution in the enriched space V⁺ = V_h ⊕ W on the same mesh (W the
hierarchical cubic surplus: one edge cubic per edge, one face bubble per face, flexure.surplus),
solved globally: the goal-error estimate that needs no calibration.

Let u⁺ ∈ V⁺ be the Galerkin solution in V⁺ and e⁺ = u⁺ − u_h = e_h + e_W (e_h ∈ V_h, e_W ∈ W).
With R(u_h)(v) = F(v) − a(u_h, v), R(u_h) = 0 on V_h (Galerkin), the block system of e⁺ is

    [K_hh  K_hW] [e_h]   [0  ]
    [K_Wh  K_WW] [e_W] = [r_W],        r_W = R(u_h)(φ_W),

so e_h = −K_hh⁻¹ K_hW e_W and, for a linear goal J with discrete dual z_h (a(v, z_h) = J(v) on V_h),

    J(u⁺) − J(u_h) = J(e_W) − a(z_h, e_W) = R*(z_h)(e_W)                                     (1)

exactly, e_W the solution of the Schur complement S e_W = r_W, S = K_WW − K_Wh K_hh⁻¹ K_hW. S is
spectrally equivalent to K_WW, (1 − γ²) K_WW ≤ S ≤ K_WW (γ < 1 the strengthened Cauchy–Schwarz
constant of V_h and W, independent of h), but γ is not small for the gauges: the first block
Gauss–Seidel sweep alone (K_WW e_W = r_W) gave 0.08–1.0 of the round STEP annulus' arm errors where
the whole solve gives 0.92–1.08. ``enriched_solve`` solves the whole system (block-preconditioned CG);
one primal solve serves every goal.

Bracketing (why ``adaptive`` reports 2 |J⁺ − J_h|): if the enriched goal error |J − J⁺| ≤ q |J − J_h|
(saturation) with q ≤ ½, then |J⁺ − J_h| ∈ [(1 − q), (1 + q)] |J − J_h|, and 2 |J⁺ − J_h| has an
effectivity in [2(1 − q), 2(1 + q)] ⊂ [1, 3] whatever the signs. Where V⁺ saturates less (q up to
0.55 next to re-entrant edges), q is measured between nested levels and the factor raised to
1.5/(1 − q̂) (flexure.saturation).
"""

from __future__ import annotations

import math
import time

import numpy as np

from flexure.mesh import TET_EDGES, TET_FACES, TET_FACES_P2, Mesh

#: relative residual of the enriched CG. The estimate needs J(u⁺) − J(u_h) to ~10 % of itself; 1e-2
#: moves it by ≤ 1.2 % against 1e-6 (first adaptive meshes: paper_disc 48.7 k P2 dofs 1.2 %, thick_disc
#: 83.9 k 0.54 %, unseen cross_frame 56 k 0.31 %, θ ≤ 2e-4; thin annulus 15 k < 1 %) in 30, 24, 23
#: iterations where 1e-3 took 43, 33, 33 (≤ 0.1 %). With the P2 duals' correction (``dual_corrected``,
#: ``goal_errors``) 2e-2 is more accurate than 1e-2 without it, in fewer iterations: thick disc
#: (2026-11-27, its adaptive levels of 84 k, 251 k, 354 k P2 dofs; the largest change of θ's d and of
#: the gauges' d against the converged solve, relative to |d_θ| and max |d_gauge|) 21, 24, 24 iterations
#: and 8.6e-4, 7.5e-4, 2.2e-3 where 1e-2 uncorrected took 24, 27, 27 and was off by 2.5e-3, 4.2e-3, 3.0e-3.
#: 5e-2 (2026-11-27, dual-corrected, against rtol 1e-8; the first meshes of paper_disc, thick_disc, reentrant,
#: three_spoke_thin, six_spoke_sharp, cross_frame, 35–84 k P2 dofs, and three of them bisected to 214–354 k):
#: 17–22 iterations where 2e-2 takes 20–27, every goal's d within 3.7 % of itself (θ's within 1e-4), 2e-2's
#: within 4.9 %; 1e-1 took 14–18 and left one gauge's small d 18 % off (three_spoke_thin, 35 k)
RTOL = 5e-2
MAX_ITER = 2000
#: the adaptive levels' cap on the enriched CG (``goal_errors``): it takes 14–24 iterations at RTOL on every
#: part measured; one still short of RTOL here is on a system its preconditioner does not reach (a
#: near-incompressible material: the paper disc at ν = 0.4999, 48.7 k P2 DOFs, stopped at MAX_ITER after 45 s),
#: and its estimate is flagged (info "converged" False: flexure.adaptive stops and withholds the ±)
LEVEL_MAX_ITER = 200
#: K_WW and K_hW as 3 × 3 blocks of float32 values (flexure.block_sparse; products summed in float64):
#: 40 bytes a block against 108 in the scalar float64 CSR. Its rounding (relative 6e-8 an entry) is far
#: below the CG's 1e-2: d moved by ≤ 1.3e-4 (relative, θ and gauges, 2026-11-27, first adaptive meshes at
#: h-factor 1: paper_disc 134 k P2 dofs, thick_disc 229 k, reentrant 138 k, cross_frame 142 k) in the
#: same PCG iterations; converged (rtol 1e-12) by ~1e-7 (tests/test_block_sparse.py)
STORAGE = "block32"
#: the preconditioner's W block and how it meets V_h: "multiplicative" (the default), one symmetric block
#: Gauss–Seidel pass W → V_h → W over the two blocks (``multiplicative_preconditioner``), damped 3 × 3 block
#: Jacobi on W and the P2 cycle on V_h; "jacobi", the two blocks apart (block-diagonal: P2 cycle, 3 × 3 block
#: Jacobi); "sgs", the two blocks apart with one multicolour symmetric block Gauss–Seidel sweep pair on K_WW
#: (flexure.block_sparse; on paper_disc 28.5 k P2 dofs 37 → 25 PCG iterations, K_WW⁻¹ exactly 24: the W block
#: was not what held the CG back). The coupling K_hW was (γ not small for the gauges, module docstring): the
#: multiplicative pass takes 9–11 iterations where the block-diagonal one took 18–20 (thick disc at
#: --rtol 0.01, 2026-11-28: its adaptive levels of 84 k, 490 k and 750 k P2 dofs, ω from 0.35 to 0.7 alike),
#: its CG 10–30 % faster there (5–25 % over seven parts' default runs) for one more pass over K_hW and K_WW
#: an iteration
W_PRECOND = "multiplicative"
#: power iterations for λ_max(D⁻¹ K_WW), which sets the W block's damping ω = 1/λ̂ (``jacobi_lambda_max``)
POWER_ITERS = 12


def surplus_numbering(mesh: Mesh, constrained: np.ndarray):
    """Global surplus functions: → (G (m,10) the global index of each element's edge and face
    functions, sign (m,10) ±1: the element's edge cubic L_p L_q (L_p − L_q) against the global one
    (oriented from the lower to the higher vertex number; face bubbles are symmetric: +1), free
    (n_W,) bool: not on a constrained edge (its mid node) or face (all six nodes))."""
    from flexure.refine import edge_codes

    t = mesh.tets.astype(np.int64)
    m = len(t)
    uc, einv = np.unique(edge_codes(t).ravel(), return_inverse=True)
    fkey = np.sort(t[:, TET_FACES].reshape(-1, 3), axis=1)
    n = int(t.max()) + 1
    if n < 2**21:                      # one int64 code a face (a n + b) n + c: a 1-D unique, 30 × faster
        _, finv = np.unique((fkey[:, 0] * n + fkey[:, 1]) * n + fkey[:, 2], return_inverse=True)
    else:                              # than the rows' unique (thick disc, 78 k elements: 0.01 against 0.30 s)
        _, finv = np.unique(fkey, axis=0, return_inverse=True)
    finv = finv.ravel()
    ne, nf = len(uc), int(finv.max()) + 1
    G = np.hstack([einv.reshape(m, 6), ne + finv.reshape(m, 4)])
    sign = np.ones((m, 10))
    sign[:, :6] = np.where(t[:, TET_EDGES[:, 0]] < t[:, TET_EDGES[:, 1]], 1.0, -1.0)
    free = np.ones(ne + nf, bool)
    mid = np.empty(ne, np.int64)
    mid[einv] = t[:, 4:].ravel()
    free[:ne] = ~constrained[mid]
    fcon = np.zeros(nf, bool)
    fcon[finv] = constrained[t[:, TET_FACES_P2]].all(axis=2).ravel()
    free[ne:] = ~fcon
    return G, sign, free


def assemble(mesh: Mesh, material, u: np.ndarray, constrained: np.ndarray, traction=None):
    """K_WW (3 n_W square, CSR; rows 3g + i) and r_W = R(u_h)(φ) (3 n_W,) from the element blocks of
    flexure.bank_weiser (their traction-jump terms cancel in the sum), the numbering."""
    import scipy.sparse as sp

    from flexure.bank_weiser import element_blocks

    constrained = np.asarray(constrained, bool)
    G, sign, free = surplus_numbering(mesh, constrained)
    n = 3 * len(free)
    dof = (3 * G[:, :, None] + np.arange(3)).reshape(-1, 30)                 # (m,30): (b, i) → 3b + i
    s30 = np.repeat(sign, 3, axis=1)
    parts = []
    r = np.zeros(n)
    for sl, A, rr, kk in element_blocks(mesh, material, u, constrained, traction):
        d, s = dof[sl], s30[sl]
        A = np.where(kk[:, :, None] & kk[:, None, :], A, 0.0) * s[:, :, None] * s[:, None, :]
        parts.append(sp.csr_matrix((A.ravel(), (np.broadcast_to(d[:, :, None], A.shape).ravel(),
                                                np.broadcast_to(d[:, None, :], A.shape).ravel())), shape=(n, n)))
        np.add.at(r, d.ravel(), (rr * s).ravel())
    return _sum(parts, (n, n)), r, (G, sign, free)


def _sum(parts, shape):
    """Σ of sparse matrices, pairwise (each addition costs the size of its operands: a running sum
    over k chunks would cost k × the final size)."""
    import scipy.sparse as sp

    while len(parts) > 1:
        parts = [parts[i] + parts[i + 1] if i + 1 < len(parts) else parts[i] for i in range(0, len(parts), 2)]
    return parts[0] if parts else sp.csr_matrix(shape)


def coupling_matrix(mesh: Mesh, material, numbering, chunk: int = 4000):
    """K_hW (3 n_nodes × 3 n_W, CSR): a(N_a e_i, φ_g e_j) of the P2 shape functions and the surplus
    functions (``surplus_numbering``); for the full enriched solve (``enriched_solve``)."""
    import scipy.sparse as sp

    from flexure.bank_weiser import point_jacobians
    from flexure.fem import tet_shape
    from flexure.surplus import surplus_basis, tet_rule_degree5

    G, sign, _ = numbering
    lmb, mu = material.lame_lambda_Pa, material.shear_modulus_Pa
    xi, wq = tet_rule_degree5()
    _, dN2 = tet_shape(2, xi)
    _, dBs = surplus_basis(xi)
    n, nW = 3 * mesh.n_nodes, 3 * (int(G.max()) + 1)
    parts = []
    for s in range(0, mesh.n_elements, chunk):
        sl = slice(s, min(mesh.n_elements, s + chunk))
        t = mesh.tets[sl].astype(np.int64)
        det, Jinv = point_jacobians(mesh.points[t], dN2)
        gN, gB = np.matmul(dN2[None], Jinv), np.matmul(dBs[None], Jinv)
        P = np.einsum("eq,eqai,eqcj->eacij", wq[None] * det, gN, gB, optimize=True)    # (e,10,10,3,3)
        A = lmb * P + mu * P.swapaxes(-1, -2) + mu * np.trace(P, axis1=-2, axis2=-1)[..., None, None] * np.eye(3)
        A = A.transpose(0, 1, 3, 2, 4).reshape(-1, 30, 30) * np.repeat(sign[sl], 3, axis=1)[:, None, :]
        rows = (3 * t[:, :, None] + np.arange(3)).reshape(-1, 30)
        cols = (3 * G[sl][:, :, None] + np.arange(3)).reshape(-1, 30)
        parts.append(sp.csr_matrix((A.ravel(), (np.broadcast_to(rows[:, :, None], A.shape).ravel(),
                                                np.broadcast_to(cols[:, None, :], A.shape).ravel())), shape=(n, nW)))
    return _sum(parts, (n, nW))


def _block_jacobi(K):
    """The inverse 3 × 3 diagonal blocks (n/3,3,3) of K (rows 3g + i)."""
    C = K.tocoo()
    on = C.row // 3 == C.col // 3
    D = np.zeros((K.shape[0] // 3, 3, 3))
    np.add.at(D, (C.row[on] // 3, C.row[on] % 3, C.col[on] % 3), C.data[on])
    return np.linalg.inv(D)


def _nbytes(M) -> int:
    """Bytes of a scipy CSR or flexure.block_sparse.BlockMatrix's arrays."""
    if hasattr(M, "indptr"):
        return M.data.nbytes + M.indices.nbytes + M.indptr.nbytes
    return M.nbytes


def p2_blocks(precond_h, storage: str | None = None):
    """The P2 smoother's 3 × 3 blocks of A (``precond_h.blocks``: flexure.solve SMOOTHER_STORAGE) where they
    hold the value type of ``storage`` (default STORAGE) and the compiled path runs: the enriched CG's
    A x then reads them (fewer bytes than the float64 CSR, the same rounding as K_WW and K_hW); else None."""
    from flexure import enriched_assembly

    storage = STORAGE if storage is None else storage
    Ab = getattr(precond_h, "blocks", None)
    if not (enriched_assembly.available() and storage in ("block32", "block64") and Ab is not None
            and Ab.dtype == (np.float32 if storage == "block32" else np.float64)):
        return None
    return Ab


def p2_residual(system, q0: np.ndarray, theta_index: int | None = None) -> np.ndarray:
    """The V_h block of the enriched system's right-hand side, b − A q0 (b the unit load on the reduced
    dof ``theta_index``, else system.b), zero on the fixed rows."""
    nq = system.A.shape[0]
    b = system.b if theta_index is None else np.eye(1, nq, theta_index).ravel()
    rh = b - system.A @ q0
    rh[system.fixed_q] = 0.0
    return rh


def enriched_solve(system, mesh, material, gauges, U0: np.ndarray, q0: np.ndarray, constrained: np.ndarray,
                   precond_h, rtol: float = RTOL, max_iter: int = MAX_ITER, theta_index: int | None = None,
                   storage: str | None = None, w_precond: str | None = None, duals: np.ndarray | None = None,
                   residual_h: np.ndarray | None = None):
    """The Galerkin error e⁺ = u⁺ − u_h in V⁺ = V_h ⊕ W of the load case whose P2 solution is the
    reduced q0 (nodal U0 (n,3)), solved as one system (module docstring)

        [A     C  ] [e_h]   [b − A q0]
        [Cᵀ  K_WW ] [e_W] = [r_W     ]

    by preconditioned CG: ``precond_h`` (R (n_q,1) → Z: the P2 solver's p-multigrid cycle) on the V_h
    block, damped 3 × 3 block Jacobi on W (spectrally equivalent to K_WW, h-independent), the two joined
    by one symmetric block Gauss–Seidel pass (``w_precond`` "multiplicative", W_PRECOND) or apart
    ("jacobi", "sgs"). The first block row also takes up the P2 solve's algebraic error. → (J(u⁺) −
    J(u_h) of each gauge (g,), of the reduced dof ``theta_index`` (the hub rotation; NaN if None),
    info). ``storage`` (default STORAGE) of K_WW and K_hW in the compiled path: "block32", "block64"
    (flexure.block_sparse) or "csr" (scalar CSR, float64); ``w_precond`` (default W_PRECOND): "multiplicative",
    "jacobi" or "sgs" (block storages). ``duals`` (n_q, 1 + g): the P2 duals z̃ of θ
    and of each gauge (the goal solve's columns): the estimates are then dual-corrected
    (``dual_corrected``). ``residual_h``: the V_h block b − A q0 (``p2_residual``) computed by the
    caller, which may then have freed ``system.A`` (None) where ``p2_blocks`` gives A x (``goal_errors``)."""
    import scipy.sparse as sp

    from flexure import dwr
    from flexure.gauges import functionals

    from flexure import enriched_assembly, sparse_parallel

    t0 = time.perf_counter()
    A = system.A
    nq = len(system.b)
    mask = np.ones(nq)
    mask[system.fixed_q] = 0.0
    storage = STORAGE if storage is None else storage
    if enriched_assembly.available():            # compiled: C kept on the nodal rows, T and the mask applied
        num = surplus_numbering(mesh, np.asarray(constrained, bool))
        if storage == "csr":
            Kww, rW, C, Dinv, num = enriched_assembly.assemble_enriched(mesh, material, U0, num)
            c_mv, c_rmv = (lambda x: sparse_parallel.matvec(C, x)), (lambda x: sparse_parallel.rmatvec(C, x))
            k_mv = lambda x: sparse_parallel.matvec(Kww, x)  # noqa: E731
        else:                                    # 3 × 3 blocks, float32 or float64 values
            Kww, rW, C, Dinv, num = enriched_assembly.assemble_enriched_blocks(
                mesh, material, U0, num, np.float32 if storage == "block32" else np.float64)
            c_mv, c_rmv, k_mv = C.matvec, C.rmatvec, Kww.matvec
        G, sign, free = num
        keep = np.repeat(free, 3)
        T, TT = system.T, None if system.T is None else system.T.T.tocsr()

        def coupling(xw):                        # mask Tᵀ C x_W
            y = c_mv(xw)
            return mask * (y if TT is None else TT @ y)

        def coupling_t(xh):                      # Cᵀ T (mask x_h)
            y = mask * xh
            return c_rmv(y if T is None else T @ y)

        if hasattr(C, "matvec_rmatvec"):         # both in one pass over C (the bits of the two apart)
            def couplings(xh, xw):
                y = mask * xh
                cw, ct = C.matvec_rmatvec(xw, y if T is None else T @ y)
                return mask * (cw if TT is None else TT @ cw), ct
        else:
            def couplings(xh, xw):
                return coupling(xw), coupling_t(xh)
    else:
        Kww, rW, num = assemble(mesh, material, U0, constrained)
        G, sign, free = num
        keep = np.repeat(free, 3)
        Kww = Kww[keep][:, keep].tocsr()
        rW = rW[keep]
        C = coupling_matrix(mesh, material, num)
        Cq = C if system.T is None else system.T.T @ C
        del C
        Cq = (sp.diags(mask) @ Cq)[:, keep].tocsr()
        Dinv = _block_jacobi(Kww)
        CqT = Cq.T                               # a CSC view: no second copy of the coupling
        coupling, coupling_t = Cq.__matmul__, CqT.__matmul__

        def couplings(xh, xw):
            return coupling(xw), coupling_t(xh)
        k_mv = lambda x: sparse_parallel.matvec(Kww, x)  # noqa: E731
    # A x on the P2 smoother's 3 × 3 blocks where they hold the storage's value type (flexure.solve
    # SMOOTHER_STORAGE): fewer bytes read than the float64 CSR, the same rounding as K_WW and K_hW
    Ab = p2_blocks(precond_h, storage)
    if Ab is None and A is None:
        raise ValueError("enriched_solve: system.A freed, but the P2 preconditioner has no blocks of this storage")
    a_mv = Ab.matvec if Ab is not None else (lambda x: sparse_parallel.matvec(A, x))
    w_mode = W_PRECOND if w_precond is None else w_precond
    w_sgs = w_mode == "sgs" and hasattr(Kww, "symmetric_gauss_seidel")
    rh = p2_residual(system, q0, theta_index) if residual_h is None else residual_h
    rhs = np.concatenate([rh, rW])
    t1 = time.perf_counter()

    def matvec(x):
        xh, xw = x[:nq], x[nq:]
        cw, ct = couplings(xh, xw)
        return np.concatenate([a_mv(xh) + cw, ct + k_mv(xw)])

    def p_h(rh):
        return np.asarray(precond_h(np.ascontiguousarray(rh[:, None])))[:, 0]

    def jacobi(rw):
        return np.einsum("kij,kj->ki", Dinv, rw.reshape(-1, 3)).ravel()

    if w_mode == "multiplicative":
        prec = multiplicative_preconditioner(nq, p_h, jacobi, coupling, coupling_t, k_mv,
                                             1.0 / jacobi_lambda_max(k_mv, jacobi, len(rW)))
    else:
        def prec(r):
            return np.concatenate([p_h(r[:nq]), Kww.symmetric_gauss_seidel(Dinv, r[nq:]) if w_sgs else jacobi(r[nq:])])

    x = np.zeros(len(rhs))
    res = rhs                                    # CG vectors updated in place: fewer alive at the peak, same bits
    nb = np.linalg.norm(rhs)
    del rhs, rh, rW
    its = 0
    if nb > 0:
        z = prec(res)
        p = z.copy()
        rz = res @ z
        for its in range(1, max_iter + 1):
            Ap = matvec(p)
            alpha = rz / (p @ Ap)
            x += alpha * p
            Ap *= alpha
            res -= Ap                            # res − α Ap
            del Ap, z
            if np.linalg.norm(res) <= rtol * nb:
                break
            z = prec(res)
            rz_new = res @ z
            p *= rz_new / rz
            p += z                               # z + β p
            rz = rz_new
    eh, ew = x[:nq], np.zeros(len(keep))
    ew[keep] = x[nq:]
    coef = ew.reshape(-1, 3)[G] * sign[..., None]
    uh = eh.reshape(-1, 3) if system.T is None else (system.T @ eh).reshape(-1, 3)
    F = functionals(gauges, mesh)
    d_eps = np.einsum("nig,ni->g", F, uh) + dwr.gauge_indicators(mesh, gauges, coef[:, :6], coef[:, 6:]).sum(axis=0)
    d_theta = float(eh[theta_index]) if theta_index is not None else math.nan
    if duals is not None:
        d_theta, d_eps = dual_corrected(d_theta, d_eps, duals, res[:nq])
    converged = bool(nb == 0 or np.linalg.norm(res) <= rtol * nb)
    info = {"enriched_dofs": int(nq + keep.sum()), "pcg_iterations": int(its), "converged": converged,
            "setup_s": t1 - t0,
            "matrix_bytes": int(sum(_nbytes(M) for M in (Kww, C if enriched_assembly.available() else Cq))),
            "solve_s": time.perf_counter() - t1, "coef": coef}
    return d_eps, d_theta, info


def jacobi_lambda_max(k_mv, jacobi, n: int, iters: int = POWER_ITERS) -> float:
    """λ̂ ≈ λ_max(D⁻¹ K_WW) by power iteration from a fixed random start (``jacobi`` x ↦ D⁻¹ x, ``k_mv``
    x ↦ K_WW x); from below, but within 2× after a few steps, which is all the damping needs."""
    x = np.random.default_rng(0).standard_normal(n)
    lam = 1.0
    for _ in range(iters):
        y = jacobi(k_mv(x))
        ny = np.linalg.norm(y)
        if not ny > 0:
            break
        lam, x = ny / np.linalg.norm(x), y / ny
    return float(lam) if math.isfinite(lam) and lam > 0 else 1.0


def multiplicative_preconditioner(nq: int, p_h, jacobi, coupling, coupling_t, k_mv, omega: float):
    """r ↦ z, one symmetric block Gauss–Seidel pass over the enriched system [[A, C], [Cᵀ, K_WW]]:

        z_W = ω D⁻¹ r_W,   z_h = P_h (r_h − C z_W),   z_W ← z_W + ω D⁻¹ (r_W − Cᵀ z_h − K_WW z_W),

    D the 3 × 3 diagonal blocks of K_WW, P_h the P2 cycle (``p_h``). Symmetric; positive definite where
    the damped Jacobi step is a convergent smoother, 2 D/ω − K_WW > 0, i.e. ω < 2/λ_max(D⁻¹ K_WW): ω = 1/λ̂
    (``jacobi_lambda_max``) keeps that with λ̂ up to 2× below λ_max."""
    def prec(r):
        rh, rw = r[:nq], r[nq:]
        zw = omega * jacobi(rw)
        zh = p_h(rh - coupling(zw))
        zw += omega * jacobi(rw - coupling_t(zh) - k_mv(zw))
        return np.concatenate([zh, zw])
    return prec


def dual_corrected(d_theta: float, d_eps: np.ndarray, duals: np.ndarray, res_h: np.ndarray):
    """The CG iterate x's goal changes J(x) corrected by the P2 duals z̃ (n_q, 1 + g), extended by zero
    on W, against the V_h block ρ_h of the iterate's residual ρ (the CG's, updated recursively):

        J(e⁺) = J(x) + z⁺ᵀ ρ ≈ J(x) + z̃ᵀ ρ_h,    error (z⁺ − (z̃, 0))ᵀ ρ,

    z⁺ the enriched dual: the error pairs the residual with the dual's own enriched error, not with z⁺,
    so the CG may stop earlier for the same accuracy (RTOL). At convergence ρ = 0 and the correction
    vanishes. → (d_theta, d_eps)."""
    c = np.asarray(duals).T @ res_h
    return d_theta + float(c[0]), np.asarray(d_eps) + c[1:]


def goal_errors(design, mesh, sol, release: bool = False) -> dict | None:
    """J(u⁺) − J(u_h) of the goals of one level (flexure.goals.GoalSolution ``sol``, its system and
    prepared solver still held): the hub rotation θ and each gauge → {"theta", "gauges" (g,), "info",
    "weight"}: ``weight`` the surplus part e_W of the enriched error as element coefficients (edges
    (m,6,3), faces (m,4,3)), the DWR weight w ≈ u − I_h u (flexure.dwr, for the marking). None where
    the enriched solve is not set up (the distributed coupling: its traction on W).

    ``release``: the caller needs neither ``sol.solver`` nor ``sol.system`` again (an adaptive level):
    both are dropped (set None) before the enriched system is assembled, where the P2 smoother's blocks
    give the CG's A x (``p2_blocks``), and the allocator's free pages returned (flexure.rss): the scalar
    CSR of A (12 bytes an entry, the level's largest P2 array), the rigid modes and the coarse
    interpolation are not read by the enriched solve. The same arithmetic, the same bits."""
    if design.coupling != "rigid" or sol.system is None:
        return None
    system = sol.system
    precond = getattr(sol.solver, "precond", None)
    if precond is None:
        dinv = 1.0 / system.A.diagonal()
        precond = lambda R: R * dinv[:, None]  # noqa: E731
    theta_index = system.ref_slices[0].start + 5
    rh = p2_residual(system, sol.q[:, 0], theta_index)
    if release and p2_blocks(precond) is not None:
        import dataclasses

        from flexure import rss

        sol.solver = sol.system = None
        system = dataclasses.replace(system, A=None, B=None, coarse=None, B_coarse=None)
        rss.now_gb(trim=True)
    d_eps, d_theta, info = enriched_solve(system, mesh, design.material, design.gauges, sol.U[:, :, 0],
                                          sol.q[:, 0], sol.constrained, precond, theta_index=theta_index,
                                          duals=sol.q, residual_h=rh, max_iter=LEVEL_MAX_ITER)
    coef = info.pop("coef")
    return {"theta": d_theta, "gauges": np.asarray(d_eps), "info": info,
            "weight": (coef[:, :6], coef[:, 6:])}
