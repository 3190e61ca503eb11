"""A sequential detector (CUSUM) on the whitened residual, its threshold set from a target mean
time between false alarms, with the residual's serial correlation accounted for.

Statistic s_k = r_kᵀ R⁻¹ r_k (χ²_n under no contact, estimator.noise). Page's CUSUM with a cap:

    g_k = min(h, max(0, g_{k−1} + s_k − n − δ))

An alarm starts at the sample where g reaches h and lasts until g is back at 0 (the end of the
excursion); each onset is one alarm, so alarms are separated by regeneration points. g is held at h
while the contact lasts, so the flag ends about h/δ samples after the contact does (release delay).
The recursion is done in fixed point (integers of ``QUANTUM`` χ² units): running it on [a, b] at
once or on a then b with the state passed along gives bit-identical alarms.

Threshold. Under no contact the increments x_k = s_k − n − δ have mean −δ and the mean time to the
first crossing grows as ARL₀(h) ≈ A (e^{θ*h} − 1 − θ*h) (Siegmund's form), with θ* the positive
root of the increments' scaled cumulant generating function (large deviations for a quadratic
form of a stationary Gaussian process, Szegő's limit):

    Λ(θ) = −½ (1/2π) ∫ log det(I − 2θ S_z(ω)) dω − θ (n + δ) = 0,

S_z(ω) the spectral density matrix of the whitened residual z = L⁻¹ r. For independent samples
(S_z = I) this is Wald's −(n/2) log(1 − 2θ) = θ(n + δ). The observer makes r an ARMA(1,1)
process with pole a = exp(−KΔt) (r_{k+1} = a r_k + b (B0 e_{k+1} + B1 e_k), estimator.noise), so
the whitened samples are NOT independent: S_z(ω) = L⁻¹ H Hᴴ L⁻ᵀ, H = diag(b/(1 − a e^{−iω}))
(B0 + B1 e^{−iω}); correlation lowers θ* (a correlated run of large s counts many times). When the
root does not exist below the singularity 1/(2 max λ(S_z)), θ* is that singularity.
The prefactor A is calibrated per model by a seeded Monte Carlo of the same process (``CAL_SAMPLES``
samples, CUSUM at thresholds with θ*h = 1…3, where alarms are frequent) and the threshold for a
target mean time 1/α samples between alarm onsets solves A φ(θ*h) = 1/α, φ(u) = e^u − 1 − u
(the Monte Carlo counts onsets with the same release rule, so the release time is included). The test
``tests/test_sequential.py`` and ``reports/detection.md`` check the measured rate against the target.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.errors import InputError

QUANTUM = 2.0 ** -20          # fixed-point step of the CUSUM, in χ² units
CAL_SAMPLES = 400_000         # Monte Carlo samples for the prefactor
CAL_POINTS = (1.0, 1.5, 2.0, 2.5, 3.0)   # θ*h of the Monte Carlo thresholds
N_FREQ = 4096                 # frequency grid of the spectral integral
DEFAULT_DRIFT = 1.0           # δ in units of n (the reference shift: s above 2n on average)


@dataclass(frozen=True)
class CusumState:
    """What the CUSUM carries from one chunk to the next: g (fixed point) and the alarm flag."""

    g: int = 0
    alarm: bool = False


def _lindley_low(x: np.ndarray, g0: int) -> np.ndarray:
    """g_k = max(0, g_{k−1} + x_k) from g0 (integers, exact): S_k − min(−g0, min_{j≤k} S_j)."""
    S = np.cumsum(x)
    return S - np.minimum(np.minimum.accumulate(S), -g0)


def cusum(statistic, n: int, h: float, drift: float | None = None, state: CusumState | None = None):
    """Capped CUSUM on the chi-square statistic s_k (module doc) → (alarm (T,) bool, new state).

    ``drift`` δ (χ² units, default n · DEFAULT_DRIFT), threshold ``h`` (χ² units). Pure: the state
    is explicit, and a chunked run equals the one-shot run bit for bit."""
    s = np.asarray(statistic, float)
    if s.ndim != 1:
        raise InputError(f"cusum: expected a 1-D statistic, got shape {s.shape}")
    delta = float(n) * DEFAULT_DRIFT if drift is None else float(drift)
    if not (np.isfinite(h) and h > 0):
        raise InputError(f"cusum threshold: must be a finite number > 0, got {h}")
    if not (np.isfinite(delta) and delta > 0):
        raise InputError(f"cusum drift: must be a finite number > 0, got {delta}")
    st = CusumState() if state is None else state
    H = int(round(h / QUANTUM))
    lo = -int(round((n + delta) / QUANTUM))
    # increments in fixed point; NaN (a skipped sample) adds nothing; |x| ≥ h acts as ±h (cap)
    x = np.nan_to_num(s - n - delta, nan=0.0)
    xi = np.clip(np.rint(x / QUANTUM), lo, H).astype(np.int64)
    T = len(xi)
    alarm = np.zeros(T, bool)
    g, on, k, win = int(st.g), bool(st.alarm), 0, 64
    while k < T:
        seg = xi[k:k + win]
        if not on:        # below: reflected at 0, look for the first sample reaching h
            gs = _lindley_low(seg, g)
            hit = np.flatnonzero(gs >= H)
        else:             # in an alarm: D = h − g reflected at 0, look for g back to 0
            gs = H - _lindley_low(-seg, H - g)
            hit = np.flatnonzero(gs <= 0)
        if hit.size == 0:
            alarm[k:k + len(seg)] = on
            g = int(gs[-1])
            k += len(seg)
            win = min(2 * win, 1 << 16)
            continue
        j = int(hit[0])
        alarm[k:k + j] = on
        on = not on
        alarm[k + j] = on
        g = H if on else 0
        k += j + 1
        win = 64
    return alarm, CusumState(g=g, alarm=on)


# ----------------------------------------------------------------------------- the threshold
def spectral_matrix(a, b, B0, B1, R, n_freq: int = N_FREQ) -> np.ndarray:
    """S_z(ω) = L⁻¹ H(ω) H(ω)ᴴ L⁻ᵀ on ω = 2πk/n_freq, (n_freq, n, n) (module doc); its mean over
    ω is the identity when R is the model's covariance."""
    w = 2 * np.pi * np.arange(n_freq) / n_freq
    zinv = np.exp(-1j * w)
    H = (b / (1 - a[None, :] * zinv[:, None]))[:, :, None] * (B0[None] + B1[None] * zinv[:, None, None])
    Linv = np.linalg.inv(np.linalg.cholesky(R))
    G = Linv[None] @ H
    return G @ np.conj(G.transpose(0, 2, 1))


