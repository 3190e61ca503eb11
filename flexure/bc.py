"""Boundary conditions: fixed dofs, nodal forces, surface tractions/pressure, rigid couplings.

Rigid coupling of a node/face set to a reference point x_ref carrying a wrench (F, M about x_ref):
* ``kind="kinematic"`` (default): a true multipoint constraint u_i = U + Θ × (x_i − x_ref), imposed
  by elimination (u = T q, reduced K_q = Tᵀ K T; no penalty). The set moves rigidly (a stiff shaft
  or clamp), and the reference rotation Θ gives the stiffness directly (e.g. k = T / Θ_z).
* ``kind="distributed"``: the wrench becomes the linear traction field statically equivalent to it,
  t(x) = F/A + (J⁻¹ M_c) × (x − x_c),  J = ∫(|r|² I − r rᵀ) dA,  M_c = M − (x_c − x_ref) × F
  (so ∫ t dA = F and ∫ r × t dA = M_c exactly); the faces stay free to deform (a compliant hub).
Fixed dofs are imposed symmetrically (rows/columns eliminated, scaled unit diagonal).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from userio.errors import InputError
from flexure.fem import TRI_QUAD, rigid_body_modes, tri_shape
from flexure.mesh import Mesh


#: A = Tᵀ K T by flexure.reduce's compiled row loop (False: scipy's products, the reference)
REDUCE_COMPILED = True


def _row_entries(A, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions in A.data/A.indices of the entries of ``rows`` of CSR A, and their row."""
    lo, hi = A.indptr[rows].astype(np.int64), A.indptr[rows + 1].astype(np.int64)
    n = hi - lo
    start = np.repeat(lo - np.concatenate([[0], np.cumsum(n)[:-1]]), n)
    return start + np.arange(int(n.sum())), np.repeat(rows, n)


def _zero_fixed(A, fixed: np.ndarray, isfix: np.ndarray, scale: float) -> bool:
    """Rows and columns ``fixed`` of the structurally symmetric CSR A zeroed, their diagonal
    ``scale``, visiting only the rows that hold them (the fixed rows and their columns' rows);
    False (A untouched) if a fixed row has no diagonal entry."""
    p, r = _row_entries(A, fixed)
    if np.count_nonzero(A.indices[p] == r) != len(fixed):
        return False
    rows = np.unique(np.concatenate([fixed, A.indices[p]]))
    p, r = _row_entries(A, rows)
    c = A.indices[p]
    diag = (r == c) & isfix[r]
    A.data[p[(isfix[r] | isfix[c]) & ~diag]] = 0.0
    A.data[p[diag]] = scale
    return True


def _faces_checked(mesh: Mesh, faces, what: str) -> np.ndarray:
    faces = np.asarray(faces, dtype=np.int64)
    nf = 3 if mesh.order == 1 else 6
    if faces.ndim != 2 or faces.shape[1] != nf:
        raise InputError(f"{what}: faces must have shape (k, {nf}) for an order-{mesh.order} mesh, "
                         f"got {faces.shape}")
    if len(faces) == 0:
        raise InputError(f"{what}: the face set is empty")
    if faces.min() < 0 or faces.max() >= mesh.n_nodes:
        raise InputError(f"{what}: face node index out of range [0, {mesh.n_nodes})")
    return faces


def _nodes_checked(mesh: Mesh, nodes, what: str) -> np.ndarray:
    nodes = np.unique(np.asarray(nodes, dtype=np.int64).ravel())
    if len(nodes) == 0:
        raise InputError(f"{what}: the node set is empty")
    if nodes[0] < 0 or nodes[-1] >= mesh.n_nodes:
        raise InputError(f"{what}: node index out of range [0, {mesh.n_nodes})")
    return nodes


