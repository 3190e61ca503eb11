"""Checks of a closed triangle surface and of the gauges on it, run before any meshing.

- ``self_intersections``: non-adjacent triangles that cross. Broad phase: bounding boxes that
  overlap (sweep and prune along the longest axis); narrow phase: each edge p0 + s(p1 − p0),
  s ∈ (0, 1), of one triangle against the other (Möller–Trumbore: s, u, v from
  ``[−d, e1, e2] [s, u, v]ᵀ = p0 − v0``, crossing iff 0 < s < 1, u, v ≥ 0, u + v ≤ 1).
- ``thin_walls``: pairs of opposed, parallel triangles (n_a · n_b < −0.95) whose planes are closer
  than t_min and whose projections overlap: a wall (or slit) of (near) zero thickness.
- ``check_gauges``: every gauge grid lies on the surface: its centre within ``tol`` of the surface,
  its normal that of the face there, and a 5 × 5 lattice over the grid within ``tol`` of the
  surface (else the grid overhangs its face). tol = 5 % of the grid's larger side.
Each raises ``InputError`` naming the file (or field) and the problem.
"""

from __future__ import annotations

import numpy as np

from userio.errors import InputError

#: a wall thinner than this fraction of the part's largest extent is a zero-thickness feature
THIN_FRACTION = 1e-3
#: a gauge grid point farther than this fraction of the grid's larger side from the surface is off it
GAUGE_TOL = 0.05
#: largest angle (deg) between a gauge's normal and the surface normal at its centre
NORMAL_TOL_DEG = 20.0
_PAIR_CHUNK = 2_000_000


def _box_pairs(lo: np.ndarray, hi: np.ndarray):
    """Yield index pairs (i, j), i ≠ j, of boxes [lo, hi] that overlap (chunks of arrays): sorted
    by their low end along the longest axis, box a against the boxes b > a that start before it
    ends there (sweep and prune), kept where they overlap along all three axes. Compiled where
    ``estimator.compiled`` is (the same pairs in the same order, none of the candidate arrays:
    3.8 M candidates for 99 k pairs on a 15.7 k-triangle STL: check_solid 1.0 → 0.3 s), else in numpy."""
    axis = int(np.argmax(np.ptp(np.vstack([lo, hi]), axis=0)))
    order = np.argsort(lo[:, axis], kind="stable")
    lo_s, hi_s = lo[order], hi[order]
    m = len(order)
    end = np.searchsorted(lo_s[:, axis], hi_s[:, axis], side="right")
    sweep = _sweep_kernel()
    if sweep is not None:
        i, j = sweep(np.ascontiguousarray(lo_s, float), np.ascontiguousarray(hi_s, float), end.astype(np.int64))
        for c0 in range(0, len(i), _PAIR_CHUNK):
            yield order[i[c0:c0 + _PAIR_CHUNK]], order[j[c0:c0 + _PAIR_CHUNK]]
        return
    counts = np.maximum(end - np.arange(m) - 1, 0)
    cum = np.concatenate([[0], np.cumsum(counts)])
    start = 0
    while start < m:
        stop = int(np.searchsorted(cum, cum[start] + _PAIR_CHUNK, side="right")) - 1
        stop = min(max(stop, start + 1), m)
        c = counts[start:stop]
        i = np.repeat(np.arange(start, stop), c)
        j = i + 1 + (np.arange(c.sum()) - np.repeat(cum[start:stop] - cum[start], c))
        ok = np.all((lo_s[j] <= hi_s[i]) & (lo_s[i] <= hi_s[j]), axis=1)
        yield order[i[ok]], order[j[ok]]
        start = stop


