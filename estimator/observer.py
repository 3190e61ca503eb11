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

The offline form evaluates the recurrence in a compiled loop (``first_order``; without
numba ``scipy.signal.lfilter``, one call per channel and regular segment: the same arithmetic,
tested bit-equal); the streaming ``MomentumObserver.step`` runs the
same arithmetic one sample at a time.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from estimator import compiled
from estimator import dynamics as dyn
from estimator import timing as timing_mod
from userio.errors import InputError

if TYPE_CHECKING:                  # annotations only: robot.py's methods call this module
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


def _irot(rob: Robot) -> np.ndarray:
    """Constant part of M: base mass/inertia and the links' rotational inertias, (n, n)."""
    a_rows = dyn._angular_rows(rob)
    Irot = np.einsum("i,ik,il->kl", rob.inertias_kgm2, a_rows, a_rows)
    Irot[0, 0] += rob.base_mass_kg
    Irot[1, 1] += rob.base_mass_kg
    Irot[2, 2] += rob.base_inertia_kgm2
    return Irot


def _matvec_rows(A: np.ndarray, xT: np.ndarray) -> np.ndarray:
    """A @ xT for a small constant (n, n) A and link-major xT (n, T), as row additions in a fixed
    order (skipping zeros): the same bits for a sample whatever batch it is in (BLAS may not)."""
    out = np.zeros((A.shape[0], xT.shape[1]))
    for i in range(A.shape[0]):
        for k in np.flatnonzero(A[i]):
            out[i] += A[i, k] * xT[k]
    return out


def cumrows(a: np.ndarray, reverse: bool = False) -> np.ndarray:
    """Cumulative sum over the first (link) axis by row additions (a loop over links, not samples:
    numpy's cumsum along a short leading axis is several times slower)."""
    out = np.empty_like(a)
    order = range(len(a) - 1, -1, -1) if reverse else range(len(a))
    prev = None
    for i in order:
        if prev is None:
            out[i] = a[i]
        else:
            np.add(out[prev], a[i], out=out[i])
        prev = i
    return out


