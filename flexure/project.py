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

import numpy as np

from flexure.mesh import TET_FACES, Mesh
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
    """Closest points on the entities of an OpenCASCADE model built by ``build(gmsh)`` (mm)."""

    #: gmsh meshes an exact CAD solid with its vertices on it: only mid nodes need projecting
    snap_vertices = False

    def __init__(self, build):
        self.build = build

    def project(self, points: np.ndarray, dim: np.ndarray, tag: np.ndarray) -> np.ndarray:
        import gmsh

        from flexure.gmsh_session import _quiet_stdout

        out = np.array(points, float)
        gmsh.initialize(interruptible=False)
        try:
            gmsh.option.setNumber("General.Terminal", 0)
            with _quiet_stdout():
                self.build(gmsh)
                for d in (1, 2):
                    for t in np.unique(tag[dim == d]):
                        sel = np.flatnonzero((dim == d) & (tag == t))
                        xyz, _ = gmsh.model.getClosestPoint(int(d), int(t), (out[sel] * MM).ravel().tolist())
                        out[sel] = np.asarray(xyz, float).reshape(-1, 3) / MM
        finally:
            gmsh.finalize()
        return out


class StlProjector:
    """Closest points on a closed triangulation (``geometry.Surface``): candidates from a KD-tree of
    points sampled on every triangle (no farther apart than ``spacing`` × the median edge), then the
    exact point–triangle distance to each candidate. gmsh re-parametrises an STL's patches and puts
    the mesh's vertices on its own surfaces, off the facets (a 3 mm bore's at r = 2.954 mm), so the
    vertices are projected too (``snap_vertices``).

    The exact distances are computed in units of the median STL edge: trimesh's point–triangle
    closest point has absolute tolerances, and in metres (a 0.33 × 3 mm facet) it returned a
    facet's edge 36 µm away where the foot of the perpendicular, 11 µm away, lies inside it."""

    snap_vertices = True

    def __init__(self, surface, spacing: float = 0.5, candidates: int = 24):
        from scipy.spatial import cKDTree

        self.tri = surface.points[surface.faces]                           # (f,3,3)
        edge = np.linalg.norm(self.tri - self.tri[:, [1, 2, 0]], axis=2)
        self.unit = float(np.median(edge))
        step = spacing * self.unit
        k = np.clip(np.ceil(edge.max(axis=1) / step), 1, 64).astype(int)
        #: every point of a triangle is within this of one of its samples (a grid cell's longest edge)
        self.gap = float((edge.max(axis=1) / k).max())
        pts, owner = [], []
        for kk in np.unique(k):                                               # barycentric grid per triangle
            sel = np.flatnonzero(k == kk)
            i, j = np.meshgrid(np.arange(kk + 1), np.arange(kk + 1), indexing="ij")
            ok = i + j <= kk
            b = np.column_stack([i[ok], j[ok], kk - i[ok] - j[ok]]) / kk   # (s,3)
            pts.append(np.einsum("sa,fai->fsi", b, self.tri[sel]).reshape(-1, 3))
            owner.append(np.repeat(sel, len(b)))
        self.owner = np.concatenate(owner)
        self.tree = cKDTree(np.vstack(pts))
        self.candidates = candidates

    def project(self, points: np.ndarray, dim=None, tag=None) -> np.ndarray:
        points = np.asarray(points, float)
        if len(points) == 0:
            return points.copy()
        c = min(self.candidates, self.tree.n)
        ds, idx = self.tree.query(points, k=c)
        ds, idx = ds.reshape(len(points), c), idx.reshape(len(points), c)
        cp, d = self._closest(points, self.owner[idx])
        # certified where every sample within d + gap (the farthest a triangle holding a closer point
        # can have its nearest sample) was a candidate; else a ball query of that radius
        for i in np.flatnonzero(ds[:, -1] < d + self.gap):
            near = self.tree.query_ball_point(points[i], d[i] + self.gap)
            cp[i], d[i] = (a[0] for a in self._closest(points[i:i + 1], np.unique(self.owner[near])[None]))
        return cp

    def _closest(self, points, cand):
        """Closest points (k,3) and distances (k,) of ``points`` on their candidate triangles (k,c)."""
        from trimesh.triangles import closest_point

        q = np.repeat(points, cand.shape[1], axis=0)
        u = self.unit
        cp = u * closest_point(self.tri[cand.ravel()] / u, q / u).reshape(len(points), -1, 3)
        d = np.linalg.norm(cp - points[:, None], axis=2)
        j = d.argmin(axis=1)
        r = np.arange(len(points))
        return cp[r, j], d[r, j]


__all__ = ["classify", "CadProjector", "StlProjector"]
