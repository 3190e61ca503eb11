"""Bayesian calibration fit with emcee.

``reading = slope·m + offset [+ quad·m²] [+ hysteresis·1{unloading}] + ε``, m in g,
ε ~ N(0, σ² + (∂reading/∂m)² σ_m²) (σ_m: optional standard uncertainty of the applied masses,
"errors in the load", marginalized analytically to first order).
Priors: flat on slope, offset, quad, hysteresis; p(σ) ∝ 1/σ, i.e. flat on log σ in [−30, 30].
With σ_m = 0 the posterior is exactly the Student-t of :mod:`calibration.posterior`.

Sampling: ``emcee.EnsembleSampler(vectorize=True)`` with the differential-evolution move
(ter Braak 2006; τ ≈ 10 steps here vs ≈ 35 for the default stretch move, so 3–4× less work to
reach 50 τ; ``moves="stretch"`` selects the default), started in a small ball around least squares,
run in chunks until the chain is ≥ 50 τ long (τ = max integrated autocorrelation time over the
parameters), then 2τ of burn-in is discarded. Not converged within ``max_steps`` → ``converged``
is False and the store refuses the fit.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from userio.errors import InputError
from calibration.posterior import (PARAM_NAMES, ExactPosterior, check_identifiable,
                                   design_matrix, exact_posterior)
from calibration.session import Session

LOG_SIGMA_BOUNDS = (-30.0, 30.0)
MAX_RESIDUALS_PER_STEP = 2e7          # walkers × readings evaluated per step (a (W, n) float64 array: 160 MB)
MAX_CHAIN_BYTES = 4 * 2**30           # the chain emcee keeps: walkers × steps × (p + 2) float64


def check_cost(n_readings: int, n_walkers: int, max_steps: int, ndim: int, source="session") -> None:
    """Refuse, before any allocation, a fit whose per-step work or stored chain is out of reach:
    walkers × readings residuals per step (memory and time of one step), and walkers × max_steps ×
    (parameters + log-probability) doubles kept by emcee. The message names the knob to turn."""
    per_step = float(n_walkers) * n_readings
    if per_step > MAX_RESIDUALS_PER_STEP:
        ok_walkers = int(MAX_RESIDUALS_PER_STEP // max(n_readings, 1))
        raise InputError(
            f"{source}: {n_readings} readings × {n_walkers} walkers = {per_step:.3g} residuals per step "
            f"({per_step * 8 / 2**20:.0f} MiB, and ≥ 300 steps), above {MAX_RESIDUALS_PER_STEP:.0e}; "
            + (f"use --walkers ≤ {ok_walkers} (at least 8)" if ok_walkers >= 8 else
               "average the readings of each load step first (the reading noise is fitted as sigma)"))
    chain = float(n_walkers) * max_steps * (ndim + 1) * 8
    if chain > MAX_CHAIN_BYTES:
        raise InputError(
            f"--walkers/--max-steps: {n_walkers} walkers × {max_steps} steps keep a chain of "
            f"{chain / 2**30:.3g} GiB, above {MAX_CHAIN_BYTES / 2**30:.0f} GiB; lower --walkers or "
            f"--max-steps (the default 256 × 50000 keeps {256 * 50000 * (ndim + 1) * 8 / 2**30:.2g} GiB)")


@dataclass
class FitResult:
    """Posterior of a calibration fit and its diagnostics."""

    model: str
    names: tuple                  # coefficient names + "log_sigma"
    samples: np.ndarray           # (S, p+1) after burn-in (flattened over walkers)
    autocorr_time: np.ndarray     # τ per parameter (steps)
    acceptance_fraction: float
    n_steps: int
    n_walkers: int
    burn_in: int
    converged: bool
    reason: str
    exact: ExactPosterior         # OLS / exact reference (σ_m = 0)
    mass_std_g: float = 0.0
    elapsed_s: float = 0.0
    seed: int | None = None
    extra: dict = field(default_factory=dict)

    @property
    def coef_names(self) -> tuple:
        return self.names[:-1]

    @property
    def mean(self) -> np.ndarray:
        return self.samples.mean(axis=0)

    @property
    def std(self) -> np.ndarray:
        return self.samples.std(axis=0, ddof=1)

    @property
    def cov(self) -> np.ndarray:
        return np.cov(self.samples, rowvar=False)

    @property
    def sigma(self) -> float:
        """Posterior mean of σ (reading units)."""
        return float(np.exp(self.samples[:, -1]).mean())

    @property
    def tau_max(self) -> float:
        return float(np.max(self.autocorr_time))

    def quantiles(self, q=(0.16, 0.5, 0.84)) -> np.ndarray:
        return np.quantile(self.samples, q, axis=0)

    @property
    def effective_samples(self) -> np.ndarray:
        """N_eff = N / τ per parameter (N = kept samples over all walkers)."""
        return self.samples.shape[0] / np.maximum(self.autocorr_time, 1.0)

    @property
    def mc_standard_error(self) -> np.ndarray:
        """Monte Carlo standard error (1σ) of each posterior mean: SE = σ_post √(τ / N)."""
        return self.std / np.sqrt(self.effective_samples)

    @property
    def rhat(self) -> float:
        """Split-R̂ (Gelman–Rubin) over the walkers' halves, max over parameters (≈ 1 when mixed)."""
        n_keep = self.samples.shape[0] // self.n_walkers
        if n_keep < 4:
            return float("nan")
        ch = self.samples[: n_keep * self.n_walkers].reshape(n_keep, self.n_walkers, -1)
        half = n_keep // 2
        ch = np.concatenate([ch[:half], ch[half:2 * half]], axis=1)        # (half, 2W, p)
        W = ch.var(axis=0, ddof=1).mean(axis=0)
        B = half * ch.mean(axis=0).var(axis=0, ddof=1)
        var = (half - 1) / half * W + B / half
        return float(np.max(np.sqrt(var / W)))

    def thinned(self, max_samples: int = 2000, rng=None) -> np.ndarray:
        """Thin by ~τ/2 then keep at most ``max_samples`` rows (for the store)."""
        thin = max(1, int(self.tau_max / 2))
        s = self.samples.reshape(-1, self.n_walkers, self.samples.shape[1])[::thin].reshape(
            -1, self.samples.shape[1])
        if s.shape[0] > max_samples:
            rng = rng or np.random.default_rng(0)
            s = s[np.sort(rng.choice(s.shape[0], max_samples, replace=False))]
        return s


