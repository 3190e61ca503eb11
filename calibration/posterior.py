"""Closed-form references: ordinary least squares and the exact posterior of the linear model.

Model y = X β + ε, ε ~ N(0, σ² I), X of full column rank p, N readings, ν = N − p.
OLS: β̂ = (XᵀX)⁻¹Xᵀy, s² = ‖y − Xβ̂‖²/ν, R² = 1 − SSR/SST.
Prior p(β, σ) ∝ 1/σ (flat on β, Jeffreys on σ) ⇒ exact posterior (Gelman et al., BDA §14.2):
    β | y ~ t_ν(β̂, s² (XᵀX)⁻¹)            (marginals: Student-t, std = √(s² V_jj ν/(ν−2)))
    σ² | y ~ Scaled-Inv-χ²(ν, s²)         (log σ = ½ log(ν s²) − ½ log χ²_ν)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from userio.errors import InputError

MODELS = ("linear", "quadratic", "hysteresis")
PARAM_NAMES = {
    "linear": ("slope", "offset"),
    "quadratic": ("slope", "offset", "quad"),
    "hysteresis": ("slope", "offset", "hysteresis"),
}


def design_matrix(mass_g: np.ndarray, model: str, unload: np.ndarray | None = None) -> np.ndarray:
    """Columns: linear [m, 1]; quadratic [m, 1, m²]; hysteresis [m, 1, 1{unloading}]."""
    m = np.asarray(mass_g, float)
    cols = [m, np.ones_like(m)]
    if model == "quadratic":
        cols.append(m**2)
    elif model == "hysteresis":
        cols.append(np.zeros_like(m) if unload is None else np.asarray(unload, float))
    elif model != "linear":
        raise InputError(f"--model: unknown model {model!r}; choose from {', '.join(MODELS)}")
    return np.column_stack(cols)


def check_identifiable(X: np.ndarray, model: str, source: str = "data") -> None:
    """InputError if the model cannot be fitted to these readings (rank, ν ≥ 3)."""
    n, p = X.shape
    if model == "hysteresis" and (np.all(X[:, 2] == 0) or np.all(X[:, 2] == 1)):
        raise InputError(f"{source}: column 'direction': model 'hysteresis' needs both "
                         "'load' and 'unload' readings")
    if model == "quadratic" and np.unique(X[:, 0]).size < 3:
        raise InputError(f"{source}: column 'mass_g': model 'quadratic' needs at least 3 load levels")
    if np.linalg.matrix_rank(X) < p:
        raise InputError(f"{source}: model {model!r} is not identifiable from these readings")
    if n - p < 3:
        raise InputError(f"{source}: {n} readings for {p} coefficients; need at least {p + 3}")


@dataclass
class ExactPosterior:
    """OLS fit and the exact Student-t posterior of the coefficients."""

    names: tuple
    beta: np.ndarray          # β̂ (= posterior mean for ν > 1)
    scale: np.ndarray         # s² (XᵀX)⁻¹
    nu: int
    s2: float
    r2: float
    ssr: float

    @property
    def std(self) -> np.ndarray:
        """Marginal posterior std √(s² V_jj ν/(ν−2))."""
        return np.sqrt(np.diag(self.scale) * self.nu / (self.nu - 2))

    @property
    def cov(self) -> np.ndarray:
        """Posterior covariance ν/(ν−2) s² (XᵀX)⁻¹."""
        return self.scale * self.nu / (self.nu - 2)

    def quantiles(self, q=(0.16, 0.5, 0.84)) -> np.ndarray:
        """Marginal quantiles, shape (len(q), p)."""
        from scipy import stats
        return self.beta + stats.t.ppf(np.asarray(q)[:, None], self.nu) * np.sqrt(np.diag(self.scale))

    def sigma_mean(self) -> float:
        """E[σ] = s √(ν/2) Γ((ν−1)/2)/Γ(ν/2)."""
        from scipy.special import gammaln
        nu = self.nu
        return float(np.sqrt(self.s2 * nu / 2) * np.exp(gammaln((nu - 1) / 2) - gammaln(nu / 2)))

    def log_sigma_moments(self) -> tuple[float, float]:
        """Mean and std of log σ: log σ = ½ log(ν s²) − ½ log χ²_ν, E log χ²_ν = ψ(ν/2) + log 2."""
        from scipy.special import digamma, polygamma
        nu = self.nu
        mean = 0.5 * np.log(nu * self.s2) - 0.5 * (digamma(nu / 2) + np.log(2))
        std = 0.5 * np.sqrt(polygamma(1, nu / 2))
        return float(mean), float(std)


def exact_posterior(X: np.ndarray, y: np.ndarray, names=None) -> ExactPosterior:
    """OLS + exact posterior (see module docstring)."""
    X = np.asarray(X, float)
    y = np.asarray(y, float)
    n, p = X.shape
    q, r = np.linalg.qr(X)
    beta = np.linalg.solve(r, q.T @ y)
    resid = y - X @ beta
    ssr = float(resid @ resid)
    sst = float(np.sum((y - y.mean()) ** 2))
    nu = n - p
    s2 = ssr / nu
    rinv = np.linalg.inv(r)
    scale = s2 * (rinv @ rinv.T)
    r2 = 1.0 - ssr / sst if sst > 0 else float("nan")
    return ExactPosterior(names=tuple(names or [f"b{i}" for i in range(p)]), beta=beta,
                          scale=scale, nu=nu, s2=s2, r2=r2, ssr=ssr)
