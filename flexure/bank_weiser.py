"""The error of a P2 displacement field element by element, from its residuals (Bank & Weiser 1985):
on each element K, in the cubic surplus space W_K (edge cubics L_p L_q (L_p − L_q) and face bubbles
L_a L_b L_c, times the three components; no rigid motion lies in it),

    a_K(e_K, v) = −∫_K σ(u_h) : ε(v) dV + ∫_∂K t̂ · v dA        for all v ∈ W_K,

t̂ = ½ (σ_K n_K − σ_K' n_K') on a face shared with K' (the averaged traction), the applied
traction on a loaded free face, 0 on a free face; functions on clamped or rigidly coupled edges and
faces are left out (the error vanishes there). The right-hand side is the element residual plus
half the traction jumps: unlike a weight recovered by fitting u_h, it sees the jumps at sharp edges
and supports, where the fields are singular and most of the error of a flexure sits. Solved for all
elements at once ((m, 30, 30) batched). flexure.dwr averages the shared edge and face coefficients
into a continuous weight w ≈ u − I_h u. Faces are integrated as flat (their vertices' plane).
"""

from __future__ import annotations

from itertools import permutations

import numpy as np

from flexure.mesh import TET_FACES, TET_FACES_P2, Mesh

_PERMS = list(permutations(range(3)))


def _face_rule():
    """Canonical face points: ξ (4·q, 3) of the degree-4 triangle rule on each face f (its local
    vertices TET_FACES[f] in that order), the weights (q,), and the table T (6, q): the canonical
    point index of the point that the face's vertices sorted by global number, permuted by
    _PERMS[p] from the canonical order, list as q' (the rule is symmetric under S₃)."""
    from flexure.fem import TRI_QUAD

    st, w = TRI_QUAD
    L3 = np.column_stack([1.0 - st.sum(axis=1), st])                          # (q,3)
    lam = np.zeros((4, len(st), 4))
    for f in range(4):
        lam[f][:, TET_FACES[f]] = L3
    T = np.zeros((6, len(st)), np.int64)
    for p, order in enumerate(_PERMS):                      # sorted vertex j is canonical vertex order[j]
        for q2 in range(len(st)):
            want = np.zeros(3)
            want[list(order)] = L3[q2]
            T[p, q2] = int(np.argmin(np.abs(L3 - want).sum(axis=1)))
    return lam[..., 1:].reshape(-1, 3), w, T


def point_jacobians(X: np.ndarray, dN: np.ndarray):
    """det J (e,q) and J⁻¹ (e,q,3,3) (J⁻¹[k,i] = ∂ξ_k/∂x_i) of P2 elements with nodes X (e,10,3) at
    reference points with shape gradients dN (q,10,3); straight elements (mid nodes at their edges'
    midpoints) are done once per element; with numba every point by a compiled loop."""
    from flexure import stiffness_assembly
    from flexure.mesh import TET_EDGES

    if stiffness_assembly.available():
        return stiffness_assembly.jacobians(X, dN)

    nq = dN.shape[0]
    mid = 0.5 * (X[:, TET_EDGES[:, 0]] + X[:, TET_EDGES[:, 1]])
    h = np.abs(X[:, 1:4] - X[:, :1]).max(axis=(1, 2))
    curved = np.abs(X[:, 4:] - mid).max(axis=(1, 2)) > 1e-10 * h
    V = X[:, :4]
    J0 = np.stack([V[:, 1] - V[:, 0], V[:, 2] - V[:, 0], V[:, 3] - V[:, 0]], axis=2)
    det = np.repeat(np.linalg.det(J0)[:, None], nq, axis=1)
    Jinv = np.repeat(np.linalg.inv(J0)[:, None], nq, axis=1)
    if curved.any():
        Jc = np.einsum("eai,qak->eqik", X[curved], dN, optimize=True)
        det[curved] = np.linalg.det(Jc)
        Jinv[curved] = np.linalg.inv(Jc)
    return det, Jinv


def _stress(u_e, G, lmb, mu):
    """σ (e,q,3,3) from element displacements u_e (e,10,3) and ∂N/∂x G (e,q,10,3)."""
    H = np.einsum("eac,eqaj->eqcj", u_e, G, optimize=True)
    eps = 0.5 * (H + H.swapaxes(-1, -2))
    return 2.0 * mu * eps + lmb * np.trace(eps, axis1=-2, axis2=-1)[..., None, None] * np.eye(3)


def local_errors(mesh: Mesh, material, u: np.ndarray, constrained: np.ndarray, traction=None,
                 chunk: int = 4000):
    """Element-local surplus coefficients of the error (edges (m,6,3) in each element's own edge
    orientation, faces (m,4,3)) of the P2 displacement u (n,3); ``traction``: an optional
    (face mask (m,4) bool, t(x) (…,3) → (…,3)) of loaded free faces."""
    coef = np.zeros((mesh.n_elements, 10, 3))
    for sl, A, r, _ in element_blocks(mesh, material, u, constrained, traction, chunk):
        coef[sl] = np.linalg.solve(A, r[..., None])[..., 0].reshape(-1, 10, 3)
    return coef[:, :6], coef[:, 6:]


