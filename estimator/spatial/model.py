"""``UrdfModel``: the RobotModel (estimator.model) of a URDF robot.

Coordinates (docs/conventions.md, "3-D robots"): q = [p (world), quat (x, y, z, w), joint
angles], v = [ṗ (world), ω (base frame), joint rates]: the log's own columns. (pinocchio's
free-flyer rate is v_pin = [Rᵀṗ, ω, q̇], so v_pin = T v with T = diag(Rᵀ, I); then P = Tᵀ P_pin,
τ = Tᵀ τ_pin and u = Tᵀ(τ_pin + C_pinᵀ v_pin − g_pin) + Ṫᵀ P_pin, Ṫᵀ = diag(R[ω]×, 0): the
linear rows are the world's total force, Ṗ_lin = F_mount + F_ext + M g, free of Coriolis terms.)
Rows: base force (3, world), base moment about the base origin (3, base frame), joints.

Inertial parameters θ: pinocchio's dynamic parameters per body (fixed links merged), body frame,
about the body origin: [m, mc_x, mc_y, mc_z, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]. Each body's momentum
h_b = [m v_b + ω_b × mc ; mc × v_b + I_o ω_b] and gravity wrench [m g ; mc_world × g + m p_b × g]
are linear in its θ, so P = Y_P θ and Cᵀv − G = Y_u θ column by column (estimator.spatial.tree's
sums, one body at a time).
"""

from __future__ import annotations

import numpy as np

from userio.errors import InputError
from estimator.spatial import inertial as spatial_inertial
from estimator.spatial import tree as tree_mod
from estimator.spatial.robot import SpatialRobot

PARAMS = spatial_inertial.PARAMS


