"""Sensor uncertainty → contact-localization error, before the robot exists (the workbench's third job).

A static contact (link c, α, F) on a leg held at posture q loads the sensors with

    τ_true = G_joint − J_jointᵀ F,     W_true = G_base − J_baseᵀ F          (estimator.sim.static)

and the estimator sees r = G − τ_meas on all rows (the observer residual once settled). Each
sensor reads τ_meas,k = (1 + g_k) τ_true,k + n_k:

- n_k: white noise of std σ_k per sample (bridge/ADC chain, FT sensor). The exact observer
  r_{j+1} = a r_j + (1 − a) d_j (a = e^{−KΔt}) drives with ū_j = (u_j + u_{j+1})/2, so the noise
  input is (n_j + n_{j+1})/2 and its impulse response c = [1, (1 + a), (1 + a) a, …]·(1 − a)/2
  gives  Var r = σ² (1 − a)²/4 · Σ c_k² = σ² (1 − a)/2  ≈ σ² KΔt/2.
  The ``paper`` method uses the raw readings: no filtering (factor 1).
- g_k: a calibration gain error (relative slope uncertainty, systematic): it scales the whole
  reading, gravity load included, and is not filtered.
- δθ: the robot file's inertial-parameter error (systematic, ``parameter_cov`` Σ_θ: an
  identification's posterior or a declared uncertainty; estimator.model): the estimator computes
  G from the file, so the settled residual gains G(θ_file) − G(θ) = −Y_u(q, 0) δθ
  (estimator.model: Cᵀv − G = Y_u θ), δθ ~ N(0, Σ_θ), drawn once per robot (per draw).

Two independent propagations of (g, n) into (α, F) and the contact point p = p_c + α Δ_c:

- ``first_order``: Σ_out = J Σ_in Jᵀ, J = ∂(α, F_x, F_z)/∂r by central differences through the
  localizer itself (one vectorized call for every posture and perturbation);
- ``monte_carlo``: D draws of (g, n) per posture, localized in one vectorized call.
Both are vectorized over postures. They agree where the localizer is smooth (α inside (0, 1),
force well off the link axis); near the flagged singularities only Monte Carlo is meaningful.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from estimator import dynamics as dyn
from estimator import localization as loc
from userio.errors import InputError
from estimator.observer import coefficients
from estimator.robot import Robot
from estimator.sim.static import static_readings

METHODS = ("dynamic", "paper")


AMBIGUITY_N_SIGMA = 2.0      # cost gap (in residual-noise norms) under which two fits tie


@dataclass(frozen=True)
class SensorNoise:
    """The sensors' errors. Arrays: per joint (N,) or per base axis (3,)."""

    torque_std_Nm: np.ndarray            # white noise per sample of each joint torque sensor
    wrench_std: np.ndarray               # [σ_Fx N, σ_Fz N, σ_My N·m] per sample (Table II: 0.1, 0.1, 0.01)
    torque_gain_rel_std: np.ndarray      # calibration slope uncertainty, relative (systematic)
    sample_rate_Hz: float = 1000.0
    gain_per_s: float = 100.0            # observer gain K (dynamic method)

    def __post_init__(self):
        for name in ("torque_std_Nm", "wrench_std", "torque_gain_rel_std"):
            value = np.atleast_1d(np.asarray(getattr(self, name), float))
            if not np.all(np.isfinite(value)) or np.any(value < 0):
                raise InputError(f"sensor noise: {name} must be finite and ≥ 0, got {value.tolist()}")
            object.__setattr__(self, name, value)
        if self.wrench_std.shape != (3,):
            raise InputError(f"sensor noise: wrench_std needs 3 values [Fx, Fz, My], got {self.wrench_std.size}")
        if not (self.sample_rate_Hz > 0 and self.gain_per_s > 0):
            raise InputError("sensor noise: sample_rate_Hz and gain_per_s must be > 0")

    def filter_factor(self, method: str) -> float:
        """Residual-noise std per unit reading-noise std: √((1 − a)/2) for the observer, 1 raw."""
        if method == "paper":
            return 1.0
        a, _ = coefficients(np.array([self.gain_per_s]), 1.0 / self.sample_rate_Hz, "exact")
        return float(np.sqrt((1.0 - a[0]) / 2.0))

    def ambiguity_tol(self, n_links: int, method: str = "dynamic", n_sigma: float = AMBIGUITY_N_SIGMA) -> float:
        """Cost gap below which two candidate contacts are indistinguishable: n_σ · ‖f σ_n‖, the
        norm of the residual's noise (f: filter factor), floored at 1e-9 for a noise-free model."""
        sig_n, _ = self.per_row(n_links)
        return max(1e-9, n_sigma * self.filter_factor(method) * float(np.linalg.norm(sig_n)))

    def per_row(self, n_links: int):
        """(σ_noise (n,), σ_gain (n,)) on the rows [x, z, θ, q_1…q_N]."""
        tau = np.broadcast_to(self.torque_std_Nm, (n_links,))
        gain = np.broadcast_to(self.torque_gain_rel_std, (n_links,))
        return np.concatenate([self.wrench_std, tau]), np.concatenate([np.zeros(3), gain])