def chain_terms(robot: Robot, q: np.ndarray, dq: np.ndarray, want=("P", "CTdq", "G")) -> dict:
    """P = M q̇, Cᵀq̇, C q̇ and G of a planar chain in O(N) vector operations per batch.

    With link CoMs c_i (velocity v_i, velocity-product acceleration a_i = J̇_i q̇), angle column k
    (o_0 = o_1 = p_1, o_k = p_k) moving the links i ≥ k − 1 (0-based), and suffix sums over those
    links S_k: Σ m_i (c_i − o_k) × w_i = Σ m_i c_i × w_i − o_k × Σ m_i w_i:

        P_k    = Σ_{S_k} m_i (c_i − o_k) × v_i + (I_rot q̇)_k,   P_xz = Σ m_i v_i + m_b v_b (in I_rot)
        (Cᵀq̇)_k = Σ_{S_k} m_i (v_i − ȯ_k) × v_i = −ȯ_k × Σ_{S_k} m_i v_i,  translational rows 0
        (C q̇)_k = Σ_{S_k} m_i (c_i − o_k) × a_i,  (C q̇)_xz = Σ m_i a_i
        G_k    = g Σ_{S_k} m_i (c_i − o_k)_x,  G_z = g (m_b + Σ m_i)

    Positions are taken relative to the base origin p_1 (no cancellation for large x, z).
    Same numbers as estimator.dynamics (M, C, G) to rounding; tested against it and pinocchio.
    """
    rob = full_robot(robot)
    N = rob.n_links
    shape = np.shape(q)
    qT = np.ascontiguousarray(np.reshape(q, (-1, shape[-1])).T)      # (n, T): link-major layout
    dqT = np.ascontiguousarray(np.reshape(dq, (-1, shape[-1])).T)
    T = qT.shape[1]
    m = rob.masses_kg[:, None]
    l, rc, rp = rob.lengths_m[:, None], rob.com_m[:, None], rob.com_perp_m[:, None]
    phi = qT[2] + cumrows(qT[3:])
    dphi = dqT[2] + cumrows(dqT[3:])
    sn, cs = np.sin(phi), np.cos(phi)
    ex, ez = sn, -cs                          # e_i = (sin φ, −cos φ), ė_i = φ̇ (cos φ, sin φ)
    dex, dez = dphi * cs, dphi * sn
    zero = np.zeros((1, T))

    def prefix(a):                            # [0, a_0, a_0 + a_1, …] over links, (N+1, T)
        return np.concatenate([zero, cumrows(a)], axis=0)

    def suffix(a):                            # Σ_{i ≥ j} a_i for j = 0 … N−1
        return cumrows(a, reverse=True)

    jx, jz = prefix(l * ex), prefix(l * ez)   # joints relative to p_1 (index 0 … N)
    vjx, vjz = dqT[0] + prefix(l * dex), dqT[1] + prefix(l * dez)
    # c_i = p_i + r_i e_i + s_i n_i, n_i = (cos φ, sin φ); ċ_i = ṗ_i + φ̇_i (r_i n_i − s_i e_i)
    cx, cz = jx[:-1] + rc * ex + rp * cs, jz[:-1] + rc * ez + rp * sn
    vx, vz = vjx[:-1] + rc * dex - rp * dphi * ex, vjz[:-1] + rc * dez - rp * dphi * ez
    # angle columns θ, q_1 … q_N: origins p_1, p_1, p_2 … p_N; link set S_k starts at max(k−1, 0)
    sel = np.r_[0, 0:N]
    ox, oz = jx[sel], jz[sel]
    out = {}
    Bx, Bz = suffix(m * vx)[sel], suffix(m * vz)[sel]
    if "P" in want:
        A = suffix(m * (cx * vz - cz * vx))[sel]
        P = _matvec_rows(_irot(rob), dqT)
        P[0] += Bx[0]
        P[1] += Bz[0]
        P[2:] += A - (ox * Bz - oz * Bx)
        out["P"] = P
    if "CTdq" in want:
        CT = np.zeros((N + 3, T))
        CT[2:] = -(vjx[sel] * Bz - vjz[sel] * Bx)
        out["CTdq"] = CT
    if "Cdq" in want:
        # a_i = J̇_i q̇ = −Σ_{j<i} φ̇_j² l_j e_j − φ̇_i² (r_i e_i + s_i n_i)  (base translation: 0)
        w2 = dphi * dphi
        ax = -prefix(w2 * l * ex)[:-1] - w2 * (rc * ex + rp * cs)
        az = -prefix(w2 * l * ez)[:-1] - w2 * (rc * ez + rp * sn)
        Ax, Az = suffix(m * ax)[sel], suffix(m * az)[sel]
        Ac = suffix(m * (cx * az - cz * ax))[sel]
        Cq = np.empty((N + 3, T))
        Cq[0], Cq[1] = Ax[0], Az[0]
        Cq[2:] = Ac - (ox * Az - oz * Ax)
        out["Cdq"] = Cq
    if "G" in want:
        g = rob.gravity_m_per_s2
        G = np.zeros((N + 3, T))
        G[1] = g * (rob.base_mass_kg + m.sum())
        G[2:] = g * (suffix(m * cx)[sel] - ox * np.cumsum(m[::-1, 0])[::-1][sel, None])
        out["G"] = G
    return {k: v.T.reshape(shape) for k, v in out.items()}


def momentum_terms(robot: Robot, q: np.ndarray, dq: np.ndarray, tau_meas: np.ndarray,
                   chunk: int = 8192):
    """P = M q̇ and u = τ_meas + Cᵀ q̇ − G for every sample, shapes (T, n) each (floating coords).

    Uses ``chain_terms`` (suffix sums over the chain), in chunks that stay in cache, or the same
    sums in one compiled loop (``momentum_terms_T``, numba) when it is available.
    """
    q = np.asarray(q, float)
    dq = np.asarray(dq, float)
    tau_meas = np.asarray(tau_meas, float)
    single = q.ndim == 1
    if single:
        q, dq, tau_meas = q[None], dq[None], tau_meas[None]
    T, n = q.shape
    if compiled.available():               # the same equations in one compiled loop
        PT, uT = momentum_terms_T(full_robot(robot), q, dq, tau_meas)
        return (PT[:, 0], uT[:, 0]) if single else (PT.T, uT.T)
    PT = np.empty((n, T))                  # link-major storage; returned as (T, n) views
    uT = np.empty((n, T))
    for s in range(0, T, chunk):
        sl = slice(s, min(T, s + chunk))
        terms = chain_terms(robot, q[sl], dq[sl])
        PT[:, sl] = terms["P"].T
        uT[:, sl] = tau_meas[sl].T + terms["CTdq"].T - terms["G"].T
    if single:
        return PT[:, 0], uT[:, 0]
    return PT.T, uT.T


