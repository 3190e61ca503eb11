"""Moving mesh nodes onto the true geometry without folding or flattening elements (flexure.refine):
the validity test of a P2 element (det J at its quadrature points and nodes against its straight det),
the (Jacobian-stiffened) graph Laplacian whose harmonic extension carries a boundary move into the
interior, and the two moves built on them: boundary nodes alone (``project_nodes``) and boundary nodes
with the interior of a patch around them following (``morph_local``). A move that would fold an
element, flatten it below MIN_VOLUME_SHARE of its volume, or make it a sliver is halved, then undone.
"""

from __future__ import annotations

import numpy as np

from flexure.mesh import Mesh


#: the morph's stiffening exponent χ: element weights (V_max / V_e)^χ (``_graph_laplacian``)
STIFFENING = 1.0


def _graph_laplacian(tets: np.ndarray, n: int, points: np.ndarray | None = None, chi: float = STIFFENING):
    """Graph Laplacian (n,n) of the P2 nodes, every pair of nodes of an element linked. With ``points``,
    each element's links weigh (V_max / V_e)^χ, summed over the elements that share them (Jacobian-based
    stiffening, Tezduyar et al. 1992: the small elements along a boundary move nearly rigidly with it and
    the large ones farther in take up the deformation); else each link weighs 1."""
    from scipy.sparse import coo_matrix, diags

    t = tets.astype(np.int64)
    k = t.shape[1]
    i = np.repeat(t, k, axis=1).ravel()
    j = np.tile(t, (1, k)).ravel()
    off = i != j
    if points is None:
        A = coo_matrix((np.ones(int(off.sum())), (i[off], j[off])), shape=(n, n)).tocsr()
        A.data[:] = 1.0                                                     # an edge once, however many elements share it
    else:
        v = np.abs(_straight_det(points[t[:, :4]]))
        w = (v.max() / np.maximum(v, 1e-30 * v.max())) ** chi
        A = coo_matrix((np.repeat(w, k * k)[off], (i[off], j[off])), shape=(n, n)).tocsr()
    return diags(np.asarray(A.sum(axis=1)).ravel()) - A


#: ``morph_local`` leaves no element below this smallest dihedral angle that was not already (slivers.SLIVER_DEG)
MORPH_MIN_DIHEDRAL_DEG = 10.0


def _angle_floor(before_deg: np.ndarray) -> np.ndarray:
    """The smallest dihedral angle a move may leave each element: MORPH_MIN_DIHEDRAL_DEG, or for one
    already below it, its own less ANGLE_SLACK_DEG (a move need not improve a poor element, only not
    make it much worse)."""
    return np.where(before_deg >= MORPH_MIN_DIHEDRAL_DEG, MORPH_MIN_DIHEDRAL_DEG, before_deg - ANGLE_SLACK_DEG)


#: how much a move may lower the smallest dihedral angle of an element already below MORPH_MIN_DIHEDRAL_DEG
ANGLE_SLACK_DEG = 0.5


