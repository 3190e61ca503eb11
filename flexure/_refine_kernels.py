"""Longest-edge bisection passes (flexure.refine) at a cost proportional to the refined region.

The same passes as ``refine._bisect_pass`` (closure to a fixpoint, then every element holding a
marked edge bisected at its chosen one), on an active set instead of the whole mesh: only the
elements holding a marked edge take part in the closure, found through a list of the elements
around every mid node (an edge's elements; a linked list, new elements prepended). Elements are
never moved: a bisected one is dropped (``alive`` False) and its children appended, each with its
rank in the reference order (``key``: the pass that made it, then child 1s before child 2s, then
its parent's rank), so the mesh handed back is the reference's, element for element. What is
cached per element (its edges' lengths, its longest edge) and per node (its edge's vertex pair)
does not change while the points stay put (no projection inside the passes; a split edge's mid node
put back on its chord, ``_straighten_folding_mids``, has its edges' lengths renewed where it was a vertex).
"""

from __future__ import annotations

import numpy as np

from flexure.mesh import TET_EDGES
from flexure.mesh_motion import MIN_VOLUME_SHARE, _straight_det

_MASK32 = np.int64(0xFFFFFFFF)
# -- the element-level rules of the bisection (flexure.refine uses them too) ------------------------
#: for edge t = (p, q): the two other local vertices (increasing)
_OTHER = np.array([[v for v in range(4) if v not in e] for e in TET_EDGES.tolist()], dtype=np.int64)
#: projection target priority by dim: a curve (1) over a surface (2) over none (0)
_PRIORITY = np.array([0, 2, 1])


def edge_codes(tets: np.ndarray) -> np.ndarray:
    """(m,6) int64 code lo·2³² + hi of every element edge's vertex pair."""
    V = tets[:, :4].astype(np.int64)
    a, b = V[:, TET_EDGES[:, 0]], V[:, TET_EDGES[:, 1]]
    return (np.minimum(a, b) << 32) | np.maximum(a, b)


