"""Collision detection (‖r‖ > ε_res) and isolation (paper eq. 5, generalized to N links).

Isolation: a force on link c moves only the joints upstream of it, so the joint rows r_{q_1…q_c}
carry it and r_{q_{c+1}…q_N} stay at zero (eq. 5). The collided link is the LAST joint row whose
magnitude exceeds its threshold. Thresholds are noise-aware: σ_i z_{α/2} with σ_i = √R_ii from
the sensor noise model's residual covariance (estimator.noise) at a per-row false-isolation
probability α per sample (``whitened_thresholds``; streamable, no statistic over the whole log),
or, when the user marks a quiet stretch, max(floor, n_σ · σ_i) with σ_i a robust (MAD) noise
estimate of row i over the samples with no detected contact (``noise_thresholds``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from userio.errors import InputError


def detect(rnorm: np.ndarray, threshold: float = 0.06, debounce: int = 0) -> np.ndarray:
    """contact[k] = ‖r_k‖ > ε for the ``debounce`` + 1 samples k−debounce…k (all of them)."""
    if not (np.isfinite(threshold) and threshold > 0):
        raise InputError(f"threshold: must be a finite number > 0, got {threshold}")
    if int(debounce) != debounce or debounce < 0:
        raise InputError(f"debounce: must be a whole number of samples ≥ 0, got {debounce}")
    raw = np.asarray(rnorm) > threshold
    d = int(debounce)
    if d == 0:
        return raw
    run = np.concatenate([[0], np.cumsum(raw)])
    k = np.arange(len(raw))
    window = run[k + 1] - run[np.maximum(k - d, 0)]
    return (window == d + 1) & (k >= d)


def robust_sigma(x: np.ndarray, axis=0) -> np.ndarray:
    """1.4826 · median(|x − median x|): a standard deviation that ignores outliers."""
    med = np.median(x, axis=axis, keepdims=True)
    return 1.4826 * np.median(np.abs(x - med), axis=axis)


def noise_thresholds(joint_residual: np.ndarray, quiet: np.ndarray | None = None,
                     floor: float = 0.01, n_sigma: float = 5.0) -> np.ndarray:
    """Per joint row: max(floor, n_σ σ_i), σ_i robust over the ``quiet`` (no-contact) samples."""
    r = np.asarray(joint_residual, float)
    if quiet is not None:
        r = r[np.asarray(quiet, bool)]
    if len(r) < 10:                 # too few contact-free samples to say anything: the floor
        return np.full(r.shape[1], float(floor))
    return np.maximum(floor, n_sigma * robust_sigma(r, axis=0))


def isolate(joint_residual: np.ndarray, thresholds) -> np.ndarray:
    """Eq. 5: the collided link (1-based) = last joint row above its threshold; 0 if none, (T,)."""
    r = np.abs(np.asarray(joint_residual, float))
    above = r > np.asarray(thresholds, float)
    N = r.shape[-1]
    last = N - np.argmax(above[..., ::-1], axis=-1)
    return np.where(above.any(axis=-1), last, 0)


def whitened_thresholds(R, alpha: float) -> np.ndarray:
    """Per joint row i: σ_i z with σ_i = √R_ii (R the (N+3)² no-contact covariance of the
    residual, estimator.noise) and z = Φ⁻¹(1 − α/2): a contact-free row exceeds it with
    probability α per sample (two-sided Gaussian)."""
    from scipy.special import ndtri          # Φ⁻¹ (scipy.stats costs seconds at start-up)

    R = np.asarray(R, float)
    if not (np.isfinite(alpha) and 0 < alpha < 1):
        raise InputError(f"false-alarm probability per sample must be in (0, 1), got {alpha}")
    return np.sqrt(np.diag(R)[3:]) * float(-ndtri(alpha / 2))


@dataclass
class DetectorState:
    """What a detector carries from one chunk to the next: the debounce run (samples in a row
    above the threshold, up to the last one seen), and room for a sequential test's state."""

    run: int = 0
    extra: dict = field(default_factory=dict)


def debounce_chunk(raw: np.ndarray, debounce: int, state: DetectorState) -> np.ndarray:
    """contact[k] = raw for the ``debounce`` + 1 samples k−debounce…k (all of them), counted
    across chunk boundaries through ``state.run`` (updated): the rule of ``detect``."""
    raw = np.asarray(raw, bool)
    if raw.size == 0:
        return raw
    idx = np.arange(raw.size)
    last_false = np.maximum.accumulate(np.where(raw, -1, idx))
    run = np.where(last_false >= 0, idx - last_false, state.run + idx + 1)
    state.run = int(run[-1])
    return run >= debounce + 1


def chi2_isf(alpha: float, dof: int) -> float:
    """h with P(χ²_dof > h) = α: scipy.special.chdtri, what scipy.stats.chi2.isf evaluates (and
    noise.chi2_threshold), without importing scipy.stats (seconds at start-up)."""
    from scipy.special import chdtri

    return float(chdtri(dof, alpha))


def sumsq_rows(xT: np.ndarray) -> np.ndarray:
    """Σ_k x_k² per sample of a link-major (n, T) array, rows added in order (batch-independent)."""
    out = xT[0] * xT[0]
    for k in range(1, len(xT)):
        out += xT[k] * xT[k]
    return out


def whitened_sumsq(rT: np.ndarray, Linv: np.ndarray) -> np.ndarray:
    """s_k = ‖L⁻¹ r_k‖², with one lower-triangular L⁻¹ (n, n) or one per sample (T, n, n)."""
    n = rT.shape[0]
    out = np.zeros(rT.shape[1])
    for i in range(n):
        z = None
        for j in range(i + 1):
            c = Linv[i, j] if Linv.ndim == 2 else Linv[:, i, j]
            z = c * rT[j] if z is None else z + c * rT[j]
        out += z * z
    return out
