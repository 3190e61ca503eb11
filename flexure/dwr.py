"""Goal-oriented (dual-weighted residual) error estimates for P2 elasticity.

For a goal J linear in the displacement (a gauge's read-out; the rotation θ = bᵀq under a unit
moment, whose reciprocal is the stiffness) with dual (adjoint) solution z, a(v, z) = J(v) for all v,
and the discrete solutions u_h, z_h of the same matrix (z_h: one more right-hand side),

    J(u) − J(u_h) = R(u_h)(z − I_h z),        R(u_h)(v) = F(v) − a(u_h, v)                 (1)

(Galerkin orthogonality lets any V_h function be subtracted from z). The stiffness' goal is its
own dual (z = u: J(u) − J(u_h) = a(e, e) ≥ 0). The weight z − I_h z is approximated by
w = z̃ − I_h z̃, z̃ a P3 field recovered from z_h: on each element the hierarchical cubic surplus

    w = Σ_edges c_e L_p L_q (L_p − L_q) + Σ_faces c_f L_a L_b L_c,
    c_e = D³z[d, d, d] / 12  (d = x_q − x_p),    c_f = 27 (q − I₂q)(face centroid),  q = D³z[x − x_c]³/6,

which is exact, w = z − I₂z, for a cubic z. D³z is the gradient of the P1 interpolant of the
vertex Hessians, each the value at the vertex of the least-squares linear fit of the elements'
constant P2 Hessians over its patch (exact for a cubic); edge and face coefficients are averaged
over the elements that share them, so w is continuous, and set to zero on constrained edges and
faces (clamped or rigidly coupled: w must lie in the constrained space).

(1) is evaluated in weak form, no jumps or second derivatives, and localised by the P1 partition
of unity ψ_a (Richter & Wick 2015): η_a = R(u_h)(w ψ_a), Σ_a η_a = R(u_h)(w). The element
indicator for marking is η_K = Σ_{a∈K} |η_a| |K| / |ω_a|.
"""

from __future__ import annotations

import numpy as np

from flexure.mesh import TET_EDGES, TET_FACES, Mesh
from flexure.refine import edge_codes
from flexure.surplus import surplus_basis, tet_rule_degree5


def _straight_grad_L(X4: np.ndarray):
    """∇L_a (m,4,3) of the straight elements (vertices X4 (m,4,3)) and their volumes (m,)."""
    J = np.stack([X4[:, 1] - X4[:, 0], X4[:, 2] - X4[:, 0], X4[:, 3] - X4[:, 0]], axis=2)   # (m,i,k)
    Jinv = np.linalg.inv(J)                                                                  # (m,k,i)
    g = np.empty((len(X4), 4, 3))
    g[:, 1:] = Jinv
    g[:, 0] = -Jinv.sum(axis=1)
    return g, np.linalg.det(J) / 6.0


#: exponents of the 20 monomials of degree ≤ 3 in (x, y, z); the last 10 are the cubic ones
_EXPONENTS = np.array([(i, j, k) for d in range(4) for i in range(d, -1, -1) for j in range(d - i, -1, -1)
                       for k in [d - i - j]])
#: (p, q, r) → index of the cubic monomial ∂_p ∂_q ∂_r picks, and its factor α! (x³ → 6, x²y → 2, xyz → 1)
_D3_INDEX = np.zeros((3, 3, 3), np.int64)
_D3_FACTOR = np.zeros((3, 3, 3))
for _p in range(3):
    for _q in range(3):
        for _r in range(3):
            _al = np.bincount([_p, _q, _r], minlength=3)
            _D3_INDEX[_p, _q, _r] = int(np.flatnonzero((_EXPONENTS == _al).all(axis=1))[0])
            _D3_FACTOR[_p, _q, _r] = float(np.prod([[1, 1, 2, 6][v] for v in _al]))


