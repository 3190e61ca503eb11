"""Graded isotropic tetrahedral meshes with gmsh's size fields, for every kind of input.

The size at a point is the project's ``sizing.SizeField``, given to gmsh as its size callback:
the smallest of

    h_gauge + g (d − r_gauge)          d: distance to the nearest gauge centre   (≥ h_gauge)
    sizing.edge_size(h_edge, d_e)      d_e: distance to a sharp re-entrant edge, graded as √d_e
                                       down to h_edge / 4 at the edge
    2πR / curvature_elements           on a curved edge or face of radius R (gmsh's own, CAD only)
    h_far

with g = 0.35 (grading), every term scaled with the refinement level. The *volume* is meshed with
this field (not just the surface, as with tetgen), so a gauge is covered by several isotropic
elements whatever the STL's triangles: an STL is re-meshed through gmsh's
``classifySurfaces``/``createGeometry`` (its triangles only define the shape; flexure.stl_remesh), a parametric profile
is extruded in OpenCASCADE and a STEP solid is meshed directly on its exact geometry, and so is the
parametric spoke disc (an exact OpenCASCADE solid, ``mesh_spoke_disc``). gmsh's Delaunay 3-D +
optimisers (VOLUME_OPTIONS). Everything in gmsh is in millimetres (its tolerances are absolute).

P2 on an exact solid (spoke disc, STEP) is isoparametric: the mid-edge nodes of boundary edges are
gmsh's second-order nodes, on the true curved faces (``_curved_quadratic``). With mid-edge nodes on
the chords instead, the rigidly coupled bore was a polygon inscribed in its circle, a coupling
radius short by the sagitta, which made the stiffness too low by an O(h²) amount of the opposite
sign to the discretisation's own (too stiff) error: on the STEP part refining only the bore
raised the stiffness by 0.6 % at h × 1, and the sum of the two errors fell by about the same
amount per level at the finest levels (order ≈ 0). Curved, the STEP part's stiffness converges at
order 1.8 (h × 1 → 1/√2 → 1/2: 2793.7, 2781.2, 2774.4 N·m/rad) and refining the bore lowers it, as
refining must. An STL keeps straight P2 (its facets are the geometry).
"""

from __future__ import annotations

import numpy as np

from userio.errors import CallbackInterrupt, InputError

from flexure.gmsh_session import LC_INTEGRATION_PRECISION, _quiet_stdout, open_session
from flexure.sizing import edge_size

MM = 1e3                        # metres → gmsh units (mm)
#: gmsh options of the volume mesh: Delaunay 3-D, gmsh's optimiser on every tetrahedron of quality
#: below 0.7 (default 0.3), Netgen's optimiser, 10 smoothing passes; ``_volume_tets`` then runs
#: gmsh's optimiser once more on the Netgen-optimised mesh. Minimum dihedral angle at the answer
#: level (h × 1/√2), measured: paper disc 13.1°, re-entrant 12.3°, thick disc 14.4°, STEP part 12.5°
#: (before LC_INTEGRATION_PRECISION: 13.5°, 14.3°, 12.6°, 11.0°; threshold 0.5 without the last
#: pass: 12.3°, 9.9°, 14.1°, 11.9°; threshold 0.9: 14.6°, 16.2°, 10.8°, 12.1°), for ±1 % elements
#: and ≤ 10 % more meshing time; at h × 1: 10.3–14.7°. The former polygonal profile gave 6.0°, whatever these options. HXT (Algorithm3D 10)
#: gave 5.9–7.7° on three of the four. A re-meshed STL keeps a few 5–8° tetrahedra whatever the
#: volume options (the thick disc's STL: 4.9° at the answer level): they stand on needle surface
#: triangles (angles 4°/172°/4°) of the re-parametrised walls of its 12-gon hub bolt holes (0.57 mm
#: facets, 30° folds), which no volume optimiser may move. gmsh's MeshAdapt surface algorithm
#: (Mesh.Algorithm 1) gave 10.5° there but 9 % fewer elements, 30 % more time and a re-meshed volume
#: 0.65 % off the STL's (0.46 % with the default), so it is not used. What lifts these (and the
#: plate-spanning tetrahedra of a CAD part) is a second pass finer around them: MIN_DIHEDRAL_DEG;
#: an STL's needle walls went only when its surface was re-triangulated first (flexure.stl_remesh).
VOLUME_OPTIONS = {"Mesh.Algorithm3D": 1, "Mesh.Optimize": 1, "Mesh.OptimizeNetgen": 1,
                  "Mesh.OptimizeThreshold": 0.7, "Mesh.Smoothing": 10}