def _terms_py(q, dq, tau, m, l, rc, rp, Irot, g, Gz, msuf, PT, uT):
    """P = M q̇ and u = τ + Cᵀq̇ − G (observer._FastTerms) for every sample, link-major."""
    T, n = q.shape
    N = n - 3
    cx = np.empty(N)
    cz = np.empty(N)
    vx = np.empty(N)
    vz = np.empty(N)
    ox = np.empty(N)
    oz = np.empty(N)
    vox = np.empty(N)
    voz = np.empty(N)
    for k in range(T):
        phi = q[k, 2]
        dphi = dq[k, 2]
        jx = 0.0
        jz = 0.0
        vjx = dq[k, 0]
        vjz = dq[k, 1]
        for i in range(N):
            phi += q[k, 3 + i]
            dphi += dq[k, 3 + i]
            s = math.sin(phi)
            c = math.cos(phi)
            ox[i] = jx
            oz[i] = jz
            vox[i] = vjx
            voz[i] = vjz
            cx[i] = jx + rc[i] * s + rp[i] * c
            cz[i] = jz - rc[i] * c + rp[i] * s
            vx[i] = vjx + dphi * (rc[i] * c - rp[i] * s)
            vz[i] = vjz + dphi * (rc[i] * s + rp[i] * c)
            jx = jx + l[i] * s
            jz = jz - l[i] * c
            vjx = vjx + l[i] * dphi * c
            vjz = vjz + l[i] * dphi * s
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += Irot[i, j] * dq[k, j]
            PT[i, k] = acc
            uT[i, k] = tau[k, i]
        uT[1, k] -= Gz
        A = 0.0
        Bx = 0.0
        Bz = 0.0
        Gs = 0.0
        for i in range(N - 1, -1, -1):
            A += m[i] * (cx[i] * vz[i] - cz[i] * vx[i])
            Bx += m[i] * vx[i]
            Bz += m[i] * vz[i]
            Gs += m[i] * cx[i]
            Pang = A - (ox[i] * Bz - oz[i] * Bx)
            Cang = -(vox[i] * Bz - voz[i] * Bx)
            Gang = g * (Gs - ox[i] * msuf[i])
            if i == 0:
                PT[2, k] += Pang
                uT[2, k] += Cang - Gang
            PT[3 + i, k] += Pang
            uT[3 + i, k] += Cang - Gang
        PT[0, k] += Bx
        PT[1, k] += Bz


def momentum_terms_T(robot, q, dq, tau):
    """(P, u) link-major (n, T) with the compiled loop (robot: floating coordinates)."""
    k = _LOOPS.get()
    q = np.ascontiguousarray(q, float)
    dq = np.ascontiguousarray(dq, float)
    tau = np.ascontiguousarray(tau, float)
    T, n = q.shape
    m = np.asarray(robot.masses_kg, float)
    g = float(robot.gravity_m_per_s2)
    PT = np.empty((n, T))
    uT = np.empty((n, T))
    msuf = np.cumsum(m[::-1])[::-1].copy()
    k["terms"](q, dq, tau, m, np.asarray(robot.lengths_m, float), np.asarray(robot.com_m, float),
               np.asarray(robot.com_perp_m, float), _irot(robot), g,
               g * (float(robot.base_mass_kg) + float(m.sum())), msuf, PT, uT)
    return PT, uT


PERIOD_HEAD_STEPS = 1024


def regular_period(t: np.ndarray) -> float:
    """The nominal sample period: the median of the first ``PERIOD_HEAD_STEPS`` (1024) steps
    (all of them on a shorter log), so that a log read in chunks knows it from its head."""
    t = np.asarray(t, float)[:PERIOD_HEAD_STEPS + 1]
    return float(np.median(np.diff(t))) if len(t) > 1 else 1.0


