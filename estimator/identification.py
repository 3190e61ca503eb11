"""Inertial-parameter identification from contact-free logs, for any ``RobotModel``.

The observer's own equation without contact (estimator.observer): over a step,
(P_{k+1} − P_k)/Δt − ū_k = 0 with ū_k = Ȳ_u,k θ + τ̄_k (Ȳ_u,k the trapezoid of the regressor,
τ̄_k the step mean of the measured force with the sensors' declared timing, estimator.timing).
Summed over a window of W steps [s, s + W] it is the momentum balance

    A_w θ = b_w,    A_w = Y_P(s+W) − Y_P(s) − Δt Σ_k Ȳ_u,k,    b_w = Δt Σ_k τ̄_k

(no numerical differentiation: P enters at the window's ends, u as an integral). Its noise is the
sensors' white noise (``estimator.noise.NoiseModel``) through the quadrature: Var b_w,j =
Δt² σ_j² (W − ½) for instantaneous readings (trapezoid weights ½, 1, …, 1, ½), Δt² σ_j² W for
interval means, plus σ_q̇² M_j M_jᵀ at both ends for joint-rate noise (M from the nominal model);
adjacent windows share one reading at weight ½ (correlation ≈ 1/(4W), neglected).

The estimate is the maximum a posteriori θ under a Gaussian prior N(θ₀, Σ₀) at the robot file's
values with its declared uncertainty (``RobotModel.parameter_covariance``):

    H = Σ_w A_wᵀ C_w⁻¹ A_w + Σ₀⁻¹,    θ̂ = H⁻¹ (Σ_w A_wᵀ C_w⁻¹ b_w + Σ₀⁻¹ θ₀),    Cov θ̂ = H⁻¹ · max(1, χ²/dof)

so a direction the log does not excite stays at its nominal value with its prior σ (named:
``unexcited``). If θ̂ is not physically consistent, the same quadratic form is minimized over the
consistent θ, the linear matrix inequalities ``RobotModel.consistency_lmis`` ⪰ 0 (a semidefinite
program, solved by a barrier method with a certified gap). Windows whose
whitened residual is an outlier (a contact, a bump) are excluded and reported as time spans; if
they cover too much of a log, it is refused.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from userio.errors import InputError

OUTLIER_PROBABILITY = 1e-6      # per window, χ²_n: a window beyond this is not noise
MAX_EXCLUDED_FRACTION = 0.25    # more than this excluded from a log: refused
MIN_WINDOWS = 40
UNEXCITED_INFORMATION = 1.0     # data information below the prior's along a direction: unexcited


@dataclass
class Equations:
    """The windowed momentum equations of one log: A (W, n, k), b (W, n), noise covariance
    C (W, n, n), window start/end times (W,), and where they come from."""

    A: np.ndarray
    b: np.ndarray
    C: np.ndarray
    t0: np.ndarray
    t1: np.ndarray
    source: str = "log"
    samples: int = 0
    motion_rad_per_s: float = 0.0      # RMS joint rate over the log
    keep: np.ndarray | None = None     # windows kept after outlier exclusion


def window_equations(model, t, q, v, tau_meas, noise, timing=None, window_s: float = 0.005,
                     source: str = "log", chunk: int = 8192) -> Equations:
    """Equations of one contiguous log (t (T,), q (T, n_q), v, τ_meas (T, n_v)) in windows of
    ``window_s`` (module doc). The log must be regularly sampled (no gaps)."""
    from estimator import timing as timing_mod
    from estimator.observer import regular_period

    t = np.asarray(t, float)
    T = len(t)
    dt = regular_period(t)
    steps = np.diff(t)
    if T > 1 and np.any(np.abs(steps - dt) > 0.01 * dt):
        k = int(np.flatnonzero(np.abs(steps - dt) > 0.01 * dt)[0])
        raise InputError(f"{source}: a gap at t = {t[k]:.6g}–{t[k + 1]:.6g} s (Δt {steps[k]:.3g} s, "
                         f"period {dt:.3g} s): the momentum integral cannot bridge it; pass the "
                         f"parts before and after it as two logs")
    W = max(1, int(round(window_s / dt)))
    n_win = (T - 1) // W
    n = np.shape(v)[1]                       # observer rows (a URDF robot's q has a quaternion)
    sig_tau = _force_sigma(noise, n)
    tauT = np.asarray(tau_meas, float).T
    taubar = 0.5 * (tauT[:, 1:] + tauT[:, :-1])
    if not timing_mod.is_instant(timing):
        taubar = taubar + timing_mod.step_mean_correction(tauT, timing, dt)
    A_parts, b = [], np.empty((n_win, n))
    for s0 in range(0, n_win, max(1, chunk // W)):
        s1 = min(n_win, s0 + max(1, chunk // W))
        lo, hi = s0 * W, s1 * W + 1
        YP, Yu = model.momentum_regressor(q[lo:hi], v[lo:hi])
        Yubar = 0.5 * (Yu[1:] + Yu[:-1])                                   # (steps, n, k)
        k = Yu.shape[2]
        m = s1 - s0
        integral = Yubar.reshape(m, W, n, k).sum(axis=1) * dt
        A_parts.append(YP[W::W] - YP[:-1:W][:m] - integral)
        b[s0:s1] = taubar[:, lo:hi - 1].T.reshape(m, W, n).sum(axis=1) * dt
    A = np.concatenate(A_parts) if A_parts else np.zeros((0, n, len(model.parameter_names)))
    mean = np.array([k == "mean" for k, _ in timing]) if timing is not None else np.zeros(n, bool)
    var = dt * dt * sig_tau ** 2 * np.where(mean, W, W - 0.5)
    C = np.broadcast_to(np.diag(var), (n_win, n, n)).copy()
    if noise.velocity_sigma_rad_per_s > 0 and n_win:
        ends = np.r_[0, np.arange(1, n_win + 1) * W]
        M = model.mass_matrix(q[ends])[:, :, model.n_base:]               # (n_win+1, n, joints)
        MM = noise.velocity_sigma_rad_per_s ** 2 * np.einsum("wij,wkj->wik", M, M)
        C += MM[:-1] + MM[1:]
    motion = float(np.sqrt(np.mean(np.asarray(v, float)[:, model.n_base:] ** 2))) if T else 0.0
    idx = np.arange(n_win) * W
    return Equations(A=A, b=b, C=C, t0=t[idx], t1=t[idx + W], source=source, samples=T,
                     motion_rad_per_s=motion)


def _force_sigma(noise, n: int) -> np.ndarray:
    """σ per force channel [Fx, Fz, My or the spatial base's, τ_1…]: FT first, then joints."""
    ft = np.asarray(noise.ft_sigma, float)
    joints = n - ft.size
    return np.concatenate([ft, np.broadcast_to(noise.torque_sigma_Nm, (joints,))])


@dataclass
class Identification:
    """θ̂ with its covariance, and what the fit says about the logs."""

    theta: np.ndarray
    covariance: np.ndarray
    nominal: np.ndarray
    prior_covariance: np.ndarray
    names: tuple
    unexcited: list[str]
    statistics: dict
    excluded: dict = field(default_factory=dict)     # source → [(t0, t1)] excluded spans
    active_constraints: list[str] = field(default_factory=list)


def _whiten(eqs: list[Equations]):
    """Stacked whitened rows (L⁻¹A, L⁻¹b) of the kept windows, and the per-window L⁻¹."""
    As, bs, Ls = [], [], []
    for e in eqs:
        keep = e.keep if e.keep is not None else np.ones(len(e.b), bool)
        Linv = np.linalg.inv(np.linalg.cholesky(e.C))
        Ls.append(Linv)
        As.append(np.einsum("wij,wjk->wik", Linv[keep], e.A[keep]))
        bs.append(np.einsum("wij,wj->wi", Linv[keep], e.b[keep]))
    k = eqs[0].A.shape[2]
    A = np.concatenate(As).reshape(-1, k) if As else np.zeros((0, k))
    b = np.concatenate(bs).ravel() if bs else np.zeros(0)
    return A, b, Ls


def _window_stat(e: Equations, Linv, theta):
    """Whitened residual s_w = ‖L⁻¹(b − Aθ)‖² per window."""
    r = e.b - np.einsum("wik,k->wi", e.A, theta)
    z = np.einsum("wij,wj->wi", Linv, r)
    return np.einsum("wi,wi->w", z, z), r


def _spans(flag, t0, t1, pad: int = 2):
    """Time spans of the flagged windows, each widened by ``pad`` windows, merged."""
    if not np.any(flag):
        return []
    f = flag.copy()
    for s in range(1, pad + 1):
        f[:-s] |= flag[s:]
        f[s:] |= flag[:-s]
    edges = np.diff(np.r_[0, f.astype(int), 0])
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(float(t0[a]), float(t1[b - 1])) for a, b in zip(starts, stops)], f