def element_blocks(mesh: Mesh, material, u: np.ndarray, constrained: np.ndarray, traction=None,
                   chunk: int = 4000):
    """Per chunk of elements: (slice, A (e,30,30), r (e,30), kept (e,30)) — the surplus stiffness
    a_K(φ_b, φ_c) and the right-hand side −a_K(u_h, φ_b) + ∫_∂K t̂·φ_b of the local problems above,
    rows (b, i) → 3b + i; constrained functions have an identity row and a zero right-hand side.
    The traction-jump terms cancel between neighbours, so assembled they give the global residual
    R(u_h)(φ) (flexure.enriched)."""
    from flexure.surplus import surplus_basis, tet_rule_degree5
    from flexure.fem import tet_shape

    u = np.asarray(u, float).reshape(-1, 3)
    m = mesh.n_elements
    t = mesh.tets
    lmb, mu = material.lame_lambda_Pa, material.shear_modulus_Pa
    rhs = face_rhs(mesh, material, u, traction, chunk)
    # pass 2: element matrices, −a_K(u_h, φ), solve
    xi, wq = tet_rule_degree5()
    _, dN2 = tet_shape(2, xi)
    _, dBs = surplus_basis(xi)
    keep = np.ones((m, 10), bool)
    keep[:, :6] = ~constrained[t[:, 4:]]
    keep[:, 6:] = ~constrained[t[:, TET_FACES_P2]].all(axis=2)
    diag = np.arange(30)
    for s in range(0, m, chunk):
        sl = slice(s, min(m, s + chunk))
        X = mesh.points[t[sl]]
        e = len(X)
        det, Jinv = point_jacobians(X, dN2)
        sig = _stress(u[t[sl]], np.matmul(dN2[None], Jinv), lmb, mu)
        gB = np.matmul(dBs[None], Jinv)                                          # (e,q,b,j)
        dv = wq[None, :] * det
        r = rhs[sl] - np.einsum("eq,eqij,eqbj->ebi", dv, sig, gB, optimize=True)
        P = np.einsum("eq,eqbi,eqcj->ebcij", dv, gB, gB, optimize=True)          # (e,10,10,3,3)
        A = lmb * P + mu * P.swapaxes(-1, -2)
        A += mu * np.trace(P, axis1=-2, axis2=-1)[..., None, None] * np.eye(3)
        A = A.transpose(0, 1, 3, 2, 4).reshape(e, 30, 30)
        kk = np.repeat(keep[sl], 3, axis=1)                                      # (e,30)
        A = np.where(kk[:, :, None] & kk[:, None, :], A, 0.0)
        A[:, diag, diag] = np.where(kk, A[:, diag, diag], 1.0)
        r = np.where(kk, r.reshape(e, 30), 0.0)
        yield sl, A, r, kk