def morph_local(mesh: Mesh, nodes, dims, tags, projector, rings: int = 2, tries: int = 6,
                min_scaled_jacobian: float | None = None) -> dict:
    """``morph`` on a patch: move boundary ``nodes`` onto their curve or surface and the interior nodes
    of the elements within ``rings`` element layers of them by the (stiffened) harmonic extension of
    that move, the patch's outer nodes held (in place). For the nodes a refinement left off the
    geometry (``bisect``): moved alone they fold their elements where the interior does not follow.
    → {"projected", "pending": (nodes, dims, tags)}"""
    from scipy.sparse.linalg import splu

    nodes, dims, tags = (np.asarray(a, np.int64) for a in (nodes, dims, tags))
    msj = MIN_SCALED_JACOBIAN if min_scaled_jacobian is None else min_scaled_jacobian
    if len(nodes) == 0:
        return {"projected": 0, "pending": (nodes, dims, tags)}
    t = mesh.tets
    X0 = mesh.points.copy()
    target = np.asarray(projector.project(X0[nodes], dims, tags), float)
    ok = np.isfinite(target).all(axis=1)
    target[~ok] = X0[nodes[~ok]]
    dB = target - X0[nodes]
    inside = np.zeros(mesh.n_nodes, bool)
    inside[nodes] = True
    for _ in range(rings + 1):
        patch = inside[t].any(axis=1)
        inside[t[patch]] = True
    patch = np.flatnonzero(inside[t].any(axis=1) & inside[t].all(axis=1) | np.isin(t, nodes).any(axis=1))
    pn = np.unique(t[patch])
    outer = np.zeros(mesh.n_nodes, bool)
    outer[t[np.setdiff1d(np.arange(len(t)), patch)]] = True                # shared with elements outside
    outer[mesh.boundary_nodes()] = True
    free = pn[~outer[pn]]
    held = pn[outer[pn]]
    loc = np.full(mesh.n_nodes, -1, np.int64)
    loc[pn] = np.arange(len(pn))
    L = _graph_laplacian(loc[t[patch]], len(pn), X0[pn]).tocsc()
    fi, hi = loc[free], loc[held]
    LII = splu(L[fi][:, fi].tocsc()) if len(free) else None
    LIB = L[fi][:, hi]
    from flexure.mesh import element_shape_metrics

    angle = lambda: element_shape_metrics(mesh.points, t[patch, :4])["dihedral_deg"].min(axis=1)  # noqa: E731
    before = _straight_det(X0[t[patch, :4]])
    floor = _angle_floor(angle())                             # no element made a sliver by the move

    def move(beta):
        D = np.zeros((mesh.n_nodes, 3))
        D[nodes] = beta[:, None] * dB
        if LII is not None:
            D[free] = LII.solve(-(LIB @ D[held]))
        mesh.points[pn] = X0[pn] + D[pn]

    def invalid():
        good = element_valid(mesh, patch, msj) & (_straight_det(mesh.points[t[patch, :4]]) >= MIN_VOLUME_SHARE * before)
        return ~(good & (angle() >= floor - 1e-9))

    beta = halve_until_valid(nodes, t[patch], mesh.n_nodes, move, invalid, tries)
    mesh._cache.clear()
    left = (beta < 1.0) & np.any(dB != 0, axis=1)
    return {"projected": int((~left).sum()), "pending": (nodes[left], dims[left], tags[left])}


#: a projected node may not leave an element with det J below this fraction of its straight det at a
#: quadrature point or node (gmsh_mesh.MIN_SCALED_JACOBIAN: below it the nodal stresses are spurious)
MIN_SCALED_JACOBIAN = 0.25


