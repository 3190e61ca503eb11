"""Post-processing, the one evaluator: strains, stresses, von Mises; point location and strain at
arbitrary points (the gauges' read-out goes through ``strain_at``).

Displacement gradient H_ij = Σ_a u_ai ∂N_a/∂x_j; small strain ε = (H + Hᵀ)/2 (tensor, not
engineering shear); stress σ = λ tr(ε) I + 2μ ε; von Mises σ_vm = √(3/2 s:s), s = σ − tr(σ)/3 I.
Strain along a unit direction d (a gauge axis): ε_d = dᵀ ε d.
"""

from __future__ import annotations

import numpy as np

from userio.errors import InputError
from flexure.fem import TET_QUAD, physical_gradients, tet_shape
from flexure.mesh import Mesh

#: reference coordinates ξ of the 10 local nodes (vertices then VTK edge midpoints).
_REF_VERTS = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
REF_NODES = np.vstack([_REF_VERTS, 0.5 * (_REF_VERTS[[0, 1, 0, 0, 1, 2]] + _REF_VERTS[[1, 2, 2, 3, 3, 3]])])


def _as_u(mesh: Mesh, u) -> np.ndarray:
    """Displacements as (n,3), or (n,3,cases) for several load cases at once."""
    u = np.asarray(u, dtype=np.float64)
    if u.shape == (mesh.n_dofs,):
        u = u.reshape(-1, 3)
    if u.shape[:2] != (mesh.n_nodes, 3) or u.ndim not in (2, 3):
        raise InputError(f"post: displacement must have shape ({mesh.n_nodes}, 3) or "
                         f"({mesh.n_nodes}, 3, cases), got {u.shape}")
    return u