def _monomials(y: np.ndarray) -> np.ndarray:
    """The 20 monomials (…, 20) of degree ≤ 3 at points y (…, 3)."""
    pw = np.stack([np.ones_like(y), y, y * y, y * y * y], axis=-1)            # (…, 3, 4)
    return pw[..., 0, _EXPONENTS[:, 0]] * pw[..., 1, _EXPONENTS[:, 1]] * pw[..., 2, _EXPONENTS[:, 2]]


def _patch_normal_equations(mesh: Mesh, Z: np.ndarray, vert: np.ndarray, elem: np.ndarray,
                            h: np.ndarray, row: np.ndarray, n_rows: int, chunk: int = 80000):
    """Σ over the pairs (vertex a = ``vert``, element K = ``elem``) of ΦᵀΦ and ΦᵀZ into
    (n_rows, 20, 20) and (n_rows, 20, K) at ``row``, Φ the monomials at K's ten nodes in the
    coordinates (x − x_a)/h_a."""
    import scipy.sparse as sp

    t = mesh.tets
    K = Z.shape[1]
    M = np.zeros((n_rows, 400))
    R = np.zeros((n_rows, 20 * K))
    for s in range(0, len(vert), chunk):
        v, e, r = vert[s:s + chunk], elem[s:s + chunk], row[s:s + chunk]
        S = sp.csr_matrix((np.ones(len(v)), (r, np.arange(len(v)))), shape=(n_rows, len(v)))
        y = (mesh.points[t[e]] - mesh.points[v][:, None, :]) / h[v][:, None, None]
        Phi = _monomials(y)                                                  # (p,10,20)
        M += S @ np.matmul(Phi.transpose(0, 2, 1), Phi).reshape(-1, 400)
        R += S @ np.matmul(Phi.transpose(0, 2, 1), Z[t[e]]).reshape(-1, 20 * K)
    return M.reshape(n_rows, 20, 20), R.reshape(n_rows, 20, K)


#: a vertex patch whose scaled normal matrix has its smallest eigenvalue below this fraction of
#: its row count is refitted on its two-ring (the elements touching its patch)
DETERMINED = 1e-7


def third_derivatives(mesh: Mesh, Z: np.ndarray, ridge: float = 1e-9) -> np.ndarray:
    """D³ (m, K, 3, 3, 3) of the fields Z (n, K) on every element: the mean over its four vertices
    of the third derivatives of the least-squares cubic fitted to the P2 nodal values of the
    elements around the vertex (each element's 10 nodes; exact when Z holds a cubic's values).
    Coordinates (x − x_a)/h_a, h_a the patch's mean element size. A patch too small to fix a
    cubic (a corner or a sharp edge with few elements) is widened to its two-ring; a ridge on the
    cubic terms keeps whatever is left solvable."""
    import scipy.sparse as sp

    t4 = mesh.corner_tets.astype(np.int64)
    m, n, K = len(t4), mesh.n_nodes, Z.shape[1]
    vol = np.abs(mesh.signed_volumes())
    P = sp.csr_matrix((np.ones(4 * m), (t4.ravel(), np.repeat(np.arange(m), 4))), shape=(n, m))
    cnt = np.asarray(P.sum(axis=1)).ravel()
    used = np.flatnonzero(cnt > 0)
    h = np.ones(n)
    h[used] = np.cbrt((P @ vol)[used] / cnt[used])
    M, R = _patch_normal_equations(mesh, Z, t4.ravel(), np.repeat(np.arange(m), 4), h, t4.ravel(), n)
    rows = 10.0 * cnt
    lam = np.full(n, np.inf)
    lam[used] = np.linalg.eigvalsh(M[used])[:, 0] / rows[used]
    bad = used[lam[used] < DETERMINED]
    if len(bad):
        ring = ((P[bad] @ P.T) @ P).tocoo()                                  # (bad, m) two-ring
        M2, R2 = _patch_normal_equations(mesh, Z, bad[ring.row], ring.col, h, ring.row, len(bad))
        M[bad], R[bad] = M2, R2
        rows[bad] = 10.0 * np.bincount(ring.row, minlength=len(bad))
    M = M[used]
    M[:, 10:, 10:] += ridge * rows[used][:, None, None] * np.eye(10)
    coef = np.linalg.solve(M, R[used])[:, 10:]                              # cubic terms
    D = np.zeros((n, K, 10))
    D[used] = (coef / (h[used] ** 3)[:, None, None]).transpose(0, 2, 1)
    D = D[t4].mean(axis=1)                                                   # (m,K,10)
    return D[:, :, _D3_INDEX - 10] * _D3_FACTOR                              # (m,K,3,3,3)


