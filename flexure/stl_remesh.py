"""An STL as a designer exports it (long needle triangles, thin walls), re-meshed by gmsh without
slivers, its geometry kept.

gmsh re-meshes a triangulated surface by classifying its triangles into patches (a fold sharper
than ``angle_deg`` is an edge), re-parametrising each patch and triangulating it anew at the size
field's size (``classifySurfaces`` + ``createGeometry``). A patch must map to a disc, so the flat
face of a disc with spoke windows is cut into pieces, and the cuts run along the STL's own
triangle edges. On a trimesh ``extrude_polygon`` part (earcut: caps of triangles 60 mm long and
0.2 mm wide) those cuts meet the patch edges at a fraction of a degree; the pieces' corners are
then needles that no volume optimiser can move, standing under 0.7–1.3° tetrahedra at every
level however fine the mesh around them (the issue's designer disc, 60 mm, four spokes, 5 mm:
1.2°, 1.2°, 1.3° at h × √2, 1, 1/√2, 51–73 tetrahedra below 10°, after gmsh's two passes finer
around them). Three surface strategies:

    direct                classify the STL's triangles, patches cut to be parametrisable (gmsh's t13)
    re-parametrised       first re-triangulate the STL's patches uncut at the field's size (gmsh
                          parametrises each whole), which leaves well-shaped triangles, then re-mesh
                          *those* patches as they were classified (``patch_topology``: their curves
                          rebuilt from where they meet): whatever gmsh cuts internally now runs
                          along well-shaped triangles
    re-parametrised, cut  the same, the re-triangulation classified anew, cut into parametrisable
                          patches

An STL with needle triangles (an angle below NEEDLE_DEG) tries the re-parametrised ones first, and
direct only where neither made a mesh keeping the geometry (``mesh_surface``'s fallback): on every needle STL
measured, direct's first pass was the worst of the three (2026-11-28, the adaptive start mesh; min
dihedral angle of direct / re-parametrised: thick disc 7.9° / 13.0°, six_spoke_thick 0.0° / 13.1°, a
five-spoke disc with bolt holes 0.04° / 8.3°, a rim with eight bolt holes 0.08° / 5.3°, the designer
discs of tests/test_stl_remesh.py with 3, 4 and 6 spokes 3.3° / 12.8°, 0.7° / 15.8°, 1.3° / 14.5°),
and its passes cost the bolt-hole discs 8 s of CPU each for a mesh never kept. An STL without
needles tries direct first. While the volume mesh has a tetrahedron below
gmsh_mesh.MIN_DIHEDRAL_DEG: the next strategy, then, once every strategy has made one, those that
left such tetrahedra once more, finer around them (gmsh_mesh._session's spots): at most
MAX_ATTEMPTS = 5 volume meshes (on idle cores those that
may be asked for next run ahead in parallel processes, flexure.gmsh_attempts: the same meshes).
Every attempt's geometry is checked against the STL (``geometry_check``): volume within
VOLUME_TOL and every boundary vertex of either surface within SURFACE_TOL_REL × h_far of the
other (a re-parametrisation that dropped or moved a feature is not kept while another attempt
keeps the geometry).

Measured (tests/test_stl_remesh.py builds the parts; loaded machine): the designer disc in one
attempt at each level, 13.2°, 14.8°, 15.3° (65–81 s per level, where the three passes on the STL's
own triangles took 86–146 s), volume within 0.05 %, surface within 0.1 mm; 3-, 4-, 5- and 6-spoke
discs 14.5–18.7° where direct left 0.2–3.3°; a 0.8 mm walled tube 16.2° (direct 3.1°). The cut
variant (second classification cut) left 3.9–9.7° on the discs, the reason it is not the first.

Why the re-triangulation is not classified again (2026-11-28). Classifying it anew by its folds
found other patches than the first classification had (the thick disc's STL: 31 where there were
30; without curvature spots 66), and on both the thick disc's STL and a five-spoke designer disc with
bolt holes gmsh refused the result ("Wrong topology of boundary mesh for parametrization"): the
strategy failed, and the designer disc was left with the STL's own needles (0.04°, 288 tetrahedra
below 10°; its adaptive run's enriched solve then did not converge and it had no error bar). Kept as
classified, the thick disc's STL meshes clean in one pass (13.0°, 4.3 s for the start mesh where five
attempts took 10–15 s and kept 9.6°) and the designer disc's first pass gives 8.3°. The curves are
built here, not by gmsh's ``createTopology``, which numbers them in memory order: its meshes changed
from run to run (8.8–9.8° on the same input).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from flexure import gmsh_mesh
from userio.errors import InputError
from flexure.gmsh_mesh import MM, QUALITY_PASSES

#: an STL triangle with an angle below this is a needle (the re-parametrised strategy goes first)
NEEDLE_DEG = 10.0
#: the strategies tried, then QUALITY_PASSES finer around the slivers: the bound on volume meshes
MAX_ATTEMPTS = 3 + QUALITY_PASSES
#: |V_mesh / V_STL − 1| allowed (the remesh replaces the STL's facets by new chords)
VOLUME_TOL = 0.01
#: surface distance allowed between the re-meshed boundary and the STL, × the far element size
#: h_far: new chords across the STL's curved facets deviate by their sagitta h²/8R ≤ h/8 where a
#: curve of radius R ≥ h is resolved (measured: 31–40 µm at h = 1.5 mm on the 9 mm hub of a
#: designer disc, 0.05–0.1 mm on the whole disc); a lost or moved feature shows as more
SURFACE_TOL_REL = 0.125


def triangle_min_angles_deg(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Smallest angle of each triangle (degrees), from the law of cosines."""
    x = np.asarray(points, float)[np.asarray(faces)]
    e = np.linalg.norm(x[:, [1, 2, 0]] - x[:, [2, 0, 1]], axis=2)       # edge opposite vertex k
    a, b, c = e[:, 0], e[:, 1], e[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        cos = np.stack([(b * b + c * c - a * a) / (2 * b * c), (a * a + c * c - b * b) / (2 * a * c),
                        (a * a + b * b - c * c) / (2 * a * b)], axis=1)
    return np.degrees(np.arccos(np.clip(np.nan_to_num(cos, nan=1.0), -1.0, 1.0))).min(axis=1)


def _add_discrete(gmsh, points_mm: np.ndarray, faces: np.ndarray) -> None:
    tag = gmsh.model.addDiscreteEntity(2)
    gmsh.model.mesh.addNodes(2, tag, np.arange(1, len(points_mm) + 1), np.asarray(points_mm, float).ravel())
    gmsh.model.mesh.addElementsByType(tag, 2, [], (np.asarray(faces) + 1).ravel())


def _closed_volume(gmsh) -> None:
    surfs = [t for _, t in gmsh.model.getEntities(2)]
    gmsh.model.geo.addVolume([gmsh.model.geo.addSurfaceLoop(surfs)])
    gmsh.model.geo.synchronize()


def _surface_patches(gmsh):
    """The current model's surface mesh → (points in gmsh's units, [triangles of each surface entity]),
    conforming: one node numbering for all, the patches as gmsh classified them."""
    tags, coords, _ = gmsh.model.mesh.getNodes()
    index = np.zeros(int(tags.max()) + 1, np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    patches = [index[np.asarray(gmsh.model.mesh.getElementsByType(2, t)[1], np.int64)].reshape(-1, 3)
               for _, t in gmsh.model.getEntities(2)]
    used = np.unique(np.concatenate(patches))
    remap = np.full(len(tags), -1)
    remap[used] = np.arange(len(used))
    return np.asarray(coords, float).reshape(-1, 3)[used], [remap[p] for p in patches]


def patch_topology(patches: list) -> tuple[list, list, list]:
    """The curves where the patches of a closed triangulated surface meet, and their end points:
    (curves, points, each patch's curve indices). A curve is a chain of edges shared by the same
    two patches, ended where the chain meets another (a vertex on three or more patches' edges, or
    where the pair changes); a closed chain without such a vertex starts and ends at its smallest
    node. curves: node sequences (closed: first == last); points: node indices. Deterministic: the
    order follows the node numbers, not memory."""
    owner, edges = [], []
    for k, tri in enumerate(patches):
        e = np.sort(np.asarray(tri, np.int64)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        u, c = np.unique(e, axis=0, return_counts=True)
        edges.append(u[c == 1])                                  # the patch's boundary edges
        owner.append(np.full(int((c == 1).sum()), k))
    e, o = np.vstack(edges), np.concatenate(owner)
    order = np.lexsort((o, e[:, 1], e[:, 0]))
    e, o = e[order], o[order]

    def key(i, j):
        return (i, j) if i < j else (j, i)

    pair = {}                                                    # edge → (patch a, patch b)
    for (i, j), k in zip(map(tuple, e), o):
        pair.setdefault((int(i), int(j)), []).append(int(k))
    pair = {ed: tuple(ks) for ed, ks in pair.items()}
    nbr: dict = {}
    for (i, j) in pair:
        nbr.setdefault(i, []).append(j)
        nbr.setdefault(j, []).append(i)
    corner = {v for v, ns in nbr.items() if len(ns) != 2 or pair[key(ns[0], v)] != pair[key(v, ns[1])]}
    seen, curves = set(), []
    for v in sorted(corner) + sorted(nbr):                       # from the corners, then the closed chains
        for w in sorted(nbr[v]):
            if key(v, w) in seen:
                continue
            chain = [v, w]
            seen.add(key(v, w))
            while chain[-1] not in corner and chain[-1] != v:
                u = chain[-1]
                ahead = [x for x in nbr[u] if key(u, x) not in seen]
                if not ahead:
                    break
                seen.add(key(u, ahead[0]))
                chain.append(ahead[0])
            curves.append(chain)
    points = sorted({c[0] for c in curves} | {c[-1] for c in curves})
    of_patch = [[] for _ in patches]
    for n, c in enumerate(curves):
        for k in pair[key(c[0], c[1])]:
            of_patch[k].append(n)
    return curves, points, of_patch


def _add_patches(gmsh, points_mm: np.ndarray, patches: list) -> None:
    """Each patch its own discrete surface, bounded by the discrete curves where it meets the others
    (``patch_topology``): the classification kept as it is, not guessed again from the folds."""
    curves, corners, of_patch = patch_topology(patches)
    dim = np.full(len(points_mm), 2)
    for c in curves:
        dim[c[1:-1]] = 1
    dim[corners] = 0
    x = np.asarray(points_mm, float)
    ptag = {}
    for v in corners:
        ptag[v] = gmsh.model.addDiscreteEntity(0)
        gmsh.model.mesh.addNodes(0, ptag[v], [v + 1], x[v])
        gmsh.model.mesh.addElementsByType(ptag[v], 15, [], [v + 1])
    ctags = []
    for c in curves:
        tag = gmsh.model.addDiscreteEntity(1, -1, [ptag[c[0]], ptag[c[-1]]])
        inner = np.asarray(c[1:-1], np.int64)
        gmsh.model.mesh.addNodes(1, tag, inner + 1, x[inner].ravel())
        seg = np.column_stack([c[:-1], c[1:]]) + 1
        gmsh.model.mesh.addElementsByType(tag, 1, [], seg.ravel())
        ctags.append(tag)
    for tri, cs in zip(patches, of_patch):
        tag = gmsh.model.addDiscreteEntity(2, -1, [ctags[n] for n in cs])
        inner = np.unique(np.asarray(tri, np.int64))
        inner = inner[dim[inner] == 2]
        gmsh.model.mesh.addNodes(2, tag, inner + 1, x[inner].ravel())
        gmsh.model.mesh.addElementsByType(tag, 2, [], (np.asarray(tri) + 1).ravel())


def _strategy(what: str):
    """A build whose gmsh failure is an InputError naming ``what`` (gmsh_mesh._session then tries
    the next strategy); Ctrl-C in the size callback stays a KeyboardInterrupt."""

    def wrap(build):
        def run(gmsh):
            try:
                build(gmsh)
            except Exception as exc:
                gmsh_mesh._INTERRUPT.check()
                raise InputError(f"{what} failed ({str(exc).splitlines()[0]})") from None
            gmsh_mesh._INTERRUPT.check()
        return run

    return wrap


def build_direct(surface, angle_deg: float):
    """The STL's own triangles classified into parametrisable patches (cut where needed)."""

    @_strategy("classifying the STL's triangles")
    def build(gmsh):
        gmsh.model.add("stl")
        _add_discrete(gmsh, surface.points * MM, surface.faces)
        gmsh.model.mesh.classifySurfaces(np.deg2rad(angle_deg), True, True, np.pi)
        gmsh.model.mesh.createGeometry()
        _closed_volume(gmsh)

    return build


def build_reparametrised(surface, angle_deg: float, cut: bool = False):
    """Re-triangulate the STL's patches, uncut, at the size field's size (gmsh_mesh._one_pass sets
    it on the current model before the build), then re-mesh those patches as classified
    (``_add_patches``; ``cut``: the triangulation classified anew, cut into parametrisable patches,
    as ``build_direct``)."""

    @_strategy("re-parametrising the STL")
    def build(gmsh):
        _add_discrete(gmsh, surface.points * MM, surface.faces)
        gmsh.model.mesh.classifySurfaces(np.deg2rad(angle_deg), True, False, np.pi)
        gmsh.model.mesh.createGeometry()
        gmsh.model.mesh.generate(2)
        pts, patches = _surface_patches(gmsh)
        gmsh.model.remove()
        gmsh.model.add("stl")
        if cut:
            _add_discrete(gmsh, pts, np.vstack(patches))
            gmsh.model.mesh.classifySurfaces(np.deg2rad(angle_deg), True, True, np.pi)
        else:
            _add_patches(gmsh, pts, patches)
        gmsh.model.mesh.createGeometry()
        _closed_volume(gmsh)

    return build


def has_needles(surface) -> bool:
    """Whether an STL has a triangle with an angle below NEEDLE_DEG."""
    return bool((triangle_min_angles_deg(surface.points, surface.faces) < NEEDLE_DEG).any())


def strategies(surface, angle_deg: float, needles: bool | None = None) -> list:
    """[(name, build)] in the order tried (module docstring); ``needles``: ``has_needles(surface)``
    where the caller has it."""
    direct = ("direct", build_direct(surface, angle_deg))
    reparam = [("re-parametrised", build_reparametrised(surface, angle_deg)),
               ("re-parametrised, cut", build_reparametrised(surface, angle_deg, cut=True))]
    return reparam + [direct] if (has_needles(surface) if needles is None else needles) else [direct] + reparam


def geometry_check(surface, h_far_m: float):
    """check(points, tets, entities) → {"ok", "volume_change", "surface_distance_m"} of a mesh of
    ``surface`` (the STL, m); the distance is the symmetric one between the mesh's boundary
    triangles and the STL's over their vertices (flexure.surface_distance.hausdorff), inf beyond
    the tolerance."""
    from flexure.surface_distance import hausdorff

    s = surface.points[surface.faces]                   # enclosed volume Σ x_a·(x_b × x_c)/6
    v0 = float(np.einsum("ij,ij->i", s[:, 0], np.cross(s[:, 1], s[:, 2])).sum() / 6.0)
    tol = SURFACE_TOL_REL * h_far_m

    def check(points, tets, entities):
        x = points[tets]
        v = float(np.abs(np.einsum("ij,ij->i", x[:, 1] - x[:, 0],
                                   np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]))).sum() / 6.0)
        dv = v / v0 - 1.0
        d = hausdorff(points, entities[0], surface.points, surface.faces, 4 * tol)
        return {"ok": bool(abs(dv) <= VOLUME_TOL and d <= tol), "volume_change": float(dv),
                "surface_distance_m": float(d), "surface_tolerance_m": tol}

    return check


def curvature_spots(surface, elements_per_turn: float, h_far: float, angle_deg: float = 40.0) -> np.ndarray:
    """Local sizes (k, 4: x, y, z, h; m) that resolve an STL's curved faces: at every fold between two
    facets gentler than ``angle_deg`` (sharper ones are edges) but not flat, the radius its facets
    approximate, R = w / φ (φ the fold angle, w the facets' mean width across the fold: a polygon of
    facets of width w on a circle of radius R turns by w/R per facet), and h = 2πR / elements_per_turn
    where that is below ``h_far``, at points ≤ h apart along the fold; one spot per cell of the
    smallest h (the smallest h in it)."""
    import trimesh

    if elements_per_turn <= 0:
        return np.zeros((0, 4))
    tm = trimesh.Trimesh(surface.points, surface.faces, process=False)
    phi = tm.face_adjacency_angles
    edges = surface.points[tm.face_adjacency_edges]                          # (k,2,3)
    L = np.linalg.norm(edges[:, 1] - edges[:, 0], axis=1)
    w = (tm.area_faces[tm.face_adjacency].sum(axis=1)) / np.maximum(L, 1e-300)   # mean height 2A/L over 2
    fold = (phi > np.deg2rad(0.1)) & (phi < np.deg2rad(angle_deg))
    h = 2 * np.pi * (w / np.maximum(phi, 1e-300)) / elements_per_turn
    keep = fold & (h < h_far)
    if not keep.any():
        return np.zeros((0, 4))
    e, h, L = edges[keep], h[keep], L[keep]
    n = np.ceil(L / h).astype(np.int64) + 1                                   # points along each fold, ≤ h apart
    k = np.repeat(np.arange(len(e)), n)
    t = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n - 1, n)
    x, h = e[k, 0] + t[:, None] * (e[k, 1] - e[k, 0]), h[k]
    cell = np.floor(x / h.min()).astype(np.int64)
    _, inv = np.unique(cell, axis=0, return_inverse=True)
    order = np.lexsort((h, inv.ravel()))
    first = order[np.r_[True, inv.ravel()[order][1:] != inv.ravel()[order][:-1]]]
    return np.column_stack([x[first], h[first]])


