"""Tetrahedral mesh container, P1 → P2 conversion and element-quality metrics.

Node ordering (VTK_TETRA / VTK_QUADRATIC_TETRA, also tetgen's ``-o2``): vertices 0..3, then the
mid-edge nodes of edges (0,1), (1,2), (0,2), (0,3), (1,3), (2,3) as local nodes 4..9. Elements are
positively oriented: det[x1−x0, x2−x0, x3−x0] > 0. Boundary faces come outward oriented, vertices
(a, b, c) then, for P2, the mid-edge nodes of (a,b), (b,c), (c,a) (VTK_QUADRATIC_TRIANGLE).
Coordinates in metres; dof of node n, component c (x=0, y=1, z=2) is 3n + c.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from userio.errors import InputError

#: local vertex pairs of the six edges, in VTK / tetgen order (local nodes 4..9).
TET_EDGES = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]], dtype=np.int64)
#: faces opposite vertex 0, 1, 2, 3, outward for a positively oriented tetrahedron.
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)


def _edge_local(i: int, j: int) -> int:
    a, b = sorted((i, j))
    return 4 + [tuple(e) for e in TET_EDGES.tolist()].index((a, b))


#: 6-node faces: vertices then mid-edge nodes of (a,b), (b,c), (c,a), as local tet node numbers.
TET_FACES_P2 = np.array(
    [[f[0], f[1], f[2], _edge_local(f[0], f[1]), _edge_local(f[1], f[2]), _edge_local(f[2], f[0])]
     for f in TET_FACES.tolist()], dtype=np.int64)


@dataclass
class Mesh:
    """Tetrahedral mesh: ``points`` (n,3) in m, ``tets`` (m,4) P1 or (m,10) P2 node indices."""

    points: np.ndarray
    tets: np.ndarray
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        pts = np.ascontiguousarray(self.points, dtype=np.float64)
        tets = np.asarray(self.tets)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InputError(f"mesh: field points must have shape (n, 3), got {pts.shape}")
        if tets.ndim != 2 or tets.shape[1] not in (4, 10):
            raise InputError(f"mesh: field tets must have shape (m, 4) or (m, 10), got {tets.shape}")
        if not np.issubdtype(tets.dtype, np.integer):
            raise InputError(f"mesh: field tets must be integer node indices, got {tets.dtype}")
        if len(tets) == 0:
            raise InputError("mesh: field tets is empty")
        if not np.all(np.isfinite(pts)):
            raise InputError("mesh: field points contains NaN or inf")
        lo, hi = int(tets.min()), int(tets.max())
        if lo < 0 or hi >= len(pts):
            raise InputError(f"mesh: field tets refers to node {lo if lo < 0 else hi}, "
                             f"but there are {len(pts)} points")
        idx_dtype = np.int32 if len(pts) < 2**31 - 1 else np.int64
        self.points = pts
        self.tets = np.ascontiguousarray(tets, dtype=idx_dtype)

    @property
    def order(self) -> int:
        """1 for 4-node, 2 for 10-node tetrahedra."""
        return 1 if self.tets.shape[1] == 4 else 2

    @property
    def n_nodes(self) -> int:
        return len(self.points)

    @property
    def n_elements(self) -> int:
        return len(self.tets)

    @property
    def n_dofs(self) -> int:
        """3 displacement dofs per node (dof = 3·node + component)."""
        return 3 * len(self.points)

    @property
    def corner_tets(self) -> np.ndarray:
        """(m,4) vertex indices of every element."""
        return self.tets[:, :4]

    def signed_volumes(self) -> np.ndarray:
        """V_e = det[x1−x0, x2−x0, x3−x0] / 6 of the straight (vertex) tetrahedra (m³)."""
        x = self.points[self.corner_tets]
        return np.einsum("ij,ij->i", x[:, 1] - x[:, 0],
                         np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0])) / 6.0

    def boundary_faces(self) -> np.ndarray:
        """Faces owned by one element, outward: (k,3) for P1, (k,6) for P2 (see module doc)."""
        if "bfaces" not in self._cache:
            m = self.n_elements
            loc = TET_FACES if self.order == 1 else TET_FACES_P2
            faces = self.tets[:, loc].reshape(4 * m, loc.shape[1]).astype(np.int64)
            key = np.sort(faces[:, :3], axis=1)
            n = np.int64(self.n_nodes)
            code = (key[:, 0] * n + key[:, 1]) * n + key[:, 2] if n < 2**21 else None
            if code is None:
                _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
            else:
                _, inv, cnt = np.unique(code, return_inverse=True, return_counts=True)
            once = cnt[inv.ravel()] == 1
            self._cache["bfaces"] = faces[once]
            self._cache["bface_tets"] = np.repeat(np.arange(m), 4)[once]
            self._cache["bface_local"] = np.tile(np.arange(4), m)[once]
        return self._cache["bfaces"]

    def boundary_face_owners(self) -> tuple[np.ndarray, np.ndarray]:
        """(element (k,), local face (k,)) of each of ``boundary_faces`` (local face f is opposite
        local vertex f)."""
        self.boundary_faces()
        return self._cache["bface_tets"], self._cache["bface_local"]

    def boundary_nodes(self) -> np.ndarray:
        """Sorted indices of nodes on the boundary surface."""
        return np.unique(self.boundary_faces())

    def select_faces(self, predicate) -> np.ndarray:
        """Boundary faces whose every node satisfies ``predicate(points (k,3)) -> bool (k,)``."""
        faces = self.boundary_faces()
        ok = np.asarray(predicate(self.points), dtype=bool)
        return faces[np.all(ok[faces], axis=1)]

    def select_nodes(self, predicate) -> np.ndarray:
        """Indices of nodes with ``predicate(points) -> bool (n,)``."""
        return np.flatnonzero(np.asarray(predicate(self.points), dtype=bool))


def unique_edges(tets4: np.ndarray, n_nodes: int):
    """Unique edges of (m,4) tetrahedra: returns edges (k,2) sorted and (m,6) element→edge map."""
    e = tets4[:, TET_EDGES].astype(np.int64)          # (m,6,2)
    lo, hi = np.minimum(e[..., 0], e[..., 1]), np.maximum(e[..., 0], e[..., 1])
    code = lo * np.int64(n_nodes) + hi
    uniq, inv = np.unique(code.ravel(), return_inverse=True)
    edges = np.stack([uniq // n_nodes, uniq % n_nodes], axis=1)
    return edges, inv.reshape(e.shape[:2])


def to_quadratic(mesh: Mesh, midpoint=None) -> Mesh:
    """P1 → P2: one node per unique edge (shared edges deduplicated), VTK edge order.

    ``midpoint(xa (k,3), xb (k,3)) -> (k,3)`` places the mid-edge nodes (default (xa+xb)/2); give one
    that projects onto a curved surface for isoparametric (curved) P2 elements.
    """
    if mesh.order == 2:
        return mesh
    edges, e2e = unique_edges(mesh.tets, mesh.n_nodes)
    xa, xb = mesh.points[edges[:, 0]], mesh.points[edges[:, 1]]
    mid = 0.5 * (xa + xb) if midpoint is None else np.asarray(midpoint(xa, xb), dtype=np.float64)
    if mid.shape != xa.shape:
        raise InputError(f"to_quadratic: midpoint returned shape {mid.shape}, expected {xa.shape}")
    points = np.vstack([mesh.points, mid])
    tets = np.hstack([mesh.tets.astype(np.int64), mesh.n_nodes + e2e])
    return Mesh(points, tets)


def to_linear(mesh: Mesh) -> Mesh:
    """P2 → P1: keep vertices only (renumbered compactly)."""
    if mesh.order == 1:
        return mesh
    used = np.unique(mesh.corner_tets)
    remap = np.full(mesh.n_nodes, -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return Mesh(mesh.points[used], remap[mesh.corner_tets])


def element_shape_metrics(points: np.ndarray, tets4: np.ndarray) -> dict:
    """Per-element volume, dihedral angles (m,6) in degrees, aspect ratio R/(3r), radius-edge R/l_min.

    Aspect ratio is 1 for the regular tetrahedron; R circumradius, r = 3V/ΣA inradius.
    """
    x = points[tets4]
    a, b, c = x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    vol = det / 6.0
    # outward area vectors of the faces opposite each vertex
    f = x[:, TET_FACES]                                # (m,4,3,3)
    nvec = 0.5 * np.cross(f[:, :, 1] - f[:, :, 0], f[:, :, 2] - f[:, :, 0])
    area = np.linalg.norm(nvec, axis=2)
    nhat = nvec / np.maximum(area, 1e-300)[..., None]
    # edge (i,j) is shared by the faces opposite the two other vertices
    other = np.array([[2, 3], [0, 3], [1, 3], [1, 2], [0, 2], [0, 1]])
    cosang = -np.einsum("mki,mki->mk", nhat[:, other[:, 0]], nhat[:, other[:, 1]])
    dihedral = np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0)))
    num = (np.einsum("ij,ij->i", a, a)[:, None] * np.cross(b, c)
           + np.einsum("ij,ij->i", b, b)[:, None] * np.cross(c, a)
           + np.einsum("ij,ij->i", c, c)[:, None] * np.cross(a, b))
    absdet = np.maximum(np.abs(det), 1e-300)
    R = np.linalg.norm(num, axis=1) / (2.0 * absdet)
    r = 3.0 * np.abs(vol) / np.maximum(area.sum(axis=1), 1e-300)
    edges = x[:, TET_EDGES[:, 1]] - x[:, TET_EDGES[:, 0]]
    lmin = np.linalg.norm(edges, axis=2).min(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        aspect = np.where(r > 0, R / (3.0 * r), np.inf)
        radius_edge = np.where(lmin > 0, R / lmin, np.inf)
    return dict(volume=vol, dihedral_deg=dihedral, aspect_ratio=aspect, radius_edge=radius_edge)


#: elements with a dihedral angle below this are counted as slivers.
SLIVER_DIHEDRAL_DEG = 5.0


def quality(mesh: Mesh) -> dict:
    """Mesh-quality summary: element count, min/max dihedral angle (deg), worst aspect ratio, ..."""
    q = element_shape_metrics(mesh.points, mesh.corner_tets)
    dmin = q["dihedral_deg"].min(axis=1)
    return dict(
        n_elements=int(mesh.n_elements), n_nodes=int(mesh.n_nodes), order=mesh.order,
        n_dofs=int(mesh.n_dofs),
        min_dihedral_deg=float(dmin.min()), max_dihedral_deg=float(q["dihedral_deg"].max()),
        max_aspect_ratio=float(q["aspect_ratio"].max()),
        mean_aspect_ratio=float(np.mean(q["aspect_ratio"])),
        max_radius_edge_ratio=float(q["radius_edge"].max()),
        min_volume_m3=float(q["volume"].min()), total_volume_m3=float(q["volume"].sum()),
        n_inverted=int(np.count_nonzero(q["volume"] <= 0)),
        n_slivers=int(np.count_nonzero(dmin < SLIVER_DIHEDRAL_DEG)),
    )


def box_mesh(nx: int, ny: int, nz: int, size=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0)) -> Mesh:
    """Structured box split into 6 tetrahedra per hexahedron (Kuhn split; conforming, positive)."""
    xs = [np.linspace(o, o + s, n + 1) for o, s, n in zip(origin, size, (nx, ny, nz))]
    X, Y, Z = np.meshgrid(*xs, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    return Mesh(pts, _hex_to_tets((nx, ny, nz)))


def _hex_to_tets(shape) -> np.ndarray:
    """Kuhn (Freudenthal) split of an (nx,ny,nz) grid of hexahedra into 6 tets each."""
    nx, ny, nz = shape
    idx = np.arange((nx + 1) * (ny + 1) * (nz + 1)).reshape(nx + 1, ny + 1, nz + 1)
    corner = {}
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                corner[(dx, dy, dz)] = idx[dx:nx + dx, dy:ny + dy, dz:nz + dz].ravel()
    # paths from (0,0,0) to (1,1,1) along the 6 permutations of the axes
    tets = []
    for perm in ([0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]):
        p = [0, 0, 0]
        verts = [corner[tuple(p)]]
        for ax in perm:
            p[ax] = 1
            verts.append(corner[tuple(p)])
        t = np.stack(verts, axis=1)
        if perm in ([0, 2, 1], [1, 0, 2], [2, 1, 0]):   # odd permutations: swap to orient positively
            t = t[:, [0, 2, 1, 3]]
        tets.append(t)
    return np.vstack(tets)


def cylinder_mesh(r_inner: float, r_outer: float, length: float, n_r: int, n_theta: int, n_z: int,
                  theta_span: float = 2 * np.pi, order: int = 1) -> Mesh:
    """Structured (hollow) cylinder / annular sector along +z; P2 mid-edge nodes on the true arcs.

    Grid in (r, θ, z) split into tetrahedra and mapped x = r cos θ, y = r sin θ; for order 2 the
    mid-edge nodes are placed at the mapped parameter midpoints (isoparametric, curved edges).
    """
    full = np.isclose(theta_span, 2 * np.pi)
    nth_pts = n_theta if full else n_theta + 1
    r = np.linspace(r_inner, r_outer, n_r + 1)
    th = np.linspace(0.0, theta_span, n_theta + 1)[:nth_pts]
    z = np.linspace(0.0, length, n_z + 1)
    R, TH, Z = np.meshgrid(r, np.arange(nth_pts), z, indexing="ij")
    param = np.stack([R.ravel(), TH.ravel().astype(float), Z.ravel()], axis=1)
    tets = _hex_to_tets((n_r, n_theta if not full else n_theta, n_z)) if not full else None
    if full:
        # periodic in θ: build on an (n_theta+1) grid, then wrap the last θ layer onto the first
        tets = _hex_to_tets((n_r, n_theta, n_z))
        ii = np.arange((n_r + 1) * (n_theta + 1) * (n_z + 1)).reshape(n_r + 1, n_theta + 1, n_z + 1)
        target = np.arange((n_r + 1) * n_theta * (n_z + 1)).reshape(n_r + 1, n_theta, n_z + 1)
        remap = np.empty(ii.size, dtype=np.int64)
        remap[ii[:, :n_theta].ravel()] = target.ravel()
        remap[ii[:, n_theta].ravel()] = target[:, 0].ravel()
        tets = remap[tets]
    dth = theta_span / n_theta

    def to_xyz(p):
        ang = p[:, 1] * dth
        return np.stack([p[:, 0] * np.cos(ang), p[:, 0] * np.sin(ang), p[:, 2]], axis=1)

    # orientation: (r, θ, z) is right-handed for r > 0, so the Kuhn split stays positive
    mesh = Mesh(to_xyz(param), tets)
    if order == 1:
        return mesh
    edges, e2e = unique_edges(mesh.tets, mesh.n_nodes)
    pa, pb = param[edges[:, 0]].copy(), param[edges[:, 1]].copy()
    if full:   # unwrap θ index across the seam
        d = pb[:, 1] - pa[:, 1]
        pb[:, 1] = np.where(d > n_theta / 2, pb[:, 1] - n_theta, pb[:, 1])
        pb[:, 1] = np.where(d < -n_theta / 2, pb[:, 1] + n_theta, pb[:, 1])
    mid = to_xyz(0.5 * (pa + pb))
    return Mesh(np.vstack([mesh.points, mid]),
                np.hstack([mesh.tets.astype(np.int64), mesh.n_nodes + e2e]))
