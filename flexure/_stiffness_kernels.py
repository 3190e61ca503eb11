"""The compiled element loop of flexure.stiffness_assembly (numba, compiled on first use and cached
beside this file): every element's stiffness added into the scalar CSR of the node-block pattern,
colour by colour (flexure._enriched_kernels.colour_elements), each colour's chunks in parallel."""

import numba
import numpy as np

from flexure import threads
from flexure._enriched_kernels import _inv3

threads.select_layer()                 # before any parallel loop runs (flexure.threads: fork safety)


@numba.njit(cache=True, nogil=True, inline="always")
def point_gradients(X, dN, q, J, Jinv, g):
    """∇N_a = J⁻ᵀ ∇_ξ N_a (nn,3) at point q of ``dN`` (q,nn,3) into g, J_ik = Σ_a X_ai ∂N_a/∂ξ_k into
    J and J⁻¹ into Jinv, of the element with nodes X (nn,3); → det J."""
    nn = dN.shape[1]
    for i in range(3):
        for k in range(3):
            s = 0.0
            for a in range(nn):
                s += X[a, i] * dN[q, a, k]
            J[i, k] = s
    det = _inv3(J, Jinv)
    for a in range(nn):
        for i in range(3):
            s = 0.0
            for k in range(3):
                s += dN[q, a, k] * Jinv[k, i]
            g[a, i] = s
    return det


@numba.njit(cache=True, nogil=True)
def _element(e, points, tets, dN, wq, lmb, mu, X, J, Jinv, g, P, A):
    """Element e's stiffness A (3nn,3nn), rows 3a + i: A_(a,i),(b,j) = λ P_ij + μ P_ji + μ δ_ij tr P,
    P = Σ_q w_q det J_q ∇N_a ∇N_bᵀ (∇N = J⁻ᵀ ∇_ξ N, J_ik = Σ_a X_ai ∂N_a/∂ξ_k); → min_q det J_q."""
    nq, nn = dN.shape[0], dN.shape[1]
    for a in range(nn):
        for i in range(3):
            X[a, i] = points[tets[e, a], i]
    P[:, :] = 0.0
    dmin = np.inf
    for q in range(nq):
        det = point_gradients(X, dN, q, J, Jinv, g)
        dmin = min(dmin, det)
        dv = wq[q] * det
        for a in range(nn):
            for i in range(3):
                v = dv * g[a, i]
                for b in range(nn):
                    for j in range(3):
                        P[3 * a + i, 3 * b + j] += v * g[b, j]
    for a in range(nn):
        for b in range(nn):
            tr = P[3 * a, 3 * b] + P[3 * a + 1, 3 * b + 1] + P[3 * a + 2, 3 * b + 2]
            for i in range(3):
                for j in range(3):
                    A[3 * a + i, 3 * b + j] = lmb * P[3 * a + i, 3 * b + j] + mu * P[3 * a + j, 3 * b + i]
                A[3 * a + i, 3 * b + i] += mu * tr
    return dmin


@numba.njit(cache=True, nogil=True, parallel=True)
def assemble(points, tets, dN, wq, lmb, mu, bptr, S, data, det_min, cptr, order, nchunk):
    """Every element's stiffness added into ``data`` (the scalar CSR of the block pattern bptr:
    flexure._enriched_kernels.scalar_csr) at its blocks' places S[e,a,b] (the index p of block
    (tets[e,a], tets[e,b]): flexure._enriched_kernels.block_pattern_slots, no row searched), its
    smallest det J into det_min (m,). Colour by colour: no two elements of a colour share a node,
    every entry sums its elements in the colour order whatever the thread count."""
    nn = tets.shape[1]
    for col in range(len(cptr) - 1):
        lo, hi = cptr[col], cptr[col + 1]
        for t in numba.prange(nchunk):
            X = np.empty((nn, 3))
            J = np.empty((3, 3))
            Jinv = np.empty((3, 3))
            g = np.empty((nn, 3))
            P = np.empty((3 * nn, 3 * nn))
            A = np.empty((3 * nn, 3 * nn))
            for k in range(lo + (hi - lo) * t // nchunk, lo + (hi - lo) * (t + 1) // nchunk):
                e = order[k]
                det_min[e] = _element(e, points, tets, dN, wq, lmb, mu, X, J, Jinv, g, P, A)
                for a in range(nn):
                    r = tets[e, a]
                    nb = bptr[r + 1] - bptr[r]
                    for b in range(nn):
                        base = 9 * bptr[r] + 3 * (S[e, a, b] - bptr[r])
                        for i in range(3):
                            for j in range(3):
                                data[base + 3 * i * nb + j] += A[3 * a + i, 3 * b + j]


@numba.njit(cache=True, nogil=True)
def _jacobian(X, e, dN, q, J):
    for i in range(3):
        for k in range(3):
            s = 0.0
            for a in range(dN.shape[1]):
                s += X[e, a, i] * dN[q, a, k]
            J[i, k] = s


@numba.njit(cache=True, nogil=True, parallel=True)
def jacobians(X, dN, det, Jinv, nchunk):
    """det J (e,q) and J⁻¹ (e,q,3,3) into det, Jinv: J_ik = Σ_a X_ai ∂N_a/∂ξ_k at every point
    (elements X (e,nn,3) in ``nchunk`` parallel ranges; each element on its own)."""
    m = X.shape[0]
    for t in numba.prange(nchunk):
        J = np.empty((3, 3))
        Ji = np.empty((3, 3))
        for e in range(m * t // nchunk, m * (t + 1) // nchunk):
            for q in range(dN.shape[0]):
                _jacobian(X, e, dN, q, J)
                det[e, q] = _inv3(J, Ji)
                Jinv[e, q, :, :] = Ji


@numba.njit(cache=True, nogil=True, parallel=True)
def gradients(X, dN, G, det, nchunk):
    """∂N_a/∂x_i = Σ_k ∂N_a/∂ξ_k J⁻¹_ki into G (e,q,nn,3) and det J into det (e,q) (``jacobians``)."""
    m = X.shape[0]
    nn = dN.shape[1]
    for t in numba.prange(nchunk):
        J = np.empty((3, 3))
        Ji = np.empty((3, 3))
        for e in range(m * t // nchunk, m * (t + 1) // nchunk):
            for q in range(dN.shape[0]):
                _jacobian(X, e, dN, q, J)
                det[e, q] = _inv3(J, Ji)
                for a in range(nn):
                    for i in range(3):
                        s = 0.0
                        for k in range(3):
                            s += dN[q, a, k] * Ji[k, i]
                        G[e, q, a, i] = s