def face_quadrature(mesh: Mesh, faces: np.ndarray):
    """Surface quadrature on faces: N (q,nf), points x (k,q,3), area vectors n dA (k,q,3)·w_q.

    x(s,t) = Σ_a N_a X_a;  dA·n = (∂x/∂s × ∂x/∂t) ds dt (outward for outward-oriented faces).
    """
    st, w = TRI_QUAD
    N, dN = tri_shape(mesh.order, st)
    X = mesh.points[faces]                                 # (k,nf,3)
    x = np.einsum("qa,kai->kqi", N, X)
    ts = np.einsum("qa,kai->kqi", dN[:, :, 0], X)
    tt = np.einsum("qa,kai->kqi", dN[:, :, 1], X)
    nda = np.cross(ts, tt) * w[None, :, None]
    return N, x, nda


def traction_load(mesh: Mesh, faces, traction_Pa) -> np.ndarray:
    """Consistent nodal forces f_a = ∫ N_a t(x) dA (n,3) for ``traction_Pa`` (3,) or callable x→(…,3)."""
    faces = _faces_checked(mesh, faces, "traction")
    N, x, nda = face_quadrature(mesh, faces)
    dA = np.linalg.norm(nda, axis=2)                         # (k,q)
    t = traction_Pa(x) if callable(traction_Pa) else np.broadcast_to(
        np.asarray(traction_Pa, dtype=np.float64), x.shape)
    t = np.asarray(t, dtype=np.float64)
    if t.shape != x.shape:
        raise InputError(f"traction: expected traction of shape {x.shape}, got {t.shape}")
    fa = np.einsum("qa,kq,kqi->kai", N, dA, t)
    return _scatter(mesh.n_nodes, faces, fa)


def pressure_load(mesh: Mesh, faces, pressure_Pa: float) -> np.ndarray:
    """Nodal forces of a pressure p on outward faces: f_a = −p ∫ N_a n dA (n,3)."""
    faces = _faces_checked(mesh, faces, "pressure")
    N, _, nda = face_quadrature(mesh, faces)
    fa = -float(pressure_Pa) * np.einsum("qa,kqi->kai", N, nda)
    return _scatter(mesh.n_nodes, faces, fa)


def _scatter(n_nodes: int, conn: np.ndarray, fa: np.ndarray) -> np.ndarray:
    f = np.zeros((n_nodes, 3))
    for i in range(3):
        f[:, i] = np.bincount(conn.ravel(), weights=fa[..., i].ravel(), minlength=n_nodes)
    return f


def face_set_properties(mesh: Mesh, faces):
    """Area A, centroid x_c and polar tensor J = ∫(|r|²I − r rᵀ) dA (r = x − x_c) of a face set."""
    faces = _faces_checked(mesh, faces, "coupling")
    _, x, nda = face_quadrature(mesh, faces)
    dA = np.linalg.norm(nda, axis=2)
    A = dA.sum()
    xc = np.einsum("kq,kqi->i", dA, x) / A
    r = x - xc
    J = np.einsum("kq,kq->", dA, np.einsum("kqi,kqi->kq", r, r)) * np.eye(3) - np.einsum(
        "kq,kqi,kqj->ij", dA, r, r)
    return A, xc, J


def wrench_traction(mesh: Mesh, faces, ref_point_m, force_N=(0, 0, 0), moment_Nm=(0, 0, 0)) -> np.ndarray:
    """Nodal forces (n,3) of the linear traction statically equivalent to (F, M about x_ref):
    t(x) = F/A + (J⁻¹ M_c) × (x − x_c), M_c = M − (x_c − x_ref) × F (see the module doc)."""
    F = np.asarray(force_N, dtype=np.float64).reshape(3)
    M = np.asarray(moment_Nm, dtype=np.float64).reshape(3)
    A, xc, J = face_set_properties(mesh, faces)
    if np.linalg.cond(J) > 1e12:
        raise InputError("couple_rigid: the face set has no rotational extent (J singular)")
    omega = np.linalg.solve(J, M - np.cross(xc - np.asarray(ref_point_m, dtype=np.float64).reshape(3), F))
    return traction_load(mesh, faces, lambda x: F / A + np.cross(omega, x - xc))