@dataclass
class Propagation:
    """Per-posture error figures (arrays of shape (B,)); lengths in m, forces in N."""

    alpha_std: np.ndarray
    position_rms_m: np.ndarray
    force_rms_N: np.ndarray
    flagged_fraction: np.ndarray       # share of draws the localizer refused (NaN α); 0 for first order
    position_p95_m: np.ndarray | None = None
    position_rms_se_m: np.ndarray | None = None    # Monte Carlo standard error (1σ) of position_rms_m
    position_p95_se_m: np.ndarray | None = None    # Monte Carlo standard error (1σ) of position_p95_m


def percentile_standard_error(x: np.ndarray, p: float = 95.0) -> np.ndarray:
    """1σ sampling error of the p-th percentile of each row (NaNs dropped), distribution-free.

    The order statistic at rank N·p has a binomial rank spread √(N p (1−p)); half the distance
    between the order statistics at ranks N p ∓ √(N p (1−p)) is its standard error
    (≈ √(p(1−p)/N)/f(x_p)); NaN with fewer than 20 finite draws.
    """
    x = np.sort(np.atleast_2d(x), axis=1)            # NaNs sort last
    n = np.sum(np.isfinite(x), axis=1)
    pf = p / 100.0
    spread = np.sqrt(n * pf * (1 - pf))
    lo = np.clip(np.floor(n * pf - spread), 0, np.maximum(n - 1, 0)).astype(int)
    hi = np.clip(np.ceil(n * pf + spread), 0, np.maximum(n - 1, 0)).astype(int)
    se = 0.5 * (np.take_along_axis(x, hi[:, None], 1) - np.take_along_axis(x, lo[:, None], 1))[:, 0]
    return np.where(n >= 20, se, np.nan)


def _check(robot: Robot, q_joint, link, alpha, force_N):
    q_joint = np.atleast_2d(np.asarray(q_joint, float))
    B, N = q_joint.shape
    if N != robot.n_links:
        raise InputError(f"posture: {N} joint angles for a robot with {robot.n_links} links")
    link = np.broadcast_to(np.asarray(link, int), (B,))
    if np.any((link < 1) | (link > N)):
        raise InputError(f"contact link must be in 1…{N}")
    alpha = np.broadcast_to(np.asarray(alpha, float), (B,))
    force = np.broadcast_to(np.asarray(force_N, float), (B, 2))
    return q_joint, link, alpha, force


def _fit_weights(noise: SensorNoise, n_links: int, method: str):
    """The estimator's fit weights: the inverse of the residual's white-noise variance per row
    (estimator.stream whitens by its noise covariance R; white sensor noise makes R diagonal,
    (f σ)²), or None (unweighted) where a σ is zero or for the paper method."""
    sig_n, _ = noise.per_row(n_links)
    if method != "dynamic" or not np.all(sig_n > 0):
        return None
    return 1.0 / (noise.filter_factor(method) * sig_n) ** 2


