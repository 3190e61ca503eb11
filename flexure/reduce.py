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
    from flexure import threads
    from flexure._reduce_kernels import count, fill

    cnt = np.empty(nf, np.int64)
    indptr = K.indptr.astype(np.int64, copy=False)
    tcnt = np.empty(nf, np.int64)
    touches = count(indptr, K.indices, fdofs, fmap, gk, m, cnt, tcnt)
    toff = np.zeros(nf + 1, np.int64)
    np.cumsum(tcnt, out=toff[1:])
    nr = 6 * m
    nq = nf + nr
    nnz_f = int(cnt.sum())
    nnz = nnz_f + 6 * touches + nr * nr
    idx = np.int32 if max(nq, nnz) < 2**31 else np.int64
    indptr_out = np.empty(nq + 1, np.int64)
    indptr_out[0] = 0
    np.cumsum(cnt, out=indptr_out[1:nf + 1])
    oind = np.empty(nnz, idx)
    odat = np.empty(nnz)
    trow, tk, tval = np.empty(touches, np.int64), np.empty(touches, np.int64), np.empty((touches, 6))
    nt = threads.use()
    with threads.dynamic():
        fill(indptr, K.indices, K.data, fdofs, fmap, gk, gslot, np.ascontiguousarray(G, float), m, nf,
             indptr_out, oind, odat, toff, trow, tk, tval, 1 if nt == 1 else 8 * nt)
    # reference rows: (K_fc G)ᵀ (the touches, rows increasing), then Gᵀ K_cc G (dense 6m)
    Gs = sp.csr_matrix((G.ravel(), (np.repeat(np.arange(len(coupled_dofs)), 6),
                                    6 * np.repeat(coupling_of, 6) + np.tile(np.arange(6), len(coupled_dofs)))),
                       shape=(len(coupled_dofs), 6 * m))
    Kcc = K[coupled_dofs][:, coupled_dofs]
    Arr = np.asarray((Gs.T @ (Kcc @ Gs)).todense())
    o = nnz_f
    for k in range(m):
        sel = np.flatnonzero(tk == k)
        for c in range(6):
            s = 6 * k + c
            oind[o:o + len(sel)] = trow[sel]
            odat[o:o + len(sel)] = tval[sel, c]
            o += len(sel)
            oind[o:o + nr] = nf + np.arange(nr)
            odat[o:o + nr] = Arr[s]
            o += nr
            indptr_out[nf + s + 1] = o
    indptr_out = indptr_out.astype(idx, copy=False)
    A = sp.csr_matrix((odat, oind, indptr_out), shape=(nq, nq), copy=False)
    A.has_sorted_indices = True
    return A
