"""Cramér–Rao bounds of contact localization: how well ANY unbiased estimator can place a contact
with these sensors, per sample and over a held contact.

Per sample. Under a held contact the observer residual is r = J(α)ᵀF + n with n ~ N(0, R), R the
no-contact covariance the detector whitens with (estimator.noise; whatever it contains flows in
here). For one link the mean m(α, F) = J(α)ᵀF has the derivatives (the localization module's row
structure: moment rows θ, q_1…q_c carry (p − o_k) × F, p = p_c + α Δ_c)

    ∂m/∂α = (Δ_c × F) e_c      (e_c: ones on the rows θ, q_1…q_c),      ∂m/∂F = J(α)ᵀ,

so with H = [∂m/∂α, ∂m/∂F_x, ∂m/∂F_z] the Fisher information is I = Hᵀ R⁻¹ H (3 × 3) and the
bound is Cov(α̂, F̂) ⪰ I⁻¹: σ_α ≥ √(I⁻¹)_αα, along the link σ_p ≥ |Δ_c| σ_α. The link is a
discrete parameter (a test between links, the localizer's ambiguity flag), not part of the bound.
The bound grows as 1/|Δ_c × F|: it diverges when the line of action runs along the link.

Over an episode. A contact fixed in the body (α) with the force free per sample, seen through the
observer: r_k = J_k(α)ᵀF_k + n_k, n a filtered (serially correlated) process,
r_{k+1} = A r_k + b (B0 e_{k+1} + B1 e_k) (estimator.noise). Its spectral density at zero
frequency is the long-run covariance

    Ω = Σ_j Cov(n_{k+j}, n_k) = H(1) H(1)ᵀ,  H(1) = diag(b/(1 − a)) (B0 + B1) = B0 + B1

(the observer's DC gain is 1; the M/Δt terms of a joint-rate noise cancel in B0 + B1: a noisy q̇
averages out over an episode, its per-sample effect does not). The constant α is a zero-frequency
signal and the free per-sample forces remove span J_kᵀ at every frequency, so for a contact held
over L ≫ 1/(KΔt) samples the information on α is (Whittle)

    I_ep = Σ_k h_kᵀ Ω⊥_k h_k,   Ω⊥ = Ω⁻¹ − Ω⁻¹Jᵀ(J Ω⁻¹ Jᵀ)⁻¹J Ω⁻¹,   h_k = (Δ × F_k) e_c,

the episode bound σ_α ≥ I_ep^(−1/2): the per-sample Schur complement with R replaced by Ω, summed.
White torque/FT noise alone gives R = Ω b/2 (instantaneous readings; b = 1 − a ≈ KΔt), so an
episode of L samples carries L·KΔt/2 independent samples' worth (0.5 s at K = 100/s, 1 kHz: 25).
``tests/test_bounds.py`` checks I against finite differences, the per-sample bound against a
Monte Carlo of the estimator, and I_ep against the exact finite-L information of the correlated
Gaussian model (dense covariance).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator import dynamics as dyn
from userio.errors import InputError


@dataclass
class Bound:
    """Per-sample Cramér–Rao bound (arrays (B,)): 1σ of α, along the link (m), and of F (N)."""

    alpha_std: np.ndarray
    position_std_m: np.ndarray
    force_std_N: np.ndarray          # (B, 2): σ of F_x, F_z
    information: np.ndarray          # (B, 3, 3) Fisher information of (α, F_x, F_z)


def design(robot, q, link: int, alpha, force_N):
    """H = ∂(J(α)ᵀF)/∂(α, F_x, F_z), (B, n, 3), and the link length |Δ_c| (B,), at postures q
    (B, n) in floating coordinates (module doc)."""
    full = robot if robot.floating else robot.with_base(True)
    q = np.atleast_2d(np.asarray(q, float))
    B, n = q.shape
    if not 1 <= int(link) <= full.n_links:
        raise InputError(f"bound: link must be 1…{full.n_links}, got {link}")
    F = np.broadcast_to(np.asarray(force_N, float), (B, 2))
    J = dyn.point_jacobian(full, q, int(link), np.broadcast_to(np.asarray(alpha, float), (B,)))
    joints, _ = dyn.forward_kinematics(full, q)
    D = joints[:, link] - joints[:, link - 1]
    H = np.zeros((B, n, 3))
    H[:, :, 1:] = np.swapaxes(J, 1, 2)
    H[:, 2:3 + int(link), 0] = (D[:, 0] * F[:, 1] - D[:, 1] * F[:, 0])[:, None]
    return H, np.hypot(D[:, 0], D[:, 1])


def design_fast(robot, q, link: int, alpha, force_N):
    """``design`` from the joint positions directly (the localization's row structure: rows x, z
    carry F; moment row m ∈ {θ, q_1…q_c} with origin o_m carries (p − o_m) × F and, for ∂/∂α,
    Δ × F): the same H, (B, n, 3), for the many samples of a log."""
    from estimator.localization import _joints_link_major

    full = robot if robot.floating else robot.with_base(True)
    q = np.atleast_2d(np.asarray(q, float))
    B, n = q.shape
    c = int(link)
    jx, jz = _joints_link_major(full, q)
    F = np.broadcast_to(np.asarray(force_N, float), (B, 2))
    a = np.broadcast_to(np.asarray(alpha, float), (B,))
    dx, dz = jx[c] - jx[c - 1], jz[c] - jz[c - 1]
    px, pz = jx[c - 1] + a * dx, jz[c - 1] + a * dz
    org = np.r_[0, 0:c]
    H = np.zeros((B, n, 3))
    H[:, 0, 1] = 1.0
    H[:, 1, 2] = 1.0
    H[:, 2:3 + c, 0] = (dx * F[:, 1] - dz * F[:, 0])[:, None]
    H[:, 2:3 + c, 1] = -(pz[None] - jz[org]).T
    H[:, 2:3 + c, 2] = (px[None] - jx[org]).T
    return H


def fisher(H: np.ndarray, R: np.ndarray) -> np.ndarray:
    """I = Hᵀ R⁻¹ H for H (B, n, p) and R (n, n) or (B, n, n)."""
    return np.swapaxes(H, -1, -2) @ np.linalg.solve(np.broadcast_to(R, H.shape[:-2] + R.shape[-2:]), H)


def profiled(I: np.ndarray) -> np.ndarray:
    """The information on α with F unknown: the Schur complement I_αα − I_αF I_FF⁻¹ I_Fα, (B,)."""
    IFF = I[..., 1:, 1:]
    IFa = I[..., 1:, 0]
    return I[..., 0, 0] - np.einsum("...i,...i->...", IFa, np.linalg.solve(IFF, IFa[..., None])[..., 0])


def per_sample(robot, q, link: int, alpha, force_N, R) -> Bound:
    """The per-sample bound of (α, F) at postures q (B, n), contact (link, α, F), covariance R."""
    H, length = design(robot, q, link, alpha, force_N)
    I = fisher(H, np.asarray(R, float))
    with np.errstate(divide="ignore", invalid="ignore"):
        det = np.linalg.det(I)
        ok = np.isfinite(det) & (np.abs(det) > 0)
        C = np.full(I.shape, np.inf)
        if ok.any():
            C[ok] = np.linalg.inv(I[ok])
        a_std = np.sqrt(np.where(ok, C[:, 0, 0], np.inf))
    return Bound(alpha_std=a_std, position_std_m=a_std * length,
                 force_std_N=np.sqrt(np.where(ok[:, None], np.stack([C[:, 1, 1], C[:, 2, 2]], -1), np.inf)),
                 information=I)


def episode_information(robot, q, link: int, alpha, force_N, Omega) -> np.ndarray:
    """Each sample's share h_kᵀ Ω⊥ h_k of the episode information on α (module doc), (B,);
    force_N (B, 2) the (filtered) force at each sample, Omega the long-run covariance."""
    H, _ = design(robot, q, link, alpha, force_N)
    return profiled(fisher(H, np.asarray(Omega, float)))


def episode_bound(robot, q, link: int, alpha, force_N, Omega) -> tuple[float, float]:
    """(σ_α, σ along the link in m) of the episode bound over the samples given (module doc)."""
    info = float(np.sum(episode_information(robot, q, link, alpha, force_N, Omega)))
    _, length = design(robot, np.atleast_2d(q)[:1], link, alpha if np.ndim(alpha) == 0 else
                       np.asarray(alpha)[:1], np.atleast_2d(force_N)[:1])
    s = 1.0 / np.sqrt(info) if info > 0 else float("inf")
    return s, s * float(length[0])


# ----------------------------------------------------------------------------- the residual's noise
@dataclass
class ResidualNoise:
    """The no-contact residual's second moments, (B, n, n) per posture (block): the residual's
    covariance R, and its drive's x_k = (r_k − A r_{k−1})/b = d_{k−1} lag-zero and lag-one
    covariances S0 = Cov x_k, S1 = Cov(x_k, x_{k−1}); a, b (n,) the observer's coefficients."""

    R: np.ndarray
    S0: np.ndarray
    S1: np.ndarray
    a: np.ndarray
    b: np.ndarray

    @property
    def G1(self) -> np.ndarray:
        """Γ₁ = Cov(r_{k+1}, r_k) = A R + diag(b) S1 diag(b)."""
        return self.a[:, None] * self.R + np.outer(self.b, self.b) * self.S1

    @property
    def Omega(self) -> np.ndarray:
        """The long-run covariance Ω = S0 + S1 + S1ᵀ (of the drive and of the residual)."""
        return self.S0 + self.S1 + np.swapaxes(self.S1, -1, -2)

    def with_R(self, R) -> "ResidualNoise":
        """The same drive with another residual covariance (the detector's, e.g. from a quiet
        window or with model-uncertainty terms)."""
        return ResidualNoise(np.broadcast_to(R, self.S0.shape).copy(), self.S0, self.S1, self.a, self.b)


