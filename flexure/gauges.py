"""Strain gauges on the flexure surface and their read-out.

A gauge is a grid of length L (along its axis a) and width W (along b = n × a) centred at c on a
surface with outward normal n. Its reading is the axial strain averaged over the grid area,

    ε_g = (1/LW) ∫∫ aᵀ ε(c + s a + t b) a ds dt,

evaluated with a tensor Gauss–Legendre rule (points moved a hair inside the solid); the strain
at the points comes from the one evaluator, ``flexure.post.strain_at``.
Bridge arms follow bridge.wheatstone's "full_bending" convention:
V_o/V_ex ≈ GF/4 (ε1 − ε2 + ε3 − ε4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from userio.errors import InputError


@dataclass(frozen=True)
class Gauge:
    """One gauge: centre (m), unit axis, outward unit normal, grid length/width (m), bridge arm 1–4."""

    centre_m: tuple
    axis: tuple
    normal: tuple
    length_m: float
    width_m: float
    arm: int
    name: str = ""

    def frame(self):
        """(c, a, b, n) with a ⟂ n re-orthogonalised, b = n × a."""
        c = np.asarray(self.centre_m, float)
        n = np.asarray(self.normal, float)
        n = n / np.linalg.norm(n)
        a = np.asarray(self.axis, float)
        a = a - (a @ n) * n
        norm = np.linalg.norm(a)
        if norm < 1e-9:
            raise InputError(f"gauge {self.name or self.arm}: axis is parallel to the surface normal")
        a = a / norm
        return c, a, np.cross(n, a), n


def sample_points(gauge: Gauge, n_length: int = 6, n_width: int = 3, inset_m: float | None = None):
    """Gauss–Legendre points (k,3) over the grid and their weights (k,) summing to 1."""
    c, a, b, n = gauge.frame()
    s, ws = np.polynomial.legendre.leggauss(n_length)
    t, wt = np.polynomial.legendre.leggauss(n_width)
    S, T = np.meshgrid(s * gauge.length_m / 2, t * gauge.width_m / 2, indexing="ij")
    W = np.outer(ws, wt).ravel() / 4.0
    inset = 1e-4 * min(gauge.length_m, gauge.width_m) if inset_m is None else inset_m
    pts = c + S.ravel()[:, None] * a + T.ravel()[:, None] * b - inset * n
    return pts, W


def read(gauges: list[Gauge], strain_fn, n_length: int = 6, n_width: int = 3) -> np.ndarray:
    """Average axial strain of each gauge, (g,) — or (g, cases) when strain_fn returns
    (k, cases, 3, 3). ``strain_fn(points (k,3)) -> (k,3,3)`` or (k, cases, 3, 3)."""
    pts, w, axes = [], [], []
    for g in gauges:
        p, wg = sample_points(g, n_length, n_width)
        pts.append(p)
        w.append(wg)
        axes.append(np.repeat(g.frame()[1][None], len(p), axis=0))
    pts, w, axes = np.vstack(pts), np.concatenate(w), np.vstack(axes)
    eps = np.asarray(strain_fn(pts))
    if eps.ndim == 3:
        e_aa = np.einsum("ki,kij,kj->k", axes, eps, axes)
    else:
        e_aa = np.einsum("ki,kcij,kj->kc", axes, eps, axes)
    k = n_length * n_width
    e_aa = (e_aa * (w[:, None] if e_aa.ndim == 2 else w)).reshape(len(gauges), k, *e_aa.shape[1:])
    return e_aa.sum(axis=1)


def bridge_strains(gauges: list[Gauge], readings: np.ndarray) -> np.ndarray:
    """Order readings (g, ...) by arm → (..., 4) for bridge.wheatstone (one gauge per arm)."""
    arms = [g.arm for g in gauges]
    if sorted(arms) != [1, 2, 3, 4]:
        raise InputError(f"gauges: need exactly one gauge on each bridge arm 1–4, got arms {arms}")
    order = np.argsort(arms)
    return np.moveaxis(np.asarray(readings)[order], 0, -1)


def _clip(poly: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Sutherland–Hodgman: the convex polygon ``poly`` (k,2) clipped by the CCW triangle ``tri`` (3,2)."""
    for i in range(3):
        p, q = tri[i], tri[(i + 1) % 3]
        e = q - p
        if not len(poly):
            break
        side = e[0] * (poly[:, 1] - p[1]) - e[1] * (poly[:, 0] - p[0])        # ≥ 0: inside
        nxt_side = np.roll(side, -1)
        nxt = np.roll(poly, -1, axis=0)
        out = []
        for k in range(len(poly)):
            if side[k] >= 0:
                out.append(poly[k])
            if (side[k] >= 0) != (nxt_side[k] >= 0):
                t = side[k] / (side[k] - nxt_side[k])
                out.append(poly[k] + t * (nxt[k] - poly[k]))
        poly = np.array(out).reshape(-1, 2)
    return poly