def _skew(a: np.ndarray) -> np.ndarray:
    K = np.zeros(a.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -a[..., 2], a[..., 1]
    K[..., 1, 0], K[..., 1, 2] = a[..., 2], -a[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -a[..., 1], a[..., 0]
    return K


def columns(tree: tree_mod.Tree, q: np.ndarray, v: np.ndarray | None = None):
    """Jacobian columns as twists at the base origin (world axes): S (T, nv, 6), their rates Ṡ
    (T, nv, 6) (zeros without v), body twists (T, NB, 6), and the poses of ``tree.body_poses``
    (relative to the base origin). Column k moves body b iff ``moves[k, b]``."""
    q = np.atleast_2d(np.asarray(q, float))
    T, NB = len(q), tree.n_bodies
    R, p, e, o = tree_mod.body_poses(tree, q, relative=True)
    nv = tree.nv
    S = np.zeros((T, nv, 6))
    for i in range(3):
        S[:, i, i] = 1.0
        S[:, 3 + i, 3:] = R[:, 0, :, i]
    for b in range(1, NB):
        if tree.kind[b] == 0:
            S[:, 5 + b, :3] = np.cross(o[:, b], e[:, b])
            S[:, 5 + b, 3:] = e[:, b]
        else:
            S[:, 5 + b, :3] = e[:, b]
    Sd = np.zeros_like(S)
    tw = np.zeros((T, NB, 6))
    if v is not None:
        v = np.atleast_2d(np.asarray(v, float))
        tw[:, 0, :3] = v[:, :3]
        tw[:, 0, 3:] = np.einsum("tij,tj->ti", R[:, 0], v[:, 3:6])
        for b in range(1, NB):
            tw[:, b] = tw[:, tree.parent[b]] + S[:, 5 + b] * v[:, 5 + b, None]

        def cross_m(t, s):
            return np.concatenate([np.cross(t[..., 3:], s[..., :3]) + np.cross(t[..., :3], s[..., 3:]),
                                   np.cross(t[..., 3:], s[..., 3:])], axis=-1)

        Sd[:, 3:6] = cross_m(tw[:, 0, None], S[:, 3:6])
        for b in range(1, NB):
            Sd[:, 5 + b] = cross_m(tw[:, b], S[:, 5 + b])
    return S, Sd, tw, (R, p)


def moves(tree: tree_mod.Tree) -> np.ndarray:
    """(nv, NB) bool: column k moves body b (the six base columns move every body)."""
    A = tree_mod.ancestors(tree)
    M = np.zeros((tree.nv, tree.n_bodies), bool)
    M[:6] = True
    M[6:] = A[:, 1:].T
    return M


class UrdfModel:
    """A URDF robot as a RobotModel: the compiled tree recursion for (P, u), pinocchio as the
    reference it is tested against, the inertial-parameter regressor, consistency checks."""

    n_base = 6

    def __init__(self, robot: SpatialRobot):
        self.robot = robot
        self.tree = tree_mod.tree_from_model(robot.model, robot.source)
        self.name = robot.name
        self.floating = robot.floating
        self.joint_names = tuple(robot.joint_names)
        self.sensed_joints = tuple(robot.sensed)
        self.n_v = 6 + len(self.joint_names)
        self.n_q = self.n_v + 1                 # q = [p, quaternion, joints]
        self.parameter_names = spatial_inertial.parameter_names(self.tree.body_names)
        self._ft = robot.ft_placement()
        self._sizes = None

    # ------------------------------------------------------------------ dynamics
    def momentum_terms(self, q, v, tau_meas):
        return tree_mod.momentum_terms(self.tree, q, v, tau_meas)

    def mass_matrix(self, q) -> np.ndarray:
        """M(q) (T, nv, nv): column j is P at v = e_j."""
        q = np.atleast_2d(np.asarray(q, float))
        T, n = len(q), self.n_v
        qq = np.repeat(q, n, axis=0)
        vv = np.tile(np.eye(n), (T, 1))
        P, _ = self.momentum_terms(qq, vv, np.zeros_like(vv))
        return P.reshape(T, n, n).transpose(0, 2, 1)

    # ------------------------------------------------------------------ parameters
    def parameters(self) -> np.ndarray:
        return spatial_inertial.parameters_of(self.robot.model)

    def with_parameters(self, theta) -> "UrdfModel":
        import pinocchio as pin

        theta = np.asarray(theta, float)
        if theta.shape != (len(self.parameter_names),):
            raise InputError(f"parameters: expected {len(self.parameter_names)} values, got {theta.shape}")
        model = self.robot.model.copy()
        for b, j in enumerate(range(1, model.njoints)):
            model.inertias[j] = pin.Inertia.FromDynamicParameters(theta[10 * b:10 * b + 10])
        return UrdfModel(self.robot.with_model(model))

    def momentum_regressor(self, q, v):
        """(Y_P, Y_u), each (T, nv, 10 NB): P = Y_P θ, Cᵀv − G = Y_u θ (module doc)."""
        tree = self.tree
        q = np.atleast_2d(np.asarray(q, float))
        v = np.atleast_2d(np.asarray(v, float))
        T, NB, nv = len(q), tree.n_bodies, self.n_v
        S, Sd, tw, (R, p) = columns(tree, q, v)
        mv = moves(tree)
        YP = np.zeros((T, nv, 10 * NB))
        Yu = np.zeros((T, nv, 10 * NB))
        g = tree.gravity
        for b in range(NB):
            Rb = R[:, b]
            wb = np.einsum("tji,tj->ti", Rb, tw[:, b, 3:])                  # ω in the body frame
            vw = tw[:, b, :3] + np.cross(tw[:, b, 3:], p[:, b])             # body origin velocity
            vb = np.einsum("tji,tj->ti", Rb, vw)
            Yh = np.zeros((T, 6, 10))                                       # body-frame momentum
            Yh[:, :3, 0] = vb
            Yh[:, :3, 1:4] = _skew(wb)
            Yh[:, 3:, 1:4] = -_skew(vb)
            wx, wy, wz = wb[:, 0], wb[:, 1], wb[:, 2]
            Yh[:, 3, 4], Yh[:, 3, 5], Yh[:, 3, 7] = wx, wy, wz
            Yh[:, 4, 5], Yh[:, 4, 6], Yh[:, 4, 8] = wx, wy, wz
            Yh[:, 5, 7], Yh[:, 5, 8], Yh[:, 5, 9] = wx, wy, wz
            lin = np.einsum("tij,tjk->tik", Rb, Yh[:, :3])                  # to world, at O
            ang = np.einsum("tij,tjk->tik", Rb, Yh[:, 3:]) + np.cross(p[:, b, :, None], lin, axis=1)
            Yw = np.concatenate([lin, ang], axis=1)
            Yg = np.zeros((T, 6, 10))                                       # gravity wrench at O
            Yg[:, :3, 0] = g
            Yg[:, 3:, 0] = np.cross(p[:, b], g)
            Yg[:, 3:, 1:4] = -np.einsum("ij,tjk->tik", _skew(g), Rb)
            rows = np.flatnonzero(mv[:, b])
            blk = slice(10 * b, 10 * b + 10)
            YP[:, rows, blk] = np.einsum("tks,tsp->tkp", S[:, rows], Yw)
            Yu[:, rows, blk] = (np.einsum("tks,tsp->tkp", Sd[:, rows], Yw)
                                + np.einsum("tks,tsp->tkp", S[:, rows], Yg))
        return YP, Yu

    def consistency_problems(self, theta) -> list[str]:
        """Per body: m > 0, I_c = I_o − m[c]ᵀ[c] positive definite with the triangle
        inequalities λ_i ≤ λ_j + λ_k; [] when consistent."""
        theta = np.asarray(theta, float).reshape(-1, 10)
        out = []
        for name, th in zip(self.tree.body_names, theta):
            m = th[0]
            if not (np.isfinite(m) and m > 0):
                out.append(f"{name}: mass {m:g} kg is not > 0")
                continue
            c = th[1:4] / m
            Io = np.array([[th[4], th[5], th[7]], [th[5], th[6], th[8]], [th[7], th[8], th[9]]])
            K = _skew(c)
            Ic = Io - m * K.T @ K
            lam = np.linalg.eigvalsh(Ic)
            if not lam[0] > 0:
                out.append(f"{name}: inertia about the centre of mass is not positive definite "
                           f"(eigenvalues {np.round(lam, 9).tolist()} kg·m²)")
            elif lam[2] > lam[0] + lam[1] + 1e-12 * lam[2]:
                out.append(f"{name}: inertia violates the triangle inequality "
                           f"(eigenvalues {np.round(lam, 9).tolist()} kg·m²)")
        return out

    def consistency_margins(self, theta) -> np.ndarray:
        """Per body [m, e₁, e₂, e₃ of m I_c, e₂, e₃ of m Σ_c]: polynomials in θ, all ≥ 0 exactly
        when the pseudo-inertia is positive semidefinite (estimator.spatial.inertial)."""
        return spatial_inertial.consistency_margins(theta)

    def consistency_lmis(self, theta) -> list[np.ndarray]:
        """The pseudo-inertias J_b ⪰ 0 (estimator.spatial.inertial.pseudo_inertia)."""
        return [spatial_inertial.pseudo_inertia(theta)]

    @property
    def consistency_margin_names(self) -> list[str]:
        return spatial_inertial.margin_names(self.tree.body_names)

    @property
    def body_sizes_m(self) -> np.ndarray:
        """ℓ per body: what a ``relative`` centre-of-mass uncertainty is relative to."""
        if self._sizes is None:
            from estimator.spatial.geometry import body_sizes

            self._sizes = body_sizes(self.robot, self.tree)
        return self._sizes

    def parameter_covariance(self, uncertainty) -> np.ndarray:
        """Σ_θ = J diag(σ_p²) Jᵀ of independent per-body errors in the mass, the centre of mass and
        a strain of the mass distribution about it (estimator.spatial.inertial)."""
        return spatial_inertial.parameter_covariance(self.parameters(), self.body_sizes_m, uncertainty)

    def model_covariance(self):
        """(Σ_θ, source) the robot file states: its [identification] covariance, else its declared
        [model_uncertainty], else (None, why)."""
        ident, unc = self.robot.identification, self.robot.model_uncertainty
        if ident is not None:
            logs = ", ".join(str(g.get("path", "?")) for g in ident.get("logs", [])) or "its logs"
            return np.asarray(ident["covariance"], float), f"identification of {self.name} from {logs}"
        if unc is not None:
            return self.parameter_covariance(unc), f"declared model uncertainty: {unc.describe()}"
        return None, "the robot file is not identified and declares no [model_uncertainty]"

    def perturbed(self, uncertainty, seed: int) -> "UrdfModel":
        """A robot whose inertial data differ from this one by one draw of the declared physical
        uncertainty (``spatial_inertial.draw``: always consistent); geometry, joints and sensors
        unchanged, no identification or declared uncertainty carried over."""
        from dataclasses import replace

        theta = spatial_inertial.draw(self.parameters(), self.body_sizes_m, uncertainty,
                                      np.random.default_rng(seed))
        robot = replace(self.robot, name=f"{self.name}_perturbed_{seed}", model_uncertainty=None,
                        identification=None)
        return UrdfModel(robot).with_parameters(theta)

    # ------------------------------------------------------------------ the FT sensor
    def base_rows_from_ft(self, q: np.ndarray, wrench_s: np.ndarray) -> np.ndarray:
        """The six base rows of τ_meas from the sensor-frame wrench ON the robot (T, 6):
        force in the world (R_wb R_bs f_s), moment about the base origin in the base frame
        (R_bs m_s + p_bs × R_bs f_s)."""
        Rbs, pbs = self._ft
        q = np.atleast_2d(q)
        w = np.atleast_2d(np.asarray(wrench_s, float))
        out = np.empty(w.shape)
        f_b = w[:, :3] @ Rbs.T
        out[:, 3:] = w[:, 3:] @ Rbs.T + cross(np.broadcast_to(pbs, f_b.shape), f_b)
        out[:, :3] = quat_rotate(q[:, 3:7], f_b)
        return out

    def ft_map(self, q: np.ndarray) -> np.ndarray:
        """The linear map of ``base_rows_from_ft`` at each posture, (T, 6, 6):
        [[R R_bs, 0], [[p_bs]× R_bs, R_bs]]."""
        Rbs, pbs = self._ft
        q = np.atleast_2d(q)
        R = tree_mod.quat_matrix(q[:, 3:7])
        out = np.zeros((len(q), 6, 6))
        out[:, :3, :3] = R @ Rbs
        out[:, 3:, :3] = _skew(pbs) @ Rbs
        out[:, 3:, 3:] = Rbs
        return out

    def ft_from_base_rows(self, q: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The inverse of ``base_rows_from_ft``: the sensor-frame wrench (T, 6)."""
        Rbs, pbs = self._ft
        q = np.atleast_2d(q)
        rows = np.atleast_2d(np.asarray(rows, float))
        f_b = quat_rotate(q[:, 3:7], rows[:, :3], inverse=True)
        m_b = rows[:, 3:] - cross(np.broadcast_to(pbs, f_b.shape), f_b)
        return np.concatenate([f_b @ Rbs, m_b @ Rbs], axis=1)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b over the last axis (3), without np.cross's axis shuffling (faster on (T, 3))."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def quat_rotate(quat: np.ndarray, v: np.ndarray, inverse: bool = False) -> np.ndarray:
    """R(quat) v (or Rᵀ v) for quaternions (T, 4) = (x, y, z, w), normalized here, and v (T, 3):
    v' = v + 2w (u × v) + 2 u × (u × v), u = (x, y, z) (−u for the inverse)."""
    n = np.sqrt(np.einsum("ti,ti->t", quat, quat))[:, None]
    u = quat[:, :3] / n
    w = quat[:, 3:4] / n
    if inverse:
        u = -u
    c = cross(u, v)
    return v + 2.0 * (w * c + cross(u, c))


def pinocchio_terms(robot: SpatialRobot, q, v, tau):
    """(P, u) through pinocchio (crba, computeCoriolisMatrix, computeGeneralizedGravity) in the
    observer's coordinates: the reference ``UrdfModel.momentum_terms`` is tested against."""
    import pinocchio as pin

    model = robot.model
    data = model.createData()
    q = np.atleast_2d(np.asarray(q, float))
    v = np.atleast_2d(np.asarray(v, float))
    tau = np.atleast_2d(np.asarray(tau, float))
    T, nv = v.shape
    P = np.empty((T, nv))
    u = np.empty((T, nv))
    for k in range(T):
        qk = q[k].copy()
        qk[3:7] /= np.linalg.norm(qk[3:7])
        R = tree_mod.quat_matrix(qk[3:7])
        vp = v[k].copy()
        vp[:3] = R.T @ v[k, :3]
        M = pin.crba(model, data, qk)
        M = np.triu(M) + np.triu(M, 1).T
        C = pin.computeCoriolisMatrix(model, data, qk, vp)
        g = pin.computeGeneralizedGravity(model, data, qk)
        Pp = M @ vp
        up = C.T @ vp - g
        P[k] = Pp
        P[k, :3] = R @ Pp[:3]
        u[k] = up + tau[k]
        u[k, :3] = R @ up[:3] + tau[k, :3] + R @ np.cross(v[k, 3:6], Pp[:3])
    return P, u