def noise_terms(robot, q, dq, noise, gain_per_s, dt_s: float, timing=None) -> ResidualNoise:
    """The ``ResidualNoise`` of the sensor noise model at B postures (estimator.noise: a, b, B0,
    B1): S0 = B0B0ᵀ + B1B1ᵀ, S1 = B1B0ᵀ, R from the closed-form Lyapunov solution. Its long-run
    covariance Ω = (B0 + B1)(B0 + B1)ᵀ (module doc)."""
    from estimator.noise import filter_terms

    a, b, B0, B1 = filter_terms(robot, q, dq, noise, gain_per_s, dt_s, timing)
    S0 = B0 @ B0.transpose(0, 2, 1) + B1 @ B1.transpose(0, 2, 1)
    S1 = B1 @ B0.transpose(0, 2, 1)
    R = np.outer(b, b) * (S0 + S1 * a[None, None, :] + S1.transpose(0, 2, 1) * a[None, :, None]) \
        / (1.0 - np.outer(a, a))
    return ResidualNoise(R, S0, S1, a, b)


def sample_terms(r: np.ndarray, R: np.ndarray, a: np.ndarray) -> ResidualNoise:
    """The ``ResidualNoise`` of a contact-free stretch of residual r (T, n) with covariance R (the
    detector's robust estimate): the drive x_k = (r_k − a r_{k−1})/b and its lag-zero and lag-one
    covariances (white sensors make x a moving average of order one: lags ≤ 1 hold all of it).
    Ω's eigenvalues are floored at 1e-6 of the largest (S0 raised to match)."""
    r = np.asarray(r, float)
    a = np.asarray(a, float)
    b = 1.0 - a
    x = (r[1:] - a * r[:-1]) / b
    x = x - x.mean(axis=0)
    S0 = x.T @ x / len(x)
    S1 = x[1:].T @ x[:-1] / len(x)
    Om = S0 + S1 + S1.T
    w, V = np.linalg.eigh(0.5 * (Om + Om.T))
    floor = np.maximum(w, 1e-6 * w.max()) - w
    S0 = 0.5 * (S0 + S0.T) + (V * floor) @ V.T
    return ResidualNoise(np.asarray(R, float)[None], S0[None], S1[None], a, b)