def residual_offline(robot: Robot, t, q, dq, tau_meas, gain_per_s=100.0, method: str = "exact",
                     dt_s: float | None = None, terms=None, timing=None) -> np.ndarray:
    """Observer residual r (T, n) for a whole log, r_0 = 0 (P_0 = P(t_0)).

    ``timing``: per-channel sampling of τ_meas [(kind, delay_s)] (estimator.timing; None =
    instantaneous); the step mean ū_k of the measured force uses the matching quadrature.

    Steps equal to the nominal period ``dt_s`` (default: ``regular_period``) run through
    the compiled recursion (``first_order``; ``scipy.signal.lfilter`` without numba, the
    same arithmetic); a longer step (a gap left by skipped NaN rows) is taken exactly with
    its own Δt and starts a new segment (a Python loop over gaps, not samples). The same
    arithmetic as ``residual_window`` on a log read in chunks (estimator.stream).
    """
    t = np.asarray(t, float)
    T = len(t)
    K = gains(robot, gain_per_s)
    if T < 2:
        return np.zeros((T, K.size))
    dt_s = regular_period(t) if dt_s is None else float(dt_s)
    P, u = momentum_terms(robot, q, dq, tau_meas) if terms is None else terms
    rT = residual_window(t, np.ascontiguousarray(P.T), np.ascontiguousarray(u.T),
                         np.asarray(tau_meas, float).T, K, dt_s, method, timing, np.zeros(K.size))
    return rT.T


def lookahead_rows(timing, dt_s: float) -> int:
    """Samples of the future a step's force mean needs (a group delay D reads ⌊D/Δt⌋ + 1 ahead)."""
    if timing is None:
        return 0
    return max([int(np.floor(d / dt_s)) + 1 for k, d in timing if k == "delay" and d > 0], default=0)


def residual_window(t, PT, uT, tauT, K, dt_s: float, method: str, timing, r0) -> np.ndarray:
    """r (n, W) over a window of W rows (link-major P, u, τ_meas) whose first row's r is ``r0``.

    r_{k+1} = a r_k + b d_k, d_k = (P_{k+1} − P_k)/Δt_k − ū_k (module doc). Row k's value depends
    only on r0 and rows ≤ k (+ ``lookahead_rows`` for a group delay), so a log cut into windows
    that overlap by one row gives the same numbers as one window.
    """
    n, W = PT.shape
    rT = np.empty((n, W))
    rT[:, 0] = r0
    if W < 2:
        return rT
    a, b = coefficients(K, dt_s, method)
    steps = np.diff(t)
    gap = np.abs(steps - dt_s) > 0.01 * dt_s
    ubar = 0.5 * (uT[:, 1:] + uT[:, :-1]) if method == "exact" else uT[:, :-1].copy()
    if not timing_mod.is_instant(timing):
        ubar += timing_mod.step_mean_correction(tauT, timing, dt_s)
        if method != "exact":              # explicit: ū_k = u_k, so correct relative to τ_k
            ubar += 0.5 * (tauT[:, 1:] - tauT[:, :-1])
    drive = np.diff(PT, axis=1)
    drive /= np.where(gap, steps, dt_s)
    drive -= ubar                          # d_k = (P_{k+1} − P_k)/Δt_k − ū_k, (n, W−1)
    bounds = np.flatnonzero(gap)
    start = 0                              # r[start] is known
    for stop in [*bounds, W - 1]:          # regular steps start … stop−1, then the gap step stop
        if stop > start and not first_order(a, b, drive, rT, start, stop):
            from scipy.signal import lfilter

            for j in range(n):
                zi = np.array([a[j] * rT[j, start]])
                rT[j, start + 1:stop + 1], _ = lfilter([b[j]], [1.0, -a[j]], drive[j, start:stop], zi=zi)
        if stop < W - 1:                   # the irregular step stop → stop+1
            ag, bg = coefficients(K, steps[stop], method)
            rT[:, stop + 1] = ag * rT[:, stop] + bg * drive[:, stop]
            start = stop + 1
    return rT


def _first_order_py(a, b, drive, out, start, stop):
    """out[j, k+1] = a_j out[j, k] + b_j drive[j, k] for k = start … stop−1 (the observer's
    recursion, in the order ``scipy.signal.lfilter`` evaluates it: b·x first, then + a·y)."""
    for j in range(drive.shape[0]):
        y = out[j, start]
        for k in range(start, stop):
            y = b[j] * drive[j, k] + a[j] * y
            out[j, k + 1] = y


def first_order(a, b, drive, out, start: int, stop: int) -> bool:
    """Run ``_first_order_py`` compiled in place on ``out``; False without numba."""
    k = _LOOPS.get()
    if k is None:
        return False
    k["filter"](a, b, drive, out, start, stop)
    return True