def _localize(robot, method, q, r, link, ambiguity_tol=1e-3, weights=None):
    """(α, F) from residual-form readings r = G − τ_meas (rows [x, z, θ, q…]); ``weights``: the
    fit's row weights (n,) or its weight blocks (W, index) (``_fit``)."""
    if method == "dynamic":
        kw = {"weight": weights} if isinstance(weights, tuple) else {"row_weights": weights}
        out = loc.localize_dynamic(robot, q, r, ambiguity_tol=ambiguity_tol, **kw)
    else:
        G = dyn.gravity_vector(robot.with_base(True), q)
        out = loc.localize_paper(robot, q, np.zeros_like(q), G - r, link, bias=G)
    return out.alpha, out.force_N


def _fit(noise: SensorNoise, n_links: int, method: str, Ym, repeat: int):
    """The estimator's own fit for B postures, each localized ``repeat`` times in a row: the row
    weights 1/(f σ)² (``_fit_weights``), or with the robot's model rows Y (B, n, r) the weight blocks

        W_b = (diag((f σ)²) + Y_b Y_bᵀ)⁻¹

    (estimator.stream weights by the noise + model covariance R + G Gᵀ; settled, G Gᵀ = Y Yᵀ)."""
    rw = _fit_weights(noise, n_links, method)
    if rw is None or Ym is None:
        return rw
    W = np.linalg.inv(np.eye(len(rw)) / rw + Ym @ np.swapaxes(Ym, 1, 2))
    return W, np.repeat(np.arange(len(W)), repeat)


def _model_rows(robot, q, parameter_cov):
    """(B, n, r): −Y_u(q, 0) S with S Sᵀ = Σ_θ, the settled residual's sensitivity to δθ in S's
    columns (None without a covariance)."""
    if parameter_cov is None:
        return None
    from estimator.model_error import covariance_sqrt

    S, _ = covariance_sqrt(parameter_cov)
    _, Yu = robot.with_base(True).momentum_regressor(q, np.zeros_like(q))
    return -Yu @ S


def _truth(robot, q_joint, link, alpha, force):
    tau, W = static_readings(robot, q_joint, link, alpha, force)
    q = np.concatenate([np.zeros((len(q_joint), 3)), q_joint], axis=1)
    readings = np.concatenate([W, tau], axis=1)                     # τ_meas,true on every row
    r_true = dyn.gravity_vector(robot.with_base(True), q) - readings  # = Jᵀ F
    return q, readings, r_true


def _link_length(robot, q, link):
    joints, _ = dyn.forward_kinematics(robot.with_base(True), q)
    idx = np.arange(len(q))
    return np.hypot(*(joints[idx, link] - joints[idx, link - 1]).T)


