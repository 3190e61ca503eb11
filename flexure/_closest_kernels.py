"""The closest point on candidate triangles (flexure.project.StlProjector), compiled with numba.

Each point p has its candidate triangles as a CSR list (``indptr``, ``indices``); the closest point
of p on a triangle abc is found by the Voronoi regions of its vertices, edges and face (Ericson,
Real-Time Collision Detection, 5.1.5): with ab = b − a, ac = c − a and the six dot products
d₁ = ab·(p−a), d₂ = ac·(p−a), d₃ = ab·(p−b), d₄ = ac·(p−b), d₅ = ab·(p−c), d₆ = ac·(p−c),
the barycentric areas vc = d₁d₄ − d₃d₂, vb = d₅d₂ − d₁d₆, va = d₃d₆ − d₅d₄ pick the region, and
inside the face q = a + ab·vb/(va+vb+vc) + ac·vc/(va+vb+vc). No absolute tolerance enters, so the
answer does not depend on the unit (the caller still works in units of the median STL edge)."""

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, inline="always")
def _seg(p0, p1, p2, a0, a1, a2, b0, b1, b2):
    """The closest point of p on the segment ab and its squared distance (q0, q1, q2, e)."""
    ab0, ab1, ab2 = b0 - a0, b1 - a1, b2 - a2
    L2 = ab0 * ab0 + ab1 * ab1 + ab2 * ab2
    t = 0.0
    if L2 > 0.0:
        t = min(max(((p0 - a0) * ab0 + (p1 - a1) * ab1 + (p2 - a2) * ab2) / L2, 0.0), 1.0)
    q0, q1, q2 = a0 + t * ab0, a1 + t * ab1, a2 + t * ab2
    return q0, q1, q2, (q0 - p0) ** 2 + (q1 - p1) ** 2 + (q2 - p2) ** 2


@numba.njit(cache=True, nogil=True)
def _on_triangle(p0, p1, p2, T):
    """The closest point of p on the triangle T (3,3) (module docstring) and its squared distance
    (q0, q1, q2, e). A flat triangle (|ab × ac|² ≤ 1e-20 |ab|² |ac|²: collinear corners to
    round-off, where the face formula divides by round-off) is taken as its three edges."""
    a0, a1, a2 = T[0, 0], T[0, 1], T[0, 2]
    b0, b1, b2 = T[1, 0], T[1, 1], T[1, 2]
    c0, c1, c2 = T[2, 0], T[2, 1], T[2, 2]
    ab0, ab1, ab2 = b0 - a0, b1 - a1, b2 - a2
    ac0, ac1, ac2 = c0 - a0, c1 - a1, c2 - a2
    n0, n1, n2 = ab1 * ac2 - ab2 * ac1, ab2 * ac0 - ab0 * ac2, ab0 * ac1 - ab1 * ac0
    if n0 * n0 + n1 * n1 + n2 * n2 <= 1e-20 * (ab0 * ab0 + ab1 * ab1 + ab2 * ab2) * (ac0 * ac0 + ac1 * ac1 + ac2 * ac2):
        r = _seg(p0, p1, p2, a0, a1, a2, b0, b1, b2)
        s = _seg(p0, p1, p2, b0, b1, b2, c0, c1, c2)
        if s[3] < r[3]:
            r = s
        s = _seg(p0, p1, p2, c0, c1, c2, a0, a1, a2)
        return s if s[3] < r[3] else r
    d1 = ab0 * (p0 - a0) + ab1 * (p1 - a1) + ab2 * (p2 - a2)
    d2 = ac0 * (p0 - a0) + ac1 * (p1 - a1) + ac2 * (p2 - a2)
    d3 = ab0 * (p0 - b0) + ab1 * (p1 - b1) + ab2 * (p2 - b2)
    d4 = ac0 * (p0 - b0) + ac1 * (p1 - b1) + ac2 * (p2 - b2)
    d5 = ab0 * (p0 - c0) + ab1 * (p1 - c1) + ab2 * (p2 - c2)
    d6 = ac0 * (p0 - c0) + ac1 * (p1 - c1) + ac2 * (p2 - c2)
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    if d1 <= 0.0 and d2 <= 0.0:                       # vertex regions
        q0, q1, q2 = a0, a1, a2
    elif d3 >= 0.0 and d4 <= d3:
        q0, q1, q2 = b0, b1, b2
    elif d6 >= 0.0 and d5 <= d6:
        q0, q1, q2 = c0, c1, c2
    elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:       # edge regions
        v = d1 / (d1 - d3)
        q0, q1, q2 = a0 + v * ab0, a1 + v * ab1, a2 + v * ab2
    elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        q0, q1, q2 = a0 + w * ac0, a1 + w * ac1, a2 + w * ac2
    elif va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        q0, q1, q2 = b0 + w * (c0 - b0), b1 + w * (c1 - b1), b2 + w * (c2 - b2)
    else:                                             # the face
        s = 1.0 / (va + vb + vc)
        v, w = vb * s, vc * s
        q0, q1, q2 = a0 + v * ab0 + w * ac0, a1 + v * ab1 + w * ac1, a2 + v * ab2 + w * ac2
    return q0, q1, q2, (q0 - p0) ** 2 + (q1 - p1) ** 2 + (q2 - p2) ** 2


@numba.njit(cache=True, nogil=True)
def closest_on_triangles(points, tri, indptr, indices):
    """Closest points (k,3) and distances (k,) of ``points`` (k,3) on their candidate triangles
    ``tri[indices[indptr[i]:indptr[i+1]]]`` (tri (f,3,3)); the first of equally near candidates,
    a candidate repeated next to itself (sorted lists) looked at once."""
    k = len(points)
    out = np.empty((k, 3))
    dist = np.empty(k)
    for i in range(k):
        p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
        best = np.inf
        for s in range(indptr[i], indptr[i + 1]):
            t = indices[s]
            if s > indptr[i] and indices[s - 1] == t:
                continue
            q0, q1, q2, e = _on_triangle(p0, p1, p2, tri[t])
            if e < best:
                best = e
                out[i, 0], out[i, 1], out[i, 2] = q0, q1, q2
        dist[i] = np.sqrt(best)
    return out, dist