def whitened_spectrum(a, b, B0, B1, R, n_freq: int = N_FREQ) -> np.ndarray:
    """Eigenvalues λ_j(ω) of S_z(ω), (n_freq, n)."""
    return np.clip(np.linalg.eigvalsh(spectral_matrix(a, b, B0, B1, R, n_freq)), 0, None)


def arma_spectrum(a: float, theta: float, n: int, n_freq: int = N_FREQ) -> np.ndarray:
    """λ(ω) of n independent unit-variance ARMA(1,1) rows x_k = a x_{k−1} + e_k + θ e_{k−1}."""
    w = 2 * np.pi * np.arange(n_freq) / n_freq
    z = np.exp(-1j * w)
    S = np.abs((1 + theta * z) / (1 - a * z)) ** 2
    S /= S.mean()
    return np.repeat(S[:, None], n, axis=1)


def exponent(lam: np.ndarray, n: int, delta: float) -> float:
    """θ* > 0 with Λ(θ*) = 0 (module doc), or the singularity 1/(2 max λ) when Λ stays < 0."""
    from scipy.optimize import brentq

    top = 1.0 / (2.0 * float(lam.max()))

    def Lam(th):
        return -0.5 * np.log1p(-2 * th * lam).sum(axis=1).mean() - th * (n + delta)

    hi = top * (1 - 1e-12)
    if Lam(hi) <= 0:
        return hi
    return float(brentq(Lam, top * 1e-9, hi, xtol=1e-14 * top, rtol=1e-12))