def mesh_surface(surface, field, order: int = 1, where: str = "mesh", angle_deg: float = 40.0,
                 curvature: bool = False):
    """Re-mesh a closed triangulated surface (STL, m) and its volume with the size field
    (module docstring: the strategies, the attempts, the geometry check). gmsh's curvature term is
    not used: a triangulated surface is its facets, and gmsh reads every fold between facets as a
    tight radius and refines along it (the adaptive start of a six-spoke designer STL with it: 184 k
    DOFs, 566 s). With ``curvature`` the curved faces are resolved from the STL's own folds instead
    (``curvature_spots``, field.curvature_elements per turn). The adaptive analysis asks for it
    (flexure.adaptive.start_mesh): its first mesh is put on the STL node by node
    (flexure.refine.morph), and a 3 mm bore meshed with chords across 65° of it has mid nodes 0.48 mm
    off the STL, a move that folds the elements along it (measured on 24-, 48- and 192-sided annuli:
    11–35 boundary nodes left partly moved without, none with, at 4.8–6.1 k DOFs)."""
    spots = curvature_spots(surface, field.curvature_elements, field.h_far, angle_deg) if curvature else None
    field = replace(field, curvature_elements=0.0)
    if spots is not None and len(spots):
        field = replace(field, spots=spots)
    needles = has_needles(surface)           # direct then a fallback, tried only without a kept mesh
    return gmsh_mesh._session(strategies(surface, angle_deg, needles), field, where, order,
                              check=geometry_check(surface, field.h_far), fallback=("direct",) if needles else ())