_INTERRUPT = CallbackInterrupt()     # Ctrl-C inside gmsh's size callback → KeyboardInterrupt after it


def _size_field(gmsh, field, spots=None) -> None:
    """Mesh size from ``field`` (sizing.SizeField, metres: h = clip(h_gauge + g(d − r_gauge),
    h_gauge, h_far), and 2πR / curvature_elements on curved edges and faces) through gmsh's size
    callback, in mm; ``spots`` (k, 4: x, y, z, h in mm) add h_k + g·d_k around the tetrahedra a
    previous pass left too flat (``_session``)."""
    spots = np.zeros((0, 4)) if spots is None else np.asarray(spots, float).reshape(-1, 4)
    spots = np.vstack([spots, np.asarray(getattr(field, "spots", np.zeros((0, 4))), float).reshape(-1, 4) * MM])
    c = np.asarray(field.centres, float).reshape(-1, 3) * MM
    h0, h1, r0, g = field.h_gauge * MM, field.h_far * MM, field.r_gauge * MM, field.grading

    edges = np.asarray(field.edges, float).reshape(-1, 2, 3) * MM
    e0, ev = edges[:, 0], edges[:, 1] - edges[:, 0]
    ev2 = np.maximum((ev * ev).sum(1), 1e-300)
    he = np.asarray(field.h_edge, float) * MM

    def size(dim, tag, x, y, z, lc):           # lc: gmsh's own size there (curvature, ≤ h_far)
        h = min(lc, h1)
        if len(c):
            d = float(np.sqrt(((c - (x, y, z)) ** 2).sum(1)).min())
            h = min(h, max(h0 + g * (d - r0), h0))
        if len(he):                             # distance to each re-entrant edge segment
            w = np.array((x, y, z)) - e0
            t = np.clip((w * ev).sum(1) / ev2, 0.0, 1.0)
            d = np.sqrt(((w - t[:, None] * ev) ** 2).sum(1))
            h = min(h, float(edge_size(he, d, g, r0).min()))
        if len(spots):
            d = np.sqrt(((spots[:, :3] - (x, y, z)) ** 2).sum(1))
            h = min(h, float((spots[:, 3] + g * d).min()))
        return h

    from flexure import gmsh_size

    fast = gmsh_size.kernel()               # the same formula compiled (flexure.gmsh_size): µs a call
    if fast is not None:
        prm = np.array([h1, h0, r0, g], float)
        cc, ee = np.ascontiguousarray(c, float), gmsh_size.pack_edges(e0, ev, ev2, he)
        ss, sb, sf = gmsh_size.pack_spots(spots)

        def size(dim, tag, x, y, z, lc):    # noqa: F811 (the numpy form above is the reference)
            return fast(x, y, z, lc, prm, cc, ee, ss, sb, sf)

    gmsh.model.mesh.setSizeCallback(_INTERRUPT.wrap(size, 0.0))   # Ctrl-C: size 0 stops gmsh
    gmsh.option.setNumber("Mesh.LcIntegrationPrecision", LC_INTEGRATION_PRECISION)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", float(field.curvature_elements))
    gmsh.option.setNumber("Mesh.MeshSizeMax", h1)


