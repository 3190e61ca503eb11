"""Excitation trajectories for identification: a few Fourier harmonics per joint, chosen so that
the identification's regressor is well conditioned within the joints' ranges.

    q_j(t) = q0_j + Σ_h A_jh sin(2π h f₀ t + φ_jh),     h = 1 … H

(periodic in 1/f₀; the controller's multi-harmonic reference, estimator.sim.config.Controller).
Quality of a trajectory: the windowed momentum equations of estimator.identification evaluated on
the reference itself (perfect tracking, base held: every row of M q̈ + C q̇ + G = τ_meas, the
base rows being the FT wrench), whitened by the sensor noise and scaled by the prior σ of each
parameter: information I = Σ_w A_wᵀ C_w⁻¹ A_w in prior units. ``condition_number`` is
√(λ_max/λ_min) over its ``rank`` largest eigenvalues (the directions a held base can identify);
``design`` minimizes it (Nelder–Mead on amplitudes and phases from a seeded start) with a penalty
outside the joint ranges and above a joint-rate limit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Fourier:
    """q0 (N,), amplitudes, frequencies (Hz) and phases (N, H): q_j = q0_j + Σ_h A sin(2π f t + φ)."""

    q0: np.ndarray
    amplitude_rad: np.ndarray
    phase_rad: np.ndarray
    frequency_Hz: np.ndarray

    @classmethod
    def harmonic(cls, q0, amplitude_rad, phase_rad, base_Hz: float) -> "Fourier":
        A = np.atleast_2d(np.asarray(amplitude_rad, float))
        f = np.broadcast_to(base_Hz * np.arange(1, A.shape[1] + 1), A.shape).copy()
        return cls(np.asarray(q0, float), A, np.atleast_2d(np.asarray(phase_rad, float)), f)

    @classmethod
    def from_controller(cls, controller) -> "Fourier":
        """The reference of a scene's controller (estimator.sim.config.Controller)."""
        A, f, ph = controller.harmonics()
        return cls(np.asarray(controller.q0_rad, float), A, ph, f)

    def evaluate(self, t):
        """(q, q̇, q̈) (T, N) at times t."""
        t = np.asarray(t, float)[:, None, None]
        w = 2 * np.pi * self.frequency_Hz
        arg = w * t + self.phase_rad
        A = self.amplitude_rad
        return (self.q0 + np.sum(A * np.sin(arg), axis=2), np.sum(A * w * np.cos(arg), axis=2),
                -np.sum(A * w * w * np.sin(arg), axis=2))


def information(model, traj: Fourier, duration_s: float, noise, prior_cov, rate_Hz: float = 200.0,
                window_s: float = 0.02) -> np.ndarray:
    """Prior-scaled information (k, k) of the identification equations along the reference
    (base held at the origin), sampled at ``rate_Hz`` (module doc)."""
    from estimator.identification import window_equations
    from estimator import dynamics as dyn

    t = np.arange(int(duration_s * rate_Hz) + 1) / rate_Hz
    qj, dqj, ddqj = traj.evaluate(t)
    T, N = qj.shape
    z = np.zeros((T, 3))
    q, dq, ddq = (np.concatenate([z, x], axis=1) for x in (qj, dqj, ddqj))
    full = model.with_base(True) if hasattr(model, "with_base") else model
    M = dyn.mass_matrix(full, q)
    C = dyn.coriolis_matrix(full, q, dq)
    tau = np.einsum("tkl,tl->tk", M, ddq) + np.einsum("tkl,tl->tk", C, dq) + dyn.gravity_vector(full, q)
    eq = window_equations(model, t, q, dq, tau, noise, None, window_s)
    Linv = np.linalg.inv(np.linalg.cholesky(eq.C))
    A = np.einsum("wij,wjk->wik", Linv, eq.A).reshape(-1, eq.A.shape[2])
    L0 = np.linalg.cholesky(prior_cov)
    return L0.T @ (A.T @ A) @ L0


def condition_number(info: np.ndarray, rank: int) -> float:
    """√(λ_max/λ_min) over the ``rank`` largest eigenvalues."""
    lam = np.sort(np.linalg.eigvalsh(info))[::-1][:rank]
    return float(np.sqrt(lam[0] / lam[-1])) if lam[-1] > 0 else float("inf")


def structural_rank(info: np.ndarray, rtol: float = 1e-8) -> int:
    lam = np.linalg.eigvalsh(info)
    return int(np.sum(lam > rtol * lam.max()))


def design(model, q_lo, q_hi, *, harmonics: int = 4, base_Hz: float = 0.1, duration_s: float = 10.0,
           max_rate_rad_per_s: float = 3.0, noise=None, prior_cov=None, seed: int = 0,
           iterations: int = 600) -> tuple[Fourier, float]:
    """A Fourier trajectory inside [q_lo, q_hi] (per joint) with joint rates ≤ max_rate that
    minimizes the condition number (module doc); returns (trajectory, condition number)."""
    from scipy.optimize import minimize

    from estimator.model import ModelUncertainty
    from estimator.noise import paper_leg_noise

    q_lo, q_hi = np.asarray(q_lo, float), np.asarray(q_hi, float)
    N, H = q_lo.size, int(harmonics)
    q0 = 0.5 * (q_lo + q_hi)
    half = 0.5 * (q_hi - q_lo)
    noise = noise or paper_leg_noise()
    prior_cov = prior_cov if prior_cov is not None else \
        model.parameter_covariance(ModelUncertainty.uniform(0.3))
    rank = structural_rank(information(model, _start(q0, half, H, base_Hz, seed), duration_s,
                                       noise, prior_cov))
    t = np.linspace(0, 1.0 / base_Hz, 400)

    def unpack(x):
        A = x[:N * H].reshape(N, H)
        return Fourier.harmonic(q0, A, x[N * H:].reshape(N, H), base_Hz)

    def cost(x):
        tr = unpack(x)
        q, dq, _ = tr.evaluate(t)
        over = np.maximum(q - q_hi, 0).max() + np.maximum(q_lo - q, 0).max()
        fast = np.maximum(np.abs(dq).max() - max_rate_rad_per_s, 0)
        c = condition_number(information(model, tr, duration_s, noise, prior_cov), rank)
        return np.log(c) + 100.0 * (over + fast)

    x0 = np.concatenate([_start(q0, half, H, base_Hz, seed).amplitude_rad.ravel(),
                         _start(q0, half, H, base_Hz, seed).phase_rad.ravel()])
    out = minimize(cost, x0, method="Nelder-Mead",
                   options={"maxiter": iterations, "xatol": 1e-4, "fatol": 1e-6, "adaptive": True})
    best = unpack(out.x)
    return best, condition_number(information(model, best, duration_s, noise, prior_cov), rank)


def _start(q0, half, H, base_Hz, seed) -> Fourier:
    """A seeded start: amplitudes 1/h of a third of the half-range, random phases."""
    rng = np.random.default_rng(seed)
    N = q0.size
    A = (half / 3.0)[:, None] / np.arange(1, H + 1)[None, :]
    return Fourier.harmonic(q0, A, rng.uniform(0, 2 * np.pi, (N, H)), base_Hz)