def identify(model, eqs: list[Equations], prior_cov: np.ndarray, *, max_rounds: int = 4) -> Identification:
    """MAP θ from the equations of one or more logs (module doc)."""
    from scipy.special import chdtri          # P(χ²_n > h) = α ↔ h = chdtri(n, α); no scipy.stats

    theta0 = np.asarray(model.parameters(), float)
    k = theta0.size
    names = tuple(model.parameter_names)
    P0 = np.asarray(prior_cov, float)
    if not np.all(np.isfinite(P0)) or np.linalg.eigvalsh(P0).min() <= 0:
        raise InputError("identification prior: the declared uncertainty must be > 0 for every "
                         "parameter (a zero σ cannot be a prior)")
    P0inv = np.linalg.inv(P0)
    n = eqs[0].A.shape[1]
    for e in eqs:
        if len(e.b) < MIN_WINDOWS:
            raise InputError(f"{e.source}: too short to identify: {e.samples} samples make "
                             f"{len(e.b)} windows; need at least {MIN_WINDOWS}")
        if e.motion_rad_per_s < 1e-3:
            raise InputError(f"{e.source}: the joints do not move (RMS joint rate "
                             f"{e.motion_rad_per_s:.2g} rad/s): a log without motion identifies "
                             f"nothing but gravity; record the excitation scene "
                             f"(scenes/identification_excitation.toml)")
        e.keep = np.ones(len(e.b), bool)
    h_out = float(chdtri(n, OUTLIER_PROBABILITY))
    q25 = float(chdtri(n, 0.75))                   # the lower quartile of χ²_n
    excluded = {}

    def solve():
        A, b, Ls = _whiten(eqs)
        return np.linalg.solve(A.T @ A + P0inv, A.T @ b + P0inv @ theta0), Ls

    # concentration steps: refit on the half of each log's windows that fits best, so that a
    # contact covering up to half a log cannot drag the fit onto itself
    theta, Ls = solve()
    for _ in range(6):
        for e, Linv in zip(eqs, Ls):
            s_w, _ = _window_stat(e, Linv, theta)
            e.keep = s_w <= np.median(s_w)
        theta, Ls = solve()
    for _ in range(max_rounds + 1):
        changed = False
        for e, Linv in zip(eqs, Ls):
            s_w, _ = _window_stat(e, Linv, theta)
            best = s_w <= np.median(s_w)
            scale = max(1.0, float(np.quantile(s_w[best], 0.5)) / q25)   # unmodelled, everywhere
            found = _spans(s_w > h_out * scale, e.t0, e.t1)
            spans, keep = (found[0], ~found[1]) if found else ([], np.ones(len(s_w), bool))
            changed |= not np.array_equal(keep, e.keep)
            e.keep = keep
            excluded[e.source] = spans
            frac = 1.0 - keep.mean()
            if frac > MAX_EXCLUDED_FRACTION:
                where = ", ".join(f"{a:.3f}–{b:.3f} s" for a, b in spans[:4])
                raise InputError(f"{e.source}: contact or unmodelled force in {where}"
                                 f"{' …' if len(spans) > 4 else ''} ({frac:.0%} of the log): too "
                                 f"much to exclude; identify on a contact-free log")
        if not changed:
            break
        theta, Ls = solve()
    A, b, Ls = _whiten(eqs)
    Hd = A.T @ A
    H = Hd + P0inv
    theta = np.linalg.solve(H, A.T @ b + P0inv @ theta0)
    active = []
    if model.consistency_problems(theta):
        theta, active = _constrained(model, H, theta, theta0, P0)
    # statistics
    res = b - A @ theta
    dof_eff = float(np.trace(np.linalg.solve(H, Hd)))
    m_eq = len(b)
    chi2_dof = float(res @ res) / max(m_eq - dof_eff, 1.0)
    cov = np.linalg.inv(H) * max(1.0, chi2_dof)
    cov = 0.5 * (cov + cov.T)
    Lp = np.linalg.cholesky(P0)
    lam, U = np.linalg.eigh(Lp.T @ Hd @ Lp)
    sig0 = np.sqrt(np.diag(P0))
    unexcited = []
    for j in np.flatnonzero(lam < UNEXCITED_INFORMATION):
        d = np.abs(Lp @ U[:, j]) / sig0
        for i in np.flatnonzero(d > 0.5 * d.max()):
            if names[i] not in unexcited:
                unexcited.append(names[i])
    lam_pos = np.clip(lam, 0.0, None)
    cond = float(np.sqrt(lam_pos.max() / lam_pos.min())) if lam_pos.min() > 0 else float("inf")
    excited = lam >= UNEXCITED_INFORMATION
    cond_exc = float(np.sqrt(lam[excited].max() / lam[excited].min())) if excited.sum() > 0 else float("nan")
    before, after = _residual_rms(eqs, theta0), _residual_rms(eqs, theta)
    stats = {
        "windows": int(sum(len(e.b) for e in eqs)),
        "windows_used": int(sum(e.keep.sum() for e in eqs)),
        "equations": int(m_eq),
        "condition_number": cond,
        "condition_number_excited": cond_exc,
        "excited_directions": int(excited.sum()),
        "parameters": int(k),
        "effective_parameters": dof_eff,
        "chi2_per_dof": chi2_dof,
        "covariance_scale": max(1.0, chi2_dof),
        "residual_rms_before": before["rms"].tolist(),
        "residual_rms_after": after["rms"].tolist(),
        "whitened_rms_before": before["whitened"],
        "whitened_rms_after": after["whitened"],
    }
    return Identification(theta=theta, covariance=cov, nominal=theta0, prior_covariance=P0,
                          names=names, unexcited=unexcited, statistics=stats, excluded=excluded,
                          active_constraints=active)


