"""Putting new boundary nodes back on the true geometry (flexure.refine): the seam is a projector,
``project(points (k,3) m, dim (k,), tag (k,)) → points (k,3)`` moving each point onto its curve
(dim 1) or surface (dim 2) of tag ``tag``.

* ``CadProjector``: an exact OpenCASCADE solid (the parametric spoke disc, a STEP file) rebuilt in a
  gmsh session; orthogonal projection with ``gmsh.model.getClosestPoint`` on the entity the mesh
  face or edge was classified on when gmsh meshed it (``classify``), batched per entity.
* ``StlProjector``: the STL's own triangles (an STL is its facets): the closest point on them.

``classify`` turns gmsh's boundary triangles and curve lines (recorded by flexure.gmsh_mesh) into
the per-element face and edge tags of a ``refine.TaggedMesh``.
"""

from __future__ import annotations

import itertools

import numpy as np

from flexure import threads        # the KD-tree queries' workers (the same results on any number)
from flexure.mesh import TET_EDGES, TET_FACES, Mesh
from flexure.refine import TaggedMesh, edge_codes

MM = 1e3


def classify(mesh: Mesh, triangles: np.ndarray, tri_tag: np.ndarray, lines: np.ndarray,
             line_tag: np.ndarray) -> TaggedMesh:
    """Face tags (m,4) from the tagged boundary triangles (k,3) and edge tags (m,6) from the tagged
    curve segments (j,2), all as corner-node indices of ``mesh``."""
    tm = TaggedMesh.untagged(mesh)
    n = np.int64(mesh.n_nodes)
    if len(triangles):
        key = np.sort(np.asarray(triangles, np.int64), axis=1)
        code = (key[:, 0] * n + key[:, 1]) * n + key[:, 2]
        order = np.argsort(code)
        code, tags = code[order], np.asarray(tri_tag, np.int64)[order]
        fk = np.sort(mesh.corner_tets[:, TET_FACES].astype(np.int64), axis=2)
        fcode = (fk[..., 0] * n + fk[..., 1]) * n + fk[..., 2]
        at = np.minimum(np.searchsorted(code, fcode), len(code) - 1)
        tm.face_tag = np.where(code[at] == fcode, tags[at], 0)
    if len(lines):
        ln = np.sort(np.asarray(lines, np.int64), axis=1)
        code = (ln[:, 0] << 32) | ln[:, 1]
        order = np.argsort(code)
        code, tags = code[order], np.asarray(line_tag, np.int64)[order]
        ecode = edge_codes(mesh.tets)
        at = np.minimum(np.searchsorted(code, ecode), len(code) - 1)
        tm.edge_tag = np.where(code[at] == ecode, tags[at], 0)
    return tm


class CadProjector:
    """Closest points on the entities of an OpenCASCADE model built by ``build(gmsh)`` (mm). The
    model is built once, on the first ``project``, in a gmsh session kept open until ``close``
    (rebuilding it per call cost ~0.4 s each, five calls a run on the paper disc); a session that
    was finalized meanwhile (gmsh is one per process) is opened again."""

    #: gmsh meshes an exact CAD solid with its vertices on it: only mid nodes need projecting
    snap_vertices = False

    def __init__(self, build):
        self.build = build
        self._open = False

    def _session(self):
        import gmsh

        from flexure.gmsh_session import _quiet_stdout, open_session

        if self._open and gmsh.isInitialized():
            return gmsh
        open_session(gmsh)
        gmsh.option.setNumber("General.Terminal", 0)
        with _quiet_stdout():
            self.build(gmsh)
        self._open = True
        return gmsh

    def project(self, points: np.ndarray, dim: np.ndarray, tag: np.ndarray, certified: bool = True) -> np.ndarray:
        """Closest points on the CAD curves (``dim`` 1) or surfaces (2) ``tag`` (gmsh's exact closest point:
        ``certified`` has no effect, it is the projectors' common signature, StlProjector.project)."""
        from flexure.gmsh_session import _quiet_stdout

        out = np.array(points, float)
        gmsh = self._session()
        try:
            with _quiet_stdout():
                for d in (1, 2):
                    for t in np.unique(tag[dim == d]):
                        sel = np.flatnonzero((dim == d) & (tag == t))
                        xyz, _ = gmsh.model.getClosestPoint(int(d), int(t), (out[sel] * MM).ravel().tolist())
                        out[sel] = np.asarray(xyz, float).reshape(-1, 3) / MM
        except BaseException:
            self.close()
            raise
        return out

    def close(self) -> None:
        """End the gmsh session (a later ``project`` opens a new one)."""
        import gmsh

        if self._open and gmsh.isInitialized():
            gmsh.finalize()
        self._open = False


