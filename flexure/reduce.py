"""The kinematically reduced stiffness A = Tᵀ K T without scipy's sparse products (flexure.bc).

T maps q = (free dofs f, then 6 reference dofs (U, Θ) per kinematic coupling) to u: the identity on
f, and u_c = G q_r on the coupled dofs c (G's rows: u_i = U − [d_i]× Θ). With K symmetric,

    A = [ K_ff        K_fc G     ]
        [ Gᵀ K_cf     Gᵀ K_cc G  ].

K_ff is K's rows and columns f (a row copy with renumbered columns: f is ordered, so each row stays
sorted); K_fc G is accumulated per free row into its 6 columns of each coupling it touches (one
compiled pass over K's rows, ``_reduce_rows``); the reference rows are its transpose and the small
Gᵀ K_cc G. The result is CSR with sorted indices, equal to (Tᵀ K T) to round-off (the sums of
K_fc G in another order).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def reduced_stiffness(K, coupled_dofs: np.ndarray, coupling_of: np.ndarray, G: np.ndarray,
                      n_couplings: int) -> sp.csr_matrix:
    """A = Tᵀ K T (CSR, sorted indices) for symmetric K (3n × 3n); ``coupled_dofs`` (increasing),
    their coupling ``coupling_of`` and G's rows (len(coupled_dofs), 6): u_c = G q_r of their coupling
    (see the module doc). The free dofs are the rest, in increasing order."""
    K = sp.csr_matrix(K)
    if not K.has_sorted_indices:
        K = K.sorted_indices()
    n = K.shape[0]
    m = int(n_couplings)
    fmap = np.zeros(n, np.int64)
    fmap[coupled_dofs] = -1
    free = fmap == 0
    fdofs = np.flatnonzero(free)
    nf = len(fdofs)
    fmap[fdofs] = np.arange(nf)
    gk = np.full(n, -1, np.int64)
    gk[coupled_dofs] = coupling_of
    gslot = np.full(n, -1, np.int64)
    gslot[coupled_dofs] = np.arange(len(coupled_dofs))
    from flexure._reduce_kernels import count, fill

    cnt = np.empty(nf, np.int64)
    indptr = K.indptr.astype(np.int64, copy=False)
    count(indptr, K.indices, fdofs, fmap, gk, m, cnt)
    optr = np.zeros(nf + 1, np.int64)
    np.cumsum(cnt, out=optr[1:])
    nnz_f = int(optr[-1])
    oind = np.empty(nnz_f, np.int64)
    odat = np.empty(nnz_f)
    fill(indptr, K.indices, K.data, fdofs, fmap, gk, gslot, np.ascontiguousarray(G, float), m, nf,
         optr, oind, odat)
    # reference rows: (K_fc G)ᵀ from the free rows' reference columns, then Gᵀ K_cc G (dense 6m)
    is_ref = oind >= nf
    rrow = oind[is_ref] - nf
    rcol = np.repeat(np.arange(nf), cnt)[is_ref]
    rval = odat[is_ref]
    order = np.lexsort((rcol, rrow))
    rrow, rcol, rval = rrow[order], rcol[order], rval[order]
    Gs = sp.csr_matrix((G.ravel(), (np.repeat(np.arange(len(coupled_dofs)), 6),
                                    6 * np.repeat(coupling_of, 6) + np.tile(np.arange(6), len(coupled_dofs)))),
                       shape=(len(coupled_dofs), 6 * m))
    Kcc = K[coupled_dofs][:, coupled_dofs]
    Arr = np.asarray((Gs.T @ (Kcc @ Gs)).todense())
    nr = 6 * m
    rcnt = np.bincount(rrow, minlength=nr) + nr
    indptr_out = np.concatenate([optr, nnz_f + np.cumsum(rcnt)])
    ind_r = np.empty(int(rcnt.sum()), np.int64)
    dat_r = np.empty(int(rcnt.sum()))
    start = np.concatenate([[0], np.cumsum(rcnt)])
    first = np.concatenate([[0], np.cumsum(np.bincount(rrow, minlength=nr))])
    for s in range(nr):
        a, b = first[s], first[s + 1]
        o = start[s]
        ind_r[o:o + b - a] = rcol[a:b]
        dat_r[o:o + b - a] = rval[a:b]
        ind_r[o + b - a:start[s + 1]] = nf + np.arange(nr)
        dat_r[o + b - a:start[s + 1]] = Arr[s]
    nq = nf + nr
    idx_dtype = np.int32 if max(nq, indptr_out[-1]) < 2**31 else np.int64
    A = sp.csr_matrix((np.concatenate([odat, dat_r]), np.concatenate([oind, ind_r]).astype(idx_dtype),
                       indptr_out.astype(idx_dtype)), shape=(nq, nq))
    A.has_sorted_indices = True
    return A