def make_log_prob(X: np.ndarray, y: np.ndarray, model: str, mass_std_g: float = 0.0):
    """Vectorized log posterior: theta (W, p+1) → (W,). See module docstring."""
    X = np.ascontiguousarray(X, float)
    y = np.asarray(y, float)
    n, p = X.shape
    m = X[:, 0]
    lo, hi = LOG_SIGMA_BOUNDS

    def log_prob(theta):
        theta = np.atleast_2d(theta)
        beta, log_s = theta[:, :p], theta[:, p]
        r = y[None, :] - beta @ X.T
        if mass_std_g > 0:
            dy_dm = beta[:, :1] + (2 * beta[:, 2:3] * m[None, :] if model == "quadratic" else 0.0)
            var = np.exp(2 * log_s)[:, None] + (dy_dm * mass_std_g) ** 2
            lp = -0.5 * np.sum(np.log(var) + r * r / var, axis=1)
        else:
            lp = -n * log_s - 0.5 * np.einsum("ij,ij->i", r, r) * np.exp(-2 * log_s)
        return np.where((log_s > lo) & (log_s < hi), lp, -np.inf)

    return log_prob


def check_readings(y: np.ndarray, source, adc_bits: int | None = None) -> None:
    """Refuse constant readings (no response to load: saturated, disconnected or stuck; the
    posterior is degenerate) and readings at an ADC rail (−2^(N−1) or 2^(N−1) − 1 counts, clipped;
    N = ``adc_bits``, else the default sensor's width, calibration.model.adc_rails)."""
    from calibration.model import adc_rails

    y = np.asarray(y, float)
    if y.size and np.ptp(y) <= 1e-12 * max(np.abs(y).max(), 1e-300):
        raise InputError(f"{source}: column 'reading': all {y.size} readings are {y[0]:g}; a sensor "
                         "that does not respond to load (saturated, stuck or disconnected) cannot "
                         "be calibrated")
    lo, hi = adc_rails(adc_bits)
    rail = (y <= lo) | (y >= hi)
    if np.count_nonzero(rail) * 2 > y.size:
        raise InputError(f"{source}: column 'reading': {np.count_nonzero(rail)} of {y.size} readings "
                         f"are at the ADC full scale (saturated), {lo} or {hi} counts; reduce the gain "
                         "or the load")