def _volume_tets(gmsh, where: str):
    """Generate the 3-D mesh (Delaunay, gmsh- and Netgen-optimised, then gmsh's optimiser once
    more) → (points m, corner tets, the boundary classification ``_entities``)."""
    for key, value in VOLUME_OPTIONS.items():
        gmsh.option.setNumber(key, value)
    try:
        gmsh.model.mesh.generate(3)
        gmsh.model.mesh.optimize("", False, 1)       # after Netgen: lifts the worst tetrahedra
    except Exception as exc:
        _INTERRUPT.check()                           # Ctrl-C in the size callback stopped gmsh
        raise InputError(f"{where}: gmsh could not mesh the volume ({str(exc).splitlines()[0]})") from None
    _INTERRUPT.check()
    tags, coords, _ = gmsh.model.mesh.getNodes()
    _, enodes = gmsh.model.mesh.getElementsByType(4)
    if len(enodes) == 0:
        raise InputError(f"{where}: gmsh produced no tetrahedra (is the surface closed?)")
    index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    tets = index[np.asarray(enodes, np.int64)].reshape(-1, 4)
    used = np.unique(tets)
    remap = np.full(len(tags), -1)
    remap[used] = np.arange(len(used))
    points = np.asarray(coords, float).reshape(-1, 3)[used] / MM
    tets = remap[tets]
    x = points[tets]
    vol = np.einsum("ij,ij->i", x[:, 1] - x[:, 0], np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]))
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]
    return points, tets, _entities(gmsh, remap[index])


def _entities(gmsh, node_of_tag: np.ndarray):
    """The boundary triangles and curve segments gmsh made, with the tag of the surface or curve
    each lies on, in our node numbering: (triangles (k,3), their tags, lines (j,2), their tags)
    (flexure.project.classify; what new nodes of a refined mesh are projected onto)."""
    out = []
    for dim, etype, nn in ((2, 2, 3), (1, 1, 2)):
        conn, tags = [np.zeros((0, nn), np.int64)], [np.zeros(0, np.int64)]
        for _, tag in gmsh.model.getEntities(dim):
            _, enodes = gmsh.model.mesh.getElementsByType(etype, tag)
            e = node_of_tag[np.asarray(enodes, np.int64)].reshape(-1, nn)
            e = e[(e >= 0).all(axis=1)]
            conn.append(e)
            tags.append(np.full(len(e), tag, np.int64))
        out += [np.vstack(conn), np.concatenate(tags)]
    return tuple(out)


def _geometric_midpoints(gmsh, points: np.ndarray):
    """gmsh's second-order nodes (``setOrder(2)``: mid-edge nodes of boundary edges on the CAD
    surface) → (edge codes lo·n + hi in our node numbering, mid-edge points m). Each of a
    10-node element's six extra nodes is matched to the corner pair whose midpoint is nearest
    (its offset from the chord's midpoint, the sagitta, is far below half an edge), so gmsh's
    node ordering is not assumed."""
    from scipy.spatial import cKDTree

    from flexure.mesh import TET_EDGES

    gmsh.model.mesh.setOrder(2)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    xyz = np.zeros((int(tags.max()) + 1, 3))
    xyz[tags.astype(np.int64)] = np.asarray(coords, float).reshape(-1, 3) / MM
    _, enodes = gmsh.model.mesh.getElementsByType(11)               # 10-node tetrahedra
    e = np.asarray(enodes, np.int64).reshape(-1, 10)
    corner, extra = xyz[e[:, :4]], xyz[e[:, 4:]]
    pairs = TET_EDGES
    chord_mid = 0.5 * (corner[:, pairs[:, 0]] + corner[:, pairs[:, 1]])        # (m, 6, 3)
    d = ((extra[:, :, None, :] - chord_mid[:, None, :, :]) ** 2).sum(-1)        # (m, extra, pair)
    k = d.argmin(axis=2)
    tree = cKDTree(points)                  # setOrder may renumber: corners found by position
    dist, idx = tree.query(corner.reshape(-1, 3))
    if dist.max() > 1e-9 * np.ptp(points, axis=0).max():
        raise RuntimeError("second-order mesh corners do not match the first-order mesh")
    idx = idx.reshape(-1, 4)
    a = np.take_along_axis(idx, pairs[k, 0], axis=1)
    b = np.take_along_axis(idx, pairs[k, 1], axis=1)
    codes = np.minimum(a, b) * np.int64(len(points)) + np.maximum(a, b)
    codes, first = np.unique(codes.ravel(), return_index=True)
    return codes, extra.reshape(-1, 3)[first]


#: a curved element is kept where det J at every quadrature point and node is at least this
#: fraction of its straight (affine) value; below it the element is nearly folded by its curved
#: edge and its nodal strains are spurious (det J down to 0.005× on the paper disc's fillets at
#: h × √2 gave a 965 MPa peak von Mises where the straight mesh reads 60.6 MPa; with it, 64.3 MPa)
MIN_SCALED_JACOBIAN = 0.25