def _sweep_py(lo_s, hi_s, end):
    """(i, j) of the overlapping boxes a < b < end[a] of the sorted boxes, in (a, b) order."""
    i, j = np.empty(max(lo_s.shape[0], 16), np.int64), np.empty(max(lo_s.shape[0], 16), np.int64)
    n = 0
    for a in range(lo_s.shape[0]):
        lx, ly, lz, hx, hy, hz = lo_s[a, 0], lo_s[a, 1], lo_s[a, 2], hi_s[a, 0], hi_s[a, 1], hi_s[a, 2]
        for b in range(a + 1, end[a]):
            if (lo_s[b, 0] <= hx and lx <= hi_s[b, 0] and lo_s[b, 1] <= hy and ly <= hi_s[b, 1]
                    and lo_s[b, 2] <= hz and lz <= hi_s[b, 2]):
                if n == i.shape[0]:                      # grow ×2
                    i, j = np.concatenate((i, np.empty_like(i))), np.concatenate((j, np.empty_like(j)))
                i[n], j[n] = a, b
                n += 1
    return i[:n].copy(), j[:n].copy()


_SWEEP = []


def _sweep_kernel():
    """The compiled ``_sweep_py`` (numba, cached beside this module), or None without numba."""
    from estimator import compiled

    if not compiled.available():
        return None
    if not _SWEEP:
        _SWEEP.append(compiled.jit(_sweep_py))
    return _SWEEP[0]


