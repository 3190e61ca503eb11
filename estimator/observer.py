"""Generalized-momentum observer (paper eqs. 2–4; De Luca & Mattone 2005).

Convention (estimator.dynamics): M q̈ + C q̇ + G = τ + τ_ext, τ_ext = J_cᵀ F_c (force ON the robot).
With P = M q̇ (eq. 2), Ṁ = C + Cᵀ gives Ṗ = u + τ_ext, u = τ_meas + Cᵀ q̇ − G, and the residual

    r(t) = K [P(t) − ∫₀ᵗ (u + r) ds − P(0)]          (eq. 3)

obeys ṙ = K (τ_ext − r): a first-order low-pass of the external generalized force, per channel.

Everything runs in floating coordinates [x, z, θ, q_1…q_N]: a fixed-base log has x = z = θ = 0
and the hip FT wrench still enters on the base rows (τ_meas = [Fx, Fz, My, τ_1…τ_N]).

Discretization over a step Δt, with d_k = (P_{k+1} − P_k)/Δt − ū_k the step-mean of τ_ext:

* ``"exact"`` (default): r_{k+1} = a r_k + (1 − a) d_k, a = exp(−K Δt), ū_k = (u_k + u_{k+1})/2.
  Exact for τ_ext held over the step (zero-order hold); stable for every K > 0.
* ``"explicit"`` (paper eq. 4): p_int ← p_int + (u_k + r_k) Δt, i.e. r_{k+1} = (1 − KΔt) r_k
  + KΔt d_k with ū_k = u_k. Unstable for K Δt ≥ 2, which is refused.

The offline form evaluates the recurrence with ``scipy.signal.lfilter`` (one call per channel and
per regular segment; no Python loop over samples); the streaming ``MomentumObserver.step`` runs the
same arithmetic one sample at a time.
"""

from __future__ import annotations

import numpy as np

from estimator import dynamics as dyn
from estimator.errors import InputError
from estimator.robot import Robot

METHODS = ("exact", "explicit")


def full_robot(robot: Robot) -> Robot:
    """The chain in floating coordinates (the observer always works on all n = N + 3 rows)."""
    return robot if robot.floating else robot.with_base(True)


def gains(robot: Robot, gain_per_s) -> np.ndarray:
    """K per row (n = N + 3), from a scalar or a vector; every entry must be finite and > 0."""
    n = robot.n_links + 3
    K = np.broadcast_to(np.asarray(gain_per_s, dtype=float), (n,)).copy() if np.ndim(gain_per_s) == 0 \
        else np.asarray(gain_per_s, dtype=float)
    if K.shape != (n,):
        raise InputError(f"gain: expected a scalar or {n} values (one per generalized coordinate), "
                         f"got {K.shape[0] if K.ndim == 1 else K.shape}")
    if not np.all(np.isfinite(K)) or np.any(K <= 0):
        raise InputError(f"gain: every observer gain must be finite and > 0 s^-1, got {K.tolist()}")
    return K


def coefficients(K: np.ndarray, dt_s: float, method: str = "exact"):
    """(a, b) of r_{k+1} = a r_k + b d_k for each channel; refuses an unstable explicit form."""
    if method not in METHODS:
        raise InputError(f"observer discretization: unknown method {method!r}; use one of {METHODS}")
    if not (np.isfinite(dt_s) and dt_s > 0):
        raise InputError(f"sample period must be > 0 s, got {dt_s}")
    if method == "exact":
        a = np.exp(-K * dt_s)
        return a, -np.expm1(-K * dt_s)
    kdt = K * dt_s
    if np.any(kdt >= 2.0):
        raise InputError(
            f"gain: the explicit (paper eq. 4) observer is unstable for K·Δt ≥ 2 "
            f"(K = {K.max():g} s^-1, Δt = {dt_s:g} s, K·Δt = {kdt.max():g}); lower K or use the "
            f"default exact discretization")
    return 1.0 - kdt, kdt