def _curved_quadratic(points: np.ndarray, tets: np.ndarray, codes: np.ndarray, mids: np.ndarray):
    """P2 mesh whose mid-edge nodes are gmsh's geometric ones (on the curved faces), straightened
    back to the chord's midpoint on every element whose Jacobian falls below MIN_SCALED_JACOBIAN × its
    straight value at a quadrature point or node (where the strains are read: flexure.post), until
    none does."""
    from flexure.fem import TET_QUAD, tet_shape
    from flexure.mesh import Mesh, unique_edges
    from flexure.post import REF_NODES

    edges, e2e = unique_edges(tets, len(points))
    mid = 0.5 * (points[edges[:, 0]] + points[edges[:, 1]])
    at = np.minimum(np.searchsorted(codes, edges[:, 0] * np.int64(len(points)) + edges[:, 1]), len(codes) - 1)
    found = codes[at] == edges[:, 0] * np.int64(len(points)) + edges[:, 1]
    curved = found & (np.abs(mids[at] - mid).max(axis=1) > 0)
    mid[curved] = mids[at[curved]]
    _, dN = tet_shape(2, np.vstack([TET_QUAD[2][0], REF_NODES[:10]]))
    for _ in range(5):
        elements = np.flatnonzero(curved[e2e].any(axis=1))
        if len(elements) == 0:
            break
        X = np.concatenate([points[tets[elements]], mid[e2e[elements]]], axis=1)
        J = np.einsum("eai,qak->eqik", X, dN)
        affine = np.linalg.det(X[:, 1:4] - X[:, :1])[:, None]                 # the straight element's
        bad = elements[~(np.linalg.det(J) > MIN_SCALED_JACOBIAN * affine).all(axis=1)]
        if len(bad) == 0:
            break
        straight = e2e[bad].ravel()
        mid[straight] = 0.5 * (points[edges[straight, 0]] + points[edges[straight, 1]])
        curved[straight] = False
    return Mesh(np.vstack([points, mid]), np.hstack([tets.astype(np.int64), len(points) + e2e]))


#: a tetrahedron with a dihedral angle below this sends the mesher back (``_session``): the
#: volume is meshed again with the size reduced around it to SPOT_REFINEMENT × its longest edge
#: (graded away like the gauges' size), at most QUALITY_PASSES times, each pass adding the new bad
#: ones; the mesh with the largest minimum angle is kept. Such a tetrahedron has all four nodes on
#: the surface where one far-size element spans a plate (the re-entrant part's rim at h × 1/√2:
#: 9.7°, whatever the optimiser, Relocate3D or random seed), or stands on a needle triangle of a
#: re-meshed STL wall; no optimiser moves surface nodes, a finer surface there removes both.
#: Measured at h × 1/√2: re-entrant 9.7° → 12.7° (+1 % elements), the thick disc's STL 5.4° →
#: 9.8° → 10.8° (+6 %), an eight-spoke disc with 0.8 mm fillets 8.0° → 7.6° → 11.1° (+7 %).
#: A spot size of 0.5 × the longest edge left the re-entrant part's mesh unchanged.
MIN_DIHEDRAL_DEG = 10.0
QUALITY_PASSES = 2
SPOT_REFINEMENT = 0.2
#: the adaptive analysis's first mesh goes back only for a tetrahedron below this (``finer_below``):
#: its refinement and estimates do not see one between it and MIN_DIHEDRAL_DEG, and the finer passes
#: often make worse ones. Measured 2026-11-28 (2 cores): a rim with eight bolt holes, its first pass
#: 5.3° (9 below 10°) against its finer pass 10.4°: the same CG and enriched iterations on every level
#: and the same ± (1.96 / 1.92 % at 2 %, 0.73 / 0.73 % at 1 %), 6 s less; a five-spoke disc with bolt
#: holes 8.3° → 7.4° → 1.9° over its finer passes (the first kept, 7 s of passes). A flat needle of
#: 0.04° is what stopped an enriched solve (flexure.stl_remesh); those still go back.
ADAPTIVE_START_DEG = 5.0
_FINER_BELOW = [MIN_DIHEDRAL_DEG]