def _area_centroid(poly: np.ndarray):
    """Area and centroid of a simple polygon (k,2) (shoelace)."""
    if len(poly) < 3:
        return 0.0, np.zeros(2)
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cr = x * yn - xn * y
    a = 0.5 * cr.sum()
    if abs(a) < 1e-300:
        return 0.0, np.zeros(2)
    return a, np.array([((x + xn) * cr).sum(), ((y + yn) * cr).sum()]) / (6.0 * a)


#: the footprint read-out falls back to the Gauss-point rule when the grid is covered by less or
#: more than this fraction off its area by flat mesh faces in its plane (a curved or stepped face)
FOOTPRINT_COVER_TOL = 1e-3


def footprint_pieces(gauge: Gauge, mesh, inset_m: float | None = None, polygons: bool = False):
    """The grid rectangle cut by the mesh's boundary faces lying in its plane (normal ≈ n):
    → (elements (k,), points (k,3) at the pieces' centroids moved ``inset`` inside, weights (k,)
    = piece area / grid area[, with ``polygons`` the pieces (list of (p,2) in the grid's (a, b)
    coordinates)]), or None if the pieces do not cover the grid (|Σw − 1| > tol)."""
    c, a, b, n = gauge.frame()
    faces = mesh.boundary_faces()[:, :3]
    owners = mesh.boundary_face_owners()[0]
    x = mesh.points[faces]                                     # (f,3,3)
    L, W = gauge.length_m, gauge.width_m
    scale = max(L, W)
    nrm = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    nlen = np.linalg.norm(nrm, axis=1)
    d = x - c
    s, t = d @ a, d @ b
    near = ((np.abs(d @ n) < 1e-6 * scale).all(axis=1) & (nrm @ n > 0.999 * nlen)
            & (s.max(1) > -L / 2) & (s.min(1) < L / 2) & (t.max(1) > -W / 2) & (t.min(1) < W / 2))
    rect = np.array([[-L / 2, -W / 2], [L / 2, -W / 2], [L / 2, W / 2], [-L / 2, W / 2]])
    elems, cents, areas, polys = [], [], [], []
    for f in np.flatnonzero(near):                  # a few dozen faces per gauge
        tri = np.column_stack([s[f], t[f]])         # CCW seen along n (outward normal · n > 0)
        poly = _clip(rect, tri)
        area, cen = _area_centroid(poly)
        if area > 1e-12 * L * W:
            elems.append(owners[f])
            cents.append(cen)
            areas.append(area)
            polys.append(poly)
    w = np.asarray(areas) / (L * W)
    if not len(w) or abs(w.sum() - 1.0) > FOOTPRINT_COVER_TOL:
        return None
    inset = 1e-4 * min(L, W) if inset_m is None else inset_m
    cents = np.asarray(cents)
    pts = c + cents[:, :1] * a + cents[:, 1:] * b - inset * n
    if polygons:
        return np.asarray(elems, np.int64), pts, w / w.sum(), polys
    return np.asarray(elems, np.int64), pts, w / w.sum()


def quadrature(gauge: Gauge, mesh, inset_m: float | None = None):
    """A rule for the grid average (1/LW)∫ f dA of functions of higher degree than the P2 strain
    (flexure.dwr's cubic weights): each footprint piece fanned into triangles with the degree-4
    rule (fem.TRI_QUAD) → (elements (k,), reference coordinates ξ (k,3), weights (k,) summing to
    1); the Gauss points of ``sample_points`` on a grid not covered by flat faces."""
    from flexure.fem import TRI_QUAD
    from flexure.post import _newton_xi, locate

    pieces = footprint_pieces(gauge, mesh, polygons=True)
    if pieces is None:
        pts, w = sample_points(gauge)
        elems, xi = locate(mesh, pts)
        return elems, xi, w
    elems, _, _, polys = pieces
    c, a, b, n = gauge.frame()
    st, wq = TRI_QUAD
    inset = 1e-4 * min(gauge.length_m, gauge.width_m) if inset_m is None else inset_m
    E, P, W = [], [], []
    for e, poly in zip(elems, polys):
        for k in range(1, len(poly) - 1):
            v0, v1, v2 = poly[0], poly[k], poly[k + 1]
            area = 0.5 * ((v1[0] - v0[0]) * (v2[1] - v0[1]) - (v1[1] - v0[1]) * (v2[0] - v0[0]))
            q2 = v0 + st[:, :1] * (v1 - v0) + st[:, 1:] * (v2 - v0)
            E.append(np.full(len(st), e))
            P.append(c + q2[:, :1] * a + q2[:, 1:] * b - inset * n)
            W.append(2.0 * wq * area)
    elems, pts, w = np.concatenate(E), np.vstack(P), np.concatenate(W)
    V = mesh.points[mesh.corner_tets[elems]]
    T = np.transpose(V[:, 1:] - V[:, :1], (0, 2, 1))
    xi = np.linalg.solve(T, (pts - V[:, 0])[..., None])[..., 0]
    if mesh.order == 2:
        xi = _newton_xi(mesh, elems, xi, pts)
    return elems, xi, w / w.sum()