def momentum_terms(robot: Robot, q: np.ndarray, dq: np.ndarray, tau_meas: np.ndarray,
                   chunk: int = 32768):
    """P = M q̇ and u = τ_meas + Cᵀ q̇ − G for every sample, shapes (T, n) each (floating coords).

    Cᵀ q̇ = Σ_i m_i J̇_iᵀ (J_i q̇) (from C = Σ m_i J_iᵀ J̇_i, estimator.dynamics). Chunked for memory.
    """
    rob = full_robot(robot)
    q = np.asarray(q, float)
    dq = np.asarray(dq, float)
    tau_meas = np.asarray(tau_meas, float)
    single = q.ndim == 1
    if single:
        q, dq, tau_meas = q[None], dq[None], tau_meas[None]
    T, n = q.shape
    P = np.empty((T, n))
    u = np.empty((T, n))
    m = rob.masses_kg
    g = rob.gravity_m_per_s2
    a_rows = dyn._angular_rows(rob)
    Irot = np.einsum("i,ik,il->kl", rob.inertias_kgm2, a_rows, a_rows)
    Irot[0, 0] += rob.base_mass_kg
    Irot[1, 1] += rob.base_mass_kg
    Irot[2, 2] += rob.base_inertia_kgm2
    for s in range(0, T, chunk):
        sl = slice(s, min(T, s + chunk))
        qc, dqc = q[sl], dq[sl]
        J, joints, coms = dyn.com_jacobians_full(rob, qc)
        v = np.einsum("...iak,...k->...ia", J, dqc)                    # CoM velocities
        P[sl] = np.einsum("i,...iak,...ia->...k", m, J, v) + dqc @ Irot
        Jdot = dyn._com_jacobian_rates(rob, qc, dqc, J, joints, coms)
        CTdq = np.einsum("i,...iak,...ia->...k", m, Jdot, v)
        G = g * np.einsum("i,...ik->...k", m, J[..., 1, :])
        G[..., 1] += g * rob.base_mass_kg
        u[sl] = tau_meas[sl] + CTdq - G
    if single:
        return P[0], u[0]
    return P, u


def _drive(P, u, dt_steps, method):
    """d_k = (P_{k+1} − P_k)/Δt_k − ū_k for k = 0…T−2, shape (T−1, n)."""
    ubar = 0.5 * (u[1:] + u[:-1]) if method == "exact" else u[:-1]
    return np.diff(P, axis=0) / dt_steps[:, None] - ubar


def regular_period(t: np.ndarray) -> float:
    """The nominal sample period: the median step."""
    return float(np.median(np.diff(t))) if len(t) > 1 else 1.0


def residual_offline(robot: Robot, t, q, dq, tau_meas, gain_per_s=100.0, method: str = "exact",
                     dt_s: float | None = None, terms=None) -> np.ndarray:
    """Observer residual r (T, n) for a whole log, r_0 = 0 (P_0 = P(t_0)).

    Steps equal to the nominal period ``dt_s`` (default: median step) run through
    ``scipy.signal.lfilter``; a longer step (a gap left by skipped NaN rows) is taken exactly with
    its own Δt and starts a new segment (a Python loop over gaps, not samples).
    """
    from scipy.signal import lfilter

    t = np.asarray(t, float)
    T = len(t)
    K = gains(robot, gain_per_s)
    n = K.size
    r = np.zeros((T, n))
    if T < 2:
        return r
    dt_s = regular_period(t) if dt_s is None else float(dt_s)
    a, b = coefficients(K, dt_s, method)
    P, u = momentum_terms(robot, q, dq, tau_meas) if terms is None else terms
    steps = np.diff(t)
    gap = np.abs(steps - dt_s) > 0.01 * dt_s
    drive = _drive(P, u, np.where(gap, steps, dt_s), method)
    # segment boundaries: indices k where step k (k → k+1) is irregular
    bounds = np.flatnonzero(gap)
    start = 0                          # r[start] is known
    for stop in [*bounds, T - 1]:      # regular steps start … stop−1, then the gap step stop
        if stop > start:
            for j in range(n):
                zi = np.array([a[j] * r[start, j]])
                r[start + 1:stop + 1, j], _ = lfilter([b[j]], [1.0, -a[j]],
                                                      drive[start:stop, j], zi=zi)
        if stop < T - 1:               # the irregular step stop → stop+1
            ag, bg = coefficients(K, steps[stop], method)
            r[stop + 1] = ag * r[stop] + bg * drive[stop]
            start = stop + 1
    return r


def lag_s(K: np.ndarray, dt_s: float, method: str = "exact") -> np.ndarray:
    """Delay of r behind τ_ext for a slowly varying τ_ext, per channel: Δt/(1 − a) − Δt/2 (→ 1/K).

    The recurrence r_{k+1} = a r_k + (1 − a) d_k has DC group delay 1/(1 − a) samples, and d_k is the
    mean of τ_ext over [t_k, t_{k+1}], centred half a step later.
    """
    a, b = coefficients(np.asarray(K, float), dt_s, method)
    return dt_s / b - 0.5 * dt_s


