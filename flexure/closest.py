"""The closest point on candidate triangles: the compiled kernel (flexure._closest_kernels, Ericson's
Voronoi regions, no absolute tolerance), else trimesh's ``closest_point`` row width by row width."""

from __future__ import annotations

import numpy as np


def closest_on_candidates(points: np.ndarray, tri: np.ndarray, indptr: np.ndarray, indices: np.ndarray):
    """Closest points (k,3) and distances (k,) of ``points`` (k,3) on their candidate triangles
    ``tri[indices[indptr[i]:indptr[i+1]]]`` (tri (f,3,3))."""
    from estimator import compiled

    if compiled.available():
        from flexure._closest_kernels import closest_on_triangles

        return closest_on_triangles(np.ascontiguousarray(points, float), np.ascontiguousarray(tri, float),
                                    indptr, indices)
    from trimesh.triangles import closest_point

    cp, d = np.empty_like(points, dtype=float), np.empty(len(points))
    for width in np.unique(np.diff(indptr)):       # rows of one length at a time
        rows = np.flatnonzero(np.diff(indptr) == width)
        cand = indices[indptr[rows][:, None] + np.arange(width)]
        q = closest_point(tri[cand.ravel()], np.repeat(points[rows], width, axis=0)).reshape(len(rows), width, 3)
        dist = np.linalg.norm(q - points[rows, None], axis=2)
        j = dist.argmin(axis=1)
        cp[rows], d[rows] = q[np.arange(len(rows)), j], dist[np.arange(len(rows)), j]
    return cp, d


def closest_points(tri: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The closest point (n,3) of each points[i] on the triangle tri[i] (n,3,3)."""
    one = np.arange(len(points) + 1)
    return closest_on_candidates(points, tri, one, one[:-1])[0]
