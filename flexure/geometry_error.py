"""The geometric error of a goal: the discrete boundary Γ_h (the P2 mesh's curved faces) against the
true surface (the STL's facets, the CAD model), as a signed shape derivative (Hadamard).

Move Γ_h by the normal field V_n (outward positive: V_n = (p(x) − x)·n, p(x) the closest point of
the true surface) to the true boundary. For a goal J(u) = ℓ(u) whose functional lives away from the
moved faces, with dual z (a(v, z) = ℓ(v) for all v), the first-order change is

    δJ ≈ Σ_faces s_f ∫_Γ V_n σ(u):ε(z) dΓ,      s_f = −1 on a traction-free face,
                                                 s_f = +1 on a face held by a Dirichlet condition
                                                        (clamped, or rigidly coupled to the hub)

(free face moved outward: material added, the part stiffer, the compliance θ = ℓ(u) with z = u falls;
a clamped or rigidly driven face moved outward: the same u spread over more material between it
and the rest, the compliance rises. On a Dirichlet face ∇(u − g) = ∂_n(u − g) ⊗ n with g the imposed
rigid motion (ε(g) = 0), so (σ(u)n)·∂_n(z − g_z) = σ(u):ε(z) there too). σ:ε = λ tr ε(u) tr ε(z) +
2μ ε(u):ε(z). A gauge whose footprint lies on a moved face also reads at the moved surface; that
footprint term, ∫_S w V_n ∂_n ε_aa(u), is not included (the footprints of the parts measured here lie
on flat faces that are on the true surface: V_n = 0 there).

δJ estimates J(true domain) − J(Γ_h) at a fixed discretization: the error of the discrete domain,
which no estimate of the discretization error on it (flexure.enriched) can see. Checked against
finite differences (tests/test_geometry_error.py: a box's free face and clamped face moved by known
offsets; the annulus' bore and rim).
"""

from __future__ import annotations

import numpy as np

from flexure.fem import TRI_QUAD, tet_shape
from flexure.mesh import TET_FACES, Mesh


def _face_rule():
    """Per local face f: the tet reference points ξ (4, q, 3) of the triangle rule's points, their
    weights (q,) (reference triangle area ½), and the tangents dξ/ds, dξ/dt (4, 2, 3)."""
    st, w = TRI_QUAD
    xi = np.zeros((4, len(st), 3))
    tang = np.zeros((4, 2, 3))
    corner = np.vstack([np.zeros(3), np.eye(3)])                 # ξ of local vertex 0..3
    for f, (a, b, c) in enumerate(TET_FACES.tolist()):
        xi[f] = corner[a] + st[:, :1] * (corner[b] - corner[a]) + st[:, 1:] * (corner[c] - corner[a])
        tang[f] = [corner[b] - corner[a], corner[c] - corner[a]]
    return xi, w, tang


def face_points(mesh: Mesh, elems: np.ndarray, faces: np.ndarray):
    """Quadrature on the isoparametric P2 faces: → points x (k,q,3), outward unit normals n (k,q,3),
    weights × area element dA (k,q), shape gradients ∂N_a/∂x_i (k,q,10,3)."""
    xi_f, w, tang = _face_rule()
    q = xi_f.shape[1]
    N, dN = tet_shape(2, xi_f.reshape(-1, 3))
    N, dN = N.reshape(4, q, 10), dN.reshape(4, q, 10, 3)
    X = mesh.points[mesh.tets[elems]]                                        # (k,10,3)
    Nf, dNf = N[faces], dN[faces]                                            # (k,q,10), (k,q,10,3)
    x = np.einsum("kqa,kai->kqi", Nf, X)
    J = np.einsum("kai,kqaj->kqij", X, dNf)                                  # dx_i/dξ_j
    G = np.einsum("kqaj,kqji->kqai", dNf, np.linalg.inv(J))
    t = np.einsum("kqij,ksj->kqsi", J, tang[faces])                         # (k,q,2,3)
    nA = np.cross(t[:, :, 0], t[:, :, 1])
    opposite = mesh.points[mesh.tets[elems, faces]]                           # the vertex the face is opposite
    s = np.sign(np.einsum("kqi,kqi->kq", nA, x - opposite[:, None, :]))
    nA *= s[..., None]
    dA = np.linalg.norm(nA, axis=2)
    return x, nA / dA[..., None], w[None, :] * dA, G


def normal_offset(projector, x: np.ndarray, n: np.ndarray) -> np.ndarray:
    """V_n = (p(x) − x)·n of points x (k, q, 3) with outward normals n: the STL's (``projector``, a
    flexure.project.StlProjector) signed distance along the normal, outward positive. The points lie
    on the mesh's own boundary, within a sample gap of the STL: its uncertified projection suffices."""
    p = projector.project(x.reshape(-1, 3), certified=False)
    return np.einsum("...i,...i->...", p.reshape(x.shape) - x, n)


