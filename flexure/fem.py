"""Vectorized stiffness assembly for isotropic linear elasticity on P1/P2 (isoparametric) tetrahedra.

Element stiffness, summed over quadrature points q with weight w_q·det J:
    K_e[a i, b j] = Σ_q w_q detJ_q ( λ ∂_i N_a ∂_j N_b + μ ∂_j N_a ∂_i N_b + μ δ_ij ∇N_a·∇N_b ),
which is ∫ Bᵀ D B dV with σ = λ tr(ε) I + 2μ ε. Global dof of node n, component i: 3n + i.
All elements of a chunk at once (einsum); COO → CSR (int32 indices where they fit), chunked.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from userio.errors import InputError
from flexure.mesh import TET_EDGES, Mesh

# 4-point, degree-2 rule on the reference tetrahedron (volume 1/6), barycentric (a,b,b,b) perms.
_A, _B = 0.5854101966249685, 0.1381966011250105
TET_QUAD = {
    1: (np.array([[0.25, 0.25, 0.25]]), np.array([1.0 / 6.0])),
    2: (np.array([[_B, _B, _B], [_A, _B, _B], [_B, _A, _B], [_B, _B, _A]]), np.full(4, 1.0 / 24.0)),
}
# 6-point, degree-4 Dunavant rule on the reference triangle (area 1/2), points (s, t).
_TA, _TB, _TC, _TD = 0.445948490915965, 0.108103018168070, 0.091576213509771, 0.816847572980459
TRI_QUAD = (
    np.array([[_TA, _TA], [_TA, _TB], [_TB, _TA], [_TC, _TC], [_TC, _TD], [_TD, _TC]]),
    0.5 * np.array([0.223381589678011] * 3 + [0.109951743655322] * 3),
)


def tet_shape(order: int, xi: np.ndarray):
    """Shape functions N (k,nn) and reference gradients dN/dξ (k,nn,3) at ref points ξ (k,3).

    Barycentric L0 = 1−ξ1−ξ2−ξ3, L_i = ξ_i. P1: N_a = L_a. P2 (VTK order): vertices L_a(2L_a−1),
    edges (a,b) 4 L_a L_b.
    """
    xi = np.atleast_2d(np.asarray(xi, dtype=np.float64))
    k = len(xi)
    L = np.column_stack([1.0 - xi.sum(axis=1), xi])                 # (k,4)
    dL = np.array([[-1.0, -1.0, -1.0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])  # dL_a/dξ (4,3)
    if order == 1:
        return L, np.broadcast_to(dL, (k, 4, 3)).copy()
    a, b = TET_EDGES[:, 0], TET_EDGES[:, 1]
    N = np.hstack([L * (2 * L - 1), 4 * L[:, a] * L[:, b]])
    dNv = (4 * L - 1)[:, :, None] * dL[None]                          # (k,4,3)
    dNe = 4 * (L[:, b, None] * dL[None, a] + L[:, a, None] * dL[None, b])  # (k,6,3)
    return N, np.concatenate([dNv, dNe], axis=1)


def tri_shape(order: int, st: np.ndarray):
    """Triangle shape functions N (k,nn) and dN/d(s,t) (k,nn,2); P2 edges (0,1),(1,2),(2,0)."""
    st = np.atleast_2d(np.asarray(st, dtype=np.float64))
    k = len(st)
    L = np.column_stack([1.0 - st.sum(axis=1), st])
    dL = np.array([[-1.0, -1.0], [1, 0], [0, 1]])
    if order == 1:
        return L, np.broadcast_to(dL, (k, 3, 2)).copy()
    a, b = np.array([0, 1, 2]), np.array([1, 2, 0])
    N = np.hstack([L * (2 * L - 1), 4 * L[:, a] * L[:, b]])
    dNv = (4 * L - 1)[:, :, None] * dL[None]
    dNe = 4 * (L[:, b, None] * dL[None, a] + L[:, a, None] * dL[None, b])
    return N, np.concatenate([dNv, dNe], axis=1)


def physical_gradients(X: np.ndarray, dN_ref: np.ndarray, first_element: int = 0):
    """∂N_a/∂x_i (e,q,nn,3) and det J (e,q) from node coords X (e,nn,3) and dN/dξ (q,nn,3).

    J_ik = Σ_a X_ai ∂N_a/∂ξ_k;  ∇_x N = J⁻ᵀ ∇_ξ N. Straight-sided (affine) elements use one J per
    element; curved (isoparametric) P2 elements one per point. InputError on det J ≤ 0 (inverted).
    """
    from flexure import stiffness_assembly

    e, nn = X.shape[:2]
    nq = dN_ref.shape[0]
    if stiffness_assembly.available():                     # compiled: J at every point, one pass
        G, det = stiffness_assembly.gradients(X, dN_ref)
        check_inverted(det, e, first_element)
        return G, det
    affine = nn == 4 or _is_affine(X)
    if affine:
        V = X[:, :4]
        J = np.stack([V[:, 1] - V[:, 0], V[:, 2] - V[:, 0], V[:, 3] - V[:, 0]], axis=2)  # (e,i,k)
        det = np.linalg.det(J)
    else:
        J = np.einsum("eai,qak->eqik", X, dN_ref)
        det = np.linalg.det(J)
    check_inverted(det, e, first_element)
    Jinv = np.linalg.inv(J)
    if affine:
        G = np.matmul(dN_ref.reshape(1, nq * nn, 3), Jinv).reshape(e, nq, nn, 3)
        return G, np.repeat(det[:, None], nq, axis=1)
    return np.einsum("qak,eqki->eqai", dN_ref, Jinv), det


def check_inverted(det: np.ndarray, e: int, first_element: int) -> None:
    """InputError naming the first of ``e`` elements (numbered from ``first_element``) with a det J ≤ 0
    among ``det`` (e, …) (inverted or degenerate)."""
    bad = ~(det > 0)
    if np.any(bad):
        idx = np.flatnonzero(bad.reshape(e, -1).any(axis=1))[0]
        raise InputError(f"mesh: element {int(idx) + first_element} is inverted or degenerate "
                         f"(det J = {float(det.reshape(e, -1)[idx].min()):.3e}); fix the mesh")


def _is_affine(X: np.ndarray, rtol: float = 1e-10) -> bool:
    """True when every P2 mid-edge node sits at its edge midpoint (straight-sided elements)."""
    mid = 0.5 * (X[:, TET_EDGES[:, 0]] + X[:, TET_EDGES[:, 1]])
    h = np.abs(X[:, 1:4] - X[:, :1]).max()
    return bool(np.abs(X[:, 4:10] - mid).max() <= rtol * h)


def _element_P(mesh: Mesh, elements: slice):
    """P_ab = Σ_q w_q detJ_q ∇N_a ∇N_bᵀ, shape (e, nn, nn, 3, 3)."""
    xi, w = TET_QUAD[mesh.order]
    _, dN = tet_shape(mesh.order, xi)
    G, det = physical_gradients(mesh.points[mesh.tets[elements]], dN, first_element=elements.start or 0)
    Gw = G * (w[None, :] * det)[:, :, None, None]
    return np.einsum("eqai,eqbj->eabij", Gw, G, optimize=True)


def _block(P: np.ndarray, lam: float, mu: float, i: int, j: int) -> np.ndarray:
    """Component (i,j) of every 3×3 node block: λ P_ij + μ P_ji + μ δ_ij tr P."""
    v = lam * P[..., i, j] + mu * P[..., j, i]
    if i == j:
        v += mu * (P[..., 0, 0] + P[..., 1, 1] + P[..., 2, 2])
    return v


def element_stiffness(mesh: Mesh, lam_Pa: float, mu_Pa: float, elements=slice(None)) -> np.ndarray:
    """Element matrices (e, 3nn, 3nn), row index 3a + i (local node a, component i)."""
    if not isinstance(elements, slice):
        raise InputError("element_stiffness: elements must be a slice")
    P = _element_P(mesh, elements)
    K = lam_Pa * P + mu_Pa * P.swapaxes(-1, -2)
    tr = P[..., 0, 0] + P[..., 1, 1] + P[..., 2, 2]
    for d in range(3):
        K[..., d, d] += mu_Pa * tr
    e, nn = K.shape[:2]
    return K.transpose(0, 1, 3, 2, 4).reshape(e, 3 * nn, 3 * nn)


def element_dofs(tets: np.ndarray) -> np.ndarray:
    """Global dofs (e, 3nn) of elements, ordered 3a + i → 3·node_a + i."""
    t = tets.astype(np.int64)
    return (3 * t[:, :, None] + np.arange(3)).reshape(len(t), -1)


def block_pattern(mesh: Mesh):
    """Node-pair sparsity: sorted unique codes r·n + c, and the (e·nn·nn,) element-pair → block map."""
    if "block_pattern" not in mesh._cache:
        t = mesh.tets.astype(np.int64)
        n = np.int64(mesh.n_nodes)
        code = (t[:, :, None] * n + t[:, None, :]).ravel()
        uniq, inv = np.unique(code, return_inverse=True)
        mesh._cache["block_pattern"] = (uniq, inv.astype(np.int32 if len(uniq) < 2**31 else np.int64))
    return mesh._cache["block_pattern"]


def stiffness_matrix(mesh: Mesh, material, chunk_elements: int | None = None,
                     fmt: str = "csr") -> sp.spmatrix:
    """Global stiffness K (n_dofs × n_dofs, symmetric), CSR (or BSR 3×3 with ``fmt="bsr"``).

    Node-block assembly: the 9 components of every element's 3×3 node-pair blocks are summed into
    the unique node-pair pattern with bincount; chunks of elements bound temporary memory. With
    numba, CSR is assembled in place by a compiled element loop (flexure.stiffness_assembly; the
    same matrix to round-off); this numpy form is its reference and the path without numba.
    """
    from flexure import stiffness_assembly

    if fmt == "csr" and chunk_elements is None and stiffness_assembly.available():
        xi, w = TET_QUAD[mesh.order]
        return stiffness_assembly.stiffness_csr(mesh, material, tet_shape(mesh.order, xi)[1], w)
    return _stiffness_numpy(mesh, material, chunk_elements, fmt)


def _stiffness_numpy(mesh: Mesh, material, chunk_elements: int | None = None, fmt: str = "csr"):
    """``stiffness_matrix`` by numpy (node-block bincount assembly)."""
    lam, mu = material.lame_lambda_Pa, material.shear_modulus_Pa
    n = mesh.n_nodes
    m = mesh.n_elements
    nn = mesh.tets.shape[1]
    if chunk_elements is None:
        chunk_elements = max(1000, int(80e6 // (nn * nn * 9 * 8)))
    uniq, inv = block_pattern(mesh)
    nb = len(uniq)
    data = np.zeros((3, 3, nb))
    for s in range(0, m, chunk_elements):
        sl = slice(s, min(m, s + chunk_elements))
        P = _element_P(mesh, sl)
        idx = inv[s * nn * nn: sl.stop * nn * nn]
        for i in range(3):
            for j in range(3):
                data[i, j] += np.bincount(idx, weights=_block(P, lam, mu, i, j).ravel(), minlength=nb)
        del P
    rows = uniq // n
    cols = (uniq % n).astype(np.int32 if n < 2**31 - 1 else np.int64)
    indptr = np.zeros(n + 1, dtype=cols.dtype)
    np.cumsum(np.bincount(rows, minlength=n), out=indptr[1:])
    K = sp.bsr_matrix((np.ascontiguousarray(data.transpose(2, 0, 1)), cols, indptr),
                      shape=(3 * n, 3 * n))
    del data                                  # one copy of the values fewer alive while K becomes CSR
    if fmt == "bsr":
        return K
    K = K.tocsr()
    if K.shape[0] < 2**31 and K.nnz < 2**31 and K.indices.dtype != np.int32:
        K.indices = K.indices.astype(np.int32)
        K.indptr = K.indptr.astype(np.int32)
    return K


def rigid_body_modes(points: np.ndarray) -> np.ndarray:
    """The 6 rigid-body modes (3n, 6): translations x, y, z and rotations about x, y, z (ω × x)."""
    n = len(points)
    c = points - points.mean(axis=0)
    B = np.zeros((n, 3, 6))
    B[:, 0, 0] = B[:, 1, 1] = B[:, 2, 2] = 1.0
    x, y, z = c[:, 0], c[:, 1], c[:, 2]
    B[:, 1, 3], B[:, 2, 3] = -z, y          # ω = e_x: (0, −z, y)
    B[:, 0, 4], B[:, 2, 4] = z, -x          # ω = e_y: (z, 0, −x)
    B[:, 0, 5], B[:, 1, 5] = -y, x          # ω = e_z: (−y, x, 0)
    return B.reshape(3 * n, 6)