# ----------------------------------------------------------------------------- compiled, per sample
def _alpha_bound_loop(q, link, alpha, F, Rinv, ui, lengths, out):
    """out[k] = (I⁻¹)_αα of sample k (``per_sample_alpha_var``), one loop (compiled with numba)."""
    T, n = q.shape
    N = n - 3
    jx = np.empty(N + 1)
    jz = np.empty(N + 1)
    H = np.empty((n, 3))
    RH = np.empty((n, 3))
    for k in range(T):
        c = link[k]
        phi = q[k, 2]
        jx[0] = 0.0
        jz[0] = 0.0
        for i in range(N):
            phi += q[k, 3 + i]
            jx[i + 1] = jx[i] + lengths[i] * np.sin(phi)
            jz[i + 1] = jz[i] - lengths[i] * np.cos(phi)
        dx = jx[c] - jx[c - 1]
        dz = jz[c] - jz[c - 1]
        px = jx[c - 1] + alpha[k] * dx
        pz = jz[c - 1] + alpha[k] * dz
        g = dx * F[k, 1] - dz * F[k, 0]
        for i in range(n):
            H[i, 0] = 0.0
            H[i, 1] = 0.0
            H[i, 2] = 0.0
        H[0, 1] = 1.0
        H[1, 2] = 1.0
        for m in range(2, 3 + c):
            o = m - 3 if m > 3 else 0
            H[m, 0] = g
            H[m, 1] = -(pz - jz[o])
            H[m, 2] = px - jx[o]
        Rk = Rinv[ui[k]]
        for i in range(n):
            for j in range(3):
                acc = 0.0
                for m in range(n):
                    acc += Rk[i, m] * H[m, j]
                RH[i, j] = acc
        I00 = I01 = I02 = I11 = I12 = I22 = 0.0
        for i in range(n):
            I00 += H[i, 0] * RH[i, 0]
            I01 += H[i, 0] * RH[i, 1]
            I02 += H[i, 0] * RH[i, 2]
            I11 += H[i, 1] * RH[i, 1]
            I12 += H[i, 1] * RH[i, 2]
            I22 += H[i, 2] * RH[i, 2]
        det = I11 * I22 - I12 * I12
        prof = I00 - (I01 * (I22 * I01 - I12 * I02) + I02 * (I11 * I02 - I12 * I01)) / det
        out[k] = 1.0 / prof if prof > 0 else np.nan