def stl_tagged(mesh: Mesh, projector: "StlProjector | None" = None, feature_deg: float = 40.0) -> TaggedMesh:
    """An STL part's TaggedMesh: every boundary face on surface 1, and every boundary edge where the
    mesh's two boundary faces fold by more than ``feature_deg`` (a sharp edge of the part, as the
    STL's: meshing.EDGE_ANGLE_DEG, gmsh's classification angle) on curve 1, so that its mid node and
    the nodes bisection puts on it go onto the STL's sharp-edge polyline (``StlProjector``, dim 1)
    rather than onto the nearer of the two faces: a chord across a faceted convex corner (a fillet
    meeting a cap) has its midpoint inside the part, nearer to either face than to the corner, and
    projected onto a face its P2 edge bows sideways (measured on a six-spoke designer STL: 33 mid
    nodes there could not be moved without folding an element)."""
    from flexure.refine import _boundary_face_mask

    tm = TaggedMesh.boundary_tagged(mesh)
    e, f = np.nonzero(_boundary_face_mask(mesh))
    if len(e) == 0:
        return tm
    tri = mesh.corner_tets[e[:, None], TET_FACES[f]].astype(np.int64)          # (k,3)
    x = mesh.points[tri]
    nrm = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    away = x.mean(axis=1) - mesh.points[mesh.corner_tets[e, f]]                   # from the opposite vertex: outward
    nrm *= np.sign(np.einsum("ki,ki->k", nrm, away))[:, None]
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1), 1e-300)[:, None]
    n = np.int64(mesh.n_nodes)
    ends = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    code = np.minimum(ends[:, 0], ends[:, 1]) * n + np.maximum(ends[:, 0], ends[:, 1])
    face = np.tile(np.arange(len(tri)), 3)
    order = np.argsort(code, kind="stable")
    code, face = code[order], face[order]
    pair = np.flatnonzero(code[1:] == code[:-1])                                  # an edge's two faces
    cos = np.einsum("ki,ki->k", nrm[face[pair]], nrm[face[pair + 1]])
    fold = pair[cos < np.cos(np.deg2rad(feature_deg))]
    if projector is not None and len(fold):
        # ... and only where the STL has a sharp edge: both ends within a quarter of the edge's length
        # of its sharp-edge polylines (a coarse mesh also folds across a tight fillet, which is a face)
        lo, hi = code[fold] // n, code[fold] % n
        L = np.linalg.norm(mesh.points[hi] - mesh.points[lo], axis=1)
        ends = np.concatenate([lo, hi])
        off = np.linalg.norm(projector.project_on_edges(mesh.points[ends]) - mesh.points[ends], axis=1)
        fold = fold[(off.reshape(2, -1) <= 0.25 * L).all(axis=0)]
    sharp = np.unique(code[fold])
    if len(sharp) == 0:
        return tm
    a, b = mesh.corner_tets[:, TET_EDGES[:, 0]].astype(np.int64), mesh.corner_tets[:, TET_EDGES[:, 1]].astype(np.int64)
    ecode = np.minimum(a, b) * n + np.maximum(a, b)
    at = np.minimum(np.searchsorted(sharp, ecode), len(sharp) - 1)
    tm.edge_tag[sharp[at] == ecode] = 1
    return tm