def _not_adjacent(faces: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    fa, fb = faces[i], faces[j]
    return ~(fa[:, :, None] == fb[:, None, :]).any(axis=(1, 2))


def _segments_cross(p0, p1, tri, eps: float = 1e-9) -> np.ndarray:
    """Segment p0→p1 (k,3) crosses triangle tri (k,3,3) strictly inside the segment (k,) bool."""
    d = p1 - p0
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    h = np.cross(d, e2)
    det = np.einsum("ki,ki->k", e1, h)
    scale = np.linalg.norm(d, axis=1) * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
    ok = np.abs(det) > 1e-12 * scale                      # not parallel (coplanar pairs: skipped)
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = p0 - tri[:, 0]
    u = inv * np.einsum("ki,ki->k", s, h)
    q = np.cross(s, e1)
    v = inv * np.einsum("ki,ki->k", d, q)
    t = inv * np.einsum("ki,ki->k", e2, q)
    return ok & (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps) & (t > eps) & (t < 1 - eps)


def self_intersections(points: np.ndarray, faces: np.ndarray) -> tuple[int, np.ndarray | None]:
    """(number of crossing triangle pairs, a point of the first crossing or None)."""
    tri = points[faces]
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    n, where = 0, None
    for i, j in _box_pairs(lo, hi):
        keep = _not_adjacent(faces, i, j)
        i, j = i[keep], j[keep]
        if not len(i):
            continue
        hit = np.zeros(len(i), bool)
        for a, b in ((i, j), (j, i)):
            for k in range(3):
                hit |= _segments_cross(tri[a, k], tri[a, (k + 1) % 3], tri[b])
        if hit.any():
            n += int(hit.sum())
            if where is None:
                where = tri[i[hit][0]].mean(axis=0)
    return n, where


def _normals(tri: np.ndarray) -> np.ndarray:
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def thin_walls(points: np.ndarray, faces: np.ndarray, t_min: float) -> tuple[float, np.ndarray | None]:
    """(smallest distance < t_min between opposed overlapping faces, where) or (inf, None)."""
    tri = points[faces]
    nrm = _normals(tri)
    cen = tri.mean(axis=1)
    lo, hi = tri.min(axis=1) - t_min, tri.max(axis=1) + t_min
    best, where = np.inf, None
    for i, j in _box_pairs(lo, hi):
        keep = (np.einsum("ki,ki->k", nrm[i], nrm[j]) < -0.95) & _not_adjacent(faces, i, j)
        i, j = i[keep], j[keep]
        if not len(i):
            continue
        gap = np.abs(np.einsum("ki,ki->k", cen[j] - cen[i], nrm[i]))
        close = gap < t_min
        i, j, gap = i[close], j[close], gap[close]
        if not len(i):
            continue
        overlap = _inside_projection(cen[j], tri[i]) | _inside_projection(cen[i], tri[j])
        if overlap.any():
            k = int(np.argmin(np.where(overlap, gap, np.inf)))
            if gap[k] < best:
                best, where = float(gap[k]), cen[i[k]]
    return best, where


def _inside_projection(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """p (k,3) projected on the plane of tri (k,3,3) falls inside it (barycentric test)."""
    e1, e2, w = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], p - tri[:, 0]
    d11, d12, d22 = (np.einsum("ki,ki->k", a, b) for a, b in ((e1, e1), (e1, e2), (e2, e2)))
    w1, w2 = np.einsum("ki,ki->k", w, e1), np.einsum("ki,ki->k", w, e2)
    den = d11 * d22 - d12 ** 2
    den = np.where(den > 0, den, np.inf)
    u = (d22 * w1 - d12 * w2) / den
    v = (d11 * w2 - d12 * w1) / den
    return (u >= 0) & (v >= 0) & (u + v <= 1)


def shells(faces: np.ndarray) -> np.ndarray:
    """The connected piece of the surface each face belongs to (faces joined across shared edges)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    f = np.asarray(faces, np.int64)
    e = np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    order = np.lexsort((e[:, 1], e[:, 0]))
    same = (e[order][1:] == e[order][:-1]).all(axis=1)            # consecutive copies of one edge
    a, b = order[:-1][same] // 3, order[1:][same] // 3
    g = coo_matrix((np.ones(len(a)), (a, b)), shape=(len(f), len(f)))
    return connected_components(g, directed=False)[1]


def check_solid(points: np.ndarray, faces: np.ndarray, where: str) -> None:
    """InputError if the closed surface crosses itself, is several pieces (separate bodies, or a body
    and a void in it) or has a wall thinner than THIN_FRACTION."""
    n, at = self_intersections(points, faces)
    if n:
        raise InputError(f"{where}: surface intersects itself ({n} crossing triangle pairs, the first near "
                         f"{np.round(at * 1e3, 3).tolist()} mm); repair the solid in your CAD tool")
    label = shells(faces)
    if label.max() > 0:
        k = int(label.max()) + 1
        x = points[np.asarray(faces)[label == int(np.argsort(-np.bincount(label), kind="stable")[1])]].reshape(-1, 3)
        raise InputError(f"{where}: the surface is {k} separate pieces (the second largest spans "
                         f"{np.round(x.min(0) * 1e3, 3).tolist()} to {np.round(x.max(0) * 1e3, 3).tolist()} mm): "
                         "a flexure is one solid without voids; export it as one body")
    scale = float(np.ptp(points, axis=0).max())
    t, at = thin_walls(points, faces, THIN_FRACTION * scale)
    if at is not None:
        raise InputError(f"{where}: a zero-thickness feature: opposite faces {t * 1e3:.3g} mm apart near "
                         f"{np.round(at * 1e3, 3).tolist()} mm (below {THIN_FRACTION:g} of the part's "
                         f"{scale * 1e3:g} mm size); thicken or remove it")


def _nearest(points: np.ndarray, tri: np.ndarray, origin: np.ndarray, scale: float):
    """For each point (k,3): distance to the surface, index of the nearest triangle, closest point.
    (flexure.closest; trimesh's closest_point, without numba, has absolute tolerances: it is called in
    units of ``scale`` about ``origin``, the gauge's size and centre.)"""
    from flexure.closest import closest_points

    points, tri = (points - origin) / scale, (tri - origin) / scale
    dist = np.empty(len(points))
    idx = np.empty(len(points), dtype=np.int64)
    close = np.empty_like(points)
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    for k, p in enumerate(points):
        box = np.linalg.norm(np.maximum(0.0, np.maximum(lo - p, p - hi)), axis=1)   # ≤ distance
        cand = np.flatnonzero(box <= (box + np.linalg.norm(hi - lo, axis=1)).min())  # ≥ distance
        c = closest_points(tri[cand], np.repeat(p[None], len(cand), axis=0))
        d = np.linalg.norm(c - p, axis=1)
        b = int(np.argmin(d))
        dist[k], idx[k], close[k] = d[b], cand[b], c[b]
    return dist * scale, idx, close * scale + origin


def check_gauges(points: np.ndarray, faces: np.ndarray, gauges, where: str) -> None:
    """InputError unless every gauge grid lies on a face of the surface (see module docstring)."""
    tri = points[faces]
    nrm = _normals(tri)
    lo, hi = points.min(axis=0), points.max(axis=0)
    for g in gauges:
        name = f"gauge {g.name or g.arm} (arm {g.arm})"
        if not np.all(np.isfinite(np.concatenate([g.centre_m, g.axis, g.normal]))):
            raise InputError(f"{where}: {name}: centre, axis and normal must be finite numbers")
        c, a, b, n = g.frame()
        size = max(g.length_m, g.width_m)
        tol = GAUGE_TOL * size
        cmm = np.round(c * 1e3, 3).tolist()
        d, k, q = _nearest(c[None], tri, c, size)
        if d[0] > tol:
            outside_box = bool(np.any(c < lo - tol) or np.any(c > hi + tol))
            inside = winding_number(c, tri) > 0.5
            span = " × ".join(f"{v:.3g}" for v in (hi - lo) * 1e3)
            what = (f"off the part (outside its bounding box, {span} mm: is the file's length unit right?)"
                    if outside_box else
                    "inside the part, not on its surface" if inside else "off the part's surface")
            raise InputError(f"{where}: {name}: centre {cmm} mm is {d[0] * 1e3:.3g} mm {what}; "
                             "put it on a face of the solid")
        touching = _touching(c, tri, d[0] + 1e-6 * size, size)      # faces at the centre (edges: several)
        angle = np.degrees(np.arccos(np.clip((nrm[touching] @ n).max(), -1.0, 1.0)))
        if angle > NORMAL_TOL_DEG:
            raise InputError(f"{where}: {name}: normal {np.round(n, 3).tolist()} is {angle:.0f}° from the "
                             f"surface normal {np.round(nrm[k[0]], 3).tolist()} at its centre {cmm} mm")
        s = np.linspace(-0.5, 0.5, 5)
        S, T = np.meshgrid(s * g.length_m, s * g.width_m, indexing="ij")
        lattice = c + S.ravel()[:, None] * a + T.ravel()[:, None] * b
        dl, _, _ = _nearest(lattice, tri, c, size)
        if dl.max() > tol:
            raise InputError(f"{where}: {name}: its {g.length_m * 1e3:g} × {g.width_m * 1e3:g} mm grid at "
                             f"{cmm} mm overhangs its face by up to {dl.max() * 1e3:.3g} mm (the gauge is "
                             "larger than the face it sits on, or too near an edge)")


def winding_number(p: np.ndarray, tri: np.ndarray) -> float:
    """Σ Ω_t / 4π over the triangles (1 inside a closed outward surface, 0 outside), with the
    solid angle tan(Ω/2) = a·(b × c) / (|a||b||c| + (a·b)|c| + (b·c)|a| + (c·a)|b|) (Van Oosterom)."""
    a, b, c = (tri[:, i] - p for i in range(3))
    la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
    num = np.einsum("ki,ki->k", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("ki,ki->k", a, b) * lc + np.einsum("ki,ki->k", b, c) * la
           + np.einsum("ki,ki->k", c, a) * lb)
    return float(2.0 * np.arctan2(num, den).sum() / (4 * np.pi))


def _touching(p: np.ndarray, tri: np.ndarray, radius: float, scale: float) -> np.ndarray:
    """Indices of the triangles within ``radius`` of the point p (computed in units of ``scale``)."""
    from flexure.closest import closest_points

    p, tri, radius = np.zeros(3), (tri - p) / scale, radius / scale
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    cand = np.flatnonzero(np.all((lo - radius <= p) & (p <= hi + radius), axis=1))
    c = closest_points(tri[cand], np.repeat(p[None], len(cand), axis=0))
    return cand[np.linalg.norm(c - p, axis=1) <= radius]
