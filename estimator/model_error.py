"""The residual's model-error covariance: what an uncertain robot file adds to the detector.

The observer (estimator.observer) filters d_k = (P_{k+1} − P_k)/Δt − ū_k. With the file's
parameters θ_m and the robot's θ (estimator.model: P = Y_P θ, u − τ = Y_u θ), a contact-free
residual is r_k = Φ_k (θ_m − θ) + noise, where Φ is the regressor of the drive,
D_k = ΔY_P/Δt − Ȳ_u, through the observer's own recursion (per row, the same a, b, steps and
quadrature): Φ_{k+1} = a ∘ Φ_k + b ∘ D_k, Φ_0 = 0. For θ_m − θ ~ N(0, Σ_θ) (an identification's
posterior, or a declared uncertainty)

    R_k = R_noise + Φ_k Σ_θ Φ_kᵀ = R_noise + G_k G_kᵀ,     G_k = Φ_k S,  Σ_θ = S Sᵀ,

which depends on the posture, the velocity and (through ΔY_P) the acceleration, sample by sample.
The chi-square detector keeps its structure (s_k = r_kᵀ R_k⁻¹ r_k against χ²_n at the stated
rate); only R_k changes. Per sample: the regressor, its (n × n_θ) filter, the product Φ S (S
triangular) and an n × n Cholesky, in one compiled loop (estimator.model_kernels ``model_chi2``; the
numpy form below is its reference).
"""

from __future__ import annotations

import numpy as np

from estimator import observer
from userio.errors import InputError


def covariance_sqrt(cov: np.ndarray, rtol: float = 1e-12):
    """(S, triangular): S Sᵀ = Σ — its Cholesky factor when Σ is positive definite, else the
    eigenvectors with eigenvalues above rtol × the largest, scaled (k, r)."""
    cov = 0.5 * (np.asarray(cov, float) + np.asarray(cov, float).T)
    try:
        return np.linalg.cholesky(cov), True
    except np.linalg.LinAlgError:
        pass
    lam, V = np.linalg.eigh(cov)
    keep = lam > rtol * max(lam.max(), 0.0)
    if not np.any(keep):
        return np.zeros((cov.shape[0], 0)), False
    return V[:, keep] * np.sqrt(lam[keep]), False


def resolve(robot, model_uncertainty=None):
    """(Σ_θ or None, source) for the estimator: ``False`` → none; a ``ModelUncertainty`` → its
    covariance on this robot (the option wins); an array → itself; None → what the robot file
    states (``model_covariance``: its identification, else its declared uncertainty)."""
    from estimator.model import ModelUncertainty

    if model_uncertainty is False:
        return None, "none (disabled)"
    if isinstance(model_uncertainty, ModelUncertainty):
        return robot.parameter_covariance(model_uncertainty), \
            f"option: {model_uncertainty.describe()}"
    if model_uncertainty is not None:
        cov = np.asarray(model_uncertainty, float)
        k = len(robot.parameter_names)
        if cov.shape != (k, k) or not np.all(np.isfinite(cov)):
            raise InputError(f"model covariance: expected a finite {k} × {k} matrix, got {cov.shape}")
        return cov, "given covariance"
    get = getattr(robot, "model_covariance", None)
    return get() if get is not None else (None, "the robot model states no uncertainty")


SUB_BLOCK = 1024                 # samples per compiled call: the regressor's arrays (100 kB) stay in cache