def fit_session(session: Session, model: str = "linear", *, mass_std_g: float = 0.0,
                n_walkers: int = 256, seed: int | None = 0, tau_multiple: float = 50.0,
                max_steps: int = 50_000, min_steps: int = 300, moves: str = "de",
                progress: bool = False, adc_bits: int | None = None) -> FitResult:
    """Fit ``session`` with emcee until converged (≥ ``tau_multiple`` τ) or ``max_steps``."""
    import time

    import emcee

    if mass_std_g < 0:
        raise InputError(f"--mass-std-g: must be ≥ 0, got {mass_std_g:g}")
    names = PARAM_NAMES.get(model)
    if names is None:
        design_matrix(session.mass_g, model)  # raises the InputError naming the models
    X = design_matrix(session.mass_g, model, session.unload)
    y = session.reading
    check_readings(y, session.source, adc_bits)
    check_identifiable(X, model, session.source)
    exact = exact_posterior(X, y, names)
    p = X.shape[1]
    ndim = p + 1
    check_cost(len(y), int(n_walkers), int(max_steps), ndim, session.source)
    n_walkers = max(int(n_walkers), 2 * ndim + 2)
    n_walkers += n_walkers % 2
    rng = np.random.default_rng(seed)
    with np.errstate(all="ignore"):
        ls_mean, ls_std = exact.log_sigma_moments()
    lo, hi = LOG_SIGMA_BOUNDS
    if not (np.isfinite(ls_mean) and lo + 2 < ls_mean < hi - 2 and np.all(np.isfinite(exact.std))
            and np.all(exact.std > 0)):
        s_hat = float(np.exp(ls_mean)) if np.isfinite(ls_mean) else float("nan")
        raise InputError(f"{session.source}: column 'reading': the readings scatter about the "
                         f"{model} fit by σ ≈ {s_hat:.3g} {session.reading_unit}, outside what a fit "
                         f"can represent (e^{lo + 2:g}–e^{hi - 2:g}): noise-free (simulated without "
                         "noise?) or wildly scaled readings; a real sensor's readings carry noise")
    center = np.concatenate([exact.beta, [ls_mean]])
    width = np.concatenate([exact.std, [ls_std]])
    p0 = center + 0.1 * width * rng.standard_normal((n_walkers, ndim))
    log_prob = make_log_prob(X, y, model, mass_std_g)
    if moves not in ("de", "stretch"):
        raise InputError(f"moves: {moves!r} is not 'de' or 'stretch'")
    move = emcee.moves.DEMove() if moves == "de" else emcee.moves.StretchMove()
    sampler = emcee.EnsembleSampler(n_walkers, ndim, log_prob, vectorize=True, moves=move)
    sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
    start = time.perf_counter()
    chunk = min_steps
    state = p0
    tau = np.full(ndim, np.inf)
    converged, reason = False, ""
    while True:
        state = sampler.run_mcmc(state, chunk, progress=progress)
        n = sampler.iteration
        tau = sampler.get_autocorr_time(tol=0)
        if np.all(np.isfinite(tau)) and n >= tau_multiple * tau.max():
            converged, reason = True, f"chain {n} steps ≥ {tau_multiple:g} τ (τ = {tau.max():.1f})"
            break
        if n >= max_steps:
            reason = (f"not converged: {n} steps < {tau_multiple:g} τ (τ = {tau.max():.1f}); "
                      "raise max_steps")
            break
        need = int(np.ceil(tau_multiple * tau.max() * 1.1)) - n if np.all(np.isfinite(tau)) else n
        chunk = int(min(max(need, 100), max_steps - n))
    burn = int(np.ceil(2 * tau.max())) if np.all(np.isfinite(tau)) else n // 2
    burn = min(burn, n - 1)
    samples = sampler.get_chain(discard=burn, flat=True)
    return FitResult(model=model, names=tuple(names) + ("log_sigma",), samples=samples,
                     autocorr_time=tau, acceptance_fraction=float(np.mean(sampler.acceptance_fraction)),
                     n_steps=n, n_walkers=n_walkers, burn_in=burn, converged=converged,
                     reason=reason, exact=exact, mass_std_g=mass_std_g,
                     elapsed_s=time.perf_counter() - start, seed=seed, extra={"moves": moves})