_BOUND_LOOP = None


def per_sample_alpha_var(robot, q, link, alpha, force_N, Rinv, ui) -> np.ndarray:
    """The per-sample bound² of α, (I⁻¹)_αα, for samples with their own link (T,), α, F (T, 2) at
    postures q (T, n), sample k's inverse covariance Rinv[ui[k]]: one compiled loop (numba), or the
    numpy form (``design_fast``, ``fisher``, ``profiled``) without it."""
    from estimator import compiled

    full = robot if robot.floating else robot.with_base(True)
    q = np.ascontiguousarray(q, float)
    link = np.asarray(link, np.int64)
    out = np.full(len(q), np.nan)
    if compiled.available():
        global _BOUND_LOOP
        if _BOUND_LOOP is None:
            from numba import njit

            _BOUND_LOOP = njit(cache=True, nogil=True, error_model="numpy")(_alpha_bound_loop)
        _BOUND_LOOP(q, link, np.ascontiguousarray(alpha, float), np.ascontiguousarray(force_N, float),
                    np.ascontiguousarray(Rinv, float), np.asarray(ui, np.int64),
                    np.asarray(full.lengths_m, float), out)
        return out
    for c in np.unique(link):
        m = np.flatnonzero(link == c)
        H = design_fast(full, q[m], int(c), np.asarray(alpha)[m], np.asarray(force_N)[m])
        with np.errstate(all="ignore"):
            prof = profiled(np.swapaxes(H, 1, 2) @ Rinv[np.asarray(ui)[m]] @ H)
        out[m] = np.where(prof > 0, 1.0 / prof, np.nan)
    return out