def face_rhs(mesh: Mesh, material, u: np.ndarray, traction=None, chunk: int = 4000) -> np.ndarray:
    """The face term ∫_∂K t̂ · φ_b dA of the local problems (module docstring) of the P2 displacement
    u (n,3): → (m,10,3), rows (b, i)."""
    from flexure.fem import tet_shape
    from flexure.surplus import surplus_basis

    u = np.asarray(u, float).reshape(-1, 3)
    m = mesh.n_elements
    t = mesh.tets
    t4 = mesh.corner_tets.astype(np.int64)
    lmb, mu = material.lame_lambda_Pa, material.shear_modulus_Pa
    xi_f, wq_f, T = _face_rule()
    nq = len(wq_f)
    _, dN_f = tet_shape(2, xi_f)
    Bf = surplus_basis(xi_f)[0].reshape(4, nq, 10)
    # outward area vectors of the flat faces, and each face's sorted-vertex permutation
    X4 = mesh.points[t4]
    fv = X4[:, TET_FACES]                                                       # (m,4,3,3)
    avec = 0.5 * np.cross(fv[:, :, 1] - fv[:, :, 0], fv[:, :, 2] - fv[:, :, 0])
    area = np.linalg.norm(avec, axis=2)
    nhat = avec / np.maximum(area, 1e-300)[..., None]
    glob = t4[:, TET_FACES]                                                     # (m,4,3)
    order = np.argsort(glob, axis=2)
    lut = np.zeros(27, np.int64)
    for i, p in enumerate(_PERMS):
        lut[9 * p[0] + 3 * p[1] + p[2]] = i
    perm = T[lut[9 * order[..., 0] + 3 * order[..., 1] + order[..., 2]]]       # (m,4,q'): canonical q
    from flexure import stiffness_assembly

    if traction is None and stiffness_assembly.available():
        return _face_rhs_compiled(mesh, u, lmb, mu, glob, perm, dN_f, Bf, wq_f, area, nhat)
    # pass 1: outward traction τ = σ n at every face point, listed in sorted-vertex order
    tau = np.empty((m, 4, nq, 3))
    for s in range(0, m, chunk):
        sl = slice(s, min(m, s + chunk))
        X = mesh.points[t[sl]]
        _, Jinv = point_jacobians(X, dN_f)
        sig = _stress(u[t[sl]], np.matmul(dN_f[None], Jinv), lmb, mu).reshape(-1, 4, nq, 3, 3)
        tc = np.einsum("efqij,efj->efqi", sig, nhat[sl])
        tau[sl] = np.take_along_axis(tc, perm[sl][..., None], axis=2)
    key = np.sort(glob, axis=2).reshape(-1, 3)
    nn = np.int64(mesh.n_nodes)                    # one int64 code per face (its sorted vertices)
    code = (key[:, 0] * nn + key[:, 1]) * nn + key[:, 2] if mesh.n_nodes < 2_000_000 else key
    _, finv, fcnt = np.unique(code, axis=0 if code.ndim == 2 else None, return_inverse=True, return_counts=True)
    finv = finv.reshape(m, 4)
    flat = tau.reshape(-1, nq * 3)                 # Σ over a face's (≤ 2) elements, in element order
    tot = np.column_stack([np.bincount(finv.ravel(), flat[:, k], len(fcnt))
                           for k in range(nq * 3)]).reshape(-1, nq, 3)
    interior = fcnt[finv] == 2
    # t̂ = ½(τ_K − τ_K') = τ_K − ½(τ_K + τ_K') on an interior face; 0 on a free one
    that = np.where(interior[..., None, None], tau - 0.5 * tot[finv], 0.0)
    if traction is not None:                       # a loaded free face: the applied traction
        mask, tfun = traction
        from flexure.fem import TRI_QUAD

        st = TRI_QUAD[0]
        L3 = np.column_stack([1.0 - st.sum(axis=1), st])
        xq = np.einsum("qj,mfji->mfqi", L3, fv)                                 # canonical order
        tx = np.take_along_axis(tfun(xq), perm[..., None], axis=2)
        that = np.where((mask & ~interior)[..., None, None], tx, that)
    del tau, tot
    # face term of the right-hand side, back in canonical point order: Σ_q 2A w_q t̂_i B_b
    inv_perm = np.argsort(perm, axis=2)
    that_c = np.take_along_axis(that, inv_perm[..., None], axis=2)
    rhs = np.einsum("mf,q,mfqi,fqb->mbi", 2.0 * area, wq_f, that_c, Bf, optimize=True)
    del that, that_c
    return rhs


def _face_pairs(glob: np.ndarray, n_nodes: int) -> np.ndarray:
    """The other element face (flat index 4 e' + f') sharing each element face (m,4) of vertices
    ``glob`` (m,4,3), −1 on a face of one element."""
    m = len(glob)
    key = np.sort(glob, axis=2).reshape(-1, 3).astype(np.int64)
    nn = np.int64(n_nodes)
    code = (key[:, 0] * nn + key[:, 1]) * nn + key[:, 2] if n_nodes < 2_000_000 else key
    _, finv, fcnt = np.unique(code, axis=0 if code.ndim == 2 else None, return_inverse=True, return_counts=True)
    finv = finv.ravel()
    o = np.argsort(finv, kind="stable")
    fs = finv[o]
    i = np.flatnonzero((fs[1:] == fs[:-1]) & (fcnt[fs[1:]] == 2))
    partner = np.full(4 * m, -1, np.int64)
    partner[o[i]], partner[o[i + 1]] = o[i + 1], o[i]
    return partner


def _face_rhs_compiled(mesh: Mesh, u, lmb, mu, glob, perm, dN_f, Bf, wq_f, area, nhat) -> np.ndarray:
    """``face_rhs`` without an applied traction by compiled element loops (flexure._indicator_kernels):
    the tractions τ at each face's points, then t̂ from the face's partner and the face integrals."""
    from flexure import _indicator_kernels as ik
    from flexure import threads

    m, nq = len(glob), len(wq_f)
    tets = np.ascontiguousarray(mesh.tets, np.int64)
    tau = np.empty((m, 4, nq, 3))
    rhs = np.empty((m, 10, 3))
    perm = np.ascontiguousarray(perm, np.int64)
    nt = threads.use()
    with threads.dynamic():
        ik.face_tractions(np.ascontiguousarray(mesh.points, float), tets, np.ascontiguousarray(u).reshape(-1, 3, 1),
                          np.ascontiguousarray(dN_f), np.ascontiguousarray(nhat), float(lmb), float(mu), tau,
                          1 if nt == 1 else 8 * nt)
        ik.face_terms(tau, _face_pairs(glob, mesh.n_nodes), perm, np.ascontiguousarray(np.argsort(perm, axis=2)),
                      np.ascontiguousarray(area), np.ascontiguousarray(wq_f, float), np.ascontiguousarray(Bf),
                      rhs, 1 if nt == 1 else 8 * nt)
    return rhs
