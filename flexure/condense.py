"""A = Tᵀ K T for the kinematic (rigid) couplings of flexure.bc, without sparse matrix products.

T maps the reduced unknowns q to the nodal dofs u = T q: a free dof is one column of q (T's row a
unit entry), a coupled node's dof c follows its coupling's reference dofs (U, Θ) as
u_c = U_c − ([d]× Θ)_c (T's row: up to 6 entries in the coupling's 6 columns, R_c). So, with F the
free dofs, 𝒞_k the dofs coupled to coupling k and R_j the row of T of dof j,

    A[F_i, F_j] = K_ij,     A[F_i, k·] = Σ_{j ∈ 𝒞_k} K_ij R_j,     A[k·, l·] = Σ_{i ∈ 𝒞_k, j ∈ 𝒞_l} R_iᵀ K_ij R_j,

and A[k·, F] the transpose of A[F, k·] (K symmetric). The free-free block keeps K's rows in order with
its columns renumbered monotonically (sorted rows stay sorted), the coupling columns come after every free
column: one pass over K in compiled loops builds A's CSR arrays directly. scipy's (Tᵀ K) T took 2.7 s of
matrix products at 938 k dofs against 0.4 s here (benchmarks/bench_fem_goal_solve.py); the numpy product is
the reference the tests compare it with.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp


def maps_from_T(T: sp.csr_matrix, n_free_cols: int):
    """From T (CSR, 3n × n_q): new (3n,) the reduced column of a free dof (−1 for a coupled one),
    base (3n,) the first column of a coupled dof's coupling (−1 for a free one), R (3n, 6) its row
    of T in the coupling's 6 columns."""
    T = T.tocsr()
    rows = np.repeat(np.arange(T.shape[0]), np.diff(T.indptr))
    cols, vals = T.indices.astype(np.int64), T.data
    new = np.full(T.shape[0], -1, np.int64)
    base = np.full(T.shape[0], -1, np.int64)
    R = np.zeros((T.shape[0], 6))
    f = cols < n_free_cols
    new[rows[f]] = cols[f]
    c = ~f
    b = n_free_cols + 6 * ((cols[c] - n_free_cols) // 6)
    base[rows[c]] = b
    R[rows[c], cols[c] - b] = vals[c]
    return new, base, R


@numba.njit(cache=True, nogil=True)
def _free_rows(indptr, indices, data, new, base, R, n_free, n_coup, out_ptr, out_idx, out_val, count_only):
    """Rows of A for the free dofs (module docstring); ``count_only``: only out_ptr's counts."""
    acc = np.zeros((n_coup, 6))
    hit = np.zeros(n_coup, np.bool_)
    for i in range(len(new)):
        r = new[i]
        if r < 0:
            continue
        pos = out_ptr[r]
        nfree = 0
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            nj = new[j]
            if nj >= 0:
                if not count_only:
                    out_idx[pos + nfree] = nj
                    out_val[pos + nfree] = data[p]
                nfree += 1
            else:
                k = (base[j] - n_free) // 6
                hit[k] = True
                if not count_only:
                    for m in range(6):
                        acc[k, m] += data[p] * R[j, m]
        extra = 0
        for k in range(n_coup):
            if hit[k]:
                if not count_only:
                    for m in range(6):
                        out_idx[pos + nfree + extra + m] = n_free + 6 * k + m
                        out_val[pos + nfree + extra + m] = acc[k, m]
                        acc[k, m] = 0.0
                extra += 6
                hit[k] = False
        if count_only:
            out_ptr[r + 1] = nfree + extra


def tkt(K: sp.csr_matrix, T: sp.csr_matrix, n_free: int) -> sp.csr_matrix:
    """A = Tᵀ K T (CSR, sorted indices) for K symmetric (3n × 3n CSR) and T of the kinematic
    couplings whose first ``n_free`` columns are the free dofs (module docstring)."""
    K = K.tocsr()
    if not K.has_sorted_indices:
        K = K.sorted_indices()
    n_q = T.shape[1]
    new, base, R = maps_from_T(T, n_free)
    n_coup = (n_q - n_free) // 6
    ptr = np.zeros(n_q + 1, np.int64)
    dummy_i, dummy_v = np.zeros(0, np.int64), np.zeros(0)
    _free_rows(K.indptr, K.indices, K.data, new, base, R, n_free, n_coup, ptr, dummy_i, dummy_v, True)
    # the coupling rows: the transposes of the free rows' coupling entries, then the dense k×l blocks
    cpl = np.flatnonzero(new < 0)
    Kc = K[cpl]                                                   # the coupled dofs' rows (few)
    kr = np.repeat(cpl, np.diff(Kc.indptr))
    kj = Kc.indices.astype(np.int64)
    kv = Kc.data
    # A[k·, F]: Σ_{i ∈ 𝒞_k} R_i K_ij for free j; A[k·, l·]: Σ R_iᵀ K_ij R_j
    fr = new[kj] >= 0
    kk = (base[kr] - n_free) // 6
    rowsF = (n_free + 6 * kk[fr, None] + np.arange(6)).ravel()
    colsF = np.repeat(new[kj[fr]], 6)
    valsF = (R[kr[fr]] * kv[fr, None]).ravel()
    cc = ~fr
    ll = (base[kj[cc]] - n_free) // 6
    blk = np.einsum("em,e,en->emn", R[kr[cc]], kv[cc], R[kj[cc]])
    rowsC = np.broadcast_to((n_free + 6 * kk[cc, None, None] + np.arange(6)[None, :, None]), blk.shape).ravel()
    colsC = np.broadcast_to((n_free + 6 * ll[:, None, None] + np.arange(6)[None, None, :]), blk.shape).ravel()
    Ck = sp.csr_matrix((np.r_[valsF, blk.ravel()], (np.r_[rowsF, rowsC] - n_free, np.r_[colsF, colsC])),
                       shape=(n_q - n_free, n_q))
    Ck.sum_duplicates()
    ptr[n_free + 1:] = np.diff(Ck.indptr)
    np.cumsum(ptr, out=ptr)
    nnz = int(ptr[-1])
    idx = np.empty(nnz, np.int64)
    val = np.empty(nnz)
    _free_rows(K.indptr, K.indices, K.data, new, base, R, n_free, n_coup, ptr, idx, val, False)
    s = ptr[n_free]
    idx[s:] = Ck.indices
    val[s:] = Ck.data
    itype = np.int32 if max(nnz, n_q) < 2 ** 31 - 1 else np.int64
    A = sp.csr_matrix((val, idx.astype(itype), ptr.astype(itype)), shape=(n_q, n_q))
    A.has_sorted_indices = True
    return A