class StlProjector:
    """Closest points on a closed triangulation (``geometry.Surface``): candidates from a KD-tree of
    points sampled on every triangle (``samples``: rows across each triangle no farther apart than a
    spacing s, uniform over the surface), then the exact point–triangle distance to each candidate,
    certified by a ball query of radius d + gap (``project``). gmsh re-parametrises an STL's patches
    and puts the mesh's vertices on its own surfaces, off the facets (a 3 mm bore's at r = 2.954 mm),
    so the vertices are projected too (``snap_vertices``).

    The spacing is uniform, s = min(``spacing`` × the median edge, √(area / MAX_SAMPLES)): the ball's
    radius follows the coarsest sampling and its cost the densest. A barycentric grid of the median
    edge's spacing (the old sampler) on an extruded designer STL (earcut caps: needles 50 mm long,
    median edge 6 mm) put the ball at 3 mm and ~770 samples in it from the small facets of the bolt
    holes' walls: 8.4 M samples for the 11 k boundary nodes of its first mesh, 2.9 of the 4.8 s of its
    snap (2026-11-28; measured after the change: see ``samples``).

    The exact distances are computed in units of the median STL edge: trimesh's point–triangle
    closest point has absolute tolerances, and in metres (a 0.33 × 3 mm facet) it returned a
    facet's edge 36 µm away where the foot of the perpendicular, 11 µm away, lies inside it."""

    snap_vertices = True

    def __init__(self, surface, spacing: float = 0.5, candidates: int = 24, feature_deg: float = 40.0):
        from scipy.spatial import cKDTree

        self.tri = surface.points[surface.faces]                           # (f,3,3)
        edge = np.linalg.norm(self.tri - self.tri[:, [1, 2, 0]], axis=2)
        self.unit = float(np.median(edge))
        self.tri_unit = self.tri / self.unit                                   # (f,3,3) in median edges
        area = 0.5 * np.linalg.norm(np.cross(self.tri[:, 1] - self.tri[:, 0], self.tri[:, 2] - self.tri[:, 0]),
                                    axis=1).sum()
        step = min(spacing * self.unit, float(np.sqrt(area / MAX_SAMPLES))) or spacing * self.unit
        pts, self.owner, self.gap = samples(self.tri, step)
        self.tree = cKDTree(pts)
        self.candidates = candidates
        self._edges = None
        self.feature_deg = feature_deg
        self.surface = surface

    def project(self, points: np.ndarray, dim=None, tag=None, certified: bool = True) -> np.ndarray:
        """Closest points on the STL's triangles; those of ``dim`` 1 (a sharp edge, ``stl_tagged``)
        on its sharp-edge polylines instead (folds above ``feature_deg``), where it has any.
        ``certified`` False: the closest of the nearest samples' triangles only, no ball query (points
        within a sample gap of the surface, e.g. the mesh's own boundary: flexure.geometry_error)."""
        points = np.asarray(points, float)
        if dim is not None and len(points) and np.any(np.asarray(dim) == 1):
            on_curve = np.asarray(dim) == 1
            out = np.empty_like(points)
            out[~on_curve] = self.project(points[~on_curve], certified=certified)
            out[on_curve] = self.project_on_edges(points[on_curve])
            return out
        if len(points) == 0:
            return points.copy()
        c = min(self.candidates, self.tree.n)
        ds, idx = self.tree.query(points, k=c, workers=threads.count())
        ds, idx = ds.reshape(len(points), c), idx.reshape(len(points), c)
        cp, d = self._closest(points, self.owner[idx])
        if not certified:
            return cp
        # certified where every sample within d + gap (the farthest a triangle holding a closer point
        # can have its nearest sample) was a candidate; else all triangles of a ball of that radius
        ball = np.flatnonzero(ds[:, -1] < d + self.gap)
        if len(ball):
            rows, tris = _owners_in_balls(self.tree, self.owner, points[ball], d[ball] + self.gap)
            indptr = np.searchsorted(rows, np.arange(len(ball) + 1))
            cp[ball], d[ball] = self._closest_csr(points[ball], indptr, tris)
        return cp

    def project_on_edges(self, points: np.ndarray) -> np.ndarray:
        """Closest points on the STL's sharp edges (segments where its facets fold by more than
        ``feature_deg``): candidates from a KD-tree of the segments' midpoints, certified by a ball
        query of radius d + half the longest segment; the STL's triangles where it has none."""
        from scipy.spatial import cKDTree

        if self._edges is None:
            import trimesh

            tm = trimesh.Trimesh(self.surface.points, self.surface.faces, process=False)
            sharp = tm.face_adjacency_angles > np.deg2rad(self.feature_deg)
            seg = self.surface.points[tm.face_adjacency_edges[sharp]]                      # (s,2,3)
            self._edges = (seg, cKDTree(seg.mean(axis=1)) if len(seg) else None,
                           0.5 * float(np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1).max(initial=0.0)))
        seg, tree, half = self._edges
        points = np.asarray(points, float)
        if tree is None or len(points) == 0:
            return self.project(points)
        c = min(8, len(seg))
        _, idx = tree.query(points, k=c, workers=threads.count())
        idx = idx.reshape(len(points), c)
        cp, d = _closest_on_segments(points, seg[idx])
        # certified: every segment whose midpoint is within d + half was a candidate; else all of those
        near = tree.query_ball_point(points, d + half, workers=threads.count())
        lengths = np.fromiter(map(len, near), np.int64, len(near))
        rows = np.repeat(np.arange(len(points)), lengths)
        found = np.fromiter(itertools.chain.from_iterable(near), np.int64, int(lengths.sum()))
        missed = np.unique(rows[~(idx[rows] == found[:, None]).any(axis=1)])
        for i in missed:
            cp[i], d[i] = (a[0] for a in _closest_on_segments(points[i:i + 1], seg[np.asarray(near[i])][None]))
        return cp

    def _closest(self, points, cand):
        """Closest points (k,3) and distances (k,) of ``points`` on their candidate triangles (k,c)."""
        k, c = cand.shape
        return self._closest_csr(points, np.arange(0, k * c + 1, c), np.sort(cand, axis=1).ravel())

    def _closest_csr(self, points, indptr, tris):
        """Closest points (k,3) and distances (k,) of ``points`` on the triangles
        ``tris[indptr[i]:indptr[i+1]]`` of each (flexure.closest), computed in units of the median edge."""
        from flexure.closest import closest_on_candidates

        u = self.unit
        cp, d = closest_on_candidates(points / u, self.tri_unit, indptr, tris)
        return u * cp, u * d