def _residual_rms(eqs, theta) -> dict:
    """Per row RMS of the window-mean force error (b − Aθ)/(W Δt) (N, N·m), and the whitened RMS,
    over the kept windows."""
    rs, zs = [], []
    for e in eqs:
        keep = e.keep
        r = e.b[keep] - np.einsum("wik,k->wi", e.A[keep], theta)
        rs.append(r / (e.t1[keep] - e.t0[keep])[:, None])
        Linv = np.linalg.inv(np.linalg.cholesky(e.C[keep]))
        zs.append(np.einsum("wij,wj->wi", Linv, r))
    r, z = np.concatenate(rs), np.concatenate(zs)
    return {"rms": np.sqrt(np.mean(r * r, axis=0)), "whitened": float(np.sqrt(np.mean(z * z)))}


def _constrained(model, H, theta_free, theta0, P0, *, gap: float = 1e-10):
    """argmin (θ − θ_free)ᵀ H (θ − θ_free) over the consistent θ: a semidefinite program, since
    consistency is a set of linear matrix inequalities S_b(θ) ⪰ 0 affine in θ
    (``model.consistency_lmis``: the pseudo-inertias in 3-D). Solved by the barrier method (Boyd &
    Vandenberghe §11.3): Newton's method on t·q(x) − Σ_b log det S_b, t × 10 per round, from the
    strictly consistent θ₀, in prior-σ units x = (θ − θ₀)/σ with q(0) = 1. The central point at t is
    within ν/t of the optimum (ν = Σ_b size of S_b), so it stops at ν/t ≤ ``gap`` (relative to the
    objective at θ₀). Returns (θ, names of the margins active at the optimum)."""
    sig = np.sqrt(np.diag(P0))
    Hs = H * np.outer(sig, sig)
    x_free = (theta_free - theta0) / sig
    Hs = Hs / max(float(x_free @ Hs @ x_free), 1e-300)      # q(0) = 1
    Hs = 0.5 * (Hs + Hs.T)
    n = x_free.size
    S0 = model.consistency_lmis(theta0)
    # the LMIs are affine: S(x) = S0 + Σ_i x_i G_i, G_i = S(e_i) − S0 (exact up to rounding)
    G = [np.stack([s_i - s0 for s_i in cols]) for s0, cols in
         zip(S0, zip(*(model.consistency_lmis(theta0 + sig * e) for e in np.eye(n))))]
    nu = sum(s0.shape[0] * s0.shape[1] for s0 in S0)

    def blocks(x):
        return [s0 + np.einsum("i,ibkl->bkl", x, g) for s0, g in zip(S0, G)]

    def barrier(x):
        """−Σ log det S_b(x), +∞ outside the strictly consistent set."""
        try:
            return -2.0 * sum(np.log(np.diagonal(np.linalg.cholesky(S), axis1=1, axis2=2)).sum()
                              for S in blocks(x))
        except np.linalg.LinAlgError:
            return np.inf

    if not np.isfinite(barrier(np.zeros(n))):
        raise InputError("identification: the robot file's own inertial parameters are not strictly "
                         "physically consistent, so there is no consistent start for the fit")
    x, t = np.zeros(n), 1.0
    while True:
        for _ in range(200):                                     # Newton's method at this t
            Wg = [np.einsum("bkl,iblm->ibkm", np.linalg.inv(S), g) for S, g in zip(blocks(x), G)]
            grad = 2 * t * Hs @ (x - x_free) - sum(np.einsum("ibkk->i", w) for w in Wg)
            hess = 2 * t * Hs + sum(np.einsum("ibkl,jblk->ij", w, w) for w in Wg)
            step = -np.linalg.lstsq(hess, grad, rcond=None)[0]
            decrement = float(-grad @ step)
            if decrement < 1e-8:                                 # ≪ ν: centred enough
                break
            f0, s_ = t * (x - x_free) @ Hs @ (x - x_free) + barrier(x), 1.0
            while s_ > 1e-12:                                    # backtracking (Armijo 0.25)
                xn = x + s_ * step
                if t * (xn - x_free) @ Hs @ (xn - x_free) + barrier(xn) <= f0 - 0.25 * s_ * decrement:
                    break
                s_ *= 0.5
            else:
                break
            x = xn
        if nu / t <= gap:
            break
        t *= 10.0
    theta = theta0 + sig * x
    if model.consistency_problems(theta):
        raise InputError("identification: no physically consistent fit found (the barrier method "
                         "ended outside the consistent set)")
    m0 = np.abs(model.consistency_margins(theta0))
    m = model.consistency_margins(theta)
    names = getattr(model, "consistency_margin_names", None) or [f"consistency margin {j}"
                                                                  for j in range(m.size)]
    return theta, [names[j] for j in np.flatnonzero(m < 1e-3 * m0)]
