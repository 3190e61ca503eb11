"""The compiled element loop of flexure.post.element_nodal_strains (numba, cached beside this file):
each element's strain at its own nodes in one pass, no (m, nn, nn, 3) gradient array."""

import numba
import numpy as np

from flexure import threads
from flexure._stiffness_kernels import point_gradients

threads.select_layer()                 # before any parallel loop runs (flexure.threads: fork safety)


@numba.njit(cache=True, nogil=True, parallel=True)
def nodal_strains(points, tets, u, dN, out, det_min, nchunk):
    """ε (m,nn,3,3) at the points q of ``dN`` (q,nn,3) of every element into ``out``: H_cj = Σ_a u_ac
    ∂N_a/∂x_j (∇N: flexure._stiffness_kernels.point_gradients), ε = (H + Hᵀ)/2; the smallest det J_q of
    each element into ``det_min`` (m,). Elements in ``nchunk`` parallel ranges, each on its own."""
    m, nn = tets.shape
    for t in numba.prange(nchunk):
        X = np.empty((nn, 3))
        U = np.empty((nn, 3))
        J = np.empty((3, 3))
        Ji = np.empty((3, 3))
        g = np.empty((nn, 3))
        H = np.empty((3, 3))
        for e in range(m * t // nchunk, m * (t + 1) // nchunk):
            for a in range(nn):
                for i in range(3):
                    X[a, i] = points[tets[e, a], i]
                    U[a, i] = u[tets[e, a], i]
            dmin = np.inf
            for q in range(dN.shape[0]):
                dmin = min(dmin, point_gradients(X, dN, q, J, Ji, g))
                for c in range(3):
                    for j in range(3):
                        s = 0.0
                        for a in range(nn):
                            s += U[a, c] * g[a, j]
                        H[c, j] = s
                for c in range(3):
                    for j in range(3):
                        out[e, q, c, j] = 0.5 * (H[c, j] + H[j, c])
            det_min[e] = dmin


@numba.njit(cache=True, nogil=True, parallel=True)
def stress_measures(eps, mu, vm, gmax, nchunk):
    """Per strain tensor ε (k,3,3): von Mises of σ = λ tr ε I + 2μ ε (its deviator 2μ d, d = ε − tr ε/3 I:
    λ drops out) into ``vm`` (k,) and ½(ε_max − ε_min) into ``gmax`` (k,), the same formulas as
    flexure.post's von_mises and max_shear_strain."""
    k = eps.shape[0]
    for t in numba.prange(nchunk):
        for i in range(k * t // nchunk, k * (t + 1) // nchunk):
            e00, e11, e22 = eps[i, 0, 0], eps[i, 1, 1], eps[i, 2, 2]
            a, b, c = eps[i, 0, 1], eps[i, 0, 2], eps[i, 1, 2]
            q = (e00 + e11 + e22) / 3.0
            d0, d1, d2 = e00 - q, e11 - q, e22 - q
            dd = d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * (a * a + b * b + c * c)       # d:d (deviatoric strain)
            vm[i] = np.sqrt(1.5 * 4.0 * mu * mu * dd)                               # s = 2μ d
            p = np.sqrt(dd / 6.0)
            if p > 0:
                det = d0 * d1 * d2 + 2.0 * a * b * c - d0 * c * c - d1 * b * b - d2 * a * a
                x = min(max(det / (2.0 * p ** 3), -1.0), 1.0)
                gmax[i] = np.sqrt(3.0) * p * np.sin(np.arccos(x) / 3.0 + np.pi / 3.0)
            else:
                gmax[i] = 0.0
