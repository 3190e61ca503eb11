"""gmsh's mesh size at one point, compiled: the loop behind gmsh_mesh._size_field's callback.

gmsh calls the size callback once per point it sizes (162 k calls for the two volume meshes of a
six-spoke designer STL's adaptive start); the numpy form of it costs ~200 µs a call over a few
thousand spots (34 CPU-s of that start's 89), this loop a few µs. Same formula (mm):

    h = min(lc, h_far,
            max(h_gauge + g (d_c − r_gauge), h_gauge)          d_c: nearest gauge centre
            min_e min(h_e + g max(d_e − r_gauge, 0),            d_e: distance to edge segment e
                      max(h_e / 4, h_e √(d_e / 2h_e)))          (sizing.edge_size)
            min_k h_k + g d_k)                                  d_k: distance to spot k

The spots (an STL's curved faces: 1–3 k of them) are grouped into blocks of at most BLOCK_SPOTS
neighbours (``pack_spots``: recursive median bisection), each with its bounding box and its
smallest h; a block whose bound h_min + g · dist(x, box) is not below the size found so far is
skipped (every spot in it gives h_k + g d_k ≥ that bound, in floating point too: the rounded
terms are monotone in the gap), the block with the smallest bound is read first. The size is the
same number as the plain loop over every spot (a minimum does not depend on the order;
tests/test_stl_remesh.py), at a fraction of the cost: a call 4.3× faster at the 2640 spots and 48
edges of a six-spoke STL's adaptive start, 2.3× at the thick disc STL's 1216 (back to back, loaded).

Without numba (or with estimator.compiled.ENABLED False) ``kernel()`` is None and the caller keeps
its numpy form, the reference this loop is tested against (tests/test_stl_remesh.py).
"""

from __future__ import annotations

import math

import numpy as np

from flexure.sizing import EDGE_REFINEMENT


#: spots per block of ``pack_spots`` (the kernel's pruning unit)
BLOCK_SPOTS = 32


def _size_py(x, y, z, lc, prm, centres, edges, spots, blocks, first):
    """prm: (h_far, h_gauge, r_gauge, grading); centres (c,3); edges (e,8): start, direction, |dir|²,
    h_edge; spots (s,4): x, y, z, h, in blocks (b,7): box low (3), box high (3), smallest h, block
    b = spots[first[b]:first[b + 1]] (``pack_spots``). All mm."""
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
    nb = blocks.shape[0]
    if nb == 0:
        return h
    near, near_bound = 0, 1e300                     # the block with the smallest bound goes first
    for b in range(nb):
        bound = _block_bound(x, y, z, g, blocks, b)
        if bound < near_bound:
            near, near_bound = b, bound
    for k in range(nb + 1):
        b = near if k == 0 else k - 1
        if (k > 0 and b == near) or _block_bound(x, y, z, g, blocks, b) >= h:
            continue
        for i in range(first[b], first[b + 1]):
            dx, dy, dz = spots[i, 0] - x, spots[i, 1] - y, spots[i, 2] - z
            h = min(h, spots[i, 3] + g * math.sqrt(dx * dx + dy * dy + dz * dz))
    return h


def _block_bound(x, y, z, g, blocks, b):
    """h_min + g · (distance from (x, y, z) to block b's box): ≤ every spot's h_k + g d_k in it."""
    gx = max(blocks[b, 0] - x, x - blocks[b, 3], 0.0)
    gy = max(blocks[b, 1] - y, y - blocks[b, 4], 0.0)
    gz = max(blocks[b, 2] - z, z - blocks[b, 5], 0.0)
    return blocks[b, 6] + g * math.sqrt(gx * gx + gy * gy + gz * gz)


_KERNEL = None


def kernel():
    """The compiled ``_size_py`` (numba, cached beside this module), or None without numba."""
    global _KERNEL
    from estimator import compiled

    if not compiled.available():
        return None
    if _KERNEL is None:
        global _block_bound
        _block_bound = compiled.jit(_block_bound)       # called from the compiled loop
        _KERNEL = compiled.jit(_size_py)
    return _KERNEL


def warm() -> None:
    """Compile the kernel once (run.sh, at install) on the argument types gmsh's callback passes it
    (gmsh_mesh._size_field): Python floats and C-contiguous float64 arrays."""
    k = kernel()
    if k is not None:
        k(0.0, 0.0, 0.0, 1.0, np.ones(4), np.zeros((1, 3)), np.zeros((1, 8)), *pack_spots(np.zeros((1, 4))))


def pack_edges(e0: np.ndarray, ev: np.ndarray, ev2: np.ndarray, he: np.ndarray) -> np.ndarray:
    """(e,8) rows of ``_size_py``'s edges: start (3), direction (3), |direction|², h_edge (mm)."""
    return np.ascontiguousarray(np.column_stack([e0, ev, ev2, he]).reshape(-1, 8), float)


def pack_spots(spots: np.ndarray):
    """Spots (s,4: x, y, z, h; mm) → (the spots reordered, blocks (b,7): box low, box high, smallest h,
    first (b+1,): block b is spots[first[b]:first[b + 1]]), blocks of ≤ BLOCK_SPOTS neighbours cut
    by recursive median bisection along the longest side (deterministic: stable sorts)."""
    spots = np.asarray(spots, float).reshape(-1, 4)
    order, pieces, todo = np.arange(len(spots)), [], [(0, len(spots))] if len(spots) else []
    while todo:
        a, b = todo.pop()
        if b - a <= BLOCK_SPOTS:
            pieces.append((a, b))
            continue
        seg = order[a:b]
        axis = int(np.argmax(np.ptp(spots[seg, :3], axis=0)))
        order[a:b] = seg[np.argsort(spots[seg, axis], kind="stable")]
        mid = (a + b) // 2
        todo += [(mid, b), (a, mid)]
    pieces.sort()
    out = np.ascontiguousarray(spots[order])
    blocks = np.array([np.r_[out[a:b, :3].min(0), out[a:b, :3].max(0), out[a:b, 3].min()] for a, b in pieces],
                      float).reshape(-1, 7)
    first = np.array([a for a, _ in pieces] + [len(out)], np.int64)
    return out, np.ascontiguousarray(blocks), first
