"""The observer residual's noise under no contact, and a detector with a stated false-alarm rate.

The exact observer (estimator.observer) is the linear filter r_{k+1} = a ∘ r_k + b ∘ d_k with
d_k = (P_{k+1} − P_k)/Δt − ū_k. Sensor noise e_k = [n_τ (n rows: Fx, Fz, My, τ_1…τ_N),
n_q̇ (N joint rates), n_q (N joint angles)], white with Σ_e = diag(σ²), enters d_k as the moving
average d_k = B0 e_{k+1} + B1 e_k (linearized at the posture):

    B0 = [−c₁ I,  M_j/Δt − ½ ∂u/∂q̇_j,  ∂P/∂q_j/Δt − ½ ∂u/∂q_j]
    B1 = [−c₀ I, −M_j/Δt − ½ ∂u/∂q̇_j, −∂P/∂q_j/Δt − ½ ∂u/∂q_j]

(c₁ = c₀ = ½ for instantaneous readings, c₁ = 1, c₀ = 0 for interval means). With S0 = B0ΣB0ᵀ +
B1ΣB1ᵀ and S1 = Cov(d_k, d_{k−1}) = B1ΣB0ᵀ, the stationary covariance (the discrete Lyapunov
equation R = A R A + b bᵀ-terms, solved in closed form for the diagonal A) is

    R_ij = b_i b_j (S0_ij + a_j S1_ij + a_i S1_ji) / (1 − a_i a_j).

Detector: z_k = L_k⁻¹ r_k with L_k Lᵀ_k = R(posture_k), s_k = ‖z_k‖² ~ χ²_n under no contact;
flag s_k > h with P(χ²_n > h) = α (the false-alarm probability per sample). The marginal law holds
for the correlated r_k too, so the expected fraction of flagged contact-free samples is α, and the
number of alarm onsets per second is at most α/Δt.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pathlib import Path

import numpy as np

from userio.errors import InputError
from userio.ranges import Range, check_ranges

# physical ranges of the sensor noise (1σ per sample), declared once (userio.ranges.Range)
TORQUE_SIGMA_RANGE = Range(1e-9, 1e4, "N·m", low="below any real sensor's noise: the residual "
                           "covariance would be singular", high="N·mm typed as N·m?")
FT_SIGMA_RANGE = Range(1e-9, 1e5, "N or N·m", low="below any real FT sensor's noise: the residual "
                       "covariance would be singular", high="mN typed as N?")
VELOCITY_SIGMA_RANGE = Range(0.0, 1e3, "rad/s", high="deg/s typed as rad/s?")
ENCODER_COUNTS_RANGE = Range(4, 2.0 ** 40, "counts/rev", zero_ok=True,
                             low="an encoder has at least 4 counts per revolution (0: no quantization)")

DEFAULT_FALSE_ALARMS_PER_S = 1.0 / 3600.0
QUIET_SEGMENTS = 8          # a quiet window's eighths must agree with each other (6 standard errors)
QUIET_MAX_OFFSET = 4.0      # and its residual's median sit within this many σ of zero


@dataclass(frozen=True)
class NoiseModel:
    """White sensor noise per sample (1σ): joint torques (N,), FT wrench [Fx N, Fz N, My N·m],
    joint-rate noise and encoder resolution (0 = none)."""

    torque_sigma_Nm: np.ndarray = field(metadata={"range": TORQUE_SIGMA_RANGE})
    ft_sigma: np.ndarray = field(metadata={"range": FT_SIGMA_RANGE})
    velocity_sigma_rad_per_s: float = field(default=0.0, metadata={"range": VELOCITY_SIGMA_RANGE})
    encoder_counts: int = field(default=0, metadata={"range": ENCODER_COUNTS_RANGE})
    source: str = "option"

    def __post_init__(self):
        for name, where in (("torque_sigma_Nm", "torque sigma"), ("ft_sigma", "FT sigma")):
            v = np.atleast_1d(np.asarray(getattr(self, name), float))
            if not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise InputError(f"{self.source}: {where}: every σ must be finite and > 0, got {v.tolist()}")
            object.__setattr__(self, name, v)
        if self.ft_sigma.shape != (3,):
            raise InputError(f"{self.source}: FT sigma: needs 3 values [Fx, Fz, My], got {self.ft_sigma.size}")
        if not (np.isfinite(self.velocity_sigma_rad_per_s) and self.velocity_sigma_rad_per_s >= 0):
            raise InputError(f"{self.source}: velocity sigma must be finite and ≥ 0")
        if not np.isfinite(self.encoder_counts) or int(self.encoder_counts) != self.encoder_counts \
                or self.encoder_counts < 0:
            raise InputError(f"{self.source}: encoder counts must be a whole number ≥ 0")
        check_ranges(self, keys={k: f"{self.source}: {v}" for k, v in (
            ("torque_sigma_Nm", "torque sigma"), ("ft_sigma", "FT sigma"),
            ("velocity_sigma_rad_per_s", "velocity sigma"), ("encoder_counts", "encoder counts"))})

    def describe(self) -> str:
        return (f"{self.source}: τ σ {np.round(self.torque_sigma_Nm, 6).tolist()} N·m, FT σ "
                f"{np.round(self.ft_sigma, 6).tolist()}, q̇ σ {self.velocity_sigma_rad_per_s:g} rad/s, "
                f"encoder {self.encoder_counts} counts/rev")


def noise_side_file(log_path) -> Path:
    """``LOG.noise.toml`` beside ``LOG.csv`` / ``LOG.parquet``: the log's sensor noise, declared."""
    p = Path(log_path)
    return p.with_name(p.stem + ".noise.toml")