def _read_points(gauge: Gauge, mesh):
    """Where and with what weights ``read_footprint`` samples one gauge: (elements (k,), reference
    coordinates ξ (k,3), weights (k,) summing to 1) — the footprint pieces' centroids, or the
    Gauss points of ``sample_points`` where the grid is not covered by flat faces in its plane."""
    from flexure.post import _newton_xi, locate

    pieces = footprint_pieces(gauge, mesh)
    if pieces is None:
        pts, w = sample_points(gauge)
        elems, xi = locate(mesh, pts)
        return elems, xi, w
    elems, pts, w = pieces
    V = mesh.points[mesh.corner_tets[elems]]
    T = np.transpose(V[:, 1:] - V[:, :1], (0, 2, 1))
    xi = np.linalg.solve(T, (pts - V[:, 0])[..., None])[..., 0]
    if mesh.order == 2:
        xi = _newton_xi(mesh, elems, xi, pts)
    return elems, xi, w


def read_footprint(gauges: list[Gauge], mesh, U) -> np.ndarray:
    """Exact area average of each gauge's axial strain over its grid footprint, (g, cases):

        ε_g = Σ_pieces (A_piece / LW) · aᵀ ε(centroid of the piece) a,

    the pieces being the grid rectangle clipped by the flat boundary faces it lies on. Within one
    straight-sided element the P2 strain is linear (P1: constant), so the centroid value times the
    area is the exact integral: unlike a fixed Gauss rule across element boundaries (a
    discontinuous integrand), the read-out carries no quadrature error that changes erratically
    from one mesh to the next. A grid not covered by flat faces in its plane (a curved face) is
    read with the Gauss rule (``read``)."""
    from flexure.post import gradient_at, strain_from_gradient

    out = []
    for g in gauges:
        elems, xi, w = _read_points(g, mesh)
        eps = strain_from_gradient(gradient_at(mesh, U, elems, xi))       # (k,[cases,]3,3)
        _, a, _, _ = g.frame()
        e_aa = np.einsum("i,k...ij,j->k...", a, eps, a)
        out.append(np.tensordot(w, e_aa, axes=1))
    return np.asarray(out)


def functionals(gauges: list[Gauge], mesh) -> np.ndarray:
    """The read-outs as linear functionals of the nodal displacements: F (n, 3, g) with
    ``read_footprint(gauges, mesh, U)[g] = Σ F[:, :, g] · U``, i.e.

        F[node, i, g] = Σ_points w_p a_i (a · ∇N_node(x_p)),

    the right-hand sides of the gauges' dual (adjoint) problems (flexure.dwr)."""
    from flexure.fem import tet_shape

    F = np.zeros((mesh.n_nodes, 3, len(gauges)))
    for col, g in enumerate(gauges):
        elems, xi, w = _read_points(g, mesh)
        _, dN = tet_shape(mesh.order, xi)                                  # (k,nn,3)
        X = mesh.points[mesh.tets[elems]]
        J = np.einsum("kai,kaj->kij", X, dN)
        G = np.einsum("kaj,kji->kai", dN, np.linalg.inv(J))                # ∂N_a/∂x_i
        _, a, _, _ = g.frame()
        contrib = (w[:, None] * (G @ a))[:, :, None] * a[None, None, :]    # (k,nn,3)
        for i in range(3):
            F[:, i, col] = np.bincount(mesh.tets[elems].ravel(), weights=contrib[..., i].ravel(),
                                       minlength=mesh.n_nodes)
    return F
