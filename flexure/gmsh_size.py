"""gmsh's mesh size at one point, compiled: the loop behind gmsh_mesh._size_field's callback.

gmsh calls the size callback once per point it sizes (162 k calls for the two volume meshes of a
six-spoke designer STL's adaptive start); the numpy form of it costs ~200 µs a call over a few
thousand spots (34 CPU-s of that start's 89), this loop a few µs. Same formula (mm):

    h = min(lc, h_far,
            max(h_gauge + g (d_c − r_gauge), h_gauge)          d_c: nearest gauge centre
            min_e min(h_e + g max(d_e − r_gauge, 0),            d_e: distance to edge segment e
                      max(h_e / 4, h_e √(d_e / 2h_e)))          (sizing.edge_size)
            min_k h_k + g d_k)                                  d_k: distance to spot k

Without numba (or with estimator.compiled.ENABLED False) ``kernel()`` is None and the caller keeps
its numpy form, the reference this loop is tested against (tests/test_stl_remesh.py).
"""

from __future__ import annotations

import math

import numpy as np

from flexure.sizing import EDGE_REFINEMENT


def _size_py(x, y, z, lc, prm, centres, edges, spots):
    """prm: (h_far, h_gauge, r_gauge, grading); centres (c,3); edges (e,8): start, direction, |dir|²,
    h_edge; spots (s,4): x, y, z, h. All mm."""
    h1, h0, r0, g = prm[0], prm[1], prm[2], prm[3]
    h = min(lc, h1)
    if centres.shape[0] > 0:
        d2 = 1e300
        for i in range(centres.shape[0]):
            dx, dy, dz = centres[i, 0] - x, centres[i, 1] - y, centres[i, 2] - z
            d2 = min(d2, dx * dx + dy * dy + dz * dz)
        h = min(h, max(h0 + g * (math.sqrt(d2) - r0), h0))
    for i in range(edges.shape[0]):
        wx, wy, wz = x - edges[i, 0], y - edges[i, 1], z - edges[i, 2]
        t = (wx * edges[i, 3] + wy * edges[i, 4] + wz * edges[i, 5]) / edges[i, 6]
        t = min(max(t, 0.0), 1.0)
        dx, dy, dz = wx - t * edges[i, 3], wy - t * edges[i, 4], wz - t * edges[i, 5]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        he = edges[i, 7]
        graded = max(he / EDGE_REFINEMENT, he * math.sqrt(d / (2.0 * he)))
        h = min(h, min(he + g * max(d - r0, 0.0), graded))
    for i in range(spots.shape[0]):
        dx, dy, dz = spots[i, 0] - x, spots[i, 1] - y, spots[i, 2] - z
        h = min(h, spots[i, 3] + g * math.sqrt(dx * dx + dy * dy + dz * dz))
    return h


_KERNEL = None


def kernel():
    """The compiled ``_size_py`` (numba, cached beside this module), or None without numba."""
    global _KERNEL
    from estimator import compiled

    if not compiled.available():
        return None
    if _KERNEL is None:
        _KERNEL = compiled.jit(_size_py)
    return _KERNEL


def warm() -> None:
    """Compile the kernel once (run.sh, at install) on the argument types gmsh's callback passes it
    (gmsh_mesh._size_field): Python floats and C-contiguous float64 arrays."""
    k = kernel()
    if k is not None:
        k(0.0, 0.0, 0.0, 1.0, np.ones(4), np.zeros((1, 3)), np.zeros((1, 8)), np.zeros((1, 4)))


def pack_edges(e0: np.ndarray, ev: np.ndarray, ev2: np.ndarray, he: np.ndarray) -> np.ndarray:
    """(e,8) rows of ``_size_py``'s edges: start (3), direction (3), |direction|², h_edge (mm)."""
    return np.ascontiguousarray(np.column_stack([e0, ev, ev2, he]).reshape(-1, 8), float)