class ObserverRun:
    """The observer over a log fed in chunks, for any model: ``feed(t, q, dq, tau, final)`` → the
    finalized rows as a dict (t, q, dq, tau (T, n), rT (n, T)); rows a group delay still needs the
    future of are held back (``lookahead_rows``) until the next chunk or ``final``. ``terms(q, dq,
    tau)`` → (P, u), each (T, n): the model's momentum and the rest of the momentum balance."""

    def __init__(self, terms, K, dt, method, timing):
        self.terms, self.K, self.dt, self.method, self.timing = terms, K, dt, method, timing
        self.ahead = lookahead_rows(timing, dt)
        self.prev = None                 # (t, P, u, τ, r) of the last finalized row (link-major rows)
        self.pending = None              # held-back raw rows: (t, q, dq, τ)

    @classmethod
    def planar(cls, robot, K, dt, method, timing):
        """On a planar chain (``momentum_terms``)."""
        return cls(lambda q, dq, tau: momentum_terms(robot, q, dq, tau), K, dt, method, timing)

    def feed(self, t, q, dq, tau, final: bool = False):
        if self.pending is not None:
            pt, pq, pdq, ptau = self.pending
            t, q, dq, tau = np.r_[pt, t], np.vstack([pq, q]), np.vstack([pdq, dq]), np.vstack([ptau, tau])
            self.pending = None
        T = len(t)
        keep = 0 if final else min(self.ahead, T)
        if T == 0 or T - keep == 0:
            self.pending = (t, q, dq, tau) if T else None
            return None
        P, u = self.terms(q, dq, tau)
        PT, uT, tauT = P.T, u.T, tau.T
        if self.prev is not None:
            t0, P0, u0, tau0, r0 = self.prev
            tw = np.r_[t0, t]
            PT, uT, tauT = (np.concatenate([x0[:, None], x], axis=1) for x0, x in
                            ((P0, PT), (u0, uT), (tau0, tauT)))
        else:
            tw, r0 = t, np.zeros(self.K.size)
        rT = residual_window(tw, np.ascontiguousarray(PT), np.ascontiguousarray(uT),
                             np.ascontiguousarray(tauT), self.K, self.dt, self.method, self.timing, r0)
        off = 1 if self.prev is not None else 0
        m = T - keep                                            # rows finalized now
        last = off + m - 1
        self.prev = (tw[last], PT[:, last].copy(), uT[:, last].copy(), tauT[:, last].copy(),
                     rT[:, last].copy())
        if keep:
            self.pending = (t[m:], q[m:], dq[m:], tau[m:])
        return {"t": t[:m], "q": q[:m], "dq": dq[:m], "tau": tau[:m],
                "rT": rT[:, off:off + m]}


def lag_s(K: np.ndarray, dt_s: float, method: str = "exact") -> np.ndarray:
    """Delay of r behind τ_ext for a slowly varying τ_ext, per channel: Δt/(1 − a) − Δt/2 (→ 1/K).

    The recurrence r_{k+1} = a r_k + (1 − a) d_k has DC group delay 1/(1 − a) samples, and d_k is the
    mean of τ_ext over [t_k, t_{k+1}], centred half a step later.
    """
    a, b = coefficients(np.asarray(K, float), dt_s, method)
    return dt_s / b - 0.5 * dt_s