#: the most samples the uniform spacing asks for (an STL's area / s²; the ``spacing`` × median edge,
#: where coarser, is used): small facets keep at least their three corners
MAX_SAMPLES = 50_000
#: rows per triangle at most (a facet longer than this × s is sampled more coarsely: ``gap`` says so)
MAX_ROWS = 1024


def samples(tri: np.ndarray, step: float):
    """Points on triangles (f,3,3) → (points (s,3), owner (s,), gap): a fan of rows from the vertex a
    opposite the shortest edge bc, row i at u = i/n (n = ⌈L/step⌉, L the longer of ab, ac), each row
    a + u((1 − v)(b − a) + v(c − a)) split into ⌈u |bc| / step⌉ equal parts (its ends included). A point
    of the triangle between rows i and i + 1 is within L/n of row i + 1 at its own v and then within
    half a part (≤ step/2) of a sample: gap = max over the triangles of L/n + step/2. A needle is a few
    samples wide, not a k × k grid of its longest edge."""
    f = len(tri)
    e = np.linalg.norm(tri[:, [1, 2, 0]] - tri[:, [2, 0, 1]], axis=2)     # edge opposite vertex k
    apex = e.argmin(axis=1)
    r = np.arange(f)
    a, b, c = tri[r, apex], tri[r, (apex + 1) % 3], tri[r, (apex + 2) % 3]
    L = np.maximum(np.linalg.norm(b - a, axis=1), np.linalg.norm(c - a, axis=1))
    W = e[r, apex]
    n = np.clip(np.ceil(L / step), 1, MAX_ROWS).astype(np.int64)
    row_tri = np.repeat(r, n + 1)
    i = np.arange(len(row_tri)) - np.repeat(np.cumsum(n + 1) - (n + 1), n + 1)
    u = i / n[row_tri]
    parts = np.where(i == 0, 0, np.maximum(np.ceil(u * W[row_tri] / step), 1)).astype(np.int64)
    pt_row = np.repeat(np.arange(len(row_tri)), parts + 1)
    j = np.arange(len(pt_row)) - np.repeat(np.cumsum(parts + 1) - (parts + 1), parts + 1)
    v = j / np.maximum(parts[pt_row], 1)
    t = row_tri[pt_row]
    uu, vv = u[pt_row][:, None], v[:, None]
    pts = a[t] + uu * ((1.0 - vv) * (b[t] - a[t]) + vv * (c[t] - a[t]))
    return pts, t, float(np.max(L / n)) + 0.5 * step


def _owners_in_balls(tree, owner: np.ndarray, centres: np.ndarray, radii: np.ndarray):
    """The distinct triangles (``owner`` of the samples) within ``radii`` of each of ``centres``,
    as (row, triangle) pairs sorted by row: one ball query for all."""
    near = tree.query_ball_point(centres, radii, workers=threads.count())
    lengths = np.fromiter(map(len, near), np.int64, len(near))
    samples = np.fromiter(itertools.chain.from_iterable(near), np.int64, int(lengths.sum()))
    n_tri = np.int64(owner.max() + 1)
    key = np.unique(np.repeat(np.arange(len(near), dtype=np.int64), lengths) * n_tri + owner[samples])
    return key // n_tri, key % n_tri


def _closest_on_segments(points: np.ndarray, seg: np.ndarray):
    """Closest points (k,3) and distances (k,) of ``points`` (k,3) on their candidate segments (k,c,2,3)."""
    a, ab = seg[:, :, 0], seg[:, :, 1] - seg[:, :, 0]
    t = np.einsum("kci,kci->kc", points[:, None] - a, ab) / np.maximum(np.einsum("kci,kci->kc", ab, ab), 1e-300)
    q = a + np.clip(t, 0.0, 1.0)[..., None] * ab
    d = np.linalg.norm(q - points[:, None], axis=2)
    j = d.argmin(axis=1)
    r = np.arange(len(points))
    return q[r, j], d[r, j]


__all__ = ["classify", "stl_tagged", "CadProjector", "StlProjector"]