class finer_below:
    """``with finer_below(deg):`` meshes made inside go back finer only for a tetrahedron below ``deg``
    (those below MIN_DIHEDRAL_DEG are still counted and reported)."""

    def __init__(self, deg: float):
        self.deg = float(deg)

    def __enter__(self):
        _FINER_BELOW.append(self.deg)
        return self

    def __exit__(self, *exc):
        _FINER_BELOW.pop()
        return False


def _session(build, field, where: str, order: int, curved: bool = False, check=None, fallback=()):
    """Run ``build(gmsh)`` (creates the volume), mesh it with ``field``; → flexure.mesh.Mesh.
    ``curved`` (order 2, exact CAD geometry): mid-edge nodes of boundary edges on the true curved
    faces (isoparametric P2), else on the chords. A mesh with a tetrahedron below MIN_DIHEDRAL_DEG
    is made again, finer around it (MIN_DIHEDRAL_DEG says how).

    ``build`` may also be a list of (name, build) strategies (an STL's surface treatments,
    flexure.stl_remesh): every strategy's first pass in turn until one has no such tetrahedron,
    then the strategies that left some, finer around them, the fewest passes first and of those
    the best mesh (``_next_strategy``): len(strategies) + QUALITY_PASSES attempts at most (one
    strategy: itself and QUALITY_PASSES finer passes). A strategy whose first pass is clean is
    taken before another's finer pass (six_spoke_thick's STL: direct left a flat tetrahedron,
    re-parametrised none; 4.4 s for the mesh where direct's second pass made it 9.7 s). A strategy
    named in ``fallback`` is tried only while no attempt has made a mesh that passes ``check``
    (flexure.stl_remesh: direct on an STL with needles), and never run ahead.
    ``check(points, tets, entities) -> dict`` with "ok" (the geometry kept) rules an attempt out
    unless none passes. Every attempt is recorded in
    ``mesh._cache["attempts"]`` (strategy, min dihedral angle, count below MIN_DIHEDRAL_DEG, the
    check's figures; the mesh returned "kept"). With several strategies and idle cores the attempts
    this logic may ask for next run ahead in parallel processes (flexure.gmsh_attempts): the same
    attempts, the same mesh."""
    from flexure import gmsh_attempts
    from flexure.mesh import Mesh, to_quadratic

    builds = dict(build) if isinstance(build, (list, tuple)) else {"mesh": build}
    untried = list(builds)
    spots = {name: np.zeros((0, 4)) for name in builds}
    tries = dict.fromkeys(builds, 0)
    pending: dict = {}                                  # strategy → (ok, worst) of its last pass, which left slivers
    best, attempts, error, name = None, [], None, untried.pop(0)
    runner = gmsh_attempts.runner([b for b in builds if b not in fallback],
                                  lambda s, p: _attempt(builds[s], field, where, order, curved, p, check),
                                  len(builds) + QUALITY_PASSES)
    try:
        for _ in range(len(builds) + QUALITY_PASSES):
            tries[name] += 1
            pending.pop(name, None)
            try:
                points, tets, geometric, entities, record, finer = runner.get(name, spots[name])
            except InputError as exc:                   # this strategy failed: the next one may not
                attempts.append({"strategy": name, "failed": str(exc)})
                error = exc
            else:
                attempts.append({"strategy": name + (" + finer at its slivers" if len(spots[name]) else ""), **record})
                worst = record["min_dihedral_deg"]
                if best is None or (record["ok"], worst) > (best[6]["ok"], best[0]):
                    best = (worst, points, tets, geometric, entities, name, record, len(attempts) - 1)
                if finer is None and record["ok"]:      # no tetrahedron below MIN_DIHEDRAL_DEG, geometry kept
                    break
                if finer is not None:                   # this strategy's next pass: finer around them
                    spots[name] = finer
                    pending[name] = (record["ok"], worst)
            if best is not None and best[6]["ok"]:      # a mesh keeping the geometry: no fallback
                untried = [u for u in untried if u not in fallback]
            name = _next_strategy(untried, pending, tries, list(builds))
            if name is None:
                break
    finally:
        runner.close()
    if best is None:
        raise error if str(error).startswith(where) else InputError(f"{where}: {error}")
    _, points, tets, geometric, entities, _, _, kept = best
    attempts[kept]["kept"] = True
    if geometric is not None:
        mesh = _curved_quadratic(points, tets, *geometric)
    else:
        mesh = Mesh(points, tets)
        mesh = to_quadratic(mesh) if order == 2 else mesh
    mesh._cache["entities"] = entities          # gmsh's classification (flexure.project.classify)
    mesh._cache["attempts"] = attempts
    return mesh