class MomentumObserver:
    """Streaming observer: ``step(q, dq, tau_meas)`` → r (n,), one sample at a time.

    The first call initializes P_0 and returns r = 0, as the offline form does. ``timing``: per
    channel 'instant' or 'mean' (estimator.timing); a group delay needs future samples and is
    offline only.
    """

    def __init__(self, robot: Robot, dt_s: float, gain_per_s=100.0, method: str = "exact",
                 timing=None):
        self.robot = full_robot(robot)
        if timing is not None and any(k == "delay" and d > 0 for k, d in timing):
            raise InputError("timing: a group delay needs future samples; the streaming observer "
                             "supports 'instant' and 'mean' only (use the offline estimate)")
        self._mean = None if timing_mod.is_instant(timing) else \
            np.array([k == "mean" for k, _ in timing])
        self.K = gains(self.robot, gain_per_s)
        self.dt_s = float(dt_s)
        self.method = method
        self.a, self.b = coefficients(self.K, self.dt_s, method)
        self._fast = _FastTerms(self.robot)
        self.reset()

    def reset(self):
        self._P = None
        self._u = None
        self._tau = None
        self.r = np.zeros(self.K.size)

    def step(self, q, dq, tau_meas, dt_s: float | None = None) -> np.ndarray:
        tau_meas = np.asarray(tau_meas, float)
        P, u = self._fast(np.asarray(q, float), np.asarray(dq, float), tau_meas)
        if self._P is None:
            self._P, self._u, self._tau = P, u, tau_meas
            return self.r.copy()
        if dt_s is None or abs(dt_s - self.dt_s) <= 0.01 * self.dt_s:
            dt, a, b = self.dt_s, self.a, self.b
        else:
            dt = float(dt_s)
            a, b = coefficients(self.K, dt, self.method)
        ubar = 0.5 * (u + self._u) if self.method == "exact" else self._u
        if self._mean is not None:         # a 'mean' reading at t_{k+1} IS the step mean
            half = 0.5 * (tau_meas - self._tau) if self.method == "exact" else tau_meas - self._tau
            ubar = ubar + np.where(self._mean, half, 0.0)
        d = (P - self._P) / dt - ubar
        self.r = a * self.r + b * d
        self._P, self._u, self._tau = P, u, tau_meas
        return self.r.copy()


class _FastTerms:
    """P = M q̇ and u = τ + Cᵀq̇ − G for ONE sample in plain Python floats (low latency).

    The formulas of ``chain_terms`` (suffix sums over the links), evaluated with ``math``.
    """

    def __init__(self, robot: Robot):
        self.N = robot.n_links
        self.m = [float(v) for v in robot.masses_kg]
        self.l = [float(v) for v in robot.lengths_m]
        self.rc = [float(v) for v in robot.com_m]
        self.rp = [float(v) for v in robot.com_perp_m]
        self.Irot = _irot(robot)
        self.g = float(robot.gravity_m_per_s2)
        self.Gz = self.g * (float(robot.base_mass_kg) + sum(self.m))
        self.msuf = [sum(self.m[j:]) for j in range(self.N)]

    def __call__(self, q, dq, tau):
        import math

        N, m, l, rc, rp = self.N, self.m, self.l, self.rc, self.rp
        ql, dql = q.tolist(), dq.tolist()
        phi, dphi = ql[2], dql[2]
        jx = jz = 0.0
        vjx, vjz = dql[0], dql[1]
        cx, cz, vx, vz, ox, oz, vox, voz = ([0.0] * N for _ in range(8))
        for i in range(N):
            phi += ql[3 + i]
            dphi += dql[3 + i]
            s, c = math.sin(phi), math.cos(phi)
            ox[i], oz[i], vox[i], voz[i] = jx, jz, vjx, vjz
            cx[i], cz[i] = jx + rc[i] * s + rp[i] * c, jz - rc[i] * c + rp[i] * s
            vx[i] = vjx + dphi * (rc[i] * c - rp[i] * s)
            vz[i] = vjz + dphi * (rc[i] * s + rp[i] * c)
            jx, jz = jx + l[i] * s, jz - l[i] * c
            vjx, vjz = vjx + l[i] * dphi * c, vjz + l[i] * dphi * s
        P = (self.Irot @ dq)
        u = np.array(tau, dtype=float)
        u[1] -= self.Gz
        A = Bx = Bz = Gs = 0.0
        Pang = [0.0] * N
        Cang = [0.0] * N
        Gang = [0.0] * N
        for i in range(N - 1, -1, -1):                 # suffix sums over links i … N−1
            A += m[i] * (cx[i] * vz[i] - cz[i] * vx[i])
            Bx += m[i] * vx[i]
            Bz += m[i] * vz[i]
            Gs += m[i] * cx[i]
            Pang[i] = A - (ox[i] * Bz - oz[i] * Bx)
            Cang[i] = -(vox[i] * Bz - voz[i] * Bx)
            Gang[i] = self.g * (Gs - ox[i] * self.msuf[i])
        P[0] += Bx
        P[1] += Bz
        P[2] += Pang[0]
        u[2] += Cang[0] - Gang[0]
        P[3:] += Pang
        u[3:] += np.subtract(Cang, Gang)
        return P, u


_LOOPS = compiled.Loops(lambda: {"terms": compiled.jit(_terms_py),
                                 "filter": compiled.jit(_first_order_py)})