def mean_rotation(mesh: Mesh, faces, u: np.ndarray) -> np.ndarray:
    """Θ = J⁻¹ ∫ (x − x_c) × u dA: the rotation work-conjugate to a ``wrench_traction`` moment
    (M·Θ is the work of the traction field on u)."""
    faces = _faces_checked(mesh, faces, "mean_rotation")
    N, x, nda = face_quadrature(mesh, faces)
    dA = np.linalg.norm(nda, axis=2)
    _, xc, J = face_set_properties(mesh, faces)
    uq = np.einsum("qa,kai->kqi", N, np.asarray(u)[faces])
    return np.linalg.solve(J, np.einsum("kq,kqi->i", dA, np.cross(x - xc, uq)))


def _skew(d: np.ndarray) -> np.ndarray:
    """[d]× such that [d]× v = d × v, for d (k,3) → (k,3,3)."""
    S = np.zeros(d.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -d[..., 2], d[..., 1]
    S[..., 1, 0], S[..., 1, 2] = d[..., 2], -d[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -d[..., 1], d[..., 0]
    return S


@dataclass
class Coupling:
    nodes: np.ndarray
    ref_point_m: np.ndarray
    force_N: np.ndarray
    moment_Nm: np.ndarray
    kind: str


@dataclass
class LinearSystem:
    """Reduced system A q = b with u = T q (+ fixed values); ``B`` rigid modes in q-space."""

    A: sp.csr_matrix
    b: np.ndarray
    T: sp.csr_matrix | None
    fixed_q: np.ndarray
    B: np.ndarray
    n_nodes: int
    ref_slices: list
    coarse: sp.csr_matrix | None = None     # P2 → P1-vertex interpolation in q-space (p-multigrid)
    B_coarse: np.ndarray | None = None


@dataclass
class Problem:
    """Linear-elastic boundary-value problem on ``mesh`` with ``material``."""

    mesh: Mesh
    material: object
    fixed: np.ndarray = field(init=False)        # (n,3) bool
    fixed_value_m: np.ndarray = field(init=False)
    force_N: np.ndarray = field(init=False)      # (n,3) nodal loads
    couplings: list = field(default_factory=list, init=False)

    def __post_init__(self):
        n = self.mesh.n_nodes
        self.fixed = np.zeros((n, 3), dtype=bool)
        self.fixed_value_m = np.zeros((n, 3))
        self.force_N = np.zeros((n, 3))

    # -- Dirichlet ---------------------------------------------------------------------------
    def fix(self, nodes, components=(0, 1, 2), value_m=0.0) -> "Problem":
        """Prescribe displacement ``value_m`` (scalar, (3,) or (k,3)) on ``components`` of nodes."""
        nodes = _nodes_checked(self.mesh, nodes, "fix")
        comps = np.atleast_1d(np.asarray(components, dtype=np.int64))
        if np.any((comps < 0) | (comps > 2)):
            raise InputError(f"fix: components must be in 0..2, got {components}")
        val = np.broadcast_to(np.asarray(value_m, dtype=np.float64), (len(nodes), 3)) \
            if np.ndim(value_m) < 2 else np.asarray(value_m, dtype=np.float64)
        if val.shape != (len(nodes), 3):
            raise InputError(f"fix: value_m must be scalar, (3,) or ({len(nodes)},3)")
        self.fixed[np.ix_(nodes, comps)] = True
        self.fixed_value_m[np.ix_(nodes, comps)] = val[:, comps]
        return self

    def fix_faces(self, faces, components=(0, 1, 2), value_m=0.0) -> "Problem":
        """Fix every node of a face set (e.g. bolt-hole or rim faces)."""
        return self.fix(np.unique(np.asarray(faces)), components, value_m)

    # -- loads -----------------------------------------------------------------------------
    def add_nodal_force(self, nodes, force_N) -> "Problem":
        """Point forces (3,) per node or (k,3)."""
        nodes = np.asarray(nodes, dtype=np.int64).ravel()
        _nodes_checked(self.mesh, nodes, "nodal force")
        np.add.at(self.force_N, nodes, np.broadcast_to(np.asarray(force_N, float), (len(nodes), 3)))
        return self

    def add_traction(self, faces, traction_Pa) -> "Problem":
        """Surface traction (Pa): constant (3,) or callable x (…,3) → (…,3); consistent loads."""
        self.force_N += traction_load(self.mesh, faces, traction_Pa)
        return self

    def add_pressure(self, faces, pressure_Pa: float) -> "Problem":
        """Pressure (Pa, positive pushes into the body) on outward-oriented boundary faces."""
        self.force_N += pressure_load(self.mesh, faces, pressure_Pa)
        return self

    def couple_rigid(self, nodes_or_faces, ref_point_m, force_N=(0, 0, 0), moment_Nm=(0, 0, 0),
                     kind: str = "kinematic") -> int:
        """Couple a node set (1-D) or face set (2-D) to ``ref_point_m`` loaded by (F, M about it).

        Returns the coupling index; the solution reports its (U, Θ). See the module doc.
        """
        F = np.asarray(force_N, dtype=np.float64).reshape(3)
        M = np.asarray(moment_Nm, dtype=np.float64).reshape(3)
        xr = np.asarray(ref_point_m, dtype=np.float64).reshape(3)
        arr = np.asarray(nodes_or_faces)
        if kind == "distributed":
            if arr.ndim != 2:
                raise InputError("couple_rigid: kind='distributed' needs a face set (k, 3|6)")
            self.force_N += wrench_traction(self.mesh, arr, xr, F, M)
            self.couplings.append(Coupling(np.unique(arr), xr, F, M, kind))
        elif kind == "kinematic":
            nodes = _nodes_checked(self.mesh, arr, "couple_rigid")
            for c in self.couplings:
                if c.kind == "kinematic" and np.intersect1d(c.nodes, nodes).size:
                    raise InputError("couple_rigid: a node belongs to two kinematic couplings")
            self.couplings.append(Coupling(nodes, xr, F, M, kind))
        else:
            raise InputError(f"couple_rigid: kind must be 'kinematic' or 'distributed', got {kind!r}")
        return len(self.couplings) - 1

    # -- assembly of the constrained system --------------------------------------------------
    def load_vector(self) -> np.ndarray:
        """Nodal loads flattened to dofs (3n,)."""
        return self.force_N.ravel().copy()

    def reduced_system(self, K: sp.spmatrix) -> LinearSystem:
        """A q = b: kinematic couplings eliminated (u = T q), fixed dofs imposed symmetrically."""
        mesh = self.mesh
        n = mesh.n_nodes
        kin = [c for c in self.couplings if c.kind == "kinematic"]
        coupled = np.zeros(n, dtype=bool)
        for c in kin:
            coupled[c.nodes] = True
        if np.any(self.fixed[coupled]):
            raise InputError("boundary conditions: a node is both fixed and rigidly coupled")
        B_full = rigid_body_modes(mesh.points)
        centre = mesh.points.mean(axis=0)
        f = self.load_vector()
        if not kin:
            T = None
            A = K.tocsr(copy=True)                                       # the caller's K kept
            b = f
            fixed_q = np.flatnonzero(self.fixed.ravel())
            g = self.fixed_value_m.ravel()[fixed_q]
            B = B_full
            ref_slices = []
        else:
            free_nodes = np.flatnonzero(~coupled)
            p = np.full(n, -1, dtype=np.int64)
            p[free_nodes] = np.arange(len(free_nodes))
            n_q = 3 * len(free_nodes) + 6 * len(kin)
            rows, cols, vals = [], [], []
            rows.append((3 * free_nodes[:, None] + np.arange(3)).ravel())
            cols.append((3 * p[free_nodes][:, None] + np.arange(3)).ravel())
            vals.append(np.ones(3 * len(free_nodes)))
            B = np.zeros((n_q, 6))
            B[:3 * len(free_nodes)] = B_full.reshape(n, 3, 6)[free_nodes].reshape(-1, 6)
            bq_extra = np.zeros(6 * len(kin))
            ref_slices = []
            g_dofs, g_of, g_rows = [], [], []
            for k, c in enumerate(kin):
                base = 3 * len(free_nodes) + 6 * k
                ref_slices.append(slice(base, base + 6))
                d = mesh.points[c.nodes] - c.ref_point_m                 # (k,3)
                # u_i = U − [d_i]× Θ
                blk = np.zeros((len(c.nodes), 3, 6))
                blk[:, :, :3] = np.eye(3)
                blk[:, :, 3:] = -_skew(d)
                r = (3 * c.nodes[:, None, None] + np.arange(3)[None, :, None]) * np.ones((1, 1, 6), int)
                cc = base + np.broadcast_to(np.arange(6), blk.shape)
                nz = blk != 0
                rows.append(r[nz]); cols.append(cc[nz]); vals.append(blk[nz])
                g_dofs.append((3 * c.nodes[:, None] + np.arange(3)).ravel())
                g_of.append(np.full(3 * len(c.nodes), k)); g_rows.append(blk.reshape(-1, 6))
                bq_extra[6 * k:6 * k + 3] = c.force_N
                bq_extra[6 * k + 3:6 * k + 6] = c.moment_Nm
                # rigid modes of the reference dofs: translation e_k → (e_k, 0); rotation a → (a×(x_r−c), a)
                B[base:base + 3, :3] = np.eye(3)
                B[base:base + 3, 3:] = -_skew((c.ref_point_m - centre)[None])[0]
                B[base + 3:base + 6, 3:] = np.eye(3)
            T = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                              shape=(3 * n, n_q))
            from estimator import compiled

            if REDUCE_COMPILED and compiled.available():        # the project's one switch of compiled loops
                from flexure.reduce import reduced_stiffness

                gd = np.concatenate(g_dofs)
                o = np.argsort(gd)
                A = reduced_stiffness(K, gd[o], np.concatenate(g_of)[o], np.concatenate(g_rows)[o], len(kin))
            else:
                A = (T.T @ K @ T).tocsr()                                # the reference path
            b = T.T @ f
            b[3 * len(free_nodes):] += bq_extra
            fixed_nodes_dofs = np.flatnonzero(self.fixed[free_nodes].ravel())
            fixed_q = fixed_nodes_dofs
            g = self.fixed_value_m[free_nodes].ravel()[fixed_q]
        # symmetric Dirichlet: b −= A[:, F] g; zero rows/cols F; diagonal = scale; b_F = scale·g
        if len(fixed_q):
            if np.any(g != 0):
                gq = np.zeros(A.shape[0]); gq[fixed_q] = g
                b = b - A @ gq
            scale = float(np.mean(np.abs(A.diagonal()))) or 1.0
            isfix = np.zeros(A.shape[0], dtype=bool); isfix[fixed_q] = True
            if not (REDUCE_COMPILED and _zero_fixed(A, fixed_q, isfix, scale)):
                rows_fixed = np.repeat(isfix, np.diff(A.indptr))
                A.data[rows_fixed | isfix[A.indices]] = 0.0
                A.setdiag(np.where(isfix, scale, A.diagonal()))
            A.eliminate_zeros()
            b = b.copy(); b[fixed_q] = scale * g
        coarse, B_coarse = (None, None)
        if mesh.order == 2:
            coarse, B_coarse = self._coarse_interpolation(coupled, kin, B)
        return LinearSystem(A=A, b=np.asarray(b, dtype=np.float64), T=T, fixed_q=fixed_q,
                            B=B, n_nodes=n, ref_slices=ref_slices, coarse=coarse, B_coarse=B_coarse)

    def _coarse_interpolation(self, coupled: np.ndarray, kin: list, B: np.ndarray):
        """q = I q₁: P2 unknowns from P1-vertex unknowns (mid-edge = mean of its two vertices).

        Coarse unknowns: free (non-coupled) vertices' 3 dofs, then the 6 reference dofs of each
        kinematic coupling (a coupled vertex moves as U − [d]× Θ). Used by the p-multigrid solver.
        """
        mesh = self.mesh
        n = mesh.n_nodes
        t = mesh.tets.astype(np.int64)
        verts = np.unique(t[:, :4])
        free = ~coupled
        free_nodes = np.flatnonzero(free)
        p = np.full(n, -1, dtype=np.int64); p[free_nodes] = np.arange(len(free_nodes))
        cverts = verts[free[verts]]
        c1 = np.full(n, -1, dtype=np.int64); c1[cverts] = np.arange(len(cverts))
        n1 = 3 * len(cverts) + 6 * len(kin)
        coupling_of = np.full(n, -1, dtype=np.int64)
        for k, c in enumerate(kin):
            coupling_of[c.nodes] = k
        # parents: vertex → itself (weight 1); mid node → its edge's two vertices (½ each)
        from flexure.mesh import TET_EDGES
        mid = t[:, 4:].ravel()
        ea = t[:, TET_EDGES[:, 0]].ravel(); eb = t[:, TET_EDGES[:, 1]].ravel()
        mid, first = np.unique(mid, return_index=True)
        child = np.concatenate([verts, mid, mid])
        parent = np.concatenate([verts, ea[first], eb[first]])
        w = np.concatenate([np.ones(len(verts)), np.full(2 * len(mid), 0.5)])
        keep = free[child]
        child, parent, w = child[keep], parent[keep], w[keep]
        rows, cols, vals = [], [], []
        fp = free[parent]
        for i in range(3):      # free parent vertex: same component
            rows.append(3 * p[child[fp]] + i); cols.append(3 * c1[parent[fp]] + i); vals.append(w[fp])
        cp = ~fp                # coupled parent vertex: u = U − [d]× Θ of its coupling
        if np.any(cp):
            k = coupling_of[parent[cp]]
            refs = np.array([c.ref_point_m for c in kin])
            d = mesh.points[parent[cp]] - refs[k]
            blk = np.zeros((cp.sum(), 3, 6)); blk[:, :, :3] = np.eye(3); blk[:, :, 3:] = -_skew(d)
            blk *= w[cp][:, None, None]
            base = 3 * len(cverts) + 6 * k
            r = 3 * p[child[cp]][:, None, None] + np.arange(3)[None, :, None] + np.zeros((1, 1, 6), int)
            cc = base[:, None, None] + np.arange(6)[None, None, :] + np.zeros((1, 3, 1), int)
            nz = blk != 0
            rows.append(r[nz]); cols.append(cc[nz]); vals.append(blk[nz])
        nq = 3 * len(free_nodes) + 6 * len(kin)
        for k in range(len(kin)):   # reference dofs map to themselves
            rows.append(3 * len(free_nodes) + 6 * k + np.arange(6))
            cols.append(3 * len(cverts) + 6 * k + np.arange(6)); vals.append(np.ones(6))
        I = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(nq, n1))
        sel = np.concatenate([(3 * p[cverts][:, None] + np.arange(3)).ravel(),
                              3 * len(free_nodes) + np.arange(6 * len(kin))])
        return I, B[sel]

    def restrict(self, system: LinearSystem, u: np.ndarray, reference=None) -> np.ndarray:
        """q of nodal displacements u (n,3[,k]) (``expand``'s inverse on the free nodes; the
        couplings' reference dofs from ``reference`` (6·couplings[,k]), else zero) — an initial
        guess from a coarser level's solution prolongated (flexure.refine)."""
        u = np.asarray(u, dtype=np.float64)
        k = u.shape[2:] if u.ndim == 3 else ()
        if system.T is None:
            return u.reshape((-1,) + k).copy()
        coupled = np.zeros(system.n_nodes, bool)
        for c in self.couplings:
            if c.kind == "kinematic":
                coupled[c.nodes] = True
        free = u[~coupled].reshape((-1,) + k)
        nref = system.A.shape[0] - len(free)
        ref = np.zeros((nref,) + k) if reference is None else np.asarray(reference, float).reshape((nref,) + k)
        q = np.concatenate([free, ref])
        q[system.fixed_q] = 0.0
        return q

    def expand(self, system: LinearSystem, q: np.ndarray) -> np.ndarray:
        """Nodal displacements (n,3) from the reduced solution q."""
        u = q if system.T is None else system.T @ q
        return np.asarray(u).reshape(-1, 3)