def noise_toml(noise: NoiseModel, who: str = "torquebench's simulator") -> str:
    """The ``LOG.noise.toml`` text of a noise model (1σ per sample, SI units)."""
    vec = lambda v: "[" + ", ".join(f"{float(x):.10g}" for x in np.atleast_1d(v)) + "]"
    return "\n".join([
        f"# Sensor noise of this log (estimator/noise.py, docs/conventions.md), written by {who}:",
        "# white noise, 1 sigma per sample; `estimate` whitens the residual with it.",
        f"# ({noise.source})",
        "[noise]",
        f"torque_sigma_Nm = {vec(noise.torque_sigma_Nm)}",
        f"ft_sigma = {vec(noise.ft_sigma)}            # Fx [N], Fz [N], My [N·m]",
        f"velocity_sigma_rad_per_s = {float(noise.velocity_sigma_rad_per_s):.10g}",
        f"encoder_counts = {int(noise.encoder_counts)}               # per revolution, 0 = none",
    ]) + "\n"


def paper_leg_noise() -> NoiseModel:
    """The paper leg's sensors: FT σ = 0.1 N, 0.1 N, 0.01 N·m; joint torque σ 0.005 N·m."""
    return NoiseModel(torque_sigma_Nm=[0.005], ft_sigma=[0.1, 0.1, 0.01],
                      source="default noise (paper leg sensors)")


def per_sample_rate(value: float, unit: str, dt_s: float, where: str = "--false-alarm-rate") -> float:
    """α per sample from a rate per 'sample', 's' or 'h'; must end in (0, 1) per sample."""
    scale = {"sample": 1.0, "s": dt_s, "h": dt_s / 3600.0}
    if unit not in scale:
        raise InputError(f"{where}: unknown unit {unit!r}; use /sample, /s or /h")
    alpha = float(value) * scale[unit]
    if not (np.isfinite(alpha) and 0 < alpha < 1):
        raise InputError(f"{where}: the false-alarm rate must be in (0, 1) per sample, got "
                         f"{alpha:g} per sample ({value:g}/{unit} at Δt = {dt_s:g} s)")
    from estimator.limits import FALSE_ALARM_PER_SAMPLE_RANGE

    why = FALSE_ALARM_PER_SAMPLE_RANGE.problem(alpha)
    if why:
        raise InputError(f"{where}: {value:g}/{unit} at Δt = {dt_s:g} s gives {why}")
    return alpha