def energy_density(G: np.ndarray, U: np.ndarray, Z: np.ndarray, lam: float, mu: float) -> np.ndarray:
    """σ(u):ε(z) (k,q,c) at the points of ``face_points`` from element nodal fields U (k,10,3) and Z
    (k,10,3,c): λ tr ε(u) tr ε(z) + 2μ ε(u):ε(z)."""
    gu = np.einsum("kqai,kaj->kqji", G, U)                                   # ∂u_j/∂x_i → (k,q,j,i)
    gz = np.einsum("kqai,kajc->kqjic", G, Z)
    eu = 0.5 * (gu + np.swapaxes(gu, 2, 3))
    ez = 0.5 * (gz + np.swapaxes(gz, 2, 3))
    tr_u = np.trace(eu, axis1=2, axis2=3)
    tr_z = np.einsum("kqiic->kqc", ez)
    return lam * tr_u[..., None] * tr_z + 2.0 * mu * np.einsum("kqij,kqijc->kqc", eu, ez)


def shape_derivative(mesh: Mesh, material, u: np.ndarray, duals: np.ndarray, constrained: np.ndarray,
                     V_n=None, projector=None, elems=None, faces=None, chunk: int = 20000,
                     per_face: bool = False):
    """δJ_c ≈ Σ_f s_f ∫_Γ V_n σ(u):ε(z_c) dΓ of each goal c (module docstring) → (c,). ``u`` (n,3) the
    primal field, ``duals`` (n,3,c); ``constrained`` (n,) bool: a face whose six nodes are all
    constrained is a Dirichlet face (s = +1), any other a free one (s = −1). V_n: a callable
    (x (k,q,3), n) → (k,q) or None for the ``projector``'s ``normal_offset``; the boundary faces
    ``elems``/``faces`` (default all). ``per_face``: → (δJ (c,), each face's term (k, c), |V_n| (k, q))."""
    from flexure.mesh import TET_FACES_P2

    if elems is None:
        elems, faces = mesh.boundary_face_owners()
    lam, mu = material.lame_lambda_Pa, material.shear_modulus_Pa
    duals = duals.reshape(len(u), 3, -1)
    out = np.zeros(duals.shape[2])
    terms, offs = [], []
    for s in range(0, len(elems), chunk):
        e, f = elems[s:s + chunk], faces[s:s + chunk]
        x, n, wdA, G = face_points(mesh, e, f)
        v = V_n(x, n) if V_n is not None else normal_offset(projector, x, n)
        t = mesh.tets[e].astype(np.int64)
        dens = energy_density(G, u[t], duals[t], lam, mu)                  # (k,q,c)
        dirichlet = constrained[t[np.arange(len(e))[:, None], TET_FACES_P2[f]]].all(axis=1)
        sign = np.where(dirichlet, 1.0, -1.0)
        term = np.einsum("k,kq,kqc->kc", sign, wdA * v, dens)
        out += term.sum(axis=0)
        if per_face:
            terms.append(term)
            offs.append(np.abs(v))
    if per_face:
        return out, np.concatenate(terms), np.concatenate(offs)
    return out


def _stats(a: np.ndarray) -> dict:
    """max, 99th percentile and median of |V_n| (m)."""
    a = np.ravel(a)
    return {"max": float(a.max(initial=0.0)), "p99": float(np.percentile(a, 99)) if a.size else 0.0,
            "median": float(np.median(a)) if a.size else 0.0}


def goal_geometry_errors(mesh: Mesh, projector, material, U: np.ndarray, constrained: np.ndarray,
                         arm_sign: np.ndarray):
    """The geometric error of one level's goals (flexure.goals.GoalSolution: U (n,3,1+g) the unit-torque
    field, then the gauges' duals; the hub rotation θ is the compliance, its own dual):
    → ({"theta", "gauges" (g,), "eps_ref": the bridge's Σ s_i δε_i / 4, "offsets": |V_n| at the face points (m)},
    the boundary faces' elements (k,), each face's term (k, 1 + g), for the marking)."""
    elems, faces = mesh.boundary_face_owners()
    u = U[:, :, 0]
    d, terms, off = shape_derivative(mesh, material, u, U, constrained, projector=projector, elems=elems,
                                     faces=faces, per_face=True)
    rec = {"theta": float(d[0]), "gauges": d[1:].tolist(), "eps_ref": float(np.asarray(arm_sign) @ d[1:] / 4.0),
           "offsets": {"quad_points_m": _stats(off)}}
    return rec, elems, terms