def _phi(u):
    return np.expm1(u) - u


def synthetic_statistic(a, b, B0, B1, R, T: int, seed: int = 0) -> np.ndarray:
    """s_k = ‖L⁻¹ r_k‖² of a simulated no-contact residual of the model (a, b, B0, B1), (T,)."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(seed)
    burn = int(20 / max(1e-6, 1 - float(np.max(a)))) + 10
    m = B0.shape[1]
    e = rng.standard_normal((T + burn + 1, m))
    d = e[1:] @ B0.T + e[:-1] @ B1.T
    r = np.empty_like(d)
    for i in range(d.shape[1]):
        r[:, i] = lfilter([b[i]], [1.0, -a[i]], d[:, i])
    z = np.linalg.solve(np.linalg.cholesky(R), r[burn:].T).T
    return np.einsum("tk,tk->t", z, z)


def synthetic_arma_statistic(a: float, theta: float, n: int, T: int, seed: int = 0) -> np.ndarray:
    """s_k = Σ_j x_jk² of n independent unit-variance ARMA(1,1) rows, (T,)."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(seed)
    burn = int(20 / max(1e-6, 1 - a)) + 10
    x = lfilter([1.0, theta], [1.0, -a], rng.standard_normal((T + burn, n)), axis=0)[burn:]
    x /= np.sqrt((1 + 2 * a * theta + theta ** 2) / (1 - a ** 2))
    return np.einsum("tk,tk->t", x, x)


@dataclass(frozen=True)
class Calibration:
    """θ*, the prefactor A and its Monte Carlo basis; ``threshold(alpha)`` gives h."""

    n: int
    drift: float
    theta: float
    log_A: float
    alarms: int
    samples: int
    method: str

    def arl(self, h: float) -> float:
        """Mean samples between alarm onsets at threshold h (χ² units)."""
        return float(np.exp(self.log_A) * _phi(self.theta * h))

    def threshold(self, alpha: float) -> float:
        """h with mean time between alarm onsets 1/α samples."""
        from scipy.optimize import brentq

        target = 1.0 / alpha
        f = lambda hh: np.log(self.arl(hh)) - np.log(target)   # noqa: E731
        lo, hi = 1e-6 / self.theta, 1.0 / self.theta
        while f(hi) < 0:
            hi *= 2
        if f(lo) > 0:
            return lo
        return float(brentq(f, lo, hi, xtol=1e-10))


_CACHE: dict = {}


def calibrate(lam: np.ndarray, simulate, n: int, drift: float | None = None, key=None,
              samples: int = CAL_SAMPLES) -> Calibration:
    """θ* from the spectrum ``lam`` and A from ``simulate(T) -> s`` (a seeded synthetic statistic)
    at θ*h in ``CAL_POINTS`` (alarm counts ≥ 30 used, weighted by count)."""
    delta = float(n) * DEFAULT_DRIFT if drift is None else float(drift)
    if key is not None and (key, delta, samples) in _CACHE:
        return _CACHE[(key, delta, samples)]
    theta = exponent(lam, n, delta)
    s = simulate(samples)
    logs, wts, total = [], [], 0
    for u in CAL_POINTS:
        h = u / theta
        alarm, _ = cusum(s, n, h, delta)
        k = int(np.count_nonzero(np.diff(alarm.astype(np.int8)) == 1) + alarm[0])
        if k >= 30:
            logs.append(np.log(len(s) / k) - np.log(_phi(u)))
            wts.append(k)
            total += k
    if not logs:
        raise InputError("cusum calibration: too few alarms in the Monte Carlo run to set the "
                         "threshold (the residual's noise model is degenerate?)")
    cal = Calibration(n=n, drift=delta, theta=theta, log_A=float(np.average(logs, weights=wts)),
                      alarms=total, samples=len(s),
                      method=(f"θ* = {theta:.4g} from the spectral cumulant generating function of the "
                              f"whitened residual; prefactor from a seeded Monte Carlo of the same "
                              f"process ({len(s):,} samples, {total} alarms at θ*h = {CAL_POINTS[0]:g}–{CAL_POINTS[-1]:g})"))
    if key is not None:
        _CACHE[(key, delta, samples)] = cal
    return cal


