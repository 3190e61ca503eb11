"""The compiled loops of flexure.enriched_assembly (numba, compiled on first use and cached beside this
file): the block sparsity pattern of an element numbering, its scalar CSR (3 × 3 blocks, rows 3r + i),
and the element loop that computes the surplus stiffness K_WW, the coupling K_hW and the residual
r_W of each element and adds them straight into those CSR arrays (flexure.enriched: the equations)."""

import numba
import numpy as np


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
def block_pattern(R, Cc, n_rows, n_cols):
    """Block pattern of Σ_e R[e]ᵀ ⊗ Cc[e]: → (bptr (n_rows+1,), bcol sorted within each row)."""
    ptr, els = _incidence(R, n_rows)
    mark = np.full(n_cols, -1, np.int64)
    bptr = np.zeros(n_rows + 1, np.int64)
    for r in range(n_rows):
        c = 0
        for p in range(ptr[r], ptr[r + 1]):
            e = els[p]
            for b in range(Cc.shape[1]):
                j = Cc[e, b]
                if j >= 0 and mark[j] != r:
                    mark[j] = r
                    c += 1
        bptr[r + 1] = bptr[r] + c
    mark[:] = -1
    bcol = np.empty(bptr[n_rows], np.int64)
    for r in range(n_rows):
        c = bptr[r]
        for p in range(ptr[r], ptr[r + 1]):
            e = els[p]
            for b in range(Cc.shape[1]):
                j = Cc[e, b]
                if j >= 0 and mark[j] != r:
                    mark[j] = r
                    bcol[c] = j
                    c += 1
        bcol[bptr[r]:bptr[r + 1]] = np.sort(bcol[bptr[r]:bptr[r + 1]])
    return bptr, bcol


@numba.njit(cache=True, nogil=True)
def scalar_csr(bptr, bcol, indptr, indices):
    """The scalar CSR (rows 3r + i, each block row's blocks in order, 3 columns each) of a block
    pattern, into indptr (3 n_rows + 1,) and indices (9 nnz_blocks,)."""
    n = len(bptr) - 1
    for r in range(n):
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


@numba.njit(cache=True, nogil=True)
def assemble(points, tets, u, rhs_face, Gk, sign, dN, dB, wq, lmb, mu,
             kb, kc, kdata, cb, cc, cdata, r, D):
    """Every element's surplus stiffness a(φ_b e_i, φ_c e_j), coupling a(N_a e_i, φ_c e_j) and residual
    rhs_face − a(u_h, φ_b e_i) at the quadrature (dN, dB (q,10,3) reference gradients of the P2 and
    surplus functions, weights wq), signed by ``sign`` and added at the kept functions Gk (m,10) (−1:
    left out) into the K_WW CSR data (kb, kc: block pattern), the coupling CSR data (cb, cc: rows the
    nodes), r (3 n_kept,) and the 3 × 3 diagonal blocks D (n_kept,3,3)."""
    m = tets.shape[0]
    nq = wq.shape[0]
    X = np.empty((10, 3))
    ue = np.empty((10, 3))
    J = np.empty((3, 3))
    Jinv = np.empty((3, 3))
    gN = np.empty((10, 3))
    gB = np.empty((10, 3))
    PB = np.empty((30, 30))
    PC = np.empty((30, 30))
    AB = np.empty((30, 30))
    AC = np.empty((30, 30))
    rl = np.empty((10, 3))
    sig = np.empty((3, 3))
    for e in range(m):
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
            for b in range(10):
                for i in range(3):
                    vb = dv * gB[b, i]
                    vn = dv * gN[b, i]
                    for c in range(10):
                        for j in range(3):
                            PB[3 * b + i, 3 * c + j] += vb * gB[c, j]
                            PC[3 * b + i, 3 * c + j] += vn * gB[c, j]
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