class MomentumObserver:
    """Streaming observer: ``step(q, dq, tau_meas)`` → r (n,), one sample at a time.

    The first call initializes P_0 and returns r = 0, as the offline form does.
    """

    def __init__(self, robot: Robot, dt_s: float, gain_per_s=100.0, method: str = "exact"):
        self.robot = full_robot(robot)
        self.K = gains(self.robot, gain_per_s)
        self.dt_s = float(dt_s)
        self.method = method
        self.a, self.b = coefficients(self.K, self.dt_s, method)
        self._fast = _FastTerms(self.robot)
        self.reset()

    def reset(self):
        self._P = None
        self._u = None
        self.r = np.zeros(self.K.size)

    def step(self, q, dq, tau_meas, dt_s: float | None = None) -> np.ndarray:
        P, u = self._fast(np.asarray(q, float), np.asarray(dq, float), np.asarray(tau_meas, float))
        if self._P is None:
            self._P, self._u = P, u
            return self.r.copy()
        if dt_s is None or abs(dt_s - self.dt_s) <= 0.01 * self.dt_s:
            dt, a, b = self.dt_s, self.a, self.b
        else:
            dt = float(dt_s)
            a, b = coefficients(self.K, dt, self.method)
        ubar = 0.5 * (u + self._u) if self.method == "exact" else self._u
        d = (P - self._P) / dt - ubar
        self.r = a * self.r + b * d
        self._P, self._u = P, u
        return self.r.copy()


class _FastTerms:
    """P = M q̇ and u = τ + Cᵀq̇ − G for ONE sample, with scalar-friendly numpy (low latency).

    Same formulas as ``momentum_terms``: each link's CoM velocity v_i = J_i q̇ and
    J̇_i q̇-rows give P = Σ m_i J_iᵀ v_i + I_rot q̇, Cᵀq̇ = Σ m_i J̇_iᵀ v_i, G = g Σ m_i J_{i,z}ᵀ.
    """

    def __init__(self, robot: Robot):
        self.robot = robot
        N = robot.n_links
        self.N = N
        a_rows = dyn._angular_rows(robot)
        Irot = np.einsum("i,ik,il->kl", robot.inertias_kgm2, a_rows, a_rows)
        Irot[0, 0] += robot.base_mass_kg
        Irot[1, 1] += robot.base_mass_kg
        Irot[2, 2] += robot.base_inertia_kgm2
        self.Irot = Irot
        self.mask = dyn._upstream_mask(N)                       # (N, N+1)
        self.m = robot.masses_kg
        self.l = robot.lengths_m
        self.rc = robot.com_m
        self.g = robot.gravity_m_per_s2
        self.mb = robot.base_mass_kg

    def __call__(self, q, dq, tau):
        N = self.N
        phi = q[2] + np.cumsum(q[3:])
        dphi = dq[2] + np.cumsum(dq[3:])
        s, c = np.sin(phi), np.cos(phi)
        e = np.stack([s, -c], axis=-1)                          # (N, 2) link directions
        de = dphi[:, None] * np.stack([c, s], axis=-1)          # ė
        joints = np.empty((N + 1, 2))
        joints[0] = q[:2]
        joints[1:] = q[:2] + np.cumsum(self.l[:, None] * e, axis=0)
        vj = np.empty((N + 1, 2))
        vj[0] = dq[:2]
        vj[1:] = dq[:2] + np.cumsum(self.l[:, None] * de, axis=0)
        coms = joints[:-1] + self.rc[:, None] * e
        vcom = vj[:-1] + self.rc[:, None] * de
        origins = np.concatenate([joints[:1], joints[:-1]], axis=0)   # (N+1, 2) o_θ, o_q1…o_qN
        vorig = np.concatenate([vj[:1], vj[:-1]], axis=0)
        rel = coms[:, None, :] - origins[None, :, :]                  # (N, N+1, 2)
        drel = vcom[:, None, :] - vorig[None, :, :]
        mk = self.mask * self.m[:, None]                              # m_i on upstream angles
        # angular columns: J[:, :, k] = ⊥(rel) = (−rel_z, rel_x); J̇ = ⊥(drel)
        # P_k = Σ m_i J_ik · v_i ; (Cᵀq̇)_k = Σ m_i J̇_ik · v_i ; G_k = g Σ m_i J_ik,z
        pv = vcom                                                      # (N, 2)
        P = dq @ self.Irot
        P[:2] += self.m @ pv
        P[2:] += np.einsum("ik,ik->k", mk, -rel[..., 1] * pv[:, None, 0] + rel[..., 0] * pv[:, None, 1])
        CT = np.zeros(N + 3)
        CT[2:] = np.einsum("ik,ik->k", mk, -drel[..., 1] * pv[:, None, 0] + drel[..., 0] * pv[:, None, 1])
        G = np.zeros(N + 3)
        G[1] = self.g * (self.mb + self.m.sum())
        G[2:] = self.g * np.einsum("ik,ik->k", mk, rel[..., 0])
        return P, tau + CT - G
