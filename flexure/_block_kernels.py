"""The compiled loops of flexure.block_sparse (numba, compiled on first use and cached beside this
file): the enriched element loop of flexure._enriched_kernels adding into 3 × 3 block-sparse (BSR)
arrays of any float type (one column index per block, not per entry), and the block products
y = A x, y = Aᵀ x (each entry accumulated in float64 whatever the stored type)."""

import numba
import numpy as np

from flexure import threads
from flexure._enriched_kernels import _element

threads.select_layer()                 # before any parallel loop runs (flexure.threads: fork safety)


@numba.njit(cache=True, nogil=True)
def _scatter(e, Gk, sign, AB, AC, rl, SK, kdata, SC, cdata, r, D):
    """Element e's blocks into the K_WW and coupling block data at their places SK, SC (m,10,10)
    (flexure._enriched_kernels.block_pattern_slots), r and D (flexure._enriched_kernels._scatter's order)."""
    for b in range(10):
        gb = Gk[e, b]
        if gb < 0:
            continue
        sb = sign[e, b]
        for i in range(3):
            r[3 * gb + i] += sb * rl[b, i]
        for c in range(10):
            if Gk[e, c] < 0:
                continue
            p = SK[e, b, c]
            s = sb * sign[e, c]
            for i in range(3):
                for j in range(3):
                    kdata[p, i, j] += s * AB[3 * b + i, 3 * c + j]
            if b == c:
                for i in range(3):
                    for j in range(3):
                        D[gb, i, j] += AB[3 * b + i, 3 * b + j]
    for a in range(10):
        for c in range(10):
            if Gk[e, c] >= 0:
                p = SC[e, a, c]
                s = sign[e, c]
                for i in range(3):
                    for j in range(3):
                        cdata[p, i, j] += s * AC[3 * a + i, 3 * c + j]


