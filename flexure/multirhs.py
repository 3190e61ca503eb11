"""Several load cases at once: CG on k right-hand sides together, with a smoother that reads the
matrix once for all k columns (numba loops, compiled on first use and cached).

The P2 systems of a design (six unit wrenches) share the matrix: a sparse product or a
Gauss–Seidel sweep is bound by reading the matrix, so doing the k columns in the same pass costs
little more than one. Same arithmetic per column as one CG on one column:

    α_j = (r_j·z_j)/(p_j·A p_j),  x_j += α_j p_j,  r_j −= α_j A p_j,  z = M r,
    β_j = (r_j·z_j)_new/(r_j·z_j)_old,  p_j = z_j + β_j p_j,   until ‖r_j‖ ≤ rtol ‖b_j‖.

Block Gauss–Seidel on 3×3 nodal blocks (D_i⁻¹ given): x_i ← x_i + D_i⁻¹ (b_i − Σ_j A_ij x_j),
rows in increasing (forward) or decreasing (backward) order, each block row for all k columns.
"""

from __future__ import annotations

import numpy as np

#: column group width: the loops are generated for k = 1 … KMAX columns (scalar accumulators that
#: stay in registers); wider blocks are done in groups.
KMAX = 6


def available() -> bool:
    """True when numba is there to compile the loops (else callers use their one-column path)."""
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def warm() -> bool:
    """Compile (and cache) the loops for 1 … KMAX columns on a tiny matrix, so that the first
    design analysis does not pay numba's compile time; False without numba."""
    if not available():
        return False
    import scipy.sparse as sp

    from flexure.block_sparse import BlockMatrix

    A = sp.identity(6, format="csr") * 2.0
    Dinv = np.tile(np.eye(3) / 2.0, (2, 1, 1))
    for k in range(1, KMAX + 1):
        spmm(A, np.zeros((6, k)))
        for order in "CF":                # pcg's X is C-ordered, a caller's may be Fortran-ordered
            block_gauss_seidel(A, Dinv, np.zeros((6, k), order=order), np.ones((6, k)), True)
        forward_gauss_seidel_residual(A, Dinv, np.ones((6, k)))
        for dtype in (np.float32, np.float64):          # the block smoother (flexure.solve SMOOTHER_STORAGE)
            Ab = BlockMatrix.from_csr(A, dtype)
            block_gauss_seidel_bsr(Ab, Dinv, np.zeros((6, k)), np.ones((6, k)), True)
            forward_gauss_seidel_residual_bsr(Ab, Dinv, np.ones((6, k)))
    for bs in (3, 6):                     # flexure.vcycle's coarse levels
        block_gauss_seidel_blocks(A, np.tile(np.eye(bs) / 2.0, (6 // bs, 1, 1)), np.zeros((6, 2)), np.ones((6, 2)), True)
    return True


def _spmm_src(k: int) -> str:
    c = range(k)
    return "\n".join([
        "def spmm(indptr, indices, data, X, Y):",
        "    for i in numba.prange(Y.shape[0]):",
        "        " + "; ".join(f"a{j} = 0.0" for j in c),
        "        for p in range(indptr[i], indptr[i + 1]):",
        "            v = data[p]; j = indices[p]",
        *[f"            a{j} += v * X[j, {j}]" for j in c],
        *[f"        Y[i, {j}] = a{j}" for j in c]])


def _gs_src(k: int) -> str:
    c = range(k)
    rows = []
    for a in range(3):
        rows += ["        r = 3 * i + %d" % a,
                 "        " + "; ".join(f"s{a}_{j} = B[r, {j}]" for j in c),
                 "        for p in range(indptr[r], indptr[r + 1]):",
                 "            v = data[p]; j = indices[p]",
                 *[f"            s{a}_{j} -= v * X[j, {j}]" for j in c]]
    upd = [f"        X[3 * i + {a}, {j}] += Dinv[i, {a}, 0] * s0_{j} + Dinv[i, {a}, 1] * s1_{j} + "
           f"Dinv[i, {a}, 2] * s2_{j}" for a in range(3) for j in c]
    return "\n".join(["def block_gs(indptr, indices, data, Dinv, X, B, forward):",
                      "    nb = Dinv.shape[0]",
                      "    for t in range(nb):",
                      "        i = t if forward else nb - 1 - t", *rows, *upd])


def _gs0_src(k: int) -> str:
    """Forward block Gauss–Seidel from X = 0 and the residual R = B − A X in one pass over the lower
    triangle (A symmetric, CSR indices sorted; R zero on entry): in block row i the entries right of
    the diagonal block meet X = 0 and are skipped; once x_i is known, the residual rows j < i take
    −A_ji x_i = −A_ij x_i (the rows j ≥ i have b − A x = 0 when they are solved, later x_i add)."""
    c = range(k)
    rows = []
    for a in range(3):
        rows += ["        r = 3 * i + %d" % a,
                 "        " + "; ".join(f"s{a}_{j} = B[r, {j}]" for j in c),
                 "        for p in range(indptr[r], indptr[r + 1]):",
                 "            j = indices[p]",
                 "            if j >= lo:",
                 "                break",
                 "            v = data[p]",
                 *[f"            s{a}_{j} -= v * X[j, {j}]" for j in c]]
    upd = [f"        x{a}_{j} = Dinv[i, {a}, 0] * s0_{j} + Dinv[i, {a}, 1] * s1_{j} + Dinv[i, {a}, 2] * s2_{j}"
           for a in range(3) for j in c]
    upd += [f"        X[3 * i + {a}, {j}] = x{a}_{j}" for a in range(3) for j in c]
    scatter = []
    for a in range(3):
        scatter += ["        r = 3 * i + %d" % a,
                    "        for p in range(indptr[r], indptr[r + 1]):",
                    "            j = indices[p]",
                    "            if j >= lo:",
                    "                break",
                    "            v = data[p]",
                    *[f"            R[j, {j}] -= v * x{a}_{j}" for j in c]]
    return "\n".join(["def gs0_res(indptr, indices, data, Dinv, X, B, R):",
                      "    for i in range(Dinv.shape[0]):",
                      "        lo = 3 * i", *rows, *upd, *scatter])


def _bvals(indent: str) -> list:
    """The block's nine values as float64 (v00 … v22) and its column c."""
    return [indent + "c = 3 * np.int64(bcol[p])",
            *[indent + "; ".join(f"v{a}{b} = np.float64(data[p, {a}, {b}])" for b in range(3)) for a in range(3)]]


def _block_times_x(c) -> list:
    """s_j −= A_block x_c for each column j in ``c`` (the block's values v, its column c: ``_bvals``)."""
    out = []
    for j in c:
        out += [f"            x0 = X[c, {j}]; x1 = X[c + 1, {j}]; x2 = X[c + 2, {j}]",
                *[f"            s{a}_{j} -= v{a}0 * x0 + v{a}1 * x1 + v{a}2 * x2" for a in range(3)]]
    return out


def _bgs_src(k: int) -> str:
    """``_gs_src`` on 3 × 3 block storage (flexure.block_sparse: bptr, bcol, values (n_blocks, 3, 3)
    of any float type, summed in float64): one pass over a block row reads each block once."""
    c = range(k)
    body = ["    nb = Dinv.shape[0]",
            "    for t in range(nb):",
            "        i = t if forward else nb - 1 - t",
            *["        " + "; ".join(f"s{a}_{j} = B[3 * i + {a}, {j}]" for j in c) for a in range(3)],
            "        for p in range(bptr[i], bptr[i + 1]):", *_bvals("            ")]
    body += _block_times_x(c)
    body += [f"        X[3 * i + {a}, {j}] += Dinv[i, {a}, 0] * s0_{j} + Dinv[i, {a}, 1] * s1_{j} + Dinv[i, {a}, 2] * s2_{j}"
             for a in range(3) for j in c]
    return "\n".join(["def bgs(bptr, bcol, data, Dinv, X, B, forward):", *body])


def _bgs0_src(k: int) -> str:
    """``_gs0_src`` on 3 × 3 block storage: the forward sweep from X = 0 over the blocks left of the
    diagonal, then each of them scatters Aᵢⱼᵀ xᵢ into the residual of block row j < i (A symmetric)."""
    c = range(k)
    body = ["    for i in range(Dinv.shape[0]):",
            *["        " + "; ".join(f"s{a}_{j} = B[3 * i + {a}, {j}]" for j in c) for a in range(3)],
            "        pend = bptr[i]",
            "        for p in range(bptr[i], bptr[i + 1]):",
            "            if bcol[p] >= i:",
            "                break",
            "            pend = p + 1", *_bvals("            ")]
    body += _block_times_x(c)
    body += [f"        x{a}_{j} = Dinv[i, {a}, 0] * s0_{j} + Dinv[i, {a}, 1] * s1_{j} + Dinv[i, {a}, 2] * s2_{j}"
             for a in range(3) for j in c]
    body += [f"        X[3 * i + {a}, {j}] = x{a}_{j}" for a in range(3) for j in c]
    body += ["        for p in range(bptr[i], pend):", *_bvals("            ")]
    for j in c:
        body += [f"            R[c + {b}, {j}] -= v0{b} * x0_{j} + v1{b} * x1_{j} + v2{b} * x2_{j}" for b in range(3)]
    return "\n".join(["def bgs0(bptr, bcol, data, Dinv, X, B, R):", *body])


#: block Gauss–Seidel for any block size b (D⁻¹ (n/b, b, b)) and any k columns (runtime loops):
#: the coarse AMG levels (b = 3 on the P1 vertex system, 6 below: the six rigid-body modes)
_GS_ANY_SRC = """def block_gs_any(indptr, indices, data, Dinv, X, B, forward):
    nb = Dinv.shape[0]
    bs = Dinv.shape[1]
    k = X.shape[1]
    s = np.empty((bs, k))
    for t in range(nb):
        i = t if forward else nb - 1 - t
        for a in range(bs):
            r = bs * i + a
            for c in range(k):
                s[a, c] = B[r, c]
            for p in range(indptr[r], indptr[r + 1]):
                v = data[p]
                j = indices[p]
                for c in range(k):
                    s[a, c] -= v * X[j, c]
        for a in range(bs):
            for c in range(k):
                acc = 0.0
                for b in range(bs):
                    acc += Dinv[i, a, b] * s[b, c]
                X[bs * i + a, c] += acc"""


def _kernel(name: str, k: int):
    """The numba loop ``name`` ("spmm" or "block_gs") for exactly k ≤ KMAX columns
    (flexure._multirhs_loops / _multirhs_fused, generated from the sources above by ``python -m flexure.multirhs``;
    numba caches the compiled code)."""
    from flexure import _multirhs_fused, _multirhs_loops

    from flexure import _multirhs_blocks

    mod = {"gs0_res": _multirhs_fused, "bgs": _multirhs_blocks, "bgs0": _multirhs_blocks}.get(name, _multirhs_loops)
    return getattr(mod, f"{name}_{k}")


def _groups(k: int):
    return [slice(s, min(k, s + KMAX)) for s in range(0, k, KMAX)]


#: rows a thread takes at a time in A X (dynamic hand-out: flexure.threads.dynamic)
ROW_CHUNK = 2048


def spmm(A, X: np.ndarray) -> np.ndarray:
    """A X for CSR A and X (n, k), the rows among flexure.threads' threads (each row summed in
    order: the same bits for every thread count)."""
    from flexure import threads

    Y = np.empty((A.shape[0], X.shape[1]))
    threads.use()
    with threads.dynamic(ROW_CHUNK):
        for g in _groups(X.shape[1]):
            Yg = Y if g.stop - g.start == X.shape[1] else np.empty((A.shape[0], g.stop - g.start))
            _kernel("spmm", g.stop - g.start)(A.indptr, A.indices, A.data, np.ascontiguousarray(X[:, g]), Yg)
            if Yg is not Y:
                Y[:, g] = Yg
    return Y


def block_gauss_seidel(A, Dinv: np.ndarray, X: np.ndarray, B: np.ndarray, forward: bool) -> None:
    """One block Gauss–Seidel sweep in place on X (n, k) for A X = B (CSR A, Dinv (n/3, 3, 3))."""
    _sweep("block_gs", (A.indptr, A.indices, A.data), Dinv, X, B, forward)


def forward_gauss_seidel_residual(A, Dinv: np.ndarray, B: np.ndarray):
    """(X, R): one forward block Gauss–Seidel sweep from X = 0 on A X = B and R = B − A X, in one
    pass over the lower triangle of the symmetric CSR A (sorted indices), for B (n, k)."""
    return _sweep_residual("gs0_res", (A.indptr, A.indices, A.data), Dinv, B)


def block_gauss_seidel_bsr(Ab, Dinv: np.ndarray, X: np.ndarray, B: np.ndarray, forward: bool) -> None:
    """``block_gauss_seidel`` on a flexure.block_sparse.BlockMatrix ``Ab`` (3 × 3 blocks, any value
    type, sums in float64)."""
    _sweep("bgs", (Ab.bptr, Ab.bcol, Ab.data), Dinv, X, B, forward)


def forward_gauss_seidel_residual_bsr(Ab, Dinv: np.ndarray, B: np.ndarray):
    """``forward_gauss_seidel_residual`` on a flexure.block_sparse.BlockMatrix ``Ab`` (symmetric,
    block columns ascending)."""
    return _sweep_residual("bgs0", (Ab.bptr, Ab.bcol, Ab.data), Dinv, B)


def _sweep(kernel: str, matrix: tuple, Dinv: np.ndarray, X: np.ndarray, B: np.ndarray, forward: bool) -> None:
    """The sweep ``kernel`` in place on X (n, k) over ``matrix`` (its index and value arrays), in
    groups of at most KMAX columns."""
    for g in _groups(X.shape[1]):
        if g.start == 0 and g.stop == X.shape[1]:
            _kernel(kernel, X.shape[1])(*matrix, Dinv, X, np.ascontiguousarray(B), forward)
        else:
            Xg = np.ascontiguousarray(X[:, g])
            _kernel(kernel, g.stop - g.start)(*matrix, Dinv, Xg, np.ascontiguousarray(B[:, g]), forward)
            X[:, g] = Xg


def _sweep_residual(kernel: str, matrix: tuple, Dinv: np.ndarray, B: np.ndarray):
    """(X, R) of the first sweep ``kernel`` from X = 0 and its residual, in groups of KMAX columns."""
    B = np.ascontiguousarray(B)
    X = np.empty_like(B)
    R = np.zeros_like(B)
    for g in _groups(B.shape[1]):
        if g.start == 0 and g.stop == B.shape[1]:
            _kernel(kernel, B.shape[1])(*matrix, Dinv, X, B, R)
        else:
            Xg, Rg = np.empty((B.shape[0], g.stop - g.start)), np.zeros((B.shape[0], g.stop - g.start))
            _kernel(kernel, g.stop - g.start)(*matrix, Dinv, Xg, np.ascontiguousarray(B[:, g]), Rg)
            X[:, g], R[:, g] = Xg, Rg
    return X, R


def block_gauss_seidel_blocks(A, Dinv: np.ndarray, X: np.ndarray, B: np.ndarray, forward: bool) -> None:
    """One block Gauss–Seidel sweep in place on X (n, k), C-ordered, for A X = B with b × b nodal
    blocks (CSR A, Dinv (n/b, b, b)): the coarse levels of an AMG hierarchy, any b and k."""
    from flexure import _multirhs_fused

    _multirhs_fused.block_gs_any(A.indptr, A.indices, A.data, Dinv, X, np.ascontiguousarray(B), forward)


def pcg(A, B: np.ndarray, M, rtol: float, maxiter: int, X0: np.ndarray | None = None, goal_stop=None):
    """CG on the columns of B (n, k) together, preconditioner M(R) → Z for R (n, m) (the active
    columns), from the initial guess X0 (n, k) (zero by default; a coarser level's solution
    prolongated saves iterations). Stops each column at ‖b_j − A x_j‖ ≤ rtol_j ‖b_j‖ (``rtol`` one
    number or one per column), or where ``goal_stop(X, R, rz, act)`` → bool (len(act),) says the
    active columns ``act`` may stop (X the iterates (n, k), R their residuals, rz = diag(Rᵀ M R):
    a goal-oriented test, flexure.goals). Returns X (n, k), iterations per column, and whether each
    column stopped (by either test)."""
    n, k = B.shape
    X = np.zeros((n, k)) if X0 is None else np.array(X0, dtype=np.float64).reshape(n, k)
    its = np.zeros(k, dtype=np.int64)
    stop = np.sqrt(np.einsum("ij,ij->j", B, B)) * np.broadcast_to(np.asarray(rtol, float), (k,))
    R0 = B - spmm(A, X) if X0 is not None else B
    done = (stop == 0) | (np.sqrt(np.einsum("ij,ij->j", R0, R0)) <= stop)
    act = np.flatnonzero(~done)
    if not len(act):
        return X, its.tolist(), done
    R = R0[:, act].copy()
    del R0                                    # the vectors updated in place: fewer alive at the peak, same bits
    Z = M(R)
    P = Z.copy()
    rz = np.einsum("ij,ij->j", R, Z)
    for _ in range(maxiter):
        AP = spmm(A, P)
        alpha = rz / np.einsum("ij,ij->j", P, AP)
        X[:, act] += P * alpha
        AP *= alpha
        R -= AP                               # R − AP α
        del AP, Z
        its[act] += 1
        ok = np.sqrt(np.einsum("ij,ij->j", R, R)) <= stop[act]
        if ok.any():
            done[act[ok]] = True
            keep = ~ok
            act, R, P, rz = act[keep], R[:, keep], P[:, keep], rz[keep]
            if not len(act):
                break
        Z = M(R)
        rz_new = np.einsum("ij,ij->j", R, Z)
        if goal_stop is not None:
            ok = np.asarray(goal_stop(X, R, rz_new, act), bool)
            if ok.any():
                done[act[ok]] = True
                keep = ~ok
                act, R, P, Z, rz, rz_new = act[keep], R[:, keep], P[:, keep], Z[:, keep], rz[keep], rz_new[keep]
                if not len(act):
                    break
        P *= rz_new / rz
        P += Z                                # Z + P β
        rz = rz_new
    return X, its.tolist(), done


#: the generated files: the loops of the sweeps and products, and of the fused first sweep and the
#: coarse levels (two files, each under the project's module-size limit)
GENERATED = {"_multirhs_loops.py": ("spmm", "block_gs"), "_multirhs_fused.py": ("gs0_res",),
             "_multirhs_blocks.py": ("bgs", "bgs0")}


def _generate(filename: str = "_multirhs_loops.py") -> str:
    """Source of flexure/<filename> (one of GENERATED)."""
    srcs = {"spmm": _spmm_src, "block_gs": _gs_src, "gs0_res": _gs0_src, "bgs": _bgs_src, "bgs0": _bgs0_src}
    out = ['"""Generated by ``python -m flexure.multirhs`` (do not edit): the loops of flexure.multirhs for',
           'k = 1 … 6 columns, one function per k so that the k accumulators stay in registers; compiled by',
           'numba on first use and cached beside this file."""', '', 'import numba']
    out += ['import numpy as np', ''] if filename != "_multirhs_loops.py" else ['']
    if filename == "_multirhs_loops.py":           # spmm's rows are split among threads (numba prange)
        out += ["from flexure import threads", "", "threads.select_layer()                 # before any parallel loop runs (flexure.threads: fork safety)", ""]
    for k in range(1, KMAX + 1):
        for name in GENERATED[filename]:
            jit = "@numba.njit(cache=True, nogil=True, parallel=True)" if name == "spmm" else "@numba.njit(cache=True, nogil=True)"
            out += ["", jit, srcs[name](k).replace(f"def {name}(", f"def {name}_{k}(", 1), ""]
    if filename == "_multirhs_fused.py":
        out += ["", "@numba.njit(cache=True, nogil=True)", _GS_ANY_SRC, ""]
    return "\n".join(out).rstrip() + "\n"


if __name__ == "__main__":
    from pathlib import Path

    for name in GENERATED:
        Path(__file__).with_name(name).write_text(_generate(name))
