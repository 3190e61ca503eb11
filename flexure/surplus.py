"""The cubic surplus space of a P2 tetrahedron (what P3 adds: edge cubics and face bubbles) and a
quadrature exact for its products: shared by the error estimators (flexure.dwr, flexure.bank_weiser)."""

from __future__ import annotations

import numpy as np

from flexure.mesh import TET_EDGES, TET_FACES


def tet_rule_degree5():
    """Walkington's 14-point rule, exact to degree 5 on the reference tetrahedron (volume 1/6),
    positive weights: two 4-point orbits (a, a, a, 1 − 3a) and one 6-point orbit (b, b, ½ − b, ½ − b).
    → (points ξ (14,3), weights (14,))."""
    pts, wts = [], []
    for a, w in ((0.0927352503108912, 0.01224884051939366), (0.3108859192633006, 0.01878132095300264)):
        L = np.full((4, 4), a)
        np.fill_diagonal(L, 1.0 - 3.0 * a)
        pts.append(L)
        wts.append(np.full(4, w))
    b, w = 0.0455037041256496, 0.007091003462846911
    L = np.array([[b, b, .5 - b, .5 - b], [b, .5 - b, b, .5 - b], [b, .5 - b, .5 - b, b],
                  [.5 - b, b, b, .5 - b], [.5 - b, b, .5 - b, b], [.5 - b, .5 - b, b, b]])
    pts.append(L)
    wts.append(np.full(6, w))
    L = np.vstack(pts)
    return np.ascontiguousarray(L[:, 1:]), np.concatenate(wts)


def surplus_basis(xi: np.ndarray):
    """Edge cubics L_p L_q (L_p − L_q) (6) and face bubbles (4, face f opposite vertex f) and their
    reference gradients at points ξ (q,3): → (B (q,10), dB (q,10,3))."""
    L = np.column_stack([1.0 - xi.sum(axis=1), xi])
    dL = np.array([[-1.0, -1.0, -1.0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    p, qq = TET_EDGES[:, 0], TET_EDGES[:, 1]
    Lp, Lq = L[:, p], L[:, qq]
    B = np.hstack([Lp * Lq * (Lp - Lq), L[:, TET_FACES[:, 0]] * L[:, TET_FACES[:, 1]] * L[:, TET_FACES[:, 2]]])
    dE = ((Lq * (Lp - Lq) + Lp * Lq)[:, :, None] * dL[p][None]
          + (Lp * (Lp - Lq) - Lp * Lq)[:, :, None] * dL[qq][None])
    a, b, c = TET_FACES[:, 0], TET_FACES[:, 1], TET_FACES[:, 2]
    dF = ((L[:, b] * L[:, c])[:, :, None] * dL[a][None] + (L[:, a] * L[:, c])[:, :, None] * dL[b][None]
          + (L[:, a] * L[:, b])[:, :, None] * dL[c][None])
    return B, np.concatenate([dE, dF], axis=1)