def parse_rate(text: str, where: str = "--false-alarm-rate") -> tuple[float, str]:
    """'1/h', '0.01/s', '1e-6/sample', or a bare number (per second) → (value, unit)."""
    s = str(text).strip().replace(" ", "")
    value, _, unit = s.partition("/")
    try:
        v = float(value)
    except ValueError:
        raise InputError(f"{where}: expected a rate like 1/h, 0.01/s or 1e-6/sample, got {text!r}") from None
    return v, (unit or "s")


def _jacobians(robot, q, dq, h=1e-6):
    """∂P/∂q, ∂P/∂q̇ (= M), ∂u/∂q, ∂u/∂q̇ at B postures by central differences: (B, n, n) each,
    u = Cᵀq̇ − G (the model part; τ_meas enters with the identity)."""
    from estimator.observer import chain_terms, full_robot

    rob = full_robot(robot)
    q = np.atleast_2d(q)
    dq = np.atleast_2d(dq)
    B, n = q.shape
    eye = np.eye(n) * h
    out = []
    for which in (0, 1):
        qq = np.repeat(q[:, None], 2 * n, axis=1)
        dd = np.repeat(dq[:, None], 2 * n, axis=1)
        tgt = qq if which == 0 else dd
        tgt[:, :n] += eye
        tgt[:, n:] -= eye
        t = chain_terms(rob, qq.reshape(-1, n), dd.reshape(-1, n))
        P = t["P"].reshape(B, 2 * n, n)
        u = (t["CTdq"] - t["G"]).reshape(B, 2 * n, n)
        out.append(((P[:, :n] - P[:, n:]) / (2 * h)).transpose(0, 2, 1))   # (B, row, coord)
        out.append(((u[:, :n] - u[:, n:]) / (2 * h)).transpose(0, 2, 1))
    JPq, Juq, JPdq, Judq = out
    return JPq, JPdq, Juq, Judq


def filter_terms(robot, q, dq, noise: NoiseModel, gain_per_s, dt_s: float, timing=None):
    """(a, b, B0, B1) of the no-contact residual r_{k+1} = a ∘ r_k + b ∘ (B0 e_{k+1} + B1 e_k),
    e_k unit white noise (m = n + 2N channels, σ folded into B0, B1 (B, n, m)) (module doc)."""
    from estimator import observer

    q = np.atleast_2d(np.asarray(q, float))
    dq = np.atleast_2d(np.asarray(dq, float))
    B, n = q.shape
    N = n - 3
    K = observer.gains(robot, gain_per_s)
    a, b = observer.coefficients(K, dt_s, "exact")
    JPq, JPdq, Juq, Judq = _jacobians(robot, q, dq)
    mean = np.zeros(n, bool) if timing is None else np.array([k == "mean" for k, _ in timing])
    c1 = np.where(mean, 1.0, 0.5)
    c0 = np.where(mean, 0.0, 0.5)
    j = slice(3, n)
    sig_tau = np.concatenate([noise.ft_sigma, np.broadcast_to(noise.torque_sigma_Nm, (N,))])
    sig_dq = np.full(N, noise.velocity_sigma_rad_per_s)
    sig_q = np.full(N, (2 * np.pi / noise.encoder_counts) / np.sqrt(12) if noise.encoder_counts else 0.0)
    sig = np.concatenate([sig_tau, sig_dq, sig_q])
    B0 = np.concatenate([np.broadcast_to(-np.diag(c1), (B, n, n)),
                         JPdq[:, :, j] / dt_s - 0.5 * Judq[:, :, j],
                         JPq[:, :, j] / dt_s - 0.5 * Juq[:, :, j]], axis=2) * sig
    B1 = np.concatenate([np.broadcast_to(-np.diag(c0), (B, n, n)),
                         -JPdq[:, :, j] / dt_s - 0.5 * Judq[:, :, j],
                         -JPq[:, :, j] / dt_s - 0.5 * Juq[:, :, j]], axis=2) * sig
    return a, b, B0, B1