def project_nodes(mesh: Mesh, nodes, dims, tags, projector, min_scaled_jacobian: float = MIN_SCALED_JACOBIAN,
                  tries: int = 6) -> dict:
    """Move ``nodes`` of ``mesh`` (in place) onto their curve (dim 1) or surface (dim 2) ``tags``.
    Where an element would fold (det J at a quadrature point or node below ``min_scaled_jacobian``
    × its straight det, or a straight det ≤ 0) the moves of its nodes are halved, ``tries`` times,
    then undone; nodes not on their geometry are returned as ``pending``."""
    if len(nodes) == 0:
        return {"projected": 0, "projection_undone": 0, "max_projection_m": 0.0, "pending": (nodes, dims, tags)}
    old = mesh.points[nodes].copy()
    new = np.asarray(projector.project(old, dims, tags), float)
    ok = np.isfinite(new).all(axis=1)
    new[~ok] = old[~ok]
    step = np.linalg.norm(new - old, axis=1)
    sel = step > 0
    nodes, dims, tags, old, new, step = nodes[sel], dims[sel], tags[sel], old[sel], new[sel], step[sel]
    beta = np.ones(len(nodes))
    where = np.full(mesh.n_nodes, -1, np.int64)
    where[nodes] = np.arange(len(nodes))
    touched = np.flatnonzero((where[mesh.tets] >= 0).any(axis=1))
    before = _straight_det(mesh.points[mesh.tets[touched, :4]])
    from flexure.mesh import element_shape_metrics

    angle = lambda: element_shape_metrics(mesh.points, mesh.tets[touched, :4])["dihedral_deg"].min(axis=1)  # noqa: E731
    floor = _angle_floor(angle())
    for k in range(tries + 1):
        mesh.points[nodes] = old + beta[:, None] * (new - old)
        # valid, and not flattened: a move of vertices may not take a straight det below MIN_VOLUME_SHARE of
        # its value before (four vertices put on one flat facet make a tet of zero volume), nor make a sliver
        ok = element_valid(mesh, touched, min_scaled_jacobian)
        ok &= _straight_det(mesh.points[mesh.tets[touched, :4]]) >= MIN_VOLUME_SHARE * before
        ok &= angle() >= floor - 1e-9
        bad = touched[~ok]
        if len(bad) == 0:
            break
        back = where[np.unique(mesh.tets[bad])]
        back = back[back >= 0]
        beta[back] = 0.0 if k >= tries - 1 else 0.5 * beta[back]
    mesh._cache.clear()
    left = beta < 1.0
    return {"projected": int((~left).sum()), "projection_undone": int((beta == 0).sum()),
            "projection_partial": int(((beta > 0) & left).sum()),
            "max_projection_m": float(step.max()) if len(step) else 0.0,
            "pending": (nodes[left], dims[left], tags[left])}


#: the smallest share of its straight volume a vertex move may leave an element (project_nodes)
MIN_VOLUME_SHARE = 0.2


def _straight_det(X4: np.ndarray) -> np.ndarray:
    """det of the straight map (k,) of elements with vertices X4 (k,4,3)."""
    return np.linalg.det(np.stack([X4[:, 1] - X4[:, 0], X4[:, 2] - X4[:, 0], X4[:, 3] - X4[:, 0]], axis=2))


def element_valid(mesh: Mesh, elements: np.ndarray, min_scaled: float = 0.05) -> np.ndarray:
    """(k,) bool: straight det > 0 and the P2 map's det J ≥ ``min_scaled`` × it at the degree-2
    quadrature points and the ten nodes."""
    from estimator import compiled
    from flexure.fem import TET_QUAD, tet_shape
    from flexure.post import REF_NODES

    _, dN = tet_shape(2, np.vstack([TET_QUAD[2][0], REF_NODES]))
    if compiled.available():
        from flexure._valid_kernels import element_valid as valid

        el = np.asarray(elements)
        el = np.flatnonzero(el) if el.dtype == bool else el.astype(np.int64).ravel()
        return valid(mesh.points, mesh.tets, el, dN, float(min_scaled))
    X = mesh.points[mesh.tets[elements]]
    straight = np.linalg.det(np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]], axis=2))
    det = np.linalg.det(np.einsum("eai,qak->eqik", X, dN))
    return (straight > 0) & (det >= min_scaled * straight[:, None]).all(axis=1)


def halve_until_valid(nodes, tets, n_nodes: int, move, invalid, tries: int) -> np.ndarray:
    """Back off the moves of ``nodes`` until every element of ``tets`` is valid: ``move(β)`` applies
    them scaled by β (one per node; interior motion included), ``invalid()`` → bool per row of
    ``tets``. The moved nodes of an invalid element are halved, ``tries`` times, then undone (β = 0);
    if no moved node touches the invalid elements, every move is undone. → β (len(nodes),)"""
    beta = np.ones(len(nodes))
    where = np.full(n_nodes, -1, np.int64)
    where[nodes] = np.arange(len(nodes))
    for k in range(tries + 1):
        move(beta)
        bad = invalid()
        if not bad.any():
            break
        back = where[np.unique(tets[bad])]
        back = back[back >= 0]
        if len(back) == 0:                                                 # folded by the interior alone: no move
            beta[:] = 0.0
            continue
        beta[back] = 0.0 if k >= tries - 1 else 0.5 * beta[back]
    return beta
