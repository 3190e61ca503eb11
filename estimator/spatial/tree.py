"""The kinematic tree of a URDF robot as flat arrays, and the observer's momentum terms over it
in one compiled pass per sample (numba; the same Python function runs without it).

Bodies b = 0 … NB−1: b = 0 is the base (pinocchio joint 1, the free-flyer), body b ≥ 1 moves with
pinocchio joint b + 1 (its parent body ``parent[b]`` < b). Each joint has its placement (Rp, pp)
in the parent body's frame and its axis in its own frame (``kind`` 0 revolute: rotation about
the axis through the joint origin; 1 prismatic: translation along it). Inertias are pinocchio's
(fixed links merged into their body): mass, centre of mass and rotational inertia about the
centre of mass, in the body frame.

Observer coordinates (docs/conventions.md): q = [p, quat (x, y, z, w), joint angles],
v = [ṗ (world), ω (base frame), joint rates]. Spatial vectors are [linear; angular], expressed
in the world frame at a point O that coincides with the base origin at the instant (positions are
relative to p, so large coordinates lose nothing). Every column k of the Jacobians is a twist
S_k; body i's momentum h_i = [m_i v_ci ; c_i × m_i v_ci + I_i ω_i]; H_k sums h over the bodies
that column k moves (its subtree). Then

    P_k     = S_kᵀ H_k                                   (P = M v)
    (Cᵀv)_k = Ṡ_kᵀ H_k,   Ṡ_k = v_k ×ₘ S_k  (body-fixed columns), Ṡ_k = 0 for the world-fixed ṗ
    G_k     = −S_kᵀ Fg_k, Fg_k = Σ_subtree [m_i g ; c_i × m_i g]
    u       = τ + Cᵀv − G

with [v; ω] ×ₘ [s_v; s_ω] = [ω × s_v + v × s_ω ; ω × s_ω]. (Ṗ = Σ J̇_iᵀ h_i + J_iᵀ ḣ_i and
Σ J_iᵀ ḣ_i = τ + τ_ext − G give Cᵀv = Σ J̇_iᵀ h_i.) Tested against pinocchio (crba,
computeCoriolisMatrix, computeGeneralizedGravity) to round-off.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from userio.errors import InputError


@dataclass(frozen=True)
class Tree:
    parent: np.ndarray      # (NB,) int, parent[0] = −1
    Rp: np.ndarray          # (NB, 3, 3) joint placement rotation in the parent body frame
    pp: np.ndarray          # (NB, 3)
    axis: np.ndarray        # (NB, 3) joint axis in the joint frame (unit)
    kind: np.ndarray        # (NB,) 0 revolute, 1 prismatic (body 0: unused)
    mass: np.ndarray        # (NB,)
    com: np.ndarray         # (NB, 3) in the body frame
    Ic: np.ndarray          # (NB, 3, 3) about the centre of mass, body frame
    gravity: np.ndarray     # (3,) world, e.g. (0, 0, −9.81)
    body_names: tuple       # URDF link name of each body
    joint_names: tuple      # joint of bodies 1 … NB−1

    @property
    def n_bodies(self) -> int:
        return len(self.parent)

    @property
    def nv(self) -> int:
        return 5 + self.n_bodies


def tree_from_model(model, source: str = "URDF") -> Tree:
    """The flat arrays of a pinocchio model with a free-flyer root (joint 1)."""
    import pinocchio as pin

    NB = model.njoints - 1
    data = model.createData()
    q0 = pin.neutral(model)
    pin.computeJointJacobians(model, data, q0)
    parent = np.full(NB, -1)
    Rp = np.zeros((NB, 3, 3))
    pp = np.zeros((NB, 3))
    axis = np.zeros((NB, 3))
    kind = np.zeros(NB, dtype=np.int64)
    mass = np.zeros(NB)
    com = np.zeros((NB, 3))
    Ic = np.zeros((NB, 3, 3))
    names = []
    for b in range(NB):
        j = b + 1
        Y = model.inertias[j]
        mass[b], com[b], Ic[b] = Y.mass, np.array(Y.lever), np.array(Y.inertia)
        body = [f.name for f in model.frames if f.parentJoint == j and f.type == pin.FrameType.BODY]
        names.append(body[0] if body else model.names[j])
        if b == 0:
            continue
        parent[b] = model.parents[j] - 1
        M = model.jointPlacements[j]
        Rp[b], pp[b] = np.array(M.rotation), np.array(M.translation)
        S = pin.getJointJacobian(model, data, j, pin.LOCAL)[:, model.idx_vs[j]]
        lin, ang = S[:3], S[3:]
        if np.linalg.norm(ang) > 1e-12 and np.linalg.norm(lin) < 1e-12:
            kind[b], axis[b] = 0, ang / np.linalg.norm(ang)
        elif np.linalg.norm(ang) < 1e-12:
            kind[b], axis[b] = 1, lin / np.linalg.norm(lin)
        else:
            raise InputError(f"{source}: joint '{model.names[j]}': neither revolute nor prismatic")
    return Tree(parent=parent, Rp=Rp, pp=pp, axis=axis, kind=kind, mass=mass, com=com, Ic=Ic,
                gravity=np.array(model.gravity.linear), body_names=tuple(names),
                joint_names=tuple(model.names[j] for j in range(2, model.njoints)))


# ----------------------------------------------------------------------------- the compiled pass
def _terms_loop(q, v, tau, parent, Rp, pp, axis, kind, mass, com, Ic, g, P, u):
    """P = M v and u = τ + Cᵀv − G per sample (module doc); P, u (T, nv) filled in place."""
    T = q.shape[0]
    NB = parent.shape[0]
    R = np.empty((NB, 3, 3))
    pos = np.empty((NB, 3))
    tw = np.empty((NB, 6))          # body twists [v_O; ω] at the reference point
    S = np.empty((NB, 6))           # joint columns (world, at O)
    H = np.empty((NB, 6))
    F = np.empty((NB, 6))
    Rj = np.empty((3, 3))
    o = np.empty(3)
    e = np.empty(3)
    c = np.empty(3)
    wb = np.empty(3)
    Iw = np.empty(3)
    L = np.empty(3)
    for k in range(T):
        x, y, z, w = q[k, 3], q[k, 4], q[k, 5], q[k, 6]
        s = 1.0 / np.sqrt(x * x + y * y + z * z + w * w)
        x *= s
        y *= s
        z *= s
        w *= s
        R[0, 0, 0] = 1 - 2 * (y * y + z * z)
        R[0, 0, 1] = 2 * (x * y - z * w)
        R[0, 0, 2] = 2 * (x * z + y * w)
        R[0, 1, 0] = 2 * (x * y + z * w)
        R[0, 1, 1] = 1 - 2 * (x * x + z * z)
        R[0, 1, 2] = 2 * (y * z - x * w)
        R[0, 2, 0] = 2 * (x * z - y * w)
        R[0, 2, 1] = 2 * (y * z + x * w)
        R[0, 2, 2] = 1 - 2 * (x * x + y * y)
        for i in range(3):
            pos[0, i] = 0.0
            tw[0, i] = v[k, i]
            tw[0, 3 + i] = R[0, i, 0] * v[k, 3] + R[0, i, 1] * v[k, 4] + R[0, i, 2] * v[k, 5]
        for b in range(1, NB):
            a = parent[b]
            # joint frame: R_a Rp, origin pos_a + R_a pp
            for i in range(3):
                o[i] = pos[a, i] + R[a, i, 0] * pp[b, 0] + R[a, i, 1] * pp[b, 1] + R[a, i, 2] * pp[b, 2]
                for j in range(3):
                    Rj[i, j] = R[a, i, 0] * Rp[b, 0, j] + R[a, i, 1] * Rp[b, 1, j] + R[a, i, 2] * Rp[b, 2, j]
            ax = axis[b]
            for i in range(3):
                e[i] = Rj[i, 0] * ax[0] + Rj[i, 1] * ax[1] + Rj[i, 2] * ax[2]
            qj = q[k, 6 + b]
            if kind[b] == 0:
                # R_b = Rj · rot(axis, q) = rot_world(e, q) · Rj (Rodrigues on the world axis)
                sn, cs = np.sin(qj), np.cos(qj)
                for j in range(3):
                    r0, r1, r2 = Rj[0, j], Rj[1, j], Rj[2, j]
                    d = e[0] * r0 + e[1] * r1 + e[2] * r2
                    cx = e[1] * r2 - e[2] * r1
                    cy = e[2] * r0 - e[0] * r2
                    cz = e[0] * r1 - e[1] * r0
                    R[b, 0, j] = r0 * cs + cx * sn + e[0] * d * (1 - cs)
                    R[b, 1, j] = r1 * cs + cy * sn + e[1] * d * (1 - cs)
                    R[b, 2, j] = r2 * cs + cz * sn + e[2] * d * (1 - cs)
                    pos[b, j] = o[j]
                S[b, 0] = o[1] * e[2] - o[2] * e[1]       # o × e: the twist at O
                S[b, 1] = o[2] * e[0] - o[0] * e[2]
                S[b, 2] = o[0] * e[1] - o[1] * e[0]
                S[b, 3], S[b, 4], S[b, 5] = e[0], e[1], e[2]
            else:
                for j in range(3):
                    for i in range(3):
                        R[b, i, j] = Rj[i, j]
                    pos[b, j] = o[j] + e[j] * qj
                S[b, 0], S[b, 1], S[b, 2] = e[0], e[1], e[2]
                S[b, 3] = S[b, 4] = S[b, 5] = 0.0
            qd = v[k, 5 + b]
            for i in range(6):
                tw[b, i] = tw[a, i] + S[b, i] * qd
        # body momenta and gravity wrenches at O
        for b in range(NB):
            m = mass[b]
            for i in range(3):
                c[i] = pos[b, i] + R[b, i, 0] * com[b, 0] + R[b, i, 1] * com[b, 1] + R[b, i, 2] * com[b, 2]
            w0_, w1_, w2_ = tw[b, 3], tw[b, 4], tw[b, 5]
            vc0 = tw[b, 0] + w1_ * c[2] - w2_ * c[1]
            vc1 = tw[b, 1] + w2_ * c[0] - w0_ * c[2]
            vc2 = tw[b, 2] + w0_ * c[1] - w1_ * c[0]
            p0, p1, p2 = m * vc0, m * vc1, m * vc2
            # I_world ω = R Ic Rᵀ ω
            for i in range(3):
                wb[i] = R[b, 0, i] * w0_ + R[b, 1, i] * w1_ + R[b, 2, i] * w2_
            for i in range(3):
                Iw[i] = Ic[b, i, 0] * wb[0] + Ic[b, i, 1] * wb[1] + Ic[b, i, 2] * wb[2]
            for i in range(3):
                L[i] = R[b, i, 0] * Iw[0] + R[b, i, 1] * Iw[1] + R[b, i, 2] * Iw[2]
            H[b, 0], H[b, 1], H[b, 2] = p0, p1, p2
            H[b, 3] = c[1] * p2 - c[2] * p1 + L[0]
            H[b, 4] = c[2] * p0 - c[0] * p2 + L[1]
            H[b, 5] = c[0] * p1 - c[1] * p0 + L[2]
            f0, f1, f2 = m * g[0], m * g[1], m * g[2]
            F[b, 0], F[b, 1], F[b, 2] = f0, f1, f2
            F[b, 3] = c[1] * f2 - c[2] * f1
            F[b, 4] = c[2] * f0 - c[0] * f2
            F[b, 5] = c[0] * f1 - c[1] * f0
        for b in range(NB - 1, 0, -1):          # subtree sums
            a = parent[b]
            for i in range(6):
                H[a, i] += H[b, i]
                F[a, i] += F[b, i]
        # base rows: ṗ columns [e_i; 0] (world-fixed), ω columns [0; R e_i] (body-fixed)
        vO0, vO1, vO2 = tw[0, 0], tw[0, 1], tw[0, 2]
        w0, w1, w2 = tw[0, 3], tw[0, 4], tw[0, 5]
        for i in range(3):
            P[k, i] = H[0, i]
            u[k, i] = tau[k, i] + F[0, i]
            a0, a1, a2 = R[0, 0, i], R[0, 1, i], R[0, 2, i]
            P[k, 3 + i] = a0 * H[0, 3] + a1 * H[0, 4] + a2 * H[0, 5]
            # Ṡ = [vO × a ; ω × a]
            sd0 = vO1 * a2 - vO2 * a1
            sd1 = vO2 * a0 - vO0 * a2
            sd2 = vO0 * a1 - vO1 * a0
            sd3 = w1 * a2 - w2 * a1
            sd4 = w2 * a0 - w0 * a2
            sd5 = w0 * a1 - w1 * a0
            ctv = sd0 * H[0, 0] + sd1 * H[0, 1] + sd2 * H[0, 2] + sd3 * H[0, 3] + sd4 * H[0, 4] + sd5 * H[0, 5]
            u[k, 3 + i] = tau[k, 3 + i] + ctv + a0 * F[0, 3] + a1 * F[0, 4] + a2 * F[0, 5]
        for b in range(1, NB):
            r = 5 + b
            s0, s1, s2, s3, s4, s5 = S[b, 0], S[b, 1], S[b, 2], S[b, 3], S[b, 4], S[b, 5]
            P[k, r] = s0 * H[b, 0] + s1 * H[b, 1] + s2 * H[b, 2] + s3 * H[b, 3] + s4 * H[b, 4] + s5 * H[b, 5]
            tv0, tv1, tv2, tw0, tw1, tw2 = tw[b, 0], tw[b, 1], tw[b, 2], tw[b, 3], tw[b, 4], tw[b, 5]
            sd0 = tw1 * s2 - tw2 * s1 + tv1 * s5 - tv2 * s4
            sd1 = tw2 * s0 - tw0 * s2 + tv2 * s3 - tv0 * s5
            sd2 = tw0 * s1 - tw1 * s0 + tv0 * s4 - tv1 * s3
            sd3 = tw1 * s5 - tw2 * s4
            sd4 = tw2 * s3 - tw0 * s5
            sd5 = tw0 * s4 - tw1 * s3
            ctv = sd0 * H[b, 0] + sd1 * H[b, 1] + sd2 * H[b, 2] + sd3 * H[b, 3] + sd4 * H[b, 4] + sd5 * H[b, 5]
            grav = s0 * F[b, 0] + s1 * F[b, 1] + s2 * F[b, 2] + s3 * F[b, 3] + s4 * F[b, 4] + s5 * F[b, 5]
            u[k, r] = tau[k, r] + ctv + grav


def _stat_loop(r, rows, Lb, block, out):
    """out[k] = ‖Lb[block[k]] r[k, rows]‖² (the whitened residual's squared norm)."""
    nu = rows.shape[0]
    for k in range(r.shape[0]):
        L = Lb[block[k]]
        s = 0.0
        for i in range(nu):
            z = 0.0
            for j in range(i + 1):
                z += L[i, j] * r[k, rows[j]]
            s += z * z
        out[k] = s


def _lstsq_loop(A, b, x):
    """x[s] = argmin ‖A[s] x − b[s]‖ by the normal equations and a Cholesky factorization
    (A[s] (m, k) of full column rank, k ≤ 8); NaN where AᵀA is not positive definite."""
    S, m, k = A.shape
    N = np.empty((k, k))
    y = np.empty(k)
    for s in range(S):
        for i in range(k):
            acc = 0.0
            for r in range(m):
                acc += A[s, r, i] * b[s, r]
            y[i] = acc
            for j in range(i + 1):
                acc = 0.0
                for r in range(m):
                    acc += A[s, r, i] * A[s, r, j]
                N[i, j] = acc
        ok = True
        for j in range(k):                       # Cholesky N = L Lᵀ in the lower triangle
            d = N[j, j]
            for p in range(j):
                d -= N[j, p] * N[j, p]
            if not d > 0.0:
                ok = False
                break
            d = np.sqrt(d)
            N[j, j] = d
            for i in range(j + 1, k):
                v = N[i, j]
                for p in range(j):
                    v -= N[i, p] * N[j, p]
                N[i, j] = v / d
        if not ok:
            for i in range(k):
                x[s, i] = np.nan
            continue
        for i in range(k):                       # L z = y
            v = y[i]
            for p in range(i):
                v -= N[i, p] * y[p]
            y[i] = v / N[i, i]
        for i in range(k - 1, -1, -1):           # Lᵀ x = z
            v = y[i]
            for p in range(i + 1, k):
                v -= N[p, i] * x[s, p]
            x[s, i] = v / N[i, i]


def lstsq_small(A, b) -> np.ndarray:
    """Batched small least squares (compiled): A (S, m, k), b (S, m) → x (S, k)."""
    A = np.ascontiguousarray(A, dtype=float)
    x = np.empty((A.shape[0], A.shape[2]))
    _compiled(_lstsq_loop)(A, np.ascontiguousarray(b, dtype=float), x)
    return x


_COMPILED = {}
USE_NUMBA = True            # False: the same loops in plain Python (tests compare the two)


def _compiled(fn):
    if not USE_NUMBA:
        return fn
    if fn.__name__ not in _COMPILED:
        try:
            import numba

            _COMPILED[fn.__name__] = numba.njit(cache=True, fastmath=False)(fn)
        except ImportError:
            _COMPILED[fn.__name__] = fn
    return _COMPILED[fn.__name__]


def _kernel():
    return _compiled(_terms_loop)


def whitened_statistic(r, rows, Lb, block) -> np.ndarray:
    """s_k = ‖L_b r_k‖² over the rows ``rows`` with lower-triangular L_b = Lb[block[k]]."""
    out = np.empty(len(r))
    _compiled(_stat_loop)(np.ascontiguousarray(r), np.asarray(rows, np.int64),
                          np.ascontiguousarray(Lb), np.asarray(block, np.int64), out)
    return out


def momentum_terms(tree: Tree, q, v, tau):
    """(P, u), each (T, nv), for q (T, nq), v and τ (T, nv) (module doc)."""
    q = np.ascontiguousarray(np.atleast_2d(q), dtype=float)
    v = np.ascontiguousarray(np.atleast_2d(v), dtype=float)
    tau = np.ascontiguousarray(np.atleast_2d(tau), dtype=float)
    T = q.shape[0]
    P = np.empty((T, tree.nv))
    u = np.empty((T, tree.nv))
    _kernel()(q, v, tau, tree.parent, tree.Rp, tree.pp, tree.axis, tree.kind, tree.mass, tree.com,
              tree.Ic, tree.gravity, P, u)
    return P, u


# ----------------------------------------------------------------------------- kinematics (numpy)
def quat_matrix(quat: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) = (x, y, z, w) (normalized here)."""
    qn = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(qn, -1, 0)
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                     np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                     np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)],
                    -2)


def _axis_rotation(e: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues: rotations (T, 3, 3) about unit axes e (T, 3) by ``angle`` (T,)."""
    K = np.zeros(e.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -e[..., 2], e[..., 1]
    K[..., 1, 0], K[..., 1, 2] = e[..., 2], -e[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -e[..., 1], e[..., 0]
    s, c = np.sin(angle)[..., None, None], np.cos(angle)[..., None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def body_poses(tree: Tree, q: np.ndarray, relative: bool = False):
    """World poses of every body: R (T, NB, 3, 3), p (T, NB, 3) (relative to the base origin
    with ``relative``), and every joint's world axis e (T, NB, 3) and origin o (T, NB, 3)."""
    q = np.atleast_2d(np.asarray(q, float))
    T, NB = len(q), tree.n_bodies
    R = np.empty((T, NB, 3, 3))
    p = np.empty((T, NB, 3))
    e = np.zeros((T, NB, 3))
    o = np.zeros((T, NB, 3))
    R[:, 0] = quat_matrix(q[:, 3:7])
    p[:, 0] = 0.0 if relative else q[:, :3]
    for b in range(1, NB):
        a = tree.parent[b]
        Rj = R[:, a] @ tree.Rp[b]
        ob = p[:, a] + R[:, a] @ tree.pp[b]
        eb = Rj @ tree.axis[b]
        qj = q[:, 6 + b]
        if tree.kind[b] == 0:
            R[:, b] = _axis_rotation(eb, qj) @ Rj
            p[:, b] = ob
        else:
            R[:, b] = Rj
            p[:, b] = ob + eb * qj[:, None]
        e[:, b], o[:, b] = eb, ob
    return R, p, e, o


def ancestors(tree: Tree) -> np.ndarray:
    """A[b, c] = True if body c's joint moves body b (c on the path from the base to b; c ≥ 1)."""
    NB = tree.n_bodies
    A = np.zeros((NB, NB), bool)
    for b in range(1, NB):
        c = b
        while c > 0:
            A[b, c] = True
            c = tree.parent[c]
    return A