def gradient_at(mesh: Mesh, u, elements: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """Displacement gradients (k,3,3) at reference points ξ (k,3) of ``elements`` (k,);
    (k,cases,3,3) for u of shape (n,3,cases)."""
    u = _as_u(mesh, u)
    elements = np.asarray(elements, dtype=np.int64)
    xi = np.asarray(xi, dtype=np.float64).reshape(-1, 3)
    _, dN = tet_shape(mesh.order, xi)                        # (k,nn,3) — one point per element
    X = mesh.points[mesh.tets[elements]]                     # (k,nn,3)
    J = np.einsum("kai,kaj->kij", X, dN)
    G = np.einsum("kaj,kji->kai", dN, np.linalg.inv(J))      # ∂N_a/∂x_i
    ue = u[mesh.tets[elements]]
    if ue.ndim == 3:
        return np.einsum("kac,kaj->kcj", ue, G)
    return np.einsum("kacl,kaj->klcj", ue, G)


def strain_from_gradient(H: np.ndarray) -> np.ndarray:
    """ε = (H + Hᵀ)/2."""
    return 0.5 * (H + np.swapaxes(H, -1, -2))


def stress_from_strain(strain: np.ndarray, material) -> np.ndarray:
    """σ = λ tr(ε) I + 2μ ε (Pa)."""
    tr = np.trace(strain, axis1=-2, axis2=-1)
    return material.lame_lambda_Pa * tr[..., None, None] * np.eye(3) + 2 * material.shear_modulus_Pa * strain


def von_mises(stress: np.ndarray) -> np.ndarray:
    """σ_vm = √(3/2 s:s), s the deviatoric stress (Pa)."""
    s = stress - np.trace(stress, axis1=-2, axis2=-1)[..., None, None] / 3.0 * np.eye(3)
    return np.sqrt(1.5 * np.einsum("...ij,...ij->...", s, s))


def max_shear_strain(strain: np.ndarray) -> np.ndarray:
    """½ (ε_max − ε_min) of symmetric 3 × 3 tensors (..., 3, 3), in closed form (Smith 1961): with
    q = tr ε / 3, d = ε − q I, p = √(d:d / 6) and φ = ⅓ arccos(det(d / p) / 2), the principal values
    are q + 2 p cos(φ + 2πk/3), so ½ (ε_max − ε_min) = √3 p sin(φ + π/3); 0 where p = 0."""
    e = np.asarray(strain, dtype=np.float64)
    q = np.trace(e, axis1=-2, axis2=-1) / 3.0
    d0, d1, d2 = e[..., 0, 0] - q, e[..., 1, 1] - q, e[..., 2, 2] - q
    a, b, c = e[..., 0, 1], e[..., 0, 2], e[..., 1, 2]
    p = np.sqrt((d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * (a * a + b * b + c * c)) / 6.0)
    det = d0 * d1 * d2 + 2.0 * a * b * c - d0 * c * c - d1 * b * b - d2 * a * a
    safe = np.where(p > 0, p, 1.0)
    phi = np.arccos(np.clip(det / (2.0 * safe ** 3), -1.0, 1.0)) / 3.0
    return np.where(p > 0, np.sqrt(3.0) * p * np.sin(phi + np.pi / 3.0), 0.0)


def stress_measures(strain: np.ndarray, material) -> tuple[np.ndarray, np.ndarray]:
    """(von Mises stress (Pa), max shear strain) of strain tensors (..., 3, 3): ``von_mises`` of
    ``stress_from_strain`` and ``max_shear_strain``, in one compiled pass where numba runs (σ's
    deviator is 2μ times ε's: σ_vm = 2μ √(3/2 d:d)); without the (..., 3, 3) stress temporaries
    (six_spoke_thick at --rtol 0.01: 1.7 s of numpy on its last mesh, 0.3 s on its earlier levels' safety
    factors)."""
    from flexure import stiffness_assembly

    e = np.asarray(strain, dtype=np.float64)
    if not stiffness_assembly.available():
        return von_mises(stress_from_strain(e, material)), max_shear_strain(e)
    from flexure import _strain_kernels, threads

    flat = np.ascontiguousarray(e.reshape(-1, 3, 3))
    vm, gmax = np.empty(len(flat)), np.empty(len(flat))
    with threads.dynamic():
        _strain_kernels.stress_measures(flat, float(material.shear_modulus_Pa), vm, gmax, stiffness_assembly.chunks())
    return vm.reshape(e.shape[:-2]), gmax.reshape(e.shape[:-2])


def directional_strain(strain: np.ndarray, direction) -> np.ndarray:
    """ε_d = dᵀ ε d for unit vectors d ((3,) or (k,3))."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    return np.einsum("...i,...ij,...j->...", d, strain, d)


def element_strains(mesh: Mesh, u, at: str = "quadrature") -> np.ndarray:
    """Strains at quadrature points (m,q,3,3) or element centroids (m,3,3) (``at="centroid"``)."""
    u = _as_u(mesh, u)
    xi = TET_QUAD[mesh.order][0] if at == "quadrature" else np.array([[0.25, 0.25, 0.25]])
    _, dN = tet_shape(mesh.order, xi)
    G, _ = physical_gradients(mesh.points[mesh.tets], dN)
    H = np.einsum("eac,eqaj->eqcj", u[mesh.tets], G)
    eps = strain_from_gradient(H)
    return eps[:, 0] if at == "centroid" else eps


def element_stresses(mesh: Mesh, u, material, at: str = "quadrature") -> np.ndarray:
    """Stresses (Pa) at quadrature points or centroids."""
    return stress_from_strain(element_strains(mesh, u, at), material)


def element_nodal_strains(mesh: Mesh, u, chunk: int = 20000) -> np.ndarray:
    """ε at every element's own nodes (m,nn,3,3): discontinuous across elements (peak stresses);
    in one compiled pass where numba runs (flexure._strain_kernels)."""
    u = _as_u(mesh, u)
    nn = mesh.tets.shape[1]
    _, dN = tet_shape(mesh.order, REF_NODES[:nn])
    out = np.empty((mesh.n_elements, nn, 3, 3))
    from flexure import stiffness_assembly

    if stiffness_assembly.available():
        from flexure import _strain_kernels, fem, threads

        det = np.empty(mesh.n_elements)
        with threads.dynamic():
            _strain_kernels.nodal_strains(mesh.points, np.ascontiguousarray(mesh.tets, np.int64),
                                          np.ascontiguousarray(u), np.ascontiguousarray(dN), out, det,
                                          stiffness_assembly.chunks())
        fem.check_inverted(det, mesh.n_elements, 0)
        return out
    for s in range(0, mesh.n_elements, chunk):
        t = mesh.tets[s:s + chunk]
        G, _ = physical_gradients(mesh.points[t], dN)
        out[s:s + chunk] = strain_from_gradient(np.einsum("eac,eqaj->eqcj", u[t], G))
    return out


def nodal_average(mesh: Mesh, values: np.ndarray) -> np.ndarray:
    """Plain mean over the elements sharing each node of element-nodal scalars (m,nn) → (n,)."""
    idx = mesh.tets.ravel()
    tot = np.bincount(idx, weights=np.asarray(values, float).ravel(), minlength=mesh.n_nodes)
    return tot / np.maximum(np.bincount(idx, minlength=mesh.n_nodes), 1)


def nodal_strains(mesh: Mesh, u) -> np.ndarray:
    """Nodal strains (n,3,3): each element's strain evaluated at its own nodes, volume-weighted mean."""
    nn = mesh.tets.shape[1]
    eps = element_nodal_strains(mesh, u)                                        # (m,nn,3,3)
    w = np.broadcast_to(np.abs(mesh.signed_volumes())[:, None], (mesh.n_elements, nn))
    idx = mesh.tets.ravel()
    out = np.zeros((mesh.n_nodes, 9))
    wsum = np.bincount(idx, weights=w.ravel(), minlength=mesh.n_nodes)
    flat = eps.reshape(-1, 9) * w.reshape(-1, 1)
    for k in range(9):
        out[:, k] = np.bincount(idx, weights=flat[:, k], minlength=mesh.n_nodes)
    out /= np.maximum(wsum, 1e-300)[:, None]
    return out.reshape(-1, 3, 3)


def nodal_stresses(mesh: Mesh, u, material) -> np.ndarray:
    """Nodal stresses (n,3,3) from averaged nodal strains (Pa)."""
    return stress_from_strain(nodal_strains(mesh, u), material)


def locate(mesh: Mesh, points, tol: float = 0.05, n_candidates: int = 24):
    """Containing element (k,) and reference coordinates ξ (k,3) of each point.

    Candidates: elements with the nearest centroids (KD-tree); the one maximising the smallest
    barycentric coordinate wins. For curved (isoparametric) P2 elements ξ is refined by Newton on
    x(ξ) = Σ N_a(ξ) X_a. A point up to ``tol`` (in barycentric units, i.e. a fraction of the
    element's size) outside its nearest element is evaluated there by extrapolation — a surface
    gauge on a faceted (P1) model of a curved face; farther out is an InputError.
    """
    from scipy.spatial import cKDTree

    pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"locate: points must have shape (k, 3), got {pts.shape}")
    V = mesh.points[mesh.corner_tets]                          # (m,4,3)
    if "kdtree" not in mesh._cache:
        mesh._cache["kdtree"] = cKDTree(V.mean(axis=1))
        mesh._cache["Tinv"] = np.linalg.inv(np.transpose(V[:, 1:] - V[:, :1], (0, 2, 1)))
    tree, Tinv = mesh._cache["kdtree"], mesh._cache["Tinv"]
    kc = min(n_candidates, mesh.n_elements)
    _, cand = tree.query(pts, k=kc)
    cand = cand.reshape(len(pts), kc)
    lam = np.einsum("kcij,kcj->kci", Tinv[cand], pts[:, None, :] - V[cand, 0])   # (k,c,3) = ξ
    minbary = np.minimum(lam.min(axis=2), 1.0 - lam.sum(axis=2))
    best = np.argmax(minbary, axis=1)
    rows = np.arange(len(pts))
    elem = cand[rows, best]
    xi = lam[rows, best]
    score = minbary[rows, best]
    miss = np.flatnonzero(score < -1e-9)
    for i in miss:          # rare fallback: brute force over all elements, vectorized
        l_all = np.einsum("mij,mj->mi", Tinv, pts[i] - V[:, 0])
        mb = np.minimum(l_all.min(axis=1), 1.0 - l_all.sum(axis=1))
        j = int(np.argmax(mb))
        if mb[j] > score[i]:
            elem[i], xi[i], score[i] = j, l_all[j], mb[j]
    if mesh.order == 2:
        xi = _newton_xi(mesh, elem, xi, pts)
        score = np.minimum(xi.min(axis=1), 1.0 - xi.sum(axis=1))
    bad = np.flatnonzero(score < -tol)
    if len(bad):
        raise InputError(f"locate: point {int(bad[0])} {pts[bad[0]].tolist()} lies outside the mesh")
    return elem, xi


def _newton_xi(mesh: Mesh, elem, xi, pts, iters: int = 4):
    X = mesh.points[mesh.tets[elem]]
    for _ in range(iters):
        N, dN = tet_shape(2, xi)
        r = np.einsum("ka,kai->ki", N, X) - pts
        J = np.einsum("kai,kaj->kij", X, dN)
        xi = xi - np.linalg.solve(J, r[..., None])[..., 0]
    return xi


def strain_at(mesh: Mesh, u, points) -> np.ndarray:
    """Strain tensors (k,3,3) at arbitrary points inside (or on the surface of) the mesh;
    (k,cases,3,3) for u of shape (n,3,cases). The one strain evaluator of the project: gauges
    (flexure.gauges.read), reports and benchmarks use it; tests/test_fem_skfem.py checks it."""
    elem, xi = locate(mesh, points)
    return strain_from_gradient(gradient_at(mesh, u, elem, xi))


def displacement_at(mesh: Mesh, u, points) -> np.ndarray:
    """Interpolated displacements (k,3) at arbitrary points."""
    u = _as_u(mesh, u)
    elem, xi = locate(mesh, points)
    N, _ = tet_shape(mesh.order, xi)
    return np.einsum("ka,kai->ki", N, u[mesh.tets[elem]])
