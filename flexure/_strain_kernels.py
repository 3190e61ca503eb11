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