def cubic_surplus(mesh: Mesh, D3: np.ndarray):
    """Element-local surplus coefficients of the cubic with third derivatives D3 (m,K,3,3,3):
    edges (m,6,K), c = D³[d,d,d]/12 (d from local p to q), faces (m,4,K),
    c_f = 3 Σ q(v) − 12 Σ q(m_e), q(x) = D³[x − x_c]³/6 (straight positions)."""
    X = mesh.points[mesh.corner_tets]
    d = X[:, TET_EDGES[:, 1]] - X[:, TET_EDGES[:, 0]]                      # (m,6,3)
    ce = np.einsum("mkijl,mei,mej,mel->mek", D3, d, d, d, optimize=True) / 12.0
    fv = X[:, TET_FACES]                                                    # (m,4,3,3)
    xc = fv.mean(axis=2)
    mids = 0.5 * (fv + fv[:, :, [1, 2, 0]])                                 # (a,b),(b,c),(c,a)
    q = lambda y: np.einsum("mkijl,mfpi,mfpj,mfpl->mfpk", D3, y, y, y, optimize=True) / 6.0  # noqa: E731
    cf = 3.0 * q(fv - xc[:, :, None]).sum(axis=2) - 12.0 * q(mids - xc[:, :, None]).sum(axis=2)
    return ce, cf


def continuous_surplus(mesh: Mesh, ce: np.ndarray, cf: np.ndarray, constrained: np.ndarray):
    """Element-local surplus coefficients (edges (m,6,K) in each element's own orientation, faces
    (m,4,K)) averaged over the elements that share each edge or face, so that the weight is
    continuous; zero on edges whose mid node, and faces whose six nodes, are ``constrained``."""
    from flexure.mesh import TET_FACES_P2

    t = mesh.tets.astype(np.int64)
    m, _, K = ce.shape
    sign = np.where(t[:, TET_EDGES[:, 0]] < t[:, TET_EDGES[:, 1]], 1.0, -1.0)   # local p is lo?
    uc, inv = np.unique(edge_codes(t).ravel(), return_inverse=True)
    tot = np.zeros((len(uc), K))
    np.add.at(tot, inv, (ce * sign[..., None]).reshape(-1, K))
    glob = tot / np.bincount(inv, minlength=len(uc)).astype(float)[:, None]
    mid = np.empty(len(uc), np.int64)
    mid[inv] = t[:, 4:].ravel()
    glob[constrained[mid]] = 0.0
    ce = glob[inv].reshape(m, 6, K) * sign[..., None]
    fkey = np.sort(t[:, TET_FACES].reshape(-1, 3), axis=1)
    _, finv, fcnt = np.unique(fkey, axis=0, return_inverse=True, return_counts=True)
    finv = finv.ravel()
    ftot = np.zeros((len(fcnt), K))
    np.add.at(ftot, finv, cf.reshape(-1, K))
    fglob = ftot / fcnt[:, None]
    fcon = constrained[t[:, TET_FACES_P2]].all(axis=2).ravel()
    fglob[finv[fcon]] = 0.0
    return ce, fglob[finv].reshape(m, 4, K)