def first_order(robot: Robot, q_joint, link, alpha, force_N, noise: SensorNoise,
                method: str = "dynamic", step: float = 1e-6, parameter_cov=None,
                model_error: bool = True) -> Propagation:
    """Linearized error: Σ_(α,F) = J Σ_r Jᵀ, Σ_r = diag(f² σ_n² + g² τ_true²) + Y Σ_θ Yᵀ
    (f: filter factor; Y = −Y_u(q, 0) with ``parameter_cov`` Σ_θ, module doc), J through the
    estimator's fit (weighted by the noise and Σ_θ: ``_fit``). ``model_error=False``: the robot's
    error is left out of Σ_r (the noise's part alone), not out of the fit."""
    if method not in METHODS:
        raise InputError(f"method: unknown {method!r}; use one of {', '.join(METHODS)}")
    q_joint, link, alpha, force = _check(robot, q_joint, link, alpha, force_N)
    q, readings, r_true = _truth(robot, q_joint, link, alpha, force)
    B, n = r_true.shape
    sig_n, sig_g = noise.per_row(robot.n_links)
    var_r = (noise.filter_factor(method) * sig_n) ** 2 + (sig_g * readings) ** 2     # (B, n)
    cov_r = var_r[:, :, None] * np.eye(n)
    Ym = _model_rows(robot, q, parameter_cov)
    if Ym is not None and model_error:
        cov_r = cov_r + Ym @ np.swapaxes(Ym, 1, 2)
    eye = np.eye(n) * step
    r_pert = np.concatenate([r_true[:, None, :] + eye, r_true[:, None, :] - eye], axis=1)   # (B, 2n, n)
    a_out, f_out = _localize(robot, method, np.repeat(q, 2 * n, axis=0), r_pert.reshape(-1, n),
                             np.repeat(link, 2 * n), weights=_fit(noise, robot.n_links, method, Ym, 2 * n))
    y = np.concatenate([a_out[:, None], f_out], axis=1).reshape(B, 2 * n, 3)
    jac = (y[:, :n] - y[:, n:]) / (2 * step)                        # (B, n, 3): ∂(α, Fx, Fz)/∂r_k
    cov = np.einsum("bki,bkl,blj->bij", jac, cov_r, jac)
    alpha_std = np.sqrt(cov[:, 0, 0])
    return Propagation(alpha_std=alpha_std,
                       position_rms_m=alpha_std * _link_length(robot, q, link),
                       force_rms_N=np.sqrt(cov[:, 1, 1] + cov[:, 2, 2]),
                       flagged_fraction=np.where(np.isfinite(alpha_std), 0.0, 1.0))


def monte_carlo(robot: Robot, q_joint, link, alpha, force_N, noise: SensorNoise,
                draws: int = 1000, rng: np.random.Generator | int = 0,
                method: str = "dynamic", parameter_cov=None) -> Propagation:
    """Sampled error over ``draws`` realizations of (g, n, δθ) per posture (δθ: with
    ``parameter_cov``); flagged draws counted."""
    if method not in METHODS:
        raise InputError(f"method: unknown {method!r}; use one of {', '.join(METHODS)}")
    if draws < 2:
        raise InputError(f"draws must be ≥ 2, got {draws}")
    rng = np.random.default_rng(rng)
    q_joint, link, alpha, force = _check(robot, q_joint, link, alpha, force_N)
    q, readings, r_true = _truth(robot, q_joint, link, alpha, force)
    B, n = r_true.shape
    sig_n, sig_g = noise.per_row(robot.n_links)
    f = noise.filter_factor(method)
    e = (f * sig_n * rng.standard_normal((B, draws, n))
         + sig_g * readings[:, None, :] * rng.standard_normal((B, draws, n)))
    Ym = _model_rows(robot, q, parameter_cov)
    if Ym is not None:                            # r = Jᵀ F + Y δθ − e, δθ = S z per draw
        e = e - np.einsum("bnr,bdr->bdn", Ym, rng.standard_normal((B, draws, Ym.shape[2])))
    r = (r_true[:, None, :] - e).reshape(-1, n)
    weights = _fit(noise, robot.n_links, method, Ym, draws)
    tol = noise.ambiguity_tol(robot.n_links, method) if weights is None else \
        AMBIGUITY_N_SIGMA * np.sqrt(robot.n_links + 3)          # whitened cost: noise norm √n
    a_out, f_out = _localize(robot, method, np.repeat(q, draws, axis=0), r, np.repeat(link, draws),
                             tol, weights)
    a_err = a_out.reshape(B, draws) - alpha[:, None]
    f_err = np.hypot(*(f_out.reshape(B, draws, 2) - force[:, None, :]).transpose(2, 0, 1))
    length = _link_length(robot, q, link)
    flagged = ~np.isfinite(a_err)                                  # refused draws carry NaN α
    pos = np.abs(a_err) * length[:, None]
    with warnings.catch_warnings():                                # all-refused postures → NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        pos_rms = np.sqrt(np.nanmean(pos ** 2, axis=1))
        p95 = np.nanpercentile(pos, 95, axis=1)
        a_std = np.nanstd(a_err, axis=1)
        # SE of an RMS: δ-method on the mean of e²: SE(√m) = SD(e²)/(2 √m √N)
        n_ok = np.sum(np.isfinite(pos), axis=1)
        rms_se = np.nanstd(pos ** 2, axis=1) / (2 * pos_rms * np.sqrt(np.maximum(n_ok, 1)))
    return Propagation(alpha_std=a_std, position_rms_m=pos_rms,
                       force_rms_N=np.sqrt(np.mean(f_err ** 2, axis=1)),
                       flagged_fraction=flagged.mean(axis=1), position_p95_m=p95,
                       position_rms_se_m=rms_se, position_p95_se_m=percentile_standard_error(pos, 95.0))