def _longest_of(L2: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """Local index of the longest of each row's edges (squared lengths L2 (m,6)), ties by the larger code."""
    best = L2.max(axis=1)
    return np.where(L2 == best[:, None], codes, -1).argmax(axis=1)


def _edge_targets(face_tag: np.ndarray, edge_tag: np.ndarray):
    """(dim, tag) (m,6) of every element edge as the element sees it: its curve (1) if tagged,
    else the surface (2) of the element's faces that hold it (opposite its two other vertices)."""
    fa, fb = face_tag[:, _OTHER[:, 0]], face_tag[:, _OTHER[:, 1]]                # (m,6)
    surf = np.where(fa == fb, fa, np.where(fa == 0, fb, np.where(fb == 0, fa, 0)))
    return (np.where(edge_tag > 0, 1, np.where(surf > 0, 2, 0)), np.where(edge_tag > 0, edge_tag, surf))


def _p2_weights(bary: np.ndarray) -> np.ndarray:
    """P2 shape functions (k,10) at barycentric points (k,4) (VTK order, flexure.mesh)."""
    N = np.empty((len(bary), 10))
    N[:, :4] = bary * (2.0 * bary - 1.0)
    N[:, 4:] = 4.0 * bary[:, TET_EDGES[:, 0]] * bary[:, TET_EDGES[:, 1]]
    return N


#: refine.CLOSURE_RATIO's "as good": children's smallest dihedral angle at least the longest-edge children's, or this
QUALITY_FLOOR_DEG = 12.0


def edge_to_split(mk, L, le, Lmax, closure_ratio: float, ids, corners, q_cache: dict) -> np.ndarray:
    """The local edge (m,) each element bisects: its longest ``le``, or its longest marked one (``mk``
    (m,6), lengths ``L``) where that is at least ``closure_ratio`` × the longest ``Lmax`` and its
    children are as good (``QUALITY_FLOOR_DEG``). The children's verdict is cached in ``q_cache`` per
    (element id ``ids``, edge); ``corners(at)`` gives the corner points (k,4,3) of rows ``at``."""
    rows = np.arange(len(le))
    Lm = np.where(mk, L, -1.0)
    cand = Lm.argmax(axis=1)
    alt = ~mk[rows, le] & (Lm[rows, cand] >= closure_ratio * Lmax)
    if alt.any():
        at = np.flatnonzero(alt)
        key = ids[at] * 6 + cand[at]
        new = np.array([k not in q_cache for k in key.tolist()], bool)
        if new.any():
            corner = corners(at[new])
            qa = _children_min_dihedral(corner, cand[at[new]])
            ql = _children_min_dihedral(corner, le[at[new]])
            q_cache.update(zip(key[new].tolist(), (qa >= np.minimum(ql, QUALITY_FLOOR_DEG)).tolist()))
        alt[at] = np.array([q_cache[k] for k in key.tolist()], bool)
    return np.where(alt, cand, le)


def _children_min_dihedral(X4: np.ndarray, edge: np.ndarray) -> np.ndarray:
    """Smallest dihedral angle (k,) of the two children of tetrahedra X4 (k,4,3) bisected at local edge
    ``edge`` (k,) (TET_EDGES order)."""
    from flexure.mesh import element_shape_metrics

    r = np.arange(len(X4))
    i, j = TET_EDGES[edge, 0], TET_EDGES[edge, 1]
    m = 0.5 * (X4[r, i] + X4[r, j])
    c1, c2 = X4.copy(), X4.copy()
    c1[r, j], c2[r, i] = m, m
    pts = np.vstack([c1, c2]).reshape(-1, 3)
    tets = np.arange(len(pts)).reshape(-1, 4)
    d = element_shape_metrics(pts, tets)["dihedral_deg"].min(axis=1)
    return np.minimum(d[: len(X4)], d[len(X4):])


def _straighten_folding_mids(points, corners, r, i, j, m) -> np.ndarray:
    """Put the mid nodes ``m`` of split edges (i, j) (local, per element ``corners`` (k,4)) back on their
    chords (in place) where a child would be folded: the mid node becomes a vertex of both children,
    and on a thin element along a curved boundary it can lie beyond the opposite face, so a child's
    straight det falls below ``MIN_VOLUME_SHARE`` (the share of its volume a vertex move may leave)
    × its straight half D/2 of the parent's D (≤ 0: a child no mid node can mend). On the chord the
    children are the straight halves (D/2 each); the node, a projection target of the pass, goes back
    on the surface as far as its elements stay valid (mesh_motion.project_nodes). → the nodes moved
    (unique)."""
    X = points[corners]                                            # (k,4,3)
    D = _straight_det(X)
    c1, c2 = X.copy(), X.copy()
    c1[r, j] = points[m]
    c2[r, i] = points[m]
    fold = np.minimum(_straight_det(c1), _straight_det(c2)) < MIN_VOLUME_SHARE * 0.5 * D
    if fold.any():
        points[m[fold]] = 0.5 * (X[r[fold], i[fold]] + X[r[fold], j[fold]])
    return np.unique(m[fold])


# -- the passes ---------------------------------------------------------------------------------------
def _grow(a: np.ndarray, need: int) -> np.ndarray:
    """``a`` with room for at least ``need`` rows (× 1.5; the new rows not set)."""
    if need <= len(a):
        return a
    b = np.empty((max(need, len(a) + len(a) // 2),) + a.shape[1:], a.dtype)
    b[: len(a)] = a
    return b


def _pair(x, y):
    return (np.minimum(x, y) << 32) | np.maximum(x, y)


class Bisector:
    """The mesh under bisection: elements (slots, never reused), nodes, and the edge → element lists.

    ``topology``: only the nodes and the element connectivity are kept (no fields, face or edge
    tags, projection targets): what a trial that counts the new nodes needs."""

    def __init__(self, points, tets, face_tag, edge_tag, fields=(), topology: bool = False):
        self.topology = topology
        m, n = len(tets), len(points)
        self.M, self.n = m, n
        self.tets = np.array(tets, np.int64)
        self.codes = edge_codes(self.tets)
        self.alive = np.ones(m, bool)
        self.flag = np.zeros(m, bool)
        self.key = np.arange(m, dtype=np.int64)
        if not topology:
            self.ft, self.et = np.array(face_tag, np.int64), np.array(edge_tag, np.int64)
        self.fields = [] if topology else [np.array(f, float) for f in fields]
        self.points = np.array(points, float)
        eid = self.tets[:, 4:]
        self.code = np.zeros(n, np.int64)
        self.code[eid] = self.codes
        mids = np.unique(eid)
        self.L2n, self.Ln = np.zeros(n), np.zeros(n)
        self._lengths(mids)
        self.L = self.Ln[eid]
        self.le = _longest_of(self.L2n[eid], self.codes)
        self.emark = np.zeros(n, bool)
        self.refc = np.bincount(eid.ravel(), minlength=n).astype(np.int64)
        self.head = np.full(n, -1, np.int64)
        self.nxt = np.full(6 * m, -1, np.int64)
        self._link(np.arange(6 * m, dtype=np.int64), eid.ravel())
        # an existing edge is found by its vertex pair among the edges that are some live element's
        # now (the reference's rule); such an edge holds a vertex made by an earlier bisection (or, in
        # a start mesh with hanging nodes, a mid node that is a vertex too): the made edges are kept,
        # one sorted chunk (codes, nodes) per pass
        self.vert = np.zeros(n, bool)
        self.vert[self.tets[:, :4]] = True
        hang = mids[self.vert[mids]]
        seed = mids[np.isin(self.code[mids] >> 32, hang) | np.isin(self.code[mids] & _MASK32, hang)]
        o = np.lexsort((seed, self.code[seed]))
        self.made = [(self.code[seed][o], seed[o])]
        self.passes = 0

    # -- storage ---------------------------------------------------------------------------------
    def _lengths(self, nodes):
        """Squared length and length of each node's edge (as the reference computes them)."""
        c = self.code[nodes]
        d = self.points[c & _MASK32] - self.points[c >> 32]
        self.L2n[nodes] = np.einsum("ei,ei->e", d, d)
        self.Ln[nodes] = np.linalg.norm(d, axis=1)

    def _link(self, ents, nodes):
        """Prepend element edges ``ents`` (slot·6 + local edge) to their mid nodes' lists (a node listed
        k times: where a write to the head is lost to another of its entries, that one goes next; k steps)."""
        while len(ents):
            self.nxt[ents] = self.head[nodes]
            self.head[nodes] = ents
            lost = self.head[nodes] != ents
            ents, nodes = ents[lost], nodes[lost]

    def holders(self, nodes) -> np.ndarray:
        """The element edges (slot·6 + local edge) of the live elements that hold mid nodes ``nodes`` (unique)."""
        cur = self.head[nodes]
        cur = cur[cur >= 0]
        out = []
        while len(cur):
            out.append(cur)
            cur = self.nxt[cur]
            cur = cur[cur >= 0]
        ents = np.concatenate(out) if out else np.zeros(0, np.int64)
        return ents[self.alive[ents // 6]]

    def _find(self, codes) -> np.ndarray:
        """The node of each edge (vertex-pair code) that is some live element's mid node, else −1."""
        found = np.full(len(codes), -1, np.int64)
        for c, nodes in self.made:
            if len(c) == 0 or len(codes) == 0:
                continue
            pos = np.minimum(np.searchsorted(c, codes), len(c) - 1)
            cand = nodes[pos]
            ok = (c[pos] == codes) & (self.refc[cand] > 0) & (found < 0)
            found[ok] = cand[ok]
        return found

    def _refresh(self, nodes):
        """After vertices ``nodes`` moved: their live edges' lengths and their elements' longest edges."""
        live = np.flatnonzero(self.refc[: self.n] > 0)
        c = self.code[live]
        at = live[np.isin(c >> 32, nodes) | np.isin(c & _MASK32, nodes)]
        self._lengths(at)
        slots = np.unique(self.holders(at) // 6)
        eid = self.tets[slots, 4:]
        self.L[slots] = self.Ln[eid]
        self.le[slots] = _longest_of(self.L2n[eid], self.codes[slots])

    def _add_nodes(self, k):
        need = self.n + k
        self.points = _grow(self.points, need)
        self.fields = [_grow(f, need) for f in self.fields]
        for name in ("code", "L2n", "Ln", "emark", "refc", "vert"):
            setattr(self, name, _grow(getattr(self, name), need))
        self.head = _grow(self.head, need)

    def _add_elements(self, k):
        need = self.M + k
        names = ("tets", "codes", "alive", "flag", "key", "L", "le") + (() if self.topology else ("ft", "et"))
        for name in names:
            setattr(self, name, _grow(getattr(self, name), need))
        self.nxt = _grow(self.nxt, 6 * need)

    # -- rounds and passes -----------------------------------------------------------------------
    def start_round(self) -> np.ndarray:
        """Mark the longest edge of every flagged element → the active set (slots holding a mark)."""
        F = np.flatnonzero(self.flag[: self.M] & self.alive[: self.M])
        self.emark[: self.n] = False
        nodes = np.unique(self.tets[F, 4 + self.le[F]])
        self.emark[nodes] = True
        return np.unique(self.holders(nodes) // 6)

    def bisect_pass(self, A: np.ndarray, closure_ratio: float):
        """``refine._bisect_pass`` on the active set ``A`` → (new active set, targets, bisections)."""
        emark = self.emark
        rows = np.arange(len(A))
        eidA, L, le = self.tets[A, 4:], self.L[A], self.le[A]
        mk = emark[eidA]
        Lmax = L[rows, le]
        q_cache = {}
        while True:                                   # closure to a fixpoint
            chosen = edge_to_split(mk, L, le, Lmax, closure_ratio, A,
                                   lambda at, A=A: self.points[self.tets[A[at], :4]], q_cache)
            need = mk.any(axis=1) & ~mk[rows, chosen]
            if not need.any():
                break
            nodes = np.unique(eidA[need, le[need]])
            nodes = nodes[~emark[nodes]]
            emark[nodes] = True
            into = np.unique(self.holders(nodes) // 6)
            into = into[~np.isin(into, A, assume_unique=True)]
            if len(into):
                A = np.concatenate([A, into])
                rows = np.arange(len(A))
                eidA = np.vstack([eidA, self.tets[into, 4:]])
                L, le = np.vstack([L, self.L[into]]), np.concatenate([le, self.le[into]])
                Lmax = L[rows, le]
            mk = emark[eidA]
        sel = np.flatnonzero(mk[rows, chosen])
        if len(sel) == 0:
            return A[:0], None, 0
        order = np.argsort(self.key[A[sel]])          # the reference's element order
        B, e = A[sel][order], chosen[sel][order]
        targets = self._split(B, e)
        rest = A[self.alive[A]]
        kids = np.arange(self.M - 2 * len(B), self.M)
        kids = kids[self.emark[self.tets[kids, 4:]].any(axis=1)]
        return np.concatenate([rest, kids]), targets, len(B)

    def _split(self, B, e):
        """Bisect elements ``B`` (in the reference order) at local edges ``e`` (as ``refine._bisect_pass``)
        → projection targets of the new nodes and of the split edges' nodes (None for ``topology``)."""
        n, nb = self.n, len(B)
        i, j = TET_EDGES[e, 0], TET_EDGES[e, 1]
        k, l = _OTHER[e, 0], _OTHER[e, 1]
        TB = self.tets[B]
        r = np.arange(nb)
        vi, vj, vk, vl = TB[r, i], TB[r, j], TB[r, k], TB[r, l]
        m = TB[r, 4 + e]
        moved = _straighten_folding_mids(self.points, TB[:, :4], r, i, j, m)
        if self.vert[moved].any():                    # a vertex already: the lengths of its edges change
            self._refresh(moved[self.vert[moved]])
        new_codes = np.concatenate([_pair(vi, m), _pair(vj, m), _pair(m, vk), _pair(m, vl)])
        uniq, first, inv = np.unique(new_codes, return_index=True, return_inverse=True)
        inv = inv.ravel()
        ask = np.zeros(len(uniq), bool)
        ask[inv] = np.tile(self.vert[m], 4)           # only an edge at a vertex made before can exist
        node_of = np.full(len(uniq), -1, np.int64)
        node_of[ask] = self._find(uniq[ask])
        exists = node_of >= 0
        node_of[~exists] = 0
        fresh = np.flatnonzero(~exists)
        nf = len(fresh)
        node_of[fresh] = n + np.arange(nf)
        bary = np.zeros((4, nb, 4))
        bary[0, r, i], bary[0, r, j] = 0.75, 0.25
        bary[1, r, i], bary[1, r, j] = 0.25, 0.75
        bary[2, r, i] = bary[2, r, j] = bary[3, r, i] = bary[3, r, j] = 0.25
        bary[2, r, k] = bary[3, r, l] = 0.5
        src = first[fresh]                            # occurrence that places each fresh node
        N = _p2_weights(bary.reshape(-1, 4)[src])
        P = TB[src % nb]
        self._add_nodes(nf)
        new = slice(n, n + nf)
        self.points[new] = np.einsum("ka,kai->ki", N, self.points[P])
        for f in self.fields:
            f[new] = np.einsum("ka,ka...->k...", N, f[P])
        self.code[new] = uniq[fresh]
        self.emark[new] = False
        self.refc[new] = 0
        self.head[new] = -1
        self.n = n + nf
        self._lengths(np.arange(n, n + nf))
        self.made.append((uniq[fresh], node_of[fresh]))
        self.vert[new] = False
        self.vert[m] = True
        targets = None
        if not self.topology:
            ft, et = self.ft, self.et
            fk, fl = ft[B, k], ft[B, l]
            # an edge's target over every element that holds it, in the reference's element order
            um = np.unique(m)
            ents = self.holders(um)
            slot, jj = ents // 6, ents % 6
            o = np.lexsort((jj, self.key[slot]))
            slot, jj = slot[o], jj[o]
            h = np.arange(len(slot))
            edim, etag = _edge_targets(ft[slot], et[slot])
            edim, etag = edim[h, jj], etag[h, jj]
            pos = np.searchsorted(um, self.tets[slot, 4 + jj])
            order = np.lexsort((_PRIORITY[edim], pos))
            best_dim = np.zeros(len(um), np.int64)
            best_tag = np.zeros(len(um), np.int64)
            best_dim[pos[order]] = edim[order]
            best_tag[pos[order]] = etag[order]
            mpos = np.searchsorted(um, m)
            dim_e, tag_e = best_dim[mpos], best_tag[mpos]
            dims = np.concatenate([dim_e, dim_e, np.where(fl > 0, 2, 0), np.where(fk > 0, 2, 0)])
            tags = np.concatenate([tag_e, tag_e, fl, fk])
            prio = np.zeros(len(uniq), np.int64)
            best_tag = np.zeros(len(uniq), np.int64)
            order = np.lexsort((_PRIORITY[dims], inv))
            prio[inv[order]] = dims[order]
            best_tag[inv[order]] = tags[order]
            targets = [np.concatenate([node_of[fresh], m]), np.concatenate([prio[fresh], dim_e]),
                       np.concatenate([best_tag[fresh], tag_e])]
        qa, qb, nk, nl = node_of[inv].reshape(4, nb)
        kids, kft, ket = [], [], []
        for gone, q in ((j, qa), (i, qb)):            # child 1: vj → m; child 2: vi → m
            child = TB.copy()
            child[r, gone] = m
            if not self.topology:
                fc = self.ft[B].copy()
                fc[r, np.where(gone == j, i, j)] = 0      # the new interior face (opposite the kept end)
                ec = self.et[B].copy()
            for t in range(6):
                p_, q_ = TET_EDGES[t]
                touches = (p_ == gone) | (q_ == gone)
                other = np.where(p_ == gone, q_, p_)
                split = touches & (t == e)
                child[:, 4 + t] = np.where(~touches, TB[:, 4 + t], np.where(split, q, np.where(other == k, nk, nl)))
                if not self.topology:
                    ec[touches & ~split, t] = 0
            kids.append(child)
            if not self.topology:
                kft.append(fc)
                ket.append(ec)
        M = self.M
        self._add_elements(2 * nb)
        s = slice(M, M + 2 * nb)
        K = np.vstack(kids)
        self.tets[s] = K
        if not self.topology:
            self.ft[s], self.et[s] = np.vstack(kft), np.vstack(ket)
        self.flag[s] = np.tile(self.flag[B], 2)
        self.alive[s] = True
        self.alive[B] = False
        self.passes += 1
        self.key[s] = (np.int64(self.passes) << 32) | np.arange(2 * nb, dtype=np.int64)
        np.subtract.at(self.refc, TB[:, 4:].ravel(), 1)
        np.add.at(self.refc, K[:, 4:].ravel(), 1)
        codes = edge_codes(K)
        self.codes[s] = codes
        eid = K[:, 4:]
        self.L[s] = self.Ln[eid]
        self.le[s] = _longest_of(self.L2n[eid], codes)
        self.M = M + 2 * nb
        self._link((np.arange(M, M + 2 * nb, dtype=np.int64)[:, None] * 6 + np.arange(6)).ravel(), eid.ravel())
        return targets

    def result(self):
        """(points, tets, face_tag, edge_tag, fields, kept) in the reference's element order; the first
        ``kept`` elements are the start mesh's that were not bisected, in their order."""
        S = np.flatnonzero(self.alive[: self.M])
        S = S[np.argsort(self.key[S])]
        n = self.n
        ft, et = (None, None) if self.topology else (self.ft[S], self.et[S])
        kept = int(np.count_nonzero(self.key[S] < np.int64(1) << 32))     # the start mesh's unsplit elements, first
        return self.points[:n].copy(), self.tets[S], ft, et, [f[:n].copy() for f in self.fields], kept


def passes(points, tets, face_tag, edge_tag, elements, fields=(), rounds: int = 1, closure_ratio: float = 1.0,
           max_passes: int = 200, topology: bool = False):
    """``rounds`` rounds of passes (refine.bisect) → (points, tets, face_tag, edge_tag, fields,
    targets [(nodes, dims, tags) per pass], passes, bisections, kept: how many of the first elements
    are the start mesh's, not bisected)."""
    bs = Bisector(points, tets, face_tag, edge_tag, fields, topology)
    bs.flag[np.asarray(elements)] = True
    targets, count, bisections = [], 0, 0
    for _ in range(rounds):
        A = bs.start_round()
        while True:
            A, tgt, nb = bs.bisect_pass(A, closure_ratio)
            if nb == 0:
                break
            count += 1
            bisections += nb
            targets.append(tgt)
            if count > max_passes:
                raise RuntimeError("bisect: the closure did not end")
    points, tets, face_tag, edge_tag, fields, kept = bs.result()
    return points, tets, face_tag, edge_tag, fields, targets, count, bisections, kept
