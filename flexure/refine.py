"""Local, nested refinement of a P2 tetrahedral mesh: longest-edge bisection with closure.

A marked element is bisected at its longest edge (a, b): its mid-edge node m becomes a vertex and
the two children are the parent with b, resp. a, replaced by m (orientation kept). New mid-edge
nodes (a–m and m–b at the quarter points of a–b; m–c and m–d on the faces a b c, a b d) are placed
by the parent's own (isoparametric) map at their reference points, so a child of a curved element
reproduces its curved geometry exactly, and every nodal field handed in (a P2 solution) is
prolongated by the parent's shape functions: the sequence of meshes and spaces is nested.

Conformity (after Rivara's longest-edge bisection): an edge to split is split in every element
that contains it. An element holding a marked edge at least CLOSURE_RATIO of its longest edge is
split at it (its longest marked edge); any other element holding a marked edge gets its longest edge
marked, so the closure

    element has a marked edge shorter than CLOSURE_RATIO × its longest  ⇒  its longest edge is marked

is applied before every pass (to a fixpoint), and passes (each bisects every element at its chosen
marked edge) repeat until no marked edge is left. The longest edge is chosen by (length, vertex-pair
code), one total order for all elements; the closure propagates along longest-edge paths and ends
(edges grow along a path). Between passes the mesh has hanging nodes; after the last one it is
conforming again (checked by ``check_conforming``). Rivara's own closure (CLOSURE_RATIO 1, the
default: split only at the longest edge) spreads far in 3-D, since an edge is split in all ~5
elements around it and each of those first at its own longest edge: 12 % of a four-spoke STL's start
mesh marked (clustered, two rounds) made it 4.1× larger, ratio 0.7 2.5× (three levels: 251 k against
108 k elements); see CLOSURE_RATIO for why 0.7 is not the default. The passes run on an active set, the
elements holding a marked edge (flexure._refine_kernels), at a cost of the refined region's size, and
give ``_passes_reference``'s whole-mesh passes' mesh bit for bit (points, element order, tags, fields).

Boundary: every element carries the geometric entity each of its faces (``face_tag`` (m,4): a
surface tag > 0, 0 inside) and edges (``edge_tag`` (m,6): a curve tag > 0, e.g. a sharp CAD edge)
lie on; children inherit them. New nodes on a tagged edge or face are moved onto the true curve or
surface by a ``Projector`` (the CAD model through gmsh, an STL through trimesh: flexure.project);
a move that would fold an element (det J ≤ 0 at a quadrature point or node) is undone.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flexure._refine_kernels import (_OTHER, _PRIORITY,  # noqa: F401
                                     _edge_targets, _longest_of, _p2_weights, _straighten_folding_mids, edge_codes,
                                     edge_to_split)
from flexure.mesh import TET_EDGES, Mesh
from flexure.mesh_motion import (MIN_SCALED_JACOBIAN, MIN_VOLUME_SHARE, _graph_laplacian, _straight_det,  # noqa: F401
                                 element_valid, halve_until_valid, morph_local, project_nodes)

#: local edge index of the vertex pair (p, q)
_EDGE_OF = np.full((4, 4), -1, dtype=np.int64)
for _t, (_p, _q) in enumerate(TET_EDGES.tolist()):
    _EDGE_OF[_p, _q] = _EDGE_OF[_q, _p] = _t


@dataclass
class TaggedMesh:
    """A P2 mesh with the geometric entity of each element face (``face_tag`` (m,4), face f opposite
    local vertex f; 0: none) and edge (``edge_tag`` (m,6), TET_EDGES order; 0: none)."""

    mesh: Mesh
    face_tag: np.ndarray
    edge_tag: np.ndarray
    #: nodes still off their curve or surface (their move would have folded an element), retried
    #: at every refinement: (nodes, dims, tags)
    pending: tuple = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64))
    #: (min_scaled, tets, points) as ``straighten_invalid`` or ``morph`` left them with every element
    #: valid (det J ≥ min_scaled × the straight det): a later bisection's ``straighten_invalid`` checks
    #: only the elements that are new or have a node moved since
    valid: tuple | None = field(default=None, repr=False, compare=False)

    @classmethod
    def untagged(cls, mesh: Mesh) -> "TaggedMesh":
        m = mesh.n_elements
        return cls(mesh, np.zeros((m, 4), np.int64), np.zeros((m, 6), np.int64))

    @classmethod
    def boundary_tagged(cls, mesh: Mesh, tag: int = 1) -> "TaggedMesh":
        """Every boundary face on surface ``tag`` (one surface: an STL)."""
        tm = cls.untagged(mesh)
        tm.face_tag[_boundary_face_mask(mesh)] = tag
        return tm


def _boundary_face_mask(mesh: Mesh) -> np.ndarray:
    """(m,4) bool: element face f (opposite local vertex f) lies on the boundary."""
    from flexure.mesh import TET_FACES

    key = np.sort(mesh.corner_tets[:, TET_FACES].astype(np.int64), axis=2).reshape(-1, 3)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return (cnt[inv.ravel()] == 1).reshape(-1, 4)


def longest_edge(points: np.ndarray, tets: np.ndarray, codes: np.ndarray | None = None) -> np.ndarray:
    """Local index (m,) of each element's longest edge, ties broken by the larger vertex-pair code
    (the same total order in every element, so neighbours sharing an edge agree)."""
    codes = edge_codes(tets) if codes is None else codes
    uc, inv = np.unique(codes.ravel(), return_inverse=True)
    return _longest(points, codes, uc, inv.reshape(codes.shape))


def _longest(points, codes, uc, eid):
    lo, hi = uc >> 32, uc & 0xFFFFFFFF
    d = points[hi] - points[lo]
    return _longest_of(np.einsum("ei,ei->e", d, d)[eid], codes)


def mid_node_targets(tm: TaggedMesh):
    """Every mid-edge node on a tagged curve (dim 1) or surface (dim 2): (nodes, dims, tags)."""
    dims, tags = _edge_targets(tm.face_tag, tm.edge_tag)
    return _strongest(tm.mesh.tets[:, 4:].astype(np.int64).ravel(), dims.ravel(), tags.ravel())


def _strongest(nodes, dims, tags):
    """One (dim, tag) per node, the strongest (curve > surface) of its listings; dim 0 dropped."""
    sel = dims > 0
    nodes, dims, tags = nodes[sel], dims[sel], tags[sel]
    order = np.lexsort((_PRIORITY[dims], nodes))
    nodes, dims, tags = nodes[order], dims[order], tags[order]
    last = np.r_[nodes[1:] != nodes[:-1], True] if len(nodes) else np.zeros(0, bool)
    return nodes[last], dims[last], tags[last]


def vertex_targets(tm: TaggedMesh):
    """Every vertex on a tagged surface face (dim 2, the face's tag) or curve edge (dim 1, the
    edge's tag; a curve over a surface), one per vertex."""
    from flexure.mesh import TET_FACES

    e, f = np.nonzero(tm.face_tag > 0)
    nodes = tm.mesh.tets[e[:, None], TET_FACES[f]].astype(np.int64)           # (k,3)
    tags = np.repeat(tm.face_tag[e, f], 3)
    ce, cj = np.nonzero(tm.edge_tag > 0)
    cnodes = tm.mesh.tets[ce[:, None], TET_EDGES[cj]].astype(np.int64)        # (j,2)
    return _strongest(np.concatenate([nodes.ravel(), cnodes.ravel()]),
                      np.concatenate([np.full(nodes.size, 2, np.int64), np.full(cnodes.size, 1, np.int64)]),
                      np.concatenate([tags, np.repeat(tm.edge_tag[ce, cj], 2)]))


def snap(tm: TaggedMesh, projector, vertices: bool = False) -> dict:
    """Put the first mesh on the true geometry (in place; ``morph``): every mid-edge node on a
    tagged curve or surface (isoparametric P2), and with ``vertices`` the boundary vertices too (a
    mesher that places them off the true surface, e.g. gmsh's re-parametrised STL patches; the mid
    nodes of their edges are then projected from between their moved ends). Nodes whose move would
    still fold an element become ``pending`` (a mid node moved by δ toward the far side of an element
    of height h folds it as δ → h/4: a chord on a concave fillet, moved into the part, over a flat
    element along it; bisecting those elements makes new such nodes rather than fewer)."""
    info = morph(tm, projector, vertices)
    info["pending"] = int(len(tm.pending[0]))
    return info


def boundary_targets(tm: TaggedMesh, projector, vertices: bool = False):
    """Where the boundary nodes belong: (nodes, dims, tags, points (k,3)). ``vertices``: the
    vertices on tagged faces, projected; then every mid node on a tagged curve or surface, projected
    from the midpoint of its edge's (moved) ends, else from itself. A failed projection (NaN) stays."""
    mesh = tm.mesh
    X0 = mesh.points
    t = mesh.tets
    target = X0.copy()
    if vertices:
        vn, vd, vt = vertex_targets(tm)
        if len(vn):
            target[vn] = projector.project(X0[vn], vd, vt)
    else:
        vn = vd = vt = np.zeros(0, np.int64)
    mn, md, mt = mid_node_targets(tm)
    start = X0[mn].copy()
    if len(vn):
        moved = np.zeros(mesh.n_nodes, bool)
        moved[vn] = True
        mid = X0.copy()
        for j, (a, b) in enumerate(TET_EDGES.tolist()):
            sel = moved[t[:, a]] | moved[t[:, b]]
            mid[t[sel, 4 + j]] = 0.5 * (target[t[sel, a]] + target[t[sel, b]])
        start = mid[mn]
    if len(mn):
        target[mn] = projector.project(start, md, mt)
    nodes = np.concatenate([vn, mn])
    out = target[nodes]
    bad = ~np.isfinite(out).all(axis=1)
    out[bad] = X0[nodes[bad]]
    return (nodes, np.concatenate([vd, md]), np.concatenate([vt, mt]), out)


def morph(tm: TaggedMesh, projector, vertices: bool = False, tries: int = 8,
          min_scaled_jacobian: float | None = None, stiffen: bool = True) -> dict:
    """Move the boundary nodes onto the true geometry all at once and the interior nodes with them:
    boundary displacement d_B (vertices ``vertices``: their projection; mid nodes on a tagged curve
    or surface: the projection of the midpoint of their moved ends, or of themselves), interior
    displacement its discrete harmonic extension, L_II d_I = −L_IB d_B (L the graph Laplacian of the
    P2 nodes). Moving only the boundary nodes folds the thin elements along a coarse curved face (a
    3 mm bore meshed with 2.4 mm chords: mid nodes 0.23 mm off, in elements a few tenths thick);
    moving their interior neighbours with them does not. Where an element is still invalid (det J
    below ``min_scaled_jacobian`` × its straight det at a quadrature point or node, or a straight
    volume below MIN_VOLUME_SHARE of its value before) the moves of its boundary nodes are halved,
    ``tries`` times, then undone; those nodes are returned as ``pending``.
    → {"projected", "projection_partial", "projection_undone", "max_projection_m", "morphed_interior"}"""
    from scipy.sparse.linalg import splu

    mesh = tm.mesh
    msj = MIN_SCALED_JACOBIAN if min_scaled_jacobian is None else min_scaled_jacobian
    X0 = mesh.points.copy()
    t = mesh.tets
    nodes, dims, tags, target_b = boundary_targets(tm, projector, vertices)
    dB = target_b - X0[nodes]
    info = {"projected": 0, "projection_partial": 0, "projection_undone": 0,
            "max_projection_m": float(np.linalg.norm(dB, axis=1).max(initial=0.0)), "morphed_interior": 0}
    if not np.any(dB):
        tm.pending = (np.zeros(0, np.int64),) * 3
        return info
    fixed = np.zeros(mesh.n_nodes, bool)
    fixed[mesh.boundary_nodes()] = True
    fixed[nodes] = True
    B, I = np.flatnonzero(fixed), np.flatnonzero(~fixed)
    L = _graph_laplacian(t, mesh.n_nodes, X0 if stiffen else None).tocsc()
    LII = splu(L[I][:, I].tocsc()) if len(I) else None
    LIB = L[I][:, B]
    before = _straight_det(X0[t[:, :4]])

    def move(beta):
        D = np.zeros((mesh.n_nodes, 3))
        D[nodes] = beta[:, None] * dB
        if LII is not None:
            D[I] = LII.solve(-(LIB @ D[B]))
        mesh.points[:] = X0 + D

    checked = []

    def invalid():
        checked[:] = [~(element_valid(mesh, np.arange(len(t)), msj)
                        & (_straight_det(mesh.points[t[:, :4]]) >= MIN_VOLUME_SHARE * before))]
        return checked[0]

    beta = halve_until_valid(nodes, t, mesh.n_nodes, move, invalid, tries)
    mesh._cache.clear()
    if not checked[0].any():                  # the mesh as left: every element valid (straighten_invalid)
        tm.valid = (msj, t.copy(), mesh.points.copy())
    left = (beta < 1.0) & np.any(dB != 0, axis=1)             # a node with nothing to move is not pending
    tm.pending = (nodes[left], dims[left], tags[left])
    info.update(projected=int((~left).sum()), projection_undone=int(((beta == 0) & left).sum()),
                projection_partial=int(((beta > 0) & left).sum()),
                morphed_interior=int((np.linalg.norm(mesh.points[I] - X0[I], axis=1) > 0).sum()))
    return info


def boundary_geometry_error(tm: TaggedMesh, projector):
    """Geometric error of the isoparametric P2 boundary, per boundary edge (a mid node on a tagged
    curve or surface): δ = the larger distance of its two quarter points x(¼), x(¾) (the P2 edge
    map, x(¼) = 3/8 x_a − 1/8 x_b + 3/4 x_m) from their projection onto the true geometry, and the
    edge's radius of curvature R = max(L²/(8 s), L) from its sagitta s = |x_m − (x_a + x_b)/2| (chord L).
    → (elements (k,), δ (k,) m, R (k,) m), one row per element edge on the boundary."""
    dims, tags = _edge_targets(tm.face_tag, tm.edge_tag)
    e, j = np.nonzero(dims > 0)
    if len(e) == 0:
        z = np.zeros(0)
        return np.zeros(0, np.int64), z, z
    P = tm.mesh.points
    t = tm.mesh.tets
    xa, xb, xm = P[t[e, TET_EDGES[j, 0]]], P[t[e, TET_EDGES[j, 1]]], P[t[e, 4 + j]]
    q1 = 0.375 * xa - 0.125 * xb + 0.75 * xm
    q3 = 0.375 * xb - 0.125 * xa + 0.75 * xm
    _, first, inv = np.unique(t[e, 4 + j], return_index=True, return_inverse=True)   # each edge once
    d, g = dims[e, j][first], tags[e, j][first]
    Q = np.vstack([q1[first], q3[first]])
    # points on the mesh's own boundary: an STL's nearest samples' triangles suffice (StlProjector)
    proj = projector.project(Q, np.concatenate([d, d]), np.concatenate([g, g]), certified=False)
    dist = np.linalg.norm(proj - Q, axis=1).reshape(2, -1).max(axis=0)[inv.ravel()]
    L2 = np.einsum("ki,ki->k", xb - xa, xb - xa)
    s = np.linalg.norm(xm - 0.5 * (xa + xb), axis=1)
    # an edge cannot resolve a radius below its own length (a mid node left off a sharp edge's
    # surfaces, or one across it, would give any R): R ≥ L
    R = np.where(s > 0, np.maximum(L2 / np.maximum(8.0 * s, 1e-300), np.sqrt(L2)), np.inf)
    return e, dist, R


def _bisect_pass(points, tets, face_tag, edge_tag, flag, emark, fields, closure_ratio: float = 1.0):
    """One pass: closure, then every element whose longest edge is marked is bisected. An edge is
    named by its mid node (one per edge, conforming or between passes alike: an edge keeps its node
    until it is split, a new edge gets one), so ``emark`` is a (n,) bool over the nodes and no pass
    needs a global sort of the edges. → (points, tets, face_tag, edge_tag, flag, emark, fields,
    targets, n_bisected)."""
    codes = edge_codes(tets)
    eid = tets[:, 4:]                                                        # (m,6) each edge's mid node
    n = len(points)
    code = np.zeros(n, np.int64)
    code[eid] = codes                                                        # every mid node's vertex pair
    lo, hi = code >> 32, code & 0xFFFFFFFF
    d = points[hi] - points[lo]
    le = _longest_of(np.einsum("ei,ei->e", d, d)[eid], codes)
    rows = np.arange(len(tets))
    mk = emark[eid]
    L = np.linalg.norm(d, axis=1)[eid]                                       # (m,6) edge lengths
    Lmax = L[rows, le]
    corner = points[tets[:, :4]]
    q_cache = {}                                  # (element, edge) → children's smallest dihedral angle
    while True:                                   # closure to a fixpoint
        chosen = edge_to_split(mk, L, le, Lmax, closure_ratio, rows, corner.__getitem__, q_cache)
        need = mk.any(axis=1) & ~mk[rows, chosen]
        if not need.any():
            break
        emark[eid[need, le[need]]] = True
        mk = emark[eid]
    B = np.flatnonzero(mk[rows, chosen])
    if len(B) == 0:
        return points, tets, face_tag, edge_tag, flag, emark, fields, None, 0
    e = chosen[B]
    i, j = TET_EDGES[e, 0], TET_EDGES[e, 1]
    k, l = _OTHER[e, 0], _OTHER[e, 1]
    TB = tets[B].astype(np.int64)
    r = np.arange(len(B))
    vi, vj, vk, vl = TB[r, i], TB[r, j], TB[r, k], TB[r, l]
    m = TB[r, 4 + e]
    _straighten_folding_mids(points, TB[:, :4], r, i, j, m)
    # the four new edges per bisected element, their reference points in the parent, and where
    # they lie: on the split edge (a curve, or a surface face next to it) or on a parent face
    pair = lambda x, y: (np.minimum(x, y) << 32) | np.maximum(x, y)  # noqa: E731
    new_codes = np.concatenate([pair(vi, m), pair(vj, m), pair(m, vk), pair(m, vl)])
    bary = np.zeros((4, len(B), 4))
    bary[0, r, i], bary[0, r, j] = 0.75, 0.25
    bary[1, r, i], bary[1, r, j] = 0.25, 0.75
    bary[2, r, i] = bary[2, r, j] = bary[3, r, i] = bary[3, r, j] = 0.25
    bary[2, r, k] = bary[3, r, l] = 0.5
    fk, fl = face_tag[B, k], face_tag[B, l]          # faces opposite k (contains i j l), opposite l
    # an edge's target (curve > surface > none) over every element that holds it: an element that
    # touches the boundary only along the edge does not know it
    split = np.zeros(n, bool)
    split[m] = True
    hold = np.flatnonzero(split[eid.ravel()])     # the element edges (flat (m,6) index) that are split
    edim, etag = _edge_targets(face_tag[hold // 6], edge_tag[hold // 6])
    edim, etag = edim[np.arange(len(hold)), hold % 6], etag[np.arange(len(hold)), hold % 6]
    order = np.lexsort((_PRIORITY[edim], eid.ravel()[hold]))
    best_dim = np.zeros(n, np.int64)
    best_tag = np.zeros(n, np.int64)
    best_dim[eid.ravel()[hold][order]] = edim[order]
    best_tag[eid.ravel()[hold][order]] = etag[order]
    dim_e, tag_e = best_dim[m], best_tag[m]
    dims = np.concatenate([dim_e, dim_e, np.where(fl > 0, 2, 0), np.where(fk > 0, 2, 0)])
    tags = np.concatenate([tag_e, tag_e, fl, fk])
    parent = np.tile(B, 4)
    # existing edges keep their node; each new one gets one node (placed by its first parent)
    # (every new edge holds m: it can exist already only where m is a vertex, split by a neighbour before)
    ismid = np.zeros(n, bool)
    ismid[eid] = True
    cand_nodes = np.flatnonzero(ismid & (split[lo] | split[hi]))
    order = np.argsort(code[cand_nodes], kind="stable")
    ex_codes, ex_nodes = code[cand_nodes][order], cand_nodes[order]
    uniq, first, inv = np.unique(new_codes, return_index=True, return_inverse=True)
    if len(ex_codes):
        pos = np.minimum(np.searchsorted(ex_codes, uniq), len(ex_codes) - 1)
        exists = ex_codes[pos] == uniq
        node_of = np.where(exists, ex_nodes[pos], 0)
    else:
        exists = np.zeros(len(uniq), bool)
        node_of = np.zeros(len(uniq), np.int64)
    fresh = np.flatnonzero(~exists)
    node_of[fresh] = n + np.arange(len(fresh))
    src = first[fresh]                            # occurrence that places each fresh node
    N = _p2_weights(bary.reshape(-1, 4)[src])
    P = tets[parent[src]]
    points = np.vstack([points, np.einsum("ka,kai->ki", N, points[P])])
    fields = [np.concatenate([f, np.einsum("ka,ka...->k...", N, f[P])]) for f in fields]
    # projection target of each fresh node: the strongest (curve > surface > none) of its occurrences
    prio = np.zeros(len(uniq), np.int64)
    best_tag = np.zeros(len(uniq), np.int64)
    order = np.lexsort((_PRIORITY[dims], inv))    # by node, then priority ascending: last wins
    prio[inv[order]] = dims[order]
    best_tag[inv[order]] = tags[order]
    targets = [np.concatenate([node_of[fresh], m]), np.concatenate([prio[fresh], dim_e]),
               np.concatenate([best_tag[fresh], tag_e])]
    qa, qb, nk, nl = node_of[inv].reshape(4, len(B))
    children = []
    for gone, q in ((j, qa), (i, qb)):            # child 1: vj → m; child 2: vi → m
        child = TB.copy()
        child[r, gone] = m
        ft = face_tag[B].copy()
        ft[r, np.where(gone == j, i, j)] = 0      # the new interior face (opposite the kept end)
        et = edge_tag[B].copy()
        for t in range(6):
            p_, q_ = TET_EDGES[t]
            touches = (p_ == gone) | (q_ == gone)
            other = np.where(p_ == gone, q_, p_)
            split = touches & (t == e)
            face_edge = touches & ~split
            child[:, 4 + t] = np.where(~touches, TB[:, 4 + t],
                                       np.where(split, q, np.where(other == k, nk, nl)))
            et[face_edge, t] = 0
        children.append((child, ft, et))
    keep = np.ones(len(tets), bool)
    keep[B] = False
    tets = np.vstack([tets[keep], children[0][0], children[1][0]])
    face_tag = np.vstack([face_tag[keep], children[0][1], children[1][1]])
    edge_tag = np.vstack([edge_tag[keep], children[0][2], children[1][2]])
    flag = np.concatenate([flag[keep], flag[B], flag[B]])
    emark = np.concatenate([emark, np.zeros(len(points) - n, bool)])
    return points, tets, face_tag, edge_tag, flag, emark, fields, targets, len(B)


#: an element holding a marked edge at least this fraction of its longest edge is bisected at that edge
#: (its longest marked one) if its children are as good as its longest edge's (``_refine_kernels.QUALITY_FLOOR_DEG``);
#: otherwise its longest edge is marked (1.0: Rivara's closure, the default). 0.7 made the levels 1.6–2.5×
#: smaller, but on an unseen four-spoke STL the adaptive run then took three levels where Rivara's took two,
#: and the marks, concentrated at the same edges level after level, left 37 tetrahedra below 10° (2.4°)
#: against 5 (7.6°): an option, measured, not the default
CLOSURE_RATIO = 1.0


def bisect(tm: TaggedMesh, elements, fields=(), rounds: int = 1, projector=None, max_passes: int = 200,
           closure_ratio: float | None = None):
    """Bisect ``elements`` (indices or an (m,) bool mask) ``rounds`` times (each round bisects every
    descendant of theirs once at its longest edge; 3 rounds ≈ halving h), with closure.

    ``fields``: nodal arrays (n, ...) prolongated by the parents' P2 shape functions. New boundary
    nodes are projected with ``projector`` (``project(points, dim, tag) → points``) if given.
    → (TaggedMesh, [fields], info dict: passes, bisections, projected nodes, undone moves)."""
    mesh = tm.mesh
    if mesh.order != 2:
        raise ValueError("bisect: a P2 mesh is expected")
    from flexure._refine_kernels import passes as bisect_passes

    n0 = mesh.n_nodes
    points, tets, face_tag, edge_tag, fields, targets, passes, bisections, kept = bisect_passes(
        mesh.points, mesh.tets, tm.face_tag, tm.edge_tag, elements, [np.asarray(f, float) for f in fields], rounds,
        CLOSURE_RATIO if closure_ratio is None else closure_ratio, max_passes)
    moved_nodes, moved_dim, moved_tag = (list(x) for x in zip(*targets)) if targets else ([], [], [])
    info = {"passes": passes, "bisections": bisections, "new_nodes": len(points) - n0,
            "projected": 0, "projection_undone": 0, "max_projection_m": 0.0}
    out = TaggedMesh(Mesh(points, tets), face_tag, edge_tag, tm.pending)
    if projector is not None and (moved_nodes or len(tm.pending[0])):
        # new nodes, the vertices made from mid nodes, and the nodes left off their geometry before;
        # a node listed twice keeps its strongest target (curve > surface)
        nodes, dims, tags = _strongest(*[np.concatenate([p] + q) for p, q in
                                         zip(tm.pending, (moved_nodes, moved_dim, moved_tag))])
        info.update(project_nodes(out.mesh, nodes, dims, tags, projector))
        out.pending = info.pop("pending")
        if len(out.pending[0]):           # those left: moved again with the interior around them following
            settled = morph_local(out.mesh, *out.pending, projector)
            info["projected_by_morph"] = settled["projected"]
            out.pending = settled["pending"]
    if projector is not None:
        info["straightened"], info["invalid_elements"] = straighten_invalid(out, known=_known_valid(tm, out, kept))
    return out, fields, info


def bisected_dofs(tm: TaggedMesh, elements, rounds: int = 1, closure_ratio: float | None = None) -> int:
    """DOFs of ``bisect(tm, elements, rounds=rounds)``'s mesh, from its passes alone (no fields, tags,
    projection): a trial that sizes a refinement (flexure.adaptive_sizing.marks_for)."""
    from flexure._refine_kernels import passes as bisect_passes

    mesh = tm.mesh
    points = bisect_passes(mesh.points, mesh.tets, tm.face_tag, tm.edge_tag, elements, (), rounds,
                           CLOSURE_RATIO if closure_ratio is None else closure_ratio, topology=True)[0]
    return 3 * len(points)


def _passes_reference(points, tets, face_tag, edge_tag, elements, fields=(), rounds: int = 1,
                      closure_ratio: float = 1.0, max_passes: int = 200):
    """The passes of ``bisect`` over the whole mesh (``_bisect_pass``: every pass and closure step
    touches every element): the reference that flexure._refine_kernels.passes reproduces bit for bit."""
    points, tets = np.array(points, float), np.array(tets, np.int64)
    face_tag, edge_tag = np.array(face_tag, np.int64), np.array(edge_tag, np.int64)
    flag = np.zeros(len(tets), bool)
    flag[np.asarray(elements)] = True
    fields = [np.asarray(f, float) for f in fields]
    targets, passes, bisections = [], 0, 0
    for _ in range(rounds):
        marked = np.zeros(len(points), bool)
        marked[tets[flag, 4 + longest_edge(points, tets[flag])]] = True
        while True:
            points, tets, face_tag, edge_tag, flag, marked, fields, tgt, nb = _bisect_pass(
                points, tets, face_tag, edge_tag, flag, marked, fields, closure_ratio)
            if nb == 0:
                break
            passes += 1
            bisections += nb
            targets.append(tgt)
            if passes > max_passes:
                raise RuntimeError("bisect: the closure did not end")
    return points, tets, face_tag, edge_tag, fields, targets, passes, bisections


def _known_valid(tm: TaggedMesh, out: TaggedMesh, kept: int, min_scaled: float = 0.05) -> np.ndarray | None:
    """(m,) bool: the elements of ``out`` (``bisect(tm)``; its first ``kept`` are tm's, unsplit) that
    ``straighten_invalid`` found valid in ``tm`` and whose nodes have not moved since; None if unknown."""
    v = tm.valid
    if (v is None or v[0] < min_scaled or not np.array_equal(v[1], tm.mesh.tets)
            or not np.array_equal(v[2], tm.mesh.points)):
        return None
    moved = np.any(out.mesh.points[: tm.mesh.n_nodes] != tm.mesh.points, axis=1)
    known = np.zeros(out.mesh.n_elements, bool)
    known[:kept] = ~moved[out.mesh.tets[:kept]].any(axis=1)
    return known


def straighten_invalid(tm: TaggedMesh, min_scaled: float = 0.05, rounds: int = 8,
                       known: np.ndarray | None = None) -> tuple[int, int]:
    """Make every element valid again (in place): a child samples its curved parent's map at new
    nodes, where the parent's det J (checked only at its quadrature points and nodes) can be ≤ 0.
    The mid nodes of an element whose det J falls below ``min_scaled`` × its straight det are put
    back on their straight midpoints (a straight element with a positive det is valid), their
    neighbours re-checked; the boundary ones join ``pending`` (retried at the next refinement).
    → (how many mid nodes were straightened, how many elements are still invalid: a straight element
    flat or inverted, which no mid node can mend — the caller must not solve on that mesh)."""
    mesh = tm.mesh
    t = mesh.tets
    check = np.arange(len(t)) if known is None else np.flatnonzero(~known)     # known: valid, unchanged
    moved = np.zeros(mesh.n_nodes, bool)
    for k in range(rounds + 1):                    # the last check only counts what is left
        bad = check[~element_valid(mesh, check, min_scaled)]
        if len(bad) == 0 or k == rounds:
            break
        for j, (a, b) in enumerate(TET_EDGES.tolist()):
            mid = t[bad, 4 + j]
            mesh.points[mid] = 0.5 * (mesh.points[t[bad, a]] + mesh.points[t[bad, b]])
            moved[mid] = True
        check = np.flatnonzero(moved[t[:, 4:]].any(axis=1))
    mesh._cache.clear()
    if moved.any():
        nodes, dims, tags = mid_node_targets(tm)
        sel = moved[nodes]
        tm.pending = _strongest(*[np.concatenate([p, q[sel]]) for p, q in zip(tm.pending, (nodes, dims, tags))])
    if len(bad) == 0:
        tm.valid = (min_scaled, t.copy(), mesh.points.copy())
    return int(moved.sum()), int(len(bad))


def check_conforming(mesh: Mesh) -> None:
    """Raise AssertionError unless every edge has one mid node and every interior face is shared
    by exactly two elements (no hanging node)."""
    from flexure.mesh import TET_FACES

    codes = edge_codes(mesh.tets).ravel()
    mids = mesh.tets[:, 4:].ravel()
    order = np.lexsort((mids, codes))
    c, mnode = codes[order], mids[order]
    same = c[1:] == c[:-1]
    assert np.all(mnode[1:][same] == mnode[:-1][same]), "an edge has two mid nodes"
    vert = np.zeros(mesh.n_nodes, bool)
    vert[mesh.corner_tets] = True
    assert not vert[mids].any(), "a mid node is also a vertex (hanging node)"
    key = np.sort(mesh.corner_tets[:, TET_FACES].astype(np.int64), axis=2).reshape(-1, 3)
    _, cnt = np.unique(key, axis=0, return_counts=True)
    assert cnt.max() <= 2, "a face is shared by more than two elements"