def interval_rms(robot: Robot, q_joint, link, alpha, force_N, noise: SensorNoise, parameter_cov,
                 draws: int = 2000, rng: np.random.Generator | int = 0,
                 method: str = "dynamic", samples: int | None = None) -> np.ndarray:
    """The RMS position error over a held contact's samples, one value per robot draw, (B, draws).

    A robot differs from its file by δθ ~ N(0, Σ_θ) (and a gain error g), fixed for the robot; the
    settled residual Jᵀ F + Y δθ (module doc) is localized without noise: the bias b(δθ, g); the
    per-sample noise adds σ_p (first order, noise only) around it. Over ``samples`` samples of
    the observer's residual (n_eff = samples (1 − a)/(1 + a) independent values, a = e^{−KΔt})
    the RMS is √((b + n̄)² + σ_p² χ²_{n_eff}/n_eff), n̄ ~ N(0, σ_p²/n_eff) (without ``samples``:
    √(b² + σ_p²)): the distribution a set of robots' measured interval errors should follow."""
    rng = np.random.default_rng(rng)
    q_joint, link, alpha, force = _check(robot, q_joint, link, alpha, force_N)
    q, readings, r_true = _truth(robot, q_joint, link, alpha, force)
    B, n = r_true.shape
    _, sig_g = noise.per_row(robot.n_links)
    e = sig_g * readings[:, None, :] * rng.standard_normal((B, draws, n))
    Ym = _model_rows(robot, q, parameter_cov)
    if Ym is not None:
        e = e - np.einsum("bnr,bdr->bdn", Ym, rng.standard_normal((B, draws, Ym.shape[2])))
    r = (r_true[:, None, :] - e).reshape(-1, n)
    weights = _fit(noise, robot.n_links, method, Ym, draws)        # the estimator's own fit
    tol = noise.ambiguity_tol(robot.n_links, method) if weights is None else \
        AMBIGUITY_N_SIGMA * np.sqrt(robot.n_links + 3)
    a_out, _ = _localize(robot, method, np.repeat(q, draws, axis=0), r, np.repeat(link, draws),
                         tol, weights)
    bias = np.abs(a_out.reshape(B, draws) - alpha[:, None]) * _link_length(robot, q, link)[:, None]
    quiet = SensorNoise(torque_std_Nm=noise.torque_std_Nm, wrench_std=noise.wrench_std,
                        torque_gain_rel_std=np.zeros(1), sample_rate_Hz=noise.sample_rate_Hz,
                        gain_per_s=noise.gain_per_s)
    sig = first_order(robot, q_joint, link, alpha, force, quiet, method=method, parameter_cov=parameter_cov,
                      model_error=False).position_rms_m[:, None]
    if samples is None:
        return np.sqrt(bias ** 2 + sig ** 2)
    a = np.exp(-noise.gain_per_s / noise.sample_rate_Hz)
    n_eff = max(1.0, samples * (1 - a) / (1 + a))
    mean = sig / np.sqrt(n_eff) * rng.standard_normal(bias.shape)
    spread = sig ** 2 * rng.chisquare(n_eff, bias.shape) / n_eff
    return np.sqrt((bias + mean) ** 2 + spread)
