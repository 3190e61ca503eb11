"""The compiled loops of flexure.enriched_assembly (numba, compiled on first use and cached beside this
file): the block sparsity pattern of an element numbering, its scalar CSR (3 × 3 blocks, rows 3r + i),
and the element loop that computes the surplus stiffness K_WW, the coupling K_hW and the residual
r_W of each element and adds them straight into those CSR arrays (flexure.enriched: the equations)."""

import numba
import numpy as np

from flexure import threads

threads.select_layer()                 # before any parallel loop runs (flexure.threads: fork safety)


@numba.njit(cache=True, nogil=True)
def _incidence(R, n_rows):
    """rows → elements (CSR ptr, elements) of the element table R (m,k) (−1: no row)."""
    m, k = R.shape
    ptr = np.zeros(n_rows + 1, np.int64)
    for e in range(m):
        for a in range(k):
            if R[e, a] >= 0:
                ptr[R[e, a] + 1] += 1
    for i in range(n_rows):
        ptr[i + 1] += ptr[i]
    fill = ptr[:-1].copy()
    els = np.empty(ptr[n_rows], np.int64)
    for e in range(m):
        for a in range(k):
            r = R[e, a]
            if r >= 0:
                els[fill[r]] = e
                fill[r] += 1
    return ptr, els


@numba.njit(cache=True, nogil=True)
def _row_blocks(ptr, els, Cc, mark, r, bcol, c0, fill):
    """The distinct columns of block row r (counted; written from bcol[c0] if ``fill``): → their count."""
    c = 0
    for p in range(ptr[r], ptr[r + 1]):
        e = els[p]
        for b in range(Cc.shape[1]):
            j = Cc[e, b]
            if j >= 0 and mark[j] != r:
                mark[j] = r
                if fill:
                    bcol[c0 + c] = j
                c += 1
    return c