@numba.njit(cache=True, nogil=True, parallel=True)
def assemble(points, tets, u, rhs_face, Gk, sign, dN, dB, wq, lmb, mu,
             SK, kdata, SC, cdata, r, D, cptr, order, nchunk):
    """flexure._enriched_kernels.assemble into block data kdata, cdata (n_blocks, 3, 3) at the blocks'
    places SK, SC (flexure._enriched_kernels.block_pattern_slots): colour by colour, each colour's elements
    in ``nchunk`` ranges (results independent of the thread count)."""
    for col in range(len(cptr) - 1):
        lo, hi = cptr[col], cptr[col + 1]
        for t in numba.prange(nchunk):
            X = np.empty((10, 3))
            ue = np.empty((10, 3))
            J = np.empty((3, 3))
            Jinv = np.empty((3, 3))
            gN = np.empty((10, 3))
            gB = np.empty((10, 3))
            PB = np.empty((30, 32))
            PC = np.empty((30, 32))
            AB = np.empty((30, 30))
            AC = np.empty((30, 30))
            rl = np.empty((10, 3))
            sig = np.empty((3, 3))
            w = np.zeros(32)
            for k in range(lo + (hi - lo) * t // nchunk, lo + (hi - lo) * (t + 1) // nchunk):
                e = order[k]
                _element(e, points, tets, u, rhs_face, dN, dB, wq, lmb, mu, X, ue, J, Jinv, gN, gB,
                         PB, PC, AB, AC, rl, sig, w)
                _scatter(e, Gk, sign, AB, AC, rl, SK, kdata, SC, cdata, r, D)


@numba.njit(cache=True, nogil=True, parallel=True)
def matvec(bptr, bcol, data, x, y):
    """y_3r+i = Σ_p Σ_j data[p, i, j] x_3 bcol_p + j, p ∈ [bptr_r, bptr_r+1) (each row in order)."""
    for r in numba.prange(len(bptr) - 1):
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for p in range(bptr[r], bptr[r + 1]):
            c = 3 * np.int64(bcol[p])
            x0, x1, x2 = x[c], x[c + 1], x[c + 2]
            s0 += np.float64(data[p, 0, 0]) * x0 + np.float64(data[p, 0, 1]) * x1 + np.float64(data[p, 0, 2]) * x2
            s1 += np.float64(data[p, 1, 0]) * x0 + np.float64(data[p, 1, 1]) * x1 + np.float64(data[p, 1, 2]) * x2
            s2 += np.float64(data[p, 2, 0]) * x0 + np.float64(data[p, 2, 1]) * x1 + np.float64(data[p, 2, 2]) * x2
        y[3 * r] = s0
        y[3 * r + 1] = s1
        y[3 * r + 2] = s2


@numba.njit(cache=True, nogil=True, parallel=True)
def rmatvec(bptr, bcol, data, x, y, nchunk):
    """y = Aᵀ x (y zeroed here): the block rows in ``nchunk`` ranges, each into its own copy of y,
    summed chunk by chunk."""
    n = len(bptr) - 1
    m = len(y)
    part = np.zeros((nchunk, m))
    for t in numba.prange(nchunk):
        for r in range(n * t // nchunk, n * (t + 1) // nchunk):
            x0, x1, x2 = x[3 * r], x[3 * r + 1], x[3 * r + 2]
            for p in range(bptr[r], bptr[r + 1]):
                c = 3 * np.int64(bcol[p])
                for j in range(3):
                    part[t, c + j] += (np.float64(data[p, 0, j]) * x0 + np.float64(data[p, 1, j]) * x1
                                       + np.float64(data[p, 2, j]) * x2)
    for j in numba.prange(m):
        s = part[0, j]
        for t in range(1, nchunk):
            s += part[t, j]
        y[j] = s


@numba.njit(cache=True, nogil=True)
def colour_rows(bptr, bcol):
    """Greedy colouring of the block rows of a structurally symmetric pattern: no two rows of a
    colour share a block → (cptr (n_colours+1,), order: the rows colour by colour, ascending)."""
    n = len(bptr) - 1
    colour = np.full(n, -1, np.int64)
    forbid = np.full(n + 1, -1, np.int64)
    n_col = 0
    for r in range(n):
        for p in range(bptr[r], bptr[r + 1]):
            c = colour[bcol[p]]
            if c >= 0:
                forbid[c] = r
        c = 0
        while forbid[c] == r:
            c += 1
        colour[r] = c
        n_col = max(n_col, c + 1)
    cptr = np.zeros(n_col + 1, np.int64)
    for r in range(n):
        cptr[colour[r] + 1] += 1
    for c in range(n_col):
        cptr[c + 1] += cptr[c]
    fill = cptr[:-1].copy()
    order = np.empty(n, np.int64)
    for r in range(n):
        order[fill[colour[r]]] = r
        fill[colour[r]] += 1
    return cptr, order


@numba.njit(cache=True, nogil=True)
def _relax(bptr, bcol, data, Dinv, r, z, k):
    """z_k = D_k⁻¹ (r_k − Σ_{j ≠ k} K_kj z_j) (3 × 3 blocks, sums in float64)."""
    s0, s1, s2 = r[3 * k], r[3 * k + 1], r[3 * k + 2]
    for p in range(bptr[k], bptr[k + 1]):
        j = np.int64(bcol[p])
        if j == k:
            continue
        x0, x1, x2 = z[3 * j], z[3 * j + 1], z[3 * j + 2]
        s0 -= np.float64(data[p, 0, 0]) * x0 + np.float64(data[p, 0, 1]) * x1 + np.float64(data[p, 0, 2]) * x2
        s1 -= np.float64(data[p, 1, 0]) * x0 + np.float64(data[p, 1, 1]) * x1 + np.float64(data[p, 1, 2]) * x2
        s2 -= np.float64(data[p, 2, 0]) * x0 + np.float64(data[p, 2, 1]) * x1 + np.float64(data[p, 2, 2]) * x2
    for i in range(3):
        z[3 * k + i] = Dinv[k, i, 0] * s0 + Dinv[k, i, 1] * s1 + Dinv[k, i, 2] * s2


@numba.njit(cache=True, nogil=True, parallel=True)
def symmetric_gauss_seidel(bptr, bcol, data, Dinv, cptr, order, r, z):
    """z = M⁻¹ r, M = (D + L) D⁻¹ (D + U) in the colour order (``colour_rows``): from z = 0 one block
    Gauss–Seidel sweep colour by colour, then one in the reverse colour order (rows of a colour in
    parallel: they share no block, so the result does not depend on the thread count)."""
    z[:] = 0.0
    nc = len(cptr) - 1
    for c in range(nc):
        for q in numba.prange(cptr[c], cptr[c + 1]):
            _relax(bptr, bcol, data, Dinv, r, z, order[q])
    for c in range(nc - 1, -1, -1):
        for q in numba.prange(cptr[c], cptr[c + 1]):
            _relax(bptr, bcol, data, Dinv, r, z, order[q])


@numba.njit(cache=True, nogil=True, parallel=True)
def csr_block_pattern(indptr, indices, nb, nbc, nchunk=1):
    """The 3 × 3 block pattern of a scalar CSR (3 nb rows, 3 nbc columns; any sorted or unsorted
    indices) → (bptr int64, bcol int32, each block row's columns ascending). Block rows in ``nchunk``
    ranges, one marker array each (each row on its own: the same result for every nchunk)."""
    bptr = np.zeros(nb + 1, np.int64)
    for t in numba.prange(nchunk):
        mark = np.full(nbc, -1, np.int64)
        for i in range(nb * t // nchunk, nb * (t + 1) // nchunk):
            c = 0
            for a in range(3):
                r = 3 * i + a
                for p in range(indptr[r], indptr[r + 1]):
                    j = indices[p] // 3
                    if mark[j] != i:
                        mark[j] = i
                        c += 1
            bptr[i + 1] = c
    for i in range(nb):
        bptr[i + 1] += bptr[i]
    bcol = np.empty(bptr[nb], np.int32)
    for t in numba.prange(nchunk):
        mark = np.full(nbc, -1, np.int64)
        for i in range(nb * t // nchunk, nb * (t + 1) // nchunk):
            q = bptr[i]
            for a in range(3):
                r = 3 * i + a
                for p in range(indptr[r], indptr[r + 1]):
                    j = indices[p] // 3
                    if mark[j] != i:
                        mark[j] = i
                        bcol[q] = j
                        q += 1
            bcol[bptr[i]:bptr[i + 1]].sort()
    return bptr, bcol


@numba.njit(cache=True, nogil=True, parallel=True)
def csr_block_values(indptr, indices, data, bptr, bcol, nbc, place, vals, nchunk=1):
    """A scalar CSR's entries added into the blocks of its pattern (bptr, bcol): block p's entries
    into vals[place[p]] (``place`` a renumbering of the blocks; empty: vals[p]); ``vals`` (n_blocks,
    3, 3) zeros of the storage type (an entry stored twice is summed in it)."""
    nb = len(bptr) - 1
    for t in numba.prange(nchunk):
        slot = np.empty(nbc, np.int64)
        for i in range(nb * t // nchunk, nb * (t + 1) // nchunk):
            for p in range(bptr[i], bptr[i + 1]):
                slot[bcol[p]] = place[p] if len(place) else p
            for a in range(3):
                r = 3 * i + a
                for p in range(indptr[r], indptr[r + 1]):
                    j = indices[p]
                    vals[slot[j // 3], a, j % 3] += data[p]


def csr_to_blocks(indptr, indices, data, nb, nbc, data_out, nchunk=1):
    """The 3 × 3 blocks of a scalar CSR (3 nb × 3 nbc) with values of ``data_out``'s type (zeros
    where a block's entry is not stored) → (bptr, bcol, values (n_blocks, 3, 3))."""
    bptr, bcol = csr_block_pattern(indptr, indices, nb, nbc, nchunk)
    vals = np.zeros((len(bcol), 3, 3), data_out.dtype)
    csr_block_values(indptr, indices, data, bptr, bcol, nbc, np.empty(0, np.int64), vals, nchunk)
    return bptr, bcol, vals


@numba.njit(cache=True, nogil=True, parallel=True)
def matvec_rmatvec(bptr, bcol, data, x, xt, y, yt, nchunk):
    """y = A x and yt = Aᵀ xt in one pass over A (``matvec``'s rows, ``rmatvec``'s partial sums of yt
    per chunk of rows, summed chunk by chunk; yt zeroed here)."""
    n = len(bptr) - 1
    m = len(yt)
    part = np.zeros((nchunk, m))
    for t in numba.prange(nchunk):
        for r in range(n * t // nchunk, n * (t + 1) // nchunk):
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            u0, u1, u2 = xt[3 * r], xt[3 * r + 1], xt[3 * r + 2]
            for p in range(bptr[r], bptr[r + 1]):
                c = 3 * np.int64(bcol[p])
                x0, x1, x2 = x[c], x[c + 1], x[c + 2]
                a00, a01, a02 = np.float64(data[p, 0, 0]), np.float64(data[p, 0, 1]), np.float64(data[p, 0, 2])
                a10, a11, a12 = np.float64(data[p, 1, 0]), np.float64(data[p, 1, 1]), np.float64(data[p, 1, 2])
                a20, a21, a22 = np.float64(data[p, 2, 0]), np.float64(data[p, 2, 1]), np.float64(data[p, 2, 2])
                s0 += a00 * x0 + a01 * x1 + a02 * x2
                s1 += a10 * x0 + a11 * x1 + a12 * x2
                s2 += a20 * x0 + a21 * x1 + a22 * x2
                part[t, c] += a00 * u0 + a10 * u1 + a20 * u2
                part[t, c + 1] += a01 * u0 + a11 * u1 + a21 * u2
                part[t, c + 2] += a02 * u0 + a12 * u1 + a22 * u2
            y[3 * r] = s0
            y[3 * r + 1] = s1
            y[3 * r + 2] = s2
    for j in numba.prange(m):
        s = part[0, j]
        for t in range(1, nchunk):
            s += part[t, j]
        yt[j] = s