def residual_covariance(robot, q, dq, noise: NoiseModel, gain_per_s, dt_s: float, timing=None):
    """Stationary no-contact covariance of the exact observer's residual, (B, n, n) (module doc)."""
    a, b, B0, B1 = filter_terms(robot, q, dq, noise, gain_per_s, dt_s, timing)
    S0 = B0 @ B0.transpose(0, 2, 1) + B1 @ B1.transpose(0, 2, 1)
    S1 = B1 @ B0.transpose(0, 2, 1)
    num = S0 + S1 * a[None, None, :] + S1.transpose(0, 2, 1) * a[None, :, None]
    return np.outer(b, b) * num / (1.0 - np.outer(a, a))


def quiet_covariance(r: np.ndarray, t: np.ndarray, t0: float, t1: float, gain_per_s,
                     dt_s: float, where: str = "--quiet-window", method: str = "exact") -> np.ndarray:
    """The residual's stationary sensor-noise covariance from the stretch t0 ≤ t ≤ t1, (n, n).

    Not the spread of r itself: over a stretch r also carries the model error Φ_k δθ (a bias on a
    held leg, a posture- and velocity-dependent signal on a moving one; estimator.model_error),
    which is not stationary noise. The sensor noise is read from the observer's innovations
    d_k = (r_{k+1} − a r_k)/b (the drive, an MA(1) process d_k = B0 e_{k+1} + B1 e_k) differenced
    once, which removes a slowly varying model error: with C0 = Cov(Δd_k), C1 = Cov(Δd_k, Δd_{k−1})
    (robust: MAD scales, winsorized products about zero),

        S0 = C0 + (C1 + C1ᵀ)/2,   S1 = (C1 + S0)/2,   R_ij = b_i b_j (S0 + a_j S1 + a_i S1ᵀ)_ij/(1 − a_i a_j)

    (the module doc's stationary covariance). Refuses a stretch shorter than 20 observer time
    constants or whose first and last quarters differ by more than 6 standard errors (a contact,
    or a drift) on any row."""
    from estimator import observer
    from estimator.detection import robust_sigma

    if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
        raise InputError(f"{where}: expected T0:T1 with T0 < T1 (seconds), got {t0:g}:{t1:g}")
    sel = (t >= t0) & (t <= t1)
    x, tx = r[sel], t[sel]
    n = r.shape[1]
    K = np.broadcast_to(np.asarray(gain_per_s, float), (n,))
    a_min = float(np.exp(-np.min(K) * dt_s))
    tau_c = (1 + a_min) / (1 - a_min)               # samples per independent value of r
    if len(x) < 20 * tau_c:
        raise InputError(f"{where}: {len(x)} samples in {t0:g}–{t1:g} s; need at least "
                         f"{int(np.ceil(20 * tau_c))} (20 observer time constants)")
    sig = robust_sigma(x, axis=0)
    if np.any(sig <= 0):
        raise InputError(f"{where}: the residual is constant on some row in {t0:g}–{t1:g} s "
                         f"(a noise-free log?); give a noise model instead")
    m = len(x) // 4
    se = sig * np.sqrt(2 * 1.57 * tau_c / m)
    z = np.abs(np.median(x[:m], axis=0) - np.median(x[-m:], axis=0)) / se
    if np.any(z > 6):
        raise InputError(f"{where}: the residual changes within {t0:g}–{t1:g} s ({z.max():.0f} "
                         f"standard errors between its first and last quarter): it contains a "
                         f"contact or a drift; mark a stretch without contact")
    # a contact inside the stretch (not at its ends): any eighth away from the stretch's median
    k = len(x) // QUIET_SEGMENTS
    if k >= 4 * tau_c:
        seg = np.median(x[:k * QUIET_SEGMENTS].reshape(QUIET_SEGMENTS, k, -1), axis=1)
        zs = np.abs(seg - np.median(x, axis=0)) / (sig * np.sqrt(1.57 * tau_c / k))
        if np.any(zs > 6):
            i = int(np.argmax(zs.max(axis=1)))
            raise InputError(f"{where}: the residual changes within {t0:g}–{t1:g} s (around "
                             f"{t0 + (i + 0.5) * (t1 - t0) / QUIET_SEGMENTS:.3g} s it sits {zs.max():.0f} "
                             f"standard errors from the rest): it contains a contact; mark a stretch "
                             f"without contact")
    a, b = observer.coefficients(K, dt_s, method)
    regular = np.abs(np.diff(tx) - dt_s) <= 0.01 * dt_s
    d = (x[1:] - a * x[:-1]) / b                     # innovations (the drive), (T−1, n)
    ok = regular[1:] & regular[:-1]                  # Δd over two regular steps
    dd = (d[1:] - d[:-1])[ok]
    if len(dd) < 20:
        raise InputError(f"{where}: too few regular steps in {t0:g}–{t1:g} s to read the noise")
    both = ok[1:] & ok[:-1]
    s = robust_sigma(dd, axis=0)
    if np.any(s <= 0):
        raise InputError(f"{where}: the residual's innovations are constant on some row in "
                         f"{t0:g}–{t1:g} s (a noise-free log?); give a noise model instead")
    w = np.clip(dd / s, -4, 4) * s                   # winsorized at ±4 robust σ, about zero
    C0 = w.T @ w / len(w) * _winsor_gain()
    dd_all = np.clip((d[1:] - d[:-1]) / s, -4, 4) * s
    pairs = np.flatnonzero(np.r_[False, both])       # Δd_k and Δd_{k−1} both regular
    C1 = dd_all[pairs].T @ dd_all[pairs - 1] / max(len(pairs), 1) * _winsor_gain()
    S0 = C0 + 0.5 * (C1 + C1.T)
    S1 = 0.5 * (C1 + S0)
    num = S0 + S1 * a[None, :] + S1.T * a[:, None]
    R = np.outer(b, b) * num / (1.0 - np.outer(a, a))
    R = 0.5 * (R + R.T)
    if np.linalg.eigvalsh(R).min() <= 0:
        raise InputError(f"{where}: the noise read from {t0:g}–{t1:g} s is not a covariance "
                         f"(the stretch is too short or not noise); give a noise model instead")
    return R


