"""Tetrahedral meshing with tetgen: quality switches, sizing finer at the gauges, P1 or P2.

Sizing: tetgen grades its interior from the boundary triangulation, so the local size is set
on the surface. For an extruded profile the caps are triangulated with a graded size field
h(x, y) (``graded_triangulation``: nested hexagonal lattices + Delaunay with boundary-edge recovery)
and the side walls are split into layers, giving h_gauge at the gauges and h_far elsewhere; tetgen
then inserts interior points under the radius-edge bound q (``minratio``), the minimum dihedral
angle (``mindihedral``) and the volume bound V ≤ h_far³/(6√2) (regular tetrahedron of edge h_far).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from userio.errors import InputError
from flexure.geometry import Surface, check_watertight
from flexure.sizing import (BYTES_PER_ELEMENT, EDGE_REFINEMENT, MAX_ELEMENTS, SizeField,  # noqa: F401 (re-exported)
                            check_cost, edge_size, estimate_elements)

#: h_far as a multiple of thickness, h_gauge as a multiple of the gauge grid's smaller side. At
#: "coarse" 0.3: 3.3 elements across a grid at h × 1, 2.4 at h × √2, 4.7 at the answer level h × 1/√2.
#: With 0.6 (1.7 elements across at h × 1) the paper disc's four arms all read 0.2 % high at h × 1
#: and low at h × √2, levels that made its three-level estimate oscillatory (± 0.69 % on a true
#: error of 0.02 %); at 0.3 its levels change by 0.05 % and then 0.04 % (tests/data/fem_reference/
#: levels.json), for 1.3× the DOFs at the answer level.
SIZES = {
    "coarse": {"far": 1.0, "gauge": 0.3, "minratio": 2.0, "mindihedral": 10.0},
    "medium": {"far": 0.7, "gauge": 0.2, "minratio": 1.8, "mindihedral": 12.0},
    "fine": {"far": 0.5, "gauge": 0.125, "minratio": 1.6, "mindihedral": 14.0},
}
#: elements per 2π of a curved edge or face at ``size = "coarse"``, h_factor 1 (gmsh meshes of CAD
#: solids; scaled like h_far: × coarse.far / size.far / h_factor). Without it a fillet or bolt hole
#: is faceted at the far size, and where its facets fall changes from one mesh level to the next: on
#: the STEP part (1 mm fillets at the spoke roots) the gauge strain then moved by 0.1–0.6 % between
#: levels in no order and the stiffness was 1–3 % high; with 12 per turn the changes from h × 1 down
#: are ≤ 0.09 % (tests/data/fem_reference/levels.json, ``fine``).
CURVATURE_ELEMENTS = 12.0


def _densify_ring(ring: np.ndarray, size_fn) -> np.ndarray:
    nxt = np.roll(ring, -1, axis=0)
    seg = np.linalg.norm(nxt - ring, axis=1)
    n = np.maximum(1, np.ceil(seg / size_fn(0.5 * (ring + nxt)))).astype(int)
    s = np.concatenate([np.arange(k) / k for k in n])
    rep = np.repeat(np.arange(len(ring)), n)
    return ring[rep] + s[:, None] * (nxt[rep] - ring[rep])


def graded_triangulation(poly, size_fn, max_iter: int = 40):
    """Triangulate a shapely polygon with spacing ≈ size_fn(xy); every boundary edge is kept.

    Returns (points (n,2), triangles (m,3) CCW, rings): points start with the boundary rings.
    Encroached boundary segments missing from the Delaunay triangulation are split (Ruppert).
    """
    import shapely
    from scipy.spatial import Delaunay, cKDTree

    poly = shapely.geometry.polygon.orient(poly, sign=1.0)
    rings = [np.asarray(poly.exterior.coords)[:-1]] + [np.asarray(r.coords)[:-1] for r in poly.interiors]
    rings = [_densify_ring(r, size_fn) for r in rings]
    minx, miny, maxx, maxy = poly.bounds
    gx, gy = np.meshgrid(np.linspace(minx, maxx, 120), np.linspace(miny, maxy, 120))
    sample = size_fn(np.column_stack([gx.ravel(), gy.ravel()]))
    hmin, hmax = float(sample.min()), float(sample.max())
    inner, lv = [], hmax
    while lv > 0.5 * hmin:                       # nested hexagonal lattices h, h/2, h/4 ...
        ny = int(np.ceil((maxy - miny) / (lv * np.sqrt(3) / 2))) + 2
        nx = int(np.ceil((maxx - minx) / lv)) + 2
        j, i = np.mgrid[0:ny, 0:nx]
        pts = np.column_stack([(minx + lv * (i + 0.5 * (j % 2))).ravel(),
                               (miny + j * lv * np.sqrt(3) / 2).ravel()])
        loc = size_fn(pts)
        keep = loc > lv / 2 * 1.0001
        if lv < hmax:
            keep &= loc <= lv * 1.0001
        inner.append(pts[keep])
        lv /= 2
    inner = np.vstack(inner)
    inner = inner[shapely.contains_xy(poly, inner[:, 0], inner[:, 1])]
    inner = inner[shapely.distance(poly.boundary, shapely.points(inner)) >= 0.6 * size_fn(inner)]
    for _ in range(max_iter):
        starts = np.cumsum([0] + [len(r) for r in rings])
        i0 = np.arange(starts[-1])
        i1 = np.concatenate([np.roll(np.arange(s, e), -1) for s, e in zip(starts[:-1], starts[1:])])
        pts = np.vstack(rings + [inner])
        tri = Delaunay(pts).simplices
        p = pts[tri]
        area2 = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                 - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
        c = p.mean(1)
        tri = tri[shapely.contains_xy(poly, c[:, 0], c[:, 1]) & (np.abs(area2) > 1e-10 * hmin ** 2)]
        e = np.sort(np.vstack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
        have = set(map(tuple, e))
        missing = np.array([(min(a, b), max(a, b)) not in have for a, b in zip(i0, i1)])
        if not missing.any():
            p = pts[tri]
            area2 = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                     - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
            tri[area2 < 0] = tri[area2 < 0][:, ::-1]
            return pts, tri, rings
        new = []
        for r, (s, e_) in zip(rings, zip(starts[:-1], starts[1:])):
            miss = missing[s:e_]
            nxt = np.roll(r, -1, axis=0)
            mids = 0.5 * (r + nxt)
            if miss.any() and len(inner):
                rad = 0.5 * np.linalg.norm(nxt[miss] - r[miss], axis=1)
                near = cKDTree(mids[miss]).query(inner, k=1)
                inner = inner[~(near[0] < 1.05 * rad[near[1]])]
            out = np.insert(r, np.flatnonzero(miss) + 1, mids[miss], axis=0)
            new.append(out)
        rings = new
    raise InputError("mesh: could not recover the profile boundary; use a coarser size or simpler profile")


def extrude_graded(poly, height: float, size_fn, source: str = "parametric") -> Surface:
    """Closed surface of ``poly`` × [0, height] with graded caps and layered side walls."""
    pts2, tri, rings = graded_triangulation(poly, size_fn)
    n = len(pts2)
    nb = sum(len(r) for r in rings)
    layers = max(1, int(np.ceil(height / np.median(size_fn(pts2[:nb])))))
    z = np.linspace(0.0, height, layers + 1)
    # node ids: caps at layer 0 / layers use all points; middle layers only boundary points
    def node(idx, k):
        idx = np.asarray(idx)
        if k == 0:
            return idx
        if k == layers:
            return idx + n
        return 2 * n + (k - 1) * nb + idx
    points = [np.column_stack([pts2, np.zeros(n)]), np.column_stack([pts2, np.full(n, height)])]
    points += [np.column_stack([pts2[:nb], np.full(nb, zk)]) for zk in z[1:-1]]
    starts = np.cumsum([0] + [len(r) for r in rings])
    i0 = np.arange(nb)
    i1 = np.concatenate([np.roll(np.arange(s, e), -1) for s, e in zip(starts[:-1], starts[1:])])
    faces = [tri[:, ::-1], tri + n]
    for k in range(layers):
        a0, b0, a1, b1 = node(i0, k), node(i1, k), node(i0, k + 1), node(i1, k + 1)
        faces += [np.column_stack([a0, b0, b1]), np.column_stack([a0, b1, a1])]
    surf = Surface(np.vstack(points), np.vstack(faces).astype(np.int64), source=source,
                   info={"profile_area_m2": float(poly.area), "thickness_m": float(height),
                         "layers": layers})
    check_watertight(surf, "mesh surface")
    return surf


def sweep_tetrahedra(pts2: np.ndarray, tri: np.ndarray, z: np.ndarray):
    """Tetrahedra of a triangulated profile swept through the levels ``z`` (3 per prism).

    Nodes are numbered level by level (node = k·n + i), so every prism's smallest node lies in
    its bottom triangle. Each prism (a, b, c | a', b', c'), rotated so that a is that smallest
    node, is split as in Dompierre et al. (1999): every quad face is cut along the diagonal
    through its smallest node, so neighbouring prisms share their diagonals (conforming mesh):
    min(b, c') < min(c, b') → (a b c c') (a b c' b') (a b' c' a'); else (a b c b') (a b' c c')
    (a b' c' a'). Returns points (n·levels, 3) and positively oriented tets (m, 4).
    """
    n, levels = len(pts2), len(z)
    points = np.column_stack([np.tile(pts2, (levels, 1)), np.repeat(z, n)])
    t = np.asarray(tri, dtype=np.int64)
    shift = np.argmin(t, axis=1)                              # rotate: smallest index first
    t = np.take_along_axis(t, (shift[:, None] + np.arange(3)) % 3, axis=1)
    k = np.arange(levels - 1, dtype=np.int64)[:, None, None] * n
    a, b, c = [(t[None, :, j] + k[..., 0])[..., None] for j in range(3)]
    a1, b1, c1 = a + n, b + n, c + n
    first = np.minimum(b, c1) < np.minimum(c, b1)
    t1 = np.where(first, np.concatenate([a, b, c, c1], -1), np.concatenate([a, b, c, b1], -1))
    t2 = np.where(first, np.concatenate([a, b, c1, b1], -1), np.concatenate([a, b1, c, c1], -1))
    t3 = np.concatenate([a, b1, c1, a1], -1)
    tets = np.stack([t1, t2, t3], axis=2).reshape(-1, 4)
    x = points[tets]
    vol = np.einsum("ij,ij->i", x[:, 1] - x[:, 0], np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]))
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]
    return points, tets


def sweep_mesh(poly, height: float, size_fn, n_layers: int, order: int = 1):
    """Mesh an extruded profile: graded 2-D triangulation swept through ``n_layers`` equal layers.

    Unlike tetgen on the closed surface, the layers resolve the through-thickness strain field
    everywhere (bending and shear of thin spokes), and the in-plane size follows ``size_fn``."""
    from flexure.mesh import Mesh, to_quadratic

    pts2, tri, _ = graded_triangulation(poly, size_fn)
    points, tets = sweep_tetrahedra(pts2, tri, np.linspace(0.0, height, int(n_layers) + 1))
    mesh = Mesh(points, tets)
    return to_quadratic(mesh) if order == 2 else mesh


@dataclass
class MeshResult:
    """``mesh`` (flexure.mesh.Mesh), the surface tetgen meshed (None for a swept mesh), the quality report."""

    mesh: object
    surface: Surface
    report: dict


def tetrahedralize(surface: Surface, h_far: float, minratio: float = 1.8, mindihedral: float = 10.0,
                   order: int = 1):
    """tetgen -pq{minratio}/{mindihedral}a{V}: returns flexure.mesh.Mesh (P1, or P2 via to_quadratic)."""
    import tetgen

    from flexure.mesh import Mesh, to_quadratic

    tg = tetgen.TetGen(np.ascontiguousarray(surface.points, float),
                       np.ascontiguousarray(surface.faces, np.int32))
    maxvol = h_far ** 3 / (6 * np.sqrt(2))
    try:
        nodes, elems, *_ = tg.tetrahedralize(plc=True, quality=True, minratio=minratio,
                                             mindihedral=mindihedral, maxvolume=maxvol,
                                             fixedvolume=True, quiet=True)
    except RuntimeError as exc:
        raise InputError(f"mesh: tetgen failed on the surface ({exc}); check it is closed and "
                         "not self-intersecting") from None
    if len(elems) == 0:
        raise InputError("mesh: tetgen produced no tetrahedra (self-intersecting surface?)")
    used = np.unique(elems[:, :4])
    remap = np.full(len(nodes), -1)
    remap[used] = np.arange(len(used))
    mesh = Mesh(np.asarray(nodes[used], float), remap[elems[:, :4]].astype(np.int64))
    if order == 2:
        mesh = to_quadratic(mesh)
    elif order != 1:
        raise InputError(f"mesh.order: must be 1 or 2, got {order!r}")
    return mesh


MESHERS = ("gmsh", "sweep", "tetgen")
def size_field(size: str, h_scale: float, gauge_centres, gauge_extent: float,
               gauge_width: float | None = None, h_factor: float = 1.0, surface: Surface | None = None,
               curvature_h_factor: float | None = None) -> SizeField:
    """h_far = f · SIZES[size].far · h_scale; h_gauge = f · SIZES[size].gauge · gauge width (≤ h_far),
    f = ``h_factor`` (the refinement levels of flexure.convergence). With the part's ``surface``,
    its sharp re-entrant edges (``reentrant_edges``) get h_edge = clip(f·D/EDGE_DISTANCE_RATIO,
    h_gauge, h_far/2), D the edge's distance to the nearest gauge grid, graded toward the edge
    (``edge_size``)."""
    if size not in SIZES:
        raise InputError(f"--size: must be one of {', '.join(SIZES)}, got {size!r}")
    s = SIZES[size]
    h_far = h_factor * s["far"] * h_scale
    h_gauge = min(h_factor * s["gauge"] * (gauge_width or gauge_extent), h_far)
    centres = np.asarray(gauge_centres, float).reshape(-1, 3)
    edges, h_edge = np.zeros((0, 2, 3)), np.zeros(0)
    if surface is not None and len(centres):
        edges = reentrant_edges(surface)
        mid = edges.mean(1)
        D = np.sqrt(((mid[:, None, :] - centres[None]) ** 2).sum(-1)).min(1) - gauge_extent
        h_edge = np.clip(h_factor * D / EDGE_DISTANCE_RATIO, h_gauge, h_far / 2)
    # grading × f and curvature elements / f too, so that the whole size function scales by f
    # (h_f(x) = f·h_1(x)): similar levels
    return SizeField(h_far, h_gauge, centres, r_gauge=gauge_extent, grading=SizeField.grading * h_factor,
                     curvature_elements=CURVATURE_ELEMENTS * SIZES["coarse"]["far"] / s["far"]
                     / (curvature_h_factor or h_factor),
                     edges=edges, h_edge=h_edge)


#: a re-entrant edge at distance D from a gauge is meshed at D / 4 (not finer than the gauges, not
#: coarser than half the far size, since every notch shapes the load path to the gauges): its
#: singular field (stress ~ r^(λ−1), λ ≈ 0.54 for a 90° notch) then pollutes the gauge reading no
#: more than the gauge's own discretisation. Without it, on the re-entrant part (gauges 1.3 mm from
#: sharp spoke roots) the gauge strain moved by up to 0.8 % between levels with no trend and the
#: stiffness was 1 % high (tests/data/fem_reference/levels.json).
EDGE_DISTANCE_RATIO = 4.0
#: a fold sharper than this between two faces of the surface is an edge (as gmsh's classification)
EDGE_ANGLE_DEG = 40.0


def reentrant_edges(surface: Surface, min_angle_deg: float = EDGE_ANGLE_DEG) -> np.ndarray:
    """The sharp re-entrant (concave) edges of a closed, outward-oriented triangulation: (k, 2, 3)
    segments where two faces meet at a fold of more than ``min_angle_deg`` with the material on
    the reflex side (a notch, a sharp spoke root), where the elastic field is singular."""
    from flexure.reentrant import fold_angles_deg

    edges, omega = fold_angles_deg(surface.points, surface.faces)
    return np.asarray(surface.points)[edges[omega > 180.0 + min_angle_deg]]


def mesh_design_surface(surface_or_poly, thickness: float | None, size: str, gauge_centres: np.ndarray,
                        gauge_extent: float, h_scale: float, order: int = 1,
                        gauge_width: float | None = None, mesher: str = "sweep",
                        h_factor: float = 1.0, max_elements: float = MAX_ELEMENTS, exact_disc=None,
                        curvature_h_factor: float | None = None,
                        feature_surface: Surface | None = None, stl_curvature: bool = False) -> MeshResult:
    """Mesh an extruded profile (shapely polygon + thickness) or a closed Surface (user STL).
    With ``exact_disc`` (a geometry.SpokeDisc) the gmsh mesher meshes that disc's exact solid
    (true circles and fillets, flexure.gmsh_mesh.mesh_spoke_disc) instead of the polygon.

    h_far = SIZES[size].far · h_scale (the thickness); h_gauge = SIZES[size].gauge · gauge width,
    within ``gauge_extent`` of each gauge centre, graded outwards. A profile is swept through
    ⌈thickness / h_gauge⌉ layers (``mesher="sweep"``), or its closed surface handed to tetgen
    (``"tetgen"``, which grades only from the surface); ``"gmsh"`` meshes the volume with the size
    field (isotropic, graded in 3-D; flexure.gmsh_mesh), re-meshing a Surface (STL) on the way;
    gmsh also refines toward the re-entrant edges of ``feature_surface`` (the part's closed surface;
    the Surface itself when one is given). ``stl_curvature``: a Surface's curved faces resolved as
    a CAD solid's (flexure.stl_remesh.mesh_surface ``curvature``).
    """
    if mesher not in MESHERS:
        raise InputError(f"mesh.mesher: must be one of {', '.join(MESHERS)}, got {mesher!r}")
    if feature_surface is None and isinstance(surface_or_poly, Surface):
        feature_surface = surface_or_poly
    field = size_field(size, h_scale, gauge_centres, gauge_extent, gauge_width, h_factor,
                       surface=feature_surface if mesher == "gmsh" else None,
                       curvature_h_factor=curvature_h_factor)
    s, h_far, h_gauge = SIZES[size], field.h_far, field.h_gauge
    surface, layers = None, None
    is_surface = isinstance(surface_or_poly, Surface)
    if is_surface:
        check_cost(field, surface_volume(surface_or_poly), surface_area(surface_or_poly), max_elements)
    else:
        perimeter = surface_or_poly.exterior.length + sum(r.length for r in surface_or_poly.interiors)
        check_cost(field, surface_or_poly.area * thickness,
                   2 * surface_or_poly.area + perimeter * thickness, max_elements)
    if is_surface and mesher == "sweep":
        mesher = "gmsh"                          # a closed surface is not an extrusion
    if mesher == "gmsh":
        from flexure import gmsh_mesh
        if is_surface:
            from flexure.stl_remesh import mesh_surface
            surface = surface_or_poly
            mesh = mesh_surface(surface, field, order, curvature=stl_curvature)
        else:
            mesh = (gmsh_mesh.mesh_spoke_disc(exact_disc, field, order) if exact_disc is not None else
                    gmsh_mesh.mesh_extrusion(surface_or_poly, thickness, field, order))
    elif mesher == "tetgen":
        surface = surface_or_poly if is_surface else extrude_graded(surface_or_poly, thickness, field)
        mesh = tetrahedralize(surface, h_far, s["minratio"], s["mindihedral"], order)
    else:
        layers = max(2, int(np.ceil(thickness / h_gauge - 1e-9)))
        mesh = sweep_mesh(surface_or_poly, thickness, field, layers, order)
    return MeshResult(mesh, surface, mesh_report(mesh, size, mesher, layers, field, surface))


def mesh_report(mesh, size: str, mesher: str, layers, field: SizeField, surface: Surface | None = None) -> dict:
    """Quality (min/max dihedral, aspect and radius-edge ratios, slivers) and sizing of a mesh; for
    a re-meshed closed surface also the relative volume change (the re-mesh is a geometry change)."""
    from flexure.mesh import quality

    rep = quality(mesh)
    rep.update({"size": size, "mesher": mesher, "layers": layers, "h_far_m": field.h_far,
                "h_gauge_m": field.h_gauge, "surface_triangles": int(len(mesh.boundary_faces()))})
    if surface is not None and mesher == "gmsh":
        v0 = surface_volume(surface)
        rep["remesh_volume_change"] = float(rep["total_volume_m3"] / v0 - 1.0) if v0 > 0 else math.nan
    attempts = mesh._cache.get("attempts")
    if attempts:                                # gmsh's meshing attempts (gmsh_mesh._session)
        rep["mesh_attempts"] = attempts
        kept = next(a for a in attempts if a.get("kept"))
        if "surface_distance_m" in kept:
            rep["remesh_surface_distance_m"] = kept["surface_distance_m"]
    return rep


def surface_area(surface: Surface) -> float:
    """Area of a triangulation: Σ |(x_b − x_a) × (x_c − x_a)| / 2."""
    x = surface.points[surface.faces]
    return float(0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1).sum())


def surface_volume(surface: Surface) -> float:
    """Enclosed volume of a closed, outward-oriented triangulation: V = Σ x_a·(x_b × x_c)/6."""
    x = surface.points[surface.faces]
    return float(np.einsum("ij,ij->i", x[:, 0], np.cross(x[:, 1], x[:, 2])).sum() / 6.0)
