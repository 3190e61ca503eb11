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
    vertices are projected too (``snap_vertices``)."""

    snap_vertices = True

    def __init__(self, surface, spacing: float = 0.5, candidates: int = 24):
        from scipy.spatial import cKDTree

        self.tri = surface.points[surface.faces]                           # (f,3,3)
        edge = np.linalg.norm(self.tri - self.tri[:, [1, 2, 0]], axis=2)
        step = spacing * float(np.median(edge))
        k = np.clip(np.ceil(edge.max(axis=1) / step), 1, 64).astype(int)
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
        from trimesh.triangles import closest_point

        points = np.asarray(points, float)
        if len(points) == 0:
            return points.copy()
        _, idx = self.tree.query(points, k=self.candidates)
        cand = self.owner[idx]                                               # (k, c)
        q = np.repeat(points, cand.shape[1], axis=0)
        cp = closest_point(self.tri[cand.ravel()], q).reshape(len(points), -1, 3)
        d = np.linalg.norm(cp - points[:, None], axis=2)
        return cp[np.arange(len(points)), d.argmin(axis=1)]


__all__ = ["classify", "CadProjector", "StlProjector"]