@numba.njit(cache=True, nogil=True, parallel=True)
def _row_pointers(R, Cc, n_rows, n_cols, nchunk):
    """The rows' element incidence (ptr, els) and the block row pointer of Σ_e R[e]ᵀ ⊗ Cc[e]: each
    row's distinct columns counted, rows in ``nchunk`` ranges with one marker array each."""
    ptr, els = _incidence(R, n_rows)
    bptr = np.zeros(n_rows + 1, np.int64)
    dummy = np.empty(0, np.int64)
    for t in numba.prange(nchunk):
        mark = np.full(n_cols, -1, np.int64)
        for r in range(n_rows * t // nchunk, n_rows * (t + 1) // nchunk):
            bptr[r + 1] = _row_blocks(ptr, els, Cc, mark, r, dummy, 0, False)
    for i in range(n_rows):
        bptr[i + 1] += bptr[i]
    return ptr, els, bptr


@numba.njit(cache=True, nogil=True, parallel=True)
def block_pattern(R, Cc, n_rows, n_cols, nchunk):
    """Block pattern of Σ_e R[e]ᵀ ⊗ Cc[e]: → (bptr (n_rows+1,), bcol sorted within each row); the rows
    in ``nchunk`` ranges, one marker array each (the same result for every nchunk)."""
    ptr, els, bptr = _row_pointers(R, Cc, n_rows, n_cols, nchunk)
    bcol = np.empty(bptr[n_rows], np.int64)
    for t in numba.prange(nchunk):
        mark = np.full(n_cols, -1, np.int64)
        for r in range(n_rows * t // nchunk, n_rows * (t + 1) // nchunk):
            _row_blocks(ptr, els, Cc, mark, r, bcol, bptr[r], True)
            bcol[bptr[r]:bptr[r + 1]].sort()                 # in place: no array per row
    return bptr, bcol


@numba.njit(cache=True, nogil=True, parallel=True)
def block_pattern_slots(R, Cc, n_rows, n_cols, nchunk):
    """``block_pattern`` and S (m,k,l) int32: the index p (bptr[R[e,a]] ≤ p < bptr[R[e,a]+1]) of block
    (R[e,a], Cc[e,b]), −1 where either is −1 (the element loop adds each block at its place without
    searching its row), written as each row is sorted (a row occurs at most once in an element, so
    every S[e,a] is written by one row) → (bptr, bcol, S)."""
    ptr, els, bptr = _row_pointers(R, Cc, n_rows, n_cols, nchunk)
    m, k = R.shape
    lc = Cc.shape[1]
    bcol = np.empty(bptr[n_rows], np.int64)
    S = np.full((m, k, lc), -1, np.int32)
    for t in numba.prange(nchunk):
        mark = np.full(n_cols, -1, np.int64)
        pos = np.empty(n_cols, np.int64)                    # the places of the current row's columns
        for r in range(n_rows * t // nchunk, n_rows * (t + 1) // nchunk):
            _row_blocks(ptr, els, Cc, mark, r, bcol, bptr[r], True)
            bcol[bptr[r]:bptr[r + 1]].sort()
            for p in range(bptr[r], bptr[r + 1]):
                pos[bcol[p]] = p
            for q in range(ptr[r], ptr[r + 1]):
                e = els[q]
                for a in range(k):
                    if R[e, a] == r:
                        for b in range(lc):
                            j = Cc[e, b]
                            if j >= 0:
                                S[e, a, b] = pos[j]
    return bptr, bcol, S


@numba.njit(cache=True, nogil=True, parallel=True)
def scalar_csr(bptr, bcol, indptr, indices):
    """The scalar CSR (rows 3r + i, each block row's blocks in order, 3 columns each) of a block
    pattern, into indptr (3 n_rows + 1,) and indices (9 nnz_blocks,)."""
    n = len(bptr) - 1
    for r in numba.prange(n):
        nb = bptr[r + 1] - bptr[r]
        for i in range(3):
            start = 9 * bptr[r] + 3 * i * nb
            indptr[3 * r + i] = start
            for s in range(nb):
                for j in range(3):
                    indices[start + 3 * s + j] = 3 * bcol[bptr[r] + s] + j
    indptr[3 * n] = 9 * bptr[n]


@numba.njit(cache=True, nogil=True)
def _slot(bptr, bcol, r, c):
    lo, hi = bptr[r], bptr[r + 1] - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if bcol[mid] < c:
            lo = mid + 1
        else:
            hi = mid
    return lo - bptr[r]


@numba.njit(cache=True, nogil=True)
def _add_block(data, bptr, bcol, r, c, A, a0, c0, s):
    """data += s A[a0:a0+3, c0:c0+3] at block (r, c) of the scalar CSR of (bptr, bcol)."""
    nb = bptr[r + 1] - bptr[r]
    base = 9 * bptr[r] + 3 * _slot(bptr, bcol, r, c)
    for i in range(3):
        for j in range(3):
            data[base + 3 * i * nb + j] += s * A[a0 + i, c0 + j]


@numba.njit(cache=True, nogil=True)
def _inv3(J, Jinv):
    """J⁻¹ of a 3 × 3 matrix into Jinv; → det J."""
    a, b, c = J[0, 0], J[0, 1], J[0, 2]
    d, e, f = J[1, 0], J[1, 1], J[1, 2]
    g, h, k = J[2, 0], J[2, 1], J[2, 2]
    A, B, C = e * k - f * h, f * g - d * k, d * h - e * g
    det = a * A + b * B + c * C
    Jinv[0, 0], Jinv[1, 0], Jinv[2, 0] = A / det, B / det, C / det
    Jinv[0, 1], Jinv[1, 1], Jinv[2, 1] = (c * h - b * k) / det, (a * k - c * g) / det, (b * g - a * h) / det
    Jinv[0, 2], Jinv[1, 2], Jinv[2, 2] = (b * f - c * e) / det, (c * d - a * f) / det, (a * e - b * d) / det
    return det


@numba.njit(cache=True, nogil=True, parallel=True)
def inverse_blocks(D, nchunk):
    """The inverses (n,3,3) of the 3 × 3 blocks D (n,3,3) (``_inv3``: the cofactors over the determinant)."""
    n = D.shape[0]
    out = np.empty_like(D)
    for t in numba.prange(nchunk):
        for i in range(n * t // nchunk, n * (t + 1) // nchunk):
            _inv3(D[i], out[i])
    return out


@numba.njit(cache=True, nogil=True)
def colour_elements(V, n_nodes):
    """Greedy colouring of the elements (corner vertices V (m,4)) so that no two of one colour share a
    vertex, hence no node, edge or face: → (cptr (n_colours+1,), order (m,): the elements colour by
    colour, ascending within each). Elements of one colour can add into shared arrays at once."""
    m = V.shape[0]
    W = 16                                              # up to 1024 colours (tet meshes need ~20–60)
    used = np.zeros((n_nodes, W), np.uint64)
    colour = np.empty(m, np.int64)
    full = ~np.uint64(0)
    one = np.uint64(1)
    n_col = 0
    for e in range(m):
        c = -1
        for w in range(W):
            busy = used[V[e, 0], w] | used[V[e, 1], w] | used[V[e, 2], w] | used[V[e, 3], w]
            if busy != full:
                b = 0
                while (busy >> np.uint64(b)) & one:
                    b += 1
                c = 64 * w + b
                for a in range(4):
                    used[V[e, a], w] |= one << np.uint64(b)
                break
        if c < 0:
            raise ValueError("colour_elements: more than 1024 colours")
        colour[e] = c
        n_col = max(n_col, c + 1)
    cptr = np.zeros(n_col + 1, np.int64)
    for e in range(m):
        cptr[colour[e] + 1] += 1
    for c in range(n_col):
        cptr[c + 1] += cptr[c]
    fill = cptr[:-1].copy()
    order = np.empty(m, np.int64)
    for e in range(m):
        order[fill[colour[e]]] = e
        fill[colour[e]] += 1
    return cptr, order


@numba.njit(cache=True, nogil=True)
def _element(e, points, tets, u, rhs_face, dN, dB, wq, lmb, mu, X, ue, J, Jinv, gN, gB, PB, PC, AB, AC, rl, sig, w):
    """Element e's surplus stiffness AB (30,30), coupling AC (30,30) and residual rl (10,3) (``assemble``;
    PB, PC (30,32) and w (32,) work arrays, w[30:] = 0: P's rows as 32-wide loops, each entry's sum over
    the points in the same order as a 30-wide one)."""
    nq = wq.shape[0]
    for a in range(10):
        for i in range(3):
            X[a, i] = points[tets[e, a], i]
            ue[a, i] = u[tets[e, a], i]
    PB[:, :] = 0.0
    PC[:, :] = 0.0
    for b in range(10):
        for i in range(3):
            rl[b, i] = rhs_face[e, b, i]
    for q in range(nq):
        for i in range(3):
            for k in range(3):
                s = 0.0
                for a in range(10):
                    s += X[a, i] * dN[q, a, k]
                J[i, k] = s
        det = _inv3(J, Jinv)
        for a in range(10):
            for i in range(3):
                sN = 0.0
                sB = 0.0
                for k in range(3):
                    sN += dN[q, a, k] * Jinv[k, i]
                    sB += dB[q, a, k] * Jinv[k, i]
                gN[a, i] = sN
                gB[a, i] = sB
        tr = 0.0
        for c in range(3):
            for j in range(3):
                s = 0.0
                for a in range(10):
                    s += ue[a, c] * gN[a, j]
                sig[c, j] = s
        for c in range(3):
            tr += sig[c, c]
        for c in range(3):                                  # σ = 2μ ε + λ tr ε I from H in sig
            for j in range(c + 1, 3):
                ej = 0.5 * (sig[c, j] + sig[j, c])
                sig[c, j] = 2.0 * mu * ej
                sig[j, c] = 2.0 * mu * ej
        for c in range(3):
            sig[c, c] = 2.0 * mu * sig[c, c] + lmb * tr
        dv = wq[q] * det
        for b in range(10):
            for i in range(3):
                s = 0.0
                for j in range(3):
                    s += sig[i, j] * gB[b, j]
                rl[b, i] -= dv * s
        for b in range(10):                                 # w: gB's 30 values, padded to 32
            for i in range(3):
                w[3 * b + i] = gB[b, i]
        for r in range(30):                                 # P rows of 32: one vectorised loop each
            vb = dv * w[r]
            vn = dv * gN[r // 3, r % 3]
            for k in range(32):
                PB[r, k] += vb * w[k]
                PC[r, k] += vn * w[k]
    # A[(b,i),(c,j)] = λ P_bc,ij + μ P_bc,ji + μ δ_ij Σ_k P_bc,kk
    for b in range(10):
        for c in range(10):
            tB = PB[3 * b, 3 * c] + PB[3 * b + 1, 3 * c + 1] + PB[3 * b + 2, 3 * c + 2]
            tC = PC[3 * b, 3 * c] + PC[3 * b + 1, 3 * c + 1] + PC[3 * b + 2, 3 * c + 2]
            for i in range(3):
                for j in range(3):
                    AB[3 * b + i, 3 * c + j] = lmb * PB[3 * b + i, 3 * c + j] + mu * PB[3 * b + j, 3 * c + i]
                    AC[3 * b + i, 3 * c + j] = lmb * PC[3 * b + i, 3 * c + j] + mu * PC[3 * b + j, 3 * c + i]
                AB[3 * b + i, 3 * c + i] += mu * tB
                AC[3 * b + i, 3 * c + i] += mu * tC


@numba.njit(cache=True, nogil=True)
def _scatter(e, tets, Gk, sign, AB, AC, rl, kb, kc, kdata, cb, cc, cdata, r, D):
    """Element e's blocks added into the K_WW and coupling CSR data, r and D (``assemble``)."""
    for b in range(10):
        gb = Gk[e, b]
        if gb < 0:
            continue
        sb = sign[e, b]
        for i in range(3):
            r[3 * gb + i] += sb * rl[b, i]
        for c in range(10):
            gc = Gk[e, c]
            if gc < 0:
                continue
            _add_block(kdata, kb, kc, gb, gc, AB, 3 * b, 3 * c, sb * sign[e, c])
            if b == c:
                for i in range(3):
                    for j in range(3):
                        D[gb, i, j] += AB[3 * b + i, 3 * b + j]
    for a in range(10):
        na = tets[e, a]
        for c in range(10):
            gc = Gk[e, c]
            if gc >= 0:
                _add_block(cdata, cb, cc, na, gc, AC, 3 * a, 3 * c, sign[e, c])


@numba.njit(cache=True, nogil=True, parallel=True)
def assemble(points, tets, u, rhs_face, Gk, sign, dN, dB, wq, lmb, mu,
             kb, kc, kdata, cb, cc, cdata, r, D, cptr, order, nchunk):
    """Every element's surplus stiffness a(φ_b e_i, φ_c e_j), coupling a(N_a e_i, φ_c e_j) and residual
    rhs_face − a(u_h, φ_b e_i) at the quadrature (dN, dB (q,10,3) reference gradients of the P2 and
    surplus functions, weights wq), signed by ``sign`` and added at the kept functions Gk (m,10) (−1:
    left out) into the K_WW CSR data (kb, kc: block pattern), the coupling CSR data (cb, cc: rows the
    nodes), r (3 n_kept,) and the 3 × 3 diagonal blocks D (n_kept,3,3).

    Colour by colour (``colour_elements``: cptr, order), each colour's elements in ``nchunk`` ranges
    run in parallel: no two of them add into the same entry, and every entry receives its elements'
    terms in the colour order whatever the thread count (results independent of it)."""
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
                _scatter(e, tets, Gk, sign, AB, AC, rl, kb, kc, kdata, cb, cc, cdata, r, D)