def calibrate_model(a, b, B0, B1, R, drift: float | None = None, samples: int = CAL_SAMPLES) -> Calibration:
    """Calibration for the residual model of estimator.noise.filter_terms (one posture)."""
    n = R.shape[0]
    lam = whitened_spectrum(a, b, B0, B1, R)
    key = ("model", np.round(np.concatenate([a, b, B0.ravel(), B1.ravel(), R.ravel()]), 12).tobytes())
    return calibrate(lam, lambda T: synthetic_statistic(a, b, B0, B1, R, T), n, drift, key, samples)


def arma_theta(a: float, rho1: float) -> float:
    """θ ∈ [−1, 1] of an ARMA(1,1) with pole a and lag-1 autocorrelation ρ₁ (clipped to the range):
    ρ₁ = (1 + aθ)(a + θ)/(1 + 2aθ + θ²)."""
    th = np.linspace(-1, 1, 20001)
    r = (1 + a * th) * (a + th) / (1 + 2 * a * th + th ** 2)
    return float(th[np.argmin(np.abs(r - rho1))])


def calibrate_quiet(z: np.ndarray, a: float, drift: float | None = None,
                    samples: int = CAL_SAMPLES) -> Calibration:
    """Calibration when the covariance comes from a quiet stretch: rows treated as independent
    ARMA(1,1) with the observer's pole ``a`` and θ from the stretch's lag-1 autocorrelation of
    the whitened residual ``z`` (T, n) (averaged over rows)."""
    z = np.asarray(z, float)
    n = z.shape[1]
    zc = z - z.mean(axis=0)
    rho1 = float(np.mean((zc[1:] * zc[:-1]).sum(axis=0) / (zc * zc).sum(axis=0)))
    theta = arma_theta(a, rho1)
    lam = arma_spectrum(a, theta, n)
    key = ("arma", round(a, 12), round(theta, 6), n)
    cal = calibrate(lam, lambda T: synthetic_arma_statistic(a, theta, n, T), n, drift, key, samples)
    from dataclasses import replace

    return replace(cal, method=f"quiet stretch: rows as independent ARMA(1,1), pole {a:.4g}, "
                               f"θ = {theta:.3f} from the lag-1 autocorrelation {rho1:.3f}; " + cal.method)


DETECTORS = ("chi2", "cusum")


def model_calibration(robot, q, dq, noise, gain_per_s, dt_s: float, timing=None,
                      drift: float | None = None) -> Calibration:
    """Calibration for the noise model (default: the paper leg's sensors) at posture (q, q̇)."""
    from estimator import noise as noise_mod

    noise = noise_mod.paper_leg_noise() if noise is None else noise
    a, b, B0, B1 = noise_mod.filter_terms(robot, q, dq, noise, gain_per_s, dt_s, timing)
    R0 = noise_mod.residual_covariance(robot, q, dq, noise, gain_per_s, dt_s, timing)[0]
    return calibrate_model(a, b, B0[0], B1[0], R0, drift)


def detector_info(info: dict, h: float, cal: Calibration) -> dict:
    """The chi-square detector's ``info`` turned into the CUSUM's (threshold, drift, calibration)."""
    out = {k: v for k, v in info.items() if k != "chi2_threshold"}
    out.update(detector="CUSUM on the whitened residual (chi-square increments)",
               cusum_threshold=h, cusum_drift=cal.drift, cusum_calibration=cal.method,
               false_alarm_rate_meaning="mean time between alarm onsets = 1/rate")
    return out