def _next_strategy(untried: list, pending: dict, tries: dict, order: list):
    """The next attempt's strategy (``_session``): the first untried one; else, of those whose last
    pass left slivers (``pending``: strategy → (geometry kept, worst dihedral angle)), the one with the
    fewest passes, then the best mesh, then the first in ``order`` (each at most 1 + QUALITY_PASSES
    passes); None when neither is left."""
    if untried:
        return untried.pop(0)
    pending = {s: v for s, v in pending.items() if tries[s] <= QUALITY_PASSES}
    if not pending:
        return None
    return min(pending, key=lambda s: (tries[s], not pending[s][0], -pending[s][1], order.index(s)))


def _attempt(build, field, where: str, order: int, curved: bool, spots, check):
    """One pass (``_one_pass``) judged → (points, corner tets, curved mid-edge nodes or None,
    entities, its record (min dihedral angle, count below MIN_DIHEDRAL_DEG, tets, ``check``'s
    figures or {"ok": True}), the spots of the strategy's next pass: ``spots`` and one per
    tetrahedron below MIN_DIHEDRAL_DEG at its centre, h = SPOT_REFINEMENT × its longest edge (mm);
    None without such a tetrahedron, or where none is below ``finer_below``'s angle)."""
    from flexure.mesh import element_shape_metrics

    points, tets, geometric, entities = _one_pass(build, field, where, order, curved, spots)
    worst = element_shape_metrics(points, tets)["dihedral_deg"].min(axis=1)
    bad = worst < MIN_DIHEDRAL_DEG
    geo = check(points, tets, entities) if check is not None else {"ok": True}
    record = {"min_dihedral_deg": float(worst.min()), "n_below_min": int(bad.sum()), "n_tets": int(len(tets)), **geo}
    finer = None
    if bad.any() and worst.min() < _FINER_BELOW[-1]:
        x = points[tets[bad]] * MM
        longest = np.linalg.norm(x[:, :, None] - x[:, None], axis=-1).max(axis=(1, 2))
        finer = np.vstack([spots, np.column_stack([x.mean(axis=1), SPOT_REFINEMENT * longest])])
    return points, tets, geometric, entities, record, finer


def _one_pass(build, field, where: str, order: int, curved: bool, spots):
    """One gmsh session: the volume meshed with ``field`` (+ ``spots``) → (points, corner tets,
    gmsh's curved mid-edge nodes or None, the boundary's classification (``_entities``))."""
    import gmsh

    open_session(gmsh)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        with _quiet_stdout():
            _size_field(gmsh, field, spots)      # for a build that meshes a surface first (stl_remesh)
            build(gmsh)
            _size_field(gmsh, field, spots)
            points, tets, entities = _volume_tets(gmsh, where)
            geometric = None
            if order == 2 and curved:
                try:
                    geometric = _geometric_midpoints(gmsh, points)
                except Exception:         # gmsh could not curve this mesh: keep straight P2
                    pass
    finally:
        gmsh.finalize()
    return points, tets, geometric, entities


def mesh_extrusion(poly, height: float, field, order: int = 1, where: str = "mesh"):
    """Graded isotropic mesh of the shapely polygon ``poly`` (m) extruded to ``height`` (m)."""

    def build(gmsh):
        occ = gmsh.model.occ
        loops = []
        for ring in [poly.exterior] + list(poly.interiors):
            xy = np.asarray(ring.coords)[:-1] * MM
            p = [occ.addPoint(x, y, 0.0) for x, y in xy]
            lines = [occ.addLine(p[i], p[(i + 1) % len(p)]) for i in range(len(p))]
            loops.append(occ.addCurveLoop(lines))
        s = occ.addPlaneSurface(loops)
        occ.extrude([(2, s)], 0, 0, height * MM)
        occ.synchronize()

    return _session(build, field, where, order)