def surplus_coefficients(mesh: Mesh, D3: np.ndarray, constrained: np.ndarray):
    """The continuous cubic surplus of the third derivatives D3 (``cubic_surplus``, averaged)."""
    return continuous_surplus(mesh, *cubic_surplus(mesh, D3), constrained)


def energy_indicators(mesh: Mesh, material, V: np.ndarray, ce: np.ndarray, cf: np.ndarray,
                      chunk: int = 6000) -> np.ndarray:
    """−a(v_c, w ψ_a) at every vertex a, (n, c), for the fields V (n, 3, c) and one weight w given
    by its surplus coefficients ``ce`` (m,6,3), ``cf`` (m,4,3) (``surplus_coefficients``):
    ∫ σ(v):ε(w ψ_a) = ∫ ψ_a σ(v):∇w + (σ(v) ∇ψ_a)·w, degree-5 quadrature, isoparametric map."""
    from flexure import stiffness_assembly
    from flexure.bank_weiser import point_jacobians
    from flexure.fem import tet_shape

    xi, wq = tet_rule_degree5()
    _, dN2 = tet_shape(2, xi)
    Bs, dBs = surplus_basis(xi)
    L = np.column_stack([1.0 - xi.sum(axis=1), xi])                        # ψ_a (q,4)
    dL = np.array([[-1.0, -1.0, -1.0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    lam, mu = material.lame_lambda_Pa, material.shear_modulus_Pa
    m = mesh.n_elements
    c = V.shape[2]
    eta = np.zeros((mesh.n_nodes, c))
    if stiffness_assembly.available():           # each element's terms by a compiled loop (flexure._indicator_kernels)
        from flexure import _indicator_kernels as ik
        from flexure import threads

        part = np.empty((m, 4, c))
        nt = threads.use()
        with threads.dynamic():
            ik.energy_parts(np.ascontiguousarray(mesh.points, float), np.ascontiguousarray(mesh.tets, np.int64),
                            np.ascontiguousarray(V, float), np.ascontiguousarray(np.concatenate([ce, cf], axis=1), float),
                            np.ascontiguousarray(dN2), np.ascontiguousarray(Bs), np.ascontiguousarray(dBs), L, dL,
                            np.ascontiguousarray(wq), float(lam), float(mu), part, 1 if nt == 1 else 8 * nt)
        t4 = mesh.tets[:, :4].ravel()
        for col in range(c):
            eta[:, col] = -np.bincount(t4, weights=part[:, :, col].ravel(), minlength=mesh.n_nodes)
        return eta
    for s in range(0, m, chunk):
        sl = slice(s, min(m, s + chunk))
        t = mesh.tets[sl]
        det, Jinv = point_jacobians(mesh.points[t], dN2)                     # (e,q), (e,q,k,i)
        G2 = np.matmul(dN2[None], Jinv)                                      # (e,q,a,i) ∂N_a/∂x_i
        H = np.einsum("eaic,eqaj->eqcij", V[t], G2, optimize=True)          # ∂v_i/∂x_j
        eps = 0.5 * (H + H.swapaxes(-1, -2))
        sig = 2.0 * mu * eps + lam * np.trace(eps, axis1=-2, axis2=-1)[..., None, None] * np.eye(3)
        coef = np.concatenate([ce[sl], cf[sl]], axis=1)                      # (e,10,3)
        w = np.einsum("qb,ebi->eqi", Bs, coef, optimize=True)                # (e,q,3)
        gw = np.einsum("eqbj,ebi->eqij", np.matmul(dBs[None], Jinv), coef, optimize=True)   # ∂w_i/∂x_j
        gpsi = np.matmul(dL[None, None], Jinv)                               # (e,q,a,j)
        dv = wq[None, :] * det                                               # (e,q)
        s_gw = np.einsum("eqcij,eqij->eqc", sig, gw, optimize=True)
        s_psi_w = np.einsum("eqcij,eqaj,eqi->eqac", sig, gpsi, w, optimize=True)
        part = np.einsum("eq,qa,eqc->eac", dv, L, s_gw, optimize=True) + np.einsum("eq,eqac->eac", dv, s_psi_w)
        for col in range(c):
            eta[:, col] -= np.bincount(t[:, :4].ravel(), weights=part[:, :, col].ravel(), minlength=mesh.n_nodes)
    return eta


def gauge_indicators(mesh: Mesh, gauges, ce: np.ndarray, cf: np.ndarray) -> np.ndarray:
    """J_g(w ψ_a) (n, g): each gauge's read-out, (1/LW)∫ aᵀ ε(w ψ_a) a dA over its grid, of the
    weight w times the vertex hat ψ_a (gauges.quadrature: exact for these degrees on flat faces);
    aᵀ ε(w ψ) a = (aᵀ ∇w a) ψ + (w·a)(a·∇ψ)."""
    from flexure.fem import tet_shape
    from flexure.gauges import quadrature

    dL = np.array([[-1.0, -1.0, -1.0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    out = np.zeros((mesh.n_nodes, len(gauges)))
    for col, g in enumerate(gauges):
        elems, xi, wts = quadrature(g, mesh)
        _, a, _, _ = g.frame()
        _, dN2 = tet_shape(2, xi)                                            # (k,10,3)
        J = np.einsum("kai,kaj->kij", mesh.points[mesh.tets[elems]], dN2)
        Jinv = np.linalg.inv(J)                                              # (k,j,i)
        B, dB = surplus_basis(xi)                                           # one point per row
        coef = np.concatenate([ce[elems], cf[elems]], axis=1)                # (k,10,3)
        w = np.einsum("kb,kbi->ki", B, coef)
        gw = np.einsum("kbm,kmj,kbi->kij", dB, Jinv, coef)                   # ∂w_i/∂x_j
        L = np.column_stack([1.0 - xi.sum(axis=1), xi])
        gpsi = np.einsum("am,kmj->kaj", dL, Jinv)
        val = wts[:, None] * (np.einsum("i,kij,j->k", a, gw, a)[:, None] * L
                              + (w @ a)[:, None] * (gpsi @ a))             # (k,4)
        out[:, col] = np.bincount(mesh.tets[elems][:, :4].ravel(), weights=val.ravel(), minlength=mesh.n_nodes)
    return out


def element_indicators(mesh: Mesh, eta_vertex: np.ndarray) -> np.ndarray:
    """η_K = Σ_{a∈K} |η_a| |K| / |ω_a| (m, c) from vertex indicators (n, c)."""
    vol = np.abs(mesh.signed_volumes())
    t4 = mesh.corner_tets
    patch = np.bincount(t4.ravel(), weights=np.repeat(vol, 4), minlength=mesh.n_nodes)
    share = vol[:, None] / np.maximum(patch[t4], 1e-300)                   # (m,4)
    return np.einsum("ma,mac->mc", share, np.abs(eta_vertex)[t4])


#: how the weight w ≈ u − I_h u is made: "residual" (Bank–Weiser local problems, flexure.bank_weiser)
#: or "recovered" (the cubic fitted to u_h around each vertex: blind to singular fields)
WEIGHT = "residual"


def primal_weight(mesh: Mesh, u: np.ndarray, constrained: np.ndarray, material=None, traction=None,
                  how: str | None = None):
    """Continuous surplus coefficients (ce (m,6,3), cf (m,4,3)) of w ≈ u − I_h u for the P2 field
    u (n,3): from the element residuals and traction jumps (``WEIGHT = "residual"``), or from
    patch-wise cubic fits of u_h (``"recovered"``)."""
    constrained = np.asarray(constrained, bool)
    if (how or WEIGHT) == "residual":
        from flexure.bank_weiser import local_errors

        return continuous_surplus(mesh, *local_errors(mesh, material, u, constrained, traction), constrained)
    return surplus_coefficients(mesh, third_derivatives(mesh, np.asarray(u, float).reshape(-1, 3)), constrained)


def dual_weighted_residuals(mesh: Mesh, material, u: np.ndarray, duals: np.ndarray, gauges,
                            constrained: np.ndarray, weight=None):
    """Vertex indicators (n, 1 + g) of the goals: column 0 the load case's own compliance goal
    (u's work-conjugate, e.g. the hub rotation θ under a unit torque: J = F(u), dual z = u),

        η_a = R(u_h)(w ψ_a) = −a(u_h, w ψ_a),

    (the rigid coupling's load acts where w = 0), columns 1… the gauges (dual z_g (n,3) each),

        η_a = R*(z_g)(w ψ_a) = J_g(w ψ_a) − a(z_g, w ψ_a),

    all weighted with the one recovered primal surplus w ≈ u − I_h u: the primal field is smooth
    at the gauges, where their duals are singular (line loads along the grid's edges). Σ_a η_a
    estimates J(u) − J(u_h). ``weight``: (ce, cf) of w if known (the enriched solve's surplus part,
    flexure.enriched), else ``primal_weight``'s."""
    ce, cf = weight if weight is not None else primal_weight(mesh, u, constrained, material)
    V = np.concatenate([np.asarray(u, float).reshape(-1, 3, 1), duals], axis=2)
    eta = energy_indicators(mesh, material, V, ce, cf)
    eta[:, 1:] += gauge_indicators(mesh, gauges, ce, cf)
    return eta


def moment_traction_indicators(mesh: Mesh, faces: np.ndarray, ref, ce: np.ndarray, cf: np.ndarray) -> np.ndarray:
    """F(w ψ_a) (n,) of a unit moment M_z carried by the statically equivalent linear traction
    t(x) = ω × (x − x_c), ω = J⁻¹ e_z (flexure.bc.wrench_traction), on ``faces`` (k,6): the load
    term of the residual where the loaded faces are free (distributed coupling)."""
    from flexure.bc import face_quadrature, face_set_properties

    _, xc, Jp = face_set_properties(mesh, faces)
    omega = np.linalg.solve(Jp, np.array([0.0, 0.0, 1.0]))
    from flexure.fem import TRI_QUAD

    _, x, nda = face_quadrature(mesh, faces)                                 # (k,q,3) points, n dA·w_q
    dA = np.linalg.norm(nda, axis=2)
    st = TRI_QUAD[0]
    Lface = np.column_stack([1.0 - st.sum(axis=1), st])                     # (q,3) on the face's corners
    bf = mesh.boundary_faces()[:, :3].astype(np.int64)
    owner_all = mesh.boundary_face_owners()[0]
    key = lambda f: np.sort(f, axis=1) @ np.array([1, 1 << 21, 1 << 42], dtype=np.int64)  # noqa: E731
    kb, kf = key(bf), key(np.asarray(faces)[:, :3].astype(np.int64))
    order = np.argsort(kb)
    owner = owner_all[order[np.searchsorted(kb[order], kf)]]
    V = mesh.corner_tets[owner].astype(np.int64)                             # (k,4)
    pos = np.argmax(V[:, :, None] == np.asarray(faces)[:, None, :3], axis=1)  # (k,3) local vertex of a,b,c
    lam = np.zeros((len(faces), len(st), 4))
    for j in range(3):
        lam[np.arange(len(faces)), :, pos[:, j]] = Lface[None, :, j]
    B, _ = surplus_basis(lam[:, :, 1:].reshape(-1, 3))
    coef = np.concatenate([ce[owner], cf[owner]], axis=1)                   # (k,10,3)
    w = np.einsum("kqb,kbi->kqi", B.reshape(len(faces), len(st), 10), coef)
    t = np.cross(omega, x - xc)
    val = (np.einsum("kqi,kqi->kq", t, w) * dA)[:, :, None] * lam           # (k,q,4)
    return np.bincount(V.ravel(), weights=val.sum(axis=1).ravel(), minlength=mesh.n_nodes)
