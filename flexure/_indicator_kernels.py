"""The compiled element loops of the error estimators (numba, compiled on first use and cached beside
this file): flexure.dwr's energy indicators −a(v, w ψ_a) and flexure.bank_weiser's face term ∫_∂K t̂·φ_b dA,
each element on its own (parallel ranges of elements; the same bits for every thread count). The numpy
forms in those modules are the references they are tested against and the paths without numba."""

import numba
import numpy as np

from flexure import threads
from flexure._enriched_kernels import _inv3

threads.select_layer()                 # before any parallel loop runs (flexure.threads: fork safety)


@numba.njit(cache=True, nogil=True)
def _jac_inv(X, dN, q, J, Jinv):
    """J_ik = Σ_a X_ai ∂N_a/∂ξ_k at point q (element nodes X (nn,3)) into J, its inverse into Jinv → det J."""
    for i in range(3):
        for k in range(3):
            s = 0.0
            for a in range(dN.shape[1]):
                s += X[a, i] * dN[q, a, k]
            J[i, k] = s
    return _inv3(J, Jinv)


@numba.njit(cache=True, nogil=True)
def _gather(points, V, tets, e, X, Ve):
    """Element e's node coordinates into X (10,3) and its nodal values of V (n,3,k) into Ve (10,3,k)."""
    for a in range(10):
        n = tets[e, a]
        for i in range(3):
            X[a, i] = points[n, i]
            for c in range(V.shape[2]):
                Ve[a, i, c] = V[n, i, c]


@numba.njit(cache=True, nogil=True)
def _gradients(dN, q, Jinv, G):
    """∂N_a/∂x_j = Σ_k ∂N_a/∂ξ_k J⁻¹_kj at point q into G (nn,3)."""
    for a in range(dN.shape[1]):
        for j in range(3):
            G[a, j] = dN[q, a, 0] * Jinv[0, j] + dN[q, a, 1] * Jinv[1, j] + dN[q, a, 2] * Jinv[2, j]


@numba.njit(cache=True, nogil=True)
def _stress(Ve, c, G, lam, mu, sig):
    """σ = 2μ ε + λ tr ε I of field c of the element's nodal values Ve (nn,3,k) (shape gradients G
    (nn,3)) into sig."""
    for i in range(3):
        for j in range(3):
            s = 0.0
            for a in range(G.shape[0]):
                s += Ve[a, i, c] * G[a, j]
            sig[i, j] = s
    tr = sig[0, 0] + sig[1, 1] + sig[2, 2]
    for i in range(3):
        for j in range(i + 1, 3):
            ej = 0.5 * (sig[i, j] + sig[j, i])
            sig[i, j] = 2.0 * mu * ej
            sig[j, i] = 2.0 * mu * ej
    for i in range(3):
        sig[i, i] = 2.0 * mu * sig[i, i] + lam * tr


