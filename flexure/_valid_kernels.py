"""The validity check of curved P2 tetrahedra (flexure.mesh_motion.element_valid), compiled with numba:
one pass per element, no (k, q, 3, 3) Jacobian array."""

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, inline="always")
def _det3(a00, a01, a02, a10, a11, a12, a20, a21, a22):
    return a00 * (a11 * a22 - a12 * a21) - a01 * (a10 * a22 - a12 * a20) + a02 * (a10 * a21 - a11 * a20)


@numba.njit(cache=True, nogil=True)
def element_valid(points, tets, elements, dN, min_scaled):
    """(k,) bool: D = det[x₁−x₀, x₂−x₀, x₃−x₀] > 0 and det J_q ≥ ``min_scaled`` · D at every point q of
    ``dN`` (q,10,3), J_q[i, c] = Σ_a x_a,i ∂N_a/∂ξ_c (the P2 map's Jacobian)."""
    out = np.zeros(len(elements), np.bool_)
    J = np.empty((3, 3))
    for k in range(len(elements)):
        t = tets[elements[k]]
        x0 = points[t[0]]
        x1, x2, x3 = points[t[1]], points[t[2]], points[t[3]]
        D = _det3(x1[0] - x0[0], x2[0] - x0[0], x3[0] - x0[0],
                  x1[1] - x0[1], x2[1] - x0[1], x3[1] - x0[1],
                  x1[2] - x0[2], x2[2] - x0[2], x3[2] - x0[2])
        if not D > 0.0:
            continue
        ok = True
        for q in range(dN.shape[0]):
            J[:] = 0.0
            for a in range(10):
                xa = points[t[a]]
                for i in range(3):
                    for c in range(3):
                        J[i, c] += xa[i] * dN[q, a, c]
            if _det3(J[0, 0], J[0, 1], J[0, 2], J[1, 0], J[1, 1], J[1, 2], J[2, 0], J[2, 1], J[2, 2]) < min_scaled * D:
                ok = False
                break
        out[k] = ok
    return out