class ModelTerm:
    """The model-error term over consecutive chunks of one log (Φ carried across chunks):
    ``statistic(t, q, q̇, rT, Rn, blk)`` → (s_k, G_k = Φ_k S) (module doc)."""

    def __init__(self, robot, cov, gain_per_s, dt_s: float, method: str = "exact"):
        self.robot = robot
        S, self.tri = covariance_sqrt(cov)
        self.S = np.ascontiguousarray(S)
        K = np.asarray(gain_per_s, float)            # one gain per observer row (n_v of the model)
        self.K = np.broadcast_to(K, (robot.n_v,)).copy() if K.ndim == 0 else K.copy()
        if self.K.shape != (robot.n_v,) or not np.all(self.K > 0):
            raise InputError(f"gain: expected a scalar or {robot.n_v} values > 0, got {K.tolist()}")
        self.dt, self.method = float(dt_s), method
        self.a, self.b = observer.coefficients(self.K, self.dt, method)
        self.n, self.k, self.r = self.K.size, self.S.shape[0], self.S.shape[1]
        self.prev = None                 # (t, Y_P, Y_u, Φ) of the last sample
        self.pattern = self._pattern()
        # a model with a compiled regressor runs it fused with the loop (the planar chain)
        self.fused = getattr(robot, "fused_model_chi2", None)
        self._bufs = None

    def _pattern(self):
        """The regressor's structurally nonzero (row, column) entries, for the compiled loop:
        nonzero at any of 16 random states (an entry not identically zero is almost surely
        nonzero there); Φ stays zero where Y is."""
        rng = np.random.default_rng(0)
        qs = rng.uniform(-np.pi, np.pi, (16, getattr(self.robot, "n_q", self.n)))   # URDF: + quaternion
        vs = rng.normal(0.0, 2.0, (16, self.n))
        YP, Yu = self.robot.momentum_regressor(qs, vs)
        live = np.any((YP != 0) | (Yu != 0), axis=0)                  # (n, k)
        act_ptr = np.r_[0, np.cumsum(live.sum(axis=1))].astype(np.int64)
        act = np.concatenate([np.flatnonzero(row) for row in live]).astype(np.int64)
        ncol = (np.minimum(np.arange(self.k) + 1, self.r) if self.tri else
                np.full(self.k, self.r)).astype(np.int64)
        return act_ptr, act, self.S, ncol

    def statistic(self, t, q, dq, rT, Rn, blk):
        """(s (T,), G (T, n, r)) for the next samples: s_k = r_kᵀ (Rn[blk_k] + G_k G_kᵀ)⁻¹ r_k."""
        from estimator import model_kernels

        t = np.ascontiguousarray(t, float)
        T = len(t)
        stat, G = np.empty(T), np.empty((T, self.n, self.r))
        Rn = np.ascontiguousarray(Rn, float)
        blk = np.ascontiguousarray(blk, np.int64)
        if self.fused is not None and T:
            has = self.prev is not None
            tp, PP, PU, PF = self.prev if has else (0.0, *(np.zeros((self.n, self.k)) for _ in range(3)))
            if self._bufs is None:
                from estimator.model_kernels import FUSED_BLOCK

                self._bufs = tuple(np.zeros((FUSED_BLOCK, self.n, self.k)) for _ in range(2))
            if self.fused(q, dq, self._bufs, self.pattern, self.a, self.b, self.K, t, self.dt,
                          self.method == "exact", has, tp, PP, PU, PF, np.ascontiguousarray(rT),
                          Rn, blk, G, stat):
                self.prev = (float(t[-1]), PP, PU, PF)
                return stat, G
        for s0 in range(0, T, SUB_BLOCK):
            sl = slice(s0, min(T, s0 + SUB_BLOCK))
            YP, Yu = self.robot.momentum_regressor(q[sl], dq[sl])
            has = self.prev is not None
            tp, PP, PU, PF = self.prev if has else (0.0, *(np.zeros((self.n, self.k)) for _ in range(3)))
            if not model_kernels.model_chi2(np.ascontiguousarray(YP), np.ascontiguousarray(Yu), self.pattern,
                                      self.a, self.b, self.K, t[sl], self.dt,
                                      self.method == "exact", has, tp, PP, PU, PF,
                                      np.ascontiguousarray(rT[:, sl]), Rn, blk[sl], G[sl], stat[sl]):
                G[sl], (PP, PU, PF) = self._phi_numpy(t[sl], YP, Yu, has, tp, PP, PU, PF)
                stat[sl] = statistic_numpy(rT[:, sl], G[sl], Rn, blk[sl])
            self.prev = (float(t[sl][-1]), PP, PU, PF)
        return stat, G

    def _phi_numpy(self, t, YP, Yu, has, tp, PP, PU, PF):
        """G = Φ S with Φ from the observer's own ``residual_window`` on the n·k channels of the
        regressor (the numpy form of model_kernels._model_chi2_py's recursion)."""
        n, k = self.n, self.k
        if has:
            tw = np.r_[tp, t]
            YPw, Yuw = np.concatenate([PP[None], YP]), np.concatenate([PU[None], Yu])
            r0 = PF.ravel()
        else:
            tw, YPw, Yuw, r0 = t, YP, Yu, np.zeros(n * k)
        out = observer.residual_window(tw, np.ascontiguousarray(YPw.reshape(len(tw), -1).T),
                                       np.ascontiguousarray(Yuw.reshape(len(tw), -1).T), None,
                                       np.repeat(self.K, k), self.dt, self.method, None, r0)
        phi = out.T.reshape(len(tw), n, k)[1 if has else 0:]
        return phi @ self.S, (YP[-1].copy(), Yu[-1].copy(), phi[-1].copy())


def statistic_numpy(rT, G, Rn, blk) -> np.ndarray:
    """s_k = r_kᵀ (Rn[blk_k] + G_k G_kᵀ)⁻¹ r_k with numpy's batched Cholesky."""
    R = Rn[blk] + np.einsum("tic,tjc->tij", G, G)
    L = np.linalg.cholesky(R)
    z = np.linalg.solve(L, np.asarray(rT).T[..., None])[..., 0]
    return np.einsum("ti,ti->t", z, z)
