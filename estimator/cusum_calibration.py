"""The CUSUM's threshold (estimator.sequential) for a target mean time between false alarms,
with the residual's serial correlation accounted for.

Threshold. The alarm-onset rate per sample at threshold h is measured on the noise model itself,
by a seeded Monte Carlo of the same residual process (``Calibration``, ``calibrate``): a free run
counts the excursions of g above 0 that reach h while they are frequent (rate ≥ ``FREE_RATE``),
and multilevel splitting (fixed effort: the states at which excursions first reached one level
are resampled and run on until they reach the next level or fall back to 0) carries that rate
down to ``RATE_FLOOR`` at the cost of a few levels instead of 1/rate samples. The alarm's own
duration and the re-triggering after a release are measured too (``Calibration`` doc); the
threshold for a target rate α solves rate(h) = α. The calibration's 1σ error of the rate at h
(``Calibration.rate_rel_error``) comes from its own counts: Poisson at the free run's top
level, and the spread of ``REPLICAS`` independent splitting chains above it.

Why not an asymptotic formula: the increments x_k = s_k − n − δ are a quadratic form of a
correlated Gaussian process; their large-deviation exponent θ*, the positive root of

    Λ(θ) = −½ (1/2π) ∫ log det(I − 2θ S_z(ω)) dω − θ (n + δ) = 0

(S_z(ω) the spectral density matrix of the whitened residual z = L⁻¹ r; Wald's
−(n/2) log(1 − 2θ) = θ(n + δ) for independent samples), sits for the observer's residual at the
singularity 1/(2 max λ(S_z)) (the AR pole a = exp(−KΔt) puts a spectral peak (1 + a)/(1 − a) at
ω = 0). There, finite-h slopes of log ARL(h) converge to θ* only slowly (the splitting measures a
local slope about 20 % above θ* at h = 100–500), so Siegmund's A (e^{θ*h} − 1 − θ*h) with a fitted
prefactor missed its target by up to 24 %. θ* is kept only for the extrapolation below
``RATE_FLOOR``, where it bounds the slope from below (a conservative threshold). The test
``tests/test_sequential.py`` and ``reports/detection.md`` check the measured rate against the target.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from userio.errors import InputError
from estimator.sequential import DEFAULT_DRIFT, cusum

CAL_SAMPLES = 2_000_000       # free-run Monte Carlo samples of the calibration
CAL_PARTICLES = 12000         # particles per splitting level (all replicas)
REPLICAS = 8                  # independent splitting chains (their spread is the error estimate)
FREE_RATE = 3e-3              # excursion rate per sample up to which the free run's counts are used
RETRIGGER_RATES = (1e-2, 5e-3, 3e-3)   # f where κ is fitted on the detector's own onset counts
RATE_FLOOR = 1e-8             # splitting down to this rate per sample; θ* extrapolation below
CAL_SEED = 20261123           # the calibration's seed (validation runs use others)
N_FREQ = 4096                 # frequency grid of the spectral integral


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


def _einsum_rows(M, x):
    """x @ M.T for (T, k) rows without BLAS (small matrices: a multithreaded BLAS only adds overhead)."""
    return np.einsum("ij,tj->ti", M, x)


def state_model(a, b, B0, B1, R):
    """The residual process in whitened coordinates z = L⁻¹ r (R = L Lᵀ), driven by e_k ~ N(0, I_m):

        z_k = Ã z_{k−1} + C0 e_k + w_{k−1},   w_k = C1 e_k,

    Ã = L⁻¹ diag(a) L, C0 = L⁻¹ diag(b) B0, C1 = L⁻¹ diag(b) B1
    (r_k = a r_{k−1} + b (B0 e_k + B1 e_{k−1}))."""
    L = np.linalg.cholesky(R)
    Li = np.linalg.inv(L)
    return Li @ (np.asarray(a)[:, None] * L), Li @ (b[:, None] * B0), Li @ (b[:, None] * B1), Li


def _free_run(a, b, B0, B1, R, T: int, rng):
    """A stationary run of the model: whitened residual z (T, n) and the carried term w (T, n)."""
    from scipy.signal import lfilter

    At, C0, C1, Li = state_model(a, b, B0, B1, R)
    burn = int(20 / max(1e-6, 1 - float(np.max(a)))) + 10
    e = rng.standard_normal((T + burn + 1, B0.shape[1]))
    d = _einsum_rows(B0, e[1:]) + _einsum_rows(B1, e[:-1])
    r = np.empty_like(d)
    for i in range(d.shape[1]):
        r[:, i] = lfilter([b[i]], [1.0, -a[i]], d[:, i])
    return _einsum_rows(Li, r[burn:]), _einsum_rows(C1, e[burn + 1:])


def synthetic_statistic(a, b, B0, B1, R, T: int, seed: int = 0) -> np.ndarray:
    """s_k = ‖L⁻¹ r_k‖² of a simulated no-contact residual of the model (a, b, B0, B1), (T,)."""
    z, _ = _free_run(a, b, B0, B1, R, T, np.random.default_rng(seed))
    return np.einsum("tk,tk->t", z, z)


def arma_model(a: float, theta: float, n: int):
    """(a, b, B0, B1, R) of n independent unit-variance ARMA(1,1) rows
    x_k = a x_{k−1} + c (e_k + θ e_{k−1})."""
    c = np.sqrt((1 - a ** 2) / (1 + 2 * a * theta + theta ** 2))
    return np.full(n, a), np.ones(n), c * np.eye(n), c * theta * np.eye(n), np.eye(n)


def synthetic_arma_statistic(a: float, theta: float, n: int, T: int, seed: int = 0) -> np.ndarray:
    """s_k = Σ_j x_jk² of n independent unit-variance ARMA(1,1) rows, (T,)."""
    return synthetic_statistic(*arma_model(a, theta, n), T, seed=seed)


def _stage(z, w, g, h_up, At, C0, C1, n, delta, rng, cap=None):
    """Particles (z, w, g) run the CUSUM increments until g ≤ 0 or g ≥ h_up (vectorized over particles).

    Returns (max g seen, succeeded, z, w, g at success, samples until the end). With ``cap`` the
    recursion is the alarm's g = min(cap, g + x) (h_up = ∞): the steps are the alarm's duration."""
    N = len(g)
    idx = np.arange(N)
    gmax, ok, steps = g.copy(), np.zeros(N, bool), np.zeros(N)
    zs, ws, gs = np.empty_like(z), np.empty_like(w), np.empty(N)
    k = 0
    while idx.size:
        k += 1
        e = rng.standard_normal((idx.size, C0.shape[1]))
        z = _einsum_rows(At, z) + _einsum_rows(C0, e) + w
        w = _einsum_rows(C1, e)
        g = g + np.einsum("ij,ij->i", z, z) - n - delta
        if cap is not None:
            g = np.minimum(cap, g)
        gmax[idx] = np.maximum(gmax[idx], g)
        up, down = g >= h_up, g <= 0
        if up.any():
            j = idx[up]
            ok[j], zs[j], ws[j], gs[j] = True, z[up], w[up], g[up]
        end = up | down
        steps[idx[end]] = k
        keep = ~end
        idx, z, w, g = idx[keep], z[keep], w[keep], g[keep]
    return gmax, ok, zs, ws, gs, steps


def _stage_py(z, w, g, h_up, cap, At, C0, C1, shift, seed, out_max, out_ok, out_z, out_w, out_g,
              out_steps):
    """``_stage`` one particle at a time (compiled with numba; its own seeded generator)."""
    np.random.seed(seed)
    N, n = z.shape
    m = C0.shape[1]
    e = np.empty(m)
    zn = np.empty(n)
    for i in range(N):
        zi = z[i].copy()
        wi = w[i].copy()
        gi = g[i]
        gmax = gi
        k = 0
        while True:
            k += 1
            for j in range(m):
                e[j] = np.random.standard_normal()
            s = 0.0
            for r in range(n):
                acc = wi[r]
                for c in range(n):
                    acc += At[r, c] * zi[c]
                for j in range(m):
                    acc += C0[r, j] * e[j]
                zn[r] = acc
                s += acc * acc
            for r in range(n):
                zi[r] = zn[r]
                acc = 0.0
                for j in range(m):
                    acc += C1[r, j] * e[j]
                wi[r] = acc
            gi = gi + s - shift
            if gi > cap:
                gi = cap
            if gi > gmax:
                gmax = gi
            if gi >= h_up:
                out_ok[i] = True
                out_z[i] = zi
                out_w[i] = wi
                out_g[i] = gi
                break
            if gi <= 0.0 or k >= 100_000_000:
                break
        out_max[i] = gmax
        out_steps[i] = k


def _onset_counts_py(x, hs, out):
    """Alarm onsets of the capped CUSUM (module doc, in floats) with increments x at each threshold
    of ``hs`` at once (compiled with numba)."""
    K = hs.shape[0]
    g = np.zeros(K)
    on = np.zeros(K, np.bool_)
    for t in range(x.shape[0]):
        xt = x[t]
        for j in range(K):
            gj = g[j] + xt
            if on[j]:
                if gj <= 0.0:
                    on[j] = False
                    gj = 0.0
                elif gj > hs[j]:
                    gj = hs[j]
            else:
                if gj <= 0.0:
                    gj = 0.0
                elif gj >= hs[j]:
                    on[j] = True
                    out[j] += 1
                    gj = hs[j]
            g[j] = gj


_NB = None


def _compiled():
    """The numba-compiled loops (cached beside this file), or False without numba."""
    global _NB
    if _NB is None:
        try:
            from numba import njit
        except ImportError:
            _NB = False
        else:
            jit = njit(cache=True, nogil=True)
            _NB = {"stage": jit(_stage_py), "onsets": jit(_onset_counts_py)}
    return _NB


def warm() -> bool:
    """Compile the calibration's loops once (numba caches them beside this file), so the first
    CUSUM calibration does not pay the compilation (about 8 s on a loaded 2-core machine); False
    without numba."""
    if not _compiled():
        return False
    z = np.zeros((2, 2))
    _run_stage(z, z, np.ones(2), 2.0, np.eye(2), np.eye(2), np.eye(2), 2, 2.0,
               np.random.default_rng(0))
    onset_counts(np.ones(4), 2, np.array([1.0]), 2.0)
    return True


def _run_stage(z, w, g, h_up, At, C0, C1, n, delta, rng, cap=None):
    """``_stage`` compiled when numba is there (seeded from ``rng``), else the numpy form."""
    nb = _compiled()
    if not nb:
        return _stage(z, w, g, h_up, At, C0, C1, n, delta, rng, cap=cap)
    N = len(g)
    out = (np.empty(N), np.zeros(N, bool), np.zeros_like(z), np.zeros_like(w), np.zeros(N), np.zeros(N))
    nb["stage"](np.ascontiguousarray(z), np.ascontiguousarray(w), np.asarray(g, float), float(h_up),
                np.inf if cap is None else float(cap), np.ascontiguousarray(At),
                np.ascontiguousarray(C0), np.ascontiguousarray(C1), float(n + delta),
                int(rng.integers(0, 2 ** 31 - 1)), *out)
    return out


def onset_counts(s, n: int, h, drift: float) -> np.ndarray:
    """Alarm onsets of the CUSUM on the statistic ``s`` at each threshold of ``h`` (floats; the
    detector itself runs in fixed point)."""
    hs = np.atleast_1d(np.asarray(h, float))
    x = np.asarray(s, float) - n - drift
    nb = _compiled()
    if not nb:
        out = []
        for hh in hs:
            alarm, _ = cusum(s, n, hh, drift)
            out.append(int(np.count_nonzero(np.diff(alarm.astype(np.int8)) == 1) + alarm[0]))
        return np.array(out)
    out = np.zeros(hs.size, np.int64)
    nb["onsets"](x, hs, out)
    return out


@dataclass(frozen=True)
class Calibration:
    """The CUSUM's false-alarm rate as a function of its threshold, measured on the noise model.

    ν(h) = rate per sample of excursions of g (from 0) that reach h: counted directly on a free run
    for h ≤ h0, and ν(h) = ν(h0) Π P(reach h_{i+1} before 0 | reached h_i) above (multilevel
    splitting); D(h) = mean alarm duration (samples from onset to release). Alarm onsets per sample:

        f(h) = ν(h) / (1 + ν(h) D(h))       (the time in alarm does not start excursions)
        rate(h) = f(h) (1 + κ f(h))

    The second factor is what this picture misses at high rates: a release in the middle of a
    stretch of large s (the residual is correlated) lets a new excursion reach a low h at once,
    so one excursion of the free run gives several onsets. That excess is proportional to f; κ is
    fitted on the real detector's onset counts on the free run at f = 0.3–1 % per sample (an
    effect of 10 % at 1 % per sample, 1 % at 0.1 %, and negligible below).

    Above the last level (rate below ``rate_floor``) ν is extrapolated with the exponent θ*, a
    lower bound of the local slope there, so the threshold is conservative (fewer alarms)."""

    n: int
    drift: float
    theta: float
    h_grid: np.ndarray          # thresholds (χ² units), increasing
    log_nu: np.ndarray          # log ν(h) on h_grid
    var_log_nu: np.ndarray      # sampling variance of log ν(h): Poisson ≤ h0, replicas' spread above
    D_h: np.ndarray             # levels where the alarm duration was measured
    D: np.ndarray               # mean alarm duration there (samples)
    retrigger: float            # κ (samples): onsets re-triggered right after a release, per onset / f
    method: str

    def _nu(self, h):
        h = np.asarray(h, float)
        top = self.h_grid[-1]
        inside = np.interp(np.minimum(h, top), self.h_grid, self.log_nu)
        return np.exp(inside - self.theta * np.maximum(h - top, 0.0))

    def duration(self, h):
        """Mean alarm duration at threshold h (samples), interpolated between the measured levels."""
        return np.interp(h, np.r_[0.0, self.D_h], np.r_[1.0, self.D],
                         right=None) + np.maximum(np.asarray(h, float) - self.D_h[-1], 0) / self.drift

    def rate(self, h):
        """Alarm onsets per sample at threshold h: f = ν/(1 + νD), times (1 + κ f) for re-triggering."""
        nu = self._nu(h)
        f = nu / (1 + nu * self.duration(h))
        return f * (1 + self.retrigger * f)

    def rate_rel_error(self, h) -> float:
        """Relative 1σ sampling error of ``rate(h)`` (from the calibration's own counts; above the
        last level, that level's error: the θ* extrapolation's own bias is conservative)."""
        return float(np.sqrt(np.interp(min(h, self.h_grid[-1]), self.h_grid, self.var_log_nu)))

    def arl(self, h: float) -> float:
        """Mean samples between alarm onsets at threshold h (χ² units)."""
        return float(1.0 / self.rate(h))

    def threshold(self, alpha: float) -> float:
        """h with alarm onsets at rate α per sample (mean time 1/α samples between them)."""
        from scipy.optimize import brentq

        f = lambda hh: np.log(self.rate(hh)) - np.log(alpha)   # noqa: E731
        lo, hi = 1e-9, self.h_grid[-1]
        if f(lo) <= 0:
            return float(self.h_grid[0]) if self.h_grid[0] > 0 else lo
        while f(hi) > 0:
            hi *= 2
        return float(brentq(f, lo, hi, xtol=1e-9, rtol=1e-12))


_CACHE: dict = {}


def calibrate(model, n: int, drift: float | None = None, key=None, lam=None,
              samples: int = CAL_SAMPLES, particles: int = CAL_PARTICLES,
              rate_floor: float = RATE_FLOOR, seed: int = CAL_SEED) -> Calibration:
    """Calibration (class doc) of the CUSUM on the residual ``model`` = (a, b, B0, B1, R), seeded.

    Free run of ``samples`` samples: ν(h) counted up to h0 where ν = ``FREE_RATE``, and the states
    at which excursions first reach h0. Then levels from h0 (spacing log(5)/slope): ``particles``
    states (``REPLICAS`` chains) drawn from those that reached h_i run until they reach h_{i+1}
    or fall to 0, down to
    ν < ``rate_floor`` (each spacing from the last slope of log ν, about 1/5 getting through; halved
    and run again when a chain keeps fewer than 5 particles).
    The alarm duration D is measured from the states at each level."""
    delta = float(n) * DEFAULT_DRIFT if drift is None else float(drift)
    ck = None if key is None else (key, delta, samples, particles, rate_floor, seed)
    if ck is not None and ck in _CACHE:
        return _CACHE[ck]
    a, b, B0, B1, R = model
    if lam is None:
        lam = whitened_spectrum(a, b, B0, B1, R)
    theta = exponent(lam, n, delta)
    rng = np.random.default_rng(seed)
    At, C0, C1, _ = state_model(a, b, B0, B1, R)
    z, w = _free_run(a, b, B0, B1, R, samples, rng)
    S = np.cumsum(np.einsum("tk,tk->t", z, z) - n - delta)
    g = S - np.minimum(np.minimum.accumulate(S), 0.0)
    pos = g > 0
    starts = np.flatnonzero(pos & ~np.r_[False, pos[:-1]])
    if starts.size < 100:
        raise InputError("cusum calibration: too few excursions in the Monte Carlo run to set the "
                         "threshold (the residual's noise model is degenerate?)")
    ex_max = np.sort(np.maximum.reduceat(g, starts))
    k0 = min(int(FREE_RATE * samples), ex_max.size - 1)
    h0 = float(ex_max[::-1][k0])
    ex_id = np.cumsum(pos & ~np.r_[False, pos[:-1]])
    cand = np.flatnonzero(g >= h0)
    ent = cand[np.r_[True, ex_id[cand][1:] != ex_id[cand][:-1]]]
    # ν(h) for h ≤ h0 straight from the counts
    h_free = np.linspace(0.0, h0, 64)
    cnt = ex_max.size - np.searchsorted(ex_max, h_free, "left")
    hs, lnu, var = [h_free], [np.log(cnt / samples)], [1.0 / cnt]
    nu0, var0 = ent.size / samples, 1.0 / ent.size
    # first spacing from the free run's slope of log ν over the upper half of [0, h0]
    slope0 = np.log(cnt[32] / max(cnt[-1], 1)) / max(h_free[-1] - h_free[32], 1e-12)
    step_h = np.log(5.0) / max(slope0, theta)
    # REPLICAS independent splitting chains from the same entrance pool: ν is their mean, and its
    # error their spread (resampled particles share ancestors, so a binomial error per level
    # would understate it), plus the Poisson error of the free run's count at h0
    per = max(particles // REPLICAS, 50)
    pools = [(z[ent], w[ent], g[ent])] * REPLICAS
    prod = np.ones(REPLICAS)
    h, D_h, D, levels = h0, [], [], 0
    while True:
        picks = [rng.integers(0, pl[2].size, per) for pl in pools]
        zi = np.concatenate([pl[0][k] for pl, k in zip(pools, picks)])
        wi = np.concatenate([pl[1][k] for pl, k in zip(pools, picks)])
        gi = np.concatenate([pl[2][k] for pl, k in zip(pools, picks)])
        nd = min(zi.shape[0], 500)           # D is a small correction (ν D ≤ a few %)
        D_h.append(h)
        D.append(float(_run_stage(zi[:nd], wi[:nd], np.full(nd, h), np.inf,
                                  At, C0, C1, n, delta, rng, cap=h)[5].mean()))
        if nu0 * prod.mean() <= rate_floor:
            break
        while True:         # a level too far for some chain: halve the spacing and run it again
            gmax, ok, zs, ws, gs, _ = _run_stage(zi, wi, gi, h + step_h, At, C0, C1, n, delta, rng)
            if ok.reshape(REPLICAS, per).sum(axis=1).min() >= 5:
                break
            step_h *= 0.5
            if step_h < 1e-6 * (1.0 + h0):
                raise InputError("cusum calibration: the splitting lost its particles (none reached "
                                 "the next level); the residual's noise model is degenerate?")
        hh = np.linspace(h, h + step_h, 33)[1:]
        curves, pools, p_level = [], [], []
        for r in range(REPLICAS):
            sl = slice(r * per, (r + 1) * per)
            gm = np.sort(gmax[sl])
            frac = (per - np.searchsorted(gm, hh, "left")) / per
            curves.append(prod[r] * frac)
            p_level.append(frac[-1])
            okr = ok[sl]
            pools.append((zs[sl][okr], ws[sl][okr], gs[sl][okr]))
        curves = np.array(curves)
        mean = curves.mean(axis=0)
        hs.append(hh)
        lnu.append(np.log(nu0 * mean))
        var.append(var0 + curves.var(axis=0, ddof=1) / (REPLICAS * mean ** 2))
        prod = curves[:, -1]
        h += step_h
        levels += 1
        # next spacing from this level's slope, so that about 1/5 of the particles get through
        step_h = np.log(5.0) / max(-np.log(np.mean(p_level)) / step_h, theta)
    h_grid = np.concatenate(hs)
    cal = Calibration(
        n=n, drift=delta, theta=theta, h_grid=h_grid, log_nu=np.concatenate(lnu),
        var_log_nu=np.concatenate(var), D_h=np.array(D_h), D=np.array(D), retrigger=0.0, method="")
    # κ from the real detector's onsets on the free run (weighted least squares of k/(T f) − 1 = κ f)
    s = np.diff(np.r_[0.0, S]) + n + delta
    hk = np.array([cal.threshold(f) for f in RETRIGGER_RATES])
    f = cal.rate(hk)
    k = onset_counts(s, n, hk, delta)
    wgt = samples * f                         # 1/var of k/(T f) − 1 (Poisson count)
    num, den = float(np.sum(wgt * f * (k / (samples * f) - 1))), float(np.sum(wgt * f * f))
    cal = replace(cal, retrigger=max(num / den, 0.0))
    cal = replace(
        cal,
        method=(f"alarm rate measured on a seeded Monte Carlo of the same process: {samples:,} "
                f"free-run samples (excursions counted up to a rate of {FREE_RATE:g} per sample), "
                f"then multilevel splitting ({levels} levels, {REPLICAS} independent chains of "
                f"{per} particles) down to "
                f"{rate_floor:g} per sample; below that, extrapolated with the exponent θ* = "
                f"{theta:.4g} from the whitened residual's spectrum (conservative); re-triggering "
                f"κ = {cal.retrigger:.3g} samples fitted on the detector's onsets in the free run"))
    if ck is not None:
        _CACHE[ck] = cal
    return cal


def calibrate_model(a, b, B0, B1, R, drift: float | None = None, samples: int = CAL_SAMPLES) -> Calibration:
    """Calibration for the residual model of estimator.noise.filter_terms (one posture)."""
    n = R.shape[0]
    key = ("model", np.round(np.concatenate([a, b, B0.ravel(), B1.ravel(), R.ravel()]), 12).tobytes())
    return calibrate((a, b, B0, B1, R), n, drift, key, samples=samples)


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
    key = ("arma", round(a, 12), round(theta, 6), n)
    cal = calibrate(arma_model(a, theta, n), n, drift, key, lam=arma_spectrum(a, theta, n),
                    samples=samples)
    return replace(cal, method=f"quiet stretch: rows as independent ARMA(1,1), pole {a:.4g}, "
                               f"θ = {theta:.3f} from the lag-1 autocorrelation {rho1:.3f}; " + cal.method)


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
    if "false_alarm_rate_per_s" in out:
        out["false_alarm_rate_per_s_error_estimate"] = out["false_alarm_rate_per_s"] * cal.rate_rel_error(h)
        out["false_alarm_rate_per_s_error_method"] = (
            "1σ of the alarm rate at the CUSUM threshold from its Monte Carlo calibration (Poisson "
            f"count of the free run, spread of {REPLICAS} independent splitting chains)")
    return out