def _winsor_gain() -> float:
    """1 / E[clip(z, −4, 4)²] for a standard normal z: undoes the winsorizing's shrinkage."""
    from scipy.special import erf

    c = 4.0
    p_in = erf(c / np.sqrt(2))
    inner = p_in - 2 * c * np.exp(-c * c / 2) / np.sqrt(2 * np.pi)
    return float(1.0 / (inner + c * c * (1 - p_in)))


def chi2_threshold(alpha: float, n: int) -> float:
    """h with P(χ²_n > h) = α."""
    from scipy.stats import chi2

    return float(chi2.isf(alpha, n))


def whitened_statistic(r: np.ndarray, R: np.ndarray, stride: int | None = None) -> np.ndarray:
    """s_k = r_kᵀ R⁻¹ r_k, with one R (n, n), or R (B, n, n) per block of ``stride`` samples
    (sample k uses R[k // stride])."""
    R = np.asarray(R, float)
    T, n = r.shape
    if R.ndim == 2:
        R, stride = R[None], max(T, 1)
    Linv = np.linalg.inv(np.linalg.cholesky(R))                # (B, n, n)
    B = Linv.shape[0]
    pad = np.zeros((B * stride, n))
    pad[:T] = r
    z = np.einsum("bij,bsj->bsi", Linv, pad.reshape(B, stride, n)).reshape(-1, n)[:T]
    return np.einsum("tk,tk->t", z, z)