@numba.njit(cache=True, nogil=True, parallel=True)
def energy_parts(points, tets, V, coef, dN, Bs, dBs, L, dL, wq, lam, mu, part, nchunk):
    """part[e, a, c] = ∫_K σ(v_c):ε(w ψ_a) = Σ_q dv (ψ_a σ:∇w + (σ ∇ψ_a)·w) of element e, vertex a, field
    c of V (n,3,k), the weight w = Σ_b coef[e,b] B_b (coef (m,10,3)), degree-5 quadrature (dN (q,10,3),
    Bs (q,10), dBs (q,10,3), L (q,4) = ψ, dL (4,3), weights wq), isoparametric map."""
    m = tets.shape[0]
    nc = V.shape[2]
    for t in numba.prange(nchunk):
        J = np.empty((3, 3))
        Jinv = np.empty((3, 3))
        sig = np.empty((3, 3))
        w = np.empty(3)
        gw = np.empty((3, 3))
        gpsi = np.empty((4, 3))
        gN = np.empty((10, 3))
        gB = np.empty((10, 3))
        X = np.empty((10, 3))
        Ve = np.empty((10, 3, nc))
        for e in range(m * t // nchunk, m * (t + 1) // nchunk):
            _gather(points, V, tets, e, X, Ve)
            for a in range(4):
                for c in range(nc):
                    part[e, a, c] = 0.0
            for q in range(wq.shape[0]):
                det = _jac_inv(X, dN, q, J, Jinv)
                dv = wq[q] * det
                _gradients(dN, q, Jinv, gN)
                _gradients(dBs, q, Jinv, gB)
                for i in range(3):
                    s = 0.0
                    for b in range(10):
                        s += Bs[q, b] * coef[e, b, i]
                    w[i] = s
                    for j in range(3):
                        s = 0.0
                        for b in range(10):
                            s += gB[b, j] * coef[e, b, i]
                        gw[i, j] = s
                for a in range(4):
                    for j in range(3):
                        gpsi[a, j] = dL[a, 0] * Jinv[0, j] + dL[a, 1] * Jinv[1, j] + dL[a, 2] * Jinv[2, j]
                for c in range(nc):
                    _stress(Ve, c, gN, lam, mu, sig)
                    s_gw = 0.0
                    for i in range(3):
                        for j in range(3):
                            s_gw += sig[i, j] * gw[i, j]
                    for a in range(4):
                        s = 0.0
                        for i in range(3):
                            for j in range(3):
                                s += sig[i, j] * gpsi[a, j] * w[i]
                        part[e, a, c] += dv * (L[q, a] * s_gw + s)


@numba.njit(cache=True, nogil=True, parallel=True)
def face_tractions(points, tets, U, dN, nhat, lam, mu, tau, nchunk):
    """The outward traction τ = σ(u) n of each element's faces at their points, canonical order (dN
    (4 nq,10,3): face f's points f nq … f nq + nq − 1; nhat (m,4,3) the flat faces' unit normals;
    U (n,3,1) the displacement) into tau (m,4,nq,3)."""
    m = tets.shape[0]
    nq = tau.shape[2]
    for t in numba.prange(nchunk):
        J = np.empty((3, 3))
        Jinv = np.empty((3, 3))
        sig = np.empty((3, 3))
        G = np.empty((10, 3))
        X = np.empty((10, 3))
        Ue = np.empty((10, 3, 1))
        for e in range(m * t // nchunk, m * (t + 1) // nchunk):
            _gather(points, U, tets, e, X, Ue)
            for f in range(4):
                for q in range(nq):
                    p = f * nq + q
                    _jac_inv(X, dN, p, J, Jinv)
                    _gradients(dN, p, Jinv, G)
                    _stress(Ue, 0, G, lam, mu, sig)
                    for i in range(3):
                        tau[e, f, q, i] = sig[i, 0] * nhat[e, f, 0] + sig[i, 1] * nhat[e, f, 1] + sig[i, 2] * nhat[e, f, 2]


@numba.njit(cache=True, nogil=True, parallel=True)
def face_terms(tau, partner, perm, inv_perm, area, wq, Bf, rhs, nchunk):
    """rhs[e,b,i] = Σ_f Σ_q 2A_f w_q t̂_i B_b of the averaged traction t̂ = τ_K − ½ (τ_K + τ_K') on an
    interior face (its partner, flat index 4 e' + f', from ``partner``; −1 on a free face: t̂ = 0),
    the two elements' points matched through the sorted-vertex order (perm: sorted → canonical point,
    inv_perm its inverse), the sum in the lower flat index's order first."""
    m = tau.shape[0]
    nq = tau.shape[2]
    for t in numba.prange(nchunk):
        that = np.empty(3)
        for e in range(m * t // nchunk, m * (t + 1) // nchunk):
            for b in range(10):
                for i in range(3):
                    rhs[e, b, i] = 0.0
            for f in range(4):
                k = 4 * e + f
                p = partner[k]
                if p < 0:
                    continue
                lo, hi = min(k, p), max(k, p)
                for q in range(nq):
                    s = inv_perm[e, f, q]
                    qa, qb = perm[lo // 4, lo % 4, s], perm[hi // 4, hi % 4, s]
                    for i in range(3):
                        that[i] = tau[e, f, q, i] - 0.5 * (tau[lo // 4, lo % 4, qa, i] + tau[hi // 4, hi % 4, qb, i])
                    c = 2.0 * area[e, f] * wq[q]
                    for b in range(10):
                        v = c * Bf[f, q, b]
                        for i in range(3):
                            rhs[e, b, i] += v * that[i]