def mesh_step(path, field, order: int = 1, where: str = "geometry.file"):
    """Graded mesh of the one solid of a STEP file, meshed on the exact OpenCASCADE geometry (no
    intermediate triangulation), read in mm whatever unit the file declares (cad.import_step)."""
    from flexure.cad import import_step

    return _session(lambda gmsh: import_step(gmsh, path), field, where, order, curved=True)


def mesh_spoke_disc(disc, field, order: int = 1, where: str = "geometry"):
    """Graded mesh of the parametric spoke disc built as an exact OpenCASCADE solid: true circles
    and fillets (no polygon), so that the geometry itself converges with the mesh (P2 mid-edge
    nodes on the curved faces: O(h³) geometric error) and no tetrahedra are wedged into the shallow
    creases of a polygonal outline (the slivers of the polygonal profile).

    Same construction as ``geometry.profile``: rim ring ∪ hub ∪ spokes (∪ pads) from mid-hub to
    mid-rim, every concave (re-entrant) vertical edge filleted with ``fillet_radius``, minus the
    bore and the bolt holes."""
    return _session(lambda gmsh: build_spoke_disc(gmsh, disc, where), field, where, order, curved=True)


def build_spoke_disc(gmsh, disc, where: str = "geometry") -> None:
    """The exact OpenCASCADE solid of a ``geometry.SpokeDisc`` in the current gmsh model (mm)."""
    import math

    occ = gmsh.model.occ
    t = disc.thickness * MM
    cyl = lambda x, y, r: (3, occ.addCylinder(x * MM, y * MM, 0.0, 0.0, 0.0, t, r * MM))  # noqa: E731 (m)
    ring = occ.cut([cyl(0, 0, disc.outer_radius)], [cyl(0, 0, disc.rim_inner_radius)])[0]
    parts = [cyl(0, 0, disc.hub_radius)]
    r0 = 0.5 * (disc.bore_radius + disc.hub_radius)
    r1 = 0.5 * (disc.rim_inner_radius + disc.outer_radius)
    for ang in disc.spoke_angles_rad():
        boxes = [(3, occ.addBox(r0 * MM, -disc.spoke_width / 2 * MM, 0, (r1 - r0) * MM, disc.spoke_width * MM, t))]
        if disc.pad_width:
            rc = disc.hub_radius + disc.pad_position * disc.spoke_length
            boxes.append((3, occ.addBox((rc - disc.pad_length / 2) * MM, -disc.pad_width / 2 * MM, 0,
                                        disc.pad_length * MM, disc.pad_width * MM, t)))
        occ.rotate(boxes, 0, 0, 0, 0, 0, 1, float(ang))
        parts += boxes
    body = occ.fuse(ring, parts)[0]
    occ.synchronize()
    if len(body) != 1:
        raise InputError(f"{where}: the profile is not one connected piece (check radii and widths)")
    if disc.fillet_radius > 0:
        tag = body[0][1]
        d = 0.05 * min(disc.fillet_radius, disc.spoke_width) * MM
        probe = [(d * math.cos(a), d * math.sin(a)) for a in np.linspace(0, 2 * np.pi, 8, endpoint=False)]
        concave = []
        for _, c in gmsh.model.getEntities(1):
            x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(1, c)
            if max(x1 - x0, y1 - y0) > 1e-6 * t or abs((z1 - z0) - t) > 1e-6 * t:
                continue                                  # not a vertical edge through the plate
            x, y = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
            inside = sum(gmsh.model.isInside(3, tag, [x + px, y + py, 0.5 * t]) > 0 for px, py in probe)
            if inside >= 5:                               # material over > 180°: re-entrant corner
                concave.append(c)
        if concave:
            body = occ.fillet([tag], concave, [disc.fillet_radius * MM], removeVolume=True)
            occ.synchronize()
    holes = [cyl(0, 0, disc.bore_radius)]
    for prefix in ("hub", "rim"):
        n = getattr(disc, f"{prefix}_bolts")
        rc, dia = getattr(disc, f"{prefix}_bolt_circle_radius"), getattr(disc, f"{prefix}_bolt_diameter")
        offset = np.pi / n if (prefix == "rim" and n) else 0.0
        for a in 2 * np.pi * np.arange(n) / max(n, 1) + offset + np.deg2rad(disc.phase_deg):
            holes.append(cyl(rc * np.cos(a), rc * np.sin(a), dia / 2))
    occ.cut(body, holes)
    occ.synchronize()
