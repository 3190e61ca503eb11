"""The compiled row loops of flexure.reduce, and the 3×3 diagonal blocks of flexure.solve (numba,
compiled on first use and cached)."""

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def count(indptr, indices, fdofs, fmap, gk, m, cnt, tcnt):
    """cnt[r]: entries of A's free row r (its free columns, 6 per coupling it touches), tcnt[r]:
    the couplings it touches; → the number of (row, coupling) touches."""
    seen = np.zeros(m, np.bool_)
    touches = 0
    for r in range(len(fdofs)):
        i = fdofs[r]
        c = 0
        tc = 0
        seen[:] = False
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            if fmap[j] >= 0:
                c += 1
            elif not seen[gk[j]]:
                seen[gk[j]] = True
                c += 6
                tc += 1
        cnt[r] = c
        tcnt[r] = tc
        touches += tc
    return touches


@numba.njit(cache=True, nogil=True, parallel=True)
def fill(indptr, indices, data, fdofs, fmap, gk, gslot, G, m, nf, optr, oind, odat, toff, trow, tk, tval, nchunk):
    """A's free rows: K_ff entries renumbered, then (K_fc G) in the 6 columns of each coupling
    touched; each touch also to (trow, tk, tval (touches, 6)) from toff[r] on, for the reference rows
    (its transpose). Rows in ``nchunk`` chunks over the threads (each row's output has its place)."""
    n = len(fdofs)
    for ch in numba.prange(nchunk):
        _fill_rows(indptr, indices, data, fdofs, fmap, gk, gslot, G, m, nf, optr, oind, odat, toff, trow, tk, tval,
                   ch * n // nchunk, (ch + 1) * n // nchunk)


@numba.njit(cache=True, nogil=True)
def _fill_rows(indptr, indices, data, fdofs, fmap, gk, gslot, G, m, nf, optr, oind, odat, toff, trow, tk, tval, r0, r1):
    acc = np.zeros(6 * m)
    seen = np.zeros(m, np.bool_)
    for r in range(r0, r1):
        i = fdofs[r]
        o = optr[r]
        t = toff[r]
        seen[:] = False
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            if fmap[j] >= 0:
                oind[o] = fmap[j]
                odat[o] = data[p]
                o += 1
            else:
                k = gk[j]
                if not seen[k]:
                    seen[k] = True
                    for c in range(6):
                        acc[6 * k + c] = 0.0
                v = data[p]
                s = gslot[j]
                for c in range(6):
                    acc[6 * k + c] += v * G[s, c]
        for k in range(m):
            if seen[k]:
                trow[t] = r
                tk[t] = k
                for c in range(6):
                    oind[o] = nf + 6 * k + c
                    odat[o] = acc[6 * k + c]
                    tval[t, c] = acc[6 * k + c]
                    o += 1
                t += 1


@numba.njit(cache=True, nogil=True)
def diagonal_blocks(indptr, indices, data, D):
    """D[i] = the 3×3 diagonal block A[3i:3i+3, 3i:3i+3] of a CSR matrix (flexure.solve's
    block-diagonal inverse); zero where A has no entry."""
    for i in range(D.shape[0]):
        for a in range(3):
            r = 3 * i + a
            for p in range(indptr[r], indptr[r + 1]):
                j = indices[p] - 3 * i
                if 0 <= j < 3:
                    D[i, a, j] += data[p]
